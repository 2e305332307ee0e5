//! The engine on one full-size pair (64 beams x 2048 columns, about 126 k
//! points, urban-turn: turning at 20 deg/s), single-threaded and with all
//! cores; and on a stream of ten consecutive pairs sharing their scans, as
//! `process` runs it (the previous scan's image and surfaces from the cache;
//! the stream restarts every ten pairs, so one pair in ten has no cache).
//! `cargo bench --bench engine`; the report gives time per pair, divide by
//! the point count printed at start for ns per point.

use criterion::{Criterion, criterion_group, criterion_main};
use looming::engine::{EngineCache, EngineConfig, compute, compute_with_cache};
use looming::synth::{scene, sensor::World, simulated_pair};

fn engine(c: &mut Criterion) {
    let world = World::new(scene::load("urban-turn").expect("built-in scenario"));
    let pair = simulated_pair(&world, 5, 1);
    let points = pair.current.points_m.len();
    eprintln!("engine bench: {points} points in the current scan");
    let config = EngineConfig::default();
    let mut group = c.benchmark_group("engine_64x2048_pair");
    group.sample_size(20);
    let single = rayon::ThreadPoolBuilder::new()
        .num_threads(1)
        .build()
        .expect("pool");
    group.bench_function("1_thread", |b| {
        b.iter(|| single.install(|| compute(&pair, &config)))
    });
    group.bench_function("all_threads", |b| b.iter(|| compute(&pair, &config)));
    let mut stream: Vec<_> = (0..STREAM_PAIRS)
        .map(|k| simulated_pair(&world, 5 + k, 1))
        .collect();
    for k in 1..stream.len() {
        stream[k].previous = stream[k - 1].current.clone();
    }
    group.bench_function("streaming_all_threads", |b| {
        let mut cache = EngineCache::default();
        let mut next = 0;
        b.iter(|| {
            let result = compute_with_cache(&stream[next], &config, &mut cache);
            next = (next + 1) % stream.len();
            result
        })
    });
    group.finish();
}

/// Consecutive pairs in the streaming case.
const STREAM_PAIRS: u64 = 10;

criterion_group!(benches, engine);
criterion_main!(benches);
