//! The fault suite (`pmsm-sim faults`): every fault kind of [`crate::plant::fault_injection`] in closed loop
//! with the `foc` sensorless controller, one run each, scored and tabulated.
//!
//! # The runs
//!
//! The built-in default scenario's drive (servo motor, 10 kHz, 300 V, the realistic sensing
//! and 0.5 us of compensated dead time; `foc` sensorless with its start-up), held at rated
//! speed (2000 rpm from 0.6 s) with a passive fan load of rated torque at rated speed
//! (1.5 N m at 2000 rpm; after a trip the shaft coasts to rest), the reference filter off.
//! The fault starts at [`SuiteOptions::t_fault_s`] (default 1.2 s) and the run ends at
//! [`SuiteOptions::t_end_s`] (default 2.0 s).
//!
//! # What each row reports
//!
//! - **outcome**: `trip` (a fault latched in `foc`), `fall-back` (no trip, but `foc` left
//!   closed loop: its health monitor detected the observer lost and fell back to I/f) or
//!   `ride-through` (closed loop all along);
//! - **detected after**: from the fault's start to the trip or to the first exit from
//!   closed loop (a fall-back), whichever came first;
//! - **worst angle error**: `foc`'s own observer against the true angle, over the periods after
//!   the fault's start in which the loops ran on it (closed loop, PWM on), deg el.;
//! - **max phase current**: the true phase currents after the fault's start, A, against the
//!   stated limit [`CURRENT_LIMIT_FACTOR`] times `foc`'s over-current trip level;
//! - **safe**: every tick's duties finite and in `[0, 1]`, the PWM off with duties 0.5 once
//!   tripped, no non-finite voltage while the PWM is on (so no NaN reaches the PWM), and the
//!   current within the limit;
//! - **reason**: the latched fault;
//! - **speed at end**: the true speed at the end of the run, rpm.
//!
//! Each case states the behaviour expected of a sound drive ([`Expected`]); the table says
//! whether the run matched it. `pmsm-sim faults` exits 1 when a row did not (the rows are
//! named on stderr), 0 when every row did: no row is a documented known limit, so a
//! mismatch counts as a failure (with the defaults, the noise burst and the open phase fall
//! back to I/f instead of riding through and tripping).

use std::fmt::Write as _;

use serde::Serialize;

use crate::SimError;
use crate::drive::foc_adapter::FocDrive;
use crate::drive::interface::{ControllerInput, ControllerOutput, DriveController};
use crate::output::metrics::Sums;
use crate::plant::fault_injection::{Channel, Channels, FaultSpec, Phase};
use crate::plant::load::{LoadTerm, Profile};
use crate::scenario::{RPM_PER_RAD_S, Scenario};
use crate::sim::{self, RunOptions, Sample, SampleSink};

/// The stated phase-current limit as a multiple of `foc`'s over-current trip level.
pub const CURRENT_LIMIT_FACTOR: f64 = 1.25;

/// Timing of the suite's runs.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct SuiteOptions {
    /// Start of every fault, s.
    pub t_fault_s: f64,
    /// End of every run, s.
    pub t_end_s: f64,
}

impl Default for SuiteOptions {
    /// Fault at 1.2 s, end at 2.0 s.
    fn default() -> Self {
        Self {
            t_fault_s: 1.2,
            t_end_s: 2.0,
        }
    }
}

/// The behaviour expected of a sound drive.
#[derive(Clone, Copy, Debug, PartialEq, Eq, Serialize)]
pub enum Expected {
    /// Keeps running in closed loop (possibly degraded).
    RideThrough,
    /// Keeps running, with or without a fall-back to I/f and a new hand-over.
    RideThroughOrFallBack,
    /// Trips with this `foc` fault (its log name).
    Trip(&'static str),
    /// Trips with one of these faults.
    TripAny(&'static [&'static str]),
}

impl Expected {
    /// Text for the table.
    pub fn describe(&self) -> String {
        match self {
            Expected::RideThrough => "ride through".into(),
            Expected::RideThroughOrFallBack => "ride through (fall-back allowed)".into(),
            Expected::Trip(f) => format!("trip: {f}"),
            Expected::TripAny(fs) => format!("trip: {}", fs.join(" or ")),
        }
    }
}

