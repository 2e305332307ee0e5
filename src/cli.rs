//! Command-line arguments (clap derive: the doc comments are the help text) and
//! the human-readable run summary.

use std::io::IsTerminal;
use std::path::PathBuf;

use clap::{Args, Parser, Subcommand};
use indicatif::{ProgressBar, ProgressDrawTarget, ProgressStyle};

use looming::annotate::{AnnotateConfig, FieldSet};
use looming::decode::DecodeLimits;
use looming::engine::EngineConfig;
use looming::events::EventConfig;
use looming::input::{InputOptions, ReadMode};
use looming::kitti::SweepDirection;
use looming::output::{OutputCompression, OutputOptions, WriteMode};
use looming::pipeline::{PairingSettings, ProcessConfig, ProcessError, ProgressSink, RunSummary};
use looming::render::{RenderAt, RenderChannel, RenderOptions, RenderView};
use looming::topics::TopicOverrides;

const EXIT_CODES: &str = "\
Exit codes:
  0  success (bad messages, if any, were skipped and are counted in the summary)
  1  failure: unreadable input, I/O error, output could not be written
  2  usage: bad arguments, unknown or ambiguous topic, output exists (see --force)
     or is the input, input already processed
  3  --strict and the input had a bad message, a bad chunk CRC or was truncated";

const SYNTH_EXIT_CODES: &str = "\
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
    command: Command,
}

#[derive(Debug, Subcommand)]
enum Command {
    /// Process a log: copy every record and add the /looming/* channels.
    #[command(after_help = EXIT_CODES)]
    Process(ProcessArgs),
    /// Show a log's channels, schemas, counts, rates, time span and the topics
    /// `process` would use.
    #[command(after_help = EXIT_CODES)]
    Inspect(InspectArgs),
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
    #[command(after_help = SYNTH_EXIT_CODES)]
    Render(RenderArgs),
}

#[derive(Debug, Args)]
struct ImportKittiArgs {
    /// The drive folder, e.g. 2011_09_26/2011_09_26_drive_0005_sync.
    drive: PathBuf,
    /// Folder of calib_imu_to_velo.txt [default: the drive folder's parent,
    /// the date folder].
    #[arg(long, value_name = "DIR")]
    calib: Option<PathBuf>,
    /// Output MCAP file.
    #[arg(short, long)]
    output: PathBuf,
    /// Which way the scanner turns seen from above, for per-point times
    /// (KITTI's HDL-64E: counter-clockwise, measured; see docs/kitti.md).
    #[arg(long, value_enum, default_value_t = SweepDirection::CounterClockwise)]
    sweep: SweepDirection,
    /// Most points accepted in one scan.
    #[arg(long, value_name = "N", default_value_t = 4_000_000)]
    max_points: usize,
    /// Replace OUTPUT if it exists.
    #[arg(long)]
    force: bool,
    /// No summary on stderr.
    #[arg(short, long)]
    quiet: bool,
}

#[derive(Debug, Args)]
struct RenderArgs {
    /// A log (annotated or not) with LiDAR scans and, for L_ego, a velocity.
    file: PathBuf,
    /// The quantity: fused, lidar (L_lidar, the paper's LiDAR-only looming),
    /// ego (L_ego, its LiDAR + IMU looming), disagreement (D), threat.
    #[arg(long, value_enum, default_value_t = RenderChannel::Fused)]
    channel: RenderChannel,
    /// Seconds after the log's first message: the first pair at or after.
    #[arg(long, value_name = "SECONDS", conflicts_with = "frame")]
    time: Option<f64>,
    /// Pair number (as /looming/pairs counts them, from 0).
    #[arg(long, value_name = "N")]
    frame: Option<u64>,
    /// range: the range image; top: the coloured cloud from above.
    #[arg(long, value_enum, default_value_t = RenderView::Range)]
    view: RenderView,
    /// Range view: pixel rows per beam.
    #[arg(long, value_name = "PX", default_value_t = 4)]
    row_height: u32,
    /// Top view: metres from the centre to the edge.
    #[arg(long, value_name = "METRES", default_value_t = 40.0)]
    extent: f64,
    /// Top view: image size, pixels.
    #[arg(long, value_name = "PX", default_value_t = 800)]
    size: u32,
    /// Output PNG.
    #[arg(short, long)]
    output: PathBuf,
    /// Replace OUTPUT if it exists.
    #[arg(long)]
    force: bool,
}

