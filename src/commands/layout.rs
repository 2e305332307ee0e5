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
use crate::decode::{DecodeLimits, decode};
use crate::input::{InputError, InputFile, InputOptions, InputRecord};
use crate::model::Decoded;
use crate::output::AtomicFile;
use crate::topics::{TopicError, TopicOverrides, select};

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
        }),
        _ => Err(no_frame()),
    }
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

fn three_d_panel(target: &LayoutTarget) -> Value {
    let mut topics = serde_json::Map::new();
    if let Some(lidar) = &target.lidar_topic {
        // Our clouds lie exactly on the input cloud: it would hide them.
        topics.insert(lidar.clone(), json!({ "visible": false }));
    }
    topics.insert(POINTS_TOPIC.into(), cloud(2.5, true));
    // Moving objects, drawn larger over the fused cloud.
    topics.insert(DISAGREEMENT_TOPIC.into(), cloud(5.0, true));
    topics.insert(THREAT_TOPIC.into(), cloud(4.0, false));
    topics.insert(THREAT_ZONES_TOPIC.into(), json!({ "visible": true }));
    // A box per object, coloured by threat, labelled with its id and TTC.
    topics.insert(OBJECTS_TOPIC.into(), json!({ "visible": true }));
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
        }
    }

    #[test]
    fn every_panel_in_the_tree_has_its_config_and_the_3d_panel_follows_the_frame() {
        let layout = layout_json(&target("velo_link"));
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
