//! The engine's front end on the real recordings of `../shared/real-data/`
//! (never copied into the repository): `looming process --json-summary`
//! names the layout it recovered. Skips, loudly, when the folder is absent.

mod common;

use std::path::{Path, PathBuf};

use common::{looming_process, scratch, stderr};

fn real_data() -> Option<PathBuf> {
    let dir = Path::new(env!("CARGO_MANIFEST_DIR")).join("../shared/real-data");
    dir.is_dir().then_some(dir)
}

/// `pairing.layout` of the run summary of `looming process` on `name`.
fn layout_of(dir: &Path, name: &str) -> Option<serde_json::Value> {
    let input = dir.join(name);
    if !input.is_file() {
        eprintln!("SKIPPED: {} absent", input.display());
        return None;
    }
    let dir_out = scratch(&format!("real-layout-{name}"));
    let (output, summary) = (dir_out.join("out.mcap"), dir_out.join("summary.json"));
    let run = looming_process(
        &input,
        &output,
        &[
            "--quiet",
            "--json-summary",
            summary.to_str().expect("UTF-8"),
            "--force",
        ],
    );
    assert!(run.status.success(), "{name}: {}", stderr(&run));
    let text = std::fs::read_to_string(&summary).expect("summary");
    let json: serde_json::Value = serde_json::from_str(&text).expect("JSON summary");
    let pairing = &json["pairing"];
    let kinds = pairing["layout_kinds"].as_object().expect("layout kinds");
    assert_eq!(
        kinds.len(),
        1,
        "{name}: the layout varies by scan: {kinds:?}"
    );
    Some(pairing["layout"].clone())
}

#[test]
fn real_logs_name_their_layout() {
    let Some(dir) = real_data() else {
        eprintln!("SKIPPED: ../shared/real-data absent: the real-log layout checks did not run");
        return;
    };
    if let Some(kitti) = layout_of(&dir, "kitti-22-scans-lidar-only.mcap") {
        assert_eq!(kitti["rings"]["kind"], "laser_order", "{kitti}");
        assert_eq!(kitti["rings"]["direction"], "counter_clockwise", "{kitti}");
        assert_eq!(kitti["ring_count"], 64, "{kitti}");
        assert_eq!(kitti["times"]["kind"], "azimuth", "{kitti}");
        assert_eq!(kitti["times"]["direction"], "counter_clockwise", "{kitti}");
        // KITTI's measured convention: the sweep starts behind the car.
        let seam = kitti["times"]["seam_deg"].as_f64().expect("seam");
        assert!((seam - 180.0).abs() < 5.0, "{kitti}");
    }
    if let Some(ouster) = layout_of(&dir, "ouster_os0-8_10scans.mcap") {
        assert_eq!(ouster["rings"]["kind"], "organized", "{ouster}");
        assert_eq!(ouster["rings"]["rows"], 8, "{ouster}");
        assert_eq!(ouster["ring_count"], 8, "{ouster}");
        assert_eq!(ouster["times"]["kind"], "field", "{ouster}");
    }
    if let Some(hesai) = layout_of(&dir, "hesai_pandar64_jointcalib_10scans.mcap") {
        assert_eq!(hesai["rings"]["kind"], "field", "{hesai}");
        assert_eq!(hesai["rings"]["name"], "ring", "{hesai}");
        assert_eq!(hesai["ring_count"], 64, "{hesai}");
        assert_eq!(hesai["times"]["kind"], "field", "{hesai}");
        assert_eq!(hesai["times"]["name"], "timestamp", "{hesai}");
    }
}
