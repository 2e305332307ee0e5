//! Last stage: the MCAP writer. Copies every input schema, channel (same ids),
//! message (same bytes, times and sequence), metadata record and attachment,
//! and adds our own channels under ids the input does not use.
//!
//! The output goes to a temporary file beside the destination and is renamed
//! only when complete, so a failed run never leaves a half-written log under
//! the requested name.

mod ids;
pub mod pairs;

use std::collections::BTreeMap;
use std::fs::File;
use std::io::BufWriter;
use std::path::{Path, PathBuf};

use mcap::records::MessageHeader;

use crate::input::{Catalog, InputAttachment, InputMessage};

pub use ids::IdAllocator;

/// Chunk compression of the output.
#[derive(Debug, Clone, Copy, PartialEq, Eq, serde::Serialize, clap::ValueEnum)]
#[serde(rename_all = "snake_case")]
pub enum OutputCompression {
    Zstd,
    Lz4,
    None,
}

#[derive(Debug, Clone, serde::Serialize)]
pub struct OutputOptions {
    pub compression: OutputCompression,
    /// Target uncompressed chunk size, bytes.
    pub chunk_size_bytes: u64,
    /// Replace an existing output file.
    pub force: bool,
    /// zstd / lz4 level; 0 = the library default (zstd 3).
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
    #[error("{path}: exists already (use --force to replace it)")]
    Exists { path: PathBuf },
    #[error("{path}: cannot create the output: {source}")]
    Create {
        path: PathBuf,
        source: std::io::Error,
    },
    #[error("{path}: writing failed: {source}")]
    Write {
        path: PathBuf,
        source: mcap::McapError,
    },
    #[error("{path}: finishing the output failed: {source}")]
    Finish {
        path: PathBuf,
        source: std::io::Error,
    },
    #[error("{path}: no free {what} id left for our own records")]
    NoFreeId { path: PathBuf, what: &'static str },
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

fn same_file(a: &Path, b: &Path) -> bool {
    match (std::fs::canonicalize(a), std::fs::canonicalize(b)) {
        (Ok(a), Ok(b)) => a == b,
        _ => false,
    }
}

/// An output MCAP being written to its temporary file.
pub struct OutputWriter {
    final_path: PathBuf,
    force: bool,
    temp: tempfile::TempPath,
    writer: mcap::Writer<BufWriter<File>>,
    schema_ids: IdAllocator,
    channel_ids: IdAllocator,
}

impl OutputWriter {
    /// Create the temporary output beside `final_path` and register every input
    /// schema and channel under its own id.
    pub fn create(
        final_path: &Path,
        options: &OutputOptions,
        catalog: &Catalog,
    ) -> Result<Self, OutputError> {
        let create_err = |source| OutputError::Create {
            path: final_path.to_path_buf(),
            source,
        };
        let dir = match final_path.parent() {
            Some(parent) if !parent.as_os_str().is_empty() => parent.to_path_buf(),
            _ => PathBuf::from("."),
        };
        let file_name = final_path
            .file_name()
            .map(|n| n.to_string_lossy().into_owned())
            .unwrap_or_else(|| "output".into());
        std::fs::create_dir_all(&dir).map_err(create_err)?;
        let temp_file = tempfile::Builder::new()
            .prefix(&format!(".{file_name}."))
            .suffix(".tmp")
            .tempfile_in(&dir)
            .map_err(create_err)?;
        let (file, temp) = temp_file.into_parts();
        let writer = write_options(options)
            .create(BufWriter::with_capacity(1 << 20, file))
            .map_err(|source| OutputError::Write {
                path: final_path.to_path_buf(),
                source,
            })?;
        let mut output = Self {
            final_path: final_path.to_path_buf(),
            force: options.force,
            temp,
            writer,
            schema_ids: IdAllocator::new(catalog.used_schema_ids(), 1),
            channel_ids: IdAllocator::new(catalog.used_channel_ids(), 0),
        };
        output.register_input(catalog)?;
        Ok(output)
    }

    fn register_input(&mut self, catalog: &Catalog) -> Result<(), OutputError> {
        for schema in catalog.schemas.values() {
            self.writer
                .add_schema_with_id(schema.id, &schema.name, &schema.encoding, &schema.data)
                .map_err(|e| self.write_err(e))?;
        }
        for channel in catalog.channels.values() {
            let schema_id = channel.schema.as_ref().map_or(0, |s| s.id);
            self.writer
                .add_channel_with_id(
                    channel.id,
                    schema_id,
                    &channel.topic,
                    &channel.message_encoding,
                    &channel.metadata,
                )
                .map_err(|e| self.write_err(e))?;
        }
        Ok(())
    }

    fn write_err(&self, source: mcap::McapError) -> OutputError {
        OutputError::Write {
            path: self.final_path.clone(),
            source,
        }
    }

    /// Add one of our own channels (and its schema) under fresh ids.
    pub fn add_own_channel(&mut self, spec: &OwnChannelSpec) -> Result<u16, OutputError> {
        let no_id = |what| OutputError::NoFreeId {
            path: self.final_path.clone(),
            what,
        };
        let schema_id = self.schema_ids.next().ok_or_else(|| no_id("schema"))?;
        let channel_id = self.channel_ids.next().ok_or_else(|| no_id("channel"))?;
        self.writer
            .add_schema_with_id(
                schema_id,
                &spec.schema_name,
                &spec.schema_encoding,
                &spec.schema_data,
            )
            .map_err(|e| self.write_err(e))?;
        self.writer
            .add_channel_with_id(
                channel_id,
                schema_id,
                &spec.topic,
                &spec.message_encoding,
                &BTreeMap::new(),
            )
            .map_err(|e| self.write_err(e))?;
        Ok(channel_id)
    }

    /// Copy one input message unchanged.
    pub fn write_input_message(&mut self, message: &InputMessage) -> Result<(), OutputError> {
        let header = MessageHeader {
            channel_id: message.channel_id,
            sequence: message.sequence,
            log_time: message.log_time_ns,
            publish_time: message.publish_time_ns,
        };
        self.writer
            .write_to_known_channel(&header, &message.data)
            .map_err(|e| self.write_err(e))
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
        self.writer
            .write_to_known_channel(&header, data)
            .map_err(|e| self.write_err(e))
    }

    pub fn write_metadata(
        &mut self,
        metadata: &mcap::records::Metadata,
    ) -> Result<(), OutputError> {
        self.writer
            .write_metadata(metadata)
            .map_err(|e| self.write_err(e))
    }

    pub fn write_attachment(&mut self, attachment: &InputAttachment) -> Result<(), OutputError> {
        let attachment = mcap::Attachment {
            log_time: attachment.log_time_ns,
            create_time: attachment.create_time_ns,
            name: attachment.name.clone(),
            media_type: attachment.media_type.clone(),
            data: std::borrow::Cow::Borrowed(&attachment.data),
        };
        self.writer
            .attach(&attachment)
            .map_err(|e| self.write_err(e))
    }

    /// Finish the file (summary, footer), flush it to disk and move it to its
    /// final name. Returns the final size in bytes.
    pub fn finish(mut self) -> Result<u64, OutputError> {
        self.writer.finish().map_err(|e| self.write_err(e))?;
        let finish_err = |source| OutputError::Finish {
            path: self.final_path.clone(),
            source,
        };
        let file = self
            .writer
            .into_inner()
            .into_inner()
            .map_err(|e| finish_err(e.into_error()))?;
        // Temporary files are created private (0600); the output is an
        // ordinary file.
        #[cfg(unix)]
        {
            use std::os::unix::fs::PermissionsExt;
            file.set_permissions(std::fs::Permissions::from_mode(0o644))
                .map_err(finish_err)?;
        }
        file.sync_all().map_err(finish_err)?;
        let size = file.metadata().map_err(finish_err)?.len();
        drop(file);
        if !self.force && self.final_path.exists() {
            return Err(OutputError::Exists {
                path: self.final_path,
            });
        }
        self.temp
            .persist(&self.final_path)
            .map_err(|e| OutputError::Finish {
                path: self.final_path.clone(),
                source: e.error,
            })?;
        Ok(size)
    }
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
        .library(format!("looming/{}", env!("CARGO_PKG_VERSION")))
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
        let dialect = crate::ros_schemas::RosDialect::Ros2;
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
