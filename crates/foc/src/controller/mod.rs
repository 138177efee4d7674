//! The controller: one pure [`Foc::tick`] per PWM period.
//!
//! # Signal path of tick `k`
//!
//! ```text
//! inputs i[k] (abc or alpha-beta), u_dc[k], [sensor angle/speed]
//!   -> checks: non-finite / absurd, over-current, bus over/under-voltage  -> latched fault
//!   -> observer.step(u_applied over [t_k-1, t_k), i_ab[k])                 (EKF, ekf-core)
//!   -> health monitor, state machine: control frame (angle th_k, speed w), current refs
//!   -> Park(i_ab, th_k) -> dq current PIs with decoupling and back-EMF feed-forward
//!   -> inverse Park at th_k + advance * w * Ts -> SVPWM(u_dc[k]) -> d[k]
//!   -> dead-time compensation (if dead_time_s > 0): duties[k] = clamp01(d[k] + delta[k]),
//!      delta_x = sgn_s(i_x) t_dead / Ts for the currents predicted at th_k + advance * w * Ts
//!   -> realized u_ab[k] = duties_to_alpha_beta(clamp01(duties[k] - delta[k]), u_dc[k])
//!      (= the voltage of d[k] unless clamped) into a 2-deep history
//! ```
//!
//! # Timing (docs/design.md, "Conventions") and the computation delay
//!
//! The ADC samples `i[k]` at `t_k`; the duties computed by tick `k` are loaded by the PWM
//! timer at the next period boundary and applied over `[t_k+1, t_k+2)`
//! ([`ComputationDelay::OnePeriod`], the default). Therefore:
//!
//! - the voltage applied over `[t_k-1, t_k)` is the one computed by tick `k-2`: tick `k`
//!   calls `observer.step(u_hist[1], i[k])`. The history holds the **realized** voltage
//!   (rebuilt from the clamped duties and the `u_dc` measured when they were computed), zero
//!   while the PWM is off;
//! - the voltage computed at tick `k` is rotated back to alpha-beta with the angle at the
//!   middle of its application interval, `th_k + 1.5 w Ts` (`angle_advance_periods`).
//!
//! With [`ComputationDelay::None`] (a simulator that applies the duties at once, over
//! `[t_k, t_k+1)`) the observer takes `u_hist[0]` (computed by tick `k-1`) and the advance
//! is 0.5.
//!
//! # Dead time
//!
//! With [`FocConfig::dead_time_s`] set, every phase's duty gets the offset that cancels the
//! bridge's average dead-time error, `sgn_s(i_x) t_dead / Ts`, with the phase currents
//! predicted for the middle of the application interval (the current reference, or the
//! measured `i_dq` at the voltage limit, turned back with the voltage's angle). The history
//! (the observer's input) holds the voltage the bridge then realizes, the duties **minus**
//! the offsets, clamped like the bridge clamps them: the intended voltage unless the offsets
//! had to be cut at 0 or 1. Module [`crate::deadtime`] derives it against the simulator's
//! inverter model.
//!
//! # Bad current samples (ride-through)
//!
//! Every tick first checks the current sample ([`SampleCheckConfig`](crate::SampleCheckConfig)):
//!
//! - **missing**: a current is NaN or infinite (an ADC conversion that did not complete, a
//!   DMA overrun);
//! - **implausible**: the current vector moved by more than `(n + 1) max_step_a` since the
//!   last accepted sample (`n` samples missed since): an inductive load's current changes by
//!   at most about `u_dc Ts / Ls` per period, so a single wild reading (a spike of ten times
//!   the rated current on one channel) is rejected, not believed.
//!
//! Such a tick rides through: the observer only predicts (`PmsmObserver::predict` with the
//! voltage applied over the last period), the state machine runs on the predicted estimate,
//! the current PIs hold their integrators and the last dq voltage is applied again in the
//! (moving) control frame; the telemetry shows the observer's predicted currents and
//! `sample_ok = false`. `missing_trip_ticks` bad samples in a row trip (non-finite:
//! [`Fault::NonFiniteInput`]; above `over_current_a`: [`Fault::OverCurrent`]; else
//! `NonFiniteInput`, an absurd value).
//!
//! A **stuck channel** (phase `a` or `b` of [`PhaseCurrents::Abc`] repeating its reading bit
//! for bit while the commanded current vector, at least 5 % of the current limit, turns by
//! `samples.stuck_angle_rad`, an eighth of a period by default) trips [`Fault::CurrentSensor`]:
//! a live channel's sinusoid moves by 7.6 % of its amplitude over an eighth period. Found by
//! two comparisons per tick. Without it a frozen reading goes unnoticed by the other checks
//! (it is plausible and finite) while the loops, chasing a current they cannot move, drive
//! the real one far past the over-current level before anything trips.
//!
//! The software over-current check runs on accepted samples only and is debounced: it trips
//! after `over_current_trip_ticks` samples in a row above `over_current_a` (default 2). A
//! single sample never trips it. This is a back-up: the bridge's hardware comparator, which
//! acts within microseconds, is the real over-current protection. A real short circuit moves
//! the current at most at the physical rate, so its samples are accepted and trip it.
//!
//! # Current loops
//!
//! ```text
//! e   = i_dq_ref - i_dq
//! u_d = PI_d(e_d) - w Lq i_q                      (cross-coupling decoupling, measured i)
//! u_q = PI_q(e_q) + w Ld i_d + w psi_f            (decoupling, back-EMF feed-forward with the
//!                                                  observer's tracked psi_f)
//! |u_dq| <= max_modulation * u_dc / sqrt(3), d axis first, q gets the rest
//! ```
//!
//! PI gains per axis: `Kp = Ld bw` on d, `Lq bw` on q (pole-zero cancellation of each
//! axis; one and the same on a surface motor).
//!
//! # Current references in closed loop
//!
//! The speed loop's output is a torque command, `i_T = T* / k_t` (module [`crate::mtpa`]).
//! A surface motor without field weakening takes it as the q reference unchanged (the plan's
//! references go to the loops as they are).
//! Otherwise (`shaped_refs`): `i_d = i_d,plan + i_d,mtpa + i_fw` (`i_d,mtpa`: one step of
//! the MTPA iteration for `i_T` from the last tick's MTPA point), limited to
//! `[-max_negative_id, current_limit_a]`; `i_q = psi_f i_T / (psi_f + (Ld - Lq) i_d)`;
//! `|i_q| <= sqrt(current_limit_a^2 - i_d^2)` (the current circle, q cut first). Before
//! that the field-weakening integrator (module [`crate::fieldweak`]) updates `i_fw` from the
//! loops' steady-state voltage (their integrators, as the last tick left them, plus this
//! tick's feed-forward). Under align and I/f the plan's references are used and `i_fw` is
//! reset. The surface path without field weakening costs one flag test.
//!
//! Told a saturating motor's flux map (`FocConfig::flux_map`, cargo feature `flux-map`),
//! the closed-loop references come from its MTPA table (or, with field weakening on, its
//! field-weakening table at the flux limit `(k u_max - Rs |i|) / |w|`), the current PIs'
//! `Kp` from its incremental inductances and the decoupling and back-EMF feed-forward from
//! its fluxes (module `mapdrive`). Built without the feature, the tick is the one above.
//!
//! `w` is the speed of the control frame: the observer's (or sensor's) speed in closed
//! loop, the ramp speed under I/f, where the back-EMF feed-forward is off (the rotor angle
//! is not the frame angle). PI gains: [`FocConfig::current_pi_gains`]; anti-windup:
//! [`crate::pi`]. When the control frame changes (hand-over, fall-back) the integrators are
//! re-expressed in the new frame so that the voltage vector is continuous.
//!
//! # Low speed by HFI (salient motors, [`Foc::enable_hfi`])
//!
//! Off unless enabled (then only in sensorless mode on a motor with `Lq / Ld >= 1.1`); off,
//! the tick is the one described above, bit for bit. On (module [`crate::hfi`]):
//!
//! - **start** from standstill: the carrier on, no current while the tracking loop settles on
//!   the salient axis, then the magnet polarity test (two d-axis pulses); the state reads
//!   [`State::Align`] meanwhile. Then closed loop at once (no I/f ramp);
//! - **closed loop**: the sequencer runs its sensored path (speed loop, stop, stall check) on
//!   a virtual sensor: the HFI angle and speed blended with the observer's, the observer's
//!   weight rising linearly with HFI's speed from `blend_low_rad_s` to `blend_high_rad_s`
//!   (with a long carrier period, the faster of HFI's and the observer's low-passed speed:
//!   [`crate::hfi`], "Hand-over band").
//!   Above `blend_high` the carrier is off and the angle is the observer's alone; it comes
//!   back on below 80 % of it, the tracker seeded from the observer (angle, speed, and the
//!   load as the drive's torque). When the observer's weight leaves zero it is re-seeded from
//!   HFI (it drifts at standstill). The observer's health monitor and its fall-back to I/f
//!   are not used in this mode;
//! - while the carrier is on, the current loops take the mean of the samples over a carrier
//!   period, their voltage limit is lowered by the carrier's amplitude, and the observer is
//!   fed the fundamental (the carrier's voltage out of its input, the carrier's predicted
//!   current out of the sample); the speed loop's torque command is fed forward to the
//!   tracking loop;
//! - while HFI has a say (carrier on, observer weight below 1) and the carrier period is short,
//!   HFI's angle is also fused into the observer after its step, as a measurement of its angle
//!   whose variance grows as the weight rises ([`crate::hfi`], "Hand-over band"); the blend
//!   takes the corrected observer angle and speed, the telemetry the step's estimate.
//!
//! # Cost
//!
//! Besides the observer step, a tick evaluates one sine/cosine pair in the common case (Park;
//! the inverse Park and the dead-time compensation turn it by the advance with a short
//! series), one division (SVPWM), no square root unless the voltage limit is active, and no
//! `f64`. Counted on the Cortex-M4F and mapped part by part: the crate README, "Cost on the
//! Cortex-M4F".

