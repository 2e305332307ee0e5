//! The engine on a stream of full-size pairs, for profiling (`perf record`):
//! `cargo run --release --example engine_stream -- [SCENARIO] [PAIRS]`
//! (default `urban-turn`, 20 pairs at 64 x 2048, streaming with the cache, as
//! `process` runs it). Prints the time per pair.

use looming::engine::{EngineCache, EngineConfig, compute_with_cache};
use looming::synth::{scene, sensor::World, simulated_pair};

fn main() {
    let args: Vec<String> = std::env::args().collect();
    let name = args.get(1).map_or("urban-turn", String::as_str);
    let pairs: u64 = args.get(2).map_or(20, |a| a.parse().expect("a count"));
    let world = World::new(scene::load(name).expect("a built-in scenario"));
    // Consecutive pairs share their scan, as the pairer's do (the cache
    // keys on it).
    let mut stream: Vec<_> = (0..pairs)
        .map(|k| simulated_pair(&world, 5 + k, 1))
        .collect();
    for k in 1..stream.len() {
        stream[k].previous = stream[k - 1].current.clone();
    }
    let config = EngineConfig::default();
    let mut cache = EngineCache::default();
    let started = std::time::Instant::now();
    for pair in &stream {
        std::hint::black_box(compute_with_cache(pair, &config, &mut cache));
    }
    let per_pair_ms = started.elapsed().as_secs_f64() * 1e3 / pairs as f64;
    println!("{name}: {pairs} pairs, {per_pair_ms:.1} ms per pair");
}
