//! High-frequency injection (HFI): rotor angle and speed of a salient motor at standstill and
//! low speed, where the back-EMF the observer needs is too small, with magnet polarity
//! detection.
//!
//! # Method: pulsating square wave on the estimated d axis at half the PWM rate
//!
//! Each tick adds `u_h[k] = V_h s[k] (cos phi_k, sin phi_k)` to the stator voltage (alpha-beta),
//! where `s[k] = -s[k-1]` alternates every PWM period (injection frequency `f_pwm / 2`: 5 kHz
//! at 10 kHz, 10 kHz at 20 kHz) and `phi_k = theta_hat + w_hat advance Ts` is the tracked d
//! axis at the middle of the period the voltage is applied in (the controller's own angle
//! advance, module [`crate::controller`]).
//!
//! **Why a square wave at `f_pwm / 2`, and not a sinusoid at a lower frequency.** (1) The
//! demodulation is a second difference of three current samples, with no band-pass or
//! low-pass filter and no phase to tune: the response is in the very next samples, so the
//! tracking loop can be fast. (2) The fundamental is separated from the carrier by averaging
//! two consecutive samples (a notch exactly at `f_pwm / 2`), so the current loops keep their
//! bandwidth and only gain half a period of delay. (3) For a given voltage the current
//! ripple is the smallest the PWM can make (`Ts V_h / L` peak to peak), and the carrier sits
//! at the top of the audible band or above it. A sinusoid at `f_pwm / 8` would need filters
//! whose delay limits the tracking bandwidth (Jang 2003, Yoon 2011 compare the two).
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
//! surface motor ([`HfiError::SurfaceMotor`]). With the sign alternating every period, the
//! second difference of the sampled currents `D2[k] = i[k] - 2 i[k-1] + i[k-2]` cancels the
//! fundamental's slope and doubles the carrier's step:
//!
//! ```text
//! (s_a / 2) D2[k] in the phi frame = Ts V (Y_s + Y_d cos 2e,  Y_d sin 2e)
//! ```
//!
//! `s_a` being the sign of the voltage applied over `[t_k-1, t_k)` (computed two ticks ago with
//! the one-period computation delay, one tick ago without it; both kept in a short history
//! with their angle). The normalised error `eps = (s_a / 2) D2_q / (2 Ts V Y_d) = sin(2e) / 2`
//! is `e` for small errors. The d part, `Ts V / Ld,inc` at `e = 0`, is the incremental d-axis
//! admittance that the polarity test compares.
//!
//! # Tracking loop (PLL)
//!
//! ```text
//! w_i   += Ki Ts eps                      Ki = w_n^2
//! theta += Ts (w_i + Kp eps)              Kp = 2 w_n        (critically damped, type 2)
//! ```
//!
//! `w_n` = [`HfiConfig::pll_bandwidth_rad_s`]. The speed output is the integrator `w_i` (no
//! proportional noise). `eps` is clamped to `+-1` so that a noise spike cannot throw the
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
//! # Current feedback and voltage
//!
//! While the carrier is on, the current loops see the mean of the last two samples (the
//! carrier removed), and their voltage limit is lowered by `V_h` so that the sum stays within
//! the modulation limit.
//!
//! # Defaults from the motor ([`HfiConfig::new`])
//!
//! - `V_h`: the voltage whose carrier ripple is 10 % of the current limit peak to peak on the
//!   d axis, `0.1 I_lim Ld / Ts`, at most 70 % of the voltage limit at the nominal bus;
//! - PLL: `w_n = 2 pi 25 Hz`, at least four times the speed loop's crossover;
//! - hand-over band to the observer: from half the start-up hand-over speed (observer weight 0)
//!   to the hand-over speed (weight 1; carrier off above it);
//! - polarity pulses: `0.8 I_lim`, 20 ms each, after 60 ms of settling.

use core::f32::consts::PI;

use ekf_core::MotorParams;

use crate::config::{ComputationDelay, FocConfig, Mode};
use crate::transforms::AlphaBeta;
use crate::trig::{add_angles, at_most, sin_cos, sin_cos_small, wrap};

/// Which [`HfiConfig`] field is wrong.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum HfiField {
    /// [`HfiConfig::injection_v`].
    InjectionV,
    /// [`HfiConfig::pll_bandwidth_rad_s`].
    PllBandwidth,
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

