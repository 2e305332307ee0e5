//! Static transform tree (from `/tf_static`) and the CLI extrinsic parser.
//!
//! Convention throughout: `a_from_b` maps coordinates given in frame `b` into
//! frame `a`, which is also the pose of frame `b` expressed in frame `a`
//! (the same convention as `FrameTransform::parent_from_child`).

use std::collections::{HashMap, HashSet};
use std::str::FromStr;

use nalgebra::{Isometry3, Quaternion, Translation3, UnitQuaternion};

use crate::model::{ExtrinsicInfo, ExtrinsicSource, FrameTransform};

/// Frame ids are compared without a leading '/': ROS 1 logs often write
/// "/base_link" where ROS 2 logs write "base_link", and both mean the same frame.
pub fn normalize_frame_id(frame_id: &str) -> &str {
    frame_id.strip_prefix('/').unwrap_or(frame_id)
}

/// A forest of frames, each child with exactly one parent (as tf requires).
#[derive(Debug, Clone, Default)]
pub struct TransformTree {
    /// child frame -> (parent frame, parent_from_child)
    parent_of: HashMap<String, (String, Isometry3<f64>)>,
}

impl TransformTree {
    pub fn new() -> Self {
        Self::default()
    }

    /// Adds or replaces (a later message wins) the edge parent -> child.
    pub fn insert(&mut self, transform: &FrameTransform) {
        let child = normalize_frame_id(&transform.child_frame).to_owned();
        let parent = normalize_frame_id(&transform.parent_frame).to_owned();
        if child == parent {
            // A self-loop carries no information and would make walks loop.
            return;
        }
        self.parent_of
            .insert(child, (parent, transform.parent_from_child));
    }

    /// Every frame the tree names, parents and children, sorted.
    pub fn frames(&self) -> Vec<String> {
        let mut frames: std::collections::BTreeSet<String> = std::collections::BTreeSet::new();
        for (child, (parent, _)) in &self.parent_of {
            frames.insert(child.clone());
            frames.insert(parent.clone());
        }
        frames.into_iter().collect()
    }

    /// Number of edges in the tree.
    pub fn len(&self) -> usize {
        self.parent_of.len()
    }

    pub fn is_empty(&self) -> bool {
        self.parent_of.is_empty()
    }

    /// `target_from_source`, through the common ancestor of the two frames.
    /// `None` when the frames are not connected. Equal frames give identity.
    pub fn lookup(&self, target_frame: &str, source_frame: &str) -> Option<Isometry3<f64>> {
        let target = normalize_frame_id(target_frame);
        let source = normalize_frame_id(source_frame);
        if target == source {
            return Some(Isometry3::identity());
        }
        // Every ancestor of `source` (itself included) with ancestor_from_source.
        let source_chain = self.ancestors(source);
        let source_poses: HashMap<&str, Isometry3<f64>> = source_chain
            .iter()
            .map(|(frame, pose)| (frame.as_str(), *pose))
            .collect();
        // Walk up from `target`; the first frame also above `source` is the
        // lowest common ancestor.
        for (frame, ancestor_from_target) in self.ancestors(target) {
            if let Some(ancestor_from_source) = source_poses.get(frame.as_str()) {
                return Some(ancestor_from_target.inverse() * ancestor_from_source);
            }
        }
        None
    }

    /// `frame` and all its ancestors, each with `ancestor_from_frame`, nearest first.
    /// Stops on a cycle (a malformed log) instead of looping forever.
    fn ancestors(&self, frame: &str) -> Vec<(String, Isometry3<f64>)> {
        let mut chain = vec![(frame.to_owned(), Isometry3::identity())];
        let mut seen: HashSet<String> = HashSet::from([frame.to_owned()]);
        let mut current = frame.to_owned();
        let mut current_from_frame = Isometry3::identity();
        while let Some((parent, parent_from_current)) = self.parent_of.get(&current) {
            if !seen.insert(parent.clone()) {
                break;
            }
            current_from_frame = parent_from_current * current_from_frame;
            current = parent.clone();
            chain.push((current.clone(), current_from_frame));
        }
        chain
    }
}

