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
//! Each state is a type that carries its own variables, in a file of its own, with its own
//! step function; `Sequencer`'s dispatcher runs the health monitor, calls the step of the
//! state it is in and builds the tick's plan from the state it ends in:
//!
//! | state ([`State`]) | type | file | what it does |
//! |---|---|---|---|
//! | `Align` | `Align` (with a `Coast` while coasting) | `align.rs`, `coast.rs` | kick, coast, launch: learn the rotor's angle from a small motion |
//! | `OpenLoop` | `Ramp` | `ramp.rs` | damped current-controlled ramp (I/f), re-acquisition, stop |
//! | `Handover` | `Blend` | `handover.rs` | observer frame, the ramp's d current faded out |
//! | `ClosedLoop` | `Closed` | `closed.rs` | speed loop on the observer, exit to I/f, fall-back |
//! | `ClosedLoop` (sensored) | `Sensored` | `sensored.rs` | speed loop on the sensor, stall check |
//!
//! What outlives a state sits beside the state in the sequencer: the command (speed target,
//! stop request), the speed loop (reference, output, counters, PI) and the count of
//! re-acquisitions in a row. Measured results of the method (start-up grids, the rules'
//! alternatives) and the commands that reproduce them: `docs/startup.md`.
//!
//! # Alignment: kick, coast, launch (module `align`, `coast`)
//!
//! The rotor stands at an unknown angle `th0`. A current vector on the d axis of
//! `align_angle_rad` pulls it with the torque `k_t I sin(gamma - th)`, toward the vector: an
//! undamped pendulum that swings through the vector and back. So the alignment does not wait
//! for the rotor to settle: it makes the rotor move a little, slowly, and learns its angle
//! from that motion.
//!
//! 1. **Kick.** The current rises at most at `r = w_k / (2 c d^2)` per second, with
//!    `w_k = kick_speed_ratio * handover_speed` the speed taken as motion,
//!    `c = 1.5 p^2 psi_f / J` the acceleration per ampere and `d` (`KICK_DELAY_S`, 6 ms)
//!    the detection's delay: from rest the speed grows as `c r t^2 / 2`, seen `d` late it has
//!    gained `c r t d`, which this `r` keeps below `w_k`. Motion is any of:
//!    - the observer's speed, low-pass filtered (1 ms; 4 ms and its `Tracking` status on an
//!      interior motor), above `w_k` for `MOVING_TICKS` ticks; on a surface motor the
//!      threshold is at least `KICK_NOISE_K` times the RMS of that speed over the kick's
//!      first 10 ms (rotor at rest, current small);
//!    - (surface motors) the flux `x = int(u - R i) dt - L i` along the kick vector (`i` the
//!      kick's current reference, from the moment it is `KICK_FIT_BAND` times the
//!      dead-time compensation's linear band, after `KICK_FIT_MIN_S`): (a) its slope
//!      (two cascaded 1.5 ms low-pass filters) over `psi_f` at least `w_k`; (b) the matched
//!      fit `x = c + A P(t)` per axis (`Q` the integral of the kick current, `P` that of
//!      `Q`: a rotor at rest under a fixed vector turns as `P`) whose speed
//!      `|A| Q / psi_f` is at least `w_k` with `|A|^2` at least `KICK_FIT_CHI2` times its
//!      variance. The fit reads the slow start of a rotor, the slope a rotor falling off the
//!      dead point late and fast. After a false alarm (a timed-out coast) the rotor may be
//!      crawling, and both flux detectors stay off until the next step.
//! 2. **Coast.** The current is cut to a small vector (at most `COAST_INJECTION` of the
//!    alignment current, and small enough that its torque swings the speed by at most
//!    `COAST_RIPPLE` of `w_k`) turning `COAST_INJECTION_TURNS` times per
//!    `EMF_BLOCK_S` block: no net torque, and its voltage (resistive, inductive, dead
//!    time) averages out of each block, so the block mean of the loops' voltage is the
//!    back-EMF `e = w psi_f j e^(j th)`. After `COAST_SETTLE_S` the sign of
//!    `e_first x e_last` gives the direction of rotation (the observer alone cannot tell
//!    `(th, w)` from `(th + pi, -w)` at this speed). The coast ends once the back-EMF has
//!    turned `COAST_TURN_RAD` from its first block (both blocks at least the back-EMF of
//!    `w_k / 2`) and, on a surface motor, the speed of that turn and the mean speed of the
//!    two blocks' magnitudes agree within `COAST_SPEED_AGREEMENT` (noise turns the block
//!    means of a slow rotor far faster than the rotor turns). No such turn within
//!    `COAST_S` is a false alarm: the kick resumes. A back-EMF falling from at least half
//!    that of `w_k` to below a quarter of it is a rotor that stopped (friction): the kick
//!    resumes at once with the flux detectors on, `w_k` `KICK_BOOST` times larger (at
//!    most `KICK_BOOST_MAX` times), and the next coast ends on `COAST_TURN_STOPPED_RAD`.
//! 3. **Launch.** From the last block: the rotor's d axis 90 deg behind `e_last` in the
//!    direction of rotation (advanced by half a block and the voltage's one-tick delay),
//!    its speed `|e_last| / psi_f`; the observer is re-seeded there (sigma
//!    `LAUNCH_SIGMA`). I/f starts with `gamma = th + 0.5 rad` (`LAUNCH_LEAD_RAD`)
//!    toward the commanded direction, the ramp at the rotor's speed when it turns the
//!    commanded way and at zero otherwise (a backward-turning rotor is braked at once; the
//!    ramp's first sign change then does not re-seed the observer).
//!
//! **Interior motors** (`Ld != Lq`) use a simpler form of these steps, on which they were
//! measured to start: no coast current, the coast ends once the observer's integrated speed
//! has turned 0.5 rad (false alarm after `SALIENT_COAST_S`), and the launch starts from
//! the observer's estimate (moved to the other branch when it lies more than 90 deg from
//! the back-EMF's angle), with a 1 rad lead and the ramp at its speed.
//!
//! A rotor that does not move within `align_time_s` sits on the vector or at its dead point
//! (180 deg away, no torque); a second step at `align_angle + 90 deg` moves either one, and
//! if even that moves nothing the ramp starts from standstill at the vector's angle (the
//! observer seeded there, sigma 45 deg). With `kick_speed_ratio = 0` the alignment is the
//! classic one: the vector held for `align_time_s` (current rising over the first half),
//! then the ramp from that angle.
//!
//! # Open loop: damped current-controlled ramp, I/f (module `ramp`)
//!
//! The current loops run in the frame of the **current vector**: angle `gamma`, speed
//! `w_ol`, references `(i_d, i_q) = (if_current_a, 0)`, no back-EMF feed-forward. `w_ol`
//! moves toward the target clamped to `+-handover_speed` at `accel_rad_s2`. The rotor
//! follows because the torque `k_t I_f sin(gamma - th)` grows when it falls behind; its
//! load angle `delta = gamma - th` is a pendulum, `J/p d2(delta)/dt2 = -k_t I_f cos(delta0)
//! delta`, with `w_n^2 = 1.5 p^2 psi_f I_f cos(delta0) / J`.
//!
//! **Damping.** The vector is turned by an offset proportional to the speed error the
//! observer sees, `gamma = gamma_ramp + phi`, `phi = -K (w_hat - w_ol)`, `|phi| <= 90 deg`.
//! Linearized, `phi` adds the torque `-k_t I_f K (w - w_ol)`: `s^2 + w_n^2 K s + w_n^2 = 0`,
//! so `K = 2 zeta / w_n` gives the damping ratio `zeta = damping_ratio` (1: critically
//! damped; 0: undamped). It acts during the start from standstill, until the first
//! hand-over; the I/f of a reversal or a fall-back is undamped.
//!
//! Zero speed is no special case: a reversal ramps `w_ol` through zero, and at the crossing
//! the observer is re-seeded at `(gamma, w_ol)` (angle sigma 45 deg), because its angle
//! drifts where the back-EMF vanishes.
//!
//! # Hand-over without a torque jump (module `handover`)
//!
//! When the ramp is at the hand-over speed and the health monitor reports the observer
//! ready for `lock_time_s`, the current loops switch to the observer's frame **with the
//! same current vector**: `(I_f, 0)` at `gamma` seen from the observer's frame is
//! `(I_f cos(gamma - th), I_f sin(gamma - th))`. Its torque (q part, or the torque of the
//! vector on an interior motor) presets the speed loop's output (bumpless), its d part is
//! faded linearly to zero over `blend_time_s`; the PI integrators are carried over to the
//! new frame (continuous voltage) and the speed reference starts at the ramp speed.
//!
//! # Closed loop, reversal, stop (module `closed`)
//!
//! The speed loop (every `speed_divider` ticks) follows the command slewed at
//! `speed_slew_rad_s2` (at `accel_rad_s2` while the reference is below the hand-over speed,
//! except in a closed-loop reversal). Below `exit_speed_ratio * handover_speed` the
//! controller goes back to I/f with a vector whose torque component equals the last `i_q`
//! reference (longer than `I_f` when that torque, or the speed loop's integrator, the
//! load's torque current, needs it: `|i| = max(I_f, min(max(|i_q|, |integrator|) / 0.95,
//! current_limit))`), at the observer's speed. A stop runs down that way and turns the PWM
//! off at zero ramp speed.
//!
//! A **reversal** depends on `startup.reversal`:
//!
//! - [`Reversal::ClosedLoop`] (default): the drive stays on the observer through zero as
//!   long as the reference keeps moving through the exit band (or the command lies outside
//!   it); a reference standing still inside the band for [`BAND_DWELL_S`] (a slow or zero
//!   command) and a stop leave closed loop as above. The EKF's model carries the angle over
//!   the few milliseconds of a pass; the health monitor's wrong-direction check is
//!   suspended inside the exit band.
//! - [`Reversal::OpenLoop`]: closed loop -> I/f through zero -> hand-over in the new
//!   direction -> closed loop.
//!
//! # Observer loss
//!
//! In `Handover`/`ClosedLoop` a loss reported by [`health`](crate::health) either trips
//! [`Fault::ObserverLost`] ([`ObserverLossPolicy::Trip`]) or falls back to I/f at the
//! commanded speed with the observer re-seeded at the new current vector, then hands over
//! again once it locks ([`ObserverLossPolicy::FallBackAndReacquire`], default). Under I/f
//! a theta+pi lock re-seeds the observer; so does a hand-over that does not happen within
//! `acquire_timeout_s` at speed (or [`Fault::Stall`] if the observer's averaged speed is
//! below a quarter of the ramp's). More than `max_reacquire` re-acquisitions without
//! `acquire_timeout_s` of closed loop in between trip [`Fault::ObserverLost`].
//!
//! # Interface and cost
//!
//! The sequencer owns the state, the speed loop and the [`health`](crate::health) monitor,
//! and nothing else: it never touches the observer, the current loops or the bridge. Each
//! tick the controller passes it `Inputs` (the observer's estimate and whether its step
//! succeeded, the sensor reading, the voltage of the observer's step, which the coast reads
//! as back-EMF) and gets back a `Plan` (control frame and current references, and the frame
//! the loops leave when it changes) or a `Stop` (idle, or a fault to latch); re-seeds of the
//! observer go through a callback. The step is inlined into the tick (a decision returned
//! through memory costs about 80 instructions per tick on the Cortex-M4F).
//!
//! The damping costs a multiply-add and a clamp per I/f tick; the kick and the coast add a
//! filter, sums and the injected vector's turn per alignment tick (the flux detectors:
//! about 30 multiply-adds, a square root and three divisions), and an `atan2` per coast
//! block.

