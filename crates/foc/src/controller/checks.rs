//! The controller's checks of its inputs (module docs of [`controller`](super), "Bad
//! current samples"): the current sample (plausible step, finite, over-current with its
//! debounce), the bus voltage and the sensor, and the stuck channel.

use super::Foc;
use crate::config::Mode;
use crate::fault::Fault;
use crate::io::{PhaseCurrents, TickInput};
use crate::startup::{Plan, State};
use crate::transforms::{Abc, AlphaBeta};
use crate::trig::{at_most, max2, sqrt};

/// The first non-finite of three values (the last one if none is).
fn first_bad(a: f32, b: f32, c: f32) -> f32 {
    if !a.is_finite() {
        a
    } else if !b.is_finite() {
        b
    } else {
        c
    }
}

impl Foc {
    /// Checks this tick's current sample (module docs, "Bad current samples"): whether it is
    /// used. Counts bad samples and over-current samples in a row and trips when either
    /// count reaches its limit.
    #[inline]
    pub(super) fn check_currents(
        &mut self,
        input: &TickInput,
        i_ab: AlphaBeta,
        c_abs: f32,
    ) -> bool {
        let lim_sq = if self.missed == 0 {
            self.max_step_sq
        } else {
            let lim = self.max_step_a * (f32::from(self.missed) + 1.0);
            lim * lim
        };
        let d = i_ab - self.i_last;
        // False for NaN: a non-finite current is never accepted (`c` too).
        if !(at_most(d.norm_squared(), lim_sq) && at_most(c_abs, f32::MAX)) {
            self.bad_sample(input, i_ab, c_abs);
            return false;
        }
        self.missed = 0;
        self.i_last = i_ab;
        if at_most(i_ab.norm_squared(), self.over_current_sq)
            && at_most(c_abs, self.cfg.over_current_a)
        {
            self.over_current_count = 0;
        } else {
            self.over_current_sample(i_ab, c_abs);
        }
        true
    }

    /// An accepted sample above the over-current level: trips when there have been
    /// `over_current_trip_ticks` in a row.
    #[cold]
    #[inline(never)]
    pub(super) fn over_current_sample(&mut self, i_ab: AlphaBeta, c_abs: f32) {
        self.over_current_count = self.over_current_count.saturating_add(1);
        if self.over_current_count >= self.cfg.samples.over_current_trip_ticks {
            self.trip(Fault::OverCurrent, max2(sqrt(i_ab.norm_squared()), c_abs));
        }
    }

    /// A missing or implausible sample: trips when there have been `missing_trip_ticks` in
    /// a row (non-finite: `NonFiniteInput`; above the over-current level: `OverCurrent`;
    /// else `NonFiniteInput`, an absurd value).
    #[cold]
    #[inline(never)]
    pub(super) fn bad_sample(&mut self, input: &TickInput, i_ab: AlphaBeta, c_abs: f32) {
        self.missed = self.missed.saturating_add(1);
        if self.missed < self.cfg.samples.missing_trip_ticks {
            return;
        }
        let non_finite = match input.currents {
            PhaseCurrents::Abc(x) if !x.is_finite() => Some(first_bad(x.a, x.b, x.c)),
            PhaseCurrents::AlphaBeta(x) if !x.is_finite() => Some(first_bad(x.alpha, x.beta, 0.0)),
            _ => None,
        };
        let magnitude = max2(sqrt(i_ab.norm_squared()), c_abs);
        match non_finite {
            Some(v) => self.trip(Fault::NonFiniteInput, v),
            None if !at_most(magnitude, self.cfg.over_current_a) => {
                self.trip(Fault::OverCurrent, magnitude)
            }
            None => self.trip(Fault::NonFiniteInput, magnitude),
        }
    }

