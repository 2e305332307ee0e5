//! Message decoding: from an MCAP message's schema name, encoding and payload
//! to the typed [`Decoded`] structs the pipeline uses.
//!
//! [`decode`] is the single entry point; the converters from raw ROS / Foxglove
//! messages are public so fixtures and tests can use them directly.

mod pointcloud;

use nalgebra::{Isometry3, Translation3};
use prost::Message as _;

pub use crate::ros::DecodeError;
pub use crate::ros::msgs::pointcloud2_from_points;
pub use pointcloud::{scan_from_foxglove, scan_from_pointcloud2};

use crate::model::{Decoded, FrameTransform, ImuSample, VelocitySample, VelocitySourceKind};
use crate::ros::cdr::{CdrReader, Ros1Reader, WireRead};
use crate::ros::msgs::{Imu, Odometry, PointCloud2, RosMessage, TFMessage, TwistStamped};
use pointcloud::normalize_frame_id;

/// The message types the pipeline understands.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Hash)]
pub enum MessageKind {
    PointCloud2,
    FoxglovePointCloud,
    Imu,
    TwistStamped,
    Odometry,
    TfMessage,
}

impl MessageKind {
    /// Recognises ROS 2 (`pkg/msg/Type`), ROS 1 (`pkg/Type`) and Foxglove
    /// protobuf (`foxglove.PointCloud`) schema names.
    pub fn from_schema_name(name: &str) -> Option<Self> {
        let name = name.trim();
        if name == "foxglove.PointCloud" {
            return Some(Self::FoxglovePointCloud);
        }
        let (package, ty) = match name.split_once("/msg/") {
            Some(parts) => parts,
            None => name.split_once('/')?,
        };
        Some(match (package, ty) {
            ("sensor_msgs", "PointCloud2") => Self::PointCloud2,
            ("sensor_msgs", "Imu") => Self::Imu,
            ("geometry_msgs", "TwistStamped") => Self::TwistStamped,
            ("nav_msgs", "Odometry") => Self::Odometry,
            // ROS 1 `tf/tfMessage` has the same layout as `tf2_msgs/TFMessage`.
            ("tf2_msgs", "TFMessage") | ("tf", "tfMessage") => Self::TfMessage,
            _ => return None,
        })
    }

    /// Human-readable name for messages and errors.
    pub fn name(self) -> &'static str {
        match self {
            Self::PointCloud2 => "sensor_msgs/PointCloud2",
            Self::FoxglovePointCloud => "foxglove.PointCloud",
            Self::Imu => "sensor_msgs/Imu",
            Self::TwistStamped => "geometry_msgs/TwistStamped",
            Self::Odometry => "nav_msgs/Odometry",
            Self::TfMessage => "tf2_msgs/TFMessage",
        }
    }
}

/// Wire encodings of MCAP channels (`message_encoding`).
#[derive(Debug, Clone, Copy, PartialEq, Eq, Hash)]
pub enum WireEncoding {
    Cdr,
    Ros1,
    Protobuf,
}

impl WireEncoding {
    pub fn from_message_encoding(encoding: &str) -> Option<Self> {
        match encoding {
            "cdr" => Some(Self::Cdr),
            "ros1" => Some(Self::Ros1),
            "protobuf" => Some(Self::Protobuf),
            _ => None,
        }
    }

    pub fn name(self) -> &'static str {
        match self {
            Self::Cdr => "cdr",
            Self::Ros1 => "ros1",
            Self::Protobuf => "protobuf",
        }
    }
}

/// Guards against hostile or corrupt messages, and which per-point field
/// names a merged cloud's sensor.
#[derive(Debug, Clone, PartialEq, Eq)]
pub struct DecodeLimits {
    /// Largest `width * height` (or foxglove point count) accepted.
    pub max_points: usize,
    /// The field read into [`crate::model::Scan::sensor_ids`].
    pub sensor_field: SensorField,
}

