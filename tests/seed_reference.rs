//! The seed's filter (`ForwardEuler`, seed Q/R, standard covariance update) against an
//! independent numpy implementation of the same equations (`data/gen_seed_reference.py`,
//! cross-checked there with filterpy), on 2500 samples of a spinning, loaded servo motor.
//!
//! Requirement: 1e-9 relative in f64 (per column, `max |a - b| / max |b|`, wrapped for the
//! angle), and 1e-3 rad on the angle in f32.

use ekf_core::nalgebra::{Matrix4, Vector4};
use ekf_core::{
    Discretization, Float, MotorParams, NoiseCovariances, ObserverConfig, PmsmObserver,
};

const CSV: &str = include_str!("data/seed_reference.csv");

struct Fixture {
    rs: f64,
    ls: f64,
    psi: f64,
    pole_pairs: u32,
    ts: f64,
    q: [f64; 4],
    r: [f64; 2],
    x0: [f64; 4],
    p0: [f64; 4],
    rows: Vec<Row>,
}

/// `u, z` in; `x, p_diag, nis` expected.
struct Row {
    u: [f64; 2],
    z: [f64; 2],
    x: [f64; 4],
    p_diag: [f64; 4],
    nis: f64,
}

fn floats<const N: usize>(list: &str) -> [f64; N] {
    let v: Vec<f64> = list.split(',').map(|s| s.parse().expect("float")).collect();
    v.try_into().expect("length")
}

fn parse() -> Fixture {
    let mut kv = std::collections::HashMap::new();
    let mut rows = Vec::new();
    let mut header_seen = false;
    for line in CSV.lines() {
        if let Some(meta) = line.strip_prefix('#') {
            for item in meta.split_whitespace() {
                if let Some((k, v)) = item.split_once('=') {
                    kv.insert(k.to_string(), v.to_string());
                }
            }
        } else if !header_seen {
            assert!(
                line.starts_with("k,u_a,u_b,z_a,z_b,i_a,i_b,w,th,p00"),
                "header: {line}"
            );
            header_seen = true;
        } else if !line.is_empty() {
            let f: Vec<f64> = line.split(',').map(|s| s.parse().expect("float")).collect();
            assert_eq!(f.len(), 16, "row {line}");
            rows.push(Row {
                u: [f[1], f[2]],
                z: [f[3], f[4]],
                x: [f[5], f[6], f[7], f[8]],
                p_diag: [f[9], f[10], f[11], f[12]],
                nis: f[13],
            });
        }
    }
    let scalar = |k: &str| -> f64 { kv[k].parse().expect("scalar") };
    Fixture {
        rs: scalar("rs"),
        ls: scalar("ls"),
        psi: scalar("psi_f"),
        pole_pairs: kv["pole_pairs"].parse().expect("pole pairs"),
        ts: scalar("ts"),
        q: floats(&kv["q"]),
        r: floats(&kv["r"]),
        x0: floats(&kv["x0"]),
        p0: floats(&kv["p0"]),
        rows,
    }
}

fn wrap(d: f64) -> f64 {
    ekf_core::wrap_angle(d)
}

