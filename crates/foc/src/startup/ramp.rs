//! `OpenLoop`: the current-controlled ramp, I/f (module docs of [`startup`](super), "Open
//! loop"). Per tick, in this order:
//!
//! 1. (start from standstill only) the damping: `phi = clamp(-K (w_hat - w_ol), +-phi_max)`,
//!    `gamma += phi - phi_last` with `K = 2 zeta / w_n`;
//! 2. a theta+pi lock reported as a loss: a re-acquisition (observer re-seeded at the
//!    vector, sigma 45 deg); more than `max_reacquire` in a row trip `ObserverLost`;
//! 3. else at the hand-over speed (`|target| >= w_h`, `w_ol` toward the target, `|w_ol| >=
//!    0.999 w_h`): the hand-over once the health monitor reports the observer ready; after
//!    `acquire_timeout_s` there without it a stall (`|w_avg| < |w_ol| / 4`) or a
//!    re-acquisition;
//! 4. a stop is complete at `w_ol = 0`;
//! 5. after the plan takes this tick's frame, the ramp advances: `gamma += w_ol Ts`,
//!    `w_ol` slews toward `clamp(target, +-w_h)` at `accel_rad_s2`; a sign change of
//!    `w_ol` re-seeds the observer at `(gamma, w_ol)` (except the first one after a
//!    launch).

use core::f32::consts::{FRAC_PI_4, PI};

use ekf_core::Estimate;

use super::closed::SpeedLoop;
use super::{Frame, Params, Phase, Seed, Sequencer, Stop, reseed_observer, sign, slew};
use crate::config::FocConfig;
use crate::fault::Fault;
use crate::health::{HealthMonitor, HealthReport};
use crate::pi::limit;
use crate::trig::wrap;

/// The ramp's variables.
#[derive(Clone, Copy, Debug, Default, PartialEq)]
pub(super) struct Ramp {
    /// Current-vector angle, rad el. (the damping offset included).
    pub gamma: f32,
    /// Ramp speed, rad/s el.
    pub omega_ol: f32,
    /// Current magnitude, A.
    pub amp: f32,
    /// Sign of the last non-zero ramp speed (0 before the first).
    pub ol_dir: f32,
    /// Ticks at the hand-over speed without a hand-over.
    pub at_speed: u32,
    /// Damping offset of the current vector (included in `gamma`), rad el.
    pub phi: f32,
    /// Launched from the rotor's motion: the ramp's first sign change does not re-seed.
    pub launch: bool,
    /// The start from standstill, until the first hand-over: the ramp is damped.
    pub starting: bool,
}

impl Ramp {
    /// I/f from standstill at `gamma`; the observer seeded there with angle standard
    /// deviation `sigma_theta`.
    pub fn from_rest(
        cfg: &FocConfig,
        gamma: f32,
        sigma_theta: f32,
        health: &mut HealthMonitor,
        reseed: &mut impl FnMut(Seed),
    ) -> Self {
        reseed_observer(health, gamma, 0.0, sigma_theta.min(PI), reseed);
        Self {
            gamma,
            amp: cfg.startup.if_current_a,
            starting: true,
            ..Self::default()
        }
    }

    /// I/f after a launch: the vector at `gamma`, the ramp at `omega_ol` toward `ol_dir`.
    pub fn launched(cfg: &FocConfig, gamma: f32, omega_ol: f32, ol_dir: f32) -> Self {
        Self {
            gamma,
            omega_ol,
            amp: cfg.startup.if_current_a,
            ol_dir,
            launch: true,
            starting: true,
            ..Self::default()
        }
    }

    /// The damping of the current vector: its angle offset from the ramp's is
    /// `-k (w_hat - w_ramp)`, limited to `+-phi_max` (module docs).
    #[inline(always)]
    fn damp(&mut self, w_hat: f32, w_ramp: f32, k: f32, phi_max: f32) {
        let phi = limit(-k * (w_hat - w_ramp), -phi_max, phi_max);
        self.gamma = wrap(self.gamma + (phi - self.phi));
        self.phi = phi;
    }