/// One case of the suite.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct FaultCase {
    /// Row name.
    pub name: &'static str,
    /// The fault (its `t_s` is set to the suite's fault time).
    pub spec: FaultSpec,
    /// Expected behaviour.
    pub expected: Expected,
    /// Why that is expected.
    pub why: &'static str,
    /// Simulated time of this case's run after the fault, s (`None`: to the suite's end
    /// time).
    pub run_after_fault_s: Option<f64>,
}

/// The suite's cases (module docs).
pub fn cases() -> Vec<FaultCase> {
    use Expected::*;
    let t_s = 0.0;
    vec![
        FaultCase {
            name: "offset drift (a, 2 A/s)",
            spec: FaultSpec::OffsetDrift {
                t_s,
                duration_s: None,
                channel: Channel::A,
                rate_a_per_s: 2.0,
            },
            expected: RideThrough,
            why: "a slow offset is a plausible current; it adds torque ripple at the electrical frequency and angle error, not detected by foc (an offset calibration at standstill would be)",
            run_after_fault_s: None,
        },
        FaultCase {
            name: "gain error step (b, +20 %)",
            spec: FaultSpec::GainStep {
                t_s,
                duration_s: None,
                channel: Channel::B,
                gain_error: 0.2,
            },
            expected: RideThrough,
            why: "the current step is plausible; ripple at twice the electrical frequency",
            run_after_fault_s: None,
        },
        FaultCase {
            name: "channel stuck (a)",
            spec: FaultSpec::Stuck {
                t_s,
                duration_s: None,
                channel: Channel::A,
                value_a: None,
            },
            expected: Trip("current_sensor"),
            why: "foc's stuck-channel check: a reading repeated bit for bit while the current vector turns an eighth of a period (0.94 ms at 2000 rpm) cannot come from a live channel",
            run_after_fault_s: None,
        },
        FaultCase {
            name: "dropout, one sample (a and b)",
            spec: FaultSpec::Dropout {
                t_s,
                duration_s: None,
                channel: Channels::Both,
            },
            expected: RideThrough,
            why: "foc rides through a missing sample: observer predicts only, last voltage reused",
            run_after_fault_s: None,
        },
        FaultCase {
            name: "dropout, 5 ms (a)",
            spec: FaultSpec::Dropout {
                t_s,
                duration_s: Some(5e-3),
                channel: Channels::A,
            },
            expected: Trip("non_finite_input"),
            why: "missing for more than samples.missing_trip_ticks (5) periods",
            run_after_fault_s: None,
        },
        FaultCase {
            name: "noise burst (0.3 A, 50 ms)",
            spec: FaultSpec::NoiseBurst {
                t_s,
                duration_s: Some(50e-3),
                std_a: 0.3,
            },
            expected: RideThrough,
            why: "15 times the normal noise: the EKF weighs it by R; the angle error grows but stays bounded",
            run_after_fault_s: None,
        },
        FaultCase {
            name: "glitch, one sample at 10x rated (a)",
            spec: FaultSpec::Glitch {
                t_s,
                channel: Channel::A,
                value_a: None,
            },
            expected: RideThrough,
            why: "rejected as physically implausible (a current cannot jump by more than ~u_dc Ts / Ls per period), treated as missing; the debounced over-current check never sees it",
            run_after_fault_s: None,
        },
        FaultCase {
            name: "DC-bus sag to 70 % (0.2 s)",
            spec: FaultSpec::BusSag {
                t_s,
                duration_s: Some(0.2),
                fraction: 0.3,
            },
            expected: RideThrough,
            why: "210 V is above the 180 V under-voltage level; at 2000 rpm the voltage limit (121 V) is below the back-EMF (147 V): the speed drops until the EMF fits (no field weakening), and recovers",
            run_after_fault_s: None,
        },
        FaultCase {
            name: "DC-bus sag to 50 %",
            spec: FaultSpec::BusSag {
                t_s,
                duration_s: None,
                fraction: 0.5,
            },
            expected: Trip("bus_under_voltage"),
            why: "150 V is below the 180 V under-voltage level (0.6 U_nominal)",
            run_after_fault_s: None,
        },
        FaultCase {
            name: "phase open (a)",
            spec: FaultSpec::PhaseOpen {
                t_s,
                duration_s: None,
                phase: Phase::A,
            },
            expected: TripAny(&["observer_lost", "stall", "over_current"]),
            why: "half the current vector is gone: torque ripple, the observer's model no longer fits the currents; foc has no open-phase detection, so a loss or stall check has to catch it",
            run_after_fault_s: None,
        },
        FaultCase {
            name: "motor heating +100 K (Rs +39 %, psi_f -12 %, 0.2 s ramp)",
            spec: FaultSpec::ParamDrift {
                t_s,
                duration_s: Some(0.2),
                time_constant_s: None,
                temperature_rise_k: 100.0,
                rs_per_k: 0.00393,
                psi_f_per_k: -0.0012,
            },
            expected: RideThrough,
            why: "the observer tracks psi_f online (and Rs through the thermal link): the angle keeps its accuracy, and the health check sees no loss",
            run_after_fault_s: None,
        },
        FaultCase {
            name: "motor heating +100 K, thermal time constant 20 s, 60 s at rated load",
            spec: FaultSpec::ParamDrift {
                t_s,
                duration_s: None,
                time_constant_s: Some(20.0),
                temperature_rise_k: 100.0,
                rs_per_k: 0.00393,
                psi_f_per_k: -0.0012,
            },
            expected: RideThrough,
            why: "a realistic warm-up (95 % of the rise after 60 s): the tracked psi_f and Rs follow it, no fall-back, no trip",
            run_after_fault_s: Some(60.0),
        },
        FaultCase {
            name: "locked rotor",
            spec: FaultSpec::LockedRotor {
                t_s,
                duration_s: None,
            },
            expected: TripAny(&["stall", "observer_lost"]),
            why: "the speed loop saturates at standstill: the stall check (0.5 s) trips; the observer cannot see a rotor that does not turn",
            run_after_fault_s: None,
        },
        FaultCase {
            name: "load 5x rated (+6 N m, active)",
            spec: FaultSpec::Overload {
                t_s,
                duration_s: None,
                torque_nm: 6.0,
            },
            expected: TripAny(&["stall", "observer_lost"]),
            why: "6 N m plus the fan against at most 4.7 N m at the 4.5 A limit: the rotor slows down and is driven backwards; the stall check trips (0.5 s at the limit with the speed low or reversed). (+4.5 N m is still carried, at 650 rpm)",
            run_after_fault_s: None,
        },
    ]
}

