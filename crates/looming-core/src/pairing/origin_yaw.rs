//! The yaw of a sensor placed from its rings at every scan
//! (`origin_track`): the rings give its position, roll and pitch, never its
//! yaw. A spinning sensor's sweep starts at one azimuth of its own (drivers
//! cut their scans there), so where the cloud's points carry their times,
//! the azimuth at which the sweep passes time 0, measured in axes that keep
//! the frame's yaw, turns as the sensor turns: its change from one scan to
//! the next is the sensor's turn ([`sweep_phase`]). That change is checked
//! against the course of the placements (a car turns as it goes and cannot
//! turn standing: [`next_yaw`]); where it disagrees (a driver that cuts its
//! scans anywhere), or the points carry no times, the axes keep the yaw
//! they had: the scans are then moved about their positions in the frame's
//! axes, which a turn leaves unfollowed (the warp between two scans is
//! right, the turn within a sweep and the path's curve are lost).

use std::f64::consts::{PI, TAU};

use nalgebra::{Isometry3, Point3};

use crate::model::{Scan, StampNs};

/// Points whose azimuth is read for the phase, at most: the phase is a
/// mean direction, a thousandth of a degree from a few thousand points.
const PHASE_SAMPLE: usize = 4_000;
/// Returns nearer than this (horizontally) to the sensor are left out: the
/// vehicle's body, where a centimetre turns the azimuth by degrees, m.
const PHASE_MIN_RANGE_M: f64 = 2.0;
/// The phases of the points must agree this well (the length of their mean
/// direction, 1 when they all agree): a sweep of one turn per scan. Lasers
/// fired a few degrees off each other's azimuth (HDL-64, Ouster) keep it
/// above 0.99.
const MIN_PHASE_AGREEMENT: f64 = 0.9;
/// Steps shorter than this give no course to check a turn against: the
/// sensor crept or stood, and then turns little, m.
const MIN_COURSE_STEP_M: f64 = 0.3;
/// A turn read from the sweeps agrees with the course's within this, rad
/// (0.6 deg per scan: a steady turn's course and yaw turn alike; the
/// course's own noise at 0.3 m steps is a few thousandths).
const TURN_AGREEMENT_RAD: f64 = 0.01;
/// Where no course checks it, a turn faster than this is no car's, rad/s.
const MAX_TURN_RATE_RADPS: f64 = 1.0;

/// The azimuth at which `scan`'s sweep passes time 0, in the axes of `pose`
/// (the sensor's position, roll and pitch in the cloud's frame, the frame's
/// yaw kept), rad; `None` without per-point times, or where the points'
/// azimuths do not follow their times one turn per `period_s` (either way
/// round).
pub(super) fn sweep_phase(scan: &Scan, pose: &Isometry3<f64>, period_s: f64) -> Option<f64> {
    let times = scan.time_offset_s.as_deref()?;
    if times.len() != scan.points_m.len() || !period_s.is_finite() || period_s <= 0.0 {
        return None;
    }
    let sensor_from_cloud = pose.inverse();
    let spin_radps = TAU / period_s;
    let step = scan.points_m.len().div_ceil(PHASE_SAMPLE).max(1);
    // The mean direction of each point's azimuth less its sweep's turn so
    // far, for a sweep turning left and for one turning right.
    let (mut left, mut right, mut count) = ([0.0f64; 2], [0.0f64; 2], 0usize);
    for (p, &t) in scan.points_m.iter().zip(times).step_by(step) {
        let q = sensor_from_cloud * Point3::new(f64::from(p[0]), f64::from(p[1]), f64::from(p[2]));
        if !t.is_finite() || q.x.hypot(q.y) < PHASE_MIN_RANGE_M {
            continue;
        }
        let azimuth = q.y.atan2(q.x);
        let turned = spin_radps * f64::from(t);
        let (sin_l, cos_l) = (azimuth - turned).sin_cos();
        let (sin_r, cos_r) = (azimuth + turned).sin_cos();
        left = [left[0] + cos_l, left[1] + sin_l];
        right = [right[0] + cos_r, right[1] + sin_r];
        count += 1;
    }
    let length = |sum: [f64; 2]| sum[0].hypot(sum[1]) / count.max(1) as f64;
    let best = if length(left) >= length(right) {
        left
    } else {
        right
    };
    (count > 0 && length(best) >= MIN_PHASE_AGREEMENT).then(|| best[1].atan2(best[0]))
}

/// A placement as the yaw needs it: its stamp, position, the yaw its axes
/// were given and its sweep's phase.
#[derive(Debug, Clone, Copy, PartialEq)]
pub(super) struct YawSample {
    pub stamp_ns: StampNs,
    pub position_m: [f64; 3],
    pub yaw_rad: f64,
    pub phase_rad: Option<f64>,
}

/// The yaw of the axes of a scan placed at `position_m` with sweep phase
/// `phase_rad`, after the placements `before` (oldest first): the last
/// one's, turned by the change of the sweep's phase since when the course
/// agrees (or, too slow for a course, when no car turns faster); `true`
/// when it turned so.
pub(super) fn next_yaw(
    before: &[YawSample],
    stamp_ns: StampNs,
    position_m: [f64; 3],
    phase_rad: Option<f64>,
) -> (f64, bool) {
    let Some(last) = before.last() else {
        return (0.0, false);
    };
    let (Some(phase), Some(last_phase)) = (phase_rad, last.phase_rad) else {
        return (last.yaw_rad, false);
    };
    let turn = wrap(phase - last_phase);
    let dt_s = (stamp_ns - last.stamp_ns) as f64 * 1e-9;
    let agrees = match course_turn(before, position_m) {
        Some(course) => (turn - course).abs() <= TURN_AGREEMENT_RAD,
        None => dt_s > 0.0 && turn.abs() <= MAX_TURN_RATE_RADPS * dt_s,
    };
    if agrees {
        (last.yaw_rad + turn, true)
    } else {
        (last.yaw_rad, false)
    }
}

