//! The per-cell math: from the current surfaces and the two renders of the
//! previous one, each cell's `L_lidar`, `L_ray_ego`, noise and mask
//! ([`raw_cell`]), the moving patches, the fused looming ([`fuse`], the 3x3
//! median of the static world) and the threat levels.

use rayon::prelude::*;

use crate::model::{PairMotion, StampNs};

use super::config::EngineConfig;
use super::egomotion::EgoEstimate;
use super::grid::{ImageGeometry, wrapped_around};
use super::result::mask;
use super::surface::Surfaces;
use super::threat::ThreatLevel;
use super::warp;

mod instant;
mod median;
use instant::{InstantVelocities, to_instant};
use median::{MedianBatch, median_3x3};

/// The per-cell fields of [`super::PairLooming`] that [`per_cell`] computes.
pub(super) struct CellValues {
    pub(super) l_lidar: Vec<f32>,
    pub(super) l_ray_ego: Vec<f32>,
    pub(super) disagreement: Vec<f32>,
    pub(super) sigma: Vec<f32>,
    pub(super) confidence: Vec<f32>,
    pub(super) mask: Vec<u8>,
    pub(super) disagrees: Vec<bool>,
    pub(super) moving: Vec<bool>,
    pub(super) fused: Vec<f32>,
    pub(super) fused_sigma: Vec<f32>,
    pub(super) ray_ego_sigma: Vec<f32>,
    pub(super) threat: Vec<ThreatLevel>,
    pub(super) dt_s: Vec<f32>,
}

/// First pass per cell: the differences, the noise and the mask.
#[derive(Clone, Copy)]
struct Raw {
    l_lidar: f32,
    l_ray_ego: f32,
    sigma: f32,
    /// Noise of `l_ray_ego`: the ego prediction's model error and, where the
    /// motion was estimated from the scans, that estimate's uncertainty.
    sigma_ego: f32,
    mask: u8,
    dt_s: f32,
}

impl Raw {
    /// A cell without a current return.
    const EMPTY: Self = Self {
        l_lidar: f32::NAN,
        l_ray_ego: f32::NAN,
        sigma: f32::NAN,
        sigma_ego: f32::NAN,
        mask: mask::EMPTY,
        dt_s: f32::NAN,
    };
}

/// Every cell's values from the current surfaces and times and the renders
/// of the previous surface moved by the rotation and, with a velocity, by the
/// full ego motion.
pub(super) fn per_cell(
    config: &EngineConfig,
    geometry: &ImageGeometry,
    current: &Surfaces,
    current_time: &[StampNs],
    rotated: &warp::Rendered,
    moved: Option<&warp::Rendered>,
    (motion, estimate): (&PairMotion, Option<&EgoEstimate>),
) -> CellValues {
    let raw = raw_cells(
        config,
        geometry,
        current,
        current_time,
        rotated,
        moved,
        (motion, estimate),
    );
    let candidate: Vec<bool> = raw
        .par_iter()
        .map(|r| {
            let d = r.l_lidar - r.l_ray_ego;
            let (sigma, sigma_ego) = (f64::from(r.sigma), f64::from(r.sigma_ego));
            let sigma_d = (sigma * sigma + sigma_ego * sigma_ego).sqrt();
            r.mask == 0
                && d.is_finite()
                && f64::from(d.abs())
                    > (config.moving_sigmas * sigma_d).max(config.moving_min_per_s)
        })
        .collect();
    let moving = moving_patches(geometry, &candidate);
    let (pointwise, fused_sigma): (Vec<f32>, Vec<f32>) = (0..geometry.cells())
        .into_par_iter()
        .map(|cell| fuse(geometry, &raw, &moving, candidate[cell], cell))
        .unzip();
    let fused = smoothed_static(geometry, current, &raw, (&moving, &candidate), &pointwise);
    let threat = threat_levels(config, &fused, &raw);
    let fields = RawFields::of(&raw);
    CellValues {
        disagreement: fields.disagreement,
        l_lidar: fields.l_lidar,
        l_ray_ego: fields.l_ray_ego,
        confidence: fields.confidence,
        sigma: fields.sigma,
        ray_ego_sigma: fields.ray_ego_sigma,
        mask: fields.mask,
        dt_s: fields.dt_s,
        disagrees: candidate,
        moving,
        fused,
        fused_sigma,
        threat,
    }
}

