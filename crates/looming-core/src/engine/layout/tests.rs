//! Tests of the ring and time recovery for every cloud layout.

use super::*;
use crate::engine::beams::BeamTable;
use crate::model::ScanLayout;
use crate::test_rng::SplitMix64;

/// An HDL-64E-like laser: elevation, azimuth offset, height above the
/// frame origin (m).
#[derive(Clone, Copy)]
struct Laser {
    elevation_rad: f64,
    azimuth_offset_rad: f64,
    height_m: f64,
}

/// 64 irregular lasers in two blocks (upper ~0.33 deg apart, lower ~0.5
/// deg), azimuth offsets up to +-4 deg, 0.12-0.21 m off the origin;
/// listed in an interleaved order (as sensors number them).
fn hdl64_like(rng: &mut SplitMix64) -> Vec<Laser> {
    let mut elevations: Vec<f64> = (0..64)
        .map(|k| {
            if k < 32 {
                2.0 - 0.33 * k as f64 + 0.04 * rng.signed()
            } else {
                -8.8 - 0.5 * (k - 32) as f64 + 0.06 * rng.signed()
            }
        })
        .collect();
    // Interleave: lasers are not listed by elevation.
    let mut order: Vec<usize> = (0..64).collect();
    order.sort_by_key(|&k| (k % 2, k));
    elevations = order.iter().map(|&k| elevations[k]).collect();
    elevations
        .into_iter()
        .enumerate()
        .map(|(k, e)| Laser {
            elevation_rad: e.to_radians(),
            azimuth_offset_rad: (4.0 * rng.signed()).to_radians(),
            height_m: if k % 2 == 0 { 0.21 } else { 0.12 } + 0.01 * rng.signed(),
        })
        .collect()
}

/// A street: a flat road 1.73 m below, walls 6-30 m away depending on
/// the azimuth, a little range noise.
fn range_at(azimuth_rad: f64, elevation_rad: f64, rng: &mut SplitMix64) -> f64 {
    let wall = 6.0 + 24.0 * (0.5 + 0.5 * (3.0 * azimuth_rad).sin());
    let horizontal = wall / elevation_rad.cos();
    let road = if elevation_rad < 0.0 {
        1.73 / (-elevation_rad).sin()
    } else {
        f64::INFINITY
    };
    horizontal.min(road).min(80.0) + 0.01 * rng.signed()
}

fn point(laser: &Laser, azimuth_rad: f64, rng: &mut SplitMix64) -> [f32; 3] {
    let r = range_at(azimuth_rad, laser.elevation_rad, rng);
    let h = r * laser.elevation_rad.cos();
    [
        (h * azimuth_rad.cos()) as f32,
        (h * azimuth_rad.sin()) as f32,
        (r * laser.elevation_rad.sin() + laser.height_m) as f32,
    ]
}

fn scan_of(points: Vec<[f32; 3]>, source_index: Vec<u32>) -> Scan {
    Scan {
        stamp_ns: 0,
        frame_id: "lidar".into(),
        sensor_pose: nalgebra::Isometry3::identity(),
        input_point_count: source_index.last().map_or(0, |&i| i + 1),
        points_m: points,
        intensity: None,
        ring: None,
        time_offset_s: None,
        source_index,
        skipped_invalid_points: 0,
        organized: None,
        layout: ScanLayout::default(),
        sensor_ids: None,
    }
}

/// Share of points whose ring, mapped to the true laser most of its
/// points have, is their true laser; and the number of rings.
fn agreement(rings: &[u16], truth: &[u16]) -> f64 {
    let mut table = std::collections::HashMap::<(u16, u16), usize>::new();
    for (&r, &t) in rings.iter().zip(truth) {
        *table.entry((r, t)).or_default() += 1;
    }
    let mut best = std::collections::HashMap::<u16, usize>::new();
    for (&(r, _), &n) in &table {
        let b = best.entry(r).or_default();
        *b = (*b).max(n);
    }
    best.values().sum::<usize>() as f64 / truth.len() as f64
}

/// A laser-by-laser list, each laser's points in firing order from the
/// seam (plus its azimuth offset) over one turn `direction`.
fn laser_order_scan(direction: Rotation, seam_rad: f64, per_laser: usize) -> (Scan, Vec<u16>) {
    let mut rng = SplitMix64(7);
    let lasers = hdl64_like(&mut rng);
    let (mut points, mut truth) = (Vec::new(), Vec::new());
    for (k, laser) in lasers.iter().enumerate() {
        for i in 0..per_laser {
            let fraction = (i as f64 + 0.5) / per_laser as f64;
            let azimuth = seam_rad + laser.azimuth_offset_rad + direction.sign() * TAU * fraction;
            // Some returns missing (sky, absorbing surfaces).
            if rng.uniform(0.0, 1.0) < 0.05 {
                continue;
            }
            points.push(point(laser, azimuth, &mut rng));
            truth.push(k as u16);
        }
    }
    let n = points.len() as u32;
    (scan_of(points, (0..n).collect()), truth)
}

