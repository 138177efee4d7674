//! Field weakening in the simulator's closed loop: the presets
//! `industrial-ipm-fw`, `traction-ipm-fw` (to twice the base speed) and `servo-fw` (1.5 x) run
//! `foc` sensorless (align, I/f, hand-over to its f32 EKF) with MTPA and field weakening on
//! the full plant, inverter (delay, dead time) and current sensing (noise, 12-bit ADC), against
//! a constant-power load at rated power (rated torque x base speed / speed above the base
//! speed).
//!
//! Asserted per motor:
//! - the speed reaches the target and holds it: over the last [`HOLD_S`] the mean within
//!   0.2 % and every sample within 1 % of the target;
//! - the current magnitude (the plant's) stays within `current_limit_a` plus
//!   [`RIPPLE_MARGIN`] (5 %: PWM-period current ripple, noise and the loop's overshoot on
//!   what the controller limits, its reference);
//! - the voltage foc commands stays within `max_modulation u_dc / sqrt 3` (and the voltage the
//!   bridge actually applied, dead time included, within 2 % of it);
//! - foc's observer converged throughout: from the hand-over on, its angle error stays
//!   below [`MAX_ANGLE_ERROR_DEG`], foc never leaves closed loop (no fall-back to I/f) and no
//!   fault trips;
//! - field weakening did the work: at the top speed the d current is negative, beyond the
//!   MTPA value of the load's torque.
//!
//! `cargo test -p pmsm-sim --test field_weakening -- --nocapture` prints the table.

use pmsm_sim::output::record::Sample;
use pmsm_sim::scenario::{RPM_PER_RAD_S, Scenario};
use pmsm_sim::sim::{RunOptions, SampleSink, run_with};

/// Allowed current above the limit: ripple and noise on the plant's current, fraction.
const RIPPLE_MARGIN: f64 = 0.05;
/// Largest angle error of foc's observer after the hand-over, deg el.
const MAX_ANGLE_ERROR_DEG: f64 = 2.0;
/// The window at the end of each run over which the speed must hold, s.
const HOLD_S: f64 = 0.4;

/// One run's figures, collected period by period.
#[derive(Debug, Default)]
struct Fw {
    ts_s: f64,
    end_s: f64,
    /// Voltage limit of the modulation per volt of bus (`max_modulation / sqrt 3`).
    u_lim_per_v: f64,
    target_rpm: f64,
    handover_s: Option<f64>,
    left_closed_loop_s: Option<f64>,
    fault: Option<&'static str>,
    max_i_a: f64,
    max_u_cmd_ratio: f64,
    max_u_applied_ratio: f64,
    err_sq: f64,
    err_n: u64,
    max_err_deg: f64,
    hold_n: u64,
    hold_speed_sum: f64,
    hold_max_dev_rpm: f64,
    hold_id_sum: f64,
    hold_iq_sum: f64,
    hold_u_sum: f64,
    hold_at_limit: u64,
}

impl SampleSink for Fw {
    fn record(&mut self, s: &Sample) -> Result<(), String> {
        let t = &s.control.telemetry;
        if self.fault.is_none() {
            self.fault = t.fault;
        }
        let closed = matches!(t.state, "handover" | "closed_loop");
        if closed && self.handover_s.is_none() {
            self.handover_s = Some(s.t_s);
        }
        if self.handover_s.is_some() && !closed && self.left_closed_loop_s.is_none() {
            self.left_closed_loop_s = Some(s.t_s);
        }
        let [i_d, i_q] = s.truth.i_dq_a;
        self.max_i_a = self.max_i_a.max(i_d.hypot(i_q));
        let u_lim = self.u_lim_per_v * s.measured.u_dc_v;
        let u_cmd = t.u_dq_ref_v[0].hypot(t.u_dq_ref_v[1]) / u_lim;
        self.max_u_cmd_ratio = self.max_u_cmd_ratio.max(u_cmd);
        let [ua, ub] = s.inverter.u_ab_v;
        self.max_u_applied_ratio = self
            .max_u_applied_ratio
            .max(ua.hypot(ub) / (self.u_lim_per_v * s.inverter.u_dc_v));
        if self.handover_s.is_some()
            && let Some(o) = s.controller_observer
        {
            let e = o.angle_error_deg;
            self.err_sq += e * e;
            self.err_n += 1;
            self.max_err_deg = self.max_err_deg.max(e.abs());
        }
        if s.t_s >= self.end_s - HOLD_S {
            self.hold_n += 1;
            self.hold_speed_sum += s.truth.speed_rpm;
            self.hold_max_dev_rpm = self
                .hold_max_dev_rpm
                .max((s.truth.speed_rpm - self.target_rpm).abs());
            self.hold_id_sum += i_d;
            self.hold_iq_sum += i_q;
            self.hold_u_sum += u_cmd;
            if t.voltage_limited {
                self.hold_at_limit += 1;
            }
        }
        Ok(())
    }
}

struct Row {
    name: &'static str,
    base_rpm: f64,
    ratio: f64,
    limit_a: f64,
    fw: Fw,
    id_mtpa_a: f64,
}

