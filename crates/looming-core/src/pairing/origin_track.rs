//! A sensor's origin over a log (`origin` finds it on one scan): found on
//! its first scan with points and applied to every scan; looked up again at
//! each scan's stamp when only `/tf` reaches it; and, found from its rings,
//! watched at every scan. Where its rings spread about it because the
//! sensor drives through its clouds' frame (a world frame, `map` or `odom`,
//! with no `/tf` to the LiDAR), it is found again at every scan by a local
//! search from where the scans before put it (source `rings_per_scan`).
//!
//! Each scan so placed is moved about its own position, roll and pitch
//! (the rings give no yaw) into axes that turn as the sensor does: the
//! first turned so that its sweep starts behind the sensor, where the range
//! image wraps (no column then holds both ends of a sweep), the others by
//! the turn of their sweeps' phase (`origin_yaw`); without per-point times
//! they keep the frame's yaw. The scan the origin was found on, held by the
//! pairer until the next, is turned with them (`Placed::turn_previous`).
//! The pair's ego motion is then the placements' own
//! ([`SensorPlacement::motion`]): the velocity from the positions' steps,
//! the turn between their axes. A twist or gyro given in the vehicle's
//! frame cannot be used instead: without `/tf` nothing says how these axes
//! lie in the vehicle.

use std::collections::VecDeque;
use std::time::Instant;

use nalgebra::{Isometry3, UnitQuaternion, Vector3};

use super::frames::TransformTree;
use super::history::TransformHistory;
use super::origin::{apply, at_stamp, locate, record};
use super::origin_search::{
    MERGED_SPREAD_DEG, RingedSample, SimplexStop, nelder_mead, objective_at, params_of, pose_of,
    ring_centre_seed, ring_spread_deg, ringed_sample, search_pose, within_reach,
};
use super::origin_yaw::{YawSample, next_yaw, sweep_phase};
use super::stats::SensorTrackStats;
use crate::model::{
    AngularSource, FrameTransform, OriginSource, PairMotion, Scan, SensorOrigin, StampNs,
    TimeSeries,
};

/// A sensor's origin over a log; see the module documentation.
#[derive(Debug, Clone, Default)]
pub struct SensorPlacement {
    origin: Option<SensorOrigin>,
    /// `/tf`'s recent transforms.
    history: TransformHistory,
    /// Scans placed since the origin was found.
    scans_placed: u32,
    /// The origin found from the rings was seen to move and could not be
    /// followed (said once).
    seen_moving: bool,
    /// Stamp of the scan the origin was found on, and its sweep's phase
    /// about it where found from the rings (`origin_yaw`: where a track
    /// started on the next scan turns it to).
    found_stamp_ns: StampNs,
    found_phase_rad: Option<f64>,
    /// No search for the sensor's motion before this many scans are placed
    /// (set after a search that found none, which costs a full search).
    next_motion_search: u32,
    /// The sensor placed at every scan, once seen driving through its
    /// clouds' frame.
    track: Option<OriginTrack>,
}

/// What placing a scan gave.
#[derive(Debug, Default)]
pub struct Placed {
    pub warnings: Vec<String>,
    /// The origin for the run's report, when this scan found it: the first
    /// scan's, or the one that started placing the sensor at every scan.
    pub found: Option<SensorOrigin>,
    /// Placing the sensor at every scan started with this scan, and the
    /// scan its origin was found on (stamped so) turns about its spin axis
    /// by this yaw, rad, to the track's axes: the pair of the two is then
    /// made in axes that turn as the sensor does (`ScanPairer` turns it
    /// while it holds it; `origin::turn`).
    pub turn_previous: Option<(StampNs, f64)>,
}

impl SensorPlacement {
    /// Keep a `/tf` transform.
    pub fn keep_tf(&mut self, transform: &FrameTransform) {
        self.history.insert(transform);
    }

    /// Move `scan`'s points about its sensor (`statics`: `/tf_static`;
    /// `period_s`: the scan period).
    pub fn place(
        &mut self,
        scan: &mut Scan,
        statics: &TransformTree,
        sensor_frame: Option<&str>,
        period_s: f64,
    ) -> Placed {
        let mut placed = Placed::default();
        if self.origin.is_none() && !scan.is_empty() {
            let tree = self.history.tree_at(statics, scan.stamp_ns);
            let (found, warnings) = locate(scan, (&tree, statics), sensor_frame, period_s);
            placed = Placed {
                warnings,
                found: Some(found.clone()),
                ..Placed::default()
            };
            let ringed = matches!(
                found.source,
                OriginSource::Geometry | OriginSource::CloudFrame
            );
            self.found_phase_rad = ringed
                .then(|| sweep_phase(scan, &found.cloud_from_sensor, period_s))
                .flatten();
            self.origin = Some(found);
            self.found_stamp_ns = scan.stamp_ns;
        }
        let Some(found) = &self.origin else {
            return placed;
        };
        let mut origin = match (found.source, &mut self.track) {
            (OriginSource::Tf, _) => {
                at_stamp(scan, &self.history.tree_at(statics, scan.stamp_ns), found)
            }
            (_, Some(track)) => {
                let (origin, warning) = track.place(scan, period_s);
                placed.warnings.extend(warning);
                origin
            }
            _ => found.clone(),
        };
        self.scans_placed += 1;
        if placed.found.is_none() && self.track.is_none() {
            origin = self.watch(scan, origin, period_s, &mut placed);
        }
        apply(scan, &origin);
        record(scan, &origin);
        placed
    }

