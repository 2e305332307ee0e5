//! The ground truth a synthetic drive carries, defined once: the `/truth/*`
//! topic names and the `/truth/points` point layout, with its encoder (used by
//! `looming synth`) and its decoder (used by `looming eval`).
//!
//! `/truth/points` is a `sensor_msgs/PointCloud2` with one point per
//! `/lidar/points` point, in the same order (definitions in
//! docs/ground-truth.md). It has no x, y, z: the noise-free point is `range`
//! along the measured point's direction, and leaving them out keeps the sample
//! logs small.

use crate::model::StampNs;
use crate::ros::msgs::{PointCloud2, PointField, datatype};

/// Per-point truth, one cloud per scan.
pub const POINTS_TOPIC: &str = "/truth/points";
/// Per-scan truth (JSON, `looming.TruthScan`).
pub const SCAN_TOPIC: &str = "/truth/scan";
/// Planted near-miss windows (JSON, `looming.TruthEvent`).
pub const EVENTS_TOPIC: &str = "/truth/events";

/// The per-point truth topic of a LiDAR: [`POINTS_TOPIC`] on a drive with one
/// LiDAR (`None`), `/truth/<sensor>/points` on a drive with several, `sensor`
/// being the LiDAR's name ([`crate::topics::sensor_name`] of its topic: `lidar_roof`, `lidar_left`, ...).
pub fn points_topic(sensor: Option<&str>) -> String {
    sensor.map_or_else(|| POINTS_TOPIC.into(), |s| format!("/truth/{s}/points"))
}

/// The per-scan truth topic of a LiDAR: [`SCAN_TOPIC`] on a drive with one
/// LiDAR (`None`), `/truth/<sensor>/scan` on a drive with several.
pub fn scan_topic(sensor: Option<&str>) -> String {
    sensor.map_or_else(|| SCAN_TOPIC.into(), |s| format!("/truth/{s}/scan"))
}

/// Bytes per `/truth/points` point.
pub const POINT_STEP: u32 = 28;

/// `surface` of a `/truth/points` entry for a pixel without a return.
pub const NO_RETURN_SURFACE: u8 = 255;

/// Field names of a `/truth/points` point.
mod field {
    pub const RANGE: &str = "range";
    pub const POINT_LOOMING: &str = "point_looming";
    pub const RAY_LOOMING: &str = "ray_looming";
    pub const OWN_MOTION_LOOMING: &str = "own_motion_looming";
    pub const INCIDENCE_COS: &str = "incidence_cos";
    pub const OBJECT_ID: &str = "object_id";
    pub const SURFACE: &str = "surface";
    pub const MOVING: &str = "moving";
}

/// Byte offsets of the fields in a written point (two bytes of padding end it).
const RANGE_OFFSET: usize = 0;
const POINT_LOOMING_OFFSET: usize = 4;
const RAY_LOOMING_OFFSET: usize = 8;
const OWN_MOTION_LOOMING_OFFSET: usize = 12;
const INCIDENCE_COS_OFFSET: usize = 16;
const OBJECT_ID_OFFSET: usize = 20;
const SURFACE_OFFSET: usize = 24;
const MOVING_OFFSET: usize = 25;

/// The written layout: name, offset, `sensor_msgs/PointField` datatype.
const LAYOUT: [(&str, usize, u8); 8] = [
    (field::RANGE, RANGE_OFFSET, datatype::FLOAT32),
    (
        field::POINT_LOOMING,
        POINT_LOOMING_OFFSET,
        datatype::FLOAT32,
    ),
    (field::RAY_LOOMING, RAY_LOOMING_OFFSET, datatype::FLOAT32),
    (
        field::OWN_MOTION_LOOMING,
        OWN_MOTION_LOOMING_OFFSET,
        datatype::FLOAT32,
    ),
    (
        field::INCIDENCE_COS,
        INCIDENCE_COS_OFFSET,
        datatype::FLOAT32,
    ),
    (field::OBJECT_ID, OBJECT_ID_OFFSET, datatype::UINT32),
    (field::SURFACE, SURFACE_OFFSET, datatype::UINT8),
    (field::MOVING, MOVING_OFFSET, datatype::UINT8),
];

