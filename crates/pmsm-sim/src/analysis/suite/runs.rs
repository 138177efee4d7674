//! The runs of one motor: the plan of its phases, the scenario of each, and the observers scored alongside.

use super::*;

/// Times of one motor's run (module docs).
#[derive(Clone, Debug, PartialEq)]
pub(super) struct Plan {
    pub(super) conv_end_s: f64,
    /// `(condition, speed fraction, loaded, window start, window end)`.
    pub(super) windows: Vec<(&'static str, f64, bool, f64, f64)>,
    pub(super) step_s: f64,
    pub(super) step_end_s: f64,
    pub(super) duration_s: f64,
    /// Speed reference points `(t, fraction of rated)`.
    pub(super) speed_points: Vec<(f64, f64)>,
}

impl Plan {
    /// The main run (module docs).
    pub(super) fn main(short: bool) -> Self {
        let (conv, ramp, settle, window, step_window) = if short {
            (0.3, 0.15, 0.25, 0.2, 0.25)
        } else {
            (0.5, 0.2, 0.3, 0.5, 0.3)
        };
        let mut t = conv;
        let mut points = vec![(0.0, 0.5), (conv, 0.5)];
        let mut windows = Vec::new();
        for (name, frac) in [("10 %", 0.1), ("50 %", 0.5), ("100 %", 1.0)] {
            t += ramp;
            points.push((t, frac));
            windows.push((name, frac, false, t + settle, t + settle + window));
            t += settle + window;
        }
        let step_s = t;
        let step_end_s = t + step_window;
        let w0 = step_end_s + settle;
        windows.push(("100 %, rated load", 1.0, true, w0, w0 + window));
        Self {
            conv_end_s: conv,
            windows,
            step_s,
            step_end_s,
            duration_s: w0 + window,
            speed_points: points,
        }
    }

    /// A real-drive run (module docs): convergence at 50 % rated speed, up to rated, the
    /// rated load step, one window at rated speed and load.
    pub(super) fn real_drive(short: bool) -> Self {
        let (conv, window) = if short { (0.2, 0.2) } else { (0.2, 0.3) };
        let up = conv + 0.2;
        let step_s = up + 0.1;
        let w0 = step_s + 0.2;
        Self {
            conv_end_s: conv,
            windows: vec![("100 %, rated load", 1.0, true, w0, w0 + window)],
            step_s,
            step_end_s: w0,
            duration_s: w0 + window,
            speed_points: vec![(0.0, 0.5), (conv, 0.5), (up, 1.0)],
        }
    }

