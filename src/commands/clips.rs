//! Near-miss clips: for each near miss of an annotated log, a small MCAP of
//! every channel from some seconds before its start to some seconds after its
//! end, so that a fleet engineer opens the moment, not a 20-minute log.
//!
//! One read of the annotated log, in log-time order, serves every clip of it
//! and stops after the last one ends. A clip holds every schema and channel
//! of the log, its metadata records (the run record among them), and each
//! message whose log time falls in its window. A latched channel
//! (`/tf_static`, or a channel recorded with `transient_local` durability or
//! `latching: 1`) publishes once, usually at the start of the log, often as
//! several messages (one per static broadcaster): its messages before the
//! window (the last [`MAX_LATCHED_PER_CHANNEL`]) are written again at the
//! window's start, so that a viewer has every transform; those copies are
//! the only records whose log time differs from the log's.

use std::collections::BTreeMap;
use std::ops::ControlFlow;
use std::path::{Path, PathBuf};

use crate::events::NearMissEvent;
use crate::input::{InputError, InputFile, InputMessage, InputOptions, InputRecord};
use crate::output::{OutputError, OutputOptions, OutputWriter};

#[derive(Debug, thiserror::Error)]
pub enum ClipError {
    #[error(transparent)]
    Input(#[from] InputError),
    #[error(transparent)]
    Output(#[from] OutputError),
}

/// Messages of one latched channel carried into a clip, at most (the newest):
/// a log that publishes a "latched" channel continuously must not grow the
/// cutter's memory.
const MAX_LATCHED_PER_CHANNEL: usize = 64;

/// One clip written.
#[derive(Debug, Clone, PartialEq, Eq, serde::Serialize, serde::Deserialize)]
pub struct ClipFile {
    pub event_id: u32,
    pub path: PathBuf,
    /// The window, log time, ns.
    pub start_log_time_ns: u64,
    pub end_log_time_ns: u64,
    pub messages: u64,
}

/// The file name of event `event_id`'s clip of a log named `stem`.
pub fn clip_name(stem: &str, event_id: u32) -> String {
    format!("{stem}.event-{event_id}.mcap")
}

/// A clip being written.
struct OpenClip {
    writer: OutputWriter,
    file: ClipFile,
}

/// Write a clip of `annotated` for each of `events` into `dir`, named
/// [`clip_name`]`(stem, id)`, each `margin_s` seconds beyond its event.
/// `force` replaces existing clips.
pub fn write_clips(
    annotated: &Path,
    events: &[NearMissEvent],
    dir: &Path,
    stem: &str,
    margin_s: f64,
    force: bool,
) -> Result<Vec<ClipFile>, ClipError> {
    if events.is_empty() {
        return Ok(Vec::new());
    }
    let margin_ns = (margin_s.max(0.0) * 1e9).round() as u64;
    let mut pending: Vec<ClipFile> = events
        .iter()
        .map(|event| ClipFile {
            event_id: event.id,
            path: dir.join(clip_name(stem, event.id)),
            start_log_time_ns: event.start_log_time_ns.saturating_sub(margin_ns),
            end_log_time_ns: event.end_log_time_ns.saturating_add(margin_ns),
            messages: 0,
        })
        .collect();
    // Refused before any work when a clip exists (the writers create the
    // folder).
    for clip in &pending {
        crate::output::check_overwrite(&clip.path, force)?;
    }
    // Opened in order of their start.
    pending.sort_by_key(|clip| (clip.start_log_time_ns, clip.event_id));
    pending.reverse();
    let input = InputFile::open(annotated, InputOptions::default())?;
    let mut cutter = Cutter {
        input: &input,
        options: OutputOptions {
            force,
            ..OutputOptions::default()
        },
        pending,
        open: Vec::new(),
        done: Vec::new(),
        metadata: Vec::new(),
        latched: BTreeMap::new(),
        latched_channels: latched_channels(&input),
        failure: None,
    };
    let read = input.read_records(false, &mut |record| cutter.take(record));
    if let Some(error) = cutter.failure.take() {
        return Err(error);
    }
    match read {
        Ok(_) | Err(InputError::Stopped) => {}
        Err(error) => return Err(error.into()),
    }
    cutter.finish_all()?;
    let mut done = cutter.done;
    done.sort_by_key(|clip| clip.event_id);
    Ok(done)
}

/// Channels whose last message before a window is carried into the clip.
fn latched_channels(input: &InputFile) -> Vec<u16> {
    input
        .catalog()
        .channels
        .values()
        .filter(|channel| {
            channel.topic == "/tf_static"
                || channel.metadata.get("latching").is_some_and(|v| v == "1")
                || channel
                    .metadata
                    .get("offered_qos_profiles")
                    .is_some_and(|qos| qos.contains("transient_local"))
        })
        .map(|channel| channel.id)
        .collect()
}

/// The state of the one pass over the log.
struct Cutter<'a> {
    input: &'a InputFile,
    options: OutputOptions,
    /// Clips not yet opened, the next to open last.
    pending: Vec<ClipFile>,
    open: Vec<OpenClip>,
    done: Vec<ClipFile>,
    metadata: Vec<mcap::records::Metadata>,
    /// The messages of each latched channel so far (the newest
    /// [`MAX_LATCHED_PER_CHANNEL`]).
    latched: BTreeMap<u16, std::collections::VecDeque<InputMessage>>,
    latched_channels: Vec<u16>,
    failure: Option<ClipError>,
}

impl Cutter<'_> {
    fn take(&mut self, record: InputRecord) -> ControlFlow<()> {
        match self.step(record) {
            Ok(flow) => flow,
            Err(error) => {
                self.failure = Some(error);
                ControlFlow::Break(())
            }
        }
    }

