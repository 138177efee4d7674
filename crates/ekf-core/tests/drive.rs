//! The drive observer on simulated records with what real drives add: a voltage lead that the
//! logged command does not show, at a speed that keeps changing.
mod common;
use common::*;
use core::f64::consts::PI;
use ekf_core::{
    DriveConfig, DriveObserver, EkfError, MotorParams, ObserverConfig, PmsmObserver, wrap_angle,
};

/// The servo stepping between 30 and 90 % of rated speed, 15 % of `I_c` on the q axis, 20 mA
/// noise; the applied voltage leads the logged one by `lead` periods: the log holds the
/// applied vector turned back by `w lead Ts`.
fn record(lead: f64) -> (Trace, Vec<[f64; 2]>) {
    let motor = MotorParams::servo();
    let ts = 1e-4;
    let wr = 3000.0 / 60.0 * 2.0 * PI * 4.0;
    let ic = motor.characteristic_current_a();
    // Steps between 30 % and 90 % of rated every 0.1 s, 15 ms ramps (a drive's speed steps).
    let speed = move |t: f64| {
        let ph = t % 0.2;
        let up = ((ph - 0.0) / 0.015).clamp(0.0, 1.0);
        let down = ((ph - 0.1) / 0.015).clamp(0.0, 1.0);
        wr * (0.3 + 0.6 * (up - down))
    };
    let iq = move |_t: f64| 0.15 * ic;
    let sc = Scenario {
        motor,
        ts,
        n: 12000,
        speed: &speed,
        iq_ref: &iq,
        th0: 0.3,
        noise_a: 0.02,
        seed: 11,
    };
    let tr = simulate(&sc);
    let logged =
        tr.u.iter()
            .zip(&tr.w)
            .map(|(u, w)| {
                let (s, c) = (-w * lead * ts).sin_cos();
                [c * u[0] - s * u[1], s * u[0] + c * u[1]]
            })
            .collect();
    (tr, logged)
}

/// (RMS about the mean, mean) of the angle error over the last half, deg.
fn spread(err: &[f64]) -> (f64, f64) {
    let h = &err[err.len() / 2..];
    let mean = h.iter().sum::<f64>() / h.len() as f64;
    let var = h.iter().map(|e| (e - mean) * (e - mean)).sum::<f64>() / h.len() as f64;
    (var.sqrt(), mean)
}

/// The default observer with `cfg` over `tr` given the `logged` voltages: (RMS about the
/// mean, mean) of the angle error over the last half, deg.
fn default_spread(cfg: &ObserverConfig<f64>, tr: &Trace, logged: &[[f64; 2]]) -> (f64, f64) {
    let mut obs = PmsmObserver::new(cfg).unwrap();
    let mut u_prev = [0.0; 2];
    let mut err = vec![];
    for (k, i) in tr.i_meas.iter().enumerate() {
        let e = obs.step(u_prev, *i).unwrap();
        err.push(wrap_angle(e.theta_rad - tr.th[k]).to_degrees());
        u_prev = logged[k];
    }
    spread(&err)
}

