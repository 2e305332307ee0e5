//! Command-line arguments, clap only: the doc comments are the help text.
//! Values are checked and turned into the library's configuration in
//! [`super::resolve`].

use std::path::PathBuf;

use clap::{Args, Parser, Subcommand};

use super::choices::{
    FieldSet, NoLidarPolicy, OutputCompression, RenderChannel, RenderView, SweepDirection,
};

use super::resolve::{parse_shard, parse_split_field, parse_threat_ttc};

pub(crate) const EXIT_CODES: &str = "\
Exit codes:
  0  success (bad messages, if any, were skipped and are counted in the summary)
  1  failure: unreadable input, I/O error, output could not be written
  2  usage: bad arguments, unknown or ambiguous topic, output exists (see --force)
     or is the input, input already processed
  3  --strict and the input had a bad message, a bad chunk CRC or was truncated";

pub(crate) const BATCH_EXIT_CODES: &str = "\
Exit codes:
  0  every log processed, or skipped by policy (no LiDAR topic)
  1  at least one log failed (fleet.json says which and why), or OUT_DIR could
     not be written
  2  usage: bad arguments";

pub(crate) const SYNTH_EXIT_CODES: &str = "\
Exit codes:
  0  success
  1  failure: the output could not be written
  2  usage: bad arguments, unknown or invalid scenario, output exists (see --force)";

/// Looming (inverse time to contact) from LiDAR drive logs in MCAP.
///
/// Reads the LiDAR point clouds and IMU / velocity channels of a log, pairs
/// consecutive scans and writes a new MCAP holding every input record unchanged
/// plus looming channels.
#[derive(Debug, Parser)]
#[command(name = "looming", version, after_help = EXIT_CODES)]
pub struct Cli {
    #[command(subcommand)]
    pub(crate) command: Command,
}

#[derive(Debug, Subcommand)]
pub(crate) enum Command {
    /// Process a log: copy every record and add the /looming/* channels.
    #[command(after_help = EXIT_CODES)]
    Process(ProcessArgs),
    /// Process a fleet of logs: every *.mcap below a folder, single files or
    /// a manifest (.txt, one path per line), into OUT_DIR/logs/, with
    /// OUT_DIR/fleet.json and the near misses of every log ranked in
    /// OUT_DIR/near_misses.jsonl and .csv. A log whose output is complete and
    /// made from the same input and options is not run again.
    #[command(after_help = BATCH_EXIT_CODES)]
    Batch(BatchArgs),
    /// Show a log's channels, schemas, counts, rates, time span and the topics
    /// `process` would use.
    #[command(after_help = EXIT_CODES)]
    Inspect(InspectArgs),
    /// Write a Foxglove / Lichtblick layout for an annotated log: a 3D panel
    /// following the log's own LiDAR frame with the looming clouds, moving
    /// objects and threat zones, the two looming range images, the near-miss
    /// events and their log lines (docs/viewers.md). Import it in the app's
    /// Layouts menu, then open the log.
    #[command(after_help = EXIT_CODES)]
    Layout(LayoutArgs),
    /// Write a synthetic drive with analytic ground truth (/truth/*) as a ROS 2 MCAP.
    ///
    /// Built-in scenarios: straight-road, urban-turn, follow, cut-in, crossing,
    /// safe-drive (see docs/scenarios.md); or a scenario JSON file.
    #[command(after_help = SYNTH_EXIT_CODES)]
    Synth(SynthArgs),
    /// Measure the engine against ground truth: per quantity and class of cell,
    /// median / p90 |error| and bias, and moving-object precision / recall / F1.
    ///
    /// FILE must carry /truth/points (a `looming synth` drive, processed or
    /// not), or --truth names a log that does.
    #[command(after_help = EXIT_CODES)]
    Eval(EvalArgs),
    /// List the near-miss events of an annotated log (its /looming/events),
    /// ranked by minimum time to contact.
    #[command(after_help = EXIT_CODES)]
    Events(EventsArgs),
    /// The quality figures of an annotated log: per scan and in total the
    /// trusted fraction, the static ground's looming (left and right), |D| on
    /// static cells, moving cells, range noise, layout and near-miss events,
    /// with diagnoses (see docs/quality.md).
    #[command(after_help = EXIT_CODES)]
    Quality(QualityArgs),
    /// Convert a KITTI raw drive folder (Velodyne scans, OXTS, calibration) to a
    /// ROS 2 MCAP that `process` reads (see docs/kitti.md).
    #[command(name = "import-kitti", after_help = SYNTH_EXIT_CODES)]
    ImportKitti(ImportKittiArgs),
    /// Draw a scan pair's looming as a PNG: the range image (rows = beams,
    /// forward at the centre) or, with --view top, the cloud from above.
    #[command(after_help = EXIT_CODES)]
    Render(RenderArgs),
}

