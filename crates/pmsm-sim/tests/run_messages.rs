//! What `pmsm-sim check` and `run` tell the user beside the results: the warnings when a
//! scenario asks for more than its drive can do (module `pmsm_sim::scenario::feasibility`: a
//! drone motor asked for 15000 rpm on 24 V is reported with its numbers, the shipped
//! scenarios are not), and what the start-up did (module `pmsm_sim::output::startup_log`:
//! the default scenario's alignment, I/f ramp, hand-over and closed loop with their times,
//! on stderr, the same times as its metrics).

use std::path::{Path, PathBuf};
use std::process::{Command, Output};

const BIN: &str = env!("CARGO_BIN_EXE_pmsm-sim");

fn run(args: &[&str], cwd: &Path) -> Output {
    Command::new(BIN)
        .args(args)
        .current_dir(cwd)
        .output()
        .unwrap_or_else(|e| panic!("cannot run {BIN}: {e}"))
}

fn text(b: &[u8]) -> String {
    String::from_utf8_lossy(b).into_owned()
}

fn temp_dir(name: &str) -> PathBuf {
    let d = std::env::temp_dir().join(format!("pmsm-sim-feas-{}-{name}", std::process::id()));
    let _ = std::fs::remove_dir_all(&d);
    std::fs::create_dir_all(&d).unwrap_or_else(|e| panic!("{}: {e}", d.display()));
    d
}

#[test]
fn a_15000_rpm_reference_at_24_v_is_reported_by_check_and_run() {
    let dir = temp_dir("drone24");
    let shipped = Path::new(env!("CARGO_MANIFEST_DIR")).join("scenarios/drone.toml");
    let drone = std::fs::read_to_string(&shipped).unwrap_or_else(|e| panic!("{e}"));
    assert!(drone.contains("u_dc_v = 48.0") && drone.contains("3429.0]"));
    let body = drone
        .replace("u_dc_v = 48.0", "u_dc_v = 24.0")
        .replace("3429.0]", "15000.0]");
    std::fs::write(dir.join("drone24.toml"), body).unwrap_or_else(|e| panic!("{e}"));
    let o = run(&["check", "drone24.toml"], &dir);
    let err = text(&o.stderr);
    // A warning, not an error: the exit code is that of a valid file.
    assert!(o.status.success(), "{err}");
    assert!(text(&o.stdout).contains("drone: ok"));
    let voltage = err
        .lines()
        .find(|l| l.contains("speed reference 15000 rpm (at"))
        .unwrap_or_else(|| panic!("no voltage warning: {err}"));
    // 24 V / sqrt(3) = 13.9 V; 13.9 V / 0.006 Wb / 7 pole pairs = 3150 rpm; 15000 rpm gives
    // 66.0 V of back-EMF.
    for part in [
        "pmsm-sim: warning: drone: ",
        "exceeds what 24 V allows",
        "back-EMF 66.0 V = 4.76 x the available 13.9 V",
        "without field weakening 3150 rpm at no load",
        "field weakening is off",
        "a finite-speed drive",
    ] {
        assert!(voltage.contains(part), "{part:?} missing: {voltage}");
    }
    // The fan load at 15000 rpm is beyond the current limit's 0.945 N m, and foc's own
    // speed limit clamps the command.
    assert!(
        err.contains("exceeds the 0.945 N m the current limit of 15 A gives"),
        "{err}"
    );
    assert!(
        err.contains("exceeds the controller's speed limit"),
        "{err}"
    );
    // `run` prints the same before it runs (over the time it simulates: the reference peaks
    // at 0.5 s).
    let o = run(
        &[
            "run",
            "drone24.toml",
            "--duration",
            "0.55",
            "--no-log",
            "--no-plot",
            "--out",
            "o",
        ],
        &dir,
    );
    assert!(o.status.success(), "{}", text(&o.stderr));
    assert!(text(&o.stderr).contains(voltage), "{}", text(&o.stderr));
    let _ = std::fs::remove_dir_all(&dir);
}

#[test]
fn the_default_and_every_shipped_scenario_check_without_a_warning() {
    let dir = temp_dir("shipped");
    let o = run(&["check", "default"], &dir);
    assert!(
        o.status.success() && o.stderr.is_empty(),
        "{}",
        text(&o.stderr)
    );
    let scenarios = Path::new(env!("CARGO_MANIFEST_DIR")).join("scenarios");
    let mut n = 0;
    for entry in std::fs::read_dir(&scenarios).unwrap_or_else(|e| panic!("{e}")) {
        let path = entry.unwrap_or_else(|e| panic!("{e}")).path();
        if path.extension().is_some_and(|e| e == "toml") {
            let o = run(&["check", &path.display().to_string()], &dir);
            let err = text(&o.stderr);
            assert!(o.status.success(), "{}: {err}", path.display());
            assert!(!err.contains("warning"), "{}: {err}", path.display());
            n += 1;
        }
    }
    assert!(n >= 12, "{n} scenario files");
    let _ = std::fs::remove_dir_all(&dir);
}

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
