//! The `foc` crate's controller in the simulator loop: [`FocDrive`], a
//! [`DriveController`] around [`foc::Foc`].
//!
//! # What the adapter does in period `k`
//!
//! ```text
//! speed reference of the scenario (rad/s mech., f64) -> Foc::set_speed_ref_mech_rad_s (f32)
//! t_k >= start_time_s, first time                    -> Foc::start()
//! t_k >= stop_time_s, first time (if any)            -> Foc::stop()
//! measured i_a, i_b, i_c (c = -a - b), measured u_dc  -> TickInput::abc (f32)
//!   sensored variant: + the true angle and electrical speed (TickInput::with_sensor)
//! Foc::tick -> TickOutput { duties, pwm_enabled, state, fault, telemetry }
//!   -> ControllerOutput { duties (f64), pwm_enabled, telemetry (state, fault, dq, refs,
//!                         the f32 observer's estimate and covariance diagonal) }
//! ```
//!
//! Nothing else: no clamping, no dead-time compensation of its own, no help (foc compensates
//! the dead time itself; [`Scenario::foc_config`] tells it the inverter's). The numbers cross
//! the boundary as `f32`, as on the MCU; the simulator's plant, sensors and its own `f64` EKF
//! stay `f64`.
//!
//! # Timing
//!
//! `foc` assumes that the duties of tick `k` act over `[t_k+1, t_k+2)`
//! ([`ComputationDelay::OnePeriod`](foc::ComputationDelay::OnePeriod)): the simulator's
//! inverter with `delay = true` does exactly that. With `delay = false` the scenario's
//! `delay_compensation` defaults to false and the adapter configures
//! [`ComputationDelay::None`](foc::ComputationDelay::None) (duties act over `[t_k, t_k+1)`).
//! [`Scenario::foc_config`] builds the configuration.
//!
//! # Faults
//!
//! A fault latches inside `foc` (PWM off, the simulator opens the bridge and the shaft
//! coasts); the adapter does not clear it. The telemetry names it every period from then
//! on, and the metrics report the first one with its time.

use foc::{Fault, Foc, FocConfig, State, TickInput};

use crate::SimError;
use crate::drive::interface::{
    ControllerEstimate, ControllerInput, ControllerOutput, ControllerTelemetry, DriveController,
};
use crate::scenario::{RPM_PER_RAD_S, RunPlan, Scenario};

/// `1 / sqrt(3)` in `f32` (the same bits as the literal `0.577_350_26`).
const INV_SQRT3: f32 = crate::plant::frames::INV_SQRT3 as f32;

/// The `foc` controller as a [`DriveController`] (module docs).
#[derive(Clone, Debug)]
pub struct FocDrive {
    foc: Foc,
    sensored: bool,
    pole_pairs: f64,
    start_time_s: f64,
    stop_time_s: Option<f64>,
    started: bool,
    stopped: bool,
    /// `max_modulation / sqrt(3)`: the current loops' voltage limit per volt of bus.
    u_limit_per_v: f32,
}

impl FocDrive {
    /// A drive around `Foc::new(cfg)`; `start()` is called at the first period with
    /// `t_k >= start_time_s`, `stop()` likewise at `stop_time_s`. Sensored when `cfg.mode` is
    /// [`foc::Mode::Sensored`].
    pub fn new(
        cfg: &FocConfig,
        start_time_s: f64,
        stop_time_s: Option<f64>,
    ) -> Result<Self, foc::ConfigError> {
        let foc = Foc::new(cfg)?;
        Ok(Self {
            foc,
            sensored: cfg.mode == foc::Mode::Sensored,
            pole_pairs: f64::from(cfg.motor.pole_pairs),
            start_time_s,
            stop_time_s,
            started: false,
            stopped: false,
            u_limit_per_v: cfg.max_modulation * INV_SQRT3,
        })
    }

    /// The drive a scenario with a `foc` controller kind asks for
    /// ([`Scenario::foc_config`], `[controller.foc]` start and stop times).
    pub fn from_scenario(scenario: &Scenario) -> Result<Self, SimError> {
        let err = |field: String, problem: String| SimError::Scenario {
            file: scenario.name.clone(),
            field,
            problem,
        };
        let cfg = scenario.foc_config().map_err(|e| err(e.field, e.problem))?;
        Self::with_config(scenario, &cfg)
    }

