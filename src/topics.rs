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
}

impl TopicSelection {
    /// No channel at all: a log copied through, nothing decoded.
    pub fn none() -> Self {
        Self {
            lidar: None,
            imu: None,
            velocity: None,
            tf: Vec::new(),
        }
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
    })
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
