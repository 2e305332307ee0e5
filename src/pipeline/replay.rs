//! Replaying a log into scan pairs on the calling thread, without writing
//! anything: what `eval`, `render`, benchmarks and tools need. It decodes and
//! pairs with the very code `process` runs on its threads (`pipeline::scans`),
//! with the same [`ScanOptions`], so all of them see the same pairs and count
//! the same bad messages.

use std::path::Path;

use crate::input::{Flow, InputError, InputFile, InputMessage, InputRecord, ReadReport};
use crate::model::ScanPair;
use crate::pairing::PairingStats;
use crate::topics::{TopicError, select};

use super::scans::{
    BadMessages, DecodedCounts, Decoder, PairingStage, ReadFailure, ScanOptions, finish_read,
};

#[derive(Debug, thiserror::Error)]
pub enum ReplayError {
    #[error(transparent)]
    Input(#[from] InputError),
    #[error("{path}: {source}")]
    Topic { path: String, source: TopicError },
    /// `strict` and the input had a bad message or was truncated.
    #[error("{0}")]
    Strict(String),
}

/// What a replay read, decoded and paired.
#[derive(Debug, Clone, Default)]
pub struct ReplayReport {
    pub decoded: DecodedCounts,
    pub pairs: u64,
    pub pairing: PairingStats,
    pub bad_messages: BadMessages,
    pub warnings: Vec<String>,
    pub read: ReadReport,
}

/// Open `path` with `options.input_options` and [`replay_input`] it.
pub fn replay(
    path: &Path,
    options: &ScanOptions,
    on_message: &mut dyn FnMut(&InputMessage),
    on_pair: &mut dyn FnMut(ScanPair),
) -> Result<ReplayReport, ReplayError> {
    let input = InputFile::open(path, options.input_options.clone())?;
    replay_input(&input, options, on_message, on_pair)
}

/// Read an opened log in log-time order: every message goes to `on_message`
/// (before decoding), every scan pair to `on_pair`. Messages that fail to
/// decode are skipped and counted (with `options.strict`, the first one ends
/// the replay with an error).
pub fn replay_input(
    input: &InputFile,
    options: &ScanOptions,
    on_message: &mut dyn FnMut(&InputMessage),
    on_pair: &mut dyn FnMut(ScanPair),
) -> Result<ReplayReport, ReplayError> {
    let path = input.path().display().to_string();
    let topics = select(input.catalog(), &options.topics).map_err(|source| ReplayError::Topic {
        path: path.clone(),
        source,
    })?;
    let decoder = Decoder::new(options, std::slice::from_ref(&topics), &path);
    let mut stage = PairingStage::new(options, input.catalog(), &topics);
    let mut pairs = 0u64;
    let mut strict_failure = None;
    let read = input.read_records(options.strict, &mut |record| {
        let InputRecord::Message(message) = record else {
            return Flow::Continue(());
        };
        on_message(&message);
        let decoded = decoder.decode(message.channel_id, message.log_time_ns, &message.data);
        match decoded {
            None => {}
            Some(Ok((log_time_ns, _, decoded))) => {
                for pair in stage.push(log_time_ns, decoded) {
                    pairs += 1;
                    on_pair(pair);
                }
            }
            Some(Err(bad)) if options.strict => {
                strict_failure = Some(bad);
                return Flow::Break(());
            }
            Some(Err(bad)) => stage.bad.add(bad),
        }
        Flow::Continue(())
    });
    let read =
        finish_read(options.strict, &path, strict_failure, read).map_err(
            |failure| match failure {
                ReadFailure::Input(error) => error.into(),
                ReadFailure::Strict(reason) => ReplayError::Strict(reason),
            },
        )?;
    for pair in stage.finish() {
        pairs += 1;
        on_pair(pair);
    }
    Ok(ReplayReport {
        pairing: stage.stats().clone(),
        decoded: stage.decoded,
        pairs,
        bad_messages: stage.bad,
        warnings: stage.warnings,
        read,
    })
}
