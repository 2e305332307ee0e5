//! Where the engine's trust goes on a log, pair by pair: trusted share of
//! points, mask bits, the ground's looming. A development tool:
//! `cargo run --release --example engine_diag -- LOG.mcap [PAIRS]`.
//!
//! More, by environment variable: `DIAG_ROWS` (masks per row), `DIAG_PNG=F`
//! (the second pair's mask, and its `L_lidar`, `L_ray_ego` and fused
//! looming as `F_lidar.png` ...), `DIAG_NORMALS` (ground normal tilt),
//! `DIAG_GROUND_ROWS`, `AHEAD` (returns in the lane ahead), `DIAG_FIT` (the
//! trusted ground's looming fitted to a rotation-rate and vertical-velocity
//! error, whole scan and per azimuth sector, and what is left by range),
//! `DIAG_BIAS` (each ring's range residual on the ground ahead and the
//! per-laser offsets the engine took out).

use looming::engine::{self, EngineCache, EngineConfig, mask};
use looming::model::Scan;

fn main() {
    let args: Vec<String> = std::env::args().collect();
    let path = args.get(1).expect("LOG.mcap");
    let max_pairs: usize = args
        .get(2)
        .map_or(usize::MAX, |a| a.parse().expect("a count"));
    // DIAG_NO_BIAS: without the per-laser range offsets, to see what they do.
    let config = EngineConfig {
        correct_range_bias: std::env::var_os("DIAG_NO_BIAS").is_none(),
        ..EngineConfig::default()
    };
    let mut cache = EngineCache::default();
    let mut totals = Totals::default();
    let mut done = 0;
    // Rings and times the clouds lack come from the engine's front end
    // (`engine::layout`), which runs in the pairer as in `process`.
    looming::pipeline::replay(
        std::path::Path::new(path),
        &looming::pipeline::ScanOptions::default(),
        &mut |_| {},
        &mut |pair| {
            if done >= max_pairs {
                return;
            }
            done += 1;
            let started = std::time::Instant::now();
            let Some(result) = engine::compute_with_cache(&pair, &config, &mut cache) else {
                println!("pair {}: no image", pair.index);
                return;
            };
            let ms = started.elapsed().as_secs_f64() * 1e3;
            totals.add(&pair.current, &result, ms);
        },
    )
    .expect("a readable log");
    totals.print();
}

#[derive(Default)]
struct Totals {
    pairs: usize,
    points: usize,
    trusted_points: usize,
    occupied: usize,
    bits: [usize; 6],
    ground_fused: Vec<f32>,
    ground_lidar_left: Vec<f32>,
    ground_lidar_right: Vec<f32>,
    ground_signed: [Vec<f32>; 3],
    ground_rows: Vec<(f64, f64, usize)>,
    static_d: Vec<f32>,
    /// The last pair's `|D|` on the cells of `static_d`.
    pair_static_d: Vec<f32>,
    ms: f64,
    rows: usize,
}

impl Totals {
    fn add(&mut self, scan: &Scan, r: &engine::PairLooming, ms: f64) {
        self.pairs += 1;
        self.ms += ms;
        self.rows = r.geometry.rows;
        if std::env::var("AHEAD").is_ok() {
            print_returns_in_lane_ahead(scan);
        }
        let trusted = trusted_point_count(scan, r);
        self.points += scan.points_m.len();
        self.trusted_points += trusted;
        let mut heights = self.count_occupied_and_ground_heights_m(scan, r);
        if std::env::var("DIAG_NORMALS").is_ok() {
            print_ground_normal_tilt_deg(scan, r);
        }
        heights.sort_by(f32::total_cmp);
        let ground_z = heights.get(heights.len() / 2).copied().unwrap_or(f32::NAN);
        let mut pair_ground = self.collect_static_ground(scan, r, ground_z);
        if std::env::var("DIAG_BIAS").is_ok() {
            ring_bias(scan, r);
        }
        if std::env::var("DIAG_FIT").is_ok() {
            ground_fit(scan, r, ground_z);
        }
        print_neighbour_normals_apart(r);
        if let Ok(png) = std::env::var("DIAG_PNG")
            && self.pairs == 2
        {
            mask_png(r, &png);
            value_png(&r.l_lidar, r, &png.replace(".png", "_lidar.png"));
            value_png(&r.l_ray_ego, r, &png.replace(".png", "_rayego.png"));
            value_png(&r.fused, r, &png.replace(".png", "_fused.png"));
        }
        if std::env::var("DIAG_ROWS").is_ok() {
            print_mask_shares_per_row(r);
        }
        if std::env::var("DIAG_FACING").is_ok() {
            print_facing_sectors(scan, r);
        }
        if let Some(e) = &r.ego_estimate {
            print_ego_estimate(e);
        }
        println!(
            "pair {:3}: {:5.1} % trusted, ground {} cells median |fused| {:.4}, static |D| median {:.4}, ground z {:.2}, {:.0} ms",
            self.pairs - 1,
            100.0 * trusted as f64 / scan.points_m.len() as f64,
            pair_ground.len(),
            median(&mut pair_ground),
            median(&mut std::mem::take(&mut self.pair_static_d)),
            ground_z,
            ms
        );
    }

