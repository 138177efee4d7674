//! Self-commissioning in the simulator: [`foc::identify`] run on a scenario's motor.
//!
//! [`identify`] builds the scenario's plant (at its initial angle, at rest), inverter
//! (computation delay, dead time, bus ripple), current sensor (noise, gain and offset errors,
//! ADC) and injected faults, ignores its speed and load profiles, and ticks
//! [`foc::Identifier`] until it finishes. The identifier sees only what a drive sees (the
//! sampled currents and bus voltage); the true parameters are used by the plant alone and
//! for the report's comparison. [`IdentifyReport`] holds the true and identified values, the
//! errors in percent and the time of each step; the run can be logged to MCAP and plotted
//! like a normal run ([`IdentifyOptions`]).
//!
//! [`identify_config`] derives the identifier's settings from the scenario, using only what
//! a user knows before the motor is measured: the PWM period and computation delay, the bus
//! voltage, the dead time is **not** used, the current limit (test current half of it), the
//! rated speed (spin at 25 % of it, reached in 0.4 s) and the pole pairs.
//!
//! [`with_identified`] gives the scenario whose controller and observers use the identified
//! parameters (plug and spin).

use std::path::{Path, PathBuf};

use foc::{Identified, IdentifyConfig, IdentifyStep, TickInput};
use glam::DVec2;
use serde::Serialize;

use crate::SimError;
use crate::drive::interface::ControllerTelemetry;
use crate::output::mcap::{LogOptions, McapLog};
use crate::output::plot::PlotSink;
use crate::plant::fault_injection::FaultInjector;
use crate::plant::frames::{inverse_park, park};
use crate::plant::inverter::Inverter;
use crate::plant::sensors::CurrentSensor;
use crate::plant::{Plant, PlantState};
use crate::scenario::{ControllerKind, RPM_PER_RAD_S, Scenario};
use crate::sim::{ControlRecord, InverterRecord, Measured, Sample, SampleSink, Truth};

/// Outputs of [`identify`].
#[derive(Clone, Debug, Default)]
pub struct IdentifyOptions {
    /// Write the MCAP log here.
    pub mcap: Option<PathBuf>,
    /// Draw the SVG plot here.
    pub svg: Option<PathBuf>,
    /// Override the scenario's seed (sensor noise).
    pub seed: Option<u64>,
    /// How the MCAP log is written (its time stamps' origin: `start_time_unix_ns`).
    pub log: LogOptions,
    /// Run the flux-map step after the sequence (module `flux_map`): its grid's largest
    /// current, A (`None`: no flux-map step).
    pub flux_map_a: Option<f64>,
}

/// The motor parameters, true or identified (SI).
#[derive(Clone, Copy, Debug, Default, PartialEq, Serialize)]
pub struct MotorValues {
    /// Stator resistance, ohm.
    pub rs_ohm: f64,
    /// d-axis inductance, H.
    pub ld_h: f64,
    /// q-axis inductance, H.
    pub lq_h: f64,
    /// Flux linkage, Wb.
    #[serde(skip_serializing_if = "Option::is_none")]
    pub psi_f_wb: Option<f64>,
    /// Inertia, kg m^2.
    #[serde(skip_serializing_if = "Option::is_none")]
    pub j_kg_m2: Option<f64>,
    /// Inverter voltage error along the phase-a axis at the test current, V (true:
    /// `4/3 t_dead / Ts u_dc`, the simulator's dead-time model).
    pub inverter_voltage_error_v: f64,
}

/// The time of one step.
#[derive(Clone, Debug, PartialEq, Serialize)]
pub struct StepTime {
    /// Step name ([`IdentifyStep::name`]).
    pub step: &'static str,
    /// Simulated time, s.
    pub time_s: f64,
}

