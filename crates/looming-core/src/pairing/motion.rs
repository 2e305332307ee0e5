//! Ego motion of the LiDAR over a scan pair: the frame change of velocity and
//! gyro samples into the LiDAR frame (pure math) and time series with
//! interpolation that the looming engine queries at per-point times.

use nalgebra::{Isometry3, Vector3};

use crate::model::{AngularSource, ExtrinsicInfo, PairMotion, StampNs, TimeSeries};

/// Angular velocity of the LiDAR in its own frame: `w_L = R^T w_M`, with
/// `R` the rotation of `motion_from_lidar`. Angular velocity is the same
/// for every point of a rigid body, so no lever-arm term appears.
pub(crate) fn angular_velocity_in_lidar(
    motion_from_lidar: &Isometry3<f64>,
    angular_motion_radps: &Vector3<f64>,
) -> Vector3<f64> {
    motion_from_lidar.rotation.inverse() * angular_motion_radps
}

/// Velocity of the LiDAR origin in the LiDAR frame from a body twist given at
/// the motion frame's origin: `v_L = R^T (v_M + w_M x l) = R^T v_M + w_L x (R^T l)`,
/// with `l` the LiDAR origin in the motion frame. Taking `w_L` as a parameter
/// lets the caller use its best angular velocity (the gyro) for the lever arm.
pub(crate) fn lidar_velocity_from_twist(
    motion_from_lidar: &Isometry3<f64>,
    linear_motion_mps: &Vector3<f64>,
    angular_lidar_radps: &Vector3<f64>,
) -> Vector3<f64> {
    let lidar_from_motion_rotation = motion_from_lidar.rotation.inverse();
    let lever_arm_lidar_m = lidar_from_motion_rotation * motion_from_lidar.translation.vector;
    lidar_from_motion_rotation * linear_motion_mps + angular_lidar_radps.cross(&lever_arm_lidar_m)
}

/// A velocity (twist) sample as the pairer buffers it, in its own frame.
#[derive(Debug, Clone, Copy, PartialEq)]
pub(crate) struct TwistSample {
    pub stamp_ns: StampNs,
    pub linear_mps: Vector3<f64>,
    pub angular_radps: Vector3<f64>,
}

/// A gyro sample as the pairer buffers it, in the IMU frame.
#[derive(Debug, Clone, Copy, PartialEq)]
pub(crate) struct GyroSample {
    pub stamp_ns: StampNs,
    pub angular_velocity_radps: Vector3<f64>,
}

