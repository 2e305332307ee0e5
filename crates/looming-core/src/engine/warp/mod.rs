//! Rendering the previous scan into the current scan's rays: the previous
//! scan's surface (a triangle mesh over its range image) is moved by a motion
//! model to each target ray's time and intersected with that ray. Sub-cell
//! exact on planar surfaces, so the static road does not light up from
//! discretisation; z-buffered, so the nearest surface wins.
//!
//! Here the render and its z-buffer; the source's fields column-major,
//! once per pair, in `source_columns.rs`; the vertices moved column by
//! column in `moved_column.rs` (the transform cache and the turns in
//! `moved_vertices.rs`, a column of a few recurring times' exact
//! transforms in `recurring.rs`), the mesh's joins and bridged dropouts in `mesh.rs`,
//! the rasterisation in `raster.rs` (its common case in `full_quad.rs`);
//! the rotation-only render sampled ray by ray, without a raster, in
//! `rotated.rs`.

mod bridges;
mod flat_triangle;
mod full_quad;
mod mesh;
mod moved_column;
mod moved_vertices;
mod raster;
mod recurring;
mod rotated;
mod source_columns;

use nalgebra::{Point3, Vector3};
use rayon::prelude::*;

use super::grid::ImageGeometry;
use super::surface::Surfaces;
use super::trajectory::Trajectory;
use crate::model::StampNs;

use bridges::BridgedMesh;
use mesh::fill_dropouts;
pub(super) use mesh::mesh_joins;
use moved_column::{ColumnRows, ColumnWarp};
use moved_vertices::arrival_poses;
use raster::{rasterize_columns, rasterize_ring};
use source_columns::SourceColumns;

/// One scan's surface, ready to be warped.
pub(crate) struct Source<'a> {
    pub surfaces: &'a Surfaces,
    /// The fields the warp reads, column-major (with each return's time),
    /// transposed once for every render of the pair.
    columns: SourceColumns,
    /// Its dropouts as a render will most likely bridge them, and the
    /// mesh's triangles then: decided once for every render of the pair.
    bridged: BridgedMesh,
    /// Each cell's time, row-major (as `surfaces`).
    time_ns: &'a [StampNs],
}

impl<'a> Source<'a> {
    /// The surface `surfaces`, the absolute time of each cell's return
    /// `time_ns` (meaningful where a range is set).
    pub fn new(surfaces: &'a Surfaces, time_ns: &'a [StampNs]) -> Self {
        Self {
            surfaces,
            columns: SourceColumns::of(surfaces, time_ns),
            bridged: BridgedMesh::of(surfaces),
            time_ns,
        }
    }
}

/// The rays to render into.
pub struct Target<'a> {
    pub surfaces: &'a Surfaces,
    /// Continuous (row, column) of each occupied cell's ray.
    pub coords: &'a [(f32, f32)],
    /// Median firing time of each column, ns (for a rolling sweep).
    pub column_time_ns: &'a [StampNs],
    /// How far an occupied cell's coordinates lie from the cell's own
    /// (row, column) at most, in rows and columns: a triangle can only
    /// cover the cells this near its bounding box.
    reach: (f64, f64),
    /// The same per target row and per target column ([`Bands`]): a few
    /// stray rays (one in 100 000 on KITTI's, a whole row off) set the
    /// global reach, where most rows' rays lie within a tenth of a row.
    bands: Bands,
}

/// How far the occupied cells' coordinates lie from their own cells, per
/// target row (`rows`: furthest below and above, rows) and per target
/// column (`cols`: furthest left and right, columns, across the seam), so
/// that a quad's box can drop the rows and columns at its ends whose rays
/// cannot reach it. An empty row or column holds `-inf`: never reached.
pub(super) struct Bands {
    pub rows: Vec<Reach>,
    pub cols: Vec<Reach>,
    /// The same as the coordinates the rays reach ([`Span`]), which the
    /// rasteriser compares with each quad's box (four per quad: the
    /// conversions and sums taken once per target, not per quad).
    pub row_spans: Vec<Span>,
    pub col_spans: Vec<Span>,
}

