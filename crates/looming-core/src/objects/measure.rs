//! Each object's figures: where it is, how big, and its looming, measured on
//! every cell that holds a measurement of its range along the ray.
//!
//! A cell measures the object's approach when it has a previous surface
//! along its ray and met the same surface there (no `EMPTY`, `NO_PREVIOUS`,
//! `OCCLUSION` or `GRAZING` bit) and faces the sensor (`|n . e| >= 0.5`: near
//! grazing the range along a ray changes fast without anything
//! approaching); an object with fewer than three such cells (seen side-on)
//! takes its cells short of grazing instead. `EDGE` does not exclude a cell: a crease or an edge of a car's rear still
//! measures its range. The looming is the weighted median of those cells'
//! `L_lidar`, each weighted by `1 / sigma_L^2` (the engine's noise of that
//! cell), which a few wrong cells (a silhouette, a reflection) cannot move;
//! its standard error is `1.4826` times the weighted median absolute
//! deviation over the square root of the effective number of cells.
//!
//! On an object that does not move on its own (its `D` within four standard
//! errors, the ego prediction's uncertainty included, or below 0.15 1/s) the
//! ego prediction measures the same looming: the weighted median of
//! `L_ray_ego` over the same cells, whose error is that of the motion (for a
//! motion estimated from the scans, its covariance carried to the object),
//! joins the measurement by inverse variance.

use super::ground::{CellPoints, cell_point};
use super::{NO_OBJECT, Object, ObjectCells, collect_bounded, order};
use crate::engine::egomotion::EgoEstimate;
use crate::engine::{PairLooming, mask};
use crate::model::Scan;

/// Cells facing the sensor at least this much measure the approach ...
const MIN_FACING_COS: f32 = 0.5;
/// ... or, on an object without three such cells, those short of grazing
/// (the engine's `GRAZING` bit: `|n . e| < 0.15`).
const MIN_SIDE_ON_COS: f32 = 0.15;
/// Fewest measured cells for a looming.
const MIN_MEASURED_CELLS: usize = 3;
/// `|D|` must exceed this many standard errors, and ...
const MOVING_SIGMAS: f64 = 4.0;
/// ... this much, for a moving object, 1/s (the cells' own rule).
const MOVING_MIN_PER_S: f64 = 0.15;

/// The figures of every object labelled in `cell_object` (ids 0: not yet
/// tracked).
pub fn measure_objects(scan: &Scan, looming: &PairLooming, cell_object: &[u32]) -> Vec<Object> {
    let cells = ObjectCells::of(cell_object, object_count(cell_object));
    measure_each(
        &|c| cell_point(looming, scan, c),
        looming,
        cell_object,
        &cells,
    )
}

/// [`measure_objects`] with the pair's cell returns already gathered (the
/// same values `cell_point` gives, read in cell order), and the cells of
/// each object.
pub(super) fn measure_labelled(
    points: &CellPoints,
    looming: &PairLooming,
    cell_object: &[u32],
) -> (Vec<Object>, ObjectCells) {
    let cells = ObjectCells::of(cell_object, object_count(cell_object));
    let objects = measure_each(&|c| points.get(c), looming, cell_object, &cells);
    (objects, cells)
}

/// How many objects `cell_object` labels: one past the largest label.
fn object_count(cell_object: &[u32]) -> usize {
    cell_object
        .iter()
        .filter(|&&o| o != NO_OBJECT)
        .map(|&o| o as usize + 1)
        .max()
        .unwrap_or(0)
}

/// Each object of `cells` measured, its returns given by `point_of`.
fn measure_each(
    point_of: &dyn Fn(usize) -> Option<[f64; 3]>,
    looming: &PairLooming,
    cell_object: &[u32],
    cells: &ObjectCells,
) -> Vec<Object> {
    let mut points = vec![0usize; cells.len()];
    for &cell in &looming.image.point_surface {
        if cell != crate::engine::NO_POINT
            && let Some(&object) = cell_object.get(cell as usize)
            && object != NO_OBJECT
        {
            points[object as usize] += 1;
        }
    }
    cells
        .iter()
        .zip(points)
        .map(|(cells, points)| measure(point_of, looming, cells, points))
        .collect()
}

