//! Indexed reading: summary section, then messages in log-time order through
//! `sans_io::IndexedReader`, one chunk read from disk per request.

use std::fs::File;
use std::io::{Read, Seek, SeekFrom};
use std::path::Path;

use mcap::records::{ChunkIndex, Record};
use mcap::sans_io::indexed_reader::ReadOrder;
use mcap::sans_io::{IndexedReadEvent, IndexedReader, IndexedReaderOptions, SummaryReadEvent};
use mcap::sans_io::{SummaryReader, SummaryReaderOptions};

use super::chunks::Unpacker;
use super::{
    Flow, InputAttachment, InputError, InputMessage, InputOptions, InputRecord, InputWarning,
    ReadReport,
};

/// Read the summary section. `Ok(None)`: the file has none. `Err(reason)`: it
/// could not be read (truncated, damaged footer): the caller falls back to a
/// linear read and reports the reason.
pub(super) fn read_summary(
    path: &Path,
    file: &mut File,
    options: &InputOptions,
) -> Result<Option<mcap::Summary>, String> {
    let file_size = file
        .metadata()
        .map_err(|e| format!("cannot stat {}: {e}", path.display()))?
        .len();
    let mut reader = SummaryReader::new_with_options(
        SummaryReaderOptions::default()
            .with_file_size(file_size)
            .with_record_length_limit(options.record_length_limit),
    );
    while let Some(event) = reader.next_event() {
        match event {
            Ok(SummaryReadEvent::ReadRequest(need)) => {
                let read = file
                    .read(reader.insert(need))
                    .map_err(|e| format!("reading the summary failed: {e}"))?;
                reader.notify_read(read);
            }
            Ok(SummaryReadEvent::SeekRequest(to)) => {
                let pos = file
                    .seek(to)
                    .map_err(|e| format!("seeking to the summary failed: {e}"))?;
                reader.notify_seeked(pos);
            }
            // A summary may repeat the channels without their schemas (valid:
            // the schemas are in the data section), which the mcap crate cannot
            // link; that is no sign of truncation, so say what it is.
            Err(mcap::McapError::UnknownSchema(topic, id)) => {
                return Err(format!(
                    "the summary's channel {topic} refers to schema {id}, which only the data section holds"
                ));
            }
            Err(e) => {
                return Err(format!(
                    "the summary could not be read ({e}); the file may be truncated"
                ));
            }
        }
    }
    Ok(reader.finish())
}

/// Why a summary cannot drive an indexed read, if it cannot.
///
/// `IndexedReader` silently yields nothing for messages outside chunks, so the
/// summary must have chunk indexes and statistics; the message count is checked
/// again after the read. An indexed read also takes channels and schemas only
/// from the summary, and metadata and attachments only through their indexes,
/// so the summary must hold as many of each as the statistics count
/// (everything in it is optional: a summary with statistics and chunk indexes
/// but no channel records, or no metadata indexes, is valid, and the records
/// are then only in the data section, which a linear read sees).
pub(super) fn why_not_indexed(summary: &mcap::Summary) -> Option<String> {
    let Some(stats) = &summary.stats else {
        return Some(
            "the summary has no statistics record, so index coverage cannot be checked".into(),
        );
    };
    if let Some(missing) = summary_shortfall(summary, stats) {
        return Some(missing);
    }
    if summary.chunk_indexes.is_empty() && stats.message_count > 0 {
        return Some("the file is unchunked (no chunk indexes)".into());
    }
    if summary.chunk_indexes.len() as u64 != u64::from(stats.chunk_count) {
        return Some(format!(
            "the summary lists {} chunk indexes but its statistics count {} chunks",
            summary.chunk_indexes.len(),
            stats.chunk_count
        ));
    }
    None
}

/// Read every record of an indexed file: metadata and attachments first (file
/// order), then all messages in log-time order.
pub(super) fn read(
    path: &Path,
    summary: &mcap::Summary,
    options: &InputOptions,
    strict: bool,
    sink: &mut dyn FnMut(InputRecord) -> Flow,
) -> Result<ReadReport, InputError> {
    let mut file = File::open(path).map_err(|source| InputError::Open {
        path: path.to_path_buf(),
        source,
    })?;
    let file_size = file.metadata().map(|m| m.len()).unwrap_or(u64::MAX);
    let mut report = ReadReport::default();
    let mut buffer = Vec::new();
    for record in side_records(summary) {
        read_span(
            path,
            &mut file,
            record.offset,
            record.length,
            file_size,
            options,
            &mut buffer,
        )?;
        let parsed = parse_whole_record(path, &buffer, record.offset)?;
        let item = match parsed {
            Record::Metadata(metadata) => {
                report.metadata_records += 1;
                InputRecord::Metadata(metadata)
            }
            Record::Attachment { header, data, .. } => {
                report.attachments += 1;
                InputRecord::Attachment(InputAttachment {
                    log_time_ns: header.log_time,
                    create_time_ns: header.create_time,
                    name: header.name,
                    media_type: header.media_type,
                    data: data.into_owned(),
                })
            }
            _ => {
                return Err(InputError::Invalid {
                    path: path.to_path_buf(),
                    what: format!(
                        "index at byte {} does not point to a metadata or attachment record",
                        record.offset
                    ),
                });
            }
        };
        if sink(item).is_break() {
            return Err(InputError::Stopped);
        }
    }
    read_messages(
        path,
        &mut file,
        file_size,
        summary,
        options,
        strict,
        &mut report,
        sink,
    )?;
    Ok(report)
}

