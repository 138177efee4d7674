//! HFI settings: [`HfiConfig`], its defaults from the motor ([`HfiConfig::new`],
//! [`HfiConfig::with_current_noise`]; the rules in the module docs of [`crate::hfi`],
//! "Defaults from the motor") and its checks ([`HfiConfig::validate`]).

use core::f32::consts::PI;

use ekf_core::MotorParams;

use super::blend::long_carrier_period;
use crate::config::{FocConfig, Mode};
use crate::trig::at_most;

/// Which [`HfiConfig`] field is wrong.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum HfiField {
    /// [`HfiConfig::injection_v`].
    InjectionV,
    /// [`HfiConfig::pll_bandwidth_rad_s`].
    PllBandwidth,
    /// [`HfiConfig::half_period_ticks`].
    HalfPeriod,
    /// [`HfiConfig::blend_low_rad_s`].
    BlendLow,
    /// [`HfiConfig::blend_high_rad_s`].
    BlendHigh,
    /// [`HfiConfig::polarity_current_a`].
    PolarityCurrent,
    /// [`HfiConfig::settle_time_s`].
    SettleTime,
    /// [`HfiConfig::pulse_time_s`].
    PulseTime,
    /// The current sensors' noise given to [`HfiConfig::with_current_noise`].
    CurrentNoise,
    /// [`HfiConfig::fusion_sigma_rad`] (finite, 0 or more).
    FusionSigma,
}

/// Why HFI was refused.
#[derive(Clone, Copy, Debug, PartialEq)]
pub enum HfiError {
    /// The motor is not salient enough (`Lq / Ld` given): the carrier's q response is
    /// proportional to `Lq - Ld`, zero for a surface motor. At least 1.1 is required.
    SurfaceMotor {
        /// `Lq / Ld` of the motor.
        saliency: f32,
    },
    /// HFI serves the sensorless mode only.
    SensoredMode,
    /// Only while the controller is idle.
    NotIdle,
    /// The field is NaN, infinite, zero or negative.
    NotPositive(HfiField),
    /// The field is out of range or inconsistent with another (the injection above the
    /// voltage limit, the blend band empty or above the maximum speed, the polarity current
    /// above the current limit, the bandwidth above a tenth of the PWM rate).
    OutOfRange(HfiField),
}

impl core::fmt::Display for HfiError {
    fn fmt(&self, f: &mut core::fmt::Formatter<'_>) -> core::fmt::Result {
        match self {
            HfiError::SurfaceMotor { saliency } => write!(
                f,
                "HFI needs a salient motor (Lq/Ld >= {MIN_SALIENCY}); this one has {saliency}"
            ),
            HfiError::SensoredMode => f.write_str("HFI serves the sensorless mode only"),
            HfiError::NotIdle => f.write_str("HFI can only be changed while idle"),
            HfiError::NotPositive(x) => write!(f, "{x:?} must be finite and positive"),
            HfiError::OutOfRange(x) => write!(f, "{x:?} is out of range"),
        }
    }
}

impl core::error::Error for HfiError {}

/// Longest half period of the carrier, PWM periods ([`HfiConfig::half_period_ticks`]).
pub const MAX_HALF_PERIOD: u8 = 8;

/// Smallest `Lq / Ld` HFI accepts.
pub const MIN_SALIENCY: f32 = 1.1;

/// With HFI on, the observer's online `psi_f`/`Rs` tracking is frozen below this many times
/// [`HfiConfig::blend_high_rad_s`] (`Foc::enable_hfi`): twice the top of the blend band, where
/// the observer's speed is still noisy and the carrier may come back on.
pub const HFI_TRACKING_SPEED_FACTOR: f32 = 2.0;

