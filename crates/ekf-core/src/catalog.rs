//! The reference motors, each defined once (docs/design.md, "Reference motors"): electrical data,
//! mechanics, rated point and the drive they are run on. The observer's presets
//! ([`MotorParams::servo`], ...), the simulator's plant and scenarios (by [`ReferenceMotor::name`])
//! and the firmware read them from here.
//!
//! | name | Rs (Ohm) | Ld / Lq (H) | psi_f (Wb) | p | J (kg m^2) | B (N m s/rad) | bus (V) | PWM | rated |
//! |---|---|---|---|---|---|---|---|---|---|
//! | `servo` | 2.875 | 8.5e-3 | 0.175 | 4 | 8e-4 | 1e-3 | 300 | 10 kHz | 2000 rpm, 1.5 N m |
//! | `industrial_2k2` | 3.6 | 36e-3 | 0.545 | 3 | 0.015 | 1e-3 | 540 | 10 kHz | 1500 rpm, 10 N m |
//! | `small_fast` | 0.12 | 0.15e-3 | 0.006 | 7 | 2e-5 | 1e-6 | 48 | 10 kHz | 3429 rpm (400 Hz el.), 0.4 N m |
//! | `industrial_ipm` | 3.6 | 30e-3 / 42e-3 | 0.50 | 3 | 0.012 | 1e-3 | 540 | 10 kHz | 1500 rpm, 14 N m |
//! | `traction_ipm` | 0.008 | 50e-6 / 150e-6 | 0.012 | 4 | 2e-3 | 3e-4 | 48 | 20 kHz | 3000 rpm, 15 N m |
//!
//! Where a source gives no friction, `B` is chosen at about 1 % of the rated torque at rated
//! speed (0.6 % on the traction motor), scaled with the motor. The interior motors' rated
//! points lie on their MTPA line within the linear modulation limit: industrial IPM 6.16 A
//! (`i_d` -0.87 A), 275 of 312 V, base speed 1719 rpm at rated torque; traction IPM 148 A peak
//! (`i_d` -79 A, 40 % of the torque from reluctance), 26.7 of 27.7 V, base speed 3116 rpm.

use crate::{Float, MotorParams};

/// One reference motor: electrical and mechanical data, rated point, and its drive's bus
/// voltage and PWM period. All SI, `f64`; [`ReferenceMotor::params`] gives the observer's view.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct ReferenceMotor {
    /// Name used by scenarios and tables (`servo`, `industrial_2k2`, ...).
    pub name: &'static str,
    /// One line for listings.
    pub description: &'static str,
    /// Stator resistance per phase, ohm.
    pub rs_ohm: f64,
    /// d-axis inductance, henry.
    pub ld_h: f64,
    /// q-axis inductance, henry (`ld_h` for a surface motor).
    pub lq_h: f64,
    /// Magnet flux linkage, Wb.
    pub psi_f_wb: f64,
    /// Pole pairs.
    pub pole_pairs: u32,
    /// Rotor inertia (with any coupled load the references assume), kg m^2.
    pub j_kg_m2: f64,
    /// Viscous friction, N m s/rad.
    pub b_nm_s_rad: f64,
    /// Rated mechanical speed, rpm.
    pub rated_speed_rpm: f64,
    /// Rated torque, N m.
    pub rated_torque_nm: f64,
    /// DC bus voltage of its drive, V.
    pub u_dc_v: f64,
    /// PWM (control) period of its drive, s.
    pub ts_s: f64,
}

/// Servo motor, the textbook default.
pub const SERVO: ReferenceMotor = ReferenceMotor {
    name: "servo",
    description: "servo, surface PM, 300 V, 2000 rpm, 1.5 N m",
    rs_ohm: 2.875,
    ld_h: 8.5e-3,
    lq_h: 8.5e-3,
    psi_f_wb: 0.175,
    pole_pairs: 4,
    j_kg_m2: 8e-4,
    b_nm_s_rad: 1e-3,
    rated_speed_rpm: 2000.0,
    rated_torque_nm: 1.5,
    u_dc_v: 300.0,
    ts_s: 1e-4,
};

