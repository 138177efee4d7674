//! Cheap `f32` math for the control path: sine/cosine, `atan2`, square root, angle wrapping.
//!
//! `core` has no `sin`, `cos` or `sqrt` for `f32`, and `libm`'s `sinf`/`cosf` compute in `f64`
//! (software floating point on a Cortex-M4F). Sine and cosine come from `ekf_core::trig` (shared
//! with the observer); the rest are short polynomials here. Errors measured by the unit tests
//! against `f64`:
//!
//! | function | method | max abs. error |
//! |---|---|---|
//! | [`sin_cos`] | `ekf_core::trig::sin_cos_f32`: branch-free quadrant reduction, minimax kernels on `[-pi/4, pi/4]`; `(0, 1)` for a non-finite `x` | 1.2e-7 for `|x| <= 8 pi` (ekf-core measures 8.6e-8 for its kernel) |
//! | [`atan2`] | octant reduction, Cephes `atanf` kernel | 3e-7 rad |
//! | [`sin_cos_small`] | `ekf_core::trig::sin_cos_small` for `|d| < 0.5`, [`sin_cos`] beyond | 1.2e-7 |
//! | [`sqrt`] | bit-level first guess, three Newton steps | 1 ulp-ish (relative 1.2e-7) |
//!
//! Nothing here panics; non-finite inputs give finite, documented outputs where that matters.
//! No `f64` arithmetic.

use core::f32::consts::{FRAC_PI_2, FRAC_PI_4, PI};

/// `(sin x, cos x)`: [`ekf_core::trig::sin_cos_f32`] (pure `f32`, error below 1.2e-7 for
/// `|x| <= 8 pi`, larger arguments wrapped first).
///
/// A non-finite `x` gives `(0, 1)` (angle zero) rather than NaN, so that a bad value cannot
/// reach the PWM through a rotation.
#[inline]
pub fn sin_cos(x: f32) -> (f32, f32) {
    if !x.is_finite() {
        return (0.0, 1.0);
    }
    ekf_core::trig::sin_cos_f32(x)
}

/// `atan(z)` for `z >= 0` (Cephes `atanf`).
fn atan_pos(z: f32) -> f32 {
    // tan(3 pi / 8) and tan(pi / 8).
    let (base, t) = if z > 2.414_213_6 {
        (FRAC_PI_2, -1.0 / z)
    } else if z > 0.414_213_57 {
        (FRAC_PI_4, (z - 1.0) / (z + 1.0))
    } else {
        (0.0, z)
    };
    let t2 = t * t;
    let p = (((8.053_744_5e-2 * t2 - 1.387_768_6e-1) * t2 + 1.997_771_1e-1) * t2 - 3.333_295e-1)
        * t2
        * t
        + t;
    base + p
}

/// `atan2(y, x)` in `[-pi, pi]`, error below 3e-7 rad. `atan2(0, 0) = 0`; a NaN argument
/// gives 0.
pub fn atan2(y: f32, x: f32) -> f32 {
    if !(y.is_finite() && x.is_finite()) {
        return 0.0;
    }
    if x == 0.0 {
        return if y > 0.0 {
            FRAC_PI_2
        } else if y < 0.0 {
            -FRAC_PI_2
        } else {
            0.0
        };
    }
    let a = atan_pos((y / x).abs());
    match (x > 0.0, y >= 0.0) {
        (true, true) => a,
        (true, false) => -a,
        (false, true) => PI - a,
        (false, false) => a - PI,
    }
}

/// Square root, relative error about 1.2e-7. Returns 0 for `x <= 0` and for NaN, `x` for
/// `+inf`.
pub fn sqrt(x: f32) -> f32 {
    if x.is_nan() || x <= 0.0 {
        return 0.0;
    }
    if x.is_infinite() {
        return x;
    }
    // Halving the exponent through the bit pattern is within 4 % of the root.
    let mut y = f32::from_bits((x.to_bits() >> 1) + 0x1fbd_1df5);
    y = 0.5 * (y + x / y);
    y = 0.5 * (y + x / y);
    0.5 * (y + x / y)
}

/// Wraps an angle to `[-pi, pi)`: [`ekf_core::wrap_angle`] (a single fold for angles at most
/// one turn out of range). NaN stays NaN. An angle already in range (the common case) is
/// returned inline, as `wrap_angle`'s own first test does, without the call.
#[inline]
pub fn wrap(x: f32) -> f32 {
    if (-PI..PI).contains(&x) {
        return x;
    }
    ekf_core::wrap_angle(x)
}

/// `(sin d, cos d)` for a small angle: Taylor series through `d^7` / `d^8` for `|d| <= 0.5`
/// (truncation below 6e-9), [`sin_cos`] otherwise. About a fifth of the cost of [`sin_cos`]; used
/// for the inverse-Park angle advance `1.5 w Ts`.
#[inline]
pub fn sin_cos_small(d: f32) -> (f32, f32) {
    if !at_most(d.abs(), 0.5) {
        return sin_cos(d);
    }
    ekf_core::trig::sin_cos_small(d)
}