    /// An origin found from the rings of the first scan holds for the next
    /// ones only if the cloud's frame moves with the sensor (its own or a
    /// vehicle frame). Watched: the rings' spread about it (a pass over the
    /// sample) at every scan whose rings the cloud carries, every tenth
    /// otherwise. Where they spread, the full search about it says whether
    /// the sensor drove off; if so it is placed at every scan from then on,
    /// else, far spread, said once (the looming is then not to be trusted).
    fn watch(
        &mut self,
        scan: &Scan,
        fixed: SensorOrigin,
        period_s: f64,
        placed: &mut Placed,
    ) -> SensorOrigin {
        let ringed = matches!(
            fixed.source,
            OriginSource::Geometry | OriginSource::CloudFrame
        );
        let Some(first_spread_deg) = fixed.ring_spread_deg.filter(|_| ringed) else {
            return fixed;
        };
        // Rings the cloud carries (a field, an organized cloud's rows) cost
        // a pass to read; recovered ones (laser or firing order) a recovery
        // per look, tens of milliseconds to a second on a 64-laser cloud.
        let rings_carried = scan.ring.is_some() || scan.organized.is_some();
        if self.scans_placed < self.next_motion_search
            || !(rings_carried || self.scans_placed.is_multiple_of(MOTION_SEARCH_EVERY_SCANS))
        {
            return fixed;
        }
        let Some(sample) = ringed_sample(scan, period_s) else {
            return fixed;
        };
        let Some(spread_deg) = ring_spread_deg(&sample, &fixed.cloud_from_sensor) else {
            return fixed;
        };
        if spread_deg <= MERGED_SPREAD_DEG.max(WATCH_SPREAD_FACTOR * first_spread_deg) {
            return fixed;
        }
        let scans_after = self.scans_placed - 1;
        let first = Placement {
            stamp_ns: self.found_stamp_ns,
            params: params_of(&fixed.cloud_from_sensor),
            yaw_rad: self.found_phase_rad.map_or(0.0, seam_behind_yaw),
            phase_rad: self.found_phase_rad,
        };
        let spreads_deg = (first_spread_deg, spread_deg);
        let unstarted = match OriginTrack::start(first, scan, (&sample, period_s), spreads_deg) {
            Ok((track, origin)) => {
                placed
                    .warnings
                    .push(tracked_note(&scan.frame_id, scans_after, spread_deg));
                placed.found = Some(origin.clone());
                placed.turn_previous = (scans_after == 1 && first.yaw_rad != 0.0)
                    .then_some((first.stamp_ns, first.yaw_rad));
                self.track = Some(track);
                return origin;
            }
            Err(unstarted) => unstarted,
        };
        self.next_motion_search = self.scans_placed + MOTION_SEARCH_EVERY_SCANS;
        let lost = unstarted == Unstarted::Spread
            && spread_deg > MERGED_SPREAD_DEG.max(MOVED_SPREAD_FACTOR * first_spread_deg);
        if lost && !self.seen_moving {
            self.seen_moving = true;
            placed
                .warnings
                .push(lost_warning(&scan.frame_id, scans_after, spreads_deg));
        }
        fixed
    }

    /// The ego motion of the pair of scans stamped `from_ns` and `to_ns`
    /// when both were placed by their rings one by one: the placements'
    /// own (see the module documentation); `None` otherwise.
    pub fn motion(&self, from_ns: StampNs, to_ns: StampNs, hold_s: f64) -> Option<PairMotion> {
        self.track.as_ref()?.motion(from_ns, to_ns, hold_s)
    }

    /// What placing the sensor at every scan cost and gave, once started.
    pub fn track_stats(&self) -> Option<&SensorTrackStats> {
        self.track.as_ref().map(|track| &track.stats)
    }
}

/// The yaw that puts a sweep whose phase is `phase_rad` (in axes of yaw 0)
/// behind the sensor, where the range image wraps (`engine::grid`: column
/// 0 behind): no column then holds returns from both ends of the sweep,
/// as in the frame of a sensor that starts its sweeps behind it (KITTI's,
/// the simulator's), whose axes these then are.
fn seam_behind_yaw(phase_rad: f64) -> f64 {
    phase_rad - std::f64::consts::PI
}

