//! The offline Q/R tuner on simulated runs with a known current-sensor noise.
//!
//! A short servo run (foc in sensored mode, ideal bridge, speed ramp 1000 -> 1500 rpm and a
//! load step, 0.4 s at 10 kHz) with 80 mA of noise per phase channel: the alpha-beta noise is
//! then `R = s^2 [[1, 1/sqrt 3], [1/sqrt 3, 5/3]]` (sigma 80 / 103 mA), well above the
//! observer's default (41 mA), so the default filter's NIS is far above 2.

use pmsm_sim::analysis::tune::{
    AngleTruth, RShape, TuneError, TuneOptions, sensor_r_ab, tune_qr, tune_qr_mcap,
};
use pmsm_sim::output::mcap::{LogEncoding, LogOptions, McapLog};
use pmsm_sim::scenario::{ControllerKind, Scenario};
use pmsm_sim::sim::{self, RunOptions, SampleSink};

const NOISE_A: f64 = 0.08;

fn scenario() -> Scenario {
    let mut sc = Scenario::preset("servo-ideal").unwrap_or_else(|e| panic!("{e}"));
    sc.name = "tune-test".into();
    sc.duration_s = 0.4;
    sc.seed = 11;
    sc.sensors.current_noise_std_a = NOISE_A;
    sc.controller.kind = ControllerKind::FocSensored;
    sc.controller.foc = None;
    sc.observer.reference_filter = false;
    sc.initial.speed_rpm = 1000.0;
    sc.initial.theta_e_rad = 0.3;
    let toml = format!(
        "{}\n",
        r#"
interpolation = "linear"
points = [[0.0, 1000.0], [0.1, 1000.0], [0.3, 1500.0]]
"#
    );
    sc.speed_ref_rpm = toml::from_str(&toml).unwrap_or_else(|e| panic!("{e}"));
    sc.load = toml::from_str::<toml::Table>(
        "[[load]]\nkind = \"step\"\ntime_s = 0.25\nbefore_nm = 0.0\nafter_nm = 1.0\n",
    )
    .ok()
    .and_then(|t| t.get("load").cloned())
    .and_then(|v| v.try_into().ok())
    .unwrap_or_else(|| panic!("load"));
    sc.validate().unwrap_or_else(|e| panic!("{e}"));
    sc
}

struct Rec {
    u: Vec<[f64; 2]>,
    i: Vec<[f64; 2]>,
    th: Vec<f64>,
    w: Vec<f64>,
}

fn record(sc: &Scenario) -> Rec {
    let out = sim::run(sc).unwrap_or_else(|e| panic!("{e}"));
    let s = &out.trace.samples;
    Rec {
        // The observer's voltage (the simulator's rule, as `LoggedRun::read`): with the PWM on,
        // the voltage foc expects of the duties now applied (its last tick's with the delay,
        // this tick's without; the first period with the delay has none: the commanded
        // voltage); zero with the PWM off.
        u: s.iter()
            .enumerate()
            .map(
                |(k, x)| match (x.inverter.pwm_enabled, sc.inverter.delay, k) {
                    (false, _, _) => [0.0; 2],
                    (true, false, _) => x.control.telemetry.u_ab_ref_v,
                    (true, true, 0) => x.inverter.u_ab_commanded_v,
                    (true, true, _) => s[k - 1].control.telemetry.u_ab_ref_v,
                },
            )
            .collect(),
        i: s.iter().map(|x| x.measured.i_ab_a).collect(),
        th: s.iter().map(|x| x.truth.theta_e_rad).collect(),
        w: s.iter().map(|x| x.truth.omega_e_rad_s).collect(),
    }
}

#[test]
fn tuned_r_matches_the_sensor_and_nis_is_two() {
    let sc = scenario();
    let rec = record(&sc);
    let truth = AngleTruth {
        theta_rad: &rec.th,
        omega_rad_s: Some(&rec.w),
    };
    let opts = TuneOptions {
        skip: Some(500),
        ..TuneOptions::default()
    };
    let motor = sc.observer_params();
    let rep = tune_qr(&motor, sc.ts_s(), &rec.u, &rec.i, Some(truth), &opts)
        .unwrap_or_else(|e| panic!("{e}"));
    let true_r = sensor_r_ab(&sc.sensors);
    let (b, a) = (&rep.before, &rep.after);
    let (ea, eb) = (
        b.angle_error.unwrap_or_else(|| panic!("no angle error")),
        a.angle_error.unwrap_or_else(|| panic!("no angle error")),
    );
    println!(
        "true R {true_r:?}\nproposed R {:?}\nQ diag {:?}",
        rep.r,
        [rep.q[0][0], rep.q[1][1], rep.q[2][2], rep.q[3][3]]
    );
    println!(
        "tuned {:?}, at bound {:?}, {} evaluations, converged {}",
        rep.tuned, rep.at_bound, rep.evaluations, rep.converged
    );
    println!(
        "mean NIS {:.3} -> {:.3}; L {:.1} -> {:.1}",
        b.mean_nis, a.mean_nis, b.log_likelihood, a.log_likelihood
    );
    println!(
        "angle error rms {:.4} -> {:.4} deg, mean {:.4} -> {:.4}, max {:.4} -> {:.4}",
        ea.rms_deg, eb.rms_deg, ea.mean_deg, eb.mean_deg, ea.max_abs_deg, eb.max_abs_deg
    );
    assert!(rep.converged);
    assert!(a.log_likelihood > b.log_likelihood);
    // R within 10 % of the sensor's (each variance), correlation within 0.05 of 1/sqrt 5.
    for d in [0, 1] {
        let rel = rep.r[d][d] / true_r[d][d] - 1.0;
        assert!(
            rel.abs() < 0.10,
            "R[{d}][{d}] {} vs {} ({rel:+.3})",
            rep.r[d][d],
            true_r[d][d]
        );
    }
    let rho = rep.r[0][1] / (rep.r[0][0] * rep.r[1][1]).sqrt();
    assert!((rho - 5f64.sqrt().recip()).abs() < 0.05, "rho {rho}");
    // The default is inconsistent here (R too small); the tuned filter is not.
    assert!(b.mean_nis > 3.0, "{}", b.mean_nis);
    assert!((a.mean_nis - 2.0).abs() < 0.15, "{}", a.mean_nis);
    // The angle is not worse than with the default by more than 0.05 deg rms.
    assert!(
        eb.rms_deg < ea.rms_deg + 0.05,
        "{} vs {}",
        eb.rms_deg,
        ea.rms_deg
    );
}

