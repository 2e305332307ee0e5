//! Each laser's range noise, estimated from the scan itself: along its row
//! ([`row_noise`]) and about the planes fitted across lasers
//! ([`noise_per_row`]), shrunk to the sensor's where a row is close to it.

use rayon::prelude::*;

use super::window::{fit_window, gated_window};
use super::{Returns, Scratch, SurfaceParams};
use crate::engine::grid::{ImageGeometry, RangeImage};

/// Range noise of each row, metres: from the second differences of the raw
/// ranges along the row (three consecutive returns of one laser on one
/// smooth surface: `r[c-1] - 2 r[c] + r[c+1]` is noise times sqrt(6) plus a
/// curvature that is negligible at one cell), robustly (median). Real lasers
/// differ (per-laser noise and intensity-dependent error); a row with too
/// few samples takes `default_m`. Clamped to [0.005, 0.1] m.
pub(super) fn row_noise(image: &RangeImage, geometry: &ImageGeometry, default_m: f64) -> Vec<f32> {
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
/// Every how many columns the plane scatter is measured.
const NOISE_STRIDE: usize = 4;

/// Second differences a row needs for its own noise estimate.
const MIN_NOISE_SAMPLES: usize = 50;
