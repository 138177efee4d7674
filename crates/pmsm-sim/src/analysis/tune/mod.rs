//! Offline tuning of the observer's noise covariances `Q` and `R` from a recorded run.
//!
//! # Method
//!
//! Given a record (voltages `u_ab`, measured currents `i_ab`, docs/design.md, "Conventions" timing:
//! row `k` of `u_ab` is the voltage held over `[t_k, t_k+1)`, so sample `k` predicts with
//! `u_ab[k-1]`, zero for `k = 0`), the observer ([`ekf_core::PmsmObserver`], `f64`) is run
//! with candidate noise parameters and scored by the log-likelihood of its innovations
//!
//! ```text
//! L = -0.5 sum_k ( log det S_k + NIS_k )        (the constant -N log 2 pi left out)
//! ```
//!
//! over the samples after a convergence window ([`TuneOptions::skip`]). The parameters are the
//! logarithms of the normalized noise levels of [`ekf_core::noise`] ([`NormalizedNoise`]):
//! `sigma_z` (sensor noise, fraction of `I_c = psi_f / Ls`; one value, or the alpha and beta
//! values and their correlation, [`RShape`]), `sigma_i` (current model error per sample,
//! fraction of `I_c`), `sigma_w` (speed random walk, rad per sample per sample) and
//! `sigma_th` (angle random walk, rad per sample). A derivative-free optimizer
//! ([`nelder_mead`], Nelder-Mead with adaptive coefficients and one restart) maximizes `L`
//! inside a box of [`TuneOptions::bound_decades`] decades around the start (the project's
//! defaults); a parameter that ends on the box is reported ([`TuneReport::at_bound`]).
//!
//! The report gives `Q` and `R` in SI units, the normalized values, and before/after
//! figures: `L`, the mean NIS (2 for a consistent filter with two measurements) and, when the
//! true angle is known, the angle error of the default and the tuned filter.
//!
//! Phase-current sensing makes the alpha-beta noise correlated: two phase channels of standard
//! deviation `s` with `i_c = -i_a - i_b` give `R = s^2 [[1, 1/sqrt 3], [1/sqrt 3, 5/3]]`
//! ([`sensor_r_ab`]). [`RShape::Full`] (the default) can represent that; `Isotropic` fits
//! one `sigma_z` (about the mean variance).
//!
//! # From a log
//!
//! [`tune_qr_mcap`] reads a `pmsm-sim` MCAP log: motor, `Ts` and sensor settings from the
//! `/pmsm_sim/scenario` message, and per period the measured currents, the voltage the
//! simulator's observer was given (rebuilt as the simulator does: the controller's expected
//! voltage, delayed with the computation delay, for `foc`; the commanded voltage of the
//! applied duties otherwise; zero with the PWM off), the true angle and speed, and the logged
//! observer's angle. Replaying the default filter on the log must reproduce the logged angle
//! exactly (protobuf; to rounding for a JSON log); [`McapTuneReport::replay_matches_log`] says
//! whether it did.

use std::path::Path;

use ekf_core::nalgebra::{Matrix2, Vector4};
use ekf_core::noise::{SIGMA_I_NORM, SIGMA_TH, SIGMA_W_NORM, SIGMA_Z_NORM};
use ekf_core::{
    Discretization, EkfError, MotorParams, NoiseCovariances, ObserverConfig, PmsmObserver,
};
use serde::Serialize;

use crate::plant::sensors::SensorConfig;
use crate::scenario::Scenario;

mod logged_run;
pub use logged_run::*;

mod mcap_read;
pub mod nelder_mead;

/// Fewest samples after the convergence window the tuner accepts.
pub const MIN_SAMPLES: usize = 200;

