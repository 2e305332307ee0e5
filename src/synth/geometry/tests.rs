//! Unit tests of the ray casting: each shape's hits, normals and misses.

use super::*;
use std::f64::consts::{FRAC_PI_2, PI};

use looming_core::test_rng::SplitMix64;

/// Unit direction from azimuth (about +z from +x) and elevation (from the
/// xy plane, positive up).
fn dir(azimuth_rad: f64, elevation_rad: f64) -> Vector3<f64> {
    Vector3::new(
        elevation_rad.cos() * azimuth_rad.cos(),
        elevation_rad.cos() * azimuth_rad.sin(),
        elevation_rad.sin(),
    )
}

fn ray(origin: [f64; 3], direction: [f64; 3]) -> Ray {
    Ray {
        origin: Point3::from(origin),
        direction: Vector3::from(direction).normalize(),
    }
}

fn unit_box(center: [f64; 3], half: [f64; 3], yaw_rad: f64) -> Shape {
    Shape::Box {
        center: Point3::from(center),
        half_extents_m: Vector3::from(half),
        yaw_rad,
    }
}

fn assert_close(actual: f64, expected: f64, tol: f64) {
    assert!(
        (actual - expected).abs() <= tol,
        "actual {actual} expected {expected} (diff {})",
        actual - expected
    );
}

fn assert_vec_close(actual: Vector3<f64>, expected: Vector3<f64>, tol: f64) {
    assert!(
        (actual - expected).norm() <= tol,
        "actual {actual:?} expected {expected:?}"
    );
}

/// Box-frame coordinates of a world point.
fn to_box_frame(shape: &Shape, p: Point3<f64>) -> Vector3<f64> {
    let Shape::Box {
        center, yaw_rad, ..
    } = shape
    else {
        unreachable!()
    };
    let r = p - center;
    let (s, c) = yaw_rad.sin_cos();
    Vector3::new(c * r.x + s * r.y, -s * r.x + c * r.y, r.z)
}

/// Signed depth of a point inside a shape (positive inside, negative
/// outside near the surface): a 1-Lipschitz function whose zero set is the
/// surface.
fn depth(shape: &Shape, p: Point3<f64>) -> f64 {
    match shape {
        Shape::Ground { height_m } => height_m - p.z,
        Shape::Box { half_extents_m, .. } => {
            let q = to_box_frame(shape, p);
            (0..3)
                .map(|i| half_extents_m[i] - q[i].abs())
                .fold(f64::INFINITY, f64::min)
        }
        Shape::Cylinder {
            base,
            radius_m,
            height_m,
        } => {
            let q = p - base;
            (radius_m - q.x.hypot(q.y)).min(q.z).min(height_m - q.z)
        }
    }
}

/// Checks that a hit lies on the surface, that the normal is unit, outward
/// at that point and faces the ray.
fn check_on_surface(shape: &Shape, r: &Ray, hit: &ShapeHit) {
    const TOL: f64 = 1e-9;
    let p = r.point_at(hit.range_m);
    assert!(hit.range_m.is_finite() && hit.range_m > 0.0);
    assert_close(hit.normal.norm(), 1.0, 1e-12);
    assert!(
        hit.normal.dot(&r.direction) <= 1e-12,
        "normal {:?} does not face the ray {r:?}",
        hit.normal
    );
    match shape {
        Shape::Ground { height_m } => {
            assert_close(p.z, *height_m, TOL);
            assert_eq!(hit.normal, Vector3::z());
        }
        Shape::Box {
            half_extents_m,
            yaw_rad,
            ..
        } => {
            let q = to_box_frame(shape, p);
            let (s, c) = yaw_rad.sin_cos();
            let n = hit.normal;
            let n_local = Vector3::new(c * n.x + s * n.y, -s * n.x + c * n.y, n.z);
            // The normal is a local axis; the point is on that face.
            let axis = n_local.iamax();
            assert_close(n_local[axis].abs(), 1.0, 1e-12);
            assert_close(q[axis], n_local[axis].signum() * half_extents_m[axis], TOL);
            for i in 0..3 {
                assert!(q[i].abs() <= half_extents_m[i] + TOL, "{q:?} outside");
            }
        }
        Shape::Cylinder {
            base,
            radius_m,
            height_m,
        } => {
            let q = p - base;
            let radial = q.x.hypot(q.y);
            assert!(radial <= radius_m + TOL && q.z >= -TOL && q.z <= height_m + TOL);
            if hit.normal.z == 1.0 {
                assert_close(q.z, *height_m, TOL);
            } else if hit.normal.z == -1.0 {
                assert_close(q.z, 0.0, TOL);
            } else {
                assert_eq!(hit.normal.z, 0.0);
                assert_close(radial, *radius_m, TOL);
                assert_vec_close(hit.normal, Vector3::new(q.x, q.y, 0.0) / radial, 1e-9);
            }
        }
    }
}

