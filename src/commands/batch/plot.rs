//! The report's plot of a log's strongest approach in the path over time,
//! as an inline SVG (no script, no network): the series, the event
//! threshold, and the spans of the log's near misses.

use std::fmt::Write;

use crate::events::NearMissEvent;

use super::record::PeakSeries;

const WIDTH_PX: f64 = 720.0;
const HEIGHT_PX: f64 = 180.0;
const LEFT_PX: f64 = 48.0;
const RIGHT_PX: f64 = 12.0;
const TOP_PX: f64 = 12.0;
const BOTTOM_PX: f64 = 28.0;
/// The y axis reaches at most this many thresholds: a spike does not flatten
/// the rest of the curve (points above are drawn at the top).
const MAX_THRESHOLDS_SHOWN: f64 = 4.0;

/// Where the plot area is and what it spans.
struct Frame {
    t_max_s: f64,
    l_max_per_s: f64,
}

impl Frame {
    fn x(&self, t_s: f64) -> f64 {
        LEFT_PX + (WIDTH_PX - LEFT_PX - RIGHT_PX) * (t_s / self.t_max_s).clamp(0.0, 1.0)
    }

    fn y(&self, looming_per_s: f64) -> f64 {
        let fraction = (looming_per_s / self.l_max_per_s).clamp(0.0, 1.0);
        HEIGHT_PX - BOTTOM_PX - (HEIGHT_PX - TOP_PX - BOTTOM_PX) * fraction
    }
}

/// The SVG of one log's series, with `events` (that log's) shaded.
pub(super) fn peak_plot(series: &PeakSeries, events: &[NearMissEvent]) -> String {
    let threshold = series.threshold_per_s;
    let highest = series
        .looming_per_s
        .iter()
        .flatten()
        .fold(0.0f64, |a, &b| a.max(b));
    let frame = Frame {
        t_max_s: series.time_s.last().copied().unwrap_or(0.0).max(0.1),
        l_max_per_s: (1.25 * highest)
            .max(1.5 * threshold)
            .min(MAX_THRESHOLDS_SHOWN * threshold),
    };
    let mut svg = format!(
        "<svg xmlns=\"http://www.w3.org/2000/svg\" width=\"{WIDTH_PX}\" height=\"{HEIGHT_PX}\" \
         viewBox=\"0 0 {WIDTH_PX} {HEIGHT_PX}\" role=\"img\" class=\"plot\">"
    );
    draw_event_spans(&mut svg, &frame, series, events);
    draw_axes(&mut svg, &frame, threshold);
    draw_series(&mut svg, &frame, series);
    svg.push_str("</svg>");
    svg
}

fn draw_event_spans(
    svg: &mut String,
    frame: &Frame,
    series: &PeakSeries,
    events: &[NearMissEvent],
) {
    let seconds = |ns: u64| ns.saturating_sub(series.start_log_time_ns) as f64 * 1e-9;
    for event in events {
        let x0 = frame.x(seconds(event.start_log_time_ns));
        // The last hot scan's sweep ends a period later: at least 2 px wide.
        let x1 = frame.x(seconds(event.end_log_time_ns)).max(x0 + 2.0);
        let _ = write!(
            svg,
            "<rect x=\"{x0:.1}\" y=\"{TOP_PX}\" width=\"{:.1}\" height=\"{:.1}\" fill=\"#f6c7c7\"/>\
             <text x=\"{x0:.1}\" y=\"{:.1}\" font-size=\"10\" fill=\"#a00\">#{}</text>",
            x1 - x0,
            HEIGHT_PX - TOP_PX - BOTTOM_PX,
            TOP_PX + 10.0,
            event.id
        );
    }
}

