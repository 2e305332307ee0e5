//! The source's triangle mesh: which neighbouring cells share a surface
//! ([`mesh_joins`], once per scan), and the one-cell dropouts bridged so the
//! mesh keeps its triangles around them ([`fill_dropouts`]).

use nalgebra::{Point3, Vector3};
use rayon::prelude::*;

use super::{Source, Vertex, Vertices};
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
    let mut bridged_row = vec![false; rows];
    let sparse = !vertices.normal.is_empty();
    // Row by row (each left to right: a bridged vertex may be the left end
    // of the next bridge; rows share nothing), so that the source's ranges
    // are read in their order and the vertices only at its dropouts.
    for (row, bridged) in bridged_row.iter_mut().enumerate() {
        for col in 0..cols {
            let cell = row * cols + col;
            let at = col * rows + row;
            if source.surfaces.range_m[cell].is_finite() || vertices.at[at].is_some() {
                continue;
            }
            let (left_col, right_col) = ((col + cols - 1) % cols, (col + 1) % cols);
            let (left, right) = (row * cols + left_col, row * cols + right_col);
            let (left_at, right_at) = (left_col * rows + row, right_col * rows + row);
            let (Some(a), Some(b)) = (vertices.at[left_at].some(), vertices.at[right_at].some())
            else {
                continue;
            };
            if !same_surface(source.surfaces, left, right) || (a.col - b.col).abs() > 3.0 {
                continue;
            }
            vertices.at[at] = Vertex {
                position: Point3::from((a.position.coords + b.position.coords) * 0.5),
                row: 0.5 * (a.row + b.row),
                col: 0.5 * (a.col + b.col),
                time_ns: a.time_ns + (b.time_ns - a.time_ns) / 2,
            };
            if sparse {
                vertices.normal[at] = (vertices.normal[left_at] + vertices.normal[right_at]) * 0.5;
            }
            proxy[cell] = left as u32;
            *bridged = true;
        }
    }
    Proxies {
        cell: proxy,
        bridged_row,
    }
}

/// What each vertex stands for, from [`fill_dropouts`].
pub(super) struct Proxies {
    /// Per cell, the source cell whose surface its vertex stands for.
    pub cell: Vec<u32>,
    /// Per row, whether any of its vertices stands for another cell: where
    /// none of a quad's does, the scan's own table (`mesh_joins`) holds.
    pub bridged_row: Vec<bool>,
}

/// Which neighbours each cell shares a surface with (`same_surface`), for
/// the mesh's triangle edges: bit [`JOIN_RIGHT`] the next column, bit
/// [`JOIN_DOWN`] the next row, bit [`JOIN_ANTI`] the next column's cell
/// with the next row's (the diagonal both triangles of a quad share). A
/// property of the scan alone: computed once with its surfaces, read by
/// every render of it (two per pair, up to eight more to estimate a motion).
pub(in crate::engine) fn mesh_joins(surfaces: &Surfaces, rows: usize, cols: usize) -> Vec<u8> {
    let mut joins = vec![0; rows * cols];
    joins
        .par_chunks_mut(cols.max(1))
        .enumerate()
        .for_each(|(row, joins_of_row)| {
            let noise_here = f64::from(surfaces.noise_m_per_row[row]);
            let noise_down = surfaces
                .noise_m_per_row
                .get(row + 1)
                .map_or(noise_here, |&n| noise_here.max(f64::from(n)));
            let finite = |cell: usize| surfaces.range_m[cell].is_finite();
            // Each cell's point and normal once per edge it ends, not once
            // per call (the right neighbour's is the next column's own).
            let mut at_right = CellPlane::of(surfaces, row * cols);
            for (col, joins) in joins_of_row.iter_mut().enumerate() {
                let cell = row * cols + col;
                let right = row * cols + if col + 1 == cols { 0 } else { col + 1 };
                let at_here = at_right;
                at_right = CellPlane::of(surfaces, right);
                let here = finite(cell);
                if here
                    && finite(right)
                    && planes_on_one(surfaces, (cell, &at_here), (right, &at_right), noise_here)
                {
                    *joins |= JOIN_RIGHT;
                }
                if row + 1 < rows {
                    let down = cell + cols;
                    let at_down = CellPlane::of(surfaces, down);
                    if here
                        && finite(down)
                        && planes_on_one(surfaces, (cell, &at_here), (down, &at_down), noise_down)
                    {
                        *joins |= JOIN_DOWN;
                    }
                    // The diagonal does not involve this cell: an empty cell's
                    // neighbours still share the quad's other triangle.
                    if finite(right)
                        && finite(down)
                        && planes_on_one(surfaces, (right, &at_right), (down, &at_down), noise_down)
                    {
                        *joins |= JOIN_ANTI;
                    }
                }
            }
        });
    // Each quad's two triangles, from its edges' bits (some in the next row
    // and column): a render reads one byte per quad instead of five.
    let mut quads = vec![0; rows * cols];
    quads
        .par_chunks_mut(cols.max(1))
        .enumerate()
        .for_each(|(row, quads_of_row)| {
            for (col, quad) in quads_of_row.iter_mut().enumerate() {
                *quad = quad_bits(surfaces, &joins, (row, col), (rows, cols));
            }
        });
    for (joins, quad) in joins.iter_mut().zip(quads) {
        *joins |= quad;
    }
    joins
}

