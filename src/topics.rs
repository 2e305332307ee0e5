//! Which input topics feed the pipeline: auto-detected by schema name, or
//! chosen with `--lidar-topic`, `--imu-topic`, `--velocity-topic`.

use std::fmt::Write as _;

use crate::decode::{MessageKind, WireEncoding};
use crate::input::{Catalog, ChannelInfo};

/// The role a topic plays for looming.
#[derive(Debug, Clone, Copy, PartialEq, Eq, serde::Serialize)]
#[serde(rename_all = "snake_case")]
pub enum Role {
    Lidar,
    Imu,
    Velocity,
    Tf,
    TfStatic,
}

impl Role {
    fn of(kind: MessageKind, topic: &str) -> Role {
        match kind {
            MessageKind::PointCloud2 | MessageKind::FoxglovePointCloud => Role::Lidar,
            MessageKind::Imu => Role::Imu,
            MessageKind::TwistStamped | MessageKind::Odometry => Role::Velocity,
            MessageKind::TfMessage if is_static_tf_topic(topic) => Role::TfStatic,
            MessageKind::TfMessage => Role::Tf,
        }
    }

    /// The role in a word or two, as messages name it.
    pub fn name(self) -> &'static str {
        match self {
            Role::Lidar => "LiDAR",
            Role::Imu => "IMU",
            Role::Velocity => "velocity",
            Role::Tf => "tf",
            Role::TfStatic => "tf_static",
        }
    }

    fn what(self) -> &'static str {
        match self {
            Role::Lidar => "LiDAR point cloud (sensor_msgs/PointCloud2 or foxglove.PointCloud)",
            Role::Imu => "IMU (sensor_msgs/Imu)",
            Role::Velocity => "velocity (geometry_msgs/TwistStamped or nav_msgs/Odometry)",
            Role::Tf => "tf",
            Role::TfStatic => "tf_static",
        }
    }
}

/// `/tf_static` (any namespace) carries static transforms.
pub(crate) fn is_static_tf_topic(topic: &str) -> bool {
    topic.trim_end_matches('/').ends_with("tf_static")
}

/// A channel the pipeline decodes, with how to decode it.
#[derive(Debug, Clone, serde::Serialize)]
pub struct SelectedChannel {
    pub channel_id: u16,
    pub topic: String,
    pub role: Role,
    #[serde(skip)]
    pub kind: MessageKind,
    #[serde(skip)]
    pub encoding: WireEncoding,
    pub schema_name: String,
    pub message_count: u64,
}

/// The topics chosen for one run.
#[derive(Debug, Clone, serde::Serialize)]
pub struct TopicSelection {
    /// `None` only when a log without LiDAR is copied through
    /// (`NoLidarPolicy::Copy`): [`select`] always chooses one.
    pub lidar: Option<SelectedChannel>,
    pub imu: Option<SelectedChannel>,
    pub velocity: Option<SelectedChannel>,
    /// Every `/tf` and `/tf_static` channel.
    pub tf: Vec<SelectedChannel>,
    /// The one sensor of the LiDAR channel's merged clouds this selection
    /// takes (`pipeline` splits them by their sensor field); `None`: the
    /// channel's clouds whole.
    #[serde(skip_serializing_if = "Option::is_none")]
    pub merged: Option<MergedSensor>,
}

/// One sensor of a LiDAR topic whose clouds merge several: the cloud's
/// per-point sensor field and this sensor's value in it.
#[derive(Debug, Clone, PartialEq, Eq, serde::Serialize)]
pub struct MergedSensor {
    pub field: String,
    pub id: u32,
}

impl TopicSelection {
    /// No channel at all: a log copied through, nothing decoded.
    pub fn none() -> Self {
        Self {
            lidar: None,
            imu: None,
            velocity: None,
            tf: Vec::new(),
            merged: None,
        }
    }

    /// This selection once per sensor of its merged clouds: `field`'s
    /// values `ids`.
    pub fn per_merged_sensor(&self, field: &str, ids: &[u32]) -> Vec<TopicSelection> {
        ids.iter()
            .map(|&id| TopicSelection {
                merged: Some(MergedSensor {
                    field: field.to_owned(),
                    id,
                }),
                ..self.clone()
            })
            .collect()
    }

