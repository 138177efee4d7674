//! Scenarios: everything one simulation run needs, read from TOML, and the built-in presets.
//!
//! A [`Scenario`] is plain data: motor, inverter, sensors, controller and observer settings,
//! speed-reference and load profiles, duration and random seed. The same scenario (and seed)
//! gives a bit-identical run. Files are parsed strictly (unknown fields are errors) and
//! checked before a run ([`Scenario::validate`]); every error names the file, the field and
//! the problem. The README documents the format; `scenarios/*.toml` are examples, and the
//! built-in presets ([`PRESETS`]) are those very files, embedded.

use core::f64::consts::PI;

use serde::{Deserialize, Serialize};

use crate::SimError;
use crate::controller::{ControllerConfig, hz_to_rad_s};
use crate::error::FieldError;
use crate::inverter::InverterConfig;
use crate::plant::MotorModel;
use crate::profile::{LoadTerm, Profile};
use crate::sensors::SensorConfig;

/// rpm per rad/s.
pub const RPM_PER_RAD_S: f64 = 30.0 / PI;

/// Built-in scenarios `(name, TOML text)`; the first is the default.
pub const PRESETS: &[(&str, &str)] = &[
    ("default", include_str!("../scenarios/default.toml")),
    ("servo-ideal", include_str!("../scenarios/servo-ideal.toml")),
    ("servo-harsh", include_str!("../scenarios/servo-harsh.toml")),
    (
        "industrial-2k2",
        include_str!("../scenarios/industrial-2k2.toml"),
    ),
    ("drone", include_str!("../scenarios/drone.toml")),
];

/// Which controller drives the plant.
#[derive(Clone, Copy, Debug, PartialEq, Eq, Serialize, Deserialize)]
#[serde(rename_all = "snake_case")]
pub enum ControllerKind {
    /// The sensored speed/current controller ([`crate::controller::SensoredController`]).
    Sensored,
}

/// Controller settings (`[controller]`).
#[derive(Clone, Copy, Debug, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct ControllerSettings {
    /// Which controller.
    pub kind: ControllerKind,
    /// The speed loop's current limit, A.
    pub current_limit_a: f64,
    /// Current loop bandwidth, Hz.
    pub current_bandwidth_hz: f64,
    /// Speed loop crossover, Hz.
    pub speed_bandwidth_hz: f64,
    /// Compensate one period of computation delay (default: whether the inverter has it).
    #[serde(default)]
    pub delay_compensation: Option<bool>,
}

/// Observer settings (`[observer]`); the observer is `ObserverConfig::new` on these
/// parameters.
#[derive(Clone, Copy, Debug, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields, default)]
pub struct ObserverSettings {
    /// Also run the seed's filter (`ObserverConfig::seed`) alongside, for comparison.
    pub seed_filter: bool,
    /// The observer's stator resistance (default: the motor's), ohm.
    pub rs_ohm: Option<f64>,
    /// The observer's inductance (default: the motor's `(Ld + Lq) / 2`), H.
    pub ls_h: Option<f64>,
    /// The observer's flux linkage (default: the motor's), Wb.
    pub psi_f_wb: Option<f64>,
    /// Status `Uncertain` above this angle standard deviation (default 0.2), rad.
    pub angle_sigma_limit_rad: Option<f64>,
}

impl Default for ObserverSettings {
    fn default() -> Self {
        Self {
            seed_filter: true,
            rs_ohm: None,
            ls_h: None,
            psi_f_wb: None,
            angle_sigma_limit_rad: None,
        }
    }
}

/// The rotor at `t = 0` (`[initial]`); the currents start at zero.
#[derive(Clone, Copy, Debug, Default, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields, default)]
pub struct InitialState {
    /// Electrical angle, rad.
    pub theta_e_rad: f64,
    /// Mechanical speed, rpm.
    pub speed_rpm: f64,
}

