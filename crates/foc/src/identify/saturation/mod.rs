//! The flux map `psi_d(i_d, i_q)`, `psi_q(i_d, i_q)` of a saturating motor measured at
//! standstill: [`SaturationProbe`], run after the alignment (the rotor's d axis known) and
//! the resistance step (`Rs`, the inverter voltage error), with `psi_f` from the spin or told.
//!
//! # Method
//!
//! At standstill the stator equations in a fixed frame are `u = Rs i + dpsi/dt` (no motion
//! voltage), so a flux change is the integral of the voltage the resistance leaves:
//!
//! `psi(t) - psi(t0) = integral_t0^t (u - Rs i - e) dt`
//!
//! (`e` the inverter's voltage error, below). The probe integrates both axes of the fixed
//! frame at the alignment angle `theta` ([`SaturationConfig::theta_rad`]) every tick, with
//! the voltage that acted over the interval (the one commanded `d` periods earlier, `d` the
//! computation delay) and the interval's mean current:
//! `psi[k] = psi[k-1] + Ts (u[k-1-d] - Rs i_mean - e)`. The mean current is the
//! trapezoidal one corrected for the current's curvature: at standstill `i` is a smooth
//! function of `psi` (also where the voltage steps), so the parabola through the last three
//! `(psi, i)` points gives its mean over the interval's flux span (`integral::mean_current`;
//! the trapezoidal rule alone overstated the drop by 0.2 mWb over a q lobe of the interior
//! PM motor below, where the current's rise per tick more than doubles within a few ticks).
//! The integral is anchored at each pulse's start to the flux known there (below), so an
//! `Rs` error drifts it only over one pulse.
//!
//! **The rotor frame.** The q pulses make a torque, and the rotor turns a little: the map
//! wants flux and current in the rotor's frame. With `J` known
//! ([`SaturationConfig::inertia_kg_m2`]; the inertia step's, or told) the probe follows the
//! rotor: the torque `T = 3/2 p (psi x i)` (a cross product, the same in any frame: the
//! integrated flux and the measured current give it exactly), `w' = p T / J`, `theta_r' = w`
//! (free rotor, friction and load neglected; both integrals trapezoidal), and every sample, every loop and every pulse
//! voltage is in the frame at `theta + theta_r`. Without `J` the frame stays at `theta`: the
//! rotor's angle error `dtheta` then costs about `|psi| dtheta` (on the PM-SyRM below, a
//! grid whose errors reach the flux itself: `J` is needed on motors whose q pulses take
//! milliseconds).
//!
//! The grid: `i_d` at `n_d` levels evenly from `-I_max` to `+I_max`, `i_q` at `n_q` levels
//! evenly from `-I_max` to `+I_max` (`n_d <= 7`, `n_q <= 9`, both odd so that zero is a
//! level; `I_max` = [`SaturationConfig::i_max_a`] per axis). Each flux sample is taken where
//! the current crosses a level: the parabola in the current through the last three ticks
//! (`grid::interpolate`; a pulse moves the current by up to a few amperes per tick where the
//! motor saturates, and a straight line between two ticks cuts the curved `psi(i)`).
//!
//! 1. **d axis**, `q = 0`: from zero current, `u_d = +U_d` until `i_d` passes `+I_max`, then
//!    `-U_d` back to zero; the same with the signs swapped. The flux is anchored at the
//!    pulse's start to `(psi_f + Ld0 i_d0, Lq0 i_q0)` (the small residual currents the rest
//!    left); the rising branches give `psi_d(i_d, 0)`. The q current is held at zero by its
//!    PI loop. The rotor is aligned, so the d current makes no torque (for a symmetric
//!    machine `psi_q(i_d, 0) = 0`).
//! 2. **q axis at each d bias** `i_dk`: the d loop (PI, feed-forward `Ld0 di/dt + Rs i`)
//!    ramps `i_d` to `i_dk` and holds it; then a bipolar q pulse: `+U_q` until `i_q` passes
//!    `+I_max`, `-U_q` until it passes `-I_max`, `+U_q` back to zero (equal volt-seconds each
//!    way, the q current's positive and negative lobes alike, so the torque impulse nearly
//!    cancels). The flux is anchored at the pulse's start to `(psi_d(i_dk, 0) + Ldd (i_d0 -
//!    i_dk), Lq0 i_q0)` from the d curve (`Ldd` its slope at `i_dk`); the rising branch gives
//!    `psi_q(i_dk, i_qj)` for `i_qj > 0`, the falling one for `i_qj < 0`. The d flux over the
//!    same time is the cross saturation. The q pulse changes the d flux faster than the d
//!    loop holds `i_d`, which strays from `i_dk` by a fraction of an ampere; at the end both
//!    samples of every node are moved back to the level along the measured grid's own d
//!    slopes there (`grid`: `psi_x(i_dk, i_qj) = psi_x,cross + L_xd (i_dk - i_d,cross)`,
//!    `L_dd`, `L_qd` by central differences over the d levels, to a fixed point). Without
//!    the `psi_q` part the stray alone biased `|psi_q|` low by up to 2.7 mWb at
//!    `|i_q| >= 1.1 I_r` on the interior PM motor below (`L_qd = dpsi_d/di_q` is large
//!    there). Then `i_d` ramps back to zero and both loops rest at zero current before the
//!    next level.
//!
//! Pulse voltages: `U_d = Ld0 I_max / (N Ts)`, `U_q = Lq0 I_max / (N Ts)` for `N` =
//! [`SaturationConfig::ramp_ticks`] (default 12) ticks per ramp at the small-signal
//! inductances, each within 80 % of the voltage limit `max_modulation u_dc / sqrt(3)`
//! (short pulses: the rotor moves with the square of their length).
//!
//! **Inverter voltage error.** `e` is the dead-time voltage of the three phases, each
//! `V_dt sign(i_x)` with `V_dt = 3/4 U_err` (`U_err` = [`SaturationConfig::voltage_error_v`],
//! the resistance step's error along the phase-a axis, where the signs `(+, -, -)` give
//! `4/3 V_dt` along alpha), linear within 5 % of `I_max` of zero current, at the currents
//! sampled at the **start** of the interval being integrated: the bridge applies the
//! interval's voltage with the phase currents' signs of that interval, and the current
//! sampled at its end has already moved on. Where a pulse drives a phase current through
//! zero (every q pulse, for every phase not on the d axis) the end sample's sign is the
//! next interval's: each crossing then cost `2 V_dt Ts` of flux on the wrong side. Measured
//! on pmsm-sim's interior PM motor (`identify_flux_map`, `across_sensor_seeds`): the EKF
//! told the identified map 1.67-3.13 x the true map's angle RMS over six sensor seeds,
//! median 1.83 x (with the end sample: 1.99-4.09 x, median 2.14 x).
//!
//! **Rotor motion.** With `T_max` the torque's peak and `t_p` a q pulse's length, the rotor
//! cannot move more than `T_max t_p^2 / (2 J)` (mechanical rad) during the pulse; the equal
//! lobes bring its speed back near zero, but not to zero, and it drifts slowly between the
//! pulses (followed by the probe). A d bias against the rotor's preferred axis (a negative
//! `i_d`, or any large `i_d` on a reluctance motor with `Lq > Ld`) is an unstable
//! equilibrium: it is held only for the settling (`settle_s / 2`) and the q pulse. Measured
//! (pmsm-sim `saturated_flux_probe`): the PM-SyRM turns 0.14 mechanical rad over the whole
//! probe, the interior PM motor 0.03.
//!
//! **Assumptions and limits.** No hysteresis (the falling q branch gives the negative
//! levels; [`FluxSamples::q_closure_wb`] reports `psi_q` where it crosses zero current); a
//! symmetric machine (`psi_q(i_d, 0) = 0`, `psi_d(0, 0) = psi_f`); a free rotor without
//! load torque when `J` is given. Every pulse part has a time-out (`4 t + 40` ticks, `t` the
//! ramp's ticks at the small-signal inductance and the pulse voltage; the q pulse's falling
//! part twice that): [`SaturationError::LevelNotReached`]. The current is limited to
//! [`SaturationConfig::over_current_a`] (default `2 I_max`: the grid's corners reach
//! `sqrt(2) I_max`, and a pulse overshoots its last level by up to two ticks' rise, the
//! computation delay's). Duration: four pulses' rests plus `n_d` biases, 0.2-0.3 s on the
//! reference motors (docs/identify.md).

