//! Sensors: the phase-current measurement.
//!
//! The current is sampled at `t_k` (`design.md` section 4): `i_meas[k] = i(t_k) + n[k]`, with
//! `n[k]` white Gaussian noise of standard deviation `noise_std_a` on each of alpha and beta,
//! drawn from a seeded, portable generator (Xoshiro256++, `rand`'s documented reproducible
//! generator, with `rand_distr`'s value-stable `StandardNormal`), so the same seed gives a
//! bit-identical run. Two normals (alpha, then beta) are drawn every sample whatever the
//! standard deviation, so the stream does not depend on it.
//!
//! Not modelled yet: ADC quantization, offset and gain errors, the three-phase shunt geometry
//! (the noise is added in alpha-beta directly).

use rand::SeedableRng;
use rand::rngs::Xoshiro256PlusPlus;
use rand_distr::{Distribution, StandardNormal};

/// Noisy alpha-beta current sensor.
#[derive(Clone, Debug, PartialEq)]
pub struct CurrentSensor {
    noise_std_a: f64,
    rng: Xoshiro256PlusPlus,
}

impl CurrentSensor {
    /// A sensor with noise standard deviation `noise_std_a` (A) seeded with `seed`.
    pub fn new(noise_std_a: f64, seed: u64) -> Self {
        Self {
            noise_std_a,
            rng: Xoshiro256PlusPlus::seed_from_u64(seed),
        }
    }

    /// Noise standard deviation, A.
    pub fn noise_std_a(&self) -> f64 {
        self.noise_std_a
    }

    /// The measurement of the true currents `i_ab_a` (A).
    pub fn measure(&mut self, i_ab_a: [f64; 2]) -> [f64; 2] {
        let std = self.noise_std_a;
        let na: f64 = StandardNormal.sample(&mut self.rng);
        let nb: f64 = StandardNormal.sample(&mut self.rng);
        [i_ab_a[0] + std * na, i_ab_a[1] + std * nb]
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn same_seed_same_noise_and_right_spread() {
        let mut a = CurrentSensor::new(0.02, 7);
        let mut b = CurrentSensor::new(0.02, 7);
        let n = 20_000;
        let mut sum_sq = 0.0;
        for _ in 0..n {
            let ma = a.measure([1.0, -1.0]);
            let mb = b.measure([1.0, -1.0]);
            assert_eq!(ma[0].to_bits(), mb[0].to_bits());
            assert_eq!(ma[1].to_bits(), mb[1].to_bits());
            sum_sq += (ma[0] - 1.0).powi(2) + (ma[1] + 1.0).powi(2);
        }
        let std = (sum_sq / (2.0 * f64::from(n))).sqrt();
        assert!((std - 0.02).abs() < 0.02 * 0.03, "std {std}");
        let mut c = CurrentSensor::new(0.02, 8);
        assert_ne!(
            c.measure([0.0; 2]),
            CurrentSensor::new(0.02, 7).measure([0.0; 2])
        );
    }
}
