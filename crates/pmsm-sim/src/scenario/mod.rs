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
use crate::error::FieldError;
use crate::plant::MotorModel;
use crate::plant::fault_injection::{FaultSpec, RunContext};
use crate::plant::inverter::InverterConfig;
use crate::plant::load::{LoadTerm, Profile};
use crate::plant::sensors::SensorConfig;

mod bounds;
pub use bounds::{
    MAX_ANGLE_RAD, MAX_RATED_SPEED_RPM, MAX_RATED_TORQUE_NM, MAX_TIME_S, SPEED_FACTOR,
    TORQUE_FACTOR,
};
mod configs;
pub mod feasibility;
mod messages;
mod noise;
pub use noise::ObserverNoise;
mod plan;
mod presets;
mod validate;
pub use plan::RunPlan;
pub use presets::PRESETS;
pub use validate::{MIN_CURRENT_BANDWIDTH_HZ, MIN_SPEED_BANDWIDTH_HZ};

/// rpm per rad/s.
pub const RPM_PER_RAD_S: f64 = 30.0 / PI;

/// Hz to rad/s.
pub fn hz_to_rad_s(f_hz: f64) -> f64 {
    2.0 * PI * f_hz
}

/// Which controller drives the plant.
#[derive(Clone, Copy, Debug, PartialEq, Eq, Serialize, Deserialize)]
#[serde(rename_all = "snake_case")]
pub enum ControllerKind {
    /// The `foc` crate's sensorless controller ([`crate::drive::foc_adapter::FocDrive`], `f32`):
    /// alignment, I/f start-up, hand-over to its own EKF, closed loop.
    Foc,
    /// The `foc` crate's controller in sensored mode: the true angle and speed through
    /// `TickInput::with_sensor`, its observer running alongside. `"sensored"` is accepted as
    /// another spelling.
    #[serde(alias = "sensored")]
    FocSensored,
}

/// What the `foc` controller does when its observer is lost in closed loop.
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq, Serialize, Deserialize)]
#[serde(rename_all = "snake_case")]
pub enum ObserverLoss {
    /// Fall back to the I/f ramp and hand over again (foc's default).
    #[default]
    FallBack,
    /// Trip the `observer_lost` fault.
    Trip,
}

/// How the unset start-up times of `foc` are chosen (`[controller.foc] startup_timing`).
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq, Serialize, Deserialize)]
#[serde(rename_all = "snake_case")]
pub enum StartupTiming {
    /// foc's fixed defaults: `align_time_s` 0.2 s, the I/f ramp reaching the hand-over
    /// speed in 0.5 s, whatever the motor.
    #[default]
    Fixed,
    /// From the motor (module `configs`, `Scenario::motor_startup_timing`): the alignment
    /// `5 L/R + 2` periods of the rotor's swing under the alignment current
    /// (`w_n^2 = 1.5 p^2 psi_f I_align / J`), the ramp's acceleration a quarter of what the
    /// I/f current's torque gives the inertia (`0.25 p k_t I_f / J` el.), but the ramp at
    /// least 2 swing periods under the I/f current long.
    Motor,
}

impl StartupTiming {
    /// The default (not written to TOML).
    pub fn is_fixed(&self) -> bool {
        *self == Self::Fixed
    }
}

/// How `foc` passes through zero speed in a reversal (`FocConfig::startup.reversal`).
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq, Serialize, Deserialize)]
#[serde(rename_all = "snake_case")]
pub enum ReversalMode {
    /// Stay in closed loop on the observer through zero (foc's default).
    #[default]
    ClosedLoop,
    /// Leave closed loop below the exit speed, I/f through zero, hand over again.
    OpenLoop,
}

