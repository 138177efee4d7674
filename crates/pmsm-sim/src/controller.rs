//! A **sensored** field-oriented controller, the stand-in drive of this first simulator.
//!
//! It is given the **true** rotor angle and the **true** mechanical speed from the plant,
//! not the observer's estimates: the observer runs alongside, open loop, and is only scored.
//! Closing the loop on the observer (and running the `foc` crate's controller instead of this
//! one) comes later; this controller exists to drive the plant through a realistic scenario.
//!
//! # Structure (one call of [`SensoredController::step`] per PWM period `k`)
//!
//! ```text
//! speed PI:   e_w = w_ref - w_mech;  i_q_ref = Kp_w e_w + I_w,  clamped to +-I_max;  i_d_ref = 0
//! Park:       i_d =  i_a cos th + i_b sin th,   i_q = -i_a sin th + i_b cos th   (th = th[k])
//! current PI: u_d = Kp (i_d_ref - i_d) + I_d - w_e Ls i_q                 (decoupling)
//!             u_q = Kp (i_q_ref - i_q) + I_q + w_e Ls i_d + w_e psi_f     (decoupling, EMF FF)
//! limit:      |u_dq| <= u_dc / sqrt(3)  (linear range of SVPWM), by scaling the vector
//! inv. Park:  at th + w_e Ts / 2
//! ```
//!
//! Choices:
//!
//! - **Gains** by pole-zero cancellation: `Kp = w_c Ls`, `Ki = w_c Rs` makes each decoupled
//!   current loop first order with bandwidth `w_c`. Speed loop: `Kp_w = w_s J / k_t`,
//!   `Ki_w = Kp_w w_s / 4` (PI zero a quarter of the crossover `w_s` below it), `k_t = 1.5 p psi_f`.
//! - **Decoupling** uses the measured currents (exact cancellation of the cross-coupling up to
//!   the sensor noise; `w_e Ls` times 20 mA noise is well below 1 V on the servo).
//! - **Integrators** are backward Euler, `I[k] = I[k-1] + Ki Ts e[k]`, and both loops run every
//!   PWM period.
//! - **Anti-windup** by conditional integration: while the output is limited, an axis does not
//!   integrate an error that would push its output further into the limit (for the voltage
//!   vector: an error of the same sign as that axis's voltage).
//! - **Mid-period angle.** The voltage computed at `t_k` is held over `[t_k, t_k+1)` while the
//!   rotor turns by `w_e Ts`; the inverse Park transform uses the mid-period angle
//!   `th + w_e Ts / 2` so that the mean applied vector lies where the dq controller meant it.
//!   This simulator has no computation delay yet (the voltage computed from the sample at
//!   `t_k` is applied from `t_k` on), so the `1.5 w_e Ts` advance of a delayed drive is not
//!   needed.
//! - No field weakening (`i_d_ref = 0`): scenarios must keep the back-EMF below the voltage
//!   limit.

use serde::Serialize;

use crate::plant::MotorModel;

/// Tuning and limits of the sensored controller.
#[derive(Clone, Copy, Debug, PartialEq, Serialize)]
pub struct ControllerConfig {
    /// Control (PWM) period, s.
    pub ts_s: f64,
    /// DC-link voltage, V; the voltage vector is limited to `u_dc / sqrt(3)`.
    pub u_dc_v: f64,
    /// Current limit: the speed loop's `i_q` reference is clamped to `+-current_limit_a`, A.
    pub current_limit_a: f64,
    /// Current loop proportional gain, V/A.
    pub kp_current_v_a: f64,
    /// Current loop integral gain, V/(A s).
    pub ki_current_v_as: f64,
    /// Speed loop proportional gain, A/(rad/s) on the mechanical speed.
    pub kp_speed_a_s_rad: f64,
    /// Speed loop integral gain, A/rad on the mechanical speed.
    pub ki_speed_a_rad: f64,
}

