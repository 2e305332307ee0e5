//! Writes the fuzz targets' seed corpora (`fuzz/corpus/<target>/`): small
//! MCAP logs and the messages of each kind in each encoding, from the
//! testkit's drive; KITTI lines; the built-in scenarios. The seeds are
//! committed; rerun this after a format change (`docs/fuzzing.md`).
//!
//! Usage: cargo run --release --example fuzz_seeds -- fuzz/corpus

use std::path::{Path, PathBuf};

use looming::testkit::{DriveSpec, Encoding, Layout, drive_log};

fn write(dir: &Path, target: &str, name: &str, bytes: &[u8]) {
    let folder = dir.join(target);
    std::fs::create_dir_all(&folder).expect("corpus folder");
    std::fs::write(folder.join(name), bytes).expect("seed written");
}

/// A drive small enough to be a seed: 3 scans of 4 x 16 points.
fn small_drive(encoding: Encoding, layout: Layout, odometry: bool) -> Vec<u8> {
    drive_log(&DriveSpec {
        encoding,
        layout,
        scans: 3,
        beams: 4,
        columns: 16,
        odometry,
        ..DriveSpec::default()
    })
}

/// The target fed with messages of a topic's kind.
fn target_of(topic: &str) -> Option<&'static str> {
    Some(match topic {
        "/sensing/lidar/points" => "pointcloud2",
        "/sensing/imu" => "imu",
        "/vehicle/twist" => "twist",
        "/odom" => "odometry",
        "/tf_static" => "tf",
        _ => return None,
    })
}

fn main() {
    let dir = PathBuf::from(
        std::env::args()
            .nth(1)
            .unwrap_or_else(|| "fuzz/corpus".into()),
    );
    let layouts = [
        ("indexed", Layout::indexed()),
        ("unchunked", Layout::unchunked()),
        ("no-summary", Layout::no_summary()),
    ];
    let encodings = [
        ("cdr", Encoding::Ros2 { big_endian: false }, 0u8),
        ("cdr-be", Encoding::Ros2 { big_endian: true }, 0u8),
        ("ros1", Encoding::Ros1, 1u8),
    ];
    for (layout_name, layout) in layouts {
        for (encoding_name, encoding, selector) in encodings {
            // The indexed drives also carry odometry, for its seeds.
            let spec_log = small_drive(encoding, layout, layout_name == "indexed");
            let name = format!("{layout_name}-{encoding_name}.mcap");
            write(&dir, "mcap_indexed", &name, &spec_log);
            write(&dir, "mcap_linear", &name, &spec_log);
            if layout_name != "indexed" {
                continue;
            }
            let stream = mcap::MessageStream::new(&spec_log).expect("a valid drive");
            for (i, message) in stream.enumerate() {
                let message = message.expect("a valid message");
                let Some(target) = target_of(&message.channel.topic) else {
                    continue;
                };
                if i % 7 != 0 && target != "pointcloud2" && target != "tf" {
                    continue;
                }
                // The selector byte: 0 CDR, 1 ROS 1; 2 also marks TF static.
                let mut seed = vec![selector | if target == "tf" { 2 } else { 0 }];
                seed.extend_from_slice(&message.data);
                write(&dir, target, &format!("{encoding_name}-{i}"), &seed);
            }
        }
    }
    foxglove_seeds(&dir);
    kitti_seeds(&dir);
    for (name, text) in looming::synth::scene::BUILT_IN {
        write(&dir, "scenario_json", name, text.as_bytes());
    }
}

fn foxglove_seeds(dir: &Path) {
    use foxglove::messages::{PackedElementField, PointCloud, packed_element_field::NumericType};
    use prost::Message;
    let field = |name: &str, offset: u32| PackedElementField {
        name: name.into(),
        offset,
        r#type: NumericType::Float32 as i32,
    };
    let data: Vec<u8> = (0..48u32)
        .flat_map(|i| (i as f32 * 0.5 + 1.0).to_le_bytes())
        .collect();
    let cloud = PointCloud {
        timestamp: None,
        frame_id: "lidar".into(),
        pose: None,
        point_stride: 12,
        fields: vec![field("x", 0), field("y", 4), field("z", 8)],
        data: data.into(),
    };
    let mut seed = vec![2u8];
    seed.extend(cloud.encode_to_vec());
    write(dir, "foxglove_pointcloud", "xyz-16", &seed);
}

fn kitti_seeds(dir: &Path) {
    let calib = "calib_time: 25-May-2012 12:00:00\nR: 9.999976e-01 7.553071e-04 -2.035826e-03 -7.854027e-04 9.998898e-01 -1.482298e-02 2.024406e-03 1.482454e-02 9.998881e-01\nT: -8.086759e-01 3.195559e-01 -7.997231e-01\n";
    let oxts = "49.015003823272 8.4342971002335 116.43032836914 0.035752 0.00903 -2.6087820941234 8.1548020670189 -0.23684056744028 -0.10249018234121 -0.19637040304342 -0.23777484583333 9.6941311646389 -0.041209 9.7126474227448 -0.038002 -0.02233 0.0045002 -0.039719 0.001256 -0.0186 0.010398 0.062 0.064 4 0.31 0.01 1.38 4";
    let stamp = "2011-09-26 13:02:25.964389445";
    let mut velodyne = vec![3u8];
    for i in 0..64u32 {
        for v in [i as f32, 1.0, -1.5, 0.3] {
            velodyne.extend_from_slice(&v.to_le_bytes());
        }
    }
    for (selector, name, text) in [
        (0u8, "calib", calib),
        (1, "oxts", oxts),
        (2, "timestamp", stamp),
    ] {
        let mut seed = vec![selector];
        seed.extend_from_slice(text.as_bytes());
        write(dir, "kitti", name, &seed);
    }
    write(dir, "kitti", "velodyne", &velodyne);
}
