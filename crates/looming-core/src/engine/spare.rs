//! Large per-scan or per-pair buffers kept for the next scan's or pair's:
//! a 64 x 2048 image's buffers run to megabytes, whose fresh pages (the
//! allocator hands such blocks back to the system when freed) cost more to
//! fault in than to fill. Each owner (the surfaces' returns and fields,
//! `surface/spare.rs`; the renders' source table, `warp/source_columns.rs`)
//! keeps its buffers in a [`Pool`] of its own.

use std::sync::Mutex;

/// Buffers given back for later scans or pairs, at most [`MAX_SPARE`]
/// (the surfaces of a pair's two scans, of a few sensors, are estimated at
/// once).
pub(crate) struct Pool<T>(Mutex<Vec<T>>);

const MAX_SPARE: usize = 4;

impl<T: Default> Pool<T> {
    pub(crate) const fn new() -> Self {
        Self(Mutex::new(Vec::new()))
    }

    /// Buffers given back earlier, or new empty ones.
    pub(crate) fn take(&self) -> T {
        self.0
            .lock()
            .ok()
            .and_then(|mut spare| spare.pop())
            .unwrap_or_default()
    }

    /// Keep `buffers` for a later [`Pool::take`].
    pub(crate) fn give(&self, buffers: T) {
        if let Ok(mut spare) = self.0.lock()
            && spare.len() < MAX_SPARE
        {
            spare.push(buffers);
        }
    }
}

/// `buffer` cleared and filled with `len` copies of `value`.
pub(crate) fn filled<T: Clone>(mut buffer: Vec<T>, len: usize, value: T) -> Vec<T> {
    buffer.clear();
    buffer.resize(len, value);
    buffer
}
