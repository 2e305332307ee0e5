//! The classic baseline: the time to contact of the nearest points in the
//! ego lane, per scan, as most TTC pipelines compute it, beside looming's
//! own results. A development tool:
//! `cargo run --release --example baseline_ttc -- LOG.mcap [--lane-half-width 1.5] [--lane-x-min 0.5] [--json OUT.json]`
//! (`scripts/baseline.sh` runs it on the scenarios and the KITTI logs).
//!
//! The ego lane, per scan: points with x > 0.5 m (`--lane-x-min`; the ego
//! body is not cropped), |y| <= the lane half width
//! (default 1.5 m: a 1.8 m wide car plus 0.6 m of margin) and z between
//! 0.3 m and 2.5 m above the ground. The axes are the LiDAR's, rotated by the
//! mount rotation of the log's extrinsic (`/tf_static`) when it has one, so
//! that x is the vehicle's forward axis and z its up (the synthetic mount is
//! yawed 4 degrees and pitched -1.5: in raw LiDAR axes the lane would drift
//! 1.4 m sideways and the ground tilt by 0.5 m over 20 m); without an extrinsic
//! (the KITTI logs) the raw LiDAR axes; `--raw-lidar-frame` forces those.
//! The ground height is estimated per scan, not taken from the sensor height,
//! so a pitched or differently mounted sensor needs nothing: the median z
//! of the lowest 20 % of the points with |y| < 3 m and 3 < x < 15 m (the
//! previous scan's estimate when fewer than 10 such points).
//!
//! The nearest distance is the 2nd-percentile x of the lane points (a stray
//! return does not set it), with at least 10 lane points, else none. Baseline
//! looming = -(x_now - x_before) / (dt x_now) over consecutive scans (dt from
//! their stamps), TTC = 1 / looming when positive. A baseline event follows
//! looming's own rule (`events::EventDetector`): looming >= 1 / 1.5 s (the
//! default `--event-ttc`) in >= 2 consecutive pairs; it starts at its first
//! hot pair, survives one pair that is not hot and ends after two.
//!
//! References. On a synthetic log (`/truth/points`): the median true ray
//! looming of the lane points within 0.5 m of the nearest distance (what the
//! baseline claims to measure) and the planted near misses of
//! `/truth/events`. Otherwise the rear-face reference of
//! `examples/face_probe.rs` (box x 2-25 m, |y| < 1 m, z -1.4..0.5 m, raw
//! LiDAR axes; face = box points within 0.5 m of its 5th-percentile x;
//! reference = -(d_now - d_before) / (dt d_now) of the face's median x).
//! Looming's own value for the same points is reported beside the baseline:
//! the engine's object looming (`objects`) of the object most of those points
//! belong to.

use std::collections::BTreeMap;
use std::path::PathBuf;

use clap::Parser;
use looming::engine::{self, EngineCache, EngineConfig, PairLooming};
use looming::input::{InputFile, InputMessage};
use looming::model::{Scan, ScanPair};
use looming::objects::{ObjectConfig, ObjectTracker, PairObjects};
use looming::synth::TruthEvent;
use nalgebra::{UnitQuaternion, Vector3};
use serde::Serialize;

/// Looming's default near-miss threshold, as a time to contact.
const EVENT_TTC_S: f64 = 1.5;
/// Consecutive hot pairs before a run of hot pairs is an event (looming's default).
const EVENT_MIN_PAIRS: u64 = 2;
/// Pairs an event may miss without ending (looming's rule).
const EVENT_MAX_GAP_PAIRS: u64 = 1;
/// Lane points lie this high above the ground: above kerbs and road relief,
/// below bridges and signs.
const LANE_Z_ABOVE_GROUND_M: (f32, f32) = (0.3, 2.5);
/// The nearest distance is this quantile of the lane points' x.
const NEAREST_QUANTILE: f64 = 0.02;
/// Fewer lane points than this: no nearest distance.
const MIN_LANE_POINTS: usize = 10;
/// The nearest object's points: within this of the nearest distance.
const NEAR_BAND_M: f32 = 0.5;

