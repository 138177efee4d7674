//! The scenario turned into the configurations of what runs: `foc`'s ([`Scenario::foc_config`],
//! foc's own defaults with the scenario's settings on top, validated by foc) and the observers'
//! ([`Scenario::observer_config`], [`Scenario::reference_filter_config`], on the parameters the
//! observers are told, [`Scenario::observer_params`]).

use super::*;

impl Scenario {
    /// The `foc` controller's configuration (module `foc_drive`): `FocConfig::new` for the
    /// observer's motor parameters (what the drive knows of the motor), `ts_s` and the
    /// nominal bus voltage, then the scenario's current limit, loop bandwidths, inertia,
    /// computation delay, mode, dead-time compensation (of `inverter.dead_time_s` unless
    /// `[controller.foc] dead_time_s` says otherwise; 0 turns it off), the damped start
    /// (`startup_damping_ratio` 1 and the kick at 0.6 % of rated speed unless set, when the
    /// dead time is compensated; off in
    /// foc's own defaults) and the other `[controller.foc]` settings. Validated by `foc`
    /// itself.
    pub fn foc_config(&self) -> Result<foc::FocConfig, FieldError> {
        use foc::{ComputationDelay, FocConfig, Mode, ObserverLossPolicy, Reversal, StartupConfig};
        let c = &self.controller;
        let s = c.foc.unwrap_or_default();
        let p = self.observer_params();
        let motor = ekf_core::MotorParams::<f32>::salient_from_f64(
            p.rs_ohm,
            p.ld_h,
            p.lq_h,
            p.psi_f_wb,
            p.pole_pairs,
        );
        let pp = f64::from(p.pole_pairs);
        let rpm_to_e = |rpm: f64| (rpm / RPM_PER_RAD_S * pp) as f32;
        let ts = self.inverter.ts_s as f32;
        let u_nom = s.u_dc_nominal_v.unwrap_or(self.inverter.u_dc_v) as f32;
        let delay = if self.delay_compensation() {
            ComputationDelay::OnePeriod
        } else {
            ComputationDelay::None
        };
        let mode = if c.kind == ControllerKind::FocSensored {
            Mode::Sensored
        } else {
            Mode::Sensorless
        };
        let mut cfg = FocConfig::new(motor, ts, u_nom)
            .with_delay(delay)
            .with_mode(mode);
        cfg.current_bw_rad_s = hz_to_rad_s(c.current_bandwidth_hz) as f32;
        cfg.speed_bw_rad_s = hz_to_rad_s(c.speed_bandwidth_hz) as f32;
        cfg.current_limit_a = c.current_limit_a as f32;
        cfg.over_current_a = s.over_current_a.unwrap_or(2.0 * c.current_limit_a) as f32;
        // After the current limit: the slew rate follows both.
        cfg = cfg.with_inertia(s.inertia_kg_m2.unwrap_or(self.motor.j_kg_m2) as f32);
        let st = &mut cfg.startup;
        st.if_current_a = s.if_current_a.unwrap_or(0.5 * c.current_limit_a) as f32;
        st.align_current_a = s.align_current_a.map_or(st.if_current_a, |x| x as f32);
        let motor_timing = (s.startup_timing == StartupTiming::Motor).then(|| {
            self.motor_startup_timing(
                f64::from(st.align_current_a),
                f64::from(st.if_current_a),
                f64::from(cfg.inertia_kg_m2),
            )
        });
        if let Some(t) = s.align_time_s.or(motor_timing.map(|m| m.0)) {
            st.align_time_s = t as f32;
        }
        // The damped start reads the observer near 1 % of rated speed, where an
        // uncompensated dead time biases it: on by default only with the dead time
        // compensated (or none).
        let dead_time = s.dead_time_s.unwrap_or(self.inverter.dead_time_s);
        let damped = self.inverter.dead_time_s == 0.0 || dead_time >= self.inverter.dead_time_s;
        let on = if damped { 1.0 } else { 0.0 };
        st.damping_ratio = s.startup_damping_ratio.unwrap_or(on) as f32;
        // The damped start hands over at 3 % of rated speed on a surface motor; an interior
        // motor and the classic start (undamped: its rotor swings faster than that) by foc's
        // rule (docs/startup.md, "Hand-over and exit speed").
        st.handover_speed_rad_s = match s.handover_speed_rpm {
            Some(rpm) => rpm_to_e(rpm),
            None if st.damping_ratio > 0.0 && !motor.is_salient() => {
                StartupConfig::handover_speed_for(self.rated_speed_e_rad_s())
            }
            None => StartupConfig::default_handover_speed_rad_s(
                &motor,
                st.if_current_a,
                cfg.max_speed_rad_s,
            ),
        };
        st.accel_rad_s2 = match (s.startup_accel_rpm_per_s, motor_timing) {
            (Some(a), _) => rpm_to_e(a),
            (None, Some((_, accel, min_ramp_s))) => {
                let w_h = f64::from(st.handover_speed_rad_s);
                accel.min(w_h / min_ramp_s) as f32
            }
            (None, None) => StartupConfig::default_accel_rad_s2(st.handover_speed_rad_s),
        };
        // foc's kick at 0.6 % of rated speed, whatever the hand-over speed.
        let kick = StartupConfig::kick_speed_ratio_for(
            self.rated_speed_e_rad_s(),
            st.handover_speed_rad_s,
        );
        st.kick_speed_ratio = match s.startup_kick_speed_ratio {
            Some(r) => r as f32,
            None => on as f32 * kick,
        };
        st.reversal = match s.reversal {
            ReversalMode::ClosedLoop => Reversal::ClosedLoop,
            ReversalMode::OpenLoop => Reversal::OpenLoop,
        };
        // The exit at 1.5 % of rated speed, at most 0.7 of the hand-over speed (foc's rule, on
        // the rated speed foc is not told), where the dead time is compensated (or none):
        // measured so (docs/accuracy.md, "Low speed"). An uncompensated dead time biases the
        // observer at low speed: 0.7 of the hand-over speed there (the default job's I/f
        // reversal without compensation lost 0.5 s with the exit at 1.5 %).
        st.exit_speed_ratio = match s.exit_speed_ratio {
            Some(r) => r as f32,
            None if damped => StartupConfig::exit_speed_ratio_for(
                self.rated_speed_e_rad_s(),
                st.handover_speed_rad_s,
            ),
            None => StartupConfig::EXIT_SPEED_RATIO_MAX,
        };
        cfg.health.policy = match s.observer_loss {
            ObserverLoss::FallBack => ObserverLossPolicy::FallBackAndReacquire,
            ObserverLoss::Trip => ObserverLossPolicy::Trip,
        };
        if let Some(sigma) = self.observer.angle_sigma_limit_rad {
            cfg.observer.angle_sigma_limit_rad = sigma as f32;
        }
        // The drive compensates the dead time of its bridge unless told otherwise.
        cfg.dead_time_s = s.dead_time_s.unwrap_or(self.inverter.dead_time_s) as f32;
        cfg.dead_time_band_a = s.dead_time_band_a.map(|x| x as f32);
        if let Some(on) = s.mtpa {
            cfg.mtpa = on;
        }
        // After the start-up defaults (the hand-over speed's floor is 2 % of foc's base-speed
        // limit, with or without field weakening).
        if let Some(fw) = s.field_weakening
            && fw.enabled
        {
            cfg = cfg.with_field_weakening(2.0);
            let f = &mut cfg.field_weakening;
            f.bandwidth_rad_s = match fw.bandwidth_hz {
                Some(hz) => hz_to_rad_s(hz) as f32,
                None => 0.1 * cfg.current_bw_rad_s,
            };
            if let Some(k) = fw.voltage_margin {
                f.voltage_margin = k as f32;
            }
            f.max_negative_id_a = fw.max_negative_id_a.map(|x| x as f32);
        }
        if let Some(rpm) = s.max_speed_rpm {
            cfg.max_speed_rad_s = rpm_to_e(rpm);
        }
        cfg.validate().map_err(|e| self.foc_error(e))?;
        Ok(cfg)
    }

