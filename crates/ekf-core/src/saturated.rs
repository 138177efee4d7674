//! An observer for saturating machines: the EKF of the PMSM observer with its motor model
//! replaced by a [`FluxMap`] (docs/design.md, "The motor as it physically is").
//!
//! # Formulation: currents as state, flux-consistent prediction
//!
//! The state stays `x = [i_a, i_b, w, th]` and the measurement `z = [i_a, i_b]` (`H = [I2 0]`),
//! as in the constant-parameter observer, so the correction and its cost are unchanged. Only
//! the prediction changes. Over one period, with the voltage `u` held in the stationary frame:
//!
//! ```text
//! i_dq0  = R(-th) i_ab                      currents in the rotor frame at the start
//! psi_dq0, L = map(i_dq0)                   flux and incremental inductance matrix
//! psi_ab1 = R(th) psi_dq0 + Ts (u - Rs i_ab)    the voltage integrated into the stator flux
//! th1 = th + w Ts,  w1 = w
//! i_dq1  = i_dq0 + L^-1 (R(-th1) psi_ab1 - psi_dq0)   one Newton step of the map's inverse
//! i_ab1  = R(th1) i_dq1
//! ```
//!
//! Why this form:
//! - The back-EMF never appears: it is the rotation of the flux, carried exactly by `R(th)`
//!   and `R(th1)`. The forward-Euler lag of the textbook filter (EMF taken at the start of the
//!   period) does not arise, and nothing has to choose between the chord inductance (which
//!   sets the EMF, `w psi_q`) and the incremental one (which sets `di/dt`): the map gives the
//!   flux itself, and `L` only converts a flux change into a current change.
//! - For constant inductances (a linear map) the Newton step is exact, and the prediction is
//!   exact except for the resistive drop, taken at the start of the period (an error of order
//!   `Ts^2 Rs / L` per period, 1e-4 of the drop on the reference motors).
//! - The state keeps the currents, so the measurement stays linear and the safeguards and
//!   status rules of the constant-parameter observer carry over unchanged.
//!
//! The transition Jacobian is that of the formulas above with `L` held (the map's second
//! derivatives are left out, as an EKF leaves out what the first-order expansion drops).
//!
//! [`MapObserver`] runs this prediction, written out in scalars
//! (`observer/mapstep.rs`), on the constant-parameter observer's structured covariance
//! schedule, followed by that observer's correction, safeguards and status. [`MapModel`] is
//! the same prediction in matrix form for the generic [`Ekf`](crate::Ekf) (a reference: the
//! scalar step equals it to rounding, tested).
//!
//! # Before the lock
//!
//! Until the filter has locked, the Newton step's inverse inductance `L^-1` is `I / L_qq`: the
//! voltage drives the currents through the q axis's incremental inductance along both axes, as
//! the constant-parameter observer's active-flux model does before its d-axis correction
//! applies. It locks at the first step whose status reads `Tracking` (the innovations
//! consistent with their learnt level and the back-EMF observable) or, as the
//! constant-parameter salient observer does, once the angle is tracked with the innovations
//! settled (running NIS at most the gate's settled level); it stays locked while the angle
//! stays tracked, and a branch flip or a reset unlocks it. (The settled rule alone is not
//! enough here: the isotropic model's own error at no load kept the NIS above the settled
//! level on the PM-SyRM test trace below, the filter unlocked into its rated current step, and
//! lost the rotor there.) The map's anisotropy makes the
//! current's response to the applied voltage depend on the angle with period `pi` (the
//! saliency an injection-based estimator reads), and an EKF started with the angle unknown
//! takes that as a strong angle measurement from the first samples: its angle variance
//! collapsed onto `th` or `th + pi` alike, whichever the first linearization pointed to, and
//! only the back-EMF's slow rotation could then tell the two apart. On the PM-SyRM (`L_d` 30
//! mH, `L_q` 150 mH at zero current: 5 to 1) at 50 % speed and no load, started 115 deg away,
//! the filter was still lost after the 0.5 s convergence phase on 16 of 24 sensor-noise seeds
//! (up to 8 % of the run's samples more than 45 deg off, `pmsm-sim suite --seed 5`): on the
//! seeds traced it had settled on `(-w, th + pi)` within 1 ms, and the branch check's flips
//! put it back on `th + pi` at positive speed. With the
//! isotropic response before the lock, the first angle information is the back-EMF's, whose
//! rotation fixes the branch: every seed converges within the convergence phase and the
//! scored rows are those of the seeds that converged before (0.42-0.49 deg RMS, `pmsm-sim
//! suite --seed S` for S in 0..23; `saturated_rows_converge_on_every_seed` in pmsm-sim's
//! tests). Once locked the map's full `L^-1` applies: the scored steady state and transients
//! are unchanged.
//!
//! # The flux offset
//!
//! The map EKF takes a map's flux at face value. A `psi_d` error at the operating point (the
//! magnets warmer or colder than when the map was measured, or an identified map's error in
//! its `i_d = 0` row, whose nodes a standstill probe measures least well) is a flux-magnitude
//! error, and it turns into an angle bias through the terms of the voltage equation that do
//! not scale with the speed (the bias flips sign with the direction of rotation). With
//! [`MapObserver::set_flux_offset_tracking`] the observer learns a `psi_d` offset online and
//! shifts the map by it ([`FluxMap::shift_psi_d`]), from windows of the voltage model:
//!
//! - a window starts at a posterior whose status reads `Tracking` (none of the step's events:
//!   rejection, branch flip, covariance reset), at [`FluxOffsetTracking::min_speed_rad_s`] or
//!   more, with the resistive drop `Rs |i|` at most [`FluxOffsetTracking::max_drop_ratio`]
//!   times `|w psi|`; its voltage model's stator flux starts at the map's at the posterior's
//!   currents and angle, `psi_s = R(th) psi(i_dq)` (stationary frame);
//! - each period adds `dt (u - Rs i)`: the voltage the prediction used (after the voltage
//!   timing and the inverter voltage), the posterior currents' mean over the period;
//! - once the angle has travelled `D` = [`FluxOffsetTracking::window_rad`] (a quarter turn),
//!   the voltage model and the map differ by `R(th0) (I - R(D)) err`, `err` the map's error
//!   in the rotor frame (constant over the window). Solved for `err`, its d part `err_d`
//!   measures the map's `psi_d` error there, free of the EKF's angle error (the rotation
//!   carries that into `err_q`) and of the map's own rotation;
//! - the map moves by `-gain err_d` (the offset held within
//!   [`FluxOffsetTracking::max_offset_fraction`] of `psi_d(0, 0)`), and the next window
//!   starts there;
//! - a window that fails a start condition on the way, or runs longer than
//!   [`FluxOffsetTracking::max_window_s`], restarts; so does one interrupted by a step that
//!   is not a regular one (`predict`, `correct`, `correct_angle`, `reset`, a refused step).
//!
//! The map's flux at each posterior is the one the next prediction evaluates at its start
//! (the posterior's currents and angle), so a window costs no map evaluation of its own: the
//! bookkeeping runs one step behind, and a shift takes effect from the step after the one
//! that closed the window. The windows integrate `Rs i`: an `Rs` error `dR` moves a window's
//! measured offset by about `dR / Rs` times the drop ratio, hence the bound on the drop. The
//! inverter's voltage error enters them as it enters the EKF.
//!
//! Measured (`cargo test --release -p ekf-core --test saturated -- --nocapture`), on the
//! PM-SyRM trace of that test (load steps to 150 % and a reversal) with the defaults: told a
//! map whose `psi_d` is 8 % of `psi_f` high (38.4 mWb), the angle is 2.27 deg RMS without the
//! tracking and 0.13 with it, the learnt offset within 0.1 % of the true one; told the right
//! map, 0.086 deg without and 0.090 with (it learns -0.32 mWb, the sampled map's own error at
//! the operating points). A gain of 0.2 settles faster (0.10 deg told the offset) and costs
//! more on the right map (0.097 deg). On motulator's PM-SyRM trace (`pyfoc`,
//! `tracking="flux"` on a map; `crates/pyfoc/tests/test_third_party_pm_syrm.py`'s fixture):
//! told the map 8 % high, 1.661 deg RMS without and 0.080 with; told the right map, 0.046
//! without and 0.079 with (it learns +1.9 mWb, 0.4 % of the flux, under the generating load
//! and the reversal). So it is opt-in: it costs a few hundredths of a degree where the map
//! is right and removes degrees where the flux has moved. On an identified map of the
//! saturating interior PM motor, plug and spin in pmsm-sim (module docs of
//! `pmsm_sim::analysis::plug_map`): docs/identify.md.
//!
//! Cost on the Cortex-M4F (`f32`, 9 x 11 map; `bash scripts/qemu-firmware.sh`): the
//! [`MapObserver`] step is 1340 instructions (median; max 1618), the constant-parameter salient
//! step 1181 (`ekf_step_salient`, with tracking); the map's evaluation is 505 of them
//! (`fluxmap_eval`). With the flux-offset tracking on, 1523 (median; max 2287 at a window's
//! end; `map_observer_step_offset`).
//!
//! The noise covariances are those of the constant-parameter observer
//! ([`NoiseCovariances::scaled`]) for the map's small-signal parameters
//! ([`MapModel::small_signal`]).

