//! One list of near misses for a vehicle with several LiDARs: each sensor's
//! events are detected on its own pairs; events of different sensors that
//! overlap in time and whose peaks lie close together in the vehicle frame
//! are one near miss, seen by several sensors. Its figures are those of the
//! sensor with the best view of it (the most cells on it at the peak).

use nalgebra::{Isometry3, Point3};

use super::NearMissEvent;

/// Events of one sensor closer in time than this to another's are the same
/// near miss when their peaks are also close, s: a sensor at 20 Hz and one
/// at 10 Hz see the same approach a scan apart.
const SAME_EVENT_GAP_S: f64 = 0.3;
/// ... within this distance of each other in the vehicle frame, m (two
/// sensors see different faces of one car).
const SAME_EVENT_DISTANCE_M: f64 = 3.0;

/// One sensor's events, with where the sensor sits on the vehicle.
#[derive(Debug, Clone)]
pub struct SensorEvents {
    /// The sensor's name (`topics::sensor_name` of its topic).
    pub sensor: String,
    /// Maps the sensor's points into the vehicle frame; `None` when no
    /// transform relates it to the vehicle (its events then stand alone).
    pub vehicle_from_sensor: Option<(String, Isometry3<f64>)>,
    pub events: Vec<NearMissEvent>,
}

/// The sensors' events as one list, numbered anew from 1 in order of start.
pub fn merge_sensor_events(sensors: &[SensorEvents]) -> Vec<NearMissEvent> {
    let all: Vec<(usize, &NearMissEvent)> = sensors
        .iter()
        .enumerate()
        .flat_map(|(s, sensor)| sensor.events.iter().map(move |e| (s, e)))
        .collect();
    let mut group: Vec<usize> = (0..all.len()).collect();
    for i in 0..all.len() {
        for j in i + 1..all.len() {
            if same_near_miss(sensors, all[i], all[j]) {
                let (a, b) = (root(&mut group, i), root(&mut group, j));
                group[a.max(b)] = a.min(b);
            }
        }
    }
    let mut merged: Vec<NearMissEvent> = Vec::new();
    for i in 0..all.len() {
        if root(&mut group, i) != i {
            continue;
        }
        let members: Vec<(usize, &NearMissEvent)> = (0..all.len())
            .filter(|&j| root(&mut group, j) == i)
            .map(|j| all[j])
            .collect();
        merged.push(one_event(sensors, &members));
    }
    merged.sort_by_key(|e| (e.start_ns, e.start_log_time_ns));
    for (k, event) in merged.iter_mut().enumerate() {
        event.id = k as u32 + 1;
    }
    merged
}

fn root(group: &mut [usize], mut i: usize) -> usize {
    while group[i] != i {
        group[i] = group[group[i]];
        i = group[i];
    }
    i
}

/// Two events of different sensors that overlap in time (within
/// [`SAME_EVENT_GAP_S`]) with peaks within [`SAME_EVENT_DISTANCE_M`] in the
/// vehicle frame.
fn same_near_miss(
    sensors: &[SensorEvents],
    (sa, a): (usize, &NearMissEvent),
    (sb, b): (usize, &NearMissEvent),
) -> bool {
    if sa == sb {
        return false;
    }
    let gap_ns = (SAME_EVENT_GAP_S * 1e9) as i64;
    if a.start_ns > b.end_ns + gap_ns || b.start_ns > a.end_ns + gap_ns {
        return false;
    }
    match (in_vehicle(&sensors[sa], a), in_vehicle(&sensors[sb], b)) {
        (Some((frame_a, pa)), Some((frame_b, pb))) => {
            frame_a == frame_b && (pa - pb).norm() <= SAME_EVENT_DISTANCE_M
        }
        _ => false,
    }
}

/// The event's peak in the vehicle frame.
fn in_vehicle<'a>(
    sensor: &'a SensorEvents,
    event: &NearMissEvent,
) -> Option<(&'a str, Point3<f64>)> {
    let (frame, pose) = sensor.vehicle_from_sensor.as_ref()?;
    let [x, y, z] = event.peak.position_m;
    Some((frame.as_str(), pose * Point3::new(x, y, z)))
}