    /// The start-up times from the motor ([`StartupTiming::Motor`]) for the alignment
    /// current `align_a`, the I/f current `if_a` (A) and the inertia `j` the drive assumes:
    /// `(align_time_s, accel_rad_s2 el., shortest ramp s)`. With `tau_e = max(Ld, Lq) / Rs`
    /// and the swing period `T(I) = 2 pi / sqrt(1.5 p^2 psi_f I / J)` of the rotor under a
    /// current vector `I` (the pendulum of the alignment and of the I/f load angle):
    /// alignment `5 tau_e + 2 T(align_a)`; acceleration `0.25 p k_t if_a / J` el. (a
    /// quarter of the I/f torque, the rest for the load and the load angle's swing);
    /// shortest ramp `2 T(if_a)` (the damped swing settles before the hand-over). Measured
    /// against foc's fixed times: docs/startup.md, "Start-up times from the motor".
    pub fn motor_startup_timing(&self, align_a: f64, if_a: f64, j: f64) -> (f64, f64, f64) {
        let m = &self.motor;
        let p = m.p();
        let tau_e = m.ld_h.max(m.lq_h) / m.rs_ohm;
        let swing = |i: f64| 2.0 * PI / (1.5 * p * p * m.psi_f_wb * i / j).sqrt();
        let align = 5.0 * tau_e + 2.0 * swing(align_a);
        let accel = 0.25 * p * m.torque_constant_nm_a() * if_a / j;
        (align, accel, 2.0 * swing(if_a))
    }

