//! Point clouds (`sensor_msgs/PointCloud2`, `foxglove.PointCloud`) to [`Scan`].
//!
//! Both formats are "a strided byte buffer plus named, typed fields", so they
//! share one extractor: the header is validated against the data length and
//! [`DecodeLimits`] first (nothing is allocated from untrusted sizes before
//! that), the fields used are resolved once into [`FieldReader`]s, and the hot
//! loop then only reads fixed offsets from each point's bytes.

use nalgebra::{Isometry3, Translation3, UnitQuaternion};

use super::DecodeLimits;
use crate::model::{DroppedRingField, RingSource, ScanLayout};
use crate::model::{Scan, StampNs};
use crate::ros::DecodeError;
use crate::ros::msgs::{PointCloud2, datatype};

/// Numeric type of one point field.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
enum Scalar {
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

    fn is_float(self) -> bool {
        matches!(self, Scalar::F32 | Scalar::F64)
    }

    /// `sensor_msgs/PointField` datatype code.
    fn from_ros(code: u8) -> Option<Self> {
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
    fn from_foxglove(code: i32) -> Option<Self> {
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
struct FieldDesc<'f> {
    name: &'f str,
    offset: u32,
    /// The numeric type, or the unknown raw code (only an error if the field is used).
    scalar: Result<Scalar, i64>,
}

/// Reads one field from one point's bytes; resolved once per cloud.
#[derive(Debug, Clone, Copy)]
struct FieldReader {
    offset: usize,
    scalar: Scalar,
    big_endian: bool,
}

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
    fn read(&self, point: &[u8]) -> f64 {
        let (o, be) = (self.offset, self.big_endian);
        match self.scalar {
            Scalar::I8 => read_as_f64!(point, o, be, i8, 1),
            Scalar::U8 => read_as_f64!(point, o, be, u8, 1),
            Scalar::I16 => read_as_f64!(point, o, be, i16, 2),
            Scalar::U16 => read_as_f64!(point, o, be, u16, 2),
            Scalar::I32 => read_as_f64!(point, o, be, i32, 4),
            Scalar::U32 => read_as_f64!(point, o, be, u32, 4),
            Scalar::F32 => read_as_f64!(point, o, be, f32, 4),
            Scalar::F64 => read_as_f64!(point, o, be, f64, 8),
        }
    }
}

/// How a per-point time field relates to the header stamp.
#[derive(Debug, Clone, Copy, PartialEq)]
enum TimeConvention {
    /// Offset from the stamp; value times `scale_s` is seconds.
    Relative { scale_s: f64 },
    /// Absolute epoch seconds (`timestamp` in Hesai / RoboSense drivers).
    AbsoluteSeconds,
    /// Absolute epoch nanoseconds stored as a float (Livox driver 2).
    AbsoluteNanos,
}

/// Per-point time field names, in priority order, and whether they are absolute.
const TIME_FIELDS: [(&str, bool); 5] = [
    ("t", false),           // Ouster: UINT32 ns since scan start
    ("time", false),        // Velodyne: FLOAT32 s relative to the stamp
    ("offset_time", false), // Livox custom: UINT32 ns relative to the stamp
    ("timestamp", true),    // Hesai / RoboSense: FLOAT64 absolute s
    ("time_stamp", true),
];

/// Ring (laser, beam) field names of common drivers, in priority order:
/// Velodyne / Ouster / Hesai `ring`, RoboSense / Ouster-ROS2 `channel`,
/// `laser_id` (Velodyne raw), `line` (Livox), `laser_number`.
pub const RING_FIELDS: [&str; 5] = ["ring", "channel", "laser_id", "line", "laser_number"];

/// A ring value above this is not a ring (the largest LiDARs have 128-256
/// lasers): the field is then dropped as a whole.
pub const MAX_RING_VALUE: f64 = 1023.0;

/// Absolute float times above this are nanoseconds, not seconds (1e14 s is
/// ~3 million years; 1e14 ns is ~28 hours after the epoch).
const ABSOLUTE_NS_THRESHOLD: f64 = 1e14;

/// A validated strided buffer: `rows` rows of `cols` points, row `r` starting at
/// byte `r * row_step`. Constructed only after the data length was checked.
struct Layout<'d> {
    data: &'d [u8],
    rows: usize,
    cols: usize,
    row_step: usize,
    point_step: usize,
    big_endian: bool,
}

