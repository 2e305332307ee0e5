//! The geometry a sensor's origin is found by (`origin`, `origin_track`):
//! a laser fires at one elevation, so about the sensor's origin each ring's
//! returns lie at one elevation, and about any other point its cone smears.
//! Here the rings' spread about a pose ([`ring_spread_deg`]) and the search
//! for the pose (position, roll and pitch; the yaw changes no elevation)
//! about which it is narrowest: a coarse grid then a simplex
//! ([`search_pose`]), and the simplex alone ([`nelder_mead`]) where a start
//! near the answer is known.

use nalgebra::{Isometry3, Point3, Translation3, UnitQuaternion};
use rayon::prelude::*;

use crate::model::{OriginSource, RingSource, Scan, SensorOrigin};

/// Points taken for the geometry, at most.
const MAX_SAMPLE: usize = 15_000;
/// Returns nearer than this to a candidate origin (horizontally) are left
/// out: the vehicle's own body, and elevations no laser fires at.
const MIN_RANGE_M: f64 = 2.0;
/// The estimate is the cloud's origin when nearer than this, m.
const SAME_ORIGIN_M: f64 = 0.05;
/// Rings spread more than this about the best origin: several origins, deg.
pub(super) const MERGED_SPREAD_DEG: f64 = 0.3;
/// Rings spread more than this about the origin a transform names: several
/// origins, deg. Wider than about a searched origin, which is the one the
/// rings are narrowest about: one sensor's lasers need not share its
/// calibrated origin (KITTI's HDL-64E spreads 0.33 deg about `velo_link`,
/// 0.11 about the origin searched; its lasers' vertical offsets reach 0.2
/// m), while two or three LiDARs merged in `base_link` spread 1.6-3.0 deg
/// about any one of theirs (`synth --lidars 2|3 --one-topic --frame
/// vehicle`).
pub(super) const MERGED_SPREAD_ABOUT_TRANSFORM_DEG: f64 = 0.8;

/// Points with their ring: what the geometry is judged on.
pub(super) struct RingedSample {
    points: Vec<[f64; 3]>,
    rings: Vec<u16>,
    ring_count: usize,
}

