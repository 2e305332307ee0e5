//! Scenario files: the scene (road, buildings, obstacles, moving actors), the
//! ego trajectory and the sensors, as JSON (serde, unknown fields refused,
//! everything optional has a default). The built-in scenarios are JSON files
//! embedded in the binary (`src/synth/scenarios/`), so they double as examples.

use serde::{Deserialize, Serialize};

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
pub type Profile = Vec<[f64; 2]>;

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
    /// Sensor imperfections (docs/scenarios.md, "Sensor realism"): `"ideal"`,
    /// `"hdl64e"` or an object of the separate options.
    #[serde(skip_serializing_if = "is_default")]
    pub realism: Realism,
}

fn is_default<T: Default + PartialEq>(value: &T) -> bool {
    *value == T::default()
}

/// What the `/lidar/points` cloud looks like: the layouts real drivers write.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Default, Serialize, Deserialize)]
#[serde(try_from = "String", into = "String")]
pub enum CloudLayout {
    /// Velodyne driver: x, y, z, intensity, `ring` (UINT16), `time` (FLOAT32 s),
    /// unorganized, returns only, in firing order.
    #[default]
    RingTime,
    /// Ouster driver: height = beams (top beam first), width = columns, a
    /// no-return pixel has NaN x, y, z; fields x, y, z, intensity, `t` (UINT32 ns),
    /// `reflectivity` (UINT16), `ring` (UINT16, = row), `ambient` (UINT16),
    /// `range` (UINT32 mm).
    Organized,
    /// As `RingTime`, with the ring under another name and type.
    RingField(RingField),
    /// KITTI `.bin` content: x, y, z, intensity only, laser by laser.
    LaserOrder(LaserOrder),
    /// x, y, z, intensity only, in firing order (column by column); `sparse`
    /// drops the no-return points, otherwise they are kept as NaN.
    FiringOrder { sparse: bool },
}

/// The ring field of a `ring-field:NAME[:TYPE]` layout.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub struct RingField {
    pub name: RingFieldName,
    /// A `sensor_msgs/PointField` datatype: UINT8, UINT16 or INT32.
    pub datatype: u8,
}

#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum RingFieldName {
    Channel,
    LaserId,
    Line,
}

impl RingFieldName {
    pub fn as_str(self) -> &'static str {
        match self {
            Self::Channel => "channel",
            Self::LaserId => "laser_id",
            Self::Line => "line",
        }
    }
}

/// The order of a `laser-order` cloud.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum LaserOrder {
    /// Lowest laser (ring 0) first, each laser's points in firing order
    /// (clockwise from behind).
    LowestFirst,
    /// As KITTI lists them: top laser first, each laser's points
    /// counter-clockwise from straight ahead.
    Kitti,
}

/// Every layout name `--layout` and `lidar.layout` accept.
pub const LAYOUT_NAMES: &[&str] = &[
    "ring-time",
    "organized",
    "ring-field:channel",
    "ring-field:laser_id",
    "ring-field:laser_id:int32",
    "ring-field:line",
    "laser-order",
    "laser-order:kitti",
    "firing-order",
    "firing-order-sparse",
];

const UINT8: u8 = 2;
const UINT16: u8 = 4;
const INT32: u8 = 5;

impl std::fmt::Display for CloudLayout {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        match self {
            Self::RingTime => f.write_str("ring-time"),
            Self::Organized => f.write_str("organized"),
            Self::RingField(field) => {
                let default = RingField::named(field.name).datatype;
                write!(f, "ring-field:{}", field.name.as_str())?;
                if field.datatype != default {
                    let name = match field.datatype {
                        UINT8 => "uint8",
                        UINT16 => "uint16",
                        _ => "int32",
                    };
                    write!(f, ":{name}")?;
                }
                Ok(())
            }
            Self::LaserOrder(LaserOrder::LowestFirst) => f.write_str("laser-order"),
            Self::LaserOrder(LaserOrder::Kitti) => f.write_str("laser-order:kitti"),
            Self::FiringOrder { sparse: false } => f.write_str("firing-order"),
            Self::FiringOrder { sparse: true } => f.write_str("firing-order-sparse"),
        }
    }
}

impl RingField {
    /// The name with its usual type: `channel` UINT16, `laser_id` and `line` UINT8.
    pub fn named(name: RingFieldName) -> Self {
        let datatype = match name {
            RingFieldName::Channel => UINT16,
            RingFieldName::LaserId | RingFieldName::Line => UINT8,
        };
        Self { name, datatype }
    }
}

impl std::str::FromStr for CloudLayout {
    type Err = String;

