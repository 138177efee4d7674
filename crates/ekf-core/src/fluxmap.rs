//! Flux maps of a saturating machine: `psi_d(i_d, i_q)` and `psi_q(i_d, i_q)` on a current
//! grid, with an interpolation whose first derivatives (the incremental inductances) are
//! continuous (docs/design.md, "The motor as it physically is").
//!
//! # Model
//!
//! Rotor frame, magnet flux included in `psi_d`:
//!
//! ```text
//! u_d = Rs i_d + dpsi_d/dt - w psi_q        dpsi/dt = L_inc di/dt
//! u_q = Rs i_q + dpsi_q/dt + w psi_d        L_inc = [[dPsi_d/di_d, dPsi_d/di_q],
//! T   = 1.5 p (psi_d i_q - psi_q i_d)                [dPsi_q/di_d, dPsi_q/di_q]]
//! ```
//!
//! # Interpolation
//!
//! Bicubic Hermite on each cell of the grid. Each node stores the value and three slopes
//! (`df/di_d`, `df/di_q`, `d2f/di_d di_q`); the patch of a cell is the tensor product of the
//! cubic Hermite basis (`h00 = 2t^3 - 3t^2 + 1`, `h10 = t^3 - 2t^2 + t`, `h01 = 3t^2 - 2t^3`,
//! `h11 = t^3 - t^2`). Neighbouring cells share the values and slopes along their common
//! edge, so the surface and its first derivatives are continuous whatever slopes are stored.
//! The slopes are chosen shape-preserving along each axis: at inner nodes Brodlie's weighted
//! harmonic mean of the two adjacent secants (zero where they change sign), so a rising curve
//! is interpolated without the overshoot of plain three-point slopes; at the end nodes the
//! one-sided three-point slope, held within a third and three times the end secant where the
//! data keep their direction (an own-axis map keeps a positive incremental inductance at its
//! edge however hard it saturates). The cross slope is the three-point difference of
//! `df/di_d` along `i_q`. The accuracy is that of a local cubic: where a curve bends within a
//! cell, the slope is close to the secant over the neighbouring cells. On a map that
//! saturates over 8 A (the unit test's), a 4.2 A grid gives the flux within 0.2 % of the map's
//! span and the incremental `Lq` within 7.8 %; a 2.1 A grid 0.02 % and 2.1 %
//! (`cargo test -p ekf-core --lib fluxmap -- --nocapture`). Give points densely where the
//! curve bends.
//!
//! Cost: one evaluation (both fluxes and the four inductances) is 505 instructions on the
//! Cortex-M4F in `f32` on a 9 x 11 grid (`fluxmap_eval` of `bash scripts/qemu-firmware.sh`):
//! two 4 x 4 bilinear forms per map, an evenly spaced axis found by one multiplication (others
//! by bisection).
//!
//! Outside the grid the map continues linearly with the gradient of its nearest edge point
//! (value and first derivatives stay continuous at the edge): a drive that leaves the measured
//! range sees the last measured incremental inductances.
//!
//! # Bounds and checks
//!
//! The grid holds at most `N` points per axis (a const generic: no allocation; `N = 16` holds
//! a map of 16 x 16 points in 8 KiB of `f32`). [`FluxMap::new`] refuses, with a
//! [`FluxMapError`] naming the problem: axes of fewer than 2 or more than `N` points, arrays of
//! the wrong length, non-finite values, axes that do not strictly ascend, `psi_d` that does not
//! strictly rise with `i_d` (for every `i_q`) or `psi_q` with `i_q` (for every `i_d`), and an
//! incremental inductance matrix that is not positive definite at a node.

use crate::{Float, to_t};
use core::fmt;

/// Why a flux map was refused ([`FluxMap::new`]). Indices are grid indices (`d` along
/// `i_d`, `q` along `i_q`).
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum FluxMapError {
    /// An axis has fewer than 2 points.
    TooFewPoints {
        /// Points given.
        points: usize,
    },
    /// An axis has more points than the map holds.
    TooManyPoints {
        /// Points given.
        points: usize,
        /// Capacity per axis (`N`).
        capacity: usize,
    },
    /// A flux array does not have `n_d * n_q` entries.
    WrongLength {
        /// Which array (`"psi_d"` or `"psi_q"`).
        array: &'static str,
        /// Entries given.
        len: usize,
        /// Entries expected.
        expected: usize,
    },
    /// A value is NaN or infinite.
    NonFinite {
        /// Which array (`"i_d"`, `"i_q"`, `"psi_d"`, `"psi_q"`).
        array: &'static str,
        /// Flat index into it.
        index: usize,
    },
    /// An axis does not strictly ascend.
    NotAscending {
        /// Which axis (`"i_d"` or `"i_q"`).
        axis: &'static str,
        /// Index of the first point not above its predecessor.
        index: usize,
    },
    /// `psi_d` does not strictly rise with `i_d`, or `psi_q` with `i_q`.
    NotMonotonic {
        /// Which map (`"psi_d"` or `"psi_q"`).
        array: &'static str,
        /// Grid index along `i_d`.
        d: usize,
        /// Grid index along `i_q`.
        q: usize,
    },
    /// The incremental inductance matrix is not positive definite at a node.
    SingularInductance {
        /// Grid index along `i_d`.
        d: usize,
        /// Grid index along `i_q`.
        q: usize,
    },
}

