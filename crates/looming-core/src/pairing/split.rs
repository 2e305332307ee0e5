//! A cloud that merges several sensors (Autoware's concatenated `base_link`
//! cloud, a driver serving several LiDARs on one topic) made into one scan
//! per sensor by its per-point sensor field (`model::SensorIds`): about
//! their common frame's origin the merged rays meet at no one point, so the
//! range image, rings and ego motion are only right per sensor. Each part
//! is then paired and placed (`origin`) like a LiDAR of its own.

use crate::model::{Scan, ScanLayout};

/// Distinct sensor values kept at most, in a cloud or over a log: a sensor
/// field holding more is no vehicle's LiDARs (16 covers the largest rigs),
/// and nothing sized from untrusted values grows beyond this.
pub const MAX_SENSORS: usize = 16;

/// The distinct values of `ids`, ascending, at most `max`; and whether
/// there were more.
pub fn distinct_ids(ids: &[u32], max: usize) -> (Vec<u32>, bool) {
    let mut seen: Vec<u32> = Vec::new();
    let mut more = false;
    for &id in ids {
        if let Err(at) = seen.binary_search(&id) {
            if seen.len() == max {
                more = true;
                continue;
            }
            seen.insert(at, id);
        }
    }
    (seen, more)
}

/// One merged cloud split by sensor.
#[derive(Debug, Default)]
pub struct Split {
    /// The scan of each id asked for, in their order (`None`: no point of
    /// that sensor in this cloud).
    pub scans: Vec<Option<Scan>>,
    /// Points of sensors not asked for.
    pub other_points: u64,
    /// Those sensors' values, ascending (at most [`MAX_SENSORS`]).
    pub other_ids: Vec<u32>,
}

/// `scan` split by its sensor field into a scan per value of `ids`: each
/// keeps the cloud's stamp, frame and pose, and its own points with their
/// attributes (indexes into the input cloud kept). The cloud's invalid
/// points are counted with the first part. A sub-cloud of an organized
/// cloud is not organized (its rows are gappy): its rings come from its
/// ring field, or are found again. Without a sensor field, nothing.
pub fn split_by_sensor(scan: &Scan, ids: &[u32]) -> Split {
    let Some(sensors) = &scan.sensor_ids else {
        return Split::default();
    };
    let mut members: Vec<Vec<usize>> = vec![Vec::new(); ids.len()];
    let mut other = Vec::new();
    for (i, id) in sensors.ids.iter().enumerate() {
        match ids.iter().position(|wanted| wanted == id) {
            Some(k) => members[k].push(i),
            None => other.push(*id),
        }
    }
    let mut first = true;
    let scans = members
        .iter()
        .map(|points| {
            if points.is_empty() {
                return None;
            }
            let mut part = part_of(scan, points);
            if std::mem::take(&mut first) {
                part.skipped_invalid_points = scan.skipped_invalid_points;
            }
            Some(part)
        })
        .collect();
    Split {
        scans,
        other_points: other.len() as u64,
        other_ids: distinct_ids(&other, MAX_SENSORS).0,
    }
}

/// The points of `scan` at `indexes`, with their attributes.
fn part_of(scan: &Scan, indexes: &[usize]) -> Scan {
    fn pick<T: Copy>(values: &[T], indexes: &[usize]) -> Vec<T> {
        indexes.iter().map(|&i| values[i]).collect()
    }
    let mut layout = ScanLayout::from_fields(None, None);
    layout.rings = scan.layout.rings.clone();
    layout.times = scan.layout.times.clone();
    layout.ring_field_dropped = scan.layout.ring_field_dropped.clone();
    if !matches!(layout.rings, crate::model::RingSource::Field { .. }) {
        // Rows or orders of the merged cloud say nothing of a part's lasers.
        layout.rings = crate::model::RingSource::None;
    }
    let mut part = Scan {
        stamp_ns: scan.stamp_ns,
        frame_id: scan.frame_id.clone(),
        sensor_pose: scan.sensor_pose,
        points_m: pick(&scan.points_m, indexes),
        intensity: scan.intensity.as_ref().map(|v| pick(v, indexes)),
        ring: scan
            .ring
            .as_ref()
            .filter(|_| matches!(layout.rings, crate::model::RingSource::Field { .. }))
            .map(|v| pick(v, indexes)),
        time_offset_s: scan
            .time_offset_s
            .as_ref()
            .filter(|_| matches!(layout.times, crate::model::TimeSource::Field { .. }))
            .map(|v| pick(v, indexes)),
        source_index: pick(&scan.source_index, indexes),
        input_point_count: indexes.len() as u32,
        skipped_invalid_points: 0,
        organized: None,
        layout,
        sensor_ids: None,
    };
    restamp(&mut part);
    part
}

