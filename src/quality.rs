//! Per-pair quality figures: what a fleet engineer checks before trusting a
//! processed log (`docs/quality.md`). A pure function of the engine's result
//! and the current scan (no I/O), computed by the annotator for every pair and
//! written into the pair's `/looming/pairs` message (`quality`);
//! `looming quality` (`crate::commands::quality`) sums them over a log.
//!
//! The static ground is found without ego information, so it can judge the
//! ego motion: cells whose fitted normal is within 15 degrees of the LiDAR's
//! z axis, whose return lies below the sensor, and near the scan's dominant
//! ground height (the median height of such cells), then near the plane fitted
//! through those (a tilted mount or a sloped road keeps its ground). On a
//! static ground looming along rays is 0 whatever the ego motion, so its
//! fused value measures the error of the whole chain (extrinsic, velocity,
//! times); left and right halves are kept apart because a rotation error
//! about the x axis reads with opposite signs on them.

use serde::{Deserialize, Serialize};

use crate::engine::{PairLooming, ThreatLevel, mask};
use crate::model::Scan;
use crate::objects::ground::GroundFit;
// An `f64` as an integer that orders as `f64::total_cmp` does, and back
// (the objects' selections use the same keys).
use crate::objects::order::{key as total_order_key, value as from_total_order_key};

/// Why occupied cells are masked: cells per `engine::mask` bit (a cell may
/// carry several bits; empty cells are not counted).
#[derive(Debug, Clone, Copy, Default, PartialEq, Eq, Serialize, Deserialize)]
pub struct MaskCounts {
    pub no_previous: u64,
    pub edge: u64,
    pub grazing: u64,
    pub no_ego: u64,
    pub occlusion: u64,
}

impl MaskCounts {
    pub fn add(&mut self, other: &MaskCounts) {
        self.no_previous += other.no_previous;
        self.edge += other.edge;
        self.grazing += other.grazing;
        self.no_ego += other.no_ego;
        self.occlusion += other.occlusion;
    }

    /// (name, cells) per bit, in bit order.
    pub fn named(&self) -> [(&'static str, u64); 5] {
        [
            ("no_previous", self.no_previous),
            ("edge", self.edge),
            ("grazing", self.grazing),
            ("no_ego", self.no_ego),
            ("occlusion", self.occlusion),
        ]
    }

    /// The bit masking the most cells (`None` when nothing is masked).
    pub fn dominant(&self) -> Option<(&'static str, u64)> {
        self.named().into_iter().filter(|&(_, n)| n > 0).fold(
            None,
            |best: Option<(&str, u64)>, (name, n)| match best {
                Some((_, m)) if m >= n => best,
                _ => Some((name, n)),
            },
        )
    }
}

/// A histogram of absolute values on log-spaced bins (50 per decade from
/// 1e-4 to 100 1/s: bins 4.7 % wide), kept sparse, so that medians over a
/// whole log can be pooled in bounded memory.
#[derive(Debug, Clone, Default, PartialEq, Eq, Serialize, Deserialize)]
#[serde(from = "HistogramWire", into = "HistogramWire")]
pub struct AbsHistogram {
    /// `[bin, count]`, bins ascending: bin 0 holds |x| < 1e-4, bin `k >= 1`
    /// holds `1e-4 * 10^((k-1)/50) <= |x| < 1e-4 * 10^(k/50)`, bin 301 holds
    /// everything from 100 up.
    pub counts: Vec<[u64; 2]>,
}

/// How a histogram is written: two arrays of integers, `bins` and their
/// `counts`. Foxglove's and Lichtblick's JSON-schema reader takes no array of
/// arrays (one such property hides the whole topic); logs written before
/// that hold `counts` as `[bin, count]` pairs, which still read.
#[derive(Serialize, Deserialize)]
struct HistogramWire {
    #[serde(default)]
    bins: Vec<u64>,
    counts: WireCounts,
}

#[derive(Serialize, Deserialize)]
#[serde(untagged)]
enum WireCounts {
    Counts(Vec<u64>),
    Pairs(Vec<[u64; 2]>),
}

impl From<AbsHistogram> for HistogramWire {
    fn from(histogram: AbsHistogram) -> Self {
        let (bins, counts) = histogram.counts.iter().map(|&[bin, n]| (bin, n)).unzip();
        Self {
            bins,
            counts: WireCounts::Counts(counts),
        }
    }
}

impl From<HistogramWire> for AbsHistogram {
    fn from(wire: HistogramWire) -> Self {
        let counts = match wire.counts {
            WireCounts::Pairs(pairs) => pairs,
            // A bin without a count (arrays of unequal length) is dropped.
            WireCounts::Counts(counts) => wire
                .bins
                .iter()
                .zip(counts)
                .map(|(&bin, n)| [bin, n])
                .collect(),
        };
        Self { counts }
    }
}

const HIST_LOWEST: f64 = 1e-4;
const HIST_BINS_PER_DECADE: f64 = 50.0;
const HIST_LAST_BIN: u64 = 301;

/// The lower edge of each bin from 1 on: `HIST_LOWEST 10^(k / 50)` for
/// bin `k + 1`. Built once: binning by these edges costs a binary search
/// where a `log10` per value was a percent of a 64 x 2048 run.
static HIST_EDGES: std::sync::LazyLock<Vec<f64>> = std::sync::LazyLock::new(|| {
    (0..HIST_LAST_BIN)
        .map(|k| HIST_LOWEST * 10f64.powf(k as f64 / HIST_BINS_PER_DECADE))
        .collect()
});

/// A value's bits shifted right by this keep the exponent and the top five
/// bits of the mantissa: slots at most 1 + 1/32 apart in ratio, finer than
/// the bins' `10^(1/50)` = 1.047, so a slot holds at most one edge.
const SLOT_SHIFT: u32 = 47;

/// Per slot of [`SLOT_SHIFT`] from that of the lowest edge to that of the
/// highest, the bin of the slot's lowest value (the edges at or below it):
/// a value's bin is then that, plus one where the next edge lies at or below
/// it. One table look-up and one comparison where the binary search over
/// the edges took nine steps (a hundred thousand values per pair).
struct BinSlots {
    first_key: u64,
    bin_at_start: Vec<u16>,
}

static HIST_SLOTS: std::sync::LazyLock<BinSlots> = std::sync::LazyLock::new(|| {
    let key = |value: f64| value.to_bits() >> SLOT_SHIFT;
    let first_key = key(HIST_EDGES[0]);
    let last_key = key(HIST_EDGES[HIST_EDGES.len() - 1]);
    let bin_at_start = (first_key..=last_key)
        .map(|k| {
            let start = f64::from_bits(k << SLOT_SHIFT);
            HIST_EDGES.partition_point(|&edge| edge <= start) as u16
        })
        .collect();
    BinSlots {
        first_key,
        bin_at_start,
    }
});

impl AbsHistogram {
    /// `floor(50 log10(|value| / HIST_LOWEST)) + 1`, at most the last bin;
    /// 0 below `HIST_LOWEST`: the number of edges at or below `|value|`,
    /// found through [`BinSlots`].
    fn bin(value: f64) -> u64 {
        let magnitude = value.abs();
        let slots = &*HIST_SLOTS;
        let Some(slot) = (magnitude.to_bits() >> SLOT_SHIFT).checked_sub(slots.first_key) else {
            return 0;
        };
        let Some(&start) = slots.bin_at_start.get(slot as usize) else {
            return HIST_LAST_BIN;
        };
        let start = usize::from(start);
        let next_edge_below = HIST_EDGES.get(start).is_some_and(|&edge| edge <= magnitude);
        (start + usize::from(next_edge_below)) as u64
    }

