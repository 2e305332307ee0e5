//! `looming quality`: the quality figures of an annotated log, per scan and in
//! total, with diagnoses (`docs/quality.md`). Reads the `quality` object of
//! every `/looming/pairs` message (written by `process`, see
//! [`crate::quality`]) and counts `/looming/events`; memory is bounded by the
//! per-scan lines and fixed-size histograms.

use std::collections::BTreeMap;
use std::path::Path;

use serde::{Deserialize, Serialize};

use crate::annotate::pairs::PAIRS_TOPIC;
use crate::input::{Flow, InputError, InputFile, InputOptions, InputRecord};
use crate::quality::{AbsHistogram, MaskCounts, PairQuality, median};

/// A ground half reads "approaching" or "receding" beyond this, 1/s.
pub const GROUND_SIDE_THRESHOLD_PER_S: f64 = 0.02;
/// Fewest trusted static ground cells a half needs to be judged in a pair.
pub const MIN_SIDE_CELLS: u64 = 10;
/// A ground pattern is consistent when it holds in at least this share of the
/// pairs where both halves can be judged (and in at least two pairs).
pub const CONSISTENT_SHARE: f64 = 0.5;
/// Above this share of the trusted ground flagged moving, the ego motion is wrong.
pub const GROUND_MOVING_LIMIT: f64 = 0.05;
/// Below this trusted fraction the log is not to be trusted.
pub const MIN_TRUSTED_FRACTION: f64 = 0.5;

