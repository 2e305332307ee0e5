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
use std::fmt;

use serde::Serialize;

use crate::messages::Scan;

use super::beams::BeamTable;

/// Which way a spinning LiDAR turns, seen from above.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Serialize)]
#[serde(rename_all = "snake_case")]
pub enum Rotation {
    /// Azimuth `atan2(y, x)` decreasing (most Velodyne / Ouster drivers).
    Clockwise,
    /// Azimuth increasing (KITTI's HDL-64E lists).
    CounterClockwise,
}

impl Rotation {
    /// +1 counter-clockwise, -1 clockwise.
    pub fn sign(self) -> f64 {
        match self {
            Rotation::Clockwise => -1.0,
            Rotation::CounterClockwise => 1.0,
        }
    }

    pub fn as_str(self) -> &'static str {
        match self {
            Rotation::Clockwise => "clockwise",
            Rotation::CounterClockwise => "counter-clockwise",
        }
    }
}

/// Where the rings of a scan came from.
#[derive(Debug, Clone, PartialEq, Serialize, Default)]
#[serde(tag = "kind", rename_all = "snake_case")]
pub enum RingSource {
    /// The row of an organized cloud; `ring_field` names a ring field that
    /// agreed with the rows.
    Organized {
        rows: u32,
        cols: u32,
        ring_field: Option<String>,
    },
    /// The cloud's ring field.
    Field { name: String },
    /// The azimuth along the point order wraps once per laser.
    LaserOrder { direction: Rotation },
    /// Consecutive points cycle through `period` lasers.
    FiringOrder { period: u32 },
    /// Elevation clusters, corrected for lasers off the rotation axis.
    Elevation,
    /// Nothing found: the range image infers rows from elevations.
    #[default]
    None,
}

impl RingSource {
    /// Short snake_case kind, for JSON records.
    pub fn kind(&self) -> &'static str {
        match self {
            RingSource::Organized { .. } => "organized",
            RingSource::Field { .. } => "field",
            RingSource::LaserOrder { .. } => "laser_order",
            RingSource::FiringOrder { .. } => "firing_order",
            RingSource::Elevation => "elevation",
            RingSource::None => "none",
        }
    }
}

/// Where the per-point times of a scan came from.
#[derive(Debug, Clone, PartialEq, Serialize, Default)]
#[serde(tag = "kind", rename_all = "snake_case")]
pub enum TimeSource {
    /// The cloud's time field.
    Field { name: String },
    /// From the azimuth: the sweep turns `direction`, starting at `seam_deg`
    /// (azimuth `atan2(y, x)`, degrees), over one scan period.
    Azimuth { direction: Rotation, seam_deg: f64 },
    /// No per-point time: every point at the header stamp.
    #[default]
    Stamp,
}

impl TimeSource {
    pub fn kind(&self) -> &'static str {
        match self {
            TimeSource::Field { .. } => "field",
            TimeSource::Azimuth { .. } => "azimuth",
            TimeSource::Stamp => "stamp",
        }
    }
}

/// A ring field the cloud carried but that is not used as rings.
#[derive(Debug, Clone, PartialEq, Serialize)]
pub struct DroppedRingField {
    pub name: String,
    pub reason: String,
}

/// How a scan's rings and times were obtained.
#[derive(Debug, Clone, PartialEq, Serialize, Default)]
pub struct ScanLayout {
    pub rings: RingSource,
    /// Distinct ring values holding points (0 without rings).
    pub ring_count: u32,
    pub times: TimeSource,
    /// A ring field present but not used: its values are not ring numbers.
    pub ring_field_dropped: Option<DroppedRingField>,
    /// Anything else worth knowing (e.g. organized rows that disagree with
    /// the ring field, which is then used).
    pub note: Option<String>,
}

impl ScanLayout {
    /// What the decoder read from the cloud's own fields.
    pub fn from_fields(ring_field: Option<&str>, time_field: Option<&str>) -> Self {
        Self {
            rings: ring_field.map_or(RingSource::None, |name| RingSource::Field {
                name: name.to_owned(),
            }),
            ring_count: 0,
            times: time_field.map_or(TimeSource::Stamp, |name| TimeSource::Field {
                name: name.to_owned(),
            }),
            ring_field_dropped: None,
            note: None,
        }
    }

    /// The rings in a few words, e.g. "laser order (64 rings)".
    pub fn rings_text(&self) -> String {
        let n = self.ring_count;
        match &self.rings {
            RingSource::Organized {
                rows,
                cols,
                ring_field,
            } => match ring_field {
                Some(name) => format!("organized {rows} x {cols} (ring field `{name}` agrees)"),
                None => format!("organized {rows} x {cols}"),
            },
            RingSource::Field { name } => format!("ring field `{name}` ({n} rings)"),
            RingSource::LaserOrder { direction } => {
                format!("laser order ({n} rings, {})", direction.as_str())
            }
            RingSource::FiringOrder { period } => format!("firing order ({period} rings)"),
            RingSource::Elevation => format!("elevation clusters ({n})"),
            RingSource::None => "no rings (elevation table)".to_owned(),
        }
    }

