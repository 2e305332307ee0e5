//! A fast `atan2` for the engine's angles: every return's azimuth and
//! elevation, every cell's, every rendered vertex's. libm's `atan2` is
//! correctly rounded and costs about 16 ns (a call the compiler cannot
//! inline or vectorise, with rounding-mode saves around it): 7 % of a
//! 64 x 2048 run. This one is within 1e-12 rad of it (a test over every
//! quadrant and both axes), far below the 3e-3 rad between columns, and a
//! few inlined multiplications and one division.

use std::f64::consts::{FRAC_PI_2, FRAC_PI_4, PI};

/// `tan(pi / 8)`: the reduced argument's bound.
const TAN_PI_8: f64 = 0.414_213_562_373_095_03;

/// `atan(u) / u` as a polynomial in `u^2` on `|u| <= tan(pi/8)`: the
/// interpolant at 8 Chebyshev nodes (computed to 50 digits; the largest
/// error of `u P(u^2)` against `atan(u)` there is 3e-13).
const ATAN_OVER_U: [f64; 8] = [
    0.999_999_999_999_244_7,
    -0.333_333_332_769_224_94,
    0.199_999_930_535_558_15,
    -0.142_853_865_537_521_39,
    0.111_034_569_089_474_64,
    -0.089_925_529_061_509_12,
    0.069_741_976_865_952_65,
    -0.037_655_106_012_914_02,
];

/// `atan(u)` for `|u| <= tan(pi / 8)`. The polynomial by Estrin's scheme
/// (pairs, then pairs of pairs): three multiplications deep instead of
/// Horner's eight, as the callers' loops wait on each angle.
#[inline]
fn atan_reduced(u: f64) -> f64 {
    let c = &ATAN_OVER_U;
    let s = u * u;
    let s2 = s * s;
    let s4 = s2 * s2;
    let low = (c[0] + c[1] * s) + s2 * (c[2] + c[3] * s);
    let high = (c[4] + c[5] * s) + s2 * (c[6] + c[7] * s);
    u * (low + s4 * high)
}

/// `y.atan2(x)` for finite `x` and `y` (the signs of zeros as libm's; NaN
/// in, NaN out; not for infinities), within 1e-12 rad of it. One division:
/// the octant's angle is `atan` of the smaller coordinate over the larger,
/// or, within `pi / 8` of a diagonal, `pi / 4` plus `atan` of their
/// difference over their sum, so that the polynomial only spans
/// `|u| <= tan(pi / 8)`. Without branches ([`select`]): on points in no
/// particular order (a cell's neighbours, a render's vertices) the
/// octant's branches were mispredicted half the time, which made this
/// 2.4 times slower (29 ns against 12 per azimuth and elevation).
#[inline]
pub fn atan2(y: f64, x: f64) -> f64 {
    let (ax, ay) = (x.abs(), y.abs());
    let (low, high) = (ax.min(ay), ax.max(ay));
    let steep = ay > ax;
    let diagonal = low > TAN_PI_8 * high;
    let numerator = select(diagonal, ay - ax, low);
    let denominator = select(diagonal, ay + ax, high);
    // Both zero: 0 (libm's atan2(0, 0)), not 0 / 0 (a NaN fails the test).
    let reduced = atan_reduced(select(high == 0.0, 0.0, numerator / denominator));
    let base = select(diagonal, FRAC_PI_4, select(steep, FRAC_PI_2, 0.0));
    let first_quadrant = base + select(steep && !diagonal, -reduced, reduced);
    let half_turn = select(x.is_sign_negative(), PI - first_quadrant, first_quadrant);
    half_turn.copysign(y)
}

/// `if condition { a } else { b }` by masking the bits, which the compiler
/// cannot turn back into a branch.
#[inline]
fn select(condition: bool, a: f64, b: f64) -> f64 {
    let mask = 0u64.wrapping_sub(u64::from(condition));
    f64::from_bits((a.to_bits() & mask) | (b.to_bits() & !mask))
}

#[cfg(test)]
mod tests {
    use super::*;

    /// The largest difference from libm's `atan2` tolerated, radians.
    const TOLERANCE_RAD: f64 = 1e-12;

    fn check(y: f64, x: f64) {
        let (fast, libm) = (atan2(y, x), y.atan2(x));
        assert!(
            (fast - libm).abs() <= TOLERANCE_RAD,
            "atan2({y}, {x}): {fast} vs libm {libm} ({:e})",
            fast - libm
        );
    }

    #[test]
    fn matches_libm_on_a_fine_sweep_of_every_quadrant() {
        // A million directions around the circle at ranges from 1 mm to
        // 1 km, off the even angles (every octant boundary crossed).
        for k in 0..1_000_000u32 {
            let angle = -PI + TAU_STEP * (f64::from(k) + 0.37);
            let range = 10f64.powf(-3.0 + 6.0 * f64::from(k % 1013) / 1012.0);
            check(range * angle.sin(), range * angle.cos());
        }
    }

    const TAU_STEP: f64 = std::f64::consts::TAU / 1_000_000.0;

    #[test]
    fn matches_libm_on_the_axes_diagonals_and_octant_boundaries() {
        let exact = [0.0, 1.0, -1.0, 2.5, -2.5, 1e-300, -1e-300, 1e300, -1e300];
        for &y in &exact {
            for &x in &exact {
                check(y, x);
            }
        }
        // About the octant boundaries, where the reduction switches.
        for &ratio in &[TAN_PI_8, 1.0 / TAN_PI_8, 1.0] {
            for step in -5i32..=5 {
                let r = ratio * (1.0 + f64::from(step) * f64::EPSILON);
                for (sy, sx) in [(1.0, 1.0), (1.0, -1.0), (-1.0, 1.0), (-1.0, -1.0)] {
                    check(sy * r * 3.0, sx * 3.0);
                }
            }
        }
    }

    #[test]
    fn zeros_keep_their_signs_and_nan_stays_nan() {
        for (y, x) in [(0.0, 0.0), (-0.0, 0.0), (0.0, -0.0), (-0.0, -0.0)] {
            let (fast, libm) = (atan2(y, x), f64::atan2(y, x));
            assert_eq!(fast.to_bits(), libm.to_bits(), "atan2({y}, {x})");
        }
        assert!(atan2(f64::NAN, 1.0).is_nan());
        assert!(atan2(1.0, f64::NAN).is_nan());
    }

    #[test]
    fn random_points_of_a_lidar_scan_match_libm() {
        // f32 coordinates as the scans hold them, a simple LCG.
        let mut state = 0x2545_f491_4f6c_dd1du64;
        let mut next = || {
            state = state
                .wrapping_mul(6_364_136_223_846_793_005)
                .wrapping_add(1_442_695_040_888_963_407);
            (state >> 11) as f64 / (1u64 << 53) as f64 * 240.0 - 120.0
        };
        for _ in 0..200_000 {
            let (x, y, z) = (next() as f32, next() as f32, next() as f32);
            let (x, y, z) = (f64::from(x), f64::from(y), f64::from(z));
            check(y, x);
            check(z, (x * x + y * y).sqrt());
        }
    }
}
