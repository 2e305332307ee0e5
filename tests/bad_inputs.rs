//! The catalogue of bad inputs (`docs/bad-inputs.md`), one test per line of
//! it, each through the real CLI: what the tool does with the input, its exit
//! code, what it says (file, topic, time, cause where they apply) and what it
//! keeps. Common to all: nothing panics, no temporary file is left behind,
//! and every message of the input that can be read is in the output.

mod common;

use std::path::{Path, PathBuf};

use common::{looming, scratch, stderr};
use looming::ros::msgs::PointCloud2;
use looming::testkit::{DriveSpec, drive_log};

/// The catalogue's case ids, in its order; `docs/bad-inputs.md` lists the
/// same, and each has a test named after it.
const CASES: &[&str] = &[
    "zero-length-file",
    "random-bytes",
    "directory-as-input",
    "missing-file",
    "truncated-at-every-record-boundary",
    "truncated-mid-record",
    "bad-chunk-crc",
    "bad-data-section-crc",
    "summary-past-the-end",
    "huge-chunk-uncompressed-size",
    "record-of-1-gib-in-a-600-byte-file",
    "chunk-of-1-gib-in-a-240-byte-file",
    "message-index-past-the-chunk",
    "channel-with-unknown-schema",
    "schema-with-unknown-encoding",
    "channel-with-unknown-message-encoding",
    "unknown-chunk-compression",
    "pointcloud2-size-overflows",
    "pointcloud2-size-disagrees-with-data",
    "pointcloud2-field-past-point-step",
    "pointcloud2-fields-overlap",
    "pointcloud2-row-step-too-small",
    "pointcloud2-huge-frame-id-length",
    "nan-and-inf-points",
    "nan-and-inf-imu-rates",
    "stamp-nanoseconds-out-of-range",
    "stamps-going-backwards",
    "scan-every-5-minutes",
    "duplicated-scans",
    "ten-million-points-in-one-message",
    "empty-scan",
    "imu-at-0-hz",
    "imu-at-10-khz",
    "tf-cycle",
    "extrinsic-non-unit-quaternion",
    "output-in-read-only-place",
    "output-on-a-full-disk",
    "output-is-input-via-symlink",
    "output-is-input-via-hard-link",
    "sigint-mid-run",
];

/// What a run of the CLI did.
struct Outcome {
    code: Option<i32>,
    stderr: String,
    /// `--json-summary`, when the run wrote one.
    summary: Option<serde_json::Value>,
    output: PathBuf,
}

/// `process INPUT -o DIR/out.mcap --json-summary DIR/summary.json EXTRA`.
fn process(dir: &Path, input: &Path, extra: &[&str]) -> Outcome {
    let output = dir.join("out.mcap");
    let summary_path = dir.join("summary.json");
    let _ = std::fs::remove_file(&summary_path);
    let mut args = vec![
        "process",
        input.to_str().unwrap(),
        "-o",
        output.to_str().unwrap(),
        "--force",
        "--json-summary",
        summary_path.to_str().unwrap(),
    ];
    args.extend_from_slice(extra);
    let run = looming(&args);
    let outcome = Outcome {
        code: run.status.code(),
        stderr: stderr(&run),
        summary: std::fs::read(&summary_path)
            .ok()
            .and_then(|b| serde_json::from_slice(&b).ok()),
        output,
    };
    assert_sane(dir, &outcome);
    outcome
}

/// No panic, an exit code of the documented ones, no temporary file left.
fn assert_sane(dir: &Path, outcome: &Outcome) {
    assert!(
        !outcome.stderr.contains("panicked"),
        "panic: {}",
        outcome.stderr
    );
    assert!(
        matches!(outcome.code, Some(0..=3)),
        "exit {:?}: {}",
        outcome.code,
        outcome.stderr
    );
    let mut leftovers = Vec::new();
    for entry in std::fs::read_dir(dir).unwrap() {
        let name = entry.unwrap().file_name().to_string_lossy().into_owned();
        if name.contains(".tmp") {
            leftovers.push(name);
        }
    }
    assert!(leftovers.is_empty(), "temporary files left: {leftovers:?}");
}

/// Every message the mcap crate reads from `input` without checking CRCs
/// (stopping at the first error) is in `output`.
fn assert_keeps_what_can_be_read(input: &[u8], output: &Path) {
    let readable: Vec<(u16, u32, u64, Vec<u8>)> = match mcap::MessageStream::new(input) {
        Ok(stream) => stream
            .map_while(Result::ok)
            .map(|m| (m.channel.id, m.sequence, m.log_time, m.data.into_owned()))
            .collect(),
        Err(_) => Vec::new(),
    };
    let written = std::fs::read(output).unwrap();
    let kept: std::collections::BTreeSet<(u16, u32, u64, Vec<u8>)> =
        mcap::MessageStream::new(&written)
            .unwrap()
            .map(|m| {
                let m = m.unwrap();
                (m.channel.id, m.sequence, m.log_time, m.data.into_owned())
            })
            .collect();
    let lost = readable.iter().filter(|m| !kept.contains(*m)).count();
    assert_eq!(
        lost,
        0,
        "{lost} of {} readable messages lost",
        readable.len()
    );
}

/// The small drive every case starts from: 6 scans of 16 x 256 towards a
/// wall, IMU, twist, `/tf_static`, a metadata record and an attachment.
fn drive_spec() -> DriveSpec {
    DriveSpec {
        scans: 6,
        ..DriveSpec::default()
    }
}

fn write_input(dir: &Path, bytes: &[u8]) -> PathBuf {
    let path = dir.join("in.mcap");
    std::fs::write(&path, bytes).unwrap();
    path
}

fn summary_count(outcome: &Outcome, key: &str) -> u64 {
    outcome.summary.as_ref().unwrap()[key].as_u64().unwrap()
}