/// Why the tuner could not run.
#[derive(Debug, thiserror::Error)]
pub enum TuneError {
    /// `u_ab` and `i_ab` differ in length.
    #[error("u_ab has {u} rows and i_ab {i}: they must be equal")]
    LengthMismatch {
        /// Rows of `u_ab`.
        u: usize,
        /// Rows of `i_ab`.
        i: usize,
    },
    /// A truth array's length differs from the record's.
    #[error("{what} has {len} rows, the record {n}")]
    TruthLength {
        /// Which array.
        what: &'static str,
        /// Its length.
        len: usize,
        /// The record's length.
        n: usize,
    },
    /// Too few samples after the convergence window.
    #[error(
        "{n} samples with {skip} skipped for convergence leaves fewer than {min} to score \
         (use a longer record or a smaller skip)"
    )]
    TooShort {
        /// Samples in the record.
        n: usize,
        /// Convergence window.
        skip: usize,
        /// Minimum scored samples ([`MIN_SAMPLES`]).
        min: usize,
    },
    /// Motor parameters or `Ts` refused by the observer.
    #[error("observer configuration refused: {0}")]
    Config(#[from] ekf_core::ConfigError),
    /// An option is out of range.
    #[error("option {name}: {problem}")]
    Option {
        /// The option.
        name: &'static str,
        /// What is wrong.
        problem: String,
    },
    /// No parameter set gave a filter that ran through the record.
    #[error("no noise setting gave a filter that runs through the record ({0})")]
    NoUsableFilter(String),
    /// The log could not be read.
    #[error("{path}: {message}")]
    Log {
        /// The file.
        path: String,
        /// What failed.
        message: String,
    },
}

/// How `R` is parametrized.
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq, Serialize)]
#[serde(rename_all = "snake_case")]
pub enum RShape {
    /// `R = sigma_z^2 I_c^2 I2`: one parameter.
    Isotropic,
    /// Alpha and beta standard deviations and their correlation: three parameters (what
    /// phase-current sensing produces, module docs).
    #[default]
    Full,
}

/// Noise levels in the normalized units of [`ekf_core::noise`] (module docs).
#[derive(Clone, Copy, Debug, PartialEq, Serialize)]
pub struct NormalizedNoise {
    /// Sensor noise standard deviation `[alpha, beta]`, fraction of `I_c`.
    pub sigma_z: [f64; 2],
    /// Correlation of the alpha and beta sensor noise (0 for [`RShape::Isotropic`]).
    pub rho_z: f64,
    /// Current model error per sample, fraction of `I_c`.
    pub sigma_i: f64,
    /// Speed random walk, `w_e Ts` radians per sample, per sample.
    pub sigma_w: f64,
    /// Angle random walk, radians per sample.
    pub sigma_th: f64,
}

impl Default for NormalizedNoise {
    /// The observer's default ([`NoiseCovariances::scaled`]).
    fn default() -> Self {
        Self {
            sigma_z: [SIGMA_Z_NORM; 2],
            rho_z: 0.0,
            sigma_i: SIGMA_I_NORM,
            sigma_w: SIGMA_W_NORM,
            sigma_th: SIGMA_TH,
        }
    }
}

/// Convergence tolerance of the search on the log-parameters (1 % on a sigma).
/// Filter passes run by the searches of this process ([`tune_qr`] and the functions built on
/// it), counted as they run, for a progress display: a reader polls it from another thread
/// (`pmsm-sim tune` on a terminal). Only ever increased; results never depend on it.
pub static FILTER_PASSES: std::sync::atomic::AtomicUsize = std::sync::atomic::AtomicUsize::new(0);

const X_TOL: f64 = 1e-2;

/// Largest `|atanh(rho)|` the search uses (`|rho| <= 0.999`).
const ATANH_RHO_MAX: f64 = 3.8;

