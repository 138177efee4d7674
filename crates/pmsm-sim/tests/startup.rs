//! The sensorless start of `foc` (module `foc::startup`: alignment, damped I/f ramp,
//! hand-over to its EKF) on the simulator's closed loop, over the three surface reference
//! motors and a grid of 12 initial rotor angles (every 30 deg el.), against the goals:
//!
//! - the rotor never turns backwards faster than 1 % of rated speed;
//! - from 0.1 s after the alignment to the hand-over the speed stays within 10 % of rated
//!   speed of the I/f ramp;
//! - the hand-over takes place at or below 3 % of rated speed (pmsm-sim's default for the
//!   damped start, `foc::StartupConfig::handover_speed_for`; the run checks that the
//!   hand-over happens, without a fault).
//!
//! The figures are pmsm-sim's own start-up metrics ([`pmsm_sim::output::metrics::StartupMetrics`]).
//! `cargo test --release -p pmsm-sim --test startup -- --nocapture` prints the table.
//!
//! Each motor runs its preset's plant, inverter (delay, dead time) and sensors (noise, ADC),
//! with `foc` sensorless in place of the preset's controller, the preset's loads and a speed
//! command of rated speed from t = 0.

use pmsm_sim::analysis::low_speed::preset_name;
use pmsm_sim::analysis::suite::SuiteMotor;
use pmsm_sim::output::metrics::StartupMetrics;
use pmsm_sim::plant::load::Profile;
use pmsm_sim::scenario::{ControllerKind, Scenario};
use pmsm_sim::sim;

/// The three surface reference motors: (name, simulator preset).
fn motors() -> impl Iterator<Item = (&'static str, &'static str)> {
    SuiteMotor::SURFACE
        .into_iter()
        .map(|m| (m.name(), preset_name(m)))
}

/// Goals, % of rated speed.
const BACKWARD_MAX_PCT: f64 = 1.0;
const DEVIATION_MAX_PCT: f64 = 10.0;
const HANDOVER_MAX_PCT: f64 = 3.0;

/// The preset's scenario from `theta0` (rad el.), its noise seed moved by `dseed`.
fn scenario(preset: &str, theta0: f64, dseed: u64) -> Scenario {
    let mut sc = Scenario::preset(preset).unwrap_or_else(|e| panic!("{e}"));
    sc.name = format!("{preset} from {:.0} deg", theta0.to_degrees());
    sc.seed += dseed;
    sc.initial.theta_e_rad = theta0;
    sc.initial.speed_rpm = 0.0;
    sc.controller.kind = ControllerKind::Foc;
    let mut foc = sc.controller.foc.unwrap_or_default();
    foc.start_time_s = 0.0;
    foc.stop_time_s = None;
    sc.controller.foc = Some(foc);
    sc.speed_ref_rpm = Profile::steps(vec![(0.0, sc.rated_speed_rpm)]);
    // The alignment (0.2 s by default, up to twice that and a coast), the ramp to the
    // hand-over speed (0.5 s by default), the observer's lock time and a margin.
    sc.duration_s = foc.align_time_s.unwrap_or(0.2) + 1.5;
    sc.faults.clear();
    sc
}

fn startup(sc: &Scenario) -> (StartupMetrics, Option<String>) {
    let out = sim::run(sc).unwrap_or_else(|e| panic!("{}: {e}", sc.name));
    let st = out
        .metrics
        .startup
        .unwrap_or_else(|| panic!("{}: no start-up", sc.name));
    (st, out.metrics.drive.fault)
}

/// One cell of the grid.
struct Cell {
    motor: &'static str,
    dseed: u64,
    theta0_deg: f64,
    st: StartupMetrics,
    fault: Option<String>,
}

