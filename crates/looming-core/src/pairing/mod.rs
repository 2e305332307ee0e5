//! Scan pairing: turns the log-time-ordered stream of scans, IMU samples,
//! velocity samples and static transforms into synchronised pairs of
//! consecutive scans, each with the ego motion covering it in the LiDAR frame.
//!
//! State machine ([`ScanPairer`]), driven by `push_*` calls in log-time order:
//!
//! ```text
//!   NoScan --scan--> HavePrevious --scan (0 < dt <= max gap)--> PairPending
//!                       ^   |  \--scan (dt <= 0): skipped, previous kept
//!                       |   \----scan (dt > max gap): skipped, becomes previous
//!                       |
//!   PairPending --motion covers current scan end / next scan / finish()--> emit,
//!                 current becomes previous (HavePrevious)
//! ```
//!
//! Physics uses header stamps; only the order of calls follows log time.
//! One pair at most is pending and two scans held; motion samples are pruned
//! as pairs go out, so memory is bounded however long the log.

mod buffer;
mod config;
pub mod frames;
mod history;
pub mod motion;
pub mod origin;
mod origin_search;
pub mod origin_track;
mod origin_yaw;
mod prepare;
pub mod split;
mod stats;
pub mod stride;

use buffer::{InsertOutcome, SampleBuffer};
pub use config::PairingConfig;
pub use stats::{PairingStats, SensorTrackStats};

pub use frames::{
    Extrinsic, ExtrinsicParseError, TransformTree, normalize_frame_id, parse_extrinsic,
    resolve_extrinsic,
};
use std::collections::{HashSet, VecDeque};
use std::mem;
use std::sync::Arc;

use crate::model::motion::seconds_to_ns;
use crate::model::{
    Decoded, ExtrinsicInfo, ExtrinsicSource, FrameTransform, ImuSample, PairMotion, Scan, ScanPair,
    StampNs, VelocitySample,
};
use motion::{GyroSample, MotionInputs, TwistSample, build_pair_motion};

/// Accepted dts kept for the running median that stands in for the nominal
/// period when none is set: enough to ride out dropped scans, bounded.
const MEDIAN_WINDOW_LEN: usize = 101;
/// Stamp differences of consecutive scans kept for the period used to time
/// points from their azimuth.
const LAYOUT_PERIOD_WINDOW_LEN: usize = 11;
/// Bounds of that period, seconds.
const LAYOUT_PERIOD_RANGE_S: (f64, f64) = (0.02, 0.5);
/// Before the first scan, motion samples this much older than the newest one
/// (plus the hold) are dropped: a sweep-start stamp lies at most about one
/// period before its log time, and logs can open with minutes of IMU data.
const PRE_SCAN_HISTORY_S: f64 = 1.0;
/// Backstop against unbounded growth when no pair can be emitted for a long
/// time (e.g. the LiDAR stops while a 1 kHz IMU keeps publishing). The oldest
/// samples are dropped beyond this and counted.
pub(crate) const MAX_BUFFERED_SAMPLES_PER_SOURCE: usize = 50_000;
/// Without a known maximum gap, a backwards stamp jump larger than this is
/// taken as a clock reset rather than jitter.
const CLOCK_RESET_FALLBACK_S: f64 = 1.0;

// Pairs are the common variant (one per scan, ~10 Hz) and move by value once;
// boxing them would only add an allocation per scan.
#[allow(clippy::large_enum_variant)]
#[derive(Debug, Clone)]
pub enum PairEvent {
    Pair(ScanPair),
    /// Something the user should know, reported once per cause.
    Warning(String),
}

#[derive(Debug, Clone)]
struct ScanEntry {
    scan: Arc<Scan>,
    log_time_ns: u64,
    start_ns: StampNs,
    end_ns: StampNs,
}

impl ScanEntry {
    fn new(log_time_ns: u64, scan: Arc<Scan>) -> Self {
        let (start_ns, end_ns) = scan.time_span_ns();
        // Per-point times may all lie on one side of the stamp; the span used
        // for motion must contain the stamp too, since dt is measured on it.
        let start_ns = start_ns.min(scan.stamp_ns);
        let end_ns = end_ns.max(scan.stamp_ns);
        Self {
            scan,
            log_time_ns,
            start_ns,
            end_ns,
        }
    }

