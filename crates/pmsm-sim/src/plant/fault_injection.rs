//! Fault injection: the `[[faults]]` of a scenario and where each acts in the loop.
//!
//! Every fault has a start time `t_s` (s; acts from the first sample at or after it) and,
//! for most kinds, a `duration_s` (default: to the end of the run). Times are rounded to
//! whole PWM periods: a fault with start period `k0 = round(t_s / Ts)` and `n =
//! max(1, round(duration_s / Ts))` periods acts on the samples `k0 .. k0 + n`.
//!
//! | `kind` | parameters | acts on | effect |
//! |---|---|---|---|
//! | `offset_drift` | `channel` (`"a"`/`"b"`, default a), `rate_a_per_s` | current sensor | the channel's offset grows at `rate_a_per_s` from `t_s` for `duration_s`, then stays at the value reached |
//! | `gain_step` | `channel`, `gain_error` (fraction, > -1) | current sensor | the channel reads `(1 + gain_error)` times what it should while active |
//! | `stuck` | `channel`, `value_a` (default: the channel's last reading before `t_s`) | current sensor | the channel's output frozen |
//! | `dropout` | `channel` (`"a"`, `"b"` or `"both"`), `duration_s` (default one period) | current sensor | the sample is missing: NaN |
//! | `noise_burst` | `std_a` | current sensor | extra white Gaussian noise of `std_a` on both channels (its own generator, seeded from the scenario's seed: the sensor's noise stream is unchanged) |
//! | `glitch` | `channel`, `value_a` (default: ten times the rated current, `rated_torque_nm / (1.5 p psi_f)`) | current sensor | one sample reads `value_a` (no `duration_s`) |
//! | `bus_sag` | `fraction` (in `(0, 1)`) | inverter, bus measurement | the DC bus drops to `(1 - fraction)` of its value (the controller measures it) |
//! | `phase_open` | `phase` (`"a"`/`"b"`/`"c"`) | plant | the phase's current is zero (an open winding or a blown bond wire; [`Plant::open_phase`]) |
//! | `param_drift` | `temperature_rise_k`, `rs_per_k` (default 0.00393, copper), `psi_f_per_k` (default -0.0012, NdFeB), `time_constant_s` (optional) | plant | the motor's `Rs` and `psi_f` ramp over `duration_s` (default: a step), or approach exponentially with `time_constant_s` (a thermal time constant), to `(1 + coeff dT)` times their value and stay; the controller keeps its nominal parameters (its observer tracks them) |
//! | `locked_rotor` | - | plant (mechanics) | the rotor jams: speed zero while active |
//! | `overload` | `torque_nm` | load | extra load torque while active (beyond rating when above `rated_torque_nm`) |
//!
//! Unknown keys are errors naming the field; [`FaultSpec::validate`] checks the values
//! before the run (the scenario's validation calls it with the field `faults[i]`).
//!
//! The run loop ([`crate::sim`]) calls the [`FaultInjector`] at each place: the sensor sample
//! ([`FaultInjector::measure`]), the bus voltage ([`FaultInjector::bus_factor`]), the load
//! ([`FaultInjector::extra_load_nm`]), the plant before and after its step
//! ([`FaultInjector::before_step`], [`FaultInjector::after_step`]). Without faults it is not
//! built and the loop is unchanged. The simulator's own observers (which only ride along) only
//! predict over a missing sample (their [`Observer`](crate::drive::rotor_observers::Observer) impl).

use rand::SeedableRng;
use rand::rngs::Xoshiro256PlusPlus;
use rand_distr::{Distribution, StandardNormal};
use serde::{Deserialize, Serialize};

use crate::error::FieldError;
use crate::plant::Plant;
use crate::plant::sensors::{ChannelFaults, CurrentSample, CurrentSensor};

/// A current-sensor channel.
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq, Serialize, Deserialize)]
#[serde(rename_all = "snake_case")]
pub enum Channel {
    /// Phase a.
    #[default]
    A,
    /// Phase b.
    B,
}

impl Channel {
    fn index(self) -> usize {
        match self {
            Channel::A => 0,
            Channel::B => 1,
        }
    }
}

