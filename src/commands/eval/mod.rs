//! `looming eval`: the engine's accuracy against ground truth. Reads a log that
//! carries `/truth/points` (a synthetic drive, before or after `process`),
//! pairs its scans like `process`, runs the engine and compares, per quantity
//! and per class of cell, with the truth of the same points.

mod accumulator;
mod external;

use accumulator::Accumulator;

use std::collections::{BTreeMap, HashMap};
use std::path::Path;

use crate::engine::{self, EngineConfig};
use crate::input::InputFile;
use crate::model::{Scan, ScanPair, StampNs};
use crate::objects::{ObjectConfig, ObjectTracker, PairObjects};
use crate::pipeline::{ReplayError, ReplayReport, ScanOptions, replay_input};
use crate::truth::{self, PointTruth};

/// |own-motion looming| above which a truth cell counts as "moving
/// observably": motion that changes the range along the ray.
pub(crate) const OBSERVABLE_MOTION_PER_S: f64 = 0.1;

#[derive(Debug, thiserror::Error)]
pub enum EvalError {
    #[error(transparent)]
    Input(#[from] crate::input::InputError),
    #[error("{path}: {source}")]
    Topic {
        path: String,
        source: crate::topics::TopicError,
    },
    #[error(
        "{0}: no /truth/points channel: eval needs a log with ground truth (see `looming synth`)"
    )]
    NoTruth(String),
    #[error("{0}")]
    Truth(String),
    #[error("truth reader thread failed")]
    Internal,
    /// `strict` and the log had a bad message or was truncated.
    #[error("{0}")]
    Strict(String),
}

/// The truth of one scan: per input point index, and, when the truth comes
/// from another log (`--truth`), the index of each point by its exact
/// position (a KITTI import reorders the points but keeps their float bits).
#[derive(Debug, Default)]
pub(crate) struct ScanTruth {
    pub points: Vec<PointTruth>,
    pub index_by_position: Option<HashMap<[u32; 3], u32>>,
}

impl ScanTruth {
    fn of(&self, scan: &Scan, point: usize) -> Option<PointTruth> {
        let index = match &self.index_by_position {
            None => *scan.source_index.get(point)?,
            Some(by_position) => *by_position.get(&position_key(&scan.points_m[point]))?,
        };
        self.points.get(index as usize).copied()
    }
}

/// The exact bits of a position.
pub(crate) fn position_key(p: &[f32; 3]) -> [u32; 3] {
    [p[0].to_bits(), p[1].to_bits(), p[2].to_bits()]
}

/// Error statistics from a histogram of |error| (log-spaced bins: bounded memory
/// however long the log) plus running sums.
#[derive(Debug, Clone)]
pub(crate) struct ErrorStats {
    bins: Vec<u64>,
    count: u64,
    sum: f64,
    sum_sq: f64,
}

const BINS_PER_DECADE: f64 = 200.0;
const LOWEST: f64 = 1e-6;
const DECADES: f64 = 9.0;

impl Default for ErrorStats {
    fn default() -> Self {
        Self {
            bins: vec![0; (BINS_PER_DECADE * DECADES) as usize + 2],
            count: 0,
            sum: 0.0,
            sum_sq: 0.0,
        }
    }
}

impl ErrorStats {
    pub fn add(&mut self, error: f64) {
        if !error.is_finite() {
            return;
        }
        let magnitude = error.abs();
        let bin = if magnitude < LOWEST {
            0
        } else {
            (((magnitude / LOWEST).log10() * BINS_PER_DECADE) as usize + 1).min(self.bins.len() - 1)
        };
        self.bins[bin] += 1;
        self.count += 1;
        self.sum += error;
        self.sum_sq += error * error;
    }

    /// |error| below which a fraction `q` of the samples lie (bin upper edge).
    pub fn quantile(&self, q: f64) -> f64 {
        if self.count == 0 {
            return f64::NAN;
        }
        let wanted = (q * self.count as f64).ceil() as u64;
        let mut seen = 0;
        for (bin, &n) in self.bins.iter().enumerate() {
            seen += n;
            if seen >= wanted.max(1) {
                return if bin == 0 {
                    LOWEST
                } else {
                    LOWEST * 10f64.powf(bin as f64 / BINS_PER_DECADE)
                };
            }
        }
        f64::INFINITY
    }

    pub fn summary(&self) -> Summary {
        let n = self.count.max(1) as f64;
        Summary {
            count: self.count,
            median_abs: self.quantile(0.5),
            p90_abs: self.quantile(0.9),
            bias: if self.count > 0 {
                self.sum / n
            } else {
                f64::NAN
            },
            rmse: if self.count > 0 {
                (self.sum_sq / n).sqrt()
            } else {
                f64::NAN
            },
        }
    }
}

