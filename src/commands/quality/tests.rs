//! Unit tests of `looming quality`: the totals and diagnoses of made-up pairs.

use super::read::{CurrentScan, PairMessage, layout_text};
use super::totals::Builder;
use super::*;
use crate::quality::{AbsHistogram, GroundSide, MaskCounts, PairQuality};

fn pair(index: u64, left: f64, right: f64, trusted: u64) -> PairMessage {
    let side = |v: f64| GroundSide {
        cells: 50,
        median_fused_per_s: Some(v),
        median_d_per_s: Some(0.0),
    };
    let mut quality = PairQuality {
        points: 100,
        trusted_points: trusted,
        trusted_fraction: Some(trusted as f64 / 100.0),
        cells: 100,
        trusted_cells: trusted,
        masked_cells: MaskCounts {
            occlusion: 100 - trusted,
            edge: (100 - trusted) / 2,
            ..MaskCounts::default()
        },
        ego_velocity: true,
        range_noise_m_per_ring: vec![0.02, 0.03, 0.05],
        ..PairQuality::default()
    };
    quality.ground.left = side(left);
    quality.ground.right = side(right);
    quality.ground.trusted_static_cells = 100;
    quality.ground.abs_fused_histogram = AbsHistogram::of([left.abs(), right.abs()].into_iter());
    PairMessage {
        index,
        current: CurrentScan {
            stamp_ns: index as i64,
            log_time_ns: index,
            layout: None,
        },
        speed_mps: Some(10.0),
        quality: Some(quality),
        extrinsic: None,
    }
}

fn report(pairs: Vec<PairMessage>) -> QualityReport {
    let mut builder = Builder::default();
    for p in pairs {
        builder.add(p);
    }
    builder.finish("test.mcap".into())
}

fn codes(report: &QualityReport) -> Vec<&str> {
    report.diagnoses.iter().map(|d| d.code.as_str()).collect()
}

#[test]
fn a_clean_ground_says_nothing() {
    let r = report((0..5).map(|i| pair(i, 0.004, -0.003, 90)).collect());
    assert!(r.diagnoses.is_empty(), "{:?}", r.diagnoses);
    assert_eq!(r.totals.trusted_fraction, Some(0.9));
    assert_eq!(r.totals.layouts.get("unknown"), Some(&5));
    assert_eq!(r.totals.range_noise.min_m, Some(0.019999999552965164));
    assert_eq!(r.totals.range_noise.max_m, Some(0.05000000074505806));
    assert_eq!(r.totals.range_noise.rings, 3);
    assert!(r.to_text().contains("nothing to report"));
}

#[test]
fn opposite_halves_consistently_are_a_split() {
    let mut pairs: Vec<PairMessage> = (0..4).map(|i| pair(i, 0.05, -0.04, 90)).collect();
    pairs.push(pair(4, 0.0, 0.0, 90));
    let r = report(pairs);
    assert_eq!(codes(&r), ["ground_split"]);
    let message = &r.diagnoses[0].message;
    assert!(
        message.starts_with("the ground reads approaching on the left and receding on the right"),
        "{message}"
    );
    assert!(message.contains("a tilted extrinsic (roll) or a wrong LiDAR frame"));
    assert_eq!(r.totals.ground_fused.left_approaching_right_receding, 4);
    assert_eq!(r.totals.ground_fused.pairs_judged, 5);
    // The reverse reads the other way round.
    let r = report((0..3).map(|i| pair(i, -0.05, 0.04, 90)).collect());
    assert!(
        r.diagnoses[0]
            .message
            .starts_with("the ground reads receding on the left and approaching on the right")
    );
}

#[test]
fn one_odd_pair_is_not_a_pattern() {
    let mut pairs: Vec<PairMessage> = (0..5).map(|i| pair(i, 0.0, 0.0, 90)).collect();
    pairs.push(pair(5, 0.05, -0.05, 90));
    assert!(report(pairs).diagnoses.is_empty());
}

#[test]
fn the_same_sign_on_both_halves_is_an_offset() {
    let r = report((0..3).map(|i| pair(i, -0.05, -0.03, 90)).collect());
    assert_eq!(codes(&r), ["ground_offset"]);
    assert!(
        r.diagnoses[0]
            .message
            .contains("the whole ground reads receding")
    );
    assert!(
        r.diagnoses[0]
            .message
            .contains("vertical velocity / pitch error")
    );
    assert!(r.diagnoses[0].message.contains("time offset"));
}

