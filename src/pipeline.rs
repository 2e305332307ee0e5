//! Wires the stages together: reader+decoder thread -> pairing thread -> writer
//! (the calling thread), with bounded channels between them so every stage
//! works at once while memory stays bounded. A single ordered chain of channels
//! makes the output deterministic: the same input and options give the same
//! bytes.

use std::collections::{BTreeMap, BTreeSet, HashMap};
use std::path::{Path, PathBuf};
use std::sync::mpsc::{Receiver, SyncSender, sync_channel};
use std::time::Instant;

use crate::annotate::{AnnotateConfig, AnnotateStats, Annotator, OwnMessage, channel_specs};
use crate::decode::{self, DecodeLimits};
use crate::events::{EventsFile, NearMissEvent};
use std::sync::Arc;

use crate::annotate::pairs::{PairRecord, pairs_channel_spec};
use crate::budget::{ByteBudget, Ticket};
use crate::input::{Catalog, CopiedRecord, CopyEvent};
use crate::input::{Flow, InputError, InputFile, InputOptions, InputRecord, ReadMode, ReadReport};
use crate::messages::Decoded;
use crate::output::{
    Copied, OutputError, OutputOptions, OutputWriter, WriteMode, check_output_path,
};
use crate::pairing::{PairEvent, PairingConfig, PairingStats, ScanPairer};
use crate::topics::{Role, SelectedChannel, TopicError, TopicOverrides, TopicSelection, select};

/// Items between the reader and pairing stages. Channels hold few items: point
/// clouds are megabytes each.
const STAGE_QUEUE_LEN: usize = 32;
/// Bytes of copied input records (chunks, attachments) read ahead of the
/// writer at most (one record bigger than this still passes, alone): a
/// dozen 4 MiB chunks, more than a second of a 64-beam sensor's log.
const COPY_BUDGET_BYTES: u64 = 48 << 20;

/// Everything `looming process` needs to know.
#[derive(Debug, Clone, serde::Serialize)]
pub struct ProcessConfig {
    pub input: PathBuf,
    pub output: PathBuf,
    pub input_options: InputOptions,
    pub output_options: OutputOptions,
    pub topics: TopicOverrides,
    pub pairing: PairingSettings,
    /// Any bad input message, or chunk CRC mismatch, fails the run.
    pub strict: bool,
    #[serde(skip)]
    pub decode_limits: DecodeLimits,
    pub annotate: AnnotateConfig,
    /// Drop the `/looming/*` channels of an already processed input and write
    /// fresh ones (else such an input is refused).
    pub replace: bool,
    /// Also write the events, ranked, to this JSON file.
    pub events_file: Option<PathBuf>,
}

/// Pairing options from the command line.
#[derive(Debug, Clone, serde::Serialize)]
pub struct PairingSettings {
    /// Largest stamp gap paired, seconds; default: `max_gap_periods` nominal periods.
    pub max_gap_s: Option<f64>,
    pub max_gap_periods: f64,
    /// LiDAR pose in the motion frame, `x,y,z,qx,qy,qz,qw`, overriding `/tf_static`.
    pub extrinsic: Option<String>,
    /// How long a motion sample may be held past the end of its series, seconds.
    pub motion_hold_s: f64,
}

impl Default for PairingSettings {
    fn default() -> Self {
        Self {
            max_gap_s: None,
            max_gap_periods: 3.0,
            extrinsic: None,
            motion_hold_s: 0.2,
        }
    }
}

/// A bad input message: skipped and counted (fatal with `--strict`).
#[derive(Debug, Clone, serde::Serialize)]
pub struct BadMessage {
    pub file: String,
    pub topic: String,
    pub log_time_ns: u64,
    pub reason: String,
}

impl std::fmt::Display for BadMessage {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        write!(
            f,
            "{}: topic {} at log time {} ({}): {}",
            self.file,
            self.topic,
            self.log_time_ns,
            format_log_time(self.log_time_ns),
            self.reason
        )
    }
}

/// Log time as seconds.nanoseconds, as `mcap cat` prints it.
pub fn format_log_time(log_time_ns: u64) -> String {
    format!(
        "{}.{:09} s",
        log_time_ns / 1_000_000_000,
        log_time_ns % 1_000_000_000
    )
}

