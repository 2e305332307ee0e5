//! Local surfaces of a range image: a plane fitted to each cell's 3x3
//! neighbourhood gives a denoised range (the cell's ray against the plane),
//! the surface normal (so grazing cells are known), and occlusion edges
//! (neighbours far off the plane).
//!
//! Here [`Surfaces`], the per-cell driver and the orientation of a fitted
//! surface; each laser's noise in `noise.rs`, a dense sensor's window fits
//! in `window.rs`, a sparse sensor's ring lines in `ring.rs`, the linear
//! algebra in `plane.rs`.

mod fits;
mod noise;
mod plane;
mod ring;
mod spare;
mod window;

use nalgebra::Vector3;
use rayon::prelude::*;

use super::grid::{ImageGeometry, NO_POINT, RangeImage};
use super::window_extremes::RowExtremes;
use super::window_sums::RowSums;
use crate::model::Scan;

pub(super) use plane::fit_plane_spread;

use noise::{noise_per_row, row_noise, shrunk_to_sensor};
use ring::ground_height;

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
    /// Range noise of each row's laser (1 sigma), metres, estimated from the
    /// scan itself (`row_noise`).
    pub noise_m_per_row: Vec<f32>,
    /// Range offset of each row's laser taken out of its returns, metres
    /// (`bias::estimate`; all zero where the scan shows none).
    pub range_bias_m_per_row: Vec<f32>,
    /// Per cell, the neighbours it shares a surface with in the mesh the
    /// renderer builds, and which of the two triangles of the quad it
    /// starts exist and touch an occlusion edge (`warp::mesh_joins`, whose
    /// bit constants say which bit is which).
    pub joins: Vec<u8>,
    /// Azimuth and elevation of each cell's return (of `direction`), radians
    /// (NaN empty): computed once per scan, as each render of the scan
    /// turns them by its motion (`warp`) instead of taking three `atan2`
    /// per return.
    pub azimuth_rad: Vec<f64>,
    pub elevation_rad: Vec<f64>,
    /// Columns of the image (cells per row).
    pub cols: usize,
}

impl Surfaces {
    /// Range noise (1 sigma) of a cell's laser, metres.
    pub fn noise_m(&self, cell: usize) -> f64 {
        f64::from(self.noise_m_per_row[cell / self.cols])
    }
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
    /// Rows too far apart to share a plane (`ImageGeometry::sparse_rows`):
    /// lines are fitted along each ring instead.
    pub sparse_rows: bool,
    /// Height of the ground below the sensor, metres (LiDAR frame z), for
    /// the orientation of a ring's line on sparse sensors; -inf unknown.
    pub ground_z_m: f64,
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
            sparse_rows: geometry.sparse_rows(),
            ground_z_m: f64::NEG_INFINITY,
        }
    }
}

impl Surfaces {
    /// Surfaces of a gridded scan, with `range_bias_m_per_row` (one per row,
    /// `bias::RangeBias`) taken out of the returns first.
    pub fn estimate(
        scan: &Scan,
        image: &RangeImage,
        geometry: &ImageGeometry,
        params: SurfaceParams,
        range_bias_m_per_row: Vec<f32>,
    ) -> Self {
        // The windows of `fit_cell`'s growths (dense sensors only).
        let window_half_cols: Vec<usize> = if params.sparse_rows {
            Vec::new()
        } else {
            (1..=MAX_GROWTH)
                .map(|grow| grow * params.half_cols)
                .collect()
        };
        let returns = Returns::new(
            scan,
            image,
            geometry.cols,
            &range_bias_m_per_row,
            &window_half_cols,
        );
        let noise_m_per_row = shrunk_to_sensor(if params.sparse_rows {
            row_noise(image, geometry, params.range_noise_m)
        } else {
            noise_per_row(&returns, geometry, params)
        });
        let params = SurfaceParams {
            ground_z_m: if params.sparse_rows {
                ground_height(scan, image)
            } else {
                params.ground_z_m
            },
            ..params
        };
        let mut surfaces = Self::empty(geometry.cells(), geometry.cols);
        surfaces.write_fits(&returns, geometry, params, &noise_m_per_row);
        returns.recycle();
        surfaces.noise_m_per_row = noise_m_per_row;
        surfaces.range_bias_m_per_row = range_bias_m_per_row;
        surfaces.joins = super::warp::mesh_joins(&surfaces, geometry.rows, geometry.cols);
        surfaces
    }

