//! Local surfaces of a range image: a plane fitted to each cell's 3x3
//! neighbourhood gives a denoised range (the cell's ray against the plane),
//! the surface normal (so grazing cells are known), and occlusion edges
//! (neighbours far off the plane).

use nalgebra::{Matrix3, Vector3};
use rayon::prelude::*;

use super::grid::{ImageGeometry, NO_POINT, RangeImage};
use super::window_extremes::RowExtremes;
use super::window_sums::{Moments, RowSums, column_spans};
use crate::model::Scan;

/// Per cell of one image.
#[derive(Debug, Clone)]
pub struct Surfaces {
    /// Denoised range (raw where no plane could be fitted), metres; NaN empty.
    pub range_m: Vec<f32>,
    /// Unit direction of the cell's return (LiDAR frame).
    pub direction: Vec<[f32; 3]>,
    /// Unit plane normal facing the sensor; zero when unknown.
    pub normal: Vec<[f32; 3]>,
    /// `|n . e|`, 1 when unknown.
    pub incidence_cos: Vec<f32>,
    /// Points the plane was fitted to (1 = raw range kept).
    pub support: Vec<u8>,
    /// A neighbour lies on another surface (occlusion edge).
    pub edge: Vec<bool>,
    /// Range noise of each row's laser (1 sigma), metres, estimated from the
    /// scan itself (`row_noise`).
    pub noise_m_per_row: Vec<f32>,
    /// Range offset of each row's laser taken out of its returns, metres
    /// (`bias::estimate`; all zero where the scan shows none).
    pub range_bias_m_per_row: Vec<f32>,
    /// Per cell, the neighbours it shares a surface with in the mesh the
    /// renderer builds (`warp::mesh_joins`).
    pub joins: Vec<u8>,
    /// Azimuth and elevation of each cell's return (of `direction`), radians
    /// (NaN empty): computed once per scan, as each render of the scan
    /// turns them by its motion (`warp`) instead of taking three `atan2`
    /// per return.
    pub azimuth_rad: Vec<f64>,
    pub elevation_rad: Vec<f64>,
    /// Columns of the image (cells per row).
    pub cols: usize,
}

impl Surfaces {
    /// Range noise (1 sigma) of a cell's laser, metres.
    pub fn noise_m(&self, cell: usize) -> f64 {
        f64::from(self.noise_m_per_row[cell / self.cols])
    }
}

/// Range noise of each row, metres: from the second differences of the raw
/// ranges along the row (three consecutive returns of one laser on one
/// smooth surface: `r[c-1] - 2 r[c] + r[c+1]` is noise times sqrt(6) plus a
/// curvature that is negligible at one cell), robustly (median). Real lasers
/// differ (per-laser noise and intensity-dependent error); a row with too
/// few samples takes `default_m`. Clamped to [0.005, 0.1] m.
pub fn row_noise(image: &RangeImage, geometry: &ImageGeometry, default_m: f64) -> Vec<f32> {
    (0..geometry.rows)
        .map(|row| {
            let ranges = &image.range_m[row * geometry.cols..(row + 1) * geometry.cols];
            let mut second: Vec<f32> = ranges
                .windows(3)
                .filter_map(|w| {
                    let (a, b, c) = (w[0], w[1], w[2]);
                    let smooth = (a - b).abs() < 0.05 * b && (c - b).abs() < 0.05 * b;
                    (a.is_finite() && b.is_finite() && c.is_finite() && smooth)
                        .then(|| (a - 2.0 * b + c).abs())
                })
                .collect();
            if second.len() < MIN_NOISE_SAMPLES {
                return default_m as f32;
            }
            let mid = second.len() / 2;
            let median = *second.select_nth_unstable_by(mid, f32::total_cmp).1;
            (1.4826 * median / 6f32.sqrt()).clamp(0.005, 0.1)
        })
        .collect()
}

/// Range noise of each row: the larger of the laser's own noise along its
/// row (`row_noise`) and the scatter of its returns about local planes
/// fitted across neighbouring lasers, which holds what real sensors add
/// between lasers (per-laser range biases, intensity-dependent error: a few
/// centimetres on an HDL-64E). Measured on every `NOISE_STRIDE`-th column,
/// with a loose gate, on cells whose window is one surface. (Taking a
/// measured per-laser bias out before fitting was tried: it moved no
/// figure on the HDL-64E and cost 15 % of D's accuracy on the synthetic
/// sensor, which has none.)
fn noise_per_row(returns: &Returns, geometry: &ImageGeometry, params: SurfaceParams) -> Vec<f32> {
    let along = row_noise(returns.image, geometry, params.range_noise_m);
    let loose = SurfaceParams {
        range_noise_m: LOOSE_NOISE_M,
        ..params
    };
    let scatter: Vec<f32> = (0..geometry.rows)
        .into_par_iter()
        .map_init(Scratch::default, |scratch, row| {
            let mut residuals: Vec<f32> = (0..geometry.cols)
                .step_by(NOISE_STRIDE)
                .filter_map(|col| {
                    let (cell, window) = (row * geometry.cols + col, (1, params.half_cols));
                    let gated = gated_window(returns, geometry, cell, window);
                    let (fit, _) = fit_window(
                        returns,
                        geometry,
                        cell,
                        loose,
                        window,
                        gated.as_ref(),
                        scratch,
                    );
                    (fit.support >= 6 && !fit.edge && fit.residual_m.is_finite())
                        .then(|| fit.residual_m.abs())
                })
                .collect();
            if residuals.len() < MIN_NOISE_SAMPLES / 2 {
                return f32::NAN;
            }
            // A return's distance to a plane fitted with it is about 0.9 of
            // its noise in a window of 15; the median of |N(0, s)| is 0.67 s.
            1.4826 * median_f32(&mut residuals) / 0.9
        })
        .collect();
    along
        .iter()
        .zip(&scatter)
        .map(|(&along, &scatter)| {
            if scatter.is_nan() {
                along
            } else {
                along.max(scatter).clamp(0.005, 0.1)
            }
        })
        .collect()
}

