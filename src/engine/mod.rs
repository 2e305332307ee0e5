//! The looming engine: a pure function of a scan pair and a configuration (no
//! I/O, no global state, deterministic; rayon inside) computing, per cell of
//! the current scan's range image and per point, the quantities of
//! `../shared/design/METHOD.md`:
//!
//! - `L_lidar`: range change along rotation-compensated rays (LiDAR only);
//! - `L_ego`: `(t . p)/(p . p)` per point from the ego velocity;
//! - `L_ray_ego`: what `L_lidar` would read were the world static;
//! - `D = L_lidar - L_ray_ego`, the looming of other objects' own motion, and a
//!   moving flag;
//! - a fused looming, its noise, an edge / occlusion / grazing mask, threat
//!   levels and the equal-looming spheres.
//!
//! The previous scan is compared to the current one by rendering its surface
//! (a triangle mesh over its range image, moved by the gyro rotation for
//! `L_lidar` and by the full ego motion for `L_ray_ego`) into the current
//! scan's own rays: exact on planes, so neither discretisation nor turning
//! lights up the static world.

pub mod beams;
mod bias;
pub mod egomotion;
pub mod grid;
pub mod layout;
mod surface;
pub mod threat;
pub mod trajectory;
mod warp;
mod window_extremes;
mod window_sums;

use nalgebra::Vector3;
use rayon::prelude::*;

use crate::model::{PairMotion, ScanPair};
use crate::model::{Scan, StampNs};

pub use grid::{ImageGeometry, NO_POINT, RangeImage};
pub use threat::{ThreatLevel, ThreatSphere};

use surface::{SurfaceParams, Surfaces};
use trajectory::{MotionModel, Trajectory};

/// Engine settings.
#[derive(Debug, Clone, serde::Serialize, serde::Deserialize)]
pub struct EngineConfig {
    /// Columns of the range image [default: the most points any beam holds].
    pub columns: Option<usize>,
    /// Range noise of the sensor (1 sigma), metres.
    pub range_noise_m: f64,
    /// Compensate the gyro rotation before differencing (METHOD.md); off only
    /// to measure what it buys.
    pub rotation_compensation: bool,
    /// Threat thresholds as times to contact, seconds: low, medium, high.
    pub threat_ttc_s: [f64; 3],
    /// A cell moves when |D| exceeds this many sigmas...
    pub moving_sigmas: f64,
    /// ...and this much, 1/s.
    pub moving_min_per_s: f64,
    /// Cells whose surface is seen more obliquely than this (|n . e|) are masked.
    pub grazing_cos: f64,
    /// Fastest plausible closing speed along a surface normal, m/s: a range
    /// change beyond it between two scans means the ray met another surface
    /// (occlusion or disocclusion), not motion.
    pub max_closing_speed_mps: f64,
    /// Where no source measured the velocity or the angular rate over a
    /// pair, estimate them from the static world (`engine::egomotion`).
    pub estimate_ego_motion: bool,
    /// Estimate each laser's range offset from the scans and take it out
    /// (`engine::bias`).
    pub correct_range_bias: bool,
}

impl Default for EngineConfig {
    fn default() -> Self {
        Self {
            columns: None,
            range_noise_m: 0.02,
            rotation_compensation: true,
            // Autey 2012; Sacchi & Sayed 2016; Hayward 1972.
            threat_ttc_s: [3.0, 1.5, 1.0],
            moving_sigmas: 4.0,
            moving_min_per_s: 0.15,
            grazing_cos: 0.15,
            max_closing_speed_mps: 30.0,
            estimate_ego_motion: true,
            correct_range_bias: true,
        }
    }
}

/// Why a cell's values are not to be trusted (bit flags).
pub mod mask {
    /// No return in the current scan.
    pub const EMPTY: u8 = 1;
    /// The previous scan has no surface along this ray (disocclusion, edge of view).
    pub const NO_PREVIOUS: u8 = 2;
    /// Next to an occlusion edge (a neighbour on another surface).
    pub const EDGE: u8 = 4;
    /// Surface seen at grazing incidence.
    pub const GRAZING: u8 = 8;
    /// The ego-motion prediction has no surface here (only with a velocity source).
    pub const NO_EGO: u8 = 16;
    /// The range changed faster than any plausible motion: the ray met another
    /// surface in the previous scan (parallax at a silhouette, occlusion).
    pub const OCCLUSION: u8 = 32;
}

/// What the engine could compute for a pair.
#[derive(Debug, Clone, Copy, PartialEq, Eq, serde::Serialize)]
pub struct Availability {
    /// A velocity source covered the pair: `L_ego`, `L_ray_ego`, `D`, moving,
    /// threat spheres are computed.
    pub ego_velocity: bool,
    /// An angular rate was used to de-rotate the previous scan.
    pub rotation_compensated: bool,
}