impl ControllerConfig {
    /// Gains from the motor and the loop bandwidths (module docs): current loops of bandwidth
    /// `current_bw_rad_s`, speed loop crossover `speed_bw_rad_s`.
    pub fn tuned(
        motor: &MotorModel,
        ts_s: f64,
        u_dc_v: f64,
        current_limit_a: f64,
        current_bw_rad_s: f64,
        speed_bw_rad_s: f64,
    ) -> Self {
        let kp_speed = speed_bw_rad_s * motor.j_kg_m2 / motor.torque_constant_nm_a();
        Self {
            ts_s,
            u_dc_v,
            current_limit_a,
            kp_current_v_a: current_bw_rad_s * motor.ls_h,
            ki_current_v_as: current_bw_rad_s * motor.rs_ohm,
            kp_speed_a_s_rad: kp_speed,
            ki_speed_a_rad: kp_speed * speed_bw_rad_s / 4.0,
        }
    }

    /// Largest voltage vector magnitude, `u_dc / sqrt(3)`, V.
    pub fn voltage_limit_v(&self) -> f64 {
        self.u_dc_v / 3f64.sqrt()
    }
}

/// What the controller reads in period `k`.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct ControlInput {
    /// Measured alpha-beta currents `i[k]`, A.
    pub i_ab_a: [f64; 2],
    /// True electrical rotor angle at `t_k`, rad (sensored controller).
    pub theta_e_rad: f64,
    /// True mechanical speed at `t_k`, rad/s (sensored controller).
    pub omega_mech_rad_s: f64,
    /// Mechanical speed reference, rad/s.
    pub speed_ref_mech_rad_s: f64,
}

/// What the controller commands in period `k`.
#[derive(Clone, Copy, Debug, Default, PartialEq, Serialize)]
pub struct ControlOutput {
    /// Stator voltage `u[k]` to hold over `[t_k, t_k+1)`, alpha-beta, V.
    pub u_ab_v: [f64; 2],
    /// The same voltage in the controller's dq frame, V.
    pub u_dq_v: [f64; 2],
    /// Measured dq currents, A.
    pub i_dq_a: [f64; 2],
    /// dq current references, A.
    pub i_dq_ref_a: [f64; 2],
    /// Whether the voltage vector was limited this period.
    pub voltage_limited: bool,
}

/// Sensored speed and current controller (module docs).
#[derive(Clone, Debug, PartialEq)]
pub struct SensoredController {
    cfg: ControllerConfig,
    motor: MotorModel,
    /// Speed integrator, A.
    int_speed: f64,
    /// Current integrators `[d, q]`, V.
    int_dq: [f64; 2],
}

impl SensoredController {
    /// A controller with zero integrators; `motor` is the controller's model of the motor
    /// (decoupling, feed-forward).
    pub fn new(cfg: ControllerConfig, motor: MotorModel) -> Self {
        Self {
            cfg,
            motor,
            int_speed: 0.0,
            int_dq: [0.0; 2],
        }
    }

    /// The configuration.
    pub fn config(&self) -> &ControllerConfig {
        &self.cfg
    }

