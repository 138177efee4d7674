//! Step [`IdentifyStep::Spin`](super::IdentifyStep::Spin): `psi_f` from the back-EMF of an
//! I/f spin at `spin_speed_rad_s`.

use crate::pi::{Pi, PiGains};
use crate::transforms::AlphaBeta;
use crate::trig::{sqrt, wrap};

use super::context::{Context, Saturation, Tick};
use super::if_drive::{IfDrive, Move, load_angle, rotor_current};
use super::inertia::Inertia;
use super::numeric::{Sums, ticks};
use super::outcome::{IdentifyError, Quantity};

/// The part of the spin.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
enum Part {
    /// The frame accelerates to the spin speed.
    Ramp,
    /// At the spin speed, `spin_settle_time_s`.
    Settle,
    /// At the spin speed, averaged over `spin_measure_time_s`.
    Measure,
}

/// The spin in progress.
#[derive(Clone, Copy, Debug)]
pub(super) struct Spin {
    part: Part,
    /// Ticks in the part.
    n: u32,
    drive: IfDrive,
    /// Sums of `(E_d, E_q, i_d, i_q)` over each quarter of the window.
    quarter: [Sums; 4],
    /// Sums of the load angle over the first and the last [`drift_ticks`] of the window,
    /// rad.
    g_ends: [f32; 2],
}

impl Spin {
    /// The spin with the measured parameters, or `None` when no spin is configured. Current
    /// loops by pole-zero cancellation (`Kp = L bw`, `Ki = Rs bw`), the d integrator preset
    /// to the resistive and inverter voltage at the spin current; the frame at rest.
    #[inline]
    pub(super) fn new(ctx: &mut Context) -> Option<Self> {
        let cfg = &ctx.cfg;
        if cfg.spin_speed_rad_s <= 0.0 {
            return None;
        }
        let f = &ctx.found;
        let bw = cfg.current_bw_rad_s;
        let ki = f.rs * bw;
        let mut pi_d = Pi::new(PiGains { kp: f.ld * bw, ki }, cfg.ts_s);
        let mut pi_q = Pi::new(PiGains { kp: f.lq * bw, ki }, cfg.ts_s);
        let i_f = cfg.spin_current_a;
        pi_d.preset_output(f.rs * i_f + f.v_err * i_f / cfg.test_current_a, 0.0, 0.0);
        pi_q.set_integrator(0.0);
        let mv = Move::new(cfg.spin_speed_rad_s, cfg.spin_accel_rad_s2, cfg.ts_s);
        ctx.frame.omega = 0.0;
        Some(Self {
            part: Part::Ramp,
            n: 0,
            drive: IfDrive {
                pi_d,
                pi_q,
                mv,
                sat: Saturation::default(),
            },
            quarter: [Sums::default(); 4],
            g_ends: [0.0; 2],
        })
    }

    /// One tick of the I/f drive; the window's EMF and currents are summed per quarter, the
    /// load angle at both ends; at the window's end [`flux`](Self::flux).
    #[inline]
    pub(super) fn step(
        &mut self,
        ctx: &mut Context,
        i_ab: AlphaBeta,
    ) -> Result<Tick, IdentifyError> {
        self.n = self.n.saturating_add(1);
        let ts = ctx.cfg.ts_s;
        // Frame speed for this tick.
        let k = self.n - 1;
        let t = self.drive.step(ctx, i_ab, k, self.part == Part::Ramp)?;
        let (e, (i_d, i_q)) = (t.e, t.i);
        let mut done = false;
        match self.part {
            Part::Ramp if k + 1 >= self.drive.mv.len() => {
                ctx.frame.omega = ctx.cfg.spin_speed_rad_s;
                self.part = Part::Settle;
                self.n = 0;
            }
            Part::Ramp => {}
            Part::Settle if self.n >= ticks(ctx.cfg.spin_settle_time_s, ts) => {
                self.part = Part::Measure;
                self.n = 0;
                self.quarter = [Sums::default(); 4];
                self.g_ends = [0.0; 2];
            }
            Part::Settle => {}
            Part::Measure => {
                let len = ticks(ctx.cfg.spin_measure_time_s, ts);
                let qi = ((k * 4) / len).min(3) as usize;
                if let Some(s) = self.quarter.get_mut(qi) {
                    s.add([e.0, e.1, i_d, i_q]);
                }
                let m = drift_ticks(len);
                if k < m {
                    self.g_ends[0] += load_angle(e);
                } else if k >= len - m {
                    self.g_ends[1] += load_angle(e);
                }
                if self.n >= len {
                    self.flux(ctx)?;
                    done = true;
                }
            }
        }
        ctx.frame.set(ctx.frame.angle + t.w * ts);
        Ok(Tick::then(Some(t.u), done))
    }

