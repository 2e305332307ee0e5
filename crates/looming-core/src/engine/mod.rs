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
//!
//! Here the orchestration ([`compute_with_cache`], the [`EngineCache`]);
//! the settings in `config.rs`, the result in `result.rs`, the ring and
//! time recovery in `layout/`, the gridding in `grid.rs` (beam tables in
//! `beams.rs`), the local fits in `surface/`, the renders in `warp/`, the
//! per-cell math in `cells.rs`, the motion estimated from the scans in
//! `egomotion.rs`.

pub(crate) mod atan;
pub mod beams;
mod bias;
mod cells;
mod config;
pub mod egomotion;
pub mod grid;
pub mod layout;
mod result;
mod rings;
mod spare;
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

pub use config::EngineConfig;
pub use grid::{ImageGeometry, NO_POINT, RangeImage};
pub use result::{Availability, PairLooming, StageTimes, mask};
pub use threat::{ThreatLevel, ThreatSphere};

use cells::per_cell;
use surface::{SurfaceParams, Surfaces};
use trajectory::{MotionModel, Trajectory};

/// The gridded scans and their surfaces, kept from one pair to the next: the
/// current scan of pair j is the previous scan of pair j+1, or of a later
/// pair where pairs span several scans ([`crate::pairing::stride`]).
#[derive(Default)]
pub struct EngineCache {
    /// The last pairs' current scans, oldest first.
    recent: std::collections::VecDeque<CachedScan>,
    /// The sensor's per-laser range offsets, averaged over the log's scans.
    range_bias: bias::RangeBias,
    /// The rings of a ring-ordered sensor as last measured (its geometry's
    /// beam table, each ring's row and parallax) and the pairs since.
    rings: Option<(ImageGeometry, u64)>,
    /// Pairs whose previous scan's image and surfaces came from the cache.
    reused_scans: u64,
}

impl EngineCache {
    /// What the cache holds of `scan` (nothing of any other), taken out with
    /// every scan older than it: pairs come in time order.
    fn take(&mut self, scan: &std::sync::Arc<Scan>) -> Option<CachedScan> {
        let at = self
            .recent
            .iter()
            .position(|c| std::sync::Arc::ptr_eq(&c.scan, scan))?;
        self.recent.drain(..at);
        self.recent.pop_front()
    }

    /// A pair's current scan, for a later pair; at most
    /// [`CACHED_SCANS`] are held.
    fn keep(&mut self, scan: CachedScan) {
        if self.recent.len() >= CACHED_SCANS {
            self.recent.pop_front();
        }
        self.recent.push_back(scan);
    }

    /// Pairs so far whose previous scan's image and surfaces were reused
    /// (all but the first of a stream, while its geometry holds).
    pub fn reused_scans(&self) -> u64 {
        self.reused_scans
    }

    /// The pair's image geometry ([`grid::geometry_for`]), a ring-ordered
    /// sensor's rings taken from the last pair that measured them but on
    /// one pair in [`RINGS_MEASURED_EVERY`]: they are the sensor's, and
    /// measuring them from every return of every scan (an elevation and a
    /// range per return, a fit per ring) was 1.7 % of braking KITTI's run
    /// (`perf`, one thread). A scan whose returns no longer lie in the rows
    /// so given (rings numbered anew: [`rings::rings_still_hold`]) measures
    /// them at once.
    fn geometry_for(
        &mut self,
        pair: &ScanPair,
        config: &EngineConfig,
        previous_cols: Option<usize>,
    ) -> Option<ImageGeometry> {
        let known = self
            .rings
            .as_ref()
            .filter(|(_, pairs)| *pairs + 1 < RINGS_MEASURED_EVERY)
            .map(|(rings, _)| rings);
        let (geometry, reused) = grid::geometry_for(
            (&pair.previous, &pair.current),
            (config.columns, config.firings_per_column),
            previous_cols,
            known,
        )?;
        match &mut self.rings {
            Some((_, pairs)) if reused => *pairs += 1,
            rings => {
                *rings = geometry
                    .ring_to_row
                    .is_some()
                    .then(|| (geometry.clone(), 0))
            }
        }
        Some(geometry)
    }
}

/// A ring-ordered sensor's rings are measured on one pair in this many
/// (`EngineCache::geometry_for`).
const RINGS_MEASURED_EVERY: u64 = 10;

/// Scans the cache holds: a pair spans at most four of a sensor's periods.
const CACHED_SCANS: usize = 4;

