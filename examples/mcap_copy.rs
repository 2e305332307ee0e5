//! The floor for `looming process` benchmarks: a plain copy of every message
//! with the mcap crate (read through the summary in log-time order, written with
//! the compression and chunk size `looming process` writes its own chunks
//! with beside passed-through ones), single-threaded.
//! `cargo run --release --example mcap_copy -- IN.mcap OUT.mcap`

use std::io::{BufWriter, Read, Seek, SeekFrom};

use mcap::sans_io::indexed_reader::ReadOrder;
use mcap::sans_io::{
    IndexedReadEvent, IndexedReader, IndexedReaderOptions, SummaryReadEvent, SummaryReader,
};

fn main() -> Result<(), Box<dyn std::error::Error>> {
    let args: Vec<String> = std::env::args().collect();
    let (input, output) = (&args[1], &args[2]);
    let mut file = std::fs::File::open(input)?;
    let mut summary_reader = SummaryReader::new();
    while let Some(event) = summary_reader.next_event() {
        match event? {
            SummaryReadEvent::ReadRequest(n) => {
                let read = file.read(summary_reader.insert(n))?;
                summary_reader.notify_read(read);
            }
            SummaryReadEvent::SeekRequest(to) => summary_reader.notify_seeked(file.seek(to)?),
        }
    }
    let summary = summary_reader.finish().ok_or("no summary")?;
    let mut writer = mcap::WriteOptions::new()
        .chunk_size(Some(4 << 20))
        .compression_level(looming::output::OWN_CHUNKS_ZSTD_LEVEL)
        .compression_threads(0)
        .create(BufWriter::with_capacity(
            1 << 20,
            std::fs::File::create(output)?,
        ))?;
    for schema in summary.schemas.values() {
        writer.add_schema_with_id(schema.id, &schema.name, &schema.encoding, &schema.data)?;
    }
    for channel in summary.channels.values() {
        let schema_id = channel.schema.as_ref().map_or(0, |s| s.id);
        writer.add_channel_with_id(
            channel.id,
            schema_id,
            &channel.topic,
            &channel.message_encoding,
            &channel.metadata,
        )?;
    }
    let mut reader = IndexedReader::new_with_options(
        &summary,
        IndexedReaderOptions::new().with_order(ReadOrder::LogTime),
    )?;
    let mut buffer = Vec::new();
    while let Some(event) = reader.next_event() {
        match event? {
            IndexedReadEvent::ReadChunkRequest { offset, length } => {
                file.seek(SeekFrom::Start(offset))?;
                buffer.resize(length, 0);
                file.read_exact(&mut buffer)?;
                reader.insert_chunk_record_data(offset, &buffer)?;
            }
            IndexedReadEvent::Message { header, data } => {
                writer.write_to_known_channel(&header, data)?
            }
        }
    }
    writer.finish()?;
    Ok(())
}
