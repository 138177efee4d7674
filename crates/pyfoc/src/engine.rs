//! How `Ekf.run` moves a long record through the filter fast, behind one interface
//! ([`run`]): the output arrays (fresh, reused from the [`pool`], or a caller's `out`), the
//! copies of the inputs (the filter runs without the GIL on private data), the 2-thread
//! pipeline of long runs ([`pipeline`]) and the page-mapping thread for fresh outputs
//! ([`prefault`]). None of it changes a result: the rows are those of the plain loop.
//!
//! | rule | value | why |
//! | --- | --- | --- |
//! | pipelined from | 2^16 rows | below it the second thread costs more than it saves |
//! | block | 2^14 rows | the unit handed between the threads |
//! | lead blocks | 1 in 8, and 2 | filtered while the helper copies the rest |
//! | pool | outputs up to 256 MiB, inputs up to 128 MiB | a dropped result's memory is reused |

use std::sync::Mutex;

use numpy::{PyArray1, PyArray2, PyArrayMethods, PyUntypedArrayMethods};
use pyo3::prelude::*;
use pyo3::types::{PyDict, PySlice};

mod outputs;
mod pipeline;
pub(crate) mod pool;
mod prefault;

pub(crate) use outputs::{OutArrays, out_arrays};
pub(crate) use pool::clear_buffer_pool;

use crate::convert::{self, RealArray, contiguous};
use crate::observer::{Columns, Filter, OUTPUTS};
use outputs::Outs;
use pipeline::run_pipelined;
use prefault::{PREFAULT_MIN_ROWS, Sink, map_ahead, run_sink};

/// `Ekf.run` over the `n` rows of `u`, `i` (checked by `convert::record_args`) with the
/// filter behind `filter`, from `u_prev` (else the filter's last voltage), into the
/// caller's checked `given` arrays or fresh ones; returns the output dict.
pub(crate) fn run<'py>(
    py: Python<'py>,
    filter: &Mutex<Filter>,
    u: &RealArray<'_>,
    i: &RealArray<'_>,
    n: usize,
    u_prev: Option<[f64; 2]>,
    given: Option<(OutArrays<'py>, Bound<'py, PyDict>)>,
) -> PyResult<Bound<'py, PyDict>> {
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
        // sequence. Into a caller's `out` only the copy moves (about 4 % of the steps).
        let cols = if pipelined {
            run_pipelined(py, filter, u, i, u_prev, cols, prefault)
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
                convert::extend_with(&mut inputs, u);
                convert::extend_with(&mut inputs, i);
                let (u, i) = inputs.split_at(2 * n);
                Filter::with(filter, py, move |inner| {
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
