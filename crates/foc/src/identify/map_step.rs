//! The opt-in flux-map step: [`IdentifyWithMap`] runs the [`Identifier`] sequence (with its
//! spin, which gives `psi_f`, and usually the inertia move, which gives `J`) and then
//! measures the flux map of a saturating motor at standstill with [`SaturationProbe`].
//!
//! # The step
//!
//! | part | what | how |
//! |---|---|---|
//! | [`MapPart::Coast`] | `psi_d(0, 0)`, the rotor's speed and d axis | where the sequence ended (the I/f frame at the spin speed; no tick with the PWM off) the current loops (the spin's gains, preset to the last voltage) hold zero current for 20 ms, then a square wave `i_d = +-0.15 I_test` along the turning frame, the sign changing each `pi/3` of the frame; each cycle's mean frame voltage is the EMF `j w_r psi(0)` (what is odd in the current, the dead-time voltage among it, cancels between the halves); the slip of its angle gives the rotor's speed and d axis, the frame is put on the rotor, and `psi_d(0, 0) = |E| / |w_r|` over at least 60 ms (`coast.rs`) |
//! | [`MapPart::Stop`] | back to standstill | the frame put on the rotor's d axis, the spin current along it (integrators preset to `Rs I_f` and `w psi_f`), the frame speed ramped to zero at `spin_accel_rad_s2` (jerk-limited, as the spin's ramp) |
//! | [`MapPart::Realign`] | rotor to a known angle | the spin current along the frame, now at rest, with the q voltage at zero (the swinging rotor's EMF drives a braking current, as in the alignment) for `align_time_s`; the probe's angle is the mean current's angle over the last fifth (the dead-time voltage turns the current, and the rotor with it, off the frame) |
//! | [`MapPart::Probe`] | the flux map | [`SaturationProbe`] told what was measured: `Rs`, the inverter voltage error, `Ld`, `Lq`, the coast's `psi_f`, `J` (0 without the inertia move: the rotor's motion is then not followed), the current offsets, the pole pairs; its grid `n_d x n_q` up to `+-i_max_a` ([`FluxMapStep`]) |
//!
//! Why the coast: the spin's `psi_f` is taken at the spin current and corrected with the
//! small-signal `Ld`, which the injection measures at the test current's d bias; on a
//! saturating motor both are off (5 % high on pmsm-sim's interior PM motor), and the probe's
//! `psi_d` samples carry the anchor's error. Why the square wave and not zero current: at
//! zero current the dead-time voltage is not defined (the loops settle on a residual current
//! whose direction sets the phases' signs, and the bridge loses the full dead-time voltage
//! along it), and the rotor does not turn at the frame's speed (the I/f drive leaves it
//! swinging): both errors are several per cent of `psi_f` (`coast.rs`).
//!
//! The step needs the spin ([`IdentifyConfig::spin_speed_rad_s`] `> 0`): without `psi_f`
//! the probe has no anchor for `psi_d`. It is kept out of [`Identifier`] (its state, about
//! 1 KB, would grow every identifier, and the board's firmware does not run it):
//! [`Identifier`], [`IdentifyStep`] and [`Identified`] are the same with and without it. Its
//! time is counted apart ([`IdentifyWithMap::map_ticks`]); the coast takes 20 ms and eight
//! cycles of `2 pi/3` at the spin speed (0.16 s on the interior PM motor), the stop about 1.3 x
//! the spin's ramp time, `align_time_s` and the probe (0.2-0.3 s on the
//! reference motors), measured in `docs/identify.md`.

use crate::controller::TickInput;
use crate::pi::{Pi, PiGains};
use crate::svpwm::SAFE_DUTIES;
use crate::transforms::AlphaBeta;
use crate::trig::{atan2, sin_cos, sqrt};

use super::coast::Coast;
use super::context::{Context, HoldLoop, Saturation};
use super::if_drive::{IfDrive, Move};
use super::numeric::ticks;
use super::saturation::{FluxSamples, SaturationConfig, SaturationError, SaturationProbe};
use super::{
    Identified, Identifier, IdentifyConfig, IdentifyError, IdentifyFailure, IdentifyOutput,
    IdentifyStep,
};

use super::numeric::INV_SQRT3;

/// Settings of the flux-map step (module docs).
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct FluxMapStep {
    /// Largest current of each axis of the grid, A (about 1.5-2x rated).
    pub i_max_a: f32,
    /// Number of d levels (odd, 3..=7).
    pub n_d: usize,
    /// Number of q levels (odd, 3..=9).
    pub n_q: usize,
}