/// One object of `cells`, `points` of the scan being their surfaces.
fn measure(
    point_of: &dyn Fn(usize) -> Option<[f64; 3]>,
    looming: &PairLooming,
    cells: &[usize],
    points: usize,
) -> Object {
    let returns = collect_bounded(cells.len(), cells.iter().filter_map(|&c| point_of(c)));
    let (nearest_range_m, centroid_m, min_m, max_m) = geometry_of(&returns);
    let measured = measuring_cells(looming, cells, |_| true);
    let fits = Fits::of(looming, &measured);
    let static_fit = fits
        .measured
        .is_none()
        .then(|| {
            let velocity = looming
                .availability
                .ego_velocity
                .then_some(looming.velocity_mps);
            looming_if_static(velocity.flatten(), looming.ego_estimate.as_ref(), &returns)
        })
        .flatten();
    let looming_fit = fits.measured.or(static_fit);
    let looming_per_s = looming_fit.map(|(l, _)| l);
    Object {
        id: 0,
        age_pairs: 0,
        cells: cells.len(),
        points,
        nearest_range_m,
        centroid_m,
        min_m,
        max_m,
        bearing_deg: centroid_m[1].atan2(centroid_m[0]).to_degrees(),
        looming_per_s,
        looming_se_per_s: looming_fit.map(|(_, se)| se),
        lidar_looming_per_s: fits.lidar.map(|(l, _)| l),
        measured_cells: measured.len(),
        looming_from_track: false,
        looming_assumed_static: static_fit.is_some(),
        time_to_contact_s: looming_per_s.filter(|&l| l > 0.0).map(|l| 1.0 / l),
        disagreement_per_s: fits.disagreement.map(|(d, _)| d),
        moving: fits.moving,
        velocity_mps: None,
    }
}

/// The cells of `cells` that measure an object's approach and pass `keep`:
/// those facing the sensor, or, on an object with fewer than three such
/// cells (seen side-on: a wall along the road, a car beside the path), its
/// cells short of grazing, which still measure how fast the free space
/// along their rays shrinks.
fn measuring_cells(
    looming: &PairLooming,
    cells: &[usize],
    keep: impl Fn(usize) -> bool,
) -> Vec<usize> {
    cells_measuring(
        cells,
        |c, min_cos| measures_approach(looming, c, min_cos),
        keep,
    )
}

/// [`measuring_cells`] with `measures` for [`measures_approach`].
fn cells_measuring(
    cells: &[usize],
    measures: impl Fn(usize, f32) -> bool,
    keep: impl Fn(usize) -> bool,
) -> Vec<usize> {
    let passing = |min_cos: f32| {
        let passes = |&c: &usize| measures(c, min_cos) && keep(c);
        collect_bounded(cells.len(), cells.iter().copied().filter(passes))
    };
    let facing = passing(MIN_FACING_COS);
    if facing.len() >= MIN_MEASURED_CELLS {
        return facing;
    }
    passing(MIN_SIDE_ON_COS)
}

/// What an object's measured cells give (value, standard error each).
struct Fits {
    /// The weighted median of their `L_lidar`.
    lidar: Option<(f64, f64)>,
    /// Of their `D`, its error with the ego prediction's; `None` without a
    /// velocity source.
    disagreement: Option<(f64, f64)>,
    moving: bool,
    /// The object's measured looming: `lidar`, and on an object not moving
    /// on its own the ego prediction joined by inverse variance.
    measured: Option<(f64, f64)>,
}

impl Fits {
    fn of(looming: &PairLooming, measured: &[usize]) -> Self {
        let lidar = robust_mean(measured, &looming.l_lidar, &looming.sigma_per_s);
        let ego_sigma = ego_prediction_sigma(looming, measured);
        let disagreement = looming
            .availability
            .ego_velocity
            .then(|| robust_mean(measured, &looming.disagreement, &looming.sigma_per_s))
            .flatten()
            .map(|(d, se)| (d, se.hypot(ego_sigma.unwrap_or(0.0))));
        let moving = disagreement
            .is_some_and(|(d, se)| d.abs() > (MOVING_SIGMAS * se).max(MOVING_MIN_PER_S));
        // (The ego prediction's error is the one just taken.)
        let ego = (!moving)
            .then(|| ego_prediction_with_sigma(looming, measured, ego_sigma))
            .flatten();
        let measured = match (lidar, ego) {
            (Some(lidar), Some(ego)) => Some(inverse_variance_mean(lidar, ego)),
            (lidar, _) => lidar,
        };
        Self {
            lidar,
            disagreement,
            moving,
            measured,
        }
    }
}

