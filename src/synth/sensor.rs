//! The simulated spinning LiDAR and its ground truth: a rolling sweep in which
//! every column is fired at its own time while the ego and the actors move.
//! Pure math, no I/O; deterministic (rayon over columns, results in order,
//! noise drawn sequentially from a per-scan seeded generator).

use nalgebra::{Isometry3, Point3, Vector3};
use rand::SeedableRng;
use rand_distr::{Distribution, Normal};
use rayon::prelude::*;

use super::geometry::{Hit, Ray, SceneObject, SceneSnapshot, Shape};
use super::kinematics::{EgoTrack, LidarState, actor_motion, vehicle_from_lidar};
use super::scene::{Actor, Realism, Scenario, StaticObject};

/// Parked-car box size, metres.
const CAR_SIZE_M: [f64; 3] = [4.5, 1.8, 1.5];

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
        }
    }

    /// Number of whole scans in the drive.
    pub fn scan_count(&self) -> u64 {
        (self.scenario.duration_s / self.period_s + 1e-9).floor() as u64
    }

    /// The first scan starting at or after `start_s`.
    pub fn first_scan_at(&self, start_s: f64) -> u64 {
        (start_s / self.period_s - 1e-9).ceil().max(0.0) as u64
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
        let stamp_s = index as f64 * self.period_s;
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

    /// Gaussian range noise, drawn in point order from a generator seeded by
    /// (seed, scan index): the same on any machine and thread count. With
    /// `realism.range_bias`, the laser's bias and the intensity-dependent
    /// error are added too. The error is along the laser's own ray (from its
    /// origin, off the axis with `realism.off_axis`).
    fn add_range_noise(&self, points: &mut [SimPoint], index: u64, seed: u64) {
        let sigma_m = self.scenario.lidar.range_noise_m;
        let noisy = !(sigma_m.is_nan() || sigma_m <= 0.0);
        let normal = Normal::new(0.0, if noisy { sigma_m } else { 1.0 }).ok();
        let noisy = noisy && normal.is_some();
        let biased = self.scenario.lidar.realism.range_bias;
        let off_axis = self.lasers.iter().any(|l| !l.on_axis());
        if !noisy && !biased && !off_axis {
            return;
        }
        let mut rng = rand_chacha::ChaCha8Rng::seed_from_u64(
            seed ^ index.wrapping_mul(0x9E37_79B9_7F4A_7C15),
        );
        for point in points {
            let noise_m = match (&normal, noisy) {
                (Some(normal), true) => normal.sample(&mut rng),
                _ => 0.0,
            };
            let laser = &self.lasers[usize::from(point.ring)];
            if !biased && laser.on_axis() {
                let range_m = point.truth.range_m;
                let noisy_m = (range_m + noise_m).max(1e-3);
                let scale = noisy_m / range_m;
                point.point_m = point.truth.point_m.map(|c| (c * scale) as f32);
                continue;
            }
            let error_m = if biased {
                laser.range_bias_m + intensity_range_error_m(point.intensity)
            } else {
                0.0
            };
            let origin = self.laser_origin(usize::from(point.ring), point.column);
            let along = Vector3::from(point.truth.point_m) - origin;
            let distance_m = along.norm();
            let measured_m = (distance_m + noise_m + error_m).max(1e-3);
            let measured = origin + along * (measured_m / distance_m);
            point.point_m = [measured.x as f32, measured.y as f32, measured.z as f32];
        }
    }

    /// Dropouts (returns lost, more at long range) and specks (a return
    /// replaced by one from a particle at a random short range along the
    /// laser's ray), drawn in point order from their own seeded generator.
    fn add_dropouts_and_specks(
        &self,
        points: &mut Vec<SimPoint>,
        stamp_s: f64,
        index: u64,
        seed: u64,
    ) {
        use rand::Rng;
        let realism = &self.scenario.lidar.realism;
        let (dropout, speck) = (realism.dropout_fraction, realism.speck_fraction);
        if !(dropout > 0.0 || speck > 0.0) {
            return;
        }
        let max_range_m = self.scenario.lidar.max_range_m;
        let mut rng = rand_chacha::ChaCha8Rng::seed_from_u64(
            seed ^ 0x5EC5_D809 ^ index.wrapping_mul(0xC2B2_AE3D_27D4_EB4F),
        );
        points.retain_mut(|point| {
            let (lost, speck_draw, at): (f64, f64, f64) =
                (rng.random(), rng.random(), rng.random());
            let lost_probability =
                dropout * (1.0 + 3.0 * (point.truth.range_m / max_range_m).min(1.0));
            if lost < lost_probability {
                return false;
            }
            if speck_draw < speck {
                self.make_speck(point, stamp_s, at);
            }
            true
        });
    }

    /// Replace `point` by a speck at rest in the world, at a fraction `at` of
    /// the way from 0.5 m to min(8 m, the surface) along the laser's ray.
    fn make_speck(&self, point: &mut SimPoint, stamp_s: f64, at: f64) {
        let ring = usize::from(point.ring);
        let origin = self.laser_origin(ring, point.column);
        let direction = self.beam_direction(ring, point.column);
        let surface_m = (Vector3::from(point.truth.point_m) - origin).norm();
        let far_m = surface_m.min(8.0);
        let near_m = 0.5_f64.min(far_m);
        let distance_m = near_m + at * (far_m - near_m);
        let p = origin + direction * distance_m;
        let lidar = self.lidar_state(stamp_s + f64::from(point.time_s));
        let velocity = lidar.to_lidar(&lidar.velocity_world_mps);
        // A particle seen face on: ray and point looming are the same.
        let looming = velocity.dot(&p) / p.norm_squared();
        point.truth = PointTruth {
            point_m: [p.x, p.y, p.z],
            range_m: p.norm(),
            point_looming_per_s: looming,
            ray_looming_per_s: looming,
            own_motion_looming_per_s: 0.0,
            incidence_cos: 1.0,
            object_id: 0,
            surface: Surface::Speck,
            moving: false,
        };
        point.point_m = [p.x as f32, p.y as f32, p.z as f32];
        point.intensity = 5.0;
    }
}