    /// Geometric centre of a bin (0 for the lowest, the lower edge of the last).
    fn centre(bin: u64) -> f64 {
        match bin {
            0 => 0.0,
            HIST_LAST_BIN => HIST_LOWEST * 10f64.powf((HIST_LAST_BIN - 1) as f64 / 50.0),
            k => HIST_LOWEST * 10f64.powf((k as f64 - 0.5) / HIST_BINS_PER_DECADE),
        }
    }

    /// The histogram of `values` (non-finite values skipped).
    pub fn of(values: impl Iterator<Item = f64>) -> Self {
        let mut dense = vec![0u64; HIST_LAST_BIN as usize + 1];
        for value in values.filter(|v| v.is_finite()) {
            dense[Self::bin(value) as usize] += 1;
        }
        Self::from_dense(&dense)
    }

    fn from_dense(dense: &[u64]) -> Self {
        Self {
            counts: dense
                .iter()
                .enumerate()
                .filter(|&(_, &n)| n > 0)
                .map(|(bin, &n)| [bin as u64, n])
                .collect(),
        }
    }

    pub fn count(&self) -> u64 {
        self.counts.iter().map(|c| c[1]).sum()
    }

    /// The sum of both.
    pub fn merge(&mut self, other: &AbsHistogram) {
        let mut dense = vec![0u64; HIST_LAST_BIN as usize + 1];
        for [bin, n] in self.counts.iter().chain(&other.counts) {
            dense[(*bin).min(HIST_LAST_BIN) as usize] += n;
        }
        *self = Self::from_dense(&dense);
    }