    /// Counts the occupied cells and their mask bits; returns the heights
    /// (metres) of the cells that look like ground: upward normal, below the
    /// sensor.
    fn count_occupied_and_ground_heights_m(
        &mut self,
        scan: &Scan,
        r: &engine::PairLooming,
    ) -> Vec<f32> {
        let mut heights = Vec::new();
        for cell in 0..r.geometry.cells() {
            let m = r.mask[cell];
            if m & mask::EMPTY != 0 {
                continue;
            }
            self.occupied += 1;
            for bit in 0..6 {
                if m & (1 << bit) != 0 {
                    self.bits[bit] += 1;
                }
            }
            let p = scan.points_m[r.image.point[cell] as usize];
            if r.normal[cell][2] > 0.96 && p[2] < -0.3 {
                heights.push(p[2]);
            }
        }
        heights
    }

    /// Adds the trusted static ground cells near `ground_z` (metres) to the
    /// totals, and every static cell's |D|; returns this pair's ground |fused|.
    fn collect_static_ground(
        &mut self,
        scan: &Scan,
        r: &engine::PairLooming,
        ground_z: f32,
    ) -> Vec<f32> {
        let mut pair_ground = Vec::new();
        for cell in 0..r.geometry.cells() {
            if r.mask[cell] != 0 || r.moving[cell] {
                continue;
            }
            let p = scan.points_m[r.image.point[cell] as usize];
            let range = (p[0] * p[0] + p[1] * p[1]).sqrt();
            if r.normal[cell][2] > 0.96 && (p[2] - ground_z).abs() < 0.2 + 0.01 * range {
                pair_ground.push(r.fused[cell].abs());
                self.add_ground_cell(r, cell, p);
            }
            let d = r.disagreement[cell];
            if d.is_finite() {
                self.static_d.push(d.abs());
                self.pair_static_d.push(d.abs());
            }
        }
        pair_ground
    }

    /// One trusted static ground cell at point `p` (metres).
    fn add_ground_cell(&mut self, r: &engine::PairLooming, cell: usize, p: [f32; 3]) {
        self.ground_signed[0].push(r.l_lidar[cell]);
        self.ground_signed[1].push(r.l_ray_ego[cell]);
        self.ground_signed[2].push(r.fused[cell]);
        let row = cell / r.geometry.cols;
        if self.ground_rows.len() < r.geometry.rows {
            self.ground_rows.resize(r.geometry.rows, (0.0, 0.0, 0));
        }
        if r.l_ray_ego[cell].is_finite() {
            let g = &mut self.ground_rows[row];
            g.0 += f64::from(r.l_lidar[cell]);
            g.1 += f64::from(r.l_ray_ego[cell]);
            g.2 += 1;
        }
        self.ground_fused.push(r.fused[cell].abs());
        if p[1] > 0.0 {
            self.ground_lidar_left.push(r.l_lidar[cell]);
        } else {
            self.ground_lidar_right.push(r.l_lidar[cell]);
        }
    }

