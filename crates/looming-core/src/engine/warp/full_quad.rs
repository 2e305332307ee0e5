//! The rasteriser's common case, a whole quad (both triangles in the
//! scan's own mesh, all four vertices moved, away from the seam, no wider
//! than a triangle may be, neither triangle degenerate: 95 % of a dense
//! sensor's quads), set up from the four vertices' coordinates alone,
//! without the general path's optional triangles and their records (a
//! quad's set-up took as many instructions as its ray tests and its hit).
//! The same candidates, bit for bit and in the same order, as
//! `rasterize_quad` on the quad's two triangles: the same differences,
//! products and sums, only taken once for both.

use super::flat_triangle::Edges;
use super::mesh::{EDGE_FIRST, EDGE_SECOND};
use super::raster::{MAX_SPAN_CELLS, TrianglePlane, hit, least, most, quad_cells};
use super::{Candidate, REACH_SLACK, Target, Vertex};
use crate::engine::grid::ImageGeometry;

/// The whole quad `(a, b, c, d)` (a's row `bits` of the scan's table)
/// rasterised into `out`: `false`, with nothing done, where it is not the
/// common case (a vertex missing, near the seam, too wide, a degenerate
/// triangle), for the general path to take.
#[inline]
pub(super) fn rasterize_full_quad(
    target: &Target,
    geometry: &ImageGeometry,
    [va, vb, vc, vd]: [&Vertex; 4],
    bits: u8,
    out: &mut Vec<Candidate>,
) -> bool {
    let (ra, rb, rc, rd) = (va.row, vb.row, vc.row, vd.row);
    let (ca, cb, cc, cd) = (va.col, vb.col, vc.col, vd.col);
    // A missing vertex's row is NaN (and so the sum).
    if (ra + rb + rc + rd).is_nan() {
        return false;
    }
    let (r_min, r_max) = (
        least(least(ra, rb), least(rc, rd)),
        most(most(ra, rb), most(rc, rd)),
    );
    let (c_min, c_max) = (
        least(least(ca, cb), least(cc, cd)),
        most(most(ca, cb), most(cc, cd)),
    );
    let cols = geometry.cols as f64;
    let col_reach = target.reach.1 + REACH_SLACK;
    // `rasterize_quad`'s conditions: away from the seam, and narrow.
    if !(c_min - 2.0 * col_reach >= 1.0
        && c_max + 2.0 * col_reach <= cols - 2.0
        && c_max - c_min <= cols / 4.0
        && col_reach <= cols / 16.0
        && r_max - r_min <= MAX_SPAN_CELLS
        && c_max - c_min <= MAX_SPAN_CELLS)
    {
        return false;
    }
    let (Some((first, sign_first)), Some((second, sign_second))) = (
        Edges::of(&[ra, rb, rc], &[ca, cb, cc]),
        Edges::of(&[rb, rd, rc], &[cb, cd, cc]),
    ) else {
        return false;
    };
    // The second's weight of d is the first's of a times this.
    let factor = -(sign_first * sign_second);
    let ((row_lo, row_hi), (col_lo, col_hi)) =
        quad_cells(target, geometry, (r_min, r_max), (c_min, c_max));
    let mut planes: [Option<TrianglePlane>; 2] = [None, None];
    let edges = [bits & EDGE_FIRST != 0, bits & EDGE_SECOND != 0];
    for row in row_lo..=row_hi {
        for col in col_lo..=col_hi {
            let cell = row * geometry.cols + col;
            if !target.surfaces.range_m[cell].is_finite() {
                continue;
            }
            let (tr, tc) = target.coords[cell];
            let (dc, dr) = (f64::from(tc) - cc, f64::from(tr) - rc);
            // `SharedDiagonal::weights`, NaN included.
            let diagonal = first.scaled(0, dc, dr);
            let in_first = if diagonal < -first.tolerance {
                None
            } else {
                first.weights_of(diagonal, first.scaled(1, dc, dr))
            };
            if let Some(w) = in_first
                && let Some(hit) = hit(target, cell, [va, vb, vc], w, edges[0], &mut planes[0])
            {
                out.push(hit);
            }
            let of_d = factor * diagonal;
            let in_second = if of_d < -second.tolerance {
                None
            } else {
                second.weights_of(second.scaled(0, dc, dr), of_d)
            };
            if let Some(w) = in_second
                && let Some(hit) = hit(target, cell, [vb, vd, vc], w, edges[1], &mut planes[1])
            {
                out.push(hit);
            }
        }
    }
    true
}