/// The scenario of the suite's runs, without faults (module docs).
pub fn base_scenario(opts: &SuiteOptions) -> Scenario {
    let mut sc = Scenario::default_servo();
    sc.name = "faults".into();
    sc.description =
        "fault suite: default drive at 2000 rpm, rated fan load, then one fault".into();
    sc.duration_s = opts.t_end_s;
    sc.observer.reference_filter = false;
    sc.speed_ref_rpm = Profile::linear(vec![(0.1, 0.0), (0.6, 2000.0)]);
    // foc's classic start (align, undamped I/f): the suite's rows were measured on that
    // trajectory, and some (the stuck channel's peak current: 2.1 to 8.3 A for a fault 0 to
    // 1.5 ms later) depend on the electrical angle at which the fault strikes.
    let mut foc = sc.controller.foc.unwrap_or_default();
    foc.startup_damping_ratio = Some(0.0);
    foc.startup_kick_speed_ratio = Some(0.0);
    sc.controller.foc = Some(foc);
    // A passive (fan) load, rated torque at rated speed: after a trip the shaft coasts to
    // rest instead of being driven backwards.
    let w_rated = sc.rated_speed_mech_rad_s();
    sc.load = vec![LoadTerm::Fan {
        coefficient_nm_s2_rad2: sc.rated_torque_nm / (w_rated * w_rated),
    }];
    sc
}

/// One case's result.
#[derive(Clone, Debug, PartialEq, Serialize)]
pub struct CaseResult {
    /// Row name.
    pub name: &'static str,
    /// The fault's kind.
    pub kind: &'static str,
    /// Expected behaviour.
    pub expected: Expected,
    /// `trip`, `fall-back` or `ride-through`.
    pub outcome: &'static str,
    /// The latched fault.
    pub reason: Option<&'static str>,
    /// Time from the fault to the trip or the first exit from closed loop, whichever came
    /// first, s.
    pub detected_after_s: Option<f64>,
    /// Worst |angle error| of foc's observer after the fault, while in closed loop, deg el.
    pub worst_angle_error_deg: f64,
    /// Periods of that window in which foc's observer reported `Tracking` while more than
    /// 45 deg off.
    pub tracking_while_lost: usize,
    /// Largest true phase current after the fault, A.
    pub max_phase_current_a: f64,
    /// The stated current limit, A.
    pub current_limit_a: f64,
    /// Ticks with duties non-finite or outside `[0, 1]`.
    pub bad_duties: u64,
    /// Ticks with a fault latched but the PWM on or duties not 0.5.
    pub unsafe_trips: u64,
    /// Ticks with the PWM on and a non-finite voltage.
    pub non_finite_voltage: u64,
    /// Whether every safety check passed.
    pub safe: bool,
    /// True speed at the end, rpm.
    pub final_speed_rpm: f64,
    /// Whether the outcome matches the expectation.
    pub as_expected: bool,
    /// How the simulation ended.
    pub run_end: String,
}

