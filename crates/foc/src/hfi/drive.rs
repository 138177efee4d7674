//! HFI inside the controller (module [`crate::controller`], "Low speed by HFI"): the drive's
//! state ([`Stage`]: the standstill test, then tracking), its dispatcher, and the hooks the
//! controller calls each tick in this order:
//!
//! ```text
//! demodulate(i_ab)        the sample through the tracker (carrier on) -> response, fundamental
//! standstill(response)    Standstill: the test's d current (Some) | Tracking: None
//! fusion_variance()       Tracking: HFI's angle as a measurement of the observer's
//! blend(theta_o, w_o)     Tracking: the control angle and speed (Track::step)
//! set_torque_command(i_T) the drive's acceleration, fed forward at the next tick
//! finish(i_ab, fund)      the next carrier (when on) and the current the loops take
//! ```

use super::blend::{Band, Blend, Track};
use super::config::HfiConfig;
use super::demod::Response;
use super::polarity::{PolarityPlan, PolarityStep, Standstill};
use super::tracker::HfiTracker;
use crate::config::FocConfig;
use crate::transforms::AlphaBeta;

/// Phase of the HFI start and run.
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq)]
pub enum HfiPhase {
    /// Standstill, no current: the loop settles on the salient axis.
    #[default]
    Settling,
    /// First polarity pulse (`+I_p` on the tracked d axis).
    PulsePositive,
    /// Second polarity pulse (`-I_p`).
    PulseNegative,
    /// Closed loop on the HFI angle (blended with the observer's by speed).
    Tracking,
}

/// What HFI is doing (the controller's [`hfi_status`](crate::Foc::hfi_status)).
#[derive(Clone, Copy, Debug, Default, PartialEq)]
pub struct HfiStatus {
    /// Phase.
    pub phase: HfiPhase,
    /// Whether the carrier is on this tick.
    pub injecting: bool,
    /// Weight of the observer's angle in the control angle, `0` (HFI alone) to `1`.
    pub observer_weight: f32,
    /// HFI's tracked angle, rad el.
    pub theta_rad: f32,
    /// HFI's tracked speed, rad/s el.
    pub omega_rad_s: f32,
    /// Mean d response under `+I_p` over that under `-I_p` (> 1: the tracked axis was north);
    /// NaN before the test ends or when it was not run.
    pub polarity_contrast: f32,
    /// Whether the polarity test turned the axis by `pi`.
    pub polarity_flipped: bool,
    /// The last demodulation.
    pub response: Response,
}

/// The drive's state, each variant with its own state.
#[derive(Clone, Copy, Debug, PartialEq)]
#[repr(u8)]
pub(crate) enum Stage {
    /// The standstill test (settling, then the polarity pulses).
    Standstill(Standstill),
    /// Closed loop on the HFI angle, blended with the observer's by speed.
    Tracking(Track),
}

impl Stage {
    /// The phase reported to the user.
    #[inline]
    pub fn phase(&self) -> HfiPhase {
        match self {
            Stage::Standstill(Standstill::Settling(_)) => HfiPhase::Settling,
            Stage::Standstill(Standstill::PulsePositive(_)) => HfiPhase::PulsePositive,
            Stage::Standstill(Standstill::PulseNegative { .. }) => HfiPhase::PulseNegative,
            Stage::Tracking(_) => HfiPhase::Tracking,
        }
    }
}

/// A stage equals the phase it reports.
impl PartialEq<HfiPhase> for Stage {
    #[inline]
    fn eq(&self, other: &HfiPhase) -> bool {
        self.phase() == *other
    }
}

/// HFI inside the controller: settings, tracker, state.
#[derive(Clone, Copy, Debug, PartialEq)]
pub(crate) struct HfiDrive {
    pub cfg: HfiConfig,
    pub tracker: HfiTracker,
    /// The state ([`Stage`]; compares with [`HfiPhase`]).
    pub phase: Stage,
    /// The standstill test's timing.
    plan: PolarityPlan,
    /// The hand-over band's constants.
    band: Band,
    /// Whether this tick's current sample went through the tracker (then the loops take
    /// its fundamental).
    demodulated: bool,
    /// `p k_t / J`: electrical acceleration per ampere of torque command, rad/s^2/A.
    accel_per_a: f32,
    /// Acceleration of the last torque command, rad/s^2 el.
    accel: f32,
}

impl HfiDrive {
    pub fn new(foc: &FocConfig, cfg: &HfiConfig) -> Self {
        Self {
            cfg: *cfg,
            tracker: HfiTracker::from_config(foc, cfg),
            phase: Stage::Standstill(Standstill::new()),
            plan: PolarityPlan::new(cfg, foc.ts_s),
            band: Band::new(foc, cfg),
            demodulated: false,
            accel_per_a: foc.motor.pole_pairs as f32 * foc.torque_constant_nm_a()
                / foc.inertia_kg_m2,
            accel: 0.0,
        }
    }

