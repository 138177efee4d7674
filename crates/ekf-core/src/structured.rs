//! Hand-scheduled predict and correct for the PMSM observer.
//!
//! Same equations as the generic [`Ekf`](crate::Ekf) with [`PmsmModel`], written out on the
//! 10 unique entries of the symmetric `P` and on the structure of the model:
//!
//! ```text
//! Phi = [ d I2   J ]     J = [ a1 a2 ]    M = [ 1  0 ]     H = [ I2 0 ]
//!       [ 0      M ]         [ b1 b2 ]        [ Ts 1 ]
//!
//! P = [ A   B ]   (A: currents, C: [w, th], 2 x 2 blocks)
//!     [ B^T C ]
//!
//! predict:  T = d B + J C,  U = d A + J B^T
//!           P- = [ U d + T J^T    T M^T   ] + Q
//!                [      .       M C M^T   ]
//! correct:  S = A- + R (2 x 2, inverted in closed form),  L = P- H^T (first two columns)
//!           K = L S^-1,  x = x- + K (z - x-_{0,1}),  NIS = y^T S^-1 y
//!           standard:  P = P- - K L^T
//!           Joseph:    E = I - K1,  K = [K1; K2]
//!                      P = [ E A E^T + K1 R K1^T     E (B - A K2^T) + K1 R K2^T         ]
//!                          [        .                C - K2 B - (K2 B)^T + K2 (A + R) K2^T ]
//! ```
//!
//! The sine and cosine of the angle are computed once per prediction. The results equal the
//! generic filter's to rounding (tested in `tests/structured.rs`). Nothing here panics.

use nalgebra::{Matrix2, Matrix4, Vector2, Vector4};

use crate::ekf::{Correction, CovarianceUpdate, EkfError, finite};
use crate::{Float, PmsmModel, to_t, wrap_angle};

/// The 10 unique entries of a symmetric 4 x 4 matrix.
#[derive(Clone, Copy, Debug, PartialEq)]
pub(crate) struct Sym4<T> {
    pub p00: T,
    pub p01: T,
    pub p02: T,
    pub p03: T,
    pub p11: T,
    pub p12: T,
    pub p13: T,
    pub p22: T,
    pub p23: T,
    pub p33: T,
}

impl<T: Float> Sym4<T> {
    /// Reads the upper triangle after forcing symmetry, `(m + m^T) / 2`.
    pub(crate) fn from_matrix(m: &Matrix4<T>) -> Self {
        let h: T = to_t(0.5);
        let s = |r: usize, c: usize| (m[(r, c)] + m[(c, r)]) * h;
        Self {
            p00: m[(0, 0)],
            p01: s(0, 1),
            p02: s(0, 2),
            p03: s(0, 3),
            p11: m[(1, 1)],
            p12: s(1, 2),
            p13: s(1, 3),
            p22: m[(2, 2)],
            p23: s(2, 3),
            p33: m[(3, 3)],
        }
    }

    #[rustfmt::skip]
    pub(crate) fn to_matrix(self) -> Matrix4<T> {
        let Self { p00, p01, p02, p03, p11, p12, p13, p22, p23, p33 } = self;
        Matrix4::new(
            p00, p01, p02, p03,
            p01, p11, p12, p13,
            p02, p12, p22, p23,
            p03, p13, p23, p33,
        )
    }

    pub(crate) fn all_finite(&self) -> bool {
        finite(&[
            self.p00, self.p01, self.p02, self.p03, self.p11, self.p12, self.p13, self.p22,
            self.p23, self.p33,
        ])
    }
}

