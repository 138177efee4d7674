//! High-frequency injection (HFI): rotor angle and speed of a salient motor at standstill and
//! low speed, where the back-EMF the observer needs is too small, with magnet polarity
//! detection.
//!
//! # Method: pulsating square wave on the estimated d axis, a fraction of the PWM rate
//!
//! Each tick adds `u_h[k] = V_h s[k] (cos phi_k, sin phi_k)` to the stator voltage (alpha-beta):
//! `s[k]` is `+1` for `N` ticks and `-1` for `N` ticks ([`HfiConfig::half_period_ticks`], 1 to
//! 8: carrier `f_pwm / (2 N)`, e.g. 10 kHz at 20 kHz PWM with `N = 1`, 1.67 kHz at 10 kHz with
//! `N = 3`), and `phi_k = theta_hat + w_hat advance Ts` is the tracked d axis at the middle of
//! the period the voltage is applied in (the controller's own angle advance, module
//! [`crate::controller`]).
//!
//! **Why a square wave and not a sinusoid.** (1) The response is demodulated from sample
//! differences and a mean over one carrier period: no band-pass or low-pass filter, no phase
//! to tune, and the response is in the very next samples, so the tracking loop can be fast.
//! (2) The same mean over a period separates the fundamental from the carrier (a comb notch
//! at the carrier and its harmonics), so the current loops keep their bandwidth and gain
//! `N - 1/2` periods of delay. (3) For a given voltage the current ripple is the smallest the
//! PWM can make (`N Ts V_h / L` peak to peak) and, with `N = 1`, the carrier sits at the top of
//! the audible band or above it. A sinusoid at `f_pwm / 8` needs filters whose delay limits
//! the tracking bandwidth (Jang 2003, Yoon 2011 compare the two). A longer half period `N`
//! raises the signal-to-noise ratio as `N` at a given voltage with the least-squares demodulation (the current moves for `N`
//! periods between the sign changes where the information is) and the ripple as `N`: the
//! choice for motors of low saliency or noisy current sensing.
//!
//! # Equations
//!
//! At the carrier frequency the resistance and the speed terms are negligible next to the
//! inductive ones, so in the rotor frame `di/dt = diag(1/Ld, 1/Lq) u`. A voltage `V` along an
//! axis `phi` that lies `e = theta - phi` behind the rotor's d axis gives, in the `phi`
//! frame (`Y = 1/L`):
//!
//! ```text
//! di_phi,d / dt = V (Y_s + Y_d cos 2e),   di_phi,q / dt = V Y_d sin 2e
//! Y_s = (1/Ld + 1/Lq) / 2,  Y_d = (1/Ld - 1/Lq) / 2 = (Lq - Ld) / (2 Ld Lq)
//! ```
//!
//! The q part is proportional to the angle error times the saliency `Lq - Ld`, and zero for a
//! surface motor ([`HfiError::SurfaceMotor`]). Each sample difference, signed with the carrier
//! applied over it and projected on that carrier's axis, `y[k] = s_a (i[k] - i[k-1])` in the
//! `phi` frame, is one carrier step plus the fundamental's change; the fundamental's change
//! cancels in the mean over one carrier period (the signs balance), leaving
//!
//! ```text
//! mean_2N(y) = Ts V (Y_s + Y_d cos 2e,  Y_d sin 2e)
//! ```
//!
//! (for `N = 1` this is the second difference `(s_a / 2) (i[k] - 2 i[k-1] + i[k-2])`; for longer
//! half periods the mean is replaced by least-squares weights, below). `s_a`
//! is the sign of the voltage applied over `[t_k-1, t_k)`, computed two ticks ago with the
//! one-period computation delay, one tick ago without it (a short history keeps sign and
//! axis). The normalised error `eps = mean(y)_q / (2 Ts V Y_d) = sin(2e) / 2` is `e` for small
//! errors. The d part, `Ts V / Ld,inc` at `e = 0`, is the incremental d-axis admittance that
//! the polarity test compares. The carrier's own current is the measured step accumulated
//! with the applied signs, less its period mean: the sample less it is the fundamental at the
//! sample's time, which the controller's observer is fed ([`HfiTracker::carrier_current`]).
//!
//! # Demodulation by least squares
//!
//! The plain mean of the `2N` signed steps telescopes to the samples next to the carrier's
//! sign changes: it uses 2 samples of `2N + 1`. Every tick the tracker instead fits the last
//! `2N + 1` samples (each axis of the `phi` frame) with `a + b j + c T_j`, where `T_j` is the
//! carrier's current (the applied signs accumulated) and `a + b j` the fundamental (offset and
//! slope, as before), and takes `c`, the carrier step: weights `T_perp / |T_perp|^2` on the
//! samples (`T_perp`: `T` less its projection on `1` and `j`), turned into weights of the
//! signed steps, a table per window phase computed once ([`HfiTracker::new`]). For `N = 1`
//! they are the mean (three samples, three unknowns); for `N = 4` the long-run noise variance
//! of the step falls to 0.67 of the mean's (12/N^2 for long half periods), the angle noise
//! RMS to 0.82 of it (measured on the industrial motor: 2.11 -> 1.75 deg RMS).
//!
//! The fundamental's slope is taken out in the fixed frame first. Each step is projected on
//! the axis its carrier was applied along, and that axis moves within the window (the loop
//! corrects the angle every tick), so a slope constant in alpha-beta, `b`, is not constant in
//! the projected steps: the weights, which cancel a constant step, let through
//! `sum w_j s_j R(-phi_j) b`, the slope times the axis' wobble. The fundamental's slope
//! is far larger than the carrier's q response when the current loops move (on the
//! firmware's industrial IPM at 20 kHz, `N = 4`, the fundamental's q current changes by 0.06 A
//! per period in the blend band, ten times the q response of a 3 deg error), and the leak
//! there biased the angle with the speed and drove the speed to three times its reference.
//! The tracker therefore subtracts that sum with `b` the mean step over the window,
//! `(i[k] - i[k-2N]) / 2N`, in which the carrier cancels: exact for a still axis, where the
//! sum is zero.
//!
//! # Angle noise
//!
//! The current sensors' noise (`sigma` per phase, two phases sampled: `c = -a - b`) is not
//! the same on every axis: its variance along an axis at `psi` from phase a is
//! `sigma^2 (4/3 - cos(2 psi) / 3 + sin(2 psi) / sqrt 3)`, from `2/3` to `2 sigma^2`. The angle
//! information is the q response, so the angle noise depends on the rotor's orientation by
//! `sqrt 3` (measured on the industrial motor at rest: 1.16 to 1.90 deg RMS over rotor
//! angles, the same noise realization), which is why a sweep of the loop bandwidth at one
//! start angle is not monotonic (the rotor comes to rest at another angle). Through the
//! loop (noise bandwidth `1.03 w_n` Hz for `w_n` in rad/s) the predicted angle noise at the
//! worst orientation is
//!
//! ```text
//! sigma_theta^2 = (12 / N^2) 2 sigma^2 / (2 Ts V Y_d)^2 * 2 (1.03 w_n) Ts
//! ```
//!
//! (it scales exactly as `sigma^2` in the simulator; measured on the industrial motor at
//! `N = 4`, `w_n = 82`: 1.9 deg RMS at the worst orientation, predicted 1.9). The largest
//! error over a few seconds is about four times the RMS.
//!
//! # Tracking loop (PLL with the drive's torque fed forward)
//!
//! ```text
//! theta += Ts (w + Kp eps)                            Kp = 3 w_n
//! w     += Ki Ts eps + Ts (a_ff - a_L)                Ki = 3 w_n^2
//! a_L   -= K3 Ts eps                                  K3 = w_n^3   (poles at -w_n, triple)
//! a_ff   = p T* / J = p k_t i_T / J                   (the speed loop's torque command)
//! ```
//!
//! A mechanical model in the loop (Lorenz's observer structure): the acceleration the drive's
//! own torque command gives is fed forward, and `a_L` estimates what the load (and friction,
//! and an inertia error) take away. The loop then only has to follow the load, not the
//! drive's own moves, so its bandwidth `w_n` ([`HfiConfig::pll_bandwidth_rad_s`]) can stay
//! low, which is what keeps the sensor noise out of the angle: a plain type-2 PLL fast enough
//! for the speed loop passed about 4.9 deg RMS of angle noise on the 1.4-saliency motor of
//! the tests. The speed output is `w` (no proportional noise). With `J` unknown, `a_ff = 0`
//! gives a type-3 loop that still tracks any speed ramp without error. `eps` is clamped to `+-1` so that a noise spike cannot throw the
//! angle. The loop has two stable points, `e = 0` and `e = pi`: the carrier cannot see the
//! magnet's polarity.
//!
//! # Magnet polarity
//!
//! Run once at standstill after the loop has settled: two current pulses along the tracked
//! d axis, `+I_p` then `-I_p` ([`HfiConfig::polarity_current_a`]), with the carrier on. The
//! pulse that adds to the magnet's flux saturates the d-axis iron and lowers its incremental
//! inductance, so the carrier's d response (`Ts V / Ld,inc`) is larger. If the response under
//! `-I_p` is the larger, the tracked axis points at the south pole and the angle is turned by
//! `pi`. The ratio of the two mean responses is reported as the contrast
//! ([`HfiStatus::polarity_contrast`]); a motor without d-axis saturation gives a contrast near 1
//! and the decision is then a coin toss (a real motor saturates by several percent at rated
//! current; the simulator's plant has an optional saturation model for this test).
//!
//! # Hand-over band
//!
//! From `blend_low_rad_s` to `blend_high_rad_s` the control angle is HFI's plus the observer's
//! weight times the observer's difference from it, the weight linear in the speed magnitude
//! (0 at the bottom, 1 at the top; the carrier goes off above the top, by HFI's speed, and
//! comes back below 80 % of it, by the observer's low-passed speed). The speed the weight
//! follows is HFI's own tracked speed: the observer's is noisiest at the bottom of its range
//! and would feed back into its own weight. With a long carrier period, where the rotor turns
//! more than [`HFI_PERIOD_ANGLE_RAD`] (0.05 rad el.) per carrier period at the top of the band
//! (`blend_high 2 N Ts`), the weight follows the faster of HFI's speed and the observer's
//! low-passed speed instead. Measured on the industrial IPM of the tests (`N = 7` at 10 kHz:
//! 0.12 rad per period at the top of its 43-87 rad/s band) over the reversal on noise seeds 1,
//! 4 and 7: HFI's angle error is within 2 deg RMS below 50 rad/s el. and 6-18 deg RMS above
//! it (its speed lags the rotor's by up to 20 rad/s el. while the speed grows), where the
//! observer is within 2 deg; every seed's largest error sat there (1.87-1.92 s, rotor at
//! -55 to -84 rad/s el., HFI's speed stuck near -58, weight 0.32-0.47 from that lagging
//! speed, HFI 19-26 deg off, the observer within 3 deg). Following the faster estimate gives
//! the observer the weight of the rotor's actual speed there. The traction IPM (`N = 2` at
//! 20 kHz, 0.016 rad per period) keeps HFI's speed: its observer is the weak side inside the
//! band (module docs of `pmsm-sim`'s `tests/hfi.rs`).
//!
//! **HFI's angle fused into the observer.** The blend mixes the two outputs only: inside the
//! band the observer can drift away from HFI on its own, and the control angle follows it by
//! its weight. With a short carrier period the controller therefore also gives the observer
//! HFI's angle as a measurement, every tick while HFI has a say (tracking, carrier on,
//! weight below 1): one scalar Kalman correction of the observer's angle
//! (`ekf_core::PmsmObserver::correct_angle`; the speed moves with it through their
//! covariance) of variance `sigma_f^2 / (1 - weight)` (the last tick's weight;
//! [`HfiConfig::fusion_sigma_rad`], default [`HFI_FUSION_SIGMA_RAD`] = 0.03 rad): tight at
//! the bottom of the band, gone at the top, so that the observer arrives at the carrier's
//! switch-off where HFI is, its speed consistent with it. Measured on the traction IPM at the
//! preset's sizing (250 A, ADC 400 A) over the reversal of `tests/hfi.rs`, noise seeds 1-24:
//! 21 of 24 within the bounds without it (seeds 5, 19, 24 at 1302, 1515, 1282 rpm speed
//! error; on seed 5 the observer drifts off inside the band, `tests/hfi.rs`), 24 of 24 with
//! it (max 9.0 deg el., 35 rpm); at 180 A with a 300 A ADC 24 of 24 (max 3.5 deg, 30 rpm;
//! seeds 1-8 passed before too). Other values of `sigma_f` (measured with an earlier rounding
//! of the same update, on which 0.03 passed all 24 as well; seeds 1-8, and 9-24 from 0.01 to
//! 0.1): 0.0003, 0.003, 0.07, 0.15, 0.2 pass 1-8; 0.05 and 0.1 pass all 24 (0.1 at 14.99 deg
//! on seed 22, the bound is 15); 0.001 fails seed 2, 0.01 seed 14, 0.02 seed 11 (23-27 deg,
//! 474-536 rpm; on the one looked at, seed 2 at 0.001, the observer puts the carrier's
//! switch-off transient into its speed, +208 rad/s el. within a tick, and the speed loop
//! drops the torque), 0.3 seed 1 (2102 rpm). Off with a long carrier
//! period (the same test as the weight's above): there HFI is the weak side at the top of
//! the band, and fusing it (0.1 rad) took the industrial IPM from 8 to 4 of seeds 1-8
//! within 15 deg.
//!
//! # Current feedback and voltage
//!
//! While the carrier is on, the current loops see the mean of the last two samples (the
//! carrier removed), and their voltage limit is lowered by `V_h` so that the sum stays within
//! the modulation limit.
//!
//! # Defaults from the motor ([`HfiConfig::new`])
//!
//! - `V_h`: the voltage whose carrier ripple is 10 % of the current limit peak to peak on the
//!   d axis, `0.1 I_lim Ld / Ts`, at most 80 % of the voltage limit at the nominal bus;
//! - half period `N` ticks ([`HfiConfig::new`], sensor noise unknown): 1 (`f_pwm / 2`) unless the saliency signal of one period,
//!   `Ts V_h Y_d`, is below 3 % of the current limit (the sensor's noise scales with its full
//!   scale, which scales with the current limit); then the smallest `N <= 4` that reaches it,
//!   at the full 80 % voltage. Longer half periods raise the signal-to-noise ratio as `N`
//!   at a given voltage, and the ripple as `N`. The traction motor of the tests (Lq/Ld 3)
//!   gets `N = 2` at its preset's sizing (5 kHz at 20 kHz PWM), the industrial one (Lq/Ld
//!   1.4, 12 A limit) `N = 4` (1.25 kHz at 10 kHz);
//! - tracking loop: `w_n = sqrt(a_max)`, `a_max = p k_t I_lim / J` the acceleration of a
//!   full-torque step, so that a full-torque load step costs about
//!   [`LOAD_STEP_PEAK`]` a_max / w_n^2 = 0.27` rad of angle at most (the triple-pole loop's
//!   peak; within the loop's +-45 deg capture range), limited to 5-50 Hz and to
//!   `0.1 / ((N + 2) Ts)` (the loop's delay: the period's estimate and the computation delay);
//! - with the sensors' noise known ([`HfiConfig::with_current_noise`]): the above if its
//!   predicted angle noise ("Angle noise") is within [`TARGET_ANGLE_RMS_RAD`] (1 deg);
//!   otherwise the bandwidth lowered to what the load step allows, `0.5` rad
//!   (`w_n = sqrt(0.54 a_max)`), the full voltage, and the shortest `N` (up to 8) that meets
//!   the target. The industrial motor of the tests (50 mA noise) gets `N = 7` (714 Hz) and
//!   `w_n` 60 rad/s instead of `N = 4`, 82 rad/s: the hold under rated load goes from 2.1 to
//!   0.6 deg RMS (max 7.4-9.8 to 2.1-2.3 deg over seeds 1-4), at 1.75x the current ripple and
//!   a slower, noisier hand-over band (module docs of `pmsm-sim`'s `tests/hfi.rs`). The
//!   traction motor keeps its defaults;
//! - hand-over band to the observer: from half the start-up hand-over speed (observer weight 0)
//!   to the hand-over speed (weight 1; carrier off above it, by HFI's speed; back on below
//!   80 % of it, by the observer's speed low-passed at the tracking loop's bandwidth, which
//!   also seeds the tracker's speed: the observer's raw speed at the bottom of its range
//!   toggled the carrier and threw the tracker off on the noisy traction motor);
//! - HFI's angle fused into the observer at `sigma_f = `[`HFI_FUSION_SIGMA_RAD`] (0.03 rad)
//!   with a short carrier period, not at all with a long one ("Hand-over band");
//! - the observer's online `psi_f`/`Rs` tracking frozen below
//!   [`HFI_TRACKING_SPEED_FACTOR`]` = 2` times the top of the band (`Foc::enable_hfi`
//!   rebuilds it so; `disable_hfi` restores it): measured on the traction motor, a flux
//!   estimate let loose at 7 % of rated speed fell by 45 % within 2 ms, and the drive lost
//!   the reversal by pi;
//! - polarity pulses: `0.8 I_lim`, 20 ms each, after 60 ms of settling.

