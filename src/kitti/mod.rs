//! KITTI raw import: a drive folder (Velodyne HDL-64E scans, OXTS GPS/IMU
//! packets, their timestamps and the IMU-to-Velodyne calibration) to a ROS 2
//! MCAP that `looming process` reads like any other log. `docs/kitti.md`.

pub mod calib;
pub mod import;
pub mod oxts;
pub mod timestamps;
pub mod velodyne;

use std::path::PathBuf;

pub use import::{ImportError, ImportOptions, ImportSummary, SweepDirection, import_kitti};

/// What can be wrong with a KITTI folder. Every error names the file, and the
/// line (1-based) when one line is at fault.
#[derive(Debug, thiserror::Error)]
pub enum KittiError {
    #[error("{path}: cannot read: {source}")]
    Io {
        path: PathBuf,
        source: std::io::Error,
    },
    #[error("{path}: missing: {what}")]
    Missing { path: PathBuf, what: String },
    #[error("{path}:{line}: {reason}")]
    Malformed {
        path: PathBuf,
        line: usize,
        reason: String,
    },
    #[error("{path}: {reason}")]
    Invalid { path: PathBuf, reason: String },
}
