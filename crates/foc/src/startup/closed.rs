//! `ClosedLoop` (and the speed loop and exits `Handover` shares with it; module docs of
//! [`startup`](super), "Closed loop").
//!
//! The speed loop, every `speed_divider` ticks: the reference slews toward the command
//! (clamped to the maximum speed; zero for a stop) at `speed_slew_rad_s2`, or at
//! `accel_rad_s2` while `|reference| <= w_h` in sensorless mode (except a closed-loop pass
//! through zero), and a PI on the mechanical speed gives the torque command `i_q`,
//! limited to the torque current limit. Per tick, in this order:
//!
//! 1. a stall reported by the health monitor trips `Stall`;
//! 2. a loss trips `ObserverLost` ([`ObserverLossPolicy::Trip`]) or falls back to I/f at
//!    the commanded speed with the observer re-seeded at the new vector (more than
//!    `max_reacquire` in a row trip);
//! 3. else the speed loop; the blend's timer (-> `ClosedLoop` after `blend_time_s`) or the
//!    closed-loop count (after `acquire_timeout_s` the re-acquisitions count from zero);
//!    below the exit speed, unless passing through zero ([`Reversal::ClosedLoop`]), back to
//!    I/f at the observer's speed.
//!
//! The I/f vector after closed loop: `|i| = max(I_f, min(max(|i_q|, |integrator|) / 0.95,
//! current_limit))`, its q part the last `i_q` (limited to `0.95 |i|`), its angle
//! `th + atan2(i_q, i_d)`.

use ekf_core::Estimate;

use super::ramp::Ramp;
use super::{
    Command, Frame, Params, Phase, Seed, Sequencer, State, Stop, observer_frame, reseed_observer,
    sign, slew, through_zero,
};
#[cfg(doc)]
use crate::config::Reversal;
use crate::config::{FocConfig, Mode, ObserverLossPolicy};
use crate::fault::Fault;
use crate::health::HealthReport;
use crate::pi::{Pi, limit};
use crate::trig::{atan2, max2, min2, sqrt, wrap};
use core::f32::consts::FRAC_PI_4;

/// The closed loop's variables.
#[derive(Clone, Copy, Debug, Default, PartialEq)]
pub(super) struct Closed {
    /// Ticks in closed loop.
    cl_ticks: u32,
    /// The blend's d current (faded to zero: the reference's d part is `i_d0 * 0`), A.
    pub i_d0: f32,
}

/// The speed loop (kept across states: I/f sets its reference, the hand-over presets it).
#[derive(Clone, Debug)]
pub(super) struct SpeedLoop {
    /// Slewed speed reference, rad/s mech.
    pub reference_mech: f32,
    /// Output of the speed loop (torque command), A.
    pub i_q_ref: f32,
    /// The speed loop is at its current limit.
    pub saturated: bool,
    /// Ticks since the last speed-loop run.
    pub div: u16,
    /// Ticks the slewed speed reference has not moved.
    pub still: u32,
    /// The PI.
    pub pi: Pi,
}

impl SpeedLoop {
    pub fn new(pi: Pi) -> Self {
        Self {
            reference_mech: 0.0,
            i_q_ref: 0.0,
            saturated: false,
            div: 0,
            still: 0,
            pi,
        }
    }

    /// At a start: the PI and the variables reset.
    pub fn restart(&mut self) {
        self.pi.reset();
        self.reference_mech = 0.0;
        self.i_q_ref = 0.0;
        self.saturated = false;
        self.div = 0;
        self.still = 0;
    }

    /// The speed loop, every `speed_divider` ticks: slews the reference toward the command
    /// and runs the PI on the measured mechanical speed `omega_mech`; the output is the
    /// torque command. `closed_loop`: the sequencer is in `ClosedLoop`.
    #[inline(always)]
    pub fn step(
        &mut self,
        cfg: &FocConfig,
        k: &Params,
        cmd: &Command,
        closed_loop: bool,
        omega_mech: f32,
    ) {
        self.div = self.div.saturating_add(1);
        if self.div < cfg.speed_divider {
            return;
        }
        self.div = 0;
        let max = cfg.max_speed_rad_s * k.inv_pole_pairs;
        let target = if cmd.stop_requested {
            0.0
        } else {
            limit(cmd.target_mech, -max, max)
        };
        // Sensorless, below the hand-over speed the reference moves at the I/f acceleration,
        // so that the rotor reaches the exit speed with a torque the I/f vector continues
        // smoothly.
        let slow = (self.reference_mech * k.pole_pairs).abs() <= k.handover;
        // (Through zero in closed loop the reference keeps its slew rate; the hand-over's own
        // first step at the ramp speed stays at the I/f acceleration either way.)
        let keep = through_zero(cfg, k, cmd, self.still) && closed_loop;
        let rate = if slow && cfg.mode == Mode::Sensorless && !keep {
            cfg.startup.accel_rad_s2
        } else {
            cfg.speed_slew_rad_s2
        };
        let step = rate * k.inv_pole_pairs * cfg.ts_s * f32::from(cfg.speed_divider);
        let moved = slew(self.reference_mech, target, step);
        self.still = if moved == self.reference_mech {
            self.still.saturating_add(u32::from(cfg.speed_divider))
        } else {
            0
        };
        self.reference_mech = moved;
        // A torque command (surface-equivalent current, module `mtpa`): `current_limit_a`
        // for a surface motor.
        let lim = cfg.torque_current_limit_a();
        let iq = self
            .pi
            .step(self.reference_mech - omega_mech, 0.0, -lim, lim);
        self.i_q_ref = iq;
        self.saturated = iq.abs() >= 0.999 * lim;
    }
}

