//! Writing a file atomically: into a temporary file beside the destination,
//! renamed onto it only when complete, so a failed run never leaves a
//! half-written file under the requested name.
//!
//! [`AtomicFile`] does this for any file (logs, events files, renders);
//! [`TempOutput`] is the MCAP writer's use of it, with the writer's errors.

use std::fs::File;
use std::io::Write;
use std::path::{Path, PathBuf};

use tempfile::{NamedTempFile, TempPath};

use super::OutputError;

/// A new temporary file beside `path` (its directory created if need be),
/// named after it (`.NAME.XXXXXX.tmp`): what every output of the tool
/// (logs, events files, renders) is written into before it is renamed
/// onto `path`.
pub(crate) fn beside(path: &Path) -> std::io::Result<NamedTempFile> {
    let (dir, prefix) = temp_dir_and_prefix(path);
    std::fs::create_dir_all(&dir)?;
    let mut builder = tempfile::Builder::new();
    builder.prefix(&prefix).suffix(TEMP_SUFFIX);
    // An ordinary file once renamed (temporary files are private, 0600, by
    // default; the umask still applies).
    #[cfg(unix)]
    {
        use std::os::unix::fs::PermissionsExt;
        builder.permissions(std::fs::Permissions::from_mode(0o644));
    }
    builder.tempfile_in(&dir)
}

/// Ends the name of every temporary file [`beside`] makes.
const TEMP_SUFFIX: &str = ".tmp";

/// The folder of the temporary files for `path` and how their names start.
fn temp_dir_and_prefix(path: &Path) -> (PathBuf, String) {
    let dir = match path.parent() {
        Some(parent) if !parent.as_os_str().is_empty() => parent.to_path_buf(),
        _ => PathBuf::from("."),
    };
    let file_name = path
        .file_name()
        .map(|n| n.to_string_lossy().into_owned())
        .unwrap_or_else(|| "output".into());
    (dir, format!(".{file_name}."))
}

/// Remove the temporary files `beside` left for `path` by a run that was
/// killed before it could clean up; the number removed. Only a caller that
/// knows no other process is writing `path` may call this.
pub fn remove_stale_temp_files(path: &Path) -> std::io::Result<usize> {
    let (dir, prefix) = temp_dir_and_prefix(path);
    let mut removed = 0;
    let Ok(entries) = std::fs::read_dir(&dir) else {
        return Ok(0);
    };
    for entry in entries {
        let entry = entry?;
        let entry_name = entry.file_name().to_string_lossy().into_owned();
        if entry_name.starts_with(&prefix) && entry_name.ends_with(TEMP_SUFFIX) {
            std::fs::remove_file(entry.path())?;
            removed += 1;
        }
    }
    Ok(removed)
}

/// A file being written under a temporary name beside its destination.
/// [`commit`](Self::commit) syncs it and renames it onto the destination;
/// dropped uncommitted (an error on the way), the temporary file is removed
/// and the destination is left as it was.
pub struct AtomicFile {
    file: File,
    target: AtomicTarget,
}

impl AtomicFile {
    /// Create the temporary file beside `final_path` (and its directory).
    pub fn create(final_path: &Path) -> std::io::Result<Self> {
        let (file, temp) = beside(final_path)?.into_parts();
        Ok(Self {
            file,
            target: AtomicTarget {
                final_path: final_path.to_path_buf(),
                temp,
            },
        })
    }

    /// Where the file goes on commit.
    pub fn final_path(&self) -> &Path {
        &self.target.final_path
    }

    /// Split off the open file, for a writer that takes ownership of it; the
    /// [`AtomicTarget`] commits it once the writer hands it back.
    pub fn into_parts(self) -> (File, AtomicTarget) {
        (self.file, self.target)
    }

    /// Sync the file to disk and rename it onto the destination, replacing
    /// any file there. Returns its size in bytes.
    pub fn commit(self) -> std::io::Result<u64> {
        self.target.commit(self.file)
    }

    /// As [`commit`](Self::commit), but fails with
    /// [`std::io::ErrorKind::AlreadyExists`] (the temporary file removed) if
    /// the destination exists by then.
    pub fn commit_no_clobber(self) -> std::io::Result<u64> {
        self.target.commit_no_clobber(self.file)
    }
}

impl Write for AtomicFile {
    fn write(&mut self, buf: &[u8]) -> std::io::Result<usize> {
        self.file.write(buf)
    }

    fn flush(&mut self) -> std::io::Result<()> {
        self.file.flush()
    }
}

/// The destination and temporary path of an [`AtomicFile`] whose open file
/// is held elsewhere (inside a writer) until commit. Dropped uncommitted, the
/// temporary file is removed.
pub struct AtomicTarget {
    final_path: PathBuf,
    temp: TempPath,
}

impl AtomicTarget {
    /// Where the file goes on commit.
    pub fn final_path(&self) -> &Path {
        &self.final_path
    }

    /// Sync `file` (the complete temporary file) to disk and rename it onto
    /// the destination, replacing any file there. Returns its size in bytes.
    pub fn commit(self, file: File) -> std::io::Result<u64> {
        let size = sync_and_close(file)?;
        self.temp.persist(&self.final_path).map_err(|e| e.error)?;
        Ok(size)
    }

    /// As [`commit`](Self::commit), but fails with
    /// [`std::io::ErrorKind::AlreadyExists`] (the temporary file removed) if
    /// the destination exists by then.
    pub fn commit_no_clobber(self, file: File) -> std::io::Result<u64> {
        let size = sync_and_close(file)?;
        self.temp
            .persist_noclobber(&self.final_path)
            .map_err(|e| e.error)?;
        Ok(size)
    }
}

