//! `/truth/points`: the truth of every point of a written `/lidar/points`
//! cloud, same shape and order, in the layout of [`crate::truth`].

use crate::ros::msgs::{Header, PointCloud2};
use crate::synth::sensor::{SimPoint, SimScan};
use crate::truth::{self, TruthPoint};

use super::{CloudShape, stamp_ns};

/// The truth cloud of `scan` in the shape of its `/lidar/points`, in frame `frame`.
pub(super) fn truth_cloud(scan: &SimScan, shape: &CloudShape, frame: &str) -> PointCloud2<'static> {
    let mut data = Vec::with_capacity(shape.slots.len() * truth::POINT_STEP as usize);
    for &slot in &shape.slots {
        let point = shape
            .point(scan, slot)
            .map_or(TruthPoint::NO_RETURN, truth_point);
        data.extend_from_slice(&point.encode());
    }
    PointCloud2 {
        header: Header::new(stamp_ns(scan.stamp_s), frame),
        height: shape.height,
        width: shape.width,
        fields: truth::point_fields(),
        is_bigendian: false,
        point_step: truth::POINT_STEP,
        row_step: shape.width * truth::POINT_STEP,
        data: data.into(),
        is_dense: shape.dense(),
    }
}

/// The written truth of a return.
fn truth_point(point: &SimPoint) -> TruthPoint {
    let truth = &point.truth;
    TruthPoint {
        range_m: truth.range_m as f32,
        point_looming_per_s: truth.point_looming_per_s as f32,
        ray_looming_per_s: truth.ray_looming_per_s as f32,
        own_motion_looming_per_s: truth.own_motion_looming_per_s as f32,
        incidence_cos: truth.incidence_cos as f32,
        object_id: truth.object_id,
        surface: truth.surface as u8,
        moving: truth.moving,
    }
}
