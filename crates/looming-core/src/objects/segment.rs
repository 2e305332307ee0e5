//! Range-image segmentation of the non-ground returns (Bogoslavskyi &
//! Stachniss, "Fast range image-based segmentation of sparse 3D laser
//! scans", 2016): two neighbouring returns at ranges `d1 >= d2`, their rays
//! `alpha` apart, are one object when the angle
//! `beta = atan2(d2 sin alpha, d1 - d2 cos alpha)` between the line joining
//! them and the farther ray is large: a steep step in range (a car in front
//! of a wall) makes `beta` small. One breadth-first pass over the cells.

use super::ground::{CellPoints, GroundFit};
use super::{NO_OBJECT, ObjectConfig};
use crate::engine::PairLooming;

/// Per cell, the index of its object (in order of discovery: of each
/// object's first cell in the image), or [`NO_OBJECT`].
pub fn segment(
    points: &CellPoints,
    looming: &PairLooming,
    ground: Option<&GroundFit>,
    config: &ObjectConfig,
) -> Vec<u32> {
    let (rows, cols) = (looming.geometry.rows, looming.geometry.cols);
    let points = object_candidates(points, looming, ground, config);
    label_groups(&points, (rows, cols), config)
}

/// The groups of `points` (a `rows` x `cols` image, `None` where no
/// candidate) that neighbours [`joined`] make, labelled in order of their
/// first cell, those of fewer than `config.min_cells` left as
/// [`NO_OBJECT`]. The groups are the connected parts of the join relation,
/// which is symmetric (bit for bit): a union-find over each pair of
/// neighbours once, in image order (a breadth-first search from each seed
/// found the same groups and labels, reading six neighbours per cell at
/// random across rows, a third of the objects' time on KITTI's braking
/// drive).
fn label_groups(
    points: &[Option<[f32; 3]>],
    (rows, cols): (usize, usize),
    config: &ObjectConfig,
) -> Vec<u32> {
    let cells = rows * cols;
    if points.len() != cells {
        // Not an image of these rows and columns: no object.
        return vec![NO_OBJECT; points.len()];
    }
    let min_sin_beta = config.join_angle_deg.to_radians().sin();
    let mut groups = Groups::new(cells);
    for row in 0..rows {
        let row_start = row * cols;
        for col in 0..cols {
            let cell = row_start + col;
            let Some(here) = points[cell] else { continue };
            let here = here.map(f64::from);
            let mut join = |other: usize| {
                if let Some(there) = points[other]
                    && joined(&here, &there.map(f64::from), min_sin_beta, config)
                {
                    groups.union(cell, other);
                }
            };
            // The row below's neighbour; the row above's joins it from there.
            if row + 1 < rows {
                join(cell + cols);
            }
            // The column before (wrapped): the one after joins it from there.
            let before = |k: usize| {
                let k = if k < cols { k } else { k % cols };
                row_start + if col >= k { col - k } else { col + cols - k }
            };
            let (one, two) = (before(1), before(2));
            if one != cell {
                join(one);
            }
            // Two columns away only across a dropout, never across another
            // return (a pole before a wall).
            if two != cell && points[one].is_none() {
                join(two);
            }
        }
    }
    groups.labels(points, config.min_cells)
}

/// Union-find over the cells, each group's root its first cell.
struct Groups {
    parent: Vec<u32>,
}

impl Groups {
    fn new(cells: usize) -> Self {
        Self {
            parent: (0..cells as u32).collect(),
        }
    }

    /// The root of `cell`'s group, halving the path on the way.
    fn root(&mut self, mut cell: usize) -> usize {
        while self.parent[cell] as usize != cell {
            let grandparent = self.parent[self.parent[cell] as usize];
            self.parent[cell] = grandparent;
            cell = grandparent as usize;
        }
        cell
    }

    /// One group of `a`'s and `b`'s, rooted at the first of their roots.
    fn union(&mut self, a: usize, b: usize) {
        let (a, b) = (self.root(a), self.root(b));
        if a != b {
            let (first, second) = if a < b { (a, b) } else { (b, a) };
            self.parent[second] = first as u32;
        }
    }

    /// Each cell's label: its group's index among the groups of at least
    /// `min_cells` cells, in order of their first cell; [`NO_OBJECT`] for
    /// the rest and for cells without a point.
    fn labels(mut self, points: &[Option<[f32; 3]>], min_cells: usize) -> Vec<u32> {
        let cells = self.parent.len();
        let mut size = vec![0u32; cells];
        for cell in (0..cells).filter(|&c| points[c].is_some()) {
            let root = self.root(cell);
            size[root] += 1;
        }
        // A group's label, at its root, given when its first cell is met.
        let mut label = vec![NO_OBJECT; cells];
        let mut next = 0u32;
        for cell in (0..cells).filter(|&c| points[c].is_some()) {
            let root = self.root(cell);
            if root == cell && size[root] as usize >= min_cells {
                label[cell] = next;
                next += 1;
            } else if root != cell {
                label[cell] = label[root];
            }
        }
        label
    }
}

