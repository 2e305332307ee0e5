//! Tests of the plane fits and their linear algebra.

use nalgebra::Matrix3;

use super::plane::{eigenvalues_below, fit_plane, scatter, symmetric_eigenvalues};
use super::window::{
    Gather, fit_beyond_gate, fit_gated_points, fit_whole_window, fit_window, gated_window,
    too_narrow,
};
use super::*;

#[test]
fn a_plane_fit_recovers_the_plane() {
    let normal = Vector3::new(0.2, -0.3, 0.9).normalize();
    let u = normal.cross(&Vector3::x()).normalize();
    let v = normal.cross(&u);
    let base = Vector3::new(5.0, 1.0, -1.7);
    let points: Vec<Vector3<f64>> = (0..9)
        .map(|k| base + u * f64::from(k % 3) * 0.2 + v * f64::from(k / 3) * 0.3)
        .collect();
    let (fitted, centroid) = fit_plane(&points).unwrap();
    assert!(fitted.dot(&normal).abs() > 1.0 - 1e-9);
    assert!((centroid - base).dot(&normal).abs() < 1e-9);
}

#[test]
fn points_on_a_line_define_no_plane() {
    let points: Vec<Vector3<f64>> = (0..5)
        .map(|k| Vector3::new(f64::from(k), 2.0 * f64::from(k), 1.0))
        .collect();
    assert!(fit_plane(&points).is_none());
}

/// Uniform numbers in [-0.5, 0.5), the same sequence every run.
fn uniform_numbers() -> impl FnMut() -> f64 {
    let mut state = 0x2545_f491_4f6c_dd1du64;
    move || {
        state ^= state << 13;
        state ^= state >> 7;
        state ^= state << 17;
        (state >> 11) as f64 / (1u64 << 53) as f64 - 0.5
    }
}

/// Scatter matrices of windows on planes (one small eigenvalue), of
/// isotropic clouds and of lines.
fn scatter_matrices() -> Vec<Matrix3<f64>> {
    let mut uniform = uniform_numbers();
    (0..300)
        .map(|case| {
            let thickness = [1e-4, 0.02, 1.0][case % 3];
            let width = if case % 7 == 0 { 1e-6 } else { 0.3 };
            let points: Vec<Vector3<f64>> = (0..15)
                .map(|_| Vector3::new(uniform(), uniform() * width, uniform() * thickness))
                .collect();
            scatter(&points).1
        })
        .collect()
}

#[test]
fn eigenvalues_match_nalgebras_on_scatter_matrices() {
    // Against nalgebra's iterative solver.
    for (case, covariance) in scatter_matrices().into_iter().enumerate() {
        let (a, b, c) = symmetric_eigenvalues(&covariance).unwrap();
        let mut expected: Vec<f64> = covariance
            .symmetric_eigen()
            .eigenvalues
            .iter()
            .copied()
            .collect();
        expected.sort_by(f64::total_cmp);
        let scale = expected[2];
        for (found, want) in [a, b, c].iter().zip(&expected) {
            assert!(
                (found - want).abs() <= 1e-9 * scale,
                "{case}: {a} {b} {c} vs {expected:?}"
            );
        }
    }
}

#[test]
fn eigenvalues_below_a_bound_are_counted_from_the_minors() {
    for (case, covariance) in scatter_matrices().into_iter().enumerate() {
        let (a, b, c) = symmetric_eigenvalues(&covariance).unwrap();
        // Bounds between and beyond the eigenvalues, clear of them.
        let bounds = [0.5 * a - 1.0, 0.5 * (a + b), 0.5 * (b + c), 2.0 * c + 1.0];
        for (expected, bound) in bounds.into_iter().enumerate() {
            let clear = [a, b, c].iter().all(|e| (e - bound).abs() > 1e-6 * c);
            if clear {
                assert_eq!(
                    eigenvalues_below(&covariance, bound),
                    Some(expected),
                    "{case}: {bound} against {a} {b} {c}"
                );
            }
        }
    }
}

