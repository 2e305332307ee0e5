//! Last stage: the MCAP writer. Copies every input schema, channel (same ids),
//! message (same bytes, times and sequence), metadata record and attachment,
//! and adds our own channels under ids the input does not use.
//!
//! Two backends: the rewrite ([`mcap::Writer`]: every message written anew
//! into new chunks) and the pass-through (`passthrough`: the input's chunk
//! records copied byte for byte, our messages in chunks of their own,
//! compressed in parallel). Either way the output goes to a temporary file
//! beside the destination and is renamed only when complete ([`AtomicFile`]),
//! so a failed run never leaves a half-written log under the requested name.

mod chunk;
mod direct;
mod ids;
mod passthrough;
mod raw;
mod summary;
mod temp;
mod writeback;
pub use temp::{AtomicFile, AtomicTarget, remove_stale_temp_files};

use std::collections::BTreeMap;
use std::io::BufWriter;
use std::path::{Path, PathBuf};

use mcap::records::MessageHeader;

use crate::input::{Catalog, CopiedRecord, InputAttachment, InputMessage};

pub use ids::IdAllocator;
use passthrough::{PassThroughWriter, SideKind};
use temp::TempOutput;
use writeback::WritebackFile;

/// How the output is written.
#[derive(Debug, Clone, PartialEq, Eq, serde::Serialize)]
#[serde(tag = "mode", rename_all = "snake_case")]
pub enum WriteMode {
    /// The input's chunks copied byte for byte, our messages in chunks of
    /// their own.
    PassThrough,
    /// Every input message written anew, in log-time order; `reason` says
    /// why the chunks were not copied.
    Rewrite { reason: String },
}

/// Chunk compression of the output.
#[derive(Debug, Clone, Copy, PartialEq, Eq, serde::Serialize, clap::ValueEnum)]
#[serde(rename_all = "snake_case")]
pub enum OutputCompression {
    Zstd,
    Lz4,
    None,
}

/// zstd level of our own chunks beside passed-through input chunks, where
/// [`OutputOptions::compression_level`] is 0. At the library's default 3,
/// compressing our channels took 8 % of `process`' CPU at 64 x 2048; level
/// 1 takes 4 % less CPU overall for 0.3 % more output (3 s safe-drive log,
/// three alternating runs). The rewrite path keeps zstd's default: it
/// recompresses the input's records too, which level 1 leaves a third
/// larger (the committed `cut-in` sample: 8.7 -> 11.8 MB).
pub const OWN_CHUNKS_ZSTD_LEVEL: u32 = 1;

#[derive(Debug, Clone, serde::Serialize)]
pub struct OutputOptions {
    pub compression: OutputCompression,
    /// Target uncompressed chunk size, bytes.
    pub chunk_size_bytes: u64,
    /// Replace an existing output file.
    pub force: bool,
    /// zstd / lz4 level; 0 = the library default (zstd 3), and
    /// [`OWN_CHUNKS_ZSTD_LEVEL`] for our chunks beside passed-through ones.
    pub compression_level: u32,
    /// MCAP header profile: empty for `process` output (our channels are not
    /// CDR), `ros2` for synthetic logs.
    pub profile: String,
}

impl Default for OutputOptions {
    fn default() -> Self {
        Self {
            compression: OutputCompression::Zstd,
            chunk_size_bytes: 4 << 20,
            force: false,
            compression_level: 0,
            profile: String::new(),
        }
    }
}

