//! The `looming` command line: argument parsing, progress, summaries and exit
//! codes. All the work is in the library.

mod cli;

use std::process::ExitCode;

use clap::Parser;

fn main() -> ExitCode {
    // First: a CPU without the instructions of the build's target level
    // (x86-64-v3, `.cargo/config.toml`) would die of SIGILL at the first
    // one, with no word of why.
    cli::cpu::exit_unless_supported();
    restore_sigpipe();
    keep_freed_memory();
    let args = cli::Cli::parse();
    cli::stop_on_ctrl_c();
    match cli::run(args) {
        Ok(()) => ExitCode::SUCCESS,
        Err(failure) => {
            // Library errors carry their causes in their own messages.
            let hint = cli::hint(&failure.error).unwrap_or_default();
            eprintln!("error: {}{hint}", failure.error);
            ExitCode::from(failure.code as u8)
        }
    }
}

/// Each scan pair allocates and frees images of a few megabytes. glibc's
/// malloc serves blocks that large with `mmap` and returns them on free, so
/// every pair faulted and zeroed its pages afresh: half a million page
/// faults and 5 % of the CPU on a 100-scan 64 x 2048 log. Blocks up to the
/// largest threshold glibc allows (32 MiB on 64-bit) now come from the heap,
/// and up to 64 MiB freed at its top stays with the process for the next
/// pair. Peak RSS on 64 x 2048 logs: 240 MiB on 30 s, 268 MiB on 90 s and
/// 253 MiB on 150 s (233 MiB on 90 s before): bounded, not growing with
/// the log.
fn keep_freed_memory() {
    #[cfg(all(target_os = "linux", target_env = "gnu"))]
    // SAFETY: called in main before any thread exists; mallopt only tunes
    // the allocator's thresholds (a rejected value leaves them unchanged).
    unsafe {
        libc::mallopt(libc::M_MMAP_THRESHOLD, 32 << 20);
        libc::mallopt(libc::M_TRIM_THRESHOLD, 64 << 20);
    }
}

/// Rust ignores SIGPIPE, so a write to a closed pipe (`looming events --json |
/// head`) fails and `println!` panics. Restore the default: the process ends
/// quietly when the reader goes away, as `cat` or `grep` do.
fn restore_sigpipe() {
    #[cfg(unix)]
    // SAFETY: called first thing in main, before any thread exists; it only
    // resets one signal's disposition to the system default.
    unsafe {
        libc::signal(libc::SIGPIPE, libc::SIG_DFL);
    }
}