impl Cell {
    /// The ramp deviation counts unless the hand-over came before its window opened.
    fn deviation_pct(&self) -> Option<f64> {
        let st = &self.st;
        let opens = st
            .align_end_s
            .map(|t| t + pmsm_sim::output::metrics::RAMP_SETTLE_S);
        match (opens, st.handover_s) {
            (Some(o), Some(h)) if h <= o => None,
            _ => Some(st.ramp_deviation_max_pct),
        }
    }

    /// What misses the goals (with the given limits, % of rated speed).
    fn misses(&self, backward: f64, deviation: f64, handover: f64) -> Vec<String> {
        let st = &self.st;
        let mut why = vec![];
        if let Some(f) = &self.fault {
            why.push(format!("fault {f}"));
        }
        if st.backward_speed_max_pct > backward {
            why.push(format!("backward {:.2} %", st.backward_speed_max_pct));
        }
        if let Some(d) = self.deviation_pct()
            && (d.is_nan() || d > deviation)
        {
            why.push(format!("ramp deviation {d:.2} %"));
        }
        let ho = st.handover_speed_pct;
        if st.handover_s.is_none() || ho.is_nan() || ho > handover + 1e-3 {
            why.push(format!(
                "hand-over {:?} at {:.2} %",
                st.handover_s, st.handover_speed_pct
            ));
        }
        why
    }
}

/// Runs the grid with the presets' noise seeds moved by `dseed` and prints its table (per
/// cell, then the worst per motor).
fn grid(dseed: u64) -> Vec<Cell> {
    println!("Noise seeds: the presets' + {dseed}");
    println!(
        "| motor | rotor at (deg el.) | backward (% rated) | ramp deviation (% rated) | hand-over (s) | hand-over speed (% rated) |"
    );
    println!("|---|---|---|---|---|---|");
    let mut cells = vec![];
    for (motor, preset) in motors() {
        for k in 0..12 {
            let theta0_deg = f64::from(k) * 30.0 - 180.0;
            let sc = scenario(preset, theta0_deg.to_radians(), dseed);
            let (st, fault) = startup(&sc);
            let cell = Cell {
                motor,
                dseed,
                theta0_deg,
                st,
                fault,
            };
            println!(
                "| {motor} | {theta0_deg:.0} | {:.2} | {} | {} | {:.2} |",
                st.backward_speed_max_pct,
                cell.deviation_pct()
                    .map_or_else(|| "- (hand-over first)".into(), |d| format!("{d:.2}")),
                st.handover_s
                    .map_or_else(|| "never".into(), |t| format!("{t:.3}")),
                st.handover_speed_pct,
            );
            cells.push(cell);
        }
    }
    println!();
    println!(
        "| motor | worst backward (% rated) | worst ramp deviation (% rated) | highest hand-over speed (% rated) | latest hand-over (s) |"
    );
    println!("|---|---|---|---|---|");
    for (motor, _) in motors() {
        let m: Vec<&Cell> = cells.iter().filter(|c| c.motor == motor).collect();
        let worst = |f: &dyn Fn(&Cell) -> f64| m.iter().map(|c| f(c)).fold(0.0_f64, f64::max);
        println!(
            "| {motor} | {:.2} | {:.2} | {:.2} | {:.3} |",
            worst(&|c| c.st.backward_speed_max_pct),
            worst(&|c| c.deviation_pct().unwrap_or(0.0)),
            worst(&|c| c.st.handover_speed_pct),
            worst(&|c| c.st.handover_s.unwrap_or(f64::INFINITY)),
        );
    }
    cells
}

