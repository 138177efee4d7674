//! `pmsm-sim sweep PLAN.toml --out DIR`: a sweep on the local cores (Rust threads), written
//! to `DIR/results.parquet` with the columns of `pyfoc.sweep` ([`super`]).
//!
//! The plan file:
//!
//! ```toml
//! scenario = "default"   # a preset name or a scenario file (relative to the plan's folder);
//!                        # or a [scenario] table holding a whole scenario
//! n = 100                # draws per grid point (default 1)
//! seed = 1               # the sweep's seed (default 0)
//!
//! [vary]                 # dotted scenario paths, as pyfoc.sweep's `vary`
//! "observer.rs_ohm" = ["relative", 0.15]
//! "inverter.dead_time_s" = ["uniform", 0.0, 2e-6]
//! "sensors.current_noise_std_a" = [0.01, 0.02, 0.06]
//! duration_s = 0.5       # a single value: a fixed setting
//! ```
//!
//! (Unquoted dotted keys under `[vary]` are nested tables in TOML; they are read back as the
//! same dotted paths.) Worker threads take the runs in index order, one at a time; a progress
//! bar on stderr counts them. On SIGINT, SIGTERM or SIGHUP the runs in flight stop, and the
//! rows finished so far are written; the interrupted runs are left out.

use std::path::{Path, PathBuf};
use std::sync::atomic::{AtomicBool, AtomicUsize, Ordering};
use std::time::Instant;

use crate::error::SimError;
use crate::scenario::Scenario;

use super::{INTERRUPTED, Plan, Row, run_one, table};

/// Arguments of `pmsm-sim sweep`.
#[derive(clap::Args, Debug)]
pub struct SweepArgs {
    /// The plan: a TOML file with `scenario`, `n`, `seed` and a `[vary]` table (docs/sweeps.md).
    pub plan: PathBuf,
    /// Output directory for results.parquet (default: out/<plan file name>/).
    #[arg(long)]
    pub out: Option<PathBuf>,
    /// Worker threads (default: the machine's cores).
    #[arg(long)]
    pub threads: Option<usize>,
}

/// What a sweep did.
#[derive(Debug)]
pub struct SweepReport {
    /// Runs in the plan.
    pub planned: usize,
    /// Rows written (finished runs).
    pub written: usize,
    /// Rows with an error.
    pub failed: usize,
    /// Whether a signal stopped the sweep.
    pub interrupted: bool,
    /// The parquet file.
    pub path: PathBuf,
    /// Wall time, s.
    pub wall_s: f64,
}

/// A plan file's contents.
#[derive(Clone, Debug)]
pub struct PlanFile {
    /// The base scenario.
    pub scenario: Scenario,
    /// The `[vary]` entries, as dotted paths.
    pub vary: Vec<(String, toml::Value)>,
    /// Draws per grid point.
    pub n: usize,
    /// The sweep's seed.
    pub seed: u64,
}

/// Reads a plan file; errors name the file and the key.
pub fn read_plan(path: &Path) -> Result<PlanFile, SimError> {
    let file = path.display().to_string();
    let err = |field: &str, problem: String| SimError::Scenario {
        file: file.clone(),
        field: field.to_string(),
        problem,
    };
    let text = std::fs::read_to_string(path).map_err(|source| SimError::Read {
        file: file.clone(),
        source,
    })?;
    let table: toml::Table =
        toml::from_str(&text).map_err(|e| err("-", e.message().to_string()))?;
    for key in table.keys() {
        if !["scenario", "n", "seed", "vary"].contains(&key.as_str()) {
            return Err(err(
                key,
                "unknown key (a plan has scenario, n, seed and [vary])".into(),
            ));
        }
    }
    let scenario = match table.get("scenario") {
        Some(toml::Value::String(s)) => {
            let file_path = path.parent().unwrap_or(Path::new(".")).join(s);
            if Scenario::preset_text(s).is_some() {
                Scenario::preset(s)?
            } else if file_path.is_file() {
                Scenario::from_file(&file_path)?
            } else {
                return Err(err(
                    "scenario",
                    format!("{s:?} is neither a preset nor a file next to the plan"),
                ));
            }
        }
        Some(toml::Value::Table(t)) => {
            let text = toml::to_string(t).map_err(|e| err("scenario", e.to_string()))?;
            Scenario::from_toml_str(&text, &format!("{file}: [scenario]"))?
        }
        Some(_) => {
            return Err(err(
                "scenario",
                "expected a preset name, a file name or a table".into(),
            ));
        }
        None => return Err(err("scenario", "missing".into())),
    };
    let whole = |key: &str, default: i64| -> Result<i64, SimError> {
        match table.get(key) {
            None => Ok(default),
            Some(toml::Value::Integer(i)) if *i >= 0 => Ok(*i),
            Some(v) => Err(err(key, format!("expected a whole number >= 0, got {v}"))),
        }
    };
    let n = usize::try_from(whole("n", 1)?).map_err(|e| err("n", e.to_string()))?;
    let seed = whole("seed", 0)? as u64;
    let mut vary = Vec::new();
    match table.get("vary") {
        None => {}
        Some(toml::Value::Table(t)) => flatten_vary("", t, &mut vary),
        Some(_) => return Err(err("vary", "expected a table of dotted paths".into())),
    }
    Ok(PlanFile {
        scenario,
        vary,
        n,
        seed,
    })
}

