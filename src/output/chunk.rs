//! Chunks of our own messages for the pass-through writer: gathered
//! uncompressed, then compressed on rayon's workers while the pipeline goes on.
//!
//! Determinism: a chunk closes before the message that would take it past
//! the target size, so which messages share a chunk depends only on the
//! messages; each chunk is compressed single-threaded at a fixed level, so its
//! bytes depend only on its records; and the chunks are written in the order
//! they closed, each when [`PENDING_CHUNKS`] younger ones are waiting (or at
//! the end), a point fixed by the records written before it. How fast the
//! workers are, or how many there are, changes when the bytes are ready, never
//! which bytes go where.

use std::cell::RefCell;
use std::collections::{BTreeMap, VecDeque};
use std::io::{self, Write};
use std::sync::mpsc::{Receiver, sync_channel};

use mcap::records::{ChunkHeader, MessageHeader, MessageIndexEntry, op};

use super::OutputCompression;
use super::raw::RECORD_PREFIX_BYTES;

/// Chunks left compressing while the next one fills: one, so compression
/// runs beside the writer, and when a chunk closes before the one before it
/// is done, both compress at once. Each pending chunk holds its records and
/// its output in memory (two pending: 27 MB more peak RSS on a 64 x 2048
/// drive, with both cores already busy).
pub(super) const PENDING_CHUNKS: usize = 1;

/// Spare chunk buffers kept for reuse: one being filled, and the records and
/// output of each chunk in flight. Reusing them keeps the allocator from
/// spreading chunk-sized blocks over every thread's arena.
const SPARE_BUFFERS: usize = 2 * (PENDING_CHUNKS + 1);

/// A message header's bytes in a record: channel id, sequence, log and
/// publish time.
const MESSAGE_HEADER_BYTES: u64 = 2 + 4 + 8 + 8;

/// How our chunks are compressed.
#[derive(Debug, Clone, Copy)]
pub(super) struct ChunkCompression {
    pub kind: OutputCompression,
    /// zstd / lz4 level; 0 = the library's default.
    pub level: u32,
}

/// Message records of one chunk, not yet compressed.
pub(super) struct ChunkBuilder {
    /// Bytes at which the chunk is full.
    target_bytes: u64,
    records: Vec<u8>,
    indexes: BTreeMap<u16, Vec<MessageIndexEntry>>,
    bounds_ns: Option<(u64, u64)>,
}

/// A closed chunk, ready to compress.
pub(super) struct ClosedChunk {
    records: Vec<u8>,
    indexes: BTreeMap<u16, Vec<MessageIndexEntry>>,
    bounds_ns: (u64, u64),
}

/// A chunk ready to write: its header, compressed records and message indexes.
pub(super) struct CompressedChunk {
    pub header: ChunkHeader,
    pub data: Vec<u8>,
    pub indexes: BTreeMap<u16, Vec<MessageIndexEntry>>,
    /// The uncompressed records' buffer, for reuse (none when the records
    /// are the data: no compression).
    pub spare: Option<Vec<u8>>,
}

impl CompressedChunk {
    /// Messages per channel.
    pub(super) fn message_counts(&self) -> BTreeMap<u16, u64> {
        self.indexes
            .iter()
            .map(|(&channel_id, entries)| (channel_id, entries.len() as u64))
            .collect()
    }
}

impl ChunkBuilder {
    pub(super) fn new(target_bytes: u64) -> Self {
        Self {
            target_bytes,
            records: Vec::new(),
            indexes: BTreeMap::new(),
            bounds_ns: None,
        }
    }

    /// Whether a message of `data_bytes` would take the chunk past its
    /// target size (a chunk holds at least one message, however large):
    /// chunks stay within the target, and so does the memory each holds
    /// while it waits to be compressed.
    pub(super) fn would_overflow(&self, data_bytes: usize) -> bool {
        let record_bytes = RECORD_PREFIX_BYTES + MESSAGE_HEADER_BYTES + data_bytes as u64;
        !self.records.is_empty() && self.records.len() as u64 + record_bytes > self.target_bytes
    }

    /// Fill `buffer` (emptied) next, when the builder holds none yet.
    pub(super) fn reuse(&mut self, mut buffer: Vec<u8>) {
        if self.records.capacity() == 0 {
            buffer.clear();
            self.records = buffer;
        }
    }

