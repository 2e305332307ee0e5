//! Builders of the Foxglove messages of our output channels (protobuf types of
//! the `foxglove` crate): point clouds, range images, threat spheres, log lines.
//! Pure functions of a scan and its engine result.

use foxglove::messages::{
    Color, CompressedImage, Event, KeyValuePair, Log, PackedElementField, PointCloud, Pose,
    Quaternion, SceneEntity, SceneEntityDeletion, SceneUpdate, SpherePrimitive, Timestamp, Vector3,
    log, packed_element_field::NumericType, scene_entity_deletion,
};

use crate::engine::{PairLooming, ThreatLevel};
use crate::events::NearMissEvent;
use crate::model::{Scan, StampNs};

use super::colour::{self, Rgba};

/// Which per-point fields `/looming/points` carries.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Default, serde::Serialize, clap::ValueEnum)]
#[serde(rename_all = "snake_case")]
pub enum FieldSet {
    /// x, y, z, the fused looming and its colour.
    #[default]
    Default,
    /// Also L_lidar, L_ego, L_ray_ego, D, confidence, threat level, mask and
    /// the id of the point's object (0: none).
    Full,
}

/// A packed point layout under construction.
struct Layout {
    fields: Vec<PackedElementField>,
    stride: u32,
}

impl Layout {
    fn new() -> Self {
        Self {
            fields: Vec::new(),
            stride: 0,
        }
    }

    fn add(mut self, name: &str, numeric: NumericType) -> Self {
        let size = match numeric {
            NumericType::Uint8 | NumericType::Int8 => 1,
            NumericType::Uint16 | NumericType::Int16 => 2,
            NumericType::Float64 => 8,
            _ => 4,
        };
        self.fields.push(PackedElementField {
            name: name.into(),
            offset: self.stride,
            r#type: numeric as i32,
        });
        self.stride += size;
        self
    }

    /// x, y, z as FLOAT32 first, as both viewers expect.
    fn xyz() -> Self {
        Self::new()
            .add("x", NumericType::Float32)
            .add("y", NumericType::Float32)
            .add("z", NumericType::Float32)
    }

    /// red, green, blue, alpha as UINT8: the names Rerun reads colours from.
    fn rgba(self) -> Self {
        self.add("red", NumericType::Uint8)
            .add("green", NumericType::Uint8)
            .add("blue", NumericType::Uint8)
            .add("alpha", NumericType::Uint8)
    }
}

/// Appends points field by field, in the layout's order.
struct Packer {
    data: Vec<u8>,
}

impl Packer {
    fn with_points(stride: u32, points: usize) -> Self {
        Self {
            data: Vec::with_capacity(stride as usize * points),
        }
    }
    fn f32(&mut self, value: f32) -> &mut Self {
        self.data.extend_from_slice(&value.to_le_bytes());
        self
    }
    fn u8(&mut self, value: u8) -> &mut Self {
        self.data.push(value);
        self
    }
    fn u32(&mut self, value: u32) -> &mut Self {
        self.data.extend_from_slice(&value.to_le_bytes());
        self
    }
    /// Positions rounded to [`POSITION_QUANTUM_M`].
    fn xyz(&mut self, p: &[f32; 3]) -> &mut Self {
        self.data.extend_from_slice(&quantized_xyz(p));
        self
    }
    fn rgba(&mut self, c: Rgba) -> &mut Self {
        self.data.extend_from_slice(&c);
        self
    }
}

pub fn timestamp(stamp_ns: StampNs) -> Timestamp {
    let ns = stamp_ns.max(0) as u64;
    let sec = u32::try_from(ns / 1_000_000_000).unwrap_or(u32::MAX);
    Timestamp::new(sec, (ns % 1_000_000_000) as u32)
}

/// The cloud's pose in its frame: the input cloud's (identity for
/// PointCloud2), always given in full (Rerun needs position and orientation).
fn pose_of(scan: &Scan) -> Pose {
    let t = scan.sensor_pose.translation.vector;
    let q = scan.sensor_pose.rotation.quaternion();
    Pose {
        position: Some(Vector3 {
            x: t.x,
            y: t.y,
            z: t.z,
        }),
        orientation: Some(Quaternion {
            x: q.i,
            y: q.j,
            z: q.k,
            w: q.w,
        }),
    }
}

