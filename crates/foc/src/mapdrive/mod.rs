//! MTPA, field weakening and current-loop gains from a flux map (`ekf_core::FluxMap`) of a
//! saturating motor: tables built once (on the host or at commissioning, no allocation),
//! looked up every tick.
//!
//! The constant-parameter laws of [`mtpa`](crate::mtpa) and [`fieldweak`](crate::fieldweak)
//! assume `psi_d = psi_f + Ld i_d`, `psi_q = Lq i_q`. A saturating motor's fluxes are
//! `psi_d(i_d, i_q)`, `psi_q(i_d, i_q)` (magnet included in `psi_d`), with the incremental
//! inductances `L_xy = dpsi_x / di_y` and the torque
//!
//! ```text
//! T = 1.5 p (psi_d i_q - psi_q i_d)
//! ```
//!
//! # MTPA table ([`MapMtpa`])
//!
//! For a current magnitude `I` the angle `beta` of `(i_d, i_q) = I (-sin beta, cos beta)`
//! that maximizes `T` is found by a scan of 48 angles over `(-pi/2, pi/2)` followed by a
//! golden-section search (40 steps) in the bracket around the best one: the map's own
//! torque, no derivative, robust to a curve that is not concave far from the optimum. The
//! best torque rises with `I`, so the MTPA point of a torque is found by bisection on `I`
//! (40 steps). The table holds `K` points of the torque command `i_T = T / k_t` (the speed
//! loop's output, a surface-equivalent current; `k_t = 1.5 p psi_f` of the configured
//! motor) from 0 to the torque of the current limit on the MTPA curve, evenly spaced in
//! `sqrt(i_T)`: dense at low torque, where the MTPA curve of a reluctance motor bends within
//! a few amperes (evenly in `i_T`, the first cell of `pm_syrm` spans 1.5 A and the torque
//! between the points was 7 % off). Each point stores the currents, the fluxes and the four
//! incremental inductances ([`MapPoint`]). A lookup finds the cell by one square root,
//! blends its two points linearly in the torque (one division) and flips the sign for a
//! negative torque: the map is taken as symmetric in `i_q` (`psi_d` even, `psi_q` odd), which
//! [`MapMtpa::from_map`] checks on every point (torque of `(i_d, -i_q)` within 1 %).
//!
//! # Field-weakening table ([`MapFieldWeakening`])
//!
//! In steady state `u_d = Rs i_d - w psi_q`, `u_q = Rs i_q + w psi_d`, so
//! `|u| <= |w| |psi| + Rs |i|`. The voltage limit `k u_max` (margin `k`,
//! `field_weakening.voltage_margin`, the same as the constant-parameter loop's) holds when
//!
//! ```text
//! |psi(i_d, i_q)| <= psi_lim = (k u_max - Rs |i_r|) / |w|
//! ```
//!
//! with `|i_r|` the magnitude of the last tick's reference (the triangle bound: conservative
//! by the angle between the resistive and the inductive voltage). For a torque `T` and a
//! flux limit the current vector of least magnitude is found on the constant-torque curve
//! (`i_q(i_d)` by bisection): the MTPA point when its flux is within the limit, else the
//! point toward negative `i_d` where `|psi| = psi_lim`, found by bisection between the MTPA
//! point and the curve's least flux (the maximum-torque-per-volt point, golden section). `T`
//! is achievable at `psi_lim` when that point lies in the current circle; the largest
//! achievable torque `T_max(psi)` comes from bisection on `T`. The table has `J` rows evenly
//! spaced in `psi_lim` from `psi_hi / speed_ratio` to `psi_hi` (the largest flux on the MTPA
//! table) and `K` columns at the fractions `tau = T / T_max(psi_lim)` from 0 to 1. A tick
//! finds the row by one multiplication, blends `T_max`, divides the command by it (a command
//! above `T_max` is cut to it: the most torque the voltage and the current allow there) and
//! blends four points bilinearly. Above `psi_hi` the MTPA table is used. This is a
//! feed-forward: the constant-parameter loop's voltage feedback (module
//! [`fieldweak`](crate::fieldweak)) does not run with a map, so the margin `1 - k` must
//! cover the map's error and the interpolation's (0.4 % of the flux at twice base speed).
//!
//! # Current-loop gains and decoupling
//!
//! With the point `P` of the tick's reference (currents `i_r`, fluxes `psi_r`, inductances
//! `L_r`), the current PIs take
//!
//! ```text
//! Kp,d = bw L_dd(i_r),   Kp,q = bw L_qq(i_r),   Ki = Rs bw (unchanged)
//! psi(i) = psi_r + L_r (i - i_r)                 (first-order expansion at the reference)
//! u_d,ff = -w psi_q(i),   u_q,ff = w psi_d(i)    (decoupling and back-EMF together)
//! ```
//!
//! so that each axis stays first order with crossover `bw` where saturation lowers the
//! incremental inductance (constant gains from the small-signal `Ld`, `Lq` raise the
//! crossover by `Lq,0 / L_qq` there, toward the delay's phase limit), and the cross-coupling
//! voltage is the map's flux, not `L i`. The expansion costs four multiply-adds a tick instead
//! of a map evaluation (505 instructions on the Cortex-M4F). The back-EMF is the map's
//! `psi_d`, not the observer's tracked `psi_f` (a warm magnet's lower flux is then left to
//! the integrators). Explicit gains (`FocConfig::current_gains`) are not scheduled. Out of
//! closed loop (align, I/f) the configured gains and feed-forward apply.
//!
//! # Cost
//!
//! Built on the host in `f64` (or in the map's precision at commissioning): the MTPA table
//! about 1.2e5 map evaluations, the field-weakening table about 2e6 (under a second in a
//! release build on the host). Per tick on the Cortex-M4F (static instruction counts of the
//! `thumbv7em-none-eabihf` release build, no loops, so an upper bound on one call; the
//! firmware example does not build the feature): `MapMtpa::lookup` 119 instructions with 4
//! divisions (3 in the square root), the whole reference path with the field-weakening
//! lookup inlined 317 more. Tables: `MapMtpa<33>` 1.0 KiB, `MapFieldWeakening<12, 13>`
//! 4.9 KiB.
//!
//! # Measured
//!
//! `cargo test -p foc --lib mapdrive -- --nocapture` (docs/saturation.md has the tables):
//! torque per ampere within 0.006 % of the map's optimum at 0.25 to 2 times the rated current
//! and between all table points, on `pm_syrm` and `saturating_ipm`; at twice base speed on
//! `saturating_ipm` the flux within 0.4 % of the limit and the largest torque 0.13 % above
//! the brute-force best (within the interpolation); current-loop steps at rated current
//! overshoot 2.8 % / 1.6 % with scheduled gains, 93 % / 47 % with the constant small-signal
//! ones.

