//! Near-miss events (METHOD.md, "Near-miss events"): a spatially coherent
//! cluster of trusted cells whose fused looming stays above the event
//! threshold for several consecutive scan pairs, inside the ego corridor.
//!
//! Pure logic: the detector takes each pair's engine result and returns the
//! events that have ended; the pipeline writes them.

mod cluster;
mod corridor;
mod merge;

use nalgebra::Vector3;
use serde::{Deserialize, Serialize};

use crate::engine::{ImageGeometry, PairLooming};
use crate::model::Scan;
use crate::model::ScanPair;
use crate::objects::PairObjects;

pub use cluster::{
    Cluster, ColSpan, FacingLooming, PATH_PEAK_FLOOR_TTC_S, hot_clusters, path_peak_looming,
};
pub use corridor::{Corridor, PathSource};
pub use merge::{SensorEvents, merge_sensor_events};

/// Schema of one event (`/looming/events` and the `--events` file's entries).
pub const EVENT_SCHEMA: &str =
    include_str!("../../../../schemas/looming.NearMissEvent.schema.json");
/// Schema of the `--events` file.
pub const EVENTS_FILE_SCHEMA: &str =
    include_str!("../../../../schemas/looming.NearMissEvents.schema.json");

/// Scan times kept per event (an event longer than this keeps its first ones).
const MAX_SCAN_TIMES: usize = 600;

/// Event detection settings.
#[derive(Debug, Clone, Serialize, Deserialize)]
pub struct EventConfig {
    /// A cell is hot when its fused looming reaches `1 / ttc_threshold_s`.
    pub ttc_threshold_s: f64,
    /// Smallest cluster, cells [default: [`default_min_cells`]].
    pub min_cells: Option<usize>,
    /// Consecutive pairs a cluster must last to become an event.
    pub min_pairs: u64,
    /// Pairs an event may miss without ending (one noisy scan does not split it).
    pub max_gap_pairs: u64,
    /// Width of the ego vehicle, metres: its swept path is this wide ...
    pub vehicle_width_m: f64,
    /// ... plus this margin either side, metres.
    pub path_margin_m: f64,
    /// Only surfaces facing the sensor this much (`|n . e|`) count: near
    /// grazing, range along a ray changes fast without anything approaching.
    pub facing_cos: f64,
}

impl EventConfig {
    /// Half width of the swept path: half the vehicle plus the margin, m.
    pub fn corridor_half_width_m(&self) -> f64 {
        0.5 * self.vehicle_width_m + self.path_margin_m
    }
}

impl Default for EventConfig {
    fn default() -> Self {
        Self {
            ttc_threshold_s: 1.5,
            min_cells: None,
            min_pairs: 2,
            max_gap_pairs: 1,
            // A passenger car (1.8-1.9 m without mirrors) with half a metre
            // either side: what passes closer is a near miss whatever its
            // speed; a parked car or a kerb-side wall 2 m from the path (a
            // car passes those every second in a city) is not.
            vehicle_width_m: 1.9,
            path_margin_m: 0.5,
            facing_cos: 0.5,
        }
    }
}

/// Side of the square face whose image, at [`REFERENCE_RANGE_M`], sets the
/// default smallest cluster.
pub(crate) const REFERENCE_FACE_M: f64 = 0.3;
pub(crate) const REFERENCE_RANGE_M: f64 = 10.0;

/// The cells a 0.3 m square face covers at 10 m (at least 3): about 40 on a
/// 64 x 2048 image, 5 on 32 x 512. Scales with the sensor's resolution so a
/// pedestrian-sized object is found at any resolution while a few noisy cells
/// are not.
pub fn default_min_cells(geometry: &ImageGeometry) -> usize {
    let angle_rad = 2.0 * (REFERENCE_FACE_M / 2.0 / REFERENCE_RANGE_M).atan();
    let col_step_rad = std::f64::consts::TAU / geometry.cols as f64;
    let elevations = &geometry.beams.elevations_rad;
    let row_step_rad = match (elevations.first(), elevations.last()) {
        (Some(lo), Some(hi)) if elevations.len() > 1 => (hi - lo) / (elevations.len() - 1) as f64,
        _ => col_step_rad,
    };
    let cells = (angle_rad / col_step_rad) * (angle_rad / row_step_rad.max(1e-6));
    (cells.round() as usize).max(3)
}

