//! The ground of one scan, found without ego information: cells whose fitted
//! normal is within 15 degrees of the LiDAR's z axis, whose return lies below
//! the sensor, and near the scan's dominant ground height (the median height
//! of such cells), then near the plane fitted through those (a tilted mount
//! or a sloped road keeps its ground). Objects are what stands above it;
//! `looming::quality` judges the ego motion by its looming.

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
        let candidates = ground_candidates(looming, scan);
        let mut heights: Vec<f64> = candidates.iter().map(|(_, p)| p[2]).collect();
        heights.sort_unstable_by(f64::total_cmp);
        let height = *heights.get(heights.len() / 2)?;
        let height = if heights.len().is_multiple_of(2) {
            0.5 * (height + heights[heights.len() / 2 - 1])
        } else {
            height
        };
        let near_height: Vec<(usize, [f64; 3])> = candidates
            .iter()
            .filter(|(_, p)| {
                (p[2] - height).abs()
                    <= GROUND_HEIGHT_TOLERANCE_M + GROUND_HEIGHT_TOLERANCE_PER_M * horizontal(p)
            })
            .copied()
            .collect();
        let plane = (near_height.len() >= MIN_PLANE_CELLS)
            .then(|| fit_plane(&near_height.iter().map(|(_, p)| *p).collect::<Vec<_>>()))
            .flatten();
        let cells = match plane {
            Some(plane) => candidates
                .into_iter()
                .filter(|(_, p)| {
                    height_above(plane, p).abs()
                        <= GROUND_PLANE_TOLERANCE_M + GROUND_PLANE_TOLERANCE_PER_M * horizontal(p)
                })
                .collect(),
            None => near_height,
        };
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

fn horizontal(p: &[f64; 3]) -> f64 {
    p[0].hypot(p[1])
}

fn height_above([a, b, c]: [f64; 3], p: &[f64; 3]) -> f64 {
    p[2] - (a * p[0] + b * p[1] + c)
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
fn ground_candidates(looming: &PairLooming, scan: &Scan) -> Vec<(usize, [f64; 3])> {
    let min_cos = GROUND_MAX_TILT_DEG.to_radians().cos();
    (0..looming.mask.len())
        .filter_map(|cell| {
            let p = cell_point(looming, scan, cell)?;
            let n = looming.normal.get(cell)?;
            let norm = (n[0] * n[0] + n[1] * n[1] + n[2] * n[2]).sqrt();
            let upward = norm > 0.5 && f64::from(n[2] / norm) >= min_cos;
            (upward && p[2] < 0.0).then_some((cell, p))
        })
        .collect()
}

/// Least-squares plane `z = a x + b y + c` through the points.
fn fit_plane(points: &[[f64; 3]]) -> Option<[f64; 3]> {
    let mut m = nalgebra::Matrix3::<f64>::zeros();
    let mut v = nalgebra::Vector3::<f64>::zeros();
    for p in points {
        let row = nalgebra::Vector3::new(p[0], p[1], 1.0);
        m += row * row.transpose();
        v += row * p[2];
    }
    let solution = m.try_inverse()? * v;
    solution
        .iter()
        .all(|x| x.is_finite())
        .then(|| [solution[0], solution[1], solution[2]])
}
