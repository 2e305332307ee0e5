//! `report.html`: the page a safety engineer opens from `OUT_DIR`. One
//! static file (inline style and plots, pictures as PNG files beside it
//! under `logs/`), so it needs no network and no server; rebuilt from the
//! records like the other fleet files, so it holds no clock time and is the
//! same bytes when nothing changed.

use std::fmt::Write;
use std::path::Path;

use crate::events::NearMissEvent;

use super::fleet::FleetNearMiss;
use super::plot::peak_plot;
use super::record::{LogRecord, LogStatus};

const STYLE: &str = "body{font:14px/1.4 system-ui,sans-serif;margin:24px;color:#222}\
table{border-collapse:collapse;margin:8px 0 24px}\
th,td{border:1px solid #ccc;padding:4px 8px;text-align:left;vertical-align:top}\
th{background:#f0f0f0}td.n{text-align:right;font-variant-numeric:tabular-nums}\
img{display:block;border:1px solid #999;image-rendering:pixelated}img.range{max-width:520px;margin-bottom:4px}img.top{width:260px}\
.failed{color:#b00}.skipped{color:#777}.moving{color:#b00;font-weight:600}\
code{font-size:12px}";

/// After loading, the page counts its pictures that did not load (a test
/// reads the count from the DOM; a reader sees nothing of it).
const IMAGE_CHECK: &str = "<script>window.addEventListener('load',function(){\
var imgs=document.images,broken=0;for(var i=0;i<imgs.length;i++){\
if(!imgs[i].complete||imgs[i].naturalWidth===0)broken++;}\
document.body.setAttribute('data-images',imgs.length);\
document.body.setAttribute('data-broken-images',broken);});</script>";

/// The whole page.
pub(super) fn report_html(records: &[LogRecord], near_misses: &[FleetNearMiss]) -> String {
    let mut html = format!(
        "<!DOCTYPE html>\n<html lang=\"en\"><head><meta charset=\"utf-8\">\
         <title>looming fleet report</title><style>{STYLE}</style></head><body>\n"
    );
    write_overview(&mut html, records, near_misses);
    write_near_misses(&mut html, records, near_misses);
    write_plots(&mut html, records);
    write_logs(&mut html, records);
    html.push_str(IMAGE_CHECK);
    html.push_str("\n</body></html>\n");
    html
}

fn write_overview(html: &mut String, records: &[LogRecord], near_misses: &[FleetNearMiss]) {
    let count = |status| records.iter().filter(|r| r.entry.status == status).count();
    let _ = writeln!(
        html,
        "<h1>Near misses in {} logs</h1><p>{} processed, {} skipped, {} failed; \
         <b>{} near misses</b>, ranked by minimum time to contact (TTC). \
         Looming is the inverse of the time to contact (<code>L = -(dr/dt)/r</code>), \
         taken along the LiDAR's rays. Tables: <code>fleet.json</code>, \
         <code>near_misses.csv</code>, <code>near_misses.jsonl</code>.</p>",
        records.len(),
        count(LogStatus::Processed),
        count(LogStatus::Skipped),
        count(LogStatus::Failed),
        near_misses.len()
    );
}

fn write_near_misses(html: &mut String, records: &[LogRecord], near_misses: &[FleetNearMiss]) {
    html.push_str("<h2>Near misses</h2>\n");
    if near_misses.is_empty() {
        html.push_str("<p>None.</p>\n");
        return;
    }
    html.push_str(
        "<table><tr><th>rank</th><th>TTC, s</th><th>looming, 1/s</th><th>range, m</th>\
         <th>bearing</th><th>ego speed, m/s</th><th>object</th><th>log and time</th>\
         <th>range image of the fused looming at the peak (rows: beams, forward at the \
         centre) and top view by threat level (forward up, rings: threat zones)</th></tr>\n",
    );
    for n in near_misses {
        let _ = writeln!(
            html,
            "<tr id=\"near-miss-{}\"><td class=\"n\">{}</td><td class=\"n\"><b>{:.2}</b></td>\
             <td class=\"n\">{:.2}</td><td class=\"n\">{:.1}</td><td>{}</td><td class=\"n\">{}</td>\
             <td>{}</td><td>{}<br>event #{}, {}{}</td><td>{}{}</td></tr>",
            n.rank,
            n.rank,
            n.min_time_to_contact_s,
            n.peak_looming_per_s,
            n.range_m,
            bearing(n.bearing_deg),
            n.ego_speed_mps
                .map_or("-".to_owned(), |v| format!("{v:.1}")),
            object_cell(n),
            escape(&n.log.display().to_string()),
            n.event_id,
            when(records, n),
            clip_link(n.clip.as_deref()),
            picture(n.range_picture.as_deref(), "range image"),
            picture(n.top_picture.as_deref(), "top view"),
        );
    }
    html.push_str("</table>\n");
}

