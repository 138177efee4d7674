//! The board's supervisor: what runs the bridge (nothing, the identification or the
//! controller), the checks before any switching, and the codes telemetry uses for states and
//! faults. Hardware-independent; the firmware calls it from the control interrupt and the
//! main loop.
//!
//! # Phases
//!
//! ```text
//! reset -> Calibrating (PWM off: current offsets averaged over OFFSET_SAMPLES periods)
//!       -> Ready   (offsets within MAX_OFFSET_A)      | Faulted(Offsets)
//! Ready --start--> checks --> Running (foc)           | Faulted(<check>)
//!                         \-> Identifying, then Running (no motor record yet, `identify` built in)
//! Ready --identify--> checks --> Identifying --> Ready (record written) | Faulted(Identify)
//! Running --off/stop--> Ready (foc idle);  foc's own faults latch in foc (`clear`)
//! any --break input--> Faulted(Break);  Faulted --clear--> Calibrating (offsets again)
//! ```
//!
//! The checks before switching ([`check_before_switching`]): bus voltage within the board's
//! range, every phase current near zero with the PWM off (the offsets hold, nothing drives
//! current), the temperature below its limit, and the controller's current limits within the
//! board's.

use crate::command::Command;
use crate::config::{
    CURRENT_LIMIT_A, MAX_IDLE_CURRENT_A, MAX_OFFSET_A, MAX_TEMPERATURE_C, OVER_CURRENT_A,
    U_DC_MAX_V, U_DC_MIN_V,
};
use foc::{Fault, State};

/// Periods averaged for the current offsets (0.1 s at 20 kHz).
pub const OFFSET_SAMPLES: u32 = 2000;

/// A fault the board detects (foc's own faults are [`foc::Fault`]).
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum BoardFault {
    /// Bus voltage below [`U_DC_MIN_V`] at a start.
    BusLow,
    /// Bus voltage above [`U_DC_MAX_V`] at a start.
    BusHigh,
    /// A current offset more than [`MAX_OFFSET_A`] from mid-scale.
    Offsets,
    /// A phase current above [`MAX_IDLE_CURRENT_A`] with the PWM off at a start.
    IdleCurrent,
    /// Power stage above [`MAX_TEMPERATURE_C`] at a start.
    Temperature,
    /// The controller's current limits exceed the board's.
    CurrentLimit,
    /// TIM1's break input fired (the outputs were cut by hardware).
    Break,
    /// The last reset was by the watchdog.
    Watchdog,
    /// The identification failed (its reason is logged).
    Identify,
}

impl BoardFault {
    /// The log's name.
    pub fn as_str(self) -> &'static str {
        match self {
            BoardFault::BusLow => "board_bus_low",
            BoardFault::BusHigh => "board_bus_high",
            BoardFault::Offsets => "board_current_offsets",
            BoardFault::IdleCurrent => "board_idle_current",
            BoardFault::Temperature => "board_temperature",
            BoardFault::CurrentLimit => "board_current_limit",
            BoardFault::Break => "board_break_input",
            BoardFault::Watchdog => "board_watchdog_reset",
            BoardFault::Identify => "board_identify_failed",
        }
    }

    const ALL: [BoardFault; 9] = [
        BoardFault::BusLow,
        BoardFault::BusHigh,
        BoardFault::Offsets,
        BoardFault::IdleCurrent,
        BoardFault::Temperature,
        BoardFault::CurrentLimit,
        BoardFault::Break,
        BoardFault::Watchdog,
        BoardFault::Identify,
    ];
}

/// A fault of either side.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum AnyFault {
    /// The controller's.
    Foc(Fault),
    /// The board's.
    Board(BoardFault),
}

const FOC_FAULTS: [Fault; 7] = [
    Fault::OverCurrent,
    Fault::BusOverVoltage,
    Fault::BusUnderVoltage,
    Fault::ObserverLost,
    Fault::Stall,
    Fault::NonFiniteInput,
    Fault::CurrentSensor,
];

/// Telemetry code of a fault: foc's 1..=7, the board's from 16.
pub fn fault_code(f: AnyFault) -> u8 {
    match f {
        AnyFault::Foc(f) => 1 + FOC_FAULTS.iter().position(|&x| x == f).unwrap_or(0) as u8,
        AnyFault::Board(b) => 16 + BoardFault::ALL.iter().position(|&x| x == b).unwrap_or(0) as u8,
    }
}

