//! Writing a KITTI raw drive as a ROS 2 MCAP: `/velodyne_points`
//! (`sensor_msgs/PointCloud2` with x, y, z, intensity, ring and a per-point
//! `time`), `/oxts/imu` (`sensor_msgs/Imu`), `/oxts/twist`
//! (`geometry_msgs/TwistStamped`) and `/tf_static` (`imu_link` -> `velo_link`).
//!
//! Scans are streamed one at a time; the OXTS packets (100 Hz, small) are read
//! first and interleaved by log time.

use std::collections::BTreeMap;
use std::path::{Path, PathBuf};
use std::time::Instant;

use nalgebra::Isometry3;

use crate::output::{OutputError, OutputOptions, OutputWriter, OwnChannelSpec};
use crate::ros::msgs::{
    Header, Imu, Quaternion, TFMessage, Transform, TransformStamped, Twist, TwistStamped,
    Vector3 as RosVector3, pointcloud2_from_points,
};
use crate::ros::schemas::{self as ros_schemas, RosDialect};

use super::KittiError;
use super::calib::read_imu_to_velo;
use super::oxts::{OxtsPacket, read_oxts_file};
use super::timestamps::read_timestamps;
use super::velodyne::{derive_rings, read_bin, sweep_fraction};

pub const LIDAR_TOPIC: &str = "/velodyne_points";
pub const IMU_TOPIC: &str = "/oxts/imu";
pub const TWIST_TOPIC: &str = "/oxts/twist";
pub(crate) const TF_STATIC_TOPIC: &str = "/tf_static";
pub const LIDAR_FRAME: &str = "velo_link";
pub const IMU_FRAME: &str = "imu_link";

/// The HDL-64E of KITTI turns at 10 Hz.
const DEFAULT_PERIOD_S: f64 = 0.1;
/// Missing frames listed in full in the summary (all are counted).
const LISTED_MISSING: usize = 20;

/// `looming import-kitti` settings.
#[derive(Debug, Clone)]
pub struct ImportOptions {
    /// The drive folder (`..._drive_NNNN_sync` or `_extract`).
    pub drive_dir: PathBuf,
    /// Folder of `calib_imu_to_velo.txt` [default: the drive folder's parent].
    pub calib_dir: Option<PathBuf>,
    pub output: PathBuf,
    pub output_options: OutputOptions,
    /// Most points accepted in one scan.
    pub max_points: usize,
    /// Which way the scanner turns, for the per-point times.
    pub sweep: SweepDirection,
}

/// Which way a spinning LiDAR turns, seen from above; its sweep starts behind.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Default, serde::Serialize, clap::ValueEnum)]
#[serde(rename_all = "snake_case")]
pub enum SweepDirection {
    /// Measured on KITTI's HDL-64E (docs/kitti.md): timing points this way
    /// removes the motion seam behind the car.
    #[default]
    CounterClockwise,
    /// The other way (`looming synth`'s sensor, many Velodyne drivers).
    Clockwise,
}

impl SweepDirection {
    /// Fraction of the sweep at which the point `(x, y)` was fired.
    pub fn fraction(self, x: f32, y: f32) -> f64 {
        match self {
            SweepDirection::CounterClockwise => sweep_fraction(x, y),
            SweepDirection::Clockwise => {
                let azimuth_rad = f64::from(y).atan2(f64::from(x));
                ((std::f64::consts::PI - azimuth_rad) / std::f64::consts::TAU).rem_euclid(1.0)
            }
        }
    }
}

