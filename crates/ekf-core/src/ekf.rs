//! A generic extended Kalman filter on statically sized `nalgebra` matrices.
//!
//! The process model and the measurement model are separate traits
//! ([`ProcessModel`], [`MeasurementModel`]); the filter ([`Ekf`]) owns only the state estimate
//! `x` (`NX`), its covariance `P` (`NX x NX`) and the diagnostics of the last correction.
//! Predict and correct are separate calls, so a caller may predict several times between
//! measurements, or coast (predict only) over a missing sample.
//!
//! Equations (seed flow, steps 1-6, with the errata of `docs/design.md` section 2 applied):
//!
//! ```text
//! predict:  x- = f_d(x, u)                      (step 1)
//!           Phi = d f_d / d x  at (x, u)        (step 2)
//!           P- = Phi P Phi^T + Q                 (step 3)
//! correct:  y = z - h(x-)                        (innovation)
//!           S = H P- H^T + R                     (innovation covariance, NZ x NZ)
//!           K = P- H^T S^-1                      (step 4)
//!           x = x- + K y                         (step 5)
//!           P = (I - K H) P- (I - K H)^T + K R K^T   (Joseph form), or
//!           P = (I - K H) P-                     (standard form, step 6)
//!           NIS = y^T S^-1 y
//! ```
//!
//! Both covariance updates end by forcing symmetry, `P = (P + P^T) / 2`; so does the prediction.
//!
//! Nothing here panics, and a call that fails (non-finite input, singular `S`, a result that is
//! not finite) returns an [`EkfError`] and leaves the state and covariance exactly as they were.

use core::fmt;

use nalgebra::{SMatrix, SVector};

use crate::Float;

/// How the posterior covariance is computed in [`Ekf::correct`].
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq)]
pub enum CovarianceUpdate {
    /// Joseph form `P = (I - K H) P- (I - K H)^T + K R K^T`, then forced symmetry.
    ///
    /// Keeps `P` positive semi-definite under rounding and for any gain; the safe default.
    #[default]
    Joseph,
    /// Standard form `P = (I - K H) P-` (seed step 6), then forced symmetry `(P + P^T) / 2`.
    ///
    /// Cheaper; exact only for the optimal gain, and it can lose definiteness in single precision
    /// when `R` is tiny compared with `H P- H^T`.
    StandardSymmetrized,
}

/// Why a call to [`Ekf::predict`] or [`Ekf::correct`] was refused. The filter is unchanged.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum EkfError {
    /// The input `u` holds a NaN or an infinity.
    NonFiniteInput,
    /// The measurement `z` holds a NaN or an infinity.
    NonFiniteMeasurement,
    /// The innovation covariance `S = H P- H^T + R` could not be inverted.
    SingularInnovation,
    /// The computed state or covariance was not finite (e.g. overflow); the step was discarded.
    NonFiniteResult,
    /// The period given for an irregular step is not finite, not above zero, or longer than
    /// [`MAX_PERIOD_FACTOR`](crate::observer::MAX_PERIOD_FACTOR) sample times.
    InvalidPeriod,
    /// The input voltage is finite but beyond anything a drive applies: held over one sample
    /// time it would move the stator flux by more than
    /// [`MAX_INPUT_FLUX_RATIO`](crate::observer::MAX_INPUT_FLUX_RATIO) times the magnet's
    /// flux (a corrupted sample in a log or on a bus).
    ImplausibleInput,
    /// The measured current is finite but beyond anything a motor carries:
    /// [`MAX_CURRENT_RATIO`](crate::observer::MAX_CURRENT_RATIO) times its characteristic
    /// current `psi_f / L` (a corrupted sample).
    ImplausibleMeasurement,
}

impl fmt::Display for EkfError {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        f.write_str(match self {
            EkfError::NonFiniteInput => "input is not finite (NaN or infinity); step rejected",
            EkfError::NonFiniteMeasurement => {
                "measurement is not finite (NaN or infinity); step rejected"
            }
            EkfError::SingularInnovation => {
                "innovation covariance S = H P H^T + R is singular; step rejected"
            }
            EkfError::NonFiniteResult => "the update produced a non-finite state or covariance",
            EkfError::InvalidPeriod => {
                "the period is not finite, not above zero, or too long; step rejected"
            }
            EkfError::ImplausibleMeasurement => {
                "the measured current is beyond anything a motor carries (a corrupted sample); \
                 step rejected"
            }
            EkfError::ImplausibleInput => {
                "the input voltage is beyond anything a drive applies (a corrupted sample); \
                 step rejected"
            }
        })
    }
}

