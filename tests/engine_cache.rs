//! The engine's cache of the previous scan's image and surfaces holds on a
//! stream whose scans' column counts move by a few percent, as a real
//! sensor's do (dropouts, doubled returns): the pair keeps the previous
//! pair's columns instead of gridding both scans anew.

use std::sync::Arc;

use looming::engine::{self, EngineCache, EngineConfig};
use looming::model::Scan;
use looming::model::ScanPair;
use looming::synth::{scene, sensor::World, simulated_pair};

fn world() -> World {
    let mut scenario = scene::load("straight-road").unwrap();
    scenario.lidar.beams = 32;
    scenario.lidar.columns = 512;
    World::new(scenario)
}

/// `scan` without its last `drop` points (the last columns of the sweep):
/// every per-point field cut alike.
fn without_last(scan: &Scan, drop: usize) -> Scan {
    let keep = scan.points_m.len() - drop;
    let mut cut = scan.clone();
    cut.points_m.truncate(keep);
    cut.source_index.truncate(keep);
    for values in [&mut cut.intensity, &mut cut.time_offset_s]
        .into_iter()
        .flatten()
    {
        values.truncate(keep);
    }
    if let Some(rings) = &mut cut.ring {
        rings.truncate(keep);
    }
    cut
}

/// Consecutive pairs sharing their scans, as the pairer emits them, the
/// current scan of pair k cut by `drops[k]` points.
fn stream(world: &World, drops: &[usize]) -> Vec<ScanPair> {
    let mut pairs: Vec<ScanPair> = Vec::new();
    for (k, &drop) in drops.iter().enumerate() {
        let mut pair = simulated_pair(world, 10 + k as u64, 1);
        pair.current = Arc::new(without_last(&pair.current, drop));
        if let Some(before) = pairs.last() {
            pair.previous = before.current.clone();
        }
        pairs.push(pair);
    }
    pairs
}

/// The engine on [`stream`]: each pair's image columns, and how many pairs
/// reused the previous scan's image and surfaces.
fn run(world: &World, drops: &[usize]) -> (Vec<usize>, u64) {
    let config = EngineConfig::default();
    let mut cache = EngineCache::default();
    let columns = stream(world, drops)
        .iter()
        .map(|pair| {
            let result = engine::compute_with_cache(pair, &config, &mut cache).expect("an image");
            result.geometry.cols
        })
        .collect();
    (columns, cache.reused_scans())
}

#[test]
fn the_previous_scan_is_reused_while_the_column_count_moves_a_little() {
    let world = world();
    let rows = 32;
    // Up to 4 % fewer points per ring from scan to scan.
    let drops = [0, 5 * rows, 0, 20 * rows, 11 * rows, 0];
    let (columns, reused) = run(&world, &drops);
    assert!(columns.iter().all(|&c| c == columns[0]), "{columns:?}");
    assert_eq!(reused, drops.len() as u64 - 1);
}

#[test]
fn a_new_resolution_grids_both_scans_anew() {
    let world = world();
    // A third of the sweep gone: not the same sensor mode.
    let drops = [0, 170 * 32, 170 * 32];
    let (columns, reused) = run(&world, &drops);
    assert!(columns[1] < columns[0], "{columns:?}");
    assert_eq!(columns[2], columns[1]);
    assert_eq!(reused, 1);
}

/// The engine on consecutive pairs sharing their scans, the rings of the
/// current scans from pair `swapped_from` on relabelled (rings 0 and 1
/// swapped): each pair's result.
fn run_relabelled(world: &World, pairs: usize, swapped_from: usize) -> Vec<engine::PairLooming> {
    let config = EngineConfig::default();
    let mut cache = EngineCache::default();
    let mut previous: Option<Arc<Scan>> = None;
    (0..pairs)
        .map(|k| {
            let mut pair = simulated_pair(world, 10 + k as u64, 1);
            if k >= swapped_from {
                let mut current = (*pair.current).clone();
                for ring in current.ring.iter_mut().flatten() {
                    *ring = match *ring {
                        0 => 1,
                        1 => 0,
                        other => other,
                    };
                }
                pair.current = Arc::new(current);
            }
            if let Some(before) = previous.take() {
                pair.previous = before;
            }
            previous = Some(pair.current.clone());
            engine::compute_with_cache(&pair, &config, &mut cache).expect("an image")
        })
        .collect()
}

/// A ring-ordered sensor's rings (each ring's row and elevation) are the
/// sensor's: measured on one pair in ten, the pairs between taking the
/// last measured (the same beam table to the bit, where each scan's own fit
/// differs in its last bits).
#[test]
fn the_rings_are_measured_on_one_pair_in_ten() {
    let world = world();
    let results = run_relabelled(&world, 12, usize::MAX);
    let elevations = |k: usize| results[k].geometry.beams.elevations_rad.clone();
    for k in 1..10 {
        assert_eq!(elevations(k), elevations(0), "pair {k}");
    }
    assert_ne!(elevations(10), elevations(0));
    assert_eq!(elevations(11), elevations(10));
}

/// Rings numbered anew within a log (a layout recovered from the points'
/// order that missed or split a laser's list renumbers the rest): the
/// rings are measured again on that very pair, not up to nine pairs later.
#[test]
fn rings_numbered_anew_are_measured_again_at_once() {
    let world = world();
    let results = run_relabelled(&world, 6, 3);
    let rows_of = |k: usize| {
        results[k]
            .geometry
            .ring_to_row
            .clone()
            .expect("rows from rings")
    };
    let measured = rows_of(0);
    assert_eq!(&measured[..2], &[0, 1]);
    for k in 1..3 {
        assert_eq!(rows_of(k), measured, "pair {k}");
    }
    for k in 3..6 {
        assert_eq!(&rows_of(k)[..2], &[1, 0], "pair {k}");
        assert_eq!(rows_of(k)[2..], measured[2..]);
    }
}
