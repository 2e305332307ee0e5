//! One pair's hot clusters: connected cells of the range image whose fused
//! looming is above the event threshold, on surfaces facing the sensor, in the
//! ego vehicle's corridor.

use nalgebra::Vector3;

use crate::engine::{ImageGeometry, NO_POINT, PairLooming, mask};
use crate::model::Scan;
use crate::objects::{NO_OBJECT, Object, ObjectCells, PairObjects};

use super::EventConfig;
use super::corridor::Corridor;

/// A connected set of hot cells in one pair.
#[derive(Debug, Clone)]
pub struct Cluster {
    pub cells: usize,
    pub rows: (usize, usize),
    pub cols: ColSpan,
    /// Median looming of the cluster's cells, 1/s: what neither noise nor
    /// edge spikes set.
    pub looming_per_s: f64,
    /// Mean point of the cluster, LiDAR frame, metres.
    pub centroid_m: [f64; 3],
    /// Median range of its cells, metres.
    pub range_m: f64,
    /// 10th percentile of its cells' ranges, metres: the near side, which
    /// closes at the closing speed.
    pub near_range_m: f64,
    /// Smallest distance from the ego path of the object it lies on (all of
    /// the object's returns, hot or not), or of its own cells when on no
    /// object, metres.
    pub lateral_offset_m: f64,
    /// The tracked object most of its cells belong to.
    pub object_id: Option<u32>,
    /// Cells flagged moving by the disagreement.
    pub moving_cells: usize,
}

impl Cluster {
    /// Azimuth (left positive) and elevation of the centroid, degrees.
    pub fn bearing_deg(&self) -> (f64, f64) {
        let [x, y, z] = self.centroid_m;
        (y.atan2(x).to_degrees(), z.atan2(x.hypot(y)).to_degrees())
    }
}

/// A run of columns on the circle of azimuths.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub struct ColSpan {
    pub start: usize,
    pub len: usize,
    pub cols: usize,
}

impl ColSpan {
    /// The shortest span holding every column of `occupied` (sorted, unique).
    fn covering(occupied: &[usize], cols: usize) -> Self {
        // The largest gap between occupied columns, going round the circle,
        // is what the span leaves out.
        let n = occupied.len();
        let mut best_gap = 0;
        let mut start = occupied[0];
        for i in 0..n {
            let here = occupied[i];
            let next = occupied[(i + 1) % n];
            let gap = (next + cols - here - 1) % cols;
            let gap = if n == 1 { cols - 1 } else { gap };
            if gap > best_gap {
                best_gap = gap;
                start = next;
            }
        }
        Self {
            start,
            len: cols - best_gap,
            cols,
        }
    }

    /// Whether the spans, each widened by `margin` columns on both sides, meet.
    pub fn overlaps(&self, other: &ColSpan, margin: usize) -> bool {
        let cols = self.cols as i64;
        let (a0, alen) = (
            self.start as i64 - margin as i64,
            (self.len + 2 * margin) as i64,
        );
        let (b0, blen) = (other.start as i64, other.len as i64);
        if alen >= cols || blen >= cols {
            return true;
        }
        // Offset of b's start from a's start, on the circle.
        let d = (b0 - a0).rem_euclid(cols);
        d < alen || d + blen > cols
    }
}

/// Cells within reach of the event threshold (at least
/// `CANDIDATE_FRACTION` of it) on a surface facing the sensor, grouped by
/// 8-connectivity (see `event_looming` for the cells that take part); the
/// clusters whose median looming reaches the threshold. Judging the median of
/// a region rather than counting cells above the threshold keeps noise from
/// lifting a face that looms just below it, and edge spikes from setting it; the clusters of at
/// least `min_cells` cells that reach into the corridor. The whole object
/// counts once part of it is in the path, so an object entering the corridor
/// is seen at its full size.
pub fn hot_clusters(
    looming: &PairLooming,
    (scan, objects): (&Scan, Option<&PairObjects>),
    (corridor, facing): (&Corridor, &FacingLooming),
    config: &EventConfig,
    min_cells: usize,
) -> Vec<Cluster> {
    let candidates = Candidates::find(looming, (scan, objects), (config, facing), min_cells);
    candidates
        .components
        .iter()
        .filter_map(|(cells, looming_per_s)| {
            candidates.described_if_counts(cells, *looming_per_s, (corridor, Offset::Exact))
        })
        .collect()
}