/// The returns of a `rows x cols` image of a noisy plane 10 m ahead,
/// with one return `off_plane_m` in front of it.
fn noisy_plane(rows: usize, cols: usize, noise_m: f64, off_plane_m: f64) -> Vec<Vector3<f64>> {
    let mut uniform = uniform_numbers();
    (0..rows * cols)
        .map(|cell| {
            let (row, col) = ((cell / cols) as f64, (cell % cols) as f64);
            let depth = 10.0 + 0.05 * col + noise_m * uniform();
            let depth = if cell == 2 * cols + 5 {
                depth - off_plane_m
            } else {
                depth
            };
            Vector3::new(depth, 0.03 * col, 0.07 * row - 0.5)
        })
        .collect()
}

/// A dense image's geometry, parameters and (unused) gridded scan.
fn dense_image(
    rows: usize,
    cols: usize,
    noise_m: f64,
) -> (ImageGeometry, SurfaceParams, RangeImage) {
    let geometry = ImageGeometry {
        rows,
        cols,
        beams: super::super::beams::BeamTable::uniform(rows, -0.1, 0.1),
        ring_to_row: None,
        parallax_rad_m: None,
    };
    let params = SurfaceParams {
        range_noise_m: noise_m,
        half_cols: 2,
        sparse_rows: false,
        ground_z_m: f64::NEG_INFINITY,
    };
    let image = RangeImage {
        range_m: Vec::new(),
        point: Vec::new(),
        point_cell: Vec::new(),
        point_surface: Vec::new(),
    };
    (geometry, params, image)
}

#[test]
fn whole_window_fits_match_fits_point_by_point() {
    let (rows, cols) = (5, 24);
    let (geometry, params, image) = dense_image(rows, cols, 0.002);
    // Noise enough for the windows' summed squared distances to exceed
    // the tolerance (rows are then looked at one by one), and a return
    // off the plane by more than the tolerance.
    let points = noisy_plane(rows, cols, 0.03, 0.2);
    let returns = Returns::of_points(&image, points, cols, &[2, 4]);
    let mut scratch = Scratch::default();
    let (mut whole, mut off) = (0, 0);
    for cell in 0..rows * cols {
        for window in [(1, 2), (2, 4)] {
            let center = returns.point(cell).unwrap();
            let gather = Gather {
                cell,
                window,
                within_gate: false,
            };
            let by_points =
                fit_gated_points(&returns, &geometry, &center, params, gather, &mut scratch);
            let gated = gated_window(&returns, &geometry, cell, window).unwrap();
            let (fit, spread) =
                fit_whole_window(&returns, cols, &center, params, &gated).expect("a plane");
            assert_eq!(fit.edge, by_points.0.edge, "cell {cell} {window:?}: edge");
            assert_eq!(fit.support, by_points.0.support, "cell {cell} {window:?}");
            if fit.edge {
                off += 1;
            } else {
                whole += 1;
            }
            assert!((fit.range_m - by_points.0.range_m).abs() < 1e-5);
            assert!((spread.unwrap() - by_points.1.unwrap()).abs() < 1e-6);
            let dot: f32 = (0..3).map(|k| fit.normal[k] * by_points.0.normal[k]).sum();
            assert!(dot > 1.0 - 1e-6, "cell {cell} {window:?}: normals {dot}");
        }
    }
    assert!(
        whole > 0 && off > 0,
        "{whole} whole windows, {off} off the plane"
    );
}

