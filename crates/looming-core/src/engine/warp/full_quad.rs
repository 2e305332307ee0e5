//! The rasteriser's common case, a whole quad (both triangles in the
//! scan's own mesh, all four vertices moved, away from the seam, no wider
//! than a triangle may be, neither triangle degenerate: 95 % of a dense
//! sensor's quads), set up from the four vertices' coordinates alone,
//! without the general path's optional triangles and their records (a
//! quad's set-up took as many instructions as its ray tests and its hit).
//! The same candidates, bit for bit and in the same order, as
//! `rasterize_quad` on the quad's two triangles: the same differences,
//! products and sums, only taken once for both.

use super::flat_triangle::EDGE_WEIGHT;
use super::mesh::{EDGE_FIRST, EDGE_SECOND};
use super::raster::{
    MAX_SPAN_CELLS, TrianglePlane, box_in_reach, hit, index_of, least, most, within_bands,
};
use super::{Candidate, REACH_SLACK, Target, Vertex};
use crate::engine::grid::ImageGeometry;

/// One triangle's ray test: its two edge functions from the third vertex
/// `c` (times the sign of the orientation), twice its area and the
/// tolerance (as `FlatTriangle`'s).
struct Edges {
    steps: [f64; 4],
    denominator: f64,
    tolerance: f64,
}

impl Edges {
    /// `None` where degenerate. `r`, `c`: the rows and columns of the
    /// triangle's vertices, the third being the quad's `c`.
    #[inline(always)]
    fn of(r: [f64; 3], c: [f64; 3]) -> Option<(Self, f64)> {
        let denominator = (r[1] - r[2]) * (c[0] - c[2]) + (c[2] - c[1]) * (r[0] - r[2]);
        if denominator.abs() < 1e-12 {
            return None;
        }
        let sign = if denominator < 0.0 { -1.0 } else { 1.0 };
        let denominator = denominator.abs();
        Some((
            Self {
                steps: [r[1] - r[2], c[2] - c[1], r[2] - r[0], c[0] - c[2]].map(|k| k * sign),
                denominator,
                tolerance: EDGE_WEIGHT * denominator,
            },
            sign,
        ))
    }

    /// Edge function `k` (0 or 1) of the ray `(dc, dr)` from `c`.
    #[inline(always)]
    fn scaled(&self, k: usize, dc: f64, dr: f64) -> f64 {
        self.steps[2 * k] * dc + self.steps[2 * k + 1] * dr
    }

    /// The weights from the first two scaled ones, where all three lie
    /// inside (`FlatTriangle::weights_of`).
    #[inline(always)]
    fn weights_of(&self, s0: f64, s1: f64) -> Option<[f64; 3]> {
        let s2 = self.denominator - s0 - s1;
        if s0 < -self.tolerance || s1 < -self.tolerance || s2 < -self.tolerance {
            return None;
        }
        let inverse = 1.0 / self.denominator;
        let (w0, w1) = (s0 * inverse, s1 * inverse);
        Some([w0, w1, 1.0 - w0 - w1])
    }
}

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
        Edges::of([ra, rb, rc], [ca, cb, cc]),
        Edges::of([rb, rd, rc], [cb, cd, cc]),
    ) else {
        return false;
    };
    // The second's weight of d is the first's of a times this.
    let factor = -(sign_first * sign_second);
    let ((row_lo, row_hi), (col_lo, col_hi)) =
        box_in_reach(target, geometry, (r_min, r_max), (c_min, c_max));
    let (col_lo, col_hi) = (index_of(col_lo), index_of(col_hi));
    let bands = &target.bands;
    let (row_lo, row_hi) = within_bands(&bands.row_spans, (row_lo, row_hi), (r_min, r_max));
    let (col_lo, col_hi) = within_bands(&bands.col_spans, (col_lo, col_hi), (c_min, c_max));
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