/// Structured prediction: `(x-, P-)` from the posterior `(x, P)` and the input held over the
/// period. Values are not checked here.
#[inline]
pub(crate) fn predict<T: Float>(
    model: &PmsmModel<T>,
    x: &Vector4<T>,
    p: &Sym4<T>,
    u: [T; 2],
) -> (Vector4<T>, Sym4<T>) {
    let (ia, ib, w, th) = (x[0], x[1], x[2], x[3]);
    let t = model.transition_terms(th, w);
    let d = model.decay();
    let g = model.input_gain();
    let ts = model.ts();
    let xn = Vector4::new(
        d * ia + g * u[0] + t.ea,
        d * ib + g * u[1] + t.eb,
        w,
        wrap_angle(th + ts * w),
    );
    let (a1, a2, b1, b2) = (t.ea_w, t.ea_th, t.eb_w, t.eb_th);
    let Sym4 {
        p00,
        p01,
        p02,
        p03,
        p11,
        p12,
        p13,
        p22,
        p23,
        p33,
    } = *p;
    // T = d B + J C
    let t00 = d * p02 + a1 * p22 + a2 * p23;
    let t01 = d * p03 + a1 * p23 + a2 * p33;
    let t10 = d * p12 + b1 * p22 + b2 * p23;
    let t11 = d * p13 + b1 * p23 + b2 * p33;
    // U = d A + J B^T
    let u00 = d * p00 + a1 * p02 + a2 * p03;
    let u01 = d * p01 + a1 * p12 + a2 * p13;
    let u10 = d * p01 + b1 * p02 + b2 * p03;
    let u11 = d * p11 + b1 * p12 + b2 * p13;
    let q = model.q_sym();
    let half: T = to_t(0.5);
    let n01 = d * u01 + t00 * b1 + t01 * b2;
    let n10 = d * u10 + t10 * a1 + t11 * a2;
    let mc10 = ts * p22 + p23;
    let pn = Sym4 {
        p00: d * u00 + t00 * a1 + t01 * a2 + q[(0, 0)],
        p01: (n01 + n10) * half + q[(0, 1)],
        p02: t00 + q[(0, 2)],
        p03: t00 * ts + t01 + q[(0, 3)],
        p11: d * u11 + t10 * b1 + t11 * b2 + q[(1, 1)],
        p12: t10 + q[(1, 2)],
        p13: t10 * ts + t11 + q[(1, 3)],
        p22: p22 + q[(2, 2)],
        p23: p22 * ts + p23 + q[(2, 3)],
        p33: mc10 * ts + ts * p23 + p33 + q[(3, 3)],
    };
    (xn, pn)
}

/// Result of a correction: state, covariance and diagnostics.
pub(crate) type Posterior<T> = (Vector4<T>, Sym4<T>, Correction<T, 2>);

