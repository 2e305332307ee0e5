//! The annotated output of `looming process`, through the real binary: every
//! `/looming/*` channel decodes with the schema it declares (protobuf
//! descriptors read dynamically with prost-reflect, JSON validated against its
//! JSON Schema) and holds what the engine computed; near-miss events are found
//! where the synthetic scenarios plant them and nowhere else; `--replace`.

mod common;

use std::collections::BTreeMap;
use std::path::{Path, PathBuf};

use common::{FileContents, RawMessage, looming, read_all, scratch, stderr};
use looming::annotate::colour;
use looming::engine::{EngineCache, EngineConfig, PairLooming, ThreatLevel, compute_with_cache};
use looming::model::ScanPair;
use prost_reflect::{DescriptorPool, DynamicMessage, Value};

const POSITION_QUANTUM_M: f32 = looming::annotate::foxglove::POSITION_QUANTUM_M;

/// A 32 x 512 synthetic drive.
fn synth(dir: &Path, scenario: &str, extra: &[&str]) -> PathBuf {
    common::synth(
        dir,
        scenario,
        &[&["--beams", "32", "--columns", "512"], extra].concat(),
    )
}

fn process(input: &Path, output: &Path, extra: &[&str]) {
    let args = [&["--force", "-q"], extra].concat();
    let out = common::looming_process(input, output, &args);
    assert!(out.status.success(), "{}", stderr(&out));
}

/// A protobuf message decoded with the descriptor its channel declares.
fn decode(contents: &FileContents, message: &RawMessage) -> DynamicMessage {
    let channel = &contents.channels[&message.channel_id];
    let schema = channel.schema.as_ref().expect("our channels have schemas");
    assert_eq!(schema.encoding, "protobuf", "{}", channel.topic);
    assert_eq!(channel.message_encoding, "protobuf");
    let pool = DescriptorPool::decode(schema.data.as_slice()).expect("a FileDescriptorSet");
    let descriptor = pool
        .get_message_by_name(&schema.name)
        .unwrap_or_else(|| panic!("{} declares {}", channel.topic, schema.name));
    DynamicMessage::decode(descriptor, message.data.as_slice()).expect("decodes")
}

fn field<'a>(message: &'a DynamicMessage, name: &str) -> std::borrow::Cow<'a, Value> {
    message
        .get_field_by_name(name)
        .unwrap_or_else(|| panic!("no field {name}"))
}

fn stamp_ns(message: &DynamicMessage) -> i64 {
    let ts = field(message, "timestamp");
    let ts = ts.as_message().unwrap();
    field(ts, "seconds").as_i64().unwrap() * 1_000_000_000
        + i64::from(field(ts, "nanos").as_i32().unwrap())
}

/// A decoded foxglove.PointCloud: field name -> (offset, type), stride, data.
struct Cloud {
    fields: BTreeMap<String, (usize, i32)>,
    stride: usize,
    data: Vec<u8>,
    frame_id: String,
    stamp_ns: i64,
}

impl Cloud {
    fn from(message: &DynamicMessage) -> Self {
        let fields = field(message, "fields")
            .as_list()
            .unwrap()
            .iter()
            .map(|f| {
                let f = f.as_message().unwrap();
                (
                    field(f, "name").as_str().unwrap().to_string(),
                    (
                        field(f, "offset").as_u32().unwrap() as usize,
                        field(f, "type").as_enum_number().unwrap(),
                    ),
                )
            })
            .collect();
        let pose = field(message, "pose");
        let pose = pose.as_message().unwrap();
        assert!(pose.has_field_by_name("position") && pose.has_field_by_name("orientation"));
        Self {
            fields,
            stride: field(message, "point_stride").as_u32().unwrap() as usize,
            data: field(message, "data").as_bytes().unwrap().to_vec(),
            frame_id: field(message, "frame_id").as_str().unwrap().to_string(),
            stamp_ns: stamp_ns(message),
        }
    }