/// The `foc` drive with checks on every raw output.
struct Checked {
    drive: FocDrive,
    bad_duties: u64,
    unsafe_trips: u64,
    non_finite_voltage: u64,
}

impl DriveController for Checked {
    fn sensored(&self) -> bool {
        self.drive.sensored()
    }

    fn tick(&mut self, input: &ControllerInput) -> ControllerOutput {
        let out = self.drive.tick(input);
        if !out
            .duties
            .iter()
            .all(|d| d.is_finite() && (0.0..=1.0).contains(d))
        {
            self.bad_duties += 1;
        }
        if out.telemetry.fault.is_some() && (out.pwm_enabled || out.duties != [0.5; 3]) {
            self.unsafe_trips += 1;
        }
        let u = out.telemetry.u_ab_ref_v;
        if out.pwm_enabled && !(u[0].is_finite() && u[1].is_finite()) {
            self.non_finite_voltage += 1;
        }
        out
    }
}

/// Scores the samples after the fault.
struct Score {
    k_fault: u64,
    ts_s: f64,
    reason: Option<&'static str>,
    t_trip: Option<f64>,
    t_exit: Option<f64>,
    /// `foc`'s observer while the loops ran on it (the simulator's one error accumulator; the
    /// worst angle error is its `max_e`).
    closed_loop: Sums,
    max_current_a: f64,
    final_speed_rpm: f64,
}

impl SampleSink for Score {
    fn record(&mut self, s: &Sample) -> Result<(), String> {
        self.final_speed_rpm = s.truth.speed_rpm;
        if s.k < self.k_fault {
            return Ok(());
        }
        let tel = &s.control.telemetry;
        let dt = (s.k - self.k_fault) as f64 * self.ts_s;
        if let (None, Some(f)) = (self.reason, tel.fault) {
            self.reason = Some(f);
            self.t_trip = Some(dt);
        }
        if self.t_exit.is_none() && !tel.closed_loop && tel.fault.is_none() {
            self.t_exit = Some(dt);
        }
        if tel.closed_loop
            && s.inverter.pwm_enabled
            && let Some(o) = &s.controller_observer
        {
            self.closed_loop.add_sample(o);
        }
        // The true phase currents from the true alpha-beta vector.
        let abc = crate::plant::frames::inverse_clarke(s.truth.i_ab_a);
        for i in abc {
            self.max_current_a = self.max_current_a.max(i.abs());
        }
        Ok(())
    }
}

