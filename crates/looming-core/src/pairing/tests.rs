//! State-machine and policy tests for [`ScanPairer`].

use super::*;
use crate::model::{AngularSource, ExtrinsicSource, VelocitySourceKind};
use nalgebra::{Isometry3, Vector3};

const MS: i64 = 1_000_000;

fn scan_with(
    stamp_ms: i64,
    frame: &str,
    point_count: usize,
    offsets_s: Option<Vec<f32>>,
) -> Arc<Scan> {
    Arc::new(Scan {
        stamp_ns: stamp_ms * MS,
        frame_id: frame.into(),
        sensor_pose: Isometry3::identity(),
        points_m: vec![[1.0, 0.0, 0.0]; point_count],
        intensity: None,
        ring: None,
        time_offset_s: offsets_s,
        source_index: (0..point_count as u32).collect(),
        input_point_count: point_count as u32,
        skipped_invalid_points: 0,
        organized: None,
        layout: crate::model::ScanLayout::default(),
        sensor_ids: None,
    })
}

fn scan(stamp_ms: i64) -> Arc<Scan> {
    scan_with(stamp_ms, "lidar", 3, None)
}

fn imu(stamp_ms: i64, frame: &str, yaw_radps: f64) -> ImuSample {
    ImuSample {
        stamp_ns: stamp_ms * MS,
        frame_id: frame.into(),
        angular_velocity_radps: Vector3::new(0.0, 0.0, yaw_radps),
        linear_acceleration_mps2: Vector3::new(0.0, 0.0, 9.81),
        orientation: None,
    }
}

fn velocity(stamp_ms: i64, frame: &str, forward_mps: f64, yaw_radps: f64) -> VelocitySample {
    VelocitySample {
        stamp_ns: stamp_ms * MS,
        frame_id: frame.into(),
        linear_mps: Vector3::new(forward_mps, 0.0, 0.0),
        angular_radps: Vector3::new(0.0, 0.0, yaw_radps),
        source: VelocitySourceKind::Odometry,
    }
}

fn log_ns(stamp_ms: i64) -> u64 {
    (stamp_ms * MS) as u64
}

fn pairs(events: &[PairEvent]) -> Vec<&ScanPair> {
    events
        .iter()
        .filter_map(|e| match e {
            PairEvent::Pair(p) => Some(p),
            PairEvent::Warning(_) => None,
        })
        .collect()
}

fn warnings(events: &[PairEvent]) -> Vec<&str> {
    events
        .iter()
        .filter_map(|e| match e {
            PairEvent::Warning(w) => Some(w.as_str()),
            PairEvent::Pair(_) => None,
        })
        .collect()
}

fn both_sources() -> PairingConfig {
    PairingConfig {
        has_velocity_source: true,
        has_imu_source: true,
        ..PairingConfig::default()
    }
}

fn push_motion(pairer: &mut ScanPairer, stamp_ms: i64) -> Vec<PairEvent> {
    let mut events = pairer.push_velocity(log_ns(stamp_ms), velocity(stamp_ms, "lidar", 2.0, 0.0));
    events.extend(pairer.push_imu(log_ns(stamp_ms), imu(stamp_ms, "lidar", 0.0)));
    events
}

#[test]
fn without_sources_each_scan_after_the_first_makes_a_pair_at_once() {
    let mut pairer = ScanPairer::new(PairingConfig::default());
    assert!(pairer.push_scan(log_ns(0), scan(0)).is_empty());
    assert_eq!(pairer.buffered_scan_count(), 1);
    let events = pairer.push_scan(log_ns(100), scan(100));
    let emitted = pairs(&events);
    assert_eq!(emitted.len(), 1);
    let pair = emitted[0];
    assert_eq!(
        (pair.previous.stamp_ns, pair.current.stamp_ns),
        (0, 100 * MS)
    );
    assert!((pair.dt_s - 0.1).abs() < 1e-12);
    assert_eq!(
        (pair.previous_log_time_ns, pair.current_log_time_ns),
        (0, log_ns(100))
    );
    assert_eq!(pair.index, 0);
    assert!(pair.motion.velocity.is_none() && pair.motion.angular.is_none());
    assert!(pair.motion.coverage_complete);
    assert_eq!(warnings(&events).len(), 2, "{events:?}");
    // Warnings are reported once, not per pair.
    let events = pairer.push_scan(log_ns(200), scan(200));
    assert_eq!(pairs(&events)[0].index, 1);
    assert!(warnings(&events).is_empty());
    let stats = pairer.stats();
    assert_eq!((stats.scans_seen, stats.pairs_emitted), (3, 2));
    assert_eq!(
        (stats.pairs_without_velocity, stats.pairs_without_imu),
        (2, 2)
    );
    assert!(pairer.finish().is_empty());
}

