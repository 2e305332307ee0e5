//! Raw ROS message structs, field for field as in the `.msg` definitions, with
//! decoders for ROS 2 CDR and ROS 1 and the matching encoders.
//!
//! Codecs are written once against [`WireRead`] / [`WireWrite`]; the inherent
//! `decode_cdr` / `decode_ros1` / `encode_cdr` / `encode_ros1` methods wrap them.

use std::borrow::Cow;

use super::DecodeError;
use super::cdr::{CdrReader, CdrWriter, Ros1Reader, Ros1Writer, WireRead, WireWrite};

/// A message with one codec shared by both wire formats.
pub trait RosMessage<'a>: Sized {
    fn read<R: WireRead<'a>>(r: &mut R) -> Result<Self, DecodeError>;
    fn write<W: WireWrite>(&self, w: &mut W);
}

/// Adds the format-specific entry points to a [`RosMessage`].
macro_rules! wire_entry_points {
    ($ty:ident $(<$lt:lifetime>)?) => {
        impl<'a> $ty $(<$lt>)? {
            /// Decodes a ROS 2 CDR payload (with its encapsulation header).
            pub fn decode_cdr(payload: &'a [u8]) -> Result<Self, DecodeError> {
                let mut r = CdrReader::new(payload)?;
                <Self as RosMessage<'a>>::read(&mut r)
            }

            /// Decodes a ROS 1 payload.
            pub fn decode_ros1(payload: &'a [u8]) -> Result<Self, DecodeError> {
                let mut r = Ros1Reader::new(payload);
                <Self as RosMessage<'a>>::read(&mut r)
            }

            /// Encodes as ROS 2 plain CDR with the encapsulation header.
            pub fn encode_cdr(&self, big_endian: bool) -> Vec<u8> {
                let mut w = CdrWriter::new(big_endian);
                <Self as RosMessage<'a>>::write(self, &mut w);
                w.into_bytes()
            }

            /// Encodes in ROS 1 serialization.
            pub fn encode_ros1(&self) -> Vec<u8> {
                let mut w = Ros1Writer::new();
                <Self as RosMessage<'a>>::write(self, &mut w);
                w.into_bytes()
            }
        }
    };
}

/// `builtin_interfaces/Time` (ROS 2: `int32 sec`, `uint32 nanosec`) or ROS 1
/// `time` (`uint32 secs`, `uint32 nsecs`). Seconds are widened to i64 so both fit.
#[derive(Debug, Clone, Copy, Default, PartialEq, Eq)]
pub struct Time {
    pub sec: i64,
    pub nanosec: u32,
}

impl Time {
    /// Splits nanoseconds since the epoch into seconds and nanoseconds.
    pub fn from_ns(stamp_ns: i64) -> Self {
        Self {
            sec: stamp_ns.div_euclid(1_000_000_000),
            nanosec: stamp_ns.rem_euclid(1_000_000_000) as u32,
        }
    }

    /// `sec * 1e9 + nanosec` (saturating; cannot overflow for wire values).
    pub fn to_ns(self) -> i64 {
        self.sec
            .saturating_mul(1_000_000_000)
            .saturating_add(i64::from(self.nanosec))
    }
}

/// `std_msgs/Header`. `seq` exists only in ROS 1 (0 when decoded from CDR,
/// ignored when encoding CDR).
#[derive(Debug, Clone, Default, PartialEq, Eq)]
pub struct Header {
    pub seq: u32,
    pub stamp: Time,
    pub frame_id: String,
}

impl Header {
    pub fn new(stamp_ns: i64, frame_id: &str) -> Self {
        Self {
            seq: 0,
            stamp: Time::from_ns(stamp_ns),
            frame_id: frame_id.to_owned(),
        }
    }
}

