//! The ego vehicle's corridor: the band of `half_width_m` either side of its
//! path, extended along the path ahead and behind. Looming measures approach
//! to the *plane* of a surface, whatever its lateral offset (a parked car's
//! face beside the road looms as much as a car ahead), so an event needs its
//! object in the path, not only a short time to contact.

use nalgebra::Vector3;

/// Below this speed the direction of travel is unknown: the LiDAR's x axis
/// stands for it.
const MIN_SPEED_FOR_HEADING_MPS: f64 = 0.5;
/// Path length sampled either side of the sensor, metres.
const REACH_M: f64 = 120.0;
/// Spacing of the path samples, metres.
const STEP_M: f64 = 0.5;

/// How the corridor's path was found.
#[derive(Debug, Clone, Copy, PartialEq, Eq, serde::Serialize, serde::Deserialize)]
#[serde(rename_all = "snake_case")]
pub enum PathSource {
    /// The arc of the LiDAR's velocity and yaw rate.
    EgoMotion,
    /// No usable velocity: the LiDAR's x axis, straight.
    LidarXAxis,
}

/// The ego path in the LiDAR frame (horizontal plane) and the band around it.
#[derive(Debug, Clone)]
pub struct Corridor {
    /// Path samples (x, y), metres, ordered along the path.
    path_xy: Vec<[f64; 2]>,
    half_width_m: f64,
    pub source: PathSource,
}

impl Corridor {
    /// The arc of constant speed and yaw rate through the sensor, tangent to
    /// the horizontal velocity (the x axis when slower than 0.5 m/s).
    pub fn new(
        velocity_mps: Option<Vector3<f64>>,
        angular_velocity_radps: Option<Vector3<f64>>,
        half_width_m: f64,
    ) -> Self {
        let speed_xy = velocity_mps.map_or(0.0, |v| v.x.hypot(v.y));
        let (heading_rad, curvature_per_m, source) = match velocity_mps {
            Some(v) if speed_xy >= MIN_SPEED_FOR_HEADING_MPS => {
                let yaw_rate = angular_velocity_radps.map_or(0.0, |w| w.z);
                (v.y.atan2(v.x), yaw_rate / speed_xy, PathSource::EgoMotion)
            }
            _ => (0.0, 0.0, PathSource::LidarXAxis),
        };
        let steps = (REACH_M / STEP_M) as i64;
        let path_xy = (-steps..=steps)
            .map(|k| arc_point(heading_rad, curvature_per_m, k as f64 * STEP_M))
            .collect();
        Self {
            path_xy,
            half_width_m,
            source,
        }
    }

    /// Horizontal distance of a point from the path, metres.
    pub fn offset_m(&self, p: &Vector3<f64>) -> f64 {
        self.path_xy
            .windows(2)
            .map(|w| segment_distance([p.x, p.y], w[0], w[1]))
            .fold(f64::INFINITY, f64::min)
    }

    pub fn contains(&self, p: &Vector3<f64>) -> bool {
        self.offset_m(p) <= self.half_width_m
    }
}

/// The point at arc length `s` of the path leaving the origin with `heading`
/// and constant `curvature` (left positive).
fn arc_point(heading_rad: f64, curvature_per_m: f64, s_m: f64) -> [f64; 2] {
    if curvature_per_m.abs() < 1e-9 {
        return [s_m * heading_rad.cos(), s_m * heading_rad.sin()];
    }
    let turned = heading_rad + curvature_per_m * s_m;
    [
        (turned.sin() - heading_rad.sin()) / curvature_per_m,
        (heading_rad.cos() - turned.cos()) / curvature_per_m,
    ]
}

fn segment_distance(p: [f64; 2], a: [f64; 2], b: [f64; 2]) -> f64 {
    let (abx, aby) = (b[0] - a[0], b[1] - a[1]);
    let (apx, apy) = (p[0] - a[0], p[1] - a[1]);
    let len2 = abx * abx + aby * aby;
    let t = if len2 > 0.0 {
        ((apx * abx + apy * aby) / len2).clamp(0.0, 1.0)
    } else {
        0.0
    };
    (apx - t * abx).hypot(apy - t * aby)
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn a_straight_path_is_a_band_ahead_and_behind() {
        let corridor = Corridor::new(Some(Vector3::new(10.0, 0.0, 0.0)), None, 2.0);
        assert_eq!(corridor.source, PathSource::EgoMotion);
        assert!((corridor.offset_m(&Vector3::new(30.0, 1.5, 0.4)) - 1.5).abs() < 1e-9);
        assert!(corridor.contains(&Vector3::new(-10.0, -1.9, 0.0)));
        assert!(!corridor.contains(&Vector3::new(20.0, 2.6, 0.0)));
    }

    #[test]
    fn a_turning_path_follows_its_circle() {
        // 10 m/s at 0.349 rad/s: a circle of radius 28.65 m around (0, 28.65).
        let corridor = Corridor::new(
            Some(Vector3::new(10.0, 0.0, 0.0)),
            Some(Vector3::new(0.0, 0.0, 0.349)),
            2.0,
        );
        let radius = 10.0 / 0.349;
        for angle in [0.3f64, 1.0, 2.0] {
            let on_circle = Vector3::new(radius * angle.sin(), radius - radius * angle.cos(), 0.0);
            assert!(corridor.offset_m(&on_circle) < 0.01);
            let outside =
                on_circle + (on_circle - Vector3::new(0.0, radius, 0.0)).normalize() * 4.0;
            assert!((corridor.offset_m(&outside) - 4.0).abs() < 0.01);
        }
        // Straight ahead 40 m is far off a 28.65 m circle.
        assert!(!corridor.contains(&Vector3::new(40.0, 0.0, 0.0)));
    }

    #[test]
    fn without_speed_the_x_axis_stands_for_the_path() {
        let corridor = Corridor::new(Some(Vector3::new(0.1, 0.3, 0.0)), None, 2.0);
        assert_eq!(corridor.source, PathSource::LidarXAxis);
        assert!(corridor.contains(&Vector3::new(15.0, 1.0, 0.0)));
        assert!(!Corridor::new(None, None, 2.0).contains(&Vector3::new(5.0, 3.0, 0.0)));
    }
}
