//! Diagnostics of the suite's interior-motor rows (`pmsm_sim::analysis::suite`), on the traction
//! motor's short run, kept as regression tests.
//!
//! # The EKF through the load step
//!
//! The active-flux model (`ekf-core`) writes the stator voltage as
//! `u = Rs i + Lq di/dt + j w psi_a e^{j th}` with the active flux `psi_a = psi_f + (Ld - Lq) i_d`.
//! The machine has one more term, `(d psi_a / dt) e^{j th}` = `(Ld - Lq) (di_d/dt) e^{j th}`:
//! a voltage along the rotor's d axis, which a model without it can only explain by turning
//! its angle. When MTPA moves `i_d` quickly (the traction motor's load step: -9 A to -79 A,
//! with `Lq - Ld` = 100 uH) that term reaches a sizeable fraction of the back-EMF `w psi_a`.
//! `ekf-core` models the term (its d-axis transient correction, `observer` module docs); the
//! test compares the plain EKF with one fed the voltage less that term,
//! `u - (Ld - Lq) (i_d[k] - i_d[k-1]) / Ts e^{j th_mid}`, which then compensates twice and
//! must be the worse one. Run with `--nocapture` for the numbers.
//!
//! # The baseline at rated load
//!
//! The salient flux baseline pulls its flux estimate radially towards the active-flux circle,
//! whose radius `psi_f + (Ld - Lq) i_d` it computes with the `i_d` read along its own estimated
//! direction. An angle error then changes the radius, and the radial pull of a wrong radius,
//! rotated by the rotor, can balance: a second, rotated equilibrium, which a too high observer
//! gain makes stable. `ekf-core`'s baseline limits its gain where the linearised loop would be
//! unstable (`flux` module docs); the test checks that no second equilibrium remains at the
//! suite's firmware timing, at the centred timing, and at lower gains.

use ekf_core::{
    EkfError, FluxObserver, FluxObserverConfig, FluxTiming, ObserverConfig, PmsmObserver,
};
use pmsm_sim::analysis::suite::{SuiteMotor, SuiteOptions, suite_scenario};
use pmsm_sim::drive::rotor_observers::{Observer, ObserverEstimate};
use pmsm_sim::output::record::{ObserverSample, Sample};
use pmsm_sim::plant::load::LoadTerm;
use pmsm_sim::scenario::Scenario;
use pmsm_sim::sim::{SideObserver, build_controller, run_with_side_observers};

/// The EKF, optionally fed the voltage less the `d psi_a / dt` term, scoring itself over the
/// load-step window.
struct Probe {
    ekf: PmsmObserver<f64>,
    /// `Ld - Lq`, H (0: the plain EKF).
    dl: f64,
    ts: f64,
    prev: Option<([f64; 2], f64, f64)>,
    window: (f64, f64),
    max_err_deg: f64,
    /// Largest `|(Ld - Lq) di_d/dt| / (w psi_a)` of the truth in the window (rad): the angle
    /// the neglected term would turn a model that ignores it.
    max_term_rad: f64,
    last_truth: Option<(f64, f64)>,
    psi_f: f64,
    /// The suite's last steady window (short run: "100 %, rated load", the last 0.2 s).
    steady: (f64, f64),
    /// `(sum e^2, n)` over the steady window.
    steady_sums: (f64, usize),
}

impl Probe {
    fn new(sc: &Scenario, compensate: bool, window: (f64, f64)) -> Self {
        let steady = (sc.duration_s - 0.2, sc.duration_s);
        let params = sc.observer_params();
        let ts = sc.ts_s();
        let ekf =
            PmsmObserver::new(&ObserverConfig::new(params, ts)).unwrap_or_else(|e| panic!("{e:?}"));
        Self {
            ekf,
            dl: if compensate {
                params.ld_h - params.lq_h
            } else {
                0.0
            },
            ts,
            prev: None,
            window,
            max_err_deg: 0.0,
            max_term_rad: 0.0,
            last_truth: None,
            psi_f: params.psi_f_wb,
            steady,
            steady_sums: (0.0, 0),
        }
    }
}