#[test]
fn ground_range_is_height_over_sine_of_depression() {
    for h in [0.5, 1.0, 1.8, 2.37, 10.0] {
        for i in 1..90 {
            let phi = -(i as f64) * PI / 180.0 * 0.999;
            for j in 0..36 {
                let theta = j as f64 * 10.0_f64.to_radians() - PI;
                let r = Ray {
                    origin: Point3::new(3.0, -7.0, h + 0.25),
                    direction: dir(theta, phi),
                };
                let ground = Shape::Ground { height_m: 0.25 };
                let hit = ground.intersect(&r, f64::INFINITY).unwrap();
                let expected = h / (-phi).sin();
                assert_close(hit.range_m, expected, 1e-12 * expected);
                assert_eq!(hit.normal, Vector3::z());
                check_on_surface(&ground, &r, &hit);
            }
        }
    }
}

#[test]
fn ground_misses_upward_parallel_below_and_beyond_max_range() {
    let ground = Shape::Ground { height_m: 0.0 };
    let o = [0.0, 0.0, 2.0];
    assert!(ground.intersect(&ray(o, [1.0, 0.0, 0.0]), 1e9).is_none());
    assert!(ground.intersect(&ray(o, [1.0, 0.0, 0.1]), 1e9).is_none());
    // Almost parallel: the hit is far beyond any finite max range.
    assert!(
        ground
            .intersect(&ray(o, [1.0, 0.0, -1e-300]), 1e9)
            .is_none()
    );
    // ... and not an infinite range with an infinite max range.
    if let Some(hit) = ground.intersect(&ray(o, [1.0, 0.0, -1e-300]), f64::INFINITY) {
        assert!(hit.range_m.is_finite());
    }
    // Max range: the hit at exactly 2 m is included, not at 1.999 m.
    let down = ray(o, [0.0, 0.0, -1.0]);
    assert_eq!(ground.intersect(&down, 2.0).unwrap().range_m, 2.0);
    assert!(ground.intersect(&down, 1.999).is_none());
    // Origin below ground or on it.
    assert!(
        ground
            .intersect(&ray([0.0, 0.0, -1.0], [0.0, 0.0, -1.0]), 1e9)
            .is_none()
    );
    assert!(
        ground
            .intersect(&ray([0.0, 0.0, -1.0], [0.0, 0.0, 1.0]), 1e9)
            .is_none()
    );
    assert!(
        ground
            .intersect(&ray([0.0, 0.0, 0.0], [0.0, 0.3, -1.0]), 1e9)
            .is_none()
    );
}

#[test]
fn wall_range_is_distance_over_cosines() {
    // A thin wall whose near face is the plane x = d, 40 m wide, 20 m tall.
    let d = 12.5;
    let thickness = 0.2;
    let wall = unit_box(
        [d + thickness / 2.0, 0.0, 0.0],
        [thickness / 2.0, 20.0, 10.0],
        0.0,
    );
    let mut hits = 0;
    for i in -20..=20 {
        let phi = i as f64 * 1.5_f64.to_radians();
        for j in -30..=30 {
            let theta = j as f64 * 1.5_f64.to_radians();
            let r = Ray {
                origin: Point3::origin(),
                direction: dir(theta, phi),
            };
            let expected = d / (phi.cos() * theta.cos());
            let p = r.point_at(expected);
            let inside_face = p.y.abs() < 20.0 && p.z.abs() < 10.0;
            match wall.intersect(&r, 1000.0) {
                Some(hit) => {
                    assert!(inside_face);
                    assert_close(hit.range_m, expected, 1e-12 * expected);
                    assert_vec_close(hit.normal, -Vector3::x(), 0.0);
                    check_on_surface(&wall, &r, &hit);
                    hits += 1;
                }
                None => assert!(!inside_face, "missed {r:?}"),
            }
        }
    }
    assert!(hits > 1500);
}