struct CachedScan {
    scan: std::sync::Arc<Scan>,
    rows: usize,
    cols: usize,
    ring_to_row: Option<Vec<usize>>,
    image: RangeImage,
    surfaces: Surfaces,
    /// Each cell's return time ([`cell_times`]), ns.
    time_ns: Vec<StampNs>,
    /// The motion estimated for the pair that ended at this scan (velocity,
    /// angular velocity): the next pair's first guess, as a vehicle's motion
    /// changes little in one scan period.
    estimate: Option<(Vector3<f64>, Vector3<f64>)>,
}

impl CachedScan {
    /// The pair's current scan as gridded by `geometry`, with the motion
    /// estimated for the pair, for the next pair.
    fn keep(
        pair: &ScanPair,
        geometry: &ImageGeometry,
        (image, surfaces, time_ns): (RangeImage, Surfaces, Vec<StampNs>),
        ego_estimate: Option<egomotion::EgoEstimate>,
    ) -> Self {
        let estimate = ego_estimate.map(|e| {
            (
                Vector3::from(e.velocity_mps),
                Vector3::from(e.angular_velocity_radps),
            )
        });
        CachedScan {
            scan: pair.current.clone(),
            rows: geometry.rows,
            cols: geometry.cols,
            ring_to_row: geometry.ring_to_row.clone(),
            image,
            surfaces,
            time_ns,
            estimate,
        }
    }

