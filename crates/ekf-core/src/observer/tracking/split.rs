//! The split filter of `(psi_f, Rs)` (module docs of the parent, "Resistance" and "Tracking
//! during transients"): its state, the window's measurement, the update.

use nalgebra::Vector4;

use super::{TRANSIENT, TrackerConstants, Window, clamp};
use crate::angle::wrap_angle;
use crate::trig::sin_cos_small;
use crate::{Float, to_t};

/// The split filter of `(psi_f, Rs)` (module docs).
#[derive(Clone, Copy, Debug, PartialEq)]
pub(in crate::observer) struct Split<T> {
    /// Estimates `(psi_f, Rs)`.
    pub psi: T,
    pub rs: T,
    /// Covariance entries.
    pub c00: T,
    pub c01: T,
    pub c11: T,
    /// Process noise per window: the temperature's random walk (K^2) and the magnets' own
    /// drift (Wb^2); the measurement variance (Wb^2).
    pub q_t: T,
    pub q_psi: T,
    pub r_m: T,
    /// The thermal link's anchor `(psi_a, Rs_a)` and variance (K^2).
    pub psi_a: T,
    pub rs_a: T,
    pub r_link: T,
    /// Whether the filter has started (module docs: at the first window after the EKF's
    /// flux has converged, from the EKF's flux and `Rs`).
    pub anchored: bool,
    /// Whether a window has ended with the EKF's tracking active (from then on the windows
    /// through speed changes leave the EKF's flux alone).
    pub tracked: bool,
    /// Temperature coefficients `alpha_cu`, `beta` (1/K).
    pub alpha: T,
    pub beta: T,
    /// The state at the end of the last window: angle (rad), `i_q` (A) in its frame.
    pub end_theta: T,
    pub end_id: T,
    pub end_iq: T,
    /// The speed of the last window read for the start-up flux (the angle's advance), rad/s;
    /// 0 when that window was left out.
    pub last_w: T,
    /// Whether a window of a braking has been read for the start-up flux (the start-up is
    /// over: no window corrects the EKF's flux any more).
    pub braked: bool,
    /// The speed of the last window read by [`update_braking`](Self::update_braking) (the
    /// angle's advance), rad/s; 0 when the last window was not one of those or was left out
    /// (host builds).
    #[cfg(feature = "std")]
    pub brake_w: T,
    /// The windows of a drive whose speed never settles (host builds; module docs of the
    /// parent, "Resistance while the speed is never steady").
    #[cfg(feature = "std")]
    pub unsteady: Unsteady,
    /// The windows-only covariance behind
    /// [`ParameterTracking::link_follows_data`](super::ParameterTracking::link_follows_data)
    /// (host builds).
    #[cfg(feature = "std")]
    pub follow: Follow<T>,
}

/// The covariance of `(psi_f, Rs)` the windows alone leave: the split filter without the
/// thermal link, from an anchor that read the lumped flux `psi_f + Rs r` at its operating
/// point's `r` (module docs of the parent, "The link's reference"; host builds).
#[cfg(feature = "std")]
#[derive(Clone, Copy, Debug, PartialEq)]
pub(in crate::observer) struct Follow<T> {
    pub d00: T,
    pub d01: T,
    pub d11: T,
    /// The `r` of the last window read for the start-up flux (0 when left out): the
    /// operating point of an anchor at the start-up's agreement.
    pub last_r: T,
}

/// The state of the split filter's windows while the EKF's own tracking has not run (module
/// docs of the parent, "Resistance while the speed is never steady"; host builds).
#[cfg(feature = "std")]
#[derive(Clone, Copy, Debug, Default, PartialEq)]
pub(in crate::observer) struct Unsteady {
    /// Before the anchor: start-up windows in a row that agree with the EKF's converged flux
    /// (at [`AGREEING_WINDOWS`] the filter anchors there); after it: windows since (the
    /// windows update from [`AGREEING_WINDOWS`] + [`GRACE_WINDOWS`] on).
    pub count: u8,
    /// The anchor came from that agreement: the first window of the EKF's own tracking
    /// drops it (the filter anchors again where the EKF's flux converges, as without it).
    pub provisional: bool,
}