#[derive(Debug, thiserror::Error)]
pub enum QualityError {
    #[error(transparent)]
    Input(#[from] InputError),
    #[error("{path}: no /looming/pairs channel: not written by `looming process` (run it first)")]
    NotProcessed { path: String },
    #[error("{path}: /looming/pairs message at log time {log_time_ns}: {reason}")]
    BadRecord {
        path: String,
        log_time_ns: u64,
        reason: String,
    },
}

/// What `quality` reads of a `/looming/pairs` message (unknown fields, such
/// as those of other tool versions, are ignored).
#[derive(Debug, Deserialize)]
struct PairMessage {
    index: u64,
    current: CurrentScan,
    #[serde(default)]
    speed_mps: Option<f64>,
    #[serde(default)]
    quality: Option<PairQuality>,
}

#[derive(Debug, Deserialize)]
struct CurrentScan {
    stamp_ns: i64,
    log_time_ns: u64,
    #[serde(default)]
    layout: Option<serde_json::Value>,
}

/// How rings and per-point times were obtained, as `/looming/pairs` records it
/// (`current.layout`); "unknown" when it does not.
fn layout_text(layout: Option<&serde_json::Value>) -> String {
    match layout {
        None | Some(serde_json::Value::Null) => "unknown".into(),
        Some(serde_json::Value::String(s)) => s.clone(),
        // The record's own words, as the run summary printed them.
        Some(serde_json::Value::Object(fields)) => match fields.get("description") {
            Some(serde_json::Value::String(s)) => s.clone(),
            _ => serde_json::Value::Object(fields.clone()).to_string(),
        },
        Some(other) => other.to_string(),
    }
}

/// One line per pair.
#[derive(Debug, Clone, Serialize)]
pub struct ScanLine {
    pub index: u64,
    pub log_time_ns: u64,
    pub stamp_ns: i64,
    pub speed_mps: Option<f64>,
    pub layout: String,
    /// `None` when the pair has no quality figures (no range image).
    pub trusted_fraction: Option<f64>,
    pub ground_cells: Option<u64>,
    pub ground_median_abs_fused_per_s: Option<f64>,
    pub ground_left_median_fused_per_s: Option<f64>,
    pub ground_right_median_fused_per_s: Option<f64>,
    pub ground_left_median_d_per_s: Option<f64>,
    pub ground_right_median_d_per_s: Option<f64>,
    pub median_abs_d_static_per_s: Option<f64>,
    pub moving_fraction: Option<f64>,
    pub threat_cells: Option<u64>,
    pub dominant_mask: Option<String>,
}

/// Min / median / max over rings, and every ring (lowest beam first).
#[derive(Debug, Clone, Serialize)]
pub struct RangeNoise {
    pub rings: usize,
    pub min_m: Option<f64>,
    pub median_m: Option<f64>,
    pub max_m: Option<f64>,
    /// Per ring, the median over pairs of the noise the engine used, metres.
    pub per_ring_m: Vec<f64>,
}

/// The per-laser range offsets the engine took out (`engine::bias`).
#[derive(Debug, Clone, Serialize)]
pub struct RangeOffsets {
    /// Rings with an offset reported.
    pub rings: usize,
    /// Root mean square over rings, metres; 0 when none was found.
    pub rms_m: Option<f64>,
    /// Largest |offset|, metres.
    pub max_abs_m: Option<f64>,
    /// Per ring, the median over pairs, metres.
    pub per_ring_m: Vec<f64>,
}

/// How one ground quantity (fused or D) reads on the two halves over the log.
#[derive(Debug, Clone, Default, Serialize)]
pub struct GroundSides {
    /// Median over pairs of the per-pair medians (not a pooled median), 1/s.
    pub left_median_per_s: Option<f64>,
    pub right_median_per_s: Option<f64>,
    /// Pairs where both halves have at least `MIN_SIDE_CELLS` trusted ground
    /// cells.
    pub pairs_judged: u64,
    /// Of those: left approaching and right receding (each beyond the
    /// threshold), the reverse, both approaching, both receding.
    pub left_approaching_right_receding: u64,
    pub left_receding_right_approaching: u64,
    pub both_approaching: u64,
    pub both_receding: u64,
}

/// The whole log.
#[derive(Debug, Clone, Serialize)]
pub struct QualityTotals {
    pub pairs: u64,
    pub pairs_with_quality: u64,
    pub points: u64,
    pub trusted_points: u64,
    /// Over all points of all pairs.
    pub trusted_fraction: Option<f64>,
    pub cells: u64,
    pub trusted_cells: u64,
    pub trusted_cell_fraction: Option<f64>,
    /// Occupied cells per mask bit, summed over pairs.
    pub masked_cells: MaskCounts,
    /// The same as fractions of the occupied cells.
    pub masked_cell_fractions: BTreeMap<String, f64>,
    pub dominant_mask: Option<String>,
    /// Pairs per layout.
    pub layouts: BTreeMap<String, u64>,
    pub range_noise: RangeNoise,
    pub range_offsets: RangeOffsets,
    pub ground_cells: u64,
    pub ground_trusted_static_cells: u64,
    /// Trusted ground cells flagged moving, and their share of the trusted
    /// ground cells (0 when all is right).
    pub ground_moving_cells: u64,
    pub ground_moving_fraction: Option<f64>,
    /// Median |fused| over the trusted static ground cells of all pairs,
    /// pooled (histogram bins 4.7 % wide), 1/s.
    pub ground_median_abs_fused_per_s: Option<f64>,
    /// 90th percentile of the same.
    pub ground_p90_abs_fused_per_s: Option<f64>,
    pub ground_fused: GroundSides,
    pub ground_d: GroundSides,
    /// Median sensor height above the ground over pairs, metres.
    pub ground_height_m: Option<f64>,
    pub ground_roll_deg: Option<f64>,
    pub ground_pitch_deg: Option<f64>,
    /// Median |L_lidar - L_ray_ego| over the trusted static cells of all pairs
    /// (pooled), 1/s; `None` without ego velocity.
    pub median_abs_d_static_per_s: Option<f64>,
    pub pairs_with_ego_velocity: u64,
    pub moving_cells: u64,
    /// Moving cells over trusted cells.
    pub moving_fraction: Option<f64>,
    pub threat_cells: u64,
    /// `/looming/events` messages.
    pub near_miss_events: u64,
}

/// A finding, with a stable code.
#[derive(Debug, Clone, Serialize)]
pub struct Diagnosis {
    /// `ground_split`, `ground_offset`, `ground_split_d`, `ground_offset_d`, `ground_moving`,
    /// `low_trust`, `range_offsets`, `no_ground`, `no_quality`.
    pub code: String,
    pub message: String,
}

/// `looming quality --json`: schema `schemas/looming.QualityReport.schema.json`.
#[derive(Debug, Clone, Serialize)]
pub struct QualityReport {
    pub tool: String,
    pub version: String,
    pub input: String,
    pub scans: Vec<ScanLine>,
    pub totals: QualityTotals,
    pub diagnoses: Vec<Diagnosis>,
}

/// Read an annotated log and sum its quality figures.
pub fn read_quality(path: &Path) -> Result<QualityReport, QualityError> {
    let input = InputFile::open(path, InputOptions::default())?;
    let name = path.display().to_string();
    let channels = &input.catalog().channels;
    let pairs_channel = channels
        .values()
        .find(|c| c.topic == PAIRS_TOPIC)
        .map(|c| c.id)
        .ok_or_else(|| QualityError::NotProcessed { path: name.clone() })?;
    let events_channel = channels
        .values()
        .find(|c| c.topic == crate::annotate::EVENTS_TOPIC)
        .map(|c| c.id);
    let mut builder = Builder::default();
    let mut bad = None;
    input.read_records(false, &mut |record| {
        let InputRecord::Message(message) = record else {
            return Flow::Continue(());
        };
        if Some(message.channel_id) == events_channel {
            builder.events += 1;
        } else if message.channel_id == pairs_channel {
            match serde_json::from_slice::<PairMessage>(&message.data) {
                Ok(pair) => builder.add(pair),
                Err(error) => {
                    bad = Some(QualityError::BadRecord {
                        path: name.clone(),
                        log_time_ns: message.log_time_ns,
                        reason: error.to_string(),
                    });
                    return Flow::Break(());
                }
            }
        }
        Flow::Continue(())
    })?;
    if let Some(error) = bad {
        return Err(error);
    }
    Ok(builder.finish(name))
}

#[derive(Default)]
struct SideAccumulator {
    left: Vec<f64>,
    right: Vec<f64>,
    sides: GroundSides,
}

impl SideAccumulator {
    fn add(&mut self, left: Option<f64>, right: Option<f64>) {
        let (Some(l), Some(r)) = (left, right) else {
            return;
        };
        self.left.push(l);
        self.right.push(r);
        let t = GROUND_SIDE_THRESHOLD_PER_S;
        let s = &mut self.sides;
        s.pairs_judged += 1;
        match (l > t, l < -t, r > t, r < -t) {
            (true, _, _, true) => s.left_approaching_right_receding += 1,
            (_, true, true, _) => s.left_receding_right_approaching += 1,
            (true, _, true, _) => s.both_approaching += 1,
            (_, true, _, true) => s.both_receding += 1,
            _ => {}
        }
    }

