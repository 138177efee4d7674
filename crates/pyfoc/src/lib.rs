//! Python bindings for the `ekf-core` observer and the `pmsm-sim` simulator.
//!
//! Thin by design: wrapper types and conversions only; every algorithm lives in the Rust
//! crates. Arrays in and out follow the project's timing convention: row `k` of `u_ab` is the
//! voltage held over `[t_k, t_k+1)`, row `k` of `i_ab` the currents sampled at `t_k`, and row
//! `k` of the output the estimate at `t_k` (predicted with `u_ab[k-1]`, corrected with
//! `i_ab[k]`).
#![forbid(unsafe_code)]
#![deny(missing_docs)]

use ekf_core::nalgebra::{Matrix2, Matrix4, Vector4};
use ekf_core::{
    CovarianceUpdate, Discretization, EkfError, Estimate, Float, MotorKind, MotorParams,
    ObserverConfig, PmsmObserver, RsTracking, Status,
};
use std::sync::{Mutex, PoisonError};

use numpy::{PyArray1, PyArray2, PyArrayMethods, PyUntypedArrayMethods};
use pyo3::create_exception;
use pyo3::exceptions::PyValueError;
use pyo3::prelude::*;
use pyo3::sync::PyOnceLock;
use pyo3::types::{PyDict, PyModule, PySlice};

mod convert;
mod drive;
mod identify;
mod pool;
mod replay;
mod simulate;
mod suite;
mod tune;

use convert::{contiguous, fixed, record_args, rows2, square, to_vec};

create_exception!(
    pyfoc,
    PyfocError,
    PyValueError,
    "Base class of pyfoc's errors (a ValueError)."
);
create_exception!(
    pyfoc,
    ConfigError,
    PyfocError,
    "Invalid motor or filter parameters; the message gives the reason."
);
create_exception!(
    pyfoc,
    SimulationError,
    PyfocError,
    "The simulator could not run the scenario (e.g. its controller could not be built)."
);
create_exception!(
    pyfoc,
    FilterError,
    PyfocError,
    "A filter operation was refused (e.g. a non-finite reset); the filter is unchanged."
);

/// The status of an output row: the members of the Python `IntEnum` `pyfoc.Status`, whose
/// values are the codes of `Ekf.run`'s int8 `status` array.
#[derive(Clone, Copy, PartialEq, Eq, Debug)]
#[repr(i8)]
enum RowStatus {
    /// The angle's standard deviation is below its limit.
    Tracking = 0,
    /// The filter ran but the angle is not trustworthy (not converged, standstill).
    Uncertain = 1,
    /// The sample was rejected (non-finite voltage or current); the state was kept.
    Rejected = 2,
}

