//! The LiDAR's motion over a pair estimated from the static world itself:
//! where a log has no gyro or no velocity source (KITTI `.bin` drives, most
//! converted logs), the previous scan is moved by a trial motion, rendered
//! into the current rays, and the motion corrected until the static surfaces
//! meet (point-to-plane alignment, linearised, robustly weighted so movers
//! and edges do not pull it).
//!
//! For a static surface with normal `n` (facing the sensor) seen along `e`
//! at `X = R e`, a small extra motion `(w, v)` over `dt` moves the surface by
//! `-(v + w x X) dt`, so the rendered range changes by
//!
//! ```text
//! dR = -dt ((X x n) . w + n . v) / (n . e)
//! ```
//!
//! Each trusted cell gives one equation `(n . e) (R_now - R_render) =
//! -dt ((X x n) . w + n . v)`, in metres along the normal; six unknowns,
//! solved by iteratively reweighted least squares.

mod linear;

use nalgebra::{Matrix6, Vector3, Vector6};
use rayon::prelude::*;

use super::config::EngineConfig;
use super::grid::ImageGeometry;
use super::surface::Surfaces;
use super::trajectory::{MotionModel, Trajectory};
use super::warp::{self, Rendered};
use crate::model::{PairMotion, ScanPair, StampNs, TimeSeries};

/// What was estimated for a pair, in the LiDAR frame at the current scan.
#[derive(Debug, Clone, Copy, PartialEq, serde::Serialize)]
pub struct EgoEstimate {
    pub velocity_mps: [f64; 3],
    pub angular_velocity_radps: [f64; 3],
    /// Cells whose equation took part (weight above one half).
    pub inlier_cells: usize,
    /// Robust scale of the remaining misfit along the normals, metres.
    pub residual_m: f64,
    /// The velocity came from the data (no velocity source covered the pair).
    pub velocity_estimated: bool,
    /// The angular velocity came from the data (no gyro or twist rate).
    pub rotation_estimated: bool,
    /// Covariance of (angular velocity, velocity), (rad/s, m/s)^2, robust to
    /// movers ([`Correction::covariance`]); zero rows and columns for what a
    /// source measured.
    pub covariance: [[f64; 6]; 6],
    /// Renders of the previous scan the estimate took.
    pub renders: usize,
}

impl EgoEstimate {
    /// The standard deviation of the static world's ray looming at a cell
    /// (return at `point_m`, surface normal `normal` facing the sensor, seen
    /// at `|n . e|` = `facing_cos`) that the estimate's uncertainty causes,
    /// 1/s: a motion error `(dw, dv)` moves the plane by `(X x n) . dw +
    /// n . dv` along its normal, that over `|n . e| R` along the ray.
    ///
    /// The quadratic form on the covariance as the estimate holds it,
    /// per cell: an nalgebra `Matrix6` built from it and nalgebra's generic
    /// products were 2 % of the braking KITTI log's run.
    #[inline]
    pub fn ray_looming_sigma_per_s(
        &self,
        point_m: Vector3<f64>,
        normal: Vector3<f64>,
        facing_cos: f64,
    ) -> f64 {
        let range_m = point_m.norm();
        if range_m <= 0.0 || facing_cos <= 0.0 {
            return f64::INFINITY;
        }
        let moment = point_m.cross(&normal);
        let gradient = [moment.x, moment.y, moment.z, normal.x, normal.y, normal.z];
        let variance = quadratic_form(&gradient, &self.covariance).max(0.0);
        variance.sqrt() / (facing_cos * range_m)
    }
}

/// `g^T C g`, summed in the order of nalgebra's `(g^T * C) * g` (each
/// entry of the row `g^T C`, then their products with `g`, left to right
/// from the first product): the same bits, in straight-line code.
#[inline]
fn quadratic_form(g: &[f64; 6], c: &[[f64; 6]; 6]) -> f64 {
    let entry = |j: usize| {
        let mut sum = g[0] * c[0][j];
        for i in 1..6 {
            sum += g[i] * c[i][j];
        }
        sum
    };
    let mut total = entry(0) * g[0];
    for (j, g_j) in g.iter().enumerate().skip(1) {
        total += entry(j) * g_j;
    }
    total
}

