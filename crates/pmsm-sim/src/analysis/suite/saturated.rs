//! The saturated-motor rows of the suite ([`SuiteReport::saturated`]): the reference
//! saturating motors of `ekf_core::saturation` (`pm_syrm`, `saturating_ipm`), their plant
//! the saturating one (module `plant::machine::saturation`), each observer told either the
//! motor's flux map or its small-signal constants.
//!
//! # The run (per motor)
//!
//! foc sensored drives the motor (its MTPA and current-loop gains from the small-signal
//! constants; the current bandwidth lowered to [`SAT_CURRENT_BANDWIDTH_HZ`] of the motor so
//! that the loop stays stable where saturation lowers the incremental inductance), with the
//! suite's realistic sensing. The observers start at zero speed and angle while the rotor
//! spins at 50 % rated speed, [`INITIAL_ANGLE_RAD`] away; then, at 50 % speed:
//!
//! ```text
//! 0.0 - 0.5 s   convergence, no load
//! 0.5 s         load to 100 % rated torque
//! 0.9 s         150 %
//! 1.3 s         -100 % (generating)
//! 1.7 s         100 %
//! 2.0 - 2.6 s   reversal under the rated load, 50 % to -50 % rated speed
//! 2.6 - 3.0 s   -50 %
//! ```
//!
//! Opt-in ([`saturated_rows_with`], [`SatDrive::Map`]; not in the suite's report): foc told
//! the same map as the observers, its MTPA, current-loop gains and decoupling from the map
//! (module `foc::mapdrive`), at a current bandwidth of the caller's choice.
//!
//! (`short`: the same at two thirds of the times.) Scored from the end of the convergence on:
//! RMS, max and share above 45 deg of the angle error over the samples where the speed is at
//! least 10 % of rated (the angle is unobservable from the EMF at standstill); status over
//! every sample: the share `Tracking` and the samples `Tracking` while more than 45 deg off.
//!
//! # The observers
//!
//! - EKF told the map: [`MapObserver`] (its default configuration) on the motor's model
//!   sampled on a 12 x 16 grid over `i_d` in `[-2.2, 0.8] I_r`, `i_q` in `[-2.2, 2.2] I_r`
//!   (`I_r` the rated current on the MTPA curve of the map);
//! - flux baseline told the map: [`FluxMapObserver`] (`FluxObserverConfig::new`);
//! - EKF told the small-signal constants: `PmsmObserver` in the mode for saturating motors,
//!   `ObserverConfig::saturating` (the model's `Lq` the midpoint of the told `Ld` and `Lq`:
//!   what a user who knows the motor saturates chooses; `ekf_core::observer` module docs,
//!   "Saturating motors told their small-signal constants"), its noise from the sensing
//!   chain on that model (`ObserverConfig::new` told the same: `docs/saturation.md`);
//! - EKF told the identified map: [`MapObserver`] on the map foc's standstill flux-map
//!   measurement gives on the plant before the run (module `identified`);
//! - flux baseline told them: `FluxObserver`.
//!
//! # Goals ([`SATURATED_CHECKS`])
//!
//! EKF told the map: RMS at most half the flux baseline told the map; no sample more than
//! 45 deg off; never `Tracking` while more than 45 deg off. EKF told the identified map: no
//! sample more than 45 deg off, never `Tracking` while lost; its RMS against the row told the
//! map is reported with its goal ([`GOAL_IDENTIFIED_RATIO`]). EKF told the small-signal
//! constants (`ObserverConfig::saturating`, `docs/saturation.md`): no sample more than 45 deg
//! off (no lock lost) and never `Tracking` while lost; its RMS is reported, not checked (what
//! saturation costs a constant model).

use ekf_core::saturated::{FluxMapObserver, MapObserver};
use ekf_core::saturation::SATURATED;
use ekf_core::{
    FluxMap, FluxObserver, FluxObserverConfig, NoiseCovariances, ObserverConfig, PmsmObserver,
};

use super::*;
use crate::output::metrics::LOST_DEG;

/// Current-loop bandwidth of the saturated motors' drive, Hz.
pub const SAT_CURRENT_BANDWIDTH_HZ: f64 = 150.0;

