//! The ground of one scan, found without ego information: cells whose fitted
//! normal is within 15 degrees of the LiDAR's z axis, whose return lies below
//! the sensor, and near the scan's dominant ground height (the median height
//! of such cells), then near the plane fitted through those (a tilted mount
//! or a sloped road keeps its ground). Objects are what stands above it;
//! `looming::quality` judges the ego motion by its looming.

use rayon::prelude::*;

use crate::engine::{PairLooming, mask};
use crate::model::Scan;

/// Largest angle between a ground cell's normal and the LiDAR's z axis.
pub const GROUND_MAX_TILT_DEG: f64 = 15.0;
/// First pass: distance from the dominant ground height allowed at the
/// sensor, metres, ...
pub const GROUND_HEIGHT_TOLERANCE_M: f64 = 0.3;
/// ... growing by this much per metre of horizontal distance (a 3 degree
/// tilt or slope).
pub const GROUND_HEIGHT_TOLERANCE_PER_M: f64 = 0.05;
/// Second pass: distance from the plane fitted through the first pass.
pub const GROUND_PLANE_TOLERANCE_M: f64 = 0.15;
pub const GROUND_PLANE_TOLERANCE_PER_M: f64 = 0.02;
/// Fewest first-pass cells to fit a plane through.
pub const MIN_PLANE_CELLS: usize = 30;

/// The ground found in one scan.
#[derive(Debug, Clone, PartialEq)]
pub struct GroundFit {
    /// Dominant ground height in the LiDAR frame (median z of the
    /// candidates), metres.
    pub height_m: f64,
    /// `z = a x + b y + c` through the ground, when enough cells support one.
    pub plane: Option<[f64; 3]>,
    /// The ground cells and their returns (LiDAR frame, metres).
    pub cells: Vec<(usize, [f64; 3])>,
}

impl GroundFit {
    /// The ground of `scan` as the engine imaged it; `None` without a
    /// candidate cell.
    pub fn find(looming: &PairLooming, scan: &Scan) -> Option<Self> {
        Self::find_in(looming, &CellPoints::of(looming, scan))
    }

    /// [`GroundFit::find`] with the pair's cell returns already gathered.
    pub fn find_in(looming: &PairLooming, points: &CellPoints) -> Option<Self> {
        let candidates = ground_candidates(looming, points);
        // Each candidate's return read again where wanted, from the dense
        // gathered returns (a list of cells and returns was four times the
        // memory, grown by doubling).
        let candidate_points = || {
            candidates
                .iter()
                .filter_map(|&cell| Some((cell, points.get(cell)?)))
        };
        let heights = candidate_points().map(|(_, p)| super::order::key(p[2]));
        let mut heights = super::collect_bounded(candidates.len(), heights);
        let height = median(&mut heights)?;
        let near = |p: &[f64; 3]| {
            (p[2] - height).abs()
                <= GROUND_HEIGHT_TOLERANCE_M + GROUND_HEIGHT_TOLERANCE_PER_M * horizontal(p)
        };
        // The plane's sums straight from the candidates near the height
        // (no list of them, wanted only where there are too few for a plane).
        let (near_count, plane) = fit_plane(candidate_points().map(|(_, p)| p).filter(|p| near(p)));
        let plane = plane.filter(|_| near_count >= MIN_PLANE_CELLS);
        let on_ground = |p: &[f64; 3]| match plane {
            Some(plane) => {
                height_above(plane, p).abs()
                    <= GROUND_PLANE_TOLERANCE_M + GROUND_PLANE_TOLERANCE_PER_M * horizontal(p)
            }
            None => near(p),
        };
        let cells = candidate_points().filter(|(_, p)| on_ground(p));
        let cells = super::collect_bounded(candidates.len(), cells);
        Some(Self {
            height_m: height,
            plane,
            cells,
        })
    }

    /// Height of `p` above the ground (the plane, else the dominant height).
    pub fn height_above(&self, p: &[f64; 3]) -> f64 {
        match self.plane {
            Some(plane) => height_above(plane, p),
            None => p[2] - self.height_m,
        }
    }
}

/// The median of the values whose [`super::order::key`]s `keys` holds
/// (the mean of the middle two for an even count), by selection, not a
/// sort: tens of thousands of ground cells per scan. Reorders `keys`.
fn median(keys: &mut [i64]) -> Option<f64> {
    let (mid, even) = (keys.len() / 2, keys.len().is_multiple_of(2));
    if keys.is_empty() {
        return None;
    }
    let (below, &mut upper, _) = keys.select_nth_unstable(mid);
    let upper = super::order::value(upper);
    if !even {
        return Some(upper);
    }
    // The lower middle is the largest of those before the middle.
    let lower = super::order::value(*below.iter().max()?);
    Some(0.5 * (upper + lower))
}