use core::f32::consts::PI;

use ekf_core::MotorParams;

use crate::config::{ComputationDelay, FocConfig, Mode};
use crate::transforms::{AlphaBeta, Dq};
use crate::trig::{add_angles, at_most, max2, sin_cos, sin_cos_small, wrap};

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

/// Length of the tracker's history rings: one carrier period at the longest half period.
const RING: usize = 2 * MAX_HALF_PERIOD as usize;

/// Smallest `Lq / Ld` HFI accepts.
pub const MIN_SALIENCY: f32 = 1.1;

/// With HFI on, the observer's online `psi_f`/`Rs` tracking is frozen below this many times
/// [`HfiConfig::blend_high_rad_s`] (`Foc::enable_hfi`): twice the top of the blend band, where
/// the observer's speed is still noisy and the carrier may come back on.
pub const HFI_TRACKING_SPEED_FACTOR: f32 = 2.0;

/// HFI settings (module docs give the defaults, [`HfiConfig::new`]).
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
    /// Fusion of HFI's angle into the observer (module docs, "Hand-over band"): standard
    /// deviation of HFI's angle as a per-tick measurement of the observer's angle at observer
    /// weight 0, rad el. (the variance grows as `1 / (1 - weight)`); 0 turns the fusion off
    /// (the default with a long carrier period). Finite, 0 or more.
    pub fusion_sigma_rad: f32,
}