/// The `fields` of a `/truth/points` cloud.
pub fn point_fields() -> Vec<PointField> {
    LAYOUT
        .iter()
        .map(|&(name, offset, datatype)| PointField::new(name, offset as u32, datatype))
        .collect()
}

/// One `/truth/points` point as written.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct TruthPoint {
    pub range_m: f32,
    pub point_looming_per_s: f32,
    pub ray_looming_per_s: f32,
    pub own_motion_looming_per_s: f32,
    pub incidence_cos: f32,
    /// 0 for the static world, the actor id otherwise.
    pub object_id: u32,
    pub surface: u8,
    pub moving: bool,
}

impl TruthPoint {
    /// A pixel without a return: NaN values, object 0, surface 255.
    pub const NO_RETURN: Self = Self {
        range_m: f32::NAN,
        point_looming_per_s: f32::NAN,
        ray_looming_per_s: f32::NAN,
        own_motion_looming_per_s: f32::NAN,
        incidence_cos: f32::NAN,
        object_id: 0,
        surface: NO_RETURN_SURFACE,
        moving: false,
    };

    /// The point's bytes (little endian), [`POINT_STEP`] of them.
    pub fn encode(&self) -> [u8; POINT_STEP as usize] {
        let mut out = [0u8; POINT_STEP as usize];
        let mut put = |offset: usize, bytes: &[u8]| {
            out[offset..offset + bytes.len()].copy_from_slice(bytes);
        };
        put(RANGE_OFFSET, &self.range_m.to_le_bytes());
        put(
            POINT_LOOMING_OFFSET,
            &self.point_looming_per_s.to_le_bytes(),
        );
        put(RAY_LOOMING_OFFSET, &self.ray_looming_per_s.to_le_bytes());
        put(
            OWN_MOTION_LOOMING_OFFSET,
            &self.own_motion_looming_per_s.to_le_bytes(),
        );
        put(INCIDENCE_COS_OFFSET, &self.incidence_cos.to_le_bytes());
        put(OBJECT_ID_OFFSET, &self.object_id.to_le_bytes());
        put(SURFACE_OFFSET, &[self.surface]);
        put(MOVING_OFFSET, &[u8::from(self.moving)]);
        out
    }
}

/// What `eval` reads of a `/truth/points` point (see docs/ground-truth.md).
#[derive(Debug, Clone, Copy, Default)]
pub struct PointTruth {
    pub point_looming: f32,
    pub ray_looming: f32,
    pub own_motion_looming: f32,
    pub incidence_cos: f32,
    pub surface: u8,
    pub moving: bool,
}