#[derive(Debug, thiserror::Error)]
pub enum ProcessError {
    #[error(transparent)]
    Input(#[from] InputError),
    #[error(transparent)]
    Output(#[from] OutputError),
    #[error("{path}: {source}")]
    Topic { path: PathBuf, source: TopicError },
    #[error("invalid option: {0}")]
    Config(String),
    #[error(
        "{path}: already holds looming output ({topics}); process the original log, or pass --replace to drop these channels and write fresh ones"
    )]
    AlreadyProcessed { path: PathBuf, topics: String },
    #[error("{path}: cannot write the events file: {source}")]
    EventsFile {
        path: PathBuf,
        source: std::io::Error,
    },
    #[error("bad input (strict mode): {0}")]
    Strict(String),
    #[error("internal error: {0}")]
    Internal(String),
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

/// What a run did, for the one-screen summary and `--json-summary`.
#[derive(Debug, Clone, serde::Serialize)]
pub struct RunSummary {
    pub tool_version: String,
    pub input: String,
    pub output: String,
    pub read: ReadMode,
    /// Input chunks copied as they are, or every message written anew.
    pub write: WriteMode,
    pub topics: TopicSelection,
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

/// Messages decoded per role.
#[derive(Debug, Clone, Default, serde::Serialize)]
pub struct DecodedCounts {
    pub scans: u64,
    pub lidar_points: u64,
    pub invalid_points_skipped: u64,
    pub imu: u64,
    pub velocity: u64,
    pub tf_messages: u64,
}

const BAD_MESSAGE_EXAMPLES: usize = 20;

/// Run `looming process`.
pub fn process(
    config: &ProcessConfig,
    progress: &dyn ProgressSink,
) -> Result<RunSummary, ProcessError> {
    let started = Instant::now();
    check_output_path(&config.input, &config.output, config.output_options.force)?;
    let cli_extrinsic = match &config.pairing.extrinsic {
        Some(text) => Some(
            crate::pairing::parse_extrinsic(text)
                .map_err(|e| ProcessError::Config(format!("--extrinsic: {e}")))?,
        ),
        None => None,
    };
    let mut input = InputFile::open(&config.input, config.input_options.clone())?;
    if !config.replace {
        refuse_processed_input(&input)?;
    }
    let mut restarted_because = None;
    loop {
        let topics =
            select(input.catalog(), &config.topics).map_err(|source| ProcessError::Topic {
                path: config.input.clone(),
                source,
            })?;
        let write_mode = choose_write_mode(config, &input);
        let outcome = run_once(
            config,
            &input,
            &topics,
            &write_mode,
            cli_extrinsic,
            progress,
        )?;
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
            topics,
            write_mode,
            started,
            restarted_because,
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

fn is_ours(topic: &str) -> bool {
    topic.starts_with("/looming/")
}

/// The input's catalog without the `/looming/*` channels (and the schemas
/// only they use), for `--replace`.
fn without_our_channels(catalog: &Catalog) -> Catalog {
    let mut kept = catalog.clone();
    kept.channels.retain(|_, c| !is_ours(&c.topic));
    let used: std::collections::BTreeSet<u16> = kept
        .channels
        .values()
        .filter_map(|c| c.schema.as_ref().map(|s| s.id))
        .collect();
    kept.schemas.retain(|id, _| used.contains(id));
    kept
}

/// A log that already carries `/looming/*` channels would end up with two sets.
fn refuse_processed_input(input: &InputFile) -> Result<(), ProcessError> {
    let ours: Vec<&str> = input
        .catalog()
        .channels
        .values()
        .filter(|c| is_ours(&c.topic))
        .map(|c| c.topic.as_str())
        .collect();
    if ours.is_empty() {
        return Ok(());
    }
    Err(ProcessError::AlreadyProcessed {
        path: input.path().to_path_buf(),
        topics: ours.join(", "),
    })
}

/// The result of one pass before the output is finalised.
struct PassOutcome {
    writer: OutputWriter,
    report: ReadReport,
    summary_counts: WriterCounts,
    pairing: PairingOutcome,
}

#[derive(Debug, Default, Clone, Copy)]
struct WriterCounts {
    messages: u64,
    metadata: u64,
    attachments: u64,
    own_messages: u64,
    /// Records of an earlier run dropped by `--replace`.
    replaced: u64,
}

/// Items from the reader+decoder stage.
// Decoded scans dominate (see `Decoded`); boxing would add an allocation each.
#[allow(clippy::large_enum_variant)]
enum FromReader {
    Record(InputRecord),
    /// An input record to copy as it is (pass-through), its bytes counted
    /// in the copy budget until written.
    Copy(CopiedRecord, Ticket),
    Decoded {
        log_time_ns: u64,
        decoded: Decoded,
    },
    Bad(BadMessage),
}

/// Items for the writer.
enum ToWriter {
    Input(InputRecord),
    Copy(CopiedRecord, Ticket),
    Own(OwnMessage),
}

fn run_once(
    config: &ProcessConfig,
    input: &InputFile,
    topics: &TopicSelection,
    write_mode: &WriteMode,
    cli_extrinsic: Option<nalgebra::Isometry3<f64>>,
    progress: &dyn ProgressSink,
) -> Result<PassOutcome, ProcessError> {
    let catalog = if config.replace {
        without_our_channels(input.catalog())
    } else {
        Catalog::clone(input.catalog())
    };
    let replaced_channels: std::collections::BTreeSet<u16> = input
        .catalog()
        .channels
        .keys()
        .filter(|id| !catalog.channels.contains_key(id))
        .copied()
        .collect();
    let mut writer = match write_mode {
        WriteMode::PassThrough => {
            OutputWriter::create_pass_through(&config.output, &config.output_options, &catalog)?
        }
        WriteMode::Rewrite { .. } => {
            OutputWriter::create(&config.output, &config.output_options, &catalog)?
        }
    };
    let pairs_channel = writer.add_own_channel(&pairs_channel_spec())?;
    let annotate_channels = channel_specs()
        .iter()
        .map(|spec| writer.add_own_channel(spec))
        .collect::<Result<Vec<u16>, _>>()?;
    let annotator = Annotator::new(config.annotate.clone(), &annotate_channels);
    let pairing_config = PairingConfig {
        max_gap_periods: config.pairing.max_gap_periods,
        max_gap_s: config.pairing.max_gap_s,
        cli_extrinsic,
        has_velocity_source: topics.velocity.is_some(),
        has_imu_source: topics.imu.is_some(),
        motion_hold_s: config.pairing.motion_hold_s,
    };
    let nominal_period_s = input.catalog().nominal_period_s(topics.lidar.channel_id);
    let (reader_tx, reader_rx) = sync_channel::<FromReader>(STAGE_QUEUE_LEN);
    let (writer_tx, writer_rx) = sync_channel::<ToWriter>(STAGE_QUEUE_LEN);
    std::thread::scope(|scope| {
        let reader = scope.spawn(|| read_and_decode(config, input, topics, write_mode, reader_tx));
        let pairing = scope.spawn(move || {
            let mut pairer = ScanPairer::new(pairing_config);
            pairer.set_nominal_period_s(nominal_period_s);
            pair_scans(pairer, annotator, pairs_channel, reader_rx, writer_tx)
        });
        let written = write_all(
            &mut writer,
            writer_rx,
            &replaced_channels,
            input.expected_messages(),
            progress,
        );
        let read = reader
            .join()
            .map_err(|_| ProcessError::Internal("the reader thread panicked".into()))?;
        let pairing = pairing
            .join()
            .map_err(|_| ProcessError::Internal("the pairing thread panicked".into()))?;
        // The writer's error explains a reader that was stopped.
        let counts = written?;
        let report = read?;
        Ok(PassOutcome {
            writer,
            report,
            summary_counts: counts,
            pairing,
        })
    })
}

/// Stage 1: read records and decode the selected topics.
fn read_and_decode(
    config: &ProcessConfig,
    input: &InputFile,
    topics: &TopicSelection,
    write_mode: &WriteMode,
    tx: SyncSender<FromReader>,
) -> Result<ReadReport, ProcessError> {
    let file_name = input.path().display().to_string();
    let mut stage = ReadStage {
        decoder: Decoder {
            config,
            by_channel: topics.all().map(|c| (c.channel_id, c)).collect(),
            file_name: file_name.clone(),
        },
        tx,
        copy_budget: ByteBudget::new(COPY_BUDGET_BYTES),
        strict: config.strict,
        strict_failure: None,
    };
    let result = match write_mode {
        WriteMode::PassThrough => {
            let selected: BTreeSet<u16> = topics.all().map(|c| c.channel_id).collect();
            input.read_copying(config.strict, &selected, &mut |event| {
                stage.copy_event(event)
            })
        }
        WriteMode::Rewrite { .. } => {
            input.read_records(config.strict, &mut |record| stage.record(record))
        }
    };
    if let Some(bad) = stage.strict_failure {
        return Err(ProcessError::Strict(bad.to_string()));
    }
    let report = result.map_err(|error| match error {
        InputError::BadChunk { .. } if config.strict => ProcessError::Strict(error.to_string()),
        error => error.into(),
    })?;
    if config.strict
        && let Some(reason) = &report.truncated
    {
        return Err(ProcessError::Strict(format!("{file_name}: {reason}")));
    }
    Ok(report)
}

/// Bytes a copied record holds while it waits to be written.
fn copied_bytes(record: &CopiedRecord) -> u64 {
    let bytes = match record {
        CopiedRecord::Chunk(chunk) => chunk.record.len() + chunk.message_indexes.len(),
        CopiedRecord::Side(side) => side.bytes.len(),
    };
    bytes as u64
}

/// A decoded message: its log time and what it holds.
type DecodeResult = Result<(u64, Decoded), BadMessage>;

/// Decodes the messages of the selected topics.
struct Decoder<'a> {
    config: &'a ProcessConfig,
    by_channel: HashMap<u16, &'a SelectedChannel>,
    file_name: String,
}

impl Decoder<'_> {
    /// The message decoded, when its channel is selected.
    fn decode(&self, channel_id: u16, log_time_ns: u64, data: &[u8]) -> Option<DecodeResult> {
        let channel = self.by_channel.get(&channel_id)?;
        let is_static = channel.role == Role::TfStatic;
        let decoded = decode::decode(
            channel.kind,
            channel.encoding,
            is_static,
            data,
            &self.config.decode_limits,
        );
        Some(
            decoded
                .map(|decoded| (log_time_ns, decoded))
                .map_err(|err| BadMessage {
                    file: self.file_name.clone(),
                    topic: channel.topic.clone(),
                    log_time_ns,
                    reason: err.to_string(),
                }),
        )
    }
}

/// The reader's side of stage 1: records and decoded messages onto the
/// channel to the pairing stage.
struct ReadStage<'a> {
    decoder: Decoder<'a>,
    tx: SyncSender<FromReader>,
    /// Bytes of copied records read and not yet written.
    copy_budget: Arc<ByteBudget>,
    strict: bool,
    /// The bad message that stopped a strict run.
    strict_failure: Option<BadMessage>,
}

impl ReadStage<'_> {
    fn send(&self, item: FromReader) -> Flow {
        match self.tx.send(item) {
            Ok(()) => Flow::Continue(()),
            Err(_) => Flow::Break(()),
        }
    }

