//! What the fleet report shows of a log with near misses: two pictures of
//! each event's peak pair (drawn by `render` from one replay of the log) and
//! the log's strongest approach in the path over time (read back from its
//! annotated output's `/looming/pairs`).

use std::path::{Path, PathBuf};

use crate::commands::quality::ScanLine;
use crate::commands::render::{
    Picture, RenderAt, RenderChannel, RenderError, RenderOptions, RenderView, render_pictures,
};
use crate::events::NearMissEvent;
use crate::pipeline::ProcessConfig;

use super::record::{EventPictures, PeakSeries};

/// Events of one log that get pictures, smallest time to contact first: the
/// report is read from the top, and a log with dozens of events is better
/// opened in a viewer.
pub const MAX_PICTURED_EVENTS: usize = 10;

/// Top view: metres from the sensor to the picture's edge, and its side in
/// pixels (a thumbnail that still shows a car at 40 m).
const TOP_EXTENT_M: f64 = 40.0;
const TOP_SIZE_PX: u32 = 480;
/// Range view: pixel rows per beam.
const RANGE_ROW_HEIGHT_PX: u32 = 3;

/// The folder of a log's pictures, relative to `OUT_DIR`.
pub(super) fn pictures_dir(relative: &Path) -> PathBuf {
    let mut dir = Path::new("logs").join(relative).into_os_string();
    dir.push(".pictures");
    PathBuf::from(dir)
}

/// Draw the pictures of `events` (already ranked) from `input` into
/// `OUT_DIR/<pictures_dir>` (which the caller has cleared of an earlier
/// run's).
pub(super) fn draw_event_pictures(
    config: &ProcessConfig,
    input: &Path,
    out_dir: &Path,
    relative: &Path,
    events: &[NearMissEvent],
    sensor_topics: &[(String, String)],
) -> Result<Vec<EventPictures>, RenderError> {
    let dir = pictures_dir(relative);
    let absolute_dir = out_dir.join(&dir);
    if events.is_empty() {
        return Ok(Vec::new());
    }
    std::fs::create_dir_all(&absolute_dir).map_err(|source| RenderError::Write {
        path: absolute_dir.clone(),
        source,
    })?;
    let pictured: Vec<EventPictures> = events
        .iter()
        .take(MAX_PICTURED_EVENTS)
        .map(|event| EventPictures {
            event_id: event.id,
            range_png: dir.join(format!("event-{}-range.png", event.id)),
            top_png: dir.join(format!("event-{}-top.png", event.id)),
        })
        .collect();
    // On a log with several LiDARs each near miss is drawn from the sensor
    // whose figures it gives (`NearMissEvent::sensor`).
    let mut by_topic: std::collections::BTreeMap<Option<&str>, Vec<Picture>> =
        std::collections::BTreeMap::new();
    for (event, paths) in events.iter().zip(&pictured) {
        let topic = event.sensor.as_deref().and_then(|name| {
            sensor_topics
                .iter()
                .find(|(sensor, _)| sensor == name)
                .map(|(_, topic)| topic.as_str())
        });
        by_topic
            .entry(topic)
            .or_default()
            .extend(requests_of(event, paths, out_dir));
    }
    for (topic, requests) in by_topic {
        let mut scans = config.scans.clone();
        if let Some(topic) = topic {
            scans.topics.lidar = Some(topic.to_owned());
        }
        let options = RenderOptions {
            input: input.to_path_buf(),
            row_height_px: RANGE_ROW_HEIGHT_PX,
            top_extent_m: TOP_EXTENT_M,
            top_size_px: TOP_SIZE_PX,
            force: true,
            scans,
            engine: config.annotate.engine.clone(),
            ..RenderOptions::default()
        };
        render_pictures(&options, &requests)?;
    }
    Ok(pictured)
}

/// The range image and the top view of an event's peak pair.
fn requests_of(event: &NearMissEvent, paths: &EventPictures, out_dir: &Path) -> [Picture; 2] {
    let at = RenderAt::LogTimeNs(event.peak.log_time_ns);
    [
        Picture {
            at,
            channel: RenderChannel::Fused,
            view: RenderView::Range,
            output: out_dir.join(&paths.range_png),
        },
        Picture {
            at,
            channel: RenderChannel::Threat,
            view: RenderView::Top,
            output: out_dir.join(&paths.top_png),
        },
    ]
}

/// Most points of a plotted series: an hour at 10 Hz is kept as the
/// largest value of each run of 18 pairs, so no peak is lost.
const MAX_SERIES_POINTS: usize = 2000;

/// The plot's series: each pair's path peak, seconds after the first pair,
/// rounded (1 ms, 0.001 1/s) so that the record stays small and stable; a
/// long log keeps the largest pair of each run of pairs.
pub(super) fn peak_series(scans: &[ScanLine], threshold_per_s: f64) -> Option<PeakSeries> {
    let start = scans.first()?.log_time_ns;
    let round = |v: f64, step: f64| (v / step).round() * step;
    let run = scans.len().div_ceil(MAX_SERIES_POINTS);
    let kept: Vec<&ScanLine> = scans
        .chunks(run)
        .filter_map(|chunk| {
            chunk.iter().max_by(|a, b| {
                let value = |s: &ScanLine| s.path_peak_looming_per_s.unwrap_or(f64::NEG_INFINITY);
                value(a).total_cmp(&value(b))
            })
        })
        .collect();
    Some(PeakSeries {
        start_log_time_ns: start,
        threshold_per_s,
        time_s: kept
            .iter()
            .map(|s| round(s.log_time_ns.saturating_sub(start) as f64 * 1e-9, 1e-3))
            .collect(),
        looming_per_s: kept
            .iter()
            .map(|s| s.path_peak_looming_per_s.map(|l| round(l, 1e-3)))
            .collect(),
    })
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn pictures_sit_beside_the_log_output() {
        assert_eq!(
            pictures_dir(Path::new("day1/cut-in.mcap")),
            Path::new("logs/day1/cut-in.mcap.pictures")
        );
    }
}