/// The lowest and highest coordinates (rows or columns) the rays of row
/// or column `i` reach, widened by [`REACH_SLACK`]: `i - before - slack`
/// and `i + after + slack`, in that order of operations (`+inf` and
/// `-inf` where it has none).
#[derive(Clone, Copy)]
pub(super) struct Span {
    pub lowest: f64,
    pub highest: f64,
}

impl Span {
    fn all(reaches: &[Reach]) -> Vec<Self> {
        reaches
            .iter()
            .enumerate()
            .map(|(i, r)| Self {
                lowest: i as f64 - r.before - REACH_SLACK,
                highest: i as f64 + r.after + REACH_SLACK,
            })
            .collect()
    }
}

/// The furthest offsets of a row's or column's rays from it, in cells:
/// `before` towards smaller indices, `after` towards larger ones (negative
/// where every ray lies on the other side).
#[derive(Clone, Copy)]
pub(super) struct Reach {
    pub before: f64,
    pub after: f64,
}

impl Reach {
    const NONE: Self = Self {
        before: f64::NEG_INFINITY,
        after: f64::NEG_INFINITY,
    };

    fn with(self, offset: f64) -> Self {
        Self {
            before: self.before.max(-offset),
            after: self.after.max(offset),
        }
    }

    /// The reach of both.
    fn joined(self, other: Self) -> Self {
        Self {
            before: self.before.max(other.before),
            after: self.after.max(other.after),
        }
    }
}

/// Rows of a task of [`Bands::of`] and `fill_dropouts`: 8 tasks at 64
/// rows.
const BAND_ROWS: usize = 8;

/// The image's `rows` in bands of [`BAND_ROWS`], on rayon's workers, in
/// order.
fn row_bands(rows: usize) -> impl IndexedParallelIterator<Item = std::ops::Range<usize>> {
    (0..rows.div_ceil(BAND_ROWS))
        .into_par_iter()
        .map(move |band| band * BAND_ROWS..((band + 1) * BAND_ROWS).min(rows))
}

/// The reaches of the rows `band` (one each, in order), and of every column
/// over those rows, from the occupied cells' `coords` (an image `cols`
/// wide).
fn band_reaches(
    surfaces: &Surfaces,
    coords: &[(f32, f32)],
    cols: usize,
    band: std::ops::Range<usize>,
) -> (Vec<Reach>, Vec<Reach>) {
    let mut col_reach = vec![Reach::NONE; cols];
    let row_reach = band
        .map(|row| {
            let mut reach = Reach::NONE;
            let cells = row * cols..(row + 1) * cols;
            let row_cells = surfaces.range_m[cells.clone()].iter().zip(&coords[cells]);
            for (col, (column, (range_m, &(row_f, col_f)))) in
                col_reach.iter_mut().zip(row_cells).enumerate()
            {
                if !range_m.is_finite() {
                    continue;
                }
                reach = reach.with(f64::from(row_f) - row as f64);
                *column = column.with(col_offset(col_f, col, cols));
            }
            reach
        })
        .collect();
    (row_reach, col_reach)
}

impl Bands {
    fn of(surfaces: &Surfaces, coords: &[(f32, f32)]) -> Self {
        let cols = surfaces.cols.max(1);
        let rows = coords.len() / cols;
        // Bands of rows on rayon's workers (one pass on one core: 23 of
        // the synthetic drive's 968 idle samples, `perf -a`), each with its
        // rows' reaches and its columns' over its rows; the columns' then
        // taken over the bands (the same maxima in another order).
        let bands: Vec<(Vec<Reach>, Vec<Reach>)> = row_bands(rows)
            .map(|band| band_reaches(surfaces, coords, cols, band))
            .collect();
        let mut col_reach = vec![Reach::NONE; cols];
        let mut row_reach = Vec::with_capacity(rows);
        for (band_rows, band_cols) in bands {
            row_reach.extend(band_rows);
            for (reach, band) in col_reach.iter_mut().zip(band_cols) {
                *reach = reach.joined(band);
            }
        }
        Self {
            row_spans: Span::all(&row_reach),
            col_spans: Span::all(&col_reach),
            rows: row_reach,
            cols: col_reach,
        }
    }