/// The returns that may belong to an object: above the ground, in range.
/// Kept as the scan's `f32` (exactly what `cell_point` widened): half the
/// memory the search reads six times per cell, at random across rows.
fn object_candidates(
    points: &CellPoints,
    looming: &PairLooming,
    ground: Option<&GroundFit>,
    config: &ObjectConfig,
) -> Vec<Option<[f32; 3]>> {
    (0..looming.mask.len())
        .map(|cell| {
            let p = points.get(cell)?;
            let range = (p[0] * p[0] + p[1] * p[1] + p[2] * p[2]).sqrt();
            let height = ground
                .as_ref()
                .map_or(f64::INFINITY, |g| g.height_above(&p));
            (range <= config.max_range_m && height >= config.min_height_m)
                .then_some(p.map(|v| v as f32))
        })
        .collect()
}

/// Whether two neighbouring returns are on one object: the angle criterion,
/// and a gap of at most `max_gap_m` or, between rays far apart, what a
/// surface facing the sensor leaves between them ([`RAY_GAP_FACTOR`] times
/// the nearer range times the sine of the rays' angle). A sparse sensor's
/// rings lie 11 degrees apart (OS0-8): a wall 8 m away shows 1.6 m between
/// them, and a fixed gap cut it into one stripe per ring, each an object
/// of its own that a newly uncovered stretch of wall left without any
/// measured cell. A dense sensor's neighbours lie a fraction of a degree
/// apart, where the fixed gap rules to 80 m.
///
/// Without a square root or a division, from the squared lengths, the dot
/// product and the squared cross product of the two returns (`d1 d2
/// sin(alpha) = |a x b|`, `d1 (d1 - d2 cos(alpha)) = d1^2 - a . b`): this
/// runs for every pair of neighbours, six per cell of every object.
fn joined(a: &[f64; 3], b: &[f64; 3], min_sin_beta: f64, config: &ObjectConfig) -> bool {
    let dot = |u: &[f64; 3], v: &[f64; 3]| u[0] * v[0] + u[1] * v[1] + u[2] * v[2];
    let gap = [a[0] - b[0], a[1] - b[1], a[2] - b[2]];
    let gap_squared = dot(&gap, &gap);
    let (ra_squared, rb_squared, ab) = (dot(a, a), dot(b, b), dot(a, b));
    let d1_squared = ra_squared.max(rb_squared);
    // |a x b|^2, from Lagrange's identity.
    let cross_squared = (ra_squared * rb_squared - ab * ab).max(0.0);
    // gap > max(max_gap, RAY_GAP_FACTOR d2 sin(alpha)), d2 sin(alpha) = |a x b| / d1.
    if gap_squared > config.max_gap_m * config.max_gap_m
        && gap_squared * d1_squared > RAY_GAP_FACTOR * RAY_GAP_FACTOR * cross_squared
    {
        return false;
    }
    // sin(beta) of the triangle, the line a-b against the farther ray:
    // `across / hypot(along, across)`, both sides times d1.
    let along = d1_squared - ab;
    let hypot_squared = along * along + cross_squared;
    hypot_squared <= 1e-18 * d1_squared
        || cross_squared >= min_sin_beta * min_sin_beta * hypot_squared
}

/// A surface facing the sensor leaves `range x sin(alpha)` between rays
/// `alpha` apart; one at 60 degrees from facing twice that.
const RAY_GAP_FACTOR: f64 = 2.0;

#[cfg(test)]
mod tests {
    use super::*;