use nalgebra::{Matrix2, Matrix4, SMatrix, SVector, Vector2, Vector4};

use crate::ekf::{EkfError, MeasurementModel, ProcessModel};
use crate::fluxmap::FluxMap;
use crate::{
    ConfigError, Estimate, Float, MotorParams, NoiseCovariances, ObserverConfig, Param,
    PmsmObserver, Status, to_t, wrap_angle,
};

/// The prediction of a saturating machine (module docs), for the generic [`Ekf`](crate::Ekf).
#[derive(Clone, Debug)]
pub struct MapModel<T: Float, const N: usize> {
    map: FluxMap<T, N>,
    rs_ohm: T,
    pole_pairs: u32,
    ts_s: T,
    q: SMatrix<T, 4, 4>,
    r: SMatrix<T, 2, 2>,
}

/// Rotation by the angle whose cosine and sine are given.
fn rot<T: Float>(c: T, s: T) -> Matrix2<T> {
    Matrix2::new(c, -s, s, c)
}

/// The rotation generator `J = [[0, -1], [1, 0]]` applied to `v`.
fn j<T: Float>(v: Vector2<T>) -> Vector2<T> {
    Vector2::new(-v.y, v.x)
}

impl<T: Float, const N: usize> MapModel<T, N> {
    /// The model of a machine with flux map `map`, resistance `rs_ohm`, `pole_pairs`, sampled
    /// every `ts_s`. The noise is the default of the constant-parameter observer for the
    /// map's small-signal parameters.
    pub fn new(
        map: FluxMap<T, N>,
        rs_ohm: T,
        pole_pairs: u32,
        ts_s: T,
    ) -> Result<Self, ConfigError> {
        crate::motor::positive(rs_ohm, Param::Rs)?;
        crate::motor::positive(ts_s, Param::Ts)?;
        let mut model = Self {
            map,
            rs_ohm,
            pole_pairs,
            ts_s,
            q: SMatrix::zeros(),
            r: SMatrix::zeros(),
        };
        let small = model.small_signal();
        small.validate()?;
        let noise = NoiseCovariances::scaled(&small, ts_s);
        model.q = noise.q;
        model.r = noise.r;
        Ok(model)
    }

