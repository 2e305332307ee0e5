//! A render of the previous scan carried to a slightly different motion
//! without rendering again: each covered ray's range moved by the first-order
//! change the motion's correction makes on the surface it meets (the same
//! linearisation the estimate's equations solve). The estimate's last
//! correction is mostly small (it starts from the pair before's motion), and
//! a second render to check it cost a third of a blind log's engine time.

use nalgebra::{Vector3, Vector6};
use rayon::prelude::*;

use crate::engine::surface::Surfaces;
use crate::engine::warp::Rendered;
use crate::model::StampNs;

/// Whether `correction` (angular rad/s, then linear m/s) moves no surface
/// within [`REACH_M`] by more than [`MAX_LINEAR_SHIFT_M`] over `dt_s`: where
/// the linearisation stands in for a render.
pub(super) fn within_linear_reach(correction: &Vector6<f64>, dt_s: f64) -> bool {
    let (angular, linear) = split(correction);
    dt_s.abs() * (linear.norm() + angular.norm() * REACH_M) <= MAX_LINEAR_SHIFT_M
}

/// Surfaces this far away bound the shift a rotation makes, m.
const REACH_M: f64 = 30.0;
/// A shift of a surface the linearised render follows, m: a plane moved by
/// it is met by the same rays (occlusion edges, where the surface a ray
/// meets changes, are masked either way). A translation it follows exactly;
/// a turn of this much at [`REACH_M`] (0.29 degrees) leaves 2 mm at 10 m
/// (the wall test below), a tenth of a real sensor's range noise. At 5 cm
/// KITTI's drives re-rendered on 18 of 21 pairs (their rotation rates move
/// 0.02-0.05 rad/s from pair to pair); at 15 cm on 2, and KITTI 22's wall
/// time 0.84 x, the braking car's face and the near misses unchanged.
const MAX_LINEAR_SHIFT_M: f64 = 0.15;

/// `rendered` as the render with the motion changed by `correction` would
/// be, to first order: a static surface with normal `n` met at `X = R e`
/// moves by `-(dv + dw x X) dt`, so the ray meets it at
/// `R - dt ((X x n) . dw + n . dv) / (n . e)`. The covering triangle's
/// normal, else the current cell's; a ray without either takes the surface
/// as facing it (`n = e`).
pub(super) fn corrected_render(
    mut rendered: Rendered,
    current: &Surfaces,
    current_time_ns: &[StampNs],
    correction: &Vector6<f64>,
) -> Rendered {
    let (angular, linear) = split(correction);
    let source_time_ns = &rendered.source_time_ns;
    let normals = &rendered.normal;
    rendered
        .range_m
        .par_iter_mut()
        .enumerate()
        .for_each(|(cell, range_m)| {
            let range = f64::from(*range_m);
            if !range.is_finite() {
                return;
            }
            let dt_s = (current_time_ns[cell] - source_time_ns[cell]) as f64 * 1e-9;
            let e = as_f64(current.direction[cell]);
            let n = [normals[cell], current.normal[cell]]
                .into_iter()
                .map(as_f64)
                .find(|n| n.norm_squared() > 0.5 && n.dot(&e).abs() >= MIN_FACING_COS)
                .unwrap_or(e);
            let x = e * range;
            let shift_m = dt_s * (x.cross(&n).dot(&angular) + n.dot(&linear)) / n.dot(&e);
            *range_m = (range - shift_m) as f32;
        });
    rendered
}

/// Normals seen more obliquely than this are not divided by: the surface is
/// taken as facing the ray instead.
const MIN_FACING_COS: f64 = 0.1;

fn split(correction: &Vector6<f64>) -> (Vector3<f64>, Vector3<f64>) {
    (
        correction.fixed_rows::<3>(0).into_owned(),
        correction.fixed_rows::<3>(3).into_owned(),
    )
}

fn as_f64(v: [f32; 3]) -> Vector3<f64> {
    Vector3::from(v).cast()
}

#[cfg(test)]
mod tests {
    use super::*;
    use nalgebra::Rotation3;

