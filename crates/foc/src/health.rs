//! Observer health: is the EKF's angle good enough to close the loop on?
//!
//! Evaluated every tick in sensorless mode from the observer's [`Estimate`] and what the
//! controller knows independently (the I/f current vector and its speed, the speed reference):
//!
//! - **NIS.** An exponential moving average (time constant `window_s`) of the normalized
//!   innovation squared. For a consistent filter its mean is 2 (two measurements); above
//!   `nis_limit` the model no longer explains the currents.
//! - **Speed consistency.** The moving average of the angle increments per period,
//!   `wrap(th_k - th_k-1) / Ts`, against the moving average of the speed estimate. In a
//!   healthy EKF the angle advances by `w Ts` plus zero-mean corrections; a filter that is
//!   slipping or re-converging moves its angle by corrections that do not average out.
//!   Tolerance `speed_tolerance * max(|w|, w_handover)`.
//! - **Status.** The angle's standard deviation above the observer's limit, or its
//!   innovations out of line ([`Estimate::angle_tracked`], [`Estimate::inconsistent`]). The
//!   observer's [`Status`](ekf_core::Status) also reads `Uncertain` while the speed is not
//!   known to be away from zero; the controller knows that from its own state machine, so
//!   that part is not a loss here.
//! - **theta + pi lock** (docs/design.md, "The reference filter": `(w, th)` and `(-w, th + pi)` give the same
//!   back-EMF). Under I/f the rotor's d axis stays within 90 deg of the current vector
//!   (a stable load angle), so an estimate more than `lock_angle_rad` (default 135 deg) away
//!   from the vector, or a speed estimate of the opposite sign to the ramp (beyond a quarter
//!   of it), is the wrong solution; checked once the ramp is above half the hand-over speed.
//!   In closed loop: the speed estimate has the opposite sign to the speed reference, while
//!   the reference is at or above the exit speed (inside that band a closed-loop reversal
//!   passes through zero, and a rotor lagging its reference turns the other way for a moment).
//! - **Tracked flux** (closed loop): the observer's tracked flux linkage outside
//!   `flux_range` (default 0.7 to 1.3) times the configured one. Heat moves it by about 12 %
//!   per 100 K; a fit beyond the range means the model no longer describes the motor (an
//!   open phase, a demagnetized or wrong motor). A warm motor is no loss: the tracked flux
//!   and resistance keep the NIS consistent.
//! - **Stall** (closed loop): the speed loop at its current limit while the estimated speed
//!   stays below half of `max(exit speed, 0.7 hand-over speed)` or has the wrong sign (an overload that drives the
//!   rotor backwards). While this holds, the loss checks are suspended: a rotor that does
//!   not follow a saturated speed loop is reported as a stall after `stall_time_s`, not as
//!   an observer loss after `lost_time_s`.
//!
//! Each condition must persist (`lost_time_s`, `lock_time_s`, `stall_time_s`, counted in
//! ticks) before it is reported, so single bad samples do nothing. What the controller does
//! with the report is in [`startup`](crate::startup).

use ekf_core::Estimate;

use crate::config::HealthConfig;
use crate::trig::{at_most, max2, wrap};

/// Which health check failed.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum LossReason {
    /// The observer refused its step (non-finite result or singular innovation covariance).
    StepFailed,
    /// The observer's angle is not tracked (covariance) or its innovations are out of line.
    Uncertain,
    /// Average NIS above `nis_limit`.
    Nis,
    /// Speed estimate and angle rate disagree.
    SpeedInconsistent,
    /// The tracked flux linkage left `flux_range` (closed loop).
    FluxImplausible,
    /// The estimate sits on the `theta + pi` solution.
    PiLock,
}

/// What the controller knows independently of the observer, for this tick.
#[derive(Clone, Copy, Debug, PartialEq)]
pub(crate) enum Reference {
    /// Open-loop I/f: current vector angle `gamma` (rad) and its speed `omega` (rad/s el.).
    OpenLoop { gamma: f32, omega: f32 },
    /// Closed loop: speed reference (rad/s el.) and whether the speed loop is at its limit.
    ClosedLoop { speed_ref: f32, saturated: bool },
    /// Nothing to compare with (alignment).
    None,
}

