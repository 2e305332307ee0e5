//! Ray casting for the synthetic LiDAR: exact, closed-form intersections of
//! rays with the primitive shapes of a scene snapshot (road plane, yawed boxes,
//! vertical cylinders).
//!
//! Frames and units: world frame x forward, y left, z up; lengths in metres,
//! angles in radians. Every shape is a *solid*: a ray only hits it when it
//! enters it from outside, so a ray starting inside (or exactly on the surface
//! of) a shape never hits that shape. The road plane is the solid half-space
//! below `z = height_m`.
//!
//! This is the simulator's inner loop (hundreds of millions of casts per
//! scenario), so [`SceneSnapshot`] precomputes everything that does not depend
//! on the ray (yaw sines and cosines, bounding spheres), `cast` never allocates,
//! a bounding-sphere test rejects most objects before the exact test, and the
//! surface normal is only computed once, for the winning hit.
//!
//! Robustness contract: non-finite origins, zero / non-finite directions,
//! non-positive or NaN maximum ranges and invalid shapes (non-finite values,
//! negative extents, non-positive cylinder radius) give no hit; no function
//! panics and no returned range or normal is NaN or infinite.

use nalgebra::{Point3, Vector3};

/// Relative slack added to bounding-sphere radii so that rounding in the
/// cheap sphere test can never reject a ray that the exact test would hit.
const SPHERE_SLACK_REL: f64 = 1e-9;
/// Absolute slack (metres) added to bounding-sphere radii, for the same reason
/// (the sphere test subtracts squares of numbers as large as the range).
const SPHERE_SLACK_M: f64 = 1e-6;
/// Directions whose squared length is within this of 1 are used as they are;
/// others are renormalised so that ranges are always in metres.
const UNIT_TOLERANCE_SQ: f64 = 1e-12;

/// A ray: origin (world, metres) and unit direction.
///
/// Functions taking a ray renormalise a finite, non-zero direction that is not
/// unit length (so ranges are always metres along the ray), and treat a
/// non-finite origin or a zero / non-finite direction as hitting nothing.
#[derive(Debug, Clone, Copy)]
pub struct Ray {
    /// Start of the ray (world, metres).
    pub origin: Point3<f64>,
    /// Direction of the ray (world, unit length).
    pub direction: Vector3<f64>,
}

impl Ray {
    /// A ray with `direction` normalised; `None` if the origin is not finite or
    /// the direction is zero, tiny (length below ~1e-154) or not finite.
    pub fn new(origin: Point3<f64>, direction: Vector3<f64>) -> Option<Self> {
        Ray { origin, direction }.sanitized()
    }

    /// The point `range_m` metres along the ray (world).
    #[inline]
    pub fn point_at(&self, range_m: f64) -> Point3<f64> {
        self.origin + self.direction * range_m
    }

    /// This ray checked and with a unit direction, or `None` if degenerate.
    #[inline]
    fn sanitized(&self) -> Option<Self> {
        let o = self.origin;
        if !(o.x.is_finite() && o.y.is_finite() && o.z.is_finite()) {
            return None;
        }
        let norm_sq = self.direction.norm_squared();
        // NaN fails `is_finite`; below MIN_POSITIVE the square has underflowed
        // and the direction is useless.
        if !norm_sq.is_finite() || norm_sq < f64::MIN_POSITIVE {
            return None;
        }
        if (norm_sq - 1.0).abs() <= UNIT_TOLERANCE_SQ {
            // Already unit (the common case): skip the square root.
            return Some(*self);
        }
        Some(Ray {
            origin: o,
            direction: self.direction / norm_sq.sqrt(),
        })
    }
}