mod checks;
mod hfi_path;
mod loops;

use ekf_core::nalgebra::{Matrix4, Vector4};
use ekf_core::{Estimate, PmsmObserver};

use crate::config::{ComputationDelay, ConfigError, FocConfig, Mode};
use crate::deadtime::DeadTimeCompensation;
use crate::fault::{Fault, FaultInfo};
use crate::fieldweak::FieldWeakening;
use crate::health::HealthReport;
use crate::hfi::{HfiPhase, HfiSlot};
use crate::mtpa::Mtpa;
use crate::pi::Pi;
use crate::startup::{Inputs, Plan, Seed, Sequencer, State, Stop};
use crate::svpwm::{SAFE_DUTIES, duties_to_alpha_beta, linear_limit_v, modulate, modulate_duties};
use crate::transforms::{AlphaBeta, Dq};
use crate::trig::{add_angles, max2, min2, sin_cos, sin_cos_small, sqrt, wrap};

pub use crate::io::{PhaseCurrents, RotorSensor, Telemetry, TickInput, TickOutput};

/// The observer's input of a tick: the voltage of its step (V), the current it takes (A),
/// and with HFI on the carrier's response and the fundamental current.
type ObserverInput = (
    [f32; 2],
    AlphaBeta,
    Option<(Option<crate::hfi::Response>, AlphaBeta)>,
);

