//! The run plan: a scenario turned once, before the run, into what the run loop and the drive
//! need. [`Scenario::plan`] validates the scenario and derives, in this order, the period,
//! the number of periods, the plant's initial state, the observers' configurations, the
//! context the injected faults are armed against and `foc`'s configuration; the run
//! ([`crate::sim`]) and [`FocDrive::from_plan`](crate::drive::foc_adapter::FocDrive::from_plan)
//! read the plan, not the scenario's translations.

use super::*;
use crate::plant::PlantState;

/// A validated scenario and what a run derives from it (module docs).
#[derive(Clone, Debug)]
pub struct RunPlan<'a> {
    /// The scenario (its profiles, load terms, faults and settings are read as they are).
    pub scenario: &'a Scenario,
    /// PWM (control) period, s.
    pub ts_s: f64,
    /// Periods simulated ([`Scenario::periods`]).
    pub periods: usize,
    /// Whether the inverter applies the duties one period late.
    pub delay: bool,
    /// The plant's state at `t = 0`.
    pub initial: PlantState,
    /// The default EKF's configuration ([`Scenario::observer_config`]).
    pub observer: ekf_core::ObserverConfig<f64>,
    /// The reference filter's configuration, when it runs
    /// ([`Scenario::reference_filter_config`]).
    pub reference_filter: Option<ekf_core::ObserverConfig<f64>>,
    /// What the injected faults are checked and armed against.
    pub fault_context: RunContext,
    /// `foc`'s configuration ([`Scenario::foc_config`]).
    pub foc: foc::FocConfig,
}

impl Scenario {
    /// The scenario as a [`RunPlan`]; errors name the field when the scenario is invalid.
    pub fn plan(&self) -> Result<RunPlan<'_>, SimError> {
        let err = |e: FieldError| SimError::Scenario {
            file: self.name.clone(),
            field: e.field,
            problem: e.problem,
        };
        self.validate().map_err(err)?;
        Ok(RunPlan {
            scenario: self,
            ts_s: self.ts_s(),
            periods: self.periods(),
            delay: self.inverter.delay,
            initial: PlantState {
                theta_e_rad: self.initial.theta_e_rad,
                omega_mech_rad_s: self.initial.speed_rpm / RPM_PER_RAD_S,
                ..PlantState::default()
            },
            observer: self.observer_config(),
            reference_filter: self
                .observer
                .reference_filter
                .then(|| self.reference_filter_config()),
            fault_context: self.fault_context(),
            foc: self.foc_config().map_err(err)?,
        })
    }
}