    /// Whether the observer's weight follows the faster of the two speeds (module
    /// [`super::blend`]).
    #[cfg(test)]
    pub fn weight_on_faster(&self) -> bool {
        self.band.weight_on_faster
    }

    /// Whether the carrier is on this tick (always during the standstill test).
    #[inline]
    pub fn injecting(&self) -> bool {
        match &self.phase {
            Stage::Standstill(_) => true,
            Stage::Tracking(t) => t.injecting,
        }
    }

    /// Whether this tick's sample was demodulated (the loops and the observer then take the
    /// fundamental).
    #[inline]
    pub fn demodulated(&self) -> bool {
        self.demodulated
    }

    /// The torque command of this tick as a surface-equivalent current (A, module
    /// [`crate::mtpa`]), fed forward to the tracking loop at the next tick.
    #[inline]
    pub fn set_torque_command(&mut self, i_t: f32) {
        let a = self.accel_per_a * i_t;
        self.accel = if a.is_finite() { a } else { 0.0 };
    }

    /// Back to the standstill start (called by `Foc::start` from idle).
    pub fn restart(&mut self, foc: &FocConfig) {
        *self = Self::new(foc, &self.cfg);
    }

    /// Status for the user.
    pub fn status(&self) -> HfiStatus {
        let (injecting, observer_weight, contrast, flipped) = match &self.phase {
            Stage::Standstill(_) => (true, 0.0, f32::NAN, false),
            Stage::Tracking(t) => (
                t.injecting,
                t.weight,
                t.polarity.contrast,
                t.polarity.flipped,
            ),
        };
        HfiStatus {
            phase: self.phase.phase(),
            injecting,
            observer_weight,
            theta_rad: self.tracker.theta(),
            omega_rad_s: self.tracker.omega(),
            polarity_contrast: contrast,
            polarity_flipped: flipped,
            response: self.tracker.response(),
        }
    }

    /// Takes this tick's current sample (when the carrier is on): the response and the
    /// current the loops should see.
    #[inline]
    pub fn demodulate(
        &mut self,
        i_ab: AlphaBeta,
        sample_ok: bool,
    ) -> (Option<Response>, AlphaBeta) {
        self.demodulated = false;
        if !self.injecting() {
            return (None, i_ab);
        }
        if !sample_ok {
            self.tracker.skip(self.accel);
            return (None, i_ab);
        }
        self.demodulated = true;
        self.tracker.update(i_ab, self.accel)
    }

    /// The standstill test for this tick: the d current reference while it runs (`Some`),
    /// `None` once tracking (the test ends in the tick it decides, which then tracks).
    #[inline]
    pub fn standstill(&mut self, resp: Option<Response>) -> Option<f32> {
        let Stage::Standstill(test) = &mut self.phase else {
            return None;
        };
        match test.step(&self.plan, resp) {
            PolarityStep::Drive(i_d) => Some(i_d),
            PolarityStep::Done(polarity) => {
                if polarity.flipped {
                    self.tracker.flip();
                }
                self.phase = Stage::Tracking(Track::new(polarity));
                None
            }
        }
    }

    /// The variance (rad^2) with which HFI's angle is fused into the observer this tick
    /// (module [`crate::hfi`], "Hand-over band"): while tracking with the carrier on and the
    /// observer's weight below 1, `fusion_sigma^2 / (1 - weight)` (the last tick's weight);
    /// `None` otherwise or with the fusion off.
    #[inline]
    pub fn fusion_variance(&self) -> Option<f32> {
        match &self.phase {
            Stage::Tracking(t) => t.fusion_variance(self.cfg.fusion_sigma_rad),
            Stage::Standstill(_) => None,
        }
    }

    /// The blended control angle and speed (observer estimate `theta_o`, `omega_o`; module
    /// [`super::blend`]) while tracking; HFI's own during the standstill test (the
    /// controller does not ask then).
    #[inline]
    pub fn blend(&mut self, theta_o: f32, omega_o: f32) -> Blend {
        match &mut self.phase {
            Stage::Tracking(t) => {
                t.step(&self.band, &mut self.tracker, self.accel, theta_o, omega_o)
            }
            Stage::Standstill(_) => Blend {
                theta: self.tracker.theta(),
                omega: self.tracker.omega(),
                reseed: None,
            },
        }
    }

    /// The carrier for this tick (when on) and the current the loops take: the fundamental
    /// while the carrier is demodulated, the sample itself otherwise.
    #[inline]
    pub fn finish(&mut self, i_ab: AlphaBeta, fund: AlphaBeta) -> (Option<AlphaBeta>, AlphaBeta) {
        let i_loop = if self.demodulated { fund } else { i_ab };
        let carrier = if self.injecting() {
            Some(self.tracker.inject())
        } else {
            None
        };
        (carrier, i_loop)
    }
}
