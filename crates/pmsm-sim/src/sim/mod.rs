//! The closed-loop run: plant, inverter, sensors, controller, and the observer(s) alongside.
//!
//! # One PWM period `k` (timing of docs/design.md, "Conventions")
//!
//! 1. The plant is at `x(t_k)`; the sensor samples the phase currents `i[k]` (PWM centre) and
//!    the DC bus.
//! 2. The observer steps with `(u[k-1], i[k])`: it predicts over `[t_k-1, t_k)` with the
//!    voltage held there, then corrects with `i[k]` (first step: `u[-1] = 0`). `u[k-1]` is
//!    the voltage the duties applied over that period realize with ideal switches on the bus
//!    the controller measured when it computed them: what a real controller knows it
//!    commanded; or, when the controller reports it (`ControllerOutput::expected_u_ab_v`,
//!    e.g. `foc` after its dead-time compensation), the voltage the controller expects those
//!    duties to realize. The actual dead-time distortion is **not** in it (a real controller
//!    does not know it), so uncompensated dead time shows up as observer error, as on a bench. The estimate is compared
//!    with the true `th(t_k)`, `w_e(t_k)`. The run's observers (the default EKF and the seed's
//!    filter) and any extra ones ([`SideObserver`], [`run_with_side_observers`]: the suite's)
//!    are all [`Observer`]s and step on the same inputs, in that order. Nothing in the loop
//!    depends on them: the run's two step on a thread of their own, pipelined a few batches of
//!    periods behind the loop, and each period's [`Sample`] is handed on (metrics, side
//!    observers, sinks, trace) in order once their estimates are in it; the extra ones step
//!    right before their period is handed on ([`RunOptions::inline_observers`]: all on the
//!    calling thread; the results are the same bit for bit).
//! 3. The controller ticks with `i[k]`, the measured bus and the speed reference (a sensored
//!    controller also gets the true angle and speed) and returns duties `d[k]`; an estimate
//!    of its own observer (`foc`'s `f32` EKF, which has stepped with its own record of the
//!    voltage and `i[k]`) is scored against the same truth as the simulator's observers.
//! 4. The inverter applies `d[k-1]` (one period of computation delay) or `d[k]` (no delay)
//!    over `[t_k, t_k+1)`, with its dead time; the plant integrates the period with the load
//!    torque of `(t_k, w(t_k))` held. When the controller disables the PWM, all switches
//!    open for that period at once and the plant coasts ([`Plant::step_open`]); the observer
//!    then gets `u = 0` for the period. With `inverter.delay_periods` the period holds two
//!    voltages ([`crate::plant::inverter`]): the plant steps over each sub-interval in turn, with
//!    the dead-time sign of the current at its start, and the record's applied voltage is
//!    the period's mean.
//!
//! # Skipped control cycles (`[skipped_cycles]`, off by default)
//!
//! A real controller sometimes misses a period: an interrupt held off by a higher-priority
//! one, a computation that overruns, a lost ADC trigger. In a skipped period `k` the
//! controller does not tick: its current sample `i[k]` is never read, the bridge holds the
//! previous tick's duties one more period (they enter the delay line again, so with the
//! computation delay they act in the next period, as a timer's shadow register that is not
//! reloaded would), and the controller's voltage record, which the simulator's observers
//! get, is that of the held duties. The ADC still converts (its sample is in the log, and
//! the simulator's own observers, which stand for an analysis of the log, step on it); the
//! controller's own observer has no estimate for the period (none is scored). The controller
//! runs on the next period as if one period had passed since its last tick: the missed
//! period is what its observer and loops see as model error. Which periods are skipped: a
//! period with probability `probability` each (a Xoshiro256++ stream of its own, seeded from
//! the scenario's seed: deterministic, the sensor noise unchanged), and the periods
//! containing the times `times_s`; never period 0 (there is nothing to hold yet).
//! [`RunMetrics::skipped_control_periods`](crate::output::metrics::RunMetrics::skipped_control_periods)
//! counts them.
//!
//! # Stops
//!
//! A run ends early, with everything recorded so far intact, when the plant state or the
//! controller's duties go non-finite (naming the quantity and the time), when the observer
//! fails, when the sink (the MCAP log) fails, or when the interrupt flag (Ctrl-C) is set.
//! (An observer's or a sink's failure is found when its period is handed on, up to a few
//! batches after the loop simulated it: the periods simulated since are dropped, so the
//! outputs are those of a run that stopped there.)
//! [`run_with`] reports how it ended in [`RunOutput::end`]; [`run`] turns an abnormal end
//! into an error.