/// Why a command was refused.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum CommandError {
    /// A fault is latched; [`Foc::clear_fault`] first.
    Faulted(Fault),
    /// The argument is NaN or infinite.
    NonFinite,
    /// Only allowed while idle.
    NotIdle,
}

impl core::fmt::Display for CommandError {
    fn fmt(&self, f: &mut core::fmt::Formatter<'_>) -> core::fmt::Result {
        match self {
            CommandError::Faulted(x) => write!(f, "fault latched: {x}"),
            CommandError::NonFinite => f.write_str("argument is not finite"),
            CommandError::NotIdle => f.write_str("only allowed while idle"),
        }
    }
}

impl core::error::Error for CommandError {}

/// The controller (module docs). Build with [`Foc::new`], call [`Foc::tick`] once per PWM
/// period, command with [`start`](Foc::start), [`stop`](Foc::stop),
/// [`set_speed_ref_mech_rad_s`](Foc::set_speed_ref_mech_rad_s).
// `repr(C)`: the fields in the order written (the layout rustc picks otherwise costs the
// tick 30 instructions on the Cortex-M4F: `scripts/qemu-firmware.sh`, foc_tick 1724 vs 1694).
#[derive(Clone, Debug)]
#[repr(C)]
pub struct Foc {
    cfg: FocConfig,
    // Constants derived from the configuration.
    over_current_sq: f32,
    /// Largest plausible change of the current vector per period, A, and its square.
    max_step_a: f32,
    max_step_sq: f32,
    advance_s: f32,
    dead_time: DeadTimeCompensation,
    // Parts.
    observer: PmsmObserver<f32>,
    pi_d: Pi,
    pi_q: Pi,
    /// MTPA law and torque conversion (salient motors).
    mtpa: Mtpa,
    /// Field-weakening loop.
    fw: FieldWeakening,
    /// The closed-loop current references are shaped ([`FocConfig::shapes_references`]).
    shaping: bool,
    /// `Ld != Lq`: torque conversion with reluctance torque.
    salient: bool,
    /// Salient and `cfg.mtpa`.
    mtpa_on: bool,
    /// `cfg.field_weakening.enabled`.
    fw_on: bool,
    /// Largest negative d current, A.
    max_neg_id: f32,
    /// The q current of the last MTPA point (warm start of the MTPA iteration), A.
    iq_last: f32,
    /// The last shaped d reference without the field-weakening correction, A.
    id_base: f32,
    /// The state machine with the speed loop and the health monitor.
    seq: Sequencer,
    // State.
    fault: Option<FaultInfo>,
    tick_count: u32,
    /// Realized voltages computed by ticks k-1 and k-2.
    u_hist: [AlphaBeta; 2],
    /// The current loops' last voltage, in the last control frame (held over bad samples).
    u_dq_last: Dq,
    /// The last accepted current sample.
    i_last: AlphaBeta,
    /// Missing or implausible current samples in a row.
    missed: u16,
    /// Accepted samples above the over-current level in a row.
    over_current_count: u16,
    /// Last raw readings of phases a and b (stuck-channel check).
    raw_last: [f32; 2],
    /// Electrical angle the current vector turned while phase a / b repeated its reading, rad.
    stuck_angle: [f32; 2],
    /// Ticks phase a / b repeated its reading.
    stuck_ticks: [u16; 2],
    /// Frame speed magnitude when phase a / b began to repeat, rad/s el. (set on the first
    /// repeat; the rate the stuck check counts at least).
    stuck_omega: [f32; 2],
    /// High-frequency injection at low speed (module docs, "Low speed by HFI"); `None`: off.
    hfi: Option<HfiSlot>,
    /// The flux map's point of the last closed-loop reference (`FocConfig::flux_map`).
    #[cfg(feature = "flux-map")]
    map_point: crate::mapdrive::MapPoint,
}

