//! Sine and cosine for the filter's angles, in the filter's own precision.
//!
//! Without `std`, `f32::sin_cos` in `nalgebra` goes to `libm::sincosf`, which computes in `f64`
//! (musl's design): on a Cortex-M4F, whose FPU is single precision only, that is software
//! floating point, about 2250 instructions per call. [`sin_cos_f32`] stays in `f32`, with no
//! branch for `|x| <= 32` (the observer's angles are wrapped to `[-pi, pi)`), from a table of
//! accurate values (Gal's method) and short corrections:
//!
//! ```text
//! j = round(x 16/pi)  (adding 2^23 + 164: the sum's bits minus those of 2^23 are j + 164, the
//!                      row of a 329-row table, j = -164 ..= 164; out of it = far path)
//! row j: hi, sin hi, cos hi   hi an f32 within 4e-4 of j pi/16 chosen so that its sine and
//!                             cosine are within 2.5e-9 of f32 values (scripts/gen-trig-table.py)
//! r = x - hi                  exact in f32;  |r| <= pi/32 + 4e-4
//! sin r     = r + S1 r^3               minimax, truncation 1.0e-8
//! cos r - 1 = r^2 (-1/2 + C2 r^2)      minimax, truncation 1.4e-10
//! sin x = sin hi + (sin hi (cos r - 1) + cos hi sin r)
//! cos x = cos hi + (cos hi (cos r - 1) - sin hi sin r)
//! ```
//!
//! The index computed from the rounding sum is also the range check (one unsigned comparison,
//! false for NaN, infinities and `|x|` beyond 32.3). The corrections are below 0.1, so the
//! error is essentially the final addition's rounding: maximum error against `f64` sin/cos
//! 4.89e-8 (0.8 ulp of 1) over every `f32` of `[-32, 32]` (`tests::exhaustive_max_error`,
//! ignored by default; 4.66e-8 on the dense grids of `tests::matches_f64_within_4_9e_8`), and
//! `|s^2 + c^2 - 1| <= 1.02e-7` there; the quarter-turn kernel this replaces (Cody-Waite reduction to `[-pi/4, pi/4]`,
//! degree 7 / 8 minimax kernels, rotation by the quadrant) had 8.6e-8. Larger arguments are
//! wrapped to `[-pi, pi)` first (a cold path). A non-finite argument gives NaN (the filter then
//! rejects the step); nothing panics. The table takes 5.3 KB of flash (16-byte rows: the index
//! is one shift).
//!
//! Cost on the Cortex-M4F (`cargo bench -p benches --bench cortex_m4`, line `sin_cos_f32`): 32
//! instructions; the measuring closure's path runs 35 (the meter subtracts its own
//! frame): 2 constant loads and one multiply-add for `j`, 4 integer instructions for the index
//! and the range check, 3 for the row's address, 3 loads of the row, 1 subtraction, 2
//! multiplies for `r^2`, `r^3`, 2 for `sin r` (a load, a multiply-add), 4 for `cos r - 1` (a
//! load, an immediate, a multiply-add, a multiply), 6 for the two results; the closure's frame
//! (the far path is a call), argument load and result store are the other 7.

use crate::{Float, to_t, wrap_angle};

mod table;

/// Kernels on `|r| <= pi/32 + 4e-4` (minimax, coefficients as rounded to `f32`):
/// `sin r = r + S1 r^3` (truncation 1.0e-8) and `cos r - 1 = r^2 (-1/2 + C2 r^2)` (1.4e-10).
const S1: f32 = -0.166_596_31;
const C2: f32 = 0.041_654_6;

/// `2^23 + OFFSET`: `q + ROUND` (`q = x 16/pi`, `q > -OFFSET - 1/2`) rounds `q` to the nearest
/// integer `j` (ties to even) and holds `j + OFFSET` in the low bits of the sum:
/// `bits - 0x4B00_0000` is the row.
const ROUND: f32 = 8_388_608.0 + table::OFFSET as f32;
/// `f32` bits of `2^23`.
const ROUND_BASE_BITS: u32 = 0x4B00_0000;

/// The rows `[hi, sin hi, cos hi, 0]`, `hi` within 4e-4 of `j pi/16` (module `table`).
static ROWS: [[f32; 4]; table::ROW_BITS.len()] = rows();

