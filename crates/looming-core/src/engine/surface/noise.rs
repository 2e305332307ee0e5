//! Each laser's range noise, estimated from the scan itself: along its row
//! ([`row_noise`]) and about the planes fitted across lasers
//! ([`noise_per_row`]), shrunk to the sensor's where a row is close to it.

use rayon::prelude::*;

use nalgebra::Vector3;

use super::plane::{Plane, plane_of_scatter};
use super::window::{
    WHOLE_WINDOW_MARGIN, fit_window, gated_window, window_rows, within_range_gate,
};
use super::{Returns, Scratch, SurfaceParams, plane_tolerance_m};
use crate::engine::grid::{ImageGeometry, RangeImage};
use crate::engine::window_sums::column_spans;

/// Range noise of each row, metres: from the second differences of the raw
/// ranges along the row (three consecutive returns of one laser on one
/// smooth surface: `r[c-1] - 2 r[c] + r[c+1]` is noise times sqrt(6) plus a
/// curvature that is negligible at one cell), robustly (median). Real lasers
/// differ (per-laser noise and intensity-dependent error); a row with too
/// few samples takes `default_m`. Clamped to [0.005, 0.1] m.
pub(super) fn row_noise(image: &RangeImage, geometry: &ImageGeometry, default_m: f64) -> Vec<f32> {
    // One buffer for every row's differences (a row's own was an
    // allocation per row per scan).
    let mut second: Vec<f32> = Vec::with_capacity(geometry.cols);
    (0..geometry.rows)
        .map(|row| {
            let ranges = &image.range_m[row * geometry.cols..(row + 1) * geometry.cols];
            second.clear();
            second.extend(ranges.windows(3).filter_map(|w| {
                let (a, b, c) = (w[0], w[1], w[2]);
                let smooth = (a - b).abs() < 0.05 * b && (c - b).abs() < 0.05 * b;
                (a.is_finite() && b.is_finite() && c.is_finite() && smooth)
                    .then(|| (a - 2.0 * b + c).abs())
            }));
            if second.len() < MIN_NOISE_SAMPLES {
                return default_m as f32;
            }
            let median = median_f32(&mut second);
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
pub(super) fn noise_per_row(
    returns: &Returns,
    geometry: &ImageGeometry,
    params: SurfaceParams,
) -> Vec<f32> {
    let along = row_noise(returns.image, geometry, params.range_noise_m);
    let loose = SurfaceParams {
        range_noise_m: LOOSE_NOISE_M,
        ..params
    };
    let scatter: Vec<f32> = (0..geometry.rows)
        .into_par_iter()
        .map_init(
            || (Scratch::default(), Vec::new()),
            |(scratch, residuals), row| {
                residuals.clear();
                residuals.extend((0..geometry.cols).step_by(NOISE_STRIDE).filter_map(|col| {
                    plane_scatter_m(returns, geometry, row * geometry.cols + col, loose, scratch)
                }));
                if residuals.len() < MIN_NOISE_SAMPLES / 2 {
                    return f32::NAN;
                }
                // A return's distance to a plane fitted with it is about 0.9 of
                // its noise in a window of 15; the median of |N(0, s)| is 0.67 s.
                1.4826 * median_f32(residuals) / 0.9
            },
        )
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

/// The distance of `cell`'s return to the plane of its window of one beam
/// either side (`loose.half_cols` columns), for [`noise_per_row`]: where
/// [`fit_window`] with the `loose` gate would give a plane of at least
/// [`MIN_SCATTER_SUPPORT`] returns with no edge (no return beyond the
/// range gate or off the plane), the same |residual| to the bit; None where
/// it would not. Only the window's gate, moments and plane: not the
/// denoised range, direction and normal facing the sensor that the fit
/// also makes (a fifth of the noise's time), nor the fit at all where a
/// return beyond the gate makes an edge. The whole fit where the window
/// is not from the running sums, or their plane fails (`plane_scatter_by_fit`).
pub(super) fn plane_scatter_m(
    returns: &Returns,
    geometry: &ImageGeometry,
    cell: usize,
    loose: SurfaceParams,
    scratch: &mut Scratch,
) -> Option<f32> {
    // `ranges` is NaN exactly where the cell is empty: no fit.
    let range_m = returns.ranges[cell];
    if range_m.is_nan() {
        return None;
    }
    let ((rows, col), half_cols) = (window_rows(geometry, cell, 1), loose.half_cols);
    // `gated_window`'s gate: a return beyond it is an edge (`fit_beyond_gate`).
    let within = within_range_gate(returns, (rows.clone(), col, half_cols), range_m);
    let total = match within {
        Some(false) => return None,
        Some(true) => returns.sums.window_over_rows(rows.clone(), col, half_cols),
        None => None,
    };
    let Some(total) = total else {
        return plane_scatter_by_fit(returns, geometry, cell, loose, scratch);
    };
    // Fewer returns: no fit of them has the support (`fit_gated_points`
    // fits a subset of them).
    if total.count < MIN_SCATTER_SUPPORT {
        return None;
    }
    let plane = total
        .scatter()
        .and_then(|(centroid, covariance)| plane_of_scatter(total.count, centroid, &covariance));
    let Some(plane) = plane else {
        return plane_scatter_by_fit(returns, geometry, cell, loose, scratch);
    };
    let tolerance = plane_tolerance_m(loose, range_m);
    if any_off_plane(
        returns,
        geometry.cols,
        (rows, col, half_cols),
        &plane,
        tolerance,
    ) {
        return None;
    }
    // `on_plane`'s residual, its sign (the normal facing the sensor) aside.
    let residual_m = ((returns.points[cell] - plane.centroid).dot(&plane.normal) as f32).abs();
    residual_m.is_finite().then_some(residual_m)
}

/// [`plane_scatter_m`] by the whole fit: the reference it keeps to.
pub(super) fn plane_scatter_by_fit(
    returns: &Returns,
    geometry: &ImageGeometry,
    cell: usize,
    loose: SurfaceParams,
    scratch: &mut Scratch,
) -> Option<f32> {
    let window = (1, loose.half_cols);
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
    (f64::from(fit.support) >= MIN_SCATTER_SUPPORT && !fit.edge && fit.residual_m.is_finite())
        .then(|| fit.residual_m.abs())
}

/// Whether a return of the window (`rows`, about `col`, `half_cols` either
/// side) lies farther than `tolerance` from `plane`: where
/// `off_plane_moments` finds any, looking at the same rows.
fn any_off_plane(
    returns: &Returns,
    cols: usize,
    (rows, col, half_cols): (std::ops::RangeInclusive<usize>, usize, usize),
    plane: &Plane,
    tolerance: f64,
) -> bool {
    let limit = WHOLE_WINDOW_MARGIN * tolerance * tolerance;
    if plane.smallest <= limit {
        return false;
    }
    let offset = plane.centroid.dot(&plane.normal);
    // An empty cell's NaN is no distance beyond the tolerance.
    let is_off = |p: &Vector3<f64>| (p - plane.centroid).dot(&plane.normal).abs() > tolerance;
    rows.filter(|&r| {
        let of_row = returns.sums.window(r, col, half_cols);
        of_row.is_none_or(|moments| moments.squared_distances(&plane.normal, offset) > limit)
    })
    .any(|r| {
        column_spans(col, half_cols, cols)
            .into_iter()
            .flatten()
            .any(|span| {
                returns.points[r * cols + span.start..r * cols + span.end]
                    .iter()
                    .any(is_off)
            })
    })
}

/// The median (upper middle) of `values`, reordering them.
pub(super) fn median_f32(values: &mut [f32]) -> f32 {
    let mid = values.len() / 2;
    *values.select_nth_unstable_by(mid, f32::total_cmp).1
}

/// Each row's noise, or the sensor's (the median over rows) where the row
/// is within a third of it: a row's own estimate moves by some 10 % from
/// scan to scan, and thresholds at 4 sigma then flip cells; a laser really
/// noisier or quieter than the rest (an HDL-64E's spread 0.007 to 0.05 m)
/// keeps its own.
pub(super) fn shrunk_to_sensor(mut noise: Vec<f32>) -> Vec<f32> {
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
/// Every how many columns the plane scatter is measured: 256 samples a row
/// at 2048 columns. Every fourth column cost 8 % more of the synthetic
/// drive's plane fits and moved no figure of the accuracy tables (its
/// outputs at 64 x 2048 are byte-identical either way); on the real
/// logs the braking face's and the static objects' figures moved by 0-8 %
/// either way, the near misses not at all (docs/performance.md,
/// 2026-11-27). Tried twice before, when the fits were the old ones, it
/// moved the braking car's object p90 by 12-16 %.
const NOISE_STRIDE: usize = 8;

/// Returns the plane of a cell's window needs for its scatter to count.
const MIN_SCATTER_SUPPORT: f64 = 6.0;

/// Second differences a row needs for its own noise estimate.
const MIN_NOISE_SAMPLES: usize = 50;
