//! The observer behind `Ekf` and its rows: the filter in the precision the user chose
//! ([`Observer`]), the output values of an estimate ([`OUTPUTS`]), one step as a row, and the
//! loop of `run` over a block of rows into output [`Columns`] (the arrays, written in place). [`Filter`] is the filter with
//! the voltage that predicts the first row of its next `run`, behind `Ekf`'s lock.

use std::sync::{Mutex, PoisonError};

use ekf_core::nalgebra::{Matrix4, Vector4};
use ekf_core::saturated::MapObserver;
use ekf_core::{EkfError, Estimate, Float, PmsmObserver};
use pyo3::prelude::*;

use crate::motor::MAP_POINTS;

use crate::status::RowStatus;

/// The observer in the precision the user chose, on constant parameters or on a flux map.
#[derive(Clone)]
// One per `Ekf` object, behind its lock; boxing the larger variant would buy nothing.
#[allow(clippy::large_enum_variant)]
pub(crate) enum Observer {
    /// A `float64` filter.
    F64(PmsmObserver<f64>),
    /// A `float32` filter.
    F32(PmsmObserver<f32>),
    /// A `float64` filter on a flux map.
    MapF64(Box<MapObserver<f64, MAP_POINTS>>),
    /// A `float32` filter on a flux map.
    MapF32(Box<MapObserver<f32, MAP_POINTS>>),
}

/// Runs `$body` with `$o` bound to the observer inside `$obs` (a `&mut Observer` or
/// `&Observer`), whichever its kind: one generic body for the four.
macro_rules! each_observer {
    ($obs:expr, $o:ident => $body:expr) => {
        match $obs {
            $crate::observer::Observer::F64($o) => $body,
            $crate::observer::Observer::F32($o) => $body,
            $crate::observer::Observer::MapF64($o) => $body,
            $crate::observer::Observer::MapF32($o) => $body,
        }
    };
}
pub(crate) use each_observer;

/// What the loops need of an observer: [`PmsmObserver`] and [`MapObserver`] alike.
pub(crate) trait Steps<T: Float> {
    /// One sample.
    fn step(&mut self, u: [T; 2], i: [T; 2]) -> Result<Estimate<T>, EkfError>;
    /// One sample over a period of `dt`.
    fn step_dt(&mut self, u: [T; 2], i: [T; 2], dt: T) -> Result<Estimate<T>, EkfError>;
    /// The current estimate.
    fn estimate(&self) -> Estimate<T>;
    /// The state.
    fn state(&self) -> Vector4<T>;
    /// The covariance.
    fn covariance(&self) -> Matrix4<T>;
    /// Replaces state and covariance.
    fn reset(&mut self, x: Vector4<T>, p: Matrix4<T>) -> Result<(), EkfError>;
}

impl<T: Float> Steps<T> for PmsmObserver<T> {
    #[inline(always)]
    fn step(&mut self, u: [T; 2], i: [T; 2]) -> Result<Estimate<T>, EkfError> {
        PmsmObserver::step(self, u, i)
    }
    fn step_dt(&mut self, u: [T; 2], i: [T; 2], dt: T) -> Result<Estimate<T>, EkfError> {
        PmsmObserver::step_dt(self, u, i, dt)
    }
    fn estimate(&self) -> Estimate<T> {
        PmsmObserver::estimate(self)
    }
    fn state(&self) -> Vector4<T> {
        *PmsmObserver::state(self)
    }
    fn covariance(&self) -> Matrix4<T> {
        PmsmObserver::covariance(self)
    }
    fn reset(&mut self, x: Vector4<T>, p: Matrix4<T>) -> Result<(), EkfError> {
        PmsmObserver::reset(self, x, p)
    }
}

impl<T: Float, const N: usize> Steps<T> for Box<MapObserver<T, N>> {
    #[inline(always)]
    fn step(&mut self, u: [T; 2], i: [T; 2]) -> Result<Estimate<T>, EkfError> {
        MapObserver::step(self, u, i)
    }
    fn step_dt(&mut self, u: [T; 2], i: [T; 2], dt: T) -> Result<Estimate<T>, EkfError> {
        MapObserver::step_dt(self, u, i, dt)
    }
    fn estimate(&self) -> Estimate<T> {
        MapObserver::estimate(self)
    }
    fn state(&self) -> Vector4<T> {
        *self.observer().state()
    }
    fn covariance(&self) -> Matrix4<T> {
        self.observer().covariance()
    }
    fn reset(&mut self, x: Vector4<T>, p: Matrix4<T>) -> Result<(), EkfError> {
        MapObserver::reset(self, x, p)
    }
}