/// The monitor's findings for one tick (also in the telemetry).
#[derive(Clone, Copy, Debug, Default, PartialEq)]
pub struct HealthReport {
    /// Moving average of the NIS.
    pub nis_avg: f32,
    /// Moving average of the speed estimate, rad/s el.
    pub omega_avg_rad_s: f32,
    /// Speed estimate minus angle rate (moving averages), rad/s el.
    pub speed_mismatch_rad_s: f32,
    /// Observer angle minus I/f current-vector angle, wrapped, rad (0 outside I/f).
    pub angle_offset_rad: f32,
    /// The observer has been healthy and consistent with the I/f ramp for `lock_time_s`.
    pub ready: bool,
    /// A loss condition has persisted for `lost_time_s` (the first failing check).
    pub lost: Option<LossReason>,
    /// The stall condition has persisted for `stall_time_s`.
    pub stall: bool,
}

/// Health monitor state.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct HealthMonitor {
    cfg: HealthConfig,
    inv_ts: f32,
    handover: f32,
    exit_speed: f32,
    /// Below this estimated speed a saturated speed loop is a stall, rad/s el.:
    /// `0.5 max(exit_speed, 0.7 handover)`.
    stall_speed: f32,
    /// EMA coefficient `Ts / window`.
    k: f32,
    lost_ticks: u32,
    lock_ticks: u32,
    stall_ticks: u32,
    nis_avg: f32,
    omega_avg: f32,
    rate_avg: f32,
    prev_theta: f32,
    has_prev: bool,
    bad_count: u32,
    ready_count: u32,
    stall_count: u32,
    /// Bounds of the tracked flux linkage, Wb.
    flux_lo: f32,
    flux_hi: f32,
}

/// The stall check's speed is half of at least this fraction of the hand-over speed (the
/// largest default exit ratio): a low exit speed does not lower it. With an exit at 1.5 % of
/// the base speed, half of it missed foc's jammed-rotor stall on the test rig (the observer's
/// speed of a jammed rotor under the saturated current crossed it).
const STALL_HANDOVER_RATIO: f32 = 0.7;

/// Number of ticks in `t` seconds, at least 1.
pub(crate) fn ticks(t_s: f32, ts_s: f32) -> u32 {
    let n = t_s / ts_s + 0.5;
    if n >= 1.0 { n as u32 } else { 1 }
}

impl HealthMonitor {
    /// A monitor with thresholds `cfg` at the PWM period `ts_s`, for the hand-over speed and
    /// the closed-loop exit speed (rad/s el.).
    pub fn new(
        cfg: &HealthConfig,
        ts_s: f32,
        handover_rad_s: f32,
        exit_rad_s: f32,
        psi_f_wb: f32,
    ) -> Self {
        let k = ts_s / cfg.window_s;
        Self {
            cfg: *cfg,
            flux_lo: cfg.flux_range[0] * psi_f_wb,
            flux_hi: cfg.flux_range[1] * psi_f_wb,
            inv_ts: 1.0 / ts_s,
            handover: handover_rad_s,
            exit_speed: exit_rad_s,
            stall_speed: 0.5 * max2(exit_rad_s, STALL_HANDOVER_RATIO * handover_rad_s),
            k: if k < 1.0 { k } else { 1.0 },
            lost_ticks: ticks(cfg.lost_time_s, ts_s),
            lock_ticks: ticks(cfg.lock_time_s, ts_s),
            stall_ticks: ticks(cfg.stall_time_s, ts_s),
            nis_avg: 0.0,
            omega_avg: 0.0,
            rate_avg: 0.0,
            prev_theta: 0.0,
            has_prev: false,
            bad_count: 0,
            ready_count: 0,
            stall_count: 0,
        }
    }

    /// Forgets the history (after the observer was re-seeded at speed `omega` rad/s el.).
    pub fn reset(&mut self, omega: f32) {
        self.nis_avg = 0.0;
        self.omega_avg = omega;
        self.rate_avg = omega;
        self.has_prev = false;
        self.bad_count = 0;
        self.ready_count = 0;
        self.stall_count = 0;
    }