impl fmt::Display for FluxMapError {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        match *self {
            Self::TooFewPoints { points } => {
                write!(f, "a current axis needs at least 2 points, has {points}")
            }
            Self::TooManyPoints { points, capacity } => write!(
                f,
                "a current axis has {points} points, more than the map holds ({capacity})"
            ),
            Self::WrongLength {
                array,
                len,
                expected,
            } => write!(
                f,
                "{array} has {len} entries, expected n_d x n_q = {expected}"
            ),
            Self::NonFinite { array, index } => {
                write!(f, "{array}[{index}] is not finite")
            }
            Self::NotAscending { axis, index } => write!(
                f,
                "{axis} must strictly ascend: point {index} is not above point {}",
                index - 1
            ),
            Self::NotMonotonic { array, d, q } => write!(
                f,
                "{array} must strictly rise along its own current: it does not between grid \
                 points (d {}, q {}) and (d {d}, q {q})",
                if array == "psi_d" { d - 1 } else { d },
                if array == "psi_d" { q } else { q - 1 },
            ),
            Self::SingularInductance { d, q } => write!(
                f,
                "the incremental inductance matrix is not positive definite at grid point \
                 (d {d}, q {q})"
            ),
        }
    }
}

impl core::error::Error for FluxMapError {}

/// The map's value at one operating point: fluxes (Wb) and incremental inductances (H).
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct FluxPoint<T> {
    /// d-axis flux linkage (magnet included), Wb.
    pub psi_d: T,
    /// q-axis flux linkage, Wb.
    pub psi_q: T,
    /// `dPsi_d / di_d`, H.
    pub l_dd: T,
    /// `dPsi_d / di_q`, H (cross saturation).
    pub l_dq: T,
    /// `dPsi_q / di_d`, H (cross saturation).
    pub l_qd: T,
    /// `dPsi_q / di_q`, H.
    pub l_qq: T,
}

impl<T: Float> FluxPoint<T> {
    /// Determinant of the incremental inductance matrix, H^2.
    pub fn det(&self) -> T {
        self.l_dd * self.l_qq - self.l_dq * self.l_qd
    }
}

/// A node of one map: value and slopes `[f, df/di_d, df/di_q, d2f/di_d di_q]`.
type Node<T> = [T; 4];

/// Flux maps on a current grid of at most `N x N` points (module docs).
#[derive(Clone, Debug, PartialEq)]
pub struct FluxMap<T, const N: usize> {
    n_d: usize,
    n_q: usize,
    i_d: [T; N],
    i_q: [T; N],
    /// `1 / (x_k+1 - x_k)` per cell of each axis.
    inv_h_d: [T; N],
    inv_h_q: [T; N],
    /// `1 / step` of an evenly spaced axis (cell found by one multiplication), else zero.
    even_d: T,
    even_q: T,
    psi_d: [[Node<T>; N]; N],
    psi_q: [[Node<T>; N]; N],
}