/// Grid points of the maps the observers are told, along `i_d` and `i_q`.
const GRID: (usize, usize) = (12, 16);

/// The checks of the saturated rows (module docs).
pub const SATURATED_CHECKS: [&str; 7] = [
    "goal: map EKF RMS / map flux baseline RMS",
    "goal: map EKF share above 45 deg (%)",
    "goal: map EKF Tracking while above 45 deg off",
    "goal: identified-map EKF share above 45 deg (%)",
    "goal: identified-map EKF Tracking while above 45 deg off",
    "goal: small-signal EKF share above 45 deg (%)",
    "goal: small-signal EKF Tracking while above 45 deg off",
];

/// What an observer of the saturated rows was told.
#[derive(Clone, Copy, Debug, PartialEq, Eq, Serialize)]
#[serde(rename_all = "snake_case")]
pub enum Told {
    /// The motor's flux map (sampled from its model).
    Map,
    /// Its small-signal constants (what a low-current commissioning measures).
    SmallSignal,
    /// The map foc's standstill flux-map measurement gives (module `identified`).
    IdentifiedMap,
}

/// One observer on one saturating motor (module docs).
#[derive(Clone, Debug, PartialEq, Serialize)]
pub struct SaturatedRow {
    /// Motor (`ekf_core::saturation` name).
    pub motor: &'static str,
    /// `"EKF"` or `"flux baseline"`.
    pub observer: &'static str,
    /// What it was told.
    pub told: Told,
    /// Samples scored (speed at least 10 % of rated, after the convergence).
    pub samples: usize,
    /// Failed steps over the run.
    pub failures: usize,
    /// RMS angle error, deg el.
    pub angle_rms_deg: f64,
    /// Largest `|e_th|`, deg el.
    pub angle_max_deg: f64,
    /// Share of the scored samples more than 45 deg off, %.
    pub lost_pct: f64,
    /// Share of all samples after the convergence with status `Tracking`, %.
    pub tracking_pct: f64,
    /// Samples after the convergence `Tracking` while more than 45 deg off.
    pub tracking_while_lost: usize,
}

/// A check of the saturated rows.
#[derive(Clone, Debug, PartialEq, Serialize)]
pub struct SaturatedCheck {
    /// What is checked ([`SATURATED_CHECKS`]).
    pub name: &'static str,
    /// Motor.
    pub motor: &'static str,
    /// Measured value.
    pub value: f64,
    /// Limit (`value <= limit` passes).
    pub limit: f64,
    /// Whether it holds.
    pub pass: bool,
}

/// foc's standstill flux-map measurement of one motor (module `identified`) and how the EKF
/// told its result compares with the EKF told the motor's map.
#[derive(Clone, Debug, PartialEq, Serialize)]
pub struct SaturatedIdentification {
    /// Motor.
    pub motor: &'static str,
    /// Duration of the measurement, s.
    pub duration_s: f64,
    /// Largest rotor movement during it, mechanical rad.
    pub rotor_moved_mech_rad: f64,
    /// Largest probe current, A.
    pub probe_current_a: f64,
    /// RMS of the EKF told the identified map over that of the EKF told the map.
    pub rms_ratio: f64,
    /// The goal on that ratio.
    pub goal: f64,
}

/// The saturated rows and their checks.
#[derive(Clone, Debug, Default, PartialEq, Serialize)]
pub struct SaturatedReport {
    /// Rows by motor, observer.
    pub rows: Vec<SaturatedRow>,
    /// Goals (module docs).
    pub checks: Vec<SaturatedCheck>,
    /// The identified maps.
    pub identification: Vec<SaturatedIdentification>,
}

/// Goal: the EKF told the identified map within this factor of the one told the map (RMS).
pub const GOAL_IDENTIFIED_RATIO: f64 = 1.5;

/// An observer of the saturated rows, scoring itself.
struct SatScored {
    observer: &'static str,
    told: Told,
    est: Box<dyn Observer>,
    /// Scoring starts here, s.
    t0: f64,
    /// Smallest `|w_e|` scored, rad/s.
    w_min: f64,
    scored: Sums,
    status: Sums,
    failures: usize,
}