impl NormalizedNoise {
    /// `Q` and `R` in SI units for a motor and `Ts`:
    /// `R = I_c^2 [[sa^2, rho sa sb], [rho sa sb, sb^2]]`,
    /// `Q = diag((sigma_i I_c)^2, (sigma_i I_c)^2, (sigma_w / Ts)^2, sigma_th^2)`.
    pub fn covariances(&self, motor: &MotorParams<f64>, ts_s: f64) -> NoiseCovariances<f64> {
        let ic = motor.characteristic_current_a();
        let [sa, sb] = self.sigma_z.map(|s| s * ic);
        let off = self.rho_z * sa * sb;
        let qi = (self.sigma_i * ic).powi(2);
        let mut n = NoiseCovariances::from_diagonals(
            [qi, qi, (self.sigma_w / ts_s).powi(2), self.sigma_th.powi(2)],
            [sa * sa, sb * sb],
        );
        n.r = Matrix2::new(sa * sa, off, off, sb * sb);
        n
    }

    /// The search vector: logs of the sigmas (and `atanh(rho)` for [`RShape::Full`]).
    fn to_vector(self, shape: RShape) -> Vec<f64> {
        let tail = [self.sigma_i.ln(), self.sigma_w.ln(), self.sigma_th.ln()];
        match shape {
            RShape::Isotropic => {
                let mean_var = 0.5 * (self.sigma_z[0].powi(2) + self.sigma_z[1].powi(2));
                let mut v = vec![0.5 * mean_var.ln()];
                v.extend(tail);
                v
            }
            RShape::Full => {
                let mut v = vec![
                    self.sigma_z[0].ln(),
                    self.sigma_z[1].ln(),
                    self.rho_z.clamp(-0.999, 0.999).atanh(),
                ];
                v.extend(tail);
                v
            }
        }
    }

    fn from_vector(shape: RShape, v: &[f64]) -> Self {
        let (sigma_z, rho_z, rest) = match shape {
            RShape::Isotropic => ([v[0].exp(); 2], 0.0, &v[1..]),
            RShape::Full => ([v[0].exp(), v[1].exp()], v[2].tanh(), &v[3..]),
        };
        Self {
            sigma_z,
            rho_z,
            sigma_i: rest[0].exp(),
            sigma_w: rest[1].exp(),
            sigma_th: rest[2].exp(),
        }
    }

    fn names(shape: RShape) -> &'static [&'static str] {
        match shape {
            RShape::Isotropic => &["sigma_z", "sigma_i", "sigma_w", "sigma_th"],
            RShape::Full => &[
                "sigma_z_alpha",
                "sigma_z_beta",
                "rho_z",
                "sigma_i",
                "sigma_w",
                "sigma_th",
            ],
        }
    }

    fn check(&self) -> Result<(), TuneError> {
        let all = [
            self.sigma_z[0],
            self.sigma_z[1],
            self.sigma_i,
            self.sigma_w,
            self.sigma_th,
        ];
        if !all.iter().all(|s| s.is_finite() && *s > 0.0) {
            return Err(TuneError::Option {
                name: "start",
                problem: format!("every sigma must be finite and > 0, got {self:?}"),
            });
        }
        if self.rho_z.is_nan() || self.rho_z.abs() >= 1.0 {
            return Err(TuneError::Option {
                name: "start",
                problem: format!("rho_z must be in (-1, 1), got {}", self.rho_z),
            });
        }
        Ok(())
    }
}

/// Options of [`tune_qr`].
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct TuneOptions {
    /// Samples excluded from the score at the start (the filter's convergence). Default
    /// (`None`): `min(N / 5, 0.1 s / Ts)`.
    pub skip: Option<usize>,
    /// Parametrization of `R`.
    pub r_shape: RShape,
    /// Objective evaluations (filter runs) allowed.
    pub max_evaluations: usize,
    /// Start of the search and the "before" of the report (default: the observer's default).
    pub start: NormalizedNoise,
    /// The search box: each sigma within this many decades of its start.
    pub bound_decades: f64,
    /// Discretization of the filter.
    pub discretization: Discretization,
    /// Initial state `[i_a, i_b, w_e, theta]`, one period before the first sample.
    pub x0: [f64; 4],
    /// Angle-error window: only samples with `|omega_true|` at least this (rad/s electrical).
    /// Default (`None`): 0 for [`tune_qr`], 5 % of rated speed for [`tune_qr_mcap`].
    pub min_speed_rad_s: Option<f64>,
}