mod align;
mod closed;
mod coast;
mod handover;
mod ramp;
mod sensored;

use core::f32::consts::{FRAC_PI_2, PI};

use ekf_core::Estimate;

#[cfg(doc)]
use crate::config::ObserverLossPolicy;
use crate::config::{FocConfig, Mode, Reversal};
#[cfg(doc)]
use crate::fault::Fault;
use crate::health::{HealthMonitor, HealthReport, Reference, ticks};
use crate::pi::{Pi, limit};
use crate::transforms::Dq;
use crate::trig::{min2, sin_cos, sqrt, wrap};

pub use crate::state::State;

use align::Align;
use closed::{Closed, SpeedLoop};
use handover::Blend;
use ramp::Ramp;
use sensored::Sensored;

/// Time constant of the filtered observer speed that detects the kick, s.
const KICK_TAU_S: f32 = 0.001;
/// The detection's delay behind a starting rotor (the observer's lag and the filter), s: the
/// kick's current rise is sized for it.
const KICK_DELAY_S: f32 = 0.006;
/// Ticks in a row the filtered speed must exceed the kick speed.
const MOVING_TICKS: u16 = 5;
/// Kick (surface motors): the chi-square of the fitted flux path against its noise that
/// shows motion (2 degrees of freedom).
const KICK_FIT_CHI2: f32 = 64.0;
/// Kick (surface motors): the time constant of the flux's two low-pass filters, s.
const KICK_SLOPE_TAU_S: f32 = 0.0015;
/// Kick (surface motors): the fit starts once the kick current is this many times the
/// dead-time compensation's linear band.
const KICK_FIT_BAND: f32 = 1.5;
/// Kick (surface motors): samples of the fit before it or the slope decides, s.
const KICK_FIT_MIN_S: f32 = 0.003;
/// Kick: the kick speed grows by this factor after each coast that saw the rotor stop.
const KICK_BOOST: f32 = 1.5;
/// Kick: the kick speed grows after a coast that saw the rotor stop at most this many times
/// (`1.5^5`: 7.6 times).
const KICK_BOOST_MAX: u8 = 5;
/// Kick (surface motors): the observer's filtered speed counts as motion from this many
/// times its RMS at standstill.
const KICK_NOISE_K: f32 = 1.4;
/// Longest coast; a coast that sees no turn of the rotor in this time was a false alarm, s.
const COAST_S: f32 = 0.3;
/// Longest coast of an interior motor, s.
const SALIENT_COAST_S: f32 = 0.15;
/// The coast ends once the back-EMF has turned this much from its first block, rad el.
const COAST_TURN_RAD: f32 = 0.5;
/// The same after a coast that saw the rotor stop (friction; surface motors), rad el.
const COAST_TURN_STOPPED_RAD: f32 = 0.2;
/// The first part of the coast (the current loops settling, the observer on the moving
/// rotor) is not used for the evidence, s.
const COAST_SETTLE_S: f32 = 0.01;
/// Block over which the back-EMF is averaged during the coast, s.
const EMF_BLOCK_S: f32 = 0.005;
/// Angle standard deviation of the observer when it is re-seeded at the launch, rad.
const LAUNCH_SIGMA: f32 = 0.3;
/// Coast: largest amplitude of the injected current vector, as a fraction of the alignment
/// current.
const COAST_INJECTION: f32 = 0.15;
/// Coast: largest speed ripple of the injected current (its torque), as a fraction of the
/// kick speed.
const COAST_RIPPLE: f32 = 0.1;
/// Coast: turns of the injected current vector per back-EMF block.
const COAST_INJECTION_TURNS: f32 = 4.0;
/// Coast (surface motors): the speed the back-EMF's turn gives and the speed its magnitude
/// gives (mean of the first and last block) must agree within this factor before the coast
/// launches.
const COAST_SPEED_AGREEMENT: f32 = 2.0;
/// Lead of the launched current vector over the rotor's angle, rad el.
const LAUNCH_LEAD_RAD: f32 = 0.5;
/// Interior motors: the kick's filter time constant, s.
const SALIENT_KICK_TAU_S: f32 = 0.004;
/// Interior motors: the lead of the launch from the observer's estimate, rad el.
const SALIENT_LAUNCH_LEAD_RAD: f32 = 1.0;
/// A closed-loop reversal ([`Reversal::ClosedLoop`]) leaves closed loop once its reference
/// has stood still inside the exit band this long (a slow or zero command, not a pass), s.
pub const BAND_DWELL_S: f32 = 0.02;

