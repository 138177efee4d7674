//! The control interrupt's body and the command handling, hardware-independent: the firmware
//! gives [`Control::period`] the raw ADC results of each PWM period and a bridge that
//! implements [`foc::hal::Inverter`]; the host tests give it numbers and a recording bridge.
//!
//! Per period ([`Control::period`]), by phase (module [`crate::state`]):
//!
//! - **calibrating**: PWM off; the raw current readings are averaged into the zero offsets;
//! - **ready / faulted**: PWM off; the measurements are kept for the checks before switching;
//! - **identifying**: [`foc::identify_period`] (the identifier drives the bridge);
//! - **running**: [`foc::hal::run_period`], which calls [`foc::Foc::tick`]: the tick the
//!   QEMU firmware counts.
//!
//! Every `every`-th period a telemetry frame is left for the main loop to send (the last one
//! wins; frames the UART could not take are counted in [`Control::dropped_frames`]).

use foc::ekf_core::Status;
use foc::hal::{CurrentSense, Inverter, run_period};
use foc::{Abc, Foc, PhaseCurrents, State, TickOutput};

use crate::command::Command;
use crate::config::{
    AMPS_PER_COUNT, CURRENT_ZERO_COUNTS, builtin_motor, bus_voltage_v, current_a, drive_config,
    temperature_c,
};
use crate::record::MotorRecord;
use crate::state::{
    Action, AnyFault, BoardFault, DriveState, Idle, OffsetCalibration, Phase, Supervisor,
    fault_code, state_code,
};
use crate::telemetry::{FLAG_OBSERVER_OK, FLAG_PWM, FLAG_SAMPLE_OK, FLAG_TRACKING, PeriodFrame};

/// The raw ADC results of one period.
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq)]
pub struct Raw {
    /// Phase currents a, b, c (op-amp outputs), counts.
    pub i: [u16; 3],
    /// Bus voltage divider, counts.
    pub vbus: u16,
    /// Temperature divider, counts.
    pub temp: u16,
}

/// One period's samples in SI units: what [`CurrentSense`] hands the controller.
struct Sample {
    i_abc_a: [f32; 3],
    u_dc_v: f32,
}

impl CurrentSense for Sample {
    fn currents(&mut self) -> PhaseCurrents {
        let [a, b, c] = self.i_abc_a;
        PhaseCurrents::Abc(Abc { a, b, c })
    }
    fn bus_voltage_v(&mut self) -> f32 {
        self.u_dc_v
    }
}

/// A command's reply: `Ok` text after `ok`, or the reason after `err`.
pub type Reply = Result<&'static str, &'static str>;

/// Where the drive's motor comes from.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum MotorSource {
    /// The flash record.
    Record,
    /// [`builtin_motor`].
    Builtin,
}

/// The controller, the identification and the supervisor (module docs).
pub struct Control {
    sup: Supervisor,
    foc: Foc,
    #[cfg(feature = "identify")]
    identify: Option<(foc::Identifier, u8)>,
    motor: MotorSource,
    cal: OffsetCalibration,
    zero: [f32; 3],
    idle: Idle,
    every: u16,
    count: u16,
    frame: Option<PeriodFrame>,
    dropped: u32,
    pending_record: Option<MotorRecord>,
    start_after_write: bool,
}

impl Control {
    /// After reset: the motor of `record` (or the built-in one), calibrating (or the
    /// watchdog fault latched).
    pub fn new(
        record: Option<MotorRecord>,
        watchdog_reset: bool,
    ) -> Result<Self, foc::ConfigError> {
        let (motor, j, source) = match record {
            Some(r) => (r.motor_params(), Some(r.j_kg_m2), MotorSource::Record),
            None => (builtin_motor(), None, MotorSource::Builtin),
        };
        let foc = Foc::new(&drive_config(motor, j))?;
        Ok(Self {
            sup: Supervisor::new(record.is_some(), watchdog_reset),
            foc,
            #[cfg(feature = "identify")]
            identify: None,
            motor: source,
            cal: OffsetCalibration::default(),
            zero: [CURRENT_ZERO_COUNTS; 3],
            idle: Idle {
                i_abc_a: [0.0; 3],
                u_dc_v: 0.0,
                temperature_c: 0.0,
            },
            every: 0,
            count: 0,
            frame: None,
            dropped: 0,
            pending_record: None,
            start_after_write: false,
        })
    }

