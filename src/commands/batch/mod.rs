//! `looming batch`: `process` over a fleet of logs on one machine. Each log's
//! output goes below `OUT_DIR/logs/` (written atomically, as `process`
//! writes it) with a record beside it; a log whose record still holds (same
//! input fingerprint, same configuration, output present) is not run again,
//! so a re-run after a crash or a kill redoes only what is missing. One bad
//! log never stops the batch: it is recorded as failed, with the reason. The
//! fleet files (`fleet`) are rebuilt from the records at the end.

mod fleet;
mod inputs;
mod pictures;
mod plot;
mod record;
mod report;

use std::path::{Path, PathBuf};
use std::sync::Mutex;
use std::sync::atomic::{AtomicUsize, Ordering};
use std::time::Instant;

pub use fleet::{
    FLEET_JSON, FleetNearMiss, LAYOUT_JSON, NEAR_MISS_EVENTS_JSONL, NEAR_MISSES_CSV,
    NEAR_MISSES_JSONL, REPORT_HTML,
};
pub use inputs::{BatchLog, Shard, discover};
pub use pictures::MAX_PICTURED_EVENTS;
pub use record::{
    EventClip, EventPictures, FleetEntry, FleetQuality, FleetSensorQuality, InputFingerprint,
    LogRecord, LogStatus, PeakSeries,
};

use crate::output::remove_stale_temp_files;
use crate::pipeline::{NO_LIDAR_COPIED, NoProgress, ProcessConfig, ProcessError, process};
use crate::topics::TopicError;

/// What a log's record file adds to its output's name.
const RECORD_SUFFIX: &str = ".batch.json";

/// Everything `looming batch` needs to know.
#[derive(Debug, Clone)]
pub struct BatchOptions {
    pub inputs: Vec<PathBuf>,
    pub out_dir: PathBuf,
    /// Logs processed at once.
    pub jobs: usize,
    pub shard: Option<Shard>,
    /// Run only these logs (output paths relative to `OUT_DIR/logs/`); like
    /// a shard, such a run writes no fleet files.
    pub only: Vec<PathBuf>,
    /// Redo every log, records or not.
    pub force: bool,
    /// `process`'s configuration for every log (its input and output are
    /// set per log).
    pub process: ProcessConfig,
    /// `--clips SECONDS`: a clip per near miss, this long before and after.
    pub clips_margin_s: Option<f64>,
}

/// What this run did with a log.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum RunAction {
    /// Run now (whatever its status).
    Ran,
    /// Its record still held: not run again.
    UpToDate,
}

/// A log's outcome in this run.
#[derive(Debug, Clone)]
pub struct LogOutcome {
    pub record: LogRecord,
    pub action: RunAction,
}

#[derive(Debug, thiserror::Error)]
pub enum BatchError {
    #[error("{path}: {source}")]
    Io {
        path: PathBuf,
        source: std::io::Error,
    },
    #[error("no input log has the output path {relative} (see --list)")]
    NotAnInput { relative: PathBuf },
    #[error("interrupted: the logs done have their outputs and records; a re-run does the rest")]
    Interrupted,
}

impl BatchError {
    /// A usage error (exit code 2 by the CLI's convention).
    pub fn is_usage(&self) -> bool {
        matches!(self, BatchError::NotAnInput { .. })
    }
}

/// The logs a batch runs on: its inputs' logs, then its shard's share, then
/// those `only` names.
pub fn plan(options: &BatchOptions) -> Result<Vec<BatchLog>, BatchError> {
    let mut logs =
        discover(&options.inputs).map_err(|(path, source)| BatchError::Io { path, source })?;
    if let Some(shard) = options.shard {
        logs = shard.select(logs);
    }
    if let Some(missing) = options
        .only
        .iter()
        .find(|wanted| !logs.iter().any(|log| &log.relative == *wanted))
    {
        return Err(BatchError::NotAnInput {
            relative: missing.clone(),
        });
    }
    if !options.only.is_empty() {
        logs.retain(|log| options.only.contains(&log.relative));
    }
    Ok(logs)
}

/// Where a log's output goes.
pub fn output_path(out_dir: &Path, log: &BatchLog) -> PathBuf {
    output_paths(out_dir, log).0
}

/// Hears how a batch goes (from its worker threads).
pub trait BatchProgress: Sync {
    /// The logs found, before any runs.
    fn start(&self, logs: usize);
    /// A log finished.
    fn done(&self, log: &BatchLog, outcome: &LogOutcome);
}

