//! Rasterising the moved mesh into the target's rays: the triangles
//! between two source rows ([`rasterize_row`]) or, on a sparse sensor, the
//! segments along one ring ([`rasterize_ring`]); each target ray inside
//! gives a [`Candidate`] (range, time, normal).

use nalgebra::Vector3;

use super::bridges::quad_bits;
use super::flat_triangle::{FlatTriangle, SharedDiagonal};
use super::full_quad::WholeQuads;
use super::mesh::{
    EDGE_FIRST, EDGE_SECOND, JOIN_RIGHT, Proxies, QUAD_FIRST, QUAD_SECOND, on_one_surface,
};
use super::{Candidate, REACH_SLACK, Source, Span, Target, Vertex, Vertices};
use crate::engine::grid::{ImageGeometry, wrap_col};
use crate::model::StampNs;

/// The triangles of the quads whose top-left vertex lies in source columns
/// `columns`, rasterised column by column (the vertices are stored
/// column-major: a column's quads read consecutive vertices, where a row's
/// read one vertex pair per column of the whole buffer).
pub(super) fn rasterize_columns(
    source: &Source,
    target: &Target,
    geometry: &ImageGeometry,
    vertices: &Vertices,
    proxies: &Proxies,
    columns: std::ops::Range<usize>,
) -> Vec<Candidate> {
    let (rows, cols) = (geometry.rows, geometry.cols);
    // About one candidate per quad: room for all without regrowing.
    let quads = columns.len() * rows.saturating_sub(1);
    let mut out = Vec::with_capacity(quads + quads / 2);
    // Per pair of rows, the table of triangles that holds for all its
    // quads, if one does: the source's plan of its bridges where both rows
    // were bridged as planned (`BridgedMesh`: most of KITTI's), else the
    // scan's own where neither row bridged a dropout (every vertex stands
    // for its own cell); `None` where each quad is judged on its own.
    let planned = &source.bridged.bits;
    let tables: Vec<Option<&[u8]>> = (0..rows.saturating_sub(1))
        .map(|row| {
            let (here, below) = (row, row + 1);
            if proxies.as_planned[here] && proxies.as_planned[below] {
                Some(planned.as_slice())
            } else if !proxies.bridged_row[here] && !proxies.bridged_row[below] {
                Some(source.surfaces.joins.as_slice())
            } else {
                None
            }
        })
        .collect();
    let whole = WholeQuads::of(target, geometry);
    let joins = &source.surfaces.joins;
    for col in columns {
        let next = if col + 1 == cols { 0 } else { col + 1 };
        // The quads' left and right vertices, each column's rows in order.
        let left = &vertices.at[col * rows..(col + 1) * rows];
        let right = &vertices.at[next * rows..(next + 1) * rows];
        for (row, &table) in tables.iter().enumerate() {
            let (own, bits) = match table {
                Some(table) => (true, table[row * cols + col]),
                None => (false, joins[row * cols + col]),
            };
            if own && bits & (QUAD_FIRST | QUAD_SECOND) == 0 {
                continue;
            }
            if own && bits & (QUAD_FIRST | QUAD_SECOND) == QUAD_FIRST | QUAD_SECOND {
                let quad = [&left[row], &right[row], &left[row + 1], &right[row + 1]];
                if whole.rasterize(quad, bits, &mut out) {
                    continue;
                }
            }
            rasterize_quad_at(
                source,
                (target, &whole),
                geometry,
                (vertices, proxies),
                (row, col),
                own.then_some(bits),
                &mut out,
            );
        }
    }
    out
}