const fn rows() -> [[f32; 4]; table::ROW_BITS.len()] {
    let mut out = [[0.0; 4]; table::ROW_BITS.len()];
    let mut i = 0;
    while i < out.len() {
        let b = table::ROW_BITS[i];
        out[i] = [
            f32::from_bits(b[0]),
            f32::from_bits(b[1]),
            f32::from_bits(b[2]),
            0.0,
        ];
        i += 1;
    }
    out
}

/// The row of `x`: `None` beyond `|x| = 32.3` or so (out of the table) and for NaN and
/// infinities.
#[inline(always)]
fn row_of(x: f32) -> Option<&'static [f32; 4]> {
    let t = x * (16.0 / core::f32::consts::PI) + ROUND;
    ROWS.get(t.to_bits().wrapping_sub(ROUND_BASE_BITS) as usize)
}

/// `(sin x, cos x)` in pure `f32` arithmetic (module docs give method and error).
#[inline]
pub fn sin_cos_f32(x: f32) -> (f32, f32) {
    match row_of(x) {
        Some(row) => sin_cos_row(x, row),
        None => sin_cos_far(x),
    }
}

/// Large or non-finite arguments: wrapped to `[-pi, pi)` first; NaN for NaN and infinities.
#[cold]
#[inline(never)]
fn sin_cos_far(x: f32) -> (f32, f32) {
    if !x.is_finite() {
        return (f32::NAN, f32::NAN);
    }
    let w = wrap_angle(x);
    match row_of(w) {
        Some(row) => sin_cos_row(w, row),
        None => (f32::NAN, f32::NAN),
    }
}

/// The kernel for `x` in the table's range (module docs): no branch.
#[inline(always)]
fn sin_cos_row(x: f32, row: &[f32; 4]) -> (f32, f32) {
    let [hi, sh, ch, _] = *row;
    // Exact: x and hi are multiples of the smaller one's ulp, |r| is below both.
    let r = x - hi;
    let r2 = r * r;
    let s = r + (r * r2) * S1;
    let cm1 = r2 * (-0.5 + r2 * C2);
    // sin(hi + r) = sin hi + (sin hi (cos r - 1) + cos hi sin r), and likewise the cosine: the
    // corrections are below 0.1, so their rounding errors are small against the final one.
    (sh + (sh * cm1 + ch * s), ch + (ch * cm1 - sh * s))
}

/// `pi/2` in three parts for the `f64` reduction: the first two have 33 significant bits (so
/// `k * PIO2_1` and `k * PIO2_2` are exact for `|k| < 2^20`), the third is the rest rounded
/// to `f64` (`pi/2 - PIO2_1 - PIO2_2 - PIO2_3 = 1.0e-37`).
const PIO2_1: f64 = 1.570_796_326_734_125_6;
const PIO2_2: f64 = 6.077_100_506_303_966e-11;
const PIO2_3: f64 = 2.022_266_248_795_950_6e-21;

/// `1.5 * 2^52`: `q + ROUND_F64` rounds `q` (`|q| < 2^51`) to the nearest integer (ties to
/// even), held in the low bits of the sum's mantissa.
const ROUND_F64: f64 = 6_755_399_441_055_744.0;

/// `f64` bits of `|x| = 2^20` shifted left by one (the sign out): arguments up to this size
/// are reduced directly (`|k| < 2^20`), larger ones (and non-finite ones) go to the cold path.
const DIRECT_LIMIT_BITS_F64: u64 = 0x4130_0000_0000_0000 << 1;

/// `(cos k pi/2, sin k pi/2)` for `k mod 4` in `f64`.
const QUADRANT_F64: [(f64, f64); 4] = [(1.0, 0.0), (0.0, 1.0), (-1.0, 0.0), (0.0, -1.0)];