/// The looming of the strongest approach in the path this pair, 1/s: the
/// largest looming of a cluster found as [`hot_clusters`] finds them, with
/// the threshold lowered to a time to contact of [`PATH_PEAK_FLOOR_TTC_S`],
/// so that it is defined below the event threshold too (the curve a near
/// miss rises out of) and is a cluster's median, which neither noise nor
/// edge spikes set; `None` when nothing in the path approaches that fast.
pub fn path_peak_looming(
    looming: &PairLooming,
    (scan, objects): (&Scan, Option<&PairObjects>),
    (corridor, facing): (&Corridor, &FacingLooming),
    config: &EventConfig,
    min_cells: usize,
) -> Option<f64> {
    let floor = EventConfig {
        ttc_threshold_s: PATH_PEAK_FLOOR_TTC_S.max(config.ttc_threshold_s),
        ..config.clone()
    };
    let mut candidates = Candidates::find(looming, (scan, objects), (&floor, facing), min_cells);
    // The fastest first: the first that counts is the largest of those that
    // do (describing a cluster takes every cell's offset from the corridor,
    // and the floor finds many slow ones). Only whether it counts is asked:
    // its distance from the path need only be known to lie within the
    // corridor ([`Offset::WithinCorridor`]).
    let mut components = std::mem::take(&mut candidates.components);
    components.sort_by(|a, b| b.1.total_cmp(&a.1));
    components
        .iter()
        .find(|(cells, looming_per_s)| {
            candidates
                .described_if_counts(cells, *looming_per_s, (corridor, Offset::WithinCorridor))
                .is_some()
        })
        .map(|(_, looming_per_s)| *looming_per_s)
}

/// Each cell's looming as the events take it ([`event_looming`]) where the
/// cell may join a cluster (on a surface facing the sensor within the
/// events' `facing_cos`, with a return), NaN elsewhere: taken once a pair
/// for both thresholds, the events' ([`hot_clusters`]) and the path peak's
/// floor ([`path_peak_looming`]), which each took it over every cell.
pub struct FacingLooming {
    looming_per_s: Vec<f32>,
    /// The `facing_cos` it was taken with: the configs it serves hold the
    /// same (they differ in their threshold only).
    facing_cos: f64,
}

impl FacingLooming {
    pub fn of(looming: &PairLooming, config: &EventConfig) -> Self {
        let facing = |cell: usize| {
            f64::from(looming.incidence_cos[cell]) >= config.facing_cos
                && looming.image.point[cell] != NO_POINT
        };
        // `event_looming` is an `f32` widened: narrowed back exactly.
        let of_cell = |cell: usize| match event_looming(looming, cell) {
            Some(l) if facing(cell) => l as f32,
            _ => f32::NAN,
        };
        Self {
            looming_per_s: (0..looming.geometry.cells()).map(of_cell).collect(),
            facing_cos: config.facing_cos,
        }
    }
}

/// One pair's clusters at a threshold before they are described: the
/// connected candidate cells whose median looming reaches it.
struct Candidates<'a> {
    looming: &'a PairLooming,
    scan: &'a Scan,
    objects: Option<&'a PairObjects>,
    object_cells: ObjectCells,
    config: &'a EventConfig,
    /// Each cluster's cells and median looming, 1/s.
    components: Vec<(Vec<usize>, f64)>,
}

