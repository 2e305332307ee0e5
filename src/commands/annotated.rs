//! Reading back the JSON channels `process` wrote (`/looming/events`,
//! `/looming/pairs`): what `events` and `quality` share.

use serde::de::DeserializeOwned;

use crate::input::{Flow, InputError, InputFile, InputRecord};

/// A message of a JSON channel that did not parse.
pub(crate) struct BadJson {
    pub(crate) log_time_ns: u64,
    pub(crate) reason: String,
}

/// Read `input` in order: each message of `channel`, parsed as `T`, goes to
/// `on_record`; the channel id of every other message to `on_other`. Stops
/// at the first message of `channel` that does not parse.
pub(crate) fn read_json_channel<T: DeserializeOwned>(
    input: &InputFile,
    channel: u16,
    on_record: &mut dyn FnMut(T),
    on_other: &mut dyn FnMut(u16),
) -> Result<Result<(), BadJson>, InputError> {
    let mut bad = None;
    input.read_records(false, &mut |record| {
        let InputRecord::Message(message) = record else {
            return Flow::Continue(());
        };
        if message.channel_id != channel {
            on_other(message.channel_id);
            return Flow::Continue(());
        }
        match serde_json::from_slice::<T>(&message.data) {
            Ok(parsed) => {
                on_record(parsed);
                Flow::Continue(())
            }
            Err(error) => {
                bad = Some(BadJson {
                    log_time_ns: message.log_time_ns,
                    reason: error.to_string(),
                });
                Flow::Break(())
            }
        }
    })?;
    Ok(bad.map_or(Ok(()), Err))
}
