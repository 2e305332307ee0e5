//! Replaying a log into scan pairs on the calling thread, without writing
//! anything: what `eval`, benchmarks and tools need (`process` runs the same
//! stages on threads, see `pipeline`).

use crate::decode::{self, DecodeLimits};
use crate::input::{Flow, InputError, InputFile, InputMessage, InputOptions, InputRecord};
use crate::model::ScanPair;
use crate::pairing::{PairEvent, PairingConfig, ScanPairer};
use crate::topics::{Role, TopicError, TopicOverrides, select};
use std::path::Path;

#[derive(Debug, thiserror::Error)]
pub enum ReplayError {
    #[error(transparent)]
    Input(#[from] InputError),
    #[error("{path}: {source}")]
    Topic { path: String, source: TopicError },
}

/// Open `path` and [`replay_input`] it.
pub fn replay(
    path: &Path,
    on_message: &mut dyn FnMut(&InputMessage),
    on_pair: &mut dyn FnMut(ScanPair),
) -> Result<(), ReplayError> {
    replay_input(
        &InputFile::open(path, InputOptions::default())?,
        on_message,
        on_pair,
    )
}

/// Read an opened log in log-time order with auto-detected topics: every
/// message goes to `on_message` (before decoding), every scan pair to
/// `on_pair`. Messages that fail to decode are skipped.
pub fn replay_input(
    input: &InputFile,
    on_message: &mut dyn FnMut(&InputMessage),
    on_pair: &mut dyn FnMut(ScanPair),
) -> Result<(), ReplayError> {
    let path = input.path();
    let catalog = input.catalog().clone();
    let topics =
        select(&catalog, &TopicOverrides::default()).map_err(|source| ReplayError::Topic {
            path: path.display().to_string(),
            source,
        })?;
    let selected: std::collections::BTreeMap<u16, _> =
        topics.all().map(|c| (c.channel_id, c.clone())).collect();
    let mut pairer = ScanPairer::new(PairingConfig {
        has_velocity_source: topics.velocity.is_some(),
        has_imu_source: topics.imu.is_some(),
        ..PairingConfig::default()
    });
    pairer.set_nominal_period_s(catalog.nominal_period_s(topics.lidar.channel_id));
    let limits = DecodeLimits::default();
    let deliver = |events: Vec<PairEvent>, on_pair: &mut dyn FnMut(ScanPair)| {
        for event in events {
            if let PairEvent::Pair(pair) = event {
                on_pair(pair);
            }
        }
    };
    input.read_records(false, &mut |record| {
        let InputRecord::Message(message) = record else {
            return Flow::Continue(());
        };
        on_message(&message);
        let Some(channel) = selected.get(&message.channel_id) else {
            return Flow::Continue(());
        };
        let is_static = channel.role == Role::TfStatic;
        let Ok(decoded) = decode::decode(
            channel.kind,
            channel.encoding,
            is_static,
            &message.data,
            &limits,
        ) else {
            return Flow::Continue(());
        };
        let events = pairer.push_decoded(message.log_time_ns, decoded);
        deliver(events, on_pair);
        Flow::Continue(())
    })?;
    deliver(pairer.finish(), on_pair);
    Ok(())
}