    /// Append one message record (the layout of `mcap::records::MessageHeader`,
    /// then the payload).
    pub(super) fn push(&mut self, header: &MessageHeader, data: &[u8]) {
        let offset = self.records.len() as u64;
        self.indexes
            .entry(header.channel_id)
            .or_default()
            .push(MessageIndexEntry {
                log_time: header.log_time,
                offset,
            });
        self.bounds_ns = Some(match self.bounds_ns {
            None => (header.log_time, header.log_time),
            Some((first, last)) => (first.min(header.log_time), last.max(header.log_time)),
        });
        let body_bytes = MESSAGE_HEADER_BYTES + data.len() as u64;
        if self.records.capacity() == 0 {
            // One allocation for the chunk rather than a doubling series.
            self.records
                .reserve(self.target_bytes.min(64 << 20) as usize);
        }
        self.records
            .reserve(RECORD_PREFIX_BYTES as usize + body_bytes as usize);
        self.records.push(op::MESSAGE);
        self.records.extend_from_slice(&body_bytes.to_le_bytes());
        self.records
            .extend_from_slice(&header.channel_id.to_le_bytes());
        self.records
            .extend_from_slice(&header.sequence.to_le_bytes());
        self.records
            .extend_from_slice(&header.log_time.to_le_bytes());
        self.records
            .extend_from_slice(&header.publish_time.to_le_bytes());
        self.records.extend_from_slice(data);
    }

    /// The chunk so far, leaving the builder empty; `None` when it holds nothing.
    pub(super) fn close(&mut self) -> Option<ClosedChunk> {
        let bounds_ns = self.bounds_ns.take()?;
        Some(ClosedChunk {
            records: std::mem::take(&mut self.records),
            indexes: std::mem::take(&mut self.indexes),
            bounds_ns,
        })
    }
}

/// Compress one chunk into `output` (emptied) single-threaded: the same
/// bytes on any machine.
pub(super) fn compress(
    chunk: ClosedChunk,
    settings: ChunkCompression,
    mut output: Vec<u8>,
) -> io::Result<CompressedChunk> {
    let uncompressed_size = chunk.records.len() as u64;
    let uncompressed_crc = crc32fast::hash(&chunk.records);
    output.clear();
    let (name, data, spare) = match settings.kind {
        OutputCompression::Zstd => {
            zstd_into(&chunk.records, settings.level, &mut output)?;
            ("zstd", output, Some(chunk.records))
        }
        OutputCompression::Lz4 => {
            let frame = lz4_frame(&chunk.records, settings.level, output)?;
            ("lz4", frame, Some(chunk.records))
        }
        OutputCompression::None => ("", chunk.records, Some(output)),
    };
    let header = ChunkHeader {
        message_start_time: chunk.bounds_ns.0,
        message_end_time: chunk.bounds_ns.1,
        uncompressed_size,
        uncompressed_crc,
        compression: name.into(),
        compressed_size: data.len() as u64,
    };
    Ok(CompressedChunk {
        header,
        data,
        indexes: chunk.indexes,
        spare,
    })
}

