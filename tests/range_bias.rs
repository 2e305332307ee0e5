//! Per-laser range offsets (`engine::bias`): recovered from the scans of a
//! simulated HDL-64E whose lasers carry the offsets of a real one (+-2 cm),
//! and never invented for the ideal sensor, which has none.

use looming::engine::{self, EngineCache, EngineConfig, PairLooming};
use looming::synth::scene::{self, Realism};
use looming::synth::sensor::World;
use looming::synth::simulated_pair;

fn world(realism: Option<Realism>) -> World {
    let mut scenario = scene::load("urban-turn").unwrap();
    scenario.lidar.beams = 64;
    scenario.lidar.columns = 1024;
    if let Some(realism) = realism {
        scenario.lidar.realism = realism;
    }
    World::new(scenario)
}

/// The engine's result for the last of `pairs` consecutive pairs, run as a
/// stream (the offsets are a running estimate over the scans).
fn last_pair(world: &World, config: &EngineConfig, pairs: u64) -> PairLooming {
    pairs_from(world, config, 10, pairs)
}

/// [`last_pair`] from the pair `first` on.
fn pairs_from(world: &World, config: &EngineConfig, first: u64, pairs: u64) -> PairLooming {
    let mut cache = EngineCache::default();
    let mut last = None;
    for index in first..first + pairs {
        let pair = simulated_pair(world, index, 1);
        last = engine::compute_with_cache(&pair, config, &mut cache);
    }
    last.expect("an image")
}

/// `values` without their mean and linear trend across rows: the part of a
/// per-laser offset that second differences across rows can see.
fn detrended(values: &[f64]) -> Vec<f64> {
    let n = values.len() as f64;
    let mid = (n - 1.0) / 2.0;
    let mean = values.iter().sum::<f64>() / n;
    let slope = values
        .iter()
        .enumerate()
        .map(|(k, v)| (k as f64 - mid) * (v - mean))
        .sum::<f64>()
        / (0..values.len())
            .map(|k| (k as f64 - mid).powi(2))
            .sum::<f64>();
    values
        .iter()
        .enumerate()
        .map(|(k, v)| v - mean - slope * (k as f64 - mid))
        .collect()
}

fn rms(values: &[f64]) -> f64 {
    (values.iter().map(|v| v * v).sum::<f64>() / values.len() as f64).sqrt()
}

#[test]
fn a_real_sensors_laser_offsets_are_recovered_and_taken_out() {
    let world = world(Some(Realism::hdl64e()));
    let result = last_pair(&world, &EngineConfig::default(), 4);
    // Rows are the lasers by elevation, lowest first, as `world.lasers`.
    let truth = detrended(
        &world
            .lasers
            .iter()
            .map(|l| l.range_bias_m)
            .collect::<Vec<_>>(),
    );
    let found = detrended(
        &result
            .range_bias_m_per_row
            .iter()
            .map(|&b| f64::from(b))
            .collect::<Vec<_>>(),
    );
    let residual: Vec<f64> = truth.iter().zip(&found).map(|(t, f)| f - t).collect();
    println!(
        "offsets rms {:.4} m, found {:.4} m, residual {:.4} m",
        rms(&truth),
        rms(&found),
        rms(&residual)
    );
    assert!(
        rms(&found) > 0.5 * rms(&truth),
        "the offsets were not applied"
    );
    assert!(
        rms(&residual) < 0.5 * rms(&truth),
        "residual {:.4} m of offsets {:.4} m",
        rms(&residual),
        rms(&truth)
    );
}

#[test]
fn an_ideal_sensor_gets_no_offsets() {
    let world = world(None);
    let result = last_pair(&world, &EngineConfig::default(), 3);
    assert!(world.lasers.iter().all(|l| l.range_bias_m == 0.0));
    assert!(
        result.range_bias_m_per_row.iter().all(|&b| b == 0.0),
        "{:?}",
        result.range_bias_m_per_row
    );
}

/// The right side sensor of `synth --lidars 3` (ideal, 32 beams, yawed -90
/// degrees) at the start of urban-turn, passing a building 8.5 m away: where
/// the road meets its wall, two rows of returns lie in one chamfer plane,
/// which read as a 13 cm offset of the laser between them (and doubled the
/// road's `D` p90) before the rows beyond were checked too.
#[test]
fn a_building_beside_an_ideal_side_sensor_reads_no_offsets() {
    let scenario = scene::load("urban-turn").unwrap();
    let right = scene::ExtraLidar::preset("right").unwrap();
    let world = World::for_lidar(&scenario, &right.lidar, right.phase_s);
    let result = pairs_from(&world, &EngineConfig::default(), 1, 4);
    assert!(
        result.range_bias_m_per_row.iter().all(|&b| b == 0.0),
        "{:?}",
        result.range_bias_m_per_row
    );
}

#[test]
fn the_correction_can_be_turned_off() {
    let world = world(Some(Realism::hdl64e()));
    let config = EngineConfig {
        correct_range_bias: false,
        ..EngineConfig::default()
    };
    let result = last_pair(&world, &config, 2);
    assert!(result.range_bias_m_per_row.iter().all(|&b| b == 0.0));
}
