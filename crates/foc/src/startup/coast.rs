//! The coast of `Align` (module docs of [`startup`](super), "Alignment"): after the kick
//! saw motion, a small current vector that turns `COAST_INJECTION_TURNS` times per block
//! (no net torque; its voltage averages out of each block), the loops' voltage averaged
//! over `EMF_BLOCK_S` blocks after `COAST_SETTLE_S` (the back-EMF `e = w psi_f j e^(j th)`).
//!
//! Rules, per complete block (surface motors):
//!
//! - turn `= atan2(e_first x e_last, e_first . e_last)` while both blocks are at least the
//!   back-EMF of half the kick speed (`e_min`), else 0;
//! - stopped when `|e_first| >= e_min` and `|e_last| < e_min / 2` (from the second block);
//! - launch when `|turn| >= COAST_TURN_RAD` (`COAST_TURN_STOPPED_RAD` after a stop), at
//!   least two blocks, and `w_turn = |turn| / t` and `w_mag = (|e_first| + |e_last|) /
//!   (2 psi_f)` agree within `COAST_SPEED_AGREEMENT` (`t`: the time between the blocks);
//! - back to the kick after `COAST_S` without a launch, or at once when stopped.
//!
//! Interior motors integrate the observer's speed for the turn instead, inject nothing and
//! launch from the observer's estimate.

use core::f32::consts::{FRAC_PI_2, PI};

use ekf_core::Estimate;

use super::align::KickFit;
use super::ramp::Ramp;
use super::{
    COAST_SPEED_AGREEMENT, COAST_TURN_RAD, COAST_TURN_STOPPED_RAD, Frame, Inputs, KICK_BOOST_MAX,
    LAUNCH_LEAD_RAD, LAUNCH_SIGMA, Params, Phase, SALIENT_LAUNCH_LEAD_RAD, Seed, Sequencer, State,
    sign,
};
use crate::config::FocConfig;
use crate::pi::limit;
use crate::trig::{atan2, max2, min2, sqrt, wrap};

/// The coast's variables.
#[derive(Clone, Copy, Debug, Default, PartialEq)]
pub(super) struct Coast {
    /// Ticks since the coast began (1 on its first tick).
    ticks: u32,
    /// The unit vector of the injected current, in the alignment's frame.
    pub inj: [f32; 2],
    /// The back-EMF's turn from the first block to the last one, rad el.
    turn: f32,
    /// Sum of the voltage over the current block, V.
    e_sum: [f32; 2],
    /// Samples in the current block.
    e_n: u32,
    /// Mean voltage (the back-EMF) of the first and of the last complete block, V.
    e_first: [f32; 2],
    e_last: [f32; 2],
    /// Complete blocks.
    e_blocks: u32,
    /// The rotor moved and stopped (surface motors).
    stopped: bool,
}

impl Coast {
    /// A coast from its first tick.
    pub fn new() -> Self {
        Self {
            ticks: 1,
            inj: [1.0, 0.0],
            ..Self::default()
        }
    }

    /// The coast's evidence is a rotation (surface motors): the speed the back-EMF's turn
    /// from the first block to the last one gives and the mean speed of the two blocks'
    /// magnitudes agree within [`COAST_SPEED_AGREEMENT`].
    fn consistent(&self, k: &Params, cfg: &FocConfig) -> bool {
        let [f0, f1] = self.e_first;
        let [l0, l1] = self.e_last;
        let w_mag = 0.5 * (sqrt(f0 * f0 + f1 * f1) + sqrt(l0 * l0 + l1 * l1)) * k.inv_psi;
        let t = self.e_blocks.saturating_sub(1) as f32 * k.block_ticks as f32 * cfg.ts_s;
        let w_turn = self.turn.abs();
        // `w_turn / t` and `w_mag` within the factor, without a division.
        w_mag * t <= COAST_SPEED_AGREEMENT * w_turn && w_turn <= COAST_SPEED_AGREEMENT * w_mag * t
    }

    /// The direction of rotation (`+-1`) the back-EMF's turn from the coast's first block
    /// to its last one gives.
    fn emf_direction(&self) -> f32 {
        let [f0, f1] = self.e_first;
        let [l0, l1] = self.e_last;
        if f0 * l1 - f1 * l0 >= 0.0 { 1.0 } else { -1.0 }
    }

    /// Adds this tick's voltage `u` to the block; on a complete block updates the turn
    /// and the stop.
    #[inline(always)]
    fn add_sample(&mut self, k: &Params, u: [f32; 2]) {
        self.e_sum[0] += u[0];
        self.e_sum[1] += u[1];
        self.e_n += 1;
        if self.e_n >= k.block_ticks {
            let n = 1.0 / self.e_n as f32;
            let mean = [self.e_sum[0] * n, self.e_sum[1] * n];
            if self.e_blocks == 0 {
                self.e_first = mean;
            }
            self.e_last = mean;
            self.e_blocks += 1;
            // The back-EMF's turn since the first block, counted while both blocks show
            // at least half the kick speed's back-EMF.
            let [f0, f1] = self.e_first;
            let [l0, l1] = mean;
            let e_min = k.e_min * k.e_min;
            if !k.salient {
                let (e_f, e_l) = (f0 * f0 + f1 * f1, l0 * l0 + l1 * l1);
                self.turn = if e_f >= e_min && e_l >= e_min {
                    atan2(f0 * l1 - f1 * l0, f0 * l0 + f1 * l1)
                } else {
                    0.0
                };
                // A rotor that moved and stopped (friction): the coast cannot see its turn.
                self.stopped = self.e_blocks >= 2 && e_f >= e_min && 4.0 * e_l < e_min;
            }
            self.e_sum = [0.0; 2];
            self.e_n = 0;
        }
    }