#[derive(Debug, Clone, Copy, serde::Serialize)]
pub struct Summary {
    pub count: u64,
    pub median_abs: f64,
    pub p90_abs: f64,
    pub bias: f64,
    pub rmse: f64,
}

/// Classes of cells (by the truth of the cell's return and the engine's mask).
pub(crate) const CLASSES: [&str; 6] = [
    "static_road",
    "static_facing",
    "static_oblique",
    "moving",
    "all_unmasked",
    "masked",
];

/// Moving-object detection counts over unmasked cells.
#[derive(Debug, Clone, Copy, Default, serde::Serialize)]
pub struct Detection {
    pub true_positive: u64,
    pub false_positive: u64,
    pub false_negative: u64,
    pub true_negative: u64,
    pub precision: f64,
    pub recall: f64,
    pub f1: f64,
    /// Recall against every cell on an actor, observable motion or not.
    pub recall_all_actor_cells: f64,
}

/// The report of `looming eval`.
#[derive(Debug, Clone, serde::Serialize)]
pub struct EvalReport {
    pub file: String,
    pub pairs: u64,
    pub pairs_with_ego_velocity: u64,
    pub config: EngineConfig,
    /// quantity -> class -> stats. Quantities: l_lidar, l_ray_ego, fused (vs true
    /// ray looming), disagreement (vs true own-motion looming), l_ego (vs true
    /// point looming, per point), l_ego_relative (|error| / |truth|, static points).
    pub errors: BTreeMap<String, BTreeMap<String, Summary>>,
    pub moving_detection: Detection,
    pub observable_motion_threshold_per_s: f64,
    /// Messages of the selected topics that failed to decode: skipped and
    /// counted, as `process` does (absent from the JSON when none).
    #[serde(skip_serializing_if = "is_zero")]
    pub bad_messages: u64,
}

fn is_zero(count: &u64) -> bool {
    *count == 0
}

/// Evaluate the engine on `path` with `config`, against the log's own truth.
pub fn evaluate(path: &Path, config: &EngineConfig) -> Result<EvalReport, EvalError> {
    evaluate_against(path, config, None, &ScanOptions::default())
}

/// Evaluate the engine on `path` with `config`, against the truth of the log
/// itself or, with `truth_path`, of another log whose LiDAR scans have the
/// same stamps and points (the synthetic drive a KITTI folder was made from);
/// its points are matched by their exact positions. The log is read, decoded
/// and paired with `scans`, as `process` would with the same options.
pub fn evaluate_against(
    path: &Path,
    config: &EngineConfig,
    truth_path: Option<&Path>,
    scans: &ScanOptions,
) -> Result<EvalReport, EvalError> {
    let input = InputFile::open(path, scans.input_options.clone())?;
    let mut state = EvalState::new(config);
    let outcome = match truth_path {
        None => own_truth(path, &input, scans, &mut state),
        Some(truth_path) => external::with_truth_of(truth_path, |truths| {
            replay_input(&input, scans, &mut |_| {}, &mut |pair| {
                if let Some(truth) = truths.truth_at(pair.current.stamp_ns) {
                    state.evaluate_pair(&pair, &truth);
                }
            })
            .map_err(replay_error)
        }),
    };
    let replayed = outcome?;
    let mut report = state.report(path);
    report.bad_messages = replayed.bad_messages.count;
    Ok(report)
}

fn replay_error(error: ReplayError) -> EvalError {
    match error {
        ReplayError::Input(e) => EvalError::Input(e),
        ReplayError::Topic { path, source } => EvalError::Topic { path, source },
        ReplayError::Strict(reason) => EvalError::Strict(reason),
    }
}

/// The truth channel of the LiDAR `scans` selects: on a drive with several
/// LiDARs, `/truth/<sensor>/points`, else `/truth/points`.
fn truth_channel_of(input: &InputFile, scans: &ScanOptions) -> Option<u16> {
    let channels = &input.catalog().channels;
    let find = |topic: &str| channels.values().find(|c| c.topic == topic).map(|c| c.id);
    let sensor = crate::topics::select(input.catalog(), &scans.topics)
        .ok()
        .and_then(|selected| selected.lidar)
        .map(|lidar| crate::topics::sensor_name(&lidar.topic));
    sensor
        .and_then(|sensor| find(&truth::points_topic(Some(&sensor))))
        .or_else(|| find(&truth::points_topic(None)))
}