/// The drive with each LiDAR message's cloud through `edit` (scan index,
/// cloud); `None` drops the scan.
fn with_scans(
    dir: &Path,
    spec: &DriveSpec,
    mut edit: impl FnMut(usize, PointCloud2<'static>) -> Option<PointCloud2<'static>>,
) -> PathBuf {
    let base = dir.join("base.mcap");
    std::fs::write(&base, drive_log(spec)).unwrap();
    let input = dir.join("in.mcap");
    let mut scan = 0;
    common::rewrite_mcap(&base, &input, |mut message| {
        if message.channel.topic != "/sensing/lidar/points" {
            return Some(message);
        }
        let cloud = PointCloud2::decode_cdr(&message.data).unwrap().into_owned();
        let edited = edit(scan, cloud)?;
        scan += 1;
        message.data = std::borrow::Cow::Owned(edited.encode_cdr(false));
        Some(message)
    });
    input
}

// ---- files that are not logs ----------------------------------------------

#[test]
fn zero_length_file() {
    let dir = scratch("bad-zero-length");
    let input = write_input(&dir, b"");
    let run = process(&dir, &input, &[]);
    assert_eq!(run.code, Some(1));
    assert!(run.stderr.contains("in.mcap"), "{}", run.stderr);
    assert!(!run.output.exists());
}

#[test]
fn random_bytes() {
    let dir = scratch("bad-random");
    let bytes: Vec<u8> = (0..100_000u32)
        .map(|i| (i.wrapping_mul(2_654_435_761) >> 13) as u8)
        .collect();
    let input = write_input(&dir, &bytes);
    let run = process(&dir, &input, &[]);
    assert_eq!(run.code, Some(1));
    assert!(
        run.stderr.contains("in.mcap") && run.stderr.contains("not an MCAP file"),
        "{}",
        run.stderr
    );
    assert!(!run.output.exists());
}

#[test]
fn directory_as_input() {
    let dir = scratch("bad-directory");
    let input = dir.join("a-folder.mcap");
    std::fs::create_dir_all(&input).unwrap();
    let run = process(&dir, &input, &[]);
    assert!(matches!(run.code, Some(1 | 2)));
    assert!(run.stderr.contains("a-folder.mcap"), "{}", run.stderr);
    assert!(
        run.stderr.to_lowercase().contains("directory"),
        "{}",
        run.stderr
    );
}

#[test]
fn missing_file() {
    let dir = scratch("bad-missing");
    let run = process(&dir, &dir.join("nope.mcap"), &[]);
    assert_eq!(run.code, Some(1));
    assert!(run.stderr.contains("nope.mcap"), "{}", run.stderr);
}

// ---- damaged MCAP structure -----------------------------------------------

/// Each top-level record of an MCAP file: its offset, opcode and the range
/// of its body.
fn records(bytes: &[u8]) -> Vec<(usize, u8, std::ops::Range<usize>)> {
    let mut found = Vec::new();
    let mut at = 8;
    while at + 9 <= bytes.len() - 8 {
        let opcode = bytes[at];
        let len = u64::from_le_bytes(bytes[at + 1..at + 9].try_into().unwrap()) as usize;
        found.push((at, opcode, at + 9..at + 9 + len));
        at += 9 + len;
    }
    found
}

const OP_CHUNK: u8 = 0x06;
const OP_MESSAGE_INDEX: u8 = 0x07;
const OP_DATA_END: u8 = 0x0F;
const OP_FOOTER: u8 = 0x02;

/// Run a cut-down copy of `bytes` (its first `len` bytes).
fn process_cut(dir: &Path, bytes: &[u8], len: usize) -> Outcome {
    let input = write_input(dir, &bytes[..len]);
    let run = process(dir, &input, &[]);
    if run.code == Some(0) {
        assert_keeps_what_can_be_read(&bytes[..len], &run.output);
    }
    run
}

#[test]
fn truncated_at_every_record_boundary() {
    let dir = scratch("bad-truncated-boundary");
    let bytes = drive_log(&drive_spec());
    let boundaries: Vec<usize> = records(&bytes).iter().map(|r| r.0).collect();
    let mut outcomes = std::collections::BTreeMap::new();
    for &cut in &boundaries {
        let run = process_cut(&dir, &bytes, cut);
        *outcomes.entry(run.code).or_insert(0) += 1;
        if run.code == Some(0) && cut < bytes.len() - 8 {
            let truncated = &run.summary.as_ref().unwrap()["input_report"]["truncated"];
            assert!(
                truncated.is_string() || cut >= data_end(&bytes),
                "cut at {cut}: {truncated}"
            );
        }
    }
    println!("{} cuts: exit codes {outcomes:?}", boundaries.len());
    // A cut before the first chunk (header, metadata and attachment only)
    // leaves no channel: no LiDAR topic, exit 2. Every later cut is processed.
    let before_channels = boundaries
        .iter()
        .filter(|&&cut| cut <= first_chunk_offset(&bytes))
        .count();
    assert_eq!(
        outcomes.get(&Some(2)).copied().unwrap_or(0),
        before_channels,
        "{outcomes:?}"
    );
    assert_eq!(
        outcomes[&Some(0)],
        boundaries.len() - before_channels,
        "{outcomes:?}"
    );
}

/// Where the first chunk starts: the drive log's schema and channel records
/// are in it, with its first messages.
fn first_chunk_offset(bytes: &[u8]) -> usize {
    records(bytes).iter().find(|r| r.1 == OP_CHUNK).unwrap().0
}

/// Where the data section ends (the DataEnd record's offset).
fn data_end(bytes: &[u8]) -> usize {
    records(bytes)
        .iter()
        .find(|r| r.1 == OP_DATA_END)
        .unwrap()
        .0
}

#[test]
fn truncated_mid_record() {
    let dir = scratch("bad-truncated-mid");
    let bytes = drive_log(&drive_spec());
    let mut ok = 0;
    let mut expected = 0;
    let all = records(&bytes);
    let first_chunk_end = all.iter().find(|r| r.1 == OP_CHUNK).unwrap().2.end;
    for (at, _, body) in &all {
        for cut in [at + 4, (body.start + body.end) / 2] {
            let cut = cut.min(bytes.len() - 1);
            let run = process_cut(&dir, &bytes, cut);
            ok += usize::from(run.code == Some(0));
            // A cut inside the first chunk leaves no channel (they are in it).
            expected += usize::from(cut >= first_chunk_end);
        }
    }
    println!("{ok} of {} cuts processed", 2 * all.len());
    assert!(ok >= expected, "{ok} processed, {expected} expected");
}

/// The first chunk's body range and the offsets of its fields.
struct ChunkFields {
    uncompressed_size: usize,
    uncompressed_crc: usize,
}

fn first_chunk(bytes: &[u8]) -> ChunkFields {
    let (_, _, body) = records(bytes)
        .into_iter()
        .find(|r| r.1 == OP_CHUNK)
        .expect("a chunked log");
    ChunkFields {
        uncompressed_size: body.start + 16,
        uncompressed_crc: body.start + 24,
    }
}

fn put_u64(bytes: &mut [u8], at: usize, value: u64) {
    bytes[at..at + 8].copy_from_slice(&value.to_le_bytes());
}

/// Run a damaged drive; print what the tool said (for the catalogue).
fn process_damaged(dir: &Path, bytes: &[u8], extra: &[&str]) -> Outcome {
    let input = write_input(dir, bytes);
    let run = process(dir, &input, extra);
    println!("exit {:?}\n{}", run.code, run.stderr);
    run
}

#[test]
fn bad_chunk_crc() {
    let dir = scratch("bad-chunk-crc");
    let mut bytes = drive_log(&drive_spec());
    let chunk = first_chunk(&bytes);
    bytes[chunk.uncompressed_crc] ^= 0xff;
    // Not checked unless asked: the chunk's records are intact.
    let run = process_damaged(&dir, &bytes, &[]);
    assert_eq!(run.code, Some(0));
    assert_keeps_what_can_be_read(&bytes, &run.output);
    let verified = process_damaged(&dir, &bytes, &["--verify"]);
    assert_eq!(verified.code, Some(0));
    assert!(verified.stderr.contains("CRC"), "{}", verified.stderr);
    assert_keeps_what_can_be_read(&bytes, &verified.output);
    let strict = process_damaged(&dir, &bytes, &["--verify", "--strict"]);
    assert_eq!(strict.code, Some(3));
}

#[test]
fn bad_data_section_crc() {
    let dir = scratch("bad-data-crc");
    let mut bytes = drive_log(&drive_spec());
    let (_, _, body) = records(&bytes)
        .into_iter()
        .find(|r| r.1 == OP_DATA_END)
        .unwrap();
    bytes[body.start] ^= 0xff;
    let run = process_damaged(&dir, &bytes, &[]);
    assert_eq!(run.code, Some(0));
    assert_keeps_what_can_be_read(&bytes, &run.output);
}

#[test]
fn summary_past_the_end() {
    let dir = scratch("bad-summary-past-end");
    let mut bytes = drive_log(&drive_spec());
    let (_, _, body) = records(&bytes)
        .into_iter()
        .find(|r| r.1 == OP_FOOTER)
        .unwrap();
    let past = bytes.len() as u64 * 4;
    put_u64(&mut bytes, body.start, past);
    let run = process_damaged(&dir, &bytes, &[]);
    assert_eq!(run.code, Some(0));
    assert!(run.stderr.contains("linear"), "{}", run.stderr);
    assert_keeps_what_can_be_read(&bytes, &run.output);
}

#[test]
fn huge_chunk_uncompressed_size() {
    let dir = scratch("bad-huge-chunk");
    let mut bytes = drive_log(&drive_spec());
    let chunk = first_chunk(&bytes);
    put_u64(&mut bytes, chunk.uncompressed_size, 1 << 60);
    let run = process_damaged(&dir, &bytes, &[]);
    assert_eq!(run.code, Some(0));
}

#[test]
fn message_index_past_the_chunk() {
    let dir = scratch("bad-message-index");
    let mut bytes = drive_log(&drive_spec());
    let (_, _, body) = records(&bytes)
        .into_iter()
        .find(|r| r.1 == OP_MESSAGE_INDEX)
        .unwrap();
    // channel id (2), entries' byte length (4), then (log time, offset).
    put_u64(&mut bytes, body.start + 6 + 8, u64::MAX / 2);
    let run = process_damaged(&dir, &bytes, &[]);
    assert_eq!(run.code, Some(0));
    assert_keeps_what_can_be_read(&bytes, &run.output);
}

#[test]
fn unknown_chunk_compression() {
    let dir = scratch("bad-compression");
    let mut bytes = drive_log(&drive_spec());
    // Every chunk's compression renamed (same length, so the framing holds).
    let chunks: Vec<usize> = records(&bytes)
        .iter()
        .filter(|r| r.1 == OP_CHUNK)
        .map(|r| r.2.start + 28)
        .collect();
    for at in chunks {
        let len = u32::from_le_bytes(bytes[at..at + 4].try_into().unwrap()) as usize;
        for b in &mut bytes[at + 4..at + 4 + len] {
            *b = b'q';
        }
    }
    // The summary's chunk indexes name the compression too: without a
    // summary, the chunks' own headers are all there is.
    let (_, _, footer) = records(&bytes)
        .into_iter()
        .find(|r| r.1 == OP_FOOTER)
        .unwrap();
    put_u64(&mut bytes, footer.start, 0);
    let run = process_damaged(&dir, &bytes, &[]);
    // Its channels are inside the chunks: no LiDAR can be found, and the
    // error says why.
    assert_eq!(run.code, Some(2));
    assert!(
        run.stderr.contains("could not be read to its end") && run.stderr.contains("compression"),
        "{}",
        run.stderr
    );
    let copied = process_damaged(&dir, &bytes, &["--if-no-lidar", "copy"]);
    assert_eq!(copied.code, Some(0));
    assert!(copied.stderr.contains("compression"), "{}", copied.stderr);
}

// ---- bad messages -----------------------------------------------------------

/// A drive whose third scan is `edit`ed: one bad message, skipped, counted
/// and named (topic, log time, cause); everything kept.
fn one_bad_scan(name: &str, edit: impl Fn(&mut PointCloud2<'static>)) -> Outcome {
    let dir = scratch(name);
    let input = with_scans(&dir, &drive_spec(), |i, mut cloud| {
        if i == 2 {
            edit(&mut cloud);
        }
        Some(cloud)
    });
    let run = process(&dir, &input, &[]);
    println!("exit {:?}\n{}", run.code, run.stderr);
    assert_eq!(run.code, Some(0), "{}", run.stderr);
    assert_eq!(summary_count(&run, "bad_messages"), 1, "{}", run.stderr);
    assert!(
        run.stderr.contains("/sensing/lidar/points"),
        "{}",
        run.stderr
    );
    assert!(run.stderr.contains("log time"), "{}", run.stderr);
    assert_keeps_what_can_be_read(&std::fs::read(&input).unwrap(), &run.output);
    let strict = process(&dir, &input, &["--strict"]);
    assert_eq!(strict.code, Some(3), "{}", strict.stderr);
    run
}

#[test]
fn pointcloud2_size_overflows() {
    one_bad_scan("bad-pc2-overflow", |cloud| {
        cloud.width = u32::MAX;
        cloud.height = u32::MAX;
        cloud.row_step = u32::MAX;
    });
}

#[test]
fn pointcloud2_size_disagrees_with_data() {
    one_bad_scan("bad-pc2-short", |cloud| {
        let half = cloud.data.len() / 2;
        cloud.data.to_mut().truncate(half);
    });
}

#[test]
fn pointcloud2_field_past_point_step() {
    one_bad_scan("bad-pc2-field-past", |cloud| {
        cloud.fields[2].offset = cloud.point_step - 2;
    });
}

#[test]
fn pointcloud2_fields_overlap() {
    one_bad_scan("bad-pc2-overlap", |cloud| {
        cloud.fields[1].offset = 2;
    });
}

#[test]
fn pointcloud2_row_step_too_small() {
    // An organised cloud (two rows) whose rows would overlap. (A single
    // row's row_step is not used: drivers leave it 0 there.)
    one_bad_scan("bad-pc2-row-step", |cloud| {
        let width = cloud.width;
        cloud.height = 2;
        cloud.width = width / 2;
        cloud.row_step = 1;
    });
}

#[test]
fn pointcloud2_huge_frame_id_length() {
    let dir = scratch("bad-pc2-frame-id");
    let base = dir.join("base.mcap");
    std::fs::write(&base, drive_log(&drive_spec())).unwrap();
    let input = dir.join("in.mcap");
    let mut scan = 0;
    common::rewrite_mcap(&base, &input, |mut message| {
        if message.channel.topic == "/sensing/lidar/points" {
            scan += 1;
            if scan == 3 {
                // CDR: 4-byte encapsulation, stamp (8), then the frame id's
                // length: now 4 GB, in a message of 100 kB.
                let mut data = message.data.into_owned();
                data[12..16].copy_from_slice(&0xFFFF_FFF0u32.to_le_bytes());
                message.data = std::borrow::Cow::Owned(data);
            }
        }
        Some(message)
    });
    let run = process(&dir, &input, &[]);
    println!("{}", run.stderr);
    assert_eq!(run.code, Some(0));
    assert_eq!(summary_count(&run, "bad_messages"), 1);
    assert_keeps_what_can_be_read(&std::fs::read(&input).unwrap(), &run.output);
}

#[test]
fn nan_and_inf_points() {
    let dir = scratch("bad-nan-points");
    let input = with_scans(&dir, &drive_spec(), |i, mut cloud| {
        if i == 2 {
            let step = cloud.point_step as usize;
            let data = cloud.data.to_mut();
            for (n, point) in data.chunks_mut(step).enumerate().take(500) {
                let value = if n % 2 == 0 { f32::NAN } else { f32::INFINITY };
                point[0..4].copy_from_slice(&value.to_le_bytes());
            }
        }
        Some(cloud)
    });
    let run = process(&dir, &input, &[]);
    println!("{}", run.stderr);
    assert_eq!(run.code, Some(0));
    let invalid = run.summary.as_ref().unwrap()["decoded"]["invalid_points_skipped"].as_u64();
    assert!(invalid >= Some(500), "{invalid:?}");
    assert_keeps_what_can_be_read(&std::fs::read(&input).unwrap(), &run.output);
}

/// The drive with every message on `topic` through `edit` (its index among
/// them, the message); `None` drops it, extra messages may be returned.
fn with_messages(
    dir: &Path,
    topic: &str,
    mut edit: impl FnMut(usize, mcap::Message<'static>) -> Vec<mcap::Message<'static>>,
) -> PathBuf {
    let base = dir.join("base.mcap");
    std::fs::write(&base, drive_log(&drive_spec())).unwrap();
    let input = dir.join("in.mcap");
    let bytes = std::fs::read(&base).unwrap();
    let mut writer = mcap::WriteOptions::new()
        .profile("ros2")
        .create(std::io::BufWriter::new(
            std::fs::File::create(&input).unwrap(),
        ))
        .unwrap();
    let mut index = 0;
    for message in mcap::MessageStream::new(&bytes).unwrap() {
        let message = message.unwrap();
        let message = mcap::Message {
            channel: message.channel.clone(),
            sequence: message.sequence,
            log_time: message.log_time,
            publish_time: message.publish_time,
            data: std::borrow::Cow::Owned(message.data.into_owned()),
        };
        let out = if message.channel.topic == topic {
            index += 1;
            edit(index - 1, message)
        } else {
            vec![message]
        };
        for m in out {
            writer.write(&m).unwrap();
        }
    }
    writer.finish().unwrap();
    input
}

fn imu_with(message: &mcap::Message<'_>, edit: impl Fn(&mut looming::ros::msgs::Imu)) -> Vec<u8> {
    let mut imu = looming::ros::msgs::Imu::decode_cdr(&message.data).unwrap();
    edit(&mut imu);
    imu.encode_cdr(false)
}

#[test]
fn nan_and_inf_imu_rates() {
    let dir = scratch("bad-nan-imu");
    let input = with_messages(&dir, "/sensing/imu", |i, mut message| {
        if i == 20 {
            message.data = std::borrow::Cow::Owned(imu_with(&message, |imu| {
                imu.angular_velocity.z = f64::NAN;
            }));
        }
        if i == 21 {
            message.data = std::borrow::Cow::Owned(imu_with(&message, |imu| {
                imu.angular_velocity.x = f64::INFINITY;
            }));
        }
        vec![message]
    });
    let run = process(&dir, &input, &[]);
    println!("{}", run.stderr);
    assert_eq!(run.code, Some(0));
    assert_eq!(summary_count(&run, "bad_messages"), 2, "{}", run.stderr);
    assert!(run.stderr.contains("/sensing/imu"), "{}", run.stderr);
    assert_keeps_what_can_be_read(&std::fs::read(&input).unwrap(), &run.output);
}

#[test]
fn stamp_nanoseconds_out_of_range() {
    let dir = scratch("bad-stamp-nanosec");
    let input = with_scans(&dir, &drive_spec(), |i, mut cloud| {
        if i == 2 {
            cloud.header.stamp.nanosec = 3_000_000_000;
        }
        Some(cloud)
    });
    let run = process(&dir, &input, &[]);
    println!("{}", run.stderr);
    assert_eq!(run.code, Some(0));
    assert_eq!(summary_count(&run, "bad_messages"), 1, "{}", run.stderr);
    assert!(run.stderr.contains("nanoseconds"), "{}", run.stderr);
    assert_keeps_what_can_be_read(&std::fs::read(&input).unwrap(), &run.output);
}

/// The scans' header stamps through `stamp_ns(scan index, stamp)`.
fn with_stamps(dir: &Path, stamp_ns: impl Fn(usize, i64) -> i64) -> PathBuf {
    with_scans(dir, &drive_spec(), |i, mut cloud| {
        let ns = stamp_ns(i, cloud.header.stamp.to_ns());
        cloud.header.stamp = looming::ros::msgs::Time::from_ns(ns);
        Some(cloud)
    })
}

fn pairing(run: &Outcome) -> &serde_json::Value {
    &run.summary.as_ref().unwrap()["pairing"]
}

#[test]
fn stamps_going_backwards() {
    let dir = scratch("bad-stamps-backwards");
    let input = with_stamps(&dir, |i, ns| ns - 2 * i as i64 * 100_000_000);
    let run = process(&dir, &input, &[]);
    println!("{}\n{}", run.stderr, pairing(&run));
    assert_eq!(run.code, Some(0));
    assert_eq!(summary_count(&run, "pairs_written"), 0, "{}", run.stderr);
    assert_keeps_what_can_be_read(&std::fs::read(&input).unwrap(), &run.output);
}

#[test]
fn scan_every_5_minutes() {
    let dir = scratch("bad-gap");
    let input = with_stamps(&dir, |i, ns| ns + i as i64 * 300_000_000_000);
    let run = process(&dir, &input, &[]);
    println!("{}\n{}", run.stderr, pairing(&run));
    assert_eq!(run.code, Some(0));
    assert_eq!(summary_count(&run, "pairs_written"), 0, "{}", run.stderr);
    assert!(run.stderr.contains("gap"), "{}", run.stderr);
}

#[test]
fn duplicated_scans() {
    let dir = scratch("bad-duplicates");
    let mut previous = None;
    let input = with_scans(&dir, &drive_spec(), |i, cloud| {
        let out = if i == 3 {
            previous.clone().unwrap()
        } else {
            cloud
        };
        previous = Some(out.clone());
        Some(out)
    });
    let run = process(&dir, &input, &[]);
    println!("{}\n{}", run.stderr, pairing(&run));
    assert_eq!(run.code, Some(0));
    assert_eq!(summary_count(&run, "pairs_written"), 4, "{}", run.stderr);
    assert!(run.stderr.contains("1 dt<=0"), "{}", run.stderr);
}

#[test]
fn ten_million_points_in_one_message() {
    let dir = scratch("bad-ten-million");
    let input = with_scans(&dir, &drive_spec(), |i, mut cloud| {
        if i == 2 {
            let points = 10_000_000usize;
            cloud.width = points as u32;
            cloud.height = 1;
            cloud.row_step = cloud.point_step * cloud.width;
            cloud.data = std::borrow::Cow::Owned(vec![0; points * cloud.point_step as usize]);
        }
        Some(cloud)
    });
    let run = process(&dir, &input, &[]);
    println!("{}", run.stderr);
    assert_eq!(run.code, Some(0));
    assert_eq!(summary_count(&run, "bad_messages"), 1, "{}", run.stderr);
    assert!(
        run.stderr.contains("max-points") || run.stderr.contains("points"),
        "{}",
        run.stderr
    );
    assert_keeps_what_can_be_read(&std::fs::read(&input).unwrap(), &run.output);
}

#[test]
fn empty_scan() {
    let dir = scratch("bad-empty-scan");
    let input = with_scans(&dir, &drive_spec(), |i, mut cloud| {
        if i == 2 {
            cloud.width = 0;
            cloud.row_step = 0;
            cloud.data = std::borrow::Cow::Owned(Vec::new());
        }
        Some(cloud)
    });
    let run = process(&dir, &input, &[]);
    println!("{}\n{}", run.stderr, pairing(&run));
    assert_eq!(run.code, Some(0));
    assert_keeps_what_can_be_read(&std::fs::read(&input).unwrap(), &run.output);
}

#[test]
fn imu_at_0_hz() {
    let dir = scratch("bad-imu-0hz");
    // One IMU message at the start, then none.
    let input = with_messages(
        &dir,
        "/sensing/imu",
        |i, m| if i == 0 { vec![m] } else { vec![] },
    );
    let run = process(&dir, &input, &[]);
    println!("{}\n{}", run.stderr, pairing(&run));
    assert_eq!(run.code, Some(0));
    assert_eq!(summary_count(&run, "pairs_written"), 5);
    assert_keeps_what_can_be_read(&std::fs::read(&input).unwrap(), &run.output);
}

#[test]
fn imu_at_10_khz() {
    let dir = scratch("bad-imu-10khz");
    // Each 100 Hz message becomes 100, 0.1 ms apart.
    let input = with_messages(&dir, "/sensing/imu", |_, m| {
        (0..100u64)
            .map(|k| {
                let data = imu_with(&m, |imu| {
                    let ns = imu.header.stamp.to_ns() + k as i64 * 100_000;
                    imu.header.stamp = looming::ros::msgs::Time::from_ns(ns);
                });
                mcap::Message {
                    channel: m.channel.clone(),
                    sequence: m.sequence * 100 + k as u32,
                    log_time: m.log_time + k * 100_000,
                    publish_time: m.publish_time + k * 100_000,
                    data: std::borrow::Cow::Owned(data),
                }
            })
            .collect()
    });
    let run = process(&dir, &input, &[]);
    println!("{}\n{}", run.stderr, pairing(&run));
    assert_eq!(run.code, Some(0));
    assert_eq!(summary_count(&run, "pairs_written"), 5);
    assert_keeps_what_can_be_read(&std::fs::read(&input).unwrap(), &run.output);
}

#[test]
fn tf_cycle() {
    use looming::ros::msgs::{Header, Quaternion, TFMessage, Transform, TransformStamped, Vector3};
    let dir = scratch("bad-tf-cycle");
    let edge = |parent: &str, child: &str| TransformStamped {
        header: Header::new(1_700_000_000_000_000_000, parent),
        child_frame_id: child.into(),
        transform: Transform {
            translation: Vector3::new(1.0, 0.0, 0.0),
            rotation: Quaternion {
                x: 0.0,
                y: 0.0,
                z: 0.0,
                w: 1.0,
            },
        },
    };
    let input = with_messages(&dir, "/tf_static", |_, mut m| {
        let cycle = TFMessage {
            transforms: vec![
                edge("base_link", "lidar_top"),
                edge("lidar_top", "imu_link"),
                edge("imu_link", "base_link"),
            ],
        };
        m.data = std::borrow::Cow::Owned(cycle.encode_cdr(false));
        vec![m]
    });
    let run = process(&dir, &input, &[]);
    println!("{}\n{}", run.stderr, pairing(&run));
    assert_eq!(run.code, Some(0));
    assert_keeps_what_can_be_read(&std::fs::read(&input).unwrap(), &run.output);
}

#[test]
fn extrinsic_non_unit_quaternion() {
    let dir = scratch("bad-extrinsic");
    let input = write_input(&dir, &drive_log(&drive_spec()));
    // Norm 2: the same rotation, normalised.
    let run = process(&dir, &input, &["--extrinsic", "1.2,0,1.8,0,0,0,2"]);
    assert_eq!(run.code, Some(0), "{}", run.stderr);
    // No rotation at all: refused.
    let zero = process(&dir, &input, &["--extrinsic", "1.2,0,1.8,0,0,0,0"]);
    assert_eq!(zero.code, Some(2));
    assert!(zero.stderr.contains("--extrinsic"), "{}", zero.stderr);
    let nan = process(&dir, &input, &["--extrinsic", "1.2,0,1.8,0,0,0,NaN"]);
    assert_eq!(nan.code, Some(2));
}

/// The drive unchunked (its schema and channel records at the top level),
/// every record of `opcode` whose body starts with id 1 through `patch`.
fn with_records_patched(opcode: u8, patch: impl Fn(&mut [u8])) -> Vec<u8> {
    let mut bytes = drive_log(&DriveSpec {
        layout: looming::testkit::Layout::unchunked(),
        ..drive_spec()
    });
    let targets: Vec<std::ops::Range<usize>> = records(&bytes)
        .into_iter()
        .filter(|r| r.1 == opcode && bytes[r.2.start..r.2.start + 2] == [1, 0])
        .map(|r| r.2)
        .collect();
    assert!(!targets.is_empty());
    for body in targets {
        patch(&mut bytes[body]);
    }
    bytes
}

#[test]
fn channel_with_unknown_schema() {
    let dir = scratch("bad-unknown-schema");
    // Channel: id (2), schema id (2), ...: the LiDAR channel's schema 1 -> 77.
    let bytes = with_records_patched(0x04, |body| {
        body[2..4].copy_from_slice(&77u16.to_le_bytes())
    });
    // Without its schema the channel's messages cannot be told apart from
    // any other bytes: no LiDAR, and the channel is listed.
    let run = process_damaged(&dir, &bytes, &[]);
    assert_eq!(run.code, Some(2), "{}", run.stderr);
    assert!(
        run.stderr.contains("/sensing/lidar/points"),
        "{}",
        run.stderr
    );
    let copied = process_damaged(&dir, &bytes, &["--if-no-lidar", "copy"]);
    assert_eq!(copied.code, Some(0), "{}", copied.stderr);
    assert_keeps_what_can_be_read(&bytes, &copied.output);
}

#[test]
fn schema_with_unknown_encoding() {
    let dir = scratch("bad-schema-encoding");
    // Schema: id (2), name (u32 length + bytes), encoding (u32 length + bytes).
    let bytes = with_records_patched(0x03, |body| {
        let name_len = u32::from_le_bytes(body[2..6].try_into().unwrap()) as usize;
        let at = 6 + name_len;
        let len = u32::from_le_bytes(body[at..at + 4].try_into().unwrap()) as usize;
        for b in &mut body[at + 4..at + 4 + len] {
            *b = b'x';
        }
    });
    // The schema's encoding names the language of its text; the messages
    // are read by their channel's message encoding: processed as usual.
    let run = process_damaged(&dir, &bytes, &[]);
    assert_eq!(run.code, Some(0), "{}", run.stderr);
    assert_eq!(summary_count(&run, "pairs_written"), 5);
    assert_keeps_what_can_be_read(&bytes, &run.output);
}

#[test]
fn channel_with_unknown_message_encoding() {
    let dir = scratch("bad-message-encoding");
    // Channel: id (2), schema id (2), topic (u32 length + bytes), message
    // encoding (u32 length + bytes).
    let bytes = with_records_patched(0x04, |body| {
        let topic_len = u32::from_le_bytes(body[4..8].try_into().unwrap()) as usize;
        let at = 8 + topic_len;
        let len = u32::from_le_bytes(body[at..at + 4].try_into().unwrap()) as usize;
        for b in &mut body[at + 4..at + 4 + len] {
            *b = b'x';
        }
    });
    let run = process_damaged(&dir, &bytes, &[]);
    assert_eq!(run.code, Some(2), "{}", run.stderr);
    assert!(run.stderr.contains("no LiDAR topic") && run.stderr.contains("/sensing/lidar/points"));
    let copied = process_damaged(&dir, &bytes, &["--if-no-lidar", "copy"]);
    assert_eq!(copied.code, Some(0), "{}", copied.stderr);
    assert_keeps_what_can_be_read(&bytes, &copied.output);
}

// ---- where the output goes ----------------------------------------------

fn sample_input(dir: &Path) -> (PathBuf, Vec<u8>) {
    let bytes = drive_log(&drive_spec());
    (write_input(dir, &bytes), bytes)
}

#[test]
fn output_in_read_only_place() {
    let dir = scratch("bad-read-only");
    let (input, bytes) = sample_input(&dir);
    // sysfs refuses new files, even to root (a chmod would not stop root).
    let run = looming(&[
        "process",
        input.to_str().unwrap(),
        "-o",
        "/sys/looming-test.mcap",
    ]);
    assert_eq!(run.status.code(), Some(1));
    assert!(
        stderr(&run).contains("/sys/looming-test.mcap"),
        "{}",
        stderr(&run)
    );
    assert!(!Path::new("/sys/looming-test.mcap").exists());
    assert_eq!(std::fs::read(&input).unwrap(), bytes, "input untouched");
}

#[test]
fn output_on_a_full_disk() {
    let dir = scratch("bad-full-disk");
    let (input, bytes) = sample_input(&dir);
    let small = dir.join("small");
    std::fs::create_dir_all(&small).unwrap();
    // A 64 KiB file system of its own, in a mount namespace of its own (so
    // nothing is left mounted); skipped where mounting is not allowed.
    let script = format!(
        "mount -t tmpfs -o size=64k tmpfs {small} || exit 99; \
         {bin} process {input} -o {small}/out.mcap; code=$?; ls -A {small}; exit $code",
        small = small.display(),
        bin = env!("CARGO_BIN_EXE_looming"),
        input = input.display(),
    );
    let run = std::process::Command::new("unshare")
        .args(["-m", "sh", "-c", &script])
        .output();
    let Ok(run) = run else {
        eprintln!("skipped: no unshare");
        return;
    };
    if run.status.code() == Some(99) || stderr(&run).contains("unshare failed") {
        eprintln!("skipped: cannot mount a tmpfs here: {}", stderr(&run));
        return;
    }
    assert_eq!(run.status.code(), Some(1), "{}", stderr(&run));
    assert!(
        stderr(&run).contains("No space left on device"),
        "{}",
        stderr(&run)
    );
    let listing = String::from_utf8_lossy(&run.stdout);
    assert!(
        listing.trim().is_empty(),
        "left on the full disk: {listing}"
    );
    assert_eq!(std::fs::read(&input).unwrap(), bytes, "input untouched");
}

/// `-o` a second name of the input (made by `link`), with `--force`: refused.
fn assert_second_name_refused(name: &str, link: impl Fn(&Path, &Path) -> std::io::Result<()>) {
    let dir = scratch(name);
    let (input, bytes) = sample_input(&dir);
    let second = dir.join("second.mcap");
    let _ = std::fs::remove_file(&second);
    link(&input, &second).unwrap();
    let run = looming(&[
        "process",
        input.to_str().unwrap(),
        "-o",
        second.to_str().unwrap(),
        "--force",
    ]);
    assert_eq!(run.status.code(), Some(2));
    assert!(
        stderr(&run).contains("must not be the input"),
        "{}",
        stderr(&run)
    );
    assert_eq!(std::fs::read(&input).unwrap(), bytes, "input untouched");
}

#[test]
fn output_is_input_via_symlink() {
    assert_second_name_refused("bad-symlink", |a, b| std::os::unix::fs::symlink(a, b));
}

#[test]
fn output_is_input_via_hard_link() {
    assert_second_name_refused("bad-hard-link", |a, b| std::fs::hard_link(a, b));
}

#[test]
fn sigint_mid_run() {
    let dir = scratch("bad-sigint");
    let input = common::synth(&dir, "cut-in", &["--duration", "8"]);
    let before = std::fs::read(&input).unwrap();
    let output = dir.join("out.mcap");
    let mut child = std::process::Command::new(env!("CARGO_BIN_EXE_looming"))
        .args([
            "process",
            input.to_str().unwrap(),
            "-o",
            output.to_str().unwrap(),
            "-q",
        ])
        .stderr(std::process::Stdio::piped())
        .spawn()
        .unwrap();
    // Once the temporary output exists, the run is writing: interrupt it.
    let started = std::time::Instant::now();
    while !temp_files(&dir) {
        assert!(
            child.try_wait().unwrap().is_none(),
            "ended before it was interrupted"
        );
        assert!(
            started.elapsed().as_secs() < 60,
            "no temporary output appeared"
        );
        std::thread::sleep(std::time::Duration::from_millis(2));
    }
    let kill = std::process::Command::new("kill")
        .args(["-INT", &child.id().to_string()])
        .status()
        .unwrap();
    assert!(kill.success());
    let run = child.wait_with_output().unwrap();
    let text = String::from_utf8_lossy(&run.stderr);
    assert_eq!(run.status.code(), Some(130), "{text}");
    assert!(text.contains("interrupted"), "{text}");
    assert!(!output.exists(), "no output");
    assert!(!temp_files(&dir), "the temporary output was removed");
    assert_eq!(std::fs::read(&input).unwrap(), before, "input untouched");
}

fn temp_files(dir: &Path) -> bool {
    std::fs::read_dir(dir)
        .unwrap()
        .any(|e| e.unwrap().file_name().to_string_lossy().ends_with(".tmp"))
}

// ---- the catalogue itself ----------------------------------------------------

/// `docs/bad-inputs.md` lists exactly [`CASES`], and each has its test here.
#[test]
fn every_case_is_in_the_catalogue_and_has_a_test() {
    let doc = include_str!("../docs/bad-inputs.md");
    let documented: Vec<&str> = doc
        .lines()
        .filter_map(|line| line.strip_prefix("| `"))
        .filter_map(|rest| rest.split('`').next())
        .collect();
    assert_eq!(documented, CASES, "docs/bad-inputs.md and CASES differ");
    let source = include_str!("bad_inputs.rs");
    for case in CASES {
        let test = format!("fn {}()", case.replace('-', "_"));
        assert!(source.contains(&test), "no test {test}");
    }
    assert!(CASES.len() >= 30);
}

// ---- memory under attack -----------------------------------------------------

/// Virtual memory the binary may use in these tests, KiB: far below the
/// 1 GiB a crafted length asks for, well above what a run needs.
const MEMORY_LIMIT_KIB: u64 = 400_000;

/// `process --if-no-lidar copy` under `ulimit -v`: an allocation sized by
/// a crafted count aborts the run ("memory allocation failed", exit 134).
fn process_with_memory_limit(dir: &Path, input: &Path) -> std::process::Output {
    let script = format!(
        "ulimit -v {MEMORY_LIMIT_KIB}; exec {bin} process {input} -o {out} --force --if-no-lidar copy",
        bin = env!("CARGO_BIN_EXE_looming"),
        input = input.display(),
        out = dir.join("out.mcap").display(),
    );
    std::process::Command::new("sh")
        .args(["-c", &script])
        .output()
        .unwrap()
}

fn record(opcode: u8, body: &[u8]) -> Vec<u8> {
    let mut out = vec![opcode];
    out.extend_from_slice(&(body.len() as u64).to_le_bytes());
    out.extend_from_slice(body);
    out
}

fn string(text: &str) -> Vec<u8> {
    let mut out = (text.len() as u32).to_le_bytes().to_vec();
    out.extend_from_slice(text.as_bytes());
    out
}

const MAGIC: &[u8] = b"\x89MCAP0\r\n";

fn crafted_header() -> Vec<u8> {
    let mut bytes = MAGIC.to_vec();
    bytes.extend(record(0x01, &[string("ros2"), string("crafted")].concat()));
    bytes
}

/// The limit is no obstacle to a real run: the drive goes through under it,
/// and so does a log whose one compressed chunk is larger than the file.
#[test]
fn the_memory_limit_lets_real_logs_through() {
    let dir = scratch("bad-memory-real");
    let (input, _) = sample_input(&dir);
    let run = process_with_memory_limit(&dir, &input);
    assert!(run.status.success(), "{}", stderr(&run));
    let one_chunk = drive_log(&DriveSpec {
        layout: looming::testkit::Layout {
            chunked: true,
            compression: Some(mcap::Compression::Zstd),
            summary: false,
            chunk_size: 1 << 30,
        },
        ..drive_spec()
    });
    let input = write_input(&dir, &one_chunk);
    let run = process(&dir, &input, &[]);
    assert_eq!(run.code, Some(0), "{}", run.stderr);
    assert_eq!(summary_count(&run, "pairs_written"), 5, "{}", run.stderr);
}

#[test]
fn record_of_1_gib_in_a_600_byte_file() {
    let dir = scratch("bad-memory-record");
    let mut bytes = crafted_header();
    bytes.push(0x06);
    bytes.extend_from_slice(&((1u64 << 30) - 1).to_le_bytes());
    bytes.extend_from_slice(&[0; 600]);
    let input = write_input(&dir, &bytes);
    let run = process_with_memory_limit(&dir, &input);
    assert!(
        !stderr(&run).contains("memory allocation"),
        "{}",
        stderr(&run)
    );
    assert_eq!(run.status.code(), Some(0), "{}", stderr(&run));
    assert!(
        stderr(&run).contains("truncated") || stderr(&run).contains("stopped"),
        "{}",
        stderr(&run)
    );
}

#[test]
fn chunk_of_1_gib_in_a_240_byte_file() {
    let dir = scratch("bad-memory-chunk");
    let mut bytes = crafted_header();
    let data = [&[0x28, 0xb5, 0x2f, 0xfd][..], &[0; 100]].concat();
    let chunk = [
        &0u64.to_le_bytes()[..],
        &0u64.to_le_bytes(),
        &((1u64 << 30) - 1).to_le_bytes(),
        &0u32.to_le_bytes(),
        &string("zstd"),
        &(data.len() as u64).to_le_bytes(),
        &data,
    ]
    .concat();
    bytes.extend(record(0x06, &chunk));
    bytes.extend(record(0x0F, &0u32.to_le_bytes()));
    bytes.extend(record(0x02, &[0u8; 20]));
    bytes.extend_from_slice(MAGIC);
    let input = write_input(&dir, &bytes);
    let run = process_with_memory_limit(&dir, &input);
    assert!(
        !stderr(&run).contains("memory allocation"),
        "{}",
        stderr(&run)
    );
    assert_eq!(run.status.code(), Some(0), "{}", stderr(&run));
}
