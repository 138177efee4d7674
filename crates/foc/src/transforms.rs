//! Reference frames and the amplitude-invariant Clarke and Park transforms.
//!
//! ```text
//! Clarke:  a = i_a,  b = (i_a + 2 i_b) / sqrt(3)          (i_a + i_b + i_c = 0 assumed)
//! Park:    d =  a cos th + b sin th,   q = -a sin th + b cos th
//! inverse Clarke:  a = alpha,  b = -alpha/2 + sqrt(3)/2 beta,  c = -alpha/2 - sqrt(3)/2 beta
//! inverse Park:    alpha = d cos th - q sin th,   beta = d sin th + q cos th
//! ```
//!
//! Amplitude-invariant: a balanced set of peak `I` has `|(alpha, beta)| = I`. Angles are
//! electrical. The `*_angle` variants compute the sine and cosine with [`crate::trig::sin_cos`]
//! (error below 2.4e-7); the plain ones take them from the caller so that one evaluation serves
//! several transforms.
//!
//! The two-axis frames keep their named components (`alpha`, `beta`; `d`, `q`) and do their
//! arithmetic as [`glam::Vec2`] (rotations are complex products, [`Vec2::rotate`]); they
//! convert to and from `Vec2` with `From`. Only the operations that compile to the same
//! single-precision instructions on the Cortex-M4F are used (no `length`, `normalize` or
//! `from_angle`, which go through software `libm`; `clippy.toml` refuses them).

use core::ops::{Add, Mul, Sub};

use glam::Vec2;

use crate::trig::sin_cos;

/// `1 / sqrt(3)` (Clarke; the linear range of SVPWM, `u_dc / sqrt(3)`).
pub(crate) const FRAC_1_SQRT_3: f32 = 0.577_350_26;
/// `sqrt(3) / 2`.
pub(crate) const SQRT_3_2: f32 = 0.866_025_4;
/// `sqrt(3)` (the f32 nearest, like the two above).
pub(crate) const SQRT_3: f32 = 2.0 * SQRT_3_2;

/// Three phase quantities (currents in A or voltages in V).
#[derive(Clone, Copy, Debug, Default, PartialEq)]
pub struct Abc {
    /// Phase a.
    pub a: f32,
    /// Phase b.
    pub b: f32,
    /// Phase c.
    pub c: f32,
}

/// Stationary two-axis frame (alpha along phase a).
#[derive(Clone, Copy, Debug, Default, PartialEq)]
pub struct AlphaBeta {
    /// Alpha component.
    pub alpha: f32,
    /// Beta component.
    pub beta: f32,
}

/// Rotor frame (d along the magnet flux).
#[derive(Clone, Copy, Debug, Default, PartialEq)]
pub struct Dq {
    /// Direct axis.
    pub d: f32,
    /// Quadrature axis.
    pub q: f32,
}

impl Abc {
    /// Amplitude-invariant Clarke transform using phases a and b only (balanced load,
    /// `c = -a - b`; `c` is ignored).
    pub fn to_alpha_beta(self) -> AlphaBeta {
        AlphaBeta {
            alpha: self.a,
            beta: (self.a + 2.0 * self.b) * FRAC_1_SQRT_3,
        }
    }

    /// Clarke transform using all three phases, `alpha = (2a - b - c) / 3`,
    /// `beta = (b - c) / sqrt(3)`: removes a common-mode component (e.g. a shared offset) and
    /// averages the sensor noise of three shunts. Equals [`to_alpha_beta`](Self::to_alpha_beta)
    /// when `a + b + c = 0`.
    pub fn to_alpha_beta_3(self) -> AlphaBeta {
        AlphaBeta {
            alpha: (2.0 * self.a - self.b - self.c) * (1.0 / 3.0),
            beta: (self.b - self.c) * FRAC_1_SQRT_3,
        }
    }

    /// Whether all three phases are finite.
    pub fn is_finite(self) -> bool {
        self.a.is_finite() && self.b.is_finite() && self.c.is_finite()
    }
}

impl AlphaBeta {
    /// Inverse Clarke: phase quantities of a balanced set.
    pub fn to_abc(self) -> Abc {
        let half_a = -0.5 * self.alpha;
        let s = SQRT_3_2 * self.beta;
        Abc {
            a: self.alpha,
            b: half_a + s,
            c: half_a - s,
        }
    }

