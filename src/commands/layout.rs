//! `looming layout`: a Foxglove / Lichtblick layout for an annotated log.
//!
//! The 3D panel, with the clouds, the objects' boxes and the threat zones,
//! follows the log's own LiDAR frame (`lidar` in `synth` logs, `velo_link`
//! in KITTI: a fixed name would leave real logs in a wrong view), found from
//! the first `/looming/pairs` message of an annotated log, else from the
//! first cloud of its LiDAR topic. Below it the two looming range
//! images, each the full width of the window (a 64 x 2048 image is drawn
//! 4 pixels per beam, 8:1, so a full-width panel shows every beam); beside it
//! the near-miss events (Raw Messages) and their log lines.

use std::io::Write as _;
use std::path::{Path, PathBuf};

use serde_json::{Value, json};

use crate::annotate::topics::{
    DISAGREEMENT_TOPIC, EVENTS_TOPIC, IMAGE_DISAGREEMENT_TOPIC, IMAGE_FUSED_TOPIC, LOG_TOPIC,
    OBJECTS_TOPIC, PAIRS_TOPIC, POINTS_TOPIC, THREAT_TOPIC, THREAT_ZONES_TOPIC,
};
use crate::annotate::topics::{sensor_of_pairs_topic, sensor_topic};
use crate::decode::{DecodeLimits, decode};
use crate::input::{InputError, InputFile, InputOptions, InputRecord};
use crate::model::Decoded;
use crate::output::AtomicFile;
use crate::topics::{TopicError, TopicOverrides, select, select_sensors, sensor_names};

