//! The fields of a strided point buffer: their numeric types, the validated
//! [`Layout`] of the buffer, and the [`Readers`] resolved once per cloud for
//! the fields a [`Scan`](crate::model::Scan) uses (x, y, z, intensity,
//! ring, time).

use super::time::{TIME_FIELDS, TimeConvention, absolute_convention};
use crate::decode::{SENSOR_FIELDS, SensorField};
use crate::ros::DecodeError;
use crate::ros::msgs::datatype;

/// Numeric type of one point field.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub(super) enum Scalar {
    I8,
    U8,
    I16,
    U16,
    I32,
    U32,
    F32,
    F64,
}

impl Scalar {
    fn size_bytes(self) -> usize {
        match self {
            Scalar::I8 | Scalar::U8 => 1,
            Scalar::I16 | Scalar::U16 => 2,
            Scalar::I32 | Scalar::U32 | Scalar::F32 => 4,
            Scalar::F64 => 8,
        }
    }

    pub(super) fn is_float(self) -> bool {
        matches!(self, Scalar::F32 | Scalar::F64)
    }

    /// `sensor_msgs/PointField` datatype code.
    pub(super) fn from_ros(code: u8) -> Option<Self> {
        Some(match code {
            datatype::INT8 => Scalar::I8,
            datatype::UINT8 => Scalar::U8,
            datatype::INT16 => Scalar::I16,
            datatype::UINT16 => Scalar::U16,
            datatype::INT32 => Scalar::I32,
            datatype::UINT32 => Scalar::U32,
            datatype::FLOAT32 => Scalar::F32,
            datatype::FLOAT64 => Scalar::F64,
            _ => return None,
        })
    }

    /// `foxglove.PackedElementField.NumericType` code (note: differs from ROS).
    pub(super) fn from_foxglove(code: i32) -> Option<Self> {
        Some(match code {
            1 => Scalar::U8,
            2 => Scalar::I8,
            3 => Scalar::U16,
            4 => Scalar::I16,
            5 => Scalar::U32,
            6 => Scalar::I32,
            7 => Scalar::F32,
            8 => Scalar::F64,
            _ => return None,
        })
    }
}

/// A field as declared by the message, before validation.
pub(super) struct FieldDesc<'f> {
    pub(super) name: &'f str,
    pub(super) offset: u32,
    /// The numeric type, or the unknown raw code (only an error if the field is used).
    pub(super) scalar: Result<Scalar, i64>,
}

/// Reads one field from one point's bytes; resolved once per cloud.
#[derive(Debug, Clone, Copy)]
pub(super) struct FieldReader {
    pub(super) offset: usize,
    pub(super) scalar: Scalar,
    pub(super) big_endian: bool,
}

/// `$mac!(args.., T, N)` with `T` the Rust type of `$scalar` and `N` its
/// size in bytes: one arm per type, each its own code.
macro_rules! by_scalar {
    ($scalar:expr, $mac:ident!($($args:expr),*)) => {
        match $scalar {
            Scalar::I8 => $mac!($($args),*, i8, 1),
            Scalar::U8 => $mac!($($args),*, u8, 1),
            Scalar::I16 => $mac!($($args),*, i16, 2),
            Scalar::U16 => $mac!($($args),*, u16, 2),
            Scalar::I32 => $mac!($($args),*, i32, 4),
            Scalar::U32 => $mac!($($args),*, u32, 4),
            Scalar::F32 => $mac!($($args),*, f32, 4),
            Scalar::F64 => $mac!($($args),*, f64, 8),
        }
    };
}
pub(super) use by_scalar;

macro_rules! read_as_f64 {
    ($p:expr, $o:expr, $be:expr, $t:ty, $n:literal) => {{
        // Offsets are validated against point_step, so this never misses; the
        // fallback only keeps the function panic-free.
        match $p
            .get($o..$o + $n)
            .and_then(|s| <[u8; $n]>::try_from(s).ok())
        {
            Some(b) if $be => <$t>::from_be_bytes(b) as f64,
            Some(b) => <$t>::from_le_bytes(b) as f64,
            None => f64::NAN,
        }
    }};
}

impl FieldReader {
    #[inline(always)]
    pub(super) fn read(&self, point: &[u8]) -> f64 {
        let (o, be) = (self.offset, self.big_endian);
        by_scalar!(self.scalar, read_as_f64!(point, o, be))
    }
}

/// Ring (laser, beam) field names of common drivers, in priority order:
/// Velodyne / Ouster / Hesai `ring`, RoboSense / Ouster-ROS2 `channel`,
/// `laser_id` (Velodyne raw), `line` (Livox), `laser_number`.
const RING_FIELDS: [&str; 5] = ["ring", "channel", "laser_id", "line", "laser_number"];

/// A ring value above this is not a ring (the largest LiDARs have 128-256
/// lasers): the field is then dropped as a whole.
pub(super) const MAX_RING_VALUE: f64 = 1023.0;

/// A validated strided buffer: `rows` rows of `cols` points, row `r` starting at
/// byte `r * row_step`. Constructed only after the data length was checked.
pub(super) struct Layout<'d> {
    pub(super) data: &'d [u8],
    pub(super) rows: usize,
    pub(super) cols: usize,
    pub(super) row_step: usize,
    pub(super) point_step: usize,
    pub(super) big_endian: bool,
}

impl Layout<'_> {
    pub(super) fn point_count(&self) -> usize {
        self.rows * self.cols
    }

    pub(super) fn first_point(&self) -> Option<&[u8]> {
        self.data
            .get(..self.point_step)
            .filter(|_| self.point_count() > 0)
    }
}