    /// One control period.
    pub fn step(&mut self, input: &ControlInput) -> ControlOutput {
        let cfg = self.cfg;
        let m = self.motor;
        let ts = cfg.ts_s;

        // Speed loop.
        let i_max = cfg.current_limit_a;
        let e_w = input.speed_ref_mech_rad_s - input.omega_mech_rad_s;
        let cand = self.int_speed + cfg.ki_speed_a_rad * ts * e_w;
        let unsat = cfg.kp_speed_a_s_rad * e_w + cand;
        let pushes_further = (unsat > i_max && e_w > 0.0) || (unsat < -i_max && e_w < 0.0);
        if !pushes_further {
            self.int_speed = cand.clamp(-i_max, i_max);
        }
        let iq_ref = (cfg.kp_speed_a_s_rad * e_w + self.int_speed).clamp(-i_max, i_max);
        let i_ref = [0.0, iq_ref];

        // Current loops.
        let (s, c) = input.theta_e_rad.sin_cos();
        let [ia, ib] = input.i_ab_a;
        let i_dq = [ia * c + ib * s, -ia * s + ib * c];
        let we = m.p() * input.omega_mech_rad_s;
        let e = [i_ref[0] - i_dq[0], i_ref[1] - i_dq[1]];
        let cand = [
            self.int_dq[0] + cfg.ki_current_v_as * ts * e[0],
            self.int_dq[1] + cfg.ki_current_v_as * ts * e[1],
        ];
        let ff = [
            -we * m.ls_h * i_dq[1],
            we * m.ls_h * i_dq[0] + we * m.psi_f_wb,
        ];
        let unsat = [
            cfg.kp_current_v_a * e[0] + cand[0] + ff[0],
            cfg.kp_current_v_a * e[1] + cand[1] + ff[1],
        ];
        let u_lim = cfg.voltage_limit_v();
        let mag = unsat[0].hypot(unsat[1]);
        let limited = mag > u_lim;
        let u_dq = if limited {
            let k = u_lim / mag;
            [unsat[0] * k, unsat[1] * k]
        } else {
            unsat
        };
        for axis in 0..2 {
            let pushes_further = limited && e[axis] * u_dq[axis] > 0.0;
            if !pushes_further {
                self.int_dq[axis] = cand[axis];
            }
        }

        // Inverse Park at the mid-period angle.
        let (s, c) = (input.theta_e_rad + 0.5 * we * ts).sin_cos();
        let u_ab = [u_dq[0] * c - u_dq[1] * s, u_dq[0] * s + u_dq[1] * c];
        ControlOutput {
            u_ab_v: u_ab,
            u_dq_v: u_dq,
            i_dq_a: i_dq,
            i_dq_ref_a: i_ref,
            voltage_limited: limited,
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::plant::{Plant, PlantState};

    fn servo_controller() -> (SensoredController, ControllerConfig) {
        let m = MotorModel::servo();
        let cfg = ControllerConfig::tuned(
            &m,
            1e-4,
            300.0,
            3.0,
            2.0 * 500.0 * core::f64::consts::PI,
            125.0,
        );
        (SensoredController::new(cfg, m), cfg)
    }

    #[test]
    fn speed_loop_reaches_its_reference_and_voltage_stays_limited() {
        let (mut ctl, cfg) = servo_controller();
        let mut plant = Plant::new(MotorModel::servo(), PlantState::default());
        let w_ref = 100.0;
        for _ in 0..3000 {
            let s = plant.state();
            let out = ctl.step(&ControlInput {
                i_ab_a: [s.i_alpha_a, s.i_beta_a],
                theta_e_rad: s.theta_e_rad,
                omega_mech_rad_s: s.omega_mech_rad_s,
                speed_ref_mech_rad_s: w_ref,
            });
            assert!(out.u_ab_v[0].hypot(out.u_ab_v[1]) <= cfg.voltage_limit_v() * (1.0 + 1e-12));
            assert!(out.i_dq_ref_a[1].abs() <= cfg.current_limit_a);
            plant.step(out.u_ab_v, 0.2, 1e-4, 10);
        }
        let w = plant.state().omega_mech_rad_s;
        assert!((w - w_ref).abs() < 0.5, "w_mech {w}");
    }

    #[test]
    fn voltage_limit_engages_and_integrators_do_not_wind_up() {
        let (mut ctl, cfg) = servo_controller();
        // A huge speed error at a high speed: the q voltage saturates.
        let input = ControlInput {
            i_ab_a: [0.0, 0.0],
            theta_e_rad: 0.0,
            omega_mech_rad_s: 240.0,
            speed_ref_mech_rad_s: 400.0,
        };
        for _ in 0..1000 {
            let out = ctl.step(&input);
            assert!(out.voltage_limited);
            assert!((out.u_dq_v[0].hypot(out.u_dq_v[1]) - cfg.voltage_limit_v()).abs() < 1e-9);
        }
        assert!(ctl.int_dq[1].abs() < cfg.voltage_limit_v());
        assert!(ctl.int_speed.abs() <= cfg.current_limit_a);
    }
}