    /// One line on the controller, for reports.
    pub fn controller_description(&self) -> String {
        let delay = match (self.inverter.delay, self.delay_compensation()) {
            (true, true) => "one period of computation delay, compensated",
            (false, false) => "no computation delay",
            (true, false) => "one period of computation delay, NOT compensated",
            (false, true) => "compensating a computation delay the inverter does not have",
        };
        let delay = match self.inverter.delay_periods {
            Some(d) => format!(
                "voltage applied {d} periods after the sample, {} compensated",
                if self.delay_compensation() {
                    "one"
                } else {
                    "none"
                }
            ),
            None => delay.to_string(),
        };
        match self.controller.kind {
            ControllerKind::Foc => {
                format!("foc, sensorless (f32; align, I/f, hand-over to its own f32 EKF), {delay}")
            }
            ControllerKind::FocSensored => {
                format!("foc, sensored (f32; true angle and speed), {delay}")
            }
        }
    }

    /// The observer's configuration (`ObserverConfig::new` on the observer's parameters).
    /// With `[observer_noise]`, its `q` and `r` replace the default noise.
    pub fn observer_config(&self) -> ekf_core::ObserverConfig<f64> {
        let mut cfg = ekf_core::ObserverConfig::new(self.observer_params(), self.inverter.ts_s)
            .with_sigma(self.observer.angle_sigma_limit_rad);
        if let Some(n) = &self.observer_noise {
            cfg.noise = n.covariances();
        }
        cfg
    }

    /// The reference filter's configuration (`ObserverConfig::seed`).
    pub fn reference_filter_config(&self) -> ekf_core::ObserverConfig<f64> {
        ekf_core::ObserverConfig::seed(self.observer_params(), self.inverter.ts_s)
            .with_sigma(self.observer.angle_sigma_limit_rad)
    }

    /// The motor parameters the observers are given.
    pub fn observer_params(&self) -> ekf_core::MotorParams<f64> {
        let o = &self.observer;
        let m = &self.motor;
        ekf_core::MotorParams::salient_from_f64(
            o.rs_ohm.unwrap_or(m.rs_ohm),
            o.ld_h.or(o.ls_h).unwrap_or(m.ld_h),
            o.lq_h.or(o.ls_h).unwrap_or(m.lq_h),
            o.psi_f_wb.unwrap_or(m.psi_f_wb),
            m.pole_pairs,
        )
    }
}

/// Sets the angle standard-deviation limit when given.
trait WithSigma {
    fn with_sigma(self, sigma: Option<f64>) -> Self;
}

impl WithSigma for ekf_core::ObserverConfig<f64> {
    fn with_sigma(mut self, sigma: Option<f64>) -> Self {
        if let Some(s) = sigma {
            self.angle_sigma_limit_rad = s;
        }
        self
    }
}
