//! Plug and spin on the identified flux map (`pmsm-sim run SCENARIO --identify --flux-map`).
//!
//! # The sequence
//!
//! 1. [`identify`](super::identify::identify) with the flux-map step (foc's
//!    `IdentifyWithMap`: the identification, a coast (a square wave of current along the
//!    turning frame) for `psi_d(0, 0)`, stop,
//!    re-align, the standstill probe of a 7 x 9 grid up to `i_max`, default 0.85 x the
//!    current limit); a failed step is an error, never a run on guessed values.
//! 2. The map ([`identified_map`]): the probe's `psi_d`, `psi_q` on its grid as an
//!    `ekf_core::FluxMap` (linear beyond the grid).
//! 3. The run ([`MapDrive`]): foc's controller told the map (`FocConfig::flux_map`, module
//!    `foc::mapdrive`: MTPA, field weakening when the scenario enables it, the current PIs'
//!    gains and the decoupling from the map; the identified `Rs`, `J` and the small-signal
//!    constants elsewhere), its angle and speed from the EKF on the map
//!    (`ekf_core::saturated::MapObserver`, the identified `Rs`, its noise from the scenario's
//!    sensing) stepped every period on the measured currents and the voltage foc expects of
//!    its duties. foc takes them through its sensor input (`Mode::Sensored`): its own
//!    constant-parameter EKF is not used for the angle. The simulator scores the map EKF as the
//!    controller's observer.
//!
//! # The flux offset
//!
//! The map EKF learns the map's `psi_d` offset online (`MapObserver::set_flux_offset_tracking`;
//! the method in the module docs of `ekf_core::saturated`, "The flux offset"): the identified
//! map's flux is least well measured in its `i_d = 0` row, where the drive runs. The drive's
//! setting is the default with a gain of [`PSI_D_GAIN`] and windows from 10 % of rated speed.
//! Measured on the saturated suite row's drive of `saturating_ipm` over six sensor seeds
//! (`cargo test --release -p pmsm-sim --test identify_flux_map -- --ignored --nocapture`):
//! docs/identify.md.
//!
//! The run starts in closed loop on the map EKF's estimate from zero angle and speed: the
//! map EKF needs the back-EMF, so the rotor must turn (the scenario's initial speed, a flying
//! start); from standstill foc's own start-up (align, I/f) is not run on this path.
//!
//! [`compare`] runs the same drive told the plant's true map (sampled from the plant's model
//! on a 12 x 16 grid over `i_d` in `[-2.2, 0.8] I`, `i_q` in `[-2.2, 2.2] I`, `I` the
//! identification's test current) and the true `Rs`, and scores both
//! ([`MapRunScore`]): angle error from a given time on where the speed is at least 10 % of
//! rated, and torque per ampere (`sum |T| / sum |i|` over the same samples).

use ekf_core::saturated::{FluxOffsetTracking, MapObserver};
use ekf_core::{FluxMap, NoiseCovariances, ObserverConfig};
use serde::Serialize;

use super::identify::{IdentifyOptions, IdentifyReport, identify, with_identified};
use super::identify_map::FluxMapReport;
use crate::SimError;
use crate::drive::foc_adapter::FocDrive;
use crate::drive::interface::{ControllerInput, ControllerOutput, DriveController, RotorFeedback};
use crate::drive::rotor_observers::{Observer, ObserverEstimate};
use crate::output::metrics::LOST_DEG;
use crate::plant::MotorModel;
use crate::scenario::Scenario;
use crate::sim::{RunOptions, Sample, SampleSink};

/// Points of the maps on this path (the probe's grid is 7 x 9; the true map 12 x 16).
pub const MAP_POINTS: usize = 16;

/// Share of a window's measured `psi_d` error the drive takes into the map (module docs, "The
/// flux offset"): about five windows, a little more than one electrical turn, to settle.
pub const PSI_D_GAIN: f64 = 0.2;

/// Field weakening of the map drive's tables: down to `1 / FW_SPEED_RATIO` of the MTPA flux.
pub const FW_SPEED_RATIO: f32 = 4.0;

