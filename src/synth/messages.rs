//! Turning the simulation into MCAP messages: ROS 2 CDR sensor messages, the
//! truth point cloud and JSON truth records, in log-time order.

use nalgebra::{UnitQuaternion, Vector3};
use rand::SeedableRng;
use rand_distr::{Distribution, Normal};

use crate::output::{OutputError, OutputWriter, OwnChannelSpec};
use crate::ros::msgs::{
    Header, Imu, Odometry, PointCloud2, PointField, Pose, PoseWithCovariance, Quaternion,
    TFMessage, Transform, TransformStamped, Twist, TwistStamped, TwistWithCovariance,
    Vector3 as RosVector3, datatype, pointcloud2_from_points,
};
use crate::ros::schemas::{self as ros_schemas, RosDialect};

use super::scene::{CloudLayout, LaserOrder, Scenario};
use super::sensor::{SimPoint, SimScan, World};
use super::truth::{TruthEvent, TruthScan};

/// Wall-clock time of the start of every synthetic drive (fixed, so the same
/// arguments give the same bytes): 2023-11-14T22:13:20Z.
pub const START_NS: i64 = 1_700_000_000_000_000_000;

pub const LIDAR_FRAME: &str = "lidar";
pub const VEHICLE_FRAME: &str = "imu_link";
pub const ODOM_FRAME: &str = "odom";

/// Topics of a synthetic log.
pub mod topics {
    pub const LIDAR: &str = "/lidar/points";
    pub const IMU: &str = "/imu/data";
    pub const TWIST: &str = "/vehicle/twist";
    pub const ODOMETRY: &str = "/odom";
    pub const TF_STATIC: &str = "/tf_static";
    pub const TRUTH_POINTS: &str = "/truth/points";
    pub const TRUTH_SCAN: &str = "/truth/scan";
    pub const TRUTH_EVENTS: &str = "/truth/events";
}

/// Seconds from the start of the drive to a ROS stamp, ns.
pub fn stamp_ns(t_s: f64) -> i64 {
    START_NS + (t_s * 1e9).round() as i64
}

struct Channels {
    lidar: u16,
    imu: u16,
    twist: u16,
    odometry: u16,
    tf_static: u16,
    truth_points: u16,
    truth_scan: u16,
    truth_events: u16,
}

/// One encoded message for the writer.
#[derive(Debug, Clone)]
pub struct Encoded {
    pub channel: u16,
    pub log_time_ns: i64,
    pub data: Vec<u8>,
}

/// Encodes a synthetic drive into messages, interval by interval. It does no
/// I/O, so it can run on its own thread while [`SequencedWriter`] writes.
pub struct SynthLog {
    channels: Channels,
    /// Motion messages are generated up to here (exclusive), seconds.
    motion_until_s: f64,
    imu_index: u64,
    velocity_index: u64,
    pending: Vec<Encoded>,
}

/// Writes encoded messages with per-channel sequence numbers.
pub struct SequencedWriter<'w> {
    writer: &'w mut OutputWriter,
    sequences: std::collections::BTreeMap<u16, u32>,
    messages: u64,
}

impl<'w> SequencedWriter<'w> {
    pub fn new(writer: &'w mut OutputWriter) -> Self {
        Self {
            writer,
            sequences: Default::default(),
            messages: 0,
        }
    }

    pub fn write_all(&mut self, messages: Vec<Encoded>) -> Result<(), OutputError> {
        for message in messages {
            let sequence = self.sequences.entry(message.channel).or_default();
            *sequence += 1;
            self.messages += 1;
            self.writer.write_own_message(
                message.channel,
                *sequence,
                message.log_time_ns.max(0) as u64,
                &message.data,
            )?;
        }
        Ok(())
    }

    pub fn messages_written(&self) -> u64 {
        self.messages
    }

    /// The resolved scenario and the seed, for reproduction.
    pub fn write_metadata(
        &mut self,
        scenario: &Scenario,
        seed: u64,
        start_s: f64,
    ) -> Result<(), OutputError> {
        let mut metadata = std::collections::BTreeMap::new();
        metadata.insert("tool".into(), "looming synth".into());
        metadata.insert("version".into(), env!("CARGO_PKG_VERSION").into());
        metadata.insert("seed".into(), seed.to_string());
        metadata.insert("start_s".into(), start_s.to_string());
        metadata.insert(
            "scenario".into(),
            serde_json::to_string(scenario).expect("scenarios serialise"),
        );
        self.writer.write_metadata(&mcap::records::Metadata {
            name: "looming.synth".into(),
            metadata,
        })
    }
}

