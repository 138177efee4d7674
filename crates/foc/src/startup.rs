//! The state machine: start-up from standstill, hand-over to the observer, closed loop,
//! reversal, stop, fall-back.
//!
//! ```text
//!            start()                 align_time          |w_ol| = w_h, observer ready
//!   Idle ───────────────> Align ─────────────> OpenLoop ───────────────────────────> Handover
//!    ^  (sensored: ─> ClosedLoop)                 ^  │                                  │ blend_time
//!    │                                            │  │ stop() and w_ol = 0               v
//!    └────────────────────────────────────────────┼──┘           |w_ref| < w_exit   ClosedLoop
//!                                                 └─────────────────────────────────────┘
//!                                                       or observer lost (fall back)
//!   any state ──fault──> Fault ──clear_fault()──> Idle
//! ```
//!
//! # Align (optional)
//!
//! A current vector of `align_current_a` on the d axis of `align_angle_rad` (rising linearly
//! over the first half of `align_time_s`) pulls the rotor's d axis onto that angle. A rotor
//! exactly at the opposite angle feels no torque (the dead point of any single-vector
//! alignment); the I/f ramp then starts it anyway, with a jerk.
//!
//! # Open loop: current-controlled ramp (I/f)
//!
//! The current loops run in the frame of the **current vector** itself: angle `gamma`, speed
//! `w_ol`, references `(i_d, i_q) = (if_current_a, 0)`, no back-EMF feed-forward. `w_ol`
//! moves toward the target clamped to `+-handover_speed` at `accel_rad_s2`; `gamma`
//! integrates it. The rotor follows because the torque `k_t I_f sin(gamma - th)` grows when it
//! falls behind: its load angle `gamma - th` settles where the torque equals load plus
//! inertial torque, always within +-90 deg (a stable pendulum). The ramp starts with `gamma`
//! at the alignment angle, so the current vector is continuous from alignment. Zero speed is
//! no special case: a reversal simply ramps `w_ol` through zero; at the crossing the
//! observer is re-seeded at `(gamma, w_ol)` (angle sigma 45 deg), because its angle drifts
//! where the back-EMF vanishes.
//!
//! # Hand-over without a torque jump
//!
//! When the ramp is at the hand-over speed and the health monitor reports the observer
//! ready for `lock_time_s` (tracking, consistent, NIS low, same speed as the ramp within
//! `speed_tolerance`, within 90 deg of the current vector), the current loops switch to the
//! observer's frame **with the same current vector**: the I/f reference `(I_f, 0)` at `gamma`
//! seen from the observer's frame is `(I_f cos(gamma - th), I_f sin(gamma - th))`. Its q part
//! (the torque) becomes the initial output of the speed loop (integrator preset, bumpless)
//! and its d part, which makes no torque on a surface PMSM, is faded linearly to zero over
//! `blend_time_s`. The PI integrators are carried over to the new frame so the voltage is
//! continuous, and the speed reference starts at the ramp speed. This is angle blending of
//! the current vector: it turns from the ramp's angle to `th + 90 deg` while its torque
//! component stays put.
//!
//! # Closed loop, reversal, stop
//!
//! The speed loop (every `speed_divider` ticks) follows the command slewed at
//! `speed_slew_rad_s2` (at `accel_rad_s2` while the reference is below the hand-over speed). Below `exit_speed_ratio * handover_speed` (default 0.7, hysteresis to the
//! hand-over) the observer is no longer trusted, so the controller goes back to I/f: the new
//! current vector of magnitude `I_f` is placed so that its torque component equals the last
//! `i_q` reference (no torque jump), at the observer's speed. A reversal therefore runs
//! closed loop -> I/f through zero -> hand-over in the new direction -> closed loop; a stop
//! runs down the same way and turns the PWM off at zero ramp speed.
//!
//! # Observer loss
//!
//! In `Handover`/`ClosedLoop` a loss reported by [`health`](crate::health) either trips
//! [`Fault::ObserverLost`] ([`ObserverLossPolicy::Trip`]) or falls back to I/f at the commanded
//! speed with the observer re-seeded at the new current vector, then hands over again once
//! it locks ([`ObserverLossPolicy::FallBackAndReacquire`], default). Under I/f a theta+pi lock
//! re-seeds the observer; so does a hand-over that does not happen within
//! `acquire_timeout_s` at speed (or [`Fault::Stall`] if the observer sees the rotor not
//! turning). More than `max_reacquire` re-acquisitions without `acquire_timeout_s` of closed
//! loop in between trip [`Fault::ObserverLost`].