/// What the statistics count that the summary does not list, if anything.
fn summary_shortfall(summary: &mcap::Summary, stats: &mcap::records::Statistics) -> Option<String> {
    let listed = [
        (
            "channel records",
            summary.channels.len() as u64,
            u64::from(stats.channel_count),
        ),
        (
            "schema records",
            summary.schemas.len() as u64,
            u64::from(stats.schema_count),
        ),
        (
            "metadata indexes",
            summary.metadata_indexes.len() as u64,
            u64::from(stats.metadata_count),
        ),
        (
            "attachment indexes",
            summary.attachment_indexes.len() as u64,
            u64::from(stats.attachment_count),
        ),
    ];
    let channel_missing = stats
        .channel_message_counts
        .iter()
        .any(|(id, count)| *count > 0 && !summary.channels.contains_key(id));
    listed
        .iter()
        .find(|(_, found, counted)| found < counted)
        .map(|(what, found, counted)| {
            format!("the summary lists {found} {what} but its statistics count {counted}")
        })
        .or_else(|| {
            channel_missing
                .then(|| "the summary lacks the channel records of some messages".to_string())
        })
}

pub(super) struct SideRecord {
    pub offset: u64,
    pub length: u64,
}

/// Metadata and attachment records in file order (deterministic).
pub(super) fn side_records(summary: &mcap::Summary) -> Vec<SideRecord> {
    let mut records: Vec<SideRecord> = summary
        .metadata_indexes
        .iter()
        .map(|m| SideRecord {
            offset: m.offset,
            length: m.length,
        })
        .chain(summary.attachment_indexes.iter().map(|a| SideRecord {
            offset: a.offset,
            length: a.length,
        }))
        .collect();
    records.sort_by_key(|r| r.offset);
    records
}

#[allow(clippy::too_many_arguments)]
fn read_messages(
    path: &Path,
    file: &mut File,
    file_size: u64,
    summary: &mcap::Summary,
    options: &InputOptions,
    strict: bool,
    report: &mut ReadReport,
    sink: &mut dyn FnMut(InputRecord) -> Flow,
) -> Result<(), InputError> {
    let mcap_err = |what: &str, source| InputError::Mcap {
        path: path.to_path_buf(),
        what: what.to_string(),
        source,
    };
    let reader_options = IndexedReaderOptions::new()
        .with_order(ReadOrder::LogTime)
        .with_record_length_limit(options.record_length_limit);
    let mut reader = IndexedReader::new_with_options(summary, reader_options)
        .map_err(|e| mcap_err("the chunk indexes are invalid", e))?;
    let mut chunk_buffer = Vec::new();
    let mut unpacker = Unpacker::default();
    while let Some(event) = reader.next_event() {
        match event.map_err(|e| mcap_err("reading messages through the index failed", e))? {
            IndexedReadEvent::ReadChunkRequest { offset, length } => {
                let index = chunk_index_at(summary, offset);
                if options.verify_crc
                    && let Some(index) = index
                {
                    let buffers = (&mut chunk_buffer, &mut unpacker);
                    verify_chunk(path, file, file_size, index, options, buffers).or_else(
                        |err| {
                            if strict {
                                return Err(err);
                            }
                            report.bad_crc_chunks += 1;
                            report.warnings.push(InputWarning {
                                message: format!(
                                    "{err}; its messages are copied unchanged but may be corrupt"
                                ),
                            });
                            Ok(())
                        },
                    )?;
                }
                read_span(
                    path,
                    file,
                    offset,
                    length as u64,
                    file_size,
                    options,
                    &mut chunk_buffer,
                )?;
                reader
                    .insert_chunk_record_data(offset, &chunk_buffer)
                    .map_err(|e| mcap_err(&format!("chunk at byte {offset} is unreadable"), e))?;
            }
            IndexedReadEvent::Message { header, data } => {
                report.messages += 1;
                let message = InputMessage::new(&header, data);
                if sink(InputRecord::Message(message)).is_break() {
                    return Err(InputError::Stopped);
                }
            }
        }
    }
    Ok(())
}

