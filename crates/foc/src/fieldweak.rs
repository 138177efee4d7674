//! Field weakening: a loop on the voltage margin that adds a negative d current above base
//! speed ([`FieldWeakeningConfig`](crate::FieldWeakeningConfig)).
//!
//! # Law
//!
//! Each tick in closed loop, after the current loops, with `|u|` the magnitude of their
//! steady-state voltage, integrators plus feed-forward (`u_I = I_dq + ff_dq`, the
//! proportional parts left out), `u_max = max_modulation u_dc / sqrt(3)` and `k =
//! voltage_margin`:
//!
//! ```text
//! e      = k u_max - |u|                                    (V; negative: too little headroom)
//! i_fw  += Ts bw e / (Ld max(|w|, w_min))                   (integrator, A)
//! i_fw   = clamp(i_fw, lo, 0),   lo = min(0, -i_d,max - min(i_d,base, 0))
//! ```
//!
//! and the next tick's d reference is `i_d,base + i_fw` (`i_d,base`: the MTPA d current plus
//! the fading d current of a hand-over). Why these choices:
//!
//! - **The loops' integrators plus feed-forward, not their whole output.** A current step
//!   asks for a large voltage through the proportional gains for a few periods (a torque
//!   step of a low-inductance motor asks for many times `u_max`); fed back, it wound the
//!   field-weakening integrator down at standstill, and the current circle then starved the
//!   q axis. The integrators carry what the motor needs in steady state (parameter errors
//!   included); at the voltage limit the q integrator sits at its limit, so a real
//!   shortage still shows.
//! - **Voltage feedback, integral only.** At high speed the q voltage dominates,
//!   `u_q ~ w (psi_f + Ld i_d)`, so `d|u| / d i_d ~ w Ld`: dividing the integrator gain by
//!   `w Ld` makes the loop first order with crossover `bw` (`bandwidth_rad_s`) at every
//!   speed. The feedback needs no motor model beyond `Ld` and no feed-forward that a wrong
//!   `psi_f` would bias; the integrator holds the steady state exactly (`|u| = k u_max`).
//!   `w_min` (the hand-over speed) only bounds the gain at low speed, where the loop sits at
//!   its upper clamp anyway.
//! - **Active above base speed, fading out below.** Below base speed the loops need less
//!   than `k u_max`, `e > 0` and the integrator runs back to its clamp at 0 (at the same
//!   rate `bw`); no speed threshold is involved.
//! - **Margin `k < 1`** (default 0.95) leaves the current loops headroom to regulate; at
//!   `k = 1` they would sit on the voltage limit, where the d-first limit of the current
//!   loop already starves the q axis.
//! - **Anti-windup.** The clamp stops the integrator where the total d reference reaches
//!   `-i_d,max` (`max_negative_id_a`, default `min(current_limit_a, psi_f / Ld)`: more
//!   negative d current than the characteristic current only costs copper) and at 0 (never
//!   a positive correction). The controller then limits the current vector to the circle
//!   `i_d^2 + i_q^2 <= current_limit_a^2`, cutting `i_q` first so the d current that keeps
//!   the voltage in bounds is kept.
//! - Out of closed loop (align, I/f) the correction is reset to 0.

use crate::pi::limit;
use crate::trig::{max2, min2, sqrt};

/// The field-weakening integrator (module docs).
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct FieldWeakening {
    /// `voltage_margin`.
    margin: f32,
    /// `Ts bw / Ld`, A per (V rad/s ... ) per tick: the integrator gain before `1/|w|`.
    gain: f32,
    /// Floor of `|w|` in the gain, rad/s.
    w_min: f32,
    /// Largest negative d current, A (positive number).
    max_neg: f32,
    /// The correction, A (`<= 0`).
    i_fw: f32,
}

impl FieldWeakening {
    /// A loop with margin `margin`, crossover `bw_rad_s`, tick `ts_s`, d inductance `ld_h`,
    /// gain floor `w_min_rad_s` and largest negative d current `max_negative_id_a`;
    /// correction at 0.
    pub fn new(
        margin: f32,
        bw_rad_s: f32,
        ts_s: f32,
        ld_h: f32,
        w_min_rad_s: f32,
        max_negative_id_a: f32,
    ) -> Self {
        Self {
            margin,
            gain: ts_s * bw_rad_s / ld_h,
            w_min: w_min_rad_s,
            max_neg: max_negative_id_a,
            i_fw: 0.0,
        }
    }

    /// The d-current correction, A (`<= 0`).
    #[inline]
    pub fn id(&self) -> f32 {
        self.i_fw
    }

    /// One tick: `u_sq` the squared magnitude of the current loops' steady-state voltage, V^2,
    /// `u_max` their voltage limit, V, `omega` the frame speed, rad/s, `id_base` the d
    /// reference without the correction, A. A NaN leaves the correction as it is.
    #[inline]
    pub fn update(&mut self, u_sq: f32, u_max: f32, omega: f32, id_base: f32) {
        let e = self.margin * u_max - sqrt(u_sq);
        let w = max2(max2(omega, -omega), self.w_min);
        let next = self.i_fw + self.gain * e / w;
        if next.is_nan() {
            return;
        }
        let lo = min2(-self.max_neg - min2(id_base, 0.0), 0.0);
        self.i_fw = limit(next, lo, 0.0);
    }

    /// Correction back to 0.
    #[inline]
    pub fn reset(&mut self) {
        self.i_fw = 0.0;
    }
}
