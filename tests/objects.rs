//! Objects through the real CLI (`/looming/objects`, `/looming/object_list`,
//! `object_id` in `--fields full`) on the committed synthetic cut-in: the car
//! that cuts in and brakes is one object, followed under one id through the
//! near miss, moving, with the looming the near miss peaked at.

mod common;

use std::path::Path;

use common::{looming_process, scratch, stderr};

#[test]
fn the_cut_in_car_is_one_tracked_moving_object_with_the_near_miss_looming() {
    let dir = scratch("objects-cut-in");
    let out = dir.join("out.mcap");
    let input = Path::new(env!("CARGO_MANIFEST_DIR")).join("sample_logs/cut-in.mcap");
    let run = looming_process(&input, &out, &["--fields", "full"]);
    assert!(run.status.success(), "{}", stderr(&run));
    let contents = common::read_all(&std::fs::read(&out).unwrap());
    let events = contents.topic_messages("/looming/events");
    assert_eq!(events.len(), 1);
    let event: serde_json::Value = serde_json::from_slice(&events[0].data).unwrap();
    let (start, end) = (
        event["start_log_time_ns"].as_u64().unwrap(),
        event["end_log_time_ns"].as_u64().unwrap(),
    );
    let peak_time = event["peak"]["log_time_ns"].as_u64().unwrap();
    let event_object = event["object_id"]
        .as_u64()
        .expect("the near miss names its object");
    let peak_looming = event["peak"]["looming_per_s"].as_f64().unwrap();
    let lists = contents.topic_messages("/looming/object_list");
    assert_eq!(
        lists.len(),
        contents.topic_messages("/looming/points").len()
    );
    assert_eq!(
        lists.len(),
        contents.topic_messages("/looming/objects").len()
    );
    let mut ids = std::collections::BTreeSet::new();
    let mut peak_seen = false;
    for message in lists {
        if !(start..=end).contains(&message.log_time) {
            continue;
        }
        let list: serde_json::Value = serde_json::from_slice(&message.data).unwrap();
        // The car: the nearest object within 15 degrees of ahead.
        let car = list["objects"]
            .as_array()
            .unwrap()
            .iter()
            .filter(|o| o["bearing_deg"].as_f64().unwrap().abs() < 15.0)
            .min_by(|a, b| {
                a["nearest_range_m"]
                    .as_f64()
                    .unwrap()
                    .total_cmp(&b["nearest_range_m"].as_f64().unwrap())
            })
            .expect("an object ahead during the near miss");
        ids.insert(car["id"].as_u64().unwrap());
        assert_eq!(car["moving"], true, "{car}");
        let looming = car["looming_per_s"].as_f64().expect("a looming");
        assert!(looming > 0.5, "{car}");
        if message.log_time == peak_time {
            peak_seen = true;
            assert!(
                (looming - peak_looming).abs() < 0.08,
                "object {looming} against the near miss's {peak_looming}"
            );
            // TTC 1.0 s: at the medium level (1.5 s) or the high (1 s).
            assert!(
                ["medium", "high"].contains(&car["threat"].as_str().unwrap()),
                "{car}"
            );
        }
    }
    assert!(peak_seen, "no object list at the near miss's peak");
    assert_eq!(ids.len(), 1, "one id through the near miss: {ids:?}");
    assert!(ids.contains(&event_object), "{event_object} vs {ids:?}");
    common::viewer::assert_opens_in_viewers(&out);
}

