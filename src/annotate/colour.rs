//! The colour scales of the output, as in the paper's figures: red for
//! approaching (positive looming), blue for receding, brighter with magnitude;
//! grey where the value is not trusted; yellow / orange / red threat levels.

use crate::engine::ThreatLevel;

/// RGBA, 0-255.
pub type Rgba = [u8; 4];

/// Looming of full intensity, 1/s: a time to contact of 1 s (the high threat
/// level's default).
pub(crate) const SATURATION_PER_S: f32 = 1.0;

/// Zero looming: dark grey, so the static world stays visible on the dark
/// backgrounds of Foxglove and Rerun.
pub(crate) const ZERO: Rgba = [60, 60, 60, 255];
/// A value that is not trusted (masked, ambiguous, no previous scan).
pub const MASKED: Rgba = [150, 150, 150, 128];
/// A cell without a return (images only).
pub const EMPTY: Rgba = [0, 0, 0, 255];

/// Intensity steps of the scale: the eye tells no more apart, and a few
/// distinct colours compress several times better than 256.
pub(crate) const STEPS: u8 = 16;
/// [`STEPS`] as a float, for the scale's arithmetic.
pub(crate) const LEVELS: f32 = STEPS as f32;

/// The looming scale: the square root of `|L| / 1 1/s` (clamped to 1, in
/// `LEVELS` steps) blends `ZERO` into red (L > 0) or blue (L < 0); the
/// square root spreads the small values that make up most of a scene. NaN is
/// [`MASKED`].
pub fn looming(looming_per_s: f32) -> Rgba {
    match looming_step(looming_per_s) {
        None => MASKED,
        Some(step) => STEP_COLOURS[usize::from(step.approaching)][usize::from(step.level)],
    }
}

/// [`step_colour`] of every step (receding, then approaching), worked out
/// once: the cloud colours every point of every scan.
static STEP_COLOURS: std::sync::LazyLock<[[Rgba; STEPS as usize + 1]; 2]> =
    std::sync::LazyLock::new(|| {
        std::array::from_fn(|approaching| {
            std::array::from_fn(|level| {
                step_colour(Step {
                    approaching: approaching == 1,
                    level: level as u8,
                })
            })
        })
    });

/// One colour of the looming scale: the sign of the value and its intensity
/// step, 0 (zero looming, [`ZERO`] whatever the sign) to [`STEPS`] (full).
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
struct Step {
    approaching: bool,
    level: u8,
}

/// The step of a value on the looming scale; `None` for NaN or infinity.
fn looming_step(looming_per_s: f32) -> Option<Step> {
    if !looming_per_s.is_finite() {
        return None;
    }
    let s = (looming_per_s.abs() / SATURATION_PER_S).min(1.0).sqrt();
    Some(Step {
        approaching: looming_per_s >= 0.0,
        level: (s * LEVELS).round() as u8,
    })
}

fn step_colour(step: Step) -> Rgba {
    // level / LEVELS is exact in f32: the blend is the one of the scale's
    // definition, rounded intensity included.
    let s = f32::from(step.level) / LEVELS;
    let target: [f32; 3] = if step.approaching {
        [255.0, 0.0, 0.0]
    } else {
        [30.0, 90.0, 255.0]
    };
    let blend = |k: usize| (f32::from(ZERO[k]) * (1.0 - s) + target[k] * s).round() as u8;
    [blend(0), blend(1), blend(2), 255]
}

/// Palette index of [`EMPTY`] in range images.
pub(crate) const EMPTY_INDEX: u8 = 0;
/// Palette index of [`MASKED`] in range images.
pub(crate) const MASKED_INDEX: u8 = 1;
/// Palette index of [`ZERO`]; then each step, approaching and receding in
/// turn: `ZERO_INDEX + 2 level - 1` and `ZERO_INDEX + 2 level`.
const ZERO_INDEX: u8 = 2;
/// Colours a range image can hold: empty, masked, zero and the scale's
/// steps each way.
pub(crate) const PALETTE_LEN: usize = 3 + 2 * STEPS as usize;

