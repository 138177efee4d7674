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

use super::PmsmModel;
use super::model::{Discrete, TransitionTerms};
use crate::ekf::{Correction, CovarianceUpdate, EkfError, finite};
use crate::{Float, to_t, wrap_angle};

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
        // Halved before the sum: no overflow near `MAX`.
        let s = |r: usize, c: usize| m[(r, c)] * h + m[(c, r)] * h;
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

    /// `p00 + p11 + p22 + p33`.
    pub(crate) fn trace(&self) -> T {
        (self.p00 + self.p11) + (self.p22 + self.p33)
    }

    /// `T P T` with `T = diag(1, 1, -1, 1)`: the covariance after the speed's sign is flipped
    /// (the entries coupling the speed with another state change sign).
    pub(crate) fn flip_speed(self) -> Self {
        Self {
            p02: -self.p02,
            p12: -self.p12,
            p23: -self.p23,
            ..self
        }
    }

    pub(crate) fn all_finite(&self) -> bool {
        finite(&[
            self.p00, self.p01, self.p02, self.p03, self.p11, self.p12, self.p13, self.p22,
            self.p23, self.p33,
        ])
    }
}

/// Structured prediction: `(x-, P-)` from the posterior `(x, P)` and the input held over the
/// period, with the step's constants `disc` and the process noise `q`; also the EMF terms
/// (the Jacobian's blocks). `trusted`: the angle is tracked, so a salient motor's d-axis
/// transient correction applies (observer module docs). Values are not checked here.
#[inline(always)]
pub(crate) fn predict<T: Float, const S: bool>(
    disc: &Discrete<T>,
    q: &Matrix4<T>,
    x: &Vector4<T>,
    p: &Sym4<T>,
    u: [T; 2],
    trusted: bool,
) -> (Vector4<T>, Sym4<T>, TransitionTerms<T>) {
    let (ia, ib, w, th) = (x[0], x[1], x[2], x[3]);
    let t = disc.transition_terms::<S>(ia, ib, th, w, u, trusted);
    let d = disc.decay;
    let g = disc.input_gain;
    let ts = disc.ts;
    let xn = Vector4::new(
        if S {
            d * ia + g * u[0] + t.ea + t.da
        } else {
            d * ia + g * u[0] + t.ea
        },
        if S {
            d * ib + g * u[1] + t.eb + t.db
        } else {
            d * ib + g * u[1] + t.eb
        },
        w,
        wrap_angle(th + ts * w),
    );
    if S {
        return (xn, predict_cov_salient(&t, ts, q, p), t);
    }
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
    let q = *q;
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
    (xn, pn, t)
}

/// `P- = Phi P Phi^T + Q` for a salient motor, whose current block of `Phi` is a full 2 x 2
/// (`a00..a11` of the terms) instead of `decay I`; otherwise the schedule of [`predict`].
#[inline(always)]
pub(crate) fn predict_cov_salient<T: Float>(
    t: &TransitionTerms<T>,
    ts: T,
    q: &Matrix4<T>,
    p: &Sym4<T>,
) -> Sym4<T> {
    let (a00, a01, a10, a11) = (t.a00, t.a01, t.a10, t.a11);
    let (j00, j01, j10, j11) = (t.ea_w, t.ea_th, t.eb_w, t.eb_th);
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
    // T = A Pix + J Pxx
    let t00 = a00 * p02 + a01 * p12 + j00 * p22 + j01 * p23;
    let t01 = a00 * p03 + a01 * p13 + j00 * p23 + j01 * p33;
    let t10 = a10 * p02 + a11 * p12 + j10 * p22 + j11 * p23;
    let t11 = a10 * p03 + a11 * p13 + j10 * p23 + j11 * p33;
    // U = A Pii + J Pix^T
    let u00 = a00 * p00 + a01 * p01 + j00 * p02 + j01 * p03;
    let u01 = a00 * p01 + a01 * p11 + j00 * p12 + j01 * p13;
    let u10 = a10 * p00 + a11 * p01 + j10 * p02 + j11 * p03;
    let u11 = a10 * p01 + a11 * p11 + j10 * p12 + j11 * p13;
    let half: T = to_t(0.5);
    let n01 = u00 * a10 + u01 * a11 + t00 * j10 + t01 * j11;
    let n10 = u10 * a00 + u11 * a01 + t10 * j00 + t11 * j01;
    let mc10 = ts * p22 + p23;
    Sym4 {
        p00: u00 * a00 + u01 * a01 + t00 * j00 + t01 * j01 + q[(0, 0)],
        p01: (n01 + n10) * half + q[(0, 1)],
        p02: t00 + q[(0, 2)],
        p03: t00 * ts + t01 + q[(0, 3)],
        p11: u10 * a10 + u11 * a11 + t10 * j10 + t11 * j11 + q[(1, 1)],
        p12: t10 + q[(1, 2)],
        p13: t10 * ts + t11 + q[(1, 3)],
        p22: p22 + q[(2, 2)],
        p23: p22 * ts + p23 + q[(2, 3)],
        p33: mc10 * ts + ts * p23 + p33 + q[(3, 3)],
    }
}

