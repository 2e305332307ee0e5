//! Helpers shared by the integration tests: build logs on disk, run the real
//! `looming` binary, and read outputs back with an independent reader
//! (`mcap::MessageStream`, a linear pass: not the code under test).
#![allow(dead_code)]

use std::collections::BTreeMap;
use std::path::{Path, PathBuf};
use std::process::Output;

#[allow(unused_imports)]
pub use looming::testkit::{DriveSpec, Encoding, Layout, drive_log};

/// A message as an independent reader sees it.
#[derive(Debug, Clone, PartialEq, Eq, PartialOrd, Ord)]
pub struct RawMessage {
    pub channel_id: u16,
    pub sequence: u32,
    pub log_time: u64,
    pub publish_time: u64,
    pub data: Vec<u8>,
}

/// A schema record as read back.
#[derive(Debug, Clone, PartialEq, Eq)]
pub struct SchemaRecord {
    pub id: u16,
    pub name: String,
    pub encoding: String,
    pub data: Vec<u8>,
}

/// A channel record as read back, with its schema.
#[derive(Debug, Clone, PartialEq, Eq)]
pub struct ChannelRecord {
    pub topic: String,
    pub message_encoding: String,
    pub schema: Option<SchemaRecord>,
}

/// An attachment as read back.
#[derive(Debug, Clone, PartialEq, Eq)]
pub struct AttachmentRecord {
    pub name: String,
    pub media_type: String,
    pub log_time: u64,
    pub create_time: u64,
    pub data: Vec<u8>,
}

/// Everything in a file, read linearly.
pub struct FileContents {
    pub profile: String,
    pub messages: Vec<RawMessage>,
    pub channels: BTreeMap<u16, ChannelRecord>,
    pub metadata: Vec<mcap::records::Metadata>,
    pub attachments: Vec<AttachmentRecord>,
}

impl FileContents {
    pub fn topic_messages(&self, topic: &str) -> Vec<&RawMessage> {
        let ids: Vec<u16> = self
            .channels
            .iter()
            .filter(|(_, channel)| channel.topic == topic)
            .map(|(id, _)| *id)
            .collect();
        self.messages
            .iter()
            .filter(|m| ids.contains(&m.channel_id))
            .collect()
    }
}

/// Read every record of `bytes` with the mcap crate's linear reader, checking
/// CRCs, and fail the test on any error (a valid, complete MCAP).
pub fn read_all(bytes: &[u8]) -> FileContents {
    let mut contents = FileContents {
        profile: String::new(),
        messages: Vec::new(),
        channels: BTreeMap::new(),
        metadata: Vec::new(),
        attachments: Vec::new(),
    };
    let mut schemas = BTreeMap::new();
    for record in mcap::read::LinearReader::new(bytes).expect("valid magic") {
        let record = record.expect("every record of the output parses and its CRCs match");
        if let mcap::records::Record::Chunk { header, data } = record {
            let inner = decompress_chunk(&header, &data);
            for inner_record in mcap::read::LinearReader::sans_magic(&inner) {
                absorb(
                    inner_record.expect("records inside chunks parse"),
                    &mut schemas,
                    &mut contents,
                );
            }
        } else {
            absorb(record, &mut schemas, &mut contents);
        }
    }
    contents
}

/// File one record into `contents`.
fn absorb(
    record: mcap::records::Record<'_>,
    schemas: &mut BTreeMap<u16, SchemaRecord>,
    contents: &mut FileContents,
) {
    use mcap::records::Record;
    match record {
        Record::Header(header) => contents.profile = header.profile,
        Record::Schema { header, data } => {
            let schema = SchemaRecord {
                id: header.id,
                name: header.name,
                encoding: header.encoding,
                data: data.into_owned(),
            };
            schemas.insert(schema.id, schema);
        }
        Record::Channel(channel) => {
            let record = ChannelRecord {
                topic: channel.topic,
                message_encoding: channel.message_encoding,
                schema: schemas.get(&channel.schema_id).cloned(),
            };
            contents.channels.insert(channel.id, record);
        }
        Record::Message { header, data } => contents.messages.push(RawMessage {
            channel_id: header.channel_id,
            sequence: header.sequence,
            log_time: header.log_time,
            publish_time: header.publish_time,
            data: data.into_owned(),
        }),
        Record::Metadata(metadata) => contents.metadata.push(metadata),
        Record::Attachment { header, data, .. } => contents.attachments.push(AttachmentRecord {
            name: header.name,
            media_type: header.media_type,
            log_time: header.log_time,
            create_time: header.create_time,
            data: data.into_owned(),
        }),
        _ => {}
    }
}