/// How the course turned over the last two steps, to `position_m`: the
/// direction of the last step less that of the one before (each about as
/// long as [`MIN_COURSE_STEP_M`] at least), rad.
fn course_turn(before: &[YawSample], position_m: [f64; 3]) -> Option<f64> {
    let [.., a, b] = before else {
        return None;
    };
    let course = |from: &[f64; 3], to: &[f64; 3]| {
        let (dx, dy) = (to[0] - from[0], to[1] - from[1]);
        (dx.hypot(dy) >= MIN_COURSE_STEP_M).then(|| dy.atan2(dx))
    };
    let earlier = course(&a.position_m, &b.position_m)?;
    let later = course(&b.position_m, &position_m)?;
    Some(wrap(later - earlier))
}

/// An angle in [-pi, pi), rad.
fn wrap(angle_rad: f64) -> f64 {
    (angle_rad + PI).rem_euclid(TAU) - PI
}

#[cfg(test)]
mod tests {
    use super::*;

    fn placed(k: i64, x: f64, y: f64, yaw: f64, phase: Option<f64>) -> YawSample {
        YawSample {
            stamp_ns: k * 100_000_000,
            position_m: [x, y, 0.0],
            yaw_rad: yaw,
            phase_rad: phase,
        }
    }

    /// On a circle of radius 30 m at 1 m per scan: each step turns the
    /// course by 1/30 rad.
    fn on_circle(k: i64) -> [f64; 3] {
        let a = k as f64 / 30.0;
        [30.0 * a.sin(), 30.0 * (1.0 - a.cos()), 0.0]
    }

    #[test]
    fn a_turn_the_course_agrees_with_is_taken_and_another_held() {
        let before: Vec<YawSample> = (0..3)
            .map(|k| {
                let p = on_circle(k);
                placed(k, p[0], p[1], 0.1 + k as f64 / 30.0, Some(k as f64 / 30.0))
            })
            .collect();
        let (yaw, turned) = next_yaw(&before, 300_000_000, on_circle(3), Some(0.1));
        assert!(turned && (yaw - (0.1 + 0.1)).abs() < 1e-12, "{yaw}");
        // A seam that jumped 3 degrees: held.
        let jumped = 2.0 / 30.0 + 0.05;
        let (yaw, turned) = next_yaw(&before, 300_000_000, on_circle(3), Some(jumped));
        assert!(!turned && (yaw - (0.1 + 2.0 / 30.0)).abs() < 1e-12, "{yaw}");
        // Standing: no course; a small turn taken, a car's impossible one not.
        let still: Vec<YawSample> = (0..3)
            .map(|k| placed(k, 0.0, 0.0, 0.0, Some(0.0)))
            .collect();
        assert!(next_yaw(&still, 300_000_000, [0.0; 3], Some(0.02)).1);
        assert!(!next_yaw(&still, 300_000_000, [0.0; 3], Some(0.5)).1);
        // No phase: held.
        assert_eq!(
            next_yaw(&before, 300_000_000, on_circle(3), None),
            (0.1 + 2.0 / 30.0, false)
        );
    }

    #[test]
    fn the_sweeps_phase_turns_with_the_sensor() {
        use crate::pairing::origin::tests::scan_in_base_link;
        use nalgebra::{Translation3, UnitQuaternion, Vector3};
        let at = [25.0, -7.0, 1.8];
        let mut scan = scan_in_base_link(&[at]);
        // Laser by laser, 720 columns each from azimuth 0, over 0.1 s.
        let times: Vec<f32> = (0..scan.points_m.len())
            .map(|i| (i % 720) as f32 / 720.0 * 0.1)
            .collect();
        scan.time_offset_s = Some(times);
        let level = Isometry3::from_parts(
            Translation3::new(at[0], at[1], at[2]),
            UnitQuaternion::identity(),
        );
        let phase = sweep_phase(&scan, &level, 0.1).unwrap();
        assert!(wrap(phase).abs() < 1e-3, "{phase}");
        // The sensor turned 0.3 rad left about its position: so does its
        // sweep's phase.
        let turn = Isometry3::from_parts(
            Translation3::new(at[0], at[1], at[2]),
            UnitQuaternion::from_axis_angle(&Vector3::z_axis(), 0.3),
        ) * level.inverse();
        for p in &mut scan.points_m {
            let q = turn * Point3::new(f64::from(p[0]), f64::from(p[1]), f64::from(p[2]));
            *p = [q.x as f32, q.y as f32, q.z as f32];
        }
        let turned = sweep_phase(&scan, &level, 0.1).unwrap();
        assert!((wrap(turned - phase) - 0.3).abs() < 1e-3, "{turned}");
        // Times that do not follow the azimuths: no phase.
        scan.time_offset_s = Some(
            (0..scan.points_m.len())
                .map(|i| (i % 7) as f32 * 0.013)
                .collect(),
        );
        assert!(sweep_phase(&scan, &level, 0.1).is_none());
    }

    #[test]
    fn angles_wrap_into_one_turn() {
        assert!((wrap(3.0 * PI) + PI).abs() < 1e-12);
        assert!((wrap(-0.5) + 0.5).abs() < 1e-12);
        assert!((wrap(TAU - 0.1) + 0.1).abs() < 1e-12);
    }
}