/// One cell's equation.
#[derive(Clone, Copy)]
struct Equation {
    /// `-dt (X x n, n)`.
    jacobian: Vector6<f64>,
    /// The azimuth sector the cell lies in: a mover or an artefact spans
    /// neighbouring cells whose misfits share one cause, so they count as one
    /// sample in the covariance.
    block: u32,
    /// `(n . e) (R_now - R_render)`, metres.
    misfit_m: f64,
}

/// What one alignment of a render gives.
#[derive(Debug, Clone, Copy)]
pub struct Correction {
    /// To add to the angular velocity the render was made with, rad/s.
    pub angular_radps: Vector3<f64>,
    /// To add to the velocity the render was made with, m/s.
    pub velocity_mps: Vector3<f64>,
    /// Cells whose equation took part (weight above one half).
    pub inlier_cells: usize,
    /// Robust scale of the misfit along the normals, metres.
    pub residual_m: f64,
    /// Covariance of the corrected motion (angular velocity, velocity):
    /// the sandwich `A^-1 B A^-1` of the weighted normal matrix `A` and the
    /// outer products `B` of each azimuth sector's summed score. Neighbouring
    /// cells on one mover (a car passing beside a stopped ego) all misfit
    /// the same way; counted as independent cells they would claim a
    /// precision of millimetres per second (50 000 equations), counted per
    /// sector the spread of the sectors shows how far such a group pulls the
    /// solution (Liang & Zeger's clustered errors; the linearised jackknife
    /// over sectors).
    pub covariance: Matrix6<f64>,
}

/// The correction to the motion the render was made with; `None` without
/// enough static surface to pin the motion down.
pub fn correction(
    current: &Surfaces,
    current_time_ns: &[StampNs],
    rendered: &Rendered,
    range_noise_m: f64,
    prior: &Prior,
) -> Option<Correction> {
    let equations = equations(current, current_time_ns, rendered);
    solve(&equations, &Vector6::zeros(), range_noise_m, prior).map(|s| s.correction(&equations))
}

/// One robust step's solution, with what its covariance is taken from
/// ([`Solved::correction`]): on a render only the last step's covariance
/// is asked for (a pass over every equation and the normal matrix's
/// inverse, in the estimate's serial code, which the other core waits on).
struct Solved {
    /// (angular, linear) velocity to add, the equations' order.
    solution: Vector6<f64>,
    inlier_cells: usize,
    residual_m: f64,
    misfits: Vec<f64>,
    weights: Vec<f64>,
    cholesky: nalgebra::Cholesky<f64, nalgebra::U6>,
}

impl Solved {
    /// The step as a [`Correction`], its covariance taken on `equations`
    /// (those it was solved on).
    fn correction(self, equations: &[Equation]) -> Correction {
        let s = self.solution;
        let covariance = clustered_covariance(
            (equations, &self.misfits),
            &self.weights,
            &s,
            &self.cholesky.inverse(),
        );
        Correction {
            angular_radps: Vector3::new(s[0], s[1], s[2]),
            velocity_mps: Vector3::new(s[3], s[4], s[5]),
            inlier_cells: self.inlier_cells,
            residual_m: self.residual_m,
            covariance,
        }
    }
}