/// Decode a `/truth/points` cloud: its stamp and its points. The fields are
/// found by name, so any cloud that carries them decodes.
pub fn decode_points(payload: &[u8]) -> Result<(StampNs, Vec<PointTruth>), String> {
    let cloud = PointCloud2::decode_cdr(payload).map_err(|e| e.to_string())?;
    let field = |name: &str| {
        cloud
            .field_offset(name)
            .ok_or_else(|| format!("/truth/points has no `{name}` field"))
    };
    let (pl, rl, om, ic, sf, mv) = (
        field(field::POINT_LOOMING)?,
        field(field::RAY_LOOMING)?,
        field(field::OWN_MOTION_LOOMING)?,
        field(field::INCIDENCE_COS)?,
        field(field::SURFACE)?,
        field(field::MOVING)?,
    );
    let step = cloud.point_step as usize;
    let count = (cloud.width as usize) * (cloud.height as usize);
    if step == 0
        || cloud.data.len() < count * step
        || [pl, rl, om, ic].iter().any(|o| o + 4 > step)
        || sf >= step
        || mv >= step
    {
        return Err("/truth/points layout does not fit its data".into());
    }
    let f32_at = |base: usize, offset: usize| {
        f32::from_le_bytes(
            cloud.data[base + offset..base + offset + 4]
                .try_into()
                .expect("4 bytes"),
        )
    };
    let points = (0..count)
        .map(|i| {
            let base = i * step;
            PointTruth {
                point_looming: f32_at(base, pl),
                ray_looming: f32_at(base, rl),
                own_motion_looming: f32_at(base, om),
                incidence_cos: f32_at(base, ic),
                surface: cloud.data[base + sf],
                moving: cloud.data[base + mv] != 0,
            }
        })
        .collect();
    Ok((cloud.header.stamp.to_ns(), points))
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::ros::msgs::Header;

    fn cloud_of(points: &[TruthPoint]) -> Vec<u8> {
        let data: Vec<u8> = points.iter().flat_map(|p| p.encode()).collect();
        PointCloud2 {
            header: Header::new(1_700_000_000_000_000_123, "lidar"),
            height: 1,
            width: points.len() as u32,
            fields: point_fields(),
            is_bigendian: false,
            point_step: POINT_STEP,
            row_step: points.len() as u32 * POINT_STEP,
            data: data.into(),
            is_dense: true,
        }
        .encode_cdr(false)
    }

    #[test]
    fn a_point_round_trips_through_the_encoder_and_the_decoder() {
        let point = TruthPoint {
            range_m: 12.5,
            point_looming_per_s: 0.25,
            ray_looming_per_s: -0.125,
            own_motion_looming_per_s: 0.0625,
            incidence_cos: 0.75,
            object_id: 7,
            surface: 2,
            moving: true,
        };
        let (stamp, decoded) = decode_points(&cloud_of(&[point, TruthPoint::NO_RETURN])).unwrap();
        assert_eq!(stamp, 1_700_000_000_000_000_123);
        let [got, empty] = decoded.as_slice() else {
            panic!("two points expected, got {}", decoded.len());
        };
        assert_eq!(got.point_looming, point.point_looming_per_s);
        assert_eq!(got.ray_looming, point.ray_looming_per_s);
        assert_eq!(got.own_motion_looming, point.own_motion_looming_per_s);
        assert_eq!(got.incidence_cos, point.incidence_cos);
        assert_eq!(got.surface, point.surface);
        assert!(got.moving);
        assert!(empty.point_looming.is_nan() && empty.incidence_cos.is_nan());
        assert_eq!(empty.surface, NO_RETURN_SURFACE);
        assert!(!empty.moving);
        // The range and the object id sit where the layout says.
        let bytes = point.encode();
        assert_eq!(bytes[RANGE_OFFSET..RANGE_OFFSET + 4], 12.5f32.to_le_bytes());
        assert_eq!(
            bytes[OBJECT_ID_OFFSET..OBJECT_ID_OFFSET + 4],
            7u32.to_le_bytes()
        );
    }

    #[test]
    fn truth_topics_of_a_sensor() {
        assert_eq!(points_topic(None), POINTS_TOPIC);
        assert_eq!(scan_topic(None), SCAN_TOPIC);
        let sensor = crate::topics::sensor_name("/lidar_left/points");
        assert_eq!(sensor, "lidar_left");
        assert_eq!(points_topic(Some(&sensor)), "/truth/lidar_left/points");
        assert_eq!(scan_topic(Some(&sensor)), "/truth/lidar_left/scan");
    }

    #[test]
    fn a_cloud_without_a_truth_field_is_refused_with_its_name() {
        let bytes = cloud_of(&[TruthPoint::NO_RETURN]);
        let mut cloud = PointCloud2::decode_cdr(&bytes).unwrap();
        cloud.fields.retain(|f| f.name != "surface");
        let error = decode_points(&cloud.encode_cdr(false)).unwrap_err();
        assert_eq!(error, "/truth/points has no `surface` field");
    }
}
