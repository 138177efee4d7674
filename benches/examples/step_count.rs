//! Runs `N` observer steps of one configuration on the data of the `ekf_step` bench, for an
//! instruction count per step under valgrind (no hardware counters on the shared machines):
//!
//! ```text
//! cargo build --profile bench -p benches --example step_count
//! valgrind --tool=callgrind --callgrind-out-file=/tmp/cg.out \
//!     target/release/examples/step_count f64-default 100000
//! ```
//!
//! Run it with two values of `N`: the difference of the totals over the difference of `N` is
//! the cost of one step; `callgrind_annotate --auto=yes` spreads it over the source lines.
//! Configurations: `f64-default`, `f64-default-x4` (four observers in turn),
//! `f64-untracked`, `f64-seed`, `f64-salient`, `f64-flux`,
//! `f32-default`, `f32-seed`.
//!
//! With `STEP_COUNT_TIME=1` in the environment it also prints the fastest of 200 batches of
//! `N / 200` steps, in ns per step (on a loaded machine the minimum is the stable figure).
//! With `STEP_COUNT_PORTABLE=1` the observers run `step_portable` (the build for any x86-64)
//! instead of the dispatched `step` (AVX2 and FMA where the CPU has them; valgrind 3.19 does
//! not decode every AVX instruction of that build, e.g. the seed configuration's).
use std::hint::black_box;

use benches::samples;
use ekf_core::{
    Float, FluxObserver, FluxObserverConfig, MotorParams, ObserverConfig, PmsmObserver,
};

/// Runs `n` steps of `step(k)`; with `STEP_COUNT_TIME` set, in 200 timed batches.
fn batches(n: usize, mut step: impl FnMut(usize)) {
    if std::env::var_os("STEP_COUNT_TIME").is_none() {
        (0..n).for_each(step);
        return;
    }
    let per = (n / 200).max(1);
    let mut best = f64::INFINITY;
    for b in 0..200 {
        let t0 = std::time::Instant::now();
        (b * per..(b + 1) * per).for_each(&mut step);
        best = best.min(t0.elapsed().as_secs_f64() * 1e9 / per as f64);
    }
    println!("{best:.1} ns/step (fastest of 200 batches of {per})");
}

fn run<T: Float>(cfg: ObserverConfig<T>, data: &[([T; 2], [T; 2])], n: usize) {
    let mut obs = PmsmObserver::new(&cfg).expect("valid config");
    if std::env::var_os("STEP_COUNT_PORTABLE").is_some() {
        batches(n, |k| {
            let (u, i) = data[k & 1023];
            let _ = black_box(obs.step_portable(black_box(u), black_box(i)));
        });
        return;
    }
    batches(n, |k| {
        let (u, i) = data[k & 1023];
        // A refused step is part of what is measured; its error is not of interest here.
        let _ = black_box(obs.step(black_box(u), black_box(i)));
    });
}

/// Four observers stepped in turn: their chains of dependent operations overlap, so the time
/// per step against [`run`]'s shows how much of a step is latency (the diagnostic of the cost
/// map).
fn run4<T: Float>(cfg: ObserverConfig<T>, data: &[([T; 2], [T; 2])], n: usize) {
    let mut obs: Vec<_> = (0..4)
        .map(|_| PmsmObserver::new(&cfg).expect("valid config"))
        .collect();
    batches(n, |k| {
        let (u, i) = data[(k >> 2) & 1023];
        let _ = black_box(obs[k & 3].step(black_box(u), black_box(i)));
    });
}

fn main() {
    let mut args = std::env::args().skip(1);
    let which = args.next().unwrap_or_else(|| "f64-default".into());
    let n: usize = args.next().and_then(|s| s.parse().ok()).unwrap_or(100_000);
    let ts = 1e-4;
    let d64 = samples(|v| v);
    let d32 = samples(|v| v as f32);
    let servo = MotorParams::<f64>::servo;
    match which.as_str() {
        "f64-default" => run(ObserverConfig::new(servo(), ts), &d64, n),
        "f64-default-x4" => run4(ObserverConfig::new(servo(), ts), &d64, n),
        "f64-untracked" => run(
            ObserverConfig {
                parameter_tracking: None,
                ..ObserverConfig::new(servo(), ts)
            },
            &d64,
            n,
        ),
        "f64-seed" => run(ObserverConfig::seed(servo(), ts), &d64, n),
        "f64-salient" => run(
            ObserverConfig::new(
                MotorParams::<f64>::salient_from_f64(2.875, 0.7 * 8.5e-3, 8.5e-3, 0.175, 4),
                ts,
            ),
            &d64,
            n,
        ),
        "f64-flux" => {
            let mut flux =
                FluxObserver::new(&FluxObserverConfig::new(servo(), ts)).expect("valid config");
            batches(n, |k| {
                let (u, i) = d64[k & 1023];
                let _ = black_box(flux.step(black_box(u), black_box(i)));
            });
        }
        "f32-default" => run(
            ObserverConfig::new(MotorParams::<f32>::servo(), ts as f32),
            &d32,
            n,
        ),
        "f32-seed" => run(
            ObserverConfig::seed(MotorParams::<f32>::servo(), ts as f32),
            &d32,
            n,
        ),
        other => {
            eprintln!("unknown configuration {other}");
            std::process::exit(2);
        }
    }
}
