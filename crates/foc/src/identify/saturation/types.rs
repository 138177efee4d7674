//! The probe's settings, errors, samples and output.

use crate::config::ComputationDelay;
use crate::transforms::AlphaBeta;

/// Largest number of d-current levels.
pub const SAT_MAX_D: usize = 7;
/// Largest number of q-current levels.
pub const SAT_MAX_Q: usize = 9;

/// Settings of the standstill flux-map measurement (module docs).
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct SaturationConfig {
    /// PWM period, s.
    pub ts_s: f32,
    /// Computation delay of the drive.
    pub delay: ComputationDelay,
    /// Stator resistance (the resistance step), ohm.
    pub rs_ohm: f32,
    /// Inverter voltage error along the phase-a axis (the resistance step), V; 0 if unknown.
    pub voltage_error_v: f32,
    /// The rotor's d axis, electrical rad (the alignment's angle, phase-a axis 0).
    pub theta_rad: f32,
    /// `psi_d(0, 0)`, Wb (the spin's `psi_f`, or told).
    pub psi_f_wb: f32,
    /// Small-signal d inductance (the inductance step), H: pulse voltage, d loop.
    pub ld_h: f32,
    /// Small-signal q inductance, H: pulse voltage, q loop.
    pub lq_h: f32,
    /// Largest current of each axis, A (about 1.5-2x rated).
    pub i_max_a: f32,
    /// Number of d levels, odd, 3..=[`SAT_MAX_D`].
    pub n_d: usize,
    /// Number of q levels, odd, 3..=[`SAT_MAX_Q`].
    pub n_q: usize,
    /// Ticks of a ramp from zero to `I_max` at the small-signal inductance.
    pub ramp_ticks: u32,
    /// Rest at zero current between pulses, and the d bias's settling, s.
    pub settle_s: f32,
    /// Bandwidth of the PI loops holding the other axis, rad/s.
    pub current_bw_rad_s: f32,
    /// Modulation limit (fraction of `u_dc / sqrt(3)`).
    pub max_modulation: f32,
    /// Current-sensor offsets to remove (the offsets step), A (a, b; or alpha, beta).
    pub current_offsets_a: [f32; 2],
    /// Over-current trip, A.
    pub over_current_a: f32,
    /// Inertia of the rotor and what it drives (the inertia step, or told), kg m^2; 0:
    /// unknown, the rotor's motion is not followed.
    pub inertia_kg_m2: f32,
    /// Pole pairs (the rotor's motion).
    pub pole_pairs: u32,
}

impl SaturationConfig {
    /// Defaults for a motor with the given PWM period, `Rs`, alignment angle, `psi_f`,
    /// small-signal inductances and largest current: a 7 x 9 grid, 12-tick ramps, 10 ms rests,
    /// 300 Hz loops, modulation 0.95, over-current `2 I_max`, one period of delay.
    pub fn new(
        ts_s: f32,
        rs_ohm: f32,
        theta_rad: f32,
        psi_f_wb: f32,
        l_dq_h: (f32, f32),
        i_max_a: f32,
    ) -> Self {
        Self {
            ts_s,
            delay: ComputationDelay::OnePeriod,
            rs_ohm,
            voltage_error_v: 0.0,
            theta_rad,
            psi_f_wb,
            ld_h: l_dq_h.0,
            lq_h: l_dq_h.1,
            i_max_a,
            n_d: 7,
            n_q: 9,
            ramp_ticks: 12,
            settle_s: 0.01,
            current_bw_rad_s: core::f32::consts::TAU * 300.0,
            max_modulation: 0.95,
            current_offsets_a: [0.0; 2],
            over_current_a: 2.0 * i_max_a,
            inertia_kg_m2: 0.0,
            pole_pairs: 1,
        }
    }

    /// Checks the settings: the name of the first one out of range.
    pub fn validate(&self) -> Result<(), &'static str> {
        let pos = |x: f32| x.is_finite() && x > 0.0;
        if !(pos(self.ts_s) && self.ts_s < 0.01) {
            return Err("ts_s");
        }
        if !(self.rs_ohm.is_finite() && self.rs_ohm >= 0.0) {
            return Err("rs_ohm");
        }
        if !self.voltage_error_v.is_finite() {
            return Err("voltage_error_v");
        }
        if !self.theta_rad.is_finite() {
            return Err("theta_rad");
        }
        if !self.psi_f_wb.is_finite() {
            return Err("psi_f_wb");
        }
        if !(pos(self.ld_h) && self.ld_h < 100.0) {
            return Err("ld_h");
        }
        if !(pos(self.lq_h) && self.lq_h < 100.0) {
            return Err("lq_h");
        }
        if !pos(self.i_max_a) {
            return Err("i_max_a");
        }
        if !(3..=SAT_MAX_D).contains(&self.n_d) || self.n_d.is_multiple_of(2) {
            return Err("n_d");
        }
        if !(3..=SAT_MAX_Q).contains(&self.n_q) || self.n_q.is_multiple_of(2) {
            return Err("n_q");
        }
        if !(4..=100_000).contains(&self.ramp_ticks) {
            return Err("ramp_ticks");
        }
        if !(pos(self.settle_s) && self.settle_s < 10.0) {
            return Err("settle_s");
        }
        if !(pos(self.current_bw_rad_s) && self.current_bw_rad_s * self.ts_s <= 0.5) {
            return Err("current_bw_rad_s");
        }
        if !(self.max_modulation > 0.0 && self.max_modulation <= 1.0) {
            return Err("max_modulation");
        }
        if !self.current_offsets_a.iter().all(|x| x.is_finite()) {
            return Err("current_offsets_a");
        }
        if !(self.over_current_a.is_finite() && self.over_current_a >= 1.45 * self.i_max_a) {
            return Err("over_current_a (at least 1.45 i_max_a)");
        }
        if !(self.inertia_kg_m2.is_finite() && self.inertia_kg_m2 >= 0.0) {
            return Err("inertia_kg_m2");
        }
        if !(1..=1000).contains(&self.pole_pairs) {
            return Err("pole_pairs");
        }
        Ok(())
    }

    /// The d level `k`, A.
    pub fn i_d_level(&self, k: usize) -> f32 {
        level(self.i_max_a, self.n_d, k)
    }

    /// The q level `j`, A.
    pub fn i_q_level(&self, j: usize) -> f32 {
        level(self.i_max_a, self.n_q, j)
    }
}