/// Shapes of the scene, in world coordinates at one instant.
#[derive(Debug, Clone, PartialEq)]
pub enum Shape {
    /// Infinite horizontal plane z = height_m (the road). Solid below: its
    /// outward normal is +z and it is only hit from above.
    Ground { height_m: f64 },
    /// Box: centre, half extents along its own axes (each >= 0; zero makes a
    /// flat rectangle), yaw (rad, about +z, counter-clockwise from +x).
    Box {
        center: Point3<f64>,
        half_extents_m: Vector3<f64>,
        yaw_rad: f64,
    },
    /// Vertical cylinder (pole): centre of its bottom face, radius (> 0),
    /// height (>= 0, extends upward).
    Cylinder {
        base: Point3<f64>,
        radius_m: f64,
        height_m: f64,
    },
}

/// The nearest intersection of a ray with a shape.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct ShapeHit {
    /// Distance from the ray origin to the hit along the (unit) direction, metres.
    pub range_m: f64,
    /// Unit outward surface normal at the hit (world).
    pub normal: Vector3<f64>,
}

impl Shape {
    /// Nearest hit with 0 < range <= max_range_m, entering the shape from outside.
    /// A ray whose origin is inside a box/cylinder (or below the ground, or
    /// exactly on any surface) gives None (sensors are never inside objects).
    /// Touching an edge or sliding along a face counts as a hit.
    ///
    /// For many rays against the same shapes use [`SceneSnapshot::cast`], which
    /// precomputes the box yaw's sine and cosine instead of recomputing them.
    pub fn intersect(&self, ray: &Ray, max_range_m: f64) -> Option<ShapeHit> {
        let ray = ray.sanitized()?;
        if max_range_m.is_nan() || max_range_m <= 0.0 {
            return None;
        }
        let geometry = Geometry::from_shape(self);
        let raw = geometry.hit(&ray, max_range_m)?;
        Some(ShapeHit {
            range_m: raw.range_m,
            normal: geometry.normal(&ray, raw),
        })
    }

    /// Centre and radius (metres) of a bounding sphere (None for Ground, which
    /// is unbounded, and for invalid shapes, which are never hit), for a cheap
    /// early-out.
    pub fn bounding_sphere(&self) -> Option<(Point3<f64>, f64)> {
        match Geometry::from_shape(self) {
            Geometry::Ground { .. } | Geometry::Never => None,
            Geometry::Box {
                center,
                half_extents_m,
                ..
            } => Some((center, half_extents_m.norm())),
            Geometry::Cylinder {
                base,
                radius_m,
                height_m,
                ..
            } => {
                let half_height_m = 0.5 * height_m;
                Some((
                    base + Vector3::new(0.0, 0.0, half_height_m),
                    radius_m.hypot(half_height_m),
                ))
            }
        }
    }
}

/// One object in a scene snapshot: its shape and the id reported for its hits
/// (0 = static world, >0 = moving actor id), and whether it moves.
#[derive(Debug, Clone, PartialEq)]
pub struct SceneObject {
    pub shape: Shape,
    /// Id reported with every hit on this object (0 = static world, >0 = actor id).
    pub object_id: u32,
    /// Whether the object moves (copied into its hits).
    pub moving: bool,
}

/// The nearest hit over all objects.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Hit {
    /// Distance from the ray origin along the unit direction, metres.
    pub range_m: f64,
    /// Unit outward surface normal at the hit (world).
    pub normal: Vector3<f64>,
    /// Index of the hit object in [`SceneSnapshot::objects`].
    pub object_index: usize,
    /// `object_id` of the hit object.
    pub object_id: u32,
    /// `moving` of the hit object.
    pub moving: bool,
}

/// A snapshot of the scene at one instant, with precomputed bounding spheres.
#[derive(Debug, Clone)]
pub struct SceneSnapshot {
    objects: Vec<SceneObject>,
    /// Same order as `objects`; validated, with the yaw as cosine/sine.
    geometry: Vec<Geometry>,
    /// Bounding spheres, same order as `objects`.
    bounds: SphereBounds,
}

