//! Objects followed across pairs under a stable id. Each object of the
//! previous pair is moved by the ego motion over the interval (a static
//! object stays put in the world, so in the LiDAR frame it moves by
//! `-(v + w x p) dt`) and by its own velocity from its track, then matched
//! to the nearest current object whose centroid lies within a gate that
//! grows with the objects' size; matches are taken nearest first, one to
//! one. A current object without a match starts a track; a track without a
//! match survives [`MAX_MISSED_PAIRS`] pairs.

use super::measure::keep_cells_seen_before;
use super::{Object, ObjectCells, PairObjects};
use crate::engine::PairLooming;

/// Pairs a track survives without a match.
const MAX_MISSED_PAIRS: u32 = 2;
/// Pairs a track has been followed in before its velocity is reported.
const MIN_PAIRS_FOR_VELOCITY: u32 = 3;
/// An object whose horizontal extent grew or shrank by more than this
/// factor since its last pair is another segment under the same id (merged
/// with a neighbour, or split): the move of its centroid is no velocity.
/// On the KITTI scans republished in `base_link` a 9-cell segment merged
/// into a 6551-cell facade read 12 m/s across the path.
const SIZE_JUMP: f64 = 2.0;
/// Smallest gate between a predicted and a current centroid, m.
const MIN_GATE_M: f64 = 1.0;
/// ... plus this share of the larger object's horizontal extent.
const GATE_PER_EXTENT: f64 = 0.3;

#[derive(Debug, Clone)]
struct Track {
    id: u32,
    age_pairs: u32,
    missed: u32,
    centroid_m: [f64; 3],
    extent_m: f64,
    /// Its own velocity in the LiDAR frame (ego motion removed), m/s.
    velocity_mps: [f64; 3],
    /// Pairs its velocity has been followed over: its age, but restarted
    /// where its object's size jumped (see [`SIZE_JUMP`]).
    velocity_pairs: u32,
    /// Its object's nearest range in its last pair, m.
    nearest_range_m: f64,
    /// The ranges its object's box spanned in its last pair, m.
    range_span_m: (f64, f64),
    /// Its object moved on its own in its last pair (its `D`).
    moving: bool,
}

/// Gives the objects of each pair their stable ids.
#[derive(Debug, Clone, Default)]
pub struct ObjectTracker {
    tracks: Vec<Track>,
    next_id: u32,
}

impl ObjectTracker {
    /// Give `objects` (of the pair `looming`, `dt_s` after the previous pair
    /// given) their ids and ages.
    pub fn update(&mut self, objects: &mut PairObjects, looming: &PairLooming, dt_s: f64) {
        let cells = ObjectCells::of(&objects.cell_object, objects.objects.len());
        self.update_with_cells(objects, &cells, looming, dt_s);
    }

    /// [`ObjectTracker::update`] with the cells of each object gathered.
    pub(super) fn update_with_cells(
        &mut self,
        objects: &mut PairObjects,
        cells: &ObjectCells,
        looming: &PairLooming,
        dt_s: f64,
    ) {
        let ego_v = looming.velocity_mps.unwrap_or([0.0; 3]);
        let ego_w = looming.angular_velocity_radps.unwrap_or([0.0; 3]);
        let predicted: Vec<[f64; 3]> = self
            .tracks
            .iter()
            .map(|t| predict(t, ego_v, ego_w, dt_s))
            .collect();
        let mut candidates = Vec::new();
        for (o, object) in objects.objects.iter().enumerate() {
            // Once per object, not per track (a `hypot` each).
            let extent_m = extent(object);
            for (t, track) in self.tracks.iter().enumerate() {
                let distance = distance(&predicted[t], &object.centroid_m);
                let gate = MIN_GATE_M + GATE_PER_EXTENT * track.extent_m.max(extent_m);
                if distance <= gate {
                    candidates.push((distance, o, t));
                }
            }
        }
        candidates.sort_by(|a, b| a.0.total_cmp(&b.0));
        let mut object_track = vec![None; objects.objects.len()];
        let mut track_taken = vec![false; self.tracks.len()];
        for (_, o, t) in candidates {
            if object_track[o].is_none() && !track_taken[t] {
                object_track[o] = Some(t);
                track_taken[t] = true;
            }
        }
        let mut next_tracks = Vec::new();
        for (o, object) in objects.objects.iter_mut().enumerate() {
            if let Some(t) = object_track[o] {
                let track = &self.tracks[t];
                // Its span as last seen, `missed` pairs before the last.
                let since_s = dt_s * f64::from(track.missed + 1);
                // How far the object's nearest return moved since: its own
                // motion and the ego's along its rays, as seen.
                let moved_m = (object.nearest_range_m - track.nearest_range_m).abs();
                let motion = ((ego_v, ego_w), moved_m);
                let spans_m = [
                    widened(track.range_span_m, motion, since_s),
                    widened(range_span(object), motion, since_s),
                ];
                let still = !track.moving;
                let cells = cells.get(o).unwrap_or(&[]);
                if !keep_cells_seen_before(object, looming, cells, (spans_m, still)) {
                    looming_from_range(object, track.nearest_range_m, since_s);
                }
            }
            let track = match object_track[o] {
                Some(t) => self.continued(t, object, ego_v, ego_w, dt_s),
                None => self.started(object),
            };
            object.id = track.id;
            object.age_pairs = track.age_pairs;
            // Two displacements smoothed before a velocity is told.
            object.velocity_mps =
                (track.velocity_pairs >= MIN_PAIRS_FOR_VELOCITY).then_some(track.velocity_mps);
            next_tracks.push(track);
        }
        for (t, track) in self.tracks.iter().enumerate() {
            if !track_taken[t] && track.missed < MAX_MISSED_PAIRS {
                let mut kept = track.clone();
                kept.missed += 1;
                kept.centroid_m = predicted[t];
                next_tracks.push(kept);
            }
        }
        self.tracks = next_tracks;
    }