impl Default for TuneOptions {
    fn default() -> Self {
        Self {
            skip: None,
            r_shape: RShape::Full,
            max_evaluations: 5000,
            start: NormalizedNoise::default(),
            bound_decades: 3.0,
            discretization: Discretization::LagFree,
            x0: [0.0; 4],
            min_speed_rad_s: None,
        }
    }
}

/// The true rotor angle (and speed) of a record, aligned on its rows.
#[derive(Clone, Copy, Debug)]
pub struct AngleTruth<'a> {
    /// Electrical angle, rad.
    pub theta_rad: &'a [f64],
    /// Electrical speed, rad/s (for the low-speed exclusion of the angle error), if known.
    pub omega_rad_s: Option<&'a [f64]>,
}

/// Angle error `wrap(theta_hat - theta)` over the scored window, electrical degrees.
#[derive(Clone, Copy, Debug, PartialEq, Serialize)]
pub struct AngleStats {
    /// Root mean square.
    pub rms_deg: f64,
    /// Mean (bias).
    pub mean_deg: f64,
    /// Largest magnitude.
    pub max_abs_deg: f64,
    /// Samples in the window.
    pub samples: usize,
}

/// How one filter setting does on the record.
#[derive(Clone, Debug, PartialEq, Serialize)]
pub struct FilterScore {
    /// `-0.5 sum (log det S_k + NIS_k)` over the scored samples (`-inf` if the filter failed).
    pub log_likelihood: f64,
    /// Mean NIS over the scored samples (2 expected).
    pub mean_nis: f64,
    /// Angle error, when the truth was given.
    pub angle_error: Option<AngleStats>,
    /// Why the filter stopped, if it did (singular or non-finite update).
    pub failure: Option<String>,
}

/// The tuner's result.
#[derive(Clone, Debug, PartialEq, Serialize)]
pub struct TuneReport {
    /// Proposed process noise `Q` (4 x 4), SI (A^2, A^2, (rad/s)^2, rad^2 per sample).
    pub q: [[f64; 4]; 4],
    /// Proposed measurement noise `R` (2 x 2), A^2.
    pub r: [[f64; 2]; 2],
    /// The proposal in normalized units.
    pub tuned: NormalizedNoise,
    /// The start (the "before" filter).
    pub start: NormalizedNoise,
    /// `R` parametrization used.
    pub r_shape: RShape,
    /// The start filter on the record.
    pub before: FilterScore,
    /// The tuned filter on the record.
    pub after: FilterScore,
    /// Filter runs the search used.
    pub evaluations: usize,
    /// Whether the search met its tolerances (else it used up its evaluations).
    pub converged: bool,
    /// Parameters that ended on the search box (the data do not pin them inside it).
    pub at_bound: Vec<&'static str>,
    /// Samples excluded at the start.
    pub skip: usize,
    /// Samples scored.
    pub samples_scored: usize,
    /// Samples the filter rejected (non-finite input or measurement).
    pub samples_rejected: usize,
    /// `I_c = psi_f / Ls` of the motor, A (the normalized units' scale).
    pub characteristic_current_a: f64,
    /// Sample time, s.
    pub ts_s: f64,
}

