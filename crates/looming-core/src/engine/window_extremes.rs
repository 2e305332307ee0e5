//! The nearest and farthest range in every window of a range image's rows,
//! so that a plane fit's range gate (no return of the window far from the
//! cell's own range) is two lookups per row instead of a pass over the
//! window's returns: the fits read windows of 15 to 91 returns around
//! every cell.

use rayon::prelude::*;

/// Per row and column, the smallest and largest range of the row's returns
/// in columns `col - half_cols ..= col + half_cols` (wrapping around the
/// sweep), for a few half widths.
pub(super) struct RowExtremes {
    cols: usize,
    /// The half widths held, ascending.
    half_widths: Vec<usize>,
    /// Per row, per half width held, per column: `[smallest, largest]`,
    /// metres; [`NONE_HELD`] where the window holds no return.
    extremes: Vec<[f64; 2]>,
}

/// The extremes of a window holding no return, `[+inf, -inf]`: no range
/// lies beyond them, so a range gate passes them as it passed the NaN they
/// replace (a comparison with NaN is false), and the widening takes plain
/// comparisons (`minpd`/`maxpd`) where `f64::min` and `max`, passing over
/// NaN, took three instructions each (with the copy `row_extremes` no
/// longer makes, the extremes' instructions fell by more than half).
const NONE_HELD: [f64; 2] = [f64::INFINITY, f64::NEG_INFINITY];

impl RowExtremes {
    /// Extremes of `ranges` (one per cell, row-major; NaN for an empty
    /// cell) for each of `half_widths` that fits the image.
    #[cfg(test)]
    pub fn new(ranges: &[f64], cols: usize, half_widths: &[usize]) -> Self {
        Self::new_in(ranges, cols, half_widths, Vec::new())
    }

    /// [`Self::new`] in `buffer`'s allocation (`into_buffer` of an earlier
    /// scan's: fresh pages cost more to fault in than the extremes).
    pub fn new_in(
        ranges: &[f64],
        cols: usize,
        half_widths: &[usize],
        buffer: Vec<[f64; 2]>,
    ) -> Self {
        let mut wanted: Vec<usize> = half_widths
            .iter()
            .copied()
            .filter(|&half| 2 * half < cols)
            .collect();
        wanted.sort_unstable();
        wanted.dedup();
        let per_row = wanted.len() * cols;
        let mut extremes = buffer;
        extremes.clear();
        extremes.resize(ranges.len() / cols.max(1) * per_row, NONE_HELD);
        if per_row > 0 {
            extremes
                .par_chunks_mut(per_row)
                .zip(ranges.par_chunks(cols))
                .for_each(|(out, row)| row_extremes(row, &wanted, out));
        }
        Self {
            cols,
            half_widths: wanted,
            extremes,
        }
    }

    /// The extremes' allocation, for [`Self::new_in`].
    pub fn into_buffer(self) -> Vec<[f64; 2]> {
        self.extremes
    }

    /// Whether `within` holds for the `[smallest, largest]` range of each
    /// of rows `rows` in columns `col - half_cols ..= col + half_cols`
    /// ([`Self::window`] row by row, the width looked up once; stops at the
    /// first row it fails); None when that half width is not held or a row
    /// is beyond the image.
    pub fn rows_all(
        &self,
        rows: std::ops::RangeInclusive<usize>,
        col: usize,
        half_cols: usize,
        within: impl Fn([f64; 2]) -> bool,
    ) -> Option<bool> {
        let index = self.index_of(half_cols)?;
        // Row after row, the index a stride on: an inclusive range's
        // iteration and the index's products per row were half the loop's
        // instructions (it runs for every window of every cell).
        let (stride, mut at) = (
            self.half_widths.len() * self.cols,
            index(*rows.start(), col),
        );
        for _ in 0..rows_in(&rows) {
            if !within(*self.extremes.get(at)?) {
                return Some(false);
            }
            at += stride;
        }
        Some(true)
    }

    /// `[smallest, largest]` range of `row`'s returns in columns `col -
    /// half_cols ..= col + half_cols`; None when that half width is not held
    /// (or the window is wider than the image). (The fits ask [`Self::rows_all`].)
    #[cfg(test)]
    pub fn window(&self, row: usize, col: usize, half_cols: usize) -> Option<[f64; 2]> {
        let index = self.index_of(half_cols)?;
        self.extremes.get(index(row, col)).copied()
    }

