//! The drive observer: an EKF for recorded drives, whose model carries what a real inverter
//! and a real firmware add to the seed's motor model.
//!
//! State (8): `x = [i_a, i_b, w, th, a, tau, dRs, v_dt]`: the currents (A), the electrical
//! speed (rad/s) and angle (rad), the electrical acceleration `a` (rad/s^2), and three input
//! errors: the lead `tau` (s) of the applied voltage over the logged one, the resistance error
//! `dRs` (ohm) and the inverter's dead-time voltage `v_dt` (V).
//!
//! # Model
//!
//! Over the period `h` that ended at the sample (the record's own period, see
//! [`DriveObserver::step_dt`]), with `I = i_a + j i_b`, `u` the logged voltage of the period:
//!
//! ```text
//! U     = u e^{j w tau} - dRs I - v_dt s(I)          the voltage applied to the windings
//! s(I)  = 2/3 sum_k tanh(i_k / i_band) e^{j 2 pi k / 3}   the phases' conduction signs
//! I-    = alpha I + (1 - alpha) / Rs U + (psi_a / Lq) (-j e^{j th}) w_m G(w_m)
//! w-    = w + a h,   th- = th + w h + a h^2 / 2,   a, tau, dRs, v_dt constant
//! ```
//!
//! with `alpha = e^{-Rs h / Lq}`, `w_m = w + a h / 2` (the period's mean speed), `G` the
//! lag-free EMF gain of [`observer`](crate::observer) (`(e^{j w h} - alpha) / (Rs / Lq + j w)`)
//! and the active flux `psi_a = psi_f + (Ld - Lq) i_d`.
//!
//! - **Voltage timing.** A firmware computes its voltage at the sample and the PWM applies it
//!   later, after rotating it by the speed times the time it expects to elapse; the logged
//!   command then lags the applied vector by a fraction of a period to more than one. At a
//!   fixed speed the lead `tau` shows as the angle offset `w tau`, which a filter without it
//!   takes for an angle; it is observable from the way that offset changes with speed (the
//!   angle must then move at `w + tau dw/dt`, which the speed state and the EMF's magnitude
//!   `w psi_f` cannot both follow) and from the current-dependent terms (`Rs I`,
//!   `j w Lq I`, which do not rotate with the EMF).
//! - **Resistance and dead time.** `dRs I` and `v_dt s(I)` are both voltage drops along the
//!   current; one operating point cannot tell them apart (nor either from an angle and flux
//!   error: the argument of [`tracking`](crate::observer::tracking)). Changes of the current's magnitude
//!   separate them (`dRs I` scales with it, `v_dt s(I)` does not), and changes of speed
//!   separate them from the angle. Both matter most at low speed and high current: on a
//!   4.5 kHz ESC recording, the configured `Rs` was about 30 % high and the dead-time voltage
//!   0.2-0.3 V, enough to lose the rotor in every hard acceleration.
//! - **Acceleration.** A drive steps its speed at 10^5 rad/s^2 el. and more; a speed modelled
//!   as a random walk falls behind, and a filter behind its rotor while the EMF grows is where
//!   `theta + pi` flips happen. The acceleration as a state (a random walk) follows a ramp
//!   without lag and keeps the speed's process noise small at steady speed.
//!
//! # Adaptation only where it is safe
//!
//! The input errors take their gain only while the angle is tracked (`P33` below the limit)
//! and the innovations are consistent ([`ConsistencyCheck`], the same check as the
//! [`PmsmObserver`]'s status), and only once both have held for `settle_s` in a row since the
//! start or the last restart; `dRs` and `v_dt` moreover only while the resistive drop
//! `Rs |i|` is at least `drop_share` (a quarter) of the EMF `|w| psi_f`, where they matter
//! and are told apart from an angle. Otherwise their gain rows are zero: they are held, and
//! the filter runs with them as known inputs (their covariance stays, the Joseph update keeps
//! it consistent with the gain actually used). They carry no process noise: their variance
//! only falls from its prior, so an unobservable direction (one steady operating point) keeps
//! its prior and moves by no more than the data supports. Each is clamped to a physical range
//! (`tau` in `[-Ts, 2 Ts]`, `dRs` in `[-0.9 Rs, 2 Rs]`, `v_dt` in `[0, 8 sigma_vdt_v]`).
//!
//! # Acquisition and restart
//!
//! A default [`PmsmObserver`] runs beside the drive filter on every sample and acquires the
//! rotor (its start-up safeguards: branch check, narrow `R`); after it has reported
//! [`Status::Tracking`] for `restart_s` in a row, the drive filter
//! takes over its angle, speed, currents and their covariance (acceleration 0). Until then the
//! estimate is the acquisition observer's. A drive filter inconsistent for `restart_s` in a
//! row (it has lost the rotor) restarts its motion states: from the acquisition observer when
//! that one tracks, else unknown (`P0`); the input errors and their covariance are kept.
//!
//! The measurement noise is `0.011 I_c` (5.5 times the simulator-tuned default): a recorded
//! drive's currents carry noise and what the model leaves out (harmonics, saturation, PWM
//! ripple). Measured on three real ESC runs and on simulated speed steps: `docs/accuracy.md`.
//!
//! Jacobian: exact in `w`, `th`, `a`, `tau`, `dRs`, `v_dt`; in the currents it keeps the
//! decay, the active flux's and the input errors' terms (the conduction signs' slope
//! included).