/// The quad at source (`row`, `col`) rasterised into `out`, where it is
/// not a whole quad ([`WholeQuads`]: one in twenty on a dense sensor);
/// `bits` its triangles' bits where a table holds them (`mesh_joins`'),
/// `None` where a vertex stands for a bridged dropout the source did not
/// plan ([`quad_bits`] then judges them). (Out of line: the whole quads' loop keeps its values in
/// registers.)
#[inline(never)]
fn rasterize_quad_at(
    source: &Source,
    (target, whole): (&Target, &WholeQuads),
    geometry: &ImageGeometry,
    (vertices, proxies): (&Vertices, &Proxies),
    (row, col): (usize, usize),
    bits: Option<u8>,
    out: &mut Vec<Candidate>,
) {
    let cols = geometry.cols;
    let a = row * cols + col;
    let next = if col + 1 == cols { 0 } else { col + 1 };
    // Either triangle needs the diagonal's two vertices.
    let (Some(vb), Some(vc)) = (vertices.get(row, next), vertices.get(row + 1, col)) else {
        return;
    };
    let (va, vd) = (vertices.get(row, col), vertices.get(row + 1, next));
    // A quad of a row bridged otherwise than planned: the plan's bits
    // where its own vertices stand for the cells planned (all but those
    // near the difference), else its edges judged on the cells they stand
    // for. (Bits from the caller: it tried the whole quad.)
    let (bits, whole_tried) = match bits {
        Some(bits) => (bits, true),
        None => {
            let (b, c) = (a - col + next, a + cols);
            let bits = source
                .bridged
                .bits_where_planned(&proxies.cell, [a, b, c, b + cols])
                .unwrap_or_else(|| quad_bits(source.surfaces, &proxies.cell, a));
            (bits, false)
        }
    };
    // The triangles' vertices in the mesh's order: (a, b, c), (b, d, c).
    let quad = [
        va.filter(|_| bits & QUAD_FIRST != 0)
            .map(|va| ([va, vb, vc], bits & EDGE_FIRST != 0)),
        vd.filter(|_| bits & QUAD_SECOND != 0)
            .map(|vd| ([vb, vd, vc], bits & EDGE_SECOND != 0)),
    ];
    // Both triangles across a bridged row judged here: the whole quads'
    // path where it takes them, the same candidates as `rasterize_quad`'s
    // (the raster tests hold them to each other).
    if let (false, [Some(([va, _, _], first)), Some(([_, vd, _], second))]) = (whole_tried, quad) {
        let bits = if first { EDGE_FIRST } else { 0 } | if second { EDGE_SECOND } else { 0 };
        if whole.rasterize([va, vb, vc, vd], bits, out) {
            return;
        }
    }
    if (quad[0].is_none() && quad[1].is_none()) || rasterize_quad(target, geometry, quad, out) {
        return;
    }
    for (corners, edge) in quad.into_iter().flatten() {
        rasterize_triangle(target, geometry, corners, edge, out);
    }
}

/// A sparse sensor's ring rendered into the same ring of the target: each
/// segment between neighbouring returns of one surface, moved, covers the
/// target rays of that laser between its ends; the range is each ray
/// against the plane through the segment with the returns' fitted normals
/// (beams 11 degrees apart share no surface to mesh across).
pub(super) fn rasterize_ring(
    source: &Source,
    target: &Target,
    geometry: &ImageGeometry,
    vertices: &Vertices,
    proxy: &[u32],
    row: usize,
) -> Vec<Candidate> {
    let cols = geometry.cols;
    let rows = geometry.rows;
    let mut out = Vec::new();
    for col in 0..cols {
        let next = (col + 1) % cols;
        let (a, b) = (row * cols + col, row * cols + next);
        let (Some(va), Some(vb)) = (vertices.get(row, col), vertices.get(row, next)) else {
            continue;
        };
        let (na, nb) = (
            vertices.normal[col * rows + row],
            vertices.normal[next * rows + row],
        );
        let joined = source.surfaces.joins[a] & JOIN_RIGHT != 0;
        if !on_one_surface(source.surfaces, proxy, (a, b), joined) {
            continue;
        }
        let (pa, pb) = (proxy[a] as usize, proxy[b] as usize);
        let edge = source.surfaces.edge[pa] || source.surfaces.edge[pb];
        let (ca, cb) = (va.col, unwrap_near(vb.col, va.col, cols));
        if (cb - ca).abs() < 1e-9 || (cb - ca).abs() > MAX_SPAN_CELLS {
            continue;
        }
        for col_unwrapped in (ca.min(cb).floor() as i64)..=(ca.max(cb).ceil() as i64) {
            let cell = row * cols + wrap_col(col_unwrapped, cols as i64);
            if !target.surfaces.range_m[cell].is_finite() {
                continue;
            }
            let tc = unwrap_near(f64::from(target.coords[cell].1), ca, cols);
            let w = (tc - ca) / (cb - ca);
            if !(-1e-9..=1.0 + 1e-9).contains(&w) {
                continue;
            }
            let normal = na * (1.0 - w) + nb * w;
            if normal.norm_squared() < 0.25 {
                continue;
            }
            let normal = normal.normalize();
            let point = va.position.coords * (1.0 - w) + vb.position.coords * w;
            let d = target.surfaces.direction[cell];
            let e = Vector3::new(f64::from(d[0]), f64::from(d[1]), f64::from(d[2]));
            let along = normal.dot(&e);
            if along.abs() < 1e-3 {
                continue;
            }
            let range = normal.dot(&point) / along;
            if !(range > 0.0 && range.is_finite()) {
                continue;
            }
            out.push(Candidate {
                cell: cell as u32,
                range_m: range as f32,
                time_ns: (va.time_ns as f64 * (1.0 - w) + vb.time_ns as f64 * w).round() as StampNs,
                normal: [normal.x as f32, normal.y as f32, normal.z as f32],
                edge,
            });
        }
    }
    out
}

