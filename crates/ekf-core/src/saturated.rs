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
//! Cost on the Cortex-M4F (`f32`, 9 x 11 map; `bash scripts/qemu-firmware.sh`): the
//! [`MapObserver`] step is 1339 instructions (median; max 1515), the constant-parameter salient
//! step 1196 (`ekf_step_salient`, with tracking); the map's evaluation is 505 of them
//! (`fluxmap_eval`).
//!
//! The noise covariances are those of the constant-parameter observer
//! ([`NoiseCovariances::scaled`]) for the map's small-signal parameters
//! ([`MapModel::small_signal`]).

use nalgebra::{Matrix2, Matrix4, SMatrix, SVector, Vector2, Vector4};

use crate::ekf::{EkfError, MeasurementModel, ProcessModel};
use crate::fluxmap::FluxMap;
use crate::{
    ConfigError, Estimate, Float, MotorParams, NoiseCovariances, ObserverConfig, Param,
    PmsmObserver, to_t, wrap_angle,
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
/// the map is the model.
#[derive(Clone, Debug, PartialEq)]
pub struct MapObserver<T: Float, const N: usize> {
    observer: PmsmObserver<T>,
    map: FluxMap<T, N>,
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
        })
    }

    /// One sample: predict on the map with `u_prev` (V, held over the previous period), then
    /// correct with the currents `i` sampled now, then the safeguards (as
    /// [`PmsmObserver::step`]).
    pub fn step(&mut self, u_prev: [T; 2], i: [T; 2]) -> Result<Estimate<T>, EkfError> {
        let ts = self.observer.model().ts();
        self.observer.map_step(&self.map, u_prev, i, ts)
    }

    /// [`step`](Self::step) over a period of `dt_s` seconds that ended at this sample (as
    /// [`PmsmObserver::step_dt`]: `Q` scaled by `dt_s / Ts`; refused with
    /// [`EkfError::InvalidPeriod`], state kept, outside `(0, MAX_PERIOD_FACTOR Ts]`).
    pub fn step_dt(&mut self, u_prev: [T; 2], i: [T; 2], dt_s: T) -> Result<Estimate<T>, EkfError> {
        let ts = self.observer.model().ts();
        if !(dt_s > T::zero() && dt_s <= ts * to_t(crate::observer::MAX_PERIOD_FACTOR)) {
            return Err(EkfError::InvalidPeriod);
        }
        self.observer.map_step(&self.map, u_prev, i, dt_s)
    }

    /// Prediction only (to coast over a missing current sample), as
    /// [`PmsmObserver::predict`].
    pub fn predict(&mut self, u_prev: [T; 2]) -> Result<(), EkfError> {
        self.observer.map_predict(&self.map, u_prev)
    }

    /// Correction only, as [`PmsmObserver::correct`].
    pub fn correct(&mut self, i: [T; 2]) -> Result<Estimate<T>, EkfError> {
        self.observer.correct(i)
    }

    /// Fuses an external angle measurement, as [`PmsmObserver::correct_angle`].
    pub fn correct_angle(&mut self, theta_rad: T, variance_rad2: T) -> Result<(), EkfError> {
        self.observer.correct_angle(theta_rad, variance_rad2)
    }

    /// Replaces the estimate and covariance, as [`PmsmObserver::reset`].
    pub fn reset(&mut self, x: Vector4<T>, p: Matrix4<T>) -> Result<(), EkfError> {
        self.observer.reset(x, p)
    }

    /// The current estimate, as [`PmsmObserver::estimate`].
    pub fn estimate(&self) -> Estimate<T> {
        self.observer.estimate()
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
