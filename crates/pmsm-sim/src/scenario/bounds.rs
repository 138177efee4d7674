//! Plausibility bounds of the scenario's values, and the observers' and `foc`'s refusals in
//! the scenario's own keys.
//!
//! The per-section checks (`motor`, `inverter`, `sensors`, load terms, faults) refuse what is
//! physically invalid (a negative inductance, a dead time longer than half the period). The
//! bounds here refuse what is valid in sign but so large that a run would overflow `f64` or
//! mean nothing: every number a run turns into a torque, a speed or a current is bounded
//! relative to the scenario's own ratings, so that one absurd value is refused at `check`,
//! by its key, with the allowed range, before any output is written.
//!
//! | keys | allowed |
//! |---|---|
//! | `motor.rs_ohm`, `ld_h`, `lq_h`, `psi_f_wb`, `pole_pairs` | the observer's plausible ranges: `0 < Rs <= 1000` ohm, `1e-8 <= L <= 10` H, `0 < psi_f <= 100` Wb, `1 <= p <= 1000` ([`MotorModel::validate`]) |
//! | `motor.j_kg_m2`, `b_nm_s_rad`, `coulomb_nm` | `1e-10 <= J <= 1e6` kg m^2, `0 <= B <= 1e6` N m s/rad, `0 <= Tc <= 1e6` N m |
//! | `inverter.ts_s`, `u_dc_v` | `1e-7 <= ts <= 1` s (the observer's range), `1 <= u_dc <= 1e5` V ([`InverterConfig::validate`]) |
//! | `controller.current_bandwidth_hz`, `speed_bandwidth_hz` | `>= 1` Hz and `<=` a tenth of the PWM frequency, `>= 0.01` Hz and `<=` a fifth of the current loop's |
//! | `faults[i]` of `param_drift`: `temperature_rise_k`, `rs_per_k`, `psi_f_per_k` | `abs(x) <= 500` K, `abs(x) <= 0.02` per K |
//! | `faults[i].duration_s`, `time_constant_s` | `0 < x <= 1e9` s |
//! | `rated_speed_rpm` | `0 < x <= 1e6` rpm |
//! | `rated_torque_nm` | `0 < x <= 1e6` N m |
//! | `initial.speed_rpm`, `speed_ref_rpm.points[i]` speeds | `abs(x) <= 10 rated_speed_rpm` |
//! | `initial.theta_e_rad` | `abs(x) <= 1e6` rad |
//! | load torques (`torque_nm`, `before_nm`, `after_nm`, `from_nm`, `to_nm`, `max_torque_nm`, table torques), `faults[i].torque_nm` | `abs(x) <= 100 rated_torque_nm` |
//! | `load[i].coefficient_nm_s_rad` (viscous) | `0 <= x`, `x w_rated <= 100 rated_torque_nm` |
//! | `load[i].coefficient_nm_s2_rad2` (fan) | `0 <= x`, `x w_rated^2 <= 100 rated_torque_nm` |
//! | `load[i].power_w` (constant power) | `0 < x <= 100 rated_torque_nm w_rated` |
//! | times of load terms and profiles (`time_s`, `start_s`, `end_s`, `ramp_s`, points' times) | `abs(x) <= 1e9` s |
//! | `faults[i].value_a` (stuck, glitch) | `abs(x) <= 100` rated currents |
//!
//! (`w_rated` is `rated_speed_rpm` in mechanical rad/s.) Values `foc` derives its own settings
//! from (currents, speeds, times of `[controller.foc]`) are also checked by `foc`. The observers' refusals
//! (`ekf_core::ConfigError`) and `foc`'s (`foc::ConfigError`) name an internal parameter; they
//! are reported under the key the value came from (`Scenario::observer_error`,
//! `Scenario::foc_error`): an
//! `[observer]` override when it is set, else the `[motor]`, `[inverter]` or `[controller]`
//! key it defaults to.

use super::*;
use crate::error::plain;
#[cfg(doc)]
use crate::plant::{MotorModel, inverter::InverterConfig};
use ekf_core::{Matrix, Param};

/// Largest rated speed, rpm.
pub const MAX_RATED_SPEED_RPM: f64 = 1e6;
/// Largest rated torque, N m.
pub const MAX_RATED_TORQUE_NM: f64 = 1e6;
/// Speeds (initial, reference) up to this multiple of the rated speed.
pub const SPEED_FACTOR: f64 = 10.0;
/// Torques (load, overload), currents of faults and load powers up to this multiple of the
/// rated value.
pub const TORQUE_FACTOR: f64 = 100.0;
/// Largest absolute time of a profile or load term, s.
pub const MAX_TIME_S: f64 = 1e9;
/// Largest absolute initial angle, rad.
pub const MAX_ANGLE_RAD: f64 = 1e6;

