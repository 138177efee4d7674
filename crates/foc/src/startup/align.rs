//! `Align`: the kick (module docs of [`startup`](super), "Alignment"). A current vector
//! on the d axis of `gamma` rises at `align_step` per tick while the detectors watch for
//! motion: the observer's filtered speed and, on a surface motor, the flux's slope and the
//! matched fit of its path ([`KickFit`]). Motion for `MOVING_TICKS` ticks starts the coast
//! (module `coast`); no motion within `align_time_s` moves the vector by 90 deg once (a
//! rotor at the vector or at its dead point), then starts the ramp from standstill.
//!
//! The fit: per axis `x = c + A P(t)`, `Q = int i dt` since the kick began, `P = int Q dt`
//! since the fit began; from the centered sums `C_pp`, `C_px`, `C_xx`,
//! `|A|^2 = sum C_px^2 / C_pp^2`, the residual variance per sample
//! `sigma^2 = (sum C_xx - sum C_px^2 / C_pp) / (2 (n - 2))`, and motion when
//! `|A| Q / psi_f >= w_k` and `|A|^2 C_pp >= KICK_FIT_CHI2 sigma^2`. The slope:
//! `|lp1(x) - lp2(x)| / (psi_f tau)` with `lp1`, `lp2` two cascaded first-order filters of
//! time constant `tau = KICK_SLOPE_TAU_S`.

use core::f32::consts::{FRAC_PI_2, FRAC_PI_4};

use ekf_core::Estimate;

use super::coast::Coast;
use super::ramp::Ramp;
use super::{
    Frame, Inputs, KICK_BOOST, KICK_FIT_BAND, KICK_FIT_CHI2, KICK_NOISE_K, KICK_SLOPE_TAU_S,
    MOVING_TICKS, Params, Phase, Seed, Sequencer, State,
};
use crate::config::FocConfig;
use crate::transforms::Dq;
use crate::trig::{max2, min2, sin_cos, sqrt, wrap};

/// The alignment's variables (reset at every start).
#[derive(Clone, Copy, Debug, Default, PartialEq)]
pub(super) struct Align {
    /// The kick vector's angle, rad el.
    pub gamma: f32,
    /// The kick current, A.
    pub amp: f32,
    /// Ticks in this step of the alignment (kick and coast).
    pub timer: u32,
    /// Second step (at +90 deg): the first one moved nothing.
    pub second: bool,
    /// Ticks in a row the detectors saw the rotor move.
    pub moving: u16,
    /// The observer's speed, low-pass filtered, rad/s el.
    pub w_f: f32,
    /// Sum of the squared filtered observer speed over the kick's first settling time,
    /// (rad/s)^2.
    pub w_noise: f32,
    /// The detectors of motion from the flux (surface motors).
    pub fit: KickFit,
    /// Coasts that ended with the rotor stopped; the kick speed grows with each and the
    /// coast ends on a shorter turn.
    pub boost: u8,
    /// The coast, once the rotor was seen moving.
    pub coast: Option<Coast>,
}

/// The kick's detectors of motion on a surface motor (module docs). From the flux
/// `x = int(u - R i) dt - L i` along the kick (since the kick current left the dead-time
/// compensation's linear band): the least-squares fit of `x = c + A P(t)` per axis, and the
/// flux's slope from two cascaded low-pass filters.
#[derive(Clone, Copy, Debug, Default, PartialEq)]
pub(super) struct KickFit {
    /// Off: the kick's start is not a rotor at rest (after a false alarm).
    pub off: bool,
    /// Samples of the fit.
    n: f32,
    /// The kick vector's unit vector (cosine, sine).
    g: [f32; 2],
    /// `Q`, the integral of the kick's current, A s.
    q: f32,
    /// `P`, the integral of `Q` since the fit began, A s^2.
    p: f32,
    /// The flux integral `int(u - R i) dt` since the fit began, Wb.
    flux: [f32; 2],
    /// Sums of `P`, `P^2`, and per axis of the flux `x`, `P x`, `x^2`.
    sp: f32,
    spp: f32,
    sf: [f32; 2],
    spf: [f32; 2],
    sff: [f32; 2],
    /// The flux low-pass filtered once and twice ([`KICK_SLOPE_TAU_S`]), Wb.
    lp1: [f32; 2],
    lp2: [f32; 2],
}