fn run(name: &'static str, base_rpm: f64, ratio: f64) -> Row {
    let sc = Scenario::preset(name).unwrap_or_else(|e| panic!("{e}"));
    let cfg = sc.foc_config().unwrap_or_else(|e| panic!("{e:?}"));
    assert!(cfg.field_weakening.enabled && cfg.mtpa, "{name}");
    let target_rpm = sc.speed_ref_rpm.points.last().map_or(0.0, |&(_, rpm)| rpm);
    assert!((target_rpm / base_rpm - ratio).abs() < 1e-3, "{name}");
    let mut fw = Fw {
        ts_s: sc.ts_s(),
        end_s: sc.duration_s - sc.ts_s(),
        u_lim_per_v: f64::from(cfg.max_modulation) / 3f64.sqrt(),
        target_rpm,
        ..Fw::default()
    };
    let out = run_with(
        &sc,
        RunOptions {
            sinks: vec![&mut fw],
            ..RunOptions::default()
        },
    )
    .unwrap_or_else(|e| panic!("{name}: {e}"));
    assert!(out.end.is_completed(), "{name}: {}", out.end.describe());
    // The MTPA d current of the load's torque at the top speed (rated power there).
    let m = sc.motor;
    let w = target_rpm / RPM_PER_RAD_S;
    let t_load = sc.rated_torque_nm * base_rpm / target_rpm + m.b_nm_s_rad * w;
    let law = foc::Mtpa::with_flux((m.lq_h - m.ld_h) as f32, m.psi_f_wb as f32);
    let i_t = t_load / (1.5 * m.p() * m.psi_f_wb);
    let id_mtpa_a = f64::from(law.currents_for_torque(i_t as f32).d);
    Row {
        name,
        base_rpm,
        ratio,
        limit_a: sc.controller.current_limit_a,
        fw,
        id_mtpa_a,
    }
}

#[test]
fn field_weakening_to_2x_base_on_the_ipms_and_1_5x_on_the_servo_sensorless() {
    // Base speeds at rated torque: the README's reference-motor table
    // (`MotorModel::base_speed_rpm`).
    let rows = [
        run("industrial-ipm-fw", 1719.0, 2.0),
        run("traction-ipm-fw", 3116.0, 2.0),
        run("servo-fw", 2301.0, 1.5),
    ];
    println!(
        "\n| motor | target / base | reached (mean, last {HOLD_S} s) | max speed dev. | max abs(i) / limit | \
         max abs(u) cmd / limit | max abs(u) applied / limit | mean abs(u) / limit at top | at voltage limit | \
         i_d at top (MTPA alone) | i_q at top | hand-over | observer RMS / max angle error after hand-over |"
    );
    println!("|---|---|---|---|---|---|---|---|---|---|---|---|---|");
    for r in &rows {
        let f = &r.fw;
        let n = f.hold_n.max(1) as f64;
        let reached = f.hold_speed_sum / n;
        let rms = (f.err_sq / f.err_n.max(1) as f64).sqrt();
        println!(
            "| {} | {:.0} rpm / {:.0} rpm = {:.2} | {:.1} rpm ({:.3} x base) | {:.1} rpm | {:.2} A / {:.0} A = {:.3} | \
             {:.4} | {:.4} | {:.3} | {:.1} % | {:.2} A ({:.2} A) | {:.2} A | {:.3} s | {:.3} / {:.3} deg |",
            r.name,
            f.target_rpm,
            r.base_rpm,
            r.ratio,
            reached,
            reached / r.base_rpm,
            f.hold_max_dev_rpm,
            f.max_i_a,
            r.limit_a,
            f.max_i_a / r.limit_a,
            f.max_u_cmd_ratio,
            f.max_u_applied_ratio,
            f.hold_u_sum / n,
            100.0 * f.hold_at_limit as f64 / n,
            f.hold_id_sum / n,
            r.id_mtpa_a,
            f.hold_iq_sum / n,
            f.handover_s.unwrap_or(f64::NAN),
            rms,
            f.max_err_deg,
        );
    }
    for r in &rows {
        let f = &r.fw;
        let name = r.name;
        let n = f.hold_n.max(1) as f64;
        assert!(f.hold_n as f64 * f.ts_s > 0.9 * HOLD_S, "{name}");
        assert_eq!(f.fault, None, "{name}");
        assert!(f.handover_s.is_some(), "{name}: never handed over");
        assert_eq!(f.left_closed_loop_s, None, "{name}: left closed loop");
        let reached = f.hold_speed_sum / n;
        assert!(
            (reached - f.target_rpm).abs() < 2e-3 * f.target_rpm,
            "{name}: {reached} rpm"
        );
        assert!(
            f.hold_max_dev_rpm < 0.01 * f.target_rpm,
            "{name}: {} rpm off",
            f.hold_max_dev_rpm
        );
        assert!(
            f.max_i_a <= (1.0 + RIPPLE_MARGIN) * r.limit_a,
            "{name}: {} A",
            f.max_i_a
        );
        assert!(f.max_u_cmd_ratio <= 1.0 + 1e-4, "{name}");
        assert!(f.max_u_applied_ratio <= 1.02, "{name}");
        assert!(
            f.max_err_deg < MAX_ANGLE_ERROR_DEG,
            "{name}: {} deg",
            f.max_err_deg
        );
        // Field weakening at work: more negative d current than MTPA alone would ask.
        let id = f.hold_id_sum / n;
        assert!(id < r.id_mtpa_a - 0.2 * r.limit_a, "{name}: i_d {id} A");
    }
}