/// Resolves `motion_from_lidar` by priority: CLI value, equal frames, `/tf_static`,
/// identity (assumed). `sensor_pose` is the scan's `sensor_pose` (the points'
/// origin inside `lidar_frame`); it is composed in every case so that the
/// result maps the scan points themselves. The CLI value is read as the pose
/// of the scan's `frame_id` in the motion frame (what a tf edge would hold).
pub fn resolve_extrinsic(
    tree: &TransformTree,
    cli_motion_from_lidar: Option<&Isometry3<f64>>,
    lidar_frame: &str,
    sensor_pose: &Isometry3<f64>,
    motion_frame: &str,
) -> ExtrinsicInfo {
    let lidar = normalize_frame_id(lidar_frame).to_owned();
    let motion = normalize_frame_id(motion_frame).to_owned();
    let (motion_from_frame, source) = if let Some(cli) = cli_motion_from_lidar {
        (*cli, ExtrinsicSource::Cli)
    } else if lidar == motion {
        (Isometry3::identity(), ExtrinsicSource::SameFrame)
    } else if let Some(found) = tree.lookup(&motion, &lidar) {
        (found, ExtrinsicSource::TfStatic)
    } else {
        (Isometry3::identity(), ExtrinsicSource::IdentityAssumed)
    };
    ExtrinsicInfo {
        lidar_frame: lidar,
        motion_frame: motion,
        motion_from_lidar: motion_from_frame * sensor_pose,
        source,
    }
}

/// Why a `x,y,z,qx,qy,qz,qw` extrinsic string was refused.
#[derive(Debug, Clone, PartialEq, thiserror::Error)]
pub enum ExtrinsicParseError {
    #[error(
        "extrinsic must be 7 comma-separated numbers `x,y,z,qx,qy,qz,qw`, found {found} field(s)"
    )]
    WrongFieldCount { found: usize },
    #[error("extrinsic field {position} (`{name}`) is not a number: `{text}`")]
    NotANumber {
        position: usize,
        name: &'static str,
        text: String,
    },
    #[error("extrinsic field {position} (`{name}`) is not finite: `{text}`")]
    NotFinite {
        position: usize,
        name: &'static str,
        text: String,
    },
    #[error("extrinsic quaternion (qx,qy,qz,qw) is zero; it cannot describe a rotation")]
    ZeroQuaternion,
}

const EXTRINSIC_FIELD_NAMES: [&str; 7] = ["x", "y", "z", "qx", "qy", "qz", "qw"];

/// An extrinsic from the command line: `x,y,z,qx,qy,qz,qw` (metres, Hamilton
/// quaternion with w last as in ROS messages), meaning `motion_from_lidar`:
/// the LiDAR's pose in the velocity/IMU frame. The quaternion is normalised.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Extrinsic(pub Isometry3<f64>);

impl FromStr for Extrinsic {
    type Err = ExtrinsicParseError;

    fn from_str(text: &str) -> Result<Self, Self::Err> {
        parse_extrinsic(text).map(Extrinsic)
    }
}

/// An extrinsic as `x,y,z,qx,qy,qz,qw` (the form [`parse_extrinsic`] reads),
/// for the run's metadata record.
pub(crate) fn serialize_extrinsic<S: serde::Serializer>(
    extrinsic: &Option<Isometry3<f64>>,
    serializer: S,
) -> Result<S::Ok, S::Error> {
    let text = extrinsic.map(|pose| {
        let t = pose.translation.vector;
        let q = pose.rotation.quaternion();
        format!("{},{},{},{},{},{},{}", t.x, t.y, t.z, q.i, q.j, q.k, q.w)
    });
    serde::Serialize::serialize(&text, serializer)
}

