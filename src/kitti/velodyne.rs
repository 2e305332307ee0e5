//! KITTI Velodyne HDL-64E scans (`velodyne_points/data/*.bin`): packed
//! little-endian float32 records `x y z reflectance`, x forward, y left,
//! z up (metres), reflectance in [0, 1].
//!
//! Point order, measured on real KITTI scans (see the ignored test below):
//! the file lists the 64 lasers one after another (top laser first); each
//! laser's points go counter-clockwise seen from above (azimuth
//! `atan2(y, x)` increasing), starting and ending straight ahead. The
//! sweep itself starts and ends behind the car: the motion seam (a jump of
//! one scan period of travel) is behind, none ahead.

use std::f64::consts::{PI, TAU};
use std::path::Path;

use super::KittiError;
use super::timestamps::{open_sized, read_exact_len};

/// Bytes per point: four little-endian float32.
const RECORD_BYTES: usize = 16;

/// Ring numbers beyond this are not a real spinning LiDAR (the largest have
/// 128 lasers).
const MAX_RINGS: usize = 128;

/// All points of a scan, at most `max_points` of them (checked from the file
/// length before anything is read or allocated). Non-finite values are kept
/// as they are: the importer or decoder skips them, and dropping them here
/// would break the laser-by-laser order `derive_rings` relies on.
pub(crate) fn read_bin(path: &Path, max_points: usize) -> Result<Vec<[f32; 4]>, KittiError> {
    let (file, len_bytes) = open_sized(path, "Velodyne scan")?;
    let invalid = |reason| KittiError::Invalid {
        path: path.to_path_buf(),
        reason,
    };
    if len_bytes % RECORD_BYTES as u64 != 0 {
        return Err(invalid(format!(
            "length {len_bytes} bytes is not a multiple of the {RECORD_BYTES}-byte point record"
        )));
    }
    let point_count = len_bytes / RECORD_BYTES as u64;
    if point_count > max_points as u64 {
        return Err(invalid(format!(
            "{point_count} points, more than the limit of {max_points}"
        )));
    }
    let bytes = read_exact_len(file, path, len_bytes)?;
    let (records, _) = bytes.as_chunks::<RECORD_BYTES>();
    Ok(records.iter().map(decode_record).collect())
}

/// Fraction of the sweep, in [0, 1), at which the HDL-64E fires at azimuth
/// `atan2(y, x)`: the sweep starts behind the car and turns
/// counter-clockwise seen from above, so behind is 0, right 0.25, forward
/// 0.5 (where the cameras trigger, KITTI's `timestamps.txt`) and left 0.75.
/// Measured on real scans: timing points this way removes the motion seam
/// behind the car; the clockwise reading doubles it. NaN for non-finite
/// input; (0, 0) counts as forward.
pub(crate) fn sweep_fraction(x: f32, y: f32) -> f64 {
    let azimuth_rad = f64::from(y).atan2(f64::from(x));
    ((azimuth_rad + PI) / TAU).rem_euclid(1.0)
}

/// Ring (laser) number of every point, from the file order alone: the
/// engine's laser-order detection (`engine::layout::laser_order`), which
/// every log gets; rings are numbered in file order (top laser first on
/// KITTI), not by elevation. Points without an azimuth (non-finite, or on
/// the z axis) keep the current ring. `None` when the result is not
/// plausibly a spinning LiDAR: fewer than 2 or more than 128 rings, a ring
/// that does not turn, or a ring holding fewer than 1/20 of the mean valid
/// points per ring.
pub(crate) fn derive_rings(points: &[[f32; 4]]) -> Option<Vec<u16>> {
    let xyz: Vec<[f32; 3]> = points.iter().map(|p| [p[0], p[1], p[2]]).collect();
    crate::engine::layout::laser_order(&xyz, 2..=MAX_RINGS).map(|order| order.rings)
}

