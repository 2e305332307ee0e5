//! The plane fit of a dense sensor's cell over its window of neighbouring
//! beams and columns: from the window's running moments where every
//! return passes the range gate, less the moments of those off its plane
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
use crate::engine::window_sums::{Moments, column_spans, unwrapped_span};

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
    let within_gate = gated.is_some();
    let by_moments = match gated {
        Some(gated) => fit_whole_window(returns, geometry.cols, &center, params, gated),
        None => fit_beyond_gate(returns, geometry, cell, &center, params, window),
    };
    by_moments.unwrap_or_else(|| {
        let points = Gather {
            cell,
            window,
            within_gate,
        };
        fit_gated_points(returns, geometry, &center, params, points, scratch)
    })
}

/// Which returns [`fit_gated_points`] fits: those of the cell's window
/// (`(half_rows, half_cols)`) within its range gate.
#[derive(Debug, Clone, Copy)]
pub(super) struct Gather {
    pub cell: usize,
    pub window: (usize, usize),
    /// Every return of the window is known to pass the gate
    /// ([`gated_window`] found it so): no return is looked at for it.
    pub within_gate: bool,
}

/// [`fit_window`]'s fit over the window's returns one by one: those within
/// a loose range gate, then those on the plane fitted to them.
pub(super) fn fit_gated_points(
    returns: &Returns,
    geometry: &ImageGeometry,
    center: &Vector3<f64>,
    params: SurfaceParams,
    gather: Gather,
    scratch: &mut Scratch,
) -> (CellSurface, Option<f64>) {
    let center = *center;
    let raw = raw_surface(&center);
    let (range, direction) = (center.norm(), center / center.norm());
    // Candidates: neighbours not absurdly far in range (a loose gate; the plane decides).
    let Scratch {
        points, on_plane, ..
    } = scratch;
    let far_neighbours = gather_within_gate(returns, geometry, gather, range, points);
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

/// Into `points`, the cell's return and then those of its window within
/// its range gate (`range_m` the cell's), row by row in column order from
/// the window's first column (wrapping around the sweep); returns how many
/// returns the gate left out. Column spans rather than a wrapped column
/// per return: the division behind each was a third of the fallback's time.
fn gather_within_gate(
    returns: &Returns,
    geometry: &ImageGeometry,
    gather: Gather,
    range_m: f64,
    points: &mut Vec<Vector3<f64>>,
) -> usize {
    let Gather {
        cell,
        window: (half_rows, half_cols),
        within_gate,
    } = gather;
    points.clear();
    points.push(returns.points[cell]);
    let mut far_neighbours = 0;
    let gate_m = range_gate_m(range_m);
    let ((rows, col), cols) = (window_rows(geometry, cell, half_rows), geometry.cols);
    let mut span = |cells: std::ops::Range<usize>| {
        let of_span = returns.ranges[cells.clone()]
            .iter()
            .zip(&returns.points[cells.clone()]);
        for (n, (&neighbour_range, p)) in cells.zip(of_span) {
            // (A NaN range is an empty cell.)
            if n == cell || neighbour_range.is_nan() {
                continue;
            }
            if within_gate || (neighbour_range - range_m).abs() <= gate_m {
                points.push(*p);
            } else {
                far_neighbours += 1;
            }
        }
    };
    let spans = spans_in_window_order(col, half_cols, cols);
    for r in rows {
        let row_start = r * cols;
        match &spans {
            Some(spans) => {
                for s in spans {
                    span(row_start + s.start..row_start + s.end);
                }
            }
            // Wider than the image: column by column, wrapping.
            None => {
                for offset in 0..=2 * half_cols {
                    let c = row_start + (col + cols + offset - half_cols) % cols;
                    span(c..c + 1);
                }
            }
        }
    }
    far_neighbours
}

/// The columns `col - half_cols ..= col + half_cols` of an image `cols`
/// wide in the window's order (wrapping around the sweep: the columns
/// before 0 first) as two spans (one maybe empty); None where the window
/// is wider than the image.
fn spans_in_window_order(
    col: usize,
    half_cols: usize,
    cols: usize,
) -> Option<[std::ops::Range<usize>; 2]> {
    if 2 * half_cols + 1 > cols || col >= cols {
        return None;
    }
    Some(if col < half_cols {
        [cols + col - half_cols..cols, 0..col + half_cols + 1]
    } else if col + half_cols >= cols {
        [col - half_cols..cols, 0..col + half_cols + 1 - cols]
    } else {
        [col - half_cols..col + half_cols + 1, 0..0]
    })
}

/// [`fit_window`]'s fit of a window whose returns all pass the range gate
/// (`gated_window`), from the window's moments: the plane of them all, and
/// where returns lie off it (`off_plane_moments`, from the moments too where
/// none can), the plane of the rest, their moments the window's less the
/// moments of those off it (the fallback gathered and summed every return
/// again, for the same plane to the rounding: 15-18 % of the windows of
/// the real sensors have a return off the plane). None where the window
/// needs the full fit (fewer than four returns, or no plane).
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
    let off = off_plane_moments(returns, cols, window, &plane, tolerance);
    if off.count == 0.0 {
        return Some(on_plane(center, &plane, moments.count, false, tolerance));
    }
    // An edge: a return of the window off the plane (`fit_gated_points`).
    Some(without_off_plane(center, &moments.minus(&off), tolerance))
}

