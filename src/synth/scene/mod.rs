//! Scenario files: the scene (road, buildings, obstacles, moving actors), the
//! ego trajectory and the sensors, as JSON (serde, unknown fields refused,
//! everything optional has a default). The built-in scenarios are JSON files
//! embedded in the binary (`src/synth/scenarios/`), so they double as examples.
//!
//! The LiDAR's cloud layouts are in `layout.rs`, its imperfections in
//! `realism.rs`, the LiDARs beside it in `rig.rs`, the checks serde cannot
//! make in `validate.rs`.

mod layout;
mod realism;
mod rig;
mod validate;

use serde::{Deserialize, Serialize};

pub use layout::{CloudLayout, LAYOUT_NAMES, LaserOrder, RingField, RingFieldName};
pub use realism::Realism;
pub use rig::{ExtraLidar, PRESET_NAMES, ROOF_NAME};

/// A whole scenario.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct Scenario {
    pub name: String,
    #[serde(default)]
    pub description: String,
    /// Length of the drive, seconds.
    #[serde(default = "defaults::duration_s")]
    pub duration_s: f64,
    /// Height of the road plane (world z), metres.
    #[serde(default)]
    pub ground_height_m: f64,
    pub ego: EgoSpec,
    /// Buildings, walls, parked cars, poles: never move.
    #[serde(default)]
    pub static_objects: Vec<StaticObject>,
    /// Moving boxes (cars, pedestrians), each with its own id (> 0).
    #[serde(default)]
    pub actors: Vec<Actor>,
    #[serde(default)]
    pub lidar: LidarSpec,
    /// More LiDARs on the vehicle, each simulated on its own (docs/scenarios.md,
    /// "Several LiDARs"); with any, `lidar` is the roof sensor `lidar_roof`.
    #[serde(default, skip_serializing_if = "Vec::is_empty")]
    pub extra_lidars: Vec<ExtraLidar>,
    #[serde(default)]
    pub imu: ImuSpec,
    /// Rate of the TwistStamped and Odometry messages, Hz.
    #[serde(default = "defaults::velocity_rate_hz")]
    pub velocity_rate_hz: f64,
    /// How planted near misses are timed from the truth (see docs/ground-truth.md).
    #[serde(default)]
    pub events: EventSpec,
}

/// A piecewise-linear profile: `[time_s, value]` knots, held constant before the
/// first and after the last.
pub(crate) type Profile = Vec<[f64; 2]>;

/// The ego vehicle: start pose and speed / yaw-rate profiles. The vehicle frame
/// (`imu_link`) is x forward, y left, z up, `imu_height_m` above the road.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct EgoSpec {
    #[serde(default)]
    pub start_xy_m: [f64; 2],
    #[serde(default)]
    pub start_yaw_deg: f64,
    /// Speed profile, m/s.
    pub speed_mps: Profile,
    /// Yaw-rate profile, degrees per second (positive = turning left).
    #[serde(default)]
    pub yaw_rate_dps: Profile,
    #[serde(default = "defaults::imu_height_m")]
    pub imu_height_m: f64,
}

/// Something that never moves.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(tag = "kind", rename_all = "snake_case", deny_unknown_fields)]
pub enum StaticObject {
    /// A box standing on the road: centre (x, y) on the ground, size (length
    /// along its x, width, height), yaw.
    Box {
        #[serde(default)]
        label: String,
        center_xy_m: [f64; 2],
        size_m: [f64; 3],
        #[serde(default)]
        yaw_deg: f64,
    },
    /// A parked car: a 4.5 x 1.8 x 1.5 m box.
    Car {
        #[serde(default)]
        label: String,
        center_xy_m: [f64; 2],
        #[serde(default)]
        yaw_deg: f64,
    },
    /// A pole: vertical cylinder.
    Pole {
        #[serde(default)]
        label: String,
        center_xy_m: [f64; 2],
        #[serde(default = "defaults::pole_radius_m")]
        radius_m: f64,
        #[serde(default = "defaults::pole_height_m")]
        height_m: f64,
    },
}

