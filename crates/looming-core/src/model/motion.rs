//! The ego motion a scan pair carries, already in the LiDAR frame: time series
//! the engine queries at per-point times, and where the extrinsics came from.

use nalgebra::{Isometry3, Vector3};

use super::scan::StampNs;

/// Between two samples further apart than this (or than twice the hold, if
/// larger) the series does not interpolate: a source dropout is not bridged by
/// a straight line, only held from each side for the hold tolerance.
pub(crate) const MIN_INTERPOLATION_GAP_S: f64 = 1.0;

/// A vector-valued time series, sorted by stamp, with linear interpolation
/// between samples and a bounded hold beyond them.
#[derive(Debug, Clone, PartialEq)]
pub struct TimeSeries {
    samples: Vec<(StampNs, Vector3<f64>)>,
    hold_ns: i64,
    max_interpolation_gap_ns: i64,
}

impl TimeSeries {
    /// `hold_s`: how far before the first / after the last sample (or beyond
    /// an un-bridged dropout) the nearest sample is still used.
    pub fn new(mut samples: Vec<(StampNs, Vector3<f64>)>, hold_s: f64) -> Self {
        // Stable: samples with equal stamps keep arrival order (the later wins below).
        samples.sort_by_key(|(stamp_ns, _)| *stamp_ns);
        let hold_ns = seconds_to_ns(hold_s.max(0.0));
        let max_interpolation_gap_ns =
            seconds_to_ns(MIN_INTERPOLATION_GAP_S).max(hold_ns.saturating_mul(2));
        Self {
            samples,
            hold_ns,
            max_interpolation_gap_ns,
        }
    }

    pub fn samples(&self) -> &[(StampNs, Vector3<f64>)] {
        &self.samples
    }

    /// The samples of `self` and of `later` (a series of the same source
    /// over a later interval, whose tolerances it keeps), each stamp once.
    pub fn joined(&self, later: &TimeSeries) -> TimeSeries {
        let mut samples: Vec<(StampNs, Vector3<f64>)> = self
            .samples
            .iter()
            .filter(|(stamp_ns, _)| {
                later
                    .samples
                    .binary_search_by_key(stamp_ns, |s| s.0)
                    .is_err()
            })
            .chain(later.samples.iter())
            .copied()
            .collect();
        samples.sort_by_key(|(stamp_ns, _)| *stamp_ns);
        TimeSeries {
            samples,
            hold_ns: later.hold_ns,
            max_interpolation_gap_ns: later.max_interpolation_gap_ns,
        }
    }

    pub fn len(&self) -> usize {
        self.samples.len()
    }

    pub fn is_empty(&self) -> bool {
        self.samples.is_empty()
    }

    /// Value at `stamp_ns`; `None` when no sample is close enough.
    pub fn at(&self, stamp_ns: StampNs) -> Option<Vector3<f64>> {
        let after_index = self.samples.partition_point(|(t, _)| *t <= stamp_ns);
        self.around(stamp_ns, after_index)
    }

    /// [`at`](Self::at), finding the samples around `stamp_ns` by walking
    /// from `*hint` (the last call's, left there for the next) instead of by
    /// bisection: the same value, in a step or none where calls come in time
    /// order or close to it (every cell of a pair asks).
    pub fn at_near(&self, stamp_ns: StampNs, hint: &mut usize) -> Option<Vector3<f64>> {
        let samples = &self.samples;
        let mut after_index = (*hint).min(samples.len());
        while after_index < samples.len() && samples[after_index].0 <= stamp_ns {
            after_index += 1;
        }
        while after_index > 0 && samples[after_index - 1].0 > stamp_ns {
            after_index -= 1;
        }
        *hint = after_index;
        self.around(stamp_ns, after_index)
    }

    /// The stretch between the samples before and after `after_index` (as
    /// [`at_near`](Self::at_near) leaves its hint), when the series
    /// interpolates across it.
    pub fn interpolation_around(&self, after_index: usize) -> Option<Interpolation> {
        let (start_ns, start) = *self.samples.get(after_index.checked_sub(1)?)?;
        let (end_ns, end) = *self.samples.get(after_index)?;
        (end_ns > start_ns && end_ns - start_ns <= self.max_interpolation_gap_ns).then(|| {
            Interpolation {
                start_ns,
                end_ns,
                start,
                step: end - start,
            }
        })
    }