    fn finish(mut self) -> GroundSides {
        self.sides.left_median_per_s = median(&mut self.left);
        self.sides.right_median_per_s = median(&mut self.right);
        self.sides
    }
}

#[derive(Default)]
struct Builder {
    scans: Vec<ScanLine>,
    pairs: u64,
    with_quality: u64,
    with_ego: u64,
    points: u64,
    trusted_points: u64,
    cells: u64,
    trusted_cells: u64,
    masked: MaskCounts,
    layouts: BTreeMap<String, u64>,
    noise_per_ring: Vec<Vec<f64>>,
    offset_per_ring: Vec<Vec<f64>>,
    ground_cells: u64,
    ground_trusted_static: u64,
    ground_moving: u64,
    ground_abs_fused: AbsHistogram,
    ground_fused: SideAccumulator,
    ground_d: SideAccumulator,
    heights: Vec<f64>,
    rolls: Vec<f64>,
    pitches: Vec<f64>,
    abs_d_static: AbsHistogram,
    moving: u64,
    threat: u64,
    events: u64,
}

impl Builder {
    fn add(&mut self, pair: PairMessage) {
        self.pairs += 1;
        let layout = layout_text(pair.current.layout.as_ref());
        *self.layouts.entry(layout.clone()).or_default() += 1;
        let q = pair.quality.as_ref();
        self.scans.push(ScanLine {
            index: pair.index,
            log_time_ns: pair.current.log_time_ns,
            stamp_ns: pair.current.stamp_ns,
            speed_mps: pair.speed_mps,
            layout,
            trusted_fraction: q.and_then(|q| q.trusted_fraction),
            ground_cells: q.map(|q| q.ground.cells),
            ground_median_abs_fused_per_s: q.and_then(|q| q.ground.median_abs_fused_per_s),
            ground_left_median_fused_per_s: q.and_then(|q| q.ground.left.median_fused_per_s),
            ground_right_median_fused_per_s: q.and_then(|q| q.ground.right.median_fused_per_s),
            ground_left_median_d_per_s: q.and_then(|q| q.ground.left.median_d_per_s),
            ground_right_median_d_per_s: q.and_then(|q| q.ground.right.median_d_per_s),
            median_abs_d_static_per_s: q.and_then(|q| q.median_abs_d_static_per_s),
            moving_fraction: q.and_then(|q| q.moving_fraction),
            threat_cells: q.map(|q| q.threat_cells),
            dominant_mask: q.and_then(|q| q.masked_cells.dominant().map(|(n, _)| n.to_string())),
        });
        let Some(q) = pair.quality else {
            return;
        };
        self.with_quality += 1;
        self.with_ego += u64::from(q.ego_velocity);
        self.points += q.points;
        self.trusted_points += q.trusted_points;
        self.cells += q.cells;
        self.trusted_cells += q.trusted_cells;
        self.masked.add(&q.masked_cells);
        if self.noise_per_ring.len() < q.range_noise_m_per_ring.len() {
            self.noise_per_ring
                .resize(q.range_noise_m_per_ring.len(), Vec::new());
        }
        for (ring, noise) in q.range_noise_m_per_ring.iter().enumerate() {
            if noise.is_finite() {
                self.noise_per_ring[ring].push(f64::from(*noise));
            }
        }
        if self.offset_per_ring.len() < q.range_offset_m_per_ring.len() {
            self.offset_per_ring
                .resize(q.range_offset_m_per_ring.len(), Vec::new());
        }
        for (ring, offset) in q.range_offset_m_per_ring.iter().enumerate() {
            if offset.is_finite() {
                self.offset_per_ring[ring].push(f64::from(*offset));
            }
        }
        let g = &q.ground;
        self.ground_cells += g.cells;
        self.ground_trusted_static += g.trusted_static_cells;
        self.ground_moving += g.moving_cells;
        self.ground_abs_fused.merge(&g.abs_fused_histogram);
        let judged = |side: &crate::quality::GroundSide, value: Option<f64>| {
            value.filter(|_| side.cells >= MIN_SIDE_CELLS)
        };
        self.ground_fused.add(
            judged(&g.left, g.left.median_fused_per_s),
            judged(&g.right, g.right.median_fused_per_s),
        );
        self.ground_d.add(
            judged(&g.left, g.left.median_d_per_s),
            judged(&g.right, g.right.median_d_per_s),
        );
        if let Some(h) = g.height_m {
            self.heights.push(-h);
        }
        self.rolls.extend(g.roll_deg);
        self.pitches.extend(g.pitch_deg);
        if let Some(h) = &q.abs_d_static_histogram {
            self.abs_d_static.merge(h);
        }
        self.moving += q.moving_cells;
        self.threat += q.threat_cells;
    }