impl RowStatus {
    /// Every member with its Python name, in value order.
    const MEMBERS: [(&'static str, RowStatus); 3] = [
        ("TRACKING", RowStatus::Tracking),
        ("UNCERTAIN", RowStatus::Uncertain),
        ("REJECTED", RowStatus::Rejected),
    ];

    /// The observer's status of an accepted sample.
    fn of(s: Status) -> Self {
        match s {
            Status::Tracking => RowStatus::Tracking,
            Status::Uncertain => RowStatus::Uncertain,
        }
    }

    /// `pyfoc.Status(self)`.
    fn to_py(self, py: Python<'_>) -> PyResult<Bound<'_, PyAny>> {
        static STATUS: PyOnceLock<Py<PyAny>> = PyOnceLock::new();
        STATUS.import(py, "pyfoc", "Status")?.call1((self as i8,))
    }

    /// The `IntEnum` class `pyfoc.Status`.
    fn py_class(py: Python<'_>) -> PyResult<Bound<'_, PyAny>> {
        let members: Vec<(&str, i8)> = Self::MEMBERS.iter().map(|&(n, s)| (n, s as i8)).collect();
        let kw = PyDict::new(py);
        kw.set_item("module", "pyfoc")?;
        let cls = py
            .import("enum")?
            .getattr("IntEnum")?
            .call(("Status", members), Some(&kw))?;
        cls.setattr(
            "__doc__",
            "Status of an estimate: the value of each row of `Ekf.run(...)[\"status\"]` (int8) \
             and the `status` of `Ekf.step`. TRACKING: the angle's standard deviation is below \
             its limit; UNCERTAIN: the filter ran but the angle is not trustworthy yet (not \
             converged, or near standstill); REJECTED: non-finite voltage or current, the sample \
             was refused and the state kept.",
        )?;
        Ok(cls)
    }
}

/// Motor parameters (SI): `Motor(rs, ls, psi_f, pole_pairs, *, ld=None, lq=None)`.
///
/// `ls` is the inductance of a surface PMSM (`Ld = Lq = ls`); `ld` / `lq` override it per
/// axis for an interior PMSM (`ls` may then be `None`, and reads back as `(ld + lq) / 2`).
#[pyclass(frozen, skip_from_py_object, module = "pyfoc")]
#[derive(Clone, Copy)]
struct Motor {
    #[pyo3(get)]
    rs: f64,
    #[pyo3(get)]
    ls: f64,
    #[pyo3(get)]
    psi_f: f64,
    #[pyo3(get)]
    pole_pairs: u32,
    #[pyo3(get)]
    ld: f64,
    #[pyo3(get)]
    lq: f64,
}

#[pymethods]
impl Motor {
    #[new]
    #[pyo3(signature = (rs, ls, psi_f, pole_pairs, *, ld = None, lq = None))]
    fn new(
        rs: f64,
        ls: Option<f64>,
        psi_f: f64,
        pole_pairs: i64,
        ld: Option<f64>,
        lq: Option<f64>,
    ) -> PyResult<Self> {
        let pole_pairs = u32::try_from(pole_pairs).map_err(|_| {
            ConfigError::new_err(format!("pole_pairs must be >= 1, got {pole_pairs}"))
        })?;
        let (ld, lq) = match (ld.or(ls), lq.or(ls)) {
            (Some(ld), Some(lq)) => (ld, lq),
            _ => {
                return Err(ConfigError::new_err(
                    "give ls (surface PMSM) or both ld and lq (interior PMSM)",
                ));
            }
        };
        let m = Self {
            rs,
            ls: ls.unwrap_or(0.5 * (ld + lq)),
            psi_f,
            pole_pairs,
            ld,
            lq,
        };
        if !(m.ls.is_finite() && m.ls > 0.0) {
            return Err(ConfigError::new_err(format!(
                "ls must be positive and finite, got {}",
                m.ls
            )));
        }
        m.params::<f64>()
            .validate()
            .map_err(|e| ConfigError::new_err(e.to_string()))?;
        Ok(m)
    }

    /// `"surface"`, `"interior"` (Lq > Ld) or `"inverse_salient"` (Lq < Ld: accepted, but
    /// check that Ld and Lq are not swapped).
    #[getter]
    fn kind(&self) -> &'static str {
        match self.params::<f64>().kind() {
            MotorKind::Surface => "surface",
            MotorKind::Interior => "interior",
            MotorKind::InverseSalient => "inverse_salient",
        }
    }

    fn __repr__(&self) -> String {
        format!(
            "Motor(rs={}, ls={}, psi_f={}, pole_pairs={}, ld={}, lq={})",
            self.rs, self.ls, self.psi_f, self.pole_pairs, self.ld, self.lq
        )
    }
}

impl Motor {
    fn params<T: Float>(&self) -> MotorParams<T> {
        MotorParams::salient_from_f64(self.rs, self.ld, self.lq, self.psi_f, self.pole_pairs)
    }
}

/// The observer in the precision the user chose.
#[derive(Clone)]
// One per `Ekf` object, behind its lock; boxing the larger variant would buy nothing.
#[allow(clippy::large_enum_variant)]
enum Observer {
    F64(PmsmObserver<f64>),
    F32(PmsmObserver<f32>),
}

/// The float outputs of `run` (one `(N,)` float64 array each) and `step` (one float each),
/// by name; [`outputs`] gives their values in the same order. Adding an output is one name
/// here and one value there (and a line in `pyfoc.pyi`).
const OUTPUTS: [&str; 9] = [
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
fn outputs<T: Float>(e: &Estimate<T>) -> [T; OUTPUTS.len()] {
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
struct Row {
    values: [f64; OUTPUTS.len()],
    status: RowStatus,
}

impl Observer {
    /// One step; a refused sample yields the unchanged estimate with the rejected status.
    fn step(&mut self, u: [f64; 2], i: [f64; 2]) -> Row {
        match self {
            Observer::F64(o) => step_row(o, u, i),
            Observer::F32(o) => step_row(o, u, i),
        }
    }

    /// `run`'s loop: row `k` predicts with the voltage of row `k - 1` (`prev` for row 0) and
    /// corrects with the currents of row `k`; returns the last row's voltage. One dispatch on
    /// the precision per call, so the loop itself is the observer's step and the stores.
    fn run(&mut self, prev: [f64; 2], u: &[f64], i: &[f64], cols: &mut Columns) -> [f64; 2] {
        match self {
            Observer::F64(o) => run_rows::<f64, false>(o, prev, u, i, cols),
            Observer::F32(o) => run_rows::<f32, true>(o, prev, u, i, cols),
        }
    }

    fn state(&self) -> [f64; 4] {
        match self {
            Observer::F64(o) => (*o.state()).into(),
            Observer::F32(o) => o.state().map(f64::from).into(),
        }
    }

    fn covariance(&self) -> [[f64; 4]; 4] {
        let m: Matrix4<f64> = match self {
            Observer::F64(o) => o.covariance(),
            Observer::F32(o) => o.covariance().map(f64::from),
        };
        core::array::from_fn(|r| core::array::from_fn(|c| m[(r, c)]))
    }
}

/// One step of a filter in either precision: the output values in its precision and the
/// status.
#[inline(always)]
fn step_values<T: Float>(
    o: &mut PmsmObserver<T>,
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
fn step_row<T: Float + Into<f64>>(o: &mut PmsmObserver<T>, u: [f64; 2], i: [f64; 2]) -> Row {
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
/// same rows either way. Measured in one process, alternating (`run / steps`, medians of 10,
/// two rounds on a quiet 2-core machine): `f32` one call 1.096 / 1.106 buffered against
/// 1.132 / 1.125 direct, streamed into `out=` 1.119 / 1.110 against 1.152 / 1.146; `f64`
/// (nothing to convert) 1.093 / 1.106 against 1.087 / 1.112, no gain: it stays direct.
fn run_rows<T: Float + Into<f64>, const BLOCKED: bool>(
    o: &mut PmsmObserver<T>,
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

/// Extended Kalman filter observer of a PMSM, surface or interior (active-flux model when
/// `ld != lq`; states `i_alpha, i_beta, omega_e, theta`).
///
/// `Ekf(motor, ts, *, q=None, r=None, x0=None, p0=None, discretization="lag_free",
/// dtype="float64", covariance_update="joseph")`.
///
/// Thread safety: the filter sits behind a lock that is taken with the GIL released, so
/// calls on one `Ekf` from several threads are serialized (each completes, in some order)
/// while other Python threads keep running.
#[pyclass(frozen, module = "pyfoc")]
struct Ekf {
    inner: Mutex<EkfInner>,
    /// Sample time, s.
    #[pyo3(get)]
    ts: f64,
    /// Precision of the filter, `"float64"` or `"float32"`.
    #[pyo3(get)]
    dtype: &'static str,
}

/// The mutable part of an [`Ekf`].
struct EkfInner {
    observer: Observer,
    /// Voltage used to predict the first row of the next `run`.
    u_last: [f64; 2],
}

impl Ekf {
    /// Runs `f` on the filter with the GIL released and the lock held (a panic in another
    /// call cannot leave the filter half-updated: its steps commit whole, so a poisoned lock
    /// is taken over).
    fn with<R: Send>(&self, py: Python<'_>, f: impl FnOnce(&mut EkfInner) -> R + Send) -> R {
        py.detach(|| {
            let mut guard = self.inner.lock().unwrap_or_else(PoisonError::into_inner);
            f(&mut guard)
        })
    }
}

/// Output columns of `run`, written in place: one slice per [`OUTPUTS`] name, and the status
/// codes, all of one length: the rows of the `(len(OUTPUTS), N)` array and the status array
/// `run` has just allocated through numpy (which asks the kernel for 2 MiB pages for large
/// arrays: the first write to 73 bytes per row of fresh memory, the kernel zeroing it, is
/// the largest cost of `run` after the steps themselves), or a caller's `out` arrays.
struct Columns<'a> {
    values: [&'a mut [f64]; OUTPUTS.len()],
    status: &'a mut [i8],
}

impl Columns<'_> {
    /// Bytes per row.
    const ROW_BYTES: u128 = (OUTPUTS.len() * 8 + 1) as u128;
}

impl<'a> Columns<'a> {
    /// Rows.
    fn len(&self) -> usize {
        self.status.len()
    }

    /// The first `k` rows (at most all of them) and the rest.
    fn split(self, k: usize) -> (Self, Self) {
        let k = k.min(self.len());
        let (s0, s1) = self.status.split_at_mut(k);
        let mut v0: [&'a mut [f64]; OUTPUTS.len()] = Default::default();
        let mut v1: [&'a mut [f64]; OUTPUTS.len()] = Default::default();
        for ((c, a), b) in self.values.into_iter().zip(&mut v0).zip(&mut v1) {
            (*a, *b) = c.split_at_mut(k.min(c.len()));
        }
        (
            Columns {
                values: v0,
                status: s0,
            },
            Columns {
                values: v1,
                status: s1,
            },
        )
    }

    /// Writes one value per 4 KiB page: the kernel maps (and zeroes) fresh pages on their
    /// first write. Only for the zero-filled arrays `run` allocates (the values written are
    /// zeros); the rows are written again by the filter afterwards.
    fn prefault(&mut self) {
        const PAGE: usize = 4096;
        for col in self.values.iter_mut() {
            for x in col.iter_mut().step_by(PAGE / 8) {
                *x = 0.0;
            }
        }
        for x in self.status.iter_mut().step_by(PAGE) {
            *x = 0;
        }
    }
}

/// Fewest rows for which `run` maps its fresh output pages on a second thread (below it the
/// thread costs more than it saves).
const PREFAULT_MIN_ROWS: usize = 1 << 16;
/// Rows per block handed from the page-mapping thread to the filter.
const PREFAULT_BLOCK_ROWS: usize = 1 << 14;

/// Where `run`'s loop writes its rows: straight into the columns, or into the blocks that
/// the page-mapping thread of [`map_ahead`] hands over in row order.
enum Sink<'a> {
    Direct(Columns<'a>),
    Mapped(std::sync::mpsc::Receiver<Columns<'a>>),
}

/// Starts the page-mapping thread on freshly allocated output columns: it takes the blocks
/// of rows in order, maps their pages (the page faults and the kernel's zeroing: about a
/// tenth of a step's time per row), and hands each block to the filter through a channel,
/// so each block is written by one thread at a time; the filter's results do not depend on
/// it. Started before the inputs are copied, it has mapped the first blocks when the filter
/// starts. Without a second thread (spawn refused) the columns are written directly.
fn map_ahead<'scope, 'a: 'scope>(
    s: &'scope std::thread::Scope<'scope, '_>,
    cols: Columns<'a>,
) -> Sink<'a> {
    use std::sync::mpsc::channel;
    let (to_mapper, whole) = channel::<Columns<'a>>();
    let (to_filter, mapped) = channel::<Columns<'a>>();
    let mapper = std::thread::Builder::new()
        .name("pyfoc-prefault".into())
        .spawn_scoped(s, move || {
            let Ok(mut rest) = whole.recv() else { return };
            while rest.len() > 0 {
                let (mut b, r) = rest.split(PREFAULT_BLOCK_ROWS);
                rest = r;
                b.prefault();
                if to_filter.send(b).is_err() {
                    return;
                }
            }
        });
    if mapper.is_err() {
        return Sink::Direct(cols);
    }
    // The mapper waits on this channel; a refused send gives the columns back.
    match to_mapper.send(cols) {
        Ok(()) => Sink::Mapped(mapped),
        Err(e) => Sink::Direct(e.0),
    }
}

/// `run`'s loop over the rows of `u`, `i` into `sink`; returns the last row's voltage.
fn run_sink(
    obs: &mut Observer,
    mut prev: [f64; 2],
    u: &[f64],
    i: &[f64],
    sink: Sink<'_>,
) -> [f64; 2] {
    match sink {
        Sink::Direct(mut cols) => obs.run(prev, u, i, &mut cols),
        Sink::Mapped(blocks) => {
            // Blocks arrive in row order; a panic of the mapper (it has no panicking
            // operation) would end the channel early and resurface from the thread scope.
            let mut k0 = 0;
            for mut b in blocks {
                let k1 = k0 + b.len();
                prev = obs.run(prev, &u[2 * k0..2 * k1], &i[2 * k0..2 * k1], &mut b);
                k0 = k1;
            }
            prev
        }
    }
}

/// A block of rows for [`run_pipelined`]'s filter: its inputs (copied) and output columns.
struct Block<'a> {
    /// The block's rows of `u_ab`, then those of `i_ab`.
    inputs: Vec<f64>,
    cols: Columns<'a>,
}

impl Block<'_> {
    /// Filters the block's rows from `prev`; returns the last row's voltage.
    fn run(&mut self, obs: &mut Observer, prev: [f64; 2]) -> [f64; 2] {
        let (u, i) = self.inputs.split_at(self.inputs.len() / 2);
        obs.run(prev, u, i, &mut self.cols)
    }

    /// The block, with the pages of its output columns mapped if `prefault` (fresh columns;
    /// reused ones are mapped already).
    fn mapped(mut self, prefault: bool) -> Self {
        if prefault {
            self.cols.prefault();
        }
        self
    }
}

/// [`run_pipelined`]'s helper copies and maps one block in this many (and two) first, and
/// hands them to the filter before it copies the others: enough rows to filter while it
/// copies the rest (a block's copy takes about a twentieth of its filtering).
const PIPELINE_LEAD_PER: usize = 8;

/// `run` over a long record on two threads. The inputs must be private copies before the
/// filter runs without the GIL (another Python thread could change the caller's arrays);
/// here a helper thread copies them block by block (into the [`pool`]'s spare vectors when
/// it has them), and maps the pages of the fresh output columns if `prefault` (zero-filled
/// arrays `run` has just allocated, not reused ones), while this thread, which holds the GIL
/// until the helper has copied the last block, already filters the first blocks. The GIL is
/// then released for the rest; the block vectors go back to the pool at the end. The lock of
/// the filter is taken without waiting: should another call hold it (or the helper not
/// start), the columns are returned untouched for the sequential path.
fn run_pipelined<'a>(
    py: Python<'_>,
    lock: &Mutex<EkfInner>,
    u: &convert::RealArray<'_>,
    i: &convert::RealArray<'_>,
    u_prev: Option<[f64; 2]>,
    cols: Columns<'a>,
    prefault: bool,
) -> Option<Columns<'a>> {
    use numpy::ndarray::{Axis, Slice};
    use std::sync::TryLockError;
    use std::sync::atomic::{AtomicBool, Ordering};
    use std::sync::mpsc::channel;
    let n = cols.len();
    let (Ok(u), Ok(i)) = (
        u.as_array().into_dimensionality::<numpy::Ix2>(),
        i.as_array().into_dimensionality::<numpy::Ix2>(),
    ) else {
        return Some(cols);
    };
    if u.nrows() != n || i.nrows() != n {
        return Some(cols);
    }
    // The copies, one vector per block (the rows of `u`, then those of `i`), taken here and
    // filled by the helper: the spare vectors of earlier calls first ([`pool`]: pages
    // already mapped), the others allocated fallibly (on failure the sequential path raises
    // MemoryError), whose fresh pages are faulted in on the helper's thread.
    let nblocks = n.div_ceil(PREFAULT_BLOCK_ROWS);
    let Some(bufs) = pool::take_blocks(nblocks, 4 * PREFAULT_BLOCK_ROWS.min(n)) else {
        return Some(cols);
    };
    // The vectors of the filtered blocks, given back to the pool at the end.
    let mut spent: Vec<Vec<f64>> = Vec::new();
    if spent.try_reserve_exact(nblocks).is_err() {
        return Some(cols);
    }
    let copied = AtomicBool::new(false);
    let lead = n.div_ceil(PREFAULT_BLOCK_ROWS) / PIPELINE_LEAD_PER + 2;
    let ran = std::thread::scope(|s| {
        let (to_helper, job) = channel::<Columns<'a>>();
        let (to_filter, blocks) = channel::<Block<'_>>();
        let copied = &copied;
        let helper = std::thread::Builder::new()
            .name("pyfoc-copy".into())
            .spawn_scoped(s, move || {
                let Ok(mut rest) = job.recv() else { return };
                let mut ready = Vec::new();
                let mut k0 = 0;
                for mut inputs in bufs {
                    let m = PREFAULT_BLOCK_ROWS.min(n - k0);
                    let (cols, r) = rest.split(m);
                    rest = r;
                    for src in [&u, &i] {
                        let rows = src.slice_axis(Axis(0), Slice::from(k0..k0 + m));
                        match rows.as_slice() {
                            Some(x) => inputs.extend_from_slice(x),
                            None => inputs.extend(rows.iter().copied()),
                        }
                    }
                    k0 += m;
                    let b = Block { inputs, cols };
                    // The lead blocks go at once (mapped), the others once all are copied.
                    if k0 < n && k0 <= lead * PREFAULT_BLOCK_ROWS {
                        if to_filter.send(b.mapped(prefault)).is_err() {
                            return;
                        }
                    } else {
                        ready.push(b);
                    }
                }
                copied.store(true, Ordering::Release);
                for b in ready {
                    if to_filter.send(b.mapped(prefault)).is_err() {
                        return;
                    }
                }
            });
        if helper.is_err() {
            return Some(cols);
        }
        let mut guard = match lock.try_lock() {
            Ok(g) => g,
            Err(TryLockError::Poisoned(p)) => p.into_inner(),
            Err(TryLockError::WouldBlock) => return Some(cols),
        };
        // The helper waits on this channel; a refused send gives the columns back.
        if let Err(e) = to_helper.send(cols) {
            return Some(e.0);
        }
        let inner = &mut *guard;
        let mut prev = u_prev.unwrap_or(inner.u_last);
        let obs = &mut inner.observer;
        let spent = &mut spent;
        let mut run = move |mut b: Block<'_>, prev: [f64; 2]| {
            let next = b.run(obs, prev);
            // Within the capacity reserved above: no allocation here.
            if spent.len() < spent.capacity() {
                spent.push(b.inputs);
            }
            next
        };
        // With the GIL, while the helper reads the caller's arrays.
        while !copied.load(Ordering::Acquire) {
            let Ok(b) = blocks.recv() else { break };
            prev = run(b, prev);
        }
        // Without it for the rest. Blocks arrive in row order; a panic of the helper (it has
        // no panicking operation) would end the channel early and resurface from `scope`.
        inner.u_last = py.detach(move || {
            for b in blocks {
                prev = run(b, prev);
            }
            prev
        });
        None
    });
    if ran.is_none() {
        pool::give_blocks(spent);
    }
    ran
}

/// `run`'s output arrays: the [`OUTPUTS`] columns and the status codes.
type OutArrays<'py> = (
    [Bound<'py, PyArray1<f64>>; OUTPUTS.len()],
    Bound<'py, PyArray1<i8>>,
);

/// `run`'s outputs: a caller's arrays (and their dict), or fresh ones (the float columns as
/// the rows of one array, and the status codes; `true` when taken from the [`pool`], whose
/// arrays may be longer than the run: their first `N` values are the output).
enum Outs<'py> {
    Given(OutArrays<'py>, Bound<'py, PyDict>),
    Fresh(Bound<'py, PyArray2<f64>>, Bound<'py, PyArray1<i8>>, bool),
}

/// The output arrays of `run` in a caller's `out` dict, checked: each present, of its dtype,
/// one-dimensional of length `n`, C-contiguous, writable, and no two overlapping (all of
/// them are borrowed for writing at once here, which rust-numpy refuses for overlapping
/// arrays and for read-only ones).
fn out_arrays<'py>(d: &Bound<'py, PyDict>, n: usize) -> PyResult<OutArrays<'py>> {
    fn get<'py, T: numpy::Element>(
        d: &Bound<'py, PyDict>,
        name: &str,
        dtype: &str,
        n: usize,
    ) -> PyResult<Bound<'py, PyArray1<T>>> {
        let item = d
            .get_item(name)?
            .ok_or_else(|| PyValueError::new_err(format!("out has no array {name:?}")))?;
        let a = item.cast_into::<PyArray1<T>>().map_err(|_| {
            PyValueError::new_err(format!(
                "out[{name:?}] must be a one-dimensional {dtype} numpy array"
            ))
        })?;
        if a.len() != n {
            return Err(PyValueError::new_err(format!(
                "out[{name:?}] must have length {n} (the rows of u_ab), got {}",
                a.len()
            )));
        }
        if !a.is_c_contiguous() {
            return Err(PyValueError::new_err(format!(
                "out[{name:?}] must be C-contiguous"
            )));
        }
        Ok(a)
    }
    let mut values = Vec::with_capacity(OUTPUTS.len());
    for name in OUTPUTS {
        values.push(get::<f64>(d, name, "float64", n)?);
    }
    let status = get::<i8>(d, "status", "int8", n)?;
    let values: [Bound<'py, PyArray1<f64>>; OUTPUTS.len()] = values
        .try_into()
        .map_err(|_| PyValueError::new_err("out: internal count of arrays"))?;
    {
        let mut borrows = Vec::with_capacity(OUTPUTS.len());
        for (name, a) in OUTPUTS.iter().zip(&values) {
            borrows.push(a.try_readwrite().map_err(|e| {
                PyValueError::new_err(format!(
                    "out[{name:?}] cannot be written ({e}): read-only, or overlapping another output or an input"
                ))
            })?);
        }
        status.try_readwrite().map_err(|e| {
            PyValueError::new_err(format!(
                "out[\"status\"] cannot be written ({e}): read-only, or overlapping another output or an input"
            ))
        })?;
    }
    Ok((values, status))
}

