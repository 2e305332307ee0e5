//! The input's chunks as they are stored, for the pass-through output.
//!
//! [`scan_message_indexes`] runs once when an indexed file is opened: it reads
//! every chunk's message index records (small: 16 bytes a message) and says
//! whether the chunks can be copied byte for byte. [`read`] then hands each
//! chunk record over whole, with its message index records, decompressing
//! only the chunks that hold a channel the pipeline decodes (or every chunk
//! with `--verify`).

use std::collections::{BTreeMap, BTreeSet};
use std::fs::File;
use std::path::Path;

use mcap::records::{ChunkHeader, ChunkIndex, MessageIndex, Record, op};

use super::indexed::{decompress_into, parse_whole_record, read_span, side_records};
use super::{
    CopiedRecord, CopyEvent, Flow, InputError, InputOptions, InputWarning, MessageRef, RawChunk,
    RawRecord, ReadReport,
};

/// What the message indexes say about the file.
pub(super) struct IndexScan {
    /// First and last log time of each channel (empty when an index could
    /// not be read).
    pub spans: BTreeMap<u16, (u64, u64)>,
    /// `Err(reason)` when the chunks cannot be copied as they are.
    pub copyable: Result<(), String>,
}

/// One chunk's message index records: where each starts in the file.
struct ChunkMessages {
    indexes: Vec<(u64, MessageIndex)>,
}

impl ChunkMessages {
    fn counts(&self) -> BTreeMap<u16, u64> {
        self.indexes
            .iter()
            .map(|(_, index)| (index.channel_id, index.records.len() as u64))
            .collect()
    }

    fn total(&self) -> u64 {
        self.indexes
            .iter()
            .map(|(_, index)| index.records.len() as u64)
            .sum()
    }
}

/// The summary's chunk indexes in file order.
fn chunks_in_file_order(summary: &mcap::Summary) -> Vec<&ChunkIndex> {
    let mut chunks: Vec<&ChunkIndex> = summary.chunk_indexes.iter().collect();
    chunks.sort_by_key(|c| c.chunk_start_offset);
    chunks
}

/// Read every chunk's message indexes once: the channels' time spans, and
/// whether the chunks can be copied byte for byte.
pub(super) fn scan_message_indexes(
    path: &Path,
    summary: &mcap::Summary,
    options: &InputOptions,
) -> IndexScan {
    let mut spans: BTreeMap<u16, (u64, u64)> = BTreeMap::new();
    let unreadable = |reason: String| IndexScan {
        spans: BTreeMap::new(),
        copyable: Err(reason),
    };
    let Ok(mut file) = File::open(path) else {
        return unreadable("the file could not be opened again".into());
    };
    let file_size = file.metadata().map(|m| m.len()).unwrap_or(0);
    let mut order = FileOrder::default();
    let mut blocker: Option<String> = None;
    let mut indexed_messages: u64 = 0;
    let mut buffer = Vec::new();
    for chunk in chunks_in_file_order(summary) {
        let messages =
            match read_message_indexes(path, &mut file, file_size, chunk, options, &mut buffer) {
                Ok(messages) => messages,
                Err(reason) => return unreadable(reason),
            };
        for (_, index) in &messages.indexes {
            for entry in &index.records {
                let span = spans
                    .entry(index.channel_id)
                    .or_insert((entry.log_time, entry.log_time));
                span.0 = span.0.min(entry.log_time);
                span.1 = span.1.max(entry.log_time);
            }
        }
        indexed_messages += messages.total();
        if blocker.is_none() {
            blocker = copy_blocker(chunk, &messages, file_size, options)
                .or_else(|| order.check(chunk, &messages));
        }
    }
    let expected = summary.stats.as_ref().map_or(0, |s| s.message_count);
    if blocker.is_none() && indexed_messages != expected {
        blocker = Some(format!(
            "the message indexes list {indexed_messages} messages but the statistics count {expected}"
        ));
    }
    IndexScan {
        spans,
        copyable: blocker.map_or(Ok(()), Err),
    }
}

/// Read and parse the message index records of `chunk`. `Err` when they are
/// not where its index says, or are not message index records.
fn read_message_indexes(
    path: &Path,
    file: &mut File,
    file_size: u64,
    chunk: &ChunkIndex,
    options: &InputOptions,
    buffer: &mut Vec<u8>,
) -> Result<ChunkMessages, String> {
    let Some(&start) = chunk.message_index_offsets.values().min() else {
        return Ok(ChunkMessages {
            indexes: Vec::new(),
        });
    };
    read_span(
        path,
        file,
        start,
        chunk.message_index_length,
        file_size,
        options,
        buffer,
    )
    .map_err(|e| e.to_string())?;
    parse_message_indexes(buffer, start).map_err(|reason| {
        format!(
            "the message indexes of the chunk at byte {}: {reason}",
            chunk.chunk_start_offset
        )
    })
}

