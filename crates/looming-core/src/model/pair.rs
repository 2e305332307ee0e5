//! Two consecutive scans and the motion between them: what the pairing stage
//! hands the looming engine.

use std::sync::Arc;

use super::motion::PairMotion;
use super::scan::Scan;

/// Two consecutive scans and the ego motion between them.
#[derive(Debug, Clone)]
pub struct ScanPair {
    pub previous: Arc<Scan>,
    pub current: Arc<Scan>,
    pub motion: PairMotion,
    /// `current.stamp_ns - previous.stamp_ns`, seconds; always > 0.
    pub dt_s: f64,
    pub previous_log_time_ns: u64,
    pub current_log_time_ns: u64,
    /// 0-based sequence number of emitted pairs.
    pub index: u64,
}
