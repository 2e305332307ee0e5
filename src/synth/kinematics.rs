//! Exact motion of the ego vehicle, its LiDAR and the actors, as functions of
//! time (seconds from the start of the drive). Pure math, no I/O.

use nalgebra::{Isometry3, Point3, Rotation3, Translation3, UnitQuaternion, Vector3};

use super::scene::{Actor, EgoSpec, Profile, profile_at, profile_slope_at};

/// Standard gravity, m/s^2 (what an IMU at rest on a level road reads on z).
pub(crate) const GRAVITY_MPS2: f64 = 9.80665;

/// Step of the tabulated ego track, seconds.
const TRACK_STEP_S: f64 = 1e-3;

/// The ego vehicle's state at one instant, in the world frame.
#[derive(Debug, Clone, Copy)]
pub struct EgoState {
    /// Origin of the vehicle/IMU frame.
    pub position_m: Vector3<f64>,
    pub yaw_rad: f64,
    pub speed_mps: f64,
    pub yaw_rate_radps: f64,
    /// d(speed)/dt.
    pub accel_long_mps2: f64,
}

impl EgoState {
    /// Heading unit vector.
    fn heading(&self) -> Vector3<f64> {
        Vector3::new(self.yaw_rad.cos(), self.yaw_rad.sin(), 0.0)
    }

    /// World pose of the vehicle frame.
    pub fn world_from_vehicle(&self) -> Isometry3<f64> {
        Isometry3::from_parts(
            Translation3::from(self.position_m),
            UnitQuaternion::from_axis_angle(&Vector3::z_axis(), self.yaw_rad),
        )
    }

    /// Velocity of the vehicle origin, world frame.
    pub fn velocity_world_mps(&self) -> Vector3<f64> {
        self.heading() * self.speed_mps
    }

    /// Angular velocity, world frame (the road is flat: yaw only).
    pub fn angular_velocity_world_radps(&self) -> Vector3<f64> {
        Vector3::new(0.0, 0.0, self.yaw_rate_radps)
    }

    /// Acceleration of the vehicle origin, world frame.
    pub fn acceleration_world_mps2(&self) -> Vector3<f64> {
        let lateral = Vector3::new(-self.yaw_rad.sin(), self.yaw_rad.cos(), 0.0);
        self.heading() * self.accel_long_mps2 + lateral * (self.speed_mps * self.yaw_rate_radps)
    }

    /// What an ideal IMU at the vehicle origin reads (vehicle frame): specific
    /// force (acceleration minus gravity, so +g on z at rest) and angular velocity.
    pub fn imu_reading(&self) -> (Vector3<f64>, Vector3<f64>) {
        let world_from_vehicle = self.world_from_vehicle();
        let specific_force_world =
            self.acceleration_world_mps2() + Vector3::new(0.0, 0.0, GRAVITY_MPS2);
        (
            world_from_vehicle.rotation.inverse() * specific_force_world,
            Vector3::new(0.0, 0.0, self.yaw_rate_radps),
        )
    }
}

/// The ego trajectory, integrated once at a fine step and interpolated with
/// cubic Hermite splines (positions and analytic velocities at both ends of a
/// step), so positions are exact to far below a micrometre.
#[derive(Debug, Clone)]
pub struct EgoTrack {
    speed_mps: Profile,
    yaw_rate_radps: Profile,
    /// World z of the vehicle frame: road height + IMU height above it.
    imu_z_m: f64,
    /// (x, y, yaw) at k * TRACK_STEP_S.
    samples: Vec<[f64; 3]>,
}

impl EgoTrack {
    pub fn new(spec: &EgoSpec, ground_height_m: f64, duration_s: f64) -> Self {
        let yaw_rate_radps: Profile = spec
            .yaw_rate_dps
            .iter()
            .map(|[t, v]| [*t, v.to_radians()])
            .collect();
        let steps = (duration_s / TRACK_STEP_S).ceil() as usize + 2;
        let mut samples = Vec::with_capacity(steps + 1);
        let [mut x, mut y] = spec.start_xy_m;
        let mut yaw = spec.start_yaw_deg.to_radians();
        samples.push([x, y, yaw]);
        for k in 0..steps {
            let t0 = k as f64 * TRACK_STEP_S;
            let (t_mid, t1) = (t0 + TRACK_STEP_S / 2.0, t0 + TRACK_STEP_S);
            // Yaw: trapezoid / Simpson on the piecewise-linear rate (exact inside a segment).
            let rate = |t: f64| profile_at(&yaw_rate_radps, t);
            let yaw_mid = yaw + (rate(t0) + rate(t_mid)) * TRACK_STEP_S / 4.0;
            let yaw_end = yaw + (rate(t0) + 4.0 * rate(t_mid) + rate(t1)) * TRACK_STEP_S / 6.0;
            // Position: Simpson on the velocity.
            let velocity = |t: f64, yaw: f64| {
                let speed = profile_at(&spec.speed_mps, t);
                [speed * yaw.cos(), speed * yaw.sin()]
            };
            let (v0, vm, v1) = (
                velocity(t0, yaw),
                velocity(t_mid, yaw_mid),
                velocity(t1, yaw_end),
            );
            x += (v0[0] + 4.0 * vm[0] + v1[0]) * TRACK_STEP_S / 6.0;
            y += (v0[1] + 4.0 * vm[1] + v1[1]) * TRACK_STEP_S / 6.0;
            yaw = yaw_end;
            samples.push([x, y, yaw]);
        }
        Self {
            speed_mps: spec.speed_mps.clone(),
            yaw_rate_radps,
            imu_z_m: ground_height_m + spec.imu_height_m,
            samples,
        }
    }

