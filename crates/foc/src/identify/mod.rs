//! Self-commissioning: measures `Rs`, `Ld`, `Lq`, `psi_f`, the inverter's voltage error and
//! (optionally) the inertia of a motor the drive knows nothing about.
//!
//! [`Identifier::tick`] takes the same [`TickInput`] as [`Foc::tick`](crate::Foc::tick), once
//! per PWM period, and returns duties; [`identify_period`] is the interrupt body for the
//! [`hal`](crate::hal) traits. Nothing here reads a clock, allocates or panics. Every step has
//! a fixed length in ticks (derived from [`IdentifyConfig`]), so the whole sequence is
//! time-bounded; it ends with the PWM off and [`Identifier::result`] set, either to the
//! [`Identified`] parameters or to an [`IdentifyFailure`] naming the error, the step and the
//! tick.
//!
//! # The sequence
//!
//! `Ts` is the PWM period, `I_t` the test current (`test_current_a`), `U_lim =
//! max_modulation u_dc / sqrt(3)` the voltage limit (the circle inside the modulator's
//! hexagon), `d` the computation delay in periods (0 or 1).
//!
//! | step | what | how |
//! |---|---|---|
//! | [`IdentifyStep::Offsets`] | current-sensor offsets | PWM off, mean of the phase currents |
//! | [`IdentifyStep::Probe`] | wiring and a rough inductance | bipolar voltage pulses along the three phase axes, doubling the voltage (then the pulse length) until one axis reaches 40 % of the test current; an axis that stays dead is an open phase, all three: no motor. `L ~ U t / di` sizes the current loop |
//! | [`IdentifyStep::Align`] | rotor to a known angle | test current at 90 deg, then at 0 deg (the phase-a axis), so that a rotor at any angle (also 180 deg away) is pulled in; the q voltage is left at zero, so the swinging rotor's EMF drives a braking current (electrical damping) |
//! | [`IdentifyStep::Resistance`] | `Rs`, inverter voltage error | DC current along the aligned d axis at 50 % and 100 % of the test current: `Rs = dU / dI`; the dead-time voltage (the same at both levels, the phase currents keep their signs) cancels and is reported as `U(I_t) - Rs I_t` |
//! | [`IdentifyStep::InductanceD`] | `Ld` | the DC voltage held, plus a sinusoidal voltage along d; the current's response at the injection frequency, demodulated over whole periods, fitted to the exact zero-order-hold model of the RL circuit with the computation delay, `i[k+1] = a i[k] + b u[k-d]`: `L = Ts (1 - a) / (b (-ln a))` |
//! | [`IdentifyStep::InductanceQ`] | `Lq` | the same along q (the DC d current holds the rotor); at two frequencies `w` and `w/2`, so that the rotor's small oscillation (an apparent `-K/w^2` in `L`) is extrapolated away: `Lq = (4 L(w) - L(w/2)) / 3` |
//! | [`IdentifyStep::Spin`] | `psi_f` | I/f: the test current along a frame that turns with a jerk-limited ramp to `spin_speed_rad_s`; at constant speed the mean frame voltage gives the active-flux EMF `E = u - (Rs + j w Lq) i` (dead-time voltage removed), `|E| = w (psi_f + (Ld - Lq) i_d)`, its angle the load angle and so `i_d`; `w` is the rotor's mean speed over the window, the frame's minus the drift of the load angle (the rotor swings about the frame) |
//! | [`IdentifyStep::Inertia`] | `J` (optional) | the frame accelerates to 1.4 x the spin speed and back at the same rate; every tick gives the rotor angle (frame minus load angle) and the torque (from the load angle and the current); a least-squares fit of the rotor's trajectory to `J theta'' = T - B theta' - T_c`, integrated twice, with the initial angle and speed and the friction as nuisance parameters, gives `J`. The I/f frame holds the rotor like a spring; with little friction the rotor swings about it for seconds, and the fit models that swing instead of averaging it (friction is fitted but not reported) |
//!
//! With the default durations the standstill steps take about 0.9 s; a spin to 25 % of rated
//! speed in 0.4 s takes about 0.8 s more, the inertia move 0.4 s. The measured accuracy and
//! the cost per tick are in `docs/identify.md`.
//!
//! # The equations of each step
//!
//! **Probe.** A pulse on phase axis `x` is `+U` for `m` ticks, `-U` for `m` ticks, zero for
//! `m + 3 + d` ticks; the axis current's change over the `+U` half is `di = U m Ts / L`
//! (resistance neglected: `m Ts` is short against `L / Rs` while `di` is small). The first
//! level is `U = U_lim / 512`, one tick; each level doubles `U` up to `U_lim / 2`, then `m` up
//! to 64 ticks. The level where one axis reaches `0.4 I_t` is repeated 4 times and averaged:
//! the largest `di` below `0.04 I_t` is [`IdentifyError::NoMotor`], an axis below 10 % of the
//! largest [`IdentifyError::OpenPhase`]. `L_min = U m Ts / di_max` sets the standstill current
//! loop `Kp = L_min bw`, `Ki = Kp bw / 8` (the smallest inductance: the stable side, `Rs`
//! still unknown); `L_max = U m Ts / di_min` sizes the injection.
//!
//! **Align.** Each half lasts `align_time_s / 2`: the d current ramps to `I_t` over the first
//! 40 % of the first half at 90 deg, then holds `I_t` at 0 deg. The d loop is the PI above with
//! `u_q = 0`.
//!
//! **Resistance.** Two levels `I1 = I_t / 2`, `I2 = I_t`, each `resistance_time_s`; the d
//! voltage and current are averaged over the last 70 % of each:
//! `Rs = (U2 - U1) / (I2 - I1)`, inverter voltage error `U2 - Rs I2` (the dead-time voltage
//! and the switches' drops at `I_t` along the phase-a axis, the same at both levels).
//!
//! **Inductance.** On top of `U2` (d), `u_x[k] = U_hf cos(w k)` along the axis, `w = 2 pi /
//! N`, `N` = [`IdentifyConfig::hf_period_ticks`]. A first part (2 periods settling, 4
//! demodulated) sets `U_hf` for a current amplitude of `0.3 I_t` (started from `0.3 I_t (Rs +
//! w L_max)`, `w` in rad/s), within `0.9 U_lim - |U2|`. After settling `3 L_max / Rs` (between 2
//! periods and 50 ms, in whole periods), the axis current and voltage are demodulated over
//! `inductance_time_s` (whole periods): `H = I / U`. The model `H = b z^-d / (z - a)` is
//! solved for real `a`, `b` from `a H + b z^-d = H z`, and `L = Ts (1 - a) / (b (-ln a))`
//! (exact for the sampled RL circuit at any `w Ts`). On q a second measurement at `w/2`
//! (half the voltage) follows; the rotor's oscillation adds `-K / w^2` to `L(w)`:
//! `Lq = (4 L(w) - L(w/2)) / 3`.
//!
//! **Spin.** Current loops by pole-zero cancellation, `Kp = Ld bw` (d), `Lq bw` (q), `Ki =
//! Rs bw`, with the cross-coupling feed-forward `-w Lq i_q`, `w Ld i_d`; the d integrator is
//! preset to `Rs I_f + U_err I_f / I_t`. The frame speed follows a jerk-limited move (the
//! acceleration rises over 20 % of the move, holds, falls) to `spin_speed_rad_s` at
//! `spin_accel_rad_s2`; the voltage is rotated by `(d + 1/2) w Ts` to the middle of the
//! interval it acts over. After `spin_settle_time_s`, over `spin_measure_time_s`:
//! `E = u - Rs i - j w Lq i - (3 / pi) U_err i / |i|` (the dead-time voltage's fundamental
//! along the current), load angle `g = pi/2 - arg E`, rotor current `i_r = e^(j g) i`,
//! `w_rotor = w - (g_end - g_start) / T`, and `psi_f = |E| / w_rotor - (Ld - Lq) i_rd`.
//! Locked: `|E| <= 0.1 (Rs + w max(Ld, Lq)) I_f`. Out of step: `|g| >= 1.3 rad`, or a quarter
//! of the window whose EMF differs from the mean by 25 % or 0.35 rad.
//!
//! **Inertia.** From the spin speed `w0`, a move of `+0.4 w0` and one of `-0.4 w0` at
//! `spin_accel_rad_s2`. With `theta = (phi - g) / p` (frame angle `phi` beyond `w0 t`), `T =
//! 1.5 p (psi_f + (Ld - Lq) i_rd) i_rq` and `s = t / T_move`, every tick is a row of the
//! least-squares fit `y = c0 + c1 s + c2 s^2 + S(t) / J - (B / J) Y(t)` (`S` the double
//! integral of `T`, `Y` the integral of `y`), solved by Givens rotations in `f32`; `J = 1 /
//! coefficient of S`.
//!
//! # Defaults and why
//!
//! [`IdentifyConfig::new`]`(Ts, U, I_t)` derives the settings from the PWM period, the
//! nominal bus and the test current; [`IdentifyConfig::with_spin`] adds the spin.
//!
//! | field | default | why |
//! |---|---|---|
//! | `test_current_a` | given; about half the rated current (pmsm-sim: half the current limit) | every level scales with it: align and resistance `I_t` and `I_t / 2`, injection amplitude `0.3 I_t`, spin current |
//! | `delay` | `ComputationDelay::OnePeriod` | real hardware; the inductance model and the spin's voltage rotation use it |
//! | `over_current_a` | `2.5 I_t` | room for the loops' overshoot and the injection's peak above `I_t` (the validation asks at least `1.5 I_t`) |
//! | `u_dc_min_v`, `u_dc_max_v` | `0.5 U`, `1.25 U` | |
//! | `max_modulation` | 0.95 | 5 % of the circle left to the current loops' transients |
//! | `current_bw_rad_s` | `2 pi 300` | the loops hold DC or slowly turning currents only; within the validation's bound `bw Ts <= 0.5` from a 3.8 kHz PWM up |
//! | `hf_frequency_hz` | 1 kHz (10 ticks at 10 kHz) | `w L` well above `Rs` on the reference motors (servo: 53 ohm against 2.9 ohm), so `a` is well away from 1 and 0; a whole number of ticks per period (at least 4) |
//! | `align_time_s` | 0.3 s | two halves of 0.15 s: the rotor swings in and is braked |
//! | `resistance_time_s` | 0.13 s per level | 30 % settling (the d loop), 70 % averaging the sensor noise |
//! | `inductance_time_s` | 0.08 s | 80 periods at 1 kHz |
//! | `spin_speed_rad_s`, `spin_accel_rad_s2` | 0 (no spin: `psi_f` and `J` not measured) | the motor may not be free to turn; the caller decides (pmsm-sim: 25 % of rated speed, reached in 0.4 s) |
//! | `spin_current_a` | `I_t` | the rotor follows the frame with a load angle well below 90 deg |
//! | `spin_settle_time_s`, `spin_measure_time_s` | 0.15 s, 0.2 s | the ramp's end transient decays; the rotor's remaining swing about the frame is corrected by the load angle's drift over the window (`w_rotor`) |
//! | `measure_inertia` | `false` | needs the spin |
//! | `pole_pairs` | 1 | only `J` (mechanical) uses it |
//!
//! Fixed rules: the offsets settle 3 ticks and average `max(20 ms, 16 ticks)`, refused above
//! `0.2 I_t`; a loop at its voltage limit (`|u| >= 0.999` of it) below 90 % of its reference
//! for more than 20 ms is [`IdentifyError::BusTooLow`]; results outside `1e-4 < Rs < 1e4`
//! ohm, `1e-8 < L < 100` H, `1e-5 < psi_f < 50` Wb, `0 < J < 1e4` kg m^2 are
//! [`IdentifyError::Implausible`]; [`Identified::motor_params`] reads `Ld`, `Lq` within
//! [`SURFACE_TOLERANCE`] of their mean as a surface motor.
//!
//! # Faults
//!
//! Checked every tick: non-finite inputs, over-current (`over_current_a`), bus outside
//! `[u_dc_min_v, u_dc_max_v]`. The current loops hitting the voltage limit below 90 % of their
//! reference for 20 ms is [`IdentifyError::BusTooLow`]. Implausible results
//! (negative or absurd `Rs`, `L`, `psi_f`, `J`) are [`IdentifyError::Implausible`]; a spin
//! without back-EMF is [`IdentifyError::RotorLocked`], one whose EMF does not turn with the
//! frame is [`IdentifyError::LostSync`]. Every failure turns the PWM off at once.
//!
//! # Structure
//!
//! [`Identifier`] holds the shared context (settings, frame, results so far) and the state of
//! the step in progress, an enum whose variants carry their own state: one file per step
//! (`offsets`, `probe`, `align`, `resistance`, `inductance`, `spin`, `inertia`; the I/f drive
//! of the last two in `if_drive`). The standstill flux-map measurement of saturating motors,
//! [`SaturationProbe`] (module [`saturation`]), is a separate state machine run after this
//! sequence, not part of it; [`IdentifyWithMap`] runs the sequence and then it (coast at zero
//! current for `psi_f`, stop, re-align, probe), opt-in. Each step's `step` returns the voltage and whether the step
//! is over, its `next` the state that follows; [`Identifier::tick`] checks the inputs, picks
//! the step and modulates.

