//! Demodulation (module [`crate::hfi`], "Equations" and "Demodulation by least squares"):
//! from the current samples and the carrier applied before each, the carrier's step along
//! and across its axis over the last carrier period, the normalised angle error, the
//! fundamental current and the carrier's own current.
//!
//! Each tick the step `y[k] = s_a R(-phi_a) (i[k] - i[k-1])` (signed with and projected on
//! the carrier applied over `[t_k-1, t_k)`) enters a ring of one period. The step estimate
//! is `sum_j w[p0][p_j] y_j` less the fundamental's slope `b = (i[k] - i[k-2N]) / 2N` seen
//! through the moving axis, `sum_j w[p0][p_j] s_j R(-phi_j) b`, and
//! `eps = clamp(q / (2 Ts V Y_d), -1, 1)`.

use super::MAX_HALF_PERIOD;
use super::injection::Carrier;
use crate::transforms::{AlphaBeta, Dq};

/// Length of the tracker's history rings: one carrier period at the longest half period.
pub(super) const RING: usize = 2 * MAX_HALF_PERIOD as usize;

/// Least-squares weights of the demodulation (module [`crate::hfi`], "Demodulation by least
/// squares"): `w[p0][p]` weighs the signed step `y` applied at carrier phase `p` in the window
/// of one period whose oldest step was applied at phase `p0` (`half` ticks per half period).
pub(super) fn ls_weights(half: u8) -> [[f32; RING]; RING] {
    let half = usize::from(half.clamp(1, MAX_HALF_PERIOD));
    let n = 2 * half;
    let sign = |p: usize| if p % n < half { 1.0_f32 } else { -1.0 };
    let mut w = [[0.0_f32; RING]; RING];
    if half == 1 {
        // Three samples, three unknowns: the second difference, `y` weighed 1/2 (exactly).
        w[0][..2].fill(0.5);
        w[1][..2].fill(0.5);
        return w;
    }
    for (p0, row) in w.iter_mut().enumerate().take(n) {
        // Samples j = 0..=n of the window; the carrier's accumulated current T_j (a unit
        // step per tick, signed).
        let mut t = [0.0_f32; RING + 1];
        for j in 1..=n {
            t[j] = t[j - 1] + sign(p0 + j - 1);
        }
        // T less its projection on the fundamental's constant and slope (orthogonal basis
        // 1 and j - n/2 over the n + 1 samples).
        let m = n as f32 + 1.0;
        let jc = |j: usize| j as f32 - 0.5 * n as f32;
        let (mut st, mut stj, mut sjj) = (0.0, 0.0, 0.0);
        for (j, tj) in t.iter().enumerate().take(n + 1) {
            st += tj;
            stj += tj * jc(j);
            sjj += jc(j) * jc(j);
        }
        let mut r = [0.0_f32; RING + 1];
        let mut rr = 0.0;
        for j in 0..=n {
            r[j] = t[j] - st / m - stj / sjj * jc(j);
            rr += r[j] * r[j];
        }
        // Sample weights r_j / |r|^2 (they sum to zero) as weights of the differences:
        // v_j = sum_{m >= j} w_m for the step into sample j; y_j = s_j (i_j - i_j-1).
        let mut v = 0.0;
        for j in (1..=n).rev() {
            v += r[j] / rr;
            let p = (p0 + j - 1) % n;
            row[p] = v * sign(p0 + j - 1);
        }
    }
    w
}

/// The carrier's response in one demodulation (module [`crate::hfi`]), A per period of carrier step:
/// `d`: `Ts V / Ld,inc` at zero error; `q`: `Ts V Y_d sin 2e`.
#[derive(Clone, Copy, Debug, Default, PartialEq)]
pub struct Response {
    /// d response along the injection axis, A.
    pub d: f32,
    /// q response, A.
    pub q: f32,
    /// Normalised angle error `sin(2e) / 2`, clamped to `+-1`.
    pub eps: f32,
}

/// The demodulator's rings and counters.
#[derive(Clone, Copy, Debug, PartialEq)]
pub(super) struct Demodulator {
    /// Ticks per carrier period, `2 N`.
    period: u8,
    /// `1 / (2 Ts V Y_d)`.
    inv_scale: f32,
    /// The last sample `i[k-1]`.
    i_prev: AlphaBeta,
    /// The last `period` samples and demodulated steps (ring, written at `pos`).
    i_ring: [AlphaBeta; RING],
    y_ring: [Dq; RING],
    /// Carrier phase of each step in `y_ring`, and the least-squares weights ([`ls_weights`]).
    p_ring: [u8; RING],
    /// The signed carrier axis of each step in `y_ring`, `s (cos phi, sin phi)`.
    a_ring: [AlphaBeta; RING],
    weights: [[f32; RING]; RING],
    /// The carrier's current predicted from the measured step (accumulated), its last
    /// `period` values, and the centred value of the last sample (module [`crate::hfi`],
    /// "Equations").
    tri: AlphaBeta,
    tri_ring: [AlphaBeta; RING],
    tri_centred: AlphaBeta,
    pos: u8,
    /// Consecutive accepted samples (saturating), consecutive demodulated steps.
    valid: u8,
    y_count: u8,
    last: Response,
}