impl Observer for SatScored {
    fn step(&mut self, u_prev: [f64; 2], i_ab_a: [f64; 2]) -> Result<ObserverEstimate, EkfError> {
        self.est.step(u_prev, i_ab_a)
    }
}

impl SideObserver for SatScored {
    fn record(&mut self, sample: &Sample, own: Result<ObserverSample, EkfError>) {
        let Ok(s) = own else {
            self.failures += 1;
            return;
        };
        if sample.t_s < self.t0 {
            return;
        }
        self.status.add_sample(&s);
        if sample.truth.omega_e_rad_s.abs() >= self.w_min {
            self.scored.add_sample(&s);
        }
    }
}

/// The scenario of one saturating motor (module docs): the suite's interior-motor drive and
/// sensing with this motor's ratings, current limit (twice the rated current), ADC range
/// and load profile.
/// `i_rated`: the rated current on the map's MTPA curve ([`rated_mtpa`]), A.
pub(super) fn scenario(
    m: &ekf_core::saturation::SaturatedMotor,
    opts: &SuiteOptions,
    k: f64,
    i_rated: f64,
) -> Scenario {
    let r = &m.reference;
    let plan = Plan {
        conv_end_s: 0.5 * k,
        windows: Vec::new(),
        step_s: f64::INFINITY,
        step_end_s: f64::INFINITY,
        duration_s: 3.0 * k,
        speed_points: vec![(0.0, 0.5), (2.0 * k, 0.5), (2.6 * k, -0.5)],
    };
    let mut sc = scenario_with(SuiteMotor::IndustrialIpm, opts, &plan, INITIAL_ANGLE_RAD);
    let motor = MotorModel::from_saturated(m);
    let fs = (4.0 * i_rated).ceil();
    sc.name = format!("suite-{}", r.name);
    sc.description = format!(
        "suite: {} (saturating) at 50 % rated speed, load steps 100/150/-100/100 %, reversal \
         under rated load",
        r.name
    );
    sc.rated_speed_rpm = r.rated_speed_rpm;
    sc.rated_torque_nm = r.rated_torque_nm;
    sc.motor = motor;
    sc.initial.speed_rpm = 0.5 * r.rated_speed_rpm;
    sc.speed_ref_rpm = Profile::linear(
        plan.speed_points
            .iter()
            .map(|&(t, f)| (t, f * r.rated_speed_rpm))
            .collect(),
    );
    let t = r.rated_torque_nm;
    sc.load = [(0.5, t), (0.9, 0.5 * t), (1.3, -2.5 * t), (1.7, 2.0 * t)]
        .into_iter()
        .map(|(at, by)| LoadTerm::Step {
            time_s: at * k,
            before_nm: 0.0,
            after_nm: by,
        })
        .collect();
    sc.controller.current_limit_a = 2.0 * i_rated;
    sc.controller.current_bandwidth_hz = SAT_CURRENT_BANDWIDTH_HZ;
    if !opts.ideal {
        sc.sensors.adc_full_scale_a = fs;
        sc.sensors.offset_a = [0.001 * fs, -0.0006 * fs];
    }
    sc
}

/// The rated point on the map's maximum-torque-per-ampere curve: `(i_d, i_q, |i|)` of the
/// smallest current giving the rated torque (bisection on `|i|`, golden-section search on
/// the angle).
pub fn rated_mtpa(m: &ekf_core::saturation::SaturatedMotor) -> (f64, f64, f64) {
    let p = f64::from(m.reference.pole_pairs);
    let model = &m.model;
    let torque = |i: f64, beta: f64| {
        let (id, iq) = (-i * beta.sin(), i * beta.cos());
        model
            .flux(id, iq, (m.reference.psi_f_wb, 0.0))
            .map_or(0.0, |(pd, pq)| 1.5 * p * (pd * iq - pq * id))
    };
    let best = |i: f64| {
        let (mut a, mut b) = (0.0, 1.4f64);
        let g = 0.5 * (5f64.sqrt() - 1.0);
        for _ in 0..60 {
            let (c, d) = (b - g * (b - a), a + g * (b - a));
            if torque(i, c) > torque(i, d) {
                b = d;
            } else {
                a = c;
            }
        }
        let beta = 0.5 * (a + b);
        (torque(i, beta), beta)
    };
    let (mut lo, mut hi) = (
        0.0,
        10.0 * m.reference.rated_torque_nm / (1.5 * p * m.reference.psi_f_wb),
    );
    for _ in 0..60 {
        let mid = 0.5 * (lo + hi);
        if best(mid).0 < m.reference.rated_torque_nm {
            lo = mid;
        } else {
            hi = mid;
        }
    }
    let beta = best(hi).1;
    (-hi * beta.sin(), hi * beta.cos(), hi)
}

