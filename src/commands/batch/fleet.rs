//! The fleet files a batch leaves in `OUT_DIR`, rebuilt from every log's
//! record on each run (so that a re-run with nothing new writes the same
//! bytes): `fleet.json` (one entry per log), `near_misses.jsonl` /
//! `near_misses.csv` (every event of every log, ranked by minimum time to
//! contact), `near_miss_events.jsonl` (the same ranking as `foxglove.Event`
//! records) and `report.html` (`super::report`).

use std::io::Write;
use std::path::{Path, PathBuf};

use serde::Serialize;

use crate::annotate::foxglove::near_miss_metadata;
use crate::events::NearMissEvent;
use crate::output::AtomicFile;

use super::record::{FleetEntry, LogRecord};

pub const FLEET_JSON: &str = "fleet.json";
pub const NEAR_MISSES_JSONL: &str = "near_misses.jsonl";
pub const NEAR_MISSES_CSV: &str = "near_misses.csv";
pub const NEAR_MISS_EVENTS_JSONL: &str = "near_miss_events.jsonl";
pub const REPORT_HTML: &str = "report.html";
/// The Foxglove / Lichtblick layout for the fleet's annotated logs.
pub const LAYOUT_JSON: &str = "layout.json";

/// One near miss in the fleet ranking.
#[derive(Debug, Clone, Serialize)]
pub struct FleetNearMiss {
    pub rank: usize,
    pub log: PathBuf,
    pub output: Option<PathBuf>,
    pub event_id: u32,
    pub start_log_time_ns: u64,
    pub end_log_time_ns: u64,
    pub duration_s: f64,
    pub min_time_to_contact_s: f64,
    pub peak_looming_per_s: f64,
    pub range_m: f64,
    pub bearing_deg: f64,
    pub ego_speed_mps: Option<f64>,
    pub moving: bool,
    /// The range image and top view of its peak pair, relative to `OUT_DIR`
    /// (absent beyond a log's first [`super::MAX_PICTURED_EVENTS`]).
    pub range_picture: Option<PathBuf>,
    pub top_picture: Option<PathBuf>,
    /// Its clip (`--clips`), relative to `OUT_DIR`.
    #[serde(skip_serializing_if = "Option::is_none")]
    pub clip: Option<PathBuf>,
    /// The tracked object it was (`/looming/object_list` id in its output).
    #[serde(skip_serializing_if = "Option::is_none")]
    pub object_id: Option<u32>,
    /// Distance of that object (or of its cluster, on no object) from the
    /// vehicle's swept path at the peak, m.
    pub lateral_offset_m: f64,
    /// With several LiDARs: the sensors that saw it, the one whose view the
    /// figures are (and whose object list `object_id` is on) first.
    #[serde(default, skip_serializing_if = "Vec::is_empty")]
    pub sensors: Vec<String>,
}

/// Every near miss of `records`, ranked: smallest time to contact first,
/// ties by log, then start, then event id.
pub fn ranked_near_misses(records: &[LogRecord]) -> Vec<FleetNearMiss> {
    ranked_events(records)
        .into_iter()
        .enumerate()
        .map(|(i, (record, event))| {
            let pictures = record.pictures.iter().find(|p| p.event_id == event.id);
            FleetNearMiss {
                rank: i + 1,
                log: record.entry.input.clone(),
                output: record.entry.output.clone(),
                event_id: event.id,
                start_log_time_ns: event.start_log_time_ns,
                end_log_time_ns: event.end_log_time_ns,
                duration_s: event.duration_s,
                min_time_to_contact_s: event.min_time_to_contact_s,
                peak_looming_per_s: event.peak_looming_per_s,
                range_m: event.peak.range_m,
                bearing_deg: event.peak.azimuth_deg,
                ego_speed_mps: event.peak.ego_speed_mps,
                moving: event.moving,
                range_picture: pictures.map(|p| p.range_png.clone()),
                top_picture: pictures.map(|p| p.top_png.clone()),
                clip: record
                    .clips
                    .iter()
                    .find(|c| c.event_id == event.id)
                    .map(|c| c.path.clone()),
                object_id: event.object_id,
                lateral_offset_m: event.peak.lateral_offset_m,
                sensors: sensors_best_first(event),
            }
        })
        .collect()
}

/// Every event of `records` with its log's record, in rank order.
fn ranked_events(records: &[LogRecord]) -> Vec<(&LogRecord, &NearMissEvent)> {
    let mut all: Vec<(&LogRecord, &NearMissEvent)> = records
        .iter()
        .flat_map(|r| r.near_misses.iter().map(move |e| (r, e)))
        .collect();
    all.sort_by(|(ra, a), (rb, b)| {
        let (la, lb) = (&ra.entry, &rb.entry);
        a.min_time_to_contact_s
            .total_cmp(&b.min_time_to_contact_s)
            .then_with(|| la.input.cmp(&lb.input))
            .then(a.start_ns.cmp(&b.start_ns))
            .then(a.id.cmp(&b.id))
    });
    all
}

