//! Whether a scenario asks for what its drive can do: the speed reference against the bus
//! voltage (with and without field weakening), the load against the current limit, and the
//! speed reference against the controller's own speed limit (`pmsm-sim check`, and `run`
//! before it runs, print the warnings on stderr; the exit code is unchanged: an infeasible
//! request is a result worth simulating, e.g. to see the drive at its limit).
//!
//! # Method
//!
//! Steady state of the dq model (amplitude-invariant currents, electrical speed `w`):
//!
//! ```text
//! u_d = Rs i_d - w Lq i_q          u_q = Rs i_q + w (Ld i_d + psi_f)
//! T   = 1.5 p (psi_f i_q + (Ld - Lq) i_d i_q)
//! ```
//!
//! - **Operating points.** The run's time is sampled (2000 even steps and every point of the
//!   speed profile and the load terms); at each sample the speed is the reference and the
//!   torque the load there at that speed plus the motor's friction (`B w + Coulomb`). The
//!   torque to accelerate the inertia is left out (the drive's speed slew rate bounds it).
//! - **Currents for a torque.** `i_d = 0` on a surface motor or with MTPA off; on an
//!   interior motor with MTPA (foc's default) the MTPA current
//!   `i_d = (psi_f - sqrt(psi_f^2 + 8 dL^2 |i|^2)) / (4 dL)`, `dL = Lq - Ld`, with `|i|`
//!   found by bisection for the torque.
//! - **Torque at the current limit** `I`: `T(I)` on that law (`1.5 p psi_f I` on a surface
//!   motor).
//! - **Voltage available** `U = max_modulation u_dc / sqrt(3)` (the linear SVPWM limit, the
//!   inscribed circle), `voltage_margin U` with field weakening (what its loop holds).
//! - **Base speed** at a torque (no field weakening): the largest `w` with `|u| <= U` on
//!   the MTPA currents, the positive root of `|u(w)|^2 = U^2` (a quadratic in `w`).
//! - **Top speed with field weakening** at a torque: the largest base speed over
//!   `i_d` from the MTPA value down to `-max_negative_id` (foc's `min(I, psi_f / Ld)` unless
//!   set), `i_q` giving the torque, `|i| <= I` (400 steps of `i_d`). At no load a motor whose
//!   characteristic current `psi_f / Ld` is within the negative d current allowed is an
//!   infinite-speed drive (the flux can be cancelled); otherwise a finite-speed one.
//! - **Controller speed limit**: foc clamps its speed command at `max_speed_rad_s`
//!   (`0.95 U / psi_f` el. by default, twice that with field weakening).
//!
//! The plant's constant parameters are used (a flux map or saturation is not read); the bus
//! is the nominal `inverter.u_dc_v` (ripple and sags are not). The warnings give the worst
//! operating point with its numbers.

use super::{RPM_PER_RAD_S, Scenario};
use crate::plant::load::load_torque_nm;

/// Even time steps of the operating-point scan (the profiles' own points are added).
const TIME_STEPS: usize = 2000;
/// Steps of `i_d` in the field-weakening search.
const ID_STEPS: usize = 400;

/// The machine's constants for the steady-state equations (module docs), SI.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Machine {
    /// Stator resistance, ohm.
    pub rs_ohm: f64,
    /// d-axis inductance, H.
    pub ld_h: f64,
    /// q-axis inductance, H.
    pub lq_h: f64,
    /// Magnet flux linkage, Wb.
    pub psi_f_wb: f64,
    /// Pole pairs.
    pub pole_pairs: f64,
}

impl Machine {
    /// Electromagnetic torque of `(i_d, i_q)`, N m.
    pub fn torque_nm(&self, id: f64, iq: f64) -> f64 {
        1.5 * self.pole_pairs * (self.psi_f_wb * iq + (self.ld_h - self.lq_h) * id * iq)
    }

    /// Whether the motor has saliency (`Lq > Ld`; MTPA adds torque).
    fn salient(&self) -> bool {
        self.lq_h > self.ld_h
    }

    /// The MTPA d current for a current magnitude `i_a` (`<= 0`; 0 without saliency).
    pub fn mtpa_id(&self, i_a: f64) -> f64 {
        if !self.salient() {
            return 0.0;
        }
        let dl = self.lq_h - self.ld_h;
        let psi = self.psi_f_wb;
        (psi - (psi * psi + 8.0 * dl * dl * i_a * i_a).sqrt()) / (4.0 * dl)
    }

