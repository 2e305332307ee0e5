//! `/looming/pairs`: one JSON message per scan pair (schema
//! `schemas/looming.ScanPair.schema.json`), saying what went into the pair's
//! looming: its two scans and their layouts, the motion, what was unavailable
//! and, once measured, the pair's quality. One of our annotation channels; the
//! writer only registers its [`OwnChannelSpec`].

use serde::Serialize;

use crate::model::{
    ExtrinsicInfo, RingSource, Scan, ScanLayout, ScanPair, SensorOrigin, TimeSource,
};
use crate::output::OwnChannelSpec;
use crate::quality::PairQuality;

pub use super::topics::PAIRS_TOPIC;
const PAIRS_SCHEMA: &str = include_str!("../../schemas/looming.ScanPair.schema.json");

/// The channel and schema of `/looming/pairs`.
pub fn pairs_channel_spec() -> OwnChannelSpec {
    OwnChannelSpec::json(PAIRS_TOPIC, "looming.ScanPair", PAIRS_SCHEMA)
}

/// One `/looming/pairs` message.
#[derive(Debug, Clone, Serialize, serde::Deserialize, PartialEq)]
pub struct PairRecord {
    pub index: u64,
    pub previous: ScanRecord,
    pub current: ScanRecord,
    pub dt_s: f64,
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub velocity_lidar_mps: Option<[f64; 3]>,
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub angular_velocity_lidar_radps: Option<[f64; 3]>,
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub speed_mps: Option<f64>,
    pub unavailable: Vec<String>,
    pub extrinsic: ExtrinsicRecord,
    /// Quality figures of the pair's looming (`docs/quality.md`); absent when
    /// the engine made no image of the pair.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub quality: Option<PairQuality>,
}

#[derive(Debug, Clone, Serialize, serde::Deserialize, PartialEq)]
pub struct ScanRecord {
    pub stamp_ns: i64,
    pub log_time_ns: u64,
    pub frame_id: String,
    pub points: u64,
    pub invalid_points: u64,
    pub per_point_time: bool,
    pub ring: bool,
    pub layout: LayoutRecord,
}

/// Where a scan's rings and times came from (`engine::layout`).
#[derive(Debug, Clone, Serialize, serde::Deserialize, PartialEq)]
pub struct LayoutRecord {
    /// organized, field, laser_order, firing_order, elevation or none.
    pub rings: String,
    pub ring_count: u32,
    /// field, azimuth or stamp.
    pub times: String,
    /// The layout in words, as in the run summary.
    pub description: String,
    /// Where the sensor is in the cloud's frame and how that was found.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub origin: Option<SensorOrigin>,
}

impl LayoutRecord {
    fn new(layout: &ScanLayout) -> Self {
        Self {
            rings: layout.rings.kind().to_owned(),
            ring_count: layout.ring_count,
            times: layout.times.kind().to_owned(),
            description: layout.to_string(),
            origin: layout.origin.clone(),
        }
    }
}

#[derive(Debug, Clone, Serialize, serde::Deserialize, PartialEq)]
pub struct ExtrinsicRecord {
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub velocity: Option<String>,
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub imu: Option<String>,
}

impl ScanRecord {
    fn new(scan: &Scan, log_time_ns: u64) -> Self {
        Self {
            stamp_ns: scan.stamp_ns,
            log_time_ns,
            frame_id: scan.frame_id.clone(),
            points: scan.points_m.len() as u64,
            invalid_points: u64::from(scan.skipped_invalid_points),
            per_point_time: matches!(scan.layout.times, TimeSource::Field { .. }),
            ring: matches!(
                scan.layout.rings,
                RingSource::Field { .. }
                    | RingSource::Organized {
                        ring_field: Some(_),
                        ..
                    }
            ),
            layout: LayoutRecord::new(&scan.layout),
        }
    }
}

impl PairRecord {
    pub fn from_pair(pair: &ScanPair) -> Self {
        let at = pair.current.stamp_ns;
        let velocity = pair.motion.velocity_at(at);
        let angular = pair.motion.angular_velocity_at(at);
        let mut unavailable = Vec::new();
        if velocity.is_none() {
            unavailable.push("velocity".to_string());
        }
        if pair.motion.imu_unavailable {
            unavailable.push("imu".to_string());
        }
        if angular.is_none() {
            unavailable.push("angular_velocity".to_string());
        }
        Self {
            index: pair.index,
            previous: ScanRecord::new(&pair.previous, pair.previous_log_time_ns),
            current: ScanRecord::new(&pair.current, pair.current_log_time_ns),
            dt_s: pair.dt_s,
            velocity_lidar_mps: velocity.map(|v| [v.x, v.y, v.z]),
            angular_velocity_lidar_radps: angular.map(|w| [w.x, w.y, w.z]),
            speed_mps: velocity.map(|v| v.norm()),
            unavailable,
            extrinsic: ExtrinsicRecord {
                velocity: extrinsic_source(pair.motion.velocity_extrinsic.as_ref()),
                imu: extrinsic_source(pair.motion.imu_extrinsic.as_ref()),
            },
            quality: None,
        }
    }
}

fn extrinsic_source(info: Option<&ExtrinsicInfo>) -> Option<String> {
    info.map(|info| info.source.as_str().to_string())
}
