//! Telemetry of the B-G431B-ESC1 firmware (crate `board-b-g431b-esc1`) into the project's
//! MCAP log: `pmsm-sim telemetry CAPTURE --out run.mcap`.
//!
//! The capture is the raw byte stream of the board's UART (e.g. `cat /dev/ttyACM0 >
//! capture.bin` after `telemetry 20`): frames mixed with the command replies' text. Each
//! valid frame ([`board_b_g431b_esc1::telemetry::scan`]: sync, known kind and length, CRC) of
//! kind period becomes one `/pmsm_sim/period` message of the simulator's record ([`Sample`],
//! the one schema), at `t = k Ts` with `Ts` from the stream's meta frame. What a bench cannot
//! know is NaN: the true state (`truth.*`), the errors against it and the observer's
//! covariance; the observer sample (`observer`, `controller_observer`) is foc's estimate as
//! the board sent it. The state names are the simulator's (`idle`, `align`, `open_loop`,
//! `handover`, `closed_loop`, `fault`) plus `identify` and `calibrate`; the fault names are
//! the simulator's for foc's faults and `board_*` for the board's. The scenario channel
//! carries the `default` preset renamed `b-g431b-esc1` with the stream's `Ts` (it does not
//! describe the bench).

use std::path::Path;

use board_b_g431b_esc1::state::{AnyFault, DriveState, fault_from_code, state_from_code};
use board_b_g431b_esc1::telemetry::{
    FLAG_OBSERVER_OK, FLAG_PWM, FLAG_TRACKING, Frame, PeriodFrame, Scan, SkipReason, scan,
};
use foc::State;

use crate::SimError;
use crate::drive::foc_adapter::{fault_name, state_name};
use crate::output::SampleSink;
use crate::output::mcap::{LogOptions, McapLog};
use crate::output::record::{
    ControlRecord, ControllerEstimate, ControllerTelemetry, InverterRecord, Measured,
    ObserverSample, Sample, Truth,
};
use crate::scenario::Scenario;

/// What a conversion found.
#[derive(Clone, Copy, Debug, Default, PartialEq)]
pub struct TelemetryStats {
    /// Period frames written.
    pub periods: usize,
    /// Meta frames seen.
    pub meta_frames: usize,
    /// Frames dropped for a bad CRC.
    pub crc_errors: usize,
    /// Bytes that were not frames (command replies, noise, torn frames).
    pub other_bytes: usize,
    /// The PWM period used, s.
    pub ts_s: f64,
}

impl std::fmt::Display for TelemetryStats {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        write!(
            f,
            "{} periods (Ts {} s), {} meta frames, {} CRC errors, {} other bytes",
            self.periods, self.ts_s, self.meta_frames, self.crc_errors, self.other_bytes
        )
    }
}

/// [`telemetry_to_mcap`] of the file `capture`.
pub fn convert_file(
    capture: &Path,
    out: &Path,
    ts_s: Option<f64>,
    log_options: LogOptions,
) -> Result<TelemetryStats, SimError> {
    let bytes = std::fs::read(capture).map_err(|e| SimError::Output {
        path: capture.display().to_string(),
        message: format!("cannot read the capture: {e}"),
    })?;
    telemetry_to_mcap(&bytes, out, ts_s, log_options)
}