#[derive(Debug, thiserror::Error)]
pub enum LayoutError {
    #[error(transparent)]
    Input(#[from] InputError),
    #[error("{path}: {source}")]
    Topic {
        path: PathBuf,
        #[source]
        source: TopicError,
    },
    #[error("{path}: no message on {topic} says which frame the LiDAR is in")]
    NoFrame { path: PathBuf, topic: String },
    #[error("{path}: cannot write the layout: {source}")]
    Write {
        path: PathBuf,
        #[source]
        source: std::io::Error,
    },
}

/// What a layout is made for: the LiDAR's frame and topic.
#[derive(Debug, Clone, PartialEq, Eq, serde::Serialize)]
pub struct LayoutTarget {
    /// The frame the 3D panel follows.
    pub frame_id: String,
    /// The input cloud's topic (hidden in the 3D panel: our clouds lie on it).
    pub lidar_topic: Option<String>,
    /// Where the frame was read: `/looming/pairs` or the LiDAR topic.
    pub frame_from: String,
    /// On a log with several LiDARs, each sensor's name (its channels
    /// `/looming/<sensor>/...`) and input topic; the 3D panel follows the
    /// first sensor's frame and shows them all (Foxglove places the others
    /// through `/tf_static`). Empty with one LiDAR.
    #[serde(skip_serializing_if = "Vec::is_empty")]
    pub sensors: Vec<LayoutSensor>,
}

/// One sensor of a layout for several LiDARs.
#[derive(Debug, Clone, PartialEq, Eq, serde::Serialize)]
pub struct LayoutSensor {
    pub name: String,
    pub lidar_topic: Option<String>,
}

/// The LiDAR frame and topic of `log`: from its first `/looming/pairs`
/// message when it is annotated, else from the first cloud of its LiDAR
/// topic (`lidar_topic` chooses one when there are several).
pub fn target_of(log: &Path, lidar_topic: Option<&str>) -> Result<LayoutTarget, LayoutError> {
    let input = InputFile::open(log, InputOptions::default())?;
    let catalog = input.catalog();
    let overrides = TopicOverrides {
        lidar: lidar_topic.map(str::to_owned),
        ..TopicOverrides::default()
    };
    let selected = select(catalog, &overrides);
    let topic_error = |source| LayoutError::Topic {
        path: log.to_path_buf(),
        source,
    };
    // A topic the user named must exist, annotated log or not; without one
    // an annotated log needs none (its pairs name the frame).
    let selected = match selected {
        Err(source) if lidar_topic.is_some() => return Err(topic_error(source)),
        other => other,
    };
    if lidar_topic.is_none()
        && let Some(target) = several_sensors_target(log, &input)?
    {
        return Ok(target);
    }
    let lidar = selected.as_ref().ok().and_then(|s| s.lidar.clone());
    if let Some(pairs) = catalog.channels.values().find(|c| c.topic == PAIRS_TOPIC) {
        let frame = first_message(&input, pairs.id)?.and_then(|data| {
            let pair: Value = serde_json::from_slice(&data).ok()?;
            Some(pair.pointer("/current/frame_id")?.as_str()?.to_owned())
        });
        if let Some(frame_id) = frame {
            return Ok(LayoutTarget {
                frame_id,
                lidar_topic: lidar.map(|l| l.topic),
                frame_from: PAIRS_TOPIC.into(),
                sensors: Vec::new(),
            });
        }
    }
    let lidar = selected
        .map_err(topic_error)?
        .lidar
        .expect("select always chooses a LiDAR topic");
    let no_frame = || LayoutError::NoFrame {
        path: log.to_path_buf(),
        topic: lidar.topic.clone(),
    };
    let data = first_message(&input, lidar.channel_id)?.ok_or_else(no_frame)?;
    let limits = DecodeLimits::default();
    match decode(lidar.kind, lidar.encoding, false, &data, &limits) {
        Ok(Decoded::Scan(scan)) => Ok(LayoutTarget {
            frame_id: scan.frame_id,
            frame_from: lidar.topic.clone(),
            lidar_topic: Some(lidar.topic),
            sensors: Vec::new(),
        }),
        _ => Err(no_frame()),
    }
}

/// The target of a log annotated for several LiDARs (`/looming/<sensor>/pairs`
/// channels): the first sensor's frame, every sensor with its input topic.
/// `None` for any other log.
fn several_sensors_target(
    log: &Path,
    input: &InputFile,
) -> Result<Option<LayoutTarget>, LayoutError> {
    let catalog = input.catalog();
    let mut pairs: Vec<(String, u16, String)> = catalog
        .channels
        .values()
        .filter_map(|c| Some((sensor_of_pairs_topic(&c.topic)??, c.id, c.topic.clone())))
        .collect();
    if pairs.is_empty() {
        return Ok(None);
    }
    pairs.sort_by_key(|(_, id, _)| *id);
    // The input topics, by the names `process` gave them.
    let inputs: Vec<String> = select_sensors(catalog, &TopicOverrides::default())
        .map(|sensors| {
            sensors
                .into_iter()
                .filter_map(|s| s.lidar.map(|l| l.topic))
                .collect()
        })
        .unwrap_or_default();
    let names = sensor_names(&inputs.iter().map(String::as_str).collect::<Vec<_>>());
    let (_, first_id, first_topic) = &pairs[0];
    let frame_id = first_message(input, *first_id)?
        .and_then(|data| {
            let pair: Value = serde_json::from_slice(&data).ok()?;
            Some(pair.pointer("/current/frame_id")?.as_str()?.to_owned())
        })
        .ok_or_else(|| LayoutError::NoFrame {
            path: log.to_path_buf(),
            topic: first_topic.clone(),
        })?;
    let sensors = pairs
        .iter()
        .map(|(name, _, _)| LayoutSensor {
            name: name.clone(),
            lidar_topic: input_of(&names, name).map(|k| inputs[k].clone()),
        })
        .collect();
    Ok(Some(LayoutTarget {
        frame_id,
        lidar_topic: None,
        frame_from: first_topic.clone(),
        sensors,
    }))
}

/// Which of the input topics' sensor `names` is sensor `name`'s: its own,
/// else (a sensor split out of a merged cloud, `<sensor>_<id>`) its topic's.
fn input_of(names: &[String], name: &str) -> Option<usize> {
    names.iter().position(|n| n == name).or_else(|| {
        let (base, id) = name.rsplit_once('_')?;
        id.parse::<u32>().ok()?;
        names.iter().position(|n| n == base)
    })
}

/// The payload of the first message (in log time) on `channel_id`; reading
/// stops there, so only the start of the log is read.
fn first_message(input: &InputFile, channel_id: u16) -> Result<Option<Vec<u8>>, LayoutError> {
    let mut found = None;
    let read = input.read_records(false, &mut |record| match record {
        InputRecord::Message(message) if message.channel_id == channel_id => {
            found = Some(message.data);
            std::ops::ControlFlow::Break(())
        }
        _ => std::ops::ControlFlow::Continue(()),
    });
    match read {
        // Stopped: this sink found its message.
        Ok(_) | Err(InputError::Stopped) => Ok(found),
        Err(error) => Err(error.into()),
    }
}

/// The layout, as Foxglove's and Lichtblick's "Import layout" read it.
pub fn layout_json(target: &LayoutTarget) -> Value {
    let mut layout = one_sensor_layout(target);
    if !target.sensors.is_empty() {
        several_sensors_images(&mut layout, &target.sensors);
    }
    layout
}

/// With several LiDARs, the image row holds each sensor's fused range
/// image (the disagreement images stay in the log: six panels would leave
/// each too small to read).
fn several_sensors_images(layout: &mut Value, sensors: &[LayoutSensor]) {
    let config = layout["configById"]
        .as_object_mut()
        .expect("the layout has its panels' configs");
    config.remove("Image!looming-fused");
    config.remove("Image!looming-disagreement");
    let ids: Vec<String> = sensors
        .iter()
        .map(|sensor| {
            let id = format!("Image!looming-fused-{}", sensor.name);
            config.insert(
                id.clone(),
                image_panel(&sensor_topic(&sensor.name, IMAGE_FUSED_TOPIC)),
            );
            id
        })
        .collect();
    layout["layout"]["second"] = image_column(&ids);
}

/// Panels `ids` stacked in equal rows (a binary tree of splits).
fn image_column(ids: &[String]) -> Value {
    match ids {
        [] => Value::Null,
        [one] => json!(one),
        [first, rest @ ..] => json!({
            "direction": "column",
            "first": first,
            "second": image_column(rest),
            "splitPercentage": 100.0 / ids.len() as f64
        }),
    }
}

fn one_sensor_layout(target: &LayoutTarget) -> Value {
    json!({
        "configById": {
            "3D!looming": three_d_panel(target),
            "Image!looming-fused": image_panel(IMAGE_FUSED_TOPIC),
            "Image!looming-disagreement": image_panel(IMAGE_DISAGREEMENT_TOPIC),
            "RawMessages!looming-events": {
                "topicPath": EVENTS_TOPIC,
                "diffEnabled": false,
                "diffMethod": "custom",
                "diffTopicPath": "",
                "showFullMessageForDiff": false
            },
            "RosOut!looming-log": {
                "topicToRender": LOG_TOPIC,
                "searchTerms": [],
                "minLogLevel": 1
            }
        },
        "globalVariables": {},
        "userNodes": {},
        "playbackConfig": { "speed": 1.0 },
        "layout": {
            "direction": "column",
            "first": {
                "direction": "row",
                "first": "3D!looming",
                "second": {
                    "direction": "column",
                    "first": "RawMessages!looming-events",
                    "second": "RosOut!looming-log",
                    "splitPercentage": 60
                },
                "splitPercentage": 68
            },
            // Two full-width image rows: at 8:1 they fill a 1600-pixel
            // window's width in about 200 pixels each.
            "second": {
                "direction": "column",
                "first": "Image!looming-fused",
                "second": "Image!looming-disagreement",
                "splitPercentage": 50
            },
            "splitPercentage": 56
        }
    })
}

fn image_panel(topic: &str) -> Value {
    json!({ "imageMode": { "imageTopic": topic } })
}

/// A point cloud coloured by its own RGBA fields (our colour scale).
fn cloud(point_size: f64, visible: bool) -> Value {
    json!({
        "visible": visible,
        "pointSize": point_size,
        "pointShape": "circle",
        "decayTime": 0,
        "colorMode": "rgba-fields"
    })
}

/// The 3D panel's topics of one sensor (`sensor` `None`: the channels of a
/// log with one LiDAR).
fn sensor_topics(
    topics: &mut serde_json::Map<String, Value>,
    sensor: Option<&str>,
    lidar_topic: Option<&String>,
) {
    if let Some(lidar) = lidar_topic {
        // Our clouds lie exactly on the input cloud: it would hide them.
        topics.insert(lidar.clone(), json!({ "visible": false }));
    }
    let ours = |topic: &str| sensor.map_or(topic.to_owned(), |s| sensor_topic(s, topic));
    topics.insert(ours(POINTS_TOPIC), cloud(2.5, true));
    // Moving objects, drawn larger over the fused cloud.
    topics.insert(ours(DISAGREEMENT_TOPIC), cloud(5.0, true));
    topics.insert(ours(THREAT_TOPIC), cloud(4.0, false));
    // One sensor's threat zones are enough: every sensor's are the same
    // spheres about a different origin.
    topics.insert(ours(THREAT_ZONES_TOPIC), json!({ "visible": true }));
    // A box per object, coloured by threat, labelled with its id and TTC.
    topics.insert(ours(OBJECTS_TOPIC), json!({ "visible": true }));
}

fn three_d_panel(target: &LayoutTarget) -> Value {
    let mut topics = serde_json::Map::new();
    if target.sensors.is_empty() {
        sensor_topics(&mut topics, None, target.lidar_topic.as_ref());
    }
    for (k, sensor) in target.sensors.iter().enumerate() {
        sensor_topics(&mut topics, Some(&sensor.name), sensor.lidar_topic.as_ref());
        if k > 0 {
            let zones = sensor_topic(&sensor.name, THREAT_ZONES_TOPIC);
            topics.insert(zones, json!({ "visible": false }));
        }
    }
    json!({
        "cameraState": {
            "distance": 40,
            "perspective": true,
            "phi": 45,
            "thetaOffset": 90,
            "target": [0, 0, 0],
            "targetOffset": [8, 0, 0],
            "targetOrientation": [0, 0, 0, 1],
            "fovy": 45,
            "near": 0.5,
            "far": 5000
        },
        "followMode": "follow-pose",
        "followTf": target.frame_id,
        "scene": { "transforms": { "showLabel": true } },
        "transforms": {},
        "topics": topics,
        "layers": {
            "grid": {
                "visible": true,
                "frameLocked": true,
                "label": "Grid (2 m)",
                "instanceId": "grid",
                "layerId": "foxglove.Grid",
                "size": 80,
                "divisions": 40,
                "lineWidth": 1,
                "color": "#248eff80",
                "position": [0, 0, 0],
                "rotation": [0, 0, 0],
                "order": 1
            }
        },
        "imageMode": {}
    })
}

/// Write the layout of `target` to `path` (temporary file, then rename).
pub fn write_layout(path: &Path, target: &LayoutTarget) -> Result<(), LayoutError> {
    let err = |source| LayoutError::Write {
        path: path.to_path_buf(),
        source,
    };
    let mut text = serde_json::to_string_pretty(&layout_json(target)).expect("JSON values print");
    text.push('\n');
    let mut file = AtomicFile::create(path).map_err(err)?;
    file.write_all(text.as_bytes()).map_err(err)?;
    file.commit().map(|_| ()).map_err(err)
}

#[cfg(test)]
mod tests {
    use super::*;

