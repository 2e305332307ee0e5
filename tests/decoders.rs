//! Decoder tests: byte-exact fixtures written by hand from the wire specs,
//! round trips for every message in every encoding, point-cloud layouts and
//! conventions, and hostile input.

use std::borrow::Cow;

use looming::decode::{
    DecodeError, DecodeLimits, MessageKind, WireEncoding, decode, pointcloud2_from_points,
    scan_from_pointcloud2,
};
use looming::model::{Decoded, Scan, VelocitySourceKind};
use looming::ros::msgs::{
    Header, Imu, Odometry, PointCloud2, PointField, Pose, PoseWithCovariance, Quaternion,
    TFMessage, Time, Transform, TransformStamped, Twist, TwistStamped, TwistWithCovariance,
    Vector3, datatype,
};
use nalgebra::{UnitQuaternion, Vector3 as V3};

// ---------------------------------------------------------------------------
// Hand-written fixtures
// ---------------------------------------------------------------------------

/// The cloud of the byte fixtures: stamp 1 s + 2 ns, frame "ab", one point
/// (1, 2, 3) as FLOAT32 x/y/z at offsets 0/4/8, point_step 12.
fn small_cloud(seq: u32, big_endian_data: bool) -> PointCloud2<'static> {
    let data: Vec<u8> = if big_endian_data {
        vec![0x3f, 0x80, 0, 0, 0x40, 0, 0, 0, 0x40, 0x40, 0, 0]
    } else {
        vec![0, 0, 0x80, 0x3f, 0, 0, 0, 0x40, 0, 0, 0x40, 0x40]
    };
    PointCloud2 {
        header: Header {
            seq,
            stamp: Time { sec: 1, nanosec: 2 },
            frame_id: "ab".into(),
        },
        height: 1,
        width: 1,
        fields: vec![
            PointField::new("x", 0, datatype::FLOAT32),
            PointField::new("y", 4, datatype::FLOAT32),
            PointField::new("z", 8, datatype::FLOAT32),
        ],
        is_bigendian: big_endian_data,
        point_step: 12,
        row_step: 12,
        data: Cow::Owned(data),
        is_dense: true,
    }
}

#[rustfmt::skip]
const PC2_CDR_LE: &[u8] = &[
    0x00, 0x01, 0x00, 0x00,             // encapsulation: plain CDR, little-endian
    0x01, 0x00, 0x00, 0x00,             // rel 0: stamp.sec = 1
    0x02, 0x00, 0x00, 0x00,             // rel 4: stamp.nanosec = 2
    0x03, 0x00, 0x00, 0x00,             // rel 8: frame_id length 3 (incl. NUL)
    b'a', b'b', 0x00,                   // rel 12: "ab\0"
    0x00,                               // rel 15: pad to 4
    0x01, 0x00, 0x00, 0x00,             // rel 16: height = 1
    0x01, 0x00, 0x00, 0x00,             // rel 20: width = 1
    0x03, 0x00, 0x00, 0x00,             // rel 24: 3 fields
    0x02, 0x00, 0x00, 0x00, b'x', 0x00, // rel 28: name "x"
    0x00, 0x00,                         // pad
    0x00, 0x00, 0x00, 0x00,             // rel 36: offset 0
    0x07,                               // rel 40: FLOAT32
    0x00, 0x00, 0x00,                   // pad
    0x01, 0x00, 0x00, 0x00,             // rel 44: count 1
    0x02, 0x00, 0x00, 0x00, b'y', 0x00, // rel 48: name "y"
    0x00, 0x00,
    0x04, 0x00, 0x00, 0x00,             // offset 4
    0x07,
    0x00, 0x00, 0x00,
    0x01, 0x00, 0x00, 0x00,
    0x02, 0x00, 0x00, 0x00, b'z', 0x00, // rel 68: name "z"
    0x00, 0x00,
    0x08, 0x00, 0x00, 0x00,             // offset 8
    0x07,
    0x00, 0x00, 0x00,
    0x01, 0x00, 0x00, 0x00,
    0x00,                               // rel 88: is_bigendian = false
    0x00, 0x00, 0x00,                   // pad
    0x0c, 0x00, 0x00, 0x00,             // rel 92: point_step 12
    0x0c, 0x00, 0x00, 0x00,             // rel 96: row_step 12
    0x0c, 0x00, 0x00, 0x00,             // rel 100: data length 12
    0x00, 0x00, 0x80, 0x3f,             // x = 1.0f32 LE
    0x00, 0x00, 0x00, 0x40,             // y = 2.0
    0x00, 0x00, 0x40, 0x40,             // z = 3.0
    0x01,                               // rel 116: is_dense = true
];

#[rustfmt::skip]
const PC2_CDR_BE: &[u8] = &[
    0x00, 0x00, 0x00, 0x00,             // encapsulation: plain CDR, big-endian
    0x00, 0x00, 0x00, 0x01,             // stamp.sec = 1
    0x00, 0x00, 0x00, 0x02,             // stamp.nanosec = 2
    0x00, 0x00, 0x00, 0x03,             // frame_id length 3
    b'a', b'b', 0x00,
    0x00,                               // pad
    0x00, 0x00, 0x00, 0x01,             // height
    0x00, 0x00, 0x00, 0x01,             // width
    0x00, 0x00, 0x00, 0x03,             // 3 fields
    0x00, 0x00, 0x00, 0x02, b'x', 0x00, 0x00, 0x00,
    0x00, 0x00, 0x00, 0x00, 0x07, 0x00, 0x00, 0x00, 0x00, 0x00, 0x00, 0x01,
    0x00, 0x00, 0x00, 0x02, b'y', 0x00, 0x00, 0x00,
    0x00, 0x00, 0x00, 0x04, 0x07, 0x00, 0x00, 0x00, 0x00, 0x00, 0x00, 0x01,
    0x00, 0x00, 0x00, 0x02, b'z', 0x00, 0x00, 0x00,
    0x00, 0x00, 0x00, 0x08, 0x07, 0x00, 0x00, 0x00, 0x00, 0x00, 0x00, 0x01,
    0x01,                               // is_bigendian = true (point data BE too)
    0x00, 0x00, 0x00,
    0x00, 0x00, 0x00, 0x0c,             // point_step
    0x00, 0x00, 0x00, 0x0c,             // row_step
    0x00, 0x00, 0x00, 0x0c,             // data length
    0x3f, 0x80, 0x00, 0x00,             // x = 1.0f32 BE
    0x40, 0x00, 0x00, 0x00,             // y = 2.0
    0x40, 0x40, 0x00, 0x00,             // z = 3.0
    0x01,                               // is_dense
];

#[rustfmt::skip]
const PC2_ROS1: &[u8] = &[
    0x07, 0x00, 0x00, 0x00,             // header.seq = 7
    0x01, 0x00, 0x00, 0x00,             // stamp.secs = 1
    0x02, 0x00, 0x00, 0x00,             // stamp.nsecs = 2
    0x02, 0x00, 0x00, 0x00, b'a', b'b', // frame_id "ab" (no NUL)
    0x01, 0x00, 0x00, 0x00,             // height
    0x01, 0x00, 0x00, 0x00,             // width
    0x03, 0x00, 0x00, 0x00,             // 3 fields
    0x01, 0x00, 0x00, 0x00, b'x', 0x00, 0x00, 0x00, 0x00, 0x07, 0x01, 0x00, 0x00, 0x00,
    0x01, 0x00, 0x00, 0x00, b'y', 0x04, 0x00, 0x00, 0x00, 0x07, 0x01, 0x00, 0x00, 0x00,
    0x01, 0x00, 0x00, 0x00, b'z', 0x08, 0x00, 0x00, 0x00, 0x07, 0x01, 0x00, 0x00, 0x00,
    0x00,                               // is_bigendian
    0x0c, 0x00, 0x00, 0x00,             // point_step
    0x0c, 0x00, 0x00, 0x00,             // row_step
    0x0c, 0x00, 0x00, 0x00,             // data length
    0x00, 0x00, 0x80, 0x3f, 0x00, 0x00, 0x00, 0x40, 0x00, 0x00, 0x40, 0x40,
    0x01,                               // is_dense
];