impl<T: Float, const N: usize> FluxMap<T, N> {
    /// A map from its grid: `i_d` (`n_d` points) and `i_q` (`n_q` points) ascending, A;
    /// `psi_d` and `psi_q` row-major `n_d x n_q` (`psi[d * n_q + q]` at `(i_d[d], i_q[q])`),
    /// Wb. Checks as the module docs list them.
    pub fn new(i_d: &[T], i_q: &[T], psi_d: &[T], psi_q: &[T]) -> Result<Self, FluxMapError> {
        let (n_d, n_q) = (i_d.len(), i_q.len());
        for (axis, v) in [("i_d", i_d), ("i_q", i_q)] {
            if v.len() < 2 {
                return Err(FluxMapError::TooFewPoints { points: v.len() });
            }
            if v.len() > N {
                return Err(FluxMapError::TooManyPoints {
                    points: v.len(),
                    capacity: N,
                });
            }
            finite(axis, v)?;
            if let Some(k) = (1..v.len()).find(|&k| v[k] <= v[k - 1]) {
                return Err(FluxMapError::NotAscending { axis, index: k });
            }
        }
        for (array, v) in [("psi_d", psi_d), ("psi_q", psi_q)] {
            if v.len() != n_d * n_q {
                return Err(FluxMapError::WrongLength {
                    array,
                    len: v.len(),
                    expected: n_d * n_q,
                });
            }
            finite(array, v)?;
        }
        for d in 0..n_d {
            for q in 0..n_q {
                if d > 0 && psi_d[d * n_q + q] <= psi_d[(d - 1) * n_q + q] {
                    return Err(FluxMapError::NotMonotonic {
                        array: "psi_d",
                        d,
                        q,
                    });
                }
                if q > 0 && psi_q[d * n_q + q] <= psi_q[d * n_q + q - 1] {
                    return Err(FluxMapError::NotMonotonic {
                        array: "psi_q",
                        d,
                        q,
                    });
                }
            }
        }
        let mut map = Self {
            n_d,
            n_q,
            i_d: [T::zero(); N],
            i_q: [T::zero(); N],
            inv_h_d: [T::zero(); N],
            inv_h_q: [T::zero(); N],
            even_d: T::zero(),
            even_q: T::zero(),
            psi_d: [[[T::zero(); 4]; N]; N],
            psi_q: [[[T::zero(); 4]; N]; N],
        };
        map.i_d[..n_d].copy_from_slice(i_d);
        map.i_q[..n_q].copy_from_slice(i_q);
        map.even_d = spacing(i_d, &mut map.inv_h_d);
        map.even_q = spacing(i_q, &mut map.inv_h_q);
        fill_nodes(&mut map.psi_d, &map.i_d[..n_d], &map.i_q[..n_q], psi_d);
        fill_nodes(&mut map.psi_q, &map.i_d[..n_d], &map.i_q[..n_q], psi_q);
        for d in 0..n_d {
            for q in 0..n_q {
                let (a, b) = (map.psi_d[d][q], map.psi_q[d][q]);
                let det = a[1] * b[2] - a[2] * b[1];
                let ok = a[1] > T::zero() && b[2] > T::zero() && det > T::zero();
                if !ok || !det.is_finite() {
                    return Err(FluxMapError::SingularInductance { d, q });
                }
            }
        }
        Ok(map)
    }

    /// Points along `i_d` and along `i_q`.
    pub fn shape(&self) -> (usize, usize) {
        (self.n_d, self.n_q)
    }

    /// The `i_d` axis, A.
    pub fn i_d_axis(&self) -> &[T] {
        &self.i_d[..self.n_d]
    }

    /// The `i_q` axis, A.
    pub fn i_q_axis(&self) -> &[T] {
        &self.i_q[..self.n_q]
    }

    /// Adds `delta_wb` to `psi_d` everywhere: the node values move, their slopes do not, and
    /// the bicubic Hermite interpolation (whose value basis sums to one) moves by
    /// `delta_wb` at every current; the inductances are unchanged (to rounding). A magnet whose flux
    /// changes (temperature) shifts `psi_d` so, to first order. No check: the caller keeps
    /// `delta_wb` finite ([`MapObserver::shift_psi_d`](crate::saturated::MapObserver::shift_psi_d)
    /// does).
    pub fn shift_psi_d(&mut self, delta_wb: T) {
        for row in self.psi_d.iter_mut().take(self.n_d) {
            for node in row.iter_mut().take(self.n_q) {
                node[0] += delta_wb;
            }
        }
    }

    /// Fluxes and incremental inductances at `(i_d, i_q)` (module docs: bicubic Hermite,
    /// linear continuation outside the grid). A non-finite current gives non-finite output.
    pub fn eval(&self, i_d: T, i_q: T) -> FluxPoint<T> {
        let (cd, xd, t) = locate(&self.i_d[..self.n_d], &self.inv_h_d, self.even_d, i_d);
        let (cq, xq, u) = locate(&self.i_q[..self.n_q], &self.inv_h_q, self.even_q, i_q);
        let (ihd, ihq) = (self.inv_h_d[cd], self.inv_h_q[cq]);
        // Basis along each axis, slopes scaled by the cell width (value, slope at the start;
        // value, slope at the end), and its derivative in the current.
        let (bt, gt) = basis(t, ihd);
        let (bu, gu) = basis(u, ihq);
        let (fd, gd_d, gd_q) = patch(&self.psi_d, cd, cq, &bt, &gt, &bu, &gu);
        let (fq, gq_d, gq_q) = patch(&self.psi_q, cd, cq, &bt, &gt, &bu, &gu);
        // Linear continuation outside the grid (zero inside).
        let ed = i_d - xd;
        let eq = i_q - xq;
        FluxPoint {
            psi_d: fd + gd_d * ed + gd_q * eq,
            psi_q: fq + gq_d * ed + gq_q * eq,
            l_dd: gd_d,
            l_dq: gd_q,
            l_qd: gq_d,
            l_qq: gq_q,
        }
    }

