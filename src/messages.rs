//! Plain typed structs decoded from input messages: what the pipeline stages
//! pass to each other. No I/O and no encoding details live here; the decoders
//! in [`crate::decode`] fill them, the pairing stage consumes them.

use nalgebra::{Isometry3, UnitQuaternion, Vector3};

pub use crate::engine::layout::ScanLayout;

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
}

impl Scan {
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

/// One `sensor_msgs/Imu` sample.
#[derive(Debug, Clone, PartialEq)]
pub struct ImuSample {
    pub stamp_ns: StampNs,
    pub frame_id: String,
    /// Gyro rate in the IMU frame, rad/s.
    pub angular_velocity_radps: Vector3<f64>,
    /// Specific force in the IMU frame (gravity included), m/s^2.
    pub linear_acceleration_mps2: Vector3<f64>,
    /// Orientation estimate, when the driver provides one (covariance[0] != -1).
    pub orientation: Option<UnitQuaternion<f64>>,
}

/// Where a velocity sample came from.
#[derive(Debug, Clone, Copy, PartialEq, Eq, serde::Serialize)]
#[serde(rename_all = "snake_case")]
pub enum VelocitySourceKind {
    TwistStamped,
    Odometry,
}

/// One body velocity sample from `geometry_msgs/TwistStamped` or `nav_msgs/Odometry`.
#[derive(Debug, Clone, PartialEq)]
pub struct VelocitySample {
    pub stamp_ns: StampNs,
    /// Frame the twist is expressed in: the TwistStamped header frame, or the
    /// Odometry `child_frame_id` (ROS convention), falling back to its header frame.
    pub frame_id: String,
    /// Linear velocity of `frame_id`'s origin, in `frame_id`, m/s.
    pub linear_mps: Vector3<f64>,
    /// Angular velocity, in `frame_id`, rad/s.
    pub angular_radps: Vector3<f64>,
    pub source: VelocitySourceKind,
}

/// One transform of a `tf2_msgs/TFMessage`: the pose of `child_frame` in `parent_frame`
/// (maps child coordinates into parent coordinates).
#[derive(Debug, Clone, PartialEq)]
pub struct FrameTransform {
    pub stamp_ns: StampNs,
    pub parent_frame: String,
    pub child_frame: String,
    pub parent_from_child: Isometry3<f64>,
}

/// A decoded input message of one of the kinds the pipeline uses.
// Scans are the common message (one per cloud, ~10 Hz) and move by value
// once; boxing them would only add an allocation per scan.
#[allow(clippy::large_enum_variant)]
#[derive(Debug, Clone, PartialEq)]
pub enum Decoded {
    Scan(Scan),
    Imu(ImuSample),
    Velocity(VelocitySample),
    /// Transforms of one TFMessage; `is_static` when it came from `/tf_static`.
    Transforms {
        transforms: Vec<FrameTransform>,
        is_static: bool,
    },
}