/// One near-miss event.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct NearMissEvent {
    /// 1-based, in order of confirmation.
    pub id: u32,
    /// Stamp (header time) of the first hot scan, ns.
    pub start_ns: i64,
    /// Stamp of the last hot scan plus its pair's period: the end of its sweep.
    pub end_ns: i64,
    /// Log times of the first and last hot scans, ns: where to jump to.
    pub start_log_time_ns: u64,
    pub end_log_time_ns: u64,
    pub duration_s: f64,
    /// Pairs in which the cluster was hot.
    pub hot_pairs: u64,
    /// Largest cluster looming over the event (median over a pair's cluster
    /// cells), 1/s, and its inverse.
    pub peak_looming_per_s: f64,
    pub min_time_to_contact_s: f64,
    pub peak: EventPeak,
    /// Largest cluster, cells.
    pub max_cluster_cells: usize,
    /// Share of the event's cluster cells flagged moving (by `D`).
    pub moving_fraction: f64,
    /// Most of the object moved on its own (`moving_fraction >= 0.5`).
    pub moving: bool,
    pub frame_id: String,
    pub corridor: PathSource,
    /// The tracked object (`/looming/object_list` id) the event's clusters
    /// belonged to most often; absent when they were on no object.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub object_id: Option<u32>,
    /// On a log with several LiDARs: every sensor that saw this near miss
    /// (their events merged, [`merge_sensor_events`]), and the one whose
    /// view (most cells on it) gave the figures, `frame_id` and `peak`.
    #[serde(default, skip_serializing_if = "Vec::is_empty")]
    pub sensors: Vec<String>,
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub sensor: Option<String>,
    /// Stamps and log times of the hot scans (at most 600).
    pub scan_stamps_ns: Vec<i64>,
    pub scan_log_times_ns: Vec<u64>,
}

/// The pair at which the event's looming peaked.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct EventPeak {
    pub stamp_ns: i64,
    pub log_time_ns: u64,
    pub looming_per_s: f64,
    /// Bearing of the cluster's centroid: azimuth (left positive) and
    /// elevation, degrees, LiDAR frame.
    pub azimuth_deg: f64,
    pub elevation_deg: f64,
    /// Median range of the cluster, metres.
    pub range_m: f64,
    /// Cluster centroid, LiDAR frame, metres.
    pub position_m: [f64; 3],
    /// Smallest distance of the cluster from the ego path, metres.
    pub lateral_offset_m: f64,
    /// LiDAR speed, m/s (absent without a velocity source).
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub ego_speed_mps: Option<f64>,
    pub cluster_cells: usize,
    /// The tracked object the peak's cluster lay on; absent when none.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub object_id: Option<u32>,
}

/// The `--events` file.
#[derive(Debug, Clone, Serialize, Deserialize)]
pub struct EventsFile {
    pub tool_version: String,
    pub input: String,
    pub output: String,
    pub config: EventConfig,
    /// Smallest cluster used, cells.
    pub min_cells: Option<usize>,
    /// Ranked by minimum time to contact, shortest first.
    pub events: Vec<NearMissEvent>,
}

/// Events ranked by minimum time to contact (ties: earlier first).
pub fn rank(events: &mut [NearMissEvent]) {
    events.sort_by(|a, b| {
        a.min_time_to_contact_s
            .total_cmp(&b.min_time_to_contact_s)
            .then(a.start_ns.cmp(&b.start_ns))
    });
}

/// One pair as the detector sees it.
pub struct PairFrame<'a> {
    pub pair: &'a ScanPair,
    pub looming: &'a PairLooming,
    /// The pair's objects, tracked: an event is then judged in the path by
    /// its object's whole footprint and names it.
    pub objects: Option<&'a PairObjects>,
}

