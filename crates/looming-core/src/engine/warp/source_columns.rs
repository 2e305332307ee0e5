//! The source scan's returns laid out column by column, once per pair.
//!
//! Each render warps the source a column at a time (`moved_column.rs`), and
//! a column's returns lie a whole image row apart in the row-major arrays
//! of [`Surfaces`] (8-24 KiB strides). Gathered there, every render of a
//! pair (two, or more while the motion is estimated) paid those strided
//! loads again; transposed here once, in blocks of columns that stay in
//! the cache, each render's gather reads one contiguous run per column.

use nalgebra::Point3;
use rayon::prelude::*;

use crate::engine::spare::Pool;
use crate::engine::surface::Surfaces;
use crate::model::StampNs;

/// The source's per-cell fields the warp reads, column-major: the return
/// of row `r`, column `c` at `c * rows + r`.
pub(crate) struct SourceColumns {
    /// Range of the return, metres (NaN: none), as in [`Surfaces::range_m`].
    pub range_m: Vec<f32>,
    /// The return's point, metres: its direction times its range, the
    /// products the warp took per render.
    pub point: [Vec<f64>; 3],
    pub time_ns: Vec<StampNs>,
    pub azimuth_rad: Vec<f64>,
    pub elevation_rad: Vec<f64>,
    /// Per column, whether its returns share one time.
    pub shares_time: Vec<bool>,
}

/// Source columns transposed by one task: their rows' runs of cells are
/// read once and written into as many column runs as fit the cache.
const BLOCK_COLS: usize = 64;

impl SourceColumns {
    /// The fields of `surfaces` (`time_ns` per cell) column-major.
    pub fn of(surfaces: &Surfaces, time_ns: &[StampNs]) -> Self {
        let cols = surfaces.cols.max(1);
        let rows = surfaces.range_m.len() / cols;
        let spare = SPARE.take();
        let mut table = Self {
            range_m: spare.range_m,
            point: spare.point,
            time_ns: spare.time_ns,
            azimuth_rad: spare.azimuth_rad,
            elevation_rad: spare.elevation_rad,
            shares_time: spare.shares_time,
        };
        table.resize(rows * cols, cols);
        let block = BLOCK_COLS * rows.max(1);
        let [px, py, pz] = &mut table.point;
        let blocks = (
            table.range_m.par_chunks_mut(block),
            px.par_chunks_mut(block),
            py.par_chunks_mut(block),
            pz.par_chunks_mut(block),
            table.time_ns.par_chunks_mut(block),
            table.azimuth_rad.par_chunks_mut(block),
            table.elevation_rad.par_chunks_mut(block),
        );
        blocks
            .into_par_iter()
            .zip(table.shares_time.par_chunks_mut(BLOCK_COLS))
            .enumerate()
            .for_each(|(index, (mut out, shares))| {
                let first_col = index * BLOCK_COLS;
                transpose_block(surfaces, time_ns, (rows, cols), first_col, &mut out);
                for (offset, shares) in shares.iter_mut().enumerate() {
                    let at = offset * rows..(offset + 1) * rows;
                    *shares = shares_one_time(&out.0[at.clone()], &out.4[at]);
                }
            });
        table
    }

    /// Every array `cells` long, `shares_time` `cols` long (their values
    /// overwritten before read).
    fn resize(&mut self, cells: usize, cols: usize) {
        self.range_m.resize(cells, f32::NAN);
        for axis in &mut self.point {
            axis.resize(cells, f64::NAN);
        }
        self.time_ns.resize(cells, 0);
        self.azimuth_rad.resize(cells, f64::NAN);
        self.elevation_rad.resize(cells, f64::NAN);
        self.shares_time.resize(cols, true);
    }
}

/// The output arrays of one block of columns, column-major.
type BlockOut<'a> = (
    &'a mut [f32],
    &'a mut [f64],
    &'a mut [f64],
    &'a mut [f64],
    &'a mut [StampNs],
    &'a mut [f64],
    &'a mut [f64],
);

/// The columns from `first_col` (as many as `out` holds) transposed, row
/// by row of the source.
fn transpose_block(
    s: &Surfaces,
    time_ns: &[StampNs],
    (rows, cols): (usize, usize),
    first_col: usize,
    out: &mut BlockOut,
) {
    let (range_m, px, py, pz, times, azimuths, elevations) = out;
    let block_cols = range_m.len() / rows.max(1);
    for row in 0..rows {
        let start = row * cols + first_col;
        for offset in 0..block_cols {
            let (cell, at) = (start + offset, offset * rows + row);
            let range = s.range_m[cell];
            let d = s.direction[cell];
            let point =
                Point3::new(f64::from(d[0]), f64::from(d[1]), f64::from(d[2])) * f64::from(range);
            range_m[at] = range;
            (px[at], py[at], pz[at]) = (point.x, point.y, point.z);
            times[at] = time_ns[cell];
            azimuths[at] = s.azimuth_rad[cell];
            elevations[at] = s.elevation_rad[cell];
        }
    }
}