/// A control frame: angle (rad el.), speed (rad/s el.), and whether the back-EMF lies on its
/// q axis (feed-forward on).
#[derive(Clone, Copy, Debug, Default, PartialEq)]
pub(crate) struct Frame {
    pub theta: f32,
    pub omega: f32,
    pub emf: bool,
}

/// How the current references and the frame are set for this tick.
#[derive(Clone, Copy, Debug, PartialEq)]
pub(crate) struct Plan {
    /// Control frame of this tick.
    pub frame: Frame,
    /// Current references in that frame, A.
    pub i_ref: Dq,
    /// The frame the current loops were in until this tick, when it changed.
    pub reframe_from: Option<Frame>,
}

/// What the sequencer needs from the controller for one tick.
#[derive(Clone, Copy, Debug)]
pub(crate) struct Inputs<'a> {
    /// The observer's estimate after this tick's step (or prediction).
    pub estimate: &'a Estimate<f32>,
    /// Whether the observer accepted this tick's step.
    pub observer_ok: bool,
    /// Rotor sensor reading, electrical angle (rad) and speed (rad/s), when supplied.
    pub sensor: Option<(f32, f32)>,
    /// The stator voltage of the observer's step (applied over the last period), V.
    pub u_ab: [f32; 2],
}

/// Why the PWM is off this tick (the sequencer's answer when there is no plan).
#[derive(Clone, Copy, Debug, PartialEq)]
pub(crate) enum Stop {
    /// Already idle or faulted: nothing to do.
    Off,
    /// The stop is complete: go to `Idle`.
    Idle,
    /// Latch this fault with the offending value.
    Trip(crate::fault::Fault, f32),
}

