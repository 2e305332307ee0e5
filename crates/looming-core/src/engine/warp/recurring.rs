//! Exact transforms for a source column whose returns come from a few
//! firing times, each recurring along the column: a Hesai Pandar64
//! publishing its cloud with per-laser azimuth offsets gridded by azimuth
//! holds six times 0.7 ms apart in every column, cycling row by row. The
//! [`super::moved_vertices::TransformCache`]'s lines (one straight line in
//! time, followed within 0.1 ms) missed on almost every return there, and
//! composing two or three poses per return was a tenth of the whole run.
//! Here each time's transforms are composed once per column and kept by
//! time: exact, as a column whose returns share one time gets them.

use nalgebra::Isometry3;

use super::moved_vertices::Moving;
use crate::engine::trajectory::Trajectory;
use crate::model::StampNs;

/// Distinct times a column may hold to be taken as recurring.
pub(super) const MAX_TIMES: usize = 8;

/// Whether the returns' times `time_ns` (one per return of a column) are
/// at most [`MAX_TIMES`] distinct values, each held by two returns on
/// average at least (a column of KITTI's, every return at its own time,
/// is not).
pub(super) fn recurring(time_ns: &[StampNs]) -> bool {
    let mut seen = [0; MAX_TIMES];
    let mut distinct = 0;
    for &t in time_ns {
        if !seen[..distinct].contains(&t) {
            if distinct == MAX_TIMES {
                return false;
            }
            seen[distinct] = t;
            distinct += 1;
        }
    }
    2 * distinct <= time_ns.len()
}

/// Target columns a column's returns of one time land in, at most, kept
/// (neighbouring rows land in neighbouring columns).
const COLUMN_SLOTS: usize = 2 * MAX_TIMES;

/// A recurring column's transforms, by departure time (and target column);
/// a worker's, emptied for each column ([`ExactTimes::clear`]).
#[derive(Default)]
pub(super) struct ExactTimes {
    departures: Vec<(StampNs, Isometry3<f64>)>,
    /// Into the frame a fixed offset later ([`ExactTimes::until`]).
    until: Vec<(StampNs, Moving)>,
    /// Into target columns' frames, the last [`COLUMN_SLOTS`] kept.
    columns: Vec<((StampNs, usize), Moving)>,
    next_column: usize,
}

impl ExactTimes {
    /// Nothing kept (for another column), the lists' room kept.
    pub(super) fn clear(&mut self) {
        self.departures.clear();
        self.until.clear();
        self.columns.clear();
        self.next_column = 0;
    }

    /// `pose(from_ns)`, kept by time.
    fn departure(&mut self, trajectory: &Trajectory, from_ns: StampNs) -> Isometry3<f64> {
        if let Some(pose) = kept(&self.departures, from_ns) {
            return pose;
        }
        let pose = trajectory.pose(from_ns);
        keep(&mut self.departures, (from_ns, pose));
        pose
    }

    /// Points measured at `from_ns` into the frame at `from_ns +
    /// offset_ns`: `pose(to)^-1 * pose(from)`, as a column of returns
    /// sharing their time composes it.
    pub(super) fn until(
        &mut self,
        trajectory: &Trajectory,
        from_ns: StampNs,
        offset_ns: StampNs,
    ) -> Moving {
        if let Some(transform) = kept(&self.until, from_ns) {
            return transform;
        }
        let transform = Moving::new(
            trajectory.pose(from_ns + offset_ns).inverse() * self.departure(trajectory, from_ns),
        );
        keep(&mut self.until, (from_ns, transform));
        transform
    }

    /// Points measured at `from_ns` into the frame target column `col`
    /// fired in, `arrival` that column's inverse pose.
    pub(super) fn until_column(
        &mut self,
        trajectory: &Trajectory,
        (from_ns, col): (StampNs, usize),
        arrival: &Isometry3<f64>,
    ) -> Moving {
        let key = (from_ns, col);
        if let Some(transform) = kept(&self.columns, key) {
            return transform;
        }
        let transform = Moving::new(arrival * self.departure(trajectory, from_ns));
        if self.columns.len() < COLUMN_SLOTS {
            self.columns.push((key, transform));
        } else {
            self.columns[self.next_column] = (key, transform);
            self.next_column = (self.next_column + 1) % COLUMN_SLOTS;
        }
        transform
    }
}

/// The value kept under `key` in `list`, if any.
fn kept<K: PartialEq, V: Copy>(list: &[(K, V)], key: K) -> Option<V> {
    list.iter()
        .find(|(k, _)| *k == key)
        .map(|&(_, value)| value)
}

/// `entry` kept in `list` while it has room for one of each of a column's
/// [`MAX_TIMES`] times (a column of more is not recurring).
fn keep<K, V>(list: &mut Vec<(K, V)>, entry: (K, V)) {
    if list.len() < MAX_TIMES {
        list.push(entry);
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn a_few_times_recurring_along_the_column_are_recurring() {
        let pandar: Vec<StampNs> = (0..64)
            .map(|k| [1662, 2326, 2991, 0, 663, 1328][k % 6])
            .collect();
        assert!(recurring(&pandar));
        let kitti: Vec<StampNs> = (0..64).map(|k| 1000 * k).collect();
        assert!(!recurring(&kitti));
        // Few returns, each at its own time: not recurring either.
        assert!(!recurring(&[5, 9, 13]));
        assert!(!recurring(&(0..9).flat_map(|k| [k, k]).collect::<Vec<_>>()));
        assert!(recurring(&[7, 7, 7, 7]));
    }
}
