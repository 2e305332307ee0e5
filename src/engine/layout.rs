//! The engine's front end: recovers the ring (beam, image row) and the time
//! of every point for every cloud layout met in real logs, and names what it
//! used ([`ScanLayout`]). Pure: no I/O.
//!
//! Rings, first that applies:
//! 1. organized clouds (`height > 1`): the row of the point;
//! 2. a ring field (`ring`, `channel`, `laser_id`, `line`, `laser_number`);
//! 3. laser-by-laser order: the azimuth along the point order wraps once per
//!    laser (KITTI `.bin`);
//! 4. firing order: elevations repeat with the laser count in the source index;
//! 5. elevation clusters corrected for lasers mounted off the rotation axis;
//! 6. none (the range image falls back to its own elevation table).
//!
//! Times, when the cloud has no time field: from the azimuth when the point
//! order is the firing order (laser and firing order), else the stamp only.

use std::f64::consts::{PI, TAU};

use crate::model::{DroppedRingField, RingSource, Rotation, Scan, TimeSource};

use super::beams::BeamTable;

/// Scan period assumed when the stamps give none, seconds.
pub const DEFAULT_PERIOD_S: f64 = 0.1;
/// Largest ring number accepted from a field (see the decoder).
pub const MAX_RING: u16 = 1023;
/// Ring counts a spinning LiDAR can have, for the recovered layouts.
pub const RING_COUNTS: std::ops::RangeInclusive<usize> = 8..=256;

/// Fills `scan.ring` and `scan.time_offset_s` when missing and records how in
/// `scan.layout` (see the module documentation). `period_s` is the scan
/// period (the stamp difference of consecutive scans); a non-positive or
/// non-finite value means [`DEFAULT_PERIOD_S`].
///
/// Times derived from the azimuth run from 0 at the sweep's seam to one
/// period at its end: the stamp is taken as the sweep start. Looming uses
/// differences between consecutive scans, which do not depend on that choice.
pub fn complete(scan: &mut Scan, period_s: f64) {
    let period_s = if period_s.is_finite() && period_s > 0.0 {
        period_s
    } else {
        DEFAULT_PERIOD_S
    };
    check_ring_field(scan);
    let mut sweep: Option<Sweep> = None;
    let field_name = match &scan.layout.rings {
        RingSource::Field { name } => name.clone(),
        _ => "ring".to_owned(),
    };
    let organized = organized_rows(scan);
    match (organized, scan.ring.take()) {
        (Some((rows, cols, org)), Some(field)) => {
            if rows_agree(&org, &field) {
                scan.ring = Some(org);
                scan.layout.rings = RingSource::Organized {
                    rows,
                    cols,
                    ring_field: Some(field_name),
                };
            } else {
                scan.ring = Some(field);
                scan.layout.rings = RingSource::Field { name: field_name };
                scan.layout.note = Some(format!(
                    "the organized rows ({rows} x {cols}) disagree with the ring field: field used"
                ));
            }
        }
        (Some((rows, cols, org)), None) => {
            scan.ring = Some(org);
            scan.layout.rings = RingSource::Organized {
                rows,
                cols,
                ring_field: None,
            };
        }
        (None, Some(field)) => {
            scan.ring = Some(field);
            scan.layout.rings = RingSource::Field { name: field_name };
        }
        (None, None) => {
            if let Some(order) = laser_order(&scan.points_m, RING_COUNTS) {
                scan.ring = Some(order.rings);
                scan.layout.rings = RingSource::LaserOrder {
                    direction: order.sweep.direction,
                };
                sweep = Some(order.sweep);
            } else if let Some(firing) = firing_order(&scan.points_m, &scan.source_index) {
                // Without its empty returns (the driver removed them) a
                // cloud loses the period's phase at every dropout: its rings
                // then come from the elevations, its times still from the
                // order.
                let by_elevation = phase_lost(&scan.source_index, firing.period as usize)
                    .then(|| elevation_rings(&scan.points_m))
                    .flatten();
                scan.layout.rings = match by_elevation {
                    Some(_) => RingSource::Elevation,
                    None => RingSource::FiringOrder {
                        period: firing.period,
                    },
                };
                scan.ring = Some(by_elevation.unwrap_or(firing.rings));
                sweep = Some(firing.sweep);
            } else if let Some(rings) = elevation_rings(&scan.points_m) {
                scan.ring = Some(rings);
                scan.layout.rings = RingSource::Elevation;
                // A driver's cloud with its empty returns removed: no period
                // in the order, but the order still follows the sweep.
                sweep = sweep_in_order(&scan.points_m);
            } else {
                scan.layout.rings = RingSource::None;
            }
        }
    }
    scan.layout.ring_count = scan.ring.as_deref().map_or(0, distinct_rings);
    if scan.time_offset_s.is_none() {
        match sweep {
            Some(sweep) => {
                scan.time_offset_s = Some(
                    scan.points_m
                        .iter()
                        .map(|p| (sweep.fraction(p) * period_s) as f32)
                        .collect(),
                );
                scan.layout.times = TimeSource::Azimuth {
                    direction: sweep.direction,
                    seam_deg: sweep.seam_turn.rem_euclid(1.0) * 360.0,
                };
            }
            None => scan.layout.times = TimeSource::Stamp,
        }
    }
}

