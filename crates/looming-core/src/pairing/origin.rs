//! Where the LiDAR is in its cloud's frame. The range image, the rings, the
//! column times and the ego motion are all built around the origin of the
//! sensor's rays; a cloud published in the vehicle frame (Waymo, Argoverse
//! 2, Autoware's `base_link`) or after a transform filter has its points
//! about another origin, and around that origin its lasers' cones smear
//! into each other (KITTI in `base_link`: 108 "rings", 0.7 % trusted).
//!
//! The origin is found once per sensor, on its first scan, by priority:
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
//!    Its position and tilt (roll, pitch) are estimated; its yaw changes no
//!    elevation and is kept. Without such rings the cloud's origin is kept,
//!    and said.
//!
//! The RMS spread of the returns' elevations about their ring's mean
//! (`ring_spread_deg`) is the residual: hundredths of a degree about a
//! spinning sensor's origin, tenths or more about another point. A cloud
//! whose best origin still leaves its rings spread is flagged: its rays do
//! not meet at one point (several sensors merged, or a tilted one).

use nalgebra::{Isometry3, Point3, Translation3, UnitQuaternion};
use rayon::prelude::*;

use super::frames::{TransformTree, normalize_frame_id};
use super::history::TransformHistory;
use crate::model::{FrameTransform, OriginSource, RingSource, Scan, SensorOrigin};

/// A sensor's origin over a log: found on its first scan with points, then
/// applied to every scan (looked up again at each scan's stamp when only
/// `/tf` reaches it).
#[derive(Debug, Clone, Default)]
pub struct SensorPlacement {
    origin: Option<SensorOrigin>,
    /// `/tf`'s recent transforms.
    history: TransformHistory,
    /// Scans placed since the origin was found.
    scans_placed: u32,
    /// The origin found from the rings was seen to move (said once).
    seen_moving: bool,
}

impl SensorPlacement {
    /// Keep a `/tf` transform.
    pub fn keep_tf(&mut self, transform: &FrameTransform) {
        self.history.insert(transform);
    }

    /// Move `scan`'s points about its sensor (`statics`: `/tf_static`;
    /// `period_s`: the scan period): the warnings, and the origin when this
    /// scan found it.
    pub fn place(
        &mut self,
        scan: &mut Scan,
        statics: &TransformTree,
        sensor_frame: Option<&str>,
        period_s: f64,
    ) -> (Vec<String>, Option<SensorOrigin>) {
        let (mut warnings, mut found_now) = (Vec::new(), None);
        if self.origin.is_none() && !scan.is_empty() {
            let tree = self.history.tree_at(statics, scan.stamp_ns);
            let found;
            (found, warnings) = locate(scan, (&tree, statics), sensor_frame, period_s);
            found_now = Some(found.clone());
            self.origin = Some(found);
        }
        let Some(found) = &self.origin else {
            return (warnings, found_now);
        };
        let found = match found.source {
            OriginSource::Tf => {
                at_stamp(scan, &self.history.tree_at(statics, scan.stamp_ns), found)
            }
            _ => found.clone(),
        };
        self.scans_placed += 1;
        if found_now.is_none() && self.scans_placed.is_multiple_of(MOVE_CHECK_EVERY_SCANS) {
            warnings.extend(self.check_still(scan, &found, period_s));
        }
        apply(scan, &found);
        record(scan, &found);
        (warnings, found_now)
    }

