//! The official MCAP conformance suite (foxglove/mcap `tests/conformance`,
//! see `tests/conformance/README.md`) through `process --if-no-lidar copy`:
//! every file must come out as a valid MCAP holding every message, attachment
//! and metadata record its `.json` lists. The expectation is parsed from the
//! suite's JSON, not read back with our own reader; the output is read with
//! the mcap crate (linear pass with CRCs, and its summary).

mod common;

use std::collections::BTreeMap;
use std::path::{Path, PathBuf};

use common::{looming_process, read_all, scratch, stderr};
use serde_json::Value;

const SUITE_SIZE: usize = 416;

/// A message as the suite lists it, keyed by topic instead of channel id.
#[derive(Debug, Clone, PartialEq, Eq, PartialOrd, Ord)]
struct Message {
    topic: String,
    sequence: u32,
    log_time: u64,
    publish_time: u64,
    data: Vec<u8>,
}

#[derive(Debug, Clone, PartialEq, Eq, PartialOrd, Ord)]
struct Attachment {
    name: String,
    media_type: String,
    log_time: u64,
    create_time: u64,
    data: Vec<u8>,
}

#[derive(Debug, Clone, PartialEq, Eq, PartialOrd, Ord)]
struct Metadata {
    name: String,
    map: BTreeMap<String, String>,
}

/// A channel as the suite lists it: topic, encoding, and its schema
/// (name, encoding, data) when it has one.
#[derive(Debug, Clone, PartialEq, Eq)]
struct Channel {
    topic: String,
    message_encoding: String,
    schema: Option<(String, String, Vec<u8>)>,
    metadata: BTreeMap<String, String>,
}

#[derive(Debug, Default)]
struct Expected {
    messages: Vec<Message>,
    attachments: Vec<Attachment>,
    metadata: Vec<Metadata>,
    channels: BTreeMap<String, Channel>,
}

/// Every `.mcap` of the suite, sorted.
fn suite_files() -> Vec<PathBuf> {
    let root = Path::new(env!("CARGO_MANIFEST_DIR")).join("tests/conformance/data");
    let mut files = Vec::new();
    for dir in std::fs::read_dir(&root).expect("tests/conformance/data exists") {
        for file in std::fs::read_dir(dir.unwrap().path()).unwrap() {
            let path = file.unwrap().path();
            if path.extension().is_some_and(|e| e == "mcap") {
                files.push(path);
            }
        }
    }
    files.sort();
    files
}

fn field<'a>(record: &'a Value, name: &str) -> &'a Value {
    record["fields"]
        .as_array()
        .expect("fields")
        .iter()
        .find(|pair| pair[0] == name)
        .map(|pair| &pair[1])
        .unwrap_or_else(|| panic!("field {name} in {record}"))
}

fn number<T: std::str::FromStr>(record: &Value, name: &str) -> T
where
    T::Err: std::fmt::Debug,
{
    field(record, name)
        .as_str()
        .expect("a number as a string")
        .parse()
        .unwrap()
}

fn text(record: &Value, name: &str) -> String {
    field(record, name).as_str().expect("a string").to_string()
}

fn bytes(record: &Value, name: &str) -> Vec<u8> {
    field(record, name)
        .as_array()
        .expect("bytes as an array")
        .iter()
        .map(|b| b.as_str().unwrap().parse().unwrap())
        .collect()
}

/// The records the suite's JSON lists for one file (the data section's and
/// the summary's: repeated schemas and channels are the same records).
fn expected(json: &Path) -> Expected {
    let parsed: Value = serde_json::from_slice(&std::fs::read(json).unwrap()).unwrap();
    let mut schemas: BTreeMap<u16, (String, String, Vec<u8>)> = BTreeMap::new();
    let mut channels: BTreeMap<u16, Channel> = BTreeMap::new();
    let mut expected = Expected::default();
    let mut message_channels = Vec::new();
    for record in parsed["records"].as_array().expect("records") {
        match record["type"].as_str().unwrap() {
            "Schema" => {
                let schema = (
                    text(record, "name"),
                    text(record, "encoding"),
                    bytes(record, "data"),
                );
                schemas.insert(number(record, "id"), schema);
            }
            "Channel" => {
                let schema_id: u16 = number(record, "schema_id");
                let channel = Channel {
                    topic: text(record, "topic"),
                    message_encoding: text(record, "message_encoding"),
                    schema: (schema_id != 0).then(|| schemas[&schema_id].clone()),
                    metadata: serde_json::from_value(field(record, "metadata").clone()).unwrap(),
                };
                channels.insert(number(record, "id"), channel);
            }
            "Message" => {
                let channel_id: u16 = number(record, "channel_id");
                message_channels.push(channel_id);
                expected.messages.push(Message {
                    topic: String::new(), // filled in below: channels may come later
                    sequence: number(record, "sequence"),
                    log_time: number(record, "log_time"),
                    publish_time: number(record, "publish_time"),
                    data: bytes(record, "data"),
                });
            }
            "Attachment" => expected.attachments.push(Attachment {
                name: text(record, "name"),
                media_type: text(record, "media_type"),
                log_time: number(record, "log_time"),
                create_time: number(record, "create_time"),
                data: bytes(record, "data"),
            }),
            "Metadata" => expected.metadata.push(Metadata {
                name: text(record, "name"),
                map: serde_json::from_value(field(record, "metadata").clone()).unwrap(),
            }),
            _ => {}
        }
    }
    for (message, channel_id) in expected.messages.iter_mut().zip(message_channels) {
        let channel = &channels[&channel_id];
        message.topic = channel.topic.clone();
        expected
            .channels
            .insert(channel.topic.clone(), channel.clone());
    }
    expected
}