/// The outcome of [`identify`].
#[derive(Clone, Debug, PartialEq, Serialize)]
pub struct IdentifyReport {
    /// Scenario name.
    pub scenario: String,
    /// Sensor seed used.
    pub seed: u64,
    /// Whether the sequence finished with results.
    pub ok: bool,
    /// The failure, if any (`"... (step X, tick N)"`).
    pub error: Option<String>,
    /// The failure's kind (`open_phase`, `rotor_locked`, ...), if any.
    pub error_kind: Option<&'static str>,
    /// The step that failed, if any.
    pub failed_step: Option<&'static str>,
    /// The plant's values.
    pub truth: MotorValues,
    /// The identified values (when `ok`).
    pub identified: Option<MotorValues>,
    /// `100 (identified - true) / true` per quantity (when `ok`).
    pub errors_pct: Option<MotorValues>,
    /// Time of each step that ran.
    pub steps: Vec<StepTime>,
    /// Whole sequence, s.
    pub total_time_s: f64,
    /// Whether the bridge was off at the end (always expected).
    pub pwm_off_at_end: bool,
    /// Peak current magnitude during the sequence, A.
    pub peak_current_a: f64,
    /// The MCAP log written, if any.
    pub mcap: Option<String>,
    /// The SVG written, if any.
    pub svg: Option<String>,
    /// The flux-map step's outcome (with `IdentifyOptions::flux_map_a`).
    #[serde(skip_serializing_if = "Option::is_none")]
    pub flux_map: Option<super::identify_map::FluxMapReport>,
}

/// The identifier's settings for a scenario (module docs).
pub fn identify_config(scenario: &Scenario) -> Result<IdentifyConfig, SimError> {
    let err = |field: &str, problem: String| SimError::Scenario {
        file: scenario.name.clone(),
        field: field.into(),
        problem,
    };
    let c = &scenario.controller;
    let s = c.foc.unwrap_or_default();
    let ts = scenario.ts_s() as f32;
    let u_nom = s.u_dc_nominal_v.unwrap_or(scenario.inverter.u_dc_v) as f32;
    let i_test = (0.5 * c.current_limit_a) as f32;
    let mut cfg = IdentifyConfig::new(ts, u_nom, i_test);
    cfg.delay = if scenario.delay_compensation() {
        foc::ComputationDelay::OnePeriod
    } else {
        foc::ComputationDelay::None
    };
    cfg.over_current_a = s.over_current_a.unwrap_or(2.0 * c.current_limit_a) as f32;
    cfg.u_dc_min_v = 0.5 * u_nom;
    let w_spin = 0.25 * scenario.rated_speed_e_rad_s() as f32;
    cfg = cfg.with_spin(w_spin, w_spin / 0.4);
    cfg.measure_inertia = true;
    cfg.pole_pairs = scenario.motor.pole_pairs;
    cfg.validate().map_err(|e| {
        err(
            "controller",
            format!("identification settings refused: {e}"),
        )
    })?;
    Ok(cfg)
}

fn values(m: &crate::plant::MotorModel, v_err: f64) -> MotorValues {
    MotorValues {
        rs_ohm: m.rs_ohm,
        ld_h: m.ld_h,
        lq_h: m.lq_h,
        psi_f_wb: Some(m.psi_f_wb),
        j_kg_m2: Some(m.j_kg_m2),
        inverter_voltage_error_v: v_err,
    }
}

fn identified_values(r: &Identified) -> MotorValues {
    MotorValues {
        rs_ohm: f64::from(r.rs_ohm),
        ld_h: f64::from(r.ld_h),
        lq_h: f64::from(r.lq_h),
        psi_f_wb: r.psi_f_wb.map(f64::from),
        j_kg_m2: r.j_kg_m2.map(f64::from),
        inverter_voltage_error_v: f64::from(r.inverter_voltage_error_v),
    }
}

fn pct(got: f64, want: f64) -> f64 {
    if want == 0.0 {
        f64::NAN
    } else {
        100.0 * (got - want) / want
    }
}

fn errors(id: &MotorValues, t: &MotorValues) -> MotorValues {
    let opt = |a: Option<f64>, b: Option<f64>| a.zip(b).map(|(a, b)| pct(a, b));
    MotorValues {
        rs_ohm: pct(id.rs_ohm, t.rs_ohm),
        ld_h: pct(id.ld_h, t.ld_h),
        lq_h: pct(id.lq_h, t.lq_h),
        psi_f_wb: opt(id.psi_f_wb, t.psi_f_wb),
        j_kg_m2: opt(id.j_kg_m2, t.j_kg_m2),
        inverter_voltage_error_v: pct(id.inverter_voltage_error_v, t.inverter_voltage_error_v),
    }
}

/// The failure's kind as a short name.
pub fn error_kind(e: &foc::IdentifyError) -> &'static str {
    use foc::IdentifyError as E;
    match e {
        E::Config(_) => "config",
        E::NonFiniteInput => "non_finite_input",
        E::OverCurrent { .. } => "over_current",
        E::BusUnderVoltage { .. } => "bus_under_voltage",
        E::BusOverVoltage { .. } => "bus_over_voltage",
        E::BusTooLow { .. } => "bus_too_low",
        E::NoMotor => "no_motor",
        E::OpenPhase { .. } => "open_phase",
        E::Implausible { .. } => "implausible",
        E::RotorLocked { .. } => "rotor_locked",
        E::LostSync { .. } => "lost_sync",
    }
}