#[derive(Debug, Args)]
pub(crate) struct ImportKittiArgs {
    /// The drive folder, e.g. 2011_09_26/2011_09_26_drive_0005_sync.
    pub(crate) drive: PathBuf,
    /// Folder of calib_imu_to_velo.txt [default: the drive folder's parent,
    /// the date folder].
    #[arg(long, value_name = "DIR")]
    pub(crate) calib: Option<PathBuf>,
    /// Output MCAP file.
    #[arg(short, long)]
    pub(crate) output: PathBuf,
    /// Which way the scanner turns seen from above, for per-point times
    /// (KITTI's HDL-64E: counter-clockwise, measured; see docs/kitti.md).
    #[arg(long, value_enum, default_value_t = SweepDirection::CounterClockwise)]
    pub(crate) sweep: SweepDirection,
    /// Most points accepted in one scan.
    #[arg(long, value_name = "N", default_value_t = 4_000_000)]
    pub(crate) max_points: usize,
    /// Replace OUTPUT if it exists.
    #[arg(long)]
    pub(crate) force: bool,
    /// No summary on stderr.
    #[arg(short, long)]
    pub(crate) quiet: bool,
}

#[derive(Debug, Args)]
pub(crate) struct RenderArgs {
    /// A log (annotated or not) with LiDAR scans and, for L_ego, a velocity.
    pub(crate) file: PathBuf,
    /// The quantity: fused, lidar (L_lidar, the paper's LiDAR-only looming),
    /// ego (L_ego, its LiDAR + IMU looming), disagreement (D), threat.
    #[arg(long, value_enum, default_value_t = RenderChannel::Fused)]
    pub(crate) channel: RenderChannel,
    /// Seconds after the log's first message: the first pair at or after.
    #[arg(long, value_name = "SECONDS", conflicts_with = "frame")]
    pub(crate) time: Option<f64>,
    /// Pair number (as /looming/pairs counts them, from 0).
    #[arg(long, value_name = "N")]
    pub(crate) frame: Option<u64>,
    /// range: the range image; top: the coloured cloud from above.
    #[arg(long, value_enum, default_value_t = RenderView::Range)]
    pub(crate) view: RenderView,
    /// Range view: pixel rows per beam.
    #[arg(long, value_name = "PX", default_value_t = 4)]
    pub(crate) row_height: u32,
    /// Top view: metres from the centre to the edge.
    #[arg(long, value_name = "METRES", default_value_t = 40.0)]
    pub(crate) extent: f64,
    /// Top view: image size, pixels.
    #[arg(long, value_name = "PX", default_value_t = 800)]
    pub(crate) size: u32,
    /// Output PNG.
    #[arg(short, long)]
    pub(crate) output: PathBuf,
    /// Replace OUTPUT if it exists.
    #[arg(long)]
    pub(crate) force: bool,
    #[command(flatten)]
    pub(crate) scans: ScanArgs,
}

