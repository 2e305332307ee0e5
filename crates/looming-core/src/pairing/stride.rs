//! Pairs that span a baseline: a sensor faster than the pairing's shortest
//! baseline has each scan paired with the scan a baseline before it, not
//! with the one just before.
//!
//! Looming is a range difference over the time between two scans; the
//! range noise does not shrink with that time, so at 20 Hz the same sensor
//! measures looming with twice the noise it has at 10 Hz (the side sensors
//! of `synth --lidars 3`: road `D` p90 0.040-0.050 1/s against the roof's
//! 0.012, and a followed car's `|D|` of 0.27 1/s under their moving
//! threshold). Paired over two periods, a 20 Hz sensor measures like a
//! 10 Hz one and still gives a pair per scan (one-to-one with its clouds);
//! only the time a pair spans grows.
//!
//! The [`Strider`] takes the pairer's consecutive pairs of one sensor and
//! joins the last few into one where they are contiguous (each one's
//! previous scan the last one's current): the first scan of the run and
//! the current of the newest, with their motion joined. A gap, a skipped
//! scan or the start of a stream starts the chain again: its first pairs
//! span what the chain holds.

use std::collections::VecDeque;
use std::sync::Arc;

use crate::model::ScanPair;

/// The default shortest span of a pair, seconds: 10 Hz sensors (0.1 s) pair
/// consecutive scans as ever; 20 Hz ones over two periods, 15 Hz over two
/// (0.133 s).
pub const DEFAULT_MIN_BASELINE_S: f64 = 0.09;

/// Most consecutive pairs joined into one (a 40 Hz sensor at the default).
const MAX_JOINED_PAIRS: usize = 4;

/// Joins a sensor's consecutive pairs into pairs spanning at least a
/// baseline; see the module documentation.
#[derive(Debug)]
pub struct Strider {
    min_baseline_s: f64,
    /// The last consecutive pairs, contiguous, oldest first.
    chain: VecDeque<ScanPair>,
}

impl Strider {
    /// A strider for pairs spanning at least `min_baseline_s` (0 or less:
    /// every pair as the pairer made it).
    pub fn new(min_baseline_s: f64) -> Self {
        Self {
            min_baseline_s,
            chain: VecDeque::with_capacity(MAX_JOINED_PAIRS),
        }
    }

    /// The pair to evaluate for the pairer's next consecutive `pair`.
    pub fn push(&mut self, pair: ScanPair) -> ScanPair {
        // (A NaN baseline, as 0, strides nothing.)
        let striding = self.min_baseline_s > 0.0 && pair.dt_s < self.min_baseline_s;
        if !striding {
            self.chain.clear();
            return pair;
        }
        let contiguous = self
            .chain
            .back()
            .is_some_and(|last| Arc::ptr_eq(&last.current, &pair.previous));
        if !contiguous {
            self.chain.clear();
        }
        self.chain.push_back(pair);
        // The fewest newest pairs that span the baseline (all the chain
        // holds where it is shorter).
        let mut span_s = 0.0;
        let mut taken = 0;
        for link in self.chain.iter().rev() {
            span_s += link.dt_s;
            taken += 1;
            if span_s >= self.min_baseline_s || taken == MAX_JOINED_PAIRS {
                break;
            }
        }
        let first = self.chain.len() - taken;
        let joined = join(self.chain.range(first..));
        // What a later pair can still need.
        while self.chain.len() >= MAX_JOINED_PAIRS {
            self.chain.pop_front();
        }
        joined
    }
}