pub(crate) mod pipeline;

use std::sync::atomic::{AtomicBool, Ordering};
use std::time::Instant;

use ekf_core::{EkfError, PmsmObserver};
use glam::DVec2;

use crate::SimError;
use crate::drive::foc_adapter::FocDrive;
use crate::drive::interface::{ControllerInput, ControllerOutput, DriveController, RotorFeedback};
use crate::drive::rotor_observers::{Observer, ObserverEstimate};
use crate::output::metrics::{MetricsAccumulator, RunMetrics};
use crate::plant::Plant;
use crate::plant::fault_injection::FaultInjector;
use crate::plant::inverter::Inverter;
use crate::plant::load::load_torque_nm;
use crate::plant::sensors::CurrentSensor;
use crate::scenario::{RPM_PER_RAD_S, RunPlan, Scenario, SkippedCycles};
use crate::sim::pipeline::{ObserverInput, ObserverPipeline, Ready, RunObservers};

pub use crate::output::SampleSink;
pub use crate::output::record::{
    ControlRecord, InverterRecord, Measured, ObserverSample, Sample, Truth,
};

/// The recorded run.
#[derive(Clone, Debug, Default, PartialEq)]
pub struct Trace {
    /// PWM period, s.
    pub ts_s: f64,
    /// One sample per period (empty when the run did not record a trace).
    pub samples: Vec<Sample>,
}

/// A filter step that failed.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub struct FilterFailure {
    /// Sample index.
    pub k: u64,
    /// The filter's error.
    pub error: EkfError,
}

/// How a run ended.
#[derive(Clone, Debug, PartialEq)]
pub enum RunEnd {
    /// Every period of the scenario was simulated.
    Completed,
    /// The interrupt flag was set (Ctrl-C) before period `k`.
    Interrupted {
        /// First period not simulated.
        k: u64,
        /// Its time, s.
        t_s: f64,
    },
    /// A quantity went non-finite at `t_s`.
    NonFinite {
        /// Period index.
        k: u64,
        /// Time, s.
        t_s: f64,
        /// Which quantity.
        quantity: &'static str,
        /// Its value.
        value: f64,
    },
    /// The observer failed at `t_s`.
    ObserverFailed {
        /// Period index.
        k: u64,
        /// Time, s.
        t_s: f64,
        /// The observer's error.
        error: EkfError,
    },
    /// The sample sink (log) failed.
    SinkFailed {
        /// Period index.
        k: u64,
        /// Time, s.
        t_s: f64,
        /// What failed.
        message: String,
    },
}

impl RunEnd {
    /// Whether every period was simulated.
    pub fn is_completed(&self) -> bool {
        matches!(self, RunEnd::Completed)
    }

    /// Time of an early end, s.
    pub fn stop_time_s(&self) -> Option<f64> {
        match self {
            RunEnd::Completed => None,
            RunEnd::Interrupted { t_s, .. }
            | RunEnd::NonFinite { t_s, .. }
            | RunEnd::ObserverFailed { t_s, .. }
            | RunEnd::SinkFailed { t_s, .. } => Some(*t_s),
        }
    }

    /// One line on how the run ended.
    pub fn describe(&self) -> String {
        match self {
            RunEnd::Completed => "completed".into(),
            RunEnd::Interrupted { t_s, .. } => format!("interrupted at t = {t_s:.6} s"),
            RunEnd::NonFinite {
                t_s,
                quantity,
                value,
                ..
            } => format!("non-finite {quantity} = {value} at t = {t_s:.6} s"),
            RunEnd::ObserverFailed { t_s, error, .. } => {
                format!("observer failed at t = {t_s:.6} s: {error}")
            }
            RunEnd::SinkFailed { t_s, message, .. } => {
                format!("log failed at t = {t_s:.6} s: {message}")
            }
        }
    }
}

/// A finished run.
#[derive(Clone, Debug, PartialEq)]
pub struct RunOutput {
    /// The recorded run (deterministic for a given scenario; empty unless asked for).
    pub trace: Trace,
    /// The metrics (wall-clock figures aside, deterministic).
    pub metrics: RunMetrics,
    /// How the run ended.
    pub end: RunEnd,
    /// Where the reference filter failed and was dropped, if it did.
    pub reference_filter_failure: Option<FilterFailure>,
    /// Wall-clock time of the simulation loop, s (not deterministic).
    pub wall_time_s: f64,
}

