//! The motion and transform samples decoded from a log, and `Decoded`, what
//! the decode stage hands the pairing stage.

use nalgebra::{Isometry3, UnitQuaternion, Vector3};

use super::scan::{Scan, StampNs};

/// One `sensor_msgs/Imu` sample.
#[derive(Debug, Clone, PartialEq)]
pub struct ImuSample {
    pub stamp_ns: StampNs,
    pub frame_id: String,
    /// Gyro rate in the IMU frame, rad/s.
    pub angular_velocity_radps: Vector3<f64>,
    /// Specific force in the IMU frame (gravity included), m/s^2.
    pub linear_acceleration_mps2: Vector3<f64>,
    /// Orientation estimate, when the driver provides one (`covariance[0] != -1`).
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
