//! `foxglove.PointCloud` (protobuf) LiDAR input, end to end: decoded with its
//! pose, paired with a ROS 2 twist, the lever arm of the pose in the velocity.

mod common;

use common::*;
use foxglove::Encode;
use foxglove::messages::{PackedElementField, PointCloud, Pose, Quaternion, Timestamp, Vector3};
use looming::annotate::pairs::PairRecord;
use looming::ros::msgs::{Header, Twist, TwistStamped};

fn cloud(stamp_ns: u64) -> PointCloud {
    let points: Vec<[f32; 3]> = (0..200)
        .map(|i| [20.0 - i as f32 * 0.01, i as f32 * 0.1 - 10.0, -1.0])
        .collect();
    let mut data = Vec::new();
    for p in &points {
        for c in p {
            data.extend_from_slice(&c.to_le_bytes());
        }
    }
    let field = |name: &str, offset: u32| PackedElementField {
        name: name.into(),
        offset,
        r#type: 7, // FLOAT32
    };
    PointCloud {
        timestamp: Some(Timestamp::new(
            (stamp_ns / 1_000_000_000) as u32,
            (stamp_ns % 1_000_000_000) as u32,
        )),
        frame_id: "base_link".into(),
        // The sensor sits 1 m ahead and 2 m left of base_link.
        pose: Some(Pose {
            position: Some(Vector3 {
                x: 1.0,
                y: 2.0,
                z: 0.0,
            }),
            orientation: Some(Quaternion {
                x: 0.0,
                y: 0.0,
                z: 0.0,
                w: 1.0,
            }),
        }),
        point_stride: 12,
        fields: vec![field("x", 0), field("y", 4), field("z", 8)],
        data: data.into(),
    }
}

#[test]
fn foxglove_point_clouds_are_paired_with_their_pose_as_lever_arm() {
    let dir = scratch("foxglove");
    let mut log = looming::testkit::LogBuilder::new(Layout::indexed(), "");
    let schema = PointCloud::get_schema().unwrap();
    log.schema(1, &schema.name, &schema.encoding, &schema.data);
    log.channel(1, 1, "/lidar", "protobuf");
    let twist_schema =
        looming::ros::schemas::twist_stamped(looming::ros::schemas::RosDialect::Ros2);
    log.schema(
        2,
        "geometry_msgs/msg/TwistStamped",
        "ros2msg",
        twist_schema.as_bytes(),
    );
    log.channel(2, 2, "/twist", "cdr");
    let start = 1_700_000_000_000_000_000u64;
    for i in 0..30u64 {
        let stamp = start + i * 20_000_000;
        let twist = TwistStamped {
            header: Header::new(stamp as i64, "base_link"),
            twist: Twist {
                linear: looming::ros::msgs::Vector3::new(10.0, 0.0, 0.0),
                angular: looming::ros::msgs::Vector3::new(0.0, 0.0, 1.0),
            },
        };
        log.message(2, i as u32, stamp, stamp, &twist.encode_cdr(false));
        if i % 5 == 0 {
            let mut bytes = Vec::new();
            cloud(stamp).encode(&mut bytes).unwrap();
            log.message(1, i as u32, stamp + 1, stamp + 1, &bytes);
        }
    }
    let input = log.finish();
    let in_path = dir.join("in.mcap");
    let out_path = dir.join("out.mcap");
    write(&in_path, &input);
    let run = looming_process(&in_path, &out_path, &["-q"]);
    assert!(run.status.success(), "{}", stderr(&run));
    let output = read_all(&std::fs::read(&out_path).unwrap());
    assert_all_input_messages_copied(&read_all(&input), &output);
    let pairs: Vec<PairRecord> = output
        .topic_messages("/looming/pairs")
        .iter()
        .map(|m| serde_json::from_slice(&m.data).unwrap())
        .collect();
    assert_eq!(pairs.len(), 5);
    for pair in &pairs {
        assert_eq!(pair.current.points, 200);
        // v_L = v + w x l = (10, 0, 0) + (0, 0, 1) x (1, 2, 0) = (8, 1, 0).
        let v = pair.velocity_lidar_mps.unwrap();
        assert!(
            (v[0] - 8.0).abs() < 1e-9 && (v[1] - 1.0).abs() < 1e-9 && v[2].abs() < 1e-9,
            "{v:?}"
        );
        let w = pair.angular_velocity_lidar_radps.unwrap();
        assert!((w[2] - 1.0).abs() < 1e-12);
        assert!(pair.unavailable.contains(&"imu".to_string()));
        assert_eq!(pair.extrinsic.velocity.as_deref(), Some("same_frame"));
    }
}