#[derive(Debug, Args)]
struct EvalArgs {
    /// Log with ground truth.
    file: PathBuf,
    /// Also write the report as JSON to this file.
    #[arg(long, value_name = "FILE")]
    json: Option<PathBuf>,
    /// Difference scans without de-rotating the previous one (to measure what
    /// rotation compensation buys).
    #[arg(long)]
    no_rotation_compensation: bool,
    /// Take the truth from this log instead (a `looming synth` drive whose
    /// scans have the same stamps and points, e.g. the one a KITTI-format
    /// folder was written from); points are matched by exact position.
    #[arg(long, value_name = "TRUTH.mcap")]
    truth: Option<PathBuf>,
}

#[derive(Debug, Args)]
struct SynthArgs {
    /// Built-in scenario name or scenario JSON file.
    #[arg(long, value_name = "NAME|FILE.json")]
    scenario: String,
    /// Output MCAP file.
    #[arg(short, long)]
    output: PathBuf,
    /// Seed of the range and IMU noise.
    #[arg(long, default_value_t = 1)]
    seed: u64,
    /// Length of the drive, seconds [default: the scenario's].
    #[arg(long, value_name = "SECONDS")]
    duration: Option<f64>,
    /// Write only the part of the drive from this time on, seconds (the
    /// scenario still starts at 0; stamps keep their times).
    #[arg(long, value_name = "SECONDS")]
    start: Option<f64>,
    /// LiDAR beams [default: the scenario's, 64].
    #[arg(long)]
    beams: Option<u16>,
    /// LiDAR columns per revolution [default: the scenario's, 2048].
    #[arg(long)]
    columns: Option<u32>,
    /// Layout of the LiDAR cloud: ring-time, organized, ring-field:channel,
    /// ring-field:laser_id[:int32], ring-field:line, laser-order[:kitti],
    /// firing-order, firing-order-sparse [default: the scenario's, ring-time].
    #[arg(long, value_name = "NAME", value_parser = clap::value_parser!(looming::synth::CloudLayout))]
    layout: Option<looming::synth::CloudLayout>,
    /// zstd level of the output chunks (1-22; higher is smaller and slower)
    /// [default: 3].
    #[arg(long, value_name = "LEVEL", value_parser = clap::value_parser!(u32).range(1..=22))]
    compression_level: Option<u32>,
    /// Replace OUTPUT if it exists.
    #[arg(long)]
    force: bool,
    /// No summary on stderr.
    #[arg(short, long)]
    quiet: bool,
}