#[derive(Debug, thiserror::Error)]
pub enum OutputError {
    #[error("{path}: the output must not be the input file")]
    SameAsInput { path: PathBuf },
    #[error("{path}: exists already")]
    Exists { path: PathBuf },
    #[error("{path}: cannot create the output: {source}")]
    Create {
        path: PathBuf,
        source: std::io::Error,
    },
    #[error("{path}: writing failed: {}", with_io_cause(source))]
    Write {
        path: PathBuf,
        source: mcap::McapError,
    },
    #[error("{path}: writing failed: {source}")]
    WriteIo {
        path: PathBuf,
        source: std::io::Error,
    },
    #[error("{path}: finishing the output failed: {source}")]
    Finish {
        path: PathBuf,
        source: std::io::Error,
    },
    #[error("{path}: no free {what} id left for our own records")]
    NoFreeId { path: PathBuf, what: &'static str },
    #[error("{path}: an input record to copy as it is reached a writer that rewrites the input")]
    CopyNeedsPassThrough { path: PathBuf },
}

/// An mcap writer's error with the system's word where it is one (the
/// crate's own text for an I/O error does not say which: a full disk must
/// say so).
fn with_io_cause(error: &mcap::McapError) -> String {
    match error {
        mcap::McapError::Io(cause) => format!("{error}: {cause}"),
        other => other.to_string(),
    }
}

/// Refuse `output` when it is `input` (same file, whatever the spelling) or
/// exists without `force`.
pub fn check_output_path(input: &Path, output: &Path, force: bool) -> Result<(), OutputError> {
    if same_file(input, output) {
        return Err(OutputError::SameAsInput {
            path: output.to_path_buf(),
        });
    }
    check_overwrite(output, force)
}

/// Refuse an existing `output` without `force`.
pub fn check_overwrite(output: &Path, force: bool) -> Result<(), OutputError> {
    if output.exists() && !force {
        return Err(OutputError::Exists {
            path: output.to_path_buf(),
        });
    }
    Ok(())
}

/// Whether `a` and `b` name the same existing file, whatever the spelling
/// (relative, `..`, symbolic links); `false` if either does not exist.
pub fn same_file(a: &Path, b: &Path) -> bool {
    // The same device and inode: a symlink, a hard link, or another path.
    #[cfg(unix)]
    if let (Ok(a), Ok(b)) = (std::fs::metadata(a), std::fs::metadata(b)) {
        use std::os::unix::fs::MetadataExt;
        return a.dev() == b.dev() && a.ino() == b.ino();
    }
    match (std::fs::canonicalize(a), std::fs::canonicalize(b)) {
        (Ok(a), Ok(b)) => a == b,
        _ => false,
    }
}

/// An output MCAP being written to its temporary file.
pub struct OutputWriter {
    target: TempOutput,
    backend: Backend,
    schema_ids: IdAllocator,
    channel_ids: IdAllocator,
}

enum Backend {
    /// Every record written anew by the `mcap` crate.
    Rewrite(Box<mcap::Writer<BufWriter<WritebackFile>>>),
    /// Input chunks copied as they are; the rest written by us.
    PassThrough(Box<PassThroughWriter<BufWriter<WritebackFile>>>),
}

/// What [`OutputWriter::copy`] copied, for the counts.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Copied {
    /// A chunk holding this many messages.
    Messages(u64),
    Metadata,
    Attachment,
}

/// Buffer between the writer and the file.
const FILE_BUFFER_BYTES: usize = 1 << 20;

/// The output's direct writes (`direct.rs`), bytes: a few chunks' worth,
/// so that each is one large request to the disk.
const DIRECT_BLOCK_BYTES: usize = 8 << 20;

impl OutputWriter {
    /// Create the temporary output beside `final_path` and register every input
    /// schema and channel under its own id; every record will be written anew.
    pub fn create(
        final_path: &Path,
        options: &OutputOptions,
        catalog: &Catalog,
    ) -> Result<Self, OutputError> {
        Self::create_as(final_path, options, catalog, false)
    }

    /// [`Self::create`] for a pass-through output: input chunks are then
    /// given to [`Self::copy`], and only our messages (and input messages
    /// written anew) are chunked here.
    pub fn create_pass_through(
        final_path: &Path,
        options: &OutputOptions,
        catalog: &Catalog,
    ) -> Result<Self, OutputError> {
        Self::create_as(final_path, options, catalog, true)
    }

    fn create_as(
        final_path: &Path,
        options: &OutputOptions,
        catalog: &Catalog,
        pass_through: bool,
    ) -> Result<Self, OutputError> {
        let (target, file) = TempOutput::create(final_path, options.force)?;
        let file = BufWriter::with_capacity(
            FILE_BUFFER_BYTES,
            WritebackFile::direct(file, writeback::WRITEBACK_BYTES, DIRECT_BLOCK_BYTES),
        );
        let backend = if pass_through {
            let header = mcap::records::Header {
                profile: options.profile.clone(),
                library: library_name(),
            };
            let compression = chunk::ChunkCompression {
                kind: options.compression,
                level: match (options.compression, options.compression_level) {
                    (OutputCompression::Zstd, 0) => OWN_CHUNKS_ZSTD_LEVEL,
                    (_, level) => level,
                },
            };
            PassThroughWriter::new(file, &header, compression, options.chunk_size_bytes)
                .map(|writer| Backend::PassThrough(Box::new(writer)))
                .map_err(|source| OutputError::WriteIo {
                    path: final_path.to_path_buf(),
                    source,
                })?
        } else {
            write_options(options)
                .create(file)
                .map(|writer| Backend::Rewrite(Box::new(writer)))
                .map_err(|source| OutputError::Write {
                    path: final_path.to_path_buf(),
                    source,
                })?
        };
        let mut output = Self {
            target,
            backend,
            schema_ids: IdAllocator::new(catalog.used_schema_ids(), 1),
            channel_ids: IdAllocator::new(catalog.used_channel_ids(), 0),
        };
        output.register_input(catalog)?;
        Ok(output)
    }