/// The correction beyond `applied` (a correction already taken, not yet
/// rendered): each equation's misfit is first moved by it along its
/// linearisation, `misfit - J . applied`. Reweighting against these instead
/// of a new render is what lets one render serve several robust steps.
fn solve(
    equations: &[Equation],
    applied: &Vector6<f64>,
    range_noise_m: f64,
    prior: &Prior,
) -> Option<Solved> {
    if equations.len() < MIN_EQUATIONS {
        return None;
    }
    // Each misfit moved by what was applied (the equations themselves are
    // the render's, shared by every step on it).
    let misfits: Vec<f64> = equations
        .iter()
        .map(|eq| eq.misfit_m - eq.jacobian.dot(applied))
        .collect();
    let mut magnitudes: Vec<f64> = misfits.iter().map(|m| m.abs()).collect();
    let median = median_in_place(&mut magnitudes);
    // The scale of a static surface's misfit: no smaller than the noise.
    let scale = (1.4826 * median).max(2.0 * range_noise_m);
    // Cauchy weights: movers and unmasked edges count for little.
    let weights: Vec<f64> = misfits
        .iter()
        .map(|misfit_m| {
            let u = misfit_m / (CAUCHY_K * scale);
            1.0 / (1.0 + u * u)
        })
        .collect();
    let mut columns = [[0.0f64; 6]; 6];
    let mut rhs = [0.0f64; 6];
    let mut inliers = 0;
    for ((eq, &w), misfit_m) in equations.iter().zip(&weights).zip(&misfits) {
        if w > 0.5 {
            inliers += 1;
        }
        let j: [f64; 6] = eq.jacobian.into();
        add_weighted_outer_upper(&mut columns, &j, w);
        let weighted_m = misfit_m * w;
        for (sum, ji) in rhs.iter_mut().zip(j) {
            *sum += ji * weighted_m;
        }
    }
    // The upper triangle mirrored.
    let mut normal = Matrix6::from_fn(|i, k| columns[k.max(i)][k.min(i)]);
    let rhs = Vector6::from(rhs);
    // Damping: the motion along directions no surface constrains (a
    // corridor of road and side walls says nothing of forward motion) stays
    // at the trial value instead of wandering; a measured quantity is only
    // refined where the data overwhelm its source.
    let typical = normal.trace() / 6.0 + 1e-12;
    for k in 0..6 {
        let known = if k < 3 {
            prior.rotation_known
        } else {
            prior.velocity_known
        };
        normal[(k, k)] += typical * if known { KNOWN_WEIGHT } else { DAMPING };
    }
    let cholesky = normal.cholesky()?;
    let solution = cholesky.solve(&rhs);
    if !solution.iter().all(|x| x.is_finite()) {
        return None;
    }
    Some(Solved {
        solution,
        inlier_cells: inliers,
        residual_m: scale,
        misfits,
        weights,
        cholesky,
    })
}

/// `normal += j j^T w`, column by column of plain arrays: each entry the
/// same `(j_i j_k) w` the full product takes, so the sums are the same to
/// the bit. Only the entries on and above the diagonal are read (`solve`
/// mirrors them); the whole columns are summed as their fixed length lets
/// the compiler take four entries an instruction (a `Matrix6`'s 21
/// entries one by one, each loaded and stored again per equation, were a
/// fifth of the estimate's solves).
#[inline(always)]
fn add_weighted_outer_upper(columns: &mut [[f64; 6]; 6], j: &[f64; 6], w: f64) {
    for (k, column) in columns.iter_mut().enumerate() {
        for i in 0..6 {
            // The whole column (a fixed length the compiler widens); the
            // entries below the diagonal are not read.
            column[i] += j[i] * j[k] * w;
        }
    }
}

/// The sandwich covariance of the weighted least-squares `solution`, each
/// azimuth sector's equations one sample: `A^-1 (sum_b s_b s_b^T) A^-1 G/(G-1)`
/// with `s_b` the block's summed `w r J` (`r` the misfit left by the
/// solution) and `G` the sectors.
fn clustered_covariance(
    (equations, misfits): (&[Equation], &[f64]),
    weights: &[f64],
    solution: &Vector6<f64>,
    normal_inverse: &Matrix6<f64>,
) -> Matrix6<f64> {
    // Per sector, in sector order (so the sums, and the output, are the same
    // from run to run).
    let mut scores: Vec<Option<Vector6<f64>>> = vec![None; AZIMUTH_SECTORS];
    for ((eq, &w), misfit_m) in equations.iter().zip(weights).zip(misfits) {
        let left_m = misfit_m - eq.jacobian.dot(solution);
        let score = scores[eq.block as usize].get_or_insert_with(Vector6::zeros);
        *score += eq.jacobian * (w * left_m);
    }
    let blocks = scores.iter().flatten().count() as f64;
    if blocks < 2.0 {
        return Matrix6::from_element(f64::INFINITY);
    }
    let meat = scores
        .iter()
        .flatten()
        .fold(Matrix6::zeros(), |sum, s| sum + s * s.transpose());
    normal_inverse * meat * normal_inverse * (blocks / (blocks - 1.0))
}

/// Which parts of the motion a source measured: those stay as measured.
#[derive(Debug, Clone, Copy)]
pub struct Prior {
    pub rotation_known: bool,
    pub velocity_known: bool,
}