fn decompress_chunk(header: &mcap::records::ChunkHeader, data: &[u8]) -> Vec<u8> {
    use std::io::Read;
    let out = match header.compression.as_str() {
        "" => data.to_vec(),
        "zstd" => zstd::decode_all(data).expect("zstd chunk"),
        "lz4" => {
            let mut out = Vec::new();
            lz4::Decoder::new(data)
                .unwrap()
                .read_to_end(&mut out)
                .unwrap();
            out
        }
        other => panic!("unexpected compression {other}"),
    };
    if header.uncompressed_crc != 0 {
        assert_eq!(crc32fast::hash(&out), header.uncompressed_crc, "chunk CRC");
    }
    out
}

/// A scratch directory for one test. It is left after the test (to look at
/// after a failure) until the same test runs again from another process,
/// which removes it: a run of the suite leaves about 2 GB (the split
/// sensors' logs alone 279 MB), and runs must not pile up on a machine.
pub fn scratch(name: &str) -> PathBuf {
    let root = std::env::temp_dir().join("looming-tests");
    remove_finished_runs(&root, name);
    let dir = root.join(format!("{name}-{}", std::process::id()));
    let _ = std::fs::remove_dir_all(&dir);
    std::fs::create_dir_all(&dir).unwrap();
    dir
}

/// Removes `root/NAME-PID` of processes that have ended (Linux's `/proc`
/// tells; elsewhere nothing is removed, as a running one could be).
fn remove_finished_runs(root: &Path, name: &str) {
    if !Path::new("/proc/self").exists() {
        return;
    }
    let Ok(entries) = std::fs::read_dir(root) else {
        return;
    };
    for entry in entries.flatten() {
        let file_name = entry.file_name();
        let pid = file_name
            .to_str()
            .and_then(|f| f.strip_prefix(name))
            .and_then(|rest| rest.strip_prefix('-'))
            .and_then(|pid| pid.parse::<u32>().ok());
        if let Some(pid) = pid
            && pid != std::process::id()
            && !Path::new(&format!("/proc/{pid}")).exists()
        {
            let _ = std::fs::remove_dir_all(entry.path());
        }
    }
}

pub fn write(path: &Path, bytes: &[u8]) {
    std::fs::write(path, bytes).unwrap();
}

/// Run the real binary.
pub fn looming(args: &[&str]) -> Output {
    std::process::Command::new(env!("CARGO_BIN_EXE_looming"))
        .args(args)
        .output()
        .expect("the looming binary runs")
}

/// Run `looming synth --scenario SCENARIO EXTRA...` into `DIR/SCENARIO.mcap`.
pub fn synth(dir: &Path, scenario: &str, extra: &[&str]) -> PathBuf {
    let out = dir.join(format!("{scenario}.mcap"));
    let mut args = vec![
        "synth",
        "--scenario",
        scenario,
        "-o",
        out.to_str().unwrap(),
        "--force",
        "-q",
    ];
    args.extend_from_slice(extra);
    let run = looming(&args);
    assert!(run.status.success(), "{scenario}: {}", stderr(&run));
    out
}

/// The cut-in's near-miss window (2-4 s) at 32 x 512, the resolution of
/// most tests, in `DIR/NAME.mcap`, with `extra` synth options.
pub fn cut_in_window(dir: &Path, name: &str, extra: &[&str]) -> PathBuf {
    let out = dir.join(format!("{name}.mcap"));
    let mut args = vec![
        "synth",
        "--scenario",
        "cut-in",
        "--start",
        "2",
        "--duration",
        "4",
        "--beams",
        "32",
        "--columns",
        "512",
        "-o",
    ];
    args.push(out.to_str().unwrap());
    args.extend_from_slice(&["--force", "-q"]);
    args.extend_from_slice(extra);
    let run = looming(&args);
    assert!(run.status.success(), "{name}: {}", stderr(&run));
    out
}

/// Run `looming process INPUT -o OUTPUT EXTRA...`.
pub fn looming_process(input: &Path, output: &Path, extra: &[&str]) -> Output {
    let mut args = vec![
        "process",
        input.to_str().expect("UTF-8 path"),
        "-o",
        output.to_str().expect("UTF-8 path"),
    ];
    args.extend_from_slice(extra);
    looming(&args)
}