/// The map an observer is told (module docs).
fn told_map(
    m: &ekf_core::saturation::SaturatedMotor,
    i_rated: f64,
) -> Result<FluxMap<f64, 16>, SimError> {
    let axis = |n: usize, lo: f64, hi: f64| -> Vec<f64> {
        (0..n)
            .map(|k| i_rated * (lo + (hi - lo) * k as f64 / (n - 1) as f64))
            .collect()
    };
    let i_d = axis(GRID.0, -2.2, 0.8);
    let i_q = axis(GRID.1, -2.2, 2.2);
    m.model
        .flux_map::<f64, 16>(&i_d, &i_q)
        .map_err(|e| SimError::Scenario {
            file: format!("suite-{}", m.reference.name),
            field: "flux map".into(),
            problem: e.to_string(),
        })
}

/// How foc drives the saturated motors.
#[derive(Clone, Copy, Debug, Default, PartialEq)]
pub enum SatDrive {
    /// The suite's rows: MTPA and current-loop gains from the small-signal constants, current
    /// bandwidth [`SAT_CURRENT_BANDWIDTH_HZ`].
    #[default]
    SmallSignal,
    /// Opt-in: foc told the map the observers are told (`FocConfig::flux_map`: MTPA,
    /// current-loop gains and decoupling from the map, module `foc::mapdrive`), at this
    /// current bandwidth, Hz.
    Map {
        /// Current-loop bandwidth, Hz.
        current_bandwidth_hz: f64,
    },
}

/// The suite's sensored drive told `map` ([`SatDrive::Map`]): tables for the scenario's
/// current limit, field weakening down to a quarter of the MTPA flux.
fn map_drive(
    sc: &Scenario,
    m: &ekf_core::saturation::SaturatedMotor,
    map: &FluxMap<f64, 16>,
) -> Result<FocDrive, SimError> {
    let err = |field: String, problem: String| SimError::Scenario {
        file: sc.name.clone(),
        field,
        problem,
    };
    let mut cfg = sc.foc_config().map_err(|e| err(e.field, e.problem))?;
    // As the suite's sensored drive (`sensored_drive`).
    cfg.speed_slew_rad_s2 *= 100.0;
    let tables = foc::MapTables::from_map(
        map,
        m.reference.pole_pairs,
        cfg.torque_constant_nm_a(),
        cfg.current_limit_a,
        4.0,
    )
    .map_err(|e| err("flux map".into(), e.to_string()))?;
    cfg.flux_map = Some(tables);
    FocDrive::new(&cfg, 0.0, None).map_err(|e| err("controller.foc".into(), e.to_string()))
}

/// The saturated rows (module docs).
pub fn saturated_rows(opts: &SuiteOptions) -> Result<SaturatedReport, SimError> {
    saturated_rows_with(opts, SatDrive::SmallSignal)
}

