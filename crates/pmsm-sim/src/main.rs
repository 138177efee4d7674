//! `pmsm-sim`: the simulator's command line (the crate README documents it).

#![forbid(unsafe_code)]

mod bench;
mod motor_command;
mod table_commands;
mod tune_command;

use table_commands::{
    faults_command, identify_command, low_speed_command, parse_suite_motor, suite,
};
use tune_command::TuneArgs;

use std::io::IsTerminal;
use std::path::{Path, PathBuf};
use std::process::ExitCode;
use std::sync::Arc;
use std::sync::atomic::{AtomicBool, Ordering};
use std::time::{Duration, Instant};

use clap::{Args, Parser, Subcommand, ValueEnum};
use indicatif::{ProgressBar, ProgressStyle};
use pmsm_sim::SimError;
use pmsm_sim::analysis::plug_map;
use pmsm_sim::analysis::suite::{SuiteMotor, SuiteOptions};
use pmsm_sim::analysis::sweep::period_table::PeriodTable;
use pmsm_sim::output::file::write_bytes;
use pmsm_sim::output::mcap::{LogCompression, LogEncoding, LogOptions, LogTime, McapLog};
use pmsm_sim::output::plot::PlotSink;
use pmsm_sim::output::report;
use pmsm_sim::output::startup_log::StartupLog;
use pmsm_sim::scenario::{PRESETS, Scenario};
use pmsm_sim::sim::{self, RunEnd, RunOptions, SampleSink};

/// Desktop simulator of a sensorless PMSM drive: plant, inverter, sensors, controller and the
/// EKF observer, with MCAP logs, an SVG plot and the observer's metrics.
///
/// With no subcommand it runs the built-in default scenario (servo motor, 10 kHz: standstill
/// -> 2000 rpm, rated load step, reversal) and writes its outputs under out/default/.
#[derive(Parser, Debug)]
#[command(version, about, long_about = None, args_conflicts_with_subcommands = true)]
struct Cli {
    #[command(subcommand)]
    command: Option<Command>,
    #[command(flatten)]
    run: RunArgs,
}