    /// `cells` cells, every per-cell field to be written (`write_fits`).
    /// (In the fields of a dropped one where there is one: see `Drop`.)
    fn empty(cells: usize, cols: usize) -> Self {
        use crate::engine::spare::filled;
        let spare = spare::FIELDS.take();
        Self {
            range_m: filled(spare.range_m, cells, f32::NAN),
            direction: filled(spare.direction, cells, [0.0; 3]),
            normal: filled(spare.normal, cells, [0.0; 3]),
            incidence_cos: filled(spare.incidence_cos, cells, 1.0),
            support: filled(spare.support, cells, 0),
            edge: filled(spare.edge, cells, false),
            noise_m_per_row: Vec::new(),
            range_bias_m_per_row: Vec::new(),
            joins: Vec::new(),
            azimuth_rad: filled(spare.azimuth_rad, cells, f64::NAN),
            elevation_rad: filled(spare.elevation_rad, cells, f64::NAN),
            cols,
        }
    }

    /// The azimuth and elevation of each cell's `direction` (NaN where
    /// empty), in a loop of their own: there the processor overlaps one
    /// cell's angles with the next's, which the fits' loop, waiting on each
    /// angle's chain of multiplications, did not (the angles were a third
    /// of the fits' time with the fast `atan2` inside it).
    fn write_angles(&mut self) {
        let cols = self.cols.max(1);
        let rows = (
            self.azimuth_rad.par_chunks_mut(cols),
            self.elevation_rad.par_chunks_mut(cols),
            self.direction.par_chunks(cols),
            self.range_m.par_chunks(cols),
        );
        rows.into_par_iter()
            .for_each(|(azimuth, elevation, direction, range_m)| {
                for (((azimuth, elevation), direction), range_m) in azimuth
                    .iter_mut()
                    .zip(elevation)
                    .zip(direction)
                    .zip(range_m)
                {
                    // Every cell's angles, an empty one's then replaced by
                    // NaN, not a branch per cell: straight-line, the loop
                    // takes two cells at a time.
                    let (a, e) = super::grid::angles(direction);
                    let finite = range_m.is_finite();
                    *azimuth = if finite { a } else { f64::NAN };
                    *elevation = if finite { e } else { f64::NAN };
                }
            });
    }
}

/// A hand-made surface for the tests of what reads one (the renders, the
/// mesh): each cell's `range_m`, `direction` and `normal`, each row's
/// noise; every other field neutral (incidence 1, one return fitted, no
/// edge, no range offset, no joins, zero angles), for the test to set.
#[cfg(test)]
impl Surfaces {
    pub(crate) fn hand_made(
        range_m: Vec<f32>,
        direction: Vec<[f32; 3]>,
        normal: Vec<[f32; 3]>,
        noise_m_per_row: Vec<f32>,
        cols: usize,
    ) -> Self {
        let (cells, rows) = (range_m.len(), noise_m_per_row.len());
        Self {
            range_m,
            direction,
            normal,
            incidence_cos: vec![1.0; cells],
            support: vec![1; cells],
            edge: vec![false; cells],
            noise_m_per_row,
            range_bias_m_per_row: vec![0.0; rows],
            joins: vec![0; cells],
            azimuth_rad: vec![0.0; cells],
            elevation_rad: vec![0.0; cells],
            cols,
        }
    }
}