    fn from_str(text: &str) -> Result<Self, String> {
        let unknown = || {
            format!(
                "unknown LiDAR layout `{text}`; layouts: {} (a ring field may add :uint8, :uint16 or :int32)",
                LAYOUT_NAMES.join(", ")
            )
        };
        Ok(match text {
            "ring-time" => Self::RingTime,
            "organized" => Self::Organized,
            "laser-order" => Self::LaserOrder(LaserOrder::LowestFirst),
            "laser-order:kitti" => Self::LaserOrder(LaserOrder::Kitti),
            "firing-order" => Self::FiringOrder { sparse: false },
            "firing-order-sparse" => Self::FiringOrder { sparse: true },
            _ => {
                let rest = text.strip_prefix("ring-field:").ok_or_else(unknown)?;
                let (name, datatype) = rest.split_once(':').unwrap_or((rest, ""));
                let name = match name {
                    "channel" => RingFieldName::Channel,
                    "laser_id" => RingFieldName::LaserId,
                    "line" => RingFieldName::Line,
                    _ => return Err(unknown()),
                };
                let mut field = RingField::named(name);
                field.datatype = match datatype {
                    "" => field.datatype,
                    "uint8" => UINT8,
                    "uint16" => UINT16,
                    "int32" => INT32,
                    _ => return Err(unknown()),
                };
                Self::RingField(field)
            }
        })
    }
}

impl TryFrom<String> for CloudLayout {
    type Error = String;

    fn try_from(text: String) -> Result<Self, String> {
        text.parse()
    }
}

impl From<CloudLayout> for String {
    fn from(layout: CloudLayout) -> Self {
        layout.to_string()
    }
}

/// Sensor imperfections, each off by default (`"ideal"`). `"hdl64e"` turns
/// all of them on with HDL-64E-like magnitudes. They combine with any layout.
#[derive(Debug, Clone, PartialEq, Default, Serialize, Deserialize)]
#[serde(try_from = "RealismRepr")]
pub struct Realism {
    /// Two blocks of lasers with different spacings (HDL-64E: 32 lasers from
    /// -24.8 to -8.8 deg, 32 from -8.5 to +2 deg), each laser a little off.
    pub irregular_elevations: bool,
    /// Lasers mounted off the rotation axis: 0.13-0.21 m above the frame
    /// origin and +-2.6 cm sideways, rotating with the head.
    pub off_axis: bool,
    /// Per-laser rotational corrections up to +-5 deg.
    pub azimuth_offsets: bool,
    /// Per-laser range biases (+-2 cm) and an intensity-dependent range error
    /// (weak returns read up to 4 cm long).
    pub range_bias: bool,
    /// Fraction of returns lost at random at short range; it grows to 4 times
    /// this at `max_range_m`.
    pub dropout_fraction: f64,
    /// Fraction of returns replaced by a speck (rain, dust) at a random short range.
    pub speck_fraction: f64,
}

impl Realism {
    pub fn hdl64e() -> Self {
        Self {
            irregular_elevations: true,
            off_axis: true,
            azimuth_offsets: true,
            range_bias: true,
            dropout_fraction: 0.015,
            speck_fraction: 0.0005,
        }
    }
}

/// `"ideal"`, `"hdl64e"` or the fields.
#[derive(Deserialize)]
#[serde(untagged)]
enum RealismRepr {
    Preset(String),
    Fields(RealismFields),
}

#[derive(Deserialize)]
#[serde(deny_unknown_fields)]
struct RealismFields {
    #[serde(default)]
    irregular_elevations: bool,
    #[serde(default)]
    off_axis: bool,
    #[serde(default)]
    azimuth_offsets: bool,
    #[serde(default)]
    range_bias: bool,
    #[serde(default)]
    dropout_fraction: f64,
    #[serde(default)]
    speck_fraction: f64,
}

impl TryFrom<RealismRepr> for Realism {
    type Error = String;

    fn try_from(repr: RealismRepr) -> Result<Self, String> {
        match repr {
            RealismRepr::Preset(name) => name.parse(),
            RealismRepr::Fields(f) => Ok(Self {
                irregular_elevations: f.irregular_elevations,
                off_axis: f.off_axis,
                azimuth_offsets: f.azimuth_offsets,
                range_bias: f.range_bias,
                dropout_fraction: f.dropout_fraction,
                speck_fraction: f.speck_fraction,
            }),
        }
    }
}

impl std::str::FromStr for Realism {
    type Err = String;

    fn from_str(name: &str) -> Result<Self, String> {
        match name {
            "ideal" => Ok(Self::default()),
            "hdl64e" => Ok(Self::hdl64e()),
            _ => Err(format!(
                "unknown realism `{name}`: \"ideal\", \"hdl64e\" or an object of options"
            )),
        }
    }
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
        include_str!("scenarios/straight-road.json"),
    ),
    ("urban-turn", include_str!("scenarios/urban-turn.json")),
    ("follow", include_str!("scenarios/follow.json")),
    ("cut-in", include_str!("scenarios/cut-in.json")),
    ("crossing", include_str!("scenarios/crossing.json")),
    ("safe-drive", include_str!("scenarios/safe-drive.json")),
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