#[derive(Subcommand, Debug)]
enum Command {
    /// Run a scenario: a TOML file or a built-in preset name (default: "default").
    Run {
        /// Scenario file (`*.toml`) or preset name (see `pmsm-sim list`).
        scenario: Option<String>,
        #[command(flatten)]
        args: RunArgs,
    },
    /// List the built-in scenarios.
    List,
    /// Print a built-in scenario's TOML (a starting point for your own file).
    Show {
        /// Preset name (default: "default").
        preset: Option<String>,
    },
    /// Print a `[motor]` table from datasheet values (line-to-line R and L; Kv or Kt), for a
    /// scenario file (docs/first-motor.md).
    Motor(motor_command::MotorArgs),
    /// Check a scenario file without running it.
    Check {
        /// Scenario file or preset name.
        scenario: String,
    },
    /// Measure the real-time factor (medians over several runs), with and without logging,
    /// and the cost of each part of a period.
    Bench {
        /// Scenario file or preset name (default: "default").
        scenario: Option<String>,
        /// Runs per configuration.
        #[arg(long, default_value_t = 7)]
        runs: usize,
        /// Directory for the benchmark's MCAP file.
        #[arg(long, default_value = "out/bench")]
        out: PathBuf,
    },
    /// Run the scenario suite: the reference motors (three surface, two interior) at
    /// 10/50/100 % rated speed, a rated load step and an unknown start; tables for the seed's
    /// filter, the flux + PLL baseline and the default EKF (printed, and written as suite.md
    /// and suite.json).
    Suite {
        /// Only this motor (repeatable; a repeat runs once): servo, industrial_2k2,
        /// small_fast, industrial_ipm, traction_ipm. Default: all.
        #[arg(long = "motor", value_parser = parse_suite_motor)]
        motors: Vec<SuiteMotor>,
        /// Shortened windows (about half the simulated time).
        #[arg(long)]
        short: bool,
        /// Seed of the sensor noise.
        #[arg(long, default_value_t = 1)]
        seed: u64,
        /// Ideal sensing and inverter (no noise, ADC, offsets, gain errors, dead time).
        #[arg(long)]
        ideal: bool,
        /// Output directory.
        #[arg(long, default_value = "out/suite")]
        out: PathBuf,
    },
    /// Low-speed table: for each reference motor the lowest speed (of 10, 7, 5, 3, 2, 1.5, 1, 0.7, 0.5 %
    /// of rated) at which foc sensorless runs closed loop under rated load for 10 s without a
    /// fall-back, with its RMS current per rated-torque current (printed, and written as
    /// lowspeed.md and lowspeed.json).
    LowSpeed {
        /// Only this motor (repeatable; a repeat runs once): servo, industrial_2k2,
        /// small_fast, industrial_ipm, traction_ipm. Default: the three surface motors.
        #[arg(long = "motor", value_parser = parse_suite_motor)]
        motors: Vec<SuiteMotor>,
        /// Time held at each speed, s.
        #[arg(long, default_value_t = pmsm_sim::analysis::low_speed::HOLD_S)]
        hold: f64,
        /// Output directory.
        #[arg(long, default_value = "out/lowspeed")]
        out: PathBuf,
    },
    /// Run the fault suite: every injected fault kind in closed loop with the foc sensorless
    /// controller; prints a markdown table and writes it to <out>/faults.md.
    Faults {
        /// Output directory.
        #[arg(long, default_value = "out/faults")]
        out: PathBuf,
        /// Start of every fault, s.
        #[arg(long, default_value_t = 1.2)]
        t_fault: f64,
        /// End of every run, s.
        #[arg(long, default_value_t = 2.0)]
        t_end: f64,
    },
    /// Self-commissioning: identify the scenario's motor (Rs, Ld, Lq, psi_f, J, inverter
    /// voltage error) from standstill and a short spin; true vs identified table, MCAP log
    /// and SVG plot in <out> (default out/<scenario name>/).
    Identify {
        /// Scenario file or preset name (default: "default").
        scenario: Option<String>,
        /// Print one JSON object on stdout (paths go to stderr).
        #[arg(long)]
        json: bool,
        /// Override the scenario's random seed.
        #[arg(long)]
        seed: Option<u64>,
        /// Output directory.
        #[arg(long)]
        out: Option<PathBuf>,
        /// Time stamps of the MCAP log: wall (the run's wall-clock start time plus the
        /// simulated time) or zero (the simulated time alone, from 1970-01-01: the same time
        /// stamps for identical runs).
        #[arg(long, value_enum, default_value_t = LogTimeArg::Wall)]
        log_time: LogTimeArg,
        /// After the sequence, measure the flux map at standstill (coast with a small square
        /// wave of d current for psi_d(0, 0), stop, re-align, probe a 7 x 9 grid of i_d, i_q): table (markdown, and in the
        /// JSON), error against the plant's flux, identify-flux-map.{md,svg} in <out>.
        #[arg(long)]
        flux_map: bool,
        /// Largest current of the flux map's grid, A (default 0.85 x the current limit).
        #[arg(long, requires = "flux_map")]
        flux_map_current: Option<f64>,
    },
    /// Propose the observer's Q and R from a run's MCAP log (innovation likelihood), with the
    /// NIS and angle error of the default and the tuned filter.
    Tune(TuneArgs),
    /// Turn a telemetry capture of the B-G431B-ESC1 firmware (its UART bytes) into an MCAP
    /// log of the period record.
    Telemetry {
        /// The capture (raw UART bytes: frames and command replies).
        capture: PathBuf,
        /// The MCAP log to write.
        #[arg(long, default_value = "out/telemetry.mcap")]
        out: PathBuf,
        /// PWM period, s, for a capture without the board's meta frame.
        #[arg(long)]
        ts_s: Option<f64>,
        /// Time stamps of the MCAP log: wall (the run's wall-clock start time plus the
        /// simulated time) or zero (the simulated time alone, from 1970-01-01: the same time
        /// stamps for identical runs).
        #[arg(long, value_enum, default_value_t = LogTimeArg::Wall)]
        log_time: LogTimeArg,
    },
    /// Run a sweep plan (a scenario with keys varied: grids, Monte-Carlo draws) on the local
    /// cores; writes <out>/results.parquet, a row per run (docs/sweeps.md).
    Sweep(pmsm_sim::analysis::sweep::cli::SweepArgs),
    /// One motor's datasheet: angle error, low-speed limit, start-up, HFI polarity,
    /// identification, lock loss under parameter error, M4F instructions; every figure from a
    /// sweep run here (<out>/datasheet.html, datasheet.md; docs/datasheet.md).
    Datasheet(pmsm_sim::analysis::datasheet::cli::DatasheetArgs),
    /// Replay a recorded drive (CSV in the documented format, or a pmsm-sim MCAP log)
    /// through the default EKF, the drive observer and the flux + PLL baseline; prints the
    /// score table and writes metrics.json, replay.mcap and plot.svg to <out>.
    Replay {
        /// The log: CSV (header t_s, dt_s, u_alpha_v, u_beta_v, i_alpha_a, i_beta_a, optional
        /// theta_ref_rad, omega_ref_rad_s) or a pmsm-sim MCAP log.
        log: PathBuf,
        /// Motor TOML (rs_ohm, ld_h and lq_h or ls_h, psi_f_wb, pole_pairs, ts_s).
        #[arg(long)]
        motor: PathBuf,
        /// Output directory.
        #[arg(long, default_value = "out/replay")]
        out: PathBuf,
        /// Clarke scaling of the CSV log's voltages and currents.
        #[arg(long, value_enum, default_value_t = ScalingArg::Amplitude)]
        scaling: ScalingArg,
        /// Time stamps of replay.mcap: wall (the replay's wall-clock start time plus the
        /// log's time) or zero (the log's time alone, from 1970-01-01).
        #[arg(long, value_enum, default_value_t = LogTimeArg::Wall)]
        log_time: LogTimeArg,
    },
}