#[derive(Parser)]
#[command(about = "Nearest-in-lane TTC baseline beside looming's results")]
struct Args {
    /// A log (`looming synth` drive or real recording).
    log: PathBuf,
    /// Half width of the ego lane, metres (1.8 m car + margin).
    #[arg(long, default_value_t = 1.5)]
    lane_half_width: f32,
    /// Where the lane starts ahead of the sensor, metres. Past the sensor's
    /// own housing; the ego body is not cropped (KITTI's right mirror, 1.5 m
    /// ahead and 1.05 m right, is in the default lane).
    #[arg(long, default_value_t = 0.5)]
    lane_x_min: f32,
    /// Also write the per-pair series and the summary here.
    #[arg(long)]
    json: Option<PathBuf>,
    /// Gate the lane in the raw LiDAR axes even where the log has an extrinsic.
    #[arg(long)]
    raw_lidar_frame: bool,
}

fn main() -> anyhow::Result<()> {
    let args = Args::parse();
    let run = replay(&args)?;
    let summary = Summary::of(&args, &run);
    print_rows(&run.rows);
    print_summary(&summary);
    if let Some(path) = &args.json {
        let json = serde_json::json!({ "summary": summary, "pairs": run.rows });
        std::fs::write(path, serde_json::to_string_pretty(&json)?)?;
    }
    Ok(())
}

// ---------------------------------------------------------------- the lane

/// One scan's ego lane, in the lane axes.
struct LaneView {
    ground_z_m: Option<f32>,
    /// Point indices (into the scan) of the lane points, and their x.
    points: Vec<(usize, f32)>,
    nearest_m: Option<f32>,
}

impl LaneView {
    /// Indices of the lane points within [`NEAR_BAND_M`] of the nearest distance.
    fn near_points(&self) -> Vec<usize> {
        let Some(nearest_m) = self.nearest_m else {
            return Vec::new();
        };
        self.points
            .iter()
            .filter(|(_, x_m)| (x_m - nearest_m).abs() <= NEAR_BAND_M)
            .map(|&(i, _)| i)
            .collect()
    }
}

/// Nearest-rank quantile (sorts `values`); NaN when empty.
fn quantile(values: &mut [f32], q: f64) -> f32 {
    values.sort_by(f32::total_cmp);
    let at = ((values.len() as f64 - 1.0) * q).round() as usize;
    values.get(at).copied().unwrap_or(f32::NAN)
}

/// Ground height: the median z of the lowest 20 % of the points on the road
/// just ahead (|y| < 3 m, 3 < x < 15 m), where a road return is likeliest.
fn ground_z_m(points: &[[f32; 3]]) -> Option<f32> {
    let mut z_m: Vec<f32> = points
        .iter()
        .filter(|p| p[1].abs() < 3.0 && p[0] > 3.0 && p[0] < 15.0)
        .map(|p| p[2])
        .collect();
    if z_m.len() < MIN_LANE_POINTS {
        return None;
    }
    z_m.sort_by(f32::total_cmp);
    let lowest_count = z_m.len().div_ceil(5);
    Some(quantile(&mut z_m[..lowest_count], 0.5))
}

/// The scan's points in the lane axes (the mount rotation taken out).
fn lane_axes(scan: &Scan, rotation: &UnitQuaternion<f32>) -> Vec<[f32; 3]> {
    scan.points_m
        .iter()
        .map(|p| (rotation * Vector3::from(*p)).into())
        .collect()
}

/// The lane's extent: ahead of `x_min_m`, within `half_width_m` of the axis.
#[derive(Clone, Copy)]
struct LaneGate {
    x_min_m: f32,
    half_width_m: f32,
}