/// The first pass's values as the result's per-cell fields.
struct RawFields {
    disagreement: Vec<f32>,
    l_lidar: Vec<f32>,
    l_ray_ego: Vec<f32>,
    confidence: Vec<f32>,
    sigma: Vec<f32>,
    ray_ego_sigma: Vec<f32>,
    mask: Vec<u8>,
    dt_s: Vec<f32>,
}

impl RawFields {
    /// In one pass over `raw` on both cores (eight were a tenth of the
    /// per-cell stage).
    fn of(raw: &[Raw]) -> Self {
        let n = raw.len();
        let mut f = Self {
            disagreement: vec![0.0; n],
            l_lidar: vec![0.0; n],
            l_ray_ego: vec![0.0; n],
            confidence: vec![0.0; n],
            sigma: vec![0.0; n],
            ray_ego_sigma: vec![0.0; n],
            mask: vec![0; n],
            dt_s: vec![0.0; n],
        };
        (
            &mut f.disagreement[..],
            &mut f.l_lidar[..],
            &mut f.l_ray_ego[..],
            &mut f.confidence[..],
            &mut f.sigma[..],
            &mut f.ray_ego_sigma[..],
            &mut f.mask[..],
            &mut f.dt_s[..],
            raw,
        )
            .into_par_iter()
            .for_each(|(d, l, e, c, s, se, m, dt, r)| {
                *d = r.l_lidar - r.l_ray_ego;
                *l = r.l_lidar;
                *e = r.l_ray_ego;
                *c = 1.0 / (1.0 + (r.sigma / 0.05).powi(2));
                *s = r.sigma;
                *se = r.sigma_ego;
                *m = r.mask;
                *dt = r.dt_s;
            });
        f
    }
}

/// The first pass: every cell's differences, noise and mask
/// ([`raw_cell`]), taken to the current return's instant ([`to_instant`])
/// where the ego motion is known. Row by row: the row's range noise and its
/// sigmas per support ([`RowNoise`]) come once per row, not from a division
/// and two square roots per cell.
fn raw_cells(
    config: &EngineConfig,
    geometry: &ImageGeometry,
    current: &Surfaces,
    current_time: &[StampNs],
    rotated: &warp::Rendered,
    moved: Option<&warp::Rendered>,
    (motion, estimate): (&PairMotion, Option<&EgoEstimate>),
) -> Vec<Raw> {
    let cols = geometry.cols;
    let mut raw = vec![Raw::EMPTY; geometry.cells()];
    raw.par_chunks_mut(cols).enumerate().for_each_init(
        || InstantVelocities::new(cols),
        |velocities, (row, raw_row)| {
            let mut noise = RowNoise::new(current.noise_m_per_row[row]);
            for (col, raw) in raw_row.iter_mut().enumerate() {
                let cell = row * cols + col;
                let value = raw_cell(
                    config,
                    (current, current_time),
                    rotated,
                    (moved, estimate),
                    (cell, &mut noise),
                );
                *raw = match moved {
                    Some(moved) => to_instant(
                        value,
                        motion,
                        (moved.source_time_ns[cell], current_time[cell]),
                        (col, velocities),
                    ),
                    None => value,
                };
            }
        },
    );
    raw
}

/// One row's range noise and, per plane-fit support, the noise of the
/// difference of a cell's two ranges ([`range_difference_sigma_m`]), worked
/// out at the first cell of the row with that support: a row holds
/// thousands of cells but a few supports.
struct RowNoise {
    noise_m: f64,
    /// By support; NaN: not worked out yet.
    difference_sigma_m: [f64; 256],
}

impl RowNoise {
    fn new(noise_m: f32) -> Self {
        Self {
            noise_m: f64::from(noise_m),
            difference_sigma_m: [f64::NAN; 256],
        }
    }

