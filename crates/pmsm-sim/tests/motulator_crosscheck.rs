//! Cross-check of the plant against a third-party simulator, motulator (PyPI).
//!
//! `tests/data/motulator/gen_motulator_trace.py` (workspace root) drives motulator's
//! synchronous machine and mechanics with an open-loop V/f voltage sequence on the 2.2 kW
//! motor of docs/design.md, "Reference motors" and records, every period, the applied `u_alpha_beta`, the
//! load torque and the machine's currents, speed and angle. This test feeds the same voltages
//! and load to [`Plant`] and compares: the currents and the speed must agree within 1 % RMS of
//! their range over the whole trace (README of that folder: how to regenerate).

use ekf_core::wrap_angle;
use pmsm_sim::plant::{MotorModel, Plant, PlantState};

const TRACE: &str = include_str!("../../../tests/data/motulator/motulator_trace.csv");
const TS: f64 = 250e-6;

/// One fixture row.
struct Row {
    u_ab: [f64; 2],
    load_nm: f64,
    i_ab: [f64; 2],
    w_mech: f64,
    theta: f64,
}

fn rows() -> Vec<Row> {
    let mut lines = TRACE.lines().filter(|l| !l.starts_with('#'));
    let header = lines.next().unwrap_or_default();
    assert_eq!(
        header,
        "k,t_s,u_alpha_v,u_beta_v,load_torque_nm,i_alpha_a,i_beta_a,omega_mech_rad_s,theta_e_rad"
    );
    lines
        .enumerate()
        .map(|(k, l)| {
            let v: Vec<f64> = l
                .split(',')
                .map(|x| x.parse().unwrap_or_else(|e| panic!("row {k}: {x:?}: {e}")))
                .collect();
            assert_eq!(v.len(), 9, "row {k}");
            assert_eq!(v[0] as usize, k);
            Row {
                u_ab: [v[2], v[3]],
                load_nm: v[4],
                i_ab: [v[5], v[6]],
                w_mech: v[7],
                theta: v[8],
            }
        })
        .collect()
}

/// RMS of `a - b` over the range of `b`.
fn rms_of_range(a: &[f64], b: &[f64]) -> f64 {
    let n = b.len() as f64;
    let rms = (a.iter().zip(b).map(|(x, y)| (x - y).powi(2)).sum::<f64>() / n).sqrt();
    let (lo, hi) = b
        .iter()
        .fold((f64::INFINITY, f64::NEG_INFINITY), |(l, h), v| {
            (l.min(*v), h.max(*v))
        });
    rms / (hi - lo)
}

#[test]
fn plant_agrees_with_motulator() {
    let rows = rows();
    assert_eq!(rows.len(), 4000);
    // The 2.2 kW motor of docs/design.md, "Reference motors", with the large friction the fixture's script
    // uses to damp open-loop hunting.
    let motor = MotorModel {
        b_nm_s_rad: 0.1,
        ..MotorModel::industrial_2k2()
    };
    let mut plant = Plant::new(motor, PlantState::default());
    let (mut ia, mut ib, mut w, mut th_err) = (vec![], vec![], vec![], 0.0f64);
    for r in &rows {
        let i = plant.i_ab_a();
        ia.push(i[0]);
        ib.push(i[1]);
        w.push(plant.state().omega_mech_rad_s);
        th_err = th_err.max(wrap_angle(plant.state().theta_e_rad - r.theta).abs());
        plant.step(r.u_ab, r.load_nm, TS);
    }
    let col = |f: fn(&Row) -> f64| rows.iter().map(f).collect::<Vec<_>>();
    let e_ia = rms_of_range(&ia, &col(|r| r.i_ab[0]));
    let e_ib = rms_of_range(&ib, &col(|r| r.i_ab[1]));
    let e_w = rms_of_range(&w, &col(|r| r.w_mech));
    println!(
        "pmsm-sim vs motulator, RMS difference / range: i_alpha {:.3e}, i_beta {:.3e}, \
         speed {:.3e}; max angle difference {:.3e} rad",
        e_ia, e_ib, e_w, th_err
    );
    assert!(e_ia < 0.01 && e_ib < 0.01 && e_w < 0.01);
    // Much tighter in fact: both integrate the same equations accurately.
    assert!(e_ia < 1e-3 && e_ib < 1e-3 && e_w < 1e-3);
}
