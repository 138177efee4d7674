//! Sine and cosine for the filter's angles, in the filter's own precision.
//!
//! Without `std`, `f32::sin_cos` in `nalgebra` goes to `libm::sincosf`, which computes in `f64`
//! (musl's design): on a Cortex-M4F, whose FPU is single precision only, that is software
//! floating point, about 2250 instructions per call. [`sin_cos_f32`] stays in `f32`, with no
//! branch for `|x| <= 32` (the observer's angles are wrapped to `[-pi, pi)`):
//!
//! ```text
//! k = round(x 2/pi)   (adding and subtracting 1.5 * 2^23; k mod 4 read from the sum's bits)
//! r = (x - k A) - k B,  A + B = pi/2   (Cody-Waite, k A exact)          |r| <= pi/4
//! sin r = r + r^3 (S1 + r^2 (S2 + r^2 S3))                minimax, truncation < 2.5e-9
//! cos r = 1 + r^2 (-1/2 + r^2 (C2 + r^2 (C3 + r^2 C4)))    minimax, truncation < 5e-10
//! (sin x, cos x) = (sin r, cos r) rotated by k quarter turns (a 4-entry table of 0, +-1: exact)
//! ```
//!
//! Maximum error against `f64` sin/cos: below 1e-7 for `|x| <= 8 pi` (measured 6.0e-8 on
//! a grid of 400 001 points, `tests::matches_f64_within_1e_7`), i.e. about one ulp. Larger
//! arguments are wrapped to `[-pi, pi)` first (a cold path). A non-finite argument gives NaN
//! (the filter then rejects the step); nothing panics.

use crate::{Float, to_t, wrap_angle};

/// `pi/2` in two parts: the first has 8 significant bits, so `k * PIO2_A` is exact for
/// `|k| < 2^16`; the second is the rest rounded to `f32` (`pi/2 - A - B = 2.6e-12`).
const PIO2_A: f32 = 1.570_312_5;
const PIO2_B: f32 = 4.838_268e-4;

/// `1.5 * 2^23`: `q + ROUND` rounds `q` (`|q| < 2^22`) to the nearest integer (ties to even),
/// held in the low bits of the sum's mantissa, and `(q + ROUND) - ROUND` is that integer.
const ROUND: f32 = 12_582_912.0;

/// Minimax kernels on `[-pi/4, pi/4]` (coefficients as rounded to `f32`):
/// `sin r = r + r^3 (S1 + r^2 (S2 + r^2 S3))` (truncation 2.5e-9) and
/// `cos r = 1 + r^2 (-1/2 + r^2 (C2 + r^2 (C3 + r^2 C4)))` (truncation 4.8e-10).
const S1: f32 = -0.166_666_51;
const S2: f32 = 0.008_331_979;
const S3: f32 = -0.000_194_956_36;
const C2: f32 = 0.041_666_646;
const C3: f32 = -0.001_388_736_4;
const C4: f32 = 2.443_808_6e-5;

/// `f32` bits of `|x| = 32` shifted left by one (the sign out): arguments up to this size are
/// reduced directly, larger ones (and non-finite ones) go to the cold path.
const DIRECT_LIMIT_BITS: u32 = 0x4200_0000 << 1;

/// `(cos k pi/2, sin k pi/2)` for `k mod 4`: the quadrant's exact rotation.
const QUADRANT: [(f32, f32); 4] = [(1.0, 0.0), (0.0, 1.0), (-1.0, 0.0), (0.0, -1.0)];

/// `(sin x, cos x)` in pure `f32` arithmetic (module docs give method and error).
#[inline]
pub fn sin_cos_f32(x: f32) -> (f32, f32) {
    // One integer comparison: `|x| <= 32`, false for NaN and infinities.
    if x.to_bits() << 1 > DIRECT_LIMIT_BITS {
        return sin_cos_far(x);
    }
    sin_cos_reduced(x)
}