impl<T: Float> Split<T> {
    /// All values finite.
    pub(super) fn finite(&self) -> bool {
        (self.psi + self.rs + (self.c00 + self.c01 + self.c11)).is_finite()
    }

    /// The split filter's step at the end of a window (module docs, "Resistance"): the
    /// window's lumped flux `m = (|e0| + Rs0 n.i) / |w|` from the length of its back-EMF
    /// vector `e0` at the filter's `Rs0` (`n = e0 / |e0|`), with `w` the rotation rate of the
    /// estimated angle over the window, is a measurement of `psi_f + Rs r`, `r = n.i / |w|`;
    /// random walk, that update, then the thermal link. `rs_used` and `psi` are the EKF's `Rs`
    /// and flux, `c_pp` its flux variance, `x` its state at the window's end. Returns the new
    /// `Rs` (bounded), `None` when the window is not used.
    pub(super) fn update(
        &mut self,
        rs_used: T,
        psi: T,
        c_pp: T,
        sums: &Window<T>,
        x: &Vector4<T>,
        k: &TrackerConstants<T>,
    ) -> Option<T> {
        let ends = self.take_ends(x);
        self.tracked = true;
        #[cfg(feature = "std")]
        if self.unsteady.provisional {
            self.unsteady.provisional = false;
            self.anchored = false;
        }
        if !self.anchored {
            // The link's reference: the first window after the EKF's flux has converged
            // (standard deviation within 0.5 % of the configured flux).
            let converged = c_pp <= k.psi0 * k.psi0 * to_t(2.5e-5);
            if converged {
                self.anchor(psi, rs_used, c_pp, k);
                // The operating point's `r = i_q / w` at the window's end.
                #[cfg(feature = "std")]
                if x[2] != T::zero() {
                    self.follow_from(ends.4 / x[2], k);
                }
            }
            return None;
        }
        let (m, r, r_m, _) = self.measure(ends, sums, x, k, Reading::Active)?;
        self.update_with(m, r, r_m, k, true)
    }

    /// Whether the EKF's speed state, its mean over the window, and the window's speed (the
    /// estimated angle's advance, as [`measure`](Self::measure) reads it) are apart by more
    /// than [`SPEED_CONFLICT`] of the latter (module docs of the parent, "Resistance while the
    /// filter is in trouble"). Reads the window's start; changes nothing.
    pub(super) fn speed_conflict(
        &self,
        sums: &Window<T>,
        x: &Vector4<T>,
        k: &TrackerConstants<T>,
    ) -> bool {
        let n = to_t::<T>(f64::from(sums.n));
        let w = window_speed(self.end_theta, sums, x, k);
        (sums.w / n - w).abs() > to_t::<T>(SPEED_CONFLICT) * w.abs()
    }

    /// The split filter's step on a window of a filter in trouble (module docs of the parent,
    /// "Resistance while the filter is in trouble"): the EKF's tracking frozen, after the filter
    /// has tracked once and anchored, and either its innovations out of line or its speed state
    /// apart from its angle's advance ([`speed_conflict`](Self::speed_conflict)). Only a window
    /// that measures `Rs` (the resistive drop `|Rs r|` above 15 % of the flux) is used, with
    /// ten times the window's variance (its speed, the angle's advance, is biased while the
    /// angle pulls in). Returns the new `Rs` (bounded), `None` when the window is not used.
    pub(super) fn update_troubled(
        &mut self,
        psi: T,
        sums: &Window<T>,
        x: &Vector4<T>,
        k: &TrackerConstants<T>,
    ) -> Option<T> {
        let ends = self.take_ends(x);
        let (m, r, r_m, _) = self.measure(ends, sums, x, k, Reading::Active)?;
        if measures_flux(r, self.rs, psi) {
            return None;
        }
        self.update_with(m, r, r_m * to_t::<T>(10.0), k, true)
    }

