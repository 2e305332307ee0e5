//! KITTI raw import, end to end through the CLI. KITTI data cannot be
//! committed (non-commercial licence), so the tests write a KITTI-format drive
//! folder from a synthetic scenario, the way KITTI stores it (Velodyne `.bin`
//! files laser by laser, sweep start / end / forward timestamps in KITTI's
//! text format, one OXTS line of 30 values per packet at 100 Hz, the
//! IMU-to-Velodyne calibration in the date folder), import it, process it,
//! evaluate it against the scenario's truth and render it, and compare the
//! looming with the same scenario processed directly.

mod common;

use std::collections::BTreeMap;
use std::fmt::Write as _;
use std::path::{Path, PathBuf};

use common::{looming, scratch, stderr};
use looming::decode::{self, DecodeLimits, MessageKind, WireEncoding};
use looming::engine::{EngineCache, EngineConfig, PairLooming, compute_with_cache};
use looming::model::{Decoded, ImuSample, Scan, VelocitySample};
use nalgebra::{Isometry3, UnitQuaternion};

const PERIOD_NS: i64 = 100_000_000;

/// Everything of a synthetic drive a KITTI folder holds.
struct Drive {
    scans: Vec<Scan>,
    imu: Vec<ImuSample>,
    twist: Vec<VelocitySample>,
    /// Pose of the LiDAR in the IMU frame.
    imu_from_lidar: Isometry3<f64>,
}

fn read_drive(path: &Path) -> Drive {
    let contents = common::read_all(&std::fs::read(path).unwrap());
    let mut drive = Drive {
        scans: Vec::new(),
        imu: Vec::new(),
        twist: Vec::new(),
        imu_from_lidar: Isometry3::identity(),
    };
    let limits = DecodeLimits::default();
    for message in &contents.messages {
        let channel = &contents.channels[&message.channel_id];
        let kind = match channel.topic.as_str() {
            "/lidar/points" => MessageKind::PointCloud2,
            "/imu/data" => MessageKind::Imu,
            "/vehicle/twist" => MessageKind::TwistStamped,
            "/tf_static" => MessageKind::TfMessage,
            _ => continue,
        };
        let decoded =
            decode::decode(kind, WireEncoding::Cdr, true, &message.data, &limits).unwrap();
        match decoded {
            Decoded::Scan(scan) => drive.scans.push(scan),
            Decoded::Imu(imu) => drive.imu.push(imu),
            Decoded::Velocity(v) => drive.twist.push(v),
            Decoded::Transforms { transforms, .. } => {
                drive.imu_from_lidar = transforms[0].parent_from_child;
            }
        }
    }
    drive.scans.sort_by_key(|s| s.stamp_ns);
    drive.imu.sort_by_key(|s| s.stamp_ns);
    drive.twist.sort_by_key(|s| s.stamp_ns);
    drive
}

/// KITTI's timestamp format, `2011-09-26 13:02:25.964389445` (UTC).
fn kitti_time(stamp_ns: i64) -> String {
    let (secs, nanos) = (
        stamp_ns.div_euclid(1_000_000_000),
        stamp_ns.rem_euclid(1_000_000_000),
    );
    let (days, day_s) = (secs.div_euclid(86_400), secs.rem_euclid(86_400));
    // Civil from days (H. Hinnant).
    let z = days + 719_468;
    let era = z.div_euclid(146_097);
    let doe = z - era * 146_097;
    let yoe = (doe - doe / 1460 + doe / 36_524 - doe / 146_096) / 365;
    let doy = doe - (365 * yoe + yoe / 4 - yoe / 100);
    let mp = (5 * doy + 2) / 153;
    let day = doy - (153 * mp + 2) / 5 + 1;
    let month = if mp < 10 { mp + 3 } else { mp - 9 };
    let year = yoe + era * 400 + i64::from(month <= 2);
    format!(
        "{year:04}-{month:02}-{day:02} {:02}:{:02}:{:02}.{nanos:09}",
        day_s / 3600,
        day_s / 60 % 60,
        day_s % 60
    )
}

fn write_lines(path: &Path, lines: &[String]) {
    std::fs::create_dir_all(path.parent().unwrap()).unwrap();
    std::fs::write(path, lines.join("\n") + "\n").unwrap();
}