/// The palette index of a value in range images (see [`image_palette`]):
/// one byte per cell instead of three, which is what makes their PNGs small.
/// Weak values of either sign get neighbouring indexes, so the noise of the
/// static world (small values of both signs side by side) differs little
/// from cell to cell: a fifth fewer bytes than with the signs apart.
pub(crate) fn looming_index(looming_per_s: f32) -> u8 {
    match looming_step(looming_per_s) {
        None => MASKED_INDEX,
        Some(Step { level: 0, .. }) => ZERO_INDEX,
        Some(Step {
            approaching: true,
            level,
        }) => ZERO_INDEX + 2 * level - 1,
        Some(Step {
            approaching: false,
            level,
        }) => ZERO_INDEX + 2 * level,
    }
}

/// The RGB colours of the range-image palette, by index: [`EMPTY`],
/// [`MASKED`], `ZERO`, then steps 1 to `STEPS`, each approaching then
/// receding. `image_palette()[looming_index(L)]` is `looming(L)` without
/// alpha.
pub fn image_palette() -> [[u8; 3]; PALETTE_LEN] {
    let mut palette = [[0; 3]; PALETTE_LEN];
    let rgb = |c: Rgba| [c[0], c[1], c[2]];
    palette[usize::from(EMPTY_INDEX)] = rgb(EMPTY);
    palette[usize::from(MASKED_INDEX)] = rgb(MASKED);
    palette[usize::from(ZERO_INDEX)] = rgb(ZERO);
    for level in 1..=STEPS {
        for (approaching, index) in [
            (true, ZERO_INDEX + 2 * level - 1),
            (false, ZERO_INDEX + 2 * level),
        ] {
            palette[usize::from(index)] = rgb(step_colour(Step { approaching, level }));
        }
    }
    palette
}

/// Yellow, orange, red for low, medium, high; `ZERO` for none.
pub fn threat(level: ThreatLevel) -> Rgba {
    match level {
        ThreatLevel::None => ZERO,
        ThreatLevel::Low => [255, 220, 0, 255],
        ThreatLevel::Medium => [255, 140, 0, 255],
        ThreatLevel::High => [255, 0, 0, 255],
    }
}

/// Translucent colour of a threat sphere, components 0-1.
pub(crate) fn threat_zone(level: ThreatLevel) -> [f64; 4] {
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

    /// The table of step colours gives each value the blend of its step.
    #[test]
    fn tabled_colours_are_the_blends_of_their_steps() {
        for k in -2200..=2200 {
            let value = k as f32 / 1000.0;
            let step = looming_step(value).unwrap();
            assert_eq!(looming(value), step_colour(step), "{value}");
        }
        assert_eq!(looming(f32::INFINITY), MASKED);
    }

    #[test]
    fn the_palette_holds_every_colour_of_the_scale() {
        let palette = image_palette();
        let rgb = |c: Rgba| [c[0], c[1], c[2]];
        assert_eq!(palette[usize::from(EMPTY_INDEX)], rgb(EMPTY));
        assert_eq!(palette[usize::from(looming_index(f32::NAN))], rgb(MASKED));
        assert_eq!(
            palette[usize::from(looming_index(f32::INFINITY))],
            rgb(MASKED)
        );
        // Every value in 1e-4 steps over and beyond the scale, and zero of
        // either sign.
        let values = (-25_000..=25_000)
            .map(|i| i as f32 * 1e-4)
            .chain([-0.0, 1e-9, -1e-9, 3.0, -7.5]);
        let mut used = [false; PALETTE_LEN];
        for value in values {
            let index = usize::from(looming_index(value));
            assert_eq!(palette[index], rgb(looming(value)), "{value}");
            used[index] = true;
        }
        // Every index but empty and masked is a value's colour.
        assert!(used[2..].iter().all(|&u| u));
    }

    #[test]
    fn threat_levels_are_yellow_orange_red() {
        assert_eq!(threat(ThreatLevel::Low), [255, 220, 0, 255]);
        assert_eq!(threat(ThreatLevel::Medium), [255, 140, 0, 255]);
        assert_eq!(threat(ThreatLevel::High), [255, 0, 0, 255]);
        assert!(threat_zone(ThreatLevel::High)[3] > threat_zone(ThreatLevel::Low)[3]);
    }
}
