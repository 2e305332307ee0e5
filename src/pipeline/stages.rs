//! `process`'s three stages on threads: read and decode -> pair and annotate
//! -> write (the calling thread), with bounded channels between them so
//! every stage works at once while memory stays bounded.

use std::collections::BTreeSet;
use std::sync::Arc;
use std::sync::mpsc::{Receiver, SyncSender, sync_channel};

use crate::annotate::OwnMessage;
use crate::budget::{ByteBudget, Ticket};
use crate::input::{Catalog, CopiedRecord, CopyEvent, Flow, InputFile, InputRecord, ReadReport};
use crate::model::{Decoded, ScanPair};
use crate::output::{Copied, OutputWriter, WriteMode};
use crate::topics::TopicSelection;

use super::replace::without_our_channels;
use super::scans::{BadMessage, DecodeResult, Decoder, ReadFailure, SensorPairing, finish_read};
use super::sensors::{Annotation, PairingOutcome, add_own_channels, outcome};
use super::summary::RUN_METADATA_NAME;
use super::{ProcessConfig, ProcessError, ProgressSink};

/// Items between the reader and pairing stages. Channels hold few items: point
/// clouds are megabytes each.
const STAGE_QUEUE_LEN: usize = 32;
/// Bytes of copied input records (chunks, attachments) read ahead of the
/// writer at most (one record bigger than this still passes, alone): a
/// dozen 4 MiB chunks, more than a second of a 64-beam sensor's log.
const COPY_BUDGET_BYTES: u64 = 48 << 20;

/// The result of one pass before the output is finalised.
pub(super) struct PassOutcome {
    pub(super) writer: OutputWriter,
    pub(super) report: ReadReport,
    pub(super) summary_counts: WriterCounts,
    pub(super) pairing: PairingOutcome,
}

#[derive(Debug, Default, Clone, Copy)]
pub(super) struct WriterCounts {
    pub(super) messages: u64,
    pub(super) metadata: u64,
    pub(super) attachments: u64,
    pub(super) own_messages: u64,
    /// Records of an earlier run dropped by `--replace`.
    pub(super) replaced: u64,
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
        channel_id: u16,
        decoded: Decoded,
    },
    Bad(BadMessage),
}

/// Items for the writer.
pub(super) enum ToWriter {
    Input(InputRecord),
    Copy(CopiedRecord, Ticket),
    Own(OwnMessage),
}

