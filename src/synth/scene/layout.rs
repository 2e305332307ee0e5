//! `lidar.layout` / `--layout`: how the `/lidar/points` cloud is laid out,
//! its names and their parsing and printing.

use serde::{Deserialize, Serialize};

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