#[test]
fn box_hit_from_each_side_has_that_sides_normal() {
    let center = [5.0, -2.0, 1.0];
    let half = [1.0, 2.0, 0.5];
    let shape = unit_box(center, half, 0.0);
    let dist = 10.0;
    for axis in 0..3 {
        for sign in [1.0, -1.0] {
            let mut origin = center;
            origin[axis] += sign * dist;
            let mut direction = [0.0; 3];
            direction[axis] = -sign;
            let r = ray(origin, direction);
            let hit = shape.intersect(&r, 100.0).unwrap();
            assert_eq!(hit.range_m, dist - half[axis]);
            let mut normal = Vector3::zeros();
            normal[axis] = sign;
            assert_eq!(hit.normal, normal);
            check_on_surface(&shape, &r, &hit);
        }
    }
}

#[test]
fn yawed_box_hand_computed() {
    // A 2 m cube (half extents 1) at the origin yawed 30 degrees, hit by a
    // ray along -x from (10, 0, 0). The +x face is the line through
    // (cos30, sin30) with normal (cos30, sin30): n.(p) = 1. On y = 0,
    // x * cos30 = 1, so x = 1 / cos30 and the range is 10 - 1 / cos30.
    let yaw = 30.0_f64.to_radians();
    let shape = unit_box([0.0, 0.0, 0.0], [1.0, 1.0, 1.0], yaw);
    let r = ray([10.0, 0.0, 0.0], [-1.0, 0.0, 0.0]);
    let hit = shape.intersect(&r, 100.0).unwrap();
    let c30 = 3.0_f64.sqrt() / 2.0;
    assert_close(hit.range_m, 10.0 - 1.0 / c30, 1e-12);
    assert_vec_close(hit.normal, Vector3::new(c30, 0.5, 0.0), 1e-12);
    check_on_surface(&shape, &r, &hit);

    // Along -y from (0, 10, 0): the +y face has normal (-sin30, cos30),
    // y * cos30 = 1 on x = 0.
    let r = ray([0.0, 10.0, 0.0], [0.0, -1.0, 0.0]);
    let hit = shape.intersect(&r, 100.0).unwrap();
    assert_close(hit.range_m, 10.0 - 1.0 / c30, 1e-12);
    assert_vec_close(hit.normal, Vector3::new(-0.5, c30, 0.0), 1e-12);

    // Aimed at a corner: the +x/+y corner is at R(30)(1, 1) =
    // (c30 - 0.5, 0.5 + c30). A ray from far along the diagonal of the
    // box frame through the corner grazes it.
    let corner = Vector3::new(c30 - 0.5, 0.5 + c30, 0.0);
    let away = Vector3::new(c30 - 0.5, 0.5 + c30, 0.0).normalize();
    let origin = Point3::from(corner + away * 5.0);
    let r = Ray {
        origin,
        direction: -away,
    };
    let hit = shape.intersect(&r, 100.0).unwrap();
    assert_close(hit.range_m, 5.0, 1e-9);
    check_on_surface(&shape, &r, &hit);
}