/// The readers for the fields a [`Scan`](crate::model::Scan) uses.
pub(super) struct Readers {
    pub(super) x: FieldReader,
    pub(super) y: FieldReader,
    /// 2D clouds may omit `z`; it then reads as 0.
    pub(super) z: Option<FieldReader>,
    pub(super) intensity: Option<FieldReader>,
    /// The ring field and its name.
    pub(super) ring: Option<(FieldReader, &'static str)>,
    /// The time field, its convention and its name.
    pub(super) time: Option<(FieldReader, TimeConvention, &'static str)>,
    /// The per-point sensor field of a merged cloud and its name.
    pub(super) sensor: Option<(FieldReader, String)>,
}

/// x, y and z must not share bytes: a cloud that says they do is corrupt
/// (its points would all lie on a line or a plane), not a layout to read.
fn check_coordinates_apart(
    x: FieldReader,
    y: FieldReader,
    z: Option<FieldReader>,
) -> Result<(), DecodeError> {
    let bytes = |r: FieldReader| r.offset..r.offset + r.scalar.size_bytes();
    let mut named = vec![("x", bytes(x)), ("y", bytes(y))];
    if let Some(z) = z {
        named.push(("z", bytes(z)));
    }
    for (i, (first, a)) in named.iter().enumerate() {
        for (second, b) in &named[i + 1..] {
            if a.start < b.end && b.start < a.end {
                return Err(DecodeError::FieldsOverlap {
                    first,
                    second,
                    first_bytes: a.clone(),
                    second_bytes: b.clone(),
                });
            }
        }
    }
    Ok(())
}

fn find<'a, 'f>(fields: &'a [FieldDesc<'f>], name: &str) -> Option<&'a FieldDesc<'f>> {
    fields.iter().find(|f| f.name == name)
}

fn field_reader(
    desc: &FieldDesc<'_>,
    point_step: usize,
    big_endian: bool,
) -> Result<FieldReader, DecodeError> {
    let scalar = desc
        .scalar
        .map_err(|code| DecodeError::UnsupportedFieldType {
            name: desc.name.to_owned(),
            datatype: code,
        })?;
    let offset = desc.offset as usize;
    if offset.saturating_add(scalar.size_bytes()) > point_step {
        return Err(DecodeError::FieldOutOfBounds {
            name: desc.name.to_owned(),
            offset: desc.offset,
            size: scalar.size_bytes(),
            point_step: u32::try_from(point_step).unwrap_or(u32::MAX),
        });
    }
    Ok(FieldReader {
        offset,
        scalar,
        big_endian,
    })
}

pub(super) fn resolve_readers(
    fields: &[FieldDesc<'_>],
    layout: &Layout<'_>,
    sensor_field: &SensorField,
) -> Result<Readers, DecodeError> {
    let (ps, be) = (layout.point_step, layout.big_endian);
    let optional = |names: &[&str]| -> Result<Option<FieldReader>, DecodeError> {
        names
            .iter()
            .find_map(|n| find(fields, n))
            .map(|d| field_reader(d, ps, be))
            .transpose()
    };
    let required = |name: &'static str| -> Result<FieldReader, DecodeError> {
        let desc = find(fields, name).ok_or(DecodeError::MissingField(name))?;
        field_reader(desc, ps, be)
    };
    let time = TIME_FIELDS
        .iter()
        .find_map(|&(n, absolute)| find(fields, n).map(|d| (d, absolute, n)))
        .map(|(d, absolute, name)| -> Result<_, DecodeError> {
            let reader = field_reader(d, ps, be)?;
            let convention = if absolute {
                absolute_convention(&reader, layout)
            } else if reader.scalar.is_float() {
                TimeConvention::Relative { scale_s: 1.0 }
            } else {
                TimeConvention::Relative { scale_s: 1e-9 }
            };
            Ok((reader, convention, name))
        })
        .transpose()?;
    // Any integer type under any of the names; a float only as `ring` (as
    // before; its values must still be whole numbers).
    let ring = RING_FIELDS
        .iter()
        .filter_map(|&n| find(fields, n).map(|d| (d, n)))
        .find(|(d, n)| match d.scalar {
            Ok(scalar) => !scalar.is_float() || *n == "ring",
            Err(_) => false,
        })
        .map(|(d, name)| field_reader(d, ps, be).map(|r| (r, name)))
        .transpose()?;
    let (x, y, z) = (required("x")?, required("y")?, optional(&["z"])?);
    check_coordinates_apart(x, y, z)?;
    Ok(Readers {
        x,
        y,
        z,
        intensity: optional(&["intensity", "reflectivity"])?,
        ring,
        time,
        sensor: sensor_reader(fields, ps, be, sensor_field)?,
    })
}

/// The sensor field `choice` names, when the cloud has it with an integer
/// type (a float sensor number is no sensor field: it is left unread).
fn sensor_reader(
    fields: &[FieldDesc<'_>],
    point_step: usize,
    big_endian: bool,
    choice: &SensorField,
) -> Result<Option<(FieldReader, String)>, DecodeError> {
    let integer = |d: &&FieldDesc<'_>| d.scalar.is_ok_and(|s| !s.is_float());
    let desc = match choice {
        SensorField::Off => None,
        SensorField::Auto => SENSOR_FIELDS
            .iter()
            .find_map(|n| find(fields, n).filter(integer)),
        SensorField::Named(name) => find(fields, name).filter(integer),
    };
    desc.map(|d| field_reader(d, point_step, big_endian).map(|r| (r, d.name.to_owned())))
        .transpose()
}