/// The saturated rows with foc driving as `how` says ([`saturated_rows`]: the small-signal
/// drive).
pub fn saturated_rows_with(
    opts: &SuiteOptions,
    how: SatDrive,
) -> Result<SaturatedReport, SimError> {
    let k = if opts.short { 2.0 / 3.0 } else { 1.0 };
    let mut report = SaturatedReport::default();
    for m in &SATURATED {
        let (_, _, i_rated) = rated_mtpa(m);
        let mut sc = scenario(m, opts, k, i_rated);
        if let SatDrive::Map {
            current_bandwidth_hz,
        } = how
        {
            sc.controller.current_bandwidth_hz = current_bandwidth_hz;
        }
        let ts = sc.ts_s();
        let map = told_map(m, i_rated)?;
        let ident = super::identified::identified_map(m, i_rated)?;
        let mut drive = match how {
            SatDrive::SmallSignal => sensored_drive(&sc)?,
            SatDrive::Map { .. } => map_drive(&sc, m, &map)?,
        };
        let small = sc.observer_params();
        // The EKFs' measurement noise from the sensing chain (module docs).
        // (Ideal sensing: the default.)
        let lsb = 2.0 * sc.sensors.adc_full_scale_a / f64::from(1u32 << sc.sensors.adc_bits);
        let noise = if opts.ideal {
            NoiseCovariances::scaled(&small, ts)
        } else {
            NoiseCovariances::from_sensing(&small, ts, sc.sensors.current_noise_std_a, lsb)
        };
        let map_cfg = ObserverConfig {
            noise,
            ..MapObserver::default_config(&map, small.rs_ohm, small.pole_pairs, ts)
        };
        let ident_cfg = ObserverConfig {
            noise,
            ..MapObserver::default_config(&ident.map, small.rs_ohm, small.pole_pairs, ts)
        };
        // Told the small-signal constants, the EKF runs what a user of a saturating motor
        // chooses: `ObserverConfig::saturating` (module docs); its noise from the sensing
        // chain on that configuration's model (`ObserverConfig::new` here: docs/saturation.md).
        let sat = ObserverConfig::saturating(small, ts);
        let ekf_cfg = ObserverConfig {
            noise: if opts.ideal {
                NoiseCovariances::scaled(&sat.motor, ts)
            } else {
                NoiseCovariances::from_sensing(&sat.motor, ts, sc.sensors.current_noise_std_a, lsb)
            },
            ..sat
        };
        let flux_cfg = FluxObserverConfig::new(small, ts);
        let scored = |observer, told, est: Box<dyn Observer>| SatScored {
            observer,
            told,
            est,
            t0: 0.5 * k,
            w_min: 0.1 * sc.rated_speed_e_rad_s(),
            scored: Sums::default(),
            status: Sums::default(),
            failures: 0,
        };
        let mut obs = vec![
            scored(
                "EKF",
                Told::Map,
                Box::new(MapObserver::new(&map_cfg, map.clone())?),
            ),
            scored(
                "flux baseline",
                Told::Map,
                Box::new(FluxMapObserver::new(&flux_cfg, map)?),
            ),
            scored(
                "EKF",
                Told::SmallSignal,
                Box::new(PmsmObserver::new(&ekf_cfg)?),
            ),
            scored(
                "EKF",
                Told::IdentifiedMap,
                Box::new(MapObserver::new(&ident_cfg, ident.map.clone())?),
            ),
            scored(
                "flux baseline",
                Told::SmallSignal,
                Box::new(FluxObserver::new(&flux_cfg)?),
            ),
        ];
        let out = {
            let mut side: Vec<&mut dyn SideObserver> =
                obs.iter_mut().map(|s| s as &mut dyn SideObserver).collect();
            run_with_side_observers(&sc, &mut drive, Default::default(), &mut side)?
        };
        if !out.end.is_completed() {
            return Err(SimError::Stopped {
                t_s: out.end.stop_time_s().unwrap_or(0.0),
                reason: format!("suite scenario {}: {}", sc.name, out.end.describe()),
            });
        }
        let name = m.reference.name;
        for o in &obs {
            report.rows.push(SaturatedRow {
                motor: name,
                observer: o.observer,
                told: o.told,
                samples: o.scored.n,
                failures: o.failures,
                angle_rms_deg: o.scored.angle_rms_deg(),
                angle_max_deg: o.scored.max_e,
                lost_pct: 100.0 * o.scored.lost as f64 / o.scored.n.max(1) as f64,
                tracking_pct: o.status.tracking_pct(),
                tracking_while_lost: o.status.tracking_lost,
            });
        }
        let row = |observer: &str, told: Told| {
            report
                .rows
                .iter()
                .find(|r| r.motor == name && r.observer == observer && r.told == told)
        };
        if let (Some(ekf), Some(flux), Some(id), Some(small)) = (
            row("EKF", Told::Map),
            row("flux baseline", Told::Map),
            row("EKF", Told::IdentifiedMap),
            row("EKF", Told::SmallSignal),
        ) {
            report.identification.push(SaturatedIdentification {
                motor: name,
                duration_s: ident.run.duration_s,
                rotor_moved_mech_rad: ident.run.rotor_moved_mech_rad,
                probe_current_a: super::identified::PROBE_CURRENT * i_rated,
                rms_ratio: id.angle_rms_deg / ekf.angle_rms_deg,
                goal: GOAL_IDENTIFIED_RATIO,
            });
            let values = [
                (ekf.angle_rms_deg / flux.angle_rms_deg, GOAL_RMS_RATIO),
                (ekf.lost_pct, 0.0),
                (ekf.tracking_while_lost as f64, 0.0),
                (id.lost_pct, 0.0),
                (id.tracking_while_lost as f64, 0.0),
                (small.lost_pct, 0.0),
                (small.tracking_while_lost as f64, 0.0),
            ];
            let checks: Vec<SaturatedCheck> = SATURATED_CHECKS
                .iter()
                .zip(values)
                .map(|(&check, (value, limit))| SaturatedCheck {
                    name: check,
                    motor: name,
                    value,
                    limit,
                    pass: value <= limit,
                })
                .collect();
            report.checks.extend(checks);
        }
    }
    Ok(report)
}

