//! The `looming` command line: argument parsing, progress, summaries and exit
//! codes. All the work is in the library.

mod cli;

use std::process::ExitCode;

use clap::Parser;

fn main() -> ExitCode {
    restore_sigpipe();
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
