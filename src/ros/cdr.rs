//! Zero-copy readers and matching writers for the two ROS wire formats.
//!
//! * ROS 2 plain CDR (XCDR1): 4-byte encapsulation header (`00 01` little-endian,
//!   `00 00` big-endian, then 2 option bytes), primitives aligned to their own
//!   size relative to the first byte after the header, strings as u32 length
//!   (including the trailing NUL) + bytes + NUL, sequences as u32 count + elements.
//! * ROS 1: little-endian, no alignment, no header, strings as u32 length + bytes
//!   (no NUL), variable arrays as u32 count + elements.
//!
//! Message codecs are written once against [`WireRead`] / [`WireWrite`]; the
//! only message-level difference (the ROS 1 `Header.seq` and unsigned time) is
//! keyed on [`WireRead::IS_ROS1`].

use super::DecodeError;

/// Encapsulation identifier of plain CDR, big-endian.
const CDR_BE: u16 = 0x0000;
/// Encapsulation identifier of plain CDR, little-endian.
const CDR_LE: u16 = 0x0001;
/// Size of the CDR encapsulation header; alignment is relative to its end.
const CDR_HEADER_BYTES: usize = 4;

/// A bounds-checked reader over a borrowed payload.
pub trait WireRead<'a> {
    /// True for ROS 1 serialization (Header has `seq`, time is unsigned).
    const IS_ROS1: bool;

    /// Absolute byte position in the payload (for error messages).
    fn position(&self) -> usize;
    /// Bytes left after the current position.
    fn remaining(&self) -> usize;

    fn read_u8(&mut self) -> Result<u8, DecodeError>;
    fn read_u32(&mut self) -> Result<u32, DecodeError>;
    fn read_i32(&mut self) -> Result<i32, DecodeError>;
    fn read_f64(&mut self) -> Result<f64, DecodeError>;
    /// A string borrowed from the payload.
    fn read_str(&mut self) -> Result<&'a str, DecodeError>;
    /// `n` raw bytes borrowed from the payload (no alignment).
    fn read_bytes(&mut self, n: usize, what: &'static str) -> Result<&'a [u8], DecodeError>;

    /// A `bool` (one byte; any non-zero value is true).
    fn read_bool(&mut self) -> Result<bool, DecodeError> {
        Ok(self.read_u8()? != 0)
    }

    /// A sequence / variable-array length prefix. `min_element_bytes` is a lower
    /// bound on the encoded size of one element; the count is refused when the
    /// remaining bytes cannot possibly hold it, so callers may allocate `count`.
    fn read_seq_len(&mut self, min_element_bytes: usize) -> Result<usize, DecodeError> {
        let offset = self.position();
        let count = self.read_u32()?;
        let remaining = self.remaining();
        let needed = u64::from(count) * min_element_bytes.max(1) as u64;
        if needed > remaining as u64 {
            return Err(DecodeError::SequenceTooLong {
                offset,
                count,
                min_element_bytes,
                remaining,
            });
        }
        Ok(count as usize)
    }

    /// A fixed-size array of float64 (no length prefix in either format).
    fn read_f64_array<const N: usize>(&mut self) -> Result<[f64; N], DecodeError> {
        let mut out = [0.0; N];
        for v in &mut out {
            *v = self.read_f64()?;
        }
        Ok(out)
    }
}

/// A writer producing one of the two wire formats.
pub trait WireWrite {
    /// True for ROS 1 serialization (Header has `seq`, time is unsigned).
    const IS_ROS1: bool;

    fn write_u8(&mut self, v: u8);
    fn write_u32(&mut self, v: u32);
    fn write_i32(&mut self, v: i32);
    fn write_f64(&mut self, v: f64);
    fn write_str(&mut self, s: &str);
    /// Raw bytes, no alignment, no length prefix.
    fn write_bytes(&mut self, bytes: &[u8]);
    /// The finished payload.
    fn into_bytes(self) -> Vec<u8>;

