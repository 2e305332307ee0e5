//! The pass-through writer: the input's chunk records and their message
//! index records copied byte for byte, our own messages (and any input
//! message that had to be written anew) in chunks of their own, compressed on
//! rayon's workers ([`super::chunk`]), and a summary section listing both.
//!
//! Layout: magic, header, every schema and channel (input ids, then ours),
//! then the records in the order they come (copied chunks with their message
//! indexes, metadata, attachments, our chunks with theirs), data end, summary,
//! footer.

use std::collections::BTreeMap;
use std::io::{self, Write};

use mcap::records::{self, MessageHeader, MessageIndex, Record, op};

use super::chunk::{ChunkBuilder, ChunkCompression, CompressedChunk, Compressor};
use super::raw::RecordWriter;
use super::summary::SummaryBuilder;
use crate::input::{InputAttachment, RawChunk, RawRecord};

/// What a copied side record was, for the counts.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub(super) enum SideKind {
    Metadata,
    Attachment,
}

pub(super) struct PassThroughWriter<W: Write> {
    out: RecordWriter<W>,
    summary: SummaryBuilder,
    builder: ChunkBuilder,
    compressor: Compressor,
}

fn invalid(what: String) -> io::Error {
    io::Error::new(io::ErrorKind::InvalidData, what)
}

impl<W: Write> PassThroughWriter<W> {
    pub(super) fn new(
        inner: W,
        header: &records::Header,
        compression: ChunkCompression,
        chunk_target_bytes: u64,
    ) -> io::Result<Self> {
        Ok(Self {
            out: RecordWriter::new(inner, header)?,
            summary: SummaryBuilder::default(),
            builder: ChunkBuilder::new(chunk_target_bytes),
            compressor: Compressor::new(compression),
        })
    }

    pub(super) fn add_schema(
        &mut self,
        header: records::SchemaHeader,
        data: &[u8],
    ) -> io::Result<()> {
        self.out.write_schema(&header, data)?;
        self.summary.add_schema(header, data.to_vec());
        Ok(())
    }

    pub(super) fn add_channel(&mut self, channel: records::Channel) -> io::Result<()> {
        self.out.write_serialized(op::CHANNEL, &channel)?;
        self.summary.add_channel(channel);
        Ok(())
    }

    /// A message in our own chunks.
    pub(super) fn write_message(&mut self, header: &MessageHeader, data: &[u8]) -> io::Result<()> {
        if self.builder.would_overflow(data.len()) {
            self.close_chunk()?;
        }
        self.builder.push(header, data);
        Ok(())
    }

    /// Hand the chunk being filled to a worker; write the chunks now due.
    fn close_chunk(&mut self) -> io::Result<()> {
        if let Some(chunk) = self.builder.close() {
            for compressed in self.compressor.submit(chunk)? {
                self.write_own_chunk(compressed)?;
            }
            self.builder.reuse(self.compressor.take_buffer());
        }
        Ok(())
    }

    fn write_own_chunk(&mut self, chunk: CompressedChunk) -> io::Result<()> {
        let chunk_start_offset = self.out.position();
        self.out.write_chunk(&chunk.header, &chunk.data)?;
        let chunk_length = self.out.position() - chunk_start_offset;
        let message_counts = chunk.message_counts();
        self.compressor.recycle(chunk.data);
        if let Some(spare) = chunk.spare {
            self.compressor.recycle(spare);
        }
        let indexes_start = self.out.position();
        let mut message_index_offsets = BTreeMap::new();
        for (channel_id, entries) in chunk.indexes {
            message_index_offsets.insert(channel_id, self.out.position());
            let index = MessageIndex {
                channel_id,
                records: entries,
            };
            self.out.write_serialized(op::MESSAGE_INDEX, &index)?;
        }
        let header = chunk.header;
        let index = records::ChunkIndex {
            message_start_time: header.message_start_time,
            message_end_time: header.message_end_time,
            chunk_start_offset,
            chunk_length,
            message_index_offsets,
            message_index_length: self.out.position() - indexes_start,
            compression: header.compression,
            compressed_size: header.compressed_size,
            uncompressed_size: header.uncompressed_size,
        };
        self.summary.add_chunk(index, &message_counts);
        Ok(())
    }

