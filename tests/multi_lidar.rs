//! Vehicles with several LiDARs through the real CLI: every sensor annotated
//! on its own channels (`/looming/<sensor>/...`), one list of near misses for
//! the log, merged across the sensors that saw each one.

mod common;

use std::path::{Path, PathBuf};

use common::{looming_process, read_all, scratch, stderr, write};

/// The committed cut-in with a second LiDAR topic, `/lidar_front/points`,
/// carrying the same clouds (the case a new user met: two sensors).
fn cut_in_with_two_lidars(dir: &Path) -> PathBuf {
    let input = Path::new(env!("CARGO_MANIFEST_DIR")).join("sample_logs/cut-in.mcap");
    let bytes = common::with_channel_copy(
        &std::fs::read(&input).unwrap(),
        "/lidar/points",
        "/lidar_front/points",
    );
    let path = dir.join("two-lidars.mcap");
    write(&path, &bytes);
    path
}

#[test]
fn two_lidars_are_each_annotated_and_their_near_miss_is_one() {
    let dir = scratch("multi-lidar");
    let input = cut_in_with_two_lidars(&dir);
    let out = dir.join("out.mcap");
    let summary = dir.join("summary.json");
    let run = looming_process(&input, &out, &["--json-summary", summary.to_str().unwrap()]);
    assert!(run.status.success(), "{}", stderr(&run));
    let contents = read_all(&std::fs::read(&out).unwrap());
    let input_contents = read_all(&std::fs::read(&input).unwrap());
    common::assert_all_input_messages_copied(&input_contents, &contents);
    let scans = input_contents.topic_messages("/lidar/points").len();
    for sensor in ["lidar", "lidar_front"] {
        for channel in ["points", "pairs", "objects", "object_list", "image/fused"] {
            let topic = format!("/looming/{sensor}/{channel}");
            assert_eq!(
                contents.topic_messages(&topic).len(),
                scans - 1,
                "{topic}: one per pair"
            );
        }
    }
    // No per-sensor copy of the log's event channels, and none unprefixed
    // of the per-sensor ones.
    assert!(contents.topic_messages("/looming/lidar/events").is_empty());
    assert!(contents.topic_messages("/looming/points").is_empty());
    // The same near miss seen by both: one event naming both sensors.
    let events = contents.topic_messages("/looming/events");
    assert_eq!(events.len(), 1, "one near miss for the vehicle");
    let event: serde_json::Value = serde_json::from_slice(&events[0].data).unwrap();
    assert_eq!(
        event["sensors"],
        serde_json::json!(["lidar", "lidar_front"])
    );
    assert!(event["sensor"].is_string(), "{event}");
    let ttc = event["min_time_to_contact_s"].as_f64().unwrap();
    assert!((0.7..1.3).contains(&ttc), "{ttc}");
    assert_eq!(contents.topic_messages("/looming/near_misses").len(), 1);
    let summary: serde_json::Value =
        serde_json::from_slice(&std::fs::read(&summary).unwrap()).unwrap();
    let sensors = summary["sensors"].as_array().expect("a line per sensor");
    assert_eq!(sensors.len(), 2);
    for sensor in sensors {
        assert_eq!(sensor["pairs_written"], scans as u64 - 1, "{sensor}");
        assert_eq!(sensor["vehicle_frame"], "imu_link", "{sensor}");
    }
    assert_eq!(summary["events"].as_array().unwrap().len(), 1);
    let text = String::from_utf8_lossy(&run.stderr);
    assert!(text.contains("/lidar_front/points"), "{text}");
}

#[test]
fn lidar_topic_takes_a_list_or_one() {
    let dir = scratch("multi-lidar-choice");
    let input = cut_in_with_two_lidars(&dir);
    // One topic asked for: today's single-sensor output.
    let one = dir.join("one.mcap");
    let run = looming_process(&input, &one, &["--lidar-topic", "/lidar_front/points"]);
    assert!(run.status.success(), "{}", stderr(&run));
    let contents = read_all(&std::fs::read(&one).unwrap());
    assert!(!contents.topic_messages("/looming/points").is_empty());
    let event: serde_json::Value =
        serde_json::from_slice(&contents.topic_messages("/looming/events")[0].data).unwrap();
    assert!(event.get("sensors").is_none(), "{event}");
    // A list, and `all`.
    for choice in ["/lidar/points,/lidar_front/points", "all"] {
        let both = dir.join("both.mcap");
        let run = looming_process(&input, &both, &["--lidar-topic", choice, "--force"]);
        assert!(run.status.success(), "{choice}: {}", stderr(&run));
        let contents = read_all(&std::fs::read(&both).unwrap());
        assert!(
            !contents
                .topic_messages("/looming/lidar_front/points")
                .is_empty()
        );
        assert!(!contents.topic_messages("/looming/lidar/points").is_empty());
    }
    // An unknown topic in the list is refused, naming the candidates.
    let bad = dir.join("bad.mcap");
    let run = looming_process(&input, &bad, &["--lidar-topic", "/lidar/points,/nope"]);
    assert_eq!(run.status.code(), Some(2), "{}", stderr(&run));
    assert!(stderr(&run).contains("/nope"), "{}", stderr(&run));
}