impl<'a> RosMessage<'a> for Header {
    fn read<R: WireRead<'a>>(r: &mut R) -> Result<Self, DecodeError> {
        let (seq, stamp) = if R::IS_ROS1 {
            let seq = r.read_u32()?;
            let sec = i64::from(r.read_u32()?);
            let nanosec = r.read_u32()?;
            (seq, Time { sec, nanosec })
        } else {
            let sec = i64::from(r.read_i32()?);
            let nanosec = r.read_u32()?;
            (0, Time { sec, nanosec })
        };
        let frame_id = r.read_str()?.to_owned();
        Ok(Self {
            seq,
            stamp,
            frame_id,
        })
    }

    fn write<W: WireWrite>(&self, w: &mut W) {
        // Out-of-range seconds wrap: the encoders build fixtures, and ROS itself
        // cannot represent such stamps either.
        if W::IS_ROS1 {
            w.write_u32(self.seq);
            w.write_u32(self.stamp.sec as u32);
        } else {
            w.write_i32(self.stamp.sec as i32);
        }
        w.write_u32(self.stamp.nanosec);
        w.write_str(&self.frame_id);
    }
}
wire_entry_points!(Header);

/// Minimum encoded size of a Header in either format (for sequence checks).
const MIN_HEADER_BYTES: usize = 12;

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

    fn read<'a, R: WireRead<'a>>(r: &mut R) -> Result<Self, DecodeError> {
        Ok(Self {
            x: r.read_f64()?,
            y: r.read_f64()?,
            z: r.read_f64()?,
        })
    }

    fn write<W: WireWrite>(&self, w: &mut W) {
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

    fn read<'a, R: WireRead<'a>>(r: &mut R) -> Result<Self, DecodeError> {
        Ok(Self {
            x: r.read_f64()?,
            y: r.read_f64()?,
            z: r.read_f64()?,
            w: r.read_f64()?,
        })
    }

    fn write<W: WireWrite>(&self, w: &mut W) {
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
    fn read<'a, R: WireRead<'a>>(r: &mut R) -> Result<Self, DecodeError> {
        Ok(Self {
            linear: Vector3::read(r)?,
            angular: Vector3::read(r)?,
        })
    }

    fn write<W: WireWrite>(&self, w: &mut W) {
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

/// `sensor_msgs/PointField` datatype codes.
pub mod datatype {
    pub const INT8: u8 = 1;
    pub const UINT8: u8 = 2;
    pub const INT16: u8 = 3;
    pub const UINT16: u8 = 4;
    pub const INT32: u8 = 5;
    pub const UINT32: u8 = 6;
    pub const FLOAT32: u8 = 7;
    pub const FLOAT64: u8 = 8;
}

/// `sensor_msgs/PointField`.
#[derive(Debug, Clone, PartialEq, Eq)]
pub struct PointField {
    pub name: String,
    pub offset: u32,
    /// One of [`datatype`].
    pub datatype: u8,
    pub count: u32,
}

impl PointField {
    pub fn new(name: &str, offset: u32, datatype: u8) -> Self {
        Self {
            name: name.to_owned(),
            offset,
            datatype,
            count: 1,
        }
    }
}

impl<'a> RosMessage<'a> for PointField {
    fn read<R: WireRead<'a>>(r: &mut R) -> Result<Self, DecodeError> {
        Ok(Self {
            name: r.read_str()?.to_owned(),
            offset: r.read_u32()?,
            datatype: r.read_u8()?,
            count: r.read_u32()?,
        })
    }

    fn write<W: WireWrite>(&self, w: &mut W) {
        w.write_str(&self.name);
        w.write_u32(self.offset);
        w.write_u8(self.datatype);
        w.write_u32(self.count);
    }
}

/// Lower bound of an encoded PointField (ROS 1: 4 + 4 + 1 + 4).
const MIN_POINT_FIELD_BYTES: usize = 13;

/// `sensor_msgs/PointCloud2`. `data` borrows from the payload when decoded.
#[derive(Debug, Clone, PartialEq)]
pub struct PointCloud2<'a> {
    pub header: Header,
    pub height: u32,
    pub width: u32,
    pub fields: Vec<PointField>,
    pub is_bigendian: bool,
    pub point_step: u32,
    pub row_step: u32,
    pub data: Cow<'a, [u8]>,
    pub is_dense: bool,
}

impl<'a> RosMessage<'a> for PointCloud2<'a> {
    fn read<R: WireRead<'a>>(r: &mut R) -> Result<Self, DecodeError> {
        let header = Header::read(r)?;
        let height = r.read_u32()?;
        let width = r.read_u32()?;
        let n_fields = r.read_seq_len(MIN_POINT_FIELD_BYTES)?;
        let mut fields = Vec::with_capacity(n_fields);
        for _ in 0..n_fields {
            fields.push(PointField::read(r)?);
        }
        let is_bigendian = r.read_bool()?;
        let point_step = r.read_u32()?;
        let row_step = r.read_u32()?;
        let n_data = r.read_seq_len(1)?;
        let data = Cow::Borrowed(r.read_bytes(n_data, "PointCloud2 data")?);
        let is_dense = r.read_bool()?;
        Ok(Self {
            header,
            height,
            width,
            fields,
            is_bigendian,
            point_step,
            row_step,
            data,
            is_dense,
        })
    }

    fn write<W: WireWrite>(&self, w: &mut W) {
        self.header.write(w);
        w.write_u32(self.height);
        w.write_u32(self.width);
        w.write_seq_len(self.fields.len());
        for f in &self.fields {
            f.write(w);
        }
        w.write_bool(self.is_bigendian);
        w.write_u32(self.point_step);
        w.write_u32(self.row_step);
        w.write_seq_len(self.data.len());
        w.write_bytes(&self.data);
        w.write_bool(self.is_dense);
    }
}
wire_entry_points!(PointCloud2<'a>);

impl PointCloud2<'_> {
    /// Detaches the cloud from the payload it was decoded from.
    pub fn into_owned(self) -> PointCloud2<'static> {
        PointCloud2 {
            data: Cow::Owned(self.data.into_owned()),
            header: self.header,
            height: self.height,
            width: self.width,
            fields: self.fields,
            is_bigendian: self.is_bigendian,
            point_step: self.point_step,
            row_step: self.row_step,
            is_dense: self.is_dense,
        }
    }
}

