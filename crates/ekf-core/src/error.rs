//! Construction errors.

use core::fmt;

/// A scalar parameter named in a [`ConfigError`].
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum Param {
    /// Stator resistance `rs_ohm`.
    Rs,
    /// d-axis inductance `ld_h`.
    Ld,
    /// q-axis inductance `lq_h`.
    Lq,
    /// Saliency ratio `lq_h / ld_h` (within `MIN_SALIENCY_RATIO..=MAX_SALIENCY_RATIO`).
    Saliency,
    /// Magnet flux linkage `psi_f_wb`.
    PsiF,
    /// Number of pole pairs `pole_pairs`.
    PolePairs,
    /// Sample time `ts_s`.
    Ts,
    /// Angle standard deviation limit of the status `angle_sigma_limit_rad`.
    AngleSigmaLimit,
    /// Flux observer gain `observer_gain_rad_s` ([`crate::flux`]).
    ObserverGain,
    /// PLL bandwidth `pll_bandwidth_rad_s` ([`crate::flux`]).
    PllBandwidth,
    /// Threshold of the branch check, `BranchCheck::threshold_rad`.
    BranchThreshold,
    /// Speed below which the branch check sleeps, `BranchCheck::min_speed_rad_s`.
    BranchMinSpeed,
    /// Allowance of the branch check, `BranchCheck::allowance`.
    BranchAllowance,
    /// NIS threshold of the innovation gate, `InnovationGate::nis_threshold`.
    GateNisThreshold,
    /// Settled level of the innovation gate, `InnovationGate::settled_nis`.
    GateSettledNis,
    /// Angle uncertainty added by a flip, `BranchCheck::flip_angle_sigma_rad`.
    BranchFlipSigma,
    /// Trace factor of the covariance health check, `CovarianceHealth::trace_factor`.
    HealthTraceFactor,
    /// Current bound of the covariance health check, `CovarianceHealth::current_factor`.
    HealthCurrentFactor,
    /// Speed bound of the covariance health check, `CovarianceHealth::max_w_ts_rad`.
    HealthMaxSpeed,
    /// Divergence level of the covariance health check, `CovarianceHealth::divergence_nis`.
    HealthDivergenceNis,
    /// Fast mean of the consistency check, `ConsistencyCheck::fast_samples` (at least 1).
    ConsistencyFastSamples,
    /// Baseline of the consistency check, `ConsistencyCheck::slow_samples` (at least 1).
    ConsistencySlowSamples,
    /// Limit of the consistency check, `ConsistencyCheck::ratio`.
    ConsistencyRatio,
    /// Ceiling of the consistency check's baseline, `ConsistencyCheck::max_baseline`.
    ConsistencyMaxBaseline,
    /// Delay of the applied voltage, `ObserverConfig::voltage_delay_s` (within `[-2 Ts, 2 Ts]`).
    VoltageDelay,
    /// Inverter voltage error, `ObserverConfig::inverter_voltage_v` (within `[0, 100]` V).
    InverterVoltage,
    /// Samples of the speed noise adaptation's NIS mean, `SpeedNoiseAdaptation::samples`.
    AdaptationSamples,
    /// Reference NIS of the speed noise adaptation, `SpeedNoiseAdaptation::nis_reference`.
    AdaptationReference,
    /// Largest factor of the speed noise adaptation, `SpeedNoiseAdaptation::max_factor`.
    AdaptationMaxFactor,
    /// Block of the acceleration feedforward's learning, `AccelerationFeedforward::block_samples`.
    FeedforwardBlock,
    /// Memory of the acceleration feedforward's learning, `AccelerationFeedforward::memory_blocks`.
    FeedforwardMemory,
    /// Largest gain of the acceleration feedforward, `AccelerationFeedforward::max_gain`.
    FeedforwardMaxGain,
    /// Conditioning of the acceleration feedforward's learning, `AccelerationFeedforward::min_conditioning`.
    FeedforwardConditioning,
    /// A noise level of the drive observer (`DriveConfig::sigma_*`).
    DriveNoise,
    /// A prior of the drive observer's input errors (`DriveConfig::sigma_tau_s`,
    /// `sigma_rs_ohm`, `sigma_vdt_v`, `sign_band_a`).
    DrivePrior,
    /// A time of the drive observer (`DriveConfig::settle_s`, `restart_s`).
    DriveTime,
    /// Initial standard deviation of the tracked flux, `ParameterTracking::psi_f_sigma0`.
    TrackingPsiSigma,
    /// Initial standard deviation of the tracked resistance, `ParameterTracking::rs_sigma0`.
    TrackingRsSigma,
    /// Random walk of the tracked flux, `ParameterTracking::psi_f_walk_per_sqrt_s`.
    TrackingPsiWalk,
    /// Random walk of the tracked resistance, `ParameterTracking::rs_walk_per_sqrt_s`.
    TrackingRsWalk,
    /// Speed below which tracking freezes, `ParameterTracking::min_speed_rad_s`.
    TrackingMinSpeed,
    /// Bounds of the tracked flux, `ParameterTracking::psi_f_range`.
    TrackingPsiRange,
    /// Bounds of the tracked resistance, `ParameterTracking::rs_range`.
    TrackingRsRange,
    /// `ParameterTracking::reference_temperature_c`.
    TrackingReferenceTemperature,
    /// `ParameterTracking::rs_temperature_coefficient_per_k`.
    TrackingTemperatureCoefficient,
    /// `RsTracking::Split::magnet_coefficient_per_k` (must be negative).
    TrackingMagnetCoefficient,
    /// `RsTracking::Split::link_sigma_k`.
    TrackingLinkSigma,
    /// `RsTracking::Split::measurement_sigma`.
    TrackingWindowSigma,
    /// `RsTracking::Split::window_samples` (at least 1).
    TrackingWindow,
    /// `FluxOffsetTracking::gain` (in `(0, 1]`).
    FluxOffsetGain,
    /// `FluxOffsetTracking::window_rad` (in `(0, pi]`).
    FluxOffsetWindow,
    /// `FluxOffsetTracking::min_speed_rad_s` (finite, at least 0).
    FluxOffsetMinSpeed,
    /// `FluxOffsetTracking::max_drop_ratio` (above 0).
    FluxOffsetDropRatio,
    /// `FluxOffsetTracking::max_window_s` (above 0).
    FluxOffsetWindowTime,
    /// `FluxOffsetTracking::max_offset_fraction` (above 0).
    FluxOffsetRange,
}