impl<'a> Candidates<'a> {
    fn find(
        looming: &'a PairLooming,
        (scan, objects): (&'a Scan, Option<&'a PairObjects>),
        (config, facing): (&'a EventConfig, &FacingLooming),
        min_cells: usize,
    ) -> Self {
        let geometry = &looming.geometry;
        let threshold_per_s = 1.0 / config.ttc_threshold_s;
        let candidate_per_s = CANDIDATE_FRACTION * threshold_per_s;
        debug_assert_eq!(
            facing.facing_cos, config.facing_cos,
            "FacingLooming taken with another config's facing_cos"
        );
        // (A NaN, where a cell takes no part, is below any threshold.)
        let hot: Vec<bool> = facing
            .looming_per_s
            .iter()
            .map(|&l| f64::from(l) >= candidate_per_s)
            .collect();
        // The threshold first, from the cluster's looming alone: most
        // clusters are below it (the floor's slow surroundings), and
        // describing one takes every cell's offset from the corridor.
        let components: Vec<(Vec<usize>, f64)> = connected_components(geometry, &hot)
            .into_iter()
            .filter(|cells| cells.len() >= min_cells)
            .filter_map(|cells| {
                let looming_per_s = cluster_looming(looming, &cells);
                (looming_per_s >= threshold_per_s).then_some((cells, looming_per_s))
            })
            .collect();
        // Each object's cells, gathered in one pass (only when a cluster needs
        // an object's footprint).
        let object_cells = objects
            .filter(|_| !components.is_empty())
            .map(|o| ObjectCells::of(&o.cell_object, o.objects.len()))
            .unwrap_or_default();
        Self {
            looming,
            scan,
            objects,
            object_cells,
            config,
            components,
        }
    }

    /// The cluster of `cells` described, where it counts: an area (a line of
    /// cells one beam or one column wide is the trace of an edge or of the
    /// sweep's seam) reaching into the corridor, and no faster than a static
    /// surface could loom unless part of it moves.
    fn described_if_counts(
        &self,
        cells: &[usize],
        looming_per_s: f64,
        (corridor, offset): (&Corridor, Offset),
    ) -> Option<Cluster> {
        let (looming, scan) = (self.looming, self.scan);
        let position = |cell: usize| -> Option<Vector3<f64>> {
            let index = looming.image.point[cell];
            (index != NO_POINT).then(|| {
                let p = scan.points_m[index as usize];
                Vector3::new(f64::from(p[0]), f64::from(p[1]), f64::from(p[2]))
            })
        };
        // The cluster's returns, for its centroid and, off any object, its
        // distance from the path.
        let points: Vec<Vector3<f64>> = cells.iter().filter_map(|&c| position(c)).collect();
        let (mut cluster, object) =
            describe(looming, self.objects, (cells, looming_per_s), &points);
        // The distance from the path last: it takes every return of the
        // cluster, or of the object it lies on, where the rest is cheap.
        let counts = cluster.rows.1 > cluster.rows.0
            && cluster.cols.len >= 2
            && plausible_if_static(&cluster, looming.velocity_mps, self.config.facing_cos);
        if !counts {
            return None;
        }
        let half_width_m = self.config.corridor_half_width_m();
        let within_m = offset.within_m(half_width_m);
        cluster.lateral_offset_m = match object {
            // The object's whole footprint: an object in the path counts whole,
            // one beside it never, whichever of its parts is hot.
            Some((objects, index)) => {
                let horizon_s = (1.0 / looming_per_s).clamp(0.0, PREDICTION_HORIZON_S);
                let object_cells = self.object_cells.get(index).unwrap_or(&[]);
                object_offset_m(
                    objects,
                    (index, object_cells),
                    (corridor, horizon_s, within_m),
                    &position,
                )
            }
            None => nearest_within(points.iter().map(|p| corridor.offset_m(p)), within_m),
        };
        (cluster.lateral_offset_m <= half_width_m).then_some(cluster)
    }
}

/// How exactly [`Candidates::described_if_counts`] takes a cluster's
/// distance from the path.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
enum Offset {
    /// The smallest distance of its returns (an event reports it).
    Exact,
    /// Only as far as needed to know whether it lies within the corridor:
    /// the first return found within it ends the search, and an object
    /// that cannot reach it by the horizon is not followed, so the distance
    /// reported lies on the same side of the corridor's half width as the
    /// smallest (the path's peak looming asks only whether a cluster
    /// counts; on a car ahead in the path its twenty predicted positions
    /// took every return again).
    WithinCorridor,
}

impl Offset {
    /// The distance the search may stop at, for a corridor `half_width_m`
    /// either side of the path (none: the exact distance).
    fn within_m(self, half_width_m: f64) -> Option<f64> {
        match self {
            Offset::Exact => None,
            Offset::WithinCorridor => Some(half_width_m),
        }
    }
}

/// The smallest of `offsets_m`, or the first at most `within_m` where
/// given ([`Offset::WithinCorridor`]).
fn nearest_within(offsets_m: impl Iterator<Item = f64>, within_m: Option<f64>) -> f64 {
    let mut nearest = f64::INFINITY;
    for offset_m in offsets_m {
        nearest = nearest.min(offset_m);
        if within_m.is_some_and(|within_m| nearest <= within_m) {
            break;
        }
    }
    nearest
}

/// The slowest approach [`path_peak_looming`] reports: a time to contact of
/// 10 s (0.1 1/s).
pub const PATH_PEAK_FLOOR_TTC_S: f64 = 10.0;

/// A static surface facing the sensor within `acos(facing_cos)` looms at
/// most `|t| / (facing_cos R)` along any ray (`(n . t) / ((n . e) R)`), `t` the
/// ego velocity: a cluster with no moving cell that reads far more is an
/// artefact (on a real HDL-64E log, cells at 2.4 m reading 13 1/s at 7 m/s,
/// where at most 6 is possible). A fifth more is allowed for the
/// velocity's own error. Unknown velocity: no check.
fn plausible_if_static(cluster: &Cluster, velocity_mps: Option<[f64; 3]>, facing_cos: f64) -> bool {
    let Some(v) = velocity_mps else {
        return true;
    };
    if cluster.moving_cells > 0 {
        return true;
    }
    let speed = (v[0] * v[0] + v[1] * v[1] + v[2] * v[2]).sqrt();
    let bound = STATIC_BOUND_MARGIN * speed / (facing_cos.max(0.1) * cluster.near_range_m.max(0.5))
        + STATIC_BOUND_SLACK_PER_S;
    cluster.looming_per_s <= bound
}

/// Margin on the static bound for an estimated or noisy velocity.
const STATIC_BOUND_MARGIN: f64 = 1.2;
/// Looming noise allowed on top of the static bound, 1/s.
const STATIC_BOUND_SLACK_PER_S: f64 = 0.3;

/// Trusted cells a cluster needs for its value to come from them alone.
const MIN_TRUSTED_CELLS: usize = 3;

/// Cells down to this fraction of the threshold join a cluster, whose median
/// then decides.
pub(crate) const CANDIDATE_FRACTION: f64 = 0.8;

/// The flaw that leaves a cell's measured `L_lidar` usable: a neighbour on
/// another surface. (Without an ego prediction the surface is newly in view,
/// and the difference may straddle a silhouette.)
const MEASURABLE: u8 = mask::EDGE;

/// The looming a cell contributes to an event: the fused value of a trusted
/// cell, unless it is ambiguous (a significant disagreement outside any
/// moving patch: static world or mover, its fused value is neither); for a
/// cell whose only flaws are [`MEASURABLE`], its measured `L_lidar` (right on
/// moving objects, where the fused value of an edge cell falls back on the
/// static-world prediction). At 32 x 512 a pedestrian 14 m away is four
/// columns wide, all of them edge cells.
fn event_looming(looming: &PairLooming, cell: usize) -> Option<f64> {
    let flags = looming.mask[cell];
    let value = if flags == 0 {
        if looming.disagrees[cell] && !looming.moving[cell] {
            return None;
        }
        looming.fused[cell]
    } else if flags & !MEASURABLE == 0 {
        looming.l_lidar[cell]
    } else {
        return None;
    };
    value.is_finite().then_some(f64::from(value))
}

/// Components of the hot cells under 8-connectivity (columns wrap).
fn connected_components(geometry: &ImageGeometry, hot: &[bool]) -> Vec<Vec<usize>> {
    let mut seen = vec![false; hot.len()];
    let mut components = Vec::new();
    let mut stack = Vec::new();
    for start in 0..hot.len() {
        if !hot[start] || seen[start] {
            continue;
        }
        seen[start] = true;
        stack.push(start);
        let mut cells = Vec::new();
        while let Some(cell) = stack.pop() {
            cells.push(cell);
            for n in geometry.neighbours(cell, 1, 1) {
                if hot[n] && !seen[n] {
                    seen[n] = true;
                    stack.push(n);
                }
            }
        }
        cells.sort_unstable();
        components.push(cells);
    }
    components
}

/// A cluster's looming, 1/s: the median (upper middle) of its cells'.
/// Trusted cells set the value when there are a few; edge cells only when
/// the object is all edges (small or far at a coarse resolution): near
/// corners an edge cell mixes two faces. `cells` are hot, so each has a
/// looming (`event_looming`); NaN without a cell.
fn cluster_looming(looming: &PairLooming, cells: &[usize]) -> f64 {
    let trusted: Vec<usize> = cells
        .iter()
        .copied()
        .filter(|&c| looming.mask[c] == 0)
        .collect();
    let valued = if trusted.len() >= MIN_TRUSTED_CELLS {
        &trusted[..]
    } else {
        cells
    };
    let mut values: Vec<f64> = valued
        .iter()
        .filter_map(|&c| event_looming(looming, c))
        .collect();
    if values.is_empty() {
        return f64::NAN;
    }
    let middle = values.len() / 2;
    *values.select_nth_unstable_by(middle, f64::total_cmp).1
}

/// The cluster of hot `cells` whose looming is `looming_per_s`
/// ([`cluster_looming`]), `points` their returns: all but its distance
/// from the path (left infinite), and the object it lies on.
fn describe<'o>(
    looming: &PairLooming,
    objects: Option<&'o PairObjects>,
    (cells, looming_per_s): (&[usize], f64),
    points: &[Vector3<f64>],
) -> (Cluster, Option<(&'o PairObjects, usize)>) {
    let cols = looming.geometry.cols;
    let mut ranges: Vec<f64> = cells
        .iter()
        .map(|&c| f64::from(looming.image.range_m[c]))
        .collect();
    // The median and the tenth percentile by selection (a cluster of a car
    // close ahead holds thousands of cells): the tenth lies in the part
    // below the median.
    let (middle, tenth) = (ranges.len() / 2, ranges.len() / 10);
    let (below, &mut range_m, _) = ranges.select_nth_unstable_by(middle, f64::total_cmp);
    let near_range_m = if tenth < middle {
        *below.select_nth_unstable_by(tenth, f64::total_cmp).1
    } else {
        range_m
    };
    let centroid = points.iter().sum::<Vector3<f64>>() / points.len().max(1) as f64;
    let object = objects.and_then(|o| dominant_object(o, cells));
    let mut occupied: Vec<usize> = cells.iter().map(|&c| c % cols).collect();
    occupied.sort_unstable();
    occupied.dedup();
    let rows = cells.iter().map(|&c| c / cols);
    let cluster = Cluster {
        cells: cells.len(),
        rows: (rows.clone().min().unwrap_or(0), rows.max().unwrap_or(0)),
        cols: ColSpan::covering(&occupied, cols),
        looming_per_s,
        centroid_m: [centroid.x, centroid.y, centroid.z],
        range_m,
        near_range_m,
        lateral_offset_m: f64::INFINITY,
        object_id: object.map(|(objects, index)| objects.objects[index].id),
        moving_cells: cells.iter().filter(|&&c| looming.moving[c]).count(),
    };
    (cluster, object)
}

/// The object (index in `objects.objects`) at least half of `cells` belong
/// to.
fn dominant_object<'o>(
    objects: &'o PairObjects,
    cells: &[usize],
) -> Option<(&'o PairObjects, usize)> {
    let mut counts: std::collections::BTreeMap<u32, usize> = std::collections::BTreeMap::new();
    for &cell in cells {
        let object = objects.cell_object.get(cell).copied().unwrap_or(NO_OBJECT);
        if object != NO_OBJECT {
            *counts.entry(object).or_default() += 1;
        }
    }
    let (&index, &count) = counts.iter().max_by_key(|&(_, n)| *n)?;
    (2 * count >= cells.len() && (index as usize) < objects.objects.len())
        .then_some((objects, index as usize))
}