impl KickFit {
    /// The detectors from their start, on or `off`.
    pub fn restart(off: bool) -> Self {
        Self {
            off,
            ..Self::default()
        }
    }
}

impl Align {
    /// The kick from rest at `gamma`.
    pub fn new(gamma: f32) -> Self {
        Self {
            gamma,
            ..Self::default()
        }
    }

    /// The control frame of the alignment.
    pub fn frame(&self) -> Frame {
        Frame {
            theta: self.gamma,
            omega: 0.0,
            emf: false,
        }
    }

    /// The current reference: the kick current on the d axis, or the coast's injection.
    #[inline(always)]
    pub fn current(&self, k: &Params) -> Dq {
        if let Some(c) = &self.coast {
            let a = k.inj_amp;
            Dq {
                d: a * c.inj[0],
                q: a * c.inj[1],
            }
        } else {
            Dq {
                d: self.amp,
                q: 0.0,
            }
        }
    }

    /// The speed the kick takes as motion: the kick speed, [`KICK_BOOST`] times larger
    /// after each coast that saw the rotor stop (friction).
    pub fn kick_threshold(&self, k: &Params) -> f32 {
        let mut w = k.kick_speed;
        for _ in 0..self.boost {
            w *= KICK_BOOST;
        }
        w
    }

    /// The speed of the observer that the kick takes as motion: the kick threshold, or on
    /// a surface motor [`KICK_NOISE_K`] times the RMS of its filtered speed over the
    /// kick's first settling time, whichever is larger.
    fn observer_threshold(&self, k: &Params) -> f32 {
        let w = self.kick_threshold(k);
        if k.salient {
            return w;
        }
        let n = k.coast_settle_ticks.max(1) as f32;
        max2(w, KICK_NOISE_K * sqrt(self.w_noise / n))
    }

    /// The kick's detectors of motion on a surface motor (module docs): adds this tick's
    /// sample, the voltage `u` applied over the last period under the kick current `i` of
    /// the last tick, and tells whether the rotor is seen moving: the flux's slope, or the
    /// fit's speed with `|A|` at least [`KICK_FIT_CHI2`] (chi-square, 2 degrees of
    /// freedom) against its noise, at least the kick speed.
    fn kick_fit(&mut self, k: &Params, cfg: &FocConfig, u: [f32; 2], i: f32) -> bool {
        let ts = cfg.ts_s;
        let w_k = self.kick_threshold(k);
        let f = &mut self.fit;
        if f.off {
            return false;
        }
        f.q += i * ts;
        // The fit starts once the dead-time compensation is out of its linear band: below,
        // its error drifts the flux along the kick vector by far more than a slow rotor.
        if i < KICK_FIT_BAND * cfg.dead_time_band() {
            return false;
        }
        if f.n == 0.0 {
            let (s, c) = sin_cos(self.gamma);
            f.g = [c, s];
        } else {
            f.p += f.q * ts;
        }
        let p = f.p;
        f.n += 1.0;
        f.sp += p;
        f.spp += p * p;
        let (rs, ls) = (cfg.motor.rs_ohm, cfg.motor.ld_h);
        let kf = k.slope_filter;
        let mut slope2 = 0.0;
        for (n, &un) in u.iter().enumerate() {
            f.flux[n] += (un - rs * i * f.g[n]) * ts;
            let x = f.flux[n] - ls * i * f.g[n];
            f.sf[n] += x;
            f.spf[n] += p * x;
            f.sff[n] += x * x;
            // The flux's slope (the back-EMF) from two cascaded low-pass filters.
            if f.n == 1.0 {
                f.lp1[n] = x;
                f.lp2[n] = x;
            }
            f.lp1[n] += (x - f.lp1[n]) * kf;
            f.lp2[n] += (f.lp1[n] - f.lp2[n]) * kf;
            let d = f.lp1[n] - f.lp2[n];
            slope2 += d * d;
        }
        if f.n < k.kick_fit_min {
            return false;
        }
        let w_slope = sqrt(slope2) * k.inv_psi / KICK_SLOPE_TAU_S;
        if w_slope >= w_k {
            return true;
        }
        // The fit of `c + A P` per axis, from the centered sums.
        let inv_n = 1.0 / f.n;
        let cpp = f.spp - f.sp * f.sp * inv_n;
        if cpp <= 0.0 {
            return false;
        }
        let mut cpf2 = 0.0;
        let mut cff = 0.0;
        for n in 0..2 {
            let cpf = f.spf[n] - f.sp * f.sf[n] * inv_n;
            cpf2 += cpf * cpf;
            cff += f.sff[n] - f.sf[n] * f.sf[n] * inv_n;
        }
        // `|A|^2 = cpf2 / cpp^2`; the residual's variance per sample `sigma^2`; the
        // chi-square of `|A|` against its variance `sigma^2 / cpp` is `|A|^2 cpp / sigma^2`.
        let a2 = cpf2 / (cpp * cpp);
        let sigma2 = max2((cff - cpf2 / cpp) / (2.0 * (f.n - 2.0)), 0.0);
        let w = sqrt(a2) * f.q * k.inv_psi;
        w >= w_k && a2 * cpp >= KICK_FIT_CHI2 * sigma2
    }
}