#[test]
fn a_batch_mixing_one_and_two_lidar_logs_processes_both_with_each_sensors_trust() {
    let dir = scratch("multi-lidar-batch");
    let logs = dir.join("logs-in");
    std::fs::create_dir_all(&logs).unwrap();
    let two = cut_in_with_two_lidars(&dir);
    std::fs::rename(&two, logs.join("two-lidars.mcap")).unwrap();
    std::fs::copy(
        Path::new(env!("CARGO_MANIFEST_DIR")).join("sample_logs/cut-in.mcap"),
        logs.join("cut-in.mcap"),
    )
    .unwrap();
    let out = dir.join("fleet");
    let fleet = common::looming_batch(&logs, &out);
    let logs = fleet.as_array().expect("a list of logs");
    assert_eq!(logs.len(), 2);
    for log in logs {
        assert_eq!(log["status"], "processed", "{log}");
        assert_eq!(log["events"], 1, "{log}");
        let sensors = log["quality"]["sensors"].as_array();
        if log["input"].as_str().unwrap().ends_with("two-lidars.mcap") {
            let sensors = sensors.expect("each sensor's trust");
            assert_eq!(sensors.len(), 2, "{log}");
            for sensor in sensors {
                let trusted = sensor["trusted_fraction"].as_f64().unwrap();
                assert!(trusted > 0.5, "{sensor}");
            }
        } else {
            assert!(sensors.is_none(), "{log}");
        }
    }
    // The near misses name their sensors; the pictures were drawn.
    let lines = std::fs::read_to_string(out.join("near_misses.jsonl")).unwrap();
    let rows: Vec<serde_json::Value> = lines
        .lines()
        .map(|l| serde_json::from_str(l).unwrap())
        .collect();
    assert_eq!(rows.len(), 2);
    for row in &rows {
        assert!(row["range_picture"].is_string(), "{row}");
        if row["log"].as_str().unwrap().ends_with("two-lidars.mcap") {
            assert_eq!(row["sensors"].as_array().unwrap().len(), 2, "{row}");
        }
    }
    // The viewer layout of the two-LiDAR output shows both sensors.
    let annotated = out.join("logs/two-lidars.mcap");
    let layout = dir.join("layout.json");
    let run = common::looming(&[
        "layout",
        annotated.to_str().unwrap(),
        "-o",
        layout.to_str().unwrap(),
    ]);
    assert!(run.status.success(), "{}", stderr(&run));
    let layout: serde_json::Value =
        serde_json::from_slice(&std::fs::read(&layout).unwrap()).unwrap();
    let topics = &layout["configById"]["3D!looming"]["topics"];
    for sensor in ["lidar", "lidar_front"] {
        assert_eq!(topics[format!("/looming/{sensor}/points")]["visible"], true);
    }
    assert_eq!(topics["/lidar_front/points"]["visible"], false);
}

