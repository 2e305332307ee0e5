//! The report's types: one [`ScanLine`] per pair, the log's [`QualityTotals`]
//! and the [`Diagnosis`] list, gathered in [`QualityReport`] (serialised as
//! `looming quality --json`).

use std::collections::BTreeMap;

use serde::Serialize;

use crate::quality::MaskCounts;

/// One line per pair.
#[derive(Debug, Clone, Serialize)]
pub struct ScanLine {
    pub index: u64,
    pub log_time_ns: u64,
    pub stamp_ns: i64,
    pub speed_mps: Option<f64>,
    pub layout: String,
    /// `None` when the pair has no quality figures (no range image).
    pub trusted_fraction: Option<f64>,
    pub ground_cells: Option<u64>,
    pub ground_median_abs_fused_per_s: Option<f64>,
    pub ground_left_median_fused_per_s: Option<f64>,
    pub ground_right_median_fused_per_s: Option<f64>,
    pub ground_left_median_d_per_s: Option<f64>,
    pub ground_right_median_d_per_s: Option<f64>,
    pub median_abs_d_static_per_s: Option<f64>,
    pub moving_fraction: Option<f64>,
    pub threat_cells: Option<u64>,
    /// Looming of the strongest approach in the ego path, 1/s.
    pub path_peak_looming_per_s: Option<f64>,
    pub dominant_mask: Option<String>,
}

/// Min / median / max over rings, and every ring (lowest beam first).
#[derive(Debug, Clone, Serialize)]
pub struct RangeNoise {
    pub rings: usize,
    pub min_m: Option<f64>,
    pub median_m: Option<f64>,
    pub max_m: Option<f64>,
    /// Per ring, the median over pairs of the noise the engine used, metres.
    pub per_ring_m: Vec<f64>,
}

/// The per-laser range offsets the engine took out (`engine::bias`).
#[derive(Debug, Clone, Serialize)]
pub struct RangeOffsets {
    /// Rings with an offset reported.
    pub rings: usize,
    /// Root mean square over rings, metres; 0 when none was found.
    pub rms_m: Option<f64>,
    /// Largest |offset|, metres.
    pub max_abs_m: Option<f64>,
    /// Per ring, the median over pairs, metres.
    pub per_ring_m: Vec<f64>,
}

/// How one ground quantity (fused or D) reads on the two halves over the log.
#[derive(Debug, Clone, Default, Serialize)]
pub struct GroundSides {
    /// Median over pairs of the per-pair medians (not a pooled median), 1/s.
    pub left_median_per_s: Option<f64>,
    pub right_median_per_s: Option<f64>,
    /// Pairs where both halves have at least `MIN_SIDE_CELLS` trusted ground
    /// cells.
    pub pairs_judged: u64,
    /// Of those: left approaching and right receding (each beyond the
    /// threshold), the reverse, both approaching, both receding.
    pub left_approaching_right_receding: u64,
    pub left_receding_right_approaching: u64,
    pub both_approaching: u64,
    pub both_receding: u64,
}

/// The whole log.
#[derive(Debug, Clone, Serialize)]
pub struct QualityTotals {
    pub pairs: u64,
    pub pairs_with_quality: u64,
    pub points: u64,
    pub trusted_points: u64,
    /// Over all points of all pairs.
    pub trusted_fraction: Option<f64>,
    pub cells: u64,
    pub trusted_cells: u64,
    pub trusted_cell_fraction: Option<f64>,
    /// Occupied cells per mask bit, summed over pairs.
    pub masked_cells: MaskCounts,
    /// The same as fractions of the occupied cells.
    pub masked_cell_fractions: BTreeMap<String, f64>,
    pub dominant_mask: Option<String>,
    /// Pairs per layout.
    pub layouts: BTreeMap<String, u64>,
    pub range_noise: RangeNoise,
    pub range_offsets: RangeOffsets,
    pub ground_cells: u64,
    pub ground_trusted_static_cells: u64,
    /// Trusted ground cells flagged moving, and their share of the trusted
    /// ground cells (0 when all is right).
    pub ground_moving_cells: u64,
    pub ground_moving_fraction: Option<f64>,
    /// Median |fused| over the trusted static ground cells of all pairs,
    /// pooled (histogram bins 4.7 % wide), 1/s.
    pub ground_median_abs_fused_per_s: Option<f64>,
    /// 90th percentile of the same.
    pub ground_p90_abs_fused_per_s: Option<f64>,
    pub ground_fused: GroundSides,
    pub ground_d: GroundSides,
    /// Median sensor height above the ground over pairs, metres.
    pub ground_height_m: Option<f64>,
    pub ground_roll_deg: Option<f64>,
    pub ground_pitch_deg: Option<f64>,
    /// Median |L_lidar - L_ray_ego| over the trusted static cells of all pairs
    /// (pooled), 1/s; `None` without ego velocity.
    pub median_abs_d_static_per_s: Option<f64>,
    pub pairs_with_ego_velocity: u64,
    pub moving_cells: u64,
    /// Moving cells over trusted cells.
    pub moving_fraction: Option<f64>,
    pub threat_cells: u64,
    /// `/looming/events` messages.
    pub near_miss_events: u64,
}

/// A finding, with a stable code.
#[derive(Debug, Clone, Serialize)]
pub struct Diagnosis {
    /// `ground_split`, `ground_offset`, `ground_split_d`, `ground_offset_d`, `ground_moving`,
    /// `low_trust`, `range_offsets`, `no_ground`, `no_quality`.
    pub code: String,
    pub message: String,
}

/// `looming quality --json`: schema `schemas/looming.QualityReport.schema.json`.
#[derive(Debug, Clone, Serialize)]
pub struct QualityReport {
    pub tool: String,
    pub version: String,
    pub input: String,
    pub scans: Vec<ScanLine>,
    pub totals: QualityTotals,
    pub diagnoses: Vec<Diagnosis>,
    /// On a log with several LiDARs: the sensor this report is of (its name
    /// in our topics, `/looming/<sensor>/pairs`); absent with one LiDAR.
    #[serde(skip_serializing_if = "Option::is_none")]
    pub sensor: Option<String>,
    /// On a log with several LiDARs, in the report of the whole log: every
    /// sensor's report (the top-level figures are the first sensor's).
    #[serde(skip_serializing_if = "Vec::is_empty")]
    pub sensors: Vec<QualityReport>,
}