fn decode_record(record: &[u8; RECORD_BYTES]) -> [f32; 4] {
    let (fields, _) = record.as_chunks::<4>();
    let mut point = [0.0; 4];
    for (value, field) in point.iter_mut().zip(fields) {
        *value = f32::from_le_bytes(*field);
    }
    point
}

#[cfg(test)]
mod tests {
    use super::*;

    fn encode(points: &[[f32; 4]]) -> Vec<u8> {
        points
            .iter()
            .flatten()
            .flat_map(|v| v.to_le_bytes())
            .collect()
    }

    fn write(dir: &tempfile::TempDir, bytes: &[u8]) -> std::path::PathBuf {
        let path = dir.path().join("0000000000.bin");
        std::fs::write(&path, bytes).expect("write");
        path
    }

    /// One laser's turn as KITTI lists it: counter-clockwise from forward.
    fn laser(elevation_rad: f64, points: usize, range_m: f64) -> Vec<[f32; 4]> {
        (0..points)
            .map(|i| {
                let azimuth_rad = TAU * (i as f64 + 0.5) / points as f64;
                let horizontal_m = range_m * elevation_rad.cos();
                [
                    (horizontal_m * azimuth_rad.cos()) as f32,
                    (horizontal_m * azimuth_rad.sin()) as f32,
                    (range_m * elevation_rad.sin()) as f32,
                    0.5,
                ]
            })
            .collect()
    }

    fn three_lasers() -> Vec<[f32; 4]> {
        [0.03, -0.1, -0.3]
            .iter()
            .flat_map(|&e| laser(e, 100, 20.0))
            .collect()
    }

    fn expected_three() -> Vec<u16> {
        (0..3).flat_map(|r| [r; 100]).collect()
    }

    #[test]
    fn reads_little_endian_records() {
        let dir = tempfile::tempdir().expect("temp dir");
        let points = [[1.5, -2.0, 0.25, 0.75], [f32::NAN, 0.0, -1.0, 1.0]];
        let path = write(&dir, &encode(&points));
        let got = read_bin(&path, 2).expect("valid");
        assert_eq!(got[0], points[0]);
        assert!(got[1][0].is_nan(), "non-finite values are kept");
        assert_eq!(got[1][1..], points[1][1..]);
        let empty = write(&dir, b"");
        assert_eq!(read_bin(&empty, 0).expect("empty"), Vec::<[f32; 4]>::new());
    }

    #[test]
    fn decode_is_little_endian() {
        let mut record = [0_u8; RECORD_BYTES];
        record[..4].copy_from_slice(&[0x00, 0x00, 0x80, 0x3f]);
        assert_eq!(decode_record(&record), [1.0, 0.0, 0.0, 0.0]);
    }

    #[test]
    fn wrong_length_is_invalid_and_names_it() {
        let dir = tempfile::tempdir().expect("temp dir");
        let path = write(&dir, &[0; 17]);
        match read_bin(&path, 10) {
            Err(KittiError::Invalid { reason, .. }) => {
                assert!(reason.contains("17 bytes"), "{reason}")
            }
            other => panic!("{other:?}"),
        }
    }

    #[test]
    fn too_many_points_are_refused_before_reading() {
        let dir = tempfile::tempdir().expect("temp dir");
        let path = write(&dir, &encode(&[[0.0; 4]; 3]));
        assert!(matches!(
            read_bin(&path, 2),
            Err(KittiError::Invalid { .. })
        ));
        assert_eq!(read_bin(&path, 3).expect("at the limit").len(), 3);
        // A huge sparse file is refused from its length alone.
        let file = std::fs::OpenOptions::new()
            .write(true)
            .open(&path)
            .expect("open");
        file.set_len(16 << 30).expect("set_len");
        assert!(matches!(
            read_bin(&path, 200_000),
            Err(KittiError::Invalid { .. })
        ));
    }

    #[test]
    fn missing_file() {
        let dir = tempfile::tempdir().expect("temp dir");
        assert!(matches!(
            read_bin(&dir.path().join("absent.bin"), 10),
            Err(KittiError::Missing { .. })
        ));
    }

