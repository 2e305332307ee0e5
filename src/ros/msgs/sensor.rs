//! `sensor_msgs`: point clouds (with a builder for fixtures) and IMU samples.

use std::borrow::Cow;

use super::{Header, Quaternion, RosMessage, Vector3};
use crate::ros::DecodeError;
use crate::ros::cdr::{WireRead, WireWrite};

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
    /// Byte offset within a point of the field named `name`.
    pub fn field_offset(&self, name: &str) -> Option<usize> {
        self.fields
            .iter()
            .find(|f| f.name == name)
            .map(|f| f.offset as usize)
    }

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