    /// A record to write anew; its message decoded too, when selected.
    fn record(&mut self, record: InputRecord) -> Flow {
        let decoded = match &record {
            InputRecord::Message(message) => {
                self.decoder
                    .decode(message.channel_id, message.log_time_ns, &message.data)
            }
            _ => None,
        };
        if self.send(FromReader::Record(record)).is_break() {
            return Flow::Break(());
        }
        self.deliver(decoded)
    }

    /// What a copying read hands over: records to copy, messages to decode,
    /// messages to write anew.
    fn copy_event(&mut self, event: CopyEvent<'_>) -> Flow {
        match event {
            CopyEvent::Copy(record) => {
                let ticket = self.copy_budget.acquire(copied_bytes(&record));
                self.send(FromReader::Copy(record, ticket))
            }
            CopyEvent::Selected(message) => {
                let header = message.header;
                let decoded = self
                    .decoder
                    .decode(header.channel_id, header.log_time, message.data);
                self.deliver(decoded)
            }
            CopyEvent::Salvaged(message) => {
                self.record(InputRecord::Message(message.to_owned_message()))
            }
        }
    }

    /// Send a decoded message (or its failure) on.
    fn deliver(&mut self, decoded: Option<DecodeResult>) -> Flow {
        let item = match decoded {
            None => return Flow::Continue(()),
            Some(Ok((log_time_ns, decoded))) => FromReader::Decoded {
                log_time_ns,
                decoded,
            },
            Some(Err(bad)) if self.strict => {
                self.strict_failure = Some(bad);
                return Flow::Break(());
            }
            Some(Err(bad)) => FromReader::Bad(bad),
        };
        self.send(item)
    }
}

