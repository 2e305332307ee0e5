//! One source column's returns moved into the target: each return moved by
//! the trajectory from its own time to the time the target fires the
//! column it lands in, its image coordinates turned by the motion.
//!
//! In phases, each a short loop over the column's rows with its results in
//! the worker's arrays ([`ColumnRows`], one entry per row): the first
//! moves, the azimuth turns and landing columns, the second moves into the
//! landing columns (the transform cache's lookups, in the returns' order),
//! the slight turns, the elevation turns, the rows. Per return the same
//! arithmetic in the same order as one return at a time, so the same
//! values; but one return's chain (three turns, five divisions, three
//! roots, two cache lookups: ~250 dependent cycles) was too long for the
//! core to overlap the next return's, where a phase's returns are
//! independent of each other.

use nalgebra::{Isometry3, Point3, Vector3};

use super::moved_vertices::{
    Moving, TransformCache, cross_dot, series_rad, slight, slight_series_rad, small, turn_rad,
};
use super::recurring::{ExactTimes, recurring};
use super::{Source, Target, Vertex};
use crate::engine::atan::atan2;
use crate::engine::grid::{ImageGeometry, between_beams};
use crate::engine::trajectory::Trajectory;
use crate::model::StampNs;

/// What every source column's warp shares.
pub(super) struct ColumnWarp<'r, 's> {
    pub source: &'r Source<'s>,
    pub target: &'r Target<'s>,
    pub geometry: &'r ImageGeometry,
    pub trajectory: &'r Trajectory,
    pub arrivals: &'r [Isometry3<f64>],
    pub scan_offset_ns: StampNs,
}

/// Where a return went once its landing column was known.
#[derive(Clone, Copy, PartialEq, Eq)]
enum Landing {
    /// No return, or one that lands across the seam of the sweep.
    None,
    /// In a column fired when it was seen (or one without a time).
    Seen,
    /// In a column fired at another time: moved again, into that column.
    Column,
}

/// One worker's arrays for a column's warp, one entry per return (the
/// column's rows with one, in order), reused column after column (no
/// allocation per column); the first `live` entries hold the column's.
#[derive(Default)]
pub(super) struct ColumnRows {
    live: usize,
    /// The source row of each return.
    row: Vec<usize>,
    /// The source return's point.
    point: [Vec<f64>; 3],
    time_ns: Vec<StampNs>,
    source_azimuth_rad: Vec<f64>,
    source_elevation_rad: Vec<f64>,
    landing: Vec<Landing>,
    /// The point moved to when it is seen, later into its landing column.
    moved: [Vec<f64>; 3],
    /// The point moved into its landing column, where it is another.
    landed: [Vec<f64>; 3],
    azimuth_rad: Vec<f64>,
    col: Vec<usize>,
    /// The slight turns from `moved` to `landed`.
    turn_rad: Vec<f64>,
    elevation_rad: Vec<f64>,
    /// From the sensor to the moved point.
    range_m: Vec<f64>,
    row_f: Vec<f64>,
    /// Turns past the series' reach, taken again by `atan2`.
    far: Vec<bool>,
    /// The transforms of a column of a few recurring times.
    exact: ExactTimes,
}

impl ColumnWarp<'_, '_> {
    /// The returns of source column `col` moved into the target, into
    /// `column` (and their normals into `normals` where asked), with one
    /// transform cache; `rows`: the worker's arrays.
    pub(super) fn rows<const LINES: bool>(
        &self,
        col: usize,
        (column, normals): (&mut [Vertex], &mut [Vector3<f64>]),
        rows: &mut ColumnRows,
    ) {
        rows.gather(self.source, column.len(), col);
        let mut cache = TransformCache::<LINES>::new(self.trajectory, self.arrivals);
        // A few times recurring along the column: each one's transforms
        // exact, composed once (`recurring.rs`).
        if LINES && recurring(&rows.time_ns[..rows.live]) {
            let mut exact = std::mem::take(&mut rows.exact);
            exact.clear();
            cache.exact = Some(exact);
        }
        if rows.live > 0 {
            // Returns sharing a time share their first transform: their
            // first moves and azimuths come before the cache's lookups of
            // their landing columns. Else each return's first transform is
            // the cache's too, and its lookups alternate with the landing
            // columns' (whose composed departures it may reuse): return by
            // return, in `landings`.
            let shared = (!LINES).then(|| {
                let first_ns = rows.time_ns[0];
                let transform = cache.until(first_ns, first_ns + self.scan_offset_ns);
                rows.first_moves(&transform);
                rows.azimuths(self.geometry);
                transform
            });
            rows.landings(self, col, &mut cache, shared, normals);
            rows.slight_turns();
            rows.elevations();
            let live = rows.live;
            rows_f_at(
                self.geometry,
                (&rows.elevation_rad[..live], &rows.range_m[..live]),
                &rows.row[..live],
                &mut rows.row_f[..live],
            );
        }
        if let Some(exact) = cache.exact.take() {
            rows.exact = exact;
        }
        rows.write(self.geometry, column);
    }
}

