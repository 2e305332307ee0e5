//! Local surfaces of a range image: a plane fitted to each cell's 3x3
//! neighbourhood gives a denoised range (the cell's ray against the plane),
//! the surface normal (so grazing cells are known), and occlusion edges
//! (neighbours far off the plane).

use nalgebra::{Matrix3, Vector3};
use rayon::prelude::*;

use super::grid::{ImageGeometry, NO_POINT, RangeImage};
use crate::messages::Scan;

/// Per cell of one image.
#[derive(Debug, Clone)]
pub struct Surfaces {
    /// Denoised range (raw where no plane could be fitted), metres; NaN empty.
    pub range_m: Vec<f32>,
    /// Unit direction of the cell's return (LiDAR frame).
    pub direction: Vec<[f32; 3]>,
    /// Unit plane normal facing the sensor; zero when unknown.
    pub normal: Vec<[f32; 3]>,
    /// `|n . e|`, 1 when unknown.
    pub incidence_cos: Vec<f32>,
    /// Points the plane was fitted to (1 = raw range kept).
    pub support: Vec<u8>,
    /// A neighbour lies on another surface (occlusion edge).
    pub edge: Vec<bool>,
}

/// Tuning of the surface fit.
#[derive(Debug, Clone, Copy)]
pub struct SurfaceParams {
    /// Range noise of the sensor (1 sigma), metres.
    pub range_noise_m: f64,
    /// Columns on each side of a cell in its fitting window: the window spans
    /// 3 beams and about as much azimuth as elevation, so a dense sensor (2048
    /// columns) does not fit planes to points a few centimetres apart.
    pub half_cols: usize,
}

impl SurfaceParams {
    pub fn for_geometry(geometry: &ImageGeometry, range_noise_m: f64) -> Self {
        let elevations = &geometry.beams.elevations_rad;
        let row_step = match (elevations.first(), elevations.last()) {
            (Some(lo), Some(hi)) if elevations.len() > 1 => {
                (hi - lo) / (elevations.len() - 1) as f64
            }
            _ => 0.0,
        };
        let col_step = std::f64::consts::TAU / geometry.cols as f64;
        let half_cols = (row_step / col_step).round().clamp(1.0, 4.0) as usize;
        Self {
            range_noise_m,
            half_cols,
        }
    }
}

impl Surfaces {
    pub fn estimate(
        scan: &Scan,
        image: &RangeImage,
        geometry: &ImageGeometry,
        params: SurfaceParams,
    ) -> Self {
        let fitted: Vec<CellSurface> = (0..geometry.cells())
            .into_par_iter()
            // One scratch buffer per worker: no allocation per cell.
            .map_init(Scratch::default, |scratch, cell| {
                fit_cell(scan, image, geometry, cell, params, scratch)
            })
            .collect();
        Self {
            range_m: fitted.iter().map(|c| c.range_m).collect(),
            direction: fitted.iter().map(|c| c.direction).collect(),
            normal: fitted.iter().map(|c| c.normal).collect(),
            incidence_cos: fitted.iter().map(|c| c.incidence_cos).collect(),
            support: fitted.iter().map(|c| c.support).collect(),
            edge: fitted.iter().map(|c| c.edge).collect(),
        }
    }
}

#[derive(Debug, Clone, Copy)]
struct CellSurface {
    range_m: f32,
    direction: [f32; 3],
    normal: [f32; 3],
    incidence_cos: f32,
    support: u8,
    edge: bool,
}

const EMPTY: CellSurface = CellSurface {
    range_m: f32::NAN,
    direction: [0.0; 3],
    normal: [0.0; 3],
    incidence_cos: 1.0,
    support: 0,
    edge: false,
};

fn point_of(scan: &Scan, image: &RangeImage, cell: usize) -> Option<Vector3<f64>> {
    let index = image.point[cell];
    (index != NO_POINT).then(|| {
        let p = scan.points_m[index as usize];
        Vector3::new(f64::from(p[0]), f64::from(p[1]), f64::from(p[2]))
    })
}

/// Reused point buffers of one worker thread.
#[derive(Default)]
struct Scratch {
    points: Vec<Vector3<f64>>,
    on_plane: Vec<Vector3<f64>>,
}