/// Flush `file` to disk and close it; its size in bytes.
fn sync_and_close(file: File) -> std::io::Result<u64> {
    file.sync_all()?;
    let size = file.metadata()?.len();
    drop(file);
    Ok(size)
}

/// Where the MCAP output goes once complete, and the temporary file until
/// then.
pub(super) struct TempOutput {
    target: AtomicTarget,
    force: bool,
}

impl TempOutput {
    /// Create the temporary file beside `final_path` (and its directory).
    pub(super) fn create(final_path: &Path, force: bool) -> Result<(Self, File), OutputError> {
        let (file, target) = AtomicFile::create(final_path)
            .map_err(|source| OutputError::Create {
                path: final_path.to_path_buf(),
                source,
            })?
            .into_parts();
        Ok((Self { target, force }, file))
    }

    pub(super) fn final_path(&self) -> &Path {
        self.target.final_path()
    }

    /// Flush `file` (the complete output) to disk and move it to its final
    /// name; without `force` an output that appeared meanwhile is not
    /// replaced. Returns its size in bytes.
    pub(super) fn persist(self, file: File) -> Result<u64, OutputError> {
        let final_path = self.target.final_path().to_path_buf();
        let committed = if self.force {
            self.target.commit(file)
        } else {
            self.target.commit_no_clobber(file)
        };
        committed.map_err(|source| {
            if !self.force && source.kind() == std::io::ErrorKind::AlreadyExists {
                OutputError::Exists { path: final_path }
            } else {
                OutputError::Finish {
                    path: final_path,
                    source,
                }
            }
        })
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    /// The names in `dir`, sorted.
    fn names_in(dir: &Path) -> Vec<String> {
        let mut names: Vec<String> = std::fs::read_dir(dir)
            .unwrap()
            .map(|entry| entry.unwrap().file_name().to_string_lossy().into_owned())
            .collect();
        names.sort();
        names
    }

    /// An uncommitted file for `target` holding `bytes`.
    fn written(target: &Path, bytes: &[u8]) -> AtomicFile {
        let mut file = AtomicFile::create(target).unwrap();
        file.write_all(bytes).unwrap();
        file
    }

    #[test]
    fn stale_temporary_files_of_a_killed_run_are_removed_and_nothing_else() {
        let dir = tempfile::tempdir().unwrap();
        let target = dir.path().join("log.mcap");
        // What a killed run leaves: its temporary file, never cleaned up.
        let (_, stale) = beside(&target).unwrap().keep().unwrap();
        std::fs::write(dir.path().join("log.mcap.batch.json"), b"{}").unwrap();
        let (_, other) = beside(&dir.path().join("other.mcap"))
            .unwrap()
            .keep()
            .unwrap();
        assert_eq!(remove_stale_temp_files(&target).unwrap(), 1);
        assert!(!stale.exists());
        assert!(other.exists(), "another file's temporary file stays");
        assert!(dir.path().join("log.mcap.batch.json").exists());
    }

    #[test]
    fn a_dropped_uncommitted_file_leaves_no_temporary_file_and_no_target() {
        let dir = tempfile::tempdir().unwrap();
        let target = dir.path().join("out.json");
        let file = written(&target, b"half");
        assert_eq!(names_in(dir.path()).len(), 1, "the temporary file exists");
        drop(file);
        assert_eq!(names_in(dir.path()), Vec::<String>::new());
    }

    #[test]
    fn a_dropped_uncommitted_file_leaves_an_existing_target_as_it_was() {
        let dir = tempfile::tempdir().unwrap();
        let target = dir.path().join("out.json");
        std::fs::write(&target, b"old").unwrap();
        let file = written(&target, b"new");
        drop(file);
        assert_eq!(names_in(dir.path()), vec!["out.json".to_string()]);
        assert_eq!(std::fs::read(&target).unwrap(), b"old");
    }

    #[test]
    fn a_committed_file_replaces_the_target() {
        let dir = tempfile::tempdir().unwrap();
        let target = dir.path().join("sub").join("out.png");
        let file = written(&target, b"first");
        assert_eq!(file.final_path(), target);
        assert_eq!(file.commit().unwrap(), 5);
        let file = written(&target, b"second");
        assert_eq!(file.commit().unwrap(), 6);
        assert_eq!(std::fs::read(&target).unwrap(), b"second");
        assert_eq!(
            names_in(&dir.path().join("sub")),
            vec!["out.png".to_string()]
        );
    }

    #[test]
    fn no_clobber_keeps_an_existing_target_and_removes_the_temporary_file() {
        let dir = tempfile::tempdir().unwrap();
        let target = dir.path().join("out.png");
        let file = written(&target, b"new");
        std::fs::write(&target, b"old").unwrap();
        let err = file.commit_no_clobber().unwrap_err();
        assert_eq!(err.kind(), std::io::ErrorKind::AlreadyExists);
        assert_eq!(std::fs::read(&target).unwrap(), b"old");
        assert_eq!(names_in(dir.path()), vec!["out.png".to_string()]);
        let file = written(&target, b"new");
        std::fs::remove_file(&target).unwrap();
        file.commit_no_clobber().unwrap();
        assert_eq!(std::fs::read(&target).unwrap(), b"new");
    }

    #[test]
    fn a_split_file_is_committed_through_its_target() {
        let dir = tempfile::tempdir().unwrap();
        let target = dir.path().join("out.mcap");
        let (mut file, pending) = AtomicFile::create(&target).unwrap().into_parts();
        file.write_all(b"mcap").unwrap();
        assert_eq!(pending.final_path(), target);
        assert_eq!(pending.commit(file).unwrap(), 4);
        assert_eq!(std::fs::read(&target).unwrap(), b"mcap");
        assert_eq!(names_in(dir.path()), vec!["out.mcap".to_string()]);
    }
}