/// A scan's surfaces are dropped when the next pair's replace them: their
/// per-cell fields go to the next scan's (`Surfaces::empty`), whose fresh
/// pages cost more to fault in than to fill.
impl Drop for Surfaces {
    fn drop(&mut self) {
        use std::mem::take;
        if self.range_m.capacity() == 0 {
            return;
        }
        spare::FIELDS.give(spare::Fields {
            range_m: take(&mut self.range_m),
            direction: take(&mut self.direction),
            normal: take(&mut self.normal),
            incidence_cos: take(&mut self.incidence_cos),
            support: take(&mut self.support),
            edge: take(&mut self.edge),
            azimuth_rad: take(&mut self.azimuth_rad),
            elevation_rad: take(&mut self.elevation_rad),
        });
    }
}

#[derive(Debug, Clone, Copy)]
struct CellSurface {
    /// The return's own distance to the fitted plane, metres.
    residual_m: f32,
    /// A point of the fitted plane (its returns' centroid), metres; NaN
    /// where no plane was fitted.
    plane_point: [f64; 3],
    range_m: f32,
    direction: [f32; 3],
    normal: [f32; 3],
    incidence_cos: f32,
    support: u8,
    edge: bool,
}

const EMPTY: CellSurface = CellSurface {
    residual_m: f32::NAN,
    plane_point: [f64::NAN; 3],
    range_m: f32::NAN,
    direction: [0.0; 3],
    normal: [0.0; 3],
    incidence_cos: 1.0,
    support: 0,
    edge: false,
};

/// The returns of one image, by cell, with each laser's range offset taken
/// out: positions and ranges computed once per scan, as every cell's window
/// reads its neighbours' many times over.
struct Returns<'a> {
    image: &'a RangeImage,
    /// Per cell, metres (NaN: empty).
    points: Vec<Vector3<f64>>,
    /// `|points[cell]|`, metres (NaN: empty).
    ranges: Vec<f64>,
    /// Running sums of `points` along each row, for the windows' scatter.
    sums: RowSums,
    /// Extremes of `ranges` along each row, for the windows' range gate.
    extremes: RowExtremes,
}

impl<'a> Returns<'a> {
    /// The returns, with the range extremes of windows `window_half_cols`
    /// wide on each side.
    fn new(
        scan: &Scan,
        image: &'a RangeImage,
        cols: usize,
        range_bias_m: &[f32],
        window_half_cols: &[usize],
    ) -> Self {
        let mut spare = spare::RETURNS.take();
        // Each return's range beside it, in the same parallel pass (a
        // pass of its own after this one ran on one core).
        image
            .point
            .par_iter()
            .enumerate()
            .map(|(cell, &index)| {
                if index == NO_POINT {
                    return (Vector3::repeat(f64::NAN), f64::NAN);
                }
                let p = scan.points_m[index as usize];
                let p = Vector3::new(f64::from(p[0]), f64::from(p[1]), f64::from(p[2]));
                let p = match range_bias_m.get(cell / cols) {
                    Some(&bias) if bias != 0.0 => {
                        let range = p.norm();
                        p * ((range - f64::from(bias)).max(0.0) / range)
                    }
                    _ => p,
                };
                (p, p.norm())
            })
            .unzip_into_vecs(&mut spare.points, &mut spare.ranges);
        Self::with_ranges_in(image, cols, window_half_cols, spare)
    }

    /// The returns `points` (one per cell of `image`; NaN empty).
    #[cfg(test)]
    fn of_points(
        image: &'a RangeImage,
        points: Vec<Vector3<f64>>,
        cols: usize,
        window_half_cols: &[usize],
    ) -> Self {
        let spare = spare::Spare {
            points,
            ..Default::default()
        };
        Self::of_points_in(image, cols, window_half_cols, spare)
    }

