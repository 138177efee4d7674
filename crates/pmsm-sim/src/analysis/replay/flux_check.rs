//! The record's back-EMF per unit speed against the told flux linkage ([`flux_check`]).
//!
//! # Method
//!
//! The record is cut into blocks of [`BLOCK`] rows. A block is read where the EKF reports
//! `TRACKING` on each of its rows and each of its periods is within 1 % of `Ts`. In the frame of
//! the EKF's angle (each period's voltage turned by the middle of the period's angle, each
//! current by its own), with the block's span `T`, its speed `W` (the estimated angle's advance
//! over the block divided by `T`) and the means `U`, `I` of the voltage and current:
//!
//! ```text
//! E = U - Rs I - j W (Ld I_d + j Lq I_q) - (Ld dI_d + j Lq dI_q) / T      |E| = |W| psi_f
//! ```
//!
//! (`dI` the change of the current over the block). `|E| / |W|` is the block's flux. Only
//! blocks where it is the flux are kept: the resistive and inductive drops
//! `(Rs + |W| Lq) |I|` at most [`MAX_DROP_SHARE`] of `|E|` (light load: a wrong `Rs` or `L`,
//! the inverter's dead-time voltage along the current, moves the reading by at most that
//! share), and a steady speed (the block's two halves within [`MAX_SPEED_CHANGE`] of each
//! other). The length of `E` does not depend on the frame's angle error, and a lead of the
//! applied voltage over the logged one turns `U` without changing its length; so the reading
//! holds where the EKF's own angle or the record's voltage timing is off. The record's flux is
//! the median of the blocks' readings weighted by `W^2` (the faster blocks, whose EMF stands
//! furthest above the voltages the model leaves out).
//!
//! # What it is for
//!
//! A flux off by more than [`FLUX_WARN_SHARE`] is beyond a magnet's temperature range and
//! tolerance: the motor file is wrong for this record, or the log's scaling is (a log written
//! with the power-invariant Clarke transform and read as amplitude-invariant reads `sqrt(3/2)`
//! = 1.22 times the flux). The replay reports it; it does not change what the observers are
//! told.
//!
//! Measured on eight real ESC records of two motors (4.5 kHz, `pmsm-sim replay LOG.csv
//! --motor RUN.toml`; records not in the repository): the three whose motor files fit their
//! logs read 0.989-1.017 times the told flux (one record has no qualifying block: its speed is
//! never steady at light load); four records of the second motor told the same file read
//! 1.069, 1.166, 1.227 (the `sqrt(3/2)` of a power-invariant log) and 1.322. On a simulated
//! log (`cargo test --release -p pmsm-sim --test replay`): 1.00 read with its own scaling,
//! 1.22 read as amplitude-invariant although written power-invariant.

use serde::Serialize;

use super::{DriveLog, ObserverTrace, ReplayMotor, ReplayStatus};
use ekf_core::wrap_angle;

/// Rows per block.
pub const BLOCK: usize = 64;

/// Largest share of `|E|` the resistive and inductive drops may take in a block that is read.
pub const MAX_DROP_SHARE: f64 = 0.1;

/// Largest change of speed between a block's halves, as a share of its speed.
pub const MAX_SPEED_CHANGE: f64 = 0.05;

/// A record whose flux differs from the told one by more than this share is reported.
pub const FLUX_WARN_SHARE: f64 = 0.1;

/// The record's flux against the told one ([`flux_check`]).
#[derive(Clone, Copy, Debug, PartialEq, Serialize)]
pub struct FluxCheck {
    /// Blocks read.
    pub blocks: usize,
    /// The record's back-EMF per unit speed (the weighted median of the blocks), Wb.
    pub flux_wb: f64,
    /// The told flux linkage, Wb.
    pub told_wb: f64,
    /// `flux_wb / told_wb`.
    pub ratio: f64,
}

