//! The grid's samples: a q crossing's record, and the whole grid moved from the d currents
//! the crossings happened at to the d levels (module docs of `saturation`, "cross
//! saturation").

use super::{SAT_MAX_D, SAT_MAX_Q, SaturationProbe, State};

/// Grid of one flux component, `[d][q]`, Wb.
type Grid = [[f32; SAT_MAX_Q]; SAT_MAX_D];

/// Passes of the fixed-point correction (the d current strays a few per cent of a level's
/// spacing: two passes settle it to float precision).
const PASSES: usize = 3;

impl SaturationProbe {
    /// Where the current of `axis` (0: d, 1: q) crossed `level` between the last tick and
    /// this one: the fluxes `(psi_d, psi_q)` and the d current there, each interpolated in
    /// that current by [`interpolate`] over the last three ticks.
    pub(super) fn at_crossing(&self, axis: usize, level: f32) -> ([f32; 2], f32) {
        let x = self.i_hist.map(|i| i[axis & 1]);
        let y = |f: &dyn Fn(usize) -> f32| interpolate(level, x, [f(0), f(1), f(2)]);
        (
            [y(&|m| self.psi_hist[m][0]), y(&|m| self.psi_hist[m][1])],
            y(&|m| self.i_hist[m][0]),
        )
    }

    /// A q crossing of level `j` at the d bias in progress: both fluxes and the d current at
    /// the crossing.
    pub(super) fn record(&mut self, j: usize, level: f32) {
        let State::QPulse(k, _) = self.state else {
            return;
        };
        let ([psi_d, psi_q], i_d) = self.at_crossing(1, level);
        let (Some(pq), Some(pd), Some(at)) = (
            self.out.psi_q.get_mut(k).and_then(|r| r.get_mut(j)),
            self.out.psi_d.get_mut(k).and_then(|r| r.get_mut(j)),
            self.i_d_at.get_mut(k).and_then(|r| r.get_mut(j)),
        ) else {
            return;
        };
        *pq = psi_q;
        *pd = psi_d;
        *at = i_d;
    }

    /// The end of the q pulse at level `k`: the zero-q column is the d curve's sample, at
    /// the level itself, `psi_q = 0` (a symmetric machine).
    pub(super) fn finish_level(&mut self, k: usize) {
        let mid = (self.cfg.n_q - 1) / 2;
        let level = self.cfg.i_d_level(k);
        if let (Some(pq), Some(at)) = (
            self.out.psi_q.get_mut(k).and_then(|r| r.get_mut(mid)),
            self.i_d_at.get_mut(k).and_then(|r| r.get_mut(mid)),
        ) {
            *pq = 0.0;
            *at = level;
        }
    }

    /// Every sample moved from the d current of its crossing `i_d,x` to its level `i_dk`
    /// along the measured grid's own d slopes at that node:
    ///
    /// `psi_d(i_dk, i_qj) = psi_d,x + L_dd (i_dk - i_d,x)`,
    /// `psi_q(i_dk, i_qj) = psi_q,x + L_qd (i_dk - i_d,x)`,
    ///
    /// `L_dd = dpsi_d/di_d`, `L_qd = dpsi_q/di_d` by central differences over the d levels
    /// (one-sided at the grid's edges) of the corrected grid, to a fixed point. The q pulse
    /// changes the d flux (cross saturation) faster than the d loop holds `i_d`, so the
    /// crossings happen a fraction of an ampere off the level; where the motor's `L_qd` is
    /// large (high `|i_q|`) that alone biases `|psi_q|` low by up to the stray times `L_qd`.
    pub(super) fn finish_grid(&mut self) {
        let (n_d, n_q) = (self.cfg.n_d, self.cfg.n_q);
        let (raw_d, raw_q) = (self.out.psi_d, self.out.psi_q);
        for _ in 0..PASSES {
            let (cur_d, cur_q) = (self.out.psi_d, self.out.psi_q);
            for k in 0..n_d {
                let lo = k.saturating_sub(1);
                let hi = (k + 1).min(n_d - 1);
                let span = self.out.i_d[hi] - self.out.i_d[lo];
                let level = self.out.i_d[k];
                for j in 0..n_q {
                    let stray = level - self.i_d_at[k][j];
                    let slope = |g: &Grid| (g[hi][j] - g[lo][j]) / span;
                    self.out.psi_d[k][j] = raw_d[k][j] + slope(&cur_d) * stray;
                    self.out.psi_q[k][j] = raw_q[k][j] + slope(&cur_q) * stray;
                }
            }
        }
    }
}

