//! Where the engine's trust goes on a log, pair by pair: trusted share of
//! points, mask bits, the ground's looming. A development tool:
//! `cargo run --release --example engine_diag -- LOG.mcap [PAIRS]`.

use looming::engine::{self, EngineCache, EngineConfig, mask};
use looming::messages::Scan;

fn main() {
    let args: Vec<String> = std::env::args().collect();
    let path = args.get(1).expect("LOG.mcap");
    let max_pairs: usize = args
        .get(2)
        .map_or(usize::MAX, |a| a.parse().expect("a count"));
    let config = EngineConfig::default();
    let mut cache = EngineCache::default();
    let mut totals = Totals::default();
    let mut done = 0;
    // Rings and times the clouds lack come from the engine's front end
    // (`engine::layout`), which runs in the pairer as in `process`.
    looming::replay::replay(std::path::Path::new(path), &mut |_| {}, &mut |pair| {
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
    })
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
    ms: f64,
    rows: usize,
}

impl Totals {
    fn add(&mut self, scan: &Scan, r: &engine::PairLooming, ms: f64) {
        self.pairs += 1;
        self.ms += ms;
        self.rows = r.geometry.rows;
        if std::env::var("AHEAD").is_ok() {
            // Returns in the lane ahead, above the road: a vehicle's rear face.
            let mut xs: Vec<f32> = scan
                .points_m
                .iter()
                .filter(|p| {
                    p[0] > 2.5 && p[0] < 15.0 && p[1].abs() < 1.2 && p[2] > -1.2 && p[2] < 0.5
                })
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
        let mut trusted = 0;
        for i in 0..scan.points_m.len() {
            if let Some(cell) = r.image.surface_cell(i)
                && r.mask[cell] == 0
            {
                trusted += 1;
            }
        }
        self.points += scan.points_m.len();
        self.trusted_points += trusted;
        // Ground: upward normal, below the sensor.
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
        if std::env::var("DIAG_NORMALS").is_ok() {
            let mut tilts: Vec<f32> = (0..r.geometry.cells())
                .filter(|&c| r.mask[c] & mask::EMPTY == 0 && r.normal[c][2] > 0.7)
                .filter(|&c| scan.points_m[r.image.point[c] as usize][2] < -1.4)
                .map(|c| r.normal[c][2].clamp(-1.0, 1.0).acos().to_degrees())
                .collect();
            tilts.sort_by(f32::total_cmp);
            let q = |f: f64| {
                tilts
                    .get((f * tilts.len() as f64) as usize)
                    .copied()
                    .unwrap_or(f32::NAN)
            };
            println!(
                "  ground normal tilt deg p50 {:.1} p75 {:.1} p90 {:.1} of {}",
                q(0.5),
                q(0.75),
                q(0.9),
                tilts.len()
            );
        }
        heights.sort_by(f32::total_cmp);
        let ground_z = heights.get(heights.len() / 2).copied().unwrap_or(f32::NAN);
        let mut pair_ground = Vec::new();
        for cell in 0..r.geometry.cells() {
            if r.mask[cell] != 0 || r.moving[cell] {
                continue;
            }
            let p = scan.points_m[r.image.point[cell] as usize];
            let range = (p[0] * p[0] + p[1] * p[1]).sqrt();
            if r.normal[cell][2] > 0.96 && (p[2] - ground_z).abs() < 0.2 + 0.01 * range {
                pair_ground.push(r.fused[cell].abs());
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
            let d = r.disagreement[cell];
            if d.is_finite() {
                self.static_d.push(d.abs());
            }
        }
        {
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
        if let Ok(png) = std::env::var("DIAG_PNG")
            && self.pairs == 2
        {
            mask_png(r, &png);
        }
        if std::env::var("DIAG_ROWS").is_ok() {
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
        if let Some(e) = &r.ego_estimate {
            println!(
                "  estimate v {:+.2} {:+.2} {:+.3} m/s  w {:+.4} {:+.4} {:+.4} rad/s  inliers {} scale {:.3} m",
                e.velocity_mps[0],
                e.velocity_mps[1],
                e.velocity_mps[2],
                e.angular_velocity_radps[0],
                e.angular_velocity_radps[1],
                e.angular_velocity_radps[2],
                e.inlier_cells,
                e.residual_m
            );
        }
        println!(
            "pair {:3}: {:5.1} % trusted, ground {} cells median |fused| {:.4}, ground z {:.2}, {:.0} ms",
            self.pairs - 1,
            100.0 * trusted as f64 / scan.points_m.len() as f64,
            pair_ground.len(),
            median(&mut pair_ground),
            ground_z,
            ms
        );
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
            let q = |f: f64| {
                values
                    .get((f * values.len() as f64) as usize)
                    .copied()
                    .unwrap_or(f32::NAN)
            };
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

fn median(values: &mut Vec<f32>) -> f32 {
    values.retain(|v| v.is_finite());
    if values.is_empty() {
        return f32::NAN;
    }
    values.sort_by(f32::total_cmp);
    values[values.len() / 2]
}

/// The mask as a picture, 3 pixels per row: trusted green, edge red,
/// no previous blue, grazing yellow, no ego magenta, occlusion cyan.
fn mask_png(r: &engine::PairLooming, path: &str) {
    let (rows, cols) = (r.geometry.rows, r.geometry.cols);
    let mut img = image::RgbImage::new(cols as u32, (rows * 3) as u32);
    for row in 0..rows {
        for col in 0..cols {
            let m = r.mask[row * cols + col];
            let colour = if m & mask::EMPTY != 0 {
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
            };
            for k in 0..3 {
                img.put_pixel(
                    col as u32,
                    ((rows - 1 - row) * 3 + k) as u32,
                    image::Rgb(colour),
                );
            }
        }
    }
    img.save(path).expect("png");
}