/// The float outputs of `run` (one `(N,)` float64 array each) and `step` (one float each),
/// by name; [`outputs`] gives their values in the same order. Adding an output is one name
/// here and one value there (and a line in the stub, `python/pyfoc/__init__.pyi`).
pub(crate) const OUTPUTS: [&str; 9] = [
    "theta",
    "omega",
    "omega_mech",
    "i_alpha",
    "i_beta",
    "nis",
    "psi_f",
    "rs",
    "winding_temperature",
];

/// The values of [`OUTPUTS`] for an estimate, in the filter's precision.
pub(crate) fn outputs<T: Float>(e: &Estimate<T>) -> [T; OUTPUTS.len()] {
    [
        e.theta_rad,
        e.omega_e_rad_s,
        e.omega_mech_rad_s,
        e.i_alpha_a,
        e.i_beta_a,
        e.nis,
        e.psi_f_wb,
        e.rs_ohm,
        e.winding_temperature_c,
    ]
}

/// One output row.
#[derive(Clone, Copy)]
pub(crate) struct Row {
    pub(crate) values: [f64; OUTPUTS.len()],
    pub(crate) status: RowStatus,
}

impl Observer {
    /// One step; a refused sample yields the unchanged estimate with the rejected status.
    pub(crate) fn step(&mut self, u: [f64; 2], i: [f64; 2]) -> Row {
        each_observer!(self, o => step_row(o, u, i))
    }

    /// `run`'s loop: row `k` predicts with the voltage of row `k - 1` (`prev` for row 0) and
    /// corrects with the currents of row `k`; returns the last row's voltage. One dispatch on
    /// the precision per call, so the loop itself is the observer's step and the stores.
    pub(crate) fn run(
        &mut self,
        prev: [f64; 2],
        u: &[f64],
        i: &[f64],
        cols: &mut Columns,
    ) -> [f64; 2] {
        match self {
            Observer::F64(o) => run_rows::<f64, _, false>(o, prev, u, i, cols),
            Observer::F32(o) => run_rows::<f32, _, true>(o, prev, u, i, cols),
            Observer::MapF64(o) => run_rows::<f64, _, false>(o, prev, u, i, cols),
            Observer::MapF32(o) => run_rows::<f32, _, true>(o, prev, u, i, cols),
        }
    }

    pub(crate) fn state(&self) -> [f64; 4] {
        each_observer!(self, o => Steps::state(o).map(f64::from).into())
    }

    pub(crate) fn covariance(&self) -> [[f64; 4]; 4] {
        let m: Matrix4<f64> = each_observer!(self, o => Steps::covariance(o).map(f64::from));
        core::array::from_fn(|r| core::array::from_fn(|c| m[(r, c)]))
    }
}

/// One step of a filter in either precision: the output values in its precision and the
/// status.
#[inline(always)]
fn step_values<T: Float, O: Steps<T>>(
    o: &mut O,
    u: [f64; 2],
    i: [f64; 2],
) -> ([T; OUTPUTS.len()], RowStatus) {
    let c = |v: f64| T::from_subset(&v);
    match o.step(u.map(c), i.map(c)) {
        Ok(e) => (outputs(&e), RowStatus::of(e.status)),
        Err(_) => (outputs(&o.estimate()), RowStatus::Rejected),
    }
}

/// One step of a filter in either precision, as an output row.
#[inline(always)]
fn step_row<T: Float + Into<f64>, O: Steps<T>>(o: &mut O, u: [f64; 2], i: [f64; 2]) -> Row {
    let (values, status) = step_values(o, u, i);
    Row {
        values: values.map(Into::into),
        status,
    }
}

/// Rows that `run`'s loop filters into a buffer before writing them to the columns.
const BLOCK_ROWS: usize = 64;
/// Input values of a block (two a row).
const BLOCK_INPUTS: usize = 2 * BLOCK_ROWS;

