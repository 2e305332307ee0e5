//! `lidar.realism`: the sensor imperfections, the `"ideal"` and `"hdl64e"`
//! presets and the JSON forms they are read from.

use serde::{Deserialize, Serialize};

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