fn level(i_max: f32, n: usize, k: usize) -> f32 {
    i_max * (2.0 * k as f32 / (n - 1) as f32 - 1.0)
}

/// Why the measurement stopped.
#[derive(Clone, Copy, Debug, PartialEq)]
pub enum SaturationError {
    /// A setting out of range (its name).
    Config(&'static str),
    /// A current or the bus voltage was not finite.
    NonFiniteInput,
    /// The current exceeded [`SaturationConfig::over_current_a`].
    OverCurrent {
        /// Current magnitude, A.
        current_a: f32,
    },
    /// A pulse did not reach its current level in time (bus too low, open phase, wrong
    /// inductance).
    LevelNotReached {
        /// `'d'` or `'q'`.
        axis: char,
        /// The level, A.
        level_a: f32,
        /// The current at the time-out, A.
        current_a: f32,
    },
}

impl core::fmt::Display for SaturationError {
    fn fmt(&self, f: &mut core::fmt::Formatter<'_>) -> core::fmt::Result {
        match self {
            Self::Config(name) => write!(f, "flux-map probe setting out of range: {name}"),
            Self::NonFiniteInput => write!(f, "flux-map probe: non-finite current or bus voltage"),
            Self::OverCurrent { current_a } => {
                write!(f, "flux-map probe: over-current {current_a:.2} A")
            }
            Self::LevelNotReached {
                axis,
                level_a,
                current_a,
            } => write!(
                f,
                "flux-map probe: the {axis} current reached {current_a:.2} A, not its level \
                 {level_a:.2} A, in time"
            ),
        }
    }
}

/// The measured grid: `psi[d][q]` at `(i_d[d], i_q[q])`, Wb, the first `n_d x n_q` entries.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct FluxSamples {
    /// Number of d levels.
    pub n_d: usize,
    /// Number of q levels.
    pub n_q: usize,
    /// d levels, ascending, A.
    pub i_d: [f32; SAT_MAX_D],
    /// q levels, ascending, A.
    pub i_q: [f32; SAT_MAX_Q],
    /// d flux, Wb.
    pub psi_d: [[f32; SAT_MAX_Q]; SAT_MAX_D],
    /// q flux, Wb.
    pub psi_q: [[f32; SAT_MAX_Q]; SAT_MAX_D],
    /// Largest `|psi_q|` where a q pulse's falling branch crossed zero current (drift and
    /// hysteresis; ideally 0), Wb.
    pub q_closure_wb: f32,
    /// Largest `|angle|` of the rotor the probe followed (from the torque and `J`, zero
    /// when `J` is not given), electrical rad from the alignment.
    pub rotor_angle_max_rad: f32,
    /// Ticks the measurement took.
    pub ticks: u32,
}

impl FluxSamples {
    /// The samples as an [`ekf_core::FluxMap`] (`FluxMap::new` checks them: ascending,
    /// monotonic fluxes). `N >= max(n_d, n_q)`.
    pub fn flux_map<const N: usize>(
        &self,
    ) -> Result<ekf_core::FluxMap<f32, N>, ekf_core::FluxMapError> {
        let mut pd = [0.0f32; SAT_MAX_D * SAT_MAX_Q];
        let mut pq = [0.0f32; SAT_MAX_D * SAT_MAX_Q];
        for d in 0..self.n_d {
            for q in 0..self.n_q {
                pd[d * self.n_q + q] = self.psi_d[d][q];
                pq[d * self.n_q + q] = self.psi_q[d][q];
            }
        }
        let n = self.n_d * self.n_q;
        ekf_core::FluxMap::new(
            &self.i_d[..self.n_d],
            &self.i_q[..self.n_q],
            &pd[..n],
            &pq[..n],
        )
    }
}

/// The part of the measurement in progress.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum SaturationPhase {
    /// Both currents held at zero.
    Rest,
    /// A d pulse (`q = 0`).
    DPulse,
    /// The d current ramps to its bias level and settles.
    BiasUp,
    /// The bipolar q pulse at a d bias.
    QPulse,
    /// The d current ramps back to zero.
    BiasDown,
    /// Finished or failed: PWM off.
    Done,
}

/// One tick's output.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct SaturationOutput {
    /// Duties of phases a, b, c.
    pub duties: [f32; 3],
    /// Whether the bridge switches.
    pub pwm_enabled: bool,
    /// The part this tick belonged to.
    pub phase: SaturationPhase,
    /// Measured currents, offsets removed, A.
    pub i_ab: AlphaBeta,
    /// Voltage the duties realize, V.
    pub u_ab: AlphaBeta,
}
