//! The large buffers of a scan's [`Returns`](super::Returns), kept between
//! scans: a 64 x 2048 image's returns, running sums and range extremes are
//! 21 MB, whose fresh pages (the allocator hands such blocks back to the
//! system when freed) cost the plane fits more to fault in than to fill.

use nalgebra::Vector3;

use crate::engine::spare::Pool;
use crate::engine::window_sums::Moments;

/// One scan's buffers, empty or of an earlier scan (contents overwritten).
#[derive(Default)]
pub(super) struct Spare {
    pub points: Vec<Vector3<f64>>,
    pub ranges: Vec<f64>,
    pub sums: Vec<Moments>,
    pub extremes: Vec<[f64; 2]>,
}

/// The returns' buffers ([`Spare`]) of scans done.
pub(super) static RETURNS: Pool<Spare> = Pool::new();

/// The per-cell fields of a dropped [`Surfaces`](super::Surfaces) (6 MB at
/// 64 x 2048), for the next scan's.
#[derive(Default)]
pub(super) struct Fields {
    pub range_m: Vec<f32>,
    pub direction: Vec<[f32; 3]>,
    pub normal: Vec<[f32; 3]>,
    pub incidence_cos: Vec<f32>,
    pub support: Vec<u8>,
    pub edge: Vec<bool>,
    pub azimuth_rad: Vec<f64>,
    pub elevation_rad: Vec<f64>,
}

/// The per-cell fields of dropped surfaces.
pub(super) static FIELDS: Pool<Fields> = Pool::new();