/// The object column: its track id, whether it moved on its own, and how
/// far it was from the swept path.
fn object_cell(near_miss: &FleetNearMiss) -> String {
    let motion = if near_miss.moving {
        "<span class=\"moving\">moving</span>"
    } else {
        "static"
    };
    let id = near_miss
        .object_id
        .map_or(String::new(), |id| format!("#{id} "));
    format!(
        "{id}{motion}<br>{:.1} m from the path",
        near_miss.lateral_offset_m
    )
}

/// When a near miss happened: seconds into its log (after its first pair,
/// as the plot counts them) and its log times, for a viewer's clock.
fn when(records: &[LogRecord], near_miss: &FleetNearMiss) -> String {
    let start = records
        .iter()
        .find(|r| r.entry.input == near_miss.log)
        .and_then(|r| r.peak_series.as_ref())
        .map(|s| s.start_log_time_ns);
    let log_times = format!(
        "log time {:.3} s to {:.3} s",
        near_miss.start_log_time_ns as f64 * 1e-9,
        near_miss.end_log_time_ns as f64 * 1e-9
    );
    match start {
        Some(start) => format!(
            "{:.1} s into the log, {:.1} s long<br><small>{log_times}</small>",
            near_miss.start_log_time_ns.saturating_sub(start) as f64 * 1e-9,
            near_miss.duration_s
        ),
        None => format!(
            "{:.1} s long<br><small>{log_times}</small>",
            near_miss.duration_s
        ),
    }
}

fn bearing(azimuth_deg: f64) -> String {
    match azimuth_deg {
        a if a > 2.0 => format!("{a:.0}&deg; left"),
        a if a < -2.0 => format!("{:.0}&deg; right", -a),
        _ => "ahead".to_owned(),
    }
}

/// A link to the near miss's clip (open it in Foxglove or Lichtblick).
fn clip_link(path: Option<&Path>) -> String {
    path.map_or(String::new(), |path| {
        format!(
            "<br><a class=\"clip\" href=\"{}\" download>clip (MCAP)</a>",
            escape(&url_path(path))
        )
    })
}

/// An image linking to itself at full size (paths relative to the page).
fn picture(path: Option<&Path>, what: &str) -> String {
    let Some(path) = path else {
        return String::new();
    };
    let href = escape(&url_path(path));
    let class = if what == "top view" { "top" } else { "range" };
    format!(
        "<a href=\"{href}\"><img class=\"{class}\" src=\"{href}\" alt=\"{what}\" loading=\"lazy\"></a>"
    )
}

/// A relative path as a URL path: `/` separators, each part percent-encoded
/// where a URL needs it.
fn url_path(path: &Path) -> String {
    path.components()
        .map(|part| {
            part.as_os_str()
                .to_string_lossy()
                .bytes()
                .map(|b| match b {
                    b'A'..=b'Z' | b'a'..=b'z' | b'0'..=b'9' | b'-' | b'_' | b'.' | b'~' => {
                        (b as char).to_string()
                    }
                    _ => format!("%{b:02X}"),
                })
                .collect::<String>()
        })
        .collect::<Vec<_>>()
        .join("/")
}

