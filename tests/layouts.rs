//! Every cloud layout of `looming synth --layout` through the real binary and
//! `looming eval --json`, against docs/method.md's 32 x 512 accuracy table
//! (the `cut-in` row, 2-4 s, 19 pairs) within 10 %: `L_lidar` median and p90
//! over unmasked cells, `|D|` p90 on each static class, and moving-cell F1.
//!
//! Layouts without a ring or a time field (KITTI-like laser order, driver
//! clouds in firing order) go through the engine's front end
//! (`engine::layout`), which recovers rings and times from the point order.

mod common;

use common::*;

/// docs/method.md, 32 x 512, `cut-in` 2-4 s.
const PAIRS: u64 = 19;
const L_LIDAR_MEDIAN: f64 = 0.008;
const L_LIDAR_P90: f64 = 0.025;
/// `|D|` p90 on static_road, static_facing, static_oblique.
const D_P90: [(&str, f64); 3] = [
    ("static_road", 0.026),
    ("static_facing", 0.015),
    ("static_oblique", 0.007),
];
const MOVING_F1: f64 = 0.999;
const SLACK: f64 = 0.10;

fn eval_layout(layout: &str) -> serde_json::Value {
    let dir = scratch(&format!("layouts-{}", layout.replace(':', "_")));
    let json = dir.join("eval.json");
    let log = common::cut_in_window(&dir, "cut-in", &["--layout", layout]);
    let run = looming(&[
        "eval",
        log.to_str().unwrap(),
        "--json",
        json.to_str().unwrap(),
    ]);
    assert!(run.status.success(), "{layout}: eval: {}", stderr(&run));
    let report = serde_json::from_slice(&std::fs::read(&json).unwrap()).unwrap();
    let _ = std::fs::remove_dir_all(&dir);
    report
}

fn check_layout(layout: &str) {
    let report = eval_layout(layout);
    assert_eq!(report["pairs"], PAIRS, "{layout}: pairs");
    let value = |quantity: &str, class: &str, key: &str| {
        report["errors"][quantity][class][key]
            .as_f64()
            .unwrap_or_else(|| panic!("{layout}: no {quantity} {class} {key}"))
    };
    let at_most = |got: f64, target: f64, what: &str| {
        assert!(
            got <= target * (1.0 + SLACK),
            "{layout}: {what} {got:.4} above {target} + 10 %"
        );
    };
    at_most(
        value("l_lidar", "all_unmasked", "median_abs"),
        L_LIDAR_MEDIAN,
        "L_lidar median",
    );
    at_most(
        value("l_lidar", "all_unmasked", "p90_abs"),
        L_LIDAR_P90,
        "L_lidar p90",
    );
    for (class, target) in D_P90 {
        at_most(
            value("disagreement", class, "p90_abs"),
            target,
            &format!("|D| p90 {class}"),
        );
    }
    let f1 = report["moving_detection"]["f1"].as_f64().unwrap_or(0.0);
    assert!(
        f1 >= MOVING_F1 * (1.0 - SLACK),
        "{layout}: moving F1 {f1:.3} below {MOVING_F1} - 10 %"
    );
}

#[test]
fn ring_time() {
    check_layout("ring-time");
}

#[test]
fn organized() {
    check_layout("organized");
}

#[test]
fn ring_field_channel() {
    check_layout("ring-field:channel");
}

#[test]
fn ring_field_laser_id() {
    check_layout("ring-field:laser_id");
}

#[test]
fn ring_field_laser_id_int32() {
    check_layout("ring-field:laser_id:int32");
}

#[test]
fn ring_field_line() {
    check_layout("ring-field:line");
}

#[test]
fn laser_order() {
    check_layout("laser-order");
}

#[test]
fn laser_order_kitti() {
    check_layout("laser-order:kitti");
}

#[test]
fn firing_order() {
    check_layout("firing-order");
}

#[test]
fn firing_order_sparse() {
    check_layout("firing-order-sparse");
}