/// Drops a ring field whose values cannot be rings (the decoder already
/// does; scans built elsewhere are checked here).
fn check_ring_field(scan: &mut Scan) {
    let Some(rings) = &scan.ring else {
        return;
    };
    let reason = if rings.len() != scan.points_m.len() {
        Some(format!(
            "{} values for {} points",
            rings.len(),
            scan.points_m.len()
        ))
    } else {
        rings
            .iter()
            .find(|&&r| r > MAX_RING)
            .map(|r| format!("value {r} is not a ring number (0..={MAX_RING})"))
    };
    if let Some(reason) = reason {
        let name = match &scan.layout.rings {
            RingSource::Field { name } => name.clone(),
            _ => "ring".to_owned(),
        };
        scan.ring = None;
        scan.layout.rings = RingSource::None;
        scan.layout.ring_field_dropped = Some(DroppedRingField { name, reason });
    }
}

/// Number of distinct ring values.
pub fn distinct_rings(rings: &[u16]) -> u32 {
    let mut seen =
        vec![false; usize::from(MAX_RING.max(rings.iter().copied().max().unwrap_or(0))) + 1];
    let mut count = 0;
    for &r in rings {
        if !std::mem::replace(&mut seen[usize::from(r)], true) {
            count += 1;
        }
    }
    count
}

/// Rows of an organized cloud: `(rows, cols, row of each point)`; `None`
/// when the scan is not organized or has more rows than ring numbers.
fn organized_rows(scan: &Scan) -> Option<(u32, u32, Vec<u16>)> {
    let (rows, cols) = scan.organized?;
    if rows < 2 || cols == 0 || rows > u32::from(MAX_RING) + 1 {
        return None;
    }
    let rings = scan
        .source_index
        .iter()
        .map(|&i| (i / cols).min(rows - 1) as u16)
        .collect::<Vec<u16>>();
    (rings.len() == scan.points_m.len()).then_some((rows, cols, rings))
}

/// The organized rows and a ring field agree when each row holds one ring
/// value and each ring value one row (for 99 % of the points).
fn rows_agree(rows: &[u16], field: &[u16]) -> bool {
    if rows.len() != field.len() {
        return false;
    }
    let mut pairs: std::collections::HashMap<(u16, u16), usize> = std::collections::HashMap::new();
    for (&r, &f) in rows.iter().zip(field) {
        *pairs.entry((r, f)).or_default() += 1;
    }
    // Each row's most common ring value, and each ring value's row.
    let mut best_ring: std::collections::HashMap<u16, (u16, usize)> = Default::default();
    for (&(r, f), &n) in &pairs {
        let entry = best_ring.entry(r).or_insert((f, 0));
        if n > entry.1 || (n == entry.1 && f < entry.0) {
            *entry = (f, n);
        }
    }
    let mut rings_used = std::collections::HashSet::new();
    if !best_ring.values().all(|(f, _)| rings_used.insert(*f)) {
        return false;
    }
    let agreeing: usize = best_ring.values().map(|(_, n)| n).sum();
    agreeing as f64 >= 0.99 * rows.len() as f64
}