fn median_f32(values: &mut [f32]) -> f32 {
    let mid = values.len() / 2;
    *values.select_nth_unstable_by(mid, f32::total_cmp).1
}

/// Each row's noise, or the sensor's (the median over rows) where the row
/// is within a third of it: a row's own estimate moves by some 10 % from
/// scan to scan, and thresholds at 4 sigma then flip cells; a laser really
/// noisier or quieter than the rest (an HDL-64E's spread 0.007 to 0.05 m)
/// keeps its own.
fn shrunk_to_sensor(mut noise: Vec<f32>) -> Vec<f32> {
    if noise.is_empty() {
        return noise;
    }
    let mut sorted = noise.clone();
    let sensor = median_f32(&mut sorted);
    for row in &mut noise {
        if (*row / sensor - 1.0).abs() < ROW_NOISE_OWN {
            *row = sensor;
        }
    }
    noise
}

/// Relative departure from the sensor's noise beyond which a row keeps its own.
const ROW_NOISE_OWN: f32 = 1.0 / 3.0;

/// Gate of the plane-scatter measurement (a loose noise, metres).
const LOOSE_NOISE_M: f64 = 0.05;
/// Every how many columns the plane scatter is measured.
const NOISE_STRIDE: usize = 4;

/// Second differences a row needs for its own noise estimate.
const MIN_NOISE_SAMPLES: usize = 50;

/// Tuning of the surface fit.
#[derive(Debug, Clone, Copy)]
pub struct SurfaceParams {
    /// Range noise of the sensor (1 sigma), metres.
    pub range_noise_m: f64,
    /// Columns on each side of a cell in its fitting window: the window spans
    /// 3 beams and about as much azimuth as elevation, so a dense sensor (2048
    /// columns) does not fit planes to points a few centimetres apart.
    pub half_cols: usize,
    /// Rows too far apart to share a plane (`ImageGeometry::sparse_rows`):
    /// lines are fitted along each ring instead.
    pub sparse_rows: bool,
    /// Height of the ground below the sensor, metres (LiDAR frame z), for
    /// the orientation of a ring's line on sparse sensors; -inf unknown.
    pub ground_z_m: f64,
}

impl SurfaceParams {
    pub fn for_geometry(geometry: &ImageGeometry, range_noise_m: f64) -> Self {
        let elevations = &geometry.beams.elevations_rad;
        let row_step = match (elevations.first(), elevations.last()) {
            (Some(lo), Some(hi)) if elevations.len() > 1 => {
                (hi - lo) / (elevations.len() - 1) as f64
            }
            _ => 0.0,
        };
        let col_step = std::f64::consts::TAU / geometry.cols as f64;
        let half_cols = (row_step / col_step).round().clamp(1.0, 4.0) as usize;
        Self {
            range_noise_m,
            half_cols,
            sparse_rows: geometry.sparse_rows(),
            ground_z_m: f64::NEG_INFINITY,
        }
    }
}

