//! The coast of the flux-map step: `psi_d(0, 0)`, the rotor's speed and its d axis from the
//! EMF, with a square wave of current along the turning frame.
//!
//! # Method
//!
//! Where the sequence ends, the frame turns at the spin speed `w` and the rotor turns near it
//! (the I/f drive leaves it swinging about the frame: on pmsm-sim's interior PM motor 5 %
//! slower when the current is released). After [`SETTLE_S`] at zero current (the spin
//! current decays), the current loops hold `i_d = +I, -I, +I, ...` along the frame, `i_q = 0`,
//! the sign changing each time the frame has turned by `pi/3` (`I` = [`CURRENT`] x the test
//! current). Over one such cycle (`2 pi/3` of the frame) the mean frame voltage is
//!
//! ```text
//! E_k = (mean over the + half + mean over the - half) / 2 = j w_r (psi(+I) + psi(-I)) / 2
//! ```
//!
//! because everything odd in the current cancels between the halves: `Rs i`, the loops'
//! cross-coupling, `L di/dt` of the mirror-image transitions, and the inverter's dead-time
//! voltage. That voltage opposes the current; over a whole sector (`pi/3` of the current's
//! angle, the period of its 6th harmonic in the frame) its mean along a current of fixed
//! direction is a constant, so the `+I` and `-I` halves carry opposite ones. At zero current it
//! is not defined: the loops settle on a current of a few tens
//! of mA whose direction decides the phases' signs, and the bridge then loses the full
//! dead-time voltage along it (5.8 V in a 55 V EMF on the interior PM motor with 1 us, its
//! `psi_f` 7 % high).
//!
//! `(psi(+I) + psi(-I)) / 2` is `psi(0)` up to the curvature of `psi_d(i_d)`: `psi_d'' I^2/2`,
//! -0.6 mWb (0.1 %) on the interior PM motor. It holds for any angle of the current to the
//! rotor's d axis (the frame is not on it during the acquisition), as does the cancellation of the torque
//! `3/2 p psi_f I sin g`, which alternates with the current.
//!
//! The rotor slips against the frame at `s = w_r - w`: the angles `phi_k` of the cycles'
//! `E_k` grow by `s T_c` a cycle (`T_c = (2 pi/3) / |w|`); `s` is the slope of a straight
//! line fitted to them. After [`ACQUIRE_CYCLES`] cycles the frame is put on the rotor's d
//! axis (the fitted angle at the end, less `pi/2`) and at its speed `w + s`, the loops'
//! integrators turned with it; one cycle settles; then the measured cycles (at least
//! [`MIN_CYCLES`] and [`MEASURE_S`], at most [`MAX_CYCLES`]), with their own line:
//!
//! ```text
//! psi_d(0, 0) = mean_k |E_k| / (|w + s| sinc(s T_c / 2)) - L i_k along the rotor's d axis
//! ```
//!
//! (`sinc` undoes the cycle's averaging of a vector turning at `s`; the last term the flux of
//! the cycles' mean current `i_k`, with the identified `Ld`, `Lq`). The rotor's d axis at the
//! end is the fitted angle half a cycle after the last cycle, less `pi/2`. The first cycle
//! (the current rising from zero) is not used.
//!
//! Why the frame is put on the rotor: while it slips, the EMF's d component in the frame
//! ramps, and the d loop follows a ramp with a constant error (40 mA on the interior PM
//! motor, whose flux `Ld i` does not cancel). The d loop's feed-forward carries the square
//! wave's odd voltage `+-(Rs I + 3/pi U_err)` (`U_err` the resistance step's voltage error
//! along a phase axis, `3/pi` of it the dead-time voltage's mean along a turning current), so
//! the integrator need not swing with it at each change of sign.

use core::f32::consts::{FRAC_PI_2, FRAC_PI_3, PI};

use crate::transforms::AlphaBeta;
use crate::trig::{atan2, sin_cos, sqrt, wrap};

use super::context::Context;
use super::if_drive::IfDrive;
use super::numeric::ticks;
use super::outcome::{IdentifyError, Quantity};

