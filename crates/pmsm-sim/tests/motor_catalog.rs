//! `[motor] catalog = "..."`: a reference motor of `ekf_core::catalog` by name, keys beside it
//! overriding it, `ls_h` for both axes; every preset's motor is its catalog entry.

use pmsm_sim::plant::MotorModel;
use pmsm_sim::scenario::Scenario;

fn with_motor(motor: &str) -> Result<Scenario, String> {
    let preset = Scenario::preset_text("servo-ideal").expect("preset");
    let start = preset.find("[motor]").expect("motor table");
    let end = start + 1 + preset[start + 1..].find("\n[").expect("next table");
    let text = format!("{}[motor]\n{motor}\n{}", &preset[..start], &preset[end..]);
    Scenario::from_toml_str(&text, "test.toml").map_err(|e| e.to_string())
}

#[test]
fn catalog_names_resolve_and_keys_override() {
    let sc = with_motor("catalog = \"servo\"").unwrap();
    assert_eq!(sc.motor, MotorModel::servo());
    let sc = with_motor("catalog = \"industrial-ipm\"\nrs_ohm = 4.0\ncoulomb_nm = 0.1").unwrap();
    assert_eq!(sc.motor.rs_ohm, 4.0);
    assert_eq!(sc.motor.lq_h, 42e-3);
    assert_eq!(sc.motor.coulomb_nm, 0.1);
    // ls_h sets both axes; an axis given beside it wins.
    let sc = with_motor("catalog = \"servo\"\nls_h = 9e-3\nlq_h = 1e-2").unwrap();
    assert_eq!((sc.motor.ld_h, sc.motor.lq_h), (9e-3, 1e-2));
}

#[test]
fn unknown_names_and_missing_keys_are_named() {
    let e = with_motor("catalog = \"servo2\"").unwrap_err();
    assert!(
        e.contains("servo2") && e.contains("known: servo, industrial_2k2"),
        "{e}"
    );
    let e = with_motor("rs_ohm = 1.0\nls_h = 1e-3\npsi_f_wb = 0.1\npole_pairs = 2\nj_kg_m2 = 1e-4")
        .unwrap_err();
    assert!(e.contains("motor.b_nm_s_rad is missing"), "{e}");
    let e = with_motor("catalog = \"servo\"\nrs = 1.0").unwrap_err();
    assert!(e.contains("rs"), "{e}");
}

#[test]
fn written_out_scenarios_list_the_resolved_values() {
    let sc = with_motor("catalog = \"drone\"").unwrap_err();
    assert!(sc.contains("drone"), "{sc}");
    let sc = with_motor("catalog = \"small_fast\"").unwrap();
    let text = toml::to_string(&sc).unwrap();
    assert!(
        text.contains("rs_ohm = 0.12") && !text.contains("catalog"),
        "{text}"
    );
}