impl SynthLog {
    /// Register the channels and queue `/tf_static`; messages start with scan `first_scan`.
    pub fn new(
        writer: &mut OutputWriter,
        world: &World,
        first_scan: u64,
    ) -> Result<Self, OutputError> {
        let d = RosDialect::Ros2;
        let mut add = |spec: OwnChannelSpec| writer.add_own_channel(&spec);
        let channels = Channels {
            lidar: add(OwnChannelSpec::ros2(
                topics::LIDAR,
                "sensor_msgs",
                "PointCloud2",
                ros_schemas::point_cloud2(d),
            ))?,
            imu: add(OwnChannelSpec::ros2(
                topics::IMU,
                "sensor_msgs",
                "Imu",
                ros_schemas::imu(d),
            ))?,
            twist: add(OwnChannelSpec::ros2(
                topics::TWIST,
                "geometry_msgs",
                "TwistStamped",
                ros_schemas::twist_stamped(d),
            ))?,
            odometry: add(OwnChannelSpec::ros2(
                topics::ODOMETRY,
                "nav_msgs",
                "Odometry",
                ros_schemas::odometry(d),
            ))?,
            tf_static: add(OwnChannelSpec::ros2(
                topics::TF_STATIC,
                "tf2_msgs",
                "TFMessage",
                ros_schemas::tf_message(d),
            ))?,
            truth_points: add(OwnChannelSpec::ros2(
                topics::TRUTH_POINTS,
                "sensor_msgs",
                "PointCloud2",
                ros_schemas::point_cloud2(d),
            ))?,
            truth_scan: add(OwnChannelSpec::json(
                topics::TRUTH_SCAN,
                "looming.TruthScan",
                include_str!("../../schemas/looming.TruthScan.schema.json"),
            ))?,
            truth_events: add(OwnChannelSpec::json(
                topics::TRUTH_EVENTS,
                "looming.TruthEvent",
                include_str!("../../schemas/looming.TruthEvent.schema.json"),
            ))?,
        };
        let start_s = first_scan as f64 * world.period_s;
        let first_index = |rate_hz: f64| (start_s * rate_hz - 1e-9).ceil().max(0.0) as u64;
        let mut log = Self {
            channels,
            motion_until_s: start_s,
            imu_index: first_index(world.scenario.imu.rate_hz),
            velocity_index: first_index(world.scenario.velocity_rate_hz),
            pending: Vec::new(),
        };
        let tf = tf_static(world, start_s);
        log.push(
            log.channels.tf_static,
            stamp_ns(start_s),
            tf.encode_cdr(false),
        );
        Ok(log)
    }

    fn push(&mut self, channel: u16, log_time_ns: i64, data: Vec<u8>) {
        self.pending.push(Encoded {
            channel,
            log_time_ns,
            data,
        });
    }

    /// Everything encoded since the last call, in log-time order.
    pub fn take(&mut self) -> Vec<Encoded> {
        std::mem::take(&mut self.pending)
    }

    /// Motion messages stamped before the end of `scan`'s sweep, then the scan
    /// and its truth, published when the sweep ends.
    pub fn encode_interval(&mut self, world: &World, scan: &SimScan, seed: u64) {
        let sweep_end_s = scan.stamp_s + world.period_s;
        self.encode_motion_until(world, sweep_end_s, seed);
        let log_time_ns = stamp_ns(sweep_end_s);
        let shape = CloudShape::new(world, scan);
        self.push(
            self.channels.lidar,
            log_time_ns,
            lidar_cloud(world, scan, &shape).encode_cdr(false),
        );
        self.push(
            self.channels.truth_points,
            log_time_ns,
            truth_cloud(scan, &shape).encode_cdr(false),
        );
        let truth = serde_json::to_vec(&TruthScan::new(world, scan)).expect("truth serialises");
        self.push(self.channels.truth_scan, log_time_ns, truth);
    }