    fn write_bool(&mut self, v: bool) {
        self.write_u8(u8::from(v));
    }

    /// Sequence length prefix. Panics only if `len` exceeds `u32::MAX`, which
    /// no encodable ROS message can hold.
    fn write_seq_len(&mut self, len: usize) {
        let len = u32::try_from(len).expect("sequence longer than u32::MAX elements");
        self.write_u32(len);
    }

    fn write_f64_array(&mut self, values: &[f64]) {
        for &v in values {
            self.write_f64(v);
        }
    }
}

/// Builds the truncation error for a read of `need` bytes at `offset`.
fn truncated(offset: usize, what: &'static str, need: usize, have: usize) -> DecodeError {
    DecodeError::Truncated {
        offset,
        what,
        need,
        have,
    }
}

/// Takes exactly `N` bytes at `pos`, bounds-checked.
#[inline]
fn take_array<const N: usize>(
    buf: &[u8],
    pos: usize,
    what: &'static str,
) -> Result<[u8; N], DecodeError> {
    let have = buf.len().saturating_sub(pos);
    buf.get(pos..pos.saturating_add(N))
        .and_then(|s| <[u8; N]>::try_from(s).ok())
        .ok_or_else(|| truncated(pos, what, N, have))
}

/// The next `n` bytes of `buf` from `pos`, or a truncation error.
fn take_slice<'a>(
    buf: &'a [u8],
    pos: usize,
    n: usize,
    what: &'static str,
) -> Result<&'a [u8], DecodeError> {
    buf.get(pos..pos.saturating_add(n))
        .ok_or_else(|| truncated(pos, what, n, buf.len().saturating_sub(pos)))
}

/// Reader for ROS 2 plain CDR (XCDR1), either endianness.
#[derive(Debug, Clone)]
pub struct CdrReader<'a> {
    buf: &'a [u8],
    pos: usize,
    big_endian: bool,
}

impl<'a> CdrReader<'a> {
    /// Parses the encapsulation header; rejects anything but plain CDR LE/BE.
    pub fn new(payload: &'a [u8]) -> Result<Self, DecodeError> {
        let header: [u8; CDR_HEADER_BYTES] = take_array(payload, 0, "CDR encapsulation header")?;
        let big_endian = match u16::from_be_bytes([header[0], header[1]]) {
            CDR_LE => false,
            CDR_BE => true,
            other => return Err(DecodeError::UnsupportedEncapsulation(other)),
        };
        Ok(Self {
            buf: payload,
            pos: CDR_HEADER_BYTES,
            big_endian,
        })
    }

    /// True when the payload is big-endian CDR.
    pub fn is_big_endian(&self) -> bool {
        self.big_endian
    }

    /// Skips padding so the next `size`-byte primitive is aligned (relative to
    /// the end of the encapsulation header).
    fn align(&mut self, size: usize, what: &'static str) -> Result<(), DecodeError> {
        let rel = self.pos - CDR_HEADER_BYTES;
        let pad = (size - rel % size) % size;
        if pad > self.remaining() {
            return Err(truncated(self.pos, what, pad + size, self.remaining()));
        }
        self.pos += pad;
        Ok(())
    }

    #[inline]
    fn primitive<const N: usize>(&mut self, what: &'static str) -> Result<[u8; N], DecodeError> {
        self.align(N, what)?;
        let bytes = take_array::<N>(self.buf, self.pos, what)?;
        self.pos += N;
        Ok(bytes)
    }

    /// An aligned number in the payload's byte order.
    #[inline]
    fn number<const N: usize, T>(
        &mut self,
        what: &'static str,
        from_be: fn([u8; N]) -> T,
        from_le: fn([u8; N]) -> T,
    ) -> Result<T, DecodeError> {
        let bytes = self.primitive::<N>(what)?;
        Ok(if self.big_endian {
            from_be(bytes)
        } else {
            from_le(bytes)
        })
    }
}