fn chunk_index_at(summary: &mcap::Summary, data_offset: u64) -> Option<&ChunkIndex> {
    summary
        .chunk_indexes
        .iter()
        .find(|c| c.compressed_data_offset().ok() == Some(data_offset))
}

/// Read `length` bytes at `offset` into `buffer`, refusing lengths the file
/// cannot hold or above the record limit (untrusted sizes never drive allocation).
pub(super) fn read_span(
    path: &Path,
    file: &mut File,
    offset: u64,
    length: u64,
    file_size: u64,
    options: &InputOptions,
    buffer: &mut Vec<u8>,
) -> Result<(), InputError> {
    let end = offset.checked_add(length);
    if end.is_none_or(|end| end > file_size) || length > options.record_length_limit as u64 {
        return Err(InputError::Invalid {
            path: path.to_path_buf(),
            what: format!(
                "a record at byte {offset} claims {length} bytes, beyond the file ({file_size} bytes) or the record limit ({} bytes)",
                options.record_length_limit
            ),
        });
    }
    buffer.resize(length as usize, 0);
    file.seek(SeekFrom::Start(offset))
        .and_then(|_| file.read_exact(buffer))
        .map_err(|source| InputError::Io {
            path: path.to_path_buf(),
            offset,
            source,
        })
}

/// Parse a record read whole (opcode, length, body).
pub(super) fn parse_whole_record<'a>(
    path: &Path,
    bytes: &'a [u8],
    offset: u64,
) -> Result<Record<'a>, InputError> {
    let invalid = |what: String| InputError::Invalid {
        path: path.to_path_buf(),
        what,
    };
    if bytes.len() < 9 {
        return Err(invalid(format!("record at byte {offset} is too short")));
    }
    let opcode = bytes[0];
    let body_len = u64::from_le_bytes(bytes[1..9].try_into().expect("8 bytes"));
    let body = bytes
        .get(9..)
        .filter(|b| b.len() as u64 == body_len)
        .ok_or_else(|| {
            invalid(format!(
                "record at byte {offset} has a length that does not match its index"
            ))
        })?;
    mcap::parse_record(opcode, body).map_err(|source| InputError::Mcap {
        path: path.to_path_buf(),
        what: format!("record at byte {offset} is malformed"),
        source,
    })
}

/// Read a whole chunk record, decompress it and compare its CRC.
fn verify_chunk(
    path: &Path,
    file: &mut File,
    file_size: u64,
    index: &ChunkIndex,
    options: &InputOptions,
    (buffer, unpacker): (&mut Vec<u8>, &mut Unpacker),
) -> Result<(), InputError> {
    let bad = |reason: String| InputError::BadChunk {
        path: path.to_path_buf(),
        offset: index.chunk_start_offset,
        start_ns: index.message_start_time,
        end_ns: index.message_end_time,
        reason,
    };
    read_span(
        path,
        file,
        index.chunk_start_offset,
        index.chunk_length,
        file_size,
        options,
        buffer,
    )?;
    let Record::Chunk { header, data } =
        parse_whole_record(path, buffer, index.chunk_start_offset)?
    else {
        return Err(bad(
            "the chunk index does not point to a chunk record".into()
        ));
    };
    unpacker
        .unpack(&header, &data, options)
        .map_err(|fault| bad(fault.reason().to_string()))
}

/// Decompress a chunk body into `out` (appended). Output is capped at
/// `expected_size` + 1 so a hostile stream cannot balloon memory.
pub(super) fn decompress_into(
    compression: &str,
    data: &[u8],
    expected_size: usize,
    out: &mut Vec<u8>,
) -> Result<(), String> {
    let limit = expected_size as u64 + 1;
    // Sized by the data actually there, not by the (untrusted) header.
    out.reserve(
        expected_size
            .min(data.len().saturating_mul(4))
            .min(64 << 20),
    );
    match compression {
        "" => out.extend_from_slice(data),
        "zstd" => {
            let decoder = zstd::stream::read::Decoder::new(data).map_err(|e| e.to_string())?;
            decoder
                .take(limit)
                .read_to_end(out)
                .map_err(|e| e.to_string())?;
        }
        "lz4" => {
            let decoder = lz4::Decoder::new(data).map_err(|e| e.to_string())?;
            decoder
                .take(limit)
                .read_to_end(out)
                .map_err(|e| e.to_string())?;
        }
        other => return Err(format!("unsupported compression `{other}`")),
    }
    Ok(())
}