/// Industrial 2.2 kW motor, surface variant.
pub const INDUSTRIAL_2K2: ReferenceMotor = ReferenceMotor {
    name: "industrial_2k2",
    description: "industrial 2.2 kW, surface PM, 540 V, 1500 rpm, 10 N m",
    rs_ohm: 3.6,
    ld_h: 36e-3,
    lq_h: 36e-3,
    psi_f_wb: 0.545,
    pole_pairs: 3,
    j_kg_m2: 0.015,
    b_nm_s_rad: 1e-3,
    rated_speed_rpm: 1500.0,
    rated_torque_nm: 10.0,
    u_dc_v: 540.0,
    ts_s: 1e-4,
};

/// Small fast (drone class) motor: 400 Hz electrical at rated speed, `w Ts = 0.25` at 10 kHz.
pub const SMALL_FAST: ReferenceMotor = ReferenceMotor {
    name: "small_fast",
    description: "small fast (drone class), surface PM, 48 V, 3429 rpm, 0.4 N m",
    rs_ohm: 0.12,
    ld_h: 0.15e-3,
    lq_h: 0.15e-3,
    psi_f_wb: 0.006,
    pole_pairs: 7,
    j_kg_m2: 2e-5,
    b_nm_s_rad: 1e-6,
    rated_speed_rpm: 3429.0,
    rated_torque_nm: 0.4,
    u_dc_v: 48.0,
    ts_s: 1e-4,
};

/// Industrial interior PMSM, 2.2 kW class, `Lq / Ld = 1.4`.
pub const INDUSTRIAL_IPM: ReferenceMotor = ReferenceMotor {
    name: "industrial_ipm",
    description: "industrial interior PM (Lq/Ld 1.4), 540 V, 1500 rpm, 14 N m",
    rs_ohm: 3.6,
    ld_h: 30e-3,
    lq_h: 42e-3,
    psi_f_wb: 0.50,
    pole_pairs: 3,
    j_kg_m2: 0.012,
    b_nm_s_rad: 1e-3,
    rated_speed_rpm: 1500.0,
    rated_torque_nm: 14.0,
    u_dc_v: 540.0,
    ts_s: 1e-4,
};

/// Strongly salient traction-class interior PMSM, 48 V, `Lq / Ld = 3`.
pub const TRACTION_IPM: ReferenceMotor = ReferenceMotor {
    name: "traction_ipm",
    description: "traction interior PM (Lq/Ld 3), 48 V, 20 kHz, 3000 rpm, 15 N m",
    rs_ohm: 0.008,
    ld_h: 50e-6,
    lq_h: 150e-6,
    psi_f_wb: 0.012,
    pole_pairs: 4,
    j_kg_m2: 2e-3,
    b_nm_s_rad: 3e-4,
    rated_speed_rpm: 3000.0,
    rated_torque_nm: 15.0,
    u_dc_v: 48.0,
    ts_s: 5e-5,
};

/// Every reference motor, surface motors first.
pub const ALL: [ReferenceMotor; 5] = [
    SERVO,
    INDUSTRIAL_2K2,
    SMALL_FAST,
    INDUSTRIAL_IPM,
    TRACTION_IPM,
];

/// The reference motor of a name (`servo`, `industrial_2k2`, `small_fast`, `industrial_ipm`,
/// `traction_ipm`; `-` and `_` alike).
pub fn by_name(name: &str) -> Option<&'static ReferenceMotor> {
    ALL.iter().find(|m| {
        m.name.len() == name.len()
            && m.name
                .bytes()
                .zip(name.bytes())
                .all(|(a, b)| a == b || (a == b'_' && b == b'-'))
    })
}

impl ReferenceMotor {
    /// The electrical parameters in the filter's precision (each value rounded once from
    /// `f64`).
    pub fn params<T: Float>(&self) -> MotorParams<T> {
        MotorParams::salient_from_f64(
            self.rs_ohm,
            self.ld_h,
            self.lq_h,
            self.psi_f_wb,
            self.pole_pairs,
        )
    }

