//! The MTPA table of a flux map ([`MapMtpa`], module docs of [`mapdrive`](super)).

use ekf_core::{Float, FluxMap};

use super::search::{Search, f, t};
use super::{MapPoint, MapTableError};
use crate::trig::{max2, min2, sqrt};

/// The MTPA curve of a flux map as `K` points evenly spaced in the square root of the torque
/// command (module docs of [`mapdrive`](super)). `K * 32 + 16` bytes.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct MapMtpa<const K: usize> {
    points: [MapPoint; K],
    /// `1 / i_t_max`, 1/A.
    inv_max: f32,
    /// Torque command of the last point (the current limit), A (surface-equivalent).
    i_t_max: f32,
    /// The torque constant of the command, N m/A.
    k_t: f32,
    /// The current limit the table was built for, A.
    current_limit: f32,
}

impl<const K: usize> MapMtpa<K> {
    /// The table of `map` for a motor of `pole_pairs`: torque commands `i_T = T / k_t` (A,
    /// `k_t = torque_constant_nm_a`) from 0 to the torque of `current_limit_a` on the map's
    /// MTPA curve. Errors: `K < 2`, a bad argument, a map without rising torque, a map not
    /// symmetric in `i_q`.
    pub fn from_map<T: Float, const N: usize>(
        map: &FluxMap<T, N>,
        pole_pairs: u32,
        torque_constant_nm_a: f32,
        current_limit_a: f32,
    ) -> Result<Self, MapTableError> {
        if K < 2 {
            return Err(MapTableError::TooFewPoints);
        }
        positive(torque_constant_nm_a, "torque_constant_nm_a")?;
        positive(current_limit_a, "current_limit_a")?;
        if pole_pairs == 0 {
            return Err(MapTableError::BadArgument("pole_pairs"));
        }
        let s = Search::new(map, pole_pairs);
        let i_max = t::<T>(current_limit_a);
        let (t_max, _) = s.best_at_magnitude(i_max);
        let t_max_f = f(t_max);
        let (t_half, _) = s.best_at_magnitude(i_max * t::<T>(0.5));
        if !(t_max_f.is_finite() && t_max_f > 0.0 && t_half < t_max) {
            return Err(MapTableError::NoTorque(current_limit_a));
        }
        let mut points = [MapPoint::ZERO; K];
        let mut last = -1.0f32;
        for (k, p) in points.iter_mut().enumerate() {
            let x = k as f32 / (K - 1) as f32;
            let torque = t_max * t::<T>(x * x);
            let (d, q) = if k == K - 1 {
                let (_, beta) = s.best_at_magnitude(i_max);
                let (sn, c) = beta.sin_cos_angle();
                (-i_max * sn, i_max * c)
            } else {
                s.mtpa_at_torque(torque, i_max)
            };
            *p = s.point(d, q);
            let finite = [p.psi.d, p.psi.q, p.l_dd, p.l_dq, p.l_qd, p.l_qq]
                .iter()
                .all(|x| x.is_finite());
            if !finite {
                return Err(MapTableError::NoTorque(current_limit_a));
            }
            let mag = f((d * d + q * q).sqrt());
            if !(mag.is_finite() && mag >= last) {
                return Err(MapTableError::NoTorque(mag));
            }
            last = mag;
            let tq = f(torque);
            let back = f(s.torque(d, -q));
            if (back + tq).abs() > 0.01 * max2(tq, 1e-3 * t_max_f) {
                return Err(MapTableError::Asymmetric(tq));
            }
        }
        let i_t_max = t_max_f / torque_constant_nm_a;
        Ok(Self {
            points,
            inv_max: 1.0 / i_t_max,
            i_t_max,
            k_t: torque_constant_nm_a,
            current_limit: current_limit_a,
        })
    }

    /// The MTPA point of the torque command `i_t` (A, surface-equivalent, sign = direction),
    /// its magnitude cut to [`torque_current_max`](Self::torque_current_max): the linear
    /// blend, linear in the torque, of the table's two neighbouring points, the cell found by
    /// `x = (K - 1) sqrt(|i_t| / i_t,max)` (one square root, one division). A NaN command
    /// gives the zero-torque point. No panics.
    #[inline]
    pub fn lookup(&self, i_t: f32) -> MapPoint {
        let n = (K - 1) as f32;
        let r = min2(max2(i_t.abs() * self.inv_max, 0.0), 1.0) * n * n;
        // `x` in `[0, K - 1]` (NaN: 0), so the index is in range; `get` keeps it panic-free.
        let x = sqrt(r);
        let k = (x as usize).min(K - 2);
        // Linear in the torque within the cell `[k^2, (k + 1)^2]`.
        let kf = k as f32;
        let a = (r - kf * kf) / (2.0 * kf + 1.0);
        let p = match (self.points.get(k), self.points.get(k + 1)) {
            (Some(p0), Some(p1)) => p0.blend(p1, a),
            _ => MapPoint::ZERO,
        };
        if i_t < 0.0 { p.mirrored() } else { p }
    }

    /// The largest torque command (A, surface-equivalent): the torque of the current limit
    /// on the MTPA curve over `k_t`.
    pub fn torque_current_max(&self) -> f32 {
        self.i_t_max
    }

    /// The torque constant the commands are expressed with, N m/A.
    pub fn torque_constant_nm_a(&self) -> f32 {
        self.k_t
    }

    /// The current limit the table was built for, A.
    pub fn current_limit_a(&self) -> f32 {
        self.current_limit
    }

    /// The table's points, from zero torque to the current limit.
    pub fn points(&self) -> &[MapPoint; K] {
        &self.points
    }
}

/// `Ok` when `x` is finite and positive, else the argument's name.
pub(super) fn positive(x: f32, name: &'static str) -> Result<(), MapTableError> {
    if x.is_finite() && x > 0.0 {
        Ok(())
    } else {
        Err(MapTableError::BadArgument(name))
    }
}