/// A new seed for the observer's angle and speed (its currents keep their estimate).
#[derive(Clone, Copy, Debug, PartialEq)]
pub(crate) struct Seed {
    /// Electrical angle, rad (not wrapped).
    pub theta: f32,
    /// Electrical speed, rad/s.
    pub omega: f32,
    /// Standard deviation of the angle, rad.
    pub sigma_theta: f32,
}

/// The state the sequencer is in, with that state's variables. (`u8` tag: a plain byte
/// compare per match on the Cortex-M4F.)
#[derive(Clone, Copy, Debug)]
#[repr(u8)]
enum Phase {
    /// PWM off, waiting for a start.
    Idle,
    /// Kick and coast (sensorless start).
    Align(Align),
    /// I/f ramp.
    OpenLoop(Ramp),
    /// Observer frame, the ramp's d current fading out.
    Handover(Blend),
    /// Speed loop on the observer.
    ClosedLoop(Closed),
    /// A fault is latched; PWM off.
    Fault,
    /// Speed loop on the sensor (reported as [`State::ClosedLoop`]).
    Sensored(Sensored),
}

/// The speed command (kept across states and starts).
#[derive(Clone, Copy, Debug, Default)]
struct Command {
    /// Speed command, rad/s mech.
    target_mech: f32,
    /// A controlled stop is under way.
    stop_requested: bool,
}