/// The channels a dropout hits.
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq, Serialize, Deserialize)]
#[serde(rename_all = "snake_case")]
pub enum Channels {
    /// Phase a.
    #[default]
    A,
    /// Phase b.
    B,
    /// Both (the whole conversion is missing).
    Both,
}

/// A motor phase.
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq, Serialize, Deserialize)]
#[serde(rename_all = "snake_case")]
pub enum Phase {
    /// Phase a.
    #[default]
    A,
    /// Phase b.
    B,
    /// Phase c.
    C,
}

fn copper() -> f64 {
    0.00393
}

fn ndfeb() -> f64 {
    -0.0012
}

/// Longest fault duration (and `param_drift` time constant), s.
pub const MAX_FAULT_DURATION_S: f64 = 1e9;
/// Largest temperature rise of `param_drift`, K (either sign).
pub const MAX_TEMPERATURE_RISE_K: f64 = 500.0;
/// Largest relative change per kelvin of `param_drift` (`rs_per_k`, `psi_f_per_k`; copper
/// is 0.00393, NdFeB -0.0012).
pub const MAX_PER_K: f64 = 0.02;

/// One injected fault (`[[faults]]`; module docs list the kinds).
#[derive(Clone, Copy, Debug, PartialEq, Serialize, Deserialize)]
#[serde(tag = "kind", rename_all = "snake_case", deny_unknown_fields)]
pub enum FaultSpec {
    /// Sensor offset drift.
    OffsetDrift {
        /// Start, s.
        t_s: f64,
        /// Drift time, s (default: to the end); the offset then stays.
        #[serde(default)]
        duration_s: Option<f64>,
        /// Channel.
        #[serde(default)]
        channel: Channel,
        /// Drift rate, A/s.
        rate_a_per_s: f64,
    },
    /// Sensor gain error step.
    GainStep {
        /// Start, s.
        t_s: f64,
        /// Duration, s (default: to the end).
        #[serde(default)]
        duration_s: Option<f64>,
        /// Channel.
        #[serde(default)]
        channel: Channel,
        /// Gain error, fraction (0.1 reads 10 % high).
        gain_error: f64,
    },
    /// A channel stuck at a value.
    Stuck {
        /// Start, s.
        t_s: f64,
        /// Duration, s (default: to the end).
        #[serde(default)]
        duration_s: Option<f64>,
        /// Channel.
        #[serde(default)]
        channel: Channel,
        /// The frozen reading, A (default: the last reading before `t_s`).
        #[serde(default)]
        value_a: Option<f64>,
    },
    /// Missing samples (NaN).
    Dropout {
        /// Start, s.
        t_s: f64,
        /// Duration, s (default: one period).
        #[serde(default)]
        duration_s: Option<f64>,
        /// Channels.
        #[serde(default)]
        channel: Channels,
    },
    /// Extra noise on both channels.
    NoiseBurst {
        /// Start, s.
        t_s: f64,
        /// Duration, s (default: to the end).
        #[serde(default)]
        duration_s: Option<f64>,
        /// Standard deviation of the extra noise, A.
        std_a: f64,
    },
    /// One wild sample.
    Glitch {
        /// Time of the sample, s.
        t_s: f64,
        /// Channel.
        #[serde(default)]
        channel: Channel,
        /// The reading, A (default: ten times the rated current).
        #[serde(default)]
        value_a: Option<f64>,
    },
    /// DC-bus sag.
    BusSag {
        /// Start, s.
        t_s: f64,
        /// Duration, s (default: to the end).
        #[serde(default)]
        duration_s: Option<f64>,
        /// Drop as a fraction of the bus voltage, in `(0, 1)`.
        fraction: f64,
    },
    /// An open motor phase.
    PhaseOpen {
        /// Start, s.
        t_s: f64,
        /// Duration, s (default: to the end).
        #[serde(default)]
        duration_s: Option<f64>,
        /// The phase.
        phase: Phase,
    },
    /// Motor parameter drift with temperature.
    ParamDrift {
        /// Start, s.
        t_s: f64,
        /// Ramp time, s (default: a step).
        #[serde(default)]
        duration_s: Option<f64>,
        /// Thermal time constant, s: the temperature approaches the rise exponentially,
        /// `dT (1 - exp(-(t - t_s) / tau))` (instead of `duration_s`'s linear ramp).
        #[serde(default)]
        time_constant_s: Option<f64>,
        /// Temperature rise, K.
        temperature_rise_k: f64,
        /// Relative change of `Rs` per kelvin (default copper, 0.00393).
        #[serde(default = "copper")]
        rs_per_k: f64,
        /// Relative change of `psi_f` per kelvin (default NdFeB, -0.0012).
        #[serde(default = "ndfeb")]
        psi_f_per_k: f64,
    },
    /// A jammed rotor.
    LockedRotor {
        /// Start, s.
        t_s: f64,
        /// Duration, s (default: to the end).
        #[serde(default)]
        duration_s: Option<f64>,
    },
    /// Extra load torque.
    Overload {
        /// Start, s.
        t_s: f64,
        /// Duration, s (default: to the end).
        #[serde(default)]
        duration_s: Option<f64>,
        /// Extra load torque, N m.
        torque_nm: f64,
    },
}