impl core::error::Error for EkfError {}

/// Discrete process model `x_{k+1} = f_d(x_k, u_k)` with its Jacobian.
///
/// `NX` is the state dimension, `NU` the input dimension.
pub trait ProcessModel<T: Float, const NX: usize, const NU: usize> {
    /// The predicted state `f_d(x, u)` (`NX`) and the transition Jacobian
    /// `Phi = d f_d / d x` (`NX x NX`), both evaluated at the prior state `x`.
    fn transition(
        &self,
        x: &SVector<T, NX>,
        u: &SVector<T, NU>,
    ) -> (SVector<T, NX>, SMatrix<T, NX, NX>);

    /// The process noise covariance `Q` (`NX x NX`) added per step.
    fn process_noise(&self) -> &SMatrix<T, NX, NX>;

    /// Brings a state back to its canonical range after a step (e.g. wraps an angle).
    /// The default does nothing.
    fn normalize(&self, _x: &mut SVector<T, NX>) {}
}

/// Measurement model `z = h(x) + v`, `v ~ N(0, R)`.
///
/// `NX` is the state dimension, `NZ` the measurement dimension.
pub trait MeasurementModel<T: Float, const NX: usize, const NZ: usize> {
    /// The predicted measurement `h(x)` (`NZ`) and its Jacobian `H = d h / d x` (`NZ x NX`).
    fn observe(&self, x: &SVector<T, NX>) -> (SVector<T, NZ>, SMatrix<T, NZ, NX>);

    /// The measurement noise covariance `R` (`NZ x NZ`).
    fn measurement_noise(&self) -> &SMatrix<T, NZ, NZ>;

    /// The innovation `z - h(x)`; override it for measurements on a circle.
    fn residual(&self, z: &SVector<T, NZ>, predicted: &SVector<T, NZ>) -> SVector<T, NZ> {
        z - predicted
    }

    /// Brings a state back to its canonical range after a correction. The default does nothing.
    fn normalize(&self, _x: &mut SVector<T, NX>) {}
}

/// Diagnostics of one correction.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Correction<T: Float, const NZ: usize> {
    /// Innovation `y = z - h(x-)` (`NZ`).
    pub innovation: SVector<T, NZ>,
    /// Innovation covariance `S = H P- H^T + R` (`NZ x NZ`).
    pub innovation_covariance: SMatrix<T, NZ, NZ>,
    /// Normalized innovation squared `y^T S^-1 y`; chi-square with `NZ` degrees of freedom
    /// when the filter is consistent.
    pub nis: T,
}

/// Extended Kalman filter state: estimate `x` (`NX`), covariance `P` (`NX x NX`), and the
/// diagnostics of the last correction (`NZ`).
#[derive(Clone, Debug, PartialEq)]
pub struct Ekf<T: Float, const NX: usize, const NZ: usize> {
    x: SVector<T, NX>,
    p: SMatrix<T, NX, NX>,
    update: CovarianceUpdate,
    last: Correction<T, NZ>,
}

/// `true` when every entry is finite.
pub(crate) fn all_finite<T: Float, const R: usize, const C: usize>(m: &SMatrix<T, R, C>) -> bool {
    finite(m.as_slice())
}

/// `true` when every value is finite (the branches are always taken the same way on good
/// data, so they cost next to nothing).
#[inline]
pub(crate) fn finite<T: Float>(v: &[T]) -> bool {
    v.iter().all(|x| x.is_finite())
}

/// `(m + m^T) / 2`.
fn symmetrize<T: Float, const N: usize>(m: &SMatrix<T, N, N>) -> SMatrix<T, N, N> {
    // Halved before the sum: the same result for normal numbers, no overflow near `MAX`.
    let h = T::from_subset(&0.5);
    m * h + m.transpose() * h
}