#[test]
fn pending_pair_waits_until_every_source_covers_the_scan_end() {
    let mut pairer = ScanPairer::new(both_sources());
    push_motion(&mut pairer, 0);
    pairer.push_scan(log_ns(0), scan(0));
    push_motion(&mut pairer, 50);
    assert!(pairer.push_scan(log_ns(100), scan(100)).is_empty());
    assert_eq!(pairer.buffered_scan_count(), 2);
    // Velocity covers the end, IMU does not yet.
    assert!(pairs(&pairer.push_velocity(log_ns(100), velocity(100, "lidar", 2.0, 0.0))).is_empty());
    let events = pairer.push_imu(log_ns(101), imu(100, "lidar", 0.0));
    let emitted = pairs(&events);
    assert_eq!(emitted.len(), 1);
    let motion = &emitted[0].motion;
    assert!(motion.coverage_complete);
    assert_eq!(motion.angular_source, AngularSource::Imu);
    assert_eq!(
        motion.velocity_at(75 * MS),
        Some(Vector3::new(2.0, 0.0, 0.0))
    );
    assert_eq!(pairer.buffered_scan_count(), 1);
    let stats = pairer.stats();
    assert_eq!(
        (stats.pairs_without_velocity, stats.pairs_without_imu),
        (0, 0)
    );
    assert_eq!(
        stats.extrinsic_source["velocity"],
        "same_frame (lidar from lidar)"
    );
}

#[test]
fn samples_ahead_of_the_scan_emit_the_pair_on_the_scan_itself() {
    let mut pairer = ScanPairer::new(both_sources());
    push_motion(&mut pairer, 0);
    pairer.push_scan(log_ns(0), scan(0));
    push_motion(&mut pairer, 120);
    assert_eq!(pairs(&pairer.push_scan(log_ns(130), scan(100))).len(), 1);
}

#[test]
fn pending_pair_is_flushed_by_the_next_scan_and_by_finish() {
    let mut pairer = ScanPairer::new(both_sources());
    pairer.push_scan(log_ns(0), scan(0));
    pairer.push_scan(log_ns(100), scan(100));
    let events = pairer.push_scan(log_ns(200), scan(200));
    let emitted = pairs(&events);
    assert_eq!(emitted.len(), 1);
    assert_eq!(emitted[0].current.stamp_ns, 100 * MS);
    assert!(!emitted[0].motion.coverage_complete);
    assert!(emitted[0].motion.velocity.is_none());
    assert_eq!(
        pairer.buffered_scan_count(),
        2,
        "pair (100, 200) now pending"
    );
    let events = pairer.finish();
    let emitted = pairs(&events);
    assert_eq!(emitted.len(), 1);
    assert_eq!(emitted[0].current.stamp_ns, 200 * MS);
    assert_eq!(emitted[0].index, 1);
    assert!(pairer.finish().is_empty(), "finish is idempotent");
    let stats = pairer.stats();
    assert_eq!(stats.pairs_motion_incomplete, 2);
    assert_eq!(stats.pairs_without_velocity, 2);
}

