//! Test support, behind the `testing` feature (for the workspace's own tests; not part of the
//! public API): one small seeded random generator for the simulated sensor noise of the
//! ekf-core and foc test rigs, so that every test draws from the same, reproducible stream.

/// xorshift64* (Vigna, 2016) with the Box-Muller transform for Gaussian draws. Small and
/// deterministic across platforms; statistical quality far beyond what measurement noise in
/// a test needs. Not for cryptography.
#[derive(Clone, Debug)]
pub struct Rng(u64);

impl Rng {
    /// A generator seeded with `seed` (any value; the state is scrambled and never zero).
    pub fn new(seed: u64) -> Self {
        Self(seed.wrapping_mul(0x9E37_79B9_7F4A_7C15) | 1)
    }

    /// Uniform on the open interval (0, 1): 53 random bits, offset by half a step.
    pub fn uniform(&mut self) -> f64 {
        self.0 ^= self.0 >> 12;
        self.0 ^= self.0 << 25;
        self.0 ^= self.0 >> 27;
        let v = self.0.wrapping_mul(0x2545_F491_4F6C_DD1D);
        ((v >> 11) as f64 + 0.5) / (1u64 << 53) as f64
    }

    /// Standard normal (zero mean, unit variance): Box-Muller's cosine branch, two uniform
    /// draws per call.
    pub fn gauss(&mut self) -> f64 {
        let (a, b) = (self.uniform(), self.uniform());
        (-2.0 * a.ln()).sqrt() * (2.0 * core::f64::consts::PI * b).cos()
    }
}

#[cfg(test)]
mod tests {
    use super::Rng;

    #[test]
    fn draws_are_reproducible_and_have_the_stated_moments() {
        let (mut a, mut b) = (Rng::new(3), Rng::new(3));
        assert!((0..100).all(|_| a.uniform().to_bits() == b.uniform().to_bits()));
        let mut r = Rng::new(1);
        let n = 200_000;
        let u: Vec<f64> = (0..n).map(|_| r.uniform()).collect();
        assert!(u.iter().all(|x| *x > 0.0 && *x < 1.0));
        let mean = u.iter().sum::<f64>() / n as f64;
        // Standard error of the mean of U(0,1): sqrt(1/12 / n) = 6.5e-4.
        assert!((mean - 0.5).abs() < 4.0 * 6.5e-4, "{mean}");
        let g: Vec<f64> = (0..n).map(|_| r.gauss()).collect();
        let m = g.iter().sum::<f64>() / n as f64;
        let v = g.iter().map(|x| (x - m) * (x - m)).sum::<f64>() / n as f64;
        // Standard errors: 1/sqrt(n) = 2.2e-3 for the mean, sqrt(2/n) = 3.2e-3 for the variance.
        assert!(m.abs() < 4.0 * 2.2e-3, "{m}");
        assert!((v - 1.0).abs() < 4.0 * 3.2e-3, "{v}");
        // A different seed, a different stream.
        assert_ne!(Rng::new(1).uniform(), Rng::new(2).uniform());
    }
}