#[derive(Debug, Args)]
struct ProcessArgs {
    /// Input MCAP file.
    input: PathBuf,
    /// Output MCAP file (written to a temporary file beside it, renamed when complete).
    #[arg(short, long)]
    output: PathBuf,
    /// Replace OUTPUT if it exists.
    #[arg(long)]
    force: bool,
    /// Fail on the first bad input message, bad chunk CRC or truncation, instead
    /// of skipping and counting it.
    #[arg(long)]
    strict: bool,
    /// Check every chunk's CRC before using its messages (otherwise only the
    /// chunks a pass-through run decompresses are checked; costs a
    /// decompression of every chunk).
    #[arg(long)]
    verify: bool,
    /// LiDAR topic (sensor_msgs/PointCloud2 or foxglove.PointCloud); auto-detected
    /// when the log has exactly one.
    #[arg(long, value_name = "TOPIC")]
    lidar_topic: Option<String>,
    /// IMU topic (sensor_msgs/Imu); auto-detected when the log has exactly one.
    #[arg(long, value_name = "TOPIC")]
    imu_topic: Option<String>,
    /// Velocity topic (geometry_msgs/TwistStamped or nav_msgs/Odometry);
    /// auto-detected when the log has exactly one.
    #[arg(long, value_name = "TOPIC")]
    velocity_topic: Option<String>,
    /// Pose of the LiDAR in the velocity/IMU frame as x,y,z,qx,qy,qz,qw (metres,
    /// unit quaternion); overrides /tf_static.
    #[arg(long, value_name = "X,Y,Z,QX,QY,QZ,QW", allow_hyphen_values = true)]
    extrinsic: Option<String>,
    /// Largest stamp gap between two scans that is still paired, seconds
    /// [default: 3 nominal scan periods].
    #[arg(long, value_name = "SECONDS")]
    max_gap: Option<f64>,
    /// Reorder window for logs read in file order, seconds of log time.
    #[arg(long, value_name = "SECONDS", default_value_t = 2.0)]
    reorder_window: f64,
    /// Most points accepted in one scan (larger clouds are bad messages).
    #[arg(long, value_name = "N", default_value_t = 4_000_000)]
    max_points: usize,
    /// Chunk compression of the output.
    #[arg(long, value_enum, default_value_t = OutputCompression::Zstd)]
    compression: OutputCompression,
    /// Also write the run summary as JSON to this file.
    #[arg(long, value_name = "FILE")]
    json_summary: Option<PathBuf>,
    /// Also write the near-miss events, ranked by minimum time to contact, to
    /// this JSON file (schema: schemas/looming.NearMissEvents.schema.json).
    #[arg(long, value_name = "FILE.json")]
    events: Option<PathBuf>,
    /// Per-point fields of /looming/points: `default` (x, y, z, looming,
    /// colour) or `full` (adds l_lidar, l_ego, l_ray_ego, disagreement,
    /// confidence, threat, mask).
    #[arg(long, value_enum, default_value_t = FieldSet::Default)]
    fields: FieldSet,
    /// Accept an input that already holds /looming/* channels: drop them and
    /// write fresh ones.
    #[arg(long)]
    replace: bool,
    /// Threat levels low, medium, high as times to contact, seconds.
    #[arg(long, value_name = "LOW,MEDIUM,HIGH", default_value = "3,1.5,1", value_parser = parse_threat_ttc)]
    threat_ttc: [f64; 3],
    /// Near-miss threshold as a time to contact, seconds.
    #[arg(long, value_name = "SECONDS", default_value_t = 1.5)]
    event_ttc: f64,
    /// Smallest near-miss cluster, range-image cells [default: the cells a
    /// 0.3 m square covers at 10 m, at least 3: 40 at 64 x 2048, 5 at 32 x 512].
    #[arg(long, value_name = "CELLS")]
    event_min_cells: Option<usize>,
    /// Consecutive scan pairs a cluster must last to be a near miss.
    #[arg(long, value_name = "PAIRS", default_value_t = 2, value_parser = clap::value_parser!(u64).range(1..))]
    event_min_pairs: u64,
    /// Half width of the ego corridor in which near misses are sought, metres.
    #[arg(long, value_name = "METRES", default_value_t = 2.0)]
    corridor_half_width: f64,
    /// No progress bar and no summary on stderr.
    #[arg(short, long)]
    quiet: bool,
}

fn parse_threat_ttc(text: &str) -> Result<[f64; 3], String> {
    let values: Vec<f64> = text
        .split(',')
        .map(|v| v.trim().parse::<f64>().map_err(|e| format!("{v:?}: {e}")))
        .collect::<Result<_, _>>()?;
    let [low, medium, high] = values[..] else {
        return Err("three times to contact are needed: LOW,MEDIUM,HIGH".into());
    };
    if !(high > 0.0 && medium > high && low > medium && low.is_finite()) {
        return Err("times to contact must be finite and decrease: LOW > MEDIUM > HIGH > 0".into());
    }
    Ok([low, medium, high])
}

#[derive(Debug, Args)]
struct EventsArgs {
    /// An MCAP written by `looming process`.
    file: PathBuf,
    /// Print JSON (the events, ranked) instead of a table.
    #[arg(long)]
    json: bool,
}

#[derive(Debug, Args)]
struct QualityArgs {
    /// An MCAP written by `looming process`.
    file: PathBuf,
    /// Also write the report as JSON to this file
    /// (schema: schemas/looming.QualityReport.schema.json).
    #[arg(long, value_name = "FILE")]
    json: Option<PathBuf>,
}