impl FluxCheck {
    /// The record's flux differs from the told one by more than [`FLUX_WARN_SHARE`].
    pub fn off(&self) -> bool {
        (self.ratio - 1.0).abs() > FLUX_WARN_SHARE
    }
}

/// The record's back-EMF per unit speed from the EKF's trace `tr` of `log` (module docs);
/// `None` when no block qualifies.
pub fn flux_check(log: &DriveLog, motor: &ReplayMotor, tr: &ObserverTrace) -> Option<FluxCheck> {
    let m = &motor.params;
    let ts = motor.ts_s;
    let n = log.len().min(tr.theta.len()).min(tr.status.len());
    let mut reads: Vec<(f64, f64)> = Vec::new();
    let mut start = 1;
    while start + BLOCK <= n {
        let rows = start..start + BLOCK;
        start += BLOCK;
        let usable = rows.clone().all(|k| {
            tr.status[k] == ReplayStatus::Tracking
                && (log.dt_s[k] - ts).abs() <= 0.01 * ts
                && tr.theta[k].is_finite()
        }) && tr.theta[rows.start - 1].is_finite();
        if !usable {
            continue;
        }
        // Angle advance per row (|w Ts| below pi), the voltage of the period that ended at
        // row k (u_ab[k - 1]) turned by the period's middle angle, the currents by their own.
        let (mut adv, mut half_adv) = (0.0, 0.0);
        let (mut ud, mut uq, mut id, mut iq) = (0.0, 0.0, 0.0, 0.0);
        let dq = |i: [f64; 2], th: f64| {
            let (s, c) = th.sin_cos();
            (c * i[0] + s * i[1], c * i[1] - s * i[0])
        };
        for (j, k) in rows.clone().enumerate() {
            let step = wrap_angle(tr.theta[k] - tr.theta[k - 1]);
            let mid = tr.theta[k - 1] + 0.5 * step;
            let (d, q) = dq(log.u_ab[k - 1], mid);
            ud += d;
            uq += q;
            let (d, q) = dq(log.i_ab[k], tr.theta[k]);
            id += d;
            iq += q;
            adv += step;
            if j < BLOCK / 2 {
                half_adv += step;
            }
        }
        let nb = BLOCK as f64;
        let span = nb * ts;
        let w = adv / span;
        let (w1, w2) = (half_adv / (0.5 * span), (adv - half_adv) / (0.5 * span));
        if w == 0.0 || (w1 - w2).abs() > MAX_SPEED_CHANGE * w.abs() {
            continue;
        }
        let (ud, uq, id, iq) = (ud / nb, uq / nb, id / nb, iq / nb);
        let first = rows.start;
        let last = rows.end - 1;
        let (d0, q0) = dq(log.i_ab[first], tr.theta[first]);
        let (d1, q1) = dq(log.i_ab[last], tr.theta[last]);
        let ed = ud - m.rs_ohm * id + w * m.lq_h * iq - m.ld_h * (d1 - d0) / span;
        let eq = uq - m.rs_ohm * iq - w * m.ld_h * id - m.lq_h * (q1 - q0) / span;
        let e = ed.hypot(eq);
        let drop = (m.rs_ohm + w.abs() * m.lq_h) * id.hypot(iq);
        if !(e.is_finite() && e > 0.0) || drop > MAX_DROP_SHARE * e {
            continue;
        }
        reads.push((e / w.abs(), w * w));
    }
    if reads.is_empty() {
        return None;
    }
    reads.sort_by(|a, b| a.0.total_cmp(&b.0));
    let total: f64 = reads.iter().map(|r| r.1).sum();
    let mut acc = 0.0;
    let mut flux = reads[reads.len() - 1].0;
    for &(f, wt) in &reads {
        acc += wt;
        if acc >= 0.5 * total {
            flux = f;
            break;
        }
    }
    Some(FluxCheck {
        blocks: reads.len(),
        flux_wb: flux,
        told_wb: m.psi_f_wb,
        ratio: flux / m.psi_f_wb,
    })
}
