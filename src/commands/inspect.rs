//! `looming inspect`: what a file holds and which topics the pipeline would use.

use std::fmt::Write as _;
use std::path::Path;

use crate::input::{ChannelInfo, InputError, InputFile, InputOptions, ReadMode};
use crate::model::format_log_time;
use crate::topics::{Role, TopicOverrides, candidates, select};

/// Everything `inspect` prints, also as JSON.
#[derive(Debug, Clone, serde::Serialize)]
pub struct InspectReport {
    pub file: String,
    pub file_bytes: u64,
    pub read: ReadMode,
    pub start_ns: Option<u64>,
    pub end_ns: Option<u64>,
    pub duration_s: Option<f64>,
    pub messages: Option<u64>,
    pub attachments: u64,
    pub metadata: u64,
    pub schemas: Vec<SchemaRow>,
    pub channels: Vec<ChannelRow>,
    pub detected: Detection,
}

#[derive(Debug, Clone, serde::Serialize)]
pub struct SchemaRow {
    pub id: u16,
    pub name: String,
    pub encoding: String,
}

#[derive(Debug, Clone, serde::Serialize)]
pub struct ChannelRow {
    #[serde(flatten)]
    pub info: ChannelInfo,
    /// Messages per second over the channel's span (or the file's, when the
    /// channel's own is not in the summary).
    pub rate_hz: Option<f64>,
    /// What the pipeline would use it for.
    pub role: Option<Role>,
}

/// Which topic auto-detection picks, or why it cannot.
#[derive(Debug, Clone, serde::Serialize)]
pub struct Detection {
    pub lidar: Vec<String>,
    pub imu: Vec<String>,
    pub velocity: Vec<String>,
    pub tf: Vec<String>,
    pub tf_static: Vec<String>,
    /// `None` when `process` would run with auto-detection; else its error.
    pub problem: Option<String>,
}

pub fn inspect(path: &Path) -> Result<InspectReport, InputError> {
    let input = InputFile::open(path, InputOptions::default())?;
    let catalog = input.catalog();
    let roles = candidates(catalog);
    let role_of = |id: u16| roles.iter().find(|c| c.channel_id == id).map(|c| c.role);
    let topics_with = |role: Role| -> Vec<String> {
        roles
            .iter()
            .filter(|c| c.role == role)
            .map(|c| c.topic.clone())
            .collect()
    };
    let file_span_s = match (catalog.start_ns, catalog.end_ns) {
        (Some(start), Some(end)) if end > start => Some((end - start) as f64 * 1e-9),
        _ => None,
    };
    let channels = catalog
        .channel_infos()
        .into_iter()
        .map(|info| {
            let span_s = match (info.first_log_time_ns, info.last_log_time_ns) {
                (Some(first), Some(last)) if last > first => Some((last - first) as f64 * 1e-9),
                (Some(_), Some(_)) => None,
                _ => file_span_s,
            };
            let rate_hz = span_s
                .filter(|_| info.message_count >= 2)
                .map(|s| (info.message_count - 1) as f64 / s);
            ChannelRow {
                role: role_of(info.id),
                rate_hz,
                info,
            }
        })
        .collect();
    let problem = select(catalog, &TopicOverrides::default())
        .err()
        .map(|e| e.to_string());
    Ok(InspectReport {
        file: path.display().to_string(),
        file_bytes: std::fs::metadata(path).map(|m| m.len()).unwrap_or(0),
        read: input.mode().clone(),
        start_ns: catalog.start_ns,
        end_ns: catalog.end_ns,
        duration_s: file_span_s,
        messages: catalog.total_messages(),
        attachments: catalog.attachment_count,
        metadata: catalog.metadata_count,
        schemas: catalog
            .schemas
            .values()
            .map(|s| SchemaRow {
                id: s.id,
                name: s.name.clone(),
                encoding: s.encoding.clone(),
            })
            .collect(),
        channels,
        detected: Detection {
            lidar: topics_with(Role::Lidar),
            imu: topics_with(Role::Imu),
            velocity: topics_with(Role::Velocity),
            tf: topics_with(Role::Tf),
            tf_static: topics_with(Role::TfStatic),
            problem,
        },
    })
}

impl InspectReport {
    /// The human-readable form.
    pub fn to_text(&self) -> String {
        let mut out = String::new();
        let _ = writeln!(out, "File:      {} ({} bytes)", self.file, self.file_bytes);
        match &self.read {
            ReadMode::Indexed => {
                let _ = writeln!(out, "Read mode: indexed (summary with chunk indexes)");
            }
            ReadMode::Linear { reason } => {
                let _ = writeln!(out, "Read mode: linear ({reason})");
            }
        }
        if let (Some(start), Some(end)) = (self.start_ns, self.end_ns) {
            let _ = writeln!(
                out,
                "Log time:  {} .. {} ({:.3} s)",
                format_log_time(start),
                format_log_time(end),
                self.duration_s.unwrap_or(0.0)
            );
        }
        let _ = writeln!(
            out,
            "Messages:  {}   attachments: {}   metadata: {}",
            self.messages.map_or("unknown".into(), |n| n.to_string()),
            self.attachments,
            self.metadata
        );
        let _ = writeln!(out, "\nChannels:");
        let _ = writeln!(
            out,
            "  {:>4}  {:<28} {:<34} {:<9} {:>9} {:>9}  role",
            "id", "topic", "schema", "encoding", "messages", "rate Hz"
        );
        for row in &self.channels {
            let role = row.role.map_or("-".to_string(), |r| {
                serde_json::to_value(r)
                    .ok()
                    .and_then(|v| v.as_str().map(str::to_string))
                    .unwrap_or_default()
            });
            let _ = writeln!(
                out,
                "  {:>4}  {:<28} {:<34} {:<9} {:>9} {:>9}  {}",
                row.info.id,
                row.info.topic,
                row.info.schema_name,
                row.info.message_encoding,
                row.info.message_count,
                row.rate_hz.map_or("-".into(), |r| format!("{r:.2}")),
                role
            );
        }
        let _ = writeln!(out, "\nDetected topics:");
        let list = |topics: &[String]| {
            if topics.is_empty() {
                "none".to_string()
            } else {
                topics.join(", ")
            }
        };
        let _ = writeln!(out, "  LiDAR:     {}", list(&self.detected.lidar));
        let _ = writeln!(out, "  IMU:       {}", list(&self.detected.imu));
        let _ = writeln!(out, "  velocity:  {}", list(&self.detected.velocity));
        let _ = writeln!(out, "  tf:        {}", list(&self.detected.tf));
        let _ = writeln!(out, "  tf_static: {}", list(&self.detected.tf_static));
        if let Some(problem) = &self.detected.problem {
            let _ = writeln!(out, "\n`looming process` needs a choice here:\n{problem}");
        }
        out
    }
}