/// [`Observer::run`] for one precision. `BLOCKED` (the `f32` filter): whole blocks of
/// [`BLOCK_ROWS`] rows are filtered into a buffer in the filter's precision, which stays in
/// the L1 cache, and each column's block is then converted to `f64` and stored in one pass
/// (vectorized conversions, contiguous stores); the other rows are written one by one. The
/// same rows either way. Buffering pays only where there is a conversion: `f32` runs about
/// 3 % faster buffered, `f64` (nothing to convert) gains nothing and stays direct.
fn run_rows<T: Float + Into<f64>, O: Steps<T>, const BLOCKED: bool>(
    o: &mut O,
    mut prev: [f64; 2],
    u: &[f64],
    i: &[f64],
    cols: &mut Columns,
) -> [f64; 2] {
    // The inputs and every column cut to the rows filtered here (`run` gives all of them
    // one length), so that the loop's stores need no bounds check of their own: ten per
    // row otherwise.
    let n = cols.values.iter().map(|c| c.len()).fold(
        cols.status.len().min(u.len() / 2).min(i.len() / 2),
        usize::min,
    );
    let (u, i) = (&u[..2 * n], &i[..2 * n]);
    let mut values = cols.values.each_mut().map(|c| &mut c[..n]);
    let status = &mut cols.status[..n];
    // Whole blocks (`BLOCKED`) through the buffer, then the other rows one by one.
    let whole = if BLOCKED { n / BLOCK_ROWS } else { 0 };
    if BLOCKED {
        let (u_blocks, _) = u[..2 * whole * BLOCK_ROWS].as_chunks::<BLOCK_INPUTS>();
        let (i_blocks, _) = i[..2 * whole * BLOCK_ROWS].as_chunks::<BLOCK_INPUTS>();
        let mut buf = [[T::zero(); BLOCK_ROWS]; OUTPUTS.len()];
        let mut status_buf = [0i8; BLOCK_ROWS];
        for (b, (ub, ib)) in u_blocks.iter().zip(i_blocks).enumerate() {
            for k in 0..BLOCK_ROWS {
                let (v, st) = step_values(o, prev, [ib[2 * k], ib[2 * k + 1]]);
                for (col, x) in buf.iter_mut().zip(v) {
                    col[k] = x;
                }
                status_buf[k] = st as i8;
                prev = [ub[2 * k], ub[2 * k + 1]];
            }
            let rows = b * BLOCK_ROWS..(b + 1) * BLOCK_ROWS;
            for (col, from) in values.iter_mut().zip(&buf) {
                for (d, x) in col[rows.clone()].iter_mut().zip(from) {
                    *d = (*x).into();
                }
            }
            status[rows].copy_from_slice(&status_buf);
        }
    }
    for k in whole * BLOCK_ROWS..n {
        let r = step_row(o, prev, [i[2 * k], i[2 * k + 1]]);
        for (col, v) in values.iter_mut().zip(r.values) {
            col[k] = v;
        }
        status[k] = r.status as i8;
        prev = [u[2 * k], u[2 * k + 1]];
    }
    prev
}

/// The filter of an `Ekf` and the voltage for its next `run` (the mutable part of an `Ekf`,
/// behind its lock).
pub(crate) struct Filter {
    /// The observer.
    pub(crate) observer: Observer,
    /// Voltage used to predict the first row of the next `run`.
    pub(crate) u_last: [f64; 2],
    /// No row has been filtered yet: the first `run` primes the online input calibration
    /// with its record ([`Observer::prime`]).
    pub(crate) fresh: bool,
}

impl Filter {
    /// Runs `f` on the filter behind `lock` with the GIL released and the lock held (a panic
    /// in another call cannot leave the filter half-updated: its steps commit whole, so a
    /// poisoned lock is taken over).
    pub(crate) fn with<R: Send>(
        lock: &Mutex<Filter>,
        py: Python<'_>,
        f: impl FnOnce(&mut Filter) -> R + Send,
    ) -> R {
        py.detach(|| {
            let mut guard = lock.lock().unwrap_or_else(PoisonError::into_inner);
            f(&mut guard)
        })
    }
}

/// Output columns of `run`, written in place: one slice per [`OUTPUTS`] name, and the status
/// codes, all of one length: the rows of the `(len(OUTPUTS), N)` array and the status array
/// `run` has just allocated through numpy (which asks the kernel for 2 MiB pages for large
/// arrays: the first write to 73 bytes per row of fresh memory, the kernel zeroing it, is
/// the largest cost of `run` after the steps themselves), or a caller's `out` arrays.
pub(crate) struct Columns<'a> {
    /// One slice per [`OUTPUTS`] name.
    pub(crate) values: [&'a mut [f64]; OUTPUTS.len()],
    /// The status codes.
    pub(crate) status: &'a mut [i8],
}

impl Columns<'_> {
    /// Bytes per row.
    pub(crate) const ROW_BYTES: u128 = (OUTPUTS.len() * 8 + 1) as u128;
}

impl<'a> Columns<'a> {
    /// Rows.
    pub(crate) fn len(&self) -> usize {
        self.status.len()
    }
}
