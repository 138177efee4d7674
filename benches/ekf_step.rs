//! Host time per observer step (predict + correct), f32 and f64, default (lag-free, Joseph,
//! online parameter tracking), the default without tracking, the default on an interior motor,
//! and seed (forward Euler, standard form) configurations; and the peers on the same data: the
//! generic `Ekf` on the same model (no safeguards, no tracking) and the flux observer + PLL.
//!
//! Run: `cargo bench -p benches --bench ekf_step`. Target: <= 30 ns per step in f64 (not met: docs/performance.md).
use std::hint::black_box;

use benches::samples;
use criterion::{Criterion, criterion_group, criterion_main};
use ekf_core::nalgebra::Vector2;
use ekf_core::{
    Ekf, Float, FluxObserver, FluxObserverConfig, MotorParams, ObserverConfig, PmsmModel,
    PmsmObserver,
};

fn bench_cfg<T: Float>(
    c: &mut Criterion,
    name: &str,
    cfg: ObserverConfig<T>,
    data: &[([T; 2], [T; 2])],
) {
    let mut obs = PmsmObserver::new(&cfg).expect("valid config");
    let mut k = 0usize;
    c.bench_function(name, |b| {
        b.iter(|| {
            let (u, i) = data[k & 1023];
            k = k.wrapping_add(1);
            black_box(obs.step(black_box(u), black_box(i)))
        })
    });
}

fn ekf_step(c: &mut Criterion) {
    let ts = 1e-4;
    let d64 = samples(|v| v);
    let d32 = samples(|v| v as f32);
    bench_cfg(
        c,
        "step f64 default",
        ObserverConfig::new(MotorParams::<f64>::servo(), ts),
        &d64,
    );
    bench_cfg(
        c,
        "step f64 default untracked",
        ObserverConfig {
            parameter_tracking: None,
            ..ObserverConfig::new(MotorParams::<f64>::servo(), ts)
        },
        &d64,
    );
    bench_cfg(
        c,
        "step f64 seed",
        ObserverConfig::seed(MotorParams::<f64>::servo(), ts),
        &d64,
    );
    bench_cfg(
        c,
        "step f64 default salient",
        ObserverConfig::new(
            MotorParams::<f64>::salient_from_f64(2.875, 0.7 * 8.5e-3, 8.5e-3, 0.175, 4),
            ts,
        ),
        &d64,
    );
    // The peers on the same data: the plain generic filter on the same model (no safeguards,
    // no tracking) and the flux observer + PLL baseline.
    let cfg = ObserverConfig::new(MotorParams::<f64>::servo(), ts);
    let model = PmsmModel::new(&cfg);
    let mut ekf = Ekf::<f64, 4, 2>::new(cfg.x0, cfg.p0, cfg.covariance_update);
    let mut k = 0usize;
    c.bench_function("step f64 generic Ekf", |b| {
        b.iter(|| {
            let (u, i) = d64[k & 1023];
            k = k.wrapping_add(1);
            let p = ekf.predict(&model, &Vector2::from(black_box(u)));
            black_box((p, ekf.correct(&model, &Vector2::from(black_box(i)))))
        })
    });
    let mut flux = FluxObserver::new(&FluxObserverConfig::new(MotorParams::<f64>::servo(), ts))
        .expect("valid config");
    let mut k = 0usize;
    c.bench_function("step f64 flux observer", |b| {
        b.iter(|| {
            let (u, i) = d64[k & 1023];
            k = k.wrapping_add(1);
            black_box(flux.step(black_box(u), black_box(i)))
        })
    });
    bench_cfg(
        c,
        "step f32 default",
        ObserverConfig::new(MotorParams::<f32>::servo(), ts as f32),
        &d32,
    );
    bench_cfg(
        c,
        "step f32 seed",
        ObserverConfig::seed(MotorParams::<f32>::servo(), ts as f32),
        &d32,
    );
}

criterion_group!(benches, ekf_step);
criterion_main!(benches);
