//! Time the engine stages on a real pair from a log:
//! `cargo run --release --example engine_timing -- LOG.mcap`.

use std::sync::Arc;
use std::time::Instant;

use looming::decode::{self, DecodeLimits};
use looming::input::{Flow, InputFile, InputOptions, InputRecord};
use looming::messages::Decoded;
use looming::pairing::{PairEvent, PairingConfig, ScanPairer};
use looming::topics::{Role, TopicOverrides, select};

fn main() {
    let path = std::env::args().nth(1).expect("LOG.mcap");
    let input = InputFile::open(std::path::Path::new(&path), InputOptions::default()).unwrap();
    let topics = select(input.catalog(), &TopicOverrides::default()).unwrap();
    let selected: std::collections::BTreeMap<u16, _> =
        topics.all().map(|c| (c.channel_id, c.clone())).collect();
    let mut pairer = ScanPairer::new(PairingConfig {
        has_velocity_source: topics.velocity.is_some(),
        has_imu_source: topics.imu.is_some(),
        ..PairingConfig::default()
    });
    let mut pairs = Vec::new();
    input
        .read_records(false, &mut |record| {
            let InputRecord::Message(m) = record else {
                return Flow::Continue(());
            };
            let Some(c) = selected.get(&m.channel_id) else {
                return Flow::Continue(());
            };
            let Ok(decoded) = decode::decode(
                c.kind,
                c.encoding,
                c.role == Role::TfStatic,
                &m.data,
                &DecodeLimits::default(),
            ) else {
                return Flow::Continue(());
            };
            let events = match decoded {
                Decoded::Scan(s) => pairer.push_scan(m.log_time_ns, Arc::new(s)),
                Decoded::Imu(s) => pairer.push_imu(m.log_time_ns, s),
                Decoded::Velocity(s) => pairer.push_velocity(m.log_time_ns, s),
                Decoded::Transforms {
                    transforms,
                    is_static,
                } => {
                    pairer.push_transforms(&transforms, is_static);
                    Vec::new()
                }
            };
            pairs.extend(events.into_iter().filter_map(|e| {
                if let PairEvent::Pair(p) = e {
                    Some(p)
                } else {
                    None
                }
            }));
            Flow::Continue(())
        })
        .unwrap();
    let config = looming::engine::EngineConfig::default();
    let mut cache = looming::engine::EngineCache::default();
    for pair in pairs.iter().take(5) {
        let started = Instant::now();
        let result = looming::engine::compute_with_cache(pair, &config, &mut cache).unwrap();
        let points = pair.current.points_m.len();
        let elapsed = started.elapsed().as_secs_f64();
        println!(
            "{} points, {} cells: {:.1} ms ({:.0} ns/point)",
            points,
            result.geometry.cells(),
            elapsed * 1e3,
            elapsed * 1e9 / points as f64
        );
    }
}
