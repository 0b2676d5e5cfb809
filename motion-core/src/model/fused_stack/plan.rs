//! How one call of the fused stack shares its work among the rayon workers: whole batch
//! elements per task, or every layer in phases over rows and attention blocks.

use candle_core::Result;

use crate::nn::kernels::{par_each, Rows};

/// How one call shares its work among the rayon workers.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub(super) enum Plan {
    /// Groups of whole batch elements through the whole pass, one single-threaded task per
    /// group: `threads` equal groups when the batch divides evenly (larger products, the
    /// weights packed once per group), else one element per group.
    Elements { threads: usize },
    /// One group of all elements, every layer split into phases over rows for `threads`.
    Rows { threads: usize },
}

impl Plan {
    pub(super) fn new(batch: usize) -> Self {
        let threads = rayon::current_num_threads().max(1);
        if threads > 1 && (batch % threads == 0 || batch >= 2 * threads) {
            Plan::Elements { threads }
        } else {
            Plan::Rows { threads }
        }
    }

    /// `(first element, elements)` of each group.
    pub(super) fn groups(self, batch: usize) -> Vec<(usize, usize)> {
        match self {
            Plan::Elements { threads } if batch % threads == 0 => {
                let size = batch / threads;
                (0..threads).map(|g| (g * size, size)).collect()
            }
            Plan::Elements { .. } => (0..batch).map(|b| (b, 1)).collect(),
            Plan::Rows { .. } => vec![(0, batch)],
        }
    }

    /// Threads inside one group.
    pub(super) fn threads(self) -> usize {
        match self {
            Plan::Elements { .. } => 1,
            Plan::Rows { threads } => threads,
        }
    }
}

/// Runs `f` on every item: on the rayon pool when `threads > 1`, else on this thread in order.
pub(super) fn run<I: Send>(threads: usize, items: Vec<I>, f: impl Fn(I) -> Result<()> + Sync + Send) -> Result<()> {
    if threads > 1 {
        par_each(items, f)
    } else {
        items.into_iter().try_for_each(f)
    }
}

/// Fewest query rows in an attention block: smaller blocks cost more in gemm packing than
/// they gain.
pub(super) const MIN_BLOCK_ROWS: usize = 16;

/// A block of query (or key) rows `[start, start + rows.len)` of batch element `batch`.
#[derive(Debug, Clone, Copy)]
pub(super) struct Block {
    pub(super) batch: usize,
    pub(super) start: usize,
    pub(super) rows: Rows,
}

/// Splits `batch × tokens` rows into attention blocks for `threads`: one block per batch element when there are at least as many elements as threads,
/// else each element cut into about `threads / batch` blocks of at least
/// [`MIN_BLOCK_ROWS`] rows. The blocks cover every row once, in order. Per-row arithmetic
/// does not depend on the split, so the result is the same for any thread count.
pub(super) fn attention_blocks(batch: usize, tokens: usize, threads: usize) -> Vec<Block> {
    let per_element = threads.div_ceil(batch.max(1)).min(tokens / MIN_BLOCK_ROWS).max(1);
    let mut out = Vec::with_capacity(batch * per_element);
    for b in 0..batch {
        for i in 0..per_element {
            let start = i * tokens / per_element;
            let len = (i + 1) * tokens / per_element - start;
            out.push(Block { batch: b, start, rows: Rows { first: b * tokens + start, len } });
        }
    }
    out
}
