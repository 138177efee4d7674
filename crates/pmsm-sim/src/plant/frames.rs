//! The plant's reference frames in `f64`: Clarke and Park transforms of phase quantities
//! (docs/design.md, "Conventions"). The drive's own transforms are `foc`'s (`f32`); the plant keeps
//! its physics in `f64`.
//!
//! Amplitude-invariant Clarke transform:
//!
//! ```text
//! u_alpha = (2 u_a - u_b - u_c) / 3,   u_beta = (u_b - u_c) / sqrt(3)
//! u_a = u_alpha,  u_b = -u_alpha / 2 + sqrt(3)/2 u_beta,  u_c = -u_alpha / 2 - sqrt(3)/2 u_beta
//! ```
//!
//! Park transform with the rotor direction `rot = (cos th, sin th)` ([`park`],
//! [`inverse_park`]): a rotation by `-th` and by `+th` of a 2-D vector ([`DVec2`]).

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
}