/// Default [`HfiConfig::fusion_sigma_rad`] with a short carrier period (module docs,
/// "Hand-over band"), rad el.: the middle of the values that passed the traction IPM's
/// reversal on noise seeds 1-24.
pub const HFI_FUSION_SIGMA_RAD: f32 = 0.03;

/// Peak angle error (rad el.) of the tracking loop after a step `a` of the load's acceleration,
/// times `w_n^2 / a` (triple pole at `-w_n`).
pub const LOAD_STEP_PEAK: f32 = 0.27;

/// Angle noise (RMS, rad el.) [`HfiConfig::with_current_noise`] aims at: 1 deg, so that the
/// largest error over seconds, about four times the RMS, stays within 5 deg.
pub const TARGET_ANGLE_RMS_RAD: f32 = 1.0 * PI / 180.0;

/// Predicted RMS angle noise (rad el.) of the tracking loop for a current noise `sigma` (A per
/// phase, two phases sampled) at the worst rotor orientation (module docs, "Angle noise").
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
    /// (module docs), for a current sensing of unknown noise. A surface motor is refused
    /// ([`HfiError::SurfaceMotor`]).
    pub fn new(cfg: &FocConfig, u_dc_nominal_v: f32) -> Result<Self, HfiError> {
        Self::derive(cfg, u_dc_nominal_v, None)
    }

    /// Defaults for current sensors of known noise (standard deviation per phase, A; module
    /// docs, "Defaults"): those of [`new`](Self::new) if their predicted angle noise at the
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

    /// Predicted RMS angle noise of the tracking loop, rad el. (module docs, "Angle noise"),
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

    /// Checks the settings against the controller's configuration (module [`HfiError`]).
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

/// One carrier period as it was applied: sign and axis (sine, cosine).
#[derive(Clone, Copy, Debug, Default, PartialEq)]
struct Carrier {
    sign: f32,
    sin: f32,
    cos: f32,
    /// Position in the carrier period (0 to `2 N - 1`).
    phase: u8,
}

/// Least-squares weights of the demodulation (module docs, "Demodulation by least
/// squares"): `w[p0][p]` weighs the signed step `y` applied at carrier phase `p` in the window
/// of one period whose oldest step was applied at phase `p0` (`half` ticks per half period).
fn ls_weights(half: u8) -> [[f32; RING]; RING] {
    let half = usize::from(half.clamp(1, MAX_HALF_PERIOD));
    let n = 2 * half;
    let sign = |p: usize| if p % n < half { 1.0_f32 } else { -1.0 };
    let mut w = [[0.0_f32; RING]; RING];
    if half == 1 {
        // Three samples, three unknowns: the second difference, `y` weighed 1/2 (exactly).
        w[0][..2].fill(0.5);
        w[1][..2].fill(0.5);
        return w;
    }
    for (p0, row) in w.iter_mut().enumerate().take(n) {
        // Samples j = 0..=n of the window; the carrier's accumulated current T_j (a unit
        // step per tick, signed).
        let mut t = [0.0_f32; RING + 1];
        for j in 1..=n {
            t[j] = t[j - 1] + sign(p0 + j - 1);
        }
        // T less its projection on the fundamental's constant and slope (orthogonal basis
        // 1 and j - n/2 over the n + 1 samples).
        let m = n as f32 + 1.0;
        let jc = |j: usize| j as f32 - 0.5 * n as f32;
        let (mut st, mut stj, mut sjj) = (0.0, 0.0, 0.0);
        for (j, tj) in t.iter().enumerate().take(n + 1) {
            st += tj;
            stj += tj * jc(j);
            sjj += jc(j) * jc(j);
        }
        let mut r = [0.0_f32; RING + 1];
        let mut rr = 0.0;
        for j in 0..=n {
            r[j] = t[j] - st / m - stj / sjj * jc(j);
            rr += r[j] * r[j];
        }
        // Sample weights r_j / |r|^2 (they sum to zero) as weights of the differences:
        // v_j = sum_{m >= j} w_m for the step into sample j; y_j = s_j (i_j - i_j-1).
        let mut v = 0.0;
        for j in (1..=n).rev() {
            v += r[j] / rr;
            let p = (p0 + j - 1) % n;
            row[p] = v * sign(p0 + j - 1);
        }
    }
    w
}

/// The carrier's response in one demodulation (module docs), A per period of carrier step:
/// `d`: `Ts V / Ld,inc` at zero error; `q`: `Ts V Y_d sin 2e`.
#[derive(Clone, Copy, Debug, Default, PartialEq)]
pub struct Response {
    /// d response along the injection axis, A.
    pub d: f32,
    /// q response, A.
    pub q: f32,
    /// Normalised angle error `sin(2e) / 2`, clamped to `+-1`.
    pub eps: f32,
}

/// The HFI angle tracker (module docs): carrier generation, demodulation, PLL. Pure: it sees
/// only the currents it is given and returns the voltage to add.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct HfiTracker {
    v: f32,
    ts: f32,
    kp: f32,
    ki_t: f32,
    k3_t: f32,
    /// `1 / (2 Ts V Y_d)`.
    inv_scale: f32,
    advance_s: f32,
    one_period_delay: bool,
    theta: f32,
    omega_i: f32,
    /// Estimated load (disturbance) acceleration, rad/s^2 el.
    load: f32,
    sign: f32,
    /// Ticks per half period of the carrier (1 to 4), and per period.
    half: u8,
    period: u8,
    /// Position in the carrier period of the next carrier.
    phase: u8,
    /// Carrier computed one and two ticks ago.
    hist: [Carrier; 2],
    /// The last sample `i[k-1]`.
    i_prev: AlphaBeta,
    /// The last `period` samples and demodulated steps (ring, written at `pos`).
    i_ring: [AlphaBeta; RING],
    y_ring: [Dq; RING],
    /// Carrier phase of each step in `y_ring`, and the least-squares weights ([`ls_weights`]).
    p_ring: [u8; RING],
    /// The signed carrier axis of each step in `y_ring`, `s (cos phi, sin phi)`.
    a_ring: [AlphaBeta; RING],
    weights: [[f32; RING]; RING],
    /// The carrier's current predicted from the measured step (accumulated), its last
    /// `period` values, and the centred value of the last sample (module docs).
    tri: AlphaBeta,
    tri_ring: [AlphaBeta; RING],
    tri_centred: AlphaBeta,
    pos: u8,
    /// Consecutive accepted samples (saturating), consecutive demodulated steps.
    valid: u8,
    y_count: u8,
    last: Response,
}

