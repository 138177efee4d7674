//! Memory `Ekf.run` reuses across calls instead of asking the system for fresh pages.
//!
//! A long `run` needs 105 bytes a row: the copies of its inputs (32) and, unless the caller
//! gives `out=`, its output arrays (73). Allocations that large are mapped afresh by the
//! allocator on every call (glibc's `mmap` for a numpy array of megabytes, and the heap top
//! it trims after the call for the copies), and the kernel zeroes every new page at its first
//! write: 7-10 % of the filter's own time. This module keeps the last call's buffers instead:
//!
//! - Outputs: the `(len(OUTPUTS), M)` float64 array whose rows are a fresh result's columns
//!   and the int8 status array of the last `run` stay referenced here. The next `run` of
//!   `n` rows with `M / 2 <= n <= M` hands them out again (as views of their first `n`
//!   columns) when nothing else references them, that is when the caller has dropped every
//!   array (and view) of that result; a result kept alive is never written again. The
//!   references are counted by Python, so a buffer is reused only when its previous result
//!   is unreachable (a weak reference does not count: it may see the array reused, where it
//!   would otherwise be dead); no `unsafe` here.
//! - Input copies: the block vectors of the pipelined path (2^14 rows each) and the single
//!   vector of the sequential path are given back here at the end of the call and taken by
//!   the next.
//!
//! Bounded: at most [`OUTPUT_POOL_MAX_BYTES`] of output arrays (one pair) and
//! [`INPUT_POOL_MAX_BYTES`] of input copies stay held once the results are dropped;
//! larger calls allocate and free as before. `pyfoc.clear_buffer_pool()` drops both.
//! Results do not depend on it: every row of every column is written by the filter.

use numpy::{PyArray1, PyArray2, PyArrayDescrMethods, PyArrayMethods, PyUntypedArrayMethods};
use pyo3::prelude::*;
use std::sync::{Mutex, MutexGuard, PoisonError};

/// Largest output pair (float columns and status codes) kept for reuse: 256 MiB, the
/// outputs of 3.6 million rows.
pub(crate) const OUTPUT_POOL_MAX_BYTES: usize = 256 << 20;
/// Largest total of input copies kept for reuse: 128 MiB, the copies of 4.2 million rows.
pub(crate) const INPUT_POOL_MAX_BYTES: usize = 128 << 20;

/// The last fresh outputs of `run`, kept for the next: the float64 `(len(OUTPUTS), M)` array
/// and the int8 `(M,)` array (as plain objects: a caller may have changed their dtype or
/// shape in place meanwhile, so they are checked again when taken).
struct Outputs {
    values: Py<PyAny>,
    status: Py<PyAny>,
}

static OUTPUTS: Mutex<Option<Outputs>> = Mutex::new(None);
/// Spare block vectors of the pipelined input copy (each of capacity `4 * block rows`).
static BLOCKS: Mutex<Vec<Vec<f64>>> = Mutex::new(Vec::new());
/// A spare vector for the sequential path's input copy.
static WHOLE: Mutex<Vec<f64>> = Mutex::new(Vec::new());

/// The pool's lock; a panic elsewhere cannot leave a pool half-updated (each update is one
/// assignment), so a poisoned lock is taken over.
fn lock<T>(m: &'static Mutex<T>) -> MutexGuard<'static, T> {
    m.lock().unwrap_or_else(PoisonError::into_inner)
}

/// Python's reference count of `obj`.
fn refs(obj: &Bound<'_, PyAny>) -> isize {
    // Deprecated in pyo3 0.29 in favour of the unsafe `ffi::Py_REFCNT`, which this crate
    // (`forbid(unsafe_code)`) cannot call; exactly that value.
    #[allow(deprecated)]
    obj.get_refcnt()
}

/// Output arrays of `run`: the float columns as the rows of one array, and the status codes.
pub(crate) type FreshArrays<'py> = (Bound<'py, PyArray2<f64>>, Bound<'py, PyArray1<i8>>);

/// Output arrays for `n` rows from the pool: a float64 `(len, M)` array and an int8 `(M,)`
/// array, both C-contiguous, writable and referenced by nobody but the caller, with
/// `n <= M <= 2 n`. `None` when the pool is empty, its arrays are still in
/// use, or their size does not fit (the pool is then emptied: the new outputs replace them).
pub(crate) fn take_outputs<'py>(py: Python<'py>, len: usize, n: usize) -> Option<FreshArrays<'py>> {
    if n == 0 {
        return None;
    }
    let o = lock(&OUTPUTS).take()?;
    let (values, status) = (o.values.into_bound(py), o.status.into_bound(py));
    // The pool's reference is now ours: one each means no result, view or other object
    // refers to them (a view of a column refers to the 2-D array), and none can appear
    // while this thread holds the GIL (an abi3 module does not load on free-threaded
    // CPython, where this count would not be final).
    if refs(&values) != 1 || refs(&status) != 1 {
        return None;
    }
    // A caller may have changed the dtype or shape in place, or frozen an array, before
    // dropping it.
    let values = values.cast_into::<PyArray2<f64>>().ok()?;
    let status = status.cast_into::<PyArray1<i8>>().ok()?;
    let m = values.shape()[1];
    let fits = values.shape()[0] == len
        && n <= m
        && m / 2 <= n
        && status.len() == m
        && values.is_c_contiguous()
        && status.is_c_contiguous()
        && values.try_readwrite().is_ok()
        && status.try_readwrite().is_ok();
    fits.then_some((values, status))
}