impl TuneReport {
    /// The proposal as a TOML table (`[observer_noise]`, SI `q` and `r` and the normalized
    /// values): a scenario file takes it as it is (`pmsm_sim::scenario::ObserverNoise`: the
    /// simulator's EKF uses `q` and `r`), and the numbers serve `ObserverConfig::noise` or
    /// `pyfoc.Ekf(q=..., r=...)`.
    pub fn toml_snippet(&self) -> String {
        let row = |r: &[f64]| {
            let v: Vec<String> = r.iter().map(|x| plain(*x)).collect();
            format!("[{}]", v.join(", "))
        };
        let mat = |m: &[&[f64]]| {
            let v: Vec<String> = m.iter().map(|r| row(r)).collect();
            format!("[{}]", v.join(", "))
        };
        let t = &self.tuned;
        let q: Vec<&[f64]> = self.q.iter().map(|r| r.as_slice()).collect();
        let r: Vec<&[f64]> = self.r.iter().map(|r| r.as_slice()).collect();
        format!(
            "# Proposed by pmsm-sim tune (innovation likelihood). Paste into a scenario file (the\n\
             # simulator's EKF takes q and r), or use for ObserverConfig::noise or pyfoc.Ekf(q=, r=).\n\
             [observer_noise]\n\
             q = {}\n\
             r = {}\n\
             # normalized (ekf_core::noise units, I_c = {} A, Ts = {} s)\n\
             sigma_z = {}\n\
             rho_z = {}\n\
             sigma_i = {}\n\
             sigma_w = {}\n\
             sigma_th = {}\n",
            mat(&q),
            mat(&r),
            plain(self.characteristic_current_a),
            plain(self.ts_s),
            row(&t.sigma_z),
            plain(t.rho_z),
            plain(t.sigma_i),
            plain(t.sigma_w),
            plain(t.sigma_th),
        )
    }
}

/// `x` as a TOML float, shortest round-trip ([`crate::error::plain`]).
pub use crate::error::plain;

/// The measurement noise `R` (alpha-beta, A^2) that a current sensor configuration
/// produces: per-phase variance `s^2` (noise plus quantization, `LSB^2 / 12`), two phases
/// measured and the third reconstructed, amplitude-invariant Clarke:
/// `R = s^2 [[1, 1/sqrt 3], [1/sqrt 3, 5/3]]`. Gain errors and offsets are not noise and are
/// left out.
pub fn sensor_r_ab(cfg: &SensorConfig) -> [[f64; 2]; 2] {
    let mut v = cfg.current_noise_std_a.powi(2);
    if cfg.adc_bits > 0 {
        let lsb = 2.0 * cfg.adc_full_scale_a / 2f64.powi(cfg.adc_bits as i32);
        v += lsb * lsb / 12.0;
    }
    let c = v / 3f64.sqrt();
    [[v, c], [c, v * 5.0 / 3.0]]
}

/// One filter pass over the record.
struct Pass {
    /// `0.5 * mean(log det S + NIS)` over the scored samples (`+inf` on failure).
    cost: f64,
    mean_nis: f64,
    scored: usize,
    rejected: usize,
    failure: Option<String>,
    theta: Vec<f64>,
}

struct Problem<'a> {
    motor: MotorParams<f64>,
    ts_s: f64,
    discretization: Discretization,
    x0: [f64; 4],
    u: &'a [[f64; 2]],
    i: &'a [[f64; 2]],
    skip: usize,
}