/// Settling of the released spin current at zero current, s.
pub(super) const SETTLE_S: f32 = 0.02;
/// Time of the measured cycles (at least), s.
pub(super) const MEASURE_S: f32 = 0.06;
/// The square wave's current, a fraction of the test current.
pub(super) const CURRENT: f32 = 0.15;
/// Cycles of the acquisition (the frame is then put on the rotor).
pub(super) const ACQUIRE_CYCLES: u32 = 2;
/// Fewest measured cycles.
pub(super) const MIN_CYCLES: u32 = 2;
/// Most measured cycles.
pub(super) const MAX_CYCLES: u32 = 16;

/// What the coast measured.
#[derive(Clone, Copy, Debug, PartialEq)]
pub(super) struct CoastResult {
    /// `psi_d(0, 0)`, Wb.
    pub(super) psi_wb: f32,
    /// The rotor's electrical speed, rad/s.
    pub(super) w_r: f32,
    /// The rotor's d axis less the frame's angle at the end, rad.
    pub(super) delta: f32,
}

/// The cycles' EMF: a straight line through their angles, their mean magnitude.
#[derive(Clone, Copy, Debug, Default)]
struct Cycles {
    /// The first cycle's `E` (the angles' reference) and the last one's.
    e_ref: [f32; 2],
    e_last: [f32; 2],
    /// Unwrapped angle of the last cycle's `E` from `e_ref`, rad.
    phi: f32,
    /// Sums over the cycles `x = 1..n`: `x`, `phi`, `x phi`, `x^2` (the line), `|E|`, the
    /// flux of the mean current along the rotor's d axis.
    s: [f32; 6],
    n: u32,
}

/// The line's slope (per cycle) and its value half a cycle after the last one: the slip
/// and the angle of `E` at the end.
#[derive(Clone, Copy, Debug)]
struct Line {
    slope: f32,
    arg_end: f32,
}

impl Cycles {
    /// Adds a cycle's mean voltage `e` and current `i` (frame), with the frame's speed `w`
    /// and the inductances `l` = `(Ld, Lq)`.
    fn add(&mut self, e: [f32; 2], i: [f32; 2], w: f32, l: (f32, f32)) {
        self.n += 1;
        if self.n == 1 {
            self.e_ref = e;
        } else {
            let p = self.e_last;
            self.phi += atan2(p[0] * e[1] - p[1] * e[0], p[0] * e[0] + p[1] * e[1]);
        }
        self.e_last = e;
        let x = self.n as f32;
        let mag = sqrt(e[0] * e[0] + e[1] * e[1]);
        let s = &mut self.s;
        s[0] += x;
        s[1] += self.phi;
        s[2] += x * self.phi;
        s[3] += x * x;
        s[4] += mag;
        // The flux of the mean current along the rotor's d axis, the direction of `E / (j w)`.
        if mag > 0.0 {
            let sg = if w < 0.0 { -1.0 } else { 1.0 };
            s[5] += sg * (l.0 * i[0] * e[1] - l.1 * i[1] * e[0]) / mag;
        }
    }

    fn line(&self) -> Line {
        let [sx, sp, sxp, sxx, ..] = self.s;
        let n = self.n as f32;
        let den = n * sxx - sx * sx;
        let slope = if den > 0.0 {
            (n * sxp - sx * sp) / den
        } else {
            0.0
        };
        let phi_end = (sp - slope * sx) / n + slope * (n + 0.5);
        Line {
            slope,
            arg_end: atan2(self.e_ref[1], self.e_ref[0]) + phi_end,
        }
    }
}

/// The rotor's d axis less the frame's angle, from the angle of `E` (`arg E = delta + pi/2`
/// when turning forward).
fn delta_of(arg_e: f32, w_r: f32) -> f32 {
    wrap(arg_e - if w_r < 0.0 { -FRAC_PI_2 } else { FRAC_PI_2 })
}

/// The coast in progress (module docs).
#[derive(Clone, Copy, Debug)]
pub(super) struct Coast {
    /// The current loops (the spin's gains).
    pub(super) drive: IfDrive,
    /// Ticks so far.
    pub(super) n: u32,
    /// The square wave's sign (0 while settling).
    sign: f32,
    /// Frame angle turned in the present half, rad.
    phase: f32,
    /// Halves completed.
    halves: u32,
    /// Sums and count of the present half's voltage and current.
    half_sum: [f32; 4],
    half_n: u32,
    /// Mean voltage and current of the present cycle's first half.
    first: [f32; 4],
    /// The cycles of the acquisition or the measurement.
    cycles: Cycles,
    /// Measured cycles wanted.
    want: u32,
}