    /// The state at `t_s` (clamped to the tabulated span).
    pub fn state(&self, t_s: f64) -> EgoState {
        let last = (self.samples.len() - 2) as f64 * TRACK_STEP_S;
        let t_s = t_s.clamp(0.0, last);
        let k = ((t_s / TRACK_STEP_S).floor() as usize).min(self.samples.len() - 2);
        let t0 = k as f64 * TRACK_STEP_S;
        let u = (t_s - t0) / TRACK_STEP_S;
        let (a, b) = (self.samples[k], self.samples[k + 1]);
        let speed_at = |t: f64| profile_at(&self.speed_mps, t);
        let rate_at = |t: f64| profile_at(&self.yaw_rate_radps, t);
        // Yaw: Hermite with the rates at both ends.
        let yaw = hermite(a[2], b[2], rate_at(t0), rate_at(t0 + TRACK_STEP_S), u);
        let (va, vb) = (
            [speed_at(t0) * a[2].cos(), speed_at(t0) * a[2].sin()],
            [
                speed_at(t0 + TRACK_STEP_S) * b[2].cos(),
                speed_at(t0 + TRACK_STEP_S) * b[2].sin(),
            ],
        );
        let x = hermite(a[0], b[0], va[0], vb[0], u);
        let y = hermite(a[1], b[1], va[1], vb[1], u);
        EgoState {
            position_m: Vector3::new(x, y, self.imu_z_m),
            yaw_rad: yaw,
            speed_mps: speed_at(t_s),
            yaw_rate_radps: rate_at(t_s),
            accel_long_mps2: profile_slope_at(&self.speed_mps, t_s),
        }
    }
}

/// Cubic Hermite between values `a`, `b` with slopes `da`, `db` (per second)
/// over one track step, at fraction `u`.
fn hermite(a: f64, b: f64, da: f64, db: f64, u: f64) -> f64 {
    let (u2, u3) = (u * u, u * u * u);
    let h = TRACK_STEP_S;
    (2.0 * u3 - 3.0 * u2 + 1.0) * a
        + (u3 - 2.0 * u2 + u) * h * da
        + (-2.0 * u3 + 3.0 * u2) * b
        + (u3 - u2) * h * db
}

/// The LiDAR mount: its pose in the vehicle frame.
pub(crate) fn vehicle_from_lidar(mount_xyz_m: [f64; 3], mount_rpy_deg: [f64; 3]) -> Isometry3<f64> {
    let [roll, pitch, yaw] = mount_rpy_deg.map(f64::to_radians);
    let rotation = Rotation3::from_euler_angles(roll, pitch, yaw);
    Isometry3::from_parts(
        Translation3::new(mount_xyz_m[0], mount_xyz_m[1], mount_xyz_m[2]),
        UnitQuaternion::from_rotation_matrix(&rotation),
    )
}

/// The LiDAR's pose and motion at one instant, world frame.
#[derive(Debug, Clone, Copy)]
pub struct LidarState {
    pub world_from_lidar: Isometry3<f64>,
    /// Velocity of the LiDAR origin, world frame (lever arm included).
    pub velocity_world_mps: Vector3<f64>,
    pub angular_velocity_world_radps: Vector3<f64>,
}

impl LidarState {
    pub fn new(ego: &EgoState, vehicle_from_lidar: &Isometry3<f64>) -> Self {
        let world_from_vehicle = ego.world_from_vehicle();
        let lever_world = world_from_vehicle.rotation * vehicle_from_lidar.translation.vector;
        let omega = ego.angular_velocity_world_radps();
        Self {
            world_from_lidar: world_from_vehicle * vehicle_from_lidar,
            velocity_world_mps: ego.velocity_world_mps() + omega.cross(&lever_world),
            angular_velocity_world_radps: omega,
        }
    }

    pub fn origin(&self) -> Point3<f64> {
        Point3::from(self.world_from_lidar.translation.vector)
    }

    /// A world vector in the LiDAR frame.
    pub fn to_lidar(&self, world: &Vector3<f64>) -> Vector3<f64> {
        self.world_from_lidar.rotation.inverse() * world
    }
}