use crate::controller::{PhaseCurrents, TickInput};
use crate::hal::{CurrentSense, Inverter, write_bridge};
use crate::svpwm::SAFE_DUTIES;
use crate::transforms::AlphaBeta;
use crate::trig::sqrt;

mod align;
mod coast;
mod config;
mod context;
mod if_drive;
mod inductance;
mod inertia;
mod lsq;
mod map_step;
mod numeric;
mod offsets;
mod outcome;
mod probe;
mod resistance;
pub mod saturation;
mod spin;

pub use config::{IdentifyConfig, IdentifyConfigError};
pub use map_step::{FluxMapError, FluxMapStep, IdentifyWithMap, MapPart};
pub use numeric::ln;
pub use outcome::{
    Identified, IdentifyError, IdentifyFailure, IdentifyOutput, IdentifyStep, Quantity,
    SURFACE_TOLERANCE,
};
pub use saturation::{
    FluxSamples, SaturationConfig, SaturationError, SaturationOutput, SaturationPhase,
    SaturationProbe,
};

use align::Align;
use context::{Context, Found, Frame, Tick};
use inductance::{AfterInjection, Injection};
use inertia::Inertia;
use offsets::Offsets;
use probe::{PROBE_MAX_M, Probe};
use resistance::Resistance;
use spin::Spin;