/// Distance from the sensor's z axis, metres (`sqrt` of the squares, not
/// libm's `hypot`, whose overflow guards metres never need: this runs for
/// every ground candidate twice).
fn horizontal(p: &[f64; 3]) -> f64 {
    (p[0] * p[0] + p[1] * p[1]).sqrt()
}

fn height_above([a, b, c]: [f64; 3], p: &[f64; 3]) -> f64 {
    p[2] - (a * p[0] + b * p[1] + c)
}

/// The return of every range-image cell (its nearest, as [`cell_point`]
/// gives it), gathered once per pair on both cores: the ground and the
/// segmentation read every cell's, and gathered from the scan's points in
/// cell order each read waited on a cache miss (a fifth of the objects'
/// stage's samples, serial, twice per pair).
pub struct CellPoints {
    /// The scan's `f32` coordinates (exactly what `cell_point` widens).
    points_m: Vec<Option<[f32; 3]>>,
}

impl CellPoints {
    pub fn of(looming: &PairLooming, scan: &Scan) -> Self {
        let points_m = (0..looming.mask.len())
            .into_par_iter()
            .map(|cell| cell_point(looming, scan, cell).map(|p| p.map(|v| v as f32)))
            .collect();
        Self { points_m }
    }

    /// The return of `cell`, as [`cell_point`] gives it.
    #[inline]
    pub fn get(&self, cell: usize) -> Option<[f64; 3]> {
        self.points_m.get(cell)?.map(|p| p.map(f64::from))
    }
}

pub fn cell_point(looming: &PairLooming, scan: &Scan, cell: usize) -> Option<[f64; 3]> {
    if looming.mask[cell] & mask::EMPTY != 0 {
        return None;
    }
    let index = *looming.image.point.get(cell)?;
    let p = scan.points_m.get(index as usize)?;
    Some([f64::from(p[0]), f64::from(p[1]), f64::from(p[2])])
}

/// Cells that may be ground: an upward normal within `GROUND_MAX_TILT_DEG` of
/// z, and the return below the sensor.
fn ground_candidates(looming: &PairLooming, points: &CellPoints) -> Vec<usize> {
    let min_cos = GROUND_MAX_TILT_DEG.to_radians().cos();
    // The normal first: it lies in a dense array, where the return is wanted
    // only for cells facing up.
    let candidates = (0..looming.mask.len()).filter(|&cell| {
        let Some(n) = looming.normal.get(cell) else {
            return false;
        };
        // (`n[2] > 0.4` first: the tilt test implies it, as a normal longer
        // than 0.5 within 15 degrees of z rises more than 0.48; a wall's or
        // an object's normal is turned away without a root and a division.)
        let upward = n[2] > 0.4 && {
            let norm = (n[0] * n[0] + n[1] * n[1] + n[2] * n[2]).sqrt();
            norm > 0.5 && f64::from(n[2] / norm) >= min_cos
        };
        upward && points.get(cell).is_some_and(|p| p[2] < 0.0)
    });
    super::collect_bounded(looming.mask.len(), candidates)
}

/// How many points there are, and the least-squares plane
/// `z = a x + b y + c` through them.
fn fit_plane(points: impl Iterator<Item = [f64; 3]>) -> (usize, Option<[f64; 3]>) {
    let mut m = nalgebra::Matrix3::<f64>::zeros();
    let mut v = nalgebra::Vector3::<f64>::zeros();
    let mut count = 0;
    for p in points {
        let row = nalgebra::Vector3::new(p[0], p[1], 1.0);
        m += row * row.transpose();
        v += row * p[2];
        count += 1;
    }
    let solution = m.try_inverse().map(|inverse| inverse * v);
    let plane = solution
        .filter(|s| s.iter().all(|x| x.is_finite()))
        .map(|s| [s[0], s[1], s[2]]);
    (count, plane)
}

#[cfg(test)]
mod tests {
    use super::*;

    /// The selection gives the sorted list's median, for odd and even counts.
    #[test]
    fn median_by_selection_is_the_sorted_median() {
        let mut state = 7u32;
        for count in 0..40 {
            let values: Vec<f64> = (0..count)
                .map(|_| {
                    state = state.wrapping_mul(1_664_525).wrapping_add(1_013_904_223);
                    f64::from(state >> 20) / 100.0 - 20.0
                })
                .collect();
            let mut sorted = values.clone();
            sorted.sort_unstable_by(f64::total_cmp);
            let expected = match count {
                0 => None,
                n if n % 2 == 1 => Some(sorted[n / 2]),
                n => Some(0.5 * (sorted[n / 2] + sorted[n / 2 - 1])),
            };
            let mut keys: Vec<i64> = values
                .iter()
                .map(|&v| crate::objects::order::key(v))
                .collect();
            assert_eq!(median(&mut keys), expected, "{values:?}");
        }
    }
}
