//! Acceleration feedforward: the speed prediction follows the q current through a mechanical
//! model learnt online ([`AccelerationFeedforward`]; the method is in the module docs of
//! [`observer`](crate::observer), "Acceleration feedforward").

#[cfg(feature = "acceleration-feedforward")]
use nalgebra::Vector4;

use crate::error::Param;
use crate::motor::{MotorParams, positive};
use crate::{ConfigError, Float, to_t};

/// Configuration of the acceleration feedforward (module docs of [`observer`](crate::observer),
/// "Acceleration feedforward"): the speed prediction adds `Ts (k i_q + c0 + c1 w)`, a mechanical
/// model whose three coefficients are learnt online by least squares from the filter's own speed
/// changes.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct AccelerationFeedforward<T> {
    /// Samples per block of the learning (at least 4).
    pub block_samples: u32,
    /// Blocks of the learning's memory (forgetting factor `1 - 1 / memory_blocks`; at least 1).
    pub memory_blocks: T,
    /// Largest `k`, rad/s^2 per A (above zero).
    pub max_gain: T,
    /// Smallest normalized determinant of the learning's information matrix at which the model
    /// is taken into use (in `(0, 1)`): how far the q current's excursions must be from a
    /// function of the speed for `k` to be told from the load.
    pub min_conditioning: T,
}

impl<T: Float> AccelerationFeedforward<T> {
    /// The defaults for `motor` sampled every `ts_s`: blocks of 32 samples, a memory of 100
    /// blocks, `max_gain` the gain at which the characteristic current `I_c = psi_f / L_q`
    /// changes `w Ts` by 0.1 rad per period (`0.1 / (Ts^2 I_c)`), conditioning `10^-3`.
    pub fn default_for(motor: &MotorParams<T>, ts_s: T) -> Self {
        Self {
            block_samples: 32,
            memory_blocks: to_t(100.0),
            max_gain: to_t::<T>(0.1) / (ts_s * ts_s * motor.characteristic_current_a()),
            min_conditioning: to_t(1e-3),
        }
    }

    /// Checks every field: at least 4 samples per block and 1 block of memory, the gain bound
    /// finite and above zero, the conditioning in `(0, 1)`.
    pub fn validate(&self) -> Result<(), ConfigError> {
        if self.block_samples < 4 {
            return Err(ConfigError::OutOfRange(Param::FeedforwardBlock));
        }
        if !self.memory_blocks.is_finite() || self.memory_blocks < T::one() {
            return Err(ConfigError::OutOfRange(Param::FeedforwardMemory));
        }
        positive(self.max_gain, Param::FeedforwardMaxGain)?;
        let c = self.min_conditioning;
        if !(c > T::zero() && c < T::one()) {
            return Err(ConfigError::OutOfRange(Param::FeedforwardConditioning));
        }
        Ok(())
    }
}

/// The feedforward's running state: the model in use, the learning's block and sums.
#[cfg(feature = "acceleration-feedforward")]
#[derive(Clone, Copy, Debug, PartialEq)]
pub(crate) struct FeedforwardState<T> {
    /// Learnt gain in use, rad/s^2 per A (0 until learnt).
    pub(crate) k: T,
    /// The load's acceleration, estimated from the filter's speed changes: a low-pass of
    /// `k i_q - dw / Ts` (rad/s^2).
    load: T,
    /// Its gain per sample.
    k_load: T,
    /// The last sample's `i_q` and `w` (the feedforward's current; the step from them to the
    /// next sample is the load's measurement).
    iq_prev: T,
    w_prev: T,
    primed: bool,
    /// Dead band of the modelled acceleration: `k` times three standard deviations of the
    /// measurement noise (a steady current's noise moves no speed).
    band: T,
    /// Three standard deviations of the measurement noise, A.
    noise3: T,
    /// Normalization: `1 / I_c` (A^-1), the nominal period (s).
    inv_ic: T,
    ts: T,
    inv_ts: T,
    block_samples: u32,
    forget: T,
    max_gain: T,
    min_conditioning: T,
    /// The block: samples, sums of `i_q / I_c` and `w Ts`, `w Ts` at its start, all trusted.
    n: u32,
    s_iq: T,
    s_w: T,
    w0: T,
    trusted: bool,
    /// Information matrix (upper triangle) and vector of the normalized regression
    /// `dw Ts = t0 sum(i_q / I_c) + t1 n + t2 sum(w Ts)`.
    a: [T; 6],
    b: [T; 3],
}

#[cfg(feature = "acceleration-feedforward")]
impl<T: Float> FeedforwardState<T> {
    /// The state for `c` for `motor` at the period `ts_s`, with the measurement noise variance
    /// `r_a2` (A^2, the larger diagonal entry of `R`).
    pub(crate) fn new(
        c: &AccelerationFeedforward<T>,
        motor: &MotorParams<T>,
        ts_s: T,
        r_a2: T,
    ) -> Self {
        Self {
            k: T::zero(),
            load: T::zero(),
            k_load: to_t(0.125),
            iq_prev: T::zero(),
            w_prev: T::zero(),
            primed: false,
            band: T::zero(),
            noise3: to_t::<T>(3.0) * r_a2.sqrt(),
            inv_ic: T::one() / motor.characteristic_current_a(),
            ts: ts_s,
            inv_ts: T::one() / ts_s,
            block_samples: c.block_samples,
            forget: T::one() - T::one() / c.memory_blocks,
            max_gain: c.max_gain,
            min_conditioning: c.min_conditioning,
            n: 0,
            s_iq: T::zero(),
            s_w: T::zero(),
            w0: T::zero(),
            trusted: false,
            a: [T::zero(); 6],
            b: [T::zero(); 3],
        }
    }