/// A cluster followed over pairs.
struct Track {
    /// 0 while tentative.
    id: u32,
    last_pair: u64,
    /// Consecutive hot pairs so far (counts towards confirmation).
    run: u64,
    cols: ColSpan,
    rows: (usize, usize),
    hot_pairs: u64,
    start: (i64, u64),
    last: (i64, u64),
    last_period_ns: i64,
    peak: EventPeak,
    max_cells: usize,
    moving_cells: usize,
    cells: usize,
    stamps: Vec<(i64, u64)>,
    /// Near range of the cluster in the last hot pair, with that pair's stamp.
    last_near_range: (i64, f64),
    /// The cluster's looming in the last hot pair, 1/s.
    last_looming_per_s: f64,
    /// Hot pairs per tracked object the clusters lay on.
    objects: std::collections::BTreeMap<u32, u64>,
}

/// Follows hot clusters over pairs and reports near-miss events.
pub struct EventDetector {
    config: EventConfig,
    frame_id: String,
    corridor_source: PathSource,
    tracks: Vec<Track>,
    next_id: u32,
    min_cells_used: Option<usize>,
    /// Slot and stamp of the last pair seen.
    last_slot: Option<(u64, i64)>,
    /// [`path_peak_looming`] of the last pair seen.
    path_peak_per_s: Option<f64>,
}

impl EventDetector {
    pub fn new(config: EventConfig) -> Self {
        Self {
            config,
            frame_id: String::new(),
            corridor_source: PathSource::EgoMotion,
            tracks: Vec::new(),
            next_id: 1,
            min_cells_used: None,
            last_slot: None,
            path_peak_per_s: None,
        }
    }

    /// The smallest cluster of the last pair, cells.
    pub fn min_cells_used(&self) -> Option<usize> {
        self.min_cells_used
    }

    /// The looming of the strongest approach in the path in the last pair
    /// ([`path_peak_looming`]), 1/s.
    pub fn path_peak_looming_per_s(&self) -> Option<f64> {
        self.path_peak_per_s
    }

    pub fn config(&self) -> &EventConfig {
        &self.config
    }

    /// Take one pair; returns the events that ended before it.
    pub fn observe(&mut self, frame: &PairFrame<'_>) -> Vec<NearMissEvent> {
        let (pair, looming) = (frame.pair, frame.looming);
        let scan: &Scan = &pair.current;
        let stamp_ns = scan.stamp_ns;
        // The motion the engine used: a source's, or the one it estimated
        // from the static world where no source measured it.
        let velocity = looming.velocity_mps.map(Vector3::from);
        let corridor = Corridor::new(
            velocity,
            looming.angular_velocity_radps.map(Vector3::from),
            self.config.corridor_half_width_m(),
        );
        self.frame_id.clone_from(&scan.frame_id);
        self.corridor_source = corridor.source;
        let min_cells = self
            .config
            .min_cells
            .unwrap_or_else(|| default_min_cells(&looming.geometry));
        self.min_cells_used = Some(min_cells);
        let facing = FacingLooming::of(looming, &self.config);
        let clusters = hot_clusters(
            looming,
            (scan, frame.objects),
            (&corridor, &facing),
            &self.config,
            min_cells,
        );
        // The floor's clusters can merge a hot object with its slower
        // surroundings; the hot clusters keep the curve at or above the
        // threshold wherever an event is hot.
        let hottest = clusters
            .iter()
            .map(|c| c.looming_per_s)
            .max_by(f64::total_cmp);
        let floor = path_peak_looming(
            looming,
            (scan, frame.objects),
            (&corridor, &facing),
            &self.config,
            min_cells,
        );
        self.path_peak_per_s = match (hottest, floor) {
            (Some(a), Some(b)) => Some(a.max(b)),
            (a, b) => a.or(b),
        };
        let margin = association_margin_cols(&looming.geometry);
        let slot = self.slot_of(stamp_ns, pair.step_s);
        let mut ended = self.close_stale(slot);
        let sample = Sample {
            pair_index: slot,
            stamp_ns,
            log_time_ns: pair.current_log_time_ns,
            period_ns: ((pair.step_s * 1e9).round() as i64).max(1),
            ego_speed_mps: velocity.map(|v| v.norm()),
        };
        for cluster in clusters {
            self.take(&cluster, &sample, margin);
        }
        ended.sort_by_key(|e| e.id);
        ended
    }

