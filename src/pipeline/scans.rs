//! How a log's messages become scan pairs, in one place for `process`,
//! `eval` and `render`: the options they share ([`ScanOptions`]), the
//! decoder of the selected topics (a failure is a [`BadMessage`], skipped and
//! counted, fatal with `strict`) and the pairing stage that counts what was
//! decoded and feeds the pairer.

use std::collections::{BTreeMap, HashMap};

use crate::decode::{self, DecodeLimits};
use crate::input::{Catalog, InputError, InputOptions, ReadReport};
use crate::model::{Decoded, ScanPair, format_log_time};
use crate::pairing::split::split_by_sensor;
use crate::pairing::stride::Strider;
use crate::pairing::{PairEvent, PairingConfig, PairingStats, ScanPairer};
use crate::topics::{Role, SelectedChannel, TopicOverrides, TopicSelection};

use super::split::MergedRoute;

/// How a log is read, decoded and paired: the options `process`, `eval`
/// and `render` share, so that all three see the same scan pairs.
#[derive(Debug, Clone, Default, serde::Serialize)]
pub struct ScanOptions {
    pub input_options: InputOptions,
    pub topics: TopicOverrides,
    /// The pairer's settings; whether a velocity and an IMU source exist is
    /// set from each log's topics.
    pub pairing: PairingConfig,
    #[serde(skip)]
    pub decode_limits: DecodeLimits,
    /// Any bad input message, or chunk CRC mismatch, fails the run.
    pub strict: bool,
}

/// A bad input message: skipped and counted (fatal with `--strict`).
#[derive(Debug, Clone, serde::Serialize)]
pub struct BadMessage {
    pub file: String,
    pub topic: String,
    pub log_time_ns: u64,
    pub reason: String,
}

impl std::fmt::Display for BadMessage {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        write!(
            f,
            "{}: topic {} at log time {} ({}): {}",
            self.file,
            self.topic,
            self.log_time_ns,
            format_log_time(self.log_time_ns),
            self.reason
        )
    }
}

/// Messages decoded per role.
#[derive(Debug, Clone, Default, serde::Serialize)]
pub struct DecodedCounts {
    pub scans: u64,
    pub lidar_points: u64,
    pub invalid_points_skipped: u64,
    pub imu: u64,
    pub velocity: u64,
    pub tf_messages: u64,
}

const BAD_MESSAGE_EXAMPLES: usize = 20;

/// How a read ended short of a report.
#[derive(Debug)]
pub(crate) enum ReadFailure {
    Input(InputError),
    /// `strict`: a bad message, a bad chunk or a truncated file.
    Strict(String),
}

/// The end of a read: under `strict`, the bad message that stopped it
/// (`strict_failure`), a bad chunk CRC and a truncated file are failures.
pub(crate) fn finish_read(
    strict: bool,
    file_name: &str,
    strict_failure: Option<BadMessage>,
    result: Result<ReadReport, InputError>,
) -> Result<ReadReport, ReadFailure> {
    if let Some(bad) = strict_failure {
        return Err(ReadFailure::Strict(bad.to_string()));
    }
    let report = result.map_err(|error| match error {
        InputError::BadChunk { .. } if strict => ReadFailure::Strict(error.to_string()),
        error => ReadFailure::Input(error),
    })?;
    match &report.truncated {
        Some(reason) if strict => Err(ReadFailure::Strict(format!("{file_name}: {reason}"))),
        _ => Ok(report),
    }
}

/// A decoded message: its log time, its channel and what it holds.
pub(crate) type DecodeResult = Result<(u64, u16, Decoded), BadMessage>;

/// Decodes the messages of the selected topics.
pub(crate) struct Decoder<'a> {
    limits: &'a DecodeLimits,
    by_channel: HashMap<u16, &'a SelectedChannel>,
    file_name: String,
}

impl<'a> Decoder<'a> {
    /// The decoder of every channel the `sensors`' selections name.
    pub(crate) fn new(
        options: &'a ScanOptions,
        sensors: &'a [TopicSelection],
        file_name: &str,
    ) -> Self {
        Self {
            limits: &options.decode_limits,
            by_channel: sensors
                .iter()
                .flat_map(TopicSelection::all)
                .map(|c| (c.channel_id, c))
                .collect(),
            file_name: file_name.to_owned(),
        }
    }

