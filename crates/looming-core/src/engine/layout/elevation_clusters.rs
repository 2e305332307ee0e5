//! Rings from elevation clusters, for clouds with no ring field and no
//! usable order: the beams are the elevations the points hug once each
//! laser's offset from the rotation axis is taken out.

use std::f64::consts::PI;

use super::{RING_COUNTS, elevation, median, range};
use crate::engine::beams::BeamTable;

/// Returns closer than this are left out of the fits (too much parallax,
/// often the vehicle itself), metres.
const NEAR_RANGE_M: f64 = 3.0;
/// The median distance of the points from their beam's line is at most this
/// share of the median beam spacing.
const MAX_RESIDUAL_OF_SPACING: f64 = 0.15;
/// Offsets of the lasers above the axis tried for the common correction, m.
const OFFSET_SEARCH_M: (f64, f64, f64) = (-0.3, 0.3, 0.01);

/// Rings from elevation clusters, for lasers mounted off the rotation axis
/// (HDL-64E lasers sit 0.1-0.2 m off the frame origin, so one laser's
/// measured elevation is `beta_k + c_k / range`: at 5 m more than the beam
/// spacing). Steps:
/// 1. a common offset `c` chosen so that `elevation - c / range` forms the
///    sharpest clusters (a histogram of 0.02 deg bins, sum of squared counts);
/// 2. the beams `beta_k` inferred ([`BeamTable::infer`]) from the corrected
///    elevations of the points beyond 3 m;
/// 3. each beam's own `c_k` (and `beta_k`) by least squares of elevation
///    against `1 / range` on the points assigned to it, then every point
///    assigned to the beam whose `beta_k + c_k / range` is nearest at its own
///    range; twice.
///
/// Ring = beam index, lowest first. `None` when no beam structure shows
/// (the points lie on median farther than 0.15 beam spacings from their
/// beam's line) or the beam count is outside [`RING_COUNTS`].
pub fn elevation_rings(points: &[[f32; 3]]) -> Option<Vec<u16>> {
    let data: Vec<(f64, f64)> = points
        .iter()
        .filter(|p| p.iter().all(|v| v.is_finite()))
        .map(|p| (elevation(p), 1.0 / range(p).max(1e-3)))
        .collect();
    if data.len() < 16 * RING_COUNTS.start() {
        return None;
    }
    let fit: Vec<(f64, f64)> = data
        .iter()
        .copied()
        .filter(|&(_, inv)| inv < 1.0 / NEAR_RANGE_M)
        .collect();
    // 1. The common offset.
    let c = common_offset(&fit);
    // 2. The beams.
    let corrected: Vec<f32> = fit.iter().map(|&(e, inv)| (e - c * inv) as f32).collect();
    let table = BeamTable::infer(&corrected, *RING_COUNTS.end())?;
    if !RING_COUNTS.contains(&table.len()) {
        return None;
    }
    let mut beams: Vec<(f64, f64)> = table.elevations_rad.iter().map(|&b| (b, c)).collect();
    // 3. Per-beam lines, refitted twice.
    for _ in 0..2 {
        refit_beam_lines(&mut beams, &fit, c);
    }
    if points_off_beams(&beams, &fit, c)? {
        return None;
    }
    Some(
        points
            .iter()
            .map(|p| {
                if !p.iter().all(|v| v.is_finite()) {
                    return 0;
                }
                nearest_beam(&beams, c, elevation(p), 1.0 / range(p).max(1e-3)) as u16
            })
            .collect(),
    )
}

