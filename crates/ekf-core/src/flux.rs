//! The baseline to beat: the nonlinear flux observer with a PLL that open motor-control
//! firmware runs (ODrive's and VESC's sensorless estimators are variants of it).
//!
//! Written from the published method (Ortega, Praly, Astolfi, Lee, Nam: "Estimation of rotor
//! position and speed of permanent magnet synchronous motors with guaranteed stability",
//! IEEE TCST 2011; Lee, Hong, Nam, Ortega, Praly, Astolfi: "Sensorless control of surface-mount
//! permanent-magnet synchronous motors based on a nonlinear observer", IEEE TPEL 2010) and the
//! publicly documented defaults of those firmwares; no firmware code is used.
//!
//! # The observer
//!
//! The stator flux linkage `lambda = Ls i + psi_f e^{j th}` obeys `d lambda/dt = u - Rs i`. The
//! observer integrates that, and pulls its estimate `x` radially towards the circle on which the
//! magnet flux `eta = x - Ls i` must lie (`|eta| = psi_f`), by the gradient of
//! `(psi_f^2 - |eta|^2)^2`:
//!
//! ```text
//! dx/dt = u - Rs i + gamma/2 eta (psi_f^2 - |eta|^2),     eta = x - Ls i
//! th_flux = atan2(eta_b, eta_a)
//! ```
//!
//! Near the circle the radial error `psi_f - |eta|` decays at the rate `gamma psi_f^2`; the
//! configuration gives that rate, `g = observer_gain_rad_s`, and `gamma = g / psi_f^2` (the
//! normalisation ODrive documents, so one gain serves any motor). The direction of `eta` (the
//! angle) is not corrected at all: it comes from the integration, which is why parameter and
//! voltage errors bias it and offsets make it wander.
//!
//! A PLL (PI on the sine of the angle difference) follows `th_flux` and gives the speed:
//!
//! ```text
//! th_pll- = th_pll + Ts w_pll                                   (predict)
//! e       = (eta_b cos th_pll- - eta_a sin th_pll-) / psi_f     (= sin(th_flux - th_pll-) |eta| / psi_f)
//! th_pll  = th_pll- + Ts kp e,    w_pll = w_pll + Ts ki e,    kp = 2 bw, ki = bw^2
//! ```
//!
//! (closed loop `(s + bw)^2`: critically damped, the tuning ODrive documents: `ki = kp^2 / 4`).
//! The angle output is `th_flux` (what both firmwares commutate with) unless
//! [`FluxAngleOutput::Pll`] is chosen; the speed output is always `w_pll`.
//!
//! # Discrete form and timing ([`FluxTiming`])
//!
//! `step(u_prev, i)` at sample `k` has the timing of [`PmsmObserver::step`](crate::PmsmObserver)
//! (`docs/design.md` section 4): `u_prev = u[k-1]`, held over `[t_k-1, t_k)`, and `i = i[k]`,
//! sampled at `t_k`. [`FluxTiming::Firmware`] (the default, the form the firmwares run) is
//! forward Euler on the sample:
//!
//! ```text
//! eta_0 = x - Ls i[k]                                    (previous flux, the NEW current)
//! x     = x + Ts (u[k-1] - Rs i[k] + gamma/2 eta_0 (psi_f^2 - |eta_0|^2))
//! eta   = x - Ls i[k],   th_flux = atan2(eta)            (estimate of th(t_k))
//! ```
//!
//! The voltage term is exact for a held voltage, so the flux itself carries no half-sample lag
//! from it. What is not centred: the correction pairs the flux of `t_k-1` with the current of
//! `t_k`, and `Rs i[k]` stands for the mean resistive drop over the period. The first is the
//! one that matters. With a q current `i_q` turning at `w_e`, `Ls (i[k-1] - i[k])` is a radial
//! vector of length `Ls i_q w_e Ts`; the correction answers it with a radial pull of
//! `g Ts Ls i_q w_e Ts` per sample along the previous angle, which the rotation turns into a
//! tangential flux error `b` with `w_e Ts b = g Ts Ls i_q w_e Ts`. So in steady state the angle
//! leads by
//!
//! ```text
//! bias = g Ts Ls i_q / psi_f   rad        (independent of the speed)
//! ```
//!
//! 0.57 deg with the default gain at `Ls i_q = 0.1 psi_f`. [`FluxTiming::Centred`] is the
//! obvious compensation: the correction uses `eta_0 = x - Ls i[k-1]` (both at `t_k-1`) and the
//! resistive drop the mean `Rs (i[k-1] + i[k]) / 2` (both forms measured in
//! `docs/accuracy.md`). The suite's baseline is the firmware form.
//!
//! # Interior motors: active flux
//!
//! With `Ld != Lq` the observer runs on the active flux (the EKF's model, `observer` module
//! docs): `eta = x - Lq i` is `psi_a e^{j th}` with `psi_a = psi_f + (Ld - Lq) i_d`, so the
//! circle's radius is `psi_a`, with `i_d` taken along the PLL's last predicted d axis. That
//! radius depends on the angle estimate, `d psi_a / d th = (Ld - Lq) i_q`, and the dependence
//! feeds back: linearised in the rotor frame (radial error `r`, angle error `d`, radial rate
//! `a = 2 gamma psi_a^2`, `b = (Ld - Lq) i_q`),
//!
//! ```text
//! dr/dt = -a r + (w psi_a + a b) d,     dd/dt = -(w / psi_a) r
//! ```
//!
//! which is stable only while `w (w + a b / psi_a) > 0`, i.e. for `|w| > 2 gamma psi_a |b|` when
//! `w b < 0`: an interior motor under load at moderate speed (the failure VESC users report at
//! `Lq = 2 Ld`; measured in `docs/accuracy.md`). The step therefore limits `gamma / 2` to
//! `|w_pll| / (8 psi_a |b|)` (a margin of 2 on the bound; surface motors are untouched). The
//! firmware form's lead shrinks with the gain.
//!
//! # Usual tuning ([`FluxObserverConfig::new`])
//!
//! ODrive's documented defaults are `observer_gain = 1000 rad/s` (with `gamma` normalised by
//! `psi_f^2` as above) and a PLL bandwidth of `1000 rad/s`, at a current-loop rate of 8 kHz:
//! both about `0.1 / Ts`. The default here keeps those products with the sample time,
//! `g Ts = 0.1` ([`OBSERVER_GAIN_TS`]) and `bw Ts = 0.1` ([`PLL_BANDWIDTH_TS`]): 1000 rad/s each
//! at 10 kHz, exactly the firmware numbers. Both products must stay at or below
//! [`MAX_GAIN_TS`] (the Euler updates become unstable well before 2).
//!
//! # Precision and cost
//!
//! Generic over [`Float`]; `no_std`, no allocation, no panics. `atan2` is `RealField::atan2`:
//! without `std` that is `libm`'s `atan2f` for `f32`, which computes in `f32` only (FreeBSD's
//! `e_atan2f.c` and `s_atanf.c`: single-precision polynomials, no `f64`); the PLL's sine and
//! cosine are [`Float::sin_cos_angle`] (single precision for `f32`).

