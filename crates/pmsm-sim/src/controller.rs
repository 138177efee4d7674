//! Drive controllers: the [`DriveController`] trait the run loop calls once per PWM period,
//! and the simulator's own **sensored** field-oriented controller that implements it. The
//! `foc` crate's controller implements it too ([`crate::foc_drive::FocDrive`]).
//!
//! # The trait
//!
//! A controller sees what a real one sees: the measured phase currents (and their Clarke
//! transform), the measured DC-bus voltage and the speed reference; in sensored mode
//! ([`DriveController::sensored`]) also the true rotor angle and speed. It returns three
//! duties in `[0, 1]`, whether the bridge switches, and telemetry for the log (state, fault,
//! dq currents and references, and the estimate of its own observer, if it has one, which the
//! simulator scores). Everything a controller does happens inside [`DriveController::tick`];
//! the simulator models the inverter (delay, dead time) behind it.
//!
//! # The sensored controller ([`SensoredController`])
//!
//! The simulator's reference drive (`kind = "sensored"`, the `servo-sensored` preset; it was
//! the stand-in until the `foc` controller closed the loop on its observer). It is given the
//! **true** rotor angle and speed; the observers run alongside and are only scored. One tick:
//!
//! ```text
//! speed PI:   e_w = w_ref - w_mech;  i_q_ref = Kp_w e_w + I_w,  clamped to +-I_max;  i_d_ref = 0
//!             (surface motor; MTPA split for an interior one, below)
//! Park:       i_d =  i_a cos th + i_b sin th,   i_q = -i_a sin th + i_b cos th   (th = th[k])
//! current PI: u_d = Kp (i_d_ref - i_d) + I_d - w_e Lq i_q                 (decoupling)
//!             u_q = Kp (i_q_ref - i_q) + I_q + w_e Ld i_d + w_e psi_f     (decoupling, EMF FF)
//! limit:      |u_dq| <= u_dc_meas / sqrt(3)  (linear range of SVPWM), by scaling the vector
//! inv. Park:  at th + w_e Ts / 2 (no delay) or th + 1.5 w_e Ts (one period of delay)
//! SVPWM:      duties for u_ab on the measured bus
//! ```
//!
//! - **Gains** by pole-zero cancellation: `Kp = w_c L`, `Ki = w_c Rs` makes each decoupled
//!   current loop first order with bandwidth `w_c` (`L = (Ld + Lq) / 2`). Speed loop:
//!   `Kp_w = w_s J / k_t`, `Ki_w = Kp_w w_s / 4`, `k_t = 1.5 p psi_f`.
//! - **Integrators** are backward Euler, `I[k] = I[k-1] + Ki Ts e[k]`.
//! - **Anti-windup** by conditional integration: while the output is limited, an axis does not
//!   integrate an error that would push its output further into the limit.
//! - **Angle advance.** The voltage is held over a period while the rotor turns by `w_e Ts`.
//!   Without delay, the vector computed at `t_k` acts over `[t_k, t_k+1)`, centred at
//!   `t_k + Ts/2`; with the one-period delay it acts over `[t_k+1, t_k+2)`, centred at
//!   `t_k + 1.5 Ts`. The inverse Park transform uses the angle at that centre so that the
//!   mean applied vector lies where the dq controller meant it
//!   ([`ControllerConfig::delay_compensation`]).
//! - **Interior motors** (`Lq > Ld`): the speed loop's output is the current magnitude `|i|`
//!   (signed), split on the maximum-torque-per-ampere line, `i_d_ref = MTPA(|i|)`
//!   ([`MotorModel::mtpa_i_d_a`]), `i_q_ref = sign sqrt(i^2 - i_d_ref^2)`; a surface motor gets
//!   `i_d_ref = 0`, `i_q_ref = i` as above. The current limit bounds `|i|`.
//! - **Dead-time compensation** (off unless [`ControllerConfig::dead_time_s`] is set; the
//!   scenario suite sets it, scenarios leave it off): each phase's duty gains
//!   `sat(i_x / band) t_dead / Ts`, `i_x` the phase current of the reference current at the
//!   angle of the application interval, `sat` linear within a band of
//!   [`DEAD_TIME_BAND_FRACTION`] of the current limit; the controller reports the voltage of
//!   the duties net of the compensation (`ControllerOutput::expected_u_ab_v`), which the
//!   observers are fed, as foc does.
//! - No field weakening: scenarios keep the voltage below the limit (rated points below base
//!   speed).

