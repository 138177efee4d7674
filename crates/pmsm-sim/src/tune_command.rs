//! `pmsm-sim tune`: its arguments, the report (text or JSON) and, on a terminal, the
//! search's progress.

use std::io::IsTerminal;
use std::sync::atomic::{AtomicBool, Ordering};
use std::time::Duration;

use clap::Args;
use indicatif::{ProgressBar, ProgressStyle};
use pmsm_sim::analysis::tune::{LoggedRun, RShape, TuneError, TuneOptions, tune_logged_run};

/// Arguments of `pmsm-sim tune` (the command line's subcommand).
#[derive(Args, Debug, Clone)]
pub(crate) struct TuneArgs {
    /// MCAP log written by `pmsm-sim run` (protobuf or JSON period channel).
    file: std::path::PathBuf,
    /// Convergence window not scored, s (default: min(20 % of the run, 0.1 s)).
    #[arg(long)]
    skip_s: Option<f64>,
    /// Fit one sigma for R (isotropic) instead of alpha, beta and their correlation.
    #[arg(long)]
    isotropic: bool,
    /// Filter runs the search may use.
    #[arg(long, default_value_t = 5000)]
    max_evals: usize,
    /// Print the report as JSON on stdout.
    #[arg(long)]
    json: bool,
}

impl TuneArgs {
    /// Runs the subcommand: the report on stdout, errors on stderr; on a terminal, the
    /// search's progress (filter runs so far, of `--max-evals`) on stderr, updated in place.
    pub(crate) fn run(&self) -> std::process::ExitCode {
        let result = if std::io::stderr().is_terminal() {
            self.report_with_progress()
        } else {
            self.report()
        };
        match result {
            Ok(text) => {
                print!("{text}");
                std::process::ExitCode::SUCCESS
            }
            Err(e) => {
                eprintln!("pmsm-sim: error: {e}");
                std::process::ExitCode::FAILURE
            }
        }
    }

    /// [`Self::report`] with a counter of the filter runs on stderr
    /// (`pmsm_sim::analysis::tune::FILTER_PASSES`, polled every 100 ms), cleared at the end.
    fn report_with_progress(&self) -> Result<String, TuneError> {
        use pmsm_sim::analysis::tune::FILTER_PASSES;
        let done = AtomicBool::new(false);
        let start = FILTER_PASSES.load(Ordering::Relaxed);
        std::thread::scope(|s| {
            s.spawn(|| {
                let bar = ProgressBar::new(self.max_evals as u64);
                if let Ok(style) = ProgressStyle::with_template(
                    "tune: [{elapsed_precise}] {pos}/{len} filter runs (at most)",
                ) {
                    bar.set_style(style);
                }
                while !done.load(Ordering::Relaxed) {
                    let n = FILTER_PASSES.load(Ordering::Relaxed) - start;
                    bar.set_position(n as u64);
                    std::thread::sleep(Duration::from_millis(100));
                }
                bar.finish_and_clear();
            });
            let r = self.report();
            done.store(true, Ordering::Relaxed);
            r
        })
    }

    fn report(&self) -> Result<String, TuneError> {
        let run = LoggedRun::read(&self.file)?;
        let skip = match self.skip_s {
            None => None,
            Some(t) if t.is_finite() && t >= 0.0 => {
                Some((t / run.scenario.ts_s()).round() as usize)
            }
            Some(t) => {
                return Err(TuneError::Option {
                    name: "--skip-s",
                    problem: format!("must be finite and >= 0, got {t}"),
                });
            }
        };
        let opts = TuneOptions {
            skip,
            r_shape: if self.isotropic {
                RShape::Isotropic
            } else {
                RShape::Full
            },
            max_evaluations: self.max_evals,
            ..TuneOptions::default()
        };
        let rep = tune_logged_run(&run, &opts)?;
        if self.json {
            serde_json::to_string_pretty(&rep)
                .map(|j| format!("{j}\n"))
                .map_err(|e| TuneError::Option {
                    name: "--json",
                    problem: e.to_string(),
                })
        } else {
            Ok(rep.render(&self.file.display().to_string()))
        }
    }
}
