//! Every MCAP we write opens right in Foxglove and Lichtblick, checked
//! without a browser (`tests/common/viewer.rs` says what each check mirrors):
//! the committed sample logs, `process` on both write paths (chunks copied,
//! and every message written anew), `synth`, `batch` and its clips.
//! `scripts/check-viewers.sh` opens the same files in the real Lichtblick.

mod common;

use std::path::{Path, PathBuf};

use common::viewer::{
    assert_opens_in_viewers, chunk_time_problems, json_schema_problem, ros2_definition_problem,
};
use common::{looming, looming_process, scratch, stderr};
use looming::testkit::{Layout, LogBuilder};

fn sample(name: &str) -> PathBuf {
    Path::new(env!("CARGO_MANIFEST_DIR"))
        .join("sample_logs")
        .join(name)
}

const SEP: &str =
    "================================================================================";

#[test]
fn the_ros2_check_refuses_a_dependency_named_with_msg() {
    let good = format!(
        "std_msgs/Header header\nfloat64 x\n{SEP}\nMSG: std_msgs/Header\nbuiltin_interfaces/Time stamp\nstring frame_id\n{SEP}\nMSG: builtin_interfaces/Time\nint32 sec\nuint32 nanosec\n"
    );
    assert_eq!(ros2_definition_problem("pkg/msg/Thing", &good), Ok(()));
    // What synth wrote before: the viewers find no `std_msgs/Header`.
    let old = good.replace("MSG: std_msgs/Header", "MSG: std_msgs/msg/Header");
    let problem = ros2_definition_problem("pkg/msg/Thing", &old).unwrap_err();
    assert!(problem.contains("MSG: std_msgs/Header"), "{problem}");
    // Same-package names resolve against their section; constants and
    // defaults are no types.
    let relative = format!(
        "geometry_msgs/Pose pose\n{SEP}\nMSG: geometry_msgs/Pose\nPoint position\nuint8 KIND = 1\nfloat64 w 1\n{SEP}\nMSG: geometry_msgs/Point\nfloat64 x\n"
    );
    assert_eq!(ros2_definition_problem("a/msg/B", &relative), Ok(()));
    let unused = format!("float64 x\n{SEP}\nMSG: std_msgs/Header\nstring frame_id\n");
    assert!(ros2_definition_problem("a/msg/B", &unused).is_err());
}

#[test]
fn the_json_schema_check_takes_only_what_the_viewers_read() {
    let ok = r#"{"type":"object","properties":{"a":{"type":"number"},
        "b":{"type":"array","items":{"type":"object","properties":{"c":{"type":"string","enum":["x"]}}}},
        "d":{"type":"object","properties":{"e":{"type":"array","items":{"type":"integer"}}}}}}"#;
    assert_eq!(json_schema_problem(ok), Ok(()));
    for (bad, why) in [
        (
            r##"{"type":"object","properties":{"p":{"$ref":"#/$defs/p"}}}"##,
            "$ref",
        ),
        (
            r#"{"type":"object","properties":{"p":{"type":["number","null"]}}}"#,
            "one string",
        ),
        (
            r#"{"type":"object","properties":{"p":{"enum":["a","b"]}}}"#,
            "no \"type\"",
        ),
        (
            r#"{"type":"object","properties":{"p":{"oneOf":[{"type":"null"},{"type":"number"}]}}}"#,
            "oneOf",
        ),
        (
            r#"{"type":"object","properties":{"p":{"type":"array","items":{"type":"array","items":{"type":"integer"}}}}}"#,
            "items must be",
        ),
    ] {
        let problem = json_schema_problem(bad).unwrap_err();
        assert!(problem.contains(why), "{bad}: {problem}");
    }
}

/// A chunked, indexed log whose first chunk holds no message (as the mcap
/// writer leaves one when a metadata record closes a chunk of schema and
/// channel records), then three messages.
fn log_with_a_message_less_chunk() -> Vec<u8> {
    let mut log = LogBuilder::new(Layout::indexed(), "ros2");
    log.schema(1, "std_msgs/msg/String", "ros2msg", b"string data");
    log.channel(1, 1, "/chatter", "cdr");
    log.empty_chunk();
    log.metadata("recorder", &[("who", "test")]);
    for i in 0..3u64 {
        let t = 1_700_000_000_000_000_000 + i * 100_000_000;
        log.message(1, i as u32, t, t, &[0, 1, 0, 0, 1, 0, 0, 0, b'x', 0]);
    }
    log.finish()
}