    fn step(&mut self, record: InputRecord) -> Result<ControlFlow<()>, ClipError> {
        let message = match record {
            InputRecord::Message(message) => message,
            InputRecord::Metadata(metadata) => {
                self.metadata.push(metadata);
                return Ok(ControlFlow::Continue(()));
            }
            InputRecord::Attachment(_) => return Ok(ControlFlow::Continue(())),
        };
        let t = message.log_time_ns;
        self.close_ended(t)?;
        while self
            .pending
            .last()
            .is_some_and(|c| c.start_log_time_ns <= t)
        {
            let clip = self.pending.pop().expect("checked above");
            self.open(clip)?;
        }
        for clip in &mut self.open {
            if t <= clip.file.end_log_time_ns {
                clip.writer.write_input_message(&message)?;
                clip.file.messages += 1;
            }
        }
        if self.latched_channels.contains(&message.channel_id) {
            let kept = self.latched.entry(message.channel_id).or_default();
            if kept.len() == MAX_LATCHED_PER_CHANNEL {
                kept.pop_front();
            }
            kept.push_back(message);
        }
        let all_started = self.pending.is_empty();
        Ok(if all_started && self.open.is_empty() {
            ControlFlow::Break(())
        } else {
            ControlFlow::Continue(())
        })
    }

    fn open(&mut self, file: ClipFile) -> Result<(), ClipError> {
        let mut writer = OutputWriter::create(&file.path, &self.options, self.input.catalog())?;
        for metadata in &self.metadata {
            writer.write_metadata(metadata)?;
        }
        let mut clip = OpenClip { writer, file };
        for message in self.latched.values().flatten() {
            let mut carried = message.clone();
            carried.log_time_ns = clip.file.start_log_time_ns;
            carried.publish_time_ns = clip.file.start_log_time_ns;
            clip.writer.write_input_message(&carried)?;
            clip.file.messages += 1;
        }
        self.open.push(clip);
        Ok(())
    }

    /// Finish the clips whose window ended before `t`.
    fn close_ended(&mut self, t: u64) -> Result<(), ClipError> {
        let (ended, open): (Vec<OpenClip>, Vec<OpenClip>) = std::mem::take(&mut self.open)
            .into_iter()
            .partition(|clip| clip.file.end_log_time_ns < t);
        self.open = open;
        for clip in ended {
            clip.writer.finish()?;
            self.done.push(clip.file);
        }
        Ok(())
    }

    /// The end of the log: every clip still open or never opened (a window
    /// beyond the last message) is finished.
    fn finish_all(&mut self) -> Result<(), ClipError> {
        while let Some(clip) = self.pending.pop() {
            self.open(clip)?;
        }
        for clip in std::mem::take(&mut self.open) {
            clip.writer.finish()?;
            self.done.push(clip.file);
        }
        Ok(())
    }
}
