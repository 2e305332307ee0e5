//! `--replace` and its guard: an input that already carries `/looming/*`
//! channels is refused, or its channels are dropped so that a fresh set is
//! written.

use crate::annotate::topics::is_ours;
use crate::input::{Catalog, InputFile};

use super::ProcessError;

/// The input's catalog without the `/looming/*` channels (and the schemas
/// only they use), for `--replace`.
pub(super) fn without_our_channels(catalog: &Catalog) -> Catalog {
    let mut kept = catalog.clone();
    kept.channels.retain(|_, c| !is_ours(&c.topic));
    let used: std::collections::BTreeSet<u16> = kept
        .channels
        .values()
        .filter_map(|c| c.schema.as_ref().map(|s| s.id))
        .collect();
    kept.schemas.retain(|id, _| used.contains(id));
    kept
}

/// A log that already carries `/looming/*` channels would end up with two sets.
pub(super) fn refuse_processed_input(input: &InputFile) -> Result<(), ProcessError> {
    let ours: Vec<&str> = input
        .catalog()
        .channels
        .values()
        .filter(|c| is_ours(&c.topic))
        .map(|c| c.topic.as_str())
        .collect();
    if ours.is_empty() {
        return Ok(());
    }
    Err(ProcessError::AlreadyProcessed {
        path: input.path().to_path_buf(),
        topics: ours.join(", "),
    })
}