/// Said when the sensor is seen driving through its clouds' frame and
/// followed: a caveat, not a failure (the bearings are in axes of our
/// making).
fn tracked_note(frame: &str, scans_after: u32, spread_deg: f64) -> String {
    format!(
        "the sensor moves through its clouds' frame `{frame}` (no /tf to it): {} after its \
         origin was found, its rings spread {spread_deg:.3} deg about it; from that scan on it \
         is placed from its rings at every scan (rings, per scan; its axes turned so that its \
         sweeps start behind it, bearings are theirs)",
        scans_text(scans_after)
    )
}

/// Said when the rings spread about the first origin and no search
/// gathers them again.
fn lost_warning(frame: &str, scans_after: u32, (first_deg, now_deg): (f64, f64)) -> String {
    format!(
        "the sensor moves through its clouds' frame `{frame}`: {} after its origin was found \
         from the rings (spread {first_deg:.3} deg), they spread {now_deg:.3} deg about it, and \
         no origin nearby gathers them again. A world frame needs /tf to the LiDAR's frame (or \
         --sensor-frame); without it this log's looming is not to be trusted",
        scans_text(scans_after)
    )
}

/// "1 scan", "2 scans".
fn scans_text(n: u32) -> String {
    format!("{n} scan{}", if n == 1 { "" } else { "s" })
}

/// How often a sensor that spread its rings without moving is searched
/// again for motion, scans (each search is a full one, about a second).
const MOTION_SEARCH_EVERY_SCANS: u32 = 10;
/// Its rings spread this many times more about the first origin (and more
/// than [`MERGED_SPREAD_DEG`]), and no origin nearby gathers them: said.
const MOVED_SPREAD_FACTOR: f64 = 5.0;
/// Rings spread more than this many times their first scan's spread (and
/// more than [`MERGED_SPREAD_DEG`]) about its origin: searched for motion.
/// The spread of a still sensor's rings varies with the scene (KITTI in
/// `base_link`: 0.11 to 0.26 deg over 22 scans); a metre's drive spreads
/// them degrees (the synthetic cut-in: 2.4 deg).
const WATCH_SPREAD_FACTOR: f64 = 3.0;
/// The sensor drove off when the search finds it further than this from
/// the first origin, m, its rings gathered there to a share of their
/// spread about it ([`MOVED_SPREAD_SHARE`]) and as narrow as a placement's
/// may be: a still sensor's estimate varies by millimetres on synthetic
/// scans and by centimetres on real ones, while the rings spread 0.3 deg
/// (the watch's threshold) about an origin 15 cm off (2 deg per metre on
/// the synthetic cut-in). Nearer, it is searched again ten scans on.
const MIN_MOVE_M: f64 = 0.1;
const MOVED_SPREAD_SHARE: f64 = 0.5;

/// A placement's rings may spread this many times the first scan's, plus
/// [`TRACK_SPREAD_MARGIN_DEG`] (and at most [`MERGED_SPREAD_DEG`]); past
/// that the local search is taken as lost.
const TRACK_SPREAD_FACTOR: f64 = 3.0;
const TRACK_SPREAD_MARGIN_DEG: f64 = 0.05;
/// The local search ends this near its prediction, m (its simplex starts a
/// centimetre wide; further, it wandered off).
const LOCAL_REACH_M: f64 = 1.0;
/// Placements kept: the pair's two and the two before (for the velocity's
/// change across the pair).
const RECENT_PLACEMENTS: usize = 4;
/// The local search's first simplex: a centimetre and 0.05 degrees, about
/// what a scan's prediction misses by (braking that starts within a step,
/// 6 m/s^2 at 10 Hz, moves the sensor 6 cm off it: the simplex grows).
const TRACK_SCALE: [f64; 5] = [0.01, 0.01, 0.01, 0.05 * DEG, 0.05 * DEG];
/// ... and its stop: at most this many steps, or once every vertex lies
/// within a tenth of a millimetre and 0.001 degrees of the best.
const TRACK_STOP: SimplexStop = SimplexStop {
    iterations: 200,
    tolerance: Some([1e-4, 1e-4, 1e-4, 1e-3 * DEG, 1e-3 * DEG]),
};
const DEG: f64 = std::f64::consts::PI / 180.0;

/// One scan's placement: its stamp, the searched parameters (position,
/// roll, pitch: `origin_search::pose_of`), the yaw its axes were given
/// about its spin axis and its sweep's phase (`origin_yaw`).
#[derive(Debug, Clone, Copy, PartialEq)]
struct Placement {
    stamp_ns: StampNs,
    params: [f64; 5],
    yaw_rad: f64,
    phase_rad: Option<f64>,
}