/// Range error of a weak return (`realism.range_bias`): 0 at intensity 210
/// (the strongest synthetic return), 4 cm at intensity 0. Metres.
pub fn intensity_range_error_m(intensity: f32) -> f64 {
    0.04 * (1.0 - f64::from(intensity) / 210.0).clamp(0.0, 1.0)
}

/// Calibration seed of the simulated head: the lasers are a property of the
/// sensor, the same whatever `--seed`.
const CALIBRATION_SEED: u64 = 0x4844_4C36_3445;

/// The lasers of `lidar`, lowest first: ideal (evenly spaced, on the axis, no
/// corrections) unless `lidar.realism` asks otherwise.
pub fn calibrate(lidar: &super::scene::LidarSpec) -> Vec<Laser> {
    use rand::Rng;
    let realism: &Realism = &lidar.realism;
    let elevations = if realism.irregular_elevations {
        two_block_elevations_rad(
            lidar.beams,
            lidar.elevation_min_deg,
            lidar.elevation_max_deg,
        )
    } else {
        beam_elevations_rad(
            lidar.beams,
            lidar.elevation_min_deg,
            lidar.elevation_max_deg,
        )
    };
    let beams = elevations.len();
    let mut rng = rand_chacha::ChaCha8Rng::seed_from_u64(CALIBRATION_SEED);
    elevations
        .into_iter()
        .enumerate()
        .map(|(k, elevation_rad)| {
            // Draw everything for every laser, so each option keeps its values
            // whichever others are on.
            let draws: [f64; 6] = std::array::from_fn(|_| rng.random::<f64>());
            let upper = k >= beams / 2;
            let side = if k % 2 == 0 { 1.0 } else { -1.0 };
            Laser {
                elevation_rad: if realism.irregular_elevations {
                    elevation_rad + (0.06 * (2.0 * draws[0] - 1.0)).to_radians()
                } else {
                    elevation_rad
                },
                azimuth_offset_rad: if realism.azimuth_offsets {
                    // HDL-64E: lasers alternate sides, 1 to 5 degrees off.
                    (side * (1.0 + 4.0 * draws[1])).to_radians()
                } else {
                    0.0
                },
                vertical_offset_m: if realism.off_axis {
                    let base = if upper { 0.20 } else { 0.14 };
                    base + 0.01 * (2.0 * draws[2] - 1.0)
                } else {
                    0.0
                },
                horizontal_offset_m: if realism.off_axis {
                    side * (0.026 + 0.004 * (2.0 * draws[3] - 1.0))
                } else {
                    0.0
                },
                range_bias_m: if realism.range_bias {
                    0.02 * (2.0 * draws[4] - 1.0)
                } else {
                    0.0
                },
            }
        })
        .collect()
}

