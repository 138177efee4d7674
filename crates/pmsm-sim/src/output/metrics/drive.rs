//! The drive's metrics: closed loop, speed tracking once settled, start-up and speed reversal (the streaming scores and what they report).

use super::*;

/// Figures of the drive.
#[derive(Clone, Debug, Default, PartialEq, Serialize)]
pub struct DriveMetrics {
    /// First time the controller ran on a rotor angle (for `foc` sensorless, the hand-over to
    /// its observer), s; `None`: never.
    pub closed_loop_time_s: Option<f64>,
    /// Share of the periods in closed loop, %.
    pub closed_loop_pct: f64,
    /// Times the controller left closed loop (`foc`: the planned returns to I/f near zero
    /// speed, and fall-backs after an observer loss).
    pub closed_loop_exits: usize,
    /// The first fault the controller reported, with its time (`"stall at 0.8123 s"`).
    pub fault: Option<String>,
    /// Periods counted as settled ([`SETTLE_S`]), s.
    pub settled_s: f64,
    /// RMS of `speed - reference` over the settled periods, mechanical rpm.
    pub speed_error_settled_rms_rpm: f64,
    /// Mean of `speed - reference` over the settled periods, mechanical rpm.
    pub speed_error_settled_mean_rpm: f64,
    /// Largest `|speed - reference|` over the settled periods, mechanical rpm.
    pub speed_error_settled_max_rpm: f64,
    /// Largest current vector magnitude, A.
    pub peak_current_a: f64,
    /// Largest `|speed reference - speed|`, mechanical rpm (start-up, ramps and load steps
    /// included).
    pub max_speed_tracking_error_rpm: f64,
    /// RMS of `i_q_ref - i_q` (controller's frame, measured currents), A.
    pub iq_tracking_error_rms_a: f64,
    /// Mechanical speed at the end of the run, rpm.
    pub final_speed_rpm: f64,
    /// Share of periods in which the voltage vector was limited, %.
    pub voltage_limited_pct: f64,
}

/// Streaming accumulator of [`DriveMetrics`].
#[derive(Clone, Debug, Default, PartialEq)]
pub struct DriveScore {
    pub(super) n: usize,
    pub(super) peak_sq: f64,
    pub(super) max_track: f64,
    pub(super) sum_iq_e2: f64,
    pub(super) last_rpm: f64,
    pub(super) limited: usize,
    pub(super) closed_loop_t: Option<f64>,
    pub(super) closed: usize,
    pub(super) was_closed: bool,
    pub(super) exits: usize,
    pub(super) fault: Option<String>,
    pub(super) load_step_nm: f64,
    pub(super) prev: Option<(f64, f64)>,
    pub(super) quiet_since: f64,
    pub(super) settled: usize,
    pub(super) sum_se: f64,
    pub(super) sum_se2: f64,
    pub(super) max_se: f64,
}

impl DriveScore {
    /// An accumulator; load changes above `LOAD_STEP_FRACTION * rated_torque_nm` in one
    /// period count as steps.
    pub fn new(rated_torque_nm: f64) -> Self {
        Self {
            load_step_nm: LOAD_STEP_FRACTION * rated_torque_nm,
            ..Self::default()
        }
    }

    /// Adds one sample.
    #[inline]
    pub fn push(&mut self, s: &Sample) {
        self.n += 1;
        let tel = &s.control.telemetry;
        let [a, b] = s.truth.i_ab_a;
        self.peak_sq = self.peak_sq.max(a * a + b * b);
        let w_ref = s.control.speed_ref_rpm;
        let e_w = s.truth.speed_rpm - w_ref;
        self.max_track = self.max_track.max(e_w.abs());
        let e = tel.i_dq_ref_a[1] - tel.i_dq_a[1];
        self.sum_iq_e2 += e * e;
        self.last_rpm = s.truth.speed_rpm;
        self.limited += usize::from(tel.voltage_limited);
        if tel.closed_loop {
            self.closed += 1;
            if self.closed_loop_t.is_none() {
                self.closed_loop_t = Some(s.t_s);
            }
        } else if self.was_closed {
            self.exits += 1;
        }
        self.was_closed = tel.closed_loop;
        if self.fault.is_none()
            && let Some(f) = tel.fault
        {
            self.fault = Some(format!("{f} at {:.4} s", s.t_s));
        }
        let load = s.truth.load_torque_nm;
        match self.prev {
            Some((r, l)) if r == w_ref && (load - l).abs() <= self.load_step_nm => {}
            _ => self.quiet_since = s.t_s,
        }
        self.prev = Some((w_ref, load));
        if s.t_s - self.quiet_since >= SETTLE_S - 1e-9 {
            self.settled += 1;
            self.sum_se += e_w;
            self.sum_se2 += e_w * e_w;
            self.max_se = self.max_se.max(e_w.abs());
        }
    }