impl Observer for Probe {
    fn step(&mut self, u_prev: [f64; 2], i: [f64; 2]) -> Result<ObserverEstimate, EkfError> {
        let mut u = u_prev;
        if let Some((i_prev, th, w)) = self.prev
            && self.dl != 0.0
        {
            // i_d at t_k-1 in the frame of then, at t_k in the frame one period on.
            let (s0, c0) = th.sin_cos();
            let (s1, c1) = (th + w * self.ts).sin_cos();
            let id0 = i_prev[0] * c0 + i_prev[1] * s0;
            let id1 = i[0] * c1 + i[1] * s1;
            let dpsi_v = self.dl * (id1 - id0) / self.ts;
            let (sm, cm) = (th + 0.5 * w * self.ts).sin_cos();
            u = [u[0] - dpsi_v * cm, u[1] - dpsi_v * sm];
        }
        let e = Observer::step(&mut self.ekf, u, i)?;
        self.prev = Some((i, e.theta_e_rad, e.omega_e_rad_s));
        Ok(e)
    }
}

impl SideObserver for Probe {
    fn record(&mut self, sample: &Sample, own: Result<ObserverSample, EkfError>) {
        let t = sample.t_s;
        if t >= self.steady.0
            && t < self.steady.1
            && let Ok(s) = &own
        {
            self.steady_sums.0 += s.angle_error_deg * s.angle_error_deg;
            self.steady_sums.1 += 1;
        }
        let id = sample.truth.i_dq_a[0];
        let w = sample.truth.omega_e_rad_s;
        if t >= self.window.0 && t < self.window.1 {
            let e = own.map_or(f64::INFINITY, |s| s.angle_error_deg.abs());
            self.max_err_deg = self.max_err_deg.max(e);
            if let Some((id_prev, _)) = self.last_truth {
                // |Ld - Lq| from the plant's own parameters (the probe's `dl` may be 0).
                let dl = 100e-6;
                let psi_a = self.psi_f + dl * id.abs();
                let term = (dl * (id - id_prev) / self.ts / (w * psi_a)).abs().atan();
                self.max_term_rad = self.max_term_rad.max(term);
            }
        }
        self.last_truth = Some((id, w));
    }
}

/// Worst `|e_th|` through the load step of the plain and the compensated EKF, the largest
/// angle of the neglected term, and the steady RMS at rated load of both, on the suite's short
/// traction run.
fn load_step(ideal: bool) -> (f64, f64, f64, f64, f64) {
    let opts = SuiteOptions {
        short: true,
        seed: 1,
        ideal,
    };
    let sc = suite_scenario(SuiteMotor::TractionIpm, &opts);
    assert!((sc.motor.lq_h - sc.motor.ld_h - 100e-6).abs() < 1e-12);
    let step_s = sc
        .load
        .iter()
        .find_map(|l| match l {
            LoadTerm::Step { time_s, .. } => Some(*time_s),
            _ => None,
        })
        .expect("load step");
    // The suite's transient window (short run: 0.25 s).
    let window = (step_s, step_s + 0.25);
    let mut drive = build_controller(&sc).unwrap_or_else(|e| panic!("{e}"));
    let mut plain = Probe::new(&sc, false, window);
    let mut comp = Probe::new(&sc, true, window);
    let out = {
        let mut side: Vec<&mut dyn SideObserver> = vec![&mut plain, &mut comp];
        run_with_side_observers(&sc, drive.as_mut(), Default::default(), &mut side)
            .unwrap_or_else(|e| panic!("{e}"))
    };
    assert!(out.end.is_completed(), "{}", out.end.describe());
    let rms = |p: &Probe| (p.steady_sums.0 / p.steady_sums.1 as f64).sqrt();
    (
        plain.max_err_deg,
        comp.max_err_deg,
        plain.max_term_rad.to_degrees(),
        rms(&plain),
        rms(&comp),
    )
}

#[test]
fn the_traction_load_step_error_was_the_active_flux_derivative_now_modelled() {
    for ideal in [true, false] {
        let (plain, comp, term, rms_plain, rms_comp) = load_step(ideal);
        println!(
            "traction_ipm load step ({} sensing): EKF worst |e_th| {plain:.2} deg as is, \
             {comp:.2} deg fed u - (Ld - Lq) di_d/dt e^(j th); largest atan(|(Ld - Lq) di_d/dt| \
             / (w psi_a)) of the truth {term:.2} deg; steady RMS at rated load {rms_plain:.3} \
             deg as is, {rms_comp:.3} deg compensated",
            if ideal { "ideal" } else { "realistic" }
        );
        // The term is large (several degrees of angle if it were left out) ...
        assert!(term > 5.0, "{term}");
        // ... and the EKF, which models it now, goes through the step within half a degree
        // (measured 0.03 ideal, see the printout for realistic); compensating it once more
        // outside is worse.
        assert!(plain < 0.5, "{plain}");
        assert!(comp > plain, "{comp} vs {plain}");
        assert!(rms_plain < 0.2, "{rms_plain}");
        let _ = rms_comp;
    }
}