/// How a sweep turns and where it starts: the time of a point is the
/// fraction of a turn from the seam in the direction of rotation.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Sweep {
    pub direction: Rotation,
    /// Azimuth of the seam, turns (`atan2(y, x) / 2 pi`).
    pub seam_turn: f64,
}

impl Sweep {
    /// Fraction of the sweep, in [0, 1), at which the point was fired; 0 for
    /// a point without an azimuth.
    pub fn fraction(&self, p: &[f32; 3]) -> f64 {
        match azimuth_turn(p) {
            Some(a) => (self.direction.sign() * (a - self.seam_turn)).rem_euclid(1.0),
            None => 0.0,
        }
    }
}

/// Azimuth `atan2(y, x)` in turns, `None` for a point without one.
fn azimuth_turn(p: &[f32; 3]) -> Option<f64> {
    let [x, y, z] = *p;
    let has = x.is_finite() && y.is_finite() && z.is_finite() && (x != 0.0 || y != 0.0);
    has.then(|| f64::from(y).atan2(f64::from(x)) / TAU)
}

/// Wraps a difference of turns into [-0.5, 0.5).
fn wrap_turn(d: f64) -> f64 {
    (d + 0.5).rem_euclid(1.0) - 0.5
}

fn elevation(p: &[f32; 3]) -> f64 {
    let (x, y, z) = (f64::from(p[0]), f64::from(p[1]), f64::from(p[2]));
    z.atan2(x.hypot(y))
}

fn range(p: &[f32; 3]) -> f64 {
    let (x, y, z) = (f64::from(p[0]), f64::from(p[1]), f64::from(p[2]));
    (x * x + y * y + z * z).sqrt()
}

/// Circular mean of angles in turns (0 for an empty list).
fn circular_mean_turn(turns: impl Iterator<Item = f64>) -> f64 {
    let (mut s, mut c) = (0.0, 0.0);
    for t in turns {
        s += (t * TAU).sin();
        c += (t * TAU).cos();
    }
    s.atan2(c) / TAU
}

fn median(values: &mut [f64]) -> Option<f64> {
    if values.is_empty() {
        return None;
    }
    values.sort_by(f64::total_cmp);
    Some(values[values.len() / 2])
}