#[test]
fn cylinder_side_straight_on_and_oblique() {
    let (radius, height) = (0.15, 4.0);
    let pole = Shape::Cylinder {
        base: Point3::new(20.0, 3.0, 0.0),
        radius_m: radius,
        height_m: height,
    };
    // Straight on from distance D to the axis: range D - r.
    for d in [1.0, 5.0, 20.0, 150.0] {
        let r = ray([20.0 - d, 3.0, 1.5], [1.0, 0.0, 0.0]);
        let hit = pole.intersect(&r, 1000.0).unwrap();
        assert_close(hit.range_m, d - radius, 1e-12 * d);
        assert_vec_close(hit.normal, -Vector3::x(), 1e-12);
        check_on_surface(&pole, &r, &hit);
    }
    // Oblique, hand computed: cylinder radius 1 at the origin, ray along
    // +x at y = 0.6 from x = -10 climbing 0.5 m per metre of horizontal
    // travel. The side is reached where x = -sqrt(1 - 0.36) = -0.8, after
    // 9.2 m horizontally, so range = 9.2 * sqrt(1 + 0.25).
    let unit = Shape::Cylinder {
        base: Point3::new(0.0, 0.0, 0.0),
        radius_m: 1.0,
        height_m: 10.0,
    };
    let r = ray([-10.0, 0.6, 0.5], [1.0, 0.0, 0.5]);
    let hit = unit.intersect(&r, 100.0).unwrap();
    assert_close(hit.range_m, 9.2 * 1.25_f64.sqrt(), 1e-12);
    assert_vec_close(hit.normal, Vector3::new(-0.8, 0.6, 0.0), 1e-12);
    check_on_surface(&unit, &r, &hit);
    // Same ray but the cylinder is only 4 m tall: at x = -0.8 the ray is at
    // z = 0.5 + 4.6 = 5.1, above the top, so it misses.
    let short = Shape::Cylinder {
        base: Point3::origin(),
        radius_m: 1.0,
        height_m: 4.0,
    };
    assert!(short.intersect(&r, 100.0).is_none());
    // Tangent ray (y = radius) grazes at x = 0, range 10.
    let r = ray([-10.0, 1.0, 0.5], [1.0, 0.0, 0.0]);
    let hit = unit.intersect(&r, 100.0).unwrap();
    assert_close(hit.range_m, 10.0, 1e-9);
    assert!(
        unit.intersect(&ray([-10.0, 1.0 + 1e-9, 0.5], [1.0, 0.0, 0.0]), 100.0)
            .is_none()
    );
}

#[test]
fn cylinder_caps() {
    let pole = Shape::Cylinder {
        base: Point3::new(2.0, 1.0, -1.0),
        radius_m: 0.5,
        height_m: 3.0,
    };
    // Straight down onto the top (z = 2) from z = 7.
    let r = ray([2.1, 0.8, 7.0], [0.0, 0.0, -1.0]);
    let hit = pole.intersect(&r, 100.0).unwrap();
    assert_eq!(hit.range_m, 5.0);
    assert_eq!(hit.normal, Vector3::z());
    check_on_surface(&pole, &r, &hit);
    // Oblique from above: 45 degrees down along +x from (0, 1, 4): reaches
    // z = 2 after 2 m horizontally at x = 2 (the axis), range 2 sqrt 2.
    let r = ray([0.0, 1.0, 4.0], [1.0, 0.0, -1.0]);
    let hit = pole.intersect(&r, 100.0).unwrap();
    assert_close(hit.range_m, 2.0 * 2.0_f64.sqrt(), 1e-12);
    assert_eq!(hit.normal, Vector3::z());
    check_on_surface(&pole, &r, &hit);
    // From below onto the bottom cap (z = -1).
    let r = ray([2.0, 1.2, -4.0], [0.0, 0.0, 1.0]);
    let hit = pole.intersect(&r, 100.0).unwrap();
    assert_eq!(hit.range_m, 3.0);
    assert_eq!(hit.normal, -Vector3::z());
    // Vertical ray just outside the radius misses.
    assert!(
        pole.intersect(&ray([2.5001, 1.0, 7.0], [0.0, 0.0, -1.0]), 100.0)
            .is_none()
    );
}

