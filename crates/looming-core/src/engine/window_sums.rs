//! Running sums of a range image's returns along each row, so that the
//! count, centroid and scatter matrix of the returns in any window of the
//! image come from a few lookups per row instead of a pass over its
//! returns: the plane fits read windows of 15 to 91 returns around every
//! cell, most returns many times over.
//!
//! The sums are of raw coordinates (the LiDAR frame), so a window's scatter
//! is `sum(p p^T) - n c c^T`, exact to about 1e-8 m^2 over a row of 2048
//! returns at up to 100 m: a thousandth of a plane fit's smallest scatter
//! at a noise of 5 mm, and a millionth of a radian on its normal.

use nalgebra::{Matrix3, Vector3};
use rayon::prelude::*;

use super::window_extremes::rows_in;

/// Sums over a set of returns: the count, the coordinates and their
/// products (`xx, xy, xz, yy, yz, zz`).
#[derive(Debug, Clone, Copy, Default, PartialEq)]
pub(super) struct Moments {
    pub count: f64,
    pub sum: [f64; 3],
    pub products: [f64; 6],
}

impl Moments {
    pub fn of_point(p: &Vector3<f64>) -> Self {
        Self {
            count: 1.0,
            sum: [p.x, p.y, p.z],
            products: [
                p.x * p.x,
                p.x * p.y,
                p.x * p.z,
                p.y * p.y,
                p.y * p.z,
                p.z * p.z,
            ],
        }
    }

    pub fn plus(&self, other: &Self) -> Self {
        let mut out = *self;
        out.count += other.count;
        for (a, b) in out.sum.iter_mut().zip(&other.sum) {
            *a += b;
        }
        for (a, b) in out.products.iter_mut().zip(&other.products) {
            *a += b;
        }
        out
    }

    pub fn minus(&self, other: &Self) -> Self {
        let mut out = *self;
        out.count -= other.count;
        for (a, b) in out.sum.iter_mut().zip(&other.sum) {
            *a -= b;
        }
        for (a, b) in out.products.iter_mut().zip(&other.products) {
            *a -= b;
        }
        out
    }

    /// Sum of the squared distances of the returns to the plane of unit
    /// `normal` at `offset` from the origin (`p . normal = offset`), metres
    /// squared: from the moments, without the returns.
    pub fn squared_distances(&self, normal: &Vector3<f64>, offset: f64) -> f64 {
        let [xx, xy, xz, yy, yz, zz] = self.products;
        let (x, y, z) = (normal.x, normal.y, normal.z);
        // sum (p . n)^2, sum p . n: the products and sums projected on n.
        let along_squared =
            xx * x * x + yy * y * y + zz * z * z + 2.0 * (xy * x * y + xz * x * z + yz * y * z);
        let along = self.sum[0] * x + self.sum[1] * y + self.sum[2] * z;
        along_squared - 2.0 * offset * along + self.count * offset * offset
    }

    /// Centroid and scatter matrix (sum of outer products about it); None
    /// for no returns.
    pub fn scatter(&self) -> Option<(Vector3<f64>, Matrix3<f64>)> {
        if self.count < 1.0 {
            return None;
        }
        let centroid = Vector3::from(self.sum) / self.count;
        let [xx, xy, xz, yy, yz, zz] = self.products;
        let n = self.count;
        let (cx, cy, cz) = (centroid.x, centroid.y, centroid.z);
        let covariance = Matrix3::new(
            xx - n * cx * cx,
            xy - n * cx * cy,
            xz - n * cx * cz,
            xy - n * cx * cy,
            yy - n * cy * cy,
            yz - n * cy * cz,
            xz - n * cx * cz,
            yz - n * cy * cz,
            zz - n * cz * cz,
        );
        Some((centroid, covariance))
    }
}

/// Per row, the running sums of its returns' moments over its columns.
pub(super) struct RowSums {
    cols: usize,
    /// `(cols + 1)` entries per row: entry `c` sums the row's columns `0..c`.
    running: Vec<Moments>,
}

impl RowSums {
    /// Sums of `points` (one per cell, row-major; NaN for an empty cell).
    #[cfg(test)]
    pub fn new(points: &[Vector3<f64>], cols: usize) -> Self {
        Self::new_in(points, cols, Vec::new())
    }