    /// The currents `(i_d, i_q)` of magnitude `i_a` on the law (`mtpa`: MTPA on a salient
    /// motor; else `i_d = 0`), for positive torque.
    pub fn law_currents(&self, i_a: f64, mtpa: bool) -> (f64, f64) {
        let id = if mtpa { self.mtpa_id(i_a) } else { 0.0 };
        (id, (i_a * i_a - id * id).max(0.0).sqrt())
    }

    /// The largest torque of current magnitude `i_a` on the law, N m.
    pub fn torque_at_current_nm(&self, i_a: f64, mtpa: bool) -> f64 {
        let (id, iq) = self.law_currents(i_a, mtpa);
        self.torque_nm(id, iq)
    }

    /// The currents on the law for the torque `t_nm >= 0`, if they are at most `i_max_a`.
    pub fn currents_for_torque(&self, t_nm: f64, mtpa: bool, i_max_a: f64) -> Option<(f64, f64)> {
        if t_nm > self.torque_at_current_nm(i_max_a, mtpa) {
            return None;
        }
        let (mut lo, mut hi) = (0.0, i_max_a);
        for _ in 0..80 {
            let mid = 0.5 * (lo + hi);
            if self.torque_at_current_nm(mid, mtpa) < t_nm {
                lo = mid;
            } else {
                hi = mid;
            }
        }
        Some(self.law_currents(hi, mtpa))
    }

    /// Steady-state voltage magnitude at electrical speed `w` with `(i_d, i_q)`, V.
    pub fn voltage_v(&self, w: f64, id: f64, iq: f64) -> f64 {
        let ud = self.rs_ohm * id - w * self.lq_h * iq;
        let uq = self.rs_ohm * iq + w * (self.ld_h * id + self.psi_f_wb);
        ud.hypot(uq)
    }

    /// The largest electrical speed (rad/s) at which `(i_d, i_q)` needs at most `u_v`:
    /// the positive root of `|u(w)|^2 = u_v^2`; infinite when the flux vanishes, 0 when the
    /// resistive drop alone exceeds `u_v`.
    pub fn speed_at_voltage_rad_s(&self, id: f64, iq: f64, u_v: f64) -> f64 {
        let (a, b) = (self.rs_ohm * id, -self.lq_h * iq);
        let (c, d) = (self.rs_ohm * iq, self.ld_h * id + self.psi_f_wb);
        let qa = b * b + d * d;
        let qb = a * b + c * d;
        let qc = a * a + c * c - u_v * u_v;
        if qc > 0.0 {
            return 0.0;
        }
        if qa <= f64::EPSILON * self.psi_f_wb * self.psi_f_wb {
            return f64::INFINITY;
        }
        (-qb + (qb * qb - qa * qc).max(0.0).sqrt()) / qa
    }

    /// Base speed (rad/s el.) at the torque `t_nm`, no field weakening; `None` when the
    /// torque needs more than `i_max_a`.
    pub fn base_speed_rad_s(&self, t_nm: f64, mtpa: bool, i_max_a: f64, u_v: f64) -> Option<f64> {
        let (id, iq) = self.currents_for_torque(t_nm, mtpa, i_max_a)?;
        Some(self.speed_at_voltage_rad_s(id, iq, u_v))
    }

    /// Top speed (rad/s el.) at the torque `t_nm` with field weakening down to
    /// `i_d = -id_max_a` (module docs); `None` when the torque needs more than `i_max_a`.
    pub fn fw_top_speed_rad_s(
        &self,
        t_nm: f64,
        mtpa: bool,
        i_max_a: f64,
        id_max_a: f64,
        u_v: f64,
    ) -> Option<f64> {
        let (id0, _) = self.currents_for_torque(t_nm, mtpa, i_max_a)?;
        let mut best = 0.0f64;
        let id_end = -id_max_a.abs();
        if t_nm <= 0.0 && -id_end * self.ld_h >= self.psi_f_wb {
            return Some(f64::INFINITY);
        }
        for k in 0..=ID_STEPS {
            let id = id0 + (id_end - id0) * k as f64 / ID_STEPS as f64;
            let k_t = 1.5 * self.pole_pairs * (self.psi_f_wb + (self.ld_h - self.lq_h) * id);
            if k_t <= 0.0 {
                continue;
            }
            let iq = t_nm / k_t;
            if id.hypot(iq) > i_max_a * (1.0 + 1e-9) {
                continue;
            }
            best = best.max(self.speed_at_voltage_rad_s(id, iq, u_v));
        }
        Some(best)
    }
}

