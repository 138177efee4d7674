//! Motor parameters of a PMSM (surface or interior), with the reference motors of
//! [`crate::catalog`] as presets.

use crate::{ConfigError, Float, Param, catalog, to_t};

/// Electrical parameters of a PMSM (SI units): surface (`ld_h == lq_h`) or interior.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct MotorParams<T> {
    /// Stator resistance per phase, ohm.
    pub rs_ohm: T,
    /// d-axis (magnet axis) inductance per phase, henry.
    pub ld_h: T,
    /// q-axis inductance per phase, henry (`ld_h` for a surface PMSM).
    pub lq_h: T,
    /// Permanent-magnet flux linkage, weber (V s / rad electrical).
    pub psi_f_wb: T,
    /// Number of pole pairs; electrical speed = pole_pairs x mechanical speed.
    pub pole_pairs: u32,
}

/// What [`MotorParams::kind`] reports of the rotor's saliency.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum MotorKind {
    /// `Ld == Lq`: surface-mounted magnets, no reluctance torque.
    Surface,
    /// `Lq > Ld`: interior magnets (the usual IPMSM); MTPA drives a negative `i_d`.
    Interior,
    /// `Lq < Ld`: inversely salient (rare; e.g. some flux-intensifying designs). Accepted, but
    /// callers should report it: a datasheet with `Ld` and `Lq` swapped looks the same.
    InverseSalient,
}

/// Smallest accepted `Lq / Ld` ([`MotorParams::validate`]).
pub const MIN_SALIENCY_RATIO: f64 = 0.25;
/// Largest accepted `Lq / Ld` ([`MotorParams::validate`]); real IPMSMs are below about 4
/// (synchronous-reluctance-like rotors reach 5-8).
pub const MAX_SALIENCY_RATIO: f64 = 8.0;

/// Largest accepted stator resistance, ohm ([`MotorParams::validate`]).
pub const MAX_RS_OHM: f64 = 1e3;
/// Smallest accepted inductance, H.
pub const MIN_INDUCTANCE_H: f64 = 1e-8;
/// Largest accepted inductance, H.
pub const MAX_INDUCTANCE_H: f64 = 10.0;
/// Largest accepted flux linkage, Wb.
pub const MAX_PSI_F_WB: f64 = 100.0;
/// Largest accepted number of pole pairs.
pub const MAX_POLE_PAIRS: u32 = 1000;

/// The accepted range of a motor parameter, as text for errors (`None` for other
/// parameters).
pub(crate) fn plausible_range(p: Param) -> Option<&'static str> {
    match p {
        Param::Rs => Some("(0, 1000] ohm"),
        Param::Ld | Param::Lq => Some("[1e-8, 10] H"),
        Param::PsiF => Some("(0, 100] Wb"),
        Param::PolePairs => Some("1..=1000"),
        Param::Ts => Some("[1e-7, 1] s"),
        _ => None,
    }
}

impl<T: Float> MotorParams<T> {
    /// Servo motor, the textbook default ([`catalog::SERVO`]: Rs 2.875, Ls 8.5 mH,
    /// psi_f 0.175 Wb, 4 pole pairs).
    pub fn servo() -> Self {
        catalog::SERVO.params()
    }

    /// Industrial 2.2 kW motor, surface variant ([`catalog::INDUSTRIAL_2K2`]: Rs 3.6, Ls 36 mH,
    /// psi_f 0.545 Wb, 3 pole pairs).
    pub fn industrial_2k2() -> Self {
        catalog::INDUSTRIAL_2K2.params()
    }

    /// Small fast (drone class) motor ([`catalog::SMALL_FAST`]: Rs 0.12, Ls 0.15 mH,
    /// psi_f 6 mWb, 7 pole pairs).
    pub fn small_fast() -> Self {
        catalog::SMALL_FAST.params()
    }

    /// Industrial interior PMSM, 2.2 kW class ([`catalog::INDUSTRIAL_IPM`]: Rs 3.6, Ld 30 mH,
    /// Lq 42 mH, psi_f 0.50 Wb, 3 pole pairs).
    pub fn industrial_ipm() -> Self {
        catalog::INDUSTRIAL_IPM.params()
    }

    /// Strongly salient traction-class interior PMSM, 48 V ([`catalog::TRACTION_IPM`]:
    /// Rs 8 mohm, Ld 50 uH, Lq 150 uH, psi_f 12 mWb, 4 pole pairs).
    pub fn traction_ipm() -> Self {
        catalog::TRACTION_IPM.params()
    }