/// `Err` naming `field` unless `ok`; the problem states the allowed range and the value.
pub(crate) fn allowed(field: &str, ok: bool, range: &str, v: f64) -> Result<(), FieldError> {
    if ok {
        Ok(())
    } else {
        Err(FieldError::new(
            field,
            format!("allowed: {range}, is {}", plain(v)),
        ))
    }
}

/// `abs(v) <= max` (and finite).
fn magnitude(field: &str, v: f64, max: f64, what: &str) -> Result<(), FieldError> {
    allowed(field, v.abs() <= max, &format!("abs(x) <= {what}"), v)
}

impl Scenario {
    /// The bounds of the module docs.
    pub(crate) fn check_bounds(&self) -> Result<(), FieldError> {
        let (n_rated, t_rated) = (self.rated_speed_rpm, self.rated_torque_nm);
        allowed(
            "rated_speed_rpm",
            n_rated > 0.0 && n_rated <= MAX_RATED_SPEED_RPM,
            &format!("0 < x <= {} rpm", plain(MAX_RATED_SPEED_RPM)),
            n_rated,
        )?;
        allowed(
            "rated_torque_nm",
            t_rated > 0.0 && t_rated <= MAX_RATED_TORQUE_NM,
            &format!("0 < x <= {} N m", plain(MAX_RATED_TORQUE_NM)),
            t_rated,
        )?;
        let n_max = SPEED_FACTOR * n_rated;
        let speed_text = format!("{SPEED_FACTOR} rated_speed_rpm = {} rpm", plain(n_max));
        magnitude(
            "initial.speed_rpm",
            self.initial.speed_rpm,
            n_max,
            &speed_text,
        )?;
        magnitude(
            "initial.theta_e_rad",
            self.initial.theta_e_rad,
            MAX_ANGLE_RAD,
            &format!("{} rad", plain(MAX_ANGLE_RAD)),
        )?;
        let time_text = format!("{} s", plain(MAX_TIME_S));
        for (i, &(t, n)) in self.speed_ref_rpm.points.iter().enumerate() {
            let field = format!("speed_ref_rpm.points[{i}]");
            magnitude(&field, t, MAX_TIME_S, &time_text)?;
            magnitude(&field, n, n_max, &speed_text)?;
        }
        let t_max = TORQUE_FACTOR * t_rated;
        let w_rated = self.rated_speed_mech_rad_s();
        for (i, term) in self.load.iter().enumerate() {
            self.check_load_term(&format!("load[{i}]"), term, t_max, w_rated)?;
        }
        let i_rated = self.fault_context().rated_current_a;
        let torque_text = format!("{TORQUE_FACTOR} rated_torque_nm = {} N m", plain(t_max));
        for (i, f) in self.faults.iter().enumerate() {
            let field = |k: &str| format!("faults[{i}].{k}");
            match *f {
                FaultSpec::Overload { torque_nm, .. } => {
                    magnitude(&field("torque_nm"), torque_nm, t_max, &torque_text)?;
                }
                FaultSpec::Stuck {
                    value_a: Some(v), ..
                }
                | FaultSpec::Glitch {
                    value_a: Some(v), ..
                } => {
                    let i_max = TORQUE_FACTOR * i_rated;
                    magnitude(
                        &field("value_a"),
                        v,
                        i_max,
                        &format!("{TORQUE_FACTOR} rated currents = {} A", plain(i_max)),
                    )?;
                }
                _ => {}
            }
        }
        Ok(())
    }

