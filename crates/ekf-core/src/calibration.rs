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
//! that they sit at their priors: a zero lead would be averaged in) and where its angle is
//! within [`AGREE_ANGLE_RAD`] (45 deg) of the filter's prediction (two observers of the same
//! voltages and currents that differ by more are not following the same rotor, and the one
//! that is lost adapts its input errors to whatever keeps it there), with the lead held to the
//! physical range `[0, 2 Ts]` (the applied voltage leads the logged command by up to two
//! periods; a lead the drive observer reads negative while it settles is not one) and the
//! dead-time voltage at or above zero. Every 20 ms, once 50 such samples are in, the averages
//! are handed over: `voltage_delay_s = -tau` and `inverter_voltage_v = v_dt` always, `Rs` when
//! it differs from the tracked one by more than 5 % (a hand-over restarts the tracking's
//! settling, so small differences are left to the split filter) and, once the EKF's own
//! tracking has ended a window (it learns `Rs` itself from then on), only when it has left the
//! told `Rs` by more than 5 % (a drive observer that learnt no resistance would reset the
//! tracking's to the told value every 20 ms: on motulator's start-up with a load step of the
//! 2.2 kW motor under its vector control (`test_third_party_closed_loop.py`), told `Rs` -30 %,
//! 0.73 deg RMS against the firmware's filter's 0.40; with the rule 0.37, told +30 % 0.58 ->
//! 0.12; the ESC records and motulator's V/f trace, whose EKF tracking never ends a window, are
//! unchanged). Nothing is handed over while the filter's flux (tracked, or corrected by the
//! start-up windows) has left the told one by more than 3 %: the drive observer runs on the
//! told flux, and a flux error reads to it as a lead and a resistance (on motulator's trace of
//! the 2.2 kW motor told 100 K cold it found `Rs` 1.62 ohm for a true 3.60, told 2.19). The
//! filter's own states are untouched: the hand-over changes the model its next prediction uses.
//! Before the first hand-over the filter is the plain one, bit for bit. Off in
//! [`ObserverConfig::new`] (the firmware knows its timing); `pyfoc.Ekf`, the observer for
//! recorded drives, turns it on by default with the acceleration feedforward.
//!
//! Why the agreement: on motulator's simulation of the 2.2 kW motor reversing under rated load
//! at 12 % of rated speed (its sensored vector control; `test_third_party_closed_loop.py`),
//! `pyfoc.Ekf` told the motor 100 K hot lost the angle after the load step; its drive observer,
//! lost too (up to 180 deg from the filter, its speed +100 rad/s el. where the filter's was
//! -127 and the rotor's -57), went on adapting, its `Rs` average climbed from 5.0 to 14.3 ohm
//! (true 3.6), and the record's retelling started the filter from 14.3: 78 deg RMS, 29 % of the
//! samples more than 45 deg off. Counting only the samples within 45 deg of the filter, none is
//! more than 45 deg off (with this module's rules the case is 0.094 deg RMS; the firmware's
//! filter 10.1). On the three ESC records, motulator's V/f trace (every told case) and the same
//! simulation's other cases the results are unchanged to 0.01 deg (the ESC records' hand-overs:
//! 89-99 % of them within 15 deg).
//!
//! # Primed by the record
//!
//! The online calibration needs the drive observer settled and adapting (on a 1 s record at
//! constant speed its lead comes at 0.43 s); until then the filter runs at the told timing,
//! `w tau` behind, and afterwards at the found one. A record whose angle holds two offsets
//! cannot be scored against (or aligned with) a reference by one constant, and the first part
//! is simply wrong by `w tau`. When the whole record is at hand (a replay, `pyfoc.Ekf.run`),
//! [`PmsmObserver::prime_input_calibration`](crate::PmsmObserver::prime_input_calibration)
//! first runs a copy of the filter over it and sets the voltage delay the copy's calibration
//! handed over last; the filter then runs from row 0 with that delay, and its own calibration
//! hands over as before. Only the delay is primed:
//!
//! - the lead is a constant of the logging firmware (when in its period it updates the PWM),
//!   and of the three input errors the one whose error costs at every speed (`w tau`);
//! - the dead-time voltage and `Rs` are handed over together, and both are voltage drops along
//!   the current: primed alone, a dead-time voltage adds to the told `Rs` drop (measured on
//!   the first ESC run: 0.35 V primed with `Rs` at the told 0.102 ohm, 8.00 deg RMS and 0.13 %
//!   of samples more than 45 deg off; priming `Rs` with it, 8.08 deg and 0.17 %; the delay alone
//!   7.24 deg and none off, as unprimed);
//! - the copy's hand-over guard holds: a record whose filter flux leaves the told one by
//!   more than 3 % hands nothing over, and no delay is primed.
//!
//! The consistency check's baseline (the innovation level of the record's noise and of what
//! the model leaves out, learnt over about 1024 samples; module docs of
//! [`observer`](crate::observer), "Consistency") is primed too, from the copy's: a short record
//! otherwise reads `Uncertain` for its first 0.2-0.3 s while it is learnt, however right the
//! angle. The check still reads a loss: the fast mean must stay within 8 times the baseline,
//! and the baseline's clamp and ceiling are unchanged. On the 1 s record at constant speed the
//! status reads `Tracking` 90.8 % of the time instead of 62.0 %, never more than 45 deg off;
//! the other two records are unchanged (63.1 / 94.1 %).
//!
//! Measured on three real ESC records (4.5 kHz; `docs/accuracy.md`, "Recorded drives";
//! `pmsm-sim replay LOG.csv --motor RUN.toml`): the replay table's rows "EKF told the
//! record's calibration" (two passes) and "calibration online, primed by the record". Online,
//! the first run's 180 deg flips at duty steps go (its `Rs` is handed over at 0.067 ohm, told
//! 0.102); primed, the 1 s record at constant speed goes from 9.18 to 5.73 deg RMS (its
//! delay primed at -0.45 Ts; the other two records move by less than 0.01 deg). On a
//! synthetic record with the voltage 0.8 periods late and the speed swinging (the unit test
//! below): primed 0.17 deg RMS, not primed 3.0, the filter without the calibration 2.3.
//!
//! # Told by the record
//!
//! What the tracking learns of `Rs` it learns slowly: a window measures `Rs` only where the
//! ratio `r = i_q / w` moves (module docs of [`observer::tracking`](crate::observer), a load
//! step, a speed swing, a reversal), and until it has, the filter runs at the told `Rs` and its
//! angle is off by about `dRs i_d / (w psi_f)` wherever the current has a d part (a V/f start's
//! magnetizing current) and by the lumped flux's error wherever `r` differs from where the flux
//! was learnt. On a whole record the priming copy has seen all of it: when the `Rs` it ends
//! with moves the back-EMF per unit speed by more than
//! [`RETELL_SHARE`](crate::observer::RETELL_SHARE) (0.25 %) of the told flux at the record's
//! mean `|i| / |w|` (the rows the copy tracks above the tracking's minimum speed), the observer
//! is built again told that `Rs`, and a copy of the new one primes it as above. That copy
//! starts nearer the record's `Rs` and its tracking moves it less: the retelling repeats (a
//! fixed-point iteration, at most [`MAX_RETELLS`](crate::observer::MAX_RETELLS) = 6 times)
//! while the copy's change is above the share. A change against the previous one's direction is
//! taken by half: the copies then bracket the record's `Rs` (where a record does not identify
//! `Rs` closer than that, its copies alternate between two values and the half step lands
//! between them, below the share). The tracked `Rs` keeps its bounds in ohms (`rs_range` is
//! rescaled). The flux is not retold: the start-up windows and the EKF's own tracking find it
//! within the record, and on a recorded drive its tracked value also lumps what the model
//! leaves out (the first ESC run through `pmsm-sim replay`: the copy's flux +3.5 %, and
//! retelling it too gave 9.82 deg RMS with 0.35 % of the samples more than 45 deg off, against
//! 5.37 and none). The reported winding temperature keeps the told `Rs` as its reference: the
//! tracking's reference temperature becomes the copy's winding temperature and its copper
//! coefficient `alpha rs0 / rs1` (`T = T_ref + (Rs - rs0) / (alpha rs0)` either way).
//!
//! Nothing is retold from a copy that read `Tracking` on less than
//! [`RETELL_MIN_TRACKING`](crate::observer::RETELL_MIN_TRACKING) (a quarter) of the rows: a
//! copy that was mostly uncertain has no resistance to tell, and its tracked `Rs` is wherever
//! its windows left it while it was lost. On motulator's reversal under rated load at 12 %
//! speed told 100 K hot, with current noise of 1.5 % of the peak current added, the copy tracks
//! 9 % of the rows and ends at the lower bound of `Rs` (1.50 ohm for the motor's 3.60): told
//! it, the run lost the rotor (66 deg RMS, 38 % of the samples more than 45 deg off, some of
//! them `Tracking`); as told, 12.8 deg RMS, none off by more than 45 deg
//! (`test_third_party_closed_loop.py`). Without the noise the first copies of motulator's
//! three closed-loop runs track 66-98 % of their rows, those of the three ESC recordings 39 /
//! 57 / 87 % (the first rising to 52 % as it is retold), and nothing changes there.
//!
//! Measured (`pyfoc.Ekf` defaults; `python -m pytest crates/pyfoc/tests/test_third_party.py
//! crates/pyfoc/tests/test_recorded_drives.py -s`): motulator's V/f trace of the 2.2 kW motor
//! (RMS deg from 0.25 s) told 100 K hot 0.07 (1.44 without the priming; retold five times, `Rs`
//! 4.27, 3.93, 3.78, 3.69, 3.61 ohm for the motor's 3.60, told 5.01), 100 K cold 0.09 (1.46;
//! four times, 2.88, 3.21, 3.40, 3.51 for the told 2.19), `Rs` +30 % 0.40 (1.17; twice, 4.14
//! and 3.93), `Rs` -30 % 0.46 (0.93; once, 3.25: the calibration's `Rs` hand-over anchors the
//! split filter, and the next copy moves `Rs` by less than the share); told the right motor,
//! the flux +-10 % or `Ls` +-20 % nothing is retold. Retold once only, at a share of 2 %: 0.76
//! / 0.73 / 0.62 / 0.46. The first ESC run 5.01 deg RMS, none more than 45 deg off (retold
//! 0.067, 0.064 and 0.061 ohm for the told 0.102; the copy told 0.061 ends at 0.064, and half
//! that step, 0.063, is the last told; told 0.064 the run is 4.98 deg, told 0.061 5.60 with
//! 0.004 % of its samples more than 45 deg off; retold once, 5.35; primed without the
//! retelling, 7.24); the other two runs retell nothing (5.73 / 7.33). On a record whose model
//! error the tracking lumps into `Rs` (a saturated interior motor told its small-signal
//! constants, `pyfoc`'s `test_flux_map.py`), the iteration follows it: `Rs` 2.2 x the motor's,
//! 13.9 deg RMS with `saturating=True` (13.6 retold once). Through a reversal under rated load
//! at 12 % speed on motulator's model of the 2.2 kW motor (`test_third_party_closed_loop.py`)
//! told 100 K hot (`Rs` 5.01 ohm, true 3.60), the copies end at 4.54, 3.15, 3.73 (half the step
//! told: 3.44), 3.65, 3.59 (3.62 told) and 3.60 ohm, and the run told 3.60 is 0.09 deg RMS (5.4
//! deg when the iteration stops at the first change that turns back); told 100 K cold 0.24 deg.
//! The cost: one more pass over the record for each retelling (`pyfoc.Ekf.run` on the 4000 rows
//! of motulator's trace, one core, best of three: 1.15 us per row told the right motor, 3.92
//! told 100 K hot, 3.47 told 100 K cold).

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
    pub fn step(
        &mut self,
        u_prev: [T; 2],
        i: [T; 2],
        dt_s: T,
        filter_theta: T,
    ) -> Option<Calibration<T>> {
        let Ok(mut e) = self.drive.step_dt(u_prev, i, dt_s) else {
            return None;
        };
        if e.adapting && agrees(&e, filter_theta) {
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

/// Largest angle between the drive observer's estimate and the filter's prediction, rad, for a
/// sample to count in the online calibration (module docs, "Online"): 45 deg.
pub const AGREE_ANGLE_RAD: f64 = core::f64::consts::FRAC_PI_4;

/// Whether the drive observer's estimate `e` and the filter's predicted angle describe the
/// same rotor (module docs, "Online").
fn agrees<T: Float>(e: &DriveEstimate<T>, theta: T) -> bool {
    crate::angle::wrap_angle(e.theta_rad - theta).abs() <= to_t(AGREE_ANGLE_RAD)
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
                on.step([0.0; 2], [0.0; 2], ts, 0.0),
                None,
                "standstill: nothing adapts"
            );
        }
        // A refused sample changes nothing.
        let before = on.clone();
        assert_eq!(on.step([f64::NAN; 2], [0.0; 2], ts, 0.0), None);
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

    /// A record's row as `PmsmObserver::step_dt` takes it: `(u_prev, i, dt_s)`.
    type Row = ([f64; 2], [f64; 2], f64);

    /// A servo motor under a deadbeat current drive (`i_q` 2 A at every sample) whose speed
    /// swings between 1200 and 2800 rad/s el. at 2 Hz; each period's voltage held in the
    /// stationary frame (the exact response over the period at its mean speed). The logged
    /// voltage lags the applied one by `lead` periods (the applied vector turned back by
    /// `w lead Ts`). Rows `(u_prev, i, dt)`, and the true angle at each row.
    fn led_record(n: usize, lead: f64, ts: f64) -> (Vec<Row>, Vec<f64>) {
        use nalgebra::Complex;
        let m = crate::MotorParams::<f64>::servo();
        let (rs, ls, psi) = (m.rs_ohm, m.lq_h, m.psi_f_wb);
        let a = rs / ls;
        let alpha = (-a * ts).exp();
        let angle = |k: usize| {
            let t = k as f64 * ts;
            0.4 + 2000.0 * t
                - 800.0 / (4.0 * core::f64::consts::PI)
                    * ((4.0 * core::f64::consts::PI * t).cos() - 1.0)
        };
        let j = Complex::new(0.0, 1.0);
        let current = |k: usize| 2.0 * j * Complex::from_polar(1.0, angle(k));
        let mut rows = Vec::with_capacity(n);
        let mut th = Vec::with_capacity(n);
        for k in 0..n {
            let w = (angle(k + 1) - angle(k)) / ts;
            let emf = -j * w * psi / ls
                * Complex::from_polar(1.0, angle(k))
                * (Complex::from_polar(1.0, w * ts) - alpha)
                / (a + j * w);
            let applied = (current(k + 1) - alpha * current(k) - emf) * rs / (1.0 - alpha);
            let logged = applied * Complex::from_polar(1.0, -w * lead * ts);
            let i = current(k + 1);
            rows.push(([logged.re, logged.im], [i.re, i.im], ts));
            th.push(angle(k + 1));
        }
        (rows, th)
    }

    #[test]
    fn online_calibration_counts_only_samples_where_the_filter_agrees() {
        // The same record, the drive observer told the filter's angle right, or a quarter turn
        // off (a filter lost: the two describe different rotors): the second hands nothing over.
        let m = crate::MotorParams::<f64>::servo();
        let ts = 1e-4;
        let (rows, th) = led_record(6000, 0.8, ts);
        let run = |off: f64| {
            let mut on = OnlineCalibration::new(&crate::DriveConfig::new(m, ts)).unwrap();
            let mut last = None;
            for (&(u, i, dt), &t) in rows.iter().zip(&th) {
                last = on.step(u, i, dt, t + off).or(last);
            }
            last
        };
        let agreed = run(0.0).expect("handed over");
        assert!(agreed.samples > 1000, "{agreed:?}");
        assert!((agreed.voltage_lead_s / ts - 0.8).abs() < 0.2, "{agreed:?}");
        assert_eq!(run(core::f64::consts::FRAC_PI_2), None);
        // Just inside the angle: counted as agreeing.
        assert!(run(0.9 * AGREE_ANGLE_RAD).is_some());
    }

    #[test]
    fn priming_sets_the_delay_a_pass_over_the_record_handed_over() {
        let m = crate::MotorParams::<f64>::servo();
        let ts = 1e-4;
        let (rows, th) = led_record(10_000, 0.8, ts);
        let cfg = ObserverConfig {
            input_calibration: true,
            ..ObserverConfig::new(m, ts)
        };
        // Off: nothing primed, nothing changed.
        let mut off = crate::PmsmObserver::new(&ObserverConfig::new(m, ts)).unwrap();
        let before = off.clone();
        assert_eq!(off.prime_input_calibration(rows.iter().copied()), None);
        assert_eq!(off, before);
        // On: the delay the pass handed over last (found -0.776 Ts for -0.8), nothing else moved
        // (the copy's tracked parameters are too close to the told ones to tell it again: at
        // this speed `Rs` barely shows, "Told by the record").
        let mut primed = crate::PmsmObserver::new(&cfg).unwrap();
        let fresh = primed.clone();
        let delay = primed
            .prime_input_calibration(rows.iter().copied())
            .expect("a lead handed over");
        assert!((delay / ts + 0.8).abs() < 0.08, "delay {} Ts", delay / ts);
        assert_eq!(primed.voltage_errors(), (delay, 0.0));
        let mut expected = fresh.clone();
        expected.set_voltage_errors(delay, 0.0).unwrap();
        let (cp, ce) = (primed.consistency.as_ref(), expected.consistency.as_mut());
        if let (Some(cp), Some(ce)) = (cp, ce) {
            ce.baseline = cp.baseline;
            ce.refresh();
        }
        assert_eq!(
            primed, expected,
            "only the delay and the status's baseline moved"
        );
        // Filtering the record: the primed filter holds one offset from the start, the plain
        // one switches part-way (RMS deg, offset removed, from row 1000: 0.17 / 3.0).
        let rms = |mut obs: crate::PmsmObserver<f64>| {
            let e: Vec<f64> = rows
                .iter()
                .zip(&th)
                .map(|(&(u, i, dt), &t)| {
                    let est = obs.step_dt(u, i, dt).unwrap();
                    crate::angle::wrap_angle(est.theta_rad - t)
                })
                .skip(1000)
                .collect();
            let (s, c) = e
                .iter()
                .fold((0.0, 0.0), |(s, c), x| (s + x.sin(), c + x.cos()));
            let off = s.atan2(c);
            let ss: f64 = e
                .iter()
                .map(|x| crate::angle::wrap_angle(x - off).powi(2))
                .sum();
            (ss / e.len() as f64).sqrt().to_degrees()
        };
        let (with, without) = (rms(primed), rms(fresh));
        assert!(with < 0.25 && with < 0.1 * without, "{with} / {without}");
        // No lead in the record: at most a hundredth of a period primed (measured 6e-5 Ts).
        let (rows, _) = led_record(10_000, 0.0, ts);
        let mut plain = crate::PmsmObserver::new(&cfg).unwrap();
        let delay = plain.prime_input_calibration(rows).unwrap_or(0.0);
        assert!(delay.abs() < 0.01 * ts, "delay {} Ts", delay / ts);
    }
}