    fn target(frame: &str) -> LayoutTarget {
        LayoutTarget {
            frame_id: frame.into(),
            lidar_topic: Some("/velodyne_points".into()),
            frame_from: PAIRS_TOPIC.into(),
            sensors: Vec::new(),
        }
    }

    #[test]
    fn a_merged_clouds_sensors_are_shown_on_its_topic() {
        let names = ["lidars".to_string(), "a".into(), "a_2".into()];
        assert_eq!(input_of(&names, "lidars_1"), Some(0));
        assert_eq!(input_of(&names, "a_2"), Some(2));
        assert_eq!(input_of(&names, "b_1"), None);
    }

    /// Every leaf of the panel tree has its config and every config a leaf.
    fn assert_panels_match(layout: &Value) {
        let config = layout["configById"].as_object().unwrap();
        let mut leaves = Vec::new();
        fn collect<'a>(node: &'a Value, leaves: &mut Vec<&'a str>) {
            match node {
                Value::String(id) => leaves.push(id),
                node => {
                    collect(&node["first"], leaves);
                    collect(&node["second"], leaves);
                }
            }
        }
        collect(&layout["layout"], &mut leaves);
        leaves.sort_unstable();
        let mut ids: Vec<&str> = config.keys().map(String::as_str).collect();
        ids.sort_unstable();
        assert_eq!(leaves, ids);
    }