#[test]
fn laser_order_both_directions() {
    for (direction, seam_deg) in [
        (Rotation::CounterClockwise, 180.0),
        (Rotation::Clockwise, 40.0),
    ] {
        let (mut scan, truth) = laser_order_scan(direction, f64::to_radians(seam_deg), 900);
        complete(&mut scan, 0.1);
        assert_eq!(scan.layout.rings, RingSource::LaserOrder { direction });
        assert_eq!(scan.layout.ring_count, 64);
        let rings = scan.ring.as_deref().expect("rings");
        let same = rings.iter().zip(&truth).filter(|(a, b)| a == b).count();
        assert!(
            same as f64 > 0.995 * truth.len() as f64,
            "{direction:?}: {same} of {} on their laser",
            truth.len()
        );
        let TimeSource::Azimuth {
            direction: d,
            seam_deg: s,
        } = scan.layout.times
        else {
            panic!("{:?}", scan.layout.times);
        };
        assert_eq!(d, direction);
        assert!(
            wrap_turn((s - seam_deg) / 360.0).abs() < 3.0 / 360.0,
            "seam {s}"
        );
        let times = scan.time_offset_s.as_deref().expect("times");
        assert!(times.iter().all(|&t| (0.0..0.1).contains(&t)));
        // The azimuths the recovery took, reused for the times: each
        // point's time as its own azimuth gives it, to the bit.
        let sweep = laser_order(&scan.points_m, RING_COUNTS)
            .expect("a laser order")
            .sweep;
        let recomputed = scan
            .points_m
            .iter()
            .map(|p| ((sweep.fraction_of_turn(azimuth_turn(p)) * 0.1) as f32).to_bits());
        assert!(recomputed.eq(times.iter().map(|t| t.to_bits())));
        // Along a laser the time rises but for the few points fired
        // before the common seam.
        let rises = times
            .windows(2)
            .zip(rings.windows(2))
            .filter(|(t, r)| r[0] == r[1] && t[1] >= t[0])
            .count();
        assert!(rises as f64 > 0.97 * times.len() as f64, "{rises}");
    }
}

#[test]
fn azimuth_cut_lists_have_their_seam_half_a_turn_away() {
    // KITTI: every list sorted by azimuth counter-clockwise from
    // straight ahead (offsets already applied).
    let mut rng = SplitMix64(3);
    let lasers = hdl64_like(&mut rng);
    let mut points = Vec::new();
    for laser in &lasers {
        for i in 0..1000 {
            let azimuth = TAU * (i as f64 + 0.5) / 1000.0;
            points.push(point(laser, azimuth, &mut rng));
        }
    }
    let n = points.len() as u32;
    let mut scan = scan_of(points, (0..n).collect());
    complete(&mut scan, 0.1);
    assert_eq!(scan.layout.ring_count, 64);
    let TimeSource::Azimuth {
        direction,
        seam_deg,
    } = scan.layout.times
    else {
        panic!("{:?}", scan.layout.times);
    };
    assert_eq!(direction, Rotation::CounterClockwise);
    assert!((seam_deg - 180.0).abs() < 1.0, "{seam_deg}");
    assert!(
        scan.layout.to_string().contains("behind"),
        "{}",
        scan.layout
    );
    let expected: Vec<u16> = (0..64).flat_map(|k| [k; 1000]).collect();
    assert_eq!(scan.ring.as_deref(), Some(expected.as_slice()));
}

/// Driver order: columns of one firing of every laser, `dropped` points
/// (no return) removed but counted in the source index.
fn firing_order_scan(direction: Rotation, columns: usize, dropped: f64) -> (Scan, Vec<u16>) {
    let mut rng = SplitMix64(11);
    let lasers = hdl64_like(&mut rng);
    let (mut points, mut index, mut truth) = (Vec::new(), Vec::new(), Vec::new());
    for c in 0..columns {
        let azimuth = 0.3 + direction.sign() * TAU * c as f64 / columns as f64;
        for (k, laser) in lasers.iter().enumerate() {
            if rng.uniform(0.0, 1.0) < dropped {
                continue;
            }
            points.push(point(laser, azimuth + laser.azimuth_offset_rad, &mut rng));
            index.push((c * lasers.len() + k) as u32);
            truth.push(k as u16);
        }
    }
    (scan_of(points, index), truth)
}

