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
mod tests;
