//! `pmsm_sim::analysis::replay` on logs the test makes itself: a simulated run written as an MCAP log,
//! read back, and written again as CSV in the documented format (power-invariant scaling,
//! skipped cycles, a voltage delay); malformed CSV and corrupt MCAP files give errors naming
//! where, never a panic.

mod support;

use std::fmt::Write as _;
use std::path::{Path, PathBuf};

use pmsm_sim::analysis::replay::{
    DriveLog, ReplayError, ReplayMotor, Scaling, parse_csv, parse_motor, read_log, replay,
};
use pmsm_sim::output::mcap::LogOptions;
use pmsm_sim::scenario::Scenario;

fn tmp(name: &str) -> PathBuf {
    let d = std::env::temp_dir().join(format!("pmsm-sim-replay-{}", std::process::id()));
    std::fs::create_dir_all(&d).unwrap_or_else(|e| panic!("{e}"));
    d.join(name)
}

/// A short simulated run (default scenario, 0.35 s) as an MCAP log; with its motor.
fn simulated() -> (PathBuf, ReplayMotor, Scenario) {
    let sc = Scenario::default_servo().with_duration(0.35);
    let path = tmp("run.mcap");
    support::log_run(&sc, &path, LogOptions::default());
    let motor = motor_of(&sc);
    (path, motor, sc)
}

/// The replay's motor file of a scenario (its observer's parameters and `Ts`).
fn motor_of(sc: &Scenario) -> ReplayMotor {
    let m = sc.observer_params();
    let toml = format!(
        "rs_ohm = {}\nld_h = {}\nlq_h = {}\npsi_f_wb = {}\npole_pairs = {}\nts_s = {}\n",
        m.rs_ohm,
        m.ld_h,
        m.lq_h,
        m.psi_f_wb,
        m.pole_pairs,
        sc.ts_s()
    );
    parse_motor(&toml, "motor.toml").unwrap_or_else(|e| panic!("{e}"))
}

/// The log as a CSV in the documented format: row `k` carries the voltage of the period that
/// ended at it (`u_csv[k+1] = u_ab[k]`, `u_csv[0] = u_prev`), scaled by `scale`; the rows in
/// `drop` left out (their period added to the next row's); the voltage column delayed by
/// `delay` rows.
fn to_csv(log: &DriveLog, scale: f64, drop: &[usize], delay: usize) -> String {
    let n = log.len();
    let u_csv: Vec<[f64; 2]> = (0..n)
        .map(|k| if k == 0 { log.u_prev } else { log.u_ab[k - 1] })
        .collect();
    let mut s = String::from(
        "t_s,dt_s,u_alpha_v,u_beta_v,i_alpha_a,i_beta_a,theta_ref_rad,omega_ref_rad_s\n",
    );
    let th = log
        .theta_ref
        .as_ref()
        .unwrap_or_else(|| panic!("reference"));
    let w = log
        .omega_ref
        .as_ref()
        .unwrap_or_else(|| panic!("reference"));
    let mut carry = 0.0;
    for k in 0..n {
        if drop.contains(&k) {
            carry += log.dt_s[k];
            continue;
        }
        let u = u_csv[k.saturating_sub(delay)];
        let _ = writeln!(
            s,
            "{},{},{},{},{},{},{},{}",
            log.t_s[k],
            log.dt_s[k] + carry,
            u[0] * scale,
            u[1] * scale,
            log.i_ab[k][0] * scale,
            log.i_ab[k][1] * scale,
            th[k],
            w[k]
        );
        carry = 0.0;
    }
    s
}

fn close(a: f64, b: f64, tol: f64) -> bool {
    (a - b).abs() <= tol * (1.0 + a.abs().max(b.abs()))
}