/// An object followed from the last pair, measured again on the cells whose
/// range before (`r (1 + L_lidar dt)`) lay within one of `spans_m`: the
/// ranges its track's object spanned then, or those it spans now (an object
/// keeping its distance; a track taken over by a neighbour), each with a
/// margin for the ego motion. A
/// cell whose ray met something else in the previous scan did not measure
/// this object's approach, even where that surface was close enough not to
/// be flagged `OCCLUSION`: without a motion source any range change up to
/// the fastest plausible approach passes, and on the OS0-8 log a static box
/// at 3.3 m read 6.5 1/s from rays that had seen the wall 2 m behind it.
/// Where no cell is left, its looming is the ego prediction along its rays
/// (`L_ray_ego`, flagged assumed static) where the ego motion is known and
/// the object was `still` (not moving on its own) in its last pair, else
/// left to its track's range rate. Unchanged where every measuring
/// cell passes. Whether the object's looming is now the ego prediction.
pub(super) fn keep_cells_seen_before(
    object: &mut Object,
    looming: &PairLooming,
    cells: &[usize],
    (spans_m, still): ([(f64, f64); 2], bool),
) -> bool {
    if object.looming_per_s.is_none() || object.looming_assumed_static {
        return false;
    }
    let seen_before = |c: usize| {
        let range_m = f64::from(looming.image.range_m[c]);
        let before_m = range_m * (1.0 + f64::from(looming.l_lidar[c] * looming.dt_s[c]));
        spans_m
            .iter()
            .any(|(near_m, far_m)| (*near_m..=*far_m).contains(&before_m))
    };
    let all = measuring_cells(looming, cells, |_| true);
    // Where every measuring cell was seen before, the cells kept are all of
    // them (the facing ones, or the side-on ones where fewer than three
    // face the sensor, pass `seen_before` alike): nothing to measure again.
    // Where one was not, it is missing from those kept.
    if all.iter().all(|&c| seen_before(c)) {
        return false;
    }
    let measured = measuring_cells(looming, cells, seen_before);
    let fits = Fits::of(looming, &measured);
    let assumed = (fits.measured.is_none() && still)
        .then(|| ego_prediction(looming, &all))
        .flatten();
    let looming_fit = fits.measured.or(assumed);
    object.looming_per_s = looming_fit.map(|(l, _)| l);
    object.looming_se_per_s = looming_fit.map(|(_, se)| se);
    object.looming_assumed_static = assumed.is_some();
    object.lidar_looming_per_s = fits.lidar.map(|(l, _)| l);
    object.measured_cells = measured.len();
    object.time_to_contact_s = object.looming_per_s.filter(|&l| l > 0.0).map(|l| 1.0 / l);
    object.disagreement_per_s = fits.disagreement.map(|(d, _)| d);
    object.moving = fits.moving;
    assumed.is_some()
}

/// The ego prediction's weighted median over `cells` and its error (that
/// of the motion included); `None` without ego motion.
fn ego_prediction(looming: &PairLooming, cells: &[usize]) -> Option<(f64, f64)> {
    ego_prediction_with_sigma(looming, cells, ego_prediction_sigma(looming, cells))
}

/// [`ego_prediction`] with the motion's error over `cells`
/// ([`ego_prediction_sigma`]) already taken.
fn ego_prediction_with_sigma(
    looming: &PairLooming,
    cells: &[usize],
    sigma: Option<f64>,
) -> Option<(f64, f64)> {
    let sigma = sigma?;
    robust_mean(cells, &looming.l_ray_ego, &looming.sigma_per_s).map(|(e, se)| (e, se.hypot(sigma)))
}

/// Where an object's `returns` are: the 10th percentile of their ranges,
/// their mean and their axis-aligned extent (smallest and largest x, y, z).
fn geometry_of(returns: &[[f64; 3]]) -> (f64, [f64; 3], [f64; 3], [f64; 3]) {
    let mut ranges: Vec<i64> = returns
        .iter()
        .map(|p| order::key((p[0] * p[0] + p[1] * p[1] + p[2] * p[2]).sqrt()))
        .collect();
    // The 10th percentile by selection: objects of thousands of cells.
    let tenth = ranges.len().saturating_sub(1) / 10;
    let nearest_range_m = if ranges.is_empty() {
        f64::NAN
    } else {
        order::select(&mut ranges, tenth)
    };
    let n = returns.len().max(1) as f64;
    let mut centroid_m = [0.0; 3];
    let mut min_m = [f64::INFINITY; 3];
    let mut max_m = [f64::NEG_INFINITY; 3];
    for p in returns {
        for k in 0..3 {
            centroid_m[k] += p[k] / n;
            min_m[k] = min_m[k].min(p[k]);
            max_m[k] = max_m[k].max(p[k]);
        }
    }
    (nearest_range_m, centroid_m, min_m, max_m)
}