    /// Rays from -30 to +30 degrees of azimuth at three elevations, the
    /// previous scan's wall `x = 10 m` rendered along them a scan earlier.
    /// The normal is the triangle's on even cells, the current cell's on
    /// odd ones.
    fn wall() -> (Rendered, Surfaces, Vec<StampNs>) {
        let mut directions = Vec::new();
        for elevation_deg in [-5.0f64, 0.0, 5.0] {
            for k in 0..61 {
                let azimuth = (f64::from(k) - 30.0).to_radians();
                let elevation = elevation_deg.to_radians();
                directions.push(Vector3::new(
                    elevation.cos() * azimuth.cos(),
                    elevation.cos() * azimuth.sin(),
                    elevation.sin(),
                ));
            }
        }
        let cells = directions.len();
        let facing = [-1.0f32, 0.0, 0.0];
        let normal_if = |even: bool| {
            (0..cells)
                .map(|c| {
                    if (c % 2 == 0) == even {
                        facing
                    } else {
                        [0.0; 3]
                    }
                })
                .collect::<Vec<_>>()
        };
        let rendered = Rendered {
            range_m: directions.iter().map(|e| (10.0 / e.x) as f32).collect(),
            source_time_ns: vec![0; cells],
            normal: normal_if(true),
            edge: vec![false; cells],
        };
        let current = Surfaces {
            range_m: vec![f32::NAN; cells],
            direction: directions
                .iter()
                .map(|e| [e.x as f32, e.y as f32, e.z as f32])
                .collect(),
            normal: normal_if(false),
            incidence_cos: vec![1.0; cells],
            support: vec![1; cells],
            edge: vec![false; cells],
            noise_m_per_row: vec![0.02; 3],
            range_bias_m_per_row: vec![0.0; 3],
            joins: vec![0; cells],
            azimuth_rad: vec![0.0; cells],
            elevation_rad: vec![0.0; cells],
            cols: 61,
        };
        (rendered, current, vec![100_000_000; cells])
    }

    /// Where each ray meets the wall with the LiDAR moved `linear * dt` and
    /// turned `angular * dt` further than the render assumed.
    fn exact_ranges(current: &Surfaces, angular: Vector3<f64>, linear: Vector3<f64>) -> Vec<f64> {
        let dt_s = 0.1;
        let n = Vector3::new(-1.0, 0.0, 0.0);
        let turned = Rotation3::new(angular * dt_s).inverse() * n;
        current
            .direction
            .iter()
            .map(|&d| (-10.0 - n.dot(&linear) * dt_s) / turned.dot(&as_f64(d)))
            .collect()
    }

    #[test]
    fn a_correction_moves_the_rendered_wall_as_a_render_would() {
        let (rendered, current, time_ns) = wall();
        for (angular, linear, tolerance_m) in [
            // A translation moves a plane exactly as linearised.
            (Vector3::zeros(), Vector3::new(0.4, 0.1, -0.05), 1e-5),
            // A turn of 0.3 degrees over the pair: second order is left.
            (
                Vector3::new(0.0, 0.0, 0.05),
                Vector3::new(0.3, 0.0, 0.0),
                2e-3,
            ),
        ] {
            let correction = Vector6::new(
                angular.x, angular.y, angular.z, linear.x, linear.y, linear.z,
            );
            let corrected = corrected_render(rendered.clone(), &current, &time_ns, &correction);
            let exact = exact_ranges(&current, angular, linear);
            for (cell, (&got, want)) in corrected.range_m.iter().zip(exact).enumerate() {
                assert!(
                    (f64::from(got) - want).abs() < tolerance_m,
                    "cell {cell}: {got} against {want}"
                );
            }
        }
    }

    #[test]
    fn the_linear_reach_bounds_the_shift_of_the_farthest_surface() {
        let small = Vector6::new(0.0, 0.0, 0.01, 0.2, 0.0, 0.0);
        assert!(within_linear_reach(&small, 0.1));
        // A pair-to-pair change of KITTI's rotation rate: 11 cm at 30 m.
        let kitti = Vector6::new(0.03, -0.02, 0.0, 0.05, 0.0, 0.0);
        assert!(within_linear_reach(&kitti, 0.1));
        // 18 cm at 30 m: rendered again.
        let turn = Vector6::new(0.0, 0.0, 0.06, 0.0, 0.0, 0.0);
        assert!(!within_linear_reach(&turn, 0.1));
        let speed = Vector6::new(0.0, 0.0, 0.0, 1.6, 0.0, 0.0);
        assert!(!within_linear_reach(&speed, 0.1));
    }
}
