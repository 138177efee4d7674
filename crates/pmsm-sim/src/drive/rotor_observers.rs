//! The observers the simulator runs and scores: one trait, [`Observer`], for every rotor
//! observer stepped alongside the drive (the default EKF and the reference filter of every run,
//! the flux + PLL baseline and the EKFs of the suite).
//!
//! An observer steps once per period with the timing of docs/design.md, "Conventions": `u_prev` the
//! voltage held over the previous period as the controller knows it, `i_ab_a` the currents
//! measured now. It returns an [`ObserverEstimate`] (angle, speed, and what it can tell of its
//! uncertainty), which the run loop scores against the truth
//! ([`ObserverSample::from_controller`](crate::output::record::ObserverSample::from_controller)).
//! A new observer (say a salient-pole EKF) is one `impl Observer` away from the run loop and
//! the suite.

use ekf_core::saturated::{FluxMapObserver, MapObserver};
use ekf_core::{EkfError, Estimate, FluxEstimate, FluxObserver, PmsmObserver, Status};

use crate::output::record::ControllerEstimate;

/// What an observer returns for one period: angle, speed, covariance diagonal, NIS and
/// whether it trusts its angle (zeros and `tracking = true` for an observer without a
/// covariance). The same record as a controller's own observer reports.
pub type ObserverEstimate = ControllerEstimate;

/// A rotor observer stepped by the simulator (module docs).
pub trait Observer {
    /// One step: predict over the last period with `u_prev`, correct with `i_ab_a`.
    fn step(&mut self, u_prev: [f64; 2], i_ab_a: [f64; 2]) -> Result<ObserverEstimate, EkfError>;
}

/// `ekf-core`'s EKF. A missing (non-finite) current sample, as the fault injection makes,
/// is a prediction only (what a drive does with a lost ADC sample).
impl Observer for PmsmObserver<f64> {
    fn step(&mut self, u_prev: [f64; 2], i_ab_a: [f64; 2]) -> Result<ObserverEstimate, EkfError> {
        let e = if i_ab_a[0].is_finite() && i_ab_a[1].is_finite() {
            PmsmObserver::step(self, u_prev, i_ab_a)?
        } else {
            self.predict(u_prev)?;
            self.estimate()
        };
        Ok(ekf_estimate(&e, self))
    }
}

/// `ekf-core`'s EKF on a flux map, as the constant-parameter one.
impl<const N: usize> Observer for MapObserver<f64, N> {
    fn step(&mut self, u_prev: [f64; 2], i_ab_a: [f64; 2]) -> Result<ObserverEstimate, EkfError> {
        let e = if i_ab_a[0].is_finite() && i_ab_a[1].is_finite() {
            MapObserver::step(self, u_prev, i_ab_a)?
        } else {
            self.predict(u_prev)?;
            self.estimate()
        };
        Ok(ekf_estimate(&e, self.observer()))
    }
}

/// The record of an EKF's estimate `e`, with the covariance of `obs`.
fn ekf_estimate(e: &Estimate<f64>, obs: &PmsmObserver<f64>) -> ObserverEstimate {
    let p = obs.covariance();
    ObserverEstimate {
        theta_e_rad: e.theta_rad,
        omega_e_rad_s: e.omega_e_rad_s,
        p_diag: [p[(0, 0)], p[(1, 1)], p[(2, 2)], p[(3, 3)]],
        nis: e.nis,
        tracking: e.status == Status::Tracking,
        psi_f_wb: e.psi_f_wb,
        psi_f_sigma_wb: e.psi_f_sigma_wb,
        rs_ohm: e.rs_ohm,
        rs_sigma_ohm: e.rs_sigma_ohm,
        winding_temperature_c: e.winding_temperature_c,
    }
}

/// `ekf-core`'s flux observer with PLL (no covariance: zeros; no confidence measure, so it
/// never reports `Tracking`; the configured flux and resistance, no temperature).
impl Observer for FluxObserver<f64> {
    fn step(&mut self, u_prev: [f64; 2], i_ab_a: [f64; 2]) -> Result<ObserverEstimate, EkfError> {
        let e = FluxObserver::step(self, u_prev, i_ab_a)?;
        Ok(flux_estimate(&e, self.parameters()))
    }
}

/// The flux observer on a flux map, as the constant-parameter one.
impl<const N: usize> Observer for FluxMapObserver<f64, N> {
    fn step(&mut self, u_prev: [f64; 2], i_ab_a: [f64; 2]) -> Result<ObserverEstimate, EkfError> {
        let e = FluxMapObserver::step(self, u_prev, i_ab_a)?;
        Ok(flux_estimate(&e, (f64::NAN, f64::NAN)))
    }
}

/// The record of a flux observer's estimate `e` with the `(psi_f, Rs)` it uses.
fn flux_estimate(e: &FluxEstimate<f64>, (psi_f_wb, rs_ohm): (f64, f64)) -> ObserverEstimate {
    ObserverEstimate {
        theta_e_rad: e.theta_rad,
        omega_e_rad_s: e.omega_e_rad_s,
        p_diag: [0.0; 4],
        nis: 0.0,
        // No confidence measure: it never claims to track.
        tracking: false,
        psi_f_wb,
        psi_f_sigma_wb: 0.0,
        rs_ohm,
        rs_sigma_ohm: 0.0,
        winding_temperature_c: f64::NAN,
    }
}
