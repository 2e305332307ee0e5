//! Per-laser range bias, estimated from the scan itself.
//!
//! Real multi-laser sensors carry a range offset per laser that their
//! factory calibration leaves (a few centimetres on KITTI's HDL-64E: on a
//! flat road the rings form a staircase, consecutive lasers up to 7 cm
//! apart in range). Looming differences the previous surface at one ray
//! against the current one at the same ray; when the ego motion or the
//! rotation brings a ray onto another laser's part of the previous surface,
//! the two lasers' offsets read as motion: 3 cm at 8 m in 0.1 s is
//! 0.04 1/s on a static road.
//!
//! Estimate: each laser's returns against the plane through the returns of
//! the two lasers beside it (rows above and below, in a window along the
//! row). On any plane that residual is `b_k - (w b_{k-1} + (1 - w) b_{k+1})`,
//! a second difference of the offsets; the offsets follow by least squares.
//! A constant offset and one growing linearly across rows are invisible to
//! it, and harmless to looming (all rays move together). Surfaces that are
//! not planes at the scale of three rows (foliage, edges) fail the planarity
//! gate, creases between the rows beside (a road meeting a wall) the rows
//! two away; the median over a row's samples takes care of the rest.

use nalgebra::{DMatrix, DVector, Vector3};
use rayon::prelude::*;

use super::grid::{ImageGeometry, NO_POINT, RangeImage};
use crate::model::Scan;

/// Columns on each side of a cell in the window of the rows beside it.
const HALF_COLS: usize = 3;
/// Every how many columns a sample is taken.
const STRIDE: usize = 2;
/// Samples a row needs for its second difference.
const MIN_SAMPLES: usize = 40;
/// Largest scatter about the neighbours' plane, metres: beyond it the
/// window is not one plane.
const PLANARITY_M: f64 = 0.04;
/// Largest distance of the returns two rows away from the plane of the rows
/// beside, metres. Two rows of returns are two lines and lie in one plane
/// whatever they see: at a crease (the road meeting a wall between them) that
/// plane is a chamfer, and the middle row, on the road or the wall, reads
/// 0.1-0.5 m off it, as much as a laser offset of that size. The rows beyond
/// leave the chamfer: on `synth --lidars 3`'s urban-turn this rejects 98 % of
/// the samples reading more than 8 cm and 2 % of those under 3 cm (the right
/// sensor, passing a building 8.5 m away, read a spurious 13 cm offset on
/// one laser without it). Loose enough for real offsets of several
/// centimetres on the rows beyond (their distance is the offset times `|n . e|`).
const OUTER_PLANARITY_M: f64 = 0.1;
/// Rays closer to grazing than this (`|n . e|`) give no sample.
const MIN_INCIDENCE: f64 = 0.1;
/// Weight pulling each offset to zero: fixes the invisible constant and
/// linear parts, and damps every pattern slower than about five rows, which
/// second differences see too faintly to tell from noise (a smaller weight
/// turned noise of a millimetre into offsets of several on the synthetic
/// sensor).
const RIDGE: f64 = 0.05;
/// Offsets whose root mean square is below this are taken for noise
/// (metres) and nothing changes: the estimate reads 0.001-0.0045 m on the
/// synthetic sensor, which has no offsets, and 0.018-0.021 m on the real
/// HDL-64E and Pandar64.
pub(crate) const MIN_RMS_M: f64 = 0.009;
/// Scans after which the running estimate becomes a moving average (a
/// sensor's offsets do not change within a log; the average makes the two
/// scans of a pair carry nearly the same correction).
const AVERAGE_SCANS: f64 = 10.0;

/// Once the average has settled, a scan in this many is estimated (the
/// offsets are the sensor's: a tenth of the estimates tracks them as well,
/// for a tenth of the cost, 11 ms per 64 x 2048 scan).
const REESTIMATE_EVERY: u64 = 10;

/// The sensor's per-laser offsets, averaged over the scans seen so far.
#[derive(Debug, Clone, Default)]
pub(crate) struct RangeBias {
    per_row_m: Vec<f64>,
    /// Estimates folded in.
    scans: f64,
    /// Scans seen (`update` calls), estimated or not.
    seen: u64,
}