/// Options of [`run_with`].
#[derive(Default)]
pub struct RunOptions<'a> {
    /// Keep every sample in [`RunOutput::trace`].
    pub record_trace: bool,
    /// Sinks that get every sample, in order.
    pub sinks: Vec<&'a mut dyn SampleSink>,
    /// Stop when this flag is set (checked every period).
    pub interrupt: Option<&'a AtomicBool>,
    /// Called with `(periods done, periods in all)` every 4096 periods and at the end.
    pub progress: Option<&'a mut dyn FnMut(usize, usize)>,
    /// d-axis saturation of the plant ([`crate::plant::DSaturation`]; `None`, the default:
    /// the linear plant of every scenario).
    pub d_saturation: Option<crate::plant::DSaturation>,
    /// Step the run's own observers (the default EKF, the reference filter) on the calling thread
    /// instead of a thread of their own, pipelined (the default); the results are
    /// the same bit for bit (`pmsm-sim bench` times both).
    pub inline_observers: bool,
}

/// Whether the run's observers should step on a thread of their own
/// ([`RunOptions::inline_observers`] `false`) on this machine: only when every busy thread gets
/// a core, the simulating thread, the observers' and, with `log_thread`, the MCAP log's writer
/// ([`crate::output::mcap`]). With fewer cores the threads take turns on them and the
/// hand-over between them costs more than it saves: on the 2-core VM of the README, the
/// default run with its log ran 127x real time pipelined against 158x inline (`pmsm-sim
/// bench`, medians of 7), while without the log the pipeline wins (229x against 215x).
pub fn pipeline_pays(log_thread: bool) -> bool {
    let cores = std::thread::available_parallelism().map_or(1, |n| n.get());
    cores >= 2 + usize::from(log_thread)
}

/// Which control periods are skipped (module docs, "Skipped control cycles").
#[derive(Clone, Debug)]
pub struct CycleSkips {
    /// `probability` as a threshold on a 53-bit uniform integer (0: no draws).
    threshold: u64,
    rng: rand::rngs::Xoshiro256PlusPlus,
    /// The periods of `times_s`, sorted, and the next one to check.
    periods: Vec<u64>,
    next: usize,
}

/// Added to the scenario's seed for the skip stream (any constant: a stream of its own).
const SKIP_SEED_OFFSET: u64 = 0x5c1b_c7c1_e5ee_d000;

impl CycleSkips {
    /// The skip schedule of the settings, for the PWM period `ts_s`; `None` when nothing is
    /// ever skipped.
    pub fn new(cfg: &SkippedCycles, seed: u64, ts_s: f64) -> Option<Self> {
        use rand::SeedableRng;
        if !cfg.is_on() {
            return None;
        }
        let mut periods: Vec<u64> = cfg
            .times_s
            .iter()
            .map(|&t| (t / ts_s + 1e-9).floor() as u64)
            .collect();
        periods.sort_unstable();
        Some(Self {
            threshold: (cfg.probability * (1u64 << 53) as f64) as u64,
            rng: rand::rngs::Xoshiro256PlusPlus::seed_from_u64(seed.wrapping_add(SKIP_SEED_OFFSET)),
            periods,
            next: 0,
        })
    }

    /// Whether period `k` is skipped; call once per period, in order (one draw per period
    /// with a probability set, whatever the outcome).
    pub fn skip(&mut self, k: u64) -> bool {
        use rand::Rng;
        let random = self.threshold > 0 && (self.rng.next_u64() >> 11) < self.threshold;
        let mut timed = false;
        while self.next < self.periods.len() && self.periods[self.next] <= k {
            timed |= self.periods[self.next] == k;
            self.next += 1;
        }
        k > 0 && (random || timed)
    }
}

/// Runs a scenario with a full trace; an early end (non-finite, observer failure) is an
/// error.
pub fn run(scenario: &Scenario) -> Result<RunOutput, SimError> {
    let out = run_with(
        scenario,
        RunOptions {
            record_trace: true,
            ..RunOptions::default()
        },
    )?;
    match out.end.stop_time_s() {
        None => Ok(out),
        Some(t_s) => Err(SimError::Stopped {
            t_s,
            reason: out.end.describe(),
        }),
    }
}

/// The controller a scenario asks for: the `foc` crate's controller ([`FocDrive`],
/// sensorless or sensored). Errors when `foc` refuses the configuration.
pub fn build_controller(scenario: &Scenario) -> Result<Box<dyn DriveController>, SimError> {
    Ok(Box::new(FocDrive::from_scenario(scenario)?))
}