/// The bar on the synthetic vehicle with three LiDARs (roof 64
/// beams at 10 Hz, two side sensors of 32 beams at 20 Hz, phases 13 and 31
/// ms): every sensor annotated, the planted near miss found once and named
/// with the sensors that saw it, no false one, and each sensor's looming
/// within the single-sensor tables' targets against its own truth.
#[test]
fn three_lidars_find_the_cut_in_once_with_each_sensor_as_accurate_as_alone() {
    let dir = scratch("three-lidars");
    let input = common::cut_in_window(&dir, "three-lidars", &["--lidars", "3"]);
    let out = dir.join("out.mcap");
    let run = looming_process(&input, &out, &[]);
    assert!(run.status.success(), "{}", stderr(&run));
    let contents = read_all(&std::fs::read(&out).unwrap());
    for (sensor, pairs) in [("lidar_roof", 19), ("lidar_left", 39), ("lidar_right", 39)] {
        let points = contents
            .topic_messages(&format!("/looming/{sensor}/points"))
            .len();
        assert!(points.abs_diff(pairs) <= 1, "{sensor}: {points} pairs");
    }
    // The 20 Hz side sensors pair each scan with the one two periods
    // before (--min-baseline 0.09 s); the 10 Hz roof scan to scan.
    for sensor in ["lidar_roof", "lidar_left", "lidar_right"] {
        let pairs = contents.topic_messages(&format!("/looming/{sensor}/pairs"));
        for message in pairs.iter().skip(1) {
            let pair: serde_json::Value = serde_json::from_slice(&message.data).unwrap();
            let dt_s = pair["dt_s"].as_f64().unwrap();
            assert!((dt_s - 0.1).abs() < 0.002, "{sensor}: {pair}");
        }
    }
    let events = contents.topic_messages("/looming/events");
    assert_eq!(events.len(), 1, "the planted near miss, once");
    let event: serde_json::Value = serde_json::from_slice(&events[0].data).unwrap();
    assert_eq!(
        event["sensors"],
        serde_json::json!(["lidar_left", "lidar_right", "lidar_roof"])
    );
    let ttc = event["min_time_to_contact_s"].as_f64().unwrap();
    assert!((0.8..1.2).contains(&ttc), "{ttc}");
    // LiDAR only (no IMU, twist or odometry): the sensors are placed in the
    // roof's frame through /tf_static and the near miss is still one.
    let lidar_only = dir.join("lidar-only.mcap");
    let motion = ["/imu/data", "/vehicle/twist", "/odom"];
    common::rewrite_mcap(&input, &lidar_only, |m| {
        (!motion.contains(&m.channel.topic.as_str())).then_some(m)
    });
    let only_out = dir.join("lidar-only-out.mcap");
    let run = looming_process(&lidar_only, &only_out, &[]);
    assert!(run.status.success(), "{}", stderr(&run));
    let only = read_all(&std::fs::read(&only_out).unwrap());
    let events = only.topic_messages("/looming/events");
    assert_eq!(events.len(), 1, "one near miss without a motion source too");
    let event: serde_json::Value = serde_json::from_slice(&events[0].data).unwrap();
    assert_eq!(event["sensors"].as_array().unwrap().len(), 3, "{event}");
    for topic in [
        "/lidar_roof/points",
        "/lidar_left/points",
        "/lidar_right/points",
    ] {
        assert_as_accurate_as_alone(&dir, &input, topic);
    }
}

/// `topic`'s sensor against its own truth (`looming eval`): the
/// single-sensor targets.
fn assert_as_accurate_as_alone(dir: &Path, input: &Path, topic: &str) {
    let json = dir.join("eval.json");
    let run = common::looming(&[
        "eval",
        input.to_str().unwrap(),
        "--lidar-topic",
        topic,
        "--json",
        json.to_str().unwrap(),
    ]);
    assert!(run.status.success(), "{topic}: {}", stderr(&run));
    let report: serde_json::Value = serde_json::from_slice(&std::fs::read(&json).unwrap()).unwrap();
    let e = &report["errors"];
    let value = |q: &str, c: &str, k: &str| e[q][c][k].as_f64().unwrap();
    assert!(
        value("l_lidar", "all_unmasked", "median_abs") < 0.02,
        "{topic}"
    );
    assert!(
        value("l_lidar", "all_unmasked", "p90_abs") < 0.05,
        "{topic}"
    );
    let fused = value("fused", "all_unmasked", "rmse");
    assert!(fused < value("l_lidar", "all_unmasked", "rmse"), "{topic}");
    assert!(
        fused < value("l_ray_ego", "all_unmasked", "rmse"),
        "{topic}"
    );
    let f1 = report["moving_detection"]["f1"].as_f64().unwrap();
    assert!(f1 >= 0.95, "{topic}: moving F1 {f1}");
    // The single-sensor target on the road, the side sensors included
    // (0.040-0.050 1/s when they paired scan to scan).
    let road_d = value("disagreement", "static_road", "p90_abs");
    assert!(road_d < 0.05, "{topic}: road D p90 {road_d}");
}

/// A sensor that dies (its clouds stop after the third) does not stop the
/// others: both are annotated as far as their clouds go, the near miss is
/// found by the living one and named with it alone.
#[test]
fn a_dead_sensor_does_not_stop_the_others() {
    let dir = scratch("multi-lidar-dead");
    let two = cut_in_with_two_lidars(&dir);
    let input = dir.join("dead.mcap");
    let mut front_seen = 0;
    common::rewrite_mcap(&two, &input, |m| {
        if m.channel.topic == "/lidar_front/points" {
            front_seen += 1;
            if front_seen > 3 {
                return None;
            }
        }
        Some(m)
    });
    let out = dir.join("out.mcap");
    let run = looming_process(&input, &out, &[]);
    assert!(run.status.success(), "{}", stderr(&run));
    let contents = read_all(&std::fs::read(&out).unwrap());
    let alive = contents.topic_messages("/looming/lidar/points").len();
    let dead = contents.topic_messages("/looming/lidar_front/points").len();
    assert_eq!((alive, dead), (19, 2));
    let events = contents.topic_messages("/looming/events");
    assert_eq!(events.len(), 1);
    let event: serde_json::Value = serde_json::from_slice(&events[0].data).unwrap();
    assert_eq!(event["sensors"], serde_json::json!(["lidar"]));
}