/// Truth from the log's own `/truth/points`: it arrives with its scan, before
/// the pair that reports on it.
fn own_truth(
    path: &Path,
    input: &InputFile,
    scans: &ScanOptions,
    state: &mut EvalState,
) -> Result<ReplayReport, EvalError> {
    let truth_channel = truth_channel_of(input, scans)
        .ok_or_else(|| EvalError::NoTruth(path.display().to_string()))?;
    let truths = std::cell::RefCell::new(BTreeMap::<StampNs, ScanTruth>::new());
    let mut failure: Option<String> = None;
    let replayed = replay_input(
        input,
        scans,
        &mut |message| {
            if message.channel_id == truth_channel {
                match truth::decode_points(&message.data) {
                    Ok((stamp, points)) => {
                        let truth = ScanTruth {
                            points,
                            index_by_position: None,
                        };
                        truths.borrow_mut().insert(stamp, truth);
                    }
                    Err(e) => failure = Some(e),
                }
            }
        },
        &mut |pair| {
            let mut truths = truths.borrow_mut();
            // Truth of older scans is no longer needed: memory stays bounded.
            let keep = truths.split_off(&pair.previous.stamp_ns);
            *truths = keep;
            if let Some(truth) = truths.get(&pair.current.stamp_ns) {
                state.evaluate_pair(&pair, truth);
            }
        },
    )
    .map_err(replay_error)?;
    match failure {
        Some(reason) => Err(EvalError::Truth(reason)),
        None => Ok(replayed),
    }
}

/// The engine, its cache and the error accumulators of a run.
struct EvalState<'c> {
    config: &'c EngineConfig,
    cache: engine::EngineCache,
    /// The objects' ids and velocities, as `process` follows them.
    tracker: ObjectTracker,
    accumulator: Accumulator,
    pairs: u64,
    with_ego: u64,
}

impl<'c> EvalState<'c> {
    fn new(config: &'c EngineConfig) -> Self {
        Self {
            config,
            cache: engine::EngineCache::default(),
            tracker: ObjectTracker::default(),
            accumulator: Accumulator::default(),
            pairs: 0,
            with_ego: 0,
        }
    }

    fn evaluate_pair(&mut self, pair: &ScanPair, truth: &ScanTruth) {
        let Some(mut result) = engine::compute_with_cache(pair, self.config, &mut self.cache)
        else {
            return;
        };
        self.pairs += 1;
        self.with_ego += u64::from(result.availability.ego_velocity);
        // What users see: the fused looming after the objects' feedback.
        let engine = (result.mask.clone(), result.fused.clone());
        let (objects, _) = PairObjects::find_tracked_fused(
            &pair.current,
            &mut result,
            (&ObjectConfig::default(), &self.config.threat_ttc_s),
            &mut self.tracker,
            pair.step_s,
        );
        self.accumulator
            .add_pair(&pair.current, (&result, &engine), &objects, truth);
    }

    fn report(self, path: &Path) -> EvalReport {
        let (errors, moving_detection) = self.accumulator.finish();
        EvalReport {
            file: path.display().to_string(),
            pairs: self.pairs,
            pairs_with_ego_velocity: self.with_ego,
            config: self.config.clone(),
            errors,
            moving_detection,
            observable_motion_threshold_per_s: OBSERVABLE_MOTION_PER_S,
            bad_messages: 0,
        }
    }
}

impl EvalReport {
    /// The human-readable tables.
    pub fn to_text(&self) -> String {
        use std::fmt::Write as _;
        let mut out = String::new();
        let _ = writeln!(
            out,
            "{}: {} pairs ({} with ego velocity)",
            self.file, self.pairs, self.pairs_with_ego_velocity
        );
        if self.bad_messages > 0 {
            let _ = writeln!(out, "{} bad messages skipped", self.bad_messages);
        }
        let _ = writeln!(
            out,
            "\n{:<16} {:<16} {:>9} {:>10} {:>10} {:>10} {:>10}",
            "quantity", "class", "cells", "median|e|", "p90|e|", "bias", "rmse"
        );
        for (quantity, classes) in &self.errors {
            for class in CLASSES
                .iter()
                .chain(["static_points", "moving_points", "static", "all"].iter())
            {
                if let Some(s) = classes.get(*class) {
                    let _ = writeln!(
                        out,
                        "{:<16} {:<16} {:>9} {:>10.4} {:>10.4} {:>10.4} {:>10.4}",
                        quantity, class, s.count, s.median_abs, s.p90_abs, s.bias, s.rmse
                    );
                }
            }
        }
        let d = &self.moving_detection;
        let _ = writeln!(
            out,
            "\nmoving cells (|own-motion looming| >= {} 1/s, unmasked): precision {:.3} recall {:.3} F1 {:.3} (tp {} fp {} fn {}); recall over all actor cells {:.3}",
            self.observable_motion_threshold_per_s,
            d.precision,
            d.recall,
            d.f1,
            d.true_positive,
            d.false_positive,
            d.false_negative,
            d.recall_all_actor_cells
        );
        out
    }
}
