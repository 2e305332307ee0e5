//! A cloud that merges several LiDARs on one topic (Autoware's concatenated
//! `base_link` cloud: `synth --lidars 3 --frame vehicle --one-topic`) with a
//! per-point `sensor_id`, through the real CLI: split into one sensor per
//! value, each placed, paired and annotated like a LiDAR of its own; kept
//! whole (and flagged) with `--split-field none`.

mod common;

use std::path::Path;

use common::{looming_process, read_all, scratch, stderr};

/// The rig's mounts in the vehicle frame (`synth`'s roof, left and right
/// LiDARs), m.
const MOUNTS_M: [[f64; 3]; 3] = [[0.8, 0.1, 0.9], [1.0, 0.85, 0.5], [1.0, -0.85, 0.5]];
const SENSORS: [&str; 3] = ["lidars_0", "lidars_1", "lidars_2"];

fn json(path: &Path) -> serde_json::Value {
    serde_json::from_slice(&std::fs::read(path).unwrap()).unwrap()
}

/// Each sensor's origin within `tolerance_m` of its mount, and not flagged.
fn assert_origins(summary: &serde_json::Value, source: &str, tolerance_m: f64) {
    let sensors = summary["sensors"].as_array().expect("a line per sensor");
    assert_eq!(sensors.len(), 3, "{summary}");
    for ((sensor, name), mount) in sensors.iter().zip(SENSORS).zip(MOUNTS_M) {
        assert_eq!(sensor["name"], name);
        assert_eq!(sensor["merged"]["field"], "sensor_id", "{sensor}");
        let origin = &sensor["pairing"]["layout"]["origin"];
        assert_eq!(origin["source"], source, "{name}: {origin}");
        assert_eq!(origin["several_origins"], false, "{name}: {origin}");
        let at: Vec<f64> = serde_json::from_value(origin["position_m"].clone()).unwrap();
        let error_m = at
            .iter()
            .zip(mount)
            .map(|(a, b)| (a - b).powi(2))
            .sum::<f64>()
            .sqrt();
        assert!(error_m < tolerance_m, "{name}: at {at:?}, mount {mount:?}");
    }
}

#[test]
fn a_merged_cloud_is_split_by_its_sensor_field_into_three_sensors() {
    let dir = scratch("split-sensors");
    let extra = ["--lidars", "3", "--frame", "vehicle", "--one-topic"];
    let input = common::cut_in_window(&dir, "merged", &extra);
    let out = dir.join("out.mcap");
    let summary_path = dir.join("summary.json");
    let run = looming_process(
        &input,
        &out,
        &["--json-summary", summary_path.to_str().unwrap()],
    );
    assert!(run.status.success(), "{}", stderr(&run));
    let summary = json(&summary_path);
    assert_origins(&summary, "tf_static", 0.01);
    assert!(
        summary["warnings"].as_array().unwrap().is_empty(),
        "{summary}"
    );
    let contents = read_all(&std::fs::read(&out).unwrap());
    let clouds = contents.topic_messages("/lidars/points").len();
    for sensor in SENSORS {
        for channel in ["pairs", "points", "objects", "image/fused"] {
            let topic = format!("/looming/{sensor}/{channel}");
            let n = contents.topic_messages(&topic).len();
            assert!(n.abs_diff(clouds - 1) <= 1, "{topic}: {n} of {clouds}");
        }
    }
    assert!(contents.topic_messages("/looming/points").is_empty());
    // The planted near miss, once, seen by the three.
    let events = contents.topic_messages("/looming/events");
    assert_eq!(events.len(), 1, "the planted near miss, once");
    let event: serde_json::Value = serde_json::from_slice(&events[0].data).unwrap();
    assert_eq!(event["sensors"], serde_json::json!(SENSORS));
    let ttc = event["min_time_to_contact_s"].as_f64().unwrap();
    assert!((0.8..1.2).contains(&ttc), "{ttc}");
    let (quality, text) = common::looming_quality(&out, &dir.join("quality.json"));
    let sensors = quality["sensors"].as_array().expect("quality per sensor");
    assert_eq!(sensors.len(), 3, "{text}");
    for sensor in sensors {
        let trusted = sensor["totals"]["trusted_fraction"].as_f64().unwrap();
        assert!(trusted > 0.6, "{}: {trusted}", sensor["sensor"]);
    }

    assert_fleet_record(&dir, &input);

    // Without /tf_static the sensors are found from their rings' geometry.
    let no_tf = dir.join("no-tf.mcap");
    common::rewrite_mcap(&input, &no_tf, |m| {
        (m.channel.topic != "/tf_static").then_some(m)
    });
    let no_tf_out = dir.join("no-tf-out.mcap");
    let no_tf_summary = dir.join("no-tf.json");
    let args = ["--json-summary", no_tf_summary.to_str().unwrap()];
    let run = looming_process(&no_tf, &no_tf_out, &args);
    assert!(run.status.success(), "{}", stderr(&run));
    assert_origins(&json(&no_tf_summary), "geometry", 0.05);

    assert_whole_cloud_flagged(&dir, &input);
}

/// `batch`'s fleet record of the merged log has each sensor's trust.
fn assert_fleet_record(dir: &Path, input: &Path) {
    let logs = dir.join("logs");
    std::fs::create_dir_all(&logs).unwrap();
    std::fs::copy(input, logs.join("merged.mcap")).unwrap();
    let fleet = common::looming_batch(&logs, &dir.join("fleet"));
    let log = &fleet[0];
    assert_eq!(log["events"], 1, "{log}");
    let sensors = log["quality"]["sensors"]
        .as_array()
        .expect("each sensor's trust");
    assert_eq!(sensors.len(), 3, "{log}");
}

/// With `--split-field none` the merged cloud is one sensor, flagged.
fn assert_whole_cloud_flagged(dir: &Path, input: &Path) {
    // Kept whole, the merged cloud is flagged as before.
    let whole = dir.join("whole.mcap");
    let whole_summary = dir.join("whole.json");
    let args = [
        "--split-field",
        "none",
        "--json-summary",
        whole_summary.to_str().unwrap(),
    ];
    let run = looming_process(input, &whole, &args);
    assert!(run.status.success(), "{}", stderr(&run));
    let summary = json(&whole_summary);
    assert!(summary["sensors"].as_array().is_none_or(Vec::is_empty));
    assert_eq!(
        summary["pairing"]["layout"]["origin"]["several_origins"],
        true
    );
    let warnings = summary["warnings"].to_string();
    assert!(warnings.contains("do not meet at one point"), "{warnings}");
}