impl HfiTracker {
    /// A tracker for `motor` at the PWM period `ts_s` with the carrier `injection_v`, the loop
    /// bandwidth `pll_bandwidth_rad_s`, and the controller's delay and angle advance
    /// (periods). Angle and speed start at zero.
    #[allow(clippy::too_many_arguments)]
    pub fn new(
        motor: &MotorParams<f32>,
        ts_s: f32,
        injection_v: f32,
        half_period_ticks: u8,
        pll_bandwidth_rad_s: f32,
        delay: ComputationDelay,
        angle_advance_periods: f32,
    ) -> Self {
        let half = half_period_ticks.clamp(1, MAX_HALF_PERIOD);
        let y_d = 0.5 * (1.0 / motor.ld_h - 1.0 / motor.lq_h);
        let w = pll_bandwidth_rad_s;
        Self {
            v: injection_v,
            ts: ts_s,
            kp: 3.0 * w,
            ki_t: 3.0 * w * w * ts_s,
            k3_t: w * w * w * ts_s,
            inv_scale: 1.0 / (2.0 * ts_s * injection_v * y_d),
            advance_s: angle_advance_periods * ts_s,
            one_period_delay: delay == ComputationDelay::OnePeriod,
            theta: 0.0,
            omega_i: 0.0,
            load: 0.0,
            sign: 1.0,
            half,
            period: 2 * half,
            phase: 0,
            hist: [Carrier::default(); 2],
            i_prev: AlphaBeta::default(),
            i_ring: [AlphaBeta::default(); RING],
            y_ring: [Dq::default(); RING],
            p_ring: [0; RING],
            a_ring: [AlphaBeta::default(); RING],
            weights: ls_weights(half),
            tri: AlphaBeta::default(),
            tri_ring: [AlphaBeta::default(); RING],
            tri_centred: AlphaBeta::default(),
            pos: 0,
            valid: 0,
            y_count: 0,
            last: Response::default(),
        }
    }

    /// The tracker for a controller configuration and HFI settings.
    pub fn from_config(cfg: &FocConfig, hfi: &HfiConfig) -> Self {
        Self::new(
            &cfg.motor,
            cfg.ts_s,
            hfi.injection_v,
            hfi.half_period_ticks,
            hfi.pll_bandwidth_rad_s,
            cfg.delay,
            cfg.angle_advance_periods,
        )
    }

    /// Restarts at angle `theta` (rad el.) and speed `omega` (rad/s el.), carrier history
    /// cleared (the first demodulation comes three samples after the carrier is applied).
    pub fn reset(&mut self, theta: f32, omega: f32) {
        self.theta = wrap(theta);
        self.omega_i = if omega.is_finite() { omega } else { 0.0 };
        self.load = 0.0;
        self.hist = [Carrier::default(); 2];
        self.valid = 0;
        self.y_count = 0;
        self.last = Response::default();
        self.tri = AlphaBeta::default();
        self.tri_centred = AlphaBeta::default();
    }

    /// The carrier voltage applied over the last period `[t_k-1, t_k)` (alpha-beta, V; zero
    /// when none was), as the next [`update`](Self::update) demodulates it.
    pub fn applied_carrier(&self) -> AlphaBeta {
        let c = if self.one_period_delay {
            self.hist[1]
        } else {
            self.hist[0]
        };
        let a = self.v * c.sign;
        AlphaBeta {
            alpha: a * c.cos,
            beta: a * c.sin,
        }
    }

    /// The carrier's part of the last sample (alpha-beta, A): the measured per-period step
    /// accumulated with the applied signs, less its mean over a carrier period. The sample
    /// less this is the fundamental at the sample's own time (no averaging lag).
    pub fn carrier_current(&self) -> AlphaBeta {
        self.tri_centred
    }

    /// Sets the estimated load (disturbance) acceleration, rad/s^2 el.
    pub fn set_load(&mut self, accel_rad_s2: f32) {
        if accel_rad_s2.is_finite() {
            self.load = accel_rad_s2;
        }
    }

    /// Turns the tracked axis by `pi` (after the polarity test).
    pub fn flip(&mut self) {
        self.theta = wrap(self.theta + PI);
    }

    /// Tracked electrical angle, rad, in `[-pi, pi)`.
    pub fn theta(&self) -> f32 {
        self.theta
    }

    /// Tracked electrical speed (the loop's integrator), rad/s.
    pub fn omega(&self) -> f32 {
        self.omega_i
    }

    /// The last demodulation.
    pub fn response(&self) -> Response {
        self.last
    }

    /// A sample was missing or refused: the next three accepted samples rebuild the history
    /// before the loop corrects again (the angle keeps integrating the speed).
    pub fn skip(&mut self, accel_rad_s2: f32) {
        self.valid = 0;
        self.y_count = 0;
        self.theta = wrap(self.theta + self.omega_i * self.ts);
        self.omega_i += self.ts * (accel_rad_s2 - self.load);
    }

    /// Takes the current sample `i[k]` (alpha-beta, A) and the acceleration the drive's own
    /// torque command gives (rad/s^2 el., `p T* / J`; 0 if unknown): demodulates the carrier
    /// and steps the loop (module docs). Returns the response when there was one (three samples of carrier
    /// history), and the fundamental current, the mean of the last two samples (`i[k]` alone
    /// on the first).
    pub fn update(&mut self, i: AlphaBeta, accel_rad_s2: f32) -> (Option<Response>, AlphaBeta) {
        let n = usize::from(self.period);
        let pos = usize::from(self.pos) % RING;
        // The carrier applied over [t_k-1, t_k): its current step, projected on its axis and
        // signed, is one demodulated step `y`.
        let applied = if self.one_period_delay {
            self.hist[1]
        } else {
            self.hist[0]
        };
        if self.valid >= 1 && applied.sign != 0.0 {
            let r = (i - self.i_prev).to_dq(applied.sin, applied.cos);
            self.y_ring[pos] = r * applied.sign;
            self.p_ring[pos] = applied.phase;
            self.a_ring[pos] = AlphaBeta {
                alpha: applied.sign * applied.cos,
                beta: applied.sign * applied.sin,
            };
            self.y_count = self.y_count.saturating_add(1);
        } else {
            self.y_count = 0;
        }
        // The carrier's own current: the last measured step along the applied axis,
        // accumulated with the applied sign, centred on its mean over a period.
        let step = Dq {
            d: self.last.d,
            q: self.last.q,
        }
        .to_alpha_beta(applied.sin, applied.cos);
        self.tri = self.tri + step * applied.sign;
        self.tri_ring[pos] = self.tri;
        // The sample a period ago (the oldest of the window, once the ring is full).
        let i_old = self.i_ring[pos];
        self.i_ring[pos] = i;
        self.i_prev = i;
        self.valid = self.valid.saturating_add(1);
        self.pos = ((pos + 1) % n) as u8;
        // Means over one carrier period: the fundamental current, and the step (the slope of
        // the fundamental cancels, the carrier's sign being balanced over a period).
        let fund = if usize::from(self.valid) >= n {
            let mut sum = AlphaBeta::default();
            let mut tri = AlphaBeta::default();
            for (x, t) in self.i_ring.iter().zip(&self.tri_ring).take(n) {
                sum = sum + *x;
                tri = tri + *t;
            }
            self.tri_centred = self.tri - tri * (1.0 / n as f32);
            sum * (1.0 / n as f32)
        } else {
            self.tri_centred = AlphaBeta::default();
            i
        };
        let resp = if usize::from(self.y_count) >= n {
            // The oldest step of the window is the one after the newest (written at `pos`).
            let p0 = usize::from((self.p_ring[pos] + 1) % self.period);
            let w = &self.weights[p0 % RING];
            let mut m = Dq::default();
            let mut axis = AlphaBeta::default();
            let steps = self.y_ring.iter().zip(&self.a_ring);
            for ((y, a), p) in steps.zip(&self.p_ring).take(n) {
                let wp = w[usize::from(*p) % RING];
                m = m + *y * wp;
                axis = axis + *a * wp;
            }
            // The fundamental's slope over the window, taken out in the fixed frame: each step
            // is projected on the axis its carrier was applied along, and that axis moves
            // within the window (the loop's correction every tick), so a slope constant in
            // alpha-beta is not constant in the steps and the weights would not cancel it
            // (module docs, "Demodulation by least squares").
            let slope = (i - i_old) * (1.0 / n as f32);
            m.d -= slope.alpha * axis.alpha + slope.beta * axis.beta;
            m.q -= slope.beta * axis.alpha - slope.alpha * axis.beta;
            let eps = crate::pi::limit(m.q * self.inv_scale, -1.0, 1.0);
            self.theta = wrap(self.theta + self.ts * (self.omega_i + self.kp * eps));
            self.omega_i += self.ki_t * eps + self.ts * (accel_rad_s2 - self.load);
            self.load -= self.k3_t * eps;
            self.last = Response {
                d: m.d,
                q: m.q,
                eps,
            };
            Some(self.last)
        } else {
            self.theta = wrap(self.theta + self.ts * self.omega_i);
            self.omega_i += self.ts * (accel_rad_s2 - self.load);
            None
        };
        (resp, fund)
    }