    /// Whether the scan was gridded as `geometry` grids it.
    fn matches(&self, geometry: &ImageGeometry) -> bool {
        self.rows == geometry.rows
            && self.cols == geometry.cols
            && self.ring_to_row == geometry.ring_to_row
            // (Not the lasers' parallax, measured with the rings: the
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
/// Runs `stage`, adding its wall time to `seconds`.
fn timed<T>(seconds: &mut f64, stage: impl FnOnce() -> T) -> T {
    let started = std::time::Instant::now();
    let value = stage();
    *seconds += started.elapsed().as_secs_f64();
    value
}

pub fn compute_with_cache(
    pair: &ScanPair,
    config: &EngineConfig,
    cache: &mut EngineCache,
) -> Option<PairLooming> {
    let (previous, current) = (&*pair.previous, &*pair.current);
    // What the cache holds of this pair's previous scan (nothing of any
    // other): its columns, kept where this scan allows so that the cache
    // holds, and the motion estimated up to it.
    let last = cache.take(&pair.previous);
    let geometry = cache.geometry_for(pair, config, last.as_ref().map(|c| c.cols))?;
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
    let mut times = StageTimes::default();
    let started = std::time::Instant::now();
    let (previous_gridded, (cur_image, cur_bias)) = rayon::join(
        || match cached {
            Some(c) => Ok((c.image, c.surfaces, c.time_ns)),
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
    times.range_images_s = started.elapsed().as_secs_f64();
    let started = std::time::Instant::now();
    let ((prev_image, prev_surfaces, prev_time), cur_surfaces) = rayon::join(
        || match previous_to_fit {
            Ok((image, surfaces, time_ns)) => (image, surfaces, Some(time_ns)),
            Err((image, applied)) => {
                let surfaces = Surfaces::estimate(previous, &image, &geometry, params, applied);
                (image, surfaces, None)
            }
        },
        || Surfaces::estimate(current, &cur_image, &geometry, params, cur_applied),
    );
    times.plane_fits_s = started.elapsed().as_secs_f64();
    let (prev_time, cur_time) = timed(&mut times.cell_times_s, || {
        pair_cell_times((previous, &prev_image, prev_time), (current, &cur_image))
    });
    let result = compute_from_surfaces(
        pair,
        config,
        &geometry,
        (&prev_surfaces, &prev_time),
        (&cur_image, &cur_surfaces, &cur_time),
        (previous_estimate, times),
    );
    let estimate = result.as_ref().and_then(|r| r.ego_estimate);
    cache.keep(CachedScan::keep(
        pair,
        &geometry,
        (cur_image, cur_surfaces, cur_time),
        estimate,
    ));
    result
}

/// A motion to start the estimate from: (velocity m/s, angular velocity
/// rad/s).
type MotionGuess = (Vector3<f64>, Vector3<f64>);

fn compute_from_surfaces(
    pair: &ScanPair,
    config: &EngineConfig,
    geometry: &ImageGeometry,
    (prev_surfaces, prev_time): (&Surfaces, &[StampNs]),
    (cur_image, cur_surfaces, cur_time): (&RangeImage, &Surfaces, &[StampNs]),
    (first_guess, mut times): (Option<MotionGuess>, StageTimes),
) -> Option<PairLooming> {
    let (previous, current) = (&*pair.previous, &*pair.current);
    let geometry = geometry.clone();
    let (coords, column_time) = timed(&mut times.cell_times_s, || {
        (
            cell_coords(cur_surfaces, &geometry),
            column_times(cur_time, cur_surfaces, &geometry),
        )
    });
    let span = (
        previous.time_span_ns().0 - 1_000_000,
        current.time_span_ns().1 + 1_000_000,
    );
    let source = timed(&mut times.renders_s, || {
        warp::Source::new(prev_surfaces, prev_time)
    });
    let target = warp::Target::new(cur_surfaces, &coords, &column_time);
    let offset_ns = current.stamp_ns - previous.stamp_ns;
    let estimated = if wants_motion_estimate(config, &geometry, &pair.motion) {
        timed(&mut times.motion_estimate_s, || {
            egomotion::estimate_motion(
                pair,
                &source,
                &target,
                &geometry,
                (cur_surfaces, cur_time),
                config,
                span,
                first_guess,
            )
        })
    } else {
        None
    };
    let (motion, ego_estimate, estimate_render) = match estimated {
        Some(e) => (e.motion, Some(e.estimate), e.rendered),
        None => (pair.motion.clone(), None, None),
    };
    let motion = &motion;
    let (rotate, rotation, full) = trajectories(config, motion, span)?;
    // The ego render: the estimate's last one where it was made with the
    // estimated motion (the same trajectory), else made here.
    let (rotated, moved) = timed(&mut times.renders_s, || {
        rayon::join(
            || warp::render_rotation(&source, &target, &geometry, &rotation, offset_ns),
            || match (estimate_render, full.as_ref()) {
                (Some(rendered), Some(_)) => Some(rendered),
                (_, full) => full.map(|t| warp::render(&source, &target, &geometry, t, offset_ns)),
            },
        )
    });
    let started = std::time::Instant::now();
    let cells = per_cell(
        config,
        &geometry,
        cur_surfaces,
        cur_time,
        &rotated,
        moved.as_ref(),
        (motion, ego_estimate.as_ref()),
    );
    let availability = Availability {
        ego_velocity: full.is_some(),
        rotation_compensated: rotate,
    };
    let mut looming = pair_looming(
        config,
        (current, cur_image, cur_surfaces),
        geometry,
        motion,
        cells,
        availability,
        ego_estimate,
    );
    times.cells_s = started.elapsed().as_secs_f64();
    looming.stage_times = times;
    Some(looming)
}

/// Whether to estimate what no source measured of the pair's motion. Not on
/// sparse sensors: a ring's orientation there is a prior (ground or
/// vertical), too rough to pin down a motion (on OS0-8 the estimate drifted
/// to four times the platform's speed).
fn wants_motion_estimate(
    config: &EngineConfig,
    geometry: &ImageGeometry,
    measured: &PairMotion,
) -> bool {
    config.estimate_ego_motion
        && !geometry.sparse_rows()
        && (measured.velocity.is_none() || measured.angular.is_none())
}

/// The previous scan's moves over `(start_ns, end_ns)`: whether the rotation
/// is compensated, the rotation only (identity when not), and the full ego
/// motion where the velocity is known. `None` when not even the rotation
/// integrates.
fn trajectories(
    config: &EngineConfig,
    motion: &PairMotion,
    (start_ns, end_ns): (StampNs, StampNs),
) -> Option<(bool, Trajectory, Option<Trajectory>)> {
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
    Some((rotate, rotation, full))
}

/// The pair's result: the per-cell values, reported on the current scan with
/// its surfaces' fields, the per-point values and the threat spheres.
fn pair_looming(
    config: &EngineConfig,
    (current, cur_image, cur_surfaces): (&Scan, &RangeImage, &Surfaces),
    geometry: ImageGeometry,
    motion: &PairMotion,
    cells: cells::CellValues,
    availability: Availability,
    ego_estimate: Option<egomotion::EgoEstimate>,
) -> PairLooming {
    let velocity = motion.velocity_at(current.stamp_ns);
    let angular = motion.angular_velocity_at(current.stamp_ns);
    let l_ego = ego_looming(current, motion);
    let point_threat = point_threats(cur_image, &cells.threat);
    let range_noise_m_per_row = cur_surfaces.noise_m_per_row.clone();
    PairLooming {
        availability,
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
        fused_sigma_per_s: cells.fused_sigma,
        ray_ego_sigma_per_s: cells.ray_ego_sigma,
        threat: cells.threat,
        incidence_cos: cur_surfaces.incidence_cos.clone(),
        normal: cur_surfaces.normal.clone(),
        range_noise_m_per_row,
        range_bias_m_per_row: cur_surfaces.range_bias_m_per_row.clone(),
        dt_s: cells.dt_s,
        l_ego,
        point_threat,
        stage_times: StageTimes::default(),
    }
}

/// Both scans' [`cell_times`]: the previous scan's as the cache kept them
/// (computed when it was the current scan), else computed here.
fn pair_cell_times(
    (previous, prev_image, kept): (&Scan, &RangeImage, Option<Vec<StampNs>>),
    (current, cur_image): (&Scan, &RangeImage),
) -> (Vec<StampNs>, Vec<StampNs>) {
    (
        kept.unwrap_or_else(|| cell_times(previous, prev_image)),
        cell_times(current, cur_image),
    )
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
/// Row by row: a cell's row from the row's chunk, not from a division per
/// cell.
fn cell_coords(surfaces: &Surfaces, geometry: &ImageGeometry) -> Vec<(f32, f32)> {
    let cols = geometry.cols;
    let mut coords = vec![(0.0, 0.0); geometry.cells()];
    coords
        .par_chunks_mut(cols)
        .enumerate()
        .for_each(|(own_row, coords_row)| {
            let first = own_row * cols;
            for (cell, coords) in (first..).zip(coords_row) {
                // A return lies in or next to its own cell's row.
                let angles = (surfaces.azimuth_rad[cell], surfaces.elevation_rad[cell]);
                let range_m = f64::from(surfaces.range_m[cell]);
                let (row, col) = geometry.coords_of(angles, range_m, own_row);
                *coords = (row as f32, col as f32);
            }
        });
    coords
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
        // One list per worker, refilled per column, not one allocated per
        // column.
        .map_init(Vec::new, |times: &mut Vec<StampNs>, col| {
            times.clear();
            times.extend(
                (0..geometry.rows)
                    .map(|row| row * geometry.cols + col)
                    .filter(|&cell| surfaces.range_m[cell].is_finite())
                    .map(|cell| time_ns[cell]),
            );
            if times.is_empty() {
                return StampNs::MIN;
            }
            let mid = times.len() / 2;
            *times.select_nth_unstable(mid).1
        })
        .collect()
}

/// `L_ego = (t . p)/(p . p)` per point, `t` at the point's own time.
fn ego_looming(scan: &Scan, motion: &PairMotion) -> Vec<f32> {
    (0..scan.points_m.len())
        .into_par_iter()
        .map_init(
            || PointVelocity {
                hint: 0,
                last: None,
            },
            |at, i| {
                let offset_s = scan.time_offset_s.as_ref().map_or(0.0, |t| f64::from(t[i]));
                let t_ns = scan.stamp_ns + (offset_s * 1e9).round() as StampNs;
                let Some(velocity) = at.velocity(motion, t_ns) else {
                    return f32::NAN;
                };
                let p = scan.points_m[i];
                let p = Vector3::new(f64::from(p[0]), f64::from(p[1]), f64::from(p[2]));
                (velocity.dot(&p) / p.norm_squared()) as f32
            },
        )
        .collect()
}

/// The ego velocity at a point's time, for [`ego_looming`]: the last
/// point's again where the times are equal (a sensor fires a column's lasers
/// at once, and a scan lists a column's returns together), else
/// [`PairMotion::velocity_near`] from the last position in the series.
struct PointVelocity {
    hint: usize,
    /// The last time asked, ns, and the velocity then.
    last: Option<(StampNs, Option<Vector3<f64>>)>,
}

impl PointVelocity {
    fn velocity(&mut self, motion: &PairMotion, t_ns: StampNs) -> Option<Vector3<f64>> {
        match self.last {
            Some((last_ns, velocity)) if last_ns == t_ns => velocity,
            _ => {
                let velocity = motion.velocity_near(t_ns, &mut self.hint);
                self.last = Some((t_ns, velocity));
                velocity
            }
        }
    }
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