    /// An origin found from the rings of the first scan holds for the next
    /// ones only if the cloud's frame moves with the sensor (its own or a
    /// vehicle frame). A world frame with no `/tf` to give the sensor's pose
    /// leaves the sensor driving through the cloud's frame: its rings spread
    /// about the first scan's origin, and every range image after is built
    /// about the wrong point. Said once (the run then carries on; what it
    /// gives is not to be trusted).
    fn check_still(&mut self, scan: &Scan, found: &SensorOrigin, period_s: f64) -> Option<String> {
        let first_spread_deg = found.ring_spread_deg?;
        if self.seen_moving
            || !matches!(
                found.source,
                OriginSource::Geometry | OriginSource::CloudFrame
            )
        {
            return None;
        }
        let sample = ringed_sample(scan, period_s)?;
        let spread_deg = ring_spread_deg(&sample, &found.cloud_from_sensor)?;
        if spread_deg <= MERGED_SPREAD_DEG.max(MOVED_SPREAD_FACTOR * first_spread_deg) {
            return None;
        }
        self.seen_moving = true;
        Some(format!(
            "the sensor moves through its clouds' frame `{}`: {} scans after its origin was \
             found from the rings (spread {first_spread_deg:.3} deg), they spread {spread_deg:.3} \
             deg about it. A world frame needs /tf to the LiDAR's frame (or --sensor-frame); \
             without it this log's looming is not to be trusted",
            scan.frame_id, self.scans_placed
        ))
    }
}

/// How often a sensor placed by its rings is checked for moving, scans.
const MOVE_CHECK_EVERY_SCANS: u32 = 10;
/// Its rings spread this many times more about the first origin (and more
/// than [`MERGED_SPREAD_DEG`]): it moved.
const MOVED_SPREAD_FACTOR: f64 = 5.0;

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
        estimate(&sample)
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
    origin.several_origins = spread.is_some_and(|s| s > MERGED_SPREAD_DEG);
    origin.sensor_frame = Some(frame);
    origin
}

/// Points taken for the geometry, at most.
const MAX_SAMPLE: usize = 15_000;
/// Returns nearer than this to a candidate origin (horizontally) are left
/// out: the vehicle's own body, and elevations no laser fires at.
const MIN_RANGE_M: f64 = 2.0;
/// The estimate is the cloud's origin when nearer than this, m.
const SAME_ORIGIN_M: f64 = 0.05;
/// Rings spread more than this about the best origin: several origins, deg.
const MERGED_SPREAD_DEG: f64 = 0.3;

/// Points with their ring: what the geometry is judged on.
struct RingedSample {
    points: Vec<[f64; 3]>,
    rings: Vec<u16>,
    ring_count: usize,
}

/// An evenly spaced subset of the scan's points with their rings, when the
/// cloud's rings are known without its origin: a ring field, an organized
/// cloud's rows, the laser or firing order (`engine::layout`, run on a
/// copy); `None` for rings found from elevations (which need the origin).
fn ringed_sample(scan: &Scan, period_s: f64) -> Option<RingedSample> {
    let rings = known_rings(scan, period_s)?;
    let step = scan.points_m.len().div_ceil(MAX_SAMPLE).max(1);
    let (points, rings): (Vec<[f64; 3]>, Vec<u16>) = scan
        .points_m
        .iter()
        .zip(&rings)
        .step_by(step)
        .map(|(p, &r)| (p.map(f64::from), r))
        .unzip();
    let ring_count = rings.iter().map(|&r| usize::from(r) + 1).max().unwrap_or(0);
    Some(RingedSample {
        points,
        rings,
        ring_count,
    })
}

/// Horizontal offsets tried about which the point order may show its
/// lasers, m: the order's azimuth wraps once per laser about the sensor,
/// and about a point a metre away the near returns' azimuths break the
/// pattern.
const RING_SEARCH_STEP_M: f64 = 0.5;
const RING_SEARCH_HALF_WIDTH_M: f64 = 2.0;

