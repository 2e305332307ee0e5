//! Raw ROS message structs, field for field as in the `.msg` definitions, with
//! decoders for ROS 2 CDR and ROS 1 and the matching encoders.
//!
//! Codecs are written once against [`WireRead`] / [`WireWrite`]; the inherent
//! `decode_cdr` / `decode_ros1` / `encode_cdr` / `encode_ros1` methods wrap them.
//!
//! One file a ROS package: `header` (`std_msgs/Header`,
//! `builtin_interfaces/Time`), `geometry` (`geometry_msgs`), `sensor`
//! (`sensor_msgs`), `nav` (`nav_msgs`) and `tf` (`tf2_msgs`). Every message
//! is re-exported here, so its path is `ros::msgs::Name`.

use super::DecodeError;
use super::cdr::{WireRead, WireWrite};

/// A message with one codec shared by both wire formats.
pub trait RosMessage<'a>: Sized {
    fn read<R: WireRead<'a>>(r: &mut R) -> Result<Self, DecodeError>;
    fn write<W: WireWrite>(&self, w: &mut W);
}

/// Adds the format-specific entry points to a [`RosMessage`].
macro_rules! wire_entry_points {
    ($ty:ident $(<$lt:lifetime>)?) => {
        impl<'a> $ty $(<$lt>)? {
            /// Decodes a ROS 2 CDR payload (with its encapsulation header).
            pub fn decode_cdr(payload: &'a [u8]) -> Result<Self, $crate::ros::DecodeError> {
                let mut r = $crate::ros::cdr::CdrReader::new(payload)?;
                <Self as $crate::ros::msgs::RosMessage<'a>>::read(&mut r)
            }

            /// Decodes a ROS 1 payload.
            pub fn decode_ros1(payload: &'a [u8]) -> Result<Self, $crate::ros::DecodeError> {
                let mut r = $crate::ros::cdr::Ros1Reader::new(payload);
                <Self as $crate::ros::msgs::RosMessage<'a>>::read(&mut r)
            }

            /// Encodes as ROS 2 plain CDR with the encapsulation header.
            pub fn encode_cdr(&self, big_endian: bool) -> Vec<u8> {
                let mut w = $crate::ros::cdr::CdrWriter::new(big_endian);
                <Self as $crate::ros::msgs::RosMessage<'a>>::write(self, &mut w);
                w.into_bytes()
            }

            /// Encodes in ROS 1 serialization.
            pub fn encode_ros1(&self) -> Vec<u8> {
                let mut w = $crate::ros::cdr::Ros1Writer::new();
                <Self as $crate::ros::msgs::RosMessage<'a>>::write(self, &mut w);
                w.into_bytes()
            }
        }
    };
}

mod geometry;
mod header;
mod nav;
mod sensor;
mod tf;

pub use geometry::{
    Pose, PoseWithCovariance, Quaternion, Transform, TransformStamped, Twist, TwistStamped,
    TwistWithCovariance, Vector3,
};
pub use header::{Header, Time};
pub use nav::Odometry;
pub use sensor::{Imu, PointCloud2, PointField, datatype, pointcloud2_from_points};
pub use tf::TFMessage;