/// The near miss of `members` (one or more sensors' events): the figures of
/// the best view, the span of them all.
fn one_event(sensors: &[SensorEvents], members: &[(usize, &NearMissEvent)]) -> NearMissEvent {
    let &(best_sensor, best) = members
        .iter()
        .max_by(|a, b| {
            a.1.peak.cluster_cells.cmp(&b.1.peak.cluster_cells).then(
                b.1.min_time_to_contact_s
                    .total_cmp(&a.1.min_time_to_contact_s),
            )
        })
        .expect("a near miss has at least one event");
    let mut event = best.clone();
    let first = members
        .iter()
        .min_by_key(|m| m.1.start_ns)
        .map(|m| m.1)
        .unwrap_or(best);
    let last = members
        .iter()
        .max_by_key(|m| m.1.end_ns)
        .map(|m| m.1)
        .unwrap_or(best);
    event.start_ns = first.start_ns;
    event.start_log_time_ns = first.start_log_time_ns;
    event.end_ns = last.end_ns;
    event.end_log_time_ns = last.end_log_time_ns;
    event.duration_s = (event.end_ns - event.start_ns) as f64 * 1e-9;
    let mut names: Vec<String> = members
        .iter()
        .map(|m| sensors[m.0].sensor.clone())
        .collect();
    names.sort();
    names.dedup();
    event.sensors = names;
    event.sensor = Some(sensors[best_sensor].sensor.clone());
    event
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::events::{EventPeak, PathSource};

    fn event(start_s: f64, end_s: f64, position_m: [f64; 3], cells: usize) -> NearMissEvent {
        let ns = |s: f64| (s * 1e9) as i64;
        NearMissEvent {
            id: 1,
            start_ns: ns(start_s),
            end_ns: ns(end_s),
            start_log_time_ns: ns(start_s) as u64,
            end_log_time_ns: ns(end_s) as u64,
            duration_s: end_s - start_s,
            hot_pairs: 3,
            peak_looming_per_s: 1.0,
            min_time_to_contact_s: 1.0,
            peak: EventPeak {
                stamp_ns: ns(start_s),
                log_time_ns: ns(start_s) as u64,
                looming_per_s: 1.0,
                azimuth_deg: 0.0,
                elevation_deg: 0.0,
                range_m: 8.0,
                position_m,
                lateral_offset_m: 0.0,
                ego_speed_mps: None,
                cluster_cells: cells,
                object_id: None,
            },
            max_cluster_cells: cells,
            moving_fraction: 0.0,
            moving: false,
            frame_id: "lidar".into(),
            corridor: PathSource::LidarXAxis,
            object_id: None,
            sensors: Vec::new(),
            sensor: None,
            scan_stamps_ns: Vec::new(),
            scan_log_times_ns: Vec::new(),
        }
    }

    fn sensor(name: &str, x_m: f64, y_m: f64, events: Vec<NearMissEvent>) -> SensorEvents {
        SensorEvents {
            sensor: name.into(),
            vehicle_from_sensor: Some(("base_link".into(), Isometry3::translation(x_m, y_m, 1.0))),
            events,
        }
    }

    #[test]
    fn one_car_seen_by_two_sensors_is_one_near_miss_with_the_best_views_figures() {
        // The car 8 m ahead of the roof sensor (x 0.5) is 7.5 m ahead of the
        // left one (x 1.0): the same point of the vehicle frame.
        let roof = sensor(
            "roof",
            0.5,
            0.0,
            vec![event(2.0, 2.6, [8.0, 0.0, -0.5], 400)],
        );
        let left = sensor(
            "left",
            1.0,
            0.0,
            vec![event(2.05, 2.7, [7.5, 0.2, -0.5], 90)],
        );
        // A wall the right sensor alone saw, 10 s later.
        let right = sensor(
            "right",
            1.0,
            -0.9,
            vec![event(12.0, 12.3, [3.0, -2.0, 0.0], 50)],
        );
        let merged = merge_sensor_events(&[roof, left, right]);
        assert_eq!(merged.len(), 2, "{merged:?}");
        assert_eq!(merged[0].sensors, ["left", "roof"]);
        assert_eq!(merged[0].sensor.as_deref(), Some("roof"));
        assert_eq!(merged[0].peak.cluster_cells, 400);
        assert_eq!(merged[0].start_ns, 2_000_000_000);
        assert_eq!(merged[0].end_ns, 2_700_000_000);
        assert_eq!((merged[0].id, merged[1].id), (1, 2));
        assert_eq!(merged[1].sensors, ["right"]);
    }

    #[test]
    fn events_far_apart_or_without_a_transform_stay_apart() {
        // Same time, 10 m apart in the vehicle frame.
        let a = sensor("a", 0.0, 0.0, vec![event(1.0, 1.5, [8.0, 0.0, 0.0], 100)]);
        let b = sensor("b", 0.0, 0.0, vec![event(1.0, 1.5, [8.0, 10.0, 0.0], 100)]);
        assert_eq!(merge_sensor_events(&[a.clone(), b]).len(), 2);
        // The same place but no transform: not merged.
        let mut c = sensor("c", 0.0, 0.0, vec![event(1.0, 1.5, [8.0, 0.0, 0.0], 100)]);
        c.vehicle_from_sensor = None;
        assert_eq!(merge_sensor_events(&[a.clone(), c]).len(), 2);
        // Two events of one sensor are never merged with each other.
        let twice = sensor(
            "a",
            0.0,
            0.0,
            vec![
                event(1.0, 1.5, [8.0, 0.0, 0.0], 100),
                event(1.6, 2.0, [8.0, 0.0, 0.0], 100),
            ],
        );
        assert_eq!(merge_sensor_events(&[twice]).len(), 2);
    }
}
