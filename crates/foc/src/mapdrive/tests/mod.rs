//! The tables on the reference saturating motors (`ekf_core::saturation`): MTPA optimality,
//! field weakening at twice base speed, current-loop step responses with scheduled gains.
//! `cargo test -p foc --lib mapdrive -- --nocapture` prints the numbers of
//! docs/saturation.md.

use ekf_core::FluxMap;
use ekf_core::saturation::{PM_SYRM, SATURATED_IPM, SaturatedMotor};

use super::*;
use crate::mtpa::Mtpa;

/// Grid capacity of the test maps.
const N: usize = 16;

/// The rated point on the model's MTPA curve (as pmsm-sim's suite defines it): the least
/// current magnitude whose best torque over the angle is the rated torque, A.
fn rated_current(m: &SaturatedMotor) -> f64 {
    let p = f64::from(m.reference.pole_pairs);
    let torque = |i: f64, beta: f64| {
        let (id, iq) = (-i * beta.sin(), i * beta.cos());
        m.model
            .flux(id, iq, (m.reference.psi_f_wb, 0.0))
            .map_or(0.0, |(pd, pq)| 1.5 * p * (pd * iq - pq * id))
    };
    let best = |i: f64| {
        let (mut a, mut b) = (0.0, 1.4f64);
        let g = 0.5 * (5f64.sqrt() - 1.0);
        for _ in 0..60 {
            let (c, d) = (b - g * (b - a), a + g * (b - a));
            if torque(i, c) > torque(i, d) {
                b = d;
            } else {
                a = c;
            }
        }
        torque(i, 0.5 * (a + b))
    };
    let (mut lo, mut hi) = (
        0.0,
        10.0 * m.reference.rated_torque_nm / (1.5 * p * m.reference.psi_f_wb),
    );
    for _ in 0..60 {
        let mid = 0.5 * (lo + hi);
        if best(mid) < m.reference.rated_torque_nm {
            lo = mid;
        } else {
            hi = mid;
        }
    }
    hi
}

/// The motor's model sampled on 12 x 16 points over `i_d` in `[-2.2, 0.8] I_r`, `i_q` in
/// `[-2.2, 2.2] I_r` (the grid of the suite's saturated rows).
fn map_of(m: &SaturatedMotor, i_r: f64) -> FluxMap<f64, N> {
    let axis = |n: usize, lo: f64, hi: f64| -> Vec<f64> {
        (0..n)
            .map(|k| i_r * (lo + (hi - lo) * k as f64 / (n - 1) as f64))
            .collect()
    };
    m.model
        .flux_map::<f64, N>(&axis(12, -2.2, 0.8), &axis(16, -2.2, 2.2))
        .unwrap()
}

struct Case {
    m: SaturatedMotor,
    map: FluxMap<f64, N>,
    i_r: f64,
    k_t: f32,
    p: f64,
}

fn case(m: SaturatedMotor) -> Case {
    let i_r = rated_current(&m);
    let map = map_of(&m, i_r);
    let r = &m.reference;
    Case {
        m,
        map,
        i_r,
        k_t: (1.5 * f64::from(r.pole_pairs) * r.psi_f_wb) as f32,
        p: f64::from(r.pole_pairs),
    }
}

impl Case {
    fn torque(&self, d: f64, q: f64) -> f64 {
        let e = self.map.eval(d, q);
        1.5 * self.p * (e.psi_d * q - e.psi_q * d)
    }
    fn flux(&self, d: f64, q: f64) -> f64 {
        let e = self.map.eval(d, q);
        e.psi_d.hypot(e.psi_q)
    }
    /// The map's best torque at magnitude `i`: a scan of 4000 angles, refined by a finer
    /// scan around the best (independent of the table's search).
    fn best_torque(&self, i: f64) -> f64 {
        let h = core::f64::consts::PI / 4000.0;
        let mut best = (0.0, f64::MIN);
        for k in 1..4000 {
            let b = -core::f64::consts::FRAC_PI_2 + h * k as f64;
            let v = self.torque(-i * b.sin(), i * b.cos());
            if v > best.1 {
                best = (b, v);
            }
        }
        for k in -100..=100 {
            let b = best.0 + h * k as f64 / 100.0;
            best.1 = best.1.max(self.torque(-i * b.sin(), i * b.cos()));
        }
        best.1
    }
}

mod steps;
mod wired;