    /// All selected channels.
    pub fn all(&self) -> impl Iterator<Item = &SelectedChannel> {
        self.lidar
            .iter()
            .chain(&self.imu)
            .chain(&self.velocity)
            .chain(&self.tf)
    }
}

/// User choices of topics.
#[derive(Debug, Clone, Default, serde::Serialize)]
pub struct TopicOverrides {
    pub lidar: Option<String>,
    pub imu: Option<String>,
    pub velocity: Option<String>,
}

#[derive(Debug, thiserror::Error)]
pub enum TopicError {
    /// The topic asked for names no channel of its role.
    #[error("{} topic {topic}: no {} channel has that topic.\n{candidates}", role.name(), role.what())]
    Unknown {
        role: Role,
        topic: String,
        candidates: String,
    },
    /// Several channels share the topic asked for.
    #[error("{} topic {topic}: several channels share that topic (ids {ids}); the file is ambiguous.", role.name())]
    Duplicated {
        role: Role,
        topic: String,
        ids: String,
    },
    /// Several channels could serve the role and none was asked for.
    #[error("several {} topics; one must be chosen.\n{candidates}", role.what())]
    Ambiguous { role: Role, candidates: String },
    #[error("{0}")]
    Missing(String),
}

/// Every channel the pipeline could decode, with its role.
pub fn candidates(catalog: &Catalog) -> Vec<SelectedChannel> {
    catalog
        .channel_infos()
        .into_iter()
        // Our own output and synthetic ground truth are never inputs.
        .filter(|info| {
            !crate::annotate::topics::is_ours(&info.topic) && !info.topic.starts_with("/truth/")
        })
        .filter_map(|info| {
            let kind = MessageKind::from_schema_name(&info.schema_name)?;
            let encoding = WireEncoding::from_message_encoding(&info.message_encoding)?;
            Some(selected(&info, kind, encoding))
        })
        .collect()
}

fn selected(info: &ChannelInfo, kind: MessageKind, encoding: WireEncoding) -> SelectedChannel {
    SelectedChannel {
        channel_id: info.id,
        topic: info.topic.clone(),
        role: Role::of(kind, &info.topic),
        kind,
        encoding,
        schema_name: info.schema_name.clone(),
        message_count: info.message_count,
    }
}

/// Choose the LiDAR, IMU, velocity and tf channels.
pub fn select(catalog: &Catalog, overrides: &TopicOverrides) -> Result<TopicSelection, TopicError> {
    let all = candidates(catalog);
    let lidar = choose(catalog, &all, Role::Lidar, overrides.lidar.as_deref())?.ok_or_else(|| {
        let stopped = catalog.listing_stopped.as_ref().map_or(String::new(), |reason| {
            format!("\nThe file could not be read to its end ({reason}): channels after that point are unknown.")
        });
        TopicError::Missing(format!(
            "no LiDAR topic found: no channel has a {} schema with a supported encoding (cdr, ros1, protobuf).{stopped}\n{}",
            Role::Lidar.what(),
            list_all_channels(catalog)
        ))
    })?;
    let imu = choose(catalog, &all, Role::Imu, overrides.imu.as_deref())?;
    let velocity = choose(catalog, &all, Role::Velocity, overrides.velocity.as_deref())?;
    let tf = all
        .iter()
        .filter(|c| matches!(c.role, Role::Tf | Role::TfStatic))
        .cloned()
        .collect();
    Ok(TopicSelection {
        lidar: Some(lidar),
        imu,
        velocity,
        tf,
        merged: None,
    })
}

/// `--lidar-topic all`: every LiDAR topic of the log.
pub const ALL_LIDARS: &str = "all";