use crate::config::ComputationDelay;
use crate::io::TickInput;
use crate::pi::{Pi, PiGains};
use crate::svpwm::{SAFE_DUTIES, svpwm};
use crate::transforms::AlphaBeta;
use crate::trig::{sin_cos, sqrt};

use super::numeric::ticks;

mod grid;
mod integral;
mod types;

pub use types::{
    FluxSamples, SAT_MAX_D, SAT_MAX_Q, SaturationConfig, SaturationError, SaturationOutput,
    SaturationPhase,
};

use super::numeric::INV_SQRT3;

/// What follows a rest.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
enum Next {
    /// The d pulse of this sign.
    DPulse(i8),
    /// The d bias level `k`.
    Bias(usize),
    /// The end.
    Done,
}

#[derive(Clone, Copy, Debug, PartialEq, Eq)]
enum State {
    Rest(Next),
    /// Sign, on the way back to zero.
    DPulse(i8, bool),
    BiasUp(usize),
    /// Level `k`, part 0 up, 1 down, 2 back.
    QPulse(usize, u8),
    BiasDown(usize),
    Done,
}

/// The standstill flux-map measurement (module docs): tick it once per PWM period until
/// [`SaturationProbe::result`] is set.
#[derive(Clone, Debug)]
pub struct SaturationProbe {
    cfg: SaturationConfig,
    d: usize,
    sc: (f32, f32),
    state: State,
    /// Ticks in the state.
    n: u32,
    tick: u32,
    pi_d: Pi,
    pi_q: Pi,
    /// Stator flux in the frame at `theta_rad` (fixed), anchored at each pulse's start, Wb.
    psi: [f32; 2],
    /// This tick's flux in the rotor frame, Wb.
    psi_rot: [f32; 2],
    /// The flux in the rotor frame two ticks ago, last tick and this tick (`[2]`), Wb.
    psi_hist: [[f32; 2]; 3],
    /// The flux in the fixed frame two ticks ago, anchored as `psi`, Wb.
    psi_fix_prev: [f32; 2],
    /// The currents in the fixed frame two ticks ago (`[0]`) and last tick, A.
    i_fix_hist: [[f32; 2]; 2],
    /// The currents in the rotor frame (d, q) two ticks ago, last tick and this tick
    /// (`[2]`), A.
    i_hist: [[f32; 2]; 3],
    /// The rotor's estimated angle from `theta_rad`, electrical rad.
    rotor_angle: f32,
    /// The rotor's estimated speed, electrical rad/s.
    rotor_speed: f32,
    /// Last tick's torque, N m.
    torque_prev: f32,
    /// `(sin, cos)` of `rotor_angle`.
    rsc: (f32, f32),
    /// Commanded voltages (d, q) of the last two ticks, V.
    u_hist: [[f32; 2]; 2],
    /// Whether `i_fix_hist` and `u_hist` are valid for integration.
    running: bool,
    /// Next level index to cross in the pulse in progress.
    next: usize,
    /// `i_d` at each q crossing, A.
    i_d_at: [[f32; SAT_MAX_Q]; SAT_MAX_D],
    out: FluxSamples,
    result: Option<Result<FluxSamples, SaturationError>>,
}

