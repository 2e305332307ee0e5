//! Every cell's surface fit ([`fit_cell`]), written into the per-cell
//! fields of [`Surfaces`] tile by tile.

use rayon::prelude::*;

use super::ring::fit_ring_cell;
use super::window::{fit_window, gated_window, too_narrow, window_rows, within_range_gate};
use super::{
    CellSurface, EMPTY, MAX_GROWTH, Returns, Scratch, SurfaceParams, Surfaces, facing_sensor,
    oriented, plane_tolerance_m,
};
use crate::engine::grid::ImageGeometry;
use nalgebra::Vector3;

impl Surfaces {
    /// Every cell's fit (`fit_cell`), a band of rows per task on rayon's
    /// workers, a tile of the band's columns at a time, written straight
    /// into the per-cell fields (no array of [`CellSurface`] to split field
    /// by field), with the azimuth and elevation of its `direction` (NaN
    /// where empty).
    pub(super) fn write_fits(
        &mut self,
        returns: &Returns,
        geometry: &ImageGeometry,
        params: SurfaceParams,
        noise_m_per_row: &[f32],
    ) {
        let cols = geometry.cols.max(1);
        let carry = cols >= CARRY_MIN_COLS;
        let band = cols * (geometry.rows / BANDS).clamp(1, MAX_BAND_ROWS);
        let bands = (
            self.range_m.par_chunks_mut(band),
            self.direction.par_chunks_mut(band),
            self.normal.par_chunks_mut(band),
            self.incidence_cos.par_chunks_mut(band),
            self.support.par_chunks_mut(band),
            self.edge.par_chunks_mut(band),
        );
        bands.into_par_iter().enumerate().for_each_init(
            // One scratch buffer per worker: no allocation per cell.
            Scratch::default,
            |scratch, (index, out)| {
                let (range_m, direction, normal, incidence_cos, support, edge) = out;
                let first = index * band;
                // Tile by tile across the band's rows (`TILE_COLS`).
                for tile in (0..cols).step_by(TILE_COLS) {
                    for row_start in (0..range_m.len()).step_by(cols) {
                        let row = (first + row_start) / cols;
                        let params = SurfaceParams {
                            range_noise_m: f64::from(noise_m_per_row[row]),
                            ..params
                        };
                        let at = row_start + tile..row_start + (tile + TILE_COLS).min(cols);
                        // The growth the last non-empty cell to the left
                        // settled on (`fit_cell`'s `first_grow`), on fine
                        // grids only (`CARRY_MIN_COLS`).
                        let mut left_grow = 1;
                        // On fine grids every odd column's cell waits for
                        // its right neighbour's fit, to be derived from it
                        // and its left one's (`settle_between`), but at a
                        // tile's last column.
                        let end = at.end;
                        // The last cell fitted (non-empty) and its growth,
                        // and the cell waiting with its left one's growth.
                        let mut last: Option<(CellSurface, usize)> = None;
                        let mut deferred = None;
                        let mut write = |at: usize, fit: &CellSurface| {
                            range_m[at] = fit.range_m;
                            direction[at] = fit.direction;
                            normal[at] = fit.normal;
                            incidence_cos[at] = fit.incidence_cos;
                            support[at] = fit.support;
                            edge[at] = fit.edge;
                        };
                        for at in at.clone() {
                            if carry && (at - row_start) % 2 == 1 && at + 1 < end {
                                deferred = Some((at, left_grow));
                                continue;
                            }
                            let cell = first + at;
                            let (mut fit, mut grow) =
                                fit_cell(returns, geometry, cell, params, scratch, left_grow);
                            if let Some((between_at, its_left_grow)) = deferred.take() {
                                let settled = settle_between(
                                    (returns, geometry, params, scratch),
                                    (first + between_at, its_left_grow),
                                    last.as_ref(),
                                    (cell, &mut fit, &mut grow),
                                );
                                write(between_at, &settled);
                            }
                            if carry && fit.range_m.is_finite() {
                                left_grow = grow;
                            }
                            last = fit.range_m.is_finite().then_some((fit, grow));
                            write(at, &fit);
                        }
                    }
                }
            },
        );
        self.write_angles();
    }
}

/// Rows of a band of [`Surfaces::write_fits`] (one task) at most, bands
/// at least (where the image has the rows: tasks for every worker), and
/// columns of a band's tiles: a tile's window rows' running sums and range
/// extremes (some 80 kB at 64 x 2048) stay in the cache while its cells read
/// them (row by row, the 7 rows of the widest windows were some 1.2 MB, read
/// again by the next row's windows after leaving the cache).
const MAX_BAND_ROWS: usize = 8;
const BANDS: usize = 8;
pub(super) const TILE_COLS: usize = 64;

/// Columns a scan needs for [`Surfaces::write_fits`] to start each cell's
/// growth at its left neighbour's. Once a wide window is needed (a close
/// object) the start carries on across the rest of the tile, and a wider
/// window than a cell needs straddles more edges. On a fine grid (64 x
/// 2048: a tile is 11 degrees) that cost nothing on the accuracy tables and
/// fitted 43 % fewer windows; on a coarse one (32 x 512: 45 degrees) the
/// crossing car's cells flagged moving fell from 106 to 30 (to 72 with
/// the start taken from 3 beams again every fourth column).
pub(super) const CARRY_MIN_COLS: usize = 1024;