/// Replaces the observer's estimate by the seed's angle (rad el.) and speed (rad/s el.) with
/// its angle standard deviation (rad); the currents keep their estimate. Rare (start-up,
/// re-acquisition): out of line.
#[cold]
#[inline(never)]
fn reseed_observer(observer: &mut PmsmObserver<f32>, cfg: &FocConfig, seed: Seed) {
    let x = observer.state();
    let si = 0.1 * cfg.motor.characteristic_current_a();
    let sw = 0.5 * cfg.startup.handover_speed_rad_s + 0.3 * seed.omega.abs();
    let x = Vector4::new(x[0], x[1], seed.omega, wrap(seed.theta));
    let p = Matrix4::from_diagonal(&Vector4::new(
        si * si,
        si * si,
        sw * sw,
        seed.sigma_theta * seed.sigma_theta,
    ));
    // Refused only for non-finite values, which these are not; nothing changes then.
    let _ = observer.reset(x, p);
}

impl Foc {
    /// Validates `cfg` and builds an idle controller.
    pub fn new(cfg: &FocConfig) -> Result<Self, ConfigError> {
        cfg.validate()?;
        // Built without the `tracking` feature the observer runs without online tracking of
        // `psi_f` and `Rs`, whatever the configuration asks.
        #[cfg(not(feature = "tracking"))]
        let cfg = &FocConfig {
            observer: ekf_core::ObserverConfig {
                parameter_tracking: None,
                ..cfg.observer
            },
            ..*cfg
        };
        let observer = PmsmObserver::new(&cfg.observer).map_err(ConfigError::Observer)?;
        let ts = cfg.ts_s;
        Ok(Self {
            cfg: *cfg,
            over_current_sq: cfg.over_current_a * cfg.over_current_a,
            // Capped so that `((n + 1) step)^2` stays finite for any count `n`: an infinite
            // step of the current vector (`d^2 = inf`) is then never accepted.
            max_step_a: min2(cfg.max_current_step(), 1.0e14),
            max_step_sq: min2(cfg.max_current_step(), 1.0e14)
                * min2(cfg.max_current_step(), 1.0e14),
            advance_s: cfg.angle_advance_periods * ts,
            dead_time: DeadTimeCompensation::new(cfg.dead_time_s, ts, cfg.dead_time_band()),
            observer,
            pi_d: Pi::new(cfg.current_pi_gains_d(), ts),
            pi_q: Pi::new(cfg.current_pi_gains(), ts),
            mtpa: Mtpa::new(&cfg.motor),
            fw: FieldWeakening::new(
                cfg.field_weakening.voltage_margin,
                cfg.field_weakening.bandwidth_rad_s,
                ts,
                cfg.motor.ld_h,
                cfg.startup.handover_speed_rad_s,
                cfg.max_negative_id(),
            ),
            // (Without the `field-weakening` feature `FocConfig::validate` refuses it.)
            shaping: cfg.shapes_references(),
            salient: cfg.motor.is_salient(),
            mtpa_on: cfg.motor.is_salient() && cfg.mtpa,
            fw_on: cfg.field_weakening.enabled,
            max_neg_id: cfg.max_negative_id(),
            iq_last: 0.0,
            id_base: 0.0,
            seq: Sequencer::new(cfg),
            fault: None,
            tick_count: 0,
            u_hist: [AlphaBeta::default(); 2],
            u_dq_last: Dq::default(),
            i_last: AlphaBeta::default(),
            missed: 0,
            over_current_count: 0,
            raw_last: [f32::NAN; 2],
            stuck_angle: [0.0; 2],
            stuck_ticks: [0; 2],
            stuck_omega: [0.0; 2],
            hfi: None,
            #[cfg(feature = "flux-map")]
            map_point: crate::mapdrive::MapPoint::ZERO,
        })
    }