    /// The carrier voltage for this tick (alpha-beta, V), along the tracked axis advanced to
    /// the middle of its application interval; the sign alternates every call.
    pub fn inject(&mut self) -> AlphaBeta {
        self.sign = if self.phase < self.half { 1.0 } else { -1.0 };
        let phase = self.phase;
        self.phase = (self.phase + 1) % self.period;
        let (s0, c0) = sin_cos(self.theta);
        let (sd, cd) = sin_cos_small(self.omega_i * self.advance_s);
        let (s, c) = add_angles(s0, c0, sd, cd);
        self.hist = [
            Carrier {
                sign: self.sign,
                sin: s,
                cos: c,
                phase,
            },
            self.hist[0],
        ];
        let a = self.v * self.sign;
        AlphaBeta {
            alpha: a * c,
            beta: a * s,
        }
    }
}

/// Phase of the HFI start and run.
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq)]
pub enum HfiPhase {
    /// Standstill, no current: the loop settles on the salient axis.
    #[default]
    Settling,
    /// First polarity pulse (`+I_p` on the tracked d axis).
    PulsePositive,
    /// Second polarity pulse (`-I_p`).
    PulseNegative,
    /// Closed loop on the HFI angle (blended with the observer's by speed).
    Tracking,
}

/// What HFI is doing (the controller's [`hfi_status`](crate::Foc::hfi_status)).
#[derive(Clone, Copy, Debug, Default, PartialEq)]
pub struct HfiStatus {
    /// Phase.
    pub phase: HfiPhase,
    /// Whether the carrier is on this tick.
    pub injecting: bool,
    /// Weight of the observer's angle in the control angle, `0` (HFI alone) to `1`.
    pub observer_weight: f32,
    /// HFI's tracked angle, rad el.
    pub theta_rad: f32,
    /// HFI's tracked speed, rad/s el.
    pub omega_rad_s: f32,
    /// Mean d response under `+I_p` over that under `-I_p` (> 1: the tracked axis was north);
    /// NaN before the test ends or when it was not run.
    pub polarity_contrast: f32,
    /// Whether the polarity test turned the axis by `pi`.
    pub polarity_flipped: bool,
    /// The last demodulation.
    pub response: Response,
}

/// The magnet polarity test's sequence (module docs): ticks of each step and the
/// accumulated responses.
#[derive(Clone, Copy, Debug, PartialEq)]
pub(crate) struct PolarityTest {
    settle: u32,
    pulse: u32,
    gap: u32,
    current: f32,
    detect: bool,
    /// Ticks in the present phase.
    t: u32,
    sum: [f32; 2],
    n: [u32; 2],
}

/// What the test asks for this tick.
#[derive(Clone, Copy, Debug, PartialEq)]
pub(crate) enum PolarityStep {
    /// Run with this d current reference, A.
    Drive(f32),
    /// Done: turn the axis by `pi` if `flip`; `contrast` as in [`HfiStatus`].
    Done { flip: bool, contrast: f32 },
}

impl PolarityTest {
    pub fn new(hfi: &HfiConfig, ts: f32) -> Self {
        let t = |s: f32| crate::health::ticks(s, ts).max(1);
        Self {
            settle: t(hfi.settle_time_s),
            pulse: t(hfi.pulse_time_s),
            gap: t(0.5 * hfi.pulse_time_s),
            current: hfi.polarity_current_a,
            detect: hfi.detect_polarity,
            t: 0,
            sum: [0.0; 2],
            n: [0; 2],
        }
    }

    /// One tick in `phase` with this tick's response: the d current reference, the next
    /// phase, or the result.
    pub fn step(&mut self, phase: &mut HfiPhase, resp: Option<Response>) -> PolarityStep {
        self.t += 1;
        match *phase {
            HfiPhase::Settling => {
                if self.t >= self.settle {
                    if !self.detect {
                        return PolarityStep::Done {
                            flip: false,
                            contrast: f32::NAN,
                        };
                    }
                    self.t = 0;
                    *phase = HfiPhase::PulsePositive;
                }
                PolarityStep::Drive(0.0)
            }
            HfiPhase::PulsePositive | HfiPhase::PulseNegative => {
                let k = usize::from(*phase == HfiPhase::PulseNegative);
                let sign = if k == 0 { 1.0 } else { -1.0 };
                if self.t <= self.pulse {
                    // Measure over the second half, once the current has settled.
                    if 2 * self.t > self.pulse
                        && let Some(r) = resp
                    {
                        self.sum[k] += r.d;
                        self.n[k] += 1;
                    }
                    return PolarityStep::Drive(sign * self.current);
                }
                if self.t < self.pulse + self.gap {
                    return PolarityStep::Drive(0.0);
                }
                if k == 0 {
                    self.t = 0;
                    *phase = HfiPhase::PulseNegative;
                    return PolarityStep::Drive(0.0);
                }
                let mean = |k: usize| self.sum[k] / (self.n[k].max(1) as f32);
                let contrast = mean(0) / mean(1);
                // NaN (no responses) keeps the axis.
                PolarityStep::Done {
                    flip: contrast < 1.0,
                    contrast,
                }
            }
            HfiPhase::Tracking => PolarityStep::Drive(0.0),
        }
    }
}

/// HFI inside the controller (module [`crate::controller`], "Low speed by HFI"): tracker,
/// polarity test, blend with the observer.
#[derive(Clone, Copy, Debug, PartialEq)]
pub(crate) struct HfiDrive {
    pub cfg: HfiConfig,
    pub tracker: HfiTracker,
    test: PolarityTest,
    pub phase: HfiPhase,
    pub injecting: bool,
    /// Observer weight of the last tick.
    pub weight: f32,
    contrast: f32,
    flipped: bool,
    /// Whether this tick's current sample went through the tracker (then the loops take
    /// its fundamental).
    demodulated: bool,
    /// `p k_t / J`: electrical acceleration per ampere of torque command, rad/s^2/A.
    accel_per_a: f32,
    /// Acceleration of the last torque command, rad/s^2 el.
    accel: f32,
    /// The observer's speed low-passed at the tracking loop's bandwidth, rad/s el.: what
    /// turns the carrier back on and seeds the tracker's speed (the observer's own speed is
    /// noisiest at the bottom of its range).
    omega_o_lp: f32,
    /// Gain of that low-pass per tick.
    lp_gain: f32,
    /// Whether the observer's weight follows the faster of HFI's speed and the observer's
    /// low-passed speed (a long carrier period: [`HFI_PERIOD_ANGLE_RAD`]).
    weight_on_faster: bool,
}

/// The virtual rotor sensor HFI gives the speed loop in [`HfiPhase::Tracking`].
#[derive(Clone, Copy, Debug, PartialEq)]
pub(crate) struct Blend {
    /// Angle (rad el.) and speed (rad/s el.) of the control frame.
    pub theta: f32,
    pub omega: f32,
    /// The observer must be re-seeded at this (angle, speed, sigma) first.
    pub reseed: Option<(f32, f32)>,
}

impl HfiDrive {
    pub fn new(foc: &FocConfig, cfg: &HfiConfig) -> Self {
        Self {
            cfg: *cfg,
            tracker: HfiTracker::from_config(foc, cfg),
            test: PolarityTest::new(cfg, foc.ts_s),
            phase: HfiPhase::Settling,
            injecting: true,
            weight: 0.0,
            contrast: f32::NAN,
            flipped: false,
            demodulated: false,
            accel_per_a: foc.motor.pole_pairs as f32 * foc.torque_constant_nm_a()
                / foc.inertia_kg_m2,
            accel: 0.0,
            omega_o_lp: 0.0,
            lp_gain: crate::trig::min2(cfg.pll_bandwidth_rad_s * foc.ts_s, 1.0),
            weight_on_faster: long_carrier_period(
                cfg.blend_high_rad_s,
                cfg.half_period_ticks,
                foc.ts_s,
            ),
        }
    }