/// The feedback of the objects' looming into their cells
/// (`objects::fuse_objects`), on the committed cut-in: on the car, the cells
/// trusted after it are most of the car and never fewer than before, and
/// their fused looming is the car's.
#[test]
fn the_objects_looming_makes_the_cut_in_cars_cells_trusted() {
    use looming::engine::EngineConfig;
    use looming::objects::{ObjectConfig, PairObjects, fuse_objects};
    let config = EngineConfig::default();
    let mut checked = 0;
    let (mut car_cells, mut trusted_before, mut trusted_after) = (0, 0, 0);
    for_each_cut_in_pair(|pair, mut result| {
        // Untracked: every object as at its first sighting.
        let objects = PairObjects::find(&pair.current, &result, &ObjectConfig::default());
        // The car: the nearest approaching object within 15 degrees of ahead.
        let Some((index, car)) = objects
            .objects
            .iter()
            .enumerate()
            .filter(|(_, o)| o.bearing_deg.abs() < 15.0 && o.looming_per_s.is_some_and(|l| l > 0.5))
            .min_by(|a, b| a.1.nearest_range_m.total_cmp(&b.1.nearest_range_m))
        else {
            return;
        };
        let car_looming = car.looming_per_s.unwrap();
        let cells: Vec<usize> = (0..objects.cell_object.len())
            .filter(|&c| objects.cell_object[c] == index as u32)
            .collect();
        let trusted =
            |r: &looming::engine::PairLooming| cells.iter().filter(|&&c| r.mask[c] == 0).count();
        let before = trusted(&result);
        let engine_mask = result.mask.clone();
        let counts = fuse_objects(&mut result, &pair.current, &objects, &config.threat_ttc_s);
        let after = trusted(&result);
        assert!(after >= before, "{after} < {before}");
        // Before a track tells whether its object moves across the rays, no
        // cell the engine found at an occlusion edge is taken: there the
        // outline of an object crossing the rays sweeps (on the synthetic
        // crossing's right side sensor, a car's edge read 0.8 1/s against a
        // truth of -1.5 when it was).
        let edge_taken = (0..engine_mask.len())
            .filter(|&c| engine_mask[c] & looming::engine::mask::EDGE != 0 && result.mask[c] == 0)
            .count();
        assert_eq!(edge_taken, 0, "edge cells trusted at a first sighting");
        assert!(counts.combined > 0, "{counts:?}");
        car_cells += cells.len();
        trusted_before += before;
        trusted_after += after;
        let mut errors: Vec<f64> = cells
            .iter()
            .filter(|&&c| result.mask[c] == 0)
            .map(|&c| (f64::from(result.fused[c]) - car_looming).abs())
            .collect();
        assert!(!errors.is_empty(), "no trusted car cell");
        errors.sort_by(f64::total_cmp);
        let median = errors[errors.len() / 2];
        assert!(median < 0.05, "median |fused - car| {median}");
        checked += 1;
    });
    assert!(checked >= 5, "{checked} pairs with the car ahead");
    // Over the pairs: most of the car (its side, cutting in, is another face
    // and keeps the engine's judgement: 70.6 % in all at 2026-11-26), a
    // twentieth more than the engine alone trusted (66.8 %; 77 % and a tenth
    // more while first sightings took edge cells too).
    assert!(
        trusted_after as f64 >= 0.7 * car_cells as f64
            && trusted_after as f64 >= 1.05 * trusted_before as f64,
        "{trusted_before} -> {trusted_after} of {car_cells} car cells trusted"
    );
}

/// A followed object's cells whose `L_lidar` says their rays met something
/// far behind it in the previous scan (a wall behind a box, seen past its
/// edge) do not measure its approach, even unflagged: on the committed
/// cut-in, a static object's cells are given the looming of rays that
/// lengthened by 10 m over the pair (20 1/s and more), and the tracker
/// measures it on no cell: its looming is the ego prediction along its
/// rays, as its cells gave untouched.
#[test]
fn cells_that_saw_another_surface_before_do_not_measure_a_followed_object() {
    use looming::objects::ObjectTracker;
    let mut tracker = ObjectTracker::default();
    let mut checked = 0;
    for_each_cut_in_pair(|pair, result| {
        let before = tracker.clone();
        let untouched = tracked_objects(&pair, &result, &mut tracker);
        // A static object followed since the last pair, its looming
        // measured on its cells.
        let Some((index, object)) = untouched.objects.iter().enumerate().find(|(_, o)| {
            o.age_pairs >= 2
                && !o.moving
                && o.measured_cells >= 20
                && !o.looming_from_track
                && o.nearest_range_m < 30.0
        }) else {
            return;
        };
        let mut planted = result.clone();
        for cell in 0..untouched.cell_object.len() {
            if untouched.cell_object[cell] == index as u32 && planted.l_lidar[cell].is_finite() {
                let range_m = planted.image.range_m[cell];
                planted.l_lidar[cell] = 10.0 / (range_m * pair.dt_s as f32);
                planted.disagreement[cell] = planted.l_lidar[cell] - planted.l_ray_ego[cell];
            }
        }
        let objects = tracked_objects(&pair, &planted, &mut before.clone());
        let same = objects
            .objects
            .iter()
            .find(|o| o.id == object.id)
            .expect("the same object, the same id");
        let looming = same.looming_per_s.expect("the ego prediction");
        assert!(same.looming_assumed_static, "{same:?}");
        assert_eq!(same.measured_cells, 0, "{same:?}");
        assert_eq!(same.lidar_looming_per_s, None, "{same:?}");
        let untouched_looming = object.looming_per_s.unwrap();
        assert!(
            (looming - untouched_looming).abs() < 0.02,
            "{looming} predicted against {untouched_looming} from its cells"
        );
        checked += 1;
    });
    assert!(
        checked >= 10,
        "{checked} pairs with a followed static object"
    );
}

