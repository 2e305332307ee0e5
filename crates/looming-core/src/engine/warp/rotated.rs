//! The previous scan turned about the sensor (`R_rot`), sampled ray by ray.
//!
//! A rotation about the sensor's origin moves no surface nearer or
//! further, and turns the image nearly as a whole. So where
//! [`render`](super::render) moves every vertex into the target's image
//! and rasterises every triangle, here each target ray is turned back into
//! the source's image (its coordinates there: `row_f_at` at the ray's own
//! range, for a laser's parallax, and `col_f`) and the one triangle holding
//! it among the source's own vertex coordinates is found by walking the
//! mesh from the cell it lands in: a fraction of the raster's work per ray.
//!
//! The same mesh (the source's triangles and bridged dropouts, as planned
//! in `BridgedMesh`), the same range (the ray, turned into a frame all the
//! source's returns share, against the triangle's plane there), time (the
//! vertices' weighted by the ray's image coordinates) and normal. What
//! differs from the raster:
//! - the ray is turned into the source's image where the raster turns the
//!   vertices into the target's: the same triangle but where the turn
//!   bends the image within a cell (second order in the turn: a ray on a
//!   triangle's edge may take its neighbour);
//! - each ray is turned at its own column's time and each vertex at its
//!   own (its column's times, interpolated), where the raster turned a
//!   vertex to the time of the column it lands in;
//! - where two triangles overlap (a folded mesh: a stray return a row off),
//!   the walk takes the one it meets, the raster's z-buffer the nearest.

use nalgebra::{Matrix3, Vector3};
use rayon::prelude::*;

use super::mesh::{EDGE_FIRST, EDGE_SECOND, MAX_BRIDGE_COLS, QUAD_FIRST, QUAD_SECOND};
use super::moved_vertices::turn_rad;
use super::{Rendered, Source, Target};
use crate::engine::atan::atan2;
use crate::engine::grid::ImageGeometry;
use crate::engine::spare::Pool;
use crate::engine::trajectory::Trajectory;
use crate::model::StampNs;

/// The source's mesh rendered along the target's rays turned by the
/// rotation-only `trajectory`; `None` where the source has no table of
/// its mesh's triangles to walk (no joins: the caller rasterises).
pub(super) fn render_rotated(
    source: &Source,
    target: &Target,
    geometry: &ImageGeometry,
    trajectory: &Trajectory,
    scan_offset_ns: StampNs,
) -> Option<Rendered> {
    let cells = geometry.cells();
    // The plan's triangles, or the scan's own where it bridges nothing.
    let bits = if source.bridged.bits.is_empty() {
        &source.surfaces.joins
    } else {
        &source.bridged.bits
    };
    if geometry.rows < 2 || geometry.cols == 0 || bits.len() != cells {
        return None;
    }
    let mesh = SharedMesh::of(source, geometry, trajectory);
    let arrivals = arrivals(target, geometry, trajectory, &mesh.column_turns);
    let mut rendered = Rendered {
        range_m: vec![f32::NAN; cells],
        source_time_ns: vec![0; cells],
        normal: vec![[0.0; 3]; cells],
        edge: vec![false; cells],
    };
    let cols = geometry.cols;
    let walk = Walk {
        mesh: &mesh,
        bits,
        rows: geometry.rows,
        cols,
        column_time_ns: target.column_time_ns,
        scan_offset_ns,
        seam_ns: scan_offset_ns.abs() / 4,
    };
    rendered
        .range_m
        .par_chunks_mut(cols)
        .zip(rendered.source_time_ns.par_chunks_mut(cols))
        .zip(rendered.normal.par_chunks_mut(cols))
        .zip(rendered.edge.par_chunks_mut(cols))
        .enumerate()
        .for_each_init(
            RowRays::default,
            |rays, (row, (((range_m, time_ns), normal), edge))| {
                rays.turn_back(target, geometry, &arrivals, row);
                for (&col, (ray, &at)) in rays.col.iter().zip(rays.ray.iter().zip(&rays.at)) {
                    let col = col as usize;
                    let (Some(arrival), Some(hit)) = (&arrivals[col], walk.hit(ray, at)) else {
                        continue;
                    };
                    range_m[col] = hit.range_m as f32;
                    time_ns[col] = hit.time_ns;
                    // Into the target's frame: the inverse of the column's turn.
                    let n = arrival.turn.tr_mul(&hit.normal);
                    let unit = n / n.norm().max(1e-300);
                    normal[col] = [unit.x as f32, unit.y as f32, unit.z as f32];
                    edge[col] = hit.edge;
                }
            },
        );
    mesh.recycle();
    Some(rendered)
}