#[test]
fn the_chunk_check_refuses_a_chunk_without_messages() {
    let problems = chunk_time_problems(&log_with_a_message_less_chunk());
    assert!(
        problems.iter().any(|p| p.contains("holds no message")),
        "{problems:?}"
    );
    assert!(
        problems.iter().any(|p| p.contains("outside")),
        "{problems:?}"
    );
}

#[test]
fn the_committed_sample_logs_open_in_viewers() {
    let dir = Path::new(env!("CARGO_MANIFEST_DIR")).join("sample_logs");
    let mut checked = 0;
    for entry in std::fs::read_dir(dir).unwrap() {
        let path = entry.unwrap().path();
        if path.extension().is_some_and(|e| e == "mcap") {
            assert_opens_in_viewers(&path);
            checked += 1;
        }
    }
    assert!(checked >= 5, "{checked} sample logs");
}

#[test]
fn process_outputs_open_in_viewers_on_both_write_paths() {
    let dir = scratch("viewer-process");
    // Pass-through: the input's chunks copied. (The sample's `/truth/events`
    // come last in the file with earlier log times, which makes `process`
    // rewrite it; without them its chunks are copied.)
    let in_order = dir.join("in-order.mcap");
    common::rewrite_mcap(&sample("cut-in.mcap"), &in_order, |message| {
        (message.channel.topic != "/truth/events").then_some(message)
    });
    let copied = dir.join("copied.mcap");
    let run = looming_process(&in_order, &copied, &[]);
    assert!(run.status.success(), "{}", stderr(&run));
    assert!(stderr(&run).contains("pass-through"), "{}", stderr(&run));
    assert_opens_in_viewers(&copied);
    // Rewrite: every message written anew (the README's first command).
    let rewritten = dir.join("rewritten.mcap");
    let run = looming_process(&sample("cut-in.mcap"), &rewritten, &[]);
    assert!(run.status.success(), "{}", stderr(&run));
    assert!(stderr(&run).contains("written anew"), "{}", stderr(&run));
    assert_opens_in_viewers(&rewritten);
    // And --replace of an annotated log.
    let replaced = dir.join("replaced.mcap");
    let run = looming_process(&copied, &replaced, &["--replace"]);
    assert!(run.status.success(), "{}", stderr(&run));
    assert_opens_in_viewers(&replaced);
}

#[test]
fn a_message_less_input_chunk_is_not_copied_and_no_record_is_lost() {
    let dir = scratch("viewer-empty-chunk");
    let input = dir.join("in.mcap");
    std::fs::write(&input, log_with_a_message_less_chunk()).unwrap();
    assert!(!chunk_time_problems(&std::fs::read(&input).unwrap()).is_empty());
    let output = dir.join("out.mcap");
    let run = looming_process(&input, &output, &["--if-no-lidar", "copy"]);
    assert!(run.status.success(), "{}", stderr(&run));
    assert_opens_in_viewers(&output);
    let before = common::read_all(&std::fs::read(&input).unwrap());
    let after = common::read_all(&std::fs::read(&output).unwrap());
    common::assert_all_input_messages_copied(&before, &after);
    assert!(
        after.metadata.iter().any(|m| m.name == "recorder"),
        "the input's metadata is kept"
    );
}

#[test]
fn synth_outputs_open_in_viewers() {
    let dir = scratch("viewer-synth");
    for (scenario, layout) in [("cut-in", "ring-time"), ("urban-turn", "organized")] {
        let log = common::synth(
            &dir,
            scenario,
            &[
                "--duration",
                "0.5",
                "--beams",
                "16",
                "--columns",
                "256",
                "--layout",
                layout,
            ],
        );
        assert_opens_in_viewers(&log);
    }
}

/// The checks on any file: `LOOMING_VIEWER_CHECK=FILE.mcap cargo test
/// --release --test viewer_compat -- --ignored any_file`.
#[test]
#[ignore = "checks the file named by LOOMING_VIEWER_CHECK"]
fn any_file_opens_in_viewers() {
    let path = std::env::var_os("LOOMING_VIEWER_CHECK").expect("LOOMING_VIEWER_CHECK=FILE.mcap");
    assert_opens_in_viewers(Path::new(&path));
}

