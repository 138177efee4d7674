//! `pmsm-sim bench`: the simulator's speed. Each configuration (the run with no outputs, with
//! the MCAP log in each encoding and compression, with the plot, with the observers pipelined
//! on their own thread) is run `runs` times and the medians are printed: wall time, wall ns per
//! PWM period, the real-time factor (simulated time / wall time), and the CPU ns per period of
//! the simulating thread and of the whole process (on a shared machine the wall time also
//! counts other processes). Then the median time per call of the loop's parts (plant,
//! inverter, sensor, controller, observers, log encoder) on the scenario's own trajectory.
//! docs/performance.md keeps the current results.

use std::path::Path;
use std::process::ExitCode;
use std::time::Instant;

use cpu_time::{ProcessTime, ThreadTime};
use pmsm_sim::SimError;
use pmsm_sim::drive::interface::{ControllerInput, RotorFeedback};
use pmsm_sim::output::mcap::{LogCompression, LogEncoding, LogOptions, McapLog};
use pmsm_sim::scenario::Scenario;
use pmsm_sim::sim::{self, RunOptions, SampleSink};

use crate::{load, out_err};

/// Median of some numbers (sorted copy; NaN-free input).
fn median(mut v: Vec<f64>) -> f64 {
    v.sort_by(f64::total_cmp);
    let n = v.len();
    if n == 0 {
        f64::NAN
    } else if n % 2 == 1 {
        v[n / 2]
    } else {
        0.5 * (v[n / 2 - 1] + v[n / 2])
    }
}

pub(crate) fn bench(what: Option<&str>, runs: usize, out: &Path) -> Result<ExitCode, SimError> {
    let base = load(what.unwrap_or("default"))?;
    let runs = runs.max(1);
    std::fs::create_dir_all(out).map_err(|e| out_err(out, e))?;
    let mcap_path = out.join("bench.mcap");
    println!(
        "benchmark: scenario {} ({:.3} s simulated, {} periods of {:.1} us), {runs} runs each, medians",
        base.name,
        base.duration_s,
        base.periods(),
        base.ts_s() * 1e6
    );
    println!(
        "{:<46} {:>10} {:>10} {:>11} {:>12} {:>12} {:>12}",
        "configuration",
        "wall (ms)",
        "ns/period",
        "real-time x",
        "CPU sim thr.",
        "CPU all thr.",
        "MB / sim. s"
    );
    println!(
        "{:<46} {:>10} {:>10} {:>11} {:>12} {:>12}",
        "", "", "(wall)", "(wall)", "ns/period", "ns/period"
    );
    let log = |compression, encoding| {
        Some(LogOptions {
            compression,
            encoding,
            ..LogOptions::default()
        })
    };
    let (pb, json) = (LogEncoding::Protobuf, LogEncoding::Json);
    // One untimed run first: page faults, caches and the CPU's clock settle.
    sim::run_with(&base, RunOptions::default())?;
    // (name, reference filter, log, observers inline on the simulating thread). `pmsm-sim run`
    // (the default run: reference filter, MCAP protobuf) and `--no-log` pipeline the observers
    // where `sim::pipeline_pays` says so, and step them inline otherwise: their rows are
    // the pipelined or the inline ones accordingly (printed below the table).
    let configs: [(&str, bool, Option<LogOptions>, bool); 10] = [
        ("no reference filter, no log", false, None, false),
        (
            "reference filter, no log, observers pipelined",
            true,
            None,
            false,
        ),
        (
            "  the same, observers inline (sequential)",
            true,
            None,
            true,
        ),
        (
            "no reference filter, MCAP protobuf",
            false,
            log(LogCompression::None, pb),
            false,
        ),
        (
            "reference filter, MCAP protobuf, observers pipelined",
            true,
            log(LogCompression::None, pb),
            false,
        ),
        (
            "  the same, observers inline (sequential)",
            true,
            log(LogCompression::None, pb),
            true,
        ),
        (
            "reference filter, MCAP protobuf lz4",
            true,
            log(LogCompression::Lz4, pb),
            false,
        ),
        (
            "reference filter, MCAP protobuf zstd",
            true,
            log(LogCompression::Zstd, pb),
            false,
        ),
        (
            "reference filter, MCAP JSON zstd",
            true,
            log(LogCompression::Zstd, json),
            false,
        ),
        (
            "no reference filter, no log, observers inline",
            false,
            None,
            true,
        ),
    ];
    // Simulating thread's CPU per period without the log, with the reference filter: observers
    // inline, and pipelined on their own thread.
    let mut no_log_ns = None;
    let mut no_log_piped_ns = None;
    for (name, seed_filter, log, inline_observers) in configs {
        let mut sc = base.clone();
        sc.observer.reference_filter = seed_filter;
        let mut walls = Vec::with_capacity(runs);
        let mut cpu_thread = Vec::with_capacity(runs);
        let mut cpu_all = Vec::with_capacity(runs);
        let mut size = 0;
        for _ in 0..runs {
            let mut logger = match log {
                Some(o) => Some(McapLog::create(&mcap_path, &sc, o)?),
                None => None,
            };
            let mut sinks: Vec<&mut dyn SampleSink> = Vec::new();
            if let Some(l) = logger.as_mut() {
                sinks.push(l);
            }
            // Wall time includes finishing the file.
            let t = Instant::now();
            let (thread0, process0) = (ThreadTime::try_now().ok(), ProcessTime::try_now().ok());
            let r = sim::run_with(
                &sc,
                RunOptions {
                    sinks,
                    inline_observers,
                    ..RunOptions::default()
                },
            )?;
            if let Some(l) = logger {
                l.finish(Some(&r.metrics))?;
            }
            walls.push(t.elapsed().as_secs_f64());
            if let Some(Ok(d)) = thread0.map(|t| t.try_elapsed()) {
                cpu_thread.push(d.as_secs_f64());
            }
            if let Some(Ok(d)) = process0.map(|t| t.try_elapsed()) {
                cpu_all.push(d.as_secs_f64());
            }
            if log.is_some() {
                size = std::fs::metadata(&mcap_path).map_or(0, |m| m.len());
            }
            if !r.end.is_completed() {
                return Err(SimError::Stopped {
                    t_s: r.end.stop_time_s().unwrap_or(0.0),
                    reason: r.end.describe(),
                });
            }
        }
        let w = median(walls);
        if seed_filter && log.is_none() {
            let ns = Some(median(cpu_thread.clone()) * 1e9 / sc.periods() as f64);
            if inline_observers {
                no_log_ns = ns;
            } else {
                no_log_piped_ns = ns;
            }
        }
        let mb = if log.is_some() {
            format!("{:.2}", size as f64 / 1e6 / sc.duration_s)
        } else {
            "-".into()
        };
        let per = |v: Vec<f64>| median(v) * 1e9 / sc.periods() as f64;
        println!(
            "{name:<46} {:>10.2} {:>10.0} {:>11.0} {:>12.0} {:>12.0} {mb:>12}",
            w * 1e3,
            w * 1e9 / sc.periods() as f64,
            sc.duration_s / w,
            per(cpu_thread),
            per(cpu_all),
        );
    }
    let mode = |log| {
        if sim::pipeline_pays(log) {
            "pipelined"
        } else {
            "inline"
        }
    };
    println!(
        "(on this machine's {} core(s) `pmsm-sim run` steps the observers {} with the log (the \
         default run) and {} with --no-log)",
        std::thread::available_parallelism().map_or(1, |n| n.get()),
        mode(true),
        mode(false),
    );
    let _ = std::fs::remove_file(&mcap_path);
    components(&base, runs, no_log_ns, no_log_piped_ns);
    Ok(ExitCode::SUCCESS)
}