/// The sum of the values, finite only when they all are: NaN and infinities propagate
/// through a sum (and, conservatively, finite values so large that their sum overflows make
/// it infinite). One test instead of one per value; four partial sums keep the dependency
/// chain short. The partial sums start from the first values, not from zero (`0 + x` is not
/// folded: `-0 + 0` is `+0`), so `N - 1` additions in all (`N >= 4`).
#[inline(always)]
pub(crate) fn check_sum<T: Float, const N: usize>(v: &[T; N]) -> T {
    const { assert!(N >= 4, "check_sum takes at least 4 values") };
    let mut acc = [v[0], v[1], v[2], v[3]];
    for (i, x) in v.iter().enumerate().skip(4) {
        acc[i % 4] += *x;
    }
    (acc[0] + acc[1]) + (acc[2] + acc[3])
}

/// Result of a correction.
pub(crate) struct Posterior<T: Float> {
    /// Posterior state.
    pub x: Vector4<T>,
    /// Posterior covariance.
    pub p: Sym4<T>,
    /// Innovation, its covariance, NIS.
    pub correction: Correction<T, 2>,
    /// The angle correction `K_th y` (rad, before wrapping) the update added to the prior.
    pub dth: T,
    /// `S^-1` as `(i00, i01, i11)` (for the tracked parameters' gain).
    pub inv_s: (T, T, T),
    /// The gain `K` (rows `i_a, i_b, w, th`).
    pub k: [[T; 2]; 4],
    /// [`check_sum`] of the results (state, NIS, `P`): finite when they all are. Checked by
    /// [`correct`]; [`correct_unchecked`]'s caller checks it.
    pub sum: T,
}

/// What [`correct`] did.
pub(crate) enum Outcome<T: Float> {
    /// The update was applied.
    Updated(Posterior<T>),
    /// The caller's gate refused the sample after seeing its NIS: no update, only the
    /// diagnostics (innovation, `S`, NIS).
    Skipped(Correction<T, 2>),
}

/// Structured correction: `(x, P, diagnostics, angle correction)` from the prior `(x-, P-)`
/// and the sampled currents; an error when `S` is not positive definite or a result is not
/// finite. `skip(nis)` is asked once the NIS is known, before the update is computed; `true`
/// skips the update ([`Outcome::Skipped`]).
#[inline(always)]
pub(crate) fn correct<T: Float>(
    model: &PmsmModel<T>,
    x: &Vector4<T>,
    p: &Sym4<T>,
    z: [T; 2],
    skip: impl FnOnce(T) -> bool,
) -> Result<Outcome<T>, EkfError> {
    match correct_unchecked(model, x, p, z, skip) {
        Ok(Outcome::Updated(post)) if !post.sum.is_finite() => Err(EkfError::NonFiniteResult),
        r => r,
    }
}

/// [`correct`] without the finiteness check of the results: the caller tests
/// [`Posterior::sum`] (with its own values' test: one branch for both).
#[inline(always)]
pub(crate) fn correct_unchecked<T: Float>(
    model: &PmsmModel<T>,
    x: &Vector4<T>,
    p: &Sym4<T>,
    z: [T; 2],
    skip: impl FnOnce(T) -> bool,
) -> Result<Outcome<T>, EkfError> {
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
    let r = *model.r_sym();
    let (r00, r01, r11) = (r[(0, 0)], r[(0, 1)], r[(1, 1)]);
    let (s00, s01, s11) = (p00 + r00, p01 + r01, p11 + r11);
    let det = s00 * s11 - s01 * s01;
    let inv_det = T::one() / det;
    // `det` finite and positive, tested as `det > 0` and `1 / det > 0` (`+inf` has the inverse
    // 0, NaN fails both): two comparisons of the FPU instead of a classification of the bits.
    if !(det > T::zero() && inv_det > T::zero()) {
        return Err(EkfError::SingularInnovation);
    }
    let (i00, i01, i11) = (s11 * inv_det, -s01 * inv_det, s00 * inv_det);
    let y0 = z[0] - x[0];
    let y1 = z[1] - x[1];
    let nis = i00 * y0 * y0 + (i01 + i01) * y0 * y1 + i11 * y1 * y1;
    let correction = Correction {
        innovation: Vector2::new(y0, y1),
        innovation_covariance: Matrix2::new(s00, s01, s01, s11),
        nis,
    };
    if skip(nis) {
        return Ok(Outcome::Skipped(correction));
    }
    // K = L S^-1, L = first two columns of P- (rows 0..3).
    let k = |l0: T, l1: T| (l0 * i00 + l1 * i01, l0 * i01 + l1 * i11);
    let (k00, k01) = k(p00, p01);
    let (k10, k11) = k(p01, p11);
    let (k20, k21) = k(p02, p12);
    let (k30, k31) = k(p03, p13);
    // The angle correction for the branch check; the state update below keeps the seed's
    // order of operations, `(th + k30 y0) + k31 y1` (bit-identical to the seed reference).
    let dth = k30 * y0 + k31 * y1;
    let xn = Vector4::new(
        x[0] + k00 * y0 + k01 * y1,
        x[1] + k10 * y0 + k11 * y1,
        x[2] + k20 * y0 + k21 * y1,
        wrap_angle(x[3] + k30 * y0 + k31 * y1),
    );
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
            (s00, s01, s11),
        ),
    };
    let sum = check_sum(&[
        xn[0], xn[1], xn[2], xn[3], nis, pn.p00, pn.p01, pn.p02, pn.p03, pn.p11, pn.p12, pn.p13,
        pn.p22, pn.p23, pn.p33,
    ]);
    Ok(Outcome::Updated(Posterior {
        x: xn,
        p: pn,
        correction,
        dth,
        inv_s: (i00, i01, i11),
        k: [[k00, k01], [k10, k11], [k20, k21], [k30, k31]],
        sum,
    }))
}

