//! The plane fit of a dense sensor's cell over its window of neighbouring
//! beams and columns: whole from the window's running moments where every
//! return passes the range gate and lies on the plane
//! ([`fit_whole_window`]), else return by return ([`fit_gated_points`]).

use nalgebra::{Matrix3, Vector3};

use super::plane::{
    Plane, eigenvalues_below, fit_plane_spread, plane_of_scatter, principal_minors,
};
use super::{
    CellSurface, EMPTY, Returns, Scratch, SurfaceParams, facing_sensor, oriented,
    plane_tolerance_m, range_gate_m, raw_surface,
};
use crate::engine::grid::ImageGeometry;
use crate::engine::window_sums::{Moments, column_spans};

/// One fit over a window of `2 half_rows + 1` beams by `2 half_cols + 1`
/// columns (`(half_rows, half_cols)`), `gated` its `gated_window`; also
/// returns the in-plane spread of the points fitted.
pub(super) fn fit_window(
    returns: &Returns,
    geometry: &ImageGeometry,
    cell: usize,
    params: SurfaceParams,
    window: (usize, usize),
    gated: Option<&GatedWindow>,
    scratch: &mut Scratch,
) -> (CellSurface, Option<f64>) {
    let Some(center) = returns.point(cell) else {
        return (EMPTY, None);
    };
    gated
        .and_then(|gated| fit_whole_window(returns, geometry.cols, &center, params, gated))
        .unwrap_or_else(|| {
            fit_gated_points(returns, geometry, cell, &center, params, window, scratch)
        })
}

/// [`fit_window`]'s fit over the window's returns one by one: those within
/// a loose range gate, then those on the plane fitted to them.
pub(super) fn fit_gated_points(
    returns: &Returns,
    geometry: &ImageGeometry,
    cell: usize,
    center: &Vector3<f64>,
    params: SurfaceParams,
    (half_rows, half_cols): (usize, usize),
    scratch: &mut Scratch,
) -> (CellSurface, Option<f64>) {
    let center = *center;
    let raw = raw_surface(&center);
    let (range, direction) = (center.norm(), center / center.norm());
    // Candidates: neighbours not absurdly far in range (a loose gate; the plane decides).
    let Scratch {
        points, on_plane, ..
    } = scratch;
    points.clear();
    points.push(center);
    let mut far_neighbours = 0;
    let gate_m = range_gate_m(range);
    let (row, col, cols) = (cell / geometry.cols, cell % geometry.cols, geometry.cols);
    for r in row.saturating_sub(half_rows)..=(row + half_rows).min(geometry.rows - 1) {
        for offset in 0..=2 * half_cols {
            // Columns wrap around the sweep.
            let c = (col + cols + offset - half_cols) % cols;
            let n = r * cols + c;
            if n == cell {
                continue;
            }
            let neighbour_range = returns.ranges[n];
            if neighbour_range.is_nan() {
                continue;
            }
            if (neighbour_range - range).abs() <= gate_m {
                points.push(returns.points[n]);
            } else {
                far_neighbours += 1;
            }
        }
    }
    let Some((normal, centroid, spread)) = fit_plane_spread(points) else {
        return (
            CellSurface {
                edge: far_neighbours > 0,
                ..raw
            },
            None,
        );
    };
    // Points off the plane by more than noise belong to another surface.
    let tolerance = plane_tolerance_m(params, range);
    on_plane.clear();
    on_plane.extend(
        points
            .iter()
            .copied()
            .filter(|p| (p - centroid).dot(&normal).abs() <= tolerance),
    );
    // An edge: a return of the window off the plane. (Letting one stray
    // return pass, as real noise has heavy tails, kept a third more of the
    // Hesai Pandar64's scan but cost 12 % of the fused accuracy on the
    // synthetic `follow` at 64 x 2048, and the share of strays does not tell
    // the two apart: 1.5-1.9 % on the real sensors, 3 % on the synthetic one
    // at its creases.)
    let edge = far_neighbours > 0 || on_plane.len() < points.len();
    let (normal, centroid, support, spread) = if on_plane.len() == points.len() {
        (normal, centroid, points.len(), spread)
    } else {
        match fit_plane_spread(on_plane) {
            Some((n, c, s)) => (n, c, on_plane.len(), s),
            None => return (CellSurface { edge, ..raw }, None),
        }
    };
    let surface = CellSurface {
        // Signed: positive when the return lies beyond the plane.
        residual_m: (center - centroid).dot(&(-facing_sensor(normal, &direction))) as f32,
        support: support.min(255) as u8,
        edge,
        ..oriented(&center, &centroid, normal, tolerance)
    };
    (surface, Some(spread))
}

