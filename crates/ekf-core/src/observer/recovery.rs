//! What the safeguards do to the observer (module docs of [`observer`](crate::observer),
//! "Safeguards"): a rejected sample, a branch flip, the health check and its self-reset, the
//! divergence count, a refused step.

use super::pmsm::Tracking;
use super::{Estimate, PmsmObserver};
use nalgebra::Vector4;

use super::safeguards::{Events, MAX_REFUSALS};
use super::structured::Sym4;
use crate::ekf::EkfError;
use crate::{Float, wrap_angle};

impl<T: Float> PmsmObserver<T> {
    /// The divergence check (covariance health) for an accepted sample above the gate's
    /// threshold: counts tracked steps in a row with `NIS > divergence_nis`; `true` at
    /// `divergence_samples`. Out of line: the rare path.
    #[cold]
    #[inline(never)]
    pub(super) fn diverging(&mut self, nis: T, tracking: bool) -> bool {
        let (Some(h), Some(g)) = (&self.health, &mut self.gate) else {
            return false;
        };
        if tracking && nis > h.divergence_nis {
            g.inconsistent = g.inconsistent.saturating_add(1);
            h.divergence_samples != 0 && g.inconsistent >= h.divergence_samples
        } else {
            g.inconsistent = 0;
            false
        }
    }

    /// A step refused for `e` (singular `S`, non-finite result): the state is kept and the
    /// error returned, unless the health check resets the filter (then its estimate).
    #[cold]
    #[inline(never)]
    pub(super) fn refused(&mut self, e: EkfError, i: [T; 2]) -> Result<Estimate<T>, EkfError> {
        if self.refused_resets() {
            self.events = Events::default();
            self.self_reset(Some(i));
            return Ok(self.estimate());
        }
        Err(e)
    }

    /// Bookkeeping of a rejected sample: counted and reported.
    #[cold]
    #[inline(never)]
    pub(super) fn gate_rejected(&mut self) {
        if let Some(g) = &mut self.gate {
            g.consecutive += 1;
        }
        self.counters.rejected = self.counters.rejected.saturating_add(1);
        self.events = Events {
            rejected: true,
            ..Events::default()
        };
    }

    /// Moves the estimate to the other branch: `theta += pi`, `w = -w`, `P = T P T`
    /// (`T = diag(1, 1, -1, 1)`), `P33 += flip_angle_sigma_rad^2`; restarts the test.
    #[cold]
    #[inline(never)]
    pub(super) fn flip(&mut self) {
        let Some(b) = &mut self.branch else {
            return;
        };
        b.sum = T::zero();
        self.locked = false;
        self.x[2] = -self.x[2];
        self.x[3] = wrap_angle(self.x[3] + T::pi());
        self.p = self.p.flip_speed();
        self.p.p33 += b.flip_var;
        if let Some(k) = &mut self.tracking {
            k.t.flip_speed();
        }
        #[cfg(feature = "acceleration-feedforward")]
        if let Some(f) = &mut self.feedforward {
            f.flip();
        }
        self.counters.branch_flips = self.counters.branch_flips.saturating_add(1);
        self.events.flipped = true;
    }

    /// `true` when the health check is on and fails: a non-positive (or NaN) diagonal entry
    /// of `P`, `trace(P)` above the bound (or NaN), or a current or speed estimate beyond its
    /// bound (or NaN).
    #[inline(always)]
    pub(super) fn unhealthy(&self, x: &Vector4<T>, p: &Sym4<T>) -> bool {
        match &self.health {
            Some(h) => {
                let z = T::zero();
                !((p.p00 + p.p11) + (p.p22 + p.p33) <= h.trace_bound
                    && p.p00 > z
                    && p.p11 > z
                    && p.p22 > z
                    && p.p33 > z
                    && x[0].abs() + x[1].abs() <= h.current_bound
                    && x[2].abs() <= h.speed_bound)
            }
            None => false,
        }
    }

    /// Whether a step refused for a singular `S` or a non-finite result must reset the filter
    /// (health check on): the stored `P` or state is unhealthy, or this is the
    /// [`MAX_REFUSALS`]-th such refusal in a row (the filter cannot step from where it is,
    /// e.g. an `S` that is singular to rounding in `f32`). Counts the refusal otherwise.
    #[cold]
    #[inline(never)]
    pub(super) fn refused_resets(&mut self) -> bool {
        let unhealthy = self.unhealthy(&self.x, &self.p);
        match &self.health {
            Some(_) => {
                self.refusals += 1;
                if unhealthy || self.refusals >= MAX_REFUSALS {
                    self.refusals = 0;
                    true
                } else {
                    false
                }
            }
            None => false,
        }
    }

    /// The self-reset of the health check: currents = the measured currents (or the current
    /// estimate if none; 0 beyond the bound), speed kept if within its bound, angle if finite
    /// (else 0),
    /// `P = P0`, gate and branch check restarted; reported in the events and counters.
    #[cold]
    #[inline(never)]
    pub(super) fn self_reset(&mut self, i: Option<[T; 2]>) {
        let Some(h) = &self.health else {
            return;
        };
        // `!(|v| <= bound)` also catches NaN.
        let keep = |v: T, bound: T| if v.abs() <= bound { v } else { T::zero() };
        let ib_max = h.current_bound;
        let (ia, ib) = match i {
            Some([a, b]) => (keep(a, ib_max), keep(b, ib_max)),
            None => (keep(self.x[0], ib_max), keep(self.x[1], ib_max)),
        };
        let w = keep(self.x[2], h.speed_bound);
        let th = if self.x[3].is_finite() {
            wrap_angle(self.x[3])
        } else {
            T::zero()
        };
        self.x = Vector4::new(ia, ib, w, th);
        self.p = h.p0;
        if let Some(Tracking { t, slow }) = &mut self.tracking {
            t.restart(slow, true);
        }
        self.restart_safeguards();
        self.refresh_rs_constants();
        self.events.reset = true;
        self.counters.covariance_resets = self.counters.covariance_resets.saturating_add(1);
    }

    /// Clears the gate's, the branch check's, the consistency check's, the speed noise
    /// adaptation's and the acceleration feedforward's running state (its learnt gain kept).
    pub(super) fn restart_safeguards(&mut self) {
        self.locked = false;
        if let Some(w) = &mut self.consistency {
            w.restart();
        }
        if let Some(a) = &mut self.adaptation {
            a.restart();
        }
        #[cfg(feature = "acceleration-feedforward")]
        if let Some(f) = &mut self.feedforward {
            f.restart();
        }
        if let Some(g) = &mut self.gate {
            g.inconsistent = 0;
            g.consecutive = 0;
            g.open = false;
            g.nis_mean = g.threshold;
        }
        if let Some(b) = &mut self.branch {
            b.sum = T::zero();
        }
    }
}
