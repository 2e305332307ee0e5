//! ROS wire formats: ROS 2 CDR (XCDR1) and ROS 1 serialization readers/writers
//! ([`cdr`]), the raw message structs built on them ([`msgs`]), and the schema
//! texts we write for them ([`schemas`]).
//!
//! Everything here works on borrowed byte slices and never does I/O. Every read
//! is bounds-checked and untrusted sizes are checked against the remaining bytes
//! before anything is allocated, so malformed input yields a [`DecodeError`],
//! never a panic or a huge allocation.

pub mod cdr;
pub mod msgs;
pub mod schemas;

/// Why a message payload could not be decoded.
///
/// Byte offsets are absolute positions in the payload (for CDR they include the
/// 4-byte encapsulation header), so they can be checked with a hex dump.
#[derive(Debug, Clone, PartialEq, thiserror::Error)]
pub enum DecodeError {
    /// A read ran past the end of the payload.
    #[error("payload truncated at byte {offset} reading {what} (need {need}, have {have})")]
    Truncated {
        offset: usize,
        what: &'static str,
        need: usize,
        have: usize,
    },

    /// The CDR encapsulation header is not plain CDR (XCDR1) LE/BE.
    #[error(
        "unsupported CDR encapsulation 0x{0:04x} (only plain CDR 0x0000 big-endian and 0x0001 little-endian are supported)"
    )]
    UnsupportedEncapsulation(u16),

    /// A sequence length prefix claims more elements than the remaining bytes can hold.
    #[error(
        "sequence at byte {offset} claims {count} elements of at least {min_element_bytes} bytes each, but only {remaining} bytes remain"
    )]
    SequenceTooLong {
        offset: usize,
        count: u32,
        min_element_bytes: usize,
        remaining: usize,
    },

    /// A string is not valid UTF-8.
    #[error("string at byte {offset} is not valid UTF-8")]
    InvalidUtf8 { offset: usize },

    /// A CDR string does not end with the NUL its length prefix includes.
    #[error("CDR string at byte {offset} is not NUL-terminated")]
    StringNotNulTerminated { offset: usize },

    /// The point cloud is larger than [`crate::decode::DecodeLimits::max_points`].
    #[error("point cloud has {points} points, more than the limit of {max_points}")]
    TooManyPoints { points: u64, max_points: usize },

    /// `data` is shorter than the layout in the cloud's header requires.
    #[error(
        "PointCloud2 data is {data_bytes} bytes but width*height*point_step needs {needed_bytes} (height {height}, width {width}, point_step {point_step}, row_step {row_step})"
    )]
    PointCloudDataTooShort {
        data_bytes: usize,
        needed_bytes: u64,
        height: u32,
        width: u32,
        point_step: u32,
        row_step: u32,
    },

    /// Inconsistent point cloud layout (e.g. rows overlapping, zero stride).
    #[error("invalid point cloud layout: {0}")]
    InvalidPointLayout(String),

    /// A required coordinate field is absent.
    #[error("point cloud has no `{0}` field")]
    MissingField(&'static str),

    /// A used field does not fit inside one point.
    #[error(
        "point field `{name}` at offset {offset} with {size} bytes does not fit in point_step {point_step}"
    )]
    FieldOutOfBounds {
        name: String,
        offset: u32,
        size: usize,
        point_step: u32,
    },

    /// A stamp's nanoseconds are a second or more: no writer means that.
    #[error("header stamp has {nanosec} nanoseconds (at most 999999999)")]
    StampOutOfRange { nanosec: u32 },

    /// A value the tool uses is NaN or infinite.
    #[error("{field} is not finite ({value})")]
    NotFinite { field: &'static str, value: String },

    /// Two coordinate fields share bytes: the points would be garbage.
    #[error(
        "point fields `{first}` and `{second}` overlap (bytes {first_bytes:?} and {second_bytes:?})"
    )]
    FieldsOverlap {
        first: &'static str,
        second: &'static str,
        first_bytes: std::ops::Range<usize>,
        second_bytes: std::ops::Range<usize>,
    },

    /// A used field has a datatype code this decoder does not know.
    #[error("point field `{name}` has unsupported datatype {datatype}")]
    UnsupportedFieldType { name: String, datatype: i64 },

    /// A quaternion that must describe a rotation is zero or not finite.
    #[error("{context}: quaternion ({x}, {y}, {z}, {w}) is not a valid rotation")]
    InvalidQuaternion {
        context: String,
        x: f64,
        y: f64,
        z: f64,
        w: f64,
    },

    /// The protobuf payload could not be parsed.
    #[error("invalid protobuf payload: {0}")]
    Protobuf(#[from] prost::DecodeError),

    /// The message kind is never carried in this wire encoding.
    #[error("message kind {kind} cannot be decoded from {encoding} encoding")]
    UnsupportedEncoding {
        kind: &'static str,
        encoding: &'static str,
    },
}
