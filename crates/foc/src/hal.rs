//! How a board plugs in: two small traits and the body of the PWM interrupt.
//!
//! The controller itself never touches hardware and never reads a clock: the board samples,
//! calls [`Foc::tick`] once per PWM period and writes the result. Implement
//! [`CurrentSense`] on the ADC side and [`Inverter`] on the timer side, then call
//! [`run_period`] from the interrupt that fires when the current samples of the period are
//! ready. (The simulator `pmsm-sim` does not go through these traits: its adapter builds the
//! [`TickInput`] from its plant and calls [`Foc::tick`] directly, which is all they do.)
//!
//! ```
//! use foc::hal::{run_period_on, CurrentSense, Inverter};
//! use foc::{Foc, FocConfig, PhaseCurrents, Abc};
//! use ekf_core::MotorParams;
//!
//! /// A board: ADC results and the timer's compare registers (here plain fields).
//! struct Board { adc: [u16; 3], vbus_raw: u16, ccr: [u16; 3], moe: bool }
//! const ARR: f32 = 4250.0; // timer period in counts (170 MHz / 20 kHz / 2, center-aligned)
//!
//! impl CurrentSense for Board {
//!     fn currents(&mut self) -> PhaseCurrents {
//!         // 12-bit ADC, mid-scale offset, 20 mA per count.
//!         let amps = |raw: u16| (f32::from(raw) - 2048.0) * 0.02;
//!         PhaseCurrents::Abc(Abc { a: amps(self.adc[0]), b: amps(self.adc[1]), c: amps(self.adc[2]) })
//!     }
//!     fn bus_voltage_v(&mut self) -> f32 {
//!         f32::from(self.vbus_raw) * 0.1
//!     }
//! }
//!
//! impl Inverter for Board {
//!     fn set_duties(&mut self, d: [f32; 3]) {
//!         // Preloaded compare registers: the new values take effect at the next update
//!         // event, i.e. one period later (the delay `ComputationDelay::OnePeriod` models).
//!         for (ccr, duty) in self.ccr.iter_mut().zip(d) {
//!             *ccr = (duty * ARR) as u16;
//!         }
//!     }
//!     fn enable(&mut self, on: bool) {
//!         self.moe = on; // main output enable of the advanced timer
//!     }
//! }
//!
//! let cfg = FocConfig::new(MotorParams::servo(), 50e-6, 300.0); // 20 kHz, 300 V bus
//! let mut foc = Foc::new(&cfg).expect("valid configuration");
//! let mut board = Board { adc: [2048; 3], vbus_raw: 3000, ccr: [0; 3], moe: false };
//! foc.set_speed_ref_mech_rad_s(100.0).unwrap();
//! foc.start().unwrap();
//!
//! // In the ADC-complete interrupt, once per PWM period:
//! for _ in 0..10 {
//!     let out = run_period_on(&mut foc, &mut board);
//!     assert!(out.pwm_enabled && out.fault.is_none());
//!     assert!(board.moe);
//! }
//! // A separate ADC driver and timer driver go through `run_period(&mut foc, &mut adc, &mut tim)`.
//! ```
//!
//! [`run_period`] takes the two sides as separate values; [`run_period_on`] one value that
//! implements both traits.

use crate::controller::Foc;
use crate::io::{PhaseCurrents, RotorSensor, TickInput, TickOutput};

/// The power stage: three half-bridges driven by a PWM timer.
pub trait Inverter {
    /// Writes the duties of phases a, b, c (each in `[0, 1]`, the fraction of the period
    /// the high-side switch is on). With a preloaded timer they apply from the next period.
    fn set_duties(&mut self, duties: [f32; 3]);
    /// Turns the bridge outputs on or off (off: all switches open).
    fn enable(&mut self, on: bool);
}

/// The measurements of one period.
pub trait CurrentSense {
    /// Phase currents sampled at the start of this period, A.
    fn currents(&mut self) -> PhaseCurrents;
    /// DC-bus voltage, V.
    fn bus_voltage_v(&mut self) -> f32;
    /// Rotor angle and speed from a position sensor, if the board has one (needed in
    /// sensored mode). Default: none.
    fn rotor_sensor(&mut self) -> Option<RotorSensor> {
        None
    }
}

/// One PWM period: reads the samples, ticks the controller, writes the outputs. When the
/// outputs turn off they are disabled before the duties are written; when they turn on the
/// duties are written first.
pub fn run_period<S: CurrentSense, I: Inverter>(
    foc: &mut Foc,
    sense: &mut S,
    inverter: &mut I,
) -> TickOutput {
    let out = foc.tick(&sample(sense));
    write(inverter, &out);
    out
}

/// [`run_period`] for one value that implements both traits.
pub fn run_period_on<B: CurrentSense + Inverter>(foc: &mut Foc, board: &mut B) -> TickOutput {
    let out = foc.tick(&sample(board));
    write(board, &out);
    out
}

/// The measurements of this period as the controller's input.
fn sample<S: CurrentSense>(sense: &mut S) -> TickInput {
    TickInput {
        currents: sense.currents(),
        u_dc_v: sense.bus_voltage_v(),
        sensor: sense.rotor_sensor(),
    }
}

/// Writes a tick's outputs.
fn write<I: Inverter>(inverter: &mut I, out: &TickOutput) {
    write_bridge(inverter, out.duties, out.pwm_enabled);
}

/// Writes duties and the enable: disabled before the duties are written when they turn off,
/// the duties first when they turn on (the controller's and the identification's periods).
#[inline]
pub(crate) fn write_bridge<I: Inverter>(inverter: &mut I, duties: [f32; 3], pwm_enabled: bool) {
    if pwm_enabled {
        inverter.set_duties(duties);
        inverter.enable(true);
    } else {
        inverter.enable(false);
        inverter.set_duties(duties);
    }
}