/// float64 little-endian byte patterns used below.
const F64_0: [u8; 8] = [0; 8];
const F64_1: [u8; 8] = [0, 0, 0, 0, 0, 0, 0xf0, 0x3f];
const F64_HALF: [u8; 8] = [0, 0, 0, 0, 0, 0, 0xe0, 0x3f];
const F64_MINUS_2: [u8; 8] = [0, 0, 0, 0, 0, 0, 0x00, 0xc0];
const F64_4: [u8; 8] = [0, 0, 0, 0, 0, 0, 0x10, 0x40];

/// Imu, CDR LE: stamp 10 s + 500 ns, frame "imu0" (length 5, so 7 padding
/// bytes before the first float64 at rel 24), orientation identity,
/// angular velocity (1, 0, -2), linear acceleration (0, 0.5, 4), covariances 0.
fn imu_cdr_le_bytes() -> Vec<u8> {
    let mut b = vec![
        0x00, 0x01, 0x00, 0x00, // encapsulation
        0x0a, 0x00, 0x00, 0x00, // rel 0: sec 10
        0xf4, 0x01, 0x00, 0x00, // rel 4: nanosec 500
        0x05, 0x00, 0x00, 0x00, // rel 8: frame length 5
        b'i', b'm', b'u', b'0', 0x00, // rel 12..17
        0, 0, 0, 0, 0, 0, 0, // pad to rel 24
    ];
    for f in [F64_0, F64_0, F64_0, F64_1] {
        b.extend_from_slice(&f); // orientation x y z w
    }
    b.extend_from_slice(&[0; 72]); // orientation_covariance
    for f in [F64_1, F64_0, F64_MINUS_2] {
        b.extend_from_slice(&f); // angular_velocity
    }
    b.extend_from_slice(&[0; 72]);
    for f in [F64_0, F64_HALF, F64_4] {
        b.extend_from_slice(&f); // linear_acceleration
    }
    b.extend_from_slice(&[0; 72]);
    assert_eq!(b.len(), 4 + 24 + 37 * 8);
    b
}

fn imu_fixture() -> Imu {
    Imu {
        header: Header {
            seq: 0,
            stamp: Time {
                sec: 10,
                nanosec: 500,
            },
            frame_id: "imu0".into(),
        },
        orientation: Quaternion::IDENTITY,
        orientation_covariance: [0.0; 9],
        angular_velocity: Vector3::new(1.0, 0.0, -2.0),
        angular_velocity_covariance: [0.0; 9],
        linear_acceleration: Vector3::new(0.0, 0.5, 4.0),
        linear_acceleration_covariance: [0.0; 9],
    }
}

/// TwistStamped, CDR LE: stamp 3 s, frame "base", linear (1, 0.5, 0),
/// angular (0, 0, -2).
fn twist_cdr_le_bytes() -> Vec<u8> {
    let mut b = vec![
        0x00, 0x01, 0x00, 0x00, // encapsulation
        0x03, 0x00, 0x00, 0x00, // sec 3
        0x00, 0x00, 0x00, 0x00, // nanosec 0
        0x05, 0x00, 0x00, 0x00, // frame length 5
        b'b', b'a', b's', b'e', 0x00, // rel 12..17
        0, 0, 0, 0, 0, 0, 0, // pad to rel 24
    ];
    for f in [F64_1, F64_HALF, F64_0, F64_0, F64_0, F64_MINUS_2] {
        b.extend_from_slice(&f);
    }
    b
}

fn twist_fixture() -> TwistStamped {
    TwistStamped {
        header: Header {
            seq: 0,
            stamp: Time { sec: 3, nanosec: 0 },
            frame_id: "base".into(),
        },
        twist: Twist {
            linear: Vector3::new(1.0, 0.5, 0.0),
            angular: Vector3::new(0.0, 0.0, -2.0),
        },
    }
}

#[test]
fn pointcloud2_fixture_bytes_cdr_le() {
    let expected = small_cloud(0, false);
    assert_eq!(PC2_CDR_LE.len(), 121);
    assert_eq!(PointCloud2::decode_cdr(PC2_CDR_LE).unwrap(), expected);
    assert_eq!(expected.encode_cdr(false), PC2_CDR_LE);
}

#[test]
fn pointcloud2_fixture_bytes_cdr_be() {
    let expected = small_cloud(0, true);
    assert_eq!(PointCloud2::decode_cdr(PC2_CDR_BE).unwrap(), expected);
    assert_eq!(expected.encode_cdr(true), PC2_CDR_BE);
}

#[test]
fn pointcloud2_fixture_bytes_ros1() {
    let expected = small_cloud(7, false);
    assert_eq!(PointCloud2::decode_ros1(PC2_ROS1).unwrap(), expected);
    assert_eq!(expected.encode_ros1(), PC2_ROS1);
}

#[test]
fn pointcloud2_fixtures_decode_to_the_same_scan() {
    let limits = DecodeLimits::default();
    for (enc, bytes) in [
        (WireEncoding::Cdr, PC2_CDR_LE),
        (WireEncoding::Cdr, PC2_CDR_BE),
        (WireEncoding::Ros1, PC2_ROS1),
    ] {
        let Decoded::Scan(scan) = decode(MessageKind::PointCloud2, enc, false, bytes, &limits)
            .unwrap_or_else(|e| panic!("{enc:?}: {e}"))
        else {
            panic!("not a scan");
        };
        assert_eq!(scan.stamp_ns, 1_000_000_002);
        assert_eq!(scan.frame_id, "ab");
        assert_eq!(scan.points_m, vec![[1.0, 2.0, 3.0]]);
        assert_eq!(scan.source_index, vec![0]);
        assert_eq!(scan.input_point_count, 1);
        assert_eq!(scan.skipped_invalid_points, 0);
        assert_eq!(scan.intensity, None);
        assert_eq!(scan.ring, None);
        assert_eq!(scan.time_offset_s, None);
    }
}

#[test]
fn imu_fixture_bytes_cdr_le() {
    let bytes = imu_cdr_le_bytes();
    assert_eq!(Imu::decode_cdr(&bytes).unwrap(), imu_fixture());
    assert_eq!(imu_fixture().encode_cdr(false), bytes);

    let limits = DecodeLimits::default();
    let Decoded::Imu(s) =
        decode(MessageKind::Imu, WireEncoding::Cdr, false, &bytes, &limits).unwrap()
    else {
        panic!("not an imu sample");
    };
    assert_eq!(s.stamp_ns, 10_000_000_500);
    assert_eq!(s.frame_id, "imu0");
    assert_eq!(s.angular_velocity_radps, V3::new(1.0, 0.0, -2.0));
    assert_eq!(s.linear_acceleration_mps2, V3::new(0.0, 0.5, 4.0));
    assert_eq!(s.orientation, Some(UnitQuaternion::identity()));
}

#[test]
fn twist_fixture_bytes_cdr_le() {
    let bytes = twist_cdr_le_bytes();
    assert_eq!(TwistStamped::decode_cdr(&bytes).unwrap(), twist_fixture());
    assert_eq!(twist_fixture().encode_cdr(false), bytes);

    let limits = DecodeLimits::default();
    let Decoded::Velocity(v) = decode(
        MessageKind::TwistStamped,
        WireEncoding::Cdr,
        false,
        &bytes,
        &limits,
    )
    .unwrap() else {
        panic!("not a velocity");
    };
    assert_eq!(v.stamp_ns, 3_000_000_000);
    assert_eq!(v.frame_id, "base");
    assert_eq!(v.linear_mps, V3::new(1.0, 0.5, 0.0));
    assert_eq!(v.angular_radps, V3::new(0.0, 0.0, -2.0));
    assert_eq!(v.source, VelocitySourceKind::TwistStamped);
}

// ---------------------------------------------------------------------------
// Round trips
// ---------------------------------------------------------------------------

