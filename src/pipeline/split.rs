//! LiDAR topics whose clouds merge several sensors (a concatenated
//! `base_link` cloud, a driver serving several LiDARs on one topic) and
//! carry a per-point sensor field: found on the topic's first clouds before
//! the run, each becomes one sensor per value (`topics::MergedSensor`),
//! paired and annotated like a LiDAR topic of its own; during the run each
//! cloud is split (`pairing::split`) and its parts routed to their sensors.

use std::collections::BTreeMap;

use crate::decode::SensorField;
use crate::input::{InputFile, InputRecord};
use crate::model::Decoded;
use crate::pairing::split::{MAX_SENSORS, Split, distinct_ids};
use crate::topics::TopicSelection;

use super::scans::{Decoder, ScanOptions};

/// Clouds of a topic looked at, at most, for its sensors: a merging node's
/// first clouds hold every sensor it merges (a second at 10-20 Hz), and a
/// driver serving several on one topic publishes each within a period.
const DISCOVERY_CLOUDS: usize = 20;
/// Log time read at most for them, ns: a topic silent that long from the
/// log's first message is left whole (a log without clouds is not read
/// twice).
const DISCOVERY_WINDOW_NS: u64 = 10_000_000_000;

/// What the first clouds of one LiDAR topic showed.
#[derive(Default)]
struct Seen {
    clouds: usize,
    field: Option<String>,
    ids: Vec<u32>,
    /// More distinct values than [`MAX_SENSORS`].
    more: bool,
    /// A cloud without the field: the topic's clouds are whole.
    done: bool,
}

/// `sensors` with every LiDAR topic whose first clouds carry a sensor field
/// (with several values, or the one `--split-field` names) replaced by a
/// selection per value, and what the user should hear of it. With
/// `--split-field none`, `sensors` as they are, the file unread.
pub(super) fn expand(
    input: &InputFile,
    options: &ScanOptions,
    sensors: Vec<TopicSelection>,
) -> (Vec<TopicSelection>, Vec<String>) {
    let choice = &options.decode_limits.sensor_field;
    if *choice == SensorField::Off || sensors.iter().all(|s| s.lidar.is_none()) {
        return (sensors, Vec::new());
    }
    let seen = first_clouds(input, options, &sensors);
    let mut expanded = Vec::new();
    let mut warnings = Vec::new();
    for selection in sensors {
        let Some(lidar) = &selection.lidar else {
            expanded.push(selection);
            continue;
        };
        let found = seen.get(&lidar.channel_id);
        let named = matches!(choice, SensorField::Named(_));
        match found {
            Some(Seen {
                field: Some(field),
                ids,
                more,
                ..
            }) if ids.len() > 1 || (named && !ids.is_empty()) => {
                if *more {
                    warnings.push(format!(
                        "{}: its field {field} holds more than {MAX_SENSORS} values; the first {MAX_SENSORS} ({}) are annotated as sensors, points of the others are not",
                        lidar.topic,
                        join(ids)
                    ));
                }
                expanded.extend(selection.per_merged_sensor(field, ids));
            }
            Some(Seen { field: None, .. }) if named => {
                if let SensorField::Named(name) = choice {
                    warnings.push(format!(
                        "--split-field {name}: the clouds of {} have no integer field {name}; they are kept whole",
                        lidar.topic
                    ));
                }
                expanded.push(selection);
            }
            _ => expanded.push(selection),
        }
    }
    (expanded, warnings)
}

/// The sensor field and values of each LiDAR topic's first clouds (at most
/// [`DISCOVERY_CLOUDS`]; one when it has no sensor field), read from the
/// start of the log until every topic is seen.
fn first_clouds(
    input: &InputFile,
    options: &ScanOptions,
    sensors: &[TopicSelection],
) -> BTreeMap<u16, Seen> {
    let lidars: Vec<TopicSelection> = sensors
        .iter()
        .map(|s| TopicSelection {
            lidar: s.lidar.clone(),
            ..TopicSelection::none()
        })
        .collect();
    let name = input.path().display().to_string();
    let decoder = Decoder::new(options, &lidars, &name);
    let mut seen: BTreeMap<u16, Seen> = lidars
        .iter()
        .filter_map(|s| Some((s.lidar.as_ref()?.channel_id, Seen::default())))
        .collect();
    let mut first_log_time_ns = None;
    let mut sink = |record: InputRecord| {
        let InputRecord::Message(message) = record else {
            return std::ops::ControlFlow::Continue(());
        };
        let first = *first_log_time_ns.get_or_insert(message.log_time_ns);
        if message.log_time_ns.saturating_sub(first) > DISCOVERY_WINDOW_NS {
            return std::ops::ControlFlow::Break(());
        }
        let Some(entry) = seen.get_mut(&message.channel_id).filter(|e| !e.done) else {
            return std::ops::ControlFlow::Continue(());
        };
        entry.clouds += 1;
        if let Some(Ok((_, _, Decoded::Scan(scan)))) =
            decoder.decode(message.channel_id, message.log_time_ns, &message.data)
        {
            match scan.sensor_ids {
                Some(sensors) => {
                    let (ids, more) = distinct_ids(&sensors.ids, MAX_SENSORS + 1);
                    entry.more |= more || ids.len() > MAX_SENSORS;
                    entry.ids = merge_ids(&entry.ids, &ids);
                    entry.field = Some(sensors.field);
                }
                None => entry.done = true,
            }
        }
        entry.done |= entry.clouds >= DISCOVERY_CLOUDS;
        if seen.values().all(|e| e.done) {
            std::ops::ControlFlow::Break(())
        } else {
            std::ops::ControlFlow::Continue(())
        }
    };
    // Stopped once every topic was seen (the rest is the run's to read); a
    // file that cannot be read is the run's to report, as it would be
    // without merged clouds.
    let _ = input.read_records(false, &mut sink);
    seen
}