    /// Surface-PMSM parameters from `f64` values (`Ld = Lq = ls_h`).
    pub fn from_f64(rs_ohm: f64, ls_h: f64, psi_f_wb: f64, pole_pairs: u32) -> Self {
        Self::salient_from_f64(rs_ohm, ls_h, ls_h, psi_f_wb, pole_pairs)
    }

    /// Parameters of a salient (or surface, `ld_h == lq_h`) PMSM from `f64` values.
    pub fn salient_from_f64(
        rs_ohm: f64,
        ld_h: f64,
        lq_h: f64,
        psi_f_wb: f64,
        pole_pairs: u32,
    ) -> Self {
        Self {
            rs_ohm: to_t(rs_ohm),
            ld_h: to_t(ld_h),
            lq_h: to_t(lq_h),
            psi_f_wb: to_t(psi_f_wb),
            pole_pairs,
        }
    }

    /// Checks that Rs, Ld, Lq and psi_f are finite and positive, that `Lq / Ld` is within
    /// [`MIN_SALIENCY_RATIO`]..=[`MAX_SALIENCY_RATIO`] and that there is a pole pair; and that
    /// every value is one a motor can have: `Rs <= 1000` ohm, `1e-8 <= L <= 10` H,
    /// `psi_f <= 100` Wb, at most 1000 pole pairs ([`MAX_RS_OHM`], ...). Beyond these no
    /// drive this observer serves exists, and the scaled covariances would leave the range of
    /// `f32`.
    pub fn validate(&self) -> Result<(), ConfigError> {
        positive(self.rs_ohm, Param::Rs)?;
        positive(self.ld_h, Param::Ld)?;
        positive(self.lq_h, Param::Lq)?;
        positive(self.psi_f_wb, Param::PsiF)?;
        let within = |v: T, lo: f64, hi: f64, p: Param| {
            if v >= to_t::<T>(lo) && v <= to_t::<T>(hi) {
                Ok(())
            } else {
                Err(ConfigError::OutOfRange(p))
            }
        };
        within(self.rs_ohm, 0.0, MAX_RS_OHM, Param::Rs)?;
        within(self.ld_h, MIN_INDUCTANCE_H, MAX_INDUCTANCE_H, Param::Ld)?;
        within(self.lq_h, MIN_INDUCTANCE_H, MAX_INDUCTANCE_H, Param::Lq)?;
        within(self.psi_f_wb, 0.0, MAX_PSI_F_WB, Param::PsiF)?;
        if self.pole_pairs > MAX_POLE_PAIRS {
            return Err(ConfigError::OutOfRange(Param::PolePairs));
        }
        let ratio = self.lq_h / self.ld_h;
        if !(ratio >= to_t(MIN_SALIENCY_RATIO) && ratio <= to_t(MAX_SALIENCY_RATIO)) {
            return Err(ConfigError::OutOfRange(Param::Saliency));
        }
        if self.pole_pairs == 0 {
            return Err(ConfigError::ZeroPolePairs);
        }
        Ok(())
    }

    /// Surface, interior or inversely salient (exact comparison of `Ld` and `Lq`).
    pub fn kind(&self) -> MotorKind {
        if self.lq_h > self.ld_h {
            MotorKind::Interior
        } else if self.lq_h < self.ld_h {
            MotorKind::InverseSalient
        } else {
            MotorKind::Surface
        }
    }

    /// `Ld != Lq`.
    pub fn is_salient(&self) -> bool {
        self.ld_h != self.lq_h
    }

    /// Characteristic (short-circuit) current `psi_f / Lq`, ampere: the current scale in which
    /// the back-EMF's effect on the current per sample is simply `w_e Ts` (see [`crate::noise`];
    /// `Lq` is the inductance of the observer's active-flux model, `Ls` of a surface motor).
    pub fn characteristic_current_a(&self) -> T {
        self.psi_f_wb / self.lq_h
    }

    /// Electromagnetic torque, N m, at rotor-frame currents `(i_d, i_q)`:
    /// `1.5 p (psi_f i_q + (Ld - Lq) i_d i_q)` (magnet plus reluctance torque).
    pub fn torque_nm(&self, i_d: T, i_q: T) -> T {
        to_t::<T>(1.5)
            * to_t::<T>(f64::from(self.pole_pairs))
            * i_q
            * (self.psi_f_wb + (self.ld_h - self.lq_h) * i_d)
    }
}

/// `Ok` when `v` is finite and strictly positive.
pub(crate) fn positive<T: Float>(v: T, param: Param) -> Result<(), ConfigError> {
    if !v.is_finite() {
        Err(ConfigError::NonFinite(param))
    } else if v <= T::zero() {
        Err(ConfigError::NotPositive(param))
    } else {
        Ok(())
    }
}
