//! The source's triangle mesh: which neighbouring cells share a surface
//! ([`mesh_joins`], once per scan), and the one-cell dropouts bridged so the
//! mesh keeps its triangles around them ([`fill_dropouts`]).

use nalgebra::{Point3, Vector3};
use rayon::prelude::*;

use super::{Source, Vertex, Vertices, row_bands};
use crate::engine::grid::ImageGeometry;
use crate::engine::surface::Surfaces;

/// Bridges one-cell dropouts of the source (a laser that returned nothing
/// there: dark paint, a window, a missed echo; a few percent of real
/// returns) so the mesh keeps its triangles around them: the missing vertex
/// is the midpoint of its row neighbours when they lie on one surface.
/// Returns, per cell, the source cell whose surface the vertex stands for
/// (itself, or the left neighbour of a bridged dropout), and per row
/// whether it bridged any.
pub(super) fn fill_dropouts(
    source: &Source,
    geometry: &ImageGeometry,
    vertices: &mut Vertices,
) -> Proxies {
    let (rows, cols) = (geometry.rows, geometry.cols);
    let mut proxy: Vec<u32> = (0..geometry.cells() as u32).collect();
    let sparse = !vertices.normal.is_empty();
    // The rows' bridges found on rayon's workers (on one core, the other
    // waited), then written. Rows share nothing, and a bridge reads only
    // vertices the source had, as one pass left to right along each row
    // did: a dropout bridged there had a vertex on its right, so the next
    // column, no dropout, bridged nothing on it (and across the seam the
    // neighbours land a whole image apart: no bridge).
    let found = &*vertices;
    // Bands of rows, each taken column by column: a column's rows of a
    // band lie side by side in the column-major buffers.
    let bands: Vec<Vec<Bridge>> = row_bands(rows)
        .map(|band| band_bridges(source, (rows, cols), found, band))
        .collect();
    let mut bridged_row = vec![false; rows];
    for bridge in bands.iter().flatten() {
        let (row, (left_at, right_at)) = (bridge.row, bridge.neighbours_at);
        let at = bridge.col * rows + row;
        bridged_row[row] = true;
        vertices.at[at] = bridge.vertex;
        if sparse {
            vertices.normal[at] = (vertices.normal[left_at] + vertices.normal[right_at]) * 0.5;
        }
        proxy[row * cols + bridge.col] = bridge.left as u32;
    }
    // Rows bridged as the source planned (most), whose quads take the
    // plan's table (`BridgedMesh`).
    let planned = &source.bridged.proxy;
    let as_planned = (0..rows)
        .map(|row| {
            let at = row * cols..(row + 1) * cols;
            planned.get(at.clone()) == Some(&proxy[at])
        })
        .collect();
    Proxies {
        cell: proxy,
        bridged_row,
        as_planned,
    }
}

/// A dropout bridged by [`fill_dropouts`]: its row and column, the vertex
/// between its neighbours, the cell of its left neighbour (whose surface
/// it stands for), and both neighbours' indices in the column-major
/// buffers.
struct Bridge {
    row: usize,
    col: usize,
    vertex: Vertex,
    left: usize,
    neighbours_at: (usize, usize),
}

/// The bridges of the dropouts of the rows `band`, each row's left to
/// right (the vertices stored column-major, `rows` a column).
fn band_bridges(
    source: &Source,
    (rows, cols): (usize, usize),
    vertices: &Vertices,
    band: std::ops::Range<usize>,
) -> Vec<Bridge> {
    let mut bridges = Vec::new();
    for col in 0..cols {
        for row in band.clone() {
            if let Some(bridge) = bridge_at(source, (rows, cols), vertices, (row, col)) {
                bridges.push(bridge);
            }
        }
    }
    bridges
}

