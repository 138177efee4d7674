//! The field-weakening table of a flux map ([`MapFieldWeakening`], module docs of
//! [`mapdrive`](super)).

use ekf_core::{Float, FluxMap};

use super::mtpa::positive;
use super::search::{Search, f, t};
use super::{MapMtpa, MapPoint, MapTableError};
use crate::trig::{max2, min2};

/// Bisection steps on the torque of a row.
const BISECT_T: usize = 32;

/// The voltage-limited current vectors of a flux map: `J` flux limits by `K` torque
/// fractions (module docs of [`mapdrive`](super)). `J (K * 32 + 4) + 12` bytes.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct MapFieldWeakening<const J: usize, const K: usize> {
    /// `rows[j][k]`: the point at the flux limit `psi_j` and the torque `k / (K - 1)` of
    /// `t_max[j]`.
    rows: [[MapPoint; K]; J],
    /// The largest torque command at each row's flux limit, A (surface-equivalent).
    t_max: [f32; J],
    /// Flux limit of the first row, Wb.
    psi_lo: f32,
    /// Flux limit of the last row, Wb (the largest flux on the MTPA table).
    psi_hi: f32,
    /// `(J - 1) / (psi_hi - psi_lo)`, 1/Wb.
    inv_step: f32,
}

impl<const J: usize, const K: usize> MapFieldWeakening<J, K> {
    /// The table of `map` (motor of `pole_pairs`) for the commands and the current limit of
    /// `mtpa`, with flux limits from `psi_hi / speed_ratio` to `psi_hi` (`psi_hi` the largest
    /// flux on `mtpa`; `speed_ratio > 1`: weakening up to about that multiple of base
    /// speed).
    pub fn from_map<T: Float, const N: usize, const M: usize>(
        map: &FluxMap<T, N>,
        pole_pairs: u32,
        mtpa: &MapMtpa<M>,
        speed_ratio: f32,
    ) -> Result<Self, MapTableError> {
        if J < 2 || K < 2 {
            return Err(MapTableError::TooFewPoints);
        }
        positive(speed_ratio - 1.0, "speed_ratio - 1")?;
        if pole_pairs == 0 {
            return Err(MapTableError::BadArgument("pole_pairs"));
        }
        let s = Search::new(map, pole_pairs);
        let k_t = mtpa.torque_constant_nm_a();
        let i_max = t::<T>(mtpa.current_limit_a());
        let i_max_sq = i_max * i_max;
        let psi_hi = mtpa
            .points()
            .iter()
            .map(|p| crate::trig::sqrt(p.psi.d * p.psi.d + p.psi.q * p.psi.q))
            .fold(0.0f32, max2);
        let psi_lo = psi_hi / speed_ratio;
        let t_top = t::<T>(mtpa.torque_current_max() * k_t);
        // The least-current point of a torque within a flux limit and the current circle.
        let solve = |torque: T, psi: T| -> Option<(T, T)> {
            if torque <= T::zero() {
                return Some((T::zero(), T::zero()));
            }
            s.weakened(torque, psi, i_max)
                .filter(|&(d, q)| d * d + q * q <= i_max_sq * t::<T>(1.000_001))
        };
        let mut rows = [[MapPoint::ZERO; K]; J];
        let mut t_max = [0.0f32; J];
        for (j, (row, tm)) in rows.iter_mut().zip(t_max.iter_mut()).enumerate() {
            let psi = t::<T>(psi_lo + (psi_hi - psi_lo) * j as f32 / (J - 1) as f32);
            // The largest torque within the flux limit and the current circle.
            let (mut lo, mut hi) = (T::zero(), t_top);
            if solve(hi, psi).is_some() {
                lo = hi;
            } else {
                for _ in 0..BISECT_T {
                    let mid = (lo + hi) * t::<T>(0.5);
                    if solve(mid, psi).is_some() {
                        lo = mid;
                    } else {
                        hi = mid;
                    }
                }
            }
            *tm = f(lo) / k_t;
            if !tm.is_finite() {
                return Err(MapTableError::NoTorque(mtpa.current_limit_a()));
            }
            for (k, p) in row.iter_mut().enumerate() {
                let torque = lo * t::<T>(k as f32 / (K - 1) as f32);
                let (d, q) =
                    solve(torque, psi).ok_or(MapTableError::NoTorque(mtpa.current_limit_a()))?;
                *p = s.point(d, q);
                let finite = [
                    p.i.d, p.i.q, p.psi.d, p.psi.q, p.l_dd, p.l_dq, p.l_qd, p.l_qq,
                ]
                .iter()
                .all(|x| x.is_finite());
                if !finite {
                    return Err(MapTableError::NoTorque(mtpa.current_limit_a()));
                }
            }
        }
        Ok(Self {
            rows,
            t_max,
            psi_lo,
            psi_hi,
            inv_step: (J - 1) as f32 / (psi_hi - psi_lo),
        })
    }

    /// The point of the torque command `i_t` (A, surface-equivalent, sign = direction) at the
    /// flux limit `psi_lim` (Wb): bilinear in the flux and the torque fraction, the command's
    /// magnitude cut to the row's largest torque (module docs). A flux limit below the first
    /// row takes the first row (the voltage limit is then exceeded); above `psi_hi` the
    /// last (the caller uses the MTPA table there). No panics.
    #[inline]
    pub fn lookup(&self, i_t: f32, psi_lim: f32) -> MapPoint {
        let x = min2(
            max2((psi_lim - self.psi_lo) * self.inv_step, 0.0),
            (J - 1) as f32,
        );
        let j = (x as usize).min(J - 2);
        let a = x - j as f32;
        let (Some(r0), Some(r1), Some(t0), Some(t1)) = (
            self.rows.get(j),
            self.rows.get(j + 1),
            self.t_max.get(j),
            self.t_max.get(j + 1),
        ) else {
            return MapPoint::ZERO;
        };
        let tm = t0 + a * (t1 - t0);
        let y = if tm > 0.0 {
            min2(max2(i_t.abs() / tm, 0.0), 1.0) * (K - 1) as f32
        } else {
            0.0
        };
        let k = (y as usize).min(K - 2);
        let b = y - k as f32;
        let p = match (r0.get(k), r0.get(k + 1), r1.get(k), r1.get(k + 1)) {
            (Some(p00), Some(p01), Some(p10), Some(p11)) => {
                p00.blend(p01, b).blend(&p10.blend(p11, b), a)
            }
            _ => MapPoint::ZERO,
        };
        if i_t < 0.0 { p.mirrored() } else { p }
    }

    /// The largest torque command at the flux limit `psi_lim`, A (surface-equivalent):
    /// blended between rows.
    pub fn torque_current_max(&self, psi_lim: f32) -> f32 {
        let x = min2(
            max2((psi_lim - self.psi_lo) * self.inv_step, 0.0),
            (J - 1) as f32,
        );
        let j = (x as usize).min(J - 2);
        let a = x - j as f32;
        match (self.t_max.get(j), self.t_max.get(j + 1)) {
            (Some(t0), Some(t1)) => t0 + a * (t1 - t0),
            _ => 0.0,
        }
    }

    /// The flux limits of the first and the last row, Wb.
    pub fn flux_range_wb(&self) -> (f32, f32) {
        (self.psi_lo, self.psi_hi)
    }
}
