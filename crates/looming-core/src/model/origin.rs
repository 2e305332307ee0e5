//! Where a scan's sensor is in its cloud's frame, and how that was found
//! (`pairing::origin` finds it): plain data, reported in the run summary,
//! `/looming/pairs` and `quality`.

use nalgebra::Isometry3;
use serde::{Deserialize, Serialize};

/// How the sensor's origin was found.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Serialize, Deserialize)]
#[serde(rename_all = "snake_case")]
pub enum OriginSource {
    /// The cloud's frame is the sensor's (its name says so, or its rays
    /// meet at its origin).
    CloudFrame,
    /// The transform to the frame `--sensor-frame` names.
    SensorFrameOption,
    /// `/tf_static`, to a LiDAR frame connected to the cloud's.
    TfStatic,
    /// `/tf` (with `/tf_static`): the cloud's frame moves (a world frame);
    /// the sensor is looked up at every scan's stamp.
    Tf,
    /// Estimated from the returns' elevations.
    Geometry,
    /// Estimated from the returns' elevations again at every scan: the
    /// sensor drives through its clouds' frame (a world frame with no `/tf`
    /// to it). The rings give no yaw: the axes turn with the sweeps' phase
    /// where the points carry their times (`pairing::origin_yaw`), else
    /// keep the frame's.
    RingsPerScan,
}

impl OriginSource {
    pub fn as_str(self) -> &'static str {
        match self {
            OriginSource::CloudFrame => "cloud_frame",
            OriginSource::SensorFrameOption => "sensor_frame_option",
            OriginSource::TfStatic => "tf_static",
            OriginSource::Tf => "tf",
            OriginSource::Geometry => "geometry",
            OriginSource::RingsPerScan => "rings_per_scan",
        }
    }
}

/// The sensor's origin in its cloud's frame, and how it was found.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct SensorOrigin {
    pub source: OriginSource,
    /// The frame a transform named (`--sensor-frame`, `/tf_static`).
    #[serde(skip_serializing_if = "Option::is_none")]
    pub sensor_frame: Option<String>,
    /// The sensor's position in the cloud's frame, m.
    pub position_m: [f64; 3],
    /// RMS distance of the returns' elevation angles from their ring's
    /// about this origin, degrees (absent when not measured: a cloud frame
    /// named as a LiDAR's is taken as it is).
    #[serde(skip_serializing_if = "Option::is_none")]
    pub ring_spread_deg: Option<f64>,
    /// The same about the cloud's own origin.
    #[serde(skip_serializing_if = "Option::is_none")]
    pub cloud_origin_ring_spread_deg: Option<f64>,
    /// Even about the best origin the rings stay spread: the rays do not
    /// meet at one point (several sensors merged into one cloud, or a
    /// sensor tilted in the cloud's frame).
    pub several_origins: bool,
    /// Maps the sensor's coordinates into the cloud's (un-posed) points'.
    #[serde(skip, default = "Isometry3::identity")]
    pub cloud_from_sensor: Isometry3<f64>,
}

impl SensorOrigin {
    pub(crate) fn at(source: OriginSource, cloud_from_sensor: Isometry3<f64>) -> Self {
        let t = cloud_from_sensor.translation.vector;
        Self {
            source,
            sensor_frame: None,
            position_m: [t.x, t.y, t.z],
            ring_spread_deg: None,
            cloud_origin_ring_spread_deg: None,
            several_origins: false,
            cloud_from_sensor,
        }
    }

    /// The cloud's own origin.
    pub fn cloud_frame() -> Self {
        Self::at(OriginSource::CloudFrame, Isometry3::identity())
    }

    /// Whether the points must be moved (the origin is not the cloud's).
    pub fn moves_points(&self) -> bool {
        self.cloud_from_sensor != Isometry3::identity()
    }

    /// Where the sensor is, for a scan's layout in words: `at` and
    /// [`describe`](Self::describe); for one placed at every scan, how
    /// only (its position and its rings' spread change with every scan, and
    /// are in the record; the words stay one layout for `quality`).
    pub fn placement_text(&self) -> String {
        match self.source {
            OriginSource::RingsPerScan => "placed from the returns' elevations at every scan \
                 (rings, per scan: it moves through the cloud's frame)"
                .to_string(),
            _ => format!("at {}", self.describe()),
        }
    }

    /// One line for the run summary.
    pub fn describe(&self) -> String {
        let [x, y, z] = self.position_m;
        let how = match self.source {
            OriginSource::CloudFrame => "the cloud's frame".to_string(),
            OriginSource::SensorFrameOption => format!(
                "--sensor-frame {}",
                self.sensor_frame.as_deref().unwrap_or("?")
            ),
            OriginSource::TfStatic => format!(
                "/tf_static to {}",
                self.sensor_frame.as_deref().unwrap_or("?")
            ),
            OriginSource::Tf => format!(
                "/tf to {} at each scan's stamp",
                self.sensor_frame.as_deref().unwrap_or("?")
            ),
            OriginSource::Geometry => "estimated from the returns' elevations".to_string(),
            OriginSource::RingsPerScan => {
                "estimated from the returns' elevations at every scan (rings, per scan: it moves \
                 through the cloud's frame)"
                    .to_string()
            }
        };
        let spread = match (self.ring_spread_deg, self.cloud_origin_ring_spread_deg) {
            (Some(at), Some(cloud)) => {
                format!("; ring spread {at:.3} deg (about the cloud's origin {cloud:.3})")
            }
            (Some(at), None) => format!("; ring spread {at:.3} deg"),
            _ => String::new(),
        };
        let merged = if self.several_origins {
            "; its rays do not meet at one point: several sensors merged, or a tilted one"
        } else {
            ""
        };
        format!("({x:+.2}, {y:+.2}, {z:+.2}) m, {how}{spread}{merged}")
    }
}