impl Layout<'_> {
    fn point_count(&self) -> usize {
        self.rows * self.cols
    }

    fn first_point(&self) -> Option<&[u8]> {
        self.data
            .get(..self.point_step)
            .filter(|_| self.point_count() > 0)
    }
}

/// The readers for the fields a [`Scan`] uses.
struct Readers {
    x: FieldReader,
    y: FieldReader,
    /// 2D clouds may omit `z`; it then reads as 0.
    z: Option<FieldReader>,
    intensity: Option<FieldReader>,
    /// The ring field and its name.
    ring: Option<(FieldReader, &'static str)>,
    /// The time field, its convention and its name.
    time: Option<(FieldReader, TimeConvention, &'static str)>,
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

fn resolve_readers(fields: &[FieldDesc<'_>], layout: &Layout<'_>) -> Result<Readers, DecodeError> {
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
    Ok(Readers {
        x: required("x")?,
        y: required("y")?,
        z: optional(&["z"])?,
        intensity: optional(&["intensity", "reflectivity"])?,
        ring,
        time,
    })
}

/// Absolute time fields come in seconds or nanoseconds depending on the
/// driver; the magnitude of the first point's value tells which.
fn absolute_convention(reader: &FieldReader, layout: &Layout<'_>) -> TimeConvention {
    let first = layout.first_point().map_or(0.0, |p| reader.read(p));
    if first.abs() > ABSOLUTE_NS_THRESHOLD {
        TimeConvention::AbsoluteNanos
    } else {
        TimeConvention::AbsoluteSeconds
    }
}

/// Converts a raw time value to seconds relative to `stamp_ns`.
struct TimeToOffset {
    convention: TimeConvention,
    stamp_whole_s: f64,
    stamp_frac_s: f64,
    stamp_ns: f64,
}

impl TimeToOffset {
    fn new(convention: TimeConvention, stamp_ns: StampNs) -> Self {
        Self {
            convention,
            // Split so that subtracting from absolute epoch seconds keeps
            // sub-microsecond precision in f64.
            stamp_whole_s: stamp_ns.div_euclid(1_000_000_000) as f64,
            stamp_frac_s: stamp_ns.rem_euclid(1_000_000_000) as f64 * 1e-9,
            stamp_ns: stamp_ns as f64,
        }
    }

    #[inline(always)]
    fn offset_s(&self, raw: f64) -> f32 {
        let s = match self.convention {
            TimeConvention::Relative { scale_s } => raw * scale_s,
            TimeConvention::AbsoluteSeconds => (raw - self.stamp_whole_s) - self.stamp_frac_s,
            TimeConvention::AbsoluteNanos => (raw - self.stamp_ns) * 1e-9,
        };
        s as f32
    }
}

/// Picks the monomorphised loop: the common all-FLOAT32 little-endian x/y/z
/// layout gets direct f32 loads instead of per-field type dispatch.
fn extract(
    layout: &Layout<'_>,
    readers: &Readers,
    stamp_ns: StampNs,
    frame_id: String,
    sensor_pose: Isometry3<f64>,
) -> Scan {
    let f32_le = |f: &FieldReader| f.scalar == Scalar::F32 && !f.big_endian;
    match readers.z {
        Some(z) if f32_le(&readers.x) && f32_le(&readers.y) && f32_le(&z) => {
            let xyz = XyzF32Le {
                x: readers.x.offset,
                y: readers.y.offset,
                z: z.offset,
            };
            extract_with(layout, xyz, readers, stamp_ns, frame_id, sensor_pose)
        }
        _ => {
            let xyz = XyzAny {
                x: readers.x,
                y: readers.y,
                z: readers.z,
            };
            extract_with(layout, xyz, readers, stamp_ns, frame_id, sensor_pose)
        }
    }
}

/// Reads the coordinates of one point.
trait XyzRead: Copy {
    fn xyz(&self, point: &[u8]) -> [f32; 3];
}

/// x, y, z FLOAT32 little-endian at the given offsets.
#[derive(Clone, Copy)]
struct XyzF32Le {
    x: usize,
    y: usize,
    z: usize,
}

#[inline(always)]
fn f32_le_at(p: &[u8], o: usize) -> f32 {
    match p.get(o..o + 4).and_then(|s| <[u8; 4]>::try_from(s).ok()) {
        Some(b) => f32::from_le_bytes(b),
        None => f32::NAN,
    }
}

impl XyzRead for XyzF32Le {
    #[inline(always)]
    fn xyz(&self, p: &[u8]) -> [f32; 3] {
        [
            f32_le_at(p, self.x),
            f32_le_at(p, self.y),
            f32_le_at(p, self.z),
        ]
    }
}

/// Any numeric types and byte order; a missing z reads as 0.
#[derive(Clone, Copy)]
struct XyzAny {
    x: FieldReader,
    y: FieldReader,
    z: Option<FieldReader>,
}

impl XyzRead for XyzAny {
    #[inline(always)]
    fn xyz(&self, p: &[u8]) -> [f32; 3] {
        [
            self.x.read(p) as f32,
            self.y.read(p) as f32,
            self.z.map_or(0.0, |f| f.read(p)) as f32,
        ]
    }
}

/// The hot loop: reads every point, drops invalid ones, fills the [`Scan`].
fn extract_with<X: XyzRead>(
    layout: &Layout<'_>,
    xyz: X,
    readers: &Readers,
    stamp_ns: StampNs,
    frame_id: String,
    sensor_pose: Isometry3<f64>,
) -> Scan {
    let n = layout.point_count();
    let mut points_m = Vec::with_capacity(n);
    let mut source_index = Vec::with_capacity(n);
    let mut intensity = readers.intensity.map(|_| Vec::with_capacity(n));
    let mut ring = readers.ring.map(|_| Vec::with_capacity(n));
    let mut time_offset_s = readers.time.map(|_| Vec::with_capacity(n));
    let time_conv = readers
        .time
        .map(|(_, conv, _)| TimeToOffset::new(conv, stamp_ns));
    let mut skipped: u32 = 0;
    // A ring value that is negative, fractional or above MAX_RING_VALUE.
    let mut bad_ring: Option<f64> = None;

    let row_bytes = layout.cols * layout.point_step;
    for r in 0..layout.rows {
        let start = r * layout.row_step;
        // Always in bounds: the data length was checked against the layout.
        let Some(row) = layout.data.get(start..start + row_bytes) else {
            break;
        };
        for (c, p) in row.chunks_exact(layout.point_step).enumerate() {
            let [x, y, z] = xyz.xyz(p);
            let finite = x.is_finite() && y.is_finite() && z.is_finite();
            if !finite || (x == 0.0 && y == 0.0 && z == 0.0) {
                skipped += 1;
                continue;
            }
            points_m.push([x, y, z]);
            source_index.push((r * layout.cols + c) as u32);
            if let (Some(v), Some(f)) = (&mut intensity, &readers.intensity) {
                v.push(f.read(p) as f32);
            }
            if let (Some(v), Some((f, _))) = (&mut ring, &readers.ring) {
                let value = f.read(p);
                if (0.0..=MAX_RING_VALUE).contains(&value) && value.fract() == 0.0 {
                    v.push(value as u16);
                } else {
                    bad_ring.get_or_insert(value);
                    v.push(0);
                }
            }
            if let (Some(v), Some((f, _, _)), Some(conv)) =
                (&mut time_offset_s, &readers.time, &time_conv)
            {
                v.push(conv.offset_s(f.read(p)));
            }
        }
    }

    let mut scan_layout = ScanLayout::from_fields(
        readers.ring.map(|(_, name)| name),
        readers.time.map(|(_, _, name)| name),
    );
    if let (Some(value), Some((_, name))) = (bad_ring, readers.ring) {
        // Not a ring: the field is dropped whole, never used to size anything.
        ring = None;
        scan_layout.rings = RingSource::None;
        scan_layout.ring_field_dropped = Some(DroppedRingField {
            name: name.to_owned(),
            reason: format!("value {value} is not a ring number (0..={MAX_RING_VALUE})"),
        });
    }
    Scan {
        stamp_ns,
        frame_id,
        sensor_pose,
        points_m,
        intensity,
        ring,
        time_offset_s,
        source_index,
        input_point_count: n as u32,
        skipped_invalid_points: skipped,
        organized: (layout.rows > 1).then_some((layout.rows as u32, layout.cols as u32)),
        layout: scan_layout,
    }
}

/// Refuses clouds above the point limit (and above what `u32` indices hold).
fn check_point_count(points: u64, limits: &DecodeLimits) -> Result<usize, DecodeError> {
    let max_points = limits.max_points.min(u32::MAX as usize);
    if points > max_points as u64 {
        return Err(DecodeError::TooManyPoints { points, max_points });
    }
    Ok(points as usize)
}

/// Strips one leading '/' (ROS 1 style frame ids).
pub(crate) fn normalize_frame_id(frame_id: &str) -> String {
    frame_id.strip_prefix('/').unwrap_or(frame_id).to_owned()
}

fn empty_scan(stamp_ns: StampNs, frame_id: String, sensor_pose: Isometry3<f64>) -> Scan {
    Scan {
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
    }
}

/// Converts a `sensor_msgs/PointCloud2` into a [`Scan`] (identity sensor pose).
///
/// `is_dense` is treated as a hint only: points are always checked, since
/// drivers set it inconsistently.
pub fn scan_from_pointcloud2(
    cloud: &PointCloud2<'_>,
    limits: &DecodeLimits,
) -> Result<Scan, DecodeError> {
    let stamp_ns = cloud.header.stamp.to_ns();
    let frame_id = normalize_frame_id(&cloud.header.frame_id);
    let n = check_point_count(u64::from(cloud.width) * u64::from(cloud.height), limits)?;
    if n == 0 {
        return Ok(empty_scan(stamp_ns, frame_id, Isometry3::identity()));
    }
    let point_step = u64::from(cloud.point_step);
    if point_step == 0 {
        return Err(DecodeError::InvalidPointLayout(
            "point_step is 0 for a non-empty cloud".into(),
        ));
    }
    let row_bytes = u64::from(cloud.width) * point_step;
    // A single row needs no row_step; some drivers leave it 0 there.
    let row_step = if cloud.height > 1 {
        u64::from(cloud.row_step)
    } else {
        row_bytes
    };
    if row_step < row_bytes {
        return Err(DecodeError::InvalidPointLayout(format!(
            "row_step {} is smaller than width {} * point_step {}",
            cloud.row_step, cloud.width, cloud.point_step
        )));
    }
    let needed = (u64::from(cloud.height) - 1) * row_step + row_bytes;
    if (cloud.data.len() as u64) < needed {
        return Err(DecodeError::PointCloudDataTooShort {
            data_bytes: cloud.data.len(),
            needed_bytes: needed,
            height: cloud.height,
            width: cloud.width,
            point_step: cloud.point_step,
            row_step: cloud.row_step,
        });
    }
    // Every size below is bounded by the data length now.
    let layout = Layout {
        data: &cloud.data,
        rows: cloud.height as usize,
        cols: cloud.width as usize,
        row_step: row_step as usize,
        point_step: point_step as usize,
        big_endian: cloud.is_bigendian,
    };
    let fields: Vec<FieldDesc<'_>> = cloud
        .fields
        .iter()
        .map(|f| FieldDesc {
            name: &f.name,
            offset: f.offset,
            scalar: Scalar::from_ros(f.datatype).ok_or(i64::from(f.datatype)),
        })
        .collect();
    let readers = resolve_readers(&fields, &layout)?;
    Ok(extract(
        &layout,
        &readers,
        stamp_ns,
        frame_id,
        Isometry3::identity(),
    ))
}

/// The cloud origin's pose; a missing pose, position or orientation (or an
/// all-zero orientation) means identity; a non-finite orientation is an error.
fn foxglove_pose(pose: Option<&foxglove::messages::Pose>) -> Result<Isometry3<f64>, DecodeError> {
    let Some(pose) = pose else {
        return Ok(Isometry3::identity());
    };
    let t = pose
        .position
        .as_ref()
        .map_or(Translation3::identity(), |p| {
            Translation3::new(p.x, p.y, p.z)
        });
    let rotation = match &pose.orientation {
        // proto3 cannot tell an unset orientation from an all-zero one.
        None => UnitQuaternion::identity(),
        Some(q) if q.x == 0.0 && q.y == 0.0 && q.z == 0.0 && q.w == 0.0 => {
            UnitQuaternion::identity()
        }
        Some(q) => crate::ros::msgs::Quaternion {
            x: q.x,
            y: q.y,
            z: q.z,
            w: q.w,
        }
        .to_unit()
        .ok_or(DecodeError::InvalidQuaternion {
            context: "foxglove.PointCloud pose".into(),
            x: q.x,
            y: q.y,
            z: q.z,
            w: q.w,
        })?,
    };
    Ok(Isometry3::from_parts(t, rotation))
}

/// Converts a `foxglove.PointCloud` into a [`Scan`], keeping its `pose` as the
/// sensor pose (points stay in the cloud's origin frame). A trailing partial
/// point in `data` is ignored, as Foxglove's own viewer does. A missing
/// `timestamp` gives `stamp_ns` 0.
pub fn scan_from_foxglove(
    cloud: &foxglove::messages::PointCloud,
    limits: &DecodeLimits,
) -> Result<Scan, DecodeError> {
    let stamp_ns = cloud.timestamp.map_or(0, |t| {
        i64::from(t.sec()) * 1_000_000_000 + i64::from(t.nsec())
    });
    let frame_id = normalize_frame_id(&cloud.frame_id);
    let sensor_pose = foxglove_pose(cloud.pose.as_ref())?;
    let stride = cloud.point_stride as usize;
    if stride == 0 {
        if cloud.data.is_empty() {
            return Ok(empty_scan(stamp_ns, frame_id, sensor_pose));
        }
        return Err(DecodeError::InvalidPointLayout(
            "point_stride is 0 but data is not empty".into(),
        ));
    }
    let n = check_point_count((cloud.data.len() / stride) as u64, limits)?;
    if n == 0 {
        return Ok(empty_scan(stamp_ns, frame_id, sensor_pose));
    }
    let layout = Layout {
        data: &cloud.data,
        rows: 1,
        cols: n,
        row_step: n * stride,
        point_step: stride,
        big_endian: false,
    };
    let fields: Vec<FieldDesc<'_>> = cloud
        .fields
        .iter()
        .map(|f| FieldDesc {
            name: &f.name,
            offset: f.offset,
            scalar: Scalar::from_foxglove(f.r#type).ok_or(i64::from(f.r#type)),
        })
        .collect();
    let readers = resolve_readers(&fields, &layout)?;
    Ok(extract(&layout, &readers, stamp_ns, frame_id, sensor_pose))
}
