//! The motion samples of one source as the pairer buffers them: sorted by
//! stamp, with a floor below which the data is consumed, and a bound on
//! how many are held.

use std::collections::VecDeque;

use crate::model::StampNs;

use super::MAX_BUFFERED_SAMPLES_PER_SOURCE;
use super::motion::{GyroSample, TwistSample};
pub(super) trait Stamped {
    fn stamp_ns(&self) -> StampNs;
}

impl Stamped for TwistSample {
    fn stamp_ns(&self) -> StampNs {
        self.stamp_ns
    }
}

impl Stamped for GyroSample {
    fn stamp_ns(&self) -> StampNs {
        self.stamp_ns
    }
}

pub(super) enum InsertOutcome {
    Inserted,
    Late,
    InsertedWithOverflow,
}

/// Motion samples of one source, sorted by stamp, with a floor below which
/// data has been consumed.
#[derive(Debug)]
pub(super) struct SampleBuffer<T> {
    pub(super) samples: VecDeque<T>,
    /// Samples stamped before this are late: the data there is already consumed.
    pub(super) floor_ns: StampNs,
    pub(super) newest_ns: Option<StampNs>,
    /// Frame of the latest sample; a frame change mid-log applies from then on.
    pub(super) frame_id: Option<String>,
}

impl<T> Default for SampleBuffer<T> {
    fn default() -> Self {
        Self {
            samples: VecDeque::new(),
            floor_ns: StampNs::MIN,
            newest_ns: None,
            frame_id: None,
        }
    }
}

impl<T: Stamped + Copy> SampleBuffer<T> {
    pub(super) fn insert(&mut self, sample: T, frame_id: &str) -> InsertOutcome {
        let stamp_ns = sample.stamp_ns();
        if stamp_ns < self.floor_ns {
            return InsertOutcome::Late;
        }
        // Usually appends; slightly out-of-order samples are placed by stamp.
        let index = self.samples.partition_point(|s| s.stamp_ns() <= stamp_ns);
        self.samples.insert(index, sample);
        self.newest_ns = Some(self.newest_ns.map_or(stamp_ns, |n| n.max(stamp_ns)));
        if self.frame_id.as_deref() != Some(frame_id) {
            self.frame_id = Some(frame_id.to_owned());
        }
        if self.samples.len() > MAX_BUFFERED_SAMPLES_PER_SOURCE {
            self.samples.pop_front();
            return InsertOutcome::InsertedWithOverflow;
        }
        InsertOutcome::Inserted
    }

    /// Drops samples before `cut_ns`, keeping the last one before it so that
    /// values just after the cut still interpolate.
    pub(super) fn prune_before(&mut self, cut_ns: StampNs) {
        while self.samples.len() >= 2 && self.samples[1].stamp_ns() <= cut_ns {
            self.samples.pop_front();
        }
        self.floor_ns = self.floor_ns.max(cut_ns);
    }

    /// Samples in `[from_ns, to_ns]` plus the nearest one on each side.
    pub(super) fn window(&self, from_ns: StampNs, to_ns: StampNs) -> Vec<T> {
        let first = self.samples.partition_point(|s| s.stamp_ns() < from_ns);
        let end = self.samples.partition_point(|s| s.stamp_ns() <= to_ns);
        let first = first.saturating_sub(1);
        let end = (end + 1).min(self.samples.len());
        self.samples.range(first..end).copied().collect()
    }

    pub(super) fn reaches(&self, stamp_ns: StampNs) -> bool {
        self.newest_ns.is_some_and(|newest| newest >= stamp_ns)
    }
}