impl FluxMapStep {
    /// A 7 x 9 grid up to `+-i_max_a`.
    pub fn new(i_max_a: f32) -> Self {
        Self {
            i_max_a,
            n_d: 7,
            n_q: 9,
        }
    }
}

/// The part of the whole run in progress.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum MapPart {
    /// A step of the identification sequence.
    Identify(IdentifyStep),
    /// Zero current at the spin speed: `psi_f` from the EMF.
    Coast,
    /// The frame decelerates to standstill.
    Stop,
    /// The rotor is held at the frame's angle.
    Realign,
    /// The flux-map probe.
    Probe,
    /// Finished or failed: PWM off.
    Done,
}

impl MapPart {
    /// A short name: the step's ([`IdentifyStep::name`]), `"stop"`, `"realign"`,
    /// `"flux_map"`, `"done"`.
    pub fn name(self) -> &'static str {
        match self {
            MapPart::Identify(s) => s.name(),
            MapPart::Coast => "coast",
            MapPart::Stop => "stop",
            MapPart::Realign => "realign",
            MapPart::Probe => "flux_map",
            MapPart::Done => "done",
        }
    }
}

/// Why the flux-map step stopped (the identification itself succeeded).
#[derive(Clone, Copy, Debug, PartialEq)]
pub enum FluxMapError {
    /// The identification has no `psi_f` (no spin).
    NoFluxLinkage,
    /// A setting of the step out of range (its name).
    Config(&'static str),
    /// A fault while stopping or re-aligning (the identification's checks).
    Drive(IdentifyError),
    /// The probe's own error.
    Probe(SaturationError),
}

impl core::fmt::Display for FluxMapError {
    fn fmt(&self, f: &mut core::fmt::Formatter<'_>) -> core::fmt::Result {
        match self {
            Self::NoFluxLinkage => write!(
                f,
                "flux-map step: the identification measured no flux linkage (the spin is off)"
            ),
            Self::Config(name) => write!(f, "flux-map step setting out of range: {name}"),
            Self::Drive(e) => write!(f, "flux-map step (stop or re-align): {e}"),
            Self::Probe(e) => write!(f, "{e}"),
        }
    }
}

#[derive(Clone, Debug)]
#[allow(clippy::large_enum_variant)]
enum State {
    Identify,
    /// The square wave of current along the turning frame (module `coast`).
    Coast(Coast),
    Stop {
        drive: IfDrive,
        n: u32,
    },
    /// `i_sum`: the current summed over the last fifth (its angle is the rotor's d axis).
    Realign {
        hold: HoldLoop,
        n: u32,
        i_sum: AlphaBeta,
    },
    Probe(SaturationProbe),
    Done,
}

/// The identification followed by the flux-map step (module docs).
#[derive(Clone, Debug)]
pub struct IdentifyWithMap {
    id: Identifier,
    map_cfg: FluxMapStep,
    state: State,
    /// Last voltage the identification applied (the stop's preset), V.
    u_prev: AlphaBeta,
    /// Ticks of the coast and the stop, the re-alignment and the probe.
    map_ticks: [u32; 3],
    /// `psi_f` at zero current (the coast), Wb.
    psi_f0: Option<f32>,
    /// The rotor's electrical speed the coast measured, rad/s.
    coast_w: Option<f32>,
    map: Option<Result<FluxSamples, FluxMapError>>,
}

impl IdentifyWithMap {
    /// The sequence with the settings `cfg` (checked: [`FluxMapError::Drive`]; the spin must
    /// be on: [`FluxMapError::NoFluxLinkage`]) and the flux-map step `map` (its grid checked:
    /// [`FluxMapError::Config`]).
    pub fn new(cfg: &IdentifyConfig, map: &FluxMapStep) -> Result<Self, FluxMapError> {
        let id = Identifier::new(cfg).map_err(FluxMapError::Drive)?;
        if cfg.spin_speed_rad_s <= 0.0 {
            return Err(FluxMapError::NoFluxLinkage);
        }
        let probe = probe_config(&id.ctx, map, 1.0, 0.0, None);
        probe.validate().map_err(FluxMapError::Config)?;
        Ok(Self {
            id,
            map_cfg: *map,
            state: State::Identify,
            u_prev: AlphaBeta::default(),
            map_ticks: [0; 3],
            psi_f0: None,
            coast_w: None,
            map: None,
        })
    }