#[derive(Debug, thiserror::Error)]
pub enum ImportError {
    #[error(transparent)]
    Kitti(#[from] KittiError),
    #[error(transparent)]
    Output(#[from] OutputError),
}

/// What an import wrote.
#[derive(Debug, Clone, Default, serde::Serialize)]
pub struct ImportSummary {
    pub drive: String,
    pub output: String,
    pub scans_written: u64,
    pub points_written: u64,
    /// Frames listed in the timestamps whose `.bin` is missing (skipped).
    pub scans_missing: u64,
    pub oxts_written: u64,
    pub oxts_missing: u64,
    /// Where each scan's sweep start and end come from.
    pub sweep_times: String,
    pub sweep_direction: SweepDirection,
    /// Scans whose rings could be derived from the point order.
    pub scans_with_rings: u64,
    pub calibration: Option<String>,
    pub warnings: Vec<String>,
    pub output_bytes: u64,
    pub elapsed_s: f64,
}

/// The files of a drive folder.
struct DriveFiles {
    velodyne_dir: PathBuf,
    oxts_dir: Option<PathBuf>,
    calib: Option<PathBuf>,
}

/// Import a KITTI raw drive folder.
pub fn import_kitti(options: &ImportOptions) -> Result<ImportSummary, ImportError> {
    let started = Instant::now();
    let files = locate(options)?;
    let mut summary = ImportSummary {
        drive: options.drive_dir.display().to_string(),
        output: options.output.display().to_string(),
        sweep_direction: options.sweep,
        ..ImportSummary::default()
    };
    let sweeps = sweep_times(&files.velodyne_dir, &mut summary)?;
    let oxts = match &files.oxts_dir {
        Some(dir) => read_oxts(dir, &mut summary)?,
        None => {
            summary
                .warnings
                .push("no oxts folder: LiDAR only (no velocity, no IMU)".into());
            Vec::new()
        }
    };
    let velo_from_imu = match &files.calib {
        Some(path) => {
            summary.calibration = Some(path.display().to_string());
            Some(read_imu_to_velo(path)?)
        }
        None => None,
    };
    let output_options = OutputOptions {
        profile: "ros2".into(),
        ..options.output_options.clone()
    };
    let mut writer = OutputWriter::create(&options.output, &output_options, &Default::default())?;
    let channels = Channels::register(&mut writer)?;
    let mut sink = Sink::new(&mut writer);
    if let (Some(velo_from_imu), Some(first)) = (velo_from_imu, sweeps.first()) {
        let tf = tf_static(first.start_ns, &velo_from_imu);
        sink.write(channels.tf_static, first.start_ns, &tf.encode_cdr(false))?;
    }
    let mut pending_oxts = oxts.iter().peekable();
    for sweep in &sweeps {
        let log_time_ns = sweep.end_ns;
        while let Some((stamp_ns, packet)) = pending_oxts.next_if(|(t, _)| *t <= log_time_ns) {
            write_oxts(&mut sink, &channels, *stamp_ns, packet)?;
        }
        let bin = files
            .velodyne_dir
            .join("data")
            .join(format!("{:010}.bin", sweep.index));
        if !bin.exists() {
            note_missing(&mut summary, &bin, "scan");
            summary.scans_missing += 1;
            continue;
        }
        let points = read_bin(&bin, options.max_points)?;
        let cloud = scan_cloud(sweep, &points, options.sweep, &mut summary);
        sink.write(channels.lidar, log_time_ns, &cloud)?;
        summary.scans_written += 1;
        summary.points_written += points.len() as u64;
    }
    for (stamp_ns, packet) in pending_oxts {
        write_oxts(&mut sink, &channels, *stamp_ns, packet)?;
    }
    summary.oxts_written = oxts.len() as u64;
    if velo_from_imu.is_none() && !oxts.is_empty() {
        summary.warnings.push(
            "no calib_imu_to_velo.txt: no /tf_static, so the LiDAR's pose in the IMU frame must be given to `looming process`".into(),
        );
    }
    summary.output_bytes = writer.finish()?;
    summary.elapsed_s = started.elapsed().as_secs_f64();
    Ok(summary)
}

fn locate(options: &ImportOptions) -> Result<DriveFiles, KittiError> {
    let drive = &options.drive_dir;
    if !drive.is_dir() {
        return Err(KittiError::Missing {
            path: drive.clone(),
            what: "the drive folder".into(),
        });
    }
    let velodyne_dir = drive.join("velodyne_points");
    if !velodyne_dir.join("timestamps.txt").is_file() {
        return Err(KittiError::Missing {
            path: velodyne_dir.join("timestamps.txt"),
            what: "the Velodyne timestamps (is this a KITTI raw drive folder?)".into(),
        });
    }
    let oxts_dir = drive.join("oxts");
    let oxts_dir = oxts_dir
        .join("timestamps.txt")
        .is_file()
        .then_some(oxts_dir);
    let calib_dir = match &options.calib_dir {
        Some(dir) => dir.clone(),
        None => drive.parent().map(Path::to_path_buf).unwrap_or_default(),
    };
    let calib = calib_dir.join("calib_imu_to_velo.txt");
    let calib = match (calib.is_file(), &options.calib_dir) {
        (true, _) => Some(calib),
        (false, Some(_)) => {
            return Err(KittiError::Missing {
                path: calib,
                what: "the IMU-to-Velodyne calibration in the calibration folder given".into(),
            });
        }
        (false, None) if oxts_dir.is_some() => {
            return Err(KittiError::Missing {
                path: calib,
                what:
                    "the IMU-to-Velodyne calibration (it sits in the date folder, or in the calibration folder given)"
                        .into(),
            });
        }
        (false, None) => None,
    };
    Ok(DriveFiles {
        velodyne_dir,
        oxts_dir,
        calib,
    })
}

/// One scan's sweep: its frame number and when it started and ended.
struct Sweep {
    index: usize,
    start_ns: i64,
    end_ns: i64,
}

/// Sweep start and end per frame: from `timestamps_start.txt` and
/// `timestamps_end.txt` when both are there, else around `timestamps.txt`
/// (the moment the laser faces forward, mid-sweep, when the cameras fire).
fn sweep_times(dir: &Path, summary: &mut ImportSummary) -> Result<Vec<Sweep>, KittiError> {
    let mid = read_timestamps(&dir.join("timestamps.txt"))?;
    let (start_path, end_path) = (
        dir.join("timestamps_start.txt"),
        dir.join("timestamps_end.txt"),
    );
    let bounds = if start_path.is_file() && end_path.is_file() {
        let (start, end) = (read_timestamps(&start_path)?, read_timestamps(&end_path)?);
        for (path, list) in [(&start_path, &start), (&end_path, &end)] {
            if list.len() != mid.len() {
                return Err(KittiError::Invalid {
                    path: path.clone(),
                    reason: format!("{} lines, but timestamps.txt has {}", list.len(), mid.len()),
                });
            }
        }
        summary.sweep_times = "timestamps_start.txt / timestamps_end.txt".into();
        Some((start, end))
    } else {
        summary.sweep_times = format!(
            "timestamps.txt taken as mid-sweep, period {} s (no timestamps_start/end.txt)",
            median_period_s(&mid)
        );
        None
    };
    let half_period_ns = (median_period_s(&mid) * 0.5e9).round() as i64;
    let mut reversed: Vec<usize> = Vec::new();
    let sweeps = (0..mid.len())
        .map(|index| match &bounds {
            Some((start, end)) if end[index] > start[index] => Sweep {
                index,
                start_ns: start[index],
                end_ns: end[index],
            },
            bounds => {
                if bounds.is_some() {
                    reversed.push(index);
                }
                Sweep {
                    index,
                    start_ns: mid[index] - half_period_ns,
                    end_ns: mid[index] + half_period_ns,
                }
            }
        })
        .collect();
    if let Some(first) = reversed.first() {
        summary.warnings.push(format!(
            "{}: {} frames (the first: line {}) end no later than they start; timed around timestamps.txt instead",
            end_path.display(),
            reversed.len(),
            first + 1
        ));
    }
    Ok(sweeps)
}

/// Median difference of consecutive stamps, seconds (0.1 s when unknown).
fn median_period_s(stamps_ns: &[i64]) -> f64 {
    let mut steps: Vec<i64> = stamps_ns
        .windows(2)
        .map(|w| w[1] - w[0])
        .filter(|d| *d > 0)
        .collect();
    if steps.is_empty() {
        return DEFAULT_PERIOD_S;
    }
    steps.sort_unstable();
    steps[steps.len() / 2] as f64 * 1e-9
}

/// Every OXTS packet with its stamp, in file order; missing files skipped.
fn read_oxts(
    dir: &Path,
    summary: &mut ImportSummary,
) -> Result<Vec<(i64, OxtsPacket)>, KittiError> {
    let stamps = read_timestamps(&dir.join("timestamps.txt"))?;
    let mut packets = Vec::with_capacity(stamps.len());
    for (index, stamp_ns) in stamps.into_iter().enumerate() {
        let path = dir.join("data").join(format!("{index:010}.txt"));
        if !path.exists() {
            note_missing(summary, &path, "OXTS packet");
            summary.oxts_missing += 1;
            continue;
        }
        packets.push((stamp_ns, read_oxts_file(&path)?));
    }
    // Interleaving with the scans needs log-time order.
    packets.sort_by_key(|(stamp_ns, _)| *stamp_ns);
    Ok(packets)
}

fn note_missing(summary: &mut ImportSummary, path: &Path, what: &str) {
    let missing = summary.scans_missing + summary.oxts_missing;
    if (missing as usize) < LISTED_MISSING {
        summary
            .warnings
            .push(format!("{}: missing {what}, skipped", path.display()));
    }
}

/// The scan as a PointCloud2: stamp = sweep start, per-point `time` from the
/// azimuth (the sweep starts behind and turns `direction`), `ring` from the
/// laser-by-laser point order when it can be derived.
fn scan_cloud(
    sweep: &Sweep,
    points: &[[f32; 4]],
    direction: SweepDirection,
    summary: &mut ImportSummary,
) -> Vec<u8> {
    let xyz: Vec<[f32; 3]> = points.iter().map(|p| [p[0], p[1], p[2]]).collect();
    let intensity: Vec<f32> = points.iter().map(|p| p[3]).collect();
    let sweep_s = (sweep.end_ns - sweep.start_ns) as f64 * 1e-9;
    let time_s: Vec<f32> = points
        .iter()
        .map(|p| (direction.fraction(p[0], p[1]) * sweep_s) as f32)
        .collect();
    let rings = derive_rings(points);
    if rings.is_some() {
        summary.scans_with_rings += 1;
    }
    pointcloud2_from_points(
        sweep.start_ns,
        LIDAR_FRAME,
        &xyz,
        Some(&intensity),
        rings.as_deref(),
        Some(&time_s),
    )
    .encode_cdr(false)
}

fn write_oxts(
    sink: &mut Sink<'_>,
    channels: &Channels,
    stamp_ns: i64,
    packet: &OxtsPacket,
) -> Result<(), OutputError> {
    let (imu, twist) = oxts_messages(stamp_ns, packet);
    sink.write(channels.imu, stamp_ns, &imu.encode_cdr(false))?;
    sink.write(channels.twist, stamp_ns, &twist.encode_cdr(false))
}

/// The packet as `sensor_msgs/Imu` (orientation from roll, pitch, yaw; rates
/// wf, wl, wu; accelerations af, al, au) and `geometry_msgs/TwistStamped`
/// (vf, vl, vu; wf, wl, wu), both in `imu_link` (x forward, y left, z up).
pub(crate) fn oxts_messages(stamp_ns: i64, packet: &OxtsPacket) -> (Imu, TwistStamped) {
    let unknown = [-1.0, 0.0, 0.0, 0.0, 0.0, 0.0, 0.0, 0.0, 0.0];
    let imu = Imu {
        header: Header::new(stamp_ns, IMU_FRAME),
        orientation: Quaternion::from(&packet.orientation()),
        orientation_covariance: [0.0; 9],
        angular_velocity: RosVector3::from(&packet.angular_velocity_vehicle_radps()),
        angular_velocity_covariance: unknown,
        linear_acceleration: RosVector3::from(&packet.acceleration_vehicle_mps2()),
        linear_acceleration_covariance: unknown,
    };
    let twist = TwistStamped {
        header: Header::new(stamp_ns, IMU_FRAME),
        twist: Twist {
            linear: RosVector3::from(&packet.velocity_vehicle_mps()),
            angular: RosVector3::from(&packet.angular_velocity_vehicle_radps()),
        },
    };
    (imu, twist)
}

/// `/tf_static`: the pose of `velo_link` in `imu_link`, the inverse of the
/// calibration's `p_velo = R p_imu + T`.
fn tf_static(stamp_ns: i64, velo_from_imu: &Isometry3<f64>) -> TFMessage {
    let imu_from_velo = velo_from_imu.inverse();
    TFMessage {
        transforms: vec![TransformStamped {
            header: Header::new(stamp_ns, IMU_FRAME),
            child_frame_id: LIDAR_FRAME.into(),
            transform: Transform {
                translation: RosVector3::from(&imu_from_velo.translation.vector),
                rotation: Quaternion::from(&imu_from_velo.rotation),
            },
        }],
    }
}

struct Channels {
    lidar: u16,
    imu: u16,
    twist: u16,
    tf_static: u16,
}

impl Channels {
    fn register(writer: &mut OutputWriter) -> Result<Self, OutputError> {
        let d = RosDialect::Ros2;
        let mut add = |topic: &str, package: &str, name: &str, definition: String| {
            writer.add_own_channel(&OwnChannelSpec::ros2(topic, package, name, definition))
        };
        Ok(Self {
            lidar: add(
                LIDAR_TOPIC,
                "sensor_msgs",
                "PointCloud2",
                ros_schemas::point_cloud2(d),
            )?,
            imu: add(IMU_TOPIC, "sensor_msgs", "Imu", ros_schemas::imu(d))?,
            twist: add(
                TWIST_TOPIC,
                "geometry_msgs",
                "TwistStamped",
                ros_schemas::twist_stamped(d),
            )?,
            tf_static: add(
                TF_STATIC_TOPIC,
                "tf2_msgs",
                "TFMessage",
                ros_schemas::tf_message(d),
            )?,
        })
    }
}

/// Writes messages with per-channel sequence numbers from 1.
struct Sink<'w> {
    writer: &'w mut OutputWriter,
    sequences: BTreeMap<u16, u32>,
}

impl<'w> Sink<'w> {
    fn new(writer: &'w mut OutputWriter) -> Self {
        Self {
            writer,
            sequences: BTreeMap::new(),
        }
    }

    fn write(&mut self, channel: u16, log_time_ns: i64, data: &[u8]) -> Result<(), OutputError> {
        let sequence = self.sequences.entry(channel).or_insert(0);
        *sequence += 1;
        self.writer
            .write_own_message(channel, *sequence, log_time_ns.max(0) as u64, data)
    }
}