/// The distinct values of both lists, at most [`MAX_SENSORS`].
fn merge_ids(a: &[u32], b: &[u32]) -> Vec<u32> {
    let both: Vec<u32> = a.iter().chain(b).copied().collect();
    distinct_ids(&both, MAX_SENSORS).0
}

fn join(ids: &[u32]) -> String {
    ids.iter()
        .map(ToString::to_string)
        .collect::<Vec<_>>()
        .join(", ")
}

/// The sensors of one merged LiDAR channel during the run: which pairing
/// stage takes each value's part, and the points of values not among them.
pub(super) struct MergedRoute {
    pub(super) topic: String,
    pub(super) field: String,
    /// (value, index of its sensor's pairing stage).
    pub(super) sensors: Vec<(u32, usize)>,
    other_points: u64,
    /// Values met that are no sensor of the run (at most [`MAX_SENSORS`]).
    other_ids: Vec<u32>,
    /// Clouds without the sensor field.
    whole_clouds: u64,
}

impl MergedRoute {
    /// The routes of `sensors`' merged channels, by channel.
    pub(super) fn of(sensors: &[TopicSelection]) -> BTreeMap<u16, MergedRoute> {
        let mut routes: BTreeMap<u16, MergedRoute> = BTreeMap::new();
        for (stage, selection) in sensors.iter().enumerate() {
            let (Some(lidar), Some(merged)) = (&selection.lidar, &selection.merged) else {
                continue;
            };
            routes
                .entry(lidar.channel_id)
                .or_insert_with(|| MergedRoute {
                    topic: lidar.topic.clone(),
                    field: merged.field.clone(),
                    sensors: Vec::new(),
                    other_points: 0,
                    other_ids: Vec::new(),
                    whole_clouds: 0,
                })
                .sensors
                .push((merged.id, stage));
        }
        routes
    }

    /// The values asked of a cloud, in route order.
    pub(super) fn ids(&self) -> Vec<u32> {
        self.sensors.iter().map(|(id, _)| *id).collect()
    }

    /// Count what a split left over.
    pub(super) fn note(&mut self, split: &Split) {
        if split.scans.is_empty() {
            self.whole_clouds += 1;
        }
        self.other_points += split.other_points;
        self.other_ids = merge_ids(&self.other_ids, &split.other_ids);
    }

    /// What the user should hear at the end of the log.
    pub(super) fn warnings(&self) -> Vec<String> {
        let mut warnings = Vec::new();
        if self.other_points > 0 {
            warnings.push(format!(
                "{}: {} points of {} values {} (first met after the clouds the sensors were found on, or beyond {MAX_SENSORS} sensors) were not annotated",
                self.topic,
                self.other_points,
                self.field,
                join(&self.other_ids)
            ));
        }
        if self.whole_clouds > 0 {
            warnings.push(format!(
                "{}: {} clouds without the field {} were not annotated (its sensors are found by it)",
                self.topic, self.whole_clouds, self.field
            ));
        }
        warnings
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::pairing::split::split_by_sensor;

    #[test]
    fn values_met_after_the_sensors_were_found_are_counted_and_bounded() {
        let mut route = MergedRoute {
            topic: "/merged/points".into(),
            field: "sensor_id".into(),
            sensors: vec![(0, 0), (1, 1)],
            other_points: 0,
            other_ids: Vec::new(),
            whole_clouds: 0,
        };
        assert!(route.warnings().is_empty());
        // A cloud with 40 sensors: 38 unknown ones, 16 of them named.
        let mut scan = crate::model::Scan {
            stamp_ns: 0,
            frame_id: "base_link".into(),
            sensor_pose: nalgebra::Isometry3::identity(),
            points_m: vec![[1.0, 0.0, 0.0]; 40],
            intensity: None,
            ring: None,
            time_offset_s: None,
            source_index: (0..40).collect(),
            input_point_count: 40,
            skipped_invalid_points: 0,
            organized: None,
            layout: crate::model::ScanLayout::default(),
            sensor_ids: Some(crate::model::SensorIds {
                field: "sensor_id".into(),
                ids: (0..40).collect(),
            }),
        };
        let split = split_by_sensor(&scan, &route.ids());
        assert_eq!(split.scans.iter().flatten().count(), 2);
        route.note(&split);
        assert_eq!(route.other_points, 38);
        assert_eq!(route.other_ids.len(), MAX_SENSORS);
        scan.sensor_ids = None;
        route.note(&split_by_sensor(&scan, &route.ids()));
        let warnings = route.warnings().join("\n");
        assert!(
            warnings.contains("38 points of sensor_id values 2, 3"),
            "{warnings}"
        );
        assert!(
            warnings.contains("1 clouds without the field"),
            "{warnings}"
        );
    }
}