use nalgebra::{SMatrix, SVector};

use crate::motor::positive;
use crate::observer::ConsistencyState;
use crate::observer::model::lag_free_gain;
use crate::trig::sin_cos_small;
use crate::{ConfigError, ConsistencyCheck, EkfError, Float, MotorParams, Param, to_t, wrap_angle};
use crate::{Estimate, ObserverConfig, PmsmObserver, Status};

/// Number of states of the drive observer.
pub const DRIVE_STATES: usize = 8;

type Vec8<T> = SVector<T, DRIVE_STATES>;
type Mat8<T> = SMatrix<T, DRIVE_STATES, DRIVE_STATES>;

/// Configuration of a [`DriveObserver`]; start from [`DriveConfig::new`].
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct DriveConfig<T: Float> {
    /// Motor parameters (as configured; the observer estimates `dRs` around `rs_ohm`).
    pub motor: MotorParams<T>,
    /// Nominal sample period `Ts`, s.
    pub ts_s: T,
    /// Current measurement noise standard deviation, A.
    pub sigma_i_a: T,
    /// Current process noise per sample, A.
    pub sigma_i_process_a: T,
    /// Speed random walk per sample, rad/s.
    pub sigma_w_rad_s: T,
    /// Angle random walk per sample, rad.
    pub sigma_th_rad: T,
    /// Acceleration random walk per sample, rad/s^2.
    pub sigma_acc_rad_s2: T,
    /// Prior standard deviation of the voltage lead `tau` (s); its prior mean is 0.
    pub sigma_tau_s: T,
    /// Prior standard deviation of `dRs`, ohm.
    pub sigma_rs_ohm: T,
    /// Prior standard deviation of the dead-time voltage, V.
    pub sigma_vdt_v: T,
    /// Current of the conduction sign's `tanh` band, A.
    pub sign_band_a: T,
    /// Input errors adapt only after this long tracked and consistent, s.
    pub settle_s: T,
    /// Restart the motion states after this long inconsistent, s.
    pub restart_s: T,
    /// The status reads tracking only while the angle's standard deviation is below this, rad.
    pub angle_sigma_limit_rad: T,
    /// `dRs` and `v_dt` adapt only while the resistive drop `Rs |i|` is at least this share
    /// of the back-EMF `|w| psi_f` (where they matter and are told apart from an angle).
    pub drop_share: T,
    /// Estimate the input errors (`false`: they stay 0, an 5-state filter with acceleration).
    pub estimate_input_errors: bool,
    /// The innovation consistency check (status and adaptation).
    pub consistency: ConsistencyCheck<T>,
}

/// Normalized noise levels of [`DriveConfig::new`] (fractions of `I_c = psi_f / Lq`, or per
/// sample in units of `Ts`).
mod norm {
    /// Measurement noise, fraction of `I_c`: a recorded drive's current noise and what the
    /// model leaves out (harmonics, saturation, PWM ripple), 5.5 times the level of
    /// [`NoiseCovariances::scaled`](crate::NoiseCovariances::scaled), which is tuned to the
    /// simulator's sensors.
    pub const SIGMA_I: f64 = 0.011;
    /// Current process noise, fraction of `I_c` per sample.
    pub const SIGMA_I_PROCESS: f64 = 1.0e-3;
    /// Speed random walk, `w Ts` per sample.
    pub const SIGMA_W: f64 = 2.0e-4;
    /// Angle random walk, rad per sample.
    pub const SIGMA_TH: f64 = 1.0e-4;
    /// Acceleration random walk, `a Ts^2` per sample.
    pub const SIGMA_ACC: f64 = 5.0e-5;
    /// Prior of the voltage lead, periods.
    pub const SIGMA_TAU: f64 = 0.5;
    /// Prior of the resistance error, fraction of `Rs`.
    pub const SIGMA_RS: f64 = 0.3;
    /// Prior of the dead-time voltage, fraction of `Rs I_c`.
    pub const SIGMA_VDT: f64 = 0.05;
    /// Conduction sign band, fraction of `I_c`.
    pub const SIGN_BAND: f64 = 0.01;
}