impl SaturatedReport {
    /// The rows and checks as a markdown section.
    pub fn to_markdown(&self) -> String {
        use std::fmt::Write;
        let mut s = String::new();
        if self.rows.is_empty() {
            return s;
        }
        let _ = writeln!(
            s,
            "\n## Saturated motors (foc sensored; load steps 100/150/-100/100 % and a reversal \
             under rated load at 50 % rated speed)\n\n\
             Scored after the convergence where the speed is at least 10 % of rated; status \
             over every sample after the convergence (the flux baseline has no confidence \
             measure: it never reports Tracking). The maps told are the motors' models \
             sampled on a {} x {} grid.\n",
            GRID.0, GRID.1
        );
        let _ = writeln!(
            s,
            "| motor | observer | told | angle RMS (deg) | angle max (deg) | > {LOST_DEG:.0} deg (%) | Tracking (%) | Tracking while > {LOST_DEG:.0} deg off | failed steps |"
        );
        let _ = writeln!(s, "|---|---|---|---|---|---|---|---|---|");
        for r in &self.rows {
            let _ = writeln!(
                s,
                "| {} | {} | {} | {:.3} | {:.2} | {:.2} | {:.1} | {} | {} |",
                r.motor,
                r.observer,
                match r.told {
                    Told::Map => "flux map",
                    Told::SmallSignal => "small-signal constants",
                    Told::IdentifiedMap => "identified map",
                },
                r.angle_rms_deg,
                r.angle_max_deg,
                r.lost_pct,
                r.tracking_pct,
                r.tracking_while_lost,
                r.failures
            );
        }
        let _ = writeln!(
            s,
            "\n| check | motor | value | limit | result |\n|---|---|---|---|---|"
        );
        for c in &self.checks {
            let _ = writeln!(
                s,
                "| {} | {} | {:.4} | {} | {} |",
                c.name,
                c.motor,
                c.value,
                c.limit,
                if c.pass { "pass" } else { "FAIL" }
            );
        }
        if !self.identification.is_empty() {
            let _ = writeln!(
                s,
                "\nThe identified maps: foc's standstill flux-map measurement on the plant \
                 (`foc::identify::saturation`), told the small-signal constants.\n\n\
                 | motor | duration (s) | rotor moved (mech rad) | largest current (A) | \
                 identified-map EKF RMS / map EKF RMS | goal |\n|---|---|---|---|---|---|"
            );
            for i in &self.identification {
                let _ = writeln!(
                    s,
                    "| {} | {:.3} | {:.3} | {:.1} | {:.2} | <= {} ({}) |",
                    i.motor,
                    i.duration_s,
                    i.rotor_moved_mech_rad,
                    i.probe_current_a,
                    i.rms_ratio,
                    i.goal,
                    if i.rms_ratio <= i.goal {
                        "met"
                    } else {
                        "missed"
                    }
                );
            }
        }
        s
    }
}