#[test]
fn isotropic_r_fits_the_mean_variance() {
    let sc = scenario().with_duration(0.25);
    let rec = record(&sc);
    let opts = TuneOptions {
        skip: Some(500),
        r_shape: RShape::Isotropic,
        ..TuneOptions::default()
    };
    let rep = tune_qr(
        &sc.observer_params(),
        sc.ts_s(),
        &rec.u,
        &rec.i,
        None,
        &opts,
    )
    .unwrap_or_else(|e| panic!("{e}"));
    let true_r = sensor_r_ab(&sc.sensors);
    let mean_var = 0.5 * (true_r[0][0] + true_r[1][1]);
    println!(
        "isotropic R {:?} vs mean variance {mean_var}, NIS {}",
        rep.r, rep.after.mean_nis
    );
    assert_eq!(rep.r[0][1], 0.0);
    assert_eq!(rep.r[0][0], rep.r[1][1]);
    assert!((rep.r[0][0] / mean_var - 1.0).abs() < 0.15, "{:?}", rep.r);
    assert!(rep.before.angle_error.is_none());
}

/// The MCAP path (protobuf and JSON period channels) reads the same record and gives the
/// same proposal as the arrays; the replay of the default filter reproduces the log.
#[test]
fn mcap_log_gives_the_same_result_as_the_arrays() {
    let sc = scenario().with_duration(0.15);
    let dir = std::env::temp_dir().join(format!("pmsm-sim-tune-{}", std::process::id()));
    std::fs::create_dir_all(&dir).unwrap_or_else(|e| panic!("{e}"));
    let opts = TuneOptions {
        skip: Some(300),
        max_evaluations: 150,
        ..TuneOptions::default()
    };
    let rec = record(&sc);
    let arrays = tune_qr(
        &sc.observer_params(),
        sc.ts_s(),
        &rec.u,
        &rec.i,
        Some(AngleTruth {
            theta_rad: &rec.th,
            omega_rad_s: Some(&rec.w),
        }),
        &TuneOptions {
            min_speed_rad_s: Some(0.05 * sc.rated_speed_e_rad_s()),
            ..opts
        },
    )
    .unwrap_or_else(|e| panic!("{e}"));
    for encoding in [LogEncoding::Protobuf, LogEncoding::Json] {
        let path = dir.join(format!("{encoding:?}.mcap"));
        let mut log = McapLog::create(
            &path,
            &sc,
            LogOptions {
                encoding,
                // Stamped with the wall clock, as the CLI writes it: the reader takes the
                // periods' own k and t_s, so the result is that of the arrays all the same.
                start_time_unix_ns: pmsm_sim::output::mcap::wall_clock_unix_ns(),
                ..LogOptions::default()
            },
        )
        .unwrap_or_else(|e| panic!("{e}"));
        let sinks: Vec<&mut dyn SampleSink> = vec![&mut log];
        let out = sim::run_with(
            &sc,
            RunOptions {
                sinks,
                ..RunOptions::default()
            },
        )
        .unwrap_or_else(|e| panic!("{e}"));
        log.finish(Some(&out.metrics))
            .unwrap_or_else(|e| panic!("{e}"));
        let m = tune_qr_mcap(&path, &opts).unwrap_or_else(|e| panic!("{e}"));
        assert!(m.replay_matches_log, "{encoding:?}");
        if encoding == LogEncoding::Protobuf {
            // Bit-exact doubles: the replay and the tuning are those of the arrays.
            assert_eq!(m.replay_max_diff_rad, 0.0);
            assert_eq!(m.report, arrays);
        } else {
            // JSON numbers may read back one unit in the last place off.
            println!("JSON replay difference {:e} rad", m.replay_max_diff_rad);
            for d in [0, 1] {
                let rel = m.report.r[d][d] / arrays.r[d][d] - 1.0;
                assert!(rel.abs() < 1e-3, "{rel}");
            }
        }
        assert_eq!(m.periods, rec.i.len());
        assert_eq!(m.scenario, "tune-test");
        assert_eq!(m.sensor_r, sensor_r_ab(&sc.sensors));
    }
    // The command line on the protobuf log: JSON report, text report, errors.
    let exe = env!("CARGO_BIN_EXE_pmsm-sim");
    let pb = dir.join("Protobuf.mcap");
    let out = std::process::Command::new(exe)
        .args(["tune", "--json", "--skip-s", "0.03", "--max-evals", "150"])
        .arg(&pb)
        .output()
        .unwrap_or_else(|e| panic!("{e}"));
    assert!(
        out.status.success(),
        "{}",
        String::from_utf8_lossy(&out.stderr)
    );
    let v: serde_json::Value =
        serde_json::from_slice(&out.stdout).unwrap_or_else(|e| panic!("{e}"));
    assert_eq!(v["replay_matches_log"], true);
    assert_eq!(v["report"]["skip"], 300);
    let r00 = v["report"]["r"][0][0].as_f64().unwrap_or(f64::NAN);
    assert_eq!(r00, arrays.r[0][0]);
    let out = std::process::Command::new(exe)
        .args(["tune", "--skip-s", "0.03", "--max-evals", "150"])
        .arg(&pb)
        .output()
        .unwrap_or_else(|e| panic!("{e}"));
    let text = String::from_utf8_lossy(&out.stdout);
    assert!(out.status.success());
    for needle in [
        "mean NIS (2 expected)",
        "angle error rms",
        "[observer_noise]",
        "r = [[",
    ] {
        assert!(text.contains(needle), "{needle} not in\n{text}");
    }
    let out = std::process::Command::new(exe)
        .args(["tune", "--skip-s=-1"])
        .arg(&pb)
        .output()
        .unwrap_or_else(|e| panic!("{e}"));
    assert!(!out.status.success());
    assert!(String::from_utf8_lossy(&out.stderr).contains("--skip-s"));
    // A file that is not a log, and one that does not exist: errors naming the file.
    let junk = dir.join("junk.mcap");
    std::fs::write(&junk, b"not an mcap file").unwrap_or_else(|e| panic!("{e}"));
    for p in [junk.clone(), dir.join("missing.mcap")] {
        match tune_qr_mcap(&p, &opts) {
            Err(TuneError::Log { path, .. }) => assert!(path.ends_with(".mcap")),
            other => panic!("{other:?}"),
        }
    }
    let _ = std::fs::remove_dir_all(&dir);
}