impl SaturationProbe {
    /// A measurement with the settings `cfg` (checked).
    pub fn new(cfg: &SaturationConfig) -> Result<Self, SaturationError> {
        cfg.validate().map_err(SaturationError::Config)?;
        let mut out = FluxSamples {
            n_d: cfg.n_d,
            n_q: cfg.n_q,
            i_d: [0.0; SAT_MAX_D],
            i_q: [0.0; SAT_MAX_Q],
            psi_d: [[0.0; SAT_MAX_Q]; SAT_MAX_D],
            psi_q: [[0.0; SAT_MAX_Q]; SAT_MAX_D],
            q_closure_wb: 0.0,
            rotor_angle_max_rad: 0.0,
            ticks: 0,
        };
        for k in 0..cfg.n_d {
            out.i_d[k] = cfg.i_d_level(k);
        }
        for j in 0..cfg.n_q {
            out.i_q[j] = cfg.i_q_level(j);
        }
        let gains = |l: f32| PiGains {
            kp: l * cfg.current_bw_rad_s,
            ki: cfg.rs_ohm.max(1e-3) * cfg.current_bw_rad_s,
        };
        Ok(Self {
            cfg: *cfg,
            d: match cfg.delay {
                ComputationDelay::OnePeriod => 1,
                ComputationDelay::None => 0,
            },
            sc: sin_cos(cfg.theta_rad),
            state: State::Rest(Next::DPulse(1)),
            n: 0,
            tick: 0,
            pi_d: Pi::new(gains(cfg.ld_h), cfg.ts_s),
            pi_q: Pi::new(gains(cfg.lq_h), cfg.ts_s),
            psi: [cfg.psi_f_wb, 0.0],
            psi_rot: [cfg.psi_f_wb, 0.0],
            psi_hist: [[cfg.psi_f_wb, 0.0]; 3],
            psi_fix_prev: [cfg.psi_f_wb, 0.0],
            i_fix_hist: [[0.0; 2]; 2],
            i_hist: [[0.0; 2]; 3],
            rotor_angle: 0.0,
            rotor_speed: 0.0,
            torque_prev: 0.0,
            rsc: (0.0, 1.0),
            u_hist: [[0.0; 2]; 2],
            running: false,
            next: 0,
            i_d_at: [[0.0; SAT_MAX_Q]; SAT_MAX_D],
            out,
            result: None,
        })
    }