/// Constants derived from the configuration.
#[derive(Clone, Copy, Debug)]
struct Params {
    pole_pairs: f32,
    inv_pole_pairs: f32,
    /// Hand-over speed, rad/s el.
    handover: f32,
    /// Exit speed of closed loop, rad/s el.
    exit_speed: f32,
    align_ticks: u32,
    blend_ticks: u32,
    acquire_ticks: u32,
    stall_ticks: u32,
    /// [`BAND_DWELL_S`] in ticks.
    dwell_ticks: u32,
    /// Gain of the damping, s (rad of vector angle per rad/s el. of speed error).
    k_damp: f32,
    /// Largest damping offset, rad el.
    phi_max: f32,
    /// Speed at which the alignment sees the rotor move, rad/s el.
    kick_speed: f32,
    /// Coast after the rotor was seen moving, ticks (at most).
    coast_ticks: u32,
    /// Coast ticks before the branch evidence is gathered.
    coast_settle_ticks: u32,
    /// Ticks per block of the back-EMF averages of the coast.
    block_ticks: u32,
    /// Weight of the new sample in the filtered speed of the alignment.
    kick_filter: f32,
    /// An interior motor: the simpler kick, coast and launch (module docs).
    salient: bool,
    /// Rise of the alignment current per tick, A.
    align_step: f32,
    /// Turn of the coast's injected current per tick (sine, cosine).
    inj_step: [f32; 2],
    /// Amplitude of the coast's injected current, A.
    inj_amp: f32,
    /// `1 / psi_f`, 1/Wb.
    inv_psi: f32,
    /// Coast: the back-EMF of half the kick speed, V.
    e_min: f32,
    /// Kick: samples of the flux before its detectors decide.
    kick_fit_min: f32,
    /// Kick: weight of the new sample in the flux's low-pass filters.
    slope_filter: f32,
}

