//! `/lidar/points`: the simulated scan as a `sensor_msgs/PointCloud2` in the
//! scenario's layout (docs/scenarios.md, "Cloud layouts"), field by field.

use crate::ros::msgs::{Header, PointCloud2, PointField, datatype, pointcloud2_from_points};
use crate::synth::scene::CloudLayout;
use crate::synth::sensor::{SimPoint, SimScan, World};

use super::{CloudShape, Slot, stamp_ns};

/// Builds a point layout field by field (each field aligned to its size).
struct Packer {
    fields: Vec<PointField>,
    step: u32,
}

impl Packer {
    fn new() -> Self {
        Self {
            fields: Vec::new(),
            step: 0,
        }
    }

    /// Add a field; its offset.
    fn add(&mut self, name: &str, datatype: u8) -> usize {
        let size = datatype_size(datatype);
        self.at(name, self.step.div_ceil(size) * size, datatype)
    }

    /// Add a field at a fixed offset; its offset.
    fn at(&mut self, name: &str, offset: u32, datatype: u8) -> usize {
        self.fields.push(PointField::new(name, offset, datatype));
        self.step = self.step.max(offset + datatype_size(datatype));
        offset as usize
    }

    /// The point step, a multiple of 4 bytes, or `step` if larger.
    fn point_step(&self, step: u32) -> u32 {
        (self.step.div_ceil(4) * 4).max(step)
    }
}

fn datatype_size(datatype: u8) -> u32 {
    match datatype {
        datatype::INT8 | datatype::UINT8 => 1,
        datatype::INT16 | datatype::UINT16 => 2,
        datatype::FLOAT64 => 8,
        _ => 4,
    }
}

/// Write `value` at `offset` as `datatype` (integers saturate).
fn put(out: &mut [u8], offset: usize, datatype: u8, value: f64) {
    let mut bytes = |b: &[u8]| out[offset..offset + b.len()].copy_from_slice(b);
    match datatype {
        datatype::INT8 => bytes(&(value as i8).to_le_bytes()),
        datatype::UINT8 => bytes(&(value as u8).to_le_bytes()),
        datatype::INT16 => bytes(&(value as i16).to_le_bytes()),
        datatype::UINT16 => bytes(&(value as u16).to_le_bytes()),
        datatype::INT32 => bytes(&(value as i32).to_le_bytes()),
        datatype::UINT32 => bytes(&(value as u32).to_le_bytes()),
        datatype::FLOAT64 => bytes(&value.to_le_bytes()),
        _ => bytes(&(value as f32).to_le_bytes()),
    }
}

fn put_f32(out: &mut [u8], offset: usize, value: f32) {
    out[offset..offset + 4].copy_from_slice(&value.to_le_bytes());
}

/// `/lidar/points` in the scenario's layout, in frame `frame`.
pub(super) fn lidar_cloud(
    world: &World,
    scan: &SimScan,
    shape: &CloudShape,
    frame: &str,
) -> PointCloud2<'static> {
    let layout = world.scenario.lidar.layout;
    if layout == CloudLayout::RingTime {
        return ring_time_cloud(scan, frame);
    }
    let (packer, offsets, point_step) = LidarFields::of(layout);
    let ps = point_step as usize;
    let mut data = vec![0u8; shape.slots.len() * ps];
    for (&slot, out) in shape.slots.iter().zip(data.chunks_exact_mut(ps)) {
        offsets.write_point(out, world, scan, shape, slot);
    }
    PointCloud2 {
        header: Header::new(stamp_ns(scan.stamp_s), frame),
        height: shape.height,
        width: shape.width,
        fields: packer.fields,
        is_bigendian: false,
        point_step,
        row_step: shape.width * point_step,
        data: data.into(),
        is_dense: shape.dense(),
    }
}

