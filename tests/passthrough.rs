//! The pass-through output (`looming process` on a chunked, indexed input
//! whose messages are in log-time order): every input chunk record and its
//! message index records copied byte for byte, our channels in chunks of their
//! own, and a summary that independent readers accept. Inputs are synthetic
//! drives rewritten with zstd, lz4 or no compression, with attachments and
//! metadata added.

mod common;

use std::collections::BTreeMap;
use std::path::{Path, PathBuf};

use common::*;
use looming::input::{InputFile, InputOptions, InputRecord, ReadMode};

/// Small chunks, so that some hold only channels `process` does not decode
/// (the truth clouds) and are copied without being decompressed.
const CHUNK_BYTES: u64 = 64 * 1024;

/// A short 32 x 512 synthetic drive (its messages in log-time order).
fn synth_drive(dir: &Path) -> PathBuf {
    synth_drive_of(dir, "1.5")
}

fn synth_drive_of(dir: &Path, duration_s: &str) -> PathBuf {
    let small = [
        "--beams",
        "32",
        "--columns",
        "512",
        "--duration",
        duration_s,
    ];
    common::synth(dir, "safe-drive", &small)
}

/// `synth` rewritten in `compression`, small chunks, with two attachments and
/// one more metadata record.
fn chunked_input(synth: &Path, compression: Option<mcap::Compression>, out: &Path) -> Vec<u8> {
    chunked_input_with(synth, compression, out, &mut |_| {})
}

