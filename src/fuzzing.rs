//! Entry points for the fuzz targets (`fuzz/`) and their corpus replay
//! (`tests/fuzz_corpus.rs`): each takes arbitrary bytes and must return,
//! never panic, never hang and never allocate from an untrusted count.
//! Thin wrappers over the real readers, so that what is fuzzed is what runs.

use std::io::Write;

use crate::decode::{DecodeLimits, MessageKind, WireEncoding, decode};
use crate::input::{Flow, InputFile, InputOptions};

/// Points per scan in the fuzz runs, for the decoders and the KITTI scan
/// reader: fewer than the default 4 M (a fuzzed cloud of 4 M points would
/// only be slow).
const MAX_POINTS: usize = 100_000;

/// The bytes in a temporary file, for the readers that take a path (their
/// size checks are part of what is fuzzed); `None` if it cannot be written.
fn temp_file_holding(data: &[u8]) -> Option<tempfile::NamedTempFile> {
    let mut file = tempfile::NamedTempFile::new().ok()?;
    file.write_all(data).ok()?;
    Some(file)
}

/// The bytes as an MCAP file, read whole: by its index when it has one
/// (`linear` false), else (or when `linear`) record by record.
pub fn mcap_input(data: &[u8], linear: bool) {
    let Some(file) = temp_file_holding(data) else {
        return;
    };
    let Ok(mut input) = InputFile::open(file.path(), InputOptions::default()) else {
        return;
    };
    if linear && input.force_linear("fuzzing".into()).is_err() {
        return;
    }
    let _ = input.read_records(false, &mut |_| Flow::Continue(()));
}

/// One message of `kind`: the first byte picks the wire encoding (CDR or
/// ROS 1; protobuf for a `foxglove.PointCloud`), the rest is the payload.
pub fn message(kind: MessageKind, data: &[u8]) {
    let Some((&selector, payload)) = data.split_first() else {
        return;
    };
    let encoding = match (kind, selector % 2) {
        (MessageKind::FoxglovePointCloud, _) => WireEncoding::Protobuf,
        (_, 0) => WireEncoding::Cdr,
        _ => WireEncoding::Ros1,
    };
    let is_static = selector & 2 != 0;
    let limits = DecodeLimits {
        max_points: MAX_POINTS,
        ..DecodeLimits::default()
    };
    let _ = decode(kind, encoding, is_static, payload, &limits);
}

/// The KITTI readers: the first byte picks the calibration, OXTS or
/// timestamp text parser, or a Velodyne scan file (with ring derivation).
pub fn kitti(data: &[u8]) {
    let Some((&selector, rest)) = data.split_first() else {
        return;
    };
    let text = String::from_utf8_lossy(rest);
    match selector % 4 {
        0 => {
            let _ = crate::kitti::calib::parse_imu_to_velo(&text);
        }
        1 => {
            let _ = crate::kitti::oxts::parse_oxts_line(&text);
        }
        2 => {
            let _ = crate::kitti::timestamps::parse_timestamp(&text);
        }
        _ => velodyne(rest),
    }
}

fn velodyne(data: &[u8]) {
    let Some(file) = temp_file_holding(data) else {
        return;
    };
    if let Ok(points) = crate::kitti::velodyne::read_bin(file.path(), MAX_POINTS) {
        let _ = crate::kitti::velodyne::derive_rings(&points);
    }
}

/// A scenario file's JSON, parsed and validated as `synth` does.
pub fn scenario_json(data: &[u8]) {
    let text = String::from_utf8_lossy(data);
    let _ = crate::synth::scene::parse("fuzz.json", &text);
}