/// Bounding spheres as a structure of arrays, so that the sphere test over a
/// block of objects is a tight, branch-free loop the compiler vectorises.
/// Unbounded objects (the ground, invalid shapes) get an infinite radius,
/// which always passes the test.
///
/// (A bounding-sphere hierarchy was tried: on a street scene of ~50 objects
/// seen from the middle of the street it was slower than this flat loop.)
#[derive(Debug, Clone, Default)]
struct SphereBounds {
    center_x_m: Vec<f64>,
    center_y_m: Vec<f64>,
    center_z_m: Vec<f64>,
    /// Radius with slack (metres), and its square.
    radius_m: Vec<f64>,
    radius_sq: Vec<f64>,
}

/// Objects are culled 64 at a time into a `u64` candidate mask (on the stack,
/// so `cast` never allocates).
const BLOCK: usize = 64;

impl SceneSnapshot {
    /// Prepares `objects` for casting (bounding spheres, yaw sines/cosines).
    /// Invalid shapes are kept (indices are preserved) but are never hit.
    pub fn new(objects: Vec<SceneObject>) -> Self {
        let mut bounds = SphereBounds::default();
        let geometry = objects
            .iter()
            .map(|object| {
                let (center, radius_m) = match object.shape.bounding_sphere() {
                    Some((center, radius_m)) => {
                        (center, radius_m * (1.0 + SPHERE_SLACK_REL) + SPHERE_SLACK_M)
                    }
                    None => (Point3::origin(), f64::INFINITY),
                };
                bounds.center_x_m.push(center.x);
                bounds.center_y_m.push(center.y);
                bounds.center_z_m.push(center.z);
                bounds.radius_m.push(radius_m);
                bounds.radius_sq.push(radius_m * radius_m);
                Geometry::from_shape(&object.shape)
            })
            .collect();
        SceneSnapshot {
            objects,
            geometry,
            bounds,
        }
    }

    /// The objects, in the order given to [`SceneSnapshot::new`]
    /// (`Hit::object_index` indexes this slice).
    pub fn objects(&self) -> &[SceneObject] {
        &self.objects
    }

    /// Nearest hit within max_range_m, ties broken by the lower object index
    /// (deterministic). Objects containing the ray origin are not hit (see
    /// [`Shape::intersect`]), but the others still are. Never allocates.
    #[inline]
    pub fn cast(&self, ray: &Ray, max_range_m: f64) -> Option<Hit> {
        let ray = ray.sanitized()?;
        if max_range_m.is_nan() || max_range_m <= 0.0 {
            return None;
        }
        let (o, d) = (ray.origin, ray.direction);
        // Shrinks to the nearest hit so far, so that both the sphere test (of
        // later blocks) and the exact tests reject everything farther away.
        let mut best_range_m = max_range_m;
        let mut best: Option<(usize, RawHit)> = None;
        let b = &self.bounds;
        let count = self.geometry.len();
        let mut block_start = 0;
        while block_start < count {
            let block = block_start..count.min(block_start + BLOCK);
            let cx = &b.center_x_m[block.clone()];
            let cy = &b.center_y_m[block.clone()];
            let cz = &b.center_z_m[block.clone()];
            let radius = &b.radius_m[block.clone()];
            let radius_sq = &b.radius_sq[block.clone()];
            let mut candidates: u64 = 0;
            for k in 0..cx.len() {
                let (tx, ty, tz) = (cx[k] - o.x, cy[k] - o.y, cz[k] - o.z);
                let along_m = tx * d.x + ty * d.y + tz * d.z;
                let center_dist_sq = tx * tx + ty * ty + tz * tz;
                // Non-short-circuit `&` and `|`: unpredictable branches per
                // object cost more than evaluating all three tests. A NaN
                // (absurdly far origins) makes every test false, i.e. keeps
                // the object for the exact test: conservative.
                // Origin outside the sphere and moving away from it;
                let behind = (along_m < 0.0) & (center_dist_sq > radius_sq[k]);
                // the sphere only starts beyond the best hit so far;
                let beyond = along_m - radius[k] > best_range_m;
                // the line passes the centre farther than the radius.
                let wide = center_dist_sq - along_m * along_m > radius_sq[k];
                candidates |= u64::from(!(behind | beyond | wide)) << k;
            }
            // Exact tests in index order, so that ties keep the lower index.
            while candidates != 0 {
                let index = block.start + candidates.trailing_zeros() as usize;
                candidates &= candidates - 1;
                if let Some(raw) = self.geometry[index].hit(&ray, best_range_m) {
                    // Strictly closer only: an equal range keeps the lower index.
                    if best.is_none() || raw.range_m < best_range_m {
                        best_range_m = raw.range_m;
                        best = Some((index, raw));
                    }
                }
            }
            block_start = block.end;
        }
        let (index, raw) = best?;
        let object = &self.objects[index];
        Some(Hit {
            range_m: raw.range_m,
            normal: self.geometry[index].normal(&ray, raw),
            object_index: index,
            object_id: object.object_id,
            moving: object.moving,
        })
    }
}