    /// Rated electrical speed, rad/s.
    pub fn rated_omega_e_rad_s(&self) -> f64 {
        self.rated_speed_rpm * core::f64::consts::TAU / 60.0 * f64::from(self.pole_pairs)
    }

    /// `Ld != Lq`.
    pub fn is_interior(&self) -> bool {
        self.ld_h != self.lq_h
    }
}

/// Motor data from a datasheet, converted to the per-phase, amplitude-invariant quantities
/// the model uses (docs/design.md, "Conventions").
///
/// Conventions (state them when you copy a datasheet):
/// - `R` and `L` are often given **line to line** (measured between two terminals of a star
///   winding): the per-phase values are half of them.
/// - `Kv` in rpm per volt is usually the mechanical speed per volt of **line-to-line peak**
///   back-EMF (hobby motors, e.g. VESC and ODrive use it this way). Then the peak phase EMF
///   is `w_mech p psi_f = w_mech / (Kv_rad sqrt(3))`, so `psi_f = 60 / (sqrt(3) 2 pi Kv p)`.
/// - `Kt` in N m per ampere is per **peak phase** (amplitude-invariant `i_q`) current:
///   `T = 1.5 p psi_f i_q`, so `psi_f = Kt / (1.5 p)`. A datasheet that gives `Kt` per RMS
///   ampere needs `Kt_rms / sqrt(2)` first.
/// - For a surface motor `L_ll / 2` gives `Ld = Lq`; an interior motor's datasheet gives `Ld`
///   and `Lq` (per phase) or `L_ll` min and max over the rotor angle (`Ld = min / 2`,
///   `Lq = max / 2`).
pub mod datasheet {
    /// Flux linkage, Wb, from `Kv` in rpm per volt (line-to-line peak back-EMF per mechanical
    /// speed) and the pole pairs: `60 / (sqrt(3) 2 pi Kv p)`.
    pub fn psi_f_from_kv(kv_rpm_per_v: f64, pole_pairs: u32) -> f64 {
        60.0 / (SQRT_3 * core::f64::consts::TAU * kv_rpm_per_v * f64::from(pole_pairs))
    }

    /// Flux linkage, Wb, from `Kt` in N m per peak phase ampere: `Kt / (1.5 p)`.
    pub fn psi_f_from_kt(kt_nm_per_a: f64, pole_pairs: u32) -> f64 {
        kt_nm_per_a / (1.5 * f64::from(pole_pairs))
    }

    /// Per-phase value (resistance or inductance) of a star winding from its line-to-line
    /// value: half of it.
    pub fn phase_from_line_to_line(value_ll: f64) -> f64 {
        0.5 * value_ll
    }

    /// `sqrt(3)` (`core` has no square root without `std`).
    const SQRT_3: f64 = 1.732_050_807_568_877_2;
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn names_are_unique_and_found() {
        for m in ALL {
            assert_eq!(by_name(m.name).map(|r| r.name), Some(m.name));
            assert_eq!(
                by_name(&m.name.replace('_', "-")).map(|r| r.name),
                Some(m.name)
            );
            assert!(m.params::<f64>().validate().is_ok(), "{}", m.name);
        }
        assert!(by_name("servo2").is_none());
    }

    #[test]
    fn datasheet_conversions_round_trip() {
        // A servo with psi_f 0.175 Wb, 4 pole pairs: Kt = 1.5 * 4 * 0.175 = 1.05 N m/A.
        let psi = datasheet::psi_f_from_kt(1.05, 4);
        assert!((psi - 0.175).abs() < 1e-12);
        // Kv: line-to-line peak EMF per mechanical rad/s = sqrt(3) p psi_f.
        let kv = 60.0 / (core::f64::consts::TAU * 3f64.sqrt() * 4.0 * 0.175);
        assert!((datasheet::psi_f_from_kv(kv, 4) - 0.175).abs() < 1e-12);
        assert_eq!(datasheet::phase_from_line_to_line(5.75), 2.875);
    }
}