#[derive(Clone, Copy, Debug, ValueEnum)]
enum ScalingArg {
    /// Amplitude-invariant Clarke transform (the project's).
    Amplitude,
    /// Power-invariant (values sqrt(3/2) times the amplitude-invariant ones).
    Power,
}

#[derive(Args, Debug, Clone)]
struct RunArgs {
    /// Output directory (default: out/<scenario name>/, relative to the current directory).
    #[arg(long)]
    out: Option<PathBuf>,
    /// Do not write the MCAP log (refused together with --log-compression, --log-encoding
    /// or --log-time).
    #[arg(long, conflicts_with_all = ["log_compression", "log_encoding", "log_time"])]
    no_log: bool,
    /// Do not draw the plot.
    #[arg(long)]
    no_plot: bool,
    /// Print the metrics as JSON on stdout (paths go to stderr).
    #[arg(long)]
    json: bool,
    /// Override the scenario's random seed.
    #[arg(long)]
    seed: Option<u64>,
    /// Override the scenario's duration, s.
    #[arg(long)]
    duration: Option<f64>,
    /// Plug and spin: identify the motor first, then run sensorless (foc) with the
    /// identified parameters only (the true ones stay in the plant).
    #[arg(long)]
    identify: bool,
    /// With --identify: also measure the flux map at standstill, then run foc on it (MTPA,
    /// gains) with its angle from the EKF on the map; the run told the plant's true map is
    /// compared after it (docs/identify.md).
    #[arg(long, requires = "identify")]
    flux_map: bool,
    /// Largest current of the flux map's grid, A (default 0.85 x the current limit).
    #[arg(long, requires = "flux_map")]
    flux_map_current: Option<f64>,
    /// Do not run the reference filter alongside.
    #[arg(long, alias = "no-seed-filter")]
    no_reference_filter: bool,
    /// Chunk compression of the MCAP log (none: fastest; zstd: smallest).
    #[arg(long, value_enum, default_value_t = Compress::None)]
    log_compression: Compress,
    /// Encoding of the per-period messages of the MCAP log (protobuf: fast; json: text).
    #[arg(long, value_enum, default_value_t = Encoding::Protobuf)]
    log_encoding: Encoding,
    /// Time stamps of the MCAP log: wall (the run's wall-clock start time plus the simulated
    /// time) or zero (the simulated time alone, from 1970-01-01: the same time stamps for
    /// identical runs).
    #[arg(long, value_enum, default_value_t = LogTimeArg::Wall)]
    log_time: LogTimeArg,
    /// Also write the per-period table as <out>/periods.csv (docs/foxglove.md).
    #[arg(long)]
    csv: bool,
    /// Also write the per-period table as <out>/periods.parquet.
    #[arg(long)]
    parquet: bool,
}

#[derive(Clone, Copy, Debug, ValueEnum)]
enum Compress {
    None,
    Lz4,
    Zstd,
}

#[derive(Clone, Copy, Debug, ValueEnum)]
enum Encoding {
    Protobuf,
    Json,
}