/// An object moving on its own flags moving its cells that disagree with
/// the ego prediction but lie outside the engine's moving patches (a car
/// seen by one beam of a side sensor): on the committed cut-in, the car's
/// cells are taken out of the patches and the objects stage puts them back,
/// their fused looming their own `L_lidar` (combined with the car's value),
/// not the ego prediction.
#[test]
fn a_moving_objects_disagreeing_cells_are_moving_though_outside_a_patch() {
    use looming::engine::EngineConfig;
    use looming::objects::{ObjectTracker, fuse_objects};
    let config = EngineConfig::default();
    let mut tracker = ObjectTracker::default();
    let mut checked = 0;
    for_each_cut_in_pair(|pair, mut result| {
        let objects = tracked_objects(&pair, &result, &mut tracker);
        let Some(index) = objects.objects.iter().position(|o| o.moving) else {
            return;
        };
        let taken_out: Vec<usize> = (0..objects.cell_object.len())
            .filter(|&c| objects.cell_object[c] == index as u32 && result.moving[c])
            .collect();
        if taken_out.len() < 5 {
            return;
        }
        for &cell in &taken_out {
            result.moving[cell] = false;
            result.fused[cell] = result.l_ray_ego[cell];
        }
        let counts = fuse_objects(&mut result, &pair.current, &objects, &config.threat_ttc_s);
        assert!(counts.confirmed_moving >= taken_out.len(), "{counts:?}");
        for &cell in &taken_out {
            assert!(result.moving[cell], "cell {cell} not moving again");
            // Its own measurement (then combined with its object's
            // value), not the ego prediction it was given.
            let (fused, lidar, ego) = (
                result.fused[cell],
                result.l_lidar[cell],
                result.l_ray_ego[cell],
            );
            assert!(
                (fused - lidar).abs() < 0.1 && (fused - lidar).abs() < (fused - ego).abs(),
                "fused {fused}, its L_lidar {lidar}, the ego prediction {ego}"
            );
        }
        checked += 1;
    });
    assert!(checked >= 5, "{checked} pairs with a moving object");
}

/// The objects of `result` with their ids and velocities from `tracker`,
/// as `process` finds and tracks them (before their feedback).
fn tracked_objects(
    pair: &looming::model::ScanPair,
    result: &looming::engine::PairLooming,
    tracker: &mut looming::objects::ObjectTracker,
) -> looming::objects::PairObjects {
    use looming::objects::{ObjectConfig, PairObjects};
    let mut objects = PairObjects::find(&pair.current, result, &ObjectConfig::default());
    tracker.update(&mut objects, result, pair.step_s);
    objects
}

/// Every pair of the committed cut-in through the engine as `process` runs
/// it (one engine cache over the log), to `each` with its result.
fn for_each_cut_in_pair(each: impl FnMut(looming::model::ScanPair, looming::engine::PairLooming)) {
    for_each_sample_pair("cut-in", each);
}

