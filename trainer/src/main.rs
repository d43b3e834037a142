//! The `trainer` command line: label states, generate and merge datasets.
//!
//! Exit codes: 0 success, 1 failure (the message names the file, state or setting at
//! fault), 2 usage error.

mod cli;

use clap::Parser;

fn main() -> std::process::ExitCode {
    match cli::dispatch(cli::Cli::parse()) {
        Ok(()) => std::process::ExitCode::SUCCESS,
        Err(e) => {
            eprintln!("error: {e:#}");
            std::process::ExitCode::FAILURE
        }
    }
}
