//! Property test over every scenario key: each numeric value of a scenario that sets every
//! key (every optional one, every load and fault kind) is replaced in turn by NaN, +-inf,
//! +-1e300, 0 and -1, written to a file and given to `pmsm-sim check` and `pmsm-sim run`.
//! Each outcome must be one of two: exit 0 with a completed run (metrics.json, plot.svg and a
//! finished run.mcap), or exit 1 with the key named on stderr and no output left. Never a
//! panic (exit 101), a signal, or a run that stops on a non-finite plant (exit 2).
//!
//! The keys are not listed here: they are found by walking the scenario serialized as a TOML
//! table. The full scenario is built with struct literals (a new field does not compile until
//! it is given a value here), every optional key that is unset somewhere is set elsewhere,
//! and its load and fault terms cover every kind serde knows (read from serde's own
//! "unknown variant" message).

use std::collections::BTreeSet;
use std::path::{Path, PathBuf};
use std::process::Command;
use std::time::Instant;

use pmsm_sim::plant::fault_injection::{Channel, Channels, FaultSpec, Phase};
use pmsm_sim::plant::load::{Interpolation, LoadTerm};
use pmsm_sim::scenario::{
    FieldWeakeningSettings, FocSettings, ObserverLoss, ObserverNoise, ObserverSettings,
    RPM_PER_RAD_S, ReversalMode, Scenario, SkippedCycles, StartupTiming,
};

const BIN: &str = env!("CARGO_BIN_EXE_pmsm-sim");

/// Simulated time of every run: 20 periods of 0.1 ms.
const DURATION_S: f64 = 2e-3;