#[test]
fn firing_order_with_dropouts() {
    for direction in [Rotation::Clockwise, Rotation::CounterClockwise] {
        let (mut scan, truth) = firing_order_scan(direction, 1000, 0.15);
        complete(&mut scan, 0.1);
        assert_eq!(scan.layout.rings, RingSource::FiringOrder { period: 64 });
        assert_eq!(scan.ring.as_deref(), Some(truth.as_slice()));
        let TimeSource::Azimuth {
            direction: d,
            seam_deg,
        } = scan.layout.times
        else {
            panic!("{:?}", scan.layout.times);
        };
        assert_eq!(d, direction);
        assert!((seam_deg - 0.3f64.to_degrees()).abs() < 5.0, "{seam_deg}");
    }
}

#[test]
fn off_axis_lasers_cluster_by_laser() {
    // No usable order: the points shuffled.
    let (scan, truth) = laser_order_scan(Rotation::Clockwise, 0.0, 1200);
    let mut rng = SplitMix64(5);
    let mut order: Vec<usize> = (0..truth.len()).collect();
    for i in (1..order.len()).rev() {
        order.swap(i, (rng.next_u64() % (i as u64 + 1)) as usize);
    }
    let points: Vec<[f32; 3]> = order.iter().map(|&i| scan.points_m[i]).collect();
    let truth: Vec<u16> = order.iter().map(|&i| truth[i]).collect();
    let n = points.len() as u32;
    let mut scan = scan_of(points, (0..n).collect());
    complete(&mut scan, 0.1);
    assert_eq!(scan.layout.rings, RingSource::Elevation);
    assert_eq!(scan.layout.times, TimeSource::Stamp);
    assert!(scan.time_offset_s.is_none());
    let rings = scan.ring.as_deref().expect("rings");
    let share = agreement(rings, &truth);
    // Measured 0.93 on this scene: short of one laser per row (the
    // nearest road returns still cross beams), but well above the
    // uncorrected table below.
    assert!(share > 0.9, "{share}");
    assert!(
        (56..=72).contains(&scan.layout.ring_count),
        "{}",
        scan.layout.ring_count
    );
    // Without the correction (elevation alone) the near road smears
    // across beams: the correction must do better.
    let elevations: Vec<f32> = scan.points_m.iter().map(|p| elevation(p) as f32).collect();
    let table = BeamTable::infer(&elevations, 256).expect("table");
    let plain: Vec<u16> = elevations
        .iter()
        .map(|&e| table.row_of(f64::from(e)) as u16)
        .collect();
    assert!(
        share > agreement(&plain, &truth),
        "{share} vs {}",
        agreement(&plain, &truth)
    );
}

#[test]
fn organized_rows_and_ring_fields() {
    let (rows, cols) = (8u32, 100u32);
    let mut points = Vec::new();
    let mut index = Vec::new();
    for r in 0..rows {
        for c in 0..cols {
            if (r * cols + c) % 7 == 3 {
                continue; // no return
            }
            let az = TAU * f64::from(c) / f64::from(cols);
            let el = (10.0 - 3.0 * f64::from(r)).to_radians();
            points.push([
                (10.0 * el.cos() * az.cos()) as f32,
                (10.0 * el.cos() * az.sin()) as f32,
                (10.0 * el.sin()) as f32,
            ]);
            index.push(r * cols + c);
        }
    }
    let rows_of: Vec<u16> = index.iter().map(|&i| (i / cols) as u16).collect();
    let organized = |ring: Option<Vec<u16>>| {
        let mut scan = scan_of(points.clone(), index.clone());
        scan.organized = Some((rows, cols));
        scan.layout = ScanLayout::from_fields(ring.as_ref().map(|_| "channel"), Some("t"));
        scan.ring = ring;
        complete(&mut scan, 0.1);
        scan
    };
    let plain = organized(None);
    assert_eq!(
        plain.layout.rings,
        RingSource::Organized {
            rows,
            cols,
            ring_field: None
        }
    );
    assert_eq!(plain.ring.as_deref(), Some(rows_of.as_slice()));
    assert_eq!(plain.layout.ring_count, 8);
    assert_eq!(
        plain.layout.times,
        TimeSource::Stamp,
        "no time field, not in firing order"
    );
    assert!(
        plain.layout.to_string().starts_with("organized 8 x 100"),
        "{}",
        plain.layout
    );
    // A field numbering the rows the other way agrees.
    let agreeing = organized(Some(rows_of.iter().map(|&r| 7 - r).collect()));
    assert_eq!(
        agreeing.layout.rings,
        RingSource::Organized {
            rows,
            cols,
            ring_field: Some("channel".into())
        }
    );
    // A field that does not follow the rows is used, and said.
    let other: Vec<u16> = (0..points.len()).map(|i| (i % 5) as u16).collect();
    let disagreeing = organized(Some(other.clone()));
    assert_eq!(
        disagreeing.layout.rings,
        RingSource::Field {
            name: "channel".into()
        }
    );
    assert_eq!(disagreeing.ring, Some(other));
    assert!(disagreeing.layout.note.is_some());
}