    /// The constant parameters the map gives at zero current: `Ld = dPsi_d/di_d`,
    /// `Lq = dPsi_q/di_q` and `psi_f = Psi_d(0, 0)` (what a low-current commissioning
    /// measures).
    pub fn small_signal(&self) -> MotorParams<T> {
        small_signal(&self.map, self.rs_ohm, self.pole_pairs)
    }

    /// The flux map.
    pub fn map(&self) -> &FluxMap<T, N> {
        &self.map
    }
}

impl<T: Float, const N: usize> ProcessModel<T, 4, 2> for MapModel<T, N> {
    fn transition(
        &self,
        x: &SVector<T, 4>,
        u: &SVector<T, 2>,
    ) -> (SVector<T, 4>, SMatrix<T, 4, 4>) {
        let ts = self.ts_s;
        let i_ab = Vector2::new(x[0], x[1]);
        let (w, th) = (x[2], x[3]);
        let (s0, c0) = th.sin_cos_angle();
        let (s1, c1) = (th + w * ts).sin_cos_angle();
        let (sw, cw) = (w * ts).sin_cos_angle();
        let (r0, r1, rw) = (rot(c0, s0), rot(c1, s1), rot(cw, sw));
        let i_dq0 = r0.transpose() * i_ab;
        let p = self.map.eval(i_dq0.x, i_dq0.y);
        let psi_dq0 = Vector2::new(p.psi_d, p.psi_q);
        let l = Matrix2::new(p.l_dd, p.l_dq, p.l_qd, p.l_qq);
        let det = p.det();
        let g = Matrix2::new(p.l_qq, -p.l_dq, -p.l_qd, p.l_dd) / det;
        // Voltage less resistive drop, integrated over the period (stationary frame).
        let v = u - i_ab * self.rs_ohm;
        let e = (rw.transpose() - Matrix2::identity()) * psi_dq0 + r1.transpose() * v * ts;
        let i_dq1 = i_dq0 + g * e;
        let i_ab1 = r1 * i_dq1;
        let mut x1 = SVector::<T, 4>::zeros();
        x1[0] = i_ab1.x;
        x1[1] = i_ab1.y;
        x1[2] = w;
        x1[3] = th + w * ts;
        // Jacobian with L held.
        let mut phi = SMatrix::<T, 4, 4>::identity();
        // d i_ab1 / d i_ab: R(w Ts) + R1 G [ (R(-w Ts) - I) L R0^T - Ts Rs R1^T ].
        let d_i = rw
            + r1 * g
                * ((rw.transpose() - Matrix2::identity()) * l * r0.transpose()
                    - r1.transpose() * (ts * self.rs_ohm));
        // d / d th: J i_ab1 + R1 [ -J i_dq0 + G ( (R(-w Ts) - I) L (-J i_dq0) - Ts J R1^T v ) ].
        let ji0 = j(i_dq0);
        let d_th = j(i_ab1)
            + r1 * (-ji0
                + g * ((rw.transpose() - Matrix2::identity()) * (l * -ji0)
                    - j(r1.transpose() * v) * ts));
        // d / d w: Ts J i_ab1 + R1 G ( -Ts J R(-w Ts) psi_dq0 - Ts^2 J R1^T v ).
        let d_w = j(i_ab1) * ts
            + r1 * g * (-(j(rw.transpose() * psi_dq0) * ts) - j(r1.transpose() * v) * (ts * ts));
        for r in 0..2 {
            for c in 0..2 {
                phi[(r, c)] = d_i[(r, c)];
            }
            phi[(r, 2)] = d_w[r];
            phi[(r, 3)] = d_th[r];
        }
        phi[(3, 2)] = ts;
        (x1, phi)
    }