#[test]
fn replay_of_simulated_logs() {
    let (path, motor, _sc) = simulated();
    let exact = read_log(&path, Scaling::Amplitude).unwrap_or_else(|e| panic!("{e}"));
    assert!(exact.len() > 3000);
    let ts = motor.ts_s;

    // The replayed EKF on the simulator's own log reproduces the simulator's EKF, so its
    // score is the simulator's own angle error (offset removed, same window).
    let r0 = replay(&exact, &motor, "mcap").unwrap_or_else(|e| panic!("{e}"));
    let s0 = r0.report.ekf.unwrap_or_else(|| panic!("scored"));
    assert!(s0.samples > 1000, "{s0:?}");
    assert!(s0.rms_deg < 1.0, "{s0:?}");
    assert_eq!(s0.tracking_while_lost, 0);
    assert!(r0.report.flux.is_some());
    // The drive observer: scored alike, every row accepted, finite, and on the simulator's
    // clean log it tracks the rotor.
    let d0 = r0.report.drive.unwrap_or_else(|| panic!("drive scored"));
    assert_eq!(d0.samples, s0.samples);
    assert_eq!(r0.report.drive_rejected, 0);
    assert!(r0.drive.theta.iter().all(|v| v.is_finite()));
    assert_eq!(r0.drive.theta.len(), exact.len());
    assert!(d0.rms_deg < 5.0, "{d0:?}");
    assert_eq!(d0.tracking_while_lost, 0, "{d0:?}");
    assert!(d0.tracking_share > 0.5, "{d0:?}");
    let json = serde_json::to_value(&r0.report).unwrap_or_else(|e| panic!("{e}"));
    assert!(json["drive"]["rms_deg"].is_number() && json["drive_rejected"] == 0);
    // The error by speed band: this run turns one way only, so bands and no fit.
    let bands = r0.report.ekf_speed_bands.as_ref().expect("bands");
    assert!(!bands.bands.is_empty() && bands.bands.iter().all(|b| b.forward));
    assert!(bands.fit.is_none() && json["ekf_speed_bands"]["fit"].is_null());
    let scored: usize = bands.bands.iter().map(|b| b.samples).sum();
    assert!(
        scored <= s0.samples && scored + 100 > s0.samples,
        "{scored} {}",
        s0.samples
    );
    assert!(pmsm_sim::analysis::replay::markdown(&r0.report).contains("| band | direction |"));

    // Exact CSV (amplitude-invariant): the same arrays, the same score.
    let csv = to_csv(&exact, 1.0, &[], 0);
    let a =
        parse_csv(csv.as_bytes(), "a.csv", Scaling::Amplitude).unwrap_or_else(|e| panic!("{e}"));
    // The last row has no next CSV row: it repeats the one before.
    let n = exact.len();
    assert!(a.u_ab[..n - 1] == exact.u_ab[..n - 1]);
    assert_eq!(a.u_ab[n - 1], exact.u_ab[n - 2]);
    assert!(a.i_ab == exact.i_ab);
    assert_eq!(a.u_prev, exact.u_prev);
    assert_eq!(a.dt_s, exact.dt_s);
    let ra = replay(&a, &motor, "a").unwrap_or_else(|e| panic!("{e}"));
    let sa = ra.report.ekf.unwrap_or_else(|| panic!("scored"));
    assert!(close(sa.rms_deg, s0.rms_deg, 1e-9), "{sa:?} {s0:?}");

    // Power-invariant: converted back to within rounding.
    let k = 1.5f64.sqrt();
    let csv = to_csv(&exact, k, &[], 0);
    let p = parse_csv(csv.as_bytes(), "p.csv", Scaling::Power).unwrap_or_else(|e| panic!("{e}"));
    for (x, y) in p
        .u_ab
        .iter()
        .zip(&exact.u_ab[..n - 1])
        .chain(p.i_ab.iter().zip(&exact.i_ab))
    {
        assert!(close(x[0], y[0], 1e-12) && close(x[1], y[1], 1e-12));
    }
    let rp = replay(&p, &motor, "p").unwrap_or_else(|e| panic!("{e}"));
    let sp = rp.report.ekf.unwrap_or_else(|| panic!("scored"));
    assert!((sp.rms_deg - s0.rms_deg).abs() < 0.01, "{sp:?} {s0:?}");
    // Read as amplitude-invariant, the same file is sqrt(3/2) too large.
    let wrong =
        parse_csv(csv.as_bytes(), "p.csv", Scaling::Amplitude).unwrap_or_else(|e| panic!("{e}"));
    assert!(close(wrong.i_ab[100][0], exact.i_ab[100][0] * k, 1e-12));
    // The record's back-EMF per unit speed: the told flux on the log read right, sqrt(3/2)
    // times it (reported as off) on the log read with the wrong scaling.
    let f0 = r0.report.flux_check.unwrap_or_else(|| panic!("flux check"));
    let fp = rp.report.flux_check.unwrap_or_else(|| panic!("flux check"));
    let rw = replay(&wrong, &motor, "wrong").unwrap_or_else(|e| panic!("{e}"));
    let fw = rw.report.flux_check.unwrap_or_else(|| panic!("flux check"));
    println!("flux check: {f0:?} / read power-invariant {fp:?} / read as amplitude {fw:?}");
    assert!(
        f0.blocks >= 10 && (f0.ratio - 1.0).abs() < 0.02 && !f0.off(),
        "{f0:?}"
    );
    assert!((fp.ratio - 1.0).abs() < 0.02 && !fp.off(), "{fp:?}");
    assert!((fw.ratio - k).abs() < 0.03 && fw.off(), "{fw:?}");
    assert!(pmsm_sim::analysis::replay::markdown(&rw.report).contains("More than 10 % off"));

    // Skipped cycles: rows merged; their periods add up, the window after is not scored.
    let drop = [1000, 2000, 2001];
    let csv = to_csv(&exact, 1.0, &drop, 0);
    let m =
        parse_csv(csv.as_bytes(), "m.csv", Scaling::Amplitude).unwrap_or_else(|e| panic!("{e}"));
    assert_eq!(m.len(), exact.len() - drop.len());
    assert!(close(m.dt_s[1000], 2.0 * ts, 1e-12));
    assert!(close(m.dt_s[1999], 3.0 * ts, 1e-12));
    assert_eq!(m.t_s[1000], exact.t_s[1001]);
    assert_eq!(m.i_ab[1999], exact.i_ab[2002]);
    // Row 999 of the merged log is held until row 1001 of the original: the original's
    // voltage of the period that ended at 1001.
    assert_eq!(m.u_ab[999], exact.u_ab[1000]);
    let rm = replay(&m, &motor, "m").unwrap_or_else(|e| panic!("{e}"));
    assert_eq!(rm.report.long_periods, 2);
    let mask = pmsm_sim::analysis::replay::score_mask(&m, ts).unwrap_or_else(|| panic!("mask"));
    let window = (0.02 / ts).round() as usize;
    assert!(mask[1000..1000 + window].iter().all(|x| !x));
    let sm = rm.report.ekf.unwrap_or_else(|| panic!("scored"));
    assert!(sm.rms_deg.is_finite() && sm.samples < s0.samples);

    // A voltage delay of 2 periods: the arrays shifted, the EKF off by more.
    let csv = to_csv(&exact, 1.0, &[], 2);
    let d =
        parse_csv(csv.as_bytes(), "d.csv", Scaling::Amplitude).unwrap_or_else(|e| panic!("{e}"));
    assert_eq!(d.u_ab[500], exact.u_ab[498]);
    assert_eq!(d.u_prev, exact.u_prev);
    let rd = replay(&d, &motor, "d").unwrap_or_else(|e| panic!("{e}"));
    let sd = rd.report.ekf.unwrap_or_else(|| panic!("scored"));
    assert!(sd.rms_deg > s0.rms_deg, "{sd:?} {s0:?}");

    // Outputs: the MCAP log the replay writes is itself a log read_log reads (stamped with
    // the wall-clock time, as the CLI's default writes it).
    let out = tmp("out");
    let wall = pmsm_sim::output::mcap::LogOptions {
        start_time_unix_ns: pmsm_sim::output::mcap::wall_clock_unix_ns(),
        ..Default::default()
    };
    let files = pmsm_sim::analysis::replay::write_outputs(&out, &a, &motor, &ra, wall)
        .unwrap_or_else(|e| panic!("{e}"));
    assert_eq!(files.len(), 3);
    let back = read_log(&files[0], Scaling::Amplitude).unwrap_or_else(|e| panic!("{e}"));
    assert_eq!(back.len(), a.len());
    assert!(back.i_ab == a.i_ab);
    let md = pmsm_sim::analysis::replay::markdown(&ra.report);
    assert!(md.contains("| EKF (firmware's defaults) |") && md.contains("| flux + PLL |"));
    assert!(md.contains(
        "| EKF + feedforward, calibration online, primed by the record (pyfoc's defaults) |"
    ));
    assert!(md.contains("| drive observer |"));
    // Skipped cycles: the drive observer steps over the merged periods and stays finite.
    let dm = rm.report.drive.unwrap_or_else(|| panic!("drive scored"));
    assert!(
        dm.rms_deg.is_finite() && rm.report.drive_rejected == 0,
        "{dm:?}"
    );

    // Corrupt MCAP: errors, never panics.
    let bytes = std::fs::read(&path).unwrap_or_else(|e| panic!("{e}"));
    let bad = tmp("bad.mcap");
    let len = bytes.len();
    for (i, cut) in [9, 40, 200, len / 3, len / 2, len - 20]
        .into_iter()
        .enumerate()
    {
        let mut b = bytes[..cut].to_vec();
        let _ = std::fs::write(&bad, &b);
        assert!(read_log(&bad, Scaling::Amplitude).is_err(), "cut {cut}");
        // Garbage in the length fields.
        b = bytes.clone();
        for j in 0..64 {
            let at = (cut + j * 131 + i) % len;
            if at >= 8 {
                b[at] = 0xff;
            }
        }
        let _ = std::fs::write(&bad, &b);
        let _ = read_log(&bad, Scaling::Amplitude);
    }
    let _ = std::fs::remove_dir_all(path.parent().unwrap_or(Path::new("/nonexistent")));
}

