//! The default EKF's error by speed and direction: where a record's remaining error comes from.
//!
//! On a real drive the error that is left once the observer tracks is mostly a bias that
//! depends on the operating point, and its dependence on the speed names its cause. With `e` the
//! angle error (offset removed, electrical rad) and `w` the reference speed (electrical rad/s,
//! signed):
//!
//! - a voltage `dU_d` along the rotor's d axis that the motor gets and the model does not (an
//!   inverter error the log does not show, a d-axis drop the model lacks) turns the back-EMF the
//!   model infers, `w psi_f` on the q axis, by `dU_d / (w psi_f)`: an error in `1 / w`, whose
//!   sign follows the direction of rotation;
//! - a delay `tau` of the reference behind the rotor (an encoder's latency), or a lead `tau` of
//!   the applied voltage over the logged one, is an error `w tau`;
//! - an error that does not change sign with the direction (a wrong inductance under load, a
//!   load-dependent drop) is neither.
//!
//! So the scored samples no more than 45 deg off are split into bands of `|w|` (a share of the
//! run's largest `|w|`: 10-20, 20-40, 40-70 and 70-100 %) and by direction, each band's mean and
//! RMS error reported with its mean `|w|`; and `e` is fitted by least squares with
//! `e ~ c + a / w + b w`, reported as `dU_d = a psi_f` (V, with `psi_f` the motor file's) and
//! `tau = b` (s). The fit needs both directions (at least 10 % of the samples each: the sign
//! flip is what tells the two shapes from the constant and from errors that keep their sign)
//! and speeds varied enough ([`MIN_CONDITIONING`]). It states what the two shapes explain,
//! not their cause; the bands show whether they fit at all.

use nalgebra::{SMatrix, SVector};
use serde::Serialize;

use super::{DriveLog, score_mask};
use crate::output::metrics::LOST_DEG;
use ekf_core::wrap_angle;

/// The bands' edges, as shares of the run's largest `|w|` (the last band includes 1).
pub const BAND_EDGES: [f64; 5] = [0.1, 0.2, 0.4, 0.7, 1.0];

/// One band of speed and direction (module docs).
#[derive(Clone, Copy, Debug, PartialEq, Serialize)]
pub struct SpeedBand {
    /// The band's lower edge, a share of the run's largest `|w|`.
    pub from_share: f64,
    /// The band's upper edge (the last band includes it).
    pub to_share: f64,
    /// Forward (`w > 0`) or backward.
    pub forward: bool,
    /// Samples.
    pub samples: usize,
    /// Mean `|w|`, electrical rad/s.
    pub speed_rad_s: f64,
    /// Mean angle error, electrical degrees.
    pub mean_deg: f64,
    /// RMS angle error, electrical degrees.
    pub rms_deg: f64,
}

/// The bands and the fit of an observer's error (module docs).
#[derive(Clone, Debug, PartialEq, Serialize)]
pub struct SpeedBands {
    /// The bands with samples, by band then direction (forward first).
    pub bands: Vec<SpeedBand>,
    /// The fit; `None` where the run turns one way only (less than [`MIN_DIRECTION_SHARE`] of
    /// the samples in one direction) or its speeds are too alike to tell the three shapes apart
    /// (the normalized determinant of the least-squares problem below [`MIN_CONDITIONING`]).
    pub fit: Option<SpeedFit>,
}

/// The fit `e ~ c + a / w + b w` of an observer's error (module docs).
#[derive(Clone, Copy, Debug, PartialEq, Serialize)]
pub struct SpeedFit {
    /// `c`, electrical degrees.
    pub constant_deg: f64,
    /// `dU_d = a psi_f`: the d-axis voltage the motor gets and the model lacks, V.
    pub d_voltage_v: f64,
    /// `tau = b`: the reference's delay behind the rotor, or the applied voltage's lead over
    /// the logged one, s.
    pub delay_s: f64,
    /// RMS of the error less the fit, electrical degrees (over the fitted samples).
    pub residual_rms_deg: f64,
}