/// The fault of a telemetry code (`None` for 0 and unknown codes).
pub fn fault_from_code(c: u8) -> Option<AnyFault> {
    match c {
        1..=7 => FOC_FAULTS
            .get(usize::from(c - 1))
            .map(|&f| AnyFault::Foc(f)),
        16..=31 => BoardFault::ALL
            .get(usize::from(c - 16))
            .map(|&b| AnyFault::Board(b)),
        _ => None,
    }
}

/// What drives the bridge, as telemetry reports it.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum DriveState {
    /// The controller, in this state.
    Foc(State),
    /// The identification.
    Identify,
    /// Offsets being measured.
    Calibrate,
}

const FOC_STATES: [State; 6] = [
    State::Idle,
    State::Align,
    State::OpenLoop,
    State::Handover,
    State::ClosedLoop,
    State::Fault,
];

/// Telemetry code of a state: foc's 0..=5, identification 6, calibration 7.
pub fn state_code(s: DriveState) -> u8 {
    match s {
        DriveState::Foc(s) => FOC_STATES.iter().position(|&x| x == s).unwrap_or(0) as u8,
        DriveState::Identify => 6,
        DriveState::Calibrate => 7,
    }
}

/// The state of a telemetry code.
pub fn state_from_code(c: u8) -> Option<DriveState> {
    match c {
        0..=5 => FOC_STATES.get(usize::from(c)).map(|&s| DriveState::Foc(s)),
        6 => Some(DriveState::Identify),
        7 => Some(DriveState::Calibrate),
        _ => None,
    }
}

/// Measurements of one period with the PWM off, SI units.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Idle {
    /// Phase currents with the offsets removed, A.
    pub i_abc_a: [f32; 3],
    /// Bus voltage, V.
    pub u_dc_v: f32,
    /// Power-stage temperature, degC.
    pub temperature_c: f32,
}

/// The checks before any switching (module docs). `current_limit_a`, `over_current_a`: the
/// limits the controller (or the identification) would use.
pub fn check_before_switching(
    m: &Idle,
    current_limit_a: f32,
    over_current_a: f32,
) -> Result<(), BoardFault> {
    if m.u_dc_v.is_nan() || m.u_dc_v < U_DC_MIN_V {
        return Err(BoardFault::BusLow);
    }
    if m.u_dc_v > U_DC_MAX_V {
        return Err(BoardFault::BusHigh);
    }
    if !m.i_abc_a.iter().all(|i| i.abs() <= MAX_IDLE_CURRENT_A) {
        return Err(BoardFault::IdleCurrent);
    }
    if m.temperature_c.is_nan() || m.temperature_c > MAX_TEMPERATURE_C {
        return Err(BoardFault::Temperature);
    }
    if !(current_limit_a <= CURRENT_LIMIT_A && over_current_a <= OVER_CURRENT_A) {
        return Err(BoardFault::CurrentLimit);
    }
    Ok(())
}

/// Averages the raw current readings with the PWM off.
#[derive(Clone, Copy, Debug, Default, PartialEq)]
pub struct OffsetCalibration {
    sums: [u32; 3],
    n: u32,
}

impl OffsetCalibration {
    /// Adds one period's raw readings; `true` once [`OFFSET_SAMPLES`] are in.
    pub fn push(&mut self, raw: [u16; 3]) -> bool {
        if self.n < OFFSET_SAMPLES {
            for (s, r) in self.sums.iter_mut().zip(raw) {
                *s += u32::from(r);
            }
            self.n += 1;
        }
        self.n >= OFFSET_SAMPLES
    }

    /// The zero readings, counts, if every one is within [`MAX_OFFSET_A`] of `nominal`.
    pub fn result(&self, nominal: f32, amps_per_count: f32) -> Result<[f32; 3], BoardFault> {
        if self.n == 0 {
            return Err(BoardFault::Offsets);
        }
        let z = self.sums.map(|s| s as f32 / self.n as f32);
        if z.iter()
            .all(|&c| ((c - nominal) * amps_per_count).abs() <= MAX_OFFSET_A)
        {
            Ok(z)
        } else {
            Err(BoardFault::Offsets)
        }
    }
}

