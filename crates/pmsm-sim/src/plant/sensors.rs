//! Sensors: phase-current measurement and DC-bus voltage.
//!
//! Two phase currents (`a`, `b`) are sampled at `t_k`, the PWM centre (docs/design.md
//! section 4; with centre-aligned PWM the low-side shunts conduct there and the current
//! ripple crosses its mean). Each channel is
//!
//! ```text
//! i_meas_x = Q( (1 + g_x) i_x + o_x + n_x )
//! ```
//!
//! with gain error `g_x`, offset `o_x` (A), white Gaussian noise `n_x` of standard deviation
//! `noise_std_a`, and `Q` the ADC: `bits` bits over `[-full_scale, +full_scale)` A, mid-tread
//! rounding to the nearest code and clipping at the ends (`bits = 0`: no quantization). The
//! third phase is reconstructed, `i_c = -i_a - i_b`, and the controller's alpha-beta currents
//! are the Clarke transform of the three.
//!
//! The noise comes from a seeded, portable generator (Xoshiro256++, `rand`'s documented
//! reproducible generator, with `rand_distr`'s value-stable `StandardNormal`): the same seed
//! gives a bit-identical run. Two normals (a, then b) are drawn every sample whatever the
//! settings, so the stream does not depend on them.
//!
//! The DC-bus voltage is measured exactly (the value held over the coming period).

use glam::DVec2;
use rand::SeedableRng;
use rand::rngs::Xoshiro256PlusPlus;
use rand_distr::{Distribution, StandardNormal};
use serde::{Deserialize, Serialize};

use crate::error::FieldError;
use crate::plant::frames::clarke;

/// Current-sensor settings (`[sensors]` in a scenario).
#[derive(Clone, Copy, Debug, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields, default)]
pub struct SensorConfig {
    /// Noise standard deviation on each phase channel, A.
    pub current_noise_std_a: f64,
    /// Gain error of channels `[a, b]`, fraction (0.01 reads 1 % high).
    pub gain_error: [f64; 2],
    /// Offset of channels `[a, b]`, A.
    pub offset_a: [f64; 2],
    /// ADC resolution, bits (0: no quantization).
    pub adc_bits: u32,
    /// ADC full scale: the range is `[-adc_full_scale_a, +adc_full_scale_a)`, A.
    pub adc_full_scale_a: f64,
}

impl Default for SensorConfig {
    /// Ideal: no noise, no errors, no quantization.
    fn default() -> Self {
        Self {
            current_noise_std_a: 0.0,
            gain_error: [0.0; 2],
            offset_a: [0.0; 2],
            adc_bits: 0,
            adc_full_scale_a: 0.0,
        }
    }
}

impl SensorConfig {
    /// Checks the settings; errors name the field (`sensors.<name>`).
    pub fn validate(&self) -> Result<(), FieldError> {
        let f = |name: &str| format!("sensors.{name}");
        let s = self.current_noise_std_a;
        if !(s.is_finite() && s >= 0.0) {
            return Err(FieldError::new(
                f("current_noise_std_a"),
                format!("must be finite and >= 0, is {s}"),
            ));
        }
        for (i, g) in self.gain_error.iter().enumerate() {
            if !(g.is_finite() && *g > -1.0) {
                return Err(FieldError::new(
                    format!("sensors.gain_error[{i}]"),
                    format!("must be finite and > -1, is {g}"),
                ));
            }
        }
        for (i, o) in self.offset_a.iter().enumerate() {
            if !o.is_finite() {
                return Err(FieldError::new(
                    format!("sensors.offset_a[{i}]"),
                    format!("must be finite, is {o}"),
                ));
            }
        }
        if self.adc_bits > 24 {
            return Err(FieldError::new(
                f("adc_bits"),
                format!("must be 0 (ideal) to 24, is {}", self.adc_bits),
            ));
        }
        if self.adc_bits > 0 && !(self.adc_full_scale_a.is_finite() && self.adc_full_scale_a > 0.0)
        {
            return Err(FieldError::new(
                f("adc_full_scale_a"),
                format!(
                    "must be finite and > 0 when adc_bits > 0, is {}",
                    self.adc_full_scale_a
                ),
            ));
        }
        Ok(())
    }
}