    fn len(&self) -> usize {
        assert_eq!(self.data.len() % self.stride, 0);
        self.data.len() / self.stride
    }

    fn f32(&self, point: usize, name: &str) -> f32 {
        let (offset, numeric) = self.fields[name];
        assert_eq!(numeric, 7, "{name} is FLOAT32");
        let at = point * self.stride + offset;
        f32::from_le_bytes(self.data[at..at + 4].try_into().unwrap())
    }

    fn u8(&self, point: usize, name: &str) -> u8 {
        let (offset, numeric) = self.fields[name];
        assert_eq!(numeric, 1, "{name} is UINT8");
        self.data[point * self.stride + offset]
    }

    fn rgba(&self, point: usize) -> [u8; 4] {
        ["red", "green", "blue", "alpha"].map(|c| self.u8(point, c))
    }

    fn xyz(&self, point: usize) -> [f32; 3] {
        ["x", "y", "z"].map(|c| self.f32(point, c))
    }
}

fn same_f32(a: f32, b: f32) -> bool {
    (a.is_nan() && b.is_nan()) || (a - b).abs() <= 1.0 / 2048.0
}

fn close_to_input(written: [f32; 3], input: [f32; 3]) -> bool {
    (0..3).all(|k| (written[k] - input[k]).abs() <= POSITION_QUANTUM_M / 2.0 + 1e-6)
}

/// The engine's results for every pair of `input`, by current log time,
/// with the objects' looming fed back into their cells as `process` does.
fn engine_results(input: &Path) -> BTreeMap<u64, (ScanPair, PairLooming)> {
    engine_results_with(input, &EngineConfig::default())
}

/// [`engine_results`] with the engine set up as `config`.
fn engine_results_with(input: &Path, config: &EngineConfig) -> EngineResults {
    let mut cache = EngineCache::default();
    let mut results = BTreeMap::new();
    let mut tracker = looming::objects::ObjectTracker::default();
    looming::pipeline::replay(
        input,
        &looming::pipeline::ScanOptions::default(),
        &mut |_| {},
        &mut |pair| {
            if let Some(mut result) = compute_with_cache(&pair, config, &mut cache) {
                looming::objects::PairObjects::find_tracked_fused(
                    &pair.current,
                    &mut result,
                    (
                        &looming::objects::ObjectConfig::default(),
                        &config.threat_ttc_s,
                    ),
                    &mut tracker,
                    pair.dt_s,
                );
                results.insert(pair.current_log_time_ns, (pair, result));
            }
        },
    )
    .unwrap();
    results
}

fn validator(schema: &str) -> jsonschema::Validator {
    let schema: serde_json::Value = serde_json::from_str(schema).unwrap();
    jsonschema::validator_for(&schema).expect("a valid JSON Schema")
}

/// The engine's results by current log time, as `engine_results` returns them.
type EngineResults = BTreeMap<u64, (ScanPair, PairLooming)>;

/// The log and the events file are ordinary files (not the temporary file's
/// private mode).
fn assert_readable_by_all(written_files: &[&PathBuf]) {
    #[cfg(unix)]
    for written in written_files {
        use std::os::unix::fs::PermissionsExt;
        let mode = std::fs::metadata(written).unwrap().permissions().mode();
        assert_eq!(mode & 0o044, 0o044, "{} mode {mode:o}", written.display());
    }
}

fn assert_every_looming_channel_present(contents: &FileContents) {
    let topics: Vec<&str> = contents
        .channels
        .values()
        .map(|c| c.topic.as_str())
        .collect();
    for topic in [
        "/looming/points",
        "/looming/disagreement",
        "/looming/threat",
        "/looming/threat_zones",
        "/looming/image/fused",
        "/looming/image/disagreement",
        "/looming/events",
        "/looming/log",
        "/looming/near_misses",
    ] {
        assert!(topics.contains(&topic), "{topic} missing: {topics:?}");
    }
}

