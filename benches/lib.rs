//! Shared helpers of the benchmarks.

use ekf_core::Float;

/// The samples the host benchmarks step through (`benches/ekf_step.rs` and
/// `examples/step_count.rs`): 1024 samples of a servo motor turning at `w_e Ts = 0.1` rad with
/// 2 A of q current, `(u_ab, i_ab)` converted by `conv`.
pub fn samples<T: Float>(conv: impl Fn(f64) -> T) -> Vec<([T; 2], [T; 2])> {
    (0..1024)
        .map(|k| {
            let th = 0.1 * k as f64;
            let (s, c) = th.sin_cos();
            let u = [conv(-180.0 * s), conv(180.0 * c)];
            let i = [conv(-2.0 * s + 0.01 * (k % 7) as f64), conv(2.0 * c)];
            (u, i)
        })
        .collect()
}
