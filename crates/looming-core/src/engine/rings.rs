//! The rows of a ring-ordered sensor: each ring's elevation model
//! `beam + c / range` and its row once sorted by elevation
//! ([`ring_elevations`]), measured on one pair in ten
//! (`EngineCache::geometry_for`), and whether the rings so measured still
//! hold for a later scan ([`rings_still_hold`]).

use rayon::prelude::*;

use super::beams::BeamTable;
use super::grid::{ImageGeometry, elevation};
use crate::model::Scan;

/// Each ring's elevation model `beam + c / range` (rings with no points
/// interpolated by ring number), and the row of each ring once sorted by
/// elevation.
pub(super) fn ring_elevations(
    scan: &Scan,
    rows: usize,
) -> Option<(BeamTable, Vec<usize>, Option<Vec<f64>>)> {
    let rings = scan.ring.as_ref()?;
    // Each ring's list made as long as it will be (its returns counted):
    // pushed into from empty, the lists grew and copied several times.
    let mut counts = vec![0usize; rows];
    for &ring in rings {
        if let Some(count) = counts.get_mut(usize::from(ring)) {
            *count += 1;
        }
    }
    let mut per_ring: Vec<Vec<(f32, f32)>> = counts.into_iter().map(Vec::with_capacity).collect();
    // The angles on both cores (an `atan2` per return), then bucketed in order.
    let values: Vec<(f32, f32)> = scan
        .points_m
        .par_iter()
        .map(|p| {
            let range = (p[0] * p[0] + p[1] * p[1] + p[2] * p[2]).sqrt();
            (1.0 / range, elevation(p) as f32)
        })
        .collect();
    for (value, &ring) in values.into_iter().zip(rings) {
        per_ring[usize::from(ring)].push(value);
    }
    let known: Vec<(usize, ElevationModel)> = per_ring
        .par_iter_mut()
        .enumerate()
        .filter_map(|(row, values)| ElevationModel::fit(values).map(|model| (row, model)))
        .collect();
    if known.len() < 2 {
        return None;
    }
    // A laser whose ranges did not spread enough to measure its offset takes
    // its neighbours' (the lasers of one block share a mounting height).
    let measured: Vec<(usize, f64)> = known
        .iter()
        .filter_map(|(row, m)| m.parallax_rad_m.map(|c| (*row, c)))
        .collect();
    let with_parallax = measured.iter().any(|(_, c)| c.abs() >= MIN_PARALLAX_RAD_M);
    let parallax: Vec<f64> = (0..rows)
        .map(|row| nearest_measured(&measured, row))
        .collect();
    let known: Vec<(usize, ElevationModel)> = known
        .into_iter()
        .map(|(row, m)| {
            let c = m.parallax_rad_m.unwrap_or(parallax[row]);
            (row, ElevationModel::with_parallax(&m, c))
        })
        .collect();
    // Fill rings without returns (sky) by linear inter/extrapolation.
    let interpolate = |row: usize, of: &dyn Fn(&ElevationModel) -> f64| {
        let upper = known
            .iter()
            .position(|(r, _)| *r >= row)
            .unwrap_or(known.len() - 1)
            .max(1);
        let (r0, m0) = &known[upper - 1];
        let (r1, m1) = &known[upper];
        let (e0, e1) = (of(m0), of(m1));
        e0 + (e1 - e0) * (row as f64 - *r0 as f64) / (*r1 as f64 - *r0 as f64)
    };
    let elevations: Vec<f64> = (0..rows)
        .map(|row| interpolate(row, &|m| m.elevation_at(ORDER_RANGE_M)))
        .collect();
    let mut order: Vec<usize> = (0..rows).collect();
    order.sort_by(|a, b| elevations[*a].total_cmp(&elevations[*b]).then(a.cmp(b)));
    let mut ring_to_row = vec![0; rows];
    for (row, &ring) in order.iter().enumerate() {
        ring_to_row[ring] = row;
    }
    // The beam table holds each beam's elevation far away; rows are ordered
    // at a typical range.
    let mut sorted: Vec<f64> = order
        .iter()
        .map(|&ring| elevations[ring] - parallax[ring] / ORDER_RANGE_M)
        .collect();
    // Equal elevations would make row_f flat: nudge them apart.
    for k in 1..sorted.len() {
        if sorted[k] <= sorted[k - 1] {
            sorted[k] = sorted[k - 1] + 1e-6;
        }
    }
    let parallax = with_parallax.then(|| order.iter().map(|&ring| parallax[ring]).collect());
    Some((
        BeamTable {
            elevations_rad: sorted,
        },
        ring_to_row,
        parallax,
    ))
}

/// Range at which rings are put in elevation order, metres.
const ORDER_RANGE_M: f64 = 10.0;

/// Offsets below this (rad m, a 5 mm lever) are no offset.
const MIN_PARALLAX_RAD_M: f64 = 0.005;

/// The measured offset of the nearest ring (by ring number) that has one.
fn nearest_measured(measured: &[(usize, f64)], row: usize) -> f64 {
    measured
        .iter()
        .min_by_key(|(r, _)| r.abs_diff(row))
        .map_or(0.0, |(_, c)| *c)
}

