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
    let (started, cpu_started) = (std::time::Instant::now(), cpu_s());
    for pair in &stream {
        std::hint::black_box(compute_with_cache(pair, &config, &mut cache));
    }
    let per_pair_ms = started.elapsed().as_secs_f64() * 1e3 / pairs as f64;
    let cpu_per_pair_ms = (cpu_s() - cpu_started) * 1e3 / pairs as f64;
    println!(
        "{name}: {pairs} pairs, {per_pair_ms:.1} ms per pair, {cpu_per_pair_ms:.1} CPU-ms per pair"
    );
}

/// CPU time of this process so far (user + system), seconds: steadier than
/// wall time on a shared machine. From /proc (Linux); 0 elsewhere.
fn cpu_s() -> f64 {
    let Ok(stat) = std::fs::read_to_string("/proc/self/stat") else {
        return 0.0;
    };
    // Fields after the command name (which may hold spaces), from field 3.
    let Some((_, rest)) = stat.rsplit_once(')') else {
        return 0.0;
    };
    let fields: Vec<&str> = rest.split_whitespace().collect();
    let ticks = |i: usize| {
        fields
            .get(i)
            .and_then(|f| f.parse::<f64>().ok())
            .unwrap_or(0.0)
    };
    // utime and stime are fields 14 and 15 (1-based), in clock ticks of 1/100 s.
    (ticks(11) + ticks(12)) / 100.0
}
