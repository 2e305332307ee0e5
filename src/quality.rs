//! Per-pair quality figures: what a fleet engineer checks before trusting a
//! processed log (`docs/quality.md`). A pure function of the engine's result
//! and the current scan (no I/O), computed by the annotator for every pair and
//! written into the pair's `/looming/pairs` message (`quality`);
//! `looming quality` (`crate::quality_report`) sums them over a log.
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
use crate::messages::Scan;

/// Largest angle between a ground cell's normal and the LiDAR's z axis.
pub const GROUND_MAX_TILT_DEG: f64 = 15.0;
/// First pass: distance from the dominant ground height allowed at the
/// sensor, metres, ...
pub const GROUND_HEIGHT_TOLERANCE_M: f64 = 0.3;
/// ... growing by this much per metre of horizontal distance (a 3 degree
/// tilt or slope).
pub const GROUND_HEIGHT_TOLERANCE_PER_M: f64 = 0.05;
/// Second pass: distance from the plane fitted through the first pass.
pub const GROUND_PLANE_TOLERANCE_M: f64 = 0.15;
pub const GROUND_PLANE_TOLERANCE_PER_M: f64 = 0.02;
/// Fewest first-pass cells to fit a plane through.
const MIN_PLANE_CELLS: usize = 30;

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
    fn add_bits(&mut self, bits: u8) {
        self.no_previous += u64::from(bits & mask::NO_PREVIOUS != 0);
        self.edge += u64::from(bits & mask::EDGE != 0);
        self.grazing += u64::from(bits & mask::GRAZING != 0);
        self.no_ego += u64::from(bits & mask::NO_EGO != 0);
        self.occlusion += u64::from(bits & mask::OCCLUSION != 0);
    }

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
        self.named()
            .into_iter()
            .filter(|&(_, n)| n > 0)
            .fold(None, |best: Option<(&str, u64)>, (name, n)| match best {
                Some((_, m)) if m >= n => best,
                _ => Some((name, n)),
            })
    }
}

/// A histogram of absolute values on log-spaced bins (50 per decade from
/// 1e-4 to 100 1/s: bins 4.7 % wide), kept sparse, so that medians over a
/// whole log can be pooled in bounded memory.
#[derive(Debug, Clone, Default, PartialEq, Eq, Serialize, Deserialize)]
pub struct AbsHistogram {
    /// `[bin, count]`, bins ascending: bin 0 holds |x| < 1e-4, bin `k >= 1`
    /// holds `1e-4 * 10^((k-1)/50) <= |x| < 1e-4 * 10^(k/50)`, bin 301 holds
    /// everything from 100 up.
    pub counts: Vec<[u64; 2]>,
}

const HIST_LOWEST: f64 = 1e-4;
const HIST_BINS_PER_DECADE: f64 = 50.0;
const HIST_LAST_BIN: u64 = 301;