    fn process_noise(&self) -> &SMatrix<T, 4, 4> {
        &self.q
    }

    fn normalize(&self, x: &mut SVector<T, 4>) {
        x[3] = wrap_angle(x[3]);
    }
}

impl<T: Float, const N: usize> MeasurementModel<T, 4, 2> for MapModel<T, N> {
    fn observe(&self, x: &SVector<T, 4>) -> (SVector<T, 2>, SMatrix<T, 2, 4>) {
        let mut h = SMatrix::<T, 2, 4>::zeros();
        h[(0, 0)] = T::one();
        h[(1, 1)] = T::one();
        (Vector2::new(x[0], x[1]), h)
    }

    fn measurement_noise(&self) -> &SMatrix<T, 2, 2> {
        &self.r
    }

    fn normalize(&self, x: &mut SVector<T, 4>) {
        x[3] = wrap_angle(x[3]);
    }
}

/// The PMSM observer on a flux map: the prediction of the module docs, written out for the
/// constant-parameter observer's structured covariance schedule, then that observer's
/// correction, safeguards (innovation gate, branch check, covariance health), consistency
/// check and status. A refused step leaves the observer as it was.
///
/// The configuration is an [`ObserverConfig`] for the map's small-signal parameters
/// ([`MapObserver::default_config`]): its noise, initial covariance, safeguards and voltage
/// timing apply as they do to the constant-parameter observer, whose motor parameters serve
/// only to scale them. Parameter tracking is refused ([`ConfigError::TrackingWithFluxMap`]):
/// the map is the model; its flux may move by an offset, which the observer learns when told
/// to ([`MapObserver::set_flux_offset_tracking`]; module docs, "The flux offset").
#[derive(Clone, Debug, PartialEq)]
pub struct MapObserver<T: Float, const N: usize> {
    observer: PmsmObserver<T>,
    map: FluxMap<T, N>,
    /// The flux-offset tracking (module docs, "The flux offset"), when on.
    offset: Option<FluxOffsetState<T>>,
}

impl<T: Float, const N: usize> MapObserver<T, N> {
    /// The default configuration on `map`: [`ObserverConfig::new`] for the map's small-signal
    /// parameters ([`small_signal`]) with parameter tracking off (the map is the model) and
    /// without the speed noise adaptation. The adaptation loosens the speed while the
    /// innovations are large; on a saturating machine whose currents reverse at speed, the
    /// inverter's dead-time voltage error near zero current makes them large, and the loosened
    /// speed ran away (the suite's PM-SyRM: 7.6 deg RMS and 0.6 % of samples above 45 deg with
    /// it, 0.50 deg and none without; `pmsm-sim suite`, saturated rows).
    pub fn default_config(
        map: &FluxMap<T, N>,
        rs_ohm: T,
        pole_pairs: u32,
        ts_s: T,
    ) -> ObserverConfig<T> {
        ObserverConfig {
            parameter_tracking: None,
            speed_noise_adaptation: None,
            ..ObserverConfig::new(small_signal(map, rs_ohm, pole_pairs), ts_s)
        }
    }

    /// Validates `cfg` (whose `motor.rs_ohm` is the resistance the prediction uses) and builds
    /// the observer at `cfg.x0`, `cfg.p0`.
    pub fn new(cfg: &ObserverConfig<T>, map: FluxMap<T, N>) -> Result<Self, ConfigError> {
        if cfg.parameter_tracking.is_some() {
            return Err(ConfigError::TrackingWithFluxMap);
        }
        Ok(Self {
            observer: PmsmObserver::new(cfg)?.on_map(),
            map,
            offset: None,
        })
    }

