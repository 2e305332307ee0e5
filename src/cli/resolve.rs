//! Every check of the command line's values, in one place, and the one
//! validated configuration each command runs with. A bad value is a usage
//! error (exit code 2) naming the flag; the library never sees it.

use looming::annotate::AnnotateConfig;
use looming::commands::render::{RenderAt, RenderOptions};
use looming::decode::DecodeLimits;
use looming::engine::EngineConfig;
use looming::events::EventConfig;
use looming::input::InputOptions;
use looming::output::OutputOptions;
use looming::pairing::{PairingConfig, parse_extrinsic};
use looming::pipeline::{ProcessConfig, ScanOptions};
use looming::topics::TopicOverrides;

use super::Failure;
use std::path::PathBuf;

use looming::commands::batch::{BatchOptions, Shard};

use super::args::{AnnotateArgs, BatchArgs, ProcessArgs, RenderArgs, ScanArgs};

/// A usage error: exit code 2.
fn usage(message: String) -> Failure {
    Failure {
        error: anyhow::anyhow!(message),
        code: 2,
    }
}

/// `--split-field FIELD|none` (a clap value parser): `auto` (the default)
/// the usual names, `none` no split.
pub(crate) fn parse_split_field(text: &str) -> Result<looming::decode::SensorField, String> {
    use looming::decode::SensorField;
    match text.trim() {
        "" => Err("expected a field name, or none".into()),
        "auto" => Ok(SensorField::Auto),
        "none" => Ok(SensorField::Off),
        name => Ok(SensorField::Named(name.to_owned())),
    }
}

