//! Small numerical helpers of the identification: window sums, durations in ticks, `ln`.

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