use numeric::INV_SQRT3;

/// The step in progress, with its own state. (`repr(u8)`: a one-byte tag the dispatch
/// reads directly; the niche layout Rust picks otherwise costs the worst tick, the
/// inertia step's last, about 18 instructions on the Cortex-M4F.)
#[derive(Clone, Debug)]
#[repr(u8)]
enum Step {
    Offsets(Offsets),
    Probe(Probe),
    Align(Align),
    Resistance(Resistance),
    /// `Ld` or `Lq`.
    Inductance(Injection),
    Spin(Spin),
    Inertia(Inertia),
    /// Finished or failed: [`Identifier::result`] is set.
    Done,
}

impl Step {
    /// The public name of the step.
    fn public(&self) -> IdentifyStep {
        match self {
            Step::Offsets(_) => IdentifyStep::Offsets,
            Step::Probe(_) => IdentifyStep::Probe,
            Step::Align(_) => IdentifyStep::Align,
            Step::Resistance(_) => IdentifyStep::Resistance,
            Step::Inductance(s) if s.is_q() => IdentifyStep::InductanceQ,
            Step::Inductance(_) => IdentifyStep::InductanceD,
            Step::Spin(_) => IdentifyStep::Spin,
            Step::Inertia(_) => IdentifyStep::Inertia,
            Step::Done => IdentifyStep::Done,
        }
    }
}