/// `[vary]`'s entries as dotted paths (nested tables are path segments).
fn flatten_vary(prefix: &str, t: &toml::Table, out: &mut Vec<(String, toml::Value)>) {
    for (k, v) in t {
        let path = if prefix.is_empty() {
            k.clone()
        } else {
            format!("{prefix}.{k}")
        };
        match v {
            toml::Value::Table(inner) => flatten_vary(&path, inner, out),
            _ => out.push((path, v.clone())),
        }
    }
}

/// Runs the sweep of `args`; `stop` (set by a signal) ends it early with the finished rows.
pub fn run(args: &SweepArgs, stop: &AtomicBool) -> Result<SweepReport, SimError> {
    let started = Instant::now();
    let plan_file = args.plan.display().to_string();
    let file = read_plan(&args.plan)?;
    let plan = Plan::new(&file.scenario, &file.vary, file.n, file.seed).map_err(|problem| {
        SimError::Scenario {
            file: plan_file.clone(),
            field: "vary".into(),
            problem,
        }
    })?;
    let runs = plan.runs()?;
    let dir = args.out.clone().unwrap_or_else(|| {
        let stem = args
            .plan
            .file_stem()
            .map_or("sweep".into(), |s| s.to_string_lossy().into_owned());
        Path::new("out").join(stem)
    });
    let out_err = |p: &Path, e: &dyn std::fmt::Display| SimError::Output {
        path: p.display().to_string(),
        message: e.to_string(),
    };
    std::fs::create_dir_all(&dir).map_err(|e| out_err(&dir, &e))?;
    let path = dir.join("results.parquet");
    let threads = args
        .threads
        .unwrap_or_else(|| std::thread::available_parallelism().map_or(1, |n| n.get()))
        .clamp(1, runs.len().max(1));

    let bar = indicatif::ProgressBar::new(runs.len() as u64);
    if let Ok(style) = indicatif::ProgressStyle::with_template(
        "{spinner} [{elapsed_precise}] {bar:40} {pos}/{len} runs, {per_sec}, eta {eta}",
    ) {
        bar.set_style(style);
    }
    let next = AtomicUsize::new(0);
    let (tx, rx) = std::sync::mpsc::channel::<Row>();
    let mut rows: Vec<Row> = Vec::with_capacity(runs.len());
    std::thread::scope(|s| {
        for _ in 0..threads {
            let tx = tx.clone();
            let (next, runs) = (&next, &runs);
            s.spawn(move || {
                while !stop.load(Ordering::Relaxed) {
                    let k = next.fetch_add(1, Ordering::Relaxed);
                    let Some(spec) = runs.get(k) else { break };
                    if tx.send(run_one(spec, Some(stop))).is_err() {
                        break;
                    }
                }
            });
        }
        drop(tx);
        for row in rx {
            bar.inc(1);
            if row.error.as_deref() != Some(INTERRUPTED) {
                rows.push(row);
            }
        }
    });
    bar.finish_and_clear();
    let interrupted = stop.load(Ordering::Relaxed) && rows.len() < runs.len();
    let columns = table::columns(&plan.paths(), &rows);
    super::parquet_out::write(&path, &columns).map_err(|message| SimError::Output {
        path: path.display().to_string(),
        message,
    })?;
    Ok(SweepReport {
        planned: runs.len(),
        written: rows.len(),
        failed: rows.iter().filter(|r| r.error.is_some()).count(),
        interrupted,
        path,
        wall_s: started.elapsed().as_secs_f64(),
    })
}