/// Everything the engine computed for one pair, reported on the current scan.
#[derive(Debug, Clone)]
pub struct PairLooming {
    pub geometry: ImageGeometry,
    pub availability: Availability,
    /// The current scan gridded: cell -> point index and nearest range, and
    /// `image.point_cell`, point -> cell (`NO_POINT` if none).
    pub image: RangeImage,
    /// Per cell, 1/s (NaN where not computed).
    pub l_lidar: Vec<f32>,
    pub l_ray_ego: Vec<f32>,
    pub disagreement: Vec<f32>,
    /// Noise of `L_lidar` from the range-noise model, 1/s.
    pub sigma_per_s: Vec<f32>,
    /// 1 / (1 + (sigma / 0.05)^2): 1 = clean, 0.5 at sigma 0.05 1/s.
    pub confidence: Vec<f32>,
    /// `mask::*` bits; 0 = trusted.
    pub mask: Vec<u8>,
    /// Trusted cells whose |D| is significant (above `moving_sigmas` sigma and
    /// `moving_min_per_s`); those outside a moving patch are ambiguous.
    pub disagrees: Vec<bool>,
    pub moving: Vec<bool>,
    pub fused: Vec<f32>,
    pub threat: Vec<ThreatLevel>,
    /// Per cell: `|n . e|` of the current surface (1 where no plane was fitted).
    pub incidence_cos: Vec<f32>,
    /// Per cell: unit normal of the current surface, facing the sensor (zero
    /// where no plane was fitted).
    pub normal: Vec<[f32; 3]>,
    /// Per row (beam, lowest first): the range noise (1 sigma, metres) used
    /// for that beam's cells.
    pub range_noise_m_per_row: Vec<f32>,
    /// Per row: the laser's range offset estimated from the scan and taken
    /// out of its returns, metres (all zero where the scan shows none).
    pub range_bias_m_per_row: Vec<f32>,
    /// Time between the compared returns, s.
    pub dt_s: Vec<f32>,
    /// Per point: `L_ego`, 1/s (NaN without velocity).
    pub l_ego: Vec<f32>,
    /// Per point: threat level of its cell when the point is that cell's surface.
    pub point_threat: Vec<ThreatLevel>,
    /// Equal-looming spheres of the low, medium and high levels (LiDAR frame),
    /// from the velocity at the current stamp.
    pub spheres: Option<[ThreatSphere; 3]>,
    /// LiDAR velocity used for the spheres, m/s.
    pub velocity_mps: Option<[f64; 3]>,
    /// LiDAR angular velocity at the current stamp, rad/s.
    pub angular_velocity_radps: Option<[f64; 3]>,
    /// The motion estimated from the static world, where a source was missing.
    pub ego_estimate: Option<egomotion::EgoEstimate>,
}

/// The gridded scan and its surfaces, kept from one pair to the next: the
/// current scan of pair j is the previous scan of pair j+1.
#[derive(Default)]
pub struct EngineCache {
    last: Option<CachedScan>,
    /// The sensor's per-laser range offsets, averaged over the log's scans.
    range_bias: bias::RangeBias,
    /// Pairs whose previous scan's image and surfaces came from the cache.
    reused_scans: u64,
}

impl EngineCache {
    /// Pairs so far whose previous scan's image and surfaces were reused
    /// (all but the first of a stream, while its geometry holds).
    pub fn reused_scans(&self) -> u64 {
        self.reused_scans
    }
}

struct CachedScan {
    scan: std::sync::Arc<Scan>,
    rows: usize,
    cols: usize,
    ring_to_row: Option<Vec<usize>>,
    image: RangeImage,
    surfaces: Surfaces,
    /// The motion estimated for the pair that ended at this scan (velocity,
    /// angular velocity): the next pair's first guess, as a vehicle's motion
    /// changes little in one scan period.
    estimate: Option<(Vector3<f64>, Vector3<f64>)>,
}

impl CachedScan {
    /// Whether the scan was gridded as `geometry` grids it.
    fn matches(&self, geometry: &ImageGeometry) -> bool {
        self.rows == geometry.rows
            && self.cols == geometry.cols
            && self.ring_to_row == geometry.ring_to_row
            // (Not the lasers' parallax, fitted anew on every scan: the
            // image and surfaces do not depend on it.)
            // Rows from elevation depend on the whole beam table.
            && geometry.ring_to_row.is_some()
    }
}