fn odometry_fixture() -> Odometry {
    let mut pose_cov = [0.0; 36];
    let mut twist_cov = [0.0; 36];
    for i in 0..36 {
        pose_cov[i] = i as f64 * 0.25;
        twist_cov[i] = -(i as f64);
    }
    Odometry {
        header: Header {
            seq: 42,
            stamp: Time {
                sec: 1_700_000_000,
                nanosec: 123_456_789,
            },
            frame_id: "/odom".into(),
        },
        child_frame_id: "/base_link".into(),
        pose: PoseWithCovariance {
            pose: Pose {
                position: Vector3::new(10.0, -5.0, 0.25),
                orientation: Quaternion {
                    x: 0.0,
                    y: 0.0,
                    z: 0.6,
                    w: 0.8,
                },
            },
            covariance: pose_cov,
        },
        twist: TwistWithCovariance {
            twist: Twist {
                linear: Vector3::new(3.5, 0.1, 0.0),
                angular: Vector3::new(0.0, 0.0, 0.3),
            },
            covariance: twist_cov,
        },
    }
}

fn tf_fixture() -> TFMessage {
    TFMessage {
        transforms: vec![
            TransformStamped {
                header: Header {
                    seq: 1,
                    stamp: Time { sec: 5, nanosec: 6 },
                    frame_id: "/base_link".into(),
                },
                child_frame_id: "lidar".into(),
                transform: Transform {
                    translation: Vector3::new(1.0, 0.0, 2.0),
                    rotation: Quaternion {
                        x: 0.0,
                        y: 0.0,
                        z: 1.0,
                        w: 0.0,
                    },
                },
            },
            TransformStamped {
                header: Header::new(7_000_000_008, "odom"),
                child_frame_id: "base_link".into(),
                transform: Transform::default(),
            },
        ],
    }
}

/// CDR has no `Header.seq`; clear it wherever a message carries one.
fn without_seq<T: Clone>(msg: &T, clear: impl Fn(&mut T)) -> T {
    let mut m = msg.clone();
    clear(&mut m);
    m
}

macro_rules! round_trip_all_encodings {
    ($msg:expr, $ty:ty, $clear:expr) => {{
        let msg = $msg;
        let cdr_expected = without_seq(&msg, $clear);
        for be in [false, true] {
            let bytes = msg.encode_cdr(be);
            assert_eq!(
                <$ty>::decode_cdr(&bytes).unwrap(),
                cdr_expected,
                "CDR be={be}"
            );
        }
        let bytes = msg.encode_ros1();
        assert_eq!(<$ty>::decode_ros1(&bytes).unwrap(), msg, "ROS1");
    }};
}

#[test]
fn round_trip_every_type_every_encoding() {
    round_trip_all_encodings!(
        {
            let mut c = pointcloud2_from_points(
                1_500_000_000_000_000_001,
                "velodyne",
                &[[1.0, 2.0, 3.0], [-4.0, 5.5, 0.0]],
                Some(&[10.0, 20.0]),
                Some(&[3, 15]),
                Some(&[-0.05, 0.0]),
            );
            c.header.seq = 9;
            c
        },
        PointCloud2,
        |m: &mut PointCloud2| m.header.seq = 0
    );
    round_trip_all_encodings!(
        {
            let mut m = imu_fixture();
            m.header.seq = 3;
            m.orientation_covariance[0] = -1.0;
            m
        },
        Imu,
        |m: &mut Imu| m.header.seq = 0
    );
    round_trip_all_encodings!(
        {
            let mut m = twist_fixture();
            m.header.seq = 4;
            m
        },
        TwistStamped,
        |m: &mut TwistStamped| m.header.seq = 0
    );
    round_trip_all_encodings!(odometry_fixture(), Odometry, |m: &mut Odometry| m
        .header
        .seq =
        0);
    round_trip_all_encodings!(tf_fixture(), TFMessage, |m: &mut TFMessage| {
        for t in &mut m.transforms {
            t.header.seq = 0;
        }
    });
    round_trip_all_encodings!(TFMessage::default(), TFMessage, |_: &mut TFMessage| {});
}

#[test]
fn ros2_negative_seconds_survive_cdr() {
    let h = Header {
        seq: 0,
        stamp: Time {
            sec: -3,
            nanosec: 5,
        },
        frame_id: String::new(),
    };
    assert_eq!(Header::decode_cdr(&h.encode_cdr(false)).unwrap(), h);
    assert_eq!(h.stamp.to_ns(), -2_999_999_995);
}

#[test]
fn odometry_and_tf_convert() {
    let limits = DecodeLimits::default();
    for enc in [WireEncoding::Cdr, WireEncoding::Ros1] {
        let odom = odometry_fixture();
        let bytes = match enc {
            WireEncoding::Cdr => odom.encode_cdr(false),
            _ => odom.encode_ros1(),
        };
        let Decoded::Velocity(v) =
            decode(MessageKind::Odometry, enc, false, &bytes, &limits).unwrap()
        else {
            panic!()
        };
        assert_eq!(v.frame_id, "base_link");
        assert_eq!(v.stamp_ns, 1_700_000_000_123_456_789);
        assert_eq!(v.linear_mps, V3::new(3.5, 0.1, 0.0));
        assert_eq!(v.angular_radps, V3::new(0.0, 0.0, 0.3));
        assert_eq!(v.source, VelocitySourceKind::Odometry);

        let tf = tf_fixture();
        let bytes = match enc {
            WireEncoding::Cdr => tf.encode_cdr(true),
            _ => tf.encode_ros1(),
        };
        let Decoded::Transforms {
            transforms,
            is_static,
        } = decode(MessageKind::TfMessage, enc, true, &bytes, &limits).unwrap()
        else {
            panic!()
        };
        assert!(is_static);
        assert_eq!(transforms.len(), 2);
        assert_eq!(transforms[0].parent_frame, "base_link");
        assert_eq!(transforms[0].child_frame, "lidar");
        assert_eq!(transforms[0].stamp_ns, 5_000_000_006);
        let p = transforms[0].parent_from_child * nalgebra::Point3::new(1.0, 0.0, 0.0);
        assert!((p.coords - V3::new(0.0, 0.0, 2.0)).norm() < 1e-12, "{p}");
        assert_eq!(transforms[1].parent_frame, "odom");
        assert_eq!(transforms[1].stamp_ns, 7_000_000_008);
    }
}

#[test]
fn odometry_without_child_frame_uses_header_frame() {
    let mut odom = odometry_fixture();
    odom.child_frame_id.clear();
    let v = looming::decode::velocity_from_odometry(&odom);
    assert_eq!(v.frame_id, "odom");
}

#[test]
fn imu_orientation_unknown_cases() {
    let mut m = imu_fixture();
    m.orientation_covariance[0] = -1.0;
    assert_eq!(looming::decode::imu_sample_from_imu(&m).orientation, None);
    let mut m = imu_fixture();
    m.orientation = Quaternion {
        x: 0.0,
        y: 0.0,
        z: 0.0,
        w: 0.0,
    };
    assert_eq!(looming::decode::imu_sample_from_imu(&m).orientation, None);
    let mut m = imu_fixture();
    m.orientation = Quaternion {
        x: 0.0,
        y: 0.0,
        z: 0.0,
        w: 2.0,
    };
    assert_eq!(
        looming::decode::imu_sample_from_imu(&m).orientation,
        Some(UnitQuaternion::identity())
    );
}

#[test]
fn tf_with_zero_quaternion_is_an_error() {
    let mut tf = tf_fixture();
    tf.transforms[0].transform.rotation = Quaternion {
        x: 0.0,
        y: 0.0,
        z: 0.0,
        w: 0.0,
    };
    let err = decode(
        MessageKind::TfMessage,
        WireEncoding::Ros1,
        false,
        &tf.encode_ros1(),
        &DecodeLimits::default(),
    )
    .unwrap_err();
    assert!(
        matches!(err, DecodeError::InvalidQuaternion { .. }),
        "{err}"
    );
}