/// Whether a column's returns (ranges `range_m`, times `time_ns`) share
/// one time.
fn shares_one_time(range_m: &[f32], time_ns: &[StampNs]) -> bool {
    let mut first = None;
    range_m
        .iter()
        .zip(time_ns)
        .filter(|(range, _)| range.is_finite())
        .all(|(_, &time)| *first.get_or_insert(time) == time)
}

/// The buffers of a dropped table, for the next pair's.
#[derive(Default)]
struct Spare {
    range_m: Vec<f32>,
    point: [Vec<f64>; 3],
    time_ns: Vec<StampNs>,
    azimuth_rad: Vec<f64>,
    elevation_rad: Vec<f64>,
    shares_time: Vec<bool>,
}

/// A pair's table is dropped when the pair's renders are done: its buffers
/// go to the next pair's, whose fresh pages cost more to fault in than to
/// fill (7 MB at 64 x 2048).
impl Drop for SourceColumns {
    fn drop(&mut self) {
        use std::mem::take;
        let spare = Spare {
            range_m: take(&mut self.range_m),
            point: take(&mut self.point),
            time_ns: take(&mut self.time_ns),
            azimuth_rad: take(&mut self.azimuth_rad),
            elevation_rad: take(&mut self.elevation_rad),
            shares_time: take(&mut self.shares_time),
        };
        SPARE.give(spare);
    }
}

/// The buffers of dropped tables.
static SPARE: Pool<Spare> = Pool::new();

#[cfg(test)]
mod tests {
    use super::*;

    /// A surface of `rows` x `cols` cells with every fourth cell empty
    /// and, in odd columns, returns at two times.
    fn surface(rows: usize, cols: usize) -> (Surfaces, Vec<StampNs>) {
        let cells = rows * cols;
        let value = |cell: usize, k: usize| ((cell * 7 + k * 13) % 101) as f32 * 0.37 - 9.0;
        let range_m = (0..cells)
            .map(|cell| {
                if cell % 4 == 3 {
                    f32::NAN
                } else {
                    1.0 + value(cell, 0).abs()
                }
            })
            .collect();
        let time_ns = (0..cells)
            .map(|cell| {
                let (row, col) = (cell / cols, cell % cols);
                1_000 * col as StampNs + if col % 2 == 1 && row > rows / 2 { 5 } else { 0 }
            })
            .collect();
        let direction = (0..cells)
            .map(|cell| [value(cell, 1), value(cell, 2), value(cell, 3)])
            .collect();
        let normal = vec![[0.0; 3]; cells];
        let mut surfaces = Surfaces::hand_made(range_m, direction, normal, vec![0.01; rows], cols);
        surfaces.azimuth_rad = (0..cells).map(|cell| f64::from(value(cell, 4))).collect();
        surfaces.elevation_rad = (0..cells).map(|cell| f64::from(value(cell, 5))).collect();
        (surfaces, time_ns)
    }

    #[test]
    fn the_table_holds_each_cells_fields_at_its_column_major_place() {
        // 130 columns: two whole blocks and a part.
        let (rows, cols) = (5, 130);
        let (surfaces, time_ns) = surface(rows, cols);
        for _ in 0..2 {
            // The second table is made in the first's buffers.
            let table = SourceColumns::of(&surfaces, &time_ns);
            for (cell, &time) in time_ns.iter().enumerate() {
                let (row, col) = (cell / cols, cell % cols);
                let at = col * rows + row;
                let range = surfaces.range_m[cell];
                assert_eq!(table.range_m[at].to_bits(), range.to_bits());
                let d = surfaces.direction[cell];
                for (column, d) in table.point.iter().zip(d) {
                    let point = f64::from(d) * f64::from(range);
                    assert_eq!(column[at].to_bits(), point.to_bits());
                }
                assert_eq!(table.time_ns[at], time);
                assert_eq!(table.azimuth_rad[at], surfaces.azimuth_rad[cell]);
                assert_eq!(table.elevation_rad[at], surfaces.elevation_rad[cell]);
            }
            for col in 0..cols {
                let times: Vec<StampNs> = (0..rows)
                    .map(|row| row * cols + col)
                    .filter(|&cell| surfaces.range_m[cell].is_finite())
                    .map(|cell| time_ns[cell])
                    .collect();
                let shares = times.iter().all(|&t| t == times[0]);
                assert_eq!(table.shares_time[col], shares, "column {col}");
            }
            assert!(table.shares_time.iter().any(|&s| !s));
        }
    }
}
