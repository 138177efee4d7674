//! Configuration of the controller ([`FocConfig`]), its defaults and its validation.
//!
//! All quantities are SI and `f32`; speeds and accelerations are **electrical** unless the
//! name says `_mech`. [`FocConfig::new`] derives every default from the motor, the PWM period
//! and the nominal DC-bus voltage; change fields afterwards as needed and let
//! [`Foc::new`](crate::Foc::new) (which calls [`FocConfig::validate`]) check them.
//!
//! # Defaults and where they come from
//!
//! With `I_c = psi_f / Ls` (characteristic current), `k_t = 1.5 p psi_f` (torque constant,
//! N m/A), `Ts` the PWM period and `U` the nominal bus voltage:
//!
//! | field | default | why |
//! |---|---|---|
//! | `current_bw_rad_s` | `0.1 pi / Ts` (a twentieth of the PWM frequency) | phase margin about 63 deg with the 1.5 `Ts` delay (computation + PWM hold) |
//! | current PI | d: `Kp = Ld bw`, q: `Kp = Lq bw`; `Ki = Rs bw` | pole-zero cancellation: each decoupled axis becomes first order with bandwidth `bw` (per axis on a salient motor) |
//! | `speed_bw_rad_s` | `current_bw / 30` | well inside the current loop and the observer's speed bandwidth |
//! | `inertia_kg_m2` | `k_t / 1000` (an assumption: 1000 rad/s^2 mech. per ampere) | a guess within a factor of 6 of the three reference motors; set the real value |
//! | speed PI | `Kp = bw J / k_t` (A per rad/s mech.), `Ki = Kp bw / 4` | crossover `bw` on the rigid body `J s`, PI zero two octaves below |
//! | `speed_divider` | `round(0.5 ms / Ts)`, at least 1 | speed loop near 2 kHz |
//! | `current_limit_a` | `0.25 I_c` | servo 5.1 A, industrial 3.8 A, drone 10 A |
//! | `over_current_a` | `2 current_limit_a` | above transient overshoot |
//! | `u_dc_min_v`, `u_dc_max_v` | `0.6 U`, `1.25 U` | |
//! | `max_speed_rad_s` | `0.95 U / (sqrt(3) psi_f)` | back-EMF below the linear voltage limit (no field weakening; [`FocConfig::with_field_weakening`] raises it) |
//! | `flux_map` | `None` | the constant-parameter laws; a saturating motor's map as tables (`MapTables`, module `mapdrive`, feature `flux-map`) schedules MTPA, field weakening, the current-loop gains and the decoupling on it |
//! | `mtpa` | `true` | salient motors run on the MTPA curve (module [`mtpa`](crate::mtpa)); no effect on a surface motor |
//! | `field_weakening.enabled` | `false` | off unless asked for: above base speed a trip leaves the back-EMF, which then exceeds the bus, to the bridge's diodes (an uncontrolled generator): a decision for the drive's designer |
//! | `field_weakening.voltage_margin` | 0.95 | the loop holds `|u| = 0.95 u_max`: headroom for the current loops (module [`fieldweak`](crate::fieldweak)) |
//! | `field_weakening.bandwidth_rad_s` | `current_bw / 10` | well inside the current loop, three times the speed loop's crossover |
//! | `field_weakening.max_negative_id_a` | `None`: `min(current_limit_a, psi_f / Ld)` | beyond the characteristic current a negative d current weakens no further |
//! | `speed_slew_rad_s2` | `0.5 p k_t current_limit / J` | half the acceleration the current limit gives (recomputed by [`FocConfig::with_inertia`]) |
//! | `max_modulation` | `1.0` | the current loop uses the whole inscribed circle `u_dc / sqrt(3)` |
//! | `dead_time_s` | `0` (compensation off) | a property of the bridge: set it to the gate driver's dead time |
//! | `dead_time_band_a` | `None`: `0.02 current_limit_a` at [`Foc::new`](crate::Foc::new) | the smooth sign's linear band (module [`deadtime`](crate::deadtime)): in pmsm-sim 1 and 2 % do alike, 5 % doubles the residual observer error; on hardware about half the current ripple |
//! | `startup.if_current_a`, `align_current_a` | `0.5 current_limit_a` | |
//! | `startup.handover_speed_rad_s` | `max(2 Rs I_f / psi_f, 0.02 max_speed)` ([`StartupConfig::default_handover_speed_rad_s`]) | the classic start (no damping, no kick): back-EMF twice the resistive drop, observable, and an `Rs` error biases the angle little; lower, the undamped I/f rotor swings faster than the ramp (the servo from its dead point at 3 % of `max_speed`: no hand-over in 1.5 s). With the damped start on, 3 % of the rated speed ([`StartupConfig::handover_speed_for`], pmsm-sim's default): the start-up grid meets its goals at 3 and 2 %, not at 1.5 %; the interior motor with field weakening hands over only from 2.5 % |
//! | `startup.accel_rad_s2` | `handover_speed / 0.5 s` ([`StartupConfig::default_accel_rad_s2`]) | hand-over speed in half a second |
//! | `startup.align_time_s` | 0.2 s | |
//! | `startup.blend_time_s` | 20 ms | |
//! | `startup.exit_speed_ratio` | exit at 1.5 % of `max_speed` (the rated speed's stand-in), at most 0.7 of the hand-over speed ([`StartupConfig::exit_speed_ratio_for`]; servo at 300 V: 0.17) | closed loop is left below it (a stop, a slow command): 1.5 times the lowest speed the low-speed table shows the observer carrying under rated load on every reference motor (1 %, industrial_2k2), so that 3 % of rated under rated load runs closed loop (before, at 0.7 of the hand-over, the servo ran I/f there with 1.75 times the rated-torque current); with the damped start's hand-over at 3 % of rated, 0.5. With an uncompensated dead time the observer is biased at low speed: pmsm-sim then keeps 0.7 |
//! | `startup.reversal` | `Reversal::ClosedLoop` | a reversal stays on the observer through zero (fast pass under load: the EKF's model carries the angle); `OpenLoop`: the classic exit to I/f |
//! | `startup.damping_ratio` | 0 (off; 1 recommended: critically damped) | the damped start (module [`startup`](crate::startup)) relies on the observer near 1 % of rated speed, which an uncompensated dead time biases: opt-in until measured on hardware (pmsm-sim turns it on) |
//! | `startup.kick_speed_ratio` | 0 (off; 0.2 recommended; [`StartupConfig::kick_speed_ratio_for`] puts the kick at 0.6 % of a known rated speed) | as `damping_ratio` |
//! | `observer` | [`ObserverConfig::new`] for the motor and `Ts`, without the speed noise adaptation | its status includes the innovation consistency check (the health monitor's `Uncertain` loss reason); the salient kick detection reads the covariance's part (`Estimate::angle_tracked`). The adaptation (raising the speed's process noise while the innovations exceed the level learnt) cannot tell a burst of current-sensor noise from an acceleration: in closed loop it turns the burst into speed noise that the speed loop amplifies (pmsm-sim's fault row "noise burst (0.3 A, 50 ms)" trips on over-current with it, falls back without it); the drive knows its own torque command instead |
//! | `samples.max_step_a` | `None`: `(u_dc_max_v + Rs over_current_a) Ts / Ls + 0.1 over_current_a` | the most the current vector can change in one period (applied voltage up to `2/3 u_dc`, back-EMF up to `u_dc / sqrt(3)` at the maximum speed: `1.24 u_dc < u_dc_max_v`), plus a margin for noise and an `Ls` a little lower than configured |
//! | `samples.missing_trip_ticks` | 5 | a missing or implausible current sample is ridden through (observer predicts only, PI state held, the last voltage reused); five in a row trip |
//! | `samples.stuck_angle_rad` | `pi / 4` | a phase reading repeated bit for bit while the current vector turns an eighth of a period: [`Fault::CurrentSensor`](crate::Fault::CurrentSensor) |
//! | `samples.over_current_trip_ticks` | 2 | the software over-current trip is debounced: one sample never trips it, two in a row do. The hardware comparator of the bridge is the real over-current protection (microseconds); this one is the controller's back-up |
//!
//! Health thresholds: [`HealthConfig::default`].

