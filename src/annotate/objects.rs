//! `/looming/objects` (a `foxglove.SceneUpdate`: a box per object, coloured
//! by its threat level, labelled with its id and time to contact) and
//! `/looming/object_list` (the objects' figures as JSON, schema
//! `looming.ObjectList`), one message each per pair.

use ::foxglove::messages::{
    Color, CubePrimitive, KeyValuePair, Pose, Quaternion, SceneEntity, SceneEntityDeletion,
    SceneUpdate, TextPrimitive, Vector3, scene_entity_deletion,
};
use serde::{Deserialize, Serialize};

use super::colour;
use super::foxglove::timestamp;
use crate::engine::ThreatLevel;
use crate::model::Scan;
use crate::objects::{Object, PairObjects};

pub const OBJECT_LIST_SCHEMA: &str = include_str!("../../schemas/looming.ObjectList.schema.json");

/// One `/looming/object_list` message.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct ObjectList {
    /// Header stamp of the pair's current scan, ns.
    pub stamp_ns: i64,
    /// The frame of the positions (the LiDAR cloud's).
    pub frame_id: String,
    pub objects: Vec<ObjectRecord>,
}

/// An object with its threat level.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct ObjectRecord {
    #[serde(flatten)]
    pub object: Object,
    /// `none`, `low`, `medium` or `high`, from its time to contact.
    pub threat: String,
}

/// The threat level of an object from its time to contact and the levels'
/// times (`--threat-ttc`, longest first); none unless its approach is
/// significant (looming above twice its standard error: a hedge's range
/// jitter is no approach).
pub fn object_threat(object: &Object, ttc_s: &[f64; 3]) -> ThreatLevel {
    let significant = match (object.looming_per_s, object.looming_se_per_s) {
        (Some(l), Some(se)) => l > 2.0 * se,
        _ => false,
    };
    match object.looming_per_s {
        Some(looming_per_s) if significant => ThreatLevel::of(looming_per_s, ttc_s),
        _ => ThreatLevel::None,
    }
}

fn threat_name(level: ThreatLevel) -> &'static str {
    match level {
        ThreatLevel::None => "none",
        ThreatLevel::Low => "low",
        ThreatLevel::Medium => "medium",
        ThreatLevel::High => "high",
    }
}

pub(crate) fn object_list(scan: &Scan, objects: &PairObjects, ttc_s: &[f64; 3]) -> ObjectList {
    ObjectList {
        stamp_ns: scan.stamp_ns,
        frame_id: scan.frame_id.clone(),
        objects: objects
            .objects
            .iter()
            .map(|object| ObjectRecord {
                object: object.clone(),
                threat: threat_name(object_threat(object, ttc_s)).into(),
            })
            .collect(),
    }
}

/// The boxes: every previous box deleted, then one entity per object.
pub(crate) fn object_scene(scan: &Scan, objects: &PairObjects, ttc_s: &[f64; 3]) -> SceneUpdate {
    let stamp = timestamp(scan.stamp_ns);
    SceneUpdate {
        deletions: vec![SceneEntityDeletion {
            timestamp: Some(stamp),
            r#type: scene_entity_deletion::Type::All as i32,
            id: String::new(),
        }],
        entities: objects
            .objects
            .iter()
            .map(|object| object_entity(scan, object, object_threat(object, ttc_s)))
            .collect(),
    }
}

fn object_entity(scan: &Scan, object: &Object, level: ThreatLevel) -> SceneEntity {
    let centre = [0, 1, 2].map(|k| 0.5 * (object.min_m[k] + object.max_m[k]));
    let size = [0, 1, 2].map(|k| (object.max_m[k] - object.min_m[k]).max(0.05));
    let [r, g, b, _] = match level {
        ThreatLevel::None => [150, 150, 150, 255],
        level => colour::threat(level),
    };
    let alpha = if level == ThreatLevel::None {
        0.25
    } else {
        0.45
    };
    let color = Color {
        r: f64::from(r) / 255.0,
        g: f64::from(g) / 255.0,
        b: f64::from(b) / 255.0,
        a: alpha,
    };
    // "if static": a value from the ego motion alone, not measured.
    let label = match object.time_to_contact_s {
        Some(ttc) if object.looming_assumed_static => {
            format!("#{} TTC {ttc:.1} s if static", object.id)
        }
        Some(ttc) => format!("#{} TTC {ttc:.1} s", object.id),
        None => format!("#{}", object.id),
    };
    let above = [centre[0], centre[1], object.max_m[2] + 0.3];
    SceneEntity {
        timestamp: Some(timestamp(scan.stamp_ns)),
        frame_id: scan.frame_id.clone(),
        id: format!("object-{}", object.id),
        metadata: vec![
            key_value("id", object.id.to_string()),
            key_value("threat", threat_name(level).into()),
            key_value("moving", object.moving.to_string()),
        ],
        cubes: vec![CubePrimitive {
            pose: Some(pose_in_frame(scan, centre)),
            size: Some(Vector3 {
                x: size[0],
                y: size[1],
                z: size[2],
            }),
            color: Some(color),
        }],
        texts: vec![TextPrimitive {
            pose: Some(pose_in_frame(scan, above)),
            billboard: true,
            font_size: 14.0,
            scale_invariant: true,
            color: Some(Color {
                r: 1.0,
                g: 1.0,
                b: 1.0,
                a: 1.0,
            }),
            text: label,
        }],
        ..SceneEntity::default()
    }
}

fn key_value(key: &str, value: String) -> KeyValuePair {
    KeyValuePair {
        key: key.into(),
        value,
    }
}

/// A point of the scan's own coordinates as a pose in its frame (the cloud's
/// pose applied: identity for PointCloud2).
fn pose_in_frame(scan: &Scan, p: [f64; 3]) -> Pose {
    let point = scan.sensor_pose * nalgebra::Point3::new(p[0], p[1], p[2]);
    let q = scan.sensor_pose.rotation.quaternion();
    Pose {
        position: Some(Vector3 {
            x: point.x,
            y: point.y,
            z: point.z,
        }),
        orientation: Some(Quaternion {
            x: q.i,
            y: q.j,
            z: q.k,
            w: q.w,
        }),
    }
}