/// An evenly spaced subset of the scan's points with their rings, when the
/// cloud's rings are known without its origin: a ring field, an organized
/// cloud's rows, the laser or firing order (`engine::layout`, run on a
/// copy); `None` for rings found from elevations (which need the origin).
pub(super) fn ringed_sample(scan: &Scan, period_s: f64) -> Option<RingedSample> {
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
pub(super) fn ring_spread_deg(
    sample: &RingedSample,
    cloud_from_sensor: &Isometry3<f64>,
) -> Option<f64> {
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
pub(super) fn pose_of(params: &[f64; 5]) -> Isometry3<f64> {
    Isometry3::from_parts(
        Translation3::new(params[0], params[1], params[2]),
        UnitQuaternion::from_euler_angles(params[3], params[4], 0.0),
    )
}

/// The sensor's origin about which the rings are narrowest, searched about
/// the cloud's origin; where its rings stay spread there, or the search ran
/// beyond its grid's reach (a world frame: the sensor may be anywhere in
/// it), about the centre of its tightest ring instead, kept when that
/// finds one origin within its reach.
pub(super) fn estimate_anywhere(sample: &RingedSample) -> SensorOrigin {
    let about_cloud = estimate(sample);
    let near = |origin: &SensorOrigin, start: &[f64; 5]| {
        within_reach(&params_of(&origin.cloud_from_sensor), start)
    };
    if !about_cloud.several_origins && near(&about_cloud, &[0.0; 5]) {
        return about_cloud;
    }
    let Some(seed) = ring_centre_seed(sample) else {
        return about_cloud;
    };
    let far = origin_at(sample, search_pose(sample, seed));
    if far.several_origins || !near(&far, &seed) {
        return about_cloud;
    }
    far
}

/// How far [`search_pose`] reaches from its start: its coarsest grid's
/// 3 m, and the simplex's refinement, m. A search that ends further has
/// wandered off (where the sensor is out of its reach).
pub(super) const SEARCH_REACH_M: f64 = 5.0;

/// Whether `params` lies within [`SEARCH_REACH_M`] of `start`.
pub(super) fn within_reach(params: &[f64; 5], start: &[f64; 5]) -> bool {
    let d2: f64 = (0..3).map(|i| (params[i] - start[i]).powi(2)).sum();
    d2.sqrt() <= SEARCH_REACH_M
}

/// The sensor's origin about which the rings are narrowest, searched about
/// the cloud's origin.
fn estimate(sample: &RingedSample) -> SensorOrigin {
    origin_at(sample, search_pose(sample, [0.0; 5]))
}

/// The origin of the searched parameters: the cloud's own when that near
/// it, with its rings' spread.
fn origin_at(sample: &RingedSample, params: [f64; 5]) -> SensorOrigin {
    let pose = pose_of(&params);
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

/// The parameters about which the rings are narrowest, from `start`:
/// coarse searches along z, over x and y, then over roll and pitch (a
/// sensor mounted tilted), each refined on a finer grid about the best.
pub(super) fn search_pose(sample: &RingedSample, start: [f64; 5]) -> [f64; 5] {
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
    let mut best = start;
    for (axes, half_width, step) in passes {
        best = search(sample, best, axes, half_width, step);
    }
    // Position and tilt pull on each other (a pitch moves the far rings as
    // a height does the near ones): a simplex search over all five from the
    // grid's best.
    nelder_mead(
        |p| objective_at(sample, p),
        best,
        [0.05, 0.05, 0.05, deg, deg],
        SimplexStop::after(SIMPLEX_ITERATIONS),
    )
}

/// Rings with fewer returns than this give no centre to start from.
const MIN_SEED_RING_POINTS: usize = 30;
/// A sensor's height above the ground its tightest ring sees, as a start
/// (the middle of the first pass's 3 m reach either way), m.
const SEED_HEIGHT_M: f64 = 1.5;

/// Where to search for a sensor far from its cloud's origin: above the
/// centre of its tightest ring (the steepest laser's circle on the ground
/// about it, or the vehicle's body), each coordinate's median.
pub(super) fn ring_centre_seed(sample: &RingedSample) -> Option<[f64; 5]> {
    let mut by_ring: Vec<Vec<[f64; 3]>> = vec![Vec::new(); sample.ring_count];
    for (p, &ring) in sample.points.iter().zip(&sample.rings) {
        if let Some(points) = by_ring.get_mut(usize::from(ring)) {
            points.push(*p);
        }
    }
    let centre_and_radius = |points: &Vec<[f64; 3]>| {
        let axis = |k: usize| {
            let mut values: Vec<f64> = points.iter().map(|p| p[k]).collect();
            median_of(&mut values)
        };
        let centre = [axis(0)?, axis(1)?, axis(2)?];
        let mut radii: Vec<f64> = points
            .iter()
            .map(|p| (p[0] - centre[0]).hypot(p[1] - centre[1]))
            .collect();
        Some((centre, median_of(&mut radii)?))
    };
    let (centre, _) = by_ring
        .iter()
        .filter(|points| points.len() >= MIN_SEED_RING_POINTS)
        .filter_map(centre_and_radius)
        .min_by(|a, b| a.1.total_cmp(&b.1))?;
    Some([centre[0], centre[1], centre[2] + SEED_HEIGHT_M, 0.0, 0.0])
}

/// The middle value (the upper of the two of an even count).
fn median_of(values: &mut [f64]) -> Option<f64> {
    if values.is_empty() {
        return None;
    }
    let mid = values.len() / 2;
    Some(*values.select_nth_unstable_by(mid, f64::total_cmp).1)
}

/// The search's objective at `params` (infinite where it has none).
pub(super) fn objective_at(sample: &RingedSample, params: &[f64; 5]) -> f64 {
    ring_objective(sample, &pose_of(params)).unwrap_or(f64::INFINITY)
}

/// Steps of the simplex search.
const SIMPLEX_ITERATIONS: usize = 400;

/// When a simplex search stops.
#[derive(Debug, Clone, Copy)]
pub(super) struct SimplexStop {
    /// Steps, at most.
    pub iterations: usize,
    /// Earlier, once every vertex lies within this of the best along each
    /// parameter (`None`: all the steps).
    pub tolerance: Option<[f64; 5]>,
}

impl SimplexStop {
    /// All of `iterations` steps.
    pub fn after(iterations: usize) -> Self {
        Self {
            iterations,
            tolerance: None,
        }
    }
}

/// Nelder and Mead's simplex search for the minimum of `f` from `start`,
/// the first simplex `scale` wide along each parameter.
pub(super) fn nelder_mead(
    f: impl Fn(&[f64; 5]) -> f64,
    start: [f64; 5],
    scale: [f64; 5],
    stop: SimplexStop,
) -> [f64; 5] {
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
    for _ in 0..stop.iterations {
        simplex.sort_by(|a, b| a.1.total_cmp(&b.1));
        if stop
            .tolerance
            .is_some_and(|tolerance| converged(&simplex, &tolerance))
        {
            break;
        }
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

/// Every vertex of the (sorted) simplex within `tolerance` of its best.
fn converged(simplex: &[([f64; 5], f64)], tolerance: &[f64; 5]) -> bool {
    let best = &simplex[0].0;
    simplex[1..]
        .iter()
        .all(|(p, _)| (0..5).all(|i| (p[i] - best[i]).abs() <= tolerance[i]))
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

/// The searched parameters of a pose [`pose_of`] made (its yaw, none,
/// left out).
pub(super) fn params_of(pose: &Isometry3<f64>) -> [f64; 5] {
    let t = pose.translation.vector;
    let (roll, pitch, _) = pose.rotation.euler_angles();
    [t.x, t.y, t.z, roll, pitch]
}
