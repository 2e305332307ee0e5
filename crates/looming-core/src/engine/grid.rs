//! Range images: rows are beams, columns are azimuth bins (forward at the
//! centre, turning clockwise like the sensor), each cell keeping its nearest
//! return. Also the continuous (row, column) coordinates of any direction, used
//! to render warped scans into the image.

use rayon::prelude::*;
use std::f64::consts::{PI, TAU};

use crate::model::Scan;

use super::atan::atan2;
use super::beams::BeamTable;
use super::rings;

/// Beam spacing over column spacing beyond which rows are sparse.
const SPARSE_ROW_RATIO: f64 = 12.0;

/// Marks an empty cell in `point`.
pub const NO_POINT: u32 = u32::MAX;

/// The shape of the range images of a pair and how directions map to cells.
#[derive(Debug, Clone)]
pub struct ImageGeometry {
    pub rows: usize,
    pub cols: usize,
    /// Beam elevations, row order (lowest first).
    pub beams: BeamTable,
    /// Row of each ring value when rows come from the clouds' `ring` field
    /// (rings sorted by elevation, so any numbering works); else rows come
    /// from elevation.
    pub ring_to_row: Option<Vec<usize>>,
    /// Per row, `c` of the beam's measured elevation `beam + c / range`
    /// (rad m), when rows come from rings: a laser mounted off the rotation
    /// axis (HDL-64E: ~0.2 m) is seen from the frame origin higher at short
    /// range, by more than the beam spacing within 10 m. `None`: on the axis.
    pub parallax_rad_m: Option<Vec<f64>>,
}

impl ImageGeometry {
    /// Continuous column of an azimuth: 0 behind the sensor, `cols / 2` straight
    /// ahead, increasing clockwise seen from above; in [0, cols).
    #[inline]
    pub fn col_f(&self, azimuth_rad: f64) -> f64 {
        // `rem_euclid(1.0)` without its `fmod` call, and the turn's
        // reciprocal multiplied instead of divided by (within an ulp): this
        // runs for every return and every vertex of every render, where a
        // division was a sixth of a vertex's time.
        let turns = (PI - azimuth_rad) * (1.0 / TAU);
        (turns - turns.floor()) * self.cols as f64
    }

    /// Cell column of an azimuth (nearest bin centre).
    #[inline]
    pub fn col_of(&self, azimuth_rad: f64) -> usize {
        // `col_f` is in [0, cols): only the last half column wraps (no
        // integer division: every vertex of every render). Through `i64`:
        // `as usize` saturates with a longer sequence.
        let col = (self.col_f(azimuth_rad) + 0.5) as i64 as usize;
        if col >= self.cols {
            col - self.cols
        } else {
            col
        }
    }

    /// Continuous row of an elevation (lasers on the rotation axis).
    pub fn row_f(&self, elevation_rad: f64) -> f64 {
        self.beams.row_f(elevation_rad)
    }

    /// Continuous row of a direction seen at `range_m`: between the beams'
    /// elevations at that range, so that a laser off the rotation axis keeps
    /// its own row near the sensor (each return's coordinate then lies
    /// within its cell, which the renderer relies on). The beams are
    /// searched outward from `near_row` (a row at or next to the answer:
    /// a return's own row, before or after the motion between two scans)
    /// instead of by bisection, in a step or two instead of six
    /// unpredictable ones; any row gives the same value, as the beams are in
    /// elevation order.
    pub fn row_f_at(&self, elevation_rad: f64, range_m: f64, near_row: usize) -> f64 {
        let beams = &self.beams.elevations_rad;
        let parallax = self
            .parallax_rad_m
            .as_deref()
            .filter(|_| range_m > 0.0 && !range_m.is_nan());
        let n = parallax.map_or(beams.len(), |p| beams.len().min(p.len()));
        if n < 2 {
            return self.row_f(elevation_rad);
        }
        // One division per return, not one per probe of the search.
        let inverse_range = 1.0 / range_m;
        let at = |k: usize| match parallax {
            Some(parallax) => beams[k] + parallax[k] * inverse_range,
            None => beams[k],
        };
        between_beams(n, at, elevation_rad, near_row)
    }