    /// The message decoded, when its channel is selected.
    pub(crate) fn decode(
        &self,
        channel_id: u16,
        log_time_ns: u64,
        data: &[u8],
    ) -> Option<DecodeResult> {
        let channel = self.by_channel.get(&channel_id)?;
        let is_static = channel.role == Role::TfStatic;
        let decoded = decode::decode(channel.kind, channel.encoding, is_static, data, self.limits);
        Some(
            decoded
                .map(|decoded| (log_time_ns, channel_id, decoded))
                .map_err(|err| BadMessage {
                    file: self.file_name.clone(),
                    topic: channel.topic.clone(),
                    log_time_ns,
                    reason: err.to_string(),
                }),
        )
    }
}

/// Bad messages: how many, per topic, and the first few in full.
#[derive(Debug, Clone, Default, serde::Serialize)]
pub struct BadMessages {
    pub count: u64,
    pub by_topic: BTreeMap<String, u64>,
    pub examples: Vec<BadMessage>,
}

impl BadMessages {
    pub(crate) fn add(&mut self, bad: BadMessage) {
        self.count += 1;
        *self.by_topic.entry(bad.topic.clone()).or_default() += 1;
        if self.examples.len() < BAD_MESSAGE_EXAMPLES {
            self.examples.push(bad);
        }
    }
}

/// The pairing side of the decode-and-pair loop: counts what was decoded and
/// what failed, feeds the pairer and keeps its warnings.
pub(crate) struct PairingStage {
    pairer: ScanPairer,
    /// The pairer's pairs joined to span the shortest baseline.
    strider: Strider,
    pub(crate) decoded: DecodedCounts,
    pub(crate) bad: BadMessages,
    pub(crate) warnings: Vec<String>,
}

impl PairingStage {
    /// A pairer for the log whose catalog and selected topics are given.
    pub(crate) fn new(options: &ScanOptions, catalog: &Catalog, topics: &TopicSelection) -> Self {
        let mut pairer = ScanPairer::new(PairingConfig {
            has_velocity_source: topics.velocity.is_some(),
            has_imu_source: topics.imu.is_some(),
            ..options.pairing.clone()
        });
        // A merged channel's rate is its sensors' together: each sensor's
        // period is found from its own stamps.
        if let (Some(lidar), None) = (&topics.lidar, &topics.merged) {
            pairer.set_nominal_period_s(catalog.nominal_period_s(lidar.channel_id));
        }
        Self {
            pairer,
            strider: Strider::new(options.pairing.min_baseline_s),
            decoded: DecodedCounts::default(),
            bad: BadMessages::default(),
            warnings: Vec::new(),
        }
    }

    /// A decoded message in; the pairs it completes out, in order.
    pub(crate) fn push(&mut self, log_time_ns: u64, decoded: Decoded) -> Vec<ScanPair> {
        let events = feed(&mut self.pairer, &mut self.decoded, log_time_ns, decoded);
        self.pairs(events)
    }

    /// The end of the log: the pairs still held.
    pub(crate) fn finish(&mut self) -> Vec<ScanPair> {
        let events = self.pairer.finish();
        self.pairs(events)
    }

    pub(crate) fn stats(&self) -> &PairingStats {
        self.pairer.stats()
    }

    /// The static transforms the pairer received.
    pub(crate) fn transforms(&self) -> &crate::pairing::TransformTree {
        self.pairer.transforms()
    }

    fn pairs(&mut self, events: Vec<PairEvent>) -> Vec<ScanPair> {
        let mut pairs = Vec::new();
        for event in events {
            match event {
                PairEvent::Pair(pair) => pairs.push(self.strider.push(pair)),
                PairEvent::Warning(warning) => self.warnings.push(warning),
            }
        }
        pairs
    }
}

/// The pairing stages of a log's LiDAR sensors: each sensor's scans go to
/// its own pairer (sensors out of step, at other rates or with dropouts, are
/// paired independently); the motion and transform messages they share go
/// to every pairer.
pub(crate) struct SensorPairing {
    stages: Vec<PairingStage>,
    /// The LiDAR channel of each stage.
    lidar_channels: Vec<u16>,
    /// The channels whose clouds merge several sensors, split among stages.
    merged: BTreeMap<u16, MergedRoute>,
    pub(crate) bad: BadMessages,
}