impl Sequencer {
    /// One tick of `Handover` or `ClosedLoop` (steps 1 to 3 of the module docs). Returns the
    /// frame the current loops leave when they go back to I/f.
    #[inline(always)]
    pub(super) fn closed_loop(
        &mut self,
        cfg: &FocConfig,
        est: &Estimate<f32>,
        report: &HealthReport,
        reseed: &mut impl FnMut(Seed),
    ) -> Result<Option<Frame>, Stop> {
        if report.stall {
            return Err(Stop::Trip(Fault::Stall, est.omega_e_rad_s));
        }
        if report.lost.is_some() {
            return match cfg.health.policy {
                ObserverLossPolicy::Trip => Err(Stop::Trip(Fault::ObserverLost, est.omega_e_rad_s)),
                ObserverLossPolicy::FallBackAndReacquire => {
                    self.attempts = self.attempts.saturating_add(1);
                    if self.attempts > cfg.health.max_reacquire {
                        return Err(Stop::Trip(Fault::ObserverLost, est.omega_e_rad_s));
                    }
                    self.enter_open_loop_from_closed(cfg, est, true, reseed);
                    Ok(Some(observer_frame(est)))
                }
            };
        }
        let k = &self.k;
        let closed = matches!(self.phase, Phase::ClosedLoop(_));
        self.speed.step(
            cfg,
            k,
            &self.cmd,
            closed,
            est.omega_e_rad_s * k.inv_pole_pairs,
        );
        match &mut self.phase {
            Phase::Handover(b) => {
                b.timer = b.timer.saturating_add(1);
                if b.timer >= k.blend_ticks {
                    let i_d0 = b.i_d0;
                    self.phase = Phase::ClosedLoop(Closed { cl_ticks: 0, i_d0 });
                    self.state = State::ClosedLoop;
                }
            }
            Phase::ClosedLoop(c) => {
                c.cl_ticks = c.cl_ticks.saturating_add(1);
                if c.cl_ticks >= k.acquire_ticks {
                    self.attempts = 0;
                }
            }
            _ => {}
        }
        if (self.speed.reference_mech * self.k.pole_pairs).abs() < self.k.exit_speed
            && !self.through_zero(cfg)
        {
            self.enter_open_loop_from_closed(cfg, est, false, reseed);
            return Ok(Some(observer_frame(est)));
        }
        Ok(None)
    }

    /// Back to I/f from the observer's frame: the current vector whose q component equals
    /// the last `i_q` reference, of magnitude `I_f` or, when that torque or the speed loop's
    /// integrator (the load's torque current) needs more, `/ 0.95` (at most the current
    /// limit), at the observer's speed (or, when `fall_back`, at the commanded speed with the
    /// observer re-seeded at the new vector). Rare: out of line.
    #[inline(never)]
    fn enter_open_loop_from_closed(
        &mut self,
        cfg: &FocConfig,
        est: &Estimate<f32>,
        fall_back: bool,
        reseed: &mut impl FnMut(Seed),
    ) {
        let sp = &mut self.speed;
        let load = max2(sp.i_q_ref.abs(), sp.pi.integrator().abs());
        let needed = min2(load / 0.95, cfg.current_limit_a);
        let amp = max2(needed, cfg.startup.if_current_a);
        let iq = limit(sp.i_q_ref, -0.95 * amp, 0.95 * amp);
        let id = sqrt(amp * amp - iq * iq);
        let gamma = wrap(est.theta_rad + atan2(iq, id));
        let omega_ol = if fall_back {
            sp.reference_mech * self.k.pole_pairs
        } else {
            est.omega_e_rad_s
        };
        sp.saturated = false;
        self.phase = Phase::OpenLoop(Ramp {
            gamma,
            omega_ol,
            amp,
            ol_dir: sign(omega_ol),
            ..Ramp::default()
        });
        self.state = State::OpenLoop;
        if fall_back {
            reseed_observer(&mut self.health, gamma, omega_ol, FRAC_PI_4, reseed);
        } else {
            self.health.reset(est.omega_e_rad_s);
        }
    }
}