/// One simulation run's description (module docs; the README documents every field).
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct Scenario {
    /// Short name (output directory, reports).
    pub name: String,
    /// One line on what the scenario shows.
    #[serde(default)]
    pub description: String,
    /// Simulated time, s.
    pub duration_s: f64,
    /// Seed of the random generators (sensor noise).
    #[serde(default)]
    pub seed: u64,
    /// Rated mechanical speed, rpm (metrics: the 5 % low-speed exclusion, speed error in %).
    pub rated_speed_rpm: f64,
    /// Rated torque, N m (documentation; the load terms use it).
    pub rated_torque_nm: f64,
    /// The motor (plant; the controller and observer are given the same parameters unless
    /// `[observer]` overrides them).
    pub motor: MotorModel,
    /// The rotor at `t = 0`.
    #[serde(default)]
    pub initial: InitialState,
    /// Inverter.
    pub inverter: InverterConfig,
    /// Current sensing (default: ideal).
    #[serde(default)]
    pub sensors: SensorConfig,
    /// Controller.
    pub controller: ControllerSettings,
    /// Observer.
    #[serde(default)]
    pub observer: ObserverSettings,
    /// Mechanical speed reference, rpm.
    pub speed_ref_rpm: Profile,
    /// Load torque terms, summed (default: none).
    #[serde(default)]
    pub load: Vec<LoadTerm>,
}

/// A problem in a TOML text, as `(field path, message)`.
fn toml_problem(text: &str, path: &str, err: &toml::de::Error) -> (String, String) {
    let mut problem = err.message().trim().to_string();
    if let Some(span) = err.span() {
        let start = span.start.min(text.len());
        let before = &text[..start];
        let line = before.matches('\n').count() + 1;
        let col = before.len() - before.rfind('\n').map_or(0, |i| i + 1) + 1;
        problem = format!("{problem} (line {line}, column {col})");
    }
    let field = if path.is_empty() || path == "." {
        "-".to_string()
    } else {
        path.to_string()
    };
    (field, problem)
}

impl Scenario {
    /// Parses and validates a scenario from TOML; `origin` names the file in errors.
    pub fn from_toml_str(text: &str, origin: &str) -> Result<Self, SimError> {
        let err = |field: String, problem: String| SimError::Scenario {
            file: origin.to_string(),
            field,
            problem,
        };
        let de = toml::Deserializer::parse(text).map_err(|e| {
            let (f, p) = toml_problem(text, "", &e);
            err(f, p)
        })?;
        let sc: Scenario = serde_path_to_error::deserialize(de).map_err(|e| {
            let path = e.path().to_string();
            let (f, p) = toml_problem(text, &path, e.inner());
            err(f, p)
        })?;
        sc.validate().map_err(|e| err(e.field, e.problem))?;
        Ok(sc)
    }

    /// Reads, parses and validates a scenario file.
    pub fn from_file(path: &std::path::Path) -> Result<Self, SimError> {
        let file = path.display().to_string();
        let text = std::fs::read_to_string(path).map_err(|source| SimError::Read {
            file: file.clone(),
            source,
        })?;
        Self::from_toml_str(&text, &file)
    }

    /// A built-in scenario by name ([`PRESETS`]).
    pub fn preset(name: &str) -> Result<Self, SimError> {
        let Some((_, text)) = PRESETS.iter().find(|(n, _)| *n == name) else {
            return Err(SimError::UnknownPreset {
                name: name.to_string(),
                known: PRESETS
                    .iter()
                    .map(|(n, _)| *n)
                    .collect::<Vec<_>>()
                    .join(", "),
            });
        };
        Self::from_toml_str(text, &format!("preset {name}"))
    }

