//! Range images: rows are beams, columns are azimuth bins (forward at the
//! centre, turning clockwise like the sensor), each cell keeping its nearest
//! return. Also the continuous (row, column) coordinates of any direction, used
//! to render warped scans into the image.

use std::f64::consts::{PI, TAU};

use crate::messages::Scan;

use super::beams::BeamTable;

/// Marks an empty cell in `point`.
pub const NO_POINT: u32 = u32::MAX;

/// The shape of the range images of a pair and how directions map to cells.
#[derive(Debug, Clone)]
pub struct ImageGeometry {
    pub rows: usize,
    pub cols: usize,
    /// Beam elevations, row order (lowest first).
    pub beams: BeamTable,
    /// Row of each ring value when rows come from the clouds' `ring` field
    /// (rings sorted by elevation, so any numbering works); else rows come
    /// from elevation.
    pub ring_to_row: Option<Vec<usize>>,
}

impl ImageGeometry {
    /// Continuous column of an azimuth: 0 behind the sensor, `cols / 2` straight
    /// ahead, increasing clockwise seen from above; in [0, cols).
    pub fn col_f(&self, azimuth_rad: f64) -> f64 {
        let turns = ((PI - azimuth_rad) / TAU).rem_euclid(1.0);
        turns * self.cols as f64
    }

    /// Cell column of an azimuth (nearest bin centre).
    pub fn col_of(&self, azimuth_rad: f64) -> usize {
        (self.col_f(azimuth_rad) + 0.5) as usize % self.cols
    }

    /// Continuous row of an elevation.
    pub fn row_f(&self, elevation_rad: f64) -> f64 {
        self.beams.row_f(elevation_rad)
    }

    pub fn cells(&self) -> usize {
        self.rows * self.cols
    }

    /// The cells around `cell` within `half_rows` beams and `half_cols`
    /// columns, the cell itself excluded. Columns wrap around (the sweep is a
    /// circle), rows do not.
    pub fn neighbours(
        &self,
        cell: usize,
        half_rows: usize,
        half_cols: usize,
    ) -> impl Iterator<Item = usize> + '_ {
        let (row, col) = ((cell / self.cols) as i64, (cell % self.cols) as i64);
        let (half_rows, half_cols) = (half_rows as i64, half_cols as i64);
        (-half_rows..=half_rows).flat_map(move |dr| {
            (-half_cols..=half_cols).filter_map(move |dc| {
                let r = row + dr;
                if (dr == 0 && dc == 0) || r < 0 || r >= self.rows as i64 {
                    return None;
                }
                let c = (col + dc).rem_euclid(self.cols as i64) as usize;
                Some(r as usize * self.cols + c)
            })
        })
    }
}

/// Azimuth and elevation of a point.
pub fn angles(p: &[f32; 3]) -> (f64, f64) {
    let (x, y, z) = (f64::from(p[0]), f64::from(p[1]), f64::from(p[2]));
    (y.atan2(x), z.atan2(x.hypot(y)))
}

/// One scan gridded.
#[derive(Debug, Clone)]
pub struct RangeImage {
    /// Range of the nearest return, metres (NaN: empty).
    pub range_m: Vec<f32>,
    /// Index of that return in the scan's points (`NO_POINT`: empty).
    pub point: Vec<u32>,
    /// Cell of every point of the scan (`NO_POINT` if outside the image).
    pub point_cell: Vec<u32>,
    /// Per point, its cell when the point is the surface that cell measured:
    /// within 5 % of the cell's nearest range. A return hidden behind that
    /// surface (a second echo, a point seen through a gap) takes none of the
    /// cell's values (`NO_POINT`).
    pub point_surface: Vec<u32>,
}

impl RangeImage {
    /// The cell whose surface point `index` is (see `point_surface`).
    pub fn surface_cell(&self, index: usize) -> Option<usize> {
        let cell = *self.point_surface.get(index)?;
        (cell != NO_POINT).then_some(cell as usize)
    }

    pub fn build(scan: &Scan, geometry: &ImageGeometry) -> Self {
        let cells = geometry.cells();
        let mut range_m = vec![f32::NAN; cells];
        let mut point = vec![NO_POINT; cells];
        let mut point_cell = vec![NO_POINT; scan.points_m.len()];
        for (index, p) in scan.points_m.iter().enumerate() {
            let Some(cell) = cell_of(scan, index, p, geometry) else {
                continue;
            };
            point_cell[index] = cell as u32;
            let r = (p[0] * p[0] + p[1] * p[1] + p[2] * p[2]).sqrt();
            // Nearest return wins; ties keep the earlier point (deterministic).
            if range_m[cell].is_nan() || r < range_m[cell] {
                range_m[cell] = r;
                point[cell] = index as u32;
            }
        }
        let point_surface = scan
            .points_m
            .iter()
            .zip(&point_cell)
            .map(|(p, &cell)| {
                if cell == NO_POINT {
                    return NO_POINT;
                }
                let r = (p[0] * p[0] + p[1] * p[1] + p[2] * p[2]).sqrt();
                if r <= range_m[cell as usize] * 1.05 {
                    cell
                } else {
                    NO_POINT
                }
            })
            .collect();
        Self {
            range_m,
            point,
            point_cell,
            point_surface,
        }
    }
}

