//! Every `/looming/*` topic name, in one place (the channels are documented
//! in `docs/channels.md`): the channels `process` writes, and the prefix that
//! tells them from the input's own channels.

/// Every topic of ours starts with this.
pub const OUR_TOPIC_PREFIX: &str = "/looming/";

pub const PAIRS_TOPIC: &str = "/looming/pairs";
pub const POINTS_TOPIC: &str = "/looming/points";
pub const DISAGREEMENT_TOPIC: &str = "/looming/disagreement";
pub const THREAT_TOPIC: &str = "/looming/threat";
pub const THREAT_ZONES_TOPIC: &str = "/looming/threat_zones";
pub const IMAGE_FUSED_TOPIC: &str = "/looming/image/fused";
pub const IMAGE_DISAGREEMENT_TOPIC: &str = "/looming/image/disagreement";
pub const EVENTS_TOPIC: &str = "/looming/events";
pub const LOG_TOPIC: &str = "/looming/log";
pub const NEAR_MISSES_TOPIC: &str = "/looming/near_misses";
pub const OBJECTS_TOPIC: &str = "/looming/objects";
pub const OBJECT_LIST_TOPIC: &str = "/looming/object_list";

/// A channel written by `looming process` (never an input of it).
pub fn is_ours(topic: &str) -> bool {
    topic.starts_with(OUR_TOPIC_PREFIX)
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn every_topic_is_ours() {
        for topic in [
            PAIRS_TOPIC,
            POINTS_TOPIC,
            DISAGREEMENT_TOPIC,
            THREAT_TOPIC,
            THREAT_ZONES_TOPIC,
            IMAGE_FUSED_TOPIC,
            IMAGE_DISAGREEMENT_TOPIC,
            EVENTS_TOPIC,
            LOG_TOPIC,
            NEAR_MISSES_TOPIC,
            OBJECTS_TOPIC,
            OBJECT_LIST_TOPIC,
        ] {
            assert!(is_ours(topic), "{topic}");
        }
        assert!(!is_ours("/sensing/lidar/points"));
        assert!(!is_ours("/truth/points"));
    }
}