/// Parse a run of message index records read from byte `start`.
fn parse_message_indexes(bytes: &[u8], start: u64) -> Result<ChunkMessages, String> {
    let mut indexes = Vec::new();
    let mut at = 0usize;
    while at < bytes.len() {
        let offset = start + at as u64;
        let (opcode, body) = record_at(bytes, at)
            .ok_or_else(|| format!("record at byte {offset} runs past the index span"))?;
        if opcode != op::MESSAGE_INDEX {
            return Err(format!(
                "record at byte {offset} is not a message index (opcode {opcode:#04x})"
            ));
        }
        match mcap::parse_record(opcode, body) {
            Ok(Record::MessageIndex(index)) => indexes.push((offset, index)),
            Ok(_) => return Err(format!("record at byte {offset} is not a message index")),
            Err(e) => return Err(format!("message index at byte {offset} is malformed: {e}")),
        }
        at += 9 + body.len();
    }
    Ok(ChunkMessages { indexes })
}

/// The record starting at `at` in `bytes`: opcode and body, if whole.
fn record_at(bytes: &[u8], at: usize) -> Option<(u8, &[u8])> {
    let opcode = *bytes.get(at)?;
    let length = u64::from_le_bytes(bytes.get(at + 1..at + 9)?.try_into().ok()?);
    let start = at + 9;
    let end = start.checked_add(usize::try_from(length).ok()?)?;
    Some((opcode, bytes.get(start..end)?))
}

/// Why `chunk` cannot be copied byte for byte, if it cannot.
fn copy_blocker(
    chunk: &ChunkIndex,
    messages: &ChunkMessages,
    file_size: u64,
    options: &InputOptions,
) -> Option<String> {
    let at = chunk.chunk_start_offset;
    let end = at.checked_add(chunk.chunk_length);
    if end.is_none_or(|end| end > file_size)
        || chunk.chunk_length > options.record_length_limit as u64
    {
        return Some(format!(
            "the chunk at byte {at} claims {} bytes, beyond the file or the record limit",
            chunk.chunk_length
        ));
    }
    let found: BTreeMap<u16, u64> = messages
        .indexes
        .iter()
        .map(|(offset, index)| (index.channel_id, *offset))
        .collect();
    if found.len() != messages.indexes.len() || found != chunk.message_index_offsets {
        return Some(format!(
            "the message index records after the chunk at byte {at} do not match its chunk index"
        ));
    }
    let outside = messages
        .indexes
        .iter()
        .flat_map(|(_, index)| &index.records)
        .any(|entry| entry.offset >= chunk.uncompressed_size);
    outside.then(|| format!("a message index points outside the chunk at byte {at}"))
}

/// Checks that the messages, in file order, are in log-time order: a copy
/// keeps the file order, and the output promises input messages in log-time
/// order (the rewrite path sorts them).
#[derive(Default)]
struct FileOrder {
    last_log_time_ns: Option<u64>,
}

impl FileOrder {
    fn check(&mut self, chunk: &ChunkIndex, messages: &ChunkMessages) -> Option<String> {
        let mut entries: Vec<(u64, u64)> = messages
            .indexes
            .iter()
            .flat_map(|(_, index)| &index.records)
            .map(|entry| (entry.offset, entry.log_time))
            .collect();
        entries.sort_unstable();
        for (_, log_time_ns) in entries {
            if self.last_log_time_ns.is_some_and(|last| log_time_ns < last) {
                return Some(format!(
                    "the messages are not in log-time order in the file (chunk at byte {}), so a copy of the chunks would not be either",
                    chunk.chunk_start_offset
                ));
            }
            self.last_log_time_ns = Some(log_time_ns);
        }
        None
    }
}

/// Why a chunk's records cannot be trusted.
pub(super) enum ChunkFault {
    /// Cannot be decompressed at all.
    Unreadable(String),
    /// Decompressed, but the size or the CRC does not match the header.
    Corrupt(String),
}

impl ChunkFault {
    pub(super) fn reason(&self) -> &str {
        match self {
            ChunkFault::Unreadable(reason) | ChunkFault::Corrupt(reason) => reason,
        }
    }
}

/// Decompresses chunks one after another into one reused buffer (and, for
/// zstd, one reused context): a chunk's worth of memory, allocated once.
#[derive(Default)]
pub(super) struct Unpacker {
    zstd: Option<zstd::bulk::Decompressor<'static>>,
    records: Vec<u8>,
}

impl Unpacker {
    /// The records of the chunk last unpacked (even a corrupt one).
    pub(super) fn records(&self) -> &[u8] {
        &self.records
    }