    fn register_input(&mut self, catalog: &Catalog) -> Result<(), OutputError> {
        for schema in catalog.schemas.values() {
            self.add_schema(schema.id, &schema.name, &schema.encoding, &schema.data)?;
        }
        for channel in catalog.channels.values() {
            let schema_id = channel.schema.as_ref().map_or(0, |s| s.id);
            self.add_channel(
                channel.id,
                schema_id,
                &channel.topic,
                &channel.message_encoding,
                &channel.metadata,
            )?;
        }
        Ok(())
    }

    fn write_err(&self, source: mcap::McapError) -> OutputError {
        match source {
            // The I/O error itself says what happened (a full disk...);
            // the mcap crate's wrapper only says that one did.
            mcap::McapError::Io(io) => self.io_err(io),
            source => OutputError::Write {
                path: self.target.final_path().to_path_buf(),
                source,
            },
        }
    }

    fn io_err(&self, source: std::io::Error) -> OutputError {
        OutputError::WriteIo {
            path: self.target.final_path().to_path_buf(),
            source,
        }
    }

    fn add_schema(
        &mut self,
        id: u16,
        name: &str,
        encoding: &str,
        data: &[u8],
    ) -> Result<(), OutputError> {
        match &mut self.backend {
            Backend::Rewrite(writer) => writer
                .add_schema_with_id(id, name, encoding, data)
                .map(|_| ())
                .map_err(|e| self.write_err(e)),
            Backend::PassThrough(writer) => {
                let header = mcap::records::SchemaHeader {
                    id,
                    name: name.into(),
                    encoding: encoding.into(),
                };
                writer.add_schema(header, data).map_err(|e| self.io_err(e))
            }
        }
    }

    fn add_channel(
        &mut self,
        id: u16,
        schema_id: u16,
        topic: &str,
        message_encoding: &str,
        metadata: &BTreeMap<String, String>,
    ) -> Result<(), OutputError> {
        match &mut self.backend {
            Backend::Rewrite(writer) => writer
                .add_channel_with_id(id, schema_id, topic, message_encoding, metadata)
                .map(|_| ())
                .map_err(|e| self.write_err(e)),
            Backend::PassThrough(writer) => {
                let channel = mcap::records::Channel {
                    id,
                    schema_id,
                    topic: topic.into(),
                    message_encoding: message_encoding.into(),
                    metadata: metadata.clone(),
                };
                writer.add_channel(channel).map_err(|e| self.io_err(e))
            }
        }
    }

    /// Add one of our own channels (and its schema) under fresh ids.
    pub fn add_own_channel(&mut self, spec: &OwnChannelSpec) -> Result<u16, OutputError> {
        let no_id = |what| OutputError::NoFreeId {
            path: self.target.final_path().to_path_buf(),
            what,
        };
        let schema_id = self.schema_ids.next().ok_or_else(|| no_id("schema"))?;
        let channel_id = self.channel_ids.next().ok_or_else(|| no_id("channel"))?;
        self.add_schema(
            schema_id,
            &spec.schema_name,
            &spec.schema_encoding,
            &spec.schema_data,
        )?;
        self.add_channel(
            channel_id,
            schema_id,
            &spec.topic,
            &spec.message_encoding,
            &BTreeMap::new(),
        )?;
        Ok(channel_id)
    }

    fn write_message(&mut self, header: &MessageHeader, data: &[u8]) -> Result<(), OutputError> {
        match &mut self.backend {
            Backend::Rewrite(writer) => writer
                .write_to_known_channel(header, data)
                .map_err(|e| self.write_err(e)),
            Backend::PassThrough(writer) => writer
                .write_message(header, data)
                .map_err(|e| self.io_err(e)),
        }
    }

    /// Copy one input message unchanged.
    pub fn write_input_message(&mut self, message: &InputMessage) -> Result<(), OutputError> {
        let header = MessageHeader {
            channel_id: message.channel_id,
            sequence: message.sequence,
            log_time: message.log_time_ns,
            publish_time: message.publish_time_ns,
        };
        self.write_message(&header, &message.data)
    }

    /// Write one message on one of our channels.
    pub fn write_own_message(
        &mut self,
        channel_id: u16,
        sequence: u32,
        log_time_ns: u64,
        data: &[u8],
    ) -> Result<(), OutputError> {
        let header = MessageHeader {
            channel_id,
            sequence,
            log_time: log_time_ns,
            publish_time: log_time_ns,
        };
        self.write_message(&header, data)
    }