    /// The rotor's angle and speed from the last block (surface motors): its d axis 90 deg
    /// behind the back-EMF in the direction of rotation, advanced by half a block and the
    /// tick of the voltage's delay; its speed `|e_last| / psi_f`.
    fn rotor(&self, k: &Params, cfg: &FocConfig) -> (f32, f32) {
        let [l0, l1] = self.e_last;
        let dir = self.emf_direction();
        let w = dir * sqrt(l0 * l0 + l1 * l1) * k.inv_psi;
        let age = (0.5 * k.block_ticks as f32 + 1.0) * cfg.ts_s;
        (wrap(atan2(l1, l0) - dir * FRAC_PI_2 + w * age), w)
    }
}

/// The back-EMF's turn that ends the coast: [`COAST_TURN_RAD`], or on a surface motor after
/// a coast that saw the rotor stop, [`COAST_TURN_STOPPED_RAD`].
fn coast_turn(k: &Params, boost: u8) -> f32 {
    if boost > 0 && !k.salient {
        COAST_TURN_STOPPED_RAD
    } else {
        COAST_TURN_RAD
    }
}

impl Sequencer {
    /// One tick of the coast: the injected vector turns, the back-EMF's blocks accumulate;
    /// the launch into I/f, or back to the kick (a false alarm, or a rotor that stopped).
    #[inline(always)]
    pub(super) fn coast(
        &mut self,
        cfg: &FocConfig,
        input: Inputs<'_>,
        reseed: &mut impl FnMut(Seed),
    ) -> Option<Frame> {
        let Phase::Align(a) = &mut self.phase else {
            return None;
        };
        let Some(c) = &mut a.coast else {
            return None;
        };
        let k = &self.k;
        c.ticks += 1;
        // The injected current turns once per block: its voltage (resistive, inductive,
        // dead time) averages out of every block.
        let [ic, is] = c.inj;
        let [ds, dc] = k.inj_step;
        c.inj = [ic * dc - is * ds, is * dc + ic * ds];
        if c.ticks > k.coast_settle_ticks {
            // The current loops have settled: the voltage is the back-EMF.
            if k.salient {
                c.turn += input.estimate.omega_e_rad_s * cfg.ts_s;
            }
            c.add_sample(k, input.u_ab);
        }
        if c.turn.abs() >= coast_turn(k, a.boost)
            && c.e_blocks >= 2
            && (k.salient || c.consistent(k, cfg))
        {
            let c = *c;
            let reframe = a.frame();
            let target = self.cmd.target_e(&self.k);
            let ramp = if self.k.salient {
                launch_from_observer(&self.k, cfg, &c, input.estimate, target, reseed)
            } else {
                launch(&self.k, cfg, &c, target, reseed)
            };
            self.health.reset(ramp.1);
            self.phase = Phase::OpenLoop(ramp.0);
            self.state = State::OpenLoop;
            return Some(reframe);
        } else if c.ticks > k.coast_ticks || c.stopped {
            // A false alarm (the rotor did not turn): back to the kick. A rotor that
            // stopped is at rest again: the flux detectors stay on, the next detection
            // waits for a faster rotor, and the next coast ends on a shorter turn.
            let stopped = c.stopped;
            if stopped && a.boost < KICK_BOOST_MAX {
                a.boost += 1;
            }
            a.coast = None;
            a.moving = 0;
            a.w_f = 0.0;
            a.fit = KickFit::restart(!stopped);
        }
        None
    }
}

/// I/f from the rotor's motion the coast saw (surface motors): the observer re-seeded at
/// the rotor's state, the vector [`LAUNCH_LEAD_RAD`] ahead of it toward the commanded
/// direction (`target`, rad/s el.), the ramp at the rotor's speed when it turns that way,
/// else at zero, never faster than the hand-over speed. Returns the ramp and the rotor's
/// speed (for the health monitor).
fn launch(
    k: &Params,
    cfg: &FocConfig,
    c: &Coast,
    target: f32,
    reseed: &mut impl FnMut(Seed),
) -> (Ramp, f32) {
    let (th, w) = c.rotor(k, cfg);
    reseed(Seed {
        theta: th,
        omega: w,
        sigma_theta: LAUNCH_SIGMA,
    });
    let fwd = sign(target);
    let omega_ol = fwd * min2(max2(w * fwd, 0.0), k.handover);
    let gamma = wrap(th + LAUNCH_LEAD_RAD * fwd);
    (Ramp::launched(cfg, gamma, omega_ol, sign(omega_ol)), w)
}

/// The launch of an interior motor: from the observer's estimate, moved to the other
/// branch (angle + pi, speed - w) when it lies more than 90 deg from the rotor angle the
/// back-EMF's turn gives.
fn launch_from_observer(
    k: &Params,
    cfg: &FocConfig,
    c: &Coast,
    est: &Estimate<f32>,
    target: f32,
    reseed: &mut impl FnMut(Seed),
) -> (Ramp, f32) {
    let (mut th, mut w) = (est.theta_rad, est.omega_e_rad_s);
    let [l0, l1] = c.e_last;
    let th_emf = wrap(atan2(l1, l0) - c.emf_direction() * FRAC_PI_2);
    if wrap(th - th_emf).abs() > FRAC_PI_2 {
        th = wrap(th + PI);
        w = -w;
        reseed(Seed {
            theta: th,
            omega: w,
            sigma_theta: LAUNCH_SIGMA,
        });
    }
    let gamma = wrap(th + SALIENT_LAUNCH_LEAD_RAD * sign(target));
    let omega_ol = limit(w, -k.handover, k.handover);
    (Ramp::launched(cfg, gamma, omega_ol, sign(w)), w)
}