/// Prior weight of a measured quantity, relative to the data's typical weight.
const KNOWN_WEIGHT: f64 = 1e6;
/// Prior weight of an unmeasured quantity (damping only).
const DAMPING: f64 = 1e-6;
const MIN_EQUATIONS: usize = 200;
/// Cauchy constant (in robust sigmas).
const CAUCHY_K: f64 = 2.5;

fn equations(
    current: &Surfaces,
    current_time_ns: &[StampNs],
    rendered: &Rendered,
) -> Vec<Equation> {
    // On rayon's workers, in cell order (`collect` keeps it): built on one
    // core, the other waited (a twelfth of braking KITTI's idle core).
    (0..current.range_m.len())
        .into_par_iter()
        .filter_map(|cell| {
            let range_now = f64::from(current.range_m[cell]);
            let range_before = f64::from(rendered.range_m[cell]);
            if !(range_now.is_finite() && range_before.is_finite())
                || current.edge[cell]
                || rendered.edge[cell]
            {
                return None;
            }
            let n = current.normal[cell];
            let n = Vector3::new(f64::from(n[0]), f64::from(n[1]), f64::from(n[2]));
            if n.norm_squared() < 0.5 {
                return None;
            }
            let d = current.direction[cell];
            let e = Vector3::new(f64::from(d[0]), f64::from(d[1]), f64::from(d[2]));
            let facing = n.dot(&e);
            if facing.abs() < MIN_INCIDENCE_COS {
                return None;
            }
            let dt_s = (current_time_ns[cell] - rendered.source_time_ns[cell]) as f64 * 1e-9;
            if dt_s <= 0.0 {
                return None;
            }
            let x = e * range_now;
            let jacobian =
                -dt_s * Vector6::from_iterator(x.cross(&n).iter().chain(n.iter()).copied());
            let block = (cell % current.cols) * AZIMUTH_SECTORS / current.cols;
            Some(Equation {
                jacobian,
                block: block as u32,
                misfit_m: facing * (range_now - range_before),
            })
        })
        .collect()
}

/// The blocks of [`Equation::block`]: azimuth sectors of 11.25 degrees, all
/// beams (a car 5 m beside the sensor fills one or two).
const AZIMUTH_SECTORS: usize = 32;

/// Cells seen more obliquely than this take no part: their rendered range
/// is the least certain.
const MIN_INCIDENCE_COS: f64 = 0.2;

fn median_in_place(values: &mut [f64]) -> f64 {
    if values.is_empty() {
        return 0.0;
    }
    let mid = values.len() / 2;
    *values.select_nth_unstable_by(mid, f64::total_cmp).1
}

/// Renders of the previous scan tried to estimate the motion, at most.
const ESTIMATE_RENDERS: usize = 8;
/// Robust steps taken on one render, at most: each reweights the cells
/// against the misfits the steps before it left (linearised), so a render
/// serves the reweighting and the next render only corrects what the
/// linearisation missed (which surfaces the rays meet).
const STEPS_PER_RENDER: usize = 4;

/// Whether a correction is small against the estimate's own uncertainty:
/// every component within a fifth of its standard deviation. A render more
/// would move the estimate by less than it is known to (where movers pull
/// it, renders went on shifting it by noise up to the cap).
fn within_noise(correction: &Vector6<f64>, covariance: &Matrix6<f64>) -> bool {
    (0..6).all(|k| correction[k].abs() <= 0.2 * covariance[(k, k)].max(0.0).sqrt())
}

/// The robust steps taken on one render's `equations` until one is
/// `negligible`: their sum (angular, then linear velocity) and the last
/// step's fit. `None` when the first finds too little static surface.
fn steps_on_render(
    equations: &[Equation],
    range_noise_m: f64,
    prior: &Prior,
    negligible: impl Fn(&Vector6<f64>) -> bool,
) -> Option<(Vector6<f64>, Correction)> {
    let mut taken = Vector6::zeros();
    let mut last = None;
    for _ in 0..STEPS_PER_RENDER {
        let Some(step) = solve(equations, &taken, range_noise_m, prior) else {
            break;
        };
        let vector = step.solution;
        taken += vector;
        last = Some(step);
        if negligible(&vector) {
            break;
        }
    }
    last.map(|step| (taken, step.correction(equations)))
}

