//! Every cell's surface fit ([`fit_cell`]), written into the per-cell
//! fields of [`Surfaces`] tile by tile.

use rayon::prelude::*;

use super::ring::fit_ring_cell;
use super::window::{fit_window, gated_window, too_narrow};
use super::{CellSurface, EMPTY, MAX_GROWTH, Returns, Scratch, SurfaceParams, Surfaces};
use crate::engine::grid::ImageGeometry;

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
                        for at in at {
                            let cell = first + at;
                            let (fit, grow) =
                                fit_cell(returns, geometry, cell, params, scratch, left_grow);
                            if carry && fit.range_m.is_finite() {
                                left_grow = grow;
                            }
                            range_m[at] = fit.range_m;
                            direction[at] = fit.direction;
                            normal[at] = fit.normal;
                            incidence_cos[at] = fit.incidence_cos;
                            support[at] = fit.support;
                            edge[at] = fit.edge;
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