    /// Whether this tick's sample was demodulated (the loops and the observer then take the
    /// fundamental).
    #[inline]
    pub fn demodulated(&self) -> bool {
        self.demodulated
    }

    /// The torque command of this tick as a surface-equivalent current (A, module
    /// [`crate::mtpa`]), fed forward to the tracking loop at the next tick.
    #[inline]
    pub fn set_torque_command(&mut self, i_t: f32) {
        let a = self.accel_per_a * i_t;
        self.accel = if a.is_finite() { a } else { 0.0 };
    }

    /// Back to the standstill start (called by `Foc::start` from idle).
    pub fn restart(&mut self, foc: &FocConfig) {
        *self = Self::new(foc, &self.cfg);
    }

    /// Status for the user.
    pub fn status(&self) -> HfiStatus {
        HfiStatus {
            phase: self.phase,
            injecting: self.injecting,
            observer_weight: self.weight,
            theta_rad: self.tracker.theta(),
            omega_rad_s: self.tracker.omega(),
            polarity_contrast: self.contrast,
            polarity_flipped: self.flipped,
            response: self.tracker.response(),
        }
    }

    /// Takes this tick's current sample (when the carrier is on): the response and the
    /// current the loops should see.
    #[inline]
    pub fn demodulate(
        &mut self,
        i_ab: AlphaBeta,
        sample_ok: bool,
    ) -> (Option<Response>, AlphaBeta) {
        self.demodulated = false;
        if !self.injecting {
            return (None, i_ab);
        }
        if !sample_ok {
            self.tracker.skip(self.accel);
            return (None, i_ab);
        }
        self.demodulated = true;
        self.tracker.update(i_ab, self.accel)
    }

    /// The standstill test for this tick: the d current reference while it runs (`Some`),
    /// `None` once tracking (the test ends in the tick it decides, which then tracks).
    #[inline]
    pub fn standstill(&mut self, resp: Option<Response>) -> Option<f32> {
        if self.phase == HfiPhase::Tracking {
            return None;
        }
        match self.test.step(&mut self.phase, resp) {
            PolarityStep::Drive(i_d) => Some(i_d),
            PolarityStep::Done { flip, contrast } => {
                if flip {
                    self.tracker.flip();
                }
                self.flipped = flip;
                self.contrast = contrast;
                self.phase = HfiPhase::Tracking;
                None
            }
        }
    }

    /// The variance (rad^2) with which HFI's angle is fused into the observer this tick
    /// (module docs, "Hand-over band"): while tracking with the carrier on and the observer's
    /// weight below 1, `fusion_sigma^2 / (1 - weight)` (the last tick's weight); `None`
    /// otherwise or with the fusion off.
    #[inline]
    pub fn fusion_variance(&self) -> Option<f32> {
        let s = self.cfg.fusion_sigma_rad;
        if self.phase == HfiPhase::Tracking && self.injecting && self.weight < 1.0 && s > 0.0 {
            Some(s * s / (1.0 - self.weight))
        } else {
            None
        }
    }

    /// The blended control angle and speed (observer estimate `theta_o`, `omega_o`):
    /// carrier on below `blend_high` (back on below 80 % of it, the tracker seeded from the
    /// observer), observer weight linear in `|w|` from `blend_low` to `blend_high` (`w` HFI's
    /// speed, or the faster of it and the observer's low-passed speed with a long carrier
    /// period: module docs, "Hand-over band"), the observer re-seeded from HFI when its
    /// weight leaves zero.
    #[inline]
    pub fn blend(&mut self, theta_o: f32, omega_o: f32) -> Blend {
        let c = &self.cfg;
        // The weight follows HFI's own speed while the carrier is on (the observer's speed is
        // unreliable at the low end of the band and would feed back into its own weight),
        // the observer's, low-passed, while it is off.
        self.omega_o_lp += self.lp_gain * (omega_o - self.omega_o_lp);
        if !self.omega_o_lp.is_finite() {
            self.omega_o_lp = self.tracker.omega();
        }
        if self.injecting && self.tracker.omega().abs() > c.blend_high_rad_s {
            self.injecting = false;
            self.omega_o_lp = self.tracker.omega();
        } else if !self.injecting && self.omega_o_lp.abs() < 0.8 * c.blend_high_rad_s {
            self.injecting = true;
            self.tracker.reset(theta_o, self.omega_o_lp);
            // The load takes what the drive's torque gives (steady speed assumed): the
            // tracker starts with that disturbance instead of learning it.
            self.tracker.set_load(self.accel);
        }
        let mut lam = if self.injecting {
            // With a long carrier period HFI's speed lags the rotor's at the top of the band
            // (module docs, "Hand-over band"): the weight follows the faster estimate.
            let w_abs = if self.weight_on_faster {
                max2(self.tracker.omega().abs(), self.omega_o_lp.abs())
            } else {
                self.tracker.omega().abs()
            };
            observer_weight(w_abs, c.blend_low_rad_s, c.blend_high_rad_s)
        } else {
            1.0
        };
        let (th_h, w_h) = (self.tracker.theta(), self.tracker.omega());
        let reseed = if lam > 0.0 && self.weight == 0.0 {
            // The observer drifted while the speed was low: it restarts from HFI's angle and
            // takes over from the next tick.
            lam = 0.0;
            Some((th_h, w_h))
        } else {
            None
        };
        let theta = wrap(th_h + lam * wrap(theta_o - th_h));
        let omega = w_h + lam * (omega_o - w_h);
        // A reseed tick keeps weight 0 but must not reseed again: mark it with the smallest
        // positive weight.
        self.weight = if reseed.is_some() {
            f32::MIN_POSITIVE
        } else {
            lam
        };
        Blend {
            theta,
            omega,
            reseed,
        }
    }

    /// The carrier for this tick (when on) and the current the loops take: the fundamental
    /// while the carrier is demodulated, the sample itself otherwise.
    #[inline]
    pub fn finish(&mut self, i_ab: AlphaBeta, fund: AlphaBeta) -> (Option<AlphaBeta>, AlphaBeta) {
        let i_loop = if self.demodulated { fund } else { i_ab };
        let carrier = if self.injecting {
            Some(self.tracker.inject())
        } else {
            None
        };
        (carrier, i_loop)
    }
}

/// Electrical angle (rad) the rotor may turn in one carrier period at the top of the blend
/// band (`blend_high_rad_s 2 N Ts`) before the observer's weight follows the faster of HFI's
/// speed and the observer's low-passed speed instead of HFI's alone (module docs, "Hand-over
/// band"): 0.05 rad (2.9 deg). The industrial IPM of the tests turns 0.12 rad (`N = 7`), the
/// traction IPM 0.016 rad (`N = 2` at 20 kHz).
pub const HFI_PERIOD_ANGLE_RAD: f32 = 0.05;

/// Whether the carrier period is long (module docs, "Hand-over band"): the rotor turns more
/// than [`HFI_PERIOD_ANGLE_RAD`] per carrier period (`2 N Ts`, `N = half_period_ticks`) at
/// the top of the blend band `blend_high_rad_s`. HFI is then the weak side there: its angle
/// is not fused into the observer ([`HfiConfig::new`]'s default `fusion_sigma_rad`) and the
/// observer's weight follows the faster of the two speeds.
#[inline]
pub fn long_carrier_period(blend_high_rad_s: f32, half_period_ticks: u8, ts_s: f32) -> bool {
    blend_high_rad_s * 2.0 * f32::from(half_period_ticks) * ts_s > HFI_PERIOD_ANGLE_RAD
}