use crate::ekf::{EkfError, finite};
use crate::motor::positive;
use crate::{ConfigError, Float, MotorParams, Param, to_t, wrap_angle};

/// Default observer gain times the sample time, `g Ts` (module docs: ODrive's 1000 rad/s at
/// 8 to 10 kHz).
pub const OBSERVER_GAIN_TS: f64 = 0.1;
/// Default PLL bandwidth times the sample time, `bw Ts` (ODrive's 1000 rad/s at 8 to 10 kHz).
pub const PLL_BANDWIDTH_TS: f64 = 0.1;
/// Largest accepted `g Ts` and `bw Ts`.
pub const MAX_GAIN_TS: f64 = 0.5;

/// Which samples the Euler step pairs (module docs).
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq)]
pub enum FluxTiming {
    /// Forward Euler on the sample, as the firmwares run it: the correction uses the previous
    /// flux with the new current, the resistive drop the new current.
    #[default]
    Firmware,
    /// Half-sample compensation: the correction uses the previous flux with the previous
    /// current, the resistive drop the mean of the previous and the new current.
    Centred,
}

/// Which angle [`FluxEstimate::theta_rad`] reports.
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq)]
pub enum FluxAngleOutput {
    /// The flux angle `atan2(eta)`, what the firmwares commutate with.
    #[default]
    Flux,
    /// The PLL's (smoothed) angle.
    Pll,
}