use core::f32::consts::{FRAC_PI_4, PI};

use ekf_core::Estimate;

use crate::config::{Mode, ObserverLossPolicy};
use crate::controller::{Foc, Plan, RotorSensor};
use crate::fault::Fault;
use crate::health::Reference;
use crate::pi::limit;
use crate::transforms::Dq;
use crate::trig::{atan2, min2, sin_cos, sqrt, wrap};

/// Controller state.
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq, Hash)]
pub enum State {
    /// PWM off, waiting for [`Foc::start`].
    #[default]
    Idle,
    /// Rotor alignment (sensorless start).
    Align,
    /// Open-loop current-controlled ramp (I/f).
    OpenLoop,
    /// Observer frame, d current of the ramp fading out.
    Handover,
    /// Speed and current loops on the observer's (or the sensor's) angle.
    ClosedLoop,
    /// A fault is latched; PWM off.
    Fault,
}

/// A control frame: angle (rad el.), speed (rad/s el.), and whether the back-EMF lies on its
/// q axis (feed-forward on).
#[derive(Clone, Copy, Debug, Default, PartialEq)]
pub(crate) struct Frame {
    pub theta: f32,
    pub omega: f32,
    pub emf: bool,
}

/// Sequencer variables.
#[derive(Clone, Copy, Debug, Default, PartialEq)]
pub(crate) struct Sequencer {
    /// Speed command, rad/s mech.
    pub target_mech: f32,
    pub stop_requested: bool,
    /// Slewed speed reference, rad/s mech.
    pub speed_ref_mech: f32,
    /// Output of the speed loop, A.
    pub i_q_ref: f32,
    /// The speed loop is at its current limit.
    pub saturated: bool,
    /// Ticks since the last speed-loop run.
    pub div: u16,
    /// I/f current-vector angle, rad el.
    pub gamma: f32,
    /// I/f speed, rad/s el.
    pub omega_ol: f32,
    /// I/f current magnitude, A.
    pub amp: f32,
    /// Sign of the last non-zero I/f speed (0 before the first).
    pub ol_dir: f32,
    /// Ticks in alignment or in the blend.
    pub timer: u32,
    /// Ticks at the hand-over speed without a hand-over.
    pub at_speed: u32,
    /// Ticks in closed loop.
    pub cl_ticks: u32,
    /// Re-acquisitions in a row.
    pub attempts: u8,
    /// d current of the ramp's vector at the hand-over, A.
    pub i_d0: f32,
    /// Stall counter of sensored mode.
    pub stall_count: u32,
    /// First tick of sensored closed loop.
    pub fresh: bool,
}

impl Sequencer {
    /// Fresh start; keeps the speed command.
    pub fn begin(&mut self) {
        *self = Self {
            target_mech: self.target_mech,
            fresh: true,
            ..Self::default()
        };
    }
}

/// `x` moved toward `target` by at most `step`.
fn slew(x: f32, target: f32, step: f32) -> f32 {
    x + limit(target - x, -step, step)
}

fn sign(x: f32) -> f32 {
    if x > 0.0 {
        1.0
    } else if x < 0.0 {
        -1.0
    } else {
        0.0
    }
}

impl Foc {
    /// Runs the state machine for this tick; the plan for the current loops, or `None` when
    /// the PWM must be off (idle or fault).
    pub(crate) fn sequence(
        &mut self,
        est: &Estimate<f32>,
        observer_ok: bool,
        sensor: Option<RotorSensor>,
    ) -> Option<Plan> {
        match self.cfg.mode {
            Mode::Sensored => self.sequence_sensored(sensor),
            Mode::Sensorless => self.sequence_sensorless(est, observer_ok),
        }
    }

    fn target_e(&self) -> f32 {
        if self.seq.stop_requested {
            0.0
        } else {
            self.seq.target_mech * self.pole_pairs
        }
    }

    fn observer_frame(est: &Estimate<f32>) -> Frame {
        Frame {
            theta: est.theta_rad,
            omega: est.omega_e_rad_s,
            emf: true,
        }
    }

