//! Medians of 3x3 windows (at most nine values) in `f32::total_cmp`'s
//! order, without a branch on the values: one window at a time
//! ([`median_of`]) or many side by side ([`MedianBatch`]), whose sorting
//! network runs on the windows' keys in SIMD lanes.

/// Median (upper middle) of at most the 9 values of a 3x3 window, without
/// allocating: this runs for every cell.
pub(super) fn median_3x3(values: impl Iterator<Item = f32>) -> Option<f32> {
    let mut window = [0f32; 9];
    let mut count = 0;
    for value in values.take(9) {
        window[count] = value;
        count += 1;
    }
    (count > 0).then(|| median_of(&window[..count]))
}

/// The middle (upper middle) value of a non-empty slice of at most nine
/// values in `f32::total_cmp`'s order: their total-order keys, padded to
/// nine with the largest key, through a sorting network of min and max
/// ([`sort_nine`]), which has no branch to mispredict (an insertion sort's
/// comparisons on noisy values were a third of the per-cell stage); the
/// padding sorts last, so the middle of the values is the key at
/// `count / 2`.
pub(super) fn median_of(values: &[f32]) -> f32 {
    debug_assert!(!values.is_empty() && values.len() <= 9);
    let mut keys = [i32::MAX; 9];
    for (key, &value) in keys.iter_mut().zip(values) {
        *key = total_order_key(value);
    }
    sort_nine(&mut keys);
    from_total_order_key(keys[values.len() / 2])
}

/// The 25 comparators of a sorting network for nine keys, seven layers
/// (Dobbelaere's list of sorting networks; checked on every 0-1 input,
/// which by the 0-1 principle sorts every input), written once and handed
/// to `$then!` (a macro taking them as a list): the table and the lanes'
/// written-out network alike.
macro_rules! nine_key_network {
    ($then:ident) => {
        $then!(
            (0, 3),
            (1, 7),
            (2, 5),
            (4, 8),
            (0, 7),
            (2, 4),
            (3, 8),
            (5, 6),
            (0, 2),
            (1, 3),
            (4, 5),
            (7, 8),
            (1, 4),
            (3, 6),
            (5, 7),
            (0, 1),
            (2, 4),
            (3, 5),
            (6, 8),
            (2, 3),
            (4, 5),
            (6, 7),
            (1, 2),
            (3, 4),
            (5, 6)
        )
    };
}

/// A list of comparators as an array.
macro_rules! comparator_table {
    ($(($i:literal, $j:literal)),* $(,)?) => {
        [$(($i, $j)),*]
    };
}

/// The network as a table.
const NINE_KEY_NETWORK: [(usize, usize); 25] = nine_key_network!(comparator_table);

/// Sorts nine keys with [`NINE_KEY_NETWORK`].
#[inline]
fn sort_nine(keys: &mut [i32; 9]) {
    for (i, j) in NINE_KEY_NETWORK {
        let (a, b) = (keys[i], keys[j]);
        keys[i] = a.min(b);
        keys[j] = a.max(b);
    }
}

/// Windows whose medians [`MedianBatch`] takes at once: two SSE registers
/// of keys per position of the window.
const LANES: usize = 8;

/// The medians of up to [`LANES`] windows at once: each window's keys in
/// one lane of nine rows, so that every comparator of the network is a
/// vector min and max over the lanes (one window at a time, the network's
/// 25 scalar comparators were a tenth of the per-cell stage). The same
/// median as [`median_of`] gives for each window.
pub(super) struct MedianBatch {
    /// Position `k` of the window in lane `l`: `keys[k][l]`; padded with
    /// the largest key.
    keys: [[i32; LANES]; 9],
    /// Per lane, how many values its window holds, and where its median
    /// goes (the caller's index).
    counts: [usize; LANES],
    at: [usize; LANES],
    len: usize,
}

impl MedianBatch {
    pub(super) fn new() -> Self {
        Self {
            keys: [[i32::MAX; LANES]; 9],
            counts: [1; LANES],
            at: [0; LANES],
            len: 0,
        }
    }

    /// Queues the median of `values` (one to nine) for the index `at`;
    /// when the batch is full, hands every queued median to `done` (index,
    /// median) and empties it.
    #[inline]
    pub(super) fn push(&mut self, at: usize, values: &[f32], done: &mut impl FnMut(usize, f32)) {
        debug_assert!(!values.is_empty() && values.len() <= 9);
        let lane = self.len;
        // The values' bits as they are (the flip to total-order keys is
        // taken over the lanes at once); the padding is a positive key,
        // which the flip keeps.
        for (k, row) in self.keys.iter_mut().enumerate() {
            row[lane] = values.get(k).map_or(i32::MAX, |&v| v.to_bits() as i32);
        }
        self.counts[lane] = values.len();
        self.at[lane] = at;
        self.len += 1;
        if self.len == LANES {
            self.flush(done);
        }
    }

    /// Hands every queued median to `done` (index, median) and empties the
    /// batch.
    pub(super) fn flush(&mut self, done: &mut impl FnMut(usize, f32)) {
        if self.len == 0 {
            return;
        }
        let mut keys = self.keys.map(|row| row.map(total_order_key_of_bits));
        sort_nine_lanes(&mut keys);
        for lane in 0..self.len {
            let middle = keys[self.counts[lane] / 2][lane];
            done(self.at[lane], from_total_order_key(middle));
        }
        self.len = 0;
    }
}

