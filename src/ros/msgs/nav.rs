//! `nav_msgs/Odometry`.

use super::{
    Header, Pose, PoseWithCovariance, Quaternion, RosMessage, Twist, TwistWithCovariance, Vector3,
};
use crate::ros::DecodeError;
use crate::ros::cdr::{WireRead, WireWrite};

/// `nav_msgs/Odometry`.
#[derive(Debug, Clone, PartialEq)]
pub struct Odometry {
    pub header: Header,
    pub child_frame_id: String,
    pub pose: PoseWithCovariance,
    pub twist: TwistWithCovariance,
}

impl<'a> RosMessage<'a> for Odometry {
    fn read<R: WireRead<'a>>(r: &mut R) -> Result<Self, DecodeError> {
        Ok(Self {
            header: Header::read(r)?,
            child_frame_id: r.read_str()?.to_owned(),
            pose: PoseWithCovariance {
                pose: Pose {
                    position: Vector3::read(r)?,
                    orientation: Quaternion::read(r)?,
                },
                covariance: r.read_f64_array()?,
            },
            twist: TwistWithCovariance {
                twist: Twist::read(r)?,
                covariance: r.read_f64_array()?,
            },
        })
    }

    fn write<W: WireWrite>(&self, w: &mut W) {
        self.header.write(w);
        w.write_str(&self.child_frame_id);
        self.pose.pose.position.write(w);
        self.pose.pose.orientation.write(w);
        w.write_f64_array(&self.pose.covariance);
        self.twist.twist.write(w);
        w.write_f64_array(&self.twist.covariance);
    }
}
wire_entry_points!(Odometry);