/// Settings of the `foc` controller (`[controller.foc]`, only with `kind = "foc"` or
/// `"foc_sensored"`). Every field is optional; the defaults are `foc`'s own
/// (`FocConfig::new`, derived from the motor, the PWM period and the bus voltage), with the
/// scenario's current limit and loop bandwidths of `[controller]` and the motor's inertia.
#[derive(Clone, Copy, Debug, Default, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields, default)]
pub struct FocSettings {
    /// Nominal DC-bus voltage the controller is configured for (bus trip levels 0.6 and
    /// 1.25 times it, maximum speed), V. Default: `inverter.u_dc_v`.
    pub u_dc_nominal_v: Option<f64>,
    /// Inertia the speed-loop gains and the speed slew rate are computed for, kg m^2.
    /// Default: `motor.j_kg_m2`.
    pub inertia_kg_m2: Option<f64>,
    /// Time of the `start()` command, s (default 0).
    pub start_time_s: f64,
    /// Time of a controlled `stop()` command, s (default: none).
    pub stop_time_s: Option<f64>,
    /// Over-current trip level, A. Default: twice `controller.current_limit_a`.
    pub over_current_a: Option<f64>,
    /// Duration of the alignment, s (0 skips it). Default 0.2 s.
    pub align_time_s: Option<f64>,
    /// Alignment current, A. Default: `if_current_a`.
    pub align_current_a: Option<f64>,
    /// Current of the open-loop I/f ramp, A. Default: half of `controller.current_limit_a`.
    pub if_current_a: Option<f64>,
    /// Speed of the hand-over to the observer, mechanical rpm. Default: 3 % of
    /// `rated_speed_rpm` with the damped start (`startup_damping_ratio` > 0) on a surface
    /// motor (`foc::StartupConfig::handover_speed_for`), else foc's rule,
    /// `max(2 Rs I_f / psi_f, 0.02 w_max)` electrical, the back-EMF twice the resistive drop.
    pub handover_speed_rpm: Option<f64>,
    /// Acceleration of the I/f ramp, mechanical rpm per second. Default: the hand-over speed
    /// in 0.5 s.
    pub startup_accel_rpm_per_s: Option<f64>,
    /// Damping ratio of foc's I/f start (`StartupConfig::damping_ratio`). Default 1
    /// (critically damped) when the drive compensates the inverter's dead time (or there is
    /// none), else 0; foc's own default is 0, off.
    pub startup_damping_ratio: Option<f64>,
    /// Kick speed of foc's alignment as a fraction of the hand-over speed
    /// (`StartupConfig::kick_speed_ratio`; 0: the classic alignment). Default: the kick at
    /// 0.6 % of rated speed when the dead time is compensated (as `startup_damping_ratio`),
    /// else 0; foc's own default is 0, off.
    pub startup_kick_speed_ratio: Option<f64>,
    /// Reaction to an observer loss in closed loop (default `fall_back`).
    pub observer_loss: ObserverLoss,
    /// How a reversal passes through zero speed: `closed_loop` (default, foc's) or
    /// `open_loop` (I/f below the exit speed).
    pub reversal: ReversalMode,
    /// How the start-up's times are chosen where `align_time_s` and
    /// `startup_accel_rpm_per_s` are not given: `fixed` (default: foc's 0.2 s alignment and
    /// the hand-over speed in 0.5 s) or `motor` (from the motor's electrical and mechanical
    /// time constants, [`StartupTiming::Motor`]).
    #[serde(skip_serializing_if = "StartupTiming::is_fixed")]
    pub startup_timing: StartupTiming,
    /// Closed loop returns to I/f below this fraction of the hand-over speed (for a stop or
    /// a slow command; `StartupConfig::exit_speed_ratio`, in `[0.01, 0.99]`). Default: the
    /// exit at 1.5 % of `rated_speed_rpm`, at most 0.7 of the hand-over speed, when the dead
    /// time is compensated (or none; else 0.7)
    /// (`foc::StartupConfig::exit_speed_ratio_for`; 0.5 with the damped start's 3 %).
    pub exit_speed_ratio: Option<f64>,
    /// Dead time foc compensates (`FocConfig::dead_time_s`), s. Default:
    /// `inverter.dead_time_s` (the drive knows its bridge); 0 turns the compensation off.
    pub dead_time_s: Option<f64>,
    /// Linear band of the compensation's smooth sign (`FocConfig::dead_time_band_a`), A.
    /// Default foc's: 2 % of `controller.current_limit_a`.
    pub dead_time_band_a: Option<f64>,
    /// Maximum torque per ampere on a salient motor (`FocConfig::mtpa`): `i_d` from the MTPA
    /// law; `false`: `i_d = 0`. Default `true` (foc's); no effect on a surface motor.
    pub mtpa: Option<bool>,
    /// Field weakening above base speed (`FocConfig::field_weakening`): `true`/`false`, or a
    /// table ([`FieldWeakeningSettings`]). Default: off.
    #[serde(deserialize_with = "field_weakening_de")]
    pub field_weakening: Option<FieldWeakeningSettings>,
    /// Limit of the speed command, mechanical rpm (`FocConfig::max_speed_rad_s`); speed
    /// references above it are clamped. Default: foc's base-speed limit (the back-EMF at
    /// 95 % of the voltage limit, `0.95 U / (sqrt(3) psi_f)`), twice that with field
    /// weakening on.
    pub max_speed_rpm: Option<f64>,
}