/// The cloud's points moved into `frame` by `frame_from_lidar` (`synth
/// --frame vehicle|world`), stamped in that frame: what a stack that
/// publishes in `base_link`, or a recorder after a transform filter,
/// records. Points without a return stay NaN.
pub(super) fn into_frame(
    cloud: &mut PointCloud2<'static>,
    frame_from_lidar: &nalgebra::Isometry3<f64>,
    frame: &str,
) {
    let offset = |name: &str| cloud.field_offset(name);
    let (Some(x), Some(y), Some(z)) = (offset("x"), offset("y"), offset("z")) else {
        return;
    };
    let step = cloud.point_step as usize;
    let read = |point: &[u8], at: usize| {
        f32::from_le_bytes([point[at], point[at + 1], point[at + 2], point[at + 3]])
    };
    for point in cloud.data.to_mut().chunks_exact_mut(step) {
        let p = [read(point, x), read(point, y), read(point, z)];
        if !p.iter().all(|v| v.is_finite()) {
            continue;
        }
        let q = frame_from_lidar * nalgebra::Point3::from(p.map(f64::from));
        put_f32(point, x, q.x as f32);
        put_f32(point, y, q.y as f32);
        put_f32(point, z, q.z as f32);
    }
    cloud.header.frame_id = frame.to_owned();
}

/// Every point of `cloud` tagged with its LiDAR in a `sensor_id` (UINT8)
/// field after the others (`--one-topic`), the point step kept a multiple
/// of 4 bytes as drivers pad it.
pub(super) fn tag_sensor(cloud: &mut PointCloud2<'static>, sensor_id: u8) {
    let old_step = cloud.point_step as usize;
    let new_step = (old_step + 1).next_multiple_of(4);
    let points = cloud.data.len() / old_step.max(1);
    let mut data = vec![0u8; points * new_step];
    for (old, new) in cloud
        .data
        .chunks_exact(old_step.max(1))
        .zip(data.chunks_exact_mut(new_step))
    {
        new[..old_step].copy_from_slice(old);
        new[old_step] = sensor_id;
    }
    cloud.fields.push(PointField {
        name: "sensor_id".into(),
        offset: old_step as u32,
        datatype: datatype::UINT8,
        count: 1,
    });
    cloud.point_step = new_step as u32;
    cloud.row_step = cloud.width * cloud.point_step;
    cloud.data = data.into();
}

/// `base` with the points of `others` after its own, as a concatenating
/// node merges clouds: one row, `base`'s stamp, each point's `time` (FLOAT32
/// seconds from the stamp) shifted to stay its own time. Clouds of another
/// point layout than `base`'s are left out (`--one-topic` keeps every
/// LiDAR in the ring-time layout).
pub(super) fn concatenate(
    mut base: PointCloud2<'static>,
    others: &[PointCloud2<'static>],
) -> PointCloud2<'static> {
    let time = base
        .fields
        .iter()
        .find(|f| f.name == "time" && f.datatype == datatype::FLOAT32)
        .map(|f| f.offset as usize);
    let step = base.point_step as usize;
    let mut data = base.data.to_vec();
    let mut points = base.width * base.height;
    for other in others
        .iter()
        .filter(|o| o.fields == base.fields && o.point_step == base.point_step)
    {
        let shift_s = (other.header.stamp.to_ns() - base.header.stamp.to_ns()) as f64 * 1e-9;
        let start = data.len();
        data.extend_from_slice(&other.data);
        if let Some(at) = time {
            for point in data[start..].chunks_exact_mut(step) {
                let t =
                    f32::from_le_bytes([point[at], point[at + 1], point[at + 2], point[at + 3]]);
                put_f32(point, at, (f64::from(t) + shift_s) as f32);
            }
        }
        points += other.width * other.height;
        base.is_dense &= other.is_dense;
    }
    base.height = 1;
    base.width = points;
    base.row_step = points * base.point_step;
    base.data = data.into();
    base
}

/// Byte offsets of a `/lidar/points` point's fields (`None`: the layout has
/// no such field).
struct LidarFields {
    layout: CloudLayout,
    xyz: [usize; 3],
    intensity: usize,
    /// Offset and datatype.
    ring: Option<(usize, u8)>,
    time_s: Option<usize>,
    time_ns: Option<usize>,
    reflectivity: Option<usize>,
    range_mm: Option<usize>,
}