    /// The supervisor.
    pub fn supervisor(&self) -> &Supervisor {
        &self.sup
    }

    /// The controller.
    pub fn foc(&self) -> &Foc {
        &self.foc
    }

    /// Where the motor in use comes from.
    pub fn motor_source(&self) -> MotorSource {
        self.motor
    }

    /// Telemetry frames overwritten before the main loop sent them.
    pub fn dropped_frames(&self) -> u32 {
        self.dropped
    }

    /// The telemetry divider (0: off).
    pub fn telemetry_every(&self) -> u16 {
        self.every
    }

    /// The measured zero readings of the current channels, counts.
    pub fn zero_counts(&self) -> [f32; 3] {
        self.zero
    }

    /// The last measurements with the PWM off.
    pub fn idle(&self) -> Idle {
        self.idle
    }

    /// One PWM period: the interrupt's body (module docs). Never panics.
    pub fn period<I: Inverter>(&mut self, raw: Raw, bridge: &mut I) {
        let i_abc_a = [0, 1, 2].map(|k| current_a(raw.i[k], self.zero[k]));
        let mut sample = Sample {
            i_abc_a,
            u_dc_v: bus_voltage_v(raw.vbus),
        };
        let temp = temperature_c(raw.temp);
        let mut frame = None;
        match self.sup.phase {
            Phase::Running => {
                let out = run_period(&mut self.foc, &mut sample, bridge);
                if self.due() {
                    frame = Some(self.drive_frame(&out, &sample, temp));
                }
                if out.state == State::Idle {
                    self.sup.drive_idle();
                }
            }
            #[cfg(feature = "identify")]
            Phase::Identifying { .. } => {
                let step = self.identify.as_mut().map(|(id, pole_pairs)| {
                    let out = foc::identify_period(id, &mut sample, bridge);
                    (out, id.is_done(), *pole_pairs)
                });
                match step {
                    Some((out, done, pole_pairs)) => {
                        if self.due() {
                            let tick = self.foc.tick_count();
                            frame = Some(identify_frame(&out, &sample, temp, tick));
                        }
                        if done {
                            bridge.enable(false);
                            self.finish_identify(pole_pairs);
                        }
                    }
                    None => bridge.enable(false),
                }
            }
            _ => {
                bridge.enable(false);
                bridge.set_duties(foc::SAFE_DUTIES);
                if self.sup.phase == Phase::Calibrating && self.cal.push(raw.i) {
                    let r = self.cal.result(CURRENT_ZERO_COUNTS, AMPS_PER_COUNT);
                    if let Ok(z) = r {
                        self.zero = z;
                    }
                    self.sup.calibrated(r);
                }
                self.idle = Idle {
                    i_abc_a: sample.i_abc_a,
                    u_dc_v: sample.u_dc_v,
                    temperature_c: temp,
                };
                if self.due() {
                    frame = Some(self.off_frame(&sample, temp));
                }
            }
        }
        if let Some(f) = frame
            && self.frame.replace(f).is_some()
        {
            self.dropped = self.dropped.wrapping_add(1);
        }
    }

    /// Whether this period sends a frame.
    fn due(&mut self) -> bool {
        if self.every == 0 {
            return false;
        }
        self.count += 1;
        if self.count >= self.every {
            self.count = 0;
            true
        } else {
            false
        }
    }

    #[cfg(feature = "identify")]
    fn finish_identify(&mut self, pole_pairs: u8) {
        let rec = match self
            .identify
            .take()
            .and_then(|(id, _)| id.result().copied())
        {
            Some(Ok(found)) => {
                MotorRecord::from_identified(&found, pole_pairs, crate::config::IDENTIFY_CURRENT_A)
                    .filter(|r| r.validate().is_ok())
            }
            _ => None,
        };
        match rec {
            Some(r) => {
                // The drive starts, if asked, once the record is in flash (a flash erase
                // stalls the CPU: never while switching).
                self.start_after_write =
                    matches!(self.sup.phase, Phase::Identifying { then_run: true });
                self.pending_record = Some(r);
            }
            None => {
                self.sup.identified(false);
            }
        }
    }

