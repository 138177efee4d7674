//! The full controller tick in closed loop: `foc::Foc` runs a small on-target plant of the servo
//! motor from standstill through align, I/f ramp and hand-over into sensorless closed loop at
//! 1000 rpm, 20 kHz PWM, 300 V bus, with the one-period computation delay of a real inverter.
//! Instructions per `tick` are tallied by controller state; the run checks that closed loop was
//! reached without a fault and that the speed settled.
//!
//! The plant is forward Euler with 8 substeps per period in `f32`: good enough to exercise the
//! controller's real code paths, not a reference (the desktop simulator is).

use cortex_m_semihosting::hprintln;
use foc::ekf_core::MotorParams;
use foc::ekf_core::catalog::SERVO;
use foc::{
    AlphaBeta, Foc, FocConfig, HfiConfig, HfiPhase, State, TickInput, TickOutput,
    duties_to_alpha_beta,
};

use crate::meter::{Clock, Tally};

const TS_S: f32 = 50e-6;
const U_DC_V: f32 = SERVO.u_dc_v as f32;
const SPEED_REF_MECH_RAD_S: f32 = 104.719_76; // 1000 rpm
const TICKS: u32 = 24_000; // 1.2 s

/// Markers around the counted closed-loop ticks of [`run`] for an instruction trace
/// (feature `trace`; `crates/foc-firmware/trace_tick.py` reads QEMU's execution log between
/// a `begin` that was passed `true` and the next `end`).
#[cfg(feature = "trace")]
pub mod trace {
    /// Start of a tick; `on`: the tick is to be traced.
    #[inline(never)]
    pub fn begin(on: bool) {
        if on {
            on_mark();
        }
    }

    #[inline(never)]
    fn on_mark() {
        // SAFETY: a no-op instruction; it only gives the marker an address of its own.
        unsafe { core::arch::asm!("nop", "nop", options(nomem, nostack)) };
    }

    /// End of a tick.
    #[inline(never)]
    pub fn end() {
        // SAFETY: as above.
        unsafe { core::arch::asm!("nop", "nop", "nop", options(nomem, nostack)) };
    }
}

/// What the drive keeps of a tick's output, as an interrupt handler would: the duties, the
/// PWM enable, state and fault, and the few telemetry values the runs check. Taken inside
/// the counted call; keeping the whole 116-byte `TickOutput` in a captured place instead
/// adds a `memcpy` of it, about 117 instructions, to every count (as before this struct).
#[derive(Clone, Copy, Debug, Default)]
struct Used {
    duties: [f32; 3],
    pwm_enabled: bool,
    state: State,
    fault: Option<foc::Fault>,
    u_ab: AlphaBeta,
    i_d_ref: f32,
    theta_rad: f32,
}

impl From<TickOutput> for Used {
    #[inline(always)]
    fn from(o: TickOutput) -> Self {
        Self {
            duties: o.duties,
            pwm_enabled: o.pwm_enabled,
            state: o.state,
            fault: o.fault,
            u_ab: o.telemetry.u_ab,
            i_d_ref: o.telemetry.i_dq_ref.d,
            theta_rad: o.telemetry.theta_rad,
        }
    }
}

/// An on-target plant: the phase currents it shows the controller, and one period of it under
/// a held alpha-beta voltage (`on`: PWM enabled; off, the currents are zero).
trait DrivePlant {
    fn i_ab(&self) -> AlphaBeta;
    fn step(&mut self, u: AlphaBeta, on: bool);
}

/// What every drive run shares: `foc` started on a plant, the measured tick, the fault check
/// and the one-period delay of the duties.
struct Drive<P> {
    foc: Foc,
    plant: P,
    u_dc_v: f32,
    /// Duties computed at tick k, applied over the next period.
    pending: ([f32; 3], bool),
    /// Prefix of the fault line, and the error of a faulted run.
    name: &'static str,
    faulted: &'static str,
}