    /// The breadth-first search [`label_groups`] replaced: from each seed
    /// not yet searched, over the neighbours [`neighbours`] gives; the
    /// reference its labels are held to.
    fn label_by_search(
        points: &[Option<[f32; 3]>],
        (rows, cols): (usize, usize),
        config: &ObjectConfig,
    ) -> Vec<u32> {
        let mut label = vec![NO_OBJECT; rows * cols];
        let mut visited = vec![false; rows * cols];
        let min_sin_beta = config.join_angle_deg.to_radians().sin();
        let mut pending = Vec::new();
        let mut members = Vec::new();
        let mut next = 0u32;
        for seed in 0..rows * cols {
            if points[seed].is_none() || visited[seed] {
                continue;
            }
            visited[seed] = true;
            members.clear();
            pending.push(Place::of(seed, cols));
            while let Some(place) = pending.pop() {
                let cell = place.cell;
                members.push(cell);
                let here = points[cell]
                    .expect("queued cells have a point")
                    .map(f64::from);
                for (neighbour, between) in neighbours(place, rows, cols) {
                    if visited[neighbour.cell] {
                        continue;
                    }
                    let Some(there) = points[neighbour.cell].map(|p| p.map(f64::from)) else {
                        continue;
                    };
                    let across_a_return = between.is_some_and(|b| points[b].is_some());
                    if !across_a_return && joined(&here, &there, min_sin_beta, config) {
                        visited[neighbour.cell] = true;
                        pending.push(neighbour);
                    }
                }
            }
            if members.len() >= config.min_cells {
                for &cell in &members {
                    label[cell] = next;
                }
                next += 1;
            }
        }
        label
    }

    /// A cell with its row and column.
    #[derive(Clone, Copy)]
    struct Place {
        cell: usize,
        row: usize,
        col: usize,
    }

    impl Place {
        fn of(cell: usize, cols: usize) -> Self {
            Self {
                cell,
                row: cell / cols,
                col: cell % cols,
            }
        }
    }

    /// The four neighbours of a cell, and the cells two columns away (a
    /// one-cell dropout does not split an object) with the cell between; columns
    /// wrap.
    fn neighbours(
        place: Place,
        rows: usize,
        cols: usize,
    ) -> impl Iterator<Item = (Place, Option<usize>)> {
        let Place { cell, row, col } = place;
        // Columns `k` (1 or 2) to either side, wrapped by a comparison, not a
        // division (this runs for every cell of every object; `k % cols` for
        // an image narrower than `k` columns).
        let row_start = row * cols;
        let at = |col: usize| Place {
            cell: row_start + col,
            row,
            col,
        };
        let left = |k: usize| {
            let k = if k < cols { k } else { k % cols };
            at(if col >= k { col - k } else { col + cols - k })
        };
        let right = |k: usize| {
            let k = if k < cols { k } else { k % cols };
            let c = col + k;
            at(if c >= cols { c - cols } else { c })
        };
        let up = (row + 1 < rows).then(|| {
            let up = Place {
                cell: cell + cols,
                row: row + 1,
                col,
            };
            (up, None)
        });
        let down = (row > 0).then(|| {
            let down = Place {
                cell: cell - cols,
                row: row - 1,
                col,
            };
            (down, None)
        });
        [
            Some((left(1), None)),
            Some((right(1), None)),
            Some((left(2), Some(left(1).cell))),
            Some((right(2), Some(right(1).cell))),
            up,
            down,
        ]
        .into_iter()
        .flatten()
        .filter(move |(n, _)| n.cell != cell)
    }

    /// Images of walls, poles and cars at random ranges with dropouts,
    /// on grids as narrow as one column: the union-find's labels are the
    /// search's, cell for cell.
    #[test]
    fn groups_are_labelled_as_the_search_labels_them() {
        let config = ObjectConfig::default();
        let mut rng = crate::test_rng::SplitMix64(7);
        let mut uniform = move |lo: f64, hi: f64| rng.uniform(lo, hi);
        let mut groups_seen = 0;
        for (rows, cols) in [
            (1, 1),
            (2, 2),
            (3, 3),
            (4, 5),
            (16, 64),
            (32, 256),
            (64, 512),
        ] {
            for _ in 0..4 {
                // Range steps along each row (objects before a wall), a
                // few dropouts, and rays 2 pi / cols apart.
                let mut range_m = 10.0;
                let points: Vec<Option<[f32; 3]>> = (0..rows * cols)
                    .map(|cell| {
                        let (row, col) = (cell / cols, cell % cols);
                        if uniform(0.0, 1.0) < 0.03 {
                            range_m = uniform(1.0, 40.0);
                        }
                        if uniform(0.0, 1.0) < 0.1 {
                            return None;
                        }
                        let azimuth = col as f64 * std::f64::consts::TAU / cols as f64;
                        let elevation = (row as f64 - rows as f64 / 2.0) * 0.007;
                        let r = range_m * (1.0 + uniform(-0.002, 0.002));
                        Some([
                            (r * elevation.cos() * azimuth.cos()) as f32,
                            (r * elevation.cos() * azimuth.sin()) as f32,
                            (r * elevation.sin()) as f32,
                        ])
                    })
                    .collect();
                let found = label_groups(&points, (rows, cols), &config);
                assert_eq!(
                    found,
                    label_by_search(&points, (rows, cols), &config),
                    "{rows} x {cols}"
                );
                groups_seen += found
                    .iter()
                    .filter(|&&l| l != NO_OBJECT)
                    .max()
                    .map_or(0, |&l| l + 1);
            }
        }
        assert!(groups_seen > 100, "{groups_seen} groups");
    }