/// The least share of the fitted samples in each direction for the fit to be reported.
pub const MIN_DIRECTION_SHARE: f64 = 0.1;

/// The least normalized determinant (the determinant over the product of the diagonal) of the
/// fit's normal equations at which the fit is reported: the regressors `1`, `1 / w` and `w`
/// must have varied independently over the run.
pub const MIN_CONDITIONING: f64 = 1e-3;

/// Splits the error of `theta` (offset `offset_rad` removed) by speed band and direction and
/// fits it (module docs); `psi_f_wb` is the motor file's flux. `None` without a reference or
/// with fewer than 16 samples.
pub fn speed_bands(
    log: &DriveLog,
    ts_s: f64,
    theta: &[f64],
    offset_rad: f64,
    psi_f_wb: f64,
) -> Option<SpeedBands> {
    let th_ref = log.theta_ref.as_ref()?;
    let w_ref = log.omega_ref.as_ref()?;
    let mask = score_mask(log, ts_s)?;
    let w_max = w_ref.iter().fold(0.0f64, |m, v| m.max(v.abs()));
    // (`fold` with `max` skips NaN; a run that never turns has nothing to split.)
    if w_max <= 0.0 || !w_max.is_finite() {
        return None;
    }
    // The scored samples no more than 45 deg off: (error rad, speed rad/s).
    let kept: Vec<(f64, f64)> = (0..th_ref.len())
        .filter(|&k| mask[k])
        .filter_map(|k| {
            let e = wrap_angle(theta[k] - th_ref[k] - offset_rad);
            let w = w_ref[k];
            (e.is_finite() && e.abs().to_degrees() <= LOST_DEG && w.is_finite() && w != 0.0)
                .then_some((e, w))
        })
        .collect();
    if kept.len() < 16 {
        return None;
    }
    let mut bands = Vec::new();
    for (i, pair) in BAND_EDGES.windows(2).enumerate() {
        let (lo, hi) = (pair[0], pair[1]);
        let last = i + 2 == BAND_EDGES.len();
        for forward in [true, false] {
            let (mut n, mut sw, mut se, mut sq) = (0usize, 0.0, 0.0, 0.0);
            for &(e, w) in &kept {
                let share = w.abs() / w_max;
                let inside = share >= lo && (share < hi || (last && share <= hi));
                if inside && (w > 0.0) == forward {
                    n += 1;
                    sw += w.abs();
                    se += e;
                    sq += e * e;
                }
            }
            if n > 0 {
                let nf = n as f64;
                bands.push(SpeedBand {
                    from_share: lo,
                    to_share: hi,
                    forward,
                    samples: n,
                    speed_rad_s: sw / nf,
                    mean_deg: (se / nf).to_degrees(),
                    rms_deg: (sq / nf).sqrt().to_degrees(),
                });
            }
        }
    }
    // The fit, on regressors scaled to order one: 1, w_max / w, w / w_max.
    let h = |w: f64| SVector::<f64, 3>::from([1.0, w_max / w, w / w_max]);
    let mut ata = SMatrix::<f64, 3, 3>::zeros();
    let mut atb = SVector::<f64, 3>::zeros();
    for &(e, w) in &kept {
        let r = h(w);
        ata += r * r.transpose();
        atb += r * e;
    }
    let det = ata.determinant();
    let scale = ata[(0, 0)] * ata[(1, 1)] * ata[(2, 2)];
    // Both directions, each at least `MIN_DIRECTION_SHARE` of the samples: the sign flip is what
    // tells the two shapes from the constant (and from errors that keep their sign).
    let forward = kept.iter().filter(|(_, w)| *w > 0.0).count() as f64;
    let share = forward / kept.len() as f64;
    let both = (MIN_DIRECTION_SHARE..=1.0 - MIN_DIRECTION_SHARE).contains(&share);
    let fit = (both && scale > 0.0 && det > MIN_CONDITIONING * scale)
        .then(|| ata.cholesky())
        .flatten()
        .map(|ch| {
            let c = ch.solve(&atb);
            let sq: f64 = kept.iter().map(|&(e, w)| (e - c.dot(&h(w))).powi(2)).sum();
            SpeedFit {
                constant_deg: c[0].to_degrees(),
                d_voltage_v: c[1] * w_max * psi_f_wb,
                delay_s: c[2] / w_max,
                residual_rms_deg: (sq / kept.len() as f64).sqrt().to_degrees(),
            }
        })
        .filter(|f| (f.constant_deg + f.d_voltage_v + f.delay_s + f.residual_rms_deg).is_finite());
    Some(SpeedBands { bands, fit })
}