#[test]
fn fits_beyond_the_gate_match_fits_point_by_point() {
    let (rows, cols) = (5, 24);
    let (geometry, params, image) = dense_image(rows, cols, 0.002);
    // A noisy plane with a return off it, and a column of returns far
    // behind it (beyond the range gate of the cells about it).
    let mut points = noisy_plane(rows, cols, 0.03, 0.2);
    for row in 0..rows {
        points[row * cols + 9] *= 3.0;
    }
    let returns = Returns::of_points(&image, points, cols, &[2, 4]);
    let mut scratch = Scratch::default();
    let mut beyond = 0;
    for cell in 0..rows * cols {
        for window in [(1, 2), (2, 4)] {
            if gated_window(&returns, &geometry, cell, window).is_some() {
                continue;
            }
            beyond += 1;
            let center = returns.point(cell).unwrap();
            let gather = Gather {
                cell,
                window,
                within_gate: false,
            };
            let (by_points, points_spread) =
                fit_gated_points(&returns, &geometry, &center, params, gather, &mut scratch);
            let (fit, spread) = fit_beyond_gate(&returns, &geometry, cell, &center, params, window)
                .expect("within the image");
            let at = format!("cell {cell} {window:?}");
            assert_eq!(fit.edge, by_points.edge, "{at}: edge");
            assert_eq!(fit.support, by_points.support, "{at}: support");
            assert_eq!(spread.is_some(), points_spread.is_some(), "{at}: a plane");
            assert!((fit.range_m - by_points.range_m).abs() < 1e-5, "{at}");
            if let (Some(a), Some(b)) = (spread, points_spread) {
                assert!((a - b).abs() < 1e-6, "{at}: spread");
                let dot: f32 = (0..3).map(|k| fit.normal[k] * by_points.normal[k]).sum();
                assert!(dot > 1.0 - 1e-6, "{at}: normals {dot}");
            }
        }
    }
    assert!(beyond > 0);
}

#[test]
fn windows_found_too_narrow_fit_with_a_spread_below_two_sigmas() {
    let (rows, cols) = (5, 24);
    let mut narrow = 0;
    for noise_m in [0.005, 0.03] {
        let (geometry, params, image) = dense_image(rows, cols, noise_m);
        let points = noisy_plane(rows, cols, noise_m, 0.5);
        let returns = Returns::of_points(&image, points, cols, &[2, 4]);
        let mut scratch = Scratch::default();
        for cell in 0..rows * cols {
            for window in [(1, 2), (2, 4)] {
                let gated = gated_window(&returns, &geometry, cell, window);
                let (fit, spread) = fit_window(
                    &returns,
                    &geometry,
                    cell,
                    params,
                    window,
                    gated.as_ref(),
                    &mut scratch,
                );
                if gated.is_some_and(|g| too_narrow(&g, params)) {
                    narrow += 1;
                    let wide = spread.is_none_or(|s| s >= 2.0 * noise_m);
                    assert!(!wide && !fit.edge, "cell {cell} {window:?}: {spread:?}");
                }
            }
        }
    }
    assert!(narrow > 0);
}

#[test]
fn eigenvalues_of_a_diagonal_matrix_are_its_diagonal() {
    let m = Matrix3::from_diagonal(&Vector3::new(3.0, 1.0, 2.0));
    let (a, b, c) = symmetric_eigenvalues(&m).unwrap();
    assert!((a - 1.0).abs() < 1e-12 && (b - 2.0).abs() < 1e-12 && (c - 3.0).abs() < 1e-12);
}

/// The smallest eigenvalue by Newton's method from 0 iterated until its
/// step is below 1e-14 of the trace (the stop before `NEWTON_CONVERGED`).
fn smallest_eigenvalue_to_1e14(a: &Matrix3<f64>) -> f64 {
    let (trace, minors, det) = (
        a.trace(),
        super::plane::principal_minors(a),
        a.determinant(),
    );
    if minors > 0.0 && det > 0.0 {
        super::plane::newton_from(0.0, (trace, minors, det), 1e-14)
    } else {
        0.0
    }
}

#[test]
fn newtons_looser_stop_leaves_a_planes_smallest_eigenvalue_as_it_was() {
    for (case, covariance) in scatter_matrices().into_iter().enumerate() {
        let (found, _, _) = symmetric_eigenvalues(&covariance).unwrap();
        let before = smallest_eigenvalue_to_1e14(&covariance);
        // Planes (one thin axis, `case % 3 < 2`, two wide ones) to the
        // last bits of the trace; lines converge linearly, no worse than
        // `eigenvalues_match_nalgebras_on_scatter_matrices` asks.
        let plane = case % 3 < 2 && case % 7 != 0;
        let bound = if plane { 1e-16 } else { 1e-9 } * covariance.trace();
        assert!(
            (found - before).abs() <= bound,
            "{case}: {found} vs {before}"
        );
    }
}

#[test]
fn bands_and_tiles_fit_every_cell_as_cell_by_cell() {
    // 17 rows: bands of 2 rows and one of 1; 150 columns: tiles of 64, 64,
    // 22, each cell's growth from 3 beams (a coarse grid).
    bands_and_tiles_fit_as_cell_by_cell(150);
}