impl Placement {
    /// The sensor's pose in the cloud's frame: position, roll and pitch,
    /// then the yaw about its own spin axis (which moves no elevation).
    fn pose(&self) -> Isometry3<f64> {
        pose_of(&self.params) * UnitQuaternion::from_axis_angle(&Vector3::z_axis(), self.yaw_rad)
    }

    fn as_yaw_sample(&self) -> YawSample {
        YawSample {
            stamp_ns: self.stamp_ns,
            position_m: [self.params[0], self.params[1], self.params[2]],
            yaw_rad: self.yaw_rad,
            phase_rad: self.phase_rad,
        }
    }
}

/// The sensor placed from its rings at every scan.
#[derive(Debug, Clone)]
struct OriginTrack {
    /// The latest placements, oldest first.
    recent: VecDeque<Placement>,
    /// The rings' spread the local search may leave, deg.
    max_spread_deg: f64,
    stats: SensorTrackStats,
    /// A placement failed (said once).
    warned: bool,
    /// No full search before this many scans are placed (after one that
    /// failed).
    no_full_search_before: u64,
}

impl OriginTrack {
    /// The track of a sensor whose first origin (`first`) leaves `scan`'s
    /// rings spread (`spreads_deg`: about it on its first scan, and now):
    /// started, with `scan`'s origin, when the full search finds the sensor
    /// driven off; else whether the search gathered the rings near the
    /// first origin (a still sensor whose scene spread them, or one that
    /// has not driven far yet).
    fn start(
        first: Placement,
        scan: &Scan,
        (sample, period_s): (&RingedSample, f64),
        (first_spread_deg, spread_deg): (f64, f64),
    ) -> Result<(Self, SensorOrigin), Unstarted> {
        let started = Instant::now();
        let max_spread_deg = (TRACK_SPREAD_FACTOR * first_spread_deg + TRACK_SPREAD_MARGIN_DEG)
            .min(MERGED_SPREAD_DEG);
        let narrow = max_spread_deg.min(MOVED_SPREAD_SHARE * spread_deg);
        let (params, moved_spread_deg) =
            moved_pose(sample, first.params, narrow).ok_or(Unstarted::Spread)?;
        if within(&params, &first.params, MIN_MOVE_M) {
            return Err(Unstarted::Near);
        }
        let mut track = Self {
            // The first origin's scan begins the track if it came before.
            recent: (first.stamp_ns < scan.stamp_ns)
                .then_some(first)
                .into_iter()
                .collect(),
            max_spread_deg,
            stats: SensorTrackStats::default(),
            warned: false,
            no_full_search_before: 0,
        };
        let placement = track.keep(scan, params, period_s);
        track
            .stats
            .record(moved_spread_deg, Search::Full, elapsed_ms(started));
        Ok((track, origin_of(&placement, Some(moved_spread_deg))))
    }

    /// Place `scan`: the local search from the prediction, the full search
    /// about it where that leaves the rings spread; a warning the first
    /// time neither gathers them.
    fn place(&mut self, scan: &Scan, period_s: f64) -> (SensorOrigin, Option<String>) {
        let started = Instant::now();
        let predicted = self.predict(scan.stamp_ns);
        let (params, spread_deg, search) = match ringed_sample(scan, period_s) {
            Some(sample) => self.search(&sample, predicted),
            None => (predicted, None, Search::Failed),
        };
        let placement = self.keep(scan, params, period_s);
        let spread_or_nan = spread_deg.unwrap_or(f64::NAN);
        self.stats
            .record(spread_or_nan, search, elapsed_ms(started));
        let warning = (search == Search::Failed && !self.warned).then(|| {
            self.warned = true;
            format!(
                "the sensor placed from its rings at every scan in frame `{}` was lost at the \
                 scan stamped {} ns: its rings spread {spread_or_nan:.3} deg about the best \
                 origin found (at most {:.3} expected); the looming of such scans is not to be \
                 trusted (pairing.sensor_track.failed counts them)",
                scan.frame_id, scan.stamp_ns, self.max_spread_deg
            )
        });
        (origin_of(&placement, spread_deg), warning)
    }

    /// Where the sensor should be at `stamp_ns`: its position carried on
    /// through the last placements (by their velocity, and its change where
    /// three are known: braking moves it centimetres off the last step's),
    /// its tilt kept.
    fn predict(&mut self, stamp_ns: StampNs) -> [f64; 5] {
        let Some(&last) = self.recent.back() else {
            return [0.0; 5];
        };
        if stamp_ns <= last.stamp_ns {
            // Stamps went back (a replayed segment): no step to go on, and
            // no velocity across the jump.
            self.recent.clear();
            self.recent.push_back(last);
            return last.params;
        }
        let known: Vec<&Placement> = self.recent.iter().rev().take(3).collect();
        let mut predicted = last.params;
        for (i, value) in predicted.iter_mut().enumerate().take(3) {
            *value = extrapolate(&known, i, stamp_ns);
        }
        predicted
    }