    fn finish(mut self, input: String) -> QualityReport {
        let ratio = |a: u64, b: u64| (b > 0).then(|| a as f64 / b as f64);
        let per_ring_m: Vec<f64> = self
            .noise_per_ring
            .iter_mut()
            .map(|v| median(v).unwrap_or(f64::NAN))
            .collect();
        let finite: Vec<f64> = per_ring_m
            .iter()
            .copied()
            .filter(|v| v.is_finite())
            .collect();
        let range_noise = RangeNoise {
            rings: per_ring_m.len(),
            min_m: finite.iter().copied().min_by(f64::total_cmp),
            median_m: median(&mut finite.clone()),
            max_m: finite.iter().copied().max_by(f64::total_cmp),
            per_ring_m: per_ring_m.into_iter().filter(|v| v.is_finite()).collect(),
        };
        let offsets_m: Vec<f64> = self
            .offset_per_ring
            .iter_mut()
            .filter_map(|v| median(v))
            .collect();
        let range_offsets = RangeOffsets {
            rings: offsets_m.len(),
            rms_m: (!offsets_m.is_empty()).then(|| {
                (offsets_m.iter().map(|b| b * b).sum::<f64>() / offsets_m.len() as f64).sqrt()
            }),
            max_abs_m: offsets_m.iter().map(|b| b.abs()).max_by(f64::total_cmp),
            per_ring_m: offsets_m,
        };
        let masked_cell_fractions = self
            .masked
            .named()
            .into_iter()
            .filter_map(|(name, n)| ratio(n, self.cells).map(|f| (name.to_string(), f)))
            .collect();
        let totals = QualityTotals {
            pairs: self.pairs,
            pairs_with_quality: self.with_quality,
            points: self.points,
            trusted_points: self.trusted_points,
            trusted_fraction: ratio(self.trusted_points, self.points),
            cells: self.cells,
            trusted_cells: self.trusted_cells,
            trusted_cell_fraction: ratio(self.trusted_cells, self.cells),
            masked_cells: self.masked,
            masked_cell_fractions,
            dominant_mask: self.masked.dominant().map(|(n, _)| n.to_string()),
            layouts: self.layouts,
            range_noise,
            range_offsets,
            ground_cells: self.ground_cells,
            ground_trusted_static_cells: self.ground_trusted_static,
            ground_moving_cells: self.ground_moving,
            ground_moving_fraction: ratio(
                self.ground_moving,
                self.ground_moving + self.ground_trusted_static,
            ),
            ground_median_abs_fused_per_s: self.ground_abs_fused.quantile(0.5),
            ground_p90_abs_fused_per_s: self.ground_abs_fused.quantile(0.9),
            ground_fused: self.ground_fused.finish(),
            ground_d: self.ground_d.finish(),
            ground_height_m: median(&mut self.heights),
            ground_roll_deg: median(&mut self.rolls),
            ground_pitch_deg: median(&mut self.pitches),
            median_abs_d_static_per_s: (self.with_ego > 0)
                .then(|| self.abs_d_static.quantile(0.5))
                .flatten(),
            pairs_with_ego_velocity: self.with_ego,
            moving_cells: self.moving,
            moving_fraction: ratio(self.moving, self.trusted_cells),
            threat_cells: self.threat,
            near_miss_events: self.events,
        };
        let diagnoses = diagnose(&totals);
        QualityReport {
            tool: "looming".into(),
            version: env!("CARGO_PKG_VERSION").into(),
            input,
            scans: self.scans,
            totals,
            diagnoses,
        }
    }
}

/// At least two pairs and `CONSISTENT_SHARE` of those judged.
fn consistent(count: u64, judged: u64) -> bool {
    count >= 2 && count as f64 >= CONSISTENT_SHARE * judged as f64
}

fn signed(value: Option<f64>) -> String {
    value.map_or("-".into(), |v| format!("{v:+.3}"))
}

/// Ground patterns of one quantity: split (opposite signs) or offset.
fn ground_diagnoses(sides: &GroundSides, what: &str, code_suffix: &str, out: &mut Vec<Diagnosis>) {
    let n = sides.pairs_judged;
    let figures = format!(
        "{what} median {} 1/s on the left, {} on the right",
        signed(sides.left_median_per_s),
        signed(sides.right_median_per_s)
    );
    let t = GROUND_SIDE_THRESHOLD_PER_S;
    let split = |count: u64, left: &str, right: &str| Diagnosis {
        code: format!("ground_split{code_suffix}"),
        message: format!(
            "the ground reads {left} on the left and {right} on the right \
             ({figures}; beyond {t} 1/s with opposite signs in {count} of {n} pairs): \
             a tilted extrinsic (roll) or a wrong LiDAR frame: a rotation about the LiDAR's \
             x axis is wrong (a roll rate the gyro reports but the LiDAR does not have, or \
             misses: a gyro axis misassigned or biased, or an IMU extrinsic whose tilt turns \
             the yaw rate of turns into roll)"
        ),
    };
    if consistent(sides.left_approaching_right_receding, n) {
        out.push(split(
            sides.left_approaching_right_receding,
            "approaching",
            "receding",
        ));
    } else if consistent(sides.left_receding_right_approaching, n) {
        out.push(split(
            sides.left_receding_right_approaching,
            "receding",
            "approaching",
        ));
    }
    let offset = |count: u64, how: &str| Diagnosis {
        code: format!("ground_offset{code_suffix}"),
        message: format!(
            "the whole ground reads {how} ({figures}; beyond {t} 1/s with the same sign \
             on both sides in {count} of {n} pairs): points to a vertical velocity / \
             pitch error (extrinsic) or a time offset between the LiDAR and the motion source"
        ),
    };
    if consistent(sides.both_approaching, n) {
        out.push(offset(sides.both_approaching, "approaching"));
    } else if consistent(sides.both_receding, n) {
        out.push(offset(sides.both_receding, "receding"));
    }
}

/// What each mask bit usually means when it dominates.
fn mask_hint(name: &str) -> &'static str {
    match name {
        "no_previous" => {
            "the previous scan has no surface along the rays: scans far apart, fields of view \
             that do not overlap, or rows (rings) that differ between scans"
        }
        "edge" => {
            "plane fits see neighbours on other surfaces: a sparse or noisy sensor, a range \
             noise set too low for it, or rings assigned to the wrong rows"
        }
        "grazing" => "surfaces seen at grazing incidence: mostly far ground on a low mount",
        "no_ego" => {
            "the ego-motion prediction has no surface: the motion moves the previous scan off \
             the current rays (a wrong velocity, extrinsic or time base)"
        }
        "occlusion" => {
            "ranges change faster than any plausible motion: wrong per-point times or scan \
             period, wrong ego motion, or rings that do not match between scans"
        }
        _ => "",
    }
}