fn draw_axes(svg: &mut String, frame: &Frame, threshold_per_s: f64) {
    let (x0, x1) = (frame.x(0.0), frame.x(frame.t_max_s));
    let (y0, y1) = (frame.y(0.0), frame.y(frame.l_max_per_s));
    let _ = write!(
        svg,
        "<path d=\"M{x0:.1},{y1:.1}V{y0:.1}H{x1:.1}\" stroke=\"#444\" fill=\"none\"/>"
    );
    let yt = frame.y(threshold_per_s);
    let _ = write!(
        svg,
        "<line x1=\"{x0:.1}\" y1=\"{yt:.1}\" x2=\"{x1:.1}\" y2=\"{yt:.1}\" stroke=\"#c00\" stroke-dasharray=\"4 3\"/>\
         <text x=\"{:.1}\" y=\"{:.1}\" font-size=\"10\" fill=\"#c00\" text-anchor=\"end\">threshold, TTC {:.1} s</text>",
        x1,
        yt - 3.0,
        1.0 / threshold_per_s
    );
    for value in [0.0, threshold_per_s, frame.l_max_per_s] {
        let _ = write!(
            svg,
            "<text x=\"{:.1}\" y=\"{:.1}\" font-size=\"10\" text-anchor=\"end\">{value:.2}</text>",
            x0 - 4.0,
            frame.y(value) + 3.0
        );
    }
    let step = tick_step_s(frame.t_max_s);
    let decimals = if step >= 1.0 { 0 } else { 2 };
    let ticks = (frame.t_max_s / step + 1e-9).floor() as u64;
    for i in 0..=ticks {
        let t = i as f64 * step;
        let _ = write!(
            svg,
            "<text x=\"{:.1}\" y=\"{:.1}\" font-size=\"10\" text-anchor=\"middle\">{t:.decimals$}</text>",
            frame.x(t),
            y0 + 12.0
        );
    }
    let _ = write!(
        svg,
        "<text x=\"{:.1}\" y=\"{:.1}\" font-size=\"10\" text-anchor=\"middle\">time after the first pair, s</text>\
         <text x=\"10\" y=\"{:.1}\" font-size=\"10\" transform=\"rotate(-90 10 {:.1})\" text-anchor=\"middle\">looming, 1/s</text>",
        (x0 + x1) / 2.0,
        HEIGHT_PX - 2.0,
        (y0 + y1) / 2.0,
        (y0 + y1) / 2.0
    );
}

/// About six ticks: 1, 2 or 5 times a power of ten.
fn tick_step_s(span_s: f64) -> f64 {
    let raw = (span_s / 6.0).max(1e-3);
    let power = 10f64.powf(raw.log10().floor());
    [1.0, 2.0, 5.0, 10.0]
        .into_iter()
        .map(|m| m * power)
        .find(|&step| step >= raw)
        .unwrap_or(10.0 * power)
}

/// The series as polylines, broken where a pair had nothing approaching.
fn draw_series(svg: &mut String, frame: &Frame, series: &PeakSeries) {
    let mut runs: Vec<Vec<(f64, f64)>> = vec![Vec::new()];
    for (&t, value) in series.time_s.iter().zip(&series.looming_per_s) {
        match value {
            Some(l) => runs
                .last_mut()
                .expect("never empty")
                .push((frame.x(t), frame.y(*l))),
            None if runs.last().is_some_and(|r| !r.is_empty()) => runs.push(Vec::new()),
            None => {}
        }
    }
    for run in runs.iter().filter(|r| !r.is_empty()) {
        if let [(x, y)] = run.as_slice() {
            let _ = write!(
                svg,
                "<circle cx=\"{x:.1}\" cy=\"{y:.1}\" r=\"1.5\" fill=\"#036\"/>"
            );
            continue;
        }
        let points: Vec<String> = run.iter().map(|(x, y)| format!("{x:.1},{y:.1}")).collect();
        let _ = write!(
            svg,
            "<polyline points=\"{}\" fill=\"none\" stroke=\"#036\" stroke-width=\"1.5\"/>",
            points.join(" ")
        );
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn ticks_are_round() {
        assert_eq!(tick_step_s(10.0), 2.0);
        assert_eq!(tick_step_s(60.0), 10.0);
        assert_eq!(tick_step_s(3000.0), 500.0);
    }

    #[test]
    fn a_gap_breaks_the_line_and_spikes_stay_in_the_frame() {
        let series = PeakSeries {
            start_log_time_ns: 0,
            threshold_per_s: 1.0,
            time_s: vec![0.0, 0.1, 0.2, 0.3, 0.4],
            looming_per_s: vec![Some(0.2), Some(0.4), None, Some(50.0), Some(0.5)],
        };
        let svg = peak_plot(&series, &[]);
        assert_eq!(svg.matches("<polyline").count(), 2);
        // The spike is drawn at the top of the plot (4 thresholds).
        assert!(svg.contains(&format!("{:.1}", TOP_PX)));
        assert!(svg.contains(">4.00<"));
    }
}