fn lane_view(points: &[[f32; 3]], gate: LaneGate, ground_fallback_m: Option<f32>) -> LaneView {
    let ground_z_m = ground_z_m(points).or(ground_fallback_m);
    let Some(ground) = ground_z_m else {
        return LaneView {
            ground_z_m,
            points: Vec::new(),
            nearest_m: None,
        };
    };
    let z_range = (ground + LANE_Z_ABOVE_GROUND_M.0)..=(ground + LANE_Z_ABOVE_GROUND_M.1);
    let lane: Vec<(usize, f32)> = points
        .iter()
        .enumerate()
        .filter(|(_, p)| p[0] > gate.x_min_m && p[1].abs() <= gate.half_width_m)
        .filter(|(_, p)| z_range.contains(&p[2]))
        .map(|(i, p)| (i, p[0]))
        .collect();
    let nearest_m = (lane.len() >= MIN_LANE_POINTS).then(|| {
        let mut x_m: Vec<f32> = lane.iter().map(|&(_, x)| x).collect();
        quantile(&mut x_m, NEAREST_QUANTILE)
    });
    LaneView {
        ground_z_m,
        points: lane,
        nearest_m,
    }
}

/// Looming from two distances along the same axis, 1/s.
fn looming_per_s(before_m: f64, now_m: f64, dt_s: f64) -> f64 {
    -(now_m - before_m) / (dt_s * now_m)
}

// ------------------------------------------------------- the face reference

/// `examples/face_probe.rs`'s rear face: the median x of the points within
/// 0.5 m of the 5th-percentile x in its box (raw LiDAR axes).
fn face_distance_m(scan: &Scan) -> Option<f64> {
    let mut x_m: Vec<f32> = scan
        .points_m
        .iter()
        .filter(|p| (2.0..25.0).contains(&p[0]) && p[1].abs() < 1.0 && (-1.4..0.5).contains(&p[2]))
        .map(|p| p[0])
        .collect();
    if x_m.len() < MIN_LANE_POINTS {
        return None;
    }
    let near_m = quantile(&mut x_m, 0.05);
    let mut face: Vec<f32> = x_m.into_iter().filter(|&x| x <= near_m + 0.5).collect();
    Some(f64::from(quantile(&mut face, 0.5)))
}

// ------------------------------------------------------------------ truth

/// The truth of one scan, per input point index.
struct ScanTruth {
    ray_looming_per_s: Vec<f32>,
    object_id: Vec<u32>,
}

/// `/truth/points` and `/truth/events` as they stream past.
#[derive(Default)]
struct TruthStore {
    points_channel: Option<u16>,
    events_channel: Option<u16>,
    scans: BTreeMap<i64, ScanTruth>,
    events: Vec<TruthEvent>,
    failure: Option<String>,
}

impl TruthStore {
    fn new(input: &InputFile) -> Self {
        let channel = |topic: &str| {
            input
                .catalog()
                .channels
                .values()
                .find(|c| c.topic == topic)
                .map(|c| c.id)
        };
        Self {
            points_channel: channel(looming::truth::POINTS_TOPIC),
            events_channel: channel(looming::truth::EVENTS_TOPIC),
            ..Self::default()
        }
    }

    fn on_message(&mut self, message: &InputMessage) {
        let id = Some(message.channel_id);
        if id == self.points_channel {
            match decode_truth(&message.data) {
                Ok((stamp_ns, truth)) => {
                    self.scans.insert(stamp_ns, truth);
                }
                Err(e) => self.failure = Some(e),
            }
        } else if id == self.events_channel {
            match serde_json::from_slice(&message.data) {
                Ok(event) => self.events.push(event),
                Err(e) => self.failure = Some(format!("/truth/events: {e}")),
            }
        }
    }

    /// The truth of the pair's current scan; older scans are dropped.
    fn for_pair(&mut self, pair: &ScanPair) -> Option<&ScanTruth> {
        self.scans = self.scans.split_off(&pair.previous.stamp_ns);
        self.scans.get(&pair.current.stamp_ns)
    }
}

