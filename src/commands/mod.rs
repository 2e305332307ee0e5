//! The commands beside `process`, each reading a log and reporting on it:
//! `inspect` (channels and the topics `process` would use), `events` (the
//! near misses of an annotated log), `render` (one pair's looming as a PNG).
//! They use the pipeline's stages; no stage uses them.

pub mod events;
pub mod inspect;
pub mod render;
