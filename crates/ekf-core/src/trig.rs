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

use crate::wrap_angle;

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
        assert!(sin_cos_f32(f32::INFINITY).1.is_nan());
    }
}
