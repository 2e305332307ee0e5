//! Local surfaces of a range image: a plane fitted to each cell's 3x3
//! neighbourhood gives a denoised range (the cell's ray against the plane),
//! the surface normal (so grazing cells are known), and occlusion edges
//! (neighbours far off the plane).

use nalgebra::{Matrix3, SymmetricEigen, Vector3};
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
            .map(|cell| fit_cell(scan, image, geometry, cell, params))
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

/// The 8 neighbours of a cell (columns wrap around, rows do not).
fn neighbours(geometry: &ImageGeometry, cell: usize) -> impl Iterator<Item = usize> + '_ {
    let (row, col) = (cell / geometry.cols, cell % geometry.cols);
    (-1i64..=1).flat_map(move |dr| {
        (-1i64..=1).filter_map(move |dc| {
            if dr == 0 && dc == 0 {
                return None;
            }
            let r = row as i64 + dr;
            if r < 0 || r >= geometry.rows as i64 {
                return None;
            }
            let c = (col as i64 + dc).rem_euclid(geometry.cols as i64) as usize;
            Some(r as usize * geometry.cols + c)
        })
    })
}

fn fit_cell(
    scan: &Scan,
    image: &RangeImage,
    geometry: &ImageGeometry,
    cell: usize,
    params: SurfaceParams,
) -> CellSurface {
    let Some(center) = point_of(scan, image, cell) else {
        return EMPTY;
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
    let mut points: Vec<Vector3<f64>> = Vec::with_capacity(9);
    points.push(center);
    let mut far_neighbour = false;
    for n in neighbours(geometry, cell) {
        if let Some(p) = point_of(scan, image, n) {
            if (p.norm() - range).abs() <= 0.3 * range + 0.5 {
                points.push(p);
            } else {
                far_neighbour = true;
            }
        }
    }
    let Some((normal, centroid)) = fit_plane(&points) else {
        return CellSurface {
            edge: far_neighbour,
            ..raw
        };
    };
    // Points off the plane by more than noise belong to another surface.
    let tolerance = 4.0 * params.range_noise_m + 0.003 * range;
    let on_plane: Vec<Vector3<f64>> = points
        .iter()
        .copied()
        .filter(|p| (p - centroid).dot(&normal).abs() <= tolerance)
        .collect();
    let edge = far_neighbour || on_plane.len() < points.len();
    let (normal, centroid, support) = if on_plane.len() == points.len() {
        (normal, centroid, points.len())
    } else {
        match fit_plane(&on_plane) {
            Some((n, c)) => (n, c, on_plane.len()),
            None => return CellSurface { edge, ..raw },
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
    CellSurface {
        range_m: range_m as f32,
        direction: as_f32(&direction),
        normal: as_f32(&normal),
        incidence_cos: incidence_cos as f32,
        support: support.min(255) as u8,
        edge,
    }
}

/// Least-squares plane: unit normal and centroid; None for fewer than 4 points
/// or points along a line.
fn fit_plane(points: &[Vector3<f64>]) -> Option<(Vector3<f64>, Vector3<f64>)> {
    if points.len() < 4 {
        return None;
    }
    let centroid = points.iter().sum::<Vector3<f64>>() / points.len() as f64;
    let mut covariance = Matrix3::zeros();
    for p in points {
        let d = p - centroid;
        covariance += d * d.transpose();
    }
    let eigen = SymmetricEigen::new(covariance);
    let mut order = [0usize, 1, 2];
    order.sort_by(|a, b| eigen.eigenvalues[*a].total_cmp(&eigen.eigenvalues[*b]));
    let (smallest, middle, largest) = (
        eigen.eigenvalues[order[0]],
        eigen.eigenvalues[order[1]],
        eigen.eigenvalues[order[2]],
    );
    // Collinear points (one row only) do not define a plane.
    if largest.is_nan() || largest <= 0.0 || middle < 1e-3 * largest || !smallest.is_finite() {
        return None;
    }
    let normal = eigen.eigenvectors.column(order[0]).into_owned();
    let norm = normal.norm();
    (norm > 0.0).then(|| (normal / norm, centroid))
}
