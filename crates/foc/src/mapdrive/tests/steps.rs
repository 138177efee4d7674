//! Current-loop step responses on a saturating plant (the map's flux as state), gains
//! scheduled on the map's incremental inductances against the constant small-signal ones.

use super::*;
use crate::pi::{Pi, PiGains};

/// PWM period, s.
const TS: f64 = 1e-4;
/// Euler substeps of the plant per period.
const SUB: usize = 20;

/// What a step response shows on the q current.
#[derive(Debug)]
struct Step {
    /// Largest excursion beyond the final value, % of the step.
    overshoot_pct: f64,
    /// Last time outside a 2 % band around the final value, ms after the step.
    settle_ms: f64,
    /// Peak-to-peak over the last 5 ms, % of the step.
    ripple_pct: f64,
}

/// The step of the torque command from `from` to `to` (A, surface-equivalent) at the speed
/// `w` (rad/s el.), the references from the MTPA table, on the map plant (no voltage
/// limit), with a one-period computation delay; `scheduled`: `Kp` and decoupling from the
/// map (module docs), else from the small-signal constants as the default drive has them.
fn step(c: &Case, t: &MapMtpa<MTPA_POINTS>, scheduled: bool, from: f32, to: f32, w: f64) -> Step {
    let r = &c.m.reference;
    let bw = (0.1 * core::f64::consts::PI / TS) as f32;
    let (ld0, lq0, psi_f, rs) = (
        r.ld_h as f32,
        r.lq_h as f32,
        r.psi_f_wb as f32,
        r.rs_ohm as f32,
    );
    let wf = w as f32;
    let gains = |kp: f32| PiGains { kp, ki: rs * bw };
    let mut pi_d = Pi::new(gains(ld0 * bw), TS as f32);
    let mut pi_q = Pi::new(gains(lq0 * bw), TS as f32);
    // Feed-forward at the measured currents for the command `it`.
    let ff = |it: f32, i: Dq| -> (Dq, MapPoint) {
        let p = t.lookup(it);
        if scheduled {
            let psi = p.flux_at(i);
            (
                Dq {
                    d: -wf * psi.q,
                    q: wf * psi.d,
                },
                p,
            )
        } else {
            (
                Dq {
                    d: -wf * lq0 * i.q,
                    q: wf * (ld0 * i.d + psi_f),
                },
                p,
            )
        }
    };
    // Start in steady state at the first command.
    let p0 = t.lookup(from);
    let (mut id, mut iq) = (f64::from(p0.i.d), f64::from(p0.i.q));
    let e0 = c.map.eval(id, iq);
    let (mut pd, mut pq) = (e0.psi_d, e0.psi_q);
    let u_ss = Dq {
        d: (r.rs_ohm * id - w * pq) as f32,
        q: (r.rs_ohm * iq + w * pd) as f32,
    };
    let (f0, _) = ff(from, p0.i);
    pi_d.set_integrator(u_ss.d - f0.d);
    pi_q.set_integrator(u_ss.q - f0.q);
    let mut u_applied = u_ss;
    let (k_step, k_end) = (50usize, 50 + 300);
    let q1 = f64::from(t.lookup(to).i.q);
    let q0 = f64::from(p0.i.q);
    let span = q1 - q0;
    let mut trace = Vec::new();
    for k in 0..k_end {
        let it = if k < k_step { from } else { to };
        let i = Dq {
            d: id as f32,
            q: iq as f32,
        };
        let (f, p) = ff(it, i);
        if scheduled {
            pi_d.set_kp(bw * p.l_dd);
            pi_q.set_kp(bw * p.l_qq);
        }
        let u = Dq {
            d: pi_d.step(p.i.d - i.d, f.d, -1e6, 1e6),
            q: pi_q.step(p.i.q - i.q, f.q, -1e6, 1e6),
        };
        if k >= k_step {
            trace.push(iq);
        }
        // The plant over [t_k, t_k+1) under the voltage computed by the last tick (tick k's
        // applies over [t_k+1, t_k+2): one period of computation delay).
        let h = TS / SUB as f64;
        for _ in 0..SUB {
            let (ud, uq) = (f64::from(u_applied.d), f64::from(u_applied.q));
            pd += h * (ud - r.rs_ohm * id + w * pq);
            pq += h * (uq - r.rs_ohm * iq - w * pd);
            let (a, b) = c.map.currents(pd, pq, (id, iq), 30, 1e-12).unwrap();
            (id, iq) = (a, b);
        }
        u_applied = u;
    }
    let overshoot = trace
        .iter()
        .map(|&x| (x - q1) / span)
        .fold(f64::MIN, f64::max)
        .max(0.0);
    let settle = trace
        .iter()
        .rposition(|&x| ((x - q1) / span).abs() > 0.02)
        .map_or(0.0, |k| (k + 1) as f64 * TS * 1e3);
    let tail = &trace[trace.len() - 50..];
    let (lo, hi) = tail
        .iter()
        .fold((f64::MAX, f64::MIN), |(a, b), &x| (a.min(x), b.max(x)));
    Step {
        overshoot_pct: 100.0 * overshoot,
        settle_ms: settle,
        ripple_pct: 100.0 * (hi - lo) / span.abs(),
    }
}

#[test]
fn scheduled_gains_stay_damped_through_the_saturation_knee() {
    for m in [PM_SYRM, SATURATED_IPM] {
        let c = case(m);
        let r = &m.reference;
        let t = MapMtpa::<MTPA_POINTS>::from_map(&c.map, r.pole_pairs, c.k_t, (2.0 * c.i_r) as f32)
            .unwrap();
        let it_r = (r.rated_torque_nm / f64::from(c.k_t)) as f32;
        let w = 0.2 * r.rated_speed_rpm * core::f64::consts::PI / 30.0 * f64::from(r.pole_pairs);
        let pr = t.lookup(it_r);
        println!(
            "{}: bw 500 Hz, Ts 100 us, w {w:.0} rad/s el.; L_dd, L_qq at rated {:.1}, {:.1} mH \
             (small-signal {:.1}, {:.1} mH)",
            r.name,
            1e3 * pr.l_dd,
            1e3 * pr.l_qq,
            1e3 * r.ld_h,
            1e3 * r.lq_h
        );
        for (name, from, to) in [("low", 0.0, 0.1 * it_r), ("rated", 0.9 * it_r, it_r)] {
            let s = step(&c, &t, true, from, to, w);
            let k = step(&c, &t, false, from, to, w);
            println!(
                "  {name} (torque {:.0} -> {:.0} %): scheduled overshoot {:.1} %, settles in \
                 {:.2} ms, ripple {:.2} %; constant overshoot {:.1} %, settles in {:.2} ms, \
                 ripple {:.2} %",
                100.0 * from / it_r,
                100.0 * to / it_r,
                s.overshoot_pct,
                s.settle_ms,
                s.ripple_pct,
                k.overshoot_pct,
                k.settle_ms,
                k.ripple_pct
            );
            assert!(
                s.overshoot_pct < 10.0 && s.settle_ms < 3.0 && s.ripple_pct < 1.0,
                "{name}: {s:?}"
            );
            // Constant small-signal gains ring where the incremental inductance has fallen.
            if name == "rated" {
                assert!(k.overshoot_pct > 30.0, "{name}: {k:?}");
            }
        }
    }
}