/// The twist at `stamp_ns`, interpolated linearly like the pairing stage does.
fn twist_at(twist: &[VelocitySample], stamp_ns: i64) -> ([f64; 3], [f64; 3]) {
    let after = twist.partition_point(|s| s.stamp_ns < stamp_ns);
    let (a, b) = match (after.checked_sub(1), twist.get(after)) {
        (Some(i), Some(b)) => (&twist[i], b),
        (None, Some(b)) => (b, b),
        (Some(i), None) => (&twist[i], &twist[i]),
        (None, None) => panic!("no twist"),
    };
    let span = (b.stamp_ns - a.stamp_ns) as f64;
    let w = if span > 0.0 {
        (stamp_ns - a.stamp_ns) as f64 / span
    } else {
        0.0
    };
    let v = a.linear_mps * (1.0 - w) + b.linear_mps * w;
    let omega = a.angular_radps * (1.0 - w) + b.angular_radps * w;
    ([v.x, v.y, v.z], [omega.x, omega.y, omega.z])
}

/// Write `drive` as `<root>/2011_09_26/2011_09_26_drive_0001_sync`; returns
/// the drive folder.
fn write_kitti(drive: &Drive, root: &Path) -> PathBuf {
    let date_dir = root.join("2011_09_26");
    let drive_dir = date_dir.join("2011_09_26_drive_0001_sync");
    let velodyne = drive_dir.join("velodyne_points");
    std::fs::create_dir_all(velodyne.join("data")).unwrap();
    let (mut start, mut end, mut mid) = (Vec::new(), Vec::new(), Vec::new());
    for (index, scan) in drive.scans.iter().enumerate() {
        // KITTI lists the points laser by laser, each from straight ahead
        // round counter-clockwise (seen from above) to straight ahead again.
        let rings = scan.ring.as_ref().expect("synthetic scans have rings");
        let around = |i: usize| {
            let p = scan.points_m[i];
            f64::from(p[1])
                .atan2(f64::from(p[0]))
                .rem_euclid(std::f64::consts::TAU)
        };
        let mut order: Vec<usize> = (0..scan.points_m.len()).collect();
        order.sort_by(|&a, &b| {
            rings[a]
                .cmp(&rings[b])
                .then(around(a).total_cmp(&around(b)))
        });
        let intensity = scan.intensity.as_ref();
        let mut bytes = Vec::with_capacity(order.len() * 16);
        for i in order {
            let p = scan.points_m[i];
            let reflectance = intensity.map_or(0.0, |v| v[i] / 255.0);
            for value in [p[0], p[1], p[2], reflectance] {
                bytes.extend_from_slice(&value.to_le_bytes());
            }
        }
        std::fs::write(
            velodyne.join("data").join(format!("{index:010}.bin")),
            bytes,
        )
        .unwrap();
        start.push(kitti_time(scan.stamp_ns));
        end.push(kitti_time(scan.stamp_ns + PERIOD_NS));
        mid.push(kitti_time(scan.stamp_ns + PERIOD_NS / 2));
    }
    write_lines(&velodyne.join("timestamps_start.txt"), &start);
    write_lines(&velodyne.join("timestamps_end.txt"), &end);
    write_lines(&velodyne.join("timestamps.txt"), &mid);
    // OXTS at the IMU's 100 Hz: gyro and accelerations from the IMU, the
    // velocity from the twist at the same instant.
    let oxts = drive_dir.join("oxts");
    let mut stamps = Vec::new();
    for (index, imu) in drive.imu.iter().enumerate() {
        let (v, _) = twist_at(&drive.twist, imu.stamp_ns);
        let (roll, pitch, yaw) = imu
            .orientation
            .unwrap_or_else(UnitQuaternion::identity)
            .euler_angles();
        let w = imu.angular_velocity_radps;
        let a = imu.linear_acceleration_mps2;
        let mut line = format!("49.0 8.4 116.0 {roll:e} {pitch:e} {yaw:e} 0 0");
        for value in [
            v[0], v[1], v[2], 0.0, 0.0, 0.0, a.x, a.y, a.z, 0.0, 0.0, 0.0, w.x, w.y, w.z,
        ] {
            write!(line, " {value:e}").unwrap();
        }
        line.push_str(" 0.5 0.05 4 10 4 4 0");
        write_lines(&oxts.join("data").join(format!("{index:010}.txt")), &[line]);
        stamps.push(kitti_time(imu.stamp_ns));
    }
    write_lines(&oxts.join("timestamps.txt"), &stamps);
    // p_velo = R p_imu + T.
    let velo_from_imu = drive.imu_from_lidar.inverse();
    let r = velo_from_imu.rotation.to_rotation_matrix();
    let t = velo_from_imu.translation.vector;
    let mut calib = String::from("calib_time: 25-May-2012 14:44:40\nR:");
    for row in 0..3 {
        for col in 0..3 {
            write!(calib, " {:.17e}", r[(row, col)]).unwrap();
        }
    }
    writeln!(calib, "\nT: {:.17e} {:.17e} {:.17e}", t.x, t.y, t.z).unwrap();
    std::fs::write(date_dir.join("calib_imu_to_velo.txt"), calib).unwrap();
    drive_dir
}

