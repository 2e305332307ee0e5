//! The rings a cloud carries itself: the rows of an organized cloud and a
//! ring field, each checked before it is trusted.

use crate::model::{DroppedRingField, RingSource, Scan};

use super::MAX_RING;

/// Drops a ring field whose values cannot be rings (the decoder already
/// does; scans built elsewhere are checked here).
pub(super) fn check_ring_field(scan: &mut Scan) {
    let Some(rings) = &scan.ring else {
        return;
    };
    let reason = if rings.len() != scan.points_m.len() {
        Some(format!(
            "{} values for {} points",
            rings.len(),
            scan.points_m.len()
        ))
    } else {
        rings
            .iter()
            .find(|&&r| r > MAX_RING)
            .map(|r| format!("value {r} is not a ring number (0..={MAX_RING})"))
    };
    if let Some(reason) = reason {
        let name = match &scan.layout.rings {
            RingSource::Field { name } => name.clone(),
            _ => "ring".to_owned(),
        };
        scan.ring = None;
        scan.layout.rings = RingSource::None;
        scan.layout.ring_field_dropped = Some(DroppedRingField { name, reason });
    }
}

/// Rows of an organized cloud: `(rows, cols, row of each point)`; `None`
/// when the scan is not organized or has more rows than ring numbers.
pub(super) fn organized_rows(scan: &Scan) -> Option<(u32, u32, Vec<u16>)> {
    let (rows, cols) = scan.organized?;
    if rows < 2 || cols == 0 || rows > u32::from(MAX_RING) + 1 {
        return None;
    }
    let rings = scan
        .source_index
        .iter()
        .map(|&i| (i / cols).min(rows - 1) as u16)
        .collect::<Vec<u16>>();
    (rings.len() == scan.points_m.len()).then_some((rows, cols, rings))
}

/// The organized rows and a ring field agree when each row holds one ring
/// value and each ring value one row (for 99 % of the points).
pub(super) fn rows_agree(rows: &[u16], field: &[u16]) -> bool {
    if rows.len() != field.len() {
        return false;
    }
    let mut pairs: std::collections::HashMap<(u16, u16), usize> = std::collections::HashMap::new();
    for (&r, &f) in rows.iter().zip(field) {
        *pairs.entry((r, f)).or_default() += 1;
    }
    // Each row's most common ring value, and each ring value's row.
    let mut best_ring: std::collections::HashMap<u16, (u16, usize)> = Default::default();
    for (&(r, f), &n) in &pairs {
        let entry = best_ring.entry(r).or_insert((f, 0));
        if n > entry.1 || (n == entry.1 && f < entry.0) {
            *entry = (f, n);
        }
    }
    let mut rings_used = std::collections::HashSet::new();
    if !best_ring.values().all(|(f, _)| rings_used.insert(*f)) {
        return false;
    }
    let agreeing: usize = best_ring.values().map(|(_, n)| n).sum();
    agreeing as f64 >= 0.99 * rows.len() as f64
}
