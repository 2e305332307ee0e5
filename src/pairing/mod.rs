//! Scan pairing (filled in).
