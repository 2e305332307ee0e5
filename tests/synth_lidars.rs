//! `looming synth --lidars N`: a vehicle with several LiDARs, each with its
//! own rolling sweep, rate, phase, mount, frame, topics and truth, run
//! through the real binary and read back with an independent MCAP reader.

mod common;

use std::collections::BTreeSet;

use common::*;
use looming::ros::msgs::{PointCloud2, TFMessage};

/// What one LiDAR of `--lidars 3` should be.
struct Expected {
    name: &'static str,
    beams: u16,
    period_ns: i64,
    /// First scan after the roof's first.
    phase_ns: i64,
    mount_xyz_m: [f64; 3],
    mount_yaw_deg: f64,
}

const RIG: [Expected; 3] = [
    Expected {
        name: "lidar_roof",
        beams: 64,
        period_ns: 100_000_000,
        phase_ns: 0,
        mount_xyz_m: [0.8, 0.1, 0.9],
        mount_yaw_deg: 4.0,
    },
    Expected {
        name: "lidar_left",
        beams: 32,
        period_ns: 50_000_000,
        phase_ns: 13_000_000,
        mount_xyz_m: [1.0, 0.85, 0.5],
        mount_yaw_deg: 90.0,
    },
    Expected {
        name: "lidar_right",
        beams: 32,
        period_ns: 50_000_000,
        phase_ns: 31_000_000,
        mount_xyz_m: [1.0, -0.85, 0.5],
        mount_yaw_deg: -90.0,
    },
];

/// Synthesize `cut-in` for 1 s with a lighter roof LiDAR and `extra` arguments.
fn cut_in(name: &str, extra: &[&str]) -> Vec<u8> {
    let dir = scratch(name);
    let mut args = vec!["--duration", "1.0", "--columns", "1024"];
    args.extend_from_slice(extra);
    let path = synth(&dir, "cut-in", &args);
    std::fs::read(path).unwrap()
}

fn clouds<'a>(file: &'a FileContents, topic: &str) -> Vec<PointCloud2<'a>> {
    file.topic_messages(topic)
        .iter()
        .map(|m| PointCloud2::decode_cdr(&m.data).unwrap())
        .collect()
}

/// The distinct `ring` values of a `ring-time` cloud.
fn rings(cloud: &PointCloud2, into: &mut BTreeSet<u16>) {
    let ring = cloud.fields.iter().find(|f| f.name == "ring").unwrap();
    let (offset, step) = (ring.offset as usize, cloud.point_step as usize);
    for point in cloud.data.chunks_exact(step) {
        into.insert(u16::from_le_bytes([point[offset], point[offset + 1]]));
    }
}

#[test]
fn three_lidars_each_with_its_rate_phase_rings_mount_and_truth() {
    let bytes = cut_in("lidars-3", &["--lidars", "3"]);
    let file = read_all(&bytes);
    let topics: BTreeSet<&str> = file.channels.values().map(|c| c.topic.as_str()).collect();
    for absent in ["/lidar/points", "/truth/points", "/truth/scan"] {
        assert!(!topics.contains(absent), "{absent} in {topics:?}");
    }
    assert!(topics.contains("/truth/events"), "{topics:?}");
    let roof_first_ns = clouds(&file, "/lidar_roof/points")[0].header.stamp.to_ns();
    for Expected {
        name,
        beams,
        period_ns,
        phase_ns,
        ..
    } in RIG
    {
        let topic = format!("/{name}/points");
        assert_eq!(looming::topics::sensor_name(&topic), name);
        let clouds = clouds(&file, &topic);
        // 1 s: 10 roof scans (every 100 ms), 19 side scans (every 50 ms from 13 or 31 ms).
        let expected = if period_ns == 100_000_000 { 10 } else { 19 };
        assert_eq!(clouds.len(), expected, "{topic}");
        let stamps: Vec<i64> = clouds.iter().map(|c| c.header.stamp.to_ns()).collect();
        assert_eq!(stamps[0] - roof_first_ns, phase_ns, "{topic}: phase");
        for pair in stamps.windows(2) {
            assert!(
                (pair[1] - pair[0] - period_ns).abs() <= 1,
                "{topic}: {pair:?}"
            );
        }
        let mut seen = BTreeSet::new();
        for cloud in &clouds {
            assert_eq!(cloud.header.frame_id, name);
            rings(cloud, &mut seen);
        }
        assert_eq!(seen.len(), usize::from(beams), "{topic}: rings");
        assert_eq!(seen.last(), Some(&(beams - 1)), "{topic}: rings");
        check_truth(&file, name, &stamps, &clouds);
    }
    check_tf_static(&file);
    check_log_time_order(&file);
}