    fn print(&mut self) {
        if std::env::var("DIAG_GROUND_ROWS").is_ok() {
            for (row, g) in self.ground_rows.iter().enumerate() {
                if g.2 > 100 {
                    println!(
                        "ground row {row:2}: mean L_lidar {:+.4} L_ray_ego {:+.4} over {}",
                        g.0 / g.2 as f64,
                        g.1 / g.2 as f64,
                        g.2
                    );
                }
            }
        }
        for (name, values) in ["l_lidar", "l_ray_ego", "fused"]
            .iter()
            .zip(self.ground_signed.iter_mut())
        {
            values.retain(|v| v.is_finite());
            values.sort_by(f32::total_cmp);
            let q = |f: f64| quantile(values, f);
            println!(
                "ground {name:10} p10 {:+.4} p25 {:+.4} p50 {:+.4} p75 {:+.4} p90 {:+.4}",
                q(0.1),
                q(0.25),
                q(0.5),
                q(0.75),
                q(0.9)
            );
        }
        let names = [
            "empty",
            "no_previous",
            "edge",
            "grazing",
            "no_ego",
            "occlusion",
        ];
        println!(
            "{} pairs, {} rows: {:.1} % of points trusted; occupied cells {}",
            self.pairs,
            self.rows,
            100.0 * self.trusted_points as f64 / self.points as f64,
            self.occupied
        );
        for (bit, name) in names.iter().enumerate().skip(1) {
            println!(
                "  {name:12} {:5.1} % of occupied cells",
                100.0 * self.bits[bit] as f64 / self.occupied.max(1) as f64
            );
        }
        println!(
            "ground: median |fused| {:.4} 1/s over {} cells; L_lidar median left {:+.4} right {:+.4}; static |D| median {:.4}; {:.0} ms/pair",
            median(&mut self.ground_fused),
            self.ground_fused.len(),
            median(&mut self.ground_lidar_left),
            median(&mut self.ground_lidar_right),
            median(&mut self.static_d),
            self.ms / self.pairs.max(1) as f64
        );
    }
}

/// Returns in the lane ahead, above the road: a vehicle's rear face.
fn print_returns_in_lane_ahead(scan: &Scan) {
    let mut xs: Vec<f32> = scan
        .points_m
        .iter()
        .filter(|p| p[0] > 2.5 && p[0] < 15.0 && p[1].abs() < 1.2 && p[2] > -1.2 && p[2] < 0.5)
        .map(|p| p[0])
        .collect();
    xs.sort_by(f32::total_cmp);
    let near = xs.get(xs.len() / 10).copied().unwrap_or(f32::NAN);
    println!(
        "  ahead: {} returns in the lane 2.5-15 m, near face at {:.2} m",
        xs.len(),
        near
    );
}

/// How many of the scan's points land in a cell the mask trusts.
fn trusted_point_count(scan: &Scan, r: &engine::PairLooming) -> usize {
    let mut trusted = 0;
    for i in 0..scan.points_m.len() {
        if let Some(cell) = r.image.surface_cell(i)
            && r.mask[cell] == 0
        {
            trusted += 1;
        }
    }
    trusted
}

/// Quantiles of the tilt from vertical of the low ground's normals.
fn print_ground_normal_tilt_deg(scan: &Scan, r: &engine::PairLooming) {
    let mut tilts: Vec<f32> = (0..r.geometry.cells())
        .filter(|&c| r.mask[c] & mask::EMPTY == 0 && r.normal[c][2] > 0.7)
        .filter(|&c| scan.points_m[r.image.point[c] as usize][2] < -1.4)
        .map(|c| r.normal[c][2].clamp(-1.0, 1.0).acos().to_degrees())
        .collect();
    tilts.sort_by(f32::total_cmp);
    let q = |f: f64| quantile(&tilts, f);
    println!(
        "  ground normal tilt deg p50 {:.1} p75 {:.1} p90 {:.1} of {}",
        q(0.5),
        q(0.75),
        q(0.9),
        tilts.len()
    );
}