/// The state machine (module docs): state, speed loop, health monitor.
#[derive(Clone, Debug)]
pub(crate) struct Sequencer {
    k: Params,
    health: HealthMonitor,
    /// The speed loop: reference, output, counters and PI.
    speed: SpeedLoop,
    cmd: Command,
    /// Re-acquisitions in a row.
    attempts: u8,
    report: HealthReport,
    phase: Phase,
    /// `phase` as reported (set with every change of `phase`: read several times a tick).
    state: State,
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

fn observer_frame(est: &Estimate<f32>) -> Frame {
    Frame {
        theta: est.theta_rad,
        omega: est.omega_e_rad_s,
        emf: true,
    }
}

/// Has the observer re-seeded at `theta`, `omega` (angle standard deviation `sigma_theta`)
/// and resets the health history. Rare: out of line.
#[cold]
#[inline(never)]
fn reseed_observer(
    health: &mut HealthMonitor,
    theta: f32,
    omega: f32,
    sigma_theta: f32,
    reseed: &mut impl FnMut(Seed),
) {
    reseed(Seed {
        theta,
        omega,
        sigma_theta,
    });
    health.reset(omega);
}

/// [`Sequencer::through_zero`] from its parts (`still`: ticks the speed reference has not
/// moved).
#[inline(always)]
fn through_zero(cfg: &FocConfig, k: &Params, cmd: &Command, still: u32) -> bool {
    cfg.startup.reversal == Reversal::ClosedLoop
        && !cmd.stop_requested
        && (still < k.dwell_ticks || cmd.target_e(k).abs() >= k.exit_speed)
}

impl Command {
    /// The command as an electrical speed: zero while a stop is under way.
    fn target_e(&self, k: &Params) -> f32 {
        if self.stop_requested {
            0.0
        } else {
            self.target_mech * k.pole_pairs
        }
    }
}

impl Params {
    fn new(cfg: &FocConfig) -> Self {
        let ts = cfg.ts_s;
        let pole_pairs = cfg.motor.pole_pairs as f32;
        let handover = cfg.startup.handover_speed_rad_s;
        let exit_speed = cfg.startup.exit_speed_ratio * handover;
        let st = &cfg.startup;
        // Acceleration per ampere of a current vector 90 deg from the rotor's d axis,
        // rad/s^2 el. (`p^2 1.5 psi_f / J`), and the I/f pendulum's natural frequency.
        let accel_per_a = 1.5 * pole_pairs * pole_pairs * cfg.motor.psi_f_wb / cfg.inertia_kg_m2;
        let wn = sqrt(accel_per_a * st.if_current_a);
        let kick_speed = st.kick_speed_ratio * handover;
        let half = (ticks(st.align_time_s, ts) / 2).max(1);
        let mut align_step = st.align_current_a / half as f32;
        if kick_speed > 0.0 {
            // The rotor's speed grows as `c r t^2 / 2` under a current rising at `r`; seen
            // `d` late it has gained `c r t d` more: at most the kick speed itself.
            let d = KICK_DELAY_S;
            align_step = min2(align_step, kick_speed / (2.0 * accel_per_a * d * d) * ts);
        }
        let block_ticks = ticks(EMF_BLOCK_S, ts).max(1);
        let w_inj = 2.0 * PI * COAST_INJECTION_TURNS / (block_ticks as f32 * ts);
        let (inj_s, inj_c) = sin_cos(wrap(w_inj * ts));
        // The injected current's torque swings the speed by `c I / w_inj`.
        let salient = cfg.motor.is_salient();
        let inj_amp = if salient {
            0.0
        } else {
            min2(
                COAST_INJECTION * st.align_current_a,
                COAST_RIPPLE * kick_speed * w_inj / accel_per_a,
            )
        };
        Self {
            inj_amp,
            inj_step: [inj_s, inj_c],
            inv_psi: 1.0 / cfg.motor.psi_f_wb,
            e_min: 0.5 * kick_speed * cfg.motor.psi_f_wb,
            kick_fit_min: ticks(KICK_FIT_MIN_S, ts).max(3) as f32,
            slope_filter: min2(ts / KICK_SLOPE_TAU_S, 1.0),
            k_damp: 2.0 * st.damping_ratio / wn,
            phi_max: FRAC_PI_2,
            kick_speed,
            coast_ticks: ticks(if salient { SALIENT_COAST_S } else { COAST_S }, ts),
            coast_settle_ticks: ticks(COAST_SETTLE_S, ts),
            block_ticks,
            kick_filter: min2(
                ts / if salient {
                    SALIENT_KICK_TAU_S
                } else {
                    KICK_TAU_S
                },
                1.0,
            ),
            salient,
            align_step,
            pole_pairs,
            inv_pole_pairs: 1.0 / pole_pairs,
            handover,
            exit_speed,
            align_ticks: ticks(cfg.startup.align_time_s, ts),
            blend_ticks: ticks(cfg.startup.blend_time_s, ts),
            acquire_ticks: ticks(cfg.startup.acquire_timeout_s, ts),
            stall_ticks: ticks(cfg.health.stall_time_s, ts),
            dwell_ticks: ticks(BAND_DWELL_S, ts),
        }
    }
}

impl Sequencer {
    /// An idle sequencer for a validated configuration.
    pub fn new(cfg: &FocConfig) -> Self {
        let ts = cfg.ts_s;
        let k = Params::new(cfg);
        let speed_ts = ts * f32::from(cfg.speed_divider);
        Self {
            health: HealthMonitor::new(
                &cfg.health,
                ts,
                k.handover,
                k.exit_speed,
                cfg.motor.psi_f_wb,
            ),
            speed: SpeedLoop::new(Pi::new(cfg.speed_pi_gains(), speed_ts)),
            k,
            cmd: Command::default(),
            attempts: 0,
            report: HealthReport::default(),
            phase: Phase::Idle,
            state: State::Idle,
        }
    }