    /// Copy an input record byte for byte (pass-through outputs only).
    pub fn copy(&mut self, record: &CopiedRecord) -> Result<Copied, OutputError> {
        let Backend::PassThrough(writer) = &mut self.backend else {
            return Err(OutputError::CopyNeedsPassThrough {
                path: self.target.final_path().to_path_buf(),
            });
        };
        let copied = match record {
            CopiedRecord::Chunk(chunk) => writer
                .copy_chunk(chunk)
                .map(|()| Copied::Messages(chunk.message_counts.values().sum())),
            CopiedRecord::Side(side) => writer.copy_side_record(side).map(|kind| match kind {
                SideKind::Metadata => Copied::Metadata,
                SideKind::Attachment => Copied::Attachment,
            }),
        };
        copied.map_err(|e| self.io_err(e))
    }

    pub fn write_metadata(
        &mut self,
        metadata: &mcap::records::Metadata,
    ) -> Result<(), OutputError> {
        match &mut self.backend {
            Backend::Rewrite(writer) => writer
                .write_metadata(metadata)
                .map_err(|e| self.write_err(e)),
            Backend::PassThrough(writer) => {
                writer.write_metadata(metadata).map_err(|e| self.io_err(e))
            }
        }
    }

    pub fn write_attachment(&mut self, attachment: &InputAttachment) -> Result<(), OutputError> {
        match &mut self.backend {
            Backend::Rewrite(writer) => {
                let attachment = mcap::Attachment {
                    log_time: attachment.log_time_ns,
                    create_time: attachment.create_time_ns,
                    name: attachment.name.clone(),
                    media_type: attachment.media_type.clone(),
                    data: std::borrow::Cow::Borrowed(&attachment.data),
                };
                writer.attach(&attachment).map_err(|e| self.write_err(e))
            }
            Backend::PassThrough(writer) => writer
                .write_attachment(attachment)
                .map_err(|e| self.io_err(e)),
        }
    }

    /// Finish the file (summary, footer), flush it to disk and move it to its
    /// final name. Returns the final size in bytes.
    pub fn finish(self) -> Result<u64, OutputError> {
        let path = self.target.final_path().to_path_buf();
        let buffered = match self.backend {
            Backend::Rewrite(mut writer) => {
                writer.finish().map_err(|source| OutputError::Write {
                    path: path.clone(),
                    source,
                })?;
                writer.into_inner()
            }
            Backend::PassThrough(writer) => {
                writer.finish().map_err(|source| OutputError::WriteIo {
                    path: path.clone(),
                    source,
                })?
            }
        };
        let file = buffered.into_inner().map_err(|e| OutputError::Finish {
            path,
            source: e.into_error(),
        })?;
        let file = file.into_file().map_err(|source| OutputError::Finish {
            path: self.target.final_path().to_path_buf(),
            source,
        })?;
        self.target.persist(file)
    }
}

fn library_name() -> String {
    format!("looming/{}", env!("CARGO_PKG_VERSION"))
}

fn write_options(options: &OutputOptions) -> mcap::WriteOptions {
    let compression = match options.compression {
        OutputCompression::Zstd => Some(mcap::Compression::Zstd),
        OutputCompression::Lz4 => Some(mcap::Compression::Lz4),
        OutputCompression::None => None,
    };
    mcap::WriteOptions::new()
        .compression(compression)
        .chunk_size(Some(options.chunk_size_bytes))
        .profile(options.profile.as_str())
        .compression_level(options.compression_level)
        .library(library_name())
        // Single-threaded zstd: the writer already runs on its own pipeline
        // thread, and this keeps the bytes identical on any machine.
        .compression_threads(0)
}

/// One of our own output channels.
#[derive(Debug, Clone)]
pub struct OwnChannelSpec {
    pub topic: String,
    pub schema_name: String,
    pub schema_encoding: String,
    pub schema_data: Vec<u8>,
    pub message_encoding: String,
}

impl OwnChannelSpec {
    /// A ROS 2 (CDR) channel of `package/msg/type_name` with its definition.
    pub fn ros2(topic: &str, package: &str, type_name: &str, definition: String) -> Self {
        let dialect = crate::ros::schemas::RosDialect::Ros2;
        Self {
            topic: topic.into(),
            schema_name: dialect.schema_name(package, type_name),
            schema_encoding: dialect.schema_encoding().into(),
            schema_data: definition.into_bytes(),
            message_encoding: dialect.message_encoding().into(),
        }
    }

    /// A JSON channel with its JSON Schema.
    pub fn json(topic: &str, schema_name: &str, schema: &str) -> Self {
        Self {
            topic: topic.into(),
            schema_name: schema_name.into(),
            schema_encoding: "jsonschema".into(),
            schema_data: schema.as_bytes().to_vec(),
            message_encoding: "json".into(),
        }
    }
}