/// HDL-64E-like elevations, lowest first, radians: a lower block of half the
/// lasers over the lower 16/26.8 of the field and an upper block over the top
/// 10.5/26.8, 0.3/26.8 of the field apart (at the default field: -24.8 to
/// -8.8 deg, 0.516 deg apart, and -8.5 to +2 deg, 0.339 deg apart).
pub fn two_block_elevations_rad(beams: u16, min_deg: f64, max_deg: f64) -> Vec<f64> {
    if beams < 4 {
        return beam_elevations_rad(beams, min_deg, max_deg);
    }
    let span = max_deg - min_deg;
    let lower_top = min_deg + span * 16.0 / 26.8;
    let upper_bottom = lower_top + span * 0.3 / 26.8;
    let lower = beams / 2;
    let mut elevations = beam_elevations_rad(lower, min_deg, lower_top);
    elevations.extend(beam_elevations_rad(beams - lower, upper_bottom, max_deg));
    elevations
}

/// Beam elevations evenly spaced, lowest first, radians.
pub fn beam_elevations_rad(beams: u16, min_deg: f64, max_deg: f64) -> Vec<f64> {
    if beams <= 1 {
        return vec![max_deg.to_radians()];
    }
    let step = (max_deg - min_deg) / f64::from(beams - 1);
    (0..beams)
        .map(|b| (min_deg + step * f64::from(b)).to_radians())
        .collect()
}

fn intensity(hit: &Hit, direction_world: &Vector3<f64>) -> f32 {
    let facing = hit.normal.dot(direction_world).abs();
    let base = if hit.moving { 150.0 } else { 40.0 };
    (base + 60.0 * facing) as f32
}

/// The static world: road plane and every static object.
fn static_objects(scenario: &Scenario) -> Vec<SceneObject> {
    let ground = scenario.ground_height_m;
    let mut objects = vec![SceneObject {
        shape: Shape::Ground { height_m: ground },
        object_id: 0,
        moving: false,
    }];
    for object in &scenario.static_objects {
        let shape = match object {
            StaticObject::Box {
                center_xy_m,
                size_m,
                yaw_deg,
                ..
            } => standing_box(*center_xy_m, *size_m, *yaw_deg, ground),
            StaticObject::Car {
                center_xy_m,
                yaw_deg,
                ..
            } => standing_box(*center_xy_m, CAR_SIZE_M, *yaw_deg, ground),
            StaticObject::Pole {
                center_xy_m,
                radius_m,
                height_m,
                ..
            } => Shape::Cylinder {
                base: Point3::new(center_xy_m[0], center_xy_m[1], ground),
                radius_m: *radius_m,
                height_m: *height_m,
            },
        };
        objects.push(SceneObject {
            shape,
            object_id: 0,
            moving: false,
        });
    }
    objects
}

fn actor_object(actor: &Actor, t_s: f64, ground: f64) -> SceneObject {
    let (position, _) = actor_motion(actor, t_s);
    SceneObject {
        shape: standing_box(position, actor.size_m, actor.yaw_deg, ground),
        object_id: actor.id,
        moving: true,
    }
}

/// A box resting on the road.
fn standing_box(center_xy_m: [f64; 2], size_m: [f64; 3], yaw_deg: f64, ground: f64) -> Shape {
    Shape::Box {
        center: Point3::new(center_xy_m[0], center_xy_m[1], ground + size_m[2] / 2.0),
        half_extents_m: Vector3::new(size_m[0], size_m[1], size_m[2]) / 2.0,
        yaw_rad: yaw_deg.to_radians(),
    }
}
