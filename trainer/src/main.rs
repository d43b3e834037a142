//! The `trainer` command line: label states, generate and merge datasets, train, certify,
//! refine, export, and run the whole pipeline (one file per subcommand in `cli/`).
//!
//! Exit codes: 0 success, 1 failure (the message names the file, state or setting at
//! fault), 2 usage error.

mod cli;
#[cfg(test)]
mod cli_reference;

use clap::Parser;

/// The error and its causes on one line, each cause once: error types that already print
/// their source (`"{path}: {source}"`) are not followed by it a second time.
fn message(e: &anyhow::Error) -> String {
    let mut msg = e.to_string();
    for cause in e.chain().skip(1) {
        let c = cause.to_string();
        if !msg.contains(&c) {
            msg = format!("{msg}: {c}");
        }
    }
    msg
}

fn main() -> std::process::ExitCode {
    match cli::dispatch(cli::Cli::parse()) {
        Ok(()) => std::process::ExitCode::SUCCESS,
        Err(e) => {
            eprintln!("error: {}", message(&e));
            std::process::ExitCode::FAILURE
        }
    }
}

#[cfg(test)]
mod tests {
    #[test]
    fn each_cause_is_printed_once() {
        let io = std::io::Error::new(std::io::ErrorKind::NotFound, "gone");
        let e = anyhow::Error::new(trainer::io::FileError::Io {
            path: "f.bin".into(),
            source: io,
        })
        .context("cannot certify");
        assert_eq!(super::message(&e), "cannot certify: f.bin: gone");
    }
}