#[allow(clippy::too_many_arguments)]
fn build<T: Float>(
    motor: &Motor,
    ts: f64,
    q: Option<[[f64; 4]; 4]>,
    r: Option<[[f64; 2]; 2]>,
    x0: Option<[f64; 4]>,
    p0: Option<[[f64; 4]; 4]>,
    disc: Discretization,
    update: CovarianceUpdate,
    tracking: Tracking,
) -> Result<PmsmObserver<T>, ekf_core::ConfigError> {
    let conv = |v: f64| T::from_subset(&v);
    let mut cfg = ObserverConfig::new(motor.params::<T>(), conv(ts));
    cfg.discretization = disc;
    cfg.covariance_update = update;
    match tracking {
        Tracking::Default => {}
        Tracking::Flux => {
            if let Some(t) = &mut cfg.parameter_tracking {
                t.rs = RsTracking::Fixed;
            }
        }
        Tracking::Off => cfg.parameter_tracking = None,
    }
    if let Some(q) = q {
        cfg.noise.q = Matrix4::from_fn(|i, j| conv(q[i][j]));
    }
    if let Some(r) = r {
        cfg.noise.r = Matrix2::from_fn(|i, j| conv(r[i][j]));
    }
    if let Some(x0) = x0 {
        cfg.x0 = Vector4::from_fn(|i, _| conv(x0[i]));
    }
    if let Some(p0) = p0 {
        cfg.p0 = Matrix4::from_fn(|i, j| conv(p0[i][j]));
    }
    PmsmObserver::new(&cfg)
}

