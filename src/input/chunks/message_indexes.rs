//! The chunks' message index records: read once when an indexed file is
//! opened, for the channels' time spans and to say whether the chunks can be
//! copied byte for byte (their indexes match, their messages are in log-time
//! order, the counts add up).

use std::collections::BTreeMap;
use std::fs::File;
use std::path::Path;

use mcap::records::{ChunkIndex, MessageIndex, Record, op};

use crate::input::InputOptions;
use crate::input::indexed::read_span;

/// What the message indexes say about the file.
pub(in crate::input) struct IndexScan {
    /// First and last log time of each channel (empty when an index could
    /// not be read).
    pub spans: BTreeMap<u16, (u64, u64)>,
    /// `Err(reason)` when the chunks cannot be copied as they are.
    pub copyable: Result<(), String>,
}

/// One chunk's message index records: where each starts in the file.
pub(super) struct ChunkMessages {
    indexes: Vec<(u64, MessageIndex)>,
}

impl ChunkMessages {
    pub(super) fn counts(&self) -> BTreeMap<u16, u64> {
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
pub(super) fn chunks_in_file_order(summary: &mcap::Summary) -> Vec<&ChunkIndex> {
    let mut chunks: Vec<&ChunkIndex> = summary.chunk_indexes.iter().collect();
    chunks.sort_by_key(|c| c.chunk_start_offset);
    chunks
}

/// Read every chunk's message indexes once: the channels' time spans, and
/// whether the chunks can be copied byte for byte.
pub(in crate::input) fn scan_message_indexes(
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
pub(super) fn parse_message_indexes(bytes: &[u8], start: u64) -> Result<ChunkMessages, String> {
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
pub(super) fn record_at(bytes: &[u8], at: usize) -> Option<(u8, &[u8])> {
    let opcode = *bytes.get(at)?;
    let length = u64::from_le_bytes(bytes.get(at + 1..at + 9)?.try_into().ok()?);
    let start = at + 9;
    let end = start.checked_add(usize::try_from(length).ok()?)?;
    Some((opcode, bytes.get(start..end)?))
}

/// Why `chunk` cannot be copied byte for byte, if it cannot.
pub(super) fn copy_blocker(
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