/// The goals, as they stand: backward at most 1 % of rated speed, ramp
/// deviation at most 10 %, hand-over at or below 3 %, no fault, on every cell, with the
/// presets' noise seeds and with the next ones (a start that meets the goals by the luck of
/// one noise sequence does not count).
///
/// Measured with the presets' seeds (and the next ones): every cell meets every goal. Worst
/// backward speed: servo 0.97 % (0.76 %), industrial_2k2 0.84 % (0.79 %), small_fast 0.94 %
/// (0.87 %); worst ramp deviation 0.68 % (industrial_2k2); every hand-over at 3 %. Before
/// the kick's flux detectors, the coast's stop rule and 0.3 s limit and the observer's
/// threshold from its noise at standstill (module `foc::startup`), 10 of these 72 cells
/// missed the backward goal, all at the kick: servo 1.29 % (from -180 deg, the dead point
/// of the first vector) and 1.00-1.02 % from 150 deg; industrial_2k2 up to 1.76 % (60 deg)
/// and 2.33 % (150 deg, next seeds), the observer's speed lagging the starting rotor (its
/// angle can be 90 deg off at standstill) or its noise starting coasts of a crawling rotor.
/// The margin is thin: the servo's worst cell is at 0.97 %.
#[test]
fn damped_start_meets_the_goals_on_three_motors_and_twelve_rotor_angles() {
    let mut cells = grid(0);
    cells.extend(grid(1));
    let failures: Vec<String> = cells
        .iter()
        .map(|c| {
            (
                c,
                c.misses(BACKWARD_MAX_PCT, DEVIATION_MAX_PCT, HANDOVER_MAX_PCT),
            )
        })
        .filter(|(_, m)| !m.is_empty())
        .map(|(c, m)| {
            format!(
                "{} (seed + {}) from {:.0} deg: {}",
                c.motor,
                c.dseed,
                c.theta0_deg,
                m.join(", ")
            )
        })
        .collect();
    assert!(failures.is_empty(), "{failures:#?}");
}

/// What the damped start achieves today, asserted with a margin (a regression guard, not
/// the goal): every cell hands over at 3 % of rated speed without a fault, never turns
/// backwards faster than 2 % of rated speed (measured 0.97 % at worst), stays within 2 % of
/// the ramp (measured 0.68 %), and the small_fast motor meets the full goals.
#[test]
fn damped_start_over_three_motors_and_twelve_rotor_angles() {
    let cells = grid(0);
    let mut failures = vec![];
    for c in &cells {
        let m = if c.motor == "small_fast" {
            c.misses(BACKWARD_MAX_PCT, DEVIATION_MAX_PCT, HANDOVER_MAX_PCT)
        } else {
            c.misses(2.0, 2.0, HANDOVER_MAX_PCT)
        };
        if !m.is_empty() {
            failures.push(format!(
                "{} from {:.0} deg: {}",
                c.motor,
                c.theta0_deg,
                m.join(", ")
            ));
        }
    }
    assert!(failures.is_empty(), "{failures:#?}");
}

/// The same grid on four more noise seeds (the presets' + 2 to + 5): the start stays
/// without a wrong launch (a regression guard, not the goal): every cell hands over at 3 %
/// of rated speed without a fault, never turns backwards faster than 5 % of rated speed
/// and stays within 5 % of the ramp. Measured: worst backward 1.42 % (small_fast from -180
/// deg, seed + 5; the goal's 1 % is missed on 6 of these 144 cells, all small_fast: from
/// -180 deg on all four seeds, 1.12-1.42 %, from 30 deg on seed + 2, 1.06 %, and from 0 deg
/// on seed + 5, 1.11 %: the late detection at the dead point and the current sensors'
/// noise in the coast, module `foc::startup`), worst ramp deviation 0.62 %.
#[test]
fn damped_start_without_a_wrong_launch_on_four_more_noise_seeds() {
    let mut failures = vec![];
    for dseed in 2..6 {
        for c in grid(dseed) {
            let m = c.misses(5.0, 5.0, HANDOVER_MAX_PCT);
            if !m.is_empty() {
                failures.push(format!(
                    "{} (seed + {}) from {:.0} deg: {}",
                    c.motor,
                    c.dseed,
                    c.theta0_deg,
                    m.join(", ")
                ));
            }
        }
    }
    assert!(failures.is_empty(), "{failures:#?}");
}