fn cloud(scan: &Scan, layout: Layout, data: Vec<u8>) -> PointCloud {
    PointCloud {
        timestamp: Some(timestamp(scan.stamp_ns)),
        frame_id: scan.frame_id.clone(),
        pose: Some(pose_of(scan)),
        point_stride: layout.stride,
        fields: layout.fields,
        data: data.into(),
    }
}

/// Per point of the current scan: its surface cell when that cell's values
/// are trusted (unmasked), else `None`.
fn trusted_cell(looming: &PairLooming, index: usize) -> Option<usize> {
    looming
        .image
        .surface_cell(index)
        .filter(|&cell| looming.mask[cell] == 0)
}

/// Positions are rounded to 1/1024 m (at most 0.5 mm away, against 20 mm of
/// range noise): the zeroed low mantissa bits compress, and the clouds are
/// most of the output.
pub const POSITION_QUANTUM_M: f32 = 1.0 / 1024.0;

/// Looming values in point fields are rounded to 1/1024 1/s, far below their
/// noise (about 0.01 1/s): the zeroed low mantissa bits let zstd shrink the
/// field to a fraction.
pub(crate) const LOOMING_QUANTUM_PER_S: f32 = 1.0 / 1024.0;

/// A position rounded to [`POSITION_QUANTUM_M`], as its three fields' bytes
/// (one append per point, not one per coordinate: every point of every
/// scan).
fn quantized_xyz(p: &[f32; 3]) -> [u8; 12] {
    let q = |v: f32| ((v / POSITION_QUANTUM_M).round() * POSITION_QUANTUM_M).to_le_bytes();
    let [x, y, z] = p.map(q);
    let mut bytes = [0; 12];
    bytes[..4].copy_from_slice(&x);
    bytes[4..8].copy_from_slice(&y);
    bytes[8..].copy_from_slice(&z);
    bytes
}

fn quantized(looming_per_s: f32) -> f32 {
    (looming_per_s / LOOMING_QUANTUM_PER_S).round() * LOOMING_QUANTUM_PER_S
}

/// `/looming/points`: every point of the scan with its fused looming (NaN
/// where untrusted) and colour.
pub(crate) fn looming_cloud(
    scan: &Scan,
    looming: &PairLooming,
    objects: &crate::objects::PairObjects,
    fields: FieldSet,
) -> PointCloud {
    let mut layout = Layout::xyz().add("looming", NumericType::Float32).rgba();
    if fields == FieldSet::Full {
        layout = layout
            .add("l_lidar", NumericType::Float32)
            .add("l_ego", NumericType::Float32)
            .add("l_ray_ego", NumericType::Float32)
            .add("disagreement", NumericType::Float32)
            .add("confidence", NumericType::Float32)
            .add("threat", NumericType::Uint8)
            .add("mask", NumericType::Uint8)
            .add("object_id", NumericType::Uint32);
    }
    let mut out = Packer::with_points(layout.stride, scan.points_m.len());
    for (index, p) in scan.points_m.iter().enumerate() {
        let cell = looming.image.surface_cell(index);
        let trusted = cell.filter(|&c| looming.mask[c] == 0);
        let fused = trusted.map_or(f32::NAN, |c| quantized(looming.fused[c]));
        // The default fields as one record, appended at once.
        let mut record = [0u8; 20];
        record[..12].copy_from_slice(&quantized_xyz(p));
        record[12..16].copy_from_slice(&fused.to_le_bytes());
        record[16..].copy_from_slice(&colour::looming(fused));
        out.data.extend_from_slice(&record);
        if fields == FieldSet::Full {
            let at = |values: &[f32]| cell.map_or(f32::NAN, |c| quantized(values[c]));
            out.f32(at(&looming.l_lidar))
                .f32(quantized(looming.l_ego[index]))
                .f32(at(&looming.l_ray_ego))
                .f32(at(&looming.disagreement))
                .f32(at(&looming.confidence))
                .u8(looming.point_threat[index] as u8)
                .u8(cell.map_or(crate::engine::mask::EMPTY, |c| looming.mask[c]))
                .u32(cell.and_then(|c| objects.object_of_cell(c)).unwrap_or(0));
        }
    }
    cloud(scan, layout, out.data)
}