    /// The configuration in use.
    pub fn config(&self) -> &FocConfig {
        &self.cfg
    }

    /// Current state (the HFI standstill test reports [`State::Align`]).
    pub fn state(&self) -> State {
        match &self.hfi {
            Some(h) if h.phase != HfiPhase::Tracking && self.seq.state() == State::ClosedLoop => {
                State::Align
            }
            _ => self.seq.state(),
        }
    }

    /// The latched fault, if any.
    pub fn fault(&self) -> Option<Fault> {
        self.fault.map(|f| f.fault)
    }

    /// The latched fault with its context, if any.
    pub fn fault_info(&self) -> Option<FaultInfo> {
        self.fault
    }

    /// The observer (runs in every driven state, in both modes).
    pub fn observer(&self) -> &PmsmObserver<f32> {
        &self.observer
    }

    /// The speed command, rad/s mech. (sign = direction), as set.
    pub fn speed_target_mech_rad_s(&self) -> f32 {
        self.seq.target_mech()
    }

    /// The health monitor's findings of the last tick (sensorless mode; default otherwise).
    pub fn health_report(&self) -> HealthReport {
        self.seq.report()
    }

    /// Calls of [`tick`](Self::tick) so far (wrapping).
    pub fn tick_count(&self) -> u32 {
        self.tick_count
    }

    /// Starts the drive from `Idle` (sensorless: align or I/f first; sensored: closed loop);
    /// while running it cancels a pending [`stop`](Self::stop). Refused while a fault is
    /// latched.
    pub fn start(&mut self) -> Result<(), CommandError> {
        if let Some(f) = self.fault {
            return Err(CommandError::Faulted(f.fault));
        }
        if self.seq.state() == State::Idle {
            self.reset_loops();
            let _ = self
                .observer
                .reset(self.cfg.observer.x0, self.cfg.observer.p0);
            if let Some(h) = self.hfi.as_mut() {
                h.restart(&self.cfg);
            }
        }
        // With HFI the sequencer runs its sensored path on the blended angle.
        let hfi = self.hfi.is_some();
        if hfi {
            self.cfg.mode = Mode::Sensored;
        }
        let (cfg, observer) = (&self.cfg, &mut self.observer);
        self.seq
            .start(cfg, &mut |seed| reseed_observer(observer, cfg, seed));
        if hfi {
            self.cfg.mode = Mode::Sensorless;
        }
        Ok(())
    }

    /// Controlled stop: the speed reference ramps to zero (closed loop down to the exit
    /// speed, then the I/f ramp down to standstill), then the PWM goes off (`Idle`). During
    /// alignment, and in sensored mode once the speed is near zero, it stops at once.
    pub fn stop(&mut self) {
        if self.seq.state() == State::Align {
            self.go_idle();
        } else {
            self.seq.request_stop();
        }
    }

    /// Immediate stop: PWM off, `Idle` (the motor coasts). Does not clear a fault.
    pub fn disable(&mut self) {
        if self.seq.state() != State::Fault {
            self.go_idle();
        }
    }

