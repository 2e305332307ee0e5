//! `looming quality`: the quality figures of an annotated log, per scan and in
//! total, with diagnoses (`docs/quality.md`). Reads the `quality` object of
//! every `/looming/pairs` message (written by `process`, see
//! [`crate::quality`]) and counts `/looming/events`; memory is bounded by the
//! per-scan lines and fixed-size histograms.
//!
//! The command runs in four steps, one file each:
//! - `read`: the log's `/looming/pairs` and `/looming/events` messages;
//! - `totals`: sums the pairs' figures into the report;
//! - `diagnose`: the findings drawn from the totals;
//! - `text`: the report as text (`--json` prints [`QualityReport`] itself).
//!
//! `report` holds the report's types (its JSON schema).

mod diagnose;
mod read;
mod report;
mod text;
mod totals;

#[cfg(test)]
mod tests;

use crate::input::InputError;

pub use self::read::{read_quality, read_sensor_qualities};
pub use self::report::{
    Diagnosis, GroundSides, QualityReport, QualityTotals, RangeNoise, RangeOffsets, ScanLine,
};

/// A ground half reads "approaching" or "receding" beyond this, 1/s.
pub(crate) const GROUND_SIDE_THRESHOLD_PER_S: f64 = 0.02;
/// Fewest trusted static ground cells a half needs to be judged in a pair.
pub(crate) const MIN_SIDE_CELLS: u64 = 10;
/// A ground pattern is consistent when it holds in at least this share of the
/// pairs where both halves can be judged (and in at least two pairs).
pub(crate) const CONSISTENT_SHARE: f64 = 0.5;
/// Above this share of the trusted ground flagged moving, the ego motion is wrong.
pub(crate) const GROUND_MOVING_LIMIT: f64 = 0.05;
/// Below this trusted fraction the log is not to be trusted.
pub const MIN_TRUSTED_FRACTION: f64 = 0.5;

#[derive(Debug, thiserror::Error)]
pub enum QualityError {
    #[error(transparent)]
    Input(#[from] InputError),
    #[error("{path}: no /looming/pairs channel: not written by `looming process` (run it first)")]
    NotProcessed { path: String },
    #[error("{path}: /looming/pairs message at log time {log_time_ns}: {reason}")]
    BadRecord {
        path: String,
        log_time_ns: u64,
        reason: String,
    },
}
