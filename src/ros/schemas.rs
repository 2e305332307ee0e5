//! Schema texts (`ros2msg` / `ros1msg`, dependencies concatenated the way
//! `ros2 bag` and `rosbag` write them) for the message types we write into
//! synthetic and fixture logs, so that Foxglove and other readers can decode
//! them.

const SEP: &str =
    "================================================================================\n";

const HEADER_ROS2: &str = "builtin_interfaces/Time stamp\nstring frame_id\n";
const HEADER_ROS1: &str = "uint32 seq\ntime stamp\nstring frame_id\n";
const TIME_ROS2: &str = "int32 sec\nuint32 nanosec\n";
const VECTOR3: &str = "float64 x\nfloat64 y\nfloat64 z\n";
const QUATERNION: &str = "float64 x 0\nfloat64 y 0\nfloat64 z 0\nfloat64 w 1\n";
const POINT: &str = "float64 x\nfloat64 y\nfloat64 z\n";
const POINT_FIELD: &str = "uint8 INT8    = 1\nuint8 UINT8   = 2\nuint8 INT16   = 3\nuint8 UINT16  = 4\nuint8 INT32   = 5\nuint8 UINT32  = 6\nuint8 FLOAT32 = 7\nuint8 FLOAT64 = 8\nstring name\nuint32 offset\nuint8  datatype\nuint32 count\n";

/// The ROS dialect a schema is written for.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum RosDialect {
    Ros1,
    Ros2,
}

impl RosDialect {
    /// MCAP schema encoding.
    pub fn schema_encoding(self) -> &'static str {
        match self {
            RosDialect::Ros1 => "ros1msg",
            RosDialect::Ros2 => "ros2msg",
        }
    }

    /// MCAP message encoding.
    pub fn message_encoding(self) -> &'static str {
        match self {
            RosDialect::Ros1 => "ros1",
            RosDialect::Ros2 => "cdr",
        }
    }

    /// Schema name of `package/Type` in this dialect.
    pub fn schema_name(self, package: &str, type_name: &str) -> String {
        match self {
            RosDialect::Ros1 => format!("{package}/{type_name}"),
            RosDialect::Ros2 => format!("{package}/msg/{type_name}"),
        }
    }
}

/// A dependency's section. Its `MSG:` name is the type as the fields spell
/// it, `package/Type` in both dialects (what `ros2 bag` writes): Foxglove's
/// and Lichtblick's parser looks a field's type up by that exact name, and a
/// ROS 2 `package/msg/Type` there hides the whole topic.
fn dep(package: &str, type_name: &str, text: &str) -> String {
    format!("{SEP}MSG: {package}/{type_name}\n{text}")
}

fn header_deps(dialect: RosDialect) -> String {
    match dialect {
        RosDialect::Ros1 => dep("std_msgs", "Header", HEADER_ROS1),
        RosDialect::Ros2 => {
            dep("std_msgs", "Header", HEADER_ROS2) + &dep("builtin_interfaces", "Time", TIME_ROS2)
        }
    }
}

pub fn point_cloud2(dialect: RosDialect) -> String {
    let main = "std_msgs/Header header\nuint32 height\nuint32 width\nsensor_msgs/PointField[] fields\nbool    is_bigendian\nuint32  point_step\nuint32  row_step\nuint8[] data\nbool is_dense\n";
    format!(
        "{main}{}{}",
        header_deps(dialect),
        dep("sensor_msgs", "PointField", POINT_FIELD)
    )
}

pub fn imu(dialect: RosDialect) -> String {
    let main = "std_msgs/Header header\ngeometry_msgs/Quaternion orientation\nfloat64[9] orientation_covariance\ngeometry_msgs/Vector3 angular_velocity\nfloat64[9] angular_velocity_covariance\ngeometry_msgs/Vector3 linear_acceleration\nfloat64[9] linear_acceleration_covariance\n";
    format!(
        "{main}{}{}{}",
        header_deps(dialect),
        dep("geometry_msgs", "Quaternion", QUATERNION),
        dep("geometry_msgs", "Vector3", VECTOR3)
    )
}

pub fn twist_stamped(dialect: RosDialect) -> String {
    let main = "std_msgs/Header header\ngeometry_msgs/Twist twist\n";
    format!(
        "{main}{}{}{}",
        header_deps(dialect),
        dep(
            "geometry_msgs",
            "Twist",
            "Vector3  linear\nVector3  angular\n"
        ),
        dep("geometry_msgs", "Vector3", VECTOR3)
    )
}

pub fn odometry(dialect: RosDialect) -> String {
    let main = "std_msgs/Header header\nstring child_frame_id\ngeometry_msgs/PoseWithCovariance pose\ngeometry_msgs/TwistWithCovariance twist\n";
    format!(
        "{main}{}{}{}{}{}{}{}",
        header_deps(dialect),
        dep(
            "geometry_msgs",
            "PoseWithCovariance",
            "Pose pose\nfloat64[36] covariance\n"
        ),
        dep(
            "geometry_msgs",
            "Pose",
            "Point position\nQuaternion orientation\n"
        ),
        dep("geometry_msgs", "Point", POINT),
        dep("geometry_msgs", "Quaternion", QUATERNION),
        dep(
            "geometry_msgs",
            "TwistWithCovariance",
            "Twist twist\nfloat64[36] covariance\n"
        ),
        dep(
            "geometry_msgs",
            "Twist",
            "Vector3  linear\nVector3  angular\n"
        ) + &dep("geometry_msgs", "Vector3", VECTOR3)
    )
}

pub fn tf_message(dialect: RosDialect) -> String {
    let main = "geometry_msgs/TransformStamped[] transforms\n";
    format!(
        "{main}{}{}{}{}{}",
        dep(
            "geometry_msgs",
            "TransformStamped",
            "std_msgs/Header header\nstring child_frame_id\nTransform transform\n"
        ),
        header_deps(dialect),
        dep(
            "geometry_msgs",
            "Transform",
            "Vector3 translation\nQuaternion rotation\n"
        ),
        dep("geometry_msgs", "Vector3", VECTOR3),
        dep("geometry_msgs", "Quaternion", QUATERNION)
    )
}
