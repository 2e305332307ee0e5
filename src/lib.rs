//! `looming`: looming (inverse time to contact) from LiDAR drive logs in MCAP.
//!
//! The math and the plain data live in the `looming-core` crate, re-exported
//! here: [`model`], [`pairing`], [`engine`], [`events`]. This crate reads and
//! writes the logs: [`input`] (streaming MCAP reader) -> [`decode`] (typed
//! messages) -> [`pairing`] (synchronised scan pairs) -> [`annotate`] (the
//! engine, near misses and our channels) -> [`output`] (MCAP writer);
//! [`pipeline`] wires them together on threads with bounded channels
//! ([`pipeline::process`]) or replays a log's pairs on one thread
//! ([`pipeline::replay()`]). [`commands`] holds the other commands; [`synth`]
//! and [`kitti`] write logs. `docs/ARCHITECTURE.md` draws the layers.

pub use looming_core::{engine, events, model, objects, pairing};

pub mod annotate;
pub mod budget;
pub mod commands;
pub mod decode;
pub mod input;
pub mod kitti;
pub mod output;
pub mod pipeline;
pub mod quality;
pub mod ros;
pub mod synth;
// The fuzz targets' entry points (`fuzz/`, `tests/fuzz_corpus.rs`): behind
// the `fuzzing` feature, so the shipped binary does not carry them.
#[cfg(feature = "fuzzing")]
#[doc(hidden)]
pub mod fuzzing;
// MCAP logs built in memory, for tests, examples and benches only: behind
// the `testkit` feature, so the shipped binary does not carry it.
#[cfg(feature = "testkit")]
pub mod testkit;
pub mod topics;
pub mod truth;