/// One selection per LiDAR sensor, for `process`: every LiDAR topic of the
/// log (by default, or `--lidar-topic all`) or those `--lidar-topic` lists
/// (comma-separated), each with the IMU, velocity and tf channels the
/// sensors share. A log with one LiDAR gets the one selection [`select`]
/// gives.
pub fn select_sensors(
    catalog: &Catalog,
    overrides: &TopicOverrides,
) -> Result<Vec<TopicSelection>, TopicError> {
    let all = candidates(catalog);
    let lidars: Vec<SelectedChannel> = match overrides.lidar.as_deref() {
        None | Some(ALL_LIDARS) => all
            .iter()
            .filter(|c| c.role == Role::Lidar)
            .cloned()
            .collect(),
        Some(list) => list
            .split(',')
            .map(str::trim)
            .filter(|topic| !topic.is_empty())
            .map(|topic| {
                choose(catalog, &all, Role::Lidar, Some(topic)).map(|c| c.into_iter().collect())
            })
            .collect::<Result<Vec<Vec<SelectedChannel>>, _>>()?
            .into_iter()
            .flatten()
            .collect(),
    };
    if lidars.is_empty() {
        // The single selection's error, which lists the log's channels.
        return select(catalog, overrides).map(|one| vec![one]);
    }
    let imu = choose(catalog, &all, Role::Imu, overrides.imu.as_deref())?;
    let velocity = choose(catalog, &all, Role::Velocity, overrides.velocity.as_deref())?;
    let tf: Vec<SelectedChannel> = all
        .iter()
        .filter(|c| matches!(c.role, Role::Tf | Role::TfStatic))
        .cloned()
        .collect();
    let mut seen = std::collections::BTreeSet::new();
    Ok(lidars
        .into_iter()
        // A topic listed twice is one sensor.
        .filter(|lidar| seen.insert(lidar.channel_id))
        .map(|lidar| TopicSelection {
            lidar: Some(lidar),
            imu: imu.clone(),
            velocity: velocity.clone(),
            tf: tf.clone(),
            merged: None,
        })
        .collect())
}

/// Last topic segments that say "a point cloud", not which sensor.
const CLOUD_SEGMENTS: [&str; 8] = [
    "points",
    "points_raw",
    "pointcloud",
    "pointcloud_raw",
    "point_cloud",
    "cloud",
    "velodyne_points",
    "lidar",
];

/// The name of the sensor publishing `topic`, for the names of its output
/// channels (`/looming/<sensor>/points`, docs/channels.md): the topic's
/// segments joined by `_`, without a last segment that only says "points"
/// (`/lidar_front/points` -> `lidar_front`,
/// `/sensing/lidar/top/pointcloud_raw` -> `sensing_lidar_top`), every
/// character outside `[A-Za-z0-9_-]` made `_`.
pub fn sensor_name(topic: &str) -> String {
    let segments: Vec<&str> = topic.split('/').filter(|s| !s.is_empty()).collect();
    let kept = match segments.split_last() {
        Some((last, rest)) if !rest.is_empty() && CLOUD_SEGMENTS.contains(last) => rest,
        _ => &segments[..],
    };
    let name: String = kept
        .join("_")
        .chars()
        .map(|c| {
            if c.is_ascii_alphanumeric() || c == '_' || c == '-' {
                c
            } else {
                '_'
            }
        })
        .collect();
    if name.is_empty() {
        "lidar".into()
    } else {
        name
    }
}

/// The sensor names of `topics`, made unique (`_2`, `_3`, ... after a name
/// already taken).
pub fn sensor_names(topics: &[&str]) -> Vec<String> {
    unique(topics.iter().map(|topic| sensor_name(topic)))
}

/// The sensor names of `sensors`' LiDARs, made unique: a merged cloud's
/// sensor is its topic's sensor name and its value, `_<id>`
/// (`/sensing/lidar/concatenated/pointcloud` sensor 2 ->
/// `sensing_lidar_concatenated_2`).
pub fn selection_names(sensors: &[TopicSelection]) -> Vec<String> {
    unique(sensors.iter().filter_map(|s| {
        let name = sensor_name(&s.lidar.as_ref()?.topic);
        Some(match &s.merged {
            Some(merged) => format!("{name}_{}", merged.id),
            None => name,
        })
    }))
}

fn unique(names: impl Iterator<Item = String>) -> Vec<String> {
    let mut taken = std::collections::BTreeSet::new();
    names
        .map(|base| {
            let mut name = base.clone();
            let mut k = 2;
            while !taken.insert(name.clone()) {
                name = format!("{base}_{k}");
                k += 1;
            }
            name
        })
        .collect()
}