/// What the pairing stage saw.
#[derive(Debug, Default)]
struct PairingOutcome {
    decoded: DecodedCounts,
    stats: Option<PairingStats>,
    pairs_written: u64,
    bad_messages: u64,
    bad_by_topic: BTreeMap<String, u64>,
    bad_examples: Vec<BadMessage>,
    warnings: Vec<String>,
    annotation: AnnotateStats,
    events: Vec<NearMissEvent>,
}

/// Stage 2: feed the pairer, pass every record on, add `/looming/pairs` and
/// the annotation of every pair.
fn pair_scans(
    mut pairer: ScanPairer,
    mut annotator: Annotator,
    pairs_channel: u16,
    rx: Receiver<FromReader>,
    tx: SyncSender<ToWriter>,
) -> PairingOutcome {
    let mut outcome = PairingOutcome::default();
    for item in rx {
        let events = match item {
            FromReader::Record(record) => {
                if tx.send(ToWriter::Input(record)).is_err() {
                    break;
                }
                continue;
            }
            FromReader::Copy(record, ticket) => {
                if tx.send(ToWriter::Copy(record, ticket)).is_err() {
                    break;
                }
                continue;
            }
            FromReader::Bad(bad) => {
                outcome.bad_messages += 1;
                *outcome.bad_by_topic.entry(bad.topic.clone()).or_default() += 1;
                if outcome.bad_examples.len() < BAD_MESSAGE_EXAMPLES {
                    outcome.bad_examples.push(bad);
                }
                continue;
            }
            FromReader::Decoded {
                log_time_ns,
                decoded,
            } => feed(&mut pairer, &mut outcome.decoded, log_time_ns, decoded),
        };
        if !emit(events, &mut annotator, pairs_channel, &mut outcome, &tx) {
            break;
        }
    }
    let events = pairer.finish();
    if emit(events, &mut annotator, pairs_channel, &mut outcome, &tx) {
        for message in annotator.finish() {
            if tx.send(ToWriter::Own(message)).is_err() {
                break;
            }
        }
    }
    outcome.stats = Some(pairer.stats().clone());
    outcome.annotation = annotator.stats().clone();
    outcome.events = annotator.events().to_vec();
    outcome
}