/// Builds an organised-as-one-row little-endian cloud laid out like the
/// Velodyne driver: `x y z` FLOAT32 at 0/4/8, then `intensity` FLOAT32,
/// `ring` UINT16 and `time` FLOAT32 (seconds relative to the stamp), each
/// present only when given, at natural offsets. Optional slices must have the
/// same length as `points` (extra entries are ignored, missing ones are 0).
/// `is_dense` is set when every point is finite and non-zero.
///
/// # Panics
/// If `points` has more than `u32::MAX` entries (not representable in ROS).
pub fn pointcloud2_from_points(
    stamp_ns: i64,
    frame_id: &str,
    points: &[[f32; 3]],
    intensity: Option<&[f32]>,
    ring: Option<&[u16]>,
    time_s: Option<&[f32]>,
) -> PointCloud2<'static> {
    let mut fields = vec![
        PointField::new("x", 0, datatype::FLOAT32),
        PointField::new("y", 4, datatype::FLOAT32),
        PointField::new("z", 8, datatype::FLOAT32),
    ];
    let mut step = 12u32;
    let mut add =
        |fields: &mut Vec<PointField>, name: &str, datatype: u8, size: u32, align: u32| {
            step = step.div_ceil(align) * align;
            let offset = step;
            fields.push(PointField::new(name, offset, datatype));
            step += size;
            offset as usize
        };
    let intensity_off =
        intensity.map(|v| (add(&mut fields, "intensity", datatype::FLOAT32, 4, 4), v));
    let ring_off = ring.map(|v| (add(&mut fields, "ring", datatype::UINT16, 2, 2), v));
    // Time stays 4-byte aligned after the u16 ring, as in the Velodyne driver.
    let time_off = time_s.map(|v| (add(&mut fields, "time", datatype::FLOAT32, 4, 4), v));
    // Pad the point to a multiple of 4 bytes.
    let point_step = step.div_ceil(4) * 4;

    let ps = point_step as usize;
    let mut data = vec![0u8; points.len() * ps];
    for (i, (p, out)) in points.iter().zip(data.chunks_exact_mut(ps)).enumerate() {
        for (k, c) in p.iter().enumerate() {
            out[4 * k..4 * k + 4].copy_from_slice(&c.to_le_bytes());
        }
        if let Some((off, v)) = intensity_off {
            let x = v.get(i).copied().unwrap_or(0.0);
            out[off..off + 4].copy_from_slice(&x.to_le_bytes());
        }
        if let Some((off, v)) = ring_off {
            let x = v.get(i).copied().unwrap_or(0);
            out[off..off + 2].copy_from_slice(&x.to_le_bytes());
        }
        if let Some((off, v)) = time_off {
            let x = v.get(i).copied().unwrap_or(0.0);
            out[off..off + 4].copy_from_slice(&x.to_le_bytes());
        }
    }
    let width = u32::try_from(points.len()).expect("more than u32::MAX points");
    PointCloud2 {
        header: Header::new(stamp_ns, frame_id),
        height: 1,
        width,
        fields,
        is_bigendian: false,
        point_step,
        row_step: point_step * width,
        data: Cow::Owned(data),
        is_dense: points
            .iter()
            .all(|p| p.iter().all(|c| c.is_finite()) && p.iter().any(|&c| c != 0.0)),
    }
}

