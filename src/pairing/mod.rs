//! Scan pairing: synchronised pairs of consecutive scans with ego motion.

pub mod frames;
pub mod motion;