    #[test]
    fn a_layout_for_three_lidars_shows_each_sensors_channels_and_fused_image() {
        let mut three = target("lidar_roof");
        three.lidar_topic = None;
        three.sensors = ["lidar_roof", "lidar_left", "lidar_right"]
            .iter()
            .map(|name| LayoutSensor {
                name: (*name).into(),
                lidar_topic: Some(format!("/{name}/points")),
            })
            .collect();
        let layout = layout_json(&three);
        assert_panels_match(&layout);
        let config = layout["configById"].as_object().unwrap();
        let topics = &config["3D!looming"]["topics"];
        for name in ["lidar_roof", "lidar_left", "lidar_right"] {
            assert_eq!(topics[format!("/{name}/points")]["visible"], false);
            assert_eq!(topics[format!("/looming/{name}/points")]["visible"], true);
            assert_eq!(topics[format!("/looming/{name}/objects")]["visible"], true);
            assert_eq!(
                config[&format!("Image!looming-fused-{name}")]["imageMode"]["imageTopic"],
                format!("/looming/{name}/image/fused")
            );
        }
        // One set of threat zones; the log's one list of events.
        assert_eq!(topics["/looming/lidar_left/threat_zones"]["visible"], false);
        assert_eq!(config["3D!looming"]["followTf"], "lidar_roof");
        assert_eq!(
            config["RawMessages!looming-events"]["topicPath"],
            EVENTS_TOPIC
        );
    }

    #[test]
    fn every_panel_in_the_tree_has_its_config_and_the_3d_panel_follows_the_frame() {
        let layout = layout_json(&target("velo_link"));
        assert_panels_match(&layout);
        let config = layout["configById"].as_object().unwrap();
        let three_d = &config["3D!looming"];
        assert_eq!(three_d["followTf"], "velo_link");
        assert_eq!(three_d["topics"]["/velodyne_points"]["visible"], false);
        assert_eq!(three_d["topics"][POINTS_TOPIC]["colorMode"], "rgba-fields");
        assert_eq!(
            config["RawMessages!looming-events"]["topicPath"],
            EVENTS_TOPIC
        );
    }
}