/// The smaller of two image coordinates by one comparison: `f64::min`
/// also sorts out NaN, which no vertex's coordinates hold (finite ranges
/// and angles), at three times the instructions, and a quad's set-up takes
/// two dozen.
#[inline(always)]
pub(super) fn least(a: f64, b: f64) -> f64 {
    if b < a { b } else { a }
}

/// The larger of two image coordinates by one comparison ([`least`]).
#[inline(always)]
pub(super) fn most(a: f64, b: f64) -> f64 {
    if b > a { b } else { a }
}

/// Largest triangle (in cells) worth rasterising: anything bigger is a bridge.
pub(super) const MAX_SPAN_CELLS: f64 = 24.0;

/// Every target ray inside a quad's triangles (`None` for one the mesh
/// does not hold), into `out`, where the quad lies away from the seam of
/// the sweep (columns need no unwrapping): the cells of the quad's box are
/// visited once for both triangles, the first triangle's candidate of a
/// cell before the second's, as the z-buffer keeps the first of equal
/// ranges. The same candidates as [`rasterize_triangle`] on each (a larger
/// box holds no more rays inside a triangle). `false`, with nothing done,
/// near the seam.
fn rasterize_quad<'v>(
    target: &Target,
    geometry: &ImageGeometry,
    triangles: [Option<([&'v Vertex; 3], bool)>; 2],
    out: &mut Vec<Candidate>,
) -> bool {
    let cols = geometry.cols as f64;
    let col_reach = target.reach.1 + REACH_SLACK;
    let (mut r_min, mut r_max) = (f64::INFINITY, f64::NEG_INFINITY);
    let (mut c_min, mut c_max) = (f64::INFINITY, f64::NEG_INFINITY);
    for (v, _) in triangles.iter().flatten() {
        for vertex in v {
            (r_min, r_max) = (least(r_min, vertex.row), most(r_max, vertex.row));
            (c_min, c_max) = (least(c_min, vertex.col), most(c_max, vertex.col));
        }
    }
    // Away from the seam, every column lies within a quarter turn of every
    // other: unwrapping leaves them as they are, and the box's columns need
    // no wrapping. Nor do the coordinates of the box's rays (within a reach
    // of their columns, so between 0 and `cols`, and within half a turn of
    // the triangle's columns): they are taken as they are.
    if !(c_min - 2.0 * col_reach >= 1.0
        && c_max + 2.0 * col_reach <= cols - 2.0
        && c_max - c_min <= cols / 4.0
        && col_reach <= cols / 16.0)
    {
        return false;
    }
    // Where the whole quad spans no more than a triangle may, neither of
    // its triangles needs its own check.
    let narrow = r_max - r_min <= MAX_SPAN_CELLS && c_max - c_min <= MAX_SPAN_CELLS;
    let set_up = |(v, edge): ([&'v Vertex; 3], bool)| {
        if narrow {
            FlatTriangle::narrow(v, edge)
        } else {
            FlatTriangle::set_up(v, edge)
        }
    };
    let first = triangles[0].and_then(set_up);
    let second = triangles[1].and_then(set_up);
    if first.is_none() && second.is_none() {
        return true;
    }
    let mut planes = [None, None];
    let ((row_lo, row_hi), (col_lo, col_hi)) =
        quad_cells(target, geometry, (r_min, r_max), (c_min, c_max));
    let shared = first
        .as_ref()
        .zip(second.as_ref())
        .and_then(|(a, b)| SharedDiagonal::of(a, b));
    for row in row_lo..=row_hi {
        for col in col_lo..=col_hi {
            let cell = row * geometry.cols + col;
            if !target.surfaces.range_m[cell].is_finite() {
                continue;
            }
            let (tr, tc) = target.coords[cell];
            let (tr, tc) = (f64::from(tr), f64::from(tc));
            let weights = match &shared {
                Some(shared) => shared.weights(tr, tc),
                None => [&first, &second].map(|t| t.as_ref().and_then(|t| t.weights(tr, tc))),
            };
            for ((triangle, plane), w) in
                [&first, &second].into_iter().zip(&mut planes).zip(weights)
            {
                if let (Some(triangle), Some(w)) = (triangle, w)
                    && let Some(hit) = hit(target, cell, triangle.v, w, triangle.edge, plane)
                {
                    out.push(hit);
                }
            }
        }
    }
    true
}

/// The range `lo..=hi` of rows (or columns) without those at its ends
/// whose rays all lie short of `[min, max]` by their band's reach: the
/// box's global reach comes from a few stray rays, and a row of rays
/// within a tenth of their row (most of KITTI's) holds none of a quad
/// whose rows begin half a row past it. (Rows in between are kept: they
/// hold rays in the box, or, rarely, ones the weights reject.) `lo > hi`
/// where none is left.
#[inline(always)]
pub(super) fn within_bands(
    spans: &[Span],
    (mut lo, mut hi): (usize, usize),
    (min, max): (f64, f64),
) -> (usize, usize) {
    while lo <= hi && spans[lo].highest < min {
        lo += 1;
    }
    while hi > lo && spans[hi].lowest > max {
        hi -= 1;
    }
    (lo, hi)
}

/// The candidate of target `cell`, whose ray falls inside triangle `v`
/// with barycentric weights `w`: the range where it meets the triangle's
/// plane (computed once a ray falls inside: about half the triangles hold
/// none, a quad's two share its one or two rays).
#[inline(always)]
pub(super) fn hit(
    target: &Target,
    cell: usize,
    v: [&Vertex; 3],
    [w0, w1, w2]: [f64; 3],
    edge: bool,
    plane: &mut Option<TrianglePlane>,
) -> Option<Candidate> {
    let direction = target.surfaces.direction[cell];
    let e = Vector3::new(
        f64::from(direction[0]),
        f64::from(direction[1]),
        f64::from(direction[2]),
    );
    let plane = plane.get_or_insert_with(|| TrianglePlane::through(v));
    let along = plane.normal.dot(&e);
    if along.abs() < plane.parallel {
        return None;
    }
    let range = plane.offset / along;
    // Positive and finite, by two comparisons (`is_finite` beside the sign
    // took two dozen instructions: one hit per quad).
    if !(range > 0.0 && range < f64::INFINITY) {
        return None;
    }
    let time = (w0 * v[0].time_ns as f64 + w1 * v[1].time_ns as f64 + w2 * v[2].time_ns as f64)
        .round() as StampNs;
    Some(Candidate {
        cell: cell as u32,
        range_m: range as f32,
        time_ns: time,
        normal: plane.unit,
        edge,
    })
}

/// `c` moved by whole turns next to column `near` (across the seam behind
/// the sensor).
#[inline]
fn unwrap_near(c: f64, near: f64, cols: usize) -> f64 {
    let cols = cols as f64;
    if c - near > cols / 2.0 {
        c - cols
    } else if near - c > cols / 2.0 {
        c + cols
    } else {
        c
    }
}

/// Every target ray inside the triangle `v` (image coordinates), with the
/// range where it meets the triangle's plane, into `out`.
fn rasterize_triangle(
    target: &Target,
    geometry: &ImageGeometry,
    v: [&Vertex; 3],
    edge: bool,
    out: &mut Vec<Candidate>,
) {
    // Unwrap columns around the first vertex (the seam behind the sensor).
    let unwrap = |c: f64| unwrap_near(c, v[0].col, geometry.cols);
    let (r, c) = (
        [v[0].row, v[1].row, v[2].row],
        [v[0].col, unwrap(v[1].col), unwrap(v[2].col)],
    );
    let Some(((row_lo, row_hi), (col_lo, col_hi))) = cells_in_reach(target, geometry, &r, &c)
    else {
        return;
    };
    let Some(triangle) = FlatTriangle::at(v, (&r, &c), edge) else {
        return;
    };
    let mut plane = None;
    let cols_i = geometry.cols as i64;
    for row in row_lo..=row_hi {
        for col_unwrapped in col_lo..=col_hi {
            let col = wrap_col(col_unwrapped, cols_i);
            let cell = row * geometry.cols + col;
            if !target.surfaces.range_m[cell].is_finite() {
                continue;
            }
            let (tr, tc) = target.coords[cell];
            // Bring the target's column next to the triangle's.
            let tc = unwrap_near(f64::from(tc), c[0], geometry.cols);
            let Some(w) = triangle.weights(f64::from(tr), tc) else {
                continue;
            };
            if let Some(hit) = hit(target, cell, v, w, edge, &mut plane) {
                out.push(hit);
            }
        }
    }
}

/// The target cells whose coordinates can lie in the bounding box of the
/// triangle with rows `r` and (unwrapped) columns `c`: `((first row, last
/// row), (first column, last column))`, columns unwrapped. `None` for a
/// triangle wider than [`MAX_SPAN_CELLS`] (a bridge) or an empty box.
#[inline]
fn cells_in_reach(
    target: &Target,
    geometry: &ImageGeometry,
    r: &[f64; 3],
    c: &[f64; 3],
) -> Option<((usize, usize), (i64, i64))> {
    let (r_min, r_max) = (least(least(r[0], r[1]), r[2]), most(most(r[0], r[1]), r[2]));
    let (c_min, c_max) = (least(least(c[0], c[1]), c[2]), most(most(c[0], c[1]), c[2]));
    if r_max - r_min > MAX_SPAN_CELLS || c_max - c_min > MAX_SPAN_CELLS {
        return None;
    }
    let ((row_lo, row_hi), (col_lo, col_hi)) =
        box_in_reach(target, geometry, (r_min, r_max), (c_min, c_max));
    let (col_lo, col_hi) = (col_lo as i64, col_hi as i64);
    if row_lo > row_hi || col_lo > col_hi {
        return None;
    }
    Some(((row_lo, row_hi), (col_lo, col_hi)))
}

/// The rows (within the image) and the columns (unwrapped, whole but as
/// coordinates) of the target cells whose rays can lie in the box of rows
/// `[r_min, r_max]` and columns `[c_min, c_max]`: the box widened by the
/// target's reach (about half a cell, where the whole cells around the box
/// hold some three times as many).
#[inline]
fn box_in_reach(
    target: &Target,
    geometry: &ImageGeometry,
    (r_min, r_max): (f64, f64),
    (c_min, c_max): (f64, f64),
) -> ((usize, usize), (f64, f64)) {
    let (row_reach, col_reach) = (target.reach.0 + REACH_SLACK, target.reach.1 + REACH_SLACK);
    let (row_lo, row_hi) = box_rows((r_min, r_max), row_reach, geometry.rows - 1);
    let col_lo = most(c_min.floor(), (c_min - col_reach).ceil());
    let col_hi = least(c_max.ceil(), (c_max + col_reach).floor());
    ((row_lo, row_hi), (col_lo, col_hi))
}

/// [`box_in_reach`]'s rows, within the image (`last_row` its last), of
/// the box of rows `[r_min, r_max]`, `row_reach` the target's reach plus
/// [`REACH_SLACK`].
#[inline(always)]
pub(super) fn box_rows(
    (r_min, r_max): (f64, f64),
    row_reach: f64,
    last_row: usize,
) -> (usize, usize) {
    let row_lo = index_of(most(most(r_min.floor(), (r_min - row_reach).ceil()), 0.0));
    let row_hi = index_of(least(r_max.ceil(), (r_max + row_reach).floor())).min(last_row);
    (row_lo, row_hi)
}

/// The target cells whose rays can lie in a quad's box of rows `[r_min,
/// r_max]` and columns `[c_min, c_max]` (away from the seam):
/// [`box_in_reach`]'s as indices, less the rows and columns at its ends
/// that [`within_bands`] drops (`lo > hi` where none is left).
#[inline]
pub(super) fn quad_cells(
    target: &Target,
    geometry: &ImageGeometry,
    rows: (f64, f64),
    cols: (f64, f64),
) -> ((usize, usize), (usize, usize)) {
    let ((row_lo, row_hi), (col_lo, col_hi)) = box_in_reach(target, geometry, rows, cols);
    let (col_lo, col_hi) = (index_of(col_lo), index_of(col_hi));
    let bands = &target.bands;
    (
        within_bands(&bands.row_spans, (row_lo, row_hi), rows),
        within_bands(&bands.col_spans, (col_lo, col_hi), cols),
    )
}

/// A whole coordinate as an index, as `x as usize` takes it for every
/// `x` below 2^63 (negative and NaN to 0), and `i64::MAX` above (which no
/// index reaches either): half the instructions of the unsigned
/// conversion, four per quad.
#[inline(always)]
pub(super) fn index_of(x: f64) -> usize {
    (x as i64).max(0) as usize
}

/// The plane through a triangle's vertices.
pub(super) struct TrianglePlane {
    /// `(b - a) x (c - a)`, unnormalised.
    normal: Vector3<f64>,
    /// `1e-12` of its length: a ray at a smaller `normal . e` runs along
    /// the plane.
    parallel: f64,
    /// `normal . a`.
    offset: f64,
    /// The unit normal, as the candidates carry it.
    unit: [f32; 3],
}

impl TrianglePlane {
    fn through(v: [&Vertex; 3]) -> Self {
        let normal = (v[1].position - v[0].position).cross(&(v[2].position - v[0].position));
        let normal_norm = normal.norm();
        // The triangle's own orientation. (The mean of the vertices' fitted
        // normals is steadier on a real sensor, 1.5 % more trusted returns
        // on the HDL-64E, but misses creases the triangle sees: fused RMSE
        // +23 % on the synthetic `crossing` at 64 x 2048.)
        let unit = normal / normal_norm.max(1e-300);
        Self {
            normal,
            parallel: 1e-12 * normal_norm,
            offset: normal.dot(&v[0].position.coords),
            unit: [unit.x as f32, unit.y as f32, unit.z as f32],
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::engine::beams::BeamTable;
    use crate::engine::surface::Surfaces;
    use crate::engine::warp::test_surfaces::unit;
    use nalgebra::Point3;

    /// A target whose rays' coordinates lie up to `spread` cell from their
    /// cells, but for every `stray`th cell's, which lies 0.95 of a row and
    /// of a column off (KITTI's few strays: its rows' bands stay narrow
    /// where the global reach does not), one cell in nine empty.
    fn target_parts(
        rows: usize,
        cols: usize,
        spread: f32,
        stray: usize,
    ) -> (ImageGeometry, Surfaces, Vec<(f32, f32)>) {
        let cells = rows * cols;
        let jitter = |k: usize, salt: usize| {
            if k % stray == stray / 2 {
                return if salt == 1 { -0.95 } else { 0.95 };
            }
            ((k * 7919 + salt * 104_729) % 1000) as f32 / 1000.0 * 2.0 * spread - spread
        };
        let coords: Vec<(f32, f32)> = (0..cells)
            .map(|k| {
                let col = (k % cols) as f32 + jitter(k, 1);
                let col = if col < 0.0 { col + cols as f32 } else { col };
                ((k / cols) as f32 + jitter(k, 2), col)
            })
            .collect();
        let direction = coords
            .iter()
            .map(|&(r, c)| unit(f64::from(c) * 0.01, 0.02 * f64::from(r) - 0.03))
            .collect();
        let range_m = (0..cells)
            .map(|k| if k % 9 == 4 { f32::NAN } else { 10.0 })
            .collect();
        let normal = vec![[0.0; 3]; cells];
        let surfaces = Surfaces::hand_made(range_m, direction, normal, vec![0.02; rows], cols);
        let geometry = ImageGeometry {
            rows,
            cols,
            beams: BeamTable::uniform(rows, -0.03, 0.03),
            ring_to_row: None,
            parallax_rad_m: None,
        };
        (geometry, surfaces, coords)
    }

    fn key(c: &Candidate) -> (u32, u32, StampNs, [u32; 3], bool) {
        (
            c.cell,
            c.range_m.to_bits(),
            c.time_ns,
            c.normal.map(f32::to_bits),
            c.edge,
        )
    }

    #[test]
    fn a_quads_box_gives_each_triangles_candidates_in_the_same_order_per_cell() {
        let (geometry, surfaces, coords) = target_parts(4, 64, 0.45, usize::MAX);
        quads_give_each_triangles_candidates(&geometry, &surfaces, &coords);
    }

    /// The same where a few stray rays set the target's reach and the
    /// bands drop the box's end rows and columns that only they could hold.
    #[test]
    fn a_quads_box_cut_to_its_bands_gives_each_triangles_candidates() {
        let (geometry, surfaces, coords) = target_parts(4, 64, 0.05, 101);
        let column_time_ns = vec![0; 64];
        let target = Target::new(&surfaces, &coords, &column_time_ns);
        assert!(target.reach.0 > 0.9 && target.reach.1 > 0.9);
        // Some rows' bands are narrow: the cut has something to drop.
        assert!(target.bands.rows.iter().any(|r| r.after < 0.5));
        let cut = within_bands(&target.bands.col_spans, (9, 12), (10.4, 10.6));
        assert!(cut.1 - cut.0 < 3, "{cut:?}");
        quads_give_each_triangles_candidates(&geometry, &surfaces, &coords);
    }

    /// Quads around random spots: [`rasterize_quad`] gives, per cell and
    /// in order, the candidates of [`rasterize_triangle`] on each triangle.
    fn quads_give_each_triangles_candidates(
        geometry: &ImageGeometry,
        surfaces: &Surfaces,
        coords: &[(f32, f32)],
    ) {
        let (geometry, surfaces) = (geometry.clone(), surfaces);
        let column_time_ns = vec![0; 64];
        let target = Target::new(surfaces, coords, &column_time_ns);
        let mut state = 12_345u64;
        let mut next = || {
            state = state
                .wrapping_mul(6_364_136_223_846_793_005)
                .wrapping_add(1);
            (state >> 11) as f64 / (1u64 << 53) as f64
        };
        let (mut quads, mut candidates, mut whole_quads) = (0, 0, 0);
        for _ in 0..4000 {
            // A quad around a random spot, sheared and moved by up to a
            // cell, on the seam now and then; sometimes a thin or
            // degenerate one.
            let (row, col) = (next() * 2.5, next() * 64.0);
            let corner = |dr: f64, dc: f64, next: &mut dyn FnMut() -> f64| {
                let c = col + dc + next() - 0.5;
                Vertex {
                    position: Point3::new(10.0 + next(), next() * 4.0, dr + next()),
                    row: row + dr * (0.2 + next()) + next() - 0.5,
                    col: if c >= 64.0 { c - 64.0 } else { c },
                    time_ns: (next() * 1e8) as StampNs,
                }
            };
            let v = [
                corner(0.0, 0.0, &mut next),
                corner(0.0, 1.0, &mut next),
                corner(1.0, 0.0, &mut next),
                corner(1.0, 1.0, &mut next),
            ];
            let (first, second) = (next() < 0.8, next() < 0.8);
            let triangles = [
                first.then_some(([&v[0], &v[1], &v[2]], next() < 0.5)),
                second.then_some(([&v[1], &v[3], &v[2]], next() < 0.5)),
            ];
            let mut expected = Vec::new();
            for (corners, edge) in triangles.into_iter().flatten() {
                rasterize_triangle(&target, &geometry, corners, edge, &mut expected);
            }
            let mut got = Vec::new();
            if !rasterize_quad(&target, &geometry, triangles, &mut got) {
                assert!(got.is_empty());
                continue;
            }
            quads += 1;
            // The whole quad's path, where it takes the quad: the same
            // candidates in the same order, bit for bit.
            if let [Some((_, first_edge)), Some((_, second_edge))] = triangles {
                let bits = if first_edge { EDGE_FIRST } else { 0 }
                    | if second_edge { EDGE_SECOND } else { 0 };
                let mut whole = Vec::new();
                if WholeQuads::of(&target, &geometry).rasterize(
                    [&v[0], &v[1], &v[2], &v[3]],
                    bits,
                    &mut whole,
                ) {
                    whole_quads += 1;
                    let keys = |c: &[Candidate]| c.iter().map(key).collect::<Vec<_>>();
                    assert_eq!(keys(&whole), keys(&got));
                }
            }
            candidates += expected.len();
            // The z-buffer sees each cell's candidates in turn: the same
            // per cell, in the same order.
            expected.sort_by_key(|c| c.cell);
            got.sort_by_key(|c| c.cell);
            let (expected, got): (Vec<_>, Vec<_>) = (
                expected.iter().map(key).collect(),
                got.iter().map(key).collect(),
            );
            assert_eq!(got, expected);
        }
        assert!(
            quads > 3000 && candidates > 1500 && whole_quads > 1500,
            "{quads} quads ({whole_quads} whole), {candidates} candidates"
        );
    }
}
