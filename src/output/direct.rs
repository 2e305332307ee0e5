//! The output written past the page cache (Linux's `O_DIRECT`), in whole
//! aligned blocks, while it only grows.
//!
//! Through the page cache every byte of the output is copied once more,
//! into pages the kernel first has to find and zero (reclaiming others'
//! when the memory is full of cache): that copy was 4 % of `process`'
//! CPU on the synthetic 64 x 2048 drive (`copy_folio_from_iter_atomic`,
//! 430 MB in about 0.45 s), more than our own chunks' compression costs
//! per byte. A direct write hands the block to the disk instead, and the
//! writer's thread waits for the device rather than spending a core.
//! The rewrite writer goes back to patch each chunk's header: a patch is
//! made in the block where it still holds those bytes, else through a
//! second handle on the file without the flag (a few bytes through the
//! page cache, below every later direct write). The last partial block
//! goes through the page cache, as do the writes after a seek past the
//! end, and whole files on a file system that refuses direct I/O (tmpfs
//! before Linux 6.6, some FUSE and network file systems): there the flag
//! is refused when set, or the first write fails with `EINVAL`, and the
//! block is written through the cache.

use std::fs::File;
use std::io::{self, Seek, SeekFrom, Write};

/// Alignment of a direct write's memory, length and file offset: the
/// largest logical block size of common devices (most take 512).
const ALIGN: usize = 4096;

/// One block of the output held for a direct write: `block_bytes` (a
/// multiple of [`ALIGN`]) at an aligned address inside `storage`.
pub(super) struct DirectBlocks {
    storage: Vec<u8>,
    /// Where the aligned block starts in `storage`.
    start: usize,
    block_bytes: usize,
    /// Bytes held.
    len: usize,
    /// Bytes of the output before the block's (written directly).
    flushed: u64,
    /// A second handle on the file, through the page cache, for patches of
    /// what the disk already holds ([`Self::patch`]); opened when needed.
    patcher: Option<File>,
    /// Where a seek back set the next writes (a patch of what was
    /// written), always before [`Self::end`]; `None` at the end.
    patch_at: Option<u64>,
}

impl DirectBlocks {
    /// `file` turned to direct I/O, with a block of `block_bytes` (rounded
    /// up to [`ALIGN`]); `None` where the system or the file system does
    /// not take it, or the file's offset is not at a block's start (only
    /// a fresh file is written so).
    pub(super) fn enable(file: &mut File, block_bytes: usize) -> Option<Self> {
        let offset = file.stream_position().ok()?;
        if !offset.is_multiple_of(ALIGN as u64) || !set_direct(file, true) {
            return None;
        }
        let block_bytes = block_bytes.max(1).div_ceil(ALIGN) * ALIGN;
        // An address aligned within a plain vector (no unsafe allocation).
        let storage = vec![0u8; block_bytes + ALIGN];
        let start = storage.as_ptr().align_offset(ALIGN);
        Some(Self {
            storage,
            start,
            block_bytes,
            len: 0,
            flushed: offset,
            patcher: None,
            patch_at: None,
        })
    }

    /// The output's length so far: written and held.
    fn end(&self) -> u64 {
        self.flushed + self.len as u64
    }

    /// Where the next write goes.
    pub(super) fn position(&self) -> u64 {
        self.patch_at.unwrap_or(self.end())
    }

    /// Where the next writes go moved within the output (the mcap rewrite
    /// writer goes back to each chunk's header, then to the end): the new
    /// position; `None`, and nothing moved, past the end.
    pub(super) fn seek(&mut self, pos: SeekFrom) -> Option<u64> {
        let end = self.end();
        let at = match pos {
            SeekFrom::Start(at) => Some(at),
            SeekFrom::Current(by) => self.position().checked_add_signed(by),
            SeekFrom::End(by) => end.checked_add_signed(by),
        }
        .filter(|&at| at <= end)?;
        self.patch_at = (at < end).then_some(at);
        Some(at)
    }

    /// `bytes` written at the position: over what was written there, as
    /// far as the end, where a seek set it back; else into the block, the
    /// block written to `file` when full. How many were taken, and whether
    /// the writes stay direct: where not (the file system refused the
    /// block, or a patch could not be made), the caller leaves direct
    /// writes ([`Self::finish`]) and writes the rest through the cache.
    pub(super) fn write(&mut self, file: &mut File, bytes: &[u8]) -> io::Result<(usize, bool)> {
        if let Some(at) = self.patch_at {
            let patched = (self.end() - at).min(bytes.len() as u64) as usize;
            // (Where the file cannot be opened again nothing was written:
            // the cache takes the patch.)
            if self.patch(file, at, &bytes[..patched]).is_err() {
                return Ok((0, false));
            }
            let next = at + patched as u64;
            self.patch_at = (next < self.end()).then_some(next);
            return Ok((patched, true));
        }
        let taken = self.take(bytes);
        let direct = !self.is_full() || self.write_block(file)?;
        Ok((taken, direct))
    }