fn choose(
    catalog: &Catalog,
    all: &[SelectedChannel],
    role: Role,
    wanted: Option<&str>,
) -> Result<Option<SelectedChannel>, TopicError> {
    let mut of_role: Vec<&SelectedChannel> = all.iter().filter(|c| c.role == role).collect();
    // A twist is the direct velocity measurement: with one TwistStamped and any
    // number of Odometry topics, auto-detection takes the twist.
    if wanted.is_none() && role == Role::Velocity {
        let twists: Vec<&SelectedChannel> = of_role
            .iter()
            .copied()
            .filter(|c| c.kind == MessageKind::TwistStamped)
            .collect();
        if twists.len() == 1 {
            of_role = twists;
        }
    }
    if let Some(topic) = wanted {
        let matching: Vec<&&SelectedChannel> =
            of_role.iter().filter(|c| c.topic == topic).collect();
        return match matching.as_slice() {
            [one] => Ok(Some((**one).clone())),
            [] => Err(TopicError::Unknown {
                role,
                topic: topic.to_owned(),
                candidates: list_candidates(&of_role, catalog),
            }),
            _ => Err(TopicError::Duplicated {
                role,
                topic: topic.to_owned(),
                ids: matching
                    .iter()
                    .map(|c| c.channel_id.to_string())
                    .collect::<Vec<_>>()
                    .join(", "),
            }),
        };
    }
    match of_role.as_slice() {
        [] => Ok(None),
        [one] => Ok(Some((*one).clone())),
        _ => Err(TopicError::Ambiguous {
            role,
            candidates: list_candidates(&of_role, catalog),
        }),
    }
}

fn list_candidates(candidates: &[&SelectedChannel], catalog: &Catalog) -> String {
    if candidates.is_empty() {
        return format!("There is no candidate.\n{}", list_all_channels(catalog));
    }
    let mut text = String::from("Candidates:\n");
    for c in candidates {
        let _ = writeln!(
            text,
            "  {:<32} {:<36} {:>8} messages",
            c.topic, c.schema_name, c.message_count
        );
    }
    text
}

fn list_all_channels(catalog: &Catalog) -> String {
    let mut text = String::from("Channels in the file:\n");
    for info in catalog.channel_infos() {
        let _ = writeln!(
            text,
            "  {:<32} {:<36} {:<10} {:>8} messages",
            info.topic, info.schema_name, info.message_encoding, info.message_count
        );
    }
    text
}

#[cfg(test)]
mod sensor_name_tests {
    use super::*;

    #[test]
    fn a_sensor_is_named_by_its_topic_without_the_points_segment() {
        assert_eq!(sensor_name("/lidar_front/points"), "lidar_front");
        assert_eq!(
            sensor_name("/sensing/lidar/top/pointcloud_raw"),
            "sensing_lidar_top"
        );
        assert_eq!(sensor_name("/velodyne_points"), "velodyne_points");
        assert_eq!(sensor_name("/points"), "points");
        assert_eq!(sensor_name("/ouster/points"), "ouster");
        assert_eq!(sensor_name("/a b/c.d/points"), "a_b_c_d");
        assert_eq!(sensor_name("/"), "lidar");
        assert_eq!(
            sensor_names(&["/a/points", "/a/cloud", "/b/points"]),
            ["a", "a_2", "b"]
        );
    }

    #[test]
    fn a_merged_clouds_sensors_are_named_by_topic_and_value() {
        let lidar = SelectedChannel {
            channel_id: 1,
            topic: "/sensing/lidar/concatenated/pointcloud".into(),
            role: Role::Lidar,
            kind: MessageKind::PointCloud2,
            encoding: WireEncoding::Cdr,
            schema_name: "sensor_msgs/msg/PointCloud2".into(),
            message_count: 3,
        };
        let whole = TopicSelection {
            lidar: Some(lidar),
            ..TopicSelection::none()
        };
        let split = whole.per_merged_sensor("sensor_id", &[0, 2]);
        assert_eq!(split[1].merged.as_ref().map(|m| m.id), Some(2));
        assert_eq!(
            selection_names(&split),
            [
                "sensing_lidar_concatenated_0",
                "sensing_lidar_concatenated_2"
            ]
        );
        assert_eq!(selection_names(&[whole]), ["sensing_lidar_concatenated"]);
    }
}