fn feed(
    pairer: &mut ScanPairer,
    counts: &mut DecodedCounts,
    log_time_ns: u64,
    decoded: Decoded,
) -> Vec<PairEvent> {
    match &decoded {
        Decoded::Scan(scan) => {
            counts.scans += 1;
            counts.lidar_points += scan.points_m.len() as u64;
            counts.invalid_points_skipped += u64::from(scan.skipped_invalid_points);
        }
        Decoded::Imu(_) => counts.imu += 1,
        Decoded::Velocity(_) => counts.velocity += 1,
        Decoded::Transforms { .. } => counts.tf_messages += 1,
    }
    pairer.push_decoded(log_time_ns, decoded)
}

/// Send the pairer's events on, annotated; false when the writer has gone.
fn emit(
    events: Vec<PairEvent>,
    annotator: &mut Annotator,
    pairs_channel: u16,
    outcome: &mut PairingOutcome,
    tx: &SyncSender<ToWriter>,
) -> bool {
    for event in events {
        match event {
            PairEvent::Pair(pair) => {
                // The pair's quality figures come from its annotation; its
                // record still goes out first.
                let annotation = annotator.annotate(&pair);
                let mut record = PairRecord::from_pair(&pair);
                record.quality = annotator.take_quality();
                let data = serde_json::to_vec(&record).expect("pair records always serialise");
                let item = ToWriter::Own(OwnMessage {
                    channel_id: pairs_channel,
                    sequence: outcome.pairs_written as u32,
                    log_time_ns: pair.current_log_time_ns,
                    data,
                });
                outcome.pairs_written += 1;
                if tx.send(item).is_err() {
                    return false;
                }
                for message in annotation {
                    if tx.send(ToWriter::Own(message)).is_err() {
                        return false;
                    }
                }
            }
            PairEvent::Warning(warning) => outcome.warnings.push(warning),
        }
    }
    true
}