impl LidarFields {
    /// The fields of `layout` (not `ring-time`), their offsets and the point step.
    fn of(layout: CloudLayout) -> (Packer, Self, u32) {
        let mut packer = Packer::new();
        let xyz = ["x", "y", "z"].map(|name| packer.add(name, datatype::FLOAT32));
        let mut step = 0;
        let intensity;
        let (mut ring, mut time_s, mut time_ns, mut reflectivity, mut range_mm) =
            (None, None, None, None, None);
        match layout {
            CloudLayout::Organized => {
                // The Ouster ROS driver's point (legacy profile), 48 bytes.
                intensity = packer.at("intensity", 16, datatype::FLOAT32);
                time_ns = Some(packer.at("t", 20, datatype::UINT32));
                reflectivity = Some(packer.at("reflectivity", 24, datatype::UINT16));
                ring = Some((packer.at("ring", 26, datatype::UINT16), datatype::UINT16));
                packer.at("ambient", 28, datatype::UINT16);
                range_mm = Some(packer.at("range", 32, datatype::UINT32));
                step = 48;
            }
            CloudLayout::RingField(field) => {
                intensity = packer.add("intensity", datatype::FLOAT32);
                ring = Some((
                    packer.add(field.name.as_str(), field.datatype),
                    field.datatype,
                ));
                time_s = Some(packer.add("time", datatype::FLOAT32));
            }
            _ => intensity = packer.add("intensity", datatype::FLOAT32),
        }
        let point_step = packer.point_step(step);
        let fields = Self {
            layout,
            xyz,
            intensity,
            ring,
            time_s,
            time_ns,
            reflectivity,
            range_mm,
        };
        (packer, fields, point_step)
    }

    /// Write the point of `slot` (NaN x, y, z for a pixel without a return).
    fn write_point(
        &self,
        out: &mut [u8],
        world: &World,
        scan: &SimScan,
        shape: &CloudShape,
        slot: Slot,
    ) {
        let beams = world.lasers.len();
        let (ring_index, column) = match (slot, shape.point(scan, slot)) {
            (_, Some(p)) => (p.ring, p.column),
            (Slot::Empty { ring, column }, None) => (ring, column),
            (Slot::Return(_), None) => (0, 0),
        };
        let point = shape.point(scan, slot);
        let xyz = point.map_or([f32::NAN; 3], |p| p.point_m);
        for (offset, value) in self.xyz.into_iter().zip(xyz) {
            put_f32(out, offset, value);
        }
        put_f32(out, self.intensity, point.map_or(0.0, |p| p.intensity));
        if let Some((offset, datatype)) = self.ring {
            // Ouster numbers rows from the top beam, Velodyne rings from the lowest.
            let value = if self.layout == CloudLayout::Organized {
                beams - 1 - usize::from(ring_index)
            } else {
                usize::from(ring_index)
            };
            put(out, offset, datatype, value as f64);
        }
        let column_time_s = world.column_time_s(column);
        if let Some(offset) = self.time_s {
            put_f32(out, offset, column_time_s as f32);
        }
        if let Some(offset) = self.time_ns {
            put(out, offset, datatype::UINT32, (column_time_s * 1e9).round());
        }
        if let Some(offset) = self.reflectivity {
            put(
                out,
                offset,
                datatype::UINT16,
                point.map_or(0.0, |p| f64::from(p.intensity).round()),
            );
        }
        if let Some(offset) = self.range_mm {
            put(
                out,
                offset,
                datatype::UINT32,
                (range_m(point) * 1000.0).round(),
            );
        }
    }
}

/// Distance of a return from the LiDAR, metres (0 without one).
fn range_m(point: Option<&SimPoint>) -> f64 {
    point.map_or(0.0, |p| {
        let [x, y, z] = p.point_m.map(f64::from);
        (x * x + y * y + z * z).sqrt()
    })
}

/// The Velodyne-driver cloud of `ring-time` (as before layouts existed).
fn ring_time_cloud(scan: &SimScan, frame: &str) -> PointCloud2<'static> {
    let points: Vec<[f32; 3]> = scan.points.iter().map(|p| p.point_m).collect();
    let intensity: Vec<f32> = scan.points.iter().map(|p| p.intensity).collect();
    let ring: Vec<u16> = scan.points.iter().map(|p| p.ring).collect();
    let time: Vec<f32> = scan.points.iter().map(|p| p.time_s).collect();
    pointcloud2_from_points(
        stamp_ns(scan.stamp_s),
        frame,
        &points,
        Some(&intensity),
        Some(&ring),
        Some(&time),
    )
}