/// `looming::truth::decode_points` for the ray looming; the object id, which
/// its `PointTruth` leaves out, read here by field name.
fn decode_truth(payload: &[u8]) -> Result<(i64, ScanTruth), String> {
    let (stamp_ns, points) = looming::truth::decode_points(payload)?;
    let cloud = looming::ros::msgs::PointCloud2::decode_cdr(payload).map_err(|e| e.to_string())?;
    let offset = cloud
        .fields
        .iter()
        .find(|f| f.name == "object_id")
        .map(|f| f.offset as usize)
        .ok_or("/truth/points has no `object_id` field")?;
    let step = cloud.point_step as usize;
    let object_id = (0..points.len())
        .map(|i| {
            let at = i * step + offset;
            let bytes = cloud
                .data
                .get(at..at + 4)
                .ok_or("object_id beyond the data")?;
            Ok(u32::from_le_bytes(bytes.try_into().expect("4 bytes")))
        })
        .collect::<Result<Vec<u32>, String>>()?;
    let ray_looming_per_s = points.iter().map(|p| p.ray_looming).collect();
    Ok((
        stamp_ns,
        ScanTruth {
            ray_looming_per_s,
            object_id,
        },
    ))
}

/// The true ray looming of the near points (median) and their most common object.
fn truth_of_near(scan: &Scan, near: &[usize], truth: &ScanTruth) -> (Option<f64>, Option<u32>) {
    let of = |i: usize| scan.source_index.get(i).map(|&s| s as usize);
    let mut looming: Vec<f32> = near
        .iter()
        .filter_map(|&i| truth.ray_looming_per_s.get(of(i)?).copied())
        .filter(|l| l.is_finite())
        .collect();
    let ids: Vec<Option<u32>> = near
        .iter()
        .map(|&i| truth.object_id.get(of(i)?).copied())
        .collect();
    let median = (!looming.is_empty()).then(|| f64::from(quantile(&mut looming, 0.5)));
    (median, most_common(&ids))
}

fn most_common(ids: &[Option<u32>]) -> Option<u32> {
    let mut counts = BTreeMap::new();
    for id in ids.iter().flatten() {
        *counts.entry(*id).or_insert(0usize) += 1;
    }
    counts.into_iter().max_by_key(|&(_, n)| n).map(|(id, _)| id)
}

// --------------------------------------------------------------- the replay

/// One scan pair: the baseline, its reference and looming's value.
#[derive(Serialize, Clone, Default)]
struct PairRow {
    /// The current scan's stamp: drive time on a synthetic log, else from
    /// the first scan.
    time_s: f64,
    dt_s: f64,
    lane_points: usize,
    ground_z_m: Option<f32>,
    nearest_before_m: Option<f64>,
    nearest_now_m: Option<f64>,
    baseline_looming_per_s: Option<f64>,
    baseline_ttc_s: Option<f64>,
    /// Truth (synthetic) or the face reference (real logs).
    reference_looming_per_s: Option<f64>,
    truth_object_id: Option<u32>,
    face_distance_m: Option<f64>,
    /// The engine's object looming of the object most near points belong to.
    looming_object_per_s: Option<f64>,
    baseline_error_per_s: Option<f64>,
    looming_error_per_s: Option<f64>,
}

struct Run {
    /// Stamp of time 0: the drive start (synthetic), else the first scan.
    origin_ns: Option<i64>,
    rows: Vec<PairRow>,
    planted: Vec<TruthEvent>,
    has_truth: bool,
    frame: &'static str,
}

/// What the replay carries from pair to pair.
struct State<'a> {
    args: &'a Args,
    config: EngineConfig,
    cache: EngineCache,
    tracker: ObjectTracker,
    ground_z_m: Option<f32>,
    origin_ns: Option<i64>,
    /// The log has `/truth/points`: the reference is the truth, never the face.
    has_truth: bool,
    rows: Vec<PairRow>,
    frame: &'static str,
}