/// Joseph form on 2 x 2 blocks (module docs), written out on scalars: `E = I - K1`,
/// `TL = E A E^T + K1 R K1^T`, `TR = E (B - A K2^T) + K1 R K2^T`,
/// `BR = C - K2 B - (K2 B)^T + K2 S K2^T` with `S = A + R`. Only the upper triangle is formed.
#[inline(always)]
fn joseph<T: Float>(p: &Sym4<T>, k: [[T; 2]; 4], r: (T, T, T), s: (T, T, T)) -> Sym4<T> {
    let (a00, a01, a11) = (p.p00, p.p01, p.p11);
    let (b00, b01, b10, b11) = (p.p02, p.p03, p.p12, p.p13);
    let (r00, r01, r11) = r;
    let (s00, s01, s11) = s;
    let [[k00, k01], [k10, k11], [k20, k21], [k30, k31]] = k;
    let one = T::one();
    let (e00, e01, e10, e11) = (one - k00, -k01, -k10, one - k11);
    // E A
    let (ea00, ea01) = (e00 * a00 + e01 * a01, e00 * a01 + e01 * a11);
    let (ea10, ea11) = (e10 * a00 + e11 * a01, e10 * a01 + e11 * a11);
    // K1 R
    let (kr00, kr01) = (k00 * r00 + k01 * r01, k00 * r01 + k01 * r11);
    let (kr10, kr11) = (k10 * r00 + k11 * r01, k10 * r01 + k11 * r11);
    // B - A K2^T
    let d00 = b00 - (a00 * k20 + a01 * k21);
    let d01 = b01 - (a00 * k30 + a01 * k31);
    let d10 = b10 - (a01 * k20 + a11 * k21);
    let d11 = b11 - (a01 * k30 + a11 * k31);
    // K2 B
    let kb00 = k20 * b00 + k21 * b10;
    let kb01 = k20 * b01 + k21 * b11;
    let kb10 = k30 * b00 + k31 * b10;
    let kb11 = k30 * b01 + k31 * b11;
    // K2 S
    let (ks00, ks01) = (k20 * s00 + k21 * s01, k20 * s01 + k21 * s11);
    let (ks10, ks11) = (k30 * s00 + k31 * s01, k30 * s01 + k31 * s11);
    Sym4 {
        p00: ea00 * e00 + ea01 * e01 + kr00 * k00 + kr01 * k01,
        p01: ea00 * e10 + ea01 * e11 + kr00 * k10 + kr01 * k11,
        p11: ea10 * e10 + ea11 * e11 + kr10 * k10 + kr11 * k11,
        p02: e00 * d00 + e01 * d10 + kr00 * k20 + kr01 * k21,
        p03: e00 * d01 + e01 * d11 + kr00 * k30 + kr01 * k31,
        p12: e10 * d00 + e11 * d10 + kr10 * k20 + kr11 * k21,
        p13: e10 * d01 + e11 * d11 + kr10 * k30 + kr11 * k31,
        p22: p.p22 - (kb00 + kb00) + ks00 * k20 + ks01 * k21,
        p23: p.p23 - kb01 - kb10 + ks00 * k30 + ks01 * k31,
        p33: p.p33 - (kb11 + kb11) + ks10 * k30 + ks11 * k31,
    }
}