    /// The figures so far; `ts_s` is the period.
    pub fn finish(&self, ts_s: f64) -> DriveMetrics {
        let n = self.n.max(1) as f64;
        let ns = self.settled as f64;
        let per = |x: f64| if self.settled > 0 { x / ns } else { f64::NAN };
        DriveMetrics {
            closed_loop_time_s: self.closed_loop_t,
            closed_loop_pct: 100.0 * self.closed as f64 / n,
            closed_loop_exits: self.exits,
            fault: self.fault.clone(),
            settled_s: ns * ts_s,
            speed_error_settled_rms_rpm: per(self.sum_se2).sqrt(),
            speed_error_settled_mean_rpm: per(self.sum_se),
            speed_error_settled_max_rpm: if self.settled > 0 {
                self.max_se
            } else {
                f64::NAN
            },
            peak_current_a: self.peak_sq.sqrt(),
            max_speed_tracking_error_rpm: self.max_track,
            iq_tracking_error_rms_a: (self.sum_iq_e2 / n).sqrt(),
            final_speed_rpm: self.last_rpm,
            voltage_limited_pct: 100.0 * self.limited as f64 / n,
        }
    }
}

/// Streaming accumulator of [`ClosedLoopObserverMetrics`].
#[derive(Clone, Copy, Debug, Default, PartialEq)]
pub struct ClosedLoopScore {
    pub(super) w_min: f64,
    pub(super) sums: Sums,
}

impl ClosedLoopScore {
    /// A scorer leaving out `|w_e|` below 5 % of `rated_omega_e_rad_s`.
    pub fn new(rated_omega_e_rad_s: f64) -> Self {
        Self {
            w_min: LOW_SPEED_FRACTION * rated_omega_e_rad_s,
            sums: Sums::default(),
        }
    }

    /// Adds one sample (ignored outside the window or without a controller observer).
    #[inline]
    pub fn push(&mut self, s: &Sample) {
        if let Some(o) = &s.controller_observer
            && s.control.telemetry.closed_loop
            && s.truth.omega_e_rad_s.abs() >= self.w_min
        {
            self.sums
                .add(o.angle_error_deg, o.speed_error_rad_s, o.tracking, o.nis);
        }
    }

    /// The figures so far (`None`: empty window).
    pub fn finish(&self, ts_s: f64) -> Option<ClosedLoopObserverMetrics> {
        let s = &self.sums;
        if s.n == 0 {
            return None;
        }
        let nf = s.n as f64;
        Some(ClosedLoopObserverMetrics {
            window_samples: s.n,
            window_s: nf * ts_s,
            angle_error_rms_deg: s.angle_rms_deg(),
            angle_error_max_deg: s.max_e,
            angle_error_mean_deg: s.angle_mean_deg(),
            speed_error_rms_rad_s: s.speed_rms_rad_s(),
            speed_error_max_rad_s: s.max_w,
        })
    }
}

/// Figures of a sensorless start (module docs): the first `align`/`open_loop` -> `handover`
/// of the run.
#[derive(Clone, Copy, Debug, Default, PartialEq, Serialize)]
pub struct StartupMetrics {
    /// Time of the first start-up period (`align` or `open_loop`), s.
    pub start_s: f64,
    /// End of the alignment (first `open_loop` period), s; `None`: never reached.
    pub align_end_s: Option<f64>,
    /// Largest backward (negative) true speed over the start, mechanical rpm (0: never).
    pub backward_speed_max_rpm: f64,
    /// The same in % of rated speed.
    pub backward_speed_max_pct: f64,
    /// Largest `|speed - ramp speed|` from [`RAMP_SETTLE_S`] after the alignment to the
    /// hand-over, mechanical rpm (`NaN`: an empty window).
    pub ramp_deviation_max_rpm: f64,
    /// The same in % of rated speed.
    pub ramp_deviation_max_pct: f64,
    /// Time of the hand-over (first `handover` period), s; `None`: no hand-over.
    pub handover_s: Option<f64>,
    /// `|ramp speed|` at the hand-over (of the last I/f period), mechanical rpm (`NaN`: no
    /// hand-over).
    pub handover_speed_rpm: f64,
    /// The same in % of rated speed.
    pub handover_speed_pct: f64,
    /// True speed at the hand-over, mechanical rpm (`NaN`: no hand-over).
    pub handover_true_speed_rpm: f64,
}