impl<'a> WireRead<'a> for CdrReader<'a> {
    const IS_ROS1: bool = false;

    fn position(&self) -> usize {
        self.pos
    }

    fn remaining(&self) -> usize {
        self.buf.len() - self.pos
    }

    fn read_u8(&mut self) -> Result<u8, DecodeError> {
        Ok(self.primitive::<1>("uint8")?[0])
    }

    fn read_u32(&mut self) -> Result<u32, DecodeError> {
        self.number("uint32", u32::from_be_bytes, u32::from_le_bytes)
    }

    fn read_i32(&mut self) -> Result<i32, DecodeError> {
        self.number("int32", i32::from_be_bytes, i32::from_le_bytes)
    }

    fn read_f64(&mut self) -> Result<f64, DecodeError> {
        self.number("float64", f64::from_be_bytes, f64::from_le_bytes)
    }

    fn read_str(&mut self) -> Result<&'a str, DecodeError> {
        let len = self.read_u32()? as usize;
        let start = self.pos;
        let bytes = self.read_bytes(len, "string")?;
        // Length 0 is not valid XCDR1, but some writers emit it for "".
        let Some((&last, text)) = bytes.split_last() else {
            return Ok("");
        };
        if last != 0 {
            return Err(DecodeError::StringNotNulTerminated { offset: start });
        }
        std::str::from_utf8(text).map_err(|_| DecodeError::InvalidUtf8 { offset: start })
    }

    fn read_bytes(&mut self, n: usize, what: &'static str) -> Result<&'a [u8], DecodeError> {
        let bytes = take_slice(self.buf, self.pos, n, what)?;
        self.pos += n;
        Ok(bytes)
    }
}

/// Reader for ROS 1 serialization.
#[derive(Debug, Clone)]
pub struct Ros1Reader<'a> {
    buf: &'a [u8],
    pos: usize,
}

impl<'a> Ros1Reader<'a> {
    pub fn new(payload: &'a [u8]) -> Self {
        Self {
            buf: payload,
            pos: 0,
        }
    }

    #[inline]
    fn primitive<const N: usize>(&mut self, what: &'static str) -> Result<[u8; N], DecodeError> {
        let bytes = take_array::<N>(self.buf, self.pos, what)?;
        self.pos += N;
        Ok(bytes)
    }
}

impl<'a> WireRead<'a> for Ros1Reader<'a> {
    const IS_ROS1: bool = true;

    fn position(&self) -> usize {
        self.pos
    }

    fn remaining(&self) -> usize {
        self.buf.len() - self.pos
    }

    fn read_u8(&mut self) -> Result<u8, DecodeError> {
        Ok(self.primitive::<1>("uint8")?[0])
    }

    fn read_u32(&mut self) -> Result<u32, DecodeError> {
        Ok(u32::from_le_bytes(self.primitive("uint32")?))
    }

    fn read_i32(&mut self) -> Result<i32, DecodeError> {
        Ok(i32::from_le_bytes(self.primitive("int32")?))
    }

    fn read_f64(&mut self) -> Result<f64, DecodeError> {
        Ok(f64::from_le_bytes(self.primitive("float64")?))
    }

    fn read_str(&mut self) -> Result<&'a str, DecodeError> {
        let len = self.read_u32()? as usize;
        let start = self.pos;
        let bytes = self.read_bytes(len, "string")?;
        std::str::from_utf8(bytes).map_err(|_| DecodeError::InvalidUtf8 { offset: start })
    }

    fn read_bytes(&mut self, n: usize, what: &'static str) -> Result<&'a [u8], DecodeError> {
        let bytes = take_slice(self.buf, self.pos, n, what)?;
        self.pos += n;
        Ok(bytes)
    }
}

/// Writer for ROS 2 plain CDR (XCDR1), either endianness.
#[derive(Debug, Clone)]
pub(crate) struct CdrWriter {
    buf: Vec<u8>,
    big_endian: bool,
}

