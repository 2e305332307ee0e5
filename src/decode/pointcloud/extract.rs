//! The hot loop: every point of a validated [`Layout`] read through its
//! resolved [`Readers`] into a [`Scan`], invalid points dropped.

use nalgebra::Isometry3;

use super::fields::{FieldReader, Layout, MAX_RING_VALUE, Readers, Scalar, by_scalar};
use super::time::TimeToOffset;
use crate::model::{DroppedRingField, RingSource, ScanLayout};
use crate::model::{Scan, SensorIds, StampNs};

/// Picks the monomorphised loop: the common all-FLOAT32 little-endian x/y/z
/// layout gets direct f32 loads instead of per-field type dispatch.
pub(super) fn extract(
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
/// The coordinates first, in one pass; then each other field the cloud has,
/// in a pass of its own over the points kept, its type and byte order
/// matched once per cloud (one loop checked each optional field and matched
/// its type at every point: 280 instructions a point on the synthetic
/// sensor's six fields, 180 in passes).
fn extract_with<X: XyzRead>(
    layout: &Layout<'_>,
    xyz: X,
    readers: &Readers,
    stamp_ns: StampNs,
    frame_id: String,
    sensor_pose: Isometry3<f64>,
) -> Scan {
    let n = layout.point_count();
    let (points_m, source_index, skipped) = valid_points(layout, xyz);
    let kept = KeptPoints {
        layout,
        source_index: &source_index,
    };
    let intensity = readers
        .intensity
        .map(|f| kept.values(f, |value| value as f32));
    // A ring value that is negative, fractional or above MAX_RING_VALUE:
    // the first such, in point order.
    let mut bad_ring: Option<f64> = None;
    let mut ring = readers.ring.map(|(f, _)| {
        kept.values(f, |value| {
            if (0.0..=MAX_RING_VALUE).contains(&value) && value.fract() == 0.0 {
                value as u16
            } else {
                bad_ring.get_or_insert(value);
                0
            }
        })
    });
    // A negative sensor value (or one above u32): no sensor field.
    let mut bad_sensor = false;
    let sensor_ids = readers.sensor.as_ref().map(|(f, _)| {
        kept.values(*f, |value| {
            bad_sensor |= !(0.0..=f64::from(u32::MAX)).contains(&value);
            value as u32
        })
    });
    let time_offset_s = readers.time.map(|(f, conv, _)| {
        let conv = TimeToOffset::new(conv, stamp_ns);
        kept.values(f, |value| conv.offset_s(value))
    });

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
        sensor_ids: sensor_ids_of(sensor_ids.filter(|_| !bad_sensor), readers),
    }
}

/// The sensor field's values with its name (`None` without the field, or
/// when a value was no sensor number).
fn sensor_ids_of(ids: Option<Vec<u32>>, readers: &Readers) -> Option<SensorIds> {
    let (_, field) = readers.sensor.as_ref()?;
    Some(SensorIds {
        field: field.clone(),
        ids: ids?,
    })
}

/// Every valid point's coordinates and index in the cloud (row-major),
/// and how many were dropped (a coordinate not finite, or all three zero).
fn valid_points<X: XyzRead>(layout: &Layout<'_>, xyz: X) -> (Vec<[f32; 3]>, Vec<u32>, u32) {
    let n = layout.point_count();
    let mut points_m = Vec::with_capacity(n);
    let mut source_index = Vec::with_capacity(n);
    let mut skipped: u32 = 0;
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
        }
    }
    (points_m, source_index, skipped)
}

/// The points [`valid_points`] kept, for the passes over their other fields.
struct KeptPoints<'l, 'd> {
    layout: &'l Layout<'d>,
    /// Each kept point's index in the cloud (row-major).
    source_index: &'l [u32],
}

/// One field's value of each kept point, in order, as
/// [`FieldReader::read`] takes it (NaN where the bytes are out of bounds,
/// which the layout's check rules out): the byte order matched once too.
macro_rules! each_value {
    ($kept:expr, $field:expr, $convert:expr, $t:ty, $n:literal) => {{
        let at = $field.offset;
        if $field.big_endian {
            $kept.each::<$n, _>(at, |b| <$t>::from_be_bytes(b) as f64, $convert)
        } else {
            $kept.each::<$n, _>(at, |b| <$t>::from_le_bytes(b) as f64, $convert)
        }
    }};
}

impl KeptPoints<'_, '_> {
    /// `convert` of field `field`'s value of each kept point, in order: the
    /// field's type matched once, each type's loop its own.
    fn values<T>(&self, field: FieldReader, convert: impl FnMut(f64) -> T) -> Vec<T> {
        by_scalar!(field.scalar, each_value!(self, field, convert))
    }

    /// `convert(read(bytes))` of the `N` bytes at `offset` in each kept
    /// point, in order.
    #[inline(always)]
    fn each<const N: usize, T>(
        &self,
        offset: usize,
        read: impl Fn([u8; N]) -> f64,
        mut convert: impl FnMut(f64) -> T,
    ) -> Vec<T> {
        let layout = self.layout;
        let (data, step, row_step) = (layout.data, layout.point_step, layout.row_step);
        // Rows without padding: a point's bytes start at its index times
        // the step (no division per point).
        let packed = row_step == layout.cols * step;
        let cols = layout.cols.max(1);
        let mut values = Vec::with_capacity(self.source_index.len());
        for &index in self.source_index {
            let index = index as usize;
            let start = if packed {
                index * step
            } else {
                (index / cols) * row_step + (index % cols) * step
            } + offset;
            let value = match data
                .get(start..start + N)
                .and_then(|s| <[u8; N]>::try_from(s).ok())
            {
                Some(bytes) => read(bytes),
                None => f64::NAN,
            };
            values.push(convert(value));
        }
        values
    }
}