impl<P: DrivePlant> Drive<P> {
    /// Sets the speed reference and starts `foc` (configured, HFI enabled, by the caller).
    fn start(
        mut foc: Foc,
        plant: P,
        u_dc_v: f32,
        speed_ref_mech_rad_s: f32,
        (name, faulted): (&'static str, &'static str),
    ) -> Result<Self, &'static str> {
        foc.set_speed_ref_mech_rad_s(speed_ref_mech_rad_s)
            .map_err(|_| "speed reference refused")?;
        foc.start().map_err(|_| "start refused")?;
        Ok(Self {
            foc,
            plant,
            u_dc_v,
            pending: ([0.5_f32; 3], false),
            name,
            faulted,
        })
    }

    /// The tick's input: the plant's currents as three phase readings.
    fn input(&self) -> TickInput {
        let abc = self.plant.i_ab().to_abc();
        TickInput::abc(abc.a, abc.b, abc.c, self.u_dc_v)
    }

    /// One measured `tick` on the plant's currents: its instruction count and what an
    /// interrupt handler keeps of its output ([`Used`]). `traced`: between the markers of
    /// the instruction trace (feature `trace`).
    fn tick(&mut self, clock: &Clock, traced: bool) -> (u32, Used) {
        let input = self.input();
        let foc = &mut self.foc;
        let mut out = Used::default();
        #[cfg(feature = "trace")]
        trace::begin(traced);
        #[cfg(not(feature = "trace"))]
        let _ = traced;
        let n = clock.count(&mut || out = Used::from(foc.tick(&input)));
        #[cfg(feature = "trace")]
        trace::end();
        (n, out)
    }

    /// Ends period `k`: `Err` on a fault, else the plant runs one period on the duties of
    /// the tick before.
    fn advance(&mut self, out: &Used, k: u32) -> Result<(), &'static str> {
        if out.fault.is_some() {
            hprintln!(
                "{}: fault {:?} at tick {}",
                self.name,
                self.foc.fault_info(),
                k
            );
            return Err(self.faulted);
        }
        let applied = core::mem::replace(&mut self.pending, (out.duties, out.pwm_enabled));
        self.plant.step(
            duties_to_alpha_beta(applied.0, self.u_dc_v),
            applied.1 && out.pwm_enabled,
        );
        Ok(())
    }
}

/// The catalog's servo motor with its mechanics.
struct Plant {
    ia: f32,
    ib: f32,
    w_mech: f32,
    th: f32,
}

impl DrivePlant for Plant {
    fn i_ab(&self) -> AlphaBeta {
        AlphaBeta {
            alpha: self.ia,
            beta: self.ib,
        }
    }

    fn step(&mut self, u: AlphaBeta, on: bool) {
        let (rs, ls, psi, p, j, b) = (
            SERVO.rs_ohm as f32,
            SERVO.ld_h as f32,
            SERVO.psi_f_wb as f32,
            SERVO.pole_pairs as f32,
            SERVO.j_kg_m2 as f32,
            SERVO.b_nm_s_rad as f32,
        );
        if !on {
            self.ia = 0.0;
            self.ib = 0.0;
        }
        let h = TS_S / 8.0;
        for _ in 0..8 {
            let we = p * self.w_mech;
            let (s, c) = foc::trig::sin_cos(self.th);
            if on {
                self.ia += h * (-rs * self.ia + we * psi * s + u.alpha) / ls;
                self.ib += h * (-rs * self.ib - we * psi * c + u.beta) / ls;
            }
            let torque = 1.5 * p * psi * (-self.ia * s + self.ib * c);
            self.w_mech += h * (torque - b * self.w_mech) / j;
            self.th = foc::trig::wrap(self.th + h * we);
        }
    }
}

/// Runs the drive and prints `cortex-m4 foc_tick: N instructions/call` (closed loop, the
/// budgeted figure) and one line per start-up state. `Err` when the drive failed.
pub fn run(clock: &Clock) -> Result<(), &'static str> {
    run_start(clock, false)
}

/// As [`run`] with foc's damped start (`StartupConfig::damping_ratio` 1, `kick_speed_ratio`
/// 0.2: kick, coast and launch, damped I/f): prints `foc_tick_align_damped`,
/// `foc_tick_openloop_damped` and `foc_tick_handover_damped` (and the closed-loop tick as
/// `foc_tick_closed_loop_damped`).
pub fn run_damped(clock: &Clock) -> Result<(), &'static str> {
    run_start(clock, true)
}