fn replay(args: &Args) -> anyhow::Result<Run> {
    let input = InputFile::open(&args.log, Default::default())?;
    let truth = std::cell::RefCell::new(TruthStore::new(&input));
    let has_truth = truth.borrow().points_channel.is_some();
    let mut state = State {
        args,
        config: EngineConfig::default(),
        cache: EngineCache::default(),
        tracker: ObjectTracker::default(),
        ground_z_m: None,
        origin_ns: has_truth.then_some(looming::synth::START_NS),
        has_truth,
        rows: Vec::new(),
        frame: "lidar",
    };
    looming::pipeline::replay_input(
        &input,
        &looming::pipeline::ScanOptions::default(),
        &mut |message| truth.borrow_mut().on_message(message),
        &mut |pair| {
            let mut truth = truth.borrow_mut();
            let row = state.pair_row(&pair, truth.for_pair(&pair));
            state.rows.push(row);
        },
    )?;
    let truth = truth.into_inner();
    if let Some(failure) = truth.failure {
        anyhow::bail!("{}: {failure}", args.log.display());
    }
    Ok(Run {
        origin_ns: state.origin_ns,
        rows: state.rows,
        planted: truth.events,
        has_truth,
        frame: state.frame,
    })
}

impl State<'_> {
    /// The mount rotation that turns LiDAR axes into vehicle axes, if known.
    fn rotation(&mut self, pair: &ScanPair) -> UnitQuaternion<f32> {
        let motion = &pair.motion;
        let extrinsic = motion
            .velocity_extrinsic
            .as_ref()
            .or(motion.imu_extrinsic.as_ref());
        match extrinsic {
            Some(e) if !self.args.raw_lidar_frame => {
                self.frame = "vehicle axes (extrinsic rotation)";
                nalgebra::convert(e.motion_from_lidar.rotation)
            }
            _ => UnitQuaternion::identity(),
        }
    }

    fn lane(&mut self, scan: &Scan, rotation: &UnitQuaternion<f32>) -> LaneView {
        let gate = LaneGate {
            x_min_m: self.args.lane_x_min,
            half_width_m: self.args.lane_half_width,
        };
        let view = lane_view(&lane_axes(scan, rotation), gate, self.ground_z_m);
        self.ground_z_m = view.ground_z_m;
        view
    }

    fn pair_row(&mut self, pair: &ScanPair, truth: Option<&ScanTruth>) -> PairRow {
        let rotation = self.rotation(pair);
        let before = self.lane(&pair.previous, &rotation);
        let now = self.lane(&pair.current, &rotation);
        let origin_ns = *self.origin_ns.get_or_insert(pair.previous.stamp_ns);
        let dt_s = pair.dt_s;
        let nearest_before_m = before.nearest_m.map(f64::from);
        let nearest_now_m = now.nearest_m.map(f64::from);
        let baseline = nearest_before_m
            .zip(nearest_now_m)
            .map(|(b, n)| looming_per_s(b, n, dt_s));
        let near = now.near_points();
        let mut row = PairRow {
            time_s: (pair.current.stamp_ns - origin_ns) as f64 * 1e-9,
            dt_s,
            lane_points: now.points.len(),
            ground_z_m: now.ground_z_m,
            nearest_before_m,
            nearest_now_m,
            baseline_looming_per_s: baseline,
            baseline_ttc_s: baseline.filter(|&l| l > 0.0).map(|l| 1.0 / l),
            looming_object_per_s: self.engine_object_looming(pair, &near),
            ..PairRow::default()
        };
        self.add_reference(&mut row, pair, &near, truth);
        row
    }

    /// Truth on a synthetic log, else the face reference; and both errors.
    fn add_reference(
        &self,
        row: &mut PairRow,
        pair: &ScanPair,
        near: &[usize],
        truth: Option<&ScanTruth>,
    ) {
        if let Some(truth) = truth {
            (row.reference_looming_per_s, row.truth_object_id) =
                truth_of_near(&pair.current, near, truth);
        } else if !self.has_truth {
            let faces = face_distance_m(&pair.previous).zip(face_distance_m(&pair.current));
            row.face_distance_m = faces.map(|(_, now)| now);
            row.reference_looming_per_s = faces
                .filter(|_| pair.dt_s <= 0.25)
                .map(|(before, now)| looming_per_s(before, now, pair.dt_s));
        }
        let error = |value: Option<f64>| {
            value
                .zip(row.reference_looming_per_s)
                .map(|(v, r)| (v - r).abs())
        };
        row.baseline_error_per_s = error(row.baseline_looming_per_s);
        row.looming_error_per_s = error(row.looming_object_per_s);
    }

    /// Looming's answer for the same points: the engine and the object
    /// tracker as `looming process` runs them, the object most near points
    /// belong to, its looming.
    fn engine_object_looming(&mut self, pair: &ScanPair, near: &[usize]) -> Option<f64> {
        let result: PairLooming = engine::compute_with_cache(pair, &self.config, &mut self.cache)?;
        let mut objects = PairObjects::find(&pair.current, &result, &ObjectConfig::default());
        self.tracker.update(&mut objects, &result, pair.step_s);
        let ids: Vec<Option<u32>> = near
            .iter()
            .map(|&i| objects.object_of_point(&result, i))
            .collect();
        let id = most_common(&ids)?;
        objects
            .objects
            .iter()
            .find(|o| o.id == id)
            .and_then(|o| o.looming_per_s)
    }
}