impl Sequencer {
    /// One tick of `Align`: the coast's step while coasting, else the kick's. Returns the
    /// frame the current loops leave when it changes.
    #[inline(always)]
    pub(super) fn align(
        &mut self,
        cfg: &FocConfig,
        input: Inputs<'_>,
        reseed: &mut impl FnMut(Seed),
    ) -> Option<Frame> {
        let Phase::Align(a) = &mut self.phase else {
            return None;
        };
        a.timer = a.timer.saturating_add(1);
        if a.coast.is_some() {
            self.coast(cfg, input, reseed)
        } else {
            self.kick(cfg, input.estimate, input.u_ab, reseed)
        }
    }

    /// One tick of the kick: the current rises, the detectors look for motion; motion
    /// starts the coast, none within `align_time_s` the second step or the ramp.
    #[inline(always)]
    fn kick(
        &mut self,
        cfg: &FocConfig,
        est: &Estimate<f32>,
        u_ab: [f32; 2],
        reseed: &mut impl FnMut(Seed),
    ) -> Option<Frame> {
        let Phase::Align(a) = &mut self.phase else {
            return None;
        };
        let k = &self.k;
        let i_align = cfg.startup.align_current_a;
        let fit = !k.salient && k.kick_speed > 0.0 && a.kick_fit(k, cfg, u_ab, a.amp);
        a.amp = min2(a.amp + k.align_step, i_align);
        a.w_f += (est.omega_e_rad_s - a.w_f) * k.kick_filter;
        // The observer's speed noise at standstill, over the kick's first settling time
        // (the current still small, the rotor at rest).
        if a.timer <= k.coast_settle_ticks {
            a.w_noise += a.w_f * a.w_f;
        }
        let seen = k.kick_speed > 0.0
            && (!k.salient || est.angle_tracked)
            && (fit || a.w_f.abs() >= a.observer_threshold(k))
            && a.timer >= k.coast_settle_ticks;
        a.moving = if seen { a.moving.saturating_add(1) } else { 0 };
        if a.moving >= MOVING_TICKS {
            a.coast = Some(Coast::new());
        } else if a.timer > k.align_ticks && a.amp >= i_align {
            if a.second || k.kick_speed == 0.0 {
                let gamma = a.gamma;
                self.phase = Phase::OpenLoop(Ramp::from_rest(
                    cfg,
                    gamma,
                    FRAC_PI_4,
                    &mut self.health,
                    reseed,
                ));
                self.state = State::OpenLoop;
            } else {
                let reframe = a.frame();
                a.second = true;
                a.timer = 0;
                a.w_noise = 0.0;
                a.amp = 0.0;
                a.gamma = wrap(a.gamma + FRAC_PI_2);
                a.fit = KickFit::restart(a.fit.off);
                return Some(reframe);
            }
        }
        None
    }
}
