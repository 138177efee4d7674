//! The page-mapping thread of `run`: fresh output pages mapped (faulted in and zeroed by the
//! kernel) on a second thread, block by block, ahead of the filter that writes them.

use crate::observer::{Columns, OUTPUTS, Observer};

/// Fewest rows for which `run` maps its fresh output pages on a second thread (below it the
/// thread costs more than it saves).
pub(super) const PREFAULT_MIN_ROWS: usize = 1 << 16;
/// Rows per block handed from the page-mapping thread to the filter.
pub(super) const PREFAULT_BLOCK_ROWS: usize = 1 << 14;

/// Where `run`'s loop writes its rows: straight into the columns, or into the blocks that
/// the page-mapping thread of [`map_ahead`] hands over in row order.
pub(super) enum Sink<'a> {
    /// Straight into the columns.
    Direct(Columns<'a>),
    /// Into the blocks the page-mapping thread hands over.
    Mapped(std::sync::mpsc::Receiver<Columns<'a>>),
}

/// Starts the page-mapping thread on freshly allocated output columns: it takes the blocks
/// of rows in order, maps their pages (the page faults and the kernel's zeroing: about a
/// tenth of a step's time per row), and hands each block to the filter through a channel,
/// so each block is written by one thread at a time; the filter's results do not depend on
/// it. Started before the inputs are copied, it has mapped the first blocks when the filter
/// starts. Without a second thread (spawn refused) the columns are written directly.
pub(super) fn map_ahead<'scope, 'a: 'scope>(
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
pub(super) fn run_sink(
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

impl<'a> Columns<'a> {
    /// The first `k` rows (at most all of them) and the rest.
    pub(super) fn split(self, k: usize) -> (Self, Self) {
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
    pub(super) fn prefault(&mut self) {
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