/// Every point cloud on `topic`, decoded.
fn decode_clouds(contents: &FileContents, topic: &str) -> Vec<Cloud> {
    contents
        .topic_messages(topic)
        .iter()
        .map(|m| Cloud::from(&decode(contents, m)))
        .collect()
}

/// Points of `/looming/points` the engine found moving, and those it gave a
/// threat level.
#[derive(Default)]
struct PointCounts {
    moving: usize,
    threat: usize,
}

/// `/looming/points` holds, point by point, the input position and what the
/// engine computed for its pair.
fn assert_points_hold_engine_results(
    contents: &FileContents,
    engine: &EngineResults,
) -> PointCounts {
    let mut counts = PointCounts::default();
    let points = contents.topic_messages("/looming/points");
    assert_eq!(points.len(), engine.len());
    for message in &points {
        let (pair, result) = &engine[&message.log_time];
        let scan = &pair.current;
        let cloud = Cloud::from(&decode(contents, message));
        assert_eq!(cloud.frame_id, scan.frame_id);
        assert_eq!(cloud.stamp_ns, scan.stamp_ns);
        assert_eq!(cloud.len(), scan.points_m.len());
        for (i, p) in scan.points_m.iter().enumerate() {
            assert_point_holds_engine_result(&cloud, i, *p, result, &mut counts);
        }
    }
    counts
}

/// Point `i` of `cloud`, at `input_m`, holds the engine's values for it.
fn assert_point_holds_engine_result(
    cloud: &Cloud,
    i: usize,
    input_m: [f32; 3],
    result: &PairLooming,
    counts: &mut PointCounts,
) {
    assert!(close_to_input(cloud.xyz(i), input_m));
    let cell = result.image.surface_cell(i);
    let trusted = cell.filter(|&c| result.mask[c] == 0);
    let fused = trusted.map_or(f32::NAN, |c| result.fused[c]);
    let written = cloud.f32(i, "looming");
    assert!(same_f32(written, fused), "point {i}: {written} vs {fused}");
    assert_eq!(cloud.rgba(i), colour::looming(written));
    let at = |values: &[f32]| cell.map_or(f32::NAN, |c| values[c]);
    assert!(same_f32(cloud.f32(i, "l_lidar"), at(&result.l_lidar)));
    assert!(same_f32(cloud.f32(i, "l_ray_ego"), at(&result.l_ray_ego)));
    assert!(same_f32(
        cloud.f32(i, "disagreement"),
        at(&result.disagreement)
    ));
    assert!(same_f32(cloud.f32(i, "confidence"), at(&result.confidence)));
    assert!(same_f32(cloud.f32(i, "l_ego"), result.l_ego[i]));
    assert_eq!(cloud.u8(i, "threat"), result.point_threat[i] as u8);
    if trusted.is_some_and(|c| result.moving[c]) {
        counts.moving += 1;
    }
    if result.point_threat[i] != ThreatLevel::None {
        counts.threat += 1;
    }
}

/// `/looming/disagreement` holds exactly the moving points, each with a
/// significant disagreement in its colour.
fn assert_disagreement_clouds_hold_moving_points(contents: &FileContents, moving_points: usize) {
    let disagreement = decode_clouds(contents, "/looming/disagreement");
    let written_moving: usize = disagreement.iter().map(Cloud::len).sum();
    assert_eq!(written_moving, moving_points);
    assert!(
        moving_points > 500,
        "the cutting-in car moves: {moving_points}"
    );
    for cloud in &disagreement {
        for i in 0..cloud.len() {
            let d = cloud.f32(i, "disagreement");
            assert!(d.abs() > 0.15, "only significant disagreement: {d}");
            assert_eq!(cloud.rgba(i), colour::looming(d));
        }
    }
}

