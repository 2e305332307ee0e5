//! The hot loop: every point of a validated [`Layout`] read through its
//! resolved [`Readers`] into a [`Scan`], invalid points dropped.

use nalgebra::Isometry3;

use super::fields::{FieldReader, Layout, MAX_RING_VALUE, Readers, Scalar};
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
    let mut sensor_ids = readers.sensor.as_ref().map(|_| Vec::with_capacity(n));
    // A negative sensor value (or one above u32): no sensor field.
    let mut bad_sensor = false;
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
            if let (Some(v), Some((f, _))) = (&mut sensor_ids, &readers.sensor) {
                let value = f.read(p);
                bad_sensor |= !(0.0..=f64::from(u32::MAX)).contains(&value);
                v.push(value as u32);
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