/// Runs the identification on the scenario's simulated drive (module docs).
pub fn identify(scenario: &Scenario, opts: &IdentifyOptions) -> Result<IdentifyReport, SimError> {
    let mut sc = scenario.clone();
    if let Some(seed) = opts.seed {
        sc.seed = seed;
    }
    let cfg = identify_config(&sc)?;
    let mut id = super::identify_map::Runner::new(&cfg, opts.flux_map_a).map_err(|problem| {
        SimError::Scenario {
            file: sc.name.clone(),
            field: "controller".into(),
            problem,
        }
    })?;
    let ts = sc.ts_s();
    let max_ticks = ((f64::from(id.max_duration_s()) + 0.1) / ts).ceil() as u64;
    // The profiles are ignored; the duration only bounds the fault times and the log.
    sc.duration_s = sc.duration_s.max(max_ticks as f64 * ts);
    sc.validate().map_err(|e| SimError::Scenario {
        file: sc.name.clone(),
        field: e.field,
        problem: e.problem,
    })?;
    let motor = sc.motor.clone();
    let mut plant = Plant::new(
        motor.clone(),
        PlantState {
            theta_e_rad: sc.initial.theta_e_rad,
            ..PlantState::default()
        },
    );
    let mut inverter = Inverter::new(sc.inverter);
    let mut sensor = CurrentSensor::new(sc.sensors, sc.seed);
    let mut faults = FaultInjector::new(&sc.faults, &sc.fault_context());
    let mut log = match &opts.mcap {
        Some(p) => Some(McapLog::create(p, &sc, opts.log)?),
        None => None,
    };
    let mut plot = opts
        .svg
        .as_ref()
        .map(|_| PlotSink::new(max_ticks as usize, motor.pole_pairs));
    let p = f64::from(motor.pole_pairs);
    let mut last_pwm = true;
    let mut peak = 0.0f64;
    for k in 0..max_ticks {
        let t = k as f64 * ts;
        if let Err((quantity, value)) = plant.check_finite() {
            return Err(SimError::Stopped {
                t_s: t,
                reason: format!("non-finite {quantity} = {value}"),
            });
        }
        let state = plant.state();
        let i_true = plant.i_abc_a();
        let (meas, u_dc) = match faults.as_mut() {
            Some(f) => (
                f.measure(k, &mut sensor, i_true),
                inverter.u_dc_at(t) * f.bus_factor(k),
            ),
            None => (sensor.measure(i_true), inverter.u_dc_at(t)),
        };
        let [a, b, c] = meas.i_abc_a.map(|x| x as f32);
        let out = id.tick(&TickInput::abc(a, b, c, u_dc as f32));
        let duties = out.duties.map(f64::from);
        let mut applied = inverter.apply(duties, u_dc, u_dc, i_true);
        if !out.pwm_enabled {
            applied.u_ab_v = DVec2::ZERO;
            applied.u_ab_commanded_v = DVec2::ZERO;
        }
        let ab = plant.i_ab_a();
        peak = peak.max(ab[0].hypot(ab[1]));
        if log.is_some() || plot.is_some() {
            let (s, cth) = plant.sin_cos();
            let frame = f64::from(out.frame_angle_rad);
            let (fs, fc) = frame.sin_cos();
            let i_ab = DVec2::new(f64::from(out.i_ab.alpha), f64::from(out.i_ab.beta));
            let frame_rpm = f64::from(out.frame_speed_rad_s) / p * RPM_PER_RAD_S;
            let sample = Sample {
                k,
                t_s: t,
                truth: Truth {
                    theta_e_rad: state.theta_e_rad,
                    omega_e_rad_s: plant.omega_e_rad_s(),
                    speed_rpm: state.omega_mech_rad_s * RPM_PER_RAD_S,
                    i_ab_a: inverse_park(DVec2::new(state.i_d_a, state.i_q_a), DVec2::new(cth, s))
                        .to_array(),
                    i_dq_a: [state.i_d_a, state.i_q_a],
                    torque_nm: plant.torque_nm(),
                    load_torque_nm: 0.0,
                    psi_f_wb: plant.motor().psi_f_wb,
                    rs_ohm: plant.motor().rs_ohm,
                },
                measured: Measured {
                    i_abc_a: meas.i_abc_a,
                    i_ab_a: meas.i_ab_a.to_array(),
                    u_dc_v: u_dc,
                },
                control: ControlRecord {
                    speed_ref_rpm: frame_rpm,
                    duties,
                    telemetry: ControllerTelemetry {
                        state: id.part_name(),
                        theta_e_rad: frame,
                        omega_e_rad_s: f64::from(out.frame_speed_rad_s),
                        i_dq_a: park(i_ab, DVec2::new(fc, fs)).to_array(),
                        u_ab_ref_v: [f64::from(out.u_ab.alpha), f64::from(out.u_ab.beta)],
                        speed_ref_rpm: out.pwm_enabled.then_some(frame_rpm),
                        ..ControllerTelemetry::default()
                    },
                },
                inverter: InverterRecord {
                    pwm_enabled: out.pwm_enabled,
                    duties: applied.duties,
                    u_ab_v: applied.u_ab_v.to_array(),
                    u_ab_commanded_v: applied.u_ab_commanded_v.to_array(),
                    u_dc_v: u_dc,
                },
                ..Sample::default()
            };
            if let Some(l) = log.as_mut() {
                l.record(&sample).map_err(|message| SimError::Output {
                    path: l.path().display().to_string(),
                    message,
                })?;
            }
            if let Some(pl) = plot.as_mut() {
                let _ = pl.record(&sample);
            }
        }
        last_pwm = out.pwm_enabled;
        if id.is_done() {
            break;
        }
        if let Some(f) = faults.as_mut() {
            f.before_step(k, &mut plant);
        }
        if out.pwm_enabled {
            plant.step(applied.u_ab_v.to_array(), 0.0, ts);
        } else {
            plant.step_open(0.0, ts);
        }
        if let Some(f) = faults.as_mut() {
            f.after_step(k, &mut plant);
        }
    }
    let v_err_true = 4.0 / 3.0 * sc.inverter.dead_time_s / ts * sc.inverter.u_dc_v;
    let truth = values(&motor, v_err_true);
    let total = f64::from(id.ticks()) * ts;
    let mut report = IdentifyReport {
        scenario: sc.name.clone(),
        seed: sc.seed,
        ok: false,
        error: None,
        error_kind: None,
        failed_step: None,
        truth,
        identified: None,
        errors_pct: None,
        steps: Vec::new(),
        total_time_s: total,
        pwm_off_at_end: !last_pwm,
        peak_current_a: peak,
        mcap: None,
        svg: None,
        flux_map: id.map_report(&motor, cfg.test_current_a.into(), ts),
    };
    match id.identifier().result() {
        Some(Ok(r)) => {
            let v = identified_values(r);
            report.ok = true;
            report.errors_pct = Some(errors(&v, &truth));
            report.identified = Some(v);
            report.steps = IdentifyStep::ALL
                .iter()
                .zip(r.step_ticks)
                .filter(|(_, n)| *n > 0)
                .map(|(s, n)| StepTime {
                    step: s.name(),
                    time_s: f64::from(n) * ts,
                })
                .collect();
        }
        Some(Err(f)) => {
            report.error = Some(f.to_string());
            report.error_kind = Some(error_kind(&f.error));
            report.failed_step = Some(f.step.name());
        }
        None => {
            report.error = Some(format!(
                "the sequence did not finish within {max_ticks} ticks"
            ));
        }
    }
    if let Some(l) = log {
        report.mcap = Some(l.finish(None)?.display().to_string());
    }
    if let (Some(pl), Some(path)) = (plot, opts.svg.as_ref()) {
        pl.write_svg(path, &format!("pmsm-sim identify: {}", sc.name))?;
        report.svg = Some(path.display().to_string());
    }
    Ok(report)
}