fn run_start(clock: &Clock, damped: bool) -> Result<(), &'static str> {
    let mut cfg =
        FocConfig::new(MotorParams::servo(), TS_S, U_DC_V).with_inertia(SERVO.j_kg_m2 as f32);
    if damped {
        cfg.startup.damping_ratio = 1.0;
        cfg.startup.kick_speed_ratio = 0.2;
    }
    let foc = Foc::new(&cfg).map_err(|_| "foc config refused")?;
    let plant = Plant {
        ia: 0.0,
        ib: 0.0,
        w_mech: 0.0,
        th: 1.0,
    };
    let names = ("foc_tick", "the drive faulted");
    let mut drive = Drive::start(foc, plant, U_DC_V, SPEED_REF_MECH_RAD_S, names)?;
    let mut tallies = [Tally::new(), Tally::new(), Tally::new(), Tally::new()];
    // The closed-loop tick split in two: its observer step, counted again on a copy of the
    // observer with the tick's own inputs, and the rest (tick minus that step).
    let (mut obs_tally, mut rest_tally) = (Tally::new(), Tally::new());
    let mut obs_mismatch = 0u32;
    // Realized voltages of ticks k-1 and k-2 (the tick's observer input with the one-period
    // delay is the older one).
    let mut u_hist = [AlphaBeta::default(); 2];
    let mut closed_loop_at = None;
    for k in 0..TICKS {
        let state = drive.foc.state();
        // The observer as the tick finds it, stepped with the tick's inputs (closed loop,
        // undamped run): the same code path, so the same count; the copy is checked to end
        // where the tick's observer does, bit for bit.
        let split = !damped && state == State::ClosedLoop;
        let mut obs_copy = split.then(|| drive.foc.observer().clone());
        let i_ab = drive.plant.i_ab().to_abc().to_alpha_beta();
        let (u_prev, i_obs) = ([u_hist[1].alpha, u_hist[1].beta], [i_ab.alpha, i_ab.beta]);
        let n_obs = obs_copy.as_mut().map(|o| {
            clock.count(&mut || {
                let _ = o.step(u_prev, i_obs);
            })
        });
        let (n, out) = drive.tick(clock, split);
        u_hist = [out.u_ab, u_hist[0]];
        if let Some(n_obs) = n_obs {
            if obs_copy.as_ref() != Some(drive.foc.observer()) {
                obs_mismatch += 1;
            }
            obs_tally.push(n_obs);
            rest_tally.push(n.saturating_sub(n_obs));
        }
        let slot = match state {
            State::Align => Some(0),
            State::OpenLoop => Some(1),
            State::Handover => Some(2),
            State::ClosedLoop => Some(3),
            _ => None,
        };
        if let Some(t) = slot.and_then(|i| tallies.get_mut(i)) {
            t.push(n);
        }
        if out.state == State::ClosedLoop && closed_loop_at.is_none() {
            closed_loop_at = Some(k);
        }
        drive.advance(&out, k)?;
    }
    let (foc, plant) = (&drive.foc, &drive.plant);
    let speed_err = plant.w_mech - SPEED_REF_MECH_RAD_S;
    hprintln!(
        "foc_tick: closed loop at tick {:?} ({} s), final speed {} rad/s mech (ref {}), error {}",
        closed_loop_at,
        closed_loop_at.map_or(-1.0, |k| k as f32 * TS_S),
        plant.w_mech,
        SPEED_REF_MECH_RAD_S,
        speed_err
    );
    if damped {
        tallies[3].report("foc_tick_closed_loop_damped");
        tallies[0].report("foc_tick_align_damped");
        tallies[1].report("foc_tick_openloop_damped");
        tallies[2].report("foc_tick_handover_damped");
    } else {
        tallies[3].report("foc_tick");
        obs_tally.report("foc_tick_observer");
        rest_tally.report("foc_tick_rest");
        tallies[0].report("foc_tick_align");
        tallies[1].report("foc_tick_openloop");
        tallies[2].report("foc_tick_handover");
        if obs_mismatch > 0 {
            hprintln!(
                "foc_tick_observer: the copy's estimate differed from the tick's {} times",
                obs_mismatch
            );
            return Err("the observer split of foc_tick does not reproduce the tick's step");
        }
    }
    if closed_loop_at.is_none() || foc.state() != State::ClosedLoop {
        return Err("the drive did not reach sensorless closed loop");
    }
    if speed_err.abs() > 2.0 {
        return Err("the drive's speed did not settle within 2 rad/s");
    }
    Ok(())
}