/// What runs.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum Phase {
    /// Offsets being measured (PWM off).
    Calibrating,
    /// PWM off, ready for a command.
    Ready,
    /// The identification drives the bridge; `then_run`: start the drive after it.
    Identifying {
        /// Start the drive when the identification succeeded.
        then_run: bool,
    },
    /// The controller drives the bridge (it may be idle or faulted itself).
    Running,
    /// A board fault is latched (PWM off).
    Faulted(BoardFault),
}

/// What the firmware is to do for a command.
#[derive(Clone, Copy, Debug, PartialEq)]
pub enum Action {
    /// Reply with an error, change nothing.
    Refuse(&'static str),
    /// Start (or keep running) the controller.
    StartDrive,
    /// Start the identification for a motor of this many pole pairs.
    StartIdentify {
        /// Pole pairs.
        pole_pairs: u8,
    },
    /// Controlled stop of the controller.
    Stop,
    /// PWM off at once.
    Off,
    /// Clear the faults (board: back to calibration; foc: `clear_fault`).
    Clear,
    /// Set the speed reference, rpm.
    Speed(f32),
    /// Erase the motor record.
    Forget,
    /// Telemetry divider.
    Telemetry(u16),
    /// Send the status line.
    Status,
}

/// Pole pairs assumed by `start` when it has to identify the motor first.
pub const DEFAULT_POLE_PAIRS: u8 = 7;

/// The supervisor's state.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Supervisor {
    /// What runs.
    pub phase: Phase,
    /// A valid motor record is in flash (or was just written).
    pub has_record: bool,
}

impl Supervisor {
    /// After reset: calibrating; `watchdog_reset` latches [`BoardFault::Watchdog`] instead
    /// (`clear` to go on).
    pub fn new(has_record: bool, watchdog_reset: bool) -> Self {
        Self {
            phase: if watchdog_reset {
                Phase::Faulted(BoardFault::Watchdog)
            } else {
                Phase::Calibrating
            },
            has_record,
        }
    }

