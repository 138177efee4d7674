//! The plant: a surface-mounted PMSM in the stationary alpha-beta frame, with its mechanics.
//!
//! # Equations (SI, electrical quantities unless `_mech`; `design.md` section 2)
//!
//! ```text
//! di_a/dt     = (-Rs i_a + w_e psi sin(th) + u_a) / Ls
//! di_b/dt     = (-Rs i_b - w_e psi cos(th) + u_b) / Ls
//! J dw_mech/dt = Te - B w_mech - T_load,   Te = 1.5 p psi (i_b cos th - i_a sin th)
//! dth/dt      = w_e = p w_mech
//! ```
//!
//! `Te = 1.5 p psi i_q` with the amplitude-invariant Park transform
//! (`i_q = -i_a sin th + i_b cos th`). `T_load` is the torque the load takes from the shaft
//! (positive: it brakes positive rotation).
//!
//! # Integration
//!
//! The inverter holds the stator voltage constant over each PWM period `[t_k, t_k+1)` (an
//! ideal inverter: no dead time, no ripple; those come with a later inverter model), and the
//! load torque is held too. [`Plant::step`] integrates one such period with classic RK4 over
//! `substeps` equal sub-steps. The angle is kept wrapped to `[-pi, pi)` after every sub-step.

use ekf_core::{MotorParams, wrap_angle};
use serde::Serialize;

/// Mechanical and electrical parameters of a surface PMSM (SI units).
#[derive(Clone, Copy, Debug, PartialEq, Serialize)]
pub struct MotorModel {
    /// Stator resistance per phase, ohm.
    pub rs_ohm: f64,
    /// Stator inductance per phase (Ld = Lq), henry.
    pub ls_h: f64,
    /// Permanent-magnet flux linkage, weber.
    pub psi_f_wb: f64,
    /// Number of pole pairs.
    pub pole_pairs: u32,
    /// Rotor (plus load) inertia, kg m^2.
    pub j_kg_m2: f64,
    /// Viscous friction coefficient, N m s/rad (on the mechanical speed).
    pub b_nm_s_rad: f64,
}

impl MotorModel {
    /// Servo motor of `design.md` section 6 (Rs 2.875 ohm, Ls 8.5 mH, psi_f 0.175 Wb,
    /// 4 pole pairs, J 8e-4 kg m^2, B 1e-3 N m s/rad).
    pub fn servo() -> Self {
        Self {
            rs_ohm: 2.875,
            ls_h: 8.5e-3,
            psi_f_wb: 0.175,
            pole_pairs: 4,
            j_kg_m2: 8e-4,
            b_nm_s_rad: 1e-3,
        }
    }

    /// Industrial 2.2 kW motor, surface variant (Rs 3.6 ohm, Ls 36 mH, psi_f 0.545 Wb,
    /// 3 pole pairs, J 0.015 kg m^2). The design gives no friction; `B = 1e-3 N m s/rad` is
    /// chosen here (small: 0.16 N m at 1500 rpm, about 1 % of a 2.2 kW motor's rated torque).
    pub fn industrial_2k2() -> Self {
        Self {
            rs_ohm: 3.6,
            ls_h: 36e-3,
            psi_f_wb: 0.545,
            pole_pairs: 3,
            j_kg_m2: 0.015,
            b_nm_s_rad: 1e-3,
        }
    }

    /// Small fast (drone class) motor (Rs 0.12 ohm, Ls 0.15 mH, psi_f 6 mWb, 7 pole pairs,
    /// J 2e-5 kg m^2). The design gives no friction; `B = 1e-6 N m s/rad` is chosen here,
    /// scaled down with the motor (`B = 1e-3` would brake it with 0.8 N m at 400 Hz electrical,
    /// far more than its torque constant of 0.063 N m/A can sensibly counter).
    pub fn small_fast() -> Self {
        Self {
            rs_ohm: 0.12,
            ls_h: 0.15e-3,
            psi_f_wb: 0.006,
            pole_pairs: 7,
            j_kg_m2: 2e-5,
            b_nm_s_rad: 1e-6,
        }
    }

    /// The electrical parameters as the observer takes them.
    pub fn params(&self) -> MotorParams<f64> {
        MotorParams::from_f64(self.rs_ohm, self.ls_h, self.psi_f_wb, self.pole_pairs)
    }