    /// Sets the speed command, rad/s mechanical; the sign is the direction. Clamped to
    /// `max_speed_rad_s / pole_pairs`. A reversal goes through zero speed (closed loop down
    /// to the exit speed, I/f through zero, hand-over in the new direction). Refused if not
    /// finite.
    pub fn set_speed_ref_mech_rad_s(&mut self, speed_mech_rad_s: f32) -> Result<(), CommandError> {
        if !speed_mech_rad_s.is_finite() {
            return Err(CommandError::NonFinite);
        }
        self.seq.set_target_mech(&self.cfg, speed_mech_rad_s);
        Ok(())
    }

    /// Clears a latched fault and returns to `Idle` (then [`start`](Self::start) again).
    /// Returns the fault that was cleared. If its cause persists it trips again at the next
    /// tick.
    pub fn clear_fault(&mut self) -> Option<FaultInfo> {
        let f = self.fault.take();
        if self.seq.state() == State::Fault {
            self.go_idle();
        }
        f
    }

    /// Changes the mode; only while idle.
    pub fn set_mode(&mut self, mode: Mode) -> Result<(), CommandError> {
        if self.seq.state() != State::Idle {
            return Err(CommandError::NotIdle);
        }
        self.cfg.mode = mode;
        Ok(())
    }