    /// Where the windows of half width `half_cols` keep their extremes,
    /// by (row, column); None when that width is not held.
    fn index_of(&self, half_cols: usize) -> Option<impl Fn(usize, usize) -> usize> {
        let held = self.half_widths.iter().position(|&h| h == half_cols)?;
        let (cols, per_row) = (self.cols, self.half_widths.len() * self.cols);
        Some(move |row, col| row * per_row + held * cols + col)
    }
}

/// How many rows `rows` holds.
#[inline]
pub(super) fn rows_in(rows: &std::ops::RangeInclusive<usize>) -> usize {
    (rows.end() + 1).saturating_sub(*rows.start())
}

/// One row's extremes for each of `wanted` (ascending half widths, each
/// window narrower than the row), into `out` (one row's worth per width).
/// A window of half width `h` is the union of one of half width `a`
/// centred on the column and two shifted by `h - a` either way, which
/// covers it when `h <= 3 a + 1`: so each width comes from the widest
/// already built, widened first where it is too narrow (a few passes over
/// the row in all, whatever the widths), the last pass of each width
/// straight into `out` (and read from there by the next width).
fn row_extremes(ranges: &[f64], wanted: &[usize], out: &mut [[f64; 2]]) {
    let cols = ranges.len();
    let single: Vec<[f64; 2]> = ranges
        .iter()
        .map(|&r| if r.is_nan() { NONE_HELD } else { [r, r] })
        .collect();
    let mut scratch = [vec![NONE_HELD; cols], vec![NONE_HELD; cols]];
    let (mut source, mut source_half): (&[[f64; 2]], usize) = (&single, 0);
    for (&half, target) in wanted.iter().zip(out.chunks_mut(cols)) {
        widen_to(source, source_half, half, target, &mut scratch);
        (source, source_half) = (target, half);
    }
}

/// Into `target`, the extremes of half width `to_half` from `source`'s
/// of half width `from_half` (at most): widened by `3 h + 1` at most per
/// pass, the passes before the last in `scratch` (turn about).
fn widen_to(
    source: &[[f64; 2]],
    from_half: usize,
    to_half: usize,
    target: &mut [[f64; 2]],
    scratch: &mut [Vec<[f64; 2]>; 2],
) {
    let [even, odd] = scratch;
    let (mut built_half, mut turn) = (from_half, 0);
    let mut widest = (3 * built_half + 1).min(to_half);
    if widest == to_half {
        return widen(source, to_half - built_half, target);
    }
    widen(source, widest - built_half, even);
    built_half = widest;
    loop {
        let (built, next) = if turn == 0 {
            (&*even, &mut *odd)
        } else {
            (&*odd, &mut *even)
        };
        widest = (3 * built_half + 1).min(to_half);
        if widest == to_half {
            return widen(built, to_half - built_half, target);
        }
        widen(built, widest - built_half, next);
        (built_half, turn) = (widest, 1 - turn);
    }
}

