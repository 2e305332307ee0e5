//! `looming`: looming (inverse time to contact) from LiDAR drive logs in MCAP.
//!
//! Pipeline stages, one module each:
//! [`input`] (streaming MCAP reader) -> [`decode`] (typed messages) ->
//! [`pairing`] (synchronised scan pairs) -> [`output`] (MCAP writer);
//! [`pipeline`] wires them together on threads with bounded channels.

pub mod annotate;
pub mod budget;
pub mod commands;
pub mod decode;
pub mod engine;
pub mod eval;
pub mod events;
pub mod fixtures;
pub mod input;
pub mod kitti;
pub mod model;
pub mod output;
pub mod pairing;
pub mod pipeline;
pub mod quality;
pub mod quality_report;
pub mod ros;
pub mod synth;
pub mod topics;

#[cfg(test)]
mod test_rng;
