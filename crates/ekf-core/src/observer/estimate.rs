//! What the observer reports: [`Estimate`] (one sample), [`Status`] and [`ObserverCounters`].

use super::PmsmObserver;
use super::pmsm::Tracking;
use crate::Float;

/// Whether the angle estimate can be trusted.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum Status {
    /// The angle's standard deviation is below the configured limit and, with the
    /// consistency check on, the innovations are consistent, the model's flux is plausible
    /// and the speed is known to be away from zero (module docs, "Consistency", "Model fit").
    Tracking,
    /// The angle's standard deviation exceeds the limit (the filter has not converged yet, or
    /// the back-EMF is too small to observe the angle near standstill), or the innovations
    /// are far out of line with the noise seen before (the model no longer explains the
    /// currents: a lost or re-converging filter), or the flux the model reads the angle from
    /// is not the magnet's (module docs, "Model fit").
    Uncertain,
}

/// One output sample of the observer.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Estimate<T> {
    /// Electrical rotor angle, rad, in `[-pi, pi)`.
    pub theta_rad: T,
    /// Electrical speed, rad/s.
    pub omega_e_rad_s: T,
    /// Mechanical speed `omega_e / pole_pairs`, rad/s.
    pub omega_mech_rad_s: T,
    /// Estimated alpha current, A.
    pub i_alpha_a: T,
    /// Estimated beta current, A.
    pub i_beta_a: T,
    /// Normalized innovation squared of the last correction (0 before the first one); also
    /// set for a sample the gate rejected.
    pub nis: T,
    /// Trust in the angle.
    pub status: Status,
    /// The innovation gate rejected this sample: the step was a prediction only.
    pub rejected: bool,
    /// The branch check moved the estimate to the other branch in this step
    /// (`theta += pi`, `w = -w`).
    pub branch_flipped: bool,
    /// The covariance health check failed in this step and the observer reset itself.
    pub covariance_reset: bool,
    /// Tracked permanent-magnet flux linkage, Wb (the configured value when tracking is off).
    pub psi_f_wb: T,
    /// Standard deviation of the tracked flux linkage, Wb (0 when tracking is off; refreshed
    /// every 64 samples).
    pub psi_f_sigma_wb: T,
    /// Tracked stator resistance, ohm (the configured value when tracking is off).
    pub rs_ohm: T,
    /// Standard deviation of the tracked resistance, ohm (0 when it is not tracked; refreshed
    /// every 64 samples).
    pub rs_sigma_ohm: T,
    /// Winding temperature derived from the tracked resistance, deg C:
    /// `T_ref + (Rs_hat / Rs_ref - 1) / alpha_cu` (the reference temperature when tracking is
    /// off).
    pub winding_temperature_c: T,
    /// The parameters were tracked in this step (else frozen: low speed, angle uncertain, or
    /// tracking off).
    pub parameters_tracking: bool,
    /// The consistency check finds the recent innovations out of line, the angle moving at
    /// another speed than the speed state, or the model's flux implausible (module docs,
    /// "Consistency", "Speed drift", "Model fit"; the status is then [`Status::Uncertain`]);
    /// `false` with the check off.
    pub inconsistent: bool,
    /// The angle's standard deviation is below the configured limit (the covariance's part of
    /// the status, whatever the innovations say).
    pub angle_tracked: bool,
}

/// Event counters of an observer since its construction (saturating).
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq)]
pub struct ObserverCounters {
    /// Samples rejected by the innovation gate.
    pub rejected: u32,
    /// Times the gate reopened after `max_consecutive` rejections in a row.
    pub gate_reopened: u32,
    /// Branch flips (`theta + pi` recoveries).
    pub branch_flips: u32,
    /// Self-resets by the covariance health check.
    pub covariance_resets: u32,
}
impl<T: Float> PmsmObserver<T> {
    /// The current estimate.
    pub fn estimate(&self) -> Estimate<T> {
        let x = &self.x;
        let angle_tracked = self.p.p33 <= self.angle_var_limit;
        // With the consistency check: the innovations consistent, and the back-EMF known to be
        // there (at the ends of the last 8 blocks: the speed away from zero by five standard
        // deviations and the EMF above three times the drop the resistance's uncertainty
        // leaves), or an angle fused recently.
        let (inconsistent, observable) = match &self.consistency {
            Some(w) => (w.inconsistent, self.fused > 0 || w.observed),
            None => (false, true),
        };
        let status = if !angle_tracked || inconsistent || !observable {
            Status::Uncertain
        } else {
            Status::Tracking
        };
        let (psi_f_wb, psi_f_sigma_wb, rs_ohm, rs_sigma_ohm, winding_temperature_c, tracking) =
            match &self.tracking {
                Some(Tracking { t, slow }) => (
                    t.psi,
                    t.psi_sigma,
                    t.rs,
                    t.rs_sigma,
                    t.winding_temperature_c(&slow.k),
                    t.s.active,
                ),
                _ => (
                    self.nominal.0,
                    T::zero(),
                    self.nominal.1,
                    T::zero(),
                    self.nominal.2,
                    false,
                ),
            };
        Estimate {
            theta_rad: x[3],
            omega_e_rad_s: x[2],
            omega_mech_rad_s: x[2] * self.inv_pole_pairs,
            i_alpha_a: x[0],
            i_beta_a: x[1],
            nis: self.last.nis,
            status,
            rejected: self.events.rejected,
            branch_flipped: self.events.flipped,
            covariance_reset: self.events.reset,
            psi_f_wb,
            psi_f_sigma_wb,
            rs_ohm,
            rs_sigma_ohm,
            winding_temperature_c,
            parameters_tracking: tracking,
            inconsistent,
            angle_tracked,
        }
    }
}
