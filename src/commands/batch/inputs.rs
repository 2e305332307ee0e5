//! Which logs a batch runs on: every `*.mcap` below a folder (recursively),
//! a single file, or a manifest (`.txt`, one path per line), each with the
//! path its output takes below `OUT_DIR/logs/`, in a deterministic order;
//! and the `--shard K/N` share of them.

use std::path::{Path, PathBuf};

/// One log of the batch.
#[derive(Debug, Clone, PartialEq, Eq, PartialOrd, Ord)]
pub struct BatchLog {
    /// Where its output goes, relative to `OUT_DIR/logs/`.
    pub relative: PathBuf,
    pub input: PathBuf,
}

/// Every log the inputs name, sorted by output path, duplicates dropped.
/// An error names the folder or manifest it came from.
pub fn discover(inputs: &[PathBuf]) -> Result<Vec<BatchLog>, (PathBuf, std::io::Error)> {
    let mut logs = Vec::new();
    for input in inputs {
        let named = |error| (input.clone(), error);
        if input.is_dir() {
            let mut found = Vec::new();
            mcap_files_below(input, &mut found).map_err(named)?;
            logs.extend(found.into_iter().map(|path| BatchLog {
                relative: path.strip_prefix(input).unwrap_or(&path).to_path_buf(),
                input: path,
            }));
        } else if input.extension().is_some_and(|e| e == "txt") {
            logs.extend(manifest_entries(input).map_err(named)?);
        } else {
            logs.push(single(input));
        }
    }
    logs.sort();
    logs.dedup_by(|a, b| a.relative == b.relative);
    Ok(logs)
}

/// A log named on its own: its output takes its file name.
fn single(path: &Path) -> BatchLog {
    BatchLog {
        relative: PathBuf::from(path.file_name().unwrap_or(path.as_os_str())),
        input: path.to_path_buf(),
    }
}

/// The paths of a manifest, relative ones taken from the manifest's folder.
fn manifest_entries(manifest: &Path) -> std::io::Result<Vec<BatchLog>> {
    let base = manifest.parent().unwrap_or(Path::new("."));
    let text = std::fs::read_to_string(manifest)?;
    Ok(text
        .lines()
        .map(str::trim)
        .filter(|line| !line.is_empty() && !line.starts_with('#'))
        .map(|line| single(&base.join(line)))
        .collect())
}

fn mcap_files_below(dir: &Path, found: &mut Vec<PathBuf>) -> std::io::Result<()> {
    for entry in std::fs::read_dir(dir)? {
        let path = entry?.path();
        if path.is_dir() {
            mcap_files_below(&path, found)?;
        } else if path.extension().is_some_and(|e| e == "mcap") {
            found.push(path);
        }
    }
    Ok(())
}

/// `--shard K/N`: shard K (0-based) of N.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub struct Shard {
    pub index: u32,
    pub count: u32,
}

impl Shard {
    /// The shard's logs: those whose output path hashes to it, so that a
    /// log's shard does not depend on which other logs exist.
    pub fn select(self, logs: Vec<BatchLog>) -> Vec<BatchLog> {
        logs.into_iter()
            .filter(|log| {
                let key = log.relative.to_string_lossy();
                crc32fast::hash(key.as_bytes()) % self.count == self.index
            })
            .collect()
    }
}