/// Per-laser range offsets worth saying (metres): RMS over the lasers, or
/// one laser's. The engine takes them out either way; above these the
/// sensor's own calibration deserves a look (KITTI's HDL-64E: 2.1 cm RMS).
const OFFSETS_RMS_LIMIT_M: f64 = 0.015;
const OFFSETS_MAX_LIMIT_M: f64 = 0.05;

fn diagnose(t: &QualityTotals) -> Vec<Diagnosis> {
    let mut out = Vec::new();
    if t.pairs_with_quality == 0 {
        out.push(Diagnosis {
            code: "no_quality".into(),
            message: if t.pairs == 0 {
                "no scan pairs in the log".into()
            } else {
                "no pair carries quality figures (processed by an older looming, or no range \
                 image could be made): re-process with `looming process --replace`"
                    .into()
            },
        });
        return out;
    }
    ground_diagnoses(&t.ground_fused, "fused", "", &mut out);
    // D on the ground is the static prediction's error itself: a pattern in it
    // alone (the fused value leaning on the prediction) is worth saying too.
    let mut in_d = Vec::new();
    ground_diagnoses(&t.ground_d, "D", "_d", &mut in_d);
    for d in in_d {
        let plain = d.code.trim_end_matches("_d");
        if !out.iter().any(|o| o.code == plain) {
            out.push(d);
        }
    }
    if t.ground_fused.pairs_judged == 0 {
        out.push(Diagnosis {
            code: "no_ground".into(),
            message: format!(
                "no pair has {MIN_SIDE_CELLS} trusted ground cells on both sides: the ground \
                 checks could not be made ({} ground cells, {} trusted)",
                t.ground_cells,
                t.ground_trusted_static_cells + t.ground_moving_cells
            ),
        });
    }
    if let Some(fraction) = t.ground_moving_fraction
        && fraction > GROUND_MOVING_LIMIT
    {
        out.push(Diagnosis {
            code: "ground_moving".into(),
            message: format!(
                "{:.1} % of the trusted ground is flagged moving (its D is significant): the \
                 static-world prediction is wrong on the ground: check the ego motion (velocity, \
                 extrinsic, times)",
                100.0 * fraction
            ),
        });
    }
    if let (Some(rms), Some(max)) = (t.range_offsets.rms_m, t.range_offsets.max_abs_m)
        && (rms > OFFSETS_RMS_LIMIT_M || max > OFFSETS_MAX_LIMIT_M)
    {
        out.push(Diagnosis {
            code: "range_offsets".into(),
            message: format!(
                "the lasers read ranges offset from each other by {:.1} cm RMS, up to {:.1} cm \
                 (taken out by the engine, estimated from the scans): the sensor's per-laser \
                 calibration is off by that much",
                100.0 * rms,
                100.0 * max
            ),
        });
    }
    if let Some(fraction) = t.trusted_fraction
        && fraction < MIN_TRUSTED_FRACTION
    {
        let dominant = t.dominant_mask.clone().unwrap_or_else(|| "none".into());
        let share = t
            .masked_cell_fractions
            .get(&dominant)
            .copied()
            .unwrap_or(0.0);
        out.push(Diagnosis {
            code: "low_trust".into(),
            message: format!(
                "only {:.1} % of the points are trusted (below {:.0} %); the dominant mask is \
                 `{dominant}` ({:.1} % of occupied cells): {}",
                100.0 * fraction,
                100.0 * MIN_TRUSTED_FRACTION,
                100.0 * share,
                mask_hint(&dominant)
            ),
        });
    }
    out
}