    fn started(&mut self, object: &Object) -> Track {
        self.next_id += 1;
        Track {
            id: self.next_id,
            age_pairs: 1,
            missed: 0,
            centroid_m: object.centroid_m,
            extent_m: extent(object),
            velocity_mps: [0.0; 3],
            velocity_pairs: 1,
            nearest_range_m: object.nearest_range_m,
            range_span_m: range_span(object),
            moving: object.moving,
        }
    }

    fn continued(
        &self,
        t: usize,
        object: &Object,
        ego_v: [f64; 3],
        ego_w: [f64; 3],
        dt_s: f64,
    ) -> Track {
        let track = &self.tracks[t];
        // Where the track would be had it stood still over this pair (a
        // track kept through missed pairs was moved along each of them),
        // against where the object is: its own displacement, smoothed.
        let still = static_prediction(&track.centroid_m, ego_v, ego_w, dt_s);
        let (mut velocity_mps, mut velocity_pairs) = (track.velocity_mps, track.velocity_pairs + 1);
        // A segment that merged with a neighbour or lost most of itself
        // moves its centroid without moving: its velocity starts again.
        let size_ratio = extent(object).max(0.1) / track.extent_m.max(0.1);
        if !(1.0 / SIZE_JUMP..=SIZE_JUMP).contains(&size_ratio) {
            (velocity_mps, velocity_pairs) = ([0.0; 3], 1);
        } else if dt_s > 0.0 {
            for k in 0..3 {
                let measured = (object.centroid_m[k] - still[k]) / dt_s;
                velocity_mps[k] = 0.5 * velocity_mps[k] + 0.5 * measured;
            }
        }
        Track {
            id: track.id,
            age_pairs: track.age_pairs + 1,
            missed: 0,
            centroid_m: object.centroid_m,
            extent_m: extent(object),
            velocity_mps,
            velocity_pairs,
            nearest_range_m: object.nearest_range_m,
            range_span_m: range_span(object),
            moving: object.moving,
        }
    }
}

/// An object none of whose cells measured its looming (vegetation, whose
/// returns have no previous surface along their rays; a pole seen by a few
/// cells) takes it from its track instead: `-(r_now - r_before) / (dt
/// r_now)` of its nearest range (10th percentile of its cells' ranges), the
/// same quantity over the object, with the standard error of two such
/// percentiles ([`NEAREST_RANGE_NOISE_M`] each). `dt_s` is the time since
/// the track was last seen (over a missed pair, the mean over both).
fn looming_from_range(object: &mut Object, range_before_m: f64, dt_s: f64) {
    let range_m = object.nearest_range_m;
    // A looming assumed from the ego motion gives way to a measured one.
    if (object.looming_per_s.is_some() && !object.looming_assumed_static)
        || dt_s <= 0.0
        || !(range_m.is_finite() && range_m > 0.0 && range_before_m.is_finite())
    {
        return;
    }
    let looming_per_s = -(range_m - range_before_m) / (dt_s * range_m);
    object.looming_per_s = Some(looming_per_s);
    object.looming_se_per_s =
        Some(std::f64::consts::SQRT_2 * NEAREST_RANGE_NOISE_M / (dt_s * range_m));
    object.time_to_contact_s = (looming_per_s > 0.0).then(|| 1.0 / looming_per_s);
    object.looming_from_track = true;
    object.looming_assumed_static = false;
}