/// `y` at `x = level`, `level` between `x[1]` and `x[2]` (the last two ticks): the parabola
/// through the three points when the current moved the same way over both intervals and the
/// earlier one is not much shorter (`|x1 - x0| >= |x2 - x1| / 4`), else the straight line
/// through the last two. The flux is a curved function of the current where the motor
/// saturates, and a pulse moves the current by up to an ampere or two per tick: the straight
/// line's chord error, `psi'' dx^2 / 8`, reached tenths of a per cent of the flux.
pub(super) fn interpolate(level: f32, x: [f32; 3], y: [f32; 3]) -> f32 {
    let [x0, x1, x2] = x;
    let [y0, y1, y2] = y;
    let (h0, h1) = (x1 - x0, x2 - x1);
    if h1 == 0.0 {
        return y2;
    }
    let f = ((level - x1) / h1).clamp(0.0, 1.0);
    let line = y1 + f * (y2 - y1);
    if !(h0 * h1 > 0.0 && h0.abs() >= 0.25 * h1.abs()) {
        return line;
    }
    let l = x1 + f * h1;
    // Newton's form: the line plus the second divided difference's term.
    let d01 = (y1 - y0) / h0;
    let d12 = (y2 - y1) / h1;
    let d012 = (d12 - d01) / (x2 - x0);
    line + d012 * (l - x1) * (l - x2)
}

#[cfg(test)]
mod tests {
    use super::super::integral::mean_current;
    use super::interpolate;

    /// A parabola is interpolated exactly; a reversal of the current falls back to the line.
    #[test]
    fn a_parabola_is_exact_and_a_reversal_is_a_line() {
        let f = |x: f32| 0.3 + 0.02 * x + 0.004 * x * x;
        let x = [1.0, 2.5, 4.0];
        let y = x.map(f);
        assert!((interpolate(3.1, x, y) - f(3.1)).abs() < 1e-6);
        let x = [3.0, 2.5, 4.0];
        let y = x.map(f);
        let line = y[1] + (3.1 - 2.5) / 1.5 * (y[2] - y[1]);
        assert!((interpolate(3.1, x, y) - line).abs() < 1e-6);
    }

    /// The mean of a current that is a parabola in the flux, the flux linear in time: exact,
    /// where the trapezoidal rule is off by `h^2 f'' / 12`.
    #[test]
    fn the_mean_current_follows_the_curvature() {
        let f = |p: f32| 2.0 * p + 30.0 * p * p;
        let psi = [0.10f32, 0.12, 0.14];
        let i = psi.map(f);
        // Mean of f over [0.12, 0.14].
        let (a, b) = (0.12f32, 0.14f32);
        let exact = (b * b - a * a) + 10.0 * (b * b * b - a * a * a);
        let exact = exact / (b - a);
        let m = mean_current(psi.map(|p| [p, 0.0]), i.map(|c| [c, 0.0]));
        assert!((m[0] - exact).abs() < 1e-5, "{} {exact}", m[0]);
        let trap = 0.5 * (i[1] + i[2]);
        assert!((trap - exact).abs() > 5e-4);
        // Three fluxes nearly equal: the trapezoidal mean.
        let psi = [0.1200f32, 0.12, 0.14];
        let m = mean_current(psi.map(|p| [p, 0.0]), i.map(|c| [c, 0.0]));
        assert_eq!(m[0], trap);
    }
}
