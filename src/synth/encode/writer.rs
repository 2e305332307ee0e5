//! Writing encoded messages: per-channel sequence numbers, and the run's
//! metadata record.

use crate::output::{OutputError, OutputWriter};
use crate::synth::scene::Scenario;

use super::Encoded;

/// Writes encoded messages with per-channel sequence numbers.
pub struct SequencedWriter<'w> {
    writer: &'w mut OutputWriter,
    sequences: std::collections::BTreeMap<u16, u32>,
    messages: u64,
}

impl<'w> SequencedWriter<'w> {
    pub fn new(writer: &'w mut OutputWriter) -> Self {
        Self {
            writer,
            sequences: Default::default(),
            messages: 0,
        }
    }

    pub fn write_all(&mut self, messages: Vec<Encoded>) -> Result<(), OutputError> {
        for message in messages {
            let sequence = self.sequences.entry(message.channel).or_default();
            *sequence += 1;
            self.messages += 1;
            self.writer.write_own_message(
                message.channel,
                *sequence,
                message.log_time_ns.max(0) as u64,
                &message.data,
            )?;
        }
        Ok(())
    }

    pub fn messages_written(&self) -> u64 {
        self.messages
    }

    /// The resolved scenario and the seed, for reproduction.
    pub fn write_metadata(
        &mut self,
        scenario: &Scenario,
        seed: u64,
        start_s: f64,
    ) -> Result<(), OutputError> {
        let mut metadata = std::collections::BTreeMap::new();
        metadata.insert("tool".into(), "looming synth".into());
        metadata.insert("version".into(), env!("CARGO_PKG_VERSION").into());
        metadata.insert("seed".into(), seed.to_string());
        metadata.insert("start_s".into(), start_s.to_string());
        metadata.insert(
            "scenario".into(),
            serde_json::to_string(scenario).expect("scenarios serialise"),
        );
        self.writer.write_metadata(&mcap::records::Metadata {
            name: "looming.synth".into(),
            metadata,
        })
    }
}
