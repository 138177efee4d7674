//! Tests of module [`crate::hfi`]: defaults, the noise model, the least-squares weights,
//! the demodulation, the loop, the polarity test, the fusion and the weight.

use core::f32::consts::PI;

use ekf_core::MotorParams;

use super::blend::{Track, observer_weight};
use super::demod::ls_weights;
use super::drive::{HfiDrive, Stage};
use super::polarity::{Polarity, PolarityPlan, PolarityStep, Standstill};
use super::*;
use crate::config::{FocConfig, Mode};
use crate::transforms::{AlphaBeta, Dq};
use crate::trig::{sin_cos, wrap};

fn ipm() -> FocConfig {
    let mut c = FocConfig::new(MotorParams::industrial_ipm(), 1e-4, 540.0);
    c.current_limit_a = 9.0;
    c
}

/// A stationary-rotor dq plant at angle `theta` (the carrier's response only: R and speed
/// neglected in the plant too, plus R for realism), stepped exactly for a held voltage:
/// `i += Ts L^-1 u` in the rotor frame (R small enough to neglect over one period), with
/// an optional d-axis saturation `Ld,inc = Ld (1 - k clamp(i_d / I_s, 0, 1))`.
struct DqPlant {
    ld: f32,
    lq: f32,
    theta: f32,
    i: Dq,
    sat: f32,
    i_sat: f32,
}

impl DqPlant {
    fn step(&mut self, u_ab: AlphaBeta, ts: f32) {
        let (s, c) = sin_cos(self.theta);
        let u = u_ab.to_dq(s, c);
        let x = crate::pi::limit(self.i.d / self.i_sat, 0.0, 1.0);
        let ld = self.ld * (1.0 - self.sat * x);
        self.i.d += ts * u.d / ld;
        self.i.q += ts * u.q / self.lq;
    }
    fn i_ab(&self) -> AlphaBeta {
        let (s, c) = sin_cos(self.theta);
        self.i.to_alpha_beta(s, c)
    }
}

/// Runs the tracker on the plant with a one-period delay and a d current held by an ideal
/// (dead-beat on the mean) current source: returns the final tracker.
fn run(theta0: f32, theta_rotor: f32, ticks: u32, drift: f32) -> HfiTracker {
    let cfg = ipm();
    let h = HfiConfig::new(&cfg, 540.0).unwrap_or_else(|e| panic!("{e}"));
    let mut t = HfiTracker::from_config(&cfg, &h);
    t.reset(theta0, 0.0);
    let mut p = DqPlant {
        ld: cfg.motor.ld_h,
        lq: cfg.motor.lq_h,
        theta: theta_rotor,
        i: Dq { d: 0.0, q: 2.0 },
        sat: 0.0,
        i_sat: 1.0,
    };
    let mut pending = AlphaBeta::default();
    for _ in 0..ticks {
        let _ = t.update(p.i_ab(), 0.0);
        let u = t.inject();
        p.step(pending, cfg.ts_s);
        pending = u;
        p.theta = wrap(p.theta + drift * cfg.ts_s);
    }
    t
}

#[test]
fn defaults_follow_the_motor_and_surface_motors_are_refused() {
    let cfg = ipm();
    let h = HfiConfig::new(&cfg, 540.0).unwrap_or_else(|e| panic!("{e}"));
    // 10 % of 9 A ripple on 30 mH at 10 kHz: 270 V, capped at 80 % of 312 V.
    assert!(
        (h.injection_v - 0.8 * 540.0 / 3.0_f32.sqrt()).abs() < 0.5,
        "{h:?}"
    );
    assert!(h.blend_low_rad_s < h.blend_high_rad_s);
    let surface = FocConfig::new(MotorParams::servo(), 1e-4, 300.0);
    assert_eq!(
        HfiConfig::new(&surface, 300.0),
        Err(HfiError::SurfaceMotor { saliency: 1.0 })
    );
    let mut bad = h;
    bad.injection_v = f32::NAN;
    assert_eq!(
        bad.validate(&cfg, 540.0),
        Err(HfiError::NotPositive(HfiField::InjectionV))
    );
    bad = h;
    bad.blend_low_rad_s = 2.0 * h.blend_high_rad_s;
    assert_eq!(
        bad.validate(&cfg, 540.0),
        Err(HfiError::OutOfRange(HfiField::BlendLow))
    );
    bad = h;
    bad.polarity_current_a = 10.0;
    assert_eq!(
        bad.validate(&cfg, 540.0),
        Err(HfiError::OutOfRange(HfiField::PolarityCurrent))
    );
    let sensored = cfg.with_mode(Mode::Sensored);
    assert_eq!(h.validate(&sensored, 540.0), Err(HfiError::SensoredMode));
}

