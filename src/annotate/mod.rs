//! The annotation stage: runs the engine on each scan pair, detects near-miss
//! events, and encodes the `/looming/*` output channels (documented in
//! `docs/channels.md`). Knows nothing of files: it returns encoded messages
//! for the writer.

pub mod colour;
pub mod foxglove;
pub mod objects;
mod overlap;
pub mod pairs;
pub mod topics;

use std::time::Instant;

use ::foxglove::Encode;
use prost::Message;

use crate::engine::{EngineCache, EngineConfig, PairLooming};
use crate::events::{EVENT_SCHEMA, EventConfig, EventDetector, NearMissEvent, PairFrame};
use crate::model::ScanPair;
use crate::objects::{ObjectConfig, ObjectTracker, PairObjects};
use crate::output::OwnChannelSpec;
use crate::quality::PairQuality;

pub use self::foxglove::FieldSet;
pub use self::overlap::{Annotated, StageSeconds};

pub use self::topics::{
    DISAGREEMENT_TOPIC, EVENTS_TOPIC, IMAGE_DISAGREEMENT_TOPIC, IMAGE_FUSED_TOPIC, LOG_TOPIC,
    NEAR_MISSES_TOPIC, OBJECT_LIST_TOPIC, OBJECTS_TOPIC, POINTS_TOPIC, THREAT_TOPIC,
    THREAT_ZONES_TOPIC,
};

/// Settings of the annotation stage.
#[derive(Debug, Clone, Default, serde::Serialize)]
pub struct AnnotateConfig {
    pub engine: EngineConfig,
    pub events: EventConfig,
    pub fields: FieldSet,
    pub objects: ObjectConfig,
}

/// One of our channels, in the order they are registered (the discriminant
/// is the channel's slot).
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
enum Channel {
    Points,
    Disagreement,
    Threat,
    ThreatZones,
    ImageFused,
    ImageDisagreement,
    Events,
    Log,
    NearMisses,
    Objects,
    ObjectList,
}

/// How many channels the stage writes.
const CHANNEL_COUNT: usize = 11;

const CHANNELS: [Channel; CHANNEL_COUNT] = [
    Channel::Points,
    Channel::Disagreement,
    Channel::Threat,
    Channel::ThreatZones,
    Channel::ImageFused,
    Channel::ImageDisagreement,
    Channel::Events,
    Channel::Log,
    Channel::NearMisses,
    Channel::Objects,
    Channel::ObjectList,
];

/// Channel and schema of a Foxglove protobuf message type.
fn protobuf_spec<T: Encode>(topic: &str) -> OwnChannelSpec {
    let schema = T::get_schema().expect("foxglove message types carry their schema");
    OwnChannelSpec {
        topic: topic.into(),
        schema_name: schema.name,
        schema_encoding: schema.encoding,
        schema_data: schema.data.into_owned(),
        message_encoding: T::get_message_encoding(),
    }
}

impl Channel {
    fn spec(self) -> OwnChannelSpec {
        use ::foxglove::messages::{CompressedImage, Event, Log, PointCloud, SceneUpdate};
        match self {
            Channel::Points => protobuf_spec::<PointCloud>(POINTS_TOPIC),
            Channel::Disagreement => protobuf_spec::<PointCloud>(DISAGREEMENT_TOPIC),
            Channel::Threat => protobuf_spec::<PointCloud>(THREAT_TOPIC),
            Channel::ThreatZones => protobuf_spec::<SceneUpdate>(THREAT_ZONES_TOPIC),
            Channel::ImageFused => protobuf_spec::<CompressedImage>(IMAGE_FUSED_TOPIC),
            Channel::ImageDisagreement => {
                protobuf_spec::<CompressedImage>(IMAGE_DISAGREEMENT_TOPIC)
            }
            Channel::Events => {
                OwnChannelSpec::json(EVENTS_TOPIC, "looming.NearMissEvent", EVENT_SCHEMA)
            }
            Channel::Log => protobuf_spec::<Log>(LOG_TOPIC),
            Channel::NearMisses => protobuf_spec::<Event>(NEAR_MISSES_TOPIC),
            Channel::Objects => protobuf_spec::<SceneUpdate>(OBJECTS_TOPIC),
            Channel::ObjectList => OwnChannelSpec::json(
                OBJECT_LIST_TOPIC,
                "looming.ObjectList",
                objects::OBJECT_LIST_SCHEMA,
            ),
        }
    }
}

/// The channel specs of the annotation stage, in registration order.
pub fn channel_specs() -> Vec<OwnChannelSpec> {
    CHANNELS.iter().map(|c| c.spec()).collect()
}