    /// [`Self::new`] in `buffer`'s allocation (`into_buffer` of an earlier
    /// scan's: a 64 x 2048 image's sums are 10 MB, whose fresh pages cost
    /// more to fault in than the sums themselves).
    pub fn new_in(points: &[Vector3<f64>], cols: usize, buffer: Vec<Moments>) -> Self {
        let mut running = buffer;
        // Every entry is written below: an earlier scan's buffer of the
        // same size is not filled first (10 MB at 64 x 2048).
        running.resize(points.len() / cols.max(1) * (cols + 1), Moments::default());
        running
            .par_chunks_mut(cols + 1)
            .zip(points.par_chunks(cols.max(1)))
            .for_each(|(running, row)| {
                let mut total = Moments::default();
                running[0] = total;
                for (sum, p) in running[1..].iter_mut().zip(row) {
                    if !p.x.is_nan() {
                        total = total.plus(&Moments::of_point(p));
                    }
                    *sum = total;
                }
            });
        Self { cols, running }
    }

    /// The sums' allocation, for [`Self::new_in`].
    pub fn into_buffer(self) -> Vec<Moments> {
        self.running
    }

    /// Moments of the returns of rows `rows` in columns `col - half_cols
    /// ..= col + half_cols`: the sum of [`Self::window`] over the rows, in
    /// order (the same bits), with the window's span found once for all
    /// rows. None when the window is wider than the image (or a row beyond it).
    pub fn window_over_rows(
        &self,
        rows: std::ops::RangeInclusive<usize>,
        col: usize,
        half_cols: usize,
    ) -> Option<Moments> {
        let mut total = Moments::default();
        if let Some(span) = unwrapped_span(col, half_cols, self.cols) {
            let stride = self.cols + 1;
            let (from, to) = (span.start, span.end);
            // Row after row, the base a stride on (an inclusive range's
            // iteration and a product per row cost more).
            let mut base = rows.start() * stride;
            for _ in 0..rows_in(&rows) {
                let (Some(to), Some(from)) =
                    (self.running.get(base + to), self.running.get(base + from))
                else {
                    return None;
                };
                total = total.plus(&to.minus(from));
                base += stride;
            }
            return Some(total);
        }
        for row in rows {
            total = total.plus(&self.window(row, col, half_cols)?);
        }
        Some(total)
    }

    /// Moments of `row`'s returns in columns `col - half_cols ..= col +
    /// half_cols` (wrapping around the sweep); None when the window is wider
    /// than the image.
    #[inline]
    pub fn window(&self, row: usize, col: usize, half_cols: usize) -> Option<Moments> {
        let base = row * (self.cols + 1);
        if let Some(span) = unwrapped_span(col, half_cols, self.cols) {
            // Most windows: one span, the same sums as below.
            let to = self.running.get(base + span.end)?;
            return Some(to.minus(self.running.get(base + span.start)?));
        }
        let mut total = Moments::default();
        for span in column_spans(col, half_cols, self.cols)? {
            let to = self.running.get(base + span.end)?;
            let from = self.running.get(base + span.start)?;
            total = total.plus(&to.minus(from));
        }
        Some(total)
    }
}

/// The columns `col - half_cols ..= col + half_cols` of an image `cols`
/// wide as one range, where the window does not wrap around the sweep (most
/// windows: [`column_spans`]' chained iterator costs more than the work
/// over a window's few columns); None where it wraps.
#[inline]
pub(super) fn unwrapped_span(
    col: usize,
    half_cols: usize,
    cols: usize,
) -> Option<std::ops::Range<usize>> {
    (col >= half_cols && col + half_cols < cols).then(|| col - half_cols..col + half_cols + 1)
}

/// The columns `col - half_cols ..= col + half_cols` of an image `cols`
/// wide as at most two ranges (where the window wraps around the sweep);
/// None when the window is wider than the image.
pub(super) fn column_spans(
    col: usize,
    half_cols: usize,
    cols: usize,
) -> Option<impl Iterator<Item = std::ops::Range<usize>>> {
    if 2 * half_cols + 1 > cols || col >= cols {
        return None;
    }
    let (first, second) = if let Some(span) = unwrapped_span(col, half_cols, cols) {
        (span, 0..0)
    } else if col < half_cols {
        (0..col + half_cols + 1, cols + col - half_cols..cols)
    } else {
        (col - half_cols..cols, 0..col + half_cols + 1 - cols)
    };
    Some([first, second].into_iter().filter(|span| !span.is_empty()))
}

#[cfg(test)]
mod tests {
    use super::*;

    fn direct(points: &[Vector3<f64>], cells: impl Iterator<Item = usize>) -> Moments {
        cells
            .map(|c| points[c])
            .filter(|p| !p.x.is_nan())
            .fold(Moments::default(), |m, p| m.plus(&Moments::of_point(&p)))
    }

    /// The returns of a `rows x cols` image, every seventh cell empty.
    fn returns_with_gaps(rows: usize, cols: usize) -> Vec<Vector3<f64>> {
        (0..rows * cols)
            .map(|i| {
                if i % 7 == 3 {
                    Vector3::repeat(f64::NAN)
                } else {
                    let f = i as f64;
                    Vector3::new(10.0 + f.sin(), f * 0.25, -1.5 + 0.01 * f)
                }
            })
            .collect()
    }

