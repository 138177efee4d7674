//! HFI in the controller (module docs of [`controller`](super), "Low speed by HFI"): turning
//! it on and off, and the plan of a tick with HFI on.

use ekf_core::{Estimate, PmsmObserver};

use super::{Foc, reseed_observer};
use crate::config::Mode;
use crate::hfi::{HFI_TRACKING_SPEED_FACTOR, HfiConfig, HfiError, HfiStatus};
use crate::startup::{Frame, Inputs, Plan, Seed, State, Stop};
use crate::transforms::{AlphaBeta, Dq};
use crate::trig::max2;

impl Foc {
    /// Turns high-frequency injection on for the low-speed range (module docs, "Low speed by
    /// HFI"), with the settings `hfi` checked against the configuration and the nominal bus
    /// voltage `u_dc_nominal_v`. Only while idle, in sensorless mode, on a salient motor.
    /// (Cargo feature `hfi`.)
    #[cfg(feature = "hfi")]
    pub fn enable_hfi(
        &mut self,
        hfi: &crate::hfi::HfiConfig,
        u_dc_nominal_v: f32,
    ) -> Result<(), HfiError> {
        if self.seq.state() != State::Idle {
            return Err(HfiError::NotIdle);
        }
        hfi.validate(&self.cfg, u_dc_nominal_v)?;
        self.rebuild_observer(Some(hfi));
        self.hfi = Some(crate::hfi::HfiDrive::new(&self.cfg, hfi));
        Ok(())
    }

    /// Turns high-frequency injection off (the controller as built by [`Foc::new`]). Only
    /// while idle.
    pub fn disable_hfi(&mut self) -> Result<(), HfiError> {
        if self.seq.state() != State::Idle {
            return Err(HfiError::NotIdle);
        }
        self.rebuild_observer(None);
        self.hfi = None;
        Ok(())
    }

    /// What HFI is doing (`None`: off).
    pub fn hfi_status(&self) -> Option<HfiStatus> {
        self.hfi.map(|h| h.status())
    }

    /// The plan of a tick with HFI on (module docs, "Low speed by HFI"): the standstill test's
    /// d current in the tracked frame, or the sequencer's sensored path on the blended angle;
    /// with the carrier to add and the current the loops take.
    #[inline(never)]
    pub(super) fn hfi_plan(
        &mut self,
        est: &Estimate<f32>,
        observer_ok: bool,
        i_ab: AlphaBeta,
        resp: Option<crate::hfi::Response>,
        fund: AlphaBeta,
    ) -> Result<(Plan, Option<AlphaBeta>, AlphaBeta), Stop> {
        let Some(h) = self.hfi.as_mut() else {
            return Err(Stop::Off);
        };
        let plan = if let Some(i_d) = h.standstill(resp) {
            Plan {
                frame: Frame {
                    theta: h.tracker.theta(),
                    omega: 0.0,
                    emf: false,
                },
                i_ref: Dq { d: i_d, q: 0.0 },
                reframe_from: None,
            }
        } else {
            // HFI's angle fused into the observer while HFI has a say (module [`crate::hfi`],
            // "Hand-over band"); the observer keeps its estimate if refused. (The tick's
            // telemetry keeps the step's estimate.)
            let (mut theta_o, mut omega_o) = (est.theta_rad, est.omega_e_rad_s);
            if observer_ok
                && let Some(var) = h.fusion_variance()
                && self.observer.correct_angle(h.tracker.theta(), var).is_ok()
            {
                let x = self.observer.state();
                (theta_o, omega_o) = (x[3], x[2]);
            }
            let b = h.blend(theta_o, omega_o);
            if let Some((theta, omega)) = b.reseed {
                let seed = Seed {
                    theta,
                    omega,
                    sigma_theta: 0.1,
                };
                reseed_observer(&mut self.observer, &self.cfg, seed);
            }
            let inputs = Inputs {
                estimate: est,
                observer_ok,
                sensor: Some((b.theta, b.omega)),
                // Read only by the damped start of the sensorless path.
                u_ab: [0.0; 2],
            };
            self.cfg.mode = Mode::Sensored;
            let (cfg, observer) = (&self.cfg, &mut self.observer);
            let r = self.seq.step(cfg, inputs, &mut |seed| {
                reseed_observer(observer, cfg, seed)
            });
            self.cfg.mode = Mode::Sensorless;
            let plan = r?;
            h.set_torque_command(plan.i_ref.q);
            plan
        };
        let (carrier, i_loop) = h.finish(i_ab, fund);
        Ok((plan, carrier, i_loop))
    }

    /// Rebuilds the (idle) observer for HFI `hfi` (or none), keeping its tracked `psi_f` and
    /// `Rs`. With HFI its online parameter tracking stays frozen below
    /// [`HFI_TRACKING_SPEED_FACTOR`](crate::hfi::HFI_TRACKING_SPEED_FACTOR) times the top of the blend band: the observer's speed is
    /// noisiest there, the carrier's steps are in its input, and a flux estimate that moves
    /// while the drive leans on HFI was measured to collapse (traction motor: `psi_f` from
    /// 0.012 to 0.0066 Wb in 2 ms at 7 % of rated speed, the speed estimate 40 % high after
    /// it, the reversal lost by pi).
    pub(super) fn rebuild_observer(&mut self, hfi: Option<&HfiConfig>) {
        let mut oc = self.cfg.observer;
        if let (Some(h), Some(t)) = (hfi, oc.parameter_tracking.as_mut()) {
            t.min_speed_rad_s = max2(
                t.min_speed_rad_s,
                HFI_TRACKING_SPEED_FACTOR * h.blend_high_rad_s,
            );
        }
        // Cannot fail: only a speed threshold differs from the validated configuration.
        if let Ok(mut o) = PmsmObserver::new(&oc) {
            let (psi_f, rs) = self.observer.parameters();
            let _ = o.set_parameters(psi_f, rs);
            self.observer = o;
        }
    }
}