/// The two passes (module docs of `pmsm_sim::analysis::replay`, "Two passes"): on the
/// default scenario's first 1.2 s (the ramp to 2000 rpm and the load step) written with the
/// voltage column 0, 1 and 2 rows late (the applied voltage leads the logged one by as many
/// periods), the drive observer's calibration finds a lead of the right sign, and the EKF
/// told it is closer than the default EKF; one pass with the calibration handed over online
/// is closer than the feedforward EKF it starts as. Measured: 0.000 / 0.142 / 0.263 periods found;
/// RMS 0.069 / 3.96 / 6.17 deg default, 0.070 / 2.91 / 5.35 deg told the calibration.
#[test]
fn calibration_finds_a_known_lead() {
    // A directory of its own: the other tests of this binary run in parallel and remove
    // theirs.
    let dir = std::env::temp_dir().join(format!("pmsm-sim-replay-lead-{}", std::process::id()));
    std::fs::create_dir_all(&dir).unwrap_or_else(|e| panic!("{e}"));
    let path = dir.join("lead.mcap");
    let sc = Scenario::default_servo();
    support::log_run(&sc, &path, LogOptions::default());
    let motor = motor_of(&sc);
    let exact = read_log(&path, Scaling::Amplitude).unwrap_or_else(|e| panic!("{e}"));
    let ts = motor.ts_s;
    for delay in [0usize, 1, 2] {
        let csv = to_csv(&exact, 1.0, &[], delay);
        let log = parse_csv(csv.as_bytes(), "l.csv", Scaling::Amplitude)
            .unwrap_or_else(|e| panic!("{e}"));
        let r = replay(&log, &motor, "l").unwrap_or_else(|e| panic!("{e}"));
        let c = r.report.calibration.unwrap_or_else(|| panic!("calibrated"));
        let s = r.report.ekf.unwrap_or_else(|| panic!("scored"));
        let sc = r.report.ekf_calibrated.unwrap_or_else(|| panic!("scored"));
        println!(
            "delay {delay}: lead {:.3} periods, Rs {:.4} ohm (motor file {:.4}), dead time {:.3} V; \
             RMS default {:.3} deg, calibrated {:.3} deg",
            c.voltage_lead_periods,
            c.rs_ohm,
            motor.params.rs_ohm,
            c.dead_time_v,
            s.rms_deg,
            sc.rms_deg
        );
        // The lead found has the delay's sign and at most its size (the drive observer's
        // lead converges slowly at this speed: module docs of `ekf_core::calibration`), the
        // resistance stays within 1 % of the motor file's (the log is the simulator's, whose
        // motor is the file's), and told the calibration the EKF is closer wherever there is
        // a lead to find, and no worse than 1.1 x without one.
        let d = delay as f64;
        assert!(
            c.voltage_lead_periods > 0.1 * d - 0.02 && c.voltage_lead_periods < d + 0.02,
            "{c:?}"
        );
        assert!((c.rs_ohm / motor.params.rs_ohm - 1.0).abs() < 0.01, "{c:?}");
        if delay == 0 {
            assert!(sc.rms_deg < 1.1 * s.rms_deg, "{s:?} {sc:?}");
        } else {
            assert!(sc.rms_deg < 0.9 * s.rms_deg, "{s:?} {sc:?}");
        }
        assert_eq!(sc.tracking_while_lost, 0);
        let on = r.report.ekf_online.unwrap_or_else(|| panic!("scored"));
        let ff = r.report.ekf_feedforward.unwrap_or_else(|| panic!("scored"));
        println!(
            "delay {delay}: RMS feedforward {:.3} deg, calibration online {:.3} deg",
            ff.rms_deg, on.rms_deg
        );
        // One pass with the calibration handed over online: where there is nothing to find
        // it is the feedforward EKF; with a lead to find, closer than it (measured 0.066 /
        // 3.10 / 5.71 deg against 0.066 / 3.32 / 6.16).
        if delay == 0 {
            assert!(on.rms_deg < 1.05 * ff.rms_deg, "{ff:?} {on:?}");
        } else {
            assert!(on.rms_deg < 0.95 * ff.rms_deg, "{ff:?} {on:?}");
        }
        assert_eq!(on.tracking_while_lost, 0);
        let _ = ts;
    }
    let _ = std::fs::remove_dir_all(&dir);
}

