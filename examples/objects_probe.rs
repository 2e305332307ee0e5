//! The objects of a log, as issue #24 judges them: of the objects with at
//! least 50 points within 25 m, the share with a looming (per pair and per
//! track), the median |D| of those not flagged moving, how long tracks last,
//! and the time objects take. A development tool:
//! `cargo run --release --example objects_probe -- LOG.mcap`.

use std::collections::BTreeMap;
use std::time::Instant;

use looming::engine::{self, EngineCache, EngineConfig};
use looming::objects::{ObjectConfig, ObjectTracker, PairObjects};

fn median(values: &mut [f64]) -> f64 {
    values.sort_by(f64::total_cmp);
    values.get(values.len() / 2).copied().unwrap_or(f64::NAN)
}

fn main() {
    let path = std::env::args().nth(1).expect("LOG.mcap");
    let config = EngineConfig::default();
    let object_config = ObjectConfig::default();
    let mut cache = EngineCache::default();
    let mut tracker = ObjectTracker::default();
    let (mut pairs, mut seen, mut with_looming) = (0usize, 0usize, 0usize);
    let mut static_abs_d = Vec::new();
    let mut per_track: BTreeMap<u32, (usize, usize)> = BTreeMap::new();
    let (mut objects_total, mut ms) = (0usize, 0.0f64);
    let (mut from_track, mut assumed_static) = (0usize, 0usize);
    // Sightings not flagged moving whose looming reads over 1 1/s (a time
    // to contact under a second): on these logs' static worlds, errors.
    let mut wild = 0usize;
    looming::pipeline::replay(
        std::path::Path::new(&path),
        &looming::pipeline::ScanOptions::default(),
        &mut |_| {},
        &mut |pair| {
            let Some(mut result) = engine::compute_with_cache(&pair, &config, &mut cache) else {
                return;
            };
            let started = Instant::now();
            let (objects, _) = PairObjects::find_tracked_fused(
                &pair.current,
                &mut result,
                (&object_config, &config.threat_ttc_s),
                &mut tracker,
                pair.step_s,
            );
            ms += started.elapsed().as_secs_f64() * 1e3;
            pairs += 1;
            objects_total += objects.objects.len();
            for object in &objects.objects {
                if object.points < 50 || object.nearest_range_m > 25.0 {
                    continue;
                }
                seen += 1;
                let measured = object.looming_per_s.is_some();
                wild += usize::from(is_wild(pair.index, object));
                if !measured && std::env::var_os("PROBE_WHY").is_some() {
                    print_why(&objects, &result, object);
                }
                with_looming += usize::from(measured);
                from_track += usize::from(object.looming_from_track);
                assumed_static += usize::from(object.looming_assumed_static);
                let entry = per_track.entry(object.id).or_default();
                entry.0 += 1;
                entry.1 += usize::from(measured);
                if let (Some(d), false) = (object.disagreement_per_s, object.moving) {
                    static_abs_d.push(d.abs());
                }
            }
        },
    )
    .expect("a readable log");
    let tracks_ok = per_track
        .values()
        .filter(|(n, m)| *m as f64 >= 0.9 * *n as f64)
        .count();
    let mut lengths: Vec<f64> = per_track.values().map(|(n, _)| *n as f64).collect();
    println!("{path}");
    println!(
        "pairs {pairs}, objects {objects_total} ({:.1} per pair), objects time {:.2} ms per pair",
        objects_total as f64 / pairs.max(1) as f64,
        ms / pairs.max(1) as f64
    );
    println!(
        "objects >= 50 points within 25 m: {seen} sightings, {:.1} % with a looming; {} tracks, {tracks_ok} ({:.0} %) with a looming in >= 90 % of their pairs; median track {} pairs",
        100.0 * with_looming as f64 / seen.max(1) as f64,
        per_track.len(),
        100.0 * tracks_ok as f64 / per_track.len().max(1) as f64,
        median(&mut lengths)
    );
    println!(
        "  of the sightings: {from_track} from their track's range rate, {assumed_static} assumed static (ego motion alone)"
    );
    println!("  not flagged moving with |looming| > 1 1/s: {wild}");
    print_static_d(&mut static_abs_d);
}

/// A sighting not flagged moving whose looming reads over 1 1/s; printed
/// with `PROBE_WILD`.
fn is_wild(pair_index: u64, object: &looming::objects::Object) -> bool {
    let wild = object.looming_per_s.is_some_and(|l| l.abs() > 1.0) && !object.moving;
    if wild && std::env::var_os("PROBE_WILD").is_some() {
        println!(
            "  wild: pair {pair_index} id {} age {} pts {} r {:.2} brg {:.0} L {:.2} lidar {:?} cells {} from track {}",
            object.id,
            object.age_pairs,
            object.points,
            object.nearest_range_m,
            object.bearing_deg,
            object.looming_per_s.unwrap_or(f64::NAN),
            object.lidar_looming_per_s,
            object.measured_cells,
            object.looming_from_track
        );
    }
    wild
}

/// The median |D| of the sightings not flagged moving.
fn print_static_d(static_abs_d: &mut [f64]) {
    if static_abs_d.is_empty() {
        println!("no D (no ego motion)");
    } else {
        println!(
            "objects not flagged moving: median |D| {:.4} 1/s over {} sightings",
            median(static_abs_d),
            static_abs_d.len()
        );
    }
}

/// Why an object has no looming: its age, size, place, and how many of its
/// cells face the sensor, have an ego prediction and carry each mask bit.
fn print_why(
    objects: &PairObjects,
    result: &looming::engine::PairLooming,
    object: &looming::objects::Object,
) {
    let cells: Vec<usize> = (0..objects.cell_object.len())
        .filter(|&c| {
            objects
                .objects
                .get(objects.cell_object[c] as usize)
                .is_some_and(|o| o.id == object.id)
        })
        .collect();
    let mut bits = [0usize; 16];
    for &c in &cells {
        for (b, n) in bits.iter_mut().enumerate() {
            *n += usize::from(result.mask[c] & (1 << b) != 0);
        }
    }
    let facing = cells
        .iter()
        .filter(|&&c| result.incidence_cos[c].abs() >= 0.5)
        .count();
    let ego = cells
        .iter()
        .filter(|&&c| result.l_ray_ego[c].is_finite())
        .count();
    println!(
        "  no looming: id {} age {} pts {} cells {} r {:.1} brg {:.0} ext {:.1}x{:.1}x{:.1} facing {facing} ego {ego} bits {:?}",
        object.id,
        object.age_pairs,
        object.points,
        object.cells,
        object.nearest_range_m,
        object.bearing_deg,
        object.max_m[0] - object.min_m[0],
        object.max_m[1] - object.min_m[1],
        object.max_m[2] - object.min_m[2],
        &bits[..8]
    );
}
