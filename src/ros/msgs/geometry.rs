//! `geometry_msgs`: vectors, rotations, poses, twists and transforms, plain
//! and stamped.

use super::{Header, RosMessage};
use crate::ros::DecodeError;
use crate::ros::cdr::{WireRead, WireWrite};

/// `geometry_msgs/Vector3` (also used for `geometry_msgs/Point`).
#[derive(Debug, Clone, Copy, Default, PartialEq)]
pub struct Vector3 {
    pub x: f64,
    pub y: f64,
    pub z: f64,
}

impl Vector3 {
    pub fn new(x: f64, y: f64, z: f64) -> Self {
        Self { x, y, z }
    }

    pub(super) fn read<'a, R: WireRead<'a>>(r: &mut R) -> Result<Self, DecodeError> {
        Ok(Self {
            x: r.read_f64()?,
            y: r.read_f64()?,
            z: r.read_f64()?,
        })
    }

    pub(super) fn write<W: WireWrite>(&self, w: &mut W) {
        w.write_f64_array(&[self.x, self.y, self.z]);
    }

    pub fn to_nalgebra(self) -> nalgebra::Vector3<f64> {
        nalgebra::Vector3::new(self.x, self.y, self.z)
    }
}

/// `geometry_msgs/Quaternion` (x, y, z, w order on the wire).
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Quaternion {
    pub x: f64,
    pub y: f64,
    pub z: f64,
    pub w: f64,
}

impl Default for Quaternion {
    /// Identity rotation (the ROS 2 IDL default).
    fn default() -> Self {
        Self::IDENTITY
    }
}

impl From<&nalgebra::Vector3<f64>> for Vector3 {
    fn from(v: &nalgebra::Vector3<f64>) -> Self {
        Self::new(v.x, v.y, v.z)
    }
}

impl From<&nalgebra::UnitQuaternion<f64>> for Quaternion {
    fn from(q: &nalgebra::UnitQuaternion<f64>) -> Self {
        Self {
            x: q.i,
            y: q.j,
            z: q.k,
            w: q.w,
        }
    }
}

impl Quaternion {
    pub const IDENTITY: Self = Self {
        x: 0.0,
        y: 0.0,
        z: 0.0,
        w: 1.0,
    };

    pub(super) fn read<'a, R: WireRead<'a>>(r: &mut R) -> Result<Self, DecodeError> {
        Ok(Self {
            x: r.read_f64()?,
            y: r.read_f64()?,
            z: r.read_f64()?,
            w: r.read_f64()?,
        })
    }

    pub(super) fn write<W: WireWrite>(&self, w: &mut W) {
        w.write_f64_array(&[self.x, self.y, self.z, self.w]);
    }

    /// The normalised rotation, or `None` for a zero / non-finite quaternion.
    pub fn to_unit(self) -> Option<nalgebra::UnitQuaternion<f64>> {
        let q = nalgebra::Quaternion::new(self.w, self.x, self.y, self.z);
        let norm = q.norm();
        if !norm.is_finite() || norm < 1e-12 {
            return None;
        }
        Some(nalgebra::UnitQuaternion::from_quaternion(q))
    }
}

/// `geometry_msgs/Pose`.
#[derive(Debug, Clone, Copy, Default, PartialEq)]
pub struct Pose {
    pub position: Vector3,
    pub orientation: Quaternion,
}

/// `geometry_msgs/Twist`.
#[derive(Debug, Clone, Copy, Default, PartialEq)]
pub struct Twist {
    pub linear: Vector3,
    pub angular: Vector3,
}

impl Twist {
    pub(super) fn read<'a, R: WireRead<'a>>(r: &mut R) -> Result<Self, DecodeError> {
        Ok(Self {
            linear: Vector3::read(r)?,
            angular: Vector3::read(r)?,
        })
    }

    pub(super) fn write<W: WireWrite>(&self, w: &mut W) {
        self.linear.write(w);
        self.angular.write(w);
    }
}

/// `geometry_msgs/Transform`.
#[derive(Debug, Clone, Copy, Default, PartialEq)]
pub struct Transform {
    pub translation: Vector3,
    pub rotation: Quaternion,
}

/// `geometry_msgs/TwistStamped`.
#[derive(Debug, Clone, Default, PartialEq)]
pub struct TwistStamped {
    pub header: Header,
    pub twist: Twist,
}

impl<'a> RosMessage<'a> for TwistStamped {
    fn read<R: WireRead<'a>>(r: &mut R) -> Result<Self, DecodeError> {
        Ok(Self {
            header: Header::read(r)?,
            twist: Twist::read(r)?,
        })
    }

    fn write<W: WireWrite>(&self, w: &mut W) {
        self.header.write(w);
        self.twist.write(w);
    }
}
wire_entry_points!(TwistStamped);

/// `geometry_msgs/PoseWithCovariance`.
#[derive(Debug, Clone, PartialEq)]
pub struct PoseWithCovariance {
    pub pose: Pose,
    pub covariance: [f64; 36],
}

/// `geometry_msgs/TwistWithCovariance`.
#[derive(Debug, Clone, PartialEq)]
pub struct TwistWithCovariance {
    pub twist: Twist,
    pub covariance: [f64; 36],
}

/// `geometry_msgs/TransformStamped`.
#[derive(Debug, Clone, Default, PartialEq)]
pub struct TransformStamped {
    pub header: Header,
    pub child_frame_id: String,
    pub transform: Transform,
}

impl<'a> RosMessage<'a> for TransformStamped {
    fn read<R: WireRead<'a>>(r: &mut R) -> Result<Self, DecodeError> {
        Ok(Self {
            header: Header::read(r)?,
            child_frame_id: r.read_str()?.to_owned(),
            transform: Transform {
                translation: Vector3::read(r)?,
                rotation: Quaternion::read(r)?,
            },
        })
    }

    fn write<W: WireWrite>(&self, w: &mut W) {
        self.header.write(w);
        w.write_str(&self.child_frame_id);
        self.transform.translation.write(w);
        self.transform.rotation.write(w);
    }
}
wire_entry_points!(TransformStamped);