/// `(sin x, cos x)` in `f64`, inline and without a branch for `|x| <= 2^20` (the host's
/// [`Float::sin_cos_angle`] for `f64`; the library call it replaces clobbers every vector
/// register of the caller):
///
/// ```text
/// k = round(x 2/pi)                       (adding and subtracting 1.5 * 2^52)
/// r = x - k (P1 + P2 + P3)  as r_hi + r_lo  (k P1, k P2 exact; Fast2Sum)   |r| <= pi/4
/// sin r = r + r^3 (-1/3! + r^2 (1/5! + ... + r^2 / 17!)) + r_lo cos r    Taylor, truncation < 1e-19
/// cos r = 1 - r^2/2 + r^4 (1/4! + ... + r^12 / 16!) - r_lo r             Taylor, truncation < 3e-20
///         (1 - r^2/2 with its rounding error carried)
/// (sin x, cos x) = (sin r, cos r) rotated by k quarter turns (exact)
/// ```
///
/// Maximum error: below 1 ulp, like the standard library's (glibc's) `sin_cos`. Measured
/// against a 300-bit reference (mpmath, at 20 000 random points of `[-pi, pi]`, 5 000 of
/// `[-8 pi, 8 pi]` and 1 000 within 30 ulp of each `k pi/4`): 0.75 ulp for the sine and 0.74
/// ulp for the cosine, 8.4e-17 absolute (glibc's: 0.51 and 0.56 ulp, 5.6e-17); it differs
/// from the standard library's by at most 1.1e-16 (`tests::f64_matches_std`). A non-finite
/// argument gives NaN; larger arguments are wrapped to `[-pi, pi)` first (exactly).
#[inline(always)]
pub fn sin_cos_f64(x: f64) -> (f64, f64) {
    if x.to_bits() << 1 > DIRECT_LIMIT_BITS_F64 {
        return sin_cos_f64_far(x);
    }
    sin_cos_f64_reduced(x)
}

/// Large or non-finite `f64` arguments: wrapped to `[-pi, pi)` first; NaN for NaN and
/// infinities.
#[cold]
#[inline(never)]
fn sin_cos_f64_far(x: f64) -> (f64, f64) {
    if !x.is_finite() {
        return (f64::NAN, f64::NAN);
    }
    sin_cos_f64_reduced(wrap_angle(x))
}

/// The `f64` kernel for `|x| <= 2^20` ([`sin_cos_f64`]): no branch.
#[inline(always)]
fn sin_cos_f64_reduced(x: f64) -> (f64, f64) {
    let t = x * core::f64::consts::FRAC_2_PI + ROUND_F64;
    let kf = t - ROUND_F64;
    let quadrant = (t.to_bits() & 3) as usize;
    // x - k P1 is exact (k P1 is, and the difference is far smaller than x); k P2 is exact.
    let w1 = x - kf * PIO2_1;
    let w2 = kf * PIO2_2;
    let hi0 = w1 - w2;
    // Fast2Sum (|w1| >= |w2|): the rounding error of w1 - w2, then the third part.
    let lo0 = ((w1 - hi0) - w2) - kf * PIO2_3;
    let r = hi0 + lo0;
    let r_lo = (hi0 - r) + lo0;
    let z = r * r;
    let f = |n: f64| 1.0 / n;
    // Estrin's scheme (pairs, then pairs of pairs): a third of Horner's chain of dependent
    // operations, the same number of them.
    let z2 = z * z;
    let z4 = z2 * z2;
    let ps = z
        * ((-f(6.0) + z * f(120.0))
            + z2 * (-f(5040.0) + z * f(362_880.0))
            + z4 * ((-f(39_916_800.0) + z * f(6_227_020_800.0))
                + z2 * (-f(1_307_674_368_000.0) + z * f(355_687_428_096_000.0))));
    let s = r + (r * ps + (r_lo - r_lo * (0.5 * z)));
    let pc = z2
        * ((f(24.0) + z * -f(720.0))
            + z2 * (f(40_320.0) + z * -f(3_628_800.0))
            + z4 * ((f(479_001_600.0) + z * -f(87_178_291_200.0)) + z2 * f(20_922_789_888_000.0)));
    let hz = 0.5 * z;
    let w = 1.0 - hz;
    let c = w + (((1.0 - w) - hz) + (pc - r * r_lo));
    let (qc, qs) = QUADRANT_F64[quadrant];
    (s * qc + c * qs, c * qc - s * qs)
}