    fn check_load_term(
        &self,
        field: &str,
        term: &LoadTerm,
        t_max: f64,
        w_rated: f64,
    ) -> Result<(), FieldError> {
        let key = |k: &str| format!("{field}.{k}");
        let torque_text = format!("{TORQUE_FACTOR} rated_torque_nm = {} N m", plain(t_max));
        let torque = |k: &str, v: f64| magnitude(&key(k), v, t_max, &torque_text);
        let time_text = format!("{} s", plain(MAX_TIME_S));
        let time = |k: &str, v: f64| magnitude(&key(k), v, MAX_TIME_S, &time_text);
        match term {
            LoadTerm::Constant { torque_nm } => torque("torque_nm", *torque_nm),
            LoadTerm::Step {
                time_s,
                before_nm,
                after_nm,
            } => {
                time("time_s", *time_s)?;
                torque("before_nm", *before_nm)?;
                torque("after_nm", *after_nm)
            }
            LoadTerm::Ramp {
                start_s,
                end_s,
                from_nm,
                to_nm,
            } => {
                time("start_s", *start_s)?;
                time("end_s", *end_s)?;
                torque("from_nm", *from_nm)?;
                torque("to_nm", *to_nm)
            }
            LoadTerm::Viscous {
                coefficient_nm_s_rad: k,
            } => {
                let k_max = t_max / w_rated;
                allowed(
                    &key("coefficient_nm_s_rad"),
                    (0.0..=k_max).contains(k),
                    &format!(
                        "0 <= x <= {} N m s/rad ({TORQUE_FACTOR} rated_torque_nm at the rated \
                         speed)",
                        plain(k_max)
                    ),
                    *k,
                )
            }
            LoadTerm::Fan {
                coefficient_nm_s2_rad2: k,
            } => {
                let k_max = t_max / (w_rated * w_rated);
                allowed(
                    &key("coefficient_nm_s2_rad2"),
                    (0.0..=k_max).contains(k),
                    &format!(
                        "0 <= x <= {} N m s^2/rad^2 ({TORQUE_FACTOR} rated_torque_nm at the \
                         rated speed)",
                        plain(k_max)
                    ),
                    *k,
                )
            }
            LoadTerm::ConstantPower {
                power_w,
                max_torque_nm,
                start_s,
                ramp_s,
            } => {
                let p_max = t_max * w_rated;
                allowed(
                    &key("power_w"),
                    *power_w > 0.0 && *power_w <= p_max,
                    &format!(
                        "0 < x <= {} W ({TORQUE_FACTOR} rated_torque_nm at the rated speed)",
                        plain(p_max)
                    ),
                    *power_w,
                )?;
                torque("max_torque_nm", *max_torque_nm)?;
                time("start_s", *start_s)?;
                time("ramp_s", *ramp_s)
            }
            LoadTerm::Table { points, .. } => {
                for (i, &(t, v)) in points.iter().enumerate() {
                    let k = format!("points[{i}]");
                    time(&k, t)?;
                    torque(&k, v)?;
                }
                Ok(())
            }
        }
    }

