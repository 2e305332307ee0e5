//! The source's dropouts as every render will most likely bridge them,
//! decided once per pair: which cells [`fill_dropouts`] will fill, and the
//! triangles of each quad then ([`BridgedMesh`]).
//!
//! A render bridges a dropout between two moved vertices that exist and
//! land within three columns of each other: on a dense sensor, every
//! return's vertex but at the seam of the sweep. The quads across a bridged
//! row (most of KITTI's HDL-64E, whose dropout rows the mesh bridges) took
//! their edges per quad and per render (five edge verdicts each), though
//! all but the vertices' presence is the source's. A render whose rows'
//! stand-ins (`Proxies::cell`) are these takes the table's bits as an
//! unbridged quad takes the scan's own (`mesh_joins`); a quad of a row
//! bridged otherwise (a vertex across the seam) is judged by [`quad_bits`]
//! on its own stand-ins.
//!
//! [`fill_dropouts`]: super::mesh::fill_dropouts

use rayon::prelude::*;

use super::mesh::{
    EDGE_FIRST, EDGE_SECOND, JOIN_ANTI, JOIN_DOWN, JOIN_RIGHT, QUAD_FIRST, QUAD_SECOND,
    on_one_surface, same_surface,
};
use crate::engine::surface::Surfaces;

/// The source's mesh as a render bridges its dropouts where every return
/// has its vertex and every bridge's ends land near each other.
pub(crate) struct BridgedMesh {
    /// Per cell, the cell whose surface its vertex stands for, as
    /// [`fill_dropouts`](super::mesh::fill_dropouts) would set it; empty
    /// (no plan) where the scan has no table of joins or nothing to bridge.
    pub proxy: Vec<u32>,
    /// Per quad (its top-left cell), [`mesh_joins`](super::mesh_joins)'s
    /// triangle bits ([`QUAD_FIRST`], [`QUAD_SECOND`], [`EDGE_FIRST`],
    /// [`EDGE_SECOND`]) with the edges judged on the cells the vertices
    /// stand for (`proxy`): the scan's own where none stands for another.
    pub bits: Vec<u8>,
}

impl BridgedMesh {
    /// The mesh of `surfaces` with its dropouts bridged.
    pub fn of(surfaces: &Surfaces) -> Self {
        let cols = surfaces.cols.max(1);
        let rows = surfaces.range_m.len() / cols;
        if surfaces.joins.len() != rows * cols {
            // No table of joins to start from: every render judges its own.
            return Self::none();
        }
        let mut proxy: Vec<u32> = (0..(rows * cols) as u32).collect();
        proxy
            .par_chunks_mut(cols)
            .enumerate()
            .for_each(|(row, proxy_of_row)| bridge_row(surfaces, row, proxy_of_row));
        if proxy
            .iter()
            .enumerate()
            .all(|(cell, &p)| p as usize == cell)
        {
            // Nothing to bridge (a sensor without dropouts: the synthetic
            // drives): the plan's bits would be the scan's own joins', which
            // the renders take where no row is bridged.
            return Self::none();
        }
        let mut bits = vec![0; rows * cols];
        bits.par_chunks_mut(cols)
            .enumerate()
            .take(rows.saturating_sub(1))
            .for_each(|(row, bits_of_row)| {
                for (col, bits) in bits_of_row.iter_mut().enumerate() {
                    *bits = quad_bits(surfaces, &proxy, row * cols + col);
                }
            });
        Self { proxy, bits }
    }

    /// No plan: every dropout a render meets is judged there.
    fn none() -> Self {
        Self {
            proxy: Vec::new(),
            bits: Vec::new(),
        }
    }

    /// The plan's bits of the quad of cells `quad` (top left, top right,
    /// bottom left, bottom right) where a render's vertices (`proxy`) of
    /// all four stand for the cells planned.
    #[inline]
    pub fn bits_where_planned(&self, proxy: &[u32], quad: [usize; 4]) -> Option<u8> {
        let planned = |x: usize| self.proxy.get(x) == Some(&proxy[x]);
        quad.into_iter().all(planned).then(|| self.bits[quad[0]])
    }
}

