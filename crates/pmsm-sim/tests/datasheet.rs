//! `pmsm-sim datasheet --quick` on the default motor: every section, finite numbers, the same
//! bytes for a seed whatever the threads, the M4F counts read from a file or plainly missing,
//! bad input refused, and the Monte-Carlo plan it writes is the plan it ran.
//! (The HTML's rendering in headless Chromium: tests/python/test_datasheet_html.py.)

use std::path::{Path, PathBuf};
use std::process::{Command, Output};

use pmsm_sim::analysis::datasheet::SECTION_TITLES;

const BIN: &str = env!("CARGO_BIN_EXE_pmsm-sim");

fn temp_dir(name: &str) -> PathBuf {
    let d = std::env::temp_dir().join(format!("pmsm-sim-ds-{}-{name}", std::process::id()));
    let _ = std::fs::remove_dir_all(&d);
    std::fs::create_dir_all(&d).unwrap_or_else(|e| panic!("{}: {e}", d.display()));
    d
}

/// Runs `pmsm-sim datasheet ARGS` with `CARGO_TARGET_DIR` at `target` (where the default
/// counts file is looked for).
fn datasheet(args: &[&str], target: &Path) -> Output {
    Command::new(BIN)
        .arg("datasheet")
        .args(args)
        .env("CARGO_TARGET_DIR", target)
        .output()
        .unwrap_or_else(|e| panic!("cannot run {BIN}: {e}"))
}

fn ok(o: &Output) {
    assert!(
        o.status.success(),
        "exit {:?}\nstdout:\n{}\nstderr:\n{}",
        o.status,
        String::from_utf8_lossy(&o.stdout),
        String::from_utf8_lossy(&o.stderr)
    );
}

fn read(p: &Path) -> String {
    std::fs::read_to_string(p).unwrap_or_else(|e| panic!("{}: {e}", p.display()))
}

/// Every number in the JSON is finite (serde_json writes a non-finite f64 as null: the
/// fields that must be numbers are checked by name).
fn number(v: &serde_json::Value, path: &[&str]) -> f64 {
    let mut cur = v;
    for k in path {
        cur = match k.parse::<usize>() {
            Ok(i) => &cur[i],
            Err(_) => &cur[*k],
        };
    }
    let x = cur
        .as_f64()
        .unwrap_or_else(|| panic!("{path:?} is not a number: {cur}"));
    assert!(x.is_finite(), "{path:?} = {x}");
    x
}