impl<T: Float, const NX: usize, const NZ: usize> Ekf<T, NX, NZ> {
    /// A filter whose estimate is `x0` with covariance `p0`.
    ///
    /// `p0` is used as given (made symmetric); validating it is the caller's job (the PMSM
    /// observer does it in its constructor).
    pub fn new(x0: SVector<T, NX>, p0: SMatrix<T, NX, NX>, update: CovarianceUpdate) -> Self {
        Self {
            x: x0,
            p: symmetrize(&p0),
            update,
            last: Correction {
                innovation: SVector::zeros(),
                innovation_covariance: SMatrix::zeros(),
                nis: T::zero(),
            },
        }
    }

    /// The state estimate `x` (`NX`).
    pub fn state(&self) -> &SVector<T, NX> {
        &self.x
    }

    /// The state covariance `P` (`NX x NX`).
    pub fn covariance(&self) -> &SMatrix<T, NX, NX> {
        &self.p
    }

    /// The covariance update method in use.
    pub fn covariance_update(&self) -> CovarianceUpdate {
        self.update
    }

    /// Diagnostics of the last successful correction (zeros before the first one).
    pub fn last_correction(&self) -> &Correction<T, NZ> {
        &self.last
    }

    /// Replaces the estimate and its covariance (made symmetric). Refused, and nothing
    /// changed, when either is not finite.
    pub fn reset(&mut self, x: SVector<T, NX>, p: SMatrix<T, NX, NX>) -> Result<(), EkfError> {
        if !all_finite(&x) || !all_finite(&p) {
            return Err(EkfError::NonFiniteResult);
        }
        self.x = x;
        self.p = symmetrize(&p);
        Ok(())
    }

    /// Time update with input `u` (`NU`): `x- = f_d(x, u)`, `P- = Phi P Phi^T + Q`.
    pub fn predict<M, const NU: usize>(
        &mut self,
        model: &M,
        u: &SVector<T, NU>,
    ) -> Result<(), EkfError>
    where
        M: ProcessModel<T, NX, NU> + ?Sized,
    {
        if !all_finite(u) {
            return Err(EkfError::NonFiniteInput);
        }
        let (mut x, phi) = model.transition(&self.x, u);
        let p = symmetrize(&(phi * self.p * phi.transpose() + model.process_noise()));
        model.normalize(&mut x);
        if !all_finite(&x) || !all_finite(&p) {
            return Err(EkfError::NonFiniteResult);
        }
        self.x = x;
        self.p = p;
        Ok(())
    }

    /// Measurement update with `z` (`NZ`); returns the innovation, `S` and the NIS.
    pub fn correct<M>(
        &mut self,
        model: &M,
        z: &SVector<T, NZ>,
    ) -> Result<Correction<T, NZ>, EkfError>
    where
        M: MeasurementModel<T, NX, NZ> + ?Sized,
    {
        if !all_finite(z) {
            return Err(EkfError::NonFiniteMeasurement);
        }
        let (z_pred, h) = model.observe(&self.x);
        let y = model.residual(z, &z_pred);
        let r = model.measurement_noise();
        let pht = self.p * h.transpose();
        let s = h * pht + r;
        let s_inv = s.try_inverse().ok_or(EkfError::SingularInnovation)?;
        if !all_finite(&s_inv) {
            return Err(EkfError::SingularInnovation);
        }
        let k = pht * s_inv;
        let mut x = self.x + k * y;
        let p = match self.update {
            CovarianceUpdate::Joseph => {
                let ikh = SMatrix::<T, NX, NX>::identity() - k * h;
                ikh * self.p * ikh.transpose() + k * r * k.transpose()
            }
            CovarianceUpdate::StandardSymmetrized => self.p - k * (h * self.p),
        };
        let p = symmetrize(&p);
        let nis = y.dot(&(s_inv * y));
        model.normalize(&mut x);
        if !all_finite(&x) || !all_finite(&p) || !nis.is_finite() {
            return Err(EkfError::NonFiniteResult);
        }
        self.x = x;
        self.p = p;
        self.last = Correction {
            innovation: y,
            innovation_covariance: s,
            nis,
        };
        Ok(self.last)
    }
}
