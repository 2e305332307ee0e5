//! What moving the source's returns to the target takes (the moves
//! themselves, column by column, in `moved_column.rs`): the relative
//! transforms of one column's returns, cached ([`TransformCache`]), and
//! the angles turned by a short series ([`turn_rad`]).

use nalgebra::{Isometry3, Matrix3, Point3, Vector3};
use rayon::prelude::*;

use super::recurring::ExactTimes;
use crate::engine::trajectory::Trajectory;
use crate::model::StampNs;

/// Per target column, the inverse of the pose at its firing time
/// (`lidar_from_reference`; the identity where the column has no time):
/// the target end of every relative transform into that column, computed
/// once per render instead of once per (return time, column) pair.
pub(super) fn arrival_poses(
    column_time_ns: &[StampNs],
    trajectory: &Trajectory,
) -> Vec<Isometry3<f64>> {
    column_time_ns
        .par_iter()
        .map(|&time_ns| {
            if time_ns == StampNs::MIN {
                Isometry3::identity()
            } else {
                trajectory.pose(time_ns).inverse()
            }
        })
        .collect()
}

/// A transform from a time into a target column's frame, keyed by both.
type ToColumn = ((StampNs, usize), Moving);

/// A relative transform as a matrix and a translation: applied to every
/// return of a column (nine products where the quaternion takes eighteen).
#[derive(Clone, Copy)]
pub(super) struct Moving {
    rotation: Matrix3<f64>,
    translation: Vector3<f64>,
}

impl Moving {
    pub(super) fn new(isometry: Isometry3<f64>) -> Self {
        Self {
            rotation: *isometry.rotation.to_rotation_matrix().matrix(),
            translation: isometry.translation.vector,
        }
    }

    #[inline]
    pub(super) fn apply(&self, point: &Point3<f64>) -> Point3<f64> {
        Point3::from(self.rotation * point.coords + self.translation)
    }

    /// A direction (a normal) turned by the rotation.
    #[inline]
    pub(super) fn rotate(&self, direction: &Vector3<f64>) -> Vector3<f64> {
        self.rotation * direction
    }
}

/// Relative transforms of one column's returns, `pose(to)^-1 * pose(from)`
/// as [`Trajectory::relative`] computes them (so the same values), each
/// composed from a departure pose (the last one kept: a column's returns
/// share their time) and an arrival pose: a target column's from the
/// render's table, any other time's computed (the last one kept). The last
/// transforms composed are kept too. (Keying whole transforms alone missed
/// on three returns in four under translation, whose rows land in
/// different target columns.)
///
/// Where a column's returns do not share their time (KITTI's, timed by
/// their own azimuth), every return's departure differs from the last, and
/// composing poses for each was a fifth of the renders: there a transform
/// is taken along the straight line between two composed ones
/// ([`Sloped`]), within [`LINEAR_REACH_NS`] of the first. `LINES` says
/// which (`render` chooses per source column): without lines the cache is
/// compiled without them, as the warp of returns sharing their time slowed
/// by a tenth with the lines' code beside it.
pub(super) struct TransformCache<'a, const LINES: bool> {
    trajectory: &'a Trajectory,
    /// Per target column, from [`arrival_poses`].
    arrivals: &'a [Isometry3<f64>],
    departure: Option<(StampNs, Isometry3<f64>)>,
    to_time: Option<((StampNs, StampNs), Moving)>,
    to_columns: [Option<ToColumn>; 4],
    next: usize,
    /// The last transforms' lines: to a time a fixed offset later (keyed by
    /// the offset), and into the last few target columns (keyed by the
    /// column: a column's rows land in neighbouring target columns).
    to_time_line: Option<(StampNs, Sloped)>,
    to_column_lines: [Option<(usize, Sloped)>; 4],
    next_line: usize,
    /// A column of a few recurring times' exact transforms, where it is
    /// one (`recurring.rs`): then neither lines nor the caches above.
    pub(super) exact: Option<ExactTimes>,
}

impl<'a, const LINES: bool> TransformCache<'a, LINES> {
    pub(super) fn new(trajectory: &'a Trajectory, arrivals: &'a [Isometry3<f64>]) -> Self {
        Self {
            trajectory,
            arrivals,
            departure: None,
            to_time: None,
            to_columns: [None; 4],
            next: 0,
            to_time_line: None,
            to_column_lines: [None; 4],
            next_line: 0,
            exact: None,
        }
    }

