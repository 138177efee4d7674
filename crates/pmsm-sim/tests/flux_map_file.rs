//! `[motor.flux_map] file = "map.csv"`: a scenario reads a saturating motor's flux map from a
//! CSV table beside it (module `plant::machine::saturation`); malformed tables are refused
//! naming the key, the line and the column.

use std::fmt::Write;
use std::sync::atomic::{AtomicUsize, Ordering};

use ekf_core::saturation::PM_SYRM_5K6;
use pmsm_sim::scenario::Scenario;

fn scenario_text() -> String {
    let base = Scenario::preset_text("default").unwrap();
    // The default scenario's motor replaced by the PM-SyRM told its map from a file.
    let mut out = String::new();
    let mut skip = false;
    for line in base.lines() {
        if line.trim_start().starts_with('[') {
            skip = line.trim() == "[motor]";
            if skip {
                out.push_str(
                    "[motor]\nrs_ohm = 0.63\npole_pairs = 2\nj_kg_m2 = 0.05\nb_nm_s_rad = 0.002\n\
                     [motor.flux_map]\nfile = \"map.csv\"\n",
                );
                continue;
            }
        }
        if !skip {
            out.push_str(line);
            out.push('\n');
        }
    }
    out
}

fn map_csv() -> String {
    let i_d: Vec<f64> = (0..10).map(|k| -21.0 + 3.0 * k as f64).collect();
    let i_q: Vec<f64> = (0..13).map(|k| -24.0 + 4.0 * k as f64).collect();
    let map = PM_SYRM_5K6.flux_map::<f64, 16>(&i_d, &i_q).unwrap();
    let mut s = String::from("psi_q, i_d, i_q, psi_d\n");
    // Rows in an order of their own (q outer), columns in another.
    for &q in &i_q {
        for &d in &i_d {
            let p = map.eval(d, q);
            let _ = writeln!(s, "{}, {d}, {q}, {}", p.psi_q, p.psi_d);
        }
    }
    s
}

/// A fresh directory of this test process.
fn temp_dir(name: &str) -> std::path::PathBuf {
    let d = std::env::temp_dir().join(format!("pmsm-sim-fluxmap-{}-{name}", std::process::id()));
    let _ = std::fs::remove_dir_all(&d);
    std::fs::create_dir_all(&d).unwrap();
    d
}

fn load_in(dir: &std::path::Path, csv: Option<&str>) -> Result<Scenario, String> {
    if let Some(csv) = csv {
        std::fs::write(dir.join("map.csv"), csv).unwrap();
    }
    let path = dir.join("sc.toml");
    std::fs::write(&path, scenario_text()).unwrap();
    let out = Scenario::from_file(&path).map_err(|e| e.to_string());
    let _ = std::fs::remove_dir_all(dir);
    out
}

fn load(csv: &str) -> Result<Scenario, String> {
    // A directory per call: the tests run in parallel.
    static CALLS: AtomicUsize = AtomicUsize::new(0);
    let n = CALLS.fetch_add(1, Ordering::Relaxed);
    load_in(&temp_dir(&format!("call{n}")), Some(csv))
}

#[test]
fn a_csv_map_beside_the_scenario_is_the_motors_flux_map() {
    let sc = load(&map_csv()).unwrap();
    let t = sc.motor.flux_map.as_ref().expect("flux map");
    assert_eq!(t.map.shape(), (10, 13));
    assert!(sc.motor.saturation.is_none());
    // Small-signal values from the map.
    assert!(
        (sc.motor.psi_f_wb - 0.4767).abs() < 2e-3,
        "{}",
        sc.motor.psi_f_wb
    );
    let p = t.map.eval(-7.0, 10.0);
    let (a, b) = PM_SYRM_5K6.currents(p.psi_d, p.psi_q);
    assert!((a + 7.0).abs() < 0.3 && (b - 10.0).abs() < 0.3, "{a} {b}");
}

#[test]
fn malformed_csv_maps_are_refused_by_line_and_column() {
    let good = map_csv();
    let cases = [
        (good.replacen("psi_d", "psi_x", 1), "no column named psi_d"),
        (
            good.replacen(", -21, ", ", abc, ", 1),
            "line 2, column 2 (i_d)",
        ),
        (format!("{good}0.1, -21, -24, 0.3\n"), "appears twice"),
        (
            good.lines().take(50).collect::<Vec<_>>().join("\n"),
            "is missing",
        ),
    ];
    for (csv, want) in cases {
        let err = load(&csv).unwrap_err();
        assert!(
            err.contains("motor.flux_map.file") && err.contains(want),
            "{want}: {err}"
        );
    }
    let err = load_in(&temp_dir("missing"), None).unwrap_err();
    assert!(err.contains("map.csv"), "{err}");
}