    /// The times in a few words, e.g. "per-point `t`".
    pub fn times_text(&self) -> String {
        match &self.times {
            TimeSource::Field { name } => format!("per-point `{name}`"),
            TimeSource::Azimuth {
                direction,
                seam_deg,
            } => format!(
                "from azimuth ({}, seam at {seam_deg:.0} deg{})",
                direction.as_str(),
                bearing_word(*seam_deg).map_or(String::new(), |w| format!(", {w}"))
            ),
            TimeSource::Stamp => "stamp only".to_owned(),
        }
    }
}

impl fmt::Display for ScanLayout {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        write!(f, "{}, times {}", self.rings_text(), self.times_text())?;
        if let Some(dropped) = &self.ring_field_dropped {
            write!(f, "; ring field `{}` not used: {}", dropped.name, dropped.reason)?;
        }
        if let Some(note) = &self.note {
            write!(f, "; {note}")?;
        }
        Ok(())
    }
}

/// "ahead", "left", "behind", "right" within 30 deg of those bearings.
fn bearing_word(azimuth_deg: f64) -> Option<&'static str> {
    let a = (azimuth_deg + 180.0).rem_euclid(360.0) - 180.0;
    let near = |centre: f64| ((a - centre + 180.0).rem_euclid(360.0) - 180.0).abs() <= 30.0;
    [(0.0, "ahead"), (90.0, "left"), (180.0, "behind"), (-90.0, "right")]
        .into_iter()
        .find(|&(c, _)| near(c))
        .map(|(_, w)| w)
}

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
                scan.ring = Some(firing.rings);
                scan.layout.rings = RingSource::FiringOrder {
                    period: firing.period,
                };
                sweep = Some(firing.sweep);
            } else if let Some(rings) = elevation_rings(&scan.points_m) {
                scan.ring = Some(rings);
                scan.layout.rings = RingSource::Elevation;
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
    let mut seen = vec![false; usize::from(MAX_RING.max(rings.iter().copied().max().unwrap_or(0))) + 1];
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
/// Lists that mostly start within this of the cut (turns, 1 deg) were cut
/// by azimuth, not by time.
const AZIMUTH_CUT_TOLERANCE_TURN: f64 = 1.0 / 360.0;

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
/// most lists start right at the cut (within 1 deg), which a time cut does
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
    let mut steps: Vec<f64> = valid.windows(2).map(|w| wrap_turn(w[1].1 - w[0].1)).collect();
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
    let cut = list_cut(&valid_turns, &elevations, sign, *counts.end())?;
    let mut starts = split_turns(&along(cut), *counts.end())?;
    // Lists cut by azimuth start right at the cut (within 1 deg), apart from
    // lasers that saw nothing there (sky); time-cut lists at their lasers'
    // own azimuth offsets.
    let at_cut = starts
        .iter()
        .skip(1)
        .filter(|&&k| (sign * (valid_turns[k] - cut)).rem_euclid(1.0) <= AZIMUTH_CUT_TOLERANCE_TURN)
        .count();
    let azimuth_cut = starts.len() > 1 && 2 * at_cut >= starts.len() - 1;
    if !azimuth_cut {
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
/// boundary does not move it).
fn list_cut(turns: &[f64], elevations: &[f64], sign: f64, max_rings: usize) -> Option<f64> {
    const WINDOW_TURN: f64 = 0.1;
    const GRID_TURN: f64 = 0.02 / 360.0;
    let first = *turns.first()?;
    let u: Vec<f64> = turns.iter().map(|&t| (sign * (t - first)).rem_euclid(1.0)).collect();
    let starts = split_turns(&u, max_rings)?;
    if starts.len() < 2 {
        return Some(first.rem_euclid(1.0));
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
    Some((first + sign * best.1).rem_euclid(1.0))
}

/// Lasers mounted at different azimuth offsets start their (time-ordered)
/// lists at different azimuths, so a common cut leaves a few points of each
/// list on a neighbour. Near each boundary (within 0.03 turn of the cut) the
/// true start shows as an azimuth step backwards (the next laser starts
/// behind where the last one ended) or a jump forwards with a jump in
/// elevation: the boundary moves there.
fn refine_boundaries(starts: &mut [usize], turns: &[f64], elevations: &[f64], sign: f64, cut: f64) {
    const WINDOW_TURN: f64 = 0.03;
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
        let (floor, ceil) = (starts[k - 1] + 1, starts.get(k + 1).map_or(turns.len(), |&n| n) - 1);
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
            } else if step > 5.0 * typical {
                jump
            } else {
                continue;
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

/// Returns closer than this are left out of the fits (too much parallax,
/// often the vehicle itself), metres.
const NEAR_RANGE_M: f64 = 3.0;
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
/// Ring = beam index, lowest first. `None` when no beam structure shows or
/// the beam count is outside [`RING_COUNTS`].
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