/// Faults acting on the two channels `[a, b]` for one sample (module
/// [`faults`](crate::plant::fault_injection)): `i_meas_x = Q((1 + g_x) gain_x i_x + o_x + offset_x + n_x)`,
/// then replaced by `value_a` when that is set (a stuck channel, a missing sample as NaN, a
/// glitch).
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct ChannelFaults {
    /// Gain multiplier on top of the configured gain error.
    pub gain: [f64; 2],
    /// Offset on top of the configured one (drift, noise burst), A.
    pub offset_a: [f64; 2],
    /// The channel's output replaced by this value (after the ADC), A.
    pub value_a: [Option<f64>; 2],
}

impl Default for ChannelFaults {
    /// No fault.
    fn default() -> Self {
        Self {
            gain: [1.0; 2],
            offset_a: [0.0; 2],
            value_a: [None; 2],
        }
    }
}

/// One current sample.
#[derive(Clone, Copy, Debug, PartialEq, Serialize)]
pub struct CurrentSample {
    /// Measured phase currents `[a, b, c]` (`c = -a - b`), A.
    pub i_abc_a: [f64; 3],
    /// Their Clarke transform (alpha, beta), A.
    pub i_ab_a: DVec2,
}

/// The phase-current sensor (module docs).
#[derive(Clone, Debug, PartialEq)]
pub struct CurrentSensor {
    cfg: SensorConfig,
    lsb_a: f64,
    code_min: f64,
    code_max: f64,
    rng: Xoshiro256PlusPlus,
}

impl CurrentSensor {
    /// A sensor seeded with `seed`.
    pub fn new(cfg: SensorConfig, seed: u64) -> Self {
        let (lsb_a, code_min, code_max) = if cfg.adc_bits > 0 {
            let half = f64::from(1u32 << (cfg.adc_bits - 1));
            (cfg.adc_full_scale_a / half, -half, half - 1.0)
        } else {
            (0.0, 0.0, 0.0)
        };
        Self {
            cfg,
            lsb_a,
            code_min,
            code_max,
            rng: Xoshiro256PlusPlus::seed_from_u64(seed),
        }
    }

    /// The settings.
    pub fn config(&self) -> &SensorConfig {
        &self.cfg
    }

    /// ADC step, A (0 without quantization).
    pub fn lsb_a(&self) -> f64 {
        self.lsb_a
    }

    #[inline]
    fn channel(&self, i: f64, ch: usize, noise: f64) -> f64 {
        let c = &self.cfg;
        let v = (1.0 + c.gain_error[ch]) * i + c.offset_a[ch] + c.current_noise_std_a * noise;
        self.adc(v)
    }

    /// The ADC: quantization and clipping (none with `adc_bits = 0`).
    #[inline]
    fn adc(&self, v: f64) -> f64 {
        if self.lsb_a > 0.0 {
            (v / self.lsb_a).round().clamp(self.code_min, self.code_max) * self.lsb_a
        } else {
            v
        }
    }

    /// The measurement of the true phase currents `i_abc_a` (A).
    #[inline]
    pub fn measure(&mut self, i_abc_a: [f64; 3]) -> CurrentSample {
        let na: f64 = StandardNormal.sample(&mut self.rng);
        let nb: f64 = StandardNormal.sample(&mut self.rng);
        let a = self.channel(i_abc_a[0], 0, na);
        let b = self.channel(i_abc_a[1], 1, nb);
        let abc = [a, b, -a - b];
        CurrentSample {
            i_abc_a: abc,
            i_ab_a: DVec2::from(clarke(abc)),
        }
    }