/// `--log-time`: the origin of the MCAP log's time stamps ([`LogTime`]).
#[derive(Clone, Copy, Debug, ValueEnum)]
enum LogTimeArg {
    /// The wall-clock time at the start of the run plus the simulated time.
    Wall,
    /// The simulated time alone (from 1970-01-01).
    Zero,
}

impl LogTimeArg {
    /// The log options with this time origin, read from the clock now.
    fn options(self) -> LogOptions {
        let t = match self {
            LogTimeArg::Wall => LogTime::Wall,
            LogTimeArg::Zero => LogTime::Zero,
        };
        LogOptions {
            start_time_unix_ns: t.start_time_unix_ns(),
            ..LogOptions::default()
        }
    }
}

impl From<Encoding> for LogEncoding {
    fn from(e: Encoding) -> Self {
        match e {
            Encoding::Protobuf => LogEncoding::Protobuf,
            Encoding::Json => LogEncoding::Json,
        }
    }
}

impl From<Compress> for LogCompression {
    fn from(c: Compress) -> Self {
        match c {
            Compress::Zstd => LogCompression::Zstd,
            Compress::Lz4 => LogCompression::Lz4,
            Compress::None => LogCompression::None,
        }
    }
}

/// The signals that stop a run (`signal_hook::flag::register`): each sets the run loop's
/// stop flag, checked every period, and a flag of its own, so that the exit code can follow
/// the shell's convention of 128 + the signal's number (SIGINT 130, SIGTERM 143, SIGHUP 129).
struct StopSignals {
    /// Set by any of them: the run stops at the next period and finishes its files.
    stop: Arc<AtomicBool>,
    /// `(exit code, name, flag)` of each signal.
    each: Vec<(u8, &'static str, Arc<AtomicBool>)>,
}

impl StopSignals {
    /// Registers the handlers; a signal that cannot be registered keeps its default action.
    fn register() -> Self {
        use signal_hook::consts::{SIGINT, SIGTERM};
        use signal_hook::flag::register;
        let stop = Arc::new(AtomicBool::new(false));
        let mut wanted: Vec<(i32, u8, &'static str)> =
            vec![(SIGINT, 130, "SIGINT"), (SIGTERM, 143, "SIGTERM")];
        #[cfg(unix)]
        wanted.push((signal_hook::consts::SIGHUP, 129, "SIGHUP"));
        let mut each = Vec::new();
        for (sig, code, name) in wanted {
            let own = Arc::new(AtomicBool::new(false));
            if register(sig, Arc::clone(&stop)).is_ok() && register(sig, Arc::clone(&own)).is_ok() {
                each.push((code, name, own));
            }
        }
        Self { stop, each }
    }

    /// The exit code and name of the first signal that came, if any did.
    fn received(&self) -> Option<(u8, &'static str)> {
        self.each
            .iter()
            .find(|(_, _, f)| f.load(Ordering::Relaxed))
            .map(|(code, name, _)| (*code, *name))
    }
}

fn main() -> ExitCode {
    let cli = Cli::parse();
    let result = match cli.command {
        None => run_command(None, &cli.run),
        Some(Command::Run { scenario, args }) => run_command(scenario.as_deref(), &args),
        Some(Command::Motor(a)) => match motor_command::motor_block(&a) {
            Ok(block) => {
                print!("{block}");
                Ok(ExitCode::SUCCESS)
            }
            Err(e) => {
                eprintln!("pmsm-sim: error: {e}");
                Ok(ExitCode::from(1))
            }
        },
        Some(Command::List) => {
            list();
            Ok(ExitCode::SUCCESS)
        }
        Some(Command::Show { preset }) => show(preset.as_deref().unwrap_or("default")),
        Some(Command::Check { scenario }) => load(&scenario).map(|s| {
            println!("{}: ok ({} periods)", s.name, s.periods());
            warn_infeasible(&s);
            ExitCode::SUCCESS
        }),
        Some(Command::Bench {
            scenario,
            runs,
            out,
        }) => bench::bench(scenario.as_deref(), runs, &out),
        Some(Command::Suite {
            motors,
            short,
            seed,
            ideal,
            out,
        }) => suite(SuiteOptions { short, seed, ideal }, &motors, &out),
        Some(Command::LowSpeed { motors, hold, out }) => low_speed_command(&motors, hold, &out),
        Some(Command::Faults {
            out,
            t_fault,
            t_end,
        }) => faults_command(&out, t_fault, t_end),
        Some(Command::Identify {
            scenario,
            json,
            seed,
            out,
            log_time,
            flux_map,
            flux_map_current,
        }) => identify_command(
            scenario.as_deref(),
            json,
            seed,
            out,
            log_time.options(),
            flux_map.then_some(flux_map_current),
        ),
        Some(Command::Tune(args)) => Ok(args.run()),
        Some(Command::Sweep(args)) => sweep_command(&args),
        Some(Command::Datasheet(args)) => {
            pmsm_sim::analysis::datasheet::cli::run(&args, &mut |s| eprintln!("datasheet: {s}"))
                .map(|w| {
                    w.files.iter().for_each(|f| println!("{}", f.display()));
                    eprintln!("datasheet: written in {:.1} s", w.wall_s);
                    ExitCode::SUCCESS
                })
        }
        Some(Command::Replay {
            log,
            motor,
            out,
            scaling,
            log_time,
        }) => Ok(replay_command(
            &log,
            &motor,
            &out,
            scaling,
            log_time.options(),
        )),
        Some(Command::Telemetry {
            capture,
            out,
            ts_s,
            log_time,
        }) => pmsm_sim::board_telemetry::convert_file(&capture, &out, ts_s, log_time.options())
            .map(|s| {
                println!("{s} -> {}", out.display());
                ExitCode::SUCCESS
            }),
    };
    match result {
        Ok(code) => code,
        Err(e) => {
            eprintln!("pmsm-sim: error: {e}");
            ExitCode::FAILURE
        }
    }
}

/// `pmsm-sim sweep`: the plan on the local cores; a signal keeps the finished rows and exits
/// with 128 + its number.
fn sweep_command(args: &pmsm_sim::analysis::sweep::cli::SweepArgs) -> Result<ExitCode, SimError> {
    let signals = StopSignals::register();
    let r = pmsm_sim::analysis::sweep::cli::run(args, &signals.stop)?;
    eprintln!(
        "{} of {} runs in {:.1} s ({} failed) -> {}",
        r.written,
        r.planned,
        r.wall_s,
        r.failed,
        r.path.display()
    );
    Ok(match signals.received() {
        Some((code, name)) if r.interrupted => {
            eprintln!("pmsm-sim: {name}: stopped; the finished runs are written");
            ExitCode::from(code)
        }
        _ => ExitCode::SUCCESS,
    })
}

/// A scenario from a file path (anything ending in `.toml` or containing a path separator)
/// or a preset name.
fn load(what: &str) -> Result<Scenario, SimError> {
    let path = Path::new(what);
    if what.ends_with(".toml") || what.contains(std::path::MAIN_SEPARATOR) || path.is_file() {
        Scenario::from_file(path)
    } else {
        Scenario::preset(what)
    }
}

/// Prints the scenario's feasibility warnings (module `scenario::feasibility`) on stderr.
fn warn_infeasible(sc: &Scenario) {
    for w in pmsm_sim::scenario::feasibility::check(sc).warnings {
        eprintln!("pmsm-sim: warning: {}: {}", sc.name, w.message);
    }
}

/// `pmsm-sim list`: one preset a line, the name column as wide as the longest name.
fn list() {
    println!("built-in scenarios (pmsm-sim run NAME; pmsm-sim show NAME prints the TOML):");
    let width = PRESETS.iter().map(|(n, _)| n.len()).max().unwrap_or(0);
    for (name, _) in PRESETS {
        match Scenario::preset(name) {
            Ok(s) => println!(
                "  {name:<width$}  {:>6.2} s  {}",
                s.duration_s, s.description
            ),
            Err(e) => println!("  {name:<width$}  (invalid: {e})"),
        }
    }
}

fn show(name: &str) -> Result<ExitCode, SimError> {
    match Scenario::preset_text(name) {
        Some(t) => {
            print!("{t}");
            Ok(ExitCode::SUCCESS)
        }
        None => Scenario::preset(name).map(|_| ExitCode::SUCCESS),
    }
}

/// A directory name from a scenario name: letters, digits, `-`, `_`, `.` kept, others `_`.
fn dir_name(name: &str) -> String {
    let s: String = name
        .chars()
        .map(|c| {
            if c.is_ascii_alphanumeric() || matches!(c, '-' | '_' | '.') {
                c
            } else {
                '_'
            }
        })
        .collect();
    if s.is_empty() || s.chars().all(|c| c == '.') {
        "scenario".into()
    } else {
        s
    }
}

fn out_err(path: &Path, e: impl std::fmt::Display) -> SimError {
    SimError::Output {
        path: path.display().to_string(),
        message: e.to_string(),
    }
}

/// `pmsm-sim identify`: exit 0 when identified, 1 when the sequence stopped with an error.
fn run_command(what: Option<&str>, args: &RunArgs) -> Result<ExitCode, SimError> {
    let mut scenario = load(what.unwrap_or("default"))?;
    if let Some(seed) = args.seed {
        scenario.seed = seed;
    }
    if let Some(d) = args.duration {
        scenario.duration_s = d;
    }
    if args.no_reference_filter {
        scenario.observer.reference_filter = false;
    }
    let (original, mut map) = (scenario.clone(), None);
    if args.identify {
        let p = plug_map::plug(&scenario, args.flux_map.then_some(args.flux_map_current))?;
        eprint!("{}", p.text);
        (scenario, map) = (p.scenario, p.map);
    }
    scenario.validate().map_err(|e| SimError::Scenario {
        file: what.unwrap_or("preset default").to_string(),
        field: e.field,
        problem: e.problem,
    })?;
    warn_infeasible(&scenario);

    let dir = args
        .out
        .clone()
        .unwrap_or_else(|| Path::new("out").join(dir_name(&scenario.name)));
    std::fs::create_dir_all(&dir).map_err(|e| out_err(&dir, e))?;
    let mcap_path = dir.join("run.mcap");
    let plot_path = dir.join("plot.svg");
    let metrics_path = dir.join("metrics.json");

    // SIGINT (Ctrl-C), SIGTERM and SIGHUP set the stop flag; the run stops at the next
    // period and the files are finished.
    let signals = StopSignals::register();

    let mut log = if args.no_log {
        None
    } else {
        Some(McapLog::create(
            &mcap_path,
            &scenario,
            LogOptions {
                compression: args.log_compression.into(),
                encoding: args.log_encoding.into(),
                ..args.log_time.options()
            },
        )?)
    };
    let mut plot =
        (!args.no_plot).then(|| PlotSink::new(scenario.periods(), scenario.motor.pole_pairs));

    let bar_wanted = std::io::stdout().is_terminal() && std::io::stderr().is_terminal();
    let started = Instant::now();
    let mut bar: Option<ProgressBar> = None;
    let mut progress = |done: usize, all: usize| {
        if !bar_wanted {
            return;
        }
        if bar.is_none() && started.elapsed() > Duration::from_secs(1) && done < all {
            let b = ProgressBar::new(all as u64);
            if let Ok(style) = ProgressStyle::with_template(
                "{spinner} [{elapsed_precise}] {bar:40} {percent:>3}% {pos}/{len} periods, eta {eta}",
            ) {
                b.set_style(style);
            }
            bar = Some(b);
        }
        if let Some(b) = &bar {
            b.set_position(done as u64);
            if done >= all {
                b.finish_and_clear();
            }
        }
    };

    // The observers' thread only where each busy thread has a core (`sim::pipeline_pays`).
    let inline_observers = !sim::pipeline_pays(log.is_some());
    // The state changes in words, printed on stderr after the run.
    let mut startup_log = StartupLog::new(&scenario);
    let mut sinks: Vec<&mut dyn SampleSink> = vec![&mut startup_log];
    if let Some(l) = log.as_mut() {
        sinks.push(l);
    }
    if let Some(p) = plot.as_mut() {
        sinks.push(p);
    }
    let mut tables = [(args.csv, false), (args.parquet, true)]
        .into_iter()
        .filter(|(wanted, _)| *wanted)
        .map(|(_, parquet)| PeriodTable::create(&dir, parquet))
        .collect::<Result<Vec<_>, _>>()?;
    sinks.extend(tables.iter_mut().map(|t| t as &mut dyn SampleSink));
    let opts = RunOptions {
        record_trace: false,
        sinks,
        interrupt: Some(&signals.stop),
        progress: Some(&mut progress),
        inline_observers,
        ..RunOptions::default()
    };
    let out = match &map {
        Some((m, rs)) => plug_map::run_with_map(&scenario, m, *rs, opts)?,
        None => sim::run_with(&scenario, opts)?,
    };
    if let Some(b) = &bar {
        b.finish_and_clear();
    }
    eprint!("{}", startup_log.summary());
    if let Some((m, rs)) = &map {
        eprint!("{}", plug_map::compared(&original, &scenario, m, *rs)?);
    }
    let metrics = &out.metrics;

    let mut written = Vec::new();
    for t in tables {
        written.push(("per-period table", t.finish()?));
    }
    if let Some(mut l) = log {
        if let Some(t) = out.end.stop_time_s() {
            let level = if matches!(out.end, RunEnd::Interrupted { .. }) {
                "warning"
            } else {
                "error"
            };
            l.event(t, level, &out.end.describe())?;
        }
        written.push(("MCAP log", l.finish(Some(metrics))?));
    }
    // Whole files: written under a temporary name and renamed when complete, removed on an
    // error (output::file): never an empty or cut plot.svg or metrics.json.
    if let Some(p) = &plot {
        p.write_svg(
            &plot_path,
            &format!("pmsm-sim: {} ({})", scenario.name, scenario.description),
        )?;
        written.push(("plot", plot_path.clone()));
    }
    let json = report::json(metrics).map_err(|e| out_err(&metrics_path, e))?;
    // metrics.json: the same for identical runs; the wall-clock fields go to timing.json.
    let (metrics_json, timing_json) =
        report::json_split(metrics).map_err(|e| out_err(&metrics_path, e))?;
    write_bytes(&metrics_path, format!("{metrics_json}\n").as_bytes())?;
    written.push(("metrics", metrics_path.clone()));
    let timing_path = dir.join("timing.json");
    write_bytes(&timing_path, format!("{timing_json}\n").as_bytes())?;
    written.push(("timing", timing_path.clone()));

    if args.json {
        println!("{json}");
    } else {
        print!("{}", report::table(metrics));
        println!();
    }
    let say = |line: String| {
        if args.json {
            eprintln!("{line}");
        } else {
            println!("{line}");
        }
    };
    say(format!("outputs in {}:", dir.display()));
    for (what, path) in &written {
        match std::fs::metadata(path) {
            Ok(m) if *what == "MCAP log" => say(format!(
                "  {what:<9} {} ({:.1} MB)",
                path.display(),
                m.len() as f64 / 1e6
            )),
            _ => say(format!("  {what:<9} {}", path.display())),
        }
    }
    Ok(match &out.end {
        RunEnd::Completed => ExitCode::SUCCESS,
        RunEnd::Interrupted { .. } => {
            let (code, name) = signals.received().unwrap_or((130, "a signal"));
            eprintln!(
                "pmsm-sim: {} by {name} (outputs cover the part simulated)",
                out.end.describe()
            );
            ExitCode::from(code)
        }
        other => {
            eprintln!(
                "pmsm-sim: error: run stopped: {} (outputs cover the part simulated)",
                other.describe()
            );
            ExitCode::from(2)
        }
    })
}

/// `pmsm-sim replay` (module `pmsm_sim::analysis::replay`): the table printed, the outputs written.
fn replay_command(
    log: &Path,
    motor: &Path,
    out: &Path,
    scaling: ScalingArg,
    log_options: LogOptions,
) -> ExitCode {
    use pmsm_sim::analysis::replay::{
        Scaling, markdown, read_log, read_motor, replay, write_outputs,
    };
    let scaling = match scaling {
        ScalingArg::Amplitude => Scaling::Amplitude,
        ScalingArg::Power => Scaling::Power,
    };
    let run = || -> Result<(), pmsm_sim::analysis::replay::ReplayError> {
        let m = read_motor(motor)?;
        let l = read_log(log, scaling)?;
        let r = replay(&l, &m, &log.display().to_string())?;
        let written = write_outputs(out, &l, &m, &r, log_options)?;
        print!("{}", markdown(&r.report));
        if let Some(f) = r.report.flux_check.filter(|f| f.off()) {
            eprintln!(
                "pmsm-sim: warning: the record's back-EMF per unit speed is {:.3} times the motor \
                 file's psi_f ({:.5} against {:.5} Wb): check the file and the log's scaling \
                 (--scaling)",
                f.ratio, f.flux_wb, f.told_wb
            );
        }
        println!("\noutputs in {}:", out.display());
        for p in written {
            println!("  {}", p.display());
        }
        Ok(())
    };
    match run() {
        Ok(()) => ExitCode::SUCCESS,
        Err(e) => {
            eprintln!("pmsm-sim: error: {e}");
            ExitCode::FAILURE
        }
    }
}