/// Stage 3 (calling thread): write everything, reporting progress.
fn write_all(
    writer: &mut OutputWriter,
    rx: Receiver<ToWriter>,
    replaced_channels: &std::collections::BTreeSet<u16>,
    total: Option<u64>,
    progress: &dyn ProgressSink,
) -> Result<WriterCounts, ProcessError> {
    let mut counts = WriterCounts::default();
    for item in rx {
        match item {
            ToWriter::Input(InputRecord::Message(message))
                if replaced_channels.contains(&message.channel_id) =>
            {
                counts.replaced += 1;
            }
            ToWriter::Input(InputRecord::Metadata(metadata))
                if !replaced_channels.is_empty() && metadata.name == RUN_METADATA_NAME =>
            {
                // The earlier run's record; this run writes its own.
            }
            ToWriter::Input(InputRecord::Message(message)) => {
                writer.write_input_message(&message)?;
                counts.messages += 1;
                if counts.messages % 512 == 0 {
                    progress.update(counts.messages, total);
                }
            }
            ToWriter::Input(InputRecord::Metadata(metadata)) => {
                writer.write_metadata(&metadata)?;
                counts.metadata += 1;
            }
            ToWriter::Input(InputRecord::Attachment(attachment)) => {
                writer.write_attachment(&attachment)?;
                counts.attachments += 1;
            }
            ToWriter::Copy(record, _ticket) => match writer.copy(&record)? {
                Copied::Messages(messages) => {
                    counts.messages += messages;
                    progress.update(counts.messages, total);
                }
                Copied::Metadata => counts.metadata += 1,
                Copied::Attachment => counts.attachments += 1,
            },
            ToWriter::Own(OwnMessage {
                channel_id,
                sequence,
                log_time_ns,
                data,
            }) => {
                writer.write_own_message(channel_id, sequence, log_time_ns, &data)?;
                counts.own_messages += 1;
            }
        }
    }
    progress.update(counts.messages, total);
    Ok(counts)
}

/// What a finished pass was run with.
struct Run {
    topics: TopicSelection,
    write_mode: WriteMode,
    started: Instant,
    restarted_because: Option<String>,
}

fn finish_run(
    config: &ProcessConfig,
    input: &InputFile,
    run: Run,
    outcome: PassOutcome,
) -> Result<RunSummary, ProcessError> {
    let Run {
        topics,
        write_mode,
        started,
        restarted_because,
    } = run;
    let PassOutcome {
        mut writer,
        report,
        summary_counts,
        pairing,
    } = outcome;
    let stats = pairing.stats.clone().unwrap_or_default();
    writer.write_metadata(&run_metadata(config, input, &topics, &write_mode, &stats))?;
    let output_bytes = writer.finish()?;
    let mut warnings: Vec<String> = Vec::new();
    if let ReadMode::Linear { reason } = input.mode() {
        warnings.push(format!("read linearly in file order ({reason})"));
    }
    if let Some(reason) = restarted_because {
        warnings.push(format!(
            "restarted the indexed read as a linear read: {reason}"
        ));
    }
    warnings.extend(report.warnings.iter().map(|w| w.message.clone()));
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
        messages_copied: summary_counts.messages,
        metadata_copied: summary_counts.metadata,
        attachments_copied: summary_counts.attachments,
        decoded: pairing.decoded,
        pairs_written: pairing.pairs_written,
        pairing: stats,
        annotation: pairing.annotation,
        events,
        replaced_messages: summary_counts.replaced,
        bad_messages: pairing.bad_messages,
        bad_messages_by_topic: pairing.bad_by_topic,
        bad_message_examples: pairing.bad_examples,
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
    topics: &TopicSelection,
    write_mode: &WriteMode,
    stats: &PairingStats,
) -> mcap::records::Metadata {
    let input_name = config
        .input
        .file_name()
        .map(|n| n.to_string_lossy().into_owned())
        .unwrap_or_default();
    let resolved = serde_json::json!({
        "input_file": input_name,
        "read": input.mode(),
        "write": write_mode,
        "topics": topics,
        "strict": config.strict,
        "verify_crc": config.input_options.verify_crc,
        "reorder_window_s": config.input_options.reorder_window_ns as f64 * 1e-9,
        "pairing": config.pairing,
        "extrinsic_source": stats.extrinsic_source,
        "nominal_period_s": stats.nominal_period_s,
        "output": config.output_options,
        "max_points_per_scan": config.decode_limits.max_points,
        "annotate": config.annotate,
        "replace": config.replace,
    });
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
    let mut temp = crate::output::temp_beside(path).map_err(err)?;
    serde_json::to_writer_pretty(&mut temp, &file).map_err(|e| err(e.into()))?;
    temp.persist(path).map_err(|e| err(e.error))?;
    Ok(())
}

fn file_size(path: &Path) -> u64 {
    std::fs::metadata(path).map(|m| m.len()).unwrap_or(0)
}