/// [`fit_window`]'s fit of a window whose returns all pass the range gate
/// (`gated_window`), where they all lie on the plane fitted to them (most
/// windows): the plane from the window's moments, and the returns'
/// distances to it from them too (`window_on_plane`). None where the window
/// needs the full fit (a return off the plane, fewer than four returns, or
/// no plane).
pub(super) fn fit_whole_window(
    returns: &Returns,
    cols: usize,
    center: &Vector3<f64>,
    params: SurfaceParams,
    window: &GatedWindow,
) -> Option<(CellSurface, Option<f64>)> {
    let range = center.norm();
    let moments = window.total;
    let (centroid, covariance) = window.scatter?;
    let plane = plane_of_scatter(moments.count, centroid, &covariance)?;
    let tolerance = plane_tolerance_m(params, range);
    if !window_on_plane(returns, cols, window, &plane, tolerance) {
        return None;
    }
    let direction = center / range;
    let surface = CellSurface {
        residual_m: (center - plane.centroid).dot(&(-facing_sensor(plane.normal, &direction)))
            as f32,
        support: (moments.count as usize).min(255) as u8,
        edge: false,
        ..oriented(center, &plane.centroid, plane.normal, tolerance)
    };
    Some((surface, Some(plane.spread)))
}

/// The moments of a window (`(half_rows, half_cols)` about a cell) whose
/// returns all lie within the cell's range gate: from each row's range
/// extremes and running sums.
pub(super) struct GatedWindow {
    /// Moments of all the window's returns.
    total: Moments,
    /// Their centroid and scatter ([`Moments::scatter`]) where they are at
    /// least four (a plane's worth): computed once for both [`too_narrow`]
    /// and [`fit_whole_window`].
    scatter: Option<(Vector3<f64>, Matrix3<f64>)>,
    first_row: usize,
    last_row: usize,
    col: usize,
    half_cols: usize,
    /// The cell's range, metres.
    range_m: f64,
}

/// None where the cell is empty, a return is beyond the gate, or the window
/// is wider than the image.
pub(super) fn gated_window(
    returns: &Returns,
    geometry: &ImageGeometry,
    cell: usize,
    (half_rows, half_cols): (usize, usize),
) -> Option<GatedWindow> {
    // `ranges` is NaN exactly where the cell is empty.
    let range_m = returns.ranges[cell];
    if range_m.is_nan() {
        return None;
    }
    let (row, col) = (cell / geometry.cols, cell % geometry.cols);
    let gate_m = range_gate_m(range_m);
    let (first_row, last_row) = (
        row.saturating_sub(half_rows),
        (row + half_rows).min(geometry.rows - 1),
    );
    // Every row's gate first: a window failing it sums no moments.
    let gated = returns.extremes.rows_all(
        first_row..=last_row,
        col,
        half_cols,
        |[nearest_m, farthest_m]| !(range_m - nearest_m > gate_m || farthest_m - range_m > gate_m),
    )?;
    if !gated {
        return None;
    }
    let total = returns
        .sums
        .window_over_rows(first_row..=last_row, col, half_cols)?;
    Some(GatedWindow {
        range_m,
        total,
        scatter: total.scatter().filter(|_| total.count >= 4.0),
        first_row,
        last_row,
        col,
        half_cols,
    })
}