/// Run the engine on a pair. `None` when the scans give no usable image.
pub fn compute(pair: &ScanPair, config: &EngineConfig) -> Option<PairLooming> {
    compute_with_cache(pair, config, &mut EngineCache::default())
}

/// [`compute`], reusing the previous scan's image and surfaces when the cache
/// holds them (the same result, about a third less work on a stream of pairs).
pub fn compute_with_cache(
    pair: &ScanPair,
    config: &EngineConfig,
    cache: &mut EngineCache,
) -> Option<PairLooming> {
    let (previous, current) = (&*pair.previous, &*pair.current);
    // What the cache holds of this pair's previous scan (nothing of any
    // other): its columns, kept where this scan allows so that the cache
    // holds, and the motion estimated up to it.
    let last = cache
        .last
        .take()
        .filter(|c| std::sync::Arc::ptr_eq(&c.scan, &pair.previous));
    let geometry = grid::geometry_for(
        previous,
        current,
        config.columns,
        last.as_ref().map(|c| c.cols),
    )?;
    let params = SurfaceParams::for_geometry(&geometry, config.range_noise_m);
    let previous_estimate = last.as_ref().and_then(|c| c.estimate);
    let cached = last.filter(|c| c.matches(&geometry));
    cache.reused_scans += u64::from(cached.is_some());
    // Each scan's offsets join the sensor's running estimate in time order
    // (the previous scan first, when it was not cached).
    let correct = config.correct_range_bias;
    let scan_bias = |scan: &Scan, image: &RangeImage, wanted: bool| {
        (correct && wanted)
            .then(|| bias::estimate(scan, image, &geometry))
            .flatten()
    };
    let previous_ahead = u64::from(cached.is_none());
    let (want_previous, want_current) = (
        cache.range_bias.wants_estimate(0),
        cache.range_bias.wants_estimate(previous_ahead),
    );
    let (previous_gridded, (cur_image, cur_bias)) = rayon::join(
        || match cached {
            Some(c) => Ok((c.image, c.surfaces)),
            None => {
                let image = RangeImage::build(previous, &geometry);
                let bias = scan_bias(previous, &image, want_previous);
                Err((image, bias))
            }
        },
        || {
            let image = RangeImage::build(current, &geometry);
            let bias = scan_bias(current, &image, want_current);
            (image, bias)
        },
    );
    let rows = geometry.rows;
    let previous_to_fit = previous_gridded.map_err(|(image, bias)| {
        let applied = cache.range_bias.update(bias, rows);
        (image, applied)
    });
    let cur_applied = cache.range_bias.update(cur_bias, rows);
    let ((prev_image, prev_surfaces), cur_surfaces) = rayon::join(
        || match previous_to_fit {
            Ok(done) => done,
            Err((image, applied)) => {
                let surfaces = Surfaces::estimate(previous, &image, &geometry, params, applied);
                (image, surfaces)
            }
        },
        || Surfaces::estimate(current, &cur_image, &geometry, params, cur_applied),
    );
    let result = compute_from_surfaces(
        pair,
        config,
        &geometry,
        (&prev_image, &prev_surfaces),
        (&cur_image, &cur_surfaces),
        previous_estimate,
    );
    let estimate = result.as_ref().and_then(|r| r.ego_estimate).map(|e| {
        (
            Vector3::from(e.velocity_mps),
            Vector3::from(e.angular_velocity_radps),
        )
    });
    cache.last = Some(CachedScan {
        scan: pair.current.clone(),
        rows: geometry.rows,
        cols: geometry.cols,
        ring_to_row: geometry.ring_to_row.clone(),
        image: cur_image,
        surfaces: cur_surfaces,
        estimate,
    });
    result
}