/// A shape in the form the intersection code wants (validated, yaw as
/// cosine/sine).
#[derive(Debug, Clone, Copy)]
enum Geometry {
    Ground {
        height_m: f64,
    },
    Box {
        center: Point3<f64>,
        half_extents_m: Vector3<f64>,
        cos_yaw: f64,
        sin_yaw: f64,
    },
    Cylinder {
        base: Point3<f64>,
        radius_m: f64,
        radius_sq: f64,
        height_m: f64,
    },
    /// An invalid shape (non-finite values, negative extents, ...): never hit.
    Never,
}

/// Which surface of a shape a ray entered through; the normal is computed
/// from it only for the winning hit.
#[derive(Debug, Clone, Copy, PartialEq)]
enum Face {
    GroundTop,
    /// Box face along local axis `axis` (0 = x, 1 = y, 2 = z), on the
    /// positive or the negative side.
    BoxSide {
        axis: u8,
        positive: bool,
    },
    CylinderSide,
    CylinderTop,
    CylinderBottom,
}

/// A hit before its normal is computed.
#[derive(Debug, Clone, Copy)]
struct RawHit {
    range_m: f64,
    face: Face,
}

fn finite_point(p: &Point3<f64>) -> bool {
    p.x.is_finite() && p.y.is_finite() && p.z.is_finite()
}

/// The final acceptance test shared by all shapes. Written with positive
/// comparisons so that NaN anywhere rejects the hit.
#[inline]
fn accept(enter_m: f64, exit_m: f64, max_range_m: f64) -> bool {
    enter_m > 0.0 && enter_m <= exit_m && enter_m <= max_range_m && enter_m < f64::INFINITY
}

impl Geometry {
    fn from_shape(shape: &Shape) -> Self {
        match *shape {
            Shape::Ground { height_m } if height_m.is_finite() => Geometry::Ground { height_m },
            Shape::Box {
                center,
                half_extents_m,
                yaw_rad,
            } if finite_point(&center)
                && yaw_rad.is_finite()
                && half_extents_m.iter().all(|h| h.is_finite() && *h >= 0.0) =>
            {
                let (sin_yaw, cos_yaw) = yaw_rad.sin_cos();
                Geometry::Box {
                    center,
                    half_extents_m,
                    cos_yaw,
                    sin_yaw,
                }
            }
            Shape::Cylinder {
                base,
                radius_m,
                height_m,
            } if finite_point(&base)
                && radius_m.is_finite()
                && radius_m > 0.0
                && height_m.is_finite()
                && height_m >= 0.0 =>
            {
                Geometry::Cylinder {
                    base,
                    radius_m,
                    radius_sq: radius_m * radius_m,
                    height_m,
                }
            }
            _ => Geometry::Never,
        }
    }

