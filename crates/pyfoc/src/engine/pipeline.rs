//! The 2-thread pipeline of a long `run`: a helper thread copies the inputs (and maps fresh
//! output pages) block by block while this thread filters the blocks already copied.

use std::sync::Mutex;

use pyo3::prelude::*;

use super::pool;
use super::prefault::PREFAULT_BLOCK_ROWS;

use crate::convert::RealArray;
use crate::observer::{Columns, Filter, Observer};

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
pub(super) fn run_pipelined<'a>(
    py: Python<'_>,
    lock: &Mutex<Filter>,
    u: &RealArray<'_>,
    i: &RealArray<'_>,
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
