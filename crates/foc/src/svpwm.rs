//! Space-vector PWM by min-max (common-mode) injection, with over-modulation clamped.
//!
//! For a voltage command `u = (u_alpha, u_beta)` and the DC-bus voltage `u_dc`:
//!
//! ```text
//! v_x   = inverse Clarke of u                       (phase voltages, x = a, b, c)
//! span  = max(v) - min(v)                           (largest line-to-line voltage)
//! s     = min(1, u_dc / span)                       (over-modulation: shrink, keep the direction)
//! d_x   = 1/2 + (s v_x - s (max(v) + min(v)) / 2) / u_dc,   clamped to [0, 1]
//! ```
//!
//! The duty `d_x` is the fraction of the period phase `x` is connected to `+u_dc`; the
//! pole voltages are `d_x u_dc` and the line-to-line voltages `(d_x - d_y) u_dc` reproduce
//! `v_x - v_y` exactly in the linear range. The injected common mode `-(max + min) / 2`
//! centres the pulses, which is the same as the classic sector-based SVPWM with equal
//! zero-vector times. The linear range is the hexagon `span <= u_dc`; its inscribed circle has
//! radius `u_dc / sqrt(3)`. Beyond the hexagon the vector is scaled back onto it along its own
//! direction (the duties of the largest and smallest phase become 1 and 0).
//!
//! [`duties_to_alpha_beta`] is the inverse: the average voltage the inverter applies for given
//! duties. The controller feeds that realized voltage to the observer, so clamping never
//! misleads the estimate (with dead-time compensation, the voltage of the duties net of the
//! compensation: [`crate::deadtime`]).

use crate::transforms::{AlphaBeta, FRAC_1_SQRT_3, SQRT_3};

/// Duties of the safe state: all phases at 50 %, zero line-to-line voltage.
pub const SAFE_DUTIES: [f32; 3] = [0.5, 0.5, 0.5];

/// Result of one modulation.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Modulation {
    /// Duties of phases a, b, c, each in `[0, 1]` and finite.
    pub duties: [f32; 3],
    /// The average alpha-beta voltage these duties apply at this `u_dc`, V.
    pub applied: AlphaBeta,
    /// Whether the command was outside the hexagon (or invalid) and had to be reduced.
    pub clamped: bool,
}

/// Sector 1..=6 of a voltage vector: sector `n` spans electrical angles
/// `[(n - 1) 60 deg, n 60 deg)`, counted from the alpha axis. The zero vector is in sector 1.
pub fn sector(u: AlphaBeta) -> u8 {
    let s3a = SQRT_3 * u.alpha;
    if u.beta > 0.0 {
        if u.beta < s3a {
            1
        } else if u.beta > -s3a {
            2
        } else {
            3
        }
    } else if u.beta < 0.0 {
        if u.beta > s3a {
            4
        } else if u.beta < -s3a {
            5
        } else {
            6
        }
    } else if u.alpha < 0.0 {
        4
    } else {
        1
    }
}

/// Duties for the voltage command `u` (V) at the DC-bus voltage `u_dc_v` (module docs).
///
/// A non-finite command, or a `u_dc_v` that is not finite and positive, gives
/// [`SAFE_DUTIES`] (zero voltage) with `clamped = true`.
pub fn svpwm(u: AlphaBeta, u_dc_v: f32) -> Modulation {
    // `!(x > 0)` also catches NaN.
    if !(u.is_finite() && u_dc_v.is_finite() && u_dc_v > 0.0) {
        return Modulation {
            duties: SAFE_DUTIES,
            applied: AlphaBeta::default(),
            clamped: true,
        };
    }
    modulate(u, u_dc_v)
}

/// [`svpwm`] without the input check, for a finite `u` and a finite positive `u_dc_v` (the
/// controller's own call). Duties stay in `[0, 1]` and finite whatever the input.
pub(crate) fn modulate(u: AlphaBeta, u_dc_v: f32) -> Modulation {
    let (duties, clamped) = modulate_duties(u, u_dc_v);
    Modulation {
        duties,
        applied: duties_to_alpha_beta(duties, u_dc_v),
        clamped,
    }
}