    /// The value at `stamp_ns` from the samples before and after
    /// `after_index` (the first sample stamped after it).
    fn around(&self, stamp_ns: StampNs, after_index: usize) -> Option<Vector3<f64>> {
        let before = after_index.checked_sub(1).map(|i| self.samples[i]);
        let after = self.samples.get(after_index).copied();
        match (before, after) {
            (Some((t_before, v_before)), _) if t_before == stamp_ns => Some(v_before),
            (Some((t_before, v_before)), Some((t_after, v_after)))
                if t_after - t_before <= self.max_interpolation_gap_ns =>
            {
                let fraction = (stamp_ns - t_before) as f64 / (t_after - t_before) as f64;
                Some(v_before + (v_after - v_before) * fraction)
            }
            _ => {
                let near_before = before.filter(|(t, _)| stamp_ns - t <= self.hold_ns);
                let near_after = after.filter(|(t, _)| t - stamp_ns <= self.hold_ns);
                match (near_before, near_after) {
                    (Some((t_b, v_b)), Some((t_a, v_a))) => {
                        Some(if stamp_ns - t_b <= t_a - stamp_ns {
                            v_b
                        } else {
                            v_a
                        })
                    }
                    (Some((_, v)), None) | (None, Some((_, v))) => Some(v),
                    (None, None) => None,
                }
            }
        }
    }
}

/// Two neighbouring samples a [`TimeSeries`] interpolates between: its
/// value strictly between their stamps without a search, by the same
/// expression ([`Interpolation::at`]), for callers asking many times inside
/// one stretch (every cell of a pair asks at its source time).
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Interpolation {
    start_ns: StampNs,
    end_ns: StampNs,
    start: Vector3<f64>,
    /// The end's value less the start's, as `around` takes it.
    step: Vector3<f64>,
}

impl Interpolation {
    /// The series' value at `stamp_ns`, strictly inside the stretch (the
    /// same bits as [`TimeSeries::at`]); `None` elsewhere.
    #[inline]
    pub fn at(&self, stamp_ns: StampNs) -> Option<Vector3<f64>> {
        (self.start_ns < stamp_ns && stamp_ns < self.end_ns).then(|| {
            let fraction = (stamp_ns - self.start_ns) as f64 / (self.end_ns - self.start_ns) as f64;
            self.start + self.step * fraction
        })
    }
}

pub(crate) fn seconds_to_ns(seconds: f64) -> i64 {
    (seconds * 1e9).round() as i64
}

/// Ego motion of the LiDAR at one instant, in the LiDAR frame.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct MotionSample {
    pub stamp_ns: StampNs,
    pub velocity_lidar_mps: Vector3<f64>,
    pub angular_velocity_lidar_radps: Vector3<f64>,
}

/// Which measurement the angular velocity came from.
#[derive(Debug, Clone, Copy, PartialEq, Eq, serde::Serialize)]
#[serde(rename_all = "snake_case")]
pub enum AngularSource {
    /// IMU gyro (preferred).
    Imu,
    /// Angular part of the velocity twist (no IMU samples for this pair).
    Twist,
    /// The turn between the sensor's placements in its clouds' frame (a
    /// world frame without `/tf`, the sensor placed from its rings at every
    /// scan: `pairing::origin_track`), which also give the velocity.
    Placements,
    Unavailable,
}

/// Ego motion covering a scan pair, already in the LiDAR frame.
#[derive(Debug, Clone, PartialEq)]
pub struct PairMotion {
    /// Translation velocity of the LiDAR origin, LiDAR frame, m/s. `None` when
    /// there is no velocity source or no sample near the pair.
    pub velocity: Option<TimeSeries>,
    /// Angular velocity of the LiDAR, LiDAR frame, rad/s.
    pub angular: Option<TimeSeries>,
    pub angular_source: AngularSource,
    /// LiDAR pose in the velocity samples' frame, when velocity samples were used.
    pub velocity_extrinsic: Option<ExtrinsicInfo>,
    /// LiDAR pose in the IMU frame, when IMU samples were used.
    pub imu_extrinsic: Option<ExtrinsicInfo>,
    /// No velocity source, or no velocity sample near this pair.
    pub velocity_unavailable: bool,
    /// No IMU source, or no IMU sample near this pair (angular from the twist if any).
    pub imu_unavailable: bool,
    /// Every existing source had delivered a sample stamped at or after the
    /// current scan's end when the pair was emitted. `false` means the pair was
    /// flushed early (next scan arrived, or end of log) and the tail is held.
    pub coverage_complete: bool,
}

impl PairMotion {
    /// The motion of a velocity series and an IMU's angular rates, both
    /// already in the LiDAR frame (no extrinsics to report), every source
    /// delivered past the pair: what a simulation or a test hands over.
    pub fn in_lidar_frame(velocity: Option<TimeSeries>, angular: Option<TimeSeries>) -> Self {
        Self {
            velocity,
            angular,
            angular_source: AngularSource::Imu,
            velocity_extrinsic: None,
            imu_extrinsic: None,
            velocity_unavailable: false,
            imu_unavailable: false,
            coverage_complete: true,
        }
    }