/// Share of an object's returns, nearest first, its looming if static is
/// taken over (the part a collision would meet first).
const NEAREST_SHARE: f64 = 0.2;

/// The looming the object would have if it stood still, from the ego motion
/// alone: the median over its nearest returns of `(v . p) / |p|^2` (a static
/// point's range changes by `-v . p/|p|`; rotation does not change a range),
/// with the uncertainty of the velocity along those rays (a measured
/// velocity's 1 % and, for one estimated from the scans, its covariance).
/// `None` without ego motion. What an object none of whose cells measured
/// its approach, seen for the first time (no track range yet), is given,
/// flagged as assumed.
fn looming_if_static(
    velocity_mps: Option<[f64; 3]>,
    estimate: Option<&EgoEstimate>,
    returns: &[[f64; 3]],
) -> Option<(f64, f64)> {
    let velocity = velocity_mps?;
    let mut by_range: Vec<(f64, [f64; 3])> = returns
        .iter()
        .map(|p| ((p[0] * p[0] + p[1] * p[1] + p[2] * p[2]).sqrt(), *p))
        .filter(|(r, _)| *r > 0.0 && r.is_finite())
        .collect();
    if by_range.is_empty() {
        return None;
    }
    by_range.sort_unstable_by(|a, b| a.0.total_cmp(&b.0));
    let nearest = ((by_range.len() as f64 * NEAREST_SHARE).ceil() as usize).max(1);
    let mut values: Vec<(f64, [f64; 3])> = by_range[..nearest]
        .iter()
        .map(|&(r, p)| {
            let dot = velocity[0] * p[0] + velocity[1] * p[1] + velocity[2] * p[2];
            (dot / (r * r), p)
        })
        .collect();
    values.sort_unstable_by(|a, b| a.0.total_cmp(&b.0));
    let (looming_per_s, at) = values[values.len() / 2];
    let model = 0.01 * looming_per_s.abs() + 0.005;
    let sigma = estimate.map_or(model, |estimate| {
        let point = nalgebra::Vector3::from(at);
        let ray = point.normalize();
        model.hypot(estimate.ray_looming_sigma_per_s(point, ray, 1.0))
    });
    Some((looming_per_s, sigma))
}

/// The uncertainty of the ego prediction over `cells`: the median of their
/// `L_ray_ego` noise (the estimated motion's share is common to all of them,
/// so it does not average out).
fn ego_prediction_sigma(looming: &PairLooming, cells: &[usize]) -> Option<f64> {
    let sigmas = cells
        .iter()
        .map(|&c| looming.ray_ego_sigma_per_s[c])
        .filter(|s| s.is_finite())
        .map(|s| order::key(f64::from(s)));
    let mut sigmas = collect_bounded(cells.len(), sigmas);
    if sigmas.is_empty() {
        return None;
    }
    let mid = sigmas.len() / 2;
    Some(order::select(&mut sigmas, mid))
}

/// Two estimates and their standard errors combined by inverse variance.
pub(super) fn inverse_variance_mean((a, se_a): (f64, f64), (b, se_b): (f64, f64)) -> (f64, f64) {
    let (w_a, w_b) = (1.0 / se_a.max(1e-6).powi(2), 1.0 / se_b.max(1e-6).powi(2));
    (
        (a * w_a + b * w_b) / (w_a + w_b),
        (1.0 / (w_a + w_b)).sqrt(),
    )
}

/// Whether a cell's `L_lidar` measures its surface's approach, seen at
/// least `min_cos` from grazing.
fn measures_approach(looming: &PairLooming, cell: usize, min_cos: f32) -> bool {
    let invalid = mask::EMPTY | mask::NO_PREVIOUS | mask::OCCLUSION | mask::GRAZING;
    looming.mask[cell] & invalid == 0
        && looming.incidence_cos[cell].abs() >= min_cos
        && looming.l_lidar[cell].is_finite()
        && looming.sigma_per_s[cell].is_finite()
}