fn parse(origin: &str, text: &str) -> Result<Scenario, ScenarioError> {
    let scenario: Scenario = serde_json::from_str(text).map_err(|source| ScenarioError::Parse {
        path: origin.into(),
        source,
    })?;
    scenario.validate()?;
    Ok(scenario)
}

impl Scenario {
    /// Check what serde cannot: positive sizes and rates, actor motion given once.
    pub fn validate(&self) -> Result<(), ScenarioError> {
        let invalid = |what: String| ScenarioError::Invalid {
            name: self.name.clone(),
            what,
        };
        let positive = |value: f64, what: &str| {
            if value.is_finite() && value > 0.0 {
                Ok(())
            } else {
                Err(invalid(format!(
                    "{what} must be a positive number, got {value}"
                )))
            }
        };
        positive(self.duration_s, "duration_s")?;
        positive(self.lidar.rate_hz, "lidar.rate_hz")?;
        positive(self.lidar.max_range_m, "lidar.max_range_m")?;
        positive(self.imu.rate_hz, "imu.rate_hz")?;
        positive(self.velocity_rate_hz, "velocity_rate_hz")?;
        if self.lidar.beams < 1 || self.lidar.columns < 8 {
            return Err(invalid("lidar needs at least 1 beam and 8 columns".into()));
        }
        if self.lidar.elevation_min_deg >= self.lidar.elevation_max_deg && self.lidar.beams > 1 {
            return Err(invalid(
                "lidar.elevation_min_deg must be below elevation_max_deg".into(),
            ));
        }
        let realism = &self.lidar.realism;
        for (value, what) in [
            (realism.dropout_fraction, "dropout_fraction"),
            (realism.speck_fraction, "speck_fraction"),
        ] {
            if !(0.0..=0.25).contains(&value) {
                return Err(invalid(format!(
                    "lidar.realism.{what} must be within 0 to 0.25, got {value}"
                )));
            }
        }
        if self.ego.speed_mps.is_empty() {
            return Err(invalid(
                "ego.speed_mps needs at least one [time_s, value] knot".into(),
            ));
        }
        check_profile(&self.ego.speed_mps).map_err(|e| invalid(format!("ego.speed_mps: {e}")))?;
        check_profile(&self.ego.yaw_rate_dps)
            .map_err(|e| invalid(format!("ego.yaw_rate_dps: {e}")))?;
        positive(self.events.ttc_threshold_s, "events.ttc_threshold_s")?;
        if self.events.min_points < 1 {
            return Err(invalid("events.min_points must be at least 1".into()));
        }
        for object in &self.static_objects {
            let sizes: Vec<f64> = match object {
                StaticObject::Box { size_m, .. } => size_m.to_vec(),
                StaticObject::Car { .. } => Vec::new(),
                StaticObject::Pole {
                    radius_m, height_m, ..
                } => vec![*radius_m, *height_m],
            };
            if sizes.iter().any(|s| !(s.is_finite() && *s > 0.0)) {
                return Err(invalid(format!(
                    "static object {object:?}: sizes must be positive"
                )));
            }
        }
        let mut ids = std::collections::BTreeSet::new();
        for actor in &self.actors {
            if actor.id == 0 || !ids.insert(actor.id) {
                return Err(invalid(format!(
                    "actor ids must be unique and > 0 (id {})",
                    actor.id
                )));
            }
            let by_velocity = actor.start_xy_m.is_some() || actor.velocity_mps.is_some();
            match (&actor.trajectory, by_velocity) {
                (Some(points), false) if !points.is_empty() => {
                    if points.windows(2).any(|w| w[1][0] <= w[0][0]) {
                        return Err(invalid(format!(
                            "actor {}: trajectory times must increase",
                            actor.id
                        )));
                    }
                }
                (None, true) if actor.start_xy_m.is_some() => {}
                _ => {
                    return Err(invalid(format!(
                        "actor {}: give either start_xy_m (+ velocity_mps) or a non-empty trajectory",
                        actor.id
                    )));
                }
            }
            if actor.size_m.iter().any(|s| !(s.is_finite() && *s > 0.0)) {
                return Err(invalid(format!(
                    "actor {}: sizes must be positive",
                    actor.id
                )));
            }
        }
        Ok(())
    }
}

fn check_profile(profile: &Profile) -> Result<(), String> {
    if profile
        .iter()
        .any(|[t, v]| !t.is_finite() || !v.is_finite())
    {
        return Err("knots must be finite numbers".into());
    }
    if profile.windows(2).any(|w| w[1][0] <= w[0][0]) {
        return Err("knot times must increase".into());
    }
    Ok(())
}