/// A moving box. Its motion is either a constant velocity from a start point, or
/// a piecewise-linear trajectory of `[time_s, x_m, y_m]` waypoints (held at the
/// ends). It translates only (its yaw is fixed).
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct Actor {
    /// Reported as the object id of its points (> 0).
    pub id: u32,
    #[serde(default)]
    pub label: String,
    /// Length, width, height, metres.
    #[serde(default = "defaults::car_size_m")]
    pub size_m: [f64; 3],
    #[serde(default)]
    pub yaw_deg: f64,
    #[serde(default)]
    pub start_xy_m: Option<[f64; 2]>,
    #[serde(default)]
    pub velocity_mps: Option<[f64; 2]>,
    #[serde(default)]
    pub trajectory: Option<Vec<[f64; 3]>>,
    /// This actor is a planted near miss: its event window is written to
    /// `/truth/events`.
    #[serde(default)]
    pub planted_near_miss: bool,
}

/// The spinning LiDAR.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields, default)]
pub struct LidarSpec {
    pub beams: u16,
    /// Beam elevations evenly spaced from `elevation_max_deg` down to `elevation_min_deg`.
    pub elevation_max_deg: f64,
    pub elevation_min_deg: f64,
    pub columns: u32,
    pub rate_hz: f64,
    pub max_range_m: f64,
    pub range_noise_m: f64,
    /// Pose of the LiDAR in the vehicle/IMU frame: translation (lever arm) and
    /// roll, pitch, yaw (degrees, applied as yaw * pitch * roll).
    pub mount_xyz_m: [f64; 3],
    pub mount_rpy_deg: [f64; 3],
    /// How the cloud is written (docs/scenarios.md, "Cloud layouts").
    #[serde(skip_serializing_if = "is_default")]
    pub layout: CloudLayout,
    /// The frame the cloud's points are published in (docs/scenarios.md,
    /// "Cloud frames"): the sensor's own (default) or the vehicle's.
    #[serde(default, skip_serializing_if = "is_default")]
    pub cloud_frame: CloudFrame,
    /// Sensor imperfections (docs/scenarios.md, "Sensor realism"): `"ideal"`,
    /// `"hdl64e"` or an object of the separate options.
    #[serde(skip_serializing_if = "is_default")]
    pub realism: Realism,
}

/// The frame a synthetic cloud is published in.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Default, Serialize, Deserialize, clap::ValueEnum)]
#[serde(rename_all = "snake_case")]
pub enum CloudFrame {
    /// The LiDAR's frame (`lidar`, `lidar_left`, ...), as drivers publish.
    #[default]
    Sensor,
    /// The vehicle frame `imu_link` (Waymo, Argoverse 2, Autoware's
    /// `base_link`): the same points moved by the sensor's mount; `/tf_static`
    /// still relates the two.
    Vehicle,
    /// The world frame `odom` (PandaSet; a recorder after a transform
    /// filter): each scan's points moved rigidly by the vehicle's pose at its
    /// stamp and the mount; `/tf` carries `odom -> imu_link`.
    World,
}

fn is_default<T: Default + PartialEq>(value: &T) -> bool {
    *value == T::default()
}

impl Default for LidarSpec {
    fn default() -> Self {
        Self {
            beams: 64,
            elevation_max_deg: 2.0,
            elevation_min_deg: -24.8,
            columns: 2048,
            rate_hz: 10.0,
            max_range_m: 120.0,
            range_noise_m: 0.02,
            // About a metre ahead of and above the IMU, yawed and pitched a little,
            // so the extrinsic and lever-arm path is exercised.
            mount_xyz_m: [0.8, 0.1, 0.9],
            mount_rpy_deg: [0.0, -1.5, 4.0],
            layout: CloudLayout::RingTime,
            cloud_frame: CloudFrame::Sensor,
            realism: Realism::default(),
        }
    }
}

/// The IMU (also the vehicle frame).
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields, default)]
pub struct ImuSpec {
    pub rate_hz: f64,
    pub gyro_noise_radps: f64,
    pub accel_noise_mps2: f64,
}

impl Default for ImuSpec {
    fn default() -> Self {
        Self {
            rate_hz: 100.0,
            gyro_noise_radps: 0.002,
            accel_noise_mps2: 0.05,
        }
    }
}