/// `--threat-ttc LOW,MEDIUM,HIGH` (a clap value parser, so that clap reports
/// it with the flag).
pub(crate) fn parse_threat_ttc(text: &str) -> Result<[f64; 3], String> {
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

/// How the log is read, decoded and paired, checked.
pub(crate) fn scan_options(args: &ScanArgs) -> Result<ScanOptions, Failure> {
    if !(args.reorder_window.is_finite() && args.reorder_window >= 0.0) {
        return Err(usage(
            "--reorder-window must be a non-negative number of seconds".into(),
        ));
    }
    if args.max_gap.is_some_and(|g| !(g.is_finite() && g > 0.0)) {
        return Err(usage(
            "--max-gap must be a positive number of seconds".into(),
        ));
    }
    if !(args.min_baseline.is_finite() && (0.0..=1.0).contains(&args.min_baseline)) {
        return Err(usage(
            "--min-baseline must be between 0 and 1 second".into(),
        ));
    }
    let cli_extrinsic = match &args.extrinsic {
        Some(text) => Some(
            parse_extrinsic(text)
                .map_err(|e| usage(format!("invalid option: --extrinsic: {e}")))?,
        ),
        None => None,
    };
    Ok(ScanOptions {
        input_options: InputOptions {
            verify_crc: args.verify,
            reorder_window_ns: (args.reorder_window * 1e9) as u64,
            ..InputOptions::default()
        },
        topics: TopicOverrides {
            lidar: args.lidar_topic.clone(),
            imu: args.imu_topic.clone(),
            velocity: args.velocity_topic.clone(),
        },
        pairing: PairingConfig {
            max_gap_s: args.max_gap,
            min_baseline_s: args.min_baseline,
            cli_extrinsic,
            sensor_frame: args.sensor_frame.clone(),
            ..PairingConfig::default()
        },
        decode_limits: DecodeLimits {
            max_points: args.max_points,
            sensor_field: args.split_field.clone(),
        },
        strict: args.strict,
    })
}

/// `--shard K/N` (a clap value parser).
pub(crate) fn parse_shard(text: &str) -> Result<Shard, String> {
    let (index, count) = text
        .split_once('/')
        .ok_or_else(|| format!("{text:?}: expected K/N, e.g. 0/4"))?;
    let parse = |v: &str| v.trim().parse::<u32>().map_err(|e| format!("{v:?}: {e}"));
    let (index, count) = (parse(index)?, parse(count)?);
    if count == 0 || index >= count {
        return Err(format!(
            "{text:?}: K must be below N (0-based), N at least 1"
        ));
    }
    Ok(Shard { index, count })
}

/// The near-miss detector's settings, checked.
fn event_config(args: &AnnotateArgs) -> Result<EventConfig, Failure> {
    if !(args.event_ttc.is_finite() && args.event_ttc > 0.0) {
        return Err(usage(
            "--event-ttc must be a positive number of seconds".into(),
        ));
    }
    if !(args.vehicle_width.is_finite() && args.vehicle_width > 0.0) {
        return Err(usage(
            "--vehicle-width must be a positive number of metres".into(),
        ));
    }
    if !(args.path_margin.is_finite() && args.path_margin >= 0.0) {
        return Err(usage(
            "--path-margin must be zero or a positive number of metres".into(),
        ));
    }
    if args.event_min_cells == Some(0) {
        return Err(usage("--event-min-cells must be at least 1".into()));
    }
    Ok(EventConfig {
        ttc_threshold_s: args.event_ttc,
        min_cells: args.event_min_cells,
        min_pairs: args.event_min_pairs,
        vehicle_width_m: args.vehicle_width,
        path_margin_m: args.path_margin,
        ..EventConfig::default()
    })
}

/// What `process` adds to a log, checked.
fn annotate_config(args: &AnnotateArgs) -> Result<AnnotateConfig, Failure> {
    Ok(AnnotateConfig {
        engine: EngineConfig {
            threat_ttc_s: args.threat_ttc,
            firings_per_column: usize::from(args.firings_per_column),
            ..EngineConfig::default()
        },
        events: event_config(args)?,
        fields: args.fields.into(),
        objects: looming::objects::ObjectConfig::default(),
    })
}

/// What `process` and `batch` share: how logs are read and paired, what is
/// added to them and how they are written; no input or output yet.
fn annotation_run(scans: &ScanArgs, annotate: &AnnotateArgs) -> Result<ProcessConfig, Failure> {
    Ok(ProcessConfig {
        input: PathBuf::new(),
        output: PathBuf::new(),
        scans: scan_options(scans)?,
        output_options: OutputOptions {
            compression: annotate.compression.into(),
            ..OutputOptions::default()
        },
        annotate: annotate_config(annotate)?,
        replace: false,
        events_file: None,
        if_no_lidar: annotate.if_no_lidar.into(),
    })
}

/// `looming process`'s configuration.
pub(crate) fn process_config(args: &ProcessArgs) -> Result<ProcessConfig, Failure> {
    let mut config = annotation_run(&args.scans, &args.annotate)?;
    config.input = args.input.clone();
    config.output = args.output.clone();
    config.output_options.force = args.force;
    config.replace = args.replace;
    config.events_file = args.events.clone();
    Ok(config)
}

/// `process --clips DIR SECONDS`: the folder and the seconds around each
/// near miss.
pub(crate) fn process_clips(args: &ProcessArgs) -> Result<Option<(PathBuf, f64)>, Failure> {
    let Some(values) = &args.clips else {
        return Ok(None);
    };
    let [dir, seconds] = values.as_slice() else {
        return Err(usage(
            "--clips takes a folder and a number of seconds".into(),
        ));
    };
    Ok(Some((PathBuf::from(dir), clip_seconds(seconds)?)))
}

/// Seconds of a clip before and after its near miss: finite, 0 to 600.
pub(crate) fn clip_seconds(text: &str) -> Result<f64, Failure> {
    match text.parse::<f64>() {
        Ok(seconds) if seconds.is_finite() && (0.0..=600.0).contains(&seconds) => Ok(seconds),
        _ => Err(usage(format!(
            "--clips: seconds must be a number from 0 to 600, not {text:?}"
        ))),
    }
}

/// `looming batch`'s options: `process`'s configuration for every log.
pub(crate) fn batch_options(args: &BatchArgs) -> Result<BatchOptions, Failure> {
    if args.jobs == Some(0) {
        return Err(usage("--jobs must be at least 1".into()));
    }
    let cores = std::thread::available_parallelism().map_or(1, |n| n.get());
    let process = annotation_run(&args.scans, &args.annotate)?;
    Ok(BatchOptions {
        inputs: args.inputs.clone(),
        out_dir: args.output.clone().unwrap_or_default(),
        jobs: args.jobs.unwrap_or((cores / 2).max(1)),
        shard: args.shard,
        only: args.only.clone(),
        force: args.force,
        process,
        clips_margin_s: args.clips.as_deref().map(clip_seconds).transpose()?,
    })
}

/// `looming render`'s options.
pub(crate) fn render_options(args: &RenderArgs) -> Result<RenderOptions, Failure> {
    let at = match (args.time, args.frame) {
        (Some(t), _) if t.is_finite() && t >= 0.0 => RenderAt::Time(t),
        (Some(_), _) => {
            return Err(usage(
                "--time must be a non-negative number of seconds".into(),
            ));
        }
        (None, Some(n)) => RenderAt::Frame(n),
        (None, None) => return Err(usage("give --time SECONDS or --frame N".into())),
    };
    Ok(RenderOptions {
        input: args.file.clone(),
        output: args.output.clone(),
        channel: args.channel.into(),
        at,
        view: args.view.into(),
        row_height_px: args.row_height.max(1),
        top_extent_m: args.extent,
        top_size_px: args.size.max(16),
        force: args.force,
        scans: scan_options(&args.scans)?,
        engine: looming::engine::EngineConfig::default(),
    })
}
