//! Per-point time fields: which names are read, how their values relate to
//! the header stamp ([`TimeConvention`]), and the conversion to seconds
//! relative to the stamp ([`TimeToOffset`]).

use super::fields::{FieldReader, Layout};
use crate::model::StampNs;

/// How a per-point time field relates to the header stamp.
#[derive(Debug, Clone, Copy, PartialEq)]
pub(super) enum TimeConvention {
    /// Offset from the stamp; value times `scale_s` is seconds.
    Relative { scale_s: f64 },
    /// Absolute epoch seconds (`timestamp` in Hesai / RoboSense drivers).
    AbsoluteSeconds,
    /// Absolute epoch nanoseconds stored as a float (Livox driver 2).
    AbsoluteNanos,
}

/// Per-point time field names, in priority order, and whether they are absolute.
pub(super) const TIME_FIELDS: [(&str, bool); 5] = [
    ("t", false),           // Ouster: UINT32 ns since scan start
    ("time", false),        // Velodyne: FLOAT32 s relative to the stamp
    ("offset_time", false), // Livox custom: UINT32 ns relative to the stamp
    ("timestamp", true),    // Hesai / RoboSense: FLOAT64 absolute s
    ("time_stamp", true),
];

/// Absolute float times above this are nanoseconds, not seconds (1e14 s is
/// ~3 million years; 1e14 ns is ~28 hours after the epoch).
const ABSOLUTE_NS_THRESHOLD: f64 = 1e14;

/// Absolute time fields come in seconds or nanoseconds depending on the
/// driver; the magnitude of the first point's value tells which.
pub(super) fn absolute_convention(reader: &FieldReader, layout: &Layout<'_>) -> TimeConvention {
    let first = layout.first_point().map_or(0.0, |p| reader.read(p));
    if first.abs() > ABSOLUTE_NS_THRESHOLD {
        TimeConvention::AbsoluteNanos
    } else {
        TimeConvention::AbsoluteSeconds
    }
}

/// Converts a raw time value to seconds relative to `stamp_ns`.
pub(super) struct TimeToOffset {
    convention: TimeConvention,
    stamp_whole_s: f64,
    stamp_frac_s: f64,
    stamp_ns: f64,
}

impl TimeToOffset {
    pub(super) fn new(convention: TimeConvention, stamp_ns: StampNs) -> Self {
        Self {
            convention,
            // Split so that subtracting from absolute epoch seconds keeps
            // sub-microsecond precision in f64.
            stamp_whole_s: stamp_ns.div_euclid(1_000_000_000) as f64,
            stamp_frac_s: stamp_ns.rem_euclid(1_000_000_000) as f64 * 1e-9,
            stamp_ns: stamp_ns as f64,
        }
    }

    #[inline(always)]
    pub(super) fn offset_s(&self, raw: f64) -> f32 {
        let s = match self.convention {
            TimeConvention::Relative { scale_s } => raw * scale_s,
            TimeConvention::AbsoluteSeconds => (raw - self.stamp_whole_s) - self.stamp_frac_s,
            TimeConvention::AbsoluteNanos => (raw - self.stamp_ns) * 1e-9,
        };
        s as f32
    }
}
