//! Reading an annotated log: the `quality` figures of every `/looming/pairs`
//! message, and the number of `/looming/events` messages.

use std::path::Path;

use serde::Deserialize;

use super::QualityError;
use super::diagnose::diagnose_sensors;
use super::report::QualityReport;
use super::totals::Builder;
use crate::annotate::topics::{EVENTS_TOPIC, sensor_of_pairs_topic};
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
    /// Where the extrinsics to the motion sources came from.
    #[serde(default)]
    pub(super) extrinsic: Option<ExtrinsicSeen>,
}

/// The pair record's `extrinsic`: `cli`, `tf_static`, `same_frame` or
/// `identity_assumed` per motion source.
#[derive(Debug, Default, Deserialize)]
pub(super) struct ExtrinsicSeen {
    #[serde(default)]
    velocity: Option<String>,
    #[serde(default)]
    imu: Option<String>,
}

impl ExtrinsicSeen {
    /// Neither source has a transform to the LiDAR: identity was assumed.
    fn assumed(&self) -> bool {
        let assumed = |s: &Option<String>| s.as_deref() == Some("identity_assumed");
        (assumed(&self.velocity) || self.velocity.is_none())
            && (assumed(&self.imu) || self.imu.is_none())
            && (self.velocity.is_some() || self.imu.is_some())
    }
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

/// Read an annotated log and sum its quality figures. On a log with
/// several LiDARs, the first sensor's report carrying every sensor's in
/// `sensors`.
pub fn read_quality(path: &Path) -> Result<QualityReport, QualityError> {
    let mut reports = read_sensor_qualities(path)?;
    if reports.len() == 1 {
        return Ok(reports.remove(0));
    }
    let mut report = reports[0].clone();
    report.sensors = reports;
    Ok(report)
}

/// The quality of each LiDAR of an annotated log: one report (sensor
/// `None`) for `/looming/pairs`, or one per `/looming/<sensor>/pairs` on a
/// log with several LiDARs. The log's near misses count in each.
pub fn read_sensor_qualities(path: &Path) -> Result<Vec<QualityReport>, QualityError> {
    let input = InputFile::open(path, InputOptions::default())?;
    let name = path.display().to_string();
    let channels = &input.catalog().channels;
    let mut pairs_channels: Vec<(Option<String>, u16)> = channels
        .values()
        .filter_map(|c| sensor_of_pairs_topic(&c.topic).map(|sensor| (sensor, c.id)))
        .collect();
    pairs_channels.sort_by_key(|(_, id)| *id);
    if pairs_channels.is_empty() {
        return Err(QualityError::NotProcessed { path: name });
    }
    let events_channel = channels
        .values()
        .find(|c| c.topic == EVENTS_TOPIC)
        .map(|c| c.id);
    let mut reports = Vec::new();
    let mut extrinsic_assumed = Vec::new();
    for (sensor, pairs_channel) in pairs_channels {
        let (mut report, assumed) = read_pairs(&input, &name, pairs_channel, events_channel)?;
        report.sensor = sensor;
        reports.push(report);
        extrinsic_assumed.push(assumed);
    }
    if reports.len() > 1 {
        diagnose_sensors(&mut reports, &extrinsic_assumed);
    }
    Ok(reports)
}

/// One pairs channel's figures, and how many of its pairs had no transform
/// to their motion sources (identity assumed).
fn read_pairs(
    input: &InputFile,
    name: &str,
    pairs_channel: u16,
    events_channel: Option<u16>,
) -> Result<(QualityReport, u64), QualityError> {
    let mut builder = Builder::default();
    let mut events = 0u64;
    let mut assumed = 0u64;
    read_json_channel(
        input,
        pairs_channel,
        &mut |pair: PairMessage| {
            assumed += u64::from(pair.extrinsic.as_ref().is_some_and(ExtrinsicSeen::assumed));
            builder.add(pair);
        },
        &mut |channel| events += u64::from(Some(channel) == events_channel),
    )?
    .map_err(|bad| QualityError::BadRecord {
        path: name.to_owned(),
        log_time_ns: bad.log_time_ns,
        reason: bad.reason,
    })?;
    builder.count_events(events);
    Ok((builder.finish(name.to_owned()), assumed))
}