/// The default scenario with every key set (module docs).
fn full_scenario() -> Scenario {
    let mut sc = Scenario::default_servo().with_duration(DURATION_S);
    let m = sc.motor.clone();
    sc.motor.coulomb_nm = 0.01;
    sc.motor.emf_harmonics.h5 = 0.01;
    sc.motor.emf_harmonics.h5_phase_rad = 0.1;
    sc.motor.emf_harmonics.h7 = 0.01;
    sc.motor.emf_harmonics.h7_phase_rad = 0.2;
    sc.initial.theta_e_rad = 0.1;
    sc.initial.speed_rpm = 10.0;
    sc.inverter.delay = true;
    sc.inverter.delay_periods = Some(1.0);
    sc.inverter.ripple_fraction = 0.02;
    sc.inverter.ripple_hz = 300.0;
    sc.sensors.current_noise_std_a = 0.01;
    sc.sensors.gain_error = [0.01, -0.01];
    sc.sensors.offset_a = [0.01, -0.01];
    sc.sensors.adc_bits = 12;
    sc.sensors.adc_full_scale_a = 20.0;
    let cfg = sc.foc_config().unwrap_or_else(|e| panic!("{e}"));
    let rpm = |w_e: f32| f64::from(w_e) / m.p() * RPM_PER_RAD_S;
    let limit = sc.controller.current_limit_a;
    sc.controller.delay_compensation = Some(true);
    sc.controller.foc = Some(FocSettings {
        u_dc_nominal_v: Some(sc.inverter.u_dc_v),
        inertia_kg_m2: Some(m.j_kg_m2),
        start_time_s: 0.0,
        stop_time_s: Some(1.5e-3),
        over_current_a: Some(2.0 * limit),
        align_time_s: Some(0.5e-3),
        align_current_a: Some(0.5 * limit),
        if_current_a: Some(0.5 * limit),
        handover_speed_rpm: Some(rpm(cfg.startup.handover_speed_rad_s)),
        startup_accel_rpm_per_s: Some(rpm(cfg.startup.accel_rad_s2)),
        startup_damping_ratio: Some(1.0),
        startup_kick_speed_ratio: Some(f64::from(cfg.startup.kick_speed_ratio)),
        observer_loss: ObserverLoss::FallBack,
        reversal: ReversalMode::ClosedLoop,
        startup_timing: StartupTiming::Motor,
        exit_speed_ratio: Some(0.7),
        dead_time_s: Some(sc.inverter.dead_time_s),
        dead_time_band_a: Some(0.02 * limit),
        mtpa: Some(true),
        field_weakening: Some(FieldWeakeningSettings {
            enabled: true,
            voltage_margin: Some(0.95),
            bandwidth_hz: Some(0.1 * sc.controller.current_bandwidth_hz),
            max_negative_id_a: Some(0.5 * limit),
        }),
        max_speed_rpm: Some(2.0 * sc.rated_speed_rpm),
    });
    sc.observer = ObserverSettings {
        reference_filter: true,
        rs_ohm: Some(m.rs_ohm),
        ls_h: Some(m.ld_h),
        ld_h: Some(m.ld_h),
        lq_h: Some(m.lq_h),
        psi_f_wb: Some(m.psi_f_wb),
        angle_sigma_limit_rad: Some(0.2),
    };
    let t = 1e-3;
    sc.load = vec![
        LoadTerm::Constant { torque_nm: 0.01 },
        LoadTerm::Step {
            time_s: t,
            before_nm: 0.0,
            after_nm: 0.1,
        },
        LoadTerm::Ramp {
            start_s: 0.5e-3,
            end_s: t,
            from_nm: 0.0,
            to_nm: 0.1,
        },
        LoadTerm::Viscous {
            coefficient_nm_s_rad: 1e-4,
        },
        LoadTerm::Fan {
            coefficient_nm_s2_rad2: 1e-6,
        },
        LoadTerm::ConstantPower {
            power_w: 10.0,
            max_torque_nm: 0.1,
            start_s: 0.0,
            ramp_s: t,
        },
        LoadTerm::Table {
            interpolation: Interpolation::Step,
            points: vec![(0.0, 0.0), (t, 0.1)],
        },
    ];
    sc.faults = vec![
        FaultSpec::OffsetDrift {
            t_s: t,
            duration_s: Some(t),
            channel: Channel::A,
            rate_a_per_s: 1.0,
        },
        FaultSpec::GainStep {
            t_s: t,
            duration_s: Some(t),
            channel: Channel::B,
            gain_error: 0.1,
        },
        FaultSpec::Stuck {
            t_s: t,
            duration_s: Some(t),
            channel: Channel::A,
            value_a: Some(0.5),
        },
        FaultSpec::Dropout {
            t_s: t,
            duration_s: Some(1e-4),
            channel: Channels::Both,
        },
        FaultSpec::NoiseBurst {
            t_s: t,
            duration_s: Some(t),
            std_a: 0.1,
        },
        FaultSpec::Glitch {
            t_s: t,
            channel: Channel::B,
            value_a: Some(5.0),
        },
        FaultSpec::BusSag {
            t_s: t,
            duration_s: Some(t),
            fraction: 0.2,
        },
        FaultSpec::PhaseOpen {
            t_s: 1.9e-3,
            duration_s: Some(1e-4),
            phase: Phase::C,
        },
        FaultSpec::ParamDrift {
            t_s: t,
            duration_s: Some(t),
            time_constant_s: None,
            temperature_rise_k: 50.0,
            rs_per_k: 0.00393,
            psi_f_per_k: -0.0012,
        },
        FaultSpec::ParamDrift {
            t_s: t,
            duration_s: None,
            time_constant_s: Some(t),
            temperature_rise_k: 50.0,
            rs_per_k: 0.00393,
            psi_f_per_k: -0.0012,
        },
        FaultSpec::LockedRotor {
            t_s: 1.8e-3,
            duration_s: Some(1e-4),
        },
        FaultSpec::Overload {
            t_s: t,
            duration_s: Some(t),
            torque_nm: 0.5,
        },
    ];
    sc.skipped_cycles = SkippedCycles {
        probability: 0.05,
        times_s: vec![t],
    };
    let noise = sc.observer_config().noise;
    sc.observer_noise = Some(ObserverNoise {
        q: core::array::from_fn(|r| core::array::from_fn(|c| noise.q[(r, c)])),
        r: core::array::from_fn(|r| core::array::from_fn(|c| noise.r[(r, c)])),
        sigma_z: Some([0.01, 0.01]),
        rho_z: Some(0.0),
        sigma_i: Some(0.01),
        sigma_w: Some(0.01),
        sigma_th: Some(0.01),
    });
    sc
}

/// One step of a key's path.
#[derive(Clone, Debug)]
enum Seg {
    Key(String),
    Index(usize),
}

fn path_text(path: &[Seg]) -> String {
    let mut s = String::new();
    for seg in path {
        match seg {
            Seg::Key(k) if s.is_empty() => s.push_str(k),
            Seg::Key(k) => {
                s.push('.');
                s.push_str(k);
            }
            Seg::Index(i) => s.push_str(&format!("[{i}]")),
        }
    }
    s
}

/// The key as an error must name it: the path up to its last named segment
/// (`speed_ref_rpm.points[2][1]` -> `speed_ref_rpm.points`).
fn named_key(path: &[Seg]) -> String {
    let last = path
        .iter()
        .rposition(|s| matches!(s, Seg::Key(_)))
        .unwrap_or(0);
    path_text(&path[..=last])
}