    /// [`measure`](Self::measure) with channel faults (the same noise stream).
    pub fn measure_with(&mut self, i_abc_a: [f64; 3], f: &ChannelFaults) -> CurrentSample {
        let na: f64 = StandardNormal.sample(&mut self.rng);
        let nb: f64 = StandardNormal.sample(&mut self.rng);
        let c = self.cfg;
        let mut out = [0.0; 2];
        for (ch, (i, n)) in [(i_abc_a[0], na), (i_abc_a[1], nb)].into_iter().enumerate() {
            out[ch] = match f.value_a[ch] {
                Some(v) => v,
                None => self.adc(
                    (1.0 + c.gain_error[ch]) * f.gain[ch] * i
                        + c.offset_a[ch]
                        + f.offset_a[ch]
                        + c.current_noise_std_a * n,
                ),
            };
        }
        let abc = [out[0], out[1], -out[0] - out[1]];
        CurrentSample {
            i_abc_a: abc,
            i_ab_a: DVec2::from(clarke(abc)),
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn noisy(std: f64) -> SensorConfig {
        SensorConfig {
            current_noise_std_a: std,
            ..SensorConfig::default()
        }
    }

    #[test]
    fn same_seed_same_noise_and_right_spread() {
        let mut a = CurrentSensor::new(noisy(0.02), 7);
        let mut b = CurrentSensor::new(noisy(0.02), 7);
        let n = 20_000;
        let mut sum_sq = 0.0;
        for _ in 0..n {
            let ma = a.measure([1.0, -1.0, 0.0]);
            let mb = b.measure([1.0, -1.0, 0.0]);
            assert_eq!(ma.i_abc_a[0].to_bits(), mb.i_abc_a[0].to_bits());
            assert_eq!(ma.i_abc_a[1].to_bits(), mb.i_abc_a[1].to_bits());
            sum_sq += (ma.i_abc_a[0] - 1.0).powi(2) + (ma.i_abc_a[1] + 1.0).powi(2);
        }
        let std = (sum_sq / (2.0 * f64::from(n))).sqrt();
        assert!((std - 0.02).abs() < 0.02 * 0.03, "std {std}");
        let mut c = CurrentSensor::new(noisy(0.02), 8);
        assert_ne!(
            c.measure([0.0; 3]),
            CurrentSensor::new(noisy(0.02), 7).measure([0.0; 3])
        );
    }

    #[test]
    fn gain_offset_and_quantization() {
        let cfg = SensorConfig {
            current_noise_std_a: 0.0,
            gain_error: [0.01, -0.02],
            offset_a: [0.05, 0.0],
            adc_bits: 12,
            adc_full_scale_a: 8.0,
        };
        let mut s = CurrentSensor::new(cfg, 1);
        let lsb = 16.0 / 4096.0;
        assert_eq!(s.lsb_a(), lsb);
        let m = s.measure([2.0, -1.0, -1.0]);
        // a: 1.01 * 2 + 0.05 = 2.07 -> nearest code 530 (2.0703125).
        assert_eq!(m.i_abc_a[0], 530.0 * lsb);
        // b: -0.98 -> code -251 (-0.98046875).
        assert_eq!(m.i_abc_a[1], -251.0 * lsb);
        assert_eq!(m.i_abc_a[2], -m.i_abc_a[0] - m.i_abc_a[1]);
        // Clipping at the ends of the range.
        let m = s.measure([100.0, -100.0, 0.0]);
        assert_eq!(m.i_abc_a[0], 2047.0 * lsb);
        assert_eq!(m.i_abc_a[1], -8.0);
    }

    #[test]
    fn invalid_settings_name_their_field() {
        let mut c = noisy(-1.0);
        assert_eq!(
            c.validate().map_err(|e| e.field),
            Err("sensors.current_noise_std_a".to_string())
        );
        c.current_noise_std_a = 0.0;
        c.adc_bits = 12;
        assert_eq!(
            c.validate().map_err(|e| e.field),
            Err("sensors.adc_full_scale_a".to_string())
        );
    }
}
