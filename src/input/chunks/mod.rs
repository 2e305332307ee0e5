//! The input's chunks as they are stored, for the pass-through output.
//!
//! [`scan_message_indexes`] runs once when an indexed file is opened: it reads
//! every chunk's message index records (small: 16 bytes a message) and says
//! whether the chunks can be copied byte for byte. [`read`] then hands each
//! chunk record over whole, with its message index records, decompressing
//! only the chunks that hold a channel the pipeline decodes (or every chunk
//! with `--verify`).
//!
//! - [`message_indexes`]: reading the message index records, and whether the
//!   chunks can be copied.
//! - [`unpack`]: decompressing a chunk and checking its size and CRC.
//! - [`copy`]: the copying read itself.

mod copy;
mod message_indexes;
mod unpack;

pub(super) use copy::read;
pub(super) use message_indexes::scan_message_indexes;
pub(super) use unpack::Unpacker;