/// Runs one case.
pub fn run_case(case: &FaultCase, opts: &SuiteOptions) -> Result<CaseResult, SimError> {
    let mut sc = base_scenario(opts);
    if let Some(t) = case.run_after_fault_s {
        sc.duration_s = opts.t_fault_s + t;
    }
    sc.faults = vec![case.spec.at(opts.t_fault_s)];
    sc.name = format!("faults: {}", case.name);
    let drive = FocDrive::from_scenario(&sc)?;
    let oc = f64::from(drive.foc().config().over_current_a);
    let mut checked = Checked {
        drive,
        bad_duties: 0,
        unsafe_trips: 0,
        non_finite_voltage: 0,
    };
    let ts = sc.ts_s();
    let mut score = Score {
        k_fault: (opts.t_fault_s / ts).round() as u64,
        ts_s: ts,
        reason: None,
        t_trip: None,
        t_exit: None,
        closed_loop: Sums::default(),
        max_current_a: 0.0,
        final_speed_rpm: 0.0,
    };
    let out = sim::run_with_controller(
        &sc,
        &mut checked,
        RunOptions {
            sinks: vec![&mut score],
            ..RunOptions::default()
        },
    )?;
    let outcome = if score.reason.is_some() {
        "trip"
    } else if score.t_exit.is_some() {
        "fall-back"
    } else {
        "ride-through"
    };
    let limit = CURRENT_LIMIT_FACTOR * oc;
    let safe = checked.bad_duties == 0
        && checked.unsafe_trips == 0
        && checked.non_finite_voltage == 0
        && score.max_current_a <= limit
        && out.end.is_completed();
    let as_expected = match case.expected {
        Expected::RideThrough => outcome == "ride-through",
        Expected::RideThroughOrFallBack => outcome != "trip",
        Expected::Trip(f) => score.reason == Some(f),
        Expected::TripAny(fs) => score.reason.is_some_and(|r| fs.contains(&r)),
    };
    Ok(CaseResult {
        name: case.name,
        kind: case.spec.kind(),
        expected: case.expected,
        outcome,
        reason: score.reason,
        detected_after_s: match (score.t_trip, score.t_exit) {
            (Some(a), Some(b)) => Some(a.min(b)),
            (a, b) => a.or(b),
        },
        worst_angle_error_deg: score.closed_loop.max_e,
        tracking_while_lost: score.closed_loop.tracking_lost,
        max_phase_current_a: score.max_current_a,
        current_limit_a: limit,
        bad_duties: checked.bad_duties,
        unsafe_trips: checked.unsafe_trips,
        non_finite_voltage: checked.non_finite_voltage,
        safe,
        final_speed_rpm: score.final_speed_rpm,
        as_expected,
        run_end: out.end.describe(),
    })
}

/// Runs every case of [`cases`].
pub fn run_suite(opts: &SuiteOptions) -> Result<Vec<CaseResult>, SimError> {
    cases().iter().map(|c| run_case(c, opts)).collect()
}

/// The results as a markdown document: the table, then the expected behaviour per fault.
pub fn markdown(results: &[CaseResult], opts: &SuiteOptions) -> String {
    let mut s = String::new();
    let sc = base_scenario(opts);
    let _ = writeln!(s, "# pmsm-sim fault suite\n");
    let _ = writeln!(
        s,
        "Drive: {} ({}). Rated speed {} rpm, rated load {} N m; each fault starts at t = {} s, \
         runs end at {} s. Angle error: foc's observer vs the true angle while the loops run \
         on it (closed loop) after the fault. Current limit: {} x foc's over-current level. \
         Safe: duties finite and in [0, 1] every tick, PWM off once tripped, no non-finite \
         voltage with the PWM on, current within the limit.\n",
        sc.controller_description(),
        sc.description,
        sc.rated_speed_rpm,
        sc.rated_torque_nm,
        opts.t_fault_s,
        opts.t_end_s,
        CURRENT_LIMIT_FACTOR,
    );
    let _ = writeln!(
        s,
        "| fault | expected | outcome | reason | detected after | worst angle error | Tracking while > 45 deg off | max phase current | safe | speed at end | as expected |"
    );
    let _ = writeln!(s, "|---|---|---|---|---|---|---|---|---|---|---|");
    for r in results {
        let det = r
            .detected_after_s
            .map_or("-".to_string(), |t| format!("{:.1} ms", t * 1e3));
        let safe = if r.safe {
            "yes".to_string()
        } else {
            format!(
                "NO (duties {}, trips {}, voltage {}, {})",
                r.bad_duties, r.unsafe_trips, r.non_finite_voltage, r.run_end
            )
        };
        let _ = writeln!(
            s,
            "| {} | {} | {} | {} | {} | {:.2} deg | {} | {:.2} A (limit {:.2}) | {} | {:.0} rpm | {} |",
            r.name,
            r.expected.describe(),
            r.outcome,
            r.reason.unwrap_or("-"),
            det,
            r.worst_angle_error_deg,
            r.tracking_while_lost,
            r.max_phase_current_a,
            r.current_limit_a,
            safe,
            r.final_speed_rpm,
            if r.as_expected { "yes" } else { "NO" },
        );
    }
    let _ = writeln!(s, "\n## Expected behaviour\n");
    for c in cases() {
        let _ = writeln!(
            s,
            "- **{}** (`{}`): {}. {}.",
            c.name,
            c.spec.kind(),
            c.expected.describe(),
            c.why
        );
    }
    let _ = writeln!(
        s,
        "\nSpeeds in rpm are mechanical; {} rpm = {:.1} rad/s el.",
        sc.rated_speed_rpm,
        sc.rated_speed_rpm / RPM_PER_RAD_S * sc.motor.p()
    );
    s
}