/// Interior PMSM (`MotorParams::industrial_ipm`, Ld 30 mH, Lq 42 mH) with its mechanics, in
/// the rotor frame (forward Euler, 8 substeps per period, `f32`).
struct SalientPlant {
    id: f32,
    iq: f32,
    w_mech: f32,
    th: f32,
}

/// `industrial_ipm` run: 20 kHz, 540 V bus, current limit 12 A, inertia 0.015 kg m^2, viscous
/// friction 0.014 N m s (the I/f start of the defaults needs the damping).
const IPM_U_DC_V: f32 = 540.0;
const IPM_J: f32 = 0.015;
const IPM_TICKS: u32 = 36_000; // 1.8 s

impl DrivePlant for SalientPlant {
    fn step(&mut self, u: AlphaBeta, on: bool) {
        let (rs, ld, lq, psi, p, b) = (3.6_f32, 30e-3_f32, 42e-3_f32, 0.5_f32, 3.0_f32, 1.4e-2_f32);
        if !on {
            self.id = 0.0;
            self.iq = 0.0;
        }
        let h = TS_S / 8.0;
        for _ in 0..8 {
            let we = p * self.w_mech;
            let (s, c) = foc::trig::sin_cos(self.th);
            if on {
                let ud = u.alpha * c + u.beta * s;
                let uq = -u.alpha * s + u.beta * c;
                let did = (ud - rs * self.id + we * lq * self.iq) / ld;
                let diq = (uq - rs * self.iq - we * (ld * self.id + psi)) / lq;
                self.id += h * did;
                self.iq += h * diq;
            }
            let torque = 1.5 * p * (psi + (ld - lq) * self.id) * self.iq;
            self.w_mech += h * (torque - b * self.w_mech) / IPM_J;
            self.th = foc::trig::wrap(self.th + h * we);
        }
    }

    fn i_ab(&self) -> AlphaBeta {
        let (s, c) = foc::trig::sin_cos(self.th);
        AlphaBeta {
            alpha: self.id * c - self.iq * s,
            beta: self.id * s + self.iq * c,
        }
    }
}

/// `industrial_ipm` at [`IPM_U_DC_V`]: current limit 12 A, over-current trip 24 A, inertia
/// [`IPM_J`].
fn ipm_config() -> FocConfig {
    let mut cfg = FocConfig::new(MotorParams::industrial_ipm(), TS_S, IPM_U_DC_V);
    cfg.current_limit_a = 12.0;
    cfg.over_current_a = 24.0;
    cfg.with_inertia(IPM_J)
}

/// The interior motor sensorless from standstill to twice its base speed with MTPA and field
/// weakening: prints `foc_tick_ipm` (closed loop with field weakening engaged, above 1.5x
/// base speed) and `foc_tick_ipm_mtpa` (closed loop below base speed: MTPA, the
/// field-weakening loop running at its clamp). `Err` when the drive failed.
pub fn run_ipm(clock: &Clock) -> Result<(), &'static str> {
    let cfg = ipm_config();
    let base_mech = cfg.max_speed_rad_s / 3.0;
    let cfg = cfg.with_field_weakening(2.2);
    let foc = Foc::new(&cfg).map_err(|_| "foc config refused (ipm)")?;
    let target = 2.0 * base_mech;
    let plant = SalientPlant {
        id: 0.0,
        iq: 0.0,
        w_mech: 0.0,
        th: 1.0,
    };
    let names = ("foc_tick_ipm", "the ipm drive faulted");
    let mut drive = Drive::start(foc, plant, IPM_U_DC_V, target, names)?;
    let (mut fw, mut mtpa) = (Tally::new(), Tally::new());
    let mut weakened = false;
    for k in 0..IPM_TICKS {
        let state = drive.foc.state();
        let (n, out) = drive.tick(clock, false);
        if state == State::ClosedLoop {
            let w = drive.plant.w_mech;
            if w > 1.5 * base_mech {
                fw.push(n);
                // Field weakening engaged: a d current well beyond the MTPA one.
                weakened |= out.i_d_ref < -3.0;
            } else if w < 0.9 * base_mech && w > 0.2 * base_mech {
                mtpa.push(n);
            }
        }
        drive.advance(&out, k)?;
    }
    let (foc, plant) = (&drive.foc, &drive.plant);
    let speed_err = plant.w_mech - target;
    hprintln!(
        "foc_tick_ipm: industrial_ipm to 2x base speed ({} rad/s mech), final {} rad/s mech, i_d {} A, field weakening engaged: {}",
        target,
        plant.w_mech,
        plant.id,
        weakened
    );
    fw.report("foc_tick_ipm");
    mtpa.report("foc_tick_ipm_mtpa");
    if foc.state() != State::ClosedLoop || !weakened {
        return Err("the ipm drive did not reach field weakening in closed loop");
    }
    if speed_err.abs() > 0.01 * target {
        return Err("the ipm drive's speed did not settle within 1 %");
    }
    Ok(())
}

