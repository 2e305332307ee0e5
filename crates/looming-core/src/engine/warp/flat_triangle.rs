//! A triangle of the moved mesh set up for the rasteriser's ray tests
//! ([`FlatTriangle`]), and a quad's two triangles tested along their
//! shared diagonal ([`SharedDiagonal`]).

use super::Vertex;
use super::raster::{MAX_SPAN_CELLS, least, most};

/// A triangle set up for the barycentric tests: the differences of its
/// coordinates the weights take, taken once, with the sign of its
/// orientation, so that a ray is tested without the division (only the
/// rays inside, about one a triangle in two, take it).
pub(super) struct FlatTriangle<'v> {
    pub v: [&'v Vertex; 3],
    /// Its third vertex's row and column.
    r2: f64,
    c2: f64,
    edges: Edges,
    /// The sign of its orientation (of `Edges::of`'s sum): `-1` or `1`.
    sign: f64,
    pub edge: bool,
}

/// A triangle's edge functions from its third vertex, for the barycentric
/// tests (shared by [`FlatTriangle`] and the rasteriser's whole quads).
pub(super) struct Edges {
    /// `[r1 - r2, c2 - c1, r2 - r0, c0 - c2]`, times the sign of the
    /// denominator.
    steps: [f64; 4],
    /// `|(r1 - r2)(c0 - c2) + (c2 - c1)(r0 - r2)|`, twice the area.
    pub denominator: f64,
    /// How far outside, in the weights' units times `denominator`, a ray
    /// still counts as inside.
    pub tolerance: f64,
}

impl Edges {
    /// The edge functions of the triangle of rows `r` and columns `c`, with
    /// the sign of its orientation; `None` where degenerate.
    #[inline(always)]
    pub fn of(r: &[f64; 3], c: &[f64; 3]) -> Option<(Self, f64)> {
        let denominator = (r[1] - r[2]) * (c[0] - c[2]) + (c[2] - c[1]) * (r[0] - r[2]);
        if denominator.abs() < 1e-12 {
            return None;
        }
        let sign = if denominator < 0.0 { -1.0 } else { 1.0 };
        Some((
            Self {
                steps: [r[1] - r[2], c[2] - c[1], r[2] - r[0], c[0] - c[2]].map(|k| k * sign),
                denominator: denominator.abs(),
                tolerance: EDGE_WEIGHT * denominator.abs(),
            },
            sign,
        ))
    }

    /// Weight `k` (0 or 1) of the ray `(dc, dr)` from the third vertex,
    /// times the denominator.
    #[inline(always)]
    pub fn scaled(&self, k: usize, dc: f64, dr: f64) -> f64 {
        self.steps[2 * k] * dc + self.steps[2 * k + 1] * dr
    }

    /// The weights from the first two times the denominator, where all
    /// three lie inside.
    #[inline(always)]
    pub fn weights_of(&self, s0: f64, s1: f64) -> Option<[f64; 3]> {
        let s2 = self.denominator - s0 - s1;
        if s0 < -self.tolerance || s1 < -self.tolerance || s2 < -self.tolerance {
            return None;
        }
        let inverse = 1.0 / self.denominator;
        let (w0, w1) = (s0 * inverse, s1 * inverse);
        Some([w0, w1, 1.0 - w0 - w1])
    }
}