#[derive(Debug, Args)]
pub(crate) struct EvalArgs {
    /// Log with ground truth.
    pub(crate) file: PathBuf,
    /// Also write the report as JSON to this file.
    #[arg(long, value_name = "FILE")]
    pub(crate) json: Option<PathBuf>,
    /// Difference scans without de-rotating the previous one (to measure what
    /// rotation compensation buys).
    #[arg(long)]
    pub(crate) no_rotation_compensation: bool,
    /// Range-image resolution: a beam's firings per image column (as
    /// `process --firings-per-column`).
    #[arg(long, value_name = "N", default_value_t = 1, value_parser = clap::value_parser!(u16).range(1..=8))]
    pub(crate) firings_per_column: u16,
    /// Take the truth from this log instead (a `looming synth` drive whose
    /// scans have the same stamps and points, e.g. the one a KITTI-format
    /// folder was written from); points are matched by exact position.
    #[arg(long, value_name = "TRUTH.mcap")]
    pub(crate) truth: Option<PathBuf>,
    #[command(flatten)]
    pub(crate) scans: ScanArgs,
}

#[derive(Debug, Args)]
pub(crate) struct SynthArgs {
    /// Built-in scenario name or scenario JSON file.
    #[arg(long, value_name = "NAME|FILE.json")]
    pub(crate) scenario: String,
    /// Output MCAP file.
    #[arg(short, long)]
    pub(crate) output: PathBuf,
    /// Seed of the range and IMU noise.
    #[arg(long, default_value_t = 1)]
    pub(crate) seed: u64,
    /// Length of the drive, seconds [default: the scenario's].
    #[arg(long, value_name = "SECONDS")]
    pub(crate) duration: Option<f64>,
    /// Write only the part of the drive from this time on, seconds (the
    /// scenario still starts at 0; stamps keep their times).
    #[arg(long, value_name = "SECONDS")]
    pub(crate) start: Option<f64>,
    /// LiDAR beams [default: the scenario's, 64].
    #[arg(long)]
    pub(crate) beams: Option<u16>,
    /// LiDAR columns per revolution [default: the scenario's, 2048].
    #[arg(long)]
    pub(crate) columns: Option<u32>,
    /// Layout of the LiDAR cloud: ring-time, organized, ring-field:channel,
    /// ring-field:laser_id[:int32], ring-field:line, laser-order[:kitti],
    /// firing-order, firing-order-sparse [default: the scenario's, ring-time].
    #[arg(long, value_name = "NAME", value_parser = clap::value_parser!(looming::synth::CloudLayout))]
    pub(crate) layout: Option<looming::synth::CloudLayout>,
    /// LiDARs on the vehicle: 1 (the scenario's, on /lidar/points), 2 (the
    /// scenario's as the roof LiDAR on /lidar_roof/points and a 32-beam 20 Hz
    /// one on the left, /lidar_left/points) or 3 (and one on the right,
    /// /lidar_right/points); replaces the scenario's extra_lidars
    /// [default: the scenario's, 1]. --beams, --columns and --layout apply to
    /// the roof LiDAR.
    #[arg(long, value_name = "N", value_parser = clap::value_parser!(u8).range(1..=3))]
    pub(crate) lidars: Option<u8>,
    /// The frame the clouds are published in: sensor (each LiDAR's own) or
    /// vehicle (imu_link, the points moved by each LiDAR's mount, as Waymo,
    /// Argoverse 2 or Autoware publish) [default: the scenario's, sensor].
    #[arg(long, value_enum)]
    pub(crate) frame: Option<looming::synth::CloudFrame>,
    /// With several LiDARs: every LiDAR's clouds on one topic,
    /// /lidars/points, each point tagged with its LiDAR in a `sensor_id`
    /// (UINT8) field, 0 the roof (as a driver serving several LiDARs on
    /// one topic publishes them; with --frame vehicle, a merged base_link
    /// cloud); each cloud is still one LiDAR's scan, published when it ends.
    #[arg(long)]
    pub(crate) one_topic: bool,
    /// zstd level of the output chunks (1-22; higher is smaller and slower)
    /// [default: 3].
    #[arg(long, value_name = "LEVEL", value_parser = clap::value_parser!(u32).range(1..=22))]
    pub(crate) compression_level: Option<u32>,
    /// Replace OUTPUT if it exists.
    #[arg(long)]
    pub(crate) force: bool,
    /// No summary on stderr.
    #[arg(short, long)]
    pub(crate) quiet: bool,
}