/// The channels of the near-miss events: one set per log however many
/// LiDARs it has (events, log, near misses).
const EVENT_CHANNELS: [Channel; 3] = [Channel::Events, Channel::Log, Channel::NearMisses];

/// On a log with several LiDARs, the channel specs of `sensor`, in
/// registration order: every channel but the events', under the sensor's
/// name ([`topics::sensor_topic`]).
pub fn sensor_channel_specs(sensor: &str) -> Vec<OwnChannelSpec> {
    CHANNELS
        .iter()
        .filter(|c| !EVENT_CHANNELS.contains(c))
        .map(|c| {
            let mut spec = c.spec();
            spec.topic = topics::sensor_topic(sensor, &spec.topic);
            spec
        })
        .collect()
}

/// The specs of the log's event channels (with several LiDARs), in
/// registration order.
pub fn event_channel_specs() -> Vec<OwnChannelSpec> {
    EVENT_CHANNELS.iter().map(|c| c.spec()).collect()
}

/// The full id list [`Annotator::new`] takes, from a sensor's ids
/// ([`sensor_channel_specs`] order) and the log's event ids
/// ([`event_channel_specs`] order).
pub fn sensor_channel_ids(sensor_ids: &[u16], event_ids: &[u16]) -> Vec<u16> {
    let (mut sensor_ids, mut event_ids) = (sensor_ids.iter(), event_ids.iter());
    CHANNELS
        .iter()
        .map(|c| {
            let next = if EVENT_CHANNELS.contains(c) {
                event_ids.next()
            } else {
                sensor_ids.next()
            };
            next.copied().unwrap_or(u16::MAX)
        })
        .collect()
}

/// Writes near-miss events on the log's event channels.
#[derive(Debug, Clone)]
pub struct EventWriter {
    channel_ids: [u16; 3],
    sequences: [u32; 3],
}

impl EventWriter {
    /// `channel_ids`: the ids of [`event_channel_specs`], same order.
    pub fn new(channel_ids: &[u16]) -> Self {
        let mut ids = [u16::MAX; 3];
        for (id, given) in ids.iter_mut().zip(channel_ids) {
            *id = *given;
        }
        Self {
            channel_ids: ids,
            sequences: [0; 3],
        }
    }

    /// An event's messages: on the events, the log and the near-miss
    /// (`foxglove.Event`) channels, at the log time of its first hot scan.
    pub fn messages(&mut self, event: &NearMissEvent) -> [OwnMessage; 3] {
        let json = serde_json::to_vec(event).expect("events always serialise");
        let line = foxglove::event_log(event).encode_to_vec();
        let span = foxglove::near_miss_event(event).encode_to_vec();
        let mut slot = 0;
        [json, line, span].map(|data| {
            let message = OwnMessage {
                channel_id: self.channel_ids[slot],
                sequence: self.sequences[slot],
                log_time_ns: event.start_log_time_ns,
                data,
            };
            self.sequences[slot] += 1;
            slot += 1;
            message
        })
    }
}

/// An encoded message for one of our channels.
#[derive(Debug, Clone)]
pub struct OwnMessage {
    pub channel_id: u16,
    pub sequence: u32,
    pub log_time_ns: u64,
    pub data: Vec<u8>,
}

/// What the stage did, for the run summary.
#[derive(Debug, Clone, Default, serde::Serialize)]
pub struct AnnotateStats {
    /// Pairs the engine computed looming for.
    pub pairs_annotated: u64,
    /// Pairs without a usable range image (too few points, no beams found).
    pub pairs_without_image: u64,
    /// Pairs without a velocity source: LiDAR-only looming, no L_ego, D,
    /// moving flags or threat spheres.
    pub pairs_lidar_only: u64,
    /// Pairs whose velocity or angular rate no source measured, estimated
    /// from the static world by the engine (`engine::egomotion`).
    pub pairs_motion_estimated: u64,
    /// Cells whose fused looming was combined with their object's
    /// (`objects::fuse_objects`).
    pub cells_fused_with_object: u64,
    /// Cells without a value of their own that took their object's.
    pub cells_filled_from_object: u64,
    pub points_written: u64,
    pub disagreement_points_written: u64,
    pub threat_points_written: u64,
    pub events: u64,
    /// Range images the PNG encoder refused (dimensions no PNG can hold):
    /// left out of their channel.
    pub images_not_encoded: u64,
    /// Time spent in the engine, seconds.
    pub engine_s: f64,
    /// Time per stage, seconds (the engine's and the rest's).
    pub stages: StageSeconds,
    /// Smallest event cluster used, cells.
    pub event_min_cells: Option<usize>,
}