    /// The split filter's step on a window of a consistent filter whose tracking is frozen
    /// (a speed change), after it has tracked once and anchored (module docs of the parent,
    /// "Resistance on a braking ramp"; host builds): only a window of a braking ramp is used,
    /// its speed (the angle's advance) below the previous such window's by more than 2 %, the
    /// drive generating (`r < 0`: the current against the back-EMF), and the resistive drop
    /// `|Rs r|` above 15 % of the flux (the window measures `Rs`); then the update of an active
    /// window. Returns the new `Rs` (bounded), `None` when the window is not used.
    pub(super) fn update_braking(
        &mut self,
        psi: T,
        sums: &Window<T>,
        x: &Vector4<T>,
        k: &TrackerConstants<T>,
    ) -> Option<T> {
        let ends = self.take_ends(x);
        let window = self.measure(ends, sums, x, k, Reading::Active);
        #[cfg(feature = "std")]
        {
            let last = self.brake_w;
            self.brake_w = window.map_or(T::zero(), |w| w.3);
            let (m, r, r_m, w) = window?;
            let slowing = last != T::zero()
                && w.abs() < last.abs()
                && last.abs() - w.abs() > to_t::<T>(BRAKING_SHARE) * w.abs();
            if !slowing || r >= T::zero() || measures_flux(r, self.rs, psi) {
                return None;
            }
            self.update_with(m, r, r_m, k, true)
        }
        #[cfg(not(feature = "std"))]
        {
            let _ = (window, psi);
            None
        }
    }

    /// The split filter's step on a window with the EKF's tracking frozen, once the filter has
    /// anchored at the end of the start-up without the EKF's tracking ever having run (module
    /// docs of the parent, "Resistance while the speed is never steady"): the window's own mean
    /// `i_d` (the current swings within it) and a current step up to half the current, then
    /// the update of an active window without the thermal link (the anchor is the lumped flux
    /// of the `Rs` in use, not a pair at one temperature). Returns `(Rs, psi_f)` (bounded) for
    /// the EKF to take, `None` when the window is not used.
    pub(super) fn update_unsteady(
        &mut self,
        sums: &Window<T>,
        x: &Vector4<T>,
        k: &TrackerConstants<T>,
    ) -> Option<(T, T)> {
        let ends = self.take_ends(x);
        let (m, r, r_m, _) = self.measure(ends, sums, x, k, Reading::Unsteady)?;
        let rs = self.update_with(m, r, r_m, k, false)?;
        Some((rs, self.psi))
    }

    /// Counts a start-up window for the unsteady windows (module docs of the parent,
    /// "Resistance while the speed is never steady"): before the anchor, whether it agrees with
    /// the EKF's flux once that has converged (to 1.5 %), at a speed where the window's variance
    /// is not widened (its lumped flux `m - Rs r` within two standard deviations); after it,
    /// one more window since.
    #[cfg(feature = "std")]
    fn count_unsteady(
        &mut self,
        window: Option<(T, T, T, T)>,
        rs_used: T,
        psi: T,
        c_pp: T,
        k: &TrackerConstants<T>,
    ) {
        let u = &mut self.unsteady;
        if u.provisional {
            u.count = u.count.saturating_add(1);
            return;
        }
        let agrees = window.is_some_and(|(m, r, r_m, w)| {
            let y = m - r * rs_used - psi;
            w * w >= to_t::<T>(100.0) * k.min_speed2
                && c_pp <= to_t::<T>(2.25e-4) * k.psi0 * k.psi0
                && y * y <= to_t::<T>(4.0) * (c_pp + r_m)
        });
        u.count = if agrees { u.count + 1 } else { 0 };
    }

