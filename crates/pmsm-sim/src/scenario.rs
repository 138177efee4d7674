//! Scenarios: everything one simulation run needs, and the built-in default.
//!
//! A [`Scenario`] is plain data (motor, drive, sensor, initial state, reference and load
//! profiles); later it will be read from TOML files, for now [`Scenario::default_servo`] is
//! built in.
//!
//! # The default scenario ([`Scenario::default_servo`])
//!
//! Servo motor of `design.md` section 6 at 10 kHz, 1.5 s:
//!
//! | time (s)    | speed reference (mech.)          | load torque |
//! |-------------|----------------------------------|-------------|
//! | 0 - 0.05    | 0 (standstill)                   | 0           |
//! | 0.05 - 0.35 | ramp 0 -> 2000 rpm               | 0           |
//! | 0.35 - 0.6  | 2000 rpm                         | 0           |
//! | 0.6         |                                  | step to 1.5 N m |
//! | 0.9 - 1.2   | ramp 2000 -> -1000 rpm (reversal) | 1.5 N m     |
//! | 1.2 - 1.5   | -1000 rpm (-50 % of rated)       | 1.5 N m     |
//!
//! Choices and checks:
//!
//! - **DC link 300 V**, so the voltage limit is `300 / sqrt(3) = 173.2 V`.
//! - **Rated speed 2000 rpm** (mechanical), not 3000: at 3000 rpm the back-EMF
//!   `w_e psi_f = 1257 rad/s x 0.175 Wb = 220 V` exceeds 173 V, and there is no field weakening.
//!   At 2000 rpm `w_e = 838 rad/s`, EMF 146.6 V; with rated current
//!   `|u| = |(Rs i_q + w_e psi_f, -w_e Ls i_q)| = |(150.7, -10.2)| = 151 V`, 87 % of the limit.
//! - **Rated torque 1.5 N m**: `k_t = 1.5 p psi_f = 1.05 N m/A`, so 1.43 A of `i_q`.
//!   The current limit (the speed loop's clamp) is **3 A**, about twice that, leaving 1.57 A
//!   for acceleration under load.
//! - The load is an **active** (constant) torque, like a hanging mass: it stays on through the
//!   reversal, so at -1000 rpm the drive brakes it (generating).
//! - The rotor starts at rest at `theta_e = 1.0 rad`; the observer starts at its default
//!   `x0 = 0`, so it has to find the angle once the rotor turns (at standstill the angle of a
//!   surface PMSM is unobservable).
//! - Current sensor noise 0.02 A standard deviation, seed 1.
//! - Current loop bandwidth `2 pi 500 rad/s`, speed loop crossover `2 pi 20 rad/s`.

use core::f64::consts::PI;

use serde::Serialize;

use crate::controller::ControllerConfig;
use crate::plant::MotorModel;

/// rpm per rad/s.
pub const RPM_PER_RAD_S: f64 = 30.0 / PI;

/// How a [`Profile`] is read between its points.
#[derive(Clone, Copy, Debug, PartialEq, Eq, Serialize)]
pub enum Interpolation {
    /// Linear between points (ramps).
    Linear,
    /// The value of the last point at or before the time (steps).
    Step,
}

/// A time profile given by points `(t_s, value)`, times non-decreasing. Before the first point
/// it holds the first value, after the last the last value; with no point it is zero.
#[derive(Clone, Debug, PartialEq, Serialize)]
pub struct Profile {
    /// The points `(time s, value)`.
    pub points: Vec<(f64, f64)>,
    /// Reading between points.
    pub interpolation: Interpolation,
}

impl Profile {
    /// A piecewise-linear profile.
    pub fn linear(points: Vec<(f64, f64)>) -> Self {
        Self {
            points,
            interpolation: Interpolation::Linear,
        }
    }

    /// A piecewise-constant profile.
    pub fn steps(points: Vec<(f64, f64)>) -> Self {
        Self {
            points,
            interpolation: Interpolation::Step,
        }
    }

