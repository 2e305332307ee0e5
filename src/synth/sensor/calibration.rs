//! The simulated head's lasers: elevations (even or HDL-64E-like blocks) and
//! per-laser corrections, drawn from a fixed calibration seed.

use rand::SeedableRng;

use super::Laser;
use crate::synth::scene::{LidarSpec, Realism};

/// Calibration seed of the simulated head: the lasers are a property of the
/// sensor, the same whatever `--seed`.
const CALIBRATION_SEED: u64 = 0x4844_4C36_3445;

/// The lasers of `lidar`, lowest first: ideal (evenly spaced, on the axis, no
/// corrections) unless `lidar.realism` asks otherwise.
pub fn calibrate(lidar: &LidarSpec) -> Vec<Laser> {
    use rand::Rng;
    let realism: &Realism = &lidar.realism;
    let elevations = if realism.irregular_elevations {
        two_block_elevations_rad(
            lidar.beams,
            lidar.elevation_min_deg,
            lidar.elevation_max_deg,
        )
    } else {
        beam_elevations_rad(
            lidar.beams,
            lidar.elevation_min_deg,
            lidar.elevation_max_deg,
        )
    };
    let beams = elevations.len();
    let mut rng = rand_chacha::ChaCha8Rng::seed_from_u64(CALIBRATION_SEED);
    elevations
        .into_iter()
        .enumerate()
        .map(|(k, elevation_rad)| {
            // Draw everything for every laser, so each option keeps its values
            // whichever others are on.
            let draws: [f64; 6] = std::array::from_fn(|_| rng.random::<f64>());
            let upper = k >= beams / 2;
            let side = if k % 2 == 0 { 1.0 } else { -1.0 };
            Laser {
                elevation_rad: if realism.irregular_elevations {
                    elevation_rad + (0.06 * (2.0 * draws[0] - 1.0)).to_radians()
                } else {
                    elevation_rad
                },
                azimuth_offset_rad: if realism.azimuth_offsets {
                    // HDL-64E: lasers alternate sides, 1 to 5 degrees off.
                    (side * (1.0 + 4.0 * draws[1])).to_radians()
                } else {
                    0.0
                },
                vertical_offset_m: if realism.off_axis {
                    let base = if upper { 0.20 } else { 0.14 };
                    base + 0.01 * (2.0 * draws[2] - 1.0)
                } else {
                    0.0
                },
                horizontal_offset_m: if realism.off_axis {
                    side * (0.026 + 0.004 * (2.0 * draws[3] - 1.0))
                } else {
                    0.0
                },
                range_bias_m: if realism.range_bias {
                    0.02 * (2.0 * draws[4] - 1.0)
                } else {
                    0.0
                },
            }
        })
        .collect()
}

/// HDL-64E-like elevations, lowest first, radians: a lower block of half the
/// lasers over the lower 16/26.8 of the field and an upper block over the top
/// 10.5/26.8, 0.3/26.8 of the field apart (at the default field: -24.8 to
/// -8.8 deg, 0.516 deg apart, and -8.5 to +2 deg, 0.339 deg apart).
pub fn two_block_elevations_rad(beams: u16, min_deg: f64, max_deg: f64) -> Vec<f64> {
    if beams < 4 {
        return beam_elevations_rad(beams, min_deg, max_deg);
    }
    let span = max_deg - min_deg;
    let lower_top = min_deg + span * 16.0 / 26.8;
    let upper_bottom = lower_top + span * 0.3 / 26.8;
    let lower = beams / 2;
    let mut elevations = beam_elevations_rad(lower, min_deg, lower_top);
    elevations.extend(beam_elevations_rad(beams - lower, upper_bottom, max_deg));
    elevations
}

/// Beam elevations evenly spaced, lowest first, radians.
pub fn beam_elevations_rad(beams: u16, min_deg: f64, max_deg: f64) -> Vec<f64> {
    if beams <= 1 {
        return vec![max_deg.to_radians()];
    }
    let step = (max_deg - min_deg) / f64::from(beams - 1);
    (0..beams)
        .map(|b| (min_deg + step * f64::from(b)).to_radians())
        .collect()
}