/// What a warning is about.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum WarningKind {
    /// The speed reference needs more voltage than the bus gives.
    Voltage,
    /// The load needs more torque than the current limit gives.
    Torque,
    /// The speed reference exceeds the controller's speed limit (clamped there).
    SpeedLimit,
}

/// One finding, with its numbers in words.
#[derive(Clone, Debug, PartialEq)]
pub struct Warning {
    /// What it is about.
    pub kind: WarningKind,
    /// The sentence printed (`warning: ` is prefixed by the CLI).
    pub message: String,
}

/// The drive's envelope for a scenario, and the warnings.
#[derive(Clone, Debug, PartialEq)]
pub struct Feasibility {
    /// Voltage available, `max_modulation u_dc / sqrt(3)`, V.
    pub u_available_v: f64,
    /// Torque at the current limit (MTPA on an interior motor with MTPA on), N m.
    pub torque_at_current_limit_nm: f64,
    /// Base speed at no load without field weakening, mechanical rpm.
    pub base_speed_no_load_rpm: f64,
    /// Top speed at no load with field weakening (whether on or not), mechanical rpm
    /// (infinite for an infinite-speed drive).
    pub fw_top_speed_no_load_rpm: f64,
    /// Characteristic current `psi_f / Ld`, A.
    pub characteristic_current_a: f64,
    /// Largest `|speed reference|`, rpm.
    pub peak_speed_rpm: f64,
    /// Largest `|load torque|` (friction included) over the run's operating points, N m.
    pub peak_torque_nm: f64,
    /// The findings (empty: feasible).
    pub warnings: Vec<Warning>,
}

/// The controller's settings the check needs (foc's configuration for the scenario).
struct Drive {
    i_max: f64,
    mtpa: bool,
    fw: bool,
    fw_margin: f64,
    id_max: f64,
    max_speed_e: f64,
    u_lin: f64,
}

fn drive_of(sc: &Scenario, m: &Machine) -> Drive {
    let i_max = sc.controller.current_limit_a;
    let u_nom = sc.inverter.u_dc_v / 3f64.sqrt();
    match sc.foc_config() {
        Ok(c) => {
            let id_max = c
                .field_weakening
                .max_negative_id_a
                .map_or((m.psi_f_wb / m.ld_h).min(i_max), f64::from);
            Drive {
                i_max,
                mtpa: c.mtpa,
                fw: c.field_weakening.enabled,
                fw_margin: f64::from(c.field_weakening.voltage_margin),
                id_max,
                // foc's clamp of its speed command (set for its nominal bus).
                max_speed_e: f64::from(c.max_speed_rad_s),
                u_lin: f64::from(c.max_modulation) * u_nom,
            }
        }
        // The scenario is validated before it is checked; without a configuration the
        // controller's defaults are assumed.
        Err(_) => Drive {
            i_max,
            mtpa: true,
            fw: false,
            fw_margin: 0.95,
            id_max: (m.psi_f_wb / m.ld_h).min(i_max),
            max_speed_e: f64::INFINITY,
            u_lin: u_nom,
        },
    }
}

/// `x` rpm with a sensible number of digits (`inf` spelled out).
fn rpm(x: f64) -> String {
    if x.is_infinite() {
        "unbounded".into()
    } else {
        format!("{x:.0} rpm")
    }
}