/// Configuration of the [`FluxObserver`]; start from [`FluxObserverConfig::new`].
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct FluxObserverConfig<T: Float> {
    /// Motor parameters (Rs, Ls, psi_f, pole pairs).
    pub motor: MotorParams<T>,
    /// Sample (PWM) period, s.
    pub ts_s: T,
    /// Radial convergence rate `g` of the flux estimate, rad/s (`gamma = g / psi_f^2`);
    /// `0 < g Ts <=` [`MAX_GAIN_TS`].
    pub observer_gain_rad_s: T,
    /// PLL bandwidth `bw`, rad/s (`kp = 2 bw`, `ki = bw^2`); `0 < bw Ts <=` [`MAX_GAIN_TS`].
    pub pll_bandwidth_rad_s: T,
    /// Discrete form (default: the firmware's).
    pub timing: FluxTiming,
    /// Angle output (default: the flux angle).
    pub angle_output: FluxAngleOutput,
}

impl<T: Float> FluxObserverConfig<T> {
    /// The usual tuning (module docs): `g = 0.1 / Ts`, `bw = 0.1 / Ts`, firmware timing, flux
    /// angle output.
    pub fn new(motor: MotorParams<T>, ts_s: T) -> Self {
        Self {
            motor,
            ts_s,
            observer_gain_rad_s: to_t::<T>(OBSERVER_GAIN_TS) / ts_s,
            pll_bandwidth_rad_s: to_t::<T>(PLL_BANDWIDTH_TS) / ts_s,
            timing: FluxTiming::Firmware,
            angle_output: FluxAngleOutput::Flux,
        }
    }

    /// Checks every field; the observer's constructor calls it.
    pub fn validate(&self) -> Result<(), ConfigError> {
        self.motor.validate()?;
        positive(self.ts_s, Param::Ts)?;
        positive(self.observer_gain_rad_s, Param::ObserverGain)?;
        positive(self.pll_bandwidth_rad_s, Param::PllBandwidth)?;
        let max: T = to_t(MAX_GAIN_TS);
        if self.observer_gain_rad_s * self.ts_s > max {
            return Err(ConfigError::TooLargeForTs(Param::ObserverGain));
        }
        if self.pll_bandwidth_rad_s * self.ts_s > max {
            return Err(ConfigError::TooLargeForTs(Param::PllBandwidth));
        }
        Ok(())
    }
}

/// One output sample of the [`FluxObserver`].
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct FluxEstimate<T> {
    /// Electrical rotor angle, rad, in `[-pi, pi)`: the flux or the PLL angle
    /// ([`FluxAngleOutput`]).
    pub theta_rad: T,
    /// Electrical speed (the PLL's), rad/s.
    pub omega_e_rad_s: T,
    /// Mechanical speed `omega_e / pole_pairs`, rad/s.
    pub omega_mech_rad_s: T,
    /// Flux angle `atan2(eta)`, rad, in `[-pi, pi)`.
    pub theta_flux_rad: T,
    /// PLL angle, rad, in `[-pi, pi)`.
    pub theta_pll_rad: T,
    /// Magnet flux estimate `eta = x - Ls i`, `[alpha, beta]`, Wb.
    pub eta_wb: [T; 2],
}

