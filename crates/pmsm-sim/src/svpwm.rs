//! Clarke transforms and space-vector PWM (the simulator's own small one).
//!
//! Amplitude-invariant Clarke transform (`design.md` section 2 frames):
//!
//! ```text
//! u_alpha = (2 u_a - u_b - u_c) / 3,   u_beta = (u_b - u_c) / sqrt(3)
//! u_a = u_alpha,  u_b = -u_alpha / 2 + sqrt(3)/2 u_beta,  u_c = -u_alpha / 2 - sqrt(3)/2 u_beta
//! ```
//!
//! Park transform with the rotor direction `rot = (cos th, sin th)` ([`park`],
//! [`inverse_park`]): a rotation by `-th` and by `+th` of a 2-D vector ([`DVec2`]).
//!
//! SVPWM by min-max zero-sequence injection: the phase references get the common offset
//! `-(max + min) / 2`, which centres them in the carrier and gives the same switching
//! pattern as the classic sector-based SVPWM. Duties are `d_x = 1/2 + v_x / u_dc`. Every
//! vector inside the hexagon of the six active vectors (vertices at `|u| = 2/3 u_dc`) is
//! realized exactly; the inscribed circle `|u| <= u_dc / sqrt(3)` is the largest *rotating*
//! vector realized without distortion (the limit the controllers use). Outside the hexagon the
//! duties are clamped to `[0, 1]` and the vector is distorted (reported as saturated).

use glam::DVec2;

/// `sqrt(3) / 2`.
const SQRT3_2: f64 = 0.866_025_403_784_438_6;
/// `1 / sqrt(3)`.
pub const INV_SQRT3: f64 = 0.577_350_269_189_625_8;

/// Amplitude-invariant Clarke transform of phase quantities `[a, b, c]`.
#[inline]
pub fn clarke(abc: [f64; 3]) -> [f64; 2] {
    [
        (2.0 * abc[0] - abc[1] - abc[2]) / 3.0,
        (abc[1] - abc[2]) * INV_SQRT3,
    ]
}

/// Inverse amplitude-invariant Clarke transform (zero-sequence free).
#[inline]
pub fn inverse_clarke(ab: [f64; 2]) -> [f64; 3] {
    let h = -0.5 * ab[0];
    let s = SQRT3_2 * ab[1];
    [ab[0], h + s, h - s]
}

/// Park transform: the stationary vector `ab` in the frame whose d axis points along
/// `rot = (cos th, sin th)`: `d = a cos th + b sin th`, `q = -a sin th + b cos th`.
#[inline]
pub fn park(ab: DVec2, rot: DVec2) -> DVec2 {
    DVec2::new(rot.x, -rot.y).rotate(ab)
}

/// Inverse Park transform: the frame vector `dq` in the stationary frame,
/// `a = d cos th - q sin th`, `b = d sin th + q cos th`.
#[inline]
pub fn inverse_park(dq: DVec2, rot: DVec2) -> DVec2 {
    rot.rotate(dq)
}

/// Duties of one period from SVPWM.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Duties {
    /// Duty of each phase leg, in `[0, 1]`.
    pub d: [f64; 3],
    /// Whether a duty had to be clamped (the vector was outside the hexagon).
    pub saturated: bool,
}

/// SVPWM duties for the stationary voltage `u_ab_v` on a DC link of `u_dc_v` (> 0).
/// Non-finite inputs give non-finite duties (the caller checks).
#[inline]
pub fn svpwm(u_ab_v: [f64; 2], u_dc_v: f64) -> Duties {
    let v = inverse_clarke(u_ab_v);
    let max = v[0].max(v[1]).max(v[2]);
    let min = v[0].min(v[1]).min(v[2]);
    let offset = -0.5 * (max + min);
    let inv = 1.0 / u_dc_v;
    let mut d = [0.0; 3];
    let mut saturated = false;
    for (dx, vx) in d.iter_mut().zip(v) {
        let raw = 0.5 + (vx + offset) * inv;
        let c = raw.clamp(0.0, 1.0);
        saturated |= c != raw;
        *dx = c;
    }
    Duties { d, saturated }
}