/// Share of neighbouring known normals more than 25 degrees apart, along a
/// row and across rows.
fn print_neighbour_normals_apart(r: &engine::PairLooming) {
    let cols = r.geometry.cols;
    let (mut n_pairs, mut bad, mut bad_vert) = (0, 0, 0);
    for cell in 0..r.geometry.cells() - cols {
        let (a, b, c) = (
            r.normal[cell],
            r.normal[cell - cell % cols + (cell % cols + 1) % cols],
            r.normal[cell + cols],
        );
        let known = |n: [f32; 3]| n[0] * n[0] + n[1] * n[1] + n[2] * n[2] > 0.5;
        if known(a) && known(b) && known(c) {
            n_pairs += 1;
            if (a[0] * b[0] + a[1] * b[1] + a[2] * b[2]).abs() < 0.906 {
                bad += 1;
            }
            if (a[0] * c[0] + a[1] * c[1] + a[2] * c[2]).abs() < 0.906 {
                bad_vert += 1;
            }
        }
    }
    println!(
        "  neighbour normals >25 deg apart: along row {:.1} %, across rows {:.1} %",
        100.0 * bad as f64 / n_pairs as f64,
        100.0 * bad_vert as f64 / n_pairs as f64
    );
}

/// Per row: occupied cells, and the share trusted and with each mask bit.
fn print_mask_shares_per_row(r: &engine::PairLooming) {
    let cols = r.geometry.cols;
    for row in 0..r.geometry.rows {
        let mut counts = [0usize; 7];
        for cell in row * cols..(row + 1) * cols {
            if r.mask[cell] & mask::EMPTY != 0 {
                continue;
            }
            counts[6] += 1;
            for (bit, c) in counts.iter_mut().enumerate().take(6) {
                if r.mask[cell] & (1 << bit) != 0 {
                    *c += 1;
                }
            }
            if r.mask[cell] == 0 {
                counts[0] += 1;
            }
        }
        let n = counts[6].max(1) as f64;
        println!(
            "  row {row:2} elev {:+6.2} par {:+.3} noise {:.3}: {:5} cells trusted {:3.0}% noprev {:3.0}% edge {:3.0}% grazing {:3.0}% occl {:3.0}%",
            r.geometry.beams.elevations_rad[row].to_degrees(),
            r.geometry.parallax_rad_m.as_ref().map_or(0.0, |p| p[row]),
            r.range_noise_m_per_row[row],
            counts[6],
            100.0 * counts[0] as f64 / n,
            100.0 * counts[1] as f64 / n,
            100.0 * counts[2] as f64 / n,
            100.0 * counts[3] as f64 / n,
            100.0 * counts[5] as f64 / n,
        );
    }
}

/// The engine's own motion estimate for the pair.
fn print_ego_estimate(e: &engine::egomotion::EgoEstimate) {
    println!(
        "  estimate v {:+.2} {:+.2} {:+.3} m/s  w {:+.4} {:+.4} {:+.4} rad/s  inliers {} scale {:.3} m  renders {}  sd v {:.3} {:.3} {:.3} m/s w {:.4} {:.4} {:.4} rad/s",
        e.velocity_mps[0],
        e.velocity_mps[1],
        e.velocity_mps[2],
        e.angular_velocity_radps[0],
        e.angular_velocity_radps[1],
        e.angular_velocity_radps[2],
        e.inlier_cells,
        e.residual_m,
        e.renders,
        e.covariance[3][3].sqrt(),
        e.covariance[4][4].sqrt(),
        e.covariance[5][5].sqrt(),
        e.covariance[0][0].sqrt(),
        e.covariance[1][1].sqrt(),
        e.covariance[2][2].sqrt(),
    );
}

/// The `f` quantile of sorted values (NaN when empty).
fn quantile(sorted: &[f32], f: f64) -> f32 {
    sorted
        .get((f * sorted.len() as f64) as usize)
        .copied()
        .unwrap_or(f32::NAN)
}

fn median(values: &mut Vec<f32>) -> f32 {
    values.retain(|v| v.is_finite());
    values.sort_by(f32::total_cmp);
    quantile(values, 0.5)
}

/// The mask as a picture, 3 pixels per row: trusted green, edge red,
/// no previous blue, grazing yellow, no ego magenta, occlusion cyan.
fn mask_png(r: &engine::PairLooming, path: &str) {
    cell_png(r, path, |cell| {
        let m = r.mask[cell];
        if m & mask::EMPTY != 0 {
            [0, 0, 0]
        } else if m == 0 {
            [40, 160, 40]
        } else if m & mask::EDGE != 0 {
            [220, 40, 40]
        } else if m & mask::NO_PREVIOUS != 0 {
            [40, 40, 220]
        } else if m & mask::GRAZING != 0 {
            [220, 220, 40]
        } else if m & mask::NO_EGO != 0 {
            [200, 40, 200]
        } else {
            [40, 200, 200]
        }
    });
}