    /// IMU, twist and odometry messages with stamps in [motion_until_s, until_s).
    fn encode_motion_until(&mut self, world: &World, until_s: f64, seed: u64) {
        let imu_period_s = 1.0 / world.scenario.imu.rate_hz;
        let velocity_period_s = 1.0 / world.scenario.velocity_rate_hz;
        loop {
            let next_imu_s = self.imu_index as f64 * imu_period_s;
            let next_velocity_s = self.velocity_index as f64 * velocity_period_s;
            let next_s = next_imu_s.min(next_velocity_s);
            if next_s >= until_s - 1e-12 {
                break;
            }
            if next_imu_s <= next_velocity_s {
                let imu = imu_message(world, next_imu_s, self.imu_index, seed);
                self.push(
                    self.channels.imu,
                    stamp_ns(next_imu_s),
                    imu.encode_cdr(false),
                );
                self.imu_index += 1;
            } else {
                let (twist, odometry) = velocity_messages(world, next_velocity_s);
                let stamp = stamp_ns(next_velocity_s);
                self.push(self.channels.twist, stamp, twist.encode_cdr(false));
                self.push(self.channels.odometry, stamp, odometry.encode_cdr(false));
                self.velocity_index += 1;
            }
        }
        self.motion_until_s = until_s;
    }

    pub fn encode_events(&mut self, events: &[TruthEvent]) {
        for event in events {
            let data = serde_json::to_vec(event).expect("events serialise");
            self.push(self.channels.truth_events, event.start_ns, data);
        }
    }
}

/// One point of a written cloud: a return, or a pixel without one.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Slot {
    /// Index into the scan's points.
    Return(u32),
    /// No return from this beam and column (dense layouts only).
    Empty { ring: u16, column: u32 },
}

/// Which point goes where in a written cloud (and in its `/truth/points`).
#[derive(Debug, Clone)]
pub struct CloudShape {
    pub height: u32,
    pub width: u32,
    /// Row by row.
    pub slots: Vec<Slot>,
}

impl CloudShape {
    pub fn new(world: &World, scan: &SimScan) -> Self {
        let beams = world.lasers.len();
        let columns = world.scenario.lidar.columns as usize;
        let returns = || (0..scan.points.len() as u32).map(Slot::Return);
        let unorganized = |slots: Vec<Slot>| Self {
            height: 1,
            width: slots.len() as u32,
            slots,
        };
        // A beams x columns grid, the pixel of (ring, column) at `at(ring, column)`.
        let grid = |at: &dyn Fn(usize, usize) -> usize| {
            let mut slots = vec![Slot::Return(0); beams * columns];
            for ring in 0..beams {
                for column in 0..columns {
                    slots[at(ring, column)] = Slot::Empty {
                        ring: ring as u16,
                        column: column as u32,
                    };
                }
            }
            for (i, p) in scan.points.iter().enumerate() {
                slots[at(usize::from(p.ring), p.column as usize)] = Slot::Return(i as u32);
            }
            slots
        };
        match world.scenario.lidar.layout {
            CloudLayout::RingTime
            | CloudLayout::RingField(_)
            | CloudLayout::FiringOrder { sparse: true } => unorganized(returns().collect()),
            CloudLayout::LaserOrder(order) => {
                let mut slots: Vec<Slot> = returns().collect();
                let key = |slot: &Slot| {
                    let Slot::Return(i) = *slot else {
                        return (0, 0);
                    };
                    let p = &scan.points[i as usize];
                    match order {
                        // Points are in firing order already: a stable sort by ring.
                        LaserOrder::LowestFirst => (usize::from(p.ring), 0),
                        // Top laser first; counter-clockwise from straight
                        // ahead (column columns/2) is decreasing column.
                        LaserOrder::Kitti => (
                            beams - 1 - usize::from(p.ring),
                            (columns + columns / 2 - p.column as usize) % columns,
                        ),
                    }
                };
                slots.sort_by_key(key);
                unorganized(slots)
            }
            CloudLayout::Organized => Self {
                height: beams as u32,
                width: columns as u32,
                slots: grid(&|ring, column| (beams - 1 - ring) * columns + column),
            },
            CloudLayout::FiringOrder { sparse: false } => {
                unorganized(grid(&|ring, column| column * beams + ring))
            }
        }
    }

    fn point<'s>(&self, scan: &'s SimScan, slot: Slot) -> Option<&'s SimPoint> {
        match slot {
            Slot::Return(i) => scan.points.get(i as usize),
            Slot::Empty { .. } => None,
        }
    }

    fn dense(&self) -> bool {
        self.slots.iter().all(|s| matches!(s, Slot::Return(_)))
    }
}

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