    /// The currents whose fluxes are `(psi_d, psi_q)`: Newton's method on the map from the
    /// guess `(i_d, i_q)` (e.g. the previous sample's currents), at most `iterations` steps,
    /// stopping when the flux residual is below `tol_wb`. `None` when it does not converge or
    /// meets a singular inductance matrix (a map accepted by [`FluxMap::new`] is invertible
    /// near its grid: its inductance matrix is positive definite at every node).
    pub fn currents(
        &self,
        psi_d: T,
        psi_q: T,
        guess: (T, T),
        iterations: u32,
        tol_wb: T,
    ) -> Option<(T, T)> {
        let (mut i_d, mut i_q) = guess;
        for _ in 0..iterations {
            let p = self.eval(i_d, i_q);
            let (rd, rq) = (psi_d - p.psi_d, psi_q - p.psi_q);
            if !(rd.is_finite() && rq.is_finite()) {
                return None;
            }
            if rd.abs() <= tol_wb && rq.abs() <= tol_wb {
                return Some((i_d, i_q));
            }
            let det = p.det();
            if det.partial_cmp(&T::zero()) != Some(core::cmp::Ordering::Greater) {
                return None;
            }
            i_d += (p.l_qq * rd - p.l_dq * rq) / det;
            i_q += (p.l_dd * rq - p.l_qd * rd) / det;
        }
        let p = self.eval(i_d, i_q);
        ((psi_d - p.psi_d).abs() <= tol_wb && (psi_q - p.psi_q).abs() <= tol_wb)
            .then_some((i_d, i_q))
    }

    /// Electromagnetic torque `1.5 p (psi_d i_q - psi_q i_d)`, N m.
    pub fn torque_nm(&self, pole_pairs: u32, i_d: T, i_q: T) -> T {
        let p = self.eval(i_d, i_q);
        to_t::<T>(1.5) * to_t::<T>(f64::from(pole_pairs)) * (p.psi_d * i_q - p.psi_q * i_d)
    }
}

fn finite<T: Float>(array: &'static str, v: &[T]) -> Result<(), FluxMapError> {
    match v.iter().position(|x| !x.is_finite()) {
        Some(index) => Err(FluxMapError::NonFinite { array, index }),
        None => Ok(()),
    }
}

/// The inverse widths of the cells of `axis` into `inv`; returns `1 / step` when the axis is
/// evenly spaced (every width within 1e-5 of the first, relative), else zero.
fn spacing<T: Float>(axis: &[T], inv: &mut [T]) -> T {
    let h0 = axis[1] - axis[0];
    let mut even = true;
    for k in 0..axis.len() - 1 {
        let h = axis[k + 1] - axis[k];
        inv[k] = T::one() / h;
        even &= (h - h0).abs() <= to_t::<T>(1e-5) * h0;
    }
    if even {
        to_t::<T>((axis.len() - 1) as f64) / (axis[axis.len() - 1] - axis[0])
    } else {
        T::zero()
    }
}

/// The cell `[x_k, x_k+1]` holding `x` (the first or last cell outside the axis), `x` clamped
/// to the axis, and the position `t` in `[0, 1]` within the cell. An evenly spaced axis finds
/// the cell by one multiplication, others by bisection.
#[inline]
fn locate<T: Float>(axis: &[T], inv_h: &[T], even: T, x: T) -> (usize, T, T) {
    let n = axis.len();
    let (first, last) = (axis[0], axis[n - 1]);
    let xc = if x < first {
        first
    } else if x > last {
        last
    } else {
        x
    };
    let k = if even > T::zero() {
        // A NaN gives cell 0 (then t is NaN, and so is the output).
        ((xc - first) * even).trunc_index().min(n - 2)
    } else {
        let (mut lo, mut hi) = (0usize, n - 1);
        while hi - lo > 1 {
            let mid = (lo + hi) / 2;
            if axis[mid] <= xc {
                lo = mid;
            } else {
                hi = mid;
            }
        }
        lo
    };
    let t = ((xc - axis[k]) * inv_h[k]).clamp(T::zero(), T::one());
    (k, if xc.is_finite() { xc } else { x }, t)
}