impl RangeBias {
    /// Whether the scan `ahead` scans after the next one to be seen
    /// (`update`) should be estimated: every scan until the average settles,
    /// then one in [`REESTIMATE_EVERY`].
    pub fn wants_estimate(&self, ahead: u64) -> bool {
        let index = self.seen + ahead;
        self.scans < AVERAGE_SCANS || index.is_multiple_of(REESTIMATE_EVERY)
    }

    /// Fold one scan's estimate in (None: not estimated; a changed row count
    /// starts afresh) and return the offsets to take out of that scan: the
    /// running average, or zeros while it stays below [`MIN_RMS_M`].
    pub fn update(&mut self, scan_estimate: Option<Vec<f64>>, rows: usize) -> Vec<f32> {
        if self.per_row_m.len() != rows && self.scans > 0.0 {
            *self = Self::default();
        }
        self.seen += 1;
        if let Some(estimate) = scan_estimate.filter(|e| e.len() == rows) {
            if self.scans == 0.0 {
                self.per_row_m = estimate;
            } else {
                let weight = 1.0 / (self.scans + 1.0).min(AVERAGE_SCANS);
                for (mean, new) in self.per_row_m.iter_mut().zip(estimate) {
                    *mean += weight * (new - *mean);
                }
            }
            self.scans += 1.0;
        }
        self.applied(rows)
    }

    fn applied(&self, rows: usize) -> Vec<f32> {
        let rms = (self.per_row_m.iter().map(|b| b * b).sum::<f64>() / rows.max(1) as f64).sqrt();
        if self.per_row_m.len() != rows || !rms.is_finite() || rms < MIN_RMS_M {
            return vec![0.0; rows];
        }
        self.per_row_m.iter().map(|&b| b as f32).collect()
    }
}

/// Most rows estimated: the dense solve grows with the cube of the rows (a
/// ring field may claim up to 1024 rings; real heads have at most 128).
const MAX_ROWS: usize = 256;

/// One scan's range offset of each row's laser, metres (positive: the laser
/// reads long); None on sparse sensors (rows too far apart to share a
/// plane) and images of fewer than three or more than [`MAX_ROWS`] rows.
pub fn estimate(scan: &Scan, image: &RangeImage, geometry: &ImageGeometry) -> Option<Vec<f64>> {
    let rows = geometry.rows;
    if !(3..=MAX_ROWS).contains(&rows) || geometry.sparse_rows() {
        return None;
    }
    let returns = CellReturns::of(scan, image);
    let second: Vec<Option<(f64, f64)>> = (0..rows)
        .into_par_iter()
        .map(|row| second_difference(&returns, geometry, row))
        .collect();
    Some(solve(&second))
}

/// Each cell's return as the estimate reads it, taken once per scan: a
/// sample's windows read each return some fourteen times, and its range
/// (a root) was taken at every read.
struct CellReturns {
    /// The cell's return in `f64`, where it has one.
    point: Vec<Vector3<f64>>,
    /// Its range (`norm`), NaN for a cell without a return.
    range_m: Vec<f64>,
}

impl CellReturns {
    fn of(scan: &Scan, image: &RangeImage) -> Self {
        let (point, range_m) = image
            .point
            .par_iter()
            .map(|&index| {
                if index == NO_POINT {
                    return (Vector3::zeros(), f64::NAN);
                }
                let p = scan.points_m[index as usize];
                let p = Vector3::new(f64::from(p[0]), f64::from(p[1]), f64::from(p[2]));
                (p, p.norm())
            })
            .unzip();
        Self { point, range_m }
    }

    /// The cell's return and its range, where it has one.
    #[inline]
    fn at(&self, cell: usize) -> Option<(Vector3<f64>, f64)> {
        let range_m = self.range_m[cell];
        (!range_m.is_nan()).then(|| (self.point[cell], range_m))
    }
}

