//! The closed-loop run: plant, current sensor, sensored controller, and the observer(s)
//! alongside.
//!
//! # One PWM period `k` (timing of `design.md` section 4)
//!
//! 1. The plant is at `x(t_k)`; the sensor samples `i[k] = i(t_k) + noise`.
//! 2. The observer steps with `(u[k-1], i[k])`: it predicts over `[t_k-1, t_k)` with the
//!    voltage that was held there, then corrects with `i[k]`. Its first step (`k = 0`) gets
//!    `u[-1] = 0`. Its estimate is compared with the true `th(t_k)`, `w_e(t_k)`.
//! 3. The sensored controller computes `u[k]` from `i[k]`, the true angle and speed at `t_k`
//!    and the speed reference at `t_k`.
//! 4. The ideal inverter holds `u[k]` over `[t_k, t_k+1)`; the plant integrates the period with
//!    the load torque of `t_k` held too.
//!
//! There is no computation delay yet: `u[k]` acts from `t_k` on.

use std::time::Instant;

use ekf_core::{EkfError, Estimate, ObserverConfig, PmsmObserver, Status, wrap_angle};
use serde::Serialize;

use crate::SimError;
use crate::controller::{ControlInput, SensoredController};
use crate::plant::{Plant, PlantState};
use crate::scenario::{RPM_PER_RAD_S, Scenario};
use crate::sensors::CurrentSensor;

/// One observer's output for one sample.
#[derive(Clone, Copy, Debug, PartialEq, Serialize)]
pub struct ObserverSample {
    /// Estimated electrical angle, rad.
    pub theta_e_rad: f64,
    /// Estimated electrical speed, rad/s.
    pub omega_e_rad_s: f64,
    /// Whether the observer reports [`Status::Tracking`].
    pub tracking: bool,
    /// Normalized innovation squared of the correction.
    pub nis: f64,
}

impl From<Estimate<f64>> for ObserverSample {
    fn from(e: Estimate<f64>) -> Self {
        Self {
            theta_e_rad: e.theta_rad,
            omega_e_rad_s: e.omega_e_rad_s,
            tracking: e.status == Status::Tracking,
            nis: e.nis,
        }
    }
}

/// Everything recorded for sample `k` (at `t_k`).
#[derive(Clone, Copy, Debug, PartialEq, Serialize)]
pub struct Sample {
    /// `t_k = k Ts`, s.
    pub t_s: f64,
    /// True plant state at `t_k`.
    pub plant: PlantState,
    /// True electrical speed at `t_k`, rad/s.
    pub omega_e_rad_s: f64,
    /// Electromagnetic torque at `t_k`, N m.
    pub torque_nm: f64,
    /// Measured currents `i[k]`, A.
    pub i_meas_ab_a: [f64; 2],
    /// Voltage `u[k]` held over `[t_k, t_k+1)`, V.
    pub u_ab_v: [f64; 2],
    /// dq current reference of the controller, A.
    pub i_dq_ref_a: [f64; 2],
    /// Whether the controller limited the voltage.
    pub voltage_limited: bool,
    /// Mechanical speed reference, rad/s.
    pub speed_ref_mech_rad_s: f64,
    /// Load torque over `[t_k, t_k+1)`, N m.
    pub load_torque_nm: f64,
    /// The project's default observer (`ObserverConfig::new`, lag-free).
    pub observer: ObserverSample,
    /// The seed's filter (`ObserverConfig::seed`), when the scenario runs it.
    pub seed_filter: Option<ObserverSample>,
}

impl Sample {
    /// Wrapped angle error `th_hat - th` of an observer sample, electrical degrees.
    pub fn angle_error_deg(&self, est: &ObserverSample) -> f64 {
        wrap_angle(est.theta_e_rad - self.plant.theta_e_rad).to_degrees()
    }

    /// Speed error `w_hat - w_e` of an observer sample, electrical rad/s.
    pub fn speed_error_rad_s(&self, est: &ObserverSample) -> f64 {
        est.omega_e_rad_s - self.omega_e_rad_s
    }

    /// True mechanical speed, rpm.
    pub fn speed_rpm(&self) -> f64 {
        self.plant.omega_mech_rad_s * RPM_PER_RAD_S
    }
}

