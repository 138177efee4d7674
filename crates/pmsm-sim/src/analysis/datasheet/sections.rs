//! Sections 2, 5 and 6: the low-speed limit, self-commissioning and lock loss under
//! parameter error, each through the analysis module that owns the method.
//!
//! - **Low speed** ([`low_speed()`]): [`crate::analysis::low_speed`]'s run at each test speed
//!   (rated active load, held, no fall-back), the speeds on the threads; the lowest speed down
//!   to which every speed passes, by that module's rule.
//! - **Identification** ([`identify`]): [`crate::analysis::identify::identify`] on the motor's
//!   preset, once per noise seed `seed + 1 ..= seed + n`; each parameter's error in % and the
//!   sequence's simulated time.
//! - **Lock loss** ([`monte_carlo`]): a [`Plan`] over the motor's preset (its own job, e.g. the
//!   default scenario's start, rated speed, load step and reversal), the drive's model (what
//!   foc and the observers are told: `observer.rs_ohm` +-30 %, `observer.ld_h` and
//!   `observer.lq_h` +-20 % each, `observer.psi_f_wb` +-10 %), the inverter's dead time
//!   0-2 us (foc is told it, as in the presets) and the current sensors' noise x0.5-x3, all
//!   uniform, the sweep's seed the datasheet's. A run **lost the lock** when it left closed
//!   loop, tripped, stopped early or could not run.

use serde::Serialize;

use crate::SimError;
use crate::analysis::identify::{IdentifyOptions, MotorValues};
use crate::analysis::low_speed::{self, LowSpeedRow};
use crate::analysis::suite::SuiteMotor;
use crate::analysis::sweep::{Cell, Plan, run_one};
use crate::scenario::Scenario;

use super::start::pct;
use super::{Sizes, all_ok, par_map};

/// Section 2: the low-speed row of `motor` over `sizes`' speeds (module docs).
pub fn low_speed(
    motor: SuiteMotor,
    sizes: &Sizes,
    threads: usize,
) -> Result<LowSpeedRow, SimError> {
    let hold = sizes.low_speed_hold_s;
    let runs = all_ok(par_map(&sizes.low_speeds_pct, threads, |&p| {
        low_speed::run_speed(motor, p, hold)
    }))?;
    let mut lowest = None;
    for r in &runs {
        if !r.pass {
            break;
        }
        lowest = Some(r.clone());
    }
    let sc = low_speed::scenario(
        motor,
        sizes.low_speeds_pct.first().copied().unwrap_or(10.0),
        hold,
    )?;
    Ok(LowSpeedRow {
        motor,
        rated_speed_rpm: sc.rated_speed_rpm,
        rated_torque_current_a: low_speed::rated_torque_current_a(&sc)?,
        runs,
        lowest,
    })
}

/// One identification.
#[derive(Clone, Debug, PartialEq, Serialize)]
pub struct IdentifyRun {
    /// Noise seed.
    pub seed: u64,
    /// Whether the sequence finished with results.
    pub ok: bool,
    /// The failure, if any.
    pub error: Option<String>,
    /// Errors, % (when `ok`).
    pub errors_pct: Option<MotorValues>,
    /// Whole sequence, simulated s.
    pub total_time_s: f64,
}

/// Section 5's runs.
#[derive(Clone, Debug, PartialEq, Serialize)]
pub struct IdentifySweep {
    /// The preset identified.
    pub preset: &'static str,
    /// One run per seed.
    pub runs: Vec<IdentifyRun>,
}

/// One quantity of a [`MotorValues`], if it has it.
pub type Quantity = fn(&MotorValues) -> Option<f64>;

/// The parameters of the identification table: name and value of a [`MotorValues`].
pub const IDENTIFIED: [(&str, Quantity); 6] = [
    ("Rs", |v| Some(v.rs_ohm)),
    ("Ld", |v| Some(v.ld_h)),
    ("Lq", |v| Some(v.lq_h)),
    ("psi_f", |v| v.psi_f_wb),
    ("J", |v| v.j_kg_m2),
    ("inverter voltage error", |v| {
        Some(v.inverter_voltage_error_v)
    }),
];

