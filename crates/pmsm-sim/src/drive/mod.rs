//! The drive layer: the controller under test and the observers scored beside it.
//!
//! | module | what it holds |
//! | --- | --- |
//! | [`interface`] | the [`DriveController`](interface::DriveController) trait the run loop calls once per period, and its inputs and outputs |
//! | [`foc_adapter`] | the `foc` crate's controller (`f32`) behind that trait |
//! | [`rotor_observers`] | the [`Observer`](rotor_observers::Observer) trait of every rotor observer stepped alongside the drive and scored |

pub mod foc_adapter;
pub mod interface;
pub mod rotor_observers;
