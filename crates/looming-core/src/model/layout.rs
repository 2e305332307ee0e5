//! How a scan's rings (beams, image rows) and per-point times were obtained:
//! plain data that the decoder starts and `engine::layout::complete` fills in,
//! then reported in the run summary and in `/looming/pairs`.

use std::fmt;

use serde::Serialize;

/// Which way a spinning LiDAR turns, seen from above.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Serialize)]
#[serde(rename_all = "snake_case")]
pub enum Rotation {
    /// Azimuth `atan2(y, x)` decreasing (most Velodyne / Ouster drivers).
    Clockwise,
    /// Azimuth increasing (KITTI's HDL-64E lists).
    CounterClockwise,
}

impl Rotation {
    /// +1 counter-clockwise, -1 clockwise.
    pub fn sign(self) -> f64 {
        match self {
            Rotation::Clockwise => -1.0,
            Rotation::CounterClockwise => 1.0,
        }
    }

    pub fn as_str(self) -> &'static str {
        match self {
            Rotation::Clockwise => "clockwise",
            Rotation::CounterClockwise => "counter-clockwise",
        }
    }
}

/// Where the rings of a scan came from.
#[derive(Debug, Clone, PartialEq, Serialize, Default)]
#[serde(tag = "kind", rename_all = "snake_case")]
pub enum RingSource {
    /// The row of an organized cloud; `ring_field` names a ring field that
    /// agreed with the rows.
    Organized {
        rows: u32,
        cols: u32,
        ring_field: Option<String>,
    },
    /// The cloud's ring field.
    Field { name: String },
    /// The azimuth along the point order wraps once per laser.
    LaserOrder { direction: Rotation },
    /// Consecutive points cycle through `period` lasers.
    FiringOrder { period: u32 },
    /// Elevation clusters, corrected for lasers off the rotation axis.
    Elevation,
    /// Nothing found: the range image infers rows from elevations.
    #[default]
    None,
}

impl RingSource {
    /// Short snake_case kind, for JSON records.
    pub fn kind(&self) -> &'static str {
        match self {
            RingSource::Organized { .. } => "organized",
            RingSource::Field { .. } => "field",
            RingSource::LaserOrder { .. } => "laser_order",
            RingSource::FiringOrder { .. } => "firing_order",
            RingSource::Elevation => "elevation",
            RingSource::None => "none",
        }
    }
}

/// Where the per-point times of a scan came from.
#[derive(Debug, Clone, PartialEq, Serialize, Default)]
#[serde(tag = "kind", rename_all = "snake_case")]
pub enum TimeSource {
    /// The cloud's time field.
    Field { name: String },
    /// From the azimuth: the sweep turns `direction`, starting at `seam_deg`
    /// (azimuth `atan2(y, x)`, degrees), over one scan period.
    Azimuth { direction: Rotation, seam_deg: f64 },
    /// No per-point time: every point at the header stamp.
    #[default]
    Stamp,
}

impl TimeSource {
    pub fn kind(&self) -> &'static str {
        match self {
            TimeSource::Field { .. } => "field",
            TimeSource::Azimuth { .. } => "azimuth",
            TimeSource::Stamp => "stamp",
        }
    }
}

/// A ring field the cloud carried but that is not used as rings.
#[derive(Debug, Clone, PartialEq, Serialize)]
pub struct DroppedRingField {
    pub name: String,
    pub reason: String,
}

/// How a scan's rings and times were obtained.
#[derive(Debug, Clone, PartialEq, Serialize, Default)]
pub struct ScanLayout {
    pub rings: RingSource,
    /// Distinct ring values holding points (0 without rings).
    pub ring_count: u32,
    pub times: TimeSource,
    /// A ring field present but not used: its values are not ring numbers.
    pub ring_field_dropped: Option<DroppedRingField>,
    /// Anything else worth knowing (e.g. organized rows that disagree with
    /// the ring field, which is then used).
    pub note: Option<String>,
    /// Where the sensor is in the cloud's frame (`pairing::origin`); the
    /// points were moved about it. `None` before pairing.
    pub origin: Option<super::SensorOrigin>,
}

impl ScanLayout {
    /// What the decoder read from the cloud's own fields.
    pub fn from_fields(ring_field: Option<&str>, time_field: Option<&str>) -> Self {
        Self {
            rings: ring_field.map_or(RingSource::None, |name| RingSource::Field {
                name: name.to_owned(),
            }),
            ring_count: 0,
            times: time_field.map_or(TimeSource::Stamp, |name| TimeSource::Field {
                name: name.to_owned(),
            }),
            ring_field_dropped: None,
            note: None,
            origin: None,
        }
    }

    /// The rings in a few words, e.g. "laser order (64 rings)".
    pub fn rings_text(&self) -> String {
        let n = self.ring_count;
        match &self.rings {
            RingSource::Organized {
                rows,
                cols,
                ring_field,
            } => match ring_field {
                Some(name) => format!("organized {rows} x {cols} (ring field `{name}` agrees)"),
                None => format!("organized {rows} x {cols}"),
            },
            RingSource::Field { name } => format!("ring field `{name}` ({n} rings)"),
            RingSource::LaserOrder { direction } => {
                format!("laser order ({n} rings, {})", direction.as_str())
            }
            RingSource::FiringOrder { period } => format!("firing order ({period} rings)"),
            RingSource::Elevation => format!("elevation clusters ({n})"),
            RingSource::None => "no rings (elevation table)".to_owned(),
        }
    }

    /// The times in a few words, e.g. "per-point `t`".
    pub fn times_text(&self) -> String {
        match &self.times {
            TimeSource::Field { name } => format!("per-point `{name}`"),
            TimeSource::Azimuth {
                direction,
                seam_deg,
            } => format!(
                "from azimuth ({}, seam at {seam_deg:.0} deg{})",
                direction.as_str(),
                bearing_word(*seam_deg).map_or(String::new(), |w| format!(", {w}"))
            ),
            TimeSource::Stamp => "stamp only".to_owned(),
        }
    }
}

impl fmt::Display for ScanLayout {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        write!(f, "{}, times {}", self.rings_text(), self.times_text())?;
        if let Some(dropped) = &self.ring_field_dropped {
            write!(
                f,
                "; ring field `{}` not used: {}",
                dropped.name, dropped.reason
            )?;
        }
        if let Some(note) = &self.note {
            write!(f, "; {note}")?;
        }
        if let Some(origin) = self
            .origin
            .as_ref()
            .filter(|o| o.moves_points() || o.several_origins)
        {
            write!(f, "; sensor {}", origin.placement_text())?;
        }
        Ok(())
    }
}

/// "ahead", "left", "behind", "right" within 30 deg of those bearings.
pub(crate) fn bearing_word(azimuth_deg: f64) -> Option<&'static str> {
    let a = (azimuth_deg + 180.0).rem_euclid(360.0) - 180.0;
    let near = |centre: f64| ((a - centre + 180.0).rem_euclid(360.0) - 180.0).abs() <= 30.0;
    [
        (0.0, "ahead"),
        (90.0, "left"),
        (180.0, "behind"),
        (-90.0, "right"),
    ]
    .into_iter()
    .find(|&(c, _)| near(c))
    .map(|(_, w)| w)
}