#[test]
fn large_laser_offsets_are_reported() {
    let with_offsets = |offsets: Vec<f32>| {
        let pairs = (0..3)
            .map(|i| {
                let mut p = pair(i, 0.004, -0.003, 90);
                if let Some(q) = p.quality.as_mut() {
                    q.range_offset_m_per_ring = offsets.clone();
                }
                p
            })
            .collect();
        report(pairs)
    };
    let r = with_offsets(vec![0.02, -0.03, 0.01]);
    assert_eq!(codes(&r), ["range_offsets"]);
    assert!(
        r.diagnoses[0].message.contains("2.2 cm RMS, up to 3.0 cm"),
        "{}",
        r.diagnoses[0].message
    );
    assert!(codes(&with_offsets(vec![0.0, 0.0, 0.0])).is_empty());
    assert!(codes(&with_offsets(vec![0.005, -0.005, 0.0])).is_empty());
}

#[test]
fn low_trust_names_the_dominant_mask() {
    let r = report((0..3).map(|i| pair(i, 0.0, 0.0, 20)).collect());
    assert_eq!(codes(&r), ["low_trust"]);
    let message = &r.diagnoses[0].message;
    assert!(
        message.contains("only 20.0 % of the points are trusted"),
        "{message}"
    );
    assert!(
        message.contains("`occlusion` (80.0 % of occupied cells)"),
        "{message}"
    );
}

#[test]
fn layouts_are_read_from_the_pair_records_when_present() {
    let mut p = pair(0, 0.0, 0.0, 90);
    p.current.layout = Some(serde_json::json!("organized_rings_from_rows"));
    let r = report(vec![p]);
    assert_eq!(r.scans[0].layout, "organized_rings_from_rows");
    let record: PairMessage = serde_json::from_str(
        r#"{"index": 3, "current": {"stamp_ns": 1, "log_time_ns": 2, "frame_id": "x",
            "layout": {"rings": "field", "times": "field"}}, "speed_mps": null}"#,
    )
    .unwrap();
    assert_eq!(
        layout_text(record.current.layout.as_ref()),
        r#"{"rings":"field","times":"field"}"#
    );
    assert!(record.quality.is_none());
    let described =
        serde_json::json!({"rings": "field", "description": "ring field `ring` (32 rings)"});
    assert_eq!(
        layout_text(Some(&described)),
        "ring field `ring` (32 rings)"
    );
}

/// Sensor `name`'s report of five pairs a `period_ns` apart, each logged
/// `lag_ns` after its stamp.
fn timed_sensor(name: &str, period_ns: u64, lag_ns: u64) -> QualityReport {
    let mut r = report(
        (0..5)
            .map(|i| {
                let mut p = pair(i, 0.004, -0.003, 90);
                p.current.stamp_ns = (1_000_000_000 + i * period_ns) as i64;
                p.current.log_time_ns = 1_000_000_000 + i * period_ns + lag_ns;
                p
            })
            .collect(),
    );
    r.sensor = Some(name.into());
    r
}

#[test]
fn a_sensor_stamped_off_the_others_or_without_a_transform_is_named() {
    // Three sensors; the third's stamps are 200 ms behind its log times.
    let mut reports = vec![
        timed_sensor("roof", 100_000_000, 0),
        timed_sensor("left", 100_000_000, 10_000_000),
        timed_sensor("right", 100_000_000, 200_000_000),
    ];
    super::diagnose::diagnose_sensors(&mut reports, &[0, 0, 3]);
    assert!(codes(&reports[0]).is_empty(), "{:?}", reports[0].diagnoses);
    assert!(codes(&reports[1]).is_empty(), "{:?}", reports[1].diagnoses);
    assert_eq!(codes(&reports[2]), ["sensor_clock", "sensor_extrinsic"]);
    assert!(reports[2].diagnoses[0].message.contains("right"));
}

#[test]
fn sensors_stamped_at_their_sweeps_start_at_different_rates_agree() {
    // A 10 Hz roof and a 20 Hz side LiDAR, each stamped when its sweep
    // starts and logged when it ends (`synth --lidars 3`): 100 and 50 ms
    // from stamp to log time, one clock.
    let mut reports = vec![
        timed_sensor("roof", 100_000_000, 100_000_000),
        timed_sensor("left", 50_000_000, 50_000_000),
    ];
    super::diagnose::diagnose_sensors(&mut reports, &[0, 0]);
    for r in &reports {
        assert!(codes(r).is_empty(), "{:?}", r.diagnoses);
    }
}