    fn sequence_sensorless(&mut self, est: &Estimate<f32>, ok: bool) -> Option<Plan> {
        let reference = match self.state {
            State::OpenLoop => Reference::OpenLoop {
                gamma: self.seq.gamma,
                omega: self.seq.omega_ol,
            },
            State::Handover | State::ClosedLoop => Reference::ClosedLoop {
                speed_ref: self.seq.speed_ref_mech * self.pole_pairs,
                saturated: self.seq.saturated,
            },
            _ => Reference::None,
        };
        let report = self.health.update(est, ok, reference);
        self.report = report;
        let mut reframe = None;

        match self.state {
            State::Align => {
                self.seq.timer = self.seq.timer.saturating_add(1);
                if self.seq.timer > self.align_ticks {
                    self.enter_open_loop_from_rest(FRAC_PI_4);
                }
            }
            State::OpenLoop => {
                let target = self.target_e();
                let w_ol = self.seq.omega_ol;
                let h = self.handover;
                let at_speed = target.abs() >= h && w_ol * target > 0.0 && w_ol.abs() >= h * 0.999;
                if report.lost.is_some() {
                    // Only the theta+pi lock is reported as a loss under I/f.
                    if !self.reacquire_in_open_loop() {
                        return None;
                    }
                } else if at_speed && report.ready {
                    reframe = Some(Frame {
                        theta: self.seq.gamma,
                        omega: w_ol,
                        emf: false,
                    });
                    self.enter_handover(est);
                } else if at_speed {
                    self.seq.at_speed = self.seq.at_speed.saturating_add(1);
                    if self.seq.at_speed >= self.acquire_ticks {
                        self.seq.at_speed = 0;
                        // The averaged estimate: a noisy sample must not decide a stall.
                        let w_avg = report.omega_avg_rad_s;
                        if w_avg.abs() < 0.25 * w_ol.abs() {
                            self.trip(Fault::Stall, w_avg);
                            return None;
                        }
                        if !self.reacquire_in_open_loop() {
                            return None;
                        }
                    }
                } else {
                    self.seq.at_speed = 0;
                }
                if self.state == State::OpenLoop
                    && self.seq.stop_requested
                    && self.seq.omega_ol == 0.0
                {
                    self.go_idle();
                    return None;
                }
            }
            State::Handover | State::ClosedLoop => {
                if report.stall {
                    self.trip(Fault::Stall, est.omega_e_rad_s);
                    return None;
                }
                if report.lost.is_some() {
                    match self.cfg.health.policy {
                        ObserverLossPolicy::Trip => {
                            self.trip(Fault::ObserverLost, est.omega_e_rad_s);
                            return None;
                        }
                        ObserverLossPolicy::FallBackAndReacquire => {
                            self.seq.attempts = self.seq.attempts.saturating_add(1);
                            if self.seq.attempts > self.cfg.health.max_reacquire {
                                self.trip(Fault::ObserverLost, est.omega_e_rad_s);
                                return None;
                            }
                            reframe = Some(Self::observer_frame(est));
                            self.enter_open_loop_from_closed(est, true);
                        }
                    }
                } else {
                    self.speed_loop(est.omega_e_rad_s * self.inv_pole_pairs);
                    if self.state == State::Handover {
                        self.seq.timer = self.seq.timer.saturating_add(1);
                        if self.seq.timer >= self.blend_ticks {
                            self.state = State::ClosedLoop;
                        }
                    } else {
                        self.seq.cl_ticks = self.seq.cl_ticks.saturating_add(1);
                        if self.seq.cl_ticks >= self.acquire_ticks {
                            self.seq.attempts = 0;
                        }
                    }
                    if (self.seq.speed_ref_mech * self.pole_pairs).abs() < self.exit_speed {
                        reframe = Some(Self::observer_frame(est));
                        self.enter_open_loop_from_closed(est, false);
                    }
                }
            }
            State::Idle | State::Fault => return None,
        }

        let plan = match self.state {
            State::Align => {
                let half = (self.align_ticks / 2).max(1);
                let ramp = min2(self.seq.timer as f32 / half as f32, 1.0);
                Plan {
                    frame: Frame {
                        theta: self.cfg.startup.align_angle_rad,
                        omega: 0.0,
                        emf: false,
                    },
                    i_ref: Dq {
                        d: self.cfg.startup.align_current_a * ramp,
                        q: 0.0,
                    },
                    reframe_from: None,
                }
            }
            State::OpenLoop => {
                let frame = Frame {
                    theta: self.seq.gamma,
                    omega: self.seq.omega_ol,
                    emf: false,
                };
                self.advance_ramp();
                Plan {
                    frame,
                    i_ref: Dq {
                        d: self.seq.amp,
                        q: 0.0,
                    },
                    reframe_from: reframe,
                }
            }
            State::Handover | State::ClosedLoop => {
                let fade = if self.state == State::Handover {
                    1.0 - self.seq.timer as f32 / self.blend_ticks as f32
                } else {
                    0.0
                };
                Plan {
                    frame: Self::observer_frame(est),
                    i_ref: Dq {
                        d: self.seq.i_d0 * fade,
                        q: self.seq.i_q_ref,
                    },
                    reframe_from: reframe,
                }
            }
            State::Idle | State::Fault => return None,
        };
        Some(plan)
    }