    /// Pole pairs as `f64`.
    pub fn p(&self) -> f64 {
        f64::from(self.pole_pairs)
    }

    /// Torque constant `1.5 p psi_f`, N m per ampere of `i_q`.
    pub fn torque_constant_nm_a(&self) -> f64 {
        1.5 * self.p() * self.psi_f_wb
    }

    /// Checks that every parameter is finite and positive (`B` may be zero).
    pub fn validate(&self) -> Result<(), String> {
        let positive = [
            ("rs_ohm", self.rs_ohm),
            ("ls_h", self.ls_h),
            ("psi_f_wb", self.psi_f_wb),
            ("j_kg_m2", self.j_kg_m2),
        ];
        for (name, v) in positive {
            if !(v.is_finite() && v > 0.0) {
                return Err(format!("motor {name} must be finite and positive, is {v}"));
            }
        }
        if !(self.b_nm_s_rad.is_finite() && self.b_nm_s_rad >= 0.0) {
            return Err(format!(
                "motor b_nm_s_rad must be finite and >= 0, is {}",
                self.b_nm_s_rad
            ));
        }
        if self.pole_pairs == 0 {
            return Err("motor pole_pairs must be at least 1".into());
        }
        Ok(())
    }
}

/// State of the plant.
#[derive(Clone, Copy, Debug, Default, PartialEq, Serialize)]
pub struct PlantState {
    /// Alpha stator current, A.
    pub i_alpha_a: f64,
    /// Beta stator current, A.
    pub i_beta_a: f64,
    /// Mechanical rotor speed, rad/s.
    pub omega_mech_rad_s: f64,
    /// Electrical rotor angle, rad, in `[-pi, pi)`.
    pub theta_e_rad: f64,
}

/// The PMSM with its mechanics; one [`step`](Plant::step) per PWM period.
#[derive(Clone, Debug, PartialEq)]
pub struct Plant {
    motor: MotorModel,
    state: PlantState,
}

/// State as an array `[i_a, i_b, w_mech, th]` for the integrator.
type X = [f64; 4];

impl Plant {
    /// A plant at the given state (angle wrapped).
    pub fn new(motor: MotorModel, mut state: PlantState) -> Self {
        state.theta_e_rad = wrap_angle(state.theta_e_rad);
        Self { motor, state }
    }

    /// The motor.
    pub fn motor(&self) -> &MotorModel {
        &self.motor
    }

    /// The present state.
    pub fn state(&self) -> PlantState {
        self.state
    }

    /// Electrical speed `p w_mech`, rad/s.
    pub fn omega_e_rad_s(&self) -> f64 {
        self.motor.p() * self.state.omega_mech_rad_s
    }

    /// Electromagnetic torque at the present state, N m.
    pub fn torque_nm(&self) -> f64 {
        let s = &self.state;
        let (sin, cos) = s.theta_e_rad.sin_cos();
        self.motor.torque_constant_nm_a() * (s.i_beta_a * cos - s.i_alpha_a * sin)
    }

    /// Advances by `dt_s` with the stator voltage `u_ab` (V) and the load torque `t_load_nm`
    /// held constant, by RK4 over `substeps` equal sub-steps (at least one is taken).
    pub fn step(&mut self, u_ab: [f64; 2], t_load_nm: f64, dt_s: f64, substeps: u32) {
        let n = substeps.max(1);
        let h = dt_s / f64::from(n);
        let s = self.state;
        let mut x: X = [s.i_alpha_a, s.i_beta_a, s.omega_mech_rad_s, s.theta_e_rad];
        for _ in 0..n {
            x = self.rk4(&x, u_ab, t_load_nm, h);
            x[3] = wrap_angle(x[3]);
        }
        self.state = PlantState {
            i_alpha_a: x[0],
            i_beta_a: x[1],
            omega_mech_rad_s: x[2],
            theta_e_rad: x[3],
        };
    }

    /// Time derivative of the state.
    fn deriv(&self, x: &X, u: [f64; 2], t_load: f64) -> X {
        let m = &self.motor;
        let [ia, ib, wm, th] = *x;
        let we = m.p() * wm;
        let (s, c) = th.sin_cos();
        let te = m.torque_constant_nm_a() * (ib * c - ia * s);
        [
            (-m.rs_ohm * ia + we * m.psi_f_wb * s + u[0]) / m.ls_h,
            (-m.rs_ohm * ib - we * m.psi_f_wb * c + u[1]) / m.ls_h,
            (te - m.b_nm_s_rad * wm - t_load) / m.j_kg_m2,
            we,
        ]
    }