impl FaultSpec {
    /// The kind's name, as in the TOML.
    pub fn kind(&self) -> &'static str {
        match self {
            FaultSpec::OffsetDrift { .. } => "offset_drift",
            FaultSpec::GainStep { .. } => "gain_step",
            FaultSpec::Stuck { .. } => "stuck",
            FaultSpec::Dropout { .. } => "dropout",
            FaultSpec::NoiseBurst { .. } => "noise_burst",
            FaultSpec::Glitch { .. } => "glitch",
            FaultSpec::BusSag { .. } => "bus_sag",
            FaultSpec::PhaseOpen { .. } => "phase_open",
            FaultSpec::ParamDrift { .. } => "param_drift",
            FaultSpec::LockedRotor { .. } => "locked_rotor",
            FaultSpec::Overload { .. } => "overload",
        }
    }

    /// Start time, s.
    pub fn start_s(&self) -> f64 {
        let mut spec = *self;
        *spec.start_mut()
    }

    /// The same fault starting at `t_s`.
    pub fn at(mut self, t: f64) -> Self {
        *self.start_mut() = t;
        self
    }

    /// The start time of every kind.
    fn start_mut(&mut self) -> &mut f64 {
        match self {
            FaultSpec::OffsetDrift { t_s, .. }
            | FaultSpec::GainStep { t_s, .. }
            | FaultSpec::Stuck { t_s, .. }
            | FaultSpec::Dropout { t_s, .. }
            | FaultSpec::NoiseBurst { t_s, .. }
            | FaultSpec::Glitch { t_s, .. }
            | FaultSpec::BusSag { t_s, .. }
            | FaultSpec::PhaseOpen { t_s, .. }
            | FaultSpec::ParamDrift { t_s, .. }
            | FaultSpec::LockedRotor { t_s, .. }
            | FaultSpec::Overload { t_s, .. } => t_s,
        }
    }

    /// `duration_s` as given (`None` for a glitch).
    pub fn duration_s(&self) -> Option<f64> {
        match *self {
            FaultSpec::OffsetDrift { duration_s, .. }
            | FaultSpec::GainStep { duration_s, .. }
            | FaultSpec::Stuck { duration_s, .. }
            | FaultSpec::Dropout { duration_s, .. }
            | FaultSpec::NoiseBurst { duration_s, .. }
            | FaultSpec::BusSag { duration_s, .. }
            | FaultSpec::PhaseOpen { duration_s, .. }
            | FaultSpec::ParamDrift { duration_s, .. }
            | FaultSpec::LockedRotor { duration_s, .. }
            | FaultSpec::Overload { duration_s, .. } => duration_s,
            FaultSpec::Glitch { .. } => None,
        }
    }

    /// Checks the values for a run (start within the run, positive durations, the kind's
    /// parameters); errors name `field.<name>`.
    pub fn validate(&self, field: &str, run: &RunContext) -> Result<(), FieldError> {
        let err =
            |name: &str, problem: String| Err(FieldError::new(format!("{field}.{name}"), problem));
        let t = self.start_s();
        if !(t.is_finite() && t >= 0.0) {
            return err("t_s", format!("must be finite and >= 0, is {t}"));
        }
        if t >= run.duration_s {
            return err(
                "t_s",
                format!(
                    "{t} s is not before the end of the run ({} s)",
                    run.duration_s
                ),
            );
        }
        if let Some(d) = self.duration_s() {
            let drift = matches!(self, FaultSpec::ParamDrift { .. });
            if !(d <= MAX_FAULT_DURATION_S && (d > 0.0 || drift && d == 0.0)) {
                let lo = if drift { "0 <=" } else { "0 <" };
                return err(
                    "duration_s",
                    format!(
                        "allowed: {lo} x <= {} s, is {}",
                        crate::error::plain(MAX_FAULT_DURATION_S),
                        crate::error::plain(d)
                    ),
                );
            }
        }
        let finite = |name: &str, v: f64| {
            if v.is_finite() {
                Ok(())
            } else {
                err(name, format!("must be finite, is {v}"))
            }
        };
        match *self {
            FaultSpec::OffsetDrift { rate_a_per_s, .. } => finite("rate_a_per_s", rate_a_per_s),
            FaultSpec::GainStep { gain_error, .. } => {
                if gain_error.is_finite() && gain_error > -1.0 {
                    Ok(())
                } else {
                    err(
                        "gain_error",
                        format!("must be finite and > -1, is {gain_error}"),
                    )
                }
            }
            FaultSpec::Stuck { value_a, .. } | FaultSpec::Glitch { value_a, .. } => {
                value_a.map_or(Ok(()), |v| finite("value_a", v))
            }
            FaultSpec::Dropout { .. } | FaultSpec::LockedRotor { .. } => Ok(()),
            FaultSpec::PhaseOpen { .. } => Ok(()),
            FaultSpec::NoiseBurst { std_a, .. } => {
                if std_a.is_finite() && std_a > 0.0 {
                    Ok(())
                } else {
                    err("std_a", format!("must be finite and > 0, is {std_a}"))
                }
            }
            FaultSpec::BusSag { fraction, .. } => {
                if fraction.is_finite() && fraction > 0.0 && fraction < 1.0 {
                    Ok(())
                } else {
                    err("fraction", format!("must be in (0, 1), is {fraction}"))
                }
            }
            FaultSpec::ParamDrift {
                temperature_rise_k,
                rs_per_k,
                psi_f_per_k,
                time_constant_s,
                duration_s,
                ..
            } => {
                if let Some(tau) = time_constant_s {
                    if !(tau > 0.0 && tau <= MAX_FAULT_DURATION_S) {
                        return err(
                            "time_constant_s",
                            format!(
                                "allowed: 0 < x <= {} s, is {}",
                                crate::error::plain(MAX_FAULT_DURATION_S),
                                crate::error::plain(tau)
                            ),
                        );
                    }
                    if duration_s.is_some() {
                        return err(
                            "time_constant_s",
                            "give either duration_s (a linear ramp) or time_constant_s".into(),
                        );
                    }
                }
                let within = |name: &str, v: f64, max: f64, unit: &str| {
                    if v.abs() <= max {
                        Ok(())
                    } else {
                        let v = crate::error::plain(v);
                        err(name, format!("allowed: abs(x) <= {max} {unit}, is {v}"))
                    }
                };
                within(
                    "temperature_rise_k",
                    temperature_rise_k,
                    MAX_TEMPERATURE_RISE_K,
                    "K",
                )?;
                within("rs_per_k", rs_per_k, MAX_PER_K, "per K")?;
                within("psi_f_per_k", psi_f_per_k, MAX_PER_K, "per K")?;
                if 1.0 + rs_per_k * temperature_rise_k <= 0.0 {
                    return err(
                        "temperature_rise_k",
                        format!("{temperature_rise_k} K with rs_per_k = {rs_per_k} makes Rs <= 0"),
                    );
                }
                if 1.0 + psi_f_per_k * temperature_rise_k <= 0.0 {
                    return err(
                        "temperature_rise_k",
                        format!(
                            "{temperature_rise_k} K with psi_f_per_k = {psi_f_per_k} makes psi_f <= 0"
                        ),
                    );
                }
                Ok(())
            }
            FaultSpec::Overload { torque_nm, .. } => finite("torque_nm", torque_nm),
        }
    }
}