impl Surfaces {
    /// Surfaces of a gridded scan, with `range_bias_m_per_row` (one per row,
    /// `bias::RangeBias`) taken out of the returns first.
    pub fn estimate(
        scan: &Scan,
        image: &RangeImage,
        geometry: &ImageGeometry,
        params: SurfaceParams,
        range_bias_m_per_row: Vec<f32>,
    ) -> Self {
        // The windows of `fit_cell`'s growths (dense sensors only).
        let window_half_cols: Vec<usize> = if params.sparse_rows {
            Vec::new()
        } else {
            (1..=MAX_GROWTH)
                .map(|grow| grow * params.half_cols)
                .collect()
        };
        let returns = Returns::new(
            scan,
            image,
            geometry.cols,
            &range_bias_m_per_row,
            &window_half_cols,
        );
        let noise_m_per_row = shrunk_to_sensor(if params.sparse_rows {
            row_noise(image, geometry, params.range_noise_m)
        } else {
            noise_per_row(&returns, geometry, params)
        });
        let params = SurfaceParams {
            ground_z_m: if params.sparse_rows {
                ground_height(scan, image)
            } else {
                params.ground_z_m
            },
            ..params
        };
        let fitted: Vec<CellSurface> = (0..geometry.cells())
            .into_par_iter()
            // One scratch buffer per worker: no allocation per cell.
            .map_init(Scratch::default, |scratch, cell| {
                let params = SurfaceParams {
                    range_noise_m: f64::from(noise_m_per_row[cell / geometry.cols]),
                    ..params
                };
                fit_cell(&returns, geometry, cell, params, scratch)
            })
            .collect();
        let mut surfaces = Self {
            range_m: fitted.iter().map(|c| c.range_m).collect(),
            direction: fitted.iter().map(|c| c.direction).collect(),
            normal: fitted.iter().map(|c| c.normal).collect(),
            incidence_cos: fitted.iter().map(|c| c.incidence_cos).collect(),
            support: fitted.iter().map(|c| c.support).collect(),
            edge: fitted.iter().map(|c| c.edge).collect(),
            noise_m_per_row,
            range_bias_m_per_row,
            joins: Vec::new(),
            azimuth_rad: Vec::new(),
            elevation_rad: Vec::new(),
            cols: geometry.cols,
        };
        surfaces.joins = super::warp::mesh_joins(&surfaces, geometry.rows, geometry.cols);
        (surfaces.azimuth_rad, surfaces.elevation_rad) = direction_angles(&surfaces);
        surfaces
    }
}

/// Azimuth and elevation of each cell's `direction` (NaN where empty).
fn direction_angles(surfaces: &Surfaces) -> (Vec<f64>, Vec<f64>) {
    surfaces
        .direction
        .par_iter()
        .zip(&surfaces.range_m)
        .map(|(d, range)| {
            if !range.is_finite() {
                return (f64::NAN, f64::NAN);
            }
            super::grid::angles(d)
        })
        .unzip()
}

#[derive(Debug, Clone, Copy)]
struct CellSurface {
    /// The return's own distance to the fitted plane, metres.
    residual_m: f32,
    range_m: f32,
    direction: [f32; 3],
    normal: [f32; 3],
    incidence_cos: f32,
    support: u8,
    edge: bool,
}

const EMPTY: CellSurface = CellSurface {
    residual_m: f32::NAN,
    range_m: f32::NAN,
    direction: [0.0; 3],
    normal: [0.0; 3],
    incidence_cos: 1.0,
    support: 0,
    edge: false,
};

/// The returns of one image, by cell, with each laser's range offset taken
/// out: positions and ranges computed once per scan, as every cell's window
/// reads its neighbours' many times over.
struct Returns<'a> {
    image: &'a RangeImage,
    /// Per cell, metres (NaN: empty).
    points: Vec<Vector3<f64>>,
    /// `|points[cell]|`, metres (NaN: empty).
    ranges: Vec<f64>,
    /// Running sums of `points` along each row, for the windows' scatter.
    sums: RowSums,
    /// Extremes of `ranges` along each row, for the windows' range gate.
    extremes: RowExtremes,
}

impl<'a> Returns<'a> {
    /// The returns, with the range extremes of windows `window_half_cols`
    /// wide on each side.
    fn new(
        scan: &Scan,
        image: &'a RangeImage,
        cols: usize,
        range_bias_m: &[f32],
        window_half_cols: &[usize],
    ) -> Self {
        let points: Vec<Vector3<f64>> = image
            .point
            .par_iter()
            .enumerate()
            .map(|(cell, &index)| {
                if index == NO_POINT {
                    return Vector3::repeat(f64::NAN);
                }
                let p = scan.points_m[index as usize];
                let p = Vector3::new(f64::from(p[0]), f64::from(p[1]), f64::from(p[2]));
                match range_bias_m.get(cell / cols) {
                    Some(&bias) if bias != 0.0 => {
                        let range = p.norm();
                        p * ((range - f64::from(bias)).max(0.0) / range)
                    }
                    _ => p,
                }
            })
            .collect();
        Self::of_points(image, points, cols, window_half_cols)
    }

    /// The returns `points` (one per cell of `image`; NaN empty).
    fn of_points(
        image: &'a RangeImage,
        points: Vec<Vector3<f64>>,
        cols: usize,
        window_half_cols: &[usize],
    ) -> Self {
        let ranges: Vec<f64> = points.iter().map(|p| p.norm()).collect();
        let sums = RowSums::new(&points, cols);
        let extremes = RowExtremes::new(&ranges, cols, window_half_cols);
        Self {
            image,
            points,
            ranges,
            sums,
            extremes,
        }
    }

    fn point(&self, cell: usize) -> Option<Vector3<f64>> {
        let p = self.points[cell];
        (!p.x.is_nan()).then_some(p)
    }
}

/// Reused point buffers of one worker thread.
#[derive(Default)]
struct Scratch {
    points: Vec<Vector3<f64>>,
    on_plane: Vec<Vector3<f64>>,
    /// Per entry of `points`: the return is one of the cell's 8 neighbours.
    immediate: Vec<bool>,
}