use core::f32::consts::PI;

use ekf_core::{MotorParams, ObserverConfig};

#[cfg(feature = "d-excitation")]
mod excitation;
mod validate;

#[cfg(feature = "d-excitation")]
pub use excitation::DExcitation;
pub use validate::{ConfigError, Field};

use crate::pi::PiGains;
use crate::transforms::FRAC_1_SQRT_3;

/// Default linear band of the dead-time compensation as a fraction of the current limit.
const DEAD_TIME_BAND_FRACTION: f32 = 0.02;

/// Where the rotor angle comes from.
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq)]
pub enum Mode {
    /// From the `ekf-core` observer, with the start-up sequence (align, I/f, hand-over).
    #[default]
    Sensorless,
    /// From the caller ([`TickInput::sensor`](crate::TickInput::sensor)); the observer runs
    /// alongside for comparison only. Starts directly in closed loop.
    Sensored,
}

/// When the duties computed at tick `k` reach the motor.
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq)]
pub enum ComputationDelay {
    /// Real hardware: loaded at the next period boundary, applied over `[t_k+1, t_k+2)`.
    /// The observer is fed the voltage computed two ticks ago; angle advance 1.5 periods.
    #[default]
    OnePeriod,
    /// Applied at once over `[t_k, t_k+1)` (a simulator without delay). The observer is fed
    /// the voltage computed one tick ago; angle advance 0.5 periods.
    None,
}

impl ComputationDelay {
    /// The inverse-Park angle advance in PWM periods that puts the applied vector where the
    /// controller meant it on average: the middle of the application interval, 1.5 or 0.5.
    pub fn default_angle_advance_periods(self) -> f32 {
        match self {
            ComputationDelay::OnePeriod => 1.5,
            ComputationDelay::None => 0.5,
        }
    }
}

/// How a reversal (a speed command of the other sign) passes through zero speed, sensorless
/// (module [`startup`](crate::startup), "Closed loop, reversal, stop").
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq)]
pub enum Reversal {
    /// Stay in closed loop on the observer through zero: the EKF's model carries the angle
    /// over the short interval in which the back-EMF vanishes. The speed reference keeps its
    /// closed-loop slew rate; the drive leaves closed loop below the exit speed only for a
    /// stop or a reference that stands still there (`startup::BAND_DWELL_S`), or when the
    /// health monitor reports a loss (then it falls back to I/f as usual).
    #[default]
    ClosedLoop,
    /// Leave closed loop below the exit speed, ramp the I/f vector through zero and hand over
    /// again in the new direction (the classic sensorless reversal).
    OpenLoop,
}

/// What to do when the observer is lost in closed loop.
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq)]
pub enum ObserverLossPolicy {
    /// Fall back to the open-loop I/f ramp at the commanded speed, re-seed the observer and
    /// hand over again when it locks (at most `HealthConfig::max_reacquire` times in a row).
    #[default]
    FallBackAndReacquire,
    /// Trip [`Fault::ObserverLost`](crate::Fault::ObserverLost).
    Trip,
}