/// Converts a capture into an MCAP log at `out`. `ts_s`: the PWM period when the capture
/// has no meta frame (refused without either; a meta frame wins). `log_options`: how the
/// log is written (its time stamps' origin; the capture has no clock of its own, so the CLI
/// stamps the time of the conversion, or 0).
pub fn telemetry_to_mcap(
    capture: &[u8],
    out: &Path,
    ts_s: Option<f64>,
    log_options: LogOptions,
) -> Result<TelemetryStats, SimError> {
    let err = |message: String| SimError::Output {
        path: out.display().to_string(),
        message,
    };
    let frames = frames(capture);
    let mut stats = frames.1;
    let meta_ts = frames.0.iter().find_map(|f| match f {
        Frame::Meta(m) if m.ts_s.is_finite() && m.ts_s > 0.0 => Some(f64::from(m.ts_s)),
        _ => None,
    });
    let ts = meta_ts
        .or(ts_s)
        .filter(|t| t.is_finite() && *t > 0.0)
        .ok_or_else(|| {
            err(
                "no meta frame in the capture and no --ts-s given: the PWM period is unknown"
                    .into(),
            )
        })?;
    stats.ts_s = ts;
    let mut scenario = Scenario::preset("default")?;
    scenario.name = "b-g431b-esc1".into();
    scenario.description = "telemetry of the B-G431B-ESC1 firmware (not a simulation)".into();
    scenario.inverter.ts_s = ts;
    let mut log = McapLog::create(out, &scenario, log_options)?;
    let mut last_k = None;
    for f in &frames.0 {
        if let Frame::Period(p) = f {
            // The tick counter restarts at a reset; the log's time keeps going forward.
            if last_k.is_some_and(|k| u64::from(p.tick) <= k) {
                log.event(
                    last_k.unwrap_or(0) as f64 * ts,
                    "warning",
                    "tick counter went back (board reset?)",
                )?;
            }
            last_k = Some(u64::from(p.tick));
            log.record(&period_sample(p, ts)).map_err(err)?;
            stats.periods += 1;
        }
    }
    log.finish(None)?;
    Ok(stats)
}

/// Every valid frame of a capture, and the counts of what was skipped.
pub fn frames(capture: &[u8]) -> (Vec<Frame>, TelemetryStats) {
    let (mut out, mut stats, mut pos) = (Vec::new(), TelemetryStats::default(), 0);
    while pos < capture.len() {
        match scan(&capture[pos..]) {
            Scan::Frame(f, n) => {
                if matches!(f, Frame::Meta(_)) {
                    stats.meta_frames += 1;
                }
                out.push(f);
                pos += n;
            }
            Scan::Skip(n, why) => {
                stats.crc_errors += usize::from(why == SkipReason::BadCrc);
                stats.other_bytes += n;
                pos += n;
            }
            Scan::NeedMore => {
                stats.other_bytes += capture.len() - pos;
                break;
            }
        }
    }
    (out, stats)
}

fn state_str(code: u8) -> &'static str {
    match state_from_code(code) {
        Some(DriveState::Foc(s)) => state_name(s),
        Some(DriveState::Identify) => "identify",
        Some(DriveState::Calibrate) => "calibrate",
        None => "unknown",
    }
}

fn fault_str(code: u8) -> Option<&'static str> {
    match fault_from_code(code) {
        Some(AnyFault::Foc(f)) => Some(fault_name(f)),
        Some(AnyFault::Board(b)) => Some(b.as_str()),
        None if code == 0 => None,
        None => Some("unknown"),
    }
}