/// Position (x, y) and velocity (vx, vy) of an actor at `t_s`.
pub(crate) fn actor_motion(actor: &Actor, t_s: f64) -> ([f64; 2], [f64; 2]) {
    if let Some(points) = &actor.trajectory {
        return trajectory_motion(points, t_s);
    }
    let start = actor.start_xy_m.unwrap_or_default();
    let velocity = actor.velocity_mps.unwrap_or_default();
    (
        [start[0] + velocity[0] * t_s, start[1] + velocity[1] * t_s],
        velocity,
    )
}

/// Piecewise-linear waypoints `[t, x, y]`, held at the ends.
fn trajectory_motion(points: &[[f64; 3]], t_s: f64) -> ([f64; 2], [f64; 2]) {
    let (first, last) = match (points.first(), points.last()) {
        (Some(first), Some(last)) => (first, last),
        _ => return ([0.0; 2], [0.0; 2]),
    };
    if t_s < first[0] {
        return ([first[1], first[2]], [0.0; 2]);
    }
    for w in points.windows(2) {
        let (a, b) = (w[0], w[1]);
        if t_s < b[0] {
            let dt = b[0] - a[0];
            let velocity = [(b[1] - a[1]) / dt, (b[2] - a[2]) / dt];
            let s = t_s - a[0];
            return ([a[1] + velocity[0] * s, a[2] + velocity[1] * s], velocity);
        }
    }
    ([last[1], last[2]], [0.0; 2])
}

#[cfg(test)]
mod tests {
    use super::*;

    fn ego(speed: f64, yaw_rate_dps: f64) -> EgoSpec {
        EgoSpec {
            start_xy_m: [0.0, 0.0],
            start_yaw_deg: 0.0,
            speed_mps: vec![[0.0, speed]],
            yaw_rate_dps: vec![[0.0, yaw_rate_dps]],
            imu_height_m: 0.83,
        }
    }

    #[test]
    fn a_constant_turn_follows_the_exact_circle() {
        let track = EgoTrack::new(&ego(10.0, 20.0), 0.0, 10.0);
        let omega = 20f64.to_radians();
        let radius = 10.0 / omega;
        for t in [0.0, 0.0123, 1.0, 3.3337, 7.5, 9.9999] {
            let state = track.state(t);
            let exact = [
                radius * (omega * t).sin(),
                radius * (1.0 - (omega * t).cos()),
            ];
            assert!(
                (state.position_m.x - exact[0]).abs() < 1e-7,
                "t {t}: x {} vs {}",
                state.position_m.x,
                exact[0]
            );
            assert!((state.position_m.y - exact[1]).abs() < 1e-7, "t {t}: y");
            assert!((state.yaw_rad - omega * t).abs() < 1e-9);
        }
    }

    #[test]
    fn braking_integrates_the_speed_profile() {
        let spec = EgoSpec {
            speed_mps: vec![[0.0, 12.0], [1.0, 12.0], [3.0, 2.0]],
            ..ego(0.0, 0.0)
        };
        let track = EgoTrack::new(&spec, 0.0, 5.0);
        // 12 m in the first second, then the trapezoid: 2 s at a mean of 7 m/s.
        assert!((track.state(3.0).position_m.x - 26.0).abs() < 1e-6);
        assert!((track.state(2.0).accel_long_mps2 + 5.0).abs() < 1e-12);
        assert!((track.state(4.0).position_m.x - 28.0).abs() < 1e-6);
    }

    #[test]
    fn the_imu_reads_gravity_and_centripetal_acceleration() {
        let track = EgoTrack::new(&ego(10.0, 20.0), 0.0, 2.0);
        let (force, gyro) = track.state(1.0).imu_reading();
        let omega = 20f64.to_radians();
        assert!((force.z - GRAVITY_MPS2).abs() < 1e-12);
        assert!(
            (force.y - 10.0 * omega).abs() < 1e-9,
            "centripetal {force:?}"
        );
        assert!(force.x.abs() < 1e-9);
        assert!((gyro.z - omega).abs() < 1e-12);
    }

    #[test]
    fn the_lidar_velocity_includes_the_lever_arm() {
        let track = EgoTrack::new(&ego(10.0, 20.0), 0.0, 1.0);
        let mount = vehicle_from_lidar([1.0, 0.0, 1.0], [0.0, 0.0, 0.0]);
        let lidar = LidarState::new(&track.state(0.0), &mount);
        // omega x (1, 0, 1) = (0, omega, 0): a sideways component.
        let omega = 20f64.to_radians();
        assert!((lidar.velocity_world_mps - Vector3::new(10.0, omega, 0.0)).norm() < 1e-12);
    }

    #[test]
    fn trajectories_interpolate_and_hold() {
        let actor: Actor =
            serde_json::from_str(r#"{"id": 1, "trajectory": [[1, 0, 0], [3, 10, 4]]}"#).unwrap();
        assert_eq!(actor_motion(&actor, 0.0), ([0.0, 0.0], [0.0, 0.0]));
        assert_eq!(actor_motion(&actor, 2.0), ([5.0, 2.0], [5.0, 2.0]));
        assert_eq!(actor_motion(&actor, 4.0), ([10.0, 4.0], [0.0, 0.0]));
    }
}