    /// Turns the flux-offset tracking on with `tracking` (module docs, "The flux offset"), or
    /// off with `None`. The offset learnt so far stays in the map either way; turned on, the
    /// offset counted by [`flux_offset_wb`](Self::flux_offset_wb) starts from zero. A setting
    /// that fails [`FluxOffsetTracking::validate`] is refused and nothing changes.
    pub fn set_flux_offset_tracking(
        &mut self,
        tracking: Option<FluxOffsetTracking<T>>,
    ) -> Result<(), ConfigError> {
        self.offset = match tracking {
            None => None,
            Some(t) => {
                t.validate()?;
                let psi0 = self.map.eval(T::zero(), T::zero()).psi_d.abs();
                Some(FluxOffsetState::new(t, self.observer.nominal.1, psi0))
            }
        };
        Ok(())
    }

    /// The `psi_d` offset the flux-offset tracking has moved the map by since it was turned
    /// on, Wb (0 when off).
    pub fn flux_offset_wb(&self) -> T {
        self.offset.as_ref().map_or(T::zero(), |o| o.offset)
    }

    /// One sample: predict on the map with `u_prev` (V, held over the previous period), then
    /// correct with the currents `i` sampled now, then the safeguards (as
    /// [`PmsmObserver::step`]); with the flux-offset tracking on, then its bookkeeping (module
    /// docs, "The flux offset"), and the estimate's `psi_f_wb` is the map's `psi_d(0, 0)` as
    /// it was told plus the learnt offset.
    pub fn step(&mut self, u_prev: [T; 2], i: [T; 2]) -> Result<Estimate<T>, EkfError> {
        let ts = self.observer.model().ts();
        self.step_over(u_prev, i, ts)
    }

    /// The step over a period `dt_s`, then the flux-offset tracking's share.
    #[inline(always)]
    fn step_over(&mut self, u_prev: [T; 2], i: [T; 2], dt_s: T) -> Result<Estimate<T>, EkfError> {
        if self.offset.is_none() {
            return self.observer.map_step(&self.map, u_prev, i, dt_s);
        }
        self.offset_step(u_prev, i, dt_s)
    }

    /// The step with the flux-offset tracking (out of line: it is opt-in).
    #[inline(never)]
    fn offset_step(&mut self, u_prev: [T; 2], i: [T; 2], dt_s: T) -> Result<Estimate<T>, EkfError> {
        let r = self.observer.map_step_inputs(&self.map, u_prev, i, dt_s);
        let Some(t) = &mut self.offset else {
            return r.map(|(e, _)| e);
        };
        match r {
            Err(e) => {
                t.interrupt();
                Err(e)
            }
            Ok((mut e, inputs)) => {
                if let Some(shift) = t.tick(inputs.psi_ab0) {
                    self.map.shift_psi_d(shift);
                }
                let x = self.observer.state();
                t.pending = Some(Pending {
                    i: [x[0], x[1]],
                    th: x[3],
                    w: x[2],
                    usable: e.status == Status::Tracking
                        && !e.rejected
                        && !e.branch_flipped
                        && !e.covariance_reset,
                    u: inputs.u,
                    dt: dt_s,
                });
                e.psi_f_wb += t.offset;
                Ok(e)
            }
        }
    }

    /// [`step`](Self::step) over a period of `dt_s` seconds that ended at this sample (as
    /// [`PmsmObserver::step_dt`]: `Q` scaled by `dt_s / Ts`; refused with
    /// [`EkfError::InvalidPeriod`], state kept, outside `(0, MAX_PERIOD_FACTOR Ts]`).
    pub fn step_dt(&mut self, u_prev: [T; 2], i: [T; 2], dt_s: T) -> Result<Estimate<T>, EkfError> {
        let ts = self.observer.model().ts();
        if !(dt_s > T::zero() && dt_s <= ts * to_t(crate::observer::MAX_PERIOD_FACTOR)) {
            return Err(EkfError::InvalidPeriod);
        }
        self.step_over(u_prev, i, dt_s)
    }

    /// Prediction only (to coast over a missing current sample), as
    /// [`PmsmObserver::predict`]. The flux-offset tracking's window restarts.
    pub fn predict(&mut self, u_prev: [T; 2]) -> Result<(), EkfError> {
        self.interrupt_offset();
        self.observer.map_predict(&self.map, u_prev)
    }

    /// Correction only, as [`PmsmObserver::correct`]. The flux-offset tracking's window
    /// restarts.
    pub fn correct(&mut self, i: [T; 2]) -> Result<Estimate<T>, EkfError> {
        self.interrupt_offset();
        self.observer.correct(i).map(|e| self.with_offset(e))
    }