    /// One PWM period (module docs): samples of `t_k` in, duties for the next period out.
    /// Never panics; the duties are finite and in `[0, 1]` whatever the input.
    ///
    /// The signal path: measure (Clarke, the sample and bus checks), observe (the
    /// observer's input and step), sequence (the state machine's plan, or a stop), control
    /// (Park, the current loops), modulate (inverse Park, SVPWM, dead time, history). The
    /// first three are helpers; control and modulate are written out here (as helpers
    /// they cost about 20 instructions per tick on the Cortex-M4F).
    pub fn tick(&mut self, input: &TickInput) -> TickOutput {
        self.tick_count = self.tick_count.wrapping_add(1);
        // Measure.
        let (i_ab, sample_ok) = self.measure(input);
        if matches!(self.seq.state(), State::Idle | State::Fault) {
            return self.safe_output();
        }
        // Observe.
        let (u_prev, i_obs, hfi_demod) = self.observer_input(i_ab, sample_ok);
        let (est, observer_ok) = self.observe(u_prev, i_obs, sample_ok);
        // Over a bad sample the observer's predicted currents stand in for the measurement
        // (telemetry, frame changes); the current loops do not use them.
        let i_ab = if sample_ok {
            i_ab
        } else {
            AlphaBeta {
                alpha: est.i_alpha_a,
                beta: est.i_beta_a,
            }
        };
        // Sequence. Matched right where it is made (a decision passed through memory costs
        // about 80 instructions per tick on the Cortex-M4F).
        let (plan, carrier, i_loop) = if self.hfi.is_none() {
            match self.sequence(input, &est, observer_ok, u_prev) {
                Ok(plan) => (plan, None, i_ab),
                Err(stop) => return self.stopped(stop),
            }
        } else {
            let (resp, fund) = hfi_demod.unwrap_or((None, i_ab));
            match self.hfi_plan(&est, observer_ok, i_ab, resp, fund) {
                Ok(p) => p,
                Err(stop) => return self.stopped(stop),
            }
        };
        // Stuck channel: a sampled phase current that repeats bit for bit while the current
        // vector turns (module docs). The common path is two comparisons.
        if let PhaseCurrents::Abc(x) = input.currents {
            let same = [x.a == self.raw_last[0], x.b == self.raw_last[1]];
            self.raw_last = [x.a, x.b];
            if same[0] || same[1] {
                if self.stuck_channel(same, x, plan) {
                    return self.safe_output();
                }
            } else if self.stuck_ticks != [0; 2] {
                self.stuck_angle = [0.0; 2];
                self.stuck_ticks = [0; 2];
            }
        }
        // Control: the current loops in the plan's frame.
        let frame = plan.frame;
        let (s, c) = sin_cos(frame.theta);
        let i_dq = i_loop.to_dq(s, c);
        let ff = self.feed_forward(i_dq, frame);
        if let Some(old) = plan.reframe_from {
            self.reframe(old, frame, i_ab, ff);
        }
        let u_dc = input.u_dc_v;
        let mut u_max = self.cfg.max_modulation * linear_limit_v(u_dc);
        if carrier.is_some()
            && let Some(h) = &self.hfi
        {
            u_max = max2(u_max - h.cfg.injection_v, 0.0);
        }
        // Current references: the plan's, or (salient motor, field weakening) shaped by
        // MTPA, the torque conversion, field weakening and the current circle in closed loop.
        let i_ref = if self.shaping {
            self.shaped_refs(plan, ff, u_max, sample_ok)
        } else {
            plan.i_ref
        };
        // The d-axis excitation in closed loop (`FocConfig::d_excitation`).
        #[cfg(feature = "d-excitation")]
        let i_ref = match &self.cfg.d_excitation {
            Some(x) if plan.frame.emf && plan.frame.omega.abs() >= x.min_speed_rad_s => Dq {
                d: i_ref.d + x.offset_a(self.tick_count),
                q: i_ref.q,
            },
            _ => i_ref,
        };
        let (u_dq, limited) = if sample_ok {
            let e = i_ref - i_dq;
            let u_d = self.pi_d.step(e.d, ff.d, -u_max, u_max);
            let uq_free = self.pi_q.unlimited(e.q, ff.q);
            let limited = u_d * u_d + uq_free * uq_free > u_max * u_max;
            let q_max = if limited {
                sqrt(u_max * u_max - u_d * u_d)
            } else {
                u_max
            };
            let u_q = self.pi_q.step(e.q, ff.q, -q_max, q_max);
            (Dq { d: u_d, q: u_q }, limited)
        } else {
            self.held_voltage(plan.reframe_from, frame, u_max)
        };
        self.u_dq_last = u_dq;

        // Modulate: inverse Park at the middle of the application interval (the advance
        // rotates the frame's sine and cosine by a small angle), SVPWM, dead-time
        // compensation, history.
        let (sd, cd) = sin_cos_small(frame.omega * self.advance_s);
        let (s2, c2) = add_angles(s, c, sd, cd);
        let mut u_ab = u_dq.to_alpha_beta(s2, c2);
        if let Some(u_h) = carrier {
            u_ab = u_ab + u_h;
        }
        let (duties, applied) = if self.dead_time.is_active() {
            let i = if limited { i_dq } else { i_ref };
            let i_pred = i.to_alpha_beta(s2, c2).to_abc();
            let (d, _) = modulate_duties(u_ab, u_dc);
            let comp = self.dead_time.apply(d, i_pred);
            (comp.duties, duties_to_alpha_beta(comp.effective, u_dc))
        } else {
            let m = modulate(u_ab, u_dc);
            (m.duties, m.applied)
        };
        self.u_hist = [applied, self.u_hist[0]];

        // (The HFI standstill test, carrier on, reports `Align`: `state()`.)
        let state = if carrier.is_some() {
            self.state()
        } else {
            self.seq.state()
        };
        TickOutput {
            duties,
            pwm_enabled: true,
            state,
            fault: None,
            telemetry: Telemetry {
                i_dq,
                i_dq_ref: i_ref,
                u_dq,
                u_ab: applied,
                theta_rad: frame.theta,
                omega_rad_s: frame.omega,
                speed_ref_mech_rad_s: self.seq.speed_ref_mech(),
                estimate: est,
                observer_ok,
                sample_ok,
            },
        }
    }

    /// Measure: the currents in alpha-beta (Clarke), whether the sample is used (module
    /// docs, "Bad current samples"), and the bus and sensor checks (which may trip).
    #[inline(always)]
    fn measure(&mut self, input: &TickInput) -> (AlphaBeta, bool) {
        let (i_ab, c_abs) = match input.currents {
            PhaseCurrents::Abc(x) => (x.to_alpha_beta(), x.c.abs()),
            PhaseCurrents::AlphaBeta(x) => (x, 0.0),
        };
        let sample_ok = self.check_currents(input, i_ab, c_abs);
        self.protect(input);
        (i_ab, sample_ok)
    }