/// Smallest distance of the object's returns from the ego path, m, now or,
/// for an object moving on its own (its track's velocity over the ground at
/// least [`MIN_PREDICTED_SPEED_MPS`]), at any time up to `horizon_s` ahead
/// (its time to contact, at most [`PREDICTION_HORIZON_S`]): a pedestrian
/// walking into the lane is in the path before it reaches it. With
/// `within_m` ([`Offset::WithinCorridor`]) only on which side of it the
/// distance lies is kept: the search ends at the first distance found
/// within it, and returns that cannot come within it by the horizon are
/// not followed.
fn object_offset_m(
    objects: &PairObjects,
    (index, cells): (usize, &[usize]),
    (corridor, horizon_s, within_m): (&Corridor, f64, Option<f64>),
    position: &dyn Fn(usize) -> Option<Vector3<f64>>,
) -> f64 {
    let object = &objects.objects[index];
    let velocity = object
        .velocity_mps
        .map(Vector3::from)
        .filter(|v| agrees_with_disagreement(object, v))
        .map(|v| Vector3::new(v.x, v.y, 0.0))
        .filter(|v| v.norm() >= MIN_PREDICTED_SPEED_MPS);
    let offsets = cells
        .iter()
        .filter_map(|&cell| position(cell))
        .map(|p| (corridor.offset_m(&p), p));
    let Some(velocity) = velocity else {
        // Not moving on its own: its distance now (no order needed).
        return nearest_within(offsets.map(|(offset, _)| offset), within_m);
    };
    // The returns by their distance from the path now, nearest first: the
    // distance from the path moves by at most the shift (it is a distance
    // to a curve), so a shifted return need only be looked at while its
    // distance now, less the shift, could beat the nearest found.
    let mut returns: Vec<(f64, Vector3<f64>)> = offsets.collect();
    // Where only the side of `within_m` is asked: none followed where one
    // lies within it now, and only those that could come within it by the
    // horizon (no distance falls by more than the largest shift) otherwise.
    let reach_m = within_m.unwrap_or(f64::INFINITY);
    if let Some(within_m) = within_m {
        let nearest_now = returns.iter().map(|r| r.0).fold(f64::INFINITY, f64::min);
        if nearest_now <= within_m {
            return nearest_now;
        }
        let largest_shift_m = velocity.norm() * horizon_s;
        returns.retain(|(offset_now, _)| offset_now - largest_shift_m <= within_m);
        if returns.is_empty() {
            return nearest_now;
        }
    }
    returns.sort_unstable_by(|a, b| a.0.total_cmp(&b.0));
    let now = returns.first().map_or(f64::INFINITY, |r| r.0);
    let steps = (horizon_s / PREDICTION_STEP_S).ceil() as usize;
    let mut nearest = now;
    for k in 1..=steps {
        let shift = velocity * (k as f64 * PREDICTION_STEP_S).min(horizon_s);
        let shift_m = shift.norm();
        for (offset_now, p) in &returns {
            if offset_now - shift_m >= nearest || offset_now - shift_m > reach_m {
                break;
            }
            nearest = nearest.min(corridor.offset_m(&(p + shift)));
            if within_m.is_some_and(|within_m| nearest <= within_m) {
                return nearest;
            }
        }
    }
    nearest
}