    /// Points measured at `from_ns` into the frame at `to_ns`.
    pub(super) fn until(&mut self, from_ns: StampNs, to_ns: StampNs) -> Moving {
        if LINES && let Some(exact) = &mut self.exact {
            return exact.until(self.trajectory, from_ns, to_ns - from_ns);
        }
        if let Some((key, transform)) = self.to_time
            && key == (from_ns, to_ns)
        {
            return transform;
        }
        let offset_ns = to_ns - from_ns;
        let composed = |cache: &mut Self, from_ns: StampNs| {
            Moving::new(
                cache.trajectory.pose(from_ns + offset_ns).inverse() * cache.departure(from_ns),
            )
        };
        let transform = match self.to_time_line {
            Some((key, line)) if LINES && key == offset_ns && line.reaches(from_ns) => {
                line.at(from_ns)
            }
            // Without lines; the first transform; or a column whose
            // returns share their time.
            _ if !LINES || self.to_time.is_none() || self.line_pays(from_ns) => {
                composed(self, from_ns)
            }
            _ => {
                let start = composed(self, from_ns);
                let end = composed(self, from_ns + LINEAR_REACH_NS);
                self.to_time_line = Some((offset_ns, Sloped::new(from_ns, start, end)));
                start
            }
        };
        self.to_time = Some(((from_ns, to_ns), transform));
        transform
    }

    /// Points measured at `from_ns` into the frame target column `col`
    /// fired in.
    pub(super) fn until_column(&mut self, from_ns: StampNs, col: usize) -> Moving {
        if LINES && let Some(exact) = &mut self.exact {
            return exact.until_column(self.trajectory, (from_ns, col), &self.arrivals[col]);
        }
        let key = (from_ns, col);
        if let Some((_, transform)) = self.to_columns.iter().flatten().find(|(k, _)| *k == key) {
            return *transform;
        }
        let line = self
            .to_column_lines
            .iter()
            .flatten()
            .find(|(line_col, line)| LINES && *line_col == col && line.reaches(from_ns));
        let transform = match line {
            Some((_, line)) => line.at(from_ns),
            None if !LINES || self.line_pays(from_ns) => {
                Moving::new(self.arrivals[col] * self.departure(from_ns))
            }
            None => {
                let start = Moving::new(self.arrivals[col] * self.departure(from_ns));
                let end = Moving::new(
                    self.arrivals[col] * self.trajectory.pose(from_ns + LINEAR_REACH_NS),
                );
                self.to_column_lines[self.next_line] =
                    Some((col, Sloped::new(from_ns, start, end)));
                self.next_line = (self.next_line + 1) % self.to_column_lines.len();
                start
            }
        };
        self.to_columns[self.next] = Some((key, transform));
        self.next = (self.next + 1) % self.to_columns.len();
        transform
    }

    /// Whether `from_ns` is the departure kept, so that composing costs
    /// little and the exact transform is taken (returns sharing their time).
    fn line_pays(&self, from_ns: StampNs) -> bool {
        self.departure
            .is_some_and(|(time_ns, _)| time_ns == from_ns)
    }

    fn departure(&mut self, from_ns: StampNs) -> Isometry3<f64> {
        match self.departure {
            Some((time_ns, pose)) if time_ns == from_ns => pose,
            _ => {
                let pose = self.trajectory.pose(from_ns);
                self.departure = Some((from_ns, pose));
                pose
            }
        }
    }
}

/// How far from the first of its two transforms a [`Sloped`] line is
/// followed, ns: two of a 2000-column sweep's columns. The line departs
/// from the transforms where the trajectory bends: its 1 ms steps change
/// the turn rate by the angular acceleration times a step, which over the
/// reach is about 1e-8 rad at 0.5 rad/s^2 (0.5 um at 50 m), and the velocity
/// by 5 mm/s at 5 m/s^2 (0.5 um); the turn itself adds its square's half,
/// 5e-9 rad at 1 rad/s. (The unit test's drive: 1.2e-8 rad, 0.1 um.)
const LINEAR_REACH_NS: StampNs = 100_000;