/// Inverse-variance weighted median of `values` over `cells`, and its
/// standard error; `None` with fewer than [`MIN_MEASURED_CELLS`] cells.
fn robust_mean(cells: &[usize], values: &[f32], sigmas: &[f32]) -> Option<(f64, f64)> {
    // The values as their order keys ([`order::key`]), for the selections.
    let weighted = cells.iter().filter(|&&c| values[c].is_finite()).map(|&c| {
        let sigma = f64::from(sigmas[c]).max(1e-3);
        (order::key(f64::from(values[c])), 1.0 / (sigma * sigma))
    });
    let mut weighted = collect_bounded(cells.len(), weighted);
    if weighted.len() < MIN_MEASURED_CELLS {
        return None;
    }
    let centre = weighted_median(&mut weighted);
    let (sum_w, sum_w2) = weighted
        .iter()
        .fold((0.0, 0.0), |(s, s2), &(_, w)| (s + w, s2 + w * w));
    // The deviations from the centre in place of the values, in the order
    // the weights were summed in (no second list).
    for value in &mut weighted {
        value.0 = order::key((order::value(value.0) - centre).abs());
    }
    let mad = weighted_median(&mut weighted);
    let effective = sum_w * sum_w / sum_w2;
    // The spread of the cells, and at least the engine's own noise.
    let noise = (1.0 / sum_w).sqrt();
    let se = (1.4826 * mad / effective.sqrt()).max(noise);
    Some((centre, se))
}

/// The value at which half the weight lies on either side: the first value,
/// in ascending order, at which the running sum of the weights reaches half
/// their total. By selection (quickselect on the values, keeping the weight
/// of all that lie below the part still searched), not a sort: an object's
/// cells run to thousands and this runs several times per object. The
/// values as their order keys ([`order::key`]: integers compared, in
/// `total_cmp`'s order). Reorders `values`.
fn weighted_median(values: &mut [(i64, f64)]) -> f64 {
    let half = values.iter().map(|v| v.1).sum::<f64>() / 2.0;
    let by_value = |a: &(i64, f64), b: &(i64, f64)| a.0.cmp(&b.0);
    // `values[lo..hi]` holds the answer; `below` weighs `values[..lo]`, all
    // of which precede it in ascending order.
    let (mut lo, mut hi, mut below) = (0, values.len(), 0.0);
    while hi - lo > SORTED_TAIL {
        let mid = lo + (hi - lo) / 2;
        let (left, pivot, _) = values[lo..hi].select_nth_unstable_by(mid - lo, by_value);
        let left_weight = left.iter().map(|v| v.1).sum::<f64>();
        if below + left_weight >= half {
            hi = mid;
        } else if below + left_weight + pivot.1 >= half {
            return order::value(pivot.0);
        } else {
            below += left_weight + pivot.1;
            lo = mid + 1;
        }
    }
    let tail = &mut values[lo..hi];
    tail.sort_unstable_by(by_value);
    let mut seen = below;
    for &(value, weight) in tail.iter() {
        seen += weight;
        if seen >= half {
            return order::value(value);
        }
    }
    // Not reached (weights not finite): the largest value, as a full scan.
    values
        .iter()
        .map(|v| v.0)
        .max()
        .map_or(f64::NAN, order::value)
}

/// Below this many values [`weighted_median`] sorts what is left.
const SORTED_TAIL: usize = 16;

#[cfg(test)]
mod tests {
    use super::*;

    /// What `keep_cells_seen_before` takes for "nothing to measure again":
    /// the cells kept are all the measuring cells exactly where every
    /// measuring cell passes the test.
    #[test]
    fn the_cells_kept_are_all_exactly_where_every_measuring_cell_passes() {
        let mut rng = crate::test_rng::SplitMix64(26);
        let (mut all_kept, mut some_dropped) = (0, 0);
        for _ in 0..5_000 {
            let n = rng.uniform(0.0, 9.0) as usize;
            let cos: Vec<f32> = (0..n).map(|_| rng.uniform(0.0, 1.0) as f32).collect();
            let valid: Vec<bool> = (0..n).map(|_| rng.uniform(0.0, 1.0) < 0.8).collect();
            let seen: Vec<bool> = (0..n).map(|_| rng.uniform(0.0, 1.0) < 0.9).collect();
            let cells: Vec<usize> = (0..n).collect();
            let measures = |c: usize, min_cos: f32| valid[c] && cos[c] >= min_cos;
            let all = cells_measuring(&cells, measures, |_| true);
            let kept = cells_measuring(&cells, measures, |c| seen[c]);
            let every_passes = all.iter().all(|&c| seen[c]);
            assert_eq!(kept == all, every_passes, "{cos:?} {valid:?} {seen:?}");
            if every_passes {
                all_kept += 1;
            } else {
                some_dropped += 1;
            }
        }
        assert!(all_kept > 500 && some_dropped > 500);
    }

