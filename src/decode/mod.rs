//! Decoders (filled in).