    /// Fuses an external angle measurement, as [`PmsmObserver::correct_angle`]. The
    /// flux-offset tracking's window restarts.
    pub fn correct_angle(&mut self, theta_rad: T, variance_rad2: T) -> Result<(), EkfError> {
        self.interrupt_offset();
        self.observer.correct_angle(theta_rad, variance_rad2)
    }

    /// Replaces the estimate and covariance, as [`PmsmObserver::reset`]. The flux-offset
    /// tracking's window restarts; the offset learnt stays.
    pub fn reset(&mut self, x: Vector4<T>, p: Matrix4<T>) -> Result<(), EkfError> {
        self.interrupt_offset();
        self.observer.reset(x, p)
    }

    /// The current estimate, as [`PmsmObserver::estimate`] (`psi_f_wb` as [`step`](Self::step)
    /// reports it).
    pub fn estimate(&self) -> Estimate<T> {
        self.with_offset(self.observer.estimate())
    }

    /// `e` with the learnt flux offset added to its `psi_f_wb`.
    fn with_offset(&self, mut e: Estimate<T>) -> Estimate<T> {
        e.psi_f_wb += self.flux_offset_wb();
        e
    }

    /// The flux-offset tracking's window restarts (a step that was not a regular one).
    fn interrupt_offset(&mut self) {
        if let Some(t) = &mut self.offset {
            t.interrupt();
        }
    }

    /// Adds `delta_wb` to the map's `psi_d` everywhere ([`FluxMap::shift_psi_d`]): the
    /// prediction's flux moves with it from the next step on, the state and covariance are
    /// kept. For a flux offset learnt online (the magnet's temperature, or an identified
    /// map's error at the operating point). A non-finite `delta_wb` is refused
    /// ([`ConfigError::NonFinite`]) and nothing changes.
    pub fn shift_psi_d(&mut self, delta_wb: T) -> Result<(), ConfigError> {
        if !delta_wb.is_finite() {
            return Err(ConfigError::NonFinite(Param::PsiF));
        }
        self.map.shift_psi_d(delta_wb);
        Ok(())
    }

    /// The underlying observer (state, covariance, last correction, counters). Its own
    /// `step` and `predict` use the constant small-signal model: step through `self`.
    pub fn observer(&self) -> &PmsmObserver<T> {
        &self.observer
    }

    /// The flux map.
    pub fn map(&self) -> &FluxMap<T, N> {
        &self.map
    }
}

/// Online learning of a flux map's `psi_d` offset by the [`MapObserver`] (module docs, "The
/// flux offset"): [`MapObserver::set_flux_offset_tracking`].
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct FluxOffsetTracking<T> {
    /// Share of a window's measured offset taken into the map, in `(0, 1]`.
    pub gain: T,
    /// A window's length as the electrical angle the rotor travels, rad, in `(0, pi]`.
    pub window_rad: T,
    /// Electrical speed below which no window runs, rad/s (at least 0).
    pub min_speed_rad_s: T,
    /// Largest resistive drop `Rs |i|` against the map's flux times the speed, `|w psi|`, at
    /// which a window runs (above 0): the windows integrate `Rs i`, and an error in `Rs`
    /// moves the measured offset by this share of it.
    pub max_drop_ratio: T,
    /// Longest window, s (above 0): a window not done by then restarts (the integral's drift
    /// from the current sensors' offsets grows with its length).
    pub max_window_s: T,
    /// Largest offset, as a fraction of the map's `psi_d(0, 0)` as told (above 0): the
    /// learnt offset is held within it.
    pub max_offset_fraction: T,
}

impl<T: Float> FluxOffsetTracking<T> {
    /// The defaults: gain 0.1 (about ten windows, two and a half turns, to settle), windows of
    /// a quarter turn, no speed bound of their own (the
    /// status must read `Tracking`), the resistive drop at most half of the back-EMF, a
    /// window at most 0.1 s, the offset within half of `psi_d(0, 0)`.
    pub fn new() -> Self {
        Self {
            gain: to_t(0.1),
            window_rad: to_t(core::f64::consts::FRAC_PI_2),
            min_speed_rad_s: T::zero(),
            max_drop_ratio: to_t(0.5),
            max_window_s: to_t(0.1),
            max_offset_fraction: to_t(0.5),
        }
    }

