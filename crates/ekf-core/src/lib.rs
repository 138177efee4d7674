#![doc = include_str!("../README.md")]
#![cfg_attr(not(any(test, feature = "std")), no_std)]
// Unsafe code only in `observer::host` (x86-64 with `std`): the call of the step compiled for
// AVX2 and FMA after their run-time detection.
#![deny(unsafe_code)]
#![deny(missing_docs)]

pub mod angle;
pub mod calibration;
pub mod catalog;
pub mod drive;
pub mod ekf;
mod error;
pub mod excitation;
pub mod flux;
pub mod fluxmap;
pub mod motor;
pub mod noise;
pub mod observer;
pub mod saturated;
pub mod saturation;
#[cfg(feature = "testing")]
#[doc(hidden)]
pub mod testing;
pub mod trig;

pub use angle::wrap_angle;
pub use calibration::{Calibration, RecordCalibration};
pub use drive::{DriveConfig, DriveEstimate, DriveObserver};
pub use ekf::{Correction, CovarianceUpdate, Ekf, EkfError, MeasurementModel, ProcessModel};
pub use error::{ConfigError, Matrix, Param};
pub use excitation::{
    ExcitationConfig, ExcitationError, ExcitationEstimate, ExcitationEstimator, excitation_sign,
};
pub use flux::{FluxAngleOutput, FluxEstimate, FluxObserver, FluxObserverConfig, FluxTiming};
pub use fluxmap::{FluxMap, FluxMapError, FluxPoint};
pub use motor::{
    MAX_INDUCTANCE_H, MAX_POLE_PAIRS, MAX_PSI_F_WB, MAX_RS_OHM, MAX_SALIENCY_RATIO,
    MIN_INDUCTANCE_H, MIN_SALIENCY_RATIO, MotorKind, MotorParams,
};
pub use noise::NoiseCovariances;
pub use observer::{
    AccelerationFeedforward, BranchCheck, ConsistencyCheck, CovarianceHealth, Discretization,
    Estimate, InnovationGate, ObserverConfig, ObserverCounters, ParameterTracking, PmsmModel,
    PmsmObserver, RsTracking, Status, default_p0,
};

/// Re-export of the `nalgebra` this crate is built on, for its matrix types.
pub use nalgebra;

/// The scalar of the filter: `f32` (Cortex-M4F) or `f64` (host).
pub trait Float: nalgebra::RealField + Copy {
    /// `(sin x, cos x)` computed in this precision only: [`trig::sin_cos_f32`] for `f32` (no
    /// `f64` on a single-precision FPU), [`trig::sin_cos_f64`] for `f64` (inline, within 1 ulp
    /// like the standard library's call, and the same with and without `std`).
    fn sin_cos_angle(self) -> (Self, Self);

    /// `self` truncated toward zero to an index, saturating (`0` for NaN and negatives): a
    /// cast in this precision (no conversion through `f64` on the MCU).
    fn trunc_index(self) -> usize;
}

impl Float for f32 {
    #[inline]
    fn sin_cos_angle(self) -> (f32, f32) {
        trig::sin_cos_f32(self)
    }

    #[inline]
    fn trunc_index(self) -> usize {
        self as usize
    }
}

impl Float for f64 {
    #[inline(always)]
    fn sin_cos_angle(self) -> (f64, f64) {
        trig::sin_cos_f64(self)
    }

    #[inline]
    fn trunc_index(self) -> usize {
        self as usize
    }
}

/// `v` converted to the scalar type (rounded to nearest for `f32`). Always inlined so that
/// constants fold at compile time and no `f64` conversion is left in `f32` code.
#[inline(always)]
pub(crate) fn to_t<T: Float>(v: f64) -> T {
    T::from_subset(&v)
}
