//! What a run did (`RunSummary`, the `--json-summary`), the `looming`
//! metadata record it leaves in the output, and the `--events` file.

use std::collections::BTreeMap;
use std::path::Path;
use std::time::Instant;

use crate::annotate::AnnotateStats;
use crate::events::{EventsFile, NearMissEvent};
use crate::input::{InputFile, ReadMode, ReadReport};
use crate::output::{AtomicFile, WriteMode};
use crate::pairing::PairingStats;
use crate::topics::TopicSelection;

use super::scans::{BadMessage, DecodedCounts};
use super::sensors::SensorOutcome;
use super::stages::PassOutcome;
use super::{ProcessConfig, ProcessError};

/// How the summary's warning about a log without LiDAR starts (`batch`
/// recognises it).
pub const NO_LIDAR_COPIED: &str = "no LiDAR topic (--if-no-lidar copy)";

/// What a run did, for the one-screen summary and `--json-summary`.
#[derive(Debug, Clone, serde::Serialize)]
pub struct RunSummary {
    pub tool_version: String,
    pub input: String,
    pub output: String,
    pub read: ReadMode,
    /// Input chunks copied as they are, or every message written anew.
    pub write: WriteMode,
    /// The topics of the (first) LiDAR sensor and the motion sources.
    pub topics: TopicSelection,
    /// With several LiDARs: each sensor's figures (empty with one).
    #[serde(skip_serializing_if = "Vec::is_empty")]
    pub sensors: Vec<SensorOutcome>,
    pub messages_copied: u64,
    pub metadata_copied: u64,
    pub attachments_copied: u64,
    pub decoded: DecodedCounts,
    pub pairs_written: u64,
    pub pairing: PairingStats,
    pub annotation: AnnotateStats,
    /// Near-miss events, ranked by minimum time to contact.
    pub events: Vec<NearMissEvent>,
    /// Messages of an earlier run's `/looming/*` channels dropped by `--replace`.
    pub replaced_messages: u64,
    pub bad_messages: u64,
    pub bad_messages_by_topic: BTreeMap<String, u64>,
    /// The first few bad messages, in full.
    pub bad_message_examples: Vec<BadMessage>,
    pub input_report: ReadReport,
    pub warnings: Vec<String>,
    pub input_bytes: u64,
    pub output_bytes: u64,
    pub elapsed_s: f64,
}

/// What a finished pass was run with.
pub(super) struct Run {
    /// One selection per LiDAR sensor (one `none` for a log copied through).
    pub(super) sensors: Vec<TopicSelection>,
    pub(super) write_mode: WriteMode,
    pub(super) started: Instant,
    pub(super) restarted_because: Option<String>,
    /// What finding merged clouds' sensors had to say.
    pub(super) split_warnings: Vec<String>,
}

pub(super) fn finish_run(
    config: &ProcessConfig,
    input: &InputFile,
    run: Run,
    outcome: PassOutcome,
) -> Result<RunSummary, ProcessError> {
    let Run {
        sensors,
        write_mode,
        started,
        restarted_because,
        split_warnings,
    } = run;
    let PassOutcome {
        mut writer,
        report,
        summary_counts,
        pairing,
    } = outcome;
    let stats = pairing.stats.clone();
    let topics = sensors
        .first()
        .cloned()
        .unwrap_or_else(TopicSelection::none);
    writer.write_metadata(&run_metadata(config, input, &sensors, &write_mode, &stats))?;
    let output_bytes = writer.finish()?;
    let mut warnings: Vec<String> = Vec::new();
    if topics.lidar.is_none() {
        warnings.push(format!(
            "{NO_LIDAR_COPIED}: every record copied through, no looming channel written"
        ));
    }
    if let ReadMode::Linear { reason } = input.mode() {
        warnings.push(format!("read linearly in file order ({reason})"));
    }
    if let Some(reason) = restarted_because {
        warnings.push(format!(
            "restarted the indexed read as a linear read: {reason}"
        ));
    }
    warnings.extend(report.warnings.iter().map(|w| w.message.clone()));
    warnings.extend(split_warnings);
    warnings.extend(pairing.warnings.iter().cloned());
    let mut events = pairing.events;
    crate::events::rank(&mut events);
    if let Some(path) = &config.events_file {
        write_events_file(config, path, &events, pairing.annotation.event_min_cells)?;
    }
    Ok(RunSummary {
        tool_version: env!("CARGO_PKG_VERSION").into(),
        input: config.input.display().to_string(),
        output: config.output.display().to_string(),
        read: input.mode().clone(),
        write: write_mode,
        topics,
        sensors: pairing.sensors,
        messages_copied: summary_counts.messages,
        metadata_copied: summary_counts.metadata,
        attachments_copied: summary_counts.attachments,
        decoded: pairing.decoded,
        pairs_written: pairing.pairs_written,
        pairing: stats,
        annotation: pairing.annotation,
        events,
        replaced_messages: summary_counts.replaced,
        bad_messages: pairing.bad.count,
        bad_messages_by_topic: pairing.bad.by_topic,
        bad_message_examples: pairing.bad.examples,
        input_report: report,
        warnings,
        input_bytes: file_size(&config.input),
        output_bytes,
        elapsed_s: started.elapsed().as_secs_f64(),
    })
}