#[derive(Debug, Args)]
pub(crate) struct ProcessArgs {
    /// Input MCAP file.
    pub(crate) input: PathBuf,
    /// Output MCAP file (written to a temporary file beside it, renamed when complete).
    #[arg(short, long)]
    pub(crate) output: PathBuf,
    /// Replace OUTPUT if it exists.
    #[arg(long)]
    pub(crate) force: bool,
    #[command(flatten)]
    pub(crate) scans: ScanArgs,
    /// Also write the run summary as JSON to this file.
    #[arg(long, value_name = "FILE")]
    pub(crate) json_summary: Option<PathBuf>,
    /// Also write the near-miss events, ranked by minimum time to contact, to
    /// this JSON file (schema: schemas/looming.NearMissEvents.schema.json).
    #[arg(long, value_name = "FILE.json")]
    pub(crate) events: Option<PathBuf>,
    /// Accept an input that already holds /looming/* channels: drop them and
    /// write fresh ones.
    #[arg(long)]
    pub(crate) replace: bool,
    /// For each near miss, also write a clip into DIR: an MCAP of every
    /// channel of the output from SECONDS before the near miss to SECONDS
    /// after it, named OUTPUT-NAME.event-ID.mcap (docs/viewers.md).
    #[arg(long, num_args = 2, value_names = ["DIR", "SECONDS"])]
    pub(crate) clips: Option<Vec<String>>,
    #[command(flatten)]
    pub(crate) annotate: AnnotateArgs,
    /// No progress bar and no summary on stderr.
    #[arg(short, long)]
    pub(crate) quiet: bool,
}

#[derive(Debug, Args)]
pub(crate) struct EventsArgs {
    /// An MCAP written by `looming process`.
    pub(crate) file: PathBuf,
    /// Print JSON (the events, ranked) instead of a table.
    #[arg(long)]
    pub(crate) json: bool,
}

#[derive(Debug, Args)]
pub(crate) struct QualityArgs {
    /// An MCAP written by `looming process`.
    pub(crate) file: PathBuf,
    /// Also write the report as JSON to this file
    /// (schema: schemas/looming.QualityReport.schema.json).
    #[arg(long, value_name = "FILE")]
    pub(crate) json: Option<PathBuf>,
}

#[derive(Debug, Args)]
pub(crate) struct LayoutArgs {
    /// An MCAP written by `looming process` (or its input: the frame is then
    /// read from the LiDAR topic).
    pub(crate) log: PathBuf,
    /// Layout file to write (JSON).
    #[arg(short, long, value_name = "LAYOUT.json")]
    pub(crate) output: PathBuf,
    /// The LiDAR topic, when the log has several.
    #[arg(long, value_name = "TOPIC")]
    pub(crate) lidar_topic: Option<String>,
    /// Replace OUTPUT if it exists.
    #[arg(long)]
    pub(crate) force: bool,
}

#[derive(Debug, Args)]
pub(crate) struct InspectArgs {
    /// MCAP file to inspect.
    pub(crate) file: PathBuf,
    /// Print JSON instead of text.
    #[arg(long)]
    pub(crate) json: bool,
}

