//! A time-bounded fuzz driver on stable Rust, on top of proptest's `TestRunner`; shared by the
//! fuzz targets of `ekf-core` and `foc` (included with `#[path]`).
//!
//! By default a target runs a fixed number of cases (part of `cargo test`). With
//! `FUZZ_SECONDS=N` it runs batches of fresh random cases for `N` seconds instead. Failures are
//! shrunk and reported by proptest, with the failing value.

use proptest::strategy::Strategy;
use proptest::test_runner::{Config, TestCaseError, TestRunner};
use std::time::{Duration, Instant};

/// Runs `test` on values of `strategy`: `cases` of them, or for `FUZZ_SECONDS` if set; then
/// prints the number of cases, the time and `stats()`.
pub fn fuzz<S: Strategy>(
    name: &str,
    cases: u32,
    strategy: S,
    test: impl Fn(S::Value) -> Result<(), TestCaseError>,
    stats: impl Fn() -> String,
) {
    let budget = std::env::var("FUZZ_SECONDS")
        .ok()
        .and_then(|s| s.parse::<f64>().ok())
        .map(Duration::from_secs_f64);
    let start = Instant::now();
    let batch = if budget.is_some() { 256 } else { cases };
    let mut total = 0u64;
    loop {
        // A fresh random seed for every batch.
        let mut runner = TestRunner::new(Config {
            cases: batch,
            failure_persistence: None,
            ..Config::default()
        });
        if let Err(e) = runner.run(&strategy, &test) {
            panic!("{name}: {e}");
        }
        total += u64::from(batch);
        match budget {
            Some(b) if start.elapsed() < b => continue,
            _ => break,
        }
    }
    println!(
        "fuzz {name}: {total} cases in {:.1} s; {}",
        start.elapsed().as_secs_f64(),
        stats()
    );
}