fn scenario_err(sc: &Scenario, field: &str, problem: String) -> SimError {
    SimError::Scenario {
        file: sc.name.clone(),
        field: field.into(),
        problem,
    }
}

/// The flux-map step's measured map as an interpolating map (module docs); errors when the
/// step did not measure it. On a grid symmetric in `i_q` (the probe's) the map is made
/// symmetric as a motor's is (`FluxMapReport::symmetric_nodes`): the measurement errors of
/// the two halves would otherwise give opposite torques that differ (foc's map tables refuse
/// more than 1 %).
pub fn identified_map(f: &FluxMapReport) -> Result<FluxMap<f64, MAP_POINTS>, String> {
    if !f.ok {
        return Err(format!(
            "the flux-map step failed: {}",
            f.error.as_deref().unwrap_or("no map")
        ));
    }
    let (rows_d, rows_q) = f
        .symmetric_nodes()
        .unwrap_or_else(|| (f.psi_d_wb.clone(), f.psi_q_wb.clone()));
    let pd: Vec<f64> = rows_d.concat();
    let pq: Vec<f64> = rows_q.concat();
    FluxMap::new(&f.i_d_a, &f.i_q_a, &pd, &pq).map_err(|e| format!("the identified flux map: {e}"))
}

/// The plant's own map (module docs): its saturation model, or `psi_f + L i` for a linear
/// plant, on a 12 x 16 grid scaled by `i_a`.
pub fn true_map(motor: &MotorModel, i_a: f64) -> Result<FluxMap<f64, MAP_POINTS>, String> {
    let axis = |n: usize, lo: f64, hi: f64| -> Vec<f64> {
        (0..n)
            .map(|k| i_a * (lo + (hi - lo) * k as f64 / (n - 1) as f64))
            .collect()
    };
    let (i_d, i_q) = (axis(12, -2.2, 0.8), axis(16, -2.2, 2.2));
    let mag = motor.magnetics();
    let (mut pd, mut pq) = (Vec::new(), Vec::new());
    for &id in &i_d {
        for &iq in &i_q {
            let lin = (motor.psi_f_wb + motor.ld_h * id, motor.lq_h * iq);
            let (d, q) = match &mag {
                Some(s) => s
                    .flux((id, iq), lin)
                    .ok_or_else(|| format!("the plant's flux at ({id}, {iq}) A"))?,
                None => lin,
            };
            pd.push(d);
            pq.push(q);
        }
    }
    FluxMap::new(&i_d, &i_q, &pd, &pq).map_err(|e| format!("the plant's flux map: {e}"))
}

/// foc told a flux map with its angle and speed from the EKF on that map (module docs).
pub struct MapDrive {
    foc: FocDrive,
    obs: MapObserver<f64, MAP_POINTS>,
    pole_pairs: f64,
    /// The voltages foc expects of its last two ticks' duties (newest first).
    u_hist: [[f64; 2]; 2],
    /// Ticks between computing a voltage and the end of the period it is held over (1 or 2).
    lag: usize,
    last: ObserverEstimate,
    /// Failed observer steps (the last estimate is kept).
    pub observer_failures: usize,
}

