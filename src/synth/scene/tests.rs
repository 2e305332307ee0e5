//! Unit tests of scenario parsing, defaults, layouts, realism and validation.

use super::*;

#[test]
fn every_built_in_scenario_parses_and_validates() {
    for (name, _) in BUILT_IN {
        let scenario = load(name).unwrap_or_else(|e| panic!("{name}: {e}"));
        assert_eq!(&scenario.name, name);
    }
}

#[test]
fn unknown_fields_and_names_are_refused() {
    let text = r#"{"name": "x", "ego": {"speed_mps": [[0, 1]]}, "colour": "red"}"#;
    assert!(matches!(parse("x", text), Err(ScenarioError::Parse { .. })));
    let err = load("no-such-scenario").unwrap_err().to_string();
    assert!(err.contains("straight-road"), "{err}");
}

#[test]
fn defaults_fill_what_is_not_given() {
    let scenario = parse("x", r#"{"name": "x", "ego": {"speed_mps": [[0, 1]]}}"#).unwrap();
    assert_eq!(scenario.lidar.beams, 64);
    assert_eq!(scenario.lidar.elevation_min_deg, -24.8);
    assert_eq!(scenario.imu.rate_hz, 100.0);
    assert_eq!(scenario.velocity_rate_hz, 50.0);
}

#[test]
fn profiles_interpolate_and_hold() {
    let profile = vec![[1.0, 10.0], [3.0, 20.0]];
    assert_eq!(profile_at(&profile, 0.0), 10.0);
    assert_eq!(profile_at(&profile, 2.0), 15.0);
    assert_eq!(profile_at(&profile, 5.0), 20.0);
    assert_eq!(profile_slope_at(&profile, 2.0), 5.0);
    assert_eq!(profile_slope_at(&profile, 4.0), 0.0);
}

#[test]
fn layouts_and_realism_parse_and_stay_out_of_the_json_when_default() {
    for name in LAYOUT_NAMES {
        let layout: CloudLayout = name.parse().unwrap();
        assert_eq!(&layout.to_string(), name);
    }
    assert_eq!(
        "ring-field:channel:uint8".parse::<CloudLayout>().unwrap(),
        CloudLayout::RingField(RingField {
            name: RingFieldName::Channel,
            datatype: 2
        })
    );
    assert!("ring-field:ringo".parse::<CloudLayout>().is_err());
    assert!("columnar".parse::<CloudLayout>().is_err());
    let minimal = r#"{"name": "x", "ego": {"speed_mps": [[0, 1]]}}"#;
    let scenario = parse("x", minimal).unwrap();
    let json = serde_json::to_string(&scenario).unwrap();
    assert!(
        !json.contains("layout") && !json.contains("realism"),
        "{json}"
    );
    let text = r#"{"name": "x", "ego": {"speed_mps": [[0, 1]]},
        "lidar": {"layout": "organized", "realism": "hdl64e"}}"#;
    let scenario = parse("x", text).unwrap();
    assert_eq!(scenario.lidar.layout, CloudLayout::Organized);
    assert_eq!(scenario.lidar.realism, Realism::hdl64e());
    // What is written back reads the same.
    let again: Scenario = serde_json::from_str(&serde_json::to_string(&scenario).unwrap()).unwrap();
    assert_eq!(again, scenario);
    let text = r#"{"name": "x", "ego": {"speed_mps": [[0, 1]]},
        "lidar": {"realism": {"off_axis": true, "speck_fraction": 0.001}}}"#;
    let realism = parse("x", text).unwrap().lidar.realism;
    assert!(realism.off_axis && !realism.azimuth_offsets && realism.speck_fraction == 0.001);
    for bad in [
        r#"{"layout": "sideways"}"#,
        r#"{"realism": "hdl32e"}"#,
        r#"{"realism": {"offaxis": true}}"#,
        r#"{"realism": {"dropout_fraction": 0.9}}"#,
    ] {
        let text = format!(r#"{{"name": "x", "ego": {{"speed_mps": [[0, 1]]}}, "lidar": {bad}}}"#);
        assert!(parse("x", &text).is_err(), "{bad}");
    }
}

#[test]
fn bad_actor_motion_is_refused() {
    let text = r#"{"name": "x", "ego": {"speed_mps": [[0, 1]]}, "actors": [{"id": 1}]}"#;
    assert!(matches!(
        parse("x", text),
        Err(ScenarioError::Invalid { .. })
    ));
}

#[test]
fn extra_lidars_are_presets_or_objects() {
    let text = r#"{"name": "x", "ego": {"speed_mps": [[0, 1]]}, "extra_lidars": [
        "left",
        {"name": "lidar_rear", "phase_s": 0.05,
         "lidar": {"beams": 16, "rate_hz": 5, "mount_rpy_deg": [0, 0, 180]}}]}"#;
    let scenario = parse("x", text).unwrap();
    let [left, rear] = scenario.extra_lidars.as_slice() else {
        panic!("two extra LiDARs expected");
    };
    assert_eq!(left, &ExtraLidar::preset("left").unwrap());
    assert_eq!(
        (
            left.name.as_str(),
            left.phase_s,
            left.lidar.beams,
            left.lidar.rate_hz
        ),
        ("lidar_left", 0.013, 32, 20.0)
    );
    assert_eq!((rear.name.as_str(), rear.lidar.beams), ("lidar_rear", 16));
    assert_eq!(
        rear.lidar.columns, 2048,
        "the rest of `lidar` has its defaults"
    );
    // What is written back (objects) reads the same; none writes nothing.
    let again: Scenario = serde_json::from_str(&serde_json::to_string(&scenario).unwrap()).unwrap();
    assert_eq!(again, scenario);
    let none = parse("x", r#"{"name": "x", "ego": {"speed_mps": [[0, 1]]}}"#).unwrap();
    assert!(
        !serde_json::to_string(&none)
            .unwrap()
            .contains("extra_lidars")
    );
    assert_eq!(ExtraLidar::presets_for(1), vec![]);
    assert_eq!(ExtraLidar::presets_for(3).len(), 2);
}

#[test]
fn bad_extra_lidars_are_refused() {
    for bad in [
        r#""middle""#,
        r#"{"name": "lidar"}"#,
        r#"{"name": "lidar_roof"}"#,
        r#"{"name": "Left"}"#,
        r#"{"name": "a/b"}"#,
        r#"{"name": "x", "phase_s": 0.2}"#,
        r#"{"name": "x", "phase_s": -0.01}"#,
        r#"{"name": "x", "lidar": {"columns": 4}}"#,
        r#"{"name": "x", "lidar": {"rate_hz": 0}}"#,
        r#"{"name": "x", "colour": "red"}"#,
        r#""left", "left""#,
    ] {
        let text = format!(
            r#"{{"name": "x", "ego": {{"speed_mps": [[0, 1]]}}, "extra_lidars": [{bad}]}}"#
        );
        assert!(parse("x", &text).is_err(), "{bad}");
    }
}