    /// The record to write to flash (after a successful identification). The main loop
    /// writes it with the PWM off, then calls [`Control::record_written`].
    pub fn take_record(&mut self) -> Option<MotorRecord> {
        self.pending_record.take()
    }

    /// The record is in flash (`Ok`) or its write failed: the controller takes the new
    /// motor, and starts if the identification was part of a `start`.
    pub fn record_written(&mut self, rec: MotorRecord, ok: bool) -> Reply {
        let cfg = drive_config(rec.motor_params(), Some(rec.j_kg_m2));
        match Foc::new(&cfg) {
            Ok(f) if ok => {
                self.foc = f;
                self.motor = MotorSource::Record;
                let run = self.sup.identified(true) && self.start_after_write;
                if run {
                    return self
                        .foc
                        .start()
                        .map(|()| "identified, running")
                        .map_err(|_| "start refused");
                }
                Ok("identified, record written")
            }
            Ok(_) => {
                self.sup.identified(false);
                Err("motor record write failed")
            }
            Err(_) => {
                self.sup.identified(false);
                Err("identified motor refused by the controller")
            }
        }
    }

    /// The frame left for the main loop, if any.
    pub fn take_frame(&mut self) -> Option<PeriodFrame> {
        self.frame.take()
    }

    /// The break input fired (the outputs are already off in hardware).
    pub fn broke(&mut self) {
        self.foc.disable();
        #[cfg(feature = "identify")]
        {
            self.identify = None;
        }
        self.sup.broke();
    }

    /// A command from the UART (main loop; called with the interrupt masked).
    pub fn command(&mut self, cmd: Command) -> Reply {
        let cfg = self.foc.config();
        let limits = (cfg.current_limit_a, cfg.over_current_a);
        let action = self
            .sup
            .command(cmd, &self.idle, limits, cfg!(feature = "identify"));
        match action {
            Action::Refuse(why) => Err(why),
            Action::StartDrive => self
                .foc
                .start()
                .map(|()| "started")
                .map_err(|_| "controller fault latched: clear first"),
            Action::StartIdentify { pole_pairs } => self.start_identify(pole_pairs),
            Action::Stop => {
                self.foc.stop();
                Ok("stopping")
            }
            Action::Off => {
                self.foc.disable();
                #[cfg(feature = "identify")]
                {
                    self.identify = None;
                }
                Ok("off")
            }
            Action::Clear => {
                self.foc.clear_fault();
                self.cal = OffsetCalibration::default();
                Ok("cleared")
            }
            Action::Speed(rpm) => {
                let w = rpm * (core::f32::consts::TAU / 60.0);
                self.foc
                    .set_speed_ref_mech_rad_s(w)
                    .map(|()| "speed set")
                    .map_err(|_| "speed not finite")
            }
            Action::Forget => {
                let r = Foc::new(&drive_config(builtin_motor(), None));
                if let Ok(f) = r {
                    self.foc = f;
                }
                self.motor = MotorSource::Builtin;
                Ok("forget")
            }
            Action::Telemetry(every) => {
                self.every = every;
                self.count = 0;
                Ok("telemetry")
            }
            Action::Status => Ok("status"),
        }
    }

    #[cfg(feature = "identify")]
    fn start_identify(&mut self, pole_pairs: u8) -> Reply {
        match foc::Identifier::new(&crate::config::identify_config(pole_pairs)) {
            Ok(id) => {
                self.identify = Some((id, pole_pairs));
                Ok("identifying")
            }
            Err(_) => {
                self.sup.identified(false);
                Err("identification settings refused")
            }
        }
    }

    #[cfg(not(feature = "identify"))]
    fn start_identify(&mut self, _pole_pairs: u8) -> Reply {
        Err("identify not built in")
    }

    /// The state and fault as telemetry codes.
    pub fn codes(&self) -> (u8, u8) {
        let state = match self.sup.phase {
            Phase::Calibrating => DriveState::Calibrate,
            Phase::Identifying { .. } => DriveState::Identify,
            _ => DriveState::Foc(self.foc.state()),
        };
        let fault = match (self.sup.fault(), self.foc.fault()) {
            (Some(b), _) => fault_code(AnyFault::Board(b)),
            (None, Some(f)) => fault_code(AnyFault::Foc(f)),
            (None, None) => 0,
        };
        (state_code(state), fault)
    }

