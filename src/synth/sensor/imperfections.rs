//! Range noise, range biases, dropouts and specks: what turns the exact
//! hits of a scan into measurements (`lidar.range_noise_m`, `lidar.realism`).

use nalgebra::Vector3;
use rand::SeedableRng;
use rand_distr::{Distribution, Normal};

use super::{PointTruth, SimPoint, Surface, World};

impl World {
    /// Gaussian range noise, drawn in point order from a generator seeded by
    /// (seed, scan index): the same on any machine and thread count. With
    /// `realism.range_bias`, the laser's bias and the intensity-dependent
    /// error are added too. The error is along the laser's own ray (from its
    /// origin, off the axis with `realism.off_axis`).
    pub(super) fn add_range_noise(&self, points: &mut [SimPoint], index: u64, seed: u64) {
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
    pub(super) fn add_dropouts_and_specks(
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