/// Large or non-finite arguments: wrapped to `[-pi, pi)` first; NaN for NaN and infinities.
#[cold]
#[inline(never)]
fn sin_cos_far(x: f32) -> (f32, f32) {
    if !x.is_finite() {
        return (f32::NAN, f32::NAN);
    }
    sin_cos_reduced(wrap_angle(x))
}

/// The kernel for `|x| <= 32` (module docs): no branch.
#[inline(always)]
fn sin_cos_reduced(x: f32) -> (f32, f32) {
    let t = x * core::f32::consts::FRAC_2_PI + ROUND;
    let kf = t - ROUND;
    // The low bits of `t`'s mantissa are `k` (two's complement, the offset 2^22 is 0 mod 4).
    let quadrant = (t.to_bits() & 3) as usize;
    // x - k A is exact (k A is, and Sterbenz); k B is rounded.
    let r = (x - kf * PIO2_A) - kf * PIO2_B;
    let r2 = r * r;
    let s = r + (r * r2) * (S1 + r2 * (S2 + r2 * S3));
    let c = 1.0 + r2 * (-0.5 + r2 * (C2 + r2 * (C3 + r2 * C4)));
    // Rotate by k quarter turns; the products with 0 and +-1 are exact.
    let (qc, qs) = QUADRANT[quadrant];
    (s * qc + c * qs, c * qc - s * qs)
}

/// `(sin x, cos x)` for a small angle (a half-step rotation `w Ts / 2`, an inverse-Park advance
/// `1.5 w Ts`): Taylor series in `x^2` for `|x| < 0.5`, no range reduction;
/// [`Float::sin_cos_angle`] otherwise. In `f64` the series runs through `x^15` / `x^16`
/// (truncation below 3e-20); in `f32` through `x^7` / `x^8` (below 6e-9, under `f32` rounding).
/// A NaN argument gives NaN.
#[inline(always)]
pub fn sin_cos_small<T: Float>(x: T) -> (T, T) {
    if x.abs() >= to_t(0.5) {
        return x.sin_cos_angle();
    }
    let x2 = x * x;
    let c = |v: f64| -> T { to_t(v) };
    let single = T::default_epsilon() > to_t(1e-10);
    // Horner in x^2 with coefficients (-1)^n / (2n+1)! and (-1)^n / (2n)!; the f64 tails are
    // folded away at compile time for f32.
    let (s_tail, c_tail) = if single {
        (T::zero(), T::zero())
    } else {
        (
            x2 * (c(1.0 / 362_880.0)
                + x2 * (c(-1.0 / 39_916_800.0)
                    + x2 * (c(1.0 / 6_227_020_800.0) + x2 * c(-1.0 / 1_307_674_368_000.0)))),
            x2 * (c(-1.0 / 3_628_800.0)
                + x2 * (c(1.0 / 479_001_600.0)
                    + x2 * (c(-1.0 / 87_178_291_200.0) + x2 * c(1.0 / 20_922_789_888_000.0)))),
        )
    };
    let s = x
        * (T::one()
            + x2 * (c(-1.0 / 6.0) + x2 * (c(1.0 / 120.0) + x2 * (c(-1.0 / 5040.0) + s_tail))));
    let co = T::one()
        + x2 * (c(-0.5)
            + x2 * (c(1.0 / 24.0) + x2 * (c(-1.0 / 720.0) + x2 * (c(1.0 / 40_320.0) + c_tail))));
    (s, co)
}

#[cfg(test)]
mod tests {
    use super::sin_cos_f32;

