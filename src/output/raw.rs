//! MCAP records written by hand, for the pass-through writer.
//!
//! The `mcap` crate's writer cannot put a chunk's compressed bytes into a file
//! as they are (foxglove/mcap#1679), so this module does the framing itself:
//! opcode, length, body, the data section's CRC, the summary section and the
//! footer with its CRC. Record bodies are serialised by the crate's own record
//! types (`mcap::records`, through binrw), so they are exactly what its readers
//! parse.

use std::io::{self, Cursor, Write};

use binrw::{BinWrite, Endian};
use mcap::records::{self, op};

/// Opcode and length in front of every record body.
pub(super) const RECORD_PREFIX_BYTES: u64 = 1 + 8;

/// Writes records to `inner`, counting the bytes (for the offsets the
/// indexes hold) and hashing them (for the data and summary section CRCs).
pub(super) struct RecordWriter<W: Write> {
    inner: W,
    position: u64,
    /// CRC of the current section: from the magic (data section) or from
    /// the summary's start (summary section).
    section_crc: crc32fast::Hasher,
    /// Serialised record bodies, reused from record to record.
    scratch: Vec<u8>,
}

impl<W: Write> RecordWriter<W> {
    /// Start a file: magic and header.
    pub(super) fn new(inner: W, header: &records::Header) -> io::Result<Self> {
        let mut writer = Self {
            inner,
            position: 0,
            section_crc: crc32fast::Hasher::new(),
            scratch: Vec::new(),
        };
        writer.write_raw(mcap::MAGIC)?;
        writer.write_serialized(op::HEADER, header)?;
        Ok(writer)
    }

    /// Bytes written so far: the offset of the next record.
    pub(super) fn position(&self) -> u64 {
        self.position
    }

    /// Bytes as they are (records copied from the input).
    pub(super) fn write_raw(&mut self, bytes: &[u8]) -> io::Result<()> {
        self.inner.write_all(bytes)?;
        self.section_crc.update(bytes);
        self.position += bytes.len() as u64;
        Ok(())
    }

    fn write_prefix(&mut self, opcode: u8, body_bytes: u64) -> io::Result<()> {
        let mut prefix = [0u8; RECORD_PREFIX_BYTES as usize];
        prefix[0] = opcode;
        prefix[1..].copy_from_slice(&body_bytes.to_le_bytes());
        self.write_raw(&prefix)
    }

    /// One record of the crate's record types.
    pub(super) fn write_serialized<T>(&mut self, opcode: u8, body: &T) -> io::Result<()>
    where
        T: for<'a> BinWrite<Args<'a> = ()>,
    {
        self.write_with_tail(opcode, body, &[])
    }

    /// A record whose body is a serialised header followed by `tail` (schema
    /// data, chunk data): the tail is written without a copy.
    fn write_with_tail<T>(&mut self, opcode: u8, head: &T, tail: &[&[u8]]) -> io::Result<()>
    where
        T: for<'a> BinWrite<Args<'a> = ()>,
    {
        let mut scratch = std::mem::take(&mut self.scratch);
        scratch.clear();
        head.write_options(&mut Cursor::new(&mut scratch), Endian::Little, ())
            .map_err(io::Error::other)?;
        let tail_bytes: u64 = tail.iter().map(|t| t.len() as u64).sum();
        let mut written = self
            .write_prefix(opcode, scratch.len() as u64 + tail_bytes)
            .and_then(|()| self.write_raw(&scratch));
        for part in tail {
            written = written.and_then(|()| self.write_raw(part));
        }
        self.scratch = scratch;
        written
    }

    /// A schema record: header, then the data with its 32-bit length.
    pub(super) fn write_schema(
        &mut self,
        header: &records::SchemaHeader,
        data: &[u8],
    ) -> io::Result<()> {
        let length = data_length_u32(data.len())?;
        self.write_with_tail(op::SCHEMA, header, &[&length.to_le_bytes(), data])
    }

    /// A chunk record: header, then the compressed records.
    pub(super) fn write_chunk(
        &mut self,
        header: &records::ChunkHeader,
        compressed: &[u8],
    ) -> io::Result<()> {
        self.write_with_tail(op::CHUNK, header, &[compressed])
    }