    /// Continuous (row, column) of a return at `(azimuth, elevation)`,
    /// radians, seen at `range_m` ([`Self::row_f_at`], [`Self::col_f`]).
    #[inline]
    pub fn coords_of(
        &self,
        (azimuth_rad, elevation_rad): (f64, f64),
        range_m: f64,
        near_row: usize,
    ) -> (f64, f64) {
        (
            self.row_f_at(elevation_rad, range_m, near_row),
            self.col_f(azimuth_rad),
        )
    }

    pub fn cells(&self) -> usize {
        self.rows * self.cols
    }

    /// Beams much further apart than columns (an 8- or 16-beam sensor with
    /// thousands of columns: OS0-8's beams are 11 degrees apart, its
    /// columns 0.18): neighbouring beams see different surfaces, so
    /// surfaces are fitted and rendered along each beam's ring instead of
    /// across beams.
    pub fn sparse_rows(&self) -> bool {
        let e = &self.beams.elevations_rad;
        if e.len() < 2 || self.cols == 0 {
            return e.len() == 1;
        }
        let row_step = (e[e.len() - 1] - e[0]) / (e.len() - 1) as f64;
        let col_step = TAU / self.cols as f64;
        row_step > SPARSE_ROW_RATIO * col_step
    }

    /// The cells next to `cell`: [`neighbours`](Self::neighbours)`(cell, 1, 1)`
    /// (the same cells in the same order) from an array instead of the
    /// general window's iterator chain, as the per-cell passes take them
    /// for every cell.
    pub fn neighbours_3x3(&self, cell: usize) -> impl Iterator<Item = usize> + use<> {
        let cols = self.cols;
        let (row, col) = (cell / cols, cell % cols);
        let cols_i = cols as i64;
        let around = [-1, 0, 1].map(|dc| wrap_col(col as i64 + dc, cols_i));
        let mut cells = [0usize; 8];
        let mut count = 0;
        for (dr, r) in [(-1, row.wrapping_sub(1)), (0, row), (1, row + 1)] {
            if r >= self.rows {
                continue;
            }
            for (dc, c) in [-1, 0, 1].into_iter().zip(around) {
                if dr != 0 || dc != 0 {
                    cells[count] = r * cols + c;
                    count += 1;
                }
            }
        }
        cells.into_iter().take(count)
    }

    /// The cells around `cell` within `half_rows` beams and `half_cols`
    /// columns, the cell itself excluded. Columns wrap around (the sweep is a
    /// circle), rows do not.
    pub fn neighbours(
        &self,
        cell: usize,
        half_rows: usize,
        half_cols: usize,
    ) -> impl Iterator<Item = usize> + '_ {
        let (row, col) = ((cell / self.cols) as i64, (cell % self.cols) as i64);
        let (half_rows, half_cols) = (half_rows as i64, half_cols as i64);
        (-half_rows..=half_rows).flat_map(move |dr| {
            (-half_cols..=half_cols).filter_map(move |dc| {
                let r = row + dr;
                if (dr == 0 && dc == 0) || r < 0 || r >= self.rows as i64 {
                    return None;
                }
                Some(r as usize * self.cols + wrap_col(col + dc, self.cols as i64))
            })
        })
    }
}

/// The continuous row of `elevation_rad` between the `n >= 2` beams'
/// elevations `at(k)` (in order), searched from `near_row`.
#[inline]
pub(crate) fn between_beams(
    n: usize,
    at: impl Fn(usize) -> f64,
    elevation_rad: f64,
    near_row: usize,
) -> f64 {
    let below = walk_to_partition(n, &at, elevation_rad, near_row);
    let k = below.clamp(1, n - 1) - 1;
    let span = at(k + 1) - at(k);
    if span > 0.0 {
        k as f64 + (elevation_rad - at(k)) / span
    } else {
        k as f64
    }
}

