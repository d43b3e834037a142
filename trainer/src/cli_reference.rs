//! `docs/cli.md`, the command reference, generated from the clap definitions of [`Cli`]: one
//! section per subcommand with its help text, its usage line and every argument (flags,
//! value names, defaults, possible values), in the order clap declares them.
//!
//! The test `cli_reference_is_current` fails when `docs/cli.md` differs from what the
//! definitions generate; `AMPC_BLESS=1 cargo test -p trainer --bin trainer cli_reference`
//! rewrites it.

use crate::cli::Cli;
use clap::{Arg, ArgAction, Command, CommandFactory};
use std::fmt::Write;

/// The whole reference as Markdown.
pub(crate) fn markdown() -> String {
    let mut root = Cli::command();
    root.build();
    let mut md = String::new();
    md.push_str("# Command reference\n\n");
    md.push_str(
        "<!-- Generated from the command line's definitions (trainer/src/cli/) by \
         trainer/src/cli_reference.rs; do not edit. Regenerate with \
         `AMPC_BLESS=1 cargo test -p trainer --bin trainer cli_reference`. -->\n\n",
    );
    if let Some(about) = root.get_about() {
        let _ = writeln!(md, "{about}\n");
    }
    md.push_str(
        "Every command: exit status 0 on success, 1 on a failure (the message names the file, \
         key, state or value at fault), 2 on a usage error. \
         In depth, with file formats: [commands.md](commands.md).\n\n",
    );
    // `help` is clap's own subcommand, added by `build`.
    let listed = |s: &Command| !s.is_hide_set() && s.get_name() != "help";
    let subs: Vec<&Command> = root.get_subcommands().filter(|s| listed(s)).collect();
    for s in &subs {
        let name = s.get_name();
        let _ = writeln!(md, "- [`trainer {name}`](#trainer-{name})");
    }
    md.push('\n');
    for s in root.get_subcommands_mut().filter(|s| listed(s)) {
        command(&mut md, s);
    }
    md
}

/// One subcommand's section.
fn command(md: &mut String, cmd: &mut Command) {
    let _ = writeln!(md, "## `trainer {}`\n", cmd.get_name());
    if let Some(about) = cmd.get_long_about().or(cmd.get_about()) {
        let _ = writeln!(md, "{}\n", about.to_string().trim());
    }
    let usage = cmd.render_usage().to_string();
    let usage = usage.trim().trim_start_matches("Usage:").trim();
    let _ = writeln!(md, "```text\n{usage}\n```\n");
    let args: Vec<&Arg> = cmd
        .get_arguments()
        .filter(|a| !a.is_hide_set())
        .filter(|a| !matches!(a.get_action(), ArgAction::Help | ArgAction::Version))
        .collect();
    if args.is_empty() {
        return;
    }
    for a in args {
        let _ = writeln!(md, "- {}", argument(a));
    }
    md.push('\n');
}

/// One argument: its spelling, then its help, required-ness, default and possible values.
fn argument(a: &Arg) -> String {
    let takes_value = matches!(a.get_action(), ArgAction::Set | ArgAction::Append);
    let value = a
        .get_value_names()
        .and_then(|v| v.first())
        .map(|v| v.to_string())
        .unwrap_or_else(|| a.get_id().to_string())
        .to_uppercase();
    let mut spelling = match (a.get_short(), a.get_long()) {
        (Some(s), Some(l)) => format!("-{s}, --{l}"),
        (None, Some(l)) => format!("--{l}"),
        (Some(s), None) => format!("-{s}"),
        (None, None) => format!("<{value}>"),
    };
    if a.get_long().is_some() || a.get_short().is_some() {
        if takes_value {
            let _ = write!(spelling, " <{value}>");
        }
        if matches!(a.get_action(), ArgAction::Append) {
            spelling.push('…');
        }
    } else if matches!(a.get_action(), ArgAction::Append)
        || a.get_num_args().is_some_and(|n| n.max_values() > 1)
    {
        spelling.push('…');
    }
    let help = a
        .get_long_help()
        .or(a.get_help())
        .map(|h| {
            h.to_string()
                .split_whitespace()
                .collect::<Vec<_>>()
                .join(" ")
        })
        .unwrap_or_default();
    let mut line = format!("`{spelling}`");
    if !help.is_empty() {
        let _ = write!(line, ": {help}");
    }
    let mut notes = Vec::new();
    if a.is_required_set() {
        notes.push("required".to_string());
    }
    let defaults: Vec<String> = a
        .get_default_values()
        .iter()
        .map(|v| v.to_string_lossy().into_owned())
        .collect();
    if !defaults.is_empty() && takes_value {
        notes.push(format!("default `{}`", defaults.join(",")));
    }
    let possible: Vec<String> = a
        .get_possible_values()
        .iter()
        .filter(|p| !p.is_hide_set())
        .map(|p| format!("`{}`", p.get_name()))
        .collect();
    if !possible.is_empty() && takes_value {
        notes.push(format!("one of {}", possible.join(", ")));
    }
    if !notes.is_empty() {
        let _ = write!(line, " ({})", notes.join("; "));
    }
    line
}

#[cfg(test)]
mod tests {
    use super::markdown;

    /// `docs/cli.md` is what the definitions generate (module doc).
    #[test]
    fn cli_reference_is_current() {
        let path = concat!(env!("CARGO_MANIFEST_DIR"), "/../docs/cli.md");
        let generated = markdown();
        if std::env::var_os("AMPC_BLESS").is_some() {
            std::fs::write(path, &generated).unwrap();
        }
        let committed = std::fs::read_to_string(path).unwrap_or_default();
        assert!(
            committed == generated,
            "{path} is stale (or missing): regenerate it with \
             `AMPC_BLESS=1 cargo test -p trainer --bin trainer cli_reference`"
        );
    }

    /// Every subcommand and every flag of one of them appears.
    #[test]
    fn cli_reference_names_every_subcommand_and_flag() {
        let md = markdown();
        for s in [
            "run", "solve", "sample", "train", "certify", "eval", "compare", "export", "refine",
            "merge", "import",
        ] {
            assert!(md.contains(&format!("## `trainer {s}`")), "{s}");
        }
        assert!(
            !md.contains("trainer help"),
            "clap's own help subcommand is not listed"
        );
        for f in [
            "--statistical-band",
            "--c-header <C_HEADER>",
            "--force <FORCE>…",
            "--seeds <SEEDS>",
            "default `10`",
            "`sample`, `validate`",
            "--config <CONFIG_FLAG>",
        ] {
            assert!(md.contains(f), "{f}");
        }
    }
}