/// The identification sequence (module docs).
#[derive(Clone, Debug)]
pub struct Identifier {
    ctx: Context,
    state: Step,
    /// The public name of `state` (kept with it).
    step: IdentifyStep,
    /// Ticks since construction.
    tick: u32,
    /// The tick the step in progress started at.
    step_start: u32,
    /// Ticks spent in each step of [`IdentifyStep::ALL`].
    step_ticks: [u32; 8],
    result: Option<Result<Identified, IdentifyFailure>>,
}

impl Identifier {
    /// A sequence with the settings `cfg` (checked), not started: the first tick starts it.
    pub fn new(cfg: &IdentifyConfig) -> Result<Self, IdentifyError> {
        cfg.validate().map_err(IdentifyError::Config)?;
        let d = match cfg.delay {
            crate::config::ComputationDelay::OnePeriod => 1,
            crate::config::ComputationDelay::None => 0,
        };
        Ok(Self {
            ctx: Context {
                cfg: *cfg,
                d,
                hf_n: cfg.hf_period_ticks(),
                u_lim: 0.0,
                frame: Frame::new(),
                found: Found::default(),
            },
            state: Step::Offsets(Offsets::default()),
            step: IdentifyStep::Offsets,
            tick: 0,
            step_start: 0,
            step_ticks: [0; 8],
            result: None,
        })
    }

