//! Two scans of one sensor and the motion between them: what the pairing
//! stage hands the looming engine.

use std::sync::Arc;

use super::motion::PairMotion;
use super::scan::Scan;

/// Two scans of one sensor and the ego motion between them: consecutive
/// scans, or for a sensor faster than the pairing's baseline the scan a
/// baseline before ([`crate::pairing::stride`]).
#[derive(Debug, Clone)]
pub struct ScanPair {
    pub previous: Arc<Scan>,
    pub current: Arc<Scan>,
    pub motion: PairMotion,
    /// `current.stamp_ns - previous.stamp_ns`, seconds; always > 0.
    pub dt_s: f64,
    /// Since the previous pair's current scan (the sensor's period), seconds:
    /// `dt_s` for consecutive scans, less where pairs span several periods.
    pub step_s: f64,
    pub previous_log_time_ns: u64,
    pub current_log_time_ns: u64,
    /// 0-based sequence number of emitted pairs.
    pub index: u64,
}
