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
}

impl WritebackFile {
    pub(super) fn new(file: File, every_bytes: u64) -> Self {
        Self {
            file,
            every_bytes: every_bytes.max(1),
            unsubmitted_bytes: 0,
            starts: 0,
        }
    }

    /// The file, for its final sync and rename.
    pub(super) fn into_file(self) -> File {
        self.file
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
        let written = self.file.write(buf)?;
        self.count(written);
        Ok(written)
    }

    fn write_vectored(&mut self, bufs: &[io::IoSlice<'_>]) -> io::Result<usize> {
        let written = self.file.write_vectored(bufs)?;
        self.count(written);
        Ok(written)
    }

    fn flush(&mut self) -> io::Result<()> {
        self.file.flush()
    }
}

impl Seek for WritebackFile {
    fn seek(&mut self, pos: SeekFrom) -> io::Result<u64> {
        self.file.seek(pos)
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use std::io::Read;

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
        let file = file.into_file();
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