pub fn stderr(output: &Output) -> String {
    String::from_utf8_lossy(&output.stderr).into_owned()
}

/// Assert that every message of `input` is in `output`, unchanged (as a multiset).
pub fn assert_all_input_messages_copied(input: &FileContents, output: &FileContents) {
    let input_ids: Vec<u16> = input.channels.keys().copied().collect();
    let mut expected = input.messages.clone();
    let mut actual: Vec<RawMessage> = output
        .messages
        .iter()
        .filter(|m| input_ids.contains(&m.channel_id))
        .cloned()
        .collect();
    expected.sort();
    actual.sort();
    assert_eq!(
        expected.len(),
        actual.len(),
        "number of copied input messages"
    );
    assert!(expected == actual, "copied messages differ from the input");
    for (id, channel) in &input.channels {
        assert_eq!(
            output.channels.get(id),
            Some(channel),
            "channel {id} copied with its schema under the same ids"
        );
    }
}

/// `looming batch LOGS -o OUT -q` through the binary: `OUT/fleet.json`
/// (the run must succeed).
pub fn looming_batch(logs: &Path, out: &Path) -> serde_json::Value {
    let run = looming(&[
        "batch",
        logs.to_str().unwrap(),
        "-o",
        out.to_str().unwrap(),
        "-q",
    ]);
    assert!(run.status.success(), "{}", stderr(&run));
    serde_json::from_slice(&std::fs::read(out.join("fleet.json")).unwrap()).unwrap()
}

/// `looming quality OUTPUT --json JSON` through the binary: the JSON report
/// and the text printed (the run must succeed).
pub fn looming_quality(output: &Path, json: &Path) -> (serde_json::Value, String) {
    let run = looming(&[
        "quality",
        output.to_str().unwrap(),
        "--json",
        json.to_str().unwrap(),
    ]);
    assert!(
        run.status.success(),
        "quality {}: {}",
        output.display(),
        stderr(&run)
    );
    let text = String::from_utf8_lossy(&run.stdout).into_owned();
    let report = serde_json::from_slice(&std::fs::read(json).unwrap()).unwrap();
    (report, text)
}

/// A copy of the MCAP `input` at `output` (ROS 2 profile), each message
/// through `edit`: returned (possibly changed) it is written, `None` drops it.
pub fn rewrite_mcap(
    input: &Path,
    output: &Path,
    mut edit: impl FnMut(mcap::Message<'_>) -> Option<mcap::Message<'_>>,
) {
    let bytes = std::fs::read(input).unwrap();
    let mut writer = mcap::WriteOptions::new()
        .profile("ros2")
        .create(std::io::BufWriter::new(
            std::fs::File::create(output).unwrap(),
        ))
        .unwrap();
    for message in mcap::MessageStream::new(&bytes).unwrap() {
        if let Some(message) = edit(message.unwrap()) {
            writer.write(&message).unwrap();
        }
    }
    writer.finish().unwrap();
}
pub mod viewer;

/// `bytes` (an MCAP) with a new channel `topic` carrying every message of
/// channel `from_topic` again: a second sensor publishing the same data.
pub fn with_channel_copy(bytes: &[u8], from_topic: &str, topic: &str) -> Vec<u8> {
    let contents = read_all(bytes);
    let (&from, source) = contents
        .channels
        .iter()
        .find(|(_, c)| c.topic == from_topic)
        .expect("the channel to copy");
    let mut log = looming::testkit::LogBuilder::new(looming::testkit::Layout::indexed(), "ros2");
    for (id, channel) in &contents.channels {
        let schema = channel.schema.clone().unwrap();
        log.schema(schema.id, &schema.name, &schema.encoding, &schema.data);
        log.channel(*id, schema.id, &channel.topic, &channel.message_encoding);
    }
    let copy = contents.channels.keys().max().copied().unwrap_or(0) + 1;
    log.channel(
        copy,
        source.schema.as_ref().unwrap().id,
        topic,
        &source.message_encoding,
    );
    for m in &contents.messages {
        log.message(
            m.channel_id,
            m.sequence,
            m.log_time,
            m.publish_time,
            &m.data,
        );
        if m.channel_id == from {
            log.message(copy, m.sequence, m.log_time, m.publish_time, &m.data);
        }
    }
    log.finish()
}
