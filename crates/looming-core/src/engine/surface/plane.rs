//! The linear algebra of the fits: scatter matrices, their eigenvalues
//! (without trigonometry), least-squares planes and lines.

use nalgebra::{Matrix3, Vector3};

/// Sum of the 2x2 principal minors of a symmetric matrix.
#[inline]
pub(super) fn principal_minors(a: &Matrix3<f64>) -> f64 {
    a[(0, 0)] * a[(1, 1)] - a[(0, 1)].powi(2) + a[(0, 0)] * a[(2, 2)] - a[(0, 2)].powi(2)
        + a[(1, 1)] * a[(2, 2)]
        - a[(1, 2)].powi(2)
}

/// How many eigenvalues of a symmetric matrix lie below `bound`: the sign
/// changes along 1 and the leading principal minors of `a - bound I`; None
/// where a minor is zero (or not finite), which the rule does not cover.
#[inline]
pub(super) fn eigenvalues_below(a: &Matrix3<f64>, bound: f64) -> Option<usize> {
    let b = a - Matrix3::identity() * bound;
    let minors = [
        1.0,
        b[(0, 0)],
        b[(0, 0)] * b[(1, 1)] - b[(0, 1)] * b[(1, 0)],
        b.determinant(),
    ];
    if minors[1..3].contains(&0.0) || !minors.iter().all(|m| m.is_finite()) {
        return None;
    }
    Some(
        minors
            .windows(2)
            .filter(|pair| (pair[0] < 0.0) != (pair[1] < 0.0))
            .count(),
    )
}

/// Centroid and scatter matrix (sum of outer products about it) of points.
/// The six distinct sums by hand: this runs for every window of every cell.
pub(super) fn scatter(points: &[Vector3<f64>]) -> (Vector3<f64>, Matrix3<f64>) {
    let centroid = points.iter().sum::<Vector3<f64>>() / points.len() as f64;
    let [mut xx, mut xy, mut xz, mut yy, mut yz, mut zz] = [0.0; 6];
    for p in points {
        let (x, y, z) = (p.x - centroid.x, p.y - centroid.y, p.z - centroid.z);
        xx += x * x;
        xy += x * y;
        xz += x * z;
        yy += y * y;
        yz += y * z;
        zz += z * z;
    }
    let covariance = Matrix3::new(xx, xy, xz, xy, yy, yz, xz, yz, zz);
    (centroid, covariance)
}

/// Least-squares line: unit direction and centroid; None for fewer than 3
/// points or no spread.
#[inline]
pub(super) fn fit_line(points: &[Vector3<f64>]) -> Option<(Vector3<f64>, Vector3<f64>)> {
    if points.len() < 3 {
        return None;
    }
    let (centroid, covariance) = scatter(points);
    let (_, _, largest) = symmetric_eigenvalues(&covariance)?;
    if !(largest.is_finite() && largest > 0.0) {
        return None;
    }
    let direction = null_vector(&(covariance - Matrix3::identity() * largest))?;
    Some((direction, centroid))
}

/// Least-squares plane: unit normal and centroid; None for fewer than 4 points
/// or points along a line.
#[cfg(test)]
pub(super) fn fit_plane(points: &[Vector3<f64>]) -> Option<(Vector3<f64>, Vector3<f64>)> {
    fit_plane_spread(points).map(|(n, c, _)| (n, c))
}

/// [`fit_plane`] plus the RMS spread of the points within the plane (the
/// smaller in-plane axis).
#[inline]
pub(in crate::engine) fn fit_plane_spread(
    points: &[Vector3<f64>],
) -> Option<(Vector3<f64>, Vector3<f64>, f64)> {
    if points.len() < 4 {
        return None;
    }
    let (centroid, covariance) = scatter(points);
    let plane = plane_of_scatter(points.len() as f64, centroid, &covariance)?;
    Some((plane.normal, plane.centroid, plane.spread))
}

/// A plane fitted to `count` points by their centroid and scatter matrix.
pub(super) struct Plane {
    pub(super) normal: Vector3<f64>,
    pub(super) centroid: Vector3<f64>,
    /// RMS spread of the points within the plane (the smaller in-plane axis).
    pub(super) spread: f64,
    /// Smallest eigenvalue of the scatter: the sum of the points' squared
    /// distances to the plane.
    pub(super) smallest: f64,
}