    /// The largest distance, in rows and in columns (across the seam), of
    /// an occupied cell's coordinates from the cell's own row and column:
    /// the furthest of the bands' (0 for an empty image).
    fn reach(&self) -> (f64, f64) {
        let furthest = |reaches: &[Reach]| {
            reaches
                .iter()
                .fold(0.0f64, |far, r| far.max(r.before).max(r.after))
        };
        (furthest(&self.rows), furthest(&self.cols))
    }
}

/// Column coordinate `col_f`'s offset from column `col`, across the seam.
fn col_offset(col_f: f32, col: usize, cols: usize) -> f64 {
    let half_turn = cols as f64 / 2.0;
    let mut col_off = f64::from(col_f) - col as f64;
    if col_off > half_turn {
        col_off -= cols as f64;
    } else if col_off < -half_turn {
        col_off += cols as f64;
    }
    col_off
}

impl<'a> Target<'a> {
    pub fn new(
        surfaces: &'a Surfaces,
        coords: &'a [(f32, f32)],
        column_time_ns: &'a [StampNs],
    ) -> Self {
        let bands = Bands::of(surfaces, coords);
        Self {
            surfaces,
            coords,
            column_time_ns,
            reach: bands.reach(),
            bands,
        }
    }
}

/// Added to a target's reach: a ray passes the triangle test up to its
/// tolerance outside the triangle (1e-9 of barycentric weight, below 1e-7
/// cells at the largest triangle).
const REACH_SLACK: f64 = 1e-6;

/// The previous surface along each target ray.
#[derive(Debug, Clone)]
pub struct Rendered {
    /// Range along the target ray, metres; NaN where no triangle covers it.
    pub range_m: Vec<f32>,
    /// Time the covering surface was measured at (interpolated), ns.
    pub source_time_ns: Vec<StampNs>,
    /// Unit normal of the covering triangle (zero where none).
    pub normal: Vec<[f32; 3]>,
    /// The covering triangle touches an occlusion edge of the source scan: the
    /// ray may have seen another surface then (disocclusion).
    pub edge: Vec<bool>,
}

/// Vertex of the warped mesh: position in the target frame, image coords, time.
#[derive(Clone, Copy)]
struct Vertex {
    position: Point3<f64>,
    row: f64,
    col: f64,
    time_ns: StampNs,
}

impl Vertex {
    /// No vertex (no return, or one across the seam of the sweep): a NaN
    /// row, which no moved return has. (48 bytes a vertex where an
    /// `Option` took 56: a render's vertices are read and written whole
    /// several times, 7 MB at 64 x 2048.)
    const NONE: Self = Self {
        position: Point3::new(0.0, 0.0, 0.0),
        row: f64::NAN,
        col: f64::NAN,
        time_ns: 0,
    };

    #[inline]
    fn is_some(&self) -> bool {
        !self.row.is_nan()
    }

    #[inline]
    fn some(&self) -> Option<&Self> {
        self.is_some().then_some(self)
    }
}

/// The moved source vertices of one render, column-major (the vertex of
/// source row `r`, column `c` at `c * rows + r`): each column is warped with
/// one transform cache and written in place, and a quad's two rows are
/// neighbours in memory.
struct Vertices {
    rows: usize,
    /// [`Vertex::NONE`] where none.
    at: Vec<Vertex>,
    /// The source surface's fitted normal of each vertex, in the target
    /// frame, column-major too: only on sparse sensors, whose rings are
    /// rendered with them (dense sensors' triangles have their own); empty
    /// otherwise.
    normal: Vec<Vector3<f64>>,
}

impl Vertices {
    #[inline]
    fn get(&self, row: usize, col: usize) -> Option<&Vertex> {
        self.at[col * self.rows + row].some()
    }
}