/// Start-up sequence (module [`startup`](crate::startup) describes it).
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct StartupConfig {
    /// Current of the alignment (d axis of the alignment angle), A.
    pub align_current_a: f32,
    /// Duration of the alignment, s; 0 skips it (the rotor angle is then unknown at the
    /// start of the ramp). The current rises linearly over the first half.
    pub align_time_s: f32,
    /// Electrical angle the rotor is aligned to, rad.
    pub align_angle_rad: f32,
    /// Magnitude of the open-loop (I/f) current vector, A.
    pub if_current_a: f32,
    /// Acceleration of the I/f ramp, rad/s^2 electrical.
    pub accel_rad_s2: f32,
    /// I/f target speed and speed of the hand-over to the observer, rad/s electrical.
    pub handover_speed_rad_s: f32,
    /// Time over which the d current of the I/f vector is faded out after the hand-over, s.
    pub blend_time_s: f32,
    /// Closed loop returns to I/f when the speed reference falls below
    /// `exit_speed_ratio * handover_speed_rad_s` (hysteresis; in `[0.01, 0.99]`); with
    /// [`Reversal::ClosedLoop`] only for a stop or a reference that stays there.
    pub exit_speed_ratio: f32,
    /// How a reversal passes through zero speed ([`Reversal::ClosedLoop`] by default).
    pub reversal: Reversal,
    /// Time allowed at the hand-over speed for the observer to lock, s; then the observer
    /// is re-seeded (a re-acquisition attempt), or a fault trips.
    pub acquire_timeout_s: f32,
    /// Damping ratio of the I/f ramp of the start (module [`startup`](crate::startup), "Open
    /// loop"): the current vector is turned by `-2 zeta / w_n (w_hat - w_ramp)`; 0 (the
    /// default) turns the damping off, 1 is critically damped. In `[0, 5]`.
    pub damping_ratio: f32,
    /// Speed at which the alignment takes the rotor as moving, as a fraction of
    /// `handover_speed_rad_s` (module [`startup`](crate::startup), "Alignment"): the current
    /// is then cut and the ramp launched from the observer's angle and speed; 0 turns this
    /// off (the default: the alignment holds its current for `align_time_s`); 0.2 is the
    /// recommended value. In `[0, 1]`.
    pub kick_speed_ratio: f32,
}

impl StartupConfig {
    /// The default hand-over speed, rad/s el.: `max(2 Rs I_f / psi_f, 0.02 max_speed)`, the
    /// speed whose back-EMF is twice the resistive drop of the I/f current `if_current_a`
    /// (observable, and an `Rs` error biases the angle little), at least 2 % of
    /// `max_speed_rad_s` (module docs, "Defaults and where they come from"). The rule of
    /// the classic start (no damping, no kick); with the damped start
    /// [`handover_speed_for`](Self::handover_speed_for) hands over lower.
    pub fn default_handover_speed_rad_s(
        motor: &MotorParams<f32>,
        if_current_a: f32,
        max_speed_rad_s: f32,
    ) -> f32 {
        (2.0 * motor.rs_ohm * if_current_a / motor.psi_f_wb).max(0.02 * max_speed_rad_s)
    }

    /// Hand-over speed of the damped start as a fraction of the rated speed (3 %): the
    /// damped start meets its goals on every cell of the start-up grid there and at 2 %, not
    /// at 1.5 %, and the interior motor with field weakening hands over only from 2.5 %
    /// (docs/startup.md, "Hand-over speed"); twice the exit speed
    /// ([`EXIT_SPEED_OF_RATED`](Self::EXIT_SPEED_OF_RATED), 1.5 %).
    pub const HANDOVER_SPEED_OF_RATED: f64 = 0.03;

    /// Exit speed of closed loop as a fraction of the rated speed (1.5 %), at most
    /// [`EXIT_SPEED_RATIO_MAX`](Self::EXIT_SPEED_RATIO_MAX) of the hand-over speed: 1.5
    /// times the lowest speed that the low-speed table (docs/accuracy.md, "Low speed") shows
    /// the observer carrying under rated load on every reference motor (1 %).
    pub const EXIT_SPEED_OF_RATED: f64 = 0.015;

    /// The largest `exit_speed_ratio` that [`exit_speed_ratio_for`](Self::exit_speed_ratio_for)
    /// gives (0.7): a hysteresis of at least 30 % of the hand-over speed.
    pub const EXIT_SPEED_RATIO_MAX: f32 = 0.7;

    /// `FocConfig::new`'s `exit_speed_ratio`: [`exit_speed_ratio_for`](Self::exit_speed_ratio_for)
    /// with the base speed `max_speed_rad_s` for the rated speed, in `f32` (no `f64` on the
    /// MCU).
    pub fn default_exit_speed_ratio(max_speed_rad_s: f32, handover_speed_rad_s: f32) -> f32 {
        const EXIT: f32 = StartupConfig::EXIT_SPEED_OF_RATED as f32;
        let r = EXIT * max_speed_rad_s / handover_speed_rad_s;
        r.clamp(0.01, Self::EXIT_SPEED_RATIO_MAX)
    }

    /// The damped start's hand-over speed for a known rated speed `rated_speed_e_rad_s`
    /// (rad/s el.): [`HANDOVER_SPEED_OF_RATED`](Self::HANDOVER_SPEED_OF_RATED) times it. A
    /// host-side helper, in `f64` like [`kick_speed_ratio_for`](Self::kick_speed_ratio_for).
    pub fn handover_speed_for(rated_speed_e_rad_s: f64) -> f32 {
        (Self::HANDOVER_SPEED_OF_RATED * rated_speed_e_rad_s) as f32
    }

