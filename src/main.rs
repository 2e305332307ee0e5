//! The `looming` command line: argument parsing, progress, summaries and exit
//! codes. All the work is in the library.

mod cli;

use std::process::ExitCode;

use clap::Parser;

fn main() -> ExitCode {
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