    /// Current state.
    #[inline(always)]
    pub fn state(&self) -> State {
        self.state
    }

    /// The health monitor's findings of the last tick (sensorless; default otherwise).
    pub fn report(&self) -> HealthReport {
        self.report
    }

    /// The speed command, rad/s mech.
    pub fn target_mech(&self) -> f32 {
        self.cmd.target_mech
    }

    /// The slewed speed reference, rad/s mech.
    pub fn speed_ref_mech(&self) -> f32 {
        self.speed.reference_mech
    }

    /// Sets the speed command (rad/s mech., finite), clamped to the maximum speed.
    pub fn set_target_mech(&mut self, cfg: &FocConfig, speed_mech: f32) {
        let max = cfg.max_speed_rad_s * self.k.inv_pole_pairs;
        self.cmd.target_mech = limit(speed_mech, -max, max);
    }

    /// Cancels a pending stop; from `Idle` starts the drive (sensorless: align or I/f, the
    /// observer re-seeded through `reseed` when I/f starts at once; sensored: closed loop).
    /// The controller resets the observer and its loops first.
    pub fn start(&mut self, cfg: &FocConfig, reseed: &mut impl FnMut(Seed)) {
        self.cmd.stop_requested = false;
        if !matches!(self.phase, Phase::Idle) {
            return;
        }
        self.speed.restart();
        self.health.reset(0.0);
        self.attempts = 0;
        let gamma = wrap(cfg.startup.align_angle_rad);
        (self.phase, self.state) = match cfg.mode {
            Mode::Sensored => (Phase::Sensored(Sensored::new()), State::ClosedLoop),
            Mode::Sensorless if cfg.startup.align_time_s > 0.0 => {
                (Phase::Align(Align::new(gamma)), State::Align)
            }
            Mode::Sensorless => (
                Phase::OpenLoop(Ramp::from_rest(cfg, gamma, PI, &mut self.health, reseed)),
                State::OpenLoop,
            ),
        };
    }

    /// Asks for a controlled stop (the speed reference ramps to zero).
    pub fn request_stop(&mut self) {
        self.cmd.stop_requested = true;
    }

    /// PWM off in `Idle`: a pending stop is done, the speed loop reset.
    pub fn idle(&mut self) {
        self.phase = Phase::Idle;
        self.state = State::Idle;
        self.cmd.stop_requested = false;
        self.speed.pi.reset();
    }

    /// PWM off in `Fault`, the speed loop reset.
    pub fn fault(&mut self) {
        self.phase = Phase::Fault;
        self.state = State::Fault;
        self.speed.pi.reset();
    }