#[test]
fn nonpositive_dt_skips_the_new_scan_and_keeps_the_previous() {
    let mut pairer = ScanPairer::new(PairingConfig::default());
    pairer.push_scan(log_ns(0), scan(100));
    assert!(pairs(&pairer.push_scan(log_ns(10), scan(100))).is_empty());
    assert!(pairs(&pairer.push_scan(log_ns(20), scan(90))).is_empty());
    assert_eq!(pairer.stats().skipped_nonpositive_dt, 2);
    let events = pairer.push_scan(log_ns(30), scan(200));
    assert_eq!(pairs(&events)[0].previous.stamp_ns, 100 * MS);
}

#[test]
fn large_backwards_jump_restarts_pairing_from_the_new_scan() {
    let mut pairer = ScanPairer::new(PairingConfig::default());
    pairer.push_scan(log_ns(0), scan(10_000));
    let events = pairer.push_scan(log_ns(10), scan(0));
    assert!(pairs(&events).is_empty());
    assert_eq!(warnings(&events).len(), 1);
    let stats = pairer.stats();
    assert_eq!((stats.skipped_nonpositive_dt, stats.clock_resets), (1, 1));
    let events = pairer.push_scan(log_ns(20), scan(100));
    assert_eq!(pairs(&events)[0].previous.stamp_ns, 0);
}

#[test]
fn gap_beyond_set_nominal_period_breaks_the_chain() {
    let mut pairer = ScanPairer::new(PairingConfig::default());
    pairer.set_nominal_period_s(Some(0.1));
    assert_eq!(pairer.max_gap_s(), Some(0.1 * 3.0));
    pairer.push_scan(log_ns(0), scan(0));
    assert_eq!(
        pairs(&pairer.push_scan(log_ns(300), scan(300))).len(),
        1,
        "3 periods is allowed"
    );
    assert!(pairs(&pairer.push_scan(log_ns(700), scan(700))).is_empty());
    assert_eq!(pairer.stats().skipped_gap, 1);
    let events = pairer.push_scan(log_ns(800), scan(800));
    assert_eq!(pairs(&events)[0].previous.stamp_ns, 700 * MS);
    assert_eq!(pairer.stats().nominal_period_s, Some(0.1));
}

#[test]
fn gap_uses_the_running_median_when_no_period_is_set() {
    let mut pairer = ScanPairer::new(PairingConfig::default());
    for k in 0..5 {
        pairer.push_scan(log_ns(k * 100), scan(k * 100));
    }
    assert!((pairer.stats().nominal_period_s.unwrap() - 0.1).abs() < 1e-12);
    assert!(pairs(&pairer.push_scan(log_ns(1_400), scan(1_400))).is_empty());
    assert_eq!(pairer.stats().skipped_gap, 1);
}

#[test]
fn explicit_max_gap_overrides_periods() {
    let mut pairer = ScanPairer::new(PairingConfig {
        max_gap_s: Some(1.0),
        ..PairingConfig::default()
    });
    pairer.set_nominal_period_s(Some(0.1));
    pairer.push_scan(log_ns(0), scan(0));
    assert_eq!(pairs(&pairer.push_scan(log_ns(900), scan(900))).len(), 1);
    assert!(pairs(&pairer.push_scan(log_ns(2_000), scan(2_000))).is_empty());
    assert_eq!(pairer.stats().skipped_gap, 1);
}

#[test]
fn empty_scans_are_counted_and_still_paired() {
    let mut pairer = ScanPairer::new(PairingConfig::default());
    pairer.push_scan(log_ns(0), scan_with(0, "lidar", 0, None));
    let events = pairer.push_scan(log_ns(100), scan(100));
    assert_eq!(pairs(&events).len(), 1);
    assert_eq!(pairer.stats().empty_scans, 1);
}

#[test]
fn late_samples_are_counted_and_ignored() {
    let mut pairer = ScanPairer::new(both_sources());
    for k in 0..=3 {
        push_motion(&mut pairer, k * 100);
        pairer.push_scan(log_ns(k * 100), scan(k * 100));
    }
    // Previous scan is now at 200 ms or later; with a 0.2 s hold, data before 0 ms is consumed.
    assert_eq!(pairer.stats().pairs_emitted, 3);
    pairer.push_imu(log_ns(400), imu(-50, "lidar", 0.0));
    pairer.push_velocity(log_ns(400), velocity(-10, "lidar", 1.0, 0.0));
    assert_eq!(pairer.stats().late_samples, 2);
    // A slightly out-of-order sample inside the live window is accepted.
    pairer.push_imu(log_ns(400), imu(250, "lidar", 0.0));
    assert_eq!(pairer.stats().late_samples, 2);
}