/// [`fill_dropouts`](super::mesh::fill_dropouts)'s bridges of one row
/// (left to right: a bridged vertex may be the left end of the next),
/// where a vertex exists at every return and each bridge's ends land
/// within three columns: a dropout stands for its left neighbour where
/// both neighbours have vertices and lie on one surface.
fn bridge_row(surfaces: &Surfaces, row: usize, proxy_of_row: &mut [u32]) {
    let cols = proxy_of_row.len();
    let first = row * cols;
    let range_m = &surfaces.range_m[first..first + cols];
    // A vertex: a return's, or a dropout's bridged (standing for another).
    let vertex = |proxy_of_row: &[u32], col: usize| {
        range_m[col].is_finite() || proxy_of_row[col] as usize != first + col
    };
    for col in 0..cols {
        if vertex(proxy_of_row, col) {
            continue;
        }
        let (left_col, right_col) = ((col + cols - 1) % cols, (col + 1) % cols);
        if !(vertex(proxy_of_row, left_col) && vertex(proxy_of_row, right_col)) {
            continue;
        }
        let (left, right) = (first + left_col, first + right_col);
        if !same_surface(surfaces, left, right) {
            continue;
        }
        proxy_of_row[col] = left as u32;
    }
}

/// The triangle bits ([`QUAD_FIRST`], [`QUAD_SECOND`], [`EDGE_FIRST`],
/// [`EDGE_SECOND`]) of the quad whose top-left cell is `a`, its vertices
/// standing for the cells `proxy` gives: a triangle where its three edges
/// lie on one surface, judged on the cells they stand for (the scan's own
/// joins where none stands for another), an edge where a cell it stands
/// for is one. For the plan and for a render's row bridged otherwise.
pub(super) fn quad_bits(surfaces: &Surfaces, proxy: &[u32], a: usize) -> u8 {
    let cols = surfaces.cols;
    let col = a % cols;
    let b = a - col + if col + 1 == cols { 0 } else { col + 1 };
    let (c, d) = (a + cols, b + cols);
    let joins = &surfaces.joins;
    let stands_in = |x: usize| proxy[x] as usize != x;
    if !(stands_in(a) || stands_in(b) || stands_in(c) || stands_in(d)) {
        return joins[a] & (QUAD_FIRST | QUAD_SECOND | EDGE_FIRST | EDGE_SECOND);
    }
    let on_one = |x: usize, y: usize, joined: bool| on_one_surface(surfaces, proxy, (x, y), joined);
    let anti = on_one(b, c, joins[a] & JOIN_ANTI != 0);
    let first =
        on_one(a, b, joins[a] & JOIN_RIGHT != 0) && anti && on_one(a, c, joins[a] & JOIN_DOWN != 0);
    let second =
        on_one(b, d, joins[b] & JOIN_DOWN != 0) && on_one(c, d, joins[c] & JOIN_RIGHT != 0) && anti;
    let edge = |x: usize| surfaces.edge[proxy[x] as usize];
    let mut bits = 0;
    if first {
        bits |= QUAD_FIRST;
    }
    if second {
        bits |= QUAD_SECOND;
    }
    if edge(a) || edge(b) || edge(c) {
        bits |= EDGE_FIRST;
    }
    if edge(d) || edge(b) || edge(c) {
        bits |= EDGE_SECOND;
    }
    bits
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::engine::warp::mesh::fill_dropouts;
    use crate::engine::warp::test_surfaces::{Pattern, flat_geometry, wall};
    use crate::engine::warp::{Source, Vertex, Vertices, mesh_joins};
    use nalgebra::Point3;

    /// A wall 10 m off with noisy ranges, steps (occlusions), one-cell
    /// and two-cell dropouts, normals known on most cells.
    fn surfaces_with_dropouts(rows: usize, cols: usize) -> Surfaces {
        let pattern = Pattern {
            empty: |k| k % 13 == 4 || matches!(k % 31, 7 | 8),
            step: |k| k % 13 == 9,
            no_normal: |k| k % 11 == 2,
            edge: |k| k % 17 == 3,
        };
        let mut surfaces = wall(rows, cols, 0x9e37_79b9_7f4a_7c15, &pattern);
        surfaces.joins = mesh_joins(&surfaces, rows, cols);
        surfaces
    }

    /// The renders' own per-triangle verdicts before the plan, kept as the
    /// reference [`quad_bits`] is held to: a quad's triangles, each with
    /// whether it touches an occlusion edge,
    /// where a vertex may stand for a bridged dropout: its edges judged on the
    /// cells the vertices stand for. Cells `a` and `b` (left and right, the
    /// next row's below them) and vertices `(a, b, c, d)`, the diagonal's `b`
    /// and `c` present (either triangle needs them).
    fn bridged_quad<'v>(
        source: &Source,
        proxy: &[u32],
        (a, b): (usize, usize),
        (va, vb, vc, vd): (
            Option<&'v Vertex>,
            &'v Vertex,
            &'v Vertex,
            Option<&'v Vertex>,
        ),
    ) -> [Option<([&'v Vertex; 3], bool)>; 2] {
        let cols = source.surfaces.cols;
        let (c, d) = (a + cols, b + cols);
        let joins = &source.surfaces.joins;
        // Each edge with the table's verdict for its two cells (`mesh_joins`),
        // which holds where neither is a bridged dropout.
        let bc = (b, c, joins[a] & JOIN_ANTI != 0);
        let triangles = [
            (
                va,
                a,
                [
                    (a, b, joins[a] & JOIN_RIGHT != 0),
                    bc,
                    (a, c, joins[a] & JOIN_DOWN != 0),
                ],
            ),
            (
                vd,
                d,
                [
                    (b, d, joins[b] & JOIN_DOWN != 0),
                    (c, d, joins[c] & JOIN_RIGHT != 0),
                    bc,
                ],
            ),
        ];
        let mut quad = [None, None];
        for (k, (apex, apex_cell, edges)) in triangles.into_iter().enumerate() {
            let Some(apex) = apex else {
                continue;
            };
            if !edges
                .into_iter()
                .all(|(x, y, joined)| on_one_surface(source.surfaces, proxy, (x, y), joined))
            {
                continue;
            }
            let edge = [apex_cell, b, c]
                .iter()
                .any(|&v| source.surfaces.edge[proxy[v] as usize]);
            let corners = if k == 0 {
                [apex, vb, vc]
            } else {
                [vb, apex, vc]
            };
            quad[k] = Some((corners, edge));
        }
        quad
    }

    /// The plan's bits are `bridged_quad`'s verdicts on every quad, the
    /// vertices present (its triangles, and each one's edge flag), and a
    /// render whose every return has a vertex near its own column
    /// bridges the dropouts as planned.
    #[test]
    fn the_plan_holds_bridged_quads_verdicts() {
        let (rows, cols) = (9, 64);
        let surfaces = surfaces_with_dropouts(rows, cols);
        let time_ns = vec![0; rows * cols];
        let source = Source::new(&surfaces, &time_ns);
        let plan = &source.bridged;
        let vertex = Vertex {
            position: Point3::new(10.0, 0.0, 0.0),
            row: 0.0,
            col: 0.0,
            time_ns: 0,
        };
        let (mut bridged, mut whole, mut broken) = (0, 0, 0);
        for row in 0..rows - 1 {
            for col in 0..cols {
                let a = row * cols + col;
                let b = row * cols + (col + 1) % cols;
                let present = Some(&vertex);
                let quad = bridged_quad(
                    &source,
                    &plan.proxy,
                    (a, b),
                    (present, &vertex, &vertex, present),
                );
                let bits = plan.bits[a];
                let expected = [quad[0].map(|(_, edge)| edge), quad[1].map(|(_, edge)| edge)];
                let table = [
                    (bits & QUAD_FIRST != 0).then_some(bits & EDGE_FIRST != 0),
                    (bits & QUAD_SECOND != 0).then_some(bits & EDGE_SECOND != 0),
                ];
                assert_eq!(table, expected, "quad at ({row}, {col})");
                let stands_in = [a, b, a + cols, b + cols]
                    .iter()
                    .any(|&x| plan.proxy[x] as usize != x);
                bridged += usize::from(stands_in);
                whole += usize::from(stands_in && quad.iter().all(Option::is_some));
                broken += usize::from(stands_in && quad.iter().any(Option::is_none));
            }
        }
        assert!(
            bridged > 50 && whole > 10 && broken > 10,
            "{bridged} {whole} {broken}"
        );
        // Every return's vertex at its own cell: the render's bridges are
        // the plan's.
        let geometry = flat_geometry(rows, cols);
        let at = (0..rows * cols)
            .map(|k| {
                let (col, row) = (k / rows, k % rows);
                if surfaces.range_m[row * cols + col].is_finite() {
                    Vertex {
                        row: row as f64,
                        col: col as f64,
                        ..vertex
                    }
                } else {
                    Vertex::NONE
                }
            })
            .collect();
        let mut vertices = Vertices {
            rows,
            at,
            normal: Vec::new(),
        };
        let proxies = fill_dropouts(&source, &geometry, &mut vertices);
        assert_eq!(proxies.cell, plan.proxy);
        assert!(proxies.as_planned.iter().all(|&p| p));
    }
}