impl CdrWriter {
    /// Starts a payload with the plain-CDR encapsulation header.
    pub fn new(big_endian: bool) -> Self {
        let id = if big_endian { CDR_BE } else { CDR_LE };
        let mut buf = Vec::with_capacity(256);
        buf.extend_from_slice(&id.to_be_bytes());
        buf.extend_from_slice(&[0, 0]); // options
        Self { buf, big_endian }
    }

    fn align(&mut self, size: usize) {
        let rel = self.buf.len() - CDR_HEADER_BYTES;
        let pad = (size - rel % size) % size;
        self.buf.resize(self.buf.len() + pad, 0);
    }

    fn primitive<const N: usize>(&mut self, le: [u8; N], be: [u8; N]) {
        self.align(N);
        self.buf
            .extend_from_slice(if self.big_endian { &be } else { &le });
    }
}

impl WireWrite for CdrWriter {
    const IS_ROS1: bool = false;

    fn write_u8(&mut self, v: u8) {
        self.buf.push(v);
    }

    fn write_u32(&mut self, v: u32) {
        self.primitive(v.to_le_bytes(), v.to_be_bytes());
    }

    fn write_i32(&mut self, v: i32) {
        self.primitive(v.to_le_bytes(), v.to_be_bytes());
    }

    fn write_f64(&mut self, v: f64) {
        self.primitive(v.to_le_bytes(), v.to_be_bytes());
    }

    fn write_str(&mut self, s: &str) {
        self.write_seq_len(s.len() + 1);
        self.buf.extend_from_slice(s.as_bytes());
        self.buf.push(0);
    }

    fn write_bytes(&mut self, bytes: &[u8]) {
        self.buf.extend_from_slice(bytes);
    }

    fn into_bytes(self) -> Vec<u8> {
        self.buf
    }
}

/// Writer for ROS 1 serialization.
#[derive(Debug, Clone, Default)]
pub(crate) struct Ros1Writer {
    buf: Vec<u8>,
}

impl Ros1Writer {
    pub fn new() -> Self {
        Self::default()
    }
}

impl WireWrite for Ros1Writer {
    const IS_ROS1: bool = true;

    fn write_u8(&mut self, v: u8) {
        self.buf.push(v);
    }

    fn write_u32(&mut self, v: u32) {
        self.buf.extend_from_slice(&v.to_le_bytes());
    }

    fn write_i32(&mut self, v: i32) {
        self.buf.extend_from_slice(&v.to_le_bytes());
    }

    fn write_f64(&mut self, v: f64) {
        self.buf.extend_from_slice(&v.to_le_bytes());
    }

    fn write_str(&mut self, s: &str) {
        self.write_seq_len(s.len());
        self.buf.extend_from_slice(s.as_bytes());
    }

    fn write_bytes(&mut self, bytes: &[u8]) {
        self.buf.extend_from_slice(bytes);
    }