    /// The local search from `predicted`, then the full one about it where
    /// that leaves the rings spread (not again for ten scans after one that
    /// failed: a second each): the parameters, their spread, and which
    /// search placed them. Where neither gathers the rings, the narrower
    /// of the two, or the prediction where both wandered off.
    fn search(
        &mut self,
        sample: &RingedSample,
        predicted: [f64; 5],
    ) -> ([f64; 5], Option<f64>, Search) {
        let local = nelder_mead(
            |p| objective_at(sample, p),
            predicted,
            TRACK_SCALE,
            TRACK_STOP,
        );
        let local_spread = ring_spread_deg(sample, &pose_of(&local))
            .filter(|_| within(&local, &predicted, LOCAL_REACH_M));
        if self.fits(local_spread) {
            return (local, local_spread, Search::Local);
        }
        let mut candidates = vec![(local, local_spread)];
        if self.stats.scans >= self.no_full_search_before {
            let full = search_pose(sample, predicted);
            let full_spread = ring_spread_deg(sample, &pose_of(&full))
                .filter(|_| within_reach(&full, &predicted));
            if self.fits(full_spread) {
                return (full, full_spread, Search::Full);
            }
            candidates.push((full, full_spread));
            self.no_full_search_before = self.stats.scans + u64::from(MOTION_SEARCH_EVERY_SCANS);
        }
        let (params, spread) = candidates
            .into_iter()
            .filter_map(|(params, spread)| Some((params, spread?)))
            .min_by(|a, b| a.1.total_cmp(&b.1))
            .map_or((predicted, None), |(params, spread)| (params, Some(spread)));
        (params, spread, Search::Failed)
    }

    /// Whether a placement's rings spread no more than a good one's (a
    /// search that wandered off has none).
    fn fits(&self, spread_deg: Option<f64>) -> bool {
        spread_deg.is_some_and(|s| s <= self.max_spread_deg)
    }

    /// Keep `scan`'s placement at `params`, its axes turned as its sweep's
    /// phase says the sensor turned (`origin_yaw`).
    fn keep(&mut self, scan: &Scan, params: [f64; 5], period_s: f64) -> Placement {
        let phase_rad = sweep_phase(scan, &pose_of(&params), period_s);
        let before: Vec<YawSample> = self.recent.iter().map(Placement::as_yaw_sample).collect();
        let position_m = [params[0], params[1], params[2]];
        let (yaw_rad, turned) = next_yaw(&before, scan.stamp_ns, position_m, phase_rad);
        self.stats.yaw_held += u64::from(!turned && !before.is_empty());
        if self.recent.len() == RECENT_PLACEMENTS {
            self.recent.pop_front();
        }
        let placement = Placement {
            stamp_ns: scan.stamp_ns,
            params,
            yaw_rad,
            phase_rad,
        };
        self.recent.push_back(placement);
        placement
    }

    /// See [`SensorPlacement::motion`]: a velocity sample at the middle of
    /// each step up to `to_ns` (the step's displacement over its time, in
    /// the sensor's axes there), the last two steps' trend carried to
    /// one step past `to_ns` (the current sweep's end; braking changes the
    /// velocity across a pair), and the turn of each step.
    fn motion(&self, from_ns: StampNs, to_ns: StampNs, hold_s: f64) -> Option<PairMotion> {
        let upto: Vec<&Placement> = self.recent.iter().filter(|p| p.stamp_ns <= to_ns).collect();
        let placed = |stamp: StampNs| upto.iter().any(|p| p.stamp_ns == stamp);
        if !placed(from_ns) || !placed(to_ns) || from_ns >= to_ns {
            return None;
        }
        let steps: Vec<Step> = upto
            .windows(2)
            .filter_map(|w| Step::of(w[0], w[1]))
            .collect();
        let mut velocity: Vec<(StampNs, Vector3<f64>)> =
            steps.iter().map(|s| (s.mid_ns, s.velocity_mps)).collect();
        if let [.., a, b] = steps.as_slice() {
            let end_ns = to_ns + (to_ns - from_ns);
            let rate = (b.velocity_mps - a.velocity_mps) / (b.mid_ns - a.mid_ns) as f64;
            velocity.push((end_ns, b.velocity_mps + rate * (end_ns - b.mid_ns) as f64));
        }
        let angular = steps.iter().map(|s| (s.mid_ns, s.angular_radps)).collect();
        Some(PairMotion {
            velocity: Some(TimeSeries::new(velocity, hold_s)),
            angular: Some(TimeSeries::new(angular, hold_s)),
            angular_source: AngularSource::Placements,
            velocity_extrinsic: None,
            imu_extrinsic: None,
            velocity_unavailable: false,
            imu_unavailable: true,
            coverage_complete: true,
        })
    }
}