/// Runs both observers on a record with `lead`; returns the drive's last estimate, the
/// (RMS about the mean, mean) of both, and the drive's tracking share of the last half.
fn compare(lead: f64) -> (ekf_core::DriveEstimate<f64>, (f64, f64), (f64, f64), f64) {
    let (tr, logged) = record(lead);
    let motor = MotorParams::servo();
    let ts = tr.ts;
    let mut drive = DriveObserver::new(&DriveConfig::new(motor, ts)).unwrap();
    // The default observer with its speed noise fixed: the drive observer's reference (the
    // adaptation of the default, which follows these speed steps more closely, is measured in
    // tests/speed_adaptation.rs).
    let fixed = ObserverConfig {
        speed_noise_adaptation: None,
        ..ObserverConfig::new(motor, ts)
    };
    let mut classic = PmsmObserver::new(&fixed).unwrap();
    let (mut e_drive, mut e_classic) = (vec![], vec![]);
    let mut u_prev = [0.0; 2];
    let mut last = None;
    let mut tracking = 0usize;
    for (k, i) in tr.i_meas.iter().enumerate() {
        let d = drive.step(u_prev, *i).unwrap();
        let c = classic.step(u_prev, *i).unwrap();
        e_drive.push(wrap_angle(d.theta_rad - tr.th[k]).to_degrees());
        e_classic.push(wrap_angle(c.theta_rad - tr.th[k]).to_degrees());
        if k >= tr.i_meas.len() / 2 && d.tracking {
            tracking += 1;
        }
        u_prev = logged[k];
        last = Some(d);
    }
    let d = last.unwrap();
    let (rms_d, mean_d) = spread(&e_drive);
    let (rms_c, mean_c) = spread(&e_classic);
    println!(
        "lead {lead} Ts: drive observer lead {:.3} Ts, Rs {:.3} ohm, v_dt {:.3} V; angle about \
         its mean: drive {rms_d:.3} deg (mean {mean_d:+.3}), default observer {rms_c:.3} deg \
         (mean {mean_c:+.3}); drive tracking {:.1} % of the last half",
        d.voltage_lead_s / ts,
        d.rs_ohm,
        d.dead_time_v,
        100.0 * tracking as f64 / (tr.i_meas.len() / 2) as f64
    );
    let share = tracking as f64 / (tr.i_meas.len() / 2) as f64;
    (d, (rms_d, mean_d), (rms_c, mean_c), share)
}

/// Measured: lead 0.514 Ts found; angle about its mean 0.33 deg (mean -0.29) against the
/// default observer's 0.91 deg (mean -2.38), which takes `w tau` for an angle.
#[test]
fn drive_observer_finds_the_voltage_lead_and_holds_the_angle() {
    let (d, (rms_d, mean_d), (rms_c, _), share) = compare(0.5);
    assert!((d.voltage_lead_s / 1e-4 - 0.5).abs() < 0.1, "{d:?}");
    assert!(rms_d < 0.4 && mean_d.abs() < 0.6, "{rms_d} {mean_d}");
    assert!(rms_c > 2.5 * rms_d, "{rms_c} vs {rms_d}");
    assert!(share >= 0.9, "{share}");
}

/// Without a lead: measured, the drive observer settles at a lead of 0.23 Ts (a bias of the
/// estimate on this record, not understood yet), its angle 0.37 deg about a mean of +0.80 deg
/// against the default observer's (speed noise fixed) 0.28 deg about +0.03 deg.
#[test]
fn drive_observer_without_a_lead_stays_close() {
    let (d, (rms_d, mean_d), (rms_c, _), share) = compare(0.0);
    assert!((d.voltage_lead_s / 1e-4).abs() < 0.3, "{d:?}");
    assert!(
        rms_d < 1.5 * rms_c && mean_d.abs() < 1.0,
        "{rms_d} {mean_d} / {rms_c}"
    );
    assert!(share >= 0.9, "{share}");
}

#[test]
fn drive_observer_refuses_bad_samples_and_keeps_its_state() {
    let motor = MotorParams::servo();
    let ts = 1e-4;
    let mut d = DriveObserver::new(&DriveConfig::new(motor, ts)).unwrap();
    d.step([1.0, 0.0], [0.1, 0.0]).unwrap();
    let before = d.clone();
    assert_eq!(
        d.step([f64::NAN, 0.0], [0.0; 2]),
        Err(EkfError::NonFiniteInput)
    );
    assert_eq!(
        d.step([0.0; 2], [0.0, f64::INFINITY]),
        Err(EkfError::NonFiniteMeasurement)
    );
    assert_eq!(
        d.step_dt([0.0; 2], [0.0; 2], -ts),
        Err(EkfError::InvalidPeriod)
    );
    assert_eq!(
        d.step_dt([0.0; 2], [0.0; 2], f64::NAN),
        Err(EkfError::InvalidPeriod)
    );
    assert_eq!(d, before);
    let mut bad = DriveConfig::new(motor, ts);
    bad.sigma_i_a = -1.0;
    assert!(DriveObserver::new(&bad).is_err());
    bad = DriveConfig::new(motor, ts);
    bad.settle_s = f64::NAN;
    assert!(DriveObserver::new(&bad).is_err());
}