    fn stamp_ns(&self) -> StampNs {
        self.scan.stamp_ns
    }
}

#[derive(Debug, Default)]
enum PairerState {
    #[default]
    NoScan,
    HavePrevious(ScanEntry),
    PairPending {
        previous: ScanEntry,
        current: ScanEntry,
    },
}

/// The pairing state machine; see the module documentation.
#[derive(Debug)]
pub struct ScanPairer {
    cfg: PairingConfig,
    hold_ns: i64,
    state: PairerState,
    velocity: SampleBuffer<TwistSample>,
    imu: SampleBuffer<GyroSample>,
    transforms: TransformTree,
    nominal_period_override_s: Option<f64>,
    accepted_dts_s: VecDeque<f64>,
    next_index: u64,
    warned: HashSet<String>,
    stats: PairingStats,
    /// Stamp of the last scan pushed through `push_decoded`.
    last_scan_stamp_ns: Option<StampNs>,
    /// Recent positive stamp differences of consecutive scans, seconds.
    recent_scan_dts_s: VecDeque<f64>,
    /// Where the sensor is in its clouds' frame (`origin`, `origin_track`),
    /// and `/tf`.
    placement: origin_track::SensorPlacement,
}

impl ScanPairer {
    pub fn new(cfg: PairingConfig) -> Self {
        let hold_ns = seconds_to_ns(cfg.motion_hold_s.max(0.0));
        Self {
            cfg,
            hold_ns,
            state: PairerState::NoScan,
            velocity: SampleBuffer::default(),
            imu: SampleBuffer::default(),
            transforms: TransformTree::new(),
            nominal_period_override_s: None,
            accepted_dts_s: VecDeque::with_capacity(MEDIAN_WINDOW_LEN),
            next_index: 0,
            warned: HashSet::new(),
            stats: PairingStats::default(),
            last_scan_stamp_ns: None,
            recent_scan_dts_s: VecDeque::with_capacity(LAYOUT_PERIOD_WINDOW_LEN),
            placement: origin_track::SensorPlacement::default(),
        }
    }

    /// Nominal scan period (e.g. from MCAP channel statistics). `None`, or a
    /// non-positive / non-finite value, falls back to the running median of dts.
    pub fn set_nominal_period_s(&mut self, period_s: Option<f64>) {
        self.nominal_period_override_s = period_s.filter(|p| p.is_finite() && *p > 0.0);
        self.stats.nominal_period_s = self.nominal_period_s();
    }

    pub fn push_scan(&mut self, log_time_ns: u64, scan: Arc<Scan>) -> Vec<PairEvent> {
        self.stats.scans_seen += 1;
        if scan.is_empty() {
            // Still paired: the outputs stay one-to-one with the input scans
            // and downstream simply has no points to evaluate.
            self.stats.empty_scans += 1;
        }
        let entry = ScanEntry::new(log_time_ns, scan);
        // Bounded latency: a pending pair never waits past the next scan.
        let mut events = self.emit_pending(false);
        self.state = match mem::take(&mut self.state) {
            PairerState::NoScan => PairerState::HavePrevious(entry),
            PairerState::HavePrevious(previous) => {
                self.accept_or_skip(previous, entry, &mut events)
            }
            pending @ PairerState::PairPending { .. } => {
                unreachable!("pending pair flushed above: {pending:?}")
            }
        };
        self.prune();
        events.extend(self.emit_if_covered());
        events
    }

    pub fn push_imu(&mut self, _log_time_ns: u64, sample: ImuSample) -> Vec<PairEvent> {
        let gyro = GyroSample {
            stamp_ns: sample.stamp_ns,
            angular_velocity_radps: sample.angular_velocity_radps,
        };
        let outcome = self.imu.insert(gyro, normalize_frame_id(&sample.frame_id));
        self.count_insert(outcome);
        self.prune();
        self.emit_if_covered()
    }