/// The stationary voltage that duties `d` realize on a DC link of `u_dc_v`, ideal switches
/// (the common mode cancels in a star-connected motor).
#[inline]
pub fn duties_to_voltage(d: [f64; 3], u_dc_v: f64) -> [f64; 2] {
    let ab = clarke(d);
    [ab[0] * u_dc_v, ab[1] * u_dc_v]
}

#[cfg(test)]
mod tests {
    use super::*;

    fn close(a: &[f64], b: &[f64], tol: f64) -> bool {
        a.iter().zip(b).all(|(x, y)| (x - y).abs() <= tol)
    }

    #[test]
    fn clarke_known_answers() {
        // A balanced set at phase 0: a = 1, b = c = -1/2 -> (1, 0).
        assert!(close(&clarke([1.0, -0.5, -0.5]), &[1.0, 0.0], 1e-15));
        // Phase b peak: (-1/2, sqrt3/2).
        assert!(close(&clarke([-0.5, 1.0, -0.5]), &[-0.5, SQRT3_2], 1e-15));
        // The zero sequence is removed.
        assert!(close(&clarke([3.0, 3.0, 3.0]), &[0.0, 0.0], 1e-15));
        let ab = [0.3, -1.7];
        assert!(close(&clarke(inverse_clarke(ab)), &ab, 1e-15));
    }

    #[test]
    fn park_known_answers() {
        let th = 0.7_f64;
        let rot = DVec2::new(th.cos(), th.sin());
        let ab = DVec2::new(1.5, -0.25);
        let dq = park(ab, rot);
        let want = [
            1.5 * th.cos() - 0.25 * th.sin(),
            -1.5 * th.sin() - 0.25 * th.cos(),
        ];
        assert!(close(&dq.to_array(), &want, 1e-15));
        assert!(close(
            &inverse_park(dq, rot).to_array(),
            &ab.to_array(),
            1e-15
        ));
        // The d axis along the rotor: a vector at angle th has no q part.
        assert!(park(rot * 2.0, rot).y.abs() < 1e-15);
    }

    #[test]
    fn svpwm_sectors_known_answers() {
        let udc = 100.0;
        // Zero vector: all 50 %.
        let z = svpwm([0.0, 0.0], udc);
        assert!(close(&z.d, &[0.5; 3], 1e-15) && !z.saturated);
        // Along alpha (sector 1 edge), |u| = udc / sqrt3: d = (1, 0.5 - .., ..) at the limit.
        let u = udc * INV_SQRT3;
        let a = svpwm([u, 0.0], udc);
        // v = (u, -u/2, -u/2), offset -u/4: d_a = 0.5 + 0.75 u / udc = 0.933, d_b = d_c = 0.067.
        let hi = 0.5 + 0.75 * INV_SQRT3;
        let lo = 0.5 - 0.75 * INV_SQRT3;
        assert!(close(&a.d, &[hi, lo, lo], 1e-12), "{:?}", a.d);
        // One vector in each of the six sectors, on the inscribed circle: duties within
        // [0, 1], not saturated, and the realized voltage is the reference.
        for k in 0..6 {
            let th = (k as f64 + 0.5) * core::f64::consts::FRAC_PI_3;
            let r = [u * th.cos(), u * th.sin()];
            let d = svpwm(r, udc);
            assert!(!d.saturated);
            assert!(close(&duties_to_voltage(d.d, udc), &r, 1e-12));
            assert!(d.d.iter().all(|x| (0.0..=1.0).contains(x)));
        }
        // Sector 2 centre (60 deg): v_c is the minimum, d_c = 0.5 - ..; d_a = d_b.
        let th = core::f64::consts::FRAC_PI_3;
        let d = svpwm([0.5 * u * th.cos(), 0.5 * u * th.sin()], udc);
        assert!((d.d[0] - d.d[1]).abs() < 1e-12 && d.d[2] < 0.5);
        // Between the circle and the hexagon (a vertex direction, 0.99 x 2/3 u_dc): still
        // realized exactly, not saturated.
        let v = [0.99 * 2.0 / 3.0 * udc, 0.0];
        let d = svpwm(v, udc);
        assert!(!d.saturated && v[0] > u);
        assert!(close(&duties_to_voltage(d.d, udc), &v, 1e-12));
        // Far outside the hexagon: clamped and flagged.
        let s = svpwm([2.0 * udc, 0.0], udc);
        assert!(s.saturated && s.d.iter().all(|x| (0.0..=1.0).contains(x)));
    }
}