/// The feasibility of `sc` (module docs).
pub fn check(sc: &Scenario) -> Feasibility {
    let mm = &sc.motor;
    let m = Machine {
        rs_ohm: mm.rs_ohm,
        ld_h: mm.ld_h,
        lq_h: mm.lq_h,
        psi_f_wb: mm.psi_f_wb,
        pole_pairs: mm.p(),
    };
    let d = drive_of(sc, &m);
    let p = m.pole_pairs;
    let to_rpm = |w_e: f64| w_e / p * RPM_PER_RAD_S;
    let u_fw = d.fw_margin * d.u_lin;
    let t_max = m.torque_at_current_nm(d.i_max, d.mtpa);
    let base0 = m.speed_at_voltage_rad_s(0.0, 0.0, d.u_lin);
    let fw0 = m
        .fw_top_speed_rad_s(0.0, d.mtpa, d.i_max, d.id_max, u_fw)
        .unwrap_or(0.0);
    let ic = m.psi_f_wb / m.ld_h;

    // Operating points (t, |w_mech| rad/s, |T| N m).
    let mut times: Vec<f64> = (0..=TIME_STEPS)
        .map(|k| sc.duration_s * k as f64 / TIME_STEPS as f64)
        .collect();
    times.extend(sc.speed_ref_rpm.points.iter().map(|&(t, _)| t));
    times.retain(|t| (0.0..=sc.duration_s).contains(t));
    let points: Vec<(f64, f64, f64)> = times
        .iter()
        .map(|&t| {
            let w = sc.speed_ref_rpm.at(t) / RPM_PER_RAD_S;
            let friction = mm.b_nm_s_rad * w + mm.coulomb_nm * w.signum();
            let torque = if w == 0.0 {
                load_torque_nm(&sc.load, t, w)
            } else {
                load_torque_nm(&sc.load, t, w) + friction
            };
            (t, w.abs(), torque.abs())
        })
        .collect();
    let peak_speed = points.iter().map(|x| x.1).fold(0.0, f64::max);
    let peak = points
        .iter()
        .copied()
        .fold((0.0, 0.0, 0.0), |a, x| if x.2 > a.2 { x } else { a });

    let mut warnings = Vec::new();
    let u_dc = sc.inverter.u_dc_v;
    // (c) torque at the current limit.
    if peak.2 > t_max * (1.0 + 1e-9) {
        let law = if m.salient() && d.mtpa { " (MTPA)" } else { "" };
        warnings.push(Warning {
            kind: WarningKind::Torque,
            message: format!(
                "load torque {:.3} N m (at {:.3} s, {}) exceeds the {:.3} N m the current \
                 limit of {} A gives{law}: the speed will sag under it",
                peak.2,
                peak.0,
                rpm(peak.1 * RPM_PER_RAD_S),
                t_max,
                d.i_max,
            ),
        });
    }
    // (a), (b) voltage: the worst point by reference speed over attainable speed.
    // Below base speed the current loops use the whole voltage; field weakening holds
    // `voltage_margin` of it above: the larger of the two speeds.
    let base_at = |t: f64| {
        m.base_speed_rad_s(t, d.mtpa, d.i_max, d.u_lin)
            .unwrap_or(0.0)
    };
    let fw_at = |t: f64| {
        m.fw_top_speed_rad_s(t, d.mtpa, d.i_max, d.id_max, u_fw)
            .unwrap_or(0.0)
            .max(base_at(t))
    };
    let attainable = |t_nm: f64| {
        let t = t_nm.min(t_max);
        if d.fw { fw_at(t) } else { base_at(t) }
    };
    let mut worst: Option<(f64, (f64, f64, f64))> = None;
    for &(t, w, torque) in &points {
        let ratio = w * p / attainable(torque);
        if ratio > 1.0 + 1e-9 && worst.is_none_or(|(r, _)| ratio > r) {
            worst = Some((ratio, (t, w, torque)));
        }
    }
    if let Some((_, (t, w, torque))) = worst {
        let emf = w * p * m.psi_f_wb;
        let t_use = torque.min(t_max);
        let at_load = if torque > t_max {
            format!(
                ", {} at {t_max:.3} N m (the load there, {torque:.3} N m, capped at the \
                 current limit's torque)",
                rpm(to_rpm(base_at(t_use)))
            )
        } else if torque > 0.0 {
            format!(
                ", {} at the load there ({torque:.3} N m)",
                rpm(to_rpm(base_at(t_use)))
            )
        } else {
            String::new()
        };
        let kind_of_drive = if ic <= d.id_max {
            format!(
                "psi_f/Ld = {ic:.1} A within the {:.1} A of negative d current allowed: an \
                 infinite-speed drive",
                d.id_max
            )
        } else {
            format!(
                "psi_f/Ld = {ic:.1} A beyond the {:.1} A of negative d current allowed: a \
                 finite-speed drive",
                d.id_max
            )
        };
        let fw_state = if d.fw {
            "with field weakening (on)"
        } else {
            "field weakening is off; with it (field_weakening = true in [controller.foc])"
        };
        let fw_load = if torque > 0.0 {
            format!(", {} at that load", rpm(to_rpm(fw_at(t_use))))
        } else {
            String::new()
        };
        warnings.push(Warning {
            kind: WarningKind::Voltage,
            message: format!(
                "speed reference {} (at {t:.3} s) exceeds what {u_dc} V allows: back-EMF \
                 {emf:.1} V = {:.2} x the available {:.1} V (u_dc/sqrt(3)); without field \
                 weakening {} at no load{at_load}; {fw_state}: {} at no load{fw_load} \
                 ({kind_of_drive})",
                rpm(w * RPM_PER_RAD_S),
                emf / d.u_lin,
                d.u_lin,
                rpm(to_rpm(base0)),
                rpm(to_rpm(fw0.max(base0))),
            ),
        });
    }
    if peak_speed * p > d.max_speed_e * (1.0 + 1e-6) {
        warnings.push(Warning {
            kind: WarningKind::SpeedLimit,
            message: format!(
                "speed reference {} exceeds the controller's speed limit {} (foc clamps its \
                 command there; [controller.foc] max_speed_rpm sets it)",
                rpm(peak_speed * RPM_PER_RAD_S),
                rpm(to_rpm(d.max_speed_e)),
            ),
        });
    }
    Feasibility {
        u_available_v: d.u_lin,
        torque_at_current_limit_nm: t_max,
        base_speed_no_load_rpm: to_rpm(base0),
        fw_top_speed_no_load_rpm: to_rpm(fw0),
        characteristic_current_a: ic,
        peak_speed_rpm: peak_speed * RPM_PER_RAD_S,
        peak_torque_nm: peak.2,
        warnings,
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::plant::load::LoadTerm;

    fn close(a: f64, b: f64, rel: f64) -> bool {
        (a - b).abs() <= rel * b.abs().max(1e-12)
    }

    fn surface(rs: f64, l: f64, psi: f64, p: f64) -> Machine {
        Machine {
            rs_ohm: rs,
            ld_h: l,
            lq_h: l,
            psi_f_wb: psi,
            pole_pairs: p,
        }
    }

    #[test]
    fn base_speed_solves_the_voltage_circle() {
        // Rs 1 ohm, L 1 mH, psi_f 0.1 Wb, i_q 10 A, U 20 V: u_d = -0.01 w 10... by hand
        // 0.0101 w^2 + 2 w - 300 = 0, w = (-1 + sqrt(1 + 3.03)) / 0.0101 = 99.751 rad/s.
        let m = surface(1.0, 1e-3, 0.1, 1.0);
        let w = m.speed_at_voltage_rad_s(0.0, 10.0, 20.0);
        assert!(close(w, 99.751_09, 1e-6), "{w}");
        assert!(close(m.voltage_v(w, 0.0, 10.0), 20.0, 1e-9));
        // Torque 1.5 p psi_f i_q = 1.5 N m needs those 10 A.
        let b = m.base_speed_rad_s(1.5, true, 15.0, 20.0);
        assert!(b.is_some_and(|b| close(b, 99.751_09, 1e-6)), "{b:?}");
        // More torque than the current limit gives: none.
        assert_eq!(m.base_speed_rad_s(1.5, true, 9.0, 20.0), None);
        // The resistive drop alone above the voltage: 0.
        assert_eq!(m.speed_at_voltage_rad_s(0.0, 30.0, 20.0), 0.0);
        // No load: U / psi_f.
        assert!(close(
            m.speed_at_voltage_rad_s(0.0, 0.0, 20.0),
            200.0,
            1e-12
        ));
    }

    #[test]
    fn mtpa_torque_at_the_current_limit() {
        // industrial IPM: Ld 30 mH, Lq 42 mH, psi_f 0.5 Wb, p 3, 10 A. By hand:
        // i_d = (0.5 - sqrt(0.25 + 8 0.012^2 100)) / 0.048 = -2.1733 A, i_q = 9.7610 A,
        // T = 4.5 (0.5 9.7610 + 0.012 2.1733 9.7610) = 23.108 N m.
        let m = Machine {
            rs_ohm: 3.6,
            ld_h: 30e-3,
            lq_h: 42e-3,
            psi_f_wb: 0.5,
            pole_pairs: 3.0,
        };
        assert!(close(m.mtpa_id(10.0), -2.173_287, 1e-5));
        assert!(close(m.torque_at_current_nm(10.0, true), 23.107_74, 1e-5));
        // Without MTPA: k_t I = 1.5 3 0.5 10 = 22.5 N m.
        assert!(close(m.torque_at_current_nm(10.0, false), 22.5, 1e-12));
        let (id, iq) = m
            .currents_for_torque(23.107_74, true, 10.0)
            .unwrap_or_default();
        assert!(close(id, -2.173_287, 1e-4) && close(iq, 9.760_985, 1e-4));
        assert_eq!(m.currents_for_torque(23.2, true, 10.0), None);
    }

    #[test]
    fn field_weakening_finite_and_infinite_speed_drives() {
        // psi_f / L = 100 A > 10 A: finite; no load, Rs 0: w = U / (psi_f - L I)
        // = 19 / (0.1 - 0.01) = 211.11 rad/s.
        let m = surface(0.0, 1e-3, 0.1, 1.0);
        let w = m.fw_top_speed_rad_s(0.0, true, 10.0, 10.0, 19.0);
        assert!(w.is_some_and(|w| close(w, 211.111_1, 1e-6)), "{w:?}");
        // psi_f / L = 10 A within the 10 A allowed: the flux can be cancelled.
        let m = surface(0.0, 1e-2, 0.1, 1.0);
        assert_eq!(
            m.fw_top_speed_rad_s(0.0, true, 10.0, 10.0, 19.0),
            Some(f64::INFINITY)
        );
        // Under load finite, and above the base speed 190 rad/s.
        let w = m.fw_top_speed_rad_s(0.5, true, 10.0, 10.0, 19.0);
        assert!(w.is_some_and(|w| w.is_finite() && w > 190.0), "{w:?}");
    }

    fn drone() -> Scenario {
        Scenario::preset("drone").unwrap_or_else(|e| panic!("{e}"))
    }

    #[test]
    fn an_impossible_speed_at_24_v_is_reported_with_its_numbers() {
        let mut sc = drone();
        sc.inverter.u_dc_v = 24.0;
        sc.speed_ref_rpm.points = vec![(0.02, 0.0), (0.5, 15000.0)];
        sc.load.clear();
        let f = check(&sc);
        // 24 / sqrt(3) / 0.006 / 7 rad/s = 3150 rpm.
        assert!(close(f.u_available_v, 13.856, 1e-4));
        assert!(close(f.base_speed_no_load_rpm, 3150.45, 1e-5));
        let v: Vec<_> = f
            .warnings
            .iter()
            .filter(|w| w.kind == WarningKind::Voltage)
            .collect();
        assert_eq!(v.len(), 1, "{:?}", f.warnings);
        let msg = &v[0].message;
        assert!(
            msg.contains("speed reference 15000 rpm")
                && msg.contains("what 24 V allows: back-EMF 66.0 V = 4.76 x the available 13.9 V")
                && msg.contains("without field weakening 3150 rpm at no load")
                && msg.contains("field weakening is off"),
            "{msg}"
        );
        // foc's own limit (0.95 of the base speed of its 24 V) clamps it too.
        assert!(f.warnings.iter().any(|w| w.kind == WarningKind::SpeedLimit));
    }

    #[test]
    fn a_load_beyond_the_current_limit_is_reported() {
        let mut sc = drone();
        let f = check(&sc);
        assert!(f.warnings.is_empty(), "{:?}", f.warnings);
        // k_t I = 1.5 7 0.006 15 = 0.945 N m.
        assert!(close(f.torque_at_current_limit_nm, 0.945, 1e-9));
        sc.load.push(LoadTerm::Constant { torque_nm: 0.8 });
        let f = check(&sc);
        assert_eq!(f.warnings.len(), 1, "{:?}", f.warnings);
        assert_eq!(f.warnings[0].kind, WarningKind::Torque);
        assert!(
            f.warnings[0].message.contains("0.945 N m"),
            "{:?}",
            f.warnings
        );
    }

    #[test]
    fn the_shipped_presets_ask_for_what_their_drive_can_do() {
        for (name, _) in crate::scenario::PRESETS {
            let sc = Scenario::preset(name).unwrap_or_else(|e| panic!("{e}"));
            let f = check(&sc);
            assert!(f.warnings.is_empty(), "{name}: {:?}", f.warnings);
            assert!(f.peak_speed_rpm > 0.0, "{name}");
        }
    }
}