impl AnnotateStats {
    /// Add another sensor's figures to these (the smallest event cluster of
    /// both; `events` is the log's, set by whoever merges them).
    pub fn absorb(&mut self, other: &AnnotateStats) {
        self.pairs_annotated += other.pairs_annotated;
        self.pairs_without_image += other.pairs_without_image;
        self.pairs_lidar_only += other.pairs_lidar_only;
        self.pairs_motion_estimated += other.pairs_motion_estimated;
        self.cells_fused_with_object += other.cells_fused_with_object;
        self.cells_filled_from_object += other.cells_filled_from_object;
        self.points_written += other.points_written;
        self.disagreement_points_written += other.disagreement_points_written;
        self.threat_points_written += other.threat_points_written;
        self.events += other.events;
        self.images_not_encoded += other.images_not_encoded;
        self.engine_s += other.engine_s;
        self.stages.add(&other.stages);
        self.event_min_cells = match (self.event_min_cells, other.event_min_cells) {
            (Some(a), Some(b)) => Some(a.min(b)),
            (a, b) => a.or(b),
        };
    }
}

/// Runs the engine and the event detector over a stream of pairs.
pub struct Annotator {
    config: AnnotateConfig,
    channel_ids: [u16; CHANNEL_COUNT],
    sequences: [u32; CHANNEL_COUNT],
    cache: EngineCache,
    detector: EventDetector,
    events: Vec<NearMissEvent>,
    stats: AnnotateStats,
    tracker: ObjectTracker,
    /// The pair the engine finished last, waiting for
    /// [`Annotator::complete`] beside the engine's next pair.
    pending: Option<(ScanPair, Option<PairLooming>)>,
    /// Events are kept, not written: on a log with several LiDARs the
    /// sensors' events are merged into one list at the end.
    hold_events: bool,
    event_writer: EventWriter,
}

impl Annotator {
    /// `channel_ids`: the ids the writer gave [`channel_specs`], same order.
    pub fn new(config: AnnotateConfig, channel_ids: &[u16]) -> Self {
        let mut ids = [0; CHANNEL_COUNT];
        ids.copy_from_slice(&channel_ids[..CHANNEL_COUNT]);
        Self {
            detector: EventDetector::new(config.events.clone()),
            config,
            channel_ids: ids,
            sequences: [0; CHANNEL_COUNT],
            cache: EngineCache::default(),
            events: Vec::new(),
            stats: AnnotateStats::default(),
            tracker: ObjectTracker::default(),
            pending: None,
            hold_events: false,
            event_writer: EventWriter::new(&EVENT_CHANNELS.map(|c| ids[c as usize])),
        }
    }

    /// Keep the events (see [`Annotator::events`]) instead of writing them.
    pub fn hold_events(mut self) -> Self {
        self.hold_events = true;
        self
    }

    pub fn stats(&self) -> &AnnotateStats {
        &self.stats
    }

    /// Every event so far, in order of id.
    pub fn events(&self) -> &[NearMissEvent] {
        &self.events
    }

    /// Everything after the engine for one pair: its objects, quality
    /// figures, events and messages (and those of the events that ended
    /// before it). `looming`: the engine's result, `None` when it made no
    /// image of the pair.
    fn complete(&mut self, pair: &ScanPair, looming: Option<PairLooming>) -> Annotated {
        let Some(mut looming) = looming else {
            self.stats.pairs_without_image += 1;
            return Annotated::default();
        };
        // The objects' looming fed back into their cells before anything is
        // judged or drawn from the fused looming.
        let started = Instant::now();
        let (objects, fusion) = PairObjects::find_tracked_fused(
            &pair.current,
            &mut looming,
            (&self.config.objects, &self.config.engine.threat_ttc_s),
            &mut self.tracker,
            pair.step_s,
        );
        self.stats.stages.objects_s += started.elapsed().as_secs_f64();
        let started = Instant::now();
        self.stats.cells_fused_with_object += fusion.combined as u64;
        self.stats.cells_filled_from_object += fusion.filled as u64;
        let mut quality =
            PairQuality::measure_on_ground(&looming, &pair.current, objects.ground.as_ref());
        quality.count_objects(&objects);
        self.stats.pairs_annotated += 1;
        if !looming.availability.ego_velocity {
            self.stats.pairs_lidar_only += 1;
        }
        if looming.ego_estimate.is_some() {
            self.stats.pairs_motion_estimated += 1;
        }
        let mut out = Vec::with_capacity(8);
        let ended = self.detector.observe(&PairFrame {
            pair,
            looming: &looming,
            objects: Some(&objects),
        });
        self.stats.event_min_cells = self.detector.min_cells_used();
        quality.path_peak_looming_per_s = self.detector.path_peak_looming_per_s();
        for event in ended {
            self.push_event(event, &mut out);
        }
        self.stats.stages.quality_and_events_s += started.elapsed().as_secs_f64();
        let started = Instant::now();
        self.push_scan_messages(pair, &looming, &objects, &mut out);
        self.stats.stages.messages_s += started.elapsed().as_secs_f64();
        Annotated {
            messages: out,
            quality: Some(quality),
        }
    }