/// One fault prepared for the run: its period window.
#[derive(Clone, Copy, Debug, PartialEq)]
struct Armed {
    spec: FaultSpec,
    k0: u64,
    /// First period after the fault (`u64::MAX`: to the end).
    k1: u64,
    /// The stuck value, once captured.
    held: Option<f64>,
    /// Thermal time constant in periods (0: none; `param_drift`).
    tau_periods: f64,
}

impl Armed {
    #[inline]
    fn active(&self, k: u64) -> bool {
        k >= self.k0 && k < self.k1
    }

    /// Fraction of the ramp done at period `k` (0 before, 1 after).
    fn ramp(&self, k: u64) -> f64 {
        if k < self.k0 {
            0.0
        } else if self.tau_periods > 0.0 {
            -(-((k - self.k0) as f64) / self.tau_periods).exp_m1()
        } else if self.k1 == u64::MAX || k >= self.k1 {
            1.0
        } else {
            (k - self.k0) as f64 / (self.k1 - self.k0) as f64
        }
    }
}

/// What faults are checked and armed against: the few figures of the run they need, not the
/// whole scenario ([`crate::scenario::Scenario::fault_context`] makes it).
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct RunContext {
    /// Simulated duration, s (a fault must start before it).
    pub duration_s: f64,
    /// PWM period, s.
    pub ts_s: f64,
    /// Random seed of the run (the glitches' generator is seeded from it).
    pub seed: u64,
    /// Rated current of the motor, A (the glitches' scale).
    pub rated_current_a: f64,
    /// The plant's stator resistance, ohm (drift starts from it).
    pub rs_ohm: f64,
    /// The plant's flux linkage, Wb (drift starts from it).
    pub psi_f_wb: f64,
}

