//! foc's standstill flux-map measurement (`foc::identify::saturation::SaturationProbe`) on a
//! saturating motor's plant: [`probe_plant`] runs it, [`identified_map`] gives the map an
//! observer of the saturated rows is told when it is told the **identified** map.
//!
//! The probe sits at rest on a fresh plant (the rotor free with the motor's inertia, at the
//! given angle), told what a self-commissioning of the motor gives ([`ProbeTold`]: `Rs`,
//! `psi_f`, the small-signal inductances, the inertia, as factors on the motor's values) and
//! the pole pairs; the voltage is applied one period after it is computed, the switches are
//! ideal, the currents exact or with uniform noise. For the suite's rows its grid spans
//! `+-`[`PROBE_CURRENT`] times the rated current (7 x 9 levels); beyond it the map continues
//! linearly (`ekf_core::FluxMap`).

use ekf_core::FluxMap;
use ekf_core::saturation::SaturatedMotor;
use foc::identify::saturation::{FluxSamples, SAT_MAX_Q, SaturationConfig, SaturationProbe};
use foc::{ComputationDelay, TickInput};

use crate::SimError;
use crate::plant::{MotorModel, Plant, PlantState};

/// Largest probe current of the suite's rows, times the rated current.
pub const PROBE_CURRENT: f64 = 1.7;

/// What the probe is told, as factors on the motor's values, and the current sensors' noise.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct ProbeTold {
    /// Factor on `Rs`.
    pub rs: f64,
    /// Factor on the small-signal `Ld` and `Lq`.
    pub l: f64,
    /// Factor on `psi_f`.
    pub psi_f: f64,
    /// Factor on the inertia.
    pub j: f64,
    /// Uniform current noise, +- A.
    pub noise_a: f64,
}

impl ProbeTold {
    /// The motor's own values, no noise.
    pub const EXACT: Self = Self {
        rs: 1.0,
        l: 1.0,
        psi_f: 1.0,
        j: 1.0,
        noise_a: 0.0,
    };
}

/// What one probe run measured.
#[derive(Clone, Copy, Debug)]
pub struct ProbeRun {
    /// The samples.
    pub samples: FluxSamples,
    /// Duration of the measurement, s.
    pub duration_s: f64,
    /// Largest rotor movement during it, mechanical rad.
    pub rotor_moved_mech_rad: f64,
    /// Largest current magnitude, A.
    pub peak_a: f64,
}

/// Runs the probe (module docs) on `m`'s plant with the rotor at `theta0_rad` (electrical),
/// up to `i_max_a`.
pub fn probe_plant(
    m: &SaturatedMotor,
    i_max_a: f64,
    theta0_rad: f64,
    told: &ProbeTold,
) -> Result<ProbeRun, SimError> {
    let r = &m.reference;
    let fail = |problem: String| SimError::Scenario {
        file: format!("flux-map probe {}", r.name),
        field: "identified flux map".into(),
        problem,
    };
    let mut plant = Plant::new(
        MotorModel::from_saturated(m),
        PlantState {
            theta_e_rad: theta0_rad,
            ..PlantState::default()
        },
    );
    let ts = r.ts_s;
    let mut cfg = SaturationConfig::new(
        ts as f32,
        (r.rs_ohm * told.rs) as f32,
        theta0_rad as f32,
        (r.psi_f_wb * told.psi_f) as f32,
        ((r.ld_h * told.l) as f32, (r.lq_h * told.l) as f32),
        i_max_a as f32,
    );
    cfg.delay = ComputationDelay::OnePeriod;
    cfg.inertia_kg_m2 = (r.j_kg_m2 * told.j) as f32;
    cfg.pole_pairs = r.pole_pairs;
    let mut p = SaturationProbe::new(&cfg).map_err(|e| fail(e.to_string()))?;
    let mut u_prev = [0.0f64; 2];
    let (mut moved, mut peak) = (0.0f64, 0.0f64);
    let mut seed = 0x9e37_79b9_7f4a_7c15u64;
    let pp = f64::from(r.pole_pairs);
    for _ in 0..(5.0 / ts) as u64 {
        let mut i = plant.i_ab_a();
        peak = peak.max(i[0].hypot(i[1]));
        for x in &mut i {
            // xorshift: uniform noise in +- noise_a.
            seed ^= seed << 13;
            seed ^= seed >> 7;
            seed ^= seed << 17;
            *x += told.noise_a * ((seed >> 11) as f64 / (1u64 << 53) as f64 * 2.0 - 1.0);
        }
        let out = p.tick(&TickInput::alpha_beta(
            i[0] as f32,
            i[1] as f32,
            r.u_dc_v as f32,
        ));
        if p.is_done() {
            break;
        }
        // One period of computation delay: this period applies last tick's voltage.
        plant.step(u_prev, 0.0, ts);
        u_prev = [f64::from(out.u_ab.alpha), f64::from(out.u_ab.beta)];
        moved = moved.max((plant.state().theta_e_rad - theta0_rad).abs() / pp);
    }
    finish(&p, ts, moved, peak, fail)
}