fn percent(value: Option<f64>) -> String {
    value.map_or("-".into(), |v| format!("{:.1} %", 100.0 * v))
}

fn per_s(value: Option<f64>) -> String {
    value.map_or("-".into(), |v| format!("{v:.4}"))
}

impl QualityReport {
    /// The report as text: one line per scan, then the totals and diagnoses.
    pub fn to_text(&self) -> String {
        use std::fmt::Write as _;
        let mut out = String::new();
        let _ = writeln!(out, "quality of {}", self.input);
        let _ = writeln!(
            out,
            "{:>5}  {:>22}  {:>8}  {:>11}  {:>11}  {:>7}  layout",
            "pair", "log time", "trusted", "ground |F|", "|D| static", "moving"
        );
        for s in &self.scans {
            let _ = writeln!(
                out,
                "{:>5}  {:>22}  {:>8}  {:>11}  {:>11}  {:>7}  {}",
                s.index,
                crate::pipeline::format_log_time(s.log_time_ns),
                percent(s.trusted_fraction),
                per_s(s.ground_median_abs_fused_per_s),
                per_s(s.median_abs_d_static_per_s),
                percent(s.moving_fraction),
                s.layout
            );
        }
        let t = &self.totals;
        let _ = writeln!(out, "\ntotal");
        let _ = writeln!(
            out,
            "  pairs                  {} ({} with quality figures, {} with ego velocity)",
            t.pairs, t.pairs_with_quality, t.pairs_with_ego_velocity
        );
        let _ = writeln!(
            out,
            "  trusted                {} of {} points ({} of {} occupied cells)",
            percent(t.trusted_fraction),
            t.points,
            percent(t.trusted_cell_fraction),
            t.cells
        );
        let masks: Vec<String> = t
            .masked_cells
            .named()
            .iter()
            .map(|(name, _)| {
                format!(
                    "{name} {}",
                    percent(t.masked_cell_fractions.get(*name).copied())
                )
            })
            .collect();
        let _ = writeln!(
            out,
            "  masked cells           {} (of occupied cells; a cell may carry several)",
            masks.join(", ")
        );
        let layouts: Vec<String> = t
            .layouts
            .iter()
            .map(|(layout, n)| format!("{layout} ({n} pairs)"))
            .collect();
        let _ = writeln!(out, "  layout                 {}", layouts.join("; "));
        let noise = &t.range_noise;
        let m = |v: Option<f64>| v.map_or("-".into(), |v| format!("{v:.3}"));
        let _ = writeln!(
            out,
            "  range noise per ring   min {} / median {} / max {} m ({} rings)",
            m(noise.min_m),
            m(noise.median_m),
            m(noise.max_m),
            noise.rings
        );
        let offsets = &t.range_offsets;
        let offsets_text = match (offsets.rms_m, offsets.max_abs_m) {
            (Some(rms), Some(max)) if max > 0.0 => format!(
                "rms {rms:.3} / max {max:.3} m, taken out ({} rings)",
                offsets.rings
            ),
            (Some(_), _) => format!("none found ({} rings)", offsets.rings),
            _ => "-".into(),
        };
        let _ = writeln!(out, "  range offset per ring  {offsets_text}");
        let _ = writeln!(
            out,
            "  ground                 {} cells, {} trusted static; sensor {} m above it, \
             roll {} deg, pitch {} deg; {} flagged moving",
            t.ground_cells,
            t.ground_trusted_static_cells,
            m(t.ground_height_m),
            t.ground_roll_deg.map_or("-".into(), |v| format!("{v:+.1}")),
            t.ground_pitch_deg
                .map_or("-".into(), |v| format!("{v:+.1}")),
            percent(t.ground_moving_fraction),
        );
        let _ = writeln!(
            out,
            "  ground |fused|         median {} 1/s, p90 {} (trusted static ground, pooled)",
            per_s(t.ground_median_abs_fused_per_s),
            per_s(t.ground_p90_abs_fused_per_s)
        );
        let _ = writeln!(
            out,
            "  ground left / right    fused {} / {} 1/s, D {} / {} 1/s (medians of per-pair medians)",
            signed(t.ground_fused.left_median_per_s),
            signed(t.ground_fused.right_median_per_s),
            signed(t.ground_d.left_median_per_s),
            signed(t.ground_d.right_median_per_s),
        );
        let _ = writeln!(
            out,
            "  |D| static             median {} 1/s (trusted static cells, pooled)",
            per_s(t.median_abs_d_static_per_s)
        );
        let _ = writeln!(
            out,
            "  moving                 {} of trusted cells; {} threat cells",
            percent(t.moving_fraction),
            t.threat_cells
        );
        let _ = writeln!(out, "  near-miss events       {}", t.near_miss_events);
        let _ = writeln!(out, "\ndiagnosis");
        if self.diagnoses.is_empty() {
            let _ = writeln!(out, "  nothing to report");
        }
        for d in &self.diagnoses {
            let _ = writeln!(out, "  - {}", d.message);
        }
        out
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::quality::{GroundSide, MaskCounts};

    fn pair(index: u64, left: f64, right: f64, trusted: u64) -> PairMessage {
        let side = |v: f64| GroundSide {
            cells: 50,
            median_fused_per_s: Some(v),
            median_d_per_s: Some(0.0),
        };
        let mut quality = PairQuality {
            points: 100,
            trusted_points: trusted,
            trusted_fraction: Some(trusted as f64 / 100.0),
            cells: 100,
            trusted_cells: trusted,
            masked_cells: MaskCounts {
                occlusion: 100 - trusted,
                edge: (100 - trusted) / 2,
                ..MaskCounts::default()
            },
            ego_velocity: true,
            range_noise_m_per_ring: vec![0.02, 0.03, 0.05],
            ..PairQuality::default()
        };
        quality.ground.left = side(left);
        quality.ground.right = side(right);
        quality.ground.trusted_static_cells = 100;
        quality.ground.abs_fused_histogram =
            AbsHistogram::of([left.abs(), right.abs()].into_iter());
        PairMessage {
            index,
            current: CurrentScan {
                stamp_ns: index as i64,
                log_time_ns: index,
                layout: None,
            },
            speed_mps: Some(10.0),
            quality: Some(quality),
        }
    }

    fn report(pairs: Vec<PairMessage>) -> QualityReport {
        let mut builder = Builder::default();
        for p in pairs {
            builder.add(p);
        }
        builder.finish("test.mcap".into())
    }

    fn codes(report: &QualityReport) -> Vec<&str> {
        report.diagnoses.iter().map(|d| d.code.as_str()).collect()
    }

    #[test]
    fn a_clean_ground_says_nothing() {
        let r = report((0..5).map(|i| pair(i, 0.004, -0.003, 90)).collect());
        assert!(r.diagnoses.is_empty(), "{:?}", r.diagnoses);
        assert_eq!(r.totals.trusted_fraction, Some(0.9));
        assert_eq!(r.totals.layouts.get("unknown"), Some(&5));
        assert_eq!(r.totals.range_noise.min_m, Some(0.019999999552965164));
        assert_eq!(r.totals.range_noise.max_m, Some(0.05000000074505806));
        assert_eq!(r.totals.range_noise.rings, 3);
        assert!(r.to_text().contains("nothing to report"));
    }

    #[test]
    fn opposite_halves_consistently_are_a_split() {
        let mut pairs: Vec<PairMessage> = (0..4).map(|i| pair(i, 0.05, -0.04, 90)).collect();
        pairs.push(pair(4, 0.0, 0.0, 90));
        let r = report(pairs);
        assert_eq!(codes(&r), ["ground_split"]);
        let message = &r.diagnoses[0].message;
        assert!(
            message
                .starts_with("the ground reads approaching on the left and receding on the right"),
            "{message}"
        );
        assert!(message.contains("a tilted extrinsic (roll) or a wrong LiDAR frame"));
        assert_eq!(r.totals.ground_fused.left_approaching_right_receding, 4);
        assert_eq!(r.totals.ground_fused.pairs_judged, 5);
        // The reverse reads the other way round.
        let r = report((0..3).map(|i| pair(i, -0.05, 0.04, 90)).collect());
        assert!(
            r.diagnoses[0]
                .message
                .starts_with("the ground reads receding on the left and approaching on the right")
        );
    }

    #[test]
    fn one_odd_pair_is_not_a_pattern() {
        let mut pairs: Vec<PairMessage> = (0..5).map(|i| pair(i, 0.0, 0.0, 90)).collect();
        pairs.push(pair(5, 0.05, -0.05, 90));
        assert!(report(pairs).diagnoses.is_empty());
    }

    #[test]
    fn the_same_sign_on_both_halves_is_an_offset() {
        let r = report((0..3).map(|i| pair(i, -0.05, -0.03, 90)).collect());
        assert_eq!(codes(&r), ["ground_offset"]);
        assert!(
            r.diagnoses[0]
                .message
                .contains("the whole ground reads receding")
        );
        assert!(
            r.diagnoses[0]
                .message
                .contains("vertical velocity / pitch error")
        );
        assert!(r.diagnoses[0].message.contains("time offset"));
    }

    #[test]
    fn large_laser_offsets_are_reported() {
        let with_offsets = |offsets: Vec<f32>| {
            let pairs = (0..3)
                .map(|i| {
                    let mut p = pair(i, 0.004, -0.003, 90);
                    if let Some(q) = p.quality.as_mut() {
                        q.range_offset_m_per_ring = offsets.clone();
                    }
                    p
                })
                .collect();
            report(pairs)
        };
        let r = with_offsets(vec![0.02, -0.03, 0.01]);
        assert_eq!(codes(&r), ["range_offsets"]);
        assert!(
            r.diagnoses[0].message.contains("2.2 cm RMS, up to 3.0 cm"),
            "{}",
            r.diagnoses[0].message
        );
        assert!(codes(&with_offsets(vec![0.0, 0.0, 0.0])).is_empty());
        assert!(codes(&with_offsets(vec![0.005, -0.005, 0.0])).is_empty());
    }

    #[test]
    fn low_trust_names_the_dominant_mask() {
        let r = report((0..3).map(|i| pair(i, 0.0, 0.0, 20)).collect());
        assert_eq!(codes(&r), ["low_trust"]);
        let message = &r.diagnoses[0].message;
        assert!(
            message.contains("only 20.0 % of the points are trusted"),
            "{message}"
        );
        assert!(
            message.contains("`occlusion` (80.0 % of occupied cells)"),
            "{message}"
        );
    }

    #[test]
    fn layouts_are_read_from_the_pair_records_when_present() {
        let mut p = pair(0, 0.0, 0.0, 90);
        p.current.layout = Some(serde_json::json!("organized_rings_from_rows"));
        let r = report(vec![p]);
        assert_eq!(r.scans[0].layout, "organized_rings_from_rows");
        let record: PairMessage = serde_json::from_str(
            r#"{"index": 3, "current": {"stamp_ns": 1, "log_time_ns": 2, "frame_id": "x",
                "layout": {"rings": "field", "times": "field"}}, "speed_mps": null}"#,
        )
        .unwrap();
        assert_eq!(
            layout_text(record.current.layout.as_ref()),
            r#"{"rings":"field","times":"field"}"#
        );
        assert!(record.quality.is_none());
        let described =
            serde_json::json!({"rings": "field", "description": "ring field `ring` (32 rings)"});
        assert_eq!(
            layout_text(Some(&described)),
            "ring field `ring` (32 rings)"
        );
    }
}