/// `/lidar/points` in the scenario's layout.
fn lidar_cloud(world: &World, scan: &SimScan, shape: &CloudShape) -> PointCloud2<'static> {
    let layout = world.scenario.lidar.layout;
    if layout == CloudLayout::RingTime {
        return ring_time_cloud(scan);
    }
    let mut packer = Packer::new();
    let [x, y, z] = ["x", "y", "z"].map(|name| packer.add(name, datatype::FLOAT32));
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
    let ps = point_step as usize;
    let beams = world.lasers.len();
    let mut data = vec![0u8; shape.slots.len() * ps];
    for (&slot, out) in shape.slots.iter().zip(data.chunks_exact_mut(ps)) {
        let (ring_index, column) = match (slot, shape.point(scan, slot)) {
            (_, Some(p)) => (p.ring, p.column),
            (Slot::Empty { ring, column }, None) => (ring, column),
            (Slot::Return(_), None) => (0, 0),
        };
        let point = shape.point(scan, slot);
        let xyz = point.map_or([f32::NAN; 3], |p| p.point_m);
        for (offset, value) in [x, y, z].into_iter().zip(xyz) {
            put_f32(out, offset, value);
        }
        put_f32(out, intensity, point.map_or(0.0, |p| p.intensity));
        if let Some((offset, datatype)) = ring {
            // Ouster numbers rows from the top beam, Velodyne rings from the lowest.
            let value = if layout == CloudLayout::Organized {
                beams - 1 - usize::from(ring_index)
            } else {
                usize::from(ring_index)
            };
            put(out, offset, datatype, value as f64);
        }
        let column_time_s = world.column_time_s(column);
        if let Some(offset) = time_s {
            put_f32(out, offset, column_time_s as f32);
        }
        if let Some(offset) = time_ns {
            put(out, offset, datatype::UINT32, (column_time_s * 1e9).round());
        }
        if let Some(offset) = reflectivity {
            put(
                out,
                offset,
                datatype::UINT16,
                point.map_or(0.0, |p| f64::from(p.intensity).round()),
            );
        }
        if let Some(offset) = range_mm {
            let range_m = point.map_or(0.0, |p| {
                let [x, y, z] = p.point_m.map(f64::from);
                (x * x + y * y + z * z).sqrt()
            });
            put(out, offset, datatype::UINT32, (range_m * 1000.0).round());
        }
    }
    PointCloud2 {
        header: Header::new(stamp_ns(scan.stamp_s), LIDAR_FRAME),
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

/// The Velodyne-driver cloud of `ring-time` (as before layouts existed).
fn ring_time_cloud(scan: &SimScan) -> PointCloud2<'static> {
    let points: Vec<[f32; 3]> = scan.points.iter().map(|p| p.point_m).collect();
    let intensity: Vec<f32> = scan.points.iter().map(|p| p.intensity).collect();
    let ring: Vec<u16> = scan.points.iter().map(|p| p.ring).collect();
    let time: Vec<f32> = scan.points.iter().map(|p| p.time_s).collect();
    pointcloud2_from_points(
        stamp_ns(scan.stamp_s),
        LIDAR_FRAME,
        &points,
        Some(&intensity),
        Some(&ring),
        Some(&time),
    )
}

/// Field layout of `/truth/points` (one point per `/lidar/points` point, same order).
const TRUTH_POINT_STEP: u32 = 28;

/// `surface` of a `/truth/points` entry for a pixel without a return.
pub const NO_RETURN_SURFACE: u8 = 255;

fn truth_cloud(scan: &SimScan, shape: &CloudShape) -> PointCloud2<'static> {
    // No x, y, z: the noise-free point is `range` along the measured point's
    // direction, and leaving them out keeps the sample logs small.
    let fields = vec![
        PointField::new("range", 0, datatype::FLOAT32),
        PointField::new("point_looming", 4, datatype::FLOAT32),
        PointField::new("ray_looming", 8, datatype::FLOAT32),
        PointField::new("own_motion_looming", 12, datatype::FLOAT32),
        PointField::new("incidence_cos", 16, datatype::FLOAT32),
        PointField::new("object_id", 20, datatype::UINT32),
        PointField::new("surface", 24, datatype::UINT8),
        PointField::new("moving", 25, datatype::UINT8),
    ];
    let mut data = Vec::with_capacity(shape.slots.len() * TRUTH_POINT_STEP as usize);
    for &slot in &shape.slots {
        let Some(point) = shape.point(scan, slot) else {
            // A pixel without a return: NaN values, object 0, surface 255.
            for _ in 0..5 {
                data.extend_from_slice(&f32::NAN.to_le_bytes());
            }
            data.extend_from_slice(&0u32.to_le_bytes());
            data.extend_from_slice(&[NO_RETURN_SURFACE, 0, 0, 0]);
            continue;
        };
        let truth = &point.truth;
        data.extend_from_slice(&(truth.range_m as f32).to_le_bytes());
        data.extend_from_slice(&(truth.point_looming_per_s as f32).to_le_bytes());
        data.extend_from_slice(&(truth.ray_looming_per_s as f32).to_le_bytes());
        data.extend_from_slice(&(truth.own_motion_looming_per_s as f32).to_le_bytes());
        data.extend_from_slice(&(truth.incidence_cos as f32).to_le_bytes());
        data.extend_from_slice(&truth.object_id.to_le_bytes());
        data.push(truth.surface as u8);
        data.push(u8::from(truth.moving));
        data.extend_from_slice(&[0, 0]);
    }
    PointCloud2 {
        header: Header::new(stamp_ns(scan.stamp_s), LIDAR_FRAME),
        height: shape.height,
        width: shape.width,
        fields,
        is_bigendian: false,
        point_step: TRUTH_POINT_STEP,
        row_step: shape.width * TRUTH_POINT_STEP,
        data: data.into(),
        is_dense: shape.dense(),
    }
}

