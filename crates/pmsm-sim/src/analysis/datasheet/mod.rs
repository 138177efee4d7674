//! The drive's datasheet (`pmsm-sim datasheet`): one motor's figures, each from a sweep run
//! here, written as a self-contained HTML page (inline SVG) and its markdown twin.
//!
//! | section | module | what is swept |
//! | --- | --- | --- |
//! | 1. angle error against load and speed | [`angle`] | a grid of speed x load, foc sensorless, one run a cell |
//! | 2. lowest closed-loop speed at rated torque | [`sections`] | [`crate::analysis::low_speed`]'s speeds, held under rated load |
//! | 3. start-up over random rotor angles | [`start`] | uniform initial angles, noise seeds drawn |
//! | 4. HFI polarity (salient motors) | [`start`] | uniform initial angles at standstill, HFI on |
//! | 5. identification error and time | [`sections`] | [`crate::analysis::identify`] on several noise seeds |
//! | 6. lock loss under parameter error | [`sections`] | a Monte-Carlo [`crate::analysis::sweep::Plan`] |
//! | 7. M4F instructions per tick | [`m4f`] | read from the QEMU run's JSON (`scripts/qemu-firmware.sh`) |
//!
//! [`render`] turns the results into sections (method, figure, table, result, command) and
//! [`page`] writes them as markdown and HTML; [`plots`] draws the figures.
//!
//! Every random draw comes from Xoshiro256++ streams seeded with [`DatasheetOptions::seed`]
//! (plus a constant per section): the datasheet is the same, byte for byte, for a seed,
//! whatever the number of threads. The runs of a section go to [`par_map`], a pool of Rust
//! threads that takes them in order and returns the results in order.
//!
//! `--quick` ([`Sizes::quick`]) runs every section with small `n` and short windows: the same
//! methods, for tests and a first look.

#[cfg(feature = "cli")]
pub mod cli;

pub mod angle;
pub mod m4f;
pub mod page;
pub mod plots;
pub mod render;
pub mod sections;
pub mod start;

use std::path::PathBuf;
use std::sync::atomic::{AtomicUsize, Ordering};

use serde::Serialize;

use crate::SimError;
use crate::analysis::suite::SuiteMotor;

/// The section titles, in order (the headings of the markdown and the HTML).
pub const SECTION_TITLES: [&str; 7] = [
    "1. Angle error against load and speed",
    "2. Lowest closed-loop speed at rated torque",
    "3. Start-up from random rotor angles",
    "4. HFI magnet polarity from random rotor angles",
    "5. Self-commissioning: identification error and time",
    "6. Lock loss under parameter error (Monte Carlo)",
    "7. Cortex-M4F instructions per control tick",
];

/// What `pmsm-sim datasheet` is asked for.
#[derive(Clone, Debug)]
pub struct DatasheetOptions {
    /// The motor (a reference motor, with its simulator preset's drive).
    pub motor: SuiteMotor,
    /// Small `n` and short windows ([`Sizes::quick`]).
    pub quick: bool,
    /// Seed of every random draw.
    pub seed: u64,
    /// Worker threads (at least 1).
    pub threads: usize,
    /// The QEMU instruction counts (JSON of `scripts/qemu-firmware.sh`); `None`: none.
    pub m4f_counts: Option<PathBuf>,
}

/// The sizes of every sweep.
#[derive(Clone, Debug, PartialEq, Serialize)]
pub struct Sizes {
    /// Section 1: test speeds, % of rated.
    pub angle_speeds_pct: Vec<f64>,
    /// Section 1: load levels, % of rated torque.
    pub angle_loads_pct: Vec<f64>,
    /// Section 1: the window over which the error is taken, s (after 0.3 s of settling).
    pub angle_window_s: f64,
    /// Section 2: test speeds, % of rated, from the top.
    pub low_speeds_pct: Vec<f64>,
    /// Section 2: time held at each speed, s.
    pub low_speed_hold_s: f64,
    /// Section 3: start-ups.
    pub startups: usize,
    /// Section 4: HFI starts.
    pub hfi_starts: usize,
    /// Section 5: identifications (noise seeds).
    pub identifications: usize,
    /// Section 6: Monte-Carlo runs.
    pub monte_carlo: usize,
}

impl Sizes {
    /// The full datasheet.
    pub fn full() -> Self {
        Self {
            angle_speeds_pct: vec![1.0, 2.0, 3.0, 5.0, 10.0, 20.0, 35.0, 50.0, 75.0, 100.0],
            angle_loads_pct: vec![0.0, 25.0, 50.0, 75.0, 100.0],
            angle_window_s: 1.0,
            low_speeds_pct: crate::analysis::low_speed::SPEEDS_PCT.to_vec(),
            low_speed_hold_s: crate::analysis::low_speed::HOLD_S,
            startups: 1000,
            hfi_starts: 200,
            identifications: 20,
            monte_carlo: 4000,
        }
    }

    /// `--quick`: the same methods, small `n`.
    pub fn quick() -> Self {
        Self {
            angle_speeds_pct: vec![10.0, 50.0, 100.0],
            angle_loads_pct: vec![0.0, 100.0],
            angle_window_s: 0.2,
            low_speeds_pct: vec![10.0, 5.0, 2.0],
            low_speed_hold_s: 1.0,
            startups: 6,
            hfi_starts: 4,
            identifications: 1,
            monte_carlo: 12,
        }
    }
}