/// HFI settings (module [`crate::hfi`] gives the defaults, [`HfiConfig::new`]).
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct HfiConfig {
    /// Amplitude of the square-wave carrier on the tracked d axis, V.
    pub injection_v: f32,
    /// PWM periods per half period of the carrier, 1 to [`MAX_HALF_PERIOD`] (carrier frequency
    /// `f_pwm / (2 half_period_ticks)`).
    pub half_period_ticks: u8,
    /// Natural frequency of the tracking loop, rad/s.
    pub pll_bandwidth_rad_s: f32,
    /// Electrical speed (magnitude) below which the angle is HFI's alone, rad/s.
    pub blend_low_rad_s: f32,
    /// Electrical speed above which the angle is the observer's alone and the carrier is off,
    /// rad/s.
    pub blend_high_rad_s: f32,
    /// Magnitude of the two polarity pulses on the d axis, A.
    pub polarity_current_a: f32,
    /// Time the tracking loop settles at standstill (no current) before the pulses, s.
    pub settle_time_s: f32,
    /// Length of each polarity pulse (the second half of it is measured), s; the pulses are
    /// separated by half of it at zero current.
    pub pulse_time_s: f32,
    /// Run the polarity test (`false`: the angle the loop settles on is taken as it is,
    /// which is right only if the rotor's d axis is known to be within 90 deg of the start).
    pub detect_polarity: bool,
    /// Fusion of HFI's angle into the observer (module [`crate::hfi`], "Hand-over band"): standard
    /// deviation of HFI's angle as a per-tick measurement of the observer's angle at observer
    /// weight 0, rad el. (the variance grows as `1 / (1 - weight)`); 0 turns the fusion off
    /// (the default with a long carrier period). Finite, 0 or more.
    pub fusion_sigma_rad: f32,
}

/// Default [`HfiConfig::fusion_sigma_rad`] with a short carrier period (module [`crate::hfi`],
/// "Hand-over band"), rad el.: inside the range that passes the traction IPM's reversal
/// over the noise seeds of `docs/hfi.md` (0.01 to 0.1 rad; off or 0.3 rad do not).
pub const HFI_FUSION_SIGMA_RAD: f32 = 0.03;

/// Peak angle error (rad el.) of the tracking loop after a step `a` of the load's acceleration,
/// times `w_n^2 / a` (triple pole at `-w_n`).
pub const LOAD_STEP_PEAK: f32 = 0.27;

/// Angle noise (RMS, rad el.) [`HfiConfig::with_current_noise`] aims at: 1 deg, so that the
/// largest error over seconds, about four times the RMS, stays within 5 deg.
pub const TARGET_ANGLE_RMS_RAD: f32 = 1.0 * PI / 180.0;

/// Predicted RMS angle noise (rad el.) of the tracking loop for a current noise `sigma` (A per
/// phase, two phases sampled) at the worst rotor orientation (module [`crate::hfi`], "Angle noise").
fn angle_noise_rms(m: &MotorParams<f32>, ts: f32, v: f32, half: u8, w_pll: f32, sigma: f32) -> f32 {
    let y_d = 0.5 * (1.0 / m.ld_h - 1.0 / m.lq_h);
    let n = f32::from(half);
    // eps per unit of noise: the least-squares step estimate's long-run variance is at most
    // 12 / N^2 of a sample's, the worst axis carries 2 sigma^2, eps = step / (2 Ts V Y_d).
    let s_eps = 12.0 / (n * n) * 2.0 * sigma * sigma / (4.0 * ts * ts * v * v * y_d * y_d);
    // Through the loop: its noise bandwidth is 1.03 w_n (Hz for w_n in rad/s).
    crate::trig::sqrt(s_eps * 2.0 * 1.03 * w_pll * ts)
}

/// `a < b` (false for NaN).
fn below(a: f32, b: f32) -> bool {
    a < b
}

/// `Lq / Ld`, or the refusal of a non-salient motor.
fn saliency(m: &MotorParams<f32>) -> Result<f32, HfiError> {
    let s = m.lq_h / m.ld_h;
    if at_most(MIN_SALIENCY, s) {
        Ok(s)
    } else {
        Err(HfiError::SurfaceMotor { saliency: s })
    }
}

impl HfiConfig {
    /// Defaults derived from the controller's configuration and the nominal bus voltage
    /// (module [`crate::hfi`]), for a current sensing of unknown noise. A surface motor is refused
    /// ([`HfiError::SurfaceMotor`]).
    pub fn new(cfg: &FocConfig, u_dc_nominal_v: f32) -> Result<Self, HfiError> {
        Self::derive(cfg, u_dc_nominal_v, None)
    }