impl<T: Float> DriveConfig<T> {
    /// Defaults scaled from the motor and `Ts` (normalized levels in the source's `norm`):
    /// `I_c = psi_f / Lq` sets the current scales, `Ts` the speed and acceleration scales,
    /// `Rs I_c` the dead-time voltage's prior; settle 0.1 s, restart after 20 ms inconsistent.
    pub fn new(motor: MotorParams<T>, ts_s: T) -> Self {
        let ic = motor.characteristic_current_a();
        Self {
            motor,
            ts_s,
            sigma_i_a: ic * to_t(norm::SIGMA_I),
            sigma_i_process_a: ic * to_t(norm::SIGMA_I_PROCESS),
            sigma_w_rad_s: to_t::<T>(norm::SIGMA_W) / ts_s,
            sigma_th_rad: to_t(norm::SIGMA_TH),
            sigma_acc_rad_s2: to_t::<T>(norm::SIGMA_ACC) / (ts_s * ts_s),
            sigma_tau_s: ts_s * to_t(norm::SIGMA_TAU),
            sigma_rs_ohm: motor.rs_ohm * to_t(norm::SIGMA_RS),
            sigma_vdt_v: motor.rs_ohm * ic * to_t(norm::SIGMA_VDT),
            sign_band_a: ic * to_t(norm::SIGN_BAND),
            settle_s: to_t(0.1),
            restart_s: to_t(0.02),
            angle_sigma_limit_rad: to_t(0.35),
            drop_share: to_t(0.25),
            estimate_input_errors: true,
            consistency: ConsistencyCheck::default_for(ts_s),
        }
    }

    /// Checks every field.
    pub fn validate(&self) -> Result<(), ConfigError> {
        self.motor.validate()?;
        let pos = positive::<T>;
        pos(self.ts_s, Param::Ts)?;
        pos(self.sigma_i_a, Param::DriveNoise)?;
        pos(self.sigma_i_process_a, Param::DriveNoise)?;
        pos(self.sigma_w_rad_s, Param::DriveNoise)?;
        pos(self.sigma_th_rad, Param::DriveNoise)?;
        pos(self.sigma_acc_rad_s2, Param::DriveNoise)?;
        pos(self.sigma_tau_s, Param::DrivePrior)?;
        pos(self.sigma_rs_ohm, Param::DrivePrior)?;
        pos(self.sigma_vdt_v, Param::DrivePrior)?;
        pos(self.sign_band_a, Param::DrivePrior)?;
        pos(self.settle_s, Param::DriveTime)?;
        pos(self.restart_s, Param::DriveTime)?;
        pos(self.angle_sigma_limit_rad, Param::AngleSigmaLimit)?;
        pos(self.drop_share, Param::DrivePrior)?;
        self.consistency.validate()?;
        // The variances must stay finite: the squares of the scales and `1 / Ts^2`.
        let big = self.sigma_acc_rad_s2 * self.sigma_acc_rad_s2 + self.sigma_i_a * self.sigma_i_a;
        if !big.is_finite() {
            return Err(ConfigError::NonFinite(Param::DriveNoise));
        }
        Ok(())
    }
}

/// One output sample of the [`DriveObserver`].
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct DriveEstimate<T> {
    /// Electrical angle, rad, in `[-pi, pi)`.
    pub theta_rad: T,
    /// Electrical speed, rad/s.
    pub omega_e_rad_s: T,
    /// Mechanical speed, rad/s.
    pub omega_mech_rad_s: T,
    /// Electrical acceleration, rad/s^2.
    pub accel_rad_s2: T,
    /// Estimated alpha current, A.
    pub i_alpha_a: T,
    /// Estimated beta current, A.
    pub i_beta_a: T,
    /// Normalized innovation squared of this sample.
    pub nis: T,
    /// Lead of the applied voltage over the logged one, s.
    pub voltage_lead_s: T,
    /// Resistance in use (configured plus estimated error), ohm.
    pub rs_ohm: T,
    /// Dead-time voltage, V.
    pub dead_time_v: T,
    /// The angle is tracked and the innovations are consistent.
    pub tracking: bool,
    /// The innovations are far out of line (the status is then not tracking).
    pub inconsistent: bool,
    /// The input errors took their gain in this sample.
    pub adapting: bool,
    /// The motion states restarted in this sample (inconsistent for `restart_s`).
    pub restarted: bool,
}

/// `Phi P Phi^T` for the drive model's transition ([`DriveObserver::transition`]): rows 0 and 1
/// of `Phi` are dense (the currents), row 2 is the speed's `e2 + h e4`, row 3 the angle's
/// `e3 + h e2 + h^2 / 2 e4`, the others the identity; a quarter of the dense product's
/// multiplications.
fn propagate<T: Float>(phi: &Mat8<T>, p: &Mat8<T>) -> Mat8<T> {
    const N: usize = DRIVE_STATES;
    let (f24, f32_, f34) = (phi[(2, 4)], phi[(3, 2)], phi[(3, 4)]);
    // B = Phi P.
    let mut b = *p;
    for c in 0..N {
        let (mut b0, mut b1) = (T::zero(), T::zero());
        for k in 0..N {
            b0 += phi[(0, k)] * p[(k, c)];
            b1 += phi[(1, k)] * p[(k, c)];
        }
        b[(0, c)] = b0;
        b[(1, c)] = b1;
        b[(2, c)] = p[(2, c)] + f24 * p[(4, c)];
        b[(3, c)] = p[(3, c)] + f32_ * p[(2, c)] + f34 * p[(4, c)];
    }
    // B Phi^T.
    let mut out = b;
    for r in 0..N {
        let (mut c0, mut c1) = (T::zero(), T::zero());
        for k in 0..N {
            c0 += b[(r, k)] * phi[(0, k)];
            c1 += b[(r, k)] * phi[(1, k)];
        }
        out[(r, 0)] = c0;
        out[(r, 1)] = c1;
        out[(r, 2)] = b[(r, 2)] + f24 * b[(r, 4)];
        out[(r, 3)] = b[(r, 3)] + f32_ * b[(r, 2)] + f34 * b[(r, 4)];
    }
    out
}

