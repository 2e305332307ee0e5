//! Stage 1: the streaming MCAP reader.
//!
//! [`InputFile::open`] looks at the file once and decides how to read it:
//! - **indexed**: the file has a summary with chunk indexes and statistics, so
//!   messages are read in log-time order through `sans_io::IndexedReader`, one
//!   chunk (plus the chunks overlapping it in time) in memory at a time;
//! - **linear**: no summary, an unchunked file, or a truncated one. A first pass
//!   lists schemas and channels (so topic detection and our own ids are decided
//!   before anything is written), the second streams records in file order
//!   through a bounded reorder window (`reorder`) that restores log-time order
//!   for the usual small disorder between recorder threads.
//!
//! Either way memory is bounded by the largest chunk or record, never by the
//! length of the log. The reader yields [`InputRecord`]s through a callback; it
//! decodes nothing itself.
//!
//! An indexed file whose messages are all indexed and already in log-time
//! order in the file can also be read for a pass-through output
//! ([`InputFile::read_copying`]): each chunk record whole, as stored, with its
//! message index records (`chunks`).

mod catalog;
mod chunks;
mod indexed;
mod linear;
mod reorder;

use std::collections::{BTreeMap, BTreeSet};
use std::path::{Path, PathBuf};
use std::sync::Arc;

pub use catalog::{Catalog, ChannelInfo};

/// What the reader hands downstream, in log-time order for messages.
#[derive(Debug, Clone)]
pub enum InputRecord {
    Message(InputMessage),
    Metadata(mcap::records::Metadata),
    Attachment(InputAttachment),
}

/// One message as stored in the input: header fields and payload bytes, unchanged.
#[derive(Debug, Clone)]
pub struct InputMessage {
    pub channel_id: u16,
    pub sequence: u32,
    pub log_time_ns: u64,
    pub publish_time_ns: u64,
    pub data: Vec<u8>,
}

impl InputMessage {
    /// An owned copy of a message record.
    pub fn new(header: &mcap::records::MessageHeader, data: &[u8]) -> Self {
        Self {
            channel_id: header.channel_id,
            sequence: header.sequence,
            log_time_ns: header.log_time,
            publish_time_ns: header.publish_time,
            data: data.to_vec(),
        }
    }
}

/// A message inside a chunk being read, borrowed from its decompressed records.
#[derive(Debug, Clone, Copy)]
pub struct MessageRef<'a> {
    pub header: mcap::records::MessageHeader,
    pub data: &'a [u8],
}

impl MessageRef<'_> {
    /// An owned copy.
    pub fn to_owned_message(&self) -> InputMessage {
        InputMessage::new(&self.header, self.data)
    }
}

/// A record of the input copied into a pass-through output byte for byte.
#[derive(Debug)]
pub enum CopiedRecord {
    Chunk(RawChunk),
    /// A metadata or attachment record.
    Side(RawRecord),
}

/// One chunk as stored in the input, with its message index records.
#[derive(Debug)]
pub struct RawChunk {
    /// The input's index of the chunk (input offsets).
    pub index: mcap::records::ChunkIndex,
    /// The chunk record: opcode, length, header, compressed records.
    pub record: Vec<u8>,
    /// The message index records after it, as stored.
    pub message_indexes: Vec<u8>,
    /// Where `message_indexes` starts in the input.
    pub message_indexes_offset: u64,
    /// Messages per channel in the chunk, from its message indexes.
    pub message_counts: BTreeMap<u16, u64>,
}

/// One whole record as stored: opcode, length, body.
#[derive(Debug)]
pub struct RawRecord {
    pub bytes: Vec<u8>,
}

impl RawRecord {
    pub fn opcode(&self) -> Option<u8> {
        self.bytes.first().copied()
    }

    /// The body, after the opcode and the 8-byte length.
    pub fn body(&self) -> &[u8] {
        self.bytes.get(9..).unwrap_or_default()
    }
}