/// Smallest `Lq / Ld` HFI accepts.
pub const MIN_SALIENCY: f32 = 1.1;

/// HFI settings (module docs give the defaults, [`HfiConfig::new`]).
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct HfiConfig {
    /// Amplitude of the square-wave carrier on the tracked d axis, V.
    pub injection_v: f32,
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
    /// (module docs). A surface motor is refused ([`HfiError::SurfaceMotor`]).
    pub fn new(cfg: &FocConfig, u_dc_nominal_v: f32) -> Result<Self, HfiError> {
        saliency(&cfg.motor)?;
        let m = &cfg.motor;
        let u_lim = cfg.max_modulation * u_dc_nominal_v * crate::transforms::FRAC_1_SQRT_3;
        let v_ripple = 0.1 * cfg.current_limit_a * m.ld_h / cfg.ts_s;
        let v = if v_ripple < 0.7 * u_lim {
            v_ripple
        } else {
            0.7 * u_lim
        };
        let w_pll = {
            let w = 2.0 * PI * 25.0;
            let w_speed = 4.0 * cfg.speed_bw_rad_s;
            if w_speed > w { w_speed } else { w }
        };
        let h = cfg.startup.handover_speed_rad_s;
        let c = Self {
            injection_v: v,
            pll_bandwidth_rad_s: w_pll,
            blend_low_rad_s: 0.5 * h,
            blend_high_rad_s: h,
            polarity_current_a: 0.8 * cfg.current_limit_a,
            settle_time_s: 0.06,
            pulse_time_s: 0.02,
            detect_polarity: true,
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
        if !(self.injection_v < 0.9 * u_lim) {
            return Err(HfiError::OutOfRange(F::InjectionV));
        }
        if !(self.pll_bandwidth_rad_s * cfg.ts_s < 0.1 * 2.0 * PI) {
            return Err(HfiError::OutOfRange(F::PllBandwidth));
        }
        if !(self.blend_low_rad_s < self.blend_high_rad_s) {
            return Err(HfiError::OutOfRange(F::BlendLow));
        }
        if !(self.blend_high_rad_s < cfg.max_speed_rad_s) {
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
        Ok(())
    }
}

/// One carrier period as it was applied: sign and axis (sine, cosine).
#[derive(Clone, Copy, Debug, Default, PartialEq)]
struct Carrier {
    sign: f32,
    sin: f32,
    cos: f32,
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
    /// `1 / (2 Ts V Y_d)`.
    inv_scale: f32,
    advance_s: f32,
    one_period_delay: bool,
    theta: f32,
    omega_i: f32,
    sign: f32,
    /// Carrier computed one and two ticks ago.
    hist: [Carrier; 2],
    /// Samples `i[k-1]`, `i[k-2]`.
    i_hist: [AlphaBeta; 2],
    /// Consecutive accepted samples with the carrier on (saturating).
    valid: u8,
    last: Response,
}

impl HfiTracker {
    /// A tracker for `motor` at the PWM period `ts_s` with the carrier `injection_v`, the loop
    /// bandwidth `pll_bandwidth_rad_s`, and the controller's delay and angle advance
    /// (periods). Angle and speed start at zero.
    pub fn new(
        motor: &MotorParams<f32>,
        ts_s: f32,
        injection_v: f32,
        pll_bandwidth_rad_s: f32,
        delay: ComputationDelay,
        angle_advance_periods: f32,
    ) -> Self {
        let y_d = 0.5 * (1.0 / motor.ld_h - 1.0 / motor.lq_h);
        let w = pll_bandwidth_rad_s;
        Self {
            v: injection_v,
            ts: ts_s,
            kp: 2.0 * w,
            ki_t: w * w * ts_s,
            inv_scale: 1.0 / (2.0 * ts_s * injection_v * y_d),
            advance_s: angle_advance_periods * ts_s,
            one_period_delay: delay == ComputationDelay::OnePeriod,
            theta: 0.0,
            omega_i: 0.0,
            sign: 1.0,
            hist: [Carrier::default(); 2],
            i_hist: [AlphaBeta::default(); 2],
            valid: 0,
            last: Response::default(),
        }
    }

    /// The tracker for a controller configuration and HFI settings.
    pub fn from_config(cfg: &FocConfig, hfi: &HfiConfig) -> Self {
        Self::new(
            &cfg.motor,
            cfg.ts_s,
            hfi.injection_v,
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
        self.hist = [Carrier::default(); 2];
        self.valid = 0;
        self.last = Response::default();
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
    pub fn skip(&mut self) {
        self.valid = 0;
        self.theta = wrap(self.theta + self.omega_i * self.ts);
    }

    /// Takes the current sample `i[k]` (alpha-beta, A): demodulates the carrier and steps the
    /// loop (module docs). Returns the response when there was one (three samples of carrier
    /// history), and the fundamental current, the mean of the last two samples (`i[k]` alone
    /// on the first).
    pub fn update(&mut self, i: AlphaBeta) -> (Option<Response>, AlphaBeta) {
        let fund = if self.valid >= 1 {
            (i + self.i_hist[0]) * 0.5
        } else {
            i
        };
        // The carrier applied over [t_k-1, t_k) and its step from the period before (the
        // tick before that one had the opposite sign: the history must cover both).
        let applied = if self.one_period_delay {
            self.hist[1]
        } else {
            self.hist[0]
        };
        let need = if self.one_period_delay { 4 } else { 3 };
        let resp = if self.valid >= need && applied.sign != 0.0 {
            let d2 = i - self.i_hist[0] * 2.0 + self.i_hist[1];
            let r = d2.to_dq(applied.sin, applied.cos);
            let h = 0.5 * applied.sign;
            let (d, q) = (h * r.d, h * r.q);
            let eps = crate::pi::limit(q * self.inv_scale, -1.0, 1.0);
            self.omega_i += self.ki_t * eps;
            self.theta = wrap(self.theta + self.ts * (self.omega_i + self.kp * eps));
            self.last = Response { d, q, eps };
            Some(self.last)
        } else {
            self.theta = wrap(self.theta + self.ts * self.omega_i);
            None
        };
        self.i_hist = [i, self.i_hist[0]];
        self.valid = self.valid.saturating_add(1);
        (resp, fund)
    }

    /// The carrier voltage for this tick (alpha-beta, V), along the tracked axis advanced to
    /// the middle of its application interval; the sign alternates every call.
    pub fn inject(&mut self) -> AlphaBeta {
        self.sign = -self.sign;
        let (s0, c0) = sin_cos(self.theta);
        let (sd, cd) = sin_cos_small(self.omega_i * self.advance_s);
        let (s, c) = add_angles(s0, c0, sd, cd);
        self.hist = [
            Carrier {
                sign: self.sign,
                sin: s,
                cos: c,
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
            let _ = t.update(p.i_ab());
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
        // 10 % of 9 A ripple on 30 mH at 10 kHz: 270 V, capped at 70 % of 312 V.
        assert!(
            (h.injection_v - 0.7 * 540.0 / 3.0_f32.sqrt()).abs() < 0.5,
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
    fn demodulation_gives_sin_2e_over_2() {
        // Tracker frozen (bandwidth tiny) at 0, rotor at e: eps = sin(2e)/2.
        let cfg = ipm();
        for e in [-1.2_f32, -0.3, 0.1, 0.6] {
            let mut t = HfiTracker::new(&cfg.motor, cfg.ts_s, 100.0, 1e-3, cfg.delay, 1.5);
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
            for _ in 0..10 {
                if let (Some(r), _) = t.update(p.i_ab()) {
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
            let result = loop {
                let (resp, fund) = t.update(p.i_ab());
                let (s, c) = sin_cos(t.theta());
                let i_est = fund.to_dq(s, c);
                match test.step(&mut phase, resp) {
                    PolarityStep::Drive(i_d) => {
                        // Ideal current source on the mean: move the mean d current (in the
                        // tracked frame) to the reference in one step.
                        let shift = Dq {
                            d: i_d - i_est.d,
                            q: -i_est.q,
                        }
                        .to_alpha_beta(s, c);
                        let (sr, cr) = sin_cos(p.theta);
                        p.i = p.i + shift.to_dq(sr, cr);
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
    fn weight_is_linear_and_clamped() {
        assert_eq!(observer_weight(0.0, 10.0, 20.0), 0.0);
        assert_eq!(observer_weight(15.0, 10.0, 20.0), 0.5);
        assert_eq!(observer_weight(50.0, 10.0, 20.0), 1.0);
        assert_eq!(observer_weight(f32::NAN, 10.0, 20.0), 0.0);
    }
}
