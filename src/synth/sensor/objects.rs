//! The scene's objects as ray-castable shapes: the road, the static objects
//! and the actors at a given time.

use nalgebra::{Point3, Vector3};

use crate::synth::geometry::{SceneObject, Shape};
use crate::synth::kinematics::actor_motion;
use crate::synth::scene::{Actor, Scenario, StaticObject};

/// Parked-car box size, metres.
const CAR_SIZE_M: [f64; 3] = [4.5, 1.8, 1.5];

/// The static world: road plane and every static object.
pub(super) fn static_objects(scenario: &Scenario) -> Vec<SceneObject> {
    let ground = scenario.ground_height_m;
    let mut objects = vec![SceneObject {
        shape: Shape::Ground { height_m: ground },
        object_id: 0,
        moving: false,
    }];
    for object in &scenario.static_objects {
        let shape = match object {
            StaticObject::Box {
                center_xy_m,
                size_m,
                yaw_deg,
                ..
            } => standing_box(*center_xy_m, *size_m, *yaw_deg, ground),
            StaticObject::Car {
                center_xy_m,
                yaw_deg,
                ..
            } => standing_box(*center_xy_m, CAR_SIZE_M, *yaw_deg, ground),
            StaticObject::Pole {
                center_xy_m,
                radius_m,
                height_m,
                ..
            } => Shape::Cylinder {
                base: Point3::new(center_xy_m[0], center_xy_m[1], ground),
                radius_m: *radius_m,
                height_m: *height_m,
            },
        };
        objects.push(SceneObject {
            shape,
            object_id: 0,
            moving: false,
        });
    }
    objects
}

pub(super) fn actor_object(actor: &Actor, t_s: f64, ground: f64) -> SceneObject {
    let (position, _) = actor_motion(actor, t_s);
    SceneObject {
        shape: standing_box(position, actor.size_m, actor.yaw_deg, ground),
        object_id: actor.id,
        moving: true,
    }
}

/// A box resting on the road.
fn standing_box(center_xy_m: [f64; 2], size_m: [f64; 3], yaw_deg: f64, ground: f64) -> Shape {
    Shape::Box {
        center: Point3::new(center_xy_m[0], center_xy_m[1], ground + size_m[2] / 2.0),
        half_extents_m: Vector3::new(size_m[0], size_m[1], size_m[2]) / 2.0,
        yaw_rad: yaw_deg.to_radians(),
    }
}