    fn off_frame(&self, s: &Sample, temp: f32) -> PeriodFrame {
        let (state, fault) = self.codes();
        let e = self.foc.observer().estimate();
        PeriodFrame {
            tick: self.foc.tick_count(),
            state,
            fault,
            flags: FLAG_SAMPLE_OK,
            i_abc_a: s.i_abc_a,
            u_dc_v: s.u_dc_v,
            duties: foc::SAFE_DUTIES,
            est_theta_rad: e.theta_rad,
            est_omega_rad_s: e.omega_e_rad_s,
            psi_f_wb: e.psi_f_wb,
            rs_ohm: e.rs_ohm,
            temperature_c: temp,
            ..PeriodFrame::default()
        }
    }

    fn drive_frame(&self, out: &TickOutput, s: &Sample, temp: f32) -> PeriodFrame {
        let t = &out.telemetry;
        let (state, fault) = self.codes();
        let flags = if out.pwm_enabled { FLAG_PWM } else { 0 }
            | if t.observer_ok { FLAG_OBSERVER_OK } else { 0 }
            | if t.sample_ok { FLAG_SAMPLE_OK } else { 0 }
            | if t.estimate.status == Status::Tracking {
                FLAG_TRACKING
            } else {
                0
            };
        PeriodFrame {
            tick: self.foc.tick_count(),
            state,
            fault,
            flags,
            i_abc_a: s.i_abc_a,
            u_dc_v: s.u_dc_v,
            duties: out.duties,
            i_dq_a: [t.i_dq.d, t.i_dq.q],
            i_dq_ref_a: [t.i_dq_ref.d, t.i_dq_ref.q],
            u_dq_v: [t.u_dq.d, t.u_dq.q],
            u_ab_v: [t.u_ab.alpha, t.u_ab.beta],
            theta_rad: t.theta_rad,
            omega_rad_s: t.omega_rad_s,
            speed_ref_mech_rad_s: t.speed_ref_mech_rad_s,
            est_theta_rad: t.estimate.theta_rad,
            est_omega_rad_s: t.estimate.omega_e_rad_s,
            psi_f_wb: t.estimate.psi_f_wb,
            rs_ohm: t.estimate.rs_ohm,
            temperature_c: temp,
        }
    }

    /// Whether the controller is switching or about to (for the main loop's flash guard).
    pub fn switching(&self) -> bool {
        matches!(self.sup.phase, Phase::Identifying { .. })
            || (self.sup.phase == Phase::Running && self.foc.state() != State::Idle)
    }

    /// The latched board fault.
    pub fn board_fault(&self) -> Option<BoardFault> {
        self.sup.fault()
    }
}