    /// One classic RK4 step of length `h`.
    fn rk4(&self, x: &X, u: [f64; 2], t_load: f64, h: f64) -> X {
        let add = |a: &X, k: &X, f: f64| -> X {
            [
                a[0] + f * k[0],
                a[1] + f * k[1],
                a[2] + f * k[2],
                a[3] + f * k[3],
            ]
        };
        let k1 = self.deriv(x, u, t_load);
        let k2 = self.deriv(&add(x, &k1, 0.5 * h), u, t_load);
        let k3 = self.deriv(&add(x, &k2, 0.5 * h), u, t_load);
        let k4 = self.deriv(&add(x, &k3, h), u, t_load);
        let mut out = *x;
        for i in 0..4 {
            out[i] += h / 6.0 * (k1[i] + 2.0 * k2[i] + 2.0 * k3[i] + k4[i]);
        }
        out
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    /// Drives the servo for 0.2 s at 10 kHz with a self-commutated voltage (`u_q = 60 V` at the
    /// start-of-period angle, `u_d = 0`), a load step of 0.5 N m at 0.1 s, and records the state.
    fn driven_run(substeps: u32) -> Vec<PlantState> {
        let ts = 1e-4;
        let mut plant = Plant::new(
            MotorModel::servo(),
            PlantState {
                theta_e_rad: 0.7,
                ..PlantState::default()
            },
        );
        let mut out = Vec::new();
        for k in 0..2000 {
            let th = plant.state().theta_e_rad;
            let (s, c) = th.sin_cos();
            let uq = 60.0;
            let u = [-uq * s, uq * c];
            let load = if k >= 1000 { 0.5 } else { 0.0 };
            plant.step(u, load, ts, substeps);
            out.push(plant.state());
        }
        out
    }

    #[test]
    fn ten_substeps_match_a_thousand_to_0p1_percent() {
        let coarse = driven_run(10);
        let fine = driven_run(1000);
        let i_max = fine
            .iter()
            .map(|s| s.i_alpha_a.hypot(s.i_beta_a))
            .fold(0.0, f64::max);
        let w_max = fine
            .iter()
            .map(|s| s.omega_mech_rad_s.abs())
            .fold(0.0, f64::max);
        // The run must really be driven: amperes of current, hundreds of rpm.
        assert!(i_max > 1.0 && w_max > 30.0, "i_max {i_max}, w_max {w_max}");
        for (k, (c, f)) in coarse.iter().zip(&fine).enumerate() {
            let di = (c.i_alpha_a - f.i_alpha_a).hypot(c.i_beta_a - f.i_beta_a);
            let dw = (c.omega_mech_rad_s - f.omega_mech_rad_s).abs();
            let dth = wrap_angle(c.theta_e_rad - f.theta_e_rad).abs();
            assert!(di <= 1e-3 * i_max, "k {k}: current differs by {di} A");
            assert!(dw <= 1e-3 * w_max, "k {k}: speed differs by {dw} rad/s");
            // 0.1 % of a full electrical turn.
            assert!(
                dth <= 1e-3 * core::f64::consts::TAU,
                "k {k}: angle differs by {dth}"
            );
        }
    }

    #[test]
    fn positive_q_current_turns_the_rotor_forward_and_the_angle_stays_wrapped() {
        let run = driven_run(10);
        assert!(
            run.iter()
                .all(|s| (-core::f64::consts::PI..core::f64::consts::PI).contains(&s.theta_e_rad))
        );
        let last = run[run.len() - 1];
        // Steady state without load: u_q ~ w_e psi + Rs i_q, so w_e a little below 60 / 0.175.
        let we = 4.0 * last.omega_mech_rad_s;
        assert!(we > 300.0 && we < 60.0 / 0.175, "w_e {we}");
    }

    #[test]
    fn reference_motors_validate() {
        for m in [
            MotorModel::servo(),
            MotorModel::industrial_2k2(),
            MotorModel::small_fast(),
        ] {
            assert_eq!(m.validate(), Ok(()));
            assert_eq!(m.params().validate(), Ok(()));
        }
    }
}