// ------------------------------------------------------------------ events

/// A baseline near miss.
#[derive(Serialize, Clone)]
struct BaselineEvent {
    start_s: f64,
    /// The last hot pair's stamp plus one scan period.
    end_s: f64,
    hot_pairs: u64,
    peak_looming_per_s: f64,
    min_ttc_s: f64,
}

/// Runs of hot pairs (baseline looming >= 1 / [`EVENT_TTC_S`]) with gaps of
/// at most [`EVENT_MAX_GAP_PAIRS`], counted in scan periods from the stamps
/// (a hole in the log ends a run); a run is an event once it holds
/// [`EVENT_MIN_PAIRS`] consecutive hot pairs.
fn baseline_events(rows: &[PairRow]) -> Vec<BaselineEvent> {
    let period_s = median_dt_s(rows);
    let threshold_per_s = 1.0 / EVENT_TTC_S;
    let slot = |row: &PairRow| ((row.time_s - rows[0].time_s) / period_s).round() as u64;
    let hot: Vec<(u64, &PairRow, f64)> = rows
        .iter()
        .filter_map(|r| Some((slot(r), r, r.baseline_looming_per_s?)))
        .filter(|&(_, _, l)| l >= threshold_per_s)
        .collect();
    let mut events = Vec::new();
    let mut run: Vec<(u64, &PairRow, f64)> = Vec::new();
    for item in hot {
        if run
            .last()
            .is_some_and(|last| item.0 > last.0 + 1 + EVENT_MAX_GAP_PAIRS)
        {
            events.extend(event_of(&run, period_s));
            run.clear();
        }
        run.push(item);
    }
    events.extend(event_of(&run, period_s));
    events
}

fn event_of(run: &[(u64, &PairRow, f64)], period_s: f64) -> Option<BaselineEvent> {
    let longest = run
        .iter()
        .scan((0u64, None::<u64>), |(streak, last), &(slot, _, _)| {
            *streak = if *last == Some(slot.wrapping_sub(1)) {
                *streak + 1
            } else {
                1
            };
            *last = Some(slot);
            Some(*streak)
        })
        .max()?;
    if longest < EVENT_MIN_PAIRS {
        return None;
    }
    let peak_looming_per_s = run.iter().map(|r| r.2).fold(f64::MIN, f64::max);
    Some(BaselineEvent {
        start_s: run[0].1.time_s,
        end_s: run[run.len() - 1].1.time_s + period_s,
        hot_pairs: run.len() as u64,
        peak_looming_per_s,
        min_ttc_s: 1.0 / peak_looming_per_s,
    })
}

fn median_dt_s(rows: &[PairRow]) -> f64 {
    let mut dt_s: Vec<f32> = rows.iter().map(|r| r.dt_s as f32).collect();
    f64::from(quantile(&mut dt_s, 0.5))
}