    #[test]
    fn sweep_fraction_quarters() {
        let close = |got: f64, want: f64| assert!((got - want).abs() < 1e-6, "{got} vs {want}");
        close(sweep_fraction(-1.0, 0.0), 0.0); // behind
        close(sweep_fraction(-1.0, -1e-6), 0.0); // just right of behind: start
        close(sweep_fraction(-1.0, 1e-6), 1.0); // just left of behind: end
        close(sweep_fraction(0.0, -1.0), 0.25); // right
        close(sweep_fraction(1.0, 0.0), 0.5); // forward
        close(sweep_fraction(0.0, 1.0), 0.75); // left
        assert!(sweep_fraction(f32::NAN, 1.0).is_nan());
        let all = (0..360).map(|d| f64::from(d).to_radians());
        for a in all {
            let f = sweep_fraction(a.cos() as f32, a.sin() as f32);
            assert!((0.0..1.0).contains(&f), "{f}");
        }
    }

    #[test]
    fn synthetic_three_laser_scan() {
        assert_eq!(derive_rings(&three_lasers()), Some(expected_three()));
    }

    #[test]
    fn sweep_fraction_runs_forward_along_a_laser_but_for_the_wrap_behind() {
        // Documents the relation the ring rule relies on: along a laser the
        // sweep fraction increases, except once behind the car (1 -> 0).
        let points = laser(0.0, 100, 10.0);
        let fractions: Vec<f64> = points.iter().map(|p| sweep_fraction(p[0], p[1])).collect();
        let falls = fractions.windows(2).filter(|w| w[1] < w[0]).count();
        assert_eq!(falls, 1);
    }

    #[test]
    fn invalid_points_keep_the_current_ring() {
        let mut points = three_lasers();
        points[150] = [f32::NAN, 1.0, 1.0, 0.5];
        points[151] = [0.0, 0.0, 0.0, 0.0];
        points[152] = [f32::INFINITY, 0.0, 0.0, 0.5];
        points[153] = [0.0, 0.0, 5.0, 0.5];
        // Invalid points right at a laser change stay in the old ring.
        points[200] = [0.0, 0.0, 0.0, 0.0];
        let rings = derive_rings(&points).expect("plausible");
        assert_eq!(&rings[148..156], &[1; 8]);
        assert_eq!(rings[200], 1);
        assert_eq!(rings[201], 2);
    }

    #[test]
    fn jitter_across_forward_moves_a_boundary_by_a_point_at_most() {
        let mut points = three_lasers();
        // Laser 1's first point lies just right of forward, as if it had
        // fired a hair early (at laser 0's height: it goes to ring 0), and
        // its last one a hair late (at its own laser's height: the cut,
        // where the elevation hands over between lasers, keeps it on ring 1).
        points[100] = [20.0, -0.01, 0.6, 0.5];
        points[199] = [20.0, 0.01, -2.0, 0.5];
        let rings = derive_rings(&points).expect("plausible");
        assert_eq!((rings[99], rings[100], rings[101]), (0, 0, 1));
        assert_eq!((rings[198], rings[199], rings[200]), (1, 1, 2));
    }

    #[test]
    fn jitter_back_and_forth_across_forward_does_not_split_a_ring() {
        let mut points = three_lasers();
        // Just after laser 1 starts, one point crosses back to just right of
        // forward: two fall-backs in three points. Without the middle-of-turn
        // rule that would make a 2-point ring.
        points[101] = [20.0, -0.01, 0.6, 0.5];
        let rings = derive_rings(&points).expect("plausible");
        assert_eq!(rings, expected_three());
    }