    /// The identification (its result, steps and ticks).
    pub fn identifier(&self) -> &Identifier {
        &self.id
    }

    /// The identification's outcome, once it finished.
    pub fn identified(&self) -> Option<&Result<Identified, IdentifyFailure>> {
        self.id.result()
    }

    /// The flux map, once the step finished.
    pub fn flux_map(&self) -> Option<&Result<FluxSamples, FluxMapError>> {
        self.map.as_ref()
    }

    /// `psi_f` measured at zero current by the coast (what the probe is told), Wb.
    pub fn psi_f_zero_current_wb(&self) -> Option<f32> {
        self.psi_f0
    }

    /// The rotor's electrical speed the coast measured (the frame's speed corrected by the
    /// slip of the EMF's angle), rad/s.
    pub fn coast_speed_rad_s(&self) -> Option<f32> {
        self.coast_w
    }

    /// Ticks of the coast and the stop, the re-alignment and the probe.
    pub fn map_ticks(&self) -> [u32; 3] {
        self.map_ticks
    }

    /// Ticks since construction (identification and flux-map step).
    pub fn ticks(&self) -> u32 {
        self.id.ticks()
    }

    /// Whether everything has finished (success or failure).
    pub fn is_done(&self) -> bool {
        matches!(self.state, State::Done)
    }

    /// The part in progress.
    pub fn part(&self) -> MapPart {
        match &self.state {
            State::Identify => MapPart::Identify(self.id.step()),
            State::Coast(_) => MapPart::Coast,
            State::Stop { .. } => MapPart::Stop,
            State::Realign { .. } => MapPart::Realign,
            State::Probe(_) => MapPart::Probe,
            State::Done => MapPart::Done,
        }
    }

    /// An upper bound of the identification's length, s (the probe's length depends on the
    /// motor; allow about 1 s more for it).
    pub fn max_duration_s(&self) -> f32 {
        let c = self.id.config();
        self.id.max_duration_s()
            + Coast::max_ticks(c.spin_speed_rad_s, c.ts_s) as f32 * c.ts_s
            + 1.3 * 1.4 * c.spin_speed_rad_s / c.spin_accel_rad_s2
            + c.align_time_s
    }

    fn finish(&mut self, map: Result<FluxSamples, FluxMapError>) {
        self.map = Some(map);
        self.state = State::Done;
    }

    /// One PWM period: the identification's tick, then the stop, the re-alignment and the
    /// probe. During the flux-map step the output's `step` is [`IdentifyStep::Done`] (the
    /// sequence is over; [`part`](Self::part) names the part).
    pub fn tick(&mut self, input: &TickInput) -> IdentifyOutput {
        let i_ab = match &mut self.state {
            State::Identify => {
                let out = self.id.tick(input);
                match self.id.result() {
                    None => {
                        self.u_prev = out.u_ab;
                        return out;
                    }
                    Some(Err(_)) => {
                        self.state = State::Done;
                        return out;
                    }
                    Some(Ok(r)) if r.psi_f_wb.is_none() => {
                        self.finish(Err(FluxMapError::NoFluxLinkage));
                        return out;
                    }
                    Some(Ok(_)) => {
                        // The spin's drive goes on in this very tick.
                        let w = self.id.ctx.frame.omega;
                        self.state = State::Coast(Coast::new(self.coast_drive(), w));
                        out.i_ab
                    }
                }
            }
            State::Probe(p) => {
                self.id.tick = self.id.tick.wrapping_add(1);
                let o = p.tick(input);
                self.map_ticks[2] = p.ticks();
                if let Some(r) = p.result().copied() {
                    self.finish(r.map_err(FluxMapError::Probe));
                }
                return IdentifyOutput {
                    duties: o.duties,
                    pwm_enabled: o.pwm_enabled,
                    step: IdentifyStep::Done,
                    i_ab: o.i_ab,
                    u_ab: o.u_ab,
                    frame_angle_rad: self.id.ctx.frame.angle,
                    frame_speed_rad_s: 0.0,
                };
            }
            State::Done => {
                self.id.tick = self.id.tick.wrapping_add(1);
                return self.off(AlphaBeta::default());
            }
            State::Coast(_) | State::Stop { .. } | State::Realign { .. } => {
                self.id.tick = self.id.tick.wrapping_add(1);
                match self.check(input) {
                    Ok(i) => i,
                    Err(e) => {
                        self.finish(Err(FluxMapError::Drive(e)));
                        return self.off(AlphaBeta::default());
                    }
                }
            }
        };
        match self.drive_tick(i_ab) {
            Ok(Some(u)) => self.modulate(u, i_ab, input.u_dc_v),
            Ok(None) => self.off(i_ab),
            Err(e) => {
                self.finish(Err(FluxMapError::Drive(e)));
                self.off(i_ab)
            }
        }
    }