impl ColumnRows {
    /// The returns of source column `col` with one, in order, from the
    /// pair's column-major table (`source_columns.rs`: the row-major
    /// arrays hold a column's returns a whole image row apart). Every row
    /// is read, the count of returns moved on past those with one (no
    /// branch on the sky's rows).
    fn gather(&mut self, source: &Source, rows: usize, col: usize) {
        let table = &source.columns;
        self.resize(rows);
        let column = col * rows..(col + 1) * rows;
        // The table's column as slices: no bounds check per read.
        let [px, py, pz] = &table.point;
        let (px, py, pz) = (
            &px[column.clone()],
            &py[column.clone()],
            &pz[column.clone()],
        );
        let time_ns = &table.time_ns[column.clone()];
        let azimuth_rad = &table.azimuth_rad[column.clone()];
        let elevation_rad = &table.elevation_rad[column.clone()];
        let range_m = &table.range_m[column];
        // The worker's arrays as slices, cut to the column's rows: no
        // bounds check, and no reload of their pointers after each store.
        let [x, y, z] = &mut self.point;
        let (x, y, z) = (&mut x[..rows], &mut y[..rows], &mut z[..rows]);
        let (row_of, time) = (&mut self.row[..rows], &mut self.time_ns[..rows]);
        let (azimuth, elevation) = (
            &mut self.source_azimuth_rad[..rows],
            &mut self.source_elevation_rad[..rows],
        );
        let live = if range_m.iter().all(|r| r.is_finite()) {
            // Every row has a return (most columns): copied whole.
            for (dst, src) in [(&mut *x, px), (&mut *y, py), (&mut *z, pz)] {
                dst.copy_from_slice(src);
            }
            time.copy_from_slice(time_ns);
            azimuth.copy_from_slice(azimuth_rad);
            elevation.copy_from_slice(elevation_rad);
            for (row, at) in row_of.iter_mut().enumerate() {
                *at = row;
            }
            rows
        } else {
            let mut live = 0;
            for row in 0..rows {
                // `live <= row < rows`: the index is always in bounds.
                let at = live.min(rows - 1);
                (x[at], y[at], z[at]) = (px[row], py[row], pz[row]);
                row_of[at] = row;
                time[at] = time_ns[row];
                azimuth[at] = azimuth_rad[row];
                elevation[at] = elevation_rad[row];
                live += usize::from(range_m[row].is_finite());
            }
            live
        };
        self.live = live;
        self.landing[..live].fill(Landing::Seen);
    }

    /// Every array `rows` long (their values overwritten before read).
    fn resize(&mut self, rows: usize) {
        if self.row.len() == rows {
            return;
        }
        let [px, py, pz] = &mut self.point;
        let [mx, my, mz] = &mut self.moved;
        let [lx, ly, lz] = &mut self.landed;
        for array in [
            px,
            py,
            pz,
            mx,
            my,
            mz,
            lx,
            ly,
            lz,
            &mut self.source_azimuth_rad,
            &mut self.source_elevation_rad,
            &mut self.azimuth_rad,
            &mut self.turn_rad,
            &mut self.elevation_rad,
            &mut self.range_m,
            &mut self.row_f,
        ] {
            array.resize(rows, 0.0);
        }
        self.row.resize(rows, 0);
        self.time_ns.resize(rows, 0);
        self.landing.resize(rows, Landing::None);
        self.col.resize(rows, 0);
        self.far.resize(rows, false);
    }