/// The common offset of the lasers above the axis (m, from
/// [`OFFSET_SEARCH_M`]) for which `elevation - c / range` of the fit points
/// `(elevation, 1 / range)` forms the sharpest clusters: a histogram of
/// 0.02 deg bins, sum of squared counts.
fn common_offset(fit: &[(f64, f64)]) -> f64 {
    let bin = 0.02 * PI / 180.0;
    // Corrected elevations lie in [-pi/2 - 0.1, pi/2 + 0.1] (|c / range| <= 0.1 rad).
    let mut counts = vec![0u32; ((PI + 0.4) / bin) as usize];
    let mut sharpness = |c: f64| -> f64 {
        counts.iter_mut().for_each(|n| *n = 0);
        for &(e, inv) in fit {
            let b = ((e - c * inv + PI / 2.0 + 0.2) / bin).max(0.0) as usize;
            if let Some(n) = counts.get_mut(b) {
                *n += 1;
            }
        }
        counts.iter().map(|&n| f64::from(n) * f64::from(n)).sum()
    };
    let (lo, hi, step) = OFFSET_SEARCH_M;
    let steps = ((hi - lo) / step).round() as usize;
    (0..=steps)
        .map(|k| lo + step * k as f64)
        .map(|c| (c, sharpness(c)))
        .max_by(|a, b| a.1.total_cmp(&b.1))
        .map_or(0.0, |(c, _)| c)
}

/// The beam `(beta, c)` whose line `beta + c / range` is nearest to the
/// elevation `e` at `inv` = 1 / range; `c` is the common offset.
#[inline]
fn nearest_beam(beams: &[(f64, f64)], c: f64, e: f64, inv: f64) -> usize {
    // Beams are sorted by beta and near-parallel: search around the
    // corrected elevation's place.
    let guess = beams.partition_point(|&(b, _)| b < e - c * inv);
    let lo = guess.saturating_sub(3);
    let hi = (guess + 3).min(beams.len());
    (lo..hi)
        .min_by(|&a, &b| {
            let da = (e - beams[a].0 - beams[a].1 * inv).abs();
            let db = (e - beams[b].0 - beams[b].1 * inv).abs();
            da.total_cmp(&db)
        })
        .unwrap_or(0)
}

/// One refit of every beam's line `(beta, c_k)`: least squares of elevation
/// against 1 / range over the fit points nearest to it, the slope kept in
/// [`OFFSET_SEARCH_M`]; the beams then sorted by `beta`.
fn refit_beam_lines(beams: &mut [(f64, f64)], fit: &[(f64, f64)], c: f64) {
    let (lo, hi, _) = OFFSET_SEARCH_M;
    let mut sums = vec![[0.0f64; 5]; beams.len()]; // n, x, y, xx, xy
    for &(e, inv) in fit {
        let k = nearest_beam(beams, c, e, inv);
        let s = &mut sums[k];
        s[0] += 1.0;
        s[1] += inv;
        s[2] += e;
        s[3] += inv * inv;
        s[4] += inv * e;
    }
    for (beam, s) in beams.iter_mut().zip(&sums) {
        let [n, x, y, xx, xy] = *s;
        if n < 20.0 {
            continue;
        }
        let var = xx - x * x / n;
        // Too little spread in range: keep the common offset.
        if var <= 1e-4 * n * (x / n).powi(2).max(1e-6) {
            beam.0 = (y - beam.1 * x) / n;
            continue;
        }
        let slope = ((xy - x * y / n) / var).clamp(lo, hi);
        *beam = ((y - slope * x) / n, slope);
    }
    beams.sort_by(|a, b| a.0.total_cmp(&b.0));
}

/// Whether the fit points stay off the beams' lines: beams are lines the
/// points hug, while points scattered between them (no beam structure, e.g.
/// random points) sit a quarter spacing off; off when the median distance
/// from the nearest line exceeds [`MAX_RESIDUAL_OF_SPACING`] of the median
/// beam spacing. `None` without a median.
fn points_off_beams(beams: &[(f64, f64)], fit: &[(f64, f64)], c: f64) -> Option<bool> {
    let mut residuals: Vec<f64> = fit
        .iter()
        .map(|&(e, inv)| {
            let k = nearest_beam(beams, c, e, inv);
            (e - beams[k].0 - beams[k].1 * inv).abs()
        })
        .collect();
    let mut spacings: Vec<f64> = beams.windows(2).map(|w| w[1].0 - w[0].0).collect();
    let (Some(residual), Some(spacing)) = (median(&mut residuals), median(&mut spacings)) else {
        return None;
    };
    Some(residual > MAX_RESIDUAL_OF_SPACING * spacing)
}