/// `(sin(a + b), cos(a + b))` from the sines and cosines of `a` and `b`.
pub fn add_angles(sa: f32, ca: f32, sb: f32, cb: f32) -> (f32, f32) {
    (sa * cb + ca * sb, ca * cb - sa * sb)
}

/// The larger of `a` and `b` by a plain comparison (`f32::max` is a library call on
/// Cortex-M4); `b` if either is NaN.
pub(crate) fn max2(a: f32, b: f32) -> f32 {
    if a > b { a } else { b }
}

/// The smaller of `a` and `b` by a plain comparison; `b` if either is NaN.
pub(crate) fn min2(a: f32, b: f32) -> f32 {
    if a < b { a } else { b }
}

/// `a <= b`, spelled as a function so that `!at_most(a, b)` reads as "not within the limit,
/// or NaN".
pub(crate) fn at_most(a: f32, b: f32) -> bool {
    a <= b
}

#[cfg(test)]
mod tests {
    use super::*;
    use core::f32::consts::TAU;

    #[test]
    fn sin_cos_matches_f64() {
        let mut worst = 0.0f64;
        for i in -200_000..=200_000 {
            let x = i as f32 * (8.0 * PI / 200_000.0);
            let (s, c) = sin_cos(x);
            let xd = f64::from(x);
            worst = worst
                .max((f64::from(s) - xd.sin()).abs())
                .max((f64::from(c) - xd.cos()).abs());
        }
        assert!(worst < 2.4e-7, "sin_cos error {worst:e}");
        assert_eq!(sin_cos(f32::NAN), (0.0, 1.0));
        assert_eq!(sin_cos(f32::INFINITY), (0.0, 1.0));
        let (s, c) = sin_cos(1.0e30);
        assert!(s.is_finite() && c.is_finite() && s.abs() <= 1.0 && c.abs() <= 1.0);
    }

    #[test]
    fn atan2_matches_f64() {
        let mut worst = 0.0f64;
        for i in 0..20_000 {
            let th = -PI + i as f32 * (TAU / 20_000.0);
            for r in [1e-3_f32, 1.0, 250.0] {
                let (s, c) = (f64::from(th)).sin_cos();
                let (y, x) = ((s * f64::from(r)) as f32, (c * f64::from(r)) as f32);
                let a = f64::from(atan2(y, x));
                let e = (a - f64::from(y).atan2(f64::from(x))).abs();
                worst = worst.max(e.min(2.0 * core::f64::consts::PI - e));
            }
        }
        assert!(worst < 3e-7, "atan2 error {worst:e}");
        assert_eq!(atan2(0.0, 0.0), 0.0);
        assert_eq!(atan2(f32::NAN, 1.0), 0.0);
        assert!((atan2(1.0, 0.0) - FRAC_PI_2).abs() < 1e-7);
    }

    #[test]
    fn small_angle_series_and_sum() {
        let mut worst = 0.0f64;
        for i in -1000..=1000 {
            let d = i as f32 * 7e-4; // +-0.7: both branches
            let (s, c) = sin_cos_small(d);
            let dd = f64::from(d);
            worst = worst
                .max((f64::from(s) - dd.sin()).abs())
                .max((f64::from(c) - dd.cos()).abs());
        }
        assert!(worst < 2.4e-7, "sin_cos_small error {worst:e}");
        let (sa, ca) = sin_cos(1.0);
        let (sb, cb) = sin_cos_small(0.2);
        let (s, c) = add_angles(sa, ca, sb, cb);
        assert!((f64::from(s) - 1.2f64.sin()).abs() < 3e-7);
        assert!((f64::from(c) - 1.2f64.cos()).abs() < 3e-7);
        assert_eq!(max2(1.0, 2.0), 2.0);
        assert_eq!(min2(1.0, 2.0), 1.0);
    }

    #[test]
    fn sqrt_matches_f64() {
        let mut worst = 0.0f64;
        let mut x = 1.0e-30_f32;
        while x < 1.0e30 {
            let rel = (f64::from(sqrt(x)) - f64::from(x).sqrt()).abs() / f64::from(x).sqrt();
            worst = worst.max(rel);
            x *= 1.37;
        }
        assert!(worst < 1.5e-7, "sqrt rel. error {worst:e}");
        assert_eq!(sqrt(-1.0), 0.0);
        assert_eq!(sqrt(f32::NAN), 0.0);
        assert_eq!(sqrt(0.0), 0.0);
    }

    #[test]
    fn wrap_into_range() {
        for (x, e) in [
            (0.0, 0.0),
            (PI, -PI),
            (-PI, -PI),
            (4.0, 4.0 - TAU),
            (-4.0, -4.0 + TAU),
            (100.0, ekf_core::wrap_angle(100.0_f32)),
        ] {
            let w = wrap(x);
            assert!((w - e).abs() < 1e-6, "{x} -> {w}");
            assert!((-PI..PI).contains(&w));
        }
        assert!(wrap(f32::NAN).is_nan());
    }
}