    /// Defaults for current sensors of known noise (standard deviation per phase, A; module [`crate::hfi`],
    /// "Defaults from the motor and why"): those of [`new`](Self::new) if their predicted angle noise at the
    /// rotor orientation worst for the two sensors is at most [`TARGET_ANGLE_RMS_RAD`];
    /// otherwise the loop's bandwidth lowered to what a full-torque load step allows and the
    /// shortest half period that meets the target ([`MAX_HALF_PERIOD`] if none does). A negative or
    /// non-finite noise is refused (`OutOfRange(`[`HfiField::CurrentNoise`]`)`).
    pub fn with_current_noise(
        cfg: &FocConfig,
        u_dc_nominal_v: f32,
        current_noise_std_a: f32,
    ) -> Result<Self, HfiError> {
        if !(current_noise_std_a.is_finite() && current_noise_std_a >= 0.0) {
            return Err(HfiError::OutOfRange(HfiField::CurrentNoise));
        }
        Self::derive(cfg, u_dc_nominal_v, Some(current_noise_std_a))
    }

    /// Predicted RMS angle noise of the tracking loop, rad el. (module [`crate::hfi`], "Angle noise"),
    /// for these settings and a current noise of `current_noise_std_a` per phase.
    pub fn predicted_angle_rms_rad(&self, cfg: &FocConfig, current_noise_std_a: f32) -> f32 {
        angle_noise_rms(
            &cfg.motor,
            cfg.ts_s,
            self.injection_v,
            self.half_period_ticks,
            self.pll_bandwidth_rad_s,
            current_noise_std_a,
        )
    }

    fn derive(cfg: &FocConfig, u_dc_nominal_v: f32, noise: Option<f32>) -> Result<Self, HfiError> {
        saliency(&cfg.motor)?;
        let m = &cfg.motor;
        let u_lim = cfg.max_modulation * u_dc_nominal_v * crate::transforms::FRAC_1_SQRT_3;
        let i_lim = cfg.current_limit_a;
        let v_cap = 0.8 * u_lim;
        let v_ripple = 0.1 * i_lim * m.ld_h / cfg.ts_s;
        let mut v = if v_ripple < v_cap { v_ripple } else { v_cap };
        let y_d = 0.5 * (1.0 / m.ld_h - 1.0 / m.lq_h);
        let a_max = m.pole_pairs as f32 * cfg.torque_constant_nm_a() * i_lim / cfg.inertia_kg_m2;
        // The bandwidth for a rule `w` at half period `n`: at most a tenth of the inverse of the
        // loop's delay (the period's estimate, N ticks, plus the computation delay and the
        // sample, 2 ticks), 5 to 50 Hz.
        let limited = |w: f32, n: u8| {
            let w_delay = 0.1 / ((f32::from(n) + 2.0) * cfg.ts_s);
            let w_hi = if w_delay < 2.0 * PI * 50.0 {
                w_delay
            } else {
                2.0 * PI * 50.0
            };
            crate::pi::limit(w, 2.0 * PI * 5.0, w_hi)
        };
        // The saliency signal per half period, `N Ts V Y_d`, at least 3 % of the current
        // limit: longer half periods (up to 4) at the full voltage when one is not enough.
        let mut n: u8 = 1;
        while n < 4 && f32::from(n) * cfg.ts_s * v * y_d < 0.03 * i_lim {
            n += 1;
            v = v_cap;
        }
        // `w_n = sqrt(a_max)`: a full-torque load step costs about `0.27 a_max / w_n^2` = 0.27
        // rad of angle at most.
        let mut w_pll = limited(crate::trig::sqrt(a_max), n);
        if let Some(sigma) = noise
            && !at_most(
                angle_noise_rms(m, cfg.ts_s, v, n, w_pll, sigma),
                TARGET_ANGLE_RMS_RAD,
            )
        {
            // Too noisy: the bandwidth down to what a full-torque load step allows (0.5 rad,
            // within the loop's +-45 deg capture range), then the shortest half period at the
            // full voltage that meets the target.
            let w_load = crate::trig::sqrt(LOAD_STEP_PEAK * a_max / 0.5);
            v = v_cap;
            w_pll = limited(w_load, n);
            while n < MAX_HALF_PERIOD
                && !at_most(
                    angle_noise_rms(m, cfg.ts_s, v, n, w_pll, sigma),
                    TARGET_ANGLE_RMS_RAD,
                )
            {
                n += 1;
                w_pll = limited(w_load, n);
            }
        }
        let h = cfg.startup.handover_speed_rad_s;
        let c = Self {
            injection_v: v,
            half_period_ticks: n,
            pll_bandwidth_rad_s: w_pll,
            blend_low_rad_s: 0.5 * h,
            blend_high_rad_s: h,
            polarity_current_a: 0.8 * cfg.current_limit_a,
            settle_time_s: 0.06,
            pulse_time_s: 0.02,
            detect_polarity: true,
            // With a long carrier period HFI is the weak side at the top of the band (module
            // docs, "Hand-over band"): no fusion.
            fusion_sigma_rad: if long_carrier_period(h, n, cfg.ts_s) {
                0.0
            } else {
                HFI_FUSION_SIGMA_RAD
            },
        };
        c.validate(cfg, u_dc_nominal_v)?;
        Ok(c)
    }