/// Rings recovered from the laser-by-laser order.
#[derive(Debug, Clone, PartialEq)]
pub struct LaserOrder {
    /// Ring of every point, in list order (first laser 0).
    pub rings: Vec<u16>,
    pub ring_count: usize,
    pub sweep: Sweep,
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
/// one laser to the next ([`list_cut`]).
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
    let turns: Vec<Option<f64>> = points.iter().map(azimuth_turn).collect();
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
    let median_step = median(&mut steps)?;
    let direction = if median_step > 0.0 {
        Rotation::CounterClockwise
    } else if median_step < 0.0 {
        Rotation::Clockwise
    } else {
        return None;
    };
    let sign = direction.sign();
    let elevations: Vec<f64> = valid.iter().map(|&(i, _)| elevation(&points[i])).collect();
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
    // Plausibility: monotone, most of a turn each, no sliver.
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
            return None;
        }
    }
    if (forward_steps as f64) < MIN_MONOTONE_SHARE * all_steps as f64 {
        return None;
    }
    let mean = valid.len() / ring_count;
    let fewest = (mean / MIN_RING_SHARE_DIVISOR).max(1);
    if sizes.iter().any(|&n| n < fewest) {
        return None;
    }
    // Rings of every point; points without an azimuth keep the current ring.
    let mut rings = vec![0u16; points.len()];
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
    })
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
    for g in -grid..=grid {
        let c = g as f64 * GRID_TURN;
        changes.clear();
        for steps in &boundaries {
            // The first step whose end lies at or after c.
            let k = steps.partition_point(|&(offset, _)| offset < c);
            if k > 0 && k < steps.len() {
                changes.push(steps[k].1);
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
    // Share of pairs (i, i + n) present in the sample whose elevations agree.
    let score = |n: u32| -> f64 {
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
    };
    let periods: Vec<u32> = (*RING_COUNTS.start() as u32..=*RING_COUNTS.end() as u32).collect();
    let scores: Vec<f64> = periods.iter().map(|&n| score(n)).collect();
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
    // Direction: azimuth step of each laser from one firing to the next.
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
    let step = median(&mut steps)?;
    let direction = if step > 0.0 {
        Rotation::CounterClockwise
    } else if step < 0.0 {
        Rotation::Clockwise
    } else {
        return None;
    };
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

/// A firing-order cloud whose empty returns were removed before us: its
/// points are numbered without gaps, yet do not fill whole firings.
fn phase_lost(source_index: &[u32], period: usize) -> bool {
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
    let bin = 0.02 * PI / 180.0;
    // Corrected elevations lie in [-pi/2 - 0.1, pi/2 + 0.1] (|c / range| <= 0.1 rad).
    let mut counts = vec![0u32; ((PI + 0.4) / bin) as usize];
    let mut sharpness = |c: f64| -> f64 {
        counts.iter_mut().for_each(|n| *n = 0);
        for &(e, inv) in &fit {
            let b = ((e - c * inv + PI / 2.0 + 0.2) / bin).max(0.0) as usize;
            if let Some(n) = counts.get_mut(b) {
                *n += 1;
            }
        }
        counts.iter().map(|&n| f64::from(n) * f64::from(n)).sum()
    };
    let (lo, hi, step) = OFFSET_SEARCH_M;
    let steps = ((hi - lo) / step).round() as usize;
    let c = (0..=steps)
        .map(|k| lo + step * k as f64)
        .map(|c| (c, sharpness(c)))
        .max_by(|a, b| a.1.total_cmp(&b.1))
        .map_or(0.0, |(c, _)| c);
    // 2. The beams.
    let corrected: Vec<f32> = fit.iter().map(|&(e, inv)| (e - c * inv) as f32).collect();
    let table = BeamTable::infer(&corrected, *RING_COUNTS.end())?;
    if !RING_COUNTS.contains(&table.len()) {
        return None;
    }
    let mut beams: Vec<(f64, f64)> = table.elevations_rad.iter().map(|&b| (b, c)).collect();
    let nearest = |beams: &[(f64, f64)], e: f64, inv: f64| -> usize {
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
    };
    // 3. Per-beam lines, refitted twice.
    for _ in 0..2 {
        let mut sums = vec![[0.0f64; 5]; beams.len()]; // n, x, y, xx, xy
        for &(e, inv) in &fit {
            let k = nearest(&beams, e, inv);
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
    // Beams are lines the points hug: points scattered between them (no
    // beam structure, e.g. random points) sit a quarter spacing off.
    let mut residuals: Vec<f64> = fit
        .iter()
        .map(|&(e, inv)| {
            let k = nearest(&beams, e, inv);
            (e - beams[k].0 - beams[k].1 * inv).abs()
        })
        .collect();
    let mut spacings: Vec<f64> = beams.windows(2).map(|w| w[1].0 - w[0].0).collect();
    let (Some(residual), Some(spacing)) = (median(&mut residuals), median(&mut spacings)) else {
        return None;
    };
    if residual > MAX_RESIDUAL_OF_SPACING * spacing {
        return None;
    }
    Some(
        points
            .iter()
            .map(|p| {
                if !p.iter().all(|v| v.is_finite()) {
                    return 0;
                }
                nearest(&beams, elevation(p), 1.0 / range(p).max(1e-3)) as u16
            })
            .collect(),
    )
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::model::ScanLayout;
    use crate::test_rng::SplitMix64;

    /// An HDL-64E-like laser: elevation, azimuth offset, height above the
    /// frame origin (m).
    #[derive(Clone, Copy)]
    struct Laser {
        elevation_rad: f64,
        azimuth_offset_rad: f64,
        height_m: f64,
    }

    /// 64 irregular lasers in two blocks (upper ~0.33 deg apart, lower ~0.5
    /// deg), azimuth offsets up to +-4 deg, 0.12-0.21 m off the origin;
    /// listed in an interleaved order (as sensors number them).
    fn hdl64_like(rng: &mut SplitMix64) -> Vec<Laser> {
        let mut elevations: Vec<f64> = (0..64)
            .map(|k| {
                if k < 32 {
                    2.0 - 0.33 * k as f64 + 0.04 * rng.signed()
                } else {
                    -8.8 - 0.5 * (k - 32) as f64 + 0.06 * rng.signed()
                }
            })
            .collect();
        // Interleave: lasers are not listed by elevation.
        let mut order: Vec<usize> = (0..64).collect();
        order.sort_by_key(|&k| (k % 2, k));
        elevations = order.iter().map(|&k| elevations[k]).collect();
        elevations
            .into_iter()
            .enumerate()
            .map(|(k, e)| Laser {
                elevation_rad: e.to_radians(),
                azimuth_offset_rad: (4.0 * rng.signed()).to_radians(),
                height_m: if k % 2 == 0 { 0.21 } else { 0.12 } + 0.01 * rng.signed(),
            })
            .collect()
    }

    /// A street: a flat road 1.73 m below, walls 6-30 m away depending on
    /// the azimuth, a little range noise.
    fn range_at(azimuth_rad: f64, elevation_rad: f64, rng: &mut SplitMix64) -> f64 {
        let wall = 6.0 + 24.0 * (0.5 + 0.5 * (3.0 * azimuth_rad).sin());
        let horizontal = wall / elevation_rad.cos();
        let road = if elevation_rad < 0.0 {
            1.73 / (-elevation_rad).sin()
        } else {
            f64::INFINITY
        };
        horizontal.min(road).min(80.0) + 0.01 * rng.signed()
    }

    fn point(laser: &Laser, azimuth_rad: f64, rng: &mut SplitMix64) -> [f32; 3] {
        let r = range_at(azimuth_rad, laser.elevation_rad, rng);
        let h = r * laser.elevation_rad.cos();
        [
            (h * azimuth_rad.cos()) as f32,
            (h * azimuth_rad.sin()) as f32,
            (r * laser.elevation_rad.sin() + laser.height_m) as f32,
        ]
    }

    fn scan_of(points: Vec<[f32; 3]>, source_index: Vec<u32>) -> Scan {
        Scan {
            stamp_ns: 0,
            frame_id: "lidar".into(),
            sensor_pose: nalgebra::Isometry3::identity(),
            input_point_count: source_index.last().map_or(0, |&i| i + 1),
            points_m: points,
            intensity: None,
            ring: None,
            time_offset_s: None,
            source_index,
            skipped_invalid_points: 0,
            organized: None,
            layout: ScanLayout::default(),
        }
    }

    /// Share of points whose ring, mapped to the true laser most of its
    /// points have, is their true laser; and the number of rings.
    fn agreement(rings: &[u16], truth: &[u16]) -> f64 {
        let mut table = std::collections::HashMap::<(u16, u16), usize>::new();
        for (&r, &t) in rings.iter().zip(truth) {
            *table.entry((r, t)).or_default() += 1;
        }
        let mut best = std::collections::HashMap::<u16, usize>::new();
        for (&(r, _), &n) in &table {
            let b = best.entry(r).or_default();
            *b = (*b).max(n);
        }
        best.values().sum::<usize>() as f64 / truth.len() as f64
    }

    /// A laser-by-laser list, each laser's points in firing order from the
    /// seam (plus its azimuth offset) over one turn `direction`.
    fn laser_order_scan(direction: Rotation, seam_rad: f64, per_laser: usize) -> (Scan, Vec<u16>) {
        let mut rng = SplitMix64(7);
        let lasers = hdl64_like(&mut rng);
        let (mut points, mut truth) = (Vec::new(), Vec::new());
        for (k, laser) in lasers.iter().enumerate() {
            for i in 0..per_laser {
                let fraction = (i as f64 + 0.5) / per_laser as f64;
                let azimuth =
                    seam_rad + laser.azimuth_offset_rad + direction.sign() * TAU * fraction;
                // Some returns missing (sky, absorbing surfaces).
                if rng.uniform(0.0, 1.0) < 0.05 {
                    continue;
                }
                points.push(point(laser, azimuth, &mut rng));
                truth.push(k as u16);
            }
        }
        let n = points.len() as u32;
        (scan_of(points, (0..n).collect()), truth)
    }

    #[test]
    fn laser_order_both_directions() {
        for (direction, seam_deg) in [
            (Rotation::CounterClockwise, 180.0),
            (Rotation::Clockwise, 40.0),
        ] {
            let (mut scan, truth) = laser_order_scan(direction, f64::to_radians(seam_deg), 900);
            complete(&mut scan, 0.1);
            assert_eq!(scan.layout.rings, RingSource::LaserOrder { direction });
            assert_eq!(scan.layout.ring_count, 64);
            let rings = scan.ring.as_deref().expect("rings");
            let same = rings.iter().zip(&truth).filter(|(a, b)| a == b).count();
            assert!(
                same as f64 > 0.995 * truth.len() as f64,
                "{direction:?}: {same} of {} on their laser",
                truth.len()
            );
            let TimeSource::Azimuth {
                direction: d,
                seam_deg: s,
            } = scan.layout.times
            else {
                panic!("{:?}", scan.layout.times);
            };
            assert_eq!(d, direction);
            assert!(
                wrap_turn((s - seam_deg) / 360.0).abs() < 3.0 / 360.0,
                "seam {s}"
            );
            let times = scan.time_offset_s.as_deref().expect("times");
            assert!(times.iter().all(|&t| (0.0..0.1).contains(&t)));
            // Along a laser the time rises but for the few points fired
            // before the common seam.
            let rises = times
                .windows(2)
                .zip(rings.windows(2))
                .filter(|(t, r)| r[0] == r[1] && t[1] >= t[0])
                .count();
            assert!(rises as f64 > 0.97 * times.len() as f64, "{rises}");
        }
    }

    #[test]
    fn azimuth_cut_lists_have_their_seam_half_a_turn_away() {
        // KITTI: every list sorted by azimuth counter-clockwise from
        // straight ahead (offsets already applied).
        let mut rng = SplitMix64(3);
        let lasers = hdl64_like(&mut rng);
        let mut points = Vec::new();
        for laser in &lasers {
            for i in 0..1000 {
                let azimuth = TAU * (i as f64 + 0.5) / 1000.0;
                points.push(point(laser, azimuth, &mut rng));
            }
        }
        let n = points.len() as u32;
        let mut scan = scan_of(points, (0..n).collect());
        complete(&mut scan, 0.1);
        assert_eq!(scan.layout.ring_count, 64);
        let TimeSource::Azimuth {
            direction,
            seam_deg,
        } = scan.layout.times
        else {
            panic!("{:?}", scan.layout.times);
        };
        assert_eq!(direction, Rotation::CounterClockwise);
        assert!((seam_deg - 180.0).abs() < 1.0, "{seam_deg}");
        assert!(
            scan.layout.to_string().contains("behind"),
            "{}",
            scan.layout
        );
        let expected: Vec<u16> = (0..64).flat_map(|k| [k; 1000]).collect();
        assert_eq!(scan.ring.as_deref(), Some(expected.as_slice()));
    }

    /// Driver order: columns of one firing of every laser, `dropped` points
    /// (no return) removed but counted in the source index.
    fn firing_order_scan(direction: Rotation, columns: usize, dropped: f64) -> (Scan, Vec<u16>) {
        let mut rng = SplitMix64(11);
        let lasers = hdl64_like(&mut rng);
        let (mut points, mut index, mut truth) = (Vec::new(), Vec::new(), Vec::new());
        for c in 0..columns {
            let azimuth = 0.3 + direction.sign() * TAU * c as f64 / columns as f64;
            for (k, laser) in lasers.iter().enumerate() {
                if rng.uniform(0.0, 1.0) < dropped {
                    continue;
                }
                points.push(point(laser, azimuth + laser.azimuth_offset_rad, &mut rng));
                index.push((c * lasers.len() + k) as u32);
                truth.push(k as u16);
            }
        }
        (scan_of(points, index), truth)
    }

    #[test]
    fn firing_order_with_dropouts() {
        for direction in [Rotation::Clockwise, Rotation::CounterClockwise] {
            let (mut scan, truth) = firing_order_scan(direction, 1000, 0.15);
            complete(&mut scan, 0.1);
            assert_eq!(scan.layout.rings, RingSource::FiringOrder { period: 64 });
            assert_eq!(scan.ring.as_deref(), Some(truth.as_slice()));
            let TimeSource::Azimuth {
                direction: d,
                seam_deg,
            } = scan.layout.times
            else {
                panic!("{:?}", scan.layout.times);
            };
            assert_eq!(d, direction);
            assert!((seam_deg - 0.3f64.to_degrees()).abs() < 5.0, "{seam_deg}");
        }
    }

    #[test]
    fn off_axis_lasers_cluster_by_laser() {
        // No usable order: the points shuffled.
        let (scan, truth) = laser_order_scan(Rotation::Clockwise, 0.0, 1200);
        let mut rng = SplitMix64(5);
        let mut order: Vec<usize> = (0..truth.len()).collect();
        for i in (1..order.len()).rev() {
            order.swap(i, (rng.next_u64() % (i as u64 + 1)) as usize);
        }
        let points: Vec<[f32; 3]> = order.iter().map(|&i| scan.points_m[i]).collect();
        let truth: Vec<u16> = order.iter().map(|&i| truth[i]).collect();
        let n = points.len() as u32;
        let mut scan = scan_of(points, (0..n).collect());
        complete(&mut scan, 0.1);
        assert_eq!(scan.layout.rings, RingSource::Elevation);
        assert_eq!(scan.layout.times, TimeSource::Stamp);
        assert!(scan.time_offset_s.is_none());
        let rings = scan.ring.as_deref().expect("rings");
        let share = agreement(rings, &truth);
        // Measured 0.93 on this scene: short of one laser per row (the
        // nearest road returns still cross beams), but well above the
        // uncorrected table below.
        assert!(share > 0.9, "{share}");
        assert!(
            (56..=72).contains(&scan.layout.ring_count),
            "{}",
            scan.layout.ring_count
        );
        // Without the correction (elevation alone) the near road smears
        // across beams: the correction must do better.
        let elevations: Vec<f32> = scan.points_m.iter().map(|p| elevation(p) as f32).collect();
        let table = BeamTable::infer(&elevations, 256).expect("table");
        let plain: Vec<u16> = elevations
            .iter()
            .map(|&e| table.row_of(f64::from(e)) as u16)
            .collect();
        assert!(
            share > agreement(&plain, &truth),
            "{share} vs {}",
            agreement(&plain, &truth)
        );
    }

    #[test]
    fn organized_rows_and_ring_fields() {
        let (rows, cols) = (8u32, 100u32);
        let mut points = Vec::new();
        let mut index = Vec::new();
        for r in 0..rows {
            for c in 0..cols {
                if (r * cols + c) % 7 == 3 {
                    continue; // no return
                }
                let az = TAU * f64::from(c) / f64::from(cols);
                let el = (10.0 - 3.0 * f64::from(r)).to_radians();
                points.push([
                    (10.0 * el.cos() * az.cos()) as f32,
                    (10.0 * el.cos() * az.sin()) as f32,
                    (10.0 * el.sin()) as f32,
                ]);
                index.push(r * cols + c);
            }
        }
        let rows_of: Vec<u16> = index.iter().map(|&i| (i / cols) as u16).collect();
        let organized = |ring: Option<Vec<u16>>| {
            let mut scan = scan_of(points.clone(), index.clone());
            scan.organized = Some((rows, cols));
            scan.layout = ScanLayout::from_fields(ring.as_ref().map(|_| "channel"), Some("t"));
            scan.ring = ring;
            complete(&mut scan, 0.1);
            scan
        };
        let plain = organized(None);
        assert_eq!(
            plain.layout.rings,
            RingSource::Organized {
                rows,
                cols,
                ring_field: None
            }
        );
        assert_eq!(plain.ring.as_deref(), Some(rows_of.as_slice()));
        assert_eq!(plain.layout.ring_count, 8);
        assert_eq!(
            plain.layout.times,
            TimeSource::Stamp,
            "no time field, not in firing order"
        );
        assert!(
            plain.layout.to_string().starts_with("organized 8 x 100"),
            "{}",
            plain.layout
        );
        // A field numbering the rows the other way agrees.
        let agreeing = organized(Some(rows_of.iter().map(|&r| 7 - r).collect()));
        assert_eq!(
            agreeing.layout.rings,
            RingSource::Organized {
                rows,
                cols,
                ring_field: Some("channel".into())
            }
        );
        // A field that does not follow the rows is used, and said.
        let other: Vec<u16> = (0..points.len()).map(|i| (i % 5) as u16).collect();
        let disagreeing = organized(Some(other.clone()));
        assert_eq!(
            disagreeing.layout.rings,
            RingSource::Field {
                name: "channel".into()
            }
        );
        assert_eq!(disagreeing.ring, Some(other));
        assert!(disagreeing.layout.note.is_some());
    }

    #[test]
    fn ring_field_is_kept_with_its_name() {
        let (mut scan, truth) = firing_order_scan(Rotation::Clockwise, 200, 0.0);
        scan.ring = Some(truth.clone());
        scan.layout = ScanLayout::from_fields(Some("laser_id"), None);
        complete(&mut scan, 0.1);
        assert_eq!(
            scan.layout.rings,
            RingSource::Field {
                name: "laser_id".into()
            }
        );
        assert_eq!(scan.ring, Some(truth));
        assert_eq!(scan.layout.ring_count, 64);
        // The field says nothing of the order: times stay the stamp's.
        assert_eq!(scan.layout.times, TimeSource::Stamp);
        assert_eq!(scan.layout.rings_text(), "ring field `laser_id` (64 rings)");
    }

    #[test]
    fn huge_ring_values_drop_the_field() {
        let (mut scan, _) = firing_order_scan(Rotation::Clockwise, 300, 0.1);
        let mut rings: Vec<u16> = vec![3; scan.len()];
        rings[17] = 60_000;
        scan.ring = Some(rings);
        scan.layout = ScanLayout::from_fields(Some("ring"), None);
        complete(&mut scan, 0.1);
        let dropped = scan.layout.ring_field_dropped.as_ref().expect("dropped");
        assert_eq!(dropped.name, "ring");
        // It falls through to what the order shows.
        assert_eq!(scan.layout.rings, RingSource::FiringOrder { period: 64 });
        // A ring list of the wrong length is dropped too.
        let (mut short, _) = firing_order_scan(Rotation::Clockwise, 300, 0.1);
        short.ring = Some(vec![1, 2]);
        complete(&mut short, 0.1);
        assert!(short.layout.ring_field_dropped.is_some());
    }

    #[test]
    fn garbage_gives_no_rings_and_no_panic() {
        let mut rng = SplitMix64(99);
        for n in [0usize, 1, 5, 300, 20_000] {
            let points: Vec<[f32; 3]> = (0..n)
                .map(|_| {
                    [
                        rng.uniform(-50.0, 50.0) as f32,
                        rng.uniform(-50.0, 50.0) as f32,
                        rng.uniform(-5.0, 5.0) as f32,
                    ]
                })
                .collect();
            let mut scan = scan_of(points, (0..n as u32).collect());
            complete(&mut scan, f64::NAN);
            assert_eq!(scan.layout.rings, RingSource::None, "{n} points");
            assert!(scan.ring.is_none());
            assert_eq!(scan.layout.times, TimeSource::Stamp);
        }
        // Non-finite and degenerate points.
        let mut odd = scan_of(
            vec![
                [f32::NAN, 0.0, 0.0],
                [0.0, 0.0, 1.0],
                [f32::INFINITY, 1.0, 1.0],
                [0.0; 3],
            ],
            vec![0, 1, 2, 3],
        );
        complete(&mut odd, 0.1);
        assert_eq!(odd.layout.rings, RingSource::None);
    }

    #[test]
    fn descriptions() {
        let layout = ScanLayout {
            rings: RingSource::LaserOrder {
                direction: Rotation::CounterClockwise,
            },
            ring_count: 64,
            times: TimeSource::Azimuth {
                direction: Rotation::CounterClockwise,
                seam_deg: 180.0,
            },
            ring_field_dropped: None,
            note: None,
        };
        assert_eq!(
            layout.to_string(),
            "laser order (64 rings, counter-clockwise), times from azimuth (counter-clockwise, seam at 180 deg, behind)"
        );
        assert_eq!(crate::model::layout::bearing_word(-179.0), Some("behind"));
        assert_eq!(crate::model::layout::bearing_word(45.0), None);
        assert_eq!(distinct_rings(&[0, 5, 5, 1023]), 3);
    }
}