/// A merged cloud's stamp is when it was merged, not when each sensor's
/// sweep began (a concatenating node takes each sensor's latest scan, whose
/// points' times say when they were measured): with per-point times the
/// part is stamped at its first point, its times taken from there, as the
/// sensor's own cloud would be, so its pairs' `dt` is its own period.
fn restamp(part: &mut Scan) {
    let Some(times) = &mut part.time_offset_s else {
        return;
    };
    let first_s = times.iter().copied().fold(f32::INFINITY, f32::min);
    if !first_s.is_finite() || first_s == 0.0 {
        return;
    }
    for t in times.iter_mut() {
        *t -= first_s;
    }
    part.stamp_ns += (f64::from(first_s) * 1e9).round() as i64;
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::model::SensorIds;

    fn merged(ids: Vec<u32>) -> Scan {
        let n = ids.len();
        Scan {
            stamp_ns: 5,
            frame_id: "base_link".into(),
            sensor_pose: nalgebra::Isometry3::identity(),
            points_m: (0..n).map(|i| [i as f32 + 1.0, 0.0, 0.0]).collect(),
            intensity: Some((0..n).map(|i| i as f32).collect()),
            ring: Some((0..n).map(|i| i as u16).collect()),
            time_offset_s: Some((0..n).map(|i| i as f32 * 0.01).collect()),
            source_index: (0..n as u32).map(|i| i * 2).collect(),
            input_point_count: 2 * n as u32,
            skipped_invalid_points: 3,
            organized: None,
            layout: ScanLayout::from_fields(Some("ring"), Some("time")),
            sensor_ids: Some(SensorIds {
                field: "sensor_id".into(),
                ids,
            }),
        }
    }

    #[test]
    fn each_sensor_gets_its_own_points_with_their_attributes() {
        let scan = merged(vec![2, 0, 2, 7, 0, 9]);
        let split = split_by_sensor(&scan, &[0, 2, 5]);
        assert_eq!(split.scans.len(), 3);
        let zero = split.scans[0].as_ref().unwrap();
        assert_eq!(zero.points_m, vec![[2.0, 0.0, 0.0], [5.0, 0.0, 0.0]]);
        assert_eq!(zero.ring, Some(vec![1, 4]));
        assert_eq!(zero.source_index, vec![2, 8]);
        assert_eq!(zero.intensity, Some(vec![1.0, 4.0]));
        // Stamped at its first point (0.01 s after the merged cloud's).
        let times = zero.time_offset_s.as_ref().unwrap();
        assert!(
            times[0] == 0.0 && (times[1] - 0.03).abs() < 1e-6,
            "{times:?}"
        );
        assert_eq!(zero.stamp_ns, 5 + 10_000_000);
        assert_eq!(zero.frame_id, "base_link");
        assert!(zero.sensor_ids.is_none());
        // The cloud's invalid points are counted once, with the first part.
        assert_eq!(zero.skipped_invalid_points, 3);
        let two = split.scans[1].as_ref().unwrap();
        assert_eq!(two.source_index, vec![0, 4]);
        assert_eq!(two.skipped_invalid_points, 0);
        assert!(split.scans[2].is_none(), "no point of sensor 5");
        assert_eq!((split.other_points, split.other_ids), (2, vec![7, 9]));
    }

    #[test]
    fn a_cloud_without_a_sensor_field_is_not_split() {
        let mut scan = merged(vec![0, 1]);
        scan.sensor_ids = None;
        let split = split_by_sensor(&scan, &[0, 1]);
        assert!(split.scans.is_empty() && split.other_points == 0);
    }

    #[test]
    fn distinct_values_are_bounded() {
        assert_eq!(distinct_ids(&[3, 1, 3, 2, 1], 16), (vec![1, 2, 3], false));
        let many: Vec<u32> = (0..1_000).rev().collect();
        let (kept, more) = distinct_ids(&many, MAX_SENSORS);
        assert_eq!(kept.len(), MAX_SENSORS);
        assert!(more);
    }
}