/// The source's vertices: their points in one frame (each return's turned
/// by its pose's orientation at its time, `reference_from_lidar`, so that
/// a target ray turned by its column's meets them all as the raster's
/// moved ones), their image coordinates as seen (`(col_f, row_f)`), their
/// times; the dropouts the source's plan bridges (`BridgedMesh::proxy`) at
/// the midpoint of their row neighbours, as the raster's `fill_dropouts`
/// puts them. Row-major; a NaN column where no vertex.
#[derive(Default)]
struct SharedMesh {
    point: Vec<[f64; 3]>,
    coords: Vec<[f64; 2]>,
    time_ns: Vec<StampNs>,
    /// Per source column, its returns' orientation at the column's first
    /// and last time (`None`: no return).
    column_turns: Vec<Option<ColumnTurn>>,
}

static SPARE_MESH: Pool<SharedMesh> = Pool::new();

/// The orientations of a source column's returns: exact at its first
/// (`start_ns`) and last time, straight between where the column spans at
/// most [`MAX_LINE_NS`] (a straight matrix departs from the turn by about
/// an eighth of the squared angle: 3e-7 rad over the Pandar64's 3.3 ms
/// columns at 0.5 rad/s), exact at each return's time where it spans more
/// (the seam's column, whose returns lie a period apart).
#[derive(Clone, Copy)]
struct ColumnTurn {
    start_ns: StampNs,
    start: Matrix3<f64>,
    /// The change per nanosecond after `start_ns`; `None`: each return's
    /// own.
    per_ns: Option<Matrix3<f64>>,
}

/// The longest span of a column's times its orientations are taken along
/// a line over.
const MAX_LINE_NS: StampNs = 5_000_000;

impl ColumnTurn {
    fn of(trajectory: &Trajectory, (first_ns, last_ns): (StampNs, StampNs)) -> Self {
        let start = orientation(trajectory, first_ns);
        let span_ns = last_ns - first_ns;
        let per_ns = match span_ns {
            0 => Some(Matrix3::zeros()),
            1..=MAX_LINE_NS => Some((orientation(trajectory, last_ns) - start) / span_ns as f64),
            _ => None,
        };
        Self {
            start_ns: first_ns,
            start,
            per_ns,
        }
    }

    #[inline]
    fn at(&self, trajectory: &Trajectory, time_ns: StampNs) -> Matrix3<f64> {
        match &self.per_ns {
            _ if time_ns == self.start_ns => self.start,
            Some(per_ns) => self.start + per_ns * (time_ns - self.start_ns) as f64,
            None => orientation(trajectory, time_ns),
        }
    }
}

/// The orientation part of `reference_from_lidar` at `time_ns`.
fn orientation(trajectory: &Trajectory, time_ns: StampNs) -> Matrix3<f64> {
    trajectory
        .pose(time_ns)
        .rotation
        .to_rotation_matrix()
        .into_inner()
}

