//! Monte-Carlo and grid sweeps: many runs of one scenario with some keys varied, one table
//! row per run (`pyfoc.sweep`, `pmsm-sim sweep`).
//!
//! [`Plan`] expands a scenario and its varied paths into one scenario per run ([`plan`]
//! documents the spellings and the sampling rules); [`run_one`] runs one of them (no trace, the
//! observers on the calling thread: one core per run) and returns its [`Row`]; [`table`] types
//! the rows' columns. The columns of a sweep's table, in order:
//!
//! - `index`: the run's position in the plan;
//! - each varied path under its dotted name (`motor.rs_ohm`), sorted;
//! - `seed`: the run's noise seed;
//! - the run's metrics (`metrics.json` of `pmsm-sim run`) flattened with dotted names
//!   (`observer.angle_error_rms_deg`, `drive.fault`, `startup.backward_speed_max_rpm`), minus
//!   the wall-clock figures (`wall_time_s`, `real_time_factor`), which differ from run to run;
//!   a metric that does not apply (`NaN` or `null` in the JSON) is a null;
//! - `error`: null, or why the run could not run (an invalid varied value, a refused
//!   configuration): such a run is a row with its error and null metrics.

#[cfg(feature = "cli")]
pub mod cli;
pub mod parquet_out;
pub mod period_table;
pub mod plan;
pub mod table;

pub use plan::{Plan, RunSpec, Spread};
pub use table::{Cell, Column, ColumnKind};

use crate::scenario::Scenario;
use crate::sim::{RunOptions, run_with};

/// The error of a run stopped by its `stop` flag ([`run_toml`]): not a result, left out of
/// the table by `pmsm-sim sweep`.
pub const INTERRUPTED: &str = "interrupted";

/// Metrics left out of a sweep's table: wall-clock figures, not deterministic.
pub const WALL_CLOCK: [&str; 2] = ["wall_time_s", "real_time_factor"];

/// One run's results: its flattened metrics (dotted name, value), or its error.
#[derive(Clone, Debug, PartialEq)]
pub struct Row {
    /// Position in the plan.
    pub index: usize,
    /// The varied values, as in [`RunSpec::values`].
    pub values: Vec<(String, toml::Value)>,
    /// The noise seed.
    pub seed: u64,
    /// The metrics, flattened (empty after an error).
    pub metrics: Vec<(String, Cell)>,
    /// Why the run failed, if it did.
    pub error: Option<String>,
}

/// Runs one scenario given as TOML text (a [`RunSpec::toml`]) and returns its flattened
/// metrics; errors (an invalid scenario, a refused configuration) as text. `stop`: the run
/// ends early when it is set, with the error [`INTERRUPTED`].
pub fn run_toml(
    toml_text: &str,
    origin: &str,
    stop: Option<&std::sync::atomic::AtomicBool>,
) -> Result<Vec<(String, Cell)>, String> {
    let sc = Scenario::from_toml_str(toml_text, origin).map_err(|e| e.to_string())?;
    let out = run_with(
        &sc,
        RunOptions {
            inline_observers: true,
            interrupt: stop,
            ..RunOptions::default()
        },
    )
    .map_err(|e| e.to_string())?;
    if matches!(out.end, crate::sim::RunEnd::Interrupted { .. }) {
        return Err(INTERRUPTED.to_string());
    }
    let json = serde_json::to_value(&out.metrics).map_err(|e| format!("metrics: {e}"))?;
    let mut cells = Vec::new();
    flatten("", &json, &mut cells);
    cells.retain(|(k, _)| !WALL_CLOCK.contains(&k.as_str()));
    Ok(cells)
}

/// Runs one planned run: its row, with the metrics or the error.
pub fn run_one(spec: &RunSpec, stop: Option<&std::sync::atomic::AtomicBool>) -> Row {
    let origin = format!("sweep run {}", spec.index);
    let (metrics, error) = match run_toml(&spec.toml, &origin, stop) {
        Ok(m) => (m, None),
        Err(e) => (Vec::new(), Some(e)),
    };
    Row {
        index: spec.index,
        values: spec.values.clone(),
        seed: spec.seed,
        metrics,
        error,
    }
}

/// Flattens JSON objects into dotted names; lists become their JSON text.
pub fn flatten(prefix: &str, v: &serde_json::Value, out: &mut Vec<(String, Cell)>) {
    use serde_json::Value as J;
    let name = |k: &str| {
        if prefix.is_empty() {
            k.to_string()
        } else {
            format!("{prefix}.{k}")
        }
    };
    match v {
        J::Object(map) => {
            for (k, x) in map {
                match x {
                    J::Object(_) => flatten(&name(k), x, out),
                    _ => out.push((name(k), Cell::of_json(x))),
                }
            }
        }
        _ => out.push((prefix.to_string(), Cell::of_json(v))),
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn a_run_flattens_its_metrics_and_reports_errors_and_stops() {
        let plan = Plan::new(
            &Scenario::default_servo(),
            &[("duration_s".into(), toml::Value::Float(0.3))],
            1,
            3,
        )
        .unwrap();
        let spec = &plan.runs().unwrap()[0];
        let row = run_one(spec, None);
        assert_eq!(row.error, None);
        let get = |k: &str| row.metrics.iter().find(|(n, _)| n == k).map(|(_, c)| c);
        assert_eq!(get("periods"), Some(&Cell::Int(3000)));
        assert_eq!(get("end"), Some(&Cell::Text("completed".into())));
        assert!(matches!(
            get("observer.angle_error_rms_deg"),
            Some(Cell::Float(_))
        ));
        assert_eq!(get("drive.fault"), Some(&Cell::Null));
        assert!(get("wall_time_s").is_none() && get("real_time_factor").is_none());
        // The same run again: the same row (deterministic).
        assert_eq!(run_one(spec, None), row);
        let stop = std::sync::atomic::AtomicBool::new(true);
        assert_eq!(
            run_one(spec, Some(&stop)).error.as_deref(),
            Some(INTERRUPTED)
        );
        let bad = run_toml("name = 1", "bad run", None).unwrap_err();
        assert!(bad.starts_with("bad run: "), "{bad}");
    }
}