/// Run one file through `process --if-no-lidar copy EXTRA` and say what is
/// wrong with the output, if anything.
fn check(input: &Path, output: &Path, extra: &[&str]) -> Result<(), String> {
    let expected = expected(&input.with_extension("json"));
    let mut args = vec!["--if-no-lidar", "copy", "--force", "-q"];
    args.extend_from_slice(extra);
    let run = looming_process(input, output, &args);
    if !run.status.success() {
        return Err(format!(
            "exit {:?}: {}",
            run.status.code(),
            stderr(&run).trim()
        ));
    }
    let bytes = std::fs::read(output).map_err(|e| format!("no output: {e}"))?;
    let contents = std::panic::catch_unwind(|| read_all(&bytes))
        .map_err(|_| "the output does not read linearly (bad record or CRC)".to_string())?;
    let summary = mcap::Summary::read(&bytes)
        .map_err(|e| format!("the output's summary does not read: {e}"))?
        .ok_or("the output has no summary")?;
    // Each channel with messages is in the output's summary with its metadata
    // (the linear pass compares encoding and schema below).
    for want in expected.channels.values() {
        let found = summary.channels.values().find(|c| c.topic == want.topic);
        if found.map(|c| c.metadata.clone().into_iter().collect()) != Some(want.metadata.clone()) {
            return Err(format!(
                "channel {} is not in the output's summary with metadata {:?}",
                want.topic, want.metadata
            ));
        }
    }
    let stats = summary
        .stats
        .ok_or("the output's summary has no statistics")?;
    if stats.message_count != expected.messages.len() as u64 {
        return Err(format!(
            "the output's statistics count {} messages, expected {}",
            stats.message_count,
            expected.messages.len()
        ));
    }

    same_records(
        "messages",
        output_messages(&contents, &expected)?,
        &expected.messages,
    )?;
    let attachments = contents
        .attachments
        .iter()
        .map(|a| Attachment {
            name: a.name.clone(),
            media_type: a.media_type.clone(),
            log_time: a.log_time,
            create_time: a.create_time,
            data: a.data.clone(),
        })
        .collect();
    same_records("attachments", attachments, &expected.attachments)?;
    // Our run record (`looming`) is the one metadata record added.
    let metadata = contents
        .metadata
        .iter()
        .filter(|m| m.name != "looming")
        .map(|m| Metadata {
            name: m.name.clone(),
            map: m.metadata.clone().into_iter().collect(),
        })
        .collect();
    same_records("metadata", metadata, &expected.metadata)?;
    if contents
        .metadata
        .iter()
        .filter(|m| m.name == "looming")
        .count()
        != 1
    {
        return Err("the output lacks the looming run record".into());
    }
    Ok(())
}

/// The output's messages keyed by topic, each channel (encoding, schema)
/// checked against the suite's.
fn output_messages(
    contents: &common::FileContents,
    expected: &Expected,
) -> Result<Vec<Message>, String> {
    let mut messages = Vec::new();
    for message in &contents.messages {
        let channel = contents
            .channels
            .get(&message.channel_id)
            .ok_or(format!("message on unknown channel {}", message.channel_id))?;
        if let Some(want) = expected.channels.get(&channel.topic) {
            let schema = channel
                .schema
                .as_ref()
                .map(|s| (s.name.clone(), s.encoding.clone(), s.data.clone()));
            if channel.message_encoding != want.message_encoding || schema != want.schema {
                return Err(format!(
                    "channel {} changed: {channel:?}, expected {want:?}",
                    channel.topic
                ));
            }
        }
        messages.push(Message {
            topic: channel.topic.clone(),
            sequence: message.sequence,
            log_time: message.log_time,
            publish_time: message.publish_time,
            data: message.data.clone(),
        });
    }
    Ok(messages)
}

/// `found` and `want` hold the same records, in any order.
fn same_records<T: Ord + Clone>(what: &str, mut found: Vec<T>, want: &[T]) -> Result<(), String> {
    let mut want = want.to_vec();
    found.sort();
    want.sort();
    if found == want {
        Ok(())
    } else {
        Err(format!(
            "{what}: {} out, {} expected (or they differ)",
            found.len(),
            want.len()
        ))
    }
}

#[test]
fn every_conformance_file_is_copied_through_in_full() {
    let files = suite_files();
    assert_eq!(
        files.len(),
        SUITE_SIZE,
        "the suite's files (tests/conformance/README.md says how to get them)"
    );
    let dir = scratch("conformance");
    let mut failures: Vec<(String, &str, String)> = Vec::new();
    for (runs, extra) in [("copy", &[][..]), ("copy --verify", &["--verify"][..])] {
        for (i, input) in files.iter().enumerate() {
            let output = dir.join(format!("{i}.mcap"));
            if let Err(why) = check(input, &output, extra) {
                let name = input.file_name().unwrap().to_string_lossy().into_owned();
                failures.push((name, runs, why));
            }
        }
    }
    let failed_files: std::collections::BTreeSet<&str> =
        failures.iter().map(|(name, _, _)| name.as_str()).collect();
    let kept = files.len() - failed_files.len();
    if !failures.is_empty() {
        eprintln!("{:<55} {:<14} what", "file", "run");
        for (name, runs, why) in &failures {
            eprintln!("{name:<55} {runs:<14} {why}");
        }
        panic!("conformance: kept in full {kept}/{}", files.len());
    }
    eprintln!("conformance: {kept}/{} kept in full", files.len());
    let _ = std::fs::remove_dir_all(&dir);
}