/// Name of the metadata record a run writes.
pub const RUN_METADATA_NAME: &str = "looming";

/// The `looming` metadata record: tool version and the fully resolved
/// configuration. Holds nothing that changes between identical runs.
fn run_metadata(
    config: &ProcessConfig,
    input: &InputFile,
    sensors: &[TopicSelection],
    write_mode: &WriteMode,
    stats: &PairingStats,
) -> mcap::records::Metadata {
    let topics = sensors
        .first()
        .cloned()
        .unwrap_or_else(TopicSelection::none);
    let input_name = config
        .input
        .file_name()
        .map(|n| n.to_string_lossy().into_owned())
        .unwrap_or_default();
    let mut resolved = serde_json::json!({
        "input_file": input_name,
        "read": input.mode(),
        "write": write_mode,
        "topics": topics,
        "strict": config.scans.strict,
        "verify_crc": config.scans.input_options.verify_crc,
        "reorder_window_s": config.scans.input_options.reorder_window_ns as f64 * 1e-9,
        "pairing": config.scans.pairing,
        "extrinsic_source": stats.extrinsic_source,
        "nominal_period_s": stats.nominal_period_s,
        "output": config.output_options,
        "max_points_per_scan": config.scans.decode_limits.max_points,
        "split_field": config.scans.decode_limits.sensor_field,
        "annotate": config.annotate,
        "replace": config.replace,
        "if_no_lidar": config.if_no_lidar,
    });
    if sensors.len() > 1 {
        // Every sensor's topics (`topics` is the first's).
        resolved["sensors"] = serde_json::json!(sensors);
    }
    let mut metadata = BTreeMap::new();
    metadata.insert("tool".to_string(), "looming".to_string());
    metadata.insert("version".to_string(), env!("CARGO_PKG_VERSION").to_string());
    metadata.insert("config".to_string(), resolved.to_string());
    mcap::records::Metadata {
        name: RUN_METADATA_NAME.into(),
        metadata,
    }
}

/// The `--events` file, written whole to a temporary file and renamed.
fn write_events_file(
    config: &ProcessConfig,
    path: &Path,
    events: &[NearMissEvent],
    min_cells: Option<usize>,
) -> Result<(), ProcessError> {
    let file = EventsFile {
        tool_version: env!("CARGO_PKG_VERSION").into(),
        input: config.input.display().to_string(),
        output: config.output.display().to_string(),
        config: config.annotate.events.clone(),
        min_cells,
        events: events.to_vec(),
    };
    let err = |source| ProcessError::EventsFile {
        path: path.to_path_buf(),
        source,
    };
    let mut temp = AtomicFile::create(path).map_err(err)?;
    serde_json::to_writer_pretty(&mut temp, &file).map_err(|e| err(e.into()))?;
    temp.commit().map_err(err)?;
    Ok(())
}

fn file_size(path: &Path) -> u64 {
    std::fs::metadata(path).map(|m| m.len()).unwrap_or(0)
}