#[test]
fn noise_model_picks_bandwidth_and_half_period() {
    // The industrial motor as the simulator's preset runs it.
    let mut cfg = ipm();
    cfg.current_limit_a = 12.0;
    cfg.inertia_kg_m2 = 0.012;
    let plain = HfiConfig::new(&cfg, 540.0).unwrap_or_else(|e| panic!("{e}"));
    // No noise: the plain defaults.
    assert_eq!(HfiConfig::with_current_noise(&cfg, 540.0, 0.0), Ok(plain));
    // 50 mA: the plain defaults predict more than 1 deg; the bandwidth drops to the load
    // step's bound, sqrt(0.54 a_max), and the half period grows until the target is met.
    let h = HfiConfig::with_current_noise(&cfg, 540.0, 0.05).unwrap_or_else(|e| panic!("{e}"));
    assert!(plain.predicted_angle_rms_rad(&cfg, 0.05) > TARGET_ANGLE_RMS_RAD);
    assert!(h.predicted_angle_rms_rad(&cfg, 0.05) <= TARGET_ANGLE_RMS_RAD);
    assert_eq!((plain.half_period_ticks, h.half_period_ticks), (4, 7));
    assert!(h.half_period_ticks > plain.half_period_ticks, "{h:?}");
    let ratio = h.pll_bandwidth_rad_s / plain.pll_bandwidth_rad_s;
    assert!(
        (ratio - (LOAD_STEP_PEAK / 0.5).sqrt()).abs() < 1e-3,
        "{ratio}"
    );
    let mut shorter = h;
    shorter.half_period_ticks -= 1;
    assert!(shorter.predicted_angle_rms_rad(&cfg, 0.05) > TARGET_ANGLE_RMS_RAD);
    // Far too noisy: the longest half period.
    let n = HfiConfig::with_current_noise(&cfg, 540.0, 1.0).unwrap_or_else(|e| panic!("{e}"));
    assert_eq!(n.half_period_ticks, MAX_HALF_PERIOD);
    for bad in [-0.1, f32::NAN, f32::INFINITY] {
        assert_eq!(
            HfiConfig::with_current_noise(&cfg, 540.0, bad),
            Err(HfiError::OutOfRange(HfiField::CurrentNoise))
        );
    }
    let mut bad = plain;
    bad.half_period_ticks = MAX_HALF_PERIOD + 1;
    assert_eq!(
        bad.validate(&cfg, 540.0),
        Err(HfiError::OutOfRange(HfiField::HalfPeriod))
    );
}

#[test]
fn least_squares_weights_are_unbiased_and_cancel_the_fundamental() {
    // For every half period and window phase: the weights of the signed steps sum to 1
    // (a carrier step is measured as itself) and weigh the carrier's signs to zero (a
    // constant slope of the fundamental cancels).
    for half in 1..=MAX_HALF_PERIOD {
        let w = ls_weights(half);
        let n = 2 * usize::from(half);
        for (p0, row) in w.iter().enumerate().take(n) {
            let sum: f32 = row.iter().take(n).sum();
            let signed: f32 = row
                .iter()
                .enumerate()
                .take(n)
                .map(|(p, x)| if p < usize::from(half) { *x } else { -*x })
                .sum();
            assert!((sum - 1.0).abs() < 1e-5, "N {half} p0 {p0}: {sum}");
            assert!(signed.abs() < 1e-5, "N {half} p0 {p0}: {signed}");
        }
    }
}

#[test]
fn demodulation_gives_sin_2e_over_2() {
    // Tracker frozen (bandwidth tiny) at 0, rotor at e: eps = sin(2e)/2.
    let cfg = ipm();
    for (e, n) in [
        (-1.2_f32, 1),
        (-0.3, 3),
        (0.1, 1),
        (0.6, 4),
        (-0.2, 7),
        (0.4, 8),
    ] {
        let mut t = HfiTracker::new(&cfg.motor, cfg.ts_s, 100.0, n, 1e-3, cfg.delay, 1.5);
        t.reset(0.0, 0.0);
        let mut p = DqPlant {
            ld: cfg.motor.ld_h,
            lq: cfg.motor.lq_h,
            theta: e,
            i: Dq { d: -1.0, q: 3.0 },
            sat: 0.0,
            i_sat: 1.0,
        };
        let mut pending = AlphaBeta::default();
        let mut last = None;
        for _ in 0..20 {
            if let (Some(r), _) = t.update(p.i_ab(), 0.0) {
                last = Some(r);
            }
            let u = t.inject();
            p.step(pending, cfg.ts_s);
            pending = u;
        }
        let r = last.unwrap_or_else(|| panic!("no response"));
        let want = 0.5 * (2.0 * e).sin();
        assert!((r.eps - want).abs() < 2e-3, "e {e}: {} vs {want}", r.eps);
        let d = cfg.ts_s
            * 100.0
            * (e.cos().powi(2) / cfg.motor.ld_h + e.sin().powi(2) / cfg.motor.lq_h);
        assert!((r.d - d).abs() < 1e-3 * d, "{} vs {d}", r.d);
    }
}