    /// `bytes` written over the output from `at` (a patch of what was
    /// written: the mcap writer's chunk headers, `at + bytes.len()` at most
    /// [`Self::end`]): into the block where it holds them, else through a
    /// second handle on `file` without `O_DIRECT` (a few bytes, through
    /// the page cache: the next direct writes lie beyond them). An error
    /// where the file cannot be opened again; nothing is written then.
    fn patch(&mut self, file: &File, at: u64, bytes: &[u8]) -> io::Result<()> {
        let len = bytes.len() as u64;
        if at.checked_add(len).is_none_or(|stop| stop > self.end()) {
            return Err(io::Error::other("a patch past the output's end"));
        }
        // The part the disk holds, then the part the block holds.
        let on_disk = (self.flushed.saturating_sub(at)).min(len) as usize;
        if on_disk > 0 {
            if self.patcher.is_none() {
                self.patcher = Some(reopened(file)?);
            }
            if let Some(patcher) = &self.patcher {
                write_all_at(patcher, &bytes[..on_disk], at)?;
            }
        }
        if on_disk < bytes.len() {
            // From the block's start where the patch began on the disk.
            let from = self.start + (at + on_disk as u64 - self.flushed) as usize;
            self.storage[from..from + bytes.len() - on_disk].copy_from_slice(&bytes[on_disk..]);
        }
        Ok(())
    }

    /// The block moved a byte off its alignment, for the tests to make a
    /// direct write fail as a file system that refuses it does.
    #[cfg(test)]
    pub(super) fn misaligned(mut self) -> Self {
        self.start = if self.start > 0 { self.start - 1 } else { 1 };
        self
    }

    /// As much of `bytes` as the block has room for, copied into it: how
    /// many.
    fn take(&mut self, bytes: &[u8]) -> usize {
        let room = self.block_bytes - self.len;
        let taken = room.min(bytes.len());
        let at = self.start + self.len;
        self.storage[at..at + taken].copy_from_slice(&bytes[..taken]);
        self.len += taken;
        taken
    }

    fn is_full(&self) -> bool {
        self.len == self.block_bytes
    }

    /// The full block written to `file`, directly: `Ok(true)`; or, where
    /// the file system refuses the direct write (`EINVAL`), through the
    /// page cache with the flag cleared: `Ok(false)`, and the caller
    /// writes on without a block.
    fn write_block(&mut self, file: &mut File) -> io::Result<bool> {
        let block = &self.storage[self.start..self.start + self.len];
        let mut written = 0;
        while written < block.len() {
            match file.write(&block[written..]) {
                Ok(0) => return Err(io::ErrorKind::WriteZero.into()),
                Ok(n) => written += n,
                Err(e) if e.kind() == io::ErrorKind::Interrupted => {}
                Err(e) if e.raw_os_error() == Some(libc::EINVAL) => {
                    // Refused (or a short write left the offset unaligned):
                    // the rest through the cache, and no more direct writes.
                    set_direct(file, false);
                    file.write_all(&block[written..])?;
                    self.flushed += self.len as u64;
                    self.len = 0;
                    return Ok(false);
                }
                Err(e) => return Err(e),
            }
        }
        self.flushed += self.len as u64;
        self.len = 0;
        Ok(true)
    }

    /// Back to the page cache: the flag cleared, what the block holds
    /// (less than a block) written through it, and the file's offset at
    /// the position (where a patch left the writes).
    pub(super) fn finish(self, file: &mut File) -> io::Result<()> {
        set_direct(file, false);
        file.write_all(&self.storage[self.start..self.start + self.len])?;
        if let Some(at) = self.patch_at {
            file.seek(SeekFrom::Start(at))?;
        }
        Ok(())
    }
}

/// `file` opened again for writing, as a new open file (without the
/// first's `O_DIRECT`).
#[cfg(target_os = "linux")]
fn reopened(file: &File) -> io::Result<File> {
    use std::os::fd::AsRawFd;
    std::fs::OpenOptions::new()
        .write(true)
        .open(format!("/proc/self/fd/{}", file.as_raw_fd()))
}

#[cfg(not(target_os = "linux"))]
fn reopened(_file: &File) -> io::Result<File> {
    Err(io::ErrorKind::Unsupported.into())
}

/// `bytes` written into `file` at offset `at`, its own offset untouched.
#[cfg(unix)]
fn write_all_at(file: &File, bytes: &[u8], at: u64) -> io::Result<()> {
    use std::os::unix::fs::FileExt;
    file.write_all_at(bytes, at)
}

#[cfg(not(unix))]
fn write_all_at(_file: &File, _bytes: &[u8], _at: u64) -> io::Result<()> {
    Err(io::ErrorKind::Unsupported.into())
}

/// `O_DIRECT` set on (or cleared from) `file`'s open flags: whether that
/// took.
#[cfg(target_os = "linux")]
fn set_direct(file: &File, on: bool) -> bool {
    use std::os::fd::AsRawFd;
    let fd = file.as_raw_fd();
    // SAFETY: `fcntl` on a descriptor this `File` owns and keeps open for
    // the calls; F_GETFL and F_SETFL read and write no memory of ours.
    unsafe {
        let flags = libc::fcntl(fd, libc::F_GETFL);
        if flags < 0 {
            return false;
        }
        let flags = if on {
            flags | libc::O_DIRECT
        } else {
            flags & !libc::O_DIRECT
        };
        libc::fcntl(fd, libc::F_SETFL, flags) == 0
    }
}

#[cfg(not(target_os = "linux"))]
fn set_direct(_file: &File, on: bool) -> bool {
    !on
}