/// The duties of [`modulate`] and whether the command was reduced, without the realized
/// voltage (the controller rebuilds that itself, after the dead-time compensation).
#[inline]
pub(crate) fn modulate_duties(u: AlphaBeta, u_dc_v: f32) -> ([f32; 3], bool) {
    let v = u.to_abc();
    // Plain comparisons: `f32::max` is a library call on the Cortex-M4.
    let (mut vmax, mut vmin) = if v.a > v.b { (v.a, v.b) } else { (v.b, v.a) };
    if v.c > vmax {
        vmax = v.c;
    }
    if v.c < vmin {
        vmin = v.c;
    }
    let span = vmax - vmin;
    // Volts to duty: 1 / u_dc, or 1 / span when the vector is shrunk onto the hexagon.
    let (k, clamped) = if span > u_dc_v {
        (1.0 / span, true)
    } else {
        (1.0 / u_dc_v, false)
    };
    let mid = 0.5 * (vmax + vmin);
    let duties = [
        clamp01((v.a - mid) * k + 0.5),
        clamp01((v.b - mid) * k + 0.5),
        clamp01((v.c - mid) * k + 0.5),
    ];
    (duties, clamped)
}

/// The average alpha-beta voltage the inverter applies with `duties` at `u_dc_v`:
/// pole voltages `d_x u_dc`, common mode removed by the Clarke transform,
/// `alpha = u_dc (2 d_a - d_b - d_c) / 3`, `beta = u_dc (d_b - d_c) / sqrt(3)`.
pub fn duties_to_alpha_beta(duties: [f32; 3], u_dc_v: f32) -> AlphaBeta {
    let [da, db, dc] = duties;
    AlphaBeta {
        alpha: (2.0 * da - db - dc) * (u_dc_v * (1.0 / 3.0)),
        beta: (db - dc) * (u_dc_v * FRAC_1_SQRT_3),
    }
}

/// `x` limited to `[0, 1]` by two comparisons; NaN gives 1 (finite and in range; the public
/// [`svpwm`] refuses non-finite inputs before, so only an overflow could make one).
#[inline]
pub(crate) fn clamp01(x: f32) -> f32 {
    let y = if x < 1.0 { x } else { 1.0 };
    if y > 0.0 { y } else { 0.0 }
}

/// Radius of the largest circle inside the linear range, `u_dc / sqrt(3)`, V.
pub fn linear_limit_v(u_dc_v: f32) -> f32 {
    u_dc_v * FRAC_1_SQRT_3
}

#[cfg(test)]
mod tests {
    use super::*;
    use core::f32::consts::PI;

    #[test]
    fn sector_boundaries() {
        for n in 0..6 {
            let mid = (n as f32 + 0.5) * PI / 3.0;
            let u = AlphaBeta {
                alpha: mid.cos(),
                beta: mid.sin(),
            };
            assert_eq!(sector(u), n as u8 + 1, "{u:?}");
        }
        assert_eq!(sector(AlphaBeta::default()), 1);
        // Boundaries belong to the sector they open.
        let s3 = SQRT_3;
        for (alpha, beta, n) in [
            (1.0, 0.0, 1),
            (1.0, s3, 2),
            (-1.0, s3, 3),
            (-1.0, 0.0, 4),
            (-1.0, -s3, 5),
            (1.0, -s3, 6),
        ] {
            assert_eq!(sector(AlphaBeta { alpha, beta }), n, "{alpha} {beta}");
        }
    }

    #[test]
    fn clamp01_handles_nan() {
        assert_eq!(clamp01(f32::NAN), 1.0);
        assert_eq!(clamp01(7.0), 1.0);
        assert_eq!(clamp01(-7.0), 0.0);
    }
}
