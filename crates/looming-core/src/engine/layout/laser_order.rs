//! Rings from the laser-by-laser order (KITTI `.bin`): the azimuth along the
//! point list wraps once per laser; where the lists are cut and where each
//! laser's list starts.

use std::f64::consts::PI;

use rayon::prelude::*;

use super::{
    Sweep, azimuth_turns, circular_mean_turn, elevation, median, rotation_of_step, wrap_turn,
};

/// Rings recovered from the laser-by-laser order.
#[derive(Debug, Clone, PartialEq)]
pub struct LaserOrder {
    /// Ring of every point, in list order (first laser 0).
    pub rings: Vec<u16>,
    pub ring_count: usize,
    pub sweep: Sweep,
    /// Azimuth of every point, turns (`atan2(y, x) / 2 pi`; `None`
    /// without one), for the times along the sweep.
    pub turns: Vec<Option<f64>>,
}

/// A ring with fewer than 1/20 of the mean points per ring is a spurious
/// split, not a laser (real KITTI lasers hold 0.55x to 1.1x the mean).
const MIN_RING_SHARE_DIVISOR: usize = 20;
/// Along one laser's list the azimuth runs one way on this share of the
/// steps at least (KITTI: 99 %).
const MIN_MONOTONE_SHARE: f64 = 0.9;
/// Each laser's list covers at least this share of a turn.
const MIN_LASER_TURN: f64 = 0.5;
/// Lists cut by azimuth change elevation by at least this (0.1 deg) where
/// they hand over from one laser to the next (beam spacings: 0.3-2 deg).
const AZIMUTH_CUT_MIN_HANDOVER_RAD: f64 = 0.1 * PI / 180.0;

/// Rings from the laser-by-laser order: the azimuth along the list runs one
/// way (the sweep direction, the sign of the median step) and wraps once per
/// laser. A new laser starts where the azimuth, measured from the lists'
/// start in the sweep direction, falls back by more than half a turn once
/// the current laser has reached the middle of its turn (so jitter of a point
/// or two across the start does not split a laser); each boundary is then
/// moved, within a few degrees, to where the elevation changes from one
/// laser's level to the next (lasers start at slightly different azimuths).
/// Points without an azimuth keep the current ring.
///
/// `None` unless the ring count is in `counts`, each laser turns at least
/// half a turn, the azimuth runs one way on 90 % of the steps, and no ring
/// is a sliver (fewer than 1/20 of the mean points).
///
/// The cut (where the lists start) is where the elevation hands over from
/// one laser to the next (`list_cut`).
///
/// The sweep: the direction above; the seam where the lists start, unless
/// the lists hand over from laser to laser at one common azimuth (the
/// median elevation change there is a beam spacing), which a time cut does
/// not give on a sensor whose lasers sit at azimuth offsets of several
/// degrees (HDL-64E): the lists were then sorted and cut by azimuth, which
/// says nothing of the firing time; the cut is taken as mid-sweep (where the
/// sensor is triggered) and the seam half a turn away. This is KITTI's
/// HDL-64E: lists start straight ahead, where the cameras trigger mid-sweep,
/// and the sweep starts behind (measured with its OXTS motion, see
/// `kitti::velodyne`). A sensor without azimuth offsets (VLP-16) whose
/// time-ordered lists were regrouped by laser would be read the same way:
/// its seam then comes out half a turn off.
pub fn laser_order(
    points: &[[f32; 3]],
    counts: std::ops::RangeInclusive<usize>,
) -> Option<LaserOrder> {
    let turns = azimuth_turns(points);
    let valid: Vec<(usize, f64)> = turns
        .iter()
        .enumerate()
        .filter_map(|(i, t)| t.map(|t| (i, t)))
        .collect();
    if valid.len() < 2 * *counts.start() {
        return None;
    }
    let mut steps: Vec<f64> = valid
        .windows(2)
        .map(|w| wrap_turn(w[1].1 - w[0].1))
        .collect();
    let direction = rotation_of_step(median(&mut steps)?)?;
    let sign = direction.sign();
    let elevations: Vec<f64> = valid
        .par_iter()
        .map(|&(i, _)| elevation(&points[i]))
        .collect();
    // Position along the sweep direction from a reference azimuth, [0, 1).
    let along = |reference: f64| -> Vec<f64> {
        valid
            .iter()
            .map(|&(_, t)| (sign * (t - reference)).rem_euclid(1.0))
            .collect()
    };
    let valid_turns: Vec<f64> = valid.iter().map(|&(_, t)| t).collect();
    let (cut, handover) = list_cut(&valid_turns, &elevations, sign, *counts.end())?;
    let mut starts = split_turns(&along(cut), *counts.end())?;
    // Lists cut by azimuth hand over from laser to laser at one azimuth: the
    // elevation changes there by a beam spacing on most boundaries, far more
    // than between neighbours along a list. Time-cut lists start at their
    // lasers' own azimuth offsets: no common cut shows that.
    let mut along_steps: Vec<f64> = elevations.windows(2).map(|w| (w[1] - w[0]).abs()).collect();
    let typical = median(&mut along_steps).unwrap_or(0.0);
    let azimuth_cut = handover > 5.0 * typical && handover > AZIMUTH_CUT_MIN_HANDOVER_RAD;
    let mut cut = cut;
    if !azimuth_cut {
        // Time-cut lists: the first list starts at the seam (give or take
        // its laser's offset); the last one may end past it, leaving a
        // sliver that belongs to it.
        cut = valid_turns[0];
        starts = split_turns(&along(cut), *counts.end() + 1)?;
        if let [.., before, last] = starts[..] {
            let turned: f64 = valid_turns[last..]
                .windows(2)
                .map(|w| (sign * wrap_turn(w[1] - w[0])).max(0.0))
                .sum();
            if turned < 1.0 - MIN_LASER_TURN && last > before {
                starts.pop();
            }
        }
        refine_boundaries(&mut starts, &valid_turns, &elevations, sign, cut);
    }
    let ring_count = starts.len();
    if !counts.contains(&ring_count) {
        return None;
    }
    if !lists_plausible(&valid, &starts, sign) {
        return None;
    }
    let rings = rings_of_points(points.len(), &valid, &starts);
    // The seam: the lists' start, or half a turn away for azimuth-cut lists.
    let seam_turn = if azimuth_cut {
        cut + 0.5
    } else {
        circular_mean_turn(starts.iter().map(|&k| valid_turns[k]))
    };
    Some(LaserOrder {
        rings,
        ring_count,
        sweep: Sweep {
            direction,
            seam_turn: seam_turn.rem_euclid(1.0),
        },
        turns,
    })
}