use core::f64::consts::PI;

use glam::DVec2;
use serde::Serialize;

use crate::plant::MotorModel;
use crate::svpwm::{INV_SQRT3, duties_to_voltage, inverse_clarke, inverse_park, park, svpwm};

/// The true rotor position and speed, given only to sensored controllers.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct RotorFeedback {
    /// Electrical angle at `t_k`, rad.
    pub theta_e_rad: f64,
    /// Mechanical speed at `t_k`, rad/s.
    pub omega_mech_rad_s: f64,
}

/// What a controller reads in period `k`.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct ControllerInput {
    /// Period index.
    pub k: u64,
    /// `t_k`, s.
    pub t_s: f64,
    /// Measured phase currents `[a, b, c]` (`c` reconstructed), A.
    pub i_abc_a: [f64; 3],
    /// Their Clarke transform `[alpha, beta]`, A.
    pub i_ab_a: [f64; 2],
    /// Measured DC-bus voltage, V.
    pub u_dc_v: f64,
    /// Mechanical speed reference, rad/s.
    pub speed_ref_mech_rad_s: f64,
    /// True rotor angle and speed: `Some` only for a [`sensored`](DriveController::sensored)
    /// controller.
    pub rotor: Option<RotorFeedback>,
}

pub use crate::record::{ControllerEstimate, ControllerTelemetry};

/// What a controller commands in period `k`.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct ControllerOutput {
    /// Duty of each leg, `[0, 1]` (the simulator clamps and checks them).
    pub duties: [f64; 3],
    /// Whether the bridge switches. `false` opens every switch for the coming period at once
    /// (a gate disable is not delayed by the computation delay; see
    /// [`Plant::step_open`](crate::plant::Plant::step_open)).
    pub pwm_enabled: bool,
    /// The alpha-beta voltage (V) the controller expects these duties to realize, when it
    /// knows better than "the duties on the measured bus" (e.g. after its own dead-time
    /// compensation, which the bridge's dead time cancels). The simulator's observers are fed
    /// this voltage (delayed like the duties); `None`: the ideal-switch voltage of the duties.
    pub expected_u_ab_v: Option<[f64; 2]>,
    /// For the log.
    pub telemetry: ControllerTelemetry,
}

/// A drive controller, called once per PWM period (module docs).
pub trait DriveController {
    /// Whether the controller is given the true rotor angle and speed
    /// ([`ControllerInput::rotor`]).
    fn sensored(&self) -> bool;

    /// One control period: measurements in, duties out.
    fn tick(&mut self, input: &ControllerInput) -> ControllerOutput;
}

/// Linear band of the dead-time compensation's sign, fraction of the current limit (as foc's
/// default, `dead_time_band_a`).
pub const DEAD_TIME_BAND_FRACTION: f64 = 0.02;

/// Tuning and limits of the sensored controller.
#[derive(Clone, Copy, Debug, PartialEq, Serialize)]
pub struct ControllerConfig {
    /// Control (PWM) period, s.
    pub ts_s: f64,
    /// Current limit: the speed loop's `i_q` reference (an interior motor's `|i|`) is clamped to
    /// `+-current_limit_a`, A.
    pub current_limit_a: f64,
    /// Current loop proportional gain, V/A.
    pub kp_current_v_a: f64,
    /// Current loop integral gain, V/(A s).
    pub ki_current_v_as: f64,
    /// Speed loop proportional gain, A/(rad/s) on the mechanical speed.
    pub kp_speed_a_s_rad: f64,
    /// Speed loop integral gain, A/rad on the mechanical speed.
    pub ki_speed_a_rad: f64,
    /// Advance the inverse Park angle by `1.5 w_e Ts` (one period of computation delay)
    /// instead of `0.5 w_e Ts`.
    pub delay_compensation: bool,
    /// Dead time to compensate, s (0: none, the default of [`ControllerConfig::tuned`]; module
    /// docs).
    pub dead_time_s: f64,
}

