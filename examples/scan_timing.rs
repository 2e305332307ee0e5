//! Time the simulation alone (no encoding, no writing):
//! `cargo run --release --example scan_timing -- SCENARIO SCANS`.

fn main() {
    let args: Vec<String> = std::env::args().collect();
    let scenario = looming::synth::scene::load(&args[1]).expect("scenario");
    let scans: u64 = args[2].parse().unwrap();
    let world = looming::synth::sensor::World::new(scenario);
    let started = std::time::Instant::now();
    let mut points = 0;
    for index in 0..scans {
        points += world.scan(index, 1).points.len();
    }
    let elapsed = started.elapsed().as_secs_f64();
    println!(
        "{scans} scans, {points} points, {:.1} ms per scan, {:.0} ns per point",
        elapsed * 1e3 / scans as f64,
        elapsed * 1e9 / points as f64
    );
}
