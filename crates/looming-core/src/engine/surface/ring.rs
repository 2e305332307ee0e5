//! The surfaces of a sparse sensor (rows too far apart to share a plane): a
//! line fitted along each cell's ring, oriented by the ground's height.

use nalgebra::Vector3;

use super::noise::median_f32;
use super::plane::fit_line;
use super::{
    CellSurface, EMPTY, Returns, Scratch, SurfaceParams, oriented, plane_tolerance_m, raw_surface,
};
use crate::engine::grid::{ImageGeometry, NO_POINT, RangeImage};
use crate::model::Scan;

/// The ground's height below a sparse sensor: the median height of the
/// returns of rays pointing more than 10 degrees down (on an 8-beam sensor
/// its lowest rings), -inf without any.
pub(super) fn ground_height(scan: &Scan, image: &RangeImage) -> f64 {
    let mut heights: Vec<f32> = image
        .point
        .iter()
        .filter(|&&i| i != NO_POINT)
        .map(|&i| scan.points_m[i as usize])
        .filter(|p| p[2] < -(p[0] * p[0] + p[1] * p[1]).sqrt() * DOWN_TAN)
        .map(|p| p[2])
        .collect();
    if heights.len() < 20 {
        return f64::NEG_INFINITY;
    }
    f64::from(median_f32(&mut heights))
}

/// tan(10 degrees).
const DOWN_TAN: f32 = 0.176;

/// A cell of a sparse sensor: a line fitted along its ring (the returns of
/// the same laser in `2 * RING_HALF_WINDOW + 1` columns). One direction
/// does not give a plane, so the surface's orientation comes from the world
/// such sensors see: a level line at the ground's height is ground (normal
/// up), anything else a vertical surface through the line (a wall, a car's
/// side, a post).
#[inline]
pub(super) fn fit_ring_cell(
    returns: &Returns,
    geometry: &ImageGeometry,
    cell: usize,
    params: SurfaceParams,
    scratch: &mut Scratch,
) -> CellSurface {
    let Some(center) = returns.point(cell) else {
        return EMPTY;
    };
    let raw = raw_surface(&center);
    let (range, direction) = (center.norm(), center / center.norm());
    let Scratch {
        points, immediate, ..
    } = scratch;
    points.clear();
    immediate.clear();
    points.push(center);
    immediate.push(false);
    let (row, col) = (cell / geometry.cols, cell % geometry.cols);
    let mut far_neighbours = 0;
    for offset in 1..=RING_HALF_WINDOW {
        for c in [col + offset, col + geometry.cols - offset] {
            let n = row * geometry.cols + c % geometry.cols;
            let Some(p) = returns.point(n) else { continue };
            if (p.norm() - range).abs() <= 0.1 * range + 0.3 {
                points.push(p);
                immediate.push(offset == 1);
            } else if offset == 1 {
                far_neighbours += 1;
            }
        }
    }
    let Some((tangent, centroid)) = fit_line(points) else {
        return CellSurface {
            edge: far_neighbours > 0,
            ..raw
        };
    };
    let tolerance = plane_tolerance_m(params, range);
    let off_line = |p: &Vector3<f64>| {
        let d = p - centroid;
        (d - tangent * d.dot(&tangent)).norm() > tolerance
    };
    let immediate_off = points
        .iter()
        .zip(immediate.iter())
        .filter(|(p, near)| **near && off_line(p))
        .count();
    let edge = off_line(&center) || far_neighbours + immediate_off > 0;
    let support = points.iter().filter(|p| !off_line(p)).count();
    let up = Vector3::z();
    let level = tangent.z.abs() < LEVEL_TANGENT_Z;
    let on_ground = (center.z - params.ground_z_m).abs() < 0.25 + 0.02 * range;
    let normal = if level && on_ground {
        (up - tangent * tangent.dot(&up)).normalize()
    } else {
        let across = tangent.cross(&up);
        if across.norm() > 0.1 {
            across.normalize()
        } else {
            // A vertical line: the surface faces the sensor horizontally.
            Vector3::new(direction.x, direction.y, 0.0).normalize()
        }
    };
    let d = center - centroid;
    CellSurface {
        residual_m: (d - tangent * d.dot(&tangent)).norm() as f32,
        support: support.min(255) as u8,
        edge,
        ..oriented(&center, &centroid, normal, tolerance)
    }
}

/// Columns on each side of a sparse sensor's cell in its ring's line fit.
const RING_HALF_WINDOW: usize = 3;
/// A ring's line is level when its direction rises less than this (sine).
const LEVEL_TANGENT_Z: f64 = 0.3;
