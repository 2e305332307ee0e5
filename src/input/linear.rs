//! Linear reading: records in file order through `sans_io::LinearReader`, for
//! files without a usable summary (unindexed, unchunked, truncated).

use std::collections::BTreeMap;
use std::fs::File;
use std::io::Read;
use std::path::Path;
use std::sync::Arc;

use mcap::records::{Record, op};
use mcap::sans_io::{LinearReadEvent, LinearReader, LinearReaderOptions};
use mcap::{Channel, Schema};

use super::catalog::Catalog;
use super::reorder::ReorderWindow;
use super::{
    Flow, InputAttachment, InputError, InputMessage, InputOptions, InputRecord, InputWarning,
    ReadReport,
};

/// A record seen by [`scan_records`], already parsed.
enum Seen<'a> {
    Schema(Arc<Schema<'static>>),
    Channel(mcap::records::Channel),
    Message(mcap::records::MessageHeader, &'a [u8]),
    Metadata(mcap::records::Metadata),
    Attachment(InputAttachment),
}

/// Why a linear pass stopped before the end magic, if it did.
struct Stop {
    reason: String,
}

/// Walk every data-section record of the file in order. A truncated or damaged
/// file ends the walk with `Ok(Some(stop))`: everything before it was delivered.
fn scan_records(
    path: &Path,
    options: &InputOptions,
    visit: &mut dyn FnMut(Seen<'_>) -> Result<Flow, InputError>,
) -> Result<Option<Stop>, InputError> {
    let mut file = File::open(path).map_err(|source| InputError::Open {
        path: path.to_path_buf(),
        source,
    })?;
    let reader_options = LinearReaderOptions::default()
        .with_validate_chunk_crcs(options.verify_crc)
        .with_record_length_limit(options.record_length_limit);
    let file_size = file.metadata().map_or(u64::MAX, |m| m.len());
    let mut reader = LinearReader::new_with_options(reader_options);
    let mut bytes_fed: u64 = 0;
    let mut past_data_end = false;
    while let Some(event) = reader.next_event() {
        let event = match event {
            Ok(event) => event,
            Err(err) => {
                return Ok(Some(Stop {
                    reason: describe_stop(&err, bytes_fed),
                }));
            }
        };
        match event {
            LinearReadEvent::ReadRequest(need) => {
                // The reader asks for a whole record at once; a length
                // field past the end of the file is a lie (or a truncation)
                // and must not size its buffer (a 600-byte file declaring a
                // 1 GiB record would allocate 1 GiB): ask the file for what
                // it has, and the read ends at its end.
                let remaining = file_size.saturating_sub(bytes_fed).max(1);
                let want = need.min(usize::try_from(remaining).unwrap_or(usize::MAX));
                let read = file
                    .read(reader.insert(want))
                    .map_err(|source| InputError::Io {
                        path: path.to_path_buf(),
                        offset: bytes_fed,
                        source,
                    })?;
                bytes_fed += read as u64;
                reader.notify_read(read);
            }
            LinearReadEvent::Record { opcode, data } => {
                if opcode == op::DATA_END {
                    past_data_end = true;
                    continue;
                }
                // The summary section repeats schemas and channels; it holds no
                // messages, metadata or attachments.
                if past_data_end {
                    continue;
                }
                let record = match mcap::parse_record(opcode, data) {
                    Ok(record) => record,
                    Err(err) => {
                        return Ok(Some(Stop {
                            reason: format!(
                                "malformed record (opcode {opcode:#04x}) near byte {bytes_fed}: {err}"
                            ),
                        }));
                    }
                };
                deliver(record, visit)?;
            }
        }
    }
    Ok(None)
}

/// Hand one data-section record to `visit`; records the reader does not use
/// are skipped.
fn deliver(
    record: Record<'_>,
    visit: &mut dyn FnMut(Seen<'_>) -> Result<Flow, InputError>,
) -> Result<(), InputError> {
    let flow = match record {
        // parse_record borrows the payload from the reader's buffer; an owned
        // one (defensive) is lent the same way.
        Record::Message { header, data } => visit(Seen::Message(header, &data))?,
        other => match seen_without_payload(other) {
            Some(seen) => visit(seen)?,
            None => return Ok(()),
        },
    };
    if flow.is_break() {
        return Err(InputError::Stopped);
    }
    Ok(())
}

/// The schema, channel, metadata or attachment `record` as a [`Seen`] that
/// owns its data; `None` for records the reader does not use.
fn seen_without_payload(record: Record<'_>) -> Option<Seen<'static>> {
    Some(match record {
        Record::Schema { header, data } => Seen::Schema(Arc::new(Schema {
            id: header.id,
            name: header.name,
            encoding: header.encoding,
            data: std::borrow::Cow::Owned(data.into_owned()),
        })),
        Record::Channel(channel) => Seen::Channel(channel),
        Record::Metadata(metadata) => Seen::Metadata(metadata),
        Record::Attachment { header, data, .. } => Seen::Attachment(InputAttachment {
            log_time_ns: header.log_time,
            create_time_ns: header.create_time,
            name: header.name,
            media_type: header.media_type,
            data: data.into_owned(),
        }),
        _ => return None,
    })
}

fn describe_stop(err: &mcap::McapError, bytes_fed: u64) -> String {
    match err {
        mcap::McapError::UnexpectedEof => {
            format!("the file ends in the middle of a record (truncated at byte {bytes_fed})")
        }
        other => format!("reading stopped near byte {bytes_fed}: {other}"),
    }
}

/// First pass: list schemas, channels and message counts.
pub(super) fn list_catalog(path: &Path, options: &InputOptions) -> Result<Catalog, InputError> {
    let mut catalog = Catalog::default();
    let mut pending_channels: BTreeMap<u16, mcap::records::Channel> = BTreeMap::new();
    let stop = scan_records(path, options, &mut |seen| {
        match seen {
            Seen::Schema(schema) => {
                catalog.schemas.entry(schema.id).or_insert(schema);
            }
            Seen::Channel(channel) => {
                pending_channels.entry(channel.id).or_insert(channel);
            }
            Seen::Message(header, _) => catalog.count_message(header.channel_id, header.log_time),
            Seen::Metadata(_) => catalog.metadata_count += 1,
            Seen::Attachment(_) => catalog.attachment_count += 1,
        }
        Ok(Flow::Continue(()))
    })?;
    catalog.listing_stopped = stop.map(|stop| stop.reason);
    for (id, channel) in pending_channels {
        let schema = catalog.schemas.get(&channel.schema_id).cloned();
        catalog.channels.insert(
            id,
            Arc::new(Channel {
                id,
                topic: channel.topic,
                schema,
                message_encoding: channel.message_encoding,
                metadata: channel.metadata,
            }),
        );
    }
    Ok(catalog)
}

/// Second pass: stream records through the reorder window.
pub(super) fn read(
    path: &Path,
    options: &InputOptions,
    sink: &mut dyn FnMut(InputRecord) -> Flow,
) -> Result<ReadReport, InputError> {
    let mut report = ReadReport::default();
    let mut window = ReorderWindow::new(options.reorder_window_ns, options.reorder_max_bytes);
    let mut ready = Vec::new();
    let stop = scan_records(path, options, &mut |seen| {
        let side_record = match seen {
            Seen::Message(header, data) => {
                let message = InputMessage::new(&header, data);
                window.push(message, &mut ready);
                return Ok(release(&mut ready, &mut report, sink));
            }
            Seen::Metadata(metadata) => {
                report.metadata_records += 1;
                InputRecord::Metadata(metadata)
            }
            Seen::Attachment(attachment) => {
                report.attachments += 1;
                InputRecord::Attachment(attachment)
            }
            Seen::Schema(_) | Seen::Channel(_) => return Ok(Flow::Continue(())),
        };
        // Side records do not wait in the window: their position among the
        // messages carries no meaning in MCAP.
        Ok(sink(side_record))
    })?;
    window.drain(&mut ready);
    if release(&mut ready, &mut report, sink).is_break() {
        return Err(InputError::Stopped);
    }
    report.out_of_order_beyond_window = window.late;
    if let Some(stop) = stop {
        report.warnings.push(InputWarning {
            message: format!(
                "{}: {}; kept the {} complete messages before it",
                path.display(),
                stop.reason,
                report.messages
            ),
        });
        report.truncated = Some(stop.reason);
    }
    if report.out_of_order_beyond_window > 0 {
        report.warnings.push(InputWarning {
            message: format!(
                "{}: {} messages arrived later than the {:.1} s reorder window; they were copied in file order",
                path.display(),
                report.out_of_order_beyond_window,
                options.reorder_window_ns as f64 * 1e-9
            ),
        });
    }
    Ok(report)
}

fn release(
    ready: &mut Vec<InputMessage>,
    report: &mut ReadReport,
    sink: &mut dyn FnMut(InputRecord) -> Flow,
) -> Flow {
    for message in ready.drain(..) {
        report.messages += 1;
        if sink(InputRecord::Message(message)).is_break() {
            return Flow::Break(());
        }
    }
    Flow::Continue(())
}