/// `(sin x, cos x)` for a small angle (a half-step rotation `w Ts / 2`, an inverse-Park advance
/// `1.5 w Ts`): Taylor series in `x^2` for `|x| < 0.5`, no range reduction;
/// [`Float::sin_cos_angle`] otherwise. In `f64` the series runs through `x^15` / `x^16`
/// (truncation below 3e-20); in `f32` through `x^7` / `x^8` (below 6e-9, under `f32` rounding).
/// A NaN argument gives NaN.
#[inline(always)]
pub fn sin_cos_small<T: Float>(x: T) -> (T, T) {
    if x.abs() >= to_t(0.5) {
        return x.sin_cos_angle();
    }
    let x2 = x * x;
    let c = |v: f64| -> T { to_t(v) };
    if T::default_epsilon() > to_t(1e-10) {
        // Single precision: Horner through x^7 / x^8 (the Cortex-M4F's code, unchanged).
        let s =
            x * (T::one() + x2 * (c(-1.0 / 6.0) + x2 * (c(1.0 / 120.0) + x2 * c(-1.0 / 5040.0))));
        let co = T::one()
            + x2 * (c(-0.5)
                + x2 * (c(1.0 / 24.0) + x2 * (c(-1.0 / 720.0) + x2 * c(1.0 / 40_320.0))));
        return (s, co);
    }
    // Double precision, through x^15 / x^16: Estrin's scheme in x^2 (pairs, then pairs of
    // pairs), a third of Horner's chain of dependent operations; coefficients
    // (-1)^n / (2n+1)! and (-1)^n / (2n)!.
    let x4 = x2 * x2;
    let x8 = x4 * x4;
    let s = x
        * (((T::one() + x2 * c(-1.0 / 6.0)) + x4 * (c(1.0 / 120.0) + x2 * c(-1.0 / 5040.0)))
            + x8 * ((c(1.0 / 362_880.0) + x2 * c(-1.0 / 39_916_800.0))
                + x4 * (c(1.0 / 6_227_020_800.0) + x2 * c(-1.0 / 1_307_674_368_000.0))));
    let co = ((T::one() + x2 * c(-0.5)) + x4 * (c(1.0 / 24.0) + x2 * c(-1.0 / 720.0)))
        + x8 * ((c(1.0 / 40_320.0) + x2 * c(-1.0 / 3_628_800.0))
            + x4 * (c(1.0 / 479_001_600.0) + x2 * c(-1.0 / 87_178_291_200.0)))
        + (x8 * x8) * c(1.0 / 20_922_789_888_000.0);
    (s, co)
}

#[cfg(test)]
mod tests {
    use super::sin_cos_f32;

    #[test]
    fn matches_f64_within_4_9e_8_on_8_pi() {
        let mut worst = 0.0f64;
        for i in -200_000..=200_000 {
            let x = i as f32 * (8.0 * core::f32::consts::PI / 200_000.0);
            let (s, c) = sin_cos_f32(x);
            let xd = f64::from(x);
            worst = worst
                .max((f64::from(s) - xd.sin()).abs())
                .max((f64::from(c) - xd.cos()).abs());
        }
        assert!(worst < 4.9e-8, "max error {worst:e}");
        // Large arguments are wrapped first; results stay on the unit circle.
        for x in [1e3f32, -7.7e4, 3.0e7, f32::MAX] {
            let (s, c) = sin_cos_f32(x);
            assert!((s * s + c * c - 1.0).abs() < 1e-6, "{x}: {s} {c}");
        }
        assert!(sin_cos_f32(f32::NAN).0.is_nan());
    }