/// How the log is read, decoded and paired: shared by `process`, `eval` and
/// `render`, so that all three see the same scan pairs.
#[derive(Debug, Args)]
pub(crate) struct ScanArgs {
    /// Fail on the first bad input message, bad chunk CRC or truncation, instead
    /// of skipping and counting it.
    #[arg(long)]
    pub(crate) strict: bool,
    /// Check every chunk's CRC before using its messages (otherwise only the
    /// chunks a pass-through run decompresses are checked; costs a
    /// decompression of every chunk).
    #[arg(long)]
    pub(crate) verify: bool,
    /// LiDAR topic (sensor_msgs/PointCloud2 or foxglove.PointCloud). `process`
    /// and `batch` annotate every LiDAR of a log by default, or those given
    /// here: one topic, a comma-separated list, or `all` (docs/channels.md,
    /// "Several LiDARs"); `eval` and `render` take one, auto-detected when the
    /// log has exactly one.
    #[arg(long, value_name = "TOPIC[,TOPIC...]|all")]
    pub(crate) lidar_topic: Option<String>,
    /// IMU topic (sensor_msgs/Imu); auto-detected when the log has exactly one.
    #[arg(long, value_name = "TOPIC")]
    pub(crate) imu_topic: Option<String>,
    /// Velocity topic (geometry_msgs/TwistStamped or nav_msgs/Odometry);
    /// auto-detected when the log has exactly one.
    #[arg(long, value_name = "TOPIC")]
    pub(crate) velocity_topic: Option<String>,
    /// Pose of the LiDAR in the velocity/IMU frame as x,y,z,qx,qy,qz,qw (metres,
    /// unit quaternion); overrides /tf_static.
    #[arg(long, value_name = "X,Y,Z,QX,QY,QZ,QW", allow_hyphen_values = true)]
    pub(crate) extrinsic: Option<String>,
    /// The LiDAR's frame, for clouds published in another (a vehicle or
    /// world frame): the points are moved about that frame's origin, found
    /// through /tf_static [default: the cloud's frame when its name says
    /// LiDAR, else a LiDAR frame in /tf_static, else estimated from the
    /// returns' rings; docs/channels.md].
    #[arg(long, value_name = "FRAME")]
    pub(crate) sensor_frame: Option<String>,
    /// The per-point field that says which sensor each point of a merged
    /// cloud (several LiDARs on one topic, e.g. a concatenated base_link
    /// cloud) came from: the cloud is split into one sensor per value, each
    /// annotated on its own (/looming/<sensor>_<id>/...); `none` keeps a
    /// merged cloud whole [default: sensor_id, lidar_id, sensor or
    /// lidar_index, any integer type; docs/channels.md].
    #[arg(long, value_name = "FIELD|none", default_value = "auto", value_parser = parse_split_field, hide_default_value = true)]
    pub(crate) split_field: looming::decode::SensorField,
    /// Largest stamp gap between two scans that is still paired, seconds
    /// [default: 3 nominal scan periods].
    #[arg(long, value_name = "SECONDS")]
    pub(crate) max_gap: Option<f64>,
    /// Shortest time a pair of scans spans, seconds: a sensor faster than
    /// this pairs each scan with the one this long before it (a 20 Hz
    /// sensor over two periods: half the looming noise, still a pair per
    /// scan); 0 pairs consecutive scans at any rate [docs/method.md].
    #[arg(long, value_name = "SECONDS", default_value_t = looming::pairing::stride::DEFAULT_MIN_BASELINE_S)]
    pub(crate) min_baseline: f64,
    /// Reorder window for logs read in file order, seconds of log time.
    #[arg(long, value_name = "SECONDS", default_value_t = 2.0)]
    pub(crate) reorder_window: f64,
    /// Most points accepted in one scan (larger clouds are bad messages).
    #[arg(long, value_name = "N", default_value_t = 4_000_000)]
    pub(crate) max_points: usize,
}