/// See [`Extrinsic`].
pub fn parse_extrinsic(text: &str) -> Result<Isometry3<f64>, ExtrinsicParseError> {
    let fields: Vec<&str> = text.split(',').map(str::trim).collect();
    if fields.len() != EXTRINSIC_FIELD_NAMES.len() {
        return Err(ExtrinsicParseError::WrongFieldCount {
            found: fields.len(),
        });
    }
    let mut values = [0.0_f64; 7];
    for (index, (field, value)) in fields.iter().zip(values.iter_mut()).enumerate() {
        let name = EXTRINSIC_FIELD_NAMES[index];
        let parsed: f64 = field.parse().map_err(|_| ExtrinsicParseError::NotANumber {
            position: index + 1,
            name,
            text: (*field).to_owned(),
        })?;
        if !parsed.is_finite() {
            return Err(ExtrinsicParseError::NotFinite {
                position: index + 1,
                name,
                text: (*field).to_owned(),
            });
        }
        *value = parsed;
    }
    let [x, y, z, qx, qy, qz, qw] = values;
    let quaternion = Quaternion::new(qw, qx, qy, qz);
    // Exact zero and denormal-small quaternions have no direction to normalise to.
    let rotation = UnitQuaternion::try_new(quaternion, f64::EPSILON)
        .ok_or(ExtrinsicParseError::ZeroQuaternion)?;
    Ok(Isometry3::from_parts(Translation3::new(x, y, z), rotation))
}

#[cfg(test)]
mod tests {
    use super::*;
    use nalgebra::{Point3, Vector3};
    use std::f64::consts::FRAC_PI_2;

    fn edge(parent: &str, child: &str, pose: Isometry3<f64>) -> FrameTransform {
        FrameTransform {
            stamp_ns: 0,
            parent_frame: parent.into(),
            child_frame: child.into(),
            parent_from_child: pose,
        }
    }

    fn translation(x: f64, y: f64, z: f64) -> Isometry3<f64> {
        Isometry3::translation(x, y, z)
    }

    fn yaw(angle_rad: f64) -> Isometry3<f64> {
        Isometry3::rotation(Vector3::z() * angle_rad)
    }

    /// base_link -> chassis (1 m ahead) -> lidar (0.5 m up, yawed 90 deg left).
    fn two_hop_tree() -> TransformTree {
        let mut tree = TransformTree::new();
        tree.insert(&edge("/base_link", "chassis", translation(1.0, 0.0, 0.0)));
        tree.insert(&edge(
            "chassis",
            "/lidar",
            translation(0.0, 0.0, 0.5) * yaw(FRAC_PI_2),
        ));
        tree
    }

    fn assert_point_close(actual: Point3<f64>, expected: [f64; 3]) {
        let expected = Point3::from(expected);
        assert!(
            (actual - expected).norm() < 1e-12,
            "{actual:?} != {expected:?}"
        );
    }

    #[test]
    fn two_hop_chain_maps_child_points_into_root() {
        let tree = two_hop_tree();
        let base_from_lidar = tree.lookup("base_link", "lidar").unwrap();
        // The LiDAR origin sits 1 m ahead and 0.5 m up.
        assert_point_close(base_from_lidar * Point3::origin(), [1.0, 0.0, 0.5]);
        // LiDAR x (its forward) points along base y (left) after the 90 deg yaw.
        assert_point_close(
            base_from_lidar * Point3::new(1.0, 0.0, 0.0),
            [1.0, 1.0, 0.5],
        );
    }

    #[test]
    fn inverse_direction_is_the_inverse() {
        let tree = two_hop_tree();
        let base_from_lidar = tree.lookup("/base_link", "/lidar").unwrap();
        let lidar_from_base = tree.lookup("lidar", "base_link").unwrap();
        let product = base_from_lidar * lidar_from_base;
        assert!(
            (product.to_homogeneous() - Isometry3::<f64>::identity().to_homogeneous()).norm()
                < 1e-12
        );
        // Base origin seen from the LiDAR: 1 m behind in base x = LiDAR +y after yaw.
        assert_point_close(lidar_from_base * Point3::origin(), [0.0, 1.0, -0.5]);
    }

    #[test]
    fn siblings_are_joined_through_their_common_parent() {
        let mut tree = TransformTree::new();
        tree.insert(&edge("base_link", "lidar", translation(1.0, 0.0, 0.0)));
        tree.insert(&edge("base_link", "imu", translation(0.0, 2.0, 0.0)));
        let imu_from_lidar = tree.lookup("imu", "lidar").unwrap();
        assert_point_close(imu_from_lidar * Point3::origin(), [1.0, -2.0, 0.0]);
    }

    #[test]
    fn missing_path_and_unknown_frames_give_none() {
        let mut tree = two_hop_tree();
        tree.insert(&edge("odom", "imu", translation(0.0, 1.0, 0.0)));
        assert!(tree.lookup("imu", "lidar").is_none());
        assert!(tree.lookup("base_link", "nowhere").is_none());
        // Equal frames are identity even when unknown to the tree.
        assert_eq!(tree.lookup("x", "/x"), Some(Isometry3::identity()));
    }

