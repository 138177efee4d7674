#![doc = include_str!("../README.md")]
#![cfg_attr(not(any(test, feature = "std")), no_std)]
#![forbid(unsafe_code)]
#![deny(missing_docs)]

pub mod angle;
pub mod ekf;
mod error;
pub mod motor;
pub mod noise;
pub mod observer;
mod structured;

pub use angle::wrap_angle;
pub use ekf::{Correction, CovarianceUpdate, Ekf, EkfError, MeasurementModel, ProcessModel};
pub use error::{ConfigError, Matrix, Param};
pub use motor::MotorParams;
pub use noise::NoiseCovariances;
pub use observer::{
    Discretization, Estimate, ObserverConfig, PmsmModel, PmsmObserver, Status, default_p0,
};

/// Re-export of the `nalgebra` this crate is built on, for its matrix types.
pub use nalgebra;

/// The scalar of the filter: `f32` (Cortex-M4F) or `f64` (host).
pub trait Float: nalgebra::RealField + Copy {}
impl Float for f32 {}
impl Float for f64 {}

/// `v` converted to the scalar type (rounded to nearest for `f32`).
pub(crate) fn to_t<T: Float>(v: f64) -> T {
    T::from_subset(&v)
}