#[test]
fn malformed_csv_names_line_and_column() {
    let h = "t_s,dt_s,u_alpha_v,u_beta_v,i_alpha_a,i_beta_a\n";
    let ok = "0,1e-4,0,0,0,0\n";
    let cases: &[(String, usize, usize)] = &[
        (String::new(), 1, 1),
        (h.to_string(), 2, 1),
        (
            "t_s,dt_s,u_alpha_v,u_beta_v,i_alpha_a\n0,1,0,0,0\n".into(),
            1,
            6,
        ),
        (format!("{h}{ok}0,1e-4,0,x,0,0\n"), 3, 4),
        (format!("{h}{ok}0,1e-4,0,0,0\n"), 3, 6),
        (format!("{h}{ok}0,1e-4,0,0,0,0,7\n"), 3, 7),
        (format!("{h}{ok}0,0,0,0,0,0\n"), 3, 2),
        (format!("{h}{ok}0,-1e-4,0,0,0,0\n"), 3, 2),
        (format!("{h}{ok}0,1e-4,0,0,nan,0\n"), 3, 5),
        (format!("{h}{ok}0,1e-4,0,0,0,inf\n"), 3, 6),
        (format!("{h}{ok}0,1e-4,,0,0,0\n"), 3, 3),
        (
            "t_s,dt_s,u_alpha_v,u_beta_v,i_alpha_a,i_beta_a,theta_ref_rad\n0,1,0,0,0,0,z\n".into(),
            2,
            7,
        ),
        ("t_s,t_s\n".into(), 1, 2),
    ];
    for (text, line, column) in cases {
        match parse_csv(text.as_bytes(), "f.csv", Scaling::Amplitude) {
            Err(ReplayError::Csv {
                line: l,
                column: c,
                ref problem,
                ..
            }) => assert_eq!((l, c), (*line, *column), "{text:?}: {problem}"),
            other => panic!("{text:?}: {other:?}"),
        }
    }
    // Bytes that are not UTF-8, CRLF line ends and a BOM.
    let e = parse_csv(
        b"t_s,dt_s,u_alpha_v,u_beta_v,i_alpha_a,i_beta_a\n0,1,\xff,0,0,0\n",
        "f",
        Scaling::Amplitude,
    );
    assert!(
        matches!(
            e,
            Err(ReplayError::Csv {
                line: 2,
                column: 3,
                ..
            })
        ),
        "{e:?}"
    );
    let crlf = format!(
        "\u{feff}{}\r\n0,1e-4,1,2,3,4\r\n1e-4,1e-4,5,6,7,8\r\n",
        h.trim_end()
    );
    let l = parse_csv(crlf.as_bytes(), "f", Scaling::Amplitude).unwrap_or_else(|e| panic!("{e}"));
    assert_eq!(l.u_prev, [1.0, 2.0]);
    assert_eq!(l.u_ab, vec![[5.0, 6.0], [5.0, 6.0]]);
    assert_eq!(l.i_ab, vec![[3.0, 4.0], [7.0, 8.0]]);
    assert!(l.theta_ref.is_none());
    // Arbitrary bytes: a result or an error, never a panic.
    let mut x: u64 = 1;
    for n in 0..300 {
        let mut b = h.as_bytes().to_vec();
        for _ in 0..n {
            x ^= x << 13;
            x ^= x >> 7;
            x ^= x << 17;
            b.push(b"0123456789,.-e\nnaif\r "[(x % 21) as usize]);
        }
        let _ = parse_csv(&b, "fuzz", Scaling::Power);
    }
}