    /// Fold one hot cluster into the track it continues (merging the tracks
    /// it joins), or start a track.
    fn take(&mut self, cluster: &Cluster, sample: &Sample, margin_cols: usize) {
        let matches: Vec<usize> = (0..self.tracks.len())
            .filter(|&t| self.tracks[t].near(cluster, margin_cols))
            .collect();
        // A cluster looming much faster than its range closes is an artefact
        // (the corner of a near object, where an edge cell sees two faces),
        // not an approach: it neither continues nor starts a track.
        if matches
            .iter()
            .any(|&t| !self.tracks[t].plausible(cluster, sample))
        {
            return;
        }
        let index = match matches.split_first() {
            None => {
                self.tracks.push(Track::start(cluster, sample));
                self.tracks.len() - 1
            }
            Some((&first, rest)) => {
                // One object seen as several clusters before: merge them into
                // the oldest (later indices first, so removal keeps the
                // indices valid).
                for &other in rest.iter().rev() {
                    let absorbed = self.tracks.remove(other);
                    self.tracks[first].absorb(absorbed);
                }
                self.tracks[first].extend(sample);
                self.tracks[first].update(cluster, sample);
                first
            }
        };
        let track = &mut self.tracks[index];
        if track.id == 0 && track.run >= self.config.min_pairs {
            track.id = self.next_id;
            self.next_id += 1;
        }
    }

    /// End of the log: every confirmed event still open.
    pub fn finish(&mut self) -> Vec<NearMissEvent> {
        let tracks = std::mem::take(&mut self.tracks);
        let mut events: Vec<NearMissEvent> = tracks
            .into_iter()
            .filter(|t| t.id != 0)
            .map(|t| t.into_event(&self.frame_id, self.corridor_source))
            .collect();
        events.sort_by_key(|e| e.id);
        events
    }

    /// The pair's place in a sequence of scan periods: consecutive pairs count
    /// one apart, pairs after a stretch without pairs (scans dropped beyond
    /// the pairing gap) as many periods apart as their stamps are, so no track
    /// bridges a hole in the log.
    fn slot_of(&mut self, stamp_ns: i64, dt_s: f64) -> u64 {
        let slot = match self.last_slot {
            None => 0,
            Some((slot, last_stamp_ns)) => {
                let periods = (stamp_ns - last_stamp_ns) as f64 * 1e-9 / dt_s.max(1e-6);
                slot + (periods.round() as u64).max(1)
            }
        };
        self.last_slot = Some((slot, stamp_ns));
        slot
    }

    /// Tracks not seen for longer than the gap allows end: confirmed ones as
    /// events, tentative ones silently.
    fn close_stale(&mut self, pair_index: u64) -> Vec<NearMissEvent> {
        let max_gap = self.config.max_gap_pairs;
        let (stale, live): (Vec<Track>, Vec<Track>) =
            std::mem::take(&mut self.tracks).into_iter().partition(|t| {
                let allowed = if t.id == 0 { 0 } else { max_gap };
                pair_index > t.last_pair + 1 + allowed
            });
        self.tracks = live;
        stale
            .into_iter()
            .filter(|t| t.id != 0)
            .map(|t| t.into_event(&self.frame_id, self.corridor_source))
            .collect()
    }
}

/// Slack of the range-rate check, 1/s.
const PLAUSIBILITY_SLACK_PER_S: f64 = 0.3;

/// Columns a cluster may move between pairs and still be the same object:
/// 3 degrees of azimuth (a 20 deg/s turn moves the scene 2 degrees per scan).
fn association_margin_cols(geometry: &ImageGeometry) -> usize {
    let col_deg = 360.0 / geometry.cols as f64;
    ((3.0 / col_deg).ceil() as usize).max(2)
}