    /// Checks every field against the ranges in its docs.
    pub fn validate(&self) -> Result<(), ConfigError> {
        let check = |v: T, ok: bool, p: Param| {
            if !v.is_finite() {
                Err(ConfigError::NonFinite(p))
            } else if ok {
                Ok(())
            } else {
                Err(ConfigError::OutOfRange(p))
            }
        };
        let pi: T = to_t(core::f64::consts::PI);
        check(
            self.gain,
            self.gain > T::zero() && self.gain <= T::one(),
            Param::FluxOffsetGain,
        )?;
        check(
            self.window_rad,
            self.window_rad > T::zero() && self.window_rad <= pi,
            Param::FluxOffsetWindow,
        )?;
        check(
            self.min_speed_rad_s,
            self.min_speed_rad_s >= T::zero(),
            Param::FluxOffsetMinSpeed,
        )?;
        check(
            self.max_drop_ratio,
            self.max_drop_ratio > T::zero(),
            Param::FluxOffsetDropRatio,
        )?;
        check(
            self.max_window_s,
            self.max_window_s > T::zero(),
            Param::FluxOffsetWindowTime,
        )?;
        check(
            self.max_offset_fraction,
            self.max_offset_fraction > T::zero(),
            Param::FluxOffsetRange,
        )
    }
}

impl<T: Float> Default for FluxOffsetTracking<T> {
    fn default() -> Self {
        Self::new()
    }
}

/// A step's posterior, waiting for the map's flux there (the next prediction evaluates it).
#[derive(Clone, Copy, Debug, PartialEq)]
struct Pending<T> {
    i: [T; 2],
    th: T,
    w: T,
    /// The status read `Tracking` and nothing unusual happened in the step.
    usable: bool,
    /// The voltage the step's prediction used, held over the period that ended at it.
    u: [T; 2],
    dt: T,
}

/// The flux-offset tracking's running state.
#[derive(Clone, Copy, Debug, PartialEq)]
struct FluxOffsetState<T> {
    cfg: FluxOffsetTracking<T>,
    rs: T,
    /// Largest `|offset|`, Wb.
    bound: T,
    /// Whether a window is open; its start angle, the angle travelled, its time, the last
    /// angle and currents.
    open: bool,
    th0: T,
    travel: T,
    elapsed: T,
    th_prev: T,
    i_prev: [T; 2],
    /// The voltage model's stator flux since the window's start (stationary frame), Wb.
    psi_int: [T; 2],
    /// The offset taken into the map, Wb.
    offset: T,
    pending: Option<Pending<T>>,
}

impl<T: Float> FluxOffsetState<T> {
    fn new(cfg: FluxOffsetTracking<T>, rs: T, psi0: T) -> Self {
        Self {
            cfg,
            rs,
            bound: cfg.max_offset_fraction * psi0,
            open: false,
            th0: T::zero(),
            travel: T::zero(),
            elapsed: T::zero(),
            th_prev: T::zero(),
            i_prev: [T::zero(); 2],
            psi_int: [T::zero(); 2],
            offset: T::zero(),
            pending: None,
        }
    }

    /// The window restarts at the next regular step.
    fn interrupt(&mut self) {
        self.open = false;
        self.pending = None;
    }

    /// The last step's posterior (`pending`) with the map's stator flux there, `model`
    /// (stationary frame): the window's bookkeeping; returns the shift to apply to the map
    /// when a window closes.
    fn tick(&mut self, model: [T; 2]) -> Option<T> {
        let p = self.pending.take()?;
        let c = &self.cfg;
        let i2 = p.i[0] * p.i[0] + p.i[1] * p.i[1];
        let m2 = model[0] * model[0] + model[1] * model[1];
        let drop = self.rs * self.rs * i2;
        let emf = c.max_drop_ratio * c.max_drop_ratio * p.w * p.w * m2;
        let usable = p.usable && p.w.abs() >= c.min_speed_rad_s && drop <= emf;
        let mut shift = None;
        if !usable || !self.open {
            self.restart(usable, p.th, model);
        } else {
            let half: T = to_t(0.5);
            let im = [
                half * (p.i[0] + self.i_prev[0]),
                half * (p.i[1] + self.i_prev[1]),
            ];
            self.psi_int[0] += p.dt * (p.u[0] - self.rs * im[0]);
            self.psi_int[1] += p.dt * (p.u[1] - self.rs * im[1]);
            self.travel += wrap_angle(p.th - self.th_prev);
            self.elapsed += p.dt;
            if self.elapsed > c.max_window_s {
                self.restart(true, p.th, model);
            } else if self.travel.abs() >= c.window_rad {
                shift = self.close(p.th, model);
            }
        }
        self.th_prev = p.th;
        self.i_prev = p.i;
        shift
    }

    /// A new window from the angle `th` and the map's flux `model` there (`open`: whether it
    /// runs).
    fn restart(&mut self, open: bool, th: T, model: [T; 2]) {
        self.open = open;
        self.th0 = th;
        self.travel = T::zero();
        self.elapsed = T::zero();
        self.psi_int = model;
    }