pub(super) fn run_once(
    config: &ProcessConfig,
    input: &InputFile,
    sensors: &[TopicSelection],
    write_mode: &WriteMode,
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
    // A log copied through for want of a LiDAR gets no channel of ours.
    let annotation = if sensors.iter().any(|t| t.lidar.is_some()) {
        Some(add_own_channels(&mut writer, config, sensors)?)
    } else {
        None
    };
    let pairing_stage = SensorPairing::new(&config.scans, input.catalog(), sensors);
    let (reader_tx, reader_rx) = sync_channel::<FromReader>(STAGE_QUEUE_LEN);
    let (writer_tx, writer_rx) = sync_channel::<ToWriter>(STAGE_QUEUE_LEN);
    std::thread::scope(|scope| {
        let reader = scope.spawn(|| read_and_decode(config, input, sensors, write_mode, reader_tx));
        let pairing =
            scope.spawn(move || pair_scans(pairing_stage, annotation, reader_rx, writer_tx));
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
    sensors: &[TopicSelection],
    write_mode: &WriteMode,
    tx: SyncSender<FromReader>,
) -> Result<ReadReport, ProcessError> {
    let file_name = input.path().display().to_string();
    let mut stage = ReadStage {
        decoder: Decoder::new(&config.scans, sensors, &file_name),
        tx,
        copy_budget: ByteBudget::new(COPY_BUDGET_BYTES),
        strict: config.scans.strict,
        strict_failure: None,
        interrupted: false,
    };
    let result = match write_mode {
        WriteMode::PassThrough => {
            let selected: BTreeSet<u16> = sensors
                .iter()
                .flat_map(TopicSelection::all)
                .map(|c| c.channel_id)
                .collect();
            input.read_copying(config.scans.strict, &selected, &mut |event| {
                stage.copy_event(event)
            })
        }
        WriteMode::Rewrite { .. } => {
            input.read_records(config.scans.strict, &mut |record| stage.record(record))
        }
    };
    if stage.interrupted {
        return Err(ProcessError::Interrupted {
            path: config.output.clone(),
        });
    }
    finish_read(
        config.scans.strict,
        &file_name,
        stage.strict_failure,
        result,
    )
    .map_err(|failure| match failure {
        ReadFailure::Input(error) => error.into(),
        ReadFailure::Strict(reason) => ProcessError::Strict(reason),
    })
}

/// Bytes a copied record holds while it waits to be written.
fn copied_bytes(record: &CopiedRecord) -> u64 {
    let bytes = match record {
        CopiedRecord::Chunk(chunk) => chunk.record.len() + chunk.message_indexes.len(),
        CopiedRecord::Side(side) => side.bytes.len(),
    };
    bytes as u64
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
    /// A stop was asked for (Ctrl-C): reading ended early.
    interrupted: bool,
}

impl ReadStage<'_> {
    fn send(&mut self, item: FromReader) -> Flow {
        if super::stop_requested() {
            self.interrupted = true;
            return Flow::Break(());
        }
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
            Some(Ok((log_time_ns, channel_id, decoded))) => FromReader::Decoded {
                log_time_ns,
                channel_id,
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

/// Stage 2: feed the pairers, pass every record on, add each sensor's
/// `/looming/pairs` and the annotation of every pair (without `annotation`,
/// only pass records on).
///
/// The pairs a message completes are annotated while the next decoded
/// message is paired: a scan's pairing (its layout recovered: some 9 ms
/// of a KITTI scan, most of it on one core) runs beside the engine's pair
/// instead of between two of them, where the other core waited (a tenth
/// of the braking KITTI drive's wall).
fn pair_scans(
    mut stage: SensorPairing,
    mut annotation: Option<Annotation>,
    rx: Receiver<FromReader>,
    tx: SyncSender<ToWriter>,
) -> PairingOutcome {
    // The pairs made, to annotate beside the next message's pairing.
    let mut waiting = Vec::new();
    let mut stopped = false;
    for item in rx {
        let (log_time_ns, channel_id, decoded) = match item {
            FromReader::Record(record) => {
                stopped = tx.send(ToWriter::Input(record)).is_err();
                if stopped {
                    break;
                }
                continue;
            }
            FromReader::Copy(record, ticket) => {
                stopped = tx.send(ToWriter::Copy(record, ticket)).is_err();
                if stopped {
                    break;
                }
                continue;
            }
            FromReader::Bad(bad) => {
                stage.bad.add(bad);
                continue;
            }
            FromReader::Decoded {
                log_time_ns,
                channel_id,
                decoded,
            } => (log_time_ns, channel_id, decoded),
        };
        let ready = std::mem::take(&mut waiting);
        let emitted;
        // Most messages (IMU, velocity) find no pair waiting: no join.
        (emitted, waiting) = if ready.is_empty() {
            (true, stage.push(log_time_ns, channel_id, decoded))
        } else {
            rayon::join(
                || emit(&mut annotation, ready, &tx),
                || stage.push(log_time_ns, channel_id, decoded),
            )
        };
        stopped = !emitted;
        if stopped {
            break;
        }
    }
    let mut events = Vec::new();
    if !stopped {
        waiting.extend(stage.finish());
        if let Some(annotation) = &mut annotation
            && annotation.emit(waiting, &tx)
        {
            let tree = stage.stages().first().map(|s| s.transforms().clone());
            events = annotation.finish(&tx, tree.as_ref());
        }
    }
    outcome(&stage, annotation.as_ref(), events)
}

/// `pairs` annotated and sent ([`Annotation::emit`]); `false` once the
/// writer is gone. Without an annotation, nothing to do.
fn emit(
    annotation: &mut Option<Annotation>,
    pairs: Vec<(usize, ScanPair)>,
    tx: &SyncSender<ToWriter>,
) -> bool {
    annotation
        .as_mut()
        .is_none_or(|annotation| annotation.emit(pairs, tx))
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