/// Noise of an object's nearest range from pair to pair, m (its returns
/// change with the sampling).
const NEAREST_RANGE_NOISE_M: f64 = 0.05;

/// Where a static point at `p` appears after the ego moved for `dt_s`.
fn static_prediction(p: &[f64; 3], v: [f64; 3], w: [f64; 3], dt_s: f64) -> [f64; 3] {
    let w_cross_p = [
        w[1] * p[2] - w[2] * p[1],
        w[2] * p[0] - w[0] * p[2],
        w[0] * p[1] - w[1] * p[0],
    ];
    [
        p[0] - (v[0] + w_cross_p[0]) * dt_s,
        p[1] - (v[1] + w_cross_p[1]) * dt_s,
        p[2] - (v[2] + w_cross_p[2]) * dt_s,
    ]
}

fn predict(track: &Track, v: [f64; 3], w: [f64; 3], dt_s: f64) -> [f64; 3] {
    let still = static_prediction(&track.centroid_m, v, w, dt_s);
    [
        still[0] + track.velocity_mps[0] * dt_s,
        still[1] + track.velocity_mps[1] * dt_s,
        still[2] + track.velocity_mps[2] * dt_s,
    ]
}

fn distance(a: &[f64; 3], b: &[f64; 3]) -> f64 {
    ((a[0] - b[0]).powi(2) + (a[1] - b[1]).powi(2) + (a[2] - b[2]).powi(2)).sqrt()
}

/// The ranges an object's box spans, m: from its point nearest the sensor
/// to its farthest corner.
fn range_span(object: &Object) -> (f64, f64) {
    let (mut near_sq, mut far_sq) = (0.0, 0.0);
    for k in 0..3 {
        let (lo, hi) = (object.min_m[k], object.max_m[k]);
        let nearest = 0.0f64.clamp(lo, hi);
        near_sq += nearest * nearest;
        far_sq += (lo * lo).max(hi * hi);
    }
    (near_sq.sqrt(), far_sq.sqrt())
}

/// A track's range span as the cells of its next pair may have seen it:
/// widened by [`SPAN_MARGIN_M`], by how far the ego motion over `dt_s`
/// moves a point of its far end along a ray, and by how far its nearest
/// return moved (`moved_m`: an object approaching fast shows more of
/// itself each scan, its side's returns beyond its last span).
fn widened(
    (near_m, far_m): (f64, f64),
    ((ego_v, ego_w), moved_m): (([f64; 3], [f64; 3]), f64),
    dt_s: f64,
) -> (f64, f64) {
    let norm = |a: [f64; 3]| (a[0] * a[0] + a[1] * a[1] + a[2] * a[2]).sqrt();
    let ego_m = (norm(ego_v) + norm(ego_w) * far_m) * dt_s.abs();
    let margin_m = SPAN_MARGIN_M + ego_m + moved_m.max(0.0);
    (near_m - margin_m, far_m + margin_m)
}

/// Range beyond a track's last span a cell's previous return may lie and
/// still have been on the same object (its sampling, its own motion over a
/// pair), m.
const SPAN_MARGIN_M: f64 = 0.5;

/// Horizontal extent (diagonal of the box), m.
fn extent(object: &Object) -> f64 {
    (object.max_m[0] - object.min_m[0]).hypot(object.max_m[1] - object.min_m[1])
}

#[cfg(test)]
mod tests {
    use super::*;

    fn object(nearest_range_m: f64, looming_per_s: Option<f64>) -> Object {
        Object {
            id: 0,
            age_pairs: 0,
            cells: 60,
            points: 60,
            nearest_range_m,
            centroid_m: [nearest_range_m, 0.0, 0.0],
            min_m: [nearest_range_m, -0.5, -1.0],
            max_m: [nearest_range_m + 1.0, 0.5, 0.5],
            bearing_deg: 0.0,
            looming_per_s,
            looming_se_per_s: looming_per_s.map(|_| 0.01),
            lidar_looming_per_s: looming_per_s,
            measured_cells: if looming_per_s.is_some() { 40 } else { 0 },
            looming_from_track: false,
            looming_assumed_static: false,
            time_to_contact_s: None,
            disagreement_per_s: None,
            moving: false,
            velocity_mps: None,
        }
    }