/// Streaming accumulator of [`StartupMetrics`].
#[derive(Clone, Copy, Debug, Default, PartialEq)]
pub struct StartupScore {
    pub(super) rated_rpm: f64,
    pub(super) start: Option<f64>,
    pub(super) align_end: Option<f64>,
    pub(super) done: bool,
    pub(super) backward: f64,
    pub(super) deviation: Option<f64>,
    pub(super) ramp: f64,
    pub(super) handover: Option<(f64, f64, f64)>,
}

impl StartupScore {
    /// An accumulator; `rated_rpm` is the rated mechanical speed (for the % figures).
    pub fn new(rated_rpm: f64) -> Self {
        Self {
            rated_rpm,
            ..Self::default()
        }
    }

    /// Adds one sample.
    #[inline]
    pub fn push(&mut self, s: &Sample) {
        if self.done {
            return;
        }
        let tel = &s.control.telemetry;
        let state = tel.state;
        let starting = state == "align" || state == "open_loop";
        if self.start.is_none() {
            if !starting {
                return;
            }
            self.start = Some(s.t_s);
        }
        if state == "handover" || state == "closed_loop" || !starting {
            if state == "handover" {
                self.handover = Some((s.t_s, self.ramp.abs(), s.truth.speed_rpm));
            }
            self.done = true;
            return;
        }
        let w = s.truth.speed_rpm;
        self.backward = self.backward.max(-w);
        if state == "open_loop" {
            self.ramp = tel.speed_ref_rpm.unwrap_or(f64::NAN);
            let t0 = *self.align_end.get_or_insert(s.t_s);
            if s.t_s >= t0 + RAMP_SETTLE_S - 1e-9
                && let Some(r) = tel.speed_ref_rpm
            {
                let d = (w - r).abs();
                self.deviation = Some(self.deviation.map_or(d, |m: f64| m.max(d)));
            }
        }
    }

    /// The figures (`None`: no start-up in the run).
    pub fn finish(&self) -> Option<StartupMetrics> {
        let start_s = self.start?;
        let pct = |x: f64| 100.0 * x / self.rated_rpm;
        let dev = self.deviation.unwrap_or(f64::NAN);
        let (handover_s, ho, ho_true) = match self.handover {
            Some((t, r, w)) => (Some(t), r, w),
            None => (None, f64::NAN, f64::NAN),
        };
        Some(StartupMetrics {
            start_s,
            align_end_s: self.align_end,
            backward_speed_max_rpm: self.backward,
            backward_speed_max_pct: pct(self.backward),
            ramp_deviation_max_rpm: dev,
            ramp_deviation_max_pct: pct(dev),
            handover_s,
            handover_speed_rpm: ho,
            handover_speed_pct: pct(ho),
            handover_true_speed_rpm: ho_true,
        })
    }
}

/// Figures of the speed reversals of a run (module docs): the worst over its reversals.
#[derive(Clone, Copy, Debug, Default, PartialEq, Serialize)]
pub struct ReversalMetrics {
    /// Reversals scored (zero crossings of the speed reference).
    pub count: usize,
    /// Start of the first one (the reference leaves its last constant value), s.
    pub first_start_s: f64,
    /// Longest time outside closed loop within one reversal (the controller's
    /// `closed_loop` flag off), s.
    pub outside_closed_loop_max_s: f64,
    /// Closed-loop exits within the reversals (planned returns to I/f and fall-backs).
    pub closed_loop_exits: usize,
    /// Largest `|speed reference - speed|` within a reversal, mechanical rpm.
    pub tracking_error_max_rpm: f64,
    /// The same in % of rated speed.
    pub tracking_error_max_pct: f64,
}

/// One reversal in progress.
#[derive(Clone, Copy, Debug, Default, PartialEq)]
pub(super) struct Pass {
    pub(super) start: f64,
    pub(super) outside: usize,
    pub(super) exits: usize,
    pub(super) max_err: f64,
}