/// The scenario's faults during a run (module docs).
#[derive(Clone, Debug)]
pub struct FaultInjector {
    faults: Vec<Armed>,
    ts_s: f64,
    rated_current_a: f64,
    rs_ohm: f64,
    psi_f_wb: f64,
    /// The plant's `(Rs, psi_f)` last set.
    drift_set: (f64, f64),
    last_reading: [f64; 2],
    rng: Xoshiro256PlusPlus,
}

impl FaultInjector {
    /// The injector of a scenario's `[[faults]]` for a run; `None` when there are none.
    pub fn new(specs: &[FaultSpec], run: &RunContext) -> Option<Self> {
        if specs.is_empty() {
            return None;
        }
        let ts = run.ts_s;
        let periods = |t: f64| (t / ts).round().max(0.0) as u64;
        let faults = specs
            .iter()
            .map(|&spec| {
                let k0 = periods(spec.start_s());
                let k1 = match (spec, spec.duration_s()) {
                    (FaultSpec::Glitch { .. }, _) | (FaultSpec::Dropout { .. }, None) => k0 + 1,
                    (FaultSpec::ParamDrift { .. }, None) => k0,
                    // (saturating: a window past the run's end is "to the end")
                    (FaultSpec::ParamDrift { .. }, Some(d)) => k0.saturating_add(periods(d)),
                    (_, Some(d)) => k0.saturating_add(periods(d).max(1)),
                    (_, None) => u64::MAX,
                };
                let tau_periods = match spec {
                    FaultSpec::ParamDrift {
                        time_constant_s: Some(tau),
                        ..
                    } => tau / ts,
                    _ => 0.0,
                };
                Armed {
                    spec,
                    k0,
                    k1,
                    held: None,
                    tau_periods,
                }
            })
            .collect();
        Some(Self {
            faults,
            ts_s: ts,
            rated_current_a: run.rated_current_a,
            rs_ohm: run.rs_ohm,
            psi_f_wb: run.psi_f_wb,
            drift_set: (run.rs_ohm, run.psi_f_wb),
            last_reading: [0.0; 2],
            rng: Xoshiro256PlusPlus::seed_from_u64(run.seed ^ 0x6661_756c_7473),
        })
    }