/// The quad at (`row`, `col`) (cells a there, b right of it, c below it, d below
/// b): [`QUAD_FIRST`] where its triangle (a, b, c) has all three edges on
/// one surface, [`QUAD_SECOND`] the same for (b, d, c), [`EDGE_FIRST`] and
/// [`EDGE_SECOND`] where a vertex of either lies on an occlusion edge.
fn quad_bits(
    surfaces: &Surfaces,
    joins: &[u8],
    (row, col): (usize, usize),
    (rows, cols): (usize, usize),
) -> u8 {
    if row + 1 >= rows {
        return 0;
    }
    let a = row * cols + col;
    let b = row * cols + if col + 1 == cols { 0 } else { col + 1 };
    let (c, d) = (a + cols, b + cols);
    let all = |bits: [bool; 3]| bits.iter().all(|&bit| bit);
    let anti = joins[a] & JOIN_ANTI != 0;
    let first = all([joins[a] & JOIN_RIGHT != 0, anti, joins[a] & JOIN_DOWN != 0]);
    let second = all([joins[b] & JOIN_DOWN != 0, joins[c] & JOIN_RIGHT != 0, anti]);
    let edge = &surfaces.edge;
    let mut bits = 0;
    if first {
        bits |= QUAD_FIRST;
    }
    if second {
        bits |= QUAD_SECOND;
    }
    if edge[a] || edge[b] || edge[c] {
        bits |= EDGE_FIRST;
    }
    if edge[b] || edge[d] || edge[c] {
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
    source: &Source,
    proxy: &[u32],
    (x, y): (usize, usize),
    joined: bool,
) -> bool {
    let (px, py) = (proxy[x] as usize, proxy[y] as usize);
    if px == x && py == y {
        joined
    } else {
        px == py || same_surface(source.surfaces, px, py)
    }
}

/// Whether two neighbouring source cells lie on one surface (so a triangle
/// between them is real and not a bridge across an occlusion).
fn same_surface(s: &Surfaces, a: usize, b: usize) -> bool {
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
}

impl CellPlane {
    #[inline]
    fn of(s: &Surfaces, cell: usize) -> Self {
        let d = s.direction[cell];
        let n = s.normal[cell];
        let n = Vector3::new(f64::from(n[0]), f64::from(n[1]), f64::from(n[2]));
        Self {
            point: Vector3::new(f64::from(d[0]), f64::from(d[1]), f64::from(d[2]))
                * f64::from(s.range_m[cell]),
            normal: (n.norm_squared() > 0.5).then_some(n),
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