/// `/looming/disagreement`: the points of moving patches, with `D` and its colour.
pub(crate) fn disagreement_cloud(scan: &Scan, looming: &PairLooming) -> PointCloud {
    let layout = Layout::xyz()
        .add("disagreement", NumericType::Float32)
        .rgba();
    let mut out = Packer::with_points(layout.stride, 0);
    for (index, p) in scan.points_m.iter().enumerate() {
        let Some(cell) = trusted_cell(looming, index) else {
            continue;
        };
        if looming.moving[cell] {
            let d = quantized(looming.disagreement[cell]);
            out.xyz(p).f32(d).rgba(colour::looming(d));
        }
    }
    cloud(scan, layout, out.data)
}

/// `/looming/threat`: the points at low, medium or high threat, with their
/// level, fused looming and the level's colour.
pub(crate) fn threat_cloud(scan: &Scan, looming: &PairLooming) -> PointCloud {
    let layout = Layout::xyz()
        .add("looming", NumericType::Float32)
        .add("level", NumericType::Uint8)
        .rgba();
    let mut out = Packer::with_points(layout.stride, 0);
    for (index, p) in scan.points_m.iter().enumerate() {
        let level = looming.point_threat[index];
        if level == ThreatLevel::None {
            continue;
        }
        let fused = looming
            .image
            .surface_cell(index)
            .map_or(f32::NAN, |cell| quantized(looming.fused[cell]));
        out.xyz(p)
            .f32(fused)
            .u8(level as u8)
            .rgba(colour::threat(level));
    }
    cloud(scan, layout, out.data)
}

/// A range image that could not be written as PNG (only dimensions a PNG
/// cannot hold make the encoder fail in memory).
#[derive(Debug, thiserror::Error)]
pub enum RangeImageError {
    #[error("range image of {cells} cells with values for {values} of them")]
    Cells { cells: usize, values: usize },
    #[error("range image of {rows} x {cols} cells: too large for a PNG")]
    TooLarge { rows: usize, cols: usize },
    #[error("range image of {rows} x {cols} cells: PNG encoding failed: {source}")]
    Png {
        rows: usize,
        cols: usize,
        #[source]
        source: png::EncodingError,
    },
}

/// Widest aspect (width over height) of a range image: a 64 x 2048 scan
/// drawn one pixel per beam is a 32:1 strip that a viewer's image panel
/// shrinks to a few pixels per beam; each beam is drawn several pixels tall
/// instead.
pub const MAX_IMAGE_ASPECT: usize = 8;

/// Pixels per beam in a range image of `rows` x `cols` cells: the fewest
/// (1 to 8) that keep it at most [`MAX_IMAGE_ASPECT`] times wider than tall.
pub fn image_row_scale(rows: usize, cols: usize) -> usize {
    cols.div_ceil(rows.max(1) * MAX_IMAGE_ASPECT).clamp(1, 8)
}