/// The previous scan turned by the rotation-only `trajectory` (`R_rot`):
/// sampled ray by ray (`rotated.rs`: a turn about the sensor changes no
/// range, so each ray finds its one triangle without a raster) where the
/// source's columns do not share a time, else rasterised as [`render`]
/// does. The raster moves each return by its own transform where its
/// column's returns do not share their time (KITTI's HDL-64E, the
/// Pandar64), and bridges more dropouts: there the sampler takes 0.7 of
/// its time (20-23 against 30-31 ms a render, one thread); on a sensor
/// firing each column at once (the synthetic drives) the raster's whole
/// quads take 0.85 of the sampler's. A sparse sensor's rings are always
/// rasterised (`rasterize_ring`).
pub fn render_rotation(
    source: &Source,
    target: &Target,
    geometry: &ImageGeometry,
    trajectory: &Trajectory,
    scan_offset_ns: StampNs,
) -> Rendered {
    let shared = source.columns.shares_time.iter().filter(|&&s| s).count();
    let sample = !geometry.sparse_rows() && 2 * shared < geometry.cols;
    if sample
        && let Some(rendered) =
            rotated::render_rotated(source, target, geometry, trajectory, scan_offset_ns)
    {
        return rendered;
    }
    render(source, target, geometry, trajectory, scan_offset_ns)
}

pub fn render(
    source: &Source,
    target: &Target,
    geometry: &ImageGeometry,
    trajectory: &Trajectory,
    scan_offset_ns: StampNs,
) -> Rendered {
    let cells = geometry.cells();
    let arrivals = arrival_poses(target.column_time_ns, trajectory);
    // A sparse sensor's rings are rendered segment by segment, with their
    // vertices' normals (`rasterize_ring`); triangles have their own.
    let sparse = geometry.sparse_rows();
    let rows = geometry.rows;
    let mut vertices = Vertices {
        rows,
        at: spare_vertices(cells),
        normal: if sparse {
            vec![Vector3::zeros(); cells]
        } else {
            Vec::new()
        },
    };
    let shares = &source.columns.shares_time;
    // Column by column: the returns of one column share a firing time, so the
    // relative transforms are computed once per column, not once per return.
    // (A column whose returns do not share their time, KITTI's, takes its
    // transforms along lines: `TransformCache`.)
    let columns = ColumnWarp {
        source,
        target,
        geometry,
        trajectory,
        arrivals: &arrivals,
        scan_offset_ns,
    };
    let warp_column = |returns: &mut ColumnRows,
                       col: usize,
                       column: &mut [Vertex],
                       normals: &mut [Vector3<f64>]| {
        if shares[col] {
            columns.rows::<false>(col, (column, normals), returns);
        } else {
            columns.rows::<true>(col, (column, normals), returns);
        }
    };
    let chunk = rows.max(1);
    if sparse {
        vertices
            .at
            .par_chunks_mut(chunk)
            .zip(vertices.normal.par_chunks_mut(chunk))
            .enumerate()
            .for_each_init(ColumnRows::default, |returns, (col, (column, normals))| {
                warp_column(returns, col, column, normals)
            });
    } else {
        vertices
            .at
            .par_chunks_mut(chunk)
            .enumerate()
            .for_each_init(ColumnRows::default, |returns, (col, column)| {
                warp_column(returns, col, column, &mut [])
            });
    }
    let proxy = fill_dropouts(source, geometry, &mut vertices);
    let candidates = rasterize(source, target, geometry, &vertices, &proxy);
    let mut range_m = vec![f32::NAN; cells];
    let mut source_time_ns = vec![0; cells];
    let mut normal = vec![[0.0; 3]; cells];
    let mut edge = vec![false; cells];
    for row in candidates {
        for candidate in row {
            let cell = candidate.cell as usize;
            if range_m[cell].is_nan() || candidate.range_m < range_m[cell] {
                range_m[cell] = candidate.range_m;
                source_time_ns[cell] = candidate.time_ns;
                normal[cell] = candidate.normal;
                edge[cell] = candidate.edge;
            }
        }
    }
    SPARE_VERTICES.with(|spare| spare.replace(vertices.at));
    Rendered {
        range_m,
        source_time_ns,
        normal,
        edge,
    }
}