/// Each point's ring when the cloud's rings are known without its origin
/// (`engine::layout` on a copy): its ring field or rows, or its laser or
/// firing order about the cloud's origin or a nearby one (nearest first).
fn known_rings(scan: &Scan, period_s: f64) -> Option<Vec<u16>> {
    let steps = (RING_SEARCH_HALF_WIDTH_M / RING_SEARCH_STEP_M).round() as i32;
    let mut offsets: Vec<(f64, f64)> = (-steps..=steps)
        .flat_map(|i| (-steps..=steps).map(move |j| (i, j)))
        .map(|(i, j)| {
            (
                f64::from(i) * RING_SEARCH_STEP_M,
                f64::from(j) * RING_SEARCH_STEP_M,
            )
        })
        .collect();
    offsets.sort_by(|a, b| a.0.hypot(a.1).total_cmp(&b.0.hypot(b.1)));
    offsets.into_iter().find_map(|(dx, dy)| {
        let mut copy = scan.clone();
        for p in &mut copy.points_m {
            p[0] -= dx as f32;
            p[1] -= dy as f32;
        }
        crate::engine::layout::complete(&mut copy, period_s);
        let known = matches!(
            copy.layout.rings,
            RingSource::Field { .. }
                | RingSource::Organized { .. }
                | RingSource::LaserOrder { .. }
                | RingSource::FiringOrder { .. }
        );
        copy.ring.filter(|_| known)
    })
}

/// The elevation of cloud point `p` seen from the sensor at `cloud_from_sensor`.
fn elevation_deg(p: &[f64; 3], sensor_from_cloud: &Isometry3<f64>) -> Option<f64> {
    let q = sensor_from_cloud * Point3::new(p[0], p[1], p[2]);
    let horizontal = q.x.hypot(q.y);
    (horizontal >= MIN_RANGE_M).then(|| q.z.atan2(horizontal).to_degrees())
}

/// RMS distance of the returns' elevations about `origin` from their
/// ring's mean, degrees: each laser fires at one elevation, so about the
/// sensor's origin this is the beam's width and the lasers' offsets from
/// the axis (hundredths of a degree); about another point the cones smear.
/// `None` without returns.
fn ring_spread_deg(sample: &RingedSample, cloud_from_sensor: &Isometry3<f64>) -> Option<f64> {
    ring_stats(sample, cloud_from_sensor).map(|(within, _)| within.sqrt())
}

/// The variance of the returns' elevations within their rings and that of
/// the rings' mean elevations (weighted by their returns), degrees^2.
fn ring_stats(sample: &RingedSample, cloud_from_sensor: &Isometry3<f64>) -> Option<(f64, f64)> {
    let sensor_from_cloud = cloud_from_sensor.inverse();
    let mut sums = vec![(0.0f64, 0.0f64, 0u32); sample.ring_count];
    for (p, &ring) in sample.points.iter().zip(&sample.rings) {
        let e = elevation_deg(p, &sensor_from_cloud);
        if let (Some(e), Some(sum)) = (e, sums.get_mut(usize::from(ring))) {
            sum.0 += e;
            sum.1 += e * e;
            sum.2 += 1;
        }
    }
    let (mut within, mut total, mut total_sq, mut count) = (0.0, 0.0, 0.0, 0.0);
    for &(s, s2, k) in sums.iter().filter(|s| s.2 > 0) {
        let k = f64::from(k);
        let mean = s / k;
        within += (s2 - mean * s).max(0.0);
        total += s;
        total_sq += mean * mean * k;
        count += k;
    }
    if count == 0.0 {
        return None;
    }
    let grand = total / count;
    Some((within / count, (total_sq / count - grand * grand).max(0.0)))
}

/// What the search minimises: the rings' spread against the spread of
/// their elevations. The spread alone has a false minimum: about a point
/// on the road's plane every ring that sees only road reads 0 degrees; but
/// then the lasers' rings no longer lie at different elevations.
fn ring_objective(sample: &RingedSample, cloud_from_sensor: &Isometry3<f64>) -> Option<f64> {
    let (within, between) = ring_stats(sample, cloud_from_sensor)?;
    (between > 0.0).then(|| within / between)
}

/// The sensor's pose from the searched parameters: position x, y, z (m),
/// roll and pitch (rad); its yaw changes no elevation and stays the cloud's.
fn pose_of(params: &[f64; 5]) -> Isometry3<f64> {
    Isometry3::from_parts(
        Translation3::new(params[0], params[1], params[2]),
        UnitQuaternion::from_euler_angles(params[3], params[4], 0.0),
    )
}