    pub fn push_velocity(&mut self, _log_time_ns: u64, sample: VelocitySample) -> Vec<PairEvent> {
        let twist = TwistSample {
            stamp_ns: sample.stamp_ns,
            linear_mps: sample.linear_mps,
            angular_radps: sample.angular_radps,
        };
        let outcome = self
            .velocity
            .insert(twist, normalize_frame_id(&sample.frame_id));
        self.count_insert(outcome);
        self.prune();
        self.emit_if_covered()
    }

    /// Static transforms build the tree used for extrinsics; dynamic `/tf`
    /// is ignored (sensor mounts are static, and odometry frames on `/tf`
    /// must not be mistaken for them).
    /// Feed any decoded message (the dispatch every caller would otherwise repeat).
    pub fn push_decoded(&mut self, log_time_ns: u64, decoded: Decoded) -> Vec<PairEvent> {
        match decoded {
            Decoded::Scan(mut scan) => {
                // Taken once: `layout_period_s` records the scan's stamp.
                let period_s = self.layout_period_s(scan.stamp_ns);
                let warnings = self.place_sensor(&mut scan, period_s);
                self.complete_layout(&mut scan, period_s);
                let mut events: Vec<PairEvent> =
                    warnings.into_iter().map(PairEvent::Warning).collect();
                events.extend(self.push_scan(log_time_ns, Arc::new(scan)));
                events
            }
            Decoded::Imu(sample) => self.push_imu(log_time_ns, sample),
            Decoded::Velocity(sample) => self.push_velocity(log_time_ns, sample),
            Decoded::Transforms {
                transforms,
                is_static,
            } => {
                self.push_transforms(&transforms, is_static);
                Vec::new()
            }
        }
    }

    pub fn push_transforms(&mut self, transforms: &[FrameTransform], is_static: bool) {
        if !is_static {
            for transform in transforms {
                self.placement.keep_tf(transform);
            }
            return;
        }
        for transform in transforms {
            self.transforms.insert(transform);
        }
    }

    /// End of log: emits the pending pair, if any, with the motion received.
    pub fn finish(&mut self) -> Vec<PairEvent> {
        self.emit_pending(false)
    }

    /// The static transforms received so far (`/tf_static`).
    pub fn transforms(&self) -> &TransformTree {
        &self.transforms
    }

    pub fn stats(&self) -> &PairingStats {
        &self.stats
    }

    /// Motion samples currently held (both sources).
    pub fn buffered_sample_count(&self) -> usize {
        self.velocity.samples.len() + self.imu.samples.len()
    }

    /// Scans currently held (0, 1 or 2).
    pub fn buffered_scan_count(&self) -> usize {
        match self.state {
            PairerState::NoScan => 0,
            PairerState::HavePrevious(_) => 1,
            PairerState::PairPending { .. } => 2,
        }
    }

    /// Nominal period in use: the value set, else the running median of dts.
    pub fn nominal_period_s(&self) -> Option<f64> {
        self.nominal_period_override_s
            .or_else(|| median(&self.accepted_dts_s))
    }

    /// Maximum dt for a pair, seconds, when one is known.
    pub fn max_gap_s(&self) -> Option<f64> {
        self.cfg.max_gap_s.or_else(|| {
            self.nominal_period_s()
                .map(|p| p * self.cfg.max_gap_periods)
        })
    }

    fn accept_or_skip(
        &mut self,
        previous: ScanEntry,
        current: ScanEntry,
        events: &mut Vec<PairEvent>,
    ) -> PairerState {
        let dt_ns = current.stamp_ns() - previous.stamp_ns();
        let dt_s = dt_ns as f64 * 1e-9;
        let max_gap_s = self.max_gap_s();
        if dt_ns <= 0 {
            self.stats.skipped_nonpositive_dt += 1;
            let reset_threshold_s = max_gap_s.unwrap_or(CLOCK_RESET_FALLBACK_S);
            if -dt_s > reset_threshold_s {
                // A jump this far back is a clock reset (e.g. a replayed
                // segment), not jitter: keeping the old scan would reject
                // every later scan, so pairing restarts from the new one.
                self.stats.clock_resets += 1;
                events.push(PairEvent::Warning(format!(
                    "scan stamps jumped back by {:.3} s (log time {} ns); pairing restarts from this scan",
                    -dt_s, current.log_time_ns
                )));
                return PairerState::HavePrevious(current);
            }
            return PairerState::HavePrevious(previous);
        }
        if max_gap_s.is_some_and(|max| dt_s > max) {
            self.stats.skipped_gap += 1;
            return PairerState::HavePrevious(current);
        }
        self.record_dt(dt_s);
        PairerState::PairPending { previous, current }
    }