// ---------------------------------------------------------------------------
// Point cloud layouts and conventions
// ---------------------------------------------------------------------------

const ALL_DATATYPES: [u8; 8] = [
    datatype::INT8,
    datatype::UINT8,
    datatype::INT16,
    datatype::UINT16,
    datatype::INT32,
    datatype::UINT32,
    datatype::FLOAT32,
    datatype::FLOAT64,
];

fn dt_size(dt: u8) -> u32 {
    match dt {
        datatype::INT8 | datatype::UINT8 => 1,
        datatype::INT16 | datatype::UINT16 => 2,
        datatype::INT32 | datatype::UINT32 | datatype::FLOAT32 => 4,
        datatype::FLOAT64 => 8,
        _ => panic!("bad datatype {dt}"),
    }
}

/// Writes `v` as datatype `dt` (test-side encoder, independent of the decoder).
fn put(buf: &mut [u8], dt: u8, v: f64, big_endian: bool) {
    macro_rules! w {
        ($t:ty) => {{
            let x = v as $t;
            let b = if big_endian {
                x.to_be_bytes()
            } else {
                x.to_le_bytes()
            };
            buf[..b.len()].copy_from_slice(&b);
        }};
    }
    match dt {
        datatype::INT8 => w!(i8),
        datatype::UINT8 => w!(u8),
        datatype::INT16 => w!(i16),
        datatype::UINT16 => w!(u16),
        datatype::INT32 => w!(i32),
        datatype::UINT32 => w!(u32),
        datatype::FLOAT32 => w!(f32),
        datatype::FLOAT64 => w!(f64),
        _ => panic!("bad datatype {dt}"),
    }
}

/// A cloud with the given fields packed back to back (plus 3 trailing bytes
/// per point so point_step exceeds the used size), `rows` rows of
/// `values.len() / rows` points, each row padded by `row_pad` bytes of 0xEE.
fn custom_cloud(
    stamp_ns: i64,
    fields: &[(&str, u8)],
    values: &[Vec<f64>],
    rows: u32,
    row_pad: u32,
    big_endian: bool,
) -> PointCloud2<'static> {
    let mut offset = 0;
    let mut pfs = Vec::new();
    for &(name, dt) in fields {
        pfs.push(PointField::new(name, offset, dt));
        offset += dt_size(dt);
    }
    let point_step = offset + 3;
    let width = values.len() as u32 / rows;
    let row_step = width * point_step + row_pad;
    let mut data = vec![0xEE; (row_step * rows) as usize];
    for (i, point) in values.iter().enumerate() {
        let (r, c) = (i as u32 / width, i as u32 % width);
        let base = (r * row_step + c * point_step) as usize;
        for (pf, &v) in pfs.iter().zip(point) {
            put(
                &mut data[base + pf.offset as usize..],
                pf.datatype,
                v,
                big_endian,
            );
        }
    }
    PointCloud2 {
        header: Header::new(stamp_ns, "/lidar"),
        height: rows,
        width,
        fields: pfs,
        is_bigendian: big_endian,
        point_step,
        row_step,
        data: Cow::Owned(data),
        is_dense: false,
    }
}

fn scan_of(cloud: &PointCloud2<'_>) -> Scan {
    scan_from_pointcloud2(cloud, &DecodeLimits::default()).unwrap()
}

#[test]
fn every_datatype_for_every_field_both_endiannesses() {
    for dt in ALL_DATATYPES {
        for big_endian in [false, true] {
            let fields = [
                ("x", dt),
                ("y", dt),
                ("z", dt),
                ("intensity", dt),
                ("ring", dt),
                ("time", dt),
            ];
            let values = vec![
                vec![1.0, 2.0, 3.0, 100.0, 7.0, 2.0],
                vec![4.0, 5.0, 6.0, 50.0, 31.0, 0.0],
            ];
            let cloud = custom_cloud(0, &fields, &values, 1, 0, big_endian);
            let ctx = format!("datatype {dt} big_endian {big_endian}");
            // Exercise the wire path too.
            let bytes = cloud.encode_cdr(big_endian);
            let Decoded::Scan(scan) = decode(
                MessageKind::PointCloud2,
                WireEncoding::Cdr,
                false,
                &bytes,
                &DecodeLimits::default(),
            )
            .expect(&ctx) else {
                panic!()
            };
            assert_eq!(scan.frame_id, "lidar", "{ctx}");
            assert_eq!(
                scan.points_m,
                vec![[1.0, 2.0, 3.0], [4.0, 5.0, 6.0]],
                "{ctx}"
            );
            assert_eq!(scan.intensity, Some(vec![100.0, 50.0]), "{ctx}");
            assert_eq!(scan.ring, Some(vec![7, 31]), "{ctx}");
            // Float time fields are seconds, integer ones nanoseconds.
            let t0 = if dt >= datatype::FLOAT32 { 2.0 } else { 2e-9 };
            assert_eq!(scan.time_offset_s, Some(vec![t0, 0.0]), "{ctx}");
        }
    }
}

#[test]
fn signed_and_negative_values() {
    let fields = [
        ("x", datatype::INT16),
        ("y", datatype::INT8),
        ("z", datatype::FLOAT64),
    ];
    let cloud = custom_cloud(0, &fields, &[vec![-300.0, -5.0, -0.5]], 1, 0, true);
    assert_eq!(scan_of(&cloud).points_m, vec![[-300.0, -5.0, -0.5]]);
}

#[test]
fn two_dimensional_cloud_without_z() {
    let fields = [("x", datatype::FLOAT32), ("y", datatype::FLOAT32)];
    let cloud = custom_cloud(0, &fields, &[vec![1.0, 2.0], vec![0.0, 0.0]], 1, 0, false);
    let scan = scan_of(&cloud);
    assert_eq!(scan.points_m, vec![[1.0, 2.0, 0.0]]);
    assert_eq!(scan.skipped_invalid_points, 1);
}

#[test]
fn padded_rows_and_source_index() {
    let fields = [
        ("x", datatype::FLOAT32),
        ("y", datatype::FLOAT32),
        ("z", datatype::FLOAT32),
        ("intensity", datatype::UINT8),
        ("ring", datatype::UINT16),
        ("time", datatype::FLOAT64),
    ];
    // Point 4 (second row) invalid: each field of the points after it read
    // from its own point's bytes, across the rows' padding.
    let values: Vec<Vec<f64>> = (0..6)
        .map(|i| {
            let x = if i == 4 { f64::NAN } else { i as f64 + 1.0 };
            vec![
                x,
                0.0,
                -(i as f64),
                10.0 * i as f64,
                i as f64,
                0.25 * i as f64,
            ]
        })
        .collect();
    let cloud = custom_cloud(0, &fields, &values, 2, 9, false);
    assert_eq!(cloud.width, 3);
    assert_eq!(cloud.row_step, 3 * cloud.point_step + 9);
    let scan = scan_of(&cloud);
    let kept = [0u32, 1, 2, 3, 5];
    let expected: Vec<[f32; 3]> = kept
        .iter()
        .map(|&i| [i as f32 + 1.0, 0.0, -(i as f32)])
        .collect();
    assert_eq!(scan.points_m, expected);
    assert_eq!(scan.source_index, kept.to_vec());
    assert_eq!(scan.input_point_count, 6);
    assert_eq!(scan.skipped_invalid_points, 1);
    let of_kept = |f: fn(u32) -> f32| kept.iter().map(|&i| f(i)).collect::<Vec<f32>>();
    assert_eq!(scan.intensity, Some(of_kept(|i| 10.0 * i as f32)));
    assert_eq!(
        scan.ring,
        Some(kept.iter().map(|&i| i as u16).collect::<Vec<_>>())
    );
    assert_eq!(scan.time_offset_s, Some(of_kept(|i| 0.25 * i as f32)));
}