/// Whether the lists split at `starts` (indices into the valid points,
/// `(point index, azimuth turn)`) look like lasers: the azimuth runs one way,
/// each list covers most of a turn, no list is a sliver.
fn lists_plausible(valid: &[(usize, f64)], starts: &[usize], sign: f64) -> bool {
    let ring_count = starts.len();
    let mut sizes = Vec::with_capacity(ring_count);
    let (mut forward_steps, mut all_steps) = (0usize, 0usize);
    for k in 0..ring_count {
        let (a, b) = (starts[k], starts.get(k + 1).copied().unwrap_or(valid.len()));
        sizes.push(b - a);
        let mut turned = 0.0;
        for w in valid[a..b].windows(2) {
            let step = sign * wrap_turn(w[1].1 - w[0].1);
            forward_steps += usize::from(step > 0.0);
            all_steps += 1;
            turned += step.max(0.0);
        }
        if turned < MIN_LASER_TURN {
            return false;
        }
    }
    if (forward_steps as f64) < MIN_MONOTONE_SHARE * all_steps as f64 {
        return false;
    }
    let mean = valid.len() / ring_count;
    let fewest = (mean / MIN_RING_SHARE_DIVISOR).max(1);
    sizes.iter().all(|&n| n >= fewest)
}

/// Ring of every one of `point_count` points from the lists' starts (indices
/// into the valid points); points without an azimuth keep the current ring.
fn rings_of_points(point_count: usize, valid: &[(usize, f64)], starts: &[usize]) -> Vec<u16> {
    let ring_count = starts.len();
    let mut rings = vec![0u16; point_count];
    let mut ring = 0usize;
    let mut next_valid = 0usize;
    for (i, slot) in rings.iter_mut().enumerate() {
        if next_valid < valid.len() && valid[next_valid].0 == i {
            while ring + 1 < ring_count && starts[ring + 1] <= next_valid {
                ring += 1;
            }
            next_valid += 1;
        }
        *slot = ring as u16;
    }
    rings
}

/// Index (into the valid points) where each laser starts, from the position
/// along the sweep `u` in [0, 1): a fall of more than half a turn after the
/// laser has passed the middle of its turn. `None` beyond `max_rings`.
fn split_turns(u: &[f64], max_rings: usize) -> Option<Vec<usize>> {
    let mut starts = vec![0];
    let mut reached_middle = false;
    for k in 0..u.len() {
        if k > 0 && u[k - 1] - u[k] > 0.5 && reached_middle {
            if starts.len() == max_rings {
                return None;
            }
            starts.push(k);
            reached_middle = false;
        }
        reached_middle |= (0.25..=0.75).contains(&u[k]);
    }
    Some(starts)
}