struct Sample {
    pair_index: u64,
    stamp_ns: i64,
    log_time_ns: u64,
    period_ns: i64,
    ego_speed_mps: Option<f64>,
}

impl Track {
    fn start(cluster: &Cluster, sample: &Sample) -> Self {
        let mut track = Self {
            id: 0,
            last_pair: sample.pair_index,
            run: 0,
            cols: cluster.cols,
            rows: cluster.rows,
            hot_pairs: 0,
            start: (sample.stamp_ns, sample.log_time_ns),
            last: (sample.stamp_ns, sample.log_time_ns),
            last_period_ns: sample.period_ns,
            peak: peak_of(cluster, sample),
            max_cells: 0,
            moving_cells: 0,
            cells: 0,
            stamps: Vec::new(),
            last_near_range: (sample.stamp_ns, cluster.near_range_m),
            last_looming_per_s: cluster.looming_per_s,
            objects: std::collections::BTreeMap::new(),
        };
        track.extend(sample);
        track.update(cluster, sample);
        track
    }

    /// Whether `cluster` continues this track: its rows and widened columns meet.
    fn near(&self, cluster: &Cluster, margin_cols: usize) -> bool {
        let rows_meet = cluster.rows.0 <= self.rows.1 + 2 && self.rows.0 <= cluster.rows.1 + 2;
        rows_meet && self.cols.overlaps(&cluster.cols, margin_cols)
    }

    /// Whether `cluster`, seen in a later pair, and this track's last
    /// cluster both loom no faster than twice the rate at which the near
    /// range closed between them (plus 0.3 1/s for the noise of a range
    /// percentile). Both ends: a track's first cluster has nothing before it
    /// to be checked against (on a real HDL-64E log a hedge beside the path
    /// read 16 1/s at 2 m in one pair, its range unchanged in the next).
    fn plausible(&self, cluster: &Cluster, sample: &Sample) -> bool {
        let (stamp_ns, near_range_m) = self.last_near_range;
        let dt_s = (sample.stamp_ns - stamp_ns) as f64 * 1e-9;
        if dt_s <= 0.0 || cluster.near_range_m <= 0.0 {
            return true;
        }
        let closing_per_s = (near_range_m - cluster.near_range_m) / (dt_s * cluster.near_range_m);
        let bound_per_s = 2.0 * closing_per_s + PLAUSIBILITY_SLACK_PER_S;
        cluster.looming_per_s <= bound_per_s && self.last_looming_per_s <= bound_per_s
    }

    /// Count a hot pair (once per pair, whatever the number of clusters).
    fn extend(&mut self, sample: &Sample) {
        let counted = self.hot_pairs > 0;
        if counted && sample.pair_index <= self.last_pair {
            return;
        }
        self.run = if counted && sample.pair_index == self.last_pair + 1 {
            self.run + 1
        } else {
            1
        };
        self.hot_pairs += 1;
        if self.stamps.len() < MAX_SCAN_TIMES {
            self.stamps.push((sample.stamp_ns, sample.log_time_ns));
        }
        self.last_pair = sample.pair_index;
        self.last = (sample.stamp_ns, sample.log_time_ns);
        self.last_period_ns = sample.period_ns;
    }

    /// Fold a cluster of the current pair in.
    fn update(&mut self, cluster: &Cluster, sample: &Sample) {
        self.last_near_range = (sample.stamp_ns, cluster.near_range_m);
        self.last_looming_per_s = cluster.looming_per_s;
        self.cols = cluster.cols;
        self.rows = cluster.rows;
        self.max_cells = self.max_cells.max(cluster.cells);
        self.cells += cluster.cells;
        self.moving_cells += cluster.moving_cells;
        if let Some(id) = cluster.object_id {
            *self.objects.entry(id).or_default() += 1;
        }
        if cluster.looming_per_s > self.peak.looming_per_s {
            self.peak = peak_of(cluster, sample);
        }
    }

