//! The summary section of a pass-through output, gathered while its data
//! section is written: schemas, channels, statistics, chunk, attachment and
//! metadata indexes, then the summary offsets that let readers find each group.

use std::collections::BTreeMap;
use std::io::{self, Write};

use mcap::records::{self, op};

use super::raw::RecordWriter;

/// Everything the summary section lists, in the order readers expect.
#[derive(Default)]
pub(super) struct SummaryBuilder {
    schemas: BTreeMap<u16, (records::SchemaHeader, Vec<u8>)>,
    channels: BTreeMap<u16, records::Channel>,
    chunk_indexes: Vec<records::ChunkIndex>,
    attachment_indexes: Vec<records::AttachmentIndex>,
    metadata_indexes: Vec<records::MetadataIndex>,
    channel_message_counts: BTreeMap<u16, u64>,
    /// Earliest and latest message log time, once there is a message.
    message_bounds_ns: Option<(u64, u64)>,
}

impl SummaryBuilder {
    pub(super) fn add_schema(&mut self, header: records::SchemaHeader, data: Vec<u8>) {
        self.schemas.insert(header.id, (header, data));
    }

    pub(super) fn add_channel(&mut self, channel: records::Channel) {
        self.channels.insert(channel.id, channel);
    }

    /// A chunk written at its final offsets, holding `message_counts`
    /// messages per channel.
    pub(super) fn add_chunk(
        &mut self,
        index: records::ChunkIndex,
        message_counts: &BTreeMap<u16, u64>,
    ) {
        if message_counts.values().any(|&n| n > 0) {
            let (start, end) = (index.message_start_time, index.message_end_time);
            self.message_bounds_ns = Some(match self.message_bounds_ns {
                None => (start, end),
                Some((first, last)) => (first.min(start), last.max(end)),
            });
        }
        for (&channel_id, &count) in message_counts {
            *self.channel_message_counts.entry(channel_id).or_default() += count;
        }
        self.chunk_indexes.push(index);
    }

    pub(super) fn add_attachment(&mut self, index: records::AttachmentIndex) {
        self.attachment_indexes.push(index);
    }

    pub(super) fn add_metadata(&mut self, index: records::MetadataIndex) {
        self.metadata_indexes.push(index);
    }

    fn statistics(&self) -> records::Statistics {
        let (message_start_time, message_end_time) = self.message_bounds_ns.unwrap_or((0, 0));
        records::Statistics {
            message_count: self.channel_message_counts.values().sum(),
            schema_count: count_u16(self.schemas.len()),
            channel_count: self.channels.len() as u32,
            attachment_count: self.attachment_indexes.len() as u32,
            metadata_count: self.metadata_indexes.len() as u32,
            chunk_count: self.chunk_indexes.len() as u32,
            message_start_time,
            message_end_time,
            channel_message_counts: self.channel_message_counts.clone(),
        }
    }

    /// Write the summary section (after the data end record), its offsets
    /// and the footer; hands the stream back.
    pub(super) fn write<W: Write>(&self, mut out: RecordWriter<W>) -> io::Result<W> {
        let summary_start = out.position();
        let mut offsets = Vec::new();
        let mut group = |out: &mut RecordWriter<W>,
                         group_opcode: u8,
                         write: &mut dyn FnMut(&mut RecordWriter<W>) -> io::Result<()>|
         -> io::Result<()> {
            let group_start = out.position();
            write(out)?;
            if out.position() > group_start {
                offsets.push(records::SummaryOffset {
                    group_opcode,
                    group_start,
                    group_length: out.position() - group_start,
                });
            }
            Ok(())
        };
        group(&mut out, op::SCHEMA, &mut |out| {
            for (header, data) in self.schemas.values() {
                out.write_schema(header, data)?;
            }
            Ok(())
        })?;
        group(&mut out, op::CHANNEL, &mut |out| {
            write_all(out, op::CHANNEL, self.channels.values())
        })?;
        let statistics = self.statistics();
        group(&mut out, op::STATISTICS, &mut |out| {
            out.write_serialized(op::STATISTICS, &statistics)
        })?;
        group(&mut out, op::CHUNK_INDEX, &mut |out| {
            write_all(out, op::CHUNK_INDEX, &self.chunk_indexes)
        })?;
        group(&mut out, op::ATTACHMENT_INDEX, &mut |out| {
            write_all(out, op::ATTACHMENT_INDEX, &self.attachment_indexes)
        })?;
        group(&mut out, op::METADATA_INDEX, &mut |out| {
            write_all(out, op::METADATA_INDEX, &self.metadata_indexes)
        })?;
        let summary_offset_start = out.position();
        write_all(&mut out, op::SUMMARY_OFFSET, &offsets)?;
        out.finish(summary_start, summary_offset_start)
    }
}

fn write_all<'a, W, T>(
    out: &mut RecordWriter<W>,
    opcode: u8,
    records: impl IntoIterator<Item = &'a T>,
) -> io::Result<()>
where
    W: Write,
    T: for<'b> binrw::BinWrite<Args<'b> = ()> + 'a,
{
    for record in records {
        out.write_serialized(opcode, record)?;
    }
    Ok(())
}

/// The statistics record counts schemas in 16 bits; ids are 16-bit, so at
/// most 65535 schemas exist (id 0 means none).
fn count_u16(count: usize) -> u16 {
    u16::try_from(count).unwrap_or(u16::MAX)
}