#[test]
fn ring_field_is_kept_with_its_name() {
    let (mut scan, truth) = firing_order_scan(Rotation::Clockwise, 200, 0.0);
    scan.ring = Some(truth.clone());
    scan.layout = ScanLayout::from_fields(Some("laser_id"), None);
    complete(&mut scan, 0.1);
    assert_eq!(
        scan.layout.rings,
        RingSource::Field {
            name: "laser_id".into()
        }
    );
    assert_eq!(scan.ring, Some(truth));
    assert_eq!(scan.layout.ring_count, 64);
    // The field says nothing of the order: times stay the stamp's.
    assert_eq!(scan.layout.times, TimeSource::Stamp);
    assert_eq!(scan.layout.rings_text(), "ring field `laser_id` (64 rings)");
}

#[test]
fn huge_ring_values_drop_the_field() {
    let (mut scan, _) = firing_order_scan(Rotation::Clockwise, 300, 0.1);
    let mut rings: Vec<u16> = vec![3; scan.len()];
    rings[17] = 60_000;
    scan.ring = Some(rings);
    scan.layout = ScanLayout::from_fields(Some("ring"), None);
    complete(&mut scan, 0.1);
    let dropped = scan.layout.ring_field_dropped.as_ref().expect("dropped");
    assert_eq!(dropped.name, "ring");
    // It falls through to what the order shows.
    assert_eq!(scan.layout.rings, RingSource::FiringOrder { period: 64 });
    // A ring list of the wrong length is dropped too.
    let (mut short, _) = firing_order_scan(Rotation::Clockwise, 300, 0.1);
    short.ring = Some(vec![1, 2]);
    complete(&mut short, 0.1);
    assert!(short.layout.ring_field_dropped.is_some());
}

#[test]
fn garbage_gives_no_rings_and_no_panic() {
    let mut rng = SplitMix64(99);
    for n in [0usize, 1, 5, 300, 20_000] {
        let points: Vec<[f32; 3]> = (0..n)
            .map(|_| {
                [
                    rng.uniform(-50.0, 50.0) as f32,
                    rng.uniform(-50.0, 50.0) as f32,
                    rng.uniform(-5.0, 5.0) as f32,
                ]
            })
            .collect();
        let mut scan = scan_of(points, (0..n as u32).collect());
        complete(&mut scan, f64::NAN);
        assert_eq!(scan.layout.rings, RingSource::None, "{n} points");
        assert!(scan.ring.is_none());
        assert_eq!(scan.layout.times, TimeSource::Stamp);
    }
    // Non-finite and degenerate points.
    let mut odd = scan_of(
        vec![
            [f32::NAN, 0.0, 0.0],
            [0.0, 0.0, 1.0],
            [f32::INFINITY, 1.0, 1.0],
            [0.0; 3],
        ],
        vec![0, 1, 2, 3],
    );
    complete(&mut odd, 0.1);
    assert_eq!(odd.layout.rings, RingSource::None);
}

#[test]
fn descriptions() {
    let layout = ScanLayout {
        rings: RingSource::LaserOrder {
            direction: Rotation::CounterClockwise,
        },
        ring_count: 64,
        times: TimeSource::Azimuth {
            direction: Rotation::CounterClockwise,
            seam_deg: 180.0,
        },
        ring_field_dropped: None,
        note: None,
        origin: None,
    };
    assert_eq!(
        layout.to_string(),
        "laser order (64 rings, counter-clockwise), times from azimuth (counter-clockwise, seam at 180 deg, behind)"
    );
    assert_eq!(crate::model::layout::bearing_word(-179.0), Some("behind"));
    assert_eq!(crate::model::layout::bearing_word(45.0), None);
    assert_eq!(distinct_rings(&[0, 5, 5, 1023]), 3);
}