#[test]
fn bad_input_is_refused_with_a_reason() {
    let sc = scenario();
    let m = sc.observer_params();
    let z = vec![[0.0; 2]; 1000];
    let opts = TuneOptions::default();
    assert!(matches!(
        tune_qr(&m, 1e-4, &z[..999], &z, None, &opts),
        Err(TuneError::LengthMismatch { u: 999, i: 1000 })
    ));
    assert!(matches!(
        tune_qr(&m, 1e-4, &z[..100], &z[..100], None, &opts),
        Err(TuneError::TooShort { .. })
    ));
    assert!(matches!(
        tune_qr(&m, 0.0, &z, &z, None, &opts),
        Err(TuneError::Config(_))
    ));
    let th = vec![0.0; 10];
    assert!(matches!(
        tune_qr(
            &m,
            1e-4,
            &z,
            &z,
            Some(AngleTruth {
                theta_rad: &th,
                omega_rad_s: None
            }),
            &opts
        ),
        Err(TuneError::TruthLength { .. })
    ));
    for bad in [
        TuneOptions {
            max_evaluations: 0,
            ..opts
        },
        TuneOptions {
            bound_decades: f64::NAN,
            ..opts
        },
        TuneOptions {
            x0: [0.0, f64::INFINITY, 0.0, 0.0],
            ..opts
        },
        TuneOptions {
            min_speed_rad_s: Some(-1.0),
            ..opts
        },
    ] {
        assert!(matches!(
            tune_qr(&m, 1e-4, &z, &z, None, &bad),
            Err(TuneError::Option { .. })
        ));
    }
    let mut start = opts.start;
    start.sigma_w = 0.0;
    assert!(matches!(
        tune_qr(&m, 1e-4, &z, &z, None, &TuneOptions { start, ..opts }),
        Err(TuneError::Option { .. })
    ));
    // Non-finite rows are rejected by the filter, counted, and not scored.
    let mut i = z.clone();
    i[600] = [f64::NAN, 0.0];
    let rep = tune_qr(
        &m,
        1e-4,
        &z,
        &i,
        None,
        &TuneOptions {
            max_evaluations: 30,
            ..opts
        },
    )
    .unwrap_or_else(|e| panic!("{e}"));
    assert_eq!(rep.samples_rejected, 1);
    assert!(rep.after.log_likelihood.is_finite());
}