    /// The motion over this interval and the `later` one that follows it:
    /// each series' samples joined (a quantity either lacks is lacking), the
    /// later's extrinsics and source.
    pub fn joined(&self, later: &PairMotion) -> PairMotion {
        let join = |a: &Option<TimeSeries>, b: &Option<TimeSeries>| match (a, b) {
            (Some(a), Some(b)) => Some(a.joined(b)),
            _ => None,
        };
        PairMotion {
            velocity: join(&self.velocity, &later.velocity),
            angular: join(&self.angular, &later.angular),
            velocity_unavailable: self.velocity_unavailable || later.velocity_unavailable,
            imu_unavailable: self.imu_unavailable || later.imu_unavailable,
            coverage_complete: self.coverage_complete && later.coverage_complete,
            ..later.clone()
        }
    }

    pub fn velocity_at(&self, stamp_ns: StampNs) -> Option<Vector3<f64>> {
        self.velocity.as_ref()?.at(stamp_ns)
    }

    /// [`velocity_at`](Self::velocity_at) by [`TimeSeries::at_near`].
    pub fn velocity_near(&self, stamp_ns: StampNs, hint: &mut usize) -> Option<Vector3<f64>> {
        self.velocity.as_ref()?.at_near(stamp_ns, hint)
    }

    pub fn angular_velocity_at(&self, stamp_ns: StampNs) -> Option<Vector3<f64>> {
        self.angular.as_ref()?.at(stamp_ns)
    }

    /// Both quantities at once, when both are available.
    pub fn motion_at(&self, stamp_ns: StampNs) -> Option<MotionSample> {
        Some(MotionSample {
            stamp_ns,
            velocity_lidar_mps: self.velocity_at(stamp_ns)?,
            angular_velocity_lidar_radps: self.angular_velocity_at(stamp_ns)?,
        })
    }
}

/// Where an extrinsic (`motion_from_lidar`) came from.
#[derive(Debug, Clone, Copy, PartialEq, Eq, serde::Serialize)]
#[serde(rename_all = "snake_case")]
pub enum ExtrinsicSource {
    /// The `--extrinsic` command-line value.
    Cli,
    /// Looked up in the `/tf_static` tree.
    TfStatic,
    /// The motion samples are already in the LiDAR frame: identity, exactly.
    SameFrame,
    /// Frames differ and nothing connects them: identity, assumed (warned once).
    IdentityAssumed,
}

impl ExtrinsicSource {
    pub fn as_str(self) -> &'static str {
        match self {
            Self::Cli => "cli",
            Self::TfStatic => "tf_static",
            Self::SameFrame => "same_frame",
            Self::IdentityAssumed => "identity_assumed",
        }
    }
}

/// The pose of the LiDAR (the scan points' origin) in a motion-sample frame.
#[derive(Debug, Clone, PartialEq)]
pub struct ExtrinsicInfo {
    /// The scan's `frame_id`, normalised.
    pub lidar_frame: String,
    /// The velocity / IMU sample's `frame_id`, normalised.
    pub motion_frame: String,
    /// Maps LiDAR-point coordinates into the motion frame; its translation is
    /// the LiDAR origin in the motion frame (the lever arm).
    pub motion_from_lidar: Isometry3<f64>,
    pub source: ExtrinsicSource,
}

#[cfg(test)]
mod tests {
    use super::*;

    /// Inside a stretch its interpolation gives what the series gives, bit
    /// for bit; at its samples and outside it, nothing.
    #[test]
    fn a_stretchs_interpolation_is_the_series_value() {
        let samples: Vec<(StampNs, Vector3<f64>)> = (0..40i64)
            .map(|k| {
                let t = k * 5_000_000 + (k % 3) * 7;
                let s = k as f64;
                (t, Vector3::new(10.0 - 0.3 * s, -0.0, 0.01 * s * s - 0.2))
            })
            .collect();
        let series = TimeSeries::new(samples.clone(), 0.05);
        let mut hint = 0;
        let mut state = 9u64;
        for _ in 0..20_000 {
            state = state
                .wrapping_mul(6_364_136_223_846_793_005)
                .wrapping_add(1_442_695_040_888_963_407);
            let stamp = (state >> 40) as i64 % 200_000_000 - 1_000_000;
            let expected = series.at(stamp);
            assert_eq!(series.at_near(stamp, &mut hint), expected);
            if let Some(stretch) = series.interpolation_around(hint) {
                match stretch.at(stamp) {
                    Some(v) => {
                        let e = expected.unwrap();
                        assert_eq!(v.map(f64::to_bits), e.map(f64::to_bits), "{stamp}");
                    }
                    None => assert!(samples.iter().any(|s| s.0 == stamp)),
                }
            }
        }
    }
}
