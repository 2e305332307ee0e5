//! The motion messages: `/imu/data` (with seeded noise), `/vehicle/twist`,
//! `/odom`, and the LiDAR mount on `/tf_static`.

use nalgebra::{UnitQuaternion, Vector3};
use rand::SeedableRng;
use rand_distr::{Distribution, Normal};

use crate::ros::msgs::{
    Header, Imu, Odometry, Pose, PoseWithCovariance, Quaternion, TFMessage, Transform,
    TransformStamped, Twist, TwistStamped, TwistWithCovariance, Vector3 as RosVector3,
};
use crate::synth::rig::RigLidar;
use crate::synth::sensor::World;

use super::{ODOM_FRAME, VEHICLE_FRAME, stamp_ns};

/// `/imu/data` at `t_s`: gyro and specific force in the vehicle frame, with
/// seeded Gaussian noise (a generator per sample index: order independent).
pub(super) fn imu_message(world: &World, t_s: f64, index: u64, seed: u64) -> Imu {
    let ego = world.track.state(t_s);
    let (mut force, mut gyro) = ego.imu_reading();
    let spec = &world.scenario.imu;
    let mut rng = rand_chacha::ChaCha8Rng::seed_from_u64(
        seed ^ 0x1A2B_3C4D ^ index.wrapping_mul(0xD1B5_4A32_D192_ED03),
    );
    if let (Ok(gyro_noise), Ok(accel_noise)) = (
        Normal::new(0.0, spec.gyro_noise_radps.max(0.0)),
        Normal::new(0.0, spec.accel_noise_mps2.max(0.0)),
    ) {
        for c in gyro.iter_mut() {
            *c += gyro_noise.sample(&mut rng);
        }
        for c in force.iter_mut() {
            *c += accel_noise.sample(&mut rng);
        }
    }
    let orientation = UnitQuaternion::from_axis_angle(&Vector3::z_axis(), ego.yaw_rad);
    let diagonal = |v: f64| [v, 0.0, 0.0, 0.0, v, 0.0, 0.0, 0.0, v];
    Imu {
        header: Header::new(stamp_ns(t_s), VEHICLE_FRAME),
        orientation: Quaternion::from(&orientation),
        orientation_covariance: diagonal(1e-4),
        angular_velocity: RosVector3::from(&gyro),
        angular_velocity_covariance: diagonal(spec.gyro_noise_radps.powi(2)),
        linear_acceleration: RosVector3::from(&force),
        linear_acceleration_covariance: diagonal(spec.accel_noise_mps2.powi(2)),
    }
}

/// `/vehicle/twist` and `/odom` at `t_s`, exact, in the vehicle frame.
pub(super) fn velocity_messages(world: &World, t_s: f64) -> (TwistStamped, Odometry) {
    let ego = world.track.state(t_s);
    let twist = Twist {
        linear: RosVector3::new(ego.speed_mps, 0.0, 0.0),
        angular: RosVector3::new(0.0, 0.0, ego.yaw_rate_radps),
    };
    let orientation = UnitQuaternion::from_axis_angle(&Vector3::z_axis(), ego.yaw_rad);
    let odometry = Odometry {
        header: Header::new(stamp_ns(t_s), ODOM_FRAME),
        child_frame_id: VEHICLE_FRAME.into(),
        pose: PoseWithCovariance {
            pose: Pose {
                position: RosVector3::from(&ego.position_m),
                orientation: Quaternion::from(&orientation),
            },
            covariance: [0.0; 36],
        },
        twist: TwistWithCovariance {
            twist,
            covariance: [0.0; 36],
        },
    };
    (
        TwistStamped {
            header: Header::new(stamp_ns(t_s), VEHICLE_FRAME),
            twist,
        },
        odometry,
    )
}

/// The vehicle's pose in the world frame at `t_s` (what `/odom` says).
pub(super) fn world_from_vehicle(world: &World, t_s: f64) -> nalgebra::Isometry3<f64> {
    let ego = world.track.state(t_s);
    nalgebra::Isometry3::from_parts(
        nalgebra::Translation3::from(ego.position_m),
        UnitQuaternion::from_axis_angle(&Vector3::z_axis(), ego.yaw_rad),
    )
}

/// `/tf` at `t_s`: `odom -> imu_link`, the vehicle's pose in the world.
pub(super) fn world_tf(world: &World, t_s: f64) -> TFMessage {
    let pose = world_from_vehicle(world, t_s);
    TFMessage {
        transforms: vec![TransformStamped {
            header: Header::new(stamp_ns(t_s), ODOM_FRAME),
            child_frame_id: VEHICLE_FRAME.into(),
            transform: Transform {
                translation: RosVector3::from(&pose.translation.vector),
                rotation: Quaternion::from(&pose.rotation),
            },
        }],
    }
}

/// `/tf_static`: the mount of each LiDAR of the rig in the vehicle/IMU frame.
pub(super) fn tf_static(rig: &[RigLidar], start_s: f64) -> TFMessage {
    TFMessage {
        transforms: rig
            .iter()
            .map(|lidar| {
                let mount = &lidar.world.vehicle_from_lidar;
                TransformStamped {
                    header: Header::new(stamp_ns(start_s), VEHICLE_FRAME),
                    child_frame_id: lidar.name.clone(),
                    transform: Transform {
                        translation: RosVector3::from(&mount.translation.vector),
                        rotation: Quaternion::from(&mount.rotation),
                    },
                }
            })
            .collect(),
    }
}