/// Whether a track's velocity agrees with what the object's `D` measured of
/// its own motion: the velocity's component along the ray to the centroid
/// predicts `D = -(v . c) / |c|^2`, which must be within
/// [`D_AGREEMENT_PER_S`] plus a radial velocity error of
/// [`TRACK_SPEED_ERROR_MPS`] over the range. A track's velocity comes from
/// its centroid's moves, which a segment merging with its neighbour also
/// makes: on the KITTI scans republished in `base_link` a facade 12 m away
/// grew from 563 to 3075 cells between two pairs and its track read
/// 14 m/s towards the path, where its `D` read -0.004 1/s (that velocity
/// predicts -0.48); followed, it was a false near miss. A pedestrian
/// crossing the lane, whose motion `D` does not see, moves across the ray
/// and agrees. Without a `D` (no ego motion), the track is taken as it is.
fn agrees_with_disagreement(object: &Object, velocity: &Vector3<f64>) -> bool {
    let Some(measured_per_s) = object.disagreement_per_s else {
        return true;
    };
    let centroid = Vector3::from(object.centroid_m);
    let range_sq = centroid.norm_squared();
    if range_sq <= 0.0 {
        return true;
    }
    let predicted_per_s = -velocity.dot(&centroid) / range_sq;
    (predicted_per_s - measured_per_s).abs()
        <= D_AGREEMENT_PER_S + TRACK_SPEED_ERROR_MPS / range_sq.sqrt()
}

