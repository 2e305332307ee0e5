//! Real recordings (`../shared/real-data/*.mcap`, beside the project; see its
//! README): `process --fields full` + `quality --json` on every log there.
//!
//! - `real_logs_run_and_print_their_quality` (always): everything runs, every
//!   pair has a record, and the figures are printed (`--nocapture`).
//! - `real_logs_meet_the_quality_bar` (ignored: run with `--ignored`): the bar
//!   of a trustworthy log, trusted fraction >= 0.60, ground median |fused| <=
//!   0.02 1/s, no near-miss events (none of these scenes has one). Today's
//!   engine does not meet it on real sensors.
//!
//! When the folder is absent both say so loudly and return: they never pass
//! silently on data they did not see.

mod common;

use std::path::{Path, PathBuf};

use common::{looming_process, looming_quality, scratch, stderr};
use serde_json::Value;

const MIN_TRUSTED_FRACTION: f64 = 0.60;
const MAX_GROUND_MEDIAN_ABS_FUSED: f64 = 0.02;

fn real_data_dir() -> PathBuf {
    Path::new(env!("CARGO_MANIFEST_DIR")).join("../shared/real-data")
}

/// The logs present, sorted; `None` (after a loud message) without the folder.
fn real_logs() -> Option<Vec<PathBuf>> {
    let dir = real_data_dir();
    let Ok(entries) = std::fs::read_dir(&dir) else {
        eprintln!("SKIPPED: ../shared/real-data absent ({})", dir.display());
        return None;
    };
    let mut logs: Vec<PathBuf> = entries
        .filter_map(|e| e.ok().map(|e| e.path()))
        .filter(|p| p.extension().is_some_and(|x| x == "mcap"))
        .collect();
    logs.sort();
    if logs.is_empty() {
        eprintln!(
            "SKIPPED: ../shared/real-data holds no .mcap ({})",
            dir.display()
        );
        return None;
    }
    Some(logs)
}

/// Process and measure one log: (name, report).
fn measure(log: &Path, dir: &Path) -> (String, Value) {
    let name = log.file_stem().unwrap().to_string_lossy().into_owned();
    let output = dir.join(format!("{name}.looming.mcap"));
    let run = looming_process(log, &output, &["--fields", "full", "--force"]);
    assert!(run.status.success(), "process {name}: {}", stderr(&run));
    let (report, text) = looming_quality(&output, &dir.join(format!("{name}.quality.json")));
    println!("==== {name}\n{text}");
    let _ = std::fs::remove_file(&output);
    (name, report)
}

fn figure(report: &Value, key: &str) -> Option<f64> {
    report["totals"][key].as_f64()
}

#[test]
fn real_logs_run_and_print_their_quality() {
    let Some(logs) = real_logs() else {
        return;
    };
    let dir = scratch("real-data");
    let mut table = Vec::new();
    for log in &logs {
        let (name, report) = measure(log, &dir);
        let totals = &report["totals"];
        let pairs = totals["pairs"].as_u64().unwrap();
        assert!(pairs > 0, "{name}: no scan pairs");
        assert_eq!(
            report["scans"].as_array().unwrap().len() as u64,
            pairs,
            "{name}: one line per pair record"
        );
        assert!(
            totals["pairs_with_quality"].as_u64().unwrap() > 0,
            "{name}: no pair has quality figures"
        );
        table.push(format!(
            "{name:<40} trusted {:>7}  ground |fused| {:>8}  events {}  dominant mask {}  masks {}",
            figure(&report, "trusted_fraction")
                .map_or("-".into(), |f| format!("{:.1} %", 100.0 * f)),
            figure(&report, "ground_median_abs_fused_per_s")
                .map_or("-".into(), |f| format!("{f:.4}")),
            totals["near_miss_events"],
            totals["dominant_mask"],
            totals["masked_cell_fractions"],
        ));
    }
    println!("real data quality:\n{}", table.join("\n"));
}

#[test]
#[ignore = "real-sensor bar: run with --ignored"]
fn real_logs_meet_the_quality_bar() {
    let Some(logs) = real_logs() else {
        return;
    };
    let dir = scratch("real-data-bar");
    let mut failures = Vec::new();
    for log in &logs {
        let (name, report) = measure(log, &dir);
        let trusted = figure(&report, "trusted_fraction").unwrap_or(0.0);
        if trusted < MIN_TRUSTED_FRACTION {
            failures.push(format!(
                "{name}: trusted fraction {trusted:.3} < {MIN_TRUSTED_FRACTION}"
            ));
        }
        match figure(&report, "ground_median_abs_fused_per_s") {
            Some(g) if g <= MAX_GROUND_MEDIAN_ABS_FUSED => {}
            other => failures.push(format!(
                "{name}: ground median |fused| {other:?} > {MAX_GROUND_MEDIAN_ABS_FUSED} 1/s"
            )),
        }
        let events = report["totals"]["near_miss_events"].as_u64().unwrap();
        if events != 0 {
            failures.push(format!("{name}: {events} near-miss events, expected none"));
        }
    }
    assert!(failures.is_empty(), "{}", failures.join("\n"));
}