/// The Joseph update `(I - K H) P- (I - K H)^T + r K K^T` with `H = [I_2 0]`, expanded:
/// `P- - K P-[0:2, :] - P-[:, 0:2] K^T + K S K^T`, `S = P-[0:2, 0:2] + r I`; made symmetric.
fn joseph<T: Float>(pm: &Mat8<T>, kg: &SMatrix<T, DRIVE_STATES, 2>, r: T) -> Mat8<T> {
    const N: usize = DRIVE_STATES;
    let (s00, s01, s10, s11) = (pm[(0, 0)] + r, pm[(0, 1)], pm[(1, 0)], pm[(1, 1)] + r);
    let mut p = *pm;
    for i in 0..N {
        let (k0, k1) = (kg[(i, 0)], kg[(i, 1)]);
        // Row i of K S.
        let (ks0, ks1) = (k0 * s00 + k1 * s10, k0 * s01 + k1 * s11);
        for j in 0..N {
            p[(i, j)] += ks0 * kg[(j, 0)] + ks1 * kg[(j, 1)]
                - (k0 * pm[(0, j)] + k1 * pm[(1, j)])
                - (pm[(i, 0)] * kg[(j, 0)] + pm[(i, 1)] * kg[(j, 1)]);
        }
    }
    let half = to_t::<T>(0.5);
    for i in 0..N {
        for j in (i + 1)..N {
            let v = (p[(i, j)] + p[(j, i)]) * half;
            p[(i, j)] = v;
            p[(j, i)] = v;
        }
    }
    p
}

/// A drive filter's step, computed and not yet committed.
struct DriveStep<T: Float> {
    x: Vec8<T>,
    p: Mat8<T>,
    consistency: ConsistencyState<T>,
    good: u32,
    settled: bool,
    nis: T,
    adapting: bool,
}

/// The drive observer (module docs).
#[derive(Clone, Debug, PartialEq)]
pub struct DriveObserver<T: Float> {
    cfg: DriveConfig<T>,
    x: Vec8<T>,
    p: Mat8<T>,
    p0: Mat8<T>,
    q: Vec8<T>,
    /// Measurement noise variance, A^2.
    r: T,
    consistency: ConsistencyState<T>,
    /// Steps in a row tracked and consistent (counted until settled).
    good: u32,
    /// Tracked and consistent for `settle_s` in a row since the start or the last restart.
    settled: bool,
    /// Steps in a row inconsistent.
    bad: u32,
    settle_samples: u32,
    restart_samples: u32,
    inv_pole_pairs: T,
    nis: T,
    adapting: bool,
    restarted: bool,
    /// The acquisition observer (module docs), always stepped.
    acq: PmsmObserver<T>,
    /// Its last estimate.
    acq_est: Option<Estimate<T>>,
    /// Steps in a row the acquisition observer has reported tracking.
    acq_good: u32,
    /// The drive filter carries the estimate (else the acquisition observer does).
    engaged: bool,
}

fn sq<T: Float>(v: T) -> T {
    v * v
}

/// Complex product of `(re, im)` pairs.
#[inline(always)]
fn cmul<T: Float>(a: (T, T), b: (T, T)) -> (T, T) {
    (a.0 * b.0 - a.1 * b.1, a.0 * b.1 + a.1 * b.0)
}