/// See [`agrees_with_disagreement`]: `D`'s own error, 1/s ...
const D_AGREEMENT_PER_S: f64 = 0.1;
/// ... and a track velocity's error along the ray, m/s.
const TRACK_SPEED_ERROR_MPS: f64 = 1.0;

/// The farthest ahead an object's own motion is followed into the path, s.
const PREDICTION_HORIZON_S: f64 = 2.0;
/// ... in steps of, s.
const PREDICTION_STEP_S: f64 = 0.1;
/// Slower than this (m/s over the ground) an object is taken to stand: its
/// track's velocity is then centroid noise.
const MIN_PREDICTED_SPEED_MPS: f64 = 0.5;

#[cfg(test)]
mod tests {
    use super::*;

    /// An object with its centroid at `centroid_m` and the `D` measured.
    fn object_at(centroid_m: [f64; 3], disagreement_per_s: Option<f64>) -> Object {
        Object {
            id: 1,
            age_pairs: 3,
            cells: 600,
            points: 600,
            nearest_range_m: Vector3::from(centroid_m).norm(),
            centroid_m,
            min_m: centroid_m,
            max_m: centroid_m,
            bearing_deg: centroid_m[1].atan2(centroid_m[0]).to_degrees(),
            looming_per_s: Some(0.04),
            looming_se_per_s: Some(0.001),
            lidar_looming_per_s: Some(0.04),
            measured_cells: 300,
            looming_from_track: false,
            looming_assumed_static: false,
            time_to_contact_s: Some(25.0),
            disagreement_per_s,
            moving: false,
            velocity_mps: None,
        }
    }

