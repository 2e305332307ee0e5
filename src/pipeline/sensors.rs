//! The annotation side of `process` for one LiDAR or several: our channels
//! registered per sensor (docs/channels.md, "Several LiDARs"), each sensor's
//! pairs annotated by its own annotator, the sensors' near misses merged into
//! the log's one list at the end, and what the pairing stage reports.

use std::sync::mpsc::SyncSender;

use crate::annotate::pairs::{PairRecord, pairs_channel_spec};
use crate::annotate::topics::{PAIRS_TOPIC, sensor_topic};
use crate::annotate::{
    AnnotateStats, Annotated, Annotator, EventWriter, OwnMessage, channel_specs,
    event_channel_specs, sensor_channel_ids, sensor_channel_specs,
};
use crate::events::{NearMissEvent, SensorEvents, merge_sensor_events};
use crate::model::{ExtrinsicSource, ScanPair};
use crate::output::OutputWriter;
use crate::pairing::PairingStats;
use crate::pairing::TransformTree;
use crate::topics::{MergedSensor, TopicSelection, selection_names};
use nalgebra::Isometry3;

use super::scans::{BadMessages, DecodedCounts, SensorPairing};
use super::stages::ToWriter;
use super::{ProcessConfig, ProcessError};

/// Our channels in the output, and the annotators that fill them: one per
/// LiDAR sensor.
pub(super) struct Annotation {
    sensors: Vec<SensorAnnotation>,
    /// With several LiDARs, the log's one set of event channels, written
    /// when the sensors' events are merged at the end.
    merged_events: Option<EventWriter>,
}

/// One sensor's annotator and channels.
struct SensorAnnotation {
    name: String,
    topic: String,
    /// Its value in its topic's sensor field, for a merged cloud's sensor.
    merged: Option<MergedSensor>,
    annotator: Annotator,
    pairs_channel: u16,
    pairs_written: u64,
    /// Where the sensor sits on the vehicle (from the extrinsic of its
    /// pairs' motion source), for merging events.
    vehicle_from_sensor: Option<(String, nalgebra::Isometry3<f64>)>,
    /// The frame its points are posed in and their pose there (its first
    /// pair's, `pairing::origin::extrinsic_frame`; a world-frame cloud's is
    /// its named sensor frame, the same in every pair): where `/tf_static`
    /// can place it when no motion source does.
    frame: Option<(String, nalgebra::Isometry3<f64>)>,
}

/// Registers our channels: as always with one LiDAR; with several, the
/// log's event channels and then each sensor's channels under its name
/// (docs/channels.md, "Several LiDARs").
pub(super) fn add_own_channels(
    writer: &mut OutputWriter,
    config: &ProcessConfig,
    sensors: &[TopicSelection],
) -> Result<Annotation, ProcessError> {
    let topics: Vec<&str> = sensors
        .iter()
        .filter_map(|t| t.lidar.as_ref().map(|c| c.topic.as_str()))
        .collect();
    let names = selection_names(sensors);
    let merged: Vec<Option<MergedSensor>> = sensors.iter().map(|t| t.merged.clone()).collect();
    let register = |writer: &mut OutputWriter, specs: Vec<crate::output::OwnChannelSpec>| {
        specs
            .iter()
            .map(|spec| writer.add_own_channel(spec))
            .collect::<Result<Vec<u16>, _>>()
    };
    let sensor = |k: usize, annotator, pairs_channel| SensorAnnotation {
        name: names[k].clone(),
        topic: topics[k].to_owned(),
        merged: merged[k].clone(),
        annotator,
        pairs_channel,
        pairs_written: 0,
        vehicle_from_sensor: None,
        frame: None,
    };
    // A merged cloud's sensors are named by their value even when one.
    if names.len() == 1 && merged[0].is_none() {
        let pairs_channel = writer.add_own_channel(&pairs_channel_spec())?;
        let ids = register(writer, channel_specs())?;
        let annotator = Annotator::new(config.annotate.clone(), &ids);
        return Ok(Annotation {
            sensors: vec![sensor(0, annotator, pairs_channel)],
            merged_events: None,
        });
    }
    let event_ids = register(writer, event_channel_specs())?;
    let mut annotations = Vec::new();
    for (k, name) in names.iter().enumerate() {
        let mut pairs_spec = pairs_channel_spec();
        pairs_spec.topic = sensor_topic(name, PAIRS_TOPIC);
        let pairs_channel = writer.add_own_channel(&pairs_spec)?;
        let ids = register(writer, sensor_channel_specs(name))?;
        let annotator = Annotator::new(
            config.annotate.clone(),
            &sensor_channel_ids(&ids, &event_ids),
        )
        .hold_events();
        annotations.push(sensor(k, annotator, pairs_channel));
    }
    Ok(Annotation {
        sensors: annotations,
        merged_events: Some(EventWriter::new(&event_ids)),
    })
}

