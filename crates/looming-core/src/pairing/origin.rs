//! Where the LiDAR is in its cloud's frame. The range image, the rings, the
//! column times and the ego motion are all built around the origin of the
//! sensor's rays; a cloud published in the vehicle frame (Waymo, Argoverse
//! 2, Autoware's `base_link`) or after a transform filter has its points
//! about another origin, and around that origin its lasers' cones smear
//! into each other (KITTI in `base_link`: 108 "rings", 0.7 % trusted).
//!
//! The origin is found on a sensor's first scan (`origin_track` follows it
//! over the log), by priority:
//! 1. `--sensor-frame`: the transform from the cloud's frame to that frame;
//! 2. a cloud frame whose name says LiDAR (`velo_link`, `lidar`, `os_sensor`,
//!    ...) is the sensor's own;
//! 3. `/tf_static` and `/tf`: a frame connected to the cloud's whose name
//!    says LiDAR (of several, the one about whose origin the rings are
//!    narrowest); when only `/tf` reaches it (a cloud in a world frame), it
//!    is looked up again at every scan's stamp;
//! 4. the geometry, where the rings are known without the origin (a ring
//!    field, an organized cloud's rows, the laser or firing order): the
//!    point about which each ring's returns lie closest to one elevation (a
//!    laser fires at one elevation; about any other point its cone smears).
//!    Its position and tilt (roll, pitch) are estimated (`origin_search`);
//!    its yaw changes no elevation and is kept. Searched about the cloud's
//!    origin, then, in a world frame where the sensor may be anywhere,
//!    about the centre of its tightest ring. Without such rings the cloud's
//!    origin is kept, and said.
//!
//! The RMS spread of the returns' elevations about their ring's mean
//! (`ring_spread_deg`) is the residual: hundredths of a degree about a
//! spinning sensor's origin, tenths or more about another point. A cloud
//! whose best origin still leaves its rings spread is flagged: its rays do
//! not meet at one point (several sensors merged, or a tilted one).

use nalgebra::{Isometry3, Point3};

use super::frames::{TransformTree, normalize_frame_id};
use super::origin_search::{
    MERGED_SPREAD_ABOUT_TRANSFORM_DEG, RingedSample, estimate_anywhere, ring_spread_deg,
    ringed_sample,
};
use crate::model::{OriginSource, Scan, SensorOrigin};

/// Frame names that say LiDAR.
const LIDAR_NAMES: [&str; 14] = [
    "lidar",
    "velo",
    "laser",
    "ouster",
    "os_sensor",
    "os_lidar",
    "hesai",
    "pandar",
    "livox",
    "rslidar",
    "robosense",
    "vlp",
    "hdl",
    "innoviz",
];

/// Whether a frame's name says it is a LiDAR's.
pub fn looks_like_lidar_frame(frame: &str) -> bool {
    let name = normalize_frame_id(frame).to_ascii_lowercase();
    LIDAR_NAMES.iter().any(|hint| name.contains(hint))
}

/// Where `scan`'s sensor is (see the module's priorities; `period_s`, the
/// scan period, lets the rings be found by the point order), and what the
/// user should hear of it.
///
/// `tree` holds `/tf_static` and `/tf` at the scan's stamp, `statics` the
/// static part: an origin only `/tf` reaches moves with the cloud's frame
/// ([`OriginSource::Tf`], looked up again per scan with [`at_stamp`]).
pub fn locate(
    scan: &Scan,
    (tree, statics): (&TransformTree, &TransformTree),
    sensor_frame: Option<&str>,
    period_s: f64,
) -> (SensorOrigin, Vec<String>) {
    let (mut origin, warning) = find(scan, tree, sensor_frame, period_s);
    if let Some(frame) = &origin.sensor_frame
        && statics.lookup(&scan.frame_id, frame).is_none()
    {
        origin.source = OriginSource::Tf;
    }
    let mut warnings: Vec<String> = warning.into_iter().collect();
    if origin.several_origins {
        warnings.push(format!(
            "{}: the returns' rays do not meet at one point (ring spread {:.2} deg about the best origin): the cloud merges several sensors, or its sensor is tilted in frame `{}`; its looming is unreliable (a merged cloud whose points carry their sensor in a field is split by it: sensor_id, lidar_id, ...)",
            scan.frame_id,
            origin.ring_spread_deg.unwrap_or(f64::NAN),
            scan.frame_id
        ));
    }
    (origin, warnings)
}