/// The range image as a picture, 3 pixels per row (highest beam on top),
/// each cell coloured by `colour_of(cell)`.
fn cell_png(r: &engine::PairLooming, path: &str, colour_of: impl Fn(usize) -> [u8; 3]) {
    let (rows, cols) = (r.geometry.rows, r.geometry.cols);
    let mut img = image::RgbImage::new(cols as u32, (rows * 3) as u32);
    for row in 0..rows {
        for col in 0..cols {
            let colour = image::Rgb(colour_of(row * cols + col));
            for k in 0..3 {
                img.put_pixel(col as u32, ((rows - 1 - row) * 3 + k) as u32, colour);
            }
        }
    }
    img.save(path).expect("png");
}

/// Trusted static ground cells of one looming image, as least-squares rows
/// `([1, e_y / s, e_x / s], L)` with each cell's range (metres) and azimuth
/// (radians).
struct GroundFitSamples {
    rows: Vec<([f64; 3], f64)>,
    ranges_m: Vec<f32>,
    azimuths_rad: Vec<f32>,
}

/// The trusted static ground near `ground_z` (metres) in `values`.
fn ground_fit_samples(
    scan: &Scan,
    r: &engine::PairLooming,
    values: &[f32],
    ground_z: f32,
) -> GroundFitSamples {
    let mut rows = Vec::new();
    let mut ranges: Vec<f32> = Vec::new();
    let mut azimuths: Vec<f32> = Vec::new();
    for (cell, &value) in values.iter().enumerate() {
        if r.mask[cell] != 0 || r.moving[cell] || !value.is_finite() {
            continue;
        }
        let p = scan.points_m[r.image.point[cell] as usize];
        let range = (p[0] * p[0] + p[1] * p[1] + p[2] * p[2]).sqrt();
        let flat = (p[0] * p[0] + p[1] * p[1]).sqrt();
        if r.normal[cell][2] > 0.96 && (p[2] - ground_z).abs() < 0.2 + 0.01 * flat {
            let s = -p[2] / range;
            ranges.push(range);
            azimuths.push(p[1].atan2(p[0]));
            rows.push((
                [
                    1.0f64,
                    f64::from(p[1] / range / s),
                    f64::from(p[0] / range / s),
                ],
                f64::from(value),
            ));
        }
    }
    GroundFitSamples {
        rows,
        ranges_m: ranges,
        azimuths_rad: azimuths,
    }
}

/// Adds one least-squares row `x . k = y` to the normal equations.
fn add_normal_equation(
    (ata, atb): &mut (nalgebra::Matrix3<f64>, nalgebra::Vector3<f64>),
    x: [f64; 3],
    y: f64,
) {
    let v = nalgebra::Vector3::from(x);
    *ata += v * v.transpose();
    *atb += v * y;
}

/// The least-squares solution of the normal equations, if they are regular.
fn solve_normal_equations(
    (ata, atb): &(nalgebra::Matrix3<f64>, nalgebra::Vector3<f64>),
) -> Option<nalgebra::Vector3<f64>> {
    ata.try_inverse().map(|i| i * atb)
}

/// |y - x . k|.
fn fit_residual(x: &[f64; 3], y: f64, k: &nalgebra::Vector3<f64>) -> f32 {
    (y - k[0] * x[0] - k[1] * x[1] - k[2] * x[2]).abs() as f32
}

/// |L| left after a fit of its own per azimuth sector (time within the
/// sweep): a motion error that changes within the scan.
fn per_sector_residuals(samples: &GroundFitSamples, sectors: usize) -> Vec<f32> {
    let mut sec: Vec<(nalgebra::Matrix3<f64>, nalgebra::Vector3<f64>)> =
        vec![(nalgebra::Matrix3::zeros(), nalgebra::Vector3::zeros()); sectors];
    for ((x, y), az) in samples.rows.iter().zip(&samples.azimuths_rad) {
        add_normal_equation(&mut sec[sector_of(*az, sectors)], *x, *y);
    }
    let sol: Vec<Option<nalgebra::Vector3<f64>>> = sec.iter().map(solve_normal_equations).collect();
    samples
        .rows
        .iter()
        .zip(&samples.azimuths_rad)
        .map(|((x, y), az)| match sol[sector_of(*az, sectors)] {
            Some(k) => fit_residual(x, *y, &k),
            None => y.abs() as f32,
        })
        .collect()
}

