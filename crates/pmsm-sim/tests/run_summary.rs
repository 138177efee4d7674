//! `pmsm-sim run` says what the start-up did (module `pmsm_sim::output::startup_log`): the
//! default scenario's alignment, I/f ramp, hand-over and closed loop with their times, on
//! stderr, the same times as its metrics.

use std::process::Command;

const BIN: &str = env!("CARGO_BIN_EXE_pmsm-sim");

#[test]
fn the_default_run_prints_its_start_up_phases_with_their_times() {
    let dir = std::env::temp_dir().join(format!("pmsm-sim-summary-{}", std::process::id()));
    let _ = std::fs::remove_dir_all(&dir);
    let o = Command::new(BIN)
        .args([
            "run",
            "--duration",
            "0.4",
            "--no-log",
            "--no-plot",
            "--json",
        ])
        .arg("--out")
        .arg(&dir)
        .output()
        .unwrap_or_else(|e| panic!("cannot run {BIN}: {e}"));
    let err = String::from_utf8_lossy(&o.stderr);
    assert!(o.status.success(), "{err}");
    let metrics: serde_json::Value =
        serde_json::from_slice(&o.stdout).unwrap_or_else(|e| panic!("{e}"));
    let line = |what: &str| {
        err.lines()
            .find(|l| l.contains(what))
            .unwrap_or_else(|| panic!("{what:?} missing:\n{err}"))
            .to_string()
    };
    let time_of = |l: &str| -> f64 {
        l.split_whitespace()
            .next()
            .and_then(|t| t.parse().ok())
            .unwrap_or_else(|| panic!("no time in {l:?}"))
    };
    assert!(err.contains("start-up and drive states:"), "{err}");
    assert_eq!(time_of(&line("alignment starts (2.50 A)")), 0.0);
    // The phases in order, the times those of the metrics (which the suite checks).
    let st = &metrics["startup"];
    let align_end = time_of(&line("alignment ends after"));
    let handover = time_of(&line("hand-over to the observer at"));
    let closed = time_of(&line("closed loop (speed reference"));
    let near = |a: f64, b: &serde_json::Value| (a - b.as_f64().unwrap_or(f64::NAN)).abs() < 1e-4;
    assert!(near(align_end, &st["align_end_s"]), "{align_end} {st}");
    assert!(near(handover, &st["handover_s"]), "{handover} {st}");
    assert!(handover > align_end && closed > handover, "{err}");
    assert!(
        line("alignment ends after").contains("I/f ramp at 2000 rpm/s"),
        "{err}"
    );
    let ttc = line("time to closed loop");
    let drive_closed = metrics["drive"]["closed_loop_time_s"]
        .as_f64()
        .unwrap_or(f64::NAN);
    assert!(
        ttc.contains(&format!("time to closed loop {drive_closed:.3} s")),
        "{ttc} vs {drive_closed}"
    );
    assert!(
        line("set by:").contains("align_time_s 0.100 s ([controller.foc])"),
        "{err}"
    );
    let _ = std::fs::remove_dir_all(&dir);
}