    /// The `exit_speed_ratio` that puts the exit speed at
    /// [`EXIT_SPEED_OF_RATED`](Self::EXIT_SPEED_OF_RATED) of the rated speed
    /// `rated_speed_e_rad_s` (rad/s el.) for the hand-over speed `handover_speed_rad_s`:
    /// `0.015 w_rated / w_handover`, within `[0.01, 0.7]` (0.5 for the damped start's
    /// hand-over at 3 % of rated). `FocConfig::new` passes the base
    /// speed `max_speed_rad_s` for the rated speed it does not know. Computed in `f64`.
    pub fn exit_speed_ratio_for(rated_speed_e_rad_s: f64, handover_speed_rad_s: f32) -> f32 {
        let r = Self::EXIT_SPEED_OF_RATED * rated_speed_e_rad_s / f64::from(handover_speed_rad_s);
        r.clamp(0.01, f64::from(Self::EXIT_SPEED_RATIO_MAX)) as f32
    }

    /// The default I/f acceleration, rad/s^2 el.: the hand-over speed reached in
    /// [`DEFAULT_RAMP_TIME_S`](Self::DEFAULT_RAMP_TIME_S) (0.5 s).
    pub fn default_accel_rad_s2(handover_speed_rad_s: f32) -> f32 {
        handover_speed_rad_s / Self::DEFAULT_RAMP_TIME_S
    }

    /// Time the default I/f ramp takes from standstill to the hand-over speed, s.
    pub const DEFAULT_RAMP_TIME_S: f32 = 0.5;

    /// Kick speed as a fraction of the rated speed when the kick is on (0.6 %, measured
    /// with the hand-over at 3 % of rated speed; docs/startup.md), whatever the hand-over
    /// speed.
    pub const KICK_SPEED_OF_RATED: f64 = 0.006;

    /// The kick speed ratio that puts the kick at [`KICK_SPEED_OF_RATED`](Self::KICK_SPEED_OF_RATED)
    /// of the rated speed `rated_speed_e_rad_s` (rad/s el.) for the hand-over speed
    /// `handover_speed_rad_s`: `min(0.006 w_rated / w_handover, 1)`. (`FocConfig::new`
    /// leaves the kick off: it does not know the rated speed.) A host-side helper: computed
    /// in `f64` (the simulator's rated speed), not meant for the MCU's tick path.
    pub fn kick_speed_ratio_for(rated_speed_e_rad_s: f64, handover_speed_rad_s: f32) -> f32 {
        let kick =
            Self::KICK_SPEED_OF_RATED * rated_speed_e_rad_s / f64::from(handover_speed_rad_s);
        kick.min(1.0) as f32
    }
}

/// Observer health monitoring (module [`health`](crate::health)).
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct HealthConfig {
    /// Time constant of the moving averages (NIS, speed, angle increments), s.
    pub window_s: f32,
    /// Average NIS above this is unhealthy (its expectation is 2 for a consistent filter).
    pub nis_limit: f32,
    /// Relative speed tolerance: the observer speed vs the rate of its angle, and vs the
    /// I/f speed for the hand-over; relative to `max(|w|, handover speed)`.
    pub speed_tolerance: f32,
    /// Angle between the observer's rotor angle and the I/f current vector beyond which the
    /// observer is taken to be locked on `theta + pi`, rad (in `(pi/2, pi)`).
    pub lock_angle_rad: f32,
    /// An unhealthy condition must persist this long to count, s.
    pub lost_time_s: f32,
    /// The observer must be healthy and agree with the I/f ramp this long before the
    /// hand-over, s.
    pub lock_time_s: f32,
    /// Stall detection time, s.
    pub stall_time_s: f32,
    /// The observer's tracked flux linkage outside `[lo, hi]` times the configured one is
    /// unhealthy: heat moves a magnet's flux by at most about 20 % (NdFeB, -0.12 %/K), so a
    /// fit farther off means the model no longer describes the motor (an open phase, a
    /// demagnetized or wrong motor). Checked in closed loop only.
    pub flux_range: [f32; 2],
    /// Re-acquisitions in a row (without `acquire_timeout_s` of closed loop in between)
    /// before [`Fault::ObserverLost`](crate::Fault::ObserverLost).
    pub max_reacquire: u8,
    /// Reaction to a loss in closed loop.
    pub policy: ObserverLossPolicy,
}

impl Default for HealthConfig {
    /// `window_s` 5 ms, `nis_limit` 20 (ten times the expectation), `speed_tolerance` 0.3,
    /// `lock_angle_rad` 135 deg, `lost_time_s` 20 ms, `lock_time_s` 30 ms, `stall_time_s`
    /// 0.5 s, `flux_range` 0.7 to 1.3, `max_reacquire` 3, policy fall back and re-acquire.
    fn default() -> Self {
        Self {
            window_s: 5e-3,
            nis_limit: 20.0,
            speed_tolerance: 0.3,
            lock_angle_rad: 0.75 * PI,
            lost_time_s: 20e-3,
            lock_time_s: 30e-3,
            stall_time_s: 0.5,
            flux_range: [0.7, 1.3],
            max_reacquire: 3,
            policy: ObserverLossPolicy::FallBackAndReacquire,
        }
    }
}