/// Contiguous consecutive pairs, oldest first, as one pair: the first's
/// previous scan, the last's current, the motion joined; the last's index
/// and step.
fn join<'a>(mut links: impl Iterator<Item = &'a ScanPair>) -> ScanPair {
    let first = links.next().expect("at least the newest pair");
    let mut joined = first.clone();
    for link in links {
        joined = ScanPair {
            previous: Arc::clone(&joined.previous),
            current: Arc::clone(&link.current),
            motion: joined.motion.joined(&link.motion),
            dt_s: (link.current.stamp_ns - joined.previous.stamp_ns) as f64 * 1e-9,
            step_s: link.step_s,
            previous_log_time_ns: joined.previous_log_time_ns,
            current_log_time_ns: link.current_log_time_ns,
            index: link.index,
        };
    }
    joined
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::model::{AngularSource, PairMotion, Scan, TimeSeries};
    use nalgebra::Vector3;

    fn scan(stamp_ns: i64) -> Arc<Scan> {
        Arc::new(Scan::empty(
            stamp_ns,
            "lidar".into(),
            nalgebra::Isometry3::identity(),
        ))
    }

    /// The consecutive pairs of scans stamped `stamps_ns`, each with one
    /// velocity sample at its current scan.
    fn pairs(stamps_ns: &[i64]) -> Vec<ScanPair> {
        let scans: Vec<Arc<Scan>> = stamps_ns.iter().map(|&t| scan(t)).collect();
        scans
            .windows(2)
            .enumerate()
            .map(|(index, w)| {
                let dt_s = (w[1].stamp_ns - w[0].stamp_ns) as f64 * 1e-9;
                let sample = vec![(w[1].stamp_ns, Vector3::new(index as f64, 0.0, 0.0))];
                ScanPair {
                    previous: Arc::clone(&w[0]),
                    current: Arc::clone(&w[1]),
                    motion: PairMotion {
                        velocity: Some(TimeSeries::new(sample, 0.2)),
                        angular: None,
                        angular_source: AngularSource::Unavailable,
                        velocity_extrinsic: None,
                        imu_extrinsic: None,
                        velocity_unavailable: false,
                        imu_unavailable: true,
                        coverage_complete: true,
                    },
                    dt_s,
                    step_s: dt_s,
                    previous_log_time_ns: w[0].stamp_ns as u64,
                    current_log_time_ns: w[1].stamp_ns as u64,
                    index: index as u64,
                }
            })
            .collect()
    }

    const MS: i64 = 1_000_000;

    #[test]
    fn a_20_hz_sensor_pairs_each_scan_with_the_one_two_periods_before() {
        let mut strider = Strider::new(DEFAULT_MIN_BASELINE_S);
        let stamps: Vec<i64> = (0..6).map(|k| k * 50 * MS).collect();
        let out: Vec<ScanPair> = pairs(&stamps)
            .into_iter()
            .map(|p| strider.push(p))
            .collect();
        // The first pair spans what there is; then two periods each.
        assert_eq!(out[0].previous.stamp_ns, 0);
        assert!((out[0].dt_s - 0.05).abs() < 1e-12);
        for (k, pair) in out.iter().enumerate().skip(1) {
            assert_eq!(pair.current.stamp_ns, (k as i64 + 1) * 50 * MS);
            assert_eq!(pair.previous.stamp_ns, (k as i64 - 1) * 50 * MS);
            assert!((pair.dt_s - 0.1).abs() < 1e-12, "{}", pair.dt_s);
            assert!((pair.step_s - 0.05).abs() < 1e-12);
            assert_eq!(
                pair.index, k as u64,
                "one pair per scan, numbered as before"
            );
            assert_eq!(pair.previous_log_time_ns, pair.previous.stamp_ns as u64);
            // Both intervals' motion samples.
            let samples = pair.motion.velocity.as_ref().unwrap().samples();
            assert_eq!(samples.len(), 2);
            assert_eq!(samples[1].0, pair.current.stamp_ns);
        }
    }

    #[test]
    fn a_10_hz_sensor_keeps_its_consecutive_pairs() {
        let mut strider = Strider::new(DEFAULT_MIN_BASELINE_S);
        let stamps: Vec<i64> = (0..5).map(|k| k * 100 * MS).collect();
        for pair in pairs(&stamps) {
            let out = strider.push(pair.clone());
            assert!(Arc::ptr_eq(&out.previous, &pair.previous));
            assert_eq!(out.dt_s, pair.dt_s);
        }
        // A zero baseline: as the pairer made them, at any rate.
        let mut off = Strider::new(0.0);
        let fast: Vec<i64> = (0..5).map(|k| k * 50 * MS).collect();
        for pair in pairs(&fast) {
            assert!(Arc::ptr_eq(
                &off.push(pair.clone()).previous,
                &pair.previous
            ));
        }
    }

    #[test]
    fn a_gap_starts_the_chain_again() {
        let mut strider = Strider::new(DEFAULT_MIN_BASELINE_S);
        let mut stream = pairs(&[0, 50 * MS, 100 * MS]);
        // A pair whose previous scan is not the last current (a skipped scan):
        // it spans only itself.
        stream.extend(pairs(&[130 * MS, 180 * MS]));
        let out: Vec<ScanPair> = stream.into_iter().map(|p| strider.push(p)).collect();
        assert_eq!(out[1].previous.stamp_ns, 0);
        assert_eq!(out[2].previous.stamp_ns, 130 * MS);
        assert!((out[2].dt_s - 0.05).abs() < 1e-12);
    }

    #[test]
    fn a_40_hz_sensor_joins_at_most_four_pairs() {
        let mut strider = Strider::new(0.2);
        let stamps: Vec<i64> = (0..10).map(|k| k * 25 * MS).collect();
        let last = pairs(&stamps)
            .into_iter()
            .map(|p| strider.push(p))
            .last()
            .unwrap();
        assert!((last.dt_s - 0.1).abs() < 1e-12, "{}", last.dt_s);
    }
}