fn read_json(path: &Path) -> serde_json::Value {
    serde_json::from_slice(&std::fs::read(path).unwrap()).unwrap()
}

/// `looming layout LOG -o LAYOUT`.
fn layout_of(log: &Path, layout: &Path) -> std::process::Output {
    looming(&[
        "layout",
        log.to_str().unwrap(),
        "-o",
        layout.to_str().unwrap(),
    ])
}

#[test]
fn layout_follows_the_logs_own_lidar_frame() {
    let dir = scratch("viewer-layout");
    let annotated = dir.join("cut-in-annotated.mcap");
    let run = looming_process(&sample("cut-in.mcap"), &annotated, &[]);
    assert!(run.status.success(), "{}", stderr(&run));
    let layout = dir.join("looming.json");
    let run = layout_of(&annotated, &layout);
    assert!(run.status.success(), "{}", stderr(&run));
    let json = read_json(&layout);
    let three_d = &json["configById"]["3D!looming"];
    assert_eq!(three_d["followTf"], "lidar");
    // A LiDAR topic named that the log lacks is refused, annotated or not.
    let unknown = looming(&[
        "layout",
        annotated.to_str().unwrap(),
        "-o",
        dir.join("unknown.json").to_str().unwrap(),
        "--lidar-topic",
        "/nope",
    ]);
    assert_eq!(unknown.status.code(), Some(2), "{}", stderr(&unknown));
    assert!(stderr(&unknown).contains("/nope"), "{}", stderr(&unknown));
    assert_eq!(
        three_d["topics"]["/looming/points"]["colorMode"],
        "rgba-fields"
    );
    assert_eq!(three_d["topics"]["/lidar/points"]["visible"], false);
    for (panel, topic) in [
        ("Image!looming-fused", "/looming/image/fused"),
        ("Image!looming-disagreement", "/looming/image/disagreement"),
    ] {
        assert_eq!(json["configById"][panel]["imageMode"]["imageTopic"], topic);
    }
    assert_eq!(
        json["configById"]["RawMessages!looming-events"]["topicPath"],
        "/looming/events"
    );
    // An input log: the frame of its LiDAR topic's first cloud.
    let from_input = dir.join("input.json");
    let run = layout_of(&sample("ouster-os0-8.mcap"), &from_input);
    assert!(run.status.success(), "{}", stderr(&run));
    let frame = read_json(&from_input)["configById"]["3D!looming"]["followTf"].clone();
    assert_eq!(frame, "os_sensor", "{}", stderr(&run));
    // An existing layout is kept unless --force.
    let again = layout_of(&annotated, &layout);
    assert_eq!(again.status.code(), Some(2), "{}", stderr(&again));
}

/// The messages of a clip, read back.
fn clip_contents(path: &Path) -> common::FileContents {
    common::read_all(&std::fs::read(path).unwrap())
}