    /// The value at `t_s`.
    pub fn at(&self, t_s: f64) -> f64 {
        let pts = &self.points;
        let Some(&(t0, v0)) = pts.first() else {
            return 0.0;
        };
        if t_s < t0 {
            return v0;
        }
        // Index of the last point at or before t.
        let idx = pts.partition_point(|&(t, _)| t <= t_s) - 1;
        let (ta, va) = pts[idx];
        match (self.interpolation, pts.get(idx + 1)) {
            (Interpolation::Linear, Some(&(tb, vb))) if tb > ta => {
                va + (vb - va) * (t_s - ta) / (tb - ta)
            }
            _ => va,
        }
    }

    /// Checks that every number is finite and times do not decrease.
    pub fn validate(&self, name: &str) -> Result<(), String> {
        for (i, &(t, v)) in self.points.iter().enumerate() {
            if !t.is_finite() || !v.is_finite() {
                return Err(format!("{name}: point {i} is not finite"));
            }
            if i > 0 && t < self.points[i - 1].0 {
                return Err(format!("{name}: point {i} goes back in time"));
            }
        }
        Ok(())
    }
}

/// The drive: inverter, control period and controller tuning.
#[derive(Clone, Copy, Debug, PartialEq, Serialize)]
pub struct DriveConfig {
    /// PWM and control period, s.
    pub ts_s: f64,
    /// RK4 sub-steps of the plant per PWM period.
    pub substeps: u32,
    /// DC-link voltage, V.
    pub u_dc_v: f64,
    /// The speed loop's current limit, A.
    pub current_limit_a: f64,
    /// Current loop bandwidth, rad/s.
    pub current_bw_rad_s: f64,
    /// Speed loop crossover, rad/s.
    pub speed_bw_rad_s: f64,
}

/// The current sensor.
#[derive(Clone, Copy, Debug, PartialEq, Serialize)]
pub struct SensorConfig {
    /// Noise standard deviation on each alpha-beta current, A.
    pub current_noise_std_a: f64,
    /// Seed of the noise generator.
    pub seed: u64,
}

/// One simulation run's description.
#[derive(Clone, Debug, PartialEq, Serialize)]
pub struct Scenario {
    /// Name shown in reports.
    pub name: String,
    /// The motor (plant; the controller and the observer are given the same parameters).
    pub motor: MotorModel,
    /// Inverter and controller.
    pub drive: DriveConfig,
    /// Current sensor.
    pub sensor: SensorConfig,
    /// Simulated time, s.
    pub duration_s: f64,
    /// Rated mechanical speed, rpm (metrics: the 5 % low-speed exclusion, speed error in %).
    pub rated_speed_rpm: f64,
    /// Rated torque, N m (documentation of the scenario; the load profile uses it).
    pub rated_torque_nm: f64,
    /// Electrical rotor angle at `t = 0`, rad (the rotor starts at rest).
    pub initial_theta_e_rad: f64,
    /// Mechanical speed reference, rpm.
    pub speed_ref_rpm: Profile,
    /// Load torque, N m (positive brakes positive rotation).
    pub load_torque_nm: Profile,
    /// Also run the seed's filter (`ObserverConfig::seed`) alongside, for comparison.
    pub run_seed_filter: bool,
}

impl Scenario {
    /// The built-in default scenario (module docs).
    pub fn default_servo() -> Self {
        let rated_rpm = 2000.0;
        let rated_torque = 1.5;
        Self {
            name: "default: servo, 10 kHz, ramp / load step / reversal".into(),
            motor: MotorModel::servo(),
            drive: DriveConfig {
                ts_s: 1e-4,
                substeps: 10,
                u_dc_v: 300.0,
                current_limit_a: 3.0,
                current_bw_rad_s: 2.0 * PI * 500.0,
                speed_bw_rad_s: 2.0 * PI * 20.0,
            },
            sensor: SensorConfig {
                current_noise_std_a: 0.02,
                seed: 1,
            },
            duration_s: 1.5,
            rated_speed_rpm: rated_rpm,
            rated_torque_nm: rated_torque,
            initial_theta_e_rad: 1.0,
            speed_ref_rpm: Profile::linear(vec![
                (0.05, 0.0),
                (0.35, rated_rpm),
                (0.9, rated_rpm),
                (1.2, -0.5 * rated_rpm),
            ]),
            load_torque_nm: Profile::steps(vec![(0.0, 0.0), (0.6, rated_torque)]),
            run_seed_filter: true,
        }
    }

    /// The same scenario cut to `duration_s` (profiles unchanged).
    pub fn with_duration(mut self, duration_s: f64) -> Self {
        self.duration_s = duration_s;
        self
    }