    /// The column's vertices, [`Vertex::NONE`] in the rows without one.
    fn write(&self, geometry: &ImageGeometry, column: &mut [Vertex]) {
        // Every vertex is written: the buffer is reused from the last render.
        debug_assert!(self.row[..self.live].iter().all(|&row| row < column.len()));
        let live = self.live;
        // Each array cut to the returns: no bounds check per vertex.
        let (rows, landing) = (&self.row[..live], &self.landing[..live]);
        let [mx, my, mz] = &self.moved;
        let (mx, my, mz) = (&mx[..live], &my[..live], &mz[..live]);
        let (row_f, azimuth) = (&self.row_f[..live], &self.azimuth_rad[..live]);
        let time_ns = &self.time_ns[..live];
        let mut next = 0;
        for (row, vertex) in column.iter_mut().enumerate() {
            *vertex = Vertex::NONE;
            if next < live && rows[next] == row {
                if landing[next] != Landing::None {
                    *vertex = Vertex {
                        position: Point3::new(mx[next], my[next], mz[next]),
                        row: row_f[next],
                        col: geometry.col_f(azimuth[next]),
                        time_ns: time_ns[next],
                    };
                }
                next += 1;
            }
        }
    }

    #[inline]
    fn point_at(&self, at: usize) -> Point3<f64> {
        Point3::new(self.point[0][at], self.point[1][at], self.point[2][at])
    }

    #[inline]
    fn set_moved(&mut self, at: usize, moved: &Point3<f64>) {
        for (axis, value) in self.moved.iter_mut().zip(moved.iter()) {
            axis[at] = *value;
        }
    }

    /// Each return moved to the time it is seen again, about one scan
    /// later (to be refined with the firing time of the column it lands
    /// in), by the column's one `transform`.
    fn first_moves(&mut self, transform: &Moving) {
        for at in 0..self.live {
            let moved = transform.apply(&self.point_at(at));
            self.set_moved(at, &moved);
        }
    }

    /// The moved returns' azimuths (the source's turned by the motion) and
    /// the columns they land in.
    fn azimuths(&mut self, geometry: &ImageGeometry) {
        let live = self.live;
        let [px, py, _] = &self.point;
        let [mx, my, _] = &self.moved;
        let (px, py, mx, my) = (&px[..live], &py[..live], &mx[..live], &my[..live]);
        let source = &self.source_azimuth_rad[..live];
        let azimuth = &mut self.azimuth_rad[..live];
        let far = &mut self.far[..live];
        for at in 0..live {
            let (cross, dot) = cross_dot((px[at], py[at]), (mx[at], my[at]));
            azimuth[at] = source[at] + series_rad(cross / dot);
            far[at] = !small(cross, dot);
        }
        for at in 0..live {
            if far[at] {
                let (cross, dot) = cross_dot((px[at], py[at]), (mx[at], my[at]));
                azimuth[at] = source[at] + atan2(cross, dot);
            }
        }
        for (col, &azimuth) in self.col.iter_mut().zip(azimuth.iter()) {
            *col = geometry.col_of(azimuth);
        }
    }

