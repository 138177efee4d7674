//! Speed noise adaptation: the process noise of the speed raised while the innovations are
//! larger than a consistent filter's ([`SpeedNoiseAdaptation`]; the method is in the module
//! docs of [`observer`](crate::observer), "Speed noise adaptation").

use crate::error::Param;
use crate::motor::positive;
use crate::{ConfigError, Float, to_t};

/// Configuration of the speed noise adaptation (module docs of
/// [`observer`](crate::observer)): `Q_ww` is multiplied by
/// `clamp((m / nis_reference)^2, 1, max_factor)`, where `m` is a running mean of the NIS over
/// `samples` steps.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct SpeedNoiseAdaptation<T> {
    /// Samples of the NIS mean's time constant (at least 1).
    pub samples: T,
    /// NIS mean at or below which `Q` is the configured one (a consistent filter's mean is 2).
    pub nis_reference: T,
    /// Largest factor on `Q_ww` (at least 1).
    pub max_factor: T,
}

impl<T: Float> Default for SpeedNoiseAdaptation<T> {
    /// `samples = 8`, `nis_reference = 4`, `max_factor = 10^4`: `Q_ww` is untouched while the
    /// innovations' mean is at most twice a consistent filter's, and its standard deviation
    /// grows at most 100 times (the default `Q_ww` allows `2e-4` rad of `w Ts` change per
    /// sample; raised 100 times, `0.02`: a motor at 4.5 kHz reaching 5000 rad/s in 25 ms).
    fn default() -> Self {
        Self {
            samples: to_t(8.0),
            nis_reference: to_t(4.0),
            max_factor: to_t(1e4),
        }
    }
}

impl<T: Float> SpeedNoiseAdaptation<T> {
    /// Checks every field: `samples` and `max_factor` finite and at least 1, `nis_reference`
    /// finite and above zero.
    pub fn validate(&self) -> Result<(), ConfigError> {
        if !self.samples.is_finite() || self.samples < T::one() {
            return Err(ConfigError::NotPositive(Param::AdaptationSamples));
        }
        positive(self.nis_reference, Param::AdaptationReference)?;
        if !self.max_factor.is_finite() || self.max_factor < T::one() {
            return Err(ConfigError::NotPositive(Param::AdaptationMaxFactor));
        }
        Ok(())
    }
}

/// The adaptation's running state.
#[derive(Clone, Copy, Debug, PartialEq)]
pub(crate) struct AdaptationState<T> {
    /// Running mean of the NIS.
    pub(crate) nis_mean: T,
    /// Its gain per step, `1 / samples`.
    k: T,
    /// `1 / nis_reference`.
    inv_reference: T,
    max_factor: T,
    /// The factor on `Q_ww` of the next prediction (1: the configured `Q`).
    pub(crate) factor: T,
    /// Tracked steps in a row with the NIS mean at or below the reference, up to
    /// [`SETTLE_STEPS`]: the filter has settled once it reaches it.
    calm: u32,
}

/// Tracked steps in a row with the innovations at their reference level after which the
/// filter counts as settled and the adaptation acts (it stays off during the initial
/// convergence and after a reset, which have their own large covariance).
pub(crate) const SETTLE_STEPS: u32 = 256;

impl<T: Float> AdaptationState<T> {
    pub(crate) fn new(cfg: &SpeedNoiseAdaptation<T>) -> Self {
        Self {
            nis_mean: T::zero(),
            k: T::one() / cfg.samples,
            inv_reference: T::one() / cfg.nis_reference,
            max_factor: cfg.max_factor,
            factor: T::one(),
            calm: 0,
        }
    }

    /// Takes the NIS of an accepted step (a sample the innovation gate rejects is an outlier,
    /// not a change of the motor's motion, and is not shown to it), `2 / b` for the innovation
    /// level `b` learnt so far (the consistency check's baseline; 1 without it) and whether the angle
    /// is tracked (its variance below the status limit), and sets the factor of the next
    /// prediction: 1 until the filter has settled ([`SETTLE_STEPS`] tracked steps in a row at
    /// the reference level) and whenever the angle is not tracked.
    #[inline(always)]
    pub(crate) fn watch(&mut self, nis: T, two_over_baseline: T, tracked: bool) {
        self.nis_mean += (nis - self.nis_mean) * self.k;
        // The reference: `nis_reference` times the learnt level over a consistent filter's 2.
        let r = self.nis_mean * self.inv_reference * two_over_baseline;
        if !tracked {
            self.calm = 0;
        } else if self.calm < SETTLE_STEPS && r <= T::one() {
            self.calm += 1;
        }
        if self.calm < SETTLE_STEPS {
            self.factor = T::one();
            return;
        }
        let f = r * r;
        // Plain comparisons: `min`/`max` are libm calls (NaN rules) on the MCU.
        self.factor = if f > self.max_factor {
            self.max_factor
        } else if f > T::one() {
            f
        } else {
            T::one()
        };
    }

    /// Forgets the innovations seen (a reset of the filter).
    pub(crate) fn restart(&mut self) {
        self.nis_mean = T::zero();
        self.factor = T::one();
        self.calm = 0;
    }
}
