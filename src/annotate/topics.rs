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

/// The topic of `sensor`'s copy of our channel `topic`, on a log with
/// several LiDARs: `/looming/points` of sensor `lidar_left` is
/// `/looming/lidar_left/points` (docs/channels.md, "Several LiDARs").
pub fn sensor_topic(sensor: &str, topic: &str) -> String {
    let rest = topic.strip_prefix(OUR_TOPIC_PREFIX).unwrap_or(topic);
    format!("{OUR_TOPIC_PREFIX}{sensor}/{rest}")
}

/// The sensor of a pairs topic: `Some(None)` for `/looming/pairs` (a log
/// with one LiDAR), `Some(Some(sensor))` for `/looming/<sensor>/pairs`,
/// `None` for any other topic.
pub fn sensor_of_pairs_topic(topic: &str) -> Option<Option<String>> {
    if topic == PAIRS_TOPIC {
        return Some(None);
    }
    let sensor = topic
        .strip_prefix(OUR_TOPIC_PREFIX)?
        .strip_suffix("/pairs")?;
    (!sensor.is_empty() && !sensor.contains('/')).then(|| Some(sensor.to_owned()))
}

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
        assert_eq!(
            sensor_topic("lidar_left", POINTS_TOPIC),
            "/looming/lidar_left/points"
        );
        assert_eq!(
            sensor_topic("roof", IMAGE_FUSED_TOPIC),
            "/looming/roof/image/fused"
        );
        assert_eq!(sensor_of_pairs_topic(PAIRS_TOPIC), Some(None));
        assert_eq!(
            sensor_of_pairs_topic("/looming/roof/pairs"),
            Some(Some("roof".into()))
        );
        assert_eq!(sensor_of_pairs_topic("/looming/roof/points"), None);
        assert_eq!(sensor_of_pairs_topic("/looming/a/b/pairs"), None);
    }
}