/// Checks of the sampled phase currents (module [`controller`](crate::controller), "Bad
/// current samples").
///
/// A sample is **missing** when a current is NaN or infinite, **implausible** when the current
/// vector moved by more than `(n + 1) max_step_a` from the last accepted sample, `n` being the
/// number of samples missed since (the current of an inductive load cannot jump). Either
/// way the tick rides through: the observer only predicts, the current loops hold their
/// integrators and reuse the last voltage (rotated with the frame), and the over-current
/// check does not see the sample. `missing_trip_ticks` such samples in a row trip: with
/// [`Fault::NonFiniteInput`](crate::Fault::NonFiniteInput) for a non-finite current,
/// [`Fault::OverCurrent`](crate::Fault::OverCurrent) when the rejected current is above
/// `over_current_a`, else `NonFiniteInput` (an absurd value).
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct SampleCheckConfig {
    /// Largest plausible change of the current vector over one period, A (`f32::INFINITY`
    /// turns the plausibility check off). `None`: derived when the controller is built
    /// ([`FocConfig::max_current_step`]).
    pub max_step_a: Option<f32>,
    /// Missing or implausible current samples in a row that trip (1: the first trips).
    pub missing_trip_ticks: u16,
    /// Accepted samples above `over_current_a` in a row that trip (1: the first trips).
    pub over_current_trip_ticks: u16,
    /// Stuck channel: a sampled phase current (`a` or `b` of [`PhaseCurrents::Abc`](crate::PhaseCurrents::Abc))
    /// that repeats its reading bit for bit while the commanded current vector (at least
    /// 5 % of `current_limit_a`) turns by more than this electrical angle (and at least 4
    /// ticks) trips [`Fault::CurrentSensor`](crate::Fault::CurrentSensor), rad. A live
    /// channel cannot repeat: over any eighth of a period a sinusoid moves by at least
    /// `1 - cos(pi / 8)` = 7.6 % of its amplitude (19 mA at the 5 % floor of the servo's
    /// 5.1 A limit, two steps of a 12-bit ADC over +-20 A), more than an ADC step and its
    /// noise (a smaller angle would not guarantee a code step at that floor). Not longer: a
    /// frozen reading misleads the current loops, which drive the real current up within a
    /// few milliseconds; on the servo test rig at 400 rad/s el. a quarter-period rule was
    /// beaten by the over-current trip (the wrong diagnosis, after 11 A) for most noise
    /// seeds, an eighth-period rule trips first (real current 2-12 A by then). 0 turns the
    /// check off.
    pub stuck_angle_rad: f32,
}

impl Default for SampleCheckConfig {
    /// Derived step limit, five missing samples, two over-current samples, stuck after an
    /// eighth of a turn.
    fn default() -> Self {
        Self {
            max_step_a: None,
            missing_trip_ticks: 5,
            over_current_trip_ticks: 2,
            stuck_angle_rad: 0.25 * PI,
        }
    }
}

impl SampleCheckConfig {
    /// No ride-through: every missing, implausible-and-over-current or over-current sample
    /// trips at once, and no step limit (the behaviour before the checks existed).
    pub fn strict() -> Self {
        Self {
            max_step_a: Some(f32::INFINITY),
            missing_trip_ticks: 1,
            over_current_trip_ticks: 1,
            stuck_angle_rad: 0.25 * PI,
        }
    }
}

/// Field weakening (module [`fieldweak`](crate::fieldweak) gives the law and the reasons).
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct FieldWeakeningConfig {
    /// Whether the loop runs (closed loop only). Off by default.
    pub enabled: bool,
    /// The voltage magnitude the loop holds above base speed, as a fraction of the current
    /// loop's limit `max_modulation u_dc / sqrt(3)`; in `[0.5, 1]`.
    pub voltage_margin: f32,
    /// Crossover of the loop, rad/s (the integrator gain is `bw / (Ld |w|)`); positive, at
    /// most the current-loop bandwidth.
    pub bandwidth_rad_s: f32,
    /// Largest negative d current, A (a positive number, at most `current_limit_a`). `None`:
    /// `min(current_limit_a, psi_f / Ld)` ([`FocConfig::max_negative_id`]).
    pub max_negative_id_a: Option<f32>,
}

