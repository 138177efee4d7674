//! The I/f drive of the spin and the inertia move: the test current held along a frame that
//! turns with a jerk-limited speed profile, and what the frame's voltage says about the rotor
//! (the active-flux EMF, the load angle, the torque).

use core::f32::consts::{FRAC_PI_2, PI};

use crate::pi::Pi;
use crate::transforms::AlphaBeta;
use crate::trig::{atan2, sin_cos, sqrt, wrap};

use super::context::{Context, Saturation};
use super::numeric::ticks;
use super::outcome::IdentifyError;

/// A jerk-limited speed move: acceleration rises over `nj` ticks, holds `nc`, falls over
/// `nj`.
#[derive(Clone, Copy, Debug, Default, PartialEq)]
pub(super) struct Move {
    nj: u32,
    nc: u32,
    accel: f32,
}

impl Move {
    pub(super) fn new(delta_w: f32, accel: f32, ts: f32) -> Self {
        let a = if delta_w < 0.0 { -accel } else { accel };
        // Total speed change = a (nc + nj) ts; nj about 20 % of the move.
        let total = ticks(delta_w / a, ts).max(2);
        let nj = (total / 5).max(1);
        let nc = total - nj;
        // Re-scale so the change is exact.
        let accel = delta_w / ((nc + nj) as f32 * ts);
        Self { nj, nc, accel }
    }

    #[inline]
    pub(super) fn len(&self) -> u32 {
        2 * self.nj + self.nc
    }

    /// Acceleration during tick `n` of the move.
    #[inline]
    pub(super) fn accel_at(&self, n: u32) -> f32 {
        let nj = self.nj as f32;
        if n < self.nj {
            self.accel * (n as f32 + 0.5) / nj
        } else if n < self.nj + self.nc {
            self.accel
        } else if n < self.len() {
            self.accel * ((self.len() - n) as f32 - 0.5) / nj
        } else {
            0.0
        }
    }
}

/// The current loops of the turning frame and its speed profile.
#[derive(Clone, Copy, Debug)]
pub(super) struct IfDrive {
    /// d-axis PI (holds `spin_current_a`).
    pub(super) pi_d: Pi,
    /// q-axis PI (holds zero).
    pub(super) pi_q: Pi,
    /// The speed move in progress.
    pub(super) mv: Move,
    /// Saturation count of the q loop.
    pub(super) sat: Saturation,
}

/// One tick of the drive: the voltage, what it says and the frame speed.
#[derive(Clone, Copy, Debug)]
pub(super) struct DriveTick {
    /// Voltage to apply, alpha-beta, V.
    pub(super) u: AlphaBeta,
    /// Active-flux EMF in the frame, V.
    pub(super) e: (f32, f32),
    /// Current in the frame `(i_d, i_q)`, A.
    pub(super) i: (f32, f32),
    /// The frame's speed this tick, rad/s electrical.
    pub(super) w: f32,
}

impl IfDrive {
    /// One tick `k` of the move (the frame accelerates when `moving`): the current loops
    /// with cross-coupling feed-forward, the q voltage within what the d loop leaves of the
    /// circle, the voltage rotated to the middle of the interval it acts over.
    #[inline(always)]
    pub(super) fn step(
        &mut self,
        ctx: &mut Context,
        i_ab: AlphaBeta,
        k: u32,
        moving: bool,
    ) -> Result<DriveTick, IdentifyError> {
        let ts = ctx.cfg.ts_s;
        let i_f = ctx.cfg.spin_current_a;
        if moving {
            ctx.frame.omega += self.mv.accel_at(k) * ts;
        }
        let (i_d, i_q) = ctx.frame.dq(i_ab);
        let lim = ctx.u_lim;
        let w = ctx.frame.omega;
        let ff_d = -w * ctx.found.lq * i_q;
        let ff_q = w * ctx.found.ld * i_d;
        let u_d = self.pi_d.step(i_f - i_d, ff_d, -lim, lim);
        let u_q_lim = sqrt((lim * lim - u_d * u_d).max(0.0));
        let u_q = self.pi_q.step(-i_q, ff_q, -u_q_lim, u_q_lim);
        self.sat.check(
            ctx,
            u_q.abs() >= 0.999 * u_q_lim,
            sqrt(i_d * i_d + i_q * i_q),
            i_f,
        )?;
        // The voltage acts over [t_k+d, t_k+d+1): rotate it to the middle of that interval.
        let adv = (ctx.d as f32 + 0.5) * w * ts;
        let (sa, ca) = sin_cos(ctx.frame.angle + adv);
        let u = AlphaBeta {
            alpha: ca * u_d - sa * u_q,
            beta: sa * u_d + ca * u_q,
        };
        let e = emf(ctx, (u_d, u_q), (i_d, i_q));
        Ok(DriveTick {
            u,
            e,
            i: (i_d, i_q),
            w,
        })
    }
}

/// The active-flux EMF `E = u - (Rs + j w Lq) i - dead-time voltage` in the frame.
#[inline]
fn emf(ctx: &Context, u: (f32, f32), i: (f32, f32)) -> (f32, f32) {
    let f = &ctx.found;
    let omega = ctx.frame.omega;
    let imag = sqrt(i.0 * i.0 + i.1 * i.1).max(1e-6);
    // The bridge loses the dead-time voltage along the current (the command includes
    // it): its fundamental is 3/pi of the DC value measured along a phase axis.
    let k = 3.0 / PI * f.v_err / imag;
    (
        u.0 - f.rs * i.0 + omega * f.lq * i.1 - k * i.0,
        u.1 - f.rs * i.1 - omega * f.lq * i.0 - k * i.1,
    )
}

/// Load angle (frame ahead of the rotor) of an EMF in the frame: `pi/2 - arg E`.
#[inline]
pub(super) fn load_angle(e: (f32, f32)) -> f32 {
    wrap(FRAC_PI_2 - atan2(e.1, e.0))
}

/// Rotor-frame `(i_d, i_q)` of a frame current with the load angle `g`.
#[inline]
pub(super) fn rotor_current(i: (f32, f32), g: f32) -> (f32, f32) {
    let (s, c) = sin_cos(g);
    (i.0 * c - i.1 * s, i.0 * s + i.1 * c)
}

/// Torque `1.5 p (psi + (Ld - Lq) i_d) i_q`, N m.
#[inline]
pub(super) fn torque(ctx: &Context, psi: f32, i_r: (f32, f32)) -> f32 {
    1.5 * ctx.cfg.pole_pairs as f32 * (psi + (ctx.found.ld - ctx.found.lq) * i_r.0) * i_r.1
}