    /// An input chunk and its message indexes, byte for byte; its index
    /// moved to where they now sit.
    ///
    /// A chunk that holds no message is left out: it can only hold schema
    /// and channel records, and this file already has every one of them
    /// before its first chunk (a pass-through read needs a summary that lists
    /// them all). Copied, its index would say its messages start and end at
    /// time 0, and viewers take the smallest start of the chunk indexes as
    /// the start of the log (Foxglove and Lichtblick then open on 1970). (A
    /// chunk with messages but no message index never gets here: a
    /// pass-through read needs the indexes to count every message.)
    pub(super) fn copy_chunk(&mut self, chunk: &RawChunk) -> io::Result<()> {
        let holds_no_message = chunk.index.message_index_offsets.is_empty()
            && chunk.message_counts.values().all(|&count| count == 0);
        if holds_no_message {
            return Ok(());
        }
        let chunk_start_offset = self.out.position();
        self.out.write_raw(&chunk.record)?;
        let indexes_start = self.out.position();
        self.out.write_raw(&chunk.message_indexes)?;
        let mut index = chunk.index.clone();
        index.chunk_start_offset = chunk_start_offset;
        for offset in index.message_index_offsets.values_mut() {
            let within = offset
                .checked_sub(chunk.message_indexes_offset)
                .filter(|&within| within < chunk.message_indexes.len() as u64)
                .ok_or_else(|| {
                    invalid(format!(
                        "a message index of the chunk at input byte {} lies outside the records read after it",
                        chunk.index.chunk_start_offset
                    ))
                })?;
            *offset = indexes_start + within;
        }
        self.summary.add_chunk(index, &chunk.message_counts);
        Ok(())
    }

    /// An input metadata or attachment record, byte for byte, indexed.
    pub(super) fn copy_side_record(&mut self, record: &RawRecord) -> io::Result<SideKind> {
        let offset = self.out.position();
        let length = record.bytes.len() as u64;
        let opcode = record
            .opcode()
            .ok_or_else(|| invalid("an empty record to copy".into()))?;
        let parsed = mcap::parse_record(opcode, record.body())
            .map_err(|e| invalid(format!("a record to copy is malformed: {e}")))?;
        let kind = match parsed {
            Record::Metadata(metadata) => {
                self.summary.add_metadata(records::MetadataIndex {
                    offset,
                    length,
                    name: metadata.name,
                });
                SideKind::Metadata
            }
            Record::Attachment { header, data, .. } => {
                self.summary
                    .add_attachment(attachment_index(offset, length, header, data.len()));
                SideKind::Attachment
            }
            _ => {
                return Err(invalid(format!(
                    "opcode {opcode:#04x} is not a side record"
                )));
            }
        };
        self.out.write_raw(&record.bytes)?;
        Ok(kind)
    }

    pub(super) fn write_metadata(&mut self, metadata: &records::Metadata) -> io::Result<()> {
        let offset = self.out.position();
        self.out.write_serialized(op::METADATA, metadata)?;
        self.summary.add_metadata(records::MetadataIndex {
            offset,
            length: self.out.position() - offset,
            name: metadata.name.clone(),
        });
        Ok(())
    }

    pub(super) fn write_attachment(&mut self, attachment: &InputAttachment) -> io::Result<()> {
        let offset = self.out.position();
        let header = records::AttachmentHeader {
            log_time: attachment.log_time_ns,
            create_time: attachment.create_time_ns,
            name: attachment.name.clone(),
            media_type: attachment.media_type.clone(),
        };
        self.out.write_attachment(&header, &attachment.data)?;
        let length = self.out.position() - offset;
        self.summary.add_attachment(attachment_index(
            offset,
            length,
            header,
            attachment.data.len(),
        ));
        Ok(())
    }

    /// Our last chunks, the data end, summary and footer; the stream back.
    pub(super) fn finish(mut self) -> io::Result<W> {
        self.close_chunk()?;
        for compressed in self.compressor.drain()? {
            self.write_own_chunk(compressed)?;
        }
        self.out.end_data_section()?;
        self.summary.write(self.out)
    }
}

fn attachment_index(
    offset: u64,
    length: u64,
    header: records::AttachmentHeader,
    data_size: usize,
) -> records::AttachmentIndex {
    records::AttachmentIndex {
        offset,
        length,
        log_time: header.log_time,
        create_time: header.create_time,
        data_size: data_size as u64,
        name: header.name,
        media_type: header.media_type,
    }
}