    /// Take over another track of the same object.
    fn absorb(&mut self, other: Track) {
        if other.start.0 < self.start.0 {
            self.start = other.start;
        }
        if self.id == 0 || (other.id != 0 && other.id < self.id) {
            self.id = other.id;
        }
        self.run = self.run.max(other.run);
        self.hot_pairs = self.hot_pairs.max(other.hot_pairs);
        if other.last_pair > self.last_pair {
            self.last_pair = other.last_pair;
            self.last = other.last;
            self.last_period_ns = other.last_period_ns;
        }
        self.max_cells = self.max_cells.max(other.max_cells);
        self.cells += other.cells;
        self.moving_cells += other.moving_cells;
        if other.peak.looming_per_s > self.peak.looming_per_s {
            self.peak = other.peak;
        }
        for (id, pairs) in other.objects {
            *self.objects.entry(id).or_default() += pairs;
        }
        let mut stamps = std::mem::take(&mut self.stamps);
        stamps.extend(other.stamps);
        stamps.sort_unstable();
        stamps.dedup();
        stamps.truncate(MAX_SCAN_TIMES);
        self.stamps = stamps;
    }

    fn into_event(self, frame_id: &str, corridor: PathSource) -> NearMissEvent {
        let moving_fraction = if self.cells > 0 {
            self.moving_cells as f64 / self.cells as f64
        } else {
            0.0
        };
        let end_ns = self.last.0 + self.last_period_ns;
        NearMissEvent {
            id: self.id,
            start_ns: self.start.0,
            end_ns,
            start_log_time_ns: self.start.1,
            end_log_time_ns: self.last.1,
            duration_s: (end_ns - self.start.0) as f64 * 1e-9,
            hot_pairs: self.hot_pairs,
            peak_looming_per_s: self.peak.looming_per_s,
            min_time_to_contact_s: 1.0 / self.peak.looming_per_s,
            max_cluster_cells: self.max_cells,
            moving_fraction,
            moving: moving_fraction >= 0.5,
            frame_id: frame_id.to_string(),
            corridor,
            object_id: most_frequent(&self.objects),
            sensors: Vec::new(),
            sensor: None,
            scan_stamps_ns: self.stamps.iter().map(|s| s.0).collect(),
            scan_log_times_ns: self.stamps.iter().map(|s| s.1).collect(),
            peak: self.peak,
        }
    }
}

/// The key counted most (the smallest of equals).
fn most_frequent(counts: &std::collections::BTreeMap<u32, u64>) -> Option<u32> {
    counts
        .iter()
        .max_by(|a, b| a.1.cmp(b.1).then(b.0.cmp(a.0)))
        .map(|(&id, _)| id)
}