impl ControllerConfig {
    /// Gains from the motor and the loop bandwidths (module docs): current loops of bandwidth
    /// `current_bw_rad_s`, speed loop crossover `speed_bw_rad_s`.
    pub fn tuned(
        motor: &MotorModel,
        ts_s: f64,
        current_limit_a: f64,
        current_bw_rad_s: f64,
        speed_bw_rad_s: f64,
        delay_compensation: bool,
    ) -> Self {
        let kp_speed = speed_bw_rad_s * motor.j_kg_m2 / motor.torque_constant_nm_a();
        Self {
            ts_s,
            current_limit_a,
            kp_current_v_a: current_bw_rad_s * motor.ls_mean_h(),
            ki_current_v_as: current_bw_rad_s * motor.rs_ohm,
            kp_speed_a_s_rad: kp_speed,
            ki_speed_a_rad: kp_speed * speed_bw_rad_s / 4.0,
            delay_compensation,
            dead_time_s: 0.0,
        }
    }
}

/// Sensored speed and current controller (module docs).
#[derive(Clone, Debug, PartialEq)]
pub struct SensoredController {
    cfg: ControllerConfig,
    motor: MotorModel,
    /// Speed integrator, A.
    int_speed: f64,
    /// Current integrators `[d, q]`, V.
    int_dq: DVec2,
    /// Angle advance factor: 0.5 or 1.5 periods.
    advance: f64,
}

impl SensoredController {
    /// A controller with zero integrators; `motor` is the controller's model of the motor
    /// (decoupling, feed-forward).
    pub fn new(cfg: ControllerConfig, motor: MotorModel) -> Self {
        Self {
            cfg,
            motor,
            int_speed: 0.0,
            int_dq: DVec2::ZERO,
            advance: if cfg.delay_compensation { 1.5 } else { 0.5 },
        }
    }

    /// The configuration.
    pub fn config(&self) -> &ControllerConfig {
        &self.cfg
    }
}

impl DriveController for SensoredController {
    fn sensored(&self) -> bool {
        true
    }

