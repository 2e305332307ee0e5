//! Decompressing a chunk's records and checking them against its header.

use mcap::records::ChunkHeader;

use crate::input::InputOptions;
use crate::input::indexed::decompress_into;

/// Why a chunk's records cannot be trusted.
pub(in crate::input) enum ChunkFault {
    /// Cannot be decompressed at all.
    Unreadable(String),
    /// Decompressed, but the size or the CRC does not match the header.
    Corrupt(String),
}

impl ChunkFault {
    pub(in crate::input) fn reason(&self) -> &str {
        match self {
            ChunkFault::Unreadable(reason) | ChunkFault::Corrupt(reason) => reason,
        }
    }
}

/// Decompressed over compressed size beyond which a chunk header's size is
/// not trusted to size a buffer up front (real LiDAR logs compress 2-5 x).
const MAX_PLAUSIBLE_RATIO: usize = 64;

/// Decompresses chunks one after another into one reused buffer (and, for
/// zstd, one reused context): a chunk's worth of memory, allocated once.
#[derive(Default)]
pub(in crate::input) struct Unpacker {
    zstd: Option<zstd::bulk::Decompressor<'static>>,
    records: Vec<u8>,
}

impl Unpacker {
    /// The records of the chunk last unpacked (even a corrupt one).
    pub(in crate::input) fn records(&self) -> &[u8] {
        &self.records
    }

    /// Decompress a chunk's records and check their size and CRC against its
    /// header.
    pub(in crate::input) fn unpack(
        &mut self,
        header: &ChunkHeader,
        data: &[u8],
        options: &InputOptions,
    ) -> Result<(), ChunkFault> {
        if header.uncompressed_size > options.record_length_limit as u64 {
            return Err(ChunkFault::Unreadable(format!(
                "uncompressed size {} is above the record limit",
                header.uncompressed_size
            )));
        }
        let expected_size = header.uncompressed_size as usize;
        self.records.clear();
        // The one-shot zstd path sizes its buffer by the header; a header
        // claiming far more than the data could hold (a crafted 1 GiB in a
        // few bytes) goes through the streaming path, whose buffer grows
        // only as the data really decompresses.
        let plausible = expected_size <= data.len().saturating_mul(MAX_PLAUSIBLE_RATIO);
        let decompressed = if header.compression == "zstd" && plausible {
            self.unpack_zstd(data, expected_size)
        } else {
            decompress_into(&header.compression, data, expected_size, &mut self.records)
        };
        decompressed.map_err(|e| ChunkFault::Unreadable(format!("cannot decompress: {e}")))?;
        if self.records.len() != expected_size {
            return Err(ChunkFault::Corrupt(format!(
                "decompressed to {} bytes, header says {expected_size}",
                self.records.len()
            )));
        }
        // A CRC of zero means the writer did not compute one.
        if header.uncompressed_crc != 0 {
            let crc = crc32fast::hash(&self.records);
            if crc != header.uncompressed_crc {
                return Err(ChunkFault::Corrupt(format!(
                    "expected CRC {:08x}, computed {crc:08x}",
                    header.uncompressed_crc
                )));
            }
        }
        Ok(())
    }

    /// One zstd frame straight into the buffer: a frame larger than the
    /// header's size fails instead of growing it.
    fn unpack_zstd(&mut self, data: &[u8], expected_size: usize) -> Result<(), String> {
        let zstd = match &mut self.zstd {
            Some(zstd) => zstd,
            None => self
                .zstd
                .insert(zstd::bulk::Decompressor::new().map_err(|e| e.to_string())?),
        };
        self.records.reserve(expected_size);
        zstd.decompress_to_buffer(data, &mut self.records)
            .map(|_| ())
            .map_err(|e| e.to_string())
    }
}