#[test]
fn per_point_times_extend_the_span_the_motion_must_cover() {
    let mut pairer = ScanPairer::new(PairingConfig {
        has_velocity_source: true,
        ..PairingConfig::default()
    });
    // Stamped at sweep start, points up to +95 ms.
    let sweep = Some(vec![0.0, 0.05, 0.095]);
    pairer.push_velocity(log_ns(0), velocity(0, "lidar", 1.0, 0.0));
    pairer.push_scan(log_ns(100), scan_with(0, "lidar", 3, sweep.clone()));
    pairer.push_velocity(log_ns(150), velocity(100, "lidar", 1.0, 0.0));
    assert!(pairs(&pairer.push_scan(log_ns(200), scan_with(100, "lidar", 3, sweep))).is_empty());
    assert!(pairs(&pairer.push_velocity(log_ns(210), velocity(190, "lidar", 1.0, 0.0))).is_empty());
    assert_eq!(
        pairs(&pairer.push_velocity(log_ns(220), velocity(195, "lidar", 1.0, 0.0))).len(),
        1
    );
}

#[test]
fn tf_static_extrinsic_adds_the_lever_arm() {
    let mut pairer = ScanPairer::new(both_sources());
    pairer.push_transforms(
        &[FrameTransform {
            stamp_ns: 0,
            parent_frame: "/base_link".into(),
            child_frame: "velodyne".into(),
            parent_from_child: Isometry3::translation(1.0, 0.0, 0.0),
        }],
        true,
    );
    // Dynamic transforms never override the mount.
    pairer.push_transforms(
        &[FrameTransform {
            stamp_ns: 0,
            parent_frame: "base_link".into(),
            child_frame: "velodyne".into(),
            parent_from_child: Isometry3::translation(9.0, 0.0, 0.0),
        }],
        false,
    );
    for k in 0..=1 {
        pairer.push_velocity(log_ns(k * 100), velocity(k * 100, "base_link", 5.0, 0.5));
        pairer.push_imu(log_ns(k * 100), imu(k * 100, "base_link", 0.5));
    }
    pairer.push_scan(log_ns(0), scan_with(0, "velodyne", 3, None));
    let events = pairer.push_scan(log_ns(100), scan_with(100, "velodyne", 3, None));
    assert!(warnings(&events).is_empty(), "{events:?}");
    let pair = pairs(&events)[0];
    let v = pair.motion.velocity_at(50 * MS).unwrap();
    assert!((v - Vector3::new(5.0, 0.5, 0.0)).norm() < 1e-12, "{v:?}");
    let extrinsic = pair.motion.velocity_extrinsic.as_ref().unwrap();
    assert_eq!(extrinsic.source, ExtrinsicSource::TfStatic);
    assert_eq!(
        pairer.stats().extrinsic_source["imu"],
        "tf_static (base_link from velodyne)"
    );
}

#[test]
fn cli_extrinsic_wins_over_tf_static() {
    let mut pairer = ScanPairer::new(PairingConfig {
        cli_extrinsic: Some(Isometry3::translation(2.0, 0.0, 0.0)),
        has_velocity_source: true,
        ..PairingConfig::default()
    });
    pairer.push_transforms(
        &[FrameTransform {
            stamp_ns: 0,
            parent_frame: "base_link".into(),
            child_frame: "velodyne".into(),
            parent_from_child: Isometry3::translation(1.0, 0.0, 0.0),
        }],
        true,
    );
    pairer.push_velocity(log_ns(0), velocity(0, "base_link", 0.0, 1.0));
    pairer.push_scan(log_ns(0), scan_with(0, "velodyne", 3, None));
    pairer.push_velocity(log_ns(100), velocity(100, "base_link", 0.0, 1.0));
    let events = pairer.push_scan(log_ns(100), scan_with(100, "velodyne", 3, None));
    let pair = pairs(&events)[0];
    assert_eq!(pair.motion.angular_source, AngularSource::Twist);
    let v = pair.motion.velocity_at(0).unwrap();
    assert!((v - Vector3::new(0.0, 2.0, 0.0)).norm() < 1e-12, "{v:?}");
    assert_eq!(
        pair.motion.velocity_extrinsic.as_ref().unwrap().source,
        ExtrinsicSource::Cli
    );
}

