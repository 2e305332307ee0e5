//! What each way of writing the range images costs, on the images of an
//! annotated log: bytes per image as written and after the writer's zstd, and
//! milliseconds per image to encode and to zstd (one thread):
//! `cargo run --release --example image_encoding -- OUT.mcap`.
//! Reads `/looming/image/*` as `foxglove.RawImage` (rgb8, before PNG) or
//! `foxglove.CompressedImage` (png), so it runs on logs of either version.
//! The row `indexed fast, adaptive (written)` is `looming process`'s own
//! encoder.

use std::collections::BTreeMap;
use std::time::Instant;

use image::codecs::png::{CompressionType, FilterType, PngEncoder};
use image::{ExtendedColorType, ImageEncoder};
use looming::annotate::colour;
use looming::annotate::foxglove::{indexed_png, indexed_png_with};
use prost::Message;

/// One range image: its pixels and their palette indexes.
struct RangeImage {
    width: u32,
    height: u32,
    rgb: Vec<u8>,
    indexes: Vec<u8>,
}

fn range_image(schema: &str, data: &[u8]) -> RangeImage {
    use foxglove::messages::{CompressedImage, RawImage};
    let (width, height, rgb) = if schema == "foxglove.RawImage" {
        let raw = RawImage::decode(data).expect("a RawImage");
        (raw.width, raw.height, raw.data.to_vec())
    } else {
        let compressed = CompressedImage::decode(data).expect("a CompressedImage");
        let decoded = image::load_from_memory(&compressed.data)
            .expect("a PNG")
            .to_rgb8();
        (decoded.width(), decoded.height(), decoded.into_raw())
    };
    let palette = colour::image_palette();
    let indexes = rgb
        .chunks_exact(3)
        .map(|p| {
            let at = palette.iter().position(|c| c[..] == *p);
            at.expect("range images hold palette colours only") as u8
        })
        .collect();
    RangeImage {
        width,
        height,
        rgb,
        indexes,
    }
}

fn rgb_png(image: &RangeImage, compression: CompressionType, filter: FilterType) -> Vec<u8> {
    let mut out = Vec::new();
    PngEncoder::new_with_quality(&mut out, compression, filter)
        .write_image(
            &image.rgb,
            image.width,
            image.height,
            ExtendedColorType::Rgb8,
        )
        .expect("encodes");
    out
}

fn indexed(image: &RangeImage, compression: png::Compression, filter: png::Filter) -> Vec<u8> {
    let (rows, cols) = (image.height as usize, image.width as usize);
    indexed_png_with(rows, cols, &image.indexes, compression, filter).expect("encodes")
}

/// Bytes after zstd-3 over blocks of ten images (about the writer's 4 MiB
/// chunks of raw images; as `channel_sizes`), and ms per image to compress.
fn zstd(blobs: &[Vec<u8>]) -> (usize, f64) {
    let started = Instant::now();
    let bytes = blobs
        .chunks(10)
        .map(|c| {
            zstd::bulk::compress(&c.concat(), 3)
                .expect("compresses")
                .len()
        })
        .sum();
    let ms = started.elapsed().as_secs_f64() * 1e3 / blobs.len() as f64;
    (bytes, ms)
}

fn row(name: &str, blobs: &[Vec<u8>], encode_ms: Option<f64>) {
    let count = blobs.len() as f64;
    let bytes: usize = blobs.iter().map(Vec::len).sum();
    let (zstd_bytes, zstd_ms) = zstd(blobs);
    println!(
        "| {name} | {:.0} | {:.0} | {} | {zstd_ms:.2} |",
        bytes as f64 / count,
        zstd_bytes as f64 / count,
        encode_ms.map_or("-".into(), |ms| format!("{ms:.2}")),
    );
}

fn timed(images: &[RangeImage], encode: impl Fn(&RangeImage) -> Vec<u8>) -> (Vec<Vec<u8>>, f64) {
    let started = Instant::now();
    let blobs: Vec<Vec<u8>> = images.iter().map(encode).collect();
    let ms = started.elapsed().as_secs_f64() * 1e3 / images.len() as f64;
    (blobs, ms)
}

/// Every range image in the log at `path`, in log order.
fn read_range_images(path: &str) -> Vec<RangeImage> {
    let input = looming::input::InputFile::open(std::path::Path::new(path), Default::default())
        .expect("a readable log");
    let channels: BTreeMap<u16, String> = input
        .catalog()
        .channels
        .values()
        .filter(|c| c.topic.starts_with("/looming/image/"))
        .map(|c| {
            (
                c.id,
                c.schema.as_ref().map_or(String::new(), |s| s.name.clone()),
            )
        })
        .collect();
    let mut images = Vec::new();
    input
        .read_records(false, &mut |record| {
            if let looming::input::InputRecord::Message(m) = record
                && let Some(schema) = channels.get(&m.channel_id)
            {
                images.push(range_image(schema, &m.data));
            }
            looming::input::Flow::Continue(())
        })
        .expect("readable");
    images
}

fn main() {
    let path = std::env::args().nth(1).expect("OUT.mcap");
    let images = read_range_images(&path);
    let Some(first) = images.first() else {
        println!("no range images in {path}");
        return;
    };
    println!(
        "{} images of {} x {}",
        images.len(),
        first.width,
        first.height
    );
    println!("| encoding | bytes/image | after zstd | encode ms | zstd ms |");
    println!("|---|---|---|---|---|");
    let raw: Vec<Vec<u8>> = images.iter().map(|i| i.rgb.clone()).collect();
    row("RawImage rgb8", &raw, None);
    let (written, ms) = timed(&images, |i| {
        let (rows, cols) = (i.height as usize, i.width as usize);
        indexed_png(rows, cols, &i.indexes).expect("encodes")
    });
    row("indexed fast, adaptive (written)", &written, Some(ms));
    let indexed_settings = [
        (
            "indexed fast, no filter",
            png::Compression::Fast,
            png::Filter::NoFilter,
        ),
        (
            "indexed fast, sub",
            png::Compression::Fast,
            png::Filter::Sub,
        ),
        (
            "indexed balanced, no filter",
            png::Compression::Balanced,
            png::Filter::NoFilter,
        ),
    ];
    for (name, compression, filter) in indexed_settings {
        let (blobs, ms) = timed(&images, |i| indexed(i, compression, filter));
        row(name, &blobs, Some(ms));
    }
    let rgb_settings = [
        ("rgb8 fast, sub", CompressionType::Fast, FilterType::Sub),
        (
            "rgb8 fast, adaptive",
            CompressionType::Fast,
            FilterType::Adaptive,
        ),
        (
            "rgb8 default, adaptive",
            CompressionType::Default,
            FilterType::Adaptive,
        ),
    ];
    for (name, compression, filter) in rgb_settings {
        let (blobs, ms) = timed(&images, |i| rgb_png(i, compression, filter));
        row(name, &blobs, Some(ms));
    }
}