fn compute_from_surfaces(
    pair: &ScanPair,
    config: &EngineConfig,
    geometry: &ImageGeometry,
    (prev_image, prev_surfaces): (&RangeImage, &Surfaces),
    (cur_image, cur_surfaces): (&RangeImage, &Surfaces),
    first_guess: Option<(Vector3<f64>, Vector3<f64>)>,
) -> Option<PairLooming> {
    let (previous, current) = (&*pair.previous, &*pair.current);
    let geometry = geometry.clone();
    let prev_time = cell_times(previous, prev_image);
    let cur_time = cell_times(current, cur_image);
    let coords = cell_coords(cur_surfaces, &geometry);
    let column_time = column_times(&cur_time, cur_surfaces, &geometry);
    let (start_ns, end_ns) = (
        previous.time_span_ns().0 - 1_000_000,
        current.time_span_ns().1 + 1_000_000,
    );
    let source = warp::Source {
        surfaces: prev_surfaces,
        time_ns: &prev_time,
    };
    let target = warp::Target::new(cur_surfaces, &coords, &column_time);
    let offset_ns = current.stamp_ns - previous.stamp_ns;
    let span = (start_ns, end_ns);
    // Not on sparse sensors: a ring's orientation there is a prior (ground
    // or vertical), too rough to pin down a motion (on OS0-8 the estimate
    // drifted to four times the platform's speed).
    let estimated = (config.estimate_ego_motion
        && !geometry.sparse_rows()
        && (pair.motion.velocity.is_none() || pair.motion.angular.is_none()))
    .then(|| {
        estimate_motion(
            pair,
            &source,
            &target,
            &geometry,
            (cur_surfaces, &cur_time),
            config,
            span,
            first_guess,
        )
    })
    .flatten();
    let motion = estimated.as_ref().map_or(&pair.motion, |(m, _)| m);
    let ego_estimate = estimated.as_ref().map(|(_, e)| *e);
    let rotation_rate_known = motion.angular.is_some();
    let rotate = config.rotation_compensation && rotation_rate_known;
    let rotation =
        Trajectory::integrate(motion, MotionModel::RotationOnly, rotate, start_ns, end_ns)?;
    let full = Trajectory::integrate(
        motion,
        MotionModel::Full,
        rotation_rate_known,
        start_ns,
        end_ns,
    );
    let (rotated, moved) = rayon::join(
        || warp::render(&source, &target, &geometry, &rotation, offset_ns),
        || {
            full.as_ref()
                .map(|t| warp::render(&source, &target, &geometry, t, offset_ns))
        },
    );
    let cells = per_cell(
        config,
        &geometry,
        cur_surfaces,
        &cur_time,
        &rotated,
        moved.as_ref(),
        motion,
    );
    let velocity = motion.velocity_at(current.stamp_ns);
    let angular = motion.angular_velocity_at(current.stamp_ns);
    let l_ego = ego_looming(current, motion);
    let point_threat = point_threats(cur_image, &cells.threat);
    let range_noise_m_per_row = cur_surfaces.noise_m_per_row.clone();
    Some(PairLooming {
        availability: Availability {
            ego_velocity: full.is_some(),
            rotation_compensated: rotate,
        },
        spheres: velocity.map(|v| threat::spheres(&v, &config.threat_ttc_s)),
        velocity_mps: velocity.map(|v| [v.x, v.y, v.z]),
        angular_velocity_radps: angular.map(|w| [w.x, w.y, w.z]),
        ego_estimate,
        image: cur_image.clone(),
        geometry,
        l_lidar: cells.l_lidar,
        l_ray_ego: cells.l_ray_ego,
        disagreement: cells.disagreement,
        sigma_per_s: cells.sigma,
        confidence: cells.confidence,
        mask: cells.mask,
        disagrees: cells.disagrees,
        moving: cells.moving,
        fused: cells.fused,
        threat: cells.threat,
        incidence_cos: cur_surfaces.incidence_cos.clone(),
        normal: cur_surfaces.normal.clone(),
        range_noise_m_per_row,
        range_bias_m_per_row: cur_surfaces.range_bias_m_per_row.clone(),
        dt_s: cells.dt_s,
        l_ego,
        point_threat,
    })
}

/// Renders of the previous scan tried to estimate the motion.
const ESTIMATE_ITERATIONS: usize = 8;

