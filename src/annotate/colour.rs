//! The colour scales of the output, as in the paper's figures: red for
//! approaching (positive looming), blue for receding, brighter with magnitude;
//! grey where the value is not trusted; yellow / orange / red threat levels.

use crate::engine::ThreatLevel;

/// RGBA, 0-255.
pub type Rgba = [u8; 4];

/// Looming of full intensity, 1/s: a time to contact of 1 s (the high threat
/// level's default).
pub const SATURATION_PER_S: f32 = 1.0;

/// Zero looming: dark grey, so the static world stays visible on the dark
/// backgrounds of Foxglove and Rerun.
pub const ZERO: Rgba = [60, 60, 60, 255];
/// A value that is not trusted (masked, ambiguous, no previous scan).
pub const MASKED: Rgba = [150, 150, 150, 128];
/// A cell without a return (images only).
pub const EMPTY: Rgba = [0, 0, 0, 255];

/// Intensity steps of the scale: the eye tells no more apart, and a few
/// distinct colours compress several times better than 256.
pub const LEVELS: f32 = 16.0;

/// The looming scale: the square root of `|L| / 1 1/s` (clamped to 1, in
/// [`LEVELS`] steps) blends [`ZERO`] into red (L > 0) or blue (L < 0); the
/// square root spreads the small values that make up most of a scene. NaN is
/// [`MASKED`].
pub fn looming(looming_per_s: f32) -> Rgba {
    if !looming_per_s.is_finite() {
        return MASKED;
    }
    let s = (looming_per_s.abs() / SATURATION_PER_S).min(1.0).sqrt();
    let s = (s * LEVELS).round() / LEVELS;
    let target: [f32; 3] = if looming_per_s >= 0.0 {
        [255.0, 0.0, 0.0]
    } else {
        [30.0, 90.0, 255.0]
    };
    let blend = |k: usize| (f32::from(ZERO[k]) * (1.0 - s) + target[k] * s).round() as u8;
    [blend(0), blend(1), blend(2), 255]
}

/// Yellow, orange, red for low, medium, high; [`ZERO`] for none.
pub fn threat(level: ThreatLevel) -> Rgba {
    match level {
        ThreatLevel::None => ZERO,
        ThreatLevel::Low => [255, 220, 0, 255],
        ThreatLevel::Medium => [255, 140, 0, 255],
        ThreatLevel::High => [255, 0, 0, 255],
    }
}

/// Translucent colour of a threat sphere, components 0-1.
pub fn threat_zone(level: ThreatLevel) -> [f64; 4] {
    let [r, g, b, _] = threat(level);
    let alpha = match level {
        ThreatLevel::High => 0.30,
        ThreatLevel::Medium => 0.20,
        _ => 0.12,
    };
    [
        f64::from(r) / 255.0,
        f64::from(g) / 255.0,
        f64::from(b) / 255.0,
        alpha,
    ]
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn the_scale_runs_from_grey_to_red_and_blue() {
        assert_eq!(looming(0.0), ZERO);
        assert_eq!(looming(1.0), [255, 0, 0, 255]);
        assert_eq!(looming(5.0), [255, 0, 0, 255]);
        assert_eq!(looming(-1.0), [30, 90, 255, 255]);
        assert_eq!(looming(f32::NAN), MASKED);
        // sqrt(0.25) = 0.5: half way.
        assert_eq!(looming(0.25), [158, 30, 30, 255]);
        // Steps of 1/16 in intensity: nearby values share a colour.
        assert_eq!(looming(0.2500), looming(0.2501));
        let (weak, strong) = (looming(0.1), looming(0.5));
        assert!(weak[0] < strong[0] && weak[1] > strong[1]);
    }

    #[test]
    fn threat_levels_are_yellow_orange_red() {
        assert_eq!(threat(ThreatLevel::Low), [255, 220, 0, 255]);
        assert_eq!(threat(ThreatLevel::Medium), [255, 140, 0, 255]);
        assert_eq!(threat(ThreatLevel::High), [255, 0, 0, 255]);
        assert!(threat_zone(ThreatLevel::High)[3] > threat_zone(ThreatLevel::Low)[3]);
    }
}
