//! Transforms that change over time (`/tf`): each edge's recent samples,
//! interpolated at a scan's stamp. What a cloud in a world frame needs to
//! find its sensor in every scan (`origin`). Bounded: a few seconds per edge.

use std::collections::{HashMap, VecDeque};

use nalgebra::{Isometry3, Translation3};

use super::frames::{TransformTree, normalize_frame_id};
use crate::model::{FrameTransform, StampNs};

/// Samples kept per edge (a second at 200 Hz; seconds at the usual rates).
const SAMPLES_PER_EDGE: usize = 256;
/// A stamp further than this from every sample of an edge gets no edge, ns.
const MAX_EXTRAPOLATION_NS: StampNs = 200_000_000;

/// One edge's samples, oldest first: (stamp, parent_from_child).
type Samples = VecDeque<(StampNs, Isometry3<f64>)>;

/// The recent samples of every `/tf` edge.
#[derive(Debug, Clone, Default)]
pub struct TransformHistory {
    /// child frame -> (parent frame, its samples).
    edges: HashMap<String, (String, Samples)>,
}

impl TransformHistory {
    /// Keep one `/tf` transform (out-of-order samples are placed in order).
    pub fn insert(&mut self, transform: &FrameTransform) {
        let child = normalize_frame_id(&transform.child_frame).to_owned();
        let parent = normalize_frame_id(&transform.parent_frame).to_owned();
        if child == parent {
            return;
        }
        let entry = self
            .edges
            .entry(child)
            .or_insert_with(|| (parent.clone(), VecDeque::new()));
        entry.0 = parent;
        let samples = &mut entry.1;
        let at = samples.partition_point(|(t, _)| *t <= transform.stamp_ns);
        samples.insert(at, (transform.stamp_ns, transform.parent_from_child));
        while samples.len() > SAMPLES_PER_EDGE {
            samples.pop_front();
        }
    }

    /// `statics` with every `/tf` edge at `stamp_ns` (interpolated between
    /// its samples; an edge with no sample within 0.2 s is left out).
    pub fn tree_at(&self, statics: &TransformTree, stamp_ns: StampNs) -> TransformTree {
        let mut tree = statics.clone();
        for (child, (parent, samples)) in &self.edges {
            if let Some(pose) = interpolate(samples, stamp_ns) {
                tree.insert(&FrameTransform {
                    stamp_ns,
                    parent_frame: parent.clone(),
                    child_frame: child.clone(),
                    parent_from_child: pose,
                });
            }
        }
        tree
    }
}

/// The pose at `stamp_ns`: linear in translation, spherical in rotation
/// between the samples about it; the nearest sample just outside them.
fn interpolate(samples: &Samples, stamp_ns: StampNs) -> Option<Isometry3<f64>> {
    let after = samples.partition_point(|(t, _)| *t < stamp_ns);
    let before = after.checked_sub(1).and_then(|k| samples.get(k));
    match (before, samples.get(after)) {
        (Some(&(t0, a)), Some(&(t1, b))) if t1 > t0 => {
            let u = (stamp_ns - t0) as f64 / (t1 - t0) as f64;
            let translation = a.translation.vector.lerp(&b.translation.vector, u);
            let rotation = a.rotation.slerp(&b.rotation, u);
            Some(Isometry3::from_parts(
                Translation3::from(translation),
                rotation,
            ))
        }
        (Some(&(t, pose)), _) | (None, Some(&(t, pose)))
            if (stamp_ns - t).abs() <= MAX_EXTRAPOLATION_NS =>
        {
            Some(pose)
        }
        _ => None,
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn at(stamp_ns: StampNs, x_m: f64) -> FrameTransform {
        FrameTransform {
            stamp_ns,
            parent_frame: "odom".into(),
            child_frame: "base_link".into(),
            parent_from_child: Isometry3::translation(x_m, 0.0, 0.0),
        }
    }

    #[test]
    fn an_edge_is_interpolated_at_the_stamp_and_absent_far_from_its_samples() {
        let mut history = TransformHistory::default();
        history.insert(&at(2_000_000_000, 20.0));
        history.insert(&at(1_000_000_000, 10.0));
        let tree = history.tree_at(&TransformTree::new(), 1_250_000_000);
        let pose = tree.lookup("odom", "base_link").unwrap();
        assert!((pose.translation.vector.x - 12.5).abs() < 1e-9);
        // Just past the last sample: held; a second past: no edge.
        let held = history.tree_at(&TransformTree::new(), 2_100_000_000);
        assert!(held.lookup("odom", "base_link").is_some());
        let gone = history.tree_at(&TransformTree::new(), 3_000_000_000);
        assert!(gone.lookup("odom", "base_link").is_none());
    }
}