    #[test]
    fn an_object_no_cell_measured_takes_its_tracks_range_rate() {
        // 10.0 m then 9.5 m over 0.1 s: 0.5 / (0.1 x 9.5) = 0.526 1/s.
        let mut hedge = object(9.5, None);
        looming_from_range(&mut hedge, 10.0, 0.1);
        let looming = hedge.looming_per_s.unwrap();
        assert!((looming - 0.5 / 0.95).abs() < 1e-9, "{looming}");
        assert!(hedge.looming_from_track);
        assert!((hedge.time_to_contact_s.unwrap() - 1.0 / looming).abs() < 1e-9);
        let se = hedge.looming_se_per_s.unwrap();
        assert!(
            (se - std::f64::consts::SQRT_2 * 0.05 / 0.95).abs() < 1e-9,
            "{se}"
        );
        // A measured object keeps its cells' value; no time, no value.
        let mut car = object(9.5, Some(0.2));
        looming_from_range(&mut car, 10.0, 0.1);
        assert_eq!(car.looming_per_s, Some(0.2));
        assert!(!car.looming_from_track);
        let mut first = object(9.5, None);
        looming_from_range(&mut first, 10.0, 0.0);
        assert_eq!(first.looming_per_s, None);
    }

    #[test]
    fn a_tracks_range_span_is_its_box_widened_by_what_moved() {
        // Box x 9.5..10.5, y -0.5..0.5, z -1..0.5: nearest 9.5 m (straight
        // ahead), farthest corner sqrt(10.5^2 + 0.5^2 + 1).
        let o = object(9.5, Some(0.0));
        let (near_m, far_m) = range_span(&o);
        assert!((near_m - 9.5).abs() < 1e-12, "{near_m}");
        assert!((far_m - (10.5f64.powi(2) + 0.25 + 1.0).sqrt()).abs() < 1e-12);
        // Still: the margin alone; at 10 m/s over 0.1 s, a metre more; and
        // by how far the nearest return moved.
        let still = widened((9.5, 11.0), (([0.0; 3], [0.0; 3]), 0.0), 0.1);
        assert_eq!(still, (9.5 - SPAN_MARGIN_M, 11.0 + SPAN_MARGIN_M));
        let driving = widened((9.5, 11.0), (([10.0, 0.0, 0.0], [0.0; 3]), 0.3), 0.1);
        let margin_m = SPAN_MARGIN_M + 1.0 + 0.3;
        assert!((driving.0 - (9.5 - margin_m)).abs() < 1e-12, "{driving:?}");
        assert!((driving.1 - (11.0 + margin_m)).abs() < 1e-12, "{driving:?}");
    }

    #[test]
    fn a_segment_whose_size_jumps_starts_its_velocity_again() {
        // A 1 m object walking 1 m/s across the LiDAR's y axis (no ego
        // motion), then merged with a 9 m neighbour: the merged centroid's
        // 4 m jump is no velocity.
        let mut tracker = ObjectTracker::default();
        let at = |y: f64, width_m: f64| {
            let mut o = object(10.0, Some(0.0));
            o.centroid_m = [10.0, y, 0.0];
            o.min_m = [9.5, y - 0.5 * width_m, -1.0];
            o.max_m = [10.5, y + 0.5 * width_m, 0.5];
            o
        };
        let mut track = tracker.started(&at(0.0, 1.0));
        tracker.tracks.push(track.clone());
        for k in 1..=3 {
            track = tracker.continued(0, &at(0.1 * f64::from(k), 1.0), [0.0; 3], [0.0; 3], 0.1);
            tracker.tracks[0] = track.clone();
        }
        assert!(track.velocity_pairs >= MIN_PAIRS_FOR_VELOCITY);
        assert!(track.velocity_mps[1] > 0.5, "{:?}", track.velocity_mps);
        let merged = tracker.continued(0, &at(4.4, 9.0), [0.0; 3], [0.0; 3], 0.1);
        assert_eq!(merged.velocity_pairs, 1);
        assert_eq!(merged.velocity_mps, [0.0; 3]);
        assert_eq!(
            merged.age_pairs,
            track.age_pairs + 1,
            "the id and age go on"
        );
    }
}