    /// The outcome, once finished.
    pub fn result(&self) -> Option<&Result<FluxSamples, SaturationError>> {
        self.result.as_ref()
    }

    /// Whether finished (success or failure).
    pub fn is_done(&self) -> bool {
        self.result.is_some()
    }

    /// Ticks since construction.
    pub fn ticks(&self) -> u32 {
        self.tick
    }

    /// The settings.
    pub fn config(&self) -> &SaturationConfig {
        &self.cfg
    }

    fn phase(&self) -> SaturationPhase {
        match self.state {
            State::Rest(_) => SaturationPhase::Rest,
            State::DPulse(..) => SaturationPhase::DPulse,
            State::BiasUp(_) => SaturationPhase::BiasUp,
            State::QPulse(..) => SaturationPhase::QPulse,
            State::BiasDown(_) => SaturationPhase::BiasDown,
            State::Done => SaturationPhase::Done,
        }
    }

    fn off(&self, i_ab: AlphaBeta) -> SaturationOutput {
        SaturationOutput {
            duties: SAFE_DUTIES,
            pwm_enabled: false,
            phase: self.phase(),
            i_ab,
            u_ab: AlphaBeta::default(),
        }
    }

    fn fail(&mut self, e: SaturationError) {
        self.state = State::Done;
        self.result = Some(Err(e));
    }

    /// Pulse voltage of an axis, V: `L I_max / (N Ts)` within 80 % of the limit.
    fn pulse_u(&self, l: f32, u_lim: f32) -> f32 {
        let c = &self.cfg;
        (l * c.i_max_a / (c.ramp_ticks as f32 * c.ts_s)).min(0.8 * u_lim)
    }

    /// Time-out of a pulse part at the voltage `u` and inductance `l`, ticks.
    fn timeout(&self, l: f32, u: f32) -> u32 {
        let c = &self.cfg;
        let t = l * c.i_max_a / (u.max(1e-6) * c.ts_s);
        (4.0 * t.min(1.0e8)) as u32 + 40
    }