    /// The window's end at the angle `th`, the map's flux `model` there: the offset measured,
    /// its share taken (within the bound), the next window started on the shifted map.
    #[cold]
    #[inline(never)]
    fn close(&mut self, th: T, model: [T; 2]) -> Option<T> {
        // psi_int - model = R(th0) (I - R(D)) err, err the map's error in the rotor frame, D
        // the angle travelled: err = (I - R(D))^-1 R(-th0) (psi_int - model).
        let d = [self.psi_int[0] - model[0], self.psi_int[1] - model[1]];
        let (s1, c1) = self.th0.sin_cos_angle();
        let r = [c1 * d[0] + s1 * d[1], c1 * d[1] - s1 * d[0]];
        let (sd, cd) = self.travel.sin_cos_angle();
        let (a, b) = (T::one() - cd, sd);
        let err_d = (a * r[0] - b * r[1]) / (a * a + b * b);
        let target = crate::observer::tracking::clamp(
            self.offset - self.cfg.gain * err_d,
            -self.bound,
            self.bound,
        );
        let step = target - self.offset;
        let (s, c) = th.sin_cos_angle();
        let step = if step.is_finite() { step } else { T::zero() };
        self.offset += step;
        self.restart(true, th, [model[0] + c * step, model[1] + s * step]);
        (step != T::zero()).then_some(step)
    }
}

/// The constant parameters a map gives at zero current: `Ld = dPsi_d/di_d`,
/// `Lq = dPsi_q/di_q`, `psi_f = Psi_d(0, 0)` (what a low-current commissioning measures).
pub fn small_signal<T: Float, const N: usize>(
    map: &FluxMap<T, N>,
    rs_ohm: T,
    pole_pairs: u32,
) -> MotorParams<T> {
    let p = map.eval(T::zero(), T::zero());
    MotorParams {
        rs_ohm,
        ld_h: p.l_dd,
        lq_h: p.l_qq,
        psi_f_wb: p.psi_d,
        pole_pairs,
    }
}

/// The flux-observer baseline on a flux map (the [`FluxObserver`](crate::FluxObserver) of
/// open firmware, told the map): the active flux of the map's operating point at the PLL's
/// angle. With `(i_d, i_q)` the currents along the PLL's last predicted d axis and the map's
/// flux there, the chord inductance `Lq_c = psi_q / i_q` (the incremental `dPsi_q/di_q` where
/// `|i_q|` is below 1e-3 of the characteristic current) makes `eta = x - Lq_c i` the rotor-frame
/// vector `(psi_d - Lq_c i_d, 0)`: the active flux `psi_a = psi_d - Lq_c i_d` along the d axis,
/// the radius the observer pulls its flux estimate to. Its dependence on the angle,
/// `(dPsi_d/di_d - Lq_c) i_q` to first order, limits the gain as for the constant interior motor
/// (module docs of [`flux`](crate::flux)). With a linear map this is the constant-parameter
/// observer's active flux.
#[derive(Clone, Debug, PartialEq)]
pub struct FluxMapObserver<T: Float, const N: usize> {
    observer: crate::FluxObserver<T>,
    map: FluxMap<T, N>,
    /// `|i_q|` below which the chord inductance is the incremental one, A.
    small_iq: T,
}

impl<T: Float, const N: usize> FluxMapObserver<T, N> {
    /// Validates `cfg` (whose motor gives `Rs`, and `psi_f` to normalise the gains: the map's
    /// small-signal parameters, [`small_signal`]) and builds the observer at rest.
    pub fn new(
        cfg: &crate::FluxObserverConfig<T>,
        map: FluxMap<T, N>,
    ) -> Result<Self, ConfigError> {
        Ok(Self {
            observer: crate::FluxObserver::new(cfg)?,
            small_iq: cfg.motor.characteristic_current_a() * to_t(1e-3),
            map,
        })
    }

    /// One sample, as [`FluxObserver::step`](crate::FluxObserver::step), on the map's active
    /// flux.
    pub fn step(&mut self, u_prev: [T; 2], i: [T; 2]) -> Result<crate::FluxEstimate<T>, EkfError> {
        let (map, small_iq) = (&self.map, self.small_iq);
        self.observer.step_with(u_prev, i, true, |id, iq| {
            let p = map.eval(id, iq);
            let lq = if iq.abs() > small_iq {
                p.psi_q / iq
            } else {
                p.l_qq
            };
            (lq, p.psi_d - lq * id, (p.l_dd - lq) * iq)
        })
    }

    /// The current estimate.
    pub fn estimate(&self) -> crate::FluxEstimate<T> {
        self.observer.estimate()
    }

    /// The flux map.
    pub fn map(&self) -> &FluxMap<T, N> {
        &self.map
    }
}