#[test]
fn mtpa_table_has_the_maps_torque_per_ampere() {
    for m in [PM_SYRM, SATURATED_IPM] {
        let c = case(m);
        let lim = (2.0 * c.i_r) as f32;
        let t =
            MapMtpa::<MTPA_POINTS>::from_map(&c.map, m.reference.pole_pairs, c.k_t, lim).unwrap();
        let small = Mtpa::new(&ekf_core::MotorParams {
            ld_h: m.reference.ld_h as f32,
            lq_h: m.reference.lq_h as f32,
            psi_f_wb: m.reference.psi_f_wb as f32,
            ..ekf_core::MotorParams::industrial_ipm()
        });
        println!(
            "{}: rated current {:.3} A, table up to {:.2} A ({:.2} N m)",
            m.reference.name,
            c.i_r,
            lim,
            t.torque_current_max() * c.k_t
        );
        let mut worst_tpa = 1.0f64;
        let mut worst_t = 0.0f64;
        for level in [0.25, 0.5, 0.75, 1.0, 1.5, 2.0] {
            let i = level * c.i_r;
            let t_opt = c.best_torque(i);
            let p = t.lookup((t_opt / f64::from(c.k_t)) as f32);
            let (d, q) = (f64::from(p.i.d), f64::from(p.i.q));
            let mag = d.hypot(q);
            let tq = c.torque(d, q);
            // Torque per ampere against the optimum at the commanded magnitude.
            let ratio = (tq / mag) / (c.best_torque(mag) / mag);
            let t_err = (tq - t_opt) / t_opt;
            // The constant-parameter law for the same torque (small-signal Ld, Lq, psi_f).
            let s = small.currents_for_torque((t_opt / f64::from(c.k_t)) as f32);
            let (sd, sq) = (f64::from(s.d), f64::from(s.q));
            let s_ratio =
                (c.torque(sd, sq) / sd.hypot(sq)) / (c.best_torque(sd.hypot(sq)) / sd.hypot(sq));
            println!(
                "  {level:.2} I_r: |i| {mag:.3} A (optimum {i:.3}), T/A / optimum {ratio:.5}, \
                 torque error {:+.4} %; small-signal law: T/A / optimum {s_ratio:.4}, torque \
                 {:+.2} %",
                100.0 * t_err,
                100.0 * (c.torque(sd, sq) - t_opt) / t_opt
            );
            worst_tpa = worst_tpa.min(ratio);
            worst_t = worst_t.max(t_err.abs());
            assert!(
                ratio > 0.99 && t_err.abs() < 0.01,
                "{level}: {ratio} {t_err}"
            );
        }
        // Between the table's points (worst case of the interpolation), every 1/7 of a cell.
        let mut worst_mid = (1.0f64, 0.0f64);
        let n = 7 * (MTPA_POINTS - 1);
        for k in 1..n {
            // Evenly in the square root of the torque, as the table's points are.
            let x = k as f32 / n as f32;
            let it = t.torque_current_max() * x * x;
            let p = t.lookup(it);
            let (d, q) = (f64::from(p.i.d), f64::from(p.i.q));
            let mag = d.hypot(q);
            let tq = c.torque(d, q);
            let want = f64::from(it * c.k_t);
            worst_mid.0 = worst_mid.0.min(tq / c.best_torque(mag));
            worst_mid.1 = worst_mid.1.max(((tq - want) / want).abs());
            // Symmetric: the opposite command gives the opposite torque.
            let n = t.lookup(-it);
            assert_eq!((n.i.d, n.i.q), (p.i.d, -p.i.q));
        }
        println!(
            "  worst over the levels: T/A / optimum {worst_tpa:.5}, |torque error| {:.4} %; \
             between table points: T/A / optimum {:.5}, |torque error| {:.3} %",
            100.0 * worst_t,
            worst_mid.0,
            100.0 * worst_mid.1
        );
        assert!(worst_mid.0 > 0.99 && worst_mid.1 < 0.01, "{worst_mid:?}");
    }
}

#[test]
fn table_sizes_are_as_documented() {
    assert_eq!(core::mem::size_of::<MapPoint>(), 32);
    assert_eq!(
        core::mem::size_of::<MapMtpa<MTPA_POINTS>>(),
        MTPA_POINTS * 32 + 16
    );
    assert_eq!(
        core::mem::size_of::<MapFieldWeakening<FW_ROWS, FW_COLUMNS>>(),
        FW_ROWS * (FW_COLUMNS * 32 + 4) + 12
    );
}

#[test]
fn tables_refuse_bad_input() {
    let c = case(SATURATED_IPM);
    assert_eq!(
        MapMtpa::<1>::from_map(&c.map, 3, c.k_t, 10.0),
        Err(MapTableError::TooFewPoints)
    );
    assert_eq!(
        MapMtpa::<8>::from_map(&c.map, 3, f32::NAN, 10.0),
        Err(MapTableError::BadArgument("torque_constant_nm_a"))
    );
    assert_eq!(
        MapMtpa::<8>::from_map(&c.map, 0, c.k_t, 10.0),
        Err(MapTableError::BadArgument("pole_pairs"))
    );
    let t = MapMtpa::<8>::from_map(&c.map, 3, c.k_t, 10.0).unwrap();
    assert!(matches!(
        MapFieldWeakening::<4, 4>::from_map(&c.map, 3, &t, 1.0),
        Err(MapTableError::BadArgument(_))
    ));
    // Lookups never panic and stay finite on wild input.
    for x in [f32::NAN, f32::INFINITY, -1e30, 0.0] {
        let p = t.lookup(x);
        assert!(p.i.d.is_finite() && p.i.q.is_finite(), "{x}: {p:?}");
    }
    let e = MapTableError::Asymmetric(3.0).to_string();
    assert!(e.contains("symmetric"), "{e}");
}

