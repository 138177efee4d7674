//! Reference frames and the amplitude-invariant Clarke and Park transforms.
//!
//! ```text
//! Clarke:  a = i_a,  b = (i_a + 2 i_b) / sqrt(3)          (i_a + i_b + i_c = 0 assumed)
//! Park:    d =  a cos th + b sin th,   q = -a sin th + b cos th
//! ```

use core::ops::{Add, Mul, Sub};

/// `1 / sqrt(3)`.
const FRAC_1_SQRT_3: f32 = 0.577_350_26;
/// `sqrt(3) / 2`.
const SQRT_3_2: f32 = 0.866_025_4;

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
    /// Amplitude-invariant Clarke transform using phases a and b only (balanced load).
    pub fn to_alpha_beta(self) -> AlphaBeta {
        AlphaBeta {
            alpha: self.a,
            beta: (self.a + 2.0 * self.b) * FRAC_1_SQRT_3,
        }
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

    /// Park transform with the sine and cosine of the electrical angle.
    pub fn to_dq(self, sin_th: f32, cos_th: f32) -> Dq {
        Dq {
            d: self.alpha * cos_th + self.beta * sin_th,
            q: -self.alpha * sin_th + self.beta * cos_th,
        }
    }
}

impl Dq {
    /// Inverse Park transform with the sine and cosine of the electrical angle.
    pub fn to_alpha_beta(self, sin_th: f32, cos_th: f32) -> AlphaBeta {
        AlphaBeta {
            alpha: self.d * cos_th - self.q * sin_th,
            beta: self.d * sin_th + self.q * cos_th,
        }
    }
}

macro_rules! vector_ops {
    ($t:ident { $($f:ident),+ }) => {
        impl Add for $t {
            type Output = $t;
            fn add(self, o: $t) -> $t { $t { $($f: self.$f + o.$f),+ } }
        }
        impl Sub for $t {
            type Output = $t;
            fn sub(self, o: $t) -> $t { $t { $($f: self.$f - o.$f),+ } }
        }
        impl Mul<f32> for $t {
            type Output = $t;
            fn mul(self, k: f32) -> $t { $t { $($f: self.$f * k),+ } }
        }
    };
}
vector_ops!(Abc { a, b, c });
vector_ops!(AlphaBeta { alpha, beta });
vector_ops!(Dq { d, q });

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
}