/// How planted near-miss windows are measured from the truth.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields, default)]
pub struct EventSpec {
    /// Time to contact below which an actor's points count as threatening, s.
    pub ttc_threshold_s: f64,
    /// Threatening points of the actor needed in a scan.
    pub min_points: usize,
}

impl Default for EventSpec {
    fn default() -> Self {
        Self {
            ttc_threshold_s: 1.5,
            min_points: 10,
        }
    }
}

mod defaults {
    pub fn duration_s() -> f64 {
        10.0
    }
    pub fn velocity_rate_hz() -> f64 {
        50.0
    }
    pub fn imu_height_m() -> f64 {
        0.83
    }
    pub fn pole_radius_m() -> f64 {
        0.12
    }
    pub fn pole_height_m() -> f64 {
        5.0
    }
    pub fn car_size_m() -> [f64; 3] {
        [4.5, 1.8, 1.5]
    }
}

/// Errors in a scenario.
#[derive(Debug, thiserror::Error)]
pub enum ScenarioError {
    #[error("unknown scenario `{name}`; built-in scenarios: {known}")]
    Unknown { name: String, known: String },
    #[error("{path}: cannot read: {source}")]
    Read {
        path: String,
        source: std::io::Error,
    },
    #[error("{path}: {source}")]
    Parse {
        path: String,
        source: serde_json::Error,
    },
    #[error("{name}: {what}")]
    Invalid { name: String, what: String },
}

/// Built-in scenarios: name and JSON text.
pub const BUILT_IN: &[(&str, &str)] = &[
    (
        "straight-road",
        include_str!("../scenarios/straight-road.json"),
    ),
    ("urban-turn", include_str!("../scenarios/urban-turn.json")),
    ("follow", include_str!("../scenarios/follow.json")),
    ("cut-in", include_str!("../scenarios/cut-in.json")),
    ("crossing", include_str!("../scenarios/crossing.json")),
    ("safe-drive", include_str!("../scenarios/safe-drive.json")),
];

/// Load a built-in scenario by name, or a JSON file by path.
pub fn load(name_or_path: &str) -> Result<Scenario, ScenarioError> {
    if let Some((_, text)) = BUILT_IN.iter().find(|(name, _)| *name == name_or_path) {
        return parse(name_or_path, text);
    }
    let path = std::path::Path::new(name_or_path);
    if path.extension().is_some_and(|e| e == "json") || path.exists() {
        let text = std::fs::read_to_string(path).map_err(|source| ScenarioError::Read {
            path: name_or_path.into(),
            source,
        })?;
        return parse(name_or_path, &text);
    }
    Err(ScenarioError::Unknown {
        name: name_or_path.into(),
        known: BUILT_IN
            .iter()
            .map(|(n, _)| *n)
            .collect::<Vec<_>>()
            .join(", "),
    })
}

pub(crate) fn parse(origin: &str, text: &str) -> Result<Scenario, ScenarioError> {
    let scenario: Scenario = serde_json::from_str(text).map_err(|source| ScenarioError::Parse {
        path: origin.into(),
        source,
    })?;
    scenario.validate()?;
    Ok(scenario)
}

/// Value of a piecewise-linear profile at `t_s` (0 for an empty profile).
pub(crate) fn profile_at(profile: &Profile, t_s: f64) -> f64 {
    let Some(first) = profile.first() else {
        return 0.0;
    };
    if t_s <= first[0] {
        return first[1];
    }
    for w in profile.windows(2) {
        let ([t0, v0], [t1, v1]) = (w[0], w[1]);
        if t_s <= t1 {
            return v0 + (v1 - v0) * (t_s - t0) / (t1 - t0);
        }
    }
    profile.last().map_or(0.0, |last| last[1])
}

/// Slope of a piecewise-linear profile at `t_s` (right derivative at knots).
pub(crate) fn profile_slope_at(profile: &Profile, t_s: f64) -> f64 {
    for w in profile.windows(2) {
        let ([t0, v0], [t1, v1]) = (w[0], w[1]);
        if t_s >= t0 && t_s < t1 {
            return (v1 - v0) / (t1 - t0);
        }
    }
    0.0
}

#[cfg(test)]
mod tests;
