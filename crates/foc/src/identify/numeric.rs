//! Small numerical helpers of the identification: window sums, durations in ticks, `ln`, the
//! measured currents less their offsets, the voltage limit before the modulator.

use crate::controller::PhaseCurrents;
use crate::svpwm::{Modulation, svpwm};
use crate::transforms::AlphaBeta;
use crate::trig::sqrt;

/// `1 / sqrt(3)`.
pub(super) const INV_SQRT3: f32 = 0.577_350_26;

/// The measured currents in alpha-beta less the offsets `o` (A; two phases: `i_a`, `i_b` of the
/// amplitude-invariant Clarke transform, or alpha and beta as measured).
#[inline(always)]
pub(super) fn less_offsets(currents: PhaseCurrents, o: [f32; 2]) -> AlphaBeta {
    match currents {
        PhaseCurrents::Abc(a) => {
            let (ia, ib) = (a.a - o[0], a.b - o[1]);
            AlphaBeta {
                alpha: ia,
                beta: (ia + 2.0 * ib) * INV_SQRT3,
            }
        }
        PhaseCurrents::AlphaBeta(ab) => AlphaBeta {
            alpha: ab.alpha - o[0],
            beta: ab.beta - o[1],
        },
    }
}

/// `u` limited to the circle of radius `u_lim` (V), then the modulator (the hexagon at `u_dc`
/// holds the circle).
#[inline(always)]
pub(super) fn limited_svpwm(u: AlphaBeta, u_lim: f32, u_dc: f32) -> Modulation {
    let mag2 = u.norm_squared();
    let u = if mag2 > u_lim * u_lim {
        u * (u_lim / sqrt(mag2))
    } else {
        u
    };
    svpwm(u, u_dc)
}

const LN_2: f32 = core::f32::consts::LN_2;

/// Running sums over a window.
#[derive(Clone, Copy, Debug, Default, PartialEq)]
pub(super) struct Sums {
    /// Rows summed.
    pub(super) n: u32,
    /// The sums.
    pub(super) s: [f32; 4],
}

impl Sums {
    /// Adds a row.
    #[inline]
    pub(super) fn add(&mut self, v: [f32; 4]) {
        self.n += 1;
        for (a, b) in self.s.iter_mut().zip(v) {
            *a += b;
        }
    }

    /// The means (zero when empty).
    #[inline]
    pub(super) fn mean(&self) -> [f32; 4] {
        let k = if self.n > 0 { 1.0 / self.n as f32 } else { 0.0 };
        self.s.map(|x| x * k)
    }
}

/// `round(t / ts)` ticks, at least 1, saturating.
#[inline]
pub(super) fn ticks(t: f32, ts: f32) -> u32 {
    let x = t / ts + 0.5;
    if x.is_finite() && x >= 1.0 {
        if x < 4.0e9 { x as u32 } else { u32::MAX / 2 }
    } else {
        1
    }
}

/// Natural logarithm of a finite positive `x` (pure `f32`, relative error about 1e-7;
/// exact in relative terms near 1, where the inductance formula needs it).
#[inline]
pub fn ln(x: f32) -> f32 {
    if !(x.is_finite() && x > 1e-30) {
        return f32::NAN;
    }
    let bits = x.to_bits();
    let mut e = ((bits >> 23) & 0xff) as i32 - 127;
    let mut m = f32::from_bits((bits & 0x007f_ffff) | 0x3f80_0000);
    if m > core::f32::consts::SQRT_2 {
        m *= 0.5;
        e += 1;
    }
    let y = (m - 1.0) / (m + 1.0);
    let y2 = y * y;
    let s = y * (2.0 + y2 * (2.0 / 3.0 + y2 * (0.4 + y2 * (2.0 / 7.0 + y2 * (2.0 / 9.0)))));
    s + e as f32 * LN_2
}
