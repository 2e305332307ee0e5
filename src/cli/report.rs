//! What the commands print: the one-screen `process` summary, the
//! `synth` and `import-kitti` lines, and the progress bar.

use std::fmt::Write as _;
use std::io::IsTerminal;

use indicatif::{ProgressBar, ProgressDrawTarget, ProgressStyle};

use looming::commands::batch::{
    BatchLog, BatchOptions, BatchProgress, LogOutcome, LogRecord, LogStatus, RunAction,
};
use looming::input::ReadMode;
use looming::model::format_log_time;
use looming::output::WriteMode;
use looming::pipeline::{ProgressSink, RunSummary};

/// indicatif progress on stderr when it is a terminal, silent otherwise.
pub(crate) struct Progress {
    pub(crate) bar: ProgressBar,
}

impl Progress {
    pub(crate) fn new(quiet: bool) -> Self {
        let bar = if quiet || !std::io::stderr().is_terminal() {
            ProgressBar::hidden()
        } else {
            let bar = ProgressBar::with_draw_target(Some(0), ProgressDrawTarget::stderr());
            bar.set_style(
                ProgressStyle::with_template("{spinner} [{elapsed_precise}] {wide_bar} {pos}/{len} messages ({per_sec}, eta {eta})")
                    .expect("static template is valid"),
            );
            bar
        };
        Self { bar }
    }
}

impl ProgressSink for Progress {
    fn update(&self, done: u64, total: Option<u64>) {
        if let Some(total) = total {
            self.bar.set_length(total.max(done));
        }
        self.bar.set_position(done);
    }
}

/// How the output was written, for the summary.
fn write_line(s: &RunSummary) -> String {
    match &s.write {
        WriteMode::PassThrough => format!(
            "pass-through: {} input chunks copied as they are ({} decompressed to read the selected topics)",
            s.input_report.chunks_copied, s.input_report.chunks_decompressed
        ),
        WriteMode::Rewrite { reason } => format!("every message written anew ({reason})"),
    }
}

/// The one-screen summary of a `process` run.
pub(crate) fn summary_text(s: &RunSummary) -> String {
    let mut out = String::new();
    read_and_decode_lines(&mut out, s);
    layout_lines(&mut out, s);
    pairs_lines(&mut out, s);
    event_lines(&mut out, s);
    problem_lines(&mut out, s);
    size_line(&mut out, s);
    out
}

/// Input, output, how they were read and written, topics and decoded counts.
fn read_and_decode_lines(out: &mut String, s: &RunSummary) {
    let mode = match &s.read {
        ReadMode::Indexed => "indexed, log-time order".to_string(),
        ReadMode::Linear { reason } => format!("linear, file order with reorder window ({reason})"),
    };
    let _ = writeln!(
        out,
        "looming {}: {} -> {}",
        s.tool_version, s.input, s.output
    );
    let _ = writeln!(out, "  read          {mode}");
    let _ = writeln!(out, "  write         {}", write_line(s));
    let _ = writeln!(
        out,
        "  copied        {} messages, {} metadata, {} attachments",
        s.messages_copied, s.metadata_copied, s.attachments_copied
    );
    let topic = |c: &Option<looming::topics::SelectedChannel>| {
        c.as_ref().map_or("none".to_string(), |c| c.topic.clone())
    };
    let lidars = if s.sensors.is_empty() {
        topic(&s.topics.lidar)
    } else {
        let mut topics: Vec<&str> = s
            .sensors
            .iter()
            .map(|sensor| sensor.topic.as_str())
            .collect();
        // A merged topic's sensors share it: named once.
        topics.dedup();
        topics.join(", ")
    };
    let _ = writeln!(
        out,
        "  topics        lidar {}, imu {}, velocity {}, tf {}",
        lidars,
        topic(&s.topics.imu),
        topic(&s.topics.velocity),
        s.topics.tf.len()
    );
    let _ = writeln!(
        out,
        "  decoded       {} scans ({} points, {} invalid skipped), {} imu, {} velocity, {} tf",
        s.decoded.scans,
        s.decoded.lidar_points,
        s.decoded.invalid_points_skipped,
        s.decoded.imu,
        s.decoded.velocity,
        s.decoded.tf_messages
    );
}

/// How the LiDAR's rings and times were found; with several LiDARs, a
/// line per sensor instead.
fn layout_lines(out: &mut String, s: &RunSummary) {
    if !s.sensors.is_empty() {
        sensor_lines(out, s);
        return;
    }
    if let (Some(layout), Some(lidar)) = (&s.pairing.layout, &s.topics.lidar) {
        let _ = writeln!(out, "  layout        {}: {layout}", lidar.topic);
        if s.pairing.layout_kinds.len() > 1 {
            let kinds: Vec<String> = s
                .pairing
                .layout_kinds
                .iter()
                .map(|(kind, n)| format!("{kind} {n}"))
                .collect();
            let _ = writeln!(
                out,
                "                (varies by scan: {})",
                kinds.join(", ")
            );
        }
        if s.pairing.ring_fields_dropped > 0 {
            let _ = writeln!(
                out,
                "                ring field dropped in {} scans (values not ring numbers)",
                s.pairing.ring_fields_dropped
            );
        }
        if let Some(track) = &s.pairing.sensor_track {
            let _ = writeln!(out, "                {}", track_text(track));
        }
    }
}