fn write_plots(html: &mut String, records: &[LogRecord]) {
    let with_events: Vec<&LogRecord> = records
        .iter()
        .filter(|r| !r.near_misses.is_empty())
        .collect();
    if with_events.is_empty() {
        return;
    }
    html.push_str(
        "<h2>Peak looming over time</h2><p>For each log with near misses: the looming of \
         the strongest approach in the ego path in each scan pair (the median of the \
         strongest cluster of cells facing the sensor, in the path; no line where nothing \
         approached at a TTC under 10 s), with the event threshold and the near misses \
         shaded.</p>\n",
    );
    for record in with_events {
        let _ = write!(
            html,
            "<h3>{}</h3>",
            escape(&record.entry.input.display().to_string())
        );
        match &record.peak_series {
            Some(series) => html.push_str(&peak_plot(series, &ranked_by_id(&record.near_misses))),
            None => html.push_str("<p>No series (the annotated log could not be read back).</p>"),
        }
        html.push('\n');
    }
}

fn ranked_by_id(events: &[NearMissEvent]) -> Vec<NearMissEvent> {
    let mut events = events.to_vec();
    events.sort_by_key(|e| e.id);
    events
}

fn write_logs(html: &mut String, records: &[LogRecord]) {
    html.push_str(
        "<h2>Logs</h2>\n<table><tr><th>log</th><th>status</th><th>reason</th><th>scans</th>\
         <th>pairs</th><th>near misses</th><th>trusted</th><th>ground |looming| median / p90, \
         1/s</th><th>diagnoses</th><th>seconds</th></tr>\n",
    );
    for record in records {
        let entry = &record.entry;
        let (status, class) = match entry.status {
            LogStatus::Processed => ("processed", ""),
            LogStatus::Skipped => ("skipped", "skipped"),
            LogStatus::Failed => ("failed", "failed"),
        };
        let quality = entry.quality.as_ref();
        let figure = |v: Option<f64>, f: &dyn Fn(f64) -> String| v.map_or("-".to_owned(), f);
        let _ = writeln!(
            html,
            "<tr><td>{}</td><td class=\"{class}\">{status}</td><td>{}</td><td class=\"n\">{}</td>\
             <td class=\"n\">{}</td><td class=\"n\">{}</td><td class=\"n\">{}</td>\
             <td class=\"n\">{} / {}</td><td>{}</td><td class=\"n\">{:.2}</td></tr>",
            escape(&entry.input.display().to_string()),
            escape(entry.reason.as_deref().unwrap_or("")),
            entry.scans,
            entry.pairs,
            entry.events,
            figure(quality.and_then(|q| q.trusted_fraction), &|v| format!(
                "{:.1} %",
                100.0 * v
            )),
            figure(
                quality.and_then(|q| q.ground_median_abs_fused_per_s),
                &|v| { format!("{v:.3}") }
            ),
            figure(quality.and_then(|q| q.ground_p90_abs_fused_per_s), &|v| {
                format!("{v:.3}")
            }),
            escape(&quality.map_or(String::new(), |q| q.diagnoses.join(", "))),
            entry.seconds,
        );
    }
    html.push_str("</table>\n");
}

/// Text as HTML.
fn escape(text: &str) -> String {
    let mut out = String::with_capacity(text.len());
    for c in text.chars() {
        match c {
            '&' => out.push_str("&amp;"),
            '<' => out.push_str("&lt;"),
            '>' => out.push_str("&gt;"),
            '"' => out.push_str("&quot;"),
            '\'' => out.push_str("&#39;"),
            _ => out.push(c),
        }
    }
    out
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn text_and_paths_cannot_break_the_page() {
        assert_eq!(
            escape("<a href=\"x\">&'"),
            "&lt;a href=&quot;x&quot;&gt;&amp;&#39;"
        );
        assert_eq!(
            url_path(Path::new("logs/day 1/a#b.mcap.pictures/event-1-top.png")),
            "logs/day%201/a%23b.mcap.pictures/event-1-top.png"
        );
    }

    #[test]
    fn an_empty_fleet_is_a_page_too() {
        let html = report_html(&[], &[]);
        assert!(html.contains("Near misses in 0 logs"));
        assert!(html.contains("<p>None.</p>"));
        assert!(html.ends_with("</html>\n"));
    }
}