/// Online parameter tracking of an [`Ekf`] (`tracking=` argument).
#[derive(Clone, Copy)]
enum Tracking {
    /// `"default"`: the flux tracked, `Rs` by the split filter with the thermal link.
    Default,
    /// `"flux"`: the flux tracked, `Rs` fixed.
    Flux,
    /// `"off"`: the configured parameters as they are.
    Off,
}

#[pymethods]
impl Ekf {
    #[new]
    #[pyo3(signature = (motor, ts, *, q = None, r = None, x0 = None, p0 = None,
        discretization = "lag_free", dtype = "float64", covariance_update = "joseph",
        tracking = "default"))]
    #[allow(clippy::too_many_arguments)]
    fn new(
        motor: &Motor,
        ts: f64,
        q: Option<&Bound<'_, PyAny>>,
        r: Option<&Bound<'_, PyAny>>,
        x0: Option<&Bound<'_, PyAny>>,
        p0: Option<&Bound<'_, PyAny>>,
        discretization: &str,
        dtype: &str,
        covariance_update: &str,
        tracking: &str,
    ) -> PyResult<Self> {
        let disc = match discretization {
            "lag_free" => Discretization::LagFree,
            "forward_euler" => Discretization::ForwardEuler,
            other => {
                return Err(ConfigError::new_err(format!(
                    "discretization must be 'lag_free' or 'forward_euler', got {other:?}"
                )));
            }
        };
        let update = match covariance_update {
            "joseph" => CovarianceUpdate::Joseph,
            "standard" => CovarianceUpdate::StandardSymmetrized,
            other => {
                return Err(ConfigError::new_err(format!(
                    "covariance_update must be 'joseph' or 'standard', got {other:?}"
                )));
            }
        };
        let tracking = match tracking {
            "default" => Tracking::Default,
            "flux" => Tracking::Flux,
            "off" => Tracking::Off,
            other => {
                return Err(ConfigError::new_err(format!(
                    "tracking must be 'default', 'flux' or 'off', got {other:?}"
                )));
            }
        };
        let q = q.map(|o| square::<4>(o, "q")).transpose()?;
        let r = r.map(|o| square::<2>(o, "r")).transpose()?;
        let p0 = p0.map(|o| square::<4>(o, "p0")).transpose()?;
        let x0 = x0.map(|o| fixed::<4>(o, "x0")).transpose()?;
        let cfg_err = |e: ekf_core::ConfigError| ConfigError::new_err(e.to_string());
        let (observer, dtype) = match dtype {
            "float64" => (
                Observer::F64(
                    build(motor, ts, q, r, x0, p0, disc, update, tracking).map_err(cfg_err)?,
                ),
                "float64",
            ),
            "float32" => (
                Observer::F32(
                    build(motor, ts, q, r, x0, p0, disc, update, tracking).map_err(cfg_err)?,
                ),
                "float32",
            ),
            other => {
                return Err(ConfigError::new_err(format!(
                    "dtype must be 'float64' or 'float32', got {other:?}"
                )));
            }
        };
        Ok(Self {
            inner: Mutex::new(EkfInner {
                observer,
                u_last: [0.0, 0.0],
            }),
            ts,
            dtype,
        })
    }

    /// Runs the filter over a record; returns a dict of `(N,)` float64 arrays `theta`, `omega`,
    /// `omega_mech`, `i_alpha`, `i_beta`, `nis`, `psi_f`, `rs`, `winding_temperature` (the
    /// tracked parameters) and an int8 array `status` (the values of
    /// `pyfoc.Status`). Continues from the filter's current state: row 0
    /// predicts with `u_prev` if given, else with the last row of the previous `run` (zero
    /// for a new filter). The GIL is released while the filter runs.
    ///
    /// `out`: a dict holding those ten arrays (e.g. the dict a previous `run` of the same
    /// length returned), written in place and returned, so that a record filtered in chunks
    /// allocates nothing per chunk (fresh output memory is the largest cost of `run` after
    /// the steps). Each array must be one-dimensional of length N, C-contiguous, writable, of
    /// the dtype above, and not shared with another output; no other thread may use them
    /// during the call. A bad `out` raises before the filter moves.
    ///
    /// `dt`: an `(N,)` array of the period that ended at each row, s (each finite and > 0,
    /// else ValueError naming `dt`), for logs with irregular periods (skipped cycles); the
    /// rows then run in a plain loop. Without it every period is `ts`.
    #[pyo3(signature = (u_ab, i_ab, *, u_prev = None, dt = None, out = None))]
    fn run<'py>(
        &self,
        py: Python<'py>,
        u_ab: &Bound<'py, PyAny>,
        i_ab: &Bound<'py, PyAny>,
        u_prev: Option<&Bound<'py, PyAny>>,
        dt: Option<&Bound<'py, PyAny>>,
        out: Option<Bound<'py, PyDict>>,
    ) -> PyResult<Bound<'py, PyDict>> {
        let (u, i, n, u_prev) = record_args(u_ab, i_ab, u_prev)?;
        if let Some(dt) = dt {
            // Per-row periods: a separate, plain loop (`replay::run_dt`); the optimized
            // path below is left as it is.
            let dt = replay::periods(dt, n)?;
            let given = out.map(|d| out_arrays(&d, n).map(|a| (a, d))).transpose()?;
            convert::ensure_memory(n as u128 * (40 + Columns::ROW_BYTES), "run")?;
            let (u, i) = (to_vec(&u, "u_ab")?, to_vec(&i, "i_ab")?);
            let rows = self.with(py, move |inner| {
                let prev = u_prev.unwrap_or(inner.u_last);
                let (rows, last) = inner.observer.run_dt(prev, &u, &i, &dt);
                inner.u_last = last;
                rows
            });
            return replay::rows_to_dict(py, &rows, given);
        }
        let given = out.map(|d| out_arrays(&d, n).map(|a| (a, d))).transpose()?;
        // The copies of both inputs and the output columns, probed at once.
        let out_bytes = if given.is_some() {
            0
        } else {
            Columns::ROW_BYTES
        };
        convert::ensure_memory(n as u128 * (32 + out_bytes), "run")?;
        // Fresh outputs: the float columns are the rows of one (len(OUTPUTS), N) array (one
        // allocation, which the kernel backs with 2 MiB pages nearly whole: half the cost
        // of the first writes to separate 8 MB arrays, whose unaligned ends are 4 KiB pages),
        // handed out as its row views; the status codes are a second array.
        // They are the last call's arrays when nothing refers to those any more and the size
        // fits ([`pool`]): memory already mapped, which nobody needs to zero.
        let outs = match given {
            Some((arrays, d)) => Outs::Given(arrays, d),
            None => match pool::take_outputs(py, OUTPUTS.len(), n) {
                Some((values, status)) => Outs::Fresh(values, status, true),
                None => Outs::Fresh(
                    PyArray2::<f64>::zeros(py, [OUTPUTS.len(), n], false),
                    PyArray1::<i8>::zeros(py, n, false),
                    false,
                ),
            },
        };
        {
            // Long runs are pipelined ([`run_pipelined`]), into fresh outputs or a caller's
            // `out`; new output pages (not reused ones) are mapped ahead of the filter, on a
            // second thread.
            let pipelined = n >= PREFAULT_MIN_ROWS;
            let prefault = pipelined && matches!(outs, Outs::Fresh(.., false));
            // The write borrows (`out_arrays` checked that those of given arrays succeed:
            // writable, not shared), alive while the filter writes through `cols`.
            let mut given_rw = match &outs {
                Outs::Given((v, _), _) => Some(v.each_ref().map(|a| a.readwrite())),
                Outs::Fresh(..) => None,
            };
            let mut fresh_rw = match &outs {
                Outs::Fresh(v, ..) => Some(v.readwrite()),
                Outs::Given(..) => None,
            };
            let mut status_rw = match &outs {
                Outs::Given((_, st), _) | Outs::Fresh(_, st, _) => st.readwrite(),
            };
            // The first `n` values of each (a reused array may be longer).
            let status = contiguous(status_rw.as_slice_mut())?;
            let mut cols = Columns {
                values: Default::default(),
                status: status.split_at_mut(n.min(status.len())).0,
            };
            if let Some(rw) = &mut given_rw {
                for (dst, r) in cols.values.iter_mut().zip(rw.iter_mut()) {
                    *dst = contiguous(r.as_slice_mut())?;
                }
            }
            if let Some(rw) = &mut fresh_rw {
                let m = rw.shape()[1];
                let mut rest = contiguous(rw.as_slice_mut())?;
                for dst in cols.values.iter_mut() {
                    let (row, r) = rest.split_at_mut(m.min(rest.len()));
                    rest = r;
                    *dst = row.split_at_mut(n.min(row.len())).0;
                }
            }
            // Long runs: copied (and, into fresh outputs, mapped) and filtered block by block
            // on two threads ([`run_pipelined`]); else, or should that not start, in
            // sequence. Into a caller's `out` only the copy moves (about 4 % of the steps):
            // streamed runs `run / steps` 1.09 / 1.11 (f64 / f32) against 1.10 / 1.15 in
            // sequence, on a quiet 2-core machine; a busy one can make the filter wait.
            let cols = if pipelined {
                run_pipelined(py, &self.inner, &u, &i, u_prev, cols, prefault)
            } else {
                Some(cols)
            };
            if let Some(cols) = cols {
                let mut inputs = pool::take_whole(4 * n, "u_ab, i_ab")?;
                std::thread::scope(|s| {
                    // The page-mapping thread starts first, and maps while the inputs are copied.
                    let sink = if prefault {
                        map_ahead(s, cols)
                    } else {
                        Sink::Direct(cols)
                    };
                    convert::extend_with(&mut inputs, &u);
                    convert::extend_with(&mut inputs, &i);
                    let (u, i) = inputs.split_at(2 * n);
                    self.with(py, move |inner| {
                        let prev = u_prev.unwrap_or(inner.u_last);
                        inner.u_last = run_sink(&mut inner.observer, prev, u, i, sink);
                    });
                });
                pool::give_whole(inputs);
            }
        }
        let (values, status) = match outs {
            Outs::Given(_, d) => return Ok(d),
            Outs::Fresh(values, status, _) => (values, status),
        };
        pool::keep_outputs(&values, &status);
        let out = PyDict::new(py);
        if values.shape()[1] == n {
            for (k, name) in OUTPUTS.iter().enumerate() {
                out.set_item(name, values.get_item(k)?)?;
            }
            out.set_item("status", status)?;
        } else {
            // A longer reused pair: views of the first `n` values.
            let first = PySlice::new(py, 0, n as isize, 1);
            for (k, name) in OUTPUTS.iter().enumerate() {
                out.set_item(name, values.get_item((k, &first))?)?;
            }
            out.set_item("status", status.get_item(&first)?)?;
        }
        Ok(out)
    }

    /// For `bench/bench_run.py` only: seconds that the observer's own steps take over the
    /// rows of `u_ab`, `i_ab` (the loop of `run` without its inputs' checks, copies and
    /// output columns), on a copy of this filter (its state is not changed).
    fn _time_steps(
        &self,
        py: Python<'_>,
        u_ab: &Bound<'_, PyAny>,
        i_ab: &Bound<'_, PyAny>,
    ) -> PyResult<f64> {
        let (u, i) = (rows2(u_ab, "u_ab")?, rows2(i_ab, "i_ab")?);
        if u.shape()[0] != i.shape()[0] {
            return Err(PyValueError::new_err(
                "u_ab and i_ab must have the same length",
            ));
        }
        let (u, i) = (to_vec(&u, "u_ab")?, to_vec(&i, "i_ab")?);
        let mut obs = self.with(py, |inner| inner.observer.clone());
        Ok(py.detach(move || {
            fn go<T: Float + Into<f64>>(o: &mut PmsmObserver<T>, u: &[f64], i: &[f64]) -> f64 {
                let c = |v: f64| T::from_subset(&v);
                let mut prev = [c(0.0); 2];
                let mut acc = 0.0;
                let t0 = std::time::Instant::now();
                for (uk, ik) in u.chunks_exact(2).zip(i.chunks_exact(2)) {
                    if let Ok(e) = o.step(prev, [c(ik[0]), c(ik[1])]) {
                        acc += e.theta_rad.into();
                    }
                    prev = [c(uk[0]), c(uk[1])];
                }
                let dt = t0.elapsed().as_secs_f64();
                std::hint::black_box(acc);
                dt
            }
            match &mut obs {
                Observer::F64(o) => go(o, &u, &i),
                Observer::F32(o) => go(o, &u, &i),
            }
        }))
    }

    /// One sample: predicts with `u_prev` (voltage held over the previous period), corrects
    /// with `i` (currents sampled now). Returns a dict of floats (`theta`, `omega`,
    /// `omega_mech`, `i_alpha`, `i_beta`, `nis`, `psi_f`, `rs`, `winding_temperature`) and
    /// `status`, a `pyfoc.Status`
    /// (`REJECTED` for a non-finite sample, in which case the state is unchanged).
    /// Does not change the voltage `run` uses for its next first row.
    fn step<'py>(
        &self,
        py: Python<'py>,
        u_prev: &Bound<'py, PyAny>,
        i: &Bound<'py, PyAny>,
    ) -> PyResult<Bound<'py, PyDict>> {
        let u = fixed::<2>(u_prev, "u_prev")?;
        let i = fixed::<2>(i, "i")?;
        let r = self.with(py, |inner| inner.observer.step(u, i));
        let out = PyDict::new(py);
        for (name, v) in OUTPUTS.iter().zip(r.values) {
            out.set_item(name, v)?;
        }
        out.set_item("status", r.status.to_py(py)?)?;
        Ok(out)
    }

    /// State `[i_alpha, i_beta, omega_e, theta]` as a `(4,)` float64 array.
    #[getter]
    fn state<'py>(&self, py: Python<'py>) -> Bound<'py, PyArray1<f64>> {
        let x = self.with(py, |inner| inner.observer.state());
        PyArray1::from_slice(py, &x)
    }

    /// State covariance as a `(4, 4)` float64 array.
    #[getter]
    fn covariance<'py>(&self, py: Python<'py>) -> PyResult<Bound<'py, PyArray2<f64>>> {
        let p = self.with(py, |inner| inner.observer.covariance());
        let rows: Vec<Vec<f64>> = p.iter().map(|r| r.to_vec()).collect();
        Ok(PyArray2::from_vec2(py, &rows)?)
    }

    /// Voltage `[u_alpha, u_beta]` that predicts the first row of the next `run`.
    #[getter]
    fn u_last<'py>(&self, py: Python<'py>) -> Bound<'py, PyArray1<f64>> {
        let u = self.with(py, |inner| inner.u_last);
        PyArray1::from_slice(py, &u)
    }

    /// Replaces state (length 4) and covariance (4 x 4). `FilterError` and nothing changed
    /// when either is not finite.
    fn reset(&self, py: Python<'_>, x: &Bound<'_, PyAny>, p: &Bound<'_, PyAny>) -> PyResult<()> {
        let x = fixed::<4>(x, "x")?;
        let p = square::<4>(p, "p")?;
        fn go<T: Float>(
            o: &mut PmsmObserver<T>,
            x: [f64; 4],
            p: [[f64; 4]; 4],
        ) -> Result<(), EkfError> {
            let c = |v: f64| T::from_subset(&v);
            o.reset(
                Vector4::from_fn(|i, _| c(x[i])),
                Matrix4::from_fn(|i, j| c(p[i][j])),
            )
        }
        let res = self.with(py, |inner| match &mut inner.observer {
            Observer::F64(o) => go(o, x, p),
            Observer::F32(o) => go(o, x, p),
        });
        res.map_err(|e| FilterError::new_err(e.to_string()))
    }

    fn __repr__(&self) -> String {
        format!("Ekf(ts={}, dtype={:?})", self.ts, self.dtype)
    }
}