/// `sensor_msgs/Imu`.
#[derive(Debug, Clone, PartialEq)]
pub struct Imu {
    pub header: Header,
    pub orientation: Quaternion,
    pub orientation_covariance: [f64; 9],
    pub angular_velocity: Vector3,
    pub angular_velocity_covariance: [f64; 9],
    pub linear_acceleration: Vector3,
    pub linear_acceleration_covariance: [f64; 9],
}

impl<'a> RosMessage<'a> for Imu {
    fn read<R: WireRead<'a>>(r: &mut R) -> Result<Self, DecodeError> {
        Ok(Self {
            header: Header::read(r)?,
            orientation: Quaternion::read(r)?,
            orientation_covariance: r.read_f64_array()?,
            angular_velocity: Vector3::read(r)?,
            angular_velocity_covariance: r.read_f64_array()?,
            linear_acceleration: Vector3::read(r)?,
            linear_acceleration_covariance: r.read_f64_array()?,
        })
    }

    fn write<W: WireWrite>(&self, w: &mut W) {
        self.header.write(w);
        self.orientation.write(w);
        w.write_f64_array(&self.orientation_covariance);
        self.angular_velocity.write(w);
        w.write_f64_array(&self.angular_velocity_covariance);
        self.linear_acceleration.write(w);
        w.write_f64_array(&self.linear_acceleration_covariance);
    }
}
wire_entry_points!(Imu);

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

/// `nav_msgs/Odometry`.
#[derive(Debug, Clone, PartialEq)]
pub struct Odometry {
    pub header: Header,
    pub child_frame_id: String,
    pub pose: PoseWithCovariance,
    pub twist: TwistWithCovariance,
}

impl<'a> RosMessage<'a> for Odometry {
    fn read<R: WireRead<'a>>(r: &mut R) -> Result<Self, DecodeError> {
        Ok(Self {
            header: Header::read(r)?,
            child_frame_id: r.read_str()?.to_owned(),
            pose: PoseWithCovariance {
                pose: Pose {
                    position: Vector3::read(r)?,
                    orientation: Quaternion::read(r)?,
                },
                covariance: r.read_f64_array()?,
            },
            twist: TwistWithCovariance {
                twist: Twist::read(r)?,
                covariance: r.read_f64_array()?,
            },
        })
    }

    fn write<W: WireWrite>(&self, w: &mut W) {
        self.header.write(w);
        w.write_str(&self.child_frame_id);
        self.pose.pose.position.write(w);
        self.pose.pose.orientation.write(w);
        w.write_f64_array(&self.pose.covariance);
        self.twist.twist.write(w);
        w.write_f64_array(&self.twist.covariance);
    }
}
wire_entry_points!(Odometry);

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

/// Lower bound of an encoded TransformStamped: header, child id length, 7 float64.
const MIN_TRANSFORM_STAMPED_BYTES: usize = MIN_HEADER_BYTES + 4 + 7 * 8;

/// `tf2_msgs/TFMessage` (same layout as ROS 1 `tf/tfMessage`).
#[derive(Debug, Clone, Default, PartialEq)]
pub struct TFMessage {
    pub transforms: Vec<TransformStamped>,
}

impl<'a> RosMessage<'a> for TFMessage {
    fn read<R: WireRead<'a>>(r: &mut R) -> Result<Self, DecodeError> {
        let n = r.read_seq_len(MIN_TRANSFORM_STAMPED_BYTES)?;
        let mut transforms = Vec::with_capacity(n);
        for _ in 0..n {
            transforms.push(TransformStamped::read(r)?);
        }
        Ok(Self { transforms })
    }

    fn write<W: WireWrite>(&self, w: &mut W) {
        w.write_seq_len(self.transforms.len());
        for t in &self.transforms {
            t.write(w);
        }
    }
}
wire_entry_points!(TFMessage);