impl IdentifySweep {
    /// Successful runs, %.
    pub fn ok_pct(&self) -> f64 {
        pct(self.runs.iter().filter(|r| r.ok).count(), self.runs.len())
    }

    /// Per parameter of [`IDENTIFIED`]: (mean |error|, largest |error|) in % over the
    /// successful runs that give it.
    pub fn summary(&self) -> Vec<(&'static str, Option<(f64, f64)>)> {
        IDENTIFIED
            .iter()
            .map(|(name, get)| {
                let e: Vec<f64> = self
                    .runs
                    .iter()
                    .filter_map(|r| r.errors_pct.as_ref().and_then(get))
                    .filter(|x| x.is_finite())
                    .map(f64::abs)
                    .collect();
                let s = (!e.is_empty()).then(|| {
                    (
                        e.iter().sum::<f64>() / e.len() as f64,
                        e.iter().fold(0.0_f64, |m, x| m.max(*x)),
                    )
                });
                (*name, s)
            })
            .collect()
    }

    /// The longest sequence, simulated s.
    pub fn longest_s(&self) -> f64 {
        self.runs.iter().fold(0.0_f64, |m, r| m.max(r.total_time_s))
    }
}

/// Section 5: `n` identifications (module docs).
pub fn identify(
    motor: SuiteMotor,
    n: usize,
    seed: u64,
    threads: usize,
) -> Result<IdentifySweep, SimError> {
    let preset = low_speed::preset_name(motor);
    let sc = Scenario::preset(preset)?;
    let seeds: Vec<u64> = (1..=n as u64).map(|k| seed.wrapping_add(k)).collect();
    let runs = all_ok(par_map(&seeds, threads, |&s| {
        let opts = IdentifyOptions {
            seed: Some(s),
            ..IdentifyOptions::default()
        };
        crate::analysis::identify::identify(&sc, &opts).map(|r| IdentifyRun {
            seed: s,
            ok: r.ok,
            error: r.error,
            errors_pct: r.errors_pct,
            total_time_s: r.total_time_s,
        })
    }))?;
    Ok(IdentifySweep { preset, runs })
}

/// One Monte-Carlo run.
#[derive(Clone, Debug, PartialEq, Serialize)]
pub struct McRun {
    /// Error of the Rs the drive is told, %.
    pub rs_error_pct: f64,
    /// Error of the Ld told, %.
    pub ld_error_pct: f64,
    /// Error of the Lq told, %.
    pub lq_error_pct: f64,
    /// Error of the psi_f told, %.
    pub psi_f_error_pct: f64,
    /// Inverter dead time, us.
    pub dead_time_us: f64,
    /// Sensor noise, times the preset's.
    pub noise_factor: f64,
    /// Lost the lock (module docs).
    pub lost: bool,
    /// Why, when it did: `fault <kind>`, `stopped early`, `left closed loop`,
    /// `could not run (<error>)`.
    pub reason: Option<String>,
    /// RMS angle error of foc's observer in closed loop, deg el. (`None`: not available).
    pub angle_error_rms_deg: Option<f64>,
}

/// Section 6's sweep.
#[derive(Clone, Debug, PartialEq, Serialize)]
pub struct MonteCarlo {
    /// The preset swept.
    pub preset: &'static str,
    /// The sweep's seed.
    pub seed: u64,
    /// The plan's `[vary]` table as `pmsm-sim sweep` reads it (TOML).
    pub plan_toml: String,
    /// Every run, in plan order.
    pub runs: Vec<McRun>,
}

impl MonteCarlo {
    /// Runs that lost the lock, %.
    pub fn lost_pct(&self) -> f64 {
        pct(self.runs.iter().filter(|r| r.lost).count(), self.runs.len())
    }
}