mod fw;
mod mtpa;
mod search;
#[cfg(test)]
mod tests;

pub use fw::MapFieldWeakening;
pub use mtpa::MapMtpa;

use core::fmt;

use crate::transforms::Dq;

/// Points of the MTPA table of [`MapTables`].
pub const MTPA_POINTS: usize = 33;
/// Flux rows of the field-weakening table of [`MapTables`].
pub const FW_ROWS: usize = 12;
/// Torque columns of the field-weakening table of [`MapTables`].
pub const FW_COLUMNS: usize = 13;

/// The map at one operating point: currents, fluxes and incremental inductances.
#[derive(Clone, Copy, Debug, Default, PartialEq)]
pub struct MapPoint {
    /// `(i_d, i_q)`, A.
    pub i: Dq,
    /// `(psi_d, psi_q)`, Wb (magnet in `psi_d`).
    pub psi: Dq,
    /// `dpsi_d / di_d`, H.
    pub l_dd: f32,
    /// `dpsi_d / di_q`, H.
    pub l_dq: f32,
    /// `dpsi_q / di_d`, H.
    pub l_qd: f32,
    /// `dpsi_q / di_q`, H.
    pub l_qq: f32,
}

impl MapPoint {
    /// All zero.
    pub const ZERO: MapPoint = MapPoint {
        i: Dq { d: 0.0, q: 0.0 },
        psi: Dq { d: 0.0, q: 0.0 },
        l_dd: 0.0,
        l_dq: 0.0,
        l_qd: 0.0,
        l_qq: 0.0,
    };

    /// `self + a (other - self)`, field by field.
    #[inline]
    pub fn blend(&self, other: &MapPoint, a: f32) -> MapPoint {
        let l = |x: f32, y: f32| x + a * (y - x);
        MapPoint {
            i: Dq {
                d: l(self.i.d, other.i.d),
                q: l(self.i.q, other.i.q),
            },
            psi: Dq {
                d: l(self.psi.d, other.psi.d),
                q: l(self.psi.q, other.psi.q),
            },
            l_dd: l(self.l_dd, other.l_dd),
            l_dq: l(self.l_dq, other.l_dq),
            l_qd: l(self.l_qd, other.l_qd),
            l_qq: l(self.l_qq, other.l_qq),
        }
    }

    /// The point of the opposite torque (`i_q`, `psi_q` and the cross inductances change
    /// sign on a map symmetric in `i_q`).
    #[inline]
    pub fn mirrored(&self) -> MapPoint {
        MapPoint {
            i: Dq {
                d: self.i.d,
                q: -self.i.q,
            },
            psi: Dq {
                d: self.psi.d,
                q: -self.psi.q,
            },
            l_dd: self.l_dd,
            l_dq: -self.l_dq,
            l_qd: -self.l_qd,
            l_qq: self.l_qq,
        }
    }

