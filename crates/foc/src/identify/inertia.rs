//! Step [`IdentifyStep::Inertia`](super::IdentifyStep::Inertia): `J` from a least-squares fit
//! of the rotor's trajectory while the I/f frame speeds up by 40 % and back.

use crate::transforms::AlphaBeta;

use super::context::{Context, Saturation, Tick};
use super::if_drive::{IfDrive, Move, load_angle, rotor_current, torque};
use super::lsq::Lsq;
use super::outcome::{IdentifyError, Quantity};

/// The half of the move.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
enum Half {
    /// From the spin speed `w0` up to `1.4 w0`.
    Up,
    /// Back down to `w0` at the same rate.
    Down,
}

/// The inertia move in progress.
#[derive(Clone, Copy, Debug)]
pub(super) struct Inertia {
    half: Half,
    /// Ticks in the half.
    n: u32,
    /// The spin's drive, with the move's speed profile.
    drive: IfDrive,
    fit: InertiaFit,
}

impl Inertia {
    /// Takes over the spin's current loops (`drive`) at the spin speed: the move up by
    /// `0.4 w0` at `spin_accel_rad_s2`, the fit over both halves.
    #[inline]
    pub(super) fn new(ctx: &Context, drive: IfDrive) -> Self {
        let cfg = &ctx.cfg;
        let ts = cfg.ts_s;
        let w0 = cfg.spin_speed_rad_s;
        let mv = Move::new(0.4 * w0, cfg.spin_accel_rad_s2, ts);
        let torque_max =
            1.5 * cfg.pole_pairs as f32 * ctx.found.psi.unwrap_or(0.0) * cfg.spin_current_a;
        Self {
            half: Half::Up,
            n: 0,
            drive: IfDrive {
                mv,
                sat: Saturation::default(),
                ..drive
            },
            fit: InertiaFit::new(w0, 2 * mv.len(), cfg.pole_pairs, ts, torque_max),
        }
    }

    /// One tick of the I/f drive; the rotor's load angle and torque feed the fit; at the end
    /// of the move `J` (refused unless in `(0, 1e4)` kg m^2).
    #[inline]
    pub(super) fn step(
        &mut self,
        ctx: &mut Context,
        i_ab: AlphaBeta,
    ) -> Result<Tick, IdentifyError> {
        self.n = self.n.saturating_add(1);
        let ts = ctx.cfg.ts_s;
        let k = self.n - 1;
        let t = self.drive.step(ctx, i_ab, k, true)?;
        let g = load_angle(t.e);
        let torque = torque(ctx, ctx.found.psi.unwrap_or(0.0), rotor_current(t.i, g));
        self.fit.push(g, torque, t.w - self.fit.w0);
        let mut done = false;
        if k + 1 >= self.drive.mv.len() {
            if self.half == Half::Up {
                self.drive.mv = Move::new(
                    -0.4 * ctx.cfg.spin_speed_rad_s,
                    ctx.cfg.spin_accel_rad_s2,
                    ts,
                );
                self.half = Half::Down;
                self.n = 0;
            } else {
                let j = self.fit.inertia().unwrap_or(f32::NAN);
                if !(j.is_finite() && j > 0.0 && j < 1e4) {
                    return Err(IdentifyError::Implausible {
                        quantity: Quantity::Inertia,
                        value: j,
                    });
                }
                ctx.found.j = Some(j);
                done = true;
            }
        }
        ctx.frame.set(ctx.frame.angle + t.w * ts);
        Ok(Tick::then(Some(t.u), done))
    }
}

/// The inertia from the rotor's trajectory during the speed move (module docs, step
/// [`IdentifyStep::Inertia`](super::IdentifyStep::Inertia)).
///
/// The rotor's mechanical angle is the frame's minus the load angle, `theta = (phi - g) / p`,
/// and obeys `J theta'' = T - B theta' - T_c` with the torque `T` from the load angle and
/// the current. Integrated twice from the start of the move:
///
/// `y(t) = c0 + c1 s + c2 s^2 + S(t) / J - (B / J) Y(t)`,
///
/// with `y = theta - w0 t / p` (the angle beyond the initial frame speed `w0`), `s = t / T`
/// (`T` the window), `S` the double integral of `T`, `Y` the integral of `y`, and `c0`, `c1`,
/// `c2` the unknown initial angle, speed and constant friction (`T_c` and `B w0`). Fitted by
/// least squares over every tick of the move, the lightly damped oscillation of the rotor
/// about the I/f frame is part of the model, not an error to be averaged away (as it would be
/// by averaging the torque over segments shorter than its period). The load-angle noise
/// enters only `y` (the fitted variable) and, integrated, `S` and `Y`.
#[derive(Clone, Copy, Debug, PartialEq)]
struct InertiaFit {
    /// Frame speed at the start, rad/s electrical.
    w0: f32,
    /// Ticks in the window.
    len: u32,
    /// Ticks so far.
    k: u32,
    ts: f32,
    /// `1 / p`.
    inv_p: f32,
    /// Scale of `S`: `1 / (T_max T^2)`.
    s_scale: f32,
    /// Frame angle beyond `w0 t`, rad electrical.
    dphi: f32,
    /// Integral of the torque, N m s.
    torque_int: f32,
    /// Double integral of the torque, N m s^2.
    torque_int2: f32,
    /// Sum of `y` (rad).
    y_sum: f32,
    lsq: Lsq<5>,
}

impl InertiaFit {
    /// A fit over `len` ticks from the frame speed `w0`; `torque_max` scales the torque
    /// integral (the fit does not depend on it, its conditioning does).
    fn new(w0: f32, len: u32, pole_pairs: u32, ts: f32, torque_max: f32) -> Self {
        let t = len.max(1) as f32 * ts;
        let s_scale = 1.0 / (torque_max * t * t);
        Self {
            w0,
            len: len.max(1),
            k: 0,
            ts,
            inv_p: 1.0 / pole_pairs.max(1) as f32,
            s_scale: if s_scale.is_finite() { s_scale } else { 1.0 },
            dphi: 0.0,
            torque_int: 0.0,
            torque_int2: 0.0,
            y_sum: 0.0,
            lsq: Lsq::new(),
        }
    }

    /// One tick: load angle `g` (rad), torque (N m), and the frame speed of this tick minus
    /// `w0` (rad/s electrical; the frame turns by it after the tick).
    #[inline]
    fn push(&mut self, g: f32, torque: f32, dw: f32) {
        let y = (self.dphi - g) * self.inv_p;
        let s = self.k as f32 / self.len as f32;
        let x = [
            1.0,
            s,
            s * s,
            self.torque_int2 * self.s_scale,
            self.y_sum / self.len as f32,
        ];
        self.lsq.add(x, y);
        self.k += 1;
        self.dphi += dw * self.ts;
        self.torque_int2 += self.torque_int * self.ts;
        self.torque_int += torque * self.ts;
        self.y_sum += y;
    }

    /// `J`, kg m^2 (`None` when the fit is singular).
    fn inertia(&self) -> Option<f32> {
        let beta = self.lsq.solve()?;
        let b = *beta.get(3)?;
        Some(1.0 / (b * self.s_scale))
    }
}