/// A relative transform as a straight line in its departure time: the
/// rotation's matrix and the translation at `from_ns`, and their change
/// per ns, from two transforms [`LINEAR_REACH_NS`] apart.
#[derive(Clone, Copy)]
struct Sloped {
    from_ns: StampNs,
    start: Moving,
    rotation_per_ns: Matrix3<f64>,
    translation_per_ns: Vector3<f64>,
}

impl Sloped {
    fn new(from_ns: StampNs, start: Moving, end: Moving) -> Self {
        let per_ns = 1.0 / LINEAR_REACH_NS as f64;
        Self {
            from_ns,
            start,
            rotation_per_ns: (end.rotation - start.rotation) * per_ns,
            translation_per_ns: (end.translation - start.translation) * per_ns,
        }
    }

    #[inline]
    fn reaches(&self, from_ns: StampNs) -> bool {
        (from_ns - self.from_ns).abs() <= LINEAR_REACH_NS
    }

    #[inline]
    fn at(&self, from_ns: StampNs) -> Moving {
        let dt_ns = (from_ns - self.from_ns) as f64;
        Moving {
            rotation: self.start.rotation + self.rotation_per_ns * dt_ns,
            translation: self.start.translation + self.translation_per_ns * dt_ns,
        }
    }
}

/// [`turn_rad`] for a turn of a few milliradians (a column's time
/// difference): its series' first four terms, whose remainder, below
/// `u^9 / 9` with `u` at most 1/64, is 1e-17 rad at most.
#[cfg(test)]
fn slight_turn_rad(a: (f64, f64), b: (f64, f64)) -> f64 {
    let (cross, dot) = cross_dot(a, b);
    if slight(cross, dot) {
        slight_series_rad(cross / dot)
    } else {
        turn_rad(a, b)
    }
}

/// Whether [`slight_series_rad`] takes the turn of `(cross, dot)`.
#[inline]
pub(super) fn slight(cross: f64, dot: f64) -> bool {
    dot > 0.0 && cross.abs() <= dot * (1.0 / 64.0)
}

/// `atan(u)` by the series' first four terms, for `|u| <= 1/64`.
#[inline]
pub(super) fn slight_series_rad(u: f64) -> f64 {
    let v = u * u;
    u * ((1.0 + v * ATAN_SERIES[1]) + v * v * (ATAN_SERIES[2] + v * ATAN_SERIES[3]))
}

/// The cross and dot products of plane vectors `a` and `b`.
#[inline]
pub(super) fn cross_dot((ax, ay): (f64, f64), (bx, by): (f64, f64)) -> (f64, f64) {
    (ax * by - ay * bx, ax * bx + ay * by)
}

/// The angle from plane vector `a` to `b`, radians: `atan2(a x b, a . b)`,
/// by its Taylor series where the turn is small (the common case: a
/// return moves a few degrees between scans), which is cheaper than
/// `atan2` and as exact for the image (the series' remainder is below
/// 4e-15 rad, a millionth of a millionth of a column); beyond its reach
/// (near returns of the ego render) the engine's `atan2`, within 1e-12 rad
/// of libm's and a third of its cost.
#[inline]
pub(super) fn turn_rad(a: (f64, f64), b: (f64, f64)) -> f64 {
    let (cross, dot) = cross_dot(a, b);
    if small(cross, dot) {
        series_rad(cross / dot)
    } else {
        crate::engine::atan::atan2(cross, dot)
    }
}

/// Whether [`series_rad`] takes the turn of `(cross, dot)`.
#[inline]
pub(super) fn small(cross: f64, dot: f64) -> bool {
    dot > 0.0 && cross.abs() <= SMALL_TURN_TAN * dot
}

/// `atan(u)` by its series, for `|u| <=` [`SMALL_TURN_TAN`]: `u (1 - v/3 +
/// v^2/5 - ...)`, in two interleaved halves (Estrin's scheme) to shorten
/// the chain of dependent steps.
#[inline]
pub(super) fn series_rad(u: f64) -> f64 {
    let v = u * u;
    let v2 = v * v;
    let even = ATAN_SERIES
        .iter()
        .step_by(2)
        .rev()
        .fold(0.0, |sum, &c| c + v2 * sum);
    let odd = ATAN_SERIES
        .iter()
        .skip(1)
        .step_by(2)
        .rev()
        .fold(0.0, |sum, &c| c + v2 * sum);
    u * (even + v * odd)
}

