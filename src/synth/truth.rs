//! Per-scan truth records and the planted near-miss windows.

use std::collections::BTreeMap;

use serde::{Deserialize, Serialize};

use super::encode::stamp_ns;
use super::kinematics::actor_motion;
use super::scene::Scenario;
use super::sensor::{SimScan, World};

/// `/truth/scan`: the state of the drive at a scan's stamp.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct TruthScan {
    pub scan_index: u64,
    pub stamp_ns: i64,
    pub period_s: f64,
    pub lidar_frame: String,
    /// Vehicle (IMU) origin in the world, metres; yaw, rad.
    pub ego_position_m: [f64; 3],
    pub ego_yaw_rad: f64,
    pub ego_speed_mps: f64,
    pub ego_yaw_rate_radps: f64,
    /// Velocity of the LiDAR origin in the LiDAR frame at the stamp, m/s.
    pub lidar_velocity_mps: [f64; 3],
    /// Angular velocity of the LiDAR in its frame at the stamp, rad/s.
    pub lidar_angular_velocity_radps: [f64; 3],
    pub actors: Vec<TruthActor>,
    pub points: u64,
    /// Points per object id (0 = static world).
    pub points_by_object: BTreeMap<u32, u64>,
}

#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct TruthActor {
    pub id: u32,
    pub label: String,
    /// World position of the box centre (x, y), m; velocity (vx, vy), m/s.
    pub position_m: [f64; 2],
    pub velocity_mps: [f64; 2],
    pub planted_near_miss: bool,
}

impl TruthScan {
    /// The truth of a scan of the (only) LiDAR, frame `lidar`.
    pub fn new(world: &World, scan: &SimScan) -> Self {
        Self::of_lidar(world, scan, super::encode::LIDAR_FRAME)
    }

    /// The truth of a scan of the LiDAR with frame `lidar_frame`.
    pub fn of_lidar(world: &World, scan: &SimScan, lidar_frame: &str) -> Self {
        let ego = world.track.state(scan.stamp_s);
        let lidar = world.lidar_state(scan.stamp_s);
        let velocity = lidar.to_lidar(&lidar.velocity_world_mps);
        let omega = lidar.to_lidar(&lidar.angular_velocity_world_radps);
        let mut points_by_object = BTreeMap::new();
        for point in &scan.points {
            *points_by_object.entry(point.truth.object_id).or_default() += 1;
        }
        Self {
            scan_index: scan.index,
            stamp_ns: stamp_ns(scan.stamp_s),
            period_s: world.period_s,
            lidar_frame: lidar_frame.into(),
            ego_position_m: ego.position_m.into(),
            ego_yaw_rad: ego.yaw_rad,
            ego_speed_mps: ego.speed_mps,
            ego_yaw_rate_radps: ego.yaw_rate_radps,
            lidar_velocity_mps: velocity.into(),
            lidar_angular_velocity_radps: omega.into(),
            actors: world
                .scenario
                .actors
                .iter()
                .map(|actor| {
                    let (position_m, velocity_mps) = actor_motion(actor, scan.stamp_s);
                    TruthActor {
                        id: actor.id,
                        label: actor.label.clone(),
                        position_m,
                        velocity_mps,
                        planted_near_miss: actor.planted_near_miss,
                    }
                })
                .collect(),
            points: scan.points.len() as u64,
            points_by_object,
        }
    }
}

/// Points count towards an event only when they face the sensor this much.
pub(crate) const FACING_COS: f64 = 0.5;

/// `/truth/events`: one planted near miss.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct TruthEvent {
    pub actor_id: u32,
    pub label: String,
    /// Stamp of the first scan in which the actor is threatening.
    pub start_ns: i64,
    /// Stamp of the last such scan plus one period.
    pub end_ns: i64,
    pub start_s: f64,
    pub end_s: f64,
    /// Largest true ray looming on the actor over the event, 1/s.
    pub peak_ray_looming_per_s: f64,
    pub min_time_to_contact_s: f64,
    pub threatening_scans: u64,
    pub ttc_threshold_s: f64,
    pub min_points: usize,
}