/// [`locate`]'s search, and a warning about how it went.
fn find(
    scan: &Scan,
    tree: &TransformTree,
    sensor_frame: Option<&str>,
    period_s: f64,
) -> (SensorOrigin, Option<String>) {
    let mut warning = None;
    let cloud_frame = normalize_frame_id(&scan.frame_id);
    // Points are un-posed: in the frame of the cloud's origin inside frame_id.
    let to_points =
        |frame_from_sensor: Isometry3<f64>| scan.sensor_pose.inverse() * frame_from_sensor;
    if let Some(frame) = sensor_frame {
        if let Some(found) = tree.lookup(cloud_frame, frame) {
            let mut origin = SensorOrigin::at(OriginSource::SensorFrameOption, to_points(found));
            origin.sensor_frame = Some(normalize_frame_id(frame).to_owned());
            return (origin, None);
        }
        warning = Some(format!(
            "--sensor-frame {frame}: no transform connects it to the cloud's frame `{cloud_frame}`; the sensor's origin is found without it"
        ));
    }
    if looks_like_lidar_frame(cloud_frame) {
        return (SensorOrigin::cloud_frame(), warning);
    }
    let candidates: Vec<(String, Isometry3<f64>)> = tree
        .frames()
        .into_iter()
        .filter(|frame| frame != cloud_frame && looks_like_lidar_frame(frame))
        .filter_map(|frame| {
            let found = tree.lookup(cloud_frame, &frame)?;
            Some((frame, to_points(found)))
        })
        .collect();
    let Some(sample) = ringed_sample(scan, period_s) else {
        let origin = match candidates.into_iter().next() {
            Some((frame, pose)) => {
                let mut origin = SensorOrigin::at(OriginSource::TfStatic, pose);
                origin.sensor_frame = Some(frame);
                origin
            }
            None => {
                warning.get_or_insert(format!(
                    "frame `{cloud_frame}` does not name a LiDAR, no transform leads from it to one, and its clouds carry no rings to find the sensor by: its origin is taken as the sensor's (give --sensor-frame if it is not)"
                ));
                SensorOrigin::cloud_frame()
            }
        };
        return (origin, warning);
    };
    let mut origin = if candidates.is_empty() {
        estimate_anywhere(&sample)
    } else {
        best_candidate(&sample, candidates)
    };
    origin.cloud_origin_ring_spread_deg = ring_spread_deg(&sample, &Isometry3::identity());
    (origin, warning)
}

/// Of the LiDAR frames the transforms lead to, the one about whose origin
/// the rings are narrowest.
fn best_candidate(
    sample: &RingedSample,
    candidates: Vec<(String, Isometry3<f64>)>,
) -> SensorOrigin {
    let (frame, pose, spread) = candidates
        .into_iter()
        .map(|(frame, pose)| {
            let spread = ring_spread_deg(sample, &pose);
            (frame, pose, spread)
        })
        .min_by(|a, b| {
            let key = |s: Option<f64>| s.unwrap_or(f64::INFINITY);
            key(a.2).total_cmp(&key(b.2))
        })
        .expect("at least one candidate");
    let mut origin = SensorOrigin::at(OriginSource::TfStatic, pose);
    origin.ring_spread_deg = spread;
    origin.several_origins = spread.is_some_and(|s| s > MERGED_SPREAD_ABOUT_TRANSFORM_DEG);
    origin.sensor_frame = Some(frame);
    origin
}

/// The frame and pose the extrinsics to the motion sources start from: the
/// sensor frame a transform named (a world-frame cloud's own frame moves),
/// else the cloud's frame with its pose; the cloud's always with a
/// command-line extrinsic (`cli`), which is read as that frame's pose.
pub fn extrinsic_frame(scan: &Scan, cli: bool) -> (String, Isometry3<f64>) {
    let named = scan
        .layout
        .origin
        .as_ref()
        .and_then(|o| o.sensor_frame.clone());
    match named.filter(|_| !cli) {
        Some(frame) => (frame, Isometry3::identity()),
        None => (scan.frame_id.clone(), scan.sensor_pose),
    }
}

/// `found` (through `/tf`) at `scan`'s stamp, from `tree` (the transforms at
/// that stamp); as found when `/tf` has no sample near the stamp.
pub fn at_stamp(scan: &Scan, tree: &TransformTree, found: &SensorOrigin) -> SensorOrigin {
    let Some(frame) = &found.sensor_frame else {
        return found.clone();
    };
    match tree.lookup(&scan.frame_id, frame) {
        Some(frame_from_sensor) => {
            let mut origin = found.clone();
            origin.cloud_from_sensor = scan.sensor_pose.inverse() * frame_from_sensor;
            let t = origin.cloud_from_sensor.translation.vector;
            origin.position_m = [t.x, t.y, t.z];
            origin
        }
        None => found.clone(),
    }
}