/// Run the batch. The outcomes come back in the logs' order.
pub fn run_batch(
    options: &BatchOptions,
    progress: &dyn BatchProgress,
) -> Result<Vec<LogOutcome>, BatchError> {
    let io_error = |path: &Path| {
        let path = path.to_path_buf();
        move |source| BatchError::Io { path, source }
    };
    let logs = plan(options)?;
    progress.start(logs.len());
    let config_crc32 = config_fingerprint(&options.process, options.clips_margin_s);
    let next = AtomicUsize::new(0);
    let outcomes = Mutex::new(vec![None; logs.len()]);
    std::thread::scope(|scope| {
        for _ in 0..options.jobs.clamp(1, logs.len().max(1)) {
            scope.spawn(|| {
                loop {
                    let index = next.fetch_add(1, Ordering::Relaxed);
                    let Some(log) = logs.get(index) else { break };
                    if crate::pipeline::stop_requested() {
                        break;
                    }
                    let outcome = run_log(options, log, config_crc32);
                    progress.done(log, &outcome);
                    outcomes.lock().unwrap_or_else(|e| e.into_inner())[index] = Some(outcome);
                }
            });
        }
    });
    if crate::pipeline::stop_requested() {
        return Err(BatchError::Interrupted);
    }
    let outcomes: Vec<LogOutcome> = outcomes
        .into_inner()
        .unwrap_or_else(|e| e.into_inner())
        .into_iter()
        .flatten()
        .collect();
    // A shard sees only its logs: the fleet files come from `merge_records`
    // once every shard is done.
    if options.shard.is_none() && options.only.is_empty() {
        let records: Vec<LogRecord> = outcomes.iter().map(|o| o.record.clone()).collect();
        fleet::write_fleet_files(&options.out_dir, &records).map_err(io_error(&options.out_dir))?;
    }
    Ok(outcomes)
}

/// Rebuild the fleet files of `out_dir` from every log record below
/// `out_dir/logs` (after sharded runs, or runs on other machines); the
/// records, in the order a single run lists its logs.
pub fn merge_records(out_dir: &Path) -> Result<Vec<LogRecord>, BatchError> {
    let logs_dir = out_dir.join("logs");
    let mut paths = Vec::new();
    record_files_below(&logs_dir, &mut paths).map_err(|source| BatchError::Io {
        path: logs_dir.clone(),
        source,
    })?;
    paths.sort();
    let mut records = Vec::with_capacity(paths.len());
    for path in paths {
        let record = LogRecord::read(&path).ok_or_else(|| BatchError::Io {
            source: std::io::Error::new(std::io::ErrorKind::InvalidData, "not a log record"),
            path,
        })?;
        records.push(record);
    }
    fleet::write_fleet_files(out_dir, &records).map_err(|source| BatchError::Io {
        path: out_dir.to_path_buf(),
        source,
    })?;
    Ok(records)
}

fn record_files_below(dir: &Path, found: &mut Vec<PathBuf>) -> std::io::Result<()> {
    for entry in std::fs::read_dir(dir)? {
        let path = entry?.path();
        if path.is_dir() {
            record_files_below(&path, found)?;
        } else if path.to_string_lossy().ends_with(RECORD_SUFFIX) {
            found.push(path);
        }
    }
    Ok(())
}

/// The configuration's fingerprint: what a log's record must match.
fn config_fingerprint(config: &ProcessConfig, clips_margin_s: Option<f64>) -> u32 {
    let mut template = config.clone();
    template.input = PathBuf::new();
    template.output = PathBuf::new();
    let mut text = serde_json::to_string(&template).unwrap_or_default();
    // Without clips the fingerprint is the one earlier versions wrote.
    if let Some(seconds) = clips_margin_s {
        text.push_str(&format!(" clips {seconds}"));
    }
    crc32fast::hash(text.as_bytes())
}

/// The folder of a log's clips, relative to `OUT_DIR`.
fn clips_dir(relative: &Path) -> PathBuf {
    Path::new("clips").join(relative.with_extension(""))
}

/// Where a log's output and record go.
fn output_paths(out_dir: &Path, log: &BatchLog) -> (PathBuf, PathBuf) {
    let output = out_dir.join("logs").join(&log.relative);
    let mut record = output.clone().into_os_string();
    record.push(RECORD_SUFFIX);
    (output, PathBuf::from(record))
}