#[test]
fn origin_inside_gives_none() {
    let cube = unit_box([0.0, 0.0, 0.0], [1.0, 1.0, 1.0], 0.3);
    let pole = Shape::Cylinder {
        base: Point3::new(0.0, 0.0, -1.0),
        radius_m: 1.0,
        height_m: 2.0,
    };
    let mut rng = SplitMix64(7);
    for _ in 0..1000 {
        let d = Vector3::new(
            rng.uniform(-1.0, 1.0),
            rng.uniform(-1.0, 1.0),
            rng.uniform(-1.0, 1.0),
        );
        let r = Ray::new(Point3::new(0.1, -0.2, 0.3), d).unwrap();
        assert!(cube.intersect(&r, 100.0).is_none());
        assert!(pole.intersect(&r, 100.0).is_none());
    }
    // On the surface, pointing in or out: no hit either (range must be > 0).
    assert!(
        cube.intersect(&ray([0.0, 0.0, 1.0], [0.0, 0.0, -1.0]), 9.0)
            .is_none()
    );
    assert!(
        cube.intersect(&ray([0.0, 0.0, 1.0], [0.0, 0.0, 1.0]), 9.0)
            .is_none()
    );
    // In a scene, the containing object is skipped but others are hit.
    let scene = SceneSnapshot::new(vec![
        SceneObject {
            shape: Shape::Ground { height_m: -1.0 },
            object_id: 0,
            moving: false,
        },
        SceneObject {
            shape: cube.clone(),
            object_id: 3,
            moving: true,
        },
    ]);
    let hit = scene
        .cast(&ray([0.0, 0.0, 0.0], [0.0, 0.0, -1.0]), 10.0)
        .unwrap();
    assert_eq!((hit.object_index, hit.range_m), (0, 1.0));
}

#[test]
fn degenerate_and_parallel_rays_give_none() {
    let shapes = [
        Shape::Ground { height_m: 0.0 },
        unit_box([5.0, 0.0, 1.0], [1.0, 1.0, 1.0], 0.0),
        unit_box([5.0, 0.0, 1.0], [1.0, 1.0, 1.0], 0.7),
        Shape::Cylinder {
            base: Point3::new(5.0, 0.0, 0.0),
            radius_m: 1.0,
            height_m: 2.0,
        },
    ];
    let scene = SceneSnapshot::new(
        shapes
            .iter()
            .map(|s| SceneObject {
                shape: s.clone(),
                object_id: 0,
                moving: false,
            })
            .collect(),
    );
    let nan = f64::NAN;
    let inf = f64::INFINITY;
    let bad = [
        ([0.0, 0.0, 1.0], [0.0, 0.0, 0.0]),
        ([0.0, 0.0, 1.0], [nan, 0.0, -1.0]),
        ([0.0, 0.0, 1.0], [1.0, inf, -1.0]),
        ([0.0, 0.0, 1.0], [1e-200, 0.0, -1e-200]),
        ([nan, 0.0, 1.0], [1.0, 0.0, -0.1]),
        ([0.0, 0.0, inf], [1.0, 0.0, -0.1]),
    ];
    for (o, d) in bad {
        let r = Ray {
            origin: Point3::from(o),
            direction: Vector3::from(d),
        };
        assert!(Ray::new(r.origin, r.direction).is_none());
        assert!(scene.cast(&r, 100.0).is_none());
        for s in &shapes {
            assert!(s.intersect(&r, 100.0).is_none());
        }
    }
    // Bad max ranges.
    let good = ray([0.0, 0.0, 1.0], [1.0, 0.0, -0.05]);
    for max in [0.0, -1.0, nan, -inf] {
        assert!(scene.cast(&good, max).is_none());
    }
    assert!(scene.cast(&good, 100.0).is_some());
    // Parallel to the ground, and parallel to box faces but outside their
    // slab (above the box, beside it).
    let over = ray([0.0, 0.0, 2.5], [1.0, 0.0, 0.0]);
    let beside = ray([0.0, 1.5, 1.0], [1.0, 0.0, 0.0]);
    for r in [over, beside] {
        for s in &shapes {
            assert!(s.intersect(&r, 100.0).is_none(), "{s:?} {r:?}");
        }
    }
    // Parallel to the faces and sliding exactly along the top face: a
    // grazing hit on the near edge of the axis-aligned box, range 4.
    let graze = ray([0.0, 0.0, 2.0], [1.0, 0.0, 0.0]);
    let hit = shapes[1].intersect(&graze, 100.0).unwrap();
    assert_eq!(hit.range_m, 4.0);
    assert_eq!(hit.normal, -Vector3::x());
    // A non-unit direction is normalised: ranges stay in metres.
    let long = Ray {
        origin: Point3::new(0.0, 0.0, 1.0),
        direction: Vector3::new(7.0, 0.0, 0.0),
    };
    assert_eq!(shapes[1].intersect(&long, 100.0).unwrap().range_m, 4.0);
}

