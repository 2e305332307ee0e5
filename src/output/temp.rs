//! The output's temporary file: created beside the destination, renamed onto
//! it only when complete, so a failed run never leaves a half-written log
//! under the requested name. Both writers ([`super::OutputWriter`]'s rewrite
//! and pass-through backends) go through it.

use std::fs::File;
use std::path::{Path, PathBuf};

use tempfile::NamedTempFile;

use super::OutputError;

/// A new temporary file beside `path` (its directory created if need be),
/// named after it (`.NAME.XXXXXX.tmp`): what every output of the tool
/// (logs, events files, renders) is written into before it is renamed
/// onto `path`.
pub(crate) fn beside(path: &Path) -> std::io::Result<NamedTempFile> {
    let dir = match path.parent() {
        Some(parent) if !parent.as_os_str().is_empty() => parent.to_path_buf(),
        _ => PathBuf::from("."),
    };
    let file_name = path
        .file_name()
        .map(|n| n.to_string_lossy().into_owned())
        .unwrap_or_else(|| "output".into());
    std::fs::create_dir_all(&dir)?;
    let prefix = format!(".{file_name}.");
    let mut builder = tempfile::Builder::new();
    builder.prefix(&prefix).suffix(".tmp");
    // An ordinary file once renamed (temporary files are private, 0600, by
    // default; the umask still applies).
    #[cfg(unix)]
    {
        use std::os::unix::fs::PermissionsExt;
        builder.permissions(std::fs::Permissions::from_mode(0o644));
    }
    builder.tempfile_in(&dir)
}

/// Where the output goes once complete, and the temporary file until then.
pub(super) struct TempOutput {
    final_path: PathBuf,
    force: bool,
    temp: tempfile::TempPath,
}

impl TempOutput {
    /// Create the temporary file beside `final_path` (and its directory).
    pub(super) fn create(final_path: &Path, force: bool) -> Result<(Self, File), OutputError> {
        let create_err = |source| OutputError::Create {
            path: final_path.to_path_buf(),
            source,
        };
        let temp_file = beside(final_path).map_err(create_err)?;
        let (file, temp) = temp_file.into_parts();
        let output = Self {
            final_path: final_path.to_path_buf(),
            force,
            temp,
        };
        Ok((output, file))
    }

    pub(super) fn final_path(&self) -> &Path {
        &self.final_path
    }

    /// Flush `file` (the complete output) to disk and move it to its final
    /// name. Returns its size in bytes.
    pub(super) fn persist(self, file: File) -> Result<u64, OutputError> {
        let finish_err = |source| OutputError::Finish {
            path: self.final_path.clone(),
            source,
        };
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