/// Everything [`build_pair_motion`] needs; samples are those near the pair.
#[derive(Debug, Clone)]
pub(crate) struct MotionInputs<'a> {
    /// `(samples, LiDAR pose in their frame)`; `None` when there is no velocity source.
    pub twists: Option<(&'a [TwistSample], ExtrinsicInfo)>,
    /// `(samples, LiDAR pose in their frame)`; `None` when there is no IMU source.
    pub gyro: Option<(&'a [GyroSample], ExtrinsicInfo)>,
    pub hold_s: f64,
    pub coverage_complete: bool,
}

/// Expresses the samples of a pair in the LiDAR frame. The angular velocity
/// comes from the gyro when there are IMU samples, else from the twist; the
/// lever-arm term of the velocity uses that same best angular velocity.
pub(crate) fn build_pair_motion(inputs: MotionInputs<'_>) -> PairMotion {
    let gyro = inputs.gyro.filter(|(samples, _)| !samples.is_empty());
    let twists = inputs.twists.filter(|(samples, _)| !samples.is_empty());

    let gyro_series = gyro.as_ref().map(|(samples, extrinsic)| {
        let rotated = samples
            .iter()
            .map(|s| {
                let w = angular_velocity_in_lidar(
                    &extrinsic.motion_from_lidar,
                    &s.angular_velocity_radps,
                );
                (s.stamp_ns, w)
            })
            .collect();
        TimeSeries::new(rotated, inputs.hold_s)
    });

    let twist_series = twists.as_ref().map(|(samples, extrinsic)| {
        let pose = &extrinsic.motion_from_lidar;
        let mut velocity = Vec::with_capacity(samples.len());
        let mut angular = Vec::with_capacity(samples.len());
        for s in samples.iter() {
            let twist_angular_lidar = angular_velocity_in_lidar(pose, &s.angular_radps);
            let best_angular_lidar = gyro_series
                .as_ref()
                .and_then(|series| series.at(s.stamp_ns))
                .unwrap_or(twist_angular_lidar);
            velocity.push((
                s.stamp_ns,
                lidar_velocity_from_twist(pose, &s.linear_mps, &best_angular_lidar),
            ));
            angular.push((s.stamp_ns, twist_angular_lidar));
        }
        (
            TimeSeries::new(velocity, inputs.hold_s),
            TimeSeries::new(angular, inputs.hold_s),
        )
    });

    let (velocity, twist_angular) = match twist_series {
        Some((velocity, angular)) => (Some(velocity), Some(angular)),
        None => (None, None),
    };
    let (angular, angular_source) = match (gyro_series, twist_angular) {
        (Some(series), _) => (Some(series), AngularSource::Imu),
        (None, Some(series)) => (Some(series), AngularSource::Twist),
        (None, None) => (None, AngularSource::Unavailable),
    };
    PairMotion {
        velocity_unavailable: velocity.is_none(),
        imu_unavailable: angular_source != AngularSource::Imu,
        velocity,
        angular,
        angular_source,
        velocity_extrinsic: twists.map(|(_, extrinsic)| extrinsic),
        imu_extrinsic: gyro.map(|(_, extrinsic)| extrinsic),
        coverage_complete: inputs.coverage_complete,
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::model::ExtrinsicSource;
    use std::f64::consts::{FRAC_PI_2, PI};

    const MS: i64 = 1_000_000;

    #[test]
    fn walking_from_a_hint_reads_what_bisection_reads() {
        // Uneven stamps, a repeated one and a gap beyond interpolation.
        let stamps = [0, 10, 10, 25, 40, 400, 410, 430];
        let series = TimeSeries::new(
            stamps
                .iter()
                .enumerate()
                .map(|(k, &t)| (t * MS, Vector3::new(k as f64, -(k as f64), 0.5)))
                .collect(),
            0.05,
        );
        let mut hint = 0;
        // Forwards, backwards and jumping, hint carried along.
        let times: Vec<i64> = (-100..600)
            .step_by(7)
            .chain((-100..600).rev().step_by(13))
            .chain([500, -50, 12, 420, 10, 0, 430, 431])
            .collect();
        for t in times {
            let expected = series.at(t * MS);
            assert_eq!(series.at_near(t * MS, &mut hint), expected, "at {t} ms");
        }
        for start in 0..12 {
            let mut hint = start;
            assert_eq!(series.at_near(25 * MS, &mut hint), series.at(25 * MS));
        }
    }

    fn assert_vec_close(actual: Vector3<f64>, expected: [f64; 3]) {
        let expected = Vector3::from(expected);
        assert!(
            (actual - expected).norm() < 1e-12,
            "{actual:?} != {expected:?}"
        );
    }

    fn yaw(angle_rad: f64) -> Isometry3<f64> {
        Isometry3::rotation(Vector3::z() * angle_rad)
    }

    fn extrinsic(motion_from_lidar: Isometry3<f64>) -> ExtrinsicInfo {
        ExtrinsicInfo {
            lidar_frame: "lidar".into(),
            motion_frame: "base_link".into(),
            motion_from_lidar,
            source: ExtrinsicSource::TfStatic,
        }
    }

    #[test]
    fn pure_yaw_with_lidar_one_metre_ahead_of_rear_axle_moves_it_left() {
        // Rear axle frame, LiDAR 1 m ahead, no rotation; 5 m/s forward, 0.5 rad/s left turn.
        let pose = Isometry3::translation(1.0, 0.0, 0.0);
        let w_lidar = angular_velocity_in_lidar(&pose, &Vector3::new(0.0, 0.0, 0.5));
        assert_vec_close(w_lidar, [0.0, 0.0, 0.5]);
        let v = lidar_velocity_from_twist(&pose, &Vector3::new(5.0, 0.0, 0.0), &w_lidar);
        // w x l = (0,0,0.5) x (1,0,0) = (0,0.5,0): the nose swings left.
        assert_vec_close(v, [5.0, 0.5, 0.0]);
    }

    #[test]
    fn rotated_mount_rotates_velocity_into_lidar_axes() {
        // LiDAR yawed 90 deg left: its x is the body's y. Forward body motion is -y for it.
        let pose = yaw(FRAC_PI_2);
        let v = lidar_velocity_from_twist(&pose, &Vector3::new(1.0, 0.0, 0.0), &Vector3::zeros());
        assert_vec_close(v, [0.0, -1.0, 0.0]);
    }

    #[test]
    fn lever_arm_with_rotated_mount() {
        // LiDAR 1 m ahead, yawed 90 deg; body spins at 1 rad/s without translating.
        // Origin velocity in the body frame = w x l = (0,1,0), i.e. LiDAR +x.
        let pose = Isometry3::translation(1.0, 0.0, 0.0) * yaw(FRAC_PI_2);
        let w_lidar = angular_velocity_in_lidar(&pose, &Vector3::new(0.0, 0.0, 1.0));
        assert_vec_close(w_lidar, [0.0, 0.0, 1.0]);
        let v = lidar_velocity_from_twist(&pose, &Vector3::zeros(), &w_lidar);
        assert_vec_close(v, [1.0, 0.0, 0.0]);
    }

    #[test]
    fn upside_down_imu_flips_the_yaw_rate() {
        let imu_from_lidar = Isometry3::rotation(Vector3::x() * PI);
        let w = angular_velocity_in_lidar(&imu_from_lidar, &Vector3::new(0.0, 0.0, 1.0));
        assert_vec_close(w, [0.0, 0.0, -1.0]);
    }

    fn series(hold_s: f64) -> TimeSeries {
        TimeSeries::new(
            vec![
                (200 * MS, Vector3::new(3.0, 0.0, -2.0)),
                (100 * MS, Vector3::new(1.0, 0.0, 0.0)),
            ],
            hold_s,
        )
    }

    #[test]
    fn interpolation_is_exact_at_and_between_samples() {
        let s = series(0.2);
        assert_vec_close(s.at(100 * MS).unwrap(), [1.0, 0.0, 0.0]);
        assert_vec_close(s.at(200 * MS).unwrap(), [3.0, 0.0, -2.0]);
        assert_vec_close(s.at(150 * MS).unwrap(), [2.0, 0.0, -1.0]);
        assert_vec_close(s.at(125 * MS).unwrap(), [1.5, 0.0, -0.5]);
    }

    #[test]
    fn hold_beyond_the_ends_is_bounded_by_the_tolerance() {
        let s = series(0.2);
        assert_vec_close(s.at(-100 * MS).unwrap(), [1.0, 0.0, 0.0]);
        assert!(s.at(-100 * MS - 1).is_none());
        assert_vec_close(s.at(400 * MS).unwrap(), [3.0, 0.0, -2.0]);
        assert!(s.at(400 * MS + 1).is_none());
        assert!(series(0.0).at(99 * MS).is_none());
        assert!(TimeSeries::new(Vec::new(), 1.0).at(0).is_none());
    }

    #[test]
    fn long_dropout_is_held_from_each_side_not_bridged() {
        let s = TimeSeries::new(
            vec![
                (0, Vector3::new(1.0, 0.0, 0.0)),
                (3_000 * MS, Vector3::new(7.0, 0.0, 0.0)),
            ],
            0.2,
        );
        assert_vec_close(s.at(150 * MS).unwrap(), [1.0, 0.0, 0.0]);
        assert_vec_close(s.at(2_900 * MS).unwrap(), [7.0, 0.0, 0.0]);
        assert!(s.at(1_500 * MS).is_none());
    }

    #[test]
    fn equal_stamps_keep_the_later_sample() {
        let s = TimeSeries::new(
            vec![
                (0, Vector3::new(1.0, 0.0, 0.0)),
                (0, Vector3::new(2.0, 0.0, 0.0)),
            ],
            0.1,
        );
        assert_vec_close(s.at(0).unwrap(), [2.0, 0.0, 0.0]);
    }

    fn twist(stamp_ns: StampNs, forward_mps: f64, yaw_radps: f64) -> TwistSample {
        TwistSample {
            stamp_ns,
            linear_mps: Vector3::new(forward_mps, 0.0, 0.0),
            angular_radps: Vector3::new(0.0, 0.0, yaw_radps),
        }
    }

    #[test]
    fn gyro_is_preferred_for_angular_velocity_and_the_lever_arm() {
        let twists = [twist(0, 5.0, 0.5), twist(100 * MS, 5.0, 0.5)];
        let gyro = [
            GyroSample {
                stamp_ns: 0,
                angular_velocity_radps: Vector3::new(0.0, 0.0, 1.0),
            },
            GyroSample {
                stamp_ns: 100 * MS,
                angular_velocity_radps: Vector3::new(0.0, 0.0, 1.0),
            },
        ];
        let motion = build_pair_motion(MotionInputs {
            twists: Some((&twists, extrinsic(Isometry3::translation(1.0, 0.0, 0.0)))),
            gyro: Some((&gyro, extrinsic(Isometry3::identity()))),
            hold_s: 0.2,
            coverage_complete: true,
        });
        assert_eq!(motion.angular_source, AngularSource::Imu);
        assert!(!motion.velocity_unavailable && !motion.imu_unavailable);
        assert_vec_close(
            motion.angular_velocity_at(50 * MS).unwrap(),
            [0.0, 0.0, 1.0],
        );
        // Lever arm from the gyro's 1 rad/s, not the twist's 0.5.
        assert_vec_close(motion.velocity_at(50 * MS).unwrap(), [5.0, 1.0, 0.0]);
        let sample = motion.motion_at(50 * MS).unwrap();
        assert_eq!(sample.stamp_ns, 50 * MS);
    }

    #[test]
    fn without_imu_angular_comes_from_the_twist() {
        let twists = [twist(0, 5.0, 0.5)];
        let motion = build_pair_motion(MotionInputs {
            twists: Some((&twists, extrinsic(Isometry3::translation(1.0, 0.0, 0.0)))),
            gyro: None,
            hold_s: 0.2,
            coverage_complete: false,
        });
        assert_eq!(motion.angular_source, AngularSource::Twist);
        assert!(motion.imu_unavailable);
        assert!(motion.imu_extrinsic.is_none());
        assert_vec_close(motion.angular_velocity_at(0).unwrap(), [0.0, 0.0, 0.5]);
        assert_vec_close(motion.velocity_at(0).unwrap(), [5.0, 0.5, 0.0]);
    }

    #[test]
    fn nothing_available_gives_none_everywhere() {
        let motion = build_pair_motion(MotionInputs {
            twists: Some((&[], extrinsic(Isometry3::identity()))),
            gyro: None,
            hold_s: 0.2,
            coverage_complete: true,
        });
        assert!(motion.velocity_unavailable && motion.imu_unavailable);
        assert_eq!(motion.angular_source, AngularSource::Unavailable);
        assert!(motion.velocity_extrinsic.is_none());
        assert!(motion.velocity_at(0).is_none() && motion.angular_velocity_at(0).is_none());
        assert!(motion.motion_at(0).is_none());
    }
}