/// One log: its record if it still holds, else a run of `process`.
fn run_log(options: &BatchOptions, log: &BatchLog, config_crc32: u32) -> LogOutcome {
    let (output, record_path) = output_paths(&options.out_dir, log);
    let fingerprint = match InputFingerprint::of(&log.input) {
        Ok(fingerprint) => fingerprint,
        Err(error) => {
            // Recorded too, so that a merge (after shards or a distributed
            // run) lists it; it never holds, so the next run tries again.
            let outcome = unreadable(log, &error.to_string());
            if !crate::pipeline::stop_requested() {
                let _ = outcome.record.write(&record_path);
            }
            return outcome;
        }
    };
    if !options.force
        && let Some(record) = LogRecord::read(&record_path)
        && record.holds_for(&fingerprint, config_crc32, &options.out_dir)
    {
        return LogOutcome {
            record,
            action: RunAction::UpToDate,
        };
    }
    // A run killed mid-log leaves its temporary output (and the record of
    // that log unwritten): clear it before the log is redone.
    let _ = remove_stale_temp_files(&output);
    let _ = remove_stale_temp_files(&record_path);
    // Pictures and clips of an earlier run's events must not outlive them.
    let _ = std::fs::remove_dir_all(options.out_dir.join(pictures::pictures_dir(&log.relative)));
    let _ = std::fs::remove_dir_all(options.out_dir.join(clips_dir(&log.relative)));
    let record = process_log(options, log, &output, fingerprint, config_crc32);
    // An interrupted log is not remembered: the next run redoes it. A
    // record that cannot be written only costs a re-run next time.
    if !crate::pipeline::stop_requested() {
        let _ = record.write(&record_path);
    }
    // The fleet files are built from the record as a later run reads it
    // back, so that they do not change when nothing else does (a float read
    // back from JSON need not be the float written).
    let record = record.read_back();
    LogOutcome {
        record,
        action: RunAction::Ran,
    }
}

/// A log that cannot even be opened: failed, and not remembered.
fn unreadable(log: &BatchLog, reason: &str) -> LogOutcome {
    LogOutcome {
        record: LogRecord {
            input: InputFingerprint {
                size_bytes: 0,
                modified_ns: 0,
                ends_crc32: 0,
            },
            config_crc32: 0,
            entry: entry(log, None, LogStatus::Failed, Some(reason.to_owned()), 0.0),
            near_misses: Vec::new(),
            pictures: Vec::new(),
            peak_series: None,
            clips: Vec::new(),
        },
        action: RunAction::Ran,
    }
}

fn entry(
    log: &BatchLog,
    output: Option<PathBuf>,
    status: LogStatus,
    reason: Option<String>,
    seconds: f64,
) -> FleetEntry {
    FleetEntry {
        input: log.input.clone(),
        output,
        status,
        reason,
        scans: 0,
        pairs: 0,
        events: 0,
        bad_messages: 0,
        seconds,
        quality: None,
        lidar_frame: None,
    }
}

/// Run `process` on the log into `output`; for a processed log, its
/// quality figures and, when it has near misses, their pictures and its
/// path peak over time.
fn process_log(
    options: &BatchOptions,
    log: &BatchLog,
    output: &Path,
    fingerprint: InputFingerprint,
    config_crc32: u32,
) -> LogRecord {
    let started = Instant::now();
    let mut config = options.process.clone();
    config.input = log.input.clone();
    config.output = output.to_path_buf();
    // The record decides whether a log is redone; an output without one is
    // from an interrupted run.
    config.output_options.force = true;
    let result = process(&config, &NoProgress);
    let mut record = LogRecord {
        input: fingerprint,
        config_crc32,
        entry: entry(log, None, LogStatus::Failed, None, 0.0),
        near_misses: Vec::new(),
        pictures: Vec::new(),
        peak_series: None,
        clips: Vec::new(),
    };
    match result {
        // `--if-no-lidar copy`: the log is copied, still skipped by policy.
        Ok(summary) if summary.topics.lidar.is_none() => {
            record.entry.status = LogStatus::Skipped;
            record.entry.output = Some(output.to_path_buf());
            record.entry.reason = Some(format!("{NO_LIDAR_COPIED}: every record copied"));
        }
        Ok(summary) => {
            let entry = &mut record.entry;
            entry.status = LogStatus::Processed;
            entry.output = Some(output.to_path_buf());
            entry.scans = summary.decoded.scans;
            entry.pairs = summary.pairs_written;
            entry.events = summary.events.len();
            entry.bad_messages = summary.bad_messages;
            // Processed, but only up to where the file ends.
            entry.reason = summary.input_report.truncated.clone();
            record.near_misses = summary.events;
            let sensor_topics: Vec<(String, String)> = summary
                .sensors
                .iter()
                .map(|s| (s.name.clone(), s.topic.clone()))
                .collect();
            describe_processed(options, log, &config, output, &sensor_topics, &mut record);
        }
        Err(ProcessError::Topic {
            source: TopicError::Missing(reason),
            ..
        }) => {
            record.entry.status = LogStatus::Skipped;
            record.entry.reason = Some(first_line(&reason));
        }
        Err(error) => record.entry.reason = Some(error.to_string()),
    }
    record.entry.seconds = (started.elapsed().as_secs_f64() * 1000.0).round() / 1000.0;
    record
}