/// Field weakening in `[controller.foc]`: `field_weakening = true` (foc's defaults) or a
/// table with `FieldWeakeningConfig`'s fields, each optional (the bandwidth in Hz, like the
/// scenario's other loops): `enabled` (default `true`: a table asks for it),
/// `voltage_margin` (default 0.95), `bandwidth_hz` (default a tenth of
/// `controller.current_bandwidth_hz`, foc's rule), `max_negative_id_a` (default foc's,
/// `min(current_limit_a, psi_f / Ld)`).
#[derive(Clone, Copy, Debug, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct FieldWeakeningSettings {
    /// Whether the loop runs.
    #[serde(default = "yes")]
    pub enabled: bool,
    /// The voltage magnitude held above base speed, fraction of the limit, in `[0.5, 1]`.
    #[serde(default)]
    pub voltage_margin: Option<f64>,
    /// Crossover of the loop, Hz.
    #[serde(default)]
    pub bandwidth_hz: Option<f64>,
    /// Largest negative d current, A (a positive number, at most the current limit).
    #[serde(default)]
    pub max_negative_id_a: Option<f64>,
}

fn yes() -> bool {
    true
}

impl FieldWeakeningSettings {
    /// `field_weakening = enabled`: foc's defaults.
    pub fn flag(enabled: bool) -> Self {
        Self {
            enabled,
            voltage_margin: None,
            bandwidth_hz: None,
            max_negative_id_a: None,
        }
    }
}

/// Reads `field_weakening` as a boolean or a table.
fn field_weakening_de<'de, D>(de: D) -> Result<Option<FieldWeakeningSettings>, D::Error>
where
    D: serde::Deserializer<'de>,
{
    struct V;
    impl<'de> serde::de::Visitor<'de> for V {
        type Value = FieldWeakeningSettings;
        fn expecting(&self, f: &mut core::fmt::Formatter<'_>) -> core::fmt::Result {
            f.write_str("true, false or a table of field-weakening settings")
        }
        fn visit_bool<E: serde::de::Error>(self, v: bool) -> Result<Self::Value, E> {
            Ok(FieldWeakeningSettings::flag(v))
        }
        fn visit_map<A: serde::de::MapAccess<'de>>(self, map: A) -> Result<Self::Value, A::Error> {
            FieldWeakeningSettings::deserialize(serde::de::value::MapAccessDeserializer::new(map))
        }
    }
    de.deserialize_any(V).map(Some)
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
    /// For `foc`: `ComputationDelay::OnePeriod` when true, `ComputationDelay::None` when false.
    #[serde(default)]
    pub delay_compensation: Option<bool>,
    /// `foc` settings (only with a `foc` kind).
    #[serde(default)]
    pub foc: Option<FocSettings>,
}

/// Observer settings (`[observer]`); the observer is `ObserverConfig::new` on these
/// parameters.
#[derive(Clone, Copy, Debug, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields, default)]
pub struct ObserverSettings {
    /// Also run the reference filter (`ObserverConfig::seed`) alongside, for comparison.
    /// TOML key `seed_filter` (the name the scenario is written out with: the presets, the
    /// MCAP log); `reference_filter` is accepted as another spelling.
    #[serde(rename = "seed_filter", alias = "reference_filter")]
    pub reference_filter: bool,
    /// The observer's stator resistance (default: the motor's), ohm.
    pub rs_ohm: Option<f64>,
    /// The observer's inductance, both axes (a surface model; default: the motor's `Ld`
    /// and `Lq`), H. `ld_h` / `lq_h` override it per axis.
    pub ls_h: Option<f64>,
    /// The observer's d-axis inductance (default: `ls_h`, else the motor's), H.
    pub ld_h: Option<f64>,
    /// The observer's q-axis inductance (default: `ls_h`, else the motor's), H.
    pub lq_h: Option<f64>,
    /// The observer's flux linkage (default: the motor's), Wb.
    pub psi_f_wb: Option<f64>,
    /// Status `Uncertain` above this angle standard deviation (default 0.2), rad.
    pub angle_sigma_limit_rad: Option<f64>,
}