impl MapDrive {
    /// The drive of `sc` (its `foc` configuration, sensing and start/stop times) told `map`,
    /// the observer's resistance `rs_ohm`.
    pub fn new(
        sc: &Scenario,
        map: &FluxMap<f64, MAP_POINTS>,
        rs_ohm: f64,
    ) -> Result<Self, SimError> {
        let plan = sc.plan()?;
        let mut cfg = plan.foc;
        cfg.mode = foc::Mode::Sensored;
        let tables = foc::MapTables::from_map(
            map,
            sc.motor.pole_pairs,
            cfg.torque_constant_nm_a(),
            cfg.current_limit_a,
            FW_SPEED_RATIO,
        )
        .map_err(|e| scenario_err(sc, "flux map", e.to_string()))?;
        cfg.flux_map = Some(tables);
        let s = sc.controller.foc.unwrap_or_default();
        let foc = FocDrive::new(&cfg, s.start_time_s, s.stop_time_s)
            .map_err(|e| scenario_err(sc, "controller.foc", e.to_string()))?;
        let ts = sc.ts_s();
        let small = sc.observer_params();
        let lsb = 2.0 * sc.sensors.adc_full_scale_a / f64::from(1u32 << sc.sensors.adc_bits);
        let ocfg = ObserverConfig {
            noise: NoiseCovariances::from_sensing(&small, ts, sc.sensors.current_noise_std_a, lsb),
            ..MapObserver::default_config(map, rs_ohm, sc.motor.pole_pairs, ts)
        };
        let mut obs = MapObserver::new(&ocfg, map.clone())
            .map_err(|e| scenario_err(sc, "observer (flux map)", e.to_string()))?;
        obs.set_flux_offset_tracking(Some(FluxOffsetTracking {
            gain: PSI_D_GAIN,
            min_speed_rad_s: 0.1 * sc.rated_speed_e_rad_s(),
            ..FluxOffsetTracking::new()
        }))
        .map_err(|e| scenario_err(sc, "observer (flux offset)", e.to_string()))?;
        let x = obs.estimate();
        let last = ObserverEstimate {
            theta_e_rad: x.theta_rad,
            omega_e_rad_s: x.omega_e_rad_s,
            ..ObserverEstimate::default()
        };
        Ok(Self {
            foc,
            obs,
            pole_pairs: f64::from(sc.motor.pole_pairs),
            u_hist: [[0.0; 2]; 2],
            lag: if plan.delay { 2 } else { 1 },
            last,
            observer_failures: 0,
        })
    }

    /// The controller.
    pub fn foc(&self) -> &FocDrive {
        &self.foc
    }

    /// The `psi_d` offset the drive has taken into the map so far, Wb (module docs, "The flux
    /// offset").
    pub fn psi_d_offset_wb(&self) -> f64 {
        self.obs.flux_offset_wb()
    }
}

impl DriveController for MapDrive {
    fn sensored(&self) -> bool {
        false
    }

    fn tick(&mut self, input: &ControllerInput) -> ControllerOutput {
        // The voltage held over the last period: computed `lag` ticks ago.
        let u_prev = self.u_hist[self.lag - 1];
        match Observer::step(&mut self.obs, u_prev, input.i_ab_a) {
            Ok(e) => self.last = e,
            Err(_) => self.observer_failures += 1,
        }
        let e = self.last;
        let fed = ControllerInput {
            rotor: Some(RotorFeedback {
                theta_e_rad: e.theta_e_rad,
                omega_mech_rad_s: e.omega_e_rad_s / self.pole_pairs,
            }),
            ..*input
        };
        let mut out = self.foc.tick(&fed);
        let u = if out.pwm_enabled {
            out.expected_u_ab_v.unwrap_or([0.0; 2])
        } else {
            [0.0; 2]
        };
        self.u_hist = [u, self.u_hist[0]];
        out.telemetry.estimate = Some(e);
        out
    }
}

/// The score of one run on a map (module docs).
#[derive(Clone, Debug, Default, PartialEq, Serialize)]
pub struct MapRunScore {
    /// Samples scored.
    pub samples: usize,
    /// RMS angle error of the map EKF, deg el.
    pub angle_rms_deg: f64,
    /// Largest `|e_th|`, deg el.
    pub angle_max_deg: f64,
    /// Share of the scored samples more than 45 deg off, %.
    pub lost_pct: f64,
    /// `sum |T| / sum |i|` over the scored samples, N m / A.
    pub torque_per_ampere_nm_a: f64,
    /// The `psi_d` offset the map EKF learnt by the run's end, Wb (module docs, "The flux
    /// offset").
    pub psi_d_offset_wb: f64,
    /// How the run ended.
    pub end: String,
    /// foc's fault, if any.
    pub fault: Option<String>,
}

/// A sink scoring the controller's (map EKF's) angle and the torque per ampere.
struct Scorer {
    t0: f64,
    w_min: f64,
    n: usize,
    sq: f64,
    max: f64,
    lost: usize,
    torque: f64,
    current: f64,
}