    /// Where each return lands: a column fired when it was seen, or at
    /// another time (then moved again, into that column's frame), or
    /// across the seam of the sweep (none). Return by return, in the
    /// cache's order; with each return's normal where asked.
    fn landings<const LINES: bool>(
        &mut self,
        warp: &ColumnWarp,
        col: usize,
        cache: &mut TransformCache<LINES>,
        shared: Option<Moving>,
        normals: &mut [Vector3<f64>],
    ) {
        let offset_ns = warp.scan_offset_ns;
        let live = self.live;
        // Every array as a slice cut to the returns: no bounds check, and
        // no reload of their pointers after each store.
        let [px, py, pz] = &self.point;
        let (px, py, pz) = (&px[..live], &py[..live], &pz[..live]);
        let [mx, my, mz] = &mut self.moved;
        let (mx, my, mz) = (&mut mx[..live], &mut my[..live], &mut mz[..live]);
        let [lx, ly, lz] = &mut self.landed;
        let (lx, ly, lz) = (&mut lx[..live], &mut ly[..live], &mut lz[..live]);
        let (time_ns, rows) = (&self.time_ns[..live], &self.row[..live]);
        let (landing, cols) = (&mut self.landing[..live], &mut self.col[..live]);
        let source_azimuth = &self.source_azimuth_rad[..live];
        let azimuth = &mut self.azimuth_rad[..live];
        // The last landing column's transform, where the returns share
        // their time (the cache's for that column: neighbouring rows land
        // in the same column).
        let mut last: Option<(usize, Moving)> = None;
        for at in 0..live {
            let measured_ns = time_ns[at];
            let seen_ns = measured_ns + offset_ns;
            let point = Point3::new(px[at], py[at], pz[at]);
            let mut transform = match shared {
                Some(transform) => transform,
                None => {
                    // `first_moves` and `azimuths` for this return.
                    let transform = cache.until(measured_ns, seen_ns);
                    let moved = transform.apply(&point);
                    (mx[at], my[at], mz[at]) = (moved.x, moved.y, moved.z);
                    azimuth[at] =
                        source_azimuth[at] + turn_rad((point.x, point.y), (moved.x, moved.y));
                    cols[at] = warp.geometry.col_of(azimuth[at]);
                    transform
                }
            };
            let landing_col = cols[at];
            let column_ns = warp.target.column_time_ns[landing_col];
            if column_ns != StampNs::MIN && column_ns != seen_ns {
                // A return that lands across the seam of the sweep would be
                // compared with one fired a whole period earlier or later:
                // no difference there.
                if (column_ns - seen_ns).abs() > offset_ns.abs() / 4 {
                    landing[at] = Landing::None;
                    continue;
                }
                transform = match last {
                    Some((last_col, transform)) if !LINES && last_col == landing_col => transform,
                    _ => cache.until_column(measured_ns, landing_col),
                };
                last = Some((landing_col, transform));
                let landed = transform.apply(&point);
                (lx[at], ly[at], lz[at]) = (landed.x, landed.y, landed.z);
                landing[at] = Landing::Column;
            }
            if let Some(normal) = normals.get_mut(rows[at]) {
                let n = warp.source.surfaces.normal[rows[at] * warp.geometry.cols + col];
                let n = Vector3::new(f64::from(n[0]), f64::from(n[1]), f64::from(n[2]));
                *normal = transform.rotate(&n);
            }
        }
    }

    /// The returns moved again turned on from their first landing: a turn
    /// of the column's small time difference, always within the short
    /// series' reach (from the source return it may be a large one again,
    /// through `atan2`).
    fn slight_turns(&mut self) {
        let live = self.live;
        let [mx, my, mz] = &mut self.moved;
        let [lx, ly, lz] = &self.landed;
        let (mx, my, mz) = (&mut mx[..live], &mut my[..live], &mut mz[..live]);
        let (lx, ly, lz) = (&lx[..live], &ly[..live], &lz[..live]);
        let landing = &self.landing[..live];
        let (turn, far) = (&mut self.turn_rad[..live], &mut self.far[..live]);
        for at in 0..live {
            let (cross, dot) = cross_dot((mx[at], my[at]), (lx[at], ly[at]));
            turn[at] = slight_series_rad(cross / dot);
            far[at] = !slight(cross, dot);
        }
        for at in 0..live {
            if landing[at] == Landing::Column && far[at] {
                turn[at] = turn_rad((mx[at], my[at]), (lx[at], ly[at]));
            }
        }
        let azimuth = &mut self.azimuth_rad[..live];
        for at in 0..live {
            if landing[at] == Landing::Column {
                azimuth[at] += turn[at];
                (mx[at], my[at], mz[at]) = (lx[at], ly[at], lz[at]);
            }
        }
    }

    /// The moved returns' elevations (the source's turned by the motion)
    /// and ranges.
    fn elevations(&mut self) {
        let live = self.live;
        let [px, py, pz] = &self.point;
        let [mx, my, mz] = &self.moved;
        let (px, py, pz) = (&px[..live], &py[..live], &pz[..live]);
        let (mx, my, mz) = (&mx[..live], &my[..live], &mz[..live]);
        let source = &self.source_elevation_rad[..live];
        let elevation = &mut self.elevation_rad[..live];
        let (range, far) = (&mut self.range_m[..live], &mut self.far[..live]);
        for at in 0..live {
            let level_squared = mx[at] * mx[at] + my[at] * my[at];
            let level = level_squared.sqrt();
            let from = ((px[at] * px[at] + py[at] * py[at]).sqrt(), pz[at]);
            let (cross, dot) = cross_dot(from, (level, mz[at]));
            elevation[at] = source[at] + series_rad(cross / dot);
            far[at] = !small(cross, dot);
            range[at] = (level_squared + mz[at] * mz[at]).sqrt();
        }
        for at in 0..live {
            if far[at] {
                let level = (mx[at] * mx[at] + my[at] * my[at]).sqrt();
                let from = ((px[at] * px[at] + py[at] * py[at]).sqrt(), pz[at]);
                let (cross, dot) = cross_dot(from, (level, mz[at]));
                elevation[at] = source[at] + atan2(cross, dot);
            }
        }
    }
}