/// A matrix named in a [`ConfigError`].
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum Matrix {
    /// Process noise covariance `Q` (4 x 4).
    Q,
    /// Measurement noise covariance `R` (2 x 2).
    R,
    /// Initial state covariance `P0` (4 x 4).
    P0,
}

/// Why a configuration was refused.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum ConfigError {
    /// The parameter is NaN or infinite.
    NonFinite(Param),
    /// The parameter is zero or negative.
    NotPositive(Param),
    /// `pole_pairs` is 0.
    ZeroPolePairs,
    /// The matrix holds a NaN or an infinity.
    NonFiniteMatrix(Matrix),
    /// The matrix is not symmetric.
    NotSymmetric(Matrix),
    /// The matrix has an entry above
    /// [`MAX_COVARIANCE_ENTRY`](crate::observer::MAX_COVARIANCE_ENTRY).
    TooLargeMatrix(Matrix),
    /// The matrix has a negative eigenvalue.
    NotPositiveSemiDefinite(Matrix),
    /// The matrix must be positive definite (the measurement noise `R`: `S` must stay
    /// invertible).
    NotPositiveDefinite(Matrix),
    /// The initial state `x0` holds a NaN or an infinity.
    NonFiniteInitialState,
    /// The parameter is too large for the sample time: its discrete update would be unstable
    /// or badly damped (the limit is in the parameter's documentation).
    TooLargeForTs(Param),
    /// The covariance health check is on but `trace(P0)` is zero, so its bound
    /// `trace_factor * trace(P0)` would reject every covariance.
    ZeroInitialCovarianceTrace,
    /// The covariance health check is on but `trace_factor * trace(P0)` overflows.
    TooLargeInitialCovariance,
    /// The parameter is outside its documented range.
    OutOfRange(Param),
    /// Parameter tracking was asked of the observer on a flux map, whose map is the model
    /// ([`MapObserver`](crate::saturated::MapObserver)).
    TrackingWithFluxMap,
    /// The acceleration feedforward was asked of an observer built without the cargo feature
    /// `acceleration-feedforward` (on with `std`).
    FeedforwardNotCompiled,
    /// [`ParameterTracking::transient_flux`](crate::observer::ParameterTracking::transient_flux)
    /// was asked of an observer built without the cargo feature `std`.
    TransientFluxNotCompiled,
    /// [`ParameterTracking::link_follows_data`](crate::observer::ParameterTracking::link_follows_data)
    /// was asked of an observer built without the cargo feature `std`.
    LinkFollowsDataNotCompiled,
}