/// The pair's motion with what no source measured estimated from the static
/// world: the previous scan is rendered with a trial motion, corrected
/// until the static surfaces meet (`egomotion`). Constant over the pair.
#[allow(clippy::too_many_arguments)]
fn estimate_motion(
    pair: &ScanPair,
    source: &warp::Source,
    target: &warp::Target,
    geometry: &ImageGeometry,
    (current, current_time): (&Surfaces, &[StampNs]),
    config: &EngineConfig,
    (start_ns, end_ns): (StampNs, StampNs),
    first_guess: Option<(Vector3<f64>, Vector3<f64>)>,
) -> Option<(PairMotion, egomotion::EgoEstimate)> {
    let stamp_ns = pair.current.stamp_ns;
    let measured = &pair.motion;
    let prior = egomotion::Prior {
        rotation_known: measured.angular.is_some(),
        velocity_known: measured.velocity.is_some(),
    };
    let (guess_velocity, guess_angular) =
        first_guess.unwrap_or((Vector3::zeros(), Vector3::zeros()));
    let mut angular = measured
        .angular_velocity_at(stamp_ns)
        .unwrap_or(guess_angular);
    let mut velocity = measured.velocity_at(stamp_ns).unwrap_or(guess_velocity);
    let offset_ns = stamp_ns - pair.previous.stamp_ns;
    let mut fit = None;
    for _ in 0..ESTIMATE_ITERATIONS {
        let trial = with_constant_motion(measured, velocity, angular, start_ns, end_ns);
        let trajectory = Trajectory::integrate(&trial, MotionModel::Full, true, start_ns, end_ns)?;
        let rendered = warp::render(source, target, geometry, &trajectory, offset_ns);
        let Some(step) = egomotion::correction(
            current,
            current_time,
            &rendered,
            config.range_noise_m,
            &prior,
        ) else {
            break;
        };
        angular += step.angular_radps;
        velocity += step.velocity_mps;
        fit = Some(step);
        // Converged: the update moves a surface 10 m away by less than a
        // millimetre.
        let dt_s = offset_ns as f64 * 1e-9;
        if (step.velocity_mps.norm() + step.angular_radps.norm() * 10.0) * dt_s < 1e-3 {
            break;
        }
    }
    let egomotion::Correction {
        inlier_cells,
        residual_m,
        ..
    } = fit?;
    let motion = with_constant_motion(measured, velocity, angular, start_ns, end_ns);
    Some((
        motion,
        egomotion::EgoEstimate {
            velocity_mps: [velocity.x, velocity.y, velocity.z],
            angular_velocity_radps: [angular.x, angular.y, angular.z],
            inlier_cells,
            residual_m,
            velocity_estimated: !prior.velocity_known,
            rotation_estimated: !prior.rotation_known,
        },
    ))
}

/// `motion` with the series no source measured replaced by constants.
fn with_constant_motion(
    motion: &PairMotion,
    velocity: Vector3<f64>,
    angular: Vector3<f64>,
    start_ns: StampNs,
    end_ns: StampNs,
) -> PairMotion {
    let constant = |value: Vector3<f64>| {
        crate::model::TimeSeries::new(vec![(start_ns, value), (end_ns, value)], 1.0)
    };
    PairMotion {
        velocity: Some(
            motion
                .velocity
                .clone()
                .unwrap_or_else(|| constant(velocity)),
        ),
        angular: Some(motion.angular.clone().unwrap_or_else(|| constant(angular))),
        ..motion.clone()
    }
}

/// Absolute time of each cell's return, ns.
fn cell_times(scan: &Scan, image: &RangeImage) -> Vec<StampNs> {
    image
        .point
        .par_iter()
        .map(|&index| {
            if index == NO_POINT {
                return scan.stamp_ns;
            }
            let offset_s = scan
                .time_offset_s
                .as_ref()
                .map_or(0.0, |t| f64::from(t[index as usize]));
            scan.stamp_ns + (offset_s * 1e9).round() as StampNs
        })
        .collect()
}

/// Continuous (row, column) of each occupied cell's ray.
fn cell_coords(surfaces: &Surfaces, geometry: &ImageGeometry) -> Vec<(f32, f32)> {
    surfaces
        .elevation_rad
        .par_iter()
        .zip(&surfaces.azimuth_rad)
        .zip(&surfaces.range_m)
        .enumerate()
        .map(|(cell, ((&elevation_rad, &azimuth_rad), &range_m))| {
            // A return lies in or next to its own cell's row.
            let own_row = cell / geometry.cols;
            let row = geometry.row_f_at(elevation_rad, f64::from(range_m), own_row);
            let col = geometry.col_f(azimuth_rad);
            (row as f32, col as f32)
        })
        .collect()
}

/// Median firing time of each column of the current scan (`StampNs::MIN` for
/// an empty column).
fn column_times(
    time_ns: &[StampNs],
    surfaces: &Surfaces,
    geometry: &ImageGeometry,
) -> Vec<StampNs> {
    (0..geometry.cols)
        .into_par_iter()
        .map(|col| {
            let mut times: Vec<StampNs> = (0..geometry.rows)
                .map(|row| row * geometry.cols + col)
                .filter(|&cell| surfaces.range_m[cell].is_finite())
                .map(|cell| time_ns[cell])
                .collect();
            if times.is_empty() {
                return StampNs::MIN;
            }
            let mid = times.len() / 2;
            *times.select_nth_unstable(mid).1
        })
        .collect()
}

struct CellValues {
    l_lidar: Vec<f32>,
    l_ray_ego: Vec<f32>,
    disagreement: Vec<f32>,
    sigma: Vec<f32>,
    confidence: Vec<f32>,
    mask: Vec<u8>,
    disagrees: Vec<bool>,
    moving: Vec<bool>,
    fused: Vec<f32>,
    threat: Vec<ThreatLevel>,
    dt_s: Vec<f32>,
}

