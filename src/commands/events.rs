//! `looming events`: the near-miss events of an annotated log.

use std::path::Path;

use super::annotated::read_json_channel;
use crate::input::{InputError, InputFile, InputOptions};

use crate::events::NearMissEvent;

#[derive(Debug, thiserror::Error)]
pub enum ListingError {
    #[error(transparent)]
    Input(#[from] InputError),
    #[error("{path}: no /looming/events channel: not written by `looming process` (run it first)")]
    NotAnnotated { path: String },
    #[error("{path}: /looming/events message at log time {log_time_ns}: {reason}")]
    BadEvent {
        path: String,
        log_time_ns: u64,
        reason: String,
    },
}

/// Every event of `/looming/events`, in file order.
pub fn read_events(path: &Path) -> Result<Vec<NearMissEvent>, ListingError> {
    let input = InputFile::open(path, InputOptions::default())?;
    let name = path.display().to_string();
    let channel = input
        .catalog()
        .channels
        .values()
        .find(|c| c.topic == crate::annotate::EVENTS_TOPIC)
        .map(|c| c.id)
        .ok_or_else(|| ListingError::NotAnnotated { path: name.clone() })?;
    let mut events = Vec::new();
    read_json_channel(
        &input,
        channel,
        &mut |event| events.push(event),
        &mut |_| {},
    )?
    .map_err(|bad| ListingError::BadEvent {
        path: name,
        log_time_ns: bad.log_time_ns,
        reason: bad.reason,
    })?;
    Ok(events)
}

/// The events as a table, one line each.
pub fn events_table(events: &[NearMissEvent]) -> String {
    use std::fmt::Write as _;
    let mut out = String::new();
    if events.is_empty() {
        out.push_str("no near-miss events\n");
        return out;
    }
    let _ = writeln!(
        out,
        "{:>4}  {:>22}  {:>7}  {:>8}  {:>8}  {:>8}  {:>8}  {:>7}  {:>6}  {:>7}  {:>6}  {:>6}",
        "id",
        "start (log time)",
        "dur s",
        "min TTC",
        "L 1/s",
        "az deg",
        "range m",
        "lat m",
        "moving",
        "ego m/s",
        "cells",
        "object"
    );
    for e in events {
        let _ = writeln!(
            out,
            "{:>4}  {:>22}  {:>7.2}  {:>8.2}  {:>8.3}  {:>8.1}  {:>8.1}  {:>7.2}  {:>6}  {:>7}  {:>6}  {:>6}",
            e.id,
            crate::model::format_log_time(e.start_log_time_ns),
            e.duration_s,
            e.min_time_to_contact_s,
            e.peak_looming_per_s,
            e.peak.azimuth_deg,
            e.peak.range_m,
            e.peak.lateral_offset_m,
            if e.moving { "yes" } else { "no" },
            e.peak
                .ego_speed_mps
                .map_or("-".into(), |v| format!("{v:.1}")),
            e.max_cluster_cells,
            e.object_id.map_or("-".into(), |id| id.to_string())
        );
    }
    out
}