    fn difference_sigma_m(&mut self, support: u8) -> f64 {
        let known = &mut self.difference_sigma_m[usize::from(support)];
        // (A NaN noise is worked out anew each time: the same NaN.)
        if known.is_nan() {
            *known = range_difference_sigma_m(self.noise_m, support);
        }
        *known
    }
}

/// The noise of the difference of a cell's current range and the rendered
/// previous one, metres, from the row's range noise `noise_m` and the
/// returns the current plane fit had (`support`). Both ranges are plane
/// fits of several returns; the rendered one mixes three vertices: about
/// sigma / sqrt(2) each, conservatively.
fn range_difference_sigma_m(noise_m: f64, support: u8) -> f64 {
    let support = f64::from(support.max(1));
    let sigma_now = noise_m * (1.0 / support).sqrt().max(0.4);
    let sigma_before = noise_m * 0.6;
    (sigma_now.powi(2) + sigma_before.powi(2)).sqrt()
}

/// A moving object is a patch spanning beams, not a lone noisy cell nor a
/// one-beam line (what the junction of road and wall leaves): keep
/// candidates with two candidate neighbours, one of them on another beam.
fn moving_patches(geometry: &ImageGeometry, candidate: &[bool]) -> Vec<bool> {
    let cols = geometry.cols;
    let mut moving = vec![false; geometry.cells()];
    // Row by row, as in `smoothed_static`: the rows above and below and the
    // wrapped columns once per row and cell, not by divisions per neighbour.
    moving
        .par_chunks_mut(cols)
        .enumerate()
        .for_each(|(row, moving_row)| {
            let window = NeighbourRows::of(geometry, row);
            let rows = &window.starts[..window.count];
            for (col, moving) in moving_row.iter_mut().enumerate() {
                if !candidate[row * cols + col] {
                    continue;
                }
                let around = wrapped_around(col, cols);
                *moving = rows.iter().any(|&(offset, start)| {
                    offset != 0 && around.iter().any(|&c| candidate[start + c])
                });
            }
        });
    moving
}

/// On the static world neighbouring cells see one smooth looming field: a
/// 3x3 median over trusted static neighbours removes what noise is left
/// without blurring across edges (masked and moving cells take no part).
/// Other cells keep their pointwise value.
fn smoothed_static(
    geometry: &ImageGeometry,
    current: &Surfaces,
    raw: &[Raw],
    (moving, candidate): (&[bool], &[bool]),
    pointwise: &[f32],
) -> Vec<f32> {
    // Once per cell, as each is read by up to nine windows.
    let trusted_static: Vec<bool> = (0..geometry.cells())
        .into_par_iter()
        .map(|n| raw[n].mask == 0 && !moving[n] && !candidate[n] && pointwise[n].is_finite())
        .collect();
    let mut smoothed = vec![0.0f32; geometry.cells()];
    // Row by row with the neighbours' rows and columns worked out once per
    // row and column, not by a division per neighbour: this reads nine
    // cells for every cell of the image.
    smoothed
        .par_chunks_mut(geometry.cols)
        .enumerate()
        .for_each(|(row, smoothed_row)| {
            let window = NeighbourRows::of(geometry, row);
            let start = row * geometry.cols;
            smoothed_row.copy_from_slice(&pointwise[start..start + geometry.cols]);
            // The trusted cells' windows' medians a batch at a time.
            let mut medians = MedianBatch::new();
            let mut done = |col: usize, median: f32| smoothed_row[col] = median;
            for col in 0..geometry.cols {
                let cell = start + col;
                if trusted_static[cell] {
                    let mut values = [0.0f32; 9];
                    let count = static_window(
                        &window,
                        (cell, col),
                        current,
                        &trusted_static,
                        pointwise,
                        &mut values,
                    );
                    medians.push(col, &values[..count], &mut done);
                }
            }
            medians.flush(&mut done);
        });
    smoothed
}

/// The rows of a cell's 3x3 window (those inside the image), as the first
/// cell of each with its row offset, for [`smoothed_static`].
struct NeighbourRows {
    /// (row offset -1, 0 or 1, first cell of the row).
    starts: [(i8, usize); 3],
    count: usize,
    cols: usize,
}