/// `pyfoc`: the sensorless PMSM observer of `ekf-core` on numpy arrays.
#[pymodule]
fn pyfoc(m: &Bound<'_, PyModule>) -> PyResult<()> {
    let py = m.py();
    m.add_class::<Motor>()?;
    m.add_class::<Ekf>()?;
    m.add_function(wrap_pyfunction!(simulate::simulate, m)?)?;
    m.add_function(wrap_pyfunction!(tune::tune_qr, m)?)?;
    m.add_function(wrap_pyfunction!(tune::tune_qr_mcap, m)?)?;
    m.add_function(wrap_pyfunction!(suite::suite, m)?)?;
    m.add_function(wrap_pyfunction!(identify::identify, m)?)?;
    m.add_function(wrap_pyfunction!(pool::clear_buffer_pool, m)?)?;
    m.add_function(wrap_pyfunction!(replay::read_log, m)?)?;
    m.add_class::<replay::FluxObserver>()?;
    m.add_class::<drive::DriveObserver>()?;
    m.add("LogError", py.get_type::<replay::LogError>())?;
    m.add("SimulationError", py.get_type::<SimulationError>())?;
    m.add("PyfocError", py.get_type::<PyfocError>())?;
    m.add("ConfigError", py.get_type::<ConfigError>())?;
    m.add("FilterError", py.get_type::<FilterError>())?;
    m.add("Status", RowStatus::py_class(py)?)?;
    m.add("__version__", env!("CARGO_PKG_VERSION"))?;
    Ok(())
}