    /// Whether the filter anchors at the start-up's agreement now (module docs of the parent,
    /// "Resistance while the speed is never steady"): it has not anchored, the EKF's tracking
    /// has not run, and [`AGREEING_WINDOWS`] windows in a row agreed. Host builds; never
    /// without.
    pub(super) fn unsteady_anchor_due(&self) -> bool {
        #[cfg(feature = "std")]
        return !self.tracked && !self.anchored && self.unsteady.count >= AGREEING_WINDOWS;
        #[cfg(not(feature = "std"))]
        false
    }

    /// Whether the unsteady windows update the filter: anchored by that agreement
    /// [`GRACE_WINDOWS`] windows ago and the EKF's tracking still not run (a drive whose speed
    /// never settles). Host builds; never without.
    pub(super) fn unsteady_ready(&self) -> bool {
        #[cfg(feature = "std")]
        return !self.tracked
            && self.unsteady.provisional
            && self.unsteady.count >= AGREEING_WINDOWS.saturating_add(GRACE_WINDOWS);
        #[cfg(not(feature = "std"))]
        false
    }

    /// Anchors at the start-up's agreement (module docs of the parent, "Resistance while the
    /// speed is never steady"): as [`anchor`](Self::anchor), marked provisional, the windows
    /// since counted from there.
    pub(super) fn anchor_unsteady(&mut self, psi: T, rs: T, c_pp: T, k: &TrackerConstants<T>) {
        self.anchor(psi, rs, c_pp, k);
        #[cfg(feature = "std")]
        {
            self.unsteady.provisional = true;
            self.follow_from(self.follow.last_r, k);
        }
    }

    /// The update with a window's measurement `m = psi_f + Rs r` of variance `r_m`: random
    /// walk, the scalar update (unless beyond 5 standard deviations), the thermal link (with
    /// `link`), the bounds. Returns the new `Rs`, `None` when the window is not used.
    fn update_with(
        &mut self,
        m: T,
        r: T,
        r_m: T,
        k: &TrackerConstants<T>,
        link: bool,
    ) -> Option<T> {
        // Random walk: the temperature moves both along (psi beta, Rs alpha_cu) per kelvin;
        // the magnets' flux drifts besides.
        let (g0, g1) = (self.psi * self.beta, self.rs * self.alpha);
        let walk = (
            self.q_t * g0 * g0 + self.q_psi,
            self.q_t * g0 * g1,
            self.q_t * g1 * g1,
        );
        self.c00 += walk.0;
        self.c01 += walk.1;
        self.c11 += walk.2;
        #[cfg(feature = "std")]
        if k.follows {
            let f = &mut self.follow;
            f.d00 += walk.0;
            f.d01 += walk.1;
            f.d11 += walk.2;
        }
        // A window the filter's own uncertainty cannot explain (beyond 5 standard deviations:
        // a model that does not fit, e.g. inductances far off on a saturating motor) is left
        // out rather than read as a resistance.
        let y = m - (self.psi + r * self.rs);
        let s = self.c00 + r * (self.c01 + self.c01) + r * r * self.c11 + r_m;
        if y * y > to_t::<T>(25.0) * s {
            return None;
        }
        self.scalar_update(T::one(), r, y, r_m);
        #[cfg(feature = "std")]
        if k.follows {
            self.follow_window(r, r_m);
        }
        // Thermal link, where the window measures the flux (the resistive drop below 15 % of
        // the back-EMF): the temperatures read from psi and from Rs agree (K). Where the drop
        // is larger the window measures Rs itself, and the link is left out: applied on
        // every window it would outweigh that measurement.
        if link && measures_flux(r, self.rs, self.psi) {
            // The link's reference follows the windows where they have told `Rs` by
            // themselves better than the link would (module docs of the parent, "The link's
            // reference"; host builds).
            #[cfg(feature = "std")]
            if k.follows {
                let link_rs = self.r_link.sqrt() * self.alpha * self.rs;
                if self.follow.d11 <= link_rs * link_rs {
                    self.psi_a = self.psi;
                    self.rs_a = self.rs;
                }
            }
            let h_psi = T::one() / (self.psi_a * self.beta);
            let h_rs = -T::one() / (self.rs_a * self.alpha);
            let h = h_psi * (self.psi - self.psi_a) + h_rs * (self.rs - self.rs_a);
            self.scalar_update(h_psi, h_rs, -h, self.r_link);
        }
        self.psi = clamp(self.psi, k.psi_min, k.psi_max);
        self.rs = clamp(self.rs, k.rs_min, k.rs_max);
        Some(self.rs)
    }

