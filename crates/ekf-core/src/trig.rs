//! Sine and cosine for the filter's angles, in the filter's own precision.
//!
//! Without `std`, `f32::sin_cos` in `nalgebra` goes to `libm::sincosf`, which computes in `f64`
//! (musl's design): on a Cortex-M4F, whose FPU is single precision only, that is software
//! floating point, about 2250 instructions per call. [`sin_cos_f32`] stays in `f32`:
//!
//! ```text
//! k = round(x 2/pi),  r = x - k pi/2   (pi/2 in three parts, Cody-Waite, exact for |k| < 2^8)
//! sin r = r - r^3/3! + r^5/5! - r^7/7! + r^9/9!        |r| <= pi/4: truncation < 2e-9
//! cos r = 1 - r^2/2! + r^4/4! - r^6/6! + r^8/8!                     truncation < 3e-8
//! (sin x, cos x) = rotate (sin r, cos r) by k quarter turns
//! ```
//!
//! Maximum error against `f64` sin/cos: 1.2e-7 for `|x| <= 8 pi` (tested), i.e. one or two
//! ulp. The observer's angles are always wrapped to `[-pi, pi)`; larger arguments are wrapped
//! first. A non-finite argument gives NaN (the filter then rejects the step).

use crate::{Float, to_t, wrap_angle};

/// `pi/2` in three parts: the first two have few significant bits, so `k * PIO2_A` and
/// `k * PIO2_B` are exact for small `k`.
const PIO2_A: f32 = 1.570_312_5;
const PIO2_B: f32 = 4.837_513e-4;
const PIO2_C: f32 = 7.549_789_7e-8;

/// Arguments beyond this are wrapped to `[-pi, pi)` first.
const DIRECT_LIMIT: f32 = 8.0 * core::f32::consts::PI;

/// `(sin x, cos x)` in pure `f32` arithmetic (module docs give method and error).
#[inline]
pub fn sin_cos_f32(x: f32) -> (f32, f32) {
    if !x.is_finite() {
        return (f32::NAN, f32::NAN);
    }
    let x = if x.abs() > DIRECT_LIMIT {
        wrap_angle(x)
    } else {
        x
    };
    let q = x * core::f32::consts::FRAC_2_PI;
    // Round half away from zero; |q| <= 17 here, so the cast is exact and cannot saturate.
    let k = (q + 0.5_f32.copysign(q)) as i32;
    let kf = k as f32;
    let r = ((x - kf * PIO2_A) - kf * PIO2_B) - kf * PIO2_C;
    let r2 = r * r;
    let s = r
        * (1.0
            + r2 * (-1.0 / 6.0
                + r2 * (1.0 / 120.0 + r2 * (-1.0 / 5040.0 + r2 * (1.0 / 362_880.0)))));
    let c = 1.0 + r2 * (-0.5 + r2 * (1.0 / 24.0 + r2 * (-1.0 / 720.0 + r2 * (1.0 / 40_320.0))));
    match k & 3 {
        0 => (s, c),
        1 => (c, -s),
        2 => (-s, -c),
        _ => (-c, s),
    }
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
