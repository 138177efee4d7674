//! A recorded drive's input errors from the drive observer, for the default observer to be
//! told: the lead of the applied voltage over the logged one, the resistance and the
//! inverter's dead-time voltage ([`RecordCalibration`]).
//!
//! # Method (two passes over a record)
//!
//! The [`DriveObserver`](crate::DriveObserver) estimates the three input errors of a record
//! as states (its module docs give the model and their observability). Its estimates move
//! while it runs: the lead is held where the speed is low (the angle offset `w tau` it
//! causes is small there) and may wander where the model leaves other errors (a reversal,
//! saturation). The calibration averages them over the record's samples where the drive
//! observer tracks, each weighted by `w^2`:
//!
//! ```text
//! tau = sum(w_k^2 tau_k) / sum(w_k^2),  likewise Rs and v_dt,   over k with status tracking
//! ```
//!
//! `w^2` is the information one sample carries about the lead (the offset `w tau` it causes
//! grows with `w`, its effect on the innovations with `w^2`). `Rs` and `v_dt` take their
//! gain only where the resistive drop is large against the EMF (low speed, high current)
//! and are held elsewhere, so the weighting leaves them at what those samples found. The
//! default [`PmsmObserver`](crate::PmsmObserver) is then run again over the record told the
//! result: `voltage_delay_s = -tau`, `Rs`, `inverter_voltage_v = v_dt`
//! ([`Calibration::apply`]).
//!
//! Measured on three real ESC records (4.5 kHz; `docs/accuracy.md`, "Recorded drives";
//! `pmsm-sim replay LOG.csv --motor RUN.toml`): see the replay table's row "EKF told the
//! record's calibration".

use crate::Float;
use crate::drive::DriveEstimate;
use crate::observer::ObserverConfig;

/// The input errors found in a record ([`RecordCalibration::result`]).
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Calibration<T> {
    /// Lead of the applied voltage over the logged one, s (positive: the applied voltage
    /// leads).
    pub voltage_lead_s: T,
    /// Stator resistance, ohm.
    pub rs_ohm: T,
    /// Inverter dead-time voltage, V.
    pub dead_time_v: T,
    /// Samples averaged (the drive observer tracking).
    pub samples: u64,
}

impl<T: Float> Calibration<T> {
    /// `cfg` told this calibration: `voltage_delay_s = -voltage_lead_s`, the motor's `Rs`,
    /// `inverter_voltage_v = dead_time_v`. The result is validated when the observer is
    /// built (`PmsmObserver::new`), which refuses a lead beyond its range.
    pub fn apply(&self, cfg: &ObserverConfig<T>) -> ObserverConfig<T> {
        let mut out = *cfg;
        out.motor.rs_ohm = self.rs_ohm;
        out.voltage_delay_s = -self.voltage_lead_s;
        out.inverter_voltage_v = self.dead_time_v;
        out
    }
}

/// Accumulates a drive observer's estimates over a record (module docs).
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct RecordCalibration<T> {
    weight: T,
    lead: T,
    rs: T,
    dead_time: T,
    samples: u64,
}

impl<T: Float> Default for RecordCalibration<T> {
    fn default() -> Self {
        Self {
            weight: T::zero(),
            lead: T::zero(),
            rs: T::zero(),
            dead_time: T::zero(),
            samples: 0,
        }
    }
}

impl<T: Float> RecordCalibration<T> {
    /// An empty accumulator.
    pub fn new() -> Self {
        Self::default()
    }

    /// Adds one sample's estimate: counted only while the drive observer tracks and every
    /// value is finite (a non-finite estimate is skipped, nothing changes).
    pub fn push(&mut self, e: &DriveEstimate<T>) {
        let w2 = e.omega_e_rad_s * e.omega_e_rad_s;
        let finite = w2.is_finite()
            && e.voltage_lead_s.is_finite()
            && e.rs_ohm.is_finite()
            && e.dead_time_v.is_finite();
        if !(e.tracking && finite) || w2 <= T::zero() {
            return;
        }
        self.weight += w2;
        self.lead += w2 * e.voltage_lead_s;
        self.rs += w2 * e.rs_ohm;
        self.dead_time += w2 * e.dead_time_v;
        self.samples += 1;
    }

    /// The weighted means (module docs); `None` before a tracked sample with a speed.
    pub fn result(&self) -> Option<Calibration<T>> {
        if self.samples == 0 || self.weight <= T::zero() {
            return None;
        }
        let inv = T::one() / self.weight;
        Some(Calibration {
            voltage_lead_s: self.lead * inv,
            rs_ohm: self.rs * inv,
            dead_time_v: self.dead_time * inv,
            samples: self.samples,
        })
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn est(w: f64, lead: f64, rs: f64, vdt: f64, tracking: bool) -> DriveEstimate<f64> {
        DriveEstimate {
            theta_rad: 0.0,
            omega_e_rad_s: w,
            omega_mech_rad_s: w / 7.0,
            accel_rad_s2: 0.0,
            i_alpha_a: 0.0,
            i_beta_a: 0.0,
            nis: 2.0,
            voltage_lead_s: lead,
            rs_ohm: rs,
            dead_time_v: vdt,
            tracking,
            inconsistent: false,
            adapting: false,
            restarted: false,
        }
    }

    #[test]
    fn weights_by_speed_squared_and_skips_untracked_and_nan() {
        let mut c = RecordCalibration::new();
        assert_eq!(c.result(), None);
        c.push(&est(100.0, 1e-4, 0.1, 0.2, true));
        c.push(&est(-300.0, 2e-4, 0.2, 0.4, true));
        c.push(&est(1000.0, 9.0, 9.0, 9.0, false));
        c.push(&est(1000.0, f64::NAN, 9.0, 9.0, true));
        c.push(&est(0.0, 9.0, 9.0, 9.0, true));
        let r = c.result().unwrap();
        // weights 1e4 and 9e4
        assert!((r.voltage_lead_s - (1e-4 + 9.0 * 2e-4) / 10.0).abs() < 1e-15);
        assert!((r.rs_ohm - (0.1 + 9.0 * 0.2) / 10.0).abs() < 1e-12);
        assert!((r.dead_time_v - (0.2 + 9.0 * 0.4) / 10.0).abs() < 1e-12);
        assert_eq!(r.samples, 2);
        let m = crate::MotorParams::<f64>::servo();
        let cfg = r.apply(&ObserverConfig::new(m, 1e-4));
        assert_eq!(cfg.voltage_delay_s, -r.voltage_lead_s);
        assert_eq!(cfg.motor.rs_ohm, r.rs_ohm);
        assert_eq!(cfg.inverter_voltage_v, r.dead_time_v);
    }
}