/// Per column, into `out`, the extremes of `extremes` at the column and at
/// `shift` columns either side (less than the row's width), wrapping around
/// the sweep. Plain comparisons: no extreme is NaN ([`NONE_HELD`]).
fn widen(extremes: &[[f64; 2]], shift: usize, out: &mut [[f64; 2]]) {
    let cols = extremes.len();
    let lower = |a: f64, b: f64| if b < a { b } else { a };
    let upper = |a: f64, b: f64| if b > a { b } else { a };
    let at = |own: [f64; 2], before: [f64; 2], after: [f64; 2]| {
        [
            lower(lower(own[0], before[0]), after[0]),
            upper(upper(own[1], before[1]), after[1]),
        ]
    };
    // The columns whose window wraps around the sweep, then the rest
    // (no wrapping: straight slices the compiler can run through).
    for col in (0..shift.min(cols)).chain(cols.saturating_sub(shift).max(shift)..cols) {
        let before = extremes[(col + cols - shift) % cols];
        let after = extremes[(col + shift) % cols];
        out[col] = at(extremes[col], before, after);
    }
    if cols > 2 * shift {
        let inner = shift..cols - shift;
        for (((out, &own), &before), &after) in out[inner.clone()]
            .iter_mut()
            .zip(&extremes[inner.clone()])
            .zip(&extremes[..cols - 2 * shift])
            .zip(&extremes[2 * shift..])
        {
            *out = at(own, before, after);
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    /// The extremes by looking at every column of the window.
    fn naive(ranges: &[f64], cols: usize, row: usize, col: usize, half: usize) -> [f64; 2] {
        (0..=2 * half)
            .map(|k| ranges[row * cols + (col + cols + k - half) % cols])
            .filter(|r| !r.is_nan())
            .fold(NONE_HELD, |[lo, hi], r| [lo.min(r), hi.max(r)])
    }

    #[test]
    fn windows_match_a_naive_loop_including_across_the_seam() {
        let (rows, cols) = (3, 29);
        let ranges: Vec<f64> = (0..rows * cols)
            .map(|i| {
                if i % 5 == 2 || (i / cols == 2 && i % cols < 9) {
                    f64::NAN
                } else {
                    10.0 + (i as f64 * 1.7).sin() * 5.0
                }
            })
            .collect();
        let halves = [0, 1, 2, 3, 4, 6, 8, 9, 12, 14];
        let extremes = RowExtremes::new(&ranges, cols, &halves);
        for row in 0..rows {
            for col in 0..cols {
                for half in halves {
                    let got = extremes.window(row, col, half).expect("held");
                    let want = naive(&ranges, cols, row, col, half);
                    for (g, w) in got.iter().zip(&want) {
                        assert!(
                            g == w || (g.is_nan() && w.is_nan()),
                            "row {row} col {col} half {half}: {got:?} vs {want:?}"
                        );
                    }
                }
            }
        }
    }

    #[test]
    fn extremes_in_an_earlier_scans_buffer_are_the_fresh_extremes() {
        let cols = 12;
        let ranges: Vec<f64> = (0..3 * cols)
            .map(|i| if i % 5 == 1 { f64::NAN } else { 3.0 + i as f64 })
            .collect();
        let bits = |e: RowExtremes| -> Vec<[u64; 2]> {
            e.into_buffer()
                .iter()
                .map(|x| x.map(f64::to_bits))
                .collect()
        };
        let fresh = bits(RowExtremes::new(&ranges, cols, &[1, 2]));
        let earlier = RowExtremes::new(&[7.0; 5 * 12], cols, &[1, 2, 3]).into_buffer();
        let reused = bits(RowExtremes::new_in(&ranges, cols, &[1, 2], earlier));
        assert_eq!(reused, fresh);
    }

    #[test]
    fn rows_all_asks_each_rows_window_in_turn() {
        let (rows, cols) = (3, 12);
        let ranges: Vec<f64> = (0..rows * cols)
            .map(|i| if i % 4 == 1 { f64::NAN } else { 5.0 + i as f64 })
            .collect();
        let extremes = RowExtremes::new(&ranges, cols, &[1, 2]);
        for col in 0..cols {
            for half in [1, 2] {
                for bound in [8.0, 20.0, 40.0, 60.0] {
                    let below = |[_, far]: [f64; 2]| far.is_nan() || far <= bound;
                    let expected =
                        (0..rows).all(|r| below(extremes.window(r, col, half).expect("held")));
                    assert_eq!(
                        extremes.rows_all(0..=rows - 1, col, half, below),
                        Some(expected)
                    );
                }
            }
        }
        assert_eq!(extremes.rows_all(0..=1, 0, 3, |_| true), None, "not held");
        assert_eq!(
            extremes.rows_all(2..=3, 0, 1, |_| true),
            None,
            "beyond the image"
        );
    }

    #[test]
    fn windows_not_asked_for_or_wider_than_the_image_are_not_held() {
        let ranges = vec![1.0; 2 * 8];
        let extremes = RowExtremes::new(&ranges, 8, &[2, 4]);
        assert!(extremes.window(0, 0, 2).is_some());
        assert!(extremes.window(0, 0, 3).is_none(), "not asked for");
        assert!(extremes.window(0, 0, 4).is_none(), "wider than the image");
    }
}