    /// Entering hit with 0 < range <= max_range_m. `ray` must be sanitised
    /// and `max_range_m` positive.
    #[inline]
    fn hit(&self, ray: &Ray, max_range_m: f64) -> Option<RawHit> {
        match *self {
            Geometry::Ground { height_m } => hit_ground(height_m, ray, max_range_m),
            Geometry::Box {
                center,
                half_extents_m,
                cos_yaw,
                sin_yaw,
            } => hit_box(center, half_extents_m, cos_yaw, sin_yaw, ray, max_range_m),
            Geometry::Cylinder {
                base,
                radius_sq,
                height_m,
                ..
            } => hit_cylinder(base, radius_sq, height_m, ray, max_range_m),
            Geometry::Never => None,
        }
    }

    /// Unit outward normal (world) for a hit returned by [`Geometry::hit`] with
    /// the same ray.
    fn normal(&self, ray: &Ray, raw: RawHit) -> Vector3<f64> {
        match (*self, raw.face) {
            (
                Geometry::Box {
                    cos_yaw, sin_yaw, ..
                },
                Face::BoxSide { axis, positive },
            ) => {
                let sign = if positive { 1.0 } else { -1.0 };
                match axis {
                    // Local +x and +y axes rotated by the yaw into the world.
                    0 => Vector3::new(sign * cos_yaw, sign * sin_yaw, 0.0),
                    1 => Vector3::new(-sign * sin_yaw, sign * cos_yaw, 0.0),
                    _ => Vector3::new(0.0, 0.0, sign),
                }
            }
            (Geometry::Cylinder { base, .. }, Face::CylinderSide) => {
                let p = ray.point_at(raw.range_m) - base;
                let radial_m = p.x.hypot(p.y);
                if radial_m > 0.0 {
                    Vector3::new(p.x / radial_m, p.y / radial_m, 0.0)
                } else {
                    // Unreachable with a positive radius; keeps the result
                    // finite whatever happens.
                    Vector3::z()
                }
            }
            (_, Face::CylinderBottom) => -Vector3::z(),
            // Ground top, cylinder top (and, defensively, any mismatch).
            _ => Vector3::z(),
        }
    }
}

#[inline]
fn hit_ground(height_m: f64, ray: &Ray, max_range_m: f64) -> Option<RawHit> {
    let dz = ray.direction.z;
    // Only rays going down can enter the half-space from above; this also
    // rejects rays parallel to the plane (no division by zero).
    if dz.is_nan() || dz >= 0.0 {
        return None;
    }
    // Negative when the origin is below the road (inside the solid).
    let range_m = (ray.origin.z - height_m) / -dz;
    accept(range_m, f64::INFINITY, max_range_m).then_some(RawHit {
        range_m,
        face: Face::GroundTop,
    })
}

/// Slab method in the box's own (yawed) frame.
#[inline]
fn hit_box(
    center: Point3<f64>,
    half_extents_m: Vector3<f64>,
    cos_yaw: f64,
    sin_yaw: f64,
    ray: &Ray,
    max_range_m: f64,
) -> Option<RawHit> {
    let rel = ray.origin - center;
    let d = ray.direction;
    // World -> box frame is the inverse (transpose) of the yaw rotation.
    let origin_local = [
        cos_yaw * rel.x + sin_yaw * rel.y,
        -sin_yaw * rel.x + cos_yaw * rel.y,
        rel.z,
    ];
    let dir_local = [
        cos_yaw * d.x + sin_yaw * d.y,
        -sin_yaw * d.x + cos_yaw * d.y,
        d.z,
    ];
    let mut enter_m = f64::NEG_INFINITY;
    let mut exit_m = f64::INFINITY;
    let mut face = Face::BoxSide {
        axis: 0,
        positive: false,
    };
    for axis in 0..3 {
        let p = origin_local[axis];
        let v = dir_local[axis];
        let h = half_extents_m[axis];
        if v == 0.0 {
            // Parallel to this pair of faces: the slab is either the whole
            // line or nothing. Points exactly on a face count as inside the
            // slab, so a ray sliding along a face hits it (grazing).
            if p.abs() > h {
                return None;
            }
            continue;
        }
        // Division rather than multiplication by 1/v: with a subnormal v the
        // reciprocal overflows and 0 * inf would be NaN; x / v is at worst
        // +-inf, which the comparisons below handle.
        let to_neg_m = (-h - p) / v;
        let to_pos_m = (h - p) / v;
        let (near_m, far_m, positive) = if v > 0.0 {
            (to_neg_m, to_pos_m, false)
        } else {
            (to_pos_m, to_neg_m, true)
        };
        if near_m > enter_m {
            enter_m = near_m;
            face = Face::BoxSide {
                axis: axis as u8,
                positive,
            };
        }
        if far_m < exit_m {
            exit_m = far_m;
        }
    }
    accept(enter_m, exit_m, max_range_m).then_some(RawHit {
        range_m: enter_m,
        face,
    })
}

