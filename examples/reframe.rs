//! A log's LiDAR clouds republished outside the sensor frame, as many stacks
//! and datasets publish them (issue #27): every point of `--topic` moved by
//! the translation `X,Y,Z` (the sensor's position in the new frame) and
//! stamped in frame `FRAME`, optionally with a `/tf_static` edge FRAME ->
//! SENSOR_FRAME holding that translation. A development tool for checking
//! that `process` finds the sensor's origin:
//! `cargo run --release --example reframe -- IN.mcap OUT.mcap X,Y,Z FRAME [SENSOR_FRAME]`
//! (KITTI: `0.81,0.32,1.73 base_link velo_link`). Little-endian FLOAT32
//! x, y, z fields only. `DROP_TF=1` leaves the input's `/tf_static` out.

use std::collections::BTreeMap;

use looming::ros::msgs::{
    Header, PointCloud2, Quaternion, TFMessage, Transform, TransformStamped, Vector3,
};

fn main() -> Result<(), Box<dyn std::error::Error>> {
    let args: Vec<String> = std::env::args().collect();
    let [_, input, output, offset, frame, rest @ ..] = args.as_slice() else {
        return Err("IN.mcap OUT.mcap X,Y,Z FRAME [SENSOR_FRAME]".into());
    };
    let offset: Vec<f32> = offset
        .split(',')
        .map(str::parse)
        .collect::<Result<_, _>>()?;
    let sensor_frame = rest.first();
    // DROP_TF=1: the input's own /tf_static left out (the sensor's origin
    // must then come from the geometry).
    let drop_tf = std::env::var_os("DROP_TF").is_some();
    let bytes = std::fs::read(input)?;
    let mut writer = mcap::WriteOptions::new()
        .profile("ros2")
        .create(std::io::BufWriter::new(std::fs::File::create(output)?))?;
    let mut channels: BTreeMap<u16, u16> = BTreeMap::new();
    let mut first_stamp = None;
    let mut first_log_time = u64::MAX;
    for message in mcap::MessageStream::new(&bytes)? {
        let message = message?;
        if drop_tf && message.channel.topic.ends_with("tf_static") {
            continue;
        }
        first_log_time = first_log_time.min(message.log_time);
        let channel = &message.channel;
        let id = match channels.get(&channel.id) {
            Some(id) => *id,
            None => {
                let schema = channel.schema.as_ref().ok_or("a channel without schema")?;
                let schema_id = writer.add_schema(&schema.name, &schema.encoding, &schema.data)?;
                let id = writer.add_channel(
                    schema_id,
                    &channel.topic,
                    &channel.message_encoding,
                    &channel.metadata,
                )?;
                channels.insert(channel.id, id);
                id
            }
        };
        let is_cloud = !channel.topic.starts_with("/truth/")
            && channel
                .schema
                .as_ref()
                .is_some_and(|s| s.name.ends_with("PointCloud2"));
        let data = if is_cloud {
            let mut cloud = PointCloud2::decode_cdr(&message.data)?.into_owned();
            first_stamp.get_or_insert(cloud.header.stamp.to_ns());
            move_points(&mut cloud, &offset)?;
            cloud.header.frame_id = frame.clone();
            cloud.encode_cdr(false)
        } else {
            message.data.to_vec()
        };
        writer.write_to_known_channel(
            &mcap::records::MessageHeader {
                channel_id: id,
                sequence: message.sequence,
                log_time: message.log_time,
                publish_time: message.publish_time,
            },
            &data,
        )?;
    }
    if let (Some(sensor_frame), Some(stamp_ns)) = (sensor_frame, first_stamp) {
        // Before the first cloud in log time, as a recorder latches it.
        let log_time = first_log_time.saturating_sub(1);
        write_tf_static(
            &mut writer,
            frame,
            sensor_frame,
            &offset,
            (stamp_ns, log_time),
        )?;
    }
    writer.finish()?;
    Ok(())
}

/// Add `offset` to the x, y, z of every point.
fn move_points(cloud: &mut PointCloud2<'static>, offset: &[f32]) -> Result<(), String> {
    let field = |name: &str| {
        cloud
            .fields
            .iter()
            .find(|f| f.name == name && f.datatype == looming::ros::msgs::datatype::FLOAT32)
            .map(|f| f.offset as usize)
            .ok_or(format!("no FLOAT32 field {name}"))
    };
    let offsets = [field("x")?, field("y")?, field("z")?];
    let step = cloud.point_step as usize;
    let data = cloud.data.to_mut();
    for point in data.chunks_exact_mut(step) {
        for (k, &at) in offsets.iter().enumerate() {
            let bytes: [u8; 4] = point[at..at + 4].try_into().map_err(|_| "short point")?;
            let value = f32::from_le_bytes(bytes);
            if value.is_finite() {
                point[at..at + 4].copy_from_slice(&(value + offset[k]).to_le_bytes());
            }
        }
    }
    Ok(())
}

/// One `/tf_static` message: `frame` -> `sensor_frame` at `offset`.
fn write_tf_static<W: std::io::Write + std::io::Seek>(
    writer: &mut mcap::Writer<W>,
    frame: &str,
    sensor_frame: &str,
    offset: &[f32],
    (stamp_ns, log_time): (i64, u64),
) -> Result<(), Box<dyn std::error::Error>> {
    let dialect = looming::ros::schemas::RosDialect::Ros2;
    let schema_id = writer.add_schema(
        &dialect.schema_name("tf2_msgs", "TFMessage"),
        dialect.schema_encoding(),
        looming::ros::schemas::tf_message(dialect).as_bytes(),
    )?;
    let mut metadata = BTreeMap::new();
    metadata.insert(
        "offered_qos_profiles".to_string(),
        "- durability: 1\n".to_string(),
    );
    let channel = writer.add_channel(schema_id, "/tf_static", "cdr", &metadata)?;
    let tf = TFMessage {
        transforms: vec![TransformStamped {
            header: Header::new(stamp_ns, frame),
            child_frame_id: sensor_frame.to_owned(),
            transform: Transform {
                translation: Vector3::new(
                    f64::from(offset[0]),
                    f64::from(offset[1]),
                    f64::from(offset[2]),
                ),
                rotation: Quaternion {
                    x: 0.0,
                    y: 0.0,
                    z: 0.0,
                    w: 1.0,
                },
            },
        }],
    };
    writer.write_to_known_channel(
        &mcap::records::MessageHeader {
            channel_id: channel,
            sequence: 0,
            log_time,
            publish_time: log_time,
        },
        &tf.encode_cdr(false),
    )?;
    Ok(())
}