/// Fit the cell's plane in its window; where the window's points spread over
/// less than a few noise sigmas in the plane (a close object seen by a dense
/// sensor) the normal would be mostly noise, so the window grows (up to 7 beams).
fn fit_cell(
    scan: &Scan,
    image: &RangeImage,
    geometry: &ImageGeometry,
    cell: usize,
    params: SurfaceParams,
    scratch: &mut Scratch,
) -> CellSurface {
    let mut best = EMPTY;
    for grow in 1..=3 {
        let (surface, spread) = fit_window(
            scan,
            image,
            geometry,
            cell,
            params,
            (grow, grow * params.half_cols),
            scratch,
        );
        best = surface;
        if spread.is_none_or(|s| s >= 2.0 * params.range_noise_m) {
            break;
        }
    }
    best
}

/// One fit over a window of `2 half_rows + 1` beams by `2 half_cols + 1`
/// columns (`(half_rows, half_cols)`); also returns the in-plane spread of the points fitted.
fn fit_window(
    scan: &Scan,
    image: &RangeImage,
    geometry: &ImageGeometry,
    cell: usize,
    params: SurfaceParams,
    (half_rows, half_cols): (usize, usize),
    scratch: &mut Scratch,
) -> (CellSurface, Option<f64>) {
    let Some(center) = point_of(scan, image, cell) else {
        return (EMPTY, None);
    };
    let range = center.norm();
    let direction = center / range;
    let as_f32 = |v: &Vector3<f64>| [v.x as f32, v.y as f32, v.z as f32];
    let raw = CellSurface {
        range_m: range as f32,
        direction: as_f32(&direction),
        support: 1,
        ..EMPTY
    };
    // Candidates: neighbours not absurdly far in range (a loose gate; the plane decides).
    let Scratch { points, on_plane } = scratch;
    points.clear();
    points.push(center);
    let mut far_neighbour = false;
    for n in geometry.neighbours(cell, half_rows, half_cols) {
        if let Some(p) = point_of(scan, image, n) {
            if (p.norm() - range).abs() <= 0.3 * range + 0.5 {
                points.push(p);
            } else {
                far_neighbour = true;
            }
        }
    }
    let Some((normal, centroid, spread)) = fit_plane_spread(points) else {
        return (
            CellSurface {
                edge: far_neighbour,
                ..raw
            },
            None,
        );
    };
    // Points off the plane by more than noise belong to another surface.
    let tolerance = 4.0 * params.range_noise_m + 0.003 * range;
    on_plane.clear();
    on_plane.extend(
        points
            .iter()
            .copied()
            .filter(|p| (p - centroid).dot(&normal).abs() <= tolerance),
    );
    let edge = far_neighbour || on_plane.len() < points.len();
    let (normal, centroid, support, spread) = if on_plane.len() == points.len() {
        (normal, centroid, points.len(), spread)
    } else {
        match fit_plane_spread(on_plane) {
            Some((n, c, s)) => (n, c, on_plane.len(), s),
            None => return (CellSurface { edge, ..raw }, None),
        }
    };
    let facing = normal.dot(&direction);
    let normal = if facing > 0.0 { -normal } else { normal };
    let incidence_cos = facing.abs();
    // The cell's ray against the plane: the denoised range. Near grazing the
    // intersection is ill-conditioned, so the raw range stays.
    let denoised = if incidence_cos >= 0.1 {
        centroid.dot(&normal) / direction.dot(&normal)
    } else {
        range
    };
    let range_m = if (denoised - range).abs() <= tolerance && denoised > 0.0 {
        denoised
    } else {
        range
    };
    let surface = CellSurface {
        range_m: range_m as f32,
        direction: as_f32(&direction),
        normal: as_f32(&normal),
        incidence_cos: incidence_cos as f32,
        support: support.min(255) as u8,
        edge,
    };
    (surface, Some(spread))
}

/// Least-squares plane: unit normal and centroid; None for fewer than 4 points
/// or points along a line.
#[cfg(test)]
fn fit_plane(points: &[Vector3<f64>]) -> Option<(Vector3<f64>, Vector3<f64>)> {
    fit_plane_spread(points).map(|(n, c, _)| (n, c))
}

