//! The simulated spinning LiDAR and its ground truth: a rolling sweep in which
//! every column is fired at its own time while the ego and the actors move.
//! Pure math, no I/O; deterministic (rayon over columns, results in order,
//! noise drawn sequentially from a per-scan seeded generator).
//!
//! The lasers' calibration is in `calibration.rs`, the scene's shapes in
//! `objects.rs`, the measurement errors added to the exact hits in
//! `imperfections.rs`.

mod calibration;
mod imperfections;
mod objects;

use nalgebra::{Isometry3, Vector3};
use rayon::prelude::*;

use super::geometry::{Hit, Ray, SceneSnapshot};
use super::kinematics::{EgoTrack, LidarState, actor_motion, vehicle_from_lidar};
use super::scene::Scenario;

pub use calibration::{beam_elevations_rad, calibrate, two_block_elevations_rad};
pub use imperfections::intensity_range_error_m;
use objects::{actor_object, static_objects};

/// One simulated point with its truth.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct SimPoint {
    /// Measured point (range noise included), LiDAR frame, metres.
    pub point_m: [f32; 3],
    pub intensity: f32,
    /// Beam index, 0 = lowest beam (as Velodyne drivers number rings).
    pub ring: u16,
    /// Firing column, 0 to `columns - 1`.
    pub column: u32,
    /// Firing time from the scan stamp, seconds.
    pub time_s: f32,
    pub truth: PointTruth,
}

/// Ground truth of one point (definitions in docs/ground-truth.md).
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct PointTruth {
    /// Noise-free hit point, LiDAR frame at the firing time, metres.
    pub point_m: [f64; 3],
    pub range_m: f64,
    /// `(v_rel . p) / (p . p)`: v_rel the LiDAR's velocity relative to the hit
    /// object, LiDAR frame. 1/s.
    pub point_looming_per_s: f64,
    /// `-(dR/dt)/R` along the ray, its direction held fixed in a non-rotating
    /// frame (what a rotation-compensated range difference measures). 1/s.
    pub ray_looming_per_s: f64,
    /// The part of the ray looming caused by the hit object's own motion:
    /// `ray_looming` minus what it would be were the object static (0 on the
    /// static world). This is the truth of the disagreement D = L_lidar - L_ray_ego.
    pub own_motion_looming_per_s: f64,
    /// `|n . d|`: cosine of the angle between the ray and the surface normal
    /// (1 = the surface faces the ray, 0 = grazing).
    pub incidence_cos: f64,
    /// 0 for the static world, the actor id otherwise.
    pub object_id: u32,
    pub surface: Surface,
    pub moving: bool,
}

/// What kind of surface a point is on.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
#[repr(u8)]
pub enum Surface {
    Road = 0,
    /// Buildings, walls, poles, parked cars.
    StaticObject = 1,
    Actor = 2,
    /// A speck of rain or dust (`realism.speck_fraction`), at rest in the world.
    Speck = 3,
}

/// One laser of the head: its calibration (all zero offsets when ideal).
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Laser {
    /// Elevation of the laser's ray, radians.
    pub elevation_rad: f64,
    /// Rotational correction: fired at encoder azimuth `a`, the ray points at
    /// `a + azimuth_offset_rad`.
    pub azimuth_offset_rad: f64,
    /// Height of the laser's origin above the frame origin, metres.
    pub vertical_offset_m: f64,
    /// Sideways offset of the laser's origin, metres, along the horizontal
    /// normal to its ray pointing left of it (rotating with the head).
    pub horizontal_offset_m: f64,
    /// Added to every range the laser measures, metres.
    pub range_bias_m: f64,
}

impl Laser {
    fn on_axis(&self) -> bool {
        self.vertical_offset_m == 0.0 && self.horizontal_offset_m == 0.0
    }
}

/// One simulated scan.
#[derive(Debug, Clone)]
pub struct SimScan {
    pub index: u64,
    /// Scan start, seconds from the start of the drive.
    pub stamp_s: f64,
    /// Points in firing order (column by column, lowest beam first).
    pub points: Vec<SimPoint>,
}

/// The simulated world: scene, ego track, sensor.
pub struct World {
    pub scenario: Scenario,
    pub track: EgoTrack,
    pub vehicle_from_lidar: Isometry3<f64>,
    static_scene: SceneSnapshot,
    /// Beam elevations, ring order (lowest first), radians.
    pub elevations_rad: Vec<f64>,
    /// The lasers, ring order (lowest first).
    pub lasers: Vec<Laser>,
    pub period_s: f64,
    /// Start of scan 0, seconds from the start of the drive (0 unless the
    /// LiDAR is one of several, phased against the roof's).
    pub phase_s: f64,
}