/// Every numeric leaf `(path, is_integer)` under `v`.
fn numeric_leaves(v: &toml::Value, path: &mut Vec<Seg>, out: &mut Vec<(Vec<Seg>, bool)>) {
    match v {
        toml::Value::Integer(_) => out.push((path.clone(), true)),
        toml::Value::Float(_) => out.push((path.clone(), false)),
        toml::Value::Table(t) => {
            for (k, x) in t {
                path.push(Seg::Key(k.clone()));
                numeric_leaves(x, path, out);
                path.pop();
            }
        }
        toml::Value::Array(a) => {
            for (i, x) in a.iter().enumerate() {
                path.push(Seg::Index(i));
                numeric_leaves(x, path, out);
                path.pop();
            }
        }
        _ => {}
    }
}

fn set(v: &mut toml::Value, path: &[Seg], new: toml::Value) {
    let mut at = v;
    for seg in path {
        at = match (seg, at) {
            (Seg::Key(k), toml::Value::Table(t)) => t.get_mut(k).expect("key"),
            (Seg::Index(i), toml::Value::Array(a)) => &mut a[*i],
            _ => panic!("bad path {}", path_text(path)),
        };
    }
    *at = new;
}

/// Keys (indices dropped) whose value is `null` in the JSON form of `v`, and those set.
fn null_and_set_keys(
    v: &serde_json::Value,
    path: &str,
    null: &mut BTreeSet<String>,
    set: &mut BTreeSet<String>,
) {
    match v {
        serde_json::Value::Null => {
            null.insert(path.to_string());
        }
        serde_json::Value::Object(o) => {
            for (k, x) in o {
                let p = if path.is_empty() {
                    k.clone()
                } else {
                    format!("{path}.{k}")
                };
                null_and_set_keys(x, &p, null, set);
            }
        }
        serde_json::Value::Array(a) => {
            for x in a {
                null_and_set_keys(x, path, null, set);
            }
        }
        _ => {
            set.insert(path.to_string());
        }
    }
}

/// The kinds serde accepts for a tagged table array (`load`, `faults`), from its
/// "unknown variant" message.
fn kinds_serde_knows(table: &str) -> BTreeSet<String> {
    let text = format!(
        "{}\n[[{table}]]\nkind = \"no_such_kind\"\n",
        Scenario::preset_text("default").unwrap_or_default()
    );
    let e = match Scenario::from_toml_str(&text, "kinds") {
        Err(e) => e.to_string(),
        Ok(_) => panic!("an unknown {table} kind was accepted"),
    };
    let list = e
        .split("expected one of ")
        .nth(1)
        .unwrap_or_else(|| panic!("no variant list in {e}"));
    let list = list.split(" (line").next().unwrap_or_default();
    list.split(',')
        .map(|s| {
            s.trim()
                .trim_matches(|c: char| !c.is_ascii_alphanumeric() && c != '_')
        })
        .filter(|s| !s.is_empty())
        .map(|s| s.to_string())
        .collect()
}

#[test]
fn the_full_scenario_sets_every_key_and_kind() {
    let sc = full_scenario();
    let json = serde_json::to_value(&sc).unwrap_or_else(|e| panic!("{e}"));
    let (mut null, mut set) = (BTreeSet::new(), BTreeSet::new());
    null_and_set_keys(&json, "", &mut null, &mut set);
    let missing: Vec<_> = null.difference(&set).collect();
    assert!(missing.is_empty(), "keys never set: {missing:?}");
    let load: BTreeSet<String> = sc
        .load
        .iter()
        .map(|l| {
            let v = serde_json::to_value(l).unwrap_or_default();
            v["kind"].as_str().unwrap_or_default().to_string()
        })
        .collect();
    assert_eq!(load, kinds_serde_knows("load"));
    let faults: BTreeSet<String> = sc.faults.iter().map(|f| f.kind().to_string()).collect();
    assert_eq!(faults, kinds_serde_knows("faults"));
}

