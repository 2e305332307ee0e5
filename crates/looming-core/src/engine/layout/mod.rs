//! The engine's front end: recovers the ring (beam, image row) and the time
//! of every point for every cloud layout met in real logs, and names what it
//! used ([`ScanLayout`](crate::model::ScanLayout)). Pure: no I/O.
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
//!
//! Here [`complete`] and the sweep; 1 and 2 in `organized.rs`, 3 in
//! `laser_order.rs`, 4 (and a sweep without a period) in `firing_order.rs`,
//! 5 in `elevation_clusters.rs`.

mod elevation_clusters;
mod firing_order;
mod laser_order;
mod organized;

use std::f64::consts::TAU;

use rayon::prelude::*;

use crate::model::{RingSource, Rotation, Scan, TimeSource};

pub use elevation_clusters::elevation_rings;
pub use firing_order::{FiringOrder, firing_order, sweep_in_order};
pub use laser_order::{LaserOrder, laser_order};

use firing_order::phase_lost;
use organized::{check_ring_field, organized_rows, rows_agree};

/// Scan period assumed when the stamps give none, seconds.
pub const DEFAULT_PERIOD_S: f64 = 0.1;
/// Largest ring number accepted from a field (see the decoder).
pub(crate) const MAX_RING: u16 = 1023;
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
    let sweep = fill_rings(scan);
    scan.layout.ring_count = scan.ring.as_deref().map_or(0, distinct_rings);
    if scan.time_offset_s.is_none() {
        fill_times(scan, sweep, period_s);
    }
}

/// A sweep the point order follows, with each point's azimuth (turns,
/// [`azimuth_turn`]) where the recovery already took them: the times
/// then reuse them (one `atan2` per point, not two: on KITTI's lists the
/// azimuths were a third of the layout's time).
struct FoundSweep {
    sweep: Sweep,
    turns: Option<Vec<Option<f64>>>,
}

impl From<Sweep> for FoundSweep {
    fn from(sweep: Sweep) -> Self {
        Self { sweep, turns: None }
    }
}

/// Sets `scan.ring` and `scan.layout.rings` from the organized rows or the
/// ring field the cloud carries, else recovers them from its points; returns
/// the sweep when the point order follows one.
fn fill_rings(scan: &mut Scan) -> Option<FoundSweep> {
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
        (None, None) => return recover_rings(scan),
    }
    None
}

/// Rings of a cloud that carries none, from the first recovery that applies
/// (laser order, firing order, elevation clusters); returns the sweep when
/// the point order follows one.
fn recover_rings(scan: &mut Scan) -> Option<FoundSweep> {
    let mut sweep: Option<FoundSweep> = None;
    if let Some(order) = laser_order(&scan.points_m, RING_COUNTS) {
        scan.ring = Some(order.rings);
        scan.layout.rings = RingSource::LaserOrder {
            direction: order.sweep.direction,
        };
        sweep = Some(FoundSweep {
            sweep: order.sweep,
            turns: Some(order.turns),
        });
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
        sweep = Some(firing.sweep.into());
    } else if let Some(rings) = elevation_rings(&scan.points_m) {
        scan.ring = Some(rings);
        scan.layout.rings = RingSource::Elevation;
        // A driver's cloud with its empty returns removed: no period
        // in the order, but the order still follows the sweep.
        sweep = sweep_in_order(&scan.points_m).map(FoundSweep::from);
    } else {
        scan.layout.rings = RingSource::None;
    }
    sweep
}

/// Sets `scan.time_offset_s` from the azimuth along the sweep, or records
/// that the stamp is all there is.
fn fill_times(scan: &mut Scan, sweep: Option<FoundSweep>, period_s: f64) {
    match sweep {
        Some(FoundSweep { sweep, turns }) => {
            let time_s = |turn: Option<f64>| (sweep.fraction_of_turn(turn) * period_s) as f32;
            scan.time_offset_s = Some(match turns {
                Some(turns) => turns.into_par_iter().map(time_s).collect(),
                None => scan
                    .points_m
                    .par_iter()
                    .map(|p| time_s(azimuth_turn(p)))
                    .collect(),
            });
            scan.layout.times = TimeSource::Azimuth {
                direction: sweep.direction,
                seam_deg: sweep.seam_turn.rem_euclid(1.0) * 360.0,
            };
        }
        None => scan.layout.times = TimeSource::Stamp,
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

/// How a sweep turns and where it starts: the time of a point is the
/// fraction of a turn from the seam in the direction of rotation.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Sweep {
    pub direction: Rotation,
    /// Azimuth of the seam, turns (`atan2(y, x) / 2 pi`).
    pub seam_turn: f64,
}

impl Sweep {
    /// Fraction of the sweep, in [0, 1), at which a point whose azimuth is
    /// `turn` (turns, [`azimuth_turn`]) was fired; 0 for a point without
    /// one.
    fn fraction_of_turn(&self, turn: Option<f64>) -> f64 {
        match turn {
            Some(a) => (self.direction.sign() * (a - self.seam_turn)).rem_euclid(1.0),
            None => 0.0,
        }
    }
}

/// [`azimuth_turn`] of every point, on rayon's workers (the layout runs on
/// the pairing thread, between the engine's pairs: both cores are free).
fn azimuth_turns(points: &[[f32; 3]]) -> Vec<Option<f64>> {
    points.par_iter().map(azimuth_turn).collect()
}

/// Azimuth `atan2(y, x)` in turns, `None` for a point without one. The
/// engine's [`atan2`](crate::engine::atan::atan2) (within 1e-12 rad of
/// libm's, 2e-13 of a turn): libm's was 1 % of a KITTI run, a call per
/// point of every scan.
fn azimuth_turn(p: &[f32; 3]) -> Option<f64> {
    let [x, y, z] = *p;
    let has = x.is_finite() && y.is_finite() && z.is_finite() && (x != 0.0 || y != 0.0);
    has.then(|| crate::engine::atan::atan2(f64::from(y), f64::from(x)) / TAU)
}

/// Wraps a difference of turns into [-0.5, 0.5).
fn wrap_turn(d: f64) -> f64 {
    (d + 0.5).rem_euclid(1.0) - 0.5
}

fn elevation(p: &[f32; 3]) -> f64 {
    crate::engine::grid::elevation(p)
}

fn range(p: &[f32; 3]) -> f64 {
    let (x, y, z) = (f64::from(p[0]), f64::from(p[1]), f64::from(p[2]));
    (x * x + y * y + z * z).sqrt()
}

/// The sweep direction of a typical azimuth step (turns); `None` for no
/// step.
fn rotation_of_step(step: f64) -> Option<Rotation> {
    if step > 0.0 {
        Some(Rotation::CounterClockwise)
    } else if step < 0.0 {
        Some(Rotation::Clockwise)
    } else {
        None
    }
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

/// The upper median (the middle value of an odd count), by selection: the
/// layout takes it for every scan, on lists of a whole scan's steps.
fn median(values: &mut [f64]) -> Option<f64> {
    if values.is_empty() {
        return None;
    }
    let mid = values.len() / 2;
    Some(*values.select_nth_unstable_by(mid, f64::total_cmp).1)
}

#[cfg(test)]
mod tests;
