//! The fleet files a batch leaves in `OUT_DIR`, rebuilt from every log's
//! record on each run (so that a re-run with nothing new writes the same
//! bytes): `fleet.json` (one entry per log) and `near_misses.jsonl` /
//! `near_misses.csv` (every event of every log, ranked by minimum time to
//! contact).

use std::io::Write;
use std::path::{Path, PathBuf};

use serde::Serialize;

use crate::events::NearMissEvent;
use crate::output::AtomicFile;

use super::record::{FleetEntry, LogRecord};

pub const FLEET_JSON: &str = "fleet.json";
pub const NEAR_MISSES_JSONL: &str = "near_misses.jsonl";
pub const NEAR_MISSES_CSV: &str = "near_misses.csv";

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
}

/// Every near miss of `records`, ranked: smallest time to contact first,
/// ties by log, then start, then event id.
pub fn ranked_near_misses(records: &[LogRecord]) -> Vec<FleetNearMiss> {
    let mut all: Vec<(&FleetEntry, &NearMissEvent)> = records
        .iter()
        .flat_map(|r| r.near_misses.iter().map(move |e| (&r.entry, e)))
        .collect();
    all.sort_by(|(la, a), (lb, b)| {
        a.min_time_to_contact_s
            .total_cmp(&b.min_time_to_contact_s)
            .then_with(|| la.input.cmp(&lb.input))
            .then(a.start_ns.cmp(&b.start_ns))
            .then(a.id.cmp(&b.id))
    });
    all.into_iter()
        .enumerate()
        .map(|(i, (log, event))| FleetNearMiss {
            rank: i + 1,
            log: log.input.clone(),
            output: log.output.clone(),
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
        })
        .collect()
}

/// Write the three fleet files into `out_dir`, each whole or not at all.
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
    Ok(())
}

/// The ranking as CSV (paths quoted).
fn csv_text(near_misses: &[FleetNearMiss]) -> String {
    let mut text = String::from(
        "rank,log,output,event_id,start_log_time_ns,end_log_time_ns,duration_s,min_time_to_contact_s,peak_looming_per_s,range_m,bearing_deg,ego_speed_mps,moving\n",
    );
    let quoted = |path: &Path| format!("\"{}\"", path.display().to_string().replace('"', "\"\""));
    for n in near_misses {
        text.push_str(&format!(
            "{},{},{},{},{},{},{:.3},{:.3},{:.3},{:.2},{:.1},{},{}\n",
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
            n.moving
        ));
    }
    text
}