thread_local! {
    /// The last render's vertex buffer on this thread, reused.
    static SPARE_VERTICES: std::cell::RefCell<Vec<Vertex>> = const { std::cell::RefCell::new(Vec::new()) };
}

/// A buffer of `cells` vertices, each to be overwritten by the warp (every
/// column writes all its rows): the last render's where it has that many,
/// so that 7 MB are neither allocated nor cleared per render.
fn spare_vertices(cells: usize) -> Vec<Vertex> {
    let mut at = SPARE_VERTICES.with(|spare| spare.take());
    at.resize(cells, Vertex::NONE);
    at
}

/// Every triangle (or, on a sparse sensor, ring segment) of the moved
/// mesh rasterised: the candidates of each task, in the z-buffer's order.
fn rasterize(
    source: &Source,
    target: &Target,
    geometry: &ImageGeometry,
    vertices: &Vertices,
    proxies: &mesh::Proxies,
) -> Vec<Vec<Candidate>> {
    if geometry.sparse_rows() {
        (0..geometry.rows)
            .into_par_iter()
            .map(|row| rasterize_ring(source, target, geometry, vertices, &proxies.cell, row))
            .collect()
    } else {
        let cols = geometry.cols;
        (0..cols.div_ceil(CHUNK_COLS))
            .into_par_iter()
            .map(|chunk| {
                let columns = chunk * CHUNK_COLS..((chunk + 1) * CHUNK_COLS).min(cols);
                rasterize_columns(source, target, geometry, vertices, proxies, columns)
            })
            .collect()
    }
}

/// Source columns rasterised by one task: the z-buffer takes their
/// candidates in turn, so this sets which of two equal ranges wins (the
/// first column's).
const CHUNK_COLS: usize = 64;

/// A triangle covering a target ray.
struct Candidate {
    cell: u32,
    range_m: f32,
    time_ns: StampNs,
    normal: [f32; 3],
    edge: bool,
}

/// Hand-made surfaces for the warp's tests.
#[cfg(test)]
pub(super) mod test_surfaces {
    use super::Surfaces;
    use crate::engine::beams::BeamTable;
    use crate::engine::grid::ImageGeometry;
    use crate::test_rng::SplitMix64;

    /// A 0.11 rad tall image of `rows` beams by `cols` columns.
    pub(in crate::engine::warp) fn flat_geometry(rows: usize, cols: usize) -> ImageGeometry {
        ImageGeometry {
            rows,
            cols,
            beams: BeamTable::uniform(rows, -0.05, 0.11),
            ring_to_row: None,
            parallax_rad_m: None,
        }
    }

    /// The unit direction at `azimuth` and `elevation`, radians.
    pub(in crate::engine::warp) fn unit(azimuth: f64, elevation: f64) -> [f32; 3] {
        [
            elevation.cos() * azimuth.cos(),
            elevation.cos() * azimuth.sin(),
            elevation.sin(),
        ]
        .map(|x| x as f32)
    }

    /// The cells' kinds in [`wall`]: each cell's index says which.
    pub(in crate::engine::warp) struct Pattern {
        /// Empty (no return).
        pub empty: fn(usize) -> bool,
        /// A step: 4-5 m, in front of the wall (an occlusion).
        pub step: fn(usize) -> bool,
        /// No normal known.
        pub no_normal: fn(usize) -> bool,
        /// An occlusion edge.
        pub edge: fn(usize) -> bool,
    }