/// The nonlinear flux observer with a PLL (module docs).
#[derive(Clone, Debug, PartialEq)]
pub struct FluxObserver<T: Float> {
    ts: T,
    rs: T,
    /// `Lq` (the active-flux inductance; `Ls` of a surface motor), H.
    ls: T,
    /// The inductance of the last step's active flux (`ls`, or a flux map's chord `Lq`), H.
    ls_now: T,
    psi2: T,
    /// `psi_f`, Wb.
    psi: T,
    /// `Ld - Lq`, H (0 for a surface motor).
    dl: T,
    inv_psi: T,
    /// `gamma / 2 = g / (2 psi_f^2)`.
    gamma_half: T,
    kp: T,
    ki: T,
    inv_pole_pairs: T,
    timing: FluxTiming,
    output: FluxAngleOutput,
    /// Stator flux estimate `x`, Wb.
    x: [T; 2],
    /// `(sin, cos)` of the PLL's last predicted angle (the d axis of a salient motor's
    /// active flux).
    pll_dir: [T; 2],
    /// Previous current sample (for [`FluxTiming::Centred`]), A.
    i_prev: [T; 2],
    theta_flux: T,
    theta_pll: T,
    w_pll: T,
}

impl<T: Float> FluxObserver<T> {
    /// Validates `cfg` and builds the observer with everything unknown: flux, current, angle
    /// and speed zero (the state one period before the first sample).
    pub fn new(cfg: &FluxObserverConfig<T>) -> Result<Self, ConfigError> {
        cfg.validate()?;
        let m = &cfg.motor;
        let psi2 = m.psi_f_wb * m.psi_f_wb;
        let bw = cfg.pll_bandwidth_rad_s;
        let two = T::one() + T::one();
        Ok(Self {
            ts: cfg.ts_s,
            rs: m.rs_ohm,
            ls: m.lq_h,
            ls_now: m.lq_h,
            psi2,
            psi: m.psi_f_wb,
            dl: m.ld_h - m.lq_h,
            inv_psi: T::one() / m.psi_f_wb,
            gamma_half: cfg.observer_gain_rad_s / (two * psi2),
            kp: two * bw,
            ki: bw * bw,
            inv_pole_pairs: T::one() / to_t(f64::from(m.pole_pairs)),
            timing: cfg.timing,
            output: cfg.angle_output,
            x: [T::zero(); 2],
            i_prev: [T::zero(); 2],
            pll_dir: [T::zero(), T::one()],
            theta_flux: T::zero(),
            theta_pll: T::zero(),
            w_pll: T::zero(),
        })
    }

    /// The `(psi_f, Rs)` it uses (the configured ones: it tracks neither), Wb and ohm.
    pub fn parameters(&self) -> (T, T) {
        (T::one() / self.inv_psi, self.rs)
    }

    /// One sample: `u_prev = [u_a, u_b]` (V) held over the previous period, `i = [i_a, i_b]`
    /// (A) sampled now (module docs give the update).
    ///
    /// A non-finite input or measurement, or a non-finite result, returns the error and leaves
    /// the observer exactly as it was.
    pub fn step(&mut self, u_prev: [T; 2], i: [T; 2]) -> Result<FluxEstimate<T>, EkfError> {
        let (ls, psi, dl) = (self.ls, self.psi, self.dl);
        self.step_with(u_prev, i, dl != T::zero(), |id, iq| {
            (ls, psi + dl * id, dl * iq)
        })
    }