/// First pass per cell: the differences, the noise and the mask.
#[derive(Clone, Copy)]
struct Raw {
    l_lidar: f32,
    l_ray_ego: f32,
    sigma: f32,
    mask: u8,
    dt_s: f32,
}

fn per_cell(
    config: &EngineConfig,
    geometry: &ImageGeometry,
    current: &Surfaces,
    current_time: &[StampNs],
    rotated: &warp::Rendered,
    moved: Option<&warp::Rendered>,
    motion: &PairMotion,
) -> CellValues {
    let raw: Vec<Raw> = (0..geometry.cells())
        .into_par_iter()
        // The motion series' positions of the last source and current
        // times, per worker (neighbouring cells' times are close).
        .map_init(
            || [0, 0],
            |hints, cell| {
                let raw = raw_cell(config, current, current_time, rotated, moved, cell);
                match moved {
                    Some(moved) => to_instant(
                        raw,
                        motion,
                        (moved.source_time_ns[cell], current_time[cell]),
                        hints,
                    ),
                    None => raw,
                }
            },
        )
        .collect();
    let candidate: Vec<bool> = raw
        .par_iter()
        .map(|r| {
            let d = r.l_lidar - r.l_ray_ego;
            r.mask == 0
                && d.is_finite()
                && f64::from(d.abs())
                    > (config.moving_sigmas * f64::from(r.sigma)).max(config.moving_min_per_s)
        })
        .collect();
    // A moving object is a patch spanning beams, not a lone noisy cell nor a
    // one-beam line (what the junction of road and wall leaves): keep
    // candidates with two candidate neighbours, one of them on another beam.
    let moving: Vec<bool> = (0..geometry.cells())
        .into_par_iter()
        .map(|cell| {
            let row = cell / geometry.cols;
            candidate[cell]
                && geometry
                    .neighbours_3x3(cell)
                    .any(|n| candidate[n] && n / geometry.cols != row)
        })
        .collect();
    let pointwise: Vec<f32> = (0..geometry.cells())
        .into_par_iter()
        .map(|cell| fuse(geometry, &raw, &moving, candidate[cell], cell))
        .collect();
    // On the static world neighbouring cells see one smooth looming field: a
    // 3x3 median over trusted static neighbours removes what noise is left
    // without blurring across edges (masked and moving cells take no part).
    // Once per cell, as each is read by up to nine windows.
    let trusted_static: Vec<bool> = (0..geometry.cells())
        .into_par_iter()
        .map(|n| raw[n].mask == 0 && !moving[n] && !candidate[n] && pointwise[n].is_finite())
        .collect();
    let trusted_static = |n: usize| trusted_static[n];
    let fused: Vec<f32> = (0..geometry.cells())
        .into_par_iter()
        .map(|cell| {
            if !trusted_static(cell) {
                return pointwise[cell];
            }
            // Only neighbours on the same surface (parallel planes): the base
            // of an object is not smoothed into the road it stands on.
            let normal = current.normal[cell];
            let same_surface = |n: usize| {
                let m = current.normal[n];
                normal[0] * m[0] + normal[1] * m[1] + normal[2] * m[2] > 0.95
            };
            let values = std::iter::once(cell)
                .chain(geometry.neighbours_3x3(cell).filter(|&n| same_surface(n)))
                .filter(|&n| trusted_static(n))
                .map(|n| pointwise[n]);
            median_3x3(values).unwrap_or(pointwise[cell])
        })
        .collect();
    let thresholds = config.threat_ttc_s;
    let threat = fused
        .par_iter()
        .zip(&raw)
        .map(|(f, r)| {
            if r.mask == 0 {
                ThreatLevel::of(f64::from(*f), &thresholds)
            } else {
                ThreatLevel::None
            }
        })
        .collect();
    // Each field on both cores (eight passes over the image).
    let field = |of: fn(&Raw) -> f32| raw.par_iter().map(of).collect::<Vec<f32>>();
    CellValues {
        disagreement: field(|r| r.l_lidar - r.l_ray_ego),
        l_lidar: field(|r| r.l_lidar),
        l_ray_ego: field(|r| r.l_ray_ego),
        confidence: field(|r| 1.0 / (1.0 + (r.sigma / 0.05).powi(2))),
        sigma: field(|r| r.sigma),
        mask: raw.par_iter().map(|r| r.mask).collect(),
        dt_s: field(|r| r.dt_s),
        disagrees: candidate,
        moving,
        fused,
        threat,
    }
}