/// The cubic Hermite basis at `t` with the slope terms scaled by the cell width
/// (`[h00, h10 h, h01, h11 h]`), and its derivative in the current
/// (`[h00' / h, h10', h01' / h, h11']`), for a cell of inverse width `inv_h`.
#[inline]
fn basis<T: Float>(t: T, inv_h: T) -> ([T; 4], [T; 4]) {
    let (two, three) = (to_t::<T>(2.0), to_t::<T>(3.0));
    let t2 = t * t;
    let t3 = t2 * t;
    let h = T::one() / inv_h;
    let h01 = three * t2 - two * t3;
    let h00 = T::one() - h01;
    let h10 = (t3 - two * t2 + t) * h;
    let h11 = (t3 - t2) * h;
    let six = to_t::<T>(6.0);
    let d01 = (six * t - six * t2) * inv_h;
    let d10 = three * t2 - to_t::<T>(4.0) * t + T::one();
    let d11 = three * t2 - two * t;
    ([h00, h10, h01, h11], [-d01, d10, d01, d11])
}

/// Value and gradient `(f, df/di_d, df/di_q)` of one map on cell `(cd, cq)`: with the node
/// terms arranged as the 4 x 4 matrix `C` (rows: value and d-slope at the cell's two
/// `i_d` ends; columns: value and q-slope at its two `i_q` ends), `f = bt C bu`,
/// `df/di_d = gt C bu`, `df/di_q = bt C gu`.
#[inline]
fn patch<T: Float, const N: usize>(
    nodes: &[[Node<T>; N]; N],
    cd: usize,
    cq: usize,
    bt: &[T; 4],
    gt: &[T; 4],
    bu: &[T; 4],
    gu: &[T; 4],
) -> (T, T, T) {
    let (a, b) = (&nodes[cd], &nodes[cd + 1]);
    let (n00, n01, n10, n11) = (&a[cq], &a[cq + 1], &b[cq], &b[cq + 1]);
    // C bu and C gu, row by row (rows: value, d-slope at the start; value, d-slope at the end).
    let row = |x: &Node<T>, y: &Node<T>, v: usize, s: usize| {
        (
            x[v] * bu[0] + x[s] * bu[1] + y[v] * bu[2] + y[s] * bu[3],
            x[v] * gu[0] + x[s] * gu[1] + y[v] * gu[2] + y[s] * gu[3],
        )
    };
    let (w0, u0) = row(n00, n01, 0, 2);
    let (w1, u1) = row(n00, n01, 1, 3);
    let (w2, u2) = row(n10, n11, 0, 2);
    let (w3, u3) = row(n10, n11, 1, 3);
    let f = bt[0] * w0 + bt[1] * w1 + bt[2] * w2 + bt[3] * w3;
    let f_d = gt[0] * w0 + gt[1] * w1 + gt[2] * w2 + gt[3] * w3;
    let f_q = bt[0] * u0 + bt[1] * u1 + bt[2] * u2 + bt[3] * u3;
    (f, f_d, f_q)
}

/// Shape-preserving slopes of `y(x)` (module docs) into `m`.
fn slopes<T: Float>(x: &[T], y: &[T], m: &mut [T]) {
    let n = x.len();
    let sec = |k: usize| (y[k + 1] - y[k]) / (x[k + 1] - x[k]);
    if n == 2 {
        m[0] = sec(0);
        m[1] = sec(0);
        return;
    }
    let (two, three) = (to_t::<T>(2.0), to_t::<T>(3.0));
    for k in 1..n - 1 {
        let (d0, d1) = (sec(k - 1), sec(k));
        let (h0, h1) = (x[k] - x[k - 1], x[k + 1] - x[k]);
        m[k] = if d0 * d1 > T::zero() {
            let (w1, w2) = (two * h1 + h0, h1 + two * h0);
            (w1 + w2) / (w1 / d0 + w2 / d1)
        } else {
            T::zero()
        };
    }
    // One-sided three-point ends. Where the data keep their direction near the end, the
    // slope is held within [1/3, 3] times the end secant (an own-axis flux map keeps a
    // positive incremental inductance at its edge however hard it saturates); elsewhere it
    // is zeroed on a sign change and limited to 3 times the secant (Fritsch-Carlson).
    let third = T::one() / three;
    let end = |h0: T, h1: T, d0: T, d1: T| {
        let m = ((two * h0 + h1) * d0 - h0 * d1) / (h0 + h1);
        if d0 * d1 > T::zero() {
            (m / d0).clamp(third, three) * d0
        } else if m * d0 <= T::zero() {
            T::zero()
        } else if m.abs() > (three * d0).abs() {
            three * d0
        } else {
            m
        }
    };
    m[0] = end(x[1] - x[0], x[2] - x[1], sec(0), sec(1));
    m[n - 1] = end(
        x[n - 1] - x[n - 2],
        x[n - 2] - x[n - 3],
        sec(n - 2),
        sec(n - 3),
    );
}