#[test]
fn a_fundamental_slope_does_not_leak_through_a_moving_axis() {
    // The rotor and the carrier's axis turn 0.03 rad per tick (the loop frozen on the
    // speed), the fundamental ramps by 0.5 A per tick in alpha-beta: the responses must
    // be those without the ramp. Without the fixed-frame slope removal the ramp leaks as
    // about 0.05 of eps.
    let cfg = ipm();
    let omega = 300.0;
    let run = |ramp: AlphaBeta| {
        let mut t = HfiTracker::new(&cfg.motor, cfg.ts_s, 100.0, 4, 1e-3, cfg.delay, 1.5);
        t.reset(0.2, omega);
        let mut p = DqPlant {
            ld: cfg.motor.ld_h,
            lq: cfg.motor.lq_h,
            theta: 0.3,
            i: Dq { d: -1.0, q: 3.0 },
            sat: 0.0,
            i_sat: 1.0,
        };
        let mut pending = AlphaBeta::default();
        let mut out = [Response::default(); 24];
        for (k, o) in out.iter_mut().enumerate() {
            let i = p.i_ab() + ramp * k as f32;
            if let (Some(r), _) = t.update(i, 0.0) {
                *o = r;
            }
            let u = t.inject();
            p.step(pending, cfg.ts_s);
            pending = u;
            p.theta = wrap(p.theta + omega * cfg.ts_s);
        }
        out
    };
    let still = run(AlphaBeta::default());
    let ramped = run(AlphaBeta {
        alpha: 0.3,
        beta: -0.4,
    });
    assert!(still[23].d > 0.0, "no response");
    for (a, b) in still.iter().zip(&ramped) {
        assert!((a.eps - b.eps).abs() < 2e-3, "{a:?} vs {b:?}");
        assert!(
            (a.d - b.d).abs() < 2e-3 * a.d.abs().max(0.1),
            "{a:?} vs {b:?}"
        );
    }
}

#[test]
fn loop_locks_on_the_axis_or_its_opposite_and_tracks_a_turning_rotor() {
    for k in 0..12 {
        let th = -PI + (k as f32 + 0.5) * PI / 6.0;
        let t = run(0.0, th, 3000, 0.0);
        let e = wrap(th - t.theta());
        let e_mod_pi = wrap(2.0 * e) * 0.5;
        assert!(
            e_mod_pi.abs() < 0.5_f32.to_radians(),
            "rotor {th}: error {e}"
        );
    }
    // 30 rad/s el. ramp-free rotation: locked within a degree, speed within 1 %.
    let t = run(0.3, 0.3, 5000, 30.0);
    let th_end = wrap(0.3 + 30.0 * 5000.0 * 1e-4);
    let e = wrap(th_end - t.theta());
    assert!(e.abs() < 1.0_f32.to_radians(), "error {e}");
    assert!((t.omega() - 30.0).abs() < 0.3, "speed {}", t.omega());
}

