//! End-to-end tests of `looming process` / `inspect` through the real binary on
//! MCAP files built in memory: every encoding and layout, out-of-order log
//! times, metadata and attachments, truncation, bad messages, determinism.

mod common;

use common::*;
use looming::annotate::pairs::PairRecord;

const SCANS: u32 = 12;

fn spec(encoding: Encoding, layout: Layout) -> DriveSpec {
    DriveSpec {
        encoding,
        layout,
        scans: SCANS,
        ..DriveSpec::default()
    }
}

/// The fixture drive in ROS 2 CDR, chunked with summary.
fn default_drive() -> Vec<u8> {
    drive_log(&spec(
        Encoding::Ros2 { big_endian: false },
        Layout::indexed(),
    ))
}

fn encodings() -> [(&'static str, Encoding); 3] {
    [
        ("ros2-le", Encoding::Ros2 { big_endian: false }),
        ("ros2-be", Encoding::Ros2 { big_endian: true }),
        ("ros1", Encoding::Ros1),
    ]
}

fn layouts() -> [(&'static str, Layout); 5] {
    let lz4 = Layout {
        compression: Some(mcap::Compression::Lz4),
        ..Layout::indexed()
    };
    let uncompressed = Layout {
        compression: None,
        ..Layout::indexed()
    };
    [
        ("indexed-zstd", Layout::indexed()),
        ("indexed-lz4", lz4),
        ("indexed-uncompressed", uncompressed),
        ("unchunked", Layout::unchunked()),
        ("no-summary", Layout::no_summary()),
    ]
}

/// Run `process` and return the JSON summary and the output contents.
fn process(
    dir: &std::path::Path,
    input: &[u8],
    extra: &[&str],
) -> (serde_json::Value, FileContents, Vec<u8>) {
    let in_path = dir.join("in.mcap");
    let out_path = dir.join("out.mcap");
    let summary_path = dir.join("summary.json");
    write(&in_path, input);
    let mut args = vec![
        "process",
        in_path.to_str().unwrap(),
        "-o",
        out_path.to_str().unwrap(),
        "--force",
        "--json-summary",
        summary_path.to_str().unwrap(),
    ];
    args.extend_from_slice(extra);
    let run = looming(&args);
    assert!(run.status.success(), "process failed: {}", stderr(&run));
    let summary: serde_json::Value =
        serde_json::from_slice(&std::fs::read(&summary_path).unwrap()).unwrap();
    let bytes = std::fs::read(&out_path).unwrap();
    (summary, read_all(&bytes), bytes)
}

fn pair_records(contents: &FileContents) -> Vec<PairRecord> {
    contents
        .topic_messages("/looming/pairs")
        .iter()
        .map(|m| {
            serde_json::from_slice(&m.data).expect("pair messages are valid JSON of the schema")
        })
        .collect()
}

/// The pairs of the fixture drive: consecutive scans 0.1 s apart, the LiDAR
/// moving at 10 m/s along x (identity extrinsic rotation, no rotation rate).
fn assert_pairs_are_right(pairs: &[PairRecord]) {
    assert_eq!(pairs.len(), SCANS as usize - 1);
    for (i, pair) in pairs.iter().enumerate() {
        assert_eq!(pair.index, i as u64);
        assert_eq!(pair.current.stamp_ns - pair.previous.stamp_ns, 100_000_000);
        assert!((pair.dt_s - 0.1).abs() < 1e-9, "dt {}", pair.dt_s);
        if i > 0 {
            assert_eq!(
                pair.previous.stamp_ns,
                pairs[i - 1].current.stamp_ns,
                "consecutive scans"
            );
        }
        let v = pair.velocity_lidar_mps.expect("velocity available");
        assert!(
            (v[0] - 10.0).abs() < 1e-9 && v[1].abs() < 1e-9 && v[2].abs() < 1e-9,
            "velocity {v:?}"
        );
        let w = pair.angular_velocity_lidar_radps.expect("gyro available");
        assert!(w.iter().all(|c| c.abs() < 1e-12));
        assert!(pair.unavailable.is_empty(), "{:?}", pair.unavailable);
        assert!(pair.current.points > 500 && pair.current.per_point_time && pair.current.ring);
        assert_eq!(pair.extrinsic.velocity.as_deref(), Some("tf_static"));
    }
}

#[test]
fn every_encoding_and_layout_is_copied_unchanged_and_paired() {
    for (encoding_name, encoding) in encodings() {
        for (layout_name, layout) in layouts() {
            let name = format!("{encoding_name}-{layout_name}");
            let dir = scratch(&name);
            let input = drive_log(&spec(encoding, layout));
            let (summary, output, _) = process(&dir, &input, &[]);
            let original = read_all(&input);
            assert_all_input_messages_copied(&original, &output);
            assert_eq!(
                output
                    .metadata
                    .iter()
                    .filter(|m| m.name == "recording")
                    .count(),
                1,
                "{name}"
            );
            assert_eq!(
                output.attachments, original.attachments,
                "{name}: attachments"
            );
            assert_eq!(output.profile, "", "{name}: our channels are not CDR");
            let looming_meta = output
                .metadata
                .iter()
                .find(|m| m.name == "looming")
                .expect("looming metadata");
            assert_eq!(looming_meta.metadata["version"], env!("CARGO_PKG_VERSION"));
            let config: serde_json::Value =
                serde_json::from_str(&looming_meta.metadata["config"]).unwrap();
            assert_eq!(
                config["topics"]["lidar"]["topic"], "/sensing/lidar/points",
                "{name}"
            );
            assert_pairs_are_right(&pair_records(&output));
            let expected_mode = if layout_name.starts_with("indexed") {
                "indexed"
            } else {
                "linear"
            };
            assert_eq!(summary["read"]["mode"], expected_mode, "{name}");
            assert_eq!(summary["bad_messages"], 0, "{name}");
            assert_eq!(
                summary["input_report"]["out_of_order_beyond_window"], 0,
                "{name}"
            );
        }
    }
}

#[test]
fn messages_come_out_in_log_time_order() {
    // The fixture writes each scan after 50 ms of later IMU messages.
    for (name, layout) in [
        ("indexed", Layout::indexed()),
        ("linear", Layout::no_summary()),
    ] {
        let dir = scratch(&format!("order-{name}"));
        let input = drive_log(&spec(Encoding::Ros2 { big_endian: false }, layout));
        let in_order: Vec<u64> = read_all(&input)
            .messages
            .iter()
            .map(|m| m.log_time)
            .collect();
        assert!(
            in_order.windows(2).any(|w| w[1] < w[0]),
            "the fixture is out of order in file order"
        );
        let (_, output, _) = process(&dir, &input, &[]);
        let input_channels = [1u16, 2, 3, 4, 5];
        let times: Vec<u64> = output
            .messages
            .iter()
            .filter(|m| input_channels.contains(&m.channel_id))
            .map(|m| m.log_time)
            .collect();
        assert!(
            times.windows(2).all(|w| w[0] <= w[1]),
            "{name}: copied in log-time order"
        );
    }
}

#[test]
fn the_same_input_gives_a_byte_identical_output() {
    let dir = scratch("determinism");
    let input = default_drive();
    let (_, _, first) = process(&dir, &input, &[]);
    let (_, _, second) = process(&dir, &input, &[]);
    assert!(first == second);
}

#[test]
fn our_ids_do_not_collide_with_input_ids() {
    let dir = scratch("ids");
    let input = drive_log(&spec(Encoding::Ros1, Layout::indexed()));
    let (_, output, _) = process(&dir, &input, &[]);
    let pairs_id = output
        .channels
        .iter()
        .find(|(_, channel)| channel.topic == "/looming/pairs")
        .map(|(id, _)| *id)
        .unwrap();
    assert!(pairs_id > 5);
    let channel = &output.channels[&pairs_id];
    assert_eq!(channel.message_encoding, "json");
    let schema = channel.schema.clone().unwrap();
    assert!(schema.id > 5);
    assert_eq!(
        (schema.name.as_str(), schema.encoding.as_str()),
        ("looming.ScanPair", "jsonschema")
    );
    let _: serde_json::Value = serde_json::from_slice(&schema.data).expect("the schema is JSON");
}

/// Cut the file inside its third chunk, `fraction` of the way through it;
/// returns the cut file and the index of the cut chunk.
fn truncated_mid_chunk(bytes: &[u8], fraction: f64) -> (Vec<u8>, mcap::records::ChunkIndex) {
    let summary = mcap::Summary::read(bytes).unwrap().unwrap();
    let mut chunks = summary.chunk_indexes.clone();
    chunks.sort_by_key(|c| c.chunk_start_offset);
    assert!(chunks.len() >= 4, "the fixture needs several chunks");
    let cut_chunk = chunks[2].clone();
    let cut = cut_chunk.chunk_start_offset + (cut_chunk.chunk_length as f64 * fraction) as u64;
    (bytes[..cut as usize].to_vec(), cut_chunk)
}

/// Messages of `full` stored in chunks wholly before `cut_chunk`, and those of
/// `cut_chunk` whose records end before byte `cut` (meaningful for an
/// uncompressed chunk, where record offsets are file offsets).
fn messages_before_cut(
    full: &[u8],
    cut_chunk: &mcap::records::ChunkIndex,
    cut: u64,
) -> (Vec<RawMessage>, Vec<RawMessage>) {
    let summary = mcap::Summary::read(full).unwrap().unwrap();
    let raw = |message: mcap::Message| RawMessage {
        channel_id: message.channel.id,
        sequence: message.sequence,
        log_time: message.log_time,
        publish_time: message.publish_time,
        data: message.data.into_owned(),
    };
    let mut whole = Vec::new();
    for chunk in summary
        .chunk_indexes
        .iter()
        .filter(|c| c.chunk_start_offset < cut_chunk.chunk_start_offset)
    {
        whole.extend(
            summary
                .stream_chunk(full, chunk)
                .unwrap()
                .map(|m| raw(m.unwrap())),
        );
    }
    let records_start = cut_chunk.compressed_data_offset().unwrap();
    let indexes = summary.read_message_indexes(full, cut_chunk).unwrap();
    let mut in_cut_chunk = Vec::new();
    for entries in indexes.values() {
        for entry in entries {
            let message = summary.seek_message(full, cut_chunk, entry).unwrap();
            let record_end = records_start + entry.offset + 9 + 22 + message.data.len() as u64;
            if record_end <= cut {
                in_cut_chunk.push(raw(message));
            }
        }
    }
    (whole, in_cut_chunk)
}

/// (channel, sequence, log time) of each message: short enough to print.
fn keys(messages: &[RawMessage]) -> Vec<(u16, u32, u64)> {
    messages
        .iter()
        .map(|m| (m.channel_id, m.sequence, m.log_time))
        .collect()
}

fn input_messages(contents: &FileContents) -> Vec<RawMessage> {
    let mut messages: Vec<RawMessage> = contents
        .messages
        .iter()
        .filter(|m| m.channel_id <= 5)
        .cloned()
        .collect();
    messages.sort();
    messages
}

#[test]
fn a_truncated_file_keeps_every_complete_message_before_the_cut() {
    let dir = scratch("truncated");
    // zstd decodes whole blocks (up to 128 KiB of data each), so its chunks
    // must span several and the cut must leave some whole.
    for (name, compression, chunk_size, fraction) in [
        ("uncompressed", None, 64 * 1024, 0.5),
        ("zstd", Some(mcap::Compression::Zstd), 512 * 1024, 0.9),
    ] {
        let layout = Layout {
            chunk_size,
            compression,
            ..Layout::indexed()
        };
        let full = drive_log(&DriveSpec {
            scans: 40,
            ..spec(Encoding::Ros2 { big_endian: false }, layout)
        });
        let (cut, cut_chunk) = truncated_mid_chunk(&full, fraction);
        let (whole, in_cut_chunk) = messages_before_cut(&full, &cut_chunk, cut.len() as u64);
        assert!(!whole.is_empty());
        let (summary, output, _) = process(&dir, &cut, &[]);
        let actual = input_messages(&output);
        let mut expected = whole.clone();
        if compression.is_none() {
            // Every record wholly before the cut, the cut chunk's included.
            assert!(
                !in_cut_chunk.is_empty(),
                "the cut chunk starts with complete messages"
            );
            expected.extend(in_cut_chunk);
            expected.sort();
            assert_eq!(
                keys(&actual),
                keys(&expected),
                "{name}: exactly the complete messages before the cut"
            );
            assert!(actual == expected, "{name}: unchanged bytes");
        } else {
            // zstd: the complete chunks, plus what the cut stream decompresses to.
            expected.sort();
            assert!(
                actual.len() > expected.len(),
                "{name}: salvaged part of the cut chunk"
            );
            let all = input_messages(&read_all(&full));
            assert!(
                actual.iter().all(|m| all.contains(m)),
                "{name}: only real messages"
            );
            assert!(
                expected.iter().all(|m| actual.contains(m)),
                "{name}: every complete chunk kept"
            );
        }
        assert_eq!(summary["read"]["mode"], "linear");
        let warnings = summary["warnings"].to_string();
        assert!(warnings.contains("truncated"), "{warnings}");
    }

    // Strict mode refuses it.
    let strict = looming_process(
        &dir.join("in.mcap"),
        &dir.join("strict.mcap"),
        &["--strict"],
    );
    assert_eq!(strict.status.code(), Some(3), "{}", stderr(&strict));
    assert!(!dir.join("strict.mcap").exists(), "no output on failure");
}

/// Register the schemas and channels of `contents` in `log`, same ids.
fn copy_channels(contents: &FileContents, log: &mut looming::testkit::LogBuilder) {
    for (id, channel) in &contents.channels {
        let schema = channel.schema.clone().unwrap();
        log.schema(schema.id, &schema.name, &schema.encoding, &schema.data);
        log.channel(*id, schema.id, &channel.topic, &channel.message_encoding);
    }
}

/// A drive whose IMU message 5 and scan 3 are replaced by garbage.
fn log_with_bad_messages() -> Vec<u8> {
    let good = default_drive();
    let contents = read_all(&good);
    let mut log = looming::testkit::LogBuilder::new(Layout::indexed(), "ros2");
    copy_channels(&contents, &mut log);
    let (mut imu_seen, mut scans_seen) = (0, 0);
    for m in &contents.messages {
        let mut data = m.data.clone();
        if m.channel_id == 2 {
            imu_seen += 1;
            if imu_seen == 5 {
                data.truncate(10);
            }
        }
        if m.channel_id == 1 {
            scans_seen += 1;
            if scans_seen == 3 {
                data.truncate(data.len() / 2);
            }
        }
        log.message(m.channel_id, m.sequence, m.log_time, m.publish_time, &data);
    }
    log.finish()
}

#[test]
fn bad_messages_are_skipped_counted_and_named() {
    let dir = scratch("bad-messages");
    let input = log_with_bad_messages();
    let (summary, output, _) = process(&dir, &input, &[]);
    assert_all_input_messages_copied(&read_all(&input), &output);
    assert_eq!(summary["bad_messages"], 2);
    assert_eq!(summary["bad_messages_by_topic"]["/sensing/imu"], 1);
    assert_eq!(summary["bad_messages_by_topic"]["/sensing/lidar/points"], 1);
    let example = summary["bad_message_examples"][0].clone();
    assert!(example["file"].as_str().unwrap().ends_with("in.mcap"));
    assert!(example["log_time_ns"].as_u64().unwrap() > 0);
    assert!(!example["reason"].as_str().unwrap().is_empty());
    // The bad scan breaks two pairs: scans 2-3 and 3-4 become one 2-4 pair
    // (0.2 s, within the 3-period gap).
    let pairs = pair_records(&output);
    assert_eq!(pairs.len(), SCANS as usize - 2);

    let strict = looming_process(
        &dir.join("in.mcap"),
        &dir.join("strict.mcap"),
        &["--strict"],
    );
    assert_eq!(strict.status.code(), Some(3));
    let message = stderr(&strict);
    assert!(
        message.contains("/sensing/") && message.contains("log time"),
        "{message}"
    );
}

#[test]
fn output_paths_are_guarded() {
    let dir = scratch("paths");
    let input = default_drive();
    let in_path = dir.join("in.mcap");
    write(&in_path, &input);
    let same = looming_process(&in_path, &in_path, &["--force"]);
    assert_eq!(same.status.code(), Some(2), "{}", stderr(&same));
    assert_eq!(std::fs::read(&in_path).unwrap(), input, "input untouched");
    let out_path = dir.join("out.mcap");
    write(&out_path, b"precious");
    let exists = looming_process(&in_path, &out_path, &[]);
    assert_eq!(exists.status.code(), Some(2));
    assert!(stderr(&exists).contains("--force"));
    assert_eq!(std::fs::read(&out_path).unwrap(), b"precious");
    let forced = looming_process(&in_path, &out_path, &["--force", "-q"]);
    assert!(forced.status.success());
    let leftovers: Vec<_> = std::fs::read_dir(&dir)
        .unwrap()
        .filter_map(|e| e.ok())
        .filter(|e| e.file_name().to_string_lossy().ends_with(".tmp"))
        .collect();
    assert!(leftovers.is_empty(), "no temporary file left behind");
}

#[test]
fn ambiguous_and_unknown_topics_list_the_candidates() {
    let dir = scratch("topics");
    let good = default_drive();
    // Add a second LiDAR channel carrying the same scans.
    let two = common::with_channel_copy(&good, "/sensing/lidar/points", "/sensing/lidar/rear");
    let in_path = dir.join("in.mcap");
    write(&in_path, &two);
    let out = dir.join("out.mcap");
    // Several LiDARs are each annotated (tests/multi_lidar.rs); `render`,
    // which draws one sensor, lists them and asks for one.
    let both = looming_process(&in_path, &out, &[]);
    assert!(both.status.success(), "{}", stderr(&both));
    let picture = dir.join("pair.png");
    let ambiguous = common::looming(&[
        "render",
        in_path.to_str().unwrap(),
        "-o",
        picture.to_str().unwrap(),
        "--frame",
        "1",
    ]);
    assert_eq!(ambiguous.status.code(), Some(2), "{}", stderr(&ambiguous));
    let text = stderr(&ambiguous);
    assert!(
        text.contains("/sensing/lidar/points") && text.contains("/sensing/lidar/rear"),
        "{text}"
    );
    assert!(
        text.contains("--lidar-topic") && text.contains("sensor_msgs/msg/PointCloud2"),
        "{text}"
    );
    let unknown = looming_process(&in_path, &out, &["--lidar-topic", "/nope", "--force"]);
    assert_eq!(unknown.status.code(), Some(2));
    assert!(stderr(&unknown).contains("/sensing/lidar/rear"));
    let chosen = looming_process(
        &in_path,
        &out,
        &["--lidar-topic", "/sensing/lidar/rear", "--force"],
    );
    assert!(chosen.status.success(), "{}", stderr(&chosen));
}

#[test]
fn missing_motion_sources_are_reported_per_pair() {
    let dir = scratch("no-motion");
    let input = drive_log(&DriveSpec {
        imu: false,
        twist: false,
        tf_static: false,
        ..spec(Encoding::Ros2 { big_endian: false }, Layout::indexed())
    });
    let (summary, output, _) = process(&dir, &input, &[]);
    let pairs = pair_records(&output);
    assert_eq!(pairs.len(), SCANS as usize - 1);
    for pair in &pairs {
        assert_eq!(pair.velocity_lidar_mps, None);
        assert!(pair.unavailable.contains(&"velocity".to_string()));
        assert!(pair.unavailable.contains(&"imu".to_string()));
    }
    assert_eq!(summary["pairing"]["pairs_without_velocity"], SCANS - 1);
}

#[test]
fn odometry_and_a_cli_extrinsic_drive_the_velocity() {
    let dir = scratch("odometry");
    let input = drive_log(&DriveSpec {
        twist: false,
        odometry: true,
        tf_static: false,
        ..spec(Encoding::Ros1, Layout::indexed())
    });
    // LiDAR yawed 90 degrees left in base_link: forward motion is -y for it.
    let s = std::f64::consts::FRAC_1_SQRT_2;
    let extrinsic = format!("1.2,0,1.8,0,0,{s},{s}");
    let (_, output, _) = process(&dir, &input, &["--extrinsic", &extrinsic]);
    for pair in pair_records(&output) {
        let v = pair.velocity_lidar_mps.unwrap();
        assert!(v[0].abs() < 1e-9 && (v[1] + 10.0).abs() < 1e-9, "{v:?}");
        assert_eq!(pair.extrinsic.velocity.as_deref(), Some("cli"));
    }
}

#[test]
fn inspect_lists_channels_and_detected_topics() {
    let dir = scratch("inspect");
    for (name, layout) in layouts() {
        let path = dir.join(format!("{name}.mcap"));
        write(
            &path,
            &drive_log(&spec(Encoding::Ros2 { big_endian: false }, layout)),
        );
        let run = looming(&["inspect", path.to_str().unwrap(), "--json"]);
        assert!(run.status.success(), "{}", stderr(&run));
        let report: serde_json::Value = serde_json::from_slice(&run.stdout).unwrap();
        assert_eq!(
            report["detected"]["lidar"][0], "/sensing/lidar/points",
            "{name}"
        );
        assert_eq!(report["detected"]["imu"][0], "/sensing/imu");
        assert_eq!(report["detected"]["velocity"][0], "/vehicle/twist");
        assert_eq!(report["detected"]["tf_static"][0], "/tf_static");
        assert_eq!(report["detected"]["problem"], serde_json::Value::Null);
        let lidar = report["channels"]
            .as_array()
            .unwrap()
            .iter()
            .find(|c| c["topic"] == "/sensing/lidar/points")
            .unwrap();
        assert_eq!(lidar["message_count"], SCANS);
        let rate = lidar["rate_hz"].as_f64().unwrap();
        assert!((rate - 10.0).abs() < 2.0, "{name}: rate {rate}");
        let text = looming(&["inspect", path.to_str().unwrap()]);
        assert!(String::from_utf8_lossy(&text.stdout).contains("LiDAR:     /sensing/lidar/points"));
    }
}

#[test]
fn verify_checks_chunk_crcs() {
    let dir = scratch("verify");
    let layout = Layout {
        compression: None,
        chunk_size: 16 * 1024,
        ..Layout::indexed()
    };
    let mut input = drive_log(&spec(Encoding::Ros2 { big_endian: false }, layout));
    let (summary, _, _) = process(&dir, &input, &["--verify"]);
    assert_eq!(summary["input_report"]["bad_crc_chunks"], 0);
    // Flip one payload byte in the middle of the second chunk (uncompressed, so
    // framing survives and only the CRC can tell).
    let index = mcap::Summary::read(&input).unwrap().unwrap();
    let mut chunks = index.chunk_indexes.clone();
    chunks.sort_by_key(|c| c.chunk_start_offset);
    let flip = (chunks[1].chunk_start_offset + chunks[1].chunk_length - 100) as usize;
    input[flip] ^= 0xff;
    let (summary, _, _) = process(&dir, &input, &["--verify"]);
    assert_eq!(summary["input_report"]["bad_crc_chunks"], 1);
    assert!(summary["warnings"].to_string().contains("CRC"));
    let in_path = dir.join("in.mcap");
    let strict = looming_process(&in_path, &dir.join("s.mcap"), &["--verify", "--strict"]);
    assert_eq!(strict.status.code(), Some(3), "{}", stderr(&strict));
}

#[test]
fn an_already_processed_log_is_refused() {
    let dir = scratch("reprocess");
    let input = default_drive();
    process(&dir, &input, &[]);
    let again = looming_process(&dir.join("out.mcap"), &dir.join("again.mcap"), &[]);
    assert_eq!(again.status.code(), Some(2));
    assert!(
        stderr(&again).contains("/looming/pairs"),
        "{}",
        stderr(&again)
    );
}

/// `eval` and `render` read, decode and pair a log with the code and the
/// options `process` uses: the same pairs, the same bad messages counted.
#[test]
fn eval_and_render_pair_scans_as_process_does() {
    let dir = scratch("same-pairing");
    let input = log_with_bad_messages();
    // A gap limit below the 0.2 s the bad scan leaves: the 2-4 pair is
    // skipped, which default options would have paired.
    let options = ["--max-gap", "0.15", "--extrinsic", "0,0,0,0,0,0,1"];
    let (summary, _, _) = process(&dir, &input, &options);
    let process_pairs = summary["pairs_written"].as_u64().unwrap();
    assert_eq!(process_pairs, SCANS as u64 - 3);
    assert_eq!(summary["bad_messages"], 2);

    // The library's replay (what eval and render call) with the same options.
    let scans = looming::pipeline::ScanOptions {
        pairing: looming::pairing::PairingConfig {
            max_gap_s: Some(0.15),
            cli_extrinsic: Some(nalgebra::Isometry3::identity()),
            ..Default::default()
        },
        ..Default::default()
    };
    let mut sources = Vec::new();
    let report = looming::pipeline::replay(&dir.join("in.mcap"), &scans, &mut |_| {}, &mut |p| {
        sources.push(p.motion.velocity_extrinsic.map(|e| e.source))
    })
    .unwrap();
    assert_eq!(report.pairs, process_pairs);
    assert_eq!(report.bad_messages.count, 2);
    assert_eq!(
        report.bad_messages.by_topic,
        serde_json::from_value(summary["bad_messages_by_topic"].clone()).unwrap()
    );
    assert_eq!(
        report.pairing.skipped_gap,
        summary["pairing"]["skipped_gap"]
    );
    assert!(
        sources
            .iter()
            .all(|s| *s == Some(looming::model::ExtrinsicSource::Cli))
    );

    // `render` through the CLI: asking for a pair past the end names the count.
    let input_path = dir.join("in.mcap");
    let png = dir.join("render.png");
    let mut args = vec![
        "render",
        input_path.to_str().unwrap(),
        "--frame",
        "1000",
        "-o",
        png.to_str().unwrap(),
    ];
    args.extend_from_slice(&options);
    let run = looming(&args);
    assert_eq!(run.status.code(), Some(2));
    let expected = format!("(the log has {process_pairs} pairs)");
    assert!(stderr(&run).contains(&expected), "{}", stderr(&run));
    // ... and with --strict, the bad message stops it as it stops process.
    args.push("--strict");
    let run = looming(&args);
    assert_eq!(run.status.code(), Some(3));
    assert!(stderr(&run).contains("topic"), "{}", stderr(&run));
}

/// `eval` through the CLI honours the pairing options too.
#[test]
fn eval_takes_the_pairing_options_of_process() {
    let log = std::path::Path::new(env!("CARGO_MANIFEST_DIR")).join("sample_logs/cut-in.mcap");
    let run = looming(&["eval", log.to_str().unwrap(), "--max-gap", "0.05"]);
    assert!(run.status.success(), "{}", stderr(&run));
    let text = String::from_utf8_lossy(&run.stdout).to_string();
    assert!(text.contains(": 0 pairs (0 with ego velocity)"), "{text}");
    let run = looming(&["eval", log.to_str().unwrap(), "--max-gap", "-1"]);
    assert_eq!(run.status.code(), Some(2));
}

/// A log with IMU messages, a metadata record and an attachment, and no
/// LiDAR.
fn log_without_lidar() -> Vec<u8> {
    let mut log = looming::testkit::LogBuilder::new(Layout::indexed(), "ros2");
    log.schema(1, "sensor_msgs/msg/Imu", "ros2msg", b"");
    log.channel(1, 1, "/imu/data", "cdr");
    log.schema(2, "std_msgs/msg/String", "ros2msg", b"string data");
    log.channel(2, 2, "/notes", "cdr");
    for i in 0..10u64 {
        let t = 1_000 + i * 10_000_000;
        log.message(1, i as u32, t, t, &[0; 8]);
        log.message(2, i as u32, t + 1, t + 1, &[1; 4]);
    }
    log.metadata("robot", &[("id", "r2")]);
    log.attachment("calib.txt", "text/plain", 5_000, b"calibration");
    log.finish()
}

/// `process` refuses a log without LiDAR, listing its channels, unless
/// `--if-no-lidar copy`: then every record is copied through, with the run
/// record and no channel of ours.
#[test]
fn a_log_without_lidar_is_refused_or_copied_through() {
    let dir = scratch("no-lidar");
    let input = dir.join("in.mcap");
    let bytes = log_without_lidar();
    write(&input, &bytes);
    let output = dir.join("out.mcap");
    let refused = looming_process(&input, &output, &[]);
    assert_eq!(refused.status.code(), Some(2), "{}", stderr(&refused));
    assert!(stderr(&refused).contains("no LiDAR topic") && stderr(&refused).contains("/notes"));
    assert!(!output.exists());
    let copied = looming_process(&input, &output, &["--if-no-lidar", "copy"]);
    assert!(copied.status.success(), "{}", stderr(&copied));
    assert!(
        stderr(&copied).contains("every record copied through"),
        "{}",
        stderr(&copied)
    );
    let before = read_all(&bytes);
    let after = read_all(&std::fs::read(&output).unwrap());
    assert_all_input_messages_copied(&before, &after);
    assert!(
        after
            .channels
            .values()
            .all(|c| !c.topic.starts_with("/looming/"))
    );
    assert_eq!(after.attachments.len(), 1);
    let names: Vec<&str> = after.metadata.iter().map(|m| m.name.as_str()).collect();
    assert_eq!(names, ["robot", "looming"]);
    let run = &after.metadata[1].metadata;
    assert!(
        run["config"].contains("\"if_no_lidar\":\"copy\""),
        "{}",
        run["config"]
    );
}