/// Median range error (metres) the whole-scan fit leaves, in 2 m range bins.
fn print_range_error_by_range_m(samples: &GroundFitSamples, k: &nalgebra::Vector3<f64>) {
    let mut bins: Vec<Vec<f32>> = vec![Vec::new(); 12];
    for ((x, y), range) in samples.rows.iter().zip(&samples.ranges_m) {
        let res = fit_residual(x, *y, k);
        let b = ((*range / 2.0) as usize).min(11);
        bins[b].push(res * 0.1 * *range);
    }
    let text: Vec<String> = bins
        .iter_mut()
        .enumerate()
        .filter(|(_, v)| v.len() > 30)
        .map(|(i, v)| format!("{}m:{:.3}", 2 * i, median(v)))
        .collect();
    println!("      |dr| by range: {}", text.join(" "));
}

/// Fits the trusted static ground's looming to what a rotation-rate error
/// (about x and y) and a vertical-velocity error would read:
/// `L = a + b e_y / s + c e_x / s`, s = -e_z; prints the spread before and after.
fn ground_fit(scan: &Scan, r: &engine::PairLooming, ground_z: f32) {
    for (name, values) in [
        ("l_lidar", &r.l_lidar),
        ("l_ray_ego", &r.l_ray_ego),
        ("fused", &r.fused),
    ] {
        let samples = ground_fit_samples(scan, r, values, ground_z);
        let rows = &samples.rows;
        if rows.len() < 50 {
            continue;
        }
        let mut normal = (
            nalgebra::Matrix3::<f64>::zeros(),
            nalgebra::Vector3::<f64>::zeros(),
        );
        for (x, y) in rows {
            add_normal_equation(&mut normal, *x, *y);
        }
        let Some(k) = solve_normal_equations(&normal) else {
            continue;
        };
        let mut before: Vec<f32> = rows.iter().map(|(_, y)| y.abs() as f32).collect();
        let mut after: Vec<f32> = rows.iter().map(|(x, y)| fit_residual(x, *y, &k)).collect();
        let mut after_sector = per_sector_residuals(&samples, 8);
        println!(
            "      per-sector fit: median |L| -> {:.4}",
            median(&mut after_sector)
        );
        println!(
            "  fit {name:9} n {:6} a {:+.4} b {:+.4} c {:+.4}: median |L| {:.4} -> {:.4}",
            rows.len(),
            k[0],
            k[1],
            k[2],
            median(&mut before),
            median(&mut after)
        );
        print_range_error_by_range_m(&samples, &k);
    }
}

/// Per row: median range residual of the ground ahead (and behind) about one
/// plane fitted to it, metres: a per-laser range bias shows as a staircase.
fn ring_bias(scan: &Scan, r: &engine::PairLooming) {
    let pick = |cell: usize| {
        if r.mask[cell] & mask::EMPTY != 0 {
            return None;
        }
        let p = scan.points_m[r.image.point[cell] as usize];
        let ok =
            p[0].abs() > 4.0 && p[0].abs() < 16.0 && p[1].abs() < 3.0 && p[2] < -1.4 && p[2] > -2.1;
        ok.then_some(p)
    };
    let mut ata = nalgebra::Matrix3::<f64>::zeros();
    let mut atb = nalgebra::Vector3::<f64>::zeros();
    for cell in 0..r.geometry.cells() {
        if let Some(p) = pick(cell) {
            let v = nalgebra::Vector3::new(1.0, f64::from(p[0]), f64::from(p[1]));
            ata += v * v.transpose();
            atb += v * f64::from(p[2]);
        }
    }
    let Some(k) = ata.try_inverse().map(|i| i * atb) else {
        return;
    };
    let mut per_row: Vec<Vec<f32>> = vec![Vec::new(); r.geometry.rows];
    for cell in 0..r.geometry.cells() {
        if let Some(p) = pick(cell) {
            let dz = f64::from(p[2]) - (k[0] + k[1] * f64::from(p[0]) + k[2] * f64::from(p[1]));
            let range = f64::from(p[0] * p[0] + p[1] * p[1] + p[2] * p[2]).sqrt();
            let sin = -f64::from(p[2]) / range;
            if dz.abs() < 0.15 {
                per_row[cell / r.geometry.cols].push((-dz / sin) as f32);
            }
        }
    }
    let text: Vec<String> = per_row
        .iter_mut()
        .enumerate()
        .filter(|(_, v)| v.len() > 20)
        .map(|(row, v)| format!("{row}:{:+.3}", median(v)))
        .collect();
    println!("  ring range residual: {}", text.join(" "));
    let bias: Vec<String> = r
        .range_bias_m_per_row
        .iter()
        .enumerate()
        .map(|(row, b)| format!("{row}:{b:+.3}"))
        .collect();
    println!("  estimated bias: {}", bias.join(" "));
}

