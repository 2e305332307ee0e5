//! Rings and times from the firing order: the elevation repeats with the
//! laser count along the source index; and the sweep of a cloud whose points
//! follow the firing order without a period.

use std::f64::consts::PI;

use crate::model::Rotation;

use super::{
    RING_COUNTS, Sweep, azimuth_turn, circular_mean_turn, elevation, median, rotation_of_step,
    wrap_turn,
};

/// Rings recovered from the firing order.
#[derive(Debug, Clone, PartialEq)]
pub struct FiringOrder {
    /// `source_index mod period` of every point.
    pub rings: Vec<u16>,
    pub period: u32,
    /// Share of index pairs `(i, i + period)` whose elevations agree.
    pub score: f64,
    pub sweep: Sweep,
}

/// Elevations of the same laser one firing apart agree within this (0.1 deg:
/// the azimuth step moves the off-axis parallax little).
const FIRING_TOLERANCE_RAD: f64 = 0.1 * PI / 180.0;
/// Points looked at to find the period (the start of the cloud).
const FIRING_SAMPLE_POINTS: usize = 40_000;
/// The period's agreement share must exceed this ...
const FIRING_MIN_SCORE: f64 = 0.8;
/// ... and that of every period that is not its multiple by this margin.
const FIRING_MIN_MARGIN: f64 = 0.3;

/// Rings from the firing order: consecutive points (in the input cloud's
/// order, `source_index`, which keeps positions across dropped points) cycle
/// through N lasers, so the elevation repeats with period N. N in
/// [`RING_COUNTS`] is accepted when the share of index pairs `(i, i + N)`
/// whose elevations agree within 0.1 deg exceeds 0.8 and that of every
/// period that is not a multiple of N by 0.3; the smallest such N wins (its
/// multiples score as high). Ring = `source_index mod N`.
///
/// The sweep: the direction from the azimuth step between firings of one
/// laser; the seam at the azimuth of the first firing.
pub fn firing_order(points: &[[f32; 3]], source_index: &[u32]) -> Option<FiringOrder> {
    if points.len() != source_index.len() || points.len() < 4 * RING_COUNTS.end() {
        return None;
    }
    if source_index.windows(2).any(|w| w[1] <= w[0]) {
        return None;
    }
    let sample = points.len().min(FIRING_SAMPLE_POINTS);
    let elevations: Vec<f64> = points[..sample].iter().map(elevation).collect();
    let index = &source_index[..sample];
    let periods: Vec<u32> = (*RING_COUNTS.start() as u32..=*RING_COUNTS.end() as u32).collect();
    let scores: Vec<f64> = periods
        .iter()
        .map(|&n| period_score(index, &elevations, n))
        .collect();
    let (k, &best) = scores
        .iter()
        .enumerate()
        .filter(|&(_, &s)| s > FIRING_MIN_SCORE)
        .min_by_key(|&(k, _)| k)?;
    let period = periods[k];
    let rival = periods
        .iter()
        .zip(&scores)
        .filter(|&(&n, _)| n % period != 0)
        .map(|(_, &s)| s)
        .fold(0.0, f64::max);
    if rival > best - FIRING_MIN_MARGIN {
        return None;
    }
    let rings = source_index.iter().map(|&s| (s % period) as u16).collect();
    let mut steps = firing_steps_turn(points, index, period);
    let direction = rotation_of_step(median(&mut steps)?)?;
    // The first firing: the points whose index is below the first + period.
    let first = source_index[0];
    let seam_turn = circular_mean_turn(
        points
            .iter()
            .zip(source_index)
            .take_while(|&(_, &s)| s < first + period)
            .filter_map(|(p, _)| azimuth_turn(p)),
    );
    Some(FiringOrder {
        rings,
        period,
        score: best,
        sweep: Sweep {
            direction,
            seam_turn: seam_turn.rem_euclid(1.0),
        },
    })
}

/// Share of the index pairs `(i, i + n)` present in the sample whose
/// elevations agree (0 with fewer than `4 n` pairs).
fn period_score(index: &[u32], elevations: &[f64], n: u32) -> f64 {
    let (mut agree, mut pairs) = (0usize, 0usize);
    let mut j = 0;
    for (i, &s) in index.iter().enumerate() {
        let target = s + n;
        while j < index.len() && index[j] < target {
            j += 1;
        }
        if j == index.len() {
            break;
        }
        if index[j] == target {
            pairs += 1;
            agree += usize::from((elevations[i] - elevations[j]).abs() <= FIRING_TOLERANCE_RAD);
        }
    }
    if pairs < 4 * n as usize {
        0.0
    } else {
        agree as f64 / pairs as f64
    }
}

/// The azimuth step (turns) of each laser from one firing to the next, over
/// the sampled points: their median gives the sweep direction.
fn firing_steps_turn(points: &[[f32; 3]], index: &[u32], period: u32) -> Vec<f64> {
    let mut steps = Vec::new();
    let mut j = 0;
    for (i, &s) in index.iter().enumerate() {
        while j < index.len() && index[j] < s + period {
            j += 1;
        }
        if j < index.len()
            && index[j] == s + period
            && let (Some(a), Some(b)) = (azimuth_turn(&points[i]), azimuth_turn(&points[j]))
        {
            steps.push(wrap_turn(b - a));
        }
    }
    steps
}

/// A firing-order cloud whose empty returns were removed before us: its
/// points are numbered without gaps, yet do not fill whole firings.
pub(super) fn phase_lost(source_index: &[u32], period: usize) -> bool {
    let contiguous = source_index
        .last()
        .is_some_and(|&last| last as usize + 1 == source_index.len());
    contiguous && period > 0 && !source_index.len().is_multiple_of(period)
}

/// The sweep of a cloud whose points are in firing order (a driver's cloud,
/// dense or not): consecutive points a small step apart in azimuth, all one
/// way, over one turn in all. `None` for any other order.
pub fn sweep_in_order(points: &[[f32; 3]]) -> Option<Sweep> {
    let turns: Vec<f64> = points.iter().filter_map(azimuth_turn).collect();
    if turns.len() < MIN_SWEEP_POINTS {
        return None;
    }
    let mut steps: Vec<f64> = turns.windows(2).map(|w| wrap_turn(w[1] - w[0])).collect();
    let small = steps.iter().filter(|s| s.abs() < SMALL_STEP_TURN).count();
    let travelled: f64 = steps.iter().filter(|s| s.abs() < SMALL_STEP_TURN).sum();
    if (small as f64) < 0.9 * steps.len() as f64 || !(0.8..=1.2).contains(&travelled.abs()) {
        return None;
    }
    let step = median(&mut steps)?;
    let direction = if travelled > 0.0 && step >= 0.0 {
        Rotation::CounterClockwise
    } else if travelled < 0.0 && step <= 0.0 {
        Rotation::Clockwise
    } else {
        return None;
    };
    let seam_turn = circular_mean_turn(turns.iter().take(SEAM_POINTS).copied());
    Some(Sweep {
        direction,
        seam_turn: seam_turn.rem_euclid(1.0),
    })
}

/// Points a cloud needs before its order is read as a sweep.
const MIN_SWEEP_POINTS: usize = 1000;
/// A step between consecutive points of a sweep: under 3.6 degrees.
const SMALL_STEP_TURN: f64 = 0.01;
/// Points that place the seam (the first firings).
const SEAM_POINTS: usize = 64;