#[derive(Debug, Args)]
struct InspectArgs {
    /// MCAP file to inspect.
    file: PathBuf,
    /// Print JSON instead of text.
    #[arg(long)]
    json: bool,
}

/// An error with its exit code.
pub struct Failure {
    pub error: anyhow::Error,
    pub code: i32,
}

impl Failure {
    fn with_code(error: impl Into<anyhow::Error>, code: i32) -> Self {
        Failure {
            error: error.into(),
            code,
        }
    }
}

impl<E: Into<anyhow::Error>> From<E> for Failure {
    fn from(error: E) -> Self {
        Failure {
            error: error.into(),
            code: 1,
        }
    }
}

pub fn run(cli: Cli) -> Result<(), Failure> {
    match cli.command {
        Command::Process(args) => process(args),
        Command::Inspect(args) => inspect(args),
        Command::Synth(args) => synth(args),
        Command::Eval(args) => eval(args),
        Command::Events(args) => events(args),
        Command::Quality(args) => quality(args),
        Command::ImportKitti(args) => import_kitti(args),
        Command::Render(args) => render(args),
    }
}

fn import_kitti(args: ImportKittiArgs) -> Result<(), Failure> {
    let options = looming::kitti::ImportOptions {
        drive_dir: args.drive,
        calib_dir: args.calib,
        output: args.output,
        output_options: OutputOptions {
            force: args.force,
            ..OutputOptions::default()
        },
        max_points: args.max_points,
        sweep: args.sweep,
    };
    let summary = looming::kitti::import_kitti(&options).map_err(|error| {
        let usage = matches!(
            &error,
            looming::kitti::ImportError::Output(looming::output::OutputError::Exists { .. })
        );
        Failure::with_code(error, if usage { 2 } else { 1 })
    })?;
    if !args.quiet {
        eprintln!(
            "looming import-kitti: {} scans ({} points, {} missing), {} OXTS packets ({} missing), {:.1} MB in {:.2} s -> {}",
            summary.scans_written,
            summary.points_written,
            summary.scans_missing,
            summary.oxts_written,
            summary.oxts_missing,
            summary.output_bytes as f64 / 1e6,
            summary.elapsed_s,
            summary.output
        );
        eprintln!(
            "  sweep times   {}; turning {:?}; rings derived in {} of {} scans",
            summary.sweep_times,
            summary.sweep_direction,
            summary.scans_with_rings,
            summary.scans_written
        );
        if let Some(calib) = &summary.calibration {
            eprintln!("  calibration   {calib}");
        }
        for warning in &summary.warnings {
            eprintln!("  warning       {warning}");
        }
    }
    Ok(())
}

fn render(args: RenderArgs) -> Result<(), Failure> {
    let at = match (args.time, args.frame) {
        (Some(t), _) if t.is_finite() && t >= 0.0 => RenderAt::Time(t),
        (Some(_), _) => {
            return Err(Failure {
                error: anyhow::anyhow!("--time must be a non-negative number of seconds"),
                code: 2,
            });
        }
        (None, Some(n)) => RenderAt::Frame(n),
        (None, None) => {
            return Err(Failure {
                error: anyhow::anyhow!("give --time SECONDS or --frame N"),
                code: 2,
            });
        }
    };
    let options = RenderOptions {
        input: args.file,
        output: args.output,
        channel: args.channel,
        at,
        view: args.view,
        row_height_px: args.row_height.max(1),
        top_extent_m: args.extent,
        top_size_px: args.size.max(16),
        force: args.force,
    };
    let summary = looming::render::render(&options).map_err(|error| {
        let code = if error.is_usage() { 2 } else { 1 };
        Failure::with_code(error, code)
    })?;
    eprintln!(
        "looming render: pair {} (stamp {}), {} x {} px -> {}",
        summary.pair_index,
        looming::model::format_log_time(summary.stamp_ns.max(0) as u64),
        summary.width_px,
        summary.height_px,
        summary.output.display()
    );
    Ok(())
}