    /// The controller of a [`RunPlan`]: its `foc` configuration, started and stopped at the
    /// scenario's `[controller.foc]` times.
    pub fn from_plan(plan: &RunPlan<'_>) -> Result<Self, SimError> {
        Self::with_config(plan.scenario, &plan.foc)
    }

    fn with_config(scenario: &Scenario, cfg: &foc::FocConfig) -> Result<Self, SimError> {
        let s = scenario.controller.foc.unwrap_or_default();
        Self::new(cfg, s.start_time_s, s.stop_time_s).map_err(|e| SimError::Scenario {
            file: scenario.name.clone(),
            field: "controller.foc".into(),
            problem: e.to_string(),
        })
    }

    /// The controller.
    pub fn foc(&self) -> &Foc {
        &self.foc
    }

    /// The controller, for commands between periods (`clear_fault`, `stop`, ...).
    pub fn foc_mut(&mut self) -> &mut Foc {
        &mut self.foc
    }
}

/// The log's name of a `foc` state.
pub fn state_name(s: State) -> &'static str {
    match s {
        State::Idle => "idle",
        State::Align => "align",
        State::OpenLoop => "open_loop",
        State::Handover => "handover",
        State::ClosedLoop => "closed_loop",
        State::Fault => "fault",
    }
}

/// The log's name of a `foc` fault.
pub fn fault_name(f: Fault) -> &'static str {
    match f {
        Fault::OverCurrent => "over_current",
        Fault::BusOverVoltage => "bus_over_voltage",
        Fault::BusUnderVoltage => "bus_under_voltage",
        Fault::ObserverLost => "observer_lost",
        Fault::Stall => "stall",
        Fault::NonFiniteInput => "non_finite_input",
        Fault::CurrentSensor => "current_sensor",
    }
}

impl DriveController for FocDrive {
    fn sensored(&self) -> bool {
        self.sensored
    }