impl<T: Float> DriveObserver<T> {
    /// Validates `cfg` and builds the observer: state 0 (rotor unknown), `P0` from the
    /// configuration's scales (`(0.1 I_c)^2`, `(0.05 / Ts)^2`, `pi^2`, `(1e-3 / Ts^2)^2`, the
    /// input errors' priors).
    pub fn new(cfg: &DriveConfig<T>) -> Result<Self, ConfigError> {
        cfg.validate()?;
        let ts = cfg.ts_s;
        let ic = cfg.motor.characteristic_current_a();
        let ie = if cfg.estimate_input_errors {
            T::one()
        } else {
            T::zero()
        };
        let p0 = Mat8::from_diagonal(&Vec8::from([
            sq(ic * to_t(0.1)),
            sq(ic * to_t(0.1)),
            sq(to_t::<T>(0.05) / ts),
            sq(T::pi()),
            sq(to_t::<T>(1e-3) / (ts * ts)),
            sq(cfg.sigma_tau_s) * ie,
            sq(cfg.sigma_rs_ohm) * ie,
            sq(cfg.sigma_vdt_v) * ie,
        ]));
        let q = Vec8::from([
            sq(cfg.sigma_i_process_a),
            sq(cfg.sigma_i_process_a),
            sq(cfg.sigma_w_rad_s),
            sq(cfg.sigma_th_rad),
            sq(cfg.sigma_acc_rad_s2),
            T::zero(),
            T::zero(),
            T::zero(),
        ]);
        let samples = |s: T| {
            let n = (s / ts).ceil();
            if n < to_t(1e9) {
                // Whole samples, at least one (`as` saturates).
                let n: f64 = n.to_subset().unwrap_or(1.0);
                (n as u32).max(1)
            } else {
                u32::MAX
            }
        };
        Ok(Self {
            x: Vec8::zeros(),
            p: p0,
            p0,
            q,
            r: sq(cfg.sigma_i_a),
            consistency: ConsistencyState::new(&cfg.consistency),
            good: 0,
            settled: false,
            bad: 0,
            settle_samples: samples(cfg.settle_s),
            restart_samples: samples(cfg.restart_s),
            inv_pole_pairs: T::one() / to_t(f64::from(cfg.motor.pole_pairs)),
            nis: T::zero(),
            adapting: false,
            restarted: false,
            acq: PmsmObserver::new(&ObserverConfig::new(cfg.motor, ts))?,
            acq_est: None,
            acq_good: 0,
            engaged: false,
            cfg: *cfg,
        })
    }

    /// The drive filter's state `[i_a, i_b, w, th, a, tau, dRs, v_dt]` (before the hand-over
    /// its motion part is not the estimate: [`estimate`](Self::estimate) then reports the
    /// acquisition observer's).
    pub fn state(&self) -> &Vec8<T> {
        &self.x
    }

    /// The state covariance (8 x 8).
    pub fn covariance(&self) -> &Mat8<T> {
        &self.p
    }

    /// One sample over the nominal period `Ts` ([`step_dt`](Self::step_dt)).
    pub fn step(&mut self, u_prev: [T; 2], i: [T; 2]) -> Result<DriveEstimate<T>, EkfError> {
        self.step_dt(u_prev, i, self.cfg.ts_s)
    }

    /// One sample: predict over the period `dt_s` that ended now with the logged voltage
    /// `u_prev` of that period, correct with the currents `i` sampled now (project timing).
    /// Refused, nothing changed: non-finite input ([`EkfError::NonFiniteInput`]) or
    /// measurement, an implausible one ([`EkfError::ImplausibleInput`],
    /// [`EkfError::ImplausibleMeasurement`]), a period not in `(0, 64 Ts]`
    /// ([`EkfError::InvalidPeriod`]), or a non-finite result.
    pub fn step_dt(
        &mut self,
        u_prev: [T; 2],
        i: [T; 2],
        dt_s: T,
    ) -> Result<DriveEstimate<T>, EkfError> {
        // Non-finite or implausible samples, as the EKF refuses them (module docs of
        // `observer`, "Implausible input").
        self.acq.check_input(u_prev)?;
        self.acq.check_measurement(i)?;
        let ts = self.cfg.ts_s;
        if !(dt_s > T::zero() && dt_s <= ts * to_t(crate::observer::MAX_PERIOD_FACTOR)) {
            return Err(EkfError::InvalidPeriod);
        }
        // The acquisition observer runs on every sample (its errors refuse the sample; a
        // refused sample leaves it as it was).
        if !self.engaged {
            let e = self.acq.step_dt(u_prev, i, dt_s)?;
            // Hand-over once the acquisition has tracked for `settle_s`: the motion states
            // and their covariance from it, acceleration 0, the input errors kept.
            let good = if e.status == Status::Tracking {
                self.acq_good.saturating_add(1)
            } else {
                0
            };
            self.acq_est = Some(e);
            self.acq_good = good;
            self.restarted = false;
            self.adapting = false;
            self.nis = e.nis;
            if good >= self.restart_samples {
                self.engage(*self.acq.state(), self.acq.covariance());
            }
            return Ok(self.estimate());
        }
        // The drive filter's step is computed first and committed once the acquisition
        // observer has taken the sample too: either one refusing it changes nothing.
        let step = self.drive_step(u_prev, i, dt_s)?;
        // A restart in this step hands over from the acquisition observer as it was before
        // this sample.
        let before = (*self.acq.state(), self.acq.covariance());
        let e = self.acq.step_dt(u_prev, i, dt_s)?;
        let out = self.commit(step, i, before);
        self.acq_est = Some(e);
        self.acq_good = if e.status == Status::Tracking {
            self.acq_good.saturating_add(1)
        } else {
            0
        };
        Ok(out)
    }

