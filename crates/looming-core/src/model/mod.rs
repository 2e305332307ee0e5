//! Plain data shared by the pipeline's stages: decoded scans and samples, the
//! scan pair the engine consumes, its motion, and log-time formatting. No I/O
//! and no logic beyond small accessors: every stage depends on this module and
//! it depends on none of them.

pub mod layout;
pub mod motion;
pub mod origin;
pub mod pair;
pub mod samples;
pub mod scan;
pub mod time;

pub use layout::{DroppedRingField, RingSource, Rotation, ScanLayout, TimeSource};
pub use motion::{
    AngularSource, ExtrinsicInfo, ExtrinsicSource, MotionSample, PairMotion, TimeSeries,
};
pub use origin::{OriginSource, SensorOrigin};
pub use pair::ScanPair;
pub use samples::{Decoded, FrameTransform, ImuSample, VelocitySample, VelocitySourceKind};
pub use scan::{Scan, SensorIds, StampNs};
pub use time::format_log_time;