/// Intersection of the infinite vertical cylinder (quadratic) with the slab
/// between the bottom and top caps.
#[inline]
fn hit_cylinder(
    base: Point3<f64>,
    radius_sq: f64,
    height_m: f64,
    ray: &Ray,
    max_range_m: f64,
) -> Option<RawHit> {
    let p = ray.origin - base;
    let d = ray.direction;

    // Slab 0 <= z <= height_m.
    let (mut enter_m, mut exit_m, mut face);
    if d.z == 0.0 {
        if p.z < 0.0 || p.z > height_m {
            return None;
        }
        enter_m = f64::NEG_INFINITY;
        exit_m = f64::INFINITY;
        face = Face::CylinderSide;
    } else {
        let to_bottom_m = -p.z / d.z;
        let to_top_m = (height_m - p.z) / d.z;
        if d.z > 0.0 {
            (enter_m, exit_m, face) = (to_bottom_m, to_top_m, Face::CylinderBottom);
        } else {
            (enter_m, exit_m, face) = (to_top_m, to_bottom_m, Face::CylinderTop);
        }
    }

    // Side: |p_xy + t d_xy|^2 = r^2, i.e. a t^2 + 2 b t + c = 0.
    let a = d.x * d.x + d.y * d.y;
    let c = p.x * p.x + p.y * p.y - radius_sq;
    // Lagrange's identity: b^2 - a c = a r^2 - (p x d)_z^2. This form does not
    // subtract the squares of the (large) distance to the pole, which would
    // lose the (small) radius to cancellation for far, thin poles.
    let cross = p.x * d.y - p.y * d.x;
    if a == 0.0 {
        // Vertical ray: inside the circle for all t, or never.
        if c > 0.0 {
            return None;
        }
    } else {
        let b = p.x * d.x + p.y * d.y;
        let disc = a * radius_sq - cross * cross;
        if disc.is_nan() || disc < 0.0 {
            return None;
        }
        // Numerically stable roots q / a and c / q (no cancellation between
        // -b and the square root, which matters for distant thin poles).
        let q = if b >= 0.0 {
            -(b + disc.sqrt())
        } else {
            disc.sqrt() - b
        };
        let (t0, t1) = if q == 0.0 {
            // b = 0 and disc = 0: origin on the circle, ray tangent.
            (0.0, 0.0)
        } else {
            let r0 = q / a;
            let r1 = c / q;
            if r0 <= r1 { (r0, r1) } else { (r1, r0) }
        };
        if t0.is_nan() || t1.is_nan() {
            return None;
        }
        if t0 > enter_m {
            enter_m = t0;
            face = Face::CylinderSide;
        }
        if t1 < exit_m {
            exit_m = t1;
        }
    }
    accept(enter_m, exit_m, max_range_m).then_some(RawHit {
        range_m: enter_m,
        face,
    })
}

#[cfg(test)]
mod tests {
    use super::*;
    use std::f64::consts::{FRAC_PI_2, PI};

    use crate::test_rng::SplitMix64;

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
}
