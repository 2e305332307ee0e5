//! One LiDAR scan as decoded: the valid points of a cloud with their optional
//! attributes, in the cloud's own frame. The decoders of the `looming` crate fill
//! it, `engine::layout::complete` completes its rings and times.

use nalgebra::Isometry3;

use super::layout::ScanLayout;

/// Nanoseconds since the Unix epoch, from a message header stamp (ROS time).
/// Signed so that differences never underflow.
pub type StampNs = i64;

/// One LiDAR scan: the valid points of a `PointCloud2` or `foxglove.PointCloud`,
/// in the cloud's own frame (metres), with optional per-point attributes.
///
/// Invalid points (NaN / infinite coordinates, zero range) are dropped and
/// counted in `skipped_invalid_points`; `source_index` maps every kept point back
/// to its index in the input cloud, so per-point outputs can be written back.
#[derive(Debug, Clone, PartialEq)]
pub struct Scan {
    /// Header stamp of the cloud.
    pub stamp_ns: StampNs,
    /// Header frame id of the cloud.
    pub frame_id: String,
    /// Pose of the cloud's origin in `frame_id` (identity for `PointCloud2`;
    /// the `pose` field of a `foxglove.PointCloud`). Points are kept un-posed.
    pub sensor_pose: Isometry3<f64>,
    /// x, y, z of each kept point in the cloud's origin frame, metres.
    pub points_m: Vec<[f32; 3]>,
    /// `intensity` (or `reflectivity`) field, when present.
    pub intensity: Option<Vec<f32>>,
    /// Ring (beam index) of each kept point: the cloud's ring field when it
    /// has one (`ring`, `channel`, `laser_id`, ...), else what
    /// [`crate::engine::layout::complete`] recovered; `layout.rings` says which.
    pub ring: Option<Vec<u16>>,
    /// Per-point time relative to `stamp_ns`, seconds (may be negative for clouds
    /// stamped at the end of the sweep): the cloud's time field, else what
    /// [`crate::engine::layout::complete`] derived from the azimuth;
    /// `layout.times` says which.
    pub time_offset_s: Option<Vec<f32>>,
    /// Index of each kept point in the input cloud (row-major).
    pub source_index: Vec<u32>,
    /// `width * height` of the input cloud.
    pub input_point_count: u32,
    /// Points dropped because a coordinate was NaN / infinite or the range was zero.
    pub skipped_invalid_points: u32,
    /// `(rows, cols)` of an organized cloud (`PointCloud2` with `height > 1`):
    /// point `i` sits in row `source_index[i] / cols`.
    pub organized: Option<(u32, u32)>,
    /// Where `ring` and `time_offset_s` come from. The decoder names the
    /// fields it read; [`crate::engine::layout::complete`] fills the rest.
    pub layout: ScanLayout,
    /// The sensor of each kept point, in a cloud that merges several
    /// sensors and says which point is whose (a `sensor_id` field);
    /// `None` for a cloud of one sensor.
    pub sensor_ids: Option<SensorIds>,
}

/// The per-point sensor field of a merged cloud: its name and each kept
/// point's value (`pairing::split` makes a scan per value).
#[derive(Debug, Clone, PartialEq, Eq)]
pub struct SensorIds {
    /// The field's name in the cloud (`sensor_id`, `lidar_id`, ...).
    pub field: String,
    pub ids: Vec<u32>,
}

impl Scan {
    /// A scan without points (a cloud with none valid, or none at all).
    pub fn empty(stamp_ns: StampNs, frame_id: String, sensor_pose: Isometry3<f64>) -> Self {
        Self {
            stamp_ns,
            frame_id,
            sensor_pose,
            points_m: Vec::new(),
            intensity: None,
            ring: None,
            time_offset_s: None,
            source_index: Vec::new(),
            input_point_count: 0,
            skipped_invalid_points: 0,
            organized: None,
            layout: ScanLayout::default(),
            sensor_ids: None,
        }
    }

    /// Number of valid points kept.
    pub fn len(&self) -> usize {
        self.points_m.len()
    }

    /// True when no valid point was kept.
    pub fn is_empty(&self) -> bool {
        self.points_m.is_empty()
    }

    /// Earliest and latest point time (absolute, ns). Without per-point times
    /// both are the header stamp.
    pub fn time_span_ns(&self) -> (StampNs, StampNs) {
        let Some(offsets) = &self.time_offset_s else {
            return (self.stamp_ns, self.stamp_ns);
        };
        let (mut lo, mut hi) = (f32::INFINITY, f32::NEG_INFINITY);
        for &t in offsets {
            lo = lo.min(t);
            hi = hi.max(t);
        }
        if !lo.is_finite() {
            return (self.stamp_ns, self.stamp_ns);
        }
        let to_ns = |s: f32| self.stamp_ns + (f64::from(s) * 1e9).round() as i64;
        (to_ns(lo), to_ns(hi))
    }
}