/// The azimuth (turns) where the lists are cut. A first cut at the first
/// point's azimuth splits the lists roughly. Near each rough boundary
/// (within 0.1 turn) a cut at `c` hands over between the two consecutive
/// points whose azimuths straddle `c`; at the true cut those are two lasers,
/// so the elevation changes there by a beam spacing, elsewhere by little.
/// The cut is the `c` (on a 0.02 deg grid) with the largest median
/// elevation change over all boundaries (an edge in the scene near one
/// boundary does not move it). Returns the cut and that median change.
fn list_cut(turns: &[f64], elevations: &[f64], sign: f64, max_rings: usize) -> Option<(f64, f64)> {
    const WINDOW_TURN: f64 = 0.1;
    const GRID_TURN: f64 = 0.02 / 360.0;
    let first = *turns.first()?;
    let u: Vec<f64> = turns
        .iter()
        .map(|&t| (sign * (t - first)).rem_euclid(1.0))
        .collect();
    let starts = split_turns(&u, max_rings)?;
    if starts.len() < 2 {
        return Some((first.rem_euclid(1.0), 0.0));
    }
    let near = |i: usize| u[i] <= WINDOW_TURN || u[i] >= 1.0 - WINDOW_TURN;
    // Per boundary: (offset of point i from `first`, |elevation change| from
    // i - 1 to i), in list order (offsets increasing).
    let mut boundaries: Vec<Vec<(f64, f64)>> = Vec::with_capacity(starts.len() - 1);
    for &b in starts.iter().skip(1) {
        let (mut lo, mut hi) = (b, b);
        while lo > 1 && near(lo - 1) {
            lo -= 1;
        }
        while hi + 1 < turns.len() && near(hi + 1) {
            hi += 1;
        }
        let steps: Vec<(f64, f64)> = (lo.max(1)..=hi)
            .map(|i| (wrap_turn(u[i]), (elevations[i] - elevations[i - 1]).abs()))
            .collect();
        boundaries.push(steps);
    }
    let grid = (WINDOW_TURN / GRID_TURN) as i64;
    let mut changes = Vec::with_capacity(boundaries.len());
    let mut best = (f64::NEG_INFINITY, 0.0);
    // Per boundary, the first step whose end lies at or after the cut: the
    // cuts rise and the offsets do too, so each only moves forward (a
    // binary search per boundary and cut was half the layout's time).
    let mut first_after = vec![0usize; boundaries.len()];
    for g in -grid..=grid {
        let c = g as f64 * GRID_TURN;
        changes.clear();
        for (steps, k) in boundaries.iter().zip(&mut first_after) {
            while *k < steps.len() && steps[*k].0 < c {
                *k += 1;
            }
            if *k > 0 && *k < steps.len() {
                changes.push(steps[*k].1);
            }
        }
        if changes.len() * 2 < boundaries.len() {
            continue;
        }
        let score = median(&mut changes).unwrap_or(0.0);
        if score > best.0 {
            best = (score, c);
        }
    }
    Some(((first + sign * best.1).rem_euclid(1.0), best.0))
}

/// Lasers mounted at different azimuth offsets start their (time-ordered)
/// lists at different azimuths, so a common cut leaves a few points of each
/// list on a neighbour. Near each boundary (within 0.08 turn of the cut) the
/// true start shows as an azimuth step backwards (the next laser starts
/// behind where the last one ended), else as the largest jump in elevation
/// (medians of 5 points either side): the boundary moves there when that
/// jump exceeds 0.1 deg.
fn refine_boundaries(starts: &mut [usize], turns: &[f64], elevations: &[f64], sign: f64, cut: f64) {
    const WINDOW_TURN: f64 = 0.08;
    let mut steps: Vec<f64> = turns
        .windows(2)
        .map(|w| sign * wrap_turn(w[1] - w[0]))
        .collect();
    let typical = median(&mut steps.clone()).unwrap_or(0.0).abs().max(1e-6);
    let near_cut = |i: usize| wrap_turn(turns[i] - cut).abs() <= WINDOW_TURN;
    let local = |a: usize, b: usize| -> f64 {
        let mut v = elevations[a..b].to_vec();
        median(&mut v).unwrap_or(0.0)
    };
    for k in 1..starts.len() {
        let b = starts[k];
        let (floor, ceil) = (
            starts[k - 1] + 1,
            starts.get(k + 1).map_or(turns.len(), |&n| n) - 1,
        );
        let (mut lo, mut hi) = (b, b);
        while lo > floor && near_cut(lo - 1) {
            lo -= 1;
        }
        while hi < ceil && near_cut(hi) {
            hi += 1;
        }
        // Candidate starts i in (lo, hi]: the step from i - 1 to i.
        let mut best: Option<(f64, usize)> = None;
        for i in (lo + 1)..=hi.min(turns.len() - 1) {
            let step = steps[i - 1];
            let jump = (local(i.saturating_sub(5).max(floor - 1), i)
                - local(i, (i + 5).min(ceil + 1)))
            .abs();
            let score = if step < -2.0 * typical {
                jump + 1.0
            } else {
                jump
            };
            if best.is_none_or(|(s, _)| score > s) {
                best = Some((score, i));
            }
        }
        if let Some((score, i)) = best
            && score > 0.1_f64.to_radians()
        {
            starts[k] = i;
        }
    }
    let _ = &mut steps;
}