/// Fit the cell's plane in its window; where the window's points spread over
/// less than a few noise sigmas in the plane (a close object seen by a dense
/// sensor) the normal would be mostly noise, so the window grows (up to 7 beams).
fn fit_cell(
    returns: &Returns,
    geometry: &ImageGeometry,
    cell: usize,
    params: SurfaceParams,
    scratch: &mut Scratch,
) -> CellSurface {
    if params.sparse_rows {
        return fit_ring_cell(returns, geometry, cell, params, scratch);
    }
    let mut best = EMPTY;
    for grow in 1..=MAX_GROWTH {
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
        best = surface;
        if spread.is_none_or(|s| s >= 2.0 * params.range_noise_m) {
            break;
        }
    }
    best
}

/// Growths of a cell's window at most: `2 grow + 1` beams.
const MAX_GROWTH: usize = 3;

/// One fit over a window of `2 half_rows + 1` beams by `2 half_cols + 1`
/// columns (`(half_rows, half_cols)`), `gated` its `gated_window`; also
/// returns the in-plane spread of the points fitted.
fn fit_window(
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
fn fit_gated_points(
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
fn fit_whole_window(
    returns: &Returns,
    cols: usize,
    center: &Vector3<f64>,
    params: SurfaceParams,
    window: &GatedWindow,
) -> Option<(CellSurface, Option<f64>)> {
    let range = center.norm();
    let moments = window.total;
    if moments.count < 4.0 {
        return None;
    }
    let (centroid, covariance) = moments.scatter()?;
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
struct GatedWindow {
    /// Moments of all the window's returns.
    total: Moments,
    first_row: usize,
    last_row: usize,
    col: usize,
    half_cols: usize,
    /// The cell's range, metres.
    range_m: f64,
}

/// None where the cell is empty, a return is beyond the gate, or the window
/// is wider than the image.
fn gated_window(
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
    Some(GatedWindow {
        range_m,
        total: returns
            .sums
            .window_over_rows(first_row..=last_row, col, half_cols)?,
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
fn too_narrow(gated: &GatedWindow, params: SurfaceParams) -> bool {
    let count = gated.total.count;
    let Some((_, scatter)) = gated.total.scatter().filter(|_| count >= 4.0) else {
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

/// Sum of the 2x2 principal minors of a symmetric matrix.
fn principal_minors(a: &Matrix3<f64>) -> f64 {
    a[(0, 0)] * a[(1, 1)] - a[(0, 1)].powi(2) + a[(0, 0)] * a[(2, 2)] - a[(0, 2)].powi(2)
        + a[(1, 1)] * a[(2, 2)]
        - a[(1, 2)].powi(2)
}

/// How many eigenvalues of a symmetric matrix lie below `bound`: the sign
/// changes along 1 and the leading principal minors of `a - bound I`; None
/// where a minor is zero (or not finite), which the rule does not cover.
fn eigenvalues_below(a: &Matrix3<f64>, bound: f64) -> Option<usize> {
    let b = a - Matrix3::identity() * bound;
    let minors = [
        1.0,
        b[(0, 0)],
        b[(0, 0)] * b[(1, 1)] - b[(0, 1)] * b[(1, 0)],
        b.determinant(),
    ];
    if minors[1..3].contains(&0.0) || !minors.iter().all(|m| m.is_finite()) {
        return None;
    }
    Some(
        minors
            .windows(2)
            .filter(|pair| (pair[0] < 0.0) != (pair[1] < 0.0))
            .count(),
    )
}

/// Every return of the window lies within `tolerance` of `plane`. The squared distances sum to the plane's smallest scatter over
/// the window, and to a quadratic of each row's moments over the row: no
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

/// The loose range gate of a window about a return `range_m` away, metres:
/// neighbours farther from it in range are not candidates for its plane.
fn range_gate_m(range_m: f64) -> f64 {
    0.3 * range_m + 0.5
}

/// How far off a fitted plane a return `range_m` away may lie and still be
/// on it, metres: four noise sigmas and the plane's own error with range.
fn plane_tolerance_m(params: SurfaceParams, range_m: f64) -> f64 {
    4.0 * params.range_noise_m + 0.003 * range_m
}

/// A return with no surface fitted: its raw range and direction.
fn raw_surface(center: &Vector3<f64>) -> CellSurface {
    let range = center.norm();
    CellSurface {
        range_m: range as f32,
        direction: as_f32(&(center / range)),
        support: 1,
        ..EMPTY
    }
}

fn as_f32(v: &Vector3<f64>) -> [f32; 3] {
    [v.x as f32, v.y as f32, v.z as f32]
}

/// `normal` turned to face the sensor along `direction`.
fn facing_sensor(normal: Vector3<f64>, direction: &Vector3<f64>) -> Vector3<f64> {
    if normal.dot(direction) > 0.0 {
        -normal
    } else {
        normal
    }
}

/// A return on the surface through `centroid` with `normal`: the normal
/// facing the sensor, the incidence, and the denoised range (the ray
/// against the surface, where within `tolerance` of the raw range; near
/// grazing the intersection is ill-conditioned, so the raw range stays).
fn oriented(
    center: &Vector3<f64>,
    centroid: &Vector3<f64>,
    normal: Vector3<f64>,
    tolerance: f64,
) -> CellSurface {
    let range = center.norm();
    let direction = center / range;
    let normal = facing_sensor(normal, &direction);
    let incidence_cos = normal.dot(&direction).abs();
    let denoised = if incidence_cos >= 0.1 {
        centroid.dot(&normal) / direction.dot(&normal)
    } else {
        range
    };
    let range_m = if (denoised - range).abs() <= tolerance && denoised > 0.0 {
        denoised
    } else {
        range
    };
    CellSurface {
        range_m: range_m as f32,
        direction: as_f32(&direction),
        normal: as_f32(&normal),
        incidence_cos: incidence_cos as f32,
        ..raw_surface(center)
    }
}

/// The ground's height below a sparse sensor: the median height of the
/// returns of rays pointing more than 10 degrees down (on an 8-beam sensor
/// its lowest rings), -inf without any.
fn ground_height(scan: &Scan, image: &RangeImage) -> f64 {
    let mut heights: Vec<f32> = image
        .point
        .iter()
        .filter(|&&i| i != NO_POINT)
        .map(|&i| scan.points_m[i as usize])
        .filter(|p| p[2] < -(p[0].hypot(p[1])) * DOWN_TAN)
        .map(|p| p[2])
        .collect();
    if heights.len() < 20 {
        return f64::NEG_INFINITY;
    }
    f64::from(median_f32(&mut heights))
}

/// tan(10 degrees).
const DOWN_TAN: f32 = 0.176;

/// A cell of a sparse sensor: a line fitted along its ring (the returns of
/// the same laser in `2 * RING_HALF_WINDOW + 1` columns). One direction
/// does not give a plane, so the surface's orientation comes from the world
/// such sensors see: a level line at the ground's height is ground (normal
/// up), anything else a vertical surface through the line (a wall, a car's
/// side, a post).
fn fit_ring_cell(
    returns: &Returns,
    geometry: &ImageGeometry,
    cell: usize,
    params: SurfaceParams,
    scratch: &mut Scratch,
) -> CellSurface {
    let Some(center) = returns.point(cell) else {
        return EMPTY;
    };
    let raw = raw_surface(&center);
    let (range, direction) = (center.norm(), center / center.norm());
    let Scratch {
        points, immediate, ..
    } = scratch;
    points.clear();
    immediate.clear();
    points.push(center);
    immediate.push(false);
    let (row, col) = (cell / geometry.cols, cell % geometry.cols);
    let mut far_neighbours = 0;
    for offset in 1..=RING_HALF_WINDOW {
        for c in [col + offset, col + geometry.cols - offset] {
            let n = row * geometry.cols + c % geometry.cols;
            let Some(p) = returns.point(n) else { continue };
            if (p.norm() - range).abs() <= 0.1 * range + 0.3 {
                points.push(p);
                immediate.push(offset == 1);
            } else if offset == 1 {
                far_neighbours += 1;
            }
        }
    }
    let Some((tangent, centroid)) = fit_line(points) else {
        return CellSurface {
            edge: far_neighbours > 0,
            ..raw
        };
    };
    let tolerance = plane_tolerance_m(params, range);
    let off_line = |p: &Vector3<f64>| {
        let d = p - centroid;
        (d - tangent * d.dot(&tangent)).norm() > tolerance
    };
    let immediate_off = points
        .iter()
        .zip(immediate.iter())
        .filter(|(p, near)| **near && off_line(p))
        .count();
    let edge = off_line(&center) || far_neighbours + immediate_off > 0;
    let support = points.iter().filter(|p| !off_line(p)).count();
    let up = Vector3::z();
    let level = tangent.z.abs() < LEVEL_TANGENT_Z;
    let on_ground = (center.z - params.ground_z_m).abs() < 0.25 + 0.02 * range;
    let normal = if level && on_ground {
        (up - tangent * tangent.dot(&up)).normalize()
    } else {
        let across = tangent.cross(&up);
        if across.norm() > 0.1 {
            across.normalize()
        } else {
            // A vertical line: the surface faces the sensor horizontally.
            Vector3::new(direction.x, direction.y, 0.0).normalize()
        }
    };
    let d = center - centroid;
    CellSurface {
        residual_m: (d - tangent * d.dot(&tangent)).norm() as f32,
        support: support.min(255) as u8,
        edge,
        ..oriented(&center, &centroid, normal, tolerance)
    }
}

/// Columns on each side of a sparse sensor's cell in its ring's line fit.
const RING_HALF_WINDOW: usize = 3;
/// A ring's line is level when its direction rises less than this (sine).
const LEVEL_TANGENT_Z: f64 = 0.3;

/// Centroid and scatter matrix (sum of outer products about it) of points.
/// The six distinct sums by hand: this runs for every window of every cell.
fn scatter(points: &[Vector3<f64>]) -> (Vector3<f64>, Matrix3<f64>) {
    let centroid = points.iter().sum::<Vector3<f64>>() / points.len() as f64;
    let [mut xx, mut xy, mut xz, mut yy, mut yz, mut zz] = [0.0; 6];
    for p in points {
        let (x, y, z) = (p.x - centroid.x, p.y - centroid.y, p.z - centroid.z);
        xx += x * x;
        xy += x * y;
        xz += x * z;
        yy += y * y;
        yz += y * z;
        zz += z * z;
    }
    let covariance = Matrix3::new(xx, xy, xz, xy, yy, yz, xz, yz, zz);
    (centroid, covariance)
}

/// Least-squares line: unit direction and centroid; None for fewer than 3
/// points or no spread.
fn fit_line(points: &[Vector3<f64>]) -> Option<(Vector3<f64>, Vector3<f64>)> {
    if points.len() < 3 {
        return None;
    }
    let (centroid, covariance) = scatter(points);
    let (_, _, largest) = symmetric_eigenvalues(&covariance)?;
    if !(largest.is_finite() && largest > 0.0) {
        return None;
    }
    let direction = null_vector(&(covariance - Matrix3::identity() * largest))?;
    Some((direction, centroid))
}

/// Least-squares plane: unit normal and centroid; None for fewer than 4 points
/// or points along a line.
#[cfg(test)]
fn fit_plane(points: &[Vector3<f64>]) -> Option<(Vector3<f64>, Vector3<f64>)> {
    fit_plane_spread(points).map(|(n, c, _)| (n, c))
}

/// [`fit_plane`] plus the RMS spread of the points within the plane (the
/// smaller in-plane axis).
pub(super) fn fit_plane_spread(
    points: &[Vector3<f64>],
) -> Option<(Vector3<f64>, Vector3<f64>, f64)> {
    if points.len() < 4 {
        return None;
    }
    let (centroid, covariance) = scatter(points);
    let plane = plane_of_scatter(points.len() as f64, centroid, &covariance)?;
    Some((plane.normal, plane.centroid, plane.spread))
}

/// A plane fitted to `count` points by their centroid and scatter matrix.
struct Plane {
    normal: Vector3<f64>,
    centroid: Vector3<f64>,
    /// RMS spread of the points within the plane (the smaller in-plane axis).
    spread: f64,
    /// Smallest eigenvalue of the scatter: the sum of the points' squared
    /// distances to the plane.
    smallest: f64,
}

fn plane_of_scatter(
    count: f64,
    centroid: Vector3<f64>,
    covariance: &Matrix3<f64>,
) -> Option<Plane> {
    let (smallest, middle, largest) = symmetric_eigenvalues(covariance)?;
    // Collinear points (one row only) do not define a plane.
    if largest.is_nan() || largest <= 0.0 || middle < 1e-3 * largest || !smallest.is_finite() {
        return None;
    }
    let normal = null_vector(&(covariance - Matrix3::identity() * smallest))?;
    Some(Plane {
        normal,
        centroid,
        spread: (middle.max(0.0) / count).sqrt(),
        smallest,
    })
}

/// Eigenvalues of a symmetric positive semi-definite 3x3 matrix (a scatter
/// matrix), ascending. The smallest by Newton's method on the characteristic
/// polynomial from 0: below the smallest root the polynomial is increasing
/// and concave, so the iteration climbs to it without overshooting, in two
/// or three steps for a plane (its smallest eigenvalue far below the
/// others); the other two from the trace and the sum of principal minors.
/// No trigonometry: this runs for every window of every cell (the closed
/// form's acos and cos were a tenth of the engine's time).
fn symmetric_eigenvalues(a: &Matrix3<f64>) -> Option<(f64, f64, f64)> {
    let trace = a.trace();
    let minors = principal_minors(a);
    let det = a.determinant();
    if !(trace.is_finite() && minors.is_finite() && det.is_finite()) {
        return None;
    }
    let mut smallest = 0.0f64;
    if minors > 0.0 && det > 0.0 {
        for _ in 0..NEWTON_STEPS {
            let value = ((smallest - trace) * smallest + minors) * smallest - det;
            let slope = (3.0 * smallest - 2.0 * trace) * smallest + minors;
            if slope <= 0.0 {
                break;
            }
            let step = value / slope;
            smallest -= step;
            if step.abs() <= 1e-14 * trace {
                break;
            }
        }
    }
    // The other two: sum `trace - smallest`, product `minors - smallest * sum`.
    let sum = trace - smallest;
    let product = minors - smallest * sum;
    let half_gap = (0.25 * sum * sum - product).max(0.0).sqrt();
    let middle = 0.5 * sum - half_gap;
    let largest = 0.5 * sum + half_gap;
    Some((smallest, middle.max(smallest), largest))
}

/// Newton steps at most for the smallest eigenvalue (a plane needs 2-3; two
/// equal small eigenvalues, a line, converge linearly).
const NEWTON_STEPS: usize = 30;

/// A unit vector in the null space of a (nearly) singular symmetric matrix: the
/// largest cross product of two of its rows.
fn null_vector(m: &Matrix3<f64>) -> Option<Vector3<f64>> {
    let rows = [
        Vector3::new(m[(0, 0)], m[(0, 1)], m[(0, 2)]),
        Vector3::new(m[(1, 0)], m[(1, 1)], m[(1, 2)]),
        Vector3::new(m[(2, 0)], m[(2, 1)], m[(2, 2)]),
    ];
    let candidates = [
        rows[0].cross(&rows[1]),
        rows[0].cross(&rows[2]),
        rows[1].cross(&rows[2]),
    ];
    // The largest (the last of equals, in total order), without an iterator.
    let mut best = 0;
    let mut best_norm_squared = candidates[0].norm_squared();
    for (k, candidate) in candidates.iter().enumerate().skip(1) {
        let norm_squared = candidate.norm_squared();
        if norm_squared.total_cmp(&best_norm_squared).is_ge() {
            (best, best_norm_squared) = (k, norm_squared);
        }
    }
    let norm = best_norm_squared.sqrt();
    (norm > 0.0 && norm.is_finite()).then(|| candidates[best] / norm)
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn a_plane_fit_recovers_the_plane() {
        let normal = Vector3::new(0.2, -0.3, 0.9).normalize();
        let u = normal.cross(&Vector3::x()).normalize();
        let v = normal.cross(&u);
        let base = Vector3::new(5.0, 1.0, -1.7);
        let points: Vec<Vector3<f64>> = (0..9)
            .map(|k| base + u * f64::from(k % 3) * 0.2 + v * f64::from(k / 3) * 0.3)
            .collect();
        let (fitted, centroid) = fit_plane(&points).unwrap();
        assert!(fitted.dot(&normal).abs() > 1.0 - 1e-9);
        assert!((centroid - base).dot(&normal).abs() < 1e-9);
    }

    #[test]
    fn points_on_a_line_define_no_plane() {
        let points: Vec<Vector3<f64>> = (0..5)
            .map(|k| Vector3::new(f64::from(k), 2.0 * f64::from(k), 1.0))
            .collect();
        assert!(fit_plane(&points).is_none());
    }

    /// Uniform numbers in [-0.5, 0.5), the same sequence every run.
    fn uniform_numbers() -> impl FnMut() -> f64 {
        let mut state = 0x2545_f491_4f6c_dd1du64;
        move || {
            state ^= state << 13;
            state ^= state >> 7;
            state ^= state << 17;
            (state >> 11) as f64 / (1u64 << 53) as f64 - 0.5
        }
    }

    /// Scatter matrices of windows on planes (one small eigenvalue), of
    /// isotropic clouds and of lines.
    fn scatter_matrices() -> Vec<Matrix3<f64>> {
        let mut uniform = uniform_numbers();
        (0..300)
            .map(|case| {
                let thickness = [1e-4, 0.02, 1.0][case % 3];
                let width = if case % 7 == 0 { 1e-6 } else { 0.3 };
                let points: Vec<Vector3<f64>> = (0..15)
                    .map(|_| Vector3::new(uniform(), uniform() * width, uniform() * thickness))
                    .collect();
                scatter(&points).1
            })
            .collect()
    }

    #[test]
    fn eigenvalues_match_nalgebras_on_scatter_matrices() {
        // Against nalgebra's iterative solver.
        for (case, covariance) in scatter_matrices().into_iter().enumerate() {
            let (a, b, c) = symmetric_eigenvalues(&covariance).unwrap();
            let mut expected: Vec<f64> = covariance
                .symmetric_eigen()
                .eigenvalues
                .iter()
                .copied()
                .collect();
            expected.sort_by(f64::total_cmp);
            let scale = expected[2];
            for (found, want) in [a, b, c].iter().zip(&expected) {
                assert!(
                    (found - want).abs() <= 1e-9 * scale,
                    "{case}: {a} {b} {c} vs {expected:?}"
                );
            }
        }
    }

    #[test]
    fn eigenvalues_below_a_bound_are_counted_from_the_minors() {
        for (case, covariance) in scatter_matrices().into_iter().enumerate() {
            let (a, b, c) = symmetric_eigenvalues(&covariance).unwrap();
            // Bounds between and beyond the eigenvalues, clear of them.
            let bounds = [0.5 * a - 1.0, 0.5 * (a + b), 0.5 * (b + c), 2.0 * c + 1.0];
            for (expected, bound) in bounds.into_iter().enumerate() {
                let clear = [a, b, c].iter().all(|e| (e - bound).abs() > 1e-6 * c);
                if clear {
                    assert_eq!(
                        eigenvalues_below(&covariance, bound),
                        Some(expected),
                        "{case}: {bound} against {a} {b} {c}"
                    );
                }
            }
        }
    }

    /// The returns of a `rows x cols` image of a noisy plane 10 m ahead,
    /// with one return `off_plane_m` in front of it.
    fn noisy_plane(rows: usize, cols: usize, noise_m: f64, off_plane_m: f64) -> Vec<Vector3<f64>> {
        let mut uniform = uniform_numbers();
        (0..rows * cols)
            .map(|cell| {
                let (row, col) = ((cell / cols) as f64, (cell % cols) as f64);
                let depth = 10.0 + 0.05 * col + noise_m * uniform();
                let depth = if cell == 2 * cols + 5 {
                    depth - off_plane_m
                } else {
                    depth
                };
                Vector3::new(depth, 0.03 * col, 0.07 * row - 0.5)
            })
            .collect()
    }

    /// A dense image's geometry, parameters and (unused) gridded scan.
    fn dense_image(
        rows: usize,
        cols: usize,
        noise_m: f64,
    ) -> (ImageGeometry, SurfaceParams, RangeImage) {
        let geometry = ImageGeometry {
            rows,
            cols,
            beams: super::super::beams::BeamTable::uniform(rows, -0.1, 0.1),
            ring_to_row: None,
            parallax_rad_m: None,
        };
        let params = SurfaceParams {
            range_noise_m: noise_m,
            half_cols: 2,
            sparse_rows: false,
            ground_z_m: f64::NEG_INFINITY,
        };
        let image = RangeImage {
            range_m: Vec::new(),
            point: Vec::new(),
            point_cell: Vec::new(),
            point_surface: Vec::new(),
        };
        (geometry, params, image)
    }

    #[test]
    fn whole_window_fits_match_fits_point_by_point() {
        let (rows, cols) = (5, 24);
        let (geometry, params, image) = dense_image(rows, cols, 0.002);
        // Noise enough for the windows' summed squared distances to exceed
        // the tolerance (rows are then looked at one by one), and a return
        // off the plane by more than the tolerance.
        let points = noisy_plane(rows, cols, 0.03, 0.2);
        let returns = Returns::of_points(&image, points, cols, &[2, 4]);
        let mut scratch = Scratch::default();
        let (mut whole, mut off) = (0, 0);
        for cell in 0..rows * cols {
            for window in [(1, 2), (2, 4)] {
                let center = returns.point(cell).unwrap();
                let by_points = fit_gated_points(
                    &returns,
                    &geometry,
                    cell,
                    &center,
                    params,
                    window,
                    &mut scratch,
                );
                let gated = gated_window(&returns, &geometry, cell, window).unwrap();
                let Some((fit, spread)) = fit_whole_window(&returns, cols, &center, params, &gated)
                else {
                    off += 1;
                    assert!(by_points.0.edge, "cell {cell} {window:?}: an edge");
                    continue;
                };
                whole += 1;
                assert!(!by_points.0.edge, "cell {cell} {window:?}: no edge");
                assert!((fit.range_m - by_points.0.range_m).abs() < 1e-5);
                assert!((spread.unwrap() - by_points.1.unwrap()).abs() < 1e-6);
                let dot: f32 = (0..3).map(|k| fit.normal[k] * by_points.0.normal[k]).sum();
                assert!(dot > 1.0 - 1e-6, "cell {cell} {window:?}: normals {dot}");
            }
        }
        assert!(
            whole > 0 && off > 0,
            "{whole} whole windows, {off} off the plane"
        );
    }

    #[test]
    fn windows_found_too_narrow_fit_with_a_spread_below_two_sigmas() {
        let (rows, cols) = (5, 24);
        let mut narrow = 0;
        for noise_m in [0.005, 0.03] {
            let (geometry, params, image) = dense_image(rows, cols, noise_m);
            let points = noisy_plane(rows, cols, noise_m, 0.5);
            let returns = Returns::of_points(&image, points, cols, &[2, 4]);
            let mut scratch = Scratch::default();
            for cell in 0..rows * cols {
                for window in [(1, 2), (2, 4)] {
                    let gated = gated_window(&returns, &geometry, cell, window);
                    let (fit, spread) = fit_window(
                        &returns,
                        &geometry,
                        cell,
                        params,
                        window,
                        gated.as_ref(),
                        &mut scratch,
                    );
                    if gated.is_some_and(|g| too_narrow(&g, params)) {
                        narrow += 1;
                        let wide = spread.is_none_or(|s| s >= 2.0 * noise_m);
                        assert!(!wide && !fit.edge, "cell {cell} {window:?}: {spread:?}");
                    }
                }
            }
        }
        assert!(narrow > 0);
    }

    #[test]
    fn eigenvalues_of_a_diagonal_matrix_are_its_diagonal() {
        let m = Matrix3::from_diagonal(&Vector3::new(3.0, 1.0, 2.0));
        let (a, b, c) = symmetric_eigenvalues(&m).unwrap();
        assert!((a - 1.0).abs() < 1e-12 && (b - 2.0).abs() < 1e-12 && (c - 3.0).abs() < 1e-12);
    }
}