/// `/imu/data` at `t_s`: gyro and specific force in the vehicle frame, with
/// seeded Gaussian noise (a generator per sample index: order independent).
fn imu_message(world: &World, t_s: f64, index: u64, seed: u64) -> Imu {
    let ego = world.track.state(t_s);
    let (mut force, mut gyro) = ego.imu_reading();
    let spec = &world.scenario.imu;
    let mut rng = rand_chacha::ChaCha8Rng::seed_from_u64(
        seed ^ 0x1A2B_3C4D ^ index.wrapping_mul(0xD1B5_4A32_D192_ED03),
    );
    if let (Ok(gyro_noise), Ok(accel_noise)) = (
        Normal::new(0.0, spec.gyro_noise_radps.max(0.0)),
        Normal::new(0.0, spec.accel_noise_mps2.max(0.0)),
    ) {
        for c in gyro.iter_mut() {
            *c += gyro_noise.sample(&mut rng);
        }
        for c in force.iter_mut() {
            *c += accel_noise.sample(&mut rng);
        }
    }
    let orientation = UnitQuaternion::from_axis_angle(&Vector3::z_axis(), ego.yaw_rad);
    let diagonal = |v: f64| [v, 0.0, 0.0, 0.0, v, 0.0, 0.0, 0.0, v];
    Imu {
        header: Header::new(stamp_ns(t_s), VEHICLE_FRAME),
        orientation: Quaternion::from(&orientation),
        orientation_covariance: diagonal(1e-4),
        angular_velocity: RosVector3::from(&gyro),
        angular_velocity_covariance: diagonal(spec.gyro_noise_radps.powi(2)),
        linear_acceleration: RosVector3::from(&force),
        linear_acceleration_covariance: diagonal(spec.accel_noise_mps2.powi(2)),
    }
}

/// `/vehicle/twist` and `/odom` at `t_s`, exact, in the vehicle frame.
fn velocity_messages(world: &World, t_s: f64) -> (TwistStamped, Odometry) {
    let ego = world.track.state(t_s);
    let twist = Twist {
        linear: RosVector3::new(ego.speed_mps, 0.0, 0.0),
        angular: RosVector3::new(0.0, 0.0, ego.yaw_rate_radps),
    };
    let orientation = UnitQuaternion::from_axis_angle(&Vector3::z_axis(), ego.yaw_rad);
    let odometry = Odometry {
        header: Header::new(stamp_ns(t_s), ODOM_FRAME),
        child_frame_id: VEHICLE_FRAME.into(),
        pose: PoseWithCovariance {
            pose: Pose {
                position: RosVector3::from(&ego.position_m),
                orientation: Quaternion::from(&orientation),
            },
            covariance: [0.0; 36],
        },
        twist: TwistWithCovariance {
            twist,
            covariance: [0.0; 36],
        },
    };
    (
        TwistStamped {
            header: Header::new(stamp_ns(t_s), VEHICLE_FRAME),
            twist,
        },
        odometry,
    )
}

/// `/tf_static`: the LiDAR mount in the vehicle/IMU frame.
fn tf_static(world: &World, start_s: f64) -> TFMessage {
    let mount = &world.vehicle_from_lidar;
    TFMessage {
        transforms: vec![TransformStamped {
            header: Header::new(stamp_ns(start_s), VEHICLE_FRAME),
            child_frame_id: LIDAR_FRAME.into(),
            transform: Transform {
                translation: RosVector3::from(&mount.translation.vector),
                rotation: Quaternion::from(&mount.rotation),
            },
        }],
    }
}