/// [`fit_window`]'s fit of a window with returns beyond the cell's range
/// gate, from moments as [`fit_whole_window`]'s: the window's less those
/// of the returns beyond the gate, less those of the rest off their plane
/// (the same fits as [`fit_gated_points`]', to the rounding, which
/// gathered the window's returns and summed them twice over). None where
/// the window is wider than the image.
pub(super) fn fit_beyond_gate(
    returns: &Returns,
    geometry: &ImageGeometry,
    cell: usize,
    center: &Vector3<f64>,
    params: SurfaceParams,
    (half_rows, half_cols): (usize, usize),
) -> Option<(CellSurface, Option<f64>)> {
    let ((rows, col), cols) = (window_rows(geometry, cell, half_rows), geometry.cols);
    let total = returns
        .sums
        .window_over_rows(rows.clone(), col, half_cols)?;
    let range_m = center.norm();
    let gate_m = range_gate_m(range_m);
    // A NaN range (an empty cell) is not beyond the gate: its moments are none.
    let beyond = |range: f64| (range - range_m).abs() > gate_m;
    let window = (rows.clone(), col, half_cols);
    let mut far = Moments::default();
    each_return(returns, cols, window.clone(), |range, p| {
        if beyond(range) {
            far = far.plus(&Moments::of_point(p));
        }
    });
    // An edge: a return beyond the gate (`fit_gated_points`; there is one
    // unless `gated_window` did not hold the window's width).
    let edge = far.count > 0.0;
    let raw = (
        CellSurface {
            edge,
            ..raw_surface(center)
        },
        None,
    );
    let tolerance = plane_tolerance_m(params, range_m);
    let near = total.minus(&far);
    let Some(plane) = plane_of_moments(&near) else {
        return Some(raw);
    };
    let mut off = Moments::default();
    each_return(returns, cols, window, |range, p| {
        if !beyond(range) && (p - plane.centroid).dot(&plane.normal).abs() > tolerance {
            off = off.plus(&Moments::of_point(p));
        }
    });
    if off.count == 0.0 {
        return Some(on_plane(center, &plane, near.count, edge, tolerance));
    }
    Some(without_off_plane(center, &near.minus(&off), tolerance))
}

/// `visit` of the range and point of each cell of the window (`rows`, about
/// `col`, `half_cols` either side), row by row. A generic visitor, not a
/// `dyn` one: a call through a pointer per return was a tenth of the plane
/// fits' instructions on KITTI's braking drive, where windows often reach
/// beyond an edge.
#[inline]
fn each_return(
    returns: &Returns,
    cols: usize,
    (rows, col, half_cols): (std::ops::RangeInclusive<usize>, usize, usize),
    mut visit: impl FnMut(f64, &Vector3<f64>),
) {
    for r in rows {
        each_span(r * cols, col, half_cols, cols, |span| {
            for (&range, p) in returns.ranges[span.clone()]
                .iter()
                .zip(&returns.points[span])
            {
                visit(range, p);
            }
        });
    }
}

/// The surface of the return `center` on the plane of `rest`, the moments
/// left once the returns off a first plane are taken out (an edge); its
/// raw range where they make no plane.
fn without_off_plane(
    center: &Vector3<f64>,
    rest: &Moments,
    tolerance: f64,
) -> (CellSurface, Option<f64>) {
    match plane_of_moments(rest) {
        Some(plane) => on_plane(center, &plane, rest.count, true, tolerance),
        None => (
            CellSurface {
                edge: true,
                ..raw_surface(center)
            },
            None,
        ),
    }
}

/// The plane of the returns with `moments`, at least four of them.
fn plane_of_moments(moments: &Moments) -> Option<Plane> {
    let (centroid, covariance) = moments.scatter().filter(|_| moments.count >= 4.0)?;
    plane_of_scatter(moments.count, centroid, &covariance)
}