impl SensorPairing {
    pub(crate) fn new(
        options: &ScanOptions,
        catalog: &Catalog,
        sensors: &[TopicSelection],
    ) -> Self {
        Self {
            stages: sensors
                .iter()
                .map(|topics| PairingStage::new(options, catalog, topics))
                .collect(),
            lidar_channels: sensors
                .iter()
                .map(|topics| topics.lidar.as_ref().map_or(u16::MAX, |c| c.channel_id))
                .collect(),
            merged: MergedRoute::of(sensors),
            bad: BadMessages::default(),
        }
    }

    /// A decoded message of `channel_id` in; the pairs it completes out, with
    /// the index of their sensor.
    pub(crate) fn push(
        &mut self,
        log_time_ns: u64,
        channel_id: u16,
        decoded: Decoded,
    ) -> Vec<(usize, ScanPair)> {
        if let Decoded::Scan(scan) = &decoded
            && let Some(route) = self.merged.get_mut(&channel_id)
        {
            let split = split_by_sensor(scan, &route.ids());
            route.note(&split);
            let mut pairs = Vec::new();
            for (part, &(_, sensor)) in split.scans.into_iter().zip(&route.sensors) {
                if let Some(part) = part {
                    let stage = &mut self.stages[sensor];
                    pairs.extend(tagged(sensor, stage.push(log_time_ns, Decoded::Scan(part))));
                }
            }
            return pairs;
        }
        if let Decoded::Scan(_) = decoded {
            let Some(sensor) = self.lidar_channels.iter().position(|&c| c == channel_id) else {
                return Vec::new();
            };
            return tagged(sensor, self.stages[sensor].push(log_time_ns, decoded));
        }
        let last = self.stages.len().saturating_sub(1);
        let mut pairs = Vec::new();
        let mut decoded = Some(decoded);
        for (sensor, stage) in self.stages.iter_mut().enumerate() {
            // The last stage takes the message itself; the others a copy.
            let message = if sensor == last {
                decoded.take()
            } else {
                decoded.clone()
            };
            if let Some(message) = message {
                pairs.extend(tagged(sensor, stage.push(log_time_ns, message)));
            }
        }
        pairs
    }

    /// The end of the log: the pairs every sensor still holds.
    pub(crate) fn finish(&mut self) -> Vec<(usize, ScanPair)> {
        let mut pairs = Vec::new();
        for (sensor, stage) in self.stages.iter_mut().enumerate() {
            pairs.extend(tagged(sensor, stage.finish()));
        }
        pairs
    }

    pub(crate) fn stages(&self) -> &[PairingStage] {
        &self.stages
    }

    /// What the merged channels' splits left over.
    pub(crate) fn merged_warnings(&self) -> Vec<String> {
        self.merged
            .values()
            .flat_map(MergedRoute::warnings)
            .collect()
    }

    /// What was decoded over all sensors: each sensor's scans, the shared
    /// messages once.
    pub(crate) fn decoded(&self) -> DecodedCounts {
        let mut counts = self
            .stages
            .first()
            .map(|s| s.decoded.clone())
            .unwrap_or_default();
        for stage in self.stages.iter().skip(1) {
            counts.scans += stage.decoded.scans;
            counts.lidar_points += stage.decoded.lidar_points;
            counts.invalid_points_skipped += stage.decoded.invalid_points_skipped;
        }
        counts
    }
}

fn tagged(sensor: usize, pairs: Vec<ScanPair>) -> Vec<(usize, ScanPair)> {
    pairs.into_iter().map(|pair| (sensor, pair)).collect()
}

fn feed(
    pairer: &mut ScanPairer,
    counts: &mut DecodedCounts,
    log_time_ns: u64,
    decoded: Decoded,
) -> Vec<PairEvent> {
    match &decoded {
        Decoded::Scan(scan) => {
            counts.scans += 1;
            counts.lidar_points += scan.points_m.len() as u64;
            counts.invalid_points_skipped += u64::from(scan.skipped_invalid_points);
        }
        Decoded::Imu(_) => counts.imu += 1,
        Decoded::Velocity(_) => counts.velocity += 1,
        Decoded::Transforms { .. } => counts.tf_messages += 1,
    }
    pairer.push_decoded(log_time_ns, decoded)
}