/// Median time per call of the loop's parts, on the scenario's own trajectory.
fn components(sc: &Scenario, runs: usize, no_log_ns: Option<f64>, piped_ns: Option<f64>) {
    use ekf_core::PmsmObserver;
    use pmsm_sim::plant::sensors::CurrentSensor;
    use pmsm_sim::plant::{Plant, PlantState};

    // Record the trajectory once (inputs for the parts).
    let Ok(out) = sim::run(&sc.clone().with_duration(sc.duration_s)) else {
        return;
    };
    let samples = &out.trace.samples;
    let n = samples.len().max(1) as f64;
    // Each part reads its inputs from a compact copy: read from the trace (20 MB, one sample
    // about 1 KB) every call would also time a cache miss, which the run loop, where the
    // period's values are at hand, does not pay.
    let plant_in: Vec<([f64; 2], f64)> = samples
        .iter()
        .map(|s| (s.inverter.u_ab_v, s.truth.load_torque_nm))
        .collect();
    let obs_in: Vec<([f64; 2], [f64; 2])> = samples
        .iter()
        .map(|s| (s.inverter.u_ab_commanded_v, s.measured.i_ab_a))
        .collect();
    let sensor_in: Vec<[f64; 2]> = samples.iter().map(|s| s.truth.i_ab_a).collect();
    let time = |f: &mut dyn FnMut()| {
        let v: Vec<f64> = (0..runs)
            .map(|_| {
                let t = ThreadTime::try_now();
                f();
                t.and_then(|t| t.try_elapsed())
                    .map_or(f64::NAN, |d| d.as_secs_f64() * 1e9 / n)
            })
            .collect();
        median(v)
    };
    let ts = sc.ts_s();
    let plant_ns = time(&mut || {
        let mut p = Plant::new(sc.motor.clone(), PlantState::default());
        for &(u, load) in &plant_in {
            p.step(u, load, ts);
        }
        std::hint::black_box(p.state());
    });
    let obs_ns = time(&mut || {
        let Ok(mut o) = PmsmObserver::new(&sc.observer_config()) else {
            return;
        };
        let mut u = [0.0; 2];
        for &(u_applied, i) in &obs_in {
            let _ = std::hint::black_box(o.step(u, i));
            u = u_applied;
        }
    });
    let Ok(sensored) = sim::build_controller(sc).map(|c| c.sensored()) else {
        return;
    };
    let ctl_in: Vec<ControllerInput> = samples
        .iter()
        .map(|s| ControllerInput {
            k: s.k,
            t_s: s.t_s,
            i_abc_a: s.measured.i_abc_a,
            i_ab_a: s.measured.i_ab_a,
            u_dc_v: s.measured.u_dc_v,
            speed_ref_mech_rad_s: s.control.speed_ref_rpm / pmsm_sim::scenario::RPM_PER_RAD_S,
            rotor: sensored.then_some(RotorFeedback {
                theta_e_rad: s.truth.theta_e_rad,
                omega_mech_rad_s: s.truth.speed_rpm / pmsm_sim::scenario::RPM_PER_RAD_S,
            }),
        })
        .collect();
    let ctl_ns = time(&mut || {
        let Ok(mut c) = sim::build_controller(sc) else {
            return;
        };
        for input in &ctl_in {
            std::hint::black_box(c.tick(input));
        }
    });
    let sensor_ns = time(&mut || {
        let mut se = CurrentSensor::new(sc.sensors, sc.seed);
        for &i in &sensor_in {
            std::hint::black_box(se.measure(pmsm_sim::plant::frames::inverse_clarke(i)));
        }
    });
    // The encoder and the copy into the log's batch read a whole sample: they cycle over the
    // first 64 (in cache, as the period's sample is in the run).
    let hot = &samples[..samples.len().min(64)];
    let hot_sample = |i: usize| hot.get(i % hot.len().max(1));
    let proto_ns = time(&mut || {
        let mut enc = pmsm_sim::output::mcap::proto::PeriodEncoder::new();
        for i in 0..samples.len() {
            if let Some(s) = hot_sample(i) {
                std::hint::black_box(enc.encode(s));
            }
        }
    });
    // The whole log as the run pays for it: the copy of each period into a batch here, the
    // encoding and the `mcap` writer on the writer thread, creating and finishing the file
    // (wall time: with a free core the two threads overlap).
    let log_path = std::env::temp_dir().join(format!("pmsm-sim-bench-{}.mcap", std::process::id()));
    let log_runs: Vec<f64> = (0..runs)
        .map(|_| {
            let t = ProcessTime::try_now();
            if let Ok(mut log) = McapLog::create(&log_path, sc, LogOptions::default()) {
                for s in samples {
                    if log.record(s).is_err() {
                        break;
                    }
                }
                let _ = log.finish(None);
            }
            t.and_then(|t| t.try_elapsed())
                .map_or(f64::NAN, |d| d.as_secs_f64() * 1e9 / n)
        })
        .collect();
    let log_ns = median(log_runs);
    let copy_ns = time(&mut || {
        let mut batch = Vec::with_capacity(256);
        for i in 0..samples.len() {
            if batch.len() == 256 {
                batch.clear();
            }
            if let Some(s) = hot_sample(i) {
                batch.push(*s);
            }
            std::hint::black_box(&batch);
        }
    });
    let _ = std::fs::remove_file(&log_path);
    let json_ns = time(&mut || {
        let mut buf = Vec::with_capacity(4096);
        for s in samples {
            buf.clear();
            let _ = serde_json::to_writer(&mut buf, s);
            std::hint::black_box(&buf);
        }
    });
    println!(
        "\nparts of one period (median CPU ns per call of the thread, {runs} runs; the whole \
         log: CPU of both threads):"
    );
    for (name, ns) in [
        ("plant step (exact electrical, mechanics)", plant_ns),
        ("observer step (default EKF)", obs_ns),
        ("controller tick (incl. SVPWM)", ctl_ns),
        ("current sensor (noise, ADC)", sensor_ns),
        ("protobuf encoding of the period message", proto_ns),
        ("copy of the period into the log's batch", copy_ns),
        ("MCAP log, whole: encoding, mcap, file", log_ns),
        ("JSON encoding of the period message", json_ns),
    ] {
        println!("  {name:<44} {ns:>8.1}");
    }
    if let Some(no_log) = no_log_ns {
        // What the parts leave of the no-log loop: the record of the period, the streaming
        // metrics, the speed and load profiles, the inverter, the adapters.
        // (A difference of medians: as noisy as the noisiest of them.)
        let rest = no_log - (plant_ns + 2.0 * obs_ns + ctl_ns + sensor_ns);
        println!(
            "  {:<44} {rest:>8.1}",
            "rest of the no-log loop (record, metrics, ...)"
        );
        println!(
            "  ({no_log:.0} CPU ns per period without the log, with the reference filter, observers \
             inline: the parts above with the EKF step twice, the simulator's and the seed \
             filter's)"
        );
    }
    if let Some(piped) = piped_ns {
        println!(
            "  ({piped:.0} CPU ns per period on the simulating thread with the observers \
             pipelined on their own thread: the EKF steps leave it)"
        );
    }
}
