//! The engine's stage times on a log's first pairs, single pass with the
//! cache as `process` runs it, for timing one stage against another build:
//! `RAYON_NUM_THREADS=1 cargo run --release --example stage_timing -- LOG.mcap [PAIRS]`.
//! Prints each stage's ms per pair (wall; with one thread, CPU).

fn main() {
    let args: Vec<String> = std::env::args().collect();
    let path = args.get(1).expect("LOG.mcap");
    let limit: usize = args.get(2).map_or(30, |a| a.parse().expect("a count"));
    let mut pairs = Vec::new();
    looming::pipeline::replay(
        std::path::Path::new(path),
        &looming::pipeline::ScanOptions::default(),
        &mut |_| {},
        &mut |pair| {
            if pairs.len() < limit {
                pairs.push(pair);
            }
        },
    )
    .expect("a readable log");
    let config = looming::engine::EngineConfig::default();
    let mut cache = looming::engine::EngineCache::default();
    let mut total = looming::engine::StageTimes::default();
    for pair in &pairs {
        if let Some(result) = looming::engine::compute_with_cache(pair, &config, &mut cache) {
            total.add(&result.stage_times);
        }
    }
    let per_pair = |s: f64| s * 1e3 / pairs.len().max(1) as f64;
    println!(
        "{} pairs: range images {:.2}, plane fits {:.2}, cell times {:.2}, motion {:.2}, renders {:.2}, cells {:.2} ms per pair",
        pairs.len(),
        per_pair(total.range_images_s),
        per_pair(total.plane_fits_s),
        per_pair(total.cell_times_s),
        per_pair(total.motion_estimate_s),
        per_pair(total.renders_s),
        per_pair(total.cells_s),
    );
}