impl World {
    pub fn new(scenario: Scenario) -> Self {
        let track = EgoTrack::new(
            &scenario.ego,
            scenario.ground_height_m,
            scenario.duration_s + 1.0,
        );
        let lidar = &scenario.lidar;
        let vehicle_from_lidar = vehicle_from_lidar(lidar.mount_xyz_m, lidar.mount_rpy_deg);
        let lasers = calibrate(lidar);
        let elevations_rad = lasers.iter().map(|l| l.elevation_rad).collect();
        let period_s = 1.0 / lidar.rate_hz;
        let static_scene = SceneSnapshot::new(static_objects(&scenario));
        Self {
            scenario,
            track,
            vehicle_from_lidar,
            static_scene,
            elevations_rad,
            lasers,
            period_s,
            phase_s: 0.0,
        }
    }

    /// The world of the same scene seen by another LiDAR, `lidar`, whose scan
    /// 0 starts at `phase_s`.
    pub fn for_lidar(scenario: &Scenario, lidar: &super::scene::LidarSpec, phase_s: f64) -> Self {
        let mut scenario = scenario.clone();
        scenario.lidar = lidar.clone();
        scenario.extra_lidars.clear();
        Self {
            phase_s,
            ..Self::new(scenario)
        }
    }

    /// Number of whole scans in the drive.
    pub fn scan_count(&self) -> u64 {
        ((self.scenario.duration_s - self.phase_s) / self.period_s + 1e-9)
            .floor()
            .max(0.0) as u64
    }

    /// The first scan starting at or after `start_s`.
    pub fn first_scan_at(&self, start_s: f64) -> u64 {
        ((start_s - self.phase_s) / self.period_s - 1e-9)
            .ceil()
            .max(0.0) as u64
    }

    /// Start of scan `index`, seconds from the start of the drive.
    pub fn scan_stamp_s(&self, index: u64) -> f64 {
        self.phase_s + index as f64 * self.period_s
    }

    pub fn lidar_state(&self, t_s: f64) -> LidarState {
        LidarState::new(&self.track.state(t_s), &self.vehicle_from_lidar)
    }

    /// The actors at `t_s`.
    pub fn actor_scene(&self, t_s: f64) -> SceneSnapshot {
        let ground = self.scenario.ground_height_m;
        SceneSnapshot::new(
            self.scenario
                .actors
                .iter()
                .map(|a| actor_object(a, t_s, ground))
                .collect(),
        )
    }

    /// Velocity of an object (0 = static world), world frame.
    pub fn object_velocity_world_mps(&self, object_id: u32, t_s: f64) -> Vector3<f64> {
        self.scenario
            .actors
            .iter()
            .find(|a| a.id == object_id)
            .map_or(Vector3::zeros(), |actor| {
                let (_, [vx, vy]) = actor_motion(actor, t_s);
                Vector3::new(vx, vy, 0.0)
            })
    }

    /// The nearest hit of a world ray (static scene and `actors`), with the
    /// kind of surface hit.
    pub fn cast(&self, ray: &Ray, actors: &SceneSnapshot) -> Option<(Hit, Surface)> {
        let max_range_m = self.scenario.lidar.max_range_m;
        let fixed = self.static_scene.cast(ray, max_range_m).map(|hit| {
            // The road is object 0 of the static scene.
            let surface = if hit.object_index == 0 {
                Surface::Road
            } else {
                Surface::StaticObject
            };
            (hit, surface)
        });
        let moving = actors
            .cast(ray, max_range_m)
            .map(|hit| (hit, Surface::Actor));
        match (fixed, moving) {
            (Some(a), Some(b)) => Some(if b.0.range_m < a.0.range_m { b } else { a }),
            (a, b) => a.or(b),
        }
    }

    /// Direction of beam `ring` at `column`, LiDAR frame. Columns sweep clockwise
    /// seen from above, starting behind the sensor, as Velodyne sensors turn.
    pub fn beam_direction(&self, ring: usize, column: u32) -> Vector3<f64> {
        let azimuth = self.beam_azimuth_rad(ring, column);
        let elevation = self.elevations_rad[ring];
        Vector3::new(
            elevation.cos() * azimuth.cos(),
            elevation.cos() * azimuth.sin(),
            elevation.sin(),
        )
    }

    /// Encoder azimuth of `column`, LiDAR frame, radians: 180 deg at column 0,
    /// then clockwise seen from above.
    pub fn encoder_azimuth_rad(&self, column: u32) -> f64 {
        std::f64::consts::PI
            - std::f64::consts::TAU * f64::from(column) / f64::from(self.scenario.lidar.columns)
    }

    /// Azimuth of beam `ring`'s ray at `column`: the encoder azimuth plus the
    /// laser's rotational correction.
    pub fn beam_azimuth_rad(&self, ring: usize, column: u32) -> f64 {
        let offset = self.lasers[ring].azimuth_offset_rad;
        let azimuth = self.encoder_azimuth_rad(column);
        if offset == 0.0 {
            azimuth
        } else {
            azimuth + offset
        }
    }

    /// Origin of beam `ring`'s ray at `column`, LiDAR frame (zero on the axis).
    pub fn laser_origin(&self, ring: usize, column: u32) -> Vector3<f64> {
        let laser = &self.lasers[ring];
        let azimuth = self.beam_azimuth_rad(ring, column);
        Vector3::new(
            -laser.horizontal_offset_m * azimuth.sin(),
            laser.horizontal_offset_m * azimuth.cos(),
            laser.vertical_offset_m,
        )
    }