impl Coast {
    /// A coast with the loops `drive` at the frame speed `w`, rad/s.
    pub(super) fn new(drive: IfDrive, w: f32) -> Self {
        let t_c = 2.0 * FRAC_PI_3 / w.abs().max(1e-3);
        let want = ceil(MEASURE_S / t_c).clamp(MIN_CYCLES as f32, MAX_CYCLES as f32) as u32;
        Self {
            drive,
            n: 0,
            sign: 0.0,
            phase: 0.0,
            halves: 0,
            half_sum: [0.0; 4],
            half_n: 0,
            first: [0.0; 4],
            cycles: Cycles::default(),
            want,
        }
    }

    /// One tick: the voltage to apply and, at the end, the result. Turns the frame by its
    /// speed times `Ts` (and once onto the rotor).
    pub(super) fn tick(
        &mut self,
        ctx: &mut Context,
        i_ab: AlphaBeta,
    ) -> Result<(AlphaBeta, Option<CoastResult>), IdentifyError> {
        let (f, cfg) = (ctx.found, ctx.cfg);
        let ts = cfg.ts_s;
        self.n += 1;
        let (i_d, i_q) = ctx.frame.dq(i_ab);
        let (w, lim) = (ctx.frame.omega, ctx.u_lim);
        let i_ref = self.sign * CURRENT * cfg.test_current_a;
        // The square wave's odd voltage as feed-forward: `Rs I` and the dead-time voltage's
        // fundamental along the current (3/pi of the voltage error measured along a phase).
        let ff_odd = self.sign * (f.rs * CURRENT * cfg.test_current_a + 3.0 / PI * f.v_err);
        let u_d = self
            .drive
            .pi_d
            .step(i_ref - i_d, ff_odd - w * f.lq * i_q, -lim, lim);
        let u_q_lim = sqrt((lim * lim - u_d * u_d).max(0.0));
        let u_q = self
            .drive
            .pi_q
            .step(-i_q, w * f.ld * i_d, -u_q_lim, u_q_lim);
        // The voltage acts over [t_k+d, t_k+d+1): rotated to the middle of that interval.
        let adv = (ctx.d as f32 + 0.5) * w * ts;
        let (sa, ca) = sin_cos(ctx.frame.angle + adv);
        let u = AlphaBeta {
            alpha: ca * u_d - sa * u_q,
            beta: sa * u_d + ca * u_q,
        };
        ctx.frame.set(ctx.frame.angle + w * ts);
        if self.sign == 0.0 {
            if self.n >= ticks(SETTLE_S, ts) {
                self.sign = 1.0;
            }
            return Ok((u, None));
        }
        let h = &mut self.half_sum;
        h[0] += u_d - f.rs * i_d;
        h[1] += u_q - f.rs * i_q;
        h[2] += i_d;
        h[3] += i_q;
        self.half_n += 1;
        self.phase += w.abs() * ts;
        if self.phase < FRAC_PI_3 {
            return Ok((u, None));
        }
        // A half is complete.
        self.phase -= FRAC_PI_3;
        self.sign = -self.sign;
        let m = self.half_n as f32;
        let mean = self.half_sum.map(|x| x / m);
        self.half_sum = [0.0; 4];
        self.half_n = 0;
        self.halves += 1;
        if self.halves % 2 == 1 {
            self.first = mean;
            return Ok((u, None));
        }
        // A cycle is complete. The first (the current rising from zero) and the one after the
        // frame is put on the rotor are not used.
        let cycle = self.halves / 2;
        let skip = ACQUIRE_CYCLES + 2;
        if cycle == 1 || cycle == skip {
            return Ok((u, None));
        }
        let avg = |a: usize| 0.5 * (self.first[a] + mean[a]);
        self.cycles
            .add([avg(0), avg(1)], [avg(2), avg(3)], w, (f.ld, f.lq));
        if cycle == ACQUIRE_CYCLES + 1 {
            // The frame onto the rotor's d axis, at its speed; the loops' integrators turned
            // with it.
            let line = self.cycles.line();
            let w_r = w + line.slope / (2.0 * FRAC_PI_3 / w.abs());
            let delta = delta_of(line.arg_end, w_r);
            ctx.frame.set(ctx.frame.angle + delta);
            ctx.frame.omega = w_r;
            let (s, c) = sin_cos(delta);
            let (a, b) = (self.drive.pi_d.integrator(), self.drive.pi_q.integrator());
            self.drive.pi_d.set_integrator(c * a + s * b);
            self.drive.pi_q.set_integrator(-s * a + c * b);
            self.cycles = Cycles::default();
            return Ok((u, None));
        }
        if self.cycles.n < self.want {
            return Ok((u, None));
        }
        Ok((u, Some(self.result(w)?)))
    }