    fn record_dt(&mut self, dt_s: f64) {
        if self.accepted_dts_s.len() == MEDIAN_WINDOW_LEN {
            self.accepted_dts_s.pop_front();
        }
        self.accepted_dts_s.push_back(dt_s);
        self.stats.nominal_period_s = self.nominal_period_s();
    }

    fn count_insert(&mut self, outcome: InsertOutcome) {
        match outcome {
            InsertOutcome::Inserted => {}
            InsertOutcome::Late => self.stats.late_samples += 1,
            InsertOutcome::InsertedWithOverflow => self.stats.overflow_dropped_samples += 1,
        }
    }

    /// Keeps only the motion samples a present or future pair can use.
    fn prune(&mut self) {
        match &self.state {
            PairerState::NoScan => {
                let history_ns = self.hold_ns + seconds_to_ns(PRE_SCAN_HISTORY_S);
                if let Some(newest) = self.velocity.newest_ns {
                    self.velocity.prune_before(newest - history_ns);
                }
                if let Some(newest) = self.imu.newest_ns {
                    self.imu.prune_before(newest - history_ns);
                }
            }
            PairerState::HavePrevious(previous) | PairerState::PairPending { previous, .. } => {
                let cut_ns = previous.start_ns - self.hold_ns;
                self.velocity.prune_before(cut_ns);
                self.imu.prune_before(cut_ns);
            }
        }
    }

    fn motion_covers(&self, stamp_ns: StampNs) -> bool {
        (!self.cfg.has_velocity_source || self.velocity.reaches(stamp_ns))
            && (!self.cfg.has_imu_source || self.imu.reaches(stamp_ns))
    }

    fn emit_if_covered(&mut self) -> Vec<PairEvent> {
        match &self.state {
            PairerState::PairPending { current, .. } if self.motion_covers(current.end_ns) => {
                self.emit_pending(true)
            }
            _ => Vec::new(),
        }
    }

    /// Emits the pending pair, if any; `current` becomes the previous scan.
    fn emit_pending(&mut self, coverage_complete: bool) -> Vec<PairEvent> {
        let (previous, current) = match mem::take(&mut self.state) {
            PairerState::PairPending { previous, current } => (previous, current),
            other => {
                // Nothing pending: put back NoScan / HavePrevious untouched.
                self.state = other;
                return Vec::new();
            }
        };
        let mut events = Vec::new();
        let coverage_complete = coverage_complete || self.motion_covers(current.end_ns);
        let motion = self.pair_motion(&previous, &current, coverage_complete, &mut events);
        self.count_pair(&motion);
        let dt_s = (current.stamp_ns() - previous.stamp_ns()) as f64 * 1e-9;
        let pair = ScanPair {
            dt_s,
            step_s: dt_s,
            previous: previous.scan,
            current: Arc::clone(&current.scan),
            motion,
            previous_log_time_ns: previous.log_time_ns,
            current_log_time_ns: current.log_time_ns,
            index: self.next_index,
        };
        self.next_index += 1;
        events.push(PairEvent::Pair(pair));
        self.state = PairerState::HavePrevious(current);
        self.prune();
        events
    }

    fn count_pair(&mut self, motion: &PairMotion) {
        self.stats.pairs_emitted += 1;
        if motion.velocity_unavailable {
            self.stats.pairs_without_velocity += 1;
        }
        if motion.imu_unavailable {
            self.stats.pairs_without_imu += 1;
        }
        if !motion.coverage_complete {
            self.stats.pairs_motion_incomplete += 1;
        }
    }

