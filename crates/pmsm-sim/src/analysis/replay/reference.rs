//! The reference's own error: the part of an observer's angle error that repeats with the
//! reference's mechanical angle.
//!
//! A shaft encoder mounted off-centre, or a magnet-and-sensor pair that is not aligned, reads
//! an angle that deviates from the rotor's by a function of the shaft position: mostly at once
//! and twice the mechanical frequency. The back-EMF carries the rotor's electrical angle, so
//! an observer of the voltages and currents cannot reproduce that deviation: it stays in the
//! score as an error of the observer. To show how much of the score it is, the angle error
//! (offset removed, over the scored samples no more than 45 deg off) is fitted by least squares
//! with a constant and the first two harmonics of the mechanical angle,
//! `theta_m = unwrap(theta_ref) / pole_pairs` (relative to the log's first row):
//!
//! ```text
//! e(k) ~ c0 + a1 cos(theta_m) + b1 sin(theta_m) + a2 cos(2 theta_m) + b2 sin(2 theta_m)
//! ```
//!
//! Reported: the amplitudes `hypot(a1, b1)` and `hypot(a2, b2)`, the RMS of the fitted periodic
//! part, and the RMS of the error with that part subtracted (all scored samples). An error
//! that is the observer's own (a voltage timing, a wrong resistance) depends on the speed and
//! the load, not on where the shaft is, and leaves the fit alone over a run that changes speed
//! at varied shaft positions.

use nalgebra::{SMatrix, SVector};
use serde::Serialize;

use super::{DriveLog, score_mask};
use crate::output::metrics::LOST_DEG;
use ekf_core::wrap_angle;

/// The part of an angle error periodic in the reference's mechanical angle (module docs).
#[derive(Clone, Copy, Debug, PartialEq, Serialize)]
pub struct MechanicalComponent {
    /// Samples fitted (scored, no more than 45 deg off).
    pub samples: usize,
    /// Amplitude at once the mechanical frequency, electrical degrees.
    pub first_deg: f64,
    /// Amplitude at twice the mechanical frequency, electrical degrees.
    pub second_deg: f64,
    /// RMS of the fitted periodic part, electrical degrees.
    pub rms_deg: f64,
    /// RMS of the score's error with the periodic part subtracted, electrical degrees.
    pub rms_without_deg: f64,
}

/// Fits the error of `theta` (offset `offset_rad` removed) against the reference's mechanical
/// angle; `None` without a reference or with fewer than 16 samples to fit.
pub fn mechanical_component(
    log: &DriveLog,
    ts_s: f64,
    theta: &[f64],
    offset_rad: f64,
    pole_pairs: u32,
) -> Option<MechanicalComponent> {
    let th_ref = log.theta_ref.as_ref()?;
    let mask = score_mask(log, ts_s)?;
    let pp = f64::from(pole_pairs.max(1));
    let mut unwrapped = 0.0;
    let mut mech = Vec::with_capacity(th_ref.len());
    for (k, t) in th_ref.iter().enumerate() {
        if k > 0 {
            unwrapped += wrap_angle(t - th_ref[k - 1]);
        }
        mech.push(unwrapped / pp);
    }
    let regressors = |m: f64| {
        let (s1, c1) = m.sin_cos();
        let (s2, c2) = (2.0 * m).sin_cos();
        SVector::<f64, 5>::from([1.0, c1, s1, c2, s2])
    };
    let err_deg = |k: usize| {
        let e = wrap_angle(theta[k] - th_ref[k] - offset_rad);
        if e.is_finite() { e.to_degrees() } else { 180.0 }
    };
    let mut ata = SMatrix::<f64, 5, 5>::zeros();
    let mut atb = SVector::<f64, 5>::zeros();
    let mut n = 0usize;
    for k in (0..th_ref.len()).filter(|&k| mask[k]) {
        let e = err_deg(k);
        if e.abs() > LOST_DEG || !mech[k].is_finite() {
            continue;
        }
        let h = regressors(mech[k]);
        ata += h * h.transpose();
        atb += h * e;
        n += 1;
    }
    if n < 16 {
        return None;
    }
    let c = ata.cholesky()?.solve(&atb);
    let (mut sq_part, mut sq_without, mut scored) = (0.0, 0.0, 0usize);
    for k in (0..th_ref.len()).filter(|&k| mask[k]) {
        let h = regressors(mech[k]);
        let periodic = c.dot(&h) - c[0];
        let e = err_deg(k);
        sq_part += periodic * periodic;
        let w = e - periodic;
        // Back to (-180, 180]: the subtraction may cross the wrap.
        let w = wrap_angle(w.to_radians()).to_degrees();
        sq_without += w * w;
        scored += 1;
    }
    let nf = scored as f64;
    Some(MechanicalComponent {
        samples: n,
        first_deg: c[1].hypot(c[2]),
        second_deg: c[3].hypot(c[4]),
        rms_deg: (sq_part / nf).sqrt(),
        rms_without_deg: (sq_without / nf).sqrt(),
    })
}

#[cfg(test)]
mod tests {
    use super::mechanical_component;
    use crate::analysis::replay::DriveLog;
    use ekf_core::wrap_angle;

    /// A reference that wobbles by 2 deg at once and 6 deg at twice the mechanical angle
    /// around the true angle, at speeds changing from 300 to 900 rad/s; an estimate equal to
    /// the true angle plus a speed-proportional error (an observer's own, like a voltage
    /// timing). The fit finds the wobble and leaves the observer's error.
    #[test]
    fn the_reference_wobble_is_found_and_the_observers_own_error_left() {
        let (ts, pp, n) = (1e-4, 7u32, 40_000);
        let (mut th, mut theta_ref, mut omega_ref, mut est) = (0.0f64, vec![], vec![], vec![]);
        for k in 0..n {
            let t = k as f64 * ts;
            let w = 600.0 + 300.0 * (2.0 * std::f64::consts::PI * 0.5 * t).sin();
            let m = th / f64::from(pp);
            let wobble =
                (2.0f64.to_radians()) * (m + 0.3).cos() + 6.0f64.to_radians() * (2.0 * m).sin();
            theta_ref.push(wrap_angle(th + wobble));
            omega_ref.push(w);
            // The observer's own error: 1e-5 s times the speed (0.2-0.5 deg), no wobble.
            est.push(wrap_angle(th - w * 1e-5));
            th += w * ts;
        }
        let log = DriveLog::reference_only(ts, theta_ref, omega_ref);
        let m = mechanical_component(&log, ts, &est, 0.0, pp).unwrap();
        assert!((m.first_deg - 2.0).abs() < 0.1, "{m:?}");
        assert!((m.second_deg - 6.0).abs() < 0.1, "{m:?}");
        // What is left is the speed-proportional error about its mean: 0.2-0.5 deg.
        assert!(m.rms_without_deg < 0.6 && m.rms_without_deg > 0.2, "{m:?}");
        // Without a wobble nothing periodic is found.
        let clean = DriveLog {
            theta_ref: Some((0..n).map(|k| est[k]).collect()),
            ..log
        };
        let m = mechanical_component(&clean, ts, &est, 0.0, pp).unwrap();
        assert!(m.rms_deg < 1e-9, "{m:?}");
    }
}