/// A plane with dropouts and a close object, 17 rows (bands of 2 rows and
/// one of 1) by `cols`: the geometry, parameters, each row's noise, the
/// returns and their surfaces as `write_fits` writes them.
fn tiled_scene(
    image: &RangeImage,
    cols: usize,
) -> (
    ImageGeometry,
    SurfaceParams,
    Vec<f32>,
    Returns<'_>,
    Surfaces,
) {
    let rows = 17;
    let (geometry, params, _) = dense_image(rows, cols, 0.02);
    let mut points = noisy_plane(rows, cols, 0.02, 0.5);
    for (cell, p) in points.iter_mut().enumerate() {
        if cell % 13 == 5 {
            *p = Vector3::repeat(f64::NAN);
        } else if (60..70).contains(&(cell % cols)) {
            // A close object: windows grow, edges at its sides.
            *p *= 0.2;
        }
    }
    let noise_m_per_row: Vec<f32> = (0..rows).map(|r| 0.01 + 0.002 * r as f32).collect();
    let returns = Returns::of_points(image, points, cols, &[2, 4, 6]);
    let mut surfaces = Surfaces::empty(rows * cols, cols);
    surfaces.write_fits(&returns, &geometry, params, &noise_m_per_row);
    (geometry, params, noise_m_per_row, returns, surfaces)
}

/// On a fine grid (1100 columns) every cell is fitted as `fit_cell` fits
/// it from some start of its growth (the growth carried along each tile),
/// or, in an odd column with a right neighbour in its tile, derived from
/// its neighbours (`fits::between`): no edge, within a noise sigma of
/// one of its own fits along its normal and 8 degrees of its normal;
/// most of the plane's odd cells are derived, none beside the close
/// object.
#[test]
fn a_fine_grids_cells_are_fitted_or_derived_from_their_neighbours() {
    let cols = 1100;
    let image = dense_image(1, 1, 0.0).2;
    let (geometry, params, noise_m_per_row, returns, surfaces) = tiled_scene(&image, cols);
    let rows = geometry.rows;
    let mut scratch = Scratch::default();
    let mut derived = 0;
    for cell in (0..rows * cols).filter(|&c| returns.point(c).is_some()) {
        let (row, col) = (cell / cols, cell % cols);
        let params = SurfaceParams {
            range_noise_m: f64::from(noise_m_per_row[row]),
            ..params
        };
        let fits: Vec<_> = (1..=MAX_GROWTH)
            .map(|grow| fits::fit_cell(&returns, &geometry, cell, params, &mut scratch, grow).0)
            .collect();
        let got = (
            surfaces.range_m[cell].to_bits(),
            surfaces.normal[cell].map(f32::to_bits),
            surfaces.support[cell],
            surfaces.edge[cell],
        );
        let as_fitted = |f: &CellSurface| {
            got == (
                f.range_m.to_bits(),
                f.normal.map(f32::to_bits),
                f.support,
                f.edge,
            )
        };
        if fits.iter().any(as_fitted) {
            continue;
        }
        derived += 1;
        let in_tile = col % fits::TILE_COLS;
        assert!(
            col % 2 == 1 && in_tile + 1 < fits::TILE_COLS && col + 1 < cols,
            "cell {cell}"
        );
        assert!(!surfaces.edge[cell], "cell {cell}");
        // Its own window (two columns either side) off the close object.
        assert!(!(58..72).contains(&col), "cell {cell} by the close object");
        // Near one of its own fits (the growth its neighbours settled on):
        // along the normal (the plane's far columns are seen near grazing,
        // where a range moves by the plane's error over the incidence).
        let sigma = f64::from(noise_m_per_row[row]);
        let range_m = f64::from(surfaces.range_m[cell]);
        let incidence = f64::from(surfaces.incidence_cos[cell]);
        let near = fits.iter().any(|own| {
            let cos: f32 = (0..3)
                .map(|k| surfaces.normal[cell][k] * own.normal[k])
                .sum();
            (range_m - f64::from(own.range_m)).abs() * incidence < sigma && cos > 0.99
        });
        let ranges: Vec<f32> = fits.iter().map(|f| f.range_m).collect();
        assert!(near, "cell {cell}: {range_m} against {ranges:?}");
    }
    // Of some 8600 odd cells, most on the plane.
    assert!(derived > 5000, "{derived} derived");
}