#[test]
fn process_writes_a_clip_per_near_miss_with_every_channel_of_its_window() {
    let dir = scratch("viewer-clips");
    let annotated = dir.join("cut-in-annotated.mcap");
    let clips = dir.join("clips");
    let run = looming_process(
        &sample("cut-in.mcap"),
        &annotated,
        &["--clips", clips.to_str().unwrap(), "0.3"],
    );
    assert!(run.status.success(), "{}", stderr(&run));
    assert!(
        stderr(&run).contains("clips         1 written"),
        "{}",
        stderr(&run)
    );
    let clip = clips.join("cut-in-annotated.event-1.mcap");
    assert_opens_in_viewers(&clip);
    let full = clip_contents(&annotated);
    let cut = clip_contents(&clip);
    // The planted near miss: log times 3.0 s to 3.9 s (after 1700000000 s).
    let (start, end) = (1_700_000_002_700_000_000, 1_700_000_004_200_000_000);
    let tf_static = full
        .channels
        .iter()
        .find(|(_, c)| c.topic == "/tf_static")
        .map(|(id, _)| *id)
        .unwrap();
    let mut expected: Vec<_> = full
        .messages
        .iter()
        .filter(|m| (start..=end).contains(&m.log_time))
        .cloned()
        .collect();
    // /tf_static (published once, before the window) carried to its start.
    let mut carried = full
        .messages
        .iter()
        .rfind(|m| m.channel_id == tf_static && m.log_time < start)
        .expect("the log publishes /tf_static before the window")
        .clone();
    carried.log_time = start;
    carried.publish_time = start;
    expected.push(carried);
    let mut got = cut.messages.clone();
    expected.sort();
    got.sort();
    assert_eq!(got.len(), expected.len());
    assert!(
        got == expected,
        "the clip holds the window's messages as they are"
    );
    assert_eq!(cut.channels, full.channels, "every channel, same ids");
    assert!(
        cut.metadata.iter().any(|m| m.name == "looming"),
        "the run record"
    );
    assert!(cut.metadata.iter().any(|m| m.name == "looming.synth"));
    // Existing clips are kept unless --force: the same output name in
    // another folder names the same clip.
    let before = std::fs::read(&clip).unwrap();
    std::fs::create_dir_all(dir.join("other")).unwrap();
    let again = dir.join("other/cut-in-annotated.mcap");
    let refused = looming_process(
        &sample("cut-in.mcap"),
        &again,
        &["--clips", clips.to_str().unwrap(), "0.3"],
    );
    assert!(!refused.status.success(), "{}", stderr(&refused));
    assert!(stderr(&refused).contains("exists"), "{}", stderr(&refused));
    assert_eq!(std::fs::read(&clip).unwrap(), before, "the clip is kept");
    let forced = looming_process(
        &sample("cut-in.mcap"),
        &again,
        &["--clips", clips.to_str().unwrap(), "0.3", "--force"],
    );
    assert!(forced.status.success(), "{}", stderr(&forced));
    let bad = looming_process(
        &sample("cut-in.mcap"),
        &dir.join("bad.mcap"),
        &["--clips", clips.to_str().unwrap(), "soon"],
    );
    assert_eq!(bad.status.code(), Some(2), "{}", stderr(&bad));
}

#[test]
fn batch_links_a_clip_per_near_miss_and_writes_a_layout() {
    let dir = scratch("viewer-batch-clips");
    let input = dir.join("in");
    std::fs::create_dir_all(input.join("day1")).unwrap();
    std::fs::copy(sample("cut-in.mcap"), input.join("day1/cut-in.mcap")).unwrap();
    std::fs::copy(sample("straight-road.mcap"), input.join("straight.mcap")).unwrap();
    let out = dir.join("out");
    let args = [
        "batch",
        input.to_str().unwrap(),
        "-o",
        out.to_str().unwrap(),
        "--jobs",
        "1",
        "--clips",
        "1",
    ];
    let run = looming(&args);
    assert!(run.status.success(), "{}", stderr(&run));
    assert_opens_in_viewers(&out.join("logs/day1/cut-in.mcap"));
    let clip = Path::new("clips/day1/cut-in/cut-in.event-1.mcap");
    assert_opens_in_viewers(&out.join(clip));
    let jsonl = std::fs::read_to_string(out.join("near_misses.jsonl")).unwrap();
    let first: serde_json::Value = serde_json::from_str(jsonl.lines().next().unwrap()).unwrap();
    assert_eq!(first["clip"], clip.to_str().unwrap());
    let csv = std::fs::read_to_string(out.join("near_misses.csv")).unwrap();
    assert!(
        csv.lines()
            .next()
            .unwrap()
            .ends_with(",clip,object_id,lateral_offset_m,sensors"),
        "{csv}"
    );
    assert!(
        csv.contains("clips/day1/cut-in/cut-in.event-1.mcap"),
        "{csv}"
    );
    let report = std::fs::read_to_string(out.join("report.html")).unwrap();
    assert!(report.contains("href=\"clips/day1/cut-in/cut-in.event-1.mcap\""));
    let layout = read_json(&out.join("layout.json"));
    assert_eq!(layout["configById"]["3D!looming"]["followTf"], "lidar");
    // Nothing new: nothing redone, the clip still there.
    let again = looming(&args);
    assert!(again.status.success(), "{}", stderr(&again));
    assert!(stderr(&again).contains("up-to-date"), "{}", stderr(&again));
    assert!(out.join(clip).exists());
}