    /// One I/f period: the current-vector angle integrates the ramp speed, which moves
    /// toward its target (`target`, rad/s el.); re-seeds the observer when the speed
    /// crosses zero. Every I/f tick: inlined.
    #[inline(always)]
    pub fn advance(
        &mut self,
        cfg: &FocConfig,
        k: &Params,
        target: f32,
        speed: &mut SpeedLoop,
        health: &mut HealthMonitor,
        reseed: &mut impl FnMut(Seed),
    ) {
        let ts = cfg.ts_s;
        let h = k.handover;
        let target = limit(target, -h, h);
        speed.reference_mech = self.omega_ol * k.inv_pole_pairs;
        self.gamma = wrap(self.gamma + self.omega_ol * ts);
        let w = slew(self.omega_ol, target, cfg.startup.accel_rad_s2 * ts);
        if w != 0.0 {
            let dir = sign(w);
            if self.ol_dir != 0.0 && dir != self.ol_dir {
                if self.launch {
                    self.launch = false;
                } else {
                    reseed_observer(health, self.gamma, w, FRAC_PI_4, reseed);
                    self.at_speed = 0;
                }
            }
            self.ol_dir = dir;
        }
        self.omega_ol = w;
    }
}

/// A re-acquisition under I/f: the observer re-seeded at the current vector; `false` (trip
/// [`Fault::ObserverLost`]) when the attempts are used up. Rare: out of line.
#[inline(never)]
fn reacquire(
    cfg: &FocConfig,
    r: &mut Ramp,
    attempts: &mut u8,
    health: &mut HealthMonitor,
    reseed: &mut impl FnMut(Seed),
) -> bool {
    *attempts = attempts.saturating_add(1);
    if *attempts > cfg.health.max_reacquire {
        return false;
    }
    reseed_observer(health, r.gamma, r.omega_ol, FRAC_PI_4, reseed);
    r.at_speed = 0;
    true
}

impl Sequencer {
    /// One tick of `OpenLoop` (steps 1 to 4 of the module docs). Returns the frame the
    /// current loops leave at a hand-over.
    #[inline(always)]
    pub(super) fn open_loop(
        &mut self,
        cfg: &FocConfig,
        est: &Estimate<f32>,
        report: &HealthReport,
        reseed: &mut impl FnMut(Seed),
    ) -> Result<Option<Frame>, Stop> {
        let Phase::OpenLoop(r) = &mut self.phase else {
            return Ok(None);
        };
        let k = &self.k;
        if r.starting {
            r.damp(est.omega_e_rad_s, r.omega_ol, k.k_damp, k.phi_max);
        }
        let target = self.cmd.target_e(k);
        let w_ol = r.omega_ol;
        let h = k.handover;
        let at_speed = target.abs() >= h && w_ol * target > 0.0 && w_ol.abs() >= h * 0.999;
        if report.lost.is_some() {
            // Only the theta+pi lock is reported as a loss under I/f.
            if !reacquire(cfg, r, &mut self.attempts, &mut self.health, reseed) {
                return Err(Stop::Trip(Fault::ObserverLost, est.omega_e_rad_s));
            }
        } else if at_speed && report.ready {
            let reframe = Frame {
                theta: r.gamma,
                omega: w_ol,
                emf: false,
            };
            let r = *r;
            self.enter_handover(cfg, est, &r);
            return Ok(Some(reframe));
        } else if at_speed {
            r.at_speed = r.at_speed.saturating_add(1);
            if r.at_speed >= k.acquire_ticks {
                r.at_speed = 0;
                // The averaged estimate: a noisy sample must not decide a stall.
                let w_avg = report.omega_avg_rad_s;
                if w_avg.abs() < 0.25 * w_ol.abs() {
                    return Err(Stop::Trip(Fault::Stall, w_avg));
                }
                if !reacquire(cfg, r, &mut self.attempts, &mut self.health, reseed) {
                    return Err(Stop::Trip(Fault::ObserverLost, est.omega_e_rad_s));
                }
            }
        } else {
            r.at_speed = 0;
        }
        if self.cmd.stop_requested && r.omega_ol == 0.0 {
            return Err(Stop::Idle);
        }
        Ok(None)
    }
}