    /// Max abs error against `f64` on dense grids: `[-pi, pi]` (the observer's angles, 2 * 10^6
    /// points) and the whole direct range `[-32, 32]` (4 * 10^6 points), also on the unit
    /// circle; plus every `f32` near the quadrant boundaries `k pi/4`.
    #[test]
    fn matches_f64_within_4_9e_8() {
        let err = |x: f32| {
            let (s, c) = sin_cos_f32(x);
            let xd = f64::from(x);
            let e = (f64::from(s) - xd.sin())
                .abs()
                .max((f64::from(c) - xd.cos()).abs());
            let norm = (f64::from(s).powi(2) + f64::from(c).powi(2) - 1.0).abs();
            (e, norm)
        };
        let mut worst = (0.0f64, 0.0f64);
        let mut take = |x: f32| {
            let (e, n) = err(x);
            worst = (worst.0.max(e), worst.1.max(n));
        };
        for i in -1_000_000..=1_000_000 {
            take(i as f32 * (core::f32::consts::PI / 1_000_000.0));
        }
        for i in -2_000_000..=2_000_000 {
            take(i as f32 * (32.0 / 2_000_000.0));
        }
        for k in -40..=40 {
            let mut x = k as f32 * core::f32::consts::FRAC_PI_4;
            for _ in 0..64 {
                x = x.next_down();
            }
            for _ in 0..128 {
                take(x);
                x = x.next_up();
            }
        }
        // The table's row boundaries (j + 1/2) pi/16.
        for j in -163..163 {
            let mut x = ((f64::from(j) + 0.5) * core::f64::consts::PI / 16.0) as f32;
            for _ in 0..64 {
                x = x.next_down();
            }
            for _ in 0..128 {
                take(x);
                x = x.next_up();
            }
        }
        println!(
            "sin_cos_f32: max abs error {:e}, max |s^2 + c^2 - 1| {:e}",
            worst.0, worst.1
        );
        assert!(worst.0 < 4.9e-8, "max error {:e}", worst.0);
        assert!(worst.1 < 1.05e-7, "off the unit circle by {:e}", worst.1);
        // Non-finite in, NaN out (both); the far path wraps and keeps the accuracy.
        for x in [f32::NAN, f32::INFINITY, f32::NEG_INFINITY, -f32::NAN] {
            let (s, c) = sin_cos_f32(x);
            assert!(s.is_nan() && c.is_nan(), "{x}: {s} {c}");
        }
        for x in [32.5f32, -40.0, 1e4, -3.3e5] {
            let (s, c) = sin_cos_f32(x);
            let w = f64::from(super::wrap_angle(x));
            assert!((f64::from(s) - w.sin()).abs() < 4.9e-8, "{x}");
            assert!((f64::from(c) - w.cos()).abs() < 4.9e-8, "{x}");
        }
    }

    /// Every `f32` of `[-32, 32]` (about 2.2e9 arguments; a minute or two in release):
    /// `cargo test -p ekf-core --release --lib trig::tests::exhaustive -- --ignored --nocapture`.
    #[test]
    #[ignore = "exhaustive, slow"]
    fn exhaustive_max_error() {
        let mut worst = (0.0f64, 0.0f32);
        let mut x = 0.0f32;
        while x <= 32.0 {
            for v in [x, -x] {
                let (s, c) = sin_cos_f32(v);
                let (rs, rc) = f64::from(v).sin_cos();
                let e = (f64::from(s) - rs).abs().max((f64::from(c) - rc).abs());
                if e > worst.0 {
                    worst = (e, v);
                }
            }
            x = x.next_up();
        }
        println!(
            "sin_cos_f32 over every f32 of [-32, 32]: max abs error {:e} at {}",
            worst.0, worst.1
        );
        assert!(worst.0 < 4.9e-8, "max error {:e} at {}", worst.0, worst.1);
    }

    /// The table: `hi` within 4e-4 of `j pi/16`, its sine and cosine within 2.5e-9; the
    /// rounding sum picks the row of the nearest `j` up to the table's ends (every
    /// `|x| <= 32` in it, beyond `32.3` out of it), so `|r| = |x - hi| <= pi/32 + 4e-4` (the
    /// kernels' fitted range), and `x - hi` is exact (dense grid and every `f32` within 64
    /// ulp of each row's boundary `(j + 1/2) pi/16`).
    #[test]
    fn rows_and_range() {
        use super::{ROWS, row_of, table::OFFSET};
        let step = core::f64::consts::PI / 16.0;
        for (i, row) in ROWS.iter().enumerate() {
            let j = f64::from(i as i32 - OFFSET);
            let [hi, sh, ch, pad] = row.map(f64::from);
            assert!((hi - j * step).abs() <= 4e-4, "{j}: {hi}");
            assert!((hi.sin() - sh).abs() <= 2.5e-9, "{j}: sin {sh}");
            assert!((hi.cos() - ch).abs() <= 2.5e-9, "{j}: cos {ch}");
            assert_eq!(pad, 0.0);
        }
        assert_eq!(ROWS[OFFSET as usize], [0.0, 0.0, 1.0, 0.0]);
        let check = |x: f32| {
            let row = row_of(x).unwrap_or_else(|| panic!("{x} is in the table"));
            let hi = row[0];
            let r = f64::from(x) - f64::from(hi);
            assert!(
                r.abs() <= core::f64::consts::PI / 32.0 + 4.1e-4,
                "{x}: r {r}"
            );
            assert_eq!(f64::from(x - hi), r, "{x}: x - hi inexact");
        };
        for i in -3_200_000..=3_200_000 {
            check(i as f32 * 1e-5);
        }
        for j in -OFFSET..OFFSET {
            let mut x = ((f64::from(j) + 0.5) * step) as f32;
            for _ in 0..64 {
                x = x.next_down();
            }
            for _ in 0..128 {
                if x.abs() <= 32.0 {
                    check(x);
                }
                x = x.next_up();
            }
        }
        for x in [
            32.5f32,
            -32.5,
            1e9,
            -1e30,
            f32::MAX,
            f32::MIN,
            f32::INFINITY,
        ] {
            assert!(row_of(x).is_none(), "{x}");
        }
        assert!(row_of(f32::NAN).is_none() && row_of(-f32::NAN).is_none());
    }