    /// One tick: the estimate, whether the observer's step succeeded, and the reference.
    /// Inlined into the tick (once per tick, from the sequencer): the report then stays in
    /// registers instead of going through memory.
    #[inline(always)]
    pub(crate) fn update(
        &mut self,
        est: &Estimate<f32>,
        step_ok: bool,
        reference: Reference,
    ) -> HealthReport {
        let w = est.omega_e_rad_s;
        let th = est.theta_rad;
        let k = self.k;
        if step_ok {
            self.nis_avg += k * (est.nis - self.nis_avg);
            self.omega_avg += k * (w - self.omega_avg);
            let rate = if self.has_prev {
                wrap(th - self.prev_theta) * self.inv_ts
            } else {
                w
            };
            self.rate_avg += k * (rate - self.rate_avg);
            self.prev_theta = th;
            self.has_prev = true;
        }
        let mismatch = self.omega_avg - self.rate_avg;
        let scale = max2(self.omega_avg.abs(), self.handover);
        let tol = self.cfg.speed_tolerance * scale;

        // First failing basic check.
        let basic = if !step_ok {
            Some(LossReason::StepFailed)
        } else if !est.angle_tracked || est.inconsistent {
            Some(LossReason::Uncertain)
        } else if !at_most(self.nis_avg, self.cfg.nis_limit) {
            Some(LossReason::Nis)
        } else if !at_most(mismatch.abs(), tol) {
            Some(LossReason::SpeedInconsistent)
        } else {
            None
        };

        let mut offset = 0.0;
        let mut ready = false;
        let mut stall = false;
        let bad = match reference {
            Reference::OpenLoop { gamma, omega } => {
                offset = wrap(th - gamma);
                let fast = omega.abs() >= 0.5 * self.handover;
                let opposite = w * omega < 0.0 && w.abs() > 0.25 * omega.abs();
                let lock = fast
                    && est.angle_tracked
                    && !est.inconsistent
                    && (offset.abs() > self.cfg.lock_angle_rad || opposite);
                let agrees = w * omega > 0.0
                    && offset.abs() < 0.5 * core::f32::consts::PI
                    && (self.omega_avg - omega).abs() <= self.cfg.speed_tolerance * omega.abs();
                ready = basic.is_none() && agrees && fast;
                // Under I/f only the theta+pi lock counts as a loss: the other checks are
                // expected to fail at low speed and only delay the hand-over.
                if lock { Some(LossReason::PiLock) } else { None }
            }
            Reference::ClosedLoop {
                speed_ref,
                saturated,
            } => {
                let wrong_way = w * speed_ref < 0.0;
                stall = saturated && (w.abs() < self.stall_speed || wrong_way);
                if stall {
                    // A rotor that does not follow a saturated speed loop is a stall (or an
                    // overload), not an observer failure: the stall timer decides.
                    None
                } else if basic.is_some() {
                    basic
                } else if wrong_way
                    && w.abs() > 0.25 * self.exit_speed
                    && speed_ref.abs() >= self.exit_speed
                {
                    Some(LossReason::PiLock)
                } else if !(est.psi_f_wb >= self.flux_lo && est.psi_f_wb <= self.flux_hi) {
                    Some(LossReason::FluxImplausible)
                } else {
                    None
                }
            }
            Reference::None => None,
        };

        self.bad_count = if bad.is_some() {
            self.bad_count.saturating_add(1)
        } else {
            0
        };
        self.ready_count = if ready {
            self.ready_count.saturating_add(1)
        } else {
            0
        };
        self.stall_count = if stall {
            self.stall_count.saturating_add(1)
        } else {
            0
        };
        HealthReport {
            nis_avg: self.nis_avg,
            omega_avg_rad_s: self.omega_avg,
            speed_mismatch_rad_s: mismatch,
            angle_offset_rad: offset,
            ready: self.ready_count >= self.lock_ticks,
            lost: if self.bad_count >= self.lost_ticks {
                bad
            } else {
                None
            },
            stall: self.stall_count >= self.stall_ticks,
        }
    }
}
