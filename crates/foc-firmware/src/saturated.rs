//! The cost of a flux map on the MCU: `FluxMap::eval` (fluxes and incremental inductances,
//! bicubic Hermite) on the servo run's currents. (The map observer of
//! `ekf_core::saturated` runs on the generic `Ekf`; counted here it would share, and change,
//! the generic step's code that the `ekf_step_generic` row measures. Its step measured
//! 2286 instructions.)
//!
//! The map is a saturating variant of the catalog's servo made here in `f32` only (no `f64` on
//! the MCU): `psi_d = psi_f + Ld i_d / (1 + |i_d| / 20)`, `psi_q = Lq i_q / (1 + |i_q| / 20)`
//! on a 9 x 11 grid over +-20 A. Only the cost is checked here: the run's motor has constant
//! inductances, so the map observer's angle is not scored against it.

use core::hint::black_box;

use ekf_core::catalog::SERVO;
use ekf_core::fluxmap::FluxMap;

use crate::meter::{Clock, Tally};
use crate::synth::{SAMPLES, Sample};

/// Grid capacity per axis.
const N: usize = 12;

fn map() -> Result<FluxMap<f32, N>, &'static str> {
    let (ld, lq, psi) = (SERVO.ld_h as f32, SERVO.lq_h as f32, SERVO.psi_f_wb as f32);
    let mut i_d = [0.0f32; 9];
    let mut i_q = [0.0f32; 11];
    for (k, x) in i_d.iter_mut().enumerate() {
        *x = -20.0 + 40.0 * k as f32 / 8.0;
    }
    for (k, x) in i_q.iter_mut().enumerate() {
        *x = -20.0 + 40.0 * k as f32 / 10.0;
    }
    let mut psi_d = [0.0f32; 99];
    let mut psi_q = [0.0f32; 99];
    for (a, &d) in i_d.iter().enumerate() {
        for (b, &q) in i_q.iter().enumerate() {
            psi_d[a * 11 + b] = psi + ld * d / (1.0 + d.abs() / 20.0);
            psi_q[a * 11 + b] = lq * q / (1.0 + q.abs() / 20.0);
        }
    }
    FluxMap::new(&i_d, &i_q, &psi_d, &psi_q).map_err(|_| "flux map refused")
}

/// Counts `fluxmap_eval` over the run.
pub fn run(clock: &Clock, data: &[Sample; SAMPLES]) -> Result<(), &'static str> {
    let map = map()?;
    let mut eval = Tally::new();
    let mut out = map.eval(0.0, 0.0);
    for s in data.iter() {
        let (sn, cs) = ekf_core::trig::sin_cos_f32(s.theta_rad);
        let (id, iq) = (cs * s.i[0] + sn * s.i[1], cs * s.i[1] - sn * s.i[0]);
        eval.push(clock.count(&mut || out = map.eval(id, iq)));
        black_box(out);
    }
    eval.report("fluxmap_eval");

    Ok(())
}
