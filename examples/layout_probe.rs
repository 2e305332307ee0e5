//! Layout recovered on a real log, and how the fallbacks compare with it:
//! `cargo run --release --example layout_probe -- LOG.mcap`.
//!
//! Per scan: the layout, points per ring (min / median / max); the share of
//! points whose ring from elevation clusters (majority mapping cluster ->
//! ring) matches the ring used; what firing-order detection finds.
use std::collections::HashMap;
use std::sync::Arc;

use looming::engine::layout;
use looming::model::Scan;

fn per_ring(rings: &[u16]) -> (usize, usize, usize) {
    let mut counts: HashMap<u16, usize> = HashMap::new();
    for &r in rings {
        *counts.entry(r).or_default() += 1;
    }
    let mut v: Vec<usize> = counts.into_values().collect();
    v.sort();
    (v[0], v[v.len() / 2], v[v.len() - 1])
}

/// Share of points whose `candidate` ring, mapped to the reference ring most
/// of its points carry, equals their `reference` ring.
fn agreement(candidate: &[u16], reference: &[u16]) -> f64 {
    let mut table: HashMap<(u16, u16), usize> = HashMap::new();
    for (&c, &r) in candidate.iter().zip(reference) {
        *table.entry((c, r)).or_default() += 1;
    }
    let mut best: HashMap<u16, usize> = HashMap::new();
    for (&(c, _), &n) in &table {
        let b = best.entry(c).or_default();
        *b = (*b).max(n);
    }
    best.values().sum::<usize>() as f64 / reference.len() as f64
}

/// The KITTI importer's ring rule before `engine::layout` (lists start
/// straight ahead, counter-clockwise), for comparison.
fn old_derive_rings(points: &[[f32; 3]]) -> Vec<u16> {
    let mut rings = Vec::with_capacity(points.len());
    let (mut ring, mut previous, mut middle) = (0u16, None::<f64>, false);
    for p in points {
        let t = (f64::from(p[1]).atan2(f64::from(p[0])) / std::f64::consts::TAU).rem_euclid(1.0);
        if let Some(prev) = previous
            && prev - t > 0.5
            && middle
        {
            ring += 1;
            middle = false;
        }
        middle |= (0.25..=0.75).contains(&t);
        previous = Some(t);
        rings.push(ring);
    }
    rings
}

fn report(scan: &Scan) {
    let rings = scan.ring.as_deref().unwrap_or(&[]);
    if matches!(
        scan.layout.rings,
        looming::model::RingSource::LaserOrder { .. }
    ) {
        let old = old_derive_rings(&scan.points_m);
        let same = old.iter().zip(rings).filter(|(a, b)| a == b).count();
        println!(
            "laser order vs the importer's former rule: {:.3} % of points on the same ring",
            100.0 * same as f64 / rings.len() as f64
        );
    }
    let (lo, med, hi) = if rings.is_empty() {
        (0, 0, 0)
    } else {
        per_ring(rings)
    };
    let elevation = layout::elevation_rings(&scan.points_m);
    let elev = match (&elevation, rings.is_empty()) {
        (Some(e), false) => format!(
            "{} clusters, {:.2} % match",
            layout::distinct_rings(e),
            100.0 * agreement(e, rings)
        ),
        (Some(e), true) => format!("{} clusters", layout::distinct_rings(e)),
        (None, _) => "none".into(),
    };
    let firing = layout::firing_order(&scan.points_m, &scan.source_index)
        .map_or("none".into(), |f| {
            format!("period {} score {:.3}", f.period, f.score)
        });
    let laser = layout::laser_order(&scan.points_m, layout::RING_COUNTS)
        .map_or("none".into(), |l| format!("{} rings", l.ring_count));
    println!(
        "{} pts | {} | per ring {lo}/{med}/{hi} | elevation clusters: {elev} | firing order: {firing} | laser order: {laser}",
        scan.len(),
        scan.layout
    );
}

fn main() {
    let path = std::env::args().nth(1).expect("log");
    let mut first = true;
    looming::pipeline::replay(
        std::path::Path::new(&path),
        &looming::pipeline::ScanOptions::default(),
        &mut |_| {},
        &mut |pair| {
            let scans: Vec<Arc<Scan>> = if first {
                vec![pair.previous.clone(), pair.current.clone()]
            } else {
                vec![pair.current.clone()]
            };
            first = false;
            for s in scans {
                if std::env::var("STARTS").is_ok() {
                    starts(&s);
                }
                report(&s);
            }
        },
    )
    .expect("replay");
}

#[allow(dead_code)]
pub fn starts(scan: &Scan) {
    let rings = scan.ring.as_deref().unwrap();
    let mut last = u16::MAX;
    let mut out = Vec::new();
    for (p, &r) in scan.points_m.iter().zip(rings) {
        if r != last {
            out.push(format!(
                "{:.1}",
                f64::from(p[1]).atan2(f64::from(p[0])).to_degrees()
            ));
            last = r;
        }
    }
    println!("starts {}", out.join(" "));
}