impl Default for DecodeLimits {
    fn default() -> Self {
        Self {
            max_points: 4_000_000,
            sensor_field: SensorField::default(),
        }
    }
}

/// Which per-point field says which sensor a point of a merged cloud (a
/// concatenated `base_link` cloud) came from (`--split-field`).
#[derive(Debug, Clone, Default, PartialEq, Eq, serde::Serialize)]
#[serde(rename_all = "snake_case")]
pub enum SensorField {
    /// The first of [`SENSOR_FIELDS`] the cloud has, of an integer type.
    #[default]
    Auto,
    /// None: a merged cloud stays one sensor (`--split-field none`).
    Off,
    /// This field (of an integer type).
    Named(String),
}

/// Field names that number a point's sensor (never its laser: `ring`,
/// `laser_id` and `channel` are rings), as merging nodes write them.
pub const SENSOR_FIELDS: [&str; 4] = ["sensor_id", "lidar_id", "sensor", "lidar_index"];

/// Decodes one message payload. `is_static_tf` marks TFMessages from
/// `/tf_static`; it is ignored for other kinds.
pub fn decode(
    kind: MessageKind,
    encoding: WireEncoding,
    is_static_tf: bool,
    payload: &[u8],
    limits: &DecodeLimits,
) -> Result<Decoded, DecodeError> {
    match (kind, encoding) {
        (MessageKind::FoxglovePointCloud, WireEncoding::Protobuf) => {
            let cloud = foxglove::messages::PointCloud::decode(payload)?;
            Ok(Decoded::Scan(scan_from_foxglove(&cloud, limits)?))
        }
        (MessageKind::FoxglovePointCloud, _) | (_, WireEncoding::Protobuf) => {
            Err(DecodeError::UnsupportedEncoding {
                kind: kind.name(),
                encoding: encoding.name(),
            })
        }
        (_, WireEncoding::Cdr) => {
            let mut r = CdrReader::new(payload)?;
            decode_ros(kind, &mut r, is_static_tf, limits)
        }
        (_, WireEncoding::Ros1) => {
            let mut r = Ros1Reader::new(payload);
            decode_ros(kind, &mut r, is_static_tf, limits)
        }
    }
}

/// Decodes a ROS message of `kind` from either ROS wire format.
fn decode_ros<'a, R: WireRead<'a>>(
    kind: MessageKind,
    r: &mut R,
    is_static_tf: bool,
    limits: &DecodeLimits,
) -> Result<Decoded, DecodeError> {
    Ok(match kind {
        MessageKind::PointCloud2 => {
            Decoded::Scan(scan_from_pointcloud2(&PointCloud2::read(r)?, limits)?)
        }
        MessageKind::Imu => {
            let imu = Imu::read(r)?;
            finite("angular_velocity", &imu.angular_velocity)?;
            Decoded::Imu(imu_sample_from_imu(&imu))
        }
        MessageKind::TwistStamped => {
            let twist = TwistStamped::read(r)?;
            finite("twist.linear", &twist.twist.linear)?;
            finite("twist.angular", &twist.twist.angular)?;
            Decoded::Velocity(velocity_from_twist_stamped(&twist))
        }
        MessageKind::Odometry => {
            let odometry = Odometry::read(r)?;
            finite("twist.twist.linear", &odometry.twist.twist.linear)?;
            finite("twist.twist.angular", &odometry.twist.twist.angular)?;
            Decoded::Velocity(velocity_from_odometry(&odometry))
        }
        MessageKind::TfMessage => Decoded::Transforms {
            transforms: transforms_from_tf_message(&TFMessage::read(r)?)?,
            is_static: is_static_tf,
        },
        // Handled (refused) by `decode` before getting here.
        MessageKind::FoxglovePointCloud => {
            return Err(DecodeError::UnsupportedEncoding {
                kind: kind.name(),
                encoding: if R::IS_ROS1 { "ros1" } else { "cdr" },
            });
        }
    })
}