/// The identified map and what its measurement took.
pub struct Identified {
    /// The map, built from the probe's samples.
    pub map: FluxMap<f64, 16>,
    /// The probe's run.
    pub run: ProbeRun,
}

/// The map of the suite's row "EKF told the identified map" (module docs): the probe told
/// the motor's own values, the rotor at 0, up to [`PROBE_CURRENT`] times `i_rated` (A).
pub fn identified_map(m: &SaturatedMotor, i_rated: f64) -> Result<Identified, SimError> {
    let run = probe_plant(m, PROBE_CURRENT * i_rated, 0.0, &ProbeTold::EXACT)?;
    let s = &run.samples;
    let i_d: Vec<f64> = s.i_d[..s.n_d].iter().map(|&x| f64::from(x)).collect();
    let i_q: Vec<f64> = s.i_q[..s.n_q].iter().map(|&x| f64::from(x)).collect();
    let grid = |psi: &[[f32; SAT_MAX_Q]]| -> Vec<f64> {
        psi[..s.n_d]
            .iter()
            .flat_map(|row| row[..s.n_q].iter().map(|&x| f64::from(x)))
            .collect()
    };
    let map = FluxMap::new(&i_d, &i_q, &grid(&s.psi_d), &grid(&s.psi_q)).map_err(|e| {
        SimError::Scenario {
            file: format!("flux-map probe {}", m.reference.name),
            field: "identified flux map".into(),
            problem: e.to_string(),
        }
    })?;
    Ok(Identified { map, run })
}

/// The probe on the saturated rows' realistic drive: [`probe_plant`]'s setting with the
/// suite's inverter (dead time, one period of delay) and current sensing (12-bit ADC over
/// four times the rated current, noise, gain and offset errors; seed `seed`) instead of
/// ideal switches and exact currents. The probe is told the offsets as the identification's
/// offsets step measures them (the mean of 256 samples, PWM off, no current), the inverter's
/// voltage error along the phase-a axis (`4/3 t_dead / Ts u_dc`, what the resistance step
/// measures), and the motor's values scaled by `told` (`told.noise_a` unused: the sensors'
/// own noise). `i_rated` sets the ADC range, as in the suite's rows.
pub fn probe_realistic(
    m: &SaturatedMotor,
    i_rated: f64,
    i_max_a: f64,
    theta0_rad: f64,
    told: &ProbeTold,
    seed: u64,
) -> Result<ProbeRun, SimError> {
    let opts = super::SuiteOptions {
        seed,
        ..super::SuiteOptions::default()
    };
    let sc = super::saturated::scenario(m, &opts, 1.0, i_rated);
    probe_on_drive(m, &sc, i_max_a, theta0_rad, told)
}