/// A laser's measured elevation against range: `beam + c / range`; `c`
/// unknown (`None`) where the ranges did not spread enough to tell.
#[derive(Debug, Clone, Copy)]
struct ElevationModel {
    beam_rad: f64,
    parallax_rad_m: Option<f64>,
    /// Median elevation and inverse range of the returns, to re-anchor the
    /// beam when `c` comes from a neighbour.
    median_elevation_rad: f64,
    median_inverse_range: f64,
}

impl ElevationModel {
    fn elevation_at(&self, range_m: f64) -> f64 {
        self.beam_rad + self.parallax_rad_m.unwrap_or(0.0) / range_m
    }

    /// The same laser with the offset `c`, through its median return.
    fn with_parallax(&self, c: f64) -> Self {
        match self.parallax_rad_m {
            Some(_) => *self,
            None => Self {
                beam_rad: self.median_elevation_rad - c * self.median_inverse_range,
                parallax_rad_m: Some(c),
                ..*self
            },
        }
    }

    /// The median elevation without parallax, and the median inverse range
    /// (`(inverse range, elevation)` samples); None without samples. The
    /// medians by selection, not a sort of the ring's returns (a sort per
    /// ring per pair was a quarter of the range images' time); the sums of
    /// [`Self::fit`] do not depend on the order but for rounding.
    fn flat(samples: &mut [(f32, f32)]) -> Option<Self> {
        if samples.is_empty() {
            return None;
        }
        let mid = samples.len() / 2;
        let median = f64::from(
            samples
                .select_nth_unstable_by(mid, |a, b| a.1.total_cmp(&b.1))
                .1
                .1,
        );
        let mut inverse: Vec<f32> = samples.iter().map(|s| s.0).collect();
        let median_inverse_range =
            f64::from(*inverse.select_nth_unstable_by(mid, f32::total_cmp).1);
        Some(Self {
            beam_rad: median,
            parallax_rad_m: None,
            median_elevation_rad: median,
            median_inverse_range,
        })
    }

    /// Least squares of elevation on inverse range, once more without the
    /// returns beyond 3 robust sigmas (mixed pixels, specks). The median
    /// elevation (no parallax) where the ranges do not spread enough to
    /// tell, or the slope is not a laser offset (beyond 0.5 m).
    fn fit(samples: &mut [(f32, f32)]) -> Option<Self> {
        let flat = Self::flat(samples)?;
        if samples.len() < 32 {
            return Some(flat);
        }
        let Some(mut model) = least_squares(
            samples.iter().map(|&(u, e)| (f64::from(u), f64::from(e))),
            flat,
        ) else {
            return Some(flat);
        };
        // Each return's residual once (two divisions each), in the returns'
        // order for the refit's gate, a copy of them reordered for its median.
        let residuals: Vec<f64> = samples
            .iter()
            .map(|&(u, e)| (f64::from(e) - model.elevation_at(1.0 / f64::from(u))).abs())
            .collect();
        let mut reordered = residuals.clone();
        let mid = reordered.len() / 2;
        let median_residual = *reordered.select_nth_unstable_by(mid, f64::total_cmp).1;
        let gate = 3.0 * 1.4826 * median_residual + 1e-5;
        let first = model;
        model = least_squares(
            samples
                .iter()
                .zip(&residuals)
                .filter(|&(_, &residual)| residual <= gate)
                .map(|(&(u, e), _)| (f64::from(u), f64::from(e))),
            flat,
        )
        .unwrap_or(first);
        if model.parallax_rad_m.is_some_and(|c| c.abs() > 0.5) {
            return Some(flat);
        }
        Some(model)
    }
}

/// `(beam, c)` minimising the squares of `e - beam - c u` over `(u, e)`;
/// `None` when the inverse ranges do not spread (a slope would be noise).
fn least_squares(
    samples: impl Iterator<Item = (f64, f64)>,
    medians: ElevationModel,
) -> Option<ElevationModel> {
    let (mut n, mut su, mut se, mut suu, mut sue) = (0.0, 0.0, 0.0, 0.0, 0.0);
    for (u, e) in samples {
        if !(u.is_finite() && e.is_finite()) {
            continue;
        }
        n += 1.0;
        su += u;
        se += e;
        suu += u * u;
        sue += u * e;
    }
    if n < 8.0 {
        return None;
    }
    let variance_u = suu / n - (su / n).powi(2);
    // Inverse ranges spreading less than 1/200 m^-1 (all returns at one
    // range) cannot tell an offset from the beam angle.
    if variance_u.is_nan() || variance_u.sqrt() <= 0.005 {
        return None;
    }
    let slope = (sue / n - su / n * se / n) / variance_u;
    Some(ElevationModel {
        beam_rad: se / n - slope * su / n,
        parallax_rad_m: Some(slope),
        ..medians
    })
}