    /// The inverter's voltage error (d, q) at the currents `i_ab` (module docs), V.
    fn inverter_error(&self, i_ab: AlphaBeta) -> [f32; 2] {
        let c = &self.cfg;
        if c.voltage_error_v == 0.0 {
            return [0.0; 2];
        }
        let band = 0.05 * c.i_max_a;
        let s = |i: f32| (i / band).clamp(-1.0, 1.0) * 0.75 * c.voltage_error_v;
        let half = 0.5 * i_ab.alpha;
        let b = 0.5 * i_ab.beta / INV_SQRT3;
        let (ea, eb, ec) = (s(i_ab.alpha), s(-half + b), s(-half - b));
        let e = AlphaBeta {
            alpha: (2.0 / 3.0) * (ea - 0.5 * eb - 0.5 * ec),
            beta: (eb - ec) * INV_SQRT3,
        };
        let (d, q) = self.dq(e);
        [d, q]
    }

    fn dq(&self, v: AlphaBeta) -> (f32, f32) {
        let (s, c) = self.sc;
        (c * v.alpha + s * v.beta, -s * v.alpha + c * v.beta)
    }

    fn ab(&self, d: f32, q: f32) -> AlphaBeta {
        let (s, c) = self.sc;
        AlphaBeta {
            alpha: c * d - s * q,
            beta: s * d + c * q,
        }
    }

    /// Starts a pulse at this tick, the flux anchored at `psi_rot` (rotor frame).
    fn start_pulse(&mut self, state: State, psi_rot: [f32; 2]) {
        self.state = state;
        self.n = 0;
        self.next = 0;
        self.anchor(psi_rot);
    }

    /// Sets the flux to `psi_rot` (rotor frame) at this tick; the last ticks' flux moves by
    /// the same amount (the integral's constant changes, not its course).
    fn anchor(&mut self, psi_rot: [f32; 2]) {
        let (s, c) = self.rsc;
        let psi = [
            c * psi_rot[0] - s * psi_rot[1],
            s * psi_rot[0] + c * psi_rot[1],
        ];
        self.psi_fix_prev[0] += psi[0] - self.psi[0];
        self.psi_fix_prev[1] += psi[1] - self.psi[1];
        self.psi = psi;
        let shift = [psi_rot[0] - self.psi_rot[0], psi_rot[1] - self.psi_rot[1]];
        for p in &mut self.psi_hist {
            p[0] += shift[0];
            p[1] += shift[1];
        }
        self.psi_rot = psi_rot;
    }

    /// `v` (fixed frame) in the rotor frame.
    fn to_rotor(&self, v: [f32; 2]) -> [f32; 2] {
        let (s, c) = self.rsc;
        [c * v[0] + s * v[1], -s * v[0] + c * v[1]]
    }

    /// The slope `dpsi_d / di_d` of the measured d curve at level `k`, H.
    fn l_dd(&self, k: usize) -> f32 {
        let c = &self.cfg;
        let q0 = (c.n_q - 1) / 2;
        let (lo, hi) = (k.saturating_sub(1), (k + 1).min(c.n_d - 1));
        (self.out.psi_d[hi][q0] - self.out.psi_d[lo][q0]) / (self.out.i_d[hi] - self.out.i_d[lo])
    }

    fn go(&mut self, state: State) {
        self.state = state;
        self.n = 0;
    }

    /// One PWM period: the input checks, the flux integration, the part in progress and the
    /// modulator.
    pub fn tick(&mut self, input: &TickInput) -> SaturationOutput {
        self.tick = self.tick.wrapping_add(1);
        let i_ab = super::numeric::less_offsets(input.currents, self.cfg.current_offsets_a);
        if self.result.is_some() {
            return self.off(i_ab);
        }
        let u_dc = input.u_dc_v;
        if !(u_dc.is_finite() && u_dc > 0.0 && i_ab.alpha.is_finite() && i_ab.beta.is_finite()) {
            self.fail(SaturationError::NonFiniteInput);
            return self.off(i_ab);
        }
        let i_mag = sqrt(i_ab.norm_squared());
        if i_mag > self.cfg.over_current_a {
            self.fail(SaturationError::OverCurrent { current_a: i_mag });
            return self.off(i_ab);
        }
        let u_lim = self.cfg.max_modulation * u_dc * INV_SQRT3;
        let (i_fd, i_fq) = self.dq(i_ab);
        self.integrate([i_fd, i_fq]);
        let [i_d, i_q] = self.to_rotor([i_fd, i_fq]);
        self.psi_rot = self.to_rotor(self.psi);
        self.psi_hist = [self.psi_hist[1], self.psi_hist[2], self.psi_rot];
        self.i_hist = [self.i_hist[1], self.i_hist[2], [i_d, i_q]];
        self.n = self.n.saturating_add(1);
        let u = match self.step(i_d, i_q, u_lim) {
            Ok(u) => u,
            Err(e) => {
                self.fail(e);
                return self.off(i_ab);
            }
        };
        let Some((ud, uq)) = u else {
            self.out.ticks = self.tick;
            self.result = Some(Ok(self.out));
            return self.off(i_ab);
        };
        let mag = sqrt(ud * ud + uq * uq);
        let k = if mag > u_lim { u_lim / mag } else { 1.0 };
        let (s, c) = self.rsc;
        let (ud, uq) = (ud * k, uq * k);
        let (ud, uq) = (c * ud - s * uq, s * ud + c * uq);
        let m = svpwm(self.ab(ud, uq), u_dc);
        let (ad, aq) = self.dq(m.applied);
        self.u_hist = [[ad, aq], self.u_hist[0]];
        self.running = true;
        SaturationOutput {
            duties: m.duties,
            pwm_enabled: true,
            phase: self.phase(),
            i_ab,
            u_ab: m.applied,
        }
    }