#[cfg(test)]
mod tests {
    use super::speed_bands;
    use crate::analysis::replay::DriveLog;
    use ekf_core::wrap_angle;

    /// An estimate 1 deg ahead of the log's reference.
    fn est_at(log: &DriveLog) -> Vec<f64> {
        let r = log.theta_ref.as_ref().expect("reference");
        r.iter()
            .map(|t| wrap_angle(t + 1f64.to_radians()))
            .collect()
    }

    /// A run forward and backward at 150-1000 rad/s whose estimate carries a d-axis voltage's
    /// error `dU / (w psi)` (0.05 V, 0.01 Wb), a timing error `30 us * w` and a constant 2 deg
    /// (the reference's offset, removed by the offset): the fit finds the voltage and the
    /// timing, and the bands' means flip sign with the direction.
    #[test]
    fn the_fit_finds_a_d_voltage_and_a_timing() {
        let (ts, n, psi) = (1e-4, 60_000, 0.01);
        let (du, tau) = (0.05, 30e-6);
        let (mut th, mut theta_ref, mut omega_ref, mut est) = (0.0f64, vec![], vec![], vec![]);
        for k in 0..n {
            let t = k as f64 * ts;
            // Up and down: +1000 to -1000 rad/s and back, a triangle of 3 s.
            let p = (t / 3.0).fract();
            let w = 1000.0 * (1.0 - 4.0 * (p - 0.5).abs()).clamp(-1.0, 1.0);
            let w = if w.abs() < 150.0 {
                150.0f64.copysign(w)
            } else {
                w
            };
            theta_ref.push(wrap_angle(th));
            omega_ref.push(w);
            est.push(wrap_angle(
                th + du / (w * psi) + tau * w + 2f64.to_radians(),
            ));
            th += w * ts;
        }
        let log = DriveLog::reference_only(ts, theta_ref, omega_ref);
        let b = speed_bands(&log, ts, &est, 2f64.to_radians(), psi).unwrap();
        let f = b.fit.expect("speeds from 15 to 100 % of the largest");
        assert!((f.d_voltage_v - du).abs() < 1e-3 * du, "{f:?}");
        assert!((f.delay_s - tau).abs() < 1e-3 * tau, "{f:?}");
        assert!(
            f.constant_deg.abs() < 1e-6 && f.residual_rms_deg < 1e-6,
            "{f:?}"
        );
        // The slowest bands: the d voltage's error dominates and flips with the direction.
        let slow: Vec<_> = b.bands.iter().filter(|x| x.from_share == 0.1).collect();
        assert_eq!(slow.len(), 2);
        assert!(slow[0].forward && slow[0].mean_deg > 1.0, "{slow:?}");
        assert!(!slow[1].forward && slow[1].mean_deg < -1.0, "{slow:?}");
        assert_eq!(b.bands.len(), 8);
        // At one speed the three shapes cannot be told apart: bands, no fit.
        let steady = DriveLog::reference_only(
            ts,
            (0..n).map(|k| wrap_angle(800.0 * ts * k as f64)).collect(),
            vec![800.0; n],
        );
        let b = speed_bands(&steady, ts, &est_at(&steady), 0.0, psi).unwrap();
        assert!(b.fit.is_none() && b.bands.len() == 1, "{b:?}");
        // No reference speed: nothing.
        let blind = DriveLog {
            omega_ref: None,
            ..log
        };
        assert!(speed_bands(&blind, ts, &est, 0.0, psi).is_none());
    }
}