/// For a middle row: the median range residual of its returns against the
/// plane of the rows beside it, and the weight `w` of the row below in that
/// plane at this row's rays. None for the first and last rows or too few
/// samples. (Rows whose neighbours are far apart were tried without: the
/// Pandar64's lowest lasers, 5 degrees apart, read offsets of +5, -11 and +5
/// cm; leaving them out left it 52.0 % trusted instead of 58.3 %, so the
/// floor they see is flatter with the offsets taken out.)
fn second_difference(
    returns: &CellReturns,
    geometry: &ImageGeometry,
    row: usize,
) -> Option<(f64, f64)> {
    if row == 0 || row + 1 >= geometry.rows {
        return None;
    }
    let elevations = &geometry.beams.elevations_rad;
    let span = elevations[row + 1] - elevations[row - 1];
    if span <= 0.0 {
        return None;
    }
    let below_weight = (elevations[row + 1] - elevations[row]) / span;
    let beside = [Some(row - 1), Some(row + 1)];
    let outer = [
        row.checked_sub(2),
        Some(row + 2).filter(|&r| r < geometry.rows),
    ];
    let mut points: Vec<Vector3<f64>> = Vec::with_capacity(2 * (2 * HALF_COLS + 1));
    let mut outer_points: Vec<Vector3<f64>> = Vec::with_capacity(2 * (2 * HALF_COLS + 1));
    let mut residuals: Vec<f64> = (0..geometry.cols)
        .step_by(STRIDE)
        .filter_map(|col| {
            let (center, range) = returns.at(row * geometry.cols + col)?;
            let window = |rows, points: &mut Vec<Vector3<f64>>| {
                window_points(returns, geometry, (rows, col, range), points)
            };
            if window(beside, &mut points).iter().any(|&n| n < 3) {
                return None;
            }
            let (normal, centroid, _) = super::surface::fit_plane_spread(&points)?;
            if off_plane(&points, &normal, &centroid) > PLANARITY_M {
                return None;
            }
            window(outer, &mut outer_points);
            if off_plane(&outer_points, &normal, &centroid) > OUTER_PLANARITY_M {
                return None;
            }
            let direction = center / range;
            let incidence = direction.dot(&normal);
            if incidence.abs() < MIN_INCIDENCE {
                return None;
            }
            let residual = range - centroid.dot(&normal) / incidence;
            (residual.abs() < 0.3).then_some(residual)
        })
        .collect();
    if residuals.len() < MIN_SAMPLES {
        return None;
    }
    let mid = residuals.len() / 2;
    let median = *residuals.select_nth_unstable_by(mid, f64::total_cmp).1;
    Some((median, below_weight))
}

/// The returns of `rows` (those that exist) in the window of columns around
/// `col`, within the range gate of a centre return at `range`, into
/// `points`; how many each row gave.
fn window_points(
    returns: &CellReturns,
    geometry: &ImageGeometry,
    (rows, col, range): ([Option<usize>; 2], usize, f64),
    points: &mut Vec<Vector3<f64>>,
) -> [usize; 2] {
    let cols = geometry.cols;
    points.clear();
    let mut per_row = [0usize; 2];
    let window_cols = window_columns(col, cols);
    for (side, r) in rows.into_iter().enumerate() {
        let Some(r) = r else { continue };
        for &c in &window_cols {
            if let Some((p, p_range)) = returns.at(r * cols + c)
                && (p_range - range).abs() <= 0.1 * range + 0.3
            {
                points.push(p);
                per_row[side] += 1;
            }
        }
    }
    per_row
}

/// The columns `col - HALF_COLS ..= col + HALF_COLS`, wrapped around the
/// sweep of `cols` columns: one division per window, then subtractions,
/// not a division per return read (they were most of [`window_points`]).
fn window_columns(col: usize, cols: usize) -> [usize; 2 * HALF_COLS + 1] {
    let first = (col + cols - HALF_COLS) % cols;
    std::array::from_fn(|offset| {
        let mut c = first + offset;
        while c >= cols {
            c -= cols;
        }
        c
    })
}

/// The largest distance of `points` from the plane (0 for none).
fn off_plane(points: &[Vector3<f64>], normal: &Vector3<f64>, centroid: &Vector3<f64>) -> f64 {
    points
        .iter()
        .map(|p| (p - centroid).dot(normal).abs())
        .fold(0.0, f64::max)
}

