//! Objects followed across pairs under a stable id. Each object of the
//! previous pair is moved by the ego motion over the interval (a static
//! object stays put in the world, so in the LiDAR frame it moves by
//! `-(v + w x p) dt`) and by its own velocity from its track, then matched
//! to the nearest current object whose centroid lies within a gate that
//! grows with the objects' size; matches are taken nearest first, one to
//! one. A current object without a match starts a track; a track without a
//! match survives [`MAX_MISSED_PAIRS`] pairs.

use super::{Object, PairObjects};
use crate::engine::PairLooming;

/// Pairs a track survives without a match.
const MAX_MISSED_PAIRS: u32 = 2;
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
        let ego_v = looming.velocity_mps.unwrap_or([0.0; 3]);
        let ego_w = looming.angular_velocity_radps.unwrap_or([0.0; 3]);
        let predicted: Vec<[f64; 3]> = self
            .tracks
            .iter()
            .map(|t| predict(t, ego_v, ego_w, dt_s))
            .collect();
        let mut candidates = Vec::new();
        for (o, object) in objects.objects.iter().enumerate() {
            for (t, track) in self.tracks.iter().enumerate() {
                let distance = distance(&predicted[t], &object.centroid_m);
                let gate = MIN_GATE_M + GATE_PER_EXTENT * track.extent_m.max(extent(object));
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
            let track = match object_track[o] {
                Some(t) => self.continued(t, object, ego_v, ego_w, dt_s),
                None => self.started(object),
            };
            object.id = track.id;
            object.age_pairs = track.age_pairs;
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
        let mut velocity_mps = track.velocity_mps;
        if dt_s > 0.0 {
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
        }
    }
}

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

/// Horizontal extent (diagonal of the box), m.
fn extent(object: &Object) -> f64 {
    (object.max_m[0] - object.min_m[0]).hypot(object.max_m[1] - object.min_m[1])
}
