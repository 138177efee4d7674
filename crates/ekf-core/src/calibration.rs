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
//! # Online (one pass)
//!
//! [`OnlineCalibration`] runs the drive observer on the same samples as a default
//! [`PmsmObserver`](crate::PmsmObserver) (`ObserverConfig::input_calibration`, host builds).
//! It averages as above, over the samples where the drive observer's input errors adapt (before
//! that they sit at their priors: a zero lead would be averaged in), with the lead held to the
//! physical range `[0, 2 Ts]` (the applied voltage leads the logged command by up to two
//! periods; a lead the drive observer reads negative while it settles is not one) and the
//! dead-time voltage at or above zero. Every 20 ms, once 50 such samples are in, the averages
//! are handed over: `voltage_delay_s = -tau` and `inverter_voltage_v = v_dt` always, `Rs`
//! when it differs from the tracked one by more than 5 % (a hand-over restarts the tracking's
//! settling, so small differences are left to the split filter). Nothing is handed over while
//! the filter's flux (tracked, or corrected by the start-up windows) has left the told one by
//! more than 3 %: the drive observer runs on the told flux, and a flux error reads to it as a
//! lead and a resistance (on motulator's trace of the 2.2 kW motor told 100 K cold it found
//! `Rs` 1.62 ohm for a true 3.60, told 2.19). The filter's own states are
//! untouched: the hand-over changes the model its next prediction uses. Before the first
//! hand-over the filter is the plain one, bit for bit. Off in [`ObserverConfig::new`] (the
//! firmware knows its timing); `pyfoc.Ekf`, the observer for recorded drives, turns it on by
//! default with the acceleration feedforward.
//!
//! Measured on three real ESC records (4.5 kHz; `docs/accuracy.md`, "Recorded drives";
//! `pmsm-sim replay LOG.csv --motor RUN.toml`): the replay table's rows "EKF told the
//! record's calibration" (two passes) and "calibration online" (one pass). Online, the first
//! run's 180 deg flips at duty steps go (its `Rs` is handed over at 0.067 ohm, told 0.102); a
//! 1 s record at constant speed loses its first half to the wait (the lead is found at
//! 0.43 s).

use crate::drive::DriveEstimate;
use crate::observer::ObserverConfig;
use crate::{Float, to_t};

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

/// The record's input errors learnt while the default observer runs (module docs, "Online"):
/// a [`DriveObserver`](crate::DriveObserver) on the same samples, its estimates averaged as
/// [`RecordCalibration`] does with the lead held to the physical range `[0, 2 Ts]`, handed
/// over every [`EVERY_S`](Self::EVERY_S) once [`MIN_SAMPLES`](Self::MIN_SAMPLES) adapting
/// samples are in.
#[derive(Clone, Debug, PartialEq)]
pub struct OnlineCalibration<T: Float> {
    drive: crate::DriveObserver<T>,
    acc: RecordCalibration<T>,
    max_lead_s: T,
    every: u32,
    count: u32,
}

impl<T: Float> OnlineCalibration<T> {
    /// Samples between hand-overs, as a time: 20 ms.
    pub const EVERY_S: f64 = 0.02;
    /// Adapting samples before the first hand-over.
    pub const MIN_SAMPLES: u64 = 50;

    /// A drive observer on `cfg` (its defaults for the motor and `Ts`, [`crate::DriveConfig::new`]).
    pub fn new(cfg: &crate::DriveConfig<T>) -> Result<Self, crate::ConfigError> {
        let drive = crate::DriveObserver::new(cfg)?;
        let every = (to_t::<T>(Self::EVERY_S) / cfg.ts_s).round().trunc_index();
        Ok(Self {
            drive,
            acc: RecordCalibration::new(),
            max_lead_s: cfg.ts_s + cfg.ts_s,
            every: u32::try_from(every).unwrap_or(u32::MAX).max(1),
            count: 0,
        })
    }

    /// One sample (the drive observer's [`step_dt`](crate::DriveObserver::step_dt)); a sample it
    /// refuses changes nothing and hands nothing over. Returns the calibration to hand over on
    /// every `every`-th accepted sample once enough samples are in, else `None`.
    pub fn step(&mut self, u_prev: [T; 2], i: [T; 2], dt_s: T) -> Option<Calibration<T>> {
        let Ok(mut e) = self.drive.step_dt(u_prev, i, dt_s) else {
            return None;
        };
        if e.adapting {
            e.voltage_lead_s = e.voltage_lead_s.max(T::zero()).min(self.max_lead_s);
            e.dead_time_v = e.dead_time_v.max(T::zero());
            self.acc.push(&e);
        }
        self.count += 1;
        if self.count < self.every {
            return None;
        }
        self.count = 0;
        self.acc.result().filter(|c| c.samples >= Self::MIN_SAMPLES)
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

    #[test]
    fn online_calibration_hands_over_nothing_before_its_samples_and_leaves_the_filter_alone() {
        let m = crate::MotorParams::<f64>::servo();
        let ts = 1e-4;
        let mut cfg = ObserverConfig::new(m, ts);
        let mut plain = crate::PmsmObserver::new(&cfg).unwrap();
        cfg.input_calibration = true;
        let mut cal = crate::PmsmObserver::new(&cfg).unwrap();
        // 0.05 s of a spinning record: the drive observer has not settled, nothing is handed
        // over, and the filter is the plain one bit for bit.
        let w: f64 = 300.0;
        for k in 0..500 {
            let th = w * ts * k as f64;
            let (s, c) = th.sin_cos();
            let u = [-w * m.psi_f_wb * s, w * m.psi_f_wb * c];
            let i = [0.1 * c, 0.1 * s];
            assert_eq!(plain.step(u, i), cal.step(u, i));
        }
        let mut on = OnlineCalibration::new(&crate::DriveConfig::new(m, ts)).unwrap();
        assert_eq!(on.every, 200);
        for _ in 0..3000 {
            assert_eq!(
                on.step([0.0; 2], [0.0; 2], ts),
                None,
                "standstill: nothing adapts"
            );
        }
        // A refused sample changes nothing.
        let before = on.clone();
        assert_eq!(on.step([f64::NAN; 2], [0.0; 2], ts), None);
        assert_eq!(on, before);
    }

    #[test]
    fn voltage_errors_are_set_at_run_time_and_refused_out_of_range() {
        let m = crate::MotorParams::<f64>::servo();
        let ts = 1e-4;
        let mut obs = crate::PmsmObserver::new(&ObserverConfig::new(m, ts)).unwrap();
        let mut told = ObserverConfig::new(m, ts);
        told.voltage_delay_s = -0.5 * ts;
        told.inverter_voltage_v = 0.3;
        let mut reference = crate::PmsmObserver::new(&told).unwrap();
        let before = obs.clone();
        for (d, v) in [
            (3.0 * ts, 0.0),
            (f64::NAN, 0.0),
            (0.0, -0.1),
            (0.0, 1e3),
            (0.0, f64::NAN),
        ] {
            assert!(obs.set_voltage_errors(d, v).is_err());
            assert_eq!(obs, before, "refused, nothing changed");
        }
        obs.set_voltage_errors(-0.5 * ts, 0.3).unwrap();
        for k in 0..200 {
            let th = 0.03 * k as f64;
            let u = [th.cos(), th.sin()];
            let i = [0.2 * th.sin(), -0.2 * th.cos()];
            assert_eq!(obs.step(u, i), reference.step(u, i), "as if configured");
        }
    }
}