/// A built-in scenario with the twist at the IMU's 100 Hz, as a file: KITTI's
/// OXTS packets carry velocity and rates together at one rate, so the same
/// motion samples reach the engine whether the drive is read directly or
/// through a KITTI folder.
fn hundred_hertz_scenario(dir: &Path, name: &str) -> PathBuf {
    let probe = dir.join("probe.mcap");
    run(&[
        "synth",
        "--scenario",
        name,
        "--duration",
        "0.2",
        "--beams",
        "4",
        "--columns",
        "16",
        "-o",
        probe.to_str().unwrap(),
        "--force",
        "-q",
    ]);
    let contents = common::read_all(&std::fs::read(&probe).unwrap());
    let record = contents
        .metadata
        .iter()
        .find(|m| m.name == "looming.synth")
        .expect("synth records its scenario");
    let mut scenario: serde_json::Value =
        serde_json::from_str(&record.metadata["scenario"]).unwrap();
    scenario["velocity_rate_hz"] = serde_json::json!(100.0);
    let path = dir.join(format!("{name}-100hz.json"));
    std::fs::write(&path, scenario.to_string()).unwrap();
    path
}

fn run(args: &[&str]) -> String {
    let out = looming(args);
    assert!(out.status.success(), "{args:?}: {}", stderr(&out));
    stderr(&out)
}

/// Per pair (by stamp of the current scan): the engine's result.
fn engine_results(path: &Path) -> BTreeMap<i64, (Scan, PairLooming)> {
    let mut cache = EngineCache::default();
    let mut results = BTreeMap::new();
    looming::pipeline::replay(
        path,
        &looming::pipeline::ScanOptions::default(),
        &mut |_| {},
        &mut |pair| {
            if let Some(result) = compute_with_cache(&pair, &EngineConfig::default(), &mut cache) {
                results.insert(pair.current.stamp_ns, ((*pair.current).clone(), result));
            }
        },
    )
    .unwrap();
    results
}

/// A 32 x 512 cut-in drive with 100 Hz motion, 2.5 s in for 4 s, at
/// `dir/synth.mcap`.
fn synthesize_cut_in_at_100_hz(dir: &Path) -> PathBuf {
    let synth = dir.join("synth.mcap");
    let scenario = hundred_hertz_scenario(dir, "cut-in");
    run(&[
        "synth",
        "--scenario",
        scenario.to_str().unwrap(),
        "--start",
        "2.5",
        "--duration",
        "4.0",
        "--beams",
        "32",
        "--columns",
        "512",
        "-o",
        synth.to_str().unwrap(),
        "--force",
        "-q",
    ]);
    synth
}

/// The imported log carries what `process` needs, found automatically.
fn assert_inspect_finds_kitti_topics(imported: &Path) {
    let inspect = looming(&["inspect", imported.to_str().unwrap(), "--json"]);
    let report: serde_json::Value = serde_json::from_slice(&inspect.stdout).unwrap();
    let detected = report.to_string();
    for topic in ["/velodyne_points", "/oxts/imu", "/oxts/twist", "/tf_static"] {
        assert!(detected.contains(topic), "{topic} in {detected}");
    }
}

/// How far the engine's results via KITTI are from the direct run's.
#[derive(Default)]
struct RoundTripGaps {
    /// Cells with a finite fused looming in the direct run.
    compared: usize,
    differing_mask: usize,
    worst_fused_per_s: f32,
    worst_lidar_per_s: f32,
}

/// NaN on both sides matches; NaN on one side is an infinite difference.
fn looming_gap_per_s(x: f32, y: f32) -> f32 {
    match (x.is_finite(), y.is_finite()) {
        (true, true) => (x - y).abs(),
        (false, false) => 0.0,
        _ => f32::INFINITY,
    }
}