/// A per-cell quantity as a PNG range image (`foxglove.CompressedImage`,
/// format `png`): rows are beams (the highest at the top), each
/// [`image_row_scale`] pixels tall, columns azimuth (straight ahead at the
/// centre, the left to the left, as seen from the driver's seat); black where
/// there is no return, grey where masked.
pub fn range_image(
    scan: &Scan,
    looming: &PairLooming,
    values: &[f32],
) -> Result<CompressedImage, RangeImageError> {
    let (rows, cols) = (looming.geometry.rows, looming.geometry.cols);
    let scale = image_row_scale(rows, cols);
    let cells = rows * cols;
    let (points, mask) = (&looming.image.point, &looming.mask);
    if points.len() < cells || mask.len() < cells || values.len() < cells {
        return Err(RangeImageError::Cells {
            cells,
            values: values.len().min(points.len()).min(mask.len()),
        });
    }
    // Each image row written whole from its cells (no push, no branch per
    // cell: the pushes' checks and branches were most of this function's
    // time), then repeated `scale` times.
    let mut indexes = vec![0u8; rows * scale * cols];
    for (image_row, pixels) in indexes.chunks_exact_mut(scale * cols).enumerate() {
        // Row 0 of the engine is the lowest beam. Engine columns run
        // clockwise from behind, so the left is at small column numbers:
        // already the driver's view.
        let row = (rows - 1 - image_row) * cols..(rows - image_row) * cols;
        let (first, repeats) = pixels.split_at_mut(cols);
        let of_row = points[row.clone()].iter().zip(&mask[row.clone()]);
        for (pixel, ((&point, &bits), &value)) in first.iter_mut().zip(of_row.zip(&values[row])) {
            let index = colour::looming_index(value);
            let index = if bits != 0 {
                colour::MASKED_INDEX
            } else {
                index
            };
            *pixel = if point == crate::engine::NO_POINT {
                colour::EMPTY_INDEX
            } else {
                index
            };
        }
        for repeat in repeats.chunks_exact_mut(cols) {
            repeat.copy_from_slice(first);
        }
    }
    Ok(CompressedImage {
        timestamp: Some(timestamp(scan.stamp_ns)),
        frame_id: scan.frame_id.clone(),
        data: indexed_png(rows * scale, cols, &indexes)?.into(),
        format: "png".into(),
    })
}

/// Palette indexes (row by row, [`colour::image_palette`]) as an 8-bit
/// indexed-colour PNG. Fast deflate with the filter chosen per row: a beam's
/// repeated pixel rows ([`image_row_scale`]) take the Up filter and cost
/// almost nothing, where Sub for every row made them cost as much as the
/// first (KITTI's 2081 x 320 images: 31.6 KB instead of 140 KB, 25 KB after
/// the writer's zstd, 0.33 ms to encode; `examples/image_encoding.rs`,
/// docs/performance.md).
pub fn indexed_png(rows: usize, cols: usize, indexes: &[u8]) -> Result<Vec<u8>, RangeImageError> {
    indexed_png_with(
        rows,
        cols,
        indexes,
        png::Compression::Fast,
        png::Filter::Adaptive,
    )
}

/// [`indexed_png`] with other deflate and filter settings, to compare them.
pub fn indexed_png_with(
    rows: usize,
    cols: usize,
    indexes: &[u8],
    compression: png::Compression,
    filter: png::Filter,
) -> Result<Vec<u8>, RangeImageError> {
    let too_large = || RangeImageError::TooLarge { rows, cols };
    let width = u32::try_from(cols).map_err(|_| too_large())?;
    let height = u32::try_from(rows).map_err(|_| too_large())?;
    let failed = |source| RangeImageError::Png { rows, cols, source };
    let mut out = Vec::with_capacity(indexes.len() / 4);
    let mut encoder = png::Encoder::new(&mut out, width, height);
    encoder.set_color(png::ColorType::Indexed);
    encoder.set_depth(png::BitDepth::Eight);
    encoder.set_palette(colour::image_palette().concat());
    encoder.set_compression(compression);
    encoder.set_filter(filter);
    let mut writer = encoder.write_header().map_err(failed)?;
    writer.write_image_data(indexes).map_err(failed)?;
    writer.finish().map_err(failed)?;
    Ok(out)
}

/// Entity ids of the three spheres.
pub(crate) const ZONE_IDS: [&str; 3] =
    ["threat_zone_low", "threat_zone_medium", "threat_zone_high"];

