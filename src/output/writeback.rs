//! The output file with its writeback to disk started as it grows.
//!
//! The output is synced to disk before it is renamed into place
//! (`temp::AtomicTarget::commit`), so that a crash never leaves a complete
//! name on an incomplete file. Without help the kernel keeps a run's whole
//! output dirty in the page cache until then (it starts writing back in
//! the background only past a tenth of the memory, 2.4 GB here, or after
//! 30 s), and that final sync wrote it all while the run waited: 0.5 s of
//! an 18 s run at 64 x 2048 (1.27 GB written), the cores idle. Asking the
//! kernel to start the writeback of what has been written every
//! [`WRITEBACK_BYTES`] (Linux's `sync_file_range`, which starts the writes
//! and returns) overlaps the disk with the run; the final sync then waits
//! for the last few megabytes only. It changes no byte of the output and
//! no guarantee: the sync before the rename still decides, and reports any
//! write error (the early writeback's own errors are left to it).

use std::fs::File;
use std::io::{self, Seek, SeekFrom, Write};

use super::direct::DirectBlocks;

/// Bytes written between two starts of the writeback: a few chunks' worth,
/// so that each start submits large writes.
pub(super) const WRITEBACK_BYTES: u64 = 32 << 20;

/// A [`File`] that starts its writeback to disk every `every_bytes`
/// written.
pub(super) struct WritebackFile {
    file: File,
    every_bytes: u64,
    /// Bytes written since the writeback was last started.
    unsubmitted_bytes: u64,
    /// Times the writeback was started.
    starts: u64,
    /// While written past the page cache, its block for the next direct
    /// write and where the writes go (`direct.rs`); `None` through the
    /// page cache.
    direct: Option<DirectBlocks>,
}

impl WritebackFile {
    pub(super) fn new(file: File, every_bytes: u64) -> Self {
        Self {
            file,
            every_bytes: every_bytes.max(1),
            unsubmitted_bytes: 0,
            starts: 0,
            direct: None,
        }
    }

    /// [`Self::new`], writing past the page cache in blocks of
    /// `block_bytes` where the file system takes it (`direct.rs`).
    pub(super) fn direct(mut file: File, every_bytes: u64, block_bytes: usize) -> Self {
        let direct = DirectBlocks::enable(&mut file, block_bytes);
        Self {
            direct,
            ..Self::new(file, every_bytes)
        }
    }

    /// The file, every byte written to it, for its final sync and rename.
    pub(super) fn into_file(mut self) -> io::Result<File> {
        self.leave_direct()?;
        Ok(self.file)
    }

    /// Whether writes still go past the page cache.
    #[cfg(test)]
    fn is_direct(&self) -> bool {
        self.direct.is_some()
    }

    /// Through the page cache from here on, what the block holds written
    /// (`DirectBlocks::finish`).
    fn leave_direct(&mut self) -> io::Result<()> {
        match self.direct.take() {
            Some(direct) => direct.finish(&mut self.file),
            None => Ok(()),
        }
    }

    /// Times the writeback was started so far.
    #[cfg(test)]
    fn starts(&self) -> u64 {
        self.starts
    }

    fn count(&mut self, written: usize) {
        self.unsubmitted_bytes += written as u64;
        if self.unsubmitted_bytes >= self.every_bytes {
            start_writeback(&self.file);
            self.unsubmitted_bytes = 0;
            self.starts += 1;
        }
    }
}

/// Start writing back every dirty page of `file` not already being
/// written (the whole file: pages written back already are skipped, and
/// the writer may have gone back to patch a header). Advisory: where the
/// call fails or the system has none, the final sync writes them.
#[cfg(target_os = "linux")]
fn start_writeback(file: &File) {
    use std::os::fd::AsRawFd;
    // SAFETY: a plain system call on a file descriptor this `File` owns and
    // keeps open for the call; it reads no memory of ours.
    unsafe {
        libc::sync_file_range(file.as_raw_fd(), 0, 0, libc::SYNC_FILE_RANGE_WRITE);
    }
}

#[cfg(not(target_os = "linux"))]
fn start_writeback(_file: &File) {}

impl Write for WritebackFile {
    fn write(&mut self, buf: &[u8]) -> io::Result<usize> {
        if let Some(direct) = &mut self.direct {
            let (taken, still_direct) = direct.write(&mut self.file, buf)?;
            if !still_direct {
                self.leave_direct()?;
            }
            if taken > 0 || buf.is_empty() {
                return Ok(taken);
            }
        }
        let written = self.file.write(buf)?;
        self.count(written);
        Ok(written)
    }