/// What the pairing stage saw.
pub(crate) struct PairingOutcome {
    pub(super) decoded: DecodedCounts,
    /// The first sensor's pairing figures (the only one's, most often).
    pub(super) stats: PairingStats,
    pub(super) pairs_written: u64,
    pub(super) bad: BadMessages,
    pub(super) warnings: Vec<String>,
    /// Summed over the sensors.
    pub(super) annotation: AnnotateStats,
    /// One list for the log (with several LiDARs, the sensors' merged).
    pub(super) events: Vec<NearMissEvent>,
    /// Per sensor, with several LiDARs (empty with one).
    pub(super) sensors: Vec<SensorOutcome>,
}

/// One sensor's figures on a log with several LiDARs.
#[derive(Debug, Clone, serde::Serialize)]
pub struct SensorOutcome {
    /// Its name in our channels' topics (`/looming/<name>/points`).
    pub name: String,
    pub topic: String,
    /// The sensor field and value that single it out of its topic's
    /// merged clouds; absent for a topic of its own.
    #[serde(skip_serializing_if = "Option::is_none")]
    pub merged: Option<MergedSensor>,
    pub pairs_written: u64,
    pub pairing: PairingStats,
    pub annotation: AnnotateStats,
    /// The frame its events were merged in (its motion source's, or on a
    /// LiDAR-only log the first sensor's through `/tf_static`); absent when
    /// no transform places it (its events stand alone).
    #[serde(skip_serializing_if = "Option::is_none")]
    pub vehicle_frame: Option<String>,
}

/// The pairing stage's figures at the end of the log.
pub(super) fn outcome(
    stage: &SensorPairing,
    annotation: Option<&Annotation>,
    events: Vec<NearMissEvent>,
) -> PairingOutcome {
    let stages = stage.stages();
    let several = stages.len() > 1 || annotation.is_some_and(|a| a.merged_events.is_some());
    let mut warnings = Vec::new();
    for (k, sensor_stage) in stages.iter().enumerate() {
        let label = annotation
            .and_then(|a| a.sensors.get(k))
            .map(|s| match &s.merged {
                Some(merged) => format!("{} ({} {})", s.topic, merged.field, merged.id),
                None => s.topic.clone(),
            });
        for warning in &sensor_stage.warnings {
            warnings.push(match &label {
                Some(label) if several => format!("{label}: {warning}"),
                _ => warning.clone(),
            });
        }
    }
    warnings.extend(stage.merged_warnings());
    let mut stats = AnnotateStats::default();
    let mut sensors = Vec::new();
    for (k, sensor) in annotation
        .map_or(&[][..], |a| &a.sensors[..])
        .iter()
        .enumerate()
    {
        stats.absorb(sensor.annotator.stats());
        if several {
            sensors.push(SensorOutcome {
                name: sensor.name.clone(),
                topic: sensor.topic.clone(),
                merged: sensor.merged.clone(),
                pairs_written: sensor.pairs_written,
                pairing: stages[k].stats().clone(),
                annotation: sensor.annotator.stats().clone(),
                vehicle_frame: sensor.vehicle_from_sensor.as_ref().map(|v| v.0.clone()),
            });
        }
    }
    stats.events = events.len() as u64;
    PairingOutcome {
        stats: stages
            .first()
            .map(|s| s.stats().clone())
            .unwrap_or_default(),
        decoded: stage.decoded(),
        pairs_written: annotation.map_or(0, |a| a.sensors.iter().map(|s| s.pairs_written).sum()),
        bad: stage.bad.clone(),
        warnings,
        annotation: stats,
        events,
        sensors,
    }
}

impl Annotation {
    /// Send the pairers' pairs on, annotated by their sensor's annotator;
    /// false when the writer has gone.
    pub(super) fn emit(
        &mut self,
        pairs: Vec<(usize, ScanPair)>,
        tx: &SyncSender<ToWriter>,
    ) -> bool {
        for (sensor, pair) in pairs {
            let Some(sensor) = self.sensors.get_mut(sensor) else {
                continue;
            };
            if !sensor.emit(pair, tx) {
                return false;
            }
        }
        true
    }

