//! Point clouds (`sensor_msgs/PointCloud2`, `foxglove.PointCloud`) to [`Scan`].
//!
//! Both formats are "a strided byte buffer plus named, typed fields", so they
//! share one extractor: the header is validated against the data length and
//! [`DecodeLimits`] first (nothing is allocated from untrusted sizes before
//! that), the fields used are resolved once into readers (`fields`), and the
//! hot loop (`extract`) then only reads fixed offsets from each point's
//! bytes; per-point times are converted as `time` describes.

mod extract;
mod fields;
mod time;

use nalgebra::{Isometry3, Translation3, UnitQuaternion};

use super::DecodeLimits;
use crate::model::Scan;
use crate::ros::DecodeError;
use crate::ros::msgs::PointCloud2;
use extract::extract;
use fields::{FieldDesc, Layout, Scalar, resolve_readers};

/// Refuses clouds above the point limit (and above what `u32` indices hold).
fn check_point_count(points: u64, limits: &DecodeLimits) -> Result<usize, DecodeError> {
    let max_points = limits.max_points.min(u32::MAX as usize);
    if points > max_points as u64 {
        return Err(DecodeError::TooManyPoints { points, max_points });
    }
    Ok(points as usize)
}

/// Strips one leading '/' (ROS 1 style frame ids).
pub(crate) fn normalize_frame_id(frame_id: &str) -> String {
    frame_id.strip_prefix('/').unwrap_or(frame_id).to_owned()
}

/// Converts a `sensor_msgs/PointCloud2` into a [`Scan`] (identity sensor pose).
///
/// `is_dense` is treated as a hint only: points are always checked, since
/// drivers set it inconsistently.
pub fn scan_from_pointcloud2(
    cloud: &PointCloud2<'_>,
    limits: &DecodeLimits,
) -> Result<Scan, DecodeError> {
    let stamp_ns = cloud.header.stamp.to_ns();
    let frame_id = normalize_frame_id(&cloud.header.frame_id);
    let n = check_point_count(u64::from(cloud.width) * u64::from(cloud.height), limits)?;
    if n == 0 {
        return Ok(Scan::empty(stamp_ns, frame_id, Isometry3::identity()));
    }
    let point_step = u64::from(cloud.point_step);
    if point_step == 0 {
        return Err(DecodeError::InvalidPointLayout(
            "point_step is 0 for a non-empty cloud".into(),
        ));
    }
    let row_bytes = u64::from(cloud.width) * point_step;
    // A single row needs no row_step; some drivers leave it 0 there.
    let row_step = if cloud.height > 1 {
        u64::from(cloud.row_step)
    } else {
        row_bytes
    };
    if row_step < row_bytes {
        return Err(DecodeError::InvalidPointLayout(format!(
            "row_step {} is smaller than width {} * point_step {}",
            cloud.row_step, cloud.width, cloud.point_step
        )));
    }
    let needed = (u64::from(cloud.height) - 1) * row_step + row_bytes;
    if (cloud.data.len() as u64) < needed {
        return Err(DecodeError::PointCloudDataTooShort {
            data_bytes: cloud.data.len(),
            needed_bytes: needed,
            height: cloud.height,
            width: cloud.width,
            point_step: cloud.point_step,
            row_step: cloud.row_step,
        });
    }
    // Every size below is bounded by the data length now.
    let layout = Layout {
        data: &cloud.data,
        rows: cloud.height as usize,
        cols: cloud.width as usize,
        row_step: row_step as usize,
        point_step: point_step as usize,
        big_endian: cloud.is_bigendian,
    };
    let fields: Vec<FieldDesc<'_>> = cloud
        .fields
        .iter()
        .map(|f| FieldDesc {
            name: &f.name,
            offset: f.offset,
            scalar: Scalar::from_ros(f.datatype).ok_or(i64::from(f.datatype)),
        })
        .collect();
    let readers = resolve_readers(&fields, &layout, &limits.sensor_field)?;
    Ok(extract(
        &layout,
        &readers,
        stamp_ns,
        frame_id,
        Isometry3::identity(),
    ))
}

/// The cloud origin's pose; a missing pose, position or orientation (or an
/// all-zero orientation) means identity; a non-finite orientation is an error.
fn foxglove_pose(pose: Option<&foxglove::messages::Pose>) -> Result<Isometry3<f64>, DecodeError> {
    let Some(pose) = pose else {
        return Ok(Isometry3::identity());
    };
    let t = pose
        .position
        .as_ref()
        .map_or(Translation3::identity(), |p| {
            Translation3::new(p.x, p.y, p.z)
        });
    let rotation = match &pose.orientation {
        // proto3 cannot tell an unset orientation from an all-zero one.
        None => UnitQuaternion::identity(),
        Some(q) if q.x == 0.0 && q.y == 0.0 && q.z == 0.0 && q.w == 0.0 => {
            UnitQuaternion::identity()
        }
        Some(q) => crate::ros::msgs::Quaternion {
            x: q.x,
            y: q.y,
            z: q.z,
            w: q.w,
        }
        .to_unit()
        .ok_or(DecodeError::InvalidQuaternion {
            context: "foxglove.PointCloud pose".into(),
            x: q.x,
            y: q.y,
            z: q.z,
            w: q.w,
        })?,
    };
    Ok(Isometry3::from_parts(t, rotation))
}

/// Converts a `foxglove.PointCloud` into a [`Scan`], keeping its `pose` as the
/// sensor pose (points stay in the cloud's origin frame). A trailing partial
/// point in `data` is ignored, as Foxglove's own viewer does. A missing
/// `timestamp` gives `stamp_ns` 0.
pub fn scan_from_foxglove(
    cloud: &foxglove::messages::PointCloud,
    limits: &DecodeLimits,
) -> Result<Scan, DecodeError> {
    let stamp_ns = cloud.timestamp.map_or(0, |t| {
        i64::from(t.sec()) * 1_000_000_000 + i64::from(t.nsec())
    });
    let frame_id = normalize_frame_id(&cloud.frame_id);
    let sensor_pose = foxglove_pose(cloud.pose.as_ref())?;
    let stride = cloud.point_stride as usize;
    if stride == 0 {
        if cloud.data.is_empty() {
            return Ok(Scan::empty(stamp_ns, frame_id, sensor_pose));
        }
        return Err(DecodeError::InvalidPointLayout(
            "point_stride is 0 but data is not empty".into(),
        ));
    }
    let n = check_point_count((cloud.data.len() / stride) as u64, limits)?;
    if n == 0 {
        return Ok(Scan::empty(stamp_ns, frame_id, sensor_pose));
    }
    let layout = Layout {
        data: &cloud.data,
        rows: 1,
        cols: n,
        row_step: n * stride,
        point_step: stride,
        big_endian: false,
    };
    let fields: Vec<FieldDesc<'_>> = cloud
        .fields
        .iter()
        .map(|f| FieldDesc {
            name: &f.name,
            offset: f.offset,
            scalar: Scalar::from_foxglove(f.r#type).ok_or(i64::from(f.r#type)),
        })
        .collect();
    let readers = resolve_readers(&fields, &layout, &limits.sensor_field)?;
    Ok(extract(&layout, &readers, stamp_ns, frame_id, sensor_pose))
}