    /// The decision for a command, given the idle measurements and the limits the
    /// controller would use; updates the phase. (The caller performs the action.)
    pub fn command(
        &mut self,
        cmd: Command,
        idle: &Idle,
        limits: (f32, f32),
        identify_built_in: bool,
    ) -> Action {
        let switching_allowed = |s: &mut Self| -> Result<(), &'static str> {
            match s.phase {
                Phase::Calibrating => Err("offsets not measured yet"),
                Phase::Faulted(f) => Err(f.as_str()),
                Phase::Identifying { .. } => Err("identification running"),
                Phase::Ready | Phase::Running => check_before_switching(idle, limits.0, limits.1)
                    .map_err(|f| {
                        s.phase = Phase::Faulted(f);
                        f.as_str()
                    }),
            }
        };
        match cmd {
            Command::Start => {
                if self.phase == Phase::Running {
                    return Action::StartDrive;
                }
                if let Err(e) = switching_allowed(self) {
                    return Action::Refuse(e);
                }
                if self.has_record {
                    self.phase = Phase::Running;
                    Action::StartDrive
                } else if identify_built_in {
                    self.phase = Phase::Identifying { then_run: true };
                    Action::StartIdentify {
                        pole_pairs: DEFAULT_POLE_PAIRS,
                    }
                } else {
                    Action::Refuse("no motor record and identify not built in")
                }
            }
            Command::Identify { pole_pairs } => {
                if !identify_built_in {
                    return Action::Refuse("identify not built in");
                }
                if self.phase != Phase::Ready {
                    return Action::Refuse("identify only when ready (PWM off)");
                }
                if let Err(e) = switching_allowed(self) {
                    return Action::Refuse(e);
                }
                self.phase = Phase::Identifying { then_run: false };
                Action::StartIdentify { pole_pairs }
            }
            Command::Stop => Action::Stop,
            Command::Off => {
                if matches!(self.phase, Phase::Running | Phase::Identifying { .. }) {
                    self.phase = Phase::Ready;
                }
                Action::Off
            }
            Command::Clear => {
                if matches!(self.phase, Phase::Faulted(_)) {
                    self.phase = Phase::Calibrating;
                }
                Action::Clear
            }
            Command::Speed { rpm } => Action::Speed(rpm),
            Command::Forget => {
                if matches!(self.phase, Phase::Running | Phase::Identifying { .. }) {
                    return Action::Refuse("forget only with the PWM off");
                }
                self.has_record = false;
                Action::Forget
            }
            Command::Telemetry { every } => Action::Telemetry(every),
            Command::Status => Action::Status,
        }
    }

    /// The offsets are in: `Ready`, or the fault.
    pub fn calibrated(&mut self, result: Result<[f32; 3], BoardFault>) {
        if self.phase == Phase::Calibrating {
            self.phase = match result {
                Ok(_) => Phase::Ready,
                Err(f) => Phase::Faulted(f),
            };
        }
    }

    /// The identification ended: its record written (`Ok`), or failed. Returns whether the
    /// drive is to start now.
    pub fn identified(&mut self, ok: bool) -> bool {
        let Phase::Identifying { then_run } = self.phase else {
            return false;
        };
        if ok {
            self.has_record = true;
            self.phase = if then_run {
                Phase::Running
            } else {
                Phase::Ready
            };
            then_run
        } else {
            self.phase = Phase::Faulted(BoardFault::Identify);
            false
        }
    }

    /// The controller went idle by itself (a controlled stop ended): `Ready`, so that the
    /// next `start` goes through the checks again.
    pub fn drive_idle(&mut self) {
        if self.phase == Phase::Running {
            self.phase = Phase::Ready;
        }
    }

    /// The break input fired: latched whatever ran.
    pub fn broke(&mut self) {
        self.phase = Phase::Faulted(BoardFault::Break);
    }

    /// The latched board fault.
    pub fn fault(&self) -> Option<BoardFault> {
        match self.phase {
            Phase::Faulted(f) => Some(f),
            _ => None,
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::config::{AMPS_PER_COUNT, CURRENT_ZERO_COUNTS};

    const OK_IDLE: Idle = Idle {
        i_abc_a: [0.01, -0.02, 0.0],
        u_dc_v: 12.0,
        temperature_c: 30.0,
    };
    const LIMITS: (f32, f32) = (5.0, 8.0);

    #[test]
    fn codes_round_trip() {
        for f in FOC_FAULTS {
            assert_eq!(
                fault_from_code(fault_code(AnyFault::Foc(f))),
                Some(AnyFault::Foc(f))
            );
        }
        for b in BoardFault::ALL {
            let c = fault_code(AnyFault::Board(b));
            assert!(c >= 16);
            assert_eq!(fault_from_code(c), Some(AnyFault::Board(b)));
        }
        for s in FOC_STATES {
            let d = DriveState::Foc(s);
            assert_eq!(state_from_code(state_code(d)), Some(d));
        }
        assert_eq!(state_from_code(6), Some(DriveState::Identify));
        assert_eq!(state_from_code(7), Some(DriveState::Calibrate));
        assert_eq!(state_from_code(200), None);
        assert_eq!(fault_from_code(0), None);
        assert_eq!(fault_from_code(9), None);
        assert_eq!(fault_from_code(255), None);
    }

    #[test]
    fn checks_before_switching_name_the_problem() {
        assert_eq!(check_before_switching(&OK_IDLE, 5.0, 8.0), Ok(()));
        let low = Idle {
            u_dc_v: 5.0,
            ..OK_IDLE
        };
        assert_eq!(
            check_before_switching(&low, 5.0, 8.0),
            Err(BoardFault::BusLow)
        );
        let nan = Idle {
            u_dc_v: f32::NAN,
            ..OK_IDLE
        };
        assert_eq!(
            check_before_switching(&nan, 5.0, 8.0),
            Err(BoardFault::BusLow)
        );
        let high = Idle {
            u_dc_v: 30.0,
            ..OK_IDLE
        };
        assert_eq!(
            check_before_switching(&high, 5.0, 8.0),
            Err(BoardFault::BusHigh)
        );
        let cur = Idle {
            i_abc_a: [0.0, 0.9, 0.0],
            ..OK_IDLE
        };
        assert_eq!(
            check_before_switching(&cur, 5.0, 8.0),
            Err(BoardFault::IdleCurrent)
        );
        let hot = Idle {
            temperature_c: 95.0,
            ..OK_IDLE
        };
        assert_eq!(
            check_before_switching(&hot, 5.0, 8.0),
            Err(BoardFault::Temperature)
        );
        assert_eq!(
            check_before_switching(&OK_IDLE, 20.0, 8.0),
            Err(BoardFault::CurrentLimit)
        );
    }

    #[test]
    fn offsets_are_averaged_and_bounded() {
        let mut c = OffsetCalibration::default();
        assert_eq!(
            c.result(CURRENT_ZERO_COUNTS, AMPS_PER_COUNT),
            Err(BoardFault::Offsets)
        );
        let mut done = false;
        for k in 0..OFFSET_SAMPLES {
            done = c.push([2040 + (k % 2) as u16 * 2, 2050, 2048]);
        }
        assert!(done);
        let z = c.result(CURRENT_ZERO_COUNTS, AMPS_PER_COUNT).unwrap();
        assert!((z[0] - 2041.0).abs() < 1e-3 && z[1] == 2050.0);
        // 2 A is 2 / 0.0294 = 68 counts.
        let mut far = OffsetCalibration::default();
        while !far.push([2048, 2200, 2048]) {}
        assert_eq!(
            far.result(CURRENT_ZERO_COUNTS, AMPS_PER_COUNT),
            Err(BoardFault::Offsets)
        );
    }

    #[test]
    fn the_phases_follow_the_commands() {
        let mut s = Supervisor::new(false, false);
        assert_eq!(
            s.command(Command::Start, &OK_IDLE, LIMITS, true),
            Action::Refuse("offsets not measured yet")
        );
        s.calibrated(Ok([2048.0; 3]));
        assert_eq!(s.phase, Phase::Ready);
        // No record: start identifies first, then runs.
        assert_eq!(
            s.command(Command::Start, &OK_IDLE, LIMITS, true),
            Action::StartIdentify { pole_pairs: 7 }
        );
        assert_eq!(
            s.command(Command::Identify { pole_pairs: 7 }, &OK_IDLE, LIMITS, true),
            Action::Refuse("identify only when ready (PWM off)")
        );
        assert!(s.identified(true));
        assert_eq!((s.phase, s.has_record), (Phase::Running, true));
        assert_eq!(
            s.command(Command::Speed { rpm: 900.0 }, &OK_IDLE, LIMITS, true),
            Action::Speed(900.0)
        );
        assert_eq!(
            s.command(Command::Forget, &OK_IDLE, LIMITS, true),
            Action::Refuse("forget only with the PWM off")
        );
        assert_eq!(s.command(Command::Off, &OK_IDLE, LIMITS, true), Action::Off);
        assert_eq!(s.phase, Phase::Ready);
        // With a record, start runs at once; a low bus refuses and latches.
        let low = Idle {
            u_dc_v: 3.0,
            ..OK_IDLE
        };
        assert_eq!(
            s.command(Command::Start, &low, LIMITS, true),
            Action::Refuse("board_bus_low")
        );
        assert_eq!(s.fault(), Some(BoardFault::BusLow));
        assert_eq!(
            s.command(Command::Start, &OK_IDLE, LIMITS, true),
            Action::Refuse("board_bus_low")
        );
        assert_eq!(
            s.command(Command::Clear, &OK_IDLE, LIMITS, true),
            Action::Clear
        );
        assert_eq!(s.phase, Phase::Calibrating);
        s.calibrated(Ok([2048.0; 3]));
        assert_eq!(
            s.command(Command::Start, &OK_IDLE, LIMITS, true),
            Action::StartDrive
        );
        assert_eq!(s.phase, Phase::Running);
        s.broke();
        assert_eq!(s.fault(), Some(BoardFault::Break));
    }

    #[test]
    fn without_identify_and_record_start_is_refused() {
        let mut s = Supervisor::new(false, false);
        s.calibrated(Ok([2048.0; 3]));
        assert!(matches!(
            s.command(Command::Start, &OK_IDLE, LIMITS, false),
            Action::Refuse(_)
        ));
        assert!(matches!(
            s.command(Command::Identify { pole_pairs: 7 }, &OK_IDLE, LIMITS, false),
            Action::Refuse(_)
        ));
        assert_eq!(s.phase, Phase::Ready);
    }

    #[test]
    fn a_failed_identification_latches_and_a_watchdog_reset_is_reported() {
        let mut s = Supervisor::new(false, false);
        s.calibrated(Ok([2048.0; 3]));
        assert_eq!(
            s.command(Command::Identify { pole_pairs: 4 }, &OK_IDLE, LIMITS, true),
            Action::StartIdentify { pole_pairs: 4 }
        );
        assert!(!s.identified(false));
        assert_eq!(s.fault(), Some(BoardFault::Identify));
        assert!(!s.has_record);
        let s = Supervisor::new(true, true);
        assert_eq!(s.fault(), Some(BoardFault::Watchdog));
    }
}
