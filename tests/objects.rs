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
    assert_eq!(ids.len(), 1, "one id through the near miss: {ids:?}");
    common::viewer::assert_opens_in_viewers(&out);
}
