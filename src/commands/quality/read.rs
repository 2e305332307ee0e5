//! Reading an annotated log: the `quality` figures of every `/looming/pairs`
//! message, and the number of `/looming/events` messages.

use std::path::Path;

use serde::Deserialize;

use super::QualityError;
use super::report::QualityReport;
use super::totals::Builder;
use crate::annotate::topics::{EVENTS_TOPIC, PAIRS_TOPIC};
use crate::commands::annotated::read_json_channel;
use crate::input::{InputFile, InputOptions};
use crate::quality::PairQuality;

/// What `quality` reads of a `/looming/pairs` message (unknown fields, such
/// as those of other tool versions, are ignored).
#[derive(Debug, Deserialize)]
pub(super) struct PairMessage {
    pub(super) index: u64,
    pub(super) current: CurrentScan,
    #[serde(default)]
    pub(super) speed_mps: Option<f64>,
    #[serde(default)]
    pub(super) quality: Option<PairQuality>,
}

#[derive(Debug, Deserialize)]
pub(super) struct CurrentScan {
    pub(super) stamp_ns: i64,
    pub(super) log_time_ns: u64,
    #[serde(default)]
    pub(super) layout: Option<serde_json::Value>,
}

/// How rings and per-point times were obtained, as `/looming/pairs` records it
/// (`current.layout`); "unknown" when it does not.
pub(super) fn layout_text(layout: Option<&serde_json::Value>) -> String {
    match layout {
        None | Some(serde_json::Value::Null) => "unknown".into(),
        Some(serde_json::Value::String(s)) => s.clone(),
        // The record's own words, as the run summary printed them.
        Some(serde_json::Value::Object(fields)) => match fields.get("description") {
            Some(serde_json::Value::String(s)) => s.clone(),
            _ => serde_json::Value::Object(fields.clone()).to_string(),
        },
        Some(other) => other.to_string(),
    }
}

/// Read an annotated log and sum its quality figures.
pub fn read_quality(path: &Path) -> Result<QualityReport, QualityError> {
    let input = InputFile::open(path, InputOptions::default())?;
    let name = path.display().to_string();
    let channels = &input.catalog().channels;
    let pairs_channel = channels
        .values()
        .find(|c| c.topic == PAIRS_TOPIC)
        .map(|c| c.id)
        .ok_or_else(|| QualityError::NotProcessed { path: name.clone() })?;
    let events_channel = channels
        .values()
        .find(|c| c.topic == EVENTS_TOPIC)
        .map(|c| c.id);
    let mut builder = Builder::default();
    let mut events = 0u64;
    read_json_channel(
        &input,
        pairs_channel,
        &mut |pair: PairMessage| builder.add(pair),
        &mut |channel| events += u64::from(Some(channel) == events_channel),
    )?
    .map_err(|bad| QualityError::BadRecord {
        path: name.clone(),
        log_time_ns: bad.log_time_ns,
        reason: bad.reason,
    })?;
    builder.count_events(events);
    Ok(builder.finish(name))
}