    /// The value below which a fraction `q` of the samples lie (the centre of
    /// its bin: within 2.3 %); `None` when empty.
    pub fn quantile(&self, q: f64) -> Option<f64> {
        let total = self.count();
        if total == 0 {
            return None;
        }
        let wanted = ((q * total as f64).ceil() as u64).max(1);
        let mut seen = 0;
        for [bin, n] in &self.counts {
            seen += n;
            if seen >= wanted {
                return Some(Self::centre(*bin));
            }
        }
        self.counts.last().map(|c| Self::centre(c[0]))
    }
}

/// One half of the ground (left: y > 0, right: y < 0), trusted cells only,
/// those flagged moving included: the ground does not move, so a moving flag
/// on it is itself a symptom (a large ego-motion error flags the whole ground
/// moving, which would leave nothing to judge it by).
#[derive(Debug, Clone, Copy, Default, PartialEq, Serialize, Deserialize)]
pub struct GroundSide {
    pub cells: u64,
    /// Median fused looming, 1/s (0 on a static ground when all is right).
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub median_fused_per_s: Option<f64>,
    /// Median `D = L_lidar - L_ray_ego`, 1/s (`None` without ego velocity).
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub median_d_per_s: Option<f64>,
}

/// The ground of one scan, found without ego information.
#[derive(Debug, Clone, Default, PartialEq, Serialize, Deserialize)]
pub struct GroundQuality {
    /// Occupied cells classified as ground (any mask).
    pub cells: u64,
    /// Of those, trusted (mask 0) and not moving.
    pub trusted_static_cells: u64,
    /// Trusted ground cells flagged moving (0 when all is right).
    pub moving_cells: u64,
    /// Dominant ground height in the LiDAR frame (median z of the candidate
    /// cells), metres: minus the sensor's height above the ground.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub height_m: Option<f64>,
    /// Slope of the plane fitted through the ground, seen in the LiDAR
    /// frame: about x (positive when the ground rises to the left) and about
    /// y (positive when it rises ahead), degrees. A level mount on a flat road
    /// reads 0.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub roll_deg: Option<f64>,
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub pitch_deg: Option<f64>,
    /// Median |fused| over the trusted static ground cells, 1/s.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub median_abs_fused_per_s: Option<f64>,
    /// The same values, for pooling over a log.
    pub abs_fused_histogram: AbsHistogram,
    pub left: GroundSide,
    pub right: GroundSide,
}

/// The quality figures of one pair (`/looming/pairs` `quality`).
#[derive(Debug, Clone, Default, PartialEq, Serialize, Deserialize)]
pub struct PairQuality {
    /// Valid points of the current scan.
    pub points: u64,
    /// Points that are their cell's surface, in a cell with mask 0.
    pub trusted_points: u64,
    /// `trusted_points / points`: the headline figure.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub trusted_fraction: Option<f64>,
    /// Occupied cells of the range image (a return in the current scan).
    pub cells: u64,
    /// Occupied cells with mask 0.
    pub trusted_cells: u64,
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub trusted_cell_fraction: Option<f64>,
    /// Occupied cells per mask bit.
    pub masked_cells: MaskCounts,
    pub ground: GroundQuality,
    /// Trusted cells not flagged moving.
    pub static_cells: u64,
    /// Median |L_lidar - L_ray_ego| over the trusted static cells, 1/s
    /// (`None` without ego velocity).
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub median_abs_d_static_per_s: Option<f64>,
    /// The same values, for pooling over a log (`None` without ego velocity).
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub abs_d_static_histogram: Option<AbsHistogram>,
    /// Trusted cells flagged moving.
    pub moving_cells: u64,
    /// `moving_cells / trusted_cells`.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub moving_fraction: Option<f64>,
    /// Cells at a threat level (low or above).
    pub threat_cells: u64,
    /// A velocity source covered the pair.
    pub ego_velocity: bool,
    /// Range noise (1 sigma) the engine used per ring (beam, lowest first), m.
    pub range_noise_m_per_ring: Vec<f32>,
    /// The looming of the strongest approach in the ego path, 1/s: the
    /// event detector's `path_peak_looming` (set by the annotation stage;
    /// absent where too few cells qualify, and in logs written before it).
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub path_peak_looming_per_s: Option<f64>,
    /// Range offset of each ring's laser the engine estimated and took out,
    /// m (all zero when it found none; empty in logs written before it).
    #[serde(default)]
    pub range_offset_m_per_ring: Vec<f32>,
    /// Objects found in the pair (`/looming/objects`), and those with a
    /// looming (0 in logs written before objects).
    #[serde(default)]
    pub objects: u64,
    #[serde(default)]
    pub objects_with_looming: u64,
}

impl PairQuality {
    /// Count the pair's objects.
    pub fn count_objects(&mut self, objects: &crate::objects::PairObjects) {
        self.objects = objects.objects.len() as u64;
        self.objects_with_looming = objects
            .objects
            .iter()
            .filter(|o| o.looming_per_s.is_some())
            .count() as u64;
    }
}

fn ratio(part: u64, whole: u64) -> Option<f64> {
    (whole > 0).then(|| part as f64 / whole as f64)
}

/// Median (mean of the two middle values for an even count); `None` when empty.
pub fn median(values: &mut [f64]) -> Option<f64> {
    let mut keys: Vec<i64> = values.iter().map(|&v| total_order_key(v)).collect();
    median_of_keys(&mut keys)
}

/// [`median`] of the values whose [`total_order_key`]s `keys` holds (the
/// pair's tens of thousands of cells: an integer comparison in the
/// selection instead of `f64::total_cmp`'s, the same order). Reorders
/// `keys`.
fn median_of_keys(keys: &mut [i64]) -> Option<f64> {
    let n = keys.len();
    if n == 0 {
        return None;
    }
    let (_, &mut upper, _) = keys.select_nth_unstable(n / 2);
    let upper = from_total_order_key(upper);
    if n % 2 == 1 {
        return Some(upper);
    }
    let lower = keys[..n / 2].iter().copied().max().expect("n >= 2");
    Some(0.5 * (from_total_order_key(lower) + upper))
}

impl PairQuality {
    /// The figures of one pair: `looming` as the engine computed it for the
    /// pair whose current scan is `current`.
    pub fn measure(looming: &PairLooming, current: &Scan) -> Self {
        Self::measure_on_ground(looming, current, GroundFit::find(looming, current).as_ref())
    }