/// What a copying read ([`InputFile::read_copying`]) hands downstream.
#[derive(Debug)]
pub enum CopyEvent<'a> {
    /// To copy into the output as it is.
    Copy(CopiedRecord),
    /// A message on a selected channel inside the chunk just copied: to
    /// decode only (it is in the output already).
    Selected(MessageRef<'a>),
    /// A message of a chunk whose records failed their CRC (that chunk is
    /// not copied): to write anew, and to decode if its channel is selected.
    Salvaged(MessageRef<'a>),
}

/// One attachment, owned.
#[derive(Debug, Clone, PartialEq, Eq)]
pub struct InputAttachment {
    pub log_time_ns: u64,
    pub create_time_ns: u64,
    pub name: String,
    pub media_type: String,
    pub data: Vec<u8>,
}

/// How the messages are being read.
#[derive(Debug, Clone, PartialEq, Eq, serde::Serialize)]
#[serde(tag = "mode", rename_all = "snake_case")]
pub enum ReadMode {
    /// Through the summary's chunk indexes, in log-time order.
    Indexed,
    /// Streaming in file order with a reorder window; `reason` says why.
    Linear { reason: String },
}

/// Reader options (all bounds on memory).
#[derive(Debug, Clone, serde::Serialize)]
pub struct InputOptions {
    /// Check each chunk's CRC before its messages are used.
    pub verify_crc: bool,
    /// Linear mode: how far (log time) a message may arrive late and still be
    /// put back in order.
    pub reorder_window_ns: u64,
    /// Linear mode: most payload bytes held in the reorder window.
    pub reorder_max_bytes: usize,
    /// Largest single record (chunk, message, attachment) accepted, bytes.
    pub record_length_limit: usize,
}

impl Default for InputOptions {
    fn default() -> Self {
        Self {
            verify_crc: false,
            reorder_window_ns: 2_000_000_000,
            reorder_max_bytes: 512 << 20,
            record_length_limit: 1 << 30,
        }
    }
}

/// Errors that stop reading an input file.
#[derive(Debug, thiserror::Error)]
pub enum InputError {
    #[error("{path}: cannot open: {source}")]
    Open {
        path: PathBuf,
        source: std::io::Error,
    },
    #[error("{path}: not an MCAP file (bad magic)")]
    NotMcap { path: PathBuf },
    #[error("{path}: I/O error at byte {offset}: {source}")]
    Io {
        path: PathBuf,
        offset: u64,
        source: std::io::Error,
    },
    #[error("{path}: {what}: {source}")]
    Mcap {
        path: PathBuf,
        what: String,
        source: mcap::McapError,
    },
    #[error(
        "{path}: chunk at byte {offset} (log time {start_ns}..{end_ns} ns) failed its CRC check: {reason}"
    )]
    BadChunk {
        path: PathBuf,
        offset: u64,
        start_ns: u64,
        end_ns: u64,
        reason: String,
    },
    #[error("{path}: {what}")]
    Invalid { path: PathBuf, what: String },
    /// The consumer asked to stop (e.g. the writer failed).
    #[error("reading stopped by the consumer")]
    Stopped,
}

/// Something wrong with the input that did not stop the read.
#[derive(Debug, Clone, PartialEq, Eq, serde::Serialize)]
pub struct InputWarning {
    pub message: String,
}

/// What a read pass saw, for the run summary.
#[derive(Debug, Clone, Default, serde::Serialize)]
pub struct ReadReport {
    pub messages: u64,
    pub metadata_records: u64,
    pub attachments: u64,
    /// Linear mode: messages that arrived later than the reorder window allows;
    /// they are still copied, in arrival order.
    pub out_of_order_beyond_window: u64,
    /// Chunks whose CRC did not match (`--verify`, and in a pass-through read
    /// every chunk decompressed); their messages were still copied unchanged
    /// (never dropped) unless the run is strict.
    pub bad_crc_chunks: u64,
    /// Pass-through read: chunks handed over whole, to copy as they are.
    pub chunks_copied: u64,
    /// Pass-through read: chunks decompressed (to decode their selected
    /// messages, or to check their CRC).
    pub chunks_decompressed: u64,
    /// Where the file ended early or was damaged, if it did.
    pub truncated: Option<String>,
    pub warnings: Vec<InputWarning>,
}

/// Whether the consumer wants more records.
pub type Flow = std::ops::ControlFlow<()>;

/// An opened MCAP input with its catalog and chosen read mode.
pub struct InputFile {
    path: PathBuf,
    options: InputOptions,
    catalog: Arc<Catalog>,
    mode: ReadMode,
    summary: Option<mcap::Summary>,
    /// `Err(reason)` when the chunks cannot be copied byte for byte.
    copyable: Result<(), String>,
}