/// Value of a piecewise-linear profile at `t_s` (0 for an empty profile).
pub fn profile_at(profile: &Profile, t_s: f64) -> f64 {
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
pub fn profile_slope_at(profile: &Profile, t_s: f64) -> f64 {
    for w in profile.windows(2) {
        let ([t0, v0], [t1, v1]) = (w[0], w[1]);
        if t_s >= t0 && t_s < t1 {
            return (v1 - v0) / (t1 - t0);
        }
    }
    0.0
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn every_built_in_scenario_parses_and_validates() {
        for (name, _) in BUILT_IN {
            let scenario = load(name).unwrap_or_else(|e| panic!("{name}: {e}"));
            assert_eq!(&scenario.name, name);
        }
    }

    #[test]
    fn unknown_fields_and_names_are_refused() {
        let text = r#"{"name": "x", "ego": {"speed_mps": [[0, 1]]}, "colour": "red"}"#;
        assert!(matches!(parse("x", text), Err(ScenarioError::Parse { .. })));
        let err = load("no-such-scenario").unwrap_err().to_string();
        assert!(err.contains("straight-road"), "{err}");
    }

    #[test]
    fn defaults_fill_what_is_not_given() {
        let scenario = parse("x", r#"{"name": "x", "ego": {"speed_mps": [[0, 1]]}}"#).unwrap();
        assert_eq!(scenario.lidar.beams, 64);
        assert_eq!(scenario.lidar.elevation_min_deg, -24.8);
        assert_eq!(scenario.imu.rate_hz, 100.0);
        assert_eq!(scenario.velocity_rate_hz, 50.0);
    }

    #[test]
    fn profiles_interpolate_and_hold() {
        let profile = vec![[1.0, 10.0], [3.0, 20.0]];
        assert_eq!(profile_at(&profile, 0.0), 10.0);
        assert_eq!(profile_at(&profile, 2.0), 15.0);
        assert_eq!(profile_at(&profile, 5.0), 20.0);
        assert_eq!(profile_slope_at(&profile, 2.0), 5.0);
        assert_eq!(profile_slope_at(&profile, 4.0), 0.0);
    }

    #[test]
    fn layouts_and_realism_parse_and_stay_out_of_the_json_when_default() {
        for name in LAYOUT_NAMES {
            let layout: CloudLayout = name.parse().unwrap();
            assert_eq!(&layout.to_string(), name);
        }
        assert_eq!(
            "ring-field:channel:uint8".parse::<CloudLayout>().unwrap(),
            CloudLayout::RingField(RingField {
                name: RingFieldName::Channel,
                datatype: 2
            })
        );
        assert!("ring-field:ringo".parse::<CloudLayout>().is_err());
        assert!("columnar".parse::<CloudLayout>().is_err());
        let minimal = r#"{"name": "x", "ego": {"speed_mps": [[0, 1]]}}"#;
        let scenario = parse("x", minimal).unwrap();
        let json = serde_json::to_string(&scenario).unwrap();
        assert!(
            !json.contains("layout") && !json.contains("realism"),
            "{json}"
        );
        let text = r#"{"name": "x", "ego": {"speed_mps": [[0, 1]]},
            "lidar": {"layout": "organized", "realism": "hdl64e"}}"#;
        let scenario = parse("x", text).unwrap();
        assert_eq!(scenario.lidar.layout, CloudLayout::Organized);
        assert_eq!(scenario.lidar.realism, Realism::hdl64e());
        // What is written back reads the same.
        let again: Scenario =
            serde_json::from_str(&serde_json::to_string(&scenario).unwrap()).unwrap();
        assert_eq!(again, scenario);
        let text = r#"{"name": "x", "ego": {"speed_mps": [[0, 1]]},
            "lidar": {"realism": {"off_axis": true, "speck_fraction": 0.001}}}"#;
        let realism = parse("x", text).unwrap().lidar.realism;
        assert!(realism.off_axis && !realism.azimuth_offsets && realism.speck_fraction == 0.001);
        for bad in [
            r#"{"layout": "sideways"}"#,
            r#"{"realism": "hdl32e"}"#,
            r#"{"realism": {"offaxis": true}}"#,
            r#"{"realism": {"dropout_fraction": 0.9}}"#,
        ] {
            let text =
                format!(r#"{{"name": "x", "ego": {{"speed_mps": [[0, 1]]}}, "lidar": {bad}}}"#);
            assert!(parse("x", &text).is_err(), "{bad}");
        }
    }

    #[test]
    fn bad_actor_motion_is_refused() {
        let text = r#"{"name": "x", "ego": {"speed_mps": [[0, 1]]}, "actors": [{"id": 1}]}"#;
        assert!(matches!(
            parse("x", text),
            Err(ScenarioError::Invalid { .. })
        ));
    }
}