/// Structured correction: `(x, P, diagnostics)` from the prior `(x-, P-)` and the sampled
/// currents; an error when `S` is not positive definite or a result is not finite.
#[inline]
pub(crate) fn correct<T: Float>(
    model: &PmsmModel<T>,
    x: &Vector4<T>,
    p: &Sym4<T>,
    z: [T; 2],
) -> Result<Posterior<T>, EkfError> {
    let Sym4 {
        p00,
        p01,
        p02,
        p03,
        p11,
        p12,
        p13,
        p22,
        p23,
        p33,
    } = *p;
    let r = model.r_sym();
    let (r00, r01, r11) = (r[(0, 0)], r[(0, 1)], r[(1, 1)]);
    let (s00, s01, s11) = (p00 + r00, p01 + r01, p11 + r11);
    let det = s00 * s11 - s01 * s01;
    if !(det.is_finite() && det > T::zero()) {
        return Err(EkfError::SingularInnovation);
    }
    let inv_det = T::one() / det;
    let (i00, i01, i11) = (s11 * inv_det, -s01 * inv_det, s00 * inv_det);
    // K = L S^-1, L = first two columns of P- (rows 0..3).
    let k = |l0: T, l1: T| (l0 * i00 + l1 * i01, l0 * i01 + l1 * i11);
    let (k00, k01) = k(p00, p01);
    let (k10, k11) = k(p01, p11);
    let (k20, k21) = k(p02, p12);
    let (k30, k31) = k(p03, p13);
    let y0 = z[0] - x[0];
    let y1 = z[1] - x[1];
    let xn = Vector4::new(
        x[0] + k00 * y0 + k01 * y1,
        x[1] + k10 * y0 + k11 * y1,
        x[2] + k20 * y0 + k21 * y1,
        wrap_angle(x[3] + k30 * y0 + k31 * y1),
    );
    let nis = i00 * y0 * y0 + (i01 + i01) * y0 * y1 + i11 * y1 * y1;
    let pn = match model.covariance_update() {
        CovarianceUpdate::StandardSymmetrized => {
            // P - K L^T, L rows (p_r0, p_r1).
            let kl = |kr0: T, kr1: T, lc0: T, lc1: T| kr0 * lc0 + kr1 * lc1;
            let half: T = to_t(0.5);
            let sym = |a: T, b: T| (a + b) * half;
            Sym4 {
                p00: p00 - kl(k00, k01, p00, p01),
                p01: p01 - sym(kl(k00, k01, p01, p11), kl(k10, k11, p00, p01)),
                p02: p02 - sym(kl(k00, k01, p02, p12), kl(k20, k21, p00, p01)),
                p03: p03 - sym(kl(k00, k01, p03, p13), kl(k30, k31, p00, p01)),
                p11: p11 - kl(k10, k11, p01, p11),
                p12: p12 - sym(kl(k10, k11, p02, p12), kl(k20, k21, p01, p11)),
                p13: p13 - sym(kl(k10, k11, p03, p13), kl(k30, k31, p01, p11)),
                p22: p22 - kl(k20, k21, p02, p12),
                p23: p23 - sym(kl(k20, k21, p03, p13), kl(k30, k31, p02, p12)),
                p33: p33 - kl(k30, k31, p03, p13),
            }
        }
        CovarianceUpdate::Joseph => joseph(
            p,
            [[k00, k01], [k10, k11], [k20, k21], [k30, k31]],
            (r00, r01, r11),
        ),
    };
    if !(finite(&[xn[0], xn[1], xn[2], xn[3], nis]) && pn.all_finite()) {
        return Err(EkfError::NonFiniteResult);
    }
    let correction = Correction {
        innovation: Vector2::new(y0, y1),
        innovation_covariance: Matrix2::new(s00, s01, s01, s11),
        nis,
    };
    Ok((xn, pn, correction))
}

/// Joseph form on 2 x 2 blocks (module docs), symmetric by construction of the upper triangle
/// with the off-diagonal blocks averaged as the generic filter's forced symmetry does.
fn joseph<T: Float>(p: &Sym4<T>, k: [[T; 2]; 4], r: (T, T, T)) -> Sym4<T> {
    let half: T = to_t(0.5);
    let (r00, r01, r11) = r;
    // A, B, C blocks.
    let a = Matrix2::new(p.p00, p.p01, p.p01, p.p11);
    let b = Matrix2::new(p.p02, p.p03, p.p12, p.p13);
    let c = Matrix2::new(p.p22, p.p23, p.p23, p.p33);
    let rm = Matrix2::new(r00, r01, r01, r11);
    let k1 = Matrix2::new(k[0][0], k[0][1], k[1][0], k[1][1]);
    let k2 = Matrix2::new(k[2][0], k[2][1], k[3][0], k[3][1]);
    let e = Matrix2::identity() - k1;
    let k1r = k1 * rm;
    let tl = e * a * e.transpose() + k1r * k1.transpose();
    let tr = e * (b - a * k2.transpose()) + k1r * k2.transpose();
    let k2b = k2 * b;
    let br = c - k2b - k2b.transpose() + k2 * (a + rm) * k2.transpose();
    Sym4 {
        p00: tl[(0, 0)],
        p01: (tl[(0, 1)] + tl[(1, 0)]) * half,
        p02: tr[(0, 0)],
        p03: tr[(0, 1)],
        p11: tl[(1, 1)],
        p12: tr[(1, 0)],
        p13: tr[(1, 1)],
        p22: br[(0, 0)],
        p23: (br[(0, 1)] + br[(1, 0)]) * half,
        p33: br[(1, 1)],
    }
}