impl AbsHistogram {
    fn bin(value: f64) -> u64 {
        let magnitude = value.abs();
        if magnitude < HIST_LOWEST {
            0
        } else {
            (((magnitude / HIST_LOWEST).log10() * HIST_BINS_PER_DECADE) as u64 + 1)
                .min(HIST_LAST_BIN)
        }
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
    pub median_fused_per_s: Option<f64>,
    /// Median `D = L_lidar - L_ray_ego`, 1/s (`None` without ego velocity).
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
    pub height_m: Option<f64>,
    /// Slope of the plane fitted through the ground, seen in the LiDAR
    /// frame: about x (positive when the ground rises to the left) and about
    /// y (positive when it rises ahead), degrees. A level mount on a flat road
    /// reads 0.
    pub roll_deg: Option<f64>,
    pub pitch_deg: Option<f64>,
    /// Median |fused| over the trusted static ground cells, 1/s.
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
    pub trusted_fraction: Option<f64>,
    /// Occupied cells of the range image (a return in the current scan).
    pub cells: u64,
    /// Occupied cells with mask 0.
    pub trusted_cells: u64,
    pub trusted_cell_fraction: Option<f64>,
    /// Occupied cells per mask bit.
    pub masked_cells: MaskCounts,
    pub ground: GroundQuality,
    /// Trusted cells not flagged moving.
    pub static_cells: u64,
    /// Median |L_lidar - L_ray_ego| over the trusted static cells, 1/s
    /// (`None` without ego velocity).
    pub median_abs_d_static_per_s: Option<f64>,
    /// The same values, for pooling over a log (`None` without ego velocity).
    pub abs_d_static_histogram: Option<AbsHistogram>,
    /// Trusted cells flagged moving.
    pub moving_cells: u64,
    /// `moving_cells / trusted_cells`.
    pub moving_fraction: Option<f64>,
    /// Cells at a threat level (low or above).
    pub threat_cells: u64,
    /// A velocity source covered the pair.
    pub ego_velocity: bool,
    /// Range noise (1 sigma) the engine used per ring (beam, lowest first), m.
    pub range_noise_m_per_ring: Vec<f32>,
}

fn ratio(part: u64, whole: u64) -> Option<f64> {
    (whole > 0).then(|| part as f64 / whole as f64)
}

/// Median (mean of the two middle values for an even count); `None` when empty.
pub fn median(values: &mut [f64]) -> Option<f64> {
    let n = values.len();
    if n == 0 {
        return None;
    }
    let (_, &mut upper, _) = values.select_nth_unstable_by(n / 2, f64::total_cmp);
    if n % 2 == 1 {
        return Some(upper);
    }
    let lower = values[..n / 2]
        .iter()
        .copied()
        .max_by(f64::total_cmp)
        .expect("n >= 2");
    Some(0.5 * (lower + upper))
}

impl PairQuality {
    /// The figures of one pair: `looming` as the engine computed it for the
    /// pair whose current scan is `current`.
    pub fn measure(looming: &PairLooming, current: &Scan) -> Self {
        let cells = looming.mask.len();
        let points = current.points_m.len() as u64;
        let trusted_points = (0..current.points_m.len())
            .filter(|&i| {
                looming
                    .image
                    .surface_cell(i)
                    .is_some_and(|cell| looming.mask.get(cell) == Some(&0))
            })
            .count() as u64;
        let mut occupied = 0u64;
        let mut trusted = 0u64;
        let mut masked = MaskCounts::default();
        let mut moving = 0u64;
        let mut threat = 0u64;
        let mut abs_d_static = Vec::new();
        let ego = looming.availability.ego_velocity;
        for cell in 0..cells {
            let bits = looming.mask[cell];
            if bits & mask::EMPTY != 0 {
                continue;
            }
            occupied += 1;
            masked.add_bits(bits);
            if looming.threat.get(cell).is_some_and(|t| *t != ThreatLevel::None) {
                threat += 1;
            }
            if bits != 0 {
                continue;
            }
            trusted += 1;
            if looming.moving[cell] {
                moving += 1;
            } else if ego {
                let d = f64::from(looming.disagreement[cell]);
                if d.is_finite() {
                    abs_d_static.push(d.abs());
                }
            }
        }
        let static_cells = trusted - moving;
        let abs_d_static_histogram = ego.then(|| AbsHistogram::of(abs_d_static.iter().copied()));
        let median_abs_d_static_per_s = if ego {
            median(&mut abs_d_static)
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
            ground: measure_ground(looming, current),
            static_cells,
            median_abs_d_static_per_s,
            abs_d_static_histogram,
            moving_cells: moving,
            moving_fraction: ratio(moving, trusted),
            threat_cells: threat,
            ego_velocity: ego,
            range_noise_m_per_ring: looming.range_noise_m_per_row.clone(),
        }
    }
}

/// Position of each occupied cell's return (`None` for empty cells).
fn cell_point(looming: &PairLooming, scan: &Scan, cell: usize) -> Option<[f64; 3]> {
    if looming.mask[cell] & mask::EMPTY != 0 {
        return None;
    }
    let index = *looming.image.point.get(cell)?;
    let p = scan.points_m.get(index as usize)?;
    Some([f64::from(p[0]), f64::from(p[1]), f64::from(p[2])])
}

/// Cells that may be ground: an upward normal within `GROUND_MAX_TILT_DEG` of
/// z, and the return below the sensor.
fn ground_candidates(looming: &PairLooming, scan: &Scan) -> Vec<(usize, [f64; 3])> {
    let min_cos = GROUND_MAX_TILT_DEG.to_radians().cos();
    (0..looming.mask.len())
        .filter_map(|cell| {
            let p = cell_point(looming, scan, cell)?;
            let n = looming.normal.get(cell)?;
            let norm = (n[0] * n[0] + n[1] * n[1] + n[2] * n[2]).sqrt();
            let upward = norm > 0.5 && f64::from(n[2] / norm) >= min_cos;
            (upward && p[2] < 0.0).then_some((cell, p))
        })
        .collect()
}

/// Least-squares plane `z = a x + b y + c` through the points.
fn fit_plane(points: &[[f64; 3]]) -> Option<[f64; 3]> {
    let mut m = nalgebra::Matrix3::<f64>::zeros();
    let mut v = nalgebra::Vector3::<f64>::zeros();
    for p in points {
        let row = nalgebra::Vector3::new(p[0], p[1], 1.0);
        m += row * row.transpose();
        v += row * p[2];
    }
    let solution = m.try_inverse()? * v;
    solution
        .iter()
        .all(|x| x.is_finite())
        .then(|| [solution[0], solution[1], solution[2]])
}

fn measure_ground(looming: &PairLooming, scan: &Scan) -> GroundQuality {
    let candidates = ground_candidates(looming, scan);
    let mut heights: Vec<f64> = candidates.iter().map(|(_, p)| p[2]).collect();
    let Some(height) = median(&mut heights) else {
        return GroundQuality::default();
    };
    let horizontal = |p: &[f64; 3]| p[0].hypot(p[1]);
    let near_height: Vec<&(usize, [f64; 3])> = candidates
        .iter()
        .filter(|(_, p)| {
            (p[2] - height).abs()
                <= GROUND_HEIGHT_TOLERANCE_M + GROUND_HEIGHT_TOLERANCE_PER_M * horizontal(p)
        })
        .collect();
    let plane = (near_height.len() >= MIN_PLANE_CELLS)
        .then(|| fit_plane(&near_height.iter().map(|(_, p)| *p).collect::<Vec<_>>()))
        .flatten();
    let ground: Vec<(usize, [f64; 3])> = match plane {
        Some([a, b, c]) => candidates
            .iter()
            .filter(|(_, p)| {
                (p[2] - (a * p[0] + b * p[1] + c)).abs()
                    <= GROUND_PLANE_TOLERANCE_M + GROUND_PLANE_TOLERANCE_PER_M * horizontal(p)
            })
            .copied()
            .collect(),
        None => near_height.into_iter().copied().collect(),
    };
    let ego = looming.availability.ego_velocity;
    let mut abs_fused = Vec::new();
    let mut sides: [(Vec<f64>, Vec<f64>, u64); 2] = Default::default();
    let mut trusted_static = 0u64;
    let mut moving = 0u64;
    for &(cell, p) in &ground {
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
                abs_fused.push(fused.abs());
            }
        }
        let side = match p[1] {
            y if y > 0.0 => &mut sides[0],
            y if y < 0.0 => &mut sides[1],
            _ => continue,
        };
        side.2 += 1;
        if fused.is_finite() {
            side.0.push(fused);
        }
        if ego && d.is_finite() {
            side.1.push(d);
        }
    }
    let [left, right] = sides.map(|(mut fused, mut d, cells)| GroundSide {
        cells,
        median_fused_per_s: median(&mut fused),
        median_d_per_s: median(&mut d),
    });
    GroundQuality {
        cells: ground.len() as u64,
        trusted_static_cells: trusted_static,
        moving_cells: moving,
        height_m: Some(height),
        roll_deg: plane.map(|[_, b, _]| b.atan().to_degrees()),
        pitch_deg: plane.map(|[a, _, _]| a.atan().to_degrees()),
        abs_fused_histogram: AbsHistogram::of(abs_fused.iter().copied()),
        median_abs_fused_per_s: median(&mut abs_fused),
        left,
        right,
    }
}