/// Fit the cell's plane in its window; where the window's points spread over
/// less than a few noise sigmas in the plane (a close object seen by a dense
/// sensor) the normal would be mostly noise, so the window grows (up to 7
/// beams). Growth starts at `first_grow` (1: 3 beams), and the growth the
/// fit settled on comes back with it: on fine grids ([`CARRY_MIN_COLS`])
/// [`Surfaces::write_fits`] starts each cell at its left neighbour's, as the
/// spread needed comes with the range and the surface, which neighbours
/// mostly share (1.5 % of the synthetic 64 x 2048 log's cells get a wider
/// window than they would growing from 3 beams).
pub(super) fn fit_cell(
    returns: &Returns,
    geometry: &ImageGeometry,
    cell: usize,
    params: SurfaceParams,
    scratch: &mut Scratch,
    first_grow: usize,
) -> (CellSurface, usize) {
    if params.sparse_rows {
        return (fit_ring_cell(returns, geometry, cell, params, scratch), 1);
    }
    let mut best = (EMPTY, 1);
    for grow in first_grow.clamp(1, MAX_GROWTH)..=MAX_GROWTH {
        let window = (grow, grow * params.half_cols);
        let gated = gated_window(returns, geometry, cell, window);
        if grow < MAX_GROWTH && gated.as_ref().is_some_and(|g| too_narrow(g, params)) {
            continue;
        }
        let (surface, spread) = fit_window(
            returns,
            geometry,
            cell,
            params,
            window,
            gated.as_ref(),
            scratch,
        );
        best = (surface, grow);
        if spread.is_none_or(|s| s >= 2.0 * params.range_noise_m) {
            break;
        }
    }
    best
}

/// The surface of `cell`, which waited for its right neighbour's fit
/// (`right_cell`, its `fit` and growth `grow`, from `its_left_grow`):
/// derived from its neighbours' ([`between`]) where their growths agree
/// and they make one plane, else fitted from its left neighbour's growth;
/// where it settles on another growth, the right neighbour is fitted
/// again from it, as the growth carries cell by cell (the order of the
/// carry mattered: without it the synthetic `follow`'s fused RMSE rose
/// from 0.0087 to 0.0103).
fn settle_between(
    (returns, geometry, params, scratch): (&Returns, &ImageGeometry, SurfaceParams, &mut Scratch),
    (cell, its_left_grow): (usize, usize),
    left: Option<&(CellSurface, usize)>,
    (right_cell, fit, grow): (usize, &mut CellSurface, &mut usize),
) -> CellSurface {
    let derived = left
        .filter(|(_, left_grow)| left_grow == grow)
        .and_then(|(left, _)| between(returns, geometry, cell, params, [left, fit]));
    if let Some(derived) = derived {
        return derived;
    }
    let (own, own_grow) = fit_cell(returns, geometry, cell, params, scratch, its_left_grow);
    if own.range_m.is_finite() && own_grow != its_left_grow {
        (*fit, *grow) = fit_cell(returns, geometry, right_cell, params, scratch, own_grow);
    }
    own
}

/// The surface of `cell` from its two neighbours' fits in its row (`[left,
/// right]`), where both are one plane: fitted without an edge, with
/// normals within [`BETWEEN_MAX_ANGLE_COS`], the cell's return within its
/// tolerance of the plane between theirs. Their windows, one column either
/// side of the cell's, hold every return of its own: the plane between
/// theirs (the mean of their points and normals) stands for the plane of
/// its window, and half of a fine grid's cells take no fit of their own.
/// `None` where a fit must decide.
fn between(
    returns: &Returns,
    geometry: &ImageGeometry,
    cell: usize,
    params: SurfaceParams,
    [left, right]: [&CellSurface; 2],
) -> Option<CellSurface> {
    // The neighbours' own tests first: they cost a few loads, where the
    // range gate reads three rows' extremes (on braking KITTI two in three
    // odd cells tried are not derived).
    if left.edge || right.edge || left.plane_point[0].is_nan() || right.plane_point[0].is_nan() {
        return None;
    }
    let normal_of = |s: &CellSurface| Vector3::from(s.normal.map(f64::from));
    let (a, b) = (normal_of(left), normal_of(right));
    if a.dot(&b) < BETWEEN_MAX_ANGLE_COS {
        return None;
    }
    let center = returns.point(cell)?;
    // Its own window within its range gate (as `gated_window` finds it).
    let (rows, col) = window_rows(geometry, cell, 1);
    let gated = within_range_gate(returns, (rows, col, params.half_cols), returns.ranges[cell]);
    if gated != Some(true) {
        return None;
    }
    let normal = (a + b).normalize();
    let point = (Vector3::from(left.plane_point) + Vector3::from(right.plane_point)) * 0.5;
    let range = center.norm();
    let tolerance = plane_tolerance_m(params, range);
    // On both neighbours' planes, and on the plane between.
    let off = |p: Vector3<f64>, n: &Vector3<f64>| (center - p).dot(n).abs() > tolerance;
    if off(point, &normal)
        || off(Vector3::from(left.plane_point), &a)
        || off(Vector3::from(right.plane_point), &b)
    {
        return None;
    }
    let direction = center / range;
    Some(CellSurface {
        residual_m: (center - point).dot(&(-facing_sensor(normal, &direction))) as f32,
        support: left.support.min(right.support),
        edge: false,
        ..oriented(&center, &point, normal, tolerance)
    })
}

/// Normals of two neighbours' planes closer than this (cosine; 3 degrees)
/// make one plane for [`between`].
const BETWEEN_MAX_ANGLE_COS: f64 = 0.9986;