/// How many of the increasing values `at(0..n)` are at or below `value`
/// (`partition_point`; 0 for NaN), by walking from `start`: as many steps
/// as `start` is away from the answer.
fn walk_to_partition(n: usize, at: &impl Fn(usize) -> f64, value: f64, start: usize) -> usize {
    if value.is_nan() {
        return 0;
    }
    let mut k = start.min(n);
    while k < n && at(k) <= value {
        k += 1;
    }
    while k > 0 && at(k - 1) > value {
        k -= 1;
    }
    k
}

/// `col.rem_euclid(cols)`, without an integer division where `col` is
/// within one turn of the image (neighbours, triangles: every cell, many
/// times per pair).
pub(super) fn wrap_col(col: i64, cols: i64) -> usize {
    let once = if col < 0 {
        col + cols
    } else if col >= cols {
        col - cols
    } else {
        col
    };
    if (0..cols).contains(&once) {
        once as usize
    } else {
        col.rem_euclid(cols) as usize
    }
}

/// The columns left of, at and right of `col`, wrapping around the sweep
/// (the per-cell passes' 3x3 windows, without a division).
pub(super) fn wrapped_around(col: usize, cols: usize) -> [usize; 3] {
    [
        if col == 0 { cols - 1 } else { col - 1 },
        col,
        if col + 1 == cols { 0 } else { col + 1 },
    ]
}

/// Azimuth and elevation of a point.
#[inline]
pub fn angles(p: &[f32; 3]) -> (f64, f64) {
    (azimuth(p), elevation(p))
}

/// Elevation of a point (the second of [`angles`]), alone: where only it is
/// wanted, the azimuth's `atan2` would still be paid (a library call the
/// compiler keeps), once per return per pair.
#[inline]
pub fn elevation(p: &[f32; 3]) -> f64 {
    let (x, y, z) = (f64::from(p[0]), f64::from(p[1]), f64::from(p[2]));
    // `sqrt` of the squares, not `hypot`: a LiDAR return's coordinates
    // neither overflow nor underflow when squared, and libm's `hypot`,
    // which guards against both, cost 3 % of a blind log's process.
    // (`atan::atan2`, not libm's: within 1e-12 rad, inlined.)
    atan2(z, (x * x + y * y).sqrt())
}

/// Azimuth of a point (the first of [`angles`]).
#[inline]
pub fn azimuth(p: &[f32; 3]) -> f64 {
    atan2(f64::from(p[1]), f64::from(p[0]))
}

/// One scan gridded.
#[derive(Debug, Clone)]
pub struct RangeImage {
    /// Range of the nearest return, metres (NaN: empty).
    pub range_m: Vec<f32>,
    /// Index of that return in the scan's points (`NO_POINT`: empty).
    pub point: Vec<u32>,
    /// Cell of every point of the scan (`NO_POINT` if outside the image).
    pub point_cell: Vec<u32>,
    /// Per point, its cell when the point is the surface that cell measured:
    /// within 5 % of the cell's nearest range. A return hidden behind that
    /// surface (a second echo, a point seen through a gap) takes none of the
    /// cell's values (`NO_POINT`).
    pub point_surface: Vec<u32>,
}

impl RangeImage {
    /// The cell whose surface point `index` is (see `point_surface`).
    pub fn surface_cell(&self, index: usize) -> Option<usize> {
        let cell = *self.point_surface.get(index)?;
        (cell != NO_POINT).then_some(cell as usize)
    }