    /// The TOML text of a built-in scenario.
    pub fn preset_text(name: &str) -> Option<&'static str> {
        PRESETS.iter().find(|(n, _)| *n == name).map(|(_, t)| *t)
    }

    /// The built-in default scenario (`scenarios/default.toml`): the servo motor of
    /// `design.md` section 6 at 10 kHz, from standstill to rated speed, a rated load step and
    /// a reversal.
    ///
    /// # Panics
    ///
    /// Never in a released build: the embedded file is parsed and validated by a unit test.
    pub fn default_servo() -> Self {
        match Self::preset("default") {
            Ok(s) => s,
            Err(e) => panic!("embedded default scenario is invalid: {e}"),
        }
    }

    /// The same scenario cut to `duration_s` (profiles unchanged).
    pub fn with_duration(mut self, duration_s: f64) -> Self {
        self.duration_s = duration_s;
        self
    }

    /// PWM and control period, s.
    pub fn ts_s(&self) -> f64 {
        self.inverter.ts_s
    }

    /// Rated mechanical speed, rad/s.
    pub fn rated_speed_mech_rad_s(&self) -> f64 {
        self.rated_speed_rpm / RPM_PER_RAD_S
    }

    /// Rated electrical speed, rad/s.
    pub fn rated_speed_e_rad_s(&self) -> f64 {
        self.rated_speed_mech_rad_s() * self.motor.p()
    }

    /// Number of PWM periods simulated, `round(duration / Ts)`.
    pub fn periods(&self) -> usize {
        // Validated finite, positive and at most 1e9 before use; `as` saturates otherwise.
        (self.duration_s / self.inverter.ts_s).round() as usize
    }

    /// Whether the controller compensates one period of delay.
    pub fn delay_compensation(&self) -> bool {
        self.controller
            .delay_compensation
            .unwrap_or(self.inverter.delay)
    }

    /// The sensored controller's configuration.
    pub fn controller_config(&self) -> ControllerConfig {
        let c = &self.controller;
        ControllerConfig::tuned(
            &self.motor,
            self.inverter.ts_s,
            c.current_limit_a,
            hz_to_rad_s(c.current_bandwidth_hz),
            hz_to_rad_s(c.speed_bandwidth_hz),
            self.delay_compensation(),
        )
    }

    /// The observer's configuration (`ObserverConfig::new` on the observer's parameters).
    pub fn observer_config(&self) -> ekf_core::ObserverConfig<f64> {
        ekf_core::ObserverConfig::new(self.observer_params(), self.inverter.ts_s)
            .with_sigma(self.observer.angle_sigma_limit_rad)
    }

    /// The seed filter's configuration (`ObserverConfig::seed`).
    pub fn seed_filter_config(&self) -> ekf_core::ObserverConfig<f64> {
        ekf_core::ObserverConfig::seed(self.observer_params(), self.inverter.ts_s)
            .with_sigma(self.observer.angle_sigma_limit_rad)
    }

    /// The motor parameters the observers are given.
    pub fn observer_params(&self) -> ekf_core::MotorParams<f64> {
        let o = &self.observer;
        let m = &self.motor;
        ekf_core::MotorParams::from_f64(
            o.rs_ohm.unwrap_or(m.rs_ohm),
            o.ls_h.unwrap_or(m.ls_mean_h()),
            o.psi_f_wb.unwrap_or(m.psi_f_wb),
            m.pole_pairs,
        )
    }

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
        let c = &self.controller;
        positive("controller.current_limit_a", c.current_limit_a)?;
        positive("controller.current_bandwidth_hz", c.current_bandwidth_hz)?;
        positive("controller.speed_bandwidth_hz", c.speed_bandwidth_hz)?;
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
        let o = &self.observer;
        for (name, v) in [
            ("observer.rs_ohm", o.rs_ohm),
            ("observer.ls_h", o.ls_h),
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
        self.speed_ref_rpm.validate("speed_ref_rpm")?;
        for (i, term) in self.load.iter().enumerate() {
            term.validate(&format!("load[{i}]"))?;
        }
        Ok(())
    }

    /// The scenario as TOML (what `pmsm-sim show` prints for a file, and the MCAP log keeps).
    pub fn to_toml(&self) -> Result<String, SimError> {
        toml::to_string(self).map_err(|e| SimError::Scenario {
            file: self.name.clone(),
            field: "-".into(),
            problem: format!("cannot write as TOML: {e}"),
        })
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

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn every_preset_parses_validates_and_round_trips() {
        for (name, _) in PRESETS {
            let sc = match Scenario::preset(name) {
                Ok(s) => s,
                Err(e) => panic!("{e}"),
            };
            assert_eq!(&sc.name, name);
            let text = sc.to_toml().unwrap_or_else(|e| panic!("{e}"));
            let back =
                Scenario::from_toml_str(&text, "round trip").unwrap_or_else(|e| panic!("{e}"));
            assert_eq!(back, sc);
        }
        assert!(matches!(
            Scenario::preset("nope"),
            Err(SimError::UnknownPreset { .. })
        ));
    }

    #[test]
    fn default_scenario_is_within_the_voltage_limit() {
        let sc = Scenario::default_servo();
        assert_eq!(sc.periods(), 15_000);
        let m = sc.motor;
        let we = sc.rated_speed_e_rad_s();
        let iq = sc.rated_torque_nm / m.torque_constant_nm_a();
        assert!(iq < sc.controller.current_limit_a);
        let u = (m.rs_ohm * iq + we * m.psi_f_wb).hypot(we * m.lq_h * iq);
        let u_lim = sc.inverter.u_dc_v / 3f64.sqrt();
        assert!(u < 0.9 * u_lim, "{u} V of {u_lim} V");
    }

    fn error_of(text: &str) -> (String, String) {
        match Scenario::from_toml_str(text, "bad.toml") {
            Err(SimError::Scenario {
                file,
                field,
                problem,
            }) => {
                assert_eq!(file, "bad.toml");
                (field, problem)
            }
            other => panic!("expected a scenario error, got {other:?}"),
        }
    }

    fn default_text() -> &'static str {
        Scenario::preset_text("default").unwrap_or_default()
    }

    #[test]
    fn malformed_and_invalid_files_name_the_field() {
        // Missing field.
        let t = default_text().replace("lq_h = ", "# lq_h = ");
        let (field, problem) = error_of(&t);
        assert_eq!(field, "motor");
        assert!(problem.contains("missing field `lq_h`"), "{problem}");
        // Wrong type.
        let t = default_text().replace("pole_pairs = 4", "pole_pairs = \"four\"");
        let (field, problem) = error_of(&t);
        assert_eq!(field, "motor.pole_pairs");
        assert!(problem.contains("line"), "{problem}");
        // Unknown field (a typo).
        let t = default_text().replace("dead_time_s", "deadtime_s");
        let (field, problem) = error_of(&t);
        assert_eq!(field, "inverter.deadtime_s");
        assert!(problem.contains("unknown field"), "{problem}");
        // Not TOML at all.
        let (field, _) = error_of("name = \n");
        assert_eq!(field, "-");
        // Physically invalid values, refused before the run.
        let t = default_text().replace("ld_h = 8.5e-3", "ld_h = -8.5e-3");
        assert_eq!(error_of(&t).0, "motor.ld_h");
        let t = default_text().replace("ts_s = 1e-4", "ts_s = 0.0");
        assert_eq!(error_of(&t).0, "inverter.ts_s");
        let t = default_text().replace("dead_time_s = 0.0", "dead_time_s = 2e-4");
        let (field, problem) = error_of(&t);
        assert_eq!(field, "inverter.dead_time_s");
        assert!(problem.contains("period"), "{problem}");
        // A bad load term names its index.
        let t = format!(
            "{}\n[[load]]\nkind = \"ramp\"\nstart_s = 1.0\nend_s = 0.5\nfrom_nm = 0.0\nto_nm = 1.0\n",
            default_text()
        );
        assert_eq!(error_of(&t).0, "load[1].end_s");
        let t = format!("{}\n[[load]]\nkind = \"wind\"\n", default_text());
        let (field, problem) = error_of(&t);
        assert_eq!(field, "load[1].kind");
        assert!(problem.contains("unknown variant"), "{problem}");
    }
}