/// Whether a ring-ordered scan's returns still lie in the rows that
/// `geometry` (its rings measured on an earlier scan) gives their rings:
/// on a sample of the returns (some [`RING_CHECK_SAMPLES_PER_RING`] a
/// ring, evenly through the scan), no ring with at least
/// [`RING_CHECK_MIN_SAMPLES`] of them has more than half further than
/// [`RING_CHECK_ROWS`] from its row. A sensor's rings do not move, but a
/// layout recovered from the points' order (`engine::layout`) numbers them
/// anew on every scan, and a laser list missed or split there renumbers
/// the rest: such a scan measures its rings again at once. (A return's
/// continuous row lies within half a row of its ring's: `row_f_at`.)
pub(crate) fn rings_still_hold(geometry: &ImageGeometry, scan: &Scan) -> bool {
    let (Some(rings), Some(ring_to_row)) = (&scan.ring, &geometry.ring_to_row) else {
        return true;
    };
    let mut sampled = vec![0u32; ring_to_row.len()];
    let mut off = vec![0u32; ring_to_row.len()];
    let stride = scan.points_m.len() / (ring_to_row.len() * RING_CHECK_SAMPLES_PER_RING).max(1);
    for (p, &ring) in scan.points_m.iter().zip(rings).step_by(stride.max(1)) {
        let ring = usize::from(ring);
        let Some(&row) = ring_to_row.get(ring) else {
            return false;
        };
        let range_m = f64::from((p[0] * p[0] + p[1] * p[1] + p[2] * p[2]).sqrt());
        if !(range_m > 0.0 && range_m.is_finite()) {
            continue;
        }
        let row_f = geometry.row_f_at(elevation(p), range_m, row);
        sampled[ring] += 1;
        off[ring] += u32::from((row_f - row as f64).abs() > RING_CHECK_ROWS);
    }
    sampled
        .iter()
        .zip(&off)
        .all(|(&n, &o)| n < RING_CHECK_MIN_SAMPLES || 2 * o <= n)
}

/// Returns a ring [`rings_still_hold`] checks, on average (some 2 000 of
/// an HDL-64E's 120 000).
const RING_CHECK_SAMPLES_PER_RING: usize = 32;
/// Returns a ring needs in [`rings_still_hold`]'s sample to be judged.
const RING_CHECK_MIN_SAMPLES: u32 = 8;
/// Rows a return may lie from its ring's row in [`rings_still_hold`]: more
/// than the half row of a return within its cell, less than the whole row
/// of a ring taken for its neighbour.
const RING_CHECK_ROWS: f64 = 0.75;

#[cfg(test)]
mod tests {
    use super::*;

    /// `ElevationModel::fit` as it was, computing each residual twice.
    fn fit_computing_residuals_twice(samples: &mut [(f32, f32)]) -> Option<ElevationModel> {
        let mid = samples.len() / 2;
        let flat = ElevationModel::flat(samples)?;
        let pairs = samples.iter().map(|&(u, e)| (f64::from(u), f64::from(e)));
        let mut model = least_squares(pairs, flat)?;
        let mut residuals: Vec<f64> = samples
            .iter()
            .map(|&(u, e)| (f64::from(e) - model.elevation_at(1.0 / f64::from(u))).abs())
            .collect();
        let median_residual = *residuals.select_nth_unstable_by(mid, f64::total_cmp).1;
        let gate = 3.0 * 1.4826 * median_residual + 1e-5;
        let first = model;
        model = least_squares(
            samples.iter().filter_map(|&(u, e)| {
                let (u, e) = (f64::from(u), f64::from(e));
                ((e - first.elevation_at(1.0 / u)).abs() <= gate).then_some((u, e))
            }),
            flat,
        )
        .unwrap_or(first);
        Some(model)
    }

    #[test]
    fn the_elevation_fit_gates_with_residuals_computed_once_to_the_bit() {
        let mut state = 0x9e37_79b9_7f4a_7c15u64;
        let mut uniform = move || {
            state ^= state << 13;
            state ^= state >> 7;
            state ^= state << 17;
            (state >> 11) as f64 / (1u64 << 53) as f64
        };
        for (ring, parallax) in [0.0, 0.02, -0.1, 0.3].into_iter().enumerate() {
            // Returns from 2 to 80 m, a noisy elevation with the laser's
            // offset, every 17th a speck far off it.
            let samples: Vec<(f32, f32)> = (0..500 + 300 * ring)
                .map(|k| {
                    let range = 2.0 + 78.0 * uniform();
                    let speck = if k % 17 == 3 { 0.05 } else { 0.0 };
                    let elevation = -0.1 + parallax / range + 1e-3 * (uniform() - 0.5) + speck;
                    ((1.0 / range) as f32, elevation as f32)
                })
                .collect();
            let (mut once, mut twice) = (samples.clone(), samples);
            let fitted = ElevationModel::fit(&mut once).expect("a model");
            let reference = fit_computing_residuals_twice(&mut twice).expect("a model");
            let bits = |m: &ElevationModel| {
                (
                    m.beam_rad.to_bits(),
                    m.parallax_rad_m.map(f64::to_bits),
                    m.median_elevation_rad.to_bits(),
                    m.median_inverse_range.to_bits(),
                )
            };
            assert_eq!(bits(&fitted), bits(&reference), "ring {ring}");
        }
    }
}