impl InputFile {
    /// Open `path`, read its summary (or list it with a linear pass) and choose
    /// the read mode.
    pub fn open(path: &Path, options: InputOptions) -> Result<Self, InputError> {
        let mut file = open_file(path)?;
        check_magic(path, &mut file)?;
        let summary = indexed::read_summary(path, &mut file, &options);
        let (mode, summary) = match summary {
            Ok(Some(summary)) => match indexed::why_not_indexed(&summary) {
                None => (ReadMode::Indexed, Some(summary)),
                Some(reason) => (ReadMode::Linear { reason }, None),
            },
            Ok(None) => (
                ReadMode::Linear {
                    reason: "the file has no summary section".into(),
                },
                None,
            ),
            Err(reason) => (ReadMode::Linear { reason }, None),
        };
        let (catalog, copyable) = match &summary {
            Some(summary) => {
                let mut catalog = Catalog::from_summary(summary);
                let scan = chunks::scan_message_indexes(path, summary, &options);
                for (channel_id, (first, last)) in scan.spans {
                    catalog.first_log_time_ns.insert(channel_id, first);
                    catalog.last_log_time_ns.insert(channel_id, last);
                }
                (catalog, scan.copyable)
            }
            None => (
                linear::list_catalog(path, &options)?,
                Err("the file is read linearly".into()),
            ),
        };
        Ok(Self {
            path: path.to_path_buf(),
            options,
            catalog: Arc::new(catalog),
            mode,
            summary,
            copyable,
        })
    }

    /// Switch to linear reading (e.g. after the indexed pass found the indexes
    /// do not cover every message). Lists the file again.
    pub fn force_linear(&mut self, reason: String) -> Result<(), InputError> {
        self.catalog = Arc::new(linear::list_catalog(&self.path, &self.options)?);
        self.summary = None;
        self.copyable = Err("the file is read linearly".into());
        self.mode = ReadMode::Linear { reason };
        Ok(())
    }

    /// Why the chunks cannot be copied byte for byte into the output, if they
    /// cannot: the file must be indexed, every message indexed, and its
    /// messages in log-time order in file order.
    pub fn copy_blocker(&self) -> Option<&str> {
        self.copyable.as_ref().err().map(String::as_str)
    }

    pub fn path(&self) -> &Path {
        &self.path
    }

    pub fn catalog(&self) -> &Arc<Catalog> {
        &self.catalog
    }

    pub fn mode(&self) -> &ReadMode {
        &self.mode
    }

    /// Total payload-bearing records expected, for progress reporting, when known.
    pub fn expected_messages(&self) -> Option<u64> {
        self.catalog.total_messages()
    }

    /// Stream every record to `sink`: metadata and attachments, then messages in
    /// log-time order (indexed), or everything in file order through the reorder
    /// window (linear). `strict` makes a bad chunk CRC fatal.
    pub fn read_records(
        &self,
        strict: bool,
        sink: &mut dyn FnMut(InputRecord) -> Flow,
    ) -> Result<ReadReport, InputError> {
        match &self.summary {
            Some(summary) => indexed::read(&self.path, summary, &self.options, strict, sink),
            None => linear::read(&self.path, &self.options, sink),
        }
    }

    /// Stream the file for a pass-through output: metadata and attachment
    /// records as stored, then every chunk whole in file order, each followed
    /// by its messages on `selected` channels (decompressed only when it holds
    /// one, or with `verify_crc`). `strict` makes a bad chunk CRC fatal;
    /// otherwise that chunk's messages come as [`CopyEvent::Salvaged`].
    pub fn read_copying(
        &self,
        strict: bool,
        selected: &BTreeSet<u16>,
        sink: &mut dyn FnMut(CopyEvent<'_>) -> Flow,
    ) -> Result<ReadReport, InputError> {
        let (Some(summary), None) = (&self.summary, self.copy_blocker()) else {
            return Err(InputError::Invalid {
                path: self.path.clone(),
                what: format!(
                    "its chunks cannot be copied as they are: {}",
                    self.copy_blocker().unwrap_or("the file has no summary")
                ),
            });
        };
        chunks::read(&self.path, summary, &self.options, strict, selected, sink)
    }
}

fn open_file(path: &Path) -> Result<std::fs::File, InputError> {
    std::fs::File::open(path).map_err(|source| InputError::Open {
        path: path.to_path_buf(),
        source,
    })
}

fn check_magic(path: &Path, file: &mut std::fs::File) -> Result<(), InputError> {
    use std::io::Read;
    let mut magic = [0u8; 8];
    match file.read_exact(&mut magic) {
        Ok(()) if magic == mcap::MAGIC => Ok(()),
        Ok(()) => Err(InputError::NotMcap {
            path: path.to_path_buf(),
        }),
        Err(e) if e.kind() == std::io::ErrorKind::UnexpectedEof => Err(InputError::NotMcap {
            path: path.to_path_buf(),
        }),
        Err(source) => Err(InputError::Io {
            path: path.to_path_buf(),
            offset: 0,
            source,
        }),
    }
}