#[test]
fn invalid_shapes_are_never_hit() {
    let r = ray([0.0, 0.0, 1.0], [1.0, 0.0, 0.0]);
    let invalid = [
        Shape::Ground { height_m: f64::NAN },
        unit_box([5.0, 0.0, 1.0], [-1.0, 1.0, 1.0], 0.0),
        unit_box([5.0, 0.0, 1.0], [1.0, 1.0, 1.0], f64::NAN),
        unit_box([5.0, f64::INFINITY, 1.0], [1.0, 1.0, 1.0], 0.0),
        Shape::Cylinder {
            base: Point3::new(5.0, 0.0, 0.0),
            radius_m: 0.0,
            height_m: 2.0,
        },
        Shape::Cylinder {
            base: Point3::new(5.0, 0.0, 0.0),
            radius_m: 1.0,
            height_m: f64::NAN,
        },
    ];
    for s in &invalid {
        assert!(s.intersect(&r, 100.0).is_none());
        assert!(s.bounding_sphere().is_none());
    }
}

#[test]
fn bounding_spheres() {
    assert!(Shape::Ground { height_m: 0.0 }.bounding_sphere().is_none());
    let (c, r) = unit_box([1.0, 2.0, 3.0], [2.0, 3.0, 6.0], 1.0)
        .bounding_sphere()
        .unwrap();
    assert_eq!((c, r), (Point3::new(1.0, 2.0, 3.0), 7.0));
    let (c, r) = Shape::Cylinder {
        base: Point3::new(1.0, 2.0, 3.0),
        radius_m: 3.0,
        height_m: 8.0,
    }
    .bounding_sphere()
    .unwrap();
    assert_eq!((c, r), (Point3::new(1.0, 2.0, 7.0), 5.0));
}

fn object(shape: Shape, object_id: u32) -> SceneObject {
    SceneObject {
        shape,
        object_id,
        moving: object_id > 0,
    }
}

#[test]
fn nearest_of_several_ties_to_lower_index_and_max_range() {
    let scene = SceneSnapshot::new(vec![
        object(Shape::Ground { height_m: 0.0 }, 0),
        object(unit_box([30.0, 0.0, 1.0], [0.5, 2.0, 1.0], 0.0), 0),
        object(unit_box([10.0, 0.0, 1.0], [0.5, 2.0, 1.0], 0.0), 7),
        // Same near face (x = 9.5) as object 2: a tie.
        object(unit_box([10.5, 0.0, 1.0], [1.0, 1.0, 1.0], 0.0), 8),
        object(
            Shape::Cylinder {
                base: Point3::new(20.0, 0.0, 0.0),
                radius_m: 0.3,
                height_m: 5.0,
            },
            0,
        ),
    ]);
    let r = ray([0.0, 0.0, 1.0], [1.0, 0.0, 0.0]);
    let hit = scene.cast(&r, 100.0).unwrap();
    assert_eq!(
        hit,
        Hit {
            range_m: 9.5,
            normal: -Vector3::x(),
            object_index: 2,
            object_id: 7,
            moving: true,
        }
    );
    // Max range cuts at exactly 9.5 (inclusive).
    assert_eq!(scene.cast(&r, 9.5).unwrap().object_index, 2);
    assert!(scene.cast(&r, 9.4999).is_none());
    // Reversed order: the tie now goes to the other box (lower index).
    let mut objects = scene.objects().to_vec();
    objects.swap(2, 3);
    let swapped = SceneSnapshot::new(objects);
    let hit = swapped.cast(&r, 100.0).unwrap();
    assert_eq!((hit.object_index, hit.object_id, hit.range_m), (2, 8, 9.5));
    // Over the boxes (z = 2.5): the pole, then the far box are behind.
    let r = ray([0.0, 0.0, 2.5], [1.0, 0.0, 0.0]);
    let hit = scene.cast(&r, 100.0).unwrap();
    assert_eq!(hit.object_index, 4);
    assert_close(hit.range_m, 19.7, 1e-12);
    // Going down: ground wins before any object.
    let r = ray([0.0, 0.0, 1.0], [1.0, 0.0, -0.5]);
    let hit = scene.cast(&r, 100.0).unwrap();
    assert_eq!(hit.object_index, 0);
    assert_close(hit.range_m, 1.25_f64.sqrt() * 2.0, 1e-12);
}