    /// [`step`](Self::step) with the active-flux model given per step (`salient`): `active`
    /// maps the currents `(i_d, i_q)` along the PLL's last predicted d axis to `(L, psi_a,
    /// d psi_a / d th)`, the inductance whose current term leaves the active flux
    /// (`eta = x - L i`), its magnitude and its dependence on the angle (module docs). The
    /// constant-parameter motor passes `(Lq, psi_f + (Ld - Lq) i_d, (Ld - Lq) i_q)`; a flux
    /// map its operating point ([`FluxMapObserver`](crate::saturated::FluxMapObserver)).
    /// Without `salient` the surface motor's fixed circle is used.
    #[inline(always)]
    pub(crate) fn step_with(
        &mut self,
        u_prev: [T; 2],
        i: [T; 2],
        salient: bool,
        active: impl FnOnce(T, T) -> (T, T, T),
    ) -> Result<FluxEstimate<T>, EkfError> {
        if !finite(&u_prev) {
            return Err(EkfError::NonFiniteInput);
        }
        if !finite(&i) {
            return Err(EkfError::NonFiniteMeasurement);
        }
        let ts = self.ts;
        let half: T = to_t(0.5);
        let (i_eta, i_r) = match self.timing {
            FluxTiming::Firmware => (i, i),
            FluxTiming::Centred => (
                self.i_prev,
                [
                    (self.i_prev[0] + i[0]) * half,
                    (self.i_prev[1] + i[1]) * half,
                ],
            ),
        };
        let (ls, g_of) = if !salient {
            (self.ls, None)
        } else {
            // Active flux: the circle's radius is psi_a at the currents along the PLL's last
            // predicted d axis; the gain limited so that the radius's dependence on the angle
            // estimate cannot destabilise the loop (module docs).
            let (sd, cd) = (self.pll_dir[0], self.pll_dir[1]);
            let id = i_eta[0] * cd + i_eta[1] * sd;
            let iq = i_eta[1] * cd - i_eta[0] * sd;
            let (ls, psi_a, b) = active(id, iq);
            (ls, Some((psi_a, b)))
        };
        let e0a = self.x[0] - ls * i_eta[0];
        let e0b = self.x[1] - ls * i_eta[1];
        let n2 = e0a * e0a + e0b * e0b;
        let g = match g_of {
            None => self.gamma_half * (self.psi2 - n2),
            Some((psi_a, b)) => {
                let coupling = to_t::<T>(8.0) * psi_a.abs() * b.abs();
                let gamma_half = if self.gamma_half * coupling > self.w_pll.abs() {
                    self.w_pll.abs() / coupling
                } else {
                    self.gamma_half
                };
                gamma_half * (psi_a * psi_a - n2)
            }
        };
        let xa = self.x[0] + ts * (u_prev[0] - self.rs * i_r[0] + g * e0a);
        let xb = self.x[1] + ts * (u_prev[1] - self.rs * i_r[1] + g * e0b);
        let ea = xa - ls * i[0];
        let eb = xb - ls * i[1];
        let theta_flux = wrap_angle(eb.atan2(ea));

        let th_pred = wrap_angle(self.theta_pll + ts * self.w_pll);
        let (s, c) = th_pred.sin_cos_angle();
        let e = (eb * c - ea * s) * self.inv_psi;
        let theta_pll = wrap_angle(th_pred + ts * self.kp * e);
        let w_pll = self.w_pll + ts * self.ki * e;

        if !finite(&[xa, xb, theta_flux, theta_pll, w_pll]) {
            return Err(EkfError::NonFiniteResult);
        }
        self.x = [xa, xb];
        self.i_prev = i;
        self.ls_now = ls;
        self.pll_dir = [s, c];
        self.theta_flux = theta_flux;
        self.theta_pll = theta_pll;
        self.w_pll = w_pll;
        Ok(self.estimate())
    }

    /// The current estimate.
    pub fn estimate(&self) -> FluxEstimate<T> {
        let eta = [
            self.x[0] - self.ls_now * self.i_prev[0],
            self.x[1] - self.ls_now * self.i_prev[1],
        ];
        FluxEstimate {
            theta_rad: match self.output {
                FluxAngleOutput::Flux => self.theta_flux,
                FluxAngleOutput::Pll => self.theta_pll,
            },
            omega_e_rad_s: self.w_pll,
            omega_mech_rad_s: self.w_pll * self.inv_pole_pairs,
            theta_flux_rad: self.theta_flux,
            theta_pll_rad: self.theta_pll,
            eta_wb: eta,
        }
    }

    /// Stator flux estimate `x = [alpha, beta]`, Wb.
    pub fn flux_wb(&self) -> [T; 2] {
        self.x
    }
}