/// The surface of the return `center` on `plane`, fitted to `count`
/// returns, and the plane's in-plane spread.
fn on_plane(
    center: &Vector3<f64>,
    plane: &Plane,
    count: f64,
    edge: bool,
    tolerance: f64,
) -> (CellSurface, Option<f64>) {
    let direction = center / center.norm();
    let surface = CellSurface {
        // Signed: positive when the return lies beyond the plane.
        residual_m: (center - plane.centroid).dot(&(-facing_sensor(plane.normal, &direction)))
            as f32,
        support: (count as usize).min(255) as u8,
        edge,
        ..oriented(center, &plane.centroid, plane.normal, tolerance)
    };
    (surface, Some(plane.spread))
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
    let (rows, col) = window_rows(geometry, cell, half_rows);
    let (first_row, last_row) = (*rows.start(), *rows.end());
    // Every row's gate first: a window failing it sums no moments.
    if !within_range_gate(returns, (rows.clone(), col, half_cols), range_m)? {
        return None;
    }
    let total = returns.sums.window_over_rows(rows, col, half_cols)?;
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

/// The rows of `cell`'s window, `half_rows` either side of its own and
/// clamped to the image, and its column.
#[inline]
pub(super) fn window_rows(
    geometry: &ImageGeometry,
    cell: usize,
    half_rows: usize,
) -> (std::ops::RangeInclusive<usize>, usize) {
    let (row, col) = (cell / geometry.cols, cell % geometry.cols);
    let rows = row.saturating_sub(half_rows)..=(row + half_rows).min(geometry.rows - 1);
    (rows, col)
}

/// Whether every return of the window (`rows`, about `col`, `half_cols`
/// either side) lies within the range gate of a centre return at
/// `range_m` (`range_gate_m`), from each row's range extremes; None where
/// the window is wider than the image. The gate of [`gated_window`], the
/// noise's plane scatter and the fits' derived cells.
#[inline]
pub(super) fn within_range_gate(
    returns: &Returns,
    (rows, col, half_cols): (std::ops::RangeInclusive<usize>, usize, usize),
    range_m: f64,
) -> Option<bool> {
    let gate_m = range_gate_m(range_m);
    returns
        .extremes
        .rows_all(rows, col, half_cols, |[nearest_m, farthest_m]| {
            !(range_m - nearest_m > gate_m || farthest_m - range_m > gate_m)
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

/// The moments of the window's returns farther than `tolerance` from
/// `plane` (none: zero). The squared distances sum to the plane's smallest
/// scatter over the window, and to a quadratic of each row's moments over
/// the row: no return exceeds the tolerance where that sum does not, so
/// only the returns of a row whose sum does are looked at (on noisy data
/// the window's sum, `(n - 3) sigma^2`, mostly does; a row's mostly not).
fn off_plane_moments(
    returns: &Returns,
    cols: usize,
    window: &GatedWindow,
    plane: &Plane,
    tolerance: f64,
) -> Moments {
    let mut off = Moments::default();
    let limit = WHOLE_WINDOW_MARGIN * tolerance * tolerance;
    if plane.smallest <= limit {
        return off;
    }
    let offset = plane.centroid.dot(&plane.normal);
    let rows = (window.first_row..=window.last_row).filter(|&r| {
        let of_row = returns.sums.window(r, window.col, window.half_cols);
        of_row.is_none_or(|moments| moments.squared_distances(&plane.normal, offset) > limit)
    });
    // An empty cell's NaN is no distance beyond the tolerance.
    let is_off = |p: &Vector3<f64>| (p - plane.centroid).dot(&plane.normal).abs() > tolerance;
    for r in rows {
        each_span(r * cols, window.col, window.half_cols, cols, |span| {
            for p in returns.points[span].iter().filter(|p| is_off(p)) {
                off = off.plus(&Moments::of_point(p));
            }
        });
    }
    off
}

/// Below this fraction of the squared tolerance, a sum of squared distances
/// to a plane shows every return in it on the plane without looking (a
/// margin for the rounding of the running sums).
pub(super) const WHOLE_WINDOW_MARGIN: f64 = 0.999;

/// `visit` of the cells of the row starting at cell `row_start` in the
/// window's columns (`window_sums::column_spans`: none when wider than the
/// image), span by span. Most windows do not wrap around the sweep: their
/// one span directly (`unwrapped_span`: the spans' iterator, chained and
/// flattened, was about a fifth of `fit_window`'s own samples on KITTI's
/// braking drive, where many windows are looked at return by return).
#[inline]
fn each_span(
    row_start: usize,
    col: usize,
    half_cols: usize,
    cols: usize,
    mut visit: impl FnMut(std::ops::Range<usize>),
) {
    if let Some(span) = unwrapped_span(col, half_cols, cols) {
        visit(row_start + span.start..row_start + span.end);
        return;
    }
    for span in column_spans(col, half_cols, cols).into_iter().flatten() {
        visit(row_start + span.start..row_start + span.end);
    }
}