    pub fn build(scan: &Scan, geometry: &ImageGeometry) -> Self {
        let cells = geometry.cells();
        let mut range_m = vec![f32::NAN; cells];
        let mut point = vec![NO_POINT; cells];
        // Each point's cell and range on both cores (angles per point),
        // then the nearest return per cell in point order.
        let (point_cell, point_range_m): (Vec<u32>, Vec<f32>) = scan
            .points_m
            .par_iter()
            .enumerate()
            .map(|(index, p)| {
                let cell = cell_of(scan, index, p, geometry).map_or(NO_POINT, |c| c as u32);
                (cell, (p[0] * p[0] + p[1] * p[1] + p[2] * p[2]).sqrt())
            })
            .unzip();
        for (index, (&cell, &r)) in point_cell.iter().zip(&point_range_m).enumerate() {
            if cell == NO_POINT {
                continue;
            }
            let cell = cell as usize;
            // Nearest return wins; ties keep the earlier point (deterministic).
            if range_m[cell].is_nan() || r < range_m[cell] {
                range_m[cell] = r;
                point[cell] = index as u32;
            }
        }
        let point_surface = point_cell
            .iter()
            .zip(&point_range_m)
            .map(|(&cell, &r)| {
                if cell != NO_POINT && r <= range_m[cell as usize] * 1.05 {
                    cell
                } else {
                    NO_POINT
                }
            })
            .collect();
        Self {
            range_m,
            point,
            point_cell,
            point_surface,
        }
    }
}

fn cell_of(scan: &Scan, index: usize, p: &[f32; 3], geometry: &ImageGeometry) -> Option<usize> {
    let azimuth = azimuth(p);
    let row = match (&scan.ring, &geometry.ring_to_row) {
        (Some(rings), Some(ring_to_row)) => *ring_to_row.get(usize::from(rings[index]))?,
        // The elevation only where no ring gives the row.
        _ => geometry.beams.row_of(elevation(p)),
    };
    (row < geometry.rows).then(|| row * geometry.cols + geometry.col_of(azimuth))
}

/// The image geometry of a pair: rows from `ring` when both clouds have it
/// (beam elevations measured per ring), else a beam table inferred from the
/// current scan; columns from `columns`, else the most points any row holds
/// over `firings_per_column` (a coarser grid: `EngineConfig::firings_per_column`).
///
/// `previous_cols`: the columns the previous pair's images had; kept where
/// this scan's count is within [`KEPT_COLUMNS_TOLERANCE`] of it.
/// `known_rings`: a geometry of rows from rings whose beam table, rings'
/// rows and parallax to take where its rows are this pair's and the current
/// scan's returns still lie in them ([`rings::rings_still_hold`]), instead
/// of measuring them on the current scan (`EngineCache::geometry_for`).
/// Also returns whether they were taken.
pub(crate) fn geometry_for(
    (previous, current): (&Scan, &Scan),
    (columns, firings_per_column): (Option<usize>, usize),
    previous_cols: Option<usize>,
    known_rings: Option<&ImageGeometry>,
) -> Option<(ImageGeometry, bool)> {
    let firings_per_column = firings_per_column.max(1);
    if let (Some(rings), Some(_)) = (&current.ring, &previous.ring) {
        let rows = rings
            .iter()
            .copied()
            .max()
            .map_or(0, |m| usize::from(m) + 1);
        if rows == 0 {
            return None;
        }
        let known = known_rings
            .filter(|g| g.rows == rows && rings::rings_still_hold(g, current))
            .and_then(|g| {
                Some((
                    g.beams.clone(),
                    g.ring_to_row.clone()?,
                    g.parallax_rad_m.clone(),
                ))
            });
        let taken = known.is_some();
        let (beams, ring_to_row, parallax_rad_m) = match known {
            Some(known) => known,
            None => rings::ring_elevations(current, rows)?,
        };
        let cols = columns.unwrap_or_else(|| {
            let counted = most_points_per_row(rings.iter().map(|&r| usize::from(r)), rows);
            kept_columns(counted.div_ceil(firings_per_column), previous_cols)
        });
        let geometry = ImageGeometry {
            rows,
            cols,
            beams,
            ring_to_row: Some(ring_to_row),
            parallax_rad_m,
        };
        return (cols >= 8).then_some((geometry, taken));
    }
    let elevations: Vec<f32> = current
        .points_m
        .par_iter()
        .map(|p| elevation(p) as f32)
        .collect();
    let beams = BeamTable::infer(&elevations, 256)?;
    let rows = beams.len();
    let cols = columns.unwrap_or_else(|| {
        let counted =
            most_points_per_row(elevations.iter().map(|&e| beams.row_of(f64::from(e))), rows);
        kept_columns(counted.div_ceil(firings_per_column), previous_cols)
    });
    let geometry = ImageGeometry {
        rows,
        cols,
        beams,
        ring_to_row: None,
        parallax_rad_m: None,
    };
    (cols >= 8).then_some((geometry, false))
}