fn random_shape(rng: &mut SplitMix64) -> Shape {
    if rng.next_u64().is_multiple_of(2) {
        Shape::Box {
            center: Point3::new(
                rng.uniform(-10.0, 10.0),
                rng.uniform(-10.0, 10.0),
                rng.uniform(0.0, 3.0),
            ),
            half_extents_m: Vector3::new(
                rng.uniform(0.05, 3.0),
                rng.uniform(0.05, 3.0),
                rng.uniform(0.05, 3.0),
            ),
            yaw_rad: rng.uniform(-PI, PI),
        }
    } else {
        Shape::Cylinder {
            base: Point3::new(
                rng.uniform(-10.0, 10.0),
                rng.uniform(-10.0, 10.0),
                rng.uniform(-1.0, 2.0),
            ),
            radius_m: rng.uniform(0.05, 2.0),
            height_m: rng.uniform(0.1, 6.0),
        }
    }
}

/// Random rays against random shapes: hits lie on the surface, with a
/// valid normal, and no sampled point of the ray before the hit (or of the
/// whole ray for a miss) is deep inside the shape.
#[test]
fn property_hits_lie_on_the_surface_and_nothing_is_skipped() {
    let mut rng = SplitMix64(0x5EED);
    let (mut hits, mut misses) = (0, 0);
    for _ in 0..4000 {
        let shape = random_shape(&mut rng);
        let (center, radius) = shape.bounding_sphere().unwrap();
        let origin = Point3::new(
            rng.uniform(-25.0, 25.0),
            rng.uniform(-25.0, 25.0),
            rng.uniform(-3.0, 8.0),
        );
        if depth(&shape, origin) >= 0.0 {
            continue;
        }
        // Aim near the shape so that about half the rays hit; sometimes
        // along exact axes or horizontally, to exercise parallel cases.
        let target = center
            + Vector3::new(
                rng.uniform(-0.6, 0.6),
                rng.uniform(-0.6, 0.6),
                rng.uniform(-0.6, 0.6),
            ) * radius;
        let mut direction = target - origin;
        match rng.next_u64() % 8 {
            0 => direction.z = 0.0,
            1 => {
                direction.x = 0.0;
                direction.y = 0.0;
            }
            _ => {}
        }
        let Some(r) = Ray::new(origin, direction) else {
            continue;
        };
        let max_range_m = 200.0;
        // The part of the ray inside the bounding sphere, where samples
        // are needed.
        let to_center = center - origin;
        let along = to_center.dot(&r.direction);
        let off_sq = to_center.norm_squared() - along * along;
        let half_chord = (radius * radius - off_sq).max(0.0).sqrt();
        let (seg_lo, seg_hi) = ((along - half_chord).max(0.0), (along + half_chord).max(0.0));
        let result = shape.intersect(&r, max_range_m);
        let sample_end = match &result {
            Some(hit) => {
                check_on_surface(&shape, &r, hit);
                // Just after entering, the ray is not outside (beyond
                // rounding), unless it only grazed.
                assert!(depth(&shape, r.point_at(hit.range_m + 1e-7)) > -1e-9);
                hits += 1;
                hit.range_m.min(seg_hi)
            }
            None => {
                misses += 1;
                seg_hi
            }
        };
        // Depth is 1-Lipschitz, so a step of 5 mm with a 5 mm threshold
        // catches any passage more than 1 cm deep.
        let step = 0.005;
        let mut t = seg_lo;
        while t < sample_end {
            assert!(
                depth(&shape, r.point_at(t)) < step,
                "{shape:?} {r:?} {result:?}: inside at {t}"
            );
            t += step;
        }
    }
    assert!(hits > 1000 && misses > 1000, "{hits} hits, {misses} misses");
}