impl NeighbourRows {
    fn of(geometry: &ImageGeometry, row: usize) -> Self {
        let mut starts = [(0, 0); 3];
        let mut count = 0;
        for (offset, r) in [(-1, row.wrapping_sub(1)), (0, row), (1, row + 1)] {
            if r < geometry.rows {
                starts[count] = (offset, r * geometry.cols);
                count += 1;
            }
        }
        Self {
            starts,
            count,
            cols: geometry.cols,
        }
    }
}

/// The values whose median smooths a trusted static cell (into `values`;
/// how many): its own and those of its trusted static 3x3 neighbours on the
/// same surface (parallel planes: the base of an object is not smoothed
/// into the road it stands on). Columns wrap around the sweep, as in
/// `ImageGeometry::neighbours_3x3`.
fn static_window(
    window: &NeighbourRows,
    (cell, col): (usize, usize),
    current: &Surfaces,
    trusted_static: &[bool],
    pointwise: &[f32],
    values: &mut [f32; 9],
) -> usize {
    let cols = window.cols;
    let normal = current.normal[cell];
    let around = wrapped_around(col, cols);
    values[0] = pointwise[cell];
    let mut count = 1;
    for &(row_offset, start) in &window.starts[..window.count] {
        for (col_offset, &c) in around.iter().enumerate() {
            if row_offset == 0 && col_offset == 1 {
                continue;
            }
            let n = start + c;
            let m = current.normal[n];
            let same_surface = normal[0] * m[0] + normal[1] * m[1] + normal[2] * m[2] > 0.95;
            // Written always, kept by the count: no branch on the values
            // (their verdicts, at every edge of a surface, were guessed
            // wrong often). At most eight values precede the ninth.
            values[count.min(8)] = pointwise[n];
            count += usize::from(same_surface & trusted_static[n]);
        }
    }
    count
}

/// The threat level of every trusted cell's fused looming (none elsewhere).
fn threat_levels(config: &EngineConfig, fused: &[f32], raw: &[Raw]) -> Vec<ThreatLevel> {
    let thresholds = config.threat_ttc_s;
    fused
        .par_iter()
        .zip(raw)
        .map(|(f, r)| {
            if r.mask == 0 {
                ThreatLevel::of(f64::from(*f), &thresholds)
            } else {
                ThreatLevel::None
            }
        })
        .collect()
}