/// `/looming/threat_zones`: the equal-looming spheres of the three levels, or,
/// without a velocity, the deletion of the previous ones.
pub fn threat_zones(scan: &Scan, looming: &PairLooming, ttc_s: &[f64; 3]) -> SceneUpdate {
    let Some(spheres) = &looming.spheres else {
        return SceneUpdate {
            deletions: vec![SceneEntityDeletion {
                timestamp: Some(timestamp(scan.stamp_ns)),
                r#type: scene_entity_deletion::Type::All as i32,
                id: String::new(),
            }],
            entities: Vec::new(),
        };
    };
    let entities = spheres
        .iter()
        .zip(ZONE_IDS)
        .zip(ttc_s)
        .map(|((sphere, id), ttc)| {
            let [r, g, b, a] = colour::threat_zone(sphere.level);
            let diameter_m = 2.0 * sphere.radius_m;
            SceneEntity {
                timestamp: Some(timestamp(scan.stamp_ns)),
                frame_id: scan.frame_id.clone(),
                id: id.into(),
                lifetime: None,
                frame_locked: true,
                metadata: vec![
                    key_value("level", &format!("{:?}", sphere.level).to_lowercase()),
                    key_value("time_to_contact_s", &format!("{ttc}")),
                    key_value("looming_per_s", &format!("{:.4}", sphere.looming_per_s)),
                    key_value("radius_m", &format!("{:.3}", sphere.radius_m)),
                ],
                spheres: vec![SpherePrimitive {
                    pose: Some(Pose {
                        position: Some(Vector3 {
                            x: sphere.center_m[0],
                            y: sphere.center_m[1],
                            z: sphere.center_m[2],
                        }),
                        orientation: Some(Quaternion {
                            x: 0.0,
                            y: 0.0,
                            z: 0.0,
                            w: 1.0,
                        }),
                    }),
                    size: Some(Vector3 {
                        x: diameter_m,
                        y: diameter_m,
                        z: diameter_m,
                    }),
                    color: Some(Color { r, g, b, a }),
                }],
                ..SceneEntity::default()
            }
        })
        .collect();
    SceneUpdate {
        deletions: Vec::new(),
        entities,
    }
}

fn key_value(key: &str, value: &str) -> KeyValuePair {
    KeyValuePair {
        key: key.into(),
        value: value.into(),
    }
}

/// `/looming/log`: one warning line announcing a near-miss event.
pub(crate) fn event_log(event: &NearMissEvent) -> Log {
    Log {
        timestamp: Some(timestamp(event.start_ns)),
        level: log::Level::Warning as i32,
        message: event_summary(event),
        name: "looming.events".into(),
        file: String::new(),
        line: 0,
    }
}

/// `/looming/near_misses`: the event as a `foxglove.Event`, the time span a
/// data platform indexes, from its first hot scan to the end of its last
/// one's sweep (header stamps, as every message of ours), with its figures
/// as metadata (`docs/channels.md` lists the keys).
pub(crate) fn near_miss_event(event: &NearMissEvent) -> Event {
    Event {
        start_time: Some(timestamp(event.start_ns)),
        end_time: Some(timestamp(event.end_ns)),
        metadata: near_miss_metadata(event)
            .into_iter()
            .map(|(key, value)| key_value(key, &value))
            .collect(),
    }
}

/// The keys and values of a near miss's `foxglove.Event` (shared with the
/// fleet's `near_miss_events.jsonl`).
pub fn near_miss_metadata(event: &NearMissEvent) -> Vec<(&'static str, String)> {
    let mut metadata = vec![
        ("kind", "near_miss".to_owned()),
        ("event_id", event.id.to_string()),
        (
            "min_time_to_contact_s",
            format!("{:.3}", event.min_time_to_contact_s),
        ),
        (
            "peak_looming_per_s",
            format!("{:.3}", event.peak_looming_per_s),
        ),
        ("range_m", format!("{:.2}", event.peak.range_m)),
        ("bearing_deg", format!("{:.1}", event.peak.azimuth_deg)),
        ("moving", event.moving.to_string()),
        ("frame_id", event.frame_id.clone()),
        ("start_log_time_ns", event.start_log_time_ns.to_string()),
        ("end_log_time_ns", event.end_log_time_ns.to_string()),
        ("peak_log_time_ns", event.peak.log_time_ns.to_string()),
    ];
    if let Some(speed) = event.peak.ego_speed_mps {
        metadata.push(("ego_speed_mps", format!("{speed:.2}")));
    }
    metadata
}

