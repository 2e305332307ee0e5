//! Threat levels from looming thresholds given as times to contact, and the
//! paper's equal-looming spheres: static points with `L >= L_k` under ego
//! velocity `t` lie inside the sphere through the sensor with centre
//! `t / (2 L_k)` and radius `|t| / (2 L_k)`.

use nalgebra::Vector3;

/// Threat of a cell or point.
#[derive(Debug, Clone, Copy, PartialEq, Eq, PartialOrd, Ord, Default, serde::Serialize)]
#[serde(rename_all = "snake_case")]
#[repr(u8)]
pub enum ThreatLevel {
    #[default]
    None = 0,
    Low = 1,
    Medium = 2,
    High = 3,
}

impl ThreatLevel {
    /// Level of a looming value against `[low, medium, high]` times to contact (s).
    pub fn of(looming_per_s: f64, ttc_s: &[f64; 3]) -> Self {
        if looming_per_s.is_nan() || looming_per_s <= 0.0 {
            return ThreatLevel::None;
        }
        let ttc = 1.0 / looming_per_s;
        if ttc <= ttc_s[2] {
            ThreatLevel::High
        } else if ttc <= ttc_s[1] {
            ThreatLevel::Medium
        } else if ttc <= ttc_s[0] {
            ThreatLevel::Low
        } else {
            ThreatLevel::None
        }
    }
}

/// One equal-looming sphere, LiDAR frame.
#[derive(Debug, Clone, Copy, PartialEq, serde::Serialize)]
pub struct ThreatSphere {
    pub level: ThreatLevel,
    /// `L_k = 1 / ttc_k`, 1/s.
    pub looming_per_s: f64,
    pub center_m: [f64; 3],
    pub radius_m: f64,
}

/// The spheres of the low, medium and high levels for velocity `t`.
pub fn spheres(velocity_mps: &Vector3<f64>, ttc_s: &[f64; 3]) -> [ThreatSphere; 3] {
    let levels = [ThreatLevel::Low, ThreatLevel::Medium, ThreatLevel::High];
    std::array::from_fn(|k| {
        let looming_per_s = 1.0 / ttc_s[k];
        let center = velocity_mps / (2.0 * looming_per_s);
        ThreatSphere {
            level: levels[k],
            looming_per_s,
            center_m: [center.x, center.y, center.z],
            radius_m: velocity_mps.norm() / (2.0 * looming_per_s),
        }
    })
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn levels_follow_the_time_to_contact() {
        let ttc = [3.0, 1.5, 1.0];
        assert_eq!(ThreatLevel::of(0.2, &ttc), ThreatLevel::None);
        assert_eq!(ThreatLevel::of(0.5, &ttc), ThreatLevel::Low);
        assert_eq!(ThreatLevel::of(0.8, &ttc), ThreatLevel::Medium);
        assert_eq!(ThreatLevel::of(1.2, &ttc), ThreatLevel::High);
        assert_eq!(ThreatLevel::of(-3.0, &ttc), ThreatLevel::None);
        assert_eq!(ThreatLevel::of(f64::NAN, &ttc), ThreatLevel::None);
    }

    #[test]
    fn points_on_a_sphere_have_its_looming() {
        // L = (t . p)/(p . p) is L_k on the sphere through the origin with
        // centre t / (2 L_k).
        let t = Vector3::new(10.0, 2.0, 0.0);
        for sphere in spheres(&t, &[3.0, 1.5, 1.0]) {
            let center = Vector3::from(sphere.center_m);
            for angle in [0.3f64, 1.0, 2.0, 4.0] {
                let p = center + Vector3::new(angle.cos(), angle.sin(), 0.0) * sphere.radius_m;
                let looming = t.dot(&p) / p.norm_squared();
                assert!((looming - sphere.looming_per_s).abs() < 1e-9);
            }
        }
    }
}