/// The scene cast agrees with a brute-force minimum over
/// `Shape::intersect`, including the tie rule and the sphere early-out.
#[test]
fn property_cast_matches_brute_force() {
    let mut rng = SplitMix64(42);
    let mut objects: Vec<SceneObject> = (0..60)
        .map(|i| object(random_shape(&mut rng), i % 3))
        .collect();
    objects.insert(0, object(Shape::Ground { height_m: 0.0 }, 0));
    // Duplicates create exact ties.
    objects.push(objects[5].clone());
    objects.push(objects[9].clone());
    let scene = SceneSnapshot::new(objects.clone());
    let mut hits = 0;
    for _ in 0..20000 {
        let origin = Point3::new(
            rng.uniform(-30.0, 30.0),
            rng.uniform(-30.0, 30.0),
            rng.uniform(0.1, 6.0),
        );
        let direction = dir(rng.uniform(-PI, PI), rng.uniform(-FRAC_PI_2, FRAC_PI_2));
        let r = Ray { origin, direction };
        let max_range_m = rng.uniform(1.0, 80.0);
        let mut expected: Option<Hit> = None;
        for (index, o) in objects.iter().enumerate() {
            if let Some(h) = o.shape.intersect(&r, max_range_m)
                && expected.is_none_or(|e| h.range_m < e.range_m)
            {
                expected = Some(Hit {
                    range_m: h.range_m,
                    normal: h.normal,
                    object_index: index,
                    object_id: o.object_id,
                    moving: o.moving,
                });
            }
        }
        let actual = scene.cast(&r, max_range_m);
        assert_eq!(actual, expected, "{r:?}");
        hits += actual.is_some() as usize;
    }
    assert!(hits > 5000, "{hits} hits");
}

/// A road scene: 1 ground + 40 boxes + 10 cylinders around a sensor.
fn benchmark_scene() -> SceneSnapshot {
    let mut rng = SplitMix64(2024);
    let mut objects = vec![object(Shape::Ground { height_m: 0.0 }, 0)];
    for i in 0..40 {
        let along = rng.uniform(-80.0, 80.0);
        let side = if i % 2 == 0 { 1.0 } else { -1.0 };
        objects.push(object(
            Shape::Box {
                center: Point3::new(along, side * rng.uniform(4.0, 25.0), 1.0),
                half_extents_m: Vector3::new(
                    rng.uniform(1.0, 6.0),
                    rng.uniform(0.8, 6.0),
                    rng.uniform(0.7, 8.0),
                ),
                yaw_rad: rng.uniform(-0.3, 0.3),
            },
            if i < 10 { i + 1 } else { 0 },
        ));
    }
    for i in 0..10 {
        objects.push(object(
            Shape::Cylinder {
                base: Point3::new(
                    -60.0 + 12.0 * i as f64,
                    if i % 2 == 0 { 4.0 } else { -4.0 },
                    0.0,
                ),
                radius_m: 0.15,
                height_m: 6.0,
            },
            0,
        ));
    }
    SceneSnapshot::new(objects)
}

/// `cargo test --release -- --ignored --nocapture cast_timing`
#[test]
#[ignore]
fn cast_timing() {
    let scene = benchmark_scene();
    let origin = Point3::new(0.0, 0.0, 1.8);
    let rays: Vec<Ray> = (0..64)
        .flat_map(|beam| {
            let elevation = (-25.0 + 40.0 * beam as f64 / 63.0).to_radians();
            (0..2048).map(move |column| Ray {
                origin,
                direction: dir(2.0 * PI * column as f64 / 2048.0, elevation),
            })
        })
        .collect();
    // Minimum over repeated passes: the least disturbed by other load.
    let mut best_ns = f64::INFINITY;
    let mut hit_count = 0usize;
    for _ in 0..15 {
        hit_count = 0;
        let start = std::time::Instant::now();
        for r in &rays {
            if let Some(hit) = scene.cast(std::hint::black_box(r), 120.0) {
                std::hint::black_box(hit);
                hit_count += 1;
            }
        }
        best_ns = best_ns.min(start.elapsed().as_nanos() as f64 / rays.len() as f64);
    }
    println!(
        "{best_ns:.1} ns per cast (best of 15 passes of {} casts, {:.1}% hits)",
        rays.len(),
        100.0 * hit_count as f64 / rays.len() as f64,
    );
}
