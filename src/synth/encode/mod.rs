//! Turning the simulation into MCAP messages, in log-time order: the ROS 2
//! CDR sensor messages (`/lidar/points` in `lidar_cloud.rs`, the motion
//! messages in `motion.rs`), the truth point cloud (`truth_cloud.rs`) and the
//! JSON truth records. [`SynthLog`] encodes, [`SequencedWriter`] writes; a
//! cloud's slots are laid out by [`CloudShape`].

mod lidar_cloud;
mod motion;
mod shape;
mod truth_cloud;
mod writer;

use crate::output::{OutputError, OutputWriter, OwnChannelSpec};
use crate::ros::schemas::{self as ros_schemas, RosDialect};

use super::rig::RigLidar;
use super::scene::CloudFrame;
use super::sensor::{SimScan, World};
use super::truth::{TruthEvent, TruthScan};

use lidar_cloud::lidar_cloud;
use motion::{imu_message, tf_static, velocity_messages};
pub use shape::{CloudShape, Slot};
use truth_cloud::truth_cloud;
pub use writer::SequencedWriter;

/// Wall-clock time of the start of every synthetic drive (fixed, so the same
/// arguments give the same bytes): 2023-11-14T22:13:20Z.
pub const START_NS: i64 = 1_700_000_000_000_000_000;

pub const LIDAR_FRAME: &str = "lidar";
pub(crate) const VEHICLE_FRAME: &str = "imu_link";
pub(crate) const ODOM_FRAME: &str = "odom";

/// Topics of a synthetic log.
pub mod topics {
    pub const LIDAR: &str = "/lidar/points";
    pub const IMU: &str = "/imu/data";
    pub const TWIST: &str = "/vehicle/twist";
    pub const ODOMETRY: &str = "/odom";
    pub const TF_STATIC: &str = "/tf_static";
    pub const TF: &str = "/tf";
    pub const TRUTH_POINTS: &str = crate::truth::POINTS_TOPIC;
    pub const TRUTH_SCAN: &str = crate::truth::SCAN_TOPIC;
    pub const TRUTH_EVENTS: &str = crate::truth::EVENTS_TOPIC;
}

/// Seconds from the start of the drive to a ROS stamp, ns.
pub fn stamp_ns(t_s: f64) -> i64 {
    START_NS + (t_s * 1e9).round() as i64
}

/// The ids of one LiDAR's channels.
struct LidarChannels {
    lidar: u16,
    truth_points: u16,
    truth_scan: u16,
}

/// The ids of a synthetic log's channels, one per topic.
struct Channels {
    /// Per LiDAR of the rig, in its order.
    lidars: Vec<LidarChannels>,
    imu: u16,
    twist: u16,
    odometry: u16,
    tf_static: u16,
    truth_events: u16,
    /// `/tf` (`odom -> imu_link`), for clouds in the world frame only.
    tf: Option<u16>,
}

impl Channels {
    /// Register every channel of a synthetic log with `writer`: the LiDARs'
    /// clouds, the motion and `/tf_static`, the LiDARs' truth, the events.
    fn register(writer: &mut OutputWriter, rig: &[RigLidar]) -> Result<Self, OutputError> {
        let d = RosDialect::Ros2;
        let mut add = |spec: OwnChannelSpec| writer.add_own_channel(&spec);
        let cloud = |topic: &str| {
            OwnChannelSpec::ros2(
                topic,
                "sensor_msgs",
                "PointCloud2",
                ros_schemas::point_cloud2(d),
            )
        };
        let clouds = per_topic(rig, |topic| add(cloud(topic)))?;
        let imu = add(OwnChannelSpec::ros2(
            topics::IMU,
            "sensor_msgs",
            "Imu",
            ros_schemas::imu(d),
        ))?;
        let twist = add(OwnChannelSpec::ros2(
            topics::TWIST,
            "geometry_msgs",
            "TwistStamped",
            ros_schemas::twist_stamped(d),
        ))?;
        let odometry = add(OwnChannelSpec::ros2(
            topics::ODOMETRY,
            "nav_msgs",
            "Odometry",
            ros_schemas::odometry(d),
        ))?;
        let tf_static = add(OwnChannelSpec::ros2(
            topics::TF_STATIC,
            "tf2_msgs",
            "TFMessage",
            ros_schemas::tf_message(d),
        ))?;
        let mut lidars = Vec::with_capacity(rig.len());
        for (lidar, cloud_id) in rig.iter().zip(clouds) {
            lidars.push(LidarChannels {
                lidar: cloud_id,
                truth_points: add(cloud(&lidar.truth_points_topic))?,
                truth_scan: add(OwnChannelSpec::json(
                    &lidar.truth_scan_topic,
                    "looming.TruthScan",
                    include_str!("../../../schemas/looming.TruthScan.schema.json"),
                ))?,
            });
        }
        let truth_events = add(OwnChannelSpec::json(
            topics::TRUTH_EVENTS,
            "looming.TruthEvent",
            include_str!("../../../schemas/looming.TruthEvent.schema.json"),
        ))?;
        // Last: the other channels keep their ids whatever the frame.
        let world_frame = rig[0].world.scenario.lidar.cloud_frame == CloudFrame::World;
        let tf = if world_frame {
            Some(add(OwnChannelSpec::ros2(
                topics::TF,
                "tf2_msgs",
                "TFMessage",
                ros_schemas::tf_message(d),
            ))?)
        } else {
            None
        };
        Ok(Self {
            lidars,
            imu,
            twist,
            odometry,
            tf_static,
            truth_events,
            tf,
        })
    }
}