/// Runs the crate's seed filter over the fixture in precision `T`; returns per-row
/// `(x, p_diag, nis)` in f64.
fn run<T: Float + Into<f64>>(
    fx: &Fixture,
    conv: impl Fn(f64) -> T,
) -> Vec<([f64; 4], [f64; 4], f64)> {
    let motor = MotorParams {
        rs_ohm: conv(fx.rs),
        ld_h: conv(fx.ls),
        lq_h: conv(fx.ls),
        psi_f_wb: conv(fx.psi),
        pole_pairs: fx.pole_pairs,
    };
    let mut cfg = ObserverConfig::seed(motor, conv(fx.ts));
    assert_eq!(cfg.discretization, Discretization::ForwardEuler);
    // The fixture's header states the seed's Q and R; the preset must be exactly those.
    let seed = NoiseCovariances::<f64>::seed();
    for i in 0..4 {
        assert_eq!(seed.q[(i, i)], fx.q[i]);
    }
    for i in 0..2 {
        assert_eq!(seed.r[(i, i)], fx.r[i]);
    }
    cfg.x0 = Vector4::from(fx.x0.map(&conv));
    cfg.p0 = Matrix4::from_diagonal(&Vector4::from(fx.p0.map(&conv)));
    let mut obs = PmsmObserver::new(&cfg).expect("valid seed configuration");
    let mut u_prev = [conv(0.0), conv(0.0)];
    fx.rows
        .iter()
        .map(|row| {
            let est = obs.step(u_prev, row.z.map(&conv)).expect("finite step");
            u_prev = row.u.map(&conv);
            let x = obs.state();
            let p = obs.covariance();
            (
                [x[0].into(), x[1].into(), x[2].into(), x[3].into()],
                [
                    p[(0, 0)].into(),
                    p[(1, 1)].into(),
                    p[(2, 2)].into(),
                    p[(3, 3)].into(),
                ],
                est.nis.into(),
            )
        })
        .collect()
}

/// Per-column `max |a - b| / max |b|`; the angle column (3) compares wrapped differences.
fn column_rel_errors(fx: &Fixture, out: &[([f64; 4], [f64; 4], f64)]) -> [f64; 9] {
    let mut max_diff = [0.0f64; 9];
    let mut max_ref = [0.0f64; 9];
    for (row, (x, p, nis)) in fx.rows.iter().zip(out) {
        for c in 0..4 {
            let d = if c == 3 {
                wrap(x[c] - row.x[c])
            } else {
                x[c] - row.x[c]
            };
            max_diff[c] = max_diff[c].max(d.abs());
            max_ref[c] = max_ref[c].max(row.x[c].abs());
            max_diff[4 + c] = max_diff[4 + c].max((p[c] - row.p_diag[c]).abs());
            max_ref[4 + c] = max_ref[4 + c].max(row.p_diag[c].abs());
        }
        max_diff[8] = max_diff[8].max((nis - row.nis).abs());
        max_ref[8] = max_ref[8].max(row.nis.abs());
    }
    core::array::from_fn(|i| max_diff[i] / max_ref[i])
}

#[test]
fn fixture_is_long_and_spinning() {
    let fx = parse();
    assert!(fx.rows.len() >= 2000, "{} rows", fx.rows.len());
    // A spinning motor: the reference speed estimate stays well away from zero.
    assert!(fx.rows.iter().all(|r| r.x[2] > 200.0));
}

#[test]
fn seed_filter_f64_matches_reference_to_1e_9() {
    let fx = parse();
    let out = run::<f64>(&fx, |v| v);
    let rel = column_rel_errors(&fx, &out);
    let names = ["i_a", "i_b", "w", "th", "p00", "p11", "p22", "p33", "nis"];
    for (name, e) in names.iter().zip(rel) {
        println!("f64 {name}: max relative difference {e:.3e}");
        assert!(e < 1e-9, "{name}: relative difference {e:e} exceeds 1e-9");
    }
}

#[test]
fn seed_filter_f32_matches_reference_angle_to_1e_3_rad() {
    let fx = parse();
    let out = run::<f32>(&fx, |v| v as f32);
    let max_angle = fx
        .rows
        .iter()
        .zip(&out)
        .map(|(row, (x, _, _))| wrap(x[3] - row.x[3]).abs())
        .fold(0.0f64, f64::max);
    let rel = column_rel_errors(&fx, &out);
    println!(
        "f32 angle: max |difference| {max_angle:.3e} rad; speed relative {:.3e}",
        rel[2]
    );
    assert!(max_angle < 1e-3, "f32 angle differs by {max_angle} rad");
    assert!(rel[2] < 1e-3, "f32 speed relative difference {}", rel[2]);
}