/// The sensor placed from its rings at every scan, in a line: how many
/// scans, how well, at what cost.
fn track_text(track: &looming::pairing::SensorTrackStats) -> String {
    format!(
        "sensor placed from its rings at every scan: {} scans, {} by the local search ({:.1} ms per scan, max {:.1}), {} by the full search ({:.0} ms each), {} failed; ring spread mean {:.4} deg (max {:.4}); its turn from the sweeps' phase, held at {} steps",
        track.scans,
        track.scans - track.full_searches,
        track.local_ms_per_scan_mean,
        track.local_ms_per_scan_max,
        track.full_searches,
        track.full_search_ms_mean,
        track.failed,
        track.ring_spread_deg_mean,
        track.ring_spread_deg_max,
        track.yaw_held
    )
}

/// Each sensor of a log with several LiDARs: its channels, layout, pairs
/// and where it sits (the frame its events were merged in).
fn sensor_lines(out: &mut String, s: &RunSummary) {
    let _ = writeln!(
        out,
        "  sensors       {} LiDARs, each on /looming/<sensor>/..., one list of near misses",
        s.sensors.len()
    );
    for sensor in &s.sensors {
        let layout = sensor
            .pairing
            .layout
            .as_ref()
            .map_or("no layout".to_string(), ToString::to_string);
        let frame = sensor.vehicle_frame.as_ref().map_or_else(
            || "no transform to the vehicle: its events stand alone".to_string(),
            |frame| format!("events merged in frame {frame}"),
        );
        let topic = match &sensor.merged {
            Some(merged) => format!("{} {} {}", sensor.topic, merged.field, merged.id),
            None => sensor.topic.clone(),
        };
        let _ = writeln!(
            out,
            "    {:<14} {}: {layout}; {} pairs, {} annotated, engine {:.1} s; {frame}",
            sensor.name,
            topic,
            sensor.pairs_written,
            sensor.annotation.pairs_annotated,
            sensor.annotation.engine_s
        );
        if let Some(track) = &sensor.pairing.sensor_track {
            let _ = writeln!(out, "                   {}", track_text(track));
        }
    }
}

/// Pairs made and skipped, and what the engine did with them.
fn pairs_lines(out: &mut String, s: &RunSummary) {
    let p = &s.pairing;
    let _ = writeln!(
        out,
        "  pairs         {} written; skipped: {} dt<=0, {} gaps; {} without velocity, {} without imu",
        s.pairs_written,
        p.skipped_nonpositive_dt,
        p.skipped_gap,
        p.pairs_without_velocity,
        p.pairs_without_imu
    );
    let a = &s.annotation;
    let _ = writeln!(
        out,
        "  looming       {} pairs annotated ({} LiDAR-only, {} with the ego motion estimated from the scans, {} without a range image); {} points, {} moving, {} at threat; engine {:.1} s",
        a.pairs_annotated,
        a.pairs_lidar_only,
        a.pairs_motion_estimated,
        a.pairs_without_image,
        a.points_written,
        a.disagreement_points_written,
        a.threat_points_written,
        a.engine_s
    );
    if a.images_not_encoded > 0 {
        let _ = writeln!(
            out,
            "  warning       {} range images could not be encoded as PNG and were left out",
            a.images_not_encoded
        );
    }
}

/// The near misses, the first five in full.
fn event_lines(out: &mut String, s: &RunSummary) {
    let _ = writeln!(out, "  near misses   {}", s.events.len());
    for event in s.events.iter().take(5) {
        let _ = writeln!(
            out,
            "    {} at {}",
            looming::annotate::foxglove::event_summary(event),
            format_log_time(event.start_log_time_ns)
        );
    }
    if s.events.len() > 5 {
        let _ = writeln!(
            out,
            "    ... (all of them with `looming events` or --events)"
        );
    }
}

/// Replaced messages, bad messages and warnings.
fn problem_lines(out: &mut String, s: &RunSummary) {
    if s.replaced_messages > 0 {
        let _ = writeln!(
            out,
            "  replaced      {} messages of an earlier run's /looming/* channels",
            s.replaced_messages
        );
    }
    let _ = writeln!(out, "  bad messages  {}", s.bad_messages);
    for bad in s.bad_message_examples.iter().take(5) {
        let _ = writeln!(out, "    {bad}");
    }
    if s.bad_messages > 5 {
        let _ = writeln!(out, "    ... (all of them in --json-summary)");
    }
    for warning in &s.warnings {
        let _ = writeln!(out, "  warning       {warning}");
    }
}

