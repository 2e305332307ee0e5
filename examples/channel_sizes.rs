//! Raw and zstd-compressed bytes per channel of a log (each channel's messages
//! compressed in 4 MiB blocks, as chunks would be):
//! `cargo run --release --example channel_sizes -- LOG.mcap`.

use std::collections::BTreeMap;

fn main() {
    let path = std::env::args().nth(1).expect("LOG.mcap");
    let input = looming::input::InputFile::open(std::path::Path::new(&path), Default::default())
        .expect("a readable log");
    let topics: BTreeMap<u16, String> = input
        .catalog()
        .channels
        .values()
        .map(|c| (c.id, c.topic.clone()))
        .collect();
    let mut buffers: BTreeMap<u16, Vec<u8>> = BTreeMap::new();
    let mut sizes: BTreeMap<u16, (usize, usize)> = BTreeMap::new();
    let flush = |buffer: &mut Vec<u8>, size: &mut (usize, usize)| {
        size.0 += buffer.len();
        size.1 += zstd::bulk::compress(buffer, 3).unwrap().len();
        buffer.clear();
    };
    input
        .read_records(false, &mut |record| {
            if let looming::input::InputRecord::Message(m) = record {
                let buffer = buffers.entry(m.channel_id).or_default();
                buffer.extend_from_slice(&m.data);
                if buffer.len() > 4 << 20 {
                    flush(buffer, sizes.entry(m.channel_id).or_default());
                }
            }
            looming::input::Flow::Continue(())
        })
        .unwrap();
    for (id, buffer) in &mut buffers {
        flush(buffer, sizes.entry(*id).or_default());
    }
    let total: usize = sizes.values().map(|s| s.1).sum();
    println!(
        "{:<32} {:>12} {:>12} {:>6}",
        "topic", "raw bytes", "zstd bytes", "share"
    );
    for (id, (raw, compressed)) in &sizes {
        println!(
            "{:<32} {:>12} {:>12} {:>5.1}%",
            topics[id],
            raw,
            compressed,
            100.0 * *compressed as f64 / total as f64
        );
    }
}