impl Problem<'_> {
    fn config(&self, noise: NoiseCovariances<f64>) -> ObserverConfig<f64> {
        let mut cfg = ObserverConfig::new(self.motor, self.ts_s);
        cfg.discretization = self.discretization;
        cfg.x0 = Vector4::from(self.x0);
        cfg.noise = noise;
        cfg
    }

    fn pass(&self, noise: &NormalizedNoise, keep_theta: bool) -> Pass {
        let fail = |why: String| Pass {
            cost: f64::INFINITY,
            mean_nis: f64::NAN,
            scored: 0,
            rejected: 0,
            failure: Some(why),
            theta: Vec::new(),
        };
        let cfg = self.config(noise.covariances(&self.motor, self.ts_s));
        let mut obs = match PmsmObserver::new(&cfg) {
            Ok(o) => o,
            Err(e) => return fail(e.to_string()),
        };
        let mut theta = Vec::with_capacity(if keep_theta { self.i.len() } else { 0 });
        let (mut sum, mut sum_nis, mut scored, mut rejected) = (0.0, 0.0, 0usize, 0usize);
        let mut prev = [0.0; 2];
        for (k, (u, i)) in self.u.iter().zip(self.i).enumerate() {
            match obs.step(prev, *i) {
                Ok(e) => {
                    if k >= self.skip {
                        let c = obs.last_correction();
                        let det = c.innovation_covariance.determinant();
                        if !(det > 0.0 && det.is_finite()) {
                            return fail(format!("sample {k}: det S = {det}"));
                        }
                        sum += det.ln() + c.nis;
                        sum_nis += c.nis;
                        scored += 1;
                    }
                    if keep_theta {
                        theta.push(e.theta_rad);
                    }
                }
                Err(EkfError::NonFiniteInput | EkfError::NonFiniteMeasurement) => {
                    rejected += 1;
                    if keep_theta {
                        theta.push(obs.estimate().theta_rad);
                    }
                }
                Err(e) => return fail(format!("sample {k}: {e}")),
            }
            prev = *u;
        }
        if scored == 0 {
            return fail("no sample scored".into());
        }
        let n = scored as f64;
        Pass {
            cost: 0.5 * sum / n,
            mean_nis: sum_nis / n,
            scored,
            rejected,
            failure: None,
            theta,
        }
    }
}

fn angle_stats(
    theta: &[f64],
    truth: &AngleTruth<'_>,
    skip: usize,
    min_speed: f64,
) -> Option<AngleStats> {
    let (mut s2, mut s1, mut mx, mut n) = (0.0, 0.0, 0.0f64, 0usize);
    for (k, (est, tru)) in theta.iter().zip(truth.theta_rad).enumerate().skip(skip) {
        if let Some(w) = truth.omega_rad_s
            && w[k].abs() < min_speed
        {
            continue;
        }
        let e = ekf_core::wrap_angle(est - tru).to_degrees();
        s2 += e * e;
        s1 += e;
        mx = mx.max(e.abs());
        n += 1;
    }
    (n > 0).then(|| AngleStats {
        rms_deg: (s2 / n as f64).sqrt(),
        mean_deg: s1 / n as f64,
        max_abs_deg: mx,
        samples: n,
    })
}

fn option_err(name: &'static str, problem: String) -> TuneError {
    TuneError::Option { name, problem }
}