    #[test]
    fn implausible_scans_give_none() {
        assert_eq!(derive_rings(&laser(0.0, 100, 10.0)), None, "one ring");
        assert_eq!(derive_rings(&[]), None);
        let many: Vec<[f32; 4]> = (0..129).flat_map(|_| laser(0.0, 4, 10.0)).collect();
        assert_eq!(derive_rings(&many), None, "129 rings");
        let at_max: Vec<[f32; 4]> = (0..128).flat_map(|_| laser(0.0, 4, 10.0)).collect();
        assert_eq!(derive_rings(&at_max).map(|r| r[r.len() - 1]), Some(127));
        let mut sliver = three_lasers();
        sliver.extend(laser(0.0, 2, 10.0));
        // Mean (300 + 2) / 4 = 75 points per ring: at least 75 / 20 = 3 each.
        assert_eq!(derive_rings(&sliver), None, "a 2-point ring among 100s");
        let invalid = vec![[f32::NAN; 4]; 10];
        assert_eq!(derive_rings(&invalid), None);
    }

    #[test]
    #[ignore = "reads ../shared/real-samples/kitti-6-scans beside the repository: cargo test -- --ignored"]
    fn kitti_hdl64e_scans() {
        let dir = concat!(
            env!("CARGO_MANIFEST_DIR"),
            "/../shared/real-samples/kitti-6-scans/"
        );
        for scan in 0..6 {
            let path = std::path::PathBuf::from(format!("{dir}{scan:06}.bin"));
            assert!(path.exists(), "{} absent", path.display());
            let points = read_bin(&path, 200_000).expect("KITTI scan");
            let rings = derive_rings(&points).expect("plausible rings");
            report_real_scan(scan, &points, &rings);
        }
    }

    fn report_real_scan(scan: usize, points: &[[f32; 4]], rings: &[u16]) {
        let ring_count = usize::from(rings.iter().copied().max().unwrap_or(0)) + 1;
        assert_eq!(ring_count, 64, "scan {scan}");
        let mut counts = vec![0_usize; ring_count];
        let mut elevations_deg = vec![Vec::new(); ring_count];
        let (mut rising, mut steps) = (0, 0);
        let mut previous: Option<(u16, f64)> = None;
        for (p, &ring) in points.iter().zip(rings) {
            let r = usize::from(ring);
            counts[r] += 1;
            let elevation = f64::from(p[2]).atan2(f64::from(p[0]).hypot(f64::from(p[1])));
            elevations_deg[r].push(elevation.to_degrees());
            let fraction = sweep_fraction(p[0], p[1]);
            if let Some((previous_ring, previous_fraction)) = previous
                && previous_ring == ring
            {
                // Step wrapped to (-0.5, 0.5] so the wrap behind is a small step.
                let step = (fraction - previous_fraction + 0.5).rem_euclid(1.0) - 0.5;
                rising += usize::from(step > 0.0);
                steps += 1;
            }
            previous = Some((ring, fraction));
        }
        let spreads: Vec<(f64, f64, f64)> = elevations_deg.iter_mut().map(|e| spread(e)).collect();
        let worst = |f: fn(&(f64, f64, f64)) -> f64| spreads.iter().map(f).fold(0.0, f64::max);
        let mut p1_99: Vec<f64> = spreads.iter().map(|s| s.1).collect();
        p1_99.sort_by(f64::total_cmp);
        println!(
            "scan {scan}: {} points, {ring_count} rings, {}..{} points/ring; elevation spread per \
             ring: IQR max {:.2} deg, p1-p99 median {:.2} max {:.2} deg, full max {:.2} deg; \
             sweep fraction rises on {:.2}% of in-ring steps",
            points.len(),
            counts.iter().min().unwrap_or(&0),
            counts.iter().max().unwrap_or(&0),
            worst(|s| s.0),
            p1_99[p1_99.len() / 2],
            worst(|s| s.1),
            worst(|s| s.2),
            100.0 * rising as f64 / steps.max(1) as f64
        );
        assert!(rising as f64 > 0.99 * steps as f64);
    }

    /// (interquartile range, p1-p99 range, full range) of the values.
    fn spread(values: &mut [f64]) -> (f64, f64, f64) {
        values.sort_by(f64::total_cmp);
        let at = |q: f64| values[((values.len() - 1) as f64 * q).round() as usize];
        (at(0.75) - at(0.25), at(0.99) - at(0.01), at(1.0) - at(0.0))
    }
}
