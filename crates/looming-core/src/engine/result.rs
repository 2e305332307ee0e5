//! What the engine reports for a pair: the per-cell and per-point fields
//! ([`PairLooming`]), what could be computed ([`Availability`]) and why a
//! cell is not to be trusted ([`mask`]).

use super::egomotion;
use super::grid::{ImageGeometry, RangeImage};
use super::threat::{ThreatLevel, ThreatSphere};

/// Why a cell's values are not to be trusted (bit flags).
pub mod mask {
    /// No return in the current scan.
    pub const EMPTY: u8 = 1;
    /// The previous scan has no surface along this ray (disocclusion, edge of view).
    pub const NO_PREVIOUS: u8 = 2;
    /// Next to an occlusion edge (a neighbour on another surface).
    pub const EDGE: u8 = 4;
    /// Surface seen at grazing incidence.
    pub const GRAZING: u8 = 8;
    /// The ego-motion prediction has no surface here (only with a velocity source).
    pub const NO_EGO: u8 = 16;
    /// The range changed faster than any plausible motion: the ray met another
    /// surface in the previous scan (parallax at a silhouette, occlusion).
    pub const OCCLUSION: u8 = 32;
}

/// What the engine could compute for a pair.
#[derive(Debug, Clone, Copy, PartialEq, Eq, serde::Serialize)]
pub struct Availability {
    /// A velocity source covered the pair: `L_ego`, `L_ray_ego`, `D`, moving,
    /// threat spheres are computed.
    pub ego_velocity: bool,
    /// An angular rate was used to de-rotate the previous scan.
    pub rotation_compensated: bool,
}

/// Wall time of the engine's stages for one pair, seconds (each stage uses
/// both cores where it can). For the speed work (docs/performance.md): the
/// run summary sums them per sensor.
#[derive(Debug, Clone, Copy, Default, PartialEq, serde::Serialize, serde::Deserialize)]
pub struct StageTimes {
    /// The pair's image geometry, the scans gridded, the lasers' offsets.
    pub range_images_s: f64,
    /// Plane fits of the scans not cached (`Surfaces::estimate`).
    pub plane_fits_s: f64,
    /// Cell times, ray coordinates and column times.
    pub cell_times_s: f64,
    /// The motion estimated from the scans (its renders included).
    pub motion_estimate_s: f64,
    /// The renders of the previous surface (rotated and ego-moved).
    pub renders_s: f64,
    /// Per-cell differences, masks, moving, fusion, `L_ego`, threat.
    pub cells_s: f64,
}

impl StageTimes {
    pub fn add(&mut self, other: &StageTimes) {
        self.range_images_s += other.range_images_s;
        self.plane_fits_s += other.plane_fits_s;
        self.cell_times_s += other.cell_times_s;
        self.motion_estimate_s += other.motion_estimate_s;
        self.renders_s += other.renders_s;
        self.cells_s += other.cells_s;
    }
}

/// Everything the engine computed for one pair, reported on the current scan.
#[derive(Debug, Clone)]
pub struct PairLooming {
    pub geometry: ImageGeometry,
    pub availability: Availability,
    /// The current scan gridded: cell -> point index and nearest range, and
    /// `image.point_cell`, point -> cell (`NO_POINT` if none).
    pub image: RangeImage,
    /// Per cell, 1/s (NaN where not computed).
    pub l_lidar: Vec<f32>,
    pub l_ray_ego: Vec<f32>,
    pub disagreement: Vec<f32>,
    /// Noise of `L_lidar` from the range-noise model, 1/s.
    pub sigma_per_s: Vec<f32>,
    /// 1 / (1 + (sigma / 0.05)^2): 1 = clean, 0.5 at sigma 0.05 1/s.
    pub confidence: Vec<f32>,
    /// `mask::*` bits; 0 = trusted.
    pub mask: Vec<u8>,
    /// Trusted cells whose |D| is significant (above `moving_sigmas` sigma and
    /// `moving_min_per_s`); those outside a moving patch are ambiguous.
    pub disagrees: Vec<bool>,
    pub moving: Vec<bool>,
    pub fused: Vec<f32>,
    /// Per cell: the noise (1 sigma) of `fused`, 1/s.
    pub fused_sigma_per_s: Vec<f32>,
    /// Per cell: the noise of `l_ray_ego`, 1/s: the prediction's model error
    /// and, where the motion was estimated, that estimate's uncertainty.
    pub ray_ego_sigma_per_s: Vec<f32>,
    pub threat: Vec<ThreatLevel>,
    /// Per cell: `|n . e|` of the current surface (1 where no plane was fitted).
    pub incidence_cos: Vec<f32>,
    /// Per cell: unit normal of the current surface, facing the sensor (zero
    /// where no plane was fitted).
    pub normal: Vec<[f32; 3]>,
    /// Per row (beam, lowest first): the range noise (1 sigma, metres) used
    /// for that beam's cells.
    pub range_noise_m_per_row: Vec<f32>,
    /// Per row: the laser's range offset estimated from the scan and taken
    /// out of its returns, metres (all zero where the scan shows none).
    pub range_bias_m_per_row: Vec<f32>,
    /// Time between the compared returns, s.
    pub dt_s: Vec<f32>,
    /// Per point: `L_ego`, 1/s (NaN without velocity).
    pub l_ego: Vec<f32>,
    /// Per point: threat level of its cell when the point is that cell's surface.
    pub point_threat: Vec<ThreatLevel>,
    /// Equal-looming spheres of the low, medium and high levels (LiDAR frame),
    /// from the velocity at the current stamp.
    pub spheres: Option<[ThreatSphere; 3]>,
    /// LiDAR velocity used for the spheres, m/s.
    pub velocity_mps: Option<[f64; 3]>,
    /// LiDAR angular velocity at the current stamp, rad/s.
    pub angular_velocity_radps: Option<[f64; 3]>,
    /// The motion estimated from the static world, where a source was missing.
    pub ego_estimate: Option<egomotion::EgoEstimate>,
    /// How long the engine's stages took on this pair.
    pub stage_times: StageTimes,
}