fn quality(args: QualityArgs) -> Result<(), Failure> {
    let report = looming::quality_report::read_quality(&args.file).map_err(|error| {
        let usage = matches!(
            error,
            looming::quality_report::QualityError::NotProcessed { .. }
        );
        Failure::with_code(error, if usage { 2 } else { 1 })
    })?;
    print!("{}", report.to_text());
    if let Some(path) = &args.json {
        let json = serde_json::to_vec_pretty(&report)?;
        std::fs::write(path, json)
            .map_err(|e| anyhow::anyhow!("cannot write {}: {e}", path.display()))?;
    }
    Ok(())
}

fn events(args: EventsArgs) -> Result<(), Failure> {
    let mut events = looming::events::read_events(&args.file)?;
    looming::events::rank(&mut events);
    if args.json {
        println!("{}", serde_json::to_string_pretty(&events)?);
    } else {
        print!("{}", looming::events::events_table(&events));
    }
    Ok(())
}

fn eval(args: EvalArgs) -> Result<(), Failure> {
    let config = looming::engine::EngineConfig {
        rotation_compensation: !args.no_rotation_compensation,
        ..Default::default()
    };
    let report = looming::eval::evaluate_against(&args.file, &config, args.truth.as_deref())?;
    print!("{}", report.to_text());
    if let Some(path) = &args.json {
        std::fs::write(path, serde_json::to_string_pretty(&report)?)
            .map_err(|e| anyhow::anyhow!("{}: cannot write the report: {e}", path.display()))?;
    }
    Ok(())
}

fn synth(args: SynthArgs) -> Result<(), Failure> {
    let options = looming::synth::SynthOptions {
        scenario: args.scenario,
        output: args.output,
        seed: args.seed,
        start_s: args.start,
        duration_s: args.duration,
        beams: args.beams,
        columns: args.columns,
        output_options: OutputOptions {
            force: args.force,
            compression_level: args.compression_level.unwrap_or(0),
            ..OutputOptions::default()
        },
    };
    let lidar = looming::synth::LidarOverrides {
        layout: args.layout,
        realism: None,
    };
    let summary = looming::synth::synthesize_with(&options, &lidar).map_err(|error| {
        let usage = matches!(
            &error,
            looming::synth::SynthError::Scenario(_)
                | looming::synth::SynthError::Output(looming::output::OutputError::Exists { .. })
        );
        Failure::with_code(error, if usage { 2 } else { 1 })
    })?;
    if !args.quiet {
        eprintln!(
            "looming synth {}: {} scans, {} points, {} messages, {:.1} MB in {:.2} s -> {}",
            summary.scenario,
            summary.scans,
            summary.points,
            summary.messages,
            summary.output_bytes as f64 / 1e6,
            summary.elapsed_s,
            summary.output
        );
        for event in &summary.events {
            eprintln!(
                "  planted near miss: actor {} ({}) {:.2}..{:.2} s, min time to contact {:.2} s",
                event.actor_id,
                event.label,
                event.start_s,
                event.end_s,
                event.min_time_to_contact_s
            );
        }
    }
    Ok(())
}

fn inspect(args: InspectArgs) -> Result<(), Failure> {
    let report = looming::inspect::inspect(&args.file)?;
    if args.json {
        println!("{}", serde_json::to_string_pretty(&report)?);
    } else {
        print!("{}", report.to_text());
    }
    Ok(())
}