    /// End of the stream: the events still open.
    pub fn finish(&mut self) -> Vec<OwnMessage> {
        let mut out = Vec::new();
        for event in self.detector.finish() {
            self.push_event(event, &mut out);
        }
        out
    }

    fn push_scan_messages(
        &mut self,
        pair: &ScanPair,
        looming: &PairLooming,
        objects: &PairObjects,
        out: &mut Vec<OwnMessage>,
    ) {
        let scan = &*pair.current;
        let log_time_ns = pair.current_log_time_ns;
        // The channels' messages built on both cores (the engine waits for
        // them); pushed below in a fixed order.
        let fields = self.config.fields;
        let ((points, disagreement), (threat, images)) = rayon::join(
            || {
                rayon::join(
                    || foxglove::looming_cloud(scan, looming, objects, fields),
                    || foxglove::disagreement_cloud(scan, looming),
                )
            },
            || {
                rayon::join(
                    || foxglove::threat_cloud(scan, looming),
                    || {
                        rayon::join(
                            || foxglove::range_image(scan, looming, &looming.fused),
                            || foxglove::range_image(scan, looming, &looming.disagreement),
                        )
                    },
                )
            },
        );
        self.stats.points_written += point_count(&points);
        self.stats.disagreement_points_written += point_count(&disagreement);
        self.stats.threat_points_written += point_count(&threat);
        let zones = foxglove::threat_zones(scan, looming, &self.config.engine.threat_ttc_s);
        self.push(Channel::Points, log_time_ns, points.encode_to_vec(), out);
        self.push(
            Channel::Disagreement,
            log_time_ns,
            disagreement.encode_to_vec(),
            out,
        );
        self.push(Channel::Threat, log_time_ns, threat.encode_to_vec(), out);
        self.push(
            Channel::ThreatZones,
            log_time_ns,
            zones.encode_to_vec(),
            out,
        );
        let ttc_s = &self.config.engine.threat_ttc_s;
        let scene = objects::object_scene(scan, objects, ttc_s);
        let list = objects::object_list(scan, objects, ttc_s);
        self.push(Channel::Objects, log_time_ns, scene.encode_to_vec(), out);
        let json = serde_json::to_vec(&list).expect("object lists always serialise");
        self.push(Channel::ObjectList, log_time_ns, json, out);
        let (fused_image, disagreement_image) = images;
        for (channel, image) in [
            (Channel::ImageFused, fused_image),
            (Channel::ImageDisagreement, disagreement_image),
        ] {
            match image {
                Ok(image) => self.push(channel, log_time_ns, image.encode_to_vec(), out),
                // Only dimensions no PNG holds (or a result whose cells
                // are not the image's) fail: the pair's other channels are
                // still worth writing, so count and go on.
                Err(_) => self.stats.images_not_encoded += 1,
            }
        }
    }

    /// An event goes out at the log time of its first hot scan, on the
    /// events, the log and the near-miss (`foxglove.Event`) channels.
    fn push_event(&mut self, event: NearMissEvent, out: &mut Vec<OwnMessage>) {
        if !self.hold_events {
            out.extend(self.event_writer.messages(&event));
        }
        self.stats.events += 1;
        self.events.push(event);
    }

    fn push(
        &mut self,
        channel: Channel,
        log_time_ns: u64,
        data: Vec<u8>,
        out: &mut Vec<OwnMessage>,
    ) {
        let slot = channel as usize;
        out.push(OwnMessage {
            channel_id: self.channel_ids[slot],
            sequence: self.sequences[slot],
            log_time_ns,
            data,
        });
        self.sequences[slot] += 1;
    }
}

fn point_count(cloud: &::foxglove::messages::PointCloud) -> u64 {
    if cloud.point_stride == 0 {
        return 0;
    }
    (cloud.data.len() / cloud.point_stride as usize) as u64
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn each_channel_is_its_own_slot() {
        for (slot, channel) in CHANNELS.iter().enumerate() {
            assert_eq!(*channel as usize, slot);
        }
        let topics: Vec<String> = channel_specs().into_iter().map(|s| s.topic).collect();
        assert_eq!(topics[0], POINTS_TOPIC);
        assert_eq!(topics[7], LOG_TOPIC);
        assert_eq!(topics[8], NEAR_MISSES_TOPIC);
    }
}
