//! Steps [`IdentifyStep::InductanceD`](super::IdentifyStep::InductanceD) and
//! [`IdentifyStep::InductanceQ`](super::IdentifyStep::InductanceQ): `Ld` and `Lq` from a
//! sinusoidal voltage along one axis of the aligned frame, on top of the resistance step's DC
//! voltage.

use core::f32::consts::TAU;

use crate::transforms::AlphaBeta;
use crate::trig::{sin_cos, sqrt};

use super::context::{Context, Tick};
use super::numeric::{Sums, ln, ticks};
use super::outcome::{IdentifyError, Quantity};
use super::spin::Spin;

/// The axis of the injection.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub(super) enum Axis {
    /// Along the rotor's d axis (the aligned frame's d): `Ld`.
    D,
    /// Along q (the DC d current holds the rotor): `Lq`.
    Q,
}

/// The part of an injection step. `d` runs the first three, `q` all five.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
enum Part {
    /// Two periods of settling, four demodulated: sets the amplitude for 30 % of the test
    /// current.
    Amplitude,
    /// Settling at the injection frequency `w`.
    Settle,
    /// Demodulated at `w`.
    Measure,
    /// Settling at `w / 2` (`q` only).
    SettleHalf,
    /// Demodulated at `w / 2` (`q` only).
    MeasureHalf,
}

/// An injection in progress.
#[derive(Clone, Copy, Debug)]
pub(super) struct Injection {
    axis: Axis,
    part: Part,
    /// Ticks in the part.
    n: u32,
    /// The DC d voltage of the resistance step's full level, V.
    u_hold: f32,
    /// Amplitude of the injected voltage, V.
    hf_u: f32,
    /// Sums of `(i c, i s, u c, u s)` over whole periods.
    sums: Sums,
    /// `L` at the injection frequency (`q`), H.
    lq_hf: f32,
}

/// What follows an injection.
#[derive(Clone, Copy, Debug)]
pub(super) enum AfterInjection {
    /// The `q` injection after the `d` one.
    Q(Injection),
    /// The spin for `psi_f`.
    Spin(Spin),
    /// Finished (no spin configured).
    Done,
}

impl Injection {
    /// An injection along `axis` on top of the DC voltage `u_hold`. First amplitude: 30 % of
    /// the test current through `|Rs + j w L|`, `L` the probe's largest (for `q` at least
    /// `Ld`), within [`amplitude_limit`](Self::amplitude_limit).
    #[inline]
    pub(super) fn new(ctx: &Context, axis: Axis, u_hold: f32) -> Self {
        let l = if axis == Axis::D {
            ctx.found.l_max
        } else {
            ctx.found.l_max.max(ctx.found.ld)
        };
        let w = TAU / ctx.hf_n as f32;
        let z = ctx.found.rs.max(0.0) + l * w / ctx.cfg.ts_s;
        let mut s = Self {
            axis,
            part: Part::Amplitude,
            n: 0,
            u_hold,
            hf_u: 0.0,
            sums: Sums::default(),
            lq_hf: 0.0,
        };
        s.hf_u = s.amplitude_limit(ctx).min(0.3 * ctx.cfg.test_current_a * z);
        s
    }

    /// The injection's peak within 90 % of the voltage limit, beside the DC voltage, V.
    #[inline]
    fn amplitude_limit(&self, ctx: &Context) -> f32 {
        (0.9 * ctx.u_lim - self.u_hold.abs()).max(0.0)
    }

    /// Whether this is the `q` injection.
    pub(super) fn is_q(&self) -> bool {
        self.axis == Axis::Q
    }

