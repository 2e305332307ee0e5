//! The LiDAR's motion over a pair, integrated from the motion series into
//! poses relative to the LiDAR frame at a reference time, so that a point
//! measured at one time can be expressed in the frame of another.

use nalgebra::{Isometry3, Translation3, UnitQuaternion, Vector3};

use crate::model::PairMotion;
use crate::model::StampNs;

/// Integration step, ns.
const STEP_NS: i64 = 1_000_000;

/// Which motion to integrate.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub(crate) enum MotionModel {
    /// Rotation only (gyro): de-rotates a scan without moving it.
    RotationOnly,
    /// Rotation and translation: the full ego motion.
    Full,
}

/// Poses `reference_from_lidar(t)` on a fine time grid.
#[derive(Debug, Clone)]
pub(crate) struct Trajectory {
    start_ns: StampNs,
    poses: Vec<Isometry3<f64>>,
}

impl Trajectory {
    /// Integrate over [start_ns, end_ns]. `None` when the model needs a quantity
    /// the motion does not have there. Rotation-only without an angular rate is
    /// the identity (no compensation).
    pub fn integrate(
        motion: &PairMotion,
        model: MotionModel,
        rotate: bool,
        start_ns: StampNs,
        end_ns: StampNs,
    ) -> Option<Self> {
        let steps = ((end_ns - start_ns).max(0) / STEP_NS + 2) as usize;
        let angular_at = |t: StampNs| -> Vector3<f64> {
            if rotate {
                motion.angular_velocity_at(t).unwrap_or_else(Vector3::zeros)
            } else {
                Vector3::zeros()
            }
        };
        let mut poses = Vec::with_capacity(steps + 1);
        let mut pose = Isometry3::identity();
        poses.push(pose);
        let dt_s = STEP_NS as f64 * 1e-9;
        for k in 0..steps {
            let t_mid = start_ns + k as i64 * STEP_NS + STEP_NS / 2;
            let omega = angular_at(t_mid);
            let half_turn = UnitQuaternion::from_scaled_axis(omega * (dt_s / 2.0));
            let velocity = match model {
                MotionModel::RotationOnly => Vector3::zeros(),
                MotionModel::Full => motion.velocity_at(t_mid)?,
            };
            // Midpoint rule: translate along the velocity seen at mid-step.
            let mid_rotation = pose.rotation * half_turn;
            let translation = pose.translation.vector + mid_rotation * (velocity * dt_s);
            let rotation = mid_rotation * half_turn;
            pose = Isometry3::from_parts(Translation3::from(translation), rotation);
            poses.push(pose);
        }
        Some(Self { start_ns, poses })
    }

    /// `reference_from_lidar` at `t_ns` (clamped to the integrated span).
    pub fn pose(&self, t_ns: StampNs) -> Isometry3<f64> {
        let offset = (t_ns - self.start_ns).max(0) as f64 / STEP_NS as f64;
        let k = (offset.floor() as usize).min(self.poses.len() - 2);
        let u = (offset - k as f64).clamp(0.0, 1.0);
        let (a, b) = (&self.poses[k], &self.poses[k + 1]);
        Isometry3::from_parts(
            Translation3::from(a.translation.vector.lerp(&b.translation.vector, u)),
            // Normalised linear interpolation: over one 1 ms step the poses
            // turn by milliradians, where it departs from the spherical one
            // by some 1e-10 rad and costs no trigonometry (this runs for
            // every column of every render).
            a.rotation.nlerp(&b.rotation, u),
        )
    }

    /// The transform taking points measured at `from_ns` into the LiDAR frame
    /// at `to_ns` (the renders' transform cache is checked against it).
    #[cfg(test)]
    pub(crate) fn relative(&self, from_ns: StampNs, to_ns: StampNs) -> Isometry3<f64> {
        self.pose(to_ns).inverse() * self.pose(from_ns)
    }
}