    /// Rated mechanical speed, rad/s.
    pub fn rated_speed_mech_rad_s(&self) -> f64 {
        self.rated_speed_rpm / RPM_PER_RAD_S
    }

    /// Rated electrical speed, rad/s.
    pub fn rated_speed_e_rad_s(&self) -> f64 {
        self.rated_speed_mech_rad_s() * self.motor.p()
    }

    /// Number of PWM periods simulated, `round(duration / Ts)`.
    pub fn periods(&self) -> usize {
        // Validated finite and positive before use; `as` saturates otherwise.
        (self.duration_s / self.drive.ts_s).round() as usize
    }

    /// The controller's configuration.
    pub fn controller_config(&self) -> ControllerConfig {
        let d = &self.drive;
        ControllerConfig::tuned(
            &self.motor,
            d.ts_s,
            d.u_dc_v,
            d.current_limit_a,
            d.current_bw_rad_s,
            d.speed_bw_rad_s,
        )
    }

    /// Checks the scenario before a run.
    pub fn validate(&self) -> Result<(), String> {
        self.motor.validate()?;
        let d = &self.drive;
        let positive = [
            ("drive.ts_s", d.ts_s),
            ("drive.u_dc_v", d.u_dc_v),
            ("drive.current_limit_a", d.current_limit_a),
            ("drive.current_bw_rad_s", d.current_bw_rad_s),
            ("drive.speed_bw_rad_s", d.speed_bw_rad_s),
            ("duration_s", self.duration_s),
            ("rated_speed_rpm", self.rated_speed_rpm),
            ("rated_torque_nm", self.rated_torque_nm),
        ];
        for (name, v) in positive {
            if !(v.is_finite() && v > 0.0) {
                return Err(format!("{name} must be finite and positive, is {v}"));
            }
        }
        if d.substeps == 0 {
            return Err("drive.substeps must be at least 1".into());
        }
        let s = self.sensor.current_noise_std_a;
        if !(s.is_finite() && s >= 0.0) {
            return Err(format!(
                "sensor.current_noise_std_a must be finite and >= 0, is {s}"
            ));
        }
        if !self.initial_theta_e_rad.is_finite() {
            return Err("initial_theta_e_rad must be finite".into());
        }
        if self.periods() == 0 {
            return Err("duration_s is shorter than half a PWM period".into());
        }
        if self.duration_s / d.ts_s > 1e9 {
            return Err("duration_s / ts_s exceeds 1e9 periods".into());
        }
        self.speed_ref_rpm.validate("speed_ref_rpm")?;
        self.load_torque_nm.validate("load_torque_nm")?;
        Ok(())
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn profiles_interpolate_and_hold() {
        let p = Profile::linear(vec![(1.0, 0.0), (2.0, 10.0), (2.0, 20.0), (3.0, 20.0)]);
        assert_eq!(p.at(0.0), 0.0);
        assert_eq!(p.at(1.5), 5.0);
        assert_eq!(p.at(2.0), 20.0);
        assert_eq!(p.at(9.0), 20.0);
        let s = Profile::steps(vec![(0.0, 1.0), (0.5, 2.0)]);
        assert_eq!(s.at(0.49), 1.0);
        assert_eq!(s.at(0.5), 2.0);
        assert_eq!(Profile::steps(vec![]).at(3.0), 0.0);
        assert!(
            Profile::linear(vec![(1.0, 0.0), (0.5, 0.0)])
                .validate("x")
                .is_err()
        );
    }

    #[test]
    fn default_scenario_is_valid_and_within_the_voltage_limit() {
        let sc = Scenario::default_servo();
        assert_eq!(sc.validate(), Ok(()));
        assert_eq!(sc.periods(), 15_000);
        let m = sc.motor;
        let we = sc.rated_speed_e_rad_s();
        let iq = sc.rated_torque_nm / m.torque_constant_nm_a();
        assert!(iq < sc.drive.current_limit_a);
        let u = (m.rs_ohm * iq + we * m.psi_f_wb).hypot(we * m.ls_h * iq);
        let u_lim = sc.controller_config().voltage_limit_v();
        assert!(u < 0.9 * u_lim, "{u} V of {u_lim} V");
    }
}
