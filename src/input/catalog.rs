//! What an input file holds: schemas, channels and per-channel message counts.

use std::collections::BTreeMap;
use std::sync::Arc;

use mcap::{Channel, Schema};

/// One channel with what inspection and topic detection need.
#[derive(Debug, Clone, serde::Serialize)]
pub struct ChannelInfo {
    pub id: u16,
    pub topic: String,
    pub message_encoding: String,
    pub schema_id: u16,
    pub schema_name: String,
    pub schema_encoding: String,
    pub message_count: u64,
    /// Log time of the first / last message on this channel, when known (linear
    /// listing); the summary only gives them for the whole file.
    pub first_log_time_ns: Option<u64>,
    pub last_log_time_ns: Option<u64>,
}

/// Schemas, channels and counts of one file, in id order (deterministic).
#[derive(Debug, Clone, Default)]
pub struct Catalog {
    pub schemas: BTreeMap<u16, Arc<Schema<'static>>>,
    pub channels: BTreeMap<u16, Arc<Channel<'static>>>,
    pub message_counts: BTreeMap<u16, u64>,
    pub first_log_time_ns: BTreeMap<u16, u64>,
    pub last_log_time_ns: BTreeMap<u16, u64>,
    /// Whole-file log time span, when known.
    pub start_ns: Option<u64>,
    pub end_ns: Option<u64>,
    pub attachment_count: u64,
    pub metadata_count: u64,
    /// Total messages according to the file's statistics (indexed) or the listing.
    pub total_messages: Option<u64>,
    /// Why a linear listing stopped before the end of the file (a truncated
    /// file, a chunk that cannot be decompressed): what it lists is only
    /// what comes before.
    pub listing_stopped: Option<String>,
}

impl Catalog {
    /// Build from a summary section.
    pub fn from_summary(summary: &mcap::Summary) -> Self {
        let mut catalog = Catalog {
            schemas: summary
                .schemas
                .iter()
                .map(|(k, v)| (*k, v.clone()))
                .collect(),
            channels: summary
                .channels
                .iter()
                .map(|(k, v)| (*k, v.clone()))
                .collect(),
            attachment_count: summary.attachment_indexes.len() as u64,
            metadata_count: summary.metadata_indexes.len() as u64,
            ..Default::default()
        };
        if let Some(stats) = &summary.stats {
            catalog.message_counts = stats.channel_message_counts.clone();
            catalog.total_messages = Some(stats.message_count);
            if stats.message_count > 0 {
                catalog.start_ns = Some(stats.message_start_time);
                catalog.end_ns = Some(stats.message_end_time);
            }
        }
        catalog
    }

    /// Record one message seen during a linear listing.
    pub fn count_message(&mut self, channel_id: u16, log_time_ns: u64) {
        *self.message_counts.entry(channel_id).or_default() += 1;
        let first = self
            .first_log_time_ns
            .entry(channel_id)
            .or_insert(log_time_ns);
        *first = (*first).min(log_time_ns);
        let last = self
            .last_log_time_ns
            .entry(channel_id)
            .or_insert(log_time_ns);
        *last = (*last).max(log_time_ns);
        self.start_ns = Some(self.start_ns.map_or(log_time_ns, |s| s.min(log_time_ns)));
        self.end_ns = Some(self.end_ns.map_or(log_time_ns, |e| e.max(log_time_ns)));
        *self.total_messages.get_or_insert(0) += 1;
    }

    pub fn total_messages(&self) -> Option<u64> {
        self.total_messages
    }

    /// All channels with their schema names and counts, in id order.
    pub fn channel_infos(&self) -> Vec<ChannelInfo> {
        self.channels
            .values()
            .map(|channel| {
                let schema = channel.schema.as_ref();
                ChannelInfo {
                    id: channel.id,
                    topic: channel.topic.clone(),
                    message_encoding: channel.message_encoding.clone(),
                    schema_id: schema.map_or(0, |s| s.id),
                    schema_name: schema.map_or(String::new(), |s| s.name.clone()),
                    schema_encoding: schema.map_or(String::new(), |s| s.encoding.clone()),
                    message_count: self.message_counts.get(&channel.id).copied().unwrap_or(0),
                    first_log_time_ns: self.first_log_time_ns.get(&channel.id).copied(),
                    last_log_time_ns: self.last_log_time_ns.get(&channel.id).copied(),
                }
            })
            .collect()
    }

    /// Schema and channel ids used by the input; ours must avoid them.
    pub fn used_schema_ids(&self) -> impl Iterator<Item = u16> + '_ {
        self.schemas.keys().copied()
    }

    pub fn used_channel_ids(&self) -> impl Iterator<Item = u16> + '_ {
        self.channels.keys().copied()
    }

    /// Nominal period of a channel from its count and time span (seconds).
    pub fn nominal_period_s(&self, channel_id: u16) -> Option<f64> {
        let count = *self.message_counts.get(&channel_id)?;
        let first = self
            .first_log_time_ns
            .get(&channel_id)
            .copied()
            .or(self.start_ns)?;
        let last = self
            .last_log_time_ns
            .get(&channel_id)
            .copied()
            .or(self.end_ns)?;
        (count >= 2 && last > first).then(|| (last - first) as f64 * 1e-9 / (count - 1) as f64)
    }
}