impl Demodulator {
    /// `half` ticks per half period (already clamped), `inv_scale = 1 / (2 Ts V Y_d)`.
    pub fn new(half: u8, inv_scale: f32) -> Self {
        Self {
            period: 2 * half,
            inv_scale,
            i_prev: AlphaBeta::default(),
            i_ring: [AlphaBeta::default(); RING],
            y_ring: [Dq::default(); RING],
            p_ring: [0; RING],
            a_ring: [AlphaBeta::default(); RING],
            weights: ls_weights(half),
            tri: AlphaBeta::default(),
            tri_ring: [AlphaBeta::default(); RING],
            tri_centred: AlphaBeta::default(),
            pos: 0,
            valid: 0,
            y_count: 0,
            last: Response::default(),
        }
    }

    /// Clears the history: the first demodulation comes a full window after this.
    #[inline]
    pub fn clear(&mut self) {
        self.valid = 0;
        self.y_count = 0;
        self.last = Response::default();
        self.tri = AlphaBeta::default();
        self.tri_centred = AlphaBeta::default();
    }

    /// A sample was missing or refused: the history is rebuilt from the next one.
    #[inline]
    pub fn skip(&mut self) {
        self.valid = 0;
        self.y_count = 0;
    }

    /// The last demodulation.
    #[inline]
    pub fn response(&self) -> Response {
        self.last
    }

    /// The carrier's part of the last sample (alpha-beta, A).
    #[inline]
    pub fn carrier_current(&self) -> AlphaBeta {
        self.tri_centred
    }

    /// Takes the sample `i[k]` (alpha-beta, A) with the carrier `applied` over
    /// `[t_k-1, t_k)`: the response once a full window of steps is in, and the fundamental
    /// current (the mean of the last period's samples; `i[k]` alone until there is one).
    #[inline]
    pub fn update(&mut self, i: AlphaBeta, applied: Carrier) -> (Option<Response>, AlphaBeta) {
        let n = usize::from(self.period);
        let pos = usize::from(self.pos) % RING;
        // The carrier applied over [t_k-1, t_k): its current step, projected on its axis and
        // signed, is one demodulated step `y`.
        if self.valid >= 1 && applied.sign != 0.0 {
            let r = (i - self.i_prev).to_dq(applied.sin, applied.cos);
            self.y_ring[pos] = r * applied.sign;
            self.p_ring[pos] = applied.phase;
            self.a_ring[pos] = AlphaBeta {
                alpha: applied.sign * applied.cos,
                beta: applied.sign * applied.sin,
            };
            self.y_count = self.y_count.saturating_add(1);
        } else {
            self.y_count = 0;
        }
        // The carrier's own current: the last measured step along the applied axis,
        // accumulated with the applied sign, centred on its mean over a period.
        let step = Dq {
            d: self.last.d,
            q: self.last.q,
        }
        .to_alpha_beta(applied.sin, applied.cos);
        self.tri = self.tri + step * applied.sign;
        self.tri_ring[pos] = self.tri;
        // The sample a period ago (the oldest of the window, once the ring is full).
        let i_old = self.i_ring[pos];
        self.i_ring[pos] = i;
        self.i_prev = i;
        self.valid = self.valid.saturating_add(1);
        self.pos = ((pos + 1) % n) as u8;
        // Means over one carrier period: the fundamental current, and the step (the slope of
        // the fundamental cancels, the carrier's sign being balanced over a period).
        let fund = if usize::from(self.valid) >= n {
            let mut sum = AlphaBeta::default();
            let mut tri = AlphaBeta::default();
            for (x, t) in self.i_ring.iter().zip(&self.tri_ring).take(n) {
                sum = sum + *x;
                tri = tri + *t;
            }
            self.tri_centred = self.tri - tri * (1.0 / n as f32);
            sum * (1.0 / n as f32)
        } else {
            self.tri_centred = AlphaBeta::default();
            i
        };
        let resp = if usize::from(self.y_count) >= n {
            // The oldest step of the window is the one after the newest (written at `pos`).
            let p0 = usize::from((self.p_ring[pos] + 1) % self.period);
            let w = &self.weights[p0 % RING];
            let mut m = Dq::default();
            let mut axis = AlphaBeta::default();
            let steps = self.y_ring.iter().zip(&self.a_ring);
            for ((y, a), p) in steps.zip(&self.p_ring).take(n) {
                let wp = w[usize::from(*p) % RING];
                m = m + *y * wp;
                axis = axis + *a * wp;
            }
            // The fundamental's slope over the window, taken out in the fixed frame: each step
            // is projected on the axis its carrier was applied along, and that axis moves
            // within the window (the loop's correction every tick), so a slope constant in
            // alpha-beta is not constant in the steps and the weights would not cancel it
            // (module [`crate::hfi`], "Demodulation by least squares").
            let slope = (i - i_old) * (1.0 / n as f32);
            m.d -= slope.alpha * axis.alpha + slope.beta * axis.beta;
            m.q -= slope.beta * axis.alpha - slope.alpha * axis.beta;
            let eps = crate::pi::limit(m.q * self.inv_scale, -1.0, 1.0);
            self.last = Response {
                d: m.d,
                q: m.q,
                eps,
            };
            Some(self.last)
        } else {
            None
        };
        (resp, fund)
    }
}
