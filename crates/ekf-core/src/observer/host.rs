//! The observer step compiled for x86-64 hosts with AVX2 and FMA, chosen at run time
//! ([`PmsmObserver::step`]): the same code as the portable step, in the VEX encoding (three
//! operands: no register copies before each operation, about a fifth fewer instructions per
//! step). Bit for bit the portable step's results: Rust never contracts a multiply and an add
//! into an FMA, and every other operation is exactly rounded in both encodings.
#![allow(unsafe_code)]

use super::{Estimate, PmsmObserver};
use crate::Float;
use crate::ekf::EkfError;

/// Whether this CPU has AVX2 and FMA (the standard library's detection, cached after the
/// first call).
#[inline]
pub(crate) fn has_avx2_fma() -> bool {
    std::arch::is_x86_feature_detected!("avx2") && std::arch::is_x86_feature_detected!("fma")
}

/// [`PmsmObserver::step_portable`] compiled with AVX2 and FMA enabled.
///
/// Its caller must have checked [`has_avx2_fma`]; this wrapper is only reachable from
/// [`PmsmObserver::step`] behind that check.
#[inline]
pub(crate) fn step_avx2_fma<T: Float>(
    obs: &mut PmsmObserver<T>,
    u_prev: [T; 2],
    i: [T; 2],
) -> Result<Estimate<T>, EkfError> {
    debug_assert!(has_avx2_fma());
    // SAFETY: `step_v3` only needs the CPU to support AVX2 and FMA, which the caller checked
    // with `has_avx2_fma` (run-time detection); it has no other precondition.
    unsafe { step_v3(obs, u_prev, i) }
}

#[target_feature(enable = "avx2,fma")]
fn step_v3<T: Float>(
    obs: &mut PmsmObserver<T>,
    u_prev: [T; 2],
    i: [T; 2],
) -> Result<Estimate<T>, EkfError> {
    obs.step_portable(u_prev, i)
}
