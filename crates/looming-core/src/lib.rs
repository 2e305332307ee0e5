//! `looming-core`: looming (`L = -(dr/dt)/r`, the inverse of time to
//! contact) from pairs of LiDAR scans, after Yepes & Raviv, "Estimation of
//! Looming from LiDAR". Pure computation, no I/O: what a robot's online
//! stack or a binding embeds. The `looming` crate reads and writes the logs.
//!
//! - [`model`]: plain data: scans, motion samples, the scan pair.
//! - [`pairing`]: [`pairing::ScanPairer`] turns scans and motion samples, in
//!   log-time order, into synchronised scan pairs.
//! - [`engine`]: [`engine::compute`] / [`engine::compute_with_cache`] turn a
//!   pair into per-cell and per-point looming ([`engine::PairLooming`]).
//! - [`objects`]: [`objects::PairObjects::find`] groups a result's
//!   non-ground returns into objects with their looming, and
//!   [`objects::ObjectTracker`] follows them across pairs.
//! - [`events`]: [`events::EventDetector`] turns a stream of results into
//!   near-miss events.

pub mod engine;
pub mod events;
pub mod model;
pub mod objects;
pub mod pairing;

// A small seeded generator for the unit tests of this crate and of `looming`.
#[doc(hidden)]
pub mod test_rng;