    /// The window's correction of the EKF's frozen flux `psi` (variance `c_pp`) through a
    /// speed change (module docs, "Tracking during transients"): the window's measurement
    /// `m = psi_f + Rs r`, read at the `Rs` in use `rs_used` as the lumped flux
    /// `m - rs_used r`, in a scalar Kalman update. Returns the flux (bounded) and its
    /// variance, `None` when the window is not used (as in [`update`](Self::update), and
    /// beyond 5 standard deviations).
    pub(super) fn transient_flux(
        &mut self,
        rs_used: T,
        psi: T,
        c_pp: T,
        sums: &Window<T>,
        x: &Vector4<T>,
        k: &TrackerConstants<T>,
    ) -> Option<(T, T)> {
        let ends = self.take_ends(x);
        if self.tracked {
            return None;
        }
        let window = self.measure(ends, sums, x, k, Reading::StartUp);
        #[cfg(feature = "std")]
        self.count_unsteady(window, rs_used, psi, c_pp, k);
        // Only through an acceleration: the window's speed (the angle's advance) above the
        // previous window's by more than 2 % (a start-up). The first window after a gap, a
        // steady speed, a braking and the angle's pull-in after a lock at speed leave the
        // EKF's flux alone: its own tracking takes over after the settling time.
        let last_w = self.last_w;
        self.last_w = window.map_or(T::zero(), |w| w.3);
        #[cfg(feature = "std")]
        {
            self.follow.last_r = window.map_or(T::zero(), |w| w.1);
        }
        if self.braked {
            return None;
        }
        let (m, r, r_m, w) = window?;
        let (w2, last2) = (w * w, last_w * last_w);
        let dw = w - last_w;
        let changed = dw * dw > to_t::<T>(4e-4) * w2;
        // The start-up ends at the first braking (the window's speed below the previous
        // window's by more than 2 %): later accelerations are steps and reversals of a drive
        // under way, not its start.
        if last_w != T::zero() && w2 < last2 && changed {
            self.braked = true;
            return None;
        }
        if last_w == T::zero() || w2 <= last2 || !changed {
            return None;
        }
        // Only where the resistive drop is within 30 % of the flux (module docs, "Tracking
        // during transients": the lumped flux at the `Rs` in use is what the EKF's model needs
        // along the ramp; at a larger drop, low speed under load, it would not hold once the
        // speed has risen).
        if !drop_within(r, rs_used, psi, START_UP_DROP_SHARE) {
            return None;
        }
        let y = m - r * rs_used - psi;
        let s = c_pp + r_m;
        if y * y > to_t::<T>(25.0) * s {
            return None;
        }
        let gain = c_pp / s;
        // The variance not below (1 % of the flux)^2: the EKF's own tracking refines it
        // (and, at 0.5 %, anchors the split filter, as without these windows).
        let c = c_pp - gain * c_pp;
        let floor = k.psi0 * k.psi0 * to_t(1e-4);
        let next = (
            clamp(psi + gain * y, k.psi_min, k.psi_max),
            if c > floor { c } else { floor },
        );
        (next.0 + next.1).is_finite().then_some(next)
    }