fn cell_of(scan: &Scan, index: usize, p: &[f32; 3], geometry: &ImageGeometry) -> Option<usize> {
    let (azimuth, elevation) = angles(p);
    let row = match (&scan.ring, &geometry.ring_to_row) {
        (Some(rings), Some(ring_to_row)) => *ring_to_row.get(usize::from(rings[index]))?,
        _ => geometry.beams.row_of(elevation),
    };
    (row < geometry.rows).then(|| row * geometry.cols + geometry.col_of(azimuth))
}

/// The image geometry of a pair: rows from `ring` when both clouds have it
/// (beam elevations measured per ring), else a beam table inferred from the
/// current scan; columns from `columns`, else the most points any row holds.
pub fn geometry_for(
    previous: &Scan,
    current: &Scan,
    columns: Option<usize>,
) -> Option<ImageGeometry> {
    if let (Some(rings), Some(_)) = (&current.ring, &previous.ring) {
        let rows = rings
            .iter()
            .copied()
            .max()
            .map_or(0, |m| usize::from(m) + 1);
        if rows == 0 {
            return None;
        }
        let (beams, ring_to_row) = ring_elevations(current, rows)?;
        let cols = columns
            .unwrap_or_else(|| most_points_per_row(rings.iter().map(|&r| usize::from(r)), rows));
        return (cols >= 8).then_some(ImageGeometry {
            rows,
            cols,
            beams,
            ring_to_row: Some(ring_to_row),
        });
    }
    let elevations: Vec<f32> = current
        .points_m
        .iter()
        .map(|p| angles(p).1 as f32)
        .collect();
    let beams = BeamTable::infer(&elevations, 256)?;
    let rows = beams.len();
    let cols = columns.unwrap_or_else(|| {
        most_points_per_row(elevations.iter().map(|&e| beams.row_of(f64::from(e))), rows)
    });
    (cols >= 8).then_some(ImageGeometry {
        rows,
        cols,
        beams,
        ring_to_row: None,
    })
}

fn most_points_per_row(rows_of_points: impl Iterator<Item = usize>, rows: usize) -> usize {
    let mut counts = vec![0usize; rows];
    for row in rows_of_points {
        if row < rows {
            counts[row] += 1;
        }
    }
    counts.into_iter().max().unwrap_or(0)
}

/// Median elevation of each ring (rings with no points interpolated by ring
/// number), and the row of each ring once sorted by elevation.
fn ring_elevations(scan: &Scan, rows: usize) -> Option<(BeamTable, Vec<usize>)> {
    let rings = scan.ring.as_ref()?;
    let mut per_ring: Vec<Vec<f32>> = vec![Vec::new(); rows];
    for (p, &ring) in scan.points_m.iter().zip(rings) {
        per_ring[usize::from(ring)].push(angles(p).1 as f32);
    }
    let mut known: Vec<(usize, f64)> = Vec::new();
    for (row, values) in per_ring.iter_mut().enumerate() {
        if values.is_empty() {
            continue;
        }
        values.sort_by(f32::total_cmp);
        known.push((row, f64::from(values[values.len() / 2])));
    }
    if known.len() < 2 {
        return None;
    }
    // Fill rings without returns (sky) by linear inter/extrapolation.
    let elevations: Vec<f64> = (0..rows)
        .map(|row| {
            let upper = known
                .iter()
                .position(|(r, _)| *r >= row)
                .unwrap_or(known.len() - 1)
                .max(1);
            let (r0, e0) = known[upper - 1];
            let (r1, e1) = known[upper];
            e0 + (e1 - e0) * (row as f64 - r0 as f64) / (r1 as f64 - r0 as f64)
        })
        .collect();
    let mut order: Vec<usize> = (0..rows).collect();
    order.sort_by(|a, b| elevations[*a].total_cmp(&elevations[*b]).then(a.cmp(b)));
    let mut ring_to_row = vec![0; rows];
    for (row, &ring) in order.iter().enumerate() {
        ring_to_row[ring] = row;
    }
    let mut sorted: Vec<f64> = order.iter().map(|&ring| elevations[ring]).collect();
    // Equal elevations would make row_f flat: nudge them apart.
    for k in 1..sorted.len() {
        if sorted[k] <= sorted[k - 1] {
            sorted[k] = sorted[k - 1] + 1e-6;
        }
    }
    Some((
        BeamTable {
            elevations_rad: sorted,
        },
        ring_to_row,
    ))
}