    fn sequence_sensored(&mut self, sensor: Option<RotorSensor>) -> Option<Plan> {
        let Some(s) = sensor else {
            self.trip(Fault::NonFiniteInput, f32::NAN);
            return None;
        };
        let theta = wrap(s.theta_e_rad);
        let w = s.omega_e_rad_s;
        if self.seq.fresh {
            self.seq.fresh = false;
            self.seq.speed_ref_mech = w * self.inv_pole_pairs;
            self.seq.i_q_ref = 0.0;
            self.speed_pi.reset();
        }
        self.speed_loop(w * self.inv_pole_pairs);
        let slow = w.abs() < 0.1 * self.handover;
        self.seq.stall_count = if self.seq.saturated && slow {
            self.seq.stall_count.saturating_add(1)
        } else {
            0
        };
        if self.seq.stall_count >= self.stall_ticks {
            self.trip(Fault::Stall, w);
            return None;
        }
        if self.seq.stop_requested && self.seq.speed_ref_mech == 0.0 && slow {
            self.go_idle();
            return None;
        }
        Some(Plan {
            frame: Frame {
                theta,
                omega: w,
                emf: true,
            },
            i_ref: Dq {
                d: 0.0,
                q: self.seq.i_q_ref,
            },
            reframe_from: None,
        })
    }

    /// The speed loop, every `speed_divider` ticks: slews the reference toward the command
    /// and runs the PI on the measured mechanical speed; the output is the q current
    /// reference, limited to `+-current_limit_a`.
    fn speed_loop(&mut self, omega_mech: f32) {
        self.seq.div = self.seq.div.saturating_add(1);
        if self.seq.div < self.cfg.speed_divider {
            return;
        }
        self.seq.div = 0;
        let max = self.cfg.max_speed_rad_s * self.inv_pole_pairs;
        let target = if self.seq.stop_requested {
            0.0
        } else {
            limit(self.seq.target_mech, -max, max)
        };
        // Sensorless, below the hand-over speed the reference moves at the I/f acceleration,
        // so that the rotor reaches the exit speed with a torque the I/f vector continues
        // smoothly.
        let slow = (self.seq.speed_ref_mech * self.pole_pairs).abs() <= self.handover;
        let rate = if slow && self.cfg.mode == Mode::Sensorless {
            self.cfg.startup.accel_rad_s2
        } else {
            self.cfg.speed_slew_rad_s2
        };
        let step = rate * self.inv_pole_pairs * self.cfg.ts_s * f32::from(self.cfg.speed_divider);
        self.seq.speed_ref_mech = slew(self.seq.speed_ref_mech, target, step);
        let lim = self.cfg.current_limit_a;
        let iq = self
            .speed_pi
            .step(self.seq.speed_ref_mech - omega_mech, 0.0, -lim, lim);
        self.seq.i_q_ref = iq;
        self.seq.saturated = iq.abs() >= 0.999 * lim;
    }