    /// The loops of the coast: the spin's gains, preset to the last voltage the sequence
    /// applied (no tick with the PWM off).
    fn coast_drive(&self) -> IfDrive {
        let ctx = &self.id.ctx;
        let (cfg, f) = (&ctx.cfg, &ctx.found);
        let bw = cfg.current_bw_rad_s;
        let ki = f.rs * bw;
        let mut pi_d = Pi::new(PiGains { kp: f.ld * bw, ki }, cfg.ts_s);
        let mut pi_q = Pi::new(PiGains { kp: f.lq * bw, ki }, cfg.ts_s);
        let w = ctx.frame.omega;
        // The voltage was rotated ahead by (d + 1/2) w Ts: back to the frame.
        let adv = (ctx.d as f32 + 0.5) * w * cfg.ts_s;
        let (s, c) = sin_cos(ctx.frame.angle + adv);
        pi_d.set_integrator(c * self.u_prev.alpha + s * self.u_prev.beta);
        pi_q.set_integrator(-s * self.u_prev.alpha + c * self.u_prev.beta);
        IfDrive {
            pi_d,
            pi_q,
            mv: Move::new(-w, cfg.spin_accel_rad_s2, cfg.ts_s),
            sat: Saturation::default(),
        }
    }

    /// The input checks of the identification; the currents with the offsets removed.
    fn check(&mut self, input: &TickInput) -> Result<AlphaBeta, IdentifyError> {
        let i_ab = super::numeric::less_offsets(input.currents, self.id.ctx.found.offsets);
        let u_dc = input.u_dc_v;
        if !(u_dc.is_finite() && i_ab.alpha.is_finite() && i_ab.beta.is_finite()) {
            return Err(IdentifyError::NonFiniteInput);
        }
        let cfg = &self.id.ctx.cfg;
        let i_mag = sqrt(i_ab.norm_squared());
        if i_mag > cfg.over_current_a {
            return Err(IdentifyError::OverCurrent { current_a: i_mag });
        }
        if u_dc > cfg.u_dc_max_v {
            return Err(IdentifyError::BusOverVoltage { u_dc_v: u_dc });
        }
        if u_dc < cfg.u_dc_min_v {
            return Err(IdentifyError::BusUnderVoltage { u_dc_v: u_dc });
        }
        self.id.ctx.u_lim = cfg.max_modulation * u_dc * INV_SQRT3;
        Ok(i_ab)
    }

    /// One tick of the stop or the re-alignment: the voltage (`None`: the probe starts next
    /// tick, PWM off for this one is not needed, so never `None` here).
    fn drive_tick(&mut self, i_ab: AlphaBeta) -> Result<Option<AlphaBeta>, IdentifyError> {
        let ctx = &mut self.id.ctx;
        let ts = ctx.cfg.ts_s;
        match &mut self.state {
            State::Coast(coast) => {
                let (u, done) = coast.tick(ctx, i_ab)?;
                if let Some(r) = done {
                    self.psi_f0 = Some(r.psi_wb);
                    self.coast_w = Some(r.w_r);
                    self.map_ticks[0] = coast.n;
                    // The frame on the rotor's d axis, at its speed.
                    ctx.frame.set(ctx.frame.angle + r.delta);
                    ctx.frame.omega = r.w_r;
                    let (f, cfg) = (&ctx.found, &ctx.cfg);
                    let i_f = cfg.spin_current_a;
                    let mut drive = coast.drive;
                    drive
                        .pi_d
                        .set_integrator(f.rs * i_f + f.v_err * i_f / cfg.test_current_a);
                    drive.pi_q.set_integrator(r.w_r * r.psi_wb);
                    drive.mv = Move::new(-r.w_r, cfg.spin_accel_rad_s2, ts);
                    self.state = State::Stop { drive, n: 0 };
                }
                Ok(Some(u))
            }
            State::Stop { drive, n } => {
                let k = *n;
                *n += 1;
                let t = drive.step(ctx, i_ab, k, true)?;
                ctx.frame.set(ctx.frame.angle + t.w * ts);
                if *n >= drive.mv.len() {
                    ctx.frame.omega = 0.0;
                    self.map_ticks[0] += *n;
                    let hold = HoldLoop {
                        pi: drive.pi_d,
                        sat: Saturation::default(),
                    };
                    self.state = State::Realign {
                        hold,
                        n: 0,
                        i_sum: AlphaBeta::default(),
                    };
                }
                Ok(Some(t.u))
            }
            State::Realign { hold, n, i_sum } => {
                *n += 1;
                let u = hold.hold(ctx, i_ab, ctx.cfg.spin_current_a)?;
                let len = ticks(ctx.cfg.align_time_s, ts);
                if 5 * *n >= 4 * len {
                    *i_sum = *i_sum + i_ab;
                }
                if *n >= len {
                    self.map_ticks[1] = *n;
                    let f = &ctx.found;
                    let cfg = probe_config(
                        ctx,
                        &self.map_cfg,
                        self.psi_f0.or(f.psi).unwrap_or(0.0),
                        atan2(i_sum.beta, i_sum.alpha),
                        f.j,
                    );
                    match SaturationProbe::new(&cfg) {
                        Ok(p) => self.state = State::Probe(p),
                        Err(e) => {
                            self.finish(Err(FluxMapError::Probe(e)));
                            return Ok(None);
                        }
                    }
                }
                Ok(Some(u))
            }
            _ => Ok(None),
        }
    }