/// An observer scored by its mean and RMS angle error over a window.
struct Windowed {
    est: Box<dyn Observer>,
    window: (f64, f64),
    sums: (f64, f64, usize),
    /// `(sum of the true speed (rpm), largest |i| (A))` over the window.
    truth: (f64, f64),
}

impl Observer for Windowed {
    fn step(&mut self, u_prev: [f64; 2], i: [f64; 2]) -> Result<ObserverEstimate, EkfError> {
        self.est.step(u_prev, i)
    }
}

impl SideObserver for Windowed {
    fn record(&mut self, sample: &Sample, own: Result<ObserverSample, EkfError>) {
        if sample.t_s >= self.window.0
            && sample.t_s < self.window.1
            && let Ok(s) = own
        {
            self.sums.0 += s.angle_error_deg;
            self.sums.1 += s.angle_error_deg * s.angle_error_deg;
            self.sums.2 += 1;
            self.truth.0 += sample.truth.speed_rpm;
            let [i_d, i_q] = sample.truth.i_dq_a;
            self.truth.1 = self.truth.1.max(i_d.hypot(i_q));
        }
    }
}

#[test]
fn the_salient_baselines_second_equilibrium_is_gone() {
    let opts = SuiteOptions {
        short: true,
        seed: 1,
        ideal: true,
    };
    let sc = suite_scenario(SuiteMotor::TractionIpm, &opts);
    let params = sc.observer_params();
    let ts = sc.ts_s();
    // The suite's last steady window: 100 %, rated load.
    let window = (sc.duration_s - 0.2, sc.duration_s);
    let flux = |timing: FluxTiming, gain_factor: f64| -> Windowed {
        let mut cfg = FluxObserverConfig::new(params, ts);
        cfg.timing = timing;
        cfg.observer_gain_rad_s *= gain_factor;
        Windowed {
            est: Box::new(FluxObserver::new(&cfg).unwrap_or_else(|e| panic!("{e:?}"))),
            window,
            sums: (0.0, 0.0, 0),
            truth: (0.0, 0.0),
        }
    };
    let mut firmware = flux(FluxTiming::Firmware, 1.0);
    let mut centred = flux(FluxTiming::Centred, 1.0);
    let mut gains: Vec<(f64, Windowed)> = [0.5, 0.2, 0.05]
        .into_iter()
        .map(|k| (k, flux(FluxTiming::Centred, k)))
        .collect();
    let mut drive = build_controller(&sc).unwrap_or_else(|e| panic!("{e}"));
    {
        let mut side: Vec<&mut dyn SideObserver> = vec![&mut firmware, &mut centred];
        for (_, w) in gains.iter_mut() {
            side.push(w);
        }
        let out = run_with_side_observers(&sc, drive.as_mut(), Default::default(), &mut side)
            .unwrap_or_else(|e| panic!("{e}"));
        assert!(out.end.is_completed());
    }
    let stats = |w: &Windowed| {
        let n = w.sums.2 as f64;
        (w.sums.0 / n, (w.sums.1 / n).sqrt())
    };
    let (fm, fr) = stats(&firmware);
    let (cm, cr) = stats(&centred);
    println!(
        "traction_ipm 100 %, rated load (ideal sensing): salient baseline mean / RMS \
         {fm:+.2} / {fr:.2} deg firmware timing (the suite's), {cm:+.2} / {cr:.2} deg centred"
    );
    // The window is the rated point: 3000 rpm, the MTPA current of 15 N m (148 A) plus
    // friction and ripple.
    let rpm = firmware.truth.0 / firmware.sums.2 as f64;
    println!(
        "  rated point: mean speed {rpm:.1} rpm, largest |i| {:.1} A",
        firmware.truth.1
    );
    assert!((rpm - 3000.0).abs() < 3.0, "{rpm}");
    assert!(firmware.truth.1 > 148.0 && firmware.truth.1 < 152.0);
    for (k, w) in &gains {
        let (m, r) = stats(w);
        println!("  centred, observer gain x {k}: mean / RMS {m:+.2} / {r:.2} deg");
    }
    // Was 45.7 deg (firmware) and 39.8 deg (centred) before the gain limit; now only the
    // firmware form's timing lead is left, and the centred form is unbiased at any gain.
    assert!(fm.abs() < 3.0, "{fm}");
    assert!(cm.abs() < 0.2, "{cm}");
    for (k, w) in &gains {
        let (m, _) = stats(w);
        assert!(m.abs() < 0.2, "gain x {k}: {m}");
    }
}