/// Compares the two runs pair by pair (same points, rings and image size
/// asserted per pair) and cell by cell.
fn round_trip_gaps(
    direct: &BTreeMap<i64, (Scan, PairLooming)>,
    via_kitti: &BTreeMap<i64, (Scan, PairLooming)>,
) -> RoundTripGaps {
    let mut gaps = RoundTripGaps::default();
    for (stamp, (scan, a)) in direct {
        let (kitti_scan, b) = &via_kitti[stamp];
        assert_eq!(kitti_scan.points_m.len(), scan.points_m.len());
        assert_eq!(
            kitti_scan.ring.as_ref().map(Vec::len),
            Some(scan.points_m.len())
        );
        assert_eq!(
            (a.geometry.rows, a.geometry.cols),
            (b.geometry.rows, b.geometry.cols)
        );
        for cell in 0..a.geometry.cells() {
            gaps.differing_mask += usize::from(a.mask[cell] != b.mask[cell]);
            gaps.compared += usize::from(a.fused[cell].is_finite());
            gaps.worst_fused_per_s = gaps
                .worst_fused_per_s
                .max(looming_gap_per_s(a.fused[cell], b.fused[cell]));
            gaps.worst_lidar_per_s = gaps
                .worst_lidar_per_s
                .max(looming_gap_per_s(a.l_lidar[cell], b.l_lidar[cell]));
        }
    }
    gaps
}

/// Round trip: the same looming per cell as the direct run.
fn assert_same_looming_as_direct_run(synth: &Path, imported: &Path) {
    let direct = engine_results(synth);
    let via_kitti = engine_results(imported);
    assert_eq!(direct.len(), via_kitti.len());
    let RoundTripGaps {
        compared,
        differing_mask,
        worst_fused_per_s: worst_fused,
        worst_lidar_per_s: worst_lidar,
    } = round_trip_gaps(&direct, &via_kitti);
    let cells = direct.len() * direct.values().next().unwrap().1.geometry.cells();
    assert!(compared > cells / 2, "{compared} of {cells} cells compared");
    eprintln!(
        "round trip: largest |difference| L_lidar {worst_lidar}, fused {worst_fused} 1/s over {compared} cells; {differing_mask} of {cells} masks differ"
    );
    // Points (float bits), rings, per-point times (from the azimuth, equal to
    // the simulator's up to f32 rounding) and motion samples travel
    // unchanged: the engine gives the same result to float tolerance (with
    // the range noise estimated per scan, a plane fit may take or leave a
    // return at its noise gate: 1.8e-4 1/s at most).
    assert!(
        worst_lidar < 5e-4 && worst_fused < 5e-4,
        "largest differences: L_lidar {worst_lidar}, fused {worst_fused} 1/s"
    );
    assert_eq!(
        differing_mask, 0,
        "{differing_mask} of {cells} masks differ"
    );
}

/// `process` of the imported log finds the one planted near miss; returns
/// the processed log.
fn process_finds_the_cut_in(dir: &Path, imported: &Path) -> PathBuf {
    let processed = dir.join("imported-out.mcap");
    let events = dir.join("events.json");
    run(&[
        "process",
        imported.to_str().unwrap(),
        "-o",
        processed.to_str().unwrap(),
        "--events",
        events.to_str().unwrap(),
        "-q",
    ]);
    let events: looming::events::EventsFile =
        serde_json::from_slice(&std::fs::read(&events).unwrap()).unwrap();
    assert_eq!(events.events.len(), 1, "the cut-in near miss");
    processed
}

/// `eval` of the imported log against the scenario's truth matches the
/// direct evaluation.
fn assert_eval_matches_direct(dir: &Path, imported: &Path, synth: &Path) {
    let eval_json = dir.join("eval.json");
    run(&[
        "eval",
        imported.to_str().unwrap(),
        "--truth",
        synth.to_str().unwrap(),
        "--json",
        eval_json.to_str().unwrap(),
    ]);
    let eval: serde_json::Value =
        serde_json::from_slice(&std::fs::read(&eval_json).unwrap()).unwrap();
    let direct_eval = looming::commands::eval::evaluate(synth, &EngineConfig::default()).unwrap();
    assert_eq!(eval["pairs"].as_u64(), Some(direct_eval.pairs));
    let p90 = |q: &str, c: &str| eval["errors"][q][c]["p90_abs"].as_f64().unwrap();
    let direct_p90 = direct_eval.errors["fused"]["all_unmasked"].p90_abs;
    assert!(
        (p90("fused", "all_unmasked") - direct_p90).abs() < 2e-3,
        "fused p90 {} via KITTI against {direct_p90} direct",
        p90("fused", "all_unmasked")
    );
}

fn assert_render_writes_a_png(dir: &Path, processed: &Path) {
    let png = dir.join("fused.png");
    run(&[
        "render",
        processed.to_str().unwrap(),
        "--channel",
        "fused",
        "--frame",
        "3",
        "-o",
        png.to_str().unwrap(),
    ]);
    assert!(std::fs::metadata(&png).unwrap().len() > 1000);
}