/// Sizes, time and throughput.
fn size_line(out: &mut String, s: &RunSummary) {
    let mb = |b: u64| b as f64 / 1e6;
    let _ = writeln!(
        out,
        "  size          {:.1} MB -> {:.1} MB in {:.2} s ({:.1} MB/s)",
        mb(s.input_bytes),
        mb(s.output_bytes),
        s.elapsed_s,
        mb(s.input_bytes) / s.elapsed_s.max(1e-9)
    );
}

/// `looming batch`'s progress: a bar over the logs with an ETA, and a line
/// per log.
pub(crate) struct BatchBar {
    pub(crate) bar: ProgressBar,
    quiet: bool,
}

impl BatchBar {
    pub(crate) fn new(quiet: bool) -> Self {
        let bar = if quiet {
            ProgressBar::hidden()
        } else {
            let bar = ProgressBar::with_draw_target(Some(0), ProgressDrawTarget::stderr());
            bar.set_style(
                ProgressStyle::with_template(
                    "[{elapsed_precise}] {wide_bar} {pos}/{len} logs (eta {eta})",
                )
                .expect("static template is valid"),
            );
            bar
        };
        Self { bar, quiet }
    }
}

impl BatchProgress for BatchBar {
    fn start(&self, logs: usize) {
        self.bar.set_length(logs as u64);
    }

    fn done(&self, log: &BatchLog, outcome: &LogOutcome) {
        self.bar.inc(1);
        if self.quiet {
            return;
        }
        // Above the bar on a terminal; plain lines into a log file.
        if self.bar.is_hidden() {
            eprintln!("{}", batch_line(log, outcome));
        } else {
            self.bar.println(batch_line(log, outcome));
        }
    }
}

/// One log's line.
fn batch_line(log: &BatchLog, outcome: &LogOutcome) -> String {
    let entry = &outcome.record.entry;
    let what = match (outcome.action, entry.status) {
        (RunAction::UpToDate, _) => "up-to-date".to_owned(),
        (RunAction::Ran, LogStatus::Processed) => format!(
            "processed ({} scans, {} near misses) in {:.1} s",
            entry.scans, entry.events, entry.seconds
        ),
        (RunAction::Ran, LogStatus::Skipped) => "skipped".to_owned(),
        (RunAction::Ran, LogStatus::Failed) => "failed".to_owned(),
    };
    let reason = entry
        .reason
        .as_deref()
        .map_or(String::new(), |r| format!(": {r}"));
    format!("  {} {what}{reason}", log.relative.display())
}

/// `--merge-only` in a line.
pub(crate) fn merge_summary(records: &[LogRecord], out_dir: &std::path::Path) -> String {
    let near_misses: usize = records.iter().map(|r| r.near_misses.len()).sum();
    format!(
        "looming batch: fleet files of {} logs, {} near misses -> {}\n",
        records.len(),
        near_misses,
        out_dir.join("near_misses.csv").display()
    )
}

/// The batch in a few lines.
pub(crate) fn batch_summary(outcomes: &[LogOutcome], options: &BatchOptions) -> String {
    let out_dir = &options.out_dir;
    let count = |f: &dyn Fn(&LogOutcome) -> bool| outcomes.iter().filter(|o| f(o)).count();
    let ran = |status| count(&|o| o.action == RunAction::Ran && o.record.entry.status == status);
    let near_misses: usize = outcomes.iter().map(|o| o.record.near_misses.len()).sum();
    format!(
        "looming batch: {} logs: {} processed, {} up to date, {} skipped, {} failed; {} near misses -> {}\n",
        outcomes.len(),
        ran(LogStatus::Processed),
        count(&|o| o.action == RunAction::UpToDate),
        ran(LogStatus::Skipped),
        ran(LogStatus::Failed),
        near_misses,
        if options.shard.is_none() && options.only.is_empty() {
            out_dir.join("report.html").display().to_string()
        } else {
            format!(
                "{} (a part of the fleet: fleet files by `looming batch --merge-only {}` once every part is done)",
                out_dir.join("logs").display(),
                out_dir.display()
            )
        }
    )
}

/// The `clips` line of `process --clips`: how many, where, and each file.
pub(crate) fn clips_text(
    clips: &[looming::commands::clips::ClipFile],
    dir: &std::path::Path,
) -> String {
    let mut out = format!(
        "  clips         {} written to {}\n",
        clips.len(),
        dir.display()
    );
    for clip in clips {
        let _ = writeln!(
            out,
            "    near miss #{}: {} ({} messages, {} to {})",
            clip.event_id,
            clip.path.display(),
            clip.messages,
            format_log_time(clip.start_log_time_ns),
            format_log_time(clip.end_log_time_ns)
        );
    }
    out
}
