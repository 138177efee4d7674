//! The optional d-axis current excitation ([`DExcitation`], `FocConfig::d_excitation`; Cargo
//! feature `d-excitation`).
//!
//! In closed loop (the observer's or the sensor's frame) the drive adds a square wave of
//! `+-amplitude_a` to its d-current reference, `half_period_ticks` ticks per half: `+a` while
//! [`DExcitation::sign`] of the tick counter ([`Foc::tick_count`](crate::Foc::tick_count)
//! after the tick) is `true`, `-a` otherwise. The sign is a pure function of the tick counter
//! (the estimator's [`ekf_core::excitation_sign`]), so the user's estimator
//! ([`ekf_core::excitation`]) computes it from the same count; the reference with the
//! excitation is also in the tick's telemetry (`i_dq_ref`). Added after MTPA, field
//! weakening and the current circle (a small `a` is assumed to fit within the current
//! limit); the start-up phases (align, I/f) are left alone, and the excitation is off below
//! `min_speed_rad_s` (electrical).
//!
//! What it costs:
//!
//! - Copper loss: `+a^2` on top of `i_q^2` (`a` = 10 % of the rated current: +1 % of the
//!   rated copper loss);
//! - torque ripple: none on a surface motor (`T = 1.5 p psi_f i_q`); on an interior one
//!   `1.5 p (Ld - Lq) i_d i_q`, a square wave of `+-1.5 p (Ld - Lq) a i_q`;
//! - voltage: the d step needs `Rs a` plus `w Ls a` on the q axis (`w Ls a / (w psi_f)` =
//!   `Ls a / psi_f` of the EMF: the voltage headroom the drive must keep at top speed).

/// A square wave on the closed-loop d-current reference (module docs).
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct DExcitation {
    /// Amplitude `a`, A (positive, at most the current limit; `FocConfig::validate`).
    pub amplitude_a: f32,
    /// Ticks per half period (at least 2).
    pub half_period_ticks: u32,
    /// Off while the control frame's electrical speed is below this, rad/s (non-negative):
    /// through zero speed the observer's angle is weakly observable and the steps of `i_d`
    /// disturb it, and `Ls` cannot be measured there anyway.
    pub min_speed_rad_s: f32,
}

impl DExcitation {
    /// The sign at tick counter `tick` (`true`: `+a`): `ekf_core::excitation_sign`.
    pub fn sign(&self, tick: u32) -> bool {
        ekf_core::excitation_sign(tick, self.half_period_ticks)
    }

    /// The d-current offset at tick counter `tick`, A.
    #[inline]
    pub fn offset_a(&self, tick: u32) -> f32 {
        if self.sign(tick) {
            self.amplitude_a
        } else {
            -self.amplitude_a
        }
    }
}
