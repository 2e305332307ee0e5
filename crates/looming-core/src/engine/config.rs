//! The engine's settings ([`EngineConfig`]) and their defaults.

/// Engine settings.
#[derive(Debug, Clone, serde::Serialize, serde::Deserialize)]
pub struct EngineConfig {
    /// Columns of the range image [default: the most points any beam holds].
    pub columns: Option<usize>,
    /// Firings of a beam per range-image column where `columns` is unset:
    /// 1 gives every firing its own cell (the default, the finest image);
    /// 2 halves the columns and takes a quarter to two fifths less CPU (a
    /// 64 x 2048 drive, the KITTI braking log) for a noisier looming image:
    /// each cell keeps its nearest return, and the other takes the cell's
    /// values where it is the same surface.
    #[serde(default = "one_firing_per_column")]
    pub firings_per_column: usize,
    /// Range noise of the sensor (1 sigma), metres.
    pub range_noise_m: f64,
    /// Compensate the gyro rotation before differencing (METHOD.md); off only
    /// to measure what it buys.
    pub rotation_compensation: bool,
    /// Threat thresholds as times to contact, seconds: low, medium, high.
    pub threat_ttc_s: [f64; 3],
    /// A cell moves when |D| exceeds this many sigmas...
    pub moving_sigmas: f64,
    /// ...and this much, 1/s.
    pub moving_min_per_s: f64,
    /// Cells whose surface is seen more obliquely than this (|n . e|) are masked.
    pub grazing_cos: f64,
    /// Fastest plausible closing speed along a surface normal, m/s: a range
    /// change beyond it between two scans means the ray met another surface
    /// (occlusion or disocclusion), not motion.
    pub max_closing_speed_mps: f64,
    /// Where no source measured the velocity or the angular rate over a
    /// pair, estimate them from the static world (`engine::egomotion`).
    pub estimate_ego_motion: bool,
    /// Estimate each laser's range offset from the scans and take it out
    /// (`engine::bias`).
    pub correct_range_bias: bool,
}

impl Default for EngineConfig {
    fn default() -> Self {
        Self {
            columns: None,
            firings_per_column: 1,
            range_noise_m: 0.02,
            rotation_compensation: true,
            // Autey 2012; Sacchi & Sayed 2016; Hayward 1972.
            threat_ttc_s: [3.0, 1.5, 1.0],
            moving_sigmas: 4.0,
            moving_min_per_s: 0.15,
            grazing_cos: 0.15,
            max_closing_speed_mps: 30.0,
            estimate_ego_motion: true,
            correct_range_bias: true,
        }
    }
}

fn one_firing_per_column() -> usize {
    1
}
