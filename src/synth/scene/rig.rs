//! `extra_lidars`: LiDARs beside the scenario's own (`lidar`, then the roof
//! sensor), each simulated on its own, and the `"left"` / `"right"` presets
//! `looming synth --lidars 2|3` adds.

use serde::{Deserialize, Serialize};

use super::LidarSpec;

/// A LiDAR beside the roof one: its name (frame `<name>`, topic
/// `/<name>/points`), its phase and its spec.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(try_from = "ExtraLidarRepr")]
pub struct ExtraLidar {
    /// Frame id and topic stem: lower-case letters, digits and `_`.
    pub name: String,
    /// Start of its first scan after the roof LiDAR's first scan, seconds
    /// (0 <= phase_s < its period).
    pub phase_s: f64,
    pub lidar: LidarSpec,
}

/// Frame (and topic stem) of the scenario's own LiDAR when there are others.
pub const ROOF_NAME: &str = "lidar_roof";

/// Names of the `extra_lidars` presets, in the order `--lidars` adds them.
pub const PRESET_NAMES: [&str; 2] = ["left", "right"];

impl ExtraLidar {
    /// A preset: `"left"` or `"right"`: 32 beams from +15 to -25 degrees, 1024
    /// columns, 20 Hz, 0.85 m to the side of the vehicle 1 m ahead of the
    /// IMU and 0.5 m above it, looking sideways (yaw +-90 degrees), first
    /// scan 13 (left) or 31 ms (right) after the roof's.
    pub fn preset(name: &str) -> Option<Self> {
        let (side, yaw_deg, phase_s) = match name {
            "left" => (1.0, 90.0, 0.013),
            "right" => (-1.0, -90.0, 0.031),
            _ => return None,
        };
        Some(Self {
            name: format!("lidar_{name}"),
            phase_s,
            lidar: LidarSpec {
                beams: 32,
                elevation_max_deg: 15.0,
                elevation_min_deg: -25.0,
                columns: 1024,
                rate_hz: 20.0,
                mount_xyz_m: [1.0, 0.85 * side, 0.5],
                mount_rpy_deg: [0.0, 0.0, yaw_deg],
                ..LidarSpec::default()
            },
        })
    }

    /// The extra LiDARs of a rig of `lidars` sensors (1 to 3): none, the left,
    /// or the left and the right preset.
    pub fn presets_for(lidars: u8) -> Vec<Self> {
        PRESET_NAMES
            .iter()
            .take(usize::from(lidars.saturating_sub(1)))
            .filter_map(|name| Self::preset(name))
            .collect()
    }
}

/// A preset name or the fields.
#[derive(Deserialize)]
#[serde(untagged)]
enum ExtraLidarRepr {
    Preset(String),
    Fields(ExtraLidarFields),
}

#[derive(Deserialize)]
#[serde(deny_unknown_fields)]
struct ExtraLidarFields {
    name: String,
    #[serde(default)]
    phase_s: f64,
    #[serde(default)]
    lidar: LidarSpec,
}

impl TryFrom<ExtraLidarRepr> for ExtraLidar {
    type Error = String;

    fn try_from(repr: ExtraLidarRepr) -> Result<Self, String> {
        match repr {
            ExtraLidarRepr::Preset(name) => Self::preset(&name).ok_or_else(|| {
                format!(
                    "unknown extra LiDAR preset `{name}`: \"left\", \"right\" or an object \
                     {{\"name\", \"phase_s\", \"lidar\"}}"
                )
            }),
            ExtraLidarRepr::Fields(f) => Ok(Self {
                name: f.name,
                phase_s: f.phase_s,
                lidar: f.lidar,
            }),
        }
    }
}