impl SampleSink for Scorer {
    fn record(&mut self, s: &Sample) -> Result<(), String> {
        if s.t_s < self.t0 || s.truth.omega_e_rad_s.abs() < self.w_min {
            return Ok(());
        }
        let Some(e) = &s.control.telemetry.estimate else {
            return Ok(());
        };
        let err = ekf_core::wrap_angle(e.theta_e_rad - s.truth.theta_e_rad)
            .abs()
            .to_degrees();
        self.n += 1;
        self.sq += err * err;
        self.max = self.max.max(err);
        if err > LOST_DEG {
            self.lost += 1;
        }
        self.torque += s.truth.torque_nm.abs();
        self.current += s.truth.i_dq_a[0].hypot(s.truth.i_dq_a[1]);
        Ok(())
    }
}

/// Runs `sc` with [`MapDrive`] told `map` (observer resistance `rs_ohm`) and scores it
/// from `t0_s` on (module docs).
pub fn run_scored(
    sc: &Scenario,
    map: &FluxMap<f64, MAP_POINTS>,
    rs_ohm: f64,
    t0_s: f64,
) -> Result<MapRunScore, SimError> {
    let mut drive = MapDrive::new(sc, map, rs_ohm)?;
    let mut sc0 = sc.clone();
    sc0.observer.reference_filter = false;
    let mut score = Scorer {
        t0: t0_s,
        w_min: 0.1 * sc.rated_speed_e_rad_s(),
        n: 0,
        sq: 0.0,
        max: 0.0,
        lost: 0,
        torque: 0.0,
        current: 0.0,
    };
    let out = crate::sim::run_with_controller(
        &sc0,
        &mut drive,
        RunOptions {
            sinks: vec![&mut score],
            ..RunOptions::default()
        },
    )?;
    let n = score.n.max(1) as f64;
    Ok(MapRunScore {
        samples: score.n,
        angle_rms_deg: (score.sq / n).sqrt(),
        angle_max_deg: score.max,
        lost_pct: 100.0 * score.lost as f64 / n,
        torque_per_ampere_nm_a: score.torque / score.current.max(f64::MIN_POSITIVE),
        psi_d_offset_wb: drive.psi_d_offset_wb(),
        end: out.end.describe(),
        fault: out.metrics.drive.fault.clone(),
    })
}

/// Plug and spin on the identified map: the identification with the flux-map step up to
/// `flux_map_a` (A), then the scenario on the identified values ([`with_identified`]) and
/// the map (module docs).
pub fn plug_and_spin_map(
    scenario: &Scenario,
    flux_map_a: f64,
) -> Result<(Scenario, IdentifyReport, FluxMap<f64, MAP_POINTS>), SimError> {
    let report = identify(
        scenario,
        &IdentifyOptions {
            flux_map_a: Some(flux_map_a),
            ..IdentifyOptions::default()
        },
    )?;
    let sc = with_identified(scenario, &report)?;
    let stopped = |reason: String| SimError::Stopped {
        t_s: report.total_time_s,
        reason,
    };
    let f = report
        .flux_map
        .as_ref()
        .ok_or_else(|| stopped("no flux-map step".into()))?;
    let map = identified_map(f).map_err(stopped)?;
    Ok((sc, report, map))
}

/// The identified-map run against the true-map run (module docs).
#[derive(Clone, Debug, PartialEq, Serialize)]
pub struct MapComparison {
    /// Told the identified map and values.
    pub identified: MapRunScore,
    /// Told the plant's map and `Rs`.
    pub truth: MapRunScore,
}

impl MapComparison {
    /// Identified-map angle RMS over the true-map one.
    pub fn rms_ratio(&self) -> f64 {
        self.identified.angle_rms_deg / self.truth.angle_rms_deg
    }

    /// Identified-map torque per ampere over the true-map one.
    pub fn torque_per_ampere_ratio(&self) -> f64 {
        self.identified.torque_per_ampere_nm_a / self.truth.torque_per_ampere_nm_a
    }