    /// The settings.
    pub fn config(&self) -> &IdentifyConfig {
        &self.ctx.cfg
    }

    /// The step in progress ([`IdentifyStep::Done`] when finished).
    pub fn step(&self) -> IdentifyStep {
        self.step
    }

    /// The outcome, once finished.
    pub fn result(&self) -> Option<&Result<Identified, IdentifyFailure>> {
        self.result.as_ref()
    }

    /// Whether the sequence has finished (success or failure).
    pub fn is_done(&self) -> bool {
        self.result.is_some()
    }

    /// Ticks since construction.
    pub fn ticks(&self) -> u32 {
        self.tick
    }

    /// An upper bound of the sequence's length with these settings, s (each step has a
    /// fixed length; the probe's is its worst case).
    pub fn max_duration_s(&self) -> f32 {
        let c = &self.ctx.cfg;
        let hf = self.ctx.hf_n as f32 * c.ts_s;
        let probe = 3.0 * 18.0 * 6.0 * c.ts_s + 3.0 * 7.0 * 3.0 * PROBE_MAX_M as f32 * c.ts_s;
        let ind = 3.0 * (c.inductance_time_s + 0.05 + 8.0 * hf);
        let mut t = 0.02 + probe + c.align_time_s + 2.0 * c.resistance_time_s + ind;
        if c.spin_speed_rad_s > 0.0 {
            t += 1.3 * c.spin_speed_rad_s / c.spin_accel_rad_s2
                + c.spin_settle_time_s
                + c.spin_measure_time_s;
            if c.measure_inertia {
                t += 3.0 * 0.4 * c.spin_speed_rad_s / c.spin_accel_rad_s2;
            }
        }
        t
    }

    /// Goes to `next`, counting the ticks of the step left.
    /// Ends the step in progress: counts its ticks.
    fn leave(&mut self) {
        if let Some(t) = self.step_ticks.get_mut(self.step.index()) {
            *t = self.tick.wrapping_sub(self.step_start);
        }
        self.step_start = self.tick;
    }

    /// The step in progress is over: goes to the state that follows it (built by the
    /// step's `next`), or finishes.
    #[inline(never)]
    fn advance(&mut self) {
        self.leave();
        let ctx = &mut self.ctx;
        self.state = match &self.state {
            Step::Offsets(s) => Step::Probe(s.next(ctx)),
            Step::Probe(s) => Step::Align(s.next(ctx)),
            Step::Align(s) => Step::Resistance(s.next()),
            Step::Resistance(s) => Step::Inductance(s.next(ctx)),
            Step::Inductance(s) => match s.next(ctx) {
                AfterInjection::Q(s) => Step::Inductance(s),
                AfterInjection::Spin(s) => Step::Spin(s),
                AfterInjection::Done => Step::Done,
            },
            Step::Spin(s) => match s.next(ctx) {
                Some(s) => Step::Inertia(s),
                None => Step::Done,
            },
            Step::Inertia(_) | Step::Done => Step::Done,
        };
        self.step = self.state.public();
        if self.step == IdentifyStep::Done {
            self.finish();
        }
    }

    fn fail(&mut self, error: IdentifyError) {
        let step = self.step;
        self.leave();
        self.state = Step::Done;
        self.step = IdentifyStep::Done;
        self.result = Some(Err(IdentifyFailure {
            error,
            step,
            tick: self.tick,
        }));
    }

    /// Sets the result from what was found (the state is [`Step::Done`]).
    fn finish(&mut self) {
        let f = &self.ctx.found;
        self.result = Some(Ok(Identified {
            rs_ohm: f.rs,
            ld_h: f.ld,
            lq_h: f.lq,
            psi_f_wb: f.psi,
            inverter_voltage_error_v: f.v_err,
            j_kg_m2: f.j,
            current_offsets_a: f.offsets,
            step_ticks: self.step_ticks,
            ticks: self.tick,
        }));
    }