impl SharedMesh {
    fn of(source: &Source, geometry: &ImageGeometry, trajectory: &Trajectory) -> Self {
        let (rows, cols) = (geometry.rows, geometry.cols);
        let table = &source.columns;
        let surfaces = source.surfaces;
        let mut mesh = SPARE_MESH.take();
        mesh.column_turns = (0..cols)
            .into_par_iter()
            .map(|col| {
                let at = col * rows..(col + 1) * rows;
                let times = table.range_m[at.clone()]
                    .iter()
                    .zip(&table.time_ns[at])
                    .filter(|(range_m, _)| range_m.is_finite())
                    .map(|(_, &t)| t);
                let span = times.fold(None, |span: Option<(StampNs, StampNs)>, t| {
                    Some(span.map_or((t, t), |(lo, hi)| (lo.min(t), hi.max(t))))
                });
                span.map(|span| ColumnTurn::of(trajectory, span))
            })
            .collect();
        let cells = rows * cols;
        mesh.point = crate::engine::spare::filled(std::mem::take(&mut mesh.point), cells, [0.0; 3]);
        mesh.coords =
            crate::engine::spare::filled(std::mem::take(&mut mesh.coords), cells, [f64::NAN; 2]);
        mesh.time_ns = crate::engine::spare::filled(std::mem::take(&mut mesh.time_ns), cells, 0);
        let turns = &mesh.column_turns;
        let proxy = &source.bridged.proxy;
        mesh.point
            .par_chunks_mut(cols)
            .zip(mesh.coords.par_chunks_mut(cols))
            .zip(mesh.time_ns.par_chunks_mut(cols))
            .enumerate()
            .for_each(|(row, ((points, coords), times))| {
                let row_cells = row * cols..(row + 1) * cols;
                for (col, cell) in row_cells.clone().enumerate() {
                    let range_m = surfaces.range_m[cell];
                    let Some(turn) = turns[col].as_ref().filter(|_| range_m.is_finite()) else {
                        continue;
                    };
                    // The point as the raster's source table holds it.
                    let [x, y, z] = surfaces.direction[cell].map(f64::from);
                    let p = Vector3::new(x, y, z) * f64::from(range_m);
                    let q = turn.at(trajectory, source.time_ns[cell]) * p;
                    points[col] = [q.x, q.y, q.z];
                    times[col] = source.time_ns[cell];
                    let (row_f, col_f) = geometry.coords_of(
                        (surfaces.azimuth_rad[cell], surfaces.elevation_rad[cell]),
                        f64::from(range_m),
                        row,
                    );
                    coords[col] = [col_f, row_f];
                }
                if let Some(proxy) = proxy.get(row_cells.clone()) {
                    bridge_row(proxy, row_cells.start, (points, coords, times));
                }
            });
        mesh
    }

    fn recycle(self) {
        SPARE_MESH.give(self);
    }
}

/// The dropouts of one row the plan bridges (`proxy`: the left neighbour
/// where it does), left to right as `fill_dropouts` takes them: at the
/// midpoint of the neighbours' vertices (where they lie within three
/// columns, as there: not across the seam), their times' midpoint.
fn bridge_row(
    proxy: &[u32],
    first: usize,
    (points, coords, times): (&mut [[f64; 3]], &mut [[f64; 2]], &mut [StampNs]),
) {
    let cols = points.len();
    for col in 0..cols {
        if proxy[col] as usize == first + col {
            continue;
        }
        let (left, right) = ((col + cols - 1) % cols, (col + 1) % cols);
        let (a, b) = (coords[left], coords[right]);
        if a[0].is_nan() || b[0].is_nan() || (a[0] - b[0]).abs() > MAX_BRIDGE_COLS {
            continue;
        }
        let (pa, pb) = (points[left], points[right]);
        points[col] = [0, 1, 2].map(|k| (pa[k] + pb[k]) * 0.5);
        coords[col] = [0.5 * (a[0] + b[0]), 0.5 * (a[1] + b[1])];
        times[col] = times[left] + (times[right] - times[left]) / 2;
    }
}

/// Per target column (`None`: no time, so no return), the turn of its rays
/// into the mesh's frame (the orientation at the column's time) and back
/// into the source's lidar frame where they land (the transposed
/// orientation of the source column its middle ray lands in).
struct Arrival {
    turn: Matrix3<f64>,
    back: Matrix3<f64>,
}

fn arrivals(
    target: &Target,
    geometry: &ImageGeometry,
    trajectory: &Trajectory,
    source_turns: &[Option<ColumnTurn>],
) -> Vec<Option<Arrival>> {
    target
        .column_time_ns
        .par_iter()
        .enumerate()
        .map(|(col, &time_ns)| {
            (time_ns != StampNs::MIN).then(|| {
                let turn = orientation(trajectory, time_ns);
                let back = landing_turn(geometry, &turn, source_turns, col).transpose();
                Arrival { turn, back }
            })
        })
        .collect()
}