/// Write the fleet files into `out_dir`, each whole or not at all.
pub fn write_fleet_files(out_dir: &Path, records: &[LogRecord]) -> std::io::Result<()> {
    let entries: Vec<&FleetEntry> = records.iter().map(|r| &r.entry).collect();
    let mut fleet = AtomicFile::create(&out_dir.join(FLEET_JSON))?;
    serde_json::to_writer_pretty(&mut fleet, &entries)?;
    fleet.commit()?;
    let near_misses = ranked_near_misses(records);
    let mut jsonl = AtomicFile::create(&out_dir.join(NEAR_MISSES_JSONL))?;
    for near_miss in &near_misses {
        serde_json::to_writer(&mut jsonl, near_miss)?;
        jsonl.write_all(b"\n")?;
    }
    jsonl.commit()?;
    let mut csv = AtomicFile::create(&out_dir.join(NEAR_MISSES_CSV))?;
    csv.write_all(csv_text(&near_misses).as_bytes())?;
    csv.commit()?;
    let mut spans = AtomicFile::create(&out_dir.join(NEAR_MISS_EVENTS_JSONL))?;
    for (rank, (record, event)) in ranked_events(records).into_iter().enumerate() {
        serde_json::to_writer(&mut spans, &foxglove_event(rank + 1, record, event))?;
        spans.write_all(b"\n")?;
    }
    spans.commit()?;
    let mut report = AtomicFile::create(&out_dir.join(REPORT_HTML))?;
    report.write_all(super::report::report_html(records, &near_misses).as_bytes())?;
    report.commit()?;
    if let Some(target) = fleet_layout_target(records) {
        crate::commands::layout::write_layout(&out_dir.join(LAYOUT_JSON), &target)
            .map_err(std::io::Error::other)?;
    }
    Ok(())
}

/// The layout for the fleet: the LiDAR frame most of its annotated logs
/// use (ties: the first in name order); none without an annotated log.
fn fleet_layout_target(records: &[LogRecord]) -> Option<crate::commands::layout::LayoutTarget> {
    let mut counts: std::collections::BTreeMap<&str, usize> = Default::default();
    for frame in records
        .iter()
        .filter_map(|r| r.entry.lidar_frame.as_deref())
    {
        *counts.entry(frame).or_default() += 1;
    }
    let most = counts.values().copied().max()?;
    let frame = counts.into_iter().find(|&(_, n)| n == most)?.0;
    Some(crate::commands::layout::LayoutTarget {
        frame_id: frame.to_owned(),
        lidar_topic: None,
        frame_from: "the fleet's annotated logs".into(),
        sensors: Vec::new(),
    })
}

/// A near miss as a `foxglove.Event` in its JSON form (the schema's field
/// names, `Timestamp` as `sec` / `nsec`), its metadata that of the event's
/// `/looming/near_misses` message plus where it is in the fleet.
fn foxglove_event(rank: usize, record: &LogRecord, event: &NearMissEvent) -> serde_json::Value {
    let time = |ns: i64| {
        serde_json::json!({
            "sec": ns.div_euclid(1_000_000_000),
            "nsec": ns.rem_euclid(1_000_000_000),
        })
    };
    let mut metadata = vec![
        ("rank", rank.to_string()),
        ("log", record.entry.input.display().to_string()),
    ];
    if let Some(output) = &record.entry.output {
        metadata.push(("output", output.display().to_string()));
    }
    metadata.extend(near_miss_metadata(event));
    let metadata: Vec<serde_json::Value> = metadata
        .into_iter()
        .map(|(key, value)| serde_json::json!({"key": key, "value": value}))
        .collect();
    serde_json::json!({
        "start_time": time(event.start_ns),
        "end_time": time(event.end_ns),
        "metadata": metadata,
    })
}

/// An event's sensors, the one with the best view first.
fn sensors_best_first(event: &crate::events::NearMissEvent) -> Vec<String> {
    let mut sensors = event.sensors.clone();
    if let Some(best) = &event.sensor {
        sensors.retain(|s| s != best);
        sensors.insert(0, best.clone());
    }
    sensors
}

/// The ranking as CSV (paths quoted).
fn csv_text(near_misses: &[FleetNearMiss]) -> String {
    let mut text = String::from(
        "rank,log,output,event_id,start_log_time_ns,end_log_time_ns,duration_s,min_time_to_contact_s,peak_looming_per_s,range_m,bearing_deg,ego_speed_mps,moving,range_picture,top_picture,clip,object_id,lateral_offset_m,sensors\n",
    );
    let quoted = |path: &Path| format!("\"{}\"", path.display().to_string().replace('"', "\"\""));
    for n in near_misses {
        text.push_str(&format!(
            "{},{},{},{},{},{},{:.3},{:.3},{:.3},{:.2},{:.1},{},{},{},{},{},{},{:.2},{}\n",
            n.rank,
            quoted(&n.log),
            n.output.as_deref().map_or(String::new(), quoted),
            n.event_id,
            n.start_log_time_ns,
            n.end_log_time_ns,
            n.duration_s,
            n.min_time_to_contact_s,
            n.peak_looming_per_s,
            n.range_m,
            n.bearing_deg,
            n.ego_speed_mps.map_or(String::new(), |v| format!("{v:.2}")),
            n.moving,
            n.range_picture.as_deref().map_or(String::new(), quoted),
            n.top_picture.as_deref().map_or(String::new(), quoted),
            n.clip.as_deref().map_or(String::new(), quoted),
            n.object_id.map_or(String::new(), |id| id.to_string()),
            n.lateral_offset_m,
            // Space-separated: sensor names hold no space or comma.
            n.sensors.join(" "),
        ));
    }
    text
}