/// One planted near miss and what the baseline made of it.
#[derive(Serialize)]
struct PlantedMatch {
    label: String,
    start_s: f64,
    end_s: f64,
    min_ttc_s: f64,
    /// The first baseline event overlapping the planted window: its index
    /// in `baseline_events` (one event may cover several windows).
    baseline_event: Option<usize>,
    baseline_start_s: Option<f64>,
    baseline_delay_s: Option<f64>,
    baseline_min_ttc_s: Option<f64>,
}

fn overlaps(event: &BaselineEvent, planted: &TruthEvent) -> bool {
    event.start_s < planted.end_s && planted.start_s < event.end_s
}

fn match_planted(planted: &[TruthEvent], events: &[BaselineEvent]) -> Vec<PlantedMatch> {
    planted
        .iter()
        .map(|p| {
            let index = events.iter().position(|e| overlaps(e, p));
            let found = index.map(|i| &events[i]);
            PlantedMatch {
                label: p.label.clone(),
                start_s: p.start_s,
                end_s: p.end_s,
                min_ttc_s: p.min_time_to_contact_s,
                baseline_event: index,
                baseline_start_s: found.map(|e| e.start_s),
                baseline_delay_s: found.map(|e| e.start_s - p.start_s),
                baseline_min_ttc_s: found.map(|e| e.min_ttc_s),
            }
        })
        .collect()
}

// ----------------------------------------------------------------- summary

/// Median and 90th percentile of |error|, 1/s.
#[derive(Serialize)]
struct ErrorStats {
    median_per_s: Option<f64>,
    p90_per_s: Option<f64>,
    pairs: usize,
}

impl ErrorStats {
    fn of(values: impl Iterator<Item = Option<f64>>) -> Self {
        let mut v: Vec<f32> = values.flatten().map(|e| e as f32).collect();
        let stat = |v: &mut [f32], q| (!v.is_empty()).then(|| f64::from(quantile(v, q)));
        Self {
            median_per_s: stat(&mut v, 0.5),
            p90_per_s: stat(&mut v, 0.9),
            pairs: v.len(),
        }
    }
}

#[derive(Serialize)]
struct Summary {
    log: String,
    /// Stamp of time 0 of every `*_s` time here, ns.
    time_origin_ns: Option<i64>,
    lane_half_width_m: f32,
    lane_x_min_m: f32,
    lane_axes: &'static str,
    /// `truth` (synthetic: the near points' true ray looming) or `face`.
    reference: &'static str,
    pairs: usize,
    pairs_with_baseline: usize,
    pairs_with_reference: usize,
    baseline_error: ErrorStats,
    /// The same pairs, looming's object value (where it has one).
    looming_object_error: ErrorStats,
    /// Looming's error over only the pairs where both have a value.
    baseline_error_common: ErrorStats,
    looming_object_error_common: ErrorStats,
    min_reference_ttc_s: Option<f64>,
    baseline_events: Vec<BaselineEvent>,
    planted: Vec<PlantedMatch>,
    /// Baseline events overlapping no planted window.
    baseline_false_events: usize,
}