/// The orientation of the source column target column `col`'s middle ray
/// lands in, turned by `turn` into the mesh's frame: found in two turns
/// (the landing column's orientation differs from the first guess's by
/// its time); the target column's own where that has none.
fn landing_turn(
    geometry: &ImageGeometry,
    turn: &Matrix3<f64>,
    source_turns: &[Option<ColumnTurn>],
    col: usize,
) -> Matrix3<f64> {
    let cols = geometry.cols;
    let beams = &geometry.beams.elevations_rad;
    let elevation_rad = beams.get(beams.len() / 2).copied().unwrap_or(0.0);
    let azimuth_rad = std::f64::consts::PI - col as f64 * std::f64::consts::TAU / cols as f64;
    let ray = turn
        * Vector3::new(
            elevation_rad.cos() * azimuth_rad.cos(),
            elevation_rad.cos() * azimuth_rad.sin(),
            elevation_rad.sin(),
        );
    let mut landing = *turn;
    let mut guess = col;
    for _ in 0..2 {
        let Some(source) = &source_turns[guess] else {
            break;
        };
        landing = source.start;
        let back = source.start.tr_mul(&ray);
        guess = geometry.col_of(atan2(back.y, back.x));
    }
    landing
}

/// One target row's rays turned, by a worker (its arrays reused row after
/// row): every ray's turn and image coordinates in the source first, then
/// the walks. (Measured: no faster than one loop, but the phases read
/// apart.)
#[derive(Default)]
struct RowRays {
    /// The columns holding a return with a time.
    col: Vec<u32>,
    /// Each one's ray in the mesh's frame.
    ray: Vec<Vector3<f64>>,
    /// Its coordinates in the source's image (column, row).
    at: Vec<(f64, f64)>,
}

impl RowRays {
    /// The rays of target row `row` turned into the mesh's frame, and
    /// their coordinates in the source's image: each ray's azimuth and
    /// elevation turned by the slight turns (`turn_rad`: a series, not an
    /// `atan2`) from its own direction to its direction in the source's
    /// lidar frame; the row at the ray's own range (a laser's parallax).
    fn turn_back(
        &mut self,
        target: &Target,
        geometry: &ImageGeometry,
        arrivals: &[Option<Arrival>],
        row: usize,
    ) {
        let cols = geometry.cols;
        let surfaces = target.surfaces;
        let first = row * cols;
        self.col.clear();
        self.ray.clear();
        self.at.clear();
        for (col, arrival) in arrivals.iter().enumerate().take(cols) {
            let cell = first + col;
            let Some(arrival) = arrival
                .as_ref()
                .filter(|_| surfaces.range_m[cell].is_finite())
            else {
                continue;
            };
            let [x, y, z] = surfaces.direction[cell].map(f64::from);
            let ray = arrival.turn * Vector3::new(x, y, z);
            let back = arrival.back * ray;
            let azimuth_rad = surfaces.azimuth_rad[cell] + turn_rad((x, y), (back.x, back.y));
            let (level, back_level) = (
                (x * x + y * y).sqrt(),
                (back.x * back.x + back.y * back.y).sqrt(),
            );
            let elevation_rad =
                surfaces.elevation_rad[cell] + turn_rad((level, z), (back_level, back.z));
            let range_m = f64::from(surfaces.range_m[cell]);
            self.col.push(col as u32);
            self.ray.push(ray);
            self.at.push((
                geometry.col_f(azimuth_rad),
                geometry.row_f_at(elevation_rad, range_m, row),
            ));
        }
    }
}

/// A ray's hit on the mesh, in the mesh's frame.
struct Hit {
    range_m: f64,
    time_ns: StampNs,
    /// The triangle's `(b - a) x (c - a)`, unnormalised.
    normal: Vector3<f64>,
    edge: bool,
}

/// What every ray's walk shares.
struct Walk<'m> {
    mesh: &'m SharedMesh,
    /// The triangle bits per quad: the plan's (`BridgedMesh::bits`), or
    /// the scan's own joins' where it bridges nothing.
    bits: &'m [u8],
    rows: usize,
    cols: usize,
    /// The target's column times.
    column_time_ns: &'m [StampNs],
    scan_offset_ns: StampNs,
    /// A quarter of the scan period: see [`Walk::across_seam`].
    seam_ns: StampNs,
}