    /// Decompress a chunk's records and check their size and CRC against its
    /// header.
    pub(super) fn unpack(
        &mut self,
        header: &ChunkHeader,
        data: &[u8],
        options: &InputOptions,
    ) -> Result<(), ChunkFault> {
        if header.uncompressed_size > options.record_length_limit as u64 {
            return Err(ChunkFault::Unreadable(format!(
                "uncompressed size {} is above the record limit",
                header.uncompressed_size
            )));
        }
        let expected_size = header.uncompressed_size as usize;
        self.records.clear();
        let decompressed = if header.compression == "zstd" {
            self.unpack_zstd(data, expected_size)
        } else {
            decompress_into(&header.compression, data, expected_size, &mut self.records)
        };
        decompressed.map_err(|e| ChunkFault::Unreadable(format!("cannot decompress: {e}")))?;
        if self.records.len() != expected_size {
            return Err(ChunkFault::Corrupt(format!(
                "decompressed to {} bytes, header says {expected_size}",
                self.records.len()
            )));
        }
        // A CRC of zero means the writer did not compute one.
        if header.uncompressed_crc != 0 {
            let crc = crc32fast::hash(&self.records);
            if crc != header.uncompressed_crc {
                return Err(ChunkFault::Corrupt(format!(
                    "expected CRC {:08x}, computed {crc:08x}",
                    header.uncompressed_crc
                )));
            }
        }
        Ok(())
    }

    /// One zstd frame straight into the buffer: a frame larger than the
    /// header's size fails instead of growing it.
    fn unpack_zstd(&mut self, data: &[u8], expected_size: usize) -> Result<(), String> {
        let zstd = match &mut self.zstd {
            Some(zstd) => zstd,
            None => self
                .zstd
                .insert(zstd::bulk::Decompressor::new().map_err(|e| e.to_string())?),
        };
        self.records.reserve(expected_size);
        zstd.decompress_to_buffer(data, &mut self.records)
            .map(|_| ())
            .map_err(|e| e.to_string())
    }
}

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
pub(super) fn read(
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

#[cfg(test)]
mod tests {
    use super::*;

    fn index_record(channel_id: u16, entries: &[(u64, u64)]) -> Vec<u8> {
        use binrw::BinWrite;
        let index = MessageIndex {
            channel_id,
            records: entries
                .iter()
                .map(|&(log_time, offset)| mcap::records::MessageIndexEntry { log_time, offset })
                .collect(),
        };
        let mut body = Vec::new();
        index
            .write_le(&mut std::io::Cursor::new(&mut body))
            .unwrap();
        let mut record = vec![op::MESSAGE_INDEX];
        record.extend_from_slice(&(body.len() as u64).to_le_bytes());
        record.extend_from_slice(&body);
        record
    }

    #[test]
    fn message_index_runs_parse_with_their_offsets() {
        let first = index_record(1, &[(10, 0), (30, 100)]);
        let second = index_record(4, &[(20, 50)]);
        let bytes = [first.clone(), second].concat();
        let messages = parse_message_indexes(&bytes, 1000).unwrap();
        let offsets: Vec<(u64, u16)> = messages
            .indexes
            .iter()
            .map(|(offset, index)| (*offset, index.channel_id))
            .collect();
        assert_eq!(offsets, vec![(1000, 1), (1000 + first.len() as u64, 4)]);
        assert_eq!(messages.total(), 3);
        assert_eq!(messages.counts(), BTreeMap::from([(1, 2), (4, 1)]));
    }

    #[test]
    fn other_records_or_a_cut_run_are_refused() {
        let mut bytes = index_record(1, &[(10, 0)]);
        bytes[0] = op::METADATA;
        assert!(parse_message_indexes(&bytes, 0).is_err());
        let cut = index_record(1, &[(10, 0)]);
        assert!(parse_message_indexes(&cut[..cut.len() - 1], 0).is_err());
    }

    #[test]
    fn file_order_is_checked_by_offset_across_channels_and_chunks() {
        let chunk = ChunkIndex {
            message_start_time: 0,
            message_end_time: 0,
            chunk_start_offset: 8,
            chunk_length: 0,
            message_index_offsets: BTreeMap::new(),
            message_index_length: 0,
            compression: String::new(),
            compressed_size: 0,
            uncompressed_size: 0,
        };
        let parse = |bytes: Vec<u8>| parse_message_indexes(&bytes, 0).unwrap();
        // Channel 4's message sits between channel 1's two, in time and offset.
        let in_order = parse(
            [
                index_record(1, &[(10, 0), (30, 200)]),
                index_record(4, &[(20, 100)]),
            ]
            .concat(),
        );
        let mut order = FileOrder::default();
        assert_eq!(order.check(&chunk, &in_order), None);
        // A later chunk may start at the same time, not before.
        assert_eq!(
            order.check(&chunk, &parse(index_record(1, &[(30, 0)]))),
            None
        );
        assert!(
            order
                .check(&chunk, &parse(index_record(1, &[(29, 0)])))
                .is_some()
        );
        let swapped = parse(
            [
                index_record(1, &[(10, 0), (30, 200)]),
                index_record(4, &[(40, 100)]),
            ]
            .concat(),
        );
        assert!(FileOrder::default().check(&chunk, &swapped).is_some());
    }
}
