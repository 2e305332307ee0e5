//! Summing a log: [`Builder`] takes the pairs one by one (a [`ScanLine`]
//! each, and their quality figures added up) and finishes into the
//! [`QualityReport`], diagnoses included.

use std::collections::BTreeMap;

use super::diagnose::diagnose;
use super::read::{PairMessage, layout_text};
use super::report::{
    GroundSides, QualityReport, QualityTotals, RangeNoise, RangeOffsets, ScanLine,
};
use super::{GROUND_SIDE_THRESHOLD_PER_S, MIN_SIDE_CELLS};
use crate::quality::{AbsHistogram, GroundQuality, GroundSide, MaskCounts, PairQuality, median};

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

/// The running sums of a log, one pair at a time.
#[derive(Default)]
pub(super) struct Builder {
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
    /// `/looming/events` messages read.
    pub(super) fn count_events(&mut self, events: u64) {
        self.events += events;
    }

    /// One `/looming/pairs` message: its scan line, and its figures summed.
    pub(super) fn add(&mut self, pair: PairMessage) {
        self.pairs += 1;
        let layout = layout_text(pair.current.layout.as_ref());
        *self.layouts.entry(layout.clone()).or_default() += 1;
        self.scans.push(scan_line(&pair, layout));
        if let Some(q) = pair.quality {
            self.add_quality(&q);
        }
    }

    fn add_quality(&mut self, q: &PairQuality) {
        self.with_quality += 1;
        self.with_ego += u64::from(q.ego_velocity);
        self.points += q.points;
        self.trusted_points += q.trusted_points;
        self.cells += q.cells;
        self.trusted_cells += q.trusted_cells;
        self.masked.add(&q.masked_cells);
        push_per_ring(&mut self.noise_per_ring, &q.range_noise_m_per_ring);
        push_per_ring(&mut self.offset_per_ring, &q.range_offset_m_per_ring);
        self.add_ground(&q.ground);
        if let Some(h) = &q.abs_d_static_histogram {
            self.abs_d_static.merge(h);
        }
        self.moving += q.moving_cells;
        self.threat += q.threat_cells;
    }

    fn add_ground(&mut self, g: &GroundQuality) {
        self.ground_cells += g.cells;
        self.ground_trusted_static += g.trusted_static_cells;
        self.ground_moving += g.moving_cells;
        self.ground_abs_fused.merge(&g.abs_fused_histogram);
        let judged =
            |side: &GroundSide, value: Option<f64>| value.filter(|_| side.cells >= MIN_SIDE_CELLS);
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
    }

    /// The report: the scan lines, the totals and what they diagnose.
    pub(super) fn finish(mut self, input: String) -> QualityReport {
        let scans = std::mem::take(&mut self.scans);
        let totals = self.into_totals();
        let diagnoses = diagnose(&totals);
        QualityReport {
            tool: "looming".into(),
            version: env!("CARGO_PKG_VERSION").into(),
            input,
            scans,
            totals,
            diagnoses,
            sensor: None,
            sensors: Vec::new(),
        }
    }

    fn into_totals(mut self) -> QualityTotals {
        let ratio = |a: u64, b: u64| (b > 0).then(|| a as f64 / b as f64);
        let range_noise = range_noise(&mut self.noise_per_ring);
        let range_offsets = range_offsets(&mut self.offset_per_ring);
        let masked_cell_fractions = self
            .masked
            .named()
            .into_iter()
            .filter_map(|(name, n)| ratio(n, self.cells).map(|f| (name.to_string(), f)))
            .collect();
        QualityTotals {
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
        }
    }
}

/// One line of the per-scan table.
fn scan_line(pair: &PairMessage, layout: String) -> ScanLine {
    let q = pair.quality.as_ref();
    ScanLine {
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
        path_peak_looming_per_s: q.and_then(|q| q.path_peak_looming_per_s),
        dominant_mask: q.and_then(|q| q.masked_cells.dominant().map(|(n, _)| n.to_string())),
    }
}

/// Append each ring's finite value of one pair to that ring's list (rings
/// added as the pair has more).
fn push_per_ring(per_ring: &mut Vec<Vec<f64>>, values_m: &[f32]) {
    if per_ring.len() < values_m.len() {
        per_ring.resize(values_m.len(), Vec::new());
    }
    for (ring, value) in values_m.iter().enumerate() {
        if value.is_finite() {
            per_ring[ring].push(f64::from(*value));
        }
    }
}

/// Per ring, the median over pairs of the range noise; and its spread over
/// the rings with one.
fn range_noise(noise_per_ring: &mut [Vec<f64>]) -> RangeNoise {
    let per_ring_m: Vec<f64> = noise_per_ring
        .iter_mut()
        .map(|v| median(v).unwrap_or(f64::NAN))
        .collect();
    let finite: Vec<f64> = per_ring_m
        .iter()
        .copied()
        .filter(|v| v.is_finite())
        .collect();
    RangeNoise {
        rings: per_ring_m.len(),
        min_m: finite.iter().copied().min_by(f64::total_cmp),
        median_m: median(&mut finite.clone()),
        max_m: finite.iter().copied().max_by(f64::total_cmp),
        per_ring_m: per_ring_m.into_iter().filter(|v| v.is_finite()).collect(),
    }
}

/// Per ring, the median over pairs of the range offset; their RMS and
/// largest magnitude.
fn range_offsets(offset_per_ring: &mut [Vec<f64>]) -> RangeOffsets {
    let offsets_m: Vec<f64> = offset_per_ring
        .iter_mut()
        .filter_map(|v| median(v))
        .collect();
    RangeOffsets {
        rings: offsets_m.len(),
        rms_m: (!offsets_m.is_empty()).then(|| {
            (offsets_m.iter().map(|b| b * b).sum::<f64>() / offsets_m.len() as f64).sqrt()
        }),
        max_abs_m: offsets_m.iter().map(|b| b.abs()).max_by(f64::total_cmp),
        per_ring_m: offsets_m,
    }
}