fn peak_of(cluster: &Cluster, sample: &Sample) -> EventPeak {
    let (azimuth_deg, elevation_deg) = cluster.bearing_deg();
    EventPeak {
        stamp_ns: sample.stamp_ns,
        log_time_ns: sample.log_time_ns,
        looming_per_s: cluster.looming_per_s,
        azimuth_deg,
        elevation_deg,
        range_m: cluster.range_m,
        position_m: cluster.centroid_m,
        lateral_offset_m: cluster.lateral_offset_m,
        ego_speed_mps: sample.ego_speed_mps,
        cluster_cells: cluster.cells,
        object_id: cluster.object_id,
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    const PERIOD_NS: i64 = 100_000_000;

    /// A cluster at columns 100-109 of a 512-column image, rows 10-15.
    fn cluster(looming_per_s: f64, near_range_m: f64) -> Cluster {
        Cluster {
            cells: 60,
            rows: (10, 15),
            cols: ColSpan {
                start: 100,
                len: 10,
                cols: 512,
            },
            looming_per_s,
            centroid_m: [near_range_m, 0.0, 0.0],
            range_m: near_range_m + 0.2,
            near_range_m,
            lateral_offset_m: 0.0,
            object_id: Some(7),
            moving_cells: 40,
        }
    }

    fn sample(pair_index: u64) -> Sample {
        Sample {
            pair_index,
            stamp_ns: pair_index as i64 * PERIOD_NS,
            log_time_ns: pair_index * PERIOD_NS as u64,
            period_ns: PERIOD_NS,
            ego_speed_mps: Some(10.0),
        }
    }

    /// Run the detector over pairs 0.. with at most one cluster each
    /// (`None`: nothing hot); returns every event.
    fn detect(pairs: &[Option<Cluster>]) -> Vec<NearMissEvent> {
        let mut detector = EventDetector::new(EventConfig::default());
        let mut events = Vec::new();
        for (index, cluster) in pairs.iter().enumerate() {
            events.extend(detector.close_stale(index as u64));
            if let Some(cluster) = cluster {
                detector.take(cluster, &sample(index as u64), 4);
            }
        }
        events.extend(detector.finish());
        events
    }

    /// An object closing at 8 m/s from `start_m`: its looming and near range
    /// at pair `k`.
    fn approaching(start_m: f64, k: usize) -> Cluster {
        let range = start_m - 0.8 * k as f64;
        cluster(8.0 / range, range)
    }

    #[test]
    fn one_hot_pair_is_no_event_two_are() {
        assert!(detect(&[None, Some(approaching(10.0, 1)), None, None]).is_empty());
        let events = detect(&[None, Some(approaching(10.0, 1)), Some(approaching(10.0, 2))]);
        assert_eq!(events.len(), 1);
        let event = &events[0];
        assert_eq!(
            (event.id, event.start_ns, event.hot_pairs),
            (1, PERIOD_NS, 2)
        );
        assert_eq!(event.end_ns, 3 * PERIOD_NS);
        // The peak is the later, closer pair.
        assert!((event.peak_looming_per_s - 8.0 / 8.4).abs() < 1e-12);
        assert!((event.min_time_to_contact_s - 8.4 / 8.0).abs() < 1e-12);
        assert!(event.moving && (event.moving_fraction - 40.0 / 60.0).abs() < 1e-12);
        // It names the object its clusters lay on.
        assert_eq!(event.object_id, Some(7));
        assert_eq!(event.peak.object_id, Some(7));
    }

    #[test]
    fn the_swept_path_is_the_vehicle_plus_its_margin() {
        let config = EventConfig::default();
        assert!((config.corridor_half_width_m() - 1.45).abs() < 1e-12);
        let wide = EventConfig {
            vehicle_width_m: 2.5,
            path_margin_m: 1.0,
            ..config
        };
        assert!((wide.corridor_half_width_m() - 2.25).abs() < 1e-12);
    }

    #[test]
    fn the_object_counted_most_names_the_event() {
        let counts = std::collections::BTreeMap::from([(3, 2), (5, 4), (9, 4)]);
        assert_eq!(most_frequent(&counts), Some(5));
        assert_eq!(most_frequent(&std::collections::BTreeMap::new()), None);
    }

    #[test]
    fn one_missed_pair_is_bridged_two_end_the_event() {
        let bridged = detect(&[
            Some(approaching(12.0, 0)),
            Some(approaching(12.0, 1)),
            None,
            Some(approaching(12.0, 3)),
        ]);
        assert_eq!(bridged.len(), 1);
        assert_eq!(bridged[0].hot_pairs, 3);
        assert_eq!(bridged[0].scan_stamps_ns, vec![0, PERIOD_NS, 3 * PERIOD_NS]);
        let split = detect(&[
            Some(approaching(12.0, 0)),
            Some(approaching(12.0, 1)),
            None,
            None,
            Some(approaching(12.0, 4)),
            Some(approaching(12.0, 5)),
        ]);
        assert_eq!(split.len(), 2);
        assert_eq!((split[0].id, split[1].id), (1, 2));
        assert_eq!(split[1].start_ns, 4 * PERIOD_NS);
    }

    #[test]
    fn a_tentative_track_must_persist_without_a_gap() {
        let events = detect(&[Some(approaching(12.0, 0)), None, Some(approaching(12.0, 2))]);
        assert!(events.is_empty());
    }

    #[test]
    fn looming_far_faster_than_the_range_closes_is_not_an_approach() {
        // The near range stays at 3.3 m while the cluster reads 7 1/s: the
        // corner of a near object, not something closing at 23 m/s.
        let corner = |_: usize| cluster(7.0, 3.3);
        let events = detect(&[
            Some(approaching(4.2, 0)),
            Some(approaching(4.2, 1)),
            Some(corner(2)),
            Some(corner(3)),
        ]);
        assert_eq!(events.len(), 1);
        assert_eq!(events[0].hot_pairs, 2, "{:?}", events[0]);
        assert!((events[0].peak_looming_per_s - 8.0 / 3.4).abs() < 1e-12);
    }

    #[test]
    fn a_first_cluster_the_next_range_belies_does_not_start_an_event() {
        // A hedge 2 m beside the path: one pair reads 16 1/s, the next pair
        // sees it at the same range reading 1 1/s. Neither end is an approach
        // at 16 1/s, so the track is not continued and no event starts.
        let hedge_spike = cluster(16.0, 2.0);
        let hedge_after = cluster(1.0, 1.98);
        assert!(detect(&[Some(hedge_spike), Some(hedge_after.clone())]).is_empty());
        // The same second pair after a first one that its range bears out is
        // an event.
        let events = detect(&[Some(cluster(1.0, 2.1)), Some(hedge_after)]);
        assert_eq!(events.len(), 1);
    }

    #[test]
    fn clusters_of_one_object_merge_into_the_oldest_track() {
        let mut detector = EventDetector::new(EventConfig::default());
        // The object approaching over columns `start..start + len`.
        let at = |start: usize, len: usize, k: usize| Cluster {
            cols: ColSpan {
                start,
                len,
                cols: 512,
            },
            ..approaching(12.0, k)
        };
        let left = |k| at(100, 10, k);
        let right = |k| at(130, 10, k);
        let whole = |k| at(100, 40, k);
        detector.take(&left(0), &sample(0), 4);
        detector.take(&right(0), &sample(0), 4);
        assert_eq!(detector.tracks.len(), 2);
        detector.close_stale(1);
        detector.take(&whole(1), &sample(1), 4);
        assert_eq!(detector.tracks.len(), 1);
        let events = detector.finish();
        assert_eq!(events.len(), 1);
        assert_eq!((events[0].start_ns, events[0].hot_pairs), (0, 2));
    }

    #[test]
    fn the_default_smallest_cluster_follows_the_resolution() {
        let geometry = |rows: usize, cols: usize| ImageGeometry {
            rows,
            cols,
            beams: crate::engine::beams::BeamTable {
                elevations_rad: (0..rows)
                    .map(|r| (-24.9 + 26.8 * r as f64 / (rows - 1) as f64).to_radians())
                    .collect(),
            },
            ring_to_row: None,
            parallax_rad_m: None,
        };
        assert_eq!(default_min_cells(&geometry(64, 2048)), 40);
        assert_eq!(default_min_cells(&geometry(32, 512)), 5);
        assert_eq!(default_min_cells(&geometry(16, 256)), 3);
    }

    #[test]
    fn pairs_after_a_hole_in_the_log_are_as_many_slots_apart_as_periods() {
        let mut detector = EventDetector::new(EventConfig::default());
        assert_eq!(detector.slot_of(0, 0.1), 0);
        assert_eq!(detector.slot_of(PERIOD_NS, 0.1), 1);
        // Jitter does not skip a slot; ten dropped scans skip ten.
        assert_eq!(detector.slot_of(2 * PERIOD_NS + 20_000_000, 0.1), 2);
        assert_eq!(detector.slot_of(13 * PERIOD_NS, 0.1), 13);
    }

    #[test]
    fn events_rank_by_time_to_contact() {
        let mut events = detect(&[
            Some(approaching(12.0, 0)),
            Some(approaching(12.0, 1)),
            None,
            None,
            Some(approaching(6.0, 0)),
            Some(approaching(6.0, 1)),
        ]);
        rank(&mut events);
        assert_eq!(events[0].id, 2);
        assert!(events[0].min_time_to_contact_s < events[1].min_time_to_contact_s);
    }
}