    fn tick(&mut self, input: &ControllerInput) -> ControllerOutput {
        let cfg = self.cfg;
        let m = self.motor;
        let ts = cfg.ts_s;
        // A sensored controller without the rotor position cannot commutate: it outputs
        // zero voltage rather than guessing.
        let Some(rotor) = input.rotor else {
            return ControllerOutput {
                expected_u_ab_v: None,
                duties: [0.5; 3],
                pwm_enabled: false,
                telemetry: ControllerTelemetry {
                    state: "no_rotor_feedback",
                    ..ControllerTelemetry::default()
                },
            };
        };

        // Speed loop.
        let i_max = cfg.current_limit_a;
        let e_w = input.speed_ref_mech_rad_s - rotor.omega_mech_rad_s;
        let cand = self.int_speed + cfg.ki_speed_a_rad * ts * e_w;
        let unsat = cfg.kp_speed_a_s_rad * e_w + cand;
        let pushes_further = (unsat > i_max && e_w > 0.0) || (unsat < -i_max && e_w < 0.0);
        if !pushes_further {
            self.int_speed = cand.clamp(-i_max, i_max);
        }
        let i_cmd = (cfg.kp_speed_a_s_rad * e_w + self.int_speed).clamp(-i_max, i_max);
        // Interior motor: the current magnitude split on the MTPA line (module docs).
        let i_ref = if m.lq_h > m.ld_h {
            let i_d = m.mtpa_i_d_a(i_cmd);
            DVec2::new(
                i_d,
                (i_cmd * i_cmd - i_d * i_d).max(0.0).sqrt().copysign(i_cmd),
            )
        } else {
            DVec2::new(0.0, i_cmd)
        };

        // Current loops. `rot` is the rotor direction `(cos th, sin th)`: Park is a rotation
        // by `-th`, the inverse Park by `+th`.
        let (s, c) = rotor.theta_e_rad.sin_cos();
        let rot = DVec2::new(c, s);
        let i_dq = park(DVec2::from(input.i_ab_a), rot);
        let we = m.p() * rotor.omega_mech_rad_s;
        let e = i_ref - i_dq;
        let cand = self.int_dq + cfg.ki_current_v_as * ts * e;
        let ff = DVec2::new(
            -we * m.lq_h * i_dq.y,
            we * m.ld_h * i_dq.x + we * m.psi_f_wb,
        );
        let unsat = cfg.kp_current_v_a * e + cand + ff;
        let u_lim = input.u_dc_v * INV_SQRT3;
        let mag = unsat.length();
        let limited = mag > u_lim;
        let u_dq = if limited {
            unsat * (u_lim / mag)
        } else {
            unsat
        };
        for axis in 0..2 {
            let pushes_further = limited && e[axis] * u_dq[axis] > 0.0;
            if !pushes_further {
                self.int_dq[axis] = cand[axis];
            }
        }

        // Inverse Park at the angle at the centre of the period the voltage will act in.
        let (sd, cd) = small_sin_cos(self.advance * we * ts);
        let rot = rot.rotate(DVec2::new(cd, sd));
        let u_ab = inverse_park(u_dq, rot).to_array();
        let mut duties = svpwm(u_ab, input.u_dc_v).d;
        let mut expected_u_ab_v = None;
        if cfg.dead_time_s > 0.0 {
            // Dead-time compensation (module docs): each duty gains `sat(i_x / band) t_d / Ts`
            // with the phase current of the reference at the application interval's angle; the
            // observers are told the duties net of it (clamped as applied).
            let band = (DEAD_TIME_BAND_FRACTION * i_max).max(f64::MIN_POSITIVE);
            let i_abc = inverse_clarke(inverse_park(i_ref, rot).to_array());
            let mut net = [0.0; 3];
            for ((d, n), i) in duties.iter_mut().zip(net.iter_mut()).zip(i_abc) {
                let comp = (i / band).clamp(-1.0, 1.0) * cfg.dead_time_s / ts;
                *d = (*d + comp).clamp(0.0, 1.0);
                *n = *d - comp;
            }
            expected_u_ab_v = Some(duties_to_voltage(net, input.u_dc_v));
        }
        ControllerOutput {
            expected_u_ab_v,
            duties,
            pwm_enabled: true,
            telemetry: ControllerTelemetry {
                state: "sensored",
                theta_e_rad: rotor.theta_e_rad,
                omega_e_rad_s: we,
                i_dq_a: i_dq.to_array(),
                i_dq_ref_a: i_ref.to_array(),
                u_dq_ref_v: u_dq.to_array(),
                u_ab_ref_v: u_ab,
                voltage_limited: limited,
                closed_loop: true,
                speed_ref_rpm: Some(input.speed_ref_mech_rad_s * 30.0 / PI),
                fault: None,
                estimate: None,
            },
        }
    }
}

/// `(sin x, cos x)`, by Taylor series for `|x| < 0.35` (error below 1e-14; the angle advance
/// of one and a half periods stays there up to `w_e Ts = 0.23`), else by `sin_cos`.
#[inline]
fn small_sin_cos(x: f64) -> (f64, f64) {
    if x.abs() < 0.35 {
        let x2 = x * x;
        let s = x
            * (1.0
                - x2 / 6.0
                    * (1.0
                        - x2 / 20.0 * (1.0 - x2 / 42.0 * (1.0 - x2 / 72.0 * (1.0 - x2 / 110.0)))));
        let c = 1.0
            - x2 / 2.0
                * (1.0
                    - x2 / 12.0
                        * (1.0
                            - x2 / 30.0
                                * (1.0 - x2 / 56.0 * (1.0 - x2 / 90.0 * (1.0 - x2 / 132.0)))));
        (s, c)
    } else {
        x.sin_cos()
    }
}