    /// End of the log: the events still open, and with several LiDARs all
    /// the sensors' events merged into one list and written. The log's events.
    pub(super) fn finish(
        &mut self,
        tx: &SyncSender<ToWriter>,
        tree: Option<&TransformTree>,
    ) -> Vec<NearMissEvent> {
        for sensor in &mut self.sensors {
            if let Some((pair, annotated)) = sensor.annotator.flush()
                && !sensor.send(&pair, annotated, tx)
            {
                return Vec::new();
            }
            for message in sensor.annotator.finish() {
                if tx.send(ToWriter::Own(message)).is_err() {
                    return Vec::new();
                }
            }
        }
        if let (Some(tree), Some(_)) = (tree, &self.merged_events) {
            self.place_by_transforms(tree);
        }
        let Some(writer) = &mut self.merged_events else {
            return self
                .sensors
                .first()
                .map(|s| s.annotator.events().to_vec())
                .unwrap_or_default();
        };
        let per_sensor: Vec<SensorEvents> = self
            .sensors
            .iter()
            .map(|s| SensorEvents {
                sensor: s.name.clone(),
                vehicle_from_sensor: s.vehicle_from_sensor.clone(),
                events: s.annotator.events().to_vec(),
            })
            .collect();
        let events = merge_sensor_events(&per_sensor);
        for event in &events {
            for message in writer.messages(event) {
                if tx.send(ToWriter::Own(message)).is_err() {
                    return events;
                }
            }
        }
        events
    }
}

impl Annotation {
    /// Without a motion source in common (a LiDAR-only log), the sensors'
    /// poses in the first sensor's frame through `/tf_static`, so that their
    /// events still merge; only when every sensor is reached.
    fn place_by_transforms(&mut self, tree: &TransformTree) {
        let frames: Vec<&str> = self
            .sensors
            .iter()
            .map(|s| s.vehicle_from_sensor.as_ref().map_or("", |v| v.0.as_str()))
            .collect();
        if frames.iter().all(|f| !f.is_empty() && *f == frames[0]) {
            return;
        }
        let Some((common, _)) = self.sensors.first().and_then(|s| s.frame.clone()) else {
            return;
        };
        let placed: Option<Vec<Isometry3<f64>>> = self
            .sensors
            .iter()
            .map(|s| {
                let (frame, pose) = s.frame.as_ref()?;
                Some(tree.lookup(&common, frame)? * pose)
            })
            .collect();
        if let Some(poses) = placed {
            for (sensor, pose) in self.sensors.iter_mut().zip(poses) {
                sensor.vehicle_from_sensor = Some((common.clone(), pose));
            }
        }
    }
}

impl SensorAnnotation {
    /// Annotate one pair and send the messages of the one before it (the
    /// engine takes a pair while the one before is completed beside it);
    /// false when the writer has gone.
    fn emit(&mut self, pair: ScanPair, tx: &SyncSender<ToWriter>) -> bool {
        if let Some(extrinsic) = pair
            .motion
            .velocity_extrinsic
            .as_ref()
            .or(pair.motion.imu_extrinsic.as_ref())
            .filter(|e| e.source != ExtrinsicSource::IdentityAssumed)
        {
            self.vehicle_from_sensor =
                Some((extrinsic.motion_frame.clone(), extrinsic.motion_from_lidar));
        }
        if self.frame.is_none() {
            self.frame = Some(crate::pairing::origin::extrinsic_frame(
                &pair.current,
                false,
            ));
        }
        match self.annotator.push_pair(pair) {
            Some((done, annotated)) => self.send(&done, annotated, tx),
            None => true,
        }
    }

    /// A completed pair's record, then its messages (the record carries the
    /// quality figures of its annotation but still goes out first).
    fn send(&mut self, pair: &ScanPair, annotated: Annotated, tx: &SyncSender<ToWriter>) -> bool {
        let mut record = PairRecord::from_pair(pair);
        record.quality = annotated.quality;
        let data = serde_json::to_vec(&record).expect("pair records always serialise");
        let item = ToWriter::Own(OwnMessage {
            channel_id: self.pairs_channel,
            sequence: self.pairs_written as u32,
            log_time_ns: pair.current_log_time_ns,
            data,
        });
        self.pairs_written += 1;
        if tx.send(item).is_err() {
            return false;
        }
        annotated
            .messages
            .into_iter()
            .all(|message| tx.send(ToWriter::Own(message)).is_ok())
    }
}