/// The bridge of the cell at (`row`, `col`), where it is a dropout between
/// two vertices on one surface.
fn bridge_at(
    source: &Source,
    (rows, cols): (usize, usize),
    vertices: &Vertices,
    (row, col): (usize, usize),
) -> Option<Bridge> {
    let at = col * rows + row;
    if source.columns.range_m[at].is_finite() || vertices.at[at].is_some() {
        return None;
    }
    let (left_col, right_col) = ((col + cols - 1) % cols, (col + 1) % cols);
    let (left, right) = (row * cols + left_col, row * cols + right_col);
    let (left_at, right_at) = (left_col * rows + row, right_col * rows + row);
    let (a, b) = (vertices.at[left_at].some()?, vertices.at[right_at].some()?);
    // The source's plan bridged this dropout between these two cells
    // only where they lie on one surface (`BridgedMesh`).
    let planned = source.bridged.proxy.get(row * cols + col) == Some(&(left as u32));
    if (a.col - b.col).abs() > MAX_BRIDGE_COLS
        || !(planned || same_surface(source.surfaces, left, right))
    {
        return None;
    }
    Some(Bridge {
        row,
        col,
        vertex: Vertex {
            position: Point3::from((a.position.coords + b.position.coords) * 0.5),
            row: 0.5 * (a.row + b.row),
            col: 0.5 * (a.col + b.col),
            time_ns: a.time_ns + (b.time_ns - a.time_ns) / 2,
        },
        left,
        neighbours_at: (left_at, right_at),
    })
}

/// How far apart, in columns, a dropout's two neighbours may land and be
/// bridged (further: across the seam of the sweep).
pub(super) const MAX_BRIDGE_COLS: f64 = 3.0;

/// What each vertex stands for, from [`fill_dropouts`].
pub(super) struct Proxies {
    /// Per cell, the source cell whose surface its vertex stands for.
    pub cell: Vec<u32>,
    /// Per row, whether any of its vertices stands for another cell: where
    /// none of a quad's does, the scan's own table (`mesh_joins`) holds.
    pub bridged_row: Vec<bool>,
    /// Per row, whether its vertices stand for the cells the source
    /// planned (`BridgedMesh::proxy`): where both rows of a quad's do, the
    /// plan's triangle bits hold.
    pub as_planned: Vec<bool>,
}

/// Which neighbours each cell shares a surface with (`same_surface`), for
/// the mesh's triangle edges: bit [`JOIN_RIGHT`] the next column, bit
/// [`JOIN_DOWN`] the next row, bit [`JOIN_ANTI`] the next column's cell
/// with the next row's (the diagonal both triangles of a quad share). A
/// property of the scan alone: computed once with its surfaces, read by
/// every render of it (two per pair, up to eight more to estimate a motion).
pub(in crate::engine) fn mesh_joins(surfaces: &Surfaces, rows: usize, cols: usize) -> Vec<u8> {
    let mut joined = vec![0; rows * cols];
    joined
        .par_chunks_mut(cols.max(1))
        .enumerate()
        .for_each(|(row, joins_of_row)| row_joins(surfaces, row, (rows, cols), joins_of_row));
    // Each quad's two triangles, from its edges' bits (some in the next row
    // and column): a render reads one byte per quad instead of five. Into
    // the table itself, row by row from the edges' table.
    let mut joins = vec![0; rows * cols];
    joins
        .par_chunks_mut(cols.max(1))
        .enumerate()
        .for_each(|(row, joins_of_row)| {
            let at = |r: usize| r * cols..(r + 1) * cols;
            let here = &joined[at(row)];
            let Some(below) = joined.get(at(row + 1)) else {
                joins_of_row.copy_from_slice(here);
                return;
            };
            let (edge_here, edge_below) = (&surfaces.edge[at(row)], &surfaces.edge[at(row + 1)]);
            for (col, joins) in joins_of_row.iter_mut().enumerate() {
                let next = if col + 1 == cols { 0 } else { col + 1 };
                let (a, b, c) = (here[col], here[next], below[col]);
                let edge = [
                    edge_here[col],
                    edge_here[next],
                    edge_below[col],
                    edge_below[next],
                ];
                *joins = a | quad_bits([a, b, c], edge);
            }
        });
    joins
}