/// The scenario for plug and spin: the `foc` controller, sensorless, with the identified
/// `Rs`, `Ls = (Ld + Lq) / 2` and `psi_f` for its observer and the simulator's observers,
/// and the identified inertia for its speed loop; the plant keeps the true values.
/// Errors when the report has no identified `psi_f`.
pub fn with_identified(scenario: &Scenario, report: &IdentifyReport) -> Result<Scenario, SimError> {
    let v = report
        .identified
        .as_ref()
        .filter(|v| v.psi_f_wb.is_some())
        .ok_or_else(|| SimError::Stopped {
            t_s: report.total_time_s,
            reason: format!(
                "identification failed: {}",
                report
                    .error
                    .as_deref()
                    .unwrap_or("no flux linkage measured")
            ),
        })?;
    let mut sc = scenario.clone();
    sc.controller.kind = ControllerKind::Foc;
    sc.observer.rs_ohm = Some(v.rs_ohm);
    sc.observer.ld_h = Some(v.ld_h);
    sc.observer.lq_h = Some(v.lq_h);
    sc.observer.psi_f_wb = v.psi_f_wb;
    let mut f = sc.controller.foc.unwrap_or_default();
    if let Some(j) = v.j_kg_m2 {
        f.inertia_kg_m2 = Some(j);
    }
    sc.controller.foc = Some(f);
    Ok(sc)
}