    /// The returns `spare.points`, the rest in `spare`'s buffers.
    #[cfg(test)]
    fn of_points_in(
        image: &'a RangeImage,
        cols: usize,
        window_half_cols: &[usize],
        mut spare: spare::Spare,
    ) -> Self {
        spare.ranges.clear();
        spare.ranges.extend(spare.points.iter().map(|p| p.norm()));
        Self::with_ranges_in(image, cols, window_half_cols, spare)
    }

    /// The returns `spare.points` and their ranges `spare.ranges`, the
    /// rest in `spare`'s buffers.
    fn with_ranges_in(
        image: &'a RangeImage,
        cols: usize,
        window_half_cols: &[usize],
        spare: spare::Spare,
    ) -> Self {
        let (points, ranges) = (spare.points, spare.ranges);
        let sums = RowSums::new_in(&points, cols, spare.sums);
        let extremes = RowExtremes::new_in(&ranges, cols, window_half_cols, spare.extremes);
        Self {
            image,
            points,
            ranges,
            sums,
            extremes,
        }
    }

    /// Give the buffers back for a later scan's.
    fn recycle(self) {
        spare::RETURNS.give(spare::Spare {
            points: self.points,
            ranges: self.ranges,
            sums: self.sums.into_buffer(),
            extremes: self.extremes.into_buffer(),
        });
    }

    #[inline]
    fn point(&self, cell: usize) -> Option<Vector3<f64>> {
        let p = self.points[cell];
        (!p.x.is_nan()).then_some(p)
    }
}

/// Reused point buffers of one worker thread.
#[derive(Default)]
struct Scratch {
    points: Vec<Vector3<f64>>,
    on_plane: Vec<Vector3<f64>>,
    /// Per entry of `points`: the return is one of the cell's 8 neighbours.
    immediate: Vec<bool>,
}

/// Growths of a cell's window at most: `2 grow + 1` beams.
pub(super) const MAX_GROWTH: usize = 3;

/// The loose range gate of a window about a return `range_m` away, metres:
/// neighbours farther from it in range are not candidates for its plane.
#[inline]
fn range_gate_m(range_m: f64) -> f64 {
    0.3 * range_m + 0.5
}

/// How far off a fitted plane a return `range_m` away may lie and still be
/// on it, metres: four noise sigmas and the plane's own error with range.
#[inline]
fn plane_tolerance_m(params: SurfaceParams, range_m: f64) -> f64 {
    4.0 * params.range_noise_m + 0.003 * range_m
}

/// A return with no surface fitted: its raw range and direction.
#[inline]
fn raw_surface(center: &Vector3<f64>) -> CellSurface {
    let range = center.norm();
    CellSurface {
        range_m: range as f32,
        direction: as_f32(&(center / range)),
        support: 1,
        ..EMPTY
    }
}

#[inline]
fn as_f32(v: &Vector3<f64>) -> [f32; 3] {
    [v.x as f32, v.y as f32, v.z as f32]
}

/// `normal` turned to face the sensor along `direction`.
#[inline]
fn facing_sensor(normal: Vector3<f64>, direction: &Vector3<f64>) -> Vector3<f64> {
    if normal.dot(direction) > 0.0 {
        -normal
    } else {
        normal
    }
}

/// A return on the surface through `centroid` with `normal`: the normal
/// facing the sensor, the incidence, and the denoised range (the ray
/// against the surface, where within `tolerance` of the raw range; near
/// grazing the intersection is ill-conditioned, so the raw range stays).
#[inline]
fn oriented(
    center: &Vector3<f64>,
    centroid: &Vector3<f64>,
    normal: Vector3<f64>,
    tolerance: f64,
) -> CellSurface {
    let range = center.norm();
    let direction = center / range;
    let normal = facing_sensor(normal, &direction);
    let incidence_cos = normal.dot(&direction).abs();
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
        plane_point: [centroid.x, centroid.y, centroid.z],
        ..raw_surface(center)
    }
}

#[cfg(test)]
mod tests;