/// Everything the controller needs (module docs give the defaults).
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct FocConfig {
    /// Motor parameters (also used by the observer, which must have the same).
    pub motor: MotorParams<f32>,
    /// PWM (control) period, s; one [`Foc::tick`](crate::Foc::tick) per period.
    pub ts_s: f32,
    /// Angle source.
    pub mode: Mode,
    /// Computation delay of the inverter.
    pub delay: ComputationDelay,
    /// Inverse-Park angle advance in periods: the voltage computed at tick `k` is rotated
    /// with `theta_k + angle_advance_periods * w_e * Ts` (1.5 with a one-period delay: the
    /// middle of `[t_k+1, t_k+2)`; 0.5 without).
    pub angle_advance_periods: f32,
    /// Current-loop bandwidth, rad/s; gives the gains unless `current_gains` is set.
    pub current_bw_rad_s: f32,
    /// Explicit current-loop gains (V/A, V/(A s)) instead of those from the bandwidth.
    pub current_gains: Option<PiGains>,
    /// Speed-loop crossover, rad/s; gives the gains with `inertia_kg_m2` unless
    /// `speed_gains` is set.
    pub speed_bw_rad_s: f32,
    /// Rotor plus load inertia, kg m^2.
    pub inertia_kg_m2: f32,
    /// Explicit speed-loop gains (A per rad/s mech., A per rad mech.).
    pub speed_gains: Option<PiGains>,
    /// The speed loop runs every `speed_divider` ticks (at least 1).
    pub speed_divider: u16,
    /// Limit of the current reference magnitude, A.
    pub current_limit_a: f32,
    /// Over-current trip level (current vector magnitude), A.
    pub over_current_a: f32,
    /// DC-bus under-voltage trip level, V.
    pub u_dc_min_v: f32,
    /// DC-bus over-voltage trip level, V.
    pub u_dc_max_v: f32,
    /// Limit of the speed reference, rad/s electrical.
    pub max_speed_rad_s: f32,
    /// Slew rate of the closed-loop speed reference, rad/s^2 electrical.
    pub speed_slew_rad_s2: f32,
    /// Radius of the current loop's voltage limit as a fraction of `u_dc / sqrt(3)` (1.0 =
    /// the linear range; up to `2 / sqrt(3)`, where SVPWM clamps the corners).
    pub max_modulation: f32,
    /// Dead time of the bridge to compensate, s: each phase's duty gets
    /// `sgn_s(i_x) dead_time_s / ts_s` (module [`deadtime`](crate::deadtime)) and the
    /// observer is fed the voltage net of it. 0 (the default) turns the compensation off;
    /// otherwise finite, in `[0, ts_s / 2)`.
    pub dead_time_s: f32,
    /// Half-width of the linear zone of the compensation's smooth sign, A (below it the
    /// offset is proportional to the phase current). `None`: 2 % of `current_limit_a`, taken
    /// when the controller is built ([`dead_time_band`](Self::dead_time_band)).
    pub dead_time_band_a: Option<f32>,
    /// Salient motors: d current from the MTPA law (module [`mtpa`](crate::mtpa)); `false`:
    /// `i_d = 0` (the torque conversion still counts the reluctance torque). No effect on a
    /// surface motor.
    pub mtpa: bool,
    /// Field weakening above base speed.
    pub field_weakening: FieldWeakeningConfig,
    /// Start-up sequence.
    pub startup: StartupConfig,
    /// Observer health monitoring.
    pub health: HealthConfig,
    /// Checks of the current samples: glitch ride-through, over-current debounce.
    pub samples: SampleCheckConfig,
    /// The observer (motor and `ts_s` must equal the fields above).
    pub observer: ObserverConfig<f32>,
    /// The motor's flux map as tables (module [`mapdrive`](crate::mapdrive)): `Some` makes
    /// the closed-loop references, the current loops' proportional gains and their
    /// decoupling come from the map (MTPA table; the field-weakening table when
    /// `field_weakening.enabled`). `None` (the default): the constant-parameter laws.
    /// The tables' torque constant must be [`torque_constant_nm_a`](Self::torque_constant_nm_a)
    /// (the speed loop's command unit). (Cargo feature `flux-map`.)
    #[cfg(feature = "flux-map")]
    pub flux_map: Option<crate::mapdrive::MapTables>,
    /// A square-wave d-current excitation in closed loop (module `excitation`), `None` by
    /// default. (Cargo feature `d-excitation`.)
    #[cfg(feature = "d-excitation")]
    pub d_excitation: Option<DExcitation>,
}

/// `x` rounded to the nearest integer, as `u16` (saturating; NaN gives 0).
fn round_u16(x: f32) -> u16 {
    (x + 0.5) as u16
}

impl FocConfig {
    /// Defaults for `motor` at the PWM period `ts_s` and the nominal DC-bus voltage
    /// `u_dc_nominal_v` (module docs list them). Invalid arguments are reported by
    /// [`validate`](Self::validate), not here.
    pub fn new(motor: MotorParams<f32>, ts_s: f32, u_dc_nominal_v: f32) -> Self {
        let ic = motor.characteristic_current_a();
        let current_limit_a = 0.25 * ic;
        let if_current_a = 0.5 * current_limit_a;
        let max_speed_rad_s = 0.95 * u_dc_nominal_v * FRAC_1_SQRT_3 / motor.psi_f_wb;
        let handover =
            StartupConfig::default_handover_speed_rad_s(&motor, if_current_a, max_speed_rad_s);
        let current_bw_rad_s = 0.1 * PI / ts_s;
        let kt = torque_constant(&motor);
        let speed_divider = round_u16(0.5e-3 / ts_s).max(1);
        Self {
            motor,
            ts_s,
            mode: Mode::Sensorless,
            delay: ComputationDelay::OnePeriod,
            angle_advance_periods: ComputationDelay::OnePeriod.default_angle_advance_periods(),
            current_bw_rad_s,
            current_gains: None,
            speed_bw_rad_s: current_bw_rad_s / 30.0,
            inertia_kg_m2: kt / 1000.0,
            speed_gains: None,
            speed_divider,
            current_limit_a,
            over_current_a: 2.0 * current_limit_a,
            u_dc_min_v: 0.6 * u_dc_nominal_v,
            u_dc_max_v: 1.25 * u_dc_nominal_v,
            max_speed_rad_s,
            speed_slew_rad_s2: 0.0,
            max_modulation: 1.0,
            dead_time_s: 0.0,
            dead_time_band_a: None,
            mtpa: true,
            field_weakening: FieldWeakeningConfig {
                enabled: false,
                voltage_margin: 0.95,
                bandwidth_rad_s: 0.1 * current_bw_rad_s,
                max_negative_id_a: None,
            },
            startup: StartupConfig {
                align_current_a: if_current_a,
                align_time_s: 0.2,
                align_angle_rad: 0.0,
                if_current_a,
                accel_rad_s2: StartupConfig::default_accel_rad_s2(handover),
                handover_speed_rad_s: handover,
                blend_time_s: 20e-3,
                exit_speed_ratio: StartupConfig::default_exit_speed_ratio(
                    max_speed_rad_s,
                    handover,
                ),
                reversal: Reversal::ClosedLoop,
                acquire_timeout_s: 1.0,
                damping_ratio: 0.0,
                kick_speed_ratio: 0.0,
            },
            health: HealthConfig::default(),
            samples: SampleCheckConfig::default(),
            observer: ObserverConfig {
                speed_noise_adaptation: None,
                ..ObserverConfig::new(motor, ts_s)
            },
            #[cfg(feature = "flux-map")]
            flux_map: None,
            #[cfg(feature = "d-excitation")]
            d_excitation: None,
        }
        .with_inertia(kt / 1000.0)
    }