    /// Park transform with the sine and cosine of the electrical angle: the vector rotated
    /// by `-th`.
    #[inline]
    pub fn to_dq(self, sin_th: f32, cos_th: f32) -> Dq {
        Vec2::from(self).rotate(Vec2::new(cos_th, -sin_th)).into()
    }

    /// Park transform at the electrical angle `theta_rad`.
    pub fn to_dq_angle(self, theta_rad: f32) -> Dq {
        let (s, c) = sin_cos(theta_rad);
        self.to_dq(s, c)
    }

    /// Squared length `alpha^2 + beta^2`.
    #[inline]
    pub fn norm_squared(self) -> f32 {
        Vec2::from(self).length_squared()
    }

    /// Whether both components are finite.
    pub fn is_finite(self) -> bool {
        self.alpha.is_finite() && self.beta.is_finite()
    }
}

impl Dq {
    /// Inverse Park transform with the sine and cosine of the electrical angle: the vector
    /// rotated by `th`.
    #[inline]
    pub fn to_alpha_beta(self, sin_th: f32, cos_th: f32) -> AlphaBeta {
        Vec2::from(self).rotate(Vec2::new(cos_th, sin_th)).into()
    }

    /// Inverse Park transform at the electrical angle `theta_rad`.
    pub fn to_alpha_beta_angle(self, theta_rad: f32) -> AlphaBeta {
        let (s, c) = sin_cos(theta_rad);
        self.to_alpha_beta(s, c)
    }

    /// The same vector seen from a frame turned by `-delta` (i.e. the components rotated by
    /// `+delta`, given as `sin delta`, `cos delta`): moving a dq quantity from a frame at angle
    /// `th_a` to one at `th_b` is `rotate(sin(th_a - th_b), cos(th_a - th_b))`.
    #[inline]
    pub fn rotate(self, sin_delta: f32, cos_delta: f32) -> Dq {
        Vec2::from(self)
            .rotate(Vec2::new(cos_delta, sin_delta))
            .into()
    }

    /// Squared length `d^2 + q^2`.
    #[inline]
    pub fn norm_squared(self) -> f32 {
        Vec2::from(self).length_squared()
    }

    /// Whether both components are finite.
    pub fn is_finite(self) -> bool {
        self.d.is_finite() && self.q.is_finite()
    }
}

impl Add for Abc {
    type Output = Abc;
    fn add(self, o: Abc) -> Abc {
        Abc {
            a: self.a + o.a,
            b: self.b + o.b,
            c: self.c + o.c,
        }
    }
}

impl Sub for Abc {
    type Output = Abc;
    fn sub(self, o: Abc) -> Abc {
        Abc {
            a: self.a - o.a,
            b: self.b - o.b,
            c: self.c - o.c,
        }
    }
}

impl Mul<f32> for Abc {
    type Output = Abc;
    fn mul(self, k: f32) -> Abc {
        Abc {
            a: self.a * k,
            b: self.b * k,
            c: self.c * k,
        }
    }
}

/// `From` both ways with [`glam::Vec2`] and the vector operations through it.
macro_rules! two_axis {
    ($t:ident { $x:ident, $y:ident }) => {
        impl From<$t> for Vec2 {
            #[inline]
            fn from(v: $t) -> Vec2 {
                Vec2::new(v.$x, v.$y)
            }
        }
        impl From<Vec2> for $t {
            #[inline]
            fn from(v: Vec2) -> $t {
                $t { $x: v.x, $y: v.y }
            }
        }
        impl Add for $t {
            type Output = $t;
            #[inline]
            fn add(self, o: $t) -> $t {
                (Vec2::from(self) + Vec2::from(o)).into()
            }
        }
        impl Sub for $t {
            type Output = $t;
            #[inline]
            fn sub(self, o: $t) -> $t {
                (Vec2::from(self) - Vec2::from(o)).into()
            }
        }
        impl Mul<f32> for $t {
            type Output = $t;
            #[inline]
            fn mul(self, k: f32) -> $t {
                (Vec2::from(self) * k).into()
            }
        }
    };
}
two_axis!(AlphaBeta { alpha, beta });
two_axis!(Dq { d, q });

#[cfg(test)]
mod tests {
    use super::*;

    fn close(a: f32, b: f32) -> bool {
        (a - b).abs() < 1e-5
    }