/// Largest `tan` of a turn taken by the series (9.5 degrees): its ninth
/// term, `(1/6)^17 / 17`, is below 4e-15 rad. (At 1/16, 3.6 degrees, the
/// nearer returns of the ego render went through `atan2`: a tenth of the
/// renders' time.)
const SMALL_TURN_TAN: f64 = 1.0 / 6.0;

/// The series' coefficients, `(-1)^k / (2k + 1)`.
const ATAN_SERIES: [f64; 8] = [
    1.0,
    -1.0 / 3.0,
    1.0 / 5.0,
    -1.0 / 7.0,
    1.0 / 9.0,
    -1.0 / 11.0,
    1.0 / 13.0,
    -1.0 / 15.0,
];

#[cfg(test)]
mod tests {
    use super::*;
    use nalgebra::Vector3;

    /// A turning, accelerating drive sampled at 100 Hz around a 10 Hz scan
    /// pair (velocity and yaw rate change from sample to sample): its
    /// trajectory, the current sweep's column times (every 1.5625 ms, one
    /// without a time) and the previous scan's time.
    fn turning_drive() -> (Trajectory, Vec<StampNs>, StampNs) {
        let previous_ns: StampNs = 1_700_000_001_200_000_000;
        let current_ns = previous_ns + 100_000_000;
        let series = |value_at: &dyn Fn(f64) -> Vector3<f64>| {
            let samples = (0..50)
                .map(|i| {
                    let t_s = f64::from(i) * 0.01;
                    (
                        previous_ns - 200_000_000 + i64::from(i) * 10_000_000,
                        value_at(t_s),
                    )
                })
                .collect();
            crate::model::TimeSeries::new(samples, 0.2)
        };
        let motion = crate::model::PairMotion::in_lidar_frame(
            Some(series(&|t| Vector3::new(8.0 + 2.0 * t, 0.5 * t, 0.02))),
            Some(series(&|t| Vector3::new(0.01, -0.02, 0.3 + 0.5 * t))),
        );
        let (start_ns, end_ns) = (previous_ns - 1_000_000, current_ns + 101_000_000);
        let trajectory = Trajectory::integrate(
            &motion,
            crate::engine::trajectory::MotionModel::Full,
            true,
            start_ns,
            end_ns,
        )
        .unwrap();
        let mut column_time_ns: Vec<StampNs> =
            (0..64).map(|c| current_ns + c * 1_562_500).collect();
        column_time_ns[7] = StampNs::MIN;
        (trajectory, column_time_ns, previous_ns)
    }

    /// Whether `a` holds `b`'s matrix and translation to the bit.
    fn same(a: Moving, b: Isometry3<f64>) -> bool {
        let b = Moving::new(b);
        a.translation
            .iter()
            .zip(b.translation.iter())
            .chain(a.rotation.iter().zip(b.rotation.iter()))
            .all(|(x, y)| x.to_bits() == y.to_bits())
    }

    #[test]
    fn cached_transforms_are_the_trajectorys_relative_ones_bit_for_bit() {
        let (trajectory, column_time_ns, previous_ns) = turning_drive();
        let arrivals = arrival_poses(&column_time_ns, &trajectory);
        let mut cache = TransformCache::<true>::new(&trajectory, &arrivals);
        // Departures repeating and changing, arrivals in columns and at
        // times, the column cache wrapping round.
        for k in 0..400i64 {
            let from_ns = previous_ns + (k / 3) * 700_000;
            let to_ns = from_ns + 100_000_000 + (k % 5) * 333_333;
            assert!(same(
                cache.until(from_ns, to_ns),
                trajectory.relative(from_ns, to_ns)
            ));
            let col = ((k * 7) % 64) as usize;
            if column_time_ns[col] != StampNs::MIN {
                let expected = trajectory.relative(from_ns, column_time_ns[col]);
                assert!(
                    same(cache.until_column(from_ns, col), expected),
                    "k {k} col {col}"
                );
            }
        }
    }