    /// The state at the window's end (the next window's start) stored; returns the window's
    /// start and end: `(theta0, id0, iq0, id_end, iq_end)`.
    fn take_ends(&mut self, x: &Vector4<T>) -> (T, T, T, T, T) {
        let (s_end, c_end) = x[3].sin_cos_angle();
        let id_end = x[0] * c_end + x[1] * s_end;
        let iq_end = x[1] * c_end - x[0] * s_end;
        let (theta0, id0, iq0) = (self.end_theta, self.end_id, self.end_iq);
        self.end_theta = x[3];
        self.end_id = id_end;
        self.end_iq = iq_end;
        (theta0, id0, iq0, id_end, iq_end)
    }

    /// The window's measurement `(m, r, r_m, w)`: `m = psi_f + Rs r`, its variance `r_m` and
    /// the window's speed `w`
    /// (module docs, "Resistance"), from the window's sums and its ends (`take_ends`) and the
    /// state `x` at its end; `None` for a window left out.
    fn measure(
        &self,
        (theta0, id0, iq0, id_end, iq_end): (T, T, T, T, T),
        sums: &Window<T>,
        x: &Vector4<T>,
        k: &TrackerConstants<T>,
        reading: Reading,
    ) -> Option<(T, T, T, T)> {
        if !sums.contiguous {
            return None;
        }
        let n = to_t::<T>(f64::from(sums.n));
        let inv_n = T::one() / n;
        let span = n * k.ts;
        let w = window_speed(theta0, sums, x, k);
        // Enough back-EMF to read the flux from: at least twice the tracking's minimum speed.
        if w * w < to_t::<T>(4.0) * k.min_speed2 {
            return None;
        }
        // The period's voltage is held while the frame turns by w Ts: its mean in the
        // rotating frame is the start frame's value turned back by half of that and scaled
        // by sinc(w Ts / 2).
        let half = w * k.ts * to_t(0.5);
        let (sh, ch) = sin_cos_small(half);
        let sinc = if half.abs() > to_t(1e-6) {
            sh / half
        } else {
            T::one()
        };
        let (ud0, uq0) = (sums.ud * inv_n, sums.uq * inv_n);
        let ud = (ud0 * ch + uq0 * sh) * sinc;
        let uq = (uq0 * ch - ud0 * sh) * sinc;
        // The window's mean i_d: the start-up flux's and the unsteady windows (host builds)
        // take its own mean (module docs, "Tracking during transients": a ramp may end
        // within the window, and the current swings when the speed is never steady); the
        // active split filter's the mean of the window's ends (the firmware's reading: a
        // window with a current step is left out below), in host builds its own mean where
        // the two differ by more than 5 % of the current (module docs, "The window's d
        // current": a d current that moves within the window, such as foc's excitation).
        let iq = sums.iq * inv_n;
        let id = if reading == Reading::Active {
            let ends = (id0 + id_end) * to_t(0.5);
            let own = sums.id * inv_n;
            let gap = own - ends;
            let floor = to_t::<T>(0.1) * k.psi0 / k.ld;
            let scale2 = (own * own + iq * iq).max(floor * floor);
            if TRANSIENT && gap * gap > to_t::<T>(D_MEAN_GAP2) * scale2 {
                own
            } else {
                ends
            }
        } else {
            sums.id * inv_n
        };
        // Windows with little current (the inverter's voltage error is least known there,
        // its compensation hinges on the current's sign; the start-up flux aside) or a
        // current step (the window's speed and angle are in transit: above a fifth of the
        // current, for the unsteady windows half of it) are left out.
        let i2 = id * id + iq * iq;
        let i_min = to_t::<T>(0.02) * k.psi0 / k.ld;
        let diq = iq_end - iq0;
        let step_share2 = to_t::<T>(if reading == Reading::Unsteady {
            0.25
        } else {
            0.04
        });
        if (i2 < i_min * i_min && reading != Reading::StartUp) || diq * diq > step_share2 * i2 {
            return None;
        }
        // The back-EMF vector of the window at the filter's `Rs` (module docs, "Resistance"):
        // `e0 = u - Rs i - L di/dt - j w L i`, of length `|w| psi_f` in any frame. Its length
        // read against `Rs` to first order, `|e(Rs)| = |e0| - (Rs - Rs0) n.i` (`n` the unit
        // vector along `e0`), is the window's measurement `m = psi_f + Rs r` with
        // `m = (|e0| + Rs0 n.i) / |w|`, `r = n.i / |w|`: the frame's angle error drops out.
        let rs0 = self.rs;
        let ed = ud - rs0 * id + w * k.lq * iq - k.ld * (id_end - id0) / span;
        let eq = uq - rs0 * iq - w * k.ld * id - k.lq * (iq_end - iq0) / span;
        let e_len = (ed * ed + eq * eq).sqrt();
        let w_abs = w.abs();
        if e_len <= T::zero() || !e_len.is_finite() {
            return None;
        }
        let ni = (ed * id + eq * iq) / e_len;
        let m = (e_len + rs0 * ni) / w_abs;
        let r = ni / w_abs;
        // Measurement of the window: m = psi + r Rs. A voltage error reads as a flux error
        // divided by the speed: below ten times the minimum speed the deviation grows as 1/w.
        let knee2 = to_t::<T>(100.0) * k.min_speed2;
        let r_m = if w * w < knee2 {
            self.r_m * knee2 / (w * w)
        } else {
            self.r_m
        };
        Some((m, r, r_m, w))
    }