/// Move `scan`'s points into the sensor's frame and its pose with them, so
/// that everything downstream works about the sensor and every output still
/// lies where the input cloud does.
pub fn apply(scan: &mut Scan, origin: &SensorOrigin) {
    if !origin.moves_points() {
        return;
    }
    let sensor_from_cloud = origin.cloud_from_sensor.inverse();
    for p in &mut scan.points_m {
        let q = sensor_from_cloud * Point3::new(f64::from(p[0]), f64::from(p[1]), f64::from(p[2]));
        *p = [q.x as f32, q.y as f32, q.z as f32];
    }
    scan.sensor_pose *= origin.cloud_from_sensor;
}

/// Turn `scan` (already moved about its sensor) by `yaw_rad` about its
/// sensor's spin axis: its points into the turned axes, its pose and
/// recorded origin with them (`origin_track`: the scan before a track
/// started, into the track's axes). Ranges, rings and times are unchanged.
pub fn turn(scan: &mut Scan, yaw_rad: f64) {
    let turn = Isometry3::rotation(nalgebra::Vector3::z() * yaw_rad);
    let back = turn.inverse();
    for p in &mut scan.points_m {
        let q = back * Point3::new(f64::from(p[0]), f64::from(p[1]), f64::from(p[2]));
        *p = [q.x as f32, q.y as f32, q.z as f32];
    }
    scan.sensor_pose *= turn;
    if let Some(origin) = &mut scan.layout.origin {
        origin.cloud_from_sensor *= turn;
    }
}

/// Record `origin` in the scan's layout (after [`apply`]).
pub fn record(scan: &mut Scan, origin: &SensorOrigin) {
    scan.layout.origin = Some(origin.clone());
}

#[cfg(test)]
pub(super) mod tests {
    use super::*;
    use crate::model::ScanLayout;

    /// A 16-laser sensor at `at` (level) seeing a box-shaped room and a
    /// floor, its points in the cloud's frame `base_link` with a ring field.
    fn sensor_points(at: [f64; 3], points: &mut Vec<[f32; 3]>, rings: &mut Vec<u16>) {
        sensor_points_offset(at, 0.0, points, rings);
    }

    /// As [`sensor_points`], each laser's own origin `laser_offset_m` above
    /// or below `at` (alternately), as a two-block sensor's lasers are.
    fn sensor_points_offset(
        at: [f64; 3],
        laser_offset_m: f64,
        points: &mut Vec<[f32; 3]>,
        rings: &mut Vec<u16>,
    ) {
        for laser in 0..16u16 {
            let offset_m = if laser % 2 == 0 {
                laser_offset_m
            } else {
                -laser_offset_m
            };
            let at = [at[0], at[1], at[2] + offset_m];
            let elevation = (-15.0 + 2.0 * f64::from(laser)).to_radians();
            for k in 0..720 {
                let azimuth = f64::from(k) * std::f64::consts::TAU / 720.0;
                let (dx, dy, dz) = (
                    elevation.cos() * azimuth.cos(),
                    elevation.cos() * azimuth.sin(),
                    elevation.sin(),
                );
                // The nearer of the floor 1.8 m below and walls 12-20 m away.
                let wall = 12.0 + 8.0 * (0.5 + 0.5 * (3.0 * azimuth).sin());
                let floor = if dz < 0.0 {
                    at[2].max(0.5) / -dz
                } else {
                    f64::INFINITY
                };
                let range = (wall / elevation.cos()).min(floor).min(60.0);
                points.push([
                    (at[0] + range * dx) as f32,
                    (at[1] + range * dy) as f32,
                    (at[2] + range * dz) as f32,
                ]);
                rings.push(laser);
            }
        }
    }

