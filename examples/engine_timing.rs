//! Time the engine on the first pairs of a log:
//! `cargo run --release --example engine_timing -- LOG.mcap`.

use std::time::Instant;

fn main() {
    let path = std::env::args().nth(1).expect("LOG.mcap");
    let mut pairs = Vec::new();
    looming::pipeline::replay(
        std::path::Path::new(&path),
        &looming::pipeline::ScanOptions::default(),
        &mut |_| {},
        &mut |pair| {
            if pairs.len() < 6 {
                pairs.push(pair);
            }
        },
    )
    .expect("a readable log");
    let config = looming::engine::EngineConfig::default();
    let mut cache = looming::engine::EngineCache::default();
    for pair in &pairs {
        let started = Instant::now();
        let Some(result) = looming::engine::compute_with_cache(pair, &config, &mut cache) else {
            continue;
        };
        let points = pair.current.points_m.len();
        let elapsed = started.elapsed().as_secs_f64();
        println!(
            "{points} points, {} cells: {:.1} ms ({:.0} ns/point)",
            result.geometry.cells(),
            elapsed * 1e3,
            elapsed * 1e9 / points as f64
        );
    }
}
