//! The copying read: metadata and attachments as stored, then each chunk
//! whole with its message index records, decompressing only the chunks that
//! hold a channel the pipeline decodes (or every chunk with `--verify`).

use std::collections::{BTreeMap, BTreeSet};
use std::fs::File;
use std::path::Path;

use mcap::records::{ChunkHeader, ChunkIndex, Record, op};

use super::message_indexes::{
    chunks_in_file_order, copy_blocker, parse_message_indexes, record_at,
};
use super::unpack::{ChunkFault, Unpacker};
use crate::input::indexed::{parse_whole_record, read_span, side_records};
use crate::input::{
    CopiedRecord, CopyEvent, Flow, InputError, InputOptions, InputWarning, MessageRef, RawChunk,
    RawRecord, ReadReport,
};

/// Everything a copying read needs at hand.
struct CopyRead<'a> {
    path: &'a Path,
    file: File,
    file_size: u64,
    options: &'a InputOptions,
    strict: bool,
    /// Channels the pipeline decodes: their chunks are decompressed.
    selected: &'a BTreeSet<u16>,
    unpacker: Unpacker,
}

/// Read every record for a pass-through output: metadata and attachments as
/// stored, then each chunk whole with its message indexes, in file order,
/// followed by its messages on `selected` channels (to decode). A chunk whose
/// records fail their CRC is not copied: its messages come as
/// [`CopyEvent::Salvaged`], to be written anew (fatal with `strict`).
pub(in crate::input) fn read(
    path: &Path,
    summary: &mcap::Summary,
    options: &InputOptions,
    strict: bool,
    selected: &BTreeSet<u16>,
    sink: &mut dyn FnMut(CopyEvent<'_>) -> Flow,
) -> Result<ReadReport, InputError> {
    let file = File::open(path).map_err(|source| InputError::Open {
        path: path.to_path_buf(),
        source,
    })?;
    let file_size = file.metadata().map(|m| m.len()).unwrap_or(u64::MAX);
    let mut read = CopyRead {
        path,
        file,
        file_size,
        options,
        strict,
        selected,
        unpacker: Unpacker::default(),
    };
    let mut report = ReadReport::default();
    read.side_records(summary, &mut report, sink)?;
    for chunk in chunks_in_file_order(summary) {
        read.chunk(chunk, &mut report, sink)?;
    }
    Ok(report)
}

impl CopyRead<'_> {
    fn invalid(&self, what: String) -> InputError {
        InputError::Invalid {
            path: self.path.to_path_buf(),
            what,
        }
    }

    /// Metadata and attachment records, as stored, in file order.
    fn side_records(
        &mut self,
        summary: &mcap::Summary,
        report: &mut ReadReport,
        sink: &mut dyn FnMut(CopyEvent<'_>) -> Flow,
    ) -> Result<(), InputError> {
        for side in side_records(summary) {
            let mut bytes = Vec::new();
            read_span(
                self.path,
                &mut self.file,
                side.offset,
                side.length,
                self.file_size,
                self.options,
                &mut bytes,
            )?;
            match parse_whole_record(self.path, &bytes, side.offset)? {
                Record::Metadata(_) => report.metadata_records += 1,
                Record::Attachment { .. } => report.attachments += 1,
                _ => {
                    return Err(self.invalid(format!(
                        "index at byte {} does not point to a metadata or attachment record",
                        side.offset
                    )));
                }
            }
            let record = CopiedRecord::Side(RawRecord { bytes });
            if sink(CopyEvent::Copy(record)).is_break() {
                return Err(InputError::Stopped);
            }
        }
        Ok(())
    }

    /// One chunk: copied whole (then its selected messages, to decode), or
    /// salvaged message by message when its records fail their CRC.
    fn chunk(
        &mut self,
        index: &ChunkIndex,
        report: &mut ReadReport,
        sink: &mut dyn FnMut(CopyEvent<'_>) -> Flow,
    ) -> Result<(), InputError> {
        let raw = self.raw_chunk(index)?;
        let wanted = raw.message_counts.keys().any(|c| self.selected.contains(c));
        if !wanted && !self.options.verify_crc {
            report.messages += raw.message_counts.values().sum::<u64>();
            report.chunks_copied += 1;
            return emit(sink, CopyEvent::Copy(CopiedRecord::Chunk(raw)));
        }
        let unpacked = {
            let (header, data) = self.chunk_body(index, &raw.record)?;
            self.unpacker.unpack(&header, &data, self.options)
        };
        report.chunks_decompressed += 1;
        match unpacked {
            Ok(()) => {
                report.messages += raw.message_counts.values().sum::<u64>();
                report.chunks_copied += 1;
                emit(sink, CopyEvent::Copy(CopiedRecord::Chunk(raw)))?;
                let selected = self.selected;
                self.messages(index, &mut |message| {
                    if !selected.contains(&message.header.channel_id) {
                        return Flow::Continue(());
                    }
                    sink(CopyEvent::Selected(message))
                })
            }
            Err(ChunkFault::Unreadable(reason)) => Err(self.bad_chunk(index, &reason)),
            Err(ChunkFault::Corrupt(reason)) => {
                let bad = self.bad_chunk(index, &reason);
                if self.strict {
                    return Err(bad);
                }
                report.bad_crc_chunks += 1;
                report.warnings.push(InputWarning {
                    message: format!(
                        "{bad}; its messages are written anew (the chunk is not copied) but may be corrupt"
                    ),
                });
                self.messages(index, &mut |message| {
                    report.messages += 1;
                    sink(CopyEvent::Salvaged(message))
                })
            }
        }
    }

    fn bad_chunk(&self, index: &ChunkIndex, reason: &str) -> InputError {
        InputError::BadChunk {
            path: self.path.to_path_buf(),
            offset: index.chunk_start_offset,
            start_ns: index.message_start_time,
            end_ns: index.message_end_time,
            reason: reason.to_string(),
        }
    }

    /// The chunk record and its message index records, read whole.
    fn raw_chunk(&mut self, index: &ChunkIndex) -> Result<RawChunk, InputError> {
        let mut record = Vec::new();
        read_span(
            self.path,
            &mut self.file,
            index.chunk_start_offset,
            index.chunk_length,
            self.file_size,
            self.options,
            &mut record,
        )?;
        let mut message_indexes = Vec::new();
        let message_counts = match index.message_index_offsets.values().min() {
            None => BTreeMap::new(),
            Some(&start) => {
                read_span(
                    self.path,
                    &mut self.file,
                    start,
                    index.message_index_length,
                    self.file_size,
                    self.options,
                    &mut message_indexes,
                )?;
                let messages = parse_message_indexes(&message_indexes, start)
                    .map_err(|reason| self.invalid(reason))?;
                if copy_blocker(index, &messages, self.file_size, self.options).is_some() {
                    return Err(self.invalid(format!(
                        "the message indexes of the chunk at byte {} changed since the file was opened",
                        index.chunk_start_offset
                    )));
                }
                messages.counts()
            }
        };
        let message_indexes_offset = index
            .message_index_offsets
            .values()
            .min()
            .copied()
            .unwrap_or(index.chunk_start_offset + index.chunk_length);
        Ok(RawChunk {
            index: index.clone(),
            record,
            message_indexes,
            message_indexes_offset,
            message_counts,
        })
    }

    /// The chunk record's header and compressed records, checked against its
    /// index (the copy keeps the index's figures).
    fn chunk_body<'r>(
        &self,
        index: &ChunkIndex,
        record: &'r [u8],
    ) -> Result<(ChunkHeader, std::borrow::Cow<'r, [u8]>), InputError> {
        let at = index.chunk_start_offset;
        let Record::Chunk { header, data } = parse_whole_record(self.path, record, at)? else {
            return Err(self.invalid(format!(
                "the chunk index points to byte {at}, which holds no chunk record"
            )));
        };
        let matches = header.compression == index.compression
            && header.compressed_size == index.compressed_size
            && header.uncompressed_size == index.uncompressed_size
            && header.message_start_time == index.message_start_time
            && header.message_end_time == index.message_end_time;
        if !matches {
            return Err(self.invalid(format!(
                "the chunk at byte {at} does not match its chunk index"
            )));
        }
        Ok((header, data))
    }

    /// Each message record of the chunk just unpacked, in order.
    fn messages(
        &self,
        index: &ChunkIndex,
        visit: &mut dyn FnMut(MessageRef<'_>) -> Flow,
    ) -> Result<(), InputError> {
        let records = self.unpacker.records();
        let mut at = 0usize;
        while at < records.len() {
            let (opcode, body) = record_at(records, at).ok_or_else(|| {
                self.invalid(format!(
                    "the chunk at byte {} holds a record cut short at byte {at} of its records",
                    index.chunk_start_offset
                ))
            })?;
            at += 9 + body.len();
            if opcode != op::MESSAGE {
                continue;
            }
            let message = parse_message(body).ok_or_else(|| {
                self.invalid(format!(
                    "the chunk at byte {} holds a malformed message record",
                    index.chunk_start_offset
                ))
            })?;
            if visit(message).is_break() {
                return Err(InputError::Stopped);
            }
        }
        Ok(())
    }
}

fn parse_message(body: &[u8]) -> Option<MessageRef<'_>> {
    match mcap::parse_record(op::MESSAGE, body).ok()? {
        Record::Message {
            header,
            data: std::borrow::Cow::Borrowed(data),
        } => Some(MessageRef { header, data }),
        _ => None,
    }
}

fn emit(
    sink: &mut dyn FnMut(CopyEvent<'_>) -> Flow,
    event: CopyEvent<'_>,
) -> Result<(), InputError> {
    if sink(event).is_break() {
        return Err(InputError::Stopped);
    }
    Ok(())
}