    /// A wall 10 m off with ranges noisy by 5 cm, the cells `pattern` says
    /// empty, steps or edges, normals tilted at random but where it says
    /// none; the rows' noise 1 cm and 4 mm more per row; no joins yet.
    pub(in crate::engine::warp) fn wall(
        rows: usize,
        cols: usize,
        seed: u64,
        pattern: &Pattern,
    ) -> Surfaces {
        let mut rng = SplitMix64(seed);
        let cells = rows * cols;
        let range_m: Vec<f32> = (0..cells)
            .map(|k| {
                if (pattern.empty)(k) {
                    f32::NAN
                } else if (pattern.step)(k) {
                    rng.uniform(4.0, 5.0) as f32
                } else {
                    rng.uniform(10.0, 10.05) as f32
                }
            })
            .collect();
        let direction = (0..cells)
            .map(|k| {
                let (row, col) = ((k / cols) as f64, (k % cols) as f64);
                unit(0.01 * col, 0.02 * row - 0.05)
            })
            .collect();
        let normal = (0..cells)
            .map(|k| {
                if (pattern.no_normal)(k) {
                    [0.0; 3]
                } else {
                    let tilt = rng.uniform(-0.15, 0.15);
                    [-(1.0 - tilt * tilt).sqrt() as f32, tilt as f32, 0.0]
                }
            })
            .collect();
        let noise = (0..rows).map(|r| 0.01 + 0.004 * r as f32).collect();
        let mut surfaces = Surfaces::hand_made(range_m, direction, normal, noise, cols);
        surfaces.edge = (0..cells).map(pattern.edge).collect();
        surfaces.support = vec![9; cells];
        surfaces
    }
}

#[cfg(test)]
mod bands_tests {
    use super::*;
    use crate::test_rng::SplitMix64;

    /// `Bands::of` in bands of rows gives each row's and column's reach of
    /// the one pass over the cells (kept here), bit for bit: coordinates
    /// jittered about their cells, a few strays a row or columns off, some
    /// across the seam, empty cells, a last band of fewer rows.
    #[test]
    fn bands_of_rows_reach_as_one_pass() {
        let (rows, cols) = (20, 64);
        let cells = rows * cols;
        let mut rng = SplitMix64(0x51_7cc1_b727_220a);
        let mut unit = || rng.uniform(0.0, 1.0);
        let mut range_m = vec![f32::NAN; cells];
        let mut coords = vec![(0.0f32, 0.0f32); cells];
        for cell in 0..cells {
            let (row, col) = (cell / cols, cell % cols);
            if unit() < 0.1 {
                continue;
            }
            range_m[cell] = 10.0;
            let stray = if unit() < 0.03 {
                3.0 * unit() - 1.5
            } else {
                0.0
            };
            let row_f = row as f64 + 0.4 * unit() - 0.2 + stray;
            let col_f = (col as f64 + 0.6 * unit() - 0.3 + 2.0 * stray).rem_euclid(cols as f64);
            coords[cell] = (row_f as f32, col_f as f32);
        }
        let surfaces = Surfaces::hand_made(
            range_m,
            vec![[1.0, 0.0, 0.0]; cells],
            vec![[0.0; 3]; cells],
            vec![0.01; rows],
            cols,
        );
        let bands = Bands::of(&surfaces, &coords);
        let (mut row_reach, mut col_reach) = (vec![Reach::NONE; rows], vec![Reach::NONE; cols]);
        for (cell, &(row_f, col_f)) in coords.iter().enumerate() {
            if !surfaces.range_m[cell].is_finite() {
                continue;
            }
            let (row, col) = (cell / cols, cell % cols);
            row_reach[row] = row_reach[row].with(f64::from(row_f) - row as f64);
            col_reach[col] = col_reach[col].with(col_offset(col_f, col, cols));
        }
        let bits = |r: &[Reach]| -> Vec<(u64, u64)> {
            r.iter()
                .map(|r| (r.before.to_bits(), r.after.to_bits()))
                .collect()
        };
        assert_eq!(bits(&bands.rows), bits(&row_reach));
        assert_eq!(bits(&bands.cols), bits(&col_reach));
        let spans = |s: &[Span]| -> Vec<(u64, u64)> {
            s.iter()
                .map(|s| (s.lowest.to_bits(), s.highest.to_bits()))
                .collect()
        };
        assert_eq!(spans(&bands.col_spans), spans(&Span::all(&col_reach)));
        assert_eq!(spans(&bands.row_spans), spans(&Span::all(&row_reach)));
        // The strays reach beyond a row (the test's point).
        assert!(bands.reach().0 > 1.0 && bands.reach().1 > 2.0);
    }
}