    #[test]
    fn clarke_known_answers() {
        // Phase a at its peak: alpha = 1, beta = 0.
        let ab = Abc {
            a: 1.0,
            b: -0.5,
            c: -0.5,
        }
        .to_alpha_beta();
        assert!(close(ab.alpha, 1.0) && close(ab.beta, 0.0), "{ab:?}");
        // Phase b at its peak (120 deg): alpha = -0.5, beta = sqrt(3)/2.
        let ab = Abc {
            a: -0.5,
            b: 1.0,
            c: -0.5,
        }
        .to_alpha_beta();
        assert!(close(ab.alpha, -0.5) && close(ab.beta, SQRT_3_2), "{ab:?}");
        let abc = AlphaBeta {
            alpha: 0.3,
            beta: -0.7,
        }
        .to_abc();
        assert!(close(abc.a + abc.b + abc.c, 0.0));
        let back = abc.to_alpha_beta();
        assert!(close(back.alpha, 0.3) && close(back.beta, -0.7));
    }

    #[test]
    fn park_known_answers() {
        // At th = 90 deg the alpha-beta vector (0, 1) is the d axis.
        let dq = AlphaBeta {
            alpha: 0.0,
            beta: 1.0,
        }
        .to_dq(1.0, 0.0);
        assert!(close(dq.d, 1.0) && close(dq.q, 0.0), "{dq:?}");
        // At th = 30 deg, (cos 30, sin 30) is the d axis too.
        let (s, c) = (0.5, SQRT_3_2);
        let dq = AlphaBeta { alpha: c, beta: s }.to_dq(s, c);
        assert!(close(dq.d, 1.0) && close(dq.q, 0.0), "{dq:?}");
        let ab = Dq { d: 0.2, q: 1.5 }.to_alpha_beta(s, c);
        let dq = ab.to_dq(s, c);
        assert!(close(dq.d, 0.2) && close(dq.q, 1.5), "{dq:?}");
    }

    #[test]
    fn inverse_clarke_known_answers() {
        // alpha = 1: phase a at +1, b and c at -1/2.
        let abc = AlphaBeta {
            alpha: 1.0,
            beta: 0.0,
        }
        .to_abc();
        assert!(
            close(abc.a, 1.0) && close(abc.b, -0.5) && close(abc.c, -0.5),
            "{abc:?}"
        );
        // beta = 1: b = sqrt(3)/2, c = -sqrt(3)/2.
        let abc = AlphaBeta {
            alpha: 0.0,
            beta: 1.0,
        }
        .to_abc();
        assert!(close(abc.a, 0.0) && close(abc.b, SQRT_3_2) && close(abc.c, -SQRT_3_2));
        // Three-phase Clarke removes a common offset and equals the two-phase one otherwise.
        let bal = Abc {
            a: 0.4,
            b: -1.1,
            c: 0.7,
        };
        let off = bal
            + Abc {
                a: 0.25,
                b: 0.25,
                c: 0.25,
            };
        let (x, y) = (bal.to_alpha_beta(), off.to_alpha_beta_3());
        assert!(
            close(x.alpha, y.alpha) && close(x.beta, y.beta),
            "{x:?} {y:?}"
        );
    }

    #[test]
    fn park_at_angles_and_rotation() {
        use core::f32::consts::PI;
        // A unit vector at angle phi is d = cos(phi - th), q = sin(phi - th) in frame th.
        for i in 0..24 {
            let phi = -PI + i as f32 * (PI / 12.0);
            let v = AlphaBeta {
                alpha: libm_cos(phi),
                beta: libm_sin(phi),
            };
            for th in [-3.0_f32, -1.0, 0.0, 0.5, 2.0, 3.1] {
                let dq = v.to_dq_angle(th);
                assert!(
                    close(dq.d, libm_cos(phi - th)) && close(dq.q, libm_sin(phi - th)),
                    "{phi} {th} {dq:?}"
                );
                let back = dq.to_alpha_beta_angle(th);
                assert!(close(back.alpha, v.alpha) && close(back.beta, v.beta));
                // Frame change th -> 0 equals a rotation by th.
                let r = dq.rotate(libm_sin(th), libm_cos(th));
                let direct = v.to_dq_angle(0.0);
                assert!(
                    close(r.d, direct.d) && close(r.q, direct.q),
                    "{r:?} {direct:?}"
                );
            }
        }
    }

    fn libm_sin(x: f32) -> f32 {
        (f64::from(x)).sin() as f32
    }

    fn libm_cos(x: f32) -> f32 {
        (f64::from(x)).cos() as f32
    }
}