/// One `/truth/<name>/points` cloud per LiDAR cloud (same stamps and sizes),
/// one `/truth/<name>/scan` record per cloud, in the LiDAR's frame.
fn check_truth(file: &FileContents, name: &str, stamps: &[i64], lidar: &[PointCloud2]) {
    let points_topic = looming::truth::points_topic(Some(name));
    assert_eq!(points_topic, format!("/truth/{name}/points"));
    let truth = clouds(file, &points_topic);
    assert_eq!(truth.len(), stamps.len(), "{points_topic}");
    for ((cloud, stamp), lidar) in truth.iter().zip(stamps).zip(lidar) {
        assert_eq!(cloud.header.stamp.to_ns(), *stamp, "{points_topic}");
        assert_eq!(cloud.header.frame_id, name);
        assert_eq!(cloud.width * cloud.height, lidar.width * lidar.height);
    }
    let scan_topic = looming::truth::scan_topic(Some(name));
    let scans = file.topic_messages(&scan_topic);
    assert_eq!(scans.len(), stamps.len(), "{scan_topic}");
    for (message, stamp) in scans.iter().zip(stamps) {
        let scan: serde_json::Value = serde_json::from_slice(&message.data).unwrap();
        assert_eq!(scan["stamp_ns"].as_i64(), Some(*stamp), "{scan_topic}");
        assert_eq!(scan["lidar_frame"], name, "{scan_topic}");
    }
}

/// One `/tf_static` message: `imu_link` to each LiDAR, at its mount.
fn check_tf_static(file: &FileContents) {
    let messages = file.topic_messages("/tf_static");
    assert_eq!(messages.len(), 1);
    let tf = TFMessage::decode_cdr(&messages[0].data).unwrap();
    assert_eq!(tf.transforms.len(), 3);
    for (transform, expected) in tf.transforms.iter().zip(RIG) {
        let (name, xyz, yaw_deg) = (expected.name, expected.mount_xyz_m, expected.mount_yaw_deg);
        assert_eq!(transform.header.frame_id, "imu_link");
        assert_eq!(transform.child_frame_id, name);
        let t = &transform.transform.translation;
        for (got, want) in [t.x, t.y, t.z].into_iter().zip(xyz) {
            assert!((got - want).abs() < 1e-9, "{name}: {t:?}");
        }
        // Sides are yawed only: a rotation about z by yaw_deg.
        let q = &transform.transform.rotation;
        if name != "lidar_roof" {
            let half = yaw_deg.to_radians() / 2.0;
            for (got, want) in [(q.x, 0.0), (q.y, 0.0), (q.z, half.sin()), (q.w, half.cos())] {
                assert!((got - want).abs() < 1e-9, "{name}: {q:?}");
            }
        }
    }
}

/// Every message but the planted near misses (written once the drive is
/// simulated, as with one LiDAR) is in log-time order across the LiDARs.
fn check_log_time_order(file: &FileContents) {
    let events: Vec<u16> = file
        .channels
        .iter()
        .filter(|(_, c)| c.topic == "/truth/events")
        .map(|(id, _)| *id)
        .collect();
    let times: Vec<u64> = file
        .messages
        .iter()
        .filter(|m| !events.contains(&m.channel_id))
        .map(|m| m.log_time)
        .collect();
    assert!(times.windows(2).all(|w| w[0] <= w[1]), "log times go back");
}

#[test]
fn one_lidar_keeps_the_old_topics_and_bytes() {
    let default = cut_in("lidars-default", &[]);
    let one = cut_in("lidars-1", &["--lidars", "1"]);
    assert!(default == one, "--lidars 1 changes the output");
    let file = read_all(&one);
    let topics: BTreeSet<&str> = file.channels.values().map(|c| c.topic.as_str()).collect();
    for topic in [
        "/lidar/points",
        "/truth/points",
        "/truth/scan",
        "/truth/events",
    ] {
        assert!(topics.contains(topic), "{topic} missing from {topics:?}");
    }
    assert!(!topics.iter().any(|t| t.contains("lidar_")), "{topics:?}");
    let lidar = clouds(&file, "/lidar/points");
    assert_eq!(lidar.len(), 10);
    assert!(lidar.iter().all(|c| c.header.frame_id == "lidar"));
    let tf = TFMessage::decode_cdr(&file.topic_messages("/tf_static")[0].data).unwrap();
    assert_eq!(tf.transforms.len(), 1);
    assert_eq!(tf.transforms[0].child_frame_id, "lidar");
}

#[test]
fn two_lidars_are_the_roof_and_the_left_one() {
    let file = read_all(&cut_in("lidars-2", &["--lidars", "2"]));
    let lidars: BTreeSet<&str> = file
        .channels
        .values()
        .map(|c| c.topic.as_str())
        .filter(|t| t.ends_with("/points") && !t.starts_with("/truth/"))
        .collect();
    assert_eq!(
        lidars,
        BTreeSet::from(["/lidar_left/points", "/lidar_roof/points"])
    );
    let out = scratch("lidars-4").join("x.mcap");
    let out = out.to_str().unwrap();
    let run = looming(&["synth", "--scenario", "cut-in", "--lidars", "4", "-o", out]);
    assert_eq!(run.status.code(), Some(2), "{}", stderr(&run));
}

#[test]
fn the_planted_near_misses_are_the_vehicles_as_with_one_lidar() {
    let events = |lidars: &str| {
        let dir = scratch(&format!("lidars-events-{lidars}"));
        let args = [
            "--duration",
            "3.5",
            "--beams",
            "32",
            "--columns",
            "512",
            "--lidars",
            lidars,
        ];
        let file = read_all(&std::fs::read(synth(&dir, "cut-in", &args)).unwrap());
        let events: Vec<Vec<u8>> = file
            .topic_messages("/truth/events")
            .iter()
            .map(|m| m.data.clone())
            .collect();
        events
    };
    let one = events("1");
    assert!(!one.is_empty(), "cut-in plants a near miss by 3.5 s");
    assert_eq!(events("3"), one);
}
