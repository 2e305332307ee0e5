//! What the pairer did, for the run report.

use std::collections::BTreeMap;

use crate::model::{ScanLayout, SensorOrigin};

/// What the pairer did, for the run report.
#[derive(Debug, Clone, Default, PartialEq, serde::Serialize)]
pub struct PairingStats {
    pub scans_seen: u64,
    pub pairs_emitted: u64,
    /// New scan's stamp not after the previous one's; the scan was dropped.
    pub skipped_nonpositive_dt: u64,
    /// dt above the maximum gap; no pair, the new scan became the previous.
    pub skipped_gap: u64,
    /// Pairs emitted with `motion.velocity == None`.
    pub pairs_without_velocity: u64,
    /// Pairs emitted without IMU angular velocity (twist used, or none).
    pub pairs_without_imu: u64,
    /// Scans with zero valid points (still paired).
    pub empty_scans: u64,
    /// Motion samples stamped before data already consumed; ignored.
    pub late_samples: u64,
    /// Pairs emitted before every source had reached the current scan's end.
    pub pairs_motion_incomplete: u64,
    /// Samples dropped by the `MAX_BUFFERED_SAMPLES_PER_SOURCE` backstop.
    pub overflow_dropped_samples: u64,
    /// Backwards stamp jumps taken as clock resets (the new scan restarted pairing).
    pub clock_resets: u64,
    /// "velocity" / "imu" -> where the last used extrinsic came from, e.g.
    /// `tf_static (base_link from velodyne)`.
    pub extrinsic_source: BTreeMap<String, String>,
    /// Nominal scan period in use (set, or running median of accepted dts).
    pub nominal_period_s: Option<f64>,
    /// How the first scan's rings and times were obtained
    /// (`engine::layout::complete`).
    pub layout: Option<ScanLayout>,
    /// Scans per layout kind, `"<rings kind> / <times kind>"` (e.g.
    /// `laser_order / azimuth`): more than one entry when it varies.
    pub layout_kinds: BTreeMap<String, u64>,
    /// Scans whose ring field was dropped (values that are not ring numbers).
    pub ring_fields_dropped: u64,
    /// Where the sensor is in its clouds' frame and how that was found
    /// (`origin`), from the first scan with points (or from the scan that
    /// started placing it at every scan, `origin_track`).
    #[serde(skip_serializing_if = "Option::is_none")]
    pub sensor_origin: Option<SensorOrigin>,
    /// The sensor placed from its rings at every scan (it drives through
    /// its clouds' frame, `origin_track`): what that cost and gave.
    #[serde(skip_serializing_if = "Option::is_none")]
    pub sensor_track: Option<SensorTrackStats>,
}

/// The per-scan placements of a sensor that drives through its clouds'
/// frame (`origin_track`).
#[derive(Debug, Clone, Default, PartialEq, serde::Serialize)]
pub struct SensorTrackStats {
    /// Scans placed one by one (from the one that started it).
    pub scans: u64,
    /// Of those, placed by the full search (grid and simplex, about a
    /// second): the first, and those the local search left spread.
    pub full_searches: u64,
    /// Of those, still spread after it: placed where the search left them,
    /// their looming not to be trusted.
    pub failed: u64,
    /// Steps whose turn the sweeps' phase did not give (no per-point times,
    /// or a phase the course disagrees with): the axes kept their yaw.
    pub yaw_held: u64,
    /// The rings' spread about the placements, mean and largest, deg.
    pub ring_spread_deg_mean: f64,
    pub ring_spread_deg_max: f64,
    /// The time a placement by the local search took (its sample, the
    /// simplex from the prediction and the checks), mean and largest, ms.
    pub local_ms_per_scan_mean: f64,
    pub local_ms_per_scan_max: f64,
    /// The time a full search took, mean, ms.
    pub full_search_ms_mean: f64,
    /// Placements whose spread was measured (the mean's count).
    #[serde(skip)]
    pub(super) measured: u64,
}