    #[test]
    fn cycle_does_not_hang() {
        let mut tree = TransformTree::new();
        tree.insert(&edge("a", "b", translation(1.0, 0.0, 0.0)));
        tree.insert(&edge("b", "a", translation(1.0, 0.0, 0.0)));
        assert!(tree.lookup("c", "a").is_none());
    }

    #[test]
    fn resolve_prefers_cli_then_same_frame_then_tf_then_identity() {
        let tree = two_hop_tree();
        let sensor_pose = Isometry3::identity();
        let cli = translation(5.0, 0.0, 0.0);
        let from_cli = resolve_extrinsic(&tree, Some(&cli), "lidar", &sensor_pose, "base_link");
        assert_eq!(from_cli.source, ExtrinsicSource::Cli);
        assert_eq!(from_cli.motion_from_lidar, cli);

        let same = resolve_extrinsic(&tree, None, "/lidar", &sensor_pose, "lidar");
        assert_eq!(same.source, ExtrinsicSource::SameFrame);

        let from_tf = resolve_extrinsic(&tree, None, "lidar", &sensor_pose, "base_link");
        assert_eq!(from_tf.source, ExtrinsicSource::TfStatic);
        assert_point_close(
            from_tf.motion_from_lidar * Point3::origin(),
            [1.0, 0.0, 0.5],
        );

        let assumed = resolve_extrinsic(&tree, None, "lidar", &sensor_pose, "gps");
        assert_eq!(assumed.source, ExtrinsicSource::IdentityAssumed);
        assert_eq!(assumed.motion_from_lidar, Isometry3::identity());
    }

    #[test]
    fn resolve_composes_the_scan_sensor_pose() {
        let tree = TransformTree::new();
        let sensor_pose = translation(0.0, 0.0, 2.0);
        let info = resolve_extrinsic(&tree, None, "lidar", &sensor_pose, "lidar");
        assert_point_close(info.motion_from_lidar * Point3::origin(), [0.0, 0.0, 2.0]);
    }

    #[test]
    fn parses_a_good_extrinsic_and_normalises_the_quaternion() {
        // 90 deg yaw written unnormalised (scaled by 2).
        let pose =
            parse_extrinsic(" 1.5, -0.25,2 ,0,0,1.4142135623730951,1.4142135623730951").unwrap();
        assert_point_close(pose * Point3::origin(), [1.5, -0.25, 2.0]);
        assert!((pose.rotation.angle() - FRAC_PI_2).abs() < 1e-12);
        assert!((pose.rotation.quaternion().norm() - 1.0).abs() < 1e-12);
        let via_from_str: Extrinsic = "0,0,0,0,0,0,1".parse().unwrap();
        assert_eq!(via_from_str.0, Isometry3::identity());
    }

    #[test]
    fn refuses_bad_extrinsic_strings_with_clear_errors() {
        assert_eq!(
            parse_extrinsic("1,2,3"),
            Err(ExtrinsicParseError::WrongFieldCount { found: 3 })
        );
        assert_eq!(
            parse_extrinsic("1,2,3,0,0,0,1,9"),
            Err(ExtrinsicParseError::WrongFieldCount { found: 8 })
        );
        let not_number = parse_extrinsic("1,2,abc,0,0,0,1").unwrap_err();
        assert_eq!(
            not_number,
            ExtrinsicParseError::NotANumber {
                position: 3,
                name: "z",
                text: "abc".into()
            }
        );
        assert!(not_number.to_string().contains("`z`"));
        assert!(matches!(
            parse_extrinsic("1,2,3,0,0,0,NaN"),
            Err(ExtrinsicParseError::NotFinite { position: 7, .. })
        ));
        assert!(matches!(
            parse_extrinsic("1,2,3,0,0,,1"),
            Err(ExtrinsicParseError::NotANumber { position: 6, .. })
        ));
        assert_eq!(
            parse_extrinsic("1,2,3,0,0,0,0"),
            Err(ExtrinsicParseError::ZeroQuaternion)
        );
    }
}