#[test]
fn a_kitti_folder_imports_processes_evaluates_renders_and_matches_the_direct_run() {
    let dir = scratch("kitti-round-trip");
    let synth = synthesize_cut_in_at_100_hz(&dir);
    let drive = read_drive(&synth);
    assert!(drive.scans.len() >= 14);
    let drive_dir = write_kitti(&drive, &dir.join("kitti"));
    let imported = dir.join("imported.mcap");
    // The synthetic sensor turns clockwise (KITTI's: counter-clockwise).
    run(&[
        "import-kitti",
        drive_dir.to_str().unwrap(),
        "-o",
        imported.to_str().unwrap(),
        "--sweep",
        "clockwise",
    ]);
    assert_inspect_finds_kitti_topics(&imported);
    assert_same_looming_as_direct_run(&synth, &imported);

    // process, events, eval against the scenario's truth, render.
    let processed = process_finds_the_cut_in(&dir, &imported);
    assert_eval_matches_direct(&dir, &imported, &synth);
    assert_render_writes_a_png(&dir, &processed);
    assert_opens_in_viewers_in_velo_link(&dir, &imported, &processed);
    let _ = std::fs::remove_dir_all(&dir);
}

/// The import and its annotated log open in Foxglove and Lichtblick, and
/// their layout follows KITTI's LiDAR frame.
fn assert_opens_in_viewers_in_velo_link(dir: &Path, imported: &Path, processed: &Path) {
    common::viewer::assert_opens_in_viewers(imported);
    common::viewer::assert_opens_in_viewers(processed);
    let layout = dir.join("layout.json");
    run(&[
        "layout",
        processed.to_str().unwrap(),
        "-o",
        layout.to_str().unwrap(),
    ]);
    let json: serde_json::Value = serde_json::from_slice(&std::fs::read(&layout).unwrap()).unwrap();
    assert_eq!(json["configById"]["3D!looming"]["followTf"], "velo_link");
}

/// Import that must fail with exit code 1; its message.
fn failed_import(drive_dir: &Path, out: &Path) -> String {
    let failed = looming(&[
        "import-kitti",
        drive_dir.to_str().unwrap(),
        "-o",
        out.to_str().unwrap(),
        "--force",
    ]);
    assert_eq!(failed.status.code(), Some(1));
    stderr(&failed)
}

#[test]
fn a_missing_frame_is_skipped_and_named_and_bad_files_are_errors_with_their_line() {
    let dir = scratch("kitti-bad");
    let synth = dir.join("synth.mcap");
    run(&[
        "synth",
        "--scenario",
        "straight-road",
        "--duration",
        "0.6",
        "--beams",
        "16",
        "--columns",
        "256",
        "-o",
        synth.to_str().unwrap(),
        "--force",
        "-q",
    ]);
    let drive = read_drive(&synth);
    let drive_dir = write_kitti(&drive, &dir.join("kitti"));
    let missing = drive_dir.join("velodyne_points/data/0000000002.bin");
    std::fs::remove_file(&missing).unwrap();
    let out = dir.join("out.mcap");
    let summary = run(&[
        "import-kitti",
        drive_dir.to_str().unwrap(),
        "-o",
        out.to_str().unwrap(),
        "--sweep",
        "clockwise",
    ]);
    assert!(
        summary.contains("0000000002.bin"),
        "the missing frame is named: {summary}"
    );
    let contents = common::read_all(&std::fs::read(&out).unwrap());
    assert_eq!(
        contents.topic_messages("/velodyne_points").len(),
        drive.scans.len() - 1
    );

    // A malformed OXTS line: an error naming the file and the line.
    let packet = drive_dir.join("oxts/data/0000000003.txt");
    std::fs::write(&packet, "49.0 8.4 116.0 0 0 0\n").unwrap();
    let message = failed_import(&drive_dir, &out);
    assert!(
        message.contains("0000000003.txt:1"),
        "names file and line: {message}"
    );
    // A malformed timestamp.
    std::fs::write(
        &packet,
        std::fs::read(drive_dir.join("oxts/data/0000000004.txt")).unwrap(),
    )
    .unwrap();
    let stamps = drive_dir.join("velodyne_points/timestamps_start.txt");
    let text = std::fs::read_to_string(&stamps).unwrap();
    // Month 13 on the first line.
    let broken = text.replacen("2023-11-14", "2023-13-14", 1);
    std::fs::write(&stamps, broken).unwrap();
    let message = failed_import(&drive_dir, &out);
    assert!(
        message.contains("timestamps_start.txt:1"),
        "names file and line: {message}"
    );
    let _ = std::fs::remove_dir_all(&dir);
}