    /// Anchors the thermal link at `(psi, rs)` (its temperature reference) and restarts the
    /// filter there: the flux's variance `c_pp`, the resistance's the initial one.
    pub(in crate::observer) fn anchor(&mut self, psi: T, rs: T, c_pp: T, k: &TrackerConstants<T>) {
        self.psi = psi;
        self.rs = rs;
        self.c00 = c_pp;
        self.c01 = T::zero();
        self.c11 = k.var0_rs;
        self.psi_a = psi;
        self.rs_a = rs;
        self.anchored = true;
        #[cfg(feature = "std")]
        {
            self.unsteady.provisional = false;
            self.follow_from(T::zero(), k);
        }
    }

    /// The windows-only covariance at an anchor whose flux is the lumped `psi_f + Rs r` of
    /// the operating point `r`: that combination known to the flux's variance, `Rs` to its
    /// initial one (host builds).
    #[cfg(feature = "std")]
    fn follow_from(&mut self, r: T, k: &TrackerConstants<T>) {
        let f = &mut self.follow;
        f.d00 = self.c00 + r * r * k.var0_rs;
        f.d01 = -r * k.var0_rs;
        f.d11 = k.var0_rs;
    }

    /// The windows-only covariance's update with a window's measurement of gradient `(1, r)`
    /// and variance `r_m` (host builds).
    #[cfg(feature = "std")]
    fn follow_window(&mut self, r: T, r_m: T) {
        let f = &mut self.follow;
        let (d00, d01, d11) = (f.d00, f.d01, f.d11);
        let ph0 = d00 + d01 * r;
        let ph1 = d01 + d11 * r;
        let s = ph0 + r * ph1 + r_m;
        if s > T::zero() {
            let inv_s = T::one() / s;
            f.d00 = d00 - ph0 * ph0 * inv_s;
            f.d01 = d01 - ph0 * ph1 * inv_s;
            f.d11 = d11 - ph1 * ph1 * inv_s;
        }
    }