impl<'v> FlatTriangle<'v> {
    /// The triangle at its vertices' own coordinates (away from the seam).
    #[inline]
    pub fn set_up(v: [&'v Vertex; 3], edge: bool) -> Option<Self> {
        let (r, c) = coords(v);
        Self::at(v, (&r, &c), edge)
    }

    /// `None` for a triangle the renderer skips: wider than
    /// [`MAX_SPAN_CELLS`] (a bridge) or degenerate. Rows `r` and
    /// (unwrapped) columns `c` of vertices `v`.
    #[inline]
    pub fn at(v: [&'v Vertex; 3], (r, c): (&[f64; 3], &[f64; 3]), edge: bool) -> Option<Self> {
        let (r_min, r_max) = (least(least(r[0], r[1]), r[2]), most(most(r[0], r[1]), r[2]));
        let (c_min, c_max) = (least(least(c[0], c[1]), c[2]), most(most(c[0], c[1]), c[2]));
        if r_max - r_min > MAX_SPAN_CELLS || c_max - c_min > MAX_SPAN_CELLS {
            return None;
        }
        Self::spanning(v, (r, c), edge)
    }

    /// [`Self::set_up`] for a triangle known to span no more than
    /// [`MAX_SPAN_CELLS`] (its quad's box does not).
    #[inline]
    pub fn narrow(v: [&'v Vertex; 3], edge: bool) -> Option<Self> {
        let (r, c) = coords(v);
        Self::spanning(v, (&r, &c), edge)
    }

    /// The set-up once the span is checked: `None` where degenerate.
    #[inline]
    fn spanning(v: [&'v Vertex; 3], (r, c): (&[f64; 3], &[f64; 3]), edge: bool) -> Option<Self> {
        let (edges, sign) = Edges::of(r, c)?;
        Some(Self {
            v,
            r2: r[2],
            c2: c[2],
            edges,
            sign,
            edge,
        })
    }

    /// The barycentric weights of `(tr, tc)`, where it lies inside (to
    /// [`EDGE_WEIGHT`]), the first tested before the second is computed.
    #[inline]
    pub fn weights(&self, tr: f64, tc: f64) -> Option<[f64; 3]> {
        let (dc, dr) = (tc - self.c2, tr - self.r2);
        self.weights_given(dc, dr, self.edges.scaled(0, dc, dr))
    }

    /// [`Self::weights`] of the ray `(dc, dr)` from the third vertex, its
    /// first weight (times the denominator) `s0` known.
    #[inline]
    fn weights_given(&self, dc: f64, dr: f64, s0: f64) -> Option<[f64; 3]> {
        if s0 < -self.edges.tolerance {
            return None;
        }
        self.edges.weights_of(s0, self.edges.scaled(1, dc, dr))
    }
}

/// The rows and columns of a triangle's vertices.
#[inline(always)]
fn coords(v: [&Vertex; 3]) -> ([f64; 3], [f64; 3]) {
    (v.map(|v| v.row), v.map(|v| v.col))
}

/// How far outside a triangle, in barycentric weight, a ray is still taken
/// as inside (so that a ray on the edge two triangles share is in both).
pub(super) const EDGE_WEIGHT: f64 = 1e-9;

/// A quad's two triangles `(a, b, c)` and `(b, d, c)`, which share the
/// diagonal `b c` and their third vertex `c`: the first's weight of `a`
/// and the second's of `d` are one edge function of that diagonal, the
/// same products (negated where the two triangles' orientations agree),
/// so a ray takes it once, and a ray beyond the diagonal on `a`'s side
/// skips the second triangle's test (most rays lie inside one of the two).
/// The same weights, bit for bit, as each triangle's own test.
pub(super) struct SharedDiagonal<'t, 'v> {
    first: &'t FlatTriangle<'v>,
    second: &'t FlatTriangle<'v>,
    /// The second triangle's weight of `d` is the first's of `a` times
    /// this (in the weights' unscaled units): `-1` or `1`.
    factor: f64,
}

impl<'t, 'v> SharedDiagonal<'t, 'v> {
    pub fn of(first: &'t FlatTriangle<'v>, second: &'t FlatTriangle<'v>) -> Option<Self> {
        let shares = std::ptr::eq(first.v[1], second.v[0]) && std::ptr::eq(first.v[2], second.v[2]);
        shares.then_some(Self {
            first,
            second,
            factor: -(first.sign * second.sign),
        })
    }

    /// Each triangle's weights of `(tr, tc)` where it lies inside.
    #[inline]
    pub fn weights(&self, tr: f64, tc: f64) -> [Option<[f64; 3]>; 2] {
        // Both triangles' third vertex is `c`: the same differences.
        let (dc, dr) = (tc - self.first.c2, tr - self.first.r2);
        let diagonal = self.first.edges.scaled(0, dc, dr);
        let first = self.first.weights_given(dc, dr, diagonal);
        let of_d = self.factor * diagonal;
        let second = &self.second.edges;
        let second = if of_d < -second.tolerance {
            None
        } else {
            second.weights_of(second.scaled(0, dc, dr), of_d)
        };
        [first, second]
    }
}