#[test]
fn invalid_points_are_skipped_and_counted() {
    let fields = [
        ("x", datatype::FLOAT32),
        ("y", datatype::FLOAT32),
        ("z", datatype::FLOAT32),
        ("intensity", datatype::FLOAT32),
    ];
    let values = vec![
        vec![1.0, 0.0, 0.0, 1.0],
        vec![f64::NAN, 0.0, 0.0, 2.0],
        vec![0.0, 0.0, 0.0, 3.0],
        vec![f64::INFINITY, 1.0, 1.0, 4.0],
        vec![1.0, f64::NEG_INFINITY, 1.0, 5.0],
        vec![1.0, 1.0, 1e300, 6.0], // FLOAT64 overflow would be inf; here f32 inf
        vec![2.0, 2.0, 2.0, 7.0],
    ];
    let cloud = custom_cloud(0, &fields, &values, 1, 0, false);
    let scan = scan_of(&cloud);
    assert_eq!(scan.points_m, vec![[1.0, 0.0, 0.0], [2.0, 2.0, 2.0]]);
    assert_eq!(scan.source_index, vec![0, 6]);
    assert_eq!(scan.intensity, Some(vec![1.0, 7.0]));
    assert_eq!(scan.skipped_invalid_points, 5);
    assert_eq!(scan.input_point_count, 7);

    // A float64 coordinate too large for f32 is also invalid.
    let fields64 = [
        ("x", datatype::FLOAT64),
        ("y", datatype::FLOAT64),
        ("z", datatype::FLOAT64),
    ];
    let cloud = custom_cloud(0, &fields64, &[vec![1e300, 0.0, 0.0]], 1, 0, false);
    assert_eq!(scan_of(&cloud).skipped_invalid_points, 1);
}

fn xyz_plus(time: (&'static str, u8)) -> [(&'static str, u8); 4] {
    [
        ("x", datatype::FLOAT32),
        ("y", datatype::FLOAT32),
        ("z", datatype::FLOAT32),
        time,
    ]
}

fn close(a: &[f32], b: &[f32], tol: f32) -> bool {
    a.len() == b.len() && a.iter().zip(b).all(|(x, y)| (x - y).abs() <= tol)
}

#[test]
fn time_field_conventions() {
    let stamp_ns = 1_700_000_000_250_000_000; // 1.7e9 s + 0.25 s
    let run = |field: (&'static str, u8), raw: [f64; 2]| -> Vec<f32> {
        let values = vec![vec![1.0, 0.0, 0.0, raw[0]], vec![2.0, 0.0, 0.0, raw[1]]];
        let scan = scan_of(&custom_cloud(
            stamp_ns,
            &xyz_plus(field),
            &values,
            1,
            0,
            false,
        ));
        scan.time_offset_s.expect("time field")
    };
    // Ouster `t`: UINT32 ns since the scan start (= stamp).
    let t = run(("t", datatype::UINT32), [0.0, 50_000_000.0]);
    assert!(close(&t, &[0.0, 0.05], 1e-9), "{t:?}");
    // Velodyne `time`: FLOAT32 s relative to the stamp (negative when stamped at the end).
    let t = run(("time", datatype::FLOAT32), [-0.1, 0.0]);
    assert!(close(&t, &[-0.1, 0.0], 1e-9), "{t:?}");
    let t = run(("time", datatype::FLOAT64), [0.02, 0.03]);
    assert!(close(&t, &[0.02, 0.03], 1e-9), "{t:?}");
    // Hesai `timestamp`: FLOAT64 absolute s.
    let t = run(
        ("timestamp", datatype::FLOAT64),
        [1_700_000_000.25, 1_700_000_000.26],
    );
    assert!(close(&t, &[0.0, 0.01], 1e-6), "{t:?}");
    // Absolute nanoseconds as float64 (Livox driver 2).
    let t = run(
        ("timestamp", datatype::FLOAT64),
        [1_700_000_000_250_000_000.0, 1_700_000_000_260_000_000.0],
    );
    assert!(close(&t, &[0.0, 0.01], 1e-6), "{t:?}");
    let t = run(("time_stamp", datatype::FLOAT64), [1_700_000_000.2, 0.0]);
    assert!((t[0] + 0.05).abs() < 1e-6, "{t:?}");
    let t = run(("offset_time", datatype::UINT32), [1000.0, 2_000_000.0]);
    assert!(close(&t, &[1e-6, 2e-3], 1e-9), "{t:?}");
}

#[test]
fn reflectivity_is_used_when_there_is_no_intensity() {
    let fields = xyz_plus(("reflectivity", datatype::UINT16));
    let cloud = custom_cloud(0, &fields, &[vec![1.0, 1.0, 1.0, 42.0]], 1, 0, false);
    assert_eq!(scan_of(&cloud).intensity, Some(vec![42.0]));
}

#[test]
fn helper_cloud_decodes_back() {
    let points = [[1.0, 2.0, 3.0], [0.0, 0.0, 0.0], [4.0, 5.0, 6.0]];
    let cloud = pointcloud2_from_points(
        2_000_000_000,
        "velodyne",
        &points,
        Some(&[1.0, 2.0, 3.0]),
        Some(&[0, 1, 2]),
        Some(&[-0.1, -0.05, 0.0]),
    );
    assert_eq!(cloud.point_step, 24);
    let names: Vec<_> = cloud
        .fields
        .iter()
        .map(|f| (f.name.as_str(), f.offset))
        .collect();
    assert_eq!(
        names,
        [
            ("x", 0),
            ("y", 4),
            ("z", 8),
            ("intensity", 12),
            ("ring", 16),
            ("time", 20)
        ]
    );
    assert!(!cloud.is_dense);
    let scan = scan_of(&cloud);
    assert_eq!(scan.points_m, vec![[1.0, 2.0, 3.0], [4.0, 5.0, 6.0]]);
    assert_eq!(scan.intensity, Some(vec![1.0, 3.0]));
    assert_eq!(scan.ring, Some(vec![0, 2]));
    assert_eq!(scan.time_offset_s, Some(vec![-0.1, 0.0]));
    assert_eq!(scan.source_index, vec![0, 2]);
    assert_eq!(scan.skipped_invalid_points, 1);

    let plain = pointcloud2_from_points(0, "l", &points[..1], None, None, None);
    assert_eq!(plain.point_step, 12);
    assert!(plain.is_dense);
}

// ---------------------------------------------------------------------------
// foxglove.PointCloud
// ---------------------------------------------------------------------------

/// A foxglove.PointCloud of three points, the second with a NaN x, at stamp
/// 12 s + 34 ns, posed at (1, 2, 3) turned 90 deg about z.
fn foxglove_cloud_of_three_points_with_pose() -> foxglove::messages::PointCloud {
    use foxglove::messages::{
        PackedElementField, PointCloud, Pose as FgPose, Quaternion as FgQ, Timestamp,
        Vector3 as FgV,
    };

    // x y z FLOAT32, intensity UINT8 (foxglove code 1), ring UINT16 (code 3),
    // t UINT32 (code 5); stride 20 (1 byte of padding after the fields).
    let field = |name: &str, offset: u32, ty: i32| PackedElementField {
        name: name.into(),
        offset,
        r#type: ty,
    };
    let fields = vec![
        field("x", 0, 7),
        field("y", 4, 7),
        field("z", 8, 7),
        field("intensity", 12, 1),
        field("ring", 13, 3),
        field("t", 15, 5),
    ];
    let mut data = Vec::new();
    for (p, i, r, t) in [
        ([1.0f32, 2.0, 3.0], 200u8, 5u16, 1000u32),
        ([f32::NAN, 0.0, 0.0], 0, 0, 0),
        ([-1.0, 0.5, 0.0], 9, 63, 2000),
    ] {
        for c in p {
            data.extend_from_slice(&c.to_le_bytes());
        }
        data.push(i);
        data.extend_from_slice(&r.to_le_bytes());
        data.extend_from_slice(&t.to_le_bytes());
        data.push(0); // padding to the stride
    }
    PointCloud {
        timestamp: Some(Timestamp::new(12, 34)),
        frame_id: "/base_link".into(),
        pose: Some(FgPose {
            position: Some(FgV {
                x: 1.0,
                y: 2.0,
                z: 3.0,
            }),
            orientation: Some(FgQ {
                x: 0.0,
                y: 0.0,
                z: std::f64::consts::FRAC_1_SQRT_2,
                w: std::f64::consts::FRAC_1_SQRT_2,
            }),
        }),
        point_stride: 20,
        fields,
        data: data.into(),
    }
}

