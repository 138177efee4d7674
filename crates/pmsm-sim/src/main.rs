//! `pmsm-sim`: runs the built-in default scenario and prints the observer's metrics.

use std::process::ExitCode;

use clap::Parser;
use pmsm_sim::{metrics::RunMetrics, report, scenario::Scenario, sim};

/// Runs the built-in default scenario (servo motor, 10 kHz: ramp to 2000 rpm, rated load step,
/// reversal to -1000 rpm) and prints the observer metrics.
#[derive(Parser, Debug)]
#[command(version, about)]
struct Args {
    /// Print the metrics as JSON instead of a table.
    #[arg(long)]
    json: bool,
    /// Seed of the current-sensor noise (default: the scenario's).
    #[arg(long)]
    seed: Option<u64>,
}

fn main() -> ExitCode {
    let args = Args::parse();
    let mut scenario = Scenario::default_servo();
    if let Some(seed) = args.seed {
        scenario.sensor.seed = seed;
    }
    let run = match sim::run(&scenario) {
        Ok(r) => r,
        Err(e) => {
            eprintln!("pmsm-sim: {e}");
            return ExitCode::FAILURE;
        }
    };
    let metrics = RunMetrics::compute(&scenario, &run);
    if args.json {
        match report::json(&metrics) {
            Ok(s) => println!("{s}"),
            Err(e) => {
                eprintln!("pmsm-sim: cannot write JSON: {e}");
                return ExitCode::FAILURE;
            }
        }
    } else {
        print!("{}", report::table(&metrics));
    }
    ExitCode::SUCCESS
}