    #[test]
    fn a_tracks_velocity_is_followed_only_where_d_agrees() {
        // The facade of the KITTI base_link copy: 12 m away at 35 deg left,
        // D -0.004 1/s, its merged segment's centroid jumping 14 m/s.
        let facade = object_at([10.6, 7.4, -0.7], Some(-0.004));
        assert!(!agrees_with_disagreement(
            &facade,
            &Vector3::new(12.3, -6.7, -0.8)
        ));
        // A pedestrian crossing the ray 12 m ahead: D does not see it.
        let walker = object_at([12.0, 1.0, -0.8], Some(0.01));
        assert!(agrees_with_disagreement(
            &walker,
            &Vector3::new(0.0, -1.5, 0.0)
        ));
        // A car closing on its own at 5 m/s from 10 m: D reads 0.5 1/s.
        let car = object_at([10.0, 0.0, -0.5], Some(0.5));
        assert!(agrees_with_disagreement(
            &car,
            &Vector3::new(-5.0, 0.0, 0.0)
        ));
        assert!(!agrees_with_disagreement(
            &car,
            &Vector3::new(5.0, 0.0, 0.0)
        ));
        // Without ego motion there is no D: the track is taken as it is.
        let unknown = object_at([10.0, 0.0, -0.5], None);
        assert!(agrees_with_disagreement(
            &unknown,
            &Vector3::new(12.0, 0.0, 0.0)
        ));
    }