/// `/looming/threat` holds exactly the threat points, coloured by level.
fn assert_threat_clouds_hold_threat_points(contents: &FileContents, threat_points: usize) {
    let threat = decode_clouds(contents, "/looming/threat");
    assert_eq!(threat.iter().map(Cloud::len).sum::<usize>(), threat_points);
    assert!(threat_points > 100);
    for cloud in &threat {
        for i in 0..cloud.len() {
            let level = cloud.u8(i, "level");
            let expected = [ThreatLevel::Low, ThreatLevel::Medium, ThreatLevel::High]
                .into_iter()
                .find(|l| *l as u8 == level)
                .expect("a threat level");
            assert_eq!(cloud.rgba(i), colour::threat(expected));
        }
    }
}

/// Range images: rows are beams with the highest on top, forward at the centre.
fn assert_range_images_show_engine_values(contents: &FileContents, engine: &EngineResults) {
    for (topic, values) in [
        ("/looming/image/fused", 0),
        ("/looming/image/disagreement", 1),
    ] {
        for message in contents.topic_messages(topic) {
            let (pair, result) = &engine[&message.log_time];
            let values = if values == 0 {
                &result.fused
            } else {
                &result.disagreement
            };
            let image = decode(contents, message);
            assert_range_image_shows(topic, &image, pair, result, values);
        }
    }
}

/// One range image on `topic` shows `values` of the engine's `result`.
fn assert_range_image_shows(
    topic: &str,
    image: &DynamicMessage,
    pair: &ScanPair,
    result: &PairLooming,
    values: &[f32],
) {
    let (rows, cols) = (result.geometry.rows, result.geometry.cols);
    assert_eq!(field(image, "format").as_str(), Some("png"));
    assert_eq!(stamp_ns(image), pair.current.stamp_ns);
    assert_eq!(
        field(image, "frame_id").as_str(),
        Some(&*pair.current.frame_id)
    );
    let png = field(image, "data").as_bytes().unwrap().to_vec();
    let decoded = image::load_from_memory_with_format(&png, image::ImageFormat::Png)
        .expect("a PNG")
        .to_rgb8();
    // Each beam is drawn `scale` pixels tall, so that the image is at most
    // 8 times wider than tall.
    let scale = looming::annotate::foxglove::image_row_scale(rows, cols);
    assert_eq!(scale, cols.div_ceil(rows * 8).clamp(1, 8));
    assert_eq!(decoded.width(), cols as u32);
    assert_eq!(decoded.height(), (rows * scale) as u32);
    let data = decoded.into_raw();
    assert_eq!(data.len(), rows * scale * cols * 3);
    for cell in (0..rows * cols).step_by(7) {
        let (row, col) = (cell / cols, cell % cols);
        let pixel_row = (rows - 1 - row) * scale + (cell / 7) % scale;
        let at = (pixel_row * cols + col) * 3;
        let expected = if result.image.point[cell] == looming::engine::NO_POINT {
            colour::EMPTY
        } else if result.mask[cell] != 0 {
            colour::MASKED
        } else {
            colour::looming(values[cell])
        };
        assert_eq!(data[at..at + 3], expected[..3], "{topic} cell {cell}");
    }
}

/// Threat zones: the equal-looming spheres of the engine.
fn assert_threat_zones_are_engine_spheres(contents: &FileContents, engine: &EngineResults) {
    for message in contents.topic_messages("/looming/threat_zones") {
        let (_, result) = &engine[&message.log_time];
        let update = decode(contents, message);
        let entities = field(&update, "entities");
        let entities = entities.as_list().unwrap();
        let spheres = result.spheres.expect("the drive has a velocity");
        assert_eq!(entities.len(), 3);
        for (entity, sphere) in entities.iter().zip(spheres) {
            let entity = entity.as_message().unwrap();
            let primitive = field(entity, "spheres");
            let primitive = primitive.as_list().unwrap()[0]
                .as_message()
                .unwrap()
                .clone();
            let pose = field(&primitive, "pose");
            let position = field(pose.as_message().unwrap(), "position");
            let position = position.as_message().unwrap();
            let x = field(position, "x").as_f64().unwrap();
            assert!((x - sphere.center_m[0]).abs() < 1e-9);
            let size = field(&primitive, "size");
            let diameter = field(size.as_message().unwrap(), "x").as_f64().unwrap();
            assert!((diameter - 2.0 * sphere.radius_m).abs() < 1e-9);
        }
    }
}

