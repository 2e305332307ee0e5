//! `tf2_msgs/TFMessage`: a list of stamped transforms.

use super::header::MIN_HEADER_BYTES;
use super::{RosMessage, TransformStamped};
use crate::ros::DecodeError;
use crate::ros::cdr::{WireRead, WireWrite};

/// Lower bound of an encoded TransformStamped: header, child id length, 7 float64.
const MIN_TRANSFORM_STAMPED_BYTES: usize = MIN_HEADER_BYTES + 4 + 7 * 8;

/// `tf2_msgs/TFMessage` (same layout as ROS 1 `tf/tfMessage`).
#[derive(Debug, Clone, Default, PartialEq)]
pub struct TFMessage {
    pub transforms: Vec<TransformStamped>,
}

impl<'a> RosMessage<'a> for TFMessage {
    fn read<R: WireRead<'a>>(r: &mut R) -> Result<Self, DecodeError> {
        let n = r.read_seq_len(MIN_TRANSFORM_STAMPED_BYTES)?;
        let mut transforms = Vec::with_capacity(n);
        for _ in 0..n {
            transforms.push(TransformStamped::read(r)?);
        }
        Ok(Self { transforms })
    }

    fn write<W: WireWrite>(&self, w: &mut W) {
        w.write_seq_len(self.transforms.len());
        for t in &self.transforms {
            t.write(w);
        }
    }
}
wire_entry_points!(TFMessage);