    #[test]
    fn a_few_recurring_times_get_the_trajectorys_relative_transforms_bit_for_bit() {
        let (trajectory, column_time_ns, previous_ns) = turning_drive();
        let arrivals = arrival_poses(&column_time_ns, &trajectory);
        let mut cache = TransformCache::<true>::new(&trajectory, &arrivals);
        cache.exact = Some(ExactTimes::default());
        // A Pandar64's column: six times 0.66 ms apart, cycling row by
        // row, landing in neighbouring target columns (more of them than
        // the column cache keeps).
        let times = [1_662_000, 2_326_000, 2_991_000, 0, 663_000, 1_328_000];
        let offset_ns = 100_000_000;
        for k in 0..64usize {
            let from_ns = previous_ns + times[k % 6];
            assert!(same(
                cache.until(from_ns, from_ns + offset_ns),
                trajectory.relative(from_ns, from_ns + offset_ns)
            ));
            let col = 20 + k % 5;
            let expected = trajectory.relative(from_ns, column_time_ns[col]);
            assert!(same(cache.until_column(from_ns, col), expected), "k {k}");
        }
    }

    #[test]
    fn a_columns_returns_at_their_own_times_follow_the_line_within_a_micrometre() {
        let (trajectory, column_time_ns, previous_ns) = turning_drive();
        let arrivals = arrival_poses(&column_time_ns, &trajectory);
        // Returns of one column each at its own time (KITTI's): along the
        // line between two composed transforms, off the exact ones by far
        // less than a micrometre or a microradian.
        let mut cache = TransformCache::<true>::new(&trajectory, &arrivals);
        let offset_ns = 100_000_000;
        let mut worst = (0.0f64, 0.0f64);
        for k in 0..2_000i64 {
            let from_ns = previous_ns + k * 23_417;
            let col = (k / 40) as usize % 64;
            let mut pairs = vec![(
                cache.until(from_ns, from_ns + offset_ns),
                trajectory.relative(from_ns, from_ns + offset_ns),
            )];
            if column_time_ns[col] != StampNs::MIN {
                pairs.push((
                    cache.until_column(from_ns, col),
                    trajectory.relative(from_ns, column_time_ns[col]),
                ));
            }
            for (got, exact) in pairs {
                let exact = Moving::new(exact);
                worst.0 = worst.0.max((got.rotation - exact.rotation).amax());
                worst.1 = worst.1.max((got.translation - exact.translation).amax());
            }
        }
        assert!(worst.0 < 5e-8 && worst.1 < 1e-6, "worst {worst:?}");
        assert!(worst.0 > 0.0, "the line is followed");
    }

    #[test]
    fn a_turn_matches_atan2_within_rounding() {
        let mut worst = 0.0f64;
        for i in 0..20_000 {
            // Directions all round, turned by up to 20 degrees either way
            // (past the series' reach, so both paths are checked).
            let from = f64::from(i) * 0.000_314_159 * 1.000_7;
            let by = (f64::from(i % 401) - 200.0) * 0.001_75;
            let length = 0.5 + f64::from(i % 7);
            let a = (from.cos() * length, from.sin() * length);
            let b = ((from + by).cos() * 2.0, (from + by).sin() * 2.0);
            let exact = (a.0 * b.1 - a.1 * b.0).atan2(a.0 * b.0 + a.1 * b.1);
            let tolerance = if by.abs() < SMALL_TURN_TAN.atan() {
                4e-15
            } else {
                1e-12
            };
            worst = worst.max((turn_rad(a, b) - exact).abs() / tolerance);
        }
        // Within the series' 4e-15 rad where it applies, the engine's
        // atan2's 1e-12 beyond.
        assert!(worst <= 1.0, "worst difference {worst} of the tolerance");
    }

    #[test]
    fn a_slight_turn_matches_atan2_within_rounding() {
        let mut worst = 0.0f64;
        for i in 0..20_000 {
            // Turns of up to 0.03 rad either way, past the short series'
            // reach of 1/64.
            let from = f64::from(i) * 0.000_314_159 * 1.000_7;
            let by = (f64::from(i % 401) - 200.0) * 0.000_15;
            let length = 0.5 + f64::from(i % 7);
            let a = (from.cos() * length, from.sin() * length);
            let b = ((from + by).cos() * 3.0, (from + by).sin() * 3.0);
            let exact = (a.0 * b.1 - a.1 * b.0).atan2(a.0 * b.0 + a.1 * b.1);
            worst = worst.max((slight_turn_rad(a, b) - exact).abs());
        }
        assert!(worst <= 1e-16, "worst difference {worst:e} rad");
    }
}