    /// Hands the estimate over from the acquisition observer (its state `xa` and covariance
    /// `pa`) to the drive filter.
    fn engage(&mut self, xa: nalgebra::Vector4<T>, pa: nalgebra::Matrix4<T>) {
        for k in 0..4 {
            self.x[k] = xa[k];
        }
        self.x[4] = T::zero();
        for r in 0..5 {
            for c in 0..DRIVE_STATES {
                self.p[(r, c)] = T::zero();
                self.p[(c, r)] = T::zero();
            }
        }
        for r in 0..4 {
            for c in 0..4 {
                self.p[(r, c)] = pa[(r, c)];
            }
        }
        self.p[(4, 4)] = self.p0[(4, 4)];
        self.consistency.restart();
        self.bad = 0;
        self.good = 0;
        self.settled = false;
        self.engaged = true;
    }

    /// One step of the drive filter (engaged), computed, not committed ([`commit`](Self::commit)).
    fn drive_step(&self, u_prev: [T; 2], i: [T; 2], dt_s: T) -> Result<DriveStep<T>, EkfError> {
        let ts = self.cfg.ts_s;
        let (xm, phi) = self.transition(&self.x, u_prev, dt_s);
        let scale = dt_s / ts;
        let mut pm = propagate(&phi, &self.p);
        for k in 0..DRIVE_STATES {
            pm[(k, k)] += self.q[k] * scale;
        }

        // Innovation, S = P-[0:2, 0:2] + R I.
        let y = [i[0] - xm[0], i[1] - xm[1]];
        let r = self.r;
        let (s00, s01, s11) = (pm[(0, 0)] + r, pm[(0, 1)], pm[(1, 1)] + r);
        let det = s00 * s11 - s01 * s01;
        if !det.is_finite() || det <= T::zero() {
            return Err(EkfError::SingularInnovation);
        }
        let inv_det = T::one() / det;
        let (i00, i01, i11) = (s11 * inv_det, -s01 * inv_det, s00 * inv_det);
        let nis = y[0] * (i00 * y[0] + i01 * y[1]) + y[1] * (i01 * y[0] + i11 * y[1]);
        // Adaptation gate (module docs), from the state before this correction.
        let tracked = pm[(3, 3)] <= sq(self.cfg.angle_sigma_limit_rad);
        let mut consistency = self.consistency;
        let _ = consistency.watch(nis);
        let good = if tracked && !consistency.inconsistent {
            self.good.saturating_add(1)
        } else {
            0
        };
        let ok = tracked && !consistency.inconsistent;
        let settled = self.settled || good >= self.settle_samples;

        let adapting = self.cfg.estimate_input_errors && settled && ok;
        // K = P- H^T S^-1 (8 x 2); the input errors' rows zero unless adapting.
        let mut kg = SMatrix::<T, DRIVE_STATES, 2>::zeros();
        // The drops along the current (dRs, v_dt) only where they are a fair share of the
        // voltage: `Rs |i| >= drop_share |w| psi_f` (module docs).
        let m = &self.cfg.motor;
        let drop = m.rs_ohm * (xm[0] * xm[0] + xm[1] * xm[1]).sqrt();
        let drops = drop >= self.cfg.drop_share * xm[2].abs() * m.psi_f_wb;
        let rows = if adapting { DRIVE_STATES } else { 5 };
        for r in 0..rows {
            if r >= 6 && !drops {
                continue;
            }
            let (a, b) = (pm[(r, 0)], pm[(r, 1)]);
            kg[(r, 0)] = a * i00 + b * i01;
            kg[(r, 1)] = a * i01 + b * i11;
        }
        let mut x = xm;
        for r in 0..DRIVE_STATES {
            x[r] += kg[(r, 0)] * y[0] + kg[(r, 1)] * y[1];
        }
        x[3] = wrap_angle(x[3]);
        self.clamp_inputs(&mut x);
        let p = joseph(&pm, &kg, r);
        if !(x.iter().all(|v| v.is_finite()) && p.iter().all(|v| v.is_finite())) {
            return Err(EkfError::NonFiniteResult);
        }
        Ok(DriveStep {
            x,
            p,
            consistency,
            good,
            settled,
            nis,
            adapting,
        })
    }

    /// Commits a drive filter's step (the measured currents `i` and the acquisition observer
    /// `acq` = (state, covariance) for a restart); returns the estimate.
    fn commit(
        &mut self,
        s: DriveStep<T>,
        i: [T; 2],
        acq: (nalgebra::Vector4<T>, nalgebra::Matrix4<T>),
    ) -> DriveEstimate<T> {
        self.x = s.x;
        self.p = s.p;
        self.consistency = s.consistency;
        self.good = s.good;
        self.settled = s.settled;
        self.nis = s.nis;
        self.adapting = s.adapting;
        self.bad = if s.consistency.inconsistent {
            self.bad.saturating_add(1)
        } else {
            0
        };
        self.restarted = false;
        if self.bad >= self.restart_samples {
            self.restart_motion(i, acq);
        }
        self.estimate()
    }

