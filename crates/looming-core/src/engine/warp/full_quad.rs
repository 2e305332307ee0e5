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
use super::raster::{
    MAX_SPAN_CELLS, TrianglePlane, box_rows, hit, index_of, least, most, within_bands,
};
use super::{Candidate, REACH_SLACK, Span, Target, Vertex};
use crate::engine::grid::ImageGeometry;

/// What every whole quad of one render's task compares itself with, taken
/// once per task: the target's reach, bands and rays as plain values and
/// slices (per quad they were read through the target again, and the
/// rasteriser's one large loop kept most of them on the stack).
pub(super) struct WholeQuads<'t> {
    target: &'t Target<'t>,
    cols: usize,
    cols_f: f64,
    last_row: usize,
    /// The target's reach plus [`REACH_SLACK`], rows and columns.
    row_reach: f64,
    col_reach: f64,
    /// Twice the column reach: the seam's margin.
    seam_margin: f64,
    /// The target's reach small enough for the seam test to hold.
    narrow_reach: bool,
    row_spans: &'t [Span],
    col_spans: &'t [Span],
    range_m: &'t [f32],
    coords: &'t [(f32, f32)],
}

impl<'t> WholeQuads<'t> {
    pub fn of(target: &'t Target<'t>, geometry: &ImageGeometry) -> Self {
        let cols_f = geometry.cols as f64;
        let col_reach = target.reach.1 + REACH_SLACK;
        Self {
            target,
            cols: geometry.cols,
            cols_f,
            last_row: geometry.rows.saturating_sub(1),
            row_reach: target.reach.0 + REACH_SLACK,
            col_reach,
            seam_margin: 2.0 * col_reach,
            narrow_reach: col_reach <= cols_f / 16.0,
            row_spans: &target.bands.row_spans,
            col_spans: &target.bands.col_spans,
            range_m: &target.surfaces.range_m,
            coords: target.coords,
        }
    }

    /// The whole quad `(a, b, c, d)` (a's row `bits` of the scan's table)
    /// rasterised into `out`: `false`, with nothing done, where it is not
    /// the common case (a vertex missing, near the seam, too wide, a
    /// degenerate triangle), for the general path to take.
    // Always inlined: in both of its callers' loops (out of line, its
    // call and its `hit`'s cost a twentieth of the renders).
    #[inline(always)]
    pub fn rasterize(
        &self,
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
        // In a chain, one comparison each (the pairs' form became vector
        // compares and branches); the same bounds, as none is NaN (a
        // zero's sign may differ, which no use of them sees).
        let (r_min, r_max) = (
            least(least(least(ra, rb), rc), rd),
            most(most(most(ra, rb), rc), rd),
        );
        let (c_min, c_max) = (
            least(least(least(ca, cb), cc), cd),
            most(most(most(ca, cb), cc), cd),
        );
        // `rasterize_quad`'s conditions: away from the seam, and narrow.
        if !(c_min - self.seam_margin >= 1.0
            && c_max + self.seam_margin <= self.cols_f - 2.0
            && c_max - c_min <= self.cols_f / 4.0
            && self.narrow_reach
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
        let ((row_lo, row_hi), (col_lo, col_hi)) = self.cells((r_min, r_max), (c_min, c_max));
        let mut planes: [Option<TrianglePlane>; 2] = [None, None];
        let edges = [bits & EDGE_FIRST != 0, bits & EDGE_SECOND != 0];
        for row in row_lo..=row_hi {
            for col in col_lo..=col_hi {
                let cell = row * self.cols + col;
                if !self.range_m[cell].is_finite() {
                    continue;
                }
                let (tr, tc) = self.coords[cell];
                let (dc, dr) = (f64::from(tc) - cc, f64::from(tr) - rc);
                // `SharedDiagonal::weights`, NaN included.
                let diagonal = first.scaled(0, dc, dr);
                let in_first = if diagonal < -first.tolerance {
                    None
                } else {
                    first.weights_of(diagonal, first.scaled(1, dc, dr))
                };
                if let Some(w) = in_first
                    && let Some(hit) =
                        hit(self.target, cell, [va, vb, vc], w, edges[0], &mut planes[0])
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
                    && let Some(hit) =
                        hit(self.target, cell, [vb, vd, vc], w, edges[1], &mut planes[1])
                {
                    out.push(hit);
                }
            }
        }
        true
    }

    /// `quad_cells` of the quad's box (rows `[r_min, r_max]`, columns
    /// `[c_min, c_max]`, away from the seam), from the values taken once.
    #[inline(always)]
    fn cells(
        &self,
        rows: (f64, f64),
        (c_min, c_max): (f64, f64),
    ) -> ((usize, usize), (usize, usize)) {
        let (row_lo, row_hi) = box_rows(rows, self.row_reach, self.last_row);
        let col_lo = index_of(most(c_min.floor(), (c_min - self.col_reach).ceil()));
        let col_hi = index_of(least(c_max.ceil(), (c_max + self.col_reach).floor()));
        (
            within_bands(self.row_spans, (row_lo, row_hi), rows),
            within_bands(self.col_spans, (col_lo, col_hi), (c_min, c_max)),
        )
    }
}
