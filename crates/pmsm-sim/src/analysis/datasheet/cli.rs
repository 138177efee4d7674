//! `pmsm-sim datasheet [--motor NAME] [--quick] --out DIR`: builds the datasheet and writes
//! `DIR/datasheet.html` (self-contained), `DIR/datasheet.md` with its figures
//! (`DIR/fig*.svg`), `DIR/datasheet.json` (every number) and `DIR/montecarlo-plan.toml` (the
//! plan of section 6, for `pmsm-sim sweep`).

use std::path::{Path, PathBuf};
use std::time::Instant;

use crate::SimError;
use crate::analysis::suite::SuiteMotor;
use crate::output::file::write_bytes;

use super::{DatasheetOptions, build, render};

/// A `--motor` name (the reference motors of `pmsm-sim suite`).
pub fn parse_motor(name: &str) -> Result<SuiteMotor, String> {
    SuiteMotor::from_name(name).ok_or_else(|| {
        let known: Vec<_> = SuiteMotor::ALL.iter().map(|m| m.name()).collect();
        format!("unknown motor `{name}` (known: {})", known.join(", "))
    })
}

/// Arguments of `pmsm-sim datasheet`.
#[derive(clap::Args, Debug)]
pub struct DatasheetArgs {
    /// The motor: servo (the default scenario's), industrial_2k2, small_fast, industrial_ipm,
    /// traction_ipm; its simulator preset's drive.
    #[arg(long, value_parser = parse_motor, default_value = "servo")]
    pub motor: SuiteMotor,
    /// Small n and short windows (well under a minute): the same methods, a first look.
    #[arg(long)]
    pub quick: bool,
    /// Seed of every random draw (the datasheet is the same for a seed).
    #[arg(long, default_value_t = 1)]
    pub seed: u64,
    /// Worker threads (default: the machine's cores).
    #[arg(long)]
    pub threads: Option<usize>,
    /// The QEMU instruction counts written by scripts/qemu-firmware.sh (default:
    /// $CARGO_TARGET_DIR/m4f-counts.json or target/m4f-counts.json, when present).
    #[arg(long)]
    pub m4f_counts: Option<PathBuf>,
    /// Output directory.
    #[arg(long, default_value = "out/datasheet")]
    pub out: PathBuf,
}

/// What was written.
#[derive(Debug)]
pub struct Written {
    /// The files, in order.
    pub files: Vec<PathBuf>,
    /// Wall time, s.
    pub wall_s: f64,
}

fn out_err(p: &Path, e: impl std::fmt::Display) -> SimError {
    SimError::Output {
        path: p.display().to_string(),
        message: e.to_string(),
    }
}

/// Builds and writes the datasheet of `args`; `progress` gets each section's title.
pub fn run(args: &DatasheetArgs, progress: &mut dyn FnMut(&str)) -> Result<Written, SimError> {
    let started = Instant::now();
    let threads = args
        .threads
        .unwrap_or_else(|| std::thread::available_parallelism().map_or(1, |n| n.get()));
    if threads == 0 {
        return Err(SimError::Scenario {
            file: "pmsm-sim datasheet".into(),
            field: "--threads".into(),
            problem: "must be at least 1".into(),
        });
    }
    let opts = DatasheetOptions {
        motor: args.motor,
        quick: args.quick,
        seed: args.seed,
        threads,
        m4f_counts: args.m4f_counts.clone(),
    };
    let dir = &args.out;
    std::fs::create_dir_all(dir).map_err(|e| out_err(dir, e))?;
    let d = build(&opts, progress)?;
    let r = render::render(&d).map_err(|e| out_err(dir, e))?;
    let mut files = Vec::new();
    let mut put = |name: &str, bytes: &[u8]| -> Result<(), SimError> {
        let p = dir.join(name);
        write_bytes(&p, bytes)?;
        files.push(p);
        Ok(())
    };
    for (name, svg) in &r.figures {
        put(name, svg.as_bytes())?;
    }
    put("datasheet.md", r.markdown.as_bytes())?;
    put("datasheet.html", r.html.as_bytes())?;
    let json = serde_json::to_string_pretty(&d).map_err(|e| out_err(dir, e))?;
    put("datasheet.json", format!("{json}\n").as_bytes())?;
    let plan = format!(
        "# The Monte-Carlo plan of the datasheet's section 6: pmsm-sim sweep THIS --out DIR\nscenario = \"{}\"\nn = {}\nseed = {}\n\n[vary]\n{}\n",
        d.monte_carlo.preset,
        d.monte_carlo.runs.len(),
        d.monte_carlo.seed,
        d.monte_carlo.plan_toml
    );
    put("montecarlo-plan.toml", plan.as_bytes())?;
    Ok(Written {
        files,
        wall_s: started.elapsed().as_secs_f64(),
    })
}