/// Offsets `b` with `b_k - w_k b_{k-1} - (1 - w_k) b_{k+1} = s_k` for every
/// row with a sample, in the least-squares sense, with a small ridge.
fn solve(second: &[Option<(f64, f64)>]) -> Vec<f64> {
    let rows = second.len();
    let mut normal = DMatrix::<f64>::identity(rows, rows) * RIDGE;
    let mut rhs = DVector::<f64>::zeros(rows);
    for (row, sample) in second.iter().enumerate() {
        let Some((s, w)) = *sample else { continue };
        let terms = [(row - 1, -w), (row, 1.0), (row + 1, -(1.0 - w))];
        for &(i, a) in &terms {
            rhs[i] += a * s;
            for &(j, b) in &terms {
                normal[(i, j)] += a * b;
            }
        }
    }
    match normal.cholesky() {
        Some(c) => c.solve(&rhs).iter().copied().collect(),
        None => vec![0.0; rows],
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn a_staircase_is_recovered_from_its_second_differences() {
        let truth: Vec<f64> = (0..16)
            .map(|k| if k % 3 == 0 { 0.04 } else { -0.02 })
            .collect();
        let mean = truth.iter().sum::<f64>() / 16.0;
        let second: Vec<Option<(f64, f64)>> = (0..16)
            .map(|k| {
                (k > 0 && k < 15).then(|| (truth[k] - 0.5 * (truth[k - 1] + truth[k + 1]), 0.5))
            })
            .collect();
        let found = solve(&second);
        // Up to a constant and a linear trend across rows.
        let fit_mean = found.iter().sum::<f64>() / 16.0;
        let detrended = |v: &[f64], m: f64| -> Vec<f64> {
            let slope = v
                .iter()
                .enumerate()
                .map(|(k, x)| (k as f64 - 7.5) * (x - m))
                .sum::<f64>()
                / (0..16).map(|k| (k as f64 - 7.5).powi(2)).sum::<f64>();
            v.iter()
                .enumerate()
                .map(|(k, x)| x - m - slope * (k as f64 - 7.5))
                .collect()
        };
        let (a, b) = (detrended(&truth, mean), detrended(&found, fit_mean));
        // The rows at the ends have one neighbour only and no equation of
        // their own: judged on the rows between; the ridge shrinks a
        // staircase of period 3 by a few percent.
        let rms = |v: &[f64]| (v.iter().map(|x| x * x).sum::<f64>() / v.len() as f64).sqrt();
        let error: Vec<f64> = a[2..14].iter().zip(&b[2..14]).map(|(x, y)| x - y).collect();
        assert!(rms(&error) < 0.15 * rms(&a[2..14]), "{a:?} vs {b:?}");
    }

    #[test]
    fn the_offsets_are_estimated_on_every_scan_until_settled_then_one_in_ten() {
        let mut bias = RangeBias::default();
        let mut estimated = Vec::new();
        for scan in 0..40u64 {
            let wanted = bias.wants_estimate(0);
            if wanted {
                estimated.push(scan);
            }
            bias.update(wanted.then(|| vec![0.02, -0.02, 0.02]), 3);
        }
        let mut expected: Vec<u64> = (0..10).collect();
        expected.extend([10, 20, 30]);
        assert_eq!(estimated, expected);
        // The average: offsets above the floor are applied.
        assert_eq!(bias.update(None, 3), vec![0.02, -0.02, 0.02]);
    }

    /// The estimate on `scan`'s returns, `rings` their lasers, the image
    /// `cols` columns wide.
    fn estimate_on(mut scan: Scan, rings: Vec<u16>, cols: usize) -> Vec<f64> {
        scan.source_index = (0..scan.points_m.len() as u32).collect();
        scan.input_point_count = scan.points_m.len() as u32;
        scan.ring = Some(rings);
        let geometry =
            crate::engine::grid::geometry_for((&scan, &scan), (Some(cols), 1), None, None)
                .unwrap()
                .0;
        let image = RangeImage::build(&scan, &geometry);
        estimate(&scan, &image, &geometry).unwrap()
    }

    /// A sensor 1.33 m above a road ringed by a wall 8.5 m away (the side
    /// sensor of `synth --lidars 3` passing a building): 32 beams from -25
    /// to +15 degrees, no laser offsets. The road meets the wall between
    /// two rows, whose returns lie in one chamfer plane; the rows beyond
    /// (checked) keep the crease from reading as offsets of the rows at it.
    #[test]
    fn a_crease_between_the_rows_beside_reads_no_offset() {
        let (beams, cols, height, wall) = (32u16, 512usize, 1.33f64, 8.5f64);
        let mut scan = Scan::empty(0, "lidar".into(), nalgebra::Isometry3::identity());
        let mut rings = Vec::new();
        for ring in 0..beams {
            let elevation = (-25.0 + 40.0 * f64::from(ring) / f64::from(beams - 1)).to_radians();
            // The road where the ray meets it before the wall, else the wall.
            let horizontal = if elevation < 0.0 {
                (height / -elevation.tan()).min(wall)
            } else {
                wall
            };
            for col in 0..cols {
                let azimuth = std::f64::consts::TAU * col as f64 / cols as f64;
                let z = (horizontal * elevation.tan()).max(-height);
                let (x, y) = (horizontal * azimuth.cos(), horizontal * azimuth.sin());
                scan.points_m.push([x as f32, y as f32, z as f32]);
                rings.push(ring);
            }
        }
        let offsets = estimate_on(scan, rings, cols);
        // Without the rows beyond: up to 37 cm on the rows about the crease.
        let largest = offsets.iter().fold(0.0f64, |m, b| m.max(b.abs()));
        assert!(largest < 0.01, "{offsets:?}");
    }

    /// A room seen by 32 lasers, each reading long by its own offset (a
    /// staircase of period three, as KITTI's rings): the scan's estimate
    /// finds each laser's offset against the others' (the differences
    /// between neighbours, which looming sees, 6 cm apart) within 2.5 cm
    /// each and 5 mm on the mean.
    #[test]
    fn each_lasers_offset_is_found_on_a_room() {
        let (beams, cols) = (32u16, 512usize);
        let offset_m = |ring: u16| if ring.is_multiple_of(3) { 0.04 } else { -0.02 };
        let mut scan = Scan::empty(0, "lidar".into(), nalgebra::Isometry3::identity());
        let mut rings = Vec::new();
        for ring in 0..beams {
            let elevation = (-20.0 + 30.0 * f64::from(ring) / f64::from(beams - 1)).to_radians();
            for col in 0..cols {
                let azimuth = std::f64::consts::TAU * col as f64 / cols as f64;
                let e = nalgebra::Vector3::new(
                    elevation.cos() * azimuth.cos(),
                    elevation.cos() * azimuth.sin(),
                    elevation.sin(),
                );
                // A box 24 x 16 m, 3 m high, the sensor 1.5 m above its floor.
                let range = [(e.x, 12.0), (e.y, 8.0), (e.z, 1.5)]
                    .iter()
                    .filter(|(d, _)| d.abs() > 1e-9)
                    .map(|&(d, half)| if d < 0.0 { -half / d } else { half / d })
                    .fold(f64::INFINITY, f64::min);
                let p = e * (range + offset_m(ring));
                scan.points_m.push([p.x as f32, p.y as f32, p.z as f32]);
                rings.push(ring);
            }
        }
        let found = estimate_on(scan, rings, cols);
        // Neighbours' differences, away from the ends (the ridge's pull);
        // the rows about the horizon, seeing the room's creases, read up
        // to 2 cm off.
        let mut error_sum = 0.0;
        for ring in 3..beams - 4 {
            let k = usize::from(ring);
            let (truth, got) = (offset_m(ring + 1) - offset_m(ring), found[k + 1] - found[k]);
            assert!(
                (got - truth).abs() < 0.025,
                "ring {ring}: {got} for {truth}"
            );
            error_sum += (got - truth).abs();
        }
        let mean_error = error_sum / f64::from(beams - 7);
        assert!(mean_error < 0.005, "mean error {mean_error} m");
    }

    #[test]
    fn no_samples_give_no_offsets() {
        assert!(solve(&[None, None, None]).iter().all(|&b| b == 0.0));
    }
}