/// Runs a scenario with its own controller ([`build_controller`]).
pub fn run_with(scenario: &Scenario, opts: RunOptions<'_>) -> Result<RunOutput, SimError> {
    let plan = scenario.plan()?;
    let mut controller = FocDrive::from_plan(&plan)?;
    run_planned(&plan, &mut controller, opts, &mut [])
}

/// Runs a scenario with the given controller (module docs give one period's order).
///
/// Errors only for an invalid scenario or observer configuration; how the run ended is in
/// [`RunOutput::end`].
pub fn run_with_controller(
    scenario: &Scenario,
    controller: &mut dyn DriveController,
    opts: RunOptions<'_>,
) -> Result<RunOutput, SimError> {
    run_with_side_observers(scenario, controller, opts, &mut [])
}

/// The estimate a [`SideObserver`] returns (the [`Observer`] trait's).
pub type SideEstimate = ObserverEstimate;

/// An extra [`Observer`] stepped alongside the run's own ones, on exactly their inputs, that
/// sees its scored estimates (the scenario suite compares observers this way). In period
/// `k`, [`Observer::step`] comes right after the run's observers' steps, before the
/// controller ticks and before the truth is known to anyone; [`record`](Self::record) comes
/// once the period's [`Sample`] is complete, with this observer's estimate scored against the
/// truth.
pub trait SideObserver: Observer {
    /// The completed sample of the period, and this observer's scored estimate (its error
    /// when the step failed; the run goes on).
    fn record(&mut self, sample: &Sample, own: Result<ObserverSample, EkfError>);
}

/// As [`run_with_controller`], with extra observers stepped alongside ([`SideObserver`]).
pub fn run_with_side_observers(
    scenario: &Scenario,
    controller: &mut dyn DriveController,
    opts: RunOptions<'_>,
    side: &mut [&mut dyn SideObserver],
) -> Result<RunOutput, SimError> {
    run_planned(&scenario.plan()?, controller, opts, side)
}