/// The previous pair's column count where `counted` (this scan's most
/// points in a row) is within [`KEPT_COLUMNS_TOLERANCE`] of it, else
/// `counted`. A real sensor's count moves by a few percent from scan to
/// scan (dropouts, doubled returns: KITTI 2068-2147); a new count changes
/// the image's cells, and the next pair then rebuilds the previous scan's
/// image and surfaces instead of reusing them (`EngineCache`).
fn kept_columns(counted: usize, previous_cols: Option<usize>) -> usize {
    match previous_cols {
        Some(cols)
            if (counted as f64 - cols as f64).abs() <= KEPT_COLUMNS_TOLERANCE * cols as f64 =>
        {
            cols
        }
        _ => counted,
    }
}

/// Largest relative change of a scan's column count that keeps the
/// previous pair's.
const KEPT_COLUMNS_TOLERANCE: f64 = 0.05;

fn most_points_per_row(rows_of_points: impl Iterator<Item = usize>, rows: usize) -> usize {
    let mut counts = vec![0usize; rows];
    for row in rows_of_points {
        if row < rows {
            counts[row] += 1;
        }
    }
    counts.into_iter().max().unwrap_or(0)
}

#[cfg(test)]
mod tests {
    use super::*;

    /// The reference: `partition_point` by bisection.
    fn bisect_to_partition(n: usize, at: &impl Fn(usize) -> f64, value: f64) -> usize {
        let (mut lo, mut hi) = (0usize, n);
        while lo < hi {
            let mid = (lo + hi) / 2;
            if at(mid) <= value {
                lo = mid + 1;
            } else {
                hi = mid;
            }
        }
        lo
    }

    #[test]
    fn walking_finds_the_partition_bisection_finds() {
        // Unevenly spaced increasing values, every start, values between,
        // on and outside them.
        let values = [-0.43, -0.4, -0.31, -0.3, -0.1, 0.0, 0.02, 0.2];
        let at = |k: usize| values[k];
        let n = values.len();
        for probe in -50..=30 {
            let value = f64::from(probe) * 0.01;
            let bisected = bisect_to_partition(n, &at, value);
            assert_eq!(bisected, values.partition_point(|&v| v <= value));
            for start in 0..=n + 2 {
                assert_eq!(walk_to_partition(n, &at, value, start), bisected);
            }
        }
        assert_eq!(walk_to_partition(n, &at, f64::NAN, 4), 0);
        assert_eq!(bisect_to_partition(n, &at, f64::NAN), 0);
    }

    #[test]
    fn a_scans_column_count_keeps_the_previous_pairs_within_five_percent() {
        assert_eq!(kept_columns(2081, None), 2081);
        // KITTI's counts over consecutive scans keep the first.
        for counted in [2106, 2093, 2068, 2141, 2147, 2137] {
            assert_eq!(kept_columns(counted, Some(2081)), 2081, "{counted}");
        }
        // A real change of resolution takes the new count.
        assert_eq!(kept_columns(1024, Some(2081)), 1024);
        assert_eq!(kept_columns(2200, Some(2081)), 2200);
    }

    #[test]
    fn the_3x3_neighbours_are_the_windows() {
        for (rows, cols) in [(1, 1), (1, 5), (2, 1), (2, 2), (3, 3), (4, 7), (64, 2048)] {
            let geometry = ImageGeometry {
                rows,
                cols,
                beams: BeamTable::uniform(rows, -0.4, 0.03),
                ring_to_row: None,
                parallax_rad_m: None,
            };
            for cell in (0..rows * cols).step_by(1 + rows * cols / 500) {
                let expected: Vec<usize> = geometry.neighbours(cell, 1, 1).collect();
                let fast: Vec<usize> = geometry.neighbours_3x3(cell).collect();
                assert_eq!(fast, expected, "{rows} x {cols}, cell {cell}");
            }
        }
    }
}