    /// Sets the computation delay and the matching default angle advance (1.5 or 0.5).
    pub fn with_delay(mut self, delay: ComputationDelay) -> Self {
        self.delay = delay;
        self.angle_advance_periods = delay.default_angle_advance_periods();
        self
    }

    /// Sets the mode.
    pub fn with_mode(mut self, mode: Mode) -> Self {
        self.mode = mode;
        self
    }

    /// Sets the inertia; the speed gains (unless given explicitly) follow, and the speed
    /// slew rate is set to `0.5 p k_t current_limit_a / J`.
    pub fn with_inertia(mut self, inertia_kg_m2: f32) -> Self {
        self.inertia_kg_m2 = inertia_kg_m2;
        self.speed_slew_rad_s2 =
            0.5 * self.motor.pole_pairs as f32 * self.torque_constant_nm_a() * self.current_limit_a
                / inertia_kg_m2;
        self
    }

    /// Torque constant `k_t = 1.5 p psi_f`, N m/A (peak-amplitude-invariant currents).
    pub fn torque_constant_nm_a(&self) -> f32 {
        torque_constant(&self.motor)
    }

    /// q-axis current-loop gains: `current_gains`, or `Kp = Lq bw` (V/A), `Ki = Rs bw`
    /// (V/(A s)). The d axis: [`current_pi_gains_d`](Self::current_pi_gains_d).
    pub fn current_pi_gains(&self) -> PiGains {
        self.current_gains.unwrap_or(PiGains {
            kp: self.motor.lq_h * self.current_bw_rad_s,
            ki: self.motor.rs_ohm * self.current_bw_rad_s,
        })
    }

    /// d-axis current-loop gains: `current_gains`, or `Kp = Ld bw` (V/A), `Ki = Rs bw`
    /// (V/(A s)); the same as the q axis' on a surface motor.
    pub fn current_pi_gains_d(&self) -> PiGains {
        self.current_gains.unwrap_or(PiGains {
            kp: self.motor.ld_h * self.current_bw_rad_s,
            ki: self.motor.rs_ohm * self.current_bw_rad_s,
        })
    }

    /// Turns field weakening on and multiplies `max_speed_rad_s` by `speed_ratio` (from the
    /// default, the base speed `0.95 U / (sqrt(3) psi_f)`, to `speed_ratio` times it).
    pub fn with_field_weakening(mut self, speed_ratio: f32) -> Self {
        self.field_weakening.enabled = true;
        self.max_speed_rad_s *= speed_ratio;
        self
    }

    /// The largest negative d current of field weakening, A:
    /// `field_weakening.max_negative_id_a`, or `min(current_limit_a, psi_f / Ld)`.
    pub fn max_negative_id(&self) -> f32 {
        self.field_weakening.max_negative_id_a.unwrap_or(min_f32(
            self.current_limit_a,
            self.motor.psi_f_wb / self.motor.ld_h,
        ))
    }

    /// Whether the closed-loop current references are shaped (MTPA, torque conversion,
    /// field weakening, current circle): a salient motor, field weakening on or a flux map.
    /// Otherwise the speed loop's output is the q reference as it is.
    pub fn shapes_references(&self) -> bool {
        self.motor.is_salient() || self.field_weakening.enabled || self.has_flux_map()
    }

    /// Whether the drive is told a flux map (`flux_map` is `Some`; always `false` without
    /// the cargo feature `flux-map`).
    pub fn has_flux_map(&self) -> bool {
        #[cfg(feature = "flux-map")]
        return self.flux_map.is_some();
        #[cfg(not(feature = "flux-map"))]
        false
    }

    /// The speed loop's output limit: the torque command (surface-equivalent current `T /
    /// k_t`, module [`mtpa`](crate::mtpa)) that `current_limit_a` makes on the MTPA curve (or
    /// with `i_d = 0` when `mtpa` is off), A. `current_limit_a` itself for a surface motor.
    /// With a flux map: the MTPA table's largest command.
    pub fn torque_current_limit_a(&self) -> f32 {
        #[cfg(feature = "flux-map")]
        if let Some(m) = &self.flux_map {
            return m.mtpa.torque_current_max();
        }
        if !self.motor.is_salient() {
            return self.current_limit_a;
        }
        let m = crate::mtpa::Mtpa::new(&self.motor);
        if self.mtpa {
            m.torque_current_at_magnitude(self.current_limit_a)
        } else {
            self.current_limit_a
        }
    }

    /// The torque command (surface-equivalent current, A) of the current vector `(i_d, i_q)`:
    /// `(psi_f + (Ld - Lq) i_d) i_q / psi_f`; `i_q` itself for a surface motor.
    pub fn torque_current_of(&self, i_d: f32, i_q: f32) -> f32 {
        if self.motor.is_salient() {
            crate::mtpa::Mtpa::new(&self.motor)
                .torque_current(crate::transforms::Dq { d: i_d, q: i_q })
        } else {
            i_q
        }
    }

    /// The linear band of the dead-time compensation's sign, A: `dead_time_band_a`, or 2 %
    /// of `current_limit_a`.
    pub fn dead_time_band(&self) -> f32 {
        self.dead_time_band_a
            .unwrap_or(DEAD_TIME_BAND_FRACTION * self.current_limit_a)
    }