/// Sorts the nine keys of every lane with [`NINE_KEY_NETWORK`], each
/// comparator a min and a max over the lanes, written out with constant
/// positions (a loop over the network's table kept it in memory).
#[inline]
fn sort_nine_lanes(keys: &mut [[i32; LANES]; 9]) {
    macro_rules! network {
        ($(($i:literal, $j:literal)),* $(,)?) => {
            $(
                let (a, b) = (keys[$i], keys[$j]);
                keys[$i] = std::array::from_fn(|l| a[l].min(b[l]));
                keys[$j] = std::array::from_fn(|l| a[l].max(b[l]));
            )*
        };
    }
    nine_key_network!(network);
}

/// An `f32`'s bits as an integer that orders as `f32::total_cmp` does
/// (negative values' magnitude bits flipped).
#[inline]
fn total_order_key(value: f32) -> i32 {
    total_order_key_of_bits(value.to_bits() as i32)
}

/// [`total_order_key`] of an `f32`'s bits.
#[inline]
fn total_order_key_of_bits(bits: i32) -> i32 {
    bits ^ (((bits >> 31) as u32) >> 1) as i32
}

/// The inverse of [`total_order_key`] (the flip is its own inverse).
#[inline]
fn from_total_order_key(key: i32) -> f32 {
    f32::from_bits((key ^ (((key >> 31) as u32) >> 1) as i32) as u32)
}

#[cfg(test)]
mod tests {
    use super::*;

    /// By the 0-1 principle a comparator network that sorts every input of
    /// zeros and ones sorts every input.
    #[test]
    fn the_nine_key_network_sorts_every_zero_one_input() {
        for bits in 0u32..512 {
            let mut keys: [i32; 9] = std::array::from_fn(|k| ((bits >> k) & 1) as i32);
            sort_nine(&mut keys);
            assert!(
                keys.windows(2).all(|w| w[0] <= w[1]),
                "{bits:09b}: {keys:?}"
            );
        }
    }

    /// The lanes' network is the table's: every 0-1 input of nine keys, one
    /// per lane, sorted as [`sort_nine`] sorts it.
    #[test]
    fn the_lanes_network_sorts_as_the_table() {
        for first in (0u32..512).step_by(LANES) {
            let mut keys = [[0i32; LANES]; 9];
            for (lane, bits) in (first..first + LANES as u32).enumerate() {
                for (k, row) in keys.iter_mut().enumerate() {
                    row[lane] = ((bits >> k) & 1) as i32;
                }
            }
            let mut expected = keys;
            sort_nine_lanes(&mut keys);
            for lane in 0..LANES {
                let mut one: [i32; 9] = std::array::from_fn(|k| expected[k][lane]);
                sort_nine(&mut one);
                for (row, key) in expected.iter_mut().zip(one) {
                    row[lane] = key;
                }
            }
            assert_eq!(keys, expected);
        }
    }

    /// Windows of one to nine values mixing finite values with zeros of
    /// both signs, infinities, NaNs and subnormals.
    fn windows(cases: usize) -> Vec<Vec<f32>> {
        let specials = [
            0.0,
            -0.0,
            1.5,
            -2.25,
            f32::INFINITY,
            f32::NEG_INFINITY,
            f32::NAN,
            -f32::NAN,
            1e-40,
            -1e-40,
        ];
        let mut state = 12345u32;
        (0..cases)
            .map(|case| {
                (0..1 + case % 9)
                    .map(|_| {
                        state = state.wrapping_mul(1_664_525).wrapping_add(1_013_904_223);
                        if state.is_multiple_of(4) {
                            specials[(state >> 8) as usize % specials.len()]
                        } else {
                            (state >> 8) as f32 / 1e5 - 80.0
                        }
                    })
                    .collect()
            })
            .collect()
    }

    #[test]
    fn the_3x3_median_is_the_total_orders_middle() {
        for values in windows(20_000) {
            let mut sorted = values.clone();
            sorted.sort_by(f32::total_cmp);
            let expected = sorted[values.len() / 2];
            let median = median_3x3(values.iter().copied()).unwrap();
            assert_eq!(median.to_bits(), expected.to_bits(), "{values:?}");
        }
        assert_eq!(median_3x3(std::iter::empty()), None);
    }

    /// The batch gives each window the median one at a time gives, however
    /// many windows it holds when flushed.
    #[test]
    fn batched_medians_are_the_single_ones() {
        let windows = windows(20_003);
        let mut medians = vec![f32::NAN; windows.len()];
        let mut batch = MedianBatch::new();
        let mut done = |at: usize, median: f32| medians[at] = median;
        for (at, values) in windows.iter().enumerate() {
            batch.push(at, values, &mut done);
            if at % 1001 == 0 {
                batch.flush(&mut done);
            }
        }
        batch.flush(&mut done);
        for (values, median) in windows.iter().zip(&medians) {
            assert_eq!(median.to_bits(), median_of(values).to_bits(), "{values:?}");
        }
    }
}