/// Proposes `Q` and `R` for a record by maximizing the innovation likelihood (module docs).
///
/// `u_ab[k]` is the voltage held over `[t_k, t_k+1)`, `i_ab[k]` the currents sampled at `t_k`
/// (docs/design.md, "Conventions"); non-finite rows are rejected by the filter and not scored.
/// `truth`, when given, adds the angle error of the start and the tuned filter to the report.
/// Each objective evaluation is one filter pass over the record: the cost is about
/// `max_evaluations` passes.
pub fn tune_qr(
    motor: &MotorParams<f64>,
    ts_s: f64,
    u_ab: &[[f64; 2]],
    i_ab: &[[f64; 2]],
    truth: Option<AngleTruth<'_>>,
    opts: &TuneOptions,
) -> Result<TuneReport, TuneError> {
    ObserverConfig::new(*motor, ts_s).validate()?;
    let n = i_ab.len();
    if u_ab.len() != n {
        return Err(TuneError::LengthMismatch {
            u: u_ab.len(),
            i: n,
        });
    }
    if let Some(t) = &truth {
        if t.theta_rad.len() != n {
            return Err(TuneError::TruthLength {
                what: "theta_true",
                len: t.theta_rad.len(),
                n,
            });
        }
        if let Some(w) = t.omega_rad_s
            && w.len() != n
        {
            return Err(TuneError::TruthLength {
                what: "omega_true",
                len: w.len(),
                n,
            });
        }
    }
    opts.start.check()?;
    if opts.max_evaluations == 0 {
        return Err(option_err("max_evaluations", "must be at least 1".into()));
    }
    if !(opts.bound_decades.is_finite() && opts.bound_decades > 0.0) {
        return Err(option_err(
            "bound_decades",
            format!("must be finite and > 0, got {}", opts.bound_decades),
        ));
    }
    if !opts.x0.iter().all(|v| v.is_finite()) {
        return Err(option_err(
            "x0",
            format!("must be finite, got {:?}", opts.x0),
        ));
    }
    let min_speed = opts.min_speed_rad_s.unwrap_or(0.0);
    if !(min_speed.is_finite() && min_speed >= 0.0) {
        return Err(option_err(
            "min_speed_rad_s",
            format!("must be finite and >= 0, got {min_speed}"),
        ));
    }
    let skip = opts
        .skip
        .unwrap_or_else(|| (n / 5).min((0.1 / ts_s).round() as usize));
    if n.saturating_sub(skip) < MIN_SAMPLES {
        return Err(TuneError::TooShort {
            n,
            skip,
            min: MIN_SAMPLES,
        });
    }
    let problem = Problem {
        motor: *motor,
        ts_s,
        discretization: opts.discretization,
        x0: opts.x0,
        u: u_ab,
        i: i_ab,
        skip,
    };
    let shape = opts.r_shape;
    let x_start = opts.start.to_vector(shape);
    let span = opts.bound_decades * core::f64::consts::LN_10;
    let names = NormalizedNoise::names(shape);
    let bounds: Vec<(f64, f64)> = x_start
        .iter()
        .zip(names)
        .map(|(x, name)| {
            if *name == "rho_z" {
                (-ATANH_RHO_MAX, ATANH_RHO_MAX)
            } else {
                (x - span, x + span)
            }
        })
        .collect();
    let clamp = |x: &[f64]| -> Vec<f64> {
        x.iter()
            .zip(&bounds)
            .map(|(v, (lo, hi))| v.clamp(*lo, *hi))
            .collect()
    };
    // Outside the box the filter runs on the clamped point, plus a quadratic penalty on the
    // excess: the objective keeps a minimum (on the box) along a direction the data do not
    // pin down, and the simplex can contract there.
    let objective = |x: &[f64]| {
        FILTER_PASSES.fetch_add(1, std::sync::atomic::Ordering::Relaxed);
        let c = clamp(x);
        let excess: f64 = x.iter().zip(&c).map(|(a, b)| (a - b) * (a - b)).sum();
        problem
            .pass(&NormalizedNoise::from_vector(shape, &c), false)
            .cost
            + excess
    };
    let steps: Vec<f64> = names
        .iter()
        .map(|n| if *n == "rho_z" { 0.5 } else { 1.0 })
        .collect();
    let result = nelder_mead::minimize(
        objective,
        &x_start,
        &steps,
        &nelder_mead::NmOptions {
            max_evaluations: opts.max_evaluations,
            x_tol: X_TOL,
            f_tol: 1e-7,
        },
    );
    if !result.f.is_finite() {
        let why = problem.pass(&opts.start, false).failure.unwrap_or_default();
        return Err(TuneError::NoUsableFilter(why));
    }
    let x_best = clamp(&result.x);
    let at_bound: Vec<&'static str> = x_best
        .iter()
        .zip(&bounds)
        .zip(names)
        .filter(|((v, (lo, hi)), _)| *v - lo < 2.0 * X_TOL || hi - *v < 2.0 * X_TOL)
        .map(|(_, name)| *name)
        .collect();
    let tuned = NormalizedNoise::from_vector(shape, &x_best);
    let keep = truth.is_some();
    let score = |p: &Pass| FilterScore {
        log_likelihood: -p.cost * p.scored as f64,
        mean_nis: p.mean_nis,
        angle_error: truth
            .as_ref()
            .filter(|_| p.failure.is_none())
            .and_then(|t| angle_stats(&p.theta, t, skip, min_speed)),
        failure: p.failure.clone(),
    };
    let before = problem.pass(&opts.start, keep);
    let after = problem.pass(&tuned, keep);
    let cov = tuned.covariances(motor, ts_s);
    Ok(TuneReport {
        q: core::array::from_fn(|r| core::array::from_fn(|c| cov.q[(r, c)])),
        r: core::array::from_fn(|r| core::array::from_fn(|c| cov.r[(r, c)])),
        tuned,
        start: opts.start,
        r_shape: shape,
        before: score(&before),
        after: score(&after),
        evaluations: result.evaluations,
        converged: result.converged,
        at_bound,
        skip,
        samples_scored: after.scored,
        samples_rejected: after.rejected,
        characteristic_current_a: motor.characteristic_current_a(),
        ts_s,
    })
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn vector_round_trip_and_covariances() {
        let n = NormalizedNoise {
            sigma_z: [3e-3, 4e-3],
            rho_z: 0.5,
            sigma_i: 1e-3,
            sigma_w: 2e-4,
            sigma_th: 1e-5,
        };
        let back = NormalizedNoise::from_vector(RShape::Full, &n.to_vector(RShape::Full));
        for (a, b) in [
            (back.sigma_z[0], n.sigma_z[0]),
            (back.sigma_z[1], n.sigma_z[1]),
            (back.rho_z, n.rho_z),
            (back.sigma_i, n.sigma_i),
            (back.sigma_w, n.sigma_w),
            (back.sigma_th, n.sigma_th),
        ] {
            assert!((a - b).abs() <= 1e-12 * b.abs(), "{a} {b}");
        }
        let m = MotorParams::from_f64(2.875, 8.5e-3, 0.175, 4);
        // The default reproduces ekf-core's scaled default exactly.
        let d = NormalizedNoise::default().covariances(&m, 1e-4);
        let e = NoiseCovariances::scaled(&m, 1e-4);
        assert!((d.q - e.q).abs().max() <= 1e-15 * e.q.abs().max());
        assert!((d.r - e.r).abs().max() <= 1e-15 * e.r.abs().max());
        let c = n.covariances(&m, 1e-4);
        let ic = 0.175 / 8.5e-3;
        assert!((c.r[(0, 1)] - 0.5 * 3e-3 * 4e-3 * ic * ic).abs() < 1e-15);
        assert_eq!(c.r[(0, 1)], c.r[(1, 0)]);
    }

    #[test]
    fn sensor_r_of_two_phase_sensing() {
        let cfg = SensorConfig {
            current_noise_std_a: 0.1,
            ..SensorConfig::default()
        };
        let r = sensor_r_ab(&cfg);
        assert!((r[0][0] - 0.01).abs() < 1e-15);
        assert!((r[1][1] - 0.01 * 5.0 / 3.0).abs() < 1e-15);
        assert!((r[0][1] / (r[0][0] * r[1][1]).sqrt() - 5f64.sqrt().recip()).abs() < 1e-12);
        // Against the simulator's sensor: sample covariance of 40 000 readings of zero current.
        let mut sensor = crate::plant::sensors::CurrentSensor::new(cfg, 3);
        let n = 40_000;
        let mut m = [[0.0; 2]; 2];
        for _ in 0..n {
            let z = sensor.measure([0.0; 3]).i_ab_a;
            for a in [0, 1] {
                for b in [0, 1] {
                    m[a][b] += z[a] * z[b] / f64::from(n);
                }
            }
        }
        for a in [0, 1] {
            for b in [0, 1] {
                // Standard error of a (co)variance estimate from 40 000 samples: under 1.5 %.
                assert!((m[a][b] - r[a][b]).abs() < 0.03 * r[0][0], "{m:?} vs {r:?}");
            }
        }
    }
}