/// Events: JSON valid against the declared schema, the same in the file
/// and in the log line.
fn assert_event_valid_and_same_in_file_and_log(contents: &FileContents, events_path: &Path) {
    let event_schema = contents
        .channels
        .values()
        .find(|c| c.topic == "/looming/events")
        .and_then(|c| c.schema.clone())
        .unwrap();
    assert_eq!(event_schema.encoding, "jsonschema");
    let validate_event = validator(std::str::from_utf8(&event_schema.data).unwrap());
    let events = contents.topic_messages("/looming/events");
    assert_eq!(events.len(), 1, "the cut-in near miss");
    let event_json: serde_json::Value = serde_json::from_slice(&events[0].data).unwrap();
    if let Err(error) = validate_event.validate(&event_json) {
        panic!("event does not match its schema: {error}");
    }
    let file: serde_json::Value =
        serde_json::from_slice(&std::fs::read(events_path).unwrap()).unwrap();
    let validate_file = validator(include_str!(
        "../schemas/looming.NearMissEvents.schema.json"
    ));
    if let Err(error) = validate_file.validate(&file) {
        panic!("events file does not match its schema: {error}");
    }
    assert_eq!(file["events"][0], event_json);
    assert_eq!(
        event_json["start_log_time_ns"].as_u64(),
        Some(events[0].log_time)
    );
    let logs = contents.topic_messages("/looming/log");
    assert_eq!(logs.len(), 1);
    let line = decode(contents, logs[0]);
    assert!(
        field(&line, "message")
            .as_str()
            .unwrap()
            .starts_with("near miss #1: min time to contact")
    );
    assert_near_miss_span(contents, &event_json);
}

/// `/looming/near_misses`: the event as a `foxglove.Event`, its span and
/// figures those of the `/looming/events` message.
fn assert_near_miss_span(contents: &FileContents, event_json: &serde_json::Value) {
    let spans = contents.topic_messages("/looming/near_misses");
    assert_eq!(spans.len(), 1);
    assert_eq!(
        Some(spans[0].log_time),
        event_json["start_log_time_ns"].as_u64()
    );
    let span = decode(contents, spans[0]);
    let time_ns = |name: &str| {
        let ts = field(&span, name);
        let ts = ts.as_message().unwrap();
        field(ts, "seconds").as_i64().unwrap() * 1_000_000_000
            + i64::from(field(ts, "nanos").as_i32().unwrap())
    };
    assert_eq!(Some(time_ns("start_time")), event_json["start_ns"].as_i64());
    assert_eq!(Some(time_ns("end_time")), event_json["end_ns"].as_i64());
    let metadata: BTreeMap<String, String> = field(&span, "metadata")
        .as_list()
        .unwrap()
        .iter()
        .map(|pair| {
            let pair = pair.as_message().unwrap();
            let text = |name| field(pair, name).as_str().unwrap().to_owned();
            (text("key"), text("value"))
        })
        .collect();
    assert_eq!(metadata["kind"], "near_miss");
    assert_eq!(metadata["event_id"], event_json["id"].to_string());
    let ttc: f64 = metadata["min_time_to_contact_s"].parse().unwrap();
    let expected = event_json["min_time_to_contact_s"].as_f64().unwrap();
    assert!((ttc - expected).abs() <= 5e-4, "{ttc} vs {expected}");
    assert_eq!(metadata["moving"], event_json["moving"].to_string());
}

