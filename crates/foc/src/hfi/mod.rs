//! High-frequency injection (HFI): rotor angle and speed of a salient motor at standstill and
//! low speed, where the back-EMF the observer needs is too small, with magnet polarity
//! detection.
//!
//! One file per part: `config` (settings, defaults, checks), `injection` (the carrier),
//! `demod` (demodulation), `pll` (tracking loop), `tracker` ([`HfiTracker`]: the three in
//! signal order), `polarity` (the standstill test's states), `blend` (the hand-over band),
//! `drive` (the controller's HFI state and its dispatcher). Measured results, with the
//! commands that reproduce them: `docs/hfi.md`.
//!
//! # Method: pulsating square wave on the estimated d axis, a fraction of the PWM rate
//!
//! Each tick adds `u_h[k] = V_h s[k] (cos phi_k, sin phi_k)` to the stator voltage (alpha-beta):
//! `s[k]` is `+1` for `N` ticks and `-1` for `N` ticks ([`HfiConfig::half_period_ticks`], 1 to
//! [`MAX_HALF_PERIOD`]: carrier `f_pwm / (2 N)`, e.g. 10 kHz at 20 kHz PWM with `N = 1`,
//! 1.67 kHz at 10 kHz with `N = 3`), and `phi_k = theta_hat + w_hat advance Ts` is the
//! tracked d axis at the middle of the period the voltage is applied in (the controller's own
//! angle advance, module [`crate::controller`]).
//!
//! **Why a square wave and not a sinusoid.** (1) The response is demodulated from sample
//! differences over one carrier period: no band-pass or low-pass filter, no phase to tune,
//! and the response is in the very next samples, so the tracking loop can be fast. (2) The
//! mean over a period separates the fundamental from the carrier (a comb notch at the carrier
//! and its harmonics), so the current loops keep their bandwidth and gain `N - 1/2` periods of
//! delay. (3) For a given voltage the current ripple is the smallest the PWM can make
//! (`N Ts V_h / L` peak to peak) and, with `N = 1`, the carrier sits at the top of the audible
//! band or above it. A sinusoid at `f_pwm / 8` needs filters whose delay limits the tracking
//! bandwidth (Jang 2003, Yoon 2011 compare the two). A longer half period `N` raises the
//! signal-to-noise ratio as `N` at a given voltage (the current moves for `N` periods between
//! the sign changes where the information is) and the ripple as `N`: the choice for motors of
//! low saliency or noisy current sensing.
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
//! surface motor ([`HfiError::SurfaceMotor`], `Lq / Ld` below [`MIN_SALIENCY`]). Each sample
//! difference, signed with the carrier applied over it and projected on that carrier's axis,
//! `y[k] = s_a R(-phi_a) (i[k] - i[k-1])`, is one carrier step plus the fundamental's change;
//! the fundamental's change cancels over one carrier period (the signs balance), leaving
//!
//! ```text
//! mean_2N(y) = Ts V (Y_s + Y_d cos 2e,  Y_d sin 2e)
//! eps = q / (2 Ts V Y_d) = sin(2e) / 2   (~ e for small errors; clamped to +-1)
//! ```
//!
//! `s_a` is the sign of the voltage applied over `[t_k-1, t_k)`, computed two ticks ago with
//! the one-period computation delay, one tick ago without it (a short history keeps sign and
//! axis). The d part, `Ts V / Ld,inc` at `e = 0`, is the incremental d-axis admittance that
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
//! slope), and takes `c`, the carrier step: weights `T_perp / |T_perp|^2` on the samples
//! (`T_perp`: `T` less its projection on `1` and `j`), turned into weights of the signed
//! steps, a table per window phase computed once ([`HfiTracker::new`]). For `N = 1` they are
//! the mean (three samples, three unknowns); for long half periods the long-run noise variance
//! of the step falls to `12 / N^2` of a sample's.
//!
//! The fundamental's slope is taken out in the fixed frame first. Each step is projected on
//! the axis its carrier was applied along, and that axis moves within the window (the loop
//! corrects the angle every tick), so a slope constant in alpha-beta, `b`, is not constant in
//! the projected steps: the weights, which cancel a constant step, let through
//! `sum w_j s_j R(-phi_j) b`, the slope times the axis' wobble. When the current loops move
//! the fundamental, its slope is far larger than the carrier's q response, and that leak
//! biases the angle with the speed. The tracker therefore subtracts that sum with `b` the mean
//! step over the window, `(i[k] - i[k-2N]) / 2N`, in which the carrier cancels: exact for a
//! still axis, where the sum is zero.
//!
//! # Angle noise
//!
//! The current sensors' noise (`sigma` per phase, two phases sampled: `c = -a - b`) is not
//! the same on every axis: its variance along an axis at `psi` from phase a is
//! `sigma^2 (4/3 - cos(2 psi) / 3 + sin(2 psi) / sqrt 3)`, from `2/3` to `2 sigma^2`. The angle
//! information is the q response, so the angle noise depends on the rotor's orientation by up
//! to `sqrt 3`. Through the loop (noise bandwidth `1.03 w_n` Hz for `w_n` in rad/s) the
//! predicted angle noise at the worst orientation
//! ([`HfiConfig::predicted_angle_rms_rad`]) is
//!
//! ```text
//! sigma_theta^2 = (12 / N^2) 2 sigma^2 / (2 Ts V Y_d)^2 * 2 (1.03 w_n) Ts
//! ```
//!
//! It scales exactly as `sigma^2`; the largest error over a few seconds is about four times
//! the RMS.
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
//! low, which is what keeps the sensor noise out of the angle. The speed output is `w` (no
//! proportional noise). With `J` unknown, `a_ff = 0` gives a type-3 loop that still tracks
//! any speed ramp without error. `eps` is clamped to `+-1` so that a noise spike cannot throw
//! the angle. Without a response (too little carrier history, a refused sample) the loop
//! predicts (`eps = 0`). The loop has two stable points, `e = 0` and `e = pi`: the carrier
//! cannot see the magnet's polarity.
//!
//! # Magnet polarity
//!
//! Run once at standstill after the loop has settled ([`HfiConfig::settle_time_s`], zero
//! current): two current pulses along the tracked d axis, `+I_p` then `-I_p`
//! ([`HfiConfig::polarity_current_a`], each [`HfiConfig::pulse_time_s`] long and followed by
//! half of it at zero current), with the carrier on; the d response is averaged over the
//! second half of each pulse. The pulse that adds to the magnet's flux saturates the d-axis
//! iron and lowers its incremental inductance, so the carrier's d response (`Ts V / Ld,inc`)
//! is larger. The rule:
//!
//! ```text
//! contrast = mean d(+I_p) / mean d(-I_p);   contrast < 1: the axis is turned by pi
//! ```
//!
//! (a NaN contrast, no response, keeps the axis). The contrast is reported
//! ([`HfiStatus::polarity_contrast`]); a motor without d-axis saturation gives a contrast near
//! 1 and the decision is then a coin toss (a real motor saturates by several percent at rated
//! current; the simulator's plant has an optional saturation model for this test). The states
//! ([`HfiPhase`]): `Settling -> PulsePositive -> PulseNegative -> Tracking`;
//! [`HfiConfig::detect_polarity`] `false` goes from `Settling` to `Tracking` unflipped.
//!
//! # Hand-over band
//!
//! From `blend_low_rad_s` to `blend_high_rad_s` the control angle is HFI's plus the observer's
//! weight times the observer's difference from it:
//!
//! ```text
//! lambda = clamp((|w| - blend_low) / (blend_high - blend_low), 0, 1)   (1 with the carrier off)
//! theta  = wrap(theta_hfi + lambda wrap(theta_o - theta_hfi)),  omega = w_hfi + lambda (w_o - w_hfi)
//! ```
//!
//! Rules:
//! - the carrier goes off above the top of the band, by HFI's speed, and comes back below
//!   80 % of it, by the observer's speed low-passed at the tracking loop's bandwidth (which
//!   also seeds the tracker's speed, with the load set to the drive's acceleration): the
//!   observer's raw speed at the bottom of its range would toggle the carrier;
//! - the speed `w` the weight follows is HFI's own tracked speed: the observer's is noisiest
//!   at the bottom of its range and would feed back into its own weight;
//! - with a long carrier period, where the rotor turns more than [`HFI_PERIOD_ANGLE_RAD`]
//!   (0.05 rad el.) per carrier period at the top of the band (`blend_high 2 N Ts`,
//!   [`long_carrier_period`]), `w` is the faster of HFI's speed and the observer's
//!   low-passed speed: there HFI's speed lags the rotor's while the speed grows, and the
//!   faster estimate gives the observer the weight of the rotor's actual speed;
//! - the tick the weight first leaves 0, the observer is re-seeded at HFI's angle and speed
//!   (it may have drifted while the speed was low) and the angle stays HFI's for that tick.
//!
//! **HFI's angle fused into the observer.** The blend mixes the two outputs only: inside the
//! band the observer can drift away from HFI on its own, and the control angle follows it by
//! its weight. With a short carrier period the controller therefore also gives the observer
//! HFI's angle as a measurement, every tick while HFI has a say (tracking, carrier on,
//! weight below 1): one scalar Kalman correction of the observer's angle
//! (`ekf_core::PmsmObserver::correct_angle`; the speed moves with it through their
//! covariance) of variance
//!
//! ```text
//! var = sigma_f^2 / (1 - lambda_prev)      sigma_f = HfiConfig::fusion_sigma_rad
//! ```
//!
//! (the last tick's weight): tight at the bottom of the band, gone at the top, so that the
//! observer arrives at the carrier's switch-off where HFI is, its speed consistent with it.
//! With a long carrier period HFI is the weak side at the top of the band and is not fused.
//!
//! # Current feedback and voltage
//!
//! While the carrier is on, the current loops see the fundamental (the mean of the last
//! carrier period's samples, the carrier removed), and their voltage limit is lowered by
//! `V_h` so that the sum stays within the modulation limit.
//!
//! # Defaults from the motor and why ([`HfiConfig::new`], [`HfiConfig::with_current_noise`])
//!
//! `I_lim` current limit, `u_lim` the voltage limit at the nominal bus, `a_max = p k_t I_lim
//! / J` the acceleration of a full-torque step, `h` the start-up hand-over speed.
//!
//! | setting | default | why |
//! |---|---|---|
//! | `injection_v` `V_h` | `0.1 I_lim Ld / Ts`, at most `0.8 u_lim` | carrier ripple 10 % of the current limit peak to peak on the d axis; room left for the fundamental |
//! | `half_period_ticks` `N` | 1, or the smallest `N <= 4` (at `0.8 u_lim`) with `N Ts V_h Y_d >= 0.03 I_lim` | the shortest period (least ripple and delay) whose saliency signal stands out of the sensor's noise, which scales with its full scale and so with `I_lim` |
//! | `pll_bandwidth_rad_s` `w_n` | `sqrt(a_max)`, within 5-50 Hz and at most `0.1 / ((N + 2) Ts)` | a full-torque load step costs at most [`LOAD_STEP_PEAK`]` a_max / w_n^2 = 0.27` rad (the triple-pole loop's peak, within its +-45 deg capture range); a tenth of the loop's delay (the period's estimate and the computation delay) |
//! | with the noise known | as above if the predicted angle noise is within [`TARGET_ANGLE_RMS_RAD`] (1 deg); otherwise `V_h = 0.8 u_lim`, `w_n = sqrt(0.54 a_max)` and the shortest `N <= 8` that meets it | 1 deg RMS keeps the largest error within about 5 deg; `0.54 a_max` is what a load step allows at 0.5 rad |
//! | `blend_low_rad_s`, `blend_high_rad_s` | `h / 2`, `h` | the observer takes over where the start-up would hand over to it |
//! | `fusion_sigma_rad` | [`HFI_FUSION_SIGMA_RAD`] (0.03 rad), 0 with a long carrier period | inside the range that passes the traction IPM's reversal over noise seeds (`docs/hfi.md`); a long period makes HFI the weak side at the band's top |
//! | observer's `psi_f`/`Rs` tracking | frozen below [`HFI_TRACKING_SPEED_FACTOR`]` = 2` times `blend_high` (`Foc::enable_hfi`; `disable_hfi` restores it) | a flux estimate let loose at a few % of rated speed collapses within milliseconds and loses the reversal by pi |
//! | polarity | `I_p = 0.8 I_lim`, 20 ms pulses after 60 ms of settling | the deeper the saturation, the clearer the contrast, with headroom under the limit for the carrier's ripple; the loop locks on the salient axis before the pulses, and each pulse's current has settled by its measured second half |

mod blend;
mod config;
mod demod;
mod drive;
mod injection;
mod pll;
mod polarity;
mod tracker;

#[cfg(test)]
mod tests;

pub use blend::{HFI_PERIOD_ANGLE_RAD, long_carrier_period};
pub use config::{
    HFI_FUSION_SIGMA_RAD, HFI_TRACKING_SPEED_FACTOR, HfiConfig, HfiError, HfiField, LOAD_STEP_PEAK,
    MAX_HALF_PERIOD, MIN_SALIENCY, TARGET_ANGLE_RMS_RAD,
};
pub use demod::Response;
pub(crate) use drive::HfiDrive;
/// What the controller holds while HFI is on: the drive, or without the `hfi` feature a type
/// with no value (every HFI branch of the tick compiled out, `crate::gate`).
#[cfg(feature = "hfi")]
pub(crate) type HfiSlot = HfiDrive;
/// What the controller holds while HFI is on: the drive, or without the `hfi` feature a type
/// with no value (every HFI branch of the tick compiled out, `crate::gate`).
#[cfg(not(feature = "hfi"))]
pub(crate) type HfiSlot = crate::gate::Absent<HfiDrive>;
pub use drive::{HfiPhase, HfiStatus};
pub use tracker::HfiTracker;