/// A motion sample with a NaN or an infinity would poison every pair it is
/// interpolated into: the message is bad, not the pairs.
fn finite(field: &'static str, v: &crate::ros::msgs::Vector3) -> Result<(), DecodeError> {
    if v.x.is_finite() && v.y.is_finite() && v.z.is_finite() {
        return Ok(());
    }
    Err(DecodeError::NotFinite {
        field,
        value: format!("[{}, {}, {}]", v.x, v.y, v.z),
    })
}

/// `sensor_msgs/Imu` to [`ImuSample`]. The orientation is dropped when the
/// driver marks it unknown (`covariance[0] == -1`, per the message docs) or
/// leaves it all zeros (common in drivers without an orientation filter).
pub fn imu_sample_from_imu(msg: &Imu) -> ImuSample {
    let q = msg.orientation;
    let all_zero = q.x == 0.0 && q.y == 0.0 && q.z == 0.0 && q.w == 0.0;
    let orientation = if msg.orientation_covariance[0] == -1.0 || all_zero {
        None
    } else {
        q.to_unit()
    };
    ImuSample {
        stamp_ns: msg.header.stamp.to_ns(),
        frame_id: normalize_frame_id(&msg.header.frame_id),
        angular_velocity_radps: msg.angular_velocity.to_nalgebra(),
        linear_acceleration_mps2: msg.linear_acceleration.to_nalgebra(),
        orientation,
    }
}

/// `geometry_msgs/TwistStamped` to [`VelocitySample`] in the header frame.
pub(crate) fn velocity_from_twist_stamped(msg: &TwistStamped) -> VelocitySample {
    VelocitySample {
        stamp_ns: msg.header.stamp.to_ns(),
        frame_id: normalize_frame_id(&msg.header.frame_id),
        linear_mps: msg.twist.linear.to_nalgebra(),
        angular_radps: msg.twist.angular.to_nalgebra(),
        source: VelocitySourceKind::TwistStamped,
    }
}

/// `nav_msgs/Odometry` to [`VelocitySample`]: by ROS convention the twist is in
/// `child_frame_id`; an empty child frame falls back to the header frame.
pub fn velocity_from_odometry(msg: &Odometry) -> VelocitySample {
    let frame = if msg.child_frame_id.is_empty() {
        &msg.header.frame_id
    } else {
        &msg.child_frame_id
    };
    VelocitySample {
        stamp_ns: msg.header.stamp.to_ns(),
        frame_id: normalize_frame_id(frame),
        linear_mps: msg.twist.twist.linear.to_nalgebra(),
        angular_radps: msg.twist.twist.angular.to_nalgebra(),
        source: VelocitySourceKind::Odometry,
    }
}

/// `tf2_msgs/TFMessage` to [`FrameTransform`]s. A transform with a zero or
/// non-finite rotation fails the whole message, as tf2 itself refuses it.
pub(crate) fn transforms_from_tf_message(
    msg: &TFMessage,
) -> Result<Vec<FrameTransform>, DecodeError> {
    msg.transforms
        .iter()
        .map(|t| {
            let (v, q) = (t.transform.translation, t.transform.rotation);
            let rotation = q.to_unit().ok_or_else(|| DecodeError::InvalidQuaternion {
                context: format!("transform {} -> {}", t.header.frame_id, t.child_frame_id),
                x: q.x,
                y: q.y,
                z: q.z,
                w: q.w,
            })?;
            Ok(FrameTransform {
                stamp_ns: t.header.stamp.to_ns(),
                parent_frame: normalize_frame_id(&t.header.frame_id),
                child_frame: normalize_frame_id(&t.child_frame_id),
                parent_from_child: Isometry3::from_parts(
                    Translation3::new(v.x, v.y, v.z),
                    rotation,
                ),
            })
        })
        .collect()
}