#[test]
fn motor_toml_is_validated() {
    let good = "rs_ohm = 0.1\nld_h = 2.8e-5\nlq_h = 4.4e-5\npsi_f_wb = 0.0025\npole_pairs = 7\nts_s = 2.2e-4\n";
    let m = parse_motor(good, "m.toml").unwrap_or_else(|e| panic!("{e}"));
    assert_eq!(m.params.pole_pairs, 7);
    let surface = "rs_ohm = 0.1\nls_h = 3e-5\npsi_f_wb = 0.0025\npole_pairs = 7\nts_s = 1e-4\n";
    assert!(parse_motor(surface, "s").is_ok());
    assert_eq!((m.voltage_delay_s, m.inverter_voltage_v), (0.0, 0.0));
    let timed = format!("{good}voltage_delay_s = -1.1e-4\ninverter_voltage_v = 0.3\n");
    let t = parse_motor(&timed, "t").unwrap_or_else(|e| panic!("{e}"));
    assert_eq!((t.voltage_delay_s, t.inverter_voltage_v), (-1.1e-4, 0.3));
    for bad in [
        good.replace("rs_ohm = 0.1", "rs_ohm = -0.1"),
        good.replace("ts_s = 2.2e-4", "ts_s = 0"),
        good.replace("pole_pairs = 7", "pole_pairs = 0"),
        good.replace("lq_h = 4.4e-5\n", ""),
        format!("{good}ls_h = 1e-5\n"),
        format!("{good}colour = 1\n"),
        format!("{good}voltage_delay_s = 5e-4\n"),
        format!("{good}voltage_delay_s = nan\n"),
        format!("{good}inverter_voltage_v = -0.1\n"),
        format!("{good}inverter_voltage_v = 1e3\n"),
        good.replace("psi_f_wb = 0.0025", "psi_f_wb = \"x\""),
        "rs_ohm = [".to_string(),
    ] {
        match parse_motor(&bad, "m.toml") {
            Err(ReplayError::Motor { file, problem }) => {
                assert_eq!(file, "m.toml");
                assert!(!problem.is_empty());
            }
            other => panic!("{bad:?}: {other:?}"),
        }
    }
}