impl fmt::Display for Param {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        f.write_str(match self {
            Param::Rs => "rs_ohm",
            Param::PolePairs => "pole_pairs",
            Param::Ld => "ld_h",
            Param::Lq => "lq_h",
            Param::Saliency => "lq_h / ld_h",
            Param::PsiF => "psi_f_wb",
            Param::Ts => "ts_s",
            Param::AngleSigmaLimit => "angle_sigma_limit_rad",
            Param::ObserverGain => "observer_gain_rad_s",
            Param::PllBandwidth => "pll_bandwidth_rad_s",
            Param::BranchThreshold => "branch_check.threshold_rad",
            Param::BranchMinSpeed => "branch_check.min_speed_rad_s",
            Param::BranchAllowance => "branch_check.allowance",
            Param::GateNisThreshold => "innovation_gate.nis_threshold",
            Param::GateSettledNis => "innovation_gate.settled_nis",
            Param::BranchFlipSigma => "branch_check.flip_angle_sigma_rad",
            Param::HealthTraceFactor => "covariance_health.trace_factor",
            Param::HealthCurrentFactor => "covariance_health.current_factor",
            Param::HealthMaxSpeed => "covariance_health.max_w_ts_rad",
            Param::HealthDivergenceNis => "covariance_health.divergence_nis",
            Param::ConsistencyFastSamples => "consistency.fast_samples",
            Param::ConsistencySlowSamples => "consistency.slow_samples",
            Param::ConsistencyRatio => "consistency.ratio",
            Param::ConsistencyMaxBaseline => "consistency.max_baseline",
            Param::VoltageDelay => "voltage_delay_s",
            Param::InverterVoltage => "inverter_voltage_v",
            Param::AdaptationSamples => "speed_noise_adaptation.samples",
            Param::AdaptationReference => "speed_noise_adaptation.nis_reference",
            Param::AdaptationMaxFactor => "speed_noise_adaptation.max_factor",
            Param::FeedforwardBlock => "acceleration_feedforward.block_samples",
            Param::FeedforwardMemory => "acceleration_feedforward.memory_blocks",
            Param::FeedforwardMaxGain => "acceleration_feedforward.max_gain",
            Param::FeedforwardConditioning => "acceleration_feedforward.min_conditioning",
            Param::DriveNoise => "drive.sigma (noise level)",
            Param::DrivePrior => "drive.sigma (input error prior)",
            Param::DriveTime => "drive.settle_s / restart_s",
            Param::TrackingPsiSigma => "parameter_tracking.psi_f_sigma0",
            Param::TrackingRsSigma => "parameter_tracking.rs_sigma0",
            Param::TrackingPsiWalk => "parameter_tracking.psi_f_walk_per_sqrt_s",
            Param::TrackingRsWalk => "parameter_tracking.rs_walk_per_sqrt_s",
            Param::TrackingMinSpeed => "parameter_tracking.min_speed_rad_s",
            Param::TrackingPsiRange => "parameter_tracking.psi_f_range",
            Param::TrackingRsRange => "parameter_tracking.rs_range",
            Param::TrackingReferenceTemperature => "parameter_tracking.reference_temperature_c",
            Param::TrackingMagnetCoefficient => "parameter_tracking.rs.magnet_coefficient_per_k",
            Param::TrackingLinkSigma => "parameter_tracking.rs.link_sigma_k",
            Param::TrackingWindowSigma => "parameter_tracking.rs.measurement_sigma",
            Param::TrackingWindow => "parameter_tracking.rs.window_samples",
            Param::FluxOffsetGain => "flux_offset.gain",
            Param::FluxOffsetWindow => "flux_offset.window_rad",
            Param::FluxOffsetMinSpeed => "flux_offset.min_speed_rad_s",
            Param::FluxOffsetDropRatio => "flux_offset.max_drop_ratio",
            Param::FluxOffsetWindowTime => "flux_offset.max_window_s",
            Param::FluxOffsetRange => "flux_offset.max_offset_fraction",
            Param::TrackingTemperatureCoefficient => {
                "parameter_tracking.rs_temperature_coefficient_per_k"
            }
        })
    }
}