/// [`fit_plane`] plus the RMS spread of the points within the plane (the
/// smaller in-plane axis).
fn fit_plane_spread(points: &[Vector3<f64>]) -> Option<(Vector3<f64>, Vector3<f64>, f64)> {
    if points.len() < 4 {
        return None;
    }
    let centroid = points.iter().sum::<Vector3<f64>>() / points.len() as f64;
    let mut covariance = Matrix3::zeros();
    for p in points {
        let d = p - centroid;
        covariance += d * d.transpose();
    }
    let (smallest, middle, largest) = symmetric_eigenvalues(&covariance)?;
    // Collinear points (one row only) do not define a plane.
    if largest.is_nan() || largest <= 0.0 || middle < 1e-3 * largest || !smallest.is_finite() {
        return None;
    }
    let normal = null_vector(&(covariance - Matrix3::identity() * smallest))?;
    Some((
        normal,
        centroid,
        (middle.max(0.0) / points.len() as f64).sqrt(),
    ))
}

/// Eigenvalues of a symmetric 3x3 matrix, ascending, in closed form (the
/// trigonometric solution of the characteristic cubic): much cheaper than an
/// iterative solver in the per-cell inner loop.
fn symmetric_eigenvalues(a: &Matrix3<f64>) -> Option<(f64, f64, f64)> {
    let p1 = a[(0, 1)].powi(2) + a[(0, 2)].powi(2) + a[(1, 2)].powi(2);
    let q = a.trace() / 3.0;
    let p2 = (a[(0, 0)] - q).powi(2) + (a[(1, 1)] - q).powi(2) + (a[(2, 2)] - q).powi(2) + 2.0 * p1;
    let p = (p2 / 6.0).sqrt();
    if !(p.is_finite()) || p == 0.0 {
        return Some((q, q, q));
    }
    let b = (a - Matrix3::identity() * q) / p;
    let r = (b.determinant() / 2.0).clamp(-1.0, 1.0);
    let phi = r.acos() / 3.0;
    let largest = q + 2.0 * p * phi.cos();
    let smallest = q + 2.0 * p * (phi + 2.0 * std::f64::consts::PI / 3.0).cos();
    let middle = 3.0 * q - largest - smallest;
    Some((smallest, middle, largest))
}

/// A unit vector in the null space of a (nearly) singular symmetric matrix: the
/// largest cross product of two of its rows.
fn null_vector(m: &Matrix3<f64>) -> Option<Vector3<f64>> {
    let rows = [
        Vector3::new(m[(0, 0)], m[(0, 1)], m[(0, 2)]),
        Vector3::new(m[(1, 0)], m[(1, 1)], m[(1, 2)]),
        Vector3::new(m[(2, 0)], m[(2, 1)], m[(2, 2)]),
    ];
    let candidates = [
        rows[0].cross(&rows[1]),
        rows[0].cross(&rows[2]),
        rows[1].cross(&rows[2]),
    ];
    let best = candidates
        .iter()
        .max_by(|a, b| a.norm_squared().total_cmp(&b.norm_squared()))?;
    let norm = best.norm();
    (norm > 0.0 && norm.is_finite()).then(|| best / norm)
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn a_plane_fit_recovers_the_plane() {
        let normal = Vector3::new(0.2, -0.3, 0.9).normalize();
        let u = normal.cross(&Vector3::x()).normalize();
        let v = normal.cross(&u);
        let base = Vector3::new(5.0, 1.0, -1.7);
        let points: Vec<Vector3<f64>> = (0..9)
            .map(|k| base + u * f64::from(k % 3) * 0.2 + v * f64::from(k / 3) * 0.3)
            .collect();
        let (fitted, centroid) = fit_plane(&points).unwrap();
        assert!(fitted.dot(&normal).abs() > 1.0 - 1e-9);
        assert!((centroid - base).dot(&normal).abs() < 1e-9);
    }

    #[test]
    fn points_on_a_line_define_no_plane() {
        let points: Vec<Vector3<f64>> = (0..5)
            .map(|k| Vector3::new(f64::from(k), 2.0 * f64::from(k), 1.0))
            .collect();
        assert!(fit_plane(&points).is_none());
    }

    #[test]
    fn closed_form_eigenvalues_match_a_diagonal_matrix() {
        let m = Matrix3::from_diagonal(&Vector3::new(3.0, 1.0, 2.0));
        let (a, b, c) = symmetric_eigenvalues(&m).unwrap();
        assert!((a - 1.0).abs() < 1e-12 && (b - 2.0).abs() < 1e-12 && (c - 3.0).abs() < 1e-12);
    }
}