    fn write_vectored(&mut self, bufs: &[io::IoSlice<'_>]) -> io::Result<usize> {
        if self.direct.is_some() {
            // The first non-empty slice (as `Write`'s own default does).
            let first = bufs.iter().find(|b| !b.is_empty()).map_or(&[][..], |b| b);
            return self.write(first);
        }
        let written = self.file.write_vectored(bufs)?;
        self.count(written);
        Ok(written)
    }

    /// Every byte handed to the file: the direct block's through the page
    /// cache, and no direct write after (only the end of a run flushes).
    fn flush(&mut self) -> io::Result<()> {
        self.leave_direct()?;
        self.file.flush()
    }
}

impl Seek for WritebackFile {
    /// While writing directly, a seek within the output only moves where
    /// the next writes go (`DirectBlocks::seek`); a seek past the end takes
    /// the writes back to the page cache, from where they stood.
    fn seek(&mut self, pos: SeekFrom) -> io::Result<u64> {
        if let Some(direct) = &mut self.direct {
            if let Some(at) = direct.seek(pos) {
                return Ok(at);
            }
            self.leave_direct()?;
        }
        self.file.seek(pos)
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use std::io::Read;

    /// Written past the page cache in whole blocks where the file system
    /// takes it (ext4, xfs, tmpfs since Linux 6.6; elsewhere the cache
    /// takes every write): every byte reaches the file as written, through
    /// blocks filled across writes, patches as the mcap rewrite writer
    /// makes them (a seek back, a few bytes, the position asked, a seek to
    /// the end: into what the disk holds, across the block's start, into
    /// the block), more blocks after them, a seek past the end (the cache
    /// from there) and a tail shorter than a block.
    #[test]
    fn writes_every_byte_past_the_cache_in_blocks_and_patches() {
        let dir = tempfile::tempdir().unwrap();
        let path = dir.path().join("out.bin");
        let block = 8192;
        let mut file = WritebackFile::direct(File::create(&path).unwrap(), 1 << 20, block);
        let direct_at_start = file.is_direct();
        let data: Vec<u8> = (0..30_000u32).map(|i| (i % 251) as u8).collect();
        let mut expected = data.clone();
        for piece in data.chunks(700) {
            file.write_all(piece).unwrap();
        }
        // Three whole blocks written directly, with no fallback.
        assert_eq!(file.stream_position().unwrap(), 30_000);
        for (at, patch) in [
            (10u64, &[7u8, 7][..]),
            (24_570, &[5; 12]),
            (29_990, &[3; 10]),
        ] {
            file.seek(SeekFrom::Start(at)).unwrap();
            file.write_all(patch).unwrap();
            let stop = at as usize + patch.len();
            assert_eq!(file.stream_position().unwrap(), stop as u64);
            expected[at as usize..stop].copy_from_slice(patch);
            assert_eq!(file.seek(SeekFrom::End(0)).unwrap(), 30_000);
        }
        assert_eq!(file.is_direct(), direct_at_start);
        let more: Vec<u8> = (0..20_000u32).map(|i| (i % 7) as u8).collect();
        file.write_all(&more).unwrap();
        expected.extend(&more);
        assert_eq!(file.is_direct(), direct_at_start);
        // Past the end: a hole of zeros, then the cache takes the writes.
        file.seek(SeekFrom::Current(3)).unwrap();
        assert!(!file.is_direct());
        file.write_all(&[9; 5]).unwrap();
        expected.extend([0; 3]);
        expected.extend([9; 5]);
        let file = file.into_file().unwrap();
        file.sync_all().unwrap();
        drop(file);
        let mut read = Vec::new();
        File::open(&path).unwrap().read_to_end(&mut read).unwrap();
        assert_eq!(read, expected);
    }

    /// Where a direct write fails (`EINVAL`: here a block off its
    /// alignment, as a file system refusing direct I/O fails it), the
    /// block goes through the page cache and every write after it: every
    /// byte reaches the file as written. (This machine's ext4 refuses the
    /// misaligned block, so the fallback runs; its tmpfs takes it.)
    #[test]
    fn a_refused_direct_write_falls_back_to_the_page_cache() {
        let dir = tempfile::tempdir().unwrap();
        let path = dir.path().join("out.bin");
        let mut file = WritebackFile::direct(File::create(&path).unwrap(), 1 << 20, 8192);
        file.direct = file.direct.take().map(DirectBlocks::misaligned);
        let data: Vec<u8> = (0..30_000u32).map(|i| (i % 241) as u8).collect();
        for piece in data.chunks(1000) {
            file.write_all(piece).unwrap();
        }
        let fell_back = !file.is_direct();
        let file = file.into_file().unwrap();
        file.sync_all().unwrap();
        drop(file);
        assert_eq!(
            std::fs::read(&path).unwrap(),
            data,
            "fell back: {fell_back}"
        );
    }

    /// A direct file's bytes held in its block when it is taken for the
    /// final sync (no flush first, as `BufWriter::into_inner` leaves it)
    /// are written then.
    #[test]
    fn a_direct_files_last_partial_block_is_written_when_it_is_taken() {
        let dir = tempfile::tempdir().unwrap();
        let path = dir.path().join("out.bin");
        let mut file = WritebackFile::direct(File::create(&path).unwrap(), 1 << 20, 4096);
        let data: Vec<u8> = (0..10_000u32).map(|i| (i % 13) as u8).collect();
        file.write_all(&data).unwrap();
        let file = file.into_file().unwrap();
        file.sync_all().unwrap();
        drop(file);
        assert_eq!(std::fs::read(&path).unwrap(), data);
    }

    /// Every byte reaches the file as written (through a seek back, as the
    /// mcap writer patches a header), and the writeback is started once per
    /// `every_bytes` written.
    #[test]
    fn writes_every_byte_and_starts_the_writeback_as_it_grows() {
        let dir = tempfile::tempdir().unwrap();
        let path = dir.path().join("out.bin");
        let mut file = WritebackFile::new(File::create(&path).unwrap(), 1000);
        let data: Vec<u8> = (0..3500u32).map(|i| (i % 251) as u8).collect();
        for piece in data.chunks(300) {
            file.write_all(piece).unwrap();
        }
        assert_eq!(file.starts(), 3);
        file.seek(SeekFrom::Start(10)).unwrap();
        file.write_all(&[7, 7]).unwrap();
        file.seek(SeekFrom::End(0)).unwrap();
        file.write_all(&[9]).unwrap();
        let file = file.into_file().unwrap();
        file.sync_all().unwrap();
        drop(file);
        let mut expected = data;
        expected[10..12].copy_from_slice(&[7, 7]);
        expected.push(9);
        let mut read = Vec::new();
        File::open(&path).unwrap().read_to_end(&mut read).unwrap();
        assert_eq!(read, expected);
    }
}
