//! A cell's differences taken to its current return's instant where the
//! ego accelerates ([`to_instant`]), with the velocity lookups it needs.

use crate::model::motion::Interpolation;
use crate::model::{PairMotion, StampNs};

use super::Raw;

/// A difference over `dt` measures the looming of the mean ego velocity over
/// the interval; reported at the current return's time it is off by
/// `a dt / (2 h)` when the ego accelerates (braking at 5 m/s^2 at 6.7 m reads
/// 0.037 1/s high). On a static surface the translation looming scales with
/// the speed, so `(k - 1) L_ray_ego`, with `k` the current speed over the mean
/// speed, is that error: removed from both differences, which leaves `D`
/// unchanged and corrects moving objects for the ego's share of the relative
/// acceleration.
/// (`col`: the cell's column, for [`InstantVelocities::current`].)
/// (Pinned inline, as [`InstantVelocities::current`]: the per-cell loop's.)
#[inline]
pub(super) fn to_instant(
    raw: Raw,
    motion: &PairMotion,
    (source_time_ns, time_ns): (StampNs, StampNs),
    (col, velocities): (usize, &mut InstantVelocities),
) -> Raw {
    if !raw.l_ray_ego.is_finite() {
        return raw;
    }
    let (Some(before), Some((now, now_speed_mps))) = (
        velocities.source(motion, source_time_ns),
        velocities.current(motion, col, time_ns),
    ) else {
        return raw;
    };
    let mean_speed_mps = (0.5 * (before + now)).norm();
    if mean_speed_mps < MIN_SPEED_FOR_INSTANT_MPS {
        return raw;
    }
    let correction = ((now_speed_mps / mean_speed_mps - 1.0) * f64::from(raw.l_ray_ego)) as f32;
    Raw {
        l_lidar: raw.l_lidar + correction,
        l_ray_ego: raw.l_ray_ego + correction,
        ..raw
    }
}

/// The ego velocities [`to_instant`] looks up, per worker: the series'
/// positions of the last source and current times asked (neighbouring
/// cells' times are close: [`PairMotion::velocity_near`]), and each
/// column's last current time with the velocity and speed then, as a
/// sensor that fires a column's lasers at once gives its cells one time:
/// one lookup per column instead of one per cell.
pub(super) struct InstantVelocities {
    source_hint: usize,
    /// The stretch of the velocity series the last source time asked fell
    /// in: the next ones (a render's interpolated times, close together)
    /// mostly fall in it too.
    source_stretch: Option<Interpolation>,
    hint: usize,
    /// By column: the time, ns, and the velocity then, if known.
    by_column: Vec<Option<(StampNs, Option<VelocityAndSpeed>)>>,
}

impl InstantVelocities {
    pub(super) fn new(cols: usize) -> Self {
        Self {
            source_hint: 0,
            source_stretch: None,
            hint: 0,
            by_column: vec![None; cols],
        }
    }

    /// The velocity at `time_ns`, a source time: inside the last stretch
    /// by its interpolation, else by [`PairMotion::velocity_near`] (the same
    /// value either way).
    #[inline]
    fn source(&mut self, motion: &PairMotion, time_ns: StampNs) -> Option<nalgebra::Vector3<f64>> {
        if let Some(velocity) = self.source_stretch.and_then(|s| s.at(time_ns)) {
            return Some(velocity);
        }
        let series = motion.velocity.as_ref()?;
        let velocity = series.at_near(time_ns, &mut self.source_hint);
        self.source_stretch = series.interpolation_around(self.source_hint);
        velocity
    }

    /// The velocity and speed at `time_ns`, a current return's time in
    /// column `col`. (Pinned inline: out of line, as the crate's codegen
    /// units once put it, the per-cell stage ran 2.7 % more instructions.)
    #[inline]
    fn current(
        &mut self,
        motion: &PairMotion,
        col: usize,
        time_ns: StampNs,
    ) -> Option<VelocityAndSpeed> {
        match self.by_column[col] {
            Some((known_ns, known)) if known_ns == time_ns => known,
            _ => {
                let now = motion
                    .velocity_near(time_ns, &mut self.hint)
                    .map(|v| (v, v.norm()));
                self.by_column[col] = Some((time_ns, now));
                now
            }
        }
    }
}

/// An ego velocity, m/s, and its norm, the speed, m/s.
type VelocityAndSpeed = (nalgebra::Vector3<f64>, f64);

/// Below this mean speed the ratio of speeds means nothing.
const MIN_SPEED_FOR_INSTANT_MPS: f64 = 0.1;