#[test]
fn every_new_channel_decodes_with_its_schema_and_holds_the_engine_result() {
    let dir = scratch("annotate-channels");
    let input = synth(&dir, "cut-in", &["--start", "2.6", "--duration", "3.6"]);
    let output = dir.join("out.mcap");
    let events_path = dir.join("events.json");
    process(
        &input,
        &output,
        &[
            "--fields",
            "full",
            "--events",
            events_path.to_str().unwrap(),
        ],
    );
    assert_readable_by_all(&[&output, &events_path]);
    let contents = read_all(&std::fs::read(&output).unwrap());
    let engine = engine_results(&input);
    assert!(engine.len() >= 9, "{} pairs", engine.len());
    assert_every_looming_channel_present(&contents);

    // Point clouds.
    let counts = assert_points_hold_engine_results(&contents, &engine);
    assert_disagreement_clouds_hold_moving_points(&contents, counts.moving);
    assert_threat_clouds_hold_threat_points(&contents, counts.threat);

    assert_range_images_show_engine_values(&contents, &engine);
    assert_threat_zones_are_engine_spheres(&contents, &engine);
    assert_event_valid_and_same_in_file_and_log(&contents, &events_path);
    let _ = std::fs::remove_dir_all(&dir);
}

#[test]
fn a_coarser_grid_halves_the_columns_and_still_holds_the_engine_result() {
    // `--firings-per-column 2`: two firings of a beam share a cell, so the
    // 512-column sensor is imaged at 256 columns, and every channel holds
    // what the engine computes on that image.
    let dir = scratch("annotate-coarse");
    let input = synth(&dir, "cut-in", &["--start", "2.6", "--duration", "3.2"]);
    let output = dir.join("out.mcap");
    process(
        &input,
        &output,
        &["--firings-per-column", "2", "--fields", "full"],
    );
    let contents = read_all(&std::fs::read(&output).unwrap());
    let config = EngineConfig {
        firings_per_column: 2,
        ..EngineConfig::default()
    };
    let engine = engine_results_with(&input, &config);
    assert!(engine.len() >= 5, "{} pairs", engine.len());
    for (_, result) in engine.values() {
        assert_eq!(
            (result.geometry.rows, result.geometry.cols),
            (32, 256),
            "the coarser image"
        );
    }
    assert_every_looming_channel_present(&contents);
    let counts = assert_points_hold_engine_results(&contents, &engine);
    assert!(
        counts.moving > 0,
        "the cut-in car moves on the coarser image"
    );
    assert_range_images_show_engine_values(&contents, &engine);
    let _ = std::fs::remove_dir_all(&dir);
}

/// Start of a window, seconds into the drive.
fn start_s(stamp_ns: i64) -> f64 {
    // `looming synth` stamps its drives from 1_700_000_000 s.
    (stamp_ns - 1_700_000_000_000_000_000) as f64 * 1e-9
}

