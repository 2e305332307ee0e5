//! The commands beside `process`, each reading a log and reporting on it:
//! `inspect` (channels and the topics `process` would use), `events` (the
//! near misses of an annotated log), `quality` (its quality figures and
//! diagnoses), `render` (one pair's looming as a PNG) and `eval` (the engine
//! against ground truth).
//! They use the pipeline's stages; no stage uses them.

mod annotated;
pub mod batch;
pub mod clips;
pub mod eval;
pub mod events;
pub mod inspect;
pub mod layout;
pub mod quality;
pub mod render;
