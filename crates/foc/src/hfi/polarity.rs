//! The magnet polarity test at standstill (module [`crate::hfi`], "Magnet polarity"): three
//! states, each with its own step, and a dispatcher ([`Standstill::step`]).
//!
//! ```text
//! Settling       i_d = 0 for settle ticks (the loop locks on the salient axis)
//!   -> PulsePositive  i_d = +I_p for pulse ticks, the responses' d part summed over the
//!                     second half; then i_d = 0 for gap = pulse / 2 ticks
//!   -> PulseNegative  the same with -I_p
//!   -> done: contrast = mean d(+I_p) / mean d(-I_p); flip the axis by pi if contrast < 1
//! ```
//!
//! Without [`HfiConfig::detect_polarity`] the test ends after settling, unflipped, contrast NaN.
//! With no response in a pulse the contrast is NaN and the axis is kept.

use super::config::HfiConfig;
use super::demod::Response;

/// The test's timing and current, from the settings.
#[derive(Clone, Copy, Debug, PartialEq)]
pub(crate) struct PolarityPlan {
    /// Ticks of settling, of each pulse, and of the zero-current gap after each pulse.
    settle: u32,
    pulse: u32,
    gap: u32,
    /// `I_p`, A.
    current: f32,
    /// Whether the pulses run at all.
    detect: bool,
}

impl PolarityPlan {
    /// The plan for `hfi` at the PWM period `ts` (s); at least one tick per step.
    pub fn new(hfi: &HfiConfig, ts: f32) -> Self {
        let t = |s: f32| crate::health::ticks(s, ts).max(1);
        Self {
            settle: t(hfi.settle_time_s),
            pulse: t(hfi.pulse_time_s),
            gap: t(0.5 * hfi.pulse_time_s),
            current: hfi.polarity_current_a,
            detect: hfi.detect_polarity,
        }
    }
}

/// The test's outcome.
#[derive(Clone, Copy, Debug, PartialEq)]
pub(crate) struct Polarity {
    /// Whether the axis was turned by `pi`.
    pub flipped: bool,
    /// As [`HfiStatus::polarity_contrast`](super::HfiStatus::polarity_contrast).
    pub contrast: f32,
}

/// What the test asks for this tick.
#[derive(Clone, Copy, Debug, PartialEq)]
pub(crate) enum PolarityStep {
    /// Run with this d current reference, A.
    Drive(f32),
    /// Done: turn the axis by `pi` if `flipped`.
    Done(Polarity),
}

/// Settling at zero current: ticks so far.
#[derive(Clone, Copy, Debug, Default, PartialEq)]
pub(crate) struct Settle {
    t: u32,
}

/// One pulse: ticks so far, and the sum and count of the d responses measured.
#[derive(Clone, Copy, Debug, Default, PartialEq)]
pub(crate) struct Pulse {
    t: u32,
    sum: f32,
    n: u32,
}

/// The standstill test's state.
#[derive(Clone, Copy, Debug, PartialEq)]
#[repr(u8)]
pub(crate) enum Standstill {
    /// Zero current while the loop settles.
    Settling(Settle),
    /// The `+I_p` pulse and its gap.
    PulsePositive(Pulse),
    /// The `-I_p` pulse and its gap, with the mean d response under `+I_p`.
    PulseNegative { pulse: Pulse, mean_positive: f32 },
}

/// What a state's step returns: the tick's d current reference, and the next state or the
/// result if the state ends.
enum Next {
    Stay(f32),
    Go(Standstill, f32),
    Done(Polarity),
}

impl Settle {
    fn step(&mut self, plan: &PolarityPlan) -> Next {
        self.t += 1;
        if self.t < plan.settle {
            return Next::Stay(0.0);
        }
        if !plan.detect {
            return Next::Done(Polarity {
                flipped: false,
                contrast: f32::NAN,
            });
        }
        Next::Go(Standstill::PulsePositive(Pulse::default()), 0.0)
    }
}

/// Where a pulse stands after its step.
enum PulseTick {
    /// Still running, with this d current reference.
    Drive(f32),
    /// Pulse and gap over: the mean d response measured.
    Over(f32),
}

impl Pulse {
    /// One tick of the pulse of sign `sign` (`+1` or `-1`) and its gap.
    fn step(&mut self, plan: &PolarityPlan, sign: f32, resp: Option<Response>) -> PulseTick {
        self.t += 1;
        if self.t <= plan.pulse {
            // Measure over the second half, once the current has settled.
            if 2 * self.t > plan.pulse
                && let Some(r) = resp
            {
                self.sum += r.d;
                self.n += 1;
            }
            return PulseTick::Drive(sign * plan.current);
        }
        if self.t < plan.pulse + plan.gap {
            return PulseTick::Drive(0.0);
        }
        PulseTick::Over(self.sum / (self.n.max(1) as f32))
    }
}

impl Standstill {
    /// The test's first state.
    pub fn new() -> Self {
        Standstill::Settling(Settle::default())
    }

    /// One tick with this tick's response: the d current reference, or the result.
    pub fn step(&mut self, plan: &PolarityPlan, resp: Option<Response>) -> PolarityStep {
        let next = match self {
            Standstill::Settling(s) => s.step(plan),
            Standstill::PulsePositive(p) => match p.step(plan, 1.0, resp) {
                PulseTick::Drive(i_d) => Next::Stay(i_d),
                PulseTick::Over(mean_positive) => Next::Go(
                    Standstill::PulseNegative {
                        pulse: Pulse::default(),
                        mean_positive,
                    },
                    0.0,
                ),
            },
            Standstill::PulseNegative {
                pulse,
                mean_positive,
            } => match pulse.step(plan, -1.0, resp) {
                PulseTick::Drive(i_d) => Next::Stay(i_d),
                PulseTick::Over(mean_negative) => {
                    let contrast = *mean_positive / mean_negative;
                    // NaN (no responses) keeps the axis.
                    Next::Done(Polarity {
                        flipped: contrast < 1.0,
                        contrast,
                    })
                }
            },
        };
        match next {
            Next::Stay(i_d) => PolarityStep::Drive(i_d),
            Next::Go(state, i_d) => {
                *self = state;
                PolarityStep::Drive(i_d)
            }
            Next::Done(p) => PolarityStep::Done(p),
        }
    }
}