    /// The slip, the speed, `psi` and the d axis (module docs).
    fn result(&self, w: f32) -> Result<CoastResult, IdentifyError> {
        let c = &self.cycles;
        let n = c.n as f32;
        let line = c.line();
        let t_c = 2.0 * FRAC_PI_3 / w.abs();
        let w_r = w + line.slope / t_c;
        let half = 0.5 * line.slope;
        let sinc = if half.abs() > 1e-6 {
            sin_cos(half).0 / half
        } else {
            1.0
        };
        let raw = c.s[4] / n / (w_r.abs() * sinc);
        let psi = raw - c.s[5] / n;
        if !(psi.is_finite() && psi > 1e-5 && psi < 50.0 && w_r * w > 0.0) {
            return Err(IdentifyError::Implausible {
                quantity: Quantity::FluxLinkage,
                value: psi,
            });
        }
        Ok(CoastResult {
            psi_wb: psi,
            w_r,
            delta: delta_of(line.arg_end, w_r),
        })
    }

    /// An upper bound of the coast's ticks at the frame speed `w`.
    pub(super) fn max_ticks(w: f32, ts: f32) -> u32 {
        let t_c = 2.0 * PI / 3.0 / w.abs().max(1e-3);
        ticks(
            SETTLE_S + (MAX_CYCLES + ACQUIRE_CYCLES + 2) as f32 * t_c,
            ts,
        )
    }
}

/// `ceil` of the small positive values here.
fn ceil(x: f32) -> f32 {
    let t = x as u32 as f32;
    if t < x { t + 1.0 } else { t }
}

#[cfg(test)]
mod tests {
    use super::*;

    /// EMF vectors turning by a fixed slip a cycle, of magnitude 50 V: the line gives the
    /// slip and the angle half a cycle after the last, across the wrap at pi; the flux of
    /// the mean current adds `Ld i_d` along the rotor's d axis.
    #[test]
    fn the_cycles_line_gives_the_slip_and_the_end_angle() {
        let (slip, start) = (-0.11f32, -3.0f32);
        let mut c = Cycles::default();
        for k in 0..5 {
            let (s, co) = sin_cos(start + slip * k as f32);
            c.add([50.0 * co, 50.0 * s], [0.0, 0.0], 100.0, (0.02, 0.04));
        }
        let l = c.line();
        assert!((l.slope - slip).abs() < 1e-5, "{l:?}");
        let want = wrap(start + slip * 4.5);
        assert!(wrap(l.arg_end - want).abs() < 1e-5, "{l:?}");
        assert!((c.s[4] / 5.0 - 50.0).abs() < 1e-3);
        // The rotor's d axis is pi/2 behind E turning forward: a current of 1 A along the
        // frame's d axis with E on the frame's q axis is all along the rotor's d axis.
        let mut c = Cycles::default();
        c.add([0.0, 50.0], [1.0, 0.0], 100.0, (0.02, 0.04));
        assert!((c.s[5] - 0.02).abs() < 1e-7, "{:?}", c.s);
        assert!(delta_of(FRAC_PI_2, 100.0).abs() < 1e-7);
        assert!(delta_of(-FRAC_PI_2, -100.0).abs() < 1e-7);
    }
}