/// The pair's motion with what no source measured estimated from the static
/// world: the previous scan is rendered with a trial motion, corrected
/// until the static surfaces meet ([`correction`]). Constant over the pair.
#[allow(clippy::too_many_arguments)]
pub(super) fn estimate_motion(
    pair: &ScanPair,
    source: &warp::Source,
    target: &warp::Target,
    geometry: &ImageGeometry,
    (current, current_time): (&Surfaces, &[StampNs]),
    config: &EngineConfig,
    (start_ns, end_ns): (StampNs, StampNs),
    first_guess: Option<(Vector3<f64>, Vector3<f64>)>,
) -> Option<EstimatedMotion> {
    let stamp_ns = pair.current.stamp_ns;
    let measured = &pair.motion;
    let prior = Prior {
        rotation_known: measured.angular.is_some(),
        velocity_known: measured.velocity.is_some(),
    };
    let (guess_velocity, guess_angular) =
        first_guess.unwrap_or((Vector3::zeros(), Vector3::zeros()));
    let mut angular = measured
        .angular_velocity_at(stamp_ns)
        .unwrap_or(guess_angular);
    let mut velocity = measured.velocity_at(stamp_ns).unwrap_or(guess_velocity);
    let offset_ns = stamp_ns - pair.previous.stamp_ns;
    // Converged: a correction moves a surface 10 m away by less than a
    // millimetre.
    let dt_s = offset_ns as f64 * 1e-9;
    let negligible = |c: &Vector6<f64>| {
        (c.fixed_rows::<3>(3).norm() + c.fixed_rows::<3>(0).norm() * 10.0) * dt_s < 1e-3
    };
    let mut fit = None;
    let mut renders = 0;
    // The last render, while it was made with the motion estimated so far.
    let mut current_render = None;
    for _ in 0..ESTIMATE_RENDERS {
        let trial = with_constant_motion(measured, velocity, angular, start_ns, end_ns);
        let trajectory = Trajectory::integrate(&trial, MotionModel::Full, true, start_ns, end_ns)?;
        let rendered = warp::render(source, target, geometry, &trajectory, offset_ns);
        renders += 1;
        let Some((taken, last)) = steps_on_render(
            &equations(current, current_time, &rendered),
            config.range_noise_m,
            &prior,
            negligible,
        ) else {
            break;
        };
        let settled = negligible(&taken) || within_noise(&taken, &last.covariance);
        fit = Some(last);
        if settled {
            // The settled correction is below what the estimate is known
            // to, or a millimetre at 10 m: left out, so this render is the
            // one of the estimated motion and serves the pair's ego render.
            current_render = Some(rendered);
            break;
        }
        angular += taken.fixed_rows::<3>(0);
        velocity += taken.fixed_rows::<3>(3);
        if linear::within_linear_reach(&taken, dt_s) {
            // Small enough to take without rendering again: the render
            // carried to it serves the pair's ego render.
            current_render = Some(linear::corrected_render(
                rendered,
                current,
                current_time,
                &taken,
            ));
            break;
        }
    }
    let Correction {
        inlier_cells,
        residual_m,
        covariance,
        ..
    } = fit?;
    let motion = with_constant_motion(measured, velocity, angular, start_ns, end_ns);
    Some(EstimatedMotion {
        motion,
        rendered: current_render,
        estimate: EgoEstimate {
            velocity_mps: [velocity.x, velocity.y, velocity.z],
            angular_velocity_radps: [angular.x, angular.y, angular.z],
            inlier_cells,
            residual_m,
            velocity_estimated: !prior.velocity_known,
            rotation_estimated: !prior.rotation_known,
            covariance: unmeasured_covariance(&covariance, &prior),
            renders,
        },
    })
}

/// What [`estimate_motion`] gives.
pub(super) struct EstimatedMotion {
    /// The pair's motion, with what no source measured estimated.
    pub(super) motion: PairMotion,
    pub(super) estimate: EgoEstimate,
    /// The previous scan rendered with exactly `motion`, when the estimate
    /// settled on its last render (else one is still to make).
    pub(super) rendered: Option<Rendered>,
}

/// `covariance` with the rows and columns of what a source measured set to
/// zero (the estimate leaves those as measured; their error is the source's).
fn unmeasured_covariance(covariance: &Matrix6<f64>, prior: &Prior) -> [[f64; 6]; 6] {
    let estimated = |k: usize| {
        if k < 3 {
            !prior.rotation_known
        } else {
            !prior.velocity_known
        }
    };
    std::array::from_fn(|i| {
        std::array::from_fn(|j| {
            if estimated(i) && estimated(j) {
                covariance[(i, j)]
            } else {
                0.0
            }
        })
    })
}