/// Observer weight in the control angle for an electrical speed magnitude `w` (linear from
/// `lo` to `hi`).
pub(crate) fn observer_weight(w: f32, lo: f32, hi: f32) -> f32 {
    let x = (w - lo) / (hi - lo);
    crate::pi::limit(x, 0.0, 1.0)
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::transforms::Dq;

    fn ipm() -> FocConfig {
        let mut c = FocConfig::new(MotorParams::industrial_ipm(), 1e-4, 540.0);
        c.current_limit_a = 9.0;
        c
    }

    /// A stationary-rotor dq plant at angle `theta` (the carrier's response only: R and speed
    /// neglected in the plant too, plus R for realism), stepped exactly for a held voltage:
    /// `i += Ts L^-1 u` in the rotor frame (R small enough to neglect over one period), with
    /// an optional d-axis saturation `Ld,inc = Ld (1 - k clamp(i_d / I_s, 0, 1))`.
    struct DqPlant {
        ld: f32,
        lq: f32,
        theta: f32,
        i: Dq,
        sat: f32,
        i_sat: f32,
    }

    impl DqPlant {
        fn step(&mut self, u_ab: AlphaBeta, ts: f32) {
            let (s, c) = sin_cos(self.theta);
            let u = u_ab.to_dq(s, c);
            let x = crate::pi::limit(self.i.d / self.i_sat, 0.0, 1.0);
            let ld = self.ld * (1.0 - self.sat * x);
            self.i.d += ts * u.d / ld;
            self.i.q += ts * u.q / self.lq;
        }
        fn i_ab(&self) -> AlphaBeta {
            let (s, c) = sin_cos(self.theta);
            self.i.to_alpha_beta(s, c)
        }
    }

    /// Runs the tracker on the plant with a one-period delay and a d current held by an ideal
    /// (dead-beat on the mean) current source: returns the final tracker.
    fn run(theta0: f32, theta_rotor: f32, ticks: u32, drift: f32) -> HfiTracker {
        let cfg = ipm();
        let h = HfiConfig::new(&cfg, 540.0).unwrap_or_else(|e| panic!("{e}"));
        let mut t = HfiTracker::from_config(&cfg, &h);
        t.reset(theta0, 0.0);
        let mut p = DqPlant {
            ld: cfg.motor.ld_h,
            lq: cfg.motor.lq_h,
            theta: theta_rotor,
            i: Dq { d: 0.0, q: 2.0 },
            sat: 0.0,
            i_sat: 1.0,
        };
        let mut pending = AlphaBeta::default();
        for _ in 0..ticks {
            let _ = t.update(p.i_ab(), 0.0);
            let u = t.inject();
            p.step(pending, cfg.ts_s);
            pending = u;
            p.theta = wrap(p.theta + drift * cfg.ts_s);
        }
        t
    }

    #[test]
    fn defaults_follow_the_motor_and_surface_motors_are_refused() {
        let cfg = ipm();
        let h = HfiConfig::new(&cfg, 540.0).unwrap_or_else(|e| panic!("{e}"));
        // 10 % of 9 A ripple on 30 mH at 10 kHz: 270 V, capped at 80 % of 312 V.
        assert!(
            (h.injection_v - 0.8 * 540.0 / 3.0_f32.sqrt()).abs() < 0.5,
            "{h:?}"
        );
        assert!(h.blend_low_rad_s < h.blend_high_rad_s);
        let surface = FocConfig::new(MotorParams::servo(), 1e-4, 300.0);
        assert_eq!(
            HfiConfig::new(&surface, 300.0),
            Err(HfiError::SurfaceMotor { saliency: 1.0 })
        );
        let mut bad = h;
        bad.injection_v = f32::NAN;
        assert_eq!(
            bad.validate(&cfg, 540.0),
            Err(HfiError::NotPositive(HfiField::InjectionV))
        );
        bad = h;
        bad.blend_low_rad_s = 2.0 * h.blend_high_rad_s;
        assert_eq!(
            bad.validate(&cfg, 540.0),
            Err(HfiError::OutOfRange(HfiField::BlendLow))
        );
        bad = h;
        bad.polarity_current_a = 10.0;
        assert_eq!(
            bad.validate(&cfg, 540.0),
            Err(HfiError::OutOfRange(HfiField::PolarityCurrent))
        );
        let sensored = cfg.with_mode(Mode::Sensored);
        assert_eq!(h.validate(&sensored, 540.0), Err(HfiError::SensoredMode));
    }

    #[test]
    fn noise_model_picks_bandwidth_and_half_period() {
        // The industrial motor as the simulator's preset runs it.
        let mut cfg = ipm();
        cfg.current_limit_a = 12.0;
        cfg.inertia_kg_m2 = 0.012;
        let plain = HfiConfig::new(&cfg, 540.0).unwrap_or_else(|e| panic!("{e}"));
        // No noise: the plain defaults.
        assert_eq!(HfiConfig::with_current_noise(&cfg, 540.0, 0.0), Ok(plain));
        // 50 mA: the plain defaults predict more than 1 deg; the bandwidth drops to the load
        // step's bound, sqrt(0.54 a_max), and the half period grows until the target is met.
        let h = HfiConfig::with_current_noise(&cfg, 540.0, 0.05).unwrap_or_else(|e| panic!("{e}"));
        assert!(plain.predicted_angle_rms_rad(&cfg, 0.05) > TARGET_ANGLE_RMS_RAD);
        assert!(h.predicted_angle_rms_rad(&cfg, 0.05) <= TARGET_ANGLE_RMS_RAD);
        assert_eq!((plain.half_period_ticks, h.half_period_ticks), (4, 7));
        assert!(h.half_period_ticks > plain.half_period_ticks, "{h:?}");
        let ratio = h.pll_bandwidth_rad_s / plain.pll_bandwidth_rad_s;
        assert!(
            (ratio - (LOAD_STEP_PEAK / 0.5).sqrt()).abs() < 1e-3,
            "{ratio}"
        );
        let mut shorter = h;
        shorter.half_period_ticks -= 1;
        assert!(shorter.predicted_angle_rms_rad(&cfg, 0.05) > TARGET_ANGLE_RMS_RAD);
        // Far too noisy: the longest half period.
        let n = HfiConfig::with_current_noise(&cfg, 540.0, 1.0).unwrap_or_else(|e| panic!("{e}"));
        assert_eq!(n.half_period_ticks, MAX_HALF_PERIOD);
        for bad in [-0.1, f32::NAN, f32::INFINITY] {
            assert_eq!(
                HfiConfig::with_current_noise(&cfg, 540.0, bad),
                Err(HfiError::OutOfRange(HfiField::CurrentNoise))
            );
        }
        let mut bad = plain;
        bad.half_period_ticks = MAX_HALF_PERIOD + 1;
        assert_eq!(
            bad.validate(&cfg, 540.0),
            Err(HfiError::OutOfRange(HfiField::HalfPeriod))
        );
    }

    #[test]
    fn least_squares_weights_are_unbiased_and_cancel_the_fundamental() {
        // For every half period and window phase: the weights of the signed steps sum to 1
        // (a carrier step is measured as itself) and weigh the carrier's signs to zero (a
        // constant slope of the fundamental cancels).
        for half in 1..=MAX_HALF_PERIOD {
            let w = ls_weights(half);
            let n = 2 * usize::from(half);
            for (p0, row) in w.iter().enumerate().take(n) {
                let sum: f32 = row.iter().take(n).sum();
                let signed: f32 = row
                    .iter()
                    .enumerate()
                    .take(n)
                    .map(|(p, x)| if p < usize::from(half) { *x } else { -*x })
                    .sum();
                assert!((sum - 1.0).abs() < 1e-5, "N {half} p0 {p0}: {sum}");
                assert!(signed.abs() < 1e-5, "N {half} p0 {p0}: {signed}");
            }
        }
    }

    #[test]
    fn demodulation_gives_sin_2e_over_2() {
        // Tracker frozen (bandwidth tiny) at 0, rotor at e: eps = sin(2e)/2.
        let cfg = ipm();
        for (e, n) in [
            (-1.2_f32, 1),
            (-0.3, 3),
            (0.1, 1),
            (0.6, 4),
            (-0.2, 7),
            (0.4, 8),
        ] {
            let mut t = HfiTracker::new(&cfg.motor, cfg.ts_s, 100.0, n, 1e-3, cfg.delay, 1.5);
            t.reset(0.0, 0.0);
            let mut p = DqPlant {
                ld: cfg.motor.ld_h,
                lq: cfg.motor.lq_h,
                theta: e,
                i: Dq { d: -1.0, q: 3.0 },
                sat: 0.0,
                i_sat: 1.0,
            };
            let mut pending = AlphaBeta::default();
            let mut last = None;
            for _ in 0..20 {
                if let (Some(r), _) = t.update(p.i_ab(), 0.0) {
                    last = Some(r);
                }
                let u = t.inject();
                p.step(pending, cfg.ts_s);
                pending = u;
            }
            let r = last.unwrap_or_else(|| panic!("no response"));
            let want = 0.5 * (2.0 * e).sin();
            assert!((r.eps - want).abs() < 2e-3, "e {e}: {} vs {want}", r.eps);
            let d = cfg.ts_s
                * 100.0
                * (e.cos().powi(2) / cfg.motor.ld_h + e.sin().powi(2) / cfg.motor.lq_h);
            assert!((r.d - d).abs() < 1e-3 * d, "{} vs {d}", r.d);
        }
    }

    #[test]
    fn a_fundamental_slope_does_not_leak_through_a_moving_axis() {
        // The rotor and the carrier's axis turn 0.03 rad per tick (the loop frozen on the
        // speed), the fundamental ramps by 0.5 A per tick in alpha-beta: the responses must
        // be those without the ramp. Without the fixed-frame slope removal the ramp leaks as
        // about 0.05 of eps.
        let cfg = ipm();
        let omega = 300.0;
        let run = |ramp: AlphaBeta| {
            let mut t = HfiTracker::new(&cfg.motor, cfg.ts_s, 100.0, 4, 1e-3, cfg.delay, 1.5);
            t.reset(0.2, omega);
            let mut p = DqPlant {
                ld: cfg.motor.ld_h,
                lq: cfg.motor.lq_h,
                theta: 0.3,
                i: Dq { d: -1.0, q: 3.0 },
                sat: 0.0,
                i_sat: 1.0,
            };
            let mut pending = AlphaBeta::default();
            let mut out = [Response::default(); 24];
            for (k, o) in out.iter_mut().enumerate() {
                let i = p.i_ab() + ramp * k as f32;
                if let (Some(r), _) = t.update(i, 0.0) {
                    *o = r;
                }
                let u = t.inject();
                p.step(pending, cfg.ts_s);
                pending = u;
                p.theta = wrap(p.theta + omega * cfg.ts_s);
            }
            out
        };
        let still = run(AlphaBeta::default());
        let ramped = run(AlphaBeta {
            alpha: 0.3,
            beta: -0.4,
        });
        assert!(still[23].d > 0.0, "no response");
        for (a, b) in still.iter().zip(&ramped) {
            assert!((a.eps - b.eps).abs() < 2e-3, "{a:?} vs {b:?}");
            assert!(
                (a.d - b.d).abs() < 2e-3 * a.d.abs().max(0.1),
                "{a:?} vs {b:?}"
            );
        }
    }

    #[test]
    fn loop_locks_on_the_axis_or_its_opposite_and_tracks_a_turning_rotor() {
        for k in 0..12 {
            let th = -PI + (k as f32 + 0.5) * PI / 6.0;
            let t = run(0.0, th, 3000, 0.0);
            let e = wrap(th - t.theta());
            let e_mod_pi = wrap(2.0 * e) * 0.5;
            assert!(
                e_mod_pi.abs() < 0.5_f32.to_radians(),
                "rotor {th}: error {e}"
            );
        }
        // 30 rad/s el. ramp-free rotation: locked within a degree, speed within 1 %.
        let t = run(0.3, 0.3, 5000, 30.0);
        let th_end = wrap(0.3 + 30.0 * 5000.0 * 1e-4);
        let e = wrap(th_end - t.theta());
        assert!(e.abs() < 1.0_f32.to_radians(), "error {e}");
        assert!((t.omega() - 30.0).abs() < 0.3, "speed {}", t.omega());
    }

    #[test]
    fn polarity_test_finds_north_on_a_saturating_plant() {
        let cfg = ipm();
        let h = HfiConfig::new(&cfg, 540.0).unwrap_or_else(|e| panic!("{e}"));
        for k in 0..12 {
            let th = -PI + (k as f32 + 0.5) * PI / 6.0;
            let mut t = HfiTracker::from_config(&cfg, &h);
            t.reset(0.0, 0.0);
            let mut test = PolarityTest::new(&h, cfg.ts_s);
            let mut phase = HfiPhase::Settling;
            let mut p = DqPlant {
                ld: cfg.motor.ld_h,
                lq: cfg.motor.lq_h,
                theta: th,
                i: Dq::default(),
                sat: 0.2,
                i_sat: 9.0,
            };
            let mut pending = AlphaBeta::default();
            let mut last_ref = 0.0;
            let result = loop {
                let (resp, _) = t.update(p.i_ab(), 0.0);
                match test.step(&mut phase, resp) {
                    PolarityStep::Drive(i_d) => {
                        // An ideal current source: the d current (tracked frame) set when the
                        // reference changes; the carrier rides on it.
                        if i_d != last_ref {
                            last_ref = i_d;
                            let (s, c) = sin_cos(t.theta());
                            let (sr, cr) = sin_cos(p.theta);
                            p.i = Dq { d: i_d, q: 0.0 }.to_alpha_beta(s, c).to_dq(sr, cr);
                        }
                    }
                    PolarityStep::Done { flip, contrast } => break (flip, contrast),
                }
                let u = t.inject();
                p.step(pending, cfg.ts_s);
                pending = u;
            };
            if result.0 {
                t.flip();
            }
            let e = wrap(th - t.theta());
            assert!(
                e.abs() < 2.0_f32.to_radians(),
                "rotor {th}: error {e}, {result:?}"
            );
            assert!(result.1 > 1.05 || result.1 < 1.0 / 1.05, "{result:?}");
        }
    }

    #[test]
    fn fusion_is_on_with_a_short_carrier_period_and_fades_with_the_weight() {
        // The traction IPM at 20 kHz (short carrier period): on; the industrial IPM at 10 kHz
        // with the simulator's sizing (`N = 4`, band top 87 rad/s: 0.07 rad per carrier
        // period, its HFI the weak side at the top of the band): off.
        let mut tr = FocConfig::new(MotorParams::traction_ipm(), 5e-5, 48.0);
        tr.current_limit_a = 250.0;
        let h = HfiConfig::new(&tr, 48.0).unwrap_or_else(|e| panic!("{e}"));
        assert_eq!(h.fusion_sigma_rad, HFI_FUSION_SIGMA_RAD, "{h:?}");
        let mut d = HfiDrive::new(&tr, &h);
        assert!(!d.weight_on_faster);
        let mut ind = ipm();
        ind.current_limit_a = 12.0;
        ind.startup.handover_speed_rad_s = 87.0;
        let long = HfiConfig::new(&ind, 540.0).unwrap_or_else(|e| panic!("{e}"));
        assert_eq!(long.fusion_sigma_rad, 0.0, "{long:?}");
        assert!(HfiDrive::new(&ind, &long).weight_on_faster);
        // Not while the standstill test runs.
        assert_eq!(d.fusion_variance(), None);
        d.phase = HfiPhase::Tracking;
        let v0 = HFI_FUSION_SIGMA_RAD * HFI_FUSION_SIGMA_RAD;
        assert_eq!(d.fusion_variance(), Some(v0));
        d.weight = 0.75;
        let v = d.fusion_variance().unwrap_or(0.0);
        assert!((v - 4.0 * v0).abs() < 1e-6 * v0, "{v}");
        d.weight = 1.0;
        assert_eq!(d.fusion_variance(), None);
        d.weight = 0.5;
        d.injecting = false;
        assert_eq!(d.fusion_variance(), None);
        d.injecting = true;
        d.cfg.fusion_sigma_rad = 0.0;
        assert_eq!(d.fusion_variance(), None);
        // Checked: finite and not negative.
        for x in [-0.1, f32::NAN, f32::INFINITY] {
            let mut bad = h;
            bad.fusion_sigma_rad = x;
            assert_eq!(
                bad.validate(&tr, 48.0),
                Err(HfiError::OutOfRange(HfiField::FusionSigma))
            );
        }
        let mut off = h;
        off.fusion_sigma_rad = 0.0;
        assert_eq!(off.validate(&tr, 48.0), Ok(()));
    }

    #[test]
    fn weight_is_linear_and_clamped() {
        assert_eq!(observer_weight(0.0, 10.0, 20.0), 0.0);
        assert_eq!(observer_weight(15.0, 10.0, 20.0), 0.5);
        assert_eq!(observer_weight(50.0, 10.0, 20.0), 1.0);
        assert_eq!(observer_weight(f32::NAN, 10.0, 20.0), 0.0);
    }
}
