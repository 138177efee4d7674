//! Motor parameters of a surface-mounted PMSM, and the reference motors of `design.md` section 6.

use crate::{ConfigError, Float, Param, to_t};

/// Electrical parameters of a surface-mounted PMSM (SI units).
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct MotorParams<T> {
    /// Stator resistance per phase, ohm.
    pub rs_ohm: T,
    /// Stator inductance per phase (Ld = Lq), henry.
    pub ls_h: T,
    /// Permanent-magnet flux linkage, weber (V s / rad electrical).
    pub psi_f_wb: T,
    /// Number of pole pairs; electrical speed = pole_pairs x mechanical speed.
    pub pole_pairs: u32,
}

impl<T: Float> MotorParams<T> {
    /// Servo motor, the textbook default of `design.md` section 6 (Rs 2.875, Ls 8.5 mH,
    /// psi_f 0.175 Wb, 4 pole pairs).
    pub fn servo() -> Self {
        Self::from_f64(2.875, 8.5e-3, 0.175, 4)
    }

    /// Industrial 2.2 kW motor, surface variant (Rs 3.6, Ls 36 mH, psi_f 0.545 Wb, 3 pole pairs).
    pub fn industrial_2k2() -> Self {
        Self::from_f64(3.6, 36e-3, 0.545, 3)
    }

    /// Small fast (drone class) motor (Rs 0.12, Ls 0.15 mH, psi_f 6 mWb, 7 pole pairs).
    pub fn small_fast() -> Self {
        Self::from_f64(0.12, 0.15e-3, 0.006, 7)
    }

    /// Parameters from `f64` values.
    pub fn from_f64(rs_ohm: f64, ls_h: f64, psi_f_wb: f64, pole_pairs: u32) -> Self {
        Self {
            rs_ohm: to_t(rs_ohm),
            ls_h: to_t(ls_h),
            psi_f_wb: to_t(psi_f_wb),
            pole_pairs,
        }
    }

    /// Checks that Rs, Ls and psi_f are finite and positive and that there is a pole pair.
    pub fn validate(&self) -> Result<(), ConfigError> {
        positive(self.rs_ohm, Param::Rs)?;
        positive(self.ls_h, Param::Ls)?;
        positive(self.psi_f_wb, Param::PsiF)?;
        if self.pole_pairs == 0 {
            return Err(ConfigError::ZeroPolePairs);
        }
        Ok(())
    }

    /// Characteristic (short-circuit) current `psi_f / Ls`, ampere: the current scale in which
    /// the back-EMF's effect on the current per sample is simply `w_e Ts` (see [`crate::noise`]).
    pub fn characteristic_current_a(&self) -> T {
        self.psi_f_wb / self.ls_h
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