/// Every pair of the committed sample log `log` (`sample_logs/LOG.mcap`)
/// through the engine as `process` runs it, to `each` with its result.
fn for_each_sample_pair(
    log: &str,
    mut each: impl FnMut(looming::model::ScanPair, looming::engine::PairLooming),
) {
    use looming::engine::{EngineCache, EngineConfig, compute_with_cache};
    let input = Path::new(env!("CARGO_MANIFEST_DIR")).join(format!("sample_logs/{log}.mcap"));
    let config = EngineConfig::default();
    let mut cache = EngineCache::default();
    looming::pipeline::replay(
        &input,
        &looming::pipeline::ScanOptions::default(),
        &mut |_| {},
        &mut |pair| {
            if let Some(result) = compute_with_cache(&pair, &config, &mut cache) {
                each(pair, result);
            }
        },
    )
    .unwrap();
}

/// The path's peak looming (the fastest cluster at the 10 s floor that
/// counts: an area, in the corridor, plausible if static) is the largest
/// looming among the clusters `hot_clusters` keeps at that floor, on every
/// pair of the committed cut-in and crossing drives, where `path_peak_looming`
/// describes the clusters fastest first and stops at the first that counts.
/// A wider corridor must raise it on some pair: clusters that do not count
/// are passed over.
#[test]
fn the_paths_peak_is_the_fastest_floor_cluster_that_counts() {
    use looming::engine::EngineConfig;
    use looming::events::{
        Corridor, EventConfig, FacingLooming, PATH_PEAK_FLOOR_TTC_S, default_min_cells,
        hot_clusters, path_peak_looming,
    };
    use looming::objects::{ObjectConfig, ObjectTracker, PairObjects};
    let config = EventConfig::default();
    let wide = EventConfig {
        path_margin_m: 20.0,
        ..config.clone()
    };
    let (mut pairs, mut with_peak, mut raised, mut counting) = (0, 0, 0, 0);
    for log in ["cut-in", "crossing"] {
        let mut tracker = ObjectTracker::default();
        for_each_sample_pair(log, |pair, mut looming| {
            let (objects, _) = PairObjects::find_tracked_fused(
                &pair.current,
                &mut looming,
                (
                    &ObjectConfig::default(),
                    &EngineConfig::default().threat_ttc_s,
                ),
                &mut tracker,
                pair.step_s,
            );
            let frame = (&*pair.current, Some(&objects));
            let min_cells = default_min_cells(&looming.geometry);
            let corridor = |config: &EventConfig| {
                Corridor::new(
                    looming.velocity_mps.map(Into::into),
                    looming.angular_velocity_radps.map(Into::into),
                    config.corridor_half_width_m(),
                )
            };
            // The peak, and the largest of the clusters kept at the
            // floor, in the default corridor and in one 20 m wider each
            // side (where several clusters count, of different looming).
            let [(peak, largest), (wider, wider_largest)] = [&config, &wide].map(|config| {
                let floor = EventConfig {
                    ttc_threshold_s: PATH_PEAK_FLOOR_TTC_S,
                    ..config.clone()
                };
                let corridor = corridor(config);
                let facing = FacingLooming::of(&looming, config);
                let kept = hot_clusters(&looming, frame, (&corridor, &facing), &floor, min_cells);
                counting += kept.len();
                (
                    path_peak_looming(&looming, frame, (&corridor, &facing), config, min_cells),
                    kept.iter()
                        .map(|cluster| cluster.looming_per_s)
                        .max_by(f64::total_cmp),
                )
            });
            assert_eq!(peak, largest, "{log} pair {}", pair.index);
            assert_eq!(wider, wider_largest, "{log} pair {} (wide)", pair.index);
            assert!(wider >= peak, "{log} pair {}", pair.index);
            pairs += 1;
            with_peak += usize::from(peak.is_some());
            raised += usize::from(wider > peak);
        });
    }
    assert!(pairs >= 30, "{pairs} pairs");
    assert!(with_peak >= 10, "{with_peak} of {pairs} pairs with a peak");
    assert!(
        raised >= 1,
        "no pair where the corridor passed a faster cluster over"
    );
    // More clusters count than pairs hold a peak: pairs with several.
    assert!(counting > 2 * with_peak, "{counting} clusters counted");
}