/// One line describing an event, for the log channel and the CLI summary.
pub fn event_summary(event: &NearMissEvent) -> String {
    let side = match event.peak.azimuth_deg {
        a if a > 2.0 => format!("{a:.0} deg left"),
        a if a < -2.0 => format!("{:.0} deg right", -a),
        _ => "ahead".into(),
    };
    let speed = event
        .peak
        .ego_speed_mps
        .map_or(String::new(), |v| format!(", ego {v:.1} m/s"));
    // Several LiDARs: who saw it, and whose view the figures are.
    let seen_by = match &event.sensor {
        Some(sensor) if !event.sensors.is_empty() => {
            format!(
                ", seen by {} (figures of {sensor})",
                event.sensors.join(", ")
            )
        }
        _ => String::new(),
    };
    format!(
        "near miss #{}: min time to contact {:.2} s (looming {:.2} 1/s), {} at {:.1} m, {} object{}, {:.1} s long ({} scans){seen_by}",
        event.id,
        event.min_time_to_contact_s,
        event.peak_looming_per_s,
        side,
        event.peak.range_m,
        if event.moving { "moving" } else { "static" },
        speed,
        event.duration_s,
        event.hot_pairs,
    )
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn an_indexed_png_decodes_to_the_palette_colours() {
        let (rows, cols) = (4, 9);
        let indexes: Vec<u8> = (0..rows * cols)
            .map(|i| (i % colour::PALETTE_LEN) as u8)
            .collect();
        let png = indexed_png(rows, cols, &indexes).unwrap();
        assert_eq!(png, indexed_png(rows, cols, &indexes).unwrap());
        let decoded = image::load_from_memory_with_format(&png, image::ImageFormat::Png)
            .unwrap()
            .to_rgb8();
        assert_eq!((decoded.width(), decoded.height()), (9, 4));
        let palette = colour::image_palette();
        for (pixel, index) in decoded.pixels().zip(&indexes) {
            assert_eq!(pixel.0, palette[usize::from(*index)]);
        }
    }

    /// A pair of the synthetic straight road at 16 x 256 and its result.
    fn small_pair() -> (crate::model::ScanPair, PairLooming) {
        let mut scenario = crate::synth::scene::load("straight-road").unwrap();
        (scenario.lidar.beams, scenario.lidar.columns) = (16, 256);
        let world = crate::synth::sensor::World::new(scenario);
        let pair = crate::synth::simulated_pair(&world, 3, 1);
        let looming = crate::engine::compute(&pair, &Default::default()).expect("an image");
        (pair, looming)
    }

    #[test]
    fn a_range_image_repeats_each_beam_row_and_fails_on_short_values() {
        let (pair, looming) = small_pair();
        let (rows, cols) = (looming.geometry.rows, looming.geometry.cols);
        let image = range_image(&pair.current, &looming, &looming.fused).unwrap();
        let decoded = image::load_from_memory_with_format(&image.data, image::ImageFormat::Png)
            .unwrap()
            .to_rgb8();
        let scale = image_row_scale(rows, cols);
        assert_eq!(
            (decoded.width(), decoded.height()),
            (cols as u32, (rows * scale) as u32)
        );
        let short = &looming.fused[..rows * cols - 1];
        let error = range_image(&pair.current, &looming, short).unwrap_err();
        assert!(
            matches!(error, RangeImageError::Cells { cells, values } if cells == rows * cols && values == cells - 1),
            "{error}"
        );
    }

    #[test]
    fn dimensions_no_png_holds_are_errors() {
        let wide = indexed_png(1, u32::MAX as usize + 1, &[]);
        assert!(matches!(wide, Err(RangeImageError::TooLarge { .. })));
        let empty = indexed_png(0, 0, &[]);
        assert!(matches!(empty, Err(RangeImageError::Png { .. })));
    }
}