    /// What follows: the inertia move with this drive, when configured (else the end).
    #[inline]
    pub(super) fn next(&self, ctx: &Context) -> Option<Inertia> {
        if ctx.cfg.measure_inertia {
            Some(Inertia::new(ctx, self.drive))
        } else {
            None
        }
    }

    /// `psi_f` from the window (module docs): the mean EMF must exceed 10 % of the
    /// resistive and inductive drop (else the rotor is locked), its load angle stay within
    /// 1.3 rad, and each quarter agree with the mean within 25 % and 0.35 rad (else the
    /// rotor slipped). `psi_f = |E| / w_rotor - (Ld - Lq) i_d`.
    fn flux(&self, ctx: &mut Context) -> Result<(), IdentifyError> {
        let mut all = Sums::default();
        for q in &self.quarter {
            all.n += q.n;
            for (a, b) in all.s.iter_mut().zip(q.s) {
                *a += b;
            }
        }
        let m = all.mean();
        let e = (m[0], m[1]);
        let e_mag = sqrt(e.0 * e.0 + e.1 * e.1);
        let w = ctx.cfg.spin_speed_rad_s;
        let i_f = ctx.cfg.spin_current_a;
        let f = &ctx.found;
        let floor = 0.1 * (f.rs * i_f + w * f.ld.max(f.lq) * i_f);
        if e_mag.is_nan() || e_mag <= floor {
            return Err(IdentifyError::RotorLocked { emf_v: e_mag });
        }
        let g = load_angle(e);
        if g.is_nan() || g.abs() >= 1.3 {
            return Err(IdentifyError::LostSync { load_angle_rad: g });
        }
        // Each quarter of the window must see the same EMF (a rotor that slips or jams
        // does not).
        for q in &self.quarter {
            let [a, b, ..] = q.mean();
            let mag = sqrt(a * a + b * b);
            let gq = load_angle((a, b));
            if !((mag - e_mag).abs() < 0.25 * e_mag && wrap(gq - g).abs() < 0.35) {
                return Err(IdentifyError::LostSync { load_angle_rad: gq });
            }
        }
        let i_r = rotor_current((m[2], m[3]), g);
        // The rotor swings about the frame (lightly damped): over the window it turns by the
        // frame's angle minus the change of the load angle, so its mean speed is not the
        // frame's. The EMF is proportional to the rotor's speed: divide by that mean (load
        // angle from the first and the last 1/64 of the window, their centres `len - m`
        // ticks apart).
        let len = ticks(ctx.cfg.spin_measure_time_s, ctx.cfg.ts_s);
        let m = drift_ticks(len);
        let drift = (self.g_ends[1] - self.g_ends[0]) / m as f32;
        let w_rotor = w - drift / ((len - m) as f32 * ctx.cfg.ts_s);
        let psi = e_mag / w_rotor - (f.ld - f.lq) * i_r.0;
        if !(psi.is_finite() && psi > 1e-5 && psi < 50.0) {
            return Err(IdentifyError::Implausible {
                quantity: Quantity::FluxLinkage,
                value: psi,
            });
        }
        ctx.found.psi = Some(psi);
        Ok(())
    }
}

/// Ticks at each end of the flux window over which the load angle is averaged for the
/// rotor's mean speed: 1/64 of the window, at least 1 and at most a quarter.
#[inline]
fn drift_ticks(len: u32) -> u32 {
    (len / 64).clamp(1, (len / 4).max(1))
}