/// Whether [`fit_window`] would fit the window's returns whole
/// (`fit_whole_window`) to a plane with an in-plane spread below 2 noise
/// sigmas, so that [`fit_cell`] drops the fit for a wider window. From the
/// window's scatter without solving for its plane: the number of its
/// eigenvalues below a bound is the number of sign changes along the
/// leading principal minors of the scatter less the bound (Sylvester's law
/// of inertia), so the middle eigenvalue below `count (2 sigma)^2` and the
/// smallest below the squared tolerance (every return on the plane) are a
/// few products each. False where unsure: the fit decides.
#[inline]
pub(super) fn too_narrow(gated: &GatedWindow, params: SurfaceParams) -> bool {
    let count = gated.total.count;
    let Some((_, scatter)) = gated.scatter else {
        return false;
    };
    let narrow_m2 = count * (2.0 * params.range_noise_m).powi(2);
    let tolerance = plane_tolerance_m(params, gated.range_m);
    let on_plane_m2 = WHOLE_WINDOW_MARGIN * tolerance * tolerance;
    let (trace, minors) = (scatter.trace(), principal_minors(&scatter));
    // The sum of the principal minors is at most three times the product
    // of the two larger eigenvalues, and the trace at least the larger: so
    // minors of `3e-3 trace^2` or more surely make a plane for
    // `plane_of_scatter` (the middle eigenvalue at least 1e-3 of the
    // largest), and minors of `3 narrow trace` or more surely a middle
    // eigenvalue above `narrow` (most windows, without a determinant).
    let plane = trace.is_finite() && trace > 0.0 && minors >= 3e-3 * trace * trace;
    plane
        && minors < 3.0 * narrow_m2 * trace
        && eigenvalues_below(&scatter, narrow_m2).is_some_and(|n| n >= 2)
        && eigenvalues_below(&scatter, on_plane_m2).is_some_and(|n| n >= 1)
}

/// Every return of the window lies within `tolerance` of `plane`. The squared distances sum to
/// the plane's smallest scatter over the window, and to a quadratic of each row's moments over the row: no
/// return exceeds the tolerance where that sum does not, so only the
/// returns of a row whose sum does are looked at (on noisy data the
/// window's sum, `(n - 3) sigma^2`, mostly does; a row's mostly not).
fn window_on_plane(
    returns: &Returns,
    cols: usize,
    window: &GatedWindow,
    plane: &Plane,
    tolerance: f64,
) -> bool {
    let limit = WHOLE_WINDOW_MARGIN * tolerance * tolerance;
    if plane.smallest <= limit {
        return true;
    }
    let offset = plane.centroid.dot(&plane.normal);
    let mut rows = (window.first_row..=window.last_row).filter(|&r| {
        let of_row = returns.sums.window(r, window.col, window.half_cols);
        of_row.is_none_or(|moments| moments.squared_distances(&plane.normal, offset) > limit)
    });
    !rows.any(|r| {
        window_cells(r * cols, window.col, window.half_cols, cols)
            .flat_map(|span| &returns.points[span])
            .any(|p| !p.x.is_nan() && (p - plane.centroid).dot(&plane.normal).abs() > tolerance)
    })
}

/// Below this fraction of the squared tolerance, a sum of squared distances
/// to a plane shows every return in it on the plane without looking (a
/// margin for the rounding of the running sums).
const WHOLE_WINDOW_MARGIN: f64 = 0.999;

/// The cells of the row starting at cell `row_start` in the window's
/// columns (`window_sums::column_spans`; empty when wider than the image).
fn window_cells(
    row_start: usize,
    col: usize,
    half_cols: usize,
    cols: usize,
) -> impl Iterator<Item = std::ops::Range<usize>> {
    column_spans(col, half_cols, cols)
        .into_iter()
        .flatten()
        .map(move |span| row_start + span.start..row_start + span.end)
}