/// A channel per distinct topic of `rig`'s LiDARs (those sharing one,
/// `--one-topic`, share its channel), each LiDAR's in rig order.
fn per_topic(
    rig: &[RigLidar],
    mut add: impl FnMut(&str) -> Result<u16, OutputError>,
) -> Result<Vec<u16>, OutputError> {
    let mut by_topic = std::collections::BTreeMap::new();
    let mut clouds = Vec::with_capacity(rig.len());
    for lidar in rig {
        let id = match by_topic.get(&lidar.topic) {
            Some(&id) => id,
            None => add(&lidar.topic)?,
        };
        by_topic.insert(lidar.topic.clone(), id);
        clouds.push(id);
    }
    Ok(clouds)
}

/// One encoded message for the writer.
#[derive(Debug, Clone)]
pub(crate) struct Encoded {
    pub channel: u16,
    pub log_time_ns: i64,
    pub data: Vec<u8>,
}

/// Encodes a synthetic drive into messages, interval by interval. It does no
/// I/O, so it can run on its own thread while [`SequencedWriter`] writes.
pub(crate) struct SynthLog {
    channels: Channels,
    /// Motion messages are generated up to here (exclusive), seconds.
    motion_until_s: f64,
    imu_index: u64,
    velocity_index: u64,
    pending: Vec<Encoded>,
    /// With every LiDAR on one topic: each LiDAR's latest cloud not yet
    /// merged (the roof's slot unused).
    latest: Vec<Option<crate::ros::msgs::PointCloud2<'static>>>,
}

impl SynthLog {
    /// Register the channels of `rig` and queue `/tf_static`; messages start
    /// at `start_s` (the first scan's start). The motion is the roof LiDAR's
    /// world's.
    pub fn new(
        writer: &mut OutputWriter,
        rig: &[RigLidar],
        start_s: f64,
    ) -> Result<Self, OutputError> {
        let channels = Channels::register(writer, rig)?;
        let world = &rig[0].world;
        let first_index = |rate_hz: f64| (start_s * rate_hz - 1e-9).ceil().max(0.0) as u64;
        let mut log = Self {
            channels,
            motion_until_s: start_s,
            imu_index: first_index(world.scenario.imu.rate_hz),
            velocity_index: first_index(world.scenario.velocity_rate_hz),
            pending: Vec::new(),
            latest: vec![None; rig.len()],
        };
        let tf = tf_static(rig, start_s);
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

    /// Motion messages (of `motion`, the roof LiDAR's world) stamped before
    /// the end of `scan`'s sweep, then the scan of LiDAR `k` of the rig and
    /// its truth, published when the sweep ends.
    pub fn encode_interval(
        &mut self,
        motion: &World,
        (k, lidar): (usize, &RigLidar),
        scan: &SimScan,
        seed: u64,
    ) {
        let world = &lidar.world;
        let sweep_end_s = scan.stamp_s + world.period_s;
        self.encode_motion_until(motion, sweep_end_s, seed);
        let log_time_ns = stamp_ns(sweep_end_s);
        let shape = CloudShape::new(world, scan);
        let channels = &self.channels.lidars[k];
        let (cloud, truth_points, truth_scan) =
            (channels.lidar, channels.truth_points, channels.truth_scan);
        let frame = lidar.name.as_str();
        let mut points = lidar_cloud(world, scan, &shape, frame);
        match motion.scenario.lidar.cloud_frame {
            CloudFrame::Sensor => {}
            CloudFrame::Vehicle => {
                lidar_cloud::into_frame(&mut points, &world.vehicle_from_lidar, VEHICLE_FRAME);
            }
            CloudFrame::World => {
                let world_from_vehicle = motion::world_from_vehicle(motion, scan.stamp_s);
                let world_from_lidar = world_from_vehicle * world.vehicle_from_lidar;
                lidar_cloud::into_frame(&mut points, &world_from_lidar, ODOM_FRAME);
            }
        }
        if let Some(merged) = self.merge(k, lidar, points) {
            self.push(cloud, log_time_ns, merged.encode_cdr(false));
        }
        self.push(
            truth_points,
            log_time_ns,
            truth_cloud(scan, &shape, frame).encode_cdr(false),
        );
        let truth =
            serde_json::to_vec(&TruthScan::of_lidar(world, scan, frame)).expect("truth serialises");
        self.push(truth_scan, log_time_ns, truth);
    }

    /// The cloud to publish now: `points` itself; with every LiDAR on one
    /// topic (`rig::on_one_topic`), what a concatenating node (Autoware's)
    /// publishes at the roof LiDAR's rate: the roof's scan with the latest
    /// scan of every other LiDAR, each point tagged with its LiDAR, and
    /// nothing when another LiDAR's scan ends (it waits for the roof's).
    fn merge(
        &mut self,
        k: usize,
        lidar: &RigLidar,
        mut points: crate::ros::msgs::PointCloud2<'static>,
    ) -> Option<crate::ros::msgs::PointCloud2<'static>> {
        let Some(sensor_id) = lidar.sensor_id else {
            return Some(points);
        };
        lidar_cloud::tag_sensor(&mut points, sensor_id);
        if k != 0 {
            self.latest[k] = Some(points);
            return None;
        }
        let others: Vec<_> = self.latest.iter_mut().filter_map(Option::take).collect();
        Some(lidar_cloud::concatenate(points, &others))
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
                if let Some(tf) = self.channels.tf {
                    let transform = motion::world_tf(world, next_velocity_s);
                    self.push(tf, stamp, transform.encode_cdr(false));
                }
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
