//! Re-seeding the observer at the sequencer's request (start-up, re-acquisition).

use ekf_core::PmsmObserver;
use ekf_core::nalgebra::{Matrix4, Vector4};

use crate::config::FocConfig;
use crate::startup::Seed;
use crate::trig::wrap;

/// Replaces the observer's estimate by the seed's angle (rad el.) and speed (rad/s el.) with
/// its angle standard deviation (rad); the currents keep their estimate. Rare (start-up,
/// re-acquisition): out of line.
#[cold]
#[inline(never)]
pub(super) fn reseed_observer(observer: &mut PmsmObserver<f32>, cfg: &FocConfig, seed: Seed) {
    let x = observer.state();
    let si = 0.1 * cfg.motor.characteristic_current_a();
    let sw = 0.5 * cfg.startup.handover_speed_rad_s + 0.3 * seed.omega.abs();
    let x = Vector4::new(x[0], x[1], seed.omega, wrap(seed.theta));
    let p = Matrix4::from_diagonal(&Vector4::new(
        si * si,
        si * si,
        sw * sw,
        seed.sigma_theta * seed.sigma_theta,
    ));
    // Refused only for non-finite values, which these are not; nothing changes then.
    let _ = observer.reset(x, p);
}