    /// One tick: `u_x = hf_u cos(w k)` on the axis, the axis current demodulated over whole
    /// periods into `H = I / U`; each part's end acts (module docs).
    #[inline]
    pub(super) fn step(
        &mut self,
        ctx: &mut Context,
        i_ab: AlphaBeta,
    ) -> Result<Tick, IdentifyError> {
        self.n = self.n.saturating_add(1);
        let q = self.axis == Axis::Q;
        let n_hf = if matches!(self.part, Part::SettleHalf | Part::MeasureHalf) {
            2 * ctx.hf_n
        } else {
            ctx.hf_n
        };
        let k = self.n - 1;
        let (s, c) = sin_cos(TAU * (k % n_hf) as f32 / n_hf as f32);
        let u_x = self.hf_u * c;
        let u = if q {
            ctx.frame.ab(self.u_hold, u_x)
        } else {
            ctx.frame.ab(self.u_hold + u_x, 0.0)
        };
        let (i_d, i_q) = ctx.frame.dq(i_ab);
        let i_x = if q { i_q } else { i_d };
        let tau_ticks = (ctx.found.l_max / ctx.found.rs / ctx.cfg.ts_s).min(4.0e5) as u32;
        let settle = {
            let t = (3 * tau_ticks).clamp(2 * n_hf, ticks(0.05, ctx.cfg.ts_s).max(2 * n_hf));
            t.div_ceil(n_hf) * n_hf
        };
        let measure = (ticks(ctx.cfg.inductance_time_s, ctx.cfg.ts_s) / n_hf).max(2) * n_hf;
        let (len, demod) = match self.part {
            Part::Amplitude => (6 * n_hf, k >= 2 * n_hf),
            Part::Settle | Part::SettleHalf => (settle, false),
            Part::Measure | Part::MeasureHalf => (measure, true),
        };
        if demod {
            self.sums.add([i_x * c, i_x * s, u_x * c, u_x * s]);
        }
        if self.n < len {
            return Ok(Tick::stay(u));
        }
        let h = self.sums.mean();
        let (hr, hi) = {
            // H = I / U with I = ic - j is, U = uc - j us.
            let (ir, ii) = (h[0], -h[1]);
            let (ur, ui) = (h[2], -h[3]);
            let den = ur * ur + ui * ui;
            ((ir * ur + ii * ui) / den, (ii * ur - ir * ui) / den)
        };
        self.sums = Sums::default();
        let done = match self.part {
            Part::Amplitude => {
                let gain = sqrt(hr * hr + hi * hi);
                let target = 0.3 * ctx.cfg.test_current_a;
                if gain.is_finite() && gain > 0.0 {
                    self.hf_u = (target / gain).min(self.amplitude_limit(ctx));
                }
                self.next_part(Part::Settle);
                false
            }
            Part::Settle => {
                self.next_part(Part::Measure);
                false
            }
            Part::SettleHalf => {
                self.next_part(Part::MeasureHalf);
                false
            }
            Part::Measure | Part::MeasureHalf => {
                let l = fit_inductance(ctx, hr, hi, n_hf);
                let quantity = if q {
                    Quantity::InductanceQ
                } else {
                    Quantity::InductanceD
                };
                if !(l.is_finite() && l > 1e-8 && l < 100.0) {
                    return Err(IdentifyError::Implausible { quantity, value: l });
                }
                if !q {
                    ctx.found.ld = l;
                    true
                } else if self.part == Part::Measure {
                    self.lq_hf = l;
                    // Half the frequency: half the voltage for the same current.
                    self.hf_u *= 0.5;
                    self.next_part(Part::SettleHalf);
                    false
                } else {
                    // The rotor's oscillation adds -K / w^2 to L: extrapolated away.
                    let lq = (4.0 * self.lq_hf - l) / 3.0;
                    if !(lq.is_finite() && lq > 1e-8 && lq < 100.0) {
                        return Err(IdentifyError::Implausible {
                            quantity,
                            value: lq,
                        });
                    }
                    ctx.found.lq = lq;
                    true
                }
            }
        };
        Ok(Tick::then(Some(u), done))
    }

    /// What follows: after `d` the `q` injection, after `q` the spin (when configured).
    #[inline]
    pub(super) fn next(&self, ctx: &mut Context) -> AfterInjection {
        if self.axis == Axis::D {
            AfterInjection::Q(Injection::new(ctx, Axis::Q, self.u_hold))
        } else {
            match Spin::new(ctx) {
                Some(spin) => AfterInjection::Spin(spin),
                None => AfterInjection::Done,
            }
        }
    }

    fn next_part(&mut self, part: Part) {
        self.part = part;
        self.n = 0;
    }
}

/// `L` from the measured `H = I / U` at `w = 2 pi / n` rad per tick: the exact discrete
/// model `H = b z^-d / (z - a)`, solved for real `a` and `b` from `a H + b z^-d = H z`, then
/// `L = Ts (1 - a) / (b (-ln a))`. `NaN` unless `0 < a < 1` and `b > 0`.
#[inline]
fn fit_inductance(ctx: &Context, hr: f32, hi: f32, n: u32) -> f32 {
    let w = TAU / n as f32;
    let (s1, c1) = sin_cos(w);
    let (sd, cd) = sin_cos(w * ctx.d as f32);
    let (wr, wi) = (cd, -sd);
    let (zr, zi) = (hr * c1 - hi * s1, hr * s1 + hi * c1);
    let det = hr * wi - hi * wr;
    let a = (zr * wi - zi * wr) / det;
    let b = (hr * zi - hi * zr) / det;
    if !(a > 0.0 && a < 1.0 && b > 0.0) {
        return f32::NAN;
    }
    ctx.cfg.ts_s * (1.0 - a) / (b * -ln(a))
}