    fn into_bytes(self) -> Vec<u8> {
        self.buf
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn cdr_header_variants() {
        assert!(!CdrReader::new(&[0, 1, 0, 0]).unwrap().is_big_endian());
        assert!(CdrReader::new(&[0, 0, 0, 0]).unwrap().is_big_endian());
        let err = CdrReader::new(&[0, 7, 0, 0]).unwrap_err();
        assert_eq!(err, DecodeError::UnsupportedEncapsulation(7));
        assert!(err.to_string().contains("0x0007"), "{err}");
        // XCDR2 little-endian (0x0007) and PL_CDR LE (0x0003) are refused.
        assert_eq!(
            CdrReader::new(&[0, 3, 0, 0]).unwrap_err(),
            DecodeError::UnsupportedEncapsulation(3)
        );
        assert!(matches!(
            CdrReader::new(&[0, 1]).unwrap_err(),
            DecodeError::Truncated {
                need: 4,
                have: 2,
                ..
            }
        ));
    }

    #[test]
    fn cdr_alignment_is_relative_to_header_end() {
        // u8 at rel 0, then u32 aligned to rel 4, then f64 aligned to rel 8.
        let bytes = [
            0, 1, 0, 0, // header LE
            9, 0xAA, 0xAA, 0xAA, // u8 + 3 padding
            5, 0, 0, 0, // u32
            0, 0, 0, 0, 0, 0, 0xF0, 0x3F, // f64 1.0
        ];
        let mut r = CdrReader::new(&bytes).unwrap();
        assert_eq!(r.read_u8().unwrap(), 9);
        assert_eq!(r.read_u32().unwrap(), 5);
        assert_eq!(r.read_f64().unwrap(), 1.0);
        assert_eq!(r.remaining(), 0);

        let mut w = CdrWriter::new(false);
        w.write_u8(9);
        w.write_u32(5);
        w.write_f64(1.0);
        let out = w.into_bytes();
        assert_eq!(out.len(), bytes.len());
        assert_eq!(&out[8..], &bytes[8..]);
    }

    #[test]
    fn truncated_error_reports_position() {
        let bytes = [0, 1, 0, 0, 1, 2, 3, 4, 5, 6, 7, 8, 1, 2, 3];
        let mut r = CdrReader::new(&bytes).unwrap();
        r.read_f64().unwrap();
        let err = r.read_f64().unwrap_err();
        assert_eq!(
            err.to_string(),
            "payload truncated at byte 12 reading float64 (need 8, have 3)"
        );
    }

    #[test]
    fn strings_both_formats() {
        let cdr = [0, 0, 0, 0, 0, 0, 0, 3, b'a', b'b', 0];
        assert_eq!(CdrReader::new(&cdr).unwrap().read_str().unwrap(), "ab");
        let no_nul = [0, 0, 0, 0, 0, 0, 0, 2, b'a', b'b'];
        assert_eq!(
            CdrReader::new(&no_nul).unwrap().read_str().unwrap_err(),
            DecodeError::StringNotNulTerminated { offset: 8 }
        );
        let ros1 = [2, 0, 0, 0, b'a', b'b'];
        assert_eq!(Ros1Reader::new(&ros1).read_str().unwrap(), "ab");
        let bad_utf8 = [1, 0, 0, 0, 0xFF];
        assert_eq!(
            Ros1Reader::new(&bad_utf8).read_str().unwrap_err(),
            DecodeError::InvalidUtf8 { offset: 4 }
        );
    }

    #[test]
    fn zero_length_cdr_string_reads_as_empty() {
        let bytes = [0, 1, 0, 0, 0, 0, 0, 0];
        assert_eq!(CdrReader::new(&bytes).unwrap().read_str().unwrap(), "");
    }

    #[test]
    fn big_endian_primitives() {
        let mut w = CdrWriter::new(true);
        w.write_i32(-2);
        w.write_f64(1.0);
        let bytes = w.into_bytes();
        assert_eq!(
            bytes,
            [
                0, 0, 0, 0, 0xff, 0xff, 0xff, 0xfe, 0, 0, 0, 0, 0x3f, 0xf0, 0, 0, 0, 0, 0, 0
            ]
        );
        let mut r = CdrReader::new(&bytes).unwrap();
        assert_eq!(r.read_i32().unwrap(), -2);
        assert_eq!(r.read_f64().unwrap(), 1.0);
    }

    #[test]
    fn huge_sequence_count_is_refused_before_allocation() {
        let bytes = [0xFF, 0xFF, 0xFF, 0xFF, 1, 2, 3];
        let err = Ros1Reader::new(&bytes).read_seq_len(1).unwrap_err();
        assert_eq!(
            err,
            DecodeError::SequenceTooLong {
                offset: 0,
                count: u32::MAX,
                min_element_bytes: 1,
                remaining: 3
            }
        );
    }
}