    fn off_output(&self, i_ab: AlphaBeta) -> IdentifyOutput {
        IdentifyOutput {
            duties: SAFE_DUTIES,
            pwm_enabled: false,
            step: self.step,
            i_ab,
            u_ab: AlphaBeta::default(),
            frame_angle_rad: self.ctx.frame.angle,
            frame_speed_rad_s: self.ctx.frame.omega,
        }
    }

    /// One PWM period (module docs): the input checks, the step in progress, the voltage
    /// limit and the modulator.
    pub fn tick(&mut self, input: &TickInput) -> IdentifyOutput {
        self.tick = self.tick.wrapping_add(1);
        if self.result.is_some() {
            return self.off_output(AlphaBeta::default());
        }
        let u_dc = input.u_dc_v;
        let offsets = self.ctx.found.offsets;
        let raw = match input.currents {
            PhaseCurrents::Abc(a) => [a.a, a.b],
            PhaseCurrents::AlphaBeta(ab) => [ab.alpha, ab.beta],
        };
        let i_ab = numeric::less_offsets(input.currents, offsets);
        if !(u_dc.is_finite() && i_ab.alpha.is_finite() && i_ab.beta.is_finite()) {
            self.fail(IdentifyError::NonFiniteInput);
            return self.off_output(AlphaBeta::default());
        }
        let i_mag = sqrt(i_ab.norm_squared());
        let cfg = &self.ctx.cfg;
        if i_mag > cfg.over_current_a {
            self.fail(IdentifyError::OverCurrent { current_a: i_mag });
            return self.off_output(i_ab);
        }
        if u_dc > cfg.u_dc_max_v {
            self.fail(IdentifyError::BusOverVoltage { u_dc_v: u_dc });
            return self.off_output(i_ab);
        }
        if u_dc < cfg.u_dc_min_v {
            self.fail(IdentifyError::BusUnderVoltage { u_dc_v: u_dc });
            return self.off_output(i_ab);
        }
        self.ctx.u_lim = cfg.max_modulation * u_dc * INV_SQRT3;
        let ctx = &mut self.ctx;
        let tick = match &mut self.state {
            Step::Offsets(s) => s.step(ctx, raw),
            Step::Probe(s) => s.step(ctx, i_ab),
            Step::Align(s) => s.step(ctx, i_ab),
            Step::Resistance(s) => s.step(ctx, i_ab),
            Step::Inductance(s) => s.step(ctx, i_ab),
            Step::Spin(s) => s.step(ctx, i_ab),
            Step::Inertia(s) => s.step(ctx, i_ab),
            Step::Done => Ok(Tick::then(None, false)),
        };
        let u = match tick {
            Ok(Tick { u, done }) => {
                if done {
                    self.advance();
                }
                match u {
                    Some(u) if self.result.is_none() => u,
                    _ => return self.off_output(i_ab),
                }
            }
            Err(e) => {
                self.fail(e);
                return self.off_output(i_ab);
            }
        };
        // Voltage limit (circle), then the modulator (hexagon; the circle is inside it).
        let m = numeric::limited_svpwm(u, self.ctx.u_lim, u_dc);
        IdentifyOutput {
            duties: m.duties,
            pwm_enabled: true,
            step: self.step,
            i_ab,
            u_ab: m.applied,
            frame_angle_rad: self.ctx.frame.angle,
            frame_speed_rad_s: self.ctx.frame.omega,
        }
    }
}

/// One PWM period of the identification with the [`hal`](crate::hal) traits: reads the
/// samples, ticks, writes the outputs (disabled before the duties are written when turning
/// off, as [`run_period`](crate::hal::run_period) does).
pub fn identify_period<S: CurrentSense, I: Inverter>(
    id: &mut Identifier,
    sense: &mut S,
    inverter: &mut I,
) -> IdentifyOutput {
    let input = TickInput {
        currents: sense.currents(),
        u_dc_v: sense.bus_voltage_v(),
        sensor: None,
    };
    let out = id.tick(&input);
    write_bridge(inverter, out.duties, out.pwm_enabled);
    out
}

#[cfg(test)]
mod tests;