    /// Restarts the drive filter's motion states (module docs): the drive filter has been
    /// inconsistent for `restart_s`. From the acquisition observer when it tracks, else
    /// unknown (`P0` block: speed, angle and acceleration), with the measured currents. The
    /// input errors and their covariance are kept; their correlation with the motion is
    /// dropped.
    fn restart_motion(&mut self, i: [T; 2], acq: (nalgebra::Vector4<T>, nalgebra::Matrix4<T>)) {
        if self.acq_est.is_some_and(|e| e.status == Status::Tracking) {
            self.engage(acq.0, acq.1);
        } else {
            self.x[0] = i[0];
            self.x[1] = i[1];
            self.x[2] = T::zero();
            self.x[4] = T::zero();
            for r in 0..5 {
                for c in 0..DRIVE_STATES {
                    self.p[(r, c)] = self.p0[(r, c)];
                    self.p[(c, r)] = self.p0[(c, r)];
                }
            }
            self.consistency.restart();
            self.bad = 0;
            self.good = 0;
            self.settled = false;
        }
        self.restarted = true;
    }

    fn clamp_inputs(&self, x: &mut Vec8<T>) {
        let ts = self.cfg.ts_s;
        let rs = self.cfg.motor.rs_ohm;
        let cl = |v: T, lo: T, hi: T| {
            if v < lo {
                lo
            } else if v > hi {
                hi
            } else {
                v
            }
        };
        x[5] = cl(x[5], -ts, ts + ts);
        x[6] = cl(x[6], rs * to_t(-0.9), rs + rs);
        let vmax = self.cfg.sigma_vdt_v * to_t(8.0);
        x[7] = cl(x[7], T::zero(), vmax);
    }

    /// The model's prediction over `h` from `x` with the logged voltage `u`, and its
    /// Jacobian (module docs).
    fn transition(&self, x: &Vec8<T>, u: [T; 2], h: T) -> (Vec8<T>, Mat8<T>) {
        let m = &self.cfg.motor;
        let (ia, ib, w, th, acc, tau, drs, vdt) = (x[0], x[1], x[2], x[3], x[4], x[5], x[6], x[7]);
        let inv_l = T::one() / m.lq_h;
        let a = m.rs_ohm * inv_l;
        let one_minus_alpha = -(-a * h).exp_m1();
        let alpha = T::one() - one_minus_alpha;
        let g = one_minus_alpha / m.rs_ohm;
        let half: T = to_t(0.5);
        // Voltage lead: U0 = u e^{j w tau}.
        let (st, ct) = sin_cos_small(w * tau);
        let u0 = cmul((u[0], u[1]), (ct, st));
        // Conduction signs s(I) and their slopes.
        let band = self.cfg.sign_band_a;
        let r3 = to_t::<T>(0.866_025_403_784_438_6);
        let phases = [ia, -half * ia + r3 * ib, -half * ia - r3 * ib];
        // d i_k / d (ia, ib).
        let dph = [(T::one(), T::zero()), (-half, r3), (-half, -r3)];
        // e^{j 2 pi k / 3}.
        let rot = [(T::one(), T::zero()), (-half, r3), (-half, -r3)];
        let two_thirds: T = to_t(2.0 / 3.0);
        let (mut s_re, mut s_im) = (T::zero(), T::zero());
        let (mut ds_a, mut ds_b) = ((T::zero(), T::zero()), (T::zero(), T::zero()));
        for k in 0..3 {
            let t = (phases[k] / band).tanh();
            let slope = (T::one() - t * t) / band * two_thirds;
            s_re += two_thirds * t * rot[k].0;
            s_im += two_thirds * t * rot[k].1;
            ds_a.0 += slope * dph[k].0 * rot[k].0;
            ds_a.1 += slope * dph[k].0 * rot[k].1;
            ds_b.0 += slope * dph[k].1 * rot[k].0;
            ds_b.1 += slope * dph[k].1 * rot[k].1;
        }
        let ur = (u0.0 - drs * ia - vdt * s_re, u0.1 - drs * ib - vdt * s_im);
        // EMF: c (-j e^{j th}) M, M = w_m G(w_m), c = psi_a / Lq.
        let (sn, cs) = th.sin_cos_angle();
        let sal = (m.ld_h - m.lq_h) * inv_l;
        let id = ia * cs + ib * sn;
        let iq = ib * cs - ia * sn;
        let c = m.psi_f_wb * inv_l + sal * id;
        let wm = w + acc * h * half;
        let (_, m_v, mp) = lag_free_gain(a, one_minus_alpha, wm, h);
        let e0 = (sn, -cs);
        let e0m = cmul(e0, m_v);
        let e0mp = cmul(e0, mp);
        let ia_n = alpha * ia + g * ur.0 + c * e0m.0;
        let ib_n = alpha * ib + g * ur.1 + c * e0m.1;
        let xn = Vec8::from([
            ia_n,
            ib_n,
            w + acc * h,
            wrap_angle(th + w * h + acc * h * h * half),
            acc,
            tau,
            drs,
            vdt,
        ]);
        let mut f = Mat8::<T>::identity();
        // d/d ia, d/d ib.
        let (ka, kb) = (sal * cs, sal * sn);
        f[(0, 0)] = alpha - g * drs - g * vdt * ds_a.0 + ka * e0m.0;
        f[(1, 0)] = -g * vdt * ds_a.1 + ka * e0m.1;
        f[(0, 1)] = -g * vdt * ds_b.0 + kb * e0m.0;
        f[(1, 1)] = alpha - g * drs - g * vdt * ds_b.1 + kb * e0m.1;
        // d/d w: g j tau U0 + c e0 M'.
        f[(0, 2)] = -g * tau * u0.1 + c * e0mp.0;
        f[(1, 2)] = g * tau * u0.0 + c * e0mp.1;
        // d/d th: c e^{j th} M + sal i_q e0 M.
        let em = cmul((cs, sn), m_v);
        f[(0, 3)] = c * em.0 + sal * iq * e0m.0;
        f[(1, 3)] = c * em.1 + sal * iq * e0m.1;
        // d/d a: c e0 M' h / 2.
        f[(0, 4)] = c * e0mp.0 * h * half;
        f[(1, 4)] = c * e0mp.1 * h * half;
        // d/d tau: g j w U0.
        f[(0, 5)] = -g * w * u0.1;
        f[(1, 5)] = g * w * u0.0;
        // d/d dRs, d/d v_dt.
        f[(0, 6)] = -g * ia;
        f[(1, 6)] = -g * ib;
        f[(0, 7)] = -g * s_re;
        f[(1, 7)] = -g * s_im;
        // Motion rows.
        f[(2, 4)] = h;
        f[(3, 2)] = h;
        f[(3, 4)] = h * h * half;
        (xn, f)
    }