#[test]
fn quick_datasheet_of_the_default_motor() {
    let dir = temp_dir("quick");
    let empty_target = temp_dir("no-counts");
    let out = dir.join("a");
    let o = datasheet(
        &["--quick", "--threads", "2", "--out", out.to_str().unwrap()],
        &empty_target,
    );
    ok(&o);
    let md = read(&out.join("datasheet.md"));
    let html = read(&out.join("datasheet.html"));
    for t in SECTION_TITLES {
        assert!(md.contains(&format!("## {t}")), "markdown lacks {t}");
        assert!(html.contains(&format!("<h2>{t}</h2>")), "HTML lacks {t}");
    }
    assert!(md.contains("# Datasheet: servo"));
    // Surface motor: HFI skipped with a sentence; no counts file: said plainly, with the command.
    assert!(md.contains("Not applicable: servo is a surface motor"));
    assert!(md.contains("Not measured: no counts file at"));
    assert!(md.contains("bash scripts/qemu-firmware.sh"));
    // Five figures: files next to the markdown, inline in the HTML; nothing external.
    let figs: Vec<&str> = md
        .lines()
        .filter_map(|l| l.strip_prefix("![").and_then(|r| r.split("](").nth(1)))
        .map(|r| r.trim_end_matches(')'))
        .collect();
    assert_eq!(figs.len(), 5, "{figs:?}");
    for f in &figs {
        assert!(read(&out.join(f)).starts_with("<svg"), "{f}");
    }
    assert_eq!(html.matches("<svg").count(), 5);
    for external in ["<script", "<link", "src=\"http", "href=\"http", "<img"] {
        assert!(!html.contains(external), "the HTML has {external}");
    }
    assert!(!md.contains("NaN") && !md.contains("inf "));

    // The numbers: finite, and the results the markdown states.
    let j: serde_json::Value = serde_json::from_str(&read(&out.join("datasheet.json"))).unwrap();
    let cells = j["angle"]["cells"].as_array().unwrap();
    assert_eq!(cells.len(), 3 * 2);
    for (k, c) in cells.iter().enumerate() {
        let e = number(
            &j,
            &["angle", "cells", &k.to_string(), "angle_error_rms_deg"],
        );
        assert!((0.0..180.0).contains(&e), "{c}");
    }
    let runs = j["low_speed"]["runs"].as_array().unwrap();
    assert_eq!(runs.len(), 3);
    for k in 0..runs.len() {
        number(&j, &["low_speed", "runs", &k.to_string(), "current_ratio"]);
    }
    let starts = j["startup"]["runs"].as_array().unwrap();
    assert_eq!(starts.len(), 6);
    let succeeded = starts.iter().filter(|r| r["success"] == true).count();
    for k in 0..starts.len() {
        number(&j, &["startup", "runs", &k.to_string(), "backward_pct"]);
    }
    let pct = 100.0 * succeeded as f64 / 6.0;
    assert!(
        md.contains(&format!("success **{pct:.1} %**")),
        "start-up rate {pct} not in the markdown"
    );
    assert!(j["hfi"].is_null());
    let id = &j["identify"]["runs"][0];
    assert_eq!(id["ok"], true, "{id}");
    for p in ["rs_ohm", "ld_h", "lq_h", "psi_f_wb"] {
        let e = number(&j, &["identify", "runs", "0", "errors_pct", p]);
        assert!(e.abs() < 20.0, "{p}: {e} %");
    }
    let mc = j["monte_carlo"]["runs"].as_array().unwrap();
    assert_eq!(mc.len(), 12);
    for k in 0..mc.len() {
        let rs = number(&j, &["monte_carlo", "runs", &k.to_string(), "rs_error_pct"]);
        assert!((-30.0..30.0).contains(&rs), "{rs}");
        let dt = number(&j, &["monte_carlo", "runs", &k.to_string(), "dead_time_us"]);
        assert!((0.0..2.0).contains(&dt), "{dt}");
    }
    assert!(j["m4f"]["counts"].is_null());

    // The plan written is the plan run: the same draws, through pmsm-sim sweep's reader.
    let plan = pmsm_sim::analysis::sweep::cli::read_plan(&out.join("montecarlo-plan.toml"))
        .unwrap_or_else(|e| panic!("{e}"));
    let specs = pmsm_sim::analysis::sweep::Plan::new(&plan.scenario, &plan.vary, plan.n, plan.seed)
        .unwrap()
        .runs()
        .unwrap();
    assert_eq!(specs.len(), 12);
    let rs0 = plan.scenario.motor.rs_ohm;
    for (spec, run) in specs.iter().zip(mc) {
        let told = spec
            .values
            .iter()
            .find(|(k, _)| k == "observer.rs_ohm")
            .and_then(|(_, v)| v.as_float())
            .unwrap();
        let want = run["rs_error_pct"].as_f64().unwrap();
        assert!((100.0 * (told / rs0 - 1.0) - want).abs() < 1e-9);
    }

    // Deterministic for the seed, whatever the threads; another seed, other draws.
    let again = dir.join("b");
    ok(&datasheet(
        &[
            "--quick",
            "--threads",
            "1",
            "--out",
            again.to_str().unwrap(),
        ],
        &empty_target,
    ));
    assert_eq!(md, read(&again.join("datasheet.md")));
    assert_eq!(html, read(&again.join("datasheet.html")));

    // The M4F counts, when given: the table and the result.
    let counts = dir.join("counts.json");
    std::fs::write(
        &counts,
        r#"{"machine": "mps2-an386", "qemu": "QEMU emulator version 7.2",
            "instructions_per_call": {"ekf_step": 1063, "foc_tick": 1721},
            "flash_bytes": 264880, "ram_bytes": 28}"#,
    )
    .unwrap();
    let with = dir.join("c");
    ok(&datasheet(
        &[
            "--quick",
            "--seed",
            "2",
            "--m4f-counts",
            counts.to_str().unwrap(),
            "--out",
            with.to_str().unwrap(),
        ],
        &empty_target,
    ));
    let md2 = read(&with.join("datasheet.md"));
    assert!(
        md2.contains("`foc_tick` **1721 instructions per call**"),
        "{md2}"
    );
    assert!(md2.contains("| `ekf_step` | 1063 |"));
    assert!(!md2.contains("Not measured"));
    assert_ne!(
        md.split("## 3.").nth(1),
        md2.split("## 3.").nth(1),
        "another seed, other start-ups"
    );
    let _ = std::fs::remove_dir_all(&dir);
    let _ = std::fs::remove_dir_all(&empty_target);
}

#[test]
fn bad_input_is_refused_with_its_name() {
    let dir = temp_dir("bad");
    let out = dir.join("x");
    let o = datasheet(
        &["--motor", "warp_drive", "--out", out.to_str().unwrap()],
        &dir,
    );
    assert!(!o.status.success());
    let err = String::from_utf8_lossy(&o.stderr);
    assert!(
        err.contains("unknown motor `warp_drive`") && err.contains("servo"),
        "{err}"
    );
    let bad = dir.join("bad.json");
    std::fs::write(&bad, "{\"instructions_per_call\": 3}").unwrap();
    for (file, want) in [
        (bad.clone(), "not an M4F counts file"),
        (dir.join("missing.json"), "missing.json"),
    ] {
        let o = datasheet(
            &[
                "--quick",
                "--m4f-counts",
                file.to_str().unwrap(),
                "--out",
                out.to_str().unwrap(),
            ],
            &dir,
        );
        assert!(!o.status.success());
        let err = String::from_utf8_lossy(&o.stderr);
        assert!(
            err.contains(want) && err.contains(file.to_str().unwrap()),
            "{err}"
        );
    }
    let o = datasheet(
        &["--quick", "--threads", "0", "--out", out.to_str().unwrap()],
        &dir,
    );
    assert!(!o.status.success());
    assert!(String::from_utf8_lossy(&o.stderr).contains("--threads"));
    let _ = std::fs::remove_dir_all(&dir);
}