    /// Checks of the bus voltage and the sensor (the currents: `check_currents`); trips the
    /// first fault found.
    #[inline]
    pub(super) fn protect(&mut self, input: &TickInput) {
        // Fast path: comparisons that are false for NaN cover finiteness too.
        let running = !matches!(self.seq.state(), State::Idle | State::Fault);
        let u_dc = input.u_dc_v;
        let u_min = if running {
            self.cfg.u_dc_min_v
        } else {
            -f32::MAX
        };
        let sensor_ok = match input.sensor {
            Some(s) => at_most(s.theta_e_rad.abs(), 1.0e4) && at_most(s.omega_e_rad_s.abs(), 1.0e6),
            None => !(running && self.cfg.mode == Mode::Sensored),
        };
        if at_most(u_dc, self.cfg.u_dc_max_v) && u_dc >= u_min && sensor_ok {
            return;
        }
        self.classify_fault(input, running);
    }

    /// The slow path of [`protect`](Self::protect): which fault, with which value.
    #[cold]
    #[inline(never)]
    pub(super) fn classify_fault(&mut self, input: &TickInput, running: bool) {
        let u_dc = input.u_dc_v;
        // Non-finite or absurd inputs.
        let bad = if !u_dc.is_finite() {
            Some(u_dc)
        } else {
            match input.sensor {
                Some(s) if !at_most(s.theta_e_rad.abs(), 1.0e4) => Some(s.theta_e_rad),
                Some(s) if !at_most(s.omega_e_rad_s.abs(), 1.0e6) => Some(s.omega_e_rad_s),
                None if running && self.cfg.mode == Mode::Sensored => Some(f32::NAN),
                _ => None,
            }
        };
        if let Some(v) = bad {
            self.trip(Fault::NonFiniteInput, v);
            return;
        }
        if u_dc > self.cfg.u_dc_max_v {
            self.trip(Fault::BusOverVoltage, u_dc);
        } else if running && u_dc < self.cfg.u_dc_min_v {
            self.trip(Fault::BusUnderVoltage, u_dc);
        }
    }

    /// A phase reading repeated: accumulates the angle the current vector turned meanwhile
    /// (only while the commanded current is at least 5 % of the current limit) and trips
    /// [`Fault::CurrentSensor`] once it exceeds `samples.stuck_angle_rad` (and at least 4
    /// ticks). Returns whether it tripped.
    ///
    /// The angle accrues at the larger of the frame's present speed and its speed when the
    /// repetition began. The frozen reading feeds the observer, so the frame's speed soon
    /// follows the fault, not the rotor: on the servo test rig at 400 rad/s el. it swings
    /// between -260 and +830 rad/s within a quarter period, and counted at the present
    /// speed alone a quarter turn took up to 1.4 quarter periods. A rotor cannot shed its
    /// speed that fast, so the speed at the onset bounds the rate the real vector turns.
    #[cold]
    #[inline(never)]
    pub(super) fn stuck_channel(&mut self, same: [bool; 2], x: Abc, plan: Plan) -> bool {
        let limit = self.cfg.samples.stuck_angle_rad;
        let i_min = 0.05 * self.cfg.current_limit_a;
        let driven = at_most(i_min * i_min, plan.i_ref.norm_squared());
        let w = max2(plan.frame.omega, -plan.frame.omega);
        for (ch, v) in [x.a, x.b].into_iter().enumerate() {
            if !same[ch] {
                self.stuck_angle[ch] = 0.0;
                self.stuck_ticks[ch] = 0;
                continue;
            }
            if self.stuck_ticks[ch] == 0 {
                self.stuck_omega[ch] = w;
            }
            if driven {
                self.stuck_angle[ch] += max2(w, self.stuck_omega[ch]) * self.cfg.ts_s;
            }
            self.stuck_ticks[ch] = self.stuck_ticks[ch].saturating_add(1);
            if limit > 0.0 && self.stuck_angle[ch] > limit && self.stuck_ticks[ch] >= 4 {
                self.trip(Fault::CurrentSensor, v);
                return true;
            }
        }
        false
    }
}