/// The interior motor held at standstill and then run slowly on high-frequency injection
/// (`foc::hfi`, defaults of `HfiConfig::new`, 20 kHz): prints `foc_tick_hfi` (closed loop on
/// the HFI angle alone: carrier, demodulation, tracking loop, observer and current loops) and
/// `foc_tick_hfi_blend` (in the hand-over band, HFI and observer angles blended). The on-target
/// plant has no saturation, so the polarity test is off and the rotor starts within 90 deg of
/// the tracker's start angle (0). `Err` when the drive failed.
pub fn run_ipm_hfi(clock: &Clock) -> Result<(), &'static str> {
    let cfg = ipm_config();
    let mut foc = Foc::new(&cfg).map_err(|_| "foc config refused (hfi)")?;
    let mut hfi = HfiConfig::new(&cfg, IPM_U_DC_V).map_err(|_| "hfi config refused")?;
    hfi.detect_polarity = false;
    foc.enable_hfi(&hfi, IPM_U_DC_V)
        .map_err(|_| "hfi refused")?;
    let plant = SalientPlant {
        id: 0.0,
        iq: 0.0,
        w_mech: 0.0,
        th: 0.3,
    };
    let names = ("foc_tick_hfi", "the hfi drive faulted");
    let mut drive = Drive::start(foc, plant, IPM_U_DC_V, 0.0, names)?;
    // Half-way through the blend band after 0.4 s.
    let blend_mech = 0.5 * (hfi.blend_low_rad_s + hfi.blend_high_rad_s) / 3.0;
    let (mut alone, mut blend) = (Tally::new(), Tally::new());
    let mut worst_deg = 0.0_f32;
    for k in 0..HFI_TICKS {
        if k == HFI_TICKS / 3 {
            drive
                .foc
                .set_speed_ref_mech_rad_s(blend_mech)
                .map_err(|_| "speed reference refused")?;
        }
        let status = drive.foc.hfi_status().ok_or("hfi off")?;
        let (n, out) = drive.tick(clock, false);
        if status.phase == HfiPhase::Tracking && out.state == State::ClosedLoop {
            if status.observer_weight == 0.0 && status.injecting {
                alone.push(n);
                let e = foc::trig::wrap(out.theta_rad - drive.plant.th).abs();
                worst_deg = if e * 57.3 > worst_deg {
                    e * 57.3
                } else {
                    worst_deg
                };
            } else if status.observer_weight > 0.0 && status.observer_weight < 1.0 {
                blend.push(n);
            }
        }
        drive.advance(&out, k)?;
    }
    let plant = &drive.plant;
    hprintln!(
        "foc_tick_hfi: industrial_ipm on HFI ({} V carrier, half period {} ticks), worst angle error on HFI alone {} deg, final {} rad/s mech (ref {})",
        hfi.injection_v,
        hfi.half_period_ticks,
        worst_deg,
        plant.w_mech,
        blend_mech
    );
    alone.report("foc_tick_hfi");
    blend.report("foc_tick_hfi_blend");
    if worst_deg > 20.0 || (plant.w_mech - blend_mech).abs() > 0.2 * blend_mech {
        return Err("the hfi drive lost its angle or speed");
    }
    Ok(())
}

/// Ticks of the HFI run (1.2 s at 20 kHz).
const HFI_TICKS: u32 = 24_000;