    /// Adds the modelled acceleration over a period of `ts` to the prior `xm`, from the q
    /// current of the posterior the prediction started from (the last sample given to
    /// [`watch`](Self::watch)): the speed by `ts a`, the angle by half of that times `ts` (the
    /// mean speed over the period). Within the dead band, and while `k` is 0, nothing.
    #[inline(always)]
    pub(crate) fn feedforward(&self, xm: &mut Vector4<T>, ts: T) {
        let iq = self.iq_prev;
        if self.k == T::zero() {
            // Not learnt (or switched off by the fit): the random walk exactly.
            return;
        }
        let a = self.k * iq - self.load;
        let a = if a > self.band {
            a - self.band
        } else if a < -self.band {
            a + self.band
        } else {
            return;
        };
        let dw = ts * a;
        xm[2] += dw;
        xm[3] += dw * ts * to_t(0.5);
    }

    /// One sample of the learning: the q current `iq` and the speed `w` of the posterior the
    /// step's prediction started from (`trusted`: its angle was tracked). A full block is
    /// closed first, by this speed.
    #[inline(always)]
    pub(crate) fn watch(&mut self, iq: T, w: T, trusted: bool) {
        // The load: what the current's acceleration leaves of the filter's speed change over
        // the last step (it has no meaning before the first sample or across a restart).
        if self.primed {
            let a = self.k * self.iq_prev - (w - self.w_prev) * self.inv_ts;
            // Held within the largest acceleration the model makes (`max_gain` times the
            // characteristic current): a step the filter did not follow (a reset, a refused
            // sample's neighbour) must not leave a load no motor has.
            let bound = self.max_gain / self.inv_ic;
            let load = self.load + (a - self.load) * self.k_load;
            let load = super::tracking::clamp(load, -bound, bound);
            if load.is_finite() {
                self.load = load;
            }
        }
        self.iq_prev = iq;
        self.w_prev = w;
        self.primed = true;
        let wts = w * self.ts;
        if self.n >= self.block_samples {
            self.learn(wts);
        }
        if self.n == 0 {
            self.w0 = wts;
            self.trusted = true;
        }
        self.s_iq += iq * self.inv_ic;
        self.s_w += wts;
        self.n += 1;
        self.trusted &= trusted;
    }

    /// The end of a block closed by the speed `wts` (`w Ts`): the regression's update and, when
    /// well conditioned, the model from its solution. The block's `n` currents drove the speed
    /// from its first sample to `wts`.
    #[cold]
    #[inline(never)]
    fn learn(&mut self, wts: T) {
        let x = [self.s_iq, to_t::<T>(f64::from(self.n)), self.s_w];
        let y = wts - self.w0;
        let trusted = self.trusted;
        self.n = 0;
        self.s_iq = T::zero();
        self.s_w = T::zero();
        if !trusted {
            return;
        }
        let l = self.forget;
        let a = [
            l * self.a[0] + x[0] * x[0],
            l * self.a[1] + x[0] * x[1],
            l * self.a[2] + x[0] * x[2],
            l * self.a[3] + x[1] * x[1],
            l * self.a[4] + x[1] * x[2],
            l * self.a[5] + x[2] * x[2],
        ];
        let b = [
            l * self.b[0] + x[0] * y,
            l * self.b[1] + x[1] * y,
            l * self.b[2] + x[2] * y,
        ];
        if !(a.iter().chain(b.iter()).fold(T::zero(), |s, &v| s + v)).is_finite() {
            return;
        }
        self.a = a;
        self.b = b;
        // Solve by Cramer's rule; the determinant normalized by the diagonal's product measures
        // how independent the regressors have been.
        let [a00, a01, a02, a11, a12, a22] = a;
        let c00 = a11 * a22 - a12 * a12;
        let c01 = a02 * a12 - a01 * a22;
        let c02 = a01 * a12 - a02 * a11;
        let det = a00 * c00 + a01 * c01 + a02 * c02;
        let scale = a00 * a11 * a22;
        if !(scale > T::zero() && det > self.min_conditioning * scale) {
            return;
        }
        // Only the current's coefficient is used: the load's terms in the regression keep it
        // unbiased by a load that moves with the speed, while the feedforward takes the load
        // from its own estimate (neutral in a steady state).
        let t0 = (c00 * b[0] + c01 * b[1] + c02 * b[2]) / det;
        let k = t0 * self.inv_ic / (self.ts * self.ts);
        let k = if !k.is_finite() || k <= T::zero() {
            // Current that does not accelerate the rotor is no model: off.
            T::zero()
        } else if k > self.max_gain {
            self.max_gain
        } else {
            k
        };
        // The load estimate moves to the new gain's balance at once.
        self.load += (k - self.k) * self.iq_prev;
        self.k = k;
        self.band = k * self.noise3;
    }

    /// After a reset: the block restarts; the model is kept (a property of the drive).
    pub(crate) fn restart(&mut self) {
        self.primed = false;
        self.n = 0;
        self.s_iq = T::zero();
        self.s_w = T::zero();
    }

    /// After a branch flip (`theta += pi`, `w = -w`): in the flipped frame `i_q`, `w` and the
    /// acceleration change sign, so the model's constant term does, and the learning's sums
    /// that pair the constant regressor with an odd one; the block restarts.
    pub(crate) fn flip(&mut self) {
        self.load = -self.load;
        self.a[1] = -self.a[1];
        self.a[4] = -self.a[4];
        self.b[1] = -self.b[1];
        self.restart();
    }
}
