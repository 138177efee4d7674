//! `pmsm-sim motor`: datasheet values to a `[motor]` table that a scenario file takes.

use std::process::Command;

fn sim(args: &[&str]) -> std::process::Output {
    Command::new(env!("CARGO_BIN_EXE_pmsm-sim"))
        .args(args)
        .output()
        .unwrap_or_else(|e| panic!("{e}"))
}

#[test]
fn datasheet_values_give_a_motor_table_a_scenario_takes() {
    let o = sim(&[
        "motor",
        "--pole-pairs",
        "4",
        "--r-ll",
        "5.75",
        "--l-ll",
        "17e-3",
        "--kt",
        "1.05",
        "--j",
        "8e-4",
        "--b",
        "1e-3",
    ]);
    assert!(o.status.success());
    let block = String::from_utf8_lossy(&o.stdout).to_string();
    for line in [
        "rs_ohm = 2.875",
        "ld_h = 0.0085",
        "lq_h = 0.0085",
        "pole_pairs = 4",
    ] {
        assert!(block.contains(line), "{block}");
    }
    let psi: f64 = block
        .lines()
        .find_map(|l| l.strip_prefix("psi_f_wb = "))
        .and_then(|v| v.parse().ok())
        .expect("psi_f_wb line");
    assert!((psi - 0.175).abs() < 1e-12);
    // Into the default preset in place of its [motor] table, then `check`.
    let preset = String::from_utf8_lossy(&sim(&["show", "default"]).stdout).to_string();
    let a = preset.find("[motor]").unwrap();
    let b = a + 1 + preset[a + 1..].find("\n[").unwrap();
    let text = format!("{}{}{}", &preset[..a], block, &preset[b..]);
    let dir = std::env::temp_dir().join(format!("pmsm-sim-motor-{}", std::process::id()));
    std::fs::create_dir_all(&dir).unwrap();
    let path = dir.join("mine.toml");
    std::fs::write(&path, text).unwrap();
    let o = sim(&["check", path.to_str().unwrap()]);
    assert!(o.status.success(), "{}", String::from_utf8_lossy(&o.stderr));
    let _ = std::fs::remove_dir_all(&dir);
}

#[test]
fn kv_and_interior_inductances_convert_and_bad_values_are_named() {
    let o = sim(&[
        "motor",
        "--pole-pairs",
        "3",
        "--r-ll",
        "7.2",
        "--ld-ll",
        "0.06",
        "--lq-ll",
        "0.084",
        "--kv",
        "100",
    ]);
    let block = String::from_utf8_lossy(&o.stdout).to_string();
    assert!(
        block.contains("ld_h = 0.03") && block.contains("lq_h = 0.042"),
        "{block}"
    );
    assert!(block.contains("# j_kg_m2 = ..."), "{block}");
    let o = sim(&[
        "motor",
        "--pole-pairs",
        "4",
        "--r-ll",
        "-1",
        "--l-ll",
        "1e-3",
        "--kv",
        "100",
    ]);
    assert_eq!(o.status.code(), Some(1));
    assert!(String::from_utf8_lossy(&o.stderr).contains("--r-ll must be positive"));
    let o = sim(&[
        "motor",
        "--pole-pairs",
        "4",
        "--r-ll",
        "1",
        "--l-ll",
        "1e-3",
        "--kv",
        "100",
        "--kt",
        "1",
    ]);
    assert_eq!(o.status.code(), Some(2));
    let o = sim(&[
        "motor",
        "--pole-pairs",
        "2000",
        "--r-ll",
        "1",
        "--l-ll",
        "1e-3",
        "--kv",
        "100",
    ]);
    assert!(
        String::from_utf8_lossy(&o.stderr).contains("pole_pairs"),
        "{o:?}"
    );
}