/// Plug and spin: [`identify`] (no log, no plot), then [`with_identified`].
pub fn plug_and_spin(scenario: &Scenario) -> Result<(Scenario, IdentifyReport), SimError> {
    let report = identify(scenario, &IdentifyOptions::default())?;
    let sc = with_identified(scenario, &report)?;
    Ok((sc, report))
}

/// The report as a table: true vs identified with % errors, then the step times.
pub fn table(r: &IdentifyReport) -> String {
    use std::fmt::Write;
    let mut s = String::new();
    let _ = writeln!(s, "identify: {} (seed {})", r.scenario, r.seed);
    if let Some(e) = &r.error {
        let _ = writeln!(s, "FAILED: {e}");
    }
    let _ = writeln!(
        s,
        "{:<28} {:>14} {:>14} {:>9}",
        "quantity", "true", "identified", "error %"
    );
    let t = &r.truth;
    let rows: [(&str, f64, Option<f64>, Option<f64>); 6] = {
        let id = r.identified.as_ref();
        let e = r.errors_pct.as_ref();
        [
            (
                "Rs (ohm)",
                t.rs_ohm,
                id.map(|v| v.rs_ohm),
                e.map(|v| v.rs_ohm),
            ),
            ("Ld (H)", t.ld_h, id.map(|v| v.ld_h), e.map(|v| v.ld_h)),
            ("Lq (H)", t.lq_h, id.map(|v| v.lq_h), e.map(|v| v.lq_h)),
            (
                "psi_f (Wb)",
                t.psi_f_wb.unwrap_or(f64::NAN),
                id.and_then(|v| v.psi_f_wb),
                e.and_then(|v| v.psi_f_wb),
            ),
            (
                "J (kg m^2)",
                t.j_kg_m2.unwrap_or(f64::NAN),
                id.and_then(|v| v.j_kg_m2),
                e.and_then(|v| v.j_kg_m2),
            ),
            (
                "inverter voltage error (V)",
                t.inverter_voltage_error_v,
                id.map(|v| v.inverter_voltage_error_v),
                e.map(|v| v.inverter_voltage_error_v),
            ),
        ]
    };
    for (name, tv, iv, ev) in rows {
        let iv = iv.map_or("-".to_string(), |x| format!("{x:.6e}"));
        let ev = ev.map_or("-".to_string(), |x| format!("{x:+.2}"));
        let _ = writeln!(s, "{name:<28} {tv:>14.6e} {iv:>14} {ev:>9}");
    }
    for st in &r.steps {
        let _ = writeln!(s, "  step {:<14} {:>8.3} s", st.step, st.time_s);
    }
    let _ = writeln!(
        s,
        "total {:.3} s, peak current {:.2} A, PWM off at the end: {}",
        r.total_time_s, r.peak_current_a, r.pwm_off_at_end
    );
    if let Some(p) = &r.mcap {
        let _ = writeln!(s, "log: {p}");
    }
    if let Some(p) = &r.svg {
        let _ = writeln!(s, "plot: {p}");
    }
    s
}

/// The report as one JSON object (`identified` holds `rs_ohm`, `ld_h`, `lq_h`, `psi_f_wb`,
/// ...).
pub fn json(r: &IdentifyReport) -> Result<String, serde_json::Error> {
    serde_json::to_string_pretty(r)
}

/// Where `pmsm-sim identify` writes its outputs for a scenario: `out/<name>/identify.*`.
pub fn output_paths(out_dir: &Path) -> (PathBuf, PathBuf) {
    (out_dir.join("identify.mcap"), out_dir.join("identify.svg"))
}