    /// A point at `range_m` along azimuth 0 and elevation `elevation_deg`.
    fn ray_point(range_m: f64, elevation_deg: f64) -> [f64; 3] {
        let e = elevation_deg.to_radians();
        [range_m * e.cos(), 0.0, range_m * e.sin()]
    }

    /// The criterion as first written, with square roots and divisions.
    fn joined_by_angles(
        a: &[f64; 3],
        b: &[f64; 3],
        min_sin_beta: f64,
        config: &ObjectConfig,
    ) -> bool {
        let gap = ((a[0] - b[0]).powi(2) + (a[1] - b[1]).powi(2) + (a[2] - b[2]).powi(2)).sqrt();
        let ra = (a[0] * a[0] + a[1] * a[1] + a[2] * a[2]).sqrt();
        let rb = (b[0] * b[0] + b[1] * b[1] + b[2] * b[2]).sqrt();
        let (d1, d2) = if ra >= rb { (ra, rb) } else { (rb, ra) };
        let cos_alpha = ((a[0] * b[0] + a[1] * b[1] + a[2] * b[2]) / (ra * rb)).clamp(-1.0, 1.0);
        let sin_alpha = (1.0 - cos_alpha * cos_alpha).sqrt();
        if gap > config.max_gap_m.max(RAY_GAP_FACTOR * d2 * sin_alpha) {
            return false;
        }
        let along = d1 - d2 * cos_alpha;
        let across = d2 * sin_alpha;
        let hypot = (along * along + across * across).sqrt();
        hypot <= 1e-9 || across / hypot >= min_sin_beta
    }

    /// Neighbouring returns of dense and sparse sensors, near and far, on
    /// surfaces at every slope: the same verdict as the angles give.
    #[test]
    fn the_criterion_without_roots_gives_the_angles_verdict() {
        let config = ObjectConfig::default();
        let min_sin_beta = config.join_angle_deg.to_radians().sin();
        let mut rng = crate::test_rng::SplitMix64(99);
        let mut uniform = || rng.uniform(0.0, 1.0);
        let (mut joined_count, mut pairs) = (0, 200_000);
        for _ in 0..pairs {
            let (azimuth, elevation) = (uniform() * 6.3, uniform() * 0.6 - 0.3);
            let apart = [0.003, 0.03, 0.2][(uniform() * 3.0) as usize];
            let range = 0.5 + uniform() * 90.0;
            let step =
                range * (uniform() * 2.0 - 1.0) * [0.001, 0.05, 0.5][(uniform() * 3.0) as usize];
            let point = |r: f64, az: f64, el: f64| {
                [
                    r * el.cos() * az.cos(),
                    r * el.cos() * az.sin(),
                    r * el.sin(),
                ]
            };
            let a = point(range, azimuth, elevation);
            let b = point(
                range + step,
                azimuth + apart * uniform(),
                elevation + apart * uniform(),
            );
            let expected = joined_by_angles(&a, &b, min_sin_beta, &config);
            assert_eq!(
                joined(&a, &b, min_sin_beta, &config),
                expected,
                "{a:?} {b:?}"
            );
            joined_count += usize::from(expected);
        }
        // Both verdicts are exercised.
        pairs -= joined_count;
        assert!(
            joined_count > 20_000 && pairs > 20_000,
            "{joined_count} joined, {pairs} not"
        );
    }

    #[test]
    fn a_sparse_sensors_rings_on_one_wall_are_one_object() {
        let config = ObjectConfig::default();
        let min_sin_beta = config.join_angle_deg.to_radians().sin();
        // An OS0-8's neighbouring rings, 11.4 degrees apart, on a wall 8 m
        // ahead: 1.6 m apart, beyond the fixed gap, and one surface.
        let (lower, upper) = (
            ray_point(8.0, 0.0),
            ray_point(8.0 / 11.4f64.to_radians().cos(), 11.4),
        );
        assert!(joined(&lower, &upper, min_sin_beta, &config));
        // A box 3.3 m away before that wall, on the next ring: a step.
        assert!(!joined(&ray_point(3.3, 0.0), &upper, min_sin_beta, &config));
        // A dense sensor's rows, 0.4 degrees apart, 2 m apart in range far
        // away: the fixed gap still parts them.
        let (near, far) = (ray_point(60.0, 0.0), ray_point(62.0, 0.4));
        assert!(!joined(&near, &far, min_sin_beta, &config));
    }
}
