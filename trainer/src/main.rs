//! The `trainer` command line: label states, generate and merge datasets, train, certify,
//! refine, export, and run the whole pipeline (one file per subcommand in `cli/`).
//!
//! Exit codes: 0 success, 1 failure (the message names the file, state or setting at
//! fault), 2 usage error.
//!
//! **Standard streams.** `println!`/`print!`/`eprintln!`/`eprint!` are redefined here (so
//! they shadow std's in every `cli/` file): a write to stdout that fails — a full disk
//! (`> /dev/full`), a closed stream — ends the command with exit status 1 and
//! `error: cannot write to stdout: …` on stderr instead of std's panic (exit 101); a broken
//! pipe (`| head`) ends it quietly with status 1. A failed write to stderr is ignored: the
//! diagnostics are lost, the files written and the exit status still tell the outcome.

/// Writes to stdout and stderr whose failures are handled (module doc).
mod stdio {
    use std::io::Write;

    /// Writes `args` (and a newline) to stdout and flushes, or ends the process (module doc).
    pub(crate) fn out(args: std::fmt::Arguments<'_>, newline: bool) {
        let mut o = std::io::stdout().lock();
        let res = o
            .write_fmt(args)
            .and_then(|()| if newline { o.write_all(b"\n") } else { Ok(()) })
            .and_then(|()| o.flush());
        if let Err(e) = res {
            if e.kind() != std::io::ErrorKind::BrokenPipe {
                let _ = writeln!(std::io::stderr(), "error: cannot write to stdout: {e}");
            }
            std::process::exit(1);
        }
    }

    /// Writes `args` (and a newline) to stderr; a failure is ignored (module doc).
    pub(crate) fn err(args: std::fmt::Arguments<'_>, newline: bool) {
        let mut e = std::io::stderr().lock();
        let _ = e
            .write_fmt(args)
            .and_then(|()| if newline { e.write_all(b"\n") } else { Ok(()) });
    }
}

/// `println!` through [`stdio::out`]: a failed write is an error, never a panic.
macro_rules! println {
    () => { $crate::stdio::out(format_args!(""), true) };
    ($($t:tt)*) => { $crate::stdio::out(format_args!($($t)*), true) };
}
/// `print!` through [`stdio::out`].
#[allow(unused_macros)]
macro_rules! print {
    ($($t:tt)*) => { $crate::stdio::out(format_args!($($t)*), false) };
}
/// `eprintln!` through [`stdio::err`]: a failed write to stderr is ignored, never a panic.
macro_rules! eprintln {
    () => { $crate::stdio::err(format_args!(""), true) };
    ($($t:tt)*) => { $crate::stdio::err(format_args!($($t)*), true) };
}
/// `eprint!` through [`stdio::err`].
#[allow(unused_macros)]
macro_rules! eprint {
    ($($t:tt)*) => { $crate::stdio::err(format_args!($($t)*), false) };
}

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