    /// Firing time of `column` from the scan stamp, seconds.
    pub fn column_time_s(&self, column: u32) -> f64 {
        self.period_s * f64::from(column) / f64::from(self.scenario.lidar.columns)
    }

    /// Simulate scan `index` with noise from `seed`.
    pub fn scan(&self, index: u64, seed: u64) -> SimScan {
        let stamp_s = self.scan_stamp_s(index);
        let columns: Vec<Vec<SimPoint>> = (0..self.scenario.lidar.columns)
            .into_par_iter()
            .map(|column| self.fire_column(stamp_s, column))
            .collect();
        let mut points: Vec<SimPoint> = columns.into_iter().flatten().collect();
        self.add_range_noise(&mut points, index, seed);
        self.add_dropouts_and_specks(&mut points, stamp_s, index, seed);
        SimScan {
            index,
            stamp_s,
            points,
        }
    }

    fn fire_column(&self, stamp_s: f64, column: u32) -> Vec<SimPoint> {
        let time_s = self.column_time_s(column);
        let t_s = stamp_s + time_s;
        let lidar = self.lidar_state(t_s);
        let actors = self.actor_scene(t_s);
        let origin = lidar.origin();
        let mut points = Vec::with_capacity(self.elevations_rad.len());
        for ring in 0..self.elevations_rad.len() {
            let direction_lidar = self.beam_direction(ring, column);
            let direction_world = lidar.world_from_lidar.rotation * direction_lidar;
            let on_axis = self.lasers[ring].on_axis();
            let laser_origin = self.laser_origin(ring, column);
            let ray = Ray {
                origin: if on_axis {
                    origin
                } else {
                    origin + lidar.world_from_lidar.rotation * laser_origin
                },
                direction: direction_world,
            };
            let Some((hit, surface)) = self.cast(&ray, &actors) else {
                continue;
            };
            // The truth is along the ray from the frame origin through the hit.
            let (point_lidar, range_m, ray_world) = if on_axis {
                (direction_lidar * hit.range_m, hit.range_m, direction_world)
            } else {
                let point = laser_origin + direction_lidar * hit.range_m;
                let range_m = point.norm();
                let ray_world = lidar.world_from_lidar.rotation * (point / range_m);
                (point, range_m, ray_world)
            };
            let truth = self.point_truth(
                &lidar,
                &point_lidar,
                range_m,
                &ray_world,
                &hit,
                surface,
                t_s,
            );
            let intensity = intensity(&hit, &direction_world);
            points.push(SimPoint {
                point_m: truth.point_m.map(|c| c as f32),
                intensity,
                ring: ring as u16,
                column,
                time_s: time_s as f32,
                truth,
            });
        }
        points
    }

    /// Truth of one hit at `point_lidar` (range `range_m` from the frame
    /// origin, unit direction `direction_world` from it). Ray looming: the
    /// range along a fixed (non-rotating) direction `d` from the frame origin
    /// to the hit surface with normal `n` changes at
    /// `dR/dt = -(n . v_rel) / (n . d)`, exactly at the instant (only the tangent
    /// plane matters), so `L_ray = (n . v_rel) / ((n . d) R)`. This holds for
    /// an off-axis laser too: the frame-origin ray through its hit meets the
    /// same tangent plane there.
    #[allow(clippy::too_many_arguments)]
    fn point_truth(
        &self,
        lidar: &LidarState,
        point_lidar: &Vector3<f64>,
        range_m: f64,
        direction_world: &Vector3<f64>,
        hit: &Hit,
        surface: Surface,
        t_s: f64,
    ) -> PointTruth {
        let velocity_rel_world =
            lidar.velocity_world_mps - self.object_velocity_world_mps(hit.object_id, t_s);
        let velocity_rel_lidar = lidar.to_lidar(&velocity_rel_world);
        let point_looming_per_s = velocity_rel_lidar.dot(point_lidar) / point_lidar.norm_squared();
        let along_ray = hit.normal.dot(direction_world) * range_m;
        let ray_looming_per_s = hit.normal.dot(&velocity_rel_world) / along_ray;
        // What the ray looming would be were the object static: the rest is its own motion.
        let own_motion_looming_per_s = if hit.moving {
            ray_looming_per_s - hit.normal.dot(&lidar.velocity_world_mps) / along_ray
        } else {
            0.0
        };
        PointTruth {
            point_m: [point_lidar.x, point_lidar.y, point_lidar.z],
            range_m,
            point_looming_per_s,
            ray_looming_per_s,
            own_motion_looming_per_s,
            incidence_cos: hit.normal.dot(direction_world).abs(),
            object_id: hit.object_id,
            surface,
            moving: hit.moving,
        }
    }
}

fn intensity(hit: &Hit, direction_world: &Vector3<f64>) -> f32 {
    let facing = hit.normal.dot(direction_world).abs();
    let base = if hit.moving { 150.0 } else { 40.0 };
    (base + 60.0 * facing) as f32
}