/// [`ImageGeometry::row_f_at`] of each of a source column's moved returns
/// (`near_rows`: each one's source row), into `rows_f`: the same
/// values, with the ranges' inverses taken first, all together (one
/// division each, which the returns' searches no longer wait on one
/// after the other).
fn rows_f_at(
    geometry: &ImageGeometry,
    (elevation_rad, range_m): (&[f64], &[f64]),
    near_rows: &[usize],
    rows_f: &mut [f64],
) {
    let beams = &geometry.beams.elevations_rad;
    let returns = elevation_rad.iter().zip(range_m).zip(near_rows);
    match geometry.parallax_rad_m.as_deref() {
        None if beams.len() >= 2 => {
            for (((&elevation_rad, _), &near_row), row_f) in returns.zip(rows_f) {
                *row_f = between_beams(beams.len(), |k| beams[k], elevation_rad, near_row);
            }
        }
        Some(parallax) if beams.len().min(parallax.len()) >= 2 => {
            let n = beams.len().min(parallax.len());
            for (inverse_range, &range_m) in rows_f.iter_mut().zip(range_m) {
                *inverse_range = 1.0 / range_m;
            }
            for (((&elevation_rad, &range_m), &near_row), row_f) in returns.zip(rows_f) {
                let inverse_range = *row_f;
                *row_f = if range_m > 0.0 && !range_m.is_nan() {
                    let at = |k: usize| beams[k] + parallax[k] * inverse_range;
                    between_beams(n, at, elevation_rad, near_row)
                } else {
                    geometry.row_f_at(elevation_rad, range_m, near_row)
                };
            }
        }
        _ => {
            for (((&elevation_rad, &range_m), &near_row), row_f) in returns.zip(rows_f) {
                *row_f = geometry.row_f_at(elevation_rad, range_m, near_row);
            }
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::engine::beams::BeamTable;

    #[test]
    fn a_columns_rows_are_each_returns_row_bit_for_bit() {
        let rows = 32;
        let parallaxes = [
            None,
            Some(
                (0..rows)
                    .map(|r| 0.002 * f64::from(r % 5) - 0.004)
                    .collect(),
            ),
            Some(vec![0.01]),
        ];
        for parallax_rad_m in parallaxes {
            let geometry = ImageGeometry {
                rows: rows as usize,
                cols: 16,
                beams: BeamTable::uniform(rows as usize, -0.4, 0.025),
                ring_to_row: None,
                parallax_rad_m,
            };
            // Elevations within, below and above the beams, a NaN; ranges
            // near and far, zero, negative, infinite and NaN.
            let elevation_rad: Vec<f64> = (0..200)
                .map(|i| {
                    if i == 7 {
                        f64::NAN
                    } else {
                        -0.5 + 0.0055 * f64::from(i)
                    }
                })
                .collect();
            let ranges = [0.7, 3.0, 45.0, 0.0, -1.0, f64::INFINITY, f64::NAN];
            let range_m: Vec<f64> = (0..200).map(|i| ranges[i % ranges.len()]).collect();
            let near_rows: Vec<usize> = (0..200).map(|i| (i * 7) % rows as usize).collect();
            let mut rows_f = vec![0.0; 200];
            rows_f_at(
                &geometry,
                (&elevation_rad, &range_m),
                &near_rows,
                &mut rows_f,
            );
            for (i, row_f) in rows_f.iter().enumerate() {
                let one = geometry.row_f_at(elevation_rad[i], range_m[i], near_rows[i]);
                assert_eq!(row_f.to_bits(), one.to_bits(), "return {i}");
            }
        }
    }
}