    fn pair_motion(
        &mut self,
        previous: &ScanEntry,
        current: &ScanEntry,
        coverage_complete: bool,
        events: &mut Vec<PairEvent>,
    ) -> PairMotion {
        // A sensor placed at every scan in its clouds' (world) frame: the
        // placements are the motion, in the axes the scans were moved into.
        if let Some(motion) = self.placement.motion(
            previous.stamp_ns(),
            current.stamp_ns(),
            self.cfg.motion_hold_s,
        ) {
            return motion;
        }
        let from_ns = previous.start_ns - self.hold_ns;
        let to_ns = current.end_ns + self.hold_ns;
        let twists = self.velocity.window(from_ns, to_ns);
        let gyro = self.imu.window(from_ns, to_ns);
        let velocity_frame = self.velocity.frame_id.clone().unwrap_or_default();
        let imu_frame = self.imu.frame_id.clone().unwrap_or_default();

        let twist_input = (!twists.is_empty()).then(|| {
            (
                twists.as_slice(),
                self.extrinsic("velocity", &current.scan, &velocity_frame, events),
            )
        });
        let gyro_input = (!gyro.is_empty()).then(|| {
            (
                gyro.as_slice(),
                self.extrinsic("imu", &current.scan, &imu_frame, events),
            )
        });

        if twist_input.is_none() {
            let reason = if self.cfg.has_velocity_source {
                "no velocity sample near a scan pair"
            } else {
                "no velocity source"
            };
            self.warn_once(reason, format!("{reason}: the engine estimates the ego motion from the static world where the scans allow it (`looming` summary line); other pairs carry no ego velocity"), events);
        }
        if gyro_input.is_none() {
            let reason = if self.cfg.has_imu_source {
                "no IMU sample near a scan pair"
            } else {
                "no IMU source"
            };
            self.warn_once(
                reason,
                format!("{reason}: angular velocity taken from the velocity twist where available"),
                events,
            );
        }

        build_pair_motion(MotionInputs {
            twists: twist_input,
            gyro: gyro_input,
            hold_s: self.cfg.motion_hold_s,
            coverage_complete,
        })
    }

    fn extrinsic(
        &mut self,
        kind: &str,
        scan: &Scan,
        motion_frame: &str,
        events: &mut Vec<PairEvent>,
    ) -> ExtrinsicInfo {
        let (lidar_frame, pose) = origin::extrinsic_frame(scan, self.cfg.cli_extrinsic.is_some());
        let info = resolve_extrinsic(
            &self.transforms,
            self.cfg.cli_extrinsic.as_ref(),
            &lidar_frame,
            &pose,
            motion_frame,
        );
        if info.source == ExtrinsicSource::IdentityAssumed {
            let key = format!("identity {kind} {} {}", info.motion_frame, info.lidar_frame);
            let message = format!(
                "no transform between LiDAR frame `{}` and {kind} frame `{}` (no --extrinsic, none in /tf_static): assuming identity, lever arm and mounting rotation ignored",
                info.lidar_frame, info.motion_frame
            );
            self.warn_once(&key, message, events);
        }
        self.stats.extrinsic_source.insert(
            kind.to_owned(),
            format!(
                "{} ({} from {})",
                info.source.as_str(),
                info.motion_frame,
                info.lidar_frame
            ),
        );
        info
    }

    fn warn_once(&mut self, key: &str, message: String, events: &mut Vec<PairEvent>) {
        if self.warned.insert(key.to_owned()) {
            events.push(PairEvent::Warning(message));
        }
    }
}

fn median(values: &VecDeque<f64>) -> Option<f64> {
    if values.is_empty() {
        return None;
    }
    let mut sorted: Vec<f64> = values.iter().copied().collect();
    sorted.sort_by(f64::total_cmp);
    let mid = sorted.len() / 2;
    Some(if sorted.len().is_multiple_of(2) {
        0.5 * (sorted[mid - 1] + sorted[mid])
    } else {
        sorted[mid]
    })
}

#[cfg(test)]
mod tests;