    /// The observer's input: the voltage applied over `[t_k-1, t_k)` (from the history, by
    /// the computation delay) and the current sample; with the HFI carrier on the
    /// fundamental only (the carrier's voltage taken out of the input, its predicted current
    /// out of the sample: module docs, "Low speed by HFI"), with the carrier's response.
    #[inline(always)]
    fn observer_input(&mut self, i_ab: AlphaBeta, sample_ok: bool) -> ObserverInput {
        let u_prev = match self.cfg.delay {
            ComputationDelay::OnePeriod => self.u_hist[1],
            ComputationDelay::None => self.u_hist[0],
        };
        let (u_prev, i_obs, hfi_demod) = match self.hfi.as_mut() {
            None => (u_prev, i_ab, None),
            Some(h) => {
                let carrier = h.tracker.applied_carrier();
                let (resp, fund) = h.demodulate(i_ab, sample_ok);
                if h.demodulated() {
                    let i_fund = i_ab - h.tracker.carrier_current();
                    (u_prev - carrier, i_fund, Some((resp, fund)))
                } else {
                    (u_prev, i_ab, Some((resp, fund)))
                }
            }
        };
        ([u_prev.alpha, u_prev.beta], i_obs, hfi_demod)
    }

    /// Observe: the observer's step on the voltage `u_prev` and the current `i_obs` (only
    /// a prediction over a bad sample); its estimate and whether it accepted the step.
    #[inline(always)]
    fn observe(
        &mut self,
        u_prev: [f32; 2],
        i_obs: AlphaBeta,
        sample_ok: bool,
    ) -> (Estimate<f32>, bool) {
        if sample_ok {
            match self.observer.step(u_prev, [i_obs.alpha, i_obs.beta]) {
                Ok(e) => (e, true),
                Err(_) => (self.observer.estimate(), false),
            }
        } else {
            let ok = self.observer.predict(u_prev).is_ok();
            (self.observer.estimate(), ok)
        }
    }

    /// Sequence: the state machine's plan for this tick (control frame, current
    /// references), or why the PWM goes off. (With HFI on: `hfi_plan`.)
    #[inline(always)]
    fn sequence(
        &mut self,
        input: &TickInput,
        est: &Estimate<f32>,
        observer_ok: bool,
        u_prev: [f32; 2],
    ) -> Result<Plan, Stop> {
        let inputs = Inputs {
            estimate: est,
            observer_ok,
            sensor: input.sensor.map(|s| (s.theta_e_rad, s.omega_e_rad_s)),
            u_ab: u_prev,
        };
        let (cfg, observer) = (&self.cfg, &mut self.observer);
        self.seq.step(cfg, inputs, &mut |seed| {
            reseed_observer(observer, cfg, seed)
        })
    }

    /// The PWM-off output for the sequencer's `stop` (idle, or a fault to latch).
    #[cold]
    #[inline(never)]
    fn stopped(&mut self, stop: Stop) -> TickOutput {
        match stop {
            Stop::Off => {}
            Stop::Idle => self.go_idle(),
            Stop::Trip(fault, value) => self.trip(fault, value),
        }
        self.safe_output()
    }

    /// Latches `fault` (if none is latched yet) and turns the PWM off.
    fn trip(&mut self, fault: Fault, value: f32) {
        if self.fault.is_none() {
            self.fault = Some(FaultInfo {
                fault,
                state: self.seq.state(),
                value,
                tick: self.tick_count,
            });
        }
        self.seq.fault();
        self.reset_loops();
    }

    /// PWM off, `Idle`.
    fn go_idle(&mut self) {
        self.seq.idle();
        self.reset_loops();
    }

    /// Current integrators and voltage history to zero (the speed loop: the sequencer).
    fn reset_loops(&mut self) {
        self.pi_d.reset();
        self.pi_q.reset();
        self.fw.reset();
        self.iq_last = 0.0;
        self.id_base = 0.0;
        #[cfg(feature = "flux-map")]
        self.reset_map();
        self.u_hist = [AlphaBeta::default(); 2];
        self.u_dq_last = Dq::default();
        self.stuck_angle = [0.0; 2];
        self.stuck_ticks = [0; 2];
    }

    /// Output of `Idle` and `Fault`: PWM off, duties 0.5.
    fn safe_output(&self) -> TickOutput {
        TickOutput {
            duties: SAFE_DUTIES,
            pwm_enabled: false,
            state: self.seq.state(),
            fault: self.fault(),
            telemetry: Telemetry {
                i_dq: Dq::default(),
                i_dq_ref: Dq::default(),
                u_dq: Dq::default(),
                u_ab: AlphaBeta::default(),
                theta_rad: 0.0,
                omega_rad_s: 0.0,
                speed_ref_mech_rad_s: 0.0,
                estimate: self.observer.estimate(),
                observer_ok: false,
                sample_ok: self.missed == 0,
            },
        }
    }
}