impl Summary {
    fn of(args: &Args, run: &Run) -> Self {
        let rows = &run.rows;
        let events = baseline_events(rows);
        let false_events = events
            .iter()
            .filter(|e| !run.planted.iter().any(|p| overlaps(e, p)))
            .count();
        let both = || {
            rows.iter()
                .filter(|r| r.baseline_error_per_s.is_some() && r.looming_error_per_s.is_some())
        };
        let max_reference = rows
            .iter()
            .filter_map(|r| r.reference_looming_per_s)
            .fold(f64::NEG_INFINITY, f64::max);
        Self {
            log: args.log.display().to_string(),
            time_origin_ns: run.origin_ns,
            lane_half_width_m: args.lane_half_width,
            lane_x_min_m: args.lane_x_min,
            lane_axes: run.frame,
            reference: if run.has_truth { "truth" } else { "face" },
            pairs: rows.len(),
            pairs_with_baseline: rows
                .iter()
                .filter(|r| r.baseline_looming_per_s.is_some())
                .count(),
            pairs_with_reference: rows
                .iter()
                .filter(|r| r.reference_looming_per_s.is_some())
                .count(),
            baseline_error: ErrorStats::of(rows.iter().map(|r| r.baseline_error_per_s)),
            looming_object_error: ErrorStats::of(rows.iter().map(|r| r.looming_error_per_s)),
            baseline_error_common: ErrorStats::of(both().map(|r| r.baseline_error_per_s)),
            looming_object_error_common: ErrorStats::of(both().map(|r| r.looming_error_per_s)),
            min_reference_ttc_s: (max_reference > 0.0).then(|| 1.0 / max_reference),
            planted: match_planted(&run.planted, &events),
            baseline_events: events,
            baseline_false_events: false_events,
        }
    }
}

fn cell(value: Option<f64>, digits: usize) -> String {
    value.map_or("-".into(), |v| format!("{v:.digits$}"))
}

fn print_rows(rows: &[PairRow]) {
    println!(
        "| t s | lane pts | nearest m | baseline 1/s | TTC s | reference 1/s | truth object | looming object 1/s | |baseline err| | |looming err| |"
    );
    println!("|---|---|---|---|---|---|---|---|---|---|");
    for r in rows {
        println!(
            "| {:.2} | {} | {} | {} | {} | {} | {} | {} | {} | {} |",
            r.time_s,
            r.lane_points,
            cell(r.nearest_now_m, 2),
            cell(r.baseline_looming_per_s, 3),
            cell(r.baseline_ttc_s, 2),
            cell(r.reference_looming_per_s, 3),
            r.truth_object_id.map_or("-".into(), |id| id.to_string()),
            cell(r.looming_object_per_s, 3),
            cell(r.baseline_error_per_s, 3),
            cell(r.looming_error_per_s, 3),
        );
    }
}

fn stats(s: &ErrorStats) -> String {
    format!(
        "{} / {} 1/s ({} pairs)",
        cell(s.median_per_s, 4),
        cell(s.p90_per_s, 4),
        s.pairs
    )
}

fn print_summary(s: &Summary) {
    println!();
    println!(
        "{}: {} pairs, lane x > {} m, |y| <= {} m in {}; baseline looming in {} pairs, reference ({}) in {}",
        s.log,
        s.pairs,
        s.lane_x_min_m,
        s.lane_half_width_m,
        s.lane_axes,
        s.pairs_with_baseline,
        s.reference,
        s.pairs_with_reference
    );
    println!(
        "- |baseline - reference| median / p90: {}",
        stats(&s.baseline_error)
    );
    println!(
        "- |looming object - reference| median / p90: {}",
        stats(&s.looming_object_error)
    );
    println!(
        "- same pairs only: baseline {}, looming object {}",
        stats(&s.baseline_error_common),
        stats(&s.looming_object_error_common)
    );
    println!(
        "- smallest reference TTC: {} s",
        cell(s.min_reference_ttc_s, 2)
    );
    print_events(s);
}

fn print_events(s: &Summary) {
    for e in &s.baseline_events {
        println!(
            "- baseline event {:.2}-{:.2} s, {} hot pairs, min TTC {:.2} s",
            e.start_s, e.end_s, e.hot_pairs, e.min_ttc_s
        );
    }
    for p in &s.planted {
        println!(
            "- planted {} {:.2}-{:.2} s (min TTC {:.2} s): baseline start {} s (delay {} s), min TTC {} s",
            p.label,
            p.start_s,
            p.end_s,
            p.min_ttc_s,
            cell(p.baseline_start_s, 2),
            cell(p.baseline_delay_s, 2),
            cell(p.baseline_min_ttc_s, 2)
        );
    }
    println!(
        "- baseline events: {}, false (outside every planted window): {}",
        s.baseline_events.len(),
        s.baseline_false_events
    );
}