/// [`chunked_input`], each message through `edit` first.
fn chunked_input_with(
    synth: &Path,
    compression: Option<mcap::Compression>,
    out: &Path,
    edit: &mut dyn FnMut(&mut mcap::Message<'_>),
) -> Vec<u8> {
    let bytes = std::fs::read(synth).unwrap();
    let mut writer = mcap::WriteOptions::new()
        .profile("ros2")
        .compression(compression)
        .chunk_size(Some(CHUNK_BYTES))
        .compression_threads(0)
        .create(std::io::BufWriter::new(std::fs::File::create(out).unwrap()))
        .unwrap();
    for message in mcap::MessageStream::new(&bytes).unwrap() {
        let mut message = message.unwrap();
        edit(&mut message);
        writer.write(&message).unwrap();
    }
    for metadata in read_all(&bytes).metadata {
        writer.write_metadata(&metadata).unwrap();
    }
    let recording = mcap::records::Metadata {
        name: "recording".into(),
        metadata: BTreeMap::from([("vehicle".into(), "test-7".into())]),
    };
    writer.write_metadata(&recording).unwrap();
    for (name, size) in [("calibration.yaml", 300usize), ("map.bin", 70_000)] {
        let data: Vec<u8> = (0..size).map(|i| (i * 31 % 251) as u8).collect();
        writer
            .attach(&mcap::Attachment {
                log_time: 1_000,
                create_time: 2_000,
                name: name.into(),
                media_type: "application/octet-stream".into(),
                data: std::borrow::Cow::Owned(data),
            })
            .unwrap();
    }
    writer.finish().unwrap();
    drop(writer);
    std::fs::read(out).unwrap()
}

fn compressions() -> [(&'static str, Option<mcap::Compression>); 3] {
    [
        ("zstd", Some(mcap::Compression::Zstd)),
        ("lz4", Some(mcap::Compression::Lz4)),
        ("uncompressed", None),
    ]
}

/// Run `process IN -o OUT EXTRA` (must succeed); the JSON summary.
fn process_ok(input: &Path, output: &Path, extra: &[&str]) -> serde_json::Value {
    let summary = output.with_extension("json");
    let mut args = vec!["--force", "-q", "--json-summary", summary.to_str().unwrap()];
    args.extend_from_slice(extra);
    let run = looming_process(input, output, &args);
    assert!(run.status.success(), "process: {}", stderr(&run));
    serde_json::from_slice(&std::fs::read(summary).unwrap()).unwrap()
}

/// A chunk record and its message index records, as stored.
#[derive(Debug, PartialEq, Eq)]
struct StoredChunk {
    record: Vec<u8>,
    message_indexes: Vec<u8>,
    channels: Vec<u16>,
}

/// Every chunk of `bytes` in file order, through its summary's chunk indexes.
fn stored_chunks(bytes: &[u8]) -> Vec<StoredChunk> {
    let summary = mcap::Summary::read(bytes).unwrap().unwrap();
    let mut indexes = summary.chunk_indexes.clone();
    indexes.sort_by_key(|c| c.chunk_start_offset);
    indexes
        .iter()
        .map(|index| {
            let start = index.chunk_start_offset as usize;
            let record = bytes[start..start + index.chunk_length as usize].to_vec();
            let indexes_start = start + index.chunk_length as usize;
            let message_indexes =
                bytes[indexes_start..indexes_start + index.message_index_length as usize].to_vec();
            if let Some(&first) = index.message_index_offsets.values().min() {
                assert_eq!(first as usize, indexes_start, "indexes follow their chunk");
            }
            StoredChunk {
                record,
                message_indexes,
                channels: index.message_index_offsets.keys().copied().collect(),
            }
        })
        .collect()
}

/// Read `bytes` with the crate's sans-io linear reader, checking the data
/// section, summary section and chunk CRCs; the opcodes seen at top level.
fn validate_crcs(bytes: &[u8]) -> Vec<u8> {
    use mcap::sans_io::{LinearReadEvent, LinearReader, LinearReaderOptions};
    let options = LinearReaderOptions::default()
        .with_validate_chunk_crcs(true)
        .with_validate_data_section_crc(true)
        .with_validate_summary_section_crc(true);
    let mut reader = LinearReader::new_with_options(options);
    let mut rest = bytes;
    let mut opcodes = Vec::new();
    while let Some(event) = reader.next_event() {
        match event.expect("the output reads with every CRC checked") {
            LinearReadEvent::ReadRequest(need) => {
                let n = need.min(rest.len());
                reader.insert(n).copy_from_slice(&rest[..n]);
                reader.notify_read(n);
                rest = &rest[n..];
            }
            LinearReadEvent::Record { opcode, .. } => opcodes.push(opcode),
        }
    }
    opcodes
}

/// Every message through `MessageStream` with chunk CRCs checked, in file order.
fn stream_messages(bytes: &[u8]) -> Vec<RawMessage> {
    let options = mcap::read::Options::ValidateChunkCrcs.into();
    mcap::MessageStream::new_with_options(bytes, options)
        .unwrap()
        .map(|message| {
            let message = message.expect("messages read with their chunk CRCs checked");
            RawMessage {
                channel_id: message.channel.id,
                sequence: message.sequence,
                log_time: message.log_time,
                publish_time: message.publish_time,
                data: message.data.into_owned(),
            }
        })
        .collect()
}

/// Every message through the project's indexed reader (summary, chunk
/// indexes, `IndexedReader` in log-time order), in the order it yields them.
fn indexed_messages(path: &Path) -> Vec<RawMessage> {
    let input = InputFile::open(path, InputOptions::default()).unwrap();
    assert_eq!(*input.mode(), ReadMode::Indexed, "{}", path.display());
    let mut messages = Vec::new();
    input
        .read_records(true, &mut |record| {
            if let InputRecord::Message(m) = record {
                messages.push(RawMessage {
                    channel_id: m.channel_id,
                    sequence: m.sequence,
                    log_time: m.log_time_ns,
                    publish_time: m.publish_time_ns,
                    data: m.data,
                });
            }
            std::ops::ControlFlow::Continue(())
        })
        .unwrap();
    messages
}

fn sorted(mut messages: Vec<RawMessage>) -> Vec<RawMessage> {
    messages.sort();
    messages
}

/// The summary's statistics match what is in the file.
fn assert_statistics(bytes: &[u8], messages: &[RawMessage]) {
    let summary = mcap::Summary::read(bytes).unwrap().unwrap();
    let stats = summary.stats.clone().unwrap();
    let mut counts: BTreeMap<u16, u64> = BTreeMap::new();
    for m in messages {
        *counts.entry(m.channel_id).or_default() += 1;
    }
    assert_eq!(stats.message_count, messages.len() as u64);
    assert_eq!(stats.channel_message_counts, counts);
    assert_eq!(stats.chunk_count as usize, summary.chunk_indexes.len());
    assert_eq!(stats.channel_count as usize, summary.channels.len());
    assert_eq!(stats.schema_count as usize, summary.schemas.len());
    assert_eq!(
        stats.message_start_time,
        messages.iter().map(|m| m.log_time).min().unwrap()
    );
    assert_eq!(
        stats.message_end_time,
        messages.iter().map(|m| m.log_time).max().unwrap()
    );
    assert_eq!(
        stats.attachment_count as usize,
        summary.attachment_indexes.len()
    );
    assert_eq!(
        stats.metadata_count as usize,
        summary.metadata_indexes.len()
    );
}

/// Each summary offset points at a group of records of its opcode.
fn assert_summary_offsets(bytes: &[u8]) {
    let footer_at = bytes.len() - 8 - (9 + 20);
    let footer = &bytes[footer_at + 9..footer_at + 29];
    let summary_offset_start = u64::from_le_bytes(footer[8..16].try_into().unwrap()) as usize;
    assert!(
        summary_offset_start > 0,
        "the footer points at summary offsets"
    );
    let mut groups = Vec::new();
    for record in mcap::read::LinearReader::sans_magic(&bytes[summary_offset_start..footer_at]) {
        let mcap::records::Record::SummaryOffset(offset) = record.unwrap() else {
            panic!("only summary offsets after summary_offset_start");
        };
        groups.push(offset.group_opcode);
        let start = offset.group_start as usize;
        let group = &bytes[start..start + offset.group_length as usize];
        for record in mcap::read::LinearReader::sans_magic(group) {
            assert_eq!(record.unwrap().opcode(), offset.group_opcode);
        }
    }
    use mcap::records::op;
    assert_eq!(
        groups,
        vec![
            op::SCHEMA,
            op::CHANNEL,
            op::STATISTICS,
            op::CHUNK_INDEX,
            op::ATTACHMENT_INDEX,
            op::METADATA_INDEX
        ]
    );
}

/// Chunk records and their message indexes, byte for byte, in order; our
/// channels in chunks of their own. Returns the input's channel ids.
fn assert_input_chunks_copied_byte_for_byte(
    name: &str,
    input: &[u8],
    output: &[u8],
    summary: &serde_json::Value,
) -> Vec<u16> {
    let in_chunks = stored_chunks(input);
    let in_ids: Vec<u16> = read_all(input).channels.keys().copied().collect();
    let (copied, ours): (Vec<StoredChunk>, Vec<StoredChunk>) = stored_chunks(output)
        .into_iter()
        .partition(|c| c.channels.iter().all(|id| in_ids.contains(id)));
    assert!(copied == in_chunks, "{name}: input chunks copied unchanged");
    assert!(
        !ours.is_empty(),
        "{name}: our channels in chunks of their own"
    );
    assert!(
        ours.iter()
            .all(|c| c.channels.iter().all(|id| !in_ids.contains(id)))
    );
    let report = &summary["input_report"];
    assert_eq!(report["chunks_copied"], in_chunks.len() as u64, "{name}");
    let decompressed = report["chunks_decompressed"].as_u64().unwrap();
    assert!(
        decompressed > 0 && decompressed < in_chunks.len() as u64,
        "{name}: only chunks with decoded topics decompressed ({decompressed} of {})",
        in_chunks.len()
    );
    in_ids
}

/// Linear readers with every CRC checked; input records unchanged. Returns
/// the output's messages in file order.
fn assert_input_records_unchanged(
    name: &str,
    input: &[u8],
    output: &[u8],
    in_ids: &[u16],
) -> Vec<RawMessage> {
    validate_crcs(output);
    let original = read_all(input);
    let contents = read_all(output);
    assert_all_input_messages_copied(&original, &contents);
    assert_eq!(contents.attachments, original.attachments, "{name}");
    for metadata in &original.metadata {
        assert!(
            contents.metadata.contains(metadata),
            "{name}: {}",
            metadata.name
        );
    }
    assert!(contents.metadata.iter().any(|m| m.name == "looming"));
    let streamed = stream_messages(output);
    let input_streamed: Vec<RawMessage> = streamed
        .iter()
        .filter(|m| in_ids.contains(&m.channel_id))
        .cloned()
        .collect();
    assert!(
        input_streamed == stream_messages(input),
        "{name}: input messages in their file order, unchanged"
    );
    streamed
}

/// The output's summary holds every input channel and schema unchanged.
fn assert_input_channels_and_schemas_in_summary(name: &str, input: &[u8], output: &[u8]) {
    let in_summary = mcap::Summary::read(input).unwrap().unwrap();
    let out_summary = mcap::Summary::read(output).unwrap().unwrap();
    for (id, channel) in &in_summary.channels {
        assert_eq!(
            out_summary.channels.get(id),
            Some(channel),
            "{name}: channel {id}"
        );
    }
    for (id, schema) in &in_summary.schemas {
        assert_eq!(
            out_summary.schemas.get(id),
            Some(schema),
            "{name}: schema {id}"
        );
    }
}

#[test]
fn input_chunks_are_copied_byte_for_byte_and_read_back_in_log_time_order() {
    let dir = scratch("passthrough");
    let synth = synth_drive(&dir);
    for (name, compression) in compressions() {
        let in_path = dir.join(format!("{name}.mcap"));
        let input = chunked_input(&synth, compression, &in_path);
        let out_path = dir.join(format!("{name}-out.mcap"));
        let summary = process_ok(&in_path, &out_path, &[]);
        let output = std::fs::read(&out_path).unwrap();
        assert_eq!(summary["write"]["mode"], "pass_through", "{name}");

        let in_ids = assert_input_chunks_copied_byte_for_byte(name, &input, &output, &summary);
        let streamed = assert_input_records_unchanged(name, &input, &output, &in_ids);
        assert_input_channels_and_schemas_in_summary(name, &input, &output);
        assert_statistics(&output, &streamed);
        assert_summary_offsets(&output);

        // Through the summary, in log-time order across copied and our chunks.
        let indexed = indexed_messages(&out_path);
        assert!(
            indexed.windows(2).all(|w| w[0].log_time <= w[1].log_time),
            "{name}: log-time order"
        );
        assert!(
            sorted(indexed) == sorted(streamed),
            "{name}: every message indexed"
        );
    }
}

#[test]
fn a_pass_through_output_is_deterministic_whatever_the_thread_count() {
    let dir = scratch("passthrough-determinism");
    // Long enough for several chunks of ours, so some are written while
    // later ones are still being compressed.
    let synth = synth_drive_of(&dir, "4");
    let in_path = dir.join("in.mcap");
    chunked_input(&synth, Some(mcap::Compression::Zstd), &in_path);
    let first = dir.join("first.mcap");
    let second = dir.join("second.mcap");
    let single = dir.join("single-thread.mcap");
    process_ok(&in_path, &first, &[]);
    process_ok(&in_path, &second, &[]);
    let run = std::process::Command::new(env!("CARGO_BIN_EXE_looming"))
        .args(["process", in_path.to_str().unwrap(), "-o"])
        .arg(&single)
        .args(["--force", "-q"])
        .env("RAYON_NUM_THREADS", "1")
        .output()
        .unwrap();
    assert!(run.status.success(), "{}", stderr(&run));
    let bytes = std::fs::read(&first).unwrap();
    let in_ids: Vec<u16> = read_all(&std::fs::read(&in_path).unwrap())
        .channels
        .into_keys()
        .collect();
    let ours = stored_chunks(&bytes)
        .iter()
        .filter(|c| c.channels.iter().all(|id| !in_ids.contains(id)))
        .count();
    assert!(ours >= 3, "{ours} chunks of ours");
    assert!(
        bytes == std::fs::read(&second).unwrap(),
        "same bytes run to run"
    );
    assert!(
        bytes == std::fs::read(&single).unwrap(),
        "same bytes on one thread"
    );
}

#[test]
fn a_processed_output_is_refused_and_can_be_replaced() {
    let dir = scratch("passthrough-reprocess");
    let synth = synth_drive(&dir);
    let in_path = dir.join("in.mcap");
    let input = chunked_input(&synth, Some(mcap::Compression::Lz4), &in_path);
    let out_path = dir.join("out.mcap");
    process_ok(&in_path, &out_path, &[]);
    let again = looming_process(&out_path, &dir.join("again.mcap"), &[]);
    assert_eq!(again.status.code(), Some(2), "{}", stderr(&again));
    assert!(stderr(&again).contains("/looming/"), "{}", stderr(&again));

    let replaced = dir.join("replaced.mcap");
    let summary = process_ok(&out_path, &replaced, &["--replace"]);
    assert_eq!(summary["write"]["mode"], "rewrite");
    let first = read_all(&std::fs::read(&out_path).unwrap());
    let second = read_all(&std::fs::read(&replaced).unwrap());
    assert_all_input_messages_copied(&read_all(&input), &second);
    assert_eq!(
        first.topic_messages("/looming/pairs"),
        second.topic_messages("/looming/pairs"),
        "the same pairs again"
    );
}

#[test]
fn inputs_that_cannot_be_copied_are_rewritten_and_say_why() {
    let dir = scratch("passthrough-rewrite");
    let spec = DriveSpec {
        scans: 6,
        ..DriveSpec::default()
    };
    for (name, layout, why) in [
        ("unchunked", Layout::unchunked(), "linearly"),
        ("indexed", Layout::indexed(), "log-time order"),
    ] {
        let in_path = dir.join(format!("{name}.mcap"));
        write(
            &in_path,
            &drive_log(&DriveSpec {
                layout,
                ..spec.clone()
            }),
        );
        let summary = process_ok(&in_path, &dir.join(format!("{name}-out.mcap")), &[]);
        assert_eq!(summary["write"]["mode"], "rewrite", "{name}");
        let reason = summary["write"]["reason"].as_str().unwrap();
        assert!(reason.contains(why), "{name}: {reason}");
    }
}

/// Flip one byte in the payload of the first message on `channel` (in an
/// uncompressed chunk: framing survives, only the chunk CRC tells).
fn corrupt_chunk_with(bytes: &mut [u8], channel: u16) {
    let summary = mcap::Summary::read(bytes).unwrap().unwrap();
    let mut chunks = summary.chunk_indexes.clone();
    chunks.sort_by_key(|c| c.chunk_start_offset);
    let chunk = chunks
        .iter()
        .find(|c| c.message_index_offsets.contains_key(&channel))
        .unwrap();
    let indexes = summary.read_message_indexes(bytes, chunk).unwrap();
    let (_, entries) = indexes.iter().find(|(c, _)| c.id == channel).unwrap();
    let payload_start = chunk.compressed_data_offset().unwrap() + entries[0].offset + 9 + 22;
    bytes[payload_start as usize + 100] ^= 0x5a;
}

/// Input messages without checking CRCs (the input is damaged on purpose).
fn unchecked_messages(bytes: &[u8]) -> Vec<RawMessage> {
    mcap::MessageStream::new(bytes)
        .unwrap()
        .map(|m| {
            let m = m.unwrap();
            RawMessage {
                channel_id: m.channel.id,
                sequence: m.sequence,
                log_time: m.log_time,
                publish_time: m.publish_time,
                data: m.data.into_owned(),
            }
        })
        .collect()
}

#[test]
fn a_chunk_failing_its_crc_is_written_anew_or_fails_a_strict_run() {
    let dir = scratch("passthrough-crc");
    let synth = synth_drive(&dir);
    let clean = chunked_input(&synth, None, &dir.join("clean.mcap"));
    let channel_of = |topic: &str| {
        let contents = read_all(&clean);
        *contents
            .channels
            .iter()
            .find(|(_, c)| c.topic == topic)
            .unwrap()
            .0
    };
    // A LiDAR chunk is decompressed anyway; a truth-only one only with --verify.
    for (topic, extra) in [
        ("/lidar/points", &[][..]),
        ("/truth/points", &["--verify"][..]),
    ] {
        let mut input = clean.clone();
        corrupt_chunk_with(&mut input, channel_of(topic));
        let in_path = dir.join("in.mcap");
        write(&in_path, &input);
        let out_path = dir.join("out.mcap");
        let summary = process_ok(&in_path, &out_path, extra);
        assert_eq!(summary["write"]["mode"], "pass_through");
        let report = &summary["input_report"];
        assert_eq!(report["bad_crc_chunks"], 1, "{topic}");
        assert!(summary["warnings"].to_string().contains("CRC"), "{topic}");
        let chunks = stored_chunks(&input).len() as u64;
        assert_eq!(report["chunks_copied"], chunks - 1, "{topic}");
        if !extra.is_empty() {
            assert_eq!(
                report["chunks_decompressed"], chunks,
                "--verify reads every chunk"
            );
        }
        let output = std::fs::read(&out_path).unwrap();
        validate_crcs(&output);
        let in_ids: Vec<u16> = read_all(&clean).channels.keys().copied().collect();
        let copied: Vec<RawMessage> = stream_messages(&output)
            .into_iter()
            .filter(|m| in_ids.contains(&m.channel_id))
            .collect();
        assert!(
            sorted(copied) == sorted(unchecked_messages(&input)),
            "{topic}: every input message kept, the damaged chunk's too"
        );
        let strict = dir.join("strict.mcap");
        let mut args = vec!["--strict"];
        args.extend_from_slice(extra);
        let run = looming_process(&in_path, &strict, &args);
        assert_eq!(run.status.code(), Some(3), "{topic}: {}", stderr(&run));
        assert!(!strict.exists(), "no output on failure");
    }
}

#[test]
fn bad_messages_in_copied_chunks_are_skipped_counted_and_kept() {
    let dir = scratch("passthrough-bad-message");
    let synth = synth_drive(&dir);
    let in_path = dir.join("in.mcap");
    let mut imu_seen = 0;
    let input = chunked_input_with(&synth, Some(mcap::Compression::Zstd), &in_path, &mut |m| {
        if m.channel.topic == "/imu/data" {
            imu_seen += 1;
            if imu_seen == 5 {
                m.data = std::borrow::Cow::Owned(m.data[..10].to_vec());
            }
        }
    });
    let out_path = dir.join("out.mcap");
    let summary = process_ok(&in_path, &out_path, &[]);
    assert_eq!(summary["write"]["mode"], "pass_through");
    assert_eq!(summary["bad_messages"], 1);
    assert_eq!(summary["bad_messages_by_topic"]["/imu/data"], 1);
    let output = read_all(&std::fs::read(&out_path).unwrap());
    assert_all_input_messages_copied(&read_all(&input), &output);

    let strict = dir.join("strict.mcap");
    let run = looming_process(&in_path, &strict, &["--strict"]);
    assert_eq!(run.status.code(), Some(3), "{}", stderr(&run));
    assert!(stderr(&run).contains("/imu/data"), "{}", stderr(&run));
    assert!(!strict.exists(), "no output on failure");
}