impl Pass {
    pub(super) fn add(&mut self, err: f64, closed: bool, exit: bool) {
        self.max_err = self.max_err.max(err);
        self.outside += usize::from(!closed);
        self.exits += usize::from(exit);
    }
}

/// Streaming accumulator of [`ReversalMetrics`].
///
/// A **reversal** is a change of sign of the scenario's speed reference (zero itself
/// belongs to neither side). Its window opens where the reference left its last constant
/// value before the crossing (the start of the ramp, or the step) and closes once the
/// reference has been constant for [`SETTLE_S`] after the crossing (or at the end of the
/// run): the approach, the crossing and the catch-up after it. Over the window: the time
/// the controller is not in closed loop, its exits from closed loop, and the largest
/// `|speed reference - speed|` (true mechanical speed).
#[derive(Clone, Debug, Default, PartialEq)]
pub struct ReversalScore {
    pub(super) rated_rpm: f64,
    pub(super) prev_ref: Option<f64>,
    /// Sign of the last non-zero reference.
    pub(super) sign: f64,
    /// The moving segment since the reference was last constant (a reversal candidate).
    pub(super) moving: Option<Pass>,
    /// The reversal under way (crossed), and the time its reference became constant.
    pub(super) active: Option<Pass>,
    pub(super) quiet_since: Option<f64>,
    pub(super) was_closed: bool,
    pub(super) count: usize,
    pub(super) first_start: Option<f64>,
    pub(super) outside_max: usize,
    pub(super) exits: usize,
    pub(super) max_err: f64,
}

impl ReversalScore {
    /// An accumulator; `rated_rpm` is the rated mechanical speed (for the % figure).
    pub fn new(rated_rpm: f64) -> Self {
        Self {
            rated_rpm,
            ..Self::default()
        }
    }

    pub(super) fn close(&mut self, p: Pass) {
        self.count += 1;
        self.first_start.get_or_insert(p.start);
        self.outside_max = self.outside_max.max(p.outside);
        self.exits += p.exits;
        self.max_err = self.max_err.max(p.max_err);
    }

    /// Adds one sample.
    #[inline]
    pub fn push(&mut self, s: &Sample) {
        let r = s.control.speed_ref_rpm;
        let closed = s.control.telemetry.closed_loop;
        let exit = self.was_closed && !closed;
        self.was_closed = closed;
        let err = (s.truth.speed_rpm - r).abs();
        let still = self.prev_ref == Some(r);
        self.prev_ref = Some(r);
        if still {
            self.moving = None;
        } else {
            self.moving.get_or_insert(Pass {
                start: s.t_s,
                ..Pass::default()
            });
        }
        if let Some(m) = self.moving.as_mut() {
            m.add(err, closed, exit);
        }
        let crossed = r != 0.0 && self.sign != 0.0 && r.signum() != self.sign;
        if r != 0.0 {
            self.sign = r.signum();
        }
        if let Some(a) = self.active.as_mut() {
            // A crossing while one is under way continues it.
            a.add(err, closed, exit);
        } else if crossed {
            // The approach (this moving segment, this sample included) opens the reversal.
            self.active = self.moving;
            self.quiet_since = None;
        }
        if self.active.is_some() {
            let q = if still {
                *self.quiet_since.get_or_insert(s.t_s)
            } else {
                self.quiet_since = None;
                s.t_s
            };
            if s.t_s - q >= SETTLE_S - 1e-9
                && let Some(p) = self.active.take()
            {
                self.close(p);
                self.quiet_since = None;
            }
        }
    }

    /// The figures (`None`: no reversal), with samples of period `ts_s`; a reversal still
    /// under way at the end counts.
    pub fn finish(&self, ts_s: f64) -> Option<ReversalMetrics> {
        let mut me = self.clone();
        if let Some(p) = me.active.take() {
            me.close(p);
        }
        let start = me.first_start?;
        Some(ReversalMetrics {
            count: me.count,
            first_start_s: start,
            outside_closed_loop_max_s: me.outside_max as f64 * ts_s,
            closed_loop_exits: me.exits,
            tracking_error_max_rpm: me.max_err,
            tracking_error_max_pct: 100.0 * me.max_err / self.rated_rpm,
        })
    }
}