fn float(v: Option<&toml::Value>) -> f64 {
    match v {
        Some(toml::Value::Float(f)) => *f,
        Some(toml::Value::Integer(i)) => *i as f64,
        _ => f64::NAN,
    }
}

/// Section 6: `n` runs of the Monte-Carlo plan (module docs).
pub fn monte_carlo(
    motor: SuiteMotor,
    n: usize,
    seed: u64,
    threads: usize,
) -> Result<MonteCarlo, SimError> {
    let preset = low_speed::preset_name(motor);
    let sc = Scenario::preset(preset)?;
    let p = sc.observer_params();
    let noise = sc.sensors.current_noise_std_a;
    let uniform =
        |lo: f64, hi: f64| toml::Value::Array(vec!["uniform".into(), lo.into(), hi.into()]);
    let vary: Vec<(String, toml::Value)> = vec![
        (
            "observer.rs_ohm".into(),
            uniform(0.7 * p.rs_ohm, 1.3 * p.rs_ohm),
        ),
        ("observer.ld_h".into(), uniform(0.8 * p.ld_h, 1.2 * p.ld_h)),
        ("observer.lq_h".into(), uniform(0.8 * p.lq_h, 1.2 * p.lq_h)),
        (
            "observer.psi_f_wb".into(),
            uniform(0.9 * p.psi_f_wb, 1.1 * p.psi_f_wb),
        ),
        ("inverter.dead_time_s".into(), uniform(0.0, 2e-6)),
        (
            "sensors.current_noise_std_a".into(),
            uniform(0.5 * noise, 3.0 * noise),
        ),
    ];
    let plan_toml = vary
        .iter()
        .map(|(k, v)| format!("\"{k}\" = {v}"))
        .collect::<Vec<_>>()
        .join("\n");
    let plan = Plan::new(&sc, &vary, n.max(1), seed).map_err(|problem| SimError::Scenario {
        file: format!("datasheet Monte-Carlo plan of {preset}"),
        field: "vary".into(),
        problem,
    })?;
    let specs = plan.runs()?;
    let rel = |v: f64, base: f64| 100.0 * (v / base - 1.0);
    let runs = par_map(&specs, threads, |spec| {
        let row = run_one(spec, None);
        let value = |path: &str| float(spec.values.iter().find(|(k, _)| k == path).map(|(_, v)| v));
        let metric = |name: &str| row.metrics.iter().find(|(k, _)| k == name).map(|(_, c)| c);
        let reason = if let Some(e) = &row.error {
            Some(format!("could not run ({e})"))
        } else if let Some(Cell::Text(f)) = metric("drive.fault") {
            // "over_current at 1.2345 s": the kind only.
            Some(format!("fault {}", f.split(" at ").next().unwrap_or(f)))
        } else if metric("end").is_some_and(|c| *c != Cell::Text("completed".into())) {
            Some("stopped early".into())
        } else if metric("drive.closed_loop_exits").is_some_and(|c| *c != Cell::Int(0)) {
            Some("left closed loop".into())
        } else {
            None
        };
        let angle = match metric("controller_observer_closed_loop.angle_error_rms_deg") {
            Some(Cell::Float(x)) => Some(*x),
            _ => None,
        };
        McRun {
            rs_error_pct: rel(value("observer.rs_ohm"), p.rs_ohm),
            ld_error_pct: rel(value("observer.ld_h"), p.ld_h),
            lq_error_pct: rel(value("observer.lq_h"), p.lq_h),
            psi_f_error_pct: rel(value("observer.psi_f_wb"), p.psi_f_wb),
            dead_time_us: 1e6 * value("inverter.dead_time_s"),
            noise_factor: if noise > 0.0 {
                value("sensors.current_noise_std_a") / noise
            } else {
                f64::NAN
            },
            lost: reason.is_some(),
            reason,
            angle_error_rms_deg: angle,
        }
    });
    Ok(MonteCarlo {
        preset,
        seed,
        plan_toml,
        runs,
    })
}