/// Three-point derivative of `y(x)` at every point (non-uniform grid) into `m`.
fn differences<T: Float>(x: &[T], y: &[T], m: &mut [T]) {
    let n = x.len();
    let sec = |k: usize| (y[k + 1] - y[k]) / (x[k + 1] - x[k]);
    if n == 2 {
        m[0] = sec(0);
        m[1] = sec(0);
        return;
    }
    for k in 1..n - 1 {
        let (h0, h1) = (x[k] - x[k - 1], x[k + 1] - x[k]);
        m[k] = (h1 * sec(k - 1) + h0 * sec(k)) / (h0 + h1);
    }
    m[0] = sec(0);
    m[n - 1] = sec(n - 2);
}

/// Values and slopes of one map at every node.
fn fill_nodes<T: Float, const N: usize>(
    nodes: &mut [[Node<T>; N]; N],
    i_d: &[T],
    i_q: &[T],
    psi: &[T],
) {
    let (n_d, n_q) = (i_d.len(), i_q.len());
    let mut col = [T::zero(); N];
    let mut m = [T::zero(); N];
    for d in 0..n_d {
        // Along i_q (a row of the row-major array).
        slopes(i_q, &psi[d * n_q..(d + 1) * n_q], &mut m[..n_q]);
        for q in 0..n_q {
            nodes[d][q][0] = psi[d * n_q + q];
            nodes[d][q][2] = m[q];
        }
    }
    for q in 0..n_q {
        for d in 0..n_d {
            col[d] = psi[d * n_q + q];
        }
        slopes(i_d, &col[..n_d], &mut m[..n_d]);
        for d in 0..n_d {
            nodes[d][q][1] = m[d];
        }
    }
    for row in nodes.iter_mut().take(n_d) {
        for (c, node) in col.iter_mut().zip(row.iter()).take(n_q) {
            *c = node[1];
        }
        differences(i_q, &col[..n_q], &mut m[..n_q]);
        for (node, &slope) in row.iter_mut().zip(m.iter()).take(n_q) {
            node[3] = slope;
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    /// A saturating map with cross saturation, the gradient of a coenergy (so `l_dq == l_qd`):
    /// `W = 0.2 i_d + 3 F(i_d / 10) + 5.12 F(i_q / 8) - c (i_d + 30)^2 i_q^2 / 2`,
    /// `F(x) = x atan x - ln(1 + x^2) / 2`.
    fn sample(i_d: f64, i_q: f64) -> (f64, f64) {
        let c = 2e-7;
        let psi_d = 0.2 + 0.3 * (i_d / 10.0).atan() - c * (i_d + 30.0) * i_q * i_q;
        let psi_q = 0.64 * (i_q / 8.0).atan() - c * (i_d + 30.0).powi(2) * i_q;
        (psi_d, psi_q)
    }

    fn grid(n_d: usize, n_q: usize) -> (Vec<f64>, Vec<f64>, Vec<f64>, Vec<f64>) {
        let i_d: Vec<f64> = (0..n_d)
            .map(|k| -20.0 + 25.0 * k as f64 / (n_d - 1) as f64)
            .collect();
        let i_q: Vec<f64> = (0..n_q)
            .map(|k| -25.0 + 50.0 * k as f64 / (n_q - 1) as f64)
            .collect();
        let mut pd = vec![];
        let mut pq = vec![];
        for &d in &i_d {
            for &q in &i_q {
                let (a, b) = sample(d, q);
                pd.push(a);
                pq.push(b);
            }
        }
        (i_d, i_q, pd, pq)
    }

    /// The test map on an `n_d x n_q` grid, in `f32`.
    fn f32_map<const N: usize>(n_d: usize, n_q: usize) -> FluxMap<f32, N> {
        let (i_d, i_q, pd, pq) = grid(n_d, n_q);
        let f = |v: &[f64]| v.iter().map(|&x| x as f32).collect::<Vec<_>>();
        FluxMap::new(&f(&i_d), &f(&i_q), &f(&pd), &f(&pq)).unwrap()
    }

    /// Worst flux error (Wb) and worst relative `l_qq` error between the nodes of a grid.
    fn interpolation_errors(n_d: usize, n_q: usize) -> (f64, f64) {
        let (i_d, i_q, pd, pq) = grid(n_d, n_q);
        let map = FluxMap::<f64, 32>::new(&i_d, &i_q, &pd, &pq).unwrap();
        let (mut flux, mut l) = (0.0f64, 0.0f64);
        for k in 0..2000 {
            let d = -19.9 + 24.8 * (k as f64 * 0.618_034).fract();
            let q = -24.9 + 49.8 * (k as f64 * 0.377_123).fract();
            let p = map.eval(d, q);
            let (td, tq) = sample(d, q);
            flux = flux.max((p.psi_d - td).abs()).max((p.psi_q - tq).abs());
            let h = 1e-5;
            let l_qq = (sample(d, q + h).1 - sample(d, q - h).1) / (2.0 * h);
            l = l.max((p.l_qq - l_qq).abs() / l_qq);
        }
        (flux, l)
    }

    #[test]
    fn a_shift_moves_psi_d_alone_everywhere() {
        let (i_d, i_q, pd, pq) = grid(11, 13);
        let map = FluxMap::<f64, 16>::new(&i_d, &i_q, &pd, &pq).unwrap();
        let mut shifted = map.clone();
        shifted.shift_psi_d(0.0123);
        for k in 0..500 {
            // Inside the grid and beyond it (the linear continuation).
            let d = -30.0 + 45.0 * (k as f64 * 0.618_034).fract();
            let q = -35.0 + 70.0 * (k as f64 * 0.377_123).fract();
            let (a, b) = (map.eval(d, q), shifted.eval(d, q));
            assert!((b.psi_d - a.psi_d - 0.0123).abs() < 1e-12, "{d} {q}");
            // The inductances to rounding (the value basis's derivative sums to zero).
            assert_eq!(b.psi_q, a.psi_q);
            for (x, y) in [
                (b.l_dd, a.l_dd),
                (b.l_dq, a.l_dq),
                (b.l_qd, a.l_qd),
                (b.l_qq, a.l_qq),
            ] {
                assert!((x - y).abs() < 1e-12, "{d} {q}");
            }
        }
    }

    #[test]
    fn reproduces_nodes_and_interpolates_smoothly() {
        let (i_d, i_q, pd, pq) = grid(11, 13);
        let map = FluxMap::<f64, 16>::new(&i_d, &i_q, &pd, &pq).unwrap();
        for (a, &d) in i_d.iter().enumerate() {
            for (b, &q) in i_q.iter().enumerate() {
                let p = map.eval(d, q);
                assert!((p.psi_d - pd[a * 13 + b]).abs() < 1e-15);
                assert!((p.psi_q - pq[a * 13 + b]).abs() < 1e-15);
            }
        }
        // The map spans about 1.6 Wb (psi_q over +-25 A); 4.2 A and 2.1 A steps along i_q.
        let coarse = interpolation_errors(11, 13);
        let fine = interpolation_errors(11, 25);
        println!("flux map interpolation: 11 x 13 {coarse:?}, 11 x 25 {fine:?}");
        assert!(coarse.0 < 4e-3 && coarse.1 < 0.085, "{coarse:?}");
        assert!(fine.0 < 5e-4 && fine.1 < 0.025, "{fine:?}");
    }

    #[test]
    fn derivatives_are_the_slopes_of_the_surface_and_continuous() {
        let (i_d, i_q, pd, pq) = grid(6, 7);
        let map = FluxMap::<f64, 8>::new(&i_d, &i_q, &pd, &pq).unwrap();
        let h = 1e-6;
        for &(d, q) in &[(-13.0, 4.0), (i_d[2], i_q[3]), (-20.0, -25.0), (7.0, 30.0)] {
            let p = map.eval(d, q);
            let num_dd = (map.eval(d + h, q).psi_d - map.eval(d - h, q).psi_d) / (2.0 * h);
            let num_qd = (map.eval(d + h, q).psi_q - map.eval(d - h, q).psi_q) / (2.0 * h);
            let num_dq = (map.eval(d, q + h).psi_d - map.eval(d, q - h).psi_d) / (2.0 * h);
            let num_qq = (map.eval(d, q + h).psi_q - map.eval(d, q - h).psi_q) / (2.0 * h);
            for (a, b) in [
                (p.l_dd, num_dd),
                (p.l_qd, num_qd),
                (p.l_dq, num_dq),
                (p.l_qq, num_qq),
            ] {
                assert!((a - b).abs() < 1e-6, "({d}, {q}): {a} vs {b}");
            }
        }
        // Across a cell edge the slopes agree from both sides.
        let e = i_d[3];
        let (l, r) = (map.eval(e - 1e-9, 2.0), map.eval(e + 1e-9, 2.0));
        assert!((l.l_dd - r.l_dd).abs() < 1e-6 && (l.l_qq - r.l_qq).abs() < 1e-6);
    }

    #[test]
    fn inverse_finds_the_currents() {
        let map = f32_map::<12>(9, 9);
        for &(d, q) in &[(-10.0f32, 12.0f32), (3.0, -20.0), (-25.0, 28.0)] {
            let p = map.eval(d, q);
            let (a, b) = map
                .currents(p.psi_d, p.psi_q, (0.0, 0.0), 20, 1e-6)
                .unwrap();
            assert!((a - d).abs() < 2e-3 && (b - q).abs() < 2e-3, "{a} {b}");
        }
        assert!(map.currents(f32::NAN, 0.0, (0.0, 0.0), 20, 1e-6).is_none());
    }

    #[test]
    fn refuses_bad_maps_naming_the_problem() {
        let (i_d, i_q, pd, pq) = grid(4, 5);
        type M = FluxMap<f64, 4>;
        assert!(matches!(
            M::new(&[0.0], &i_q[..4], &pd, &pq),
            Err(FluxMapError::TooFewPoints { points: 1 })
        ));
        assert!(matches!(
            M::new(&i_d, &i_q, &pd, &pq),
            Err(FluxMapError::TooManyPoints {
                points: 5,
                capacity: 4
            })
        ));
        let ok = FluxMap::<f64, 8>::new(&i_d, &i_q, &pd, &pq);
        assert!(ok.is_ok(), "{ok:?}");
        let e = FluxMap::<f64, 8>::new(&i_d, &i_q, &pd[..19], &pq).unwrap_err();
        assert_eq!(
            e,
            FluxMapError::WrongLength {
                array: "psi_d",
                len: 19,
                expected: 20
            }
        );
        let mut bad = pq.clone();
        bad[7] = f64::NAN;
        assert_eq!(
            FluxMap::<f64, 8>::new(&i_d, &i_q, &pd, &bad).unwrap_err(),
            FluxMapError::NonFinite {
                array: "psi_q",
                index: 7
            }
        );
        let mut axis = i_q.clone();
        axis[3] = axis[2];
        assert_eq!(
            FluxMap::<f64, 8>::new(&i_d, &axis, &pd, &pq).unwrap_err(),
            FluxMapError::NotAscending {
                axis: "i_q",
                index: 3
            }
        );
        let mut flat = pd.clone();
        flat[2 * 5 + 1] = flat[5 + 1];
        let e = FluxMap::<f64, 8>::new(&i_d, &i_q, &flat, &pq).unwrap_err();
        assert_eq!(
            e,
            FluxMapError::NotMonotonic {
                array: "psi_d",
                d: 2,
                q: 1
            }
        );
        assert!(e.to_string().contains("(d 1, q 1) and (d 2, q 1)"), "{e}");
        // Cross saturation so strong that L_inc is not positive definite.
        let mut cross = pq.clone();
        for d in 0..4 {
            for q in 0..5 {
                cross[d * 5 + q] += 5.0 * i_d[d];
            }
        }
        let mut pd2 = pd.clone();
        for d in 0..4 {
            for q in 0..5 {
                pd2[d * 5 + q] += 5.0 * i_q[q];
            }
        }
        assert!(matches!(
            FluxMap::<f64, 8>::new(&i_d, &i_q, &pd2, &cross),
            Err(FluxMapError::SingularInductance { .. })
        ));
    }

    #[test]
    fn constant_inductances_are_reproduced_exactly() {
        // A linear map (constant Ld, Lq): the interpolation is exact everywhere.
        let i_d = [-10.0, -4.0, 0.0, 3.0];
        let i_q = [-8.0, 0.0, 2.0, 8.0, 9.0];
        let (ld, lq, psi) = (0.03, 0.042, 0.5);
        let mut pd = vec![];
        let mut pq = vec![];
        for &d in &i_d {
            for &q in &i_q {
                pd.push(psi + ld * d);
                pq.push(lq * q);
            }
        }
        let map = FluxMap::<f64, 6>::new(&i_d, &i_q, &pd, &pq).unwrap();
        for &(d, q) in &[(-7.3, 1.1), (2.5, 8.7), (-30.0, 40.0)] {
            let p = map.eval(d, q);
            assert!((p.psi_d - (psi + ld * d)).abs() < 1e-12);
            assert!((p.psi_q - lq * q).abs() < 1e-12);
            assert!((p.l_dd - ld).abs() < 1e-12 && (p.l_qq - lq).abs() < 1e-12);
            assert!(p.l_dq.abs() < 1e-12 && p.l_qd.abs() < 1e-12);
        }
        assert!((map.torque_nm(3, 0.0, 10.0) - 1.5 * 3.0 * 0.5 * 10.0).abs() < 1e-12);
    }

    #[test]
    fn non_finite_currents_give_non_finite_output_without_panic() {
        let map = f32_map::<8>(5, 6);
        for x in [f32::NAN, f32::INFINITY, f32::NEG_INFINITY] {
            assert!(!map.eval(x, 1.0).psi_d.is_finite());
            assert!(!map.eval(1.0, x).psi_q.is_finite());
        }
        // Far outside the grid: the edge's gradient, continued.
        let edge = map.eval(5.0, 25.0);
        let far = map.eval(1e6, 25.0);
        assert_eq!(far.l_dd, edge.l_dd);
        assert!(far.psi_d > edge.psi_d);
    }
}