/// Per planted actor: the scans in which at least `min_points` of its points
/// that face the sensor (incidence within 60 degrees: grazing points have
/// unbounded ray looming and no detector trusts them) have a true ray looming
/// of at least `1 / ttc_threshold_s`.
pub(crate) struct EventTracker {
    threshold_per_s: f64,
    ttc_threshold_s: f64,
    min_points: usize,
    /// actor id -> (scan index, peak looming) of threatening scans.
    hot: BTreeMap<u32, Vec<(u64, f64)>>,
}

impl EventTracker {
    pub fn new(scenario: &Scenario) -> Self {
        Self {
            threshold_per_s: 1.0 / scenario.events.ttc_threshold_s,
            ttc_threshold_s: scenario.events.ttc_threshold_s,
            min_points: scenario.events.min_points,
            hot: scenario
                .actors
                .iter()
                .filter(|a| a.planted_near_miss)
                .map(|a| (a.id, Vec::new()))
                .collect(),
        }
    }

    pub fn observe(&mut self, _world: &World, scan: &SimScan) {
        for (actor_id, scans) in &mut self.hot {
            let looming: Vec<f64> = scan
                .points
                .iter()
                .filter(|p| p.truth.object_id == *actor_id && p.truth.incidence_cos >= FACING_COS)
                .map(|p| p.truth.ray_looming_per_s)
                .filter(|l| *l >= self.threshold_per_s)
                .collect();
            if looming.len() >= self.min_points {
                let peak = looming.iter().copied().fold(f64::MIN, f64::max);
                scans.push((scan.index, peak));
            }
        }
    }

    /// Windows of threatening scans (a one-scan gap does not split a window).
    pub fn finish(self, world: &World) -> Vec<TruthEvent> {
        let mut events = Vec::new();
        for (actor_id, scans) in &self.hot {
            let label = world
                .scenario
                .actors
                .iter()
                .find(|a| a.id == *actor_id)
                .map(|a| a.label.clone())
                .unwrap_or_default();
            for window in split_windows(scans) {
                let (first, last) = (window[0].0, window[window.len() - 1].0);
                let peak = window.iter().map(|w| w.1).fold(f64::MIN, f64::max);
                // Whole nanoseconds, as the stamps are.
                let start_s = round_ns(first as f64 * world.period_s);
                let end_s = round_ns((last + 1) as f64 * world.period_s);
                events.push(TruthEvent {
                    actor_id: *actor_id,
                    label: label.clone(),
                    start_ns: stamp_ns(start_s),
                    end_ns: stamp_ns(end_s),
                    start_s,
                    end_s,
                    peak_ray_looming_per_s: peak,
                    min_time_to_contact_s: 1.0 / peak,
                    threatening_scans: window.len() as u64,
                    ttc_threshold_s: self.ttc_threshold_s,
                    min_points: self.min_points,
                });
            }
        }
        events.sort_by_key(|e| (e.start_ns, e.actor_id));
        events
    }
}

fn round_ns(t_s: f64) -> f64 {
    (t_s * 1e9).round() / 1e9
}

fn split_windows(scans: &[(u64, f64)]) -> Vec<&[(u64, f64)]> {
    let mut windows = Vec::new();
    let mut start = 0;
    for i in 1..=scans.len() {
        if i == scans.len() || scans[i].0 > scans[i - 1].0 + 2 {
            if i > start {
                windows.push(&scans[start..i]);
            }
            start = i;
        }
    }
    windows
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn windows_tolerate_one_missing_scan() {
        let scans = [(3, 1.0), (4, 1.0), (6, 1.0), (9, 1.0), (10, 1.0)];
        let windows = split_windows(&scans);
        assert_eq!(windows.len(), 2);
        assert_eq!(windows[0].len(), 3);
        assert_eq!(windows[1][0].0, 9);
    }
}