    /// Runs the state machine for one tick (module docs): the plan for the current loops, or
    /// why the PWM is off. When the observer must be re-seeded it calls `reseed` (at most
    /// twice a tick; the last seed counts), before it returns.
    #[inline(always)]
    pub fn step(
        &mut self,
        cfg: &FocConfig,
        input: Inputs<'_>,
        reseed: &mut impl FnMut(Seed),
    ) -> Result<Plan, Stop> {
        match cfg.mode {
            Mode::Sensored => self.sensored(cfg, input.sensor),
            Mode::Sensorless => self.sensorless(cfg, input, reseed),
        }
    }

    /// Closed loop through the exit band ([`Reversal::ClosedLoop`], no stop requested): the
    /// reference is still moving (a reversal or a speed change passing through), or the
    /// command lies outside the band. A reference held inside the band for
    /// [`BAND_DWELL_S`] (a slow or zero command) leaves closed loop as before.
    #[inline(always)]
    fn through_zero(&self, cfg: &FocConfig) -> bool {
        through_zero(cfg, &self.k, &self.cmd, self.speed.still)
    }

    /// The sensorless dispatcher: the health monitor on this tick's estimate, the step of
    /// the state the sequencer is in (which may change the state), then the plan of the
    /// state it ends in. Inlined into the tick.
    #[inline(always)]
    fn sensorless(
        &mut self,
        cfg: &FocConfig,
        input: Inputs<'_>,
        reseed: &mut impl FnMut(Seed),
    ) -> Result<Plan, Stop> {
        let est = input.estimate;
        let reference = match &self.phase {
            Phase::OpenLoop(r) => Reference::OpenLoop {
                gamma: r.gamma,
                omega: r.omega_ol,
            },
            Phase::Handover(_) | Phase::ClosedLoop(_) => Reference::ClosedLoop {
                speed_ref: self.speed.reference_mech * self.k.pole_pairs,
                saturated: self.speed.saturated,
            },
            _ => Reference::None,
        };
        let report = self.health.update(est, input.observer_ok, reference);
        self.report = report;
        let reframe = match self.phase {
            Phase::Align(_) => self.align(cfg, input, reseed),
            Phase::OpenLoop(_) => self.open_loop(cfg, est, &report, reseed)?,
            Phase::Handover(_) | Phase::ClosedLoop(_) => {
                self.closed_loop(cfg, est, &report, reseed)?
            }
            Phase::Idle | Phase::Fault | Phase::Sensored(_) => return Err(Stop::Off),
        };
        self.plan(cfg, est, reframe, reseed)
    }

    /// The plan of the state the tick ends in (the I/f ramp advances here, after its
    /// frame is taken).
    #[inline(always)]
    fn plan(
        &mut self,
        cfg: &FocConfig,
        est: &Estimate<f32>,
        reframe_from: Option<Frame>,
        reseed: &mut impl FnMut(Seed),
    ) -> Result<Plan, Stop> {
        let plan = match &mut self.phase {
            Phase::Align(a) => Plan {
                frame: a.frame(),
                i_ref: a.current(&self.k),
                reframe_from,
            },
            Phase::OpenLoop(r) => {
                let frame = Frame {
                    theta: r.gamma,
                    omega: r.omega_ol,
                    emf: false,
                };
                let target = self.cmd.target_e(&self.k);
                r.advance(
                    cfg,
                    &self.k,
                    target,
                    &mut self.speed,
                    &mut self.health,
                    reseed,
                );
                Plan {
                    frame,
                    i_ref: Dq { d: r.amp, q: 0.0 },
                    reframe_from,
                }
            }
            Phase::Handover(b) => Plan {
                frame: observer_frame(est),
                i_ref: Dq {
                    d: b.i_d0 * (1.0 - b.timer as f32 / self.k.blend_ticks as f32),
                    q: self.speed.i_q_ref,
                },
                reframe_from,
            },
            Phase::ClosedLoop(c) => Plan {
                frame: observer_frame(est),
                i_ref: Dq {
                    d: c.i_d0 * 0.0,
                    q: self.speed.i_q_ref,
                },
                reframe_from,
            },
            Phase::Idle | Phase::Fault | Phase::Sensored(_) => return Err(Stop::Off),
        };
        Ok(plan)
    }
}