/// The recorded run.
#[derive(Clone, Debug, PartialEq)]
pub struct Trace {
    /// PWM period, s.
    pub ts_s: f64,
    /// One sample per period.
    pub samples: Vec<Sample>,
}

/// A filter step that failed.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub struct FilterFailure {
    /// Sample index.
    pub k: usize,
    /// The filter's error.
    pub error: EkfError,
}

/// A finished run: its trace and how long it took.
#[derive(Clone, Debug, PartialEq)]
pub struct RunOutput {
    /// The recorded run (deterministic for a given scenario).
    pub trace: Trace,
    /// Where the seed filter failed and was dropped, if it did.
    pub seed_filter_failure: Option<FilterFailure>,
    /// Wall-clock time of the simulation loop, s (not deterministic).
    pub wall_time_s: f64,
}

impl RunOutput {
    /// Simulated time, s.
    pub fn simulated_s(&self) -> f64 {
        self.trace.samples.len() as f64 * self.trace.ts_s
    }

    /// Real-time factor: simulated seconds per wall-clock second.
    pub fn real_time_factor(&self) -> f64 {
        self.simulated_s() / self.wall_time_s
    }
}

/// Runs a scenario (module docs give one period's order).
pub fn run(scenario: &Scenario) -> Result<RunOutput, SimError> {
    scenario.validate().map_err(SimError::Scenario)?;
    let ts = scenario.drive.ts_s;
    let motor = scenario.motor;
    let mut plant = Plant::new(
        motor,
        PlantState {
            theta_e_rad: scenario.initial_theta_e_rad,
            ..PlantState::default()
        },
    );
    let mut sensor = CurrentSensor::new(scenario.sensor.current_noise_std_a, scenario.sensor.seed);
    let mut controller = SensoredController::new(scenario.controller_config(), motor);
    let mut observer = PmsmObserver::new(&ObserverConfig::new(motor.params(), ts))
        .map_err(SimError::ObserverConfig)?;
    let mut seed_filter = if scenario.run_seed_filter {
        Some(
            PmsmObserver::new(&ObserverConfig::seed(motor.params(), ts))
                .map_err(SimError::ObserverConfig)?,
        )
    } else {
        None
    };

    let n = scenario.periods();
    let mut samples = Vec::with_capacity(n);
    let mut u_prev = [0.0; 2];
    let mut seed_filter_failure = None;
    let start = Instant::now();
    for k in 0..n {
        let t = k as f64 * ts;
        let state = plant.state();
        let i_meas = sensor.measure([state.i_alpha_a, state.i_beta_a]);

        let est = observer
            .step(u_prev, i_meas)
            .map_err(|error| SimError::Observer { k, error })?;
        // The seed filter is only a comparison: if it fails, it is dropped, not the run.
        let seed_est = match seed_filter.as_mut().map(|f| f.step(u_prev, i_meas)) {
            Some(Ok(e)) => Some(e),
            Some(Err(error)) => {
                seed_filter = None;
                seed_filter_failure = Some(FilterFailure { k, error });
                None
            }
            None => None,
        };

        let speed_ref = scenario.speed_ref_rpm.at(t) / RPM_PER_RAD_S;
        let out = controller.step(&ControlInput {
            i_ab_a: i_meas,
            theta_e_rad: state.theta_e_rad,
            omega_mech_rad_s: state.omega_mech_rad_s,
            speed_ref_mech_rad_s: speed_ref,
        });
        let load = scenario.load_torque_nm.at(t);

        samples.push(Sample {
            t_s: t,
            plant: state,
            omega_e_rad_s: plant.omega_e_rad_s(),
            torque_nm: plant.torque_nm(),
            i_meas_ab_a: i_meas,
            u_ab_v: out.u_ab_v,
            i_dq_ref_a: out.i_dq_ref_a,
            voltage_limited: out.voltage_limited,
            speed_ref_mech_rad_s: speed_ref,
            load_torque_nm: load,
            observer: est.into(),
            seed_filter: seed_est.map(Into::into),
        });

        plant.step(out.u_ab_v, load, ts, scenario.drive.substeps);
        u_prev = out.u_ab_v;
    }
    let wall_time_s = start.elapsed().as_secs_f64();
    Ok(RunOutput {
        trace: Trace { ts_s: ts, samples },
        seed_filter_failure,
        wall_time_s,
    })
}