    /// The selection gives what the running sum over the sorted values
    /// gives, ties and equal weights included.
    #[test]
    fn weighted_median_by_selection_is_the_sorted_scans() {
        let sorted_scan = |values: &[(f64, f64)]| {
            let mut sorted = values.to_vec();
            sorted.sort_by(|a, b| a.0.total_cmp(&b.0));
            let half = values.iter().map(|v| v.1).sum::<f64>() / 2.0;
            let mut seen = 0.0;
            for &(value, weight) in &sorted {
                seen += weight;
                if seen >= half {
                    return value;
                }
            }
            sorted.last().map_or(f64::NAN, |v| v.0)
        };
        let mut state = 99u32;
        let mut next = |modulo: u32| {
            state = state.wrapping_mul(1_664_525).wrapping_add(1_013_904_223);
            (state >> 8) % modulo
        };
        for case in 0..3000 {
            let count = 1 + case % 200;
            let values: Vec<(f64, f64)> = (0..count)
                .map(|_| {
                    // Few distinct values (ties) and weights: 1, 4 or 1e6.
                    let value = f64::from(next(40)) * 0.25 - 5.0;
                    let weight = [1.0, 4.0, 1e6][next(3) as usize];
                    (value, weight)
                })
                .collect();
            let expected = sorted_scan(&values);
            let mut keyed: Vec<(i64, f64)> =
                values.iter().map(|&(v, w)| (order::key(v), w)).collect();
            assert_eq!(weighted_median(&mut keyed), expected, "{values:?}");
        }
    }

    #[test]
    fn an_object_assumed_static_looms_by_the_ego_velocity_along_its_nearest_rays() {
        // A wall 10 m ahead, 2 m wide, approached at 5 m/s: its nearest
        // returns (straight ahead) loom at v / r = 0.5 1/s.
        let wall: Vec<[f64; 3]> = (0..=40)
            .map(|k| [10.0, -1.0 + 0.05 * f64::from(k), 0.0])
            .collect();
        let (looming, sigma) = looming_if_static(Some([5.0, 0.0, 0.0]), None, &wall).unwrap();
        assert!((looming - 0.5).abs() < 0.002, "{looming}");
        // A measured velocity: 1 % of the value and 0.005 1/s.
        assert!((sigma - 0.01).abs() < 1e-3, "{sigma}");
        // An estimated one adds its uncertainty along the ray: 0.1 m/s at
        // 10 m is 0.01 1/s.
        let mut covariance = [[0.0; 6]; 6];
        for (k, row) in covariance.iter_mut().enumerate().skip(3) {
            row[k] = 0.01;
        }
        let estimate = EgoEstimate {
            velocity_mps: [5.0, 0.0, 0.0],
            angular_velocity_radps: [0.0; 3],
            inlier_cells: 1000,
            renders: 1,
            residual_m: 0.02,
            velocity_estimated: true,
            rotation_estimated: true,
            covariance,
        };
        let (_, sigma) = looming_if_static(Some([5.0, 0.0, 0.0]), Some(&estimate), &wall).unwrap();
        assert!((sigma - 0.01f64.hypot(0.01)).abs() < 1e-3, "{sigma}");
        // Rotation changes no range; no ego motion, no value.
        assert_eq!(looming_if_static(None, None, &wall), None);
        assert_eq!(looming_if_static(Some([5.0, 0.0, 0.0]), None, &[]), None);
    }

    #[test]
    fn the_weighted_median_ignores_a_few_wild_cells() {
        let values = [0.10f32, 0.11, 0.09, 0.10, 0.12, 5.0, -4.0];
        let sigmas = [0.02f32; 7];
        let cells: Vec<usize> = (0..7).collect();
        let (centre, se) = robust_mean(&cells, &values, &sigmas).unwrap();
        assert!((centre - 0.10).abs() < 0.011, "{centre}");
        assert!(se < 0.02, "{se}");
        // A precise cell outweighs noisy ones.
        let sigmas = [0.01f32, 0.2, 0.2, 0.2, 0.2, 0.2, 0.2];
        let values = [0.3f32, 0.0, 0.0, 0.0, 0.0, 0.0, 0.0];
        let (precise, _) = robust_mean(&cells, &values, &sigmas).unwrap();
        assert!((precise - 0.3).abs() < 1e-6, "{precise}");
        assert_eq!(robust_mean(&cells[..2], &values, &sigmas), None);
    }
}
