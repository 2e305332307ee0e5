//! How scans are paired: the policies of [`super::ScanPairer`] and their
//! defaults.

use nalgebra::Isometry3;

use super::{frames, stride};

/// Pairing policies.
#[derive(Debug, Clone, PartialEq, serde::Serialize)]
pub struct PairingConfig {
    /// Maximum dt, in nominal periods, for two scans to form a pair.
    pub max_gap_periods: f64,
    /// Maximum dt in seconds; overrides `max_gap_periods` when set.
    pub max_gap_s: Option<f64>,
    /// `motion_from_lidar` from the command line (LiDAR pose in the
    /// velocity/IMU frame); overrides `/tf_static` for both sources.
    #[serde(rename = "extrinsic", serialize_with = "frames::serialize_extrinsic")]
    pub cli_extrinsic: Option<Isometry3<f64>>,
    /// A velocity topic exists: pending pairs wait for its samples.
    #[serde(skip)]
    pub has_velocity_source: bool,
    /// An IMU topic exists: pending pairs wait for its samples.
    #[serde(skip)]
    pub has_imu_source: bool,
    /// How far motion is held beyond the first/last sample, seconds.
    pub motion_hold_s: f64,
    /// The sensor's frame (`--sensor-frame`), for clouds published in
    /// another frame (`origin`).
    #[serde(skip_serializing_if = "Option::is_none")]
    pub sensor_frame: Option<String>,
    /// Shortest time a pair spans, seconds: a faster sensor's scan is paired
    /// with the scan at least this long before it ([`stride`]).
    pub min_baseline_s: f64,
}

impl Default for PairingConfig {
    fn default() -> Self {
        Self {
            max_gap_periods: 3.0,
            max_gap_s: None,
            cli_extrinsic: None,
            has_velocity_source: false,
            has_imu_source: false,
            motion_hold_s: 0.2,
            sensor_frame: None,
            min_baseline_s: stride::DEFAULT_MIN_BASELINE_S,
        }
    }
}