    /// Kalman update of `(psi, Rs)` with a scalar measurement of gradient `(h0, h1)`,
    /// innovation `y` and variance `r`.
    fn scalar_update(&mut self, h0: T, h1: T, y: T, r: T) {
        let (c00, c01, c11) = (self.c00, self.c01, self.c11);
        let ph0 = c00 * h0 + c01 * h1;
        let ph1 = c01 * h0 + c11 * h1;
        let s = h0 * ph0 + h1 * ph1 + r;
        let positive = s > T::zero();
        if !positive {
            return;
        }
        let inv_s = T::one() / s;
        let (k0, k1) = (ph0 * inv_s, ph1 * inv_s);
        self.psi += k0 * y;
        self.rs += k1 * y;
        self.c00 = c00 - k0 * ph0;
        self.c01 = c01 - k0 * ph1;
        self.c11 = c11 - k1 * ph1;
    }
}

/// How a window is read ([`Split::measure`]): the active split filter's, the start-up flux's
/// (no current minimum, the window's own mean `i_d`), or an unsteady window's (the window's
/// own mean `i_d`, a current step up to half the current).
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
enum Reading {
    Active,
    StartUp,
    Unsteady,
}

/// Consecutive start-up windows agreeing with the EKF's converged flux after which the split
/// filter anchors without the EKF's tracking (module docs of the parent, "Resistance while the
/// speed is never steady").
#[cfg(feature = "std")]
pub(super) const AGREEING_WINDOWS: u8 = 4;

/// Windows after that anchor before the unsteady windows update the filter (module docs of the
/// parent, "Resistance while the speed is never steady"): twice the default settling time of
/// the EKF's own tracking (500 samples, windows of 100), so that a drive whose speed settles
/// starts its own tracking first and runs as without these windows.
#[cfg(feature = "std")]
pub(super) const GRACE_WINDOWS: u8 = 10;

/// Square of the share of the window's current by which its own mean `i_d` must differ from
/// the mean of its ends for an active window to take its own (module docs of the parent,
/// "The window's d current"; host builds): 5 %.
const D_MEAN_GAP2: f64 = 0.0025;

/// The largest resistive drop `|Rs r|`, as a share of the flux, of a start-up window that
/// corrects the EKF's flux (module docs of the parent, "Tracking during transients").
const START_UP_DROP_SHARE: f64 = 0.3;

/// The window's speed: the rotation rate of the estimated angle from `theta0` at the window's
/// start to `x`'s at its end, the speed estimate's advance corrected by the angle's own advance
/// modulo a turn (the speed estimate is off by far less than half a turn per window).
fn window_speed<T: Float>(
    theta0: T,
    sums: &Window<T>,
    x: &Vector4<T>,
    k: &TrackerConstants<T>,
) -> T {
    let n = to_t::<T>(f64::from(sums.n));
    let advance = sums.w * k.ts;
    (advance + wrap_angle(x[3] - theta0 - advance)) / (n * k.ts)
}

/// Share of the window's speed (the estimated angle's advance) by which the speed state's
/// mean must differ from it for a window of a frozen, consistent filter to correct `Rs`
/// (module docs of the parent, "Resistance while the filter is in trouble").
pub(super) const SPEED_CONFLICT: f64 = 0.12;

/// The least fall of a braking window's speed below the previous braking window's, as a share
/// of its speed (module docs of the parent, "Resistance on a braking ramp"): 2 %, the start-up
/// flux's rule for a speed change.
#[cfg(feature = "std")]
const BRAKING_SHARE: f64 = 0.02;

/// Whether a window of `r = n.i / |w|` measures the flux rather than `Rs` at the resistance
/// `rs` and flux `psi` (module docs of the parent, "Resistance"): the resistive drop `|Rs r|`
/// within 15 % of the flux.
fn measures_flux<T: Float>(r: T, rs: T, psi: T) -> bool {
    drop_within(r, rs, psi, 0.15)
}

/// Whether the resistive drop `|Rs r|` of a window is within `share` of the flux `psi`.
fn drop_within<T: Float>(r: T, rs: T, psi: T, share: f64) -> bool {
    (r * rs).abs() <= to_t::<T>(share) * psi
}