    #[test]
    fn windows_match_direct_sums_including_across_the_seam() {
        let (rows, cols) = (3, 16);
        let points = returns_with_gaps(rows, cols);
        let sums = RowSums::new(&points, cols);
        for row in 0..rows {
            for col in 0..cols {
                for half in [0, 1, 3, 7] {
                    let cells = (0..=2 * half).map(|k| row * cols + (col + cols + k - half) % cols);
                    let expected = direct(&points, cells);
                    let got = sums.window(row, col, half).expect("fits the image");
                    assert_eq!(got.count, expected.count);
                    for (a, b) in got
                        .sum
                        .iter()
                        .chain(&got.products)
                        .zip(expected.sum.iter().chain(&expected.products))
                    {
                        assert!((a - b).abs() <= 1e-9 * (1.0 + b.abs()), "{a} vs {b}");
                    }
                }
            }
        }
        assert!(sums.window(0, 0, 8).is_none(), "wider than the image");
    }

    #[test]
    fn sums_in_an_earlier_scans_buffer_are_the_fresh_sums() {
        let (rows, cols) = (4, 16);
        let points = returns_with_gaps(rows, cols);
        let fresh = RowSums::new(&points, cols).into_buffer();
        let earlier = RowSums::new(&returns_with_gaps(7, cols), cols).into_buffer();
        assert_eq!(RowSums::new_in(&points, cols, earlier).into_buffer(), fresh);
        // A buffer of another width (two entries longer), with no zero in
        // it where this image's rows start, and one of junk: every entry
        // is written.
        let other_width = RowSums::new(&returns_with_gaps(5, 13), 13).into_buffer();
        assert_eq!(
            RowSums::new_in(&points, cols, other_width).into_buffer(),
            fresh
        );
        let junk = vec![Moments::of_point(&Vector3::new(1.0, 2.0, 3.0)); fresh.len()];
        assert_eq!(RowSums::new_in(&points, cols, junk).into_buffer(), fresh);
    }

    #[test]
    fn windows_over_rows_are_the_rows_windows_summed_in_order() {
        let (rows, cols) = (4, 16);
        let points = returns_with_gaps(rows, cols);
        let sums = RowSums::new(&points, cols);
        for col in 0..cols {
            for half in [0, 2, 5, 7] {
                for (first, last) in [(0, 0), (0, 2), (1, 3), (2, 3)] {
                    let expected = (first..=last).fold(Moments::default(), |m, r| {
                        m.plus(&sums.window(r, col, half).expect("fits"))
                    });
                    let got = sums.window_over_rows(first..=last, col, half);
                    assert_eq!(
                        got,
                        Some(expected),
                        "col {col} half {half} rows {first}..={last}"
                    );
                }
            }
        }
        assert!(
            sums.window_over_rows(0..=1, 0, 8).is_none(),
            "wider than the image"
        );
        assert!(
            sums.window_over_rows(3..=4, 8, 2).is_none(),
            "a row beyond the image"
        );
    }

    /// Four returns near a plane 20 m ahead, and their moments.
    fn four_returns() -> ([Vector3<f64>; 4], Moments) {
        let points = [
            Vector3::new(20.0, 1.0, -1.7),
            Vector3::new(20.1, 1.2, -1.69),
            Vector3::new(19.9, 1.1, -1.71),
            Vector3::new(20.05, 0.9, -1.7),
        ];
        let moments = points
            .iter()
            .fold(Moments::default(), |m, p| m.plus(&Moments::of_point(p)));
        (points, moments)
    }

    #[test]
    fn squared_distances_match_the_returns_distances() {
        let (points, moments) = four_returns();
        let normal = Vector3::new(0.1, -0.2, 1.0).normalize();
        let offset = -1.2;
        let direct: f64 = points
            .iter()
            .map(|p| (p.dot(&normal) - offset).powi(2))
            .sum();
        assert!((moments.squared_distances(&normal, offset) - direct).abs() < 1e-10);
    }

    #[test]
    fn the_scatter_of_moments_is_the_centred_scatter() {
        let (points, moments) = four_returns();
        let (centroid, scatter) = moments.scatter().expect("points");
        let mean = points.iter().sum::<Vector3<f64>>() / 4.0;
        let centred: Matrix3<f64> = points
            .iter()
            .map(|p| (p - mean) * (p - mean).transpose())
            .sum();
        assert!((centroid - mean).norm() < 1e-12);
        assert!((scatter - centred).abs().max() < 1e-10);
    }
}