fn raw_cell(
    config: &EngineConfig,
    (current, current_time): (&Surfaces, &[StampNs]),
    rotated: &warp::Rendered,
    (moved, estimate): (Option<&warp::Rendered>, Option<&EgoEstimate>),
    (cell, noise): (usize, &mut RowNoise),
) -> Raw {
    let nan = Raw::EMPTY;
    let range_now = f64::from(current.range_m[cell]);
    if !range_now.is_finite() {
        return nan;
    }
    let mut flags = 0;
    if current.edge[cell] {
        flags |= mask::EDGE;
    }
    if f64::from(current.incidence_cos[cell]) < config.grazing_cos {
        flags |= mask::GRAZING;
    }
    // The previous surface along this ray must be the surface seen now: a
    // covering triangle tilted away from the current plane straddles a crease
    // (road meeting a wall) or an occlusion, where the difference means nothing.
    let current_normal = current.normal[cell];
    // Whether the current normal is known, once for both renders; every
    // test evaluated (`&`, `|`), without a branch on its verdict.
    let current_known = known(&current_normal);
    let creased = |normal: &[f32; 3]| current_known & apart_if_known(normal, &current_normal);
    // (Excusing the moved render's crease where it meets the return within
    // the noise kept 1 % more of a real HDL-64E scan and cost 12 % of the
    // fused accuracy on the synthetic cut-in at 64 x 2048.)
    let creased_here =
        creased(&rotated.normal[cell]) | moved.is_some_and(|m| creased(&m.normal[cell]));
    if creased_here | rotated.edge[cell] | moved.is_some_and(|m| m.edge[cell]) {
        flags |= mask::EDGE;
    }
    let range_before = f64::from(rotated.range_m[cell]);
    let dt_s = (current_time[cell] - rotated.source_time_ns[cell]) as f64 * 1e-9;
    if !range_before.is_finite() || dt_s <= 0.0 {
        return Raw {
            mask: flags | mask::NO_PREVIOUS,
            ..nan
        };
    }
    // Near grazing a small normal motion moves the range a lot; but a fitted
    // normal can be wrong (two surfaces in one window), so obliqueness excuses
    // at most 1.4 times the plausible displacement.
    let incidence = f64::from(current.incidence_cos[cell]).max(0.7);
    if (range_now - range_before).abs() * incidence > config.max_closing_speed_mps * dt_s {
        flags |= mask::OCCLUSION;
    }
    let l_lidar = -(range_now - range_before) / (dt_s * range_now);
    let l_ray_ego = match moved {
        Some(moved) => {
            let predicted = f64::from(moved.range_m[cell]);
            // The static prediction must be the surface seen now, moved by at
            // most what an object's own motion allows: else it is the ghost of
            // an object that has moved away (or an occlusion), not a difference.
            if predicted.is_finite()
                && (predicted - range_now).abs() * incidence > config.max_closing_speed_mps * dt_s
            {
                flags |= mask::OCCLUSION;
            }
            if predicted.is_finite() {
                // The measured range as reference: on a plane the predicted
                // displacement is the same at any range, so this is the static
                // world's looming at the current geometry and D is exactly the
                // looming of the object's own motion (METHOD.md's R-hat in the
                // denominator differs by R / R-hat on moving objects).
                -(predicted - range_before) / (dt_s * range_now)
            } else {
                flags |= mask::NO_EGO;
                f64::NAN
            }
        }
        None => f64::NAN,
    };
    let sigma = noise.difference_sigma_m(current.support[cell]) / (dt_s * range_now);
    let sigma_ego = ray_ego_sigma(current, cell, l_ray_ego, estimate);
    Raw {
        l_lidar: l_lidar as f32,
        l_ray_ego: l_ray_ego as f32,
        sigma: sigma as f32,
        sigma_ego: sigma_ego as f32,
        mask: flags,
        dt_s: dt_s as f32,
    }
}

/// The noise of a cell's ego prediction `l_ray_ego_per_s`: a measured
/// velocity's error (about 1 %) and the interpolation of the previous surface,
/// and where the motion was estimated from the scans, that estimate's
/// uncertainty carried to the cell's ray ([`EgoEstimate::ray_looming_sigma_per_s`]).
/// On a log without a velocity source the estimate can be pulled by movers
/// (a car passing beside a stopped ego made it read half a metre per second
/// backwards on KITTI): then the measurement must outweigh it.
fn ray_ego_sigma(
    current: &Surfaces,
    cell: usize,
    l_ray_ego_per_s: f64,
    estimate: Option<&EgoEstimate>,
) -> f64 {
    let model = 0.01 * l_ray_ego_per_s.abs() + 0.005;
    let Some(estimate) = estimate else {
        return model;
    };
    let range_m = f64::from(current.range_m[cell]);
    let [dx, dy, dz] = current.direction[cell].map(f64::from);
    let [nx, ny, nz] = current.normal[cell].map(f64::from);
    let facing_cos = f64::from(current.incidence_cos[cell]).max(0.15);
    let estimated = estimate.ray_looming_sigma_per_s(
        nalgebra::Vector3::new(dx, dy, dz) * range_m,
        nalgebra::Vector3::new(nx, ny, nz),
        facing_cos,
    );
    // Both terms are small positive rates: the plain root of the squares
    // (libm's `hypot` guards against overflow at a cost of 1.7 ms per pair
    // on the braking log, for values that never near it).
    (model * model + estimated * estimated).sqrt()
}

/// Two known normals more than the crease angle apart, where `b` is
/// known to be known (both tests evaluated).
#[inline]
fn apart_if_known(a: &[f32; 3], b: &[f32; 3]) -> bool {
    known(a) & ((a[0] * b[0] + a[1] * b[1] + a[2] * b[2]).abs() < CREASE_COS)
}