#[cfg(feature = "identify")]
fn identify_frame(out: &foc::IdentifyOutput, s: &Sample, temp: f32, tick: u32) -> PeriodFrame {
    PeriodFrame {
        tick,
        state: state_code(DriveState::Identify),
        fault: 0,
        flags: crate::telemetry::FLAG_IDENTIFY
            | FLAG_SAMPLE_OK
            | if out.pwm_enabled { FLAG_PWM } else { 0 },
        i_abc_a: s.i_abc_a,
        u_dc_v: s.u_dc_v,
        duties: out.duties,
        u_ab_v: [out.u_ab.alpha, out.u_ab.beta],
        theta_rad: out.frame_angle_rad,
        omega_rad_s: out.frame_speed_rad_s,
        temperature_c: temp,
        ..PeriodFrame::default()
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::config::{TS_S, VOLTS_PER_COUNT};
    use crate::state::OFFSET_SAMPLES;

    /// A bridge that records what it was told.
    #[derive(Default)]
    struct Bridge {
        duties: [f32; 3],
        on: bool,
        on_periods: u32,
    }

    impl Inverter for Bridge {
        fn set_duties(&mut self, d: [f32; 3]) {
            self.duties = d;
        }
        fn enable(&mut self, on: bool) {
            self.on = on;
        }
    }

    /// A surface PMSM in the rotor frame (forward Euler, 8 substeps), with the ADC's view.
    struct Plant {
        rs: f32,
        l: f32,
        psi: f32,
        pp: f32,
        j: f32,
        i_d: f32,
        i_q: f32,
        w_mech: f32,
        th: f32,
    }

    impl Plant {
        fn new() -> Self {
            Self {
                rs: 0.5,
                l: 4e-4,
                psi: 0.01,
                pp: 4.0,
                j: 2e-5,
                i_d: 0.0,
                i_q: 0.0,
                w_mech: 0.0,
                th: 0.7,
            }
        }
        fn step(&mut self, d: [f32; 3], on: bool, u_dc: f32) {
            if !on {
                self.i_d = 0.0;
                self.i_q = 0.0;
            }
            let u = foc::duties_to_alpha_beta(d, u_dc);
            let h = TS_S / 8.0;
            for _ in 0..8 {
                let we = self.pp * self.w_mech;
                if on {
                    let (s, c) = foc::trig::sin_cos(self.th);
                    let u_d = c * u.alpha + s * u.beta;
                    let u_q = -s * u.alpha + c * u.beta;
                    self.i_d += h * (u_d - self.rs * self.i_d + we * self.l * self.i_q) / self.l;
                    self.i_q += h
                        * (u_q - self.rs * self.i_q - we * (self.l * self.i_d + self.psi))
                        / self.l;
                }
                let torque = 1.5 * self.pp * self.psi * self.i_q;
                self.w_mech += h * (torque - 1e-5 * self.w_mech) / self.j;
                self.th = foc::trig::wrap(self.th + h * we);
            }
        }
        fn raw(&self, u_dc: f32) -> Raw {
            let (s, c) = foc::trig::sin_cos(self.th);
            let ia = c * self.i_d - s * self.i_q;
            let ib = -0.5 * ia + 0.866_025_4 * (s * self.i_d + c * self.i_q);
            let ic = -ia - ib;
            let counts = |i: f32| (2048.0 + i / AMPS_PER_COUNT + 0.5) as u16;
            Raw {
                i: [counts(ia), counts(ib), counts(ic)],
                vbus: (u_dc / VOLTS_PER_COUNT + 0.5) as u16,
                temp: 1309,
            }
        }
    }

    fn calibrated(record: Option<MotorRecord>) -> (Control, Bridge) {
        let mut c = Control::new(record, false).unwrap();
        let mut b = Bridge::default();
        let raw = Raw {
            i: [2050, 2046, 2048],
            vbus: 1433,
            temp: 1309,
        };
        for _ in 0..OFFSET_SAMPLES {
            c.period(raw, &mut b);
            assert!(!b.on);
        }
        assert_eq!(c.supervisor().phase, Phase::Ready);
        assert_eq!(c.zero_counts(), [2050.0, 2046.0, 2048.0]);
        (c, b)
    }

    #[test]
    fn calibration_then_the_checks_gate_switching() {
        let (mut c, mut b) = calibrated(None);
        assert!((c.idle().u_dc_v - 12.0).abs() < 0.1);
        // A bus of 5 V: refused, latched, the bridge stays off.
        for _ in 0..10 {
            c.period(
                Raw {
                    i: [2050, 2046, 2048],
                    vbus: 597,
                    temp: 1309,
                },
                &mut b,
            );
        }
        assert_eq!(c.command(Command::Start), Err("board_bus_low"));
        assert_eq!(c.board_fault(), Some(BoardFault::BusLow));
        c.period(
            Raw {
                i: [2050, 2046, 2048],
                vbus: 1433,
                temp: 1309,
            },
            &mut b,
        );
        assert!(!b.on);
        assert_eq!(c.command(Command::Clear), Ok("cleared"));
        assert_eq!(c.supervisor().phase, Phase::Calibrating);
    }

    #[test]
    fn a_record_runs_the_controller_and_telemetry_flows() {
        let rec = MotorRecord {
            rs_ohm: 0.5,
            ld_h: 4e-4,
            lq_h: 4e-4,
            psi_f_wb: 0.01,
            j_kg_m2: f32::NAN,
            inverter_voltage_error_v: 0.0,
            test_current_a: 2.0,
            pole_pairs: 4,
        };
        let (mut c, mut b) = calibrated(Some(rec));
        assert_eq!(c.motor_source(), MotorSource::Record);
        assert_eq!(c.command(Command::Telemetry { every: 10 }), Ok("telemetry"));
        assert_eq!(c.command(Command::Speed { rpm: 600.0 }), Ok("speed set"));
        assert_eq!(c.command(Command::Start), Ok("started"));
        let mut plant = Plant::new();
        let mut frames = 0;
        for _ in 0..4000 {
            c.period(plant.raw(12.0), &mut b);
            plant.step(b.duties, b.on, 12.0);
            b.on_periods += u32::from(b.on);
            if let Some(f) = c.take_frame() {
                frames += 1;
                assert!(f.flags & FLAG_PWM != 0 || f.state == 0);
            }
        }
        assert_eq!(frames, 400);
        assert!(b.on_periods > 3900, "{}", b.on_periods);
        assert!(
            plant.w_mech > 10.0,
            "the rotor turns: {} rad/s",
            plant.w_mech
        );
        // A controlled stop ends idle; the next start is checked again (here: a low bus).
        assert_eq!(c.command(Command::Stop), Ok("stopping"));
        let mut k = 0;
        while c.supervisor().phase == Phase::Running && k < 200_000 {
            c.period(plant.raw(12.0), &mut b);
            plant.step(b.duties, b.on, 12.0);
            k += 1;
        }
        assert_eq!(
            c.supervisor().phase,
            Phase::Ready,
            "still running after {k} periods"
        );
        assert!(!b.on);
        c.period(plant.raw(5.0), &mut b);
        assert_eq!(c.command(Command::Start), Err("board_bus_low"));
        c.broke();
        c.period(plant.raw(12.0), &mut b);
        assert!(!b.on);
        assert_eq!(c.codes().1, fault_code(AnyFault::Board(BoardFault::Break)));
    }

    #[cfg(feature = "identify")]
    #[test]
    fn first_start_identifies_writes_the_record_then_spins() {
        let (mut c, mut b) = calibrated(None);
        assert_eq!(c.command(Command::Start), Ok("identifying"));
        let mut plant = Plant::new();
        let (mut rec, mut periods) = (None, 0);
        for k in 0..200_000 {
            c.period(plant.raw(12.0), &mut b);
            plant.step(b.duties, b.on, 12.0);
            if let Some(r) = c.take_record() {
                (rec, periods) = (Some(r), k);
                break;
            }
        }
        // The sequence with its spin and inertia move takes about 2 s.
        assert!(periods as f32 * TS_S > 1.0, "{periods} periods");
        let Some(rec) = rec else {
            panic!("no record: {:?}", c.supervisor().phase);
        };
        assert!(!b.on, "PWM off while the record is written");
        assert!((rec.rs_ohm / 0.5 - 1.0).abs() < 0.1, "{rec:?}");
        assert!((rec.psi_f_wb / 0.01 - 1.0).abs() < 0.1, "{rec:?}");
        assert_eq!(MotorRecord::decode(&rec.encode()), Ok(rec));
        assert_eq!(c.record_written(rec, true), Ok("identified, running"));
        assert_eq!(c.motor_source(), MotorSource::Record);
        assert_eq!(c.supervisor().phase, Phase::Running);
        c.command(Command::Speed { rpm: 300.0 }).unwrap();
        for _ in 0..2000 {
            c.period(plant.raw(12.0), &mut b);
            plant.step(b.duties, b.on, 12.0);
        }
        assert!(b.on);
    }

    #[cfg(feature = "identify")]
    #[test]
    fn identify_without_a_motor_fails_and_latches() {
        let (mut c, mut b) = calibrated(None);
        assert_eq!(
            c.command(Command::Identify { pole_pairs: 7 }),
            Ok("identifying")
        );
        let raw = Raw {
            i: [2050, 2046, 2048],
            vbus: 1433,
            temp: 1309,
        };
        for _ in 0..100_000 {
            c.period(raw, &mut b);
            if c.board_fault().is_some() {
                break;
            }
        }
        assert_eq!(c.board_fault(), Some(BoardFault::Identify));
        assert!(c.take_record().is_none());
        c.period(raw, &mut b);
        assert!(!b.on);
    }
}