    /// An attachment record: header, data with its 64-bit length, and the
    /// CRC of everything before it in the record body.
    pub(super) fn write_attachment(
        &mut self,
        header: &records::AttachmentHeader,
        data: &[u8],
    ) -> io::Result<()> {
        let mut head = Vec::new();
        header
            .write_options(&mut Cursor::new(&mut head), Endian::Little, ())
            .map_err(io::Error::other)?;
        head.extend_from_slice(&(data.len() as u64).to_le_bytes());
        let mut crc = crc32fast::Hasher::new();
        crc.update(&head);
        crc.update(data);
        let body_bytes = head.len() as u64 + data.len() as u64 + 4;
        self.write_prefix(op::ATTACHMENT, body_bytes)?;
        self.write_raw(&head)?;
        self.write_raw(data)?;
        self.write_raw(&crc.finalize().to_le_bytes())
    }

    /// End the data section: the DataEnd record with the CRC of every byte
    /// before it. Returns where the summary section starts.
    pub(super) fn end_data_section(&mut self) -> io::Result<u64> {
        let data_section_crc = std::mem::take(&mut self.section_crc).finalize();
        self.write_serialized(op::DATA_END, &records::DataEnd { data_section_crc })?;
        // The summary CRC covers the summary section only.
        self.section_crc = crc32fast::Hasher::new();
        Ok(self.position)
    }

    /// The footer (its CRC covers the summary section and the footer up to
    /// the CRC itself), the closing magic; hands the stream back flushed.
    pub(super) fn finish(mut self, summary_start: u64, summary_offset_start: u64) -> io::Result<W> {
        self.write_prefix(op::FOOTER, 8 + 8 + 4)?;
        self.write_raw(&summary_start.to_le_bytes())?;
        self.write_raw(&summary_offset_start.to_le_bytes())?;
        let summary_crc = std::mem::take(&mut self.section_crc).finalize();
        self.write_raw(&summary_crc.to_le_bytes())?;
        self.write_raw(mcap::MAGIC)?;
        self.inner.flush()?;
        Ok(self.inner)
    }
}

fn data_length_u32(bytes: usize) -> io::Result<u32> {
    u32::try_from(bytes).map_err(|_| {
        io::Error::new(
            io::ErrorKind::InvalidInput,
            format!("{bytes} bytes of schema data do not fit a 32-bit length"),
        )
    })
}

#[cfg(test)]
mod tests {
    use super::*;

    fn header() -> records::Header {
        records::Header {
            profile: String::new(),
            library: "test".into(),
        }
    }

    #[test]
    fn an_empty_file_reads_back_with_its_crcs() {
        let mut out = RecordWriter::new(Vec::new(), &header()).unwrap();
        let summary_start = out.end_data_section().unwrap();
        let statistics = records::Statistics::default();
        out.write_serialized(op::STATISTICS, &statistics).unwrap();
        let offsets_start = out.position();
        let offset = records::SummaryOffset {
            group_opcode: op::STATISTICS,
            group_start: summary_start,
            group_length: offsets_start - summary_start,
        };
        out.write_serialized(op::SUMMARY_OFFSET, &offset).unwrap();
        let bytes = out.finish(summary_start, offsets_start).unwrap();
        let summary = mcap::Summary::read(&bytes).unwrap().unwrap();
        assert_eq!(summary.stats, Some(statistics));
        let options = mcap::sans_io::LinearReaderOptions::default()
            .with_validate_data_section_crc(true)
            .with_validate_summary_section_crc(true);
        let mut reader = mcap::sans_io::LinearReader::new_with_options(options);
        let mut rest = bytes.as_slice();
        while let Some(event) = reader.next_event() {
            match event.expect("valid file, CRCs match") {
                mcap::sans_io::LinearReadEvent::ReadRequest(need) => {
                    let n = need.min(rest.len());
                    reader.insert(n).copy_from_slice(&rest[..n]);
                    reader.notify_read(n);
                    rest = &rest[n..];
                }
                mcap::sans_io::LinearReadEvent::Record { .. } => {}
            }
        }
    }

    #[test]
    fn schema_records_parse_back() {
        let mut out = RecordWriter::new(Vec::new(), &header()).unwrap();
        let start = out.position();
        let schema = records::SchemaHeader {
            id: 3,
            name: "a/b".into(),
            encoding: "ros2msg".into(),
        };
        out.write_schema(&schema, b"int32 x").unwrap();
        let bytes = out.finish(0, 0).unwrap();
        let record = &bytes[start as usize..];
        let length = u64::from_le_bytes(record[1..9].try_into().unwrap()) as usize;
        let parsed = mcap::parse_record(record[0], &record[9..9 + length]).unwrap();
        let mcap::records::Record::Schema { header, data } = parsed else {
            panic!("a schema record");
        };
        assert_eq!((header, data.as_ref()), (schema, &b"int32 x"[..]));
    }
}