fn process(args: ProcessArgs) -> Result<(), Failure> {
    let usage = |error: anyhow::Error| Failure { error, code: 2 };
    if !(args.reorder_window.is_finite() && args.reorder_window >= 0.0) {
        return Err(usage(anyhow::anyhow!(
            "--reorder-window must be a non-negative number of seconds"
        )));
    }
    if !(args.event_ttc.is_finite() && args.event_ttc > 0.0) {
        return Err(usage(anyhow::anyhow!(
            "--event-ttc must be a positive number of seconds"
        )));
    }
    if !(args.corridor_half_width.is_finite() && args.corridor_half_width > 0.0) {
        return Err(usage(anyhow::anyhow!(
            "--corridor-half-width must be a positive number of metres"
        )));
    }
    if args.event_min_cells == Some(0) {
        return Err(usage(anyhow::anyhow!(
            "--event-min-cells must be at least 1"
        )));
    }
    if args.max_gap.is_some_and(|g| !(g.is_finite() && g > 0.0)) {
        return Err(usage(anyhow::anyhow!(
            "--max-gap must be a positive number of seconds"
        )));
    }
    let config = ProcessConfig {
        input: args.input.clone(),
        output: args.output.clone(),
        input_options: InputOptions {
            verify_crc: args.verify,
            reorder_window_ns: (args.reorder_window * 1e9) as u64,
            ..InputOptions::default()
        },
        output_options: OutputOptions {
            compression: args.compression,
            force: args.force,
            ..OutputOptions::default()
        },
        topics: TopicOverrides {
            lidar: args.lidar_topic.clone(),
            imu: args.imu_topic.clone(),
            velocity: args.velocity_topic.clone(),
        },
        pairing: PairingSettings {
            max_gap_s: args.max_gap,
            extrinsic: args.extrinsic.clone(),
            ..PairingSettings::default()
        },
        strict: args.strict,
        decode_limits: DecodeLimits {
            max_points: args.max_points,
        },
        annotate: AnnotateConfig {
            engine: EngineConfig {
                threat_ttc_s: args.threat_ttc,
                ..EngineConfig::default()
            },
            events: EventConfig {
                ttc_threshold_s: args.event_ttc,
                min_cells: args.event_min_cells,
                min_pairs: args.event_min_pairs,
                corridor_half_width_m: args.corridor_half_width,
                ..EventConfig::default()
            },
            fields: args.fields,
        },
        replace: args.replace,
        events_file: args.events.clone(),
    };
    let progress = Progress::new(args.quiet);
    let result = looming::pipeline::process(&config, &progress);
    progress.bar.finish_and_clear();
    let summary = result.map_err(|error| {
        let code = match &error {
            ProcessError::Topic { .. }
            | ProcessError::Config(_)
            | ProcessError::AlreadyProcessed { .. } => 2,
            ProcessError::Output(
                looming::output::OutputError::Exists { .. }
                | looming::output::OutputError::SameAsInput { .. },
            ) => 2,
            ProcessError::Strict(_) => 3,
            _ => 1,
        };
        Failure {
            error: error.into(),
            code,
        }
    })?;
    if let Some(path) = &args.json_summary {
        let json = serde_json::to_string_pretty(&summary)?;
        std::fs::write(path, json).map_err(|e| {
            anyhow::anyhow!("{}: cannot write the JSON summary: {e}", path.display())
        })?;
    }
    if !args.quiet {
        eprint!("{}", summary_text(&summary));
    }
    Ok(())
}

/// indicatif progress on stderr when it is a terminal, silent otherwise.
struct Progress {
    bar: ProgressBar,
}

impl Progress {
    fn new(quiet: bool) -> Self {
        let bar = if quiet || !std::io::stderr().is_terminal() {
            ProgressBar::hidden()
        } else {
            let bar = ProgressBar::with_draw_target(Some(0), ProgressDrawTarget::stderr());
            bar.set_style(
                ProgressStyle::with_template("{spinner} [{elapsed_precise}] {wide_bar} {pos}/{len} messages ({per_sec}, eta {eta})")
                    .expect("static template is valid"),
            );
            bar
        };
        Self { bar }
    }
}

impl ProgressSink for Progress {
    fn update(&self, done: u64, total: Option<u64>) {
        if let Some(total) = total {
            self.bar.set_length(total.max(done));
        }
        self.bar.set_position(done);
    }
}

/// The one-screen summary.
/// How the output was written, for the summary.
fn write_line(s: &RunSummary) -> String {
    match &s.write {
        WriteMode::PassThrough => format!(
            "pass-through: {} input chunks copied as they are ({} decompressed to read the selected topics)",
            s.input_report.chunks_copied, s.input_report.chunks_decompressed
        ),
        WriteMode::Rewrite { reason } => format!("every message written anew ({reason})"),
    }
}