    #[test]
    fn matches_f64_within_1_2e_7() {
        let mut worst = 0.0f64;
        for i in -200_000..=200_000 {
            let x = i as f32 * (8.0 * core::f32::consts::PI / 200_000.0);
            let (s, c) = sin_cos_f32(x);
            let xd = f64::from(x);
            worst = worst
                .max((f64::from(s) - xd.sin()).abs())
                .max((f64::from(c) - xd.cos()).abs());
        }
        assert!(worst < 1.2e-7, "max error {worst:e}");
        // Large arguments are wrapped first; results stay on the unit circle.
        for x in [1e3f32, -7.7e4, 3.0e7, f32::MAX] {
            let (s, c) = sin_cos_f32(x);
            assert!((s * s + c * c - 1.0).abs() < 1e-6, "{x}: {s} {c}");
        }
        assert!(sin_cos_f32(f32::NAN).0.is_nan());
    }

    /// Max abs error against `f64` on dense grids: `[-pi, pi]` (the observer's angles, 2 * 10^6
    /// points) and the whole direct range `[-32, 32]` (4 * 10^6 points), also on the unit
    /// circle; plus every `f32` near the quadrant boundaries `k pi/4`.
    #[test]
    fn matches_f64_within_1e_7() {
        let err = |x: f32| {
            let (s, c) = sin_cos_f32(x);
            let xd = f64::from(x);
            let e = (f64::from(s) - xd.sin())
                .abs()
                .max((f64::from(c) - xd.cos()).abs());
            let norm = (f64::from(s).powi(2) + f64::from(c).powi(2) - 1.0).abs();
            (e, norm)
        };
        let mut worst = (0.0f64, 0.0f64);
        let mut take = |x: f32| {
            let (e, n) = err(x);
            worst = (worst.0.max(e), worst.1.max(n));
        };
        for i in -1_000_000..=1_000_000 {
            take(i as f32 * (core::f32::consts::PI / 1_000_000.0));
        }
        for i in -2_000_000..=2_000_000 {
            take(i as f32 * (32.0 / 2_000_000.0));
        }
        for k in -40..=40 {
            let mut x = k as f32 * core::f32::consts::FRAC_PI_4;
            for _ in 0..64 {
                x = x.next_down();
            }
            for _ in 0..128 {
                take(x);
                x = x.next_up();
            }
        }
        println!(
            "sin_cos_f32: max abs error {:e}, max |s^2 + c^2 - 1| {:e}",
            worst.0, worst.1
        );
        assert!(worst.0 < 1e-7, "max error {:e}", worst.0);
        assert!(worst.1 < 2.5e-7, "off the unit circle by {:e}", worst.1);
        // Non-finite in, NaN out (both); the far path wraps and keeps the accuracy.
        for x in [f32::NAN, f32::INFINITY, f32::NEG_INFINITY, -f32::NAN] {
            let (s, c) = sin_cos_f32(x);
            assert!(s.is_nan() && c.is_nan(), "{x}: {s} {c}");
        }
        for x in [32.5f32, -40.0, 1e4, -3.3e5] {
            let (s, c) = sin_cos_f32(x);
            let w = f64::from(super::wrap_angle(x));
            assert!((f64::from(s) - w.sin()).abs() < 1e-7, "{x}");
            assert!((f64::from(c) - w.cos()).abs() < 1e-7, "{x}");
        }
    }

    #[test]
    fn small_angle_series_matches_sin_cos() {
        let mut worst64 = 0.0f64;
        let mut worst32 = 0.0f64;
        for i in -1000..=1000 {
            let x = i as f64 * 7e-4; // up to +-0.7: series and fallback
            let (s, c) = super::sin_cos_small(x);
            worst64 = worst64.max((s - x.sin()).abs()).max((c - x.cos()).abs());
            let xf = x as f32;
            let (s, c) = super::sin_cos_small(xf);
            let xd = f64::from(xf);
            worst32 = worst32
                .max((f64::from(s) - xd.sin()).abs())
                .max((f64::from(c) - xd.cos()).abs());
        }
        assert!(worst64 < 4e-16, "f64 series error {worst64:e}");
        assert!(worst32 < 1.2e-7, "f32 series error {worst32:e}");
        assert!(super::sin_cos_small(f64::NAN).0.is_nan());
        assert!(sin_cos_f32(f32::INFINITY).1.is_nan());
    }
}
