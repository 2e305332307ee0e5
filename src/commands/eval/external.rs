//! `looming eval --truth OTHER.mcap`: the truth of another log, read on its
//! own thread in step with the evaluated log (bounded: a few scans ahead).

use std::collections::{BTreeMap, HashMap};
use std::path::Path;
use std::sync::mpsc::{Receiver, SyncSender, sync_channel};

use crate::decode::{self, DecodeLimits};
use crate::input::{Flow, InputFile, InputOptions, InputRecord};
use crate::model::{Decoded, StampNs};
use crate::topics::{TopicError, TopicOverrides, select};
use crate::truth::{self, PointTruth};

use super::{EvalError, ScanTruth, position_key};

/// Scans of truth read ahead of the evaluation.
const READ_AHEAD: usize = 4;

/// Hands out the other log's truth by scan stamp, in increasing order.
pub(crate) struct TruthCursor {
    rx: Receiver<(StampNs, ScanTruth)>,
    ahead: Option<(StampNs, ScanTruth)>,
}

impl TruthCursor {
    /// The truth of the scan stamped `stamp_ns`, if the other log has it.
    /// Stamps must be asked in increasing order; older truth is dropped.
    pub fn truth_at(&mut self, stamp_ns: StampNs) -> Option<ScanTruth> {
        loop {
            let (stamp, truth) = match self.ahead.take() {
                Some(item) => item,
                None => self.rx.recv().ok()?,
            };
            if stamp == stamp_ns {
                return Some(truth);
            }
            if stamp > stamp_ns {
                self.ahead = Some((stamp, truth));
                return None;
            }
        }
    }
}

/// Run `evaluate` with a cursor over the truth of `truth_path`.
pub(crate) fn with_truth_of<T>(
    truth_path: &Path,
    evaluate: impl FnOnce(&mut TruthCursor) -> Result<T, EvalError>,
) -> Result<T, EvalError> {
    let input = InputFile::open(truth_path, InputOptions::default())?;
    let (tx, rx) = sync_channel(READ_AHEAD);
    std::thread::scope(|scope| {
        let reader = scope.spawn(|| read_truth(truth_path, &input, tx));
        let mut cursor = TruthCursor { rx, ahead: None };
        let evaluated = evaluate(&mut cursor);
        // The reader stops at its next send once the cursor is gone.
        drop(cursor);
        let read = reader.join().map_err(|_| EvalError::Internal)?;
        let evaluated = evaluated?;
        read.map(|()| evaluated)
    })
}

/// The other log's LiDAR scans (positions -> point index) and truth, paired
/// by stamp and sent in log order.
fn read_truth(
    path: &Path,
    input: &InputFile,
    tx: SyncSender<(StampNs, ScanTruth)>,
) -> Result<(), EvalError> {
    let name = path.display().to_string();
    let catalog = input.catalog();
    let truth_channel = catalog
        .channels
        .values()
        .find(|c| c.topic == truth::POINTS_TOPIC)
        .map(|c| c.id)
        .ok_or_else(|| EvalError::NoTruth(name.clone()))?;
    let topics =
        select(catalog, &TopicOverrides::default()).map_err(|source| EvalError::Topic {
            path: name.clone(),
            source,
        })?;
    let lidar = topics.lidar.ok_or_else(|| EvalError::Topic {
        path: name.clone(),
        source: TopicError::Missing("no LiDAR topic".into()),
    })?;
    let limits = DecodeLimits::default();
    let mut positions: BTreeMap<StampNs, HashMap<[u32; 3], u32>> = BTreeMap::new();
    let mut truths: BTreeMap<StampNs, Vec<PointTruth>> = BTreeMap::new();
    let mut failure = None;
    input.read_records(false, &mut |record| {
        let InputRecord::Message(message) = record else {
            return Flow::Continue(());
        };
        if message.channel_id == truth_channel {
            match truth::decode_points(&message.data) {
                Ok((stamp, points)) => {
                    truths.insert(stamp, points);
                }
                Err(reason) => {
                    failure = Some(EvalError::Truth(format!("{name}: {reason}")));
                    return Flow::Break(());
                }
            }
        } else if message.channel_id == lidar.channel_id {
            let decoded = decode::decode(lidar.kind, lidar.encoding, false, &message.data, &limits);
            if let Ok(Decoded::Scan(scan)) = decoded {
                let by_position = scan
                    .points_m
                    .iter()
                    .zip(&scan.source_index)
                    .map(|(p, &index)| (position_key(p), index))
                    .collect();
                positions.insert(scan.stamp_ns, by_position);
            }
        }
        // Send every stamp that has both halves, oldest first.
        let complete: Vec<StampNs> = truths
            .keys()
            .filter(|stamp| positions.contains_key(stamp))
            .copied()
            .collect();
        for stamp in complete {
            let truth = ScanTruth {
                points: truths.remove(&stamp).unwrap_or_default(),
                index_by_position: positions.remove(&stamp),
            };
            if tx.send((stamp, truth)).is_err() {
                return Flow::Break(());
            }
        }
        // A half whose other half never comes must not pile up.
        while truths.len() > READ_AHEAD * 4 {
            truths.pop_first();
        }
        while positions.len() > READ_AHEAD * 4 {
            positions.pop_first();
        }
        Flow::Continue(())
    })?;
    match failure {
        Some(error) => Err(error),
        None => Ok(()),
    }
}