/// Without a pose the sensor pose is the identity.
fn assert_no_pose_gives_identity_sensor_pose(cloud: &foxglove::messages::PointCloud) {
    let mut no_pose = cloud.clone();
    no_pose.pose = None;
    let scan = looming::decode::scan_from_foxglove(&no_pose, &DecodeLimits::default()).unwrap();
    assert_eq!(scan.sensor_pose, nalgebra::Isometry3::identity());
}

/// A non-finite orientation is refused.
fn assert_non_finite_orientation_refused(cloud: &foxglove::messages::PointCloud) {
    let mut bad = cloud.clone();
    if let Some(pose) = bad.pose.as_mut() {
        pose.orientation = Some(foxglove::messages::Quaternion {
            x: f64::NAN,
            y: 0.0,
            z: 0.0,
            w: 1.0,
        });
    }
    let err = looming::decode::scan_from_foxglove(&bad, &DecodeLimits::default()).unwrap_err();
    assert!(
        matches!(err, DecodeError::InvalidQuaternion { .. }),
        "{err}"
    );
}

#[test]
fn foxglove_point_cloud_with_pose() {
    use prost::Message as _;

    let cloud = foxglove_cloud_of_three_points_with_pose();
    let bytes = cloud.encode_to_vec();
    let Decoded::Scan(scan) = decode(
        MessageKind::FoxglovePointCloud,
        WireEncoding::Protobuf,
        false,
        &bytes,
        &DecodeLimits::default(),
    )
    .unwrap() else {
        panic!()
    };
    assert_eq!(scan.stamp_ns, 12_000_000_034);
    assert_eq!(scan.frame_id, "base_link");
    assert_eq!(scan.points_m, vec![[1.0, 2.0, 3.0], [-1.0, 0.5, 0.0]]);
    assert_eq!(scan.intensity, Some(vec![200.0, 9.0]));
    assert_eq!(scan.ring, Some(vec![5, 63]));
    assert_eq!(scan.time_offset_s, Some(vec![1e-6, 2e-6]));
    assert_eq!(scan.source_index, vec![0, 2]);
    assert_eq!(scan.skipped_invalid_points, 1);
    assert_eq!(scan.input_point_count, 3);
    // Pose: rotate 90 deg about z, then translate.
    let p = scan.sensor_pose * nalgebra::Point3::new(1.0, 0.0, 0.0);
    assert!((p.coords - V3::new(1.0, 3.0, 3.0)).norm() < 1e-12, "{p}");

    assert_no_pose_gives_identity_sensor_pose(&cloud);
    assert_non_finite_orientation_refused(&cloud);
}

#[test]
fn foxglove_cloud_errors() {
    use foxglove::messages::{PackedElementField, PointCloud};
    let limits = DecodeLimits::default();
    let mut cloud = PointCloud {
        point_stride: 8,
        fields: vec![
            PackedElementField {
                name: "x".into(),
                offset: 0,
                r#type: 7,
            },
            PackedElementField {
                name: "y".into(),
                offset: 6,
                r#type: 7,
            },
        ],
        data: vec![0u8; 16].into(),
        ..Default::default()
    };
    let err = looming::decode::scan_from_foxglove(&cloud, &limits).unwrap_err();
    assert!(matches!(err, DecodeError::FieldOutOfBounds { .. }), "{err}");
    cloud.fields[1].offset = 4;
    cloud.fields[1].r#type = 0;
    let err = looming::decode::scan_from_foxglove(&cloud, &limits).unwrap_err();
    assert_eq!(
        err,
        DecodeError::UnsupportedFieldType {
            name: "y".into(),
            datatype: 0
        }
    );
    cloud.point_stride = 0;
    let err = looming::decode::scan_from_foxglove(&cloud, &limits).unwrap_err();
    assert!(matches!(err, DecodeError::InvalidPointLayout(_)), "{err}");
    let err = decode(
        MessageKind::FoxglovePointCloud,
        WireEncoding::Protobuf,
        false,
        &[0xff, 0xff, 0xff],
        &limits,
    )
    .unwrap_err();
    assert!(matches!(err, DecodeError::Protobuf(_)), "{err}");
}

// ---------------------------------------------------------------------------
// Errors and hostile input
// ---------------------------------------------------------------------------

#[test]
fn schema_and_encoding_names() {
    use MessageKind as K;
    for (name, kind) in [
        ("sensor_msgs/msg/PointCloud2", K::PointCloud2),
        ("sensor_msgs/PointCloud2", K::PointCloud2),
        ("foxglove.PointCloud", K::FoxglovePointCloud),
        ("sensor_msgs/msg/Imu", K::Imu),
        ("sensor_msgs/Imu", K::Imu),
        ("geometry_msgs/msg/TwistStamped", K::TwistStamped),
        ("geometry_msgs/TwistStamped", K::TwistStamped),
        ("nav_msgs/msg/Odometry", K::Odometry),
        ("nav_msgs/Odometry", K::Odometry),
        ("tf2_msgs/msg/TFMessage", K::TfMessage),
        ("tf2_msgs/TFMessage", K::TfMessage),
        ("tf/tfMessage", K::TfMessage),
    ] {
        assert_eq!(MessageKind::from_schema_name(name), Some(kind), "{name}");
    }
    for name in [
        "",
        "sensor_msgs/msg/Image",
        "PointCloud2",
        "foxglove.PointCloud2",
    ] {
        assert_eq!(MessageKind::from_schema_name(name), None, "{name}");
    }
    assert_eq!(
        WireEncoding::from_message_encoding("cdr"),
        Some(WireEncoding::Cdr)
    );
    assert_eq!(
        WireEncoding::from_message_encoding("ros1"),
        Some(WireEncoding::Ros1)
    );
    assert_eq!(
        WireEncoding::from_message_encoding("protobuf"),
        Some(WireEncoding::Protobuf)
    );
    assert_eq!(WireEncoding::from_message_encoding("json"), None);
}

#[test]
fn mismatched_kind_and_encoding() {
    let limits = DecodeLimits::default();
    let err = decode(
        MessageKind::Imu,
        WireEncoding::Protobuf,
        false,
        &[],
        &limits,
    )
    .unwrap_err();
    assert!(
        matches!(err, DecodeError::UnsupportedEncoding { .. }),
        "{err}"
    );
    let err = decode(
        MessageKind::FoxglovePointCloud,
        WireEncoding::Cdr,
        false,
        PC2_CDR_LE,
        &limits,
    )
    .unwrap_err();
    assert!(
        matches!(err, DecodeError::UnsupportedEncoding { .. }),
        "{err}"
    );
}

#[test]
fn xcdr2_and_pl_cdr_are_refused() {
    let mut bytes = PC2_CDR_LE.to_vec();
    bytes[1] = 0x07; // XCDR2 little-endian (DELIMITED_CDR2_LE... family)
    let err = PointCloud2::decode_cdr(&bytes).unwrap_err();
    assert_eq!(
        err.to_string().split(" (").next().unwrap(),
        "unsupported CDR encapsulation 0x0007"
    );
    bytes[1] = 0x03; // PL_CDR_LE
    assert_eq!(
        PointCloud2::decode_cdr(&bytes).unwrap_err(),
        DecodeError::UnsupportedEncapsulation(3)
    );
}