    /// The current sample of period `k` with the sensor faults active then.
    pub fn measure(
        &mut self,
        k: u64,
        sensor: &mut CurrentSensor,
        i_abc_a: [f64; 3],
    ) -> CurrentSample {
        let mut f = ChannelFaults::default();
        let mut noise_std: f64 = 0.0;
        for a in &mut self.faults {
            match a.spec {
                FaultSpec::OffsetDrift {
                    channel,
                    rate_a_per_s,
                    ..
                } if k >= a.k0 => {
                    let end = if a.k1 == u64::MAX { k } else { k.min(a.k1) };
                    f.offset_a[channel.index()] += rate_a_per_s * (end - a.k0) as f64 * self.ts_s;
                }
                FaultSpec::GainStep {
                    channel,
                    gain_error,
                    ..
                } if a.active(k) => f.gain[channel.index()] *= 1.0 + gain_error,
                FaultSpec::Stuck {
                    channel, value_a, ..
                } if a.active(k) => {
                    let ch = channel.index();
                    let v = *a
                        .held
                        .get_or_insert(value_a.unwrap_or(self.last_reading[ch]));
                    f.value_a[ch] = Some(v);
                }
                FaultSpec::Dropout { channel, .. } if a.active(k) => match channel {
                    Channels::A => f.value_a[0] = Some(f64::NAN),
                    Channels::B => f.value_a[1] = Some(f64::NAN),
                    Channels::Both => f.value_a = [Some(f64::NAN); 2],
                },
                FaultSpec::NoiseBurst { std_a, .. } if a.active(k) => {
                    noise_std = noise_std.hypot(std_a);
                }
                FaultSpec::Glitch {
                    channel, value_a, ..
                } if a.active(k) => {
                    f.value_a[channel.index()] =
                        Some(value_a.unwrap_or(10.0 * self.rated_current_a));
                }
                _ => {}
            }
        }
        if noise_std > 0.0 {
            for o in &mut f.offset_a {
                let n: f64 = StandardNormal.sample(&mut self.rng);
                *o += noise_std * n;
            }
        }
        let m = if f == ChannelFaults::default() {
            sensor.measure(i_abc_a)
        } else {
            sensor.measure_with(i_abc_a, &f)
        };
        for (r, v) in self.last_reading.iter_mut().zip(m.i_abc_a) {
            if v.is_finite() {
                *r = v;
            }
        }
        m
    }

    /// Factor on the bus voltage at period `k` (1 without a sag).
    pub fn bus_factor(&self, k: u64) -> f64 {
        self.faults
            .iter()
            .filter(|a| a.active(k))
            .fold(1.0, |acc, a| match a.spec {
                FaultSpec::BusSag { fraction, .. } => acc * (1.0 - fraction),
                _ => acc,
            })
    }

    /// Extra load torque at period `k`, N m.
    pub fn extra_load_nm(&self, k: u64) -> f64 {
        self.faults
            .iter()
            .filter(|a| a.active(k))
            .map(|a| match a.spec {
                FaultSpec::Overload { torque_nm, .. } => torque_nm,
                _ => 0.0,
            })
            .sum()
    }

    /// Before the plant's step of period `k`: parameter drift, locked rotor, open phase.
    pub fn before_step(&mut self, k: u64, plant: &mut Plant) {
        let (mut rs, mut psi) = (1.0, 1.0);
        let mut locked = false;
        for a in &self.faults {
            match a.spec {
                FaultSpec::ParamDrift {
                    temperature_rise_k,
                    rs_per_k,
                    psi_f_per_k,
                    ..
                } => {
                    let dt = temperature_rise_k * a.ramp(k);
                    rs *= 1.0 + rs_per_k * dt;
                    psi *= 1.0 + psi_f_per_k * dt;
                }
                FaultSpec::LockedRotor { .. } if a.active(k) => locked = true,
                _ => {}
            }
        }
        let want = (self.rs_ohm * rs, self.psi_f_wb * psi);
        if want != self.drift_set {
            plant.set_rs_psi(want.0, want.1);
            self.drift_set = want;
        }
        if locked != plant.is_locked() {
            plant.set_locked(locked);
        }
        self.open_phases(k, plant);
    }