impl fmt::Display for Matrix {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        f.write_str(match self {
            Matrix::Q => "Q",
            Matrix::R => "R",
            Matrix::P0 => "P0",
        })
    }
}

impl fmt::Display for ConfigError {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        match self {
            ConfigError::NonFinite(p) => write!(f, "{p} is not finite"),
            ConfigError::NotPositive(p) => write!(f, "{p} must be positive"),
            ConfigError::ZeroPolePairs => f.write_str("pole_pairs must be at least 1"),
            ConfigError::NonFiniteMatrix(m) => write!(f, "{m} holds a NaN or an infinity"),
            ConfigError::NotSymmetric(m) => write!(f, "{m} is not symmetric"),
            ConfigError::TooLargeMatrix(m) => write!(
                f,
                "{m} has an entry above {:e}: no noise is that large, and the filter's \
                 arithmetic would overflow",
                crate::observer::MAX_COVARIANCE_ENTRY
            ),
            ConfigError::NotPositiveDefinite(m) => {
                write!(f, "{m} is not positive definite (it must be invertible)")
            }
            ConfigError::NotPositiveSemiDefinite(m) => {
                write!(f, "{m} is not positive semi-definite (negative eigenvalue)")
            }
            ConfigError::NonFiniteInitialState => f.write_str("x0 holds a NaN or an infinity"),
            ConfigError::TooLargeForTs(p) => {
                write!(f, "{p} is too large for ts_s (unstable discrete update)")
            }
            ConfigError::TooLargeInitialCovariance => {
                f.write_str("covariance_health: trace_factor * trace(P0) is not finite")
            }
            ConfigError::OutOfRange(p) => match crate::motor::plausible_range(*p) {
                Some(range) => write!(f, "{p} is outside its accepted range {range}"),
                None => write!(f, "{p} is outside its documented range"),
            },
            ConfigError::TrackingWithFluxMap => f.write_str(
                "parameter_tracking is not available on a flux map (the map is the motor's \
                 model): set it to None",
            ),
            ConfigError::FeedforwardNotCompiled => f.write_str(
                "acceleration_feedforward needs ekf-core's cargo feature \
                 `acceleration-feedforward` (on with `std`): enable it or set it to None",
            ),
            ConfigError::TransientFluxNotCompiled => f.write_str(
                "parameter_tracking.transient_flux needs ekf-core's cargo feature `std`: \
                 enable it or set transient_flux to false",
            ),
            ConfigError::LinkFollowsDataNotCompiled => f.write_str(
                "parameter_tracking.link_follows_data needs ekf-core's cargo feature `std`: \
                 enable it or set link_follows_data to false",
            ),
            ConfigError::ZeroInitialCovarianceTrace => f.write_str(
                "covariance_health needs trace(P0) > 0 (its bound is a multiple of trace(P0))",
            ),
        }
    }
}

impl core::error::Error for ConfigError {}