#[test]
fn short_point_data_is_refused() {
    // Claims 2x5 points of 16 bytes (160) but carries 100 bytes.
    let mut cloud =
        pointcloud2_from_points(0, "l", &[[1.0, 1.0, 1.0]; 25], Some(&[0.0; 25]), None, None);
    cloud.height = 2;
    cloud.width = 5;
    cloud.row_step = 80;
    cloud.data = Cow::Owned(cloud.data[..100].to_vec());
    let err = scan_from_pointcloud2(&cloud, &DecodeLimits::default()).unwrap_err();
    assert!(
        err.to_string()
            .starts_with("PointCloud2 data is 100 bytes but width*height*point_step needs 160"),
        "{err}"
    );
}

#[test]
fn huge_headers_never_allocate() {
    // width * height far beyond the data: refused by the limit first...
    let mut cloud = pointcloud2_from_points(0, "l", &[[1.0, 1.0, 1.0]], None, None, None);
    cloud.width = u32::MAX;
    cloud.height = u32::MAX;
    let err = scan_from_pointcloud2(&cloud, &DecodeLimits::default()).unwrap_err();
    assert!(matches!(err, DecodeError::TooManyPoints { .. }), "{err}");
    // ...and by the data length when the limit is lifted.
    let limits = DecodeLimits {
        max_points: usize::MAX,
        ..DecodeLimits::default()
    };
    cloud.height = 1;
    let err = scan_from_pointcloud2(&cloud, &limits).unwrap_err();
    assert!(
        matches!(err, DecodeError::PointCloudDataTooShort { .. }),
        "{err}"
    );
    cloud.width = 1 << 30;
    cloud.point_step = u32::MAX;
    let err = scan_from_pointcloud2(&cloud, &limits).unwrap_err();
    assert!(
        matches!(err, DecodeError::PointCloudDataTooShort { .. }),
        "{err}"
    );

    // A sequence count of 2^32-1 in the wire data.
    let mut bytes = PC2_ROS1.to_vec();
    bytes[26..30].copy_from_slice(&[0xff; 4]); // fields count
    let err = PointCloud2::decode_ros1(&bytes).unwrap_err();
    assert!(
        matches!(
            err,
            DecodeError::SequenceTooLong {
                count: u32::MAX,
                ..
            }
        ),
        "{err}"
    );
}

#[test]
fn layout_errors() {
    let limits = DecodeLimits::default();
    let base = pointcloud2_from_points(0, "l", &[[1.0, 1.0, 1.0]; 4], None, None, None);

    let mut c = base.clone();
    c.fields.retain(|f| f.name != "x");
    assert_eq!(
        scan_from_pointcloud2(&c, &limits).unwrap_err(),
        DecodeError::MissingField("x")
    );

    let mut c = base.clone();
    c.fields[2].offset = 10; // z would end at 14 > point_step 12
    let err = scan_from_pointcloud2(&c, &limits).unwrap_err();
    assert_eq!(
        err,
        DecodeError::FieldOutOfBounds {
            name: "z".into(),
            offset: 10,
            size: 4,
            point_step: 12
        }
    );

    let mut c = base.clone();
    c.fields[1].datatype = 9;
    assert_eq!(
        scan_from_pointcloud2(&c, &limits).unwrap_err(),
        DecodeError::UnsupportedFieldType {
            name: "y".into(),
            datatype: 9
        }
    );

    let mut c = base.clone();
    c.height = 2;
    c.width = 2;
    c.row_step = 12; // rows would overlap
    assert!(matches!(
        scan_from_pointcloud2(&c, &limits).unwrap_err(),
        DecodeError::InvalidPointLayout(_)
    ));

    let mut c = base.clone();
    c.point_step = 0;
    assert!(matches!(
        scan_from_pointcloud2(&c, &limits).unwrap_err(),
        DecodeError::InvalidPointLayout(_)
    ));

    // An empty cloud is fine, whatever its fields.
    let mut c = base.clone();
    c.width = 0;
    c.fields.clear();
    let scan = scan_from_pointcloud2(&c, &limits).unwrap();
    assert!(scan.is_empty());
    assert_eq!(scan.input_point_count, 0);

    // An unknown datatype on an unused field is ignored.
    let mut c = base;
    c.fields.push(PointField::new("rgb", 0, 42));
    assert_eq!(scan_from_pointcloud2(&c, &limits).unwrap().len(), 4);
}

#[test]
fn pointcloud2_truncation_error_is_precise() {
    // Cut inside the 12 data bytes (declared length 12 at byte 104).
    let err = PointCloud2::decode_cdr(&PC2_CDR_LE[..110]).unwrap_err();
    assert_eq!(
        err.to_string(),
        "sequence at byte 104 claims 12 elements of at least 1 bytes each, but only 2 bytes remain"
    );
    let err = Imu::decode_cdr(&imu_cdr_le_bytes()[..31]).unwrap_err();
    assert_eq!(
        err.to_string(),
        "payload truncated at byte 28 reading float64 (need 8, have 3)"
    );
}

/// Valid payloads of every kind in every encoding.
fn valid_payloads() -> Vec<(MessageKind, WireEncoding, Vec<u8>)> {
    use MessageKind as K;
    use WireEncoding as E;
    let cloud = pointcloud2_from_points(
        5,
        "v",
        &[[1.0, 2.0, 3.0], [4.0, 5.0, 6.0]],
        Some(&[1.0, 2.0]),
        Some(&[1, 2]),
        Some(&[0.0, 0.1]),
    );
    let mut out = Vec::new();
    for be in [false, true] {
        out.push((K::PointCloud2, E::Cdr, cloud.encode_cdr(be)));
        out.push((K::Imu, E::Cdr, imu_fixture().encode_cdr(be)));
        out.push((K::TwistStamped, E::Cdr, twist_fixture().encode_cdr(be)));
        out.push((K::Odometry, E::Cdr, odometry_fixture().encode_cdr(be)));
        out.push((K::TfMessage, E::Cdr, tf_fixture().encode_cdr(be)));
    }
    out.push((K::PointCloud2, E::Ros1, cloud.encode_ros1()));
    out.push((K::Imu, E::Ros1, imu_fixture().encode_ros1()));
    out.push((K::TwistStamped, E::Ros1, twist_fixture().encode_ros1()));
    out.push((K::Odometry, E::Ros1, odometry_fixture().encode_ros1()));
    out.push((K::TfMessage, E::Ros1, tf_fixture().encode_ros1()));
    out
}

#[test]
fn every_truncation_of_every_message_is_an_error() {
    let limits = DecodeLimits::default();
    for (kind, enc, bytes) in valid_payloads() {
        decode(kind, enc, false, &bytes, &limits).expect("valid payload decodes");
        for len in 0..bytes.len() {
            let err = decode(kind, enc, false, &bytes[..len], &limits)
                .expect_err(&format!("{kind:?} {enc:?} cut at {len} decoded"));
            assert!(
                matches!(
                    err,
                    DecodeError::Truncated { .. } | DecodeError::SequenceTooLong { .. }
                ),
                "{kind:?} {enc:?} cut at {len}: {err}"
            );
        }
    }
}

/// Small deterministic PRNG (xorshift64*), so failures are reproducible.
struct Rng(u64);

impl Rng {
    fn next(&mut self) -> u64 {
        self.0 ^= self.0 >> 12;
        self.0 ^= self.0 << 25;
        self.0 ^= self.0 >> 27;
        self.0.wrapping_mul(0x2545_f491_4f6c_dd1d)
    }
}