    /// One I/f period: the current-vector angle integrates the ramp speed, which moves
    /// toward its target; re-seeds the observer when the speed crosses zero.
    fn advance_ramp(&mut self) {
        let ts = self.cfg.ts_s;
        let h = self.handover;
        let target = limit(self.target_e(), -h, h);
        self.seq.speed_ref_mech = self.seq.omega_ol * self.inv_pole_pairs;
        self.seq.gamma = wrap(self.seq.gamma + self.seq.omega_ol * ts);
        let w = slew(
            self.seq.omega_ol,
            target,
            self.cfg.startup.accel_rad_s2 * ts,
        );
        if w != 0.0 {
            let dir = sign(w);
            if self.seq.ol_dir != 0.0 && dir != self.seq.ol_dir {
                self.reseed_observer(self.seq.gamma, w, FRAC_PI_4);
                self.seq.at_speed = 0;
            }
            self.seq.ol_dir = dir;
        }
        self.seq.omega_ol = w;
    }

    /// I/f from standstill at the alignment angle; the observer seeded there with angle
    /// standard deviation `sigma_theta`.
    pub(crate) fn enter_open_loop_from_rest(&mut self, sigma_theta: f32) {
        let angle = wrap(self.cfg.startup.align_angle_rad);
        self.seq.gamma = angle;
        self.seq.omega_ol = 0.0;
        self.seq.ol_dir = 0.0;
        self.seq.amp = self.cfg.startup.if_current_a;
        self.seq.at_speed = 0;
        self.reseed_observer(angle, 0.0, sigma_theta.min(PI));
        self.state = State::OpenLoop;
    }

    /// Back to I/f from the observer's frame: the current vector of magnitude `I_f` whose q
    /// component equals the last `i_q` reference, at the observer's speed (or, when
    /// `reseed`, at the commanded speed with the observer re-seeded at the new vector).
    fn enter_open_loop_from_closed(&mut self, est: &Estimate<f32>, reseed: bool) {
        let amp = self.cfg.startup.if_current_a;
        let iq = limit(self.seq.i_q_ref, -0.95 * amp, 0.95 * amp);
        let id = sqrt(amp * amp - iq * iq);
        self.seq.gamma = wrap(est.theta_rad + atan2(iq, id));
        self.seq.omega_ol = if reseed {
            self.seq.speed_ref_mech * self.pole_pairs
        } else {
            est.omega_e_rad_s
        };
        self.seq.ol_dir = sign(self.seq.omega_ol);
        self.seq.amp = amp;
        self.seq.at_speed = 0;
        self.seq.saturated = false;
        if reseed {
            self.reseed_observer(self.seq.gamma, self.seq.omega_ol, FRAC_PI_4);
        } else {
            self.health.reset(est.omega_e_rad_s);
        }
        self.state = State::OpenLoop;
    }

    /// A re-acquisition under I/f: the observer re-seeded at the current vector; `false`
    /// (and [`Fault::ObserverLost`] tripped) when the attempts are used up.
    fn reacquire_in_open_loop(&mut self) -> bool {
        self.seq.attempts = self.seq.attempts.saturating_add(1);
        if self.seq.attempts > self.cfg.health.max_reacquire {
            self.trip(Fault::ObserverLost, self.observer.estimate().omega_e_rad_s);
            return false;
        }
        self.reseed_observer(self.seq.gamma, self.seq.omega_ol, FRAC_PI_4);
        self.seq.at_speed = 0;
        true
    }

    /// I/f -> observer frame with the same current vector (module docs).
    fn enter_handover(&mut self, est: &Estimate<f32>) {
        let (s, c) = sin_cos(wrap(self.seq.gamma - est.theta_rad));
        let i0 = Dq {
            d: self.seq.amp,
            q: 0.0,
        }
        .rotate(s, c);
        let lim = self.cfg.current_limit_a;
        let iq0 = limit(i0.q, -lim, lim);
        self.seq.i_d0 = i0.d;
        self.seq.i_q_ref = iq0;
        self.seq.timer = 0;
        self.seq.div = 0;
        self.seq.cl_ticks = 0;
        self.seq.saturated = false;
        self.seq.speed_ref_mech = self.seq.omega_ol * self.inv_pole_pairs;
        let err = self.seq.speed_ref_mech - est.omega_e_rad_s * self.inv_pole_pairs;
        self.speed_pi.preset_output(iq0, err, 0.0);
        self.state = State::Handover;
    }
}