/// The pose about which the rings are narrowest: coarse searches along z,
/// over x and y, then over roll and pitch (a sensor mounted tilted), each
/// refined on a finer grid about the best.
fn estimate(sample: &RingedSample) -> SensorOrigin {
    const Z: &[usize] = &[2];
    const XY: &[usize] = &[0, 1];
    const TILT: &[usize] = &[3, 4];
    let deg = std::f64::consts::PI / 180.0;
    // (parameters, half width, step), coarse to fine; m or rad.
    let passes: [(&[usize], f64, f64); 11] = [
        (Z, 3.0, 0.05),
        (XY, 3.0, 0.25),
        (Z, 0.3, 0.01),
        (XY, 0.25, 0.05),
        (TILT, 6.0 * deg, 0.5 * deg),
        (XY, 0.05, 0.01),
        (Z, 0.05, 0.002),
        (TILT, 0.5 * deg, 0.05 * deg),
        (XY, 0.01, 0.002),
        (Z, 0.01, 0.001),
        (TILT, 0.05 * deg, 0.01 * deg),
    ];
    let mut best = [0.0; 5];
    for (axes, half_width, step) in passes {
        best = search(sample, best, axes, half_width, step);
    }
    // Position and tilt pull on each other (a pitch moves the far rings as
    // a height does the near ones): a simplex search over all five from the
    // grid's best.
    best = nelder_mead(
        |p| objective_at(sample, p),
        best,
        [0.05, 0.05, 0.05, deg, deg],
    );
    let pose = pose_of(&best);
    let mut origin = if pose.translation.vector.norm() < SAME_ORIGIN_M
        && pose.rotation.angle() < SAME_TILT_RAD
    {
        SensorOrigin::cloud_frame()
    } else {
        SensorOrigin::at(OriginSource::Geometry, pose)
    };
    origin.ring_spread_deg = ring_spread_deg(sample, &origin.cloud_from_sensor);
    origin.several_origins = origin
        .ring_spread_deg
        .is_some_and(|s| s > MERGED_SPREAD_DEG);
    origin
}

/// The search's objective at `params` (infinite where it has none).
fn objective_at(sample: &RingedSample, params: &[f64; 5]) -> f64 {
    ring_objective(sample, &pose_of(params)).unwrap_or(f64::INFINITY)
}

/// Steps of the simplex search.
const SIMPLEX_ITERATIONS: usize = 400;

/// Nelder and Mead's simplex search for the minimum of `f` from `start`,
/// the first simplex `scale` wide along each parameter.
fn nelder_mead(f: impl Fn(&[f64; 5]) -> f64, start: [f64; 5], scale: [f64; 5]) -> [f64; 5] {
    let mut simplex: Vec<([f64; 5], f64)> = (0..=5)
        .map(|k| {
            let mut p = start;
            if k > 0 {
                p[k - 1] += scale[k - 1];
            }
            (p, f(&p))
        })
        .collect();
    let along = |a: &[f64; 5], b: &[f64; 5], t: f64| -> [f64; 5] {
        std::array::from_fn(|i| a[i] + t * (b[i] - a[i]))
    };
    for _ in 0..SIMPLEX_ITERATIONS {
        simplex.sort_by(|a, b| a.1.total_cmp(&b.1));
        let centroid: [f64; 5] =
            std::array::from_fn(|i| simplex[..5].iter().map(|(p, _)| p[i]).sum::<f64>() / 5.0);
        let (worst, worst_value) = simplex[5];
        let reflected = along(&centroid, &worst, -1.0);
        let reflected_value = f(&reflected);
        if reflected_value < simplex[0].1 {
            let expanded = along(&centroid, &worst, -2.0);
            let expanded_value = f(&expanded);
            simplex[5] = if expanded_value < reflected_value {
                (expanded, expanded_value)
            } else {
                (reflected, reflected_value)
            };
        } else if reflected_value < simplex[4].1 {
            simplex[5] = (reflected, reflected_value);
        } else {
            let contracted = along(&centroid, &worst, 0.5);
            let contracted_value = f(&contracted);
            if contracted_value < worst_value {
                simplex[5] = (contracted, contracted_value);
            } else {
                let best = simplex[0].0;
                for vertex in simplex.iter_mut().skip(1) {
                    vertex.0 = along(&best, &vertex.0, 0.5);
                    vertex.1 = f(&vertex.0);
                }
            }
        }
    }
    simplex.sort_by(|a, b| a.1.total_cmp(&b.1));
    simplex[0].0
}