    fn modulate(&self, u: AlphaBeta, i_ab: AlphaBeta, u_dc: f32) -> IdentifyOutput {
        let ctx = &self.id.ctx;
        let m = super::numeric::limited_svpwm(u, ctx.u_lim, u_dc);
        IdentifyOutput {
            duties: m.duties,
            pwm_enabled: true,
            step: IdentifyStep::Done,
            i_ab,
            u_ab: m.applied,
            frame_angle_rad: ctx.frame.angle,
            frame_speed_rad_s: ctx.frame.omega,
        }
    }

    fn off(&self, i_ab: AlphaBeta) -> IdentifyOutput {
        IdentifyOutput {
            duties: SAFE_DUTIES,
            pwm_enabled: false,
            step: IdentifyStep::Done,
            i_ab,
            u_ab: AlphaBeta::default(),
            frame_angle_rad: self.id.ctx.frame.angle,
            frame_speed_rad_s: 0.0,
        }
    }
}

/// The probe's settings from what the sequence found (module docs).
fn probe_config(
    ctx: &Context,
    map: &FluxMapStep,
    psi_f: f32,
    theta: f32,
    j: Option<f32>,
) -> SaturationConfig {
    let (c, f) = (&ctx.cfg, &ctx.found);
    let l = |x: f32| if x > 0.0 { x } else { 1e-3 };
    let mut p = SaturationConfig::new(c.ts_s, f.rs, theta, psi_f, (l(f.ld), l(f.lq)), map.i_max_a);
    p.delay = c.delay;
    p.voltage_error_v = f.v_err;
    p.n_d = map.n_d;
    p.n_q = map.n_q;
    p.current_bw_rad_s = c.current_bw_rad_s;
    p.max_modulation = c.max_modulation;
    p.current_offsets_a = f.offsets;
    p.inertia_kg_m2 = j.unwrap_or(0.0);
    p.pole_pairs = c.pole_pairs;
    p
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn refuses_without_the_spin_and_a_bad_grid() {
        let cfg = IdentifyConfig::new(1e-4, 24.0, 2.0);
        assert!(matches!(
            IdentifyWithMap::new(&cfg, &FluxMapStep::new(4.0)),
            Err(FluxMapError::NoFluxLinkage)
        ));
        let spin = cfg.with_spin(100.0, 250.0);
        let mut bad = FluxMapStep::new(4.0);
        bad.n_d = 4;
        assert_eq!(
            IdentifyWithMap::new(&spin, &bad).err(),
            Some(FluxMapError::Config("n_d"))
        );
        assert!(matches!(
            IdentifyWithMap::new(&spin, &FluxMapStep::new(f32::NAN)),
            Err(FluxMapError::Config("i_max_a"))
        ));
        let m = IdentifyWithMap::new(&spin, &FluxMapStep::new(4.0)).unwrap();
        assert_eq!(m.part(), MapPart::Identify(IdentifyStep::Offsets));
        assert!(m.flux_map().is_none() && !m.is_done());
    }
}