#[test]
fn near_misses_are_reported_where_planted_and_nowhere_else() {
    let dir = scratch("annotate-events");
    for scenario in [
        "cut-in",
        "crossing",
        "straight-road",
        "urban-turn",
        "follow",
        "safe-drive",
    ] {
        let input = synth(&dir, scenario, &[]);
        let output = dir.join(format!("{scenario}-out.mcap"));
        let events_path = dir.join(format!("{scenario}-events.json"));
        let file = process_events(&input, &output, &events_path);
        let contents = read_all(&std::fs::read(&input).unwrap());
        let truth: Vec<serde_json::Value> = contents
            .topic_messages("/truth/events")
            .iter()
            .map(|m| serde_json::from_slice(&m.data).unwrap())
            .collect();
        let mut found: Vec<&looming::events::NearMissEvent> = file.events.iter().collect();
        found.sort_by_key(|e| e.start_ns);
        let summary: Vec<String> = found
            .iter()
            .map(|e| {
                format!(
                    "{:.2}-{:.2} s TTC {:.2}",
                    start_s(e.start_ns),
                    start_s(e.end_ns),
                    e.min_time_to_contact_s
                )
            })
            .collect();
        assert_eq!(
            found.len(),
            truth.len(),
            "{scenario}: found {summary:?}, planted {truth:?}"
        );
        for (event, planted) in found.iter().zip(&truth) {
            let planted_start_ns = planted["start_ns"].as_i64().unwrap();
            // Within one scan (0.1 s) of the planted start.
            assert!(
                (event.start_ns - planted_start_ns).abs() <= 100_000_000,
                "{scenario}: found {summary:?}, planted {truth:?}"
            );
            assert!(event.min_time_to_contact_s < 1.5);
            // Each near miss names its object, in the swept path.
            assert!(event.object_id.is_some(), "{scenario}: {event:?}");
            assert!(event.peak.lateral_offset_m <= 1.45, "{scenario}: {event:?}");
        }
        match scenario {
            "cut-in" => {
                // Peak: 1.008 1/s (TTC 0.99 s) planted; the car moves.
                let ttc = found[0].min_time_to_contact_s;
                assert!((ttc - 0.99).abs() < 0.1, "{summary:?}");
                assert!(found[0].moving, "{:?}", found[0]);
            }
            "crossing" => {
                // The first window (TTC 1.40 s) lies wholly in the corridor;
                // the second's planted peak (0.29 s) comes after the
                // pedestrian has left it.
                let ttc = found[0].min_time_to_contact_s;
                assert!((ttc - 1.40).abs() < 0.1, "{summary:?}");
            }
            _ => {}
        }
        if scenario == "cut-in" {
            // Size: the default output stays within twice the input.
            let ratio = std::fs::metadata(&output).unwrap().len() as f64
                / std::fs::metadata(&input).unwrap().len() as f64;
            assert!(ratio <= 2.0, "output is {ratio:.2} times the input");
        }
        // `looming events` lists the same events, ranked.
        let listed = looming(&["events", output.to_str().unwrap(), "--json"]);
        assert!(listed.status.success(), "{}", stderr(&listed));
        let listed: Vec<looming::events::NearMissEvent> =
            serde_json::from_slice(&listed.stdout).unwrap();
        assert_eq!(listed, file.events);
        let _ = std::fs::remove_file(&output);
        let _ = std::fs::remove_file(&input);
    }
    let _ = std::fs::remove_dir_all(&dir);
}

#[test]
fn a_processed_log_is_refused_unless_replace_which_writes_fresh_channels() {
    let dir = scratch("annotate-replace");
    let input = synth(&dir, "cut-in", &["--start", "2.8", "--duration", "3.4"]);
    let first = dir.join("first.mcap");
    process(&input, &first, &[]);
    let refused = common::looming_process(&first, &dir.join("again.mcap"), &[]);
    assert_eq!(refused.status.code(), Some(2));
    let message = stderr(&refused);
    assert!(
        message.contains("/looming/points") && message.contains("--replace"),
        "{message}"
    );
    let second = dir.join("second.mcap");
    process(&first, &second, &["--replace"]);
    let (a, b) = (
        read_all(&std::fs::read(&first).unwrap()),
        read_all(&std::fs::read(&second).unwrap()),
    );
    // Each of our topics once, with the same messages as the first run.
    let topics = |c: &FileContents| {
        let mut t: Vec<String> = c.channels.values().map(|c| c.topic.clone()).collect();
        t.sort();
        t
    };
    assert_eq!(topics(&a), topics(&b));
    for topic in topics(&a) {
        let data = |c: &FileContents| -> Vec<(u64, Vec<u8>)> {
            c.topic_messages(&topic)
                .iter()
                .map(|m| (m.log_time, m.data.clone()))
                .collect()
        };
        assert_eq!(data(&a), data(&b), "{topic}");
    }
    assert_eq!(
        b.metadata.iter().filter(|m| m.name == "looming").count(),
        1,
        "one run record"
    );
    let _ = std::fs::remove_dir_all(&dir);
}

