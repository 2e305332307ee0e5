//! The ego vehicle's corridor: the band of `half_width_m` either side of its
//! path, extended along the path ahead and behind. Looming measures approach
//! to the *plane* of a surface, whatever its lateral offset (a parked car's
//! face beside the road looms as much as a car ahead), so an event needs its
//! object in the path, not only a short time to contact.

use nalgebra::Vector3;

/// Below this speed the direction of travel is unknown: the LiDAR's x axis
/// stands for it.
const MIN_SPEED_FOR_HEADING_MPS: f64 = 0.5;
/// Path length either side of the sensor, metres.
const REACH_M: f64 = 120.0;

/// How the corridor's path was found.
#[derive(Debug, Clone, Copy, PartialEq, Eq, serde::Serialize, serde::Deserialize)]
#[serde(rename_all = "snake_case")]
pub enum PathSource {
    /// The arc of the LiDAR's velocity and yaw rate.
    EgoMotion,
    /// No usable velocity: the LiDAR's x axis, straight.
    LidarXAxis,
}

/// The ego path in the LiDAR frame (horizontal plane) and the band around it:
/// the arc through the sensor tangent to its heading with constant
/// `curvature_per_m` (left positive), `REACH_M` long either way.
#[derive(Debug, Clone)]
pub struct Corridor {
    /// The heading's sine and cosine, taken once (`offset_m` runs for
    /// every cell of every hot cluster).
    heading_sin_cos: (f64, f64),
    curvature_per_m: f64,
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
        Self {
            heading_sin_cos: heading_rad.sin_cos(),
            curvature_per_m,
            half_width_m,
            source,
        }
    }

    /// Horizontal distance of a point from the path, metres, in closed form:
    /// from the line, or from the circle when the point's foot lies on the
    /// arc; else from the nearer end.
    pub fn offset_m(&self, p: &Vector3<f64>) -> f64 {
        // Path-aligned coordinates: `along` the heading, `left` of it.
        let (sin, cos) = self.heading_sin_cos;
        let along = p.x * cos + p.y * sin;
        let left = -p.x * sin + p.y * cos;
        let k = self.curvature_per_m;
        if k.abs() < 1e-9 {
            // `sqrt` of the squares, not libm's `hypot` (whose overflow
            // guards metres never need): this runs for every return of a
            // hot cluster's object.
            let beyond = along - along.clamp(-REACH_M, REACH_M);
            return (beyond * beyond + left * left).sqrt();
        }
        // The circle's centre is at (0, 1/k); the path point at arc length s
        // is (sin(ks)/k, (1 - cos(ks))/k).
        let (du, dv) = (along, left - 1.0 / k);
        let from_circle_m = ((du * du + dv * dv).sqrt() - 1.0 / k.abs()).abs();
        // The arc to the point's foot is at most pi times the point's
        // distance from the sensor (the chord to the foot is at most twice
        // that distance, and an arc at most pi/2 times its chord), so near
        // points need no angle (this runs for every cell of every cluster).
        if std::f64::consts::PI * (along * along + left * left).sqrt() <= REACH_M {
            return from_circle_m;
        }
        let arc_m = (du * k).atan2(-dv * k) / k;
        if arc_m.abs() <= REACH_M {
            return from_circle_m;
        }
        [-REACH_M, REACH_M]
            .iter()
            .map(|&s| {
                let end = [(k * s).sin() / k, (1.0 - (k * s).cos()) / k];
                (along - end[0]).hypot(left - end[1])
            })
            .fold(f64::INFINITY, f64::min)
    }

    pub fn contains(&self, p: &Vector3<f64>) -> bool {
        self.offset_m(p) <= self.half_width_m
    }
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
    fn beyond_its_reach_the_path_ends() {
        // 10 m/s at 0.01 rad/s: a 1 km radius, so 120 m of arc is a small part.
        let corridor = Corridor::new(
            Some(Vector3::new(10.0, 0.0, 0.0)),
            Some(Vector3::new(0.0, 0.0, 0.01)),
            2.0,
        );
        let (k, s) = (0.001_f64, REACH_M);
        let end = Vector3::new((k * s).sin() / k, (1.0 - (k * s).cos()) / k, 0.0);
        let beyond = end + Vector3::new((k * s).cos(), (k * s).sin(), 0.0) * 30.0;
        assert!((corridor.offset_m(&beyond) - 30.0).abs() < 0.05);
        let straight = Corridor::new(Some(Vector3::new(10.0, 0.0, 0.0)), None, 2.0);
        assert!((straight.offset_m(&Vector3::new(150.0, 0.0, 0.0)) - 30.0).abs() < 1e-9);
    }

    #[test]
    fn without_speed_the_x_axis_stands_for_the_path() {
        let corridor = Corridor::new(Some(Vector3::new(0.1, 0.3, 0.0)), None, 2.0);
        assert_eq!(corridor.source, PathSource::LidarXAxis);
        assert!(corridor.contains(&Vector3::new(15.0, 1.0, 0.0)));
        assert!(!Corridor::new(None, None, 2.0).contains(&Vector3::new(5.0, 3.0, 0.0)));
    }
}