fn bands_and_tiles_fit_as_cell_by_cell(cols: usize) {
    let carry = cols >= fits::CARRY_MIN_COLS;
    let image = dense_image(1, 1, 0.0).2;
    let (geometry, params, noise_m_per_row, returns, surfaces) = tiled_scene(&image, cols);
    let rows = geometry.rows;
    let mut scratch = Scratch::default();
    // On a fine grid each cell's growth starts at that of the last
    // non-empty cell to its left in its tile (3 beams at the tile's first
    // column), on a coarse one at 3 beams.
    let mut left_grow = 1;
    let mut grows = [0usize; 4];
    for cell in 0..rows * cols {
        let params = SurfaceParams {
            range_noise_m: f64::from(noise_m_per_row[cell / cols]),
            ..params
        };
        if (cell % cols).is_multiple_of(fits::TILE_COLS) {
            left_grow = 1;
        }
        let (want, grow) =
            fits::fit_cell(&returns, &geometry, cell, params, &mut scratch, left_grow);
        if carry && want.range_m.is_finite() {
            left_grow = grow;
        }
        grows[grow] += 1;
        let got = (
            surfaces.range_m[cell].to_bits(),
            surfaces.direction[cell].map(f32::to_bits),
            surfaces.normal[cell].map(f32::to_bits),
            surfaces.incidence_cos[cell].to_bits(),
            surfaces.support[cell],
            surfaces.edge[cell],
        );
        let wanted = (
            want.range_m.to_bits(),
            want.direction.map(f32::to_bits),
            want.normal.map(f32::to_bits),
            want.incidence_cos.to_bits(),
            want.support,
            want.edge,
        );
        assert_eq!(got, wanted, "cell {cell}");
    }
    // Some windows stayed at 3 beams, and the close object's grew.
    assert!(grows[1] > 0 && grows[2] + grows[3] > 0, "{grows:?}");
}

#[test]
fn plane_scatter_is_the_whole_fits_residual_to_the_bit() {
    use super::noise::{plane_scatter_by_fit, plane_scatter_m};
    // Images with returns off the plane, beyond the range gate (a column
    // far behind, a close object), empty cells, and too narrow for the
    // running sums (the window wider than the image: the fit itself).
    let mut counts = [0usize; 2];
    for (rows, cols, half_cols) in [(5, 24, 2), (7, 40, 2), (4, 4, 2), (3, 3, 1), (1, 12, 2)] {
        for (noise_m, off_m) in [(0.002, 0.2), (0.03, 0.5), (0.0, 0.0)] {
            let (geometry, params, image) = dense_image(rows, cols, noise_m);
            let mut points = noisy_plane(rows, cols, noise_m, off_m);
            for (cell, p) in points.iter_mut().enumerate() {
                let col = cell % cols;
                if cell % 11 == 4 {
                    *p = Vector3::repeat(f64::NAN);
                } else if col == 9 {
                    *p *= 3.0;
                } else if (14..17).contains(&col) {
                    *p *= 0.2;
                }
            }
            let returns = Returns::of_points(&image, points, cols, &[half_cols, 2 * half_cols]);
            let loose = SurfaceParams {
                range_noise_m: 0.05,
                half_cols,
                ..params
            };
            let mut scratch = Scratch::default();
            for cell in 0..rows * cols {
                let fast = plane_scatter_m(&returns, &geometry, cell, loose, &mut scratch);
                let fit = plane_scatter_by_fit(&returns, &geometry, cell, loose, &mut scratch);
                assert_eq!(
                    fast.map(f32::to_bits),
                    fit.map(f32::to_bits),
                    "{rows} x {cols}, noise {noise_m}, cell {cell}"
                );
                counts[usize::from(fit.is_some())] += 1;
            }
        }
    }
    assert!(counts[0] > 0 && counts[1] > 0, "{counts:?}");
}