/// A copy of `input` with only the LiDAR, the transforms and the truth: no
/// IMU, no velocity source.
fn lidar_only(input: &Path, output: &Path) {
    common::rewrite_mcap(input, output, |message| {
        let topic = message.channel.topic.as_str();
        (topic == "/lidar/points" || topic.starts_with("/tf") || topic.starts_with("/truth"))
            .then_some(message)
    });
}

/// `process INPUT OUTPUT --events FILE`, and the events it wrote.
fn process_events(input: &Path, output: &Path, events_path: &Path) -> looming::events::EventsFile {
    process(input, output, &["--events", events_path.to_str().unwrap()]);
    serde_json::from_slice(&std::fs::read(events_path).unwrap()).unwrap()
}

#[test]
fn on_a_lidar_only_log_the_near_miss_is_judged_with_the_estimated_motion() {
    // Without a velocity source the engine estimates the motion from the
    // static world; the near-miss corridor and the ego speed must come from
    // that estimate (they once came from the missing source: the LiDAR's x
    // axis and no speed).
    let dir = scratch("annotate-lidar-only-events");
    let full = synth(&dir, "cut-in", &["--start", "2", "--duration", "5"]);
    let input = dir.join("cut-in-lidar-only.mcap");
    lidar_only(&full, &input);
    let file = process_events(
        &input,
        &dir.join("cut-in-lidar-only-out.mcap"),
        &dir.join("events.json"),
    );
    assert_eq!(file.events.len(), 1, "{:?}", file.events);
    let event = &file.events[0];
    assert_eq!(event.corridor, looming::events::PathSource::EgoMotion);
    // The planted near miss: TTC about 1 s from 2.9 s, the ego at 12 m/s
    // braking from 2.9 s.
    let speed = event.peak.ego_speed_mps.expect("the estimated speed");
    assert!((3.0..=12.5).contains(&speed), "{speed}");
    assert!(event.min_time_to_contact_s < 1.5, "{event:?}");
    let _ = std::fs::remove_dir_all(&dir);
}

#[test]
fn an_object_beside_the_swept_path_is_never_a_near_miss() {
    // safe-drive's oncoming cars pass 2.5 m from the LiDAR's path, looming
    // 5 1/s: outside the default swept path (1.9 m vehicle, 0.5 m margin
    // either side: 1.45 m), no near miss; a path widened to 2.95 m takes them
    // in, which shows the gate, not the looming, keeps them out.
    let dir = scratch("annotate-swept-path");
    let input = synth(&dir, "safe-drive", &[]);
    let default = process_events(&input, &dir.join("default.mcap"), &dir.join("default.json"));
    assert!(default.events.is_empty(), "{:?}", default.events);
    assert_eq!(default.config.vehicle_width_m, 1.9);
    assert_eq!(default.config.path_margin_m, 0.5);
    let wide_events = dir.join("wide.json");
    process(
        &input,
        &dir.join("wide.mcap"),
        &[
            "--path-margin",
            "2.0",
            "--events",
            wide_events.to_str().unwrap(),
        ],
    );
    let wide: looming::events::EventsFile =
        serde_json::from_slice(&std::fs::read(&wide_events).unwrap()).unwrap();
    assert!(
        !wide.events.is_empty(),
        "the oncoming cars in a 2.95 m path"
    );
    for event in &wide.events {
        let offset = event.peak.lateral_offset_m;
        assert!((1.45..=2.95).contains(&offset), "{event:?}");
        assert!(event.object_id.is_some(), "{event:?}");
    }
    // A width that is not a width is refused.
    let refused = common::looming_process(&input, &dir.join("bad.mcap"), &["--vehicle-width", "0"]);
    assert_eq!(refused.status.code(), Some(2));
    assert!(
        stderr(&refused).contains("--vehicle-width"),
        "{}",
        stderr(&refused)
    );
    let _ = std::fs::remove_dir_all(&dir);
}