#[test]
fn garbage_and_mutated_input_never_panics() {
    use MessageKind as K;
    use WireEncoding as E;
    let limits = DecodeLimits {
        max_points: 10_000,
        ..DecodeLimits::default()
    };
    let mut rng = Rng(0x9e37_79b9_7f4a_7c15);
    let all = [
        (K::PointCloud2, E::Cdr),
        (K::PointCloud2, E::Ros1),
        (K::FoxglovePointCloud, E::Protobuf),
        (K::Imu, E::Cdr),
        (K::Imu, E::Ros1),
        (K::TwistStamped, E::Cdr),
        (K::TwistStamped, E::Ros1),
        (K::Odometry, E::Cdr),
        (K::Odometry, E::Ros1),
        (K::TfMessage, E::Cdr),
        (K::TfMessage, E::Ros1),
    ];
    // Pure garbage, with a valid CDR header half the time.
    for _ in 0..2000 {
        let len = (rng.next() % 300) as usize;
        let mut bytes: Vec<u8> = (0..len).map(|_| rng.next() as u8).collect();
        if len >= 4 && rng.next().is_multiple_of(2) {
            bytes[..4].copy_from_slice(&[0, 1, 0, 0]);
        }
        for &(kind, enc) in &all {
            let _ = decode(kind, enc, false, &bytes, &limits);
        }
    }
    // Valid messages with random bytes overwritten.
    let valid = valid_payloads();
    for _ in 0..300 {
        for (kind, enc, bytes) in &valid {
            let mut m = bytes.clone();
            for _ in 0..(1 + rng.next() % 4) {
                let i = (rng.next() as usize) % m.len();
                m[i] = rng.next() as u8;
            }
            let _ = decode(*kind, *enc, false, &m, &limits);
        }
    }
}

#[test]
fn ring_fields_under_their_common_names_and_integer_types() {
    use looming::model::RingSource;
    let integers = [
        datatype::INT8,
        datatype::UINT8,
        datatype::INT16,
        datatype::UINT16,
        datatype::INT32,
        datatype::UINT32,
    ];
    for name in ["ring", "channel", "laser_id", "line", "laser_number"] {
        for dt in integers {
            let fields = [
                ("x", datatype::FLOAT32),
                ("y", datatype::FLOAT32),
                ("z", datatype::FLOAT32),
                (name, dt),
            ];
            let values = vec![vec![1.0, 2.0, 3.0, 5.0], vec![4.0, 5.0, 6.0, 63.0]];
            let scan = scan_of(&custom_cloud(0, &fields, &values, 1, 0, false));
            let ctx = format!("{name} datatype {dt}");
            assert_eq!(scan.ring, Some(vec![5, 63]), "{ctx}");
            assert_eq!(
                scan.layout.rings,
                RingSource::Field { name: name.into() },
                "{ctx}"
            );
        }
    }
    // A float is a ring only as `ring` (as before); `line` as a float is not.
    let fields = [
        ("x", datatype::FLOAT32),
        ("y", datatype::FLOAT32),
        ("z", datatype::FLOAT32),
        ("line", datatype::FLOAT32),
    ];
    let scan = scan_of(&custom_cloud(
        0,
        &fields,
        &[vec![1.0, 2.0, 3.0, 2.5]],
        1,
        0,
        false,
    ));
    assert_eq!(scan.ring, None);
    // `ring` wins over the other names.
    let fields = [
        ("x", datatype::FLOAT32),
        ("y", datatype::FLOAT32),
        ("z", datatype::FLOAT32),
        ("channel", datatype::UINT16),
        ("ring", datatype::UINT8),
    ];
    let scan = scan_of(&custom_cloud(
        0,
        &fields,
        &[vec![1.0, 2.0, 3.0, 9.0, 4.0]],
        1,
        0,
        false,
    ));
    assert_eq!(scan.ring, Some(vec![4]));
}

#[test]
fn ring_values_that_are_not_rings_drop_the_field() {
    for (dt, bad) in [
        (datatype::INT16, -1.0),
        (datatype::UINT32, 1024.0),
        (datatype::UINT32, 4_000_000_000.0),
        (datatype::FLOAT32, 2.5),
    ] {
        let fields = [
            ("x", datatype::FLOAT32),
            ("y", datatype::FLOAT32),
            ("z", datatype::FLOAT32),
            ("ring", dt),
        ];
        let values = vec![vec![1.0, 2.0, 3.0, 1.0], vec![4.0, 5.0, 6.0, bad]];
        let scan = scan_of(&custom_cloud(0, &fields, &values, 1, 0, false));
        let ctx = format!("datatype {dt} value {bad}");
        assert_eq!(scan.ring, None, "{ctx}");
        let dropped = scan.layout.ring_field_dropped.expect(&ctx);
        assert_eq!(dropped.name, "ring", "{ctx}");
    }
    // 1023 is still a ring.
    let fields = [
        ("x", datatype::FLOAT32),
        ("y", datatype::FLOAT32),
        ("z", datatype::FLOAT32),
        ("ring", datatype::UINT16),
    ];
    let scan = scan_of(&custom_cloud(
        0,
        &fields,
        &[vec![1.0, 2.0, 3.0, 1023.0]],
        1,
        0,
        false,
    ));
    assert_eq!(scan.ring, Some(vec![1023]));
}

#[test]
fn organized_shape_is_kept() {
    let fields = [
        ("x", datatype::FLOAT32),
        ("y", datatype::FLOAT32),
        ("z", datatype::FLOAT32),
    ];
    // 2 rows of 3, the middle of row 0 without a return.
    let mut values: Vec<Vec<f64>> = (0..6).map(|i| vec![i as f64 + 1.0, 0.0, 1.0]).collect();
    values[1] = vec![f64::NAN, f64::NAN, f64::NAN];
    let scan = scan_of(&custom_cloud(0, &fields, &values, 2, 4, false));
    assert_eq!(scan.organized, Some((2, 3)));
    assert_eq!(scan.source_index, vec![0, 2, 3, 4, 5]);
    let mut completed = scan.clone();
    looming::engine::layout::complete(&mut completed, 0.1);
    assert_eq!(completed.ring, Some(vec![0, 0, 1, 1, 1]));
    // One row is not organized.
    let flat = scan_of(&custom_cloud(0, &fields, &values, 1, 0, false));
    assert_eq!(flat.organized, None);
}

/// A merged cloud's per-point sensor field: read under its usual names with
/// any integer type, or the one named; a float, negative or absent field,
/// or `--split-field none`, gives none.
#[test]
fn the_sensor_field_of_a_merged_cloud() {
    use looming::decode::SensorField;
    let ids = |name: &str, dt: u8, values: [f64; 2], choice: SensorField| {
        let fields = [
            ("x", datatype::FLOAT32),
            ("y", datatype::FLOAT32),
            ("z", datatype::FLOAT32),
            (name, dt),
        ];
        let rows = vec![
            vec![1.0, 2.0, 3.0, values[0]],
            vec![4.0, 5.0, 6.0, values[1]],
        ];
        let cloud = custom_cloud(0, &fields, &rows, 1, 0, false);
        let limits = DecodeLimits {
            sensor_field: choice,
            ..DecodeLimits::default()
        };
        scan_from_pointcloud2(&cloud, &limits)
            .unwrap()
            .sensor_ids
            .map(|s| (s.field, s.ids))
    };
    for dt in [
        datatype::UINT8,
        datatype::UINT16,
        datatype::INT32,
        datatype::UINT32,
    ] {
        let got = ids("sensor_id", dt, [2.0, 0.0], SensorField::Auto);
        assert_eq!(got, Some(("sensor_id".into(), vec![2, 0])), "datatype {dt}");
    }
    let got = ids("lidar_id", datatype::UINT8, [1.0, 3.0], SensorField::Auto);
    assert_eq!(got, Some(("lidar_id".into(), vec![1, 3])));
    // A laser's number is no sensor's.
    assert_eq!(
        ids("laser_id", datatype::UINT8, [1.0, 3.0], SensorField::Auto),
        None
    );
    assert_eq!(
        ids(
            "sensor_id",
            datatype::FLOAT32,
            [1.0, 3.0],
            SensorField::Auto
        ),
        None
    );
    assert_eq!(
        ids("sensor_id", datatype::INT16, [-1.0, 3.0], SensorField::Auto),
        None
    );
    assert_eq!(
        ids("sensor_id", datatype::UINT8, [1.0, 3.0], SensorField::Off),
        None
    );
    let named = SensorField::Named("source".into());
    let got = ids("source", datatype::UINT16, [7.0, 7.0], named.clone());
    assert_eq!(got, Some(("source".into(), vec![7, 7])));
    assert_eq!(ids("sensor_id", datatype::UINT8, [1.0, 3.0], named), None);
}