/// A normal that is one (a missing normal is zero).
#[inline]
fn known(n: &[f32; 3]) -> bool {
    n[0] * n[0] + n[1] * n[1] + n[2] * n[2] > 0.5
}

/// Cosine of the largest angle between the current surface and the previous
/// surface rendered along the same ray (25 degrees).
const CREASE_COS: f32 = 0.906;

/// The best estimate per cell: on the static world the ego prediction (exact
/// up to the ego-motion error) weighed with the measurement by their noise; on
/// moving cells the measurement (median over moving neighbours); where the two
/// disagree without forming a moving patch, the measurement; without ego
/// motion, the measurement.
fn fuse(
    geometry: &ImageGeometry,
    raw: &[Raw],
    moving: &[bool],
    disagrees: bool,
    cell: usize,
) -> (f32, f32) {
    let r = raw[cell];
    if !r.l_lidar.is_finite() {
        return (f32::NAN, f32::NAN);
    }
    // A significant disagreement outside any moving patch is either a small
    // mover or an artefact of one of the two: neither is to be trusted alone
    // (their half difference is the uncertainty of their mean).
    if disagrees && !moving[cell] {
        return if r.l_ray_ego.is_finite() {
            (
                0.5 * (r.l_lidar + r.l_ray_ego),
                (0.5 * (r.l_lidar - r.l_ray_ego).abs()).max(r.sigma),
            )
        } else {
            (r.l_lidar, r.sigma)
        };
    }
    if moving[cell] {
        // The median over the moving neighbours: less noise, and an edge cell
        // with a wild value cannot drag it.
        let values = std::iter::once(cell)
            .chain(geometry.neighbours_3x3(cell))
            .filter(|&n| moving[n] && raw[n].l_lidar.is_finite() && raw[n].mask == 0)
            .map(|n| raw[n].l_lidar);
        return (median_3x3(values).unwrap_or(r.l_lidar), r.sigma);
    }
    if !r.l_ray_ego.is_finite() {
        return (r.l_lidar, r.sigma);
    }
    let w_ego = 1.0 / f64::from(r.sigma_ego).max(1e-6).powi(2);
    let w_lidar = 1.0 / f64::from(r.sigma).max(1e-6).powi(2);
    let value =
        (f64::from(r.l_ray_ego) * w_ego + f64::from(r.l_lidar) * w_lidar) / (w_ego + w_lidar);
    (value as f32, (1.0 / (w_ego + w_lidar)).sqrt() as f32)
}

#[cfg(test)]
mod tests {
    use super::*;

    /// The crease test as first written, with short-circuits.
    fn apart(a: &[f32; 3], b: &[f32; 3]) -> bool {
        let known = |n: &[f32; 3]| n[0] * n[0] + n[1] * n[1] + n[2] * n[2] > 0.5;
        known(a) && known(b) && (a[0] * b[0] + a[1] * b[1] + a[2] * b[2]).abs() < CREASE_COS
    }

    /// Missing, short and unit normals at every angle: the same verdict.
    #[test]
    fn the_crease_test_without_branches_gives_the_same_verdict() {
        let mut state = 4242u32;
        let mut next = || {
            state = state.wrapping_mul(1_664_525).wrapping_add(1_013_904_223);
            (state >> 8) as f32 / (1 << 24) as f32
        };
        let normal = |next: &mut dyn FnMut() -> f32| -> [f32; 3] {
            let (azimuth, elevation) = (next() * 6.3, next() * 3.2 - 1.6);
            let length = [0.0, 0.5, 0.7, 0.71, 1.0][(next() * 5.0) as usize % 5];
            [
                length * elevation.cos() * azimuth.cos(),
                length * elevation.cos() * azimuth.sin(),
                length * elevation.sin(),
            ]
        };
        for _ in 0..200_000 {
            let (a, b) = (normal(&mut next), normal(&mut next));
            assert_eq!(
                known(&b) & apart_if_known(&a, &b),
                apart(&a, &b),
                "{a:?} {b:?}"
            );
        }
    }
}