/// The plane of `count` points with `centroid` and scatter `covariance`;
/// None where they lie along a line (or the scatter is not finite).
#[inline]
pub(super) fn plane_of_scatter(
    count: f64,
    centroid: Vector3<f64>,
    covariance: &Matrix3<f64>,
) -> Option<Plane> {
    let (smallest, middle, largest) = symmetric_eigenvalues(covariance)?;
    // Collinear points (one row only) do not define a plane.
    if largest.is_nan() || largest <= 0.0 || middle < 1e-3 * largest || !smallest.is_finite() {
        return None;
    }
    let normal = null_vector(&(covariance - Matrix3::identity() * smallest))?;
    Some(Plane {
        normal,
        centroid,
        spread: (middle.max(0.0) / count).sqrt(),
        smallest,
    })
}

/// Eigenvalues of a symmetric positive semi-definite 3x3 matrix (a scatter
/// matrix), ascending. The smallest by Newton's method on the characteristic
/// polynomial from 0: below the smallest root the polynomial is increasing
/// and concave, so the iteration climbs to it without overshooting, in two
/// or three steps for a plane (its smallest eigenvalue far below the
/// others); the other two from the trace and the sum of principal minors.
/// No trigonometry: this runs for every window of every cell (the closed
/// form's acos and cos were a tenth of the engine's time).
#[inline]
pub(super) fn symmetric_eigenvalues(a: &Matrix3<f64>) -> Option<(f64, f64, f64)> {
    let trace = a.trace();
    let minors = principal_minors(a);
    let det = a.determinant();
    if !(trace.is_finite() && minors.is_finite() && det.is_finite()) {
        return None;
    }
    let mut smallest = 0.0f64;
    if minors > 0.0 && det > 0.0 {
        // The first step from 0 by hand (the polynomial is -det there, its
        // slope `minors`): the same bits, without its products.
        smallest = det / minors;
        if smallest > NEWTON_CONVERGED * trace {
            smallest = newton_from(smallest, (trace, minors, det), NEWTON_CONVERGED);
        }
    }
    // The other two: sum `trace - smallest`, product `minors - smallest * sum`.
    let sum = trace - smallest;
    let product = minors - smallest * sum;
    let half_gap = (0.25 * sum * sum - product).max(0.0).sqrt();
    let middle = 0.5 * sum - half_gap;
    let largest = 0.5 * sum + half_gap;
    Some((smallest, middle.max(smallest), largest))
}

/// Newton's iteration for the smallest root of the characteristic
/// polynomial `-x^3 + trace x^2 - minors x + det` (sign flipped), from
/// `start`, below it, until a step falls below `converged` of the trace.
pub(super) fn newton_from(
    start: f64,
    (trace, minors, det): (f64, f64, f64),
    converged: f64,
) -> f64 {
    let mut smallest = start;
    for _ in 1..NEWTON_STEPS {
        let value = ((smallest - trace) * smallest + minors) * smallest - det;
        let slope = (3.0 * smallest - 2.0 * trace) * smallest + minors;
        if slope <= 0.0 {
            break;
        }
        let step = value / slope;
        smallest -= step;
        // Converged: the error left after a step is about its square
        // over the middle eigenvalue (at least 1e-3 of the trace for a
        // plane), so a step of 1e-10 of the trace leaves under 1e-16 of
        // it, and the step that would show as much is not taken.
        if step.abs() <= converged * trace {
            break;
        }
    }
    smallest
}

/// Newton steps at most for the smallest eigenvalue (a plane needs 2-3; two
/// equal small eigenvalues, a line, converge linearly).
const NEWTON_STEPS: usize = 30;

/// A Newton step below this fraction of the trace ends the iteration.
const NEWTON_CONVERGED: f64 = 1e-10;

/// A unit vector in the null space of a (nearly) singular symmetric matrix: the
/// largest cross product of two of its rows.
#[inline]
fn null_vector(m: &Matrix3<f64>) -> Option<Vector3<f64>> {
    let rows = [
        Vector3::new(m[(0, 0)], m[(0, 1)], m[(0, 2)]),
        Vector3::new(m[(1, 0)], m[(1, 1)], m[(1, 2)]),
        Vector3::new(m[(2, 0)], m[(2, 1)], m[(2, 2)]),
    ];
    let candidates = [
        rows[0].cross(&rows[1]),
        rows[0].cross(&rows[2]),
        rows[1].cross(&rows[2]),
    ];
    // The largest (the last of equals, in total order), without an iterator.
    let mut best = 0;
    let mut best_norm_squared = candidates[0].norm_squared();
    for (k, candidate) in candidates.iter().enumerate().skip(1) {
        let norm_squared = candidate.norm_squared();
        if norm_squared.total_cmp(&best_norm_squared).is_ge() {
            (best, best_norm_squared) = (k, norm_squared);
        }
    }
    let norm = best_norm_squared.sqrt();
    (norm > 0.0 && norm.is_finite()).then(|| candidates[best] / norm)
}