/// The estimate is the cloud's own frame when tilted less than this, rad.
const SAME_TILT_RAD: f64 = 0.2 * std::f64::consts::PI / 180.0;

/// The parameters with the narrowest rings on a grid about `centre` over
/// `axes`.
fn search(
    sample: &RingedSample,
    centre: [f64; 5],
    axes: &[usize],
    half_width: f64,
    step: f64,
) -> [f64; 5] {
    let steps = (half_width / step).round() as i64;
    let offsets: Vec<f64> = (-steps..=steps).map(|k| k as f64 * step).collect();
    let grid: Vec<[f64; 5]> = match axes {
        [axis] => offsets
            .iter()
            .map(|&d| {
                let mut o = centre;
                o[*axis] += d;
                o
            })
            .collect(),
        [a, b, ..] => offsets
            .iter()
            .flat_map(|&da| offsets.iter().map(move |&db| (da, db)))
            .map(|(da, db)| {
                let mut o = centre;
                o[*a] += da;
                o[*b] += db;
                o
            })
            .collect(),
        [] => vec![centre],
    };
    let size = |o: &[f64; 5]| o.iter().map(|v| v * v).sum::<f64>();
    grid.into_par_iter()
        .map(|o| (objective_at(sample, &o), o))
        .filter(|(value, _)| value.is_finite())
        .min_by(|a, b| a.0.total_cmp(&b.0).then(size(&a.1).total_cmp(&size(&b.1))))
        .map_or(centre, |(_, o)| o)
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

/// Record `origin` in the scan's layout (after [`apply`]).
pub fn record(scan: &mut Scan, origin: &SensorOrigin) {
    scan.layout.origin = Some(origin.clone());
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::model::ScanLayout;

    /// A 16-laser sensor at `at` (level) seeing a box-shaped room and a
    /// floor, its points in the cloud's frame `base_link` with a ring field.
    fn sensor_points(at: [f64; 3], points: &mut Vec<[f32; 3]>, rings: &mut Vec<u16>) {
        for laser in 0..16u16 {
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

    fn scan_in_base_link(sensors: &[[f64; 3]]) -> Scan {
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
    fn a_sensor_driving_through_a_world_frame_without_tf_is_said() {
        let tree = TransformTree::new();
        let mut placement = SensorPlacement::default();
        let mut warned = Vec::new();
        // The sensor 1 m further along x at every scan, no /tf.
        for k in 0..MOVE_CHECK_EVERY_SCANS {
            let mut scan = scan_in_base_link(&[[0.9 + f64::from(k), -0.3, 1.8]]);
            scan.frame_id = "map".into();
            let (warnings, _) = placement.place(&mut scan, &tree, None, 0.1);
            warned.extend(warnings);
        }
        assert!(
            warned
                .iter()
                .any(|w| w.contains("moves through its clouds' frame `map`")),
            "{warned:?}"
        );
        // A sensor that stays where it was found (a vehicle frame) is not.
        let mut still = SensorPlacement::default();
        for _ in 0..MOVE_CHECK_EVERY_SCANS {
            let mut scan = scan_in_base_link(&[[0.9, -0.3, 1.8]]);
            let (warnings, _) = still.place(&mut scan, &tree, None, 0.1);
            assert!(warnings.is_empty(), "{warnings:?}");
        }
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
