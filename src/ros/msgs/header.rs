//! `std_msgs/Header` and its stamp (`builtin_interfaces/Time`, ROS 1 `time`).

use super::RosMessage;
use crate::ros::DecodeError;
use crate::ros::cdr::{WireRead, WireWrite};

/// `builtin_interfaces/Time` (ROS 2: `int32 sec`, `uint32 nanosec`) or ROS 1
/// `time` (`uint32 secs`, `uint32 nsecs`). Seconds are widened to i64 so both fit.
#[derive(Debug, Clone, Copy, Default, PartialEq, Eq)]
pub struct Time {
    pub sec: i64,
    pub nanosec: u32,
}

impl Time {
    /// Splits nanoseconds since the epoch into seconds and nanoseconds.
    pub fn from_ns(stamp_ns: i64) -> Self {
        Self {
            sec: stamp_ns.div_euclid(1_000_000_000),
            nanosec: stamp_ns.rem_euclid(1_000_000_000) as u32,
        }
    }

    /// `sec * 1e9 + nanosec` (saturating; cannot overflow for wire values).
    pub fn to_ns(self) -> i64 {
        self.sec
            .saturating_mul(1_000_000_000)
            .saturating_add(i64::from(self.nanosec))
    }
}

/// `std_msgs/Header`. `seq` exists only in ROS 1 (0 when decoded from CDR,
/// ignored when encoding CDR).
#[derive(Debug, Clone, Default, PartialEq, Eq)]
pub struct Header {
    pub seq: u32,
    pub stamp: Time,
    pub frame_id: String,
}

impl Header {
    pub fn new(stamp_ns: i64, frame_id: &str) -> Self {
        Self {
            seq: 0,
            stamp: Time::from_ns(stamp_ns),
            frame_id: frame_id.to_owned(),
        }
    }
}

impl<'a> RosMessage<'a> for Header {
    fn read<R: WireRead<'a>>(r: &mut R) -> Result<Self, DecodeError> {
        let (seq, stamp) = if R::IS_ROS1 {
            let seq = r.read_u32()?;
            let sec = i64::from(r.read_u32()?);
            let nanosec = r.read_u32()?;
            (seq, Time { sec, nanosec })
        } else {
            let sec = i64::from(r.read_i32()?);
            let nanosec = r.read_u32()?;
            (0, Time { sec, nanosec })
        };
        // A time of a full second or more in `nanosec` is corrupt: read as
        // it is, it would move the stamp by seconds.
        if stamp.nanosec >= 1_000_000_000 {
            return Err(DecodeError::StampOutOfRange {
                nanosec: stamp.nanosec,
            });
        }
        let frame_id = r.read_str()?.to_owned();
        Ok(Self {
            seq,
            stamp,
            frame_id,
        })
    }

    fn write<W: WireWrite>(&self, w: &mut W) {
        // Out-of-range seconds wrap: the encoders build fixtures, and ROS itself
        // cannot represent such stamps either.
        if W::IS_ROS1 {
            w.write_u32(self.seq);
            w.write_u32(self.stamp.sec as u32);
        } else {
            w.write_i32(self.stamp.sec as i32);
        }
        w.write_u32(self.stamp.nanosec);
        w.write_str(&self.frame_id);
    }
}
wire_entry_points!(Header);

/// Minimum encoded size of a Header in either format (for sequence checks).
pub(super) const MIN_HEADER_BYTES: usize = 12;