    /// The smallest distance from the path of `points` moved by `velocity`
    /// at each prediction step up to `horizon_s`, all of them tried.
    fn offset_by_every_step(
        corridor: &Corridor,
        points: &[Vector3<f64>],
        velocity: Option<Vector3<f64>>,
        horizon_s: f64,
    ) -> f64 {
        let steps = (horizon_s / PREDICTION_STEP_S).ceil() as usize;
        let shifts = (0..=steps).map(|k| match velocity {
            Some(v) => v * (k as f64 * PREDICTION_STEP_S).min(horizon_s),
            None => Vector3::zeros(),
        });
        shifts
            .flat_map(|shift| points.iter().map(move |p| corridor.offset_m(&(p + shift))))
            .fold(f64::INFINITY, f64::min)
    }

    #[test]
    fn an_objects_distance_from_the_path_is_every_steps_and_the_quick_one_on_its_side() {
        let mut rng = crate::test_rng::SplitMix64(26);
        let half_width_m = 1.5;
        let (mut within, mut beyond) = (0, 0);
        for trial in 0..600 {
            let yaw_rate = rng.uniform(-0.3, 0.3);
            let corridor = Corridor::new(
                Some(Vector3::new(8.0, 0.0, 0.0)),
                Some(Vector3::new(0.0, 0.0, yaw_rate)),
                half_width_m,
            );
            let centre = Vector3::new(rng.uniform(3.0, 30.0), rng.uniform(-8.0, 8.0), -0.5);
            let points: Vec<Vector3<f64>> = (0..80)
                .map(|_| centre + Vector3::new(rng.signed(), rng.signed(), 0.5 * rng.signed()))
                .collect();
            let mut object = object_at(centre.into(), None);
            // A third stand (their distance now only).
            let velocity = (trial % 3 != 0)
                .then(|| Vector3::new(3.0 * rng.signed(), 3.0 * rng.signed(), 0.0))
                .filter(|v| v.norm() >= MIN_PREDICTED_SPEED_MPS);
            object.velocity_mps = velocity.map(Into::into);
            let objects = PairObjects {
                ground: None,
                cell_object: Vec::new(),
                objects: vec![object],
            };
            let cells: Vec<usize> = (0..points.len()).collect();
            let position = |cell: usize| points.get(cell).copied();
            let horizon_s = rng.uniform(0.05, PREDICTION_HORIZON_S);
            let offset = |within_m| {
                object_offset_m(
                    &objects,
                    (0, &cells),
                    (&corridor, horizon_s, within_m),
                    &position,
                )
            };
            let every_step = offset_by_every_step(&corridor, &points, velocity, horizon_s);
            let exact = offset(None);
            assert_eq!(exact, every_step, "trial {trial}");
            let quick = offset(Some(half_width_m));
            assert_eq!(
                quick <= half_width_m,
                exact <= half_width_m,
                "trial {trial}"
            );
            if exact <= half_width_m {
                within += 1;
            } else {
                beyond += 1;
            }
        }
        // Both sides were tried.
        assert!(
            within > 100 && beyond > 100,
            "{within} within, {beyond} beyond"
        );
    }

    #[test]
    fn spans_cover_their_columns_the_short_way_round() {
        let span = ColSpan::covering(&[3, 4, 5], 16);
        assert_eq!((span.start, span.len), (3, 3));
        let wrapped = ColSpan::covering(&[0, 1, 14, 15], 16);
        assert_eq!((wrapped.start, wrapped.len), (14, 4));
        let single = ColSpan::covering(&[7], 16);
        assert_eq!((single.start, single.len), (7, 1));
    }

    #[test]
    fn spans_overlap_across_the_seam_and_with_a_margin() {
        let a = ColSpan::covering(&[14, 15, 0], 16);
        let b = ColSpan::covering(&[1, 2], 16);
        assert!(!a.overlaps(&b, 0));
        assert!(a.overlaps(&b, 1));
        assert!(b.overlaps(&a, 1));
        let far = ColSpan::covering(&[7, 8], 16);
        assert!(!a.overlaps(&far, 2));
        assert!(!far.overlaps(&a, 2));
        assert!(far.overlaps(&a, 6));
    }
}
