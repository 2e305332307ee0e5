//! The engine and the rest of the annotation overlapped: while the engine
//! computes a pair, the pair before it is completed (objects, quality,
//! events, messages) beside it. Each uses both cores through rayon where it
//! can, but neither does all the way through (the objects' segmentation and
//! tracking, the event detector and parts of the engine run on one), so
//! one after the other left a core idle for a third of the time.

use std::time::Instant;

use super::{Annotator, OwnMessage};
use crate::engine::{StageTimes, compute_with_cache};
use crate::model::ScanPair;
use crate::quality::PairQuality;

/// One pair's annotation.
#[derive(Debug, Default)]
pub struct Annotated {
    /// Its messages, and those of the events that ended before it.
    pub messages: Vec<OwnMessage>,
    /// Its quality figures (`None` when the engine made no image of it), for
    /// its `/looming/pairs` message.
    pub quality: Option<PairQuality>,
}

/// Wall time per stage over a run, seconds: the engine's
/// ([`StageTimes`]) and the annotation's after it. The two overlap (see the
/// module note), so they add up to more than the run's wall time.
#[derive(Debug, Clone, Default, serde::Serialize)]
pub struct StageSeconds {
    #[serde(flatten)]
    pub engine: StageTimes,
    /// Objects: segmentation, measurement, tracking, their feedback.
    pub objects_s: f64,
    /// Quality figures and the near-miss detector.
    pub quality_and_events_s: f64,
    /// Our channels' messages built and encoded.
    pub messages_s: f64,
}

impl StageSeconds {
    pub fn add(&mut self, other: &StageSeconds) {
        self.engine.add(&other.engine);
        self.objects_s += other.objects_s;
        self.quality_and_events_s += other.quality_and_events_s;
        self.messages_s += other.messages_s;
    }
}

impl Annotator {
    /// Takes `pair` into the engine while the pair pushed before it is
    /// completed; returns that one with its annotation (`None` on the first
    /// push). Pairs come out in the order they went in, one push late; the
    /// last comes out of [`Annotator::flush`].
    pub fn push_pair(&mut self, pair: ScanPair) -> Option<(ScanPair, Annotated)> {
        let previous = self.pending.take();
        let mut cache = std::mem::take(&mut self.cache);
        let engine = self.config.engine.clone();
        let ((looming, engine_s), completed) = rayon::join(
            || {
                let started = Instant::now();
                let looming = compute_with_cache(&pair, &engine, &mut cache);
                (looming, started.elapsed().as_secs_f64())
            },
            || {
                previous.map(|(pair, looming)| {
                    let annotated = self.complete(&pair, looming);
                    (pair, annotated)
                })
            },
        );
        self.cache = cache;
        self.stats.engine_s += engine_s;
        if let Some(looming) = &looming {
            self.stats.stages.engine.add(&looming.stage_times);
        }
        self.pending = Some((pair, looming));
        completed
    }

    /// The last pair pushed, completed.
    pub fn flush(&mut self) -> Option<(ScanPair, Annotated)> {
        let (pair, looming) = self.pending.take()?;
        let annotated = self.complete(&pair, looming);
        Some((pair, annotated))
    }
}