    /// The key a refusal of the observer's parameter `p` is about (module docs).
    pub(crate) fn observer_key(&self, p: Param) -> &'static str {
        let o = &self.observer;
        match p {
            Param::Rs if o.rs_ohm.is_some() => "observer.rs_ohm",
            Param::Rs => "motor.rs_ohm",
            Param::Ld if o.ld_h.is_some() => "observer.ld_h",
            Param::Lq if o.lq_h.is_some() => "observer.lq_h",
            Param::Ld | Param::Lq if o.ls_h.is_some() => "observer.ls_h",
            Param::Ld => "motor.ld_h",
            Param::Lq => "motor.lq_h",
            Param::Saliency if o.lq_h.is_some() => "observer.lq_h",
            Param::Saliency if o.ld_h.is_some() => "observer.ld_h",
            Param::Saliency => "motor.lq_h",
            Param::PsiF if o.psi_f_wb.is_some() => "observer.psi_f_wb",
            Param::PsiF => "motor.psi_f_wb",
            Param::PolePairs => "motor.pole_pairs",
            Param::Ts => "inverter.ts_s",
            Param::AngleSigmaLimit => "observer.angle_sigma_limit_rad",
            _ => "observer",
        }
    }

    /// An observer's refusal under the key it is about.
    pub(crate) fn observer_error(&self, e: ekf_core::ConfigError) -> FieldError {
        use ekf_core::ConfigError as E;
        let field = match e {
            E::NonFinite(p) | E::NotPositive(p) | E::TooLargeForTs(p) | E::OutOfRange(p) => {
                self.observer_key(p)
            }
            E::ZeroPolePairs => "motor.pole_pairs",
            E::NonFiniteMatrix(m)
            | E::NotSymmetric(m)
            | E::TooLargeMatrix(m)
            | E::NotPositiveSemiDefinite(m)
            | E::NotPositiveDefinite(m) => match m {
                Matrix::Q => "observer_noise.q",
                Matrix::R => "observer_noise.r",
                Matrix::P0 => "observer",
            },
            _ => "observer",
        };
        FieldError::new(field, format!("the observer refuses it: {e}"))
    }

    /// `foc`'s refusal under the key it is about, with the allowed range where foc documents
    /// one.
    pub(crate) fn foc_error(&self, e: foc::ConfigError) -> FieldError {
        use foc::ConfigError as E;
        use foc::Field as F;
        let f = match e {
            E::Observer(o) => return self.observer_error(o),
            E::NonFinite(f) | E::NotPositive(f) | E::OutOfRange(f) => f,
            E::ObserverMismatch => {
                return FieldError::new("controller.foc", format!("foc refuses it: {e}"));
            }
        };
        let s = self.controller.foc.unwrap_or_default();
        let fw = s
            .field_weakening
            .unwrap_or(FieldWeakeningSettings::flag(false));
        let pick = |set: bool, key: &'static str, default: &'static str| {
            if set { key } else { default }
        };
        let (key, range) = match f {
            F::Ts => ("inverter.ts_s", "> 0"),
            F::CurrentBandwidth | F::CurrentGains => {
                ("controller.current_bandwidth_hz", "> 0, gains finite")
            }
            F::SpeedBandwidth | F::SpeedGains => {
                ("controller.speed_bandwidth_hz", "> 0, gains finite")
            }
            F::Inertia => (
                pick(
                    s.inertia_kg_m2.is_some(),
                    "controller.foc.inertia_kg_m2",
                    "motor.j_kg_m2",
                ),
                "> 0, finite in f32",
            ),
            F::CurrentLimit => ("controller.current_limit_a", "> 0, finite in f32"),
            F::OverCurrent => (
                pick(
                    s.over_current_a.is_some(),
                    "controller.foc.over_current_a",
                    "controller.current_limit_a",
                ),
                "> controller.current_limit_a, finite in f32",
            ),
            F::UdcMin | F::UdcMax => (
                pick(
                    s.u_dc_nominal_v.is_some(),
                    "controller.foc.u_dc_nominal_v",
                    "inverter.u_dc_v",
                ),
                "> 0, finite in f32",
            ),
            F::MaxSpeed | F::SpeedSlew => ("controller.foc.max_speed_rpm", "> 0, finite in f32"),
            F::DeadTime => (
                pick(
                    s.dead_time_s.is_some(),
                    "controller.foc.dead_time_s",
                    "inverter.dead_time_s",
                ),
                "0 <= x < ts_s / 2",
            ),
            F::DeadTimeBand => ("controller.foc.dead_time_band_a", "> 0, finite in f32"),
            F::AlignCurrent => (
                pick(
                    s.align_current_a.is_some(),
                    "controller.foc.align_current_a",
                    "controller.foc.if_current_a",
                ),
                "0 < x <= controller.current_limit_a",
            ),
            F::AlignTime => ("controller.foc.align_time_s", "0 <= x <= 60 s"),
            F::IfCurrent => (
                "controller.foc.if_current_a",
                "0 < x <= controller.current_limit_a",
            ),
            F::Accel => (
                "controller.foc.startup_accel_rpm_per_s",
                "> 0, finite in f32",
            ),
            F::HandoverSpeed => (
                "controller.foc.handover_speed_rpm",
                "0 < x < the maximum speed",
            ),
            F::ExitSpeedRatio => ("controller.foc.exit_speed_ratio", "0.01 <= x <= 0.99"),
            F::DampingRatio => ("controller.foc.startup_damping_ratio", "0 <= x <= 5"),
            F::KickSpeedRatio => ("controller.foc.startup_kick_speed_ratio", "0 <= x <= 1"),
            F::FwVoltageMargin => (
                "controller.foc.field_weakening.voltage_margin",
                "0.5 <= x <= 1",
            ),
            F::FwBandwidth => (
                pick(
                    fw.bandwidth_hz.is_some(),
                    "controller.foc.field_weakening.bandwidth_hz",
                    "controller.current_bandwidth_hz",
                ),
                "0 < x <= controller.current_bandwidth_hz",
            ),
            F::FwMaxNegativeId => (
                "controller.foc.field_weakening.max_negative_id_a",
                "0 < x <= controller.current_limit_a",
            ),
            _ => ("controller.foc", "see foc::FocConfig"),
        };
        FieldError::new(key, format!("foc refuses it: {e} (allowed: {range})"))
    }
}