/// Whether `params` lies within `reach_m` of `start` (position).
fn within(params: &[f64; 5], start: &[f64; 5], reach_m: f64) -> bool {
    Vector3::from_column_slice(&params[..3])
        .metric_distance(&Vector3::from_column_slice(&start[..3]))
        <= reach_m
}

/// Where the sensor went from `first` (its first origin's parameters): the
/// full search about it, then (it drove beyond that search's reach) about
/// its tightest ring's centre; `None` where neither gathers the rings to
/// `narrow_deg`.
fn moved_pose(sample: &RingedSample, first: [f64; 5], narrow_deg: f64) -> Option<([f64; 5], f64)> {
    let gathered = |start: [f64; 5]| {
        let params = search_pose(sample, start);
        let spread = ring_spread_deg(sample, &pose_of(&params))?;
        (spread <= narrow_deg && within_reach(&params, &start)).then_some((params, spread))
    };
    gathered(first).or_else(|| gathered(ring_centre_seed(sample)?))
}

/// Parameter `i` of the placements `known` (newest first, up to three)
/// carried on to `stamp_ns` by the polynomial through them (Lagrange's).
fn extrapolate(known: &[&Placement], i: usize, stamp_ns: StampNs) -> f64 {
    let at = |p: &Placement| (p.stamp_ns - stamp_ns) as f64 * 1e-9;
    known
        .iter()
        .enumerate()
        .map(|(j, pj)| {
            let weight: f64 = known
                .iter()
                .enumerate()
                .filter(|&(k, _)| k != j)
                .map(|(_, pk)| at(pk) / (at(pk) - at(pj)))
                .product();
            weight * pj.params[i]
        })
        .sum()
}

/// The motion between two placements, at their middle.
struct Step {
    mid_ns: StampNs,
    /// In the sensor's axes at the step's middle, m/s.
    velocity_mps: Vector3<f64>,
    /// The turn from the first placement's axes to the second's over the
    /// step (body axes), rad/s.
    angular_radps: Vector3<f64>,
}

impl Step {
    fn of(a: &Placement, b: &Placement) -> Option<Self> {
        let dt_s = (b.stamp_ns - a.stamp_ns) as f64 * 1e-9;
        if dt_s <= 0.0 {
            return None;
        }
        let (pose_a, pose_b): (Isometry3<f64>, Isometry3<f64>) = (a.pose(), b.pose());
        let displacement = pose_b.translation.vector - pose_a.translation.vector;
        let turn = pose_a.rotation.inverse() * pose_b.rotation;
        // The chord is the velocity at the step's middle, in the axes the
        // sensor had there: half the step's turn (a degree per step at
        // 20 deg/s and 10 Hz) away from either end's.
        let mid_rotation =
            pose_a.rotation * UnitQuaternion::from_scaled_axis(turn.scaled_axis() / 2.0);
        Some(Self {
            mid_ns: a.stamp_ns + (b.stamp_ns - a.stamp_ns) / 2,
            velocity_mps: mid_rotation.inverse() * displacement / dt_s,
            angular_radps: turn.scaled_axis() / dt_s,
        })
    }
}

/// Why a track was not started.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
enum Unstarted {
    /// The rings gather about an origin near the first one: the sensor has
    /// not driven off (or not yet far).
    Near,
    /// No origin gathers them.
    Spread,
}

/// Which search placed a scan.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
enum Search {
    /// The local one, from the prediction.
    Local,
    /// The full one (grid and simplex) about the prediction.
    Full,
    /// Neither gathered the rings: the narrower of the two was kept.
    Failed,
}

impl SensorTrackStats {
    /// Count one placement: its rings' spread, its search and its time.
    fn record(&mut self, spread_deg: f64, search: Search, ms: f64) {
        self.scans += 1;
        self.full_searches += u64::from(search != Search::Local);
        self.failed += u64::from(search == Search::Failed);
        if spread_deg.is_finite() {
            self.measured += 1;
            let n = self.measured as f64;
            self.ring_spread_deg_mean += (spread_deg - self.ring_spread_deg_mean) / n;
            self.ring_spread_deg_max = self.ring_spread_deg_max.max(spread_deg);
        }
        if search == Search::Local {
            let n = (self.scans - self.full_searches) as f64;
            self.local_ms_per_scan_mean += (ms - self.local_ms_per_scan_mean) / n;
            self.local_ms_per_scan_max = self.local_ms_per_scan_max.max(ms);
        } else {
            let n = self.full_searches as f64;
            self.full_search_ms_mean += (ms - self.full_search_ms_mean) / n;
        }
    }
}