/// Hz to rad/s.
pub fn hz_to_rad_s(f_hz: f64) -> f64 {
    2.0 * PI * f_hz
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::inverter::{Inverter, InverterConfig};
    use crate::plant::{Plant, PlantState};

    fn servo_controller(delay: bool) -> SensoredController {
        let m = MotorModel::servo();
        let cfg = ControllerConfig::tuned(&m, 1e-4, 3.0, hz_to_rad_s(500.0), 125.0, delay);
        SensoredController::new(cfg, m)
    }

    /// Closed loop through the inverter model, with or without the delay, and checks that
    /// the speed settles and the current tracks its reference.
    fn closed_loop(delay: bool, compensate: bool) -> (f64, f64) {
        let mut ctl = servo_controller(compensate);
        let mut inv = Inverter::new(InverterConfig {
            ts_s: 1e-4,
            u_dc_v: 300.0,
            dead_time_s: 0.0,
            delay,
            delay_periods: None,
            ripple_fraction: 0.0,
            ripple_hz: 0.0,
        });
        let mut plant = Plant::new(MotorModel::servo(), PlantState::default());
        let w_ref = 150.0;
        let mut worst_id = 0.0f64;
        for k in 0..4000u64 {
            let s = plant.state();
            let i_ab = plant.i_ab_a();
            let out = ctl.tick(&ControllerInput {
                k,
                t_s: k as f64 * 1e-4,
                i_abc_a: crate::svpwm::inverse_clarke(i_ab),
                i_ab_a: i_ab,
                u_dc_v: 300.0,
                speed_ref_mech_rad_s: w_ref,
                rotor: Some(RotorFeedback {
                    theta_e_rad: s.theta_e_rad,
                    omega_mech_rad_s: s.omega_mech_rad_s,
                }),
            });
            assert!(out.duties.iter().all(|d| (0.0..=1.0).contains(d)));
            if k > 3000 {
                worst_id = worst_id.max(s.i_d_a.abs());
            }
            let a = inv.apply(out.duties, 300.0, 300.0, plant.i_abc_a());
            plant.step(a.u_ab_v.to_array(), 0.5, 1e-4);
        }
        (plant.state().omega_mech_rad_s - w_ref, worst_id)
    }

    #[test]
    fn speed_loop_reaches_its_reference_through_the_inverter() {
        let (dw, id) = closed_loop(false, false);
        assert!(dw.abs() < 0.5 && id < 0.05, "no delay: dw {dw}, i_d {id}");
        let (dw, id) = closed_loop(true, true);
        assert!(
            dw.abs() < 0.5 && id < 0.05,
            "delay compensated: dw {dw}, i_d {id}"
        );
    }

    #[test]
    fn delay_compensation_removes_the_d_current_error() {
        // Uncompensated, the applied vector lags by w_e Ts and the steady i_d is off zero.
        let (_, id_bad) = closed_loop(true, false);
        let (_, id_good) = closed_loop(true, true);
        assert!(id_good < id_bad, "compensated {id_good} A, not {id_bad} A");
    }

    #[test]
    fn small_angle_series_matches_sin_cos() {
        for i in -400..=400 {
            let x = f64::from(i) * 1e-3;
            let (s, c) = small_sin_cos(x);
            assert!(
                (s - x.sin()).abs() < 1e-14 && (c - x.cos()).abs() < 1e-14,
                "{x}"
            );
        }
    }

    #[test]
    fn voltage_limit_engages_and_integrators_do_not_wind_up() {
        let mut ctl = servo_controller(true);
        let input = ControllerInput {
            k: 0,
            t_s: 0.0,
            i_abc_a: [0.0; 3],
            i_ab_a: [0.0, 0.0],
            u_dc_v: 300.0,
            speed_ref_mech_rad_s: 400.0,
            rotor: Some(RotorFeedback {
                theta_e_rad: 0.0,
                omega_mech_rad_s: 240.0,
            }),
        };
        for _ in 0..1000 {
            let out = ctl.tick(&input);
            let t = out.telemetry;
            assert!(t.voltage_limited);
            let lim = 300.0 * INV_SQRT3;
            assert!((t.u_dq_ref_v[0].hypot(t.u_dq_ref_v[1]) - lim).abs() < 1e-9);
        }
        assert!(ctl.int_dq[1].abs() < 300.0 * INV_SQRT3);
        assert!(ctl.int_speed.abs() <= 3.0);
    }
}