    /// A convergence run: the convergence phase only.
    pub(super) fn convergence(short: bool) -> Self {
        let conv = Self::main(short).conv_end_s;
        Self {
            conv_end_s: conv,
            windows: Vec::new(),
            step_s: f64::INFINITY,
            step_end_s: f64::INFINITY,
            duration_s: conv,
            speed_points: vec![(0.0, 0.5)],
        }
    }
}

/// `(motor, rated rpm, rated torque, bus V, dead time s, noise A, ADC full scale A, current
/// limit A, current bandwidth Hz, speed bandwidth Hz, PWM period s)`: the simulator's presets
/// for these motors (`servo-sensored`/`default`, `industrial-2k2`, `drone`, `industrial-ipm`,
/// `traction-ipm`).
pub(super) fn setting(
    m: SuiteMotor,
) -> (MotorModel, f64, f64, f64, f64, f64, f64, f64, f64, f64, f64) {
    let r = m.reference();
    // The drive each motor runs on: (dead time s, noise A, ADC full scale A, current limit
    // A, current bandwidth Hz, speed bandwidth Hz).
    let (dead, noise, fs, i_lim, bw_i, bw_w) = match m {
        SuiteMotor::Servo => (0.5e-6, 0.02, 10.0, 4.5, 500.0, 20.0),
        SuiteMotor::Industrial2k2 => (1e-6, 0.05, 25.0, 8.0, 300.0, 10.0),
        SuiteMotor::SmallFast => (0.2e-6, 0.1, 40.0, 15.0, 800.0, 40.0),
        SuiteMotor::IndustrialIpm => (1e-6, 0.05, 25.0, 9.0, 300.0, 10.0),
        SuiteMotor::TractionIpm => (0.2e-6, 0.3, 300.0, 180.0, 1000.0, 30.0),
    };
    (
        MotorModel::from_catalog(r),
        r.rated_speed_rpm,
        r.rated_torque_nm,
        r.u_dc_v,
        dead,
        noise,
        fs,
        i_lim,
        bw_i,
        bw_w,
        r.ts_s,
    )
}

/// The main scenario of one motor (module docs).
pub fn suite_scenario(motor: SuiteMotor, opts: &SuiteOptions) -> Scenario {
    scenario_with(motor, opts, &Plan::main(opts.short), INITIAL_ANGLE_RAD)
}

/// Start angles of the convergence runs, deg el.: 8 (4 with `short`) around the circle,
/// none at 0 or 180 deg.
pub fn start_angles_deg(short: bool) -> Vec<f64> {
    if short {
        vec![-135.0, -45.0, 45.0, 135.0]
    } else {
        (0..8).map(|i| -157.5 + 45.0 * f64::from(i)).collect()
    }
}

/// Start angles of one motor's convergence runs, deg el.: [`start_angles_deg`], and for an
/// interior motor also 180 deg (the observers start at 0: the `theta + pi` cell).
pub fn motor_start_angles_deg(motor: SuiteMotor, short: bool) -> Vec<f64> {
    let mut a = start_angles_deg(short);
    if motor.is_interior() {
        a.push(180.0);
    }
    a
}

/// The scenario of one motor for a plan and a start angle.
pub(super) fn scenario_with(
    motor: SuiteMotor,
    opts: &SuiteOptions,
    plan: &Plan,
    theta0_rad: f64,
) -> Scenario {
    let (model, rpm, torque, u_dc, dead, noise, fs, i_lim, bw_i, bw_w, ts) = setting(motor);
    let index = SuiteMotor::ALL
        .iter()
        .position(|&x| x == motor)
        .unwrap_or(0) as u64;
    Scenario {
        name: format!("suite-{}", motor.name()),
        description: format!(
            "suite: {} spinning at 50 % rated, observers from zero; 10/50/100 % rated, rated load step",
            motor.name()
        ),
        duration_s: plan.duration_s,
        seed: opts.seed.wrapping_add(index),
        rated_speed_rpm: rpm,
        rated_torque_nm: torque,
        motor: model,
        initial: InitialState {
            theta_e_rad: theta0_rad,
            speed_rpm: 0.5 * rpm,
        },
        inverter: InverterConfig {
            ts_s: ts,
            u_dc_v: u_dc,
            dead_time_s: if opts.ideal { 0.0 } else { dead },
            delay: true,
            delay_periods: None,
            ripple_fraction: 0.0,
            ripple_hz: 0.0,
        },
        sensors: if opts.ideal {
            SensorConfig::default()
        } else {
            SensorConfig {
                current_noise_std_a: noise,
                gain_error: [0.002, -0.001],
                offset_a: [0.001 * fs, -0.0006 * fs],
                adc_bits: 12,
                adc_full_scale_a: fs,
            }
        },
        controller: ControllerSettings {
            // foc sensored, on the interior motors with its MTPA (on by default).
            kind: ControllerKind::FocSensored,
            current_limit_a: i_lim,
            current_bandwidth_hz: bw_i,
            speed_bandwidth_hz: bw_w,
            delay_compensation: None,
            foc: Some(FocSettings::default()),
        },
        observer: ObserverSettings {
            reference_filter: false,
            ..ObserverSettings::default()
        },
        speed_ref_rpm: Profile::linear(
            plan.speed_points
                .iter()
                .map(|&(t, f)| (t, f * rpm))
                .collect(),
        ),
        load: {
            let w_rated = rpm / RPM_PER_RAD_S;
            let mut load = vec![LoadTerm::Fan {
                coefficient_nm_s2_rad2: FAN_LOAD_FRACTION * torque / (w_rated * w_rated),
            }];
            if plan.step_s.is_finite() {
                // Interior motors: rated torque in all at rated speed (the fan's share less), since
                // the traction motor's rated point is just below its base speed.
                let step = if motor.is_interior() {
                    (1.0 - FAN_LOAD_FRACTION) * torque
                } else {
                    torque
                };
                load.push(LoadTerm::Step {
                    time_s: plan.step_s,
                    before_nm: 0.0,
                    after_nm: step,
                });
            }
            load
        },
        faults: Vec::new(),
        skipped_cycles: Default::default(),
        observer_noise: None,
    }
}

/// An observer stepped alongside the run, scoring itself per window.
pub(super) struct Scored {
    pub(super) kind: ObserverKind,
    /// The mismatch case told, if any (index in [`MISMATCHES`]).
    pub(super) told: Option<usize>,
    pub(super) est: Box<dyn Observer>,
    /// Tracked `(psi_f, Rs)` of the last step (the told ones for the baseline).
    pub(super) params: (f64, f64),
    /// Per window: sums of the tracked `psi_f` and `Rs` over its samples.
    pub(super) param_sums: Vec<[f64; 2]>,
    pub(super) plan: Plan,
    pub(super) windows: Vec<Sums>,
    pub(super) step: Sums,
    /// Time of the last sample of the convergence phase with `|e_th| >= 5 deg` (or failed).
    pub(super) last_bad_s: Option<f64>,
    /// Time of the last sample of the convergence phase.
    pub(super) last_conv_s: f64,
    pub(super) failures: usize,
    /// Every estimate of the whole run: the status shares.
    pub(super) run: Sums,
}

impl Scored {
    pub(super) fn new(
        kind: ObserverKind,
        told: Option<usize>,
        scenario: &Scenario,
        plan: Plan,
    ) -> Result<Self, SimError> {
        let mut params = scenario.observer_params();
        if let Some(m) = told.map(|i| MISMATCHES[i]) {
            params.psi_f_wb *= m.psi_f;
            params.rs_ohm *= m.rs;
            params.ld_h *= m.ls;
            params.lq_h *= m.ls;
        }
        let ts = scenario.ts_s();
        let est: Box<dyn Observer> = match kind {
            ObserverKind::SeedEkf => {
                Box::new(PmsmObserver::new(&ObserverConfig::seed(params, ts))?)
            }
            ObserverKind::DefaultEkf => {
                Box::new(PmsmObserver::new(&ObserverConfig::new(params, ts))?)
            }
            ObserverKind::FluxBaseline => {
                Box::new(FluxObserver::new(&FluxObserverConfig::new(params, ts))?)
            }
        };
        Ok(Self {
            kind,
            told,
            est,
            params: (params.psi_f_wb, params.rs_ohm),
            param_sums: vec![[0.0; 2]; plan.windows.len()],
            windows: vec![Sums::default(); plan.windows.len()],
            plan,
            step: Sums::default(),
            last_bad_s: None,
            last_conv_s: 0.0,
            failures: 0,
            run: Sums::default(),
        })
    }
}

impl Observer for Scored {
    fn step(&mut self, u_prev: [f64; 2], i_ab_a: [f64; 2]) -> Result<ObserverEstimate, EkfError> {
        let e = self.est.step(u_prev, i_ab_a)?;
        self.params = (e.psi_f_wb, e.rs_ohm);
        Ok(e)
    }
}

impl SideObserver for Scored {
    fn record(&mut self, sample: &Sample, own: Result<ObserverSample, EkfError>) {
        let t = sample.t_s;
        let own = own.ok();
        match &own {
            None => self.failures += 1,
            Some(s) => self.run.add_sample(s),
        }
        if t < self.plan.conv_end_s {
            self.last_conv_s = t;
            let bad = own
                .as_ref()
                .is_none_or(|s| !is_converged(s.angle_error_deg));
            if bad {
                self.last_bad_s = Some(t);
            }
        }
        let in_window = |t0: f64, t1: f64| t >= t0 && t < t1;
        for ((sums, w), ps) in self
            .windows
            .iter_mut()
            .zip(&self.plan.windows)
            .zip(self.param_sums.iter_mut())
        {
            if in_window(w.3, w.4) {
                match &own {
                    Some(s) => {
                        sums.add_sample(s);
                        ps[0] += self.params.0;
                        ps[1] += self.params.1;
                    }
                    None => sums.add_failure(),
                }
            }
        }
        if in_window(self.plan.step_s, self.plan.step_end_s) {
            match &own {
                Some(s) => self.step.add_sample(s),
                None => self.step.add_failure(),
            }
        }
    }
}

/// Runs one scenario with the three observers alongside (and, with `mismatch`, the default
/// EKF and the baseline told each wrong motor of [`MISMATCHES`]); an early end is an error.
pub(super) fn run_scored(
    sc: &Scenario,
    plan: &Plan,
    mismatch: bool,
) -> Result<(Vec<Scored>, String), SimError> {
    run_scored_with(sc, plan, &ObserverKind::ALL, mismatch, Vec::new()).map(|(s, e, _)| (s, e))
}

/// [`run_scored`] with the given observers and sinks, also returning the run.
pub(super) fn run_scored_with(
    sc: &Scenario,
    plan: &Plan,
    kinds: &[ObserverKind],
    mismatch: bool,
    sinks: Vec<&mut dyn crate::sim::SampleSink>,
) -> Result<(Vec<Scored>, String, crate::sim::RunOutput), SimError> {
    let mut scored = kinds
        .iter()
        .map(|&k| Scored::new(k, None, sc, plan.clone()))
        .collect::<Result<Vec<_>, _>>()?;
    if mismatch {
        for i in 0..MISMATCHES.len() {
            for k in [ObserverKind::DefaultEkf, ObserverKind::FluxBaseline] {
                scored.push(Scored::new(k, Some(i), sc, plan.clone())?);
            }
        }
    }
    let mut drive = sensored_drive(sc)?;
    let out = {
        let mut side: Vec<&mut dyn SideObserver> = scored
            .iter_mut()
            .map(|s| s as &mut dyn SideObserver)
            .collect();
        let opts = crate::sim::RunOptions {
            sinks,
            ..Default::default()
        };
        run_with_side_observers(sc, &mut drive, opts, &mut side)?
    };
    if !out.end.is_completed() {
        return Err(SimError::Stopped {
            t_s: out.end.stop_time_s().unwrap_or(0.0),
            reason: format!("suite scenario {}: {}", sc.name, out.end.describe()),
        });
    }
    let end = out.end.describe();
    Ok((scored, end, out))
}

/// The suite's drive for a scenario: foc sensored with its speed slew raised a hundredfold.
/// Its own slew (half the acceleration of its current limit, for the motor's inertia) would
/// turn the scenario's ramps into slower ones and leave the windows on a ramp; the profile's
/// ramps are the acceleration here.
pub(super) fn sensored_drive(sc: &Scenario) -> Result<FocDrive, SimError> {
    sensored_drive_with(sc, |_| {})
}

/// [`sensored_drive`] with its configuration changed by `edit` first.
pub(super) fn sensored_drive_with(
    sc: &Scenario,
    edit: impl FnOnce(&mut foc::FocConfig),
) -> Result<FocDrive, SimError> {
    let mut cfg = sc.foc_config().map_err(|e| SimError::Scenario {
        file: sc.name.clone(),
        field: e.field,
        problem: e.problem,
    })?;
    cfg.speed_slew_rad_s2 *= 100.0;
    edit(&mut cfg);
    FocDrive::new(&cfg, 0.0, None).map_err(|e| SimError::Scenario {
        file: sc.name.clone(),
        field: "controller.foc".into(),
        problem: e.to_string(),
    })
}

/// Scores the controller's own observer over a window (a sink of the run).
pub(super) struct FocScore {
    pub(super) window: (f64, f64),
    pub(super) sums: Sums,
}

impl crate::sim::SampleSink for FocScore {
    fn record(&mut self, s: &Sample) -> Result<(), String> {
        if s.t_s >= self.window.0
            && s.t_s < self.window.1
            && let Some(o) = &s.controller_observer
        {
            self.sums.add_sample(o);
        }
        Ok(())
    }
}

/// The real-drive rows of one motor (module docs).
pub(super) fn real_drive_rows(
    motor: SuiteMotor,
    opts: &SuiteOptions,
) -> Result<Vec<RealDriveRow>, SimError> {
    let plan = Plan::real_drive(opts.short);
    let mut rows = Vec::new();
    for effect in RealDriveEffect::ALL {
        let mut sc = scenario_with(motor, opts, &plan, INITIAL_ANGLE_RAD);
        sc.name = format!("suite-{}-real-drive", motor.name());
        effect.apply(&mut sc);
        let mut foc = FocScore {
            window: (plan.windows[0].3, plan.windows[0].4),
            sums: Sums::default(),
        };
        let kinds = [ObserverKind::FluxBaseline, ObserverKind::DefaultEkf];
        let (scored, _, out) = run_scored_with(&sc, &plan, &kinds, false, vec![&mut foc])?;
        let stats = |k: ObserverKind| {
            scored
                .iter()
                .find(|s| s.kind == k)
                .and_then(|s| s.windows.first())
                .map_or(
                    AngleStats {
                        samples: 0,
                        rms_deg: f64::NAN,
                        max_deg: f64::NAN,
                        mean_deg: f64::NAN,
                    },
                    AngleStats::of,
                )
        };
        if let Some(w) = plan.windows.first() {
            rows.push(RealDriveRow {
                motor,
                effect,
                condition: w.0.to_string(),
                w_ts_rad: w.1 * sc.rated_speed_e_rad_s() * sc.ts_s(),
                ekf: stats(ObserverKind::DefaultEkf),
                baseline: stats(ObserverKind::FluxBaseline),
                foc_observer: AngleStats::of(&foc.sums),
                skipped_periods: out.metrics.skipped_control_periods,
                periods: out.metrics.periods,
            });
        }
    }
    Ok(rows)
}

impl Scored {
    /// Convergence time (`None`: the last sample of the convergence phase is off).
    pub(super) fn convergence_time_s(&self, ts_s: f64) -> Option<f64> {
        let converged = self.last_bad_s.is_none_or(|t| t < self.last_conv_s);
        converged.then(|| self.last_bad_s.map_or(0.0, |t| t + ts_s))
    }
}
