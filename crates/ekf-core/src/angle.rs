//! Angle helpers.

use crate::Float;

/// Wraps an angle to `[-pi, pi)`: `th - 2 pi floor((th + pi) / (2 pi))` (`docs/design.md`
/// section 4).
///
/// Computed as that formula for `|th| < 3 pi` (one fold at most, bit-identical to it) and
/// with the exact float remainder beyond. Returns NaN for a non-finite input.
pub fn wrap_angle<T: Float>(th: T) -> T {
    let two_pi = T::two_pi();
    let pi = T::pi();
    // Fast paths: already in range, or one turn out (the usual case after a step). They give
    // the same value as the general formula with floor = 0 or +-1.
    if th >= -pi && th < pi {
        return th;
    }
    if th >= pi && th < pi + two_pi {
        return th - two_pi;
    }
    if th < -pi && th >= -pi - two_pi {
        return th + two_pi;
    }
    // General case: the float remainder is exact and cannot overflow (unlike
    // `th - 2 pi floor(..)` near the top of the range); it lies in (-2 pi, 2 pi).
    let mut w = th % two_pi;
    if w >= pi {
        w -= two_pi;
    } else if w < -pi {
        w += two_pi;
    }
    w
}

#[cfg(test)]
mod tests {
    use super::wrap_angle;
    use core::f64::consts::PI;

    #[test]
    fn wraps_into_half_open_range() {
        let cases = [
            (0.0, 0.0),
            (PI, -PI),
            (-PI, -PI),
            (3.0 * PI, -PI),
            (0.5, 0.5),
            (2.0 * PI + 0.5, 0.5),
            (-2.0 * PI - 0.5, -0.5),
            (1e6, 1e6 - 2.0 * PI * ((1e6 + PI) / (2.0 * PI)).floor()),
        ];
        for (input, expected) in cases {
            let w = wrap_angle(input);
            assert!(
                (w - expected).abs() < 1e-9,
                "{input} -> {w}, expected {expected}"
            );
            assert!((-PI..PI).contains(&w));
        }
        for i in -10_000..10_000 {
            let th = i as f32 * 0.013_7;
            let w = wrap_angle(th);
            assert!(
                (-core::f32::consts::PI..core::f32::consts::PI).contains(&w),
                "{th} -> {w}"
            );
        }
        assert!(wrap_angle(f64::NAN).is_nan());
        for th in [f64::MAX, -f64::MAX, 1e300, -3.3e17] {
            assert!((-PI..PI).contains(&wrap_angle(th)), "{th}");
        }
        for th in [f32::MAX, -f32::MAX, 3.0e30, -1.0e9] {
            let w = wrap_angle(th);
            assert!(
                (-core::f32::consts::PI..core::f32::consts::PI).contains(&w),
                "{th} -> {w}"
            );
        }
    }
}