fn raw_cell(
    config: &EngineConfig,
    current: &Surfaces,
    current_time: &[StampNs],
    rotated: &warp::Rendered,
    moved: Option<&warp::Rendered>,
    cell: usize,
) -> Raw {
    let nan = Raw {
        l_lidar: f32::NAN,
        l_ray_ego: f32::NAN,
        sigma: f32::NAN,
        mask: mask::EMPTY,
        dt_s: f32::NAN,
    };
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
    let creased = |normal: &[f32; 3]| apart(normal, &current_normal);
    // (Excusing the moved render's crease where it meets the return within
    // the noise kept 1 % more of a real HDL-64E scan and cost 12 % of the
    // fused accuracy on the synthetic cut-in at 64 x 2048.)
    let creased_here =
        creased(&rotated.normal[cell]) || moved.is_some_and(|m| creased(&m.normal[cell]));
    if creased_here || rotated.edge[cell] || moved.is_some_and(|m| m.edge[cell]) {
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
    // Both ranges are plane fits of several returns; the rendered one mixes
    // three vertices: about sigma / sqrt(2) each, conservatively.
    let support = f64::from(current.support[cell].max(1));
    let noise_m = current.noise_m(cell);
    let sigma_now = noise_m * (1.0 / support).sqrt().max(0.4);
    let sigma_before = noise_m * 0.6;
    let sigma = (sigma_now.powi(2) + sigma_before.powi(2)).sqrt() / (dt_s * range_now);
    Raw {
        l_lidar: l_lidar as f32,
        l_ray_ego: l_ray_ego as f32,
        sigma: sigma as f32,
        mask: flags,
        dt_s: dt_s as f32,
    }
}

/// A difference over `dt` measures the looming of the mean ego velocity over
/// the interval; reported at the current return's time it is off by
/// `a dt / (2 h)` when the ego accelerates (braking at 5 m/s^2 at 6.7 m reads
/// 0.037 1/s high). On a static surface the translation looming scales with
/// the speed, so `(k - 1) L_ray_ego`, with `k` the current speed over the mean
/// speed, is that error: removed from both differences, which leaves `D`
/// unchanged and corrects moving objects for the ego's share of the relative
/// acceleration.
/// (`hints`: the series' positions of the last two times asked, for
/// [`PairMotion::velocity_near`].)
fn to_instant(
    raw: Raw,
    motion: &PairMotion,
    (source_time_ns, time_ns): (StampNs, StampNs),
    hints: &mut [usize; 2],
) -> Raw {
    if !raw.l_ray_ego.is_finite() {
        return raw;
    }
    let [source_hint, hint] = hints;
    let (Some(before), Some(now)) = (
        motion.velocity_near(source_time_ns, source_hint),
        motion.velocity_near(time_ns, hint),
    ) else {
        return raw;
    };
    let mean_speed_mps = (0.5 * (before + now)).norm();
    if mean_speed_mps < MIN_SPEED_FOR_INSTANT_MPS {
        return raw;
    }
    let correction = ((now.norm() / mean_speed_mps - 1.0) * f64::from(raw.l_ray_ego)) as f32;
    Raw {
        l_lidar: raw.l_lidar + correction,
        l_ray_ego: raw.l_ray_ego + correction,
        ..raw
    }
}

/// Below this mean speed the ratio of speeds means nothing.
const MIN_SPEED_FOR_INSTANT_MPS: f64 = 0.1;

/// Two known normals more than the crease angle apart.
fn apart(a: &[f32; 3], b: &[f32; 3]) -> bool {
    let known = |n: &[f32; 3]| n[0] * n[0] + n[1] * n[1] + n[2] * n[2] > 0.5;
    known(a) && known(b) && (a[0] * b[0] + a[1] * b[1] + a[2] * b[2]).abs() < CREASE_COS
}

/// Cosine of the largest angle between the current surface and the previous
/// surface rendered along the same ray (25 degrees).
const CREASE_COS: f32 = 0.906;

/// Median (upper middle) of at most the 9 values of a 3x3 window, without
/// allocating: this runs for every cell.
fn median_3x3(values: impl Iterator<Item = f32>) -> Option<f32> {
    let mut window = [0f32; 9];
    let mut count = 0;
    for value in values.take(9) {
        window[count] = value;
        count += 1;
    }
    if count == 0 {
        return None;
    }
    // The middle order statistic of `f32::total_cmp`'s order, by insertion
    // sort of the values' total-order keys: for nine values a few dozen
    // integer comparisons, where the general selection's setup costs more
    // than the sort.
    let mut keys = window.map(total_order_key);
    let keys = &mut keys[..count];
    for i in 1..count {
        let key = keys[i];
        let mut j = i;
        while j > 0 && keys[j - 1] > key {
            keys[j] = keys[j - 1];
            j -= 1;
        }
        keys[j] = key;
    }
    Some(from_total_order_key(keys[count / 2]))
}

/// An `f32`'s bits as an integer that orders as `f32::total_cmp` does
/// (negative values' magnitude bits flipped).
fn total_order_key(value: f32) -> i32 {
    let bits = value.to_bits() as i32;
    bits ^ (((bits >> 31) as u32) >> 1) as i32
}

/// The inverse of [`total_order_key`] (the flip is its own inverse).
fn from_total_order_key(key: i32) -> f32 {
    f32::from_bits((key ^ (((key >> 31) as u32) >> 1) as i32) as u32)
}

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
) -> f32 {
    let r = raw[cell];
    if !r.l_lidar.is_finite() {
        return f32::NAN;
    }
    // A significant disagreement outside any moving patch is either a small
    // mover or an artefact of one of the two: neither is to be trusted alone.
    if disagrees && !moving[cell] {
        return if r.l_ray_ego.is_finite() {
            0.5 * (r.l_lidar + r.l_ray_ego)
        } else {
            r.l_lidar
        };
    }
    if moving[cell] {
        // The median over the moving neighbours: less noise, and an edge cell
        // with a wild value cannot drag it.
        let values = std::iter::once(cell)
            .chain(geometry.neighbours_3x3(cell))
            .filter(|&n| moving[n] && raw[n].l_lidar.is_finite() && raw[n].mask == 0)
            .map(|n| raw[n].l_lidar);
        return median_3x3(values).unwrap_or(r.l_lidar);
    }
    if !r.l_ray_ego.is_finite() {
        return r.l_lidar;
    }
    // The ego prediction's own error: velocity error (about 1 %) and the
    // interpolation of the previous surface.
    let sigma_ego = 0.01 * f64::from(r.l_ray_ego.abs()) + 0.005;
    let w_ego = 1.0 / sigma_ego.powi(2);
    let w_lidar = 1.0 / f64::from(r.sigma).max(1e-6).powi(2);
    ((f64::from(r.l_ray_ego) * w_ego + f64::from(r.l_lidar) * w_lidar) / (w_ego + w_lidar)) as f32
}