/// The run of a [`RunPlan`] (module docs give one period's order).
pub fn run_planned(
    plan: &RunPlan<'_>,
    controller: &mut dyn DriveController,
    mut opts: RunOptions<'_>,
    side: &mut [&mut dyn SideObserver],
) -> Result<RunOutput, SimError> {
    let scenario = plan.scenario;
    let ts = plan.ts_s;
    let motor = &scenario.motor;
    let mut plant = Plant::new(motor.clone(), plan.initial);
    if !plant.set_d_saturation(opts.d_saturation) {
        return Err(SimError::Scenario {
            file: scenario.name.clone(),
            field: "d_saturation".into(),
            problem: format!("{:?}: drop in [0, 1), current_a > 0", opts.d_saturation),
        });
    }
    let mut inverter = Inverter::new(scenario.inverter);
    let mut sensor = CurrentSensor::new(scenario.sensors, scenario.seed);
    // Injected faults (`[[faults]]`; none: not built, the loop unchanged).
    let mut faults = FaultInjector::new(&scenario.faults, &plan.fault_context);
    // The run's own observers: the default EKF (its failure ends the run) and the seed's
    // filter (a comparison only: dropped when it fails). Nothing in the loop depends on them:
    // they step pipelined on a thread of their own ([`crate::sim::pipeline`]), and each period's
    // sample is handed on (metrics, side observers, sinks, trace) once their estimates are
    // in it.
    let observers = RunObservers {
        observer: PmsmObserver::new(&plan.observer)?,
        reference_filter: match &plan.reference_filter {
            Some(cfg) => Some(PmsmObserver::new(cfg)?),
            None => None,
        },
    };
    let mut pipeline = if opts.inline_observers {
        ObserverPipeline::inline(observers)
    } else {
        ObserverPipeline::threaded(observers)
    };
    let sensored = controller.sensored();

    let n = plan.periods;
    let mut samples = Vec::with_capacity(if opts.record_trace { n } else { 0 });
    let mut acc = MetricsAccumulator::new(scenario);
    let mut u_prev = [0.0; 2];
    // The voltage the controller expects of its last duties (`ControllerOutput::expected_u_ab_v`),
    // held back like the duties when the inverter has its computation delay.
    let mut expected_pending: Option<[f64; 2]> = None;
    let delay = plan.delay;
    let mut skips = CycleSkips::new(&scenario.skipped_cycles, scenario.seed, ts);
    let mut last_out: Option<ControllerOutput> = None;
    let mut skipped: u64 = 0;
    let mut reference_filter_failure = None;
    let mut side_est = Vec::with_capacity(side.len());
    // How the loop ended (interrupt, non-finite) and how the hand-on ended (observer or
    // sink failure, at an earlier or the same period: it takes precedence).
    let mut end = RunEnd::Completed;
    let mut hand_end: Option<RunEnd> = None;
    let record_trace = opts.record_trace;
    let sinks = &mut opts.sinks;
    // One period, complete, in order: what a sequential run does after its observers' steps.
    let mut hand_on = |r: Ready<'_>| -> bool {
        let (sample, input, reference_filter_error) = match r {
            Ready::ObserverFailed { k, error } => {
                hand_end = Some(RunEnd::ObserverFailed {
                    k,
                    t_s: k as f64 * ts,
                    error,
                });
                return false;
            }
            Ready::Period {
                sample,
                input,
                reference_filter_error,
            } => (sample, input, reference_filter_error),
        };
        if let Some(error) = reference_filter_error {
            reference_filter_failure = Some(FilterFailure { k: input.k, error });
            acc.drop_reference_filter();
        }
        side_est.clear();
        side_est.extend(side.iter_mut().map(|o| o.step(input.u_prev, input.i_ab_a)));
        let Some(sample) = sample else {
            return true;
        };
        acc.push(sample);
        for (o, r) in side.iter_mut().zip(&side_est) {
            o.record(
                sample,
                r.map(|e| ObserverSample::from_controller(&e, &sample.truth)),
            );
        }
        let mut sink_error = None;
        for sink in sinks.iter_mut() {
            if let Err(message) = sink.record(sample) {
                sink_error = Some(message);
                break;
            }
        }
        if record_trace {
            samples.push(*sample);
        }
        if let Some(message) = sink_error {
            hand_end = Some(RunEnd::SinkFailed {
                k: sample.k,
                t_s: sample.t_s,
                message,
            });
            return false;
        }
        true
    };
    let start = Instant::now();
    for k in 0..n {
        let kk = k as u64;
        let t = k as f64 * ts;
        if opts.interrupt.is_some_and(|f| f.load(Ordering::Relaxed)) {
            end = RunEnd::Interrupted { k: kk, t_s: t };
            break;
        }
        if let Err((quantity, value)) = plant.check_finite() {
            end = RunEnd::NonFinite {
                k: kk,
                t_s: t,
                quantity,
                value,
            };
            break;
        }
        let state = plant.state();
        let omega_e = plant.omega_e_rad_s();
        let i_abc_true = plant.i_abc_a();
        let (meas, u_dc) = match faults.as_mut() {
            Some(f) => (
                f.measure(kk, &mut sensor, i_abc_true),
                inverter.u_dc_at(t) * f.bus_factor(kk),
            ),
            None => (sensor.measure(i_abc_true), inverter.u_dc_at(t)),
        };
        let i_ab_meas = meas.i_ab_a.to_array();
        // The observers' step of this period, (u[k-1], i[k]) scored against the truth at t_k.
        let obs_input = ObserverInput {
            k: kk,
            u_prev,
            i_ab_a: i_ab_meas,
            theta_e_rad: state.theta_e_rad,
            omega_e_rad_s: omega_e,
        };

        let speed_ref_rpm = scenario.speed_ref_rpm.at(t);
        // A skipped period (module docs): no tick, the last output held.
        let held = if skips.as_mut().is_some_and(|s| s.skip(kk)) {
            last_out
        } else {
            None
        };
        let out = match held {
            Some(o) => {
                skipped += 1;
                o
            }
            None => controller.tick(&ControllerInput {
                k: kk,
                t_s: t,
                i_abc_a: meas.i_abc_a,
                i_ab_a: i_ab_meas,
                u_dc_v: u_dc,
                speed_ref_mech_rad_s: speed_ref_rpm / RPM_PER_RAD_S,
                rotor: sensored.then_some(RotorFeedback {
                    theta_e_rad: state.theta_e_rad,
                    omega_mech_rad_s: state.omega_mech_rad_s,
                }),
            }),
        };
        if skips.is_some() {
            last_out = Some(out);
        }
        if let Some(&d) = out.duties.iter().find(|d| !d.is_finite()) {
            end = RunEnd::NonFinite {
                k: kk,
                t_s: t,
                quantity: "controller duties",
                value: d,
            };
            // The observers stepped in this period before the controller ticked.
            pipeline.push(obs_input, None, &mut hand_on);
            break;
        }
        let duties = out.duties.map(|d| d.clamp(0.0, 1.0));
        let load = load_torque_nm(&scenario.load, t, state.omega_mech_rad_s)
            + faults.as_ref().map_or(0.0, |f| f.extra_load_nm(kk));
        let mut applied = inverter.apply(duties, u_dc, u_dc, i_abc_true);
        let pwm = out.pwm_enabled;
        if !pwm {
            // All switches open: no voltage is commanded; the plant coasts (step_open).
            applied.u_ab_v = DVec2::ZERO;
            applied.u_ab_commanded_v = DVec2::ZERO;
        }

        let truth = Truth {
            theta_e_rad: state.theta_e_rad,
            omega_e_rad_s: omega_e,
            speed_rpm: state.omega_mech_rad_s * RPM_PER_RAD_S,
            i_ab_a: plant.i_ab_a(),
            i_dq_a: plant.i_dq_a().to_array(),
            torque_nm: plant.torque_nm(),
            load_torque_nm: load,
            psi_f_wb: plant.motor().psi_f_wb,
            rs_ohm: plant.motor().rs_ohm,
        };

        if let Some(f) = faults.as_mut() {
            f.before_step(kk, &mut plant);
        }
        if pwm {
            match inverter.segments() {
                None => plant.step(applied.u_ab_v.to_array(), load, ts),
                Some(segments) => {
                    // The delay line: each sub-interval with its own voltage (module docs).
                    let mut mean = DVec2::ZERO;
                    for s in segments.iter().filter(|s| s.fraction > 0.0) {
                        let u = inverter.voltage(s.duties, u_dc, plant.i_abc_a());
                        plant.step(u.to_array(), load, s.fraction * ts);
                        mean += u * s.fraction;
                    }
                    applied.u_ab_v = mean;
                }
            }
        } else {
            plant.step_open(load, ts);
        }
        if let Some(f) = faults.as_mut() {
            f.after_step(kk, &mut plant);
        }

        let sample = Sample {
            k: kk,
            t_s: t,
            truth,
            measured: crate::sim::Measured {
                i_abc_a: meas.i_abc_a,
                i_ab_a: i_ab_meas,
                u_dc_v: u_dc,
            },
            // Filled in by the pipeline with the observers' estimates.
            observer: ObserverSample::default(),
            seed_filter: None,
            controller_observer: match held {
                // A skipped period: the controller's observer made no estimate.
                Some(_) => None,
                None => out
                    .telemetry
                    .estimate
                    .map(|e| ObserverSample::from_controller(&e, &truth)),
            },
            control: ControlRecord {
                speed_ref_rpm,
                duties,
                telemetry: out.telemetry,
            },
            inverter: InverterRecord {
                pwm_enabled: pwm,
                duties: applied.duties,
                u_ab_v: applied.u_ab_v.to_array(),
                u_ab_commanded_v: applied.u_ab_commanded_v.to_array(),
                u_dc_v: u_dc,
            },
        };
        if !pipeline.push(obs_input, Some(sample), &mut hand_on) {
            // The hand-on ended the run (observer or sink failure): `hand_end` says where.
            break;
        }
        // Voltage over [t_k, t_k+1) as the controller knows it: its expectation for the duties
        // now applied (those of the previous tick with the delay, these without), else the
        // ideal-switch voltage of the applied duties; nothing with the PWM off.
        let expected_now = out.expected_u_ab_v;
        let expected_applied = if delay {
            core::mem::replace(&mut expected_pending, expected_now)
        } else {
            expected_now
        };
        u_prev = if pwm {
            expected_applied.unwrap_or(applied.u_ab_commanded_v.to_array())
        } else {
            [0.0; 2]
        };
        if k % 4096 == 4095
            && let Some(p) = opts.progress.as_mut()
        {
            p(k + 1, n);
        }
    }
    // The periods still in the pipeline.
    pipeline.finish(&mut hand_on);
    drop(pipeline);
    if let Some(e) = hand_end {
        end = e;
    }
    let wall_time_s = start.elapsed().as_secs_f64();
    if let Some(p) = opts.progress.as_mut() {
        p(n, n);
    }
    let mut metrics = acc.finish(
        scenario,
        end.describe(),
        wall_time_s,
        reference_filter_failure.map(|f| format!("sample {}: {}", f.k, f.error)),
    );
    metrics.skipped_control_periods = skipped;
    Ok(RunOutput {
        trace: Trace { ts_s: ts, samples },
        metrics,
        end,
        reference_filter_failure,
        wall_time_s,
    })
}
