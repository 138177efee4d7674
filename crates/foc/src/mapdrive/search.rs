//! The host-side searches on a flux map that build the tables (module docs of
//! [`mapdrive`](super)): golden section on the current angle, bisection on the current
//! magnitude, the constant-torque curve. Computed in the map's precision `T`.

use ekf_core::nalgebra::{convert, try_convert};
use ekf_core::{Float, FluxMap};

use super::MapPoint;
use crate::transforms::Dq;

/// Angles of the coarse scan before the golden-section search.
const SCAN: usize = 48;
/// Golden-section steps (bracket shrinks by `0.618^40 = 4e-9`).
const GOLDEN: usize = 40;
/// Bisection steps.
const BISECT: usize = 40;

/// `x` as `T`.
pub(super) fn t<T: Float>(x: f32) -> T {
    convert::<f32, T>(x)
}

/// `x` as `f32`.
pub(super) fn f<T: Float>(x: T) -> f32 {
    try_convert::<T, f32>(x).unwrap_or(f32::NAN)
}

/// A flux map with its torque factor `1.5 p`.
pub(super) struct Search<'a, T, const N: usize> {
    pub map: &'a FluxMap<T, N>,
    pub k: T,
}

impl<'a, T: Float, const N: usize> Search<'a, T, N> {
    pub fn new(map: &'a FluxMap<T, N>, pole_pairs: u32) -> Self {
        let p: T = convert::<f64, T>(f64::from(pole_pairs));
        Self {
            map,
            k: t::<T>(1.5) * p,
        }
    }

    /// Torque at `(i_d, i_q)`, N m.
    pub fn torque(&self, i_d: T, i_q: T) -> T {
        let p = self.map.eval(i_d, i_q);
        self.k * (p.psi_d * i_q - p.psi_q * i_d)
    }

    /// Flux magnitude at `(i_d, i_q)`, Wb.
    pub fn flux(&self, i_d: T, i_q: T) -> T {
        let p = self.map.eval(i_d, i_q);
        (p.psi_d * p.psi_d + p.psi_q * p.psi_q).sqrt()
    }

    /// The map point at `(i_d, i_q)` in `f32`.
    pub fn point(&self, i_d: T, i_q: T) -> MapPoint {
        let p = self.map.eval(i_d, i_q);
        MapPoint {
            i: Dq {
                d: f(i_d),
                q: f(i_q),
            },
            psi: Dq {
                d: f(p.psi_d),
                q: f(p.psi_q),
            },
            l_dd: f(p.l_dd),
            l_dq: f(p.l_dq),
            l_qd: f(p.l_qd),
            l_qq: f(p.l_qq),
        }
    }

    /// Torque at magnitude `i` and angle `beta` (`i_d = -i sin beta`, `i_q = i cos beta`).
    fn torque_polar(&self, i: T, beta: T) -> T {
        let (s, c) = beta.sin_cos_angle();
        self.torque(-i * s, i * c)
    }

    /// The largest torque at the current magnitude `i` and its angle: a scan of `SCAN`
    /// angles over `(-pi/2, pi/2)`, then golden section between the best one's neighbours.
    pub fn best_at_magnitude(&self, i: T) -> (T, T) {
        let half_pi = t::<T>(core::f32::consts::FRAC_PI_2);
        let step = (half_pi + half_pi) / convert::<f64, T>((SCAN + 1) as f64);
        let angle = |k: usize| -half_pi + step * convert::<f64, T>((k + 1) as f64);
        let mut best = (0, self.torque_polar(i, angle(0)));
        for k in 1..SCAN {
            let v = self.torque_polar(i, angle(k));
            if v > best.1 {
                best = (k, v);
            }
        }
        let a = angle(best.0) - step;
        let b = angle(best.0) + step;
        let beta = golden_max(a, b, |x| self.torque_polar(i, x));
        (self.torque_polar(i, beta), beta)
    }

    /// The MTPA point `(i_d, i_q)` of the torque `torque` (N m, >= 0) below the current
    /// `i_max`: bisection on the magnitude, whose best torque rises with it.
    pub fn mtpa_at_torque(&self, torque: T, i_max: T) -> (T, T) {
        let (mut lo, mut hi) = (T::zero(), i_max);
        for _ in 0..BISECT {
            let mid = (lo + hi) * t::<T>(0.5);
            if self.best_at_magnitude(mid).0 < torque {
                lo = mid;
            } else {
                hi = mid;
            }
        }
        let (_, beta) = self.best_at_magnitude(hi);
        let (s, c) = beta.sin_cos_angle();
        (-hi * s, hi * c)
    }

    /// The q current (>= 0) that makes `torque` with the d current `i_d`: bisection on
    /// `[0, i_hi]` (`i_hi` when even that is too little).
    pub fn iq_for_torque(&self, i_d: T, torque: T, i_hi: T) -> T {
        let (mut lo, mut hi) = (T::zero(), i_hi);
        if self.torque(i_d, hi) <= torque {
            return hi;
        }
        for _ in 0..BISECT {
            let mid = (lo + hi) * t::<T>(0.5);
            if self.torque(i_d, mid) < torque {
                lo = mid;
            } else {
                hi = mid;
            }
        }
        hi
    }

    /// The current vector of least magnitude that makes `torque` (N m, > 0) with the flux
    /// magnitude at most `psi_lim` (Wb), searched for `i_d` in `[-i_max, i_max]` (module
    /// docs); `None` when no point of the constant-torque curve has so little flux.
    pub fn weakened(&self, torque: T, psi_lim: T, i_max: T) -> Option<(T, T)> {
        let i_hi = i_max * t::<T>(4.0);
        let iq = |d: T| self.iq_for_torque(d, torque, i_hi);
        let mag2 = |d: T| {
            let q = iq(d);
            d * d + q * q
        };
        let flux = |d: T| self.flux(d, iq(d));
        // MTPA along the curve: least magnitude.
        let d_m = golden_max(-i_max, i_max, |d| -mag2(d));
        if flux(d_m) <= psi_lim {
            return Some((d_m, iq(d_m)));
        }
        // Maximum torque per volt: least flux toward negative i_d.
        let d_v = golden_max(-i_max, d_m, |d| -flux(d));
        if flux(d_v) > psi_lim {
            return None;
        }
        let (mut lo, mut hi) = (d_v, d_m);
        for _ in 0..BISECT {
            let mid = (lo + hi) * t::<T>(0.5);
            if flux(mid) > psi_lim {
                hi = mid;
            } else {
                lo = mid;
            }
        }
        Some((lo, iq(lo)))
    }
}

/// The argument of the maximum of a unimodal `g` on `[a, b]` by golden section.
pub(super) fn golden_max<T: Float>(a: T, b: T, g: impl Fn(T) -> T) -> T {
    let r = t::<T>(0.618_034);
    let (mut a, mut b) = (a, b);
    let mut c = b - r * (b - a);
    let mut d = a + r * (b - a);
    let (mut gc, mut gd) = (g(c), g(d));
    for _ in 0..GOLDEN {
        if gc > gd {
            b = d;
            d = c;
            gd = gc;
            c = b - r * (b - a);
            gc = g(c);
        } else {
            a = c;
            c = d;
            gc = gd;
            d = a + r * (b - a);
            gd = g(d);
        }
    }
    (a + b) * t::<T>(0.5)
}