    /// [`Self::measure`] with the pair's ground already found (the objects
    /// stage finds it too).
    pub fn measure_on_ground(
        looming: &PairLooming,
        current: &Scan,
        ground: Option<&GroundFit>,
    ) -> Self {
        let points = current.points_m.len() as u64;
        let trusted_points = trusted_points(looming, current.points_m.len());
        let CellCounts {
            occupied,
            trusted,
            masked,
            threat,
        } = CellCounts::of(looming);
        let mut moving = 0u64;
        let ego = looming.availability.ego_velocity;
        // At most one value a cell: allocated once (grown by doubling, its
        // copies were a tenth of this stage).
        let mut abs_d_static = Vec::with_capacity(if ego { looming.mask.len() } else { 0 });
        for (cell, (&bits, &moving_cell)) in looming.mask.iter().zip(&looming.moving).enumerate() {
            if bits != 0 {
                continue;
            }
            if moving_cell {
                moving += 1;
            } else if ego {
                let d = f64::from(looming.disagreement[cell]);
                if d.is_finite() {
                    abs_d_static.push(total_order_key(d.abs()));
                }
            }
        }
        let static_cells = trusted - moving;
        let abs_d_static_histogram =
            ego.then(|| AbsHistogram::of(abs_d_static.iter().map(|&k| from_total_order_key(k))));
        let median_abs_d_static_per_s = if ego {
            median_of_keys(&mut abs_d_static)
        } else {
            None
        };
        Self {
            points,
            trusted_points,
            trusted_fraction: ratio(trusted_points, points),
            cells: occupied,
            trusted_cells: trusted,
            trusted_cell_fraction: ratio(trusted, occupied),
            masked_cells: masked,
            ground: measure_ground(looming, ground),
            static_cells,
            median_abs_d_static_per_s,
            abs_d_static_histogram,
            moving_cells: moving,
            moving_fraction: ratio(moving, trusted),
            threat_cells: threat,
            ego_velocity: ego,
            range_noise_m_per_ring: looming.range_noise_m_per_row.clone(),
            path_peak_looming_per_s: None,
            range_offset_m_per_ring: looming.range_bias_m_per_row.clone(),
            objects: 0,
            objects_with_looming: 0,
        }
    }
}

/// How many of the scan's first `points` points lie on a trusted cell (mask
/// 0): `NO_POINT`, beyond any cell, is none.
fn trusted_points(looming: &PairLooming, points: usize) -> u64 {
    let mask = &looming.mask;
    let surface = looming.image.point_surface.iter().take(points);
    surface
        .filter(|&&cell| mask.get(cell as usize) == Some(&0))
        .count() as u64
}

/// The pair's cell counts: occupied, trusted (mask 0), per mask bit, at a
/// threat. Each a count over the cells' bytes in a loop of its own, with
/// no branch per cell: with one loop of them all, branching on each cell's
/// bits and keeping the mask counters on the stack, `measure_on_ground` was
/// 2.3 % of the synthetic drive's one-thread samples (1.2 % without).
struct CellCounts {
    occupied: u64,
    trusted: u64,
    masked: MaskCounts,
    threat: u64,
}

impl CellCounts {
    fn of(looming: &PairLooming) -> Self {
        let mask = &looming.mask;
        let occupied_with = |bit: u8| {
            let with = |&&bits: &&u8| bits & mask::EMPTY == 0 && bits & bit != 0;
            mask.iter().filter(with).count() as u64
        };
        let threats = mask.iter().zip(&looming.threat);
        Self {
            occupied: mask.iter().filter(|&&bits| bits & mask::EMPTY == 0).count() as u64,
            trusted: mask.iter().filter(|&&bits| bits == 0).count() as u64,
            masked: MaskCounts {
                no_previous: occupied_with(mask::NO_PREVIOUS),
                edge: occupied_with(mask::EDGE),
                grazing: occupied_with(mask::GRAZING),
                no_ego: occupied_with(mask::NO_EGO),
                occlusion: occupied_with(mask::OCCLUSION),
            },
            threat: threats
                .filter(|&(&bits, &level)| bits & mask::EMPTY == 0 && level != ThreatLevel::None)
                .count() as u64,
        }
    }
}

fn measure_ground(looming: &PairLooming, fit: Option<&GroundFit>) -> GroundQuality {
    let Some(GroundFit {
        height_m: height,
        plane,
        cells: ground,
    }) = fit
    else {
        return GroundQuality::default();
    };
    let (height, plane) = (*height, *plane);
    let ego = looming.availability.ego_velocity;
    // At most one value a ground cell each: allocated once.
    let mut abs_fused = Vec::with_capacity(ground.len());
    // (The values as their total-order keys, for the medians.)
    let mut sides: [(Vec<i64>, Vec<i64>, u64); 2] = std::array::from_fn(|_| {
        let d = if ego { ground.len() } else { 0 };
        (Vec::with_capacity(ground.len()), Vec::with_capacity(d), 0)
    });
    let mut trusted_static = 0u64;
    let mut moving = 0u64;
    for &(cell, p) in ground {
        if looming.mask[cell] != 0 {
            continue;
        }
        let fused = f64::from(looming.fused[cell]);
        let d = f64::from(looming.disagreement[cell]);
        if looming.moving[cell] {
            moving += 1;
        } else {
            trusted_static += 1;
            if fused.is_finite() {
                abs_fused.push(total_order_key(fused.abs()));
            }
        }
        let side = match p[1] {
            y if y > 0.0 => &mut sides[0],
            y if y < 0.0 => &mut sides[1],
            _ => continue,
        };
        side.2 += 1;
        if fused.is_finite() {
            side.0.push(total_order_key(fused));
        }
        if ego && d.is_finite() {
            side.1.push(total_order_key(d));
        }
    }
    let [left, right] = sides.map(|(mut fused, mut d, cells)| GroundSide {
        cells,
        median_fused_per_s: median_of_keys(&mut fused),
        median_d_per_s: median_of_keys(&mut d),
    });
    GroundQuality {
        cells: ground.len() as u64,
        trusted_static_cells: trusted_static,
        moving_cells: moving,
        height_m: Some(height),
        roll_deg: plane.map(|[_, b, _]| b.atan().to_degrees()),
        pitch_deg: plane.map(|[a, _, _]| a.atan().to_degrees()),
        abs_fused_histogram: AbsHistogram::of(abs_fused.iter().map(|&k| from_total_order_key(k))),
        median_abs_fused_per_s: median_of_keys(&mut abs_fused),
        left,
        right,
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    /// Binning by the edge table gives the logarithm's bin (but within
    /// rounding of an edge).
    #[test]
    fn histogram_bins_by_edges_are_the_logarithms() {
        let by_log = |value: f64| -> u64 {
            let magnitude = value.abs();
            if magnitude < HIST_LOWEST {
                0
            } else {
                (((magnitude / HIST_LOWEST).log10() * HIST_BINS_PER_DECADE) as u64 + 1)
                    .min(HIST_LAST_BIN)
            }
        };
        let mut state = 3u64;
        for _ in 0..200_000 {
            // Magnitudes from 1e-6 to 1e3, either sign.
            let exponent = next_unit(&mut state) * 9.0 - 6.0;
            let value = 10f64.powf(exponent) * if state & 1 == 0 { 1.0 } else { -1.0 };
            let fractional = (exponent + 4.0) * HIST_BINS_PER_DECADE;
            if (fractional - fractional.round()).abs() < 1e-9 {
                continue;
            }
            assert_eq!(AbsHistogram::bin(value), by_log(value), "{value}");
        }
        assert_eq!(AbsHistogram::bin(0.0), 0);
        assert_eq!(AbsHistogram::bin(1e9), HIST_LAST_BIN);
    }

    /// The next of a linear congruential sequence (Knuth's MMIX constants)
    /// as a value in [0, 1): the histogram tests' reproducible magnitudes.
    fn next_unit(state: &mut u64) -> f64 {
        *state = state
            .wrapping_mul(6_364_136_223_846_793_005)
            .wrapping_add(1_442_695_040_888_963_407);
        (*state >> 11) as f64 / (1u64 << 53) as f64
    }

    /// The slot table gives the binary search's bin exactly: at every edge,
    /// one step either side of it, at every slot's bounds, and far beyond.
    #[test]
    fn bins_by_slot_are_the_binary_searchs() {
        let by_search = |value: f64| {
            let magnitude = value.abs();
            HIST_EDGES.partition_point(|&edge| edge <= magnitude) as u64
        };
        let mut values = vec![0.0, -0.0, f64::MIN_POSITIVE, 1e-300, 1e300, f64::MAX];
        for &edge in HIST_EDGES.iter() {
            values.extend([edge, edge.next_up(), edge.next_down(), -edge]);
        }
        let first = HIST_SLOTS.first_key;
        for k in first.saturating_sub(3)..first + HIST_SLOTS.bin_at_start.len() as u64 + 3 {
            let start = f64::from_bits(k << SLOT_SHIFT);
            values.extend([start, start.next_down(), start.next_up()]);
        }
        let mut state = 11u64;
        for _ in 0..100_000 {
            let exponent = next_unit(&mut state) * 12.0 - 7.0;
            values.push(10f64.powf(exponent));
        }
        for value in values {
            assert_eq!(AbsHistogram::bin(value), by_search(value), "{value:e}");
        }
    }
    use crate::engine::beams::BeamTable;
    use crate::engine::{Availability, ImageGeometry, NO_POINT, RangeImage};

    /// One cell per point (cell i holds point i), on 2 rows.
    struct Cells {
        points: Vec<[f32; 3]>,
        normals: Vec<[f32; 3]>,
        masks: Vec<u8>,
        fused: Vec<f32>,
        d: Vec<f32>,
        moving: Vec<bool>,
    }

    impl Cells {
        fn new() -> Self {
            Self {
                points: Vec::new(),
                normals: Vec::new(),
                masks: Vec::new(),
                fused: Vec::new(),
                d: Vec::new(),
                moving: Vec::new(),
            }
        }

        fn push(&mut self, p: [f32; 3], n: [f32; 3], mask: u8, fused: f32, d: f32) -> usize {
            self.points.push(p);
            self.normals.push(n);
            self.masks.push(mask);
            self.fused.push(fused);
            self.d.push(d);
            self.moving.push(false);
            self.points.len() - 1
        }

        fn build(mut self, ego: bool) -> (PairLooming, Scan) {
            self.pad_to_full_rows();
            let image = self.range_image();
            let points = std::mem::take(&mut self.points);
            let looming = self.into_looming(image, points.len(), ego);
            (looming, scan_of(points))
        }

        fn pad_to_full_rows(&mut self) {
            if self.points.len() % 2 == 1 {
                // Pad to two full rows with an empty cell (no point).
                self.normals.push([0.0; 3]);
                self.masks.push(mask::EMPTY);
                self.fused.push(f32::NAN);
                self.d.push(f32::NAN);
                self.moving.push(false);
            }
        }

        fn range_image(&self) -> RangeImage {
            let cells = self.masks.len();
            let n_points = self.points.len();
            let point: Vec<u32> = (0..cells)
                .map(|c| if c < n_points { c as u32 } else { NO_POINT })
                .collect();
            let range_m = (0..cells)
                .map(|c| {
                    self.points.get(c).map_or(f32::NAN, |p| {
                        (p[0] * p[0] + p[1] * p[1] + p[2] * p[2]).sqrt()
                    })
                })
                .collect();
            // An empty-masked cell's point is no cell's surface.
            let point_surface = (0..n_points)
                .map(|i| {
                    if self.masks[i] & mask::EMPTY != 0 {
                        NO_POINT
                    } else {
                        i as u32
                    }
                })
                .collect();
            RangeImage {
                range_m,
                point,
                point_cell: (0..n_points as u32).collect(),
                point_surface,
            }
        }

        /// The engine's result over these cells (what the cells do not set
        /// is NaN, not disagreeing, or at no threat).
        fn into_looming(self, image: RangeImage, n_points: usize, ego: bool) -> PairLooming {
            let cells = self.masks.len();
            let geometry = ImageGeometry {
                rows: 2,
                cols: cells / 2,
                beams: BeamTable::uniform(2, -0.3, 0.0),
                ring_to_row: None,
                parallax_rad_m: None,
            };
            let nan = vec![f32::NAN; cells];
            PairLooming {
                geometry,
                availability: Availability {
                    ego_velocity: ego,
                    rotation_compensated: true,
                },
                image,
                l_lidar: nan.clone(),
                l_ray_ego: nan.clone(),
                disagreement: self.d,
                sigma_per_s: nan.clone(),
                fused_sigma_per_s: nan.clone(),
                ray_ego_sigma_per_s: nan.clone(),
                confidence: nan.clone(),
                mask: self.masks,
                disagrees: vec![false; cells],
                moving: self.moving,
                fused: self.fused,
                threat: vec![ThreatLevel::None; cells],
                incidence_cos: vec![1.0; cells],
                normal: self.normals,
                range_noise_m_per_row: vec![0.02, 0.03],
                range_bias_m_per_row: vec![0.0, 0.0],
                dt_s: vec![0.1; cells],
                l_ego: vec![f32::NAN; n_points],
                point_threat: vec![ThreatLevel::None; n_points],
                spheres: None,
                velocity_mps: None,
                angular_velocity_radps: None,
                ego_estimate: None,
                stage_times: Default::default(),
            }
        }
    }

    /// The current scan of `points`, in the LiDAR frame.
    fn scan_of(points: Vec<[f32; 3]>) -> Scan {
        let n_points = points.len();
        Scan {
            stamp_ns: 0,
            frame_id: "lidar".into(),
            sensor_pose: nalgebra::Isometry3::identity(),
            points_m: points,
            intensity: None,
            ring: None,
            time_offset_s: None,
            source_index: (0..n_points as u32).collect(),
            input_point_count: n_points as u32,
            skipped_invalid_points: 0,
            organized: None,
            layout: Default::default(),
            sensor_ids: None,
        }
    }

    const UP: [f32; 3] = [0.0, 0.0, 1.0];
    const FACING: [f32; 3] = [-1.0, 0.0, 0.0];

    #[test]
    fn counts_trusted_points_cells_and_masks() {
        let mut cells = Cells::new();
        for k in 0..6 {
            cells.push([10.0, k as f32, 0.5], FACING, 0, 0.1, 0.0);
        }
        cells.push([10.0, 7.0, 0.5], FACING, mask::EDGE, 0.1, 0.0);
        cells.push(
            [10.0, 8.0, 0.5],
            FACING,
            mask::EDGE | mask::OCCLUSION,
            0.1,
            0.0,
        );
        cells.push([10.0, 9.0, 0.5], FACING, mask::GRAZING, 0.1, 0.0);
        // A point whose cell is empty of surface (hidden return): not trusted,
        // its cell not occupied.
        cells.push([12.0, 9.0, 0.5], FACING, mask::EMPTY, f32::NAN, f32::NAN);
        let (looming, scan) = cells.build(true);
        let q = PairQuality::measure(&looming, &scan);
        assert_eq!(q.points, 10);
        assert_eq!(q.trusted_points, 6);
        assert_eq!(q.trusted_fraction, Some(0.6));
        assert_eq!(q.cells, 9);
        assert_eq!(q.trusted_cells, 6);
        assert_eq!(
            q.masked_cells,
            MaskCounts {
                edge: 2,
                occlusion: 1,
                grazing: 1,
                ..MaskCounts::default()
            }
        );
        assert_eq!(q.masked_cells.dominant(), Some(("edge", 2)));
        assert_eq!(q.static_cells, 6);
        assert_eq!(q.median_abs_d_static_per_s, Some(0.0));
        assert_eq!(q.moving_fraction, Some(0.0));
        assert_eq!(q.range_noise_m_per_ring, vec![0.02, 0.03]);
        assert_eq!(q.ground.cells, 0);
        assert_eq!(q.ground.median_abs_fused_per_s, None);
    }

    /// An empty cell is not occupied, whatever other bits it carries: its
    /// bits count in no mask.
    #[test]
    fn an_empty_cells_other_bits_count_in_no_mask() {
        let mut cells = Cells::new();
        cells.push([10.0, 0.0, 0.5], FACING, 0, 0.1, 0.0);
        cells.push([10.0, 1.0, 0.5], FACING, mask::NO_PREVIOUS, 0.1, 0.0);
        let empty = mask::EMPTY | mask::NO_PREVIOUS | mask::EDGE;
        cells.push([12.0, 2.0, 0.5], FACING, empty, f32::NAN, f32::NAN);
        let (looming, scan) = cells.build(true);
        let q = PairQuality::measure(&looming, &scan);
        assert_eq!((q.cells, q.trusted_cells), (2, 1));
        let no_previous_only = MaskCounts {
            no_previous: 1,
            ..MaskCounts::default()
        };
        assert_eq!(q.masked_cells, no_previous_only);
    }

    #[test]
    fn without_ego_velocity_there_is_no_d_figure() {
        let mut cells = Cells::new();
        cells.push([10.0, 0.0, 0.5], FACING, 0, 0.1, f32::NAN);
        cells.push([10.0, 1.0, 0.5], FACING, 0, 0.1, f32::NAN);
        let (looming, scan) = cells.build(false);
        let q = PairQuality::measure(&looming, &scan);
        assert!(!q.ego_velocity);
        assert_eq!(q.median_abs_d_static_per_s, None);
        assert_eq!(q.abs_d_static_histogram, None);
    }

    /// A road 1.7 m below the sensor, rising to the left at `slope` (dz/dy),
    /// 20 cells a side, reading `left` and `right`; plus what is not ground.
    fn road(slope: f32, left: f32, right: f32) -> Cells {
        let mut cells = Cells::new();
        for k in 0..20 {
            let x = 4.0 + k as f32;
            for y in [2.5f32, -2.5] {
                let z = -1.7 + slope * y;
                let fused = if y > 0.0 { left } else { right };
                cells.push([x, y, z], UP, 0, fused, fused);
            }
        }
        // Not ground: a car roof (up, 1.5 m above the road), a wall (facing
        // the sensor), an awning above the sensor (normal down... facing the
        // sensor: down), a steep bank (normal 30 deg off z).
        cells.push([8.0, 0.5, -0.2], UP, 0, 0.9, 0.9);
        cells.push([15.0, 0.0, -1.0], FACING, 0, 0.9, 0.9);
        cells.push([5.0, 0.0, 2.0], [0.0, 0.0, -1.0], 0, 0.9, 0.9);
        cells.push([6.0, 3.0, -1.6], [0.0, -0.5, 0.866], 0, 0.9, 0.9);
        cells
    }

    #[test]
    fn classifies_the_ground_and_reads_its_halves() {
        let (looming, scan) = road(0.0, 0.004, -0.002).build(true);
        let q = PairQuality::measure(&looming, &scan);
        let g = &q.ground;
        assert_eq!(g.cells, 40);
        assert_eq!(g.trusted_static_cells, 40);
        assert!((g.height_m.unwrap() + 1.7).abs() < 1e-6);
        assert!(g.roll_deg.unwrap().abs() < 1e-3);
        assert!(g.pitch_deg.unwrap().abs() < 1e-3);
        assert_eq!(g.left.cells, 20);
        assert_eq!(g.right.cells, 20);
        assert!((g.left.median_fused_per_s.unwrap() - 0.004).abs() < 1e-6);
        assert!((g.right.median_fused_per_s.unwrap() + 0.002).abs() < 1e-6);
        assert!((g.left.median_d_per_s.unwrap() - 0.004).abs() < 1e-6);
        // |fused| over both halves: 20 x 0.002 and 20 x 0.004.
        assert!((g.median_abs_fused_per_s.unwrap() - 0.003).abs() < 1e-6);
        assert_eq!(g.abs_fused_histogram.count(), 40);
    }

    #[test]
    fn a_tilted_ground_is_still_ground_and_its_slope_is_measured() {
        // 3 degrees of roll: the far side 0.13 m off the median height.
        let slope = 3f32.to_radians().tan();
        let (looming, scan) = road(slope, 0.03, -0.03).build(true);
        let q = PairQuality::measure(&looming, &scan);
        let g = &q.ground;
        assert_eq!(g.cells, 40);
        assert!((g.roll_deg.unwrap() - 3.0).abs() < 0.01, "{:?}", g.roll_deg);
        assert!(g.pitch_deg.unwrap().abs() < 0.01);
        assert!(g.left.median_fused_per_s.unwrap() > 0.02);
        assert!(g.right.median_fused_per_s.unwrap() < -0.02);
    }

    #[test]
    fn moving_ground_cells_count_in_the_halves_but_not_in_the_static_median() {
        let mut cells = road(0.0, 0.5, 0.5);
        for m in cells.moving.iter_mut().take(40) {
            *m = true;
        }
        let (looming, scan) = cells.build(true);
        let q = PairQuality::measure(&looming, &scan);
        assert_eq!(q.ground.moving_cells, 40);
        assert_eq!(q.ground.trusted_static_cells, 0);
        assert_eq!(q.ground.median_abs_fused_per_s, None);
        assert_eq!(q.ground.left.median_fused_per_s, Some(0.5));
        assert_eq!(q.moving_cells, 40);
    }

    #[test]
    fn histogram_quantiles_pool_exactly_to_a_bin() {
        let mut a = AbsHistogram::of([0.001, 0.002, 0.003].into_iter());
        let b = AbsHistogram::of([0.004, 0.005, -0.006, f64::NAN].into_iter());
        a.merge(&b);
        assert_eq!(a.count(), 6);
        let median = a.quantile(0.5).unwrap();
        assert!((median / 0.003 - 1.0).abs() < 0.025, "{median}");
        assert_eq!(AbsHistogram::default().quantile(0.5), None);
        assert_eq!(AbsHistogram::of([0.0].into_iter()).quantile(0.5), Some(0.0));
    }

    #[test]
    fn median_by_keys_is_the_total_orders() {
        let mut state = 5u64;
        for count in 0..60 {
            let values: Vec<f64> = (0..count)
                .map(|k| match k % 7 {
                    0 => -0.0,
                    1 => 0.0,
                    2 => -(next_unit(&mut state) * 3.0),
                    _ => next_unit(&mut state) * 5.0 - 1.0,
                })
                .collect();
            let mut sorted = values.clone();
            sorted.sort_by(f64::total_cmp);
            let expected = match count {
                0 => None,
                n if n % 2 == 1 => Some(sorted[n / 2]),
                n => Some(0.5 * (sorted[n / 2 - 1] + sorted[n / 2])),
            };
            let got = median(&mut values.clone());
            assert_eq!(
                got.map(f64::to_bits),
                expected.map(f64::to_bits),
                "{values:?}"
            );
        }
    }

    #[test]
    fn median_of_even_and_odd_counts() {
        assert_eq!(median(&mut []), None);
        assert_eq!(median(&mut [3.0, 1.0, 2.0]), Some(2.0));
        assert_eq!(median(&mut [4.0, 1.0, 3.0, 2.0]), Some(2.5));
    }
}