/// One row's edge bits ([`mesh_joins`]'s first three) into `joins_of_row`.
fn row_joins(
    surfaces: &Surfaces,
    row: usize,
    (rows, cols): (usize, usize),
    joins_of_row: &mut [u8],
) {
    let noise_here = f64::from(surfaces.noise_m_per_row[row]);
    let noise_down = surfaces
        .noise_m_per_row
        .get(row + 1)
        .map_or(noise_here, |&n| noise_here.max(f64::from(n)));
    // Each cell's point and normal once per edge it ends, not once
    // per call (the right neighbour's is the next column's own).
    let mut at_right = CellPlane::of(surfaces, row * cols);
    for (col, joins) in joins_of_row.iter_mut().enumerate() {
        let cell = row * cols + col;
        let right = row * cols + if col + 1 == cols { 0 } else { col + 1 };
        let at_here = at_right;
        at_right = CellPlane::of(surfaces, right);
        if at_here.finite
            && at_right.finite
            && planes_on_one(surfaces, (cell, &at_here), (right, &at_right), noise_here)
        {
            *joins |= JOIN_RIGHT;
        }
        if row + 1 < rows {
            let down = cell + cols;
            let at_down = CellPlane::of(surfaces, down);
            if at_here.finite
                && at_down.finite
                && planes_on_one(surfaces, (cell, &at_here), (down, &at_down), noise_down)
            {
                *joins |= JOIN_DOWN;
            }
            // The diagonal does not involve this cell: an empty cell's
            // neighbours still share the quad's other triangle.
            if at_right.finite
                && at_down.finite
                && planes_on_one(surfaces, (right, &at_right), (down, &at_down), noise_down)
            {
                *joins |= JOIN_ANTI;
            }
        }
    }
}

/// The quad of cells a, b right of it, c below it and d below b, from the
/// edge bits of a, b and c and whether each of a, b, c, d is on an
/// occlusion edge: [`QUAD_FIRST`] where its triangle (a, b, c) has all
/// three edges on one surface, [`QUAD_SECOND`] the same for (b, d, c),
/// [`EDGE_FIRST`] and [`EDGE_SECOND`] where a vertex of either lies on an
/// occlusion edge.
#[inline]
fn quad_bits([a, b, c]: [u8; 3], [edge_a, edge_b, edge_c, edge_d]: [bool; 4]) -> u8 {
    let anti = a & JOIN_ANTI != 0;
    let first = a & JOIN_RIGHT != 0 && anti && a & JOIN_DOWN != 0;
    let second = b & JOIN_DOWN != 0 && c & JOIN_RIGHT != 0 && anti;
    let mut bits = 0;
    if first {
        bits |= QUAD_FIRST;
    }
    if second {
        bits |= QUAD_SECOND;
    }
    if edge_a || edge_b || edge_c {
        bits |= EDGE_FIRST;
    }
    if edge_b || edge_d || edge_c {
        bits |= EDGE_SECOND;
    }
    bits
}

pub(super) const JOIN_RIGHT: u8 = 1;
pub(super) const JOIN_DOWN: u8 = 2;
pub(super) const JOIN_ANTI: u8 = 4;
pub(super) const QUAD_FIRST: u8 = 8;
pub(super) const QUAD_SECOND: u8 = 16;
pub(super) const EDGE_FIRST: u8 = 32;
pub(super) const EDGE_SECOND: u8 = 64;

/// Whether the mesh edge between source cells `x` and `y` lies on one
/// surface: the scan's table (`joined`, from [`mesh_joins`]) where neither
/// vertex stands in for a bridged dropout, else the cells the vertices
/// stand for, judged now.
#[inline]
pub(super) fn on_one_surface(
    surfaces: &Surfaces,
    proxy: &[u32],
    (x, y): (usize, usize),
    joined: bool,
) -> bool {
    let (px, py) = (proxy[x] as usize, proxy[y] as usize);
    if px == x && py == y {
        joined
    } else {
        px == py || same_surface(surfaces, px, py)
    }
}