fn elapsed_ms(started: Instant) -> f64 {
    started.elapsed().as_secs_f64() * 1e3
}

/// A placement as the scan's origin.
fn origin_of(placement: &Placement, spread_deg: Option<f64>) -> SensorOrigin {
    let mut origin = SensorOrigin::at(OriginSource::RingsPerScan, placement.pose());
    origin.ring_spread_deg = spread_deg;
    origin.several_origins = spread_deg.is_none_or(|s| s > MERGED_SPREAD_DEG);
    origin
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::pairing::origin::tests::scan_in_base_link;

    const PERIOD_NS: StampNs = 100_000_000;

    /// Scan `k` of 16-laser sensors at `sensors` in frame `map`, stamped
    /// every 0.1 s.
    fn scan_in_map(k: i64, sensors: &[[f64; 3]]) -> Scan {
        let mut scan = scan_in_base_link(sensors);
        scan.frame_id = "map".into();
        scan.stamp_ns = k * PERIOD_NS;
        scan
    }

    /// The sensor 1 m further along x at every scan (10 m/s), braking in
    /// the last ones.
    fn driven_x_m(k: i64) -> f64 {
        let t = k as f64 * 0.1;
        25.0 + 10.0 * t - if k > 6 { 2.5 * (t - 0.6).powi(2) } else { 0.0 }
    }

    #[test]
    fn a_sensor_driving_through_a_world_frame_without_tf_is_placed_at_every_scan() {
        let tree = TransformTree::new();
        let mut placement = SensorPlacement::default();
        let mut notes = Vec::new();
        let (mut sources, mut motions) = (Vec::new(), Vec::new());
        for k in 0..10 {
            let mut scan = scan_in_map(k, &[[driven_x_m(k), -7.0, 1.8]]);
            let placed = placement.place(&mut scan, &tree, None, 0.1);
            notes.extend(placed.warnings);
            // The pair ending here, as the pairer asks once it is placed.
            motions.push(placement.motion((k - 1) * PERIOD_NS, k * PERIOD_NS, 0.2));
            let origin = scan.layout.origin.clone().unwrap();
            for (got, want) in origin.position_m.iter().zip([driven_x_m(k), -7.0, 1.8]) {
                assert!((got - want).abs() < 0.005, "scan {k}: {origin:?}");
            }
            sources.push(origin.source);
        }
        // Found on the first scan (25 m from the frame's origin), followed
        // from the second.
        assert_eq!(sources[0], OriginSource::Geometry);
        assert!(
            sources[1..]
                .iter()
                .all(|s| *s == OriginSource::RingsPerScan)
        );
        assert_eq!(notes.len(), 1, "{notes:?}");
        assert!(
            notes[0].contains("moves through its clouds' frame `map`")
                && notes[0].contains("placed from its rings at every scan")
                && !notes[0].contains("not to be trusted"),
            "{notes:?}"
        );
        let stats = placement.track_stats().unwrap();
        assert_eq!((stats.scans, stats.failed), (9, 0), "{stats:?}");
        // The pair's motion is the placements': 10 m/s along x before the
        // braking, slowing after (5 m/s^2).
        assert!(motions[0].is_none(), "no scan before the first");
        let motion = motions[2].as_ref().unwrap();
        let v = motion.velocity_at(2 * PERIOD_NS).unwrap();
        assert!((v - Vector3::new(10.0, 0.0, 0.0)).norm() < 0.05, "{v:?}");
        assert_eq!(motion.angular_source, AngularSource::Placements);
        // Braking (5 m/s^2 from 0.6 s): the velocity within the pair, and
        // carried on to the end of the current scan's sweep.
        let braking = motions[9].as_ref().unwrap();
        for t_s in [0.85, 0.95] {
            let v = braking.velocity_at((t_s * 1e9) as StampNs).unwrap();
            let want = 10.0 - 5.0 * (t_s - 0.6);
            assert!((v.x - want).abs() < 0.05, "{v:?} against {want} at {t_s} s");
        }
    }

    #[test]
    fn a_sensor_that_stays_where_it_was_found_is_not_followed() {
        let tree = TransformTree::new();
        let mut still = SensorPlacement::default();
        for k in 0..12 {
            let mut scan = scan_in_map(k, &[[0.9, -0.3, 1.8]]);
            let placed = still.place(&mut scan, &tree, None, 0.1);
            assert!(placed.warnings.is_empty(), "{:?}", placed.warnings);
            assert_eq!(scan.layout.origin.unwrap().source, OriginSource::Geometry);
        }
        assert!(still.track_stats().is_none());
        assert!(still.motion(0, PERIOD_NS, 0.2).is_none());
    }

    #[test]
    fn a_followed_sensor_whose_rings_no_origin_gathers_is_said() {
        let tree = TransformTree::new();
        let mut placement = SensorPlacement::default();
        let mut warned = Vec::new();
        for k in 0..3 {
            let mut scan = scan_in_map(k, &[[driven_x_m(k), -7.0, 1.8]]);
            warned.extend(placement.place(&mut scan, &tree, None, 0.1).warnings);
        }
        // Another sensor's points merged in: no one origin for the rings.
        let k = 3;
        let mut scan = scan_in_map(k, &[[driven_x_m(k), -7.0, 1.8], [driven_x_m(k), -5.0, 0.6]]);
        warned.extend(placement.place(&mut scan, &tree, None, 0.1).warnings);
        assert!(
            warned
                .iter()
                .any(|w| w.contains("was lost") && w.contains("not to be trusted")),
            "{warned:?}"
        );
        let stats = placement.track_stats().unwrap();
        assert_eq!(stats.failed, 1, "{stats:?}");
    }

    #[test]
    fn a_turning_sensor_is_followed_in_axes_that_turn_with_it() {
        // Around a circle of 50 m at 1 m per scan (10 m/s, turning
        // 0.2 rad/s), yawed 0.3 rad off its course; its sweeps start at its
        // own azimuth 0 (each laser's columns from there over 0.1 s).
        let turn_per_scan = 1.0 / 50.0;
        let at = |k: i64| {
            let a = k as f64 * turn_per_scan;
            [25.0 + 50.0 * a.sin(), -7.0 + 50.0 * (1.0 - a.cos()), 1.8]
        };
        let yaw = |k: i64| 0.3 + k as f64 * turn_per_scan;
        let tree = TransformTree::new();
        let mut placement = SensorPlacement::default();
        let mut turned_previous = None;
        for k in 0..6 {
            let mut scan = scan_in_map(k, &[at(k)]);
            let n = scan.points_m.len();
            scan.time_offset_s = Some((0..n).map(|i| (i % 720) as f32 / 7200.0).collect());
            let centre = nalgebra::Point3::from(at(k));
            let turn = UnitQuaternion::from_axis_angle(&Vector3::z_axis(), yaw(k));
            for p in &mut scan.points_m {
                let q = nalgebra::Point3::new(f64::from(p[0]), f64::from(p[1]), f64::from(p[2]));
                let q = centre + turn * (q - centre);
                *p = [q.x as f32, q.y as f32, q.z as f32];
            }
            let placed = placement.place(&mut scan, &tree, None, 0.1);
            turned_previous = turned_previous.or(placed.turn_previous);
            let origin = scan.layout.origin.unwrap();
            if k > 0 {
                // Its axes turned half a turn from its own (the sweep then
                // starts behind it): the frame's yaw of its own plus pi.
                let (_, _, frame_yaw) = origin.cloud_from_sensor.rotation.euler_angles();
                let off = (frame_yaw - yaw(k)).rem_euclid(std::f64::consts::TAU);
                assert!((off - std::f64::consts::PI).abs() < 1e-3, "scan {k}: {off}");
            }
        }
        // The first scan, held by the pairer, is turned into those axes.
        let (stamp_ns, first_yaw) = turned_previous.unwrap();
        assert_eq!(stamp_ns, 0);
        assert!((first_yaw - (yaw(0) - std::f64::consts::PI)).abs() < 1e-3);
        // The pair's motion: 10 m/s, turning 0.2 rad/s about the spin axis.
        let motion = placement.motion(4 * PERIOD_NS, 5 * PERIOD_NS, 0.2).unwrap();
        let v = motion.velocity_at(5 * PERIOD_NS).unwrap();
        let w = motion.angular_velocity_at(5 * PERIOD_NS).unwrap();
        assert!((v.norm() - 10.0).abs() < 0.01, "{v:?}");
        assert!((w - Vector3::new(0.0, 0.0, 0.2)).norm() < 1e-3, "{w:?}");
        assert_eq!(placement.track_stats().unwrap().yaw_held, 0);
    }

    #[test]
    fn the_prediction_carries_a_braking_sensor_on_exactly() {
        let at = |k: i64| Placement {
            stamp_ns: k * PERIOD_NS,
            params: [driven_x_m(k), 0.0, 0.0, 0.0, 0.0],
            yaw_rad: 0.0,
            phase_rad: None,
        };
        let known = [at(9), at(8), at(7)];
        let known: Vec<&Placement> = known.iter().collect();
        let predicted = extrapolate(&known, 0, 10 * PERIOD_NS);
        assert!((predicted - driven_x_m(10)).abs() < 1e-9, "{predicted}");
    }
}
