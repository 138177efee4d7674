//! The cost of a flux map on the MCU:
//! - `fluxmap_eval`: `FluxMap::eval` (fluxes and incremental inductances, bicubic Hermite) on
//!   the servo run's currents, on a saturating variant of the catalog's servo made here in
//!   `f32` only (no `f64` on the MCU): `psi_d = psi_f + Ld i_d / (1 + |i_d| / 20)`,
//!   `psi_q = Lq i_q / (1 + |i_q| / 20)` on a 9 x 11 grid over +-20 A;
//! - `map_observer_step`: one step of `ekf_core::saturated::MapObserver` (its default
//!   configuration: the constant-parameter observer's safeguards, no parameter tracking) on
//!   the servo run, told the servo itself as a 9 x 11 map (`psi_d = psi_f + Ld i_d`,
//!   `psi_q = Lq i_q`), so that its angle is checked as the other observers' are (within 1 deg
//!   over the run's last samples). The evaluation's cost does not depend on the values;
//! - `map_observer_step_offset`: the same with the flux-offset tracking on
//!   (`FluxOffsetTracking::new`).

use core::hint::black_box;

use cortex_m_semihosting::hprintln;
use ekf_core::EkfError;
use ekf_core::catalog::SERVO;
use ekf_core::fluxmap::FluxMap;
use ekf_core::saturated::{FluxOffsetTracking, MapObserver};

use crate::meter::{Clock, Tally};
use crate::synth::TS_S;
use crate::synth::{SAMPLES, Sample};
use crate::{CHECK_WINDOW, angle_err_deg};

/// Grid capacity per axis.
const N: usize = 12;

/// The servo's fluxes on a 9 x 11 grid over +-20 A, saturating (`saturating`, module docs) or
/// linear.
fn map(saturating: bool) -> Result<FluxMap<f32, N>, &'static str> {
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
            let (kd, kq) = if saturating {
                (1.0 + d.abs() / 20.0, 1.0 + q.abs() / 20.0)
            } else {
                (1.0, 1.0)
            };
            psi_d[a * 11 + b] = psi + ld * d / kd;
            psi_q[a * 11 + b] = lq * q / kq;
        }
    }
    FluxMap::new(&i_d, &i_q, &psi_d, &psi_q).map_err(|_| "flux map refused")
}

/// Counts `fluxmap_eval` and `map_observer_step` over the run; an error when the map
/// observer misses the angle.
pub fn run(clock: &Clock, data: &[Sample; SAMPLES]) -> Result<(), &'static str> {
    let sat = map(true)?;
    let mut eval = Tally::new();
    let mut out = sat.eval(0.0, 0.0);
    for s in data.iter() {
        let (sn, cs) = ekf_core::trig::sin_cos_f32(s.theta_rad);
        let (id, iq) = (cs * s.i[0] + sn * s.i[1], cs * s.i[1] - sn * s.i[0]);
        eval.push(clock.count(&mut || out = sat.eval(id, iq)));
        black_box(out);
    }
    eval.report("fluxmap_eval");

    observer_run(clock, data, false, "map_observer_step")?;
    observer_run(clock, data, true, "map_observer_step_offset")
}

/// Counts the map observer's step over the run under `name`, with the flux-offset tracking
/// (`FluxOffsetTracking::new`) when `offset`; an error when it misses the angle.
fn observer_run(
    clock: &Clock,
    data: &[Sample; SAMPLES],
    offset: bool,
    name: &str,
) -> Result<(), &'static str> {
    let linear = map(false)?;
    let cfg = MapObserver::default_config(&linear, SERVO.rs_ohm as f32, SERVO.pole_pairs, TS_S);
    let mut obs = MapObserver::new(&cfg, linear).map_err(|_| "map observer refused")?;
    if offset {
        obs.set_flux_offset_tracking(Some(FluxOffsetTracking::new()))
            .map_err(|_| "flux-offset tracking refused")?;
    }
    let mut step = Tally::new();
    let mut u_prev = [0.0f32; 2];
    let mut max_err = 0.0f32;
    for (k, s) in data.iter().enumerate() {
        let mut out = Err(EkfError::NonFiniteResult);
        step.push(clock.count(&mut || out = obs.step(u_prev, s.i)));
        u_prev = s.u;
        let e = out.map_err(|_| "map observer step refused")?;
        if k + CHECK_WINDOW >= SAMPLES {
            max_err = max_err.max(angle_err_deg(e.theta_rad, s.theta_rad).abs());
        }
    }
    step.report(name);
    hprintln!(
        "    {}: max |angle error| {} deg over the last {} samples",
        name,
        max_err,
        CHECK_WINDOW
    );
    if max_err > 1.0 {
        return Err("map observer: angle error above 1 deg");
    }
    Ok(())
}
