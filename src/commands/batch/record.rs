//! What a batch remembers of each log, beside its output
//! (`OUT_DIR/logs/<log>.batch.json`): the input's fingerprint, the
//! configuration's, and the log's entry in the fleet table with its near
//! misses. A log whose record matches its input and the configuration is
//! not run again.

use std::io::{Read, Seek, SeekFrom};
use std::path::{Path, PathBuf};
use std::time::UNIX_EPOCH;

use serde::{Deserialize, Serialize};

use crate::events::NearMissEvent;
use crate::output::AtomicFile;

/// Bytes read at each end of an input for its content fingerprint: enough
/// to tell logs apart (headers, summaries, footers differ) without reading
/// gigabytes.
const FINGERPRINT_END_BYTES: u64 = 64 << 10;

/// How an input is recognised without reading it whole.
#[derive(Debug, Clone, PartialEq, Eq, Serialize, Deserialize)]
pub struct InputFingerprint {
    pub size_bytes: u64,
    pub modified_ns: u128,
    /// CRC-32 of the first and last `FINGERPRINT_END_BYTES` bytes.
    pub ends_crc32: u32,
}

impl InputFingerprint {
    pub fn of(path: &Path) -> std::io::Result<Self> {
        let mut file = std::fs::File::open(path)?;
        let metadata = file.metadata()?;
        let size_bytes = metadata.len();
        let modified_ns = metadata
            .modified()?
            .duration_since(UNIX_EPOCH)
            .map_or(0, |d| d.as_nanos());
        let mut hasher = crc32fast::Hasher::new();
        let mut head = Vec::new();
        (&mut file)
            .take(FINGERPRINT_END_BYTES)
            .read_to_end(&mut head)?;
        hasher.update(&head);
        if size_bytes > 2 * FINGERPRINT_END_BYTES {
            file.seek(SeekFrom::End(-(FINGERPRINT_END_BYTES as i64)))?;
            let mut tail = Vec::new();
            file.take(FINGERPRINT_END_BYTES).read_to_end(&mut tail)?;
            hasher.update(&tail);
        }
        Ok(Self {
            size_bytes,
            modified_ns,
            ends_crc32: hasher.finalize(),
        })
    }
}

/// What happened to a log.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Serialize, Deserialize)]
#[serde(rename_all = "kebab-case")]
pub enum LogStatus {
    /// Annotated: its output is complete.
    Processed,
    /// Not processed, by policy (no LiDAR topic).
    Skipped,
    /// Could not be processed (unreadable, truncated past use, not MCAP...).
    Failed,
}

/// A log's line in `fleet.json`.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct FleetEntry {
    pub input: PathBuf,
    pub output: Option<PathBuf>,
    pub status: LogStatus,
    pub reason: Option<String>,
    pub scans: u64,
    pub pairs: u64,
    pub events: usize,
    pub bad_messages: u64,
    /// Wall time of the run that did the work, seconds.
    pub seconds: f64,
    /// The `looming quality` figures of the annotated log.
    pub quality: Option<FleetQuality>,
    /// The frame of its LiDAR clouds (what a viewer's 3D panel follows).
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub lidar_frame: Option<String>,
}

/// The quality figures of a log that say whether to trust it
/// (`docs/quality.md`).
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct FleetQuality {
    /// Share of the points the engine trusts (with several LiDARs, over all
    /// their points).
    pub trusted_fraction: Option<f64>,
    pub ground_median_abs_fused_per_s: Option<f64>,
    pub ground_p90_abs_fused_per_s: Option<f64>,
    pub ground_moving_fraction: Option<f64>,
    pub dominant_mask: Option<String>,
    /// The codes of `looming quality`'s diagnoses (`low_trust`, ...).
    pub diagnoses: Vec<String>,
    /// With several LiDARs, each sensor's (the other figures are the first
    /// sensor's); absent with one.
    #[serde(default, skip_serializing_if = "Vec::is_empty")]
    pub sensors: Vec<FleetSensorQuality>,
}

/// One sensor's trust on a log with several LiDARs.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct FleetSensorQuality {
    /// Its name in our topics (`/looming/<sensor>/...`).
    pub sensor: String,
    pub trusted_fraction: Option<f64>,
    pub diagnoses: Vec<String>,
}

/// The pictures of a near miss's peak pair, paths relative to `OUT_DIR`.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct EventPictures {
    pub event_id: u32,
    /// The range image of the fused looming.
    pub range_png: PathBuf,
    /// The cloud from above, coloured by threat, with the threat zones.
    pub top_png: PathBuf,
}

/// A log's strongest approach in the ego path over time (each pair's
/// `path_peak_looming_per_s`), for the report's plot.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct PeakSeries {
    /// Log time of the first pair, ns: where `time_s` starts.
    pub start_log_time_ns: u64,
    /// The event threshold, 1/s (`1 / --threat-ttc`'s event time).
    pub threshold_per_s: f64,
    /// Each pair's time after the first, seconds.
    pub time_s: Vec<f64>,
    /// Its looming, 1/s (`None`: nothing in the path approaching).
    pub looming_per_s: Vec<Option<f64>>,
}

/// The record kept beside a log's output.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct LogRecord {
    pub input: InputFingerprint,
    pub config_crc32: u32,
    pub entry: FleetEntry,
    pub near_misses: Vec<NearMissEvent>,
    /// The pictures of its near misses (the first [`super::pictures::MAX_PICTURED_EVENTS`]).
    #[serde(default)]
    pub pictures: Vec<EventPictures>,
    /// For a log with near misses, its path peak over time.
    #[serde(default)]
    pub peak_series: Option<PeakSeries>,
    /// With `--clips`: a clip per near miss, paths relative to `OUT_DIR`.
    #[serde(default)]
    pub clips: Vec<EventClip>,
}

/// A near miss's clip (`batch --clips`).
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct EventClip {
    pub event_id: u32,
    /// Relative to `OUT_DIR`.
    pub path: PathBuf,
}

impl LogRecord {
    /// The record at `path`, if there is a readable one.
    pub fn read(path: &Path) -> Option<Self> {
        serde_json::from_slice(&std::fs::read(path).ok()?).ok()
    }

    /// The record as it reads back from its JSON.
    pub fn read_back(self) -> Self {
        serde_json::to_vec(&self)
            .ok()
            .and_then(|bytes| serde_json::from_slice(&bytes).ok())
            .unwrap_or(self)
    }

    /// Written whole or not at all.
    pub fn write(&self, path: &Path) -> std::io::Result<()> {
        let mut file = AtomicFile::create(path)?;
        serde_json::to_writer_pretty(&mut file, self)?;
        file.commit()?;
        Ok(())
    }

    /// Still true of `input` under the configuration `config_crc32`, its
    /// output (when it has one) and its pictures (below `out_dir`) there.
    pub fn holds_for(&self, input: &InputFingerprint, config_crc32: u32, out_dir: &Path) -> bool {
        self.input == *input
            && self.config_crc32 == config_crc32
            && self
                .entry
                .output
                .as_ref()
                .is_none_or(|output| output.exists())
            && self
                .pictures
                .iter()
                .all(|p| out_dir.join(&p.range_png).exists() && out_dir.join(&p.top_png).exists())
            && self.clips.iter().all(|c| out_dir.join(&c.path).exists())
    }
}