    fn tick(&mut self, input: &ControllerInput) -> ControllerOutput {
        // Refused only for a non-finite reference (scenario profiles are finite): then the
        // previous command stays.
        let _ = self
            .foc
            .set_speed_ref_mech_rad_s(input.speed_ref_mech_rad_s as f32);
        if !self.started && input.t_s >= self.start_time_s {
            self.started = true;
            // Refused only while a fault is latched, which cannot be before the first start.
            let _ = self.foc.start();
        }
        if let Some(t_stop) = self.stop_time_s
            && !self.stopped
            && input.t_s >= t_stop
        {
            self.stopped = true;
            self.foc.stop();
        }
        let [a, b, c] = input.i_abc_a;
        let mut tick_in = TickInput::abc(a as f32, b as f32, c as f32, input.u_dc_v as f32);
        if self.sensored
            && let Some(r) = input.rotor
        {
            tick_in = tick_in.with_sensor(
                r.theta_e_rad as f32,
                (r.omega_mech_rad_s * self.pole_pairs) as f32,
            );
        }
        let out = self.foc.tick(&tick_in);

        let t = &out.telemetry;
        let p = self.foc.observer().covariance();
        let u_lim = self.u_limit_per_v * input.u_dc_v as f32;
        let driven = out.pwm_enabled;
        ControllerOutput {
            duties: out.duties.map(f64::from),
            pwm_enabled: out.pwm_enabled,
            // foc's own record of what its duties realize (duties minus its dead-time
            // compensation, on the bus it measured): what its observer is fed too.
            expected_u_ab_v: Some([f64::from(t.u_ab.alpha), f64::from(t.u_ab.beta)]),
            telemetry: ControllerTelemetry {
                state: state_name(out.state),
                theta_e_rad: f64::from(t.theta_rad),
                omega_e_rad_s: f64::from(t.omega_rad_s),
                i_dq_a: [f64::from(t.i_dq.d), f64::from(t.i_dq.q)],
                i_dq_ref_a: [f64::from(t.i_dq_ref.d), f64::from(t.i_dq_ref.q)],
                u_dq_ref_v: [f64::from(t.u_dq.d), f64::from(t.u_dq.q)],
                u_ab_ref_v: [f64::from(t.u_ab.alpha), f64::from(t.u_ab.beta)],
                // foc limits |u_dq| to max_modulation u_dc / sqrt(3); at the limit it sits
                // on the circle (d first, q gets the rest).
                voltage_limited: driven && t.u_dq.d.hypot(t.u_dq.q) >= 0.9999 * u_lim,
                closed_loop: matches!(out.state, State::Handover | State::ClosedLoop),
                speed_ref_rpm: driven.then(|| f64::from(t.speed_ref_mech_rad_s) * RPM_PER_RAD_S),
                fault: out.fault.map(fault_name),
                estimate: Some(ControllerEstimate {
                    theta_e_rad: f64::from(t.estimate.theta_rad),
                    omega_e_rad_s: f64::from(t.estimate.omega_e_rad_s),
                    p_diag: [p[(0, 0)], p[(1, 1)], p[(2, 2)], p[(3, 3)]].map(f64::from),
                    nis: f64::from(t.estimate.nis),
                    tracking: t.estimate.status == foc::ekf_core::Status::Tracking,
                    psi_f_wb: f64::from(t.estimate.psi_f_wb),
                    psi_f_sigma_wb: f64::from(t.estimate.psi_f_sigma_wb),
                    rs_ohm: f64::from(t.estimate.rs_ohm),
                    rs_sigma_ohm: f64::from(t.estimate.rs_sigma_ohm),
                    winding_temperature_c: f64::from(t.estimate.winding_temperature_c),
                }),
            },
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::drive::interface::RotorFeedback;

    fn input(t_s: f64, rotor: Option<RotorFeedback>) -> ControllerInput {
        ControllerInput {
            k: 0,
            t_s,
            i_abc_a: [0.0; 3],
            i_ab_a: [0.0; 2],
            u_dc_v: 300.0,
            speed_ref_mech_rad_s: 100.0,
            rotor,
        }
    }

    #[test]
    fn starts_at_the_start_time_and_reports_its_state() {
        let sc = Scenario::default_servo();
        let mut cfg = sc.foc_config().unwrap_or_else(|e| panic!("{e:?}"));
        cfg.mode = foc::Mode::Sensorless;
        let mut d = FocDrive::new(&cfg, 1e-3, None).unwrap_or_else(|e| panic!("{e}"));
        assert!(!d.sensored());
        let o = d.tick(&input(0.0, None));
        assert!(!o.pwm_enabled);
        assert_eq!(o.telemetry.state, "idle");
        assert_eq!(o.duties, [0.5; 3]);
        let o = d.tick(&input(1e-3, None));
        assert!(o.pwm_enabled);
        assert_eq!(o.telemetry.state, "align");
        assert!(!o.telemetry.closed_loop);
        assert!(o.telemetry.estimate.is_some());
        assert!((d.foc().speed_target_mech_rad_s() - 100.0).abs() < 1e-4);
        // A missing (NaN) sample is ridden through; five in a row trip foc's fault, and the
        // adapter reports it.
        let mut bad = input(2e-3, None);
        bad.i_abc_a[0] = f64::NAN;
        let n = cfg.samples.missing_trip_ticks;
        for _ in 1..n {
            let o = d.tick(&bad);
            assert!(o.pwm_enabled && o.telemetry.fault.is_none(), "{o:?}");
        }
        let o = d.tick(&bad);
        assert!(!o.pwm_enabled);
        assert_eq!(o.telemetry.fault, Some("non_finite_input"));
        assert_eq!(o.telemetry.state, "fault");
    }

    #[test]
    fn sensored_variant_passes_the_rotor_through() {
        let sc = Scenario::default_servo();
        let cfg = sc
            .foc_config()
            .unwrap_or_else(|e| panic!("{e:?}"))
            .with_mode(foc::Mode::Sensored);
        let mut d = FocDrive::new(&cfg, 0.0, None).unwrap_or_else(|e| panic!("{e}"));
        assert!(d.sensored());
        let o = d.tick(&input(
            0.0,
            Some(RotorFeedback {
                theta_e_rad: 0.3,
                omega_mech_rad_s: 0.0,
            }),
        ));
        assert!(o.pwm_enabled);
        assert_eq!(o.telemetry.state, "closed_loop");
        assert!((o.telemetry.theta_e_rad - 0.3).abs() < 1e-6);
        // Without the rotor a sensored foc trips (missing sensor).
        let o = d.tick(&input(1e-4, None));
        assert_eq!(o.telemetry.fault, Some("non_finite_input"));
    }
}