#[test]
fn polarity_test_finds_north_on_a_saturating_plant() {
    let cfg = ipm();
    let h = HfiConfig::new(&cfg, 540.0).unwrap_or_else(|e| panic!("{e}"));
    for k in 0..12 {
        let th = -PI + (k as f32 + 0.5) * PI / 6.0;
        let mut t = HfiTracker::from_config(&cfg, &h);
        t.reset(0.0, 0.0);
        let plan = PolarityPlan::new(&h, cfg.ts_s);
        let mut test = Standstill::new();
        let mut p = DqPlant {
            ld: cfg.motor.ld_h,
            lq: cfg.motor.lq_h,
            theta: th,
            i: Dq::default(),
            sat: 0.2,
            i_sat: 9.0,
        };
        let mut pending = AlphaBeta::default();
        let mut last_ref = 0.0;
        let result = loop {
            let (resp, _) = t.update(p.i_ab(), 0.0);
            match test.step(&plan, resp) {
                PolarityStep::Drive(i_d) => {
                    // An ideal current source: the d current (tracked frame) set when the
                    // reference changes; the carrier rides on it.
                    if i_d != last_ref {
                        last_ref = i_d;
                        let (s, c) = sin_cos(t.theta());
                        let (sr, cr) = sin_cos(p.theta);
                        p.i = Dq { d: i_d, q: 0.0 }.to_alpha_beta(s, c).to_dq(sr, cr);
                    }
                }
                PolarityStep::Done(Polarity { flipped, contrast }) => break (flipped, contrast),
            }
            let u = t.inject();
            p.step(pending, cfg.ts_s);
            pending = u;
        };
        if result.0 {
            t.flip();
        }
        let e = wrap(th - t.theta());
        assert!(
            e.abs() < 2.0_f32.to_radians(),
            "rotor {th}: error {e}, {result:?}"
        );
        assert!(result.1 > 1.05 || result.1 < 1.0 / 1.05, "{result:?}");
    }
}

#[test]
fn fusion_is_on_with_a_short_carrier_period_and_fades_with_the_weight() {
    // The traction IPM at 20 kHz (short carrier period): on; the industrial IPM at 10 kHz
    // with the simulator's sizing (`N = 4`, band top 87 rad/s: 0.07 rad per carrier
    // period, its HFI the weak side at the top of the band): off.
    let mut tr = FocConfig::new(MotorParams::traction_ipm(), 5e-5, 48.0);
    tr.current_limit_a = 250.0;
    let h = HfiConfig::new(&tr, 48.0).unwrap_or_else(|e| panic!("{e}"));
    assert_eq!(h.fusion_sigma_rad, HFI_FUSION_SIGMA_RAD, "{h:?}");
    let mut d = HfiDrive::new(&tr, &h);
    assert!(!d.weight_on_faster());
    let mut ind = ipm();
    ind.current_limit_a = 12.0;
    ind.startup.handover_speed_rad_s = 87.0;
    let long = HfiConfig::new(&ind, 540.0).unwrap_or_else(|e| panic!("{e}"));
    assert_eq!(long.fusion_sigma_rad, 0.0, "{long:?}");
    assert!(HfiDrive::new(&ind, &long).weight_on_faster());
    // Not while the standstill test runs.
    assert_eq!(d.fusion_variance(), None);
    let mut track = Track::new(Polarity {
        flipped: false,
        contrast: f32::NAN,
    });
    d.phase = Stage::Tracking(track);
    assert!(d.phase == HfiPhase::Tracking);
    let v0 = HFI_FUSION_SIGMA_RAD * HFI_FUSION_SIGMA_RAD;
    assert_eq!(d.fusion_variance(), Some(v0));
    track.weight = 0.75;
    d.phase = Stage::Tracking(track);
    let v = d.fusion_variance().unwrap_or(0.0);
    assert!((v - 4.0 * v0).abs() < 1e-6 * v0, "{v}");
    track.weight = 1.0;
    d.phase = Stage::Tracking(track);
    assert_eq!(d.fusion_variance(), None);
    track.weight = 0.5;
    track.injecting = false;
    d.phase = Stage::Tracking(track);
    assert_eq!(d.fusion_variance(), None);
    track.injecting = true;
    d.phase = Stage::Tracking(track);
    d.cfg.fusion_sigma_rad = 0.0;
    assert_eq!(d.fusion_variance(), None);
    // Checked: finite and not negative.
    for x in [-0.1, f32::NAN, f32::INFINITY] {
        let mut bad = h;
        bad.fusion_sigma_rad = x;
        assert_eq!(
            bad.validate(&tr, 48.0),
            Err(HfiError::OutOfRange(HfiField::FusionSigma))
        );
    }
    let mut off = h;
    off.fusion_sigma_rad = 0.0;
    assert_eq!(off.validate(&tr, 48.0), Ok(()));
}

#[test]
fn weight_is_linear_and_clamped() {
    assert_eq!(observer_weight(0.0, 10.0, 20.0), 0.0);
    assert_eq!(observer_weight(15.0, 10.0, 20.0), 0.5);
    assert_eq!(observer_weight(50.0, 10.0, 20.0), 1.0);
    assert_eq!(observer_weight(f32::NAN, 10.0, 20.0), 0.0);
}