#[test]
fn fw_table_holds_the_flux_limit_at_twice_base_speed() {
    let m = SATURATED_IPM;
    let c = case(m);
    let r = &m.reference;
    let lim = 2.0 * c.i_r;
    let tables = MapTables::from_map(&c.map, r.pole_pairs, c.k_t, lim as f32, 4.0).unwrap();
    // Base speed: the rated MTPA point reaches the margin's voltage (the triangle bound of
    // the module docs).
    let (k, u_max) = (0.95, r.u_dc_v / 3f64.sqrt());
    let rated = tables
        .mtpa
        .lookup((r.rated_torque_nm / f64::from(c.k_t)) as f32);
    let (rd, rq) = (f64::from(rated.i.d), f64::from(rated.i.q));
    let w_base = (k * u_max - r.rs_ohm * rd.hypot(rq)) / c.flux(rd, rq);
    let w = 2.0 * w_base;
    // The drive's flux limit with the current limit's resistive drop (conservative).
    let psi_lim = (k * u_max - r.rs_ohm * lim) / w;
    // The best achievable torque: a dense polar search within both limits.
    let mut t_best = 0.0f64;
    for a in 1..=300 {
        let i = lim * a as f64 / 300.0;
        for b in 0..400 {
            let beta = core::f64::consts::FRAC_PI_2 * b as f64 / 400.0;
            let (d, q) = (-i * beta.sin(), i * beta.cos());
            if c.flux(d, q) <= psi_lim {
                t_best = t_best.max(c.torque(d, q));
            }
        }
    }
    println!(
        "{}: base speed {:.0} rad/s el., at {:.0} rad/s: flux limit {:.4} Wb (MTPA flux at \
         rated {:.4} Wb); best torque within the limits {:.3} N m (rated {:.1})",
        r.name,
        w_base,
        w,
        psi_lim,
        c.flux(rd, rq),
        t_best,
        r.rated_torque_nm
    );
    let t_max = f64::from(tables.fw.torque_current_max(psi_lim as f32) * c.k_t);
    let mut worst_flux = 0.0f64;
    let mut worst_mag = 0.0f64;
    for frac in [0.1, 0.25, 0.5, 0.75, 0.9, 1.0, 1.5] {
        let cmd = frac * t_best;
        let p = tables
            .fw
            .lookup((cmd / f64::from(c.k_t)) as f32, psi_lim as f32);
        let (d, q) = (f64::from(p.i.d), f64::from(p.i.q));
        let tq = c.torque(d, q);
        let flux = c.flux(d, q) / psi_lim;
        let mag = d.hypot(q);
        // The least current that makes the same torque within the flux limit (dense scan of
        // the constant-torque curve).
        let mut least = f64::MAX;
        if frac <= 1.0 {
            for a in 0..4000 {
                let dd = -lim + 1.5 * lim * a as f64 / 4000.0;
                let (mut lo, mut hi) = (0.0, 3.0 * lim);
                for _ in 0..50 {
                    let mid = 0.5 * (lo + hi);
                    if c.torque(dd, mid) < cmd {
                        lo = mid
                    } else {
                        hi = mid
                    }
                }
                if c.flux(dd, hi) <= psi_lim {
                    least = least.min(dd.hypot(hi));
                }
            }
        }
        println!(
            "  command {:.3} N m ({:.0} % of the best): torque {:.3} N m, |psi| / limit \
             {flux:.4}, |i| {mag:.3} A (least {})",
            cmd,
            100.0 * frac,
            tq,
            if least < f64::MAX {
                format!("{least:.3} A")
            } else {
                "-".into()
            }
        );
        worst_flux = worst_flux.max(flux);
        assert!(flux <= 1.005, "{frac}: flux {flux}");
        assert!(mag <= lim * 1.002, "{frac}: |i| {mag}");
        if frac <= 1.0 {
            assert!((tq - cmd).abs() <= 0.01 * t_best, "{frac}: {tq} vs {cmd}");
            worst_mag = worst_mag.max(mag / least);
            assert!(mag <= 1.01 * least + 1e-3, "{frac}: {mag} vs {least}");
        } else {
            // Above the achievable: the most torque, within 1 % of the best.
            assert!(tq >= 0.99 * t_best, "{tq} vs {t_best}");
        }
    }
    println!(
        "  table's largest torque {t_max:.3} N m ({:+.2} % vs the best), worst |psi| / limit \
         {worst_flux:.4}, worst |i| / least {worst_mag:.4}",
        100.0 * (t_max / t_best - 1.0)
    );
    assert!((t_max / t_best - 1.0).abs() < 0.01);
}