#[test]
fn unknown_extrinsic_assumes_identity_with_a_single_warning() {
    let mut pairer = ScanPairer::new(PairingConfig {
        has_velocity_source: true,
        ..PairingConfig::default()
    });
    let mut identity_warnings = 0;
    for k in 0..5 {
        pairer.push_velocity(log_ns(k * 100), velocity(k * 100, "base_link", 1.0, 0.0));
        let events = pairer.push_scan(log_ns(k * 100), scan_with(k * 100, "velodyne", 3, None));
        identity_warnings += warnings(&events)
            .iter()
            .filter(|w| w.contains("assuming identity"))
            .count();
        for pair in pairs(&events) {
            assert_eq!(
                pair.motion.velocity_extrinsic.as_ref().unwrap().source,
                ExtrinsicSource::IdentityAssumed
            );
        }
    }
    assert_eq!(pairer.stats().pairs_emitted, 4);
    assert_eq!(identity_warnings, 1);
}

#[test]
fn long_run_keeps_buffers_small() {
    let mut pairer = ScanPairer::new(both_sources());
    pairer.set_nominal_period_s(Some(0.1));
    let mut emitted = 0_u64;
    let mut max_buffered = 0;
    // 10 kHz combined motion (5 kHz each source) for 1000 s would be too slow
    // in debug; 100k samples over 10k scans at 10 Hz = 10 samples per scan.
    for scan_index in 0..10_000_i64 {
        let scan_ms = scan_index * 100;
        for k in 0..5 {
            let sample_ms = scan_ms + k * 20;
            let mut events =
                pairer.push_velocity(log_ns(sample_ms), velocity(sample_ms, "lidar", 1.0, 0.0));
            events.extend(pairer.push_imu(log_ns(sample_ms), imu(sample_ms, "lidar", 0.1)));
            emitted += pairs(&events).len() as u64;
        }
        let events = pairer.push_scan(log_ns(scan_ms + 5), scan(scan_ms));
        emitted += pairs(&events).len() as u64;
        max_buffered = max_buffered.max(pairer.buffered_sample_count());
        assert!(pairer.buffered_scan_count() <= 2);
    }
    emitted += pairs(&pairer.finish()).len() as u64;
    assert_eq!(emitted, 9_999);
    assert_eq!(pairer.stats().pairs_emitted, 9_999);
    // Hold (0.2 s) + one period of 50 Hz per source, plus bracketing samples.
    assert!(max_buffered <= 40, "buffered {max_buffered}");
}

#[test]
fn samples_before_the_first_scan_are_bounded() {
    let mut pairer = ScanPairer::new(both_sources());
    for k in 0..20_000_i64 {
        pairer.push_imu(log_ns(k), imu(k, "imu", 0.0));
    }
    // 1 kHz for 20 s: only hold + pre-scan history (1.2 s) is kept.
    assert!(
        pairer.buffered_sample_count() <= 1_202,
        "{}",
        pairer.buffered_sample_count()
    );
}

#[test]
fn stats_serialise_to_json() {
    let mut pairer = ScanPairer::new(PairingConfig::default());
    pairer.push_scan(log_ns(0), scan(0));
    pairer.push_scan(log_ns(100), scan(100));
    let json = serde_json::to_value(pairer.stats()).unwrap();
    assert_eq!(json["pairs_emitted"], 1);
    assert_eq!(json["scans_seen"], 2);
    assert!(json["extrinsic_source"].is_object());
}