    /// The comparison as a markdown table.
    pub fn table(&self) -> String {
        use std::fmt::Write;
        let mut s = String::from(
            "| told | angle RMS (deg) | angle max (deg) | > 45 deg (%) | torque per ampere \
             (N m/A) | psi_d offset learnt (mWb) | end |\n|---|---|---|---|---|---|---|\n",
        );
        for (name, r) in [
            ("identified map", &self.identified),
            ("true map", &self.truth),
        ] {
            let _ = writeln!(
                s,
                "| {name} | {:.3} | {:.2} | {:.2} | {:.4} | {:+.2} | {}{} |",
                r.angle_rms_deg,
                r.angle_max_deg,
                r.lost_pct,
                r.torque_per_ampere_nm_a,
                1e3 * r.psi_d_offset_wb,
                r.end,
                r.fault
                    .as_deref()
                    .map_or(String::new(), |f| format!(", fault {f}"))
            );
        }
        let _ = writeln!(
            s,
            "\nidentified / true: angle RMS {:.2} x, torque per ampere {:.4} x",
            self.rms_ratio(),
            self.torque_per_ampere_ratio()
        );
        s
    }
}

/// The plug-and-spin scenario `sc` told the original `scenario`'s plant: its `Rs`, `Ld`,
/// `Lq`, `psi_f` (observer) and inertia (foc).
pub fn told_the_plant(scenario: &Scenario, sc: &Scenario) -> Scenario {
    let mut told = sc.clone();
    told.observer.rs_ohm = Some(scenario.motor.rs_ohm);
    told.observer.ld_h = Some(scenario.motor.ld_h);
    told.observer.lq_h = Some(scenario.motor.lq_h);
    told.observer.psi_f_wb = Some(scenario.motor.psi_f_wb);
    if let Some(f) = told.controller.foc.as_mut() {
        f.inertia_kg_m2 = Some(scenario.motor.j_kg_m2);
    }
    told
}

/// Runs the plug-and-spin scenario `sc` told the identified `map` and `rs` (ohm), and the
/// same told the original `scenario`'s plant (its map, `Rs`, constants and inertia), both
/// scored from `t0_s` on.
pub fn compare(
    scenario: &Scenario,
    sc: &Scenario,
    map: &FluxMap<f64, MAP_POINTS>,
    rs: f64,
    t0_s: f64,
) -> Result<MapComparison, SimError> {
    let identified = run_scored(sc, map, rs, t0_s)?;
    let i = 0.5 * scenario.controller.current_limit_a;
    let tm = true_map(&scenario.motor, i).map_err(|e| scenario_err(scenario, "motor", e))?;
    let told_truth = told_the_plant(scenario, sc);
    let truth = run_scored(&told_truth, &tm, scenario.motor.rs_ohm, t0_s)?;
    Ok(MapComparison { identified, truth })
}

/// Runs `sc` with [`MapDrive`] told `map` (observer resistance `rs_ohm`), as
/// `sim::run_with` runs it with the scenario's own controller.
pub fn run_with_map(
    sc: &Scenario,
    map: &FluxMap<f64, MAP_POINTS>,
    rs_ohm: f64,
    opts: RunOptions<'_>,
) -> Result<crate::sim::RunOutput, SimError> {
    let mut drive = MapDrive::new(sc, map, rs_ohm)?;
    crate::sim::run_with_controller(sc, &mut drive, opts)
}

/// What `pmsm-sim run --identify [--flux-map]` runs after the identification.
pub struct Plugged {
    /// The scenario on the identified values ([`with_identified`]).
    pub scenario: Scenario,
    /// With the flux-map step: the identified map and `Rs` for [`run_with_map`].
    pub map: Option<(FluxMap<f64, MAP_POINTS>, f64)>,
    /// The identification's table (and the map's), for the terminal.
    pub text: String,
}

/// Plug and spin for the command line: [`plug_and_spin`](super::identify::plug_and_spin)
/// without `flux_map`, [`plug_and_spin_map`] with it (`Some(None)`: the grid up to 0.85 x
/// the current limit, as `pmsm-sim identify --flux-map`).
pub fn plug(scenario: &Scenario, flux_map: Option<Option<f64>>) -> Result<Plugged, SimError> {
    let Some(i) = flux_map else {
        let (sc, report) = super::identify::plug_and_spin(scenario)?;
        return Ok(Plugged {
            scenario: sc,
            map: None,
            text: super::identify::table(&report),
        });
    };
    let i = i.unwrap_or(0.85 * scenario.controller.current_limit_a);
    let (sc, report, map) = plug_and_spin_map(scenario, i)?;
    let mut text = super::identify::table(&report);
    if let Some(f) = &report.flux_map {
        text.push_str(&f.table());
    }
    let rs = report.identified.as_ref().map_or(f64::NAN, |v| v.rs_ohm);
    Ok(Plugged {
        scenario: sc,
        map: Some((map, rs)),
        text,
    })
}