/// The simulator's record of one period frame (module docs: NaN where a bench cannot know).
pub fn period_sample(p: &PeriodFrame, ts_s: f64) -> Sample {
    let f = f64::from;
    let nan = f64::NAN;
    let pair = |x: [f32; 2]| [f(x[0]), f(x[1])];
    let [a, b, c] = p.i_abc_a.map(f);
    let i_ab = [a, (a + 2.0 * b) / 3f64.sqrt()];
    let pwm = p.flags & FLAG_PWM != 0;
    let tracking = p.flags & FLAG_TRACKING != 0;
    let rpm = f(p.speed_ref_mech_rad_s) * 60.0 / std::f64::consts::TAU;
    let estimate = ControllerEstimate {
        theta_e_rad: f(p.est_theta_rad),
        omega_e_rad_s: f(p.est_omega_rad_s),
        p_diag: [nan; 4],
        nis: nan,
        tracking,
        psi_f_wb: f(p.psi_f_wb),
        psi_f_sigma_wb: nan,
        rs_ohm: f(p.rs_ohm),
        rs_sigma_ohm: nan,
        winding_temperature_c: nan,
    };
    let truth = Truth {
        theta_e_rad: nan,
        omega_e_rad_s: nan,
        speed_rpm: nan,
        i_ab_a: [nan; 2],
        i_dq_a: [nan; 2],
        torque_nm: nan,
        load_torque_nm: nan,
        psi_f_wb: nan,
        rs_ohm: nan,
    };
    let observer = ObserverSample::from_controller(&estimate, &truth);
    let closed = matches!(
        state_from_code(p.state),
        Some(DriveState::Foc(State::Handover | State::ClosedLoop))
    );
    Sample {
        k: u64::from(p.tick),
        t_s: f64::from(p.tick) * ts_s,
        truth,
        measured: Measured {
            i_abc_a: [a, b, c],
            i_ab_a: i_ab,
            u_dc_v: f(p.u_dc_v),
        },
        observer,
        seed_filter: None,
        controller_observer: Some(observer),
        control: ControlRecord {
            speed_ref_rpm: rpm,
            duties: p.duties.map(f),
            telemetry: ControllerTelemetry {
                state: state_str(p.state),
                theta_e_rad: f(p.theta_rad),
                omega_e_rad_s: f(p.omega_rad_s),
                i_dq_a: pair(p.i_dq_a),
                i_dq_ref_a: pair(p.i_dq_ref_a),
                u_dq_ref_v: pair(p.u_dq_v),
                u_ab_ref_v: pair(p.u_ab_v),
                voltage_limited: false,
                closed_loop: closed && p.flags & FLAG_OBSERVER_OK != 0,
                speed_ref_rpm: pwm.then_some(rpm),
                fault: fault_str(p.fault),
                estimate: Some(estimate),
            },
        },
        inverter: InverterRecord {
            pwm_enabled: pwm,
            duties: p.duties.map(f),
            u_ab_v: if pwm { pair(p.u_ab_v) } else { [0.0; 2] },
            u_ab_commanded_v: if pwm { pair(p.u_ab_v) } else { [0.0; 2] },
            u_dc_v: f(p.u_dc_v),
        },
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::output::mcap::proto::decode_to_json;
    use board_b_g431b_esc1::state::{BoardFault, fault_code, state_code};
    use board_b_g431b_esc1::telemetry::{FLAG_SAMPLE_OK, LAYOUT_VERSION, MAX_FRAME, MetaFrame};

    fn period(tick: u32) -> PeriodFrame {
        PeriodFrame {
            tick,
            state: state_code(DriveState::Foc(State::ClosedLoop)),
            fault: 0,
            flags: FLAG_PWM | FLAG_OBSERVER_OK | FLAG_SAMPLE_OK | FLAG_TRACKING,
            i_abc_a: [1.0, -0.25, -0.75],
            u_dc_v: 12.0,
            duties: [0.6, 0.45, 0.4],
            i_dq_a: [0.0, 1.2],
            i_dq_ref_a: [0.0, 1.25],
            u_dq_v: [-0.3, 2.1],
            u_ab_v: [1.5, -1.2],
            theta_rad: 0.5,
            omega_rad_s: 600.0,
            speed_ref_mech_rad_s: 150.0,
            est_theta_rad: 0.49,
            est_omega_rad_s: 601.0,
            psi_f_wb: 0.004,
            rs_ohm: 0.21,
            temperature_c: 35.0,
        }
    }

    fn capture() -> Vec<u8> {
        let mut buf = [0u8; MAX_FRAME];
        let mut v = b"ok telemetry\n".to_vec();
        let meta = MetaFrame {
            ts_s: 50e-6,
            every: 20,
            pole_pairs: 7,
            layout: LAYOUT_VERSION,
            u_dc_nominal_v: 12.0,
        };
        let n = meta.encode(&mut buf);
        v.extend_from_slice(&buf[..n]);
        for k in 0..50 {
            let mut p = period(1000 + 20 * k);
            if k == 49 {
                p.state = state_code(DriveState::Foc(State::Fault));
                p.fault = fault_code(AnyFault::Board(BoardFault::Break));
                p.flags = 0;
            }
            let n = p.encode(&mut buf);
            if k == 10 {
                buf[20] ^= 0x40; // a corrupted frame
            }
            v.extend_from_slice(&buf[..n]);
        }
        v.extend_from_slice(b"err unknown command\n");
        v
    }

    #[test]
    fn a_capture_becomes_an_mcap_of_the_period_record() {
        let dir = std::env::temp_dir().join(format!("board-telemetry-{}", std::process::id()));
        std::fs::create_dir_all(&dir).unwrap();
        let out = dir.join("run.mcap");
        let stats = telemetry_to_mcap(&capture(), &out, None, LogOptions::default()).unwrap();
        assert_eq!(stats.periods, 49);
        assert_eq!(stats.crc_errors, 1);
        assert_eq!(stats.meta_frames, 1);
        assert_eq!(stats.ts_s, f64::from(50e-6_f32));
        let bytes = std::fs::read(&out).unwrap();
        let mut periods = Vec::new();
        for m in mcap::MessageStream::new(&bytes).unwrap() {
            let m = m.unwrap();
            if m.channel.topic == crate::output::mcap::TOPIC_PERIOD {
                periods.push(decode_to_json("Period", &m.data).unwrap());
            }
        }
        assert_eq!(periods.len(), 49);
        let first = &periods[0];
        assert_eq!(first["k"].as_u64(), Some(1000));
        assert!((first["t_s"].as_f64().unwrap() - 0.05).abs() < 1e-6);
        assert_eq!(first["control"]["telemetry"]["state"], "closed_loop");
        assert_eq!(first["control"]["telemetry"]["closed_loop"], true);
        let rpm = first["control"]["speed_ref_rpm"].as_f64().unwrap();
        assert!((rpm - 150.0 * 60.0 / std::f64::consts::TAU).abs() < 1e-3);
        let i_ab = &first["measured"]["i_ab_a"];
        assert!((i_ab[0].as_f64().unwrap() - 1.0).abs() < 0.01);
        assert!((first["observer"]["psi_f_wb"].as_f64().unwrap() - 0.004).abs() < 1e-6);
        let last = &periods[48];
        assert_eq!(last["control"]["telemetry"]["state"], "fault");
        assert_eq!(last["control"]["telemetry"]["fault"], "board_break_input");
        assert_eq!(last["inverter"]["pwm_enabled"], false);
        std::fs::remove_dir_all(&dir).ok();
    }

    #[test]
    fn without_a_period_the_capture_is_refused_by_name() {
        let out = std::env::temp_dir().join("board-telemetry-refused.mcap");
        let mut buf = [0u8; MAX_FRAME];
        let n = period(1).encode(&mut buf);
        let e = telemetry_to_mcap(&buf[..n], &out, None, LogOptions::default()).unwrap_err();
        assert!(e.to_string().contains("--ts-s"), "{e}");
        assert!(telemetry_to_mcap(&buf[..n], &out, Some(-1.0), LogOptions::default()).is_err());
        let stats = telemetry_to_mcap(&buf[..n], &out, Some(1e-4), LogOptions::default()).unwrap();
        assert_eq!(stats.periods, 1);
        std::fs::remove_file(&out).ok();
    }

    #[test]
    fn garbage_never_panics() {
        let mut x: u32 = 7;
        let junk: Vec<u8> = (0..20_000)
            .map(|_| {
                x = x.wrapping_mul(1_103_515_245).wrapping_add(12345);
                if x.is_multiple_of(5) {
                    0xA5
                } else {
                    (x >> 16) as u8
                }
            })
            .collect();
        let (frames, stats) = frames(&junk);
        assert!(frames.len() + stats.other_bytes > 0);
    }
}
