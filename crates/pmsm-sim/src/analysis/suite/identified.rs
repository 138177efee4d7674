//! The map an observer of the saturated rows is told when it is told the **identified** map:
//! foc's standstill flux-map measurement (`foc::identify::saturation::SaturationProbe`) run on
//! the motor's saturating plant before the row's run.
//!
//! The probe sits at rest on a fresh plant (the rotor free with the motor's inertia, aligned
//! at 0), told what a self-commissioning of the motor gives: `Rs`, `psi_f` and the
//! small-signal inductances (the plant's own at zero current), the inertia and the pole pairs;
//! the voltage is applied one period after it is computed, the switches are ideal and the
//! currents exact. Its grid spans `+-`[`PROBE_CURRENT`] times the rated current (7 x 9
//! levels); beyond it the map continues linearly (`ekf_core::FluxMap`).

use ekf_core::FluxMap;
use ekf_core::saturation::SaturatedMotor;
use foc::identify::saturation::{SaturationConfig, SaturationProbe};
use foc::{ComputationDelay, TickInput};

use crate::SimError;
use crate::plant::{MotorModel, Plant, PlantState};

/// Largest probe current, times the rated current.
pub const PROBE_CURRENT: f64 = 1.7;

/// The identified map and what its measurement took.
pub struct Identified {
    /// The map, built from the probe's samples.
    pub map: FluxMap<f64, 16>,
    /// Duration of the measurement, s.
    pub duration_s: f64,
    /// Largest rotor movement during it, mechanical rad.
    pub rotor_moved_mech_rad: f64,
}

/// Runs the probe on `m`'s plant (module docs); `i_rated`: the rated current, A.
pub fn identified_map(m: &SaturatedMotor, i_rated: f64) -> Result<Identified, SimError> {
    let r = &m.reference;
    let fail = |problem: String| SimError::Scenario {
        file: format!("suite-{}", r.name),
        field: "identified flux map".into(),
        problem,
    };
    // Small-signal inductances at zero current (what a low-current measurement gives).
    let (pd0, _) = m
        .model
        .flux(0.0, 0.0, (r.psi_f_wb, 0.0))
        .ok_or_else(|| fail("no flux at zero current".into()))?;
    let h = 1e-3;
    let ld0 = m
        .model
        .flux(h, 0.0, (pd0, 0.0))
        .map(|(d, _)| (d - pd0) / h)
        .ok_or_else(|| fail("no d flux".into()))?;
    let lq0 = m
        .model
        .flux(0.0, h, (pd0, 0.0))
        .map(|(_, q)| q / h)
        .ok_or_else(|| fail("no q flux".into()))?;
    let mut plant = Plant::new(MotorModel::from_saturated(m), PlantState::default());
    let ts = r.ts_s;
    let mut cfg = SaturationConfig::new(
        ts as f32,
        r.rs_ohm as f32,
        0.0,
        pd0 as f32,
        (ld0 as f32, lq0 as f32),
        (PROBE_CURRENT * i_rated) as f32,
    );
    cfg.delay = ComputationDelay::OnePeriod;
    cfg.inertia_kg_m2 = r.j_kg_m2 as f32;
    cfg.pole_pairs = r.pole_pairs;
    let mut p = SaturationProbe::new(&cfg).map_err(|e| fail(e.to_string()))?;
    let mut u_prev = [0.0f64; 2];
    let mut moved = 0.0f64;
    let pp = f64::from(r.pole_pairs);
    for _ in 0..(5.0 / ts) as u64 {
        let i = plant.i_ab_a();
        let out = p.tick(&TickInput::alpha_beta(
            i[0] as f32,
            i[1] as f32,
            r.u_dc_v as f32,
        ));
        if p.is_done() {
            break;
        }
        plant.step(u_prev, 0.0, ts);
        u_prev = [f64::from(out.u_ab.alpha), f64::from(out.u_ab.beta)];
        moved = moved.max(plant.state().theta_e_rad.abs() / pp);
    }
    let s = match p.result() {
        Some(Ok(s)) => *s,
        Some(Err(e)) => return Err(fail(e.to_string())),
        None => return Err(fail("the probe did not end within 5 s".into())),
    };
    let i_d: Vec<f64> = s.i_d[..s.n_d].iter().map(|&x| f64::from(x)).collect();
    let i_q: Vec<f64> = s.i_q[..s.n_q].iter().map(|&x| f64::from(x)).collect();
    let grid = |psi: &[[f32; foc::identify::saturation::SAT_MAX_Q]]| -> Vec<f64> {
        psi[..s.n_d]
            .iter()
            .flat_map(|row| row[..s.n_q].iter().map(|&x| f64::from(x)))
            .collect()
    };
    let (pdv, pqv) = (grid(&s.psi_d), grid(&s.psi_q));
    let map = FluxMap::new(&i_d, &i_q, &pdv, &pqv).map_err(|e| fail(e.to_string()))?;
    Ok(Identified {
        map,
        duration_s: f64::from(p.ticks()) * ts,
        rotor_moved_mech_rad: moved,
    })
}