impl Default for ObserverSettings {
    fn default() -> Self {
        Self {
            reference_filter: true,
            rs_ohm: None,
            ls_h: None,
            ld_h: None,
            lq_h: None,
            psi_f_wb: None,
            angle_sigma_limit_rad: None,
        }
    }
}

/// Control periods in which the controller does not run (`[skipped_cycles]`; module
/// [`crate::sim`], "Skipped control cycles"). Default: none.
#[derive(Clone, Debug, Default, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields, default)]
pub struct SkippedCycles {
    /// Probability that a period is skipped, each period independently, `[0, 0.5]`.
    pub probability: f64,
    /// Times at which the period containing them is skipped, s (`>= 0`).
    pub times_s: Vec<f64>,
}

impl SkippedCycles {
    /// Whether any period can be skipped.
    pub fn is_on(&self) -> bool {
        self.probability > 0.0 || !self.times_s.is_empty()
    }

    /// Nothing set (not written to TOML).
    pub fn is_default(&self) -> bool {
        *self == Self::default()
    }

    /// Checks the settings; errors name `skipped_cycles.<field>`.
    pub fn validate(&self) -> Result<(), FieldError> {
        let p = self.probability;
        if !(p.is_finite() && (0.0..=0.5).contains(&p)) {
            return Err(FieldError::new(
                "skipped_cycles.probability",
                format!("must be in [0, 0.5], is {p}"),
            ));
        }
        for (i, t) in self.times_s.iter().enumerate() {
            if !(t.is_finite() && *t >= 0.0) {
                return Err(FieldError::new(
                    format!("skipped_cycles.times_s[{i}]"),
                    format!("must be finite and >= 0, is {t}"),
                ));
            }
        }
        Ok(())
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
    /// Injected faults (`[[faults]]`, module [`crate::plant::fault_injection`]; default: none).
    #[serde(default, skip_serializing_if = "Vec::is_empty")]
    pub faults: Vec<FaultSpec>,
    /// Control periods the controller misses (`[skipped_cycles]`; default: none).
    #[serde(default, skip_serializing_if = "SkippedCycles::is_default")]
    pub skipped_cycles: SkippedCycles,
    /// The simulator's EKF noise (`[observer_noise]`, the block `pmsm-sim tune` prints;
    /// [`ObserverNoise`]; default: `ObserverConfig::new`'s).
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub observer_noise: Option<ObserverNoise>,
}

/// A problem in a TOML text, as `(field path, message)`.
fn toml_problem(text: &str, path: &str, err: &toml::de::Error) -> (String, String) {
    let mut problem = messages::user_words(err.message().trim());
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

    /// Reads and validates a scenario from any serde data with the TOML file's layout (a
    /// Python dict through pythonize, JSON, ...), with a file's messages: the data become a
    /// TOML table first (what TOML cannot hold, a `None`, is refused there by its key path),
    /// then the table is read as a file's is (`motor.pole_pairs: expected a whole number >= 0,
    /// got the string "four"`). `origin` names the source in errors.
    pub fn from_deserializer<'de, D: serde::Deserializer<'de>>(
        de: D,
        origin: &str,
    ) -> Result<Self, SimError> {
        let err = |field: String, problem: String| SimError::Scenario {
            file: origin.to_string(),
            field,
            problem,
        };
        let field_of = |path: String| {
            if path.is_empty() || path == "." {
                "-".to_string()
            } else {
                path
            }
        };
        let table: toml::Value = serde_path_to_error::deserialize(de).map_err(|e| {
            let path = field_of(e.path().to_string());
            err(path, messages::user_words(e.inner().to_string().trim()))
        })?;
        let sc: Scenario = serde_path_to_error::deserialize(table).map_err(|e| {
            let path = field_of(e.path().to_string());
            err(path, messages::user_words(e.inner().message().trim()))
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
        // A flux map in a file of its own is read into the table first.
        if text.contains("flux_map")
            && let Ok(mut table) = toml::from_str::<toml::Value>(&text)
            && table
                .get("motor")
                .and_then(|m| m.get("flux_map"))
                .and_then(|f| f.get("file"))
                .is_some()
        {
            let dir = path.parent().unwrap_or(std::path::Path::new("."));
            crate::plant::saturation::inline_flux_map_file(&mut table, dir).map_err(
                |(field, problem)| SimError::Scenario {
                    file: file.clone(),
                    field,
                    problem,
                },
            )?;
            let text = toml::to_string(&table).map_err(|e| SimError::Scenario {
                file: file.clone(),
                field: "motor.flux_map".into(),
                problem: e.to_string(),
            })?;
            return Self::from_toml_str(&text, &file);
        }
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

    /// The built-in default scenario (`scenarios/default.toml`): the `foc` crate's sensorless
    /// controller on the servo motor of docs/design.md, "Reference motors" at 10 kHz, from standstill to
    /// rated speed, a rated load step and a reversal.
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

    /// What the injected faults are checked and armed against.
    pub fn fault_context(&self) -> RunContext {
        RunContext {
            duration_s: self.duration_s,
            ts_s: self.ts_s(),
            seed: self.seed,
            rated_current_a: self.rated_torque_nm / self.motor.torque_constant_nm_a(),
            rs_ohm: self.motor.rs_ohm,
            psi_f_wb: self.motor.psi_f_wb,
        }
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

    /// The scenario as TOML (what `pmsm-sim show` prints for a file, and the MCAP log keeps).
    pub fn to_toml(&self) -> Result<String, SimError> {
        toml::to_string(self).map_err(|e| SimError::Scenario {
            file: self.name.clone(),
            field: "-".into(),
            problem: format!("cannot write as TOML: {e}"),
        })
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
        assert_eq!(sc.periods(), 20_000);
        let m = sc.motor.clone();
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
        // The default preset takes its motor from the catalog; keys beside it override.
        let catalog = "catalog = \"servo\"  # ekf_core::catalog; keys given here override it";
        assert!(default_text().contains(catalog));
        let with = |extra: &str| default_text().replace(catalog, &format!("{catalog}\n{extra}"));
        // Missing field (no catalog, no data).
        let t = default_text().replace(catalog, "");
        let (field, problem) = error_of(&t);
        assert_eq!(field, "motor");
        assert!(problem.contains("motor.rs_ohm is missing"), "{problem}");
        // Wrong type, in the file's words.
        let (field, problem) = error_of(&with("pole_pairs = \"four\""));
        assert_eq!(field, "motor.pole_pairs");
        assert!(
            problem.starts_with("expected a whole number >= 0, got the string \"four\" (line"),
            "{problem}"
        );
        // Unknown field (a typo).
        let t = default_text().replace("dead_time_s", "deadtime_s");
        let (field, problem) = error_of(&t);
        assert_eq!(field, "inverter.deadtime_s");
        assert!(problem.contains("unknown field"), "{problem}");
        // Not TOML at all.
        let (field, _) = error_of("name = \n");
        assert_eq!(field, "-");
        // Physically invalid values, refused before the run.
        assert_eq!(error_of(&with("ld_h = -8.5e-3")).0, "motor.ld_h");
        // ls_h (both axes) is resolved on reading: named as written.
        let (field, problem) = error_of(&with("ls_h = 1e300"));
        assert_eq!(field, "motor");
        assert!(
            problem.starts_with("motor.ls_h: allowed: 1e-8 <= x <= 10.0 H, is 1e300"),
            "{problem}"
        );
        let t = default_text().replace("ts_s = 1e-4", "ts_s = 0.0");
        assert_eq!(error_of(&t).0, "inverter.ts_s");
        let t = default_text().replace("dead_time_s = 0.5e-6", "dead_time_s = 2e-4");
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

    #[test]
    fn other_serde_sources_get_a_files_messages() {
        let table: toml::Value = toml::from_str(default_text()).unwrap_or_else(|e| panic!("{e}"));
        let mut v = serde_json::to_value(&table).unwrap_or_else(|e| panic!("{e}"));
        let sc = Scenario::from_deserializer(v.clone(), "dict").unwrap_or_else(|e| panic!("{e}"));
        assert_eq!(sc, Scenario::default_servo());
        v["motor"]["pole_pairs"] = "four".into();
        let e = Scenario::from_deserializer(v.clone(), "dict").map_err(|e| e.to_string());
        assert_eq!(
            e.err().as_deref(),
            Some("dict: motor.pole_pairs: expected a whole number >= 0, got the string \"four\"")
        );
        v["motor"]["pole_pairs"] = 4.into();
        v["duration_s"] = serde_json::Value::Null;
        let e = Scenario::from_deserializer(v, "dict").map_err(|e| e.to_string());
        assert!(
            e.as_ref()
                .is_err_and(|e| e.starts_with("dict: duration_s: ")),
            "{e:?}"
        );
    }

    #[test]
    fn the_reference_filter_key_has_two_spellings() {
        for (key, on) in [("reference_filter", false), ("seed_filter", false)] {
            let t = default_text().replace("seed_filter = true", &format!("{key} = {on}"));
            let sc = Scenario::from_toml_str(&t, key).unwrap_or_else(|e| panic!("{e}"));
            assert_eq!(sc.observer.reference_filter, on, "{key}");
        }
    }

    #[test]
    fn foc_settings_are_checked() {
        // A typo in [controller.foc].
        let t = default_text().replace("if_current_a = 2.5", "if_curent_a = 2.5");
        let (field, problem) = error_of(&t);
        assert_eq!(field, "controller.foc.if_curent_a");
        assert!(problem.contains("unknown field"), "{problem}");
        // Out of range here.
        let t = default_text().replace("if_current_a = 2.5", "if_current_a = -2.5");
        assert_eq!(error_of(&t).0, "controller.foc.if_current_a");
        let t = default_text().replace("start_time_s = 0.0", "start_time_s = -1.0");
        assert_eq!(error_of(&t).0, "controller.foc.start_time_s");
        // Refused by foc itself (the I/f current above the current limit).
        let t = default_text().replace("if_current_a = 2.5", "if_current_a = 5.0");
        let (field, problem) = error_of(&t);
        // (the alignment current follows the I/f current and is checked first: named by
        // the key it follows, with foc's allowed range)
        assert_eq!(field, "controller.foc.if_current_a");
        assert!(
            problem.contains("foc refuses")
                && problem.contains("out of range")
                && problem.contains("allowed: 0 < x <= controller.current_limit_a"),
            "{problem}"
        );
        // "sensored" is another spelling of "foc_sensored".
        let t = default_text().replace("kind = \"foc\"", "kind = \"sensored\"");
        let sc = Scenario::from_toml_str(&t, "sensored").unwrap_or_else(|e| panic!("{e}"));
        assert_eq!(sc.controller.kind, ControllerKind::FocSensored);
    }

    #[test]
    fn foc_config_matches_the_scenario() {
        use foc::{ComputationDelay, Mode};
        let sc = Scenario::default_servo();
        let c = sc.foc_config().unwrap_or_else(|e| panic!("{e:?}"));
        assert_eq!(c.delay, ComputationDelay::OnePeriod);
        assert_eq!(c.angle_advance_periods, 1.5);
        assert_eq!(c.mode, Mode::Sensorless);
        assert_eq!(c.ts_s, 1e-4);
        assert_eq!(c.current_limit_a, 4.5);
        assert_eq!(c.over_current_a, 9.0);
        assert_eq!(c.inertia_kg_m2, 8e-4);
        assert_eq!(c.startup.if_current_a, 2.5);
        assert_eq!(c.startup.align_time_s, 0.1);
        // 2000 rpm/s mech. = 837.8 rad/s^2 el.; the damped start's hand-over at 3 % of the
        // rated 2000 rpm: 25.13 rad/s el., the exit at half of it (1.5 % of rated).
        assert!((c.startup.accel_rad_s2 - 837.758).abs() < 1e-2);
        assert!((c.startup.handover_speed_rad_s - 25.132_74).abs() < 1e-3);
        assert!((c.startup.exit_speed_ratio - 0.5).abs() < 1e-6);
        // The classic start (no damping): foc's rule, 2 Rs I_f / psi_f = 82.1 rad/s el., the
        // exit at 1.5 % of rated speed (12.57 rad/s el.).
        let mut classic = sc.clone();
        let mut f = classic.controller.foc.unwrap_or_default();
        f.startup_damping_ratio = Some(0.0);
        classic.controller.foc = Some(f);
        let c = classic.foc_config().unwrap_or_else(|e| panic!("{e:?}"));
        assert!((c.startup.handover_speed_rad_s - 82.142_86).abs() < 1e-3);
        let exit = c.startup.exit_speed_ratio * c.startup.handover_speed_rad_s;
        assert!((exit - 12.566_37).abs() < 1e-3, "{exit}");
        let c = sc.foc_config().unwrap_or_else(|e| panic!("{e:?}"));
        assert!((c.current_bw_rad_s - 3141.5927).abs() < 1e-2);
        let ideal = Scenario::preset("servo-ideal").unwrap_or_else(|e| panic!("{e}"));
        let c = ideal.foc_config().unwrap_or_else(|e| panic!("{e:?}"));
        assert_eq!(c.delay, ComputationDelay::None);
        assert_eq!(c.angle_advance_periods, 0.5);
        let mut s = sc.clone();
        s.controller.kind = ControllerKind::FocSensored;
        assert_eq!(s.foc_config().map(|c| c.mode), Ok(Mode::Sensored));
    }

    #[test]
    fn startup_timing_from_the_motor_is_opt_in() {
        let drone = Scenario::preset("drone").unwrap_or_else(|e| panic!("{e}"));
        let fixed = drone.foc_config().unwrap_or_else(|e| panic!("{e:?}"));
        assert_eq!(fixed.startup.align_time_s, 0.2);
        // By hand (small_fast, I_align = I_f = 7.5 A, J = 2e-5): tau_e = 0.15 mH / 0.12 ohm
        // = 1.25 ms; w_n^2 = 1.5 49 0.006 7.5 / 2e-5 = 165375, T = 2 pi / 406.66 = 15.451 ms;
        // alignment 5 tau_e + 2 T = 37.15 ms; acceleration 0.25 7 0.063 7.5 / 2e-5 = 41344
        // rad/s^2 el., but the ramp to the hand-over speed (the damped start's 3 % of the
        // rated 3429 rpm, 75.41 rad/s el.) at least 2 T = 30.90 ms: 2440.2 rad/s^2 el.
        let (align, accel, ramp) = drone.motor_startup_timing(7.5, 7.5, 2e-5);
        assert!((align - 0.037_15).abs() < 1e-5, "{align}");
        assert!((accel - 41_343.75).abs() < 1e-2, "{accel}");
        assert!((ramp - 0.030_90).abs() < 1e-5, "{ramp}");
        let mut sc = drone.clone();
        let mut foc = sc.controller.foc.unwrap_or_default();
        foc.startup_timing = StartupTiming::Motor;
        sc.controller.foc = Some(foc);
        let c = sc.foc_config().unwrap_or_else(|e| panic!("{e:?}"));
        assert!((c.startup.align_time_s - 0.037_15).abs() < 1e-5);
        assert!(
            (c.startup.accel_rad_s2 - 2440.2).abs() < 1.0,
            "{}",
            c.startup.accel_rad_s2
        );
        // Explicit times win; the option is written to TOML only when set.
        foc.align_time_s = Some(0.15);
        sc.controller.foc = Some(foc);
        let c = sc.foc_config().unwrap_or_else(|e| panic!("{e:?}"));
        assert_eq!(c.startup.align_time_s, 0.15);
        let text = sc.to_toml().unwrap_or_default();
        assert!(text.contains("startup_timing = \"motor\""), "{text}");
        assert!(
            !drone
                .to_toml()
                .unwrap_or_default()
                .contains("startup_timing")
        );
    }

    #[test]
    fn mtpa_field_weakening_and_max_speed_settings() {
        let with = |extra: &str| {
            default_text().replace(
                "startup_accel_rpm_per_s = 2000.0",
                &format!("startup_accel_rpm_per_s = 2000.0\n{extra}"),
            )
        };
        let cfg_of = |text: &str| {
            Scenario::from_toml_str(text, "t.toml")
                .and_then(|sc| {
                    sc.foc_config().map_err(|e| SimError::Scenario {
                        file: "t.toml".into(),
                        field: e.field,
                        problem: e.problem,
                    })
                })
                .unwrap_or_else(|e| panic!("{e}"))
        };
        // Defaults: foc's (MTPA on, field weakening off, base-speed limit).
        let base = cfg_of(default_text());
        assert!(base.mtpa);
        assert!(!base.field_weakening.enabled);
        let u_max = 300.0 / 3f32.sqrt();
        assert!((base.max_speed_rad_s - 0.95 * u_max / 0.175).abs() < 1e-2);
        // A flag: foc's defaults, the speed limit doubled, bandwidth a tenth of the current
        // loop's (500 Hz); the hand-over speed unchanged.
        let c = cfg_of(&with("field_weakening = true\nmtpa = false"));
        assert!(c.field_weakening.enabled && !c.mtpa);
        assert_eq!(c.max_speed_rad_s, 2.0 * base.max_speed_rad_s);
        assert!((c.field_weakening.bandwidth_rad_s - 0.1 * c.current_bw_rad_s).abs() < 1e-3);
        assert_eq!(c.field_weakening.voltage_margin, 0.95);
        assert_eq!(
            c.startup.handover_speed_rad_s,
            base.startup.handover_speed_rad_s
        );
        assert!(
            !cfg_of(&with("field_weakening = false"))
                .field_weakening
                .enabled
        );
        // A table, and an explicit maximum speed (4 pole pairs: 3000 rpm = 1256.6 rad/s el.).
        let c = cfg_of(&with(
            "max_speed_rpm = 3000.0\n[controller.foc.field_weakening]\nvoltage_margin = 0.9\n\
             bandwidth_hz = 40.0\nmax_negative_id_a = 4.0",
        ));
        let fw = c.field_weakening;
        assert!(fw.enabled);
        assert_eq!(fw.voltage_margin, 0.9);
        assert!((fw.bandwidth_rad_s - 251.327_4).abs() < 1e-3);
        assert_eq!(fw.max_negative_id_a, Some(4.0));
        assert!((c.max_speed_rad_s - 1256.637).abs() < 1e-2);
        // Round trip of the table form.
        let sc = Scenario::from_toml_str(&with("field_weakening = true"), "t")
            .unwrap_or_else(|e| panic!("{e}"));
        let back = Scenario::from_toml_str(&sc.to_toml().unwrap_or_default(), "back")
            .unwrap_or_else(|e| panic!("{e}"));
        assert_eq!(back, sc);
        // Bad values name the field.
        for (extra, field) in [
            (
                "[controller.foc.field_weakening]\nvoltage_margin = 1.2",
                "controller.foc.field_weakening.voltage_margin",
            ),
            (
                "[controller.foc.field_weakening]\nbandwidth_hz = 900.0",
                "controller.foc.field_weakening.bandwidth_hz",
            ),
            (
                "[controller.foc.field_weakening]\nmax_negative_id_a = 9.0",
                "controller.foc.field_weakening.max_negative_id_a",
            ),
            (
                "[controller.foc.field_weakening]\nmax_negative_id_a = -1.0",
                "controller.foc.field_weakening.max_negative_id_a",
            ),
            ("max_speed_rpm = 0.0", "controller.foc.max_speed_rpm"),
            (
                "[controller.foc.field_weakening]\nmargin = 0.9",
                "controller.foc.field_weakening.margin",
            ),
        ] {
            assert_eq!(error_of(&with(extra)).0, field, "{extra}");
        }
        let (field, problem) = error_of(&with("field_weakening = 3"));
        assert_eq!(field, "controller.foc.field_weakening");
        assert!(problem.contains("true, false or a table"), "{problem}");
    }
}