/// The default observer told the record's timing (`voltage_delay_s = -0.5 Ts`: the applied
/// voltage leads the logged one by half a period) against the same observer told nothing.
/// Measured (`cargo test --release -p ekf-core --test drive told -- --nocapture`): mean error
/// -2.38 deg untold, +0.03 deg told; RMS about the mean 0.89 vs 0.26 deg. A delay outside `[-2 Ts, 2 Ts]` or non-finite is refused.
#[test]
fn default_observer_told_the_voltage_lead() {
    let (tr, logged) = record(0.5);
    let motor = MotorParams::servo();
    let ts = tr.ts;
    let run = |delay: f64| {
        let cfg = ObserverConfig {
            voltage_delay_s: delay,
            ..ObserverConfig::new(motor, ts)
        };
        default_spread(&cfg, &tr, &logged)
    };
    let (rms_told, mean_told) = run(-0.5 * ts);
    let (rms_untold, mean_untold) = run(0.0);
    println!(
        "lead 0.5 Ts: told rms {rms_told:.3} deg about mean {mean_told:+.3}; untold rms \
         {rms_untold:.3} about {mean_untold:+.3}"
    );
    assert!(mean_told.abs() < 0.3, "{mean_told}");
    assert!(mean_untold.abs() > 1.5, "{mean_untold}");
    assert!(rms_told < 0.5 * rms_untold, "{rms_told} vs {rms_untold}");
    for bad in [2.5 * ts, -2.5 * ts, f64::NAN, f64::INFINITY] {
        let cfg = ObserverConfig {
            voltage_delay_s: bad,
            ..ObserverConfig::new(motor, ts)
        };
        assert!(PmsmObserver::new(&cfg).is_err(), "{bad} accepted");
    }
}

/// The inverter's voltage error: a log whose voltage is the applied one plus 2 V along the
/// signs of the phase currents (a dead time the firmware did not compensate; the servo at
/// 15 % of `I_c`, 30-90 % of rated speed). The default observer told `inverter_voltage_v = 2`
/// against the same observer told nothing. Measured (`cargo test --release -p ekf-core --test
/// drive inverter -- --nocapture`): told, 0.23 deg about a mean of +0.00 deg; untold, 0.68 deg
/// about +0.35 deg. A value outside `[0, 100]` V or non-finite is refused.
#[test]
fn default_observer_told_the_inverter_voltage() {
    let (tr, applied) = record(0.0);
    let motor = MotorParams::servo();
    let ts = tr.ts;
    let v = 2.0;
    let r3 = 3f64.sqrt() / 2.0;
    let logged: Vec<[f64; 2]> = applied
        .iter()
        .zip(&tr.i_meas)
        .map(|(u, i)| {
            let (pa, pb, pc) = (i[0], -0.5 * i[0] + r3 * i[1], -0.5 * i[0] - r3 * i[1]);
            let s = |x: f64| x.signum();
            let da = 0.5 * (s(pa) - 0.5 * (s(pb) + s(pc)));
            let db = 0.5 * r3 * (s(pb) - s(pc));
            [u[0] + v * da, u[1] + v * db]
        })
        .collect();
    let run = |told: f64| {
        let cfg = ObserverConfig {
            inverter_voltage_v: told,
            ..ObserverConfig::new(motor, ts)
        };
        default_spread(&cfg, &tr, &logged)
    };
    let (rms_told, mean_told) = run(v);
    let (rms_untold, mean_untold) = run(0.0);
    println!(
        "inverter voltage 2 V: told rms {rms_told:.3} deg about mean {mean_told:+.3}; untold rms \
         {rms_untold:.3} about {mean_untold:+.3}"
    );
    let total = |r: f64, m: f64| (r * r + m * m).sqrt();
    assert!(
        total(rms_told, mean_told) < 0.5 * total(rms_untold, mean_untold),
        "told {rms_told}/{mean_told}, untold {rms_untold}/{mean_untold}"
    );
    for bad in [-0.1, 101.0, f64::NAN] {
        let cfg = ObserverConfig {
            inverter_voltage_v: bad,
            ..ObserverConfig::new(motor, ts)
        };
        assert!(PmsmObserver::new(&cfg).is_err(), "{bad} accepted");
    }
}
