//! Linear least squares by Givens rotations (the inertia fit's solver).

use crate::trig::sqrt;

/// Linear least squares with `N` regressors, updated one row at a time by Givens rotations
/// (the square-root information form: the triangular `R` and `z = Q^T y` of the QR
/// factorization of the rows so far; Golub & Van Loan, "Matrix Computations", sec. 5.1.8 and
/// 6.5.3). The normal equations are never formed, so `f32` holds the accuracy of a fit over
/// thousands of rows whose columns are close to dependent.
#[derive(Clone, Copy, Debug, PartialEq)]
pub(super) struct Lsq<const N: usize> {
    /// `N x N` upper triangular factor.
    r: [[f32; N]; N],
    /// `Q^T y`, `N`.
    z: [f32; N],
}

impl<const N: usize> Lsq<N> {
    pub(super) fn new() -> Self {
        Self {
            r: [[0.0; N]; N],
            z: [0.0; N],
        }
    }

    /// Adds the row `x . beta = y`.
    #[inline]
    pub(super) fn add(&mut self, mut x: [f32; N], mut y: f32) {
        for (i, (row, zi)) in self.r.iter_mut().zip(self.z.iter_mut()).enumerate() {
            let xi = x.get(i).copied().unwrap_or(0.0);
            if xi == 0.0 {
                continue;
            }
            let rii = row.get(i).copied().unwrap_or(0.0);
            let h = sqrt(rii * rii + xi * xi);
            let (c, s) = (rii / h, xi / h);
            for (rj, xj) in row.iter_mut().zip(x.iter_mut()).skip(i) {
                let (a, b) = (*rj, *xj);
                *rj = c * a + s * b;
                *xj = c * b - s * a;
            }
            let (a, b) = (*zi, y);
            *zi = c * a + s * b;
            y = c * b - s * a;
        }
    }

    /// `beta` minimizing `|X beta - y|` (back substitution), `None` when `R` is singular: a
    /// diagonal element below `1e-5` of the largest (a column that is, to `f32` rounding, a
    /// combination of the ones before it).
    #[inline]
    pub(super) fn solve(&self) -> Option<[f32; N]> {
        let tol = 1e-5
            * self
                .r
                .iter()
                .enumerate()
                .map(|(i, row)| row.get(i).map_or(0.0, |d| d.abs()))
                .fold(0.0f32, f32::max);
        let mut beta = [0.0f32; N];
        for i in (0..N).rev() {
            let row = self.r.get(i)?;
            let mut acc = *self.z.get(i)?;
            for (rj, bj) in row.iter().zip(beta.iter()).skip(i + 1) {
                acc -= rj * bj;
            }
            let d = *row.get(i)?;
            let b = acc / d;
            if !(d.abs() > tol && b.is_finite()) {
                return None;
            }
            *beta.get_mut(i)? = b;
        }
        Some(beta)
    }
}