fn summary_text(s: &RunSummary) -> String {
    use std::fmt::Write as _;
    let mut out = String::new();
    let mode = match &s.read {
        ReadMode::Indexed => "indexed, log-time order".to_string(),
        ReadMode::Linear { reason } => format!("linear, file order with reorder window ({reason})"),
    };
    let mb = |b: u64| b as f64 / 1e6;
    let _ = writeln!(
        out,
        "looming {}: {} -> {}",
        s.tool_version, s.input, s.output
    );
    let _ = writeln!(out, "  read          {mode}");
    let _ = writeln!(out, "  write         {}", write_line(s));
    let _ = writeln!(
        out,
        "  copied        {} messages, {} metadata, {} attachments",
        s.messages_copied, s.metadata_copied, s.attachments_copied
    );
    let topic = |c: &Option<looming::topics::SelectedChannel>| {
        c.as_ref().map_or("none".to_string(), |c| c.topic.clone())
    };
    let _ = writeln!(
        out,
        "  topics        lidar {}, imu {}, velocity {}, tf {}",
        s.topics.lidar.topic,
        topic(&s.topics.imu),
        topic(&s.topics.velocity),
        s.topics.tf.len()
    );
    let _ = writeln!(
        out,
        "  decoded       {} scans ({} points, {} invalid skipped), {} imu, {} velocity, {} tf",
        s.decoded.scans,
        s.decoded.lidar_points,
        s.decoded.invalid_points_skipped,
        s.decoded.imu,
        s.decoded.velocity,
        s.decoded.tf_messages
    );
    if let Some(layout) = &s.pairing.layout {
        let _ = writeln!(out, "  layout        {}: {layout}", s.topics.lidar.topic);
        if s.pairing.layout_kinds.len() > 1 {
            let kinds: Vec<String> = s
                .pairing
                .layout_kinds
                .iter()
                .map(|(kind, n)| format!("{kind} {n}"))
                .collect();
            let _ = writeln!(
                out,
                "                (varies by scan: {})",
                kinds.join(", ")
            );
        }
        if s.pairing.ring_fields_dropped > 0 {
            let _ = writeln!(
                out,
                "                ring field dropped in {} scans (values not ring numbers)",
                s.pairing.ring_fields_dropped
            );
        }
    }
    let p = &s.pairing;
    let _ = writeln!(
        out,
        "  pairs         {} written; skipped: {} dt<=0, {} gaps; {} without velocity, {} without imu",
        s.pairs_written,
        p.skipped_nonpositive_dt,
        p.skipped_gap,
        p.pairs_without_velocity,
        p.pairs_without_imu
    );
    let a = &s.annotation;
    let _ = writeln!(
        out,
        "  looming       {} pairs annotated ({} LiDAR-only, {} with the ego motion estimated from the scans, {} without a range image); {} points, {} moving, {} at threat; engine {:.1} s",
        a.pairs_annotated,
        a.pairs_lidar_only,
        a.pairs_motion_estimated,
        a.pairs_without_image,
        a.points_written,
        a.disagreement_points_written,
        a.threat_points_written,
        a.engine_s
    );
    if a.images_not_encoded > 0 {
        let _ = writeln!(
            out,
            "  warning       {} range images could not be encoded as PNG and were left out",
            a.images_not_encoded
        );
    }
    let _ = writeln!(out, "  near misses   {}", s.events.len());
    for event in s.events.iter().take(5) {
        let _ = writeln!(
            out,
            "    {} at {}",
            looming::annotate::foxglove::event_summary(event),
            looming::model::format_log_time(event.start_log_time_ns)
        );
    }
    if s.events.len() > 5 {
        let _ = writeln!(
            out,
            "    ... (all of them with `looming events` or --events)"
        );
    }
    if s.replaced_messages > 0 {
        let _ = writeln!(
            out,
            "  replaced      {} messages of an earlier run's /looming/* channels",
            s.replaced_messages
        );
    }
    let _ = writeln!(out, "  bad messages  {}", s.bad_messages);
    for bad in s.bad_message_examples.iter().take(5) {
        let _ = writeln!(out, "    {bad}");
    }
    if s.bad_messages > 5 {
        let _ = writeln!(out, "    ... (all of them in --json-summary)");
    }
    for warning in &s.warnings {
        let _ = writeln!(out, "  warning       {warning}");
    }
    let _ = writeln!(
        out,
        "  size          {:.1} MB -> {:.1} MB in {:.2} s ({:.1} MB/s)",
        mb(s.input_bytes),
        mb(s.output_bytes),
        s.elapsed_s,
        mb(s.input_bytes) / s.elapsed_s.max(1e-9)
    );
    out
}