/// `L_ego = (t . p)/(p . p)` per point, `t` at the point's own time.
fn ego_looming(scan: &Scan, motion: &PairMotion) -> Vec<f32> {
    (0..scan.points_m.len())
        .into_par_iter()
        .map_init(
            || 0,
            |hint, i| {
                let offset_s = scan.time_offset_s.as_ref().map_or(0.0, |t| f64::from(t[i]));
                let t_ns = scan.stamp_ns + (offset_s * 1e9).round() as StampNs;
                let Some(velocity) = motion.velocity_near(t_ns, hint) else {
                    return f32::NAN;
                };
                let p = scan.points_m[i];
                let p = Vector3::new(f64::from(p[0]), f64::from(p[1]), f64::from(p[2]));
                (velocity.dot(&p) / p.norm_squared()) as f32
            },
        )
        .collect()
}

/// A point takes its cell's threat level when it is the surface the cell
/// measured; hidden returns behind it do not.
fn point_threats(image: &RangeImage, threat: &[ThreatLevel]) -> Vec<ThreatLevel> {
    image
        .point_surface
        .iter()
        .map(|&cell| {
            if cell == NO_POINT {
                ThreatLevel::None
            } else {
                threat[cell as usize]
            }
        })
        .collect()
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn the_3x3_median_is_the_total_orders_middle() {
        let specials = [
            0.0,
            -0.0,
            1.5,
            -2.25,
            f32::INFINITY,
            f32::NEG_INFINITY,
            f32::NAN,
            -f32::NAN,
            1e-40,
            -1e-40,
        ];
        // Every window length from 1 to 9 over a deterministic mix.
        let mut state = 12345u32;
        for case in 0..20_000 {
            let count = 1 + case % 9;
            let values: Vec<f32> = (0..count)
                .map(|_| {
                    state = state.wrapping_mul(1_664_525).wrapping_add(1_013_904_223);
                    if state.is_multiple_of(4) {
                        specials[(state >> 8) as usize % specials.len()]
                    } else {
                        (state >> 8) as f32 / 1e5 - 80.0
                    }
                })
                .collect();
            let mut sorted = values.clone();
            sorted.sort_by(f32::total_cmp);
            let expected = sorted[count / 2];
            let median = median_3x3(values.iter().copied()).unwrap();
            assert_eq!(median.to_bits(), expected.to_bits(), "{values:?}");
        }
        assert_eq!(median_3x3(std::iter::empty()), None);
    }
}