/// Looming of trusted cells as a picture, 3 pixels per row: red approaching,
/// blue receding, saturated at 0.1 1/s; masked cells dark grey.
fn value_png(values: &[f32], r: &engine::PairLooming, path: &str) {
    cell_png(r, path, |cell| {
        let v = values[cell];
        if r.mask[cell] != 0 || !v.is_finite() {
            return [30, 30, 30];
        }
        let t = (v / 0.1).clamp(-1.0, 1.0);
        let k = (255.0 * t.abs()) as u8;
        if t > 0.0 {
            [255, 255 - k, 255 - k]
        } else {
            [255 - k, 255 - k, 255]
        }
    });
}

fn sector_of(azimuth: f32, sectors: usize) -> usize {
    let t = (azimuth + std::f32::consts::PI) / std::f32::consts::TAU;
    ((t * sectors as f32) as usize).min(sectors - 1)
}

/// DIAG_FACING: trusted cells whose surface faces along x (|n_x| > 0.7), by
/// side (ahead / behind) and range band: their count and median `L_lidar`
/// and `L_ray_ego`, to see which surfaces pin down forward motion.
fn print_facing_sectors(scan: &Scan, r: &engine::PairLooming) {
    let mut bands: std::collections::BTreeMap<(bool, u32), (Vec<f32>, Vec<f32>)> =
        std::collections::BTreeMap::new();
    for cell in 0..r.mask.len() {
        let n = r.normal[cell];
        if r.mask[cell] != 0 || n[0].abs() < 0.7 || !r.l_lidar[cell].is_finite() {
            continue;
        }
        let index = r.image.point[cell];
        if index == engine::NO_POINT {
            continue;
        }
        let p = scan.points_m[index as usize];
        let range = (p[0] * p[0] + p[1] * p[1] + p[2] * p[2]).sqrt();
        let band = (range / 5.0) as u32 * 5;
        if std::env::var("DIAG_FACING_POINTS").is_ok() && p[0] < 0.0 && range < 5.0 && cell % 7 == 0
        {
            println!(
                "    behind cell {cell} row {} col {} p {:+.2} {:+.2} {:+.2} n {:+.2} {:+.2} {:+.2} L_lidar {:+.3} dt {:.3}",
                cell / r.geometry.cols,
                cell % r.geometry.cols,
                p[0],
                p[1],
                p[2],
                n[0],
                n[1],
                n[2],
                r.l_lidar[cell],
                r.dt_s[cell]
            );
        }
        let entry = bands.entry((p[0] > 0.0, band)).or_default();
        entry.0.push(r.l_lidar[cell]);
        entry.1.push(r.l_ray_ego[cell]);
    }
    for ((ahead, band), (mut lidar, mut ego)) in bands {
        if lidar.len() < 30 {
            continue;
        }
        lidar.sort_by(f32::total_cmp);
        ego.sort_by(f32::total_cmp);
        println!(
            "  facing x {} {band:>2}-{:>2} m: {:5} cells, L_lidar {:+.3}, L_ray_ego {:+.3}",
            if ahead { "ahead " } else { "behind" },
            band + 5,
            lidar.len(),
            lidar[lidar.len() / 2],
            ego[ego.len() / 2]
        );
    }
}
