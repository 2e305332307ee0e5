//! Wires the stages together: reader+decoder thread -> pairing thread -> writer
//! (the calling thread), with bounded channels between them so every stage
//! works at once while memory stays bounded. A single ordered chain of channels
//! makes the output deterministic: the same input and options give the same
//! bytes.
//!
//! `scans` turns messages into scan pairs (shared with `eval` and `render`
//! through [`replay()`]; with several LiDARs, a pairer per sensor),
//! `stages` runs `process`'s threads, `sensors` annotates each LiDAR and
//! merges their near misses, `summary` reports the run, `replace` guards
//! against processing an annotated log twice.

mod replace;
pub mod replay;
mod scans;
mod sensors;
mod split;
mod stages;
mod summary;

use std::path::PathBuf;
use std::sync::atomic::{AtomicBool, Ordering};
use std::time::Instant;

use crate::annotate::AnnotateConfig;
use crate::input::{InputError, InputFile, ReadMode};
use crate::output::{OutputError, OutputOptions, WriteMode, check_output_path};
use crate::topics::{TopicError, TopicSelection, select_sensors};

pub use replay::{ReplayError, ReplayReport, replay, replay_input};
pub use scans::{BadMessage, BadMessages, DecodedCounts, ScanOptions};
pub use sensors::SensorOutcome;
pub use summary::{NO_LIDAR_COPIED, RUN_METADATA_NAME, RunSummary};

use replace::refuse_processed_input;
use stages::run_once;
use summary::{Run, finish_run};

/// Everything `looming process` needs to know.
#[derive(Debug, Clone, serde::Serialize)]
pub struct ProcessConfig {
    pub input: PathBuf,
    pub output: PathBuf,
    /// How the log is read, decoded and paired (shared with `eval` and `render`).
    pub scans: ScanOptions,
    pub output_options: OutputOptions,
    pub annotate: AnnotateConfig,
    /// Drop the `/looming/*` channels of an already processed input and write
    /// fresh ones (else such an input is refused).
    pub replace: bool,
    /// Also write the events, ranked, to this JSON file.
    pub events_file: Option<PathBuf>,
    /// What to do with a log that has no LiDAR topic.
    pub if_no_lidar: NoLidarPolicy,
}

/// What `process` does with a log in which no LiDAR topic is found.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Default, serde::Serialize)]
#[serde(rename_all = "snake_case")]
pub enum NoLidarPolicy {
    /// Refuse it ([`ProcessError::Topic`] with [`TopicError::Missing`],
    /// which lists the log's channels).
    #[default]
    Refuse,
    /// Copy every record through with the run record, and no looming
    /// channel, so that a fleet's output holds every log.
    Copy,
}

#[derive(Debug, thiserror::Error)]
pub enum ProcessError {
    #[error(transparent)]
    Input(#[from] InputError),
    #[error(transparent)]
    Output(#[from] OutputError),
    #[error("{path}: {source}")]
    Topic { path: PathBuf, source: TopicError },
    #[error("{path}: already holds looming output ({topics})")]
    AlreadyProcessed { path: PathBuf, topics: String },
    #[error("{path}: cannot write the events file: {source}")]
    EventsFile {
        path: PathBuf,
        source: std::io::Error,
    },
    #[error("bad input (strict mode): {0}")]
    Strict(String),
    #[error("{path}: interrupted; nothing written (the temporary output was removed)")]
    Interrupted { path: PathBuf },
    #[error("internal error: {0}")]
    Internal(String),
}

/// Set once a stop is asked for (Ctrl-C): every running pass stops at its
/// next record, and its temporary output is removed as on any error.
static STOP_REQUESTED: AtomicBool = AtomicBool::new(false);

/// Ask every `process` run of this process to stop (from a signal handler:
/// it only sets a flag).
pub fn request_stop() {
    STOP_REQUESTED.store(true, Ordering::SeqCst);
}

/// Whether a stop was asked for.
pub fn stop_requested() -> bool {
    STOP_REQUESTED.load(Ordering::SeqCst)
}

/// Progress reports from the writer: messages copied so far and the total
/// expected, when known.
pub trait ProgressSink: Sync {
    fn update(&self, messages_done: u64, messages_total: Option<u64>);
}

/// No progress output.
pub struct NoProgress;
impl ProgressSink for NoProgress {
    fn update(&self, _: u64, _: Option<u64>) {}
}

/// Run `looming process`.
pub fn process(
    config: &ProcessConfig,
    progress: &dyn ProgressSink,
) -> Result<RunSummary, ProcessError> {
    let started = Instant::now();
    check_output_path(&config.input, &config.output, config.output_options.force)?;
    let mut input = InputFile::open(&config.input, config.scans.input_options.clone())?;
    if !config.replace {
        refuse_processed_input(&input)?;
    }
    let mut restarted_because = None;
    loop {
        let sensors = match select_sensors(input.catalog(), &config.scans.topics) {
            Ok(sensors) => sensors,
            // Nothing to decode: the pass copies every record.
            Err(TopicError::Missing(_)) if config.if_no_lidar == NoLidarPolicy::Copy => {
                vec![TopicSelection::none()]
            }
            Err(source) => {
                return Err(ProcessError::Topic {
                    path: config.input.clone(),
                    source,
                });
            }
        };
        let (sensors, split_warnings) = split::expand(&input, &config.scans, sensors);
        let write_mode = choose_write_mode(config, &input);
        let outcome = run_once(config, &input, &sensors, &write_mode, progress)?;
        // IndexedReader silently skips messages outside chunks: if the count
        // disagrees with the statistics, read the file linearly instead.
        let expected = input.expected_messages();
        let read = outcome.summary_counts.messages + outcome.summary_counts.replaced;
        if *input.mode() == ReadMode::Indexed
            && expected.is_some_and(|n| n != read)
            && outcome.report.bad_crc_chunks == 0
        {
            let reason = format!(
                "the chunk indexes yielded {} messages but the statistics count {}",
                read,
                expected.unwrap_or(0)
            );
            drop(outcome.writer);
            restarted_because = Some(reason.clone());
            input.force_linear(reason)?;
            continue;
        }
        let run = Run {
            sensors,
            write_mode,
            started,
            restarted_because,
            split_warnings,
        };
        return finish_run(config, &input, run, outcome);
    }
}

/// Copy the input's chunks as they are when the input allows it; else write
/// every message anew (the reason goes into the summary).
fn choose_write_mode(config: &ProcessConfig, input: &InputFile) -> WriteMode {
    let reason = if config.replace {
        "--replace drops channels whose messages share the input's chunks".to_string()
    } else if let Some(blocker) = input.copy_blocker() {
        blocker.to_string()
    } else {
        return WriteMode::PassThrough;
    };
    WriteMode::Rewrite { reason }
}