    /// The current estimate.
    pub fn estimate(&self) -> DriveEstimate<T> {
        let x = &self.x;
        if !self.engaged {
            let e = self.acq_est.unwrap_or_else(|| self.acq.estimate());
            return DriveEstimate {
                theta_rad: e.theta_rad,
                omega_e_rad_s: e.omega_e_rad_s,
                omega_mech_rad_s: e.omega_mech_rad_s,
                accel_rad_s2: T::zero(),
                i_alpha_a: e.i_alpha_a,
                i_beta_a: e.i_beta_a,
                nis: e.nis,
                voltage_lead_s: x[5],
                rs_ohm: self.cfg.motor.rs_ohm + x[6],
                dead_time_v: x[7],
                tracking: e.status == Status::Tracking,
                inconsistent: e.inconsistent,
                adapting: false,
                restarted: self.restarted,
            };
        }
        let tracked = self.p[(3, 3)] <= sq(self.cfg.angle_sigma_limit_rad);
        let inconsistent = self.consistency.inconsistent;
        DriveEstimate {
            theta_rad: x[3],
            omega_e_rad_s: x[2],
            omega_mech_rad_s: x[2] * self.inv_pole_pairs,
            accel_rad_s2: x[4],
            i_alpha_a: x[0],
            i_beta_a: x[1],
            nis: self.nis,
            voltage_lead_s: x[5],
            rs_ohm: self.cfg.motor.rs_ohm + x[6],
            dead_time_v: x[7],
            tracking: tracked && !inconsistent,
            inconsistent,
            adapting: self.adapting,
            restarted: self.restarted,
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    /// A symmetric positive definite 8 x 8 matrix of distinct entries.
    fn spd() -> Mat8<f64> {
        let a = Mat8::<f64>::from_fn(|r, c| {
            ((r * 8 + c) as f64 * 0.37).sin() + if r == c { 2.0 } else { 0.0 }
        });
        a * a.transpose()
    }

    #[test]
    fn structured_products_are_the_dense_ones() {
        let m = MotorParams::<f64>::servo();
        let ts = 1e-4;
        let obs = DriveObserver::new(&DriveConfig::new(m, ts)).unwrap();
        let x = Vec8::from([1.2, -0.7, 900.0, 0.4, 3e4, 0.3 * ts, 0.02, 0.15]);
        for h in [ts, 2.5 * ts] {
            let (_, phi) = obs.transition(&x, [3.0, -1.0], h);
            let p = spd();
            let dense = phi * p * phi.transpose();
            let fast = propagate(&phi, &p);
            let scale = dense.abs().max();
            assert!((fast - dense).abs().max() <= 1e-13 * scale, "propagate");
            let kg =
                SMatrix::<f64, DRIVE_STATES, 2>::from_fn(|r, c| ((r + 3 * c) as f64).cos() * 0.1);
            let r = 0.3;
            let mut a = Mat8::<f64>::identity();
            for k in 0..DRIVE_STATES {
                a[(k, 0)] -= kg[(k, 0)];
                a[(k, 1)] -= kg[(k, 1)];
            }
            let mut jd = a * dense * a.transpose() + kg * kg.transpose() * r;
            jd = (jd + jd.transpose()) * 0.5;
            let jf = joseph(&dense, &kg, r);
            assert!((jf - jd).abs().max() <= 1e-12 * jd.abs().max(), "joseph");
            assert_eq!(jf, jf.transpose());
        }
    }
}