/// Whether two neighbouring source cells lie on one surface (so a triangle
/// between them is real and not a bridge across an occlusion).
pub(super) fn same_surface(s: &Surfaces, a: usize, b: usize) -> bool {
    on_one_plane(s, a, b, s.noise_m(a).max(s.noise_m(b)))
}

/// [`same_surface`] with the larger of the two cells' range noise given
/// (metres): the mesh's table takes it per row, not per cell.
fn on_one_plane(s: &Surfaces, a: usize, b: usize, noise_m: f64) -> bool {
    let (at_a, at_b) = (CellPlane::of(s, a), CellPlane::of(s, b));
    planes_on_one(s, (a, &at_a), (b, &at_b), noise_m)
}

/// A cell's return and surface normal in `f64` ([`on_one_plane`]'s terms).
#[derive(Clone, Copy)]
struct CellPlane {
    point: Vector3<f64>,
    /// The normal, where the cell has one.
    normal: Option<Vector3<f64>>,
    /// The cell has a return (a finite range).
    finite: bool,
}

impl CellPlane {
    #[inline]
    fn of(s: &Surfaces, cell: usize) -> Self {
        let d = s.direction[cell];
        let n = s.normal[cell];
        let n = Vector3::new(f64::from(n[0]), f64::from(n[1]), f64::from(n[2]));
        let range_m = s.range_m[cell];
        Self {
            point: Vector3::new(f64::from(d[0]), f64::from(d[1]), f64::from(d[2]))
                * f64::from(range_m),
            normal: (n.norm_squared() > 0.5).then_some(n),
            finite: range_m.is_finite(),
        }
    }
}