/// Steps a walk takes before it searches the quads around it.
const MAX_STEPS: usize = 8;

/// A triangle of the mesh: its quad's row and column (top-left vertex),
/// and which of its two: `(a, b, c)` or `(b, d, c)`, with `b` the next
/// column's, `c` the next row's, `d` both.
#[derive(Clone, Copy)]
struct Triangle {
    row: usize,
    col: usize,
    second: bool,
}

impl Walk<'_> {
    /// The hit of `ray` (in the mesh's frame) at the source's image coordinates `at` (column,
    /// row), the walk starting in the triangle of the cells `at` lies
    /// among.
    fn hit(&self, ray: &Vector3<f64>, at: (f64, f64)) -> Option<Hit> {
        let mut triangle = self.start(at)?;
        for _ in 0..MAX_STEPS {
            let corners = self.corners(triangle);
            let Some(flat) = self.flat(corners, at.0) else {
                return self.search(ray, at, triangle);
            };
            let s = edge_products(&flat, at);
            // The edge `at` lies furthest outside of, if any.
            let (outside, _) = (0..3).fold((None, 0.0), |(k, worst), i| {
                if s[i] < worst {
                    (Some(i), s[i])
                } else {
                    (k, worst)
                }
            });
            match outside {
                None => return self.hit_inside(ray, triangle, corners, s),
                Some(i) => triangle = self.across(triangle, i)?,
            }
        }
        self.search(ray, at, triangle)
    }

    /// The triangle holding image coordinates `(col_f, row_f)` were the
    /// vertices at their cells' own: `(a, b, c)` below the quad's
    /// diagonal. `None` outside the image's rows.
    fn start(&self, (col_f, row_f): (f64, f64)) -> Option<Triangle> {
        if !(row_f > -1.0 && row_f < self.rows as f64) {
            return None;
        }
        let row = row_f.floor().clamp(0.0, (self.rows - 2) as f64);
        // `col_f` lies in [0, cols): a whole column, but for rounding.
        let col = col_f.floor();
        let (fr, fc) = (row_f - row, col_f - col);
        Some(Triangle {
            row: row as usize,
            col: (col as usize).min(self.cols - 1),
            second: fr + fc > 1.0,
        })
    }

    /// The columns of the triangle's corners, in its winding order.
    #[inline]
    fn columns(&self, t: Triangle) -> [usize; 3] {
        let next = if t.col + 1 == self.cols { 0 } else { t.col + 1 };
        if t.second {
            [next, next, t.col]
        } else {
            [t.col, next, t.col]
        }
    }

    /// The triangle's cells in its winding order: `(a, b, c)` or `(b, d,
    /// c)`, the first two in the quad's row, the last in the next.
    #[inline]
    fn corners(&self, t: Triangle) -> [usize; 3] {
        let [p, q, r] = self.columns(t);
        let row = t.row * self.cols;
        let lower = if t.second { row + self.cols } else { row };
        [row + p, lower + q, row + self.cols + r]
    }

    /// The corners' image coordinates, columns taken next to `near` (across
    /// the seam); `None` where one has no vertex.
    #[inline]
    fn flat(&self, corners: [usize; 3], near: f64) -> Option<[[f64; 2]; 3]> {
        let half_turn = self.cols as f64 / 2.0;
        let mut flat = corners.map(|k| self.mesh.coords[k]);
        for [col, _] in &mut flat {
            if col.is_nan() {
                return None;
            }
            if *col - near > half_turn {
                *col -= self.cols as f64;
            } else if near - *col > half_turn {
                *col += self.cols as f64;
            }
        }
        Some(flat)
    }

    /// The triangle across the edge opposite corner `i` (`None` past the
    /// image's first or last row).
    fn across(&self, t: Triangle, i: usize) -> Option<Triangle> {
        let (row, col) = (t.row, t.col);
        let left = if col == 0 { self.cols - 1 } else { col - 1 };
        let right = if col + 1 == self.cols { 0 } else { col + 1 };
        let (row, col, second) = match (t.second, i) {
            // (a, b, c): the diagonal, the column's own edge, the row's.
            (false, 0) => (row, col, true),
            (false, 1) => (row, left, true),
            (false, _) => (row.checked_sub(1)?, col, true),
            // (b, d, c): the next row's edge, the diagonal, the next column's.
            (true, 0) => (row + 1, col, false),
            (true, 1) => (row, col, false),
            (true, _) => (row, right, false),
        };
        (row + 1 < self.rows).then_some(Triangle { row, col, second })
    }

    /// The nearest hit among the triangles of the quads around `t`'s:
    /// where the walk met a missing vertex or did not settle.
    fn search(&self, ray: &Vector3<f64>, at: (f64, f64), t: Triangle) -> Option<Hit> {
        let mut best: Option<Hit> = None;
        for row in t.row.saturating_sub(1)..=(t.row + 1).min(self.rows - 2) {
            for step in [self.cols - 1, 0, 1] {
                let col = (t.col + step) % self.cols;
                for second in [false, true] {
                    let triangle = Triangle { row, col, second };
                    let corners = self.corners(triangle);
                    let Some(flat) = self.flat(corners, at.0) else {
                        continue;
                    };
                    let s = edge_products(&flat, at);
                    if s.iter().any(|&v| v < 0.0) {
                        continue;
                    }
                    let hit = self.hit_inside(ray, triangle, corners, s);
                    if let Some(hit) = hit
                        && best.as_ref().is_none_or(|b| hit.range_m < b.range_m)
                    {
                        best = Some(hit);
                    }
                }
            }
        }
        best
    }

    /// The hit on triangle `t` (cells `corners`) of a ray inside it (its
    /// edge products `s`): `None` where the mesh has no such triangle, a
    /// vertex lies across the seam, or the ray runs along its plane.
    fn hit_inside(
        &self,
        ray: &Vector3<f64>,
        t: Triangle,
        corners: [usize; 3],
        s: [f64; 3],
    ) -> Option<Hit> {
        let bits = self.bits[t.row * self.cols + t.col];
        let (exists, edge) = if t.second {
            (QUAD_SECOND, EDGE_SECOND)
        } else {
            (QUAD_FIRST, EDGE_FIRST)
        };
        let total = s[0] + s[1] + s[2];
        if bits & exists == 0 || total <= 0.0 {
            return None;
        }
        let times = corners.map(|k| self.mesh.time_ns[k]);
        let columns = self.columns(t);
        if (0..3).any(|i| self.across_seam(columns[i], times[i])) {
            return None;
        }
        let [a, b, c] = corners.map(|k| Vector3::from(self.mesh.point[k]));
        let normal = (b - a).cross(&(c - a));
        let along = normal.dot(ray);
        // Along the plane within 1e-12 of the normal's length (squared: no root).
        if along * along < 1e-24 * normal.norm_squared() {
            return None;
        }
        let range_m = normal.dot(&a) / along;
        if !(range_m > 0.0 && range_m < f64::INFINITY) {
            return None;
        }
        let per_total = 1.0 / total;
        let time = (0..3)
            .map(|i| s[i] * per_total * times[i] as f64)
            .sum::<f64>();
        Some(Hit {
            range_m,
            time_ns: time.round() as StampNs,
            normal,
            edge: bits & edge != 0,
        })
    }
}