    /// The PI of axis `x` toward `i_ref` with feed-forward `ff`, V.
    fn loop_u(&mut self, d_axis: bool, err: f32, ff: f32, u_lim: f32) -> f32 {
        let pi = if d_axis {
            &mut self.pi_d
        } else {
            &mut self.pi_q
        };
        pi.step(err, ff, -0.6 * u_lim, 0.6 * u_lim)
    }

    /// The part in progress: the voltage `(u_d, u_q)`, `None` when finished.
    fn step(
        &mut self,
        i_d: f32,
        i_q: f32,
        u_lim: f32,
    ) -> Result<Option<(f32, f32)>, SaturationError> {
        let c = self.cfg;
        let settle = ticks(c.settle_s, c.ts_s);
        let ramp = c.ramp_ticks;
        match self.state {
            State::Rest(next) => {
                let u_d = self.loop_u(true, -i_d, 0.0, u_lim);
                let u_q = self.loop_u(false, -i_q, 0.0, u_lim);
                if self.n >= settle {
                    // Near zero current: the small-signal inductances.
                    let psi0 = [c.psi_f_wb + c.ld_h * i_d, c.lq_h * i_q];
                    match next {
                        Next::DPulse(s) => self.start_pulse(State::DPulse(s, false), psi0),
                        Next::Bias(k) => {
                            self.go(State::BiasUp(k));
                            self.anchor(psi0);
                        }
                        Next::Done => {
                            self.finish_grid();
                            self.state = State::Done;
                            return Ok(None);
                        }
                    }
                }
                Ok(Some((u_d, u_q)))
            }
            State::DPulse(sign, back) => {
                let s = f32::from(sign);
                let u_p = self.pulse_u(c.ld_h, u_lim);
                let u_q = self.loop_u(false, -i_q, 0.0, u_lim);
                let mid = (c.n_d - 1) / 2;
                let q0 = (c.n_q - 1) / 2;
                if !back {
                    // Levels away from zero in the pulse's direction.
                    while self.next < mid {
                        let k = if sign > 0 {
                            mid + 1 + self.next
                        } else {
                            mid - 1 - self.next
                        };
                        let level = c.i_d_level(k);
                        if s * i_d < s * level {
                            break;
                        }
                        self.out.psi_d[k][q0] = self.at_crossing(0, level).0[0];
                        self.next += 1;
                    }
                    if self.next >= mid {
                        self.go(State::DPulse(sign, true));
                    } else if self.n > self.timeout(c.ld_h, u_p) {
                        return Err(SaturationError::LevelNotReached {
                            axis: 'd',
                            level_a: s * c.i_max_a,
                            current_a: i_d,
                        });
                    }
                    Ok(Some((s * u_p, u_q)))
                } else if s * i_d <= 0.0 {
                    self.pi_d.reset();
                    self.out.psi_d[mid][q0] = c.psi_f_wb;
                    let next = if sign > 0 {
                        Next::DPulse(-1)
                    } else {
                        Next::Bias(0)
                    };
                    self.go(State::Rest(next));
                    Ok(Some((0.0, u_q)))
                } else if self.n > self.timeout(c.ld_h, u_p) {
                    Err(SaturationError::LevelNotReached {
                        axis: 'd',
                        level_a: 0.0,
                        current_a: i_d,
                    })
                } else {
                    Ok(Some((-s * u_p, u_q)))
                }
            }
            State::BiasUp(k) => {
                let target = c.i_d_level(k);
                let frac = (self.n as f32 / ramp as f32).min(1.0);
                let ff = if self.n <= ramp {
                    c.ld_h * target / (ramp as f32 * c.ts_s)
                } else {
                    0.0
                } + c.rs_ohm * target * frac;
                let u_d = self.loop_u(true, target * frac - i_d, ff, u_lim);
                let u_q = self.loop_u(false, -i_q, 0.0, u_lim);
                if self.n >= ramp + settle / 2 {
                    self.pi_q.reset();
                    // psi_d along the measured d curve, psi_q = Lq0 i_q near zero.
                    let q0 = (c.n_q - 1) / 2;
                    let psi_d = self.out.psi_d[k][q0] + self.l_dd(k) * (i_d - target);
                    self.start_pulse(State::QPulse(k, 0), [psi_d, c.lq_h * i_q]);
                }
                Ok(Some((u_d, u_q)))
            }
            State::QPulse(k, part) => {
                let target = c.i_d_level(k);
                let u_d = self.loop_u(true, target - i_d, c.rs_ohm * target, u_lim);
                let u_p = self.pulse_u(c.lq_h, u_lim);
                let mid = (c.n_q - 1) / 2;
                let timeout = self.timeout(c.lq_h, u_p) * if part == 1 { 2 } else { 1 };
                let (u_q, level, passed) = match part {
                    0 => {
                        while self.next < mid {
                            let j = mid + 1 + self.next;
                            let level = c.i_q_level(j);
                            if i_q < level {
                                break;
                            }
                            self.record(j, level);
                            self.next += 1;
                        }
                        (u_p, c.i_max_a, self.next >= mid)
                    }
                    1 => {
                        // The zero crossing: closure check, then the negative levels.
                        while self.next < mid + 1 {
                            let j = mid - self.next;
                            let level = c.i_q_level(j);
                            if i_q > level {
                                break;
                            }
                            if j == mid {
                                let p = self.at_crossing(1, 0.0).0[1];
                                self.out.q_closure_wb = self.out.q_closure_wb.max(p.abs());
                            } else {
                                self.record(j, level);
                            }
                            self.next += 1;
                        }
                        (-u_p, -c.i_max_a, self.next > mid)
                    }
                    _ => (u_p, 0.0, i_q >= 0.0),
                };
                if passed {
                    if part < 2 {
                        self.n = 0;
                        self.next = 0;
                        self.state = State::QPulse(k, part + 1);
                    } else {
                        self.finish_level(k);
                        self.go(State::BiasDown(k));
                        return Ok(Some((u_d, 0.0)));
                    }
                } else if self.n > timeout {
                    return Err(SaturationError::LevelNotReached {
                        axis: 'q',
                        level_a: level,
                        current_a: i_q,
                    });
                }
                Ok(Some((u_d, u_q)))
            }
            State::BiasDown(k) => {
                let from = c.i_d_level(k);
                let frac = 1.0 - (self.n as f32 / ramp as f32).min(1.0);
                let ff = if self.n <= ramp {
                    -c.ld_h * from / (ramp as f32 * c.ts_s) + c.rs_ohm * from * frac
                } else {
                    0.0
                };
                let u_d = self.loop_u(true, from * frac - i_d, ff, u_lim);
                let u_q = self.loop_u(false, -i_q, 0.0, u_lim);
                if self.n >= ramp {
                    self.go(State::Rest(if k + 1 < c.n_d {
                        Next::Bias(k + 1)
                    } else {
                        Next::Done
                    }));
                }
                Ok(Some((u_d, u_q)))
            }
            State::Done => Ok(None),
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    /// A linear motor held at standstill at `theta`: flux state in the rotor frame, one
    /// period of delay; `open` leaves the q winding open (no q current).
    fn run(
        cfg: &SaturationConfig,
        ld: f32,
        lq: f32,
        open_q: bool,
    ) -> Result<FluxSamples, SaturationError> {
        let mut p = SaturationProbe::new(cfg).unwrap();
        let (s, c) = sin_cos(cfg.theta_rad);
        let (mut pd, mut pq) = (cfg.psi_f_wb, 0.0f32);
        let mut u_prev = (0.0f32, 0.0f32);
        for _ in 0..200_000 {
            let i_d = (pd - cfg.psi_f_wb) / ld;
            let i_q = if open_q { 0.0 } else { pq / lq };
            let ab = AlphaBeta {
                alpha: c * i_d - s * i_q,
                beta: s * i_d + c * i_q,
            };
            let out = p.tick(&TickInput::alpha_beta(ab.alpha, ab.beta, 300.0));
            if let Some(r) = p.result() {
                return *r;
            }
            // Trapezoidal resistive drop, solved for the new current (linear circuit).
            let (h, r) = (cfg.ts_s, cfg.rs_ohm);
            let x = pd - cfg.psi_f_wb + h * (u_prev.0 - 0.5 * r * i_d);
            pd = cfg.psi_f_wb + x / (1.0 + 0.5 * h * r / ld);
            if !open_q {
                let x = pq + h * (u_prev.1 - 0.5 * r * i_q);
                pq = x / (1.0 + 0.5 * h * r / lq);
            }
            let u = out.u_ab;
            u_prev = (c * u.alpha + s * u.beta, -s * u.alpha + c * u.beta);
        }
        panic!("did not finish");
    }

    fn cfg() -> SaturationConfig {
        SaturationConfig::new(1e-4, 0.5, 0.9, 0.1, (0.004, 0.008), 10.0)
    }

    #[test]
    fn a_linear_motor_gives_its_inductances() {
        let c = cfg();
        let s = run(&c, 0.004, 0.008, false).unwrap();
        for d in 0..s.n_d {
            for q in 0..s.n_q {
                let (id, iq) = (s.i_d[d], s.i_q[q]);
                let want_d = 0.1 + 0.004 * id;
                let want_q = 0.008 * iq;
                assert!(
                    (s.psi_d[d][q] - want_d).abs() < 2e-4 * 0.14,
                    "d {d} {q} {}",
                    s.psi_d[d][q]
                );
                assert!(
                    (s.psi_q[d][q] - want_q).abs() < 2e-4 * 0.14,
                    "q {d} {q} {}",
                    s.psi_q[d][q]
                );
            }
        }
        assert!(s.q_closure_wb < 1e-3);
        let map = s.flux_map::<9>().unwrap();
        assert_eq!(map.shape(), (7, 9));
    }

    #[test]
    fn an_open_q_winding_is_a_timeout_and_the_pwm_off() {
        let c = cfg();
        let e = run(&c, 0.004, 0.008, true).unwrap_err();
        assert!(
            matches!(e, SaturationError::LevelNotReached { axis: 'q', .. }),
            "{e:?}"
        );
    }

    #[test]
    fn bad_settings_and_inputs_are_refused() {
        let mut c = cfg();
        c.n_d = 4;
        assert_eq!(
            SaturationProbe::new(&c).unwrap_err(),
            SaturationError::Config("n_d")
        );
        let mut c = cfg();
        c.over_current_a = c.i_max_a;
        assert!(SaturationProbe::new(&c).is_err());
        let mut p = SaturationProbe::new(&cfg()).unwrap();
        let out = p.tick(&TickInput::alpha_beta(f32::NAN, 0.0, 300.0));
        assert!(!out.pwm_enabled);
        assert_eq!(p.result(), Some(&Err(SaturationError::NonFiniteInput)));
        let mut p = SaturationProbe::new(&cfg()).unwrap();
        p.tick(&TickInput::alpha_beta(21.0, 0.0, 300.0));
        assert!(matches!(
            p.result(),
            Some(Err(SaturationError::OverCurrent { .. }))
        ));
    }
}