/// The probe on the drive of the scenario `sc` (its inverter and current sensing, sensor
/// seed `sc.seed`), told as in [`probe_realistic`]: the offsets step's mean of 256 samples,
/// the inverter's voltage error along the phase-a axis from `sc`'s dead time, the motor's
/// values scaled by `told`, the computation delay of `sc.inverter.delay`.
pub fn probe_on_drive(
    m: &SaturatedMotor,
    sc: &crate::scenario::Scenario,
    i_max_a: f64,
    theta0_rad: f64,
    told: &ProbeTold,
) -> Result<ProbeRun, SimError> {
    use crate::plant::inverter::Inverter;
    use crate::plant::sensors::CurrentSensor;

    let r = &m.reference;
    let fail = |problem: String| SimError::Scenario {
        file: format!("flux-map probe {}", r.name),
        field: "identified flux map (realistic sensing)".into(),
        problem,
    };
    let ts = sc.ts_s();
    let mut plant = Plant::new(
        MotorModel::from_saturated(m),
        PlantState {
            theta_e_rad: theta0_rad,
            ..PlantState::default()
        },
    );
    let mut inverter = Inverter::new(sc.inverter);
    let mut sensor = CurrentSensor::new(sc.sensors, sc.seed);
    // The offsets step: PWM off, no current.
    let n_off = 256;
    let mut off = [0.0f64; 2];
    for _ in 0..n_off {
        let s = sensor.measure([0.0; 3]);
        off[0] += s.i_abc_a[0] / f64::from(n_off);
        off[1] += s.i_abc_a[1] / f64::from(n_off);
    }
    let mut cfg = SaturationConfig::new(
        ts as f32,
        (r.rs_ohm * told.rs) as f32,
        theta0_rad as f32,
        (r.psi_f_wb * told.psi_f) as f32,
        ((r.ld_h * told.l) as f32, (r.lq_h * told.l) as f32),
        i_max_a as f32,
    );
    cfg.delay = if sc.inverter.delay {
        ComputationDelay::OnePeriod
    } else {
        ComputationDelay::None
    };
    cfg.inertia_kg_m2 = (r.j_kg_m2 * told.j) as f32;
    cfg.pole_pairs = r.pole_pairs;
    cfg.current_offsets_a = [off[0] as f32, off[1] as f32];
    cfg.voltage_error_v = (4.0 / 3.0 * sc.inverter.dead_time_s / ts * sc.inverter.u_dc_v) as f32;
    let mut p = SaturationProbe::new(&cfg).map_err(|e| fail(e.to_string()))?;
    let (mut moved, mut peak) = (0.0f64, 0.0f64);
    let pp = f64::from(r.pole_pairs);
    for k in 0..(5.0 / ts) as u64 {
        let t = k as f64 * ts;
        let i_true = plant.i_abc_a();
        let ab = plant.i_ab_a();
        peak = peak.max(ab[0].hypot(ab[1]));
        let meas = sensor.measure(i_true);
        let u_dc = inverter.u_dc_at(t);
        let [a, b, c] = meas.i_abc_a.map(|x| x as f32);
        let out = p.tick(&TickInput::abc(a, b, c, u_dc as f32));
        if p.is_done() {
            break;
        }
        let applied = inverter.apply(out.duties.map(f64::from), u_dc, u_dc, i_true);
        if out.pwm_enabled {
            plant.step(applied.u_ab_v.to_array(), 0.0, ts);
        } else {
            plant.step_open(0.0, ts);
        }
        moved = moved.max((plant.state().theta_e_rad - theta0_rad).abs() / pp);
    }
    finish(&p, ts, moved, peak, fail)
}

/// A probe's run after its last tick: its samples (`fail` names the problem when it failed or
/// did not end), its duration at the period `ts`, the largest rotor motion and the peak current.
fn finish(
    p: &SaturationProbe,
    ts: f64,
    moved: f64,
    peak: f64,
    fail: impl Fn(String) -> SimError,
) -> Result<ProbeRun, SimError> {
    let samples = match p.result() {
        Some(Ok(s)) => *s,
        Some(Err(e)) => return Err(fail(e.to_string())),
        None => return Err(fail("the probe did not end within 5 s".into())),
    };
    Ok(ProbeRun {
        samples,
        duration_s: f64::from(p.ticks()) * ts,
        rotor_moved_mech_rad: moved,
        peak_a: peak,
    })
}

/// The saturated rows' scenario of `m` (module `saturated`: the realistic drive, current
/// limit twice the rated current, sensor seed `seed`) and its rated current (A), for the
/// identification with the flux-map step (`analysis::identify`).
pub fn saturated_scenario(m: &SaturatedMotor, seed: u64) -> (crate::scenario::Scenario, f64) {
    let (_, _, i_rated) = super::saturated::rated_mtpa(m);
    let opts = super::SuiteOptions {
        seed,
        ..super::SuiteOptions::default()
    };
    (super::saturated::scenario(m, &opts, 1.0, i_rated), i_rated)
}