/// [`compare`] for `pmsm-sim run --identify --flux-map`: scored from 0.5 s (at most a quarter
/// of the run) on, as text for the terminal; the run's own tables score the map EKF in their
/// "foc EKF" rows.
pub fn compared(
    scenario: &Scenario,
    sc: &Scenario,
    map: &FluxMap<f64, MAP_POINTS>,
    rs: f64,
) -> Result<String, SimError> {
    let t0 = 0.5f64.min(0.25 * sc.duration_s);
    Ok(format!(
        "(the run's \"foc EKF\" rows: the map EKF); against the plant's map from {t0} s:\n{}",
        compare(scenario, sc, map, rs, t0)?.table()
    ))
}

#[cfg(test)]
mod tests {
    use super::*;

    fn report(ok: bool) -> FluxMapReport {
        let i_d = vec![-2.0, 0.0, 2.0];
        let i_q = vec![-2.0, 0.0, 2.0];
        // Linear flux plus an asymmetric error on the node (0, +2).
        let psi_d: Vec<Vec<f64>> = i_d
            .iter()
            .map(|&d| {
                i_q.iter()
                    .map(|&q| 0.1 + 0.01 * d + if d == 0.0 && q > 0.0 { 0.004 } else { 0.0 })
                    .collect()
            })
            .collect();
        let psi_q: Vec<Vec<f64>> = i_d
            .iter()
            .map(|&d| {
                i_q.iter()
                    .map(|&q| 0.02 * q + if d == 0.0 && q > 0.0 { 0.002 } else { 0.0 })
                    .collect()
            })
            .collect();
        FluxMapReport {
            ok,
            error: (!ok).then(|| "probe failed".into()),
            i_max_a: 2.0,
            i_rated_a: 1.0,
            i_d_a: i_d,
            i_q_a: i_q,
            psi_d_wb: psi_d,
            psi_q_wb: psi_q,
            true_psi_d_wb: Vec::new(),
            true_psi_q_wb: Vec::new(),
            max_error_rated_pct: None,
            max_error_grid_pct: None,
            max_error_rated_map_pct: None,
            max_error_grid_map_pct: None,
            stop_s: 0.0,
            realign_s: 0.0,
            probe_s: 0.0,
            rotor_angle_max_rad: 0.0,
        }
    }

    #[test]
    fn the_identified_map_is_made_symmetric_in_i_q() {
        let m = identified_map(&report(true)).unwrap();
        let (a, b) = (m.eval(0.0, 2.0), m.eval(0.0, -2.0));
        // psi_d even, psi_q odd: each node the mean of it and its mirror.
        assert!((a.psi_d - b.psi_d).abs() < 1e-12);
        assert!((a.psi_q + b.psi_q).abs() < 1e-12);
        assert!((a.psi_d - 0.102).abs() < 1e-12, "{}", a.psi_d);
        assert!((a.psi_q - 0.041).abs() < 1e-12, "{}", a.psi_q);
    }

    #[test]
    fn a_failed_flux_map_step_is_an_error() {
        let e = identified_map(&report(false)).unwrap_err();
        assert!(e.contains("probe failed"), "{e}");
    }

    #[test]
    fn the_true_map_of_a_linear_plant_is_psi_f_plus_l_i() {
        let motor = MotorModel::industrial_ipm();
        let m = true_map(&motor, 2.0).unwrap();
        let p = m.eval(-1.0, 1.5);
        assert!((p.psi_d - (motor.psi_f_wb - motor.ld_h)).abs() < 1e-9);
        assert!((p.psi_q - 1.5 * motor.lq_h).abs() < 1e-9);
    }
}