impl Walk<'_> {
    /// Whether the vertex of source column `col` seen at `time_ns` lands
    /// across the seam of the sweep: the target fires its column (the
    /// raster's landing column, but for the turn's few columns) further
    /// than a quarter period from a whole scan period later, so it would be
    /// compared with a return fired a period earlier or later (the raster
    /// drops it).
    #[inline]
    fn across_seam(&self, col: usize, time_ns: StampNs) -> bool {
        let column_ns = self.column_time_ns[col];
        column_ns != StampNs::MIN
            && (column_ns - (time_ns + self.scan_offset_ns)).abs() > self.seam_ns
    }
}

/// For each corner `p` of the flat triangle `(p, q, r)` (column, row), the
/// cross product `(r - q) x (at - q)` of its opposite edge: twice the area
/// `at` makes with that edge, positive on the triangle's side (the mesh's
/// triangles wind counter-clockwise in (column, row)), so all three are
/// non-negative where `at` lies inside, and each over their sum is its
/// corner's barycentric weight.
#[inline]
fn edge_products(flat: &[[f64; 2]; 3], (col_f, row_f): (f64, f64)) -> [f64; 3] {
    let side =
        |q: [f64; 2], r: [f64; 2]| (r[0] - q[0]) * (row_f - q[1]) - (r[1] - q[1]) * (col_f - q[0]);
    [
        side(flat[1], flat[2]),
        side(flat[2], flat[0]),
        side(flat[0], flat[1]),
    ]
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::engine::beams::BeamTable;
    use crate::engine::surface::Surfaces;
    use crate::engine::trajectory::MotionModel;
    use crate::engine::warp::{mesh_joins, render};
    use crate::model::{PairMotion, TimeSeries};

    const ROWS: usize = 16;
    const COLS: usize = 512;
    const PERIOD_NS: StampNs = 100_000_000;
    const SOURCE_NS: StampNs = 1_000_000_000;

    /// A sensor turning at a steady rate (0.6 rad/s of yaw, some pitch and
    /// roll), from `SOURCE_NS`: its poses over two scans.
    fn turning() -> Trajectory {
        let samples = (-5..40)
            .map(|i| {
                let t_ns = SOURCE_NS + i * 10_000_000;
                (t_ns, Vector3::new(0.05, -0.08, 0.6))
            })
            .collect();
        let motion = PairMotion::in_lidar_frame(None, Some(TimeSeries::new(samples, 0.2)));
        let (start_ns, end_ns) = (SOURCE_NS - 1_000_000, SOURCE_NS + 2 * PERIOD_NS + 1_000_000);
        Trajectory::integrate(&motion, MotionModel::RotationOnly, true, start_ns, end_ns).unwrap()
    }

    /// From the origin along unit `d` (the frame the poses start in) to a
    /// box room's inside (walls 8 and 6 m off, floor 1.5 m down, ceiling 3
    /// m up): the range and the face's normal towards the origin.
    fn room(d: &Vector3<f64>) -> (f64, Vector3<f64>) {
        let faces = [
            (0, 8.0),
            (0, -8.0),
            (1, 6.0),
            (1, -6.0),
            (2, 3.0),
            (2, -1.5),
        ];
        faces
            .iter()
            .filter_map(|&(axis, at): &(usize, f64)| {
                let range_m = at / d[axis];
                let mut normal = Vector3::zeros();
                normal[axis] = -at.signum();
                (range_m > 0.0).then_some((range_m, normal))
            })
            .min_by(|a, b| a.0.total_cmp(&b.0))
            .unwrap()
    }

    fn geometry() -> ImageGeometry {
        ImageGeometry {
            rows: ROWS,
            cols: COLS,
            beams: BeamTable::uniform(ROWS, -0.25, 0.15),
            ring_to_row: None,
            parallax_rad_m: None,
        }
    }

    /// A scan of the room from `start_ns`, each column fired at its own
    /// time, its returns' azimuths off their column's by up to 0.3 of a
    /// column; the cells `dropped` says without a return. Its surfaces
    /// (the true normals, the mesh's joins) and each cell's time.
    fn scan(
        trajectory: &Trajectory,
        start_ns: StampNs,
        dropped: impl Fn(usize) -> bool,
    ) -> (Surfaces, Vec<StampNs>) {
        let geometry = geometry();
        let cells = ROWS * COLS;
        let (mut range_m, mut direction, mut normal) = (
            vec![f32::NAN; cells],
            vec![[0.0f32; 3]; cells],
            vec![[0.0f32; 3]; cells],
        );
        let mut time_ns = vec![0; cells];
        for cell in 0..cells {
            let (row, col) = (cell / COLS, cell % COLS);
            let jitter = ((cell * 7919) % 601) as f64 / 1000.0 - 0.3;
            let azimuth_rad =
                std::f64::consts::PI - (col as f64 + jitter) * std::f64::consts::TAU / COLS as f64;
            let elevation_rad = geometry.beams.elevations_rad[row];
            let e = Vector3::new(
                elevation_rad.cos() * azimuth_rad.cos(),
                elevation_rad.cos() * azimuth_rad.sin(),
                elevation_rad.sin(),
            );
            time_ns[cell] = start_ns + col as StampNs * PERIOD_NS / COLS as StampNs;
            let turn = orientation(trajectory, time_ns[cell]);
            let (range, n) = room(&(turn * e));
            let n = turn.tr_mul(&n);
            direction[cell] = [e.x as f32, e.y as f32, e.z as f32];
            normal[cell] = [n.x as f32, n.y as f32, n.z as f32];
            if !dropped(cell) {
                range_m[cell] = range as f32;
            }
        }
        let mut surfaces = Surfaces::hand_made(range_m, direction, normal, vec![0.01; ROWS], COLS);
        for cell in 0..cells {
            let [x, y, z] = surfaces.direction[cell].map(f64::from);
            surfaces.azimuth_rad[cell] = y.atan2(x);
            surfaces.elevation_rad[cell] = z.atan2(x.hypot(y));
        }
        surfaces.support = vec![9; cells];
        surfaces.joins = mesh_joins(&surfaces, ROWS, COLS);
        (surfaces, time_ns)
    }

    /// The rotation-only render sampled ray by ray against the truth and
    /// the raster, on a turning sensor in a room: the room's ranges (a
    /// turn about the sensor changes none) and faces' normals, the
    /// raster's ranges, times and rays covered; with one-cell dropouts
    /// bridged.
    #[test]
    fn sampled_turn_matches_the_raster_and_the_room() {
        let geometry = geometry();
        let trajectory = turning();
        let (source, source_ns) = scan(&trajectory, SOURCE_NS, |cell| cell % 37 == 5);
        let (target, _) = scan(&trajectory, SOURCE_NS + PERIOD_NS, |_| false);
        let coords: Vec<(f32, f32)> = (0..ROWS * COLS)
            .map(|cell| {
                let range_m = f64::from(target.range_m[cell]);
                let row_f = geometry.row_f_at(target.elevation_rad[cell], range_m, cell / COLS);
                (
                    row_f as f32,
                    geometry.col_f(target.azimuth_rad[cell]) as f32,
                )
            })
            .collect();
        let column_time_ns: Vec<StampNs> = (0..COLS as StampNs)
            .map(|col| SOURCE_NS + PERIOD_NS + col * PERIOD_NS / COLS as StampNs)
            .collect();
        let source = Source::new(&source, &source_ns);
        let target_rays = Target::new(&target, &coords, &column_time_ns);
        let sampled =
            render_rotated(&source, &target_rays, &geometry, &trajectory, PERIOD_NS).unwrap();
        let raster = render(&source, &target_rays, &geometry, &trajectory, PERIOD_NS);
        let (mut both, mut one, mut off_room, mut off_face) = (0, 0, 0, 0);
        for cell in 0..ROWS * COLS {
            let (s, r) = (sampled.range_m[cell], raster.range_m[cell]);
            if s.is_nan() != r.is_nan() {
                one += 1;
                continue;
            }
            if s.is_nan() {
                continue;
            }
            both += 1;
            assert!((s - r).abs() < 1e-4 * r, "cell {cell}: {s} against {r}");
            if (s - target.range_m[cell]).abs() > 1e-6 * s {
                off_room += 1;
            }
            let dt_ns = (sampled.source_time_ns[cell] - raster.source_time_ns[cell]).abs();
            assert!(dt_ns < 2_000, "cell {cell}: times {dt_ns} ns apart");
            // The face's own normal, where the raster's triangles tilt by
            // the turn over the columns its vertices land in (0.6 rad/s
            // over a column: 1e-4 to 2e-3 here).
            let normal_gap = (0..3)
                .map(|k| (sampled.normal[cell][k] - target.normal[cell][k]).abs())
                .fold(0.0f32, f32::max);
            if normal_gap > 1e-4 || sampled.edge[cell] {
                off_face += 1;
            }
        }
        let cells = ROWS * COLS;
        // The room's corners hold no triangle (no joins across faces);
        // the rest of the image is covered (86 %), the two differing on
        // the corners' rays by the triangles' edges (1 %).
        assert!(both > cells * 8 / 10, "{both} of {cells} covered");
        assert!(one * 50 < cells, "{one} covered by one only");
        assert!(off_room * 1000 < both, "{off_room} off the room");
        assert!(off_face * 1000 < both, "{off_face} off the room's faces");
    }
}