/// `motion` with the series no source measured replaced by constants.
fn with_constant_motion(
    motion: &PairMotion,
    velocity: Vector3<f64>,
    angular: Vector3<f64>,
    start_ns: StampNs,
    end_ns: StampNs,
) -> PairMotion {
    let constant =
        |value: Vector3<f64>| TimeSeries::new(vec![(start_ns, value), (end_ns, value)], 1.0);
    PairMotion {
        velocity: Some(
            motion
                .velocity
                .clone()
                .unwrap_or_else(|| constant(velocity)),
        ),
        angular: Some(motion.angular.clone().unwrap_or_else(|| constant(angular))),
        ..motion.clone()
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::test_rng::SplitMix64;

    /// The straight-line quadratic form is nalgebra's `(g^T C) g` to the
    /// bit (the outputs of every log stay as they were).
    #[test]
    fn quadratic_form_is_nalgebras_to_the_bit() {
        let mut rng = SplitMix64(7);
        for _ in 0..10_000 {
            let g: [f64; 6] = std::array::from_fn(|_| rng.uniform(-50.0, 50.0));
            let c: [[f64; 6]; 6] =
                std::array::from_fn(|_| std::array::from_fn(|_| rng.uniform(-1e-2, 1e-2)));
            let (gv, cm) = (Vector6::from(g), Matrix6::from_fn(|i, j| c[i][j]));
            let nalgebra = (gv.transpose() * cm * gv)[(0, 0)];
            assert_eq!(quadratic_form(&g, &c).to_bits(), nalgebra.to_bits());
        }
    }

    /// The normal matrix summed column by column is nalgebra's sum of
    /// `j j^T w` to the bit, on and above the diagonal.
    #[test]
    fn the_normal_matrix_by_columns_is_the_outer_products_sum_to_the_bit() {
        let mut rng = SplitMix64(6);
        let mut columns = [[0.0f64; 6]; 6];
        let mut nalgebra = Matrix6::<f64>::zeros();
        for _ in 0..5_000 {
            let j: [f64; 6] = std::array::from_fn(|_| rng.uniform(-3.0, 3.0));
            let w = rng.uniform(0.0, 1.0);
            add_weighted_outer_upper(&mut columns, &j, w);
            let jv = Vector6::from(j);
            nalgebra += jv * jv.transpose() * w;
        }
        for k in 0..6 {
            for i in 0..=k {
                assert_eq!(columns[k][i].to_bits(), nalgebra[(i, k)].to_bits());
            }
        }
    }

    /// The steps on a render give the covariance of their last step, as a
    /// covariance taken at every step did (it is taken once, at the end).
    #[test]
    fn steps_on_a_render_carry_their_last_steps_covariance() {
        let mut rng = SplitMix64(26);
        let equations: Vec<Equation> = (0..2_000)
            .map(|k| Equation {
                jacobian: Vector6::from_fn(|_, _| rng.uniform(-1.0, 1.0)),
                block: (k % AZIMUTH_SECTORS) as u32,
                // Outliers one in ten: the reweighting moves the steps.
                misfit_m: rng.uniform(-0.02, 0.02) + if k % 10 == 0 { 0.5 } else { 0.0 },
            })
            .collect();
        let prior = Prior {
            rotation_known: false,
            velocity_known: false,
        };
        // Every step taken (none negligible), as in the render loop.
        let (taken, last) = steps_on_render(&equations, 0.01, &prior, |_| false).unwrap();
        let mut applied = Vector6::zeros();
        let mut every = None;
        for _ in 0..STEPS_PER_RENDER {
            let step = solve(&equations, &applied, 0.01, &prior).unwrap();
            applied += step.solution;
            every = Some(step.correction(&equations));
        }
        let every = every.unwrap();
        assert_eq!(taken, applied);
        assert_eq!(last.covariance, every.covariance);
        assert_eq!(last.velocity_mps, every.velocity_mps);
        // Not the first step's: the steps moved.
        let first = solve(&equations, &Vector6::zeros(), 0.01, &prior).unwrap();
        assert_ne!(first.correction(&equations).covariance, last.covariance);
    }
}