    /// Checks the settings against the controller's configuration ([`HfiError`]).
    pub fn validate(&self, cfg: &FocConfig, u_dc_nominal_v: f32) -> Result<(), HfiError> {
        saliency(&cfg.motor)?;
        if cfg.mode == Mode::Sensored {
            return Err(HfiError::SensoredMode);
        }
        use HfiField as F;
        let positive = [
            (self.injection_v, F::InjectionV),
            (self.pll_bandwidth_rad_s, F::PllBandwidth),
            (self.blend_low_rad_s, F::BlendLow),
            (self.blend_high_rad_s, F::BlendHigh),
            (self.polarity_current_a, F::PolarityCurrent),
            (self.settle_time_s, F::SettleTime),
            (self.pulse_time_s, F::PulseTime),
        ];
        for (x, f) in positive {
            if !(x.is_finite() && x > 0.0) {
                return Err(HfiError::NotPositive(f));
            }
        }
        let u_lim = cfg.max_modulation * u_dc_nominal_v * crate::transforms::FRAC_1_SQRT_3;
        if !(1..=MAX_HALF_PERIOD).contains(&self.half_period_ticks) {
            return Err(HfiError::OutOfRange(F::HalfPeriod));
        }
        if !below(self.injection_v, 0.9 * u_lim) {
            return Err(HfiError::OutOfRange(F::InjectionV));
        }
        if !below(self.pll_bandwidth_rad_s * cfg.ts_s, 0.1 * 2.0 * PI) {
            return Err(HfiError::OutOfRange(F::PllBandwidth));
        }
        if !below(self.blend_low_rad_s, self.blend_high_rad_s) {
            return Err(HfiError::OutOfRange(F::BlendLow));
        }
        if !below(self.blend_high_rad_s, cfg.max_speed_rad_s) {
            return Err(HfiError::OutOfRange(F::BlendHigh));
        }
        if !at_most(self.polarity_current_a, cfg.current_limit_a) {
            return Err(HfiError::OutOfRange(F::PolarityCurrent));
        }
        // At least a few carrier periods per measurement, at most a minute.
        if !(self.settle_time_s >= 20.0 * cfg.ts_s && self.settle_time_s <= 60.0) {
            return Err(HfiError::OutOfRange(F::SettleTime));
        }
        if !(self.pulse_time_s >= 20.0 * cfg.ts_s && self.pulse_time_s <= 60.0) {
            return Err(HfiError::OutOfRange(F::PulseTime));
        }
        if !(self.fusion_sigma_rad.is_finite() && self.fusion_sigma_rad >= 0.0) {
            return Err(HfiError::OutOfRange(F::FusionSigma));
        }
        Ok(())
    }
}