    /// The largest plausible change of the current vector per period, A:
    /// `samples.max_step_a`, or `(u_dc_max_v + Rs over_current_a) Ts / Ls + 0.1
    /// over_current_a` ([`SampleCheckConfig`]; `Ls` the smaller of `Ld` and `Lq`).
    pub fn max_current_step(&self) -> f32 {
        self.samples.max_step_a.unwrap_or(
            (self.u_dc_max_v + self.motor.rs_ohm * self.over_current_a) * self.ts_s
                / min_f32(self.motor.ld_h, self.motor.lq_h)
                + 0.1 * self.over_current_a,
        )
    }

    /// Speed-loop gains on the mechanical speed: `speed_gains`, or `Kp = bw J / k_t`
    /// (A per rad/s), `Ki = Kp bw / 4` (A per rad).
    pub fn speed_pi_gains(&self) -> PiGains {
        self.speed_gains.unwrap_or_else(|| {
            let kp = self.speed_bw_rad_s * self.inertia_kg_m2 / self.torque_constant_nm_a();
            PiGains {
                kp,
                ki: kp * self.speed_bw_rad_s * 0.25,
            }
        })
    }
}

/// `min(a, b)` without `f32::min` (whose NaN handling hides a NaN in `a`).
fn min_f32(a: f32, b: f32) -> f32 {
    if a < b { a } else { b }
}

fn torque_constant(motor: &MotorParams<f32>) -> f32 {
    1.5 * motor.pole_pairs as f32 * motor.psi_f_wb
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn startup_defaults_come_from_the_startup_functions() {
        let (m, ts, u) = (MotorParams::servo(), 100e-6, 300.0);
        let c = FocConfig::new(m, ts, u);
        let h = StartupConfig::default_handover_speed_rad_s(
            &m,
            c.startup.if_current_a,
            c.max_speed_rad_s,
        );
        // The exit at 1.5 % of the base speed (the rated speed's stand-in), below 0.7 of the
        // hand-over speed here.
        let exit = c.startup.exit_speed_ratio * h;
        assert!((exit - 0.015 * c.max_speed_rad_s).abs() < 1e-3, "{exit}");
        assert!(c.startup.exit_speed_ratio < 0.7);
        assert!((StartupConfig::handover_speed_for(1000.0) - 30.0).abs() < 1e-4);
        assert_eq!(StartupConfig::exit_speed_ratio_for(1000.0, 30.0), 0.5);
        assert_eq!(StartupConfig::exit_speed_ratio_for(1000.0, 10.0), 0.7);
        assert_eq!(StartupConfig::exit_speed_ratio_for(1000.0, 5000.0), 0.01);
        assert_eq!(c.startup.handover_speed_rad_s.to_bits(), h.to_bits());
        assert_eq!(
            c.startup.accel_rad_s2.to_bits(),
            StartupConfig::default_accel_rad_s2(h).to_bits()
        );
        // 0.6 % of the rated speed, at most the hand-over speed.
        let r = StartupConfig::kick_speed_ratio_for(f64::from(10.0 * h), h);
        assert!((r - 0.06).abs() < 1e-6);
        assert_eq!(StartupConfig::kick_speed_ratio_for(1e9, h), 1.0);
    }

    #[test]
    fn defaults_validate_on_reference_motors() {
        for (m, ts, u) in [
            (MotorParams::servo(), 100e-6, 300.0),
            (MotorParams::servo(), 50e-6, 300.0),
            (MotorParams::industrial_2k2(), 125e-6, 540.0),
            (MotorParams::small_fast(), 50e-6, 48.0),
        ] {
            let c = FocConfig::new(m, ts, u);
            assert_eq!(c.validate(), Ok(()), "{m:?}");
            assert!(c.speed_divider >= 1);
        }
        let c = FocConfig::new(MotorParams::servo(), 100e-6, 300.0);
        let g = c.current_pi_gains();
        assert!((g.kp - 8.5e-3 * 0.1 * PI / 100e-6).abs() < 1e-3);
        assert_eq!(c.speed_divider, 5);
    }

    #[test]
    fn bad_fields_are_named() {
        let base = FocConfig::new(MotorParams::servo(), 100e-6, 300.0);
        let mut c = base;
        c.health.flux_range = [1.1, 1.3];
        assert_eq!(c.validate(), Err(ConfigError::OutOfRange(Field::FluxRange)));
        c.health.flux_range = [0.7, f32::NAN];
        assert_eq!(c.validate(), Err(ConfigError::NonFinite(Field::FluxRange)));
        let mut c = base;
        c.ts_s = f32::NAN;
        assert!(c.validate().is_err());
        let mut c = base;
        c.over_current_a = c.current_limit_a;
        assert_eq!(
            c.validate(),
            Err(ConfigError::OutOfRange(Field::OverCurrent))
        );
        let mut c = base;
        c.u_dc_max_v = c.u_dc_min_v;
        assert_eq!(c.validate(), Err(ConfigError::OutOfRange(Field::UdcMax)));
        let mut c = base;
        c.startup.accel_rad_s2 = f32::INFINITY;
        assert_eq!(c.validate(), Err(ConfigError::NonFinite(Field::Accel)));
        let mut c = base;
        c.speed_divider = 0;
        assert_eq!(
            c.validate(),
            Err(ConfigError::NotPositive(Field::SpeedDivider))
        );
        let mut c = base;
        c.observer.ts_s = 50e-6;
        assert_eq!(c.validate(), Err(ConfigError::ObserverMismatch));
        let mut c = base;
        c.motor.rs_ohm = -1.0;
        assert!(matches!(c.validate(), Err(ConfigError::Observer(_))));
        let mut c = base;
        c.current_gains = Some(PiGains {
            kp: f32::NAN,
            ki: 1.0,
        });
        assert_eq!(
            c.validate(),
            Err(ConfigError::OutOfRange(Field::CurrentGains))
        );
    }
}
