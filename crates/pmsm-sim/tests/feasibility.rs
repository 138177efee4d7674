//! `pmsm-sim check` and `run` warn when a scenario asks for more than its drive can do
//! (module `pmsm_sim::scenario::feasibility`): a drone motor asked for 15000 rpm on 24 V is
//! reported with its numbers, the shipped scenarios are not.

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
