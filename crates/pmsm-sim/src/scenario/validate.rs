//! The scenario's validation: every physically invalid value, and a configuration `foc`
//! refuses, is an error naming the field before anything runs.

use super::*;
use crate::error::plain;

/// Smallest current-loop bandwidth, Hz.
pub const MIN_CURRENT_BANDWIDTH_HZ: f64 = 1.0;
/// Smallest speed-loop bandwidth, Hz.
pub const MIN_SPEED_BANDWIDTH_HZ: f64 = 0.01;

impl Scenario {
    /// Checks the scenario before a run; the error names the field.
    pub fn validate(&self) -> Result<(), FieldError> {
        if self.name.trim().is_empty() {
            return Err(FieldError::new("name", "must not be empty"));
        }
        let positive = |field: &str, v: f64| {
            if v.is_finite() && v > 0.0 {
                Ok(())
            } else {
                Err(FieldError::new(
                    field,
                    format!("must be finite and > 0, is {v}"),
                ))
            }
        };
        positive("duration_s", self.duration_s)?;
        positive("rated_speed_rpm", self.rated_speed_rpm)?;
        positive("rated_torque_nm", self.rated_torque_nm)?;
        self.motor.validate()?;
        self.inverter.validate()?;
        self.sensors.validate()?;
        self.skipped_cycles.validate()?;
        let c = &self.controller;
        positive("controller.current_limit_a", c.current_limit_a)?;
        positive("controller.current_bandwidth_hz", c.current_bandwidth_hz)?;
        positive("controller.speed_bandwidth_hz", c.speed_bandwidth_hz)?;
        // Plausible lower ends, before the relations between the loops.
        for (name, v, min) in [
            (
                "controller.current_bandwidth_hz",
                c.current_bandwidth_hz,
                MIN_CURRENT_BANDWIDTH_HZ,
            ),
            (
                "controller.speed_bandwidth_hz",
                c.speed_bandwidth_hz,
                MIN_SPEED_BANDWIDTH_HZ,
            ),
        ] {
            if v < min {
                return Err(FieldError::new(
                    name,
                    format!("allowed: x >= {} Hz, is {}", plain(min), plain(v)),
                ));
            }
        }
        let f_pwm = 1.0 / self.inverter.ts_s;
        if c.current_bandwidth_hz > 0.1 * f_pwm {
            return Err(FieldError::new(
                "controller.current_bandwidth_hz",
                format!(
                    "{} Hz is above a tenth of the PWM frequency ({} Hz): the discrete loop \
                     would be unstable",
                    c.current_bandwidth_hz,
                    0.1 * f_pwm
                ),
            ));
        }
        if c.speed_bandwidth_hz > 0.2 * c.current_bandwidth_hz {
            return Err(FieldError::new(
                "controller.speed_bandwidth_hz",
                format!(
                    "{} Hz is above a fifth of the current bandwidth ({} Hz)",
                    c.speed_bandwidth_hz, c.current_bandwidth_hz
                ),
            ));
        }
        if let Some(f) = &c.foc {
            for (name, v) in [
                ("controller.foc.u_dc_nominal_v", f.u_dc_nominal_v),
                ("controller.foc.inertia_kg_m2", f.inertia_kg_m2),
                ("controller.foc.over_current_a", f.over_current_a),
                ("controller.foc.align_current_a", f.align_current_a),
                ("controller.foc.if_current_a", f.if_current_a),
                ("controller.foc.handover_speed_rpm", f.handover_speed_rpm),
                (
                    "controller.foc.startup_accel_rpm_per_s",
                    f.startup_accel_rpm_per_s,
                ),
                ("controller.foc.max_speed_rpm", f.max_speed_rpm),
                (
                    "controller.foc.field_weakening.bandwidth_hz",
                    f.field_weakening.and_then(|w| w.bandwidth_hz),
                ),
                (
                    "controller.foc.field_weakening.max_negative_id_a",
                    f.field_weakening.and_then(|w| w.max_negative_id_a),
                ),
            ] {
                if let Some(v) = v {
                    positive(name, v)?;
                }
            }
            if let Some(k) = f.field_weakening.and_then(|w| w.voltage_margin)
                && !(0.5..=1.0).contains(&k)
            {
                return Err(FieldError::new(
                    "controller.foc.field_weakening.voltage_margin",
                    format!("must be in [0.5, 1], is {k}"),
                ));
            }
            if let Some(w) = f.field_weakening.filter(|w| w.enabled)
                && let Some(hz) = w.bandwidth_hz
                && hz > c.current_bandwidth_hz
            {
                return Err(FieldError::new(
                    "controller.foc.field_weakening.bandwidth_hz",
                    format!(
                        "{hz} Hz is above the current bandwidth ({} Hz)",
                        c.current_bandwidth_hz
                    ),
                ));
            }
            if let Some(i) = f.field_weakening.and_then(|w| w.max_negative_id_a)
                && i > c.current_limit_a
            {
                return Err(FieldError::new(
                    "controller.foc.field_weakening.max_negative_id_a",
                    format!(
                        "{i} A is above controller.current_limit_a ({} A)",
                        c.current_limit_a
                    ),
                ));
            }
            for (name, v) in [
                ("controller.foc.start_time_s", Some(f.start_time_s)),
                ("controller.foc.stop_time_s", f.stop_time_s),
                ("controller.foc.align_time_s", f.align_time_s),
            ] {
                if let Some(v) = v
                    && !(v.is_finite() && v >= 0.0)
                {
                    return Err(FieldError::new(
                        name,
                        format!("must be finite and >= 0, is {v}"),
                    ));
                }
            }
        }
        let o = &self.observer;
        for (name, v) in [
            ("observer.rs_ohm", o.rs_ohm),
            ("observer.ls_h", o.ls_h),
            ("observer.ld_h", o.ld_h),
            ("observer.lq_h", o.lq_h),
            ("observer.psi_f_wb", o.psi_f_wb),
            ("observer.angle_sigma_limit_rad", o.angle_sigma_limit_rad),
        ] {
            if let Some(v) = v {
                positive(name, v)?;
            }
        }
        for (name, v) in [
            ("initial.theta_e_rad", self.initial.theta_e_rad),
            ("initial.speed_rpm", self.initial.speed_rpm),
        ] {
            if !v.is_finite() {
                return Err(FieldError::new(name, format!("must be finite, is {v}")));
            }
        }
        // The observers' own checks (motor parameters in their plausible ranges, ts_s, Q and
        // R of [observer_noise]), under the keys the values came from.
        self.observer_config()
            .validate()
            .map_err(|e| self.observer_error(e))?;
        if self.observer.reference_filter {
            self.reference_filter_config()
                .validate()
                .map_err(|e| self.observer_error(e))?;
        }
        let n = self.duration_s / self.inverter.ts_s;
        if n.round() < 1.0 {
            return Err(FieldError::new(
                "duration_s",
                format!(
                    "{} s is shorter than half a PWM period ({} s)",
                    self.duration_s, self.inverter.ts_s
                ),
            ));
        }
        if n > 1e9 {
            return Err(FieldError::new(
                "duration_s",
                format!("{} s is more than 1e9 PWM periods", self.duration_s),
            ));
        }
        // Magnitudes first: an absurd value is named, not the relation it breaks.
        self.check_bounds()?;
        self.speed_ref_rpm.validate("speed_ref_rpm")?;
        for (i, term) in self.load.iter().enumerate() {
            term.validate(&format!("load[{i}]"))?;
        }
        for (i, fault) in self.faults.iter().enumerate() {
            fault.validate(&format!("faults[{i}]"), &self.fault_context())?;
        }
        self.foc_config()?;
        Ok(())
    }
}