/// What the fleet files show of a processed log beyond its summary: the
/// quality figures and, for near misses, the series and pictures. A picture
/// that cannot be drawn is said in the reason; the log stays processed.
fn describe_processed(
    options: &BatchOptions,
    log: &BatchLog,
    config: &ProcessConfig,
    output: &Path,
    sensor_topics: &[(String, String)],
    record: &mut LogRecord,
) {
    let report = crate::commands::quality::read_quality(output).ok();
    let threshold_per_s = 1.0 / config.annotate.events.ttc_threshold_s;
    if let Some(report) = report {
        if !record.near_misses.is_empty() {
            record.peak_series = pictures::peak_series(&report.scans, threshold_per_s);
        }
        record.entry.quality = Some(fleet_quality(report));
    }
    record.entry.lidar_frame = crate::commands::layout::target_of(output, None)
        .ok()
        .map(|target| target.frame_id);
    let drawn = pictures::draw_event_pictures(
        config,
        &log.input,
        &options.out_dir,
        &log.relative,
        &record.near_misses,
        sensor_topics,
    );
    match drawn {
        Ok(pictures) => record.pictures = pictures,
        Err(error) => add_reason(record, format!("pictures not drawn: {error}")),
    }
    if let Some(seconds) = options.clips_margin_s {
        match write_log_clips(options, log, output, &record.near_misses, seconds) {
            Ok(clips) => record.clips = clips,
            Err(error) => add_reason(record, format!("clips not written: {error}")),
        }
    }
}

/// A log's clips, in `OUT_DIR/clips/<log without extension>/`.
fn write_log_clips(
    options: &BatchOptions,
    log: &BatchLog,
    output: &Path,
    events: &[crate::events::NearMissEvent],
    seconds: f64,
) -> Result<Vec<record::EventClip>, crate::commands::clips::ClipError> {
    let dir = clips_dir(&log.relative);
    let stem = log
        .relative
        .file_stem()
        .unwrap_or_default()
        .to_string_lossy();
    let written = crate::commands::clips::write_clips(
        output,
        events,
        &options.out_dir.join(&dir),
        &stem,
        seconds,
        true,
    )?;
    Ok(written
        .into_iter()
        .map(|clip| record::EventClip {
            event_id: clip.event_id,
            path: dir.join(clip.path.file_name().unwrap_or_default()),
        })
        .collect())
}

/// Say `said` in the log's reason (it stays processed).
fn add_reason(record: &mut LogRecord, said: String) {
    record.entry.reason = Some(match record.entry.reason.take() {
        Some(reason) => format!("{reason}; {said}"),
        None => said,
    });
}

/// The quality figures of an annotated log that the fleet table shows.
fn fleet_quality(report: crate::commands::quality::QualityReport) -> FleetQuality {
    // Several LiDARs: each sensor's trust, and the log's over all their points.
    let sensors: Vec<FleetSensorQuality> = report
        .sensors
        .iter()
        .map(|sensor| FleetSensorQuality {
            sensor: sensor.sensor.clone().unwrap_or_default(),
            trusted_fraction: sensor.totals.trusted_fraction,
            diagnoses: sensor.diagnoses.iter().map(|d| d.code.clone()).collect(),
        })
        .collect();
    let (points, trusted) = report.sensors.iter().fold((0, 0), |(p, t), s| {
        (p + s.totals.points, t + s.totals.trusted_points)
    });
    let totals = report.totals;
    let trusted_fraction = if sensors.is_empty() || points == 0 {
        totals.trusted_fraction
    } else {
        Some(trusted as f64 / points as f64)
    };
    FleetQuality {
        sensors,
        trusted_fraction,
        ground_median_abs_fused_per_s: totals.ground_median_abs_fused_per_s,
        ground_p90_abs_fused_per_s: totals.ground_p90_abs_fused_per_s,
        ground_moving_fraction: totals.ground_moving_fraction,
        dominant_mask: totals.dominant_mask,
        diagnoses: report.diagnoses.into_iter().map(|d| d.code).collect(),
    }
}

fn first_line(text: &str) -> String {
    text.lines().next().unwrap_or_default().to_owned()
}