/// Corrupted samples (a real ESC record holds a 670 kV voltage and a 1.4e17 A current): the
/// EKF refuses them (module docs of `ekf_core::observer`, "Implausible input"), each refused
/// row is a skipped cycle whose angle is advanced to its time, and the replay scores as on the
/// clean log.
#[test]
fn corrupted_samples_are_skipped_cycles() {
    let (path, motor, _sc) = simulated();
    let clean = read_log(&path, Scaling::Amplitude).unwrap_or_else(|e| panic!("{e}"));
    let mut bad = clean.clone();
    let n = bad.len();
    let (k_u, k_i) = (n / 2, n / 2 + 300);
    bad.u_ab[k_u - 1] = [6.7e5, 7.6];
    bad.i_ab[k_i] = [1.4e17, -2.0];
    let r0 = replay(&clean, &motor, "clean").unwrap_or_else(|e| panic!("{e}"));
    let r = replay(&bad, &motor, "bad").unwrap_or_else(|e| panic!("{e}"));
    let rejected: Vec<usize> = (0..n)
        .filter(|&k| r.ekf.status[k] == pmsm_sim::analysis::replay::ReplayStatus::Rejected)
        .collect();
    assert_eq!(rejected, vec![k_u, k_i]);
    for &k in &rejected {
        let expected = ekf_core::wrap_angle(r.ekf.theta[k - 1] + r.ekf.omega[k - 1] * bad.dt_s[k]);
        assert!(ekf_core::wrap_angle(r.ekf.theta[k] - expected).abs() < 1e-9);
    }
    let (s0, s) = (
        r0.report.ekf.unwrap_or_else(|| panic!("scored")),
        r.report.ekf.unwrap_or_else(|| panic!("scored")),
    );
    println!(
        "clean {:.3} deg RMS, with the corrupted samples {:.3}",
        s0.rms_deg, s.rms_deg
    );
    assert!(s.rms_deg < s0.rms_deg * 1.05 + 0.01, "{s:?} {s0:?}");
    assert_eq!(s.tracking_while_lost, 0);
}