    /// The fluxes at the currents `i` by the first-order expansion at this point,
    /// `psi + L (i - i_p)`, Wb.
    #[inline]
    pub fn flux_at(&self, i: Dq) -> Dq {
        let (ed, eq) = (i.d - self.i.d, i.q - self.i.q);
        Dq {
            d: self.psi.d + self.l_dd * ed + self.l_dq * eq,
            q: self.psi.q + self.l_qd * ed + self.l_qq * eq,
        }
    }
}

/// Why a table could not be built from a map.
#[derive(Clone, Copy, Debug, PartialEq)]
pub enum MapTableError {
    /// A table needs at least 2 points (rows, columns).
    TooFewPoints,
    /// An argument is not finite and positive (its name).
    BadArgument(&'static str),
    /// The map's torque is not finite, or does not rise with the current, at this current
    /// magnitude, A (the map does not describe a motor there).
    NoTorque(f32),
    /// The map is not symmetric in `i_q`: the torque at `(i_d, -i_q)` differs from the
    /// opposite of the torque at `(i_d, i_q)` by more than 1 % at this torque, N m.
    Asymmetric(f32),
}

impl fmt::Display for MapTableError {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        match *self {
            Self::TooFewPoints => f.write_str("a map table needs at least 2 points per axis"),
            Self::BadArgument(name) => write!(f, "{name} must be finite and positive"),
            Self::NoTorque(i) => write!(
                f,
                "the flux map gives no rising, finite torque at {i} A on its MTPA curve"
            ),
            Self::Asymmetric(t) => write!(
                f,
                "the flux map is not symmetric in i_q: torques of opposite q currents differ \
                 by more than 1 % at {t} N m"
            ),
        }
    }
}

impl core::error::Error for MapTableError {}

/// What a drive told a flux map uses ([`FocConfig::flux_map`](crate::FocConfig::flux_map),
/// cargo feature `flux-map`): the MTPA table, the field-weakening table (used when
/// `field_weakening.enabled`) and the scheduled gains (module docs).
///
/// ```
/// use foc::{Foc, FocConfig, MapTables, Mode};
/// use foc::ekf_core::saturation::SATURATED_IPM;
///
/// let r = &SATURATED_IPM.reference;
/// let mut cfg = FocConfig::new(r.params::<f32>(), r.ts_s as f32, r.u_dc_v as f32)
///     .with_mode(Mode::Sensored)
///     .with_field_weakening(2.0);
/// cfg.current_limit_a = 12.0;
/// cfg.over_current_a = 24.0;
/// // The motor's map (here sampled from its model on a 12 x 16 grid).
/// let axis = |n: usize, lo: f64, hi: f64| -> Vec<f64> {
///     (0..n).map(|k| lo + (hi - lo) * k as f64 / (n - 1) as f64).collect()
/// };
/// let map = SATURATED_IPM
///     .model
///     .flux_map::<f64, 16>(&axis(12, -13.0, 5.0), &axis(16, -13.0, 13.0))?;
/// // MTPA up to the current limit, field weakening down to a quarter of the MTPA flux.
/// let tables = MapTables::from_map(
///     &map,
///     r.pole_pairs,
///     cfg.torque_constant_nm_a(),
///     cfg.current_limit_a,
///     4.0,
/// )?;
/// cfg.flux_map = Some(tables);
/// assert_eq!(cfg.torque_current_limit_a(), tables.mtpa.torque_current_max());
/// let foc = Foc::new(&cfg)?;
/// # let _ = foc;
/// # Ok::<(), Box<dyn std::error::Error>>(())
/// ```
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct MapTables {
    /// MTPA table.
    pub mtpa: MapMtpa<MTPA_POINTS>,
    /// Field-weakening table.
    pub fw: MapFieldWeakening<FW_ROWS, FW_COLUMNS>,
}

impl MapTables {
    /// Both tables from `map` for a motor of `pole_pairs`, the torque command's torque
    /// constant `torque_constant_nm_a` (`FocConfig::torque_constant_nm_a`), the current limit
    /// `current_limit_a` and field weakening down to `1 / speed_ratio` of the MTPA flux
    /// (`speed_ratio` times base speed).
    pub fn from_map<T: ekf_core::Float, const N: usize>(
        map: &ekf_core::FluxMap<T, N>,
        pole_pairs: u32,
        torque_constant_nm_a: f32,
        current_limit_a: f32,
        speed_ratio: f32,
    ) -> Result<Self, MapTableError> {
        let mtpa = MapMtpa::from_map(map, pole_pairs, torque_constant_nm_a, current_limit_a)?;
        let fw = MapFieldWeakening::from_map(map, pole_pairs, &mtpa, speed_ratio)?;
        Ok(Self { mtpa, fw })
    }
}