/// [`on_one_plane`] of cells `a` and `b` with their [`CellPlane`]s.
#[inline]
fn planes_on_one(
    s: &Surfaces,
    (a, at_a): (usize, &CellPlane),
    (b, at_b): (usize, &CellPlane),
    noise_m: f64,
) -> bool {
    let gap = at_b.point - at_a.point;
    let off_plane = |at: &CellPlane| at.normal.map(|n| gap.dot(&n).abs());
    match (off_plane(at_a), off_plane(at_b)) {
        // Each vertex must lie on the other's plane: a triangle across a crease
        // (road meeting a wall) is a chamfer that is not there. The tolerance
        // is at least its noise term (the rounded sum of it and a term >= 0),
        // so most joins need no square root for the gap's term.
        (Some(da), Some(db)) => {
            let (off, noise_term) = (da.max(db), 4.0 * noise_m);
            off <= noise_term || off <= noise_term + 0.05 * gap.norm()
        }
        // No plane: fall back to a range-ratio test.
        _ => {
            let (ra, rb) = (f64::from(s.range_m[a]), f64::from(s.range_m[b]));
            (ra - rb).abs() <= 0.05 * ra.max(rb) + 4.0 * noise_m
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::engine::warp::test_surfaces::{Pattern, flat_geometry, wall};
    use crate::engine::warp::{Source, mesh_joins};

    /// `mesh_joins` as it was: the edges' table, then each quad's bits
    /// from it in a table of their own, added to it.
    fn mesh_joins_in_two_tables(surfaces: &Surfaces, rows: usize, cols: usize) -> Vec<u8> {
        let mut joins = vec![0; rows * cols];
        for row in 0..rows {
            let noise_here = f64::from(surfaces.noise_m_per_row[row]);
            let noise_down = surfaces
                .noise_m_per_row
                .get(row + 1)
                .map_or(noise_here, |&n| noise_here.max(f64::from(n)));
            let finite = |cell: usize| surfaces.range_m[cell].is_finite();
            for col in 0..cols {
                let cell = row * cols + col;
                let right = row * cols + (col + 1) % cols;
                if finite(cell) && finite(right) && on_one_plane(surfaces, cell, right, noise_here)
                {
                    joins[cell] |= JOIN_RIGHT;
                }
                if row + 1 < rows {
                    let down = cell + cols;
                    if finite(cell)
                        && finite(down)
                        && on_one_plane(surfaces, cell, down, noise_down)
                    {
                        joins[cell] |= JOIN_DOWN;
                    }
                    if finite(right)
                        && finite(down)
                        && on_one_plane(surfaces, right, down, noise_down)
                    {
                        joins[cell] |= JOIN_ANTI;
                    }
                }
            }
        }
        let mut quads = vec![0; rows * cols];
        for row in 0..rows.saturating_sub(1) {
            for col in 0..cols {
                let a = row * cols + col;
                let b = row * cols + (col + 1) % cols;
                let (c, d) = (a + cols, b + cols);
                let edge = [a, b, c, d].map(|k| surfaces.edge[k]);
                quads[a] = quad_bits([joins[a], joins[b], joins[c]], edge);
            }
        }
        joins.iter().zip(quads).map(|(j, q)| j | q).collect()
    }

    #[test]
    fn the_joins_table_is_as_from_two_tables() {
        // Noisy ranges with steps (occlusions), empty cells, and normals
        // known on most cells.
        let pattern = Pattern {
            empty: |k| k % 13 == 4,
            step: |k| k % 13 == 7,
            no_normal: |k| k % 5 == 2,
            edge: |k| k % 7 == 3,
        };
        for (rows, cols) in [(1, 5), (2, 1), (6, 17), (9, 64)] {
            let cells = rows * cols;
            let surfaces = wall(rows, cols, 0x2545_f491_4f6c_dd1d, &pattern);
            let joins = mesh_joins(&surfaces, rows, cols);
            assert_eq!(
                joins,
                mesh_joins_in_two_tables(&surfaces, rows, cols),
                "{rows} x {cols}"
            );
            if cells > 100 {
                // Joined and parted neighbours, whole and broken quads.
                for bit in [JOIN_RIGHT, JOIN_DOWN, JOIN_ANTI, QUAD_FIRST, QUAD_SECOND] {
                    let joined = joins.iter().filter(|&&j| j & bit != 0).count();
                    assert!(joined > 0 && joined < cells, "bit {bit}: {joined}");
                }
            }
        }
    }

    /// The one pass `fill_dropouts` took before its rows were found apart:
    /// column by column, each column's rows in turn, every bridge written
    /// as it was found (the reference its row-parallel form is held to).
    fn one_pass(
        source: &Source,
        (rows, cols): (usize, usize),
        vertices: &mut Vertices,
    ) -> Vec<u32> {
        let mut proxy: Vec<u32> = (0..(rows * cols) as u32).collect();
        for col in 0..cols {
            let (left_col, right_col) = ((col + cols - 1) % cols, (col + 1) % cols);
            for row in 0..rows {
                let at = col * rows + row;
                if source.columns.range_m[at].is_finite() || vertices.at[at].is_some() {
                    continue;
                }
                let (left, right) = (row * cols + left_col, row * cols + right_col);
                let (left_at, right_at) = (left_col * rows + row, right_col * rows + row);
                let (Some(a), Some(b)) =
                    (vertices.at[left_at].some(), vertices.at[right_at].some())
                else {
                    continue;
                };
                let planned = source.bridged.proxy.get(row * cols + col) == Some(&(left as u32));
                if (a.col - b.col).abs() > MAX_BRIDGE_COLS
                    || !(planned || same_surface(source.surfaces, left, right))
                {
                    continue;
                }
                vertices.at[at] = Vertex {
                    position: Point3::from((a.position.coords + b.position.coords) * 0.5),
                    row: 0.5 * (a.row + b.row),
                    col: 0.5 * (a.col + b.col),
                    time_ns: a.time_ns + (b.time_ns - a.time_ns) / 2,
                };
                proxy[row * cols + col] = left as u32;
            }
        }
        proxy
    }

    /// Each return's vertex near its cell, one in 19 four columns off, one
    /// in 23 missing (a return that landed across the seam); column-major.
    fn vertices_near(
        surfaces: &Surfaces,
        (rows, cols): (usize, usize),
        time_ns: &[i64],
    ) -> Vec<Vertex> {
        (0..rows * cols)
            .map(|k| {
                let (col, row) = (k / rows, k % rows);
                let cell = row * cols + col;
                if !surfaces.range_m[cell].is_finite() || cell % 23 == 5 {
                    return Vertex::NONE;
                }
                let shift = if cell % 19 == 1 {
                    4.0
                } else {
                    0.01 * (cell % 7) as f64
                };
                Vertex {
                    position: Point3::new(
                        10.0,
                        0.1 * col as f64,
                        0.2 * row as f64 + 0.001 * k as f64,
                    ),
                    row: row as f64 + 0.02,
                    col: col as f64 + shift,
                    time_ns: time_ns[cell] + 37,
                }
            })
            .collect()
    }

    /// Rows found apart bridge the same dropouts with the same vertices as
    /// the one pass, bit for bit: dropouts in the first and last columns
    /// (their neighbours land a whole image apart: none), next to each
    /// other (none), beside a return without a vertex (none), whose
    /// neighbours land columns apart (none), and the rest.
    #[test]
    fn rows_found_apart_bridge_as_one_pass() {
        let (rows, cols) = (9, 64);
        let pattern = Pattern {
            // The first column of even rows and the last of odd rows (the
            // seam), and pairs of neighbours, empty.
            empty: |k| {
                let (row, col) = (k / 64, k % 64);
                (col == 0 && row % 2 == 0)
                    || (col == 63 && row % 2 == 1)
                    || k % 13 == 4
                    || matches!(k % 31, 7 | 8)
            },
            step: |k| k % 13 == 9,
            no_normal: |k| k % 11 == 2,
            edge: |k| k % 17 == 3,
        };
        let mut surfaces = wall(rows, cols, 0x2545_f491_4f6c_dd1d, &pattern);
        surfaces.joins = mesh_joins(&surfaces, rows, cols);
        let time_ns: Vec<i64> = (0..rows * cols).map(|k| 1_000 * k as i64).collect();
        let source = Source::new(&surfaces, &time_ns);
        let geometry = flat_geometry(rows, cols);
        let at = vertices_near(&surfaces, (rows, cols), &time_ns);
        let mut vertices = Vertices {
            rows,
            at: at.clone(),
            normal: Vec::new(),
        };
        let mut reference = Vertices {
            rows,
            at,
            normal: Vec::new(),
        };
        let proxies = fill_dropouts(&source, &geometry, &mut vertices);
        let proxy = one_pass(&source, (rows, cols), &mut reference);
        assert_eq!(proxies.cell, proxy);
        let bits = |v: &Vertex| {
            v.some().map(|v| {
                (
                    v.position.coords.map(f64::to_bits),
                    v.row.to_bits(),
                    v.col.to_bits(),
                    v.time_ns,
                )
            })
        };
        let bridged = proxy
            .iter()
            .enumerate()
            .filter(|&(k, &p)| p as usize != k)
            .count();
        assert!(bridged > 20, "{bridged} bridged");
        for (k, (got, want)) in vertices.at.iter().zip(&reference.at).enumerate() {
            assert_eq!(bits(got), bits(want), "vertex {k}");
        }
        for row in 0..rows {
            let any = (0..cols).any(|c| proxy[row * cols + c] as usize != row * cols + c);
            assert_eq!(proxies.bridged_row[row], any, "row {row}");
        }
    }
}