    /// A cloud in `base_link` of the 16-laser sensors at `sensors`.
    pub(in crate::pairing) fn scan_in_base_link(sensors: &[[f64; 3]]) -> Scan {
        let (mut points, mut rings) = (Vec::new(), Vec::new());
        for &at in sensors {
            sensor_points(at, &mut points, &mut rings);
        }
        let n = points.len() as u32;
        Scan {
            stamp_ns: 0,
            frame_id: "base_link".into(),
            sensor_pose: Isometry3::identity(),
            input_point_count: n,
            points_m: points,
            intensity: None,
            ring: Some(rings),
            time_offset_s: None,
            source_index: (0..n).collect(),
            skipped_invalid_points: 0,
            organized: None,
            layout: ScanLayout::from_fields(Some("ring"), None),
            sensor_ids: None,
        }
    }

    #[test]
    fn a_sensor_off_the_clouds_origin_is_found_from_its_rings() {
        let scan = scan_in_base_link(&[[0.9, -0.3, 1.8]]);
        let tree = TransformTree::new();
        let (origin, warnings) = locate(&scan, (&tree, &tree), None, 0.1);
        assert_eq!(origin.source, OriginSource::Geometry, "{origin:?}");
        for (got, want) in origin.position_m.iter().zip([0.9, -0.3, 1.8]) {
            assert!((got - want).abs() < 0.01, "{origin:?}");
        }
        assert!(origin.ring_spread_deg.unwrap() < 0.05, "{origin:?}");
        assert!(
            !origin.several_origins && warnings.is_empty(),
            "{warnings:?}"
        );
        // Moved about it, the points are the sensor's own again.
        let mut moved = scan.clone();
        apply(&mut moved, &origin);
        let p = moved.points_m[0];
        assert!((f64::from(p[2]) + 1.8).abs() < 0.05, "{p:?}");
        assert!((moved.sensor_pose.translation.vector.x - 0.9).abs() < 0.01);
    }

    #[test]
    fn a_sensor_far_from_its_world_frames_origin_is_found_from_its_tightest_ring() {
        // 25 m along the frame's x and 7 m across: beyond the search's
        // reach about the cloud's origin.
        let scan = scan_in_base_link(&[[25.0, -7.0, 1.8]]);
        let tree = TransformTree::new();
        let (origin, warnings) = locate(&scan, (&tree, &tree), None, 0.1);
        assert_eq!(origin.source, OriginSource::Geometry, "{origin:?}");
        for (got, want) in origin.position_m.iter().zip([25.0, -7.0, 1.8]) {
            assert!((got - want).abs() < 0.01, "{origin:?}");
        }
        assert!(
            !origin.several_origins && warnings.is_empty(),
            "{warnings:?}"
        );
    }

    /// One sensor whose lasers do not share the origin `/tf_static` names:
    /// its rings spread 0.3-0.8 deg about it (KITTI's HDL-64E spreads 0.33
    /// about `velo_link`; here, in a room whose walls stand 12-20 m away,
    /// its lasers sit 0.9 m above or below). Its origin, and no word of a
    /// merged cloud.
    #[test]
    fn a_sensor_whose_lasers_do_not_share_one_origin_is_not_a_merged_cloud() {
        let (mut points, mut rings) = (Vec::new(), Vec::new());
        sensor_points_offset([0.8, 0.3, 1.7], 0.9, &mut points, &mut rings);
        let mut scan = scan_in_base_link(&[]);
        scan.input_point_count = points.len() as u32;
        scan.source_index = (0..scan.input_point_count).collect();
        scan.points_m = points;
        scan.ring = Some(rings);
        let mut statics = TransformTree::new();
        statics.insert(&crate::model::FrameTransform {
            stamp_ns: 0,
            parent_frame: "base_link".into(),
            child_frame: "velo_link".into(),
            parent_from_child: Isometry3::translation(0.8, 0.3, 1.7),
        });
        let (origin, warnings) = locate(&scan, (&statics, &statics), None, 0.1);
        assert_eq!(origin.source, OriginSource::TfStatic, "{origin:?}");
        let spread_deg = origin.ring_spread_deg.unwrap();
        assert!((0.3..0.8).contains(&spread_deg), "{origin:?}");
        assert!(
            !origin.several_origins && warnings.is_empty(),
            "{warnings:?}"
        );
    }

    #[test]
    fn two_sensors_merged_into_one_cloud_are_said() {
        let scan = scan_in_base_link(&[[1.0, 0.8, 0.6], [1.0, -0.8, 1.9]]);
        let tree = TransformTree::new();
        let (origin, warnings) = locate(&scan, (&tree, &tree), None, 0.1);
        assert!(origin.several_origins, "{origin:?}");
        assert!(
            warnings.iter().any(|w| w.contains("several sensors")),
            "{warnings:?}"
        );
    }
}