/// What one CLI call did wrong, if anything.
fn judge(what: &str, key: &str, out: &std::process::Output, dir: Option<&Path>) -> Option<String> {
    let stderr = String::from_utf8_lossy(&out.stderr);
    let left: Vec<PathBuf> = dir
        .and_then(|d| std::fs::read_dir(d).ok())
        .map(|r| r.filter_map(|e| e.ok().map(|e| e.path())).collect())
        .unwrap_or_default();
    match out.status.code() {
        Some(0) => {
            if let Some(d) = dir {
                for f in ["metrics.json", "plot.svg", "run.mcap"] {
                    let ok = std::fs::metadata(d.join(f)).is_ok_and(|m| m.len() > 0);
                    if !ok {
                        return Some(format!("{what}: exit 0 without {f}"));
                    }
                }
            }
            None
        }
        Some(1) if !stderr.contains(key) => {
            Some(format!("{what}: exit 1 without naming {key}: {stderr}"))
        }
        Some(1) if !left.is_empty() => Some(format!("{what}: exit 1 left {left:?}: {stderr}")),
        Some(1) if stderr.contains("panicked") => Some(format!("{what}: {stderr}")),
        Some(1) => None,
        code => Some(format!("{what}: exit {code:?}: {stderr}")),
    }
}

#[test]
fn every_key_with_every_bad_number_is_refused_by_name_or_runs() {
    let started = Instant::now();
    let base = toml::Value::try_from(full_scenario()).unwrap_or_else(|e| panic!("{e}"));
    let mut leaves = Vec::new();
    numeric_leaves(&base, &mut Vec::new(), &mut leaves);
    let floats = [
        f64::NAN,
        f64::INFINITY,
        f64::NEG_INFINITY,
        1e300,
        -1e300,
        0.0,
        -1.0,
    ];
    let mut cases: Vec<(String, String, String)> = Vec::new();
    for (path, integer) in &leaves {
        for x in floats {
            let new = if *integer && (x == 0.0 || x == -1.0) {
                toml::Value::Integer(x as i64)
            } else {
                toml::Value::Float(x)
            };
            let mut v = base.clone();
            set(&mut v, path, new.clone());
            let text = toml::to_string(&v).unwrap_or_else(|e| panic!("{e}"));
            let what = format!("{} = {x:?}", path_text(path));
            cases.push((what, named_key(path), text));
        }
    }
    let root = std::env::temp_dir().join(format!("pmsm-sim-keys-{}", std::process::id()));
    let _ = std::fs::remove_dir_all(&root);
    std::fs::create_dir_all(&root).unwrap_or_else(|e| panic!("{e}"));
    // The unchanged full scenario checks and runs.
    let text = toml::to_string(&base).unwrap_or_else(|e| panic!("{e}"));
    let file = root.join("full.toml");
    std::fs::write(&file, text).unwrap_or_else(|e| panic!("{e}"));
    let out = Command::new(BIN)
        .args(["run"])
        .arg(&file)
        .arg("--out")
        .arg(root.join("full"))
        .output()
        .unwrap_or_else(|e| panic!("{e}"));
    assert!(
        out.status.success(),
        "{}",
        String::from_utf8_lossy(&out.stderr)
    );

    let threads = std::thread::available_parallelism()
        .map_or(2, |n| n.get())
        .min(4);
    let failures: Vec<String> = std::thread::scope(|s| {
        let handles: Vec<_> = (0..threads)
            .map(|t| {
                let (cases, root) = (&cases, &root);
                s.spawn(move || {
                    let mut bad = Vec::new();
                    for (i, (what, key, text)) in cases.iter().enumerate().skip(t).step_by(threads)
                    {
                        let file = root.join(format!("case{i}.toml"));
                        let dir = root.join(format!("out{i}"));
                        std::fs::write(&file, text).unwrap_or_else(|e| panic!("{e}"));
                        let check = Command::new(BIN).arg("check").arg(&file).output();
                        let check = check.unwrap_or_else(|e| panic!("{e}"));
                        bad.extend(judge(&format!("check {what}"), key, &check, None));
                        let run = Command::new(BIN)
                            .arg("run")
                            .arg(&file)
                            .arg("--out")
                            .arg(&dir)
                            .output()
                            .unwrap_or_else(|e| panic!("{e}"));
                        bad.extend(judge(&format!("run {what}"), key, &run, Some(&dir)));
                        let _ = std::fs::remove_dir_all(&dir);
                        let _ = std::fs::remove_file(&file);
                    }
                    bad
                })
            })
            .collect();
        handles
            .into_iter()
            .flat_map(|h| h.join().unwrap_or_else(|_| vec!["thread panicked".into()]))
            .collect()
    });
    let _ = std::fs::remove_dir_all(&root);
    println!(
        "{} keys x {} values: {} cases in {:.1} s",
        leaves.len(),
        floats.len(),
        cases.len(),
        started.elapsed().as_secs_f64()
    );
    assert!(
        failures.is_empty(),
        "{} of {} cases failed:\n{}",
        failures.len(),
        cases.len(),
        failures.join("\n")
    );
}