/// Keeps `values` and `status`, the outputs `run` is about to return, for a later call
/// (replacing what the pool held), if they are within [`OUTPUT_POOL_MAX_BYTES`].
pub(crate) fn keep_outputs(values: &Bound<'_, PyArray2<f64>>, status: &Bound<'_, PyArray1<i8>>) {
    let bytes = values.len() * 8 + status.len();
    if bytes > OUTPUT_POOL_MAX_BYTES {
        return;
    }
    let old = lock(&OUTPUTS).replace(Outputs {
        values: values.clone().into_any().unbind(),
        status: status.clone().into_any().unbind(),
    });
    // Released after the pool's lock (a decref may run arbitrary deallocation code).
    drop(old);
}

/// `k` block vectors of capacity `cap` (empty), spare ones from the pool first, the others
/// allocated fallibly (`None` if the system refuses one).
pub(crate) fn take_blocks(k: usize, cap: usize) -> Option<Vec<Vec<f64>>> {
    let mut out = Vec::new();
    out.try_reserve_exact(k).ok()?;
    {
        let mut pool = lock(&BLOCKS);
        while out.len() < k {
            match pool.pop() {
                Some(mut v) if v.capacity() >= cap => {
                    v.clear();
                    out.push(v);
                }
                Some(_) => {}
                None => break,
            }
        }
    }
    while out.len() < k {
        let mut v = Vec::new();
        v.try_reserve_exact(cap).ok()?;
        out.push(v);
    }
    Some(out)
}

/// Gives block vectors back; those over [`INPUT_POOL_MAX_BYTES`] (with the pool's others)
/// are freed.
pub(crate) fn give_blocks(blocks: impl IntoIterator<Item = Vec<f64>>) {
    let mut pool = lock(&BLOCKS);
    let mut bytes: usize = pool.iter().map(|v| v.capacity() * 8).sum();
    for v in blocks {
        let b = v.capacity() * 8;
        if bytes + b <= INPUT_POOL_MAX_BYTES && pool.try_reserve(1).is_ok() {
            bytes += b;
            pool.push(v);
        }
    }
}

/// An empty vector with room for `n` values for the sequential input copy: the pool's spare
/// if its capacity is `n` to `2 n`, else a fresh one (MemoryError naming `what`).
pub(crate) fn take_whole(n: usize, what: &str) -> PyResult<Vec<f64>> {
    let spare = core::mem::take(&mut *lock(&WHOLE));
    if spare.capacity() >= n && spare.capacity() / 2 <= n && n > 0 {
        let mut v = spare;
        v.clear();
        return Ok(v);
    }
    drop(spare);
    crate::convert::try_vec::<f64>(n, what)
}

/// Gives the sequential input copy back, if within [`INPUT_POOL_MAX_BYTES`].
pub(crate) fn give_whole(v: Vec<f64>) {
    if v.capacity() * 8 <= INPUT_POOL_MAX_BYTES {
        let old = core::mem::replace(&mut *lock(&WHOLE), v);
        drop(old);
    }
}

/// `pyfoc.clear_buffer_pool()`: drops the buffers `Ekf.run` keeps for reuse (the last
/// result's output arrays, freed once no result uses them, and the spare input copies);
/// returns the bytes the pool held. Later calls fill it again.
#[pyfunction]
pub(crate) fn clear_buffer_pool(py: Python<'_>) -> usize {
    let outputs = lock(&OUTPUTS).take();
    let blocks = core::mem::take(&mut *lock(&BLOCKS));
    let whole = core::mem::take(&mut *lock(&WHOLE));
    let mut bytes = whole.capacity() * 8 + blocks.iter().map(|v| v.capacity() * 8).sum::<usize>();
    if let Some(o) = outputs {
        for a in [o.values.bind(py), o.status.bind(py)] {
            if let Ok(a) = a.cast::<numpy::PyUntypedArray>() {
                bytes += a.len() * a.dtype().itemsize();
            }
        }
    }
    bytes
}
