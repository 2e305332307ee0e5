//! The vehicle's LiDARs: the scenario's one (frame `lidar`, `/lidar/points`,
//! `/truth/points`, `/truth/scan`) or several, the scenario's as the roof
//! sensor `lidar_roof` and its `extra_lidars`, each with its own world (rolling
//! sweep, scan times), topics and noise seed, all in the same scene.

use super::encode::{LIDAR_FRAME, stamp_ns, topics};
use super::scene::{ROOF_NAME, Scenario};
use super::sensor::World;

/// One LiDAR of the vehicle.
pub struct RigLidar {
    /// Frame id, and the `<sensor>` of its truth topics when there are several.
    pub name: String,
    pub topic: String,
    pub truth_points_topic: String,
    pub truth_scan_topic: String,
    pub world: World,
    /// Seed of its range noise, dropouts and specks.
    pub seed: u64,
    /// Its value in the clouds' `sensor_id` field, when every LiDAR
    /// publishes on one topic ([`on_one_topic`]).
    pub sensor_id: Option<u8>,
}

/// The topic every LiDAR publishes on with `--one-topic`.
pub const ONE_TOPIC: &str = "/lidars/points";

/// Every LiDAR of `rig` on [`ONE_TOPIC`], its points tagged with its index
/// (0 the roof) in a `sensor_id` field, as a driver serving several LiDARs
/// on one topic (or a merging node) publishes them. Truth stays per LiDAR.
pub fn on_one_topic(rig: &mut [RigLidar]) {
    for (k, lidar) in rig.iter_mut().enumerate() {
        lidar.topic = ONE_TOPIC.into();
        lidar.sensor_id = u8::try_from(k).ok();
    }
}

/// The LiDARs of `scenario`, the roof (or only) one first; `seed` is the
/// run's, the roof LiDAR's noise seed (the others get their own from it).
pub fn rig(scenario: &Scenario, seed: u64) -> Vec<RigLidar> {
    let roof = World::new(scenario.clone());
    if scenario.extra_lidars.is_empty() {
        return vec![RigLidar {
            name: LIDAR_FRAME.into(),
            topic: topics::LIDAR.into(),
            truth_points_topic: topics::TRUTH_POINTS.into(),
            truth_scan_topic: topics::TRUTH_SCAN.into(),
            world: roof,
            seed,
            sensor_id: None,
        }];
    }
    let named = |name: &str, world: World, seed: u64| RigLidar {
        name: name.into(),
        topic: format!("/{name}/points"),
        truth_points_topic: crate::truth::points_topic(Some(name)),
        truth_scan_topic: crate::truth::scan_topic(Some(name)),
        world,
        seed,
        sensor_id: None,
    };
    let mut lidars = vec![named(ROOF_NAME, roof, seed)];
    for (k, extra) in scenario.extra_lidars.iter().enumerate() {
        let world = World::for_lidar(scenario, &extra.lidar, extra.phase_s);
        lidars.push(named(&extra.name, world, sensor_seed(seed, k as u64 + 1)));
    }
    lidars
}

/// The noise seed of LiDAR `k` (0 = the roof: the run's seed itself).
fn sensor_seed(seed: u64, k: u64) -> u64 {
    seed ^ k.wrapping_mul(0xA076_1D64_78BD_642F)
}

/// Every scan of the rig written for a drive from `start_s` on, as (LiDAR,
/// scan index), in order of publication (the end of the scan's sweep, when
/// its cloud is logged), the earlier LiDAR first on a tie.
pub fn schedule(rig: &[RigLidar], start_s: f64) -> Vec<(usize, u64)> {
    let mut order: Vec<(i64, usize, u64)> = rig
        .iter()
        .enumerate()
        .flat_map(|(k, lidar)| {
            let world = &lidar.world;
            (world.first_scan_at(start_s)..world.scan_count())
                .map(move |i| (stamp_ns(world.scan_stamp_s(i) + world.period_s), k, i))
        })
        .collect();
    order.sort_unstable();
    order.into_iter().map(|(_, k, i)| (k, i)).collect()
}

/// Start of the first scan written (of any LiDAR) for a drive from `start_s` on.
pub fn first_stamp_s(rig: &[RigLidar], start_s: f64) -> f64 {
    rig.iter()
        .map(|lidar| {
            let world = &lidar.world;
            world.scan_stamp_s(world.first_scan_at(start_s))
        })
        .fold(f64::INFINITY, f64::min)
}