    /// After the plant's step of period `k`: the open phase's current stays zero.
    pub fn after_step(&mut self, k: u64, plant: &mut Plant) {
        self.open_phases(k, plant);
    }

    fn open_phases(&self, k: u64, plant: &mut Plant) {
        for a in &self.faults {
            if let FaultSpec::PhaseOpen { phase, .. } = a.spec
                && a.active(k)
            {
                plant.open_phase(phase as usize);
            }
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::scenario::Scenario;

    fn with_faults(toml: &str) -> Result<Scenario, crate::SimError> {
        let text = format!(
            "{}\n{toml}",
            Scenario::preset_text("default").unwrap_or_default()
        );
        Scenario::from_toml_str(&text, "f.toml")
    }

    fn field_of(toml: &str) -> (String, String) {
        match with_faults(toml) {
            Err(crate::SimError::Scenario { field, problem, .. }) => (field, problem),
            other => panic!("expected an error, got {other:?}"),
        }
    }

    #[test]
    fn every_kind_parses_and_round_trips() {
        let sc = with_faults(
            r#"
[[faults]]
kind = "offset_drift"
t_s = 1.0
rate_a_per_s = 0.5
[[faults]]
kind = "gain_step"
t_s = 1.0
duration_s = 0.1
channel = "b"
gain_error = 0.2
[[faults]]
kind = "stuck"
t_s = 1.0
[[faults]]
kind = "dropout"
t_s = 1.0
channel = "both"
[[faults]]
kind = "noise_burst"
t_s = 1.0
std_a = 0.5
[[faults]]
kind = "glitch"
t_s = 1.0
[[faults]]
kind = "bus_sag"
t_s = 1.0
fraction = 0.3
[[faults]]
kind = "phase_open"
t_s = 1.0
phase = "c"
[[faults]]
kind = "param_drift"
t_s = 1.0
temperature_rise_k = 80.0
[[faults]]
kind = "locked_rotor"
t_s = 1.0
[[faults]]
kind = "overload"
t_s = 1.0
torque_nm = 4.0
"#,
        )
        .unwrap_or_else(|e| panic!("{e}"));
        assert_eq!(sc.faults.len(), 11);
        assert!(matches!(
            sc.faults[8],
            FaultSpec::ParamDrift { rs_per_k, .. } if rs_per_k == 0.00393
        ));
        let text = sc.to_toml().unwrap_or_else(|e| panic!("{e}"));
        let back = Scenario::from_toml_str(&text, "rt").unwrap_or_else(|e| panic!("{e}"));
        assert_eq!(back, sc);
    }

    #[test]
    fn bad_faults_name_their_field() {
        // An unknown key: the fault's index, the key's name and its place in the file.
        let (f, p) = field_of("[[faults]]\nkind = \"glitch\"\nt_s = 1.0\nduration_s = 0.1\n");
        assert_eq!(f, "faults[0]");
        assert!(
            p.contains("unknown field `duration_s`") && p.contains("line"),
            "{p}"
        );
        let (f, p) = field_of("[[faults]]\nkind = \"meltdown\"\nt_s = 1.0\n");
        assert_eq!(f, "faults[0].kind");
        assert!(p.contains("unknown variant"), "{p}");
        let (f, p) = field_of("[[faults]]\nkind = \"bus_sag\"\nt_s = 1.0\n");
        assert_eq!(f, "faults[0]");
        assert!(p.contains("missing field `fraction`"), "{p}");
        let (f, _) = field_of("[[faults]]\nkind = \"bus_sag\"\nt_s = 1.0\nfraction = 1.5\n");
        assert_eq!(f, "faults[0].fraction");
        let (f, p) = field_of("[[faults]]\nkind = \"locked_rotor\"\nt_s = 5.0\n");
        assert_eq!(f, "faults[0].t_s");
        assert!(p.contains("end of the run"), "{p}");
        let (f, _) = field_of(
            "[[faults]]\nkind = \"overload\"\nt_s = 1.0\nduration_s = -1.0\ntorque_nm = 1.0\n",
        );
        assert_eq!(f, "faults[0].duration_s");
        let (f, p) = field_of("[[faults]]\nkind = \"stuck\"\nt_s = 1.0\nchannel = \"c\"\n");
        assert_eq!(f, "faults[0]");
        assert!(p.contains("unknown variant `c`"), "{p}");
        let (f, _) = field_of(
            "[[faults]]\nkind = \"param_drift\"\nt_s = 1.0\ntemperature_rise_k = 1000.0\n",
        );
        assert_eq!(f, "faults[0].temperature_rise_k");
    }

    #[test]
    fn sensor_faults_act_in_their_window() {
        let sc = with_faults(
            r#"
[[faults]]
kind = "glitch"
t_s = 0.001
value_a = 14.0
[[faults]]
kind = "dropout"
t_s = 0.002
duration_s = 0.0002
channel = "b"
[[faults]]
kind = "stuck"
t_s = 0.003
duration_s = 0.001
channel = "a"
"#,
        )
        .unwrap_or_else(|e| panic!("{e}"));
        let mut inj = FaultInjector::new(&sc.faults, &sc.fault_context())
            .unwrap_or_else(|| panic!("no injector"));
        let mut sensor = CurrentSensor::new(crate::plant::sensors::SensorConfig::default(), 1);
        let i = |k: u64| {
            let a = (k as f64 * 0.01).sin();
            [a, -0.5 * a, -0.5 * a]
        };
        for k in 0..50 {
            let m = inj.measure(k, &mut sensor, i(k));
            match k {
                10 => assert_eq!(m.i_abc_a[0], 14.0),
                20 | 21 => assert!(m.i_abc_a[1].is_nan() && m.i_abc_a[0].is_finite()),
                30..40 => assert_eq!(m.i_abc_a[0], i(29)[0]),
                _ => assert_eq!(m.i_abc_a[0], i(k)[0], "{k}"),
            }
        }
    }

    #[test]
    fn plant_bus_and_load_faults_act_where_they_should() {
        let sc = with_faults(
            r#"
[[faults]]
kind = "phase_open"
t_s = 0.5
duration_s = 0.05
phase = "b"
[[faults]]
kind = "locked_rotor"
t_s = 0.6
duration_s = 0.05
[[faults]]
kind = "bus_sag"
t_s = 0.7
duration_s = 0.01
fraction = 0.2
[[faults]]
kind = "overload"
t_s = 0.72
duration_s = 0.01
torque_nm = 0.5
"#,
        )
        .unwrap_or_else(|e| panic!("{e}"))
        .with_duration(0.75);
        let out = crate::sim::run_with(
            &sc,
            crate::sim::RunOptions {
                record_trace: true,
                ..Default::default()
            },
        )
        .unwrap_or_else(|e| panic!("{e}"));
        let s = &out.trace.samples;
        // Open phase b: its true current is zero (to rounding) after the first step.
        for x in &s[5001..5500] {
            let ib = crate::plant::frames::inverse_clarke(x.truth.i_ab_a)[1];
            assert!(ib.abs() < 1e-9, "k {}: i_b {ib}", x.k);
        }
        assert!(crate::plant::frames::inverse_clarke(s[5600].truth.i_ab_a)[1].abs() > 1e-3);
        // Locked: no speed while locked (unless foc has tripped, the shaft then coasts).
        for x in &s[6001..6500] {
            assert_eq!(x.truth.speed_rpm, 0.0, "k {}", x.k);
        }
        // Bus sag: the controller measures 240 V; the load carries the extra torque.
        assert_eq!(s[7000].measured.u_dc_v, 240.0);
        assert_eq!(s[7100].measured.u_dc_v, 300.0);
        let base = s[7150].truth.load_torque_nm;
        assert!((s[7200].truth.load_torque_nm - base - 0.5).abs() < 0.05);
    }
}