    /// The `f64` kernel against the standard library's (itself within 1 ulp): at most one ulp
    /// apart (both within 1 ulp of the exact value) over `[-8 pi, 8 pi]` and near every
    /// `k pi/4`; the far path and non-finite arguments. (Against a 300-bit reference the
    /// kernel's error is at most 0.75 ulp on `[-pi, pi]`; module docs of `sin_cos_f64`.)
    #[test]
    fn f64_matches_std() {
        use super::sin_cos_f64;
        let mut worst_abs = 0.0f64;
        let mut worst_ulp = 0.0f64;
        let mut take = |x: f64| {
            let (s, c) = sin_cos_f64(x);
            let (rs, rc) = x.sin_cos();
            worst_abs = worst_abs.max((s - rs).abs()).max((c - rc).abs());
            // Relative to the larger of the two (near a zero the absolute error is what counts).
            let tol = |r: f64| f64::EPSILON * r.abs().max(1e-3);
            worst_ulp = worst_ulp
                .max((s - rs).abs() / tol(rs))
                .max((c - rc).abs() / tol(rc));
        };
        for i in -2_000_000..=2_000_000 {
            take(f64::from(i) * (8.0 * core::f64::consts::PI / 2_000_000.0));
        }
        for k in -40..=40 {
            let mut x = f64::from(k) * core::f64::consts::FRAC_PI_4;
            for _ in 0..64 {
                x = x.next_down();
            }
            for _ in 0..128 {
                take(x);
                x = x.next_up();
            }
        }
        println!("sin_cos_f64 vs std: max abs {worst_abs:e}, max {worst_ulp} eps (relative)");
        assert!(worst_abs <= 2.3e-16, "max abs difference {worst_abs:e}");
        assert!(worst_ulp <= 1.0, "max relative difference {worst_ulp} eps");
        for x in [f64::NAN, f64::INFINITY, f64::NEG_INFINITY] {
            let (s, c) = sin_cos_f64(x);
            assert!(s.is_nan() && c.is_nan(), "{x}: {s} {c}");
        }
        for x in [1.1e6f64, -3.3e9, 1e300, f64::MAX, 1048575.9] {
            let (s, c) = sin_cos_f64(x);
            let w = super::wrap_angle(x);
            let (rs, rc) = if x.abs() <= 1_048_576.0 {
                x.sin_cos()
            } else {
                w.sin_cos()
            };
            assert!(
                (s - rs).abs() < 1e-9 && (c - rc).abs() < 1e-9,
                "{x}: {s} {c}"
            );
            assert!((s * s + c * c - 1.0).abs() < 1e-15, "{x}");
        }
        assert_eq!(sin_cos_f64(0.0), (0.0, 1.0));
    }

    #[test]
    fn small_angle_series_matches_sin_cos() {
        let mut worst64 = 0.0f64;
        let mut worst32 = 0.0f64;
        for i in -1000..=1000 {
            let x = i as f64 * 7e-4; // up to +-0.7: series and fallback
            let (s, c) = super::sin_cos_small(x);
            worst64 = worst64.max((s - x.sin()).abs()).max((c - x.cos()).abs());
            let xf = x as f32;
            let (s, c) = super::sin_cos_small(xf);
            let xd = f64::from(xf);
            worst32 = worst32
                .max((f64::from(s) - xd.sin()).abs())
                .max((f64::from(c) - xd.cos()).abs());
        }
        assert!(worst64 < 4e-16, "f64 series error {worst64:e}");
        assert!(worst32 < 1.2e-7, "f32 series error {worst32:e}");
        assert!(super::sin_cos_small(f64::NAN).0.is_nan());
        assert!(sin_cos_f32(f32::INFINITY).1.is_nan());
    }
}