/// Everything the datasheet shows.
#[derive(Clone, Debug, Serialize)]
pub struct Datasheet {
    /// The motor.
    pub motor: SuiteMotor,
    /// The simulator preset whose drive (inverter, sensors, controller) is used.
    pub preset: &'static str,
    /// Rated speed, rpm.
    pub rated_speed_rpm: f64,
    /// Rated torque, N m.
    pub rated_torque_nm: f64,
    /// Whether `--quick` made it.
    pub quick: bool,
    /// The seed.
    pub seed: u64,
    /// The sizes of the sweeps.
    pub sizes: Sizes,
    /// Section 1.
    pub angle: angle::AngleGrid,
    /// Section 2.
    pub low_speed: crate::analysis::low_speed::LowSpeedRow,
    /// Section 3.
    pub startup: start::StartupSweep,
    /// Section 4 (`None`: a surface motor).
    pub hfi: Option<start::HfiSweep>,
    /// Section 5.
    pub identify: sections::IdentifySweep,
    /// Section 6.
    pub monte_carlo: sections::MonteCarlo,
    /// Section 7.
    pub m4f: m4f::M4fCounts,
}

/// Builds the datasheet: every section's sweep, in order; `progress` is told each section's
/// title as it starts.
pub fn build(
    opts: &DatasheetOptions,
    progress: &mut dyn FnMut(&str),
) -> Result<Datasheet, SimError> {
    // Read first: a bad counts file fails before minutes of sweeps.
    let m4f = m4f::M4fCounts::load(opts.m4f_counts.as_deref())?;
    let sizes = if opts.quick {
        Sizes::quick()
    } else {
        Sizes::full()
    };
    let preset = crate::analysis::low_speed::preset_name(opts.motor);
    let base = crate::scenario::Scenario::preset(preset)?;
    let threads = opts.threads.max(1);
    progress(SECTION_TITLES[0]);
    let angle = angle::run(opts.motor, &sizes, threads)?;
    progress(SECTION_TITLES[1]);
    let low_speed = sections::low_speed(opts.motor, &sizes, threads)?;
    progress(SECTION_TITLES[2]);
    let startup = start::startups(opts.motor, sizes.startups, opts.seed, threads)?;
    progress(SECTION_TITLES[3]);
    let hfi = if opts.motor.is_interior() {
        Some(start::hfi_polarity(
            opts.motor,
            sizes.hfi_starts,
            opts.seed,
            threads,
        )?)
    } else {
        None
    };
    progress(SECTION_TITLES[4]);
    let identify = sections::identify(opts.motor, sizes.identifications, opts.seed, threads)?;
    progress(SECTION_TITLES[5]);
    let monte_carlo = sections::monte_carlo(opts.motor, sizes.monte_carlo, opts.seed, threads)?;
    Ok(Datasheet {
        motor: opts.motor,
        preset,
        rated_speed_rpm: base.rated_speed_rpm,
        rated_torque_nm: base.rated_torque_nm,
        quick: opts.quick,
        seed: opts.seed,
        sizes,
        angle,
        low_speed,
        startup,
        hfi,
        identify,
        monte_carlo,
        m4f,
    })
}

/// `f` over `items` on `threads` Rust threads (each takes the next item in order); the
/// results in the order of `items`, whatever the threads.
pub fn par_map<T: Sync, R: Send>(
    items: &[T],
    threads: usize,
    f: impl Fn(&T) -> R + Sync,
) -> Vec<R> {
    let threads = threads.clamp(1, items.len().max(1));
    let next = AtomicUsize::new(0);
    let mut out: Vec<(usize, R)> = Vec::with_capacity(items.len());
    std::thread::scope(|s| {
        let handles: Vec<_> = (0..threads)
            .map(|_| {
                let (next, f) = (&next, &f);
                s.spawn(move || {
                    let mut mine = Vec::new();
                    loop {
                        let k = next.fetch_add(1, Ordering::Relaxed);
                        let Some(item) = items.get(k) else { break };
                        mine.push((k, f(item)));
                    }
                    mine
                })
            })
            .collect();
        for h in handles {
            match h.join() {
                Ok(mine) => out.extend(mine),
                // A panicking run is a bug: pass it on unchanged.
                Err(p) => std::panic::resume_unwind(p),
            }
        }
    });
    out.sort_by_key(|(k, _)| *k);
    out.into_iter().map(|(_, r)| r).collect()
}

/// `Err` of the first failed run, else the values.
pub(crate) fn all_ok<R>(rs: Vec<Result<R, SimError>>) -> Result<Vec<R>, SimError> {
    rs.into_iter().collect()
}

/// A uniform draw in `[0, 1)` (53 bits) of `rng`.
pub(crate) fn unit(rng: &mut rand::rngs::Xoshiro256PlusPlus) -> f64 {
    use rand::Rng;
    (rng.next_u64() >> 11) as f64 * (1.0 / (1u64 << 53) as f64)
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn par_map_keeps_the_order_whatever_the_threads() {
        let items: Vec<u64> = (0..37).collect();
        let one = par_map(&items, 1, |x| x * x);
        let four = par_map(&items, 4, |x| x * x);
        assert_eq!(one, four);
        assert_eq!(one[36], 36 * 36);
        assert!(par_map(&Vec::<u64>::new(), 3, |x| *x).is_empty());
    }

    #[test]
    fn quick_is_smaller_than_full() {
        let (q, f) = (Sizes::quick(), Sizes::full());
        assert!(q.monte_carlo < f.monte_carlo && q.startups < f.startups);
        assert!(
            q.angle_speeds_pct.len() * q.angle_loads_pct.len()
                < f.angle_speeds_pct.len() * f.angle_loads_pct.len()
        );
    }
}