thread_local! {
    /// Each worker's zstd context and its level, kept between chunks (a
    /// context is megabytes; the frames do not depend on its reuse).
    static ZSTD: RefCell<Option<(u32, zstd::bulk::Compressor<'static>)>> =
        const { RefCell::new(None) };
}

/// One zstd frame of `records` at `level` (0: zstd's default) into `output`.
fn zstd_into(records: &[u8], level: u32, output: &mut Vec<u8>) -> io::Result<()> {
    output.reserve(zstd::zstd_safe::compress_bound(records.len()));
    ZSTD.with(|cell| {
        let mut slot = cell.borrow_mut();
        let compressor = match &mut *slot {
            Some((kept_level, compressor)) if *kept_level == level => compressor,
            _ => {
                &mut slot
                    .insert((level, zstd::bulk::Compressor::new(level as i32)?))
                    .1
            }
        };
        compressor.compress_to_buffer(records, output).map(|_| ())
    })
}

/// One lz4 frame in `output`, as the `mcap` crate writes them (no block
/// checksums: the chunk CRC covers the records).
fn lz4_frame(records: &[u8], level: u32, output: Vec<u8>) -> io::Result<Vec<u8>> {
    let mut encoder = lz4::EncoderBuilder::new()
        .level(level)
        .block_checksum(lz4::liblz4::BlockChecksum::NoBlockChecksum)
        .build(output)?;
    encoder.write_all(records)?;
    let (frame, finished) = encoder.finish();
    finished.map(|()| frame)
}

/// Chunks being compressed on rayon's workers, oldest first, and spare
/// chunk buffers.
pub(super) struct Compressor {
    settings: ChunkCompression,
    pending: VecDeque<Receiver<io::Result<CompressedChunk>>>,
    spare: Vec<Vec<u8>>,
}

impl Compressor {
    pub(super) fn new(settings: ChunkCompression) -> Self {
        Self {
            settings,
            pending: VecDeque::new(),
            spare: Vec::new(),
        }
    }

    /// A spare buffer (empty), or a new one.
    pub(super) fn take_buffer(&mut self) -> Vec<u8> {
        self.spare.pop().unwrap_or_default()
    }

    /// Keep `buffer` for a later chunk.
    pub(super) fn recycle(&mut self, mut buffer: Vec<u8>) {
        if self.spare.len() < SPARE_BUFFERS && buffer.capacity() > 0 {
            buffer.clear();
            self.spare.push(buffer);
        }
    }

    /// Start compressing `chunk`; returns the chunks due to be written now
    /// (the oldest, once more than [`PENDING_CHUNKS`] wait), in order.
    pub(super) fn submit(&mut self, chunk: ClosedChunk) -> io::Result<Vec<CompressedChunk>> {
        let (tx, rx) = sync_channel(1);
        let settings = self.settings;
        let output = self.take_buffer();
        rayon::spawn(move || {
            // The writer may have gone (its run failed): nothing to tell it.
            let _ = tx.send(compress(chunk, settings, output));
        });
        self.pending.push_back(rx);
        let mut due = Vec::new();
        while self.pending.len() > PENDING_CHUNKS {
            due.push(self.wait_oldest()?);
        }
        Ok(due)
    }

    /// Every chunk still being compressed, in order.
    pub(super) fn drain(&mut self) -> io::Result<Vec<CompressedChunk>> {
        let mut due = Vec::with_capacity(self.pending.len());
        while !self.pending.is_empty() {
            due.push(self.wait_oldest()?);
        }
        Ok(due)
    }

    fn wait_oldest(&mut self) -> io::Result<CompressedChunk> {
        let Some(oldest) = self.pending.pop_front() else {
            return Err(io::Error::other("no chunk is being compressed"));
        };
        oldest
            .recv()
            .map_err(|_| io::Error::other("a chunk compression worker stopped without a result"))?
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn chunk_of(messages: &[(u16, u64, &[u8])]) -> ClosedChunk {
        let mut builder = ChunkBuilder::new(4 << 20);
        for (i, &(channel_id, log_time, data)) in messages.iter().enumerate() {
            let header = MessageHeader {
                channel_id,
                sequence: i as u32,
                log_time,
                publish_time: log_time,
            };
            builder.push(&header, data);
        }
        builder.close().expect("messages were pushed")
    }

    /// The records of `chunk`, read back with the crate's chunk reader.
    fn read_back(chunk: &CompressedChunk) -> Vec<(u16, u64, Vec<u8>)> {
        mcap::read::ChunkReader::new(chunk.header.clone(), &chunk.data)
            .unwrap()
            .map(|record| match record.unwrap() {
                mcap::records::Record::Message { header, data } => {
                    (header.channel_id, header.log_time, data.into_owned())
                }
                other => panic!("only messages in our chunks, not {other:?}"),
            })
            .collect()
    }

    #[test]
    fn every_compression_reads_back_with_its_crc_and_indexes() {
        let messages: [(u16, u64, &[u8]); 3] = [(7, 30, b"late"), (3, 10, b"first"), (7, 20, b"")];
        for kind in [
            OutputCompression::Zstd,
            OutputCompression::Lz4,
            OutputCompression::None,
        ] {
            let settings = ChunkCompression { kind, level: 0 };
            let chunk = compress(chunk_of(&messages), settings, Vec::new()).unwrap();
            assert_eq!(
                (
                    chunk.header.message_start_time,
                    chunk.header.message_end_time
                ),
                (10, 30)
            );
            let expected: Vec<(u16, u64, Vec<u8>)> = messages
                .iter()
                .map(|&(c, t, d)| (c, t, d.to_vec()))
                .collect();
            assert_eq!(read_back(&chunk), expected, "{kind:?}");
            assert_eq!(chunk.message_counts(), BTreeMap::from([(3, 1), (7, 2)]));
            assert_eq!(chunk.indexes[&3][0].offset, 9 + 22 + 4, "{kind:?}");
        }
    }

    #[test]
    fn chunks_come_back_in_submission_order() {
        let settings = ChunkCompression {
            kind: OutputCompression::Zstd,
            level: 0,
        };
        let mut compressor = Compressor::new(settings);
        let mut written = Vec::new();
        for t in 0..5u64 {
            let payload = vec![t as u8; 1000 * (5 - t as usize)];
            let due = compressor.submit(chunk_of(&[(1, t, &payload)])).unwrap();
            written.extend(due.iter().map(|c| c.header.message_start_time));
            assert!(compressor.pending.len() <= PENDING_CHUNKS);
        }
        written.extend(
            compressor
                .drain()
                .unwrap()
                .iter()
                .map(|c| c.header.message_start_time),
        );
        assert_eq!(written, vec![0, 1, 2, 3, 4]);
    }

    #[test]
    fn an_empty_builder_closes_to_nothing() {
        assert!(ChunkBuilder::new(1).close().is_none());
    }
}