/// What `process` adds to a log and how it writes it: shared by `process`
/// and `batch`.
#[derive(Debug, Args)]
pub(crate) struct AnnotateArgs {
    /// Chunk compression of the output.
    #[arg(long, value_enum, default_value_t = OutputCompression::Zstd)]
    pub(crate) compression: OutputCompression,
    /// Per-point fields of /looming/points: `default` (x, y, z, looming,
    /// colour) or `full` (adds l_lidar, l_ego, l_ray_ego, disagreement,
    /// confidence, threat, mask).
    #[arg(long, value_enum, default_value_t = FieldSet::Default)]
    pub(crate) fields: FieldSet,
    /// Threat levels low, medium, high as times to contact, seconds.
    #[arg(long, value_name = "LOW,MEDIUM,HIGH", default_value = "3,1.5,1", value_parser = parse_threat_ttc)]
    pub(crate) threat_ttc: [f64; 3],
    /// Range-image resolution: a beam's firings per image column. 1 (the
    /// default) gives every return its own cell; 2 halves the columns and
    /// takes a quarter to two fifths less CPU, for a noisier looming image
    /// (docs/performance.md has what it costs).
    #[arg(long, value_name = "N", default_value_t = 1, value_parser = clap::value_parser!(u16).range(1..=8))]
    pub(crate) firings_per_column: u16,
    /// Near-miss threshold as a time to contact, seconds.
    #[arg(long, value_name = "SECONDS", default_value_t = 1.5)]
    pub(crate) event_ttc: f64,
    /// Smallest near-miss cluster, range-image cells [default: the cells a
    /// 0.3 m square covers at 10 m, at least 3: 40 at 64 x 2048, 5 at 32 x 512].
    #[arg(long, value_name = "CELLS")]
    pub(crate) event_min_cells: Option<usize>,
    /// Consecutive scan pairs a cluster must last to be a near miss.
    #[arg(long, value_name = "PAIRS", default_value_t = 2, value_parser = clap::value_parser!(u64).range(1..))]
    pub(crate) event_min_pairs: u64,
    /// Width of the vehicle, metres: near misses are sought in its swept
    /// path (the arc of its speed and yaw rate), this wide plus the margin
    /// either side; an object beside it is never a near miss.
    #[arg(long, value_name = "METRES", default_value_t = 1.9)]
    pub(crate) vehicle_width: f64,
    /// Clearance added either side of the vehicle's swept path, metres.
    #[arg(long, value_name = "METRES", default_value_t = 0.5)]
    pub(crate) path_margin: f64,
    /// A log with no LiDAR topic: `refuse` it (exit 2, listing its
    /// channels) or `copy` every record through with the run record and no
    /// looming channel.
    #[arg(long, value_enum, value_name = "POLICY", default_value_t = NoLidarPolicy::Refuse)]
    pub(crate) if_no_lidar: NoLidarPolicy,
}

#[derive(Debug, Args)]
pub(crate) struct BatchArgs {
    /// Folders (every *.mcap below them), MCAP files, or manifests (.txt).
    #[arg(required_unless_present = "merge_only")]
    pub(crate) inputs: Vec<PathBuf>,
    /// Output folder: logs/ (the annotated logs, same relative paths as
    /// below an input folder), fleet.json, near_misses.jsonl, near_misses.csv.
    #[arg(
        short,
        long,
        value_name = "OUT_DIR",
        required_unless_present = "merge_only"
    )]
    pub(crate) output: Option<PathBuf>,
    /// Only rebuild OUT_DIR's fleet files from its logs' records: after
    /// sharded runs (which write no fleet files), or runs on other machines.
    #[arg(long, value_name = "OUT_DIR", conflicts_with_all = ["inputs", "output", "shard", "force", "only", "list"])]
    pub(crate) merge_only: Option<PathBuf>,
    /// Logs processed at once [default: half the cores, at least 1: the
    /// engine uses every core inside a log].
    #[arg(long, value_name = "N")]
    pub(crate) jobs: Option<usize>,
    /// Take shard K of N (0-based; a log's shard depends only on its path),
    /// e.g. from a Kubernetes Indexed Job's JOB_COMPLETION_INDEX.
    #[arg(long, value_name = "K/N", value_parser = parse_shard)]
    pub(crate) shard: Option<looming::commands::batch::Shard>,
    /// Run only the log with this output path (relative to OUT_DIR/logs/, as
    /// --list prints it); repeatable. Writes no fleet files, as a shard: what
    /// a distributed driver (python/looming_fleet) runs per task.
    #[arg(long, value_name = "RELATIVE")]
    pub(crate) only: Vec<PathBuf>,
    /// Print the logs the batch would run (after --shard and --only), one
    /// JSON object per line ({"relative", "input", "output"}), and exit.
    #[arg(long)]
    pub(crate) list: bool,
    /// Redo every log, even those whose output is up to date.
    #[arg(long)]
    pub(crate) force: bool,
    /// For each near miss, also write a clip: an MCAP of every channel of
    /// the annotated log from SECONDS before the near miss to SECONDS after
    /// it, in OUT_DIR/clips/ (linked from near_misses.jsonl / .csv and the
    /// report).
    #[arg(long, value_name = "SECONDS")]
    pub(crate) clips: Option<String>,
    #[command(flatten)]
    pub(crate) scans: ScanArgs,
    #[command(flatten)]
    pub(crate) annotate: AnnotateArgs,
    /// No progress bar and no per-log lines on stderr.
    #[arg(short, long)]
    pub(crate) quiet: bool,
}
