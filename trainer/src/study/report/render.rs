//! Rendering of a [`Report`]: Markdown ([`Report::to_markdown`]) and a self-contained HTML
//! page ([`Report::to_html`]), with the inline markup (`**bold**`, `` `code` ``) and the
//! escaping both need.

use super::{Block, Report, ReportError};
use std::fmt::Write as _;
use std::path::Path;

/// A Markdown table cell: `|` escaped.
fn md_cell(s: &str) -> String {
    s.replace('|', "\\|")
}

impl Report {
    /// Markdown; figures link `plots/<stem>.png` (and the SVG).
    pub fn to_markdown(&self) -> String {
        let mut s = format!("# {}\n\n", self.title);
        for b in &self.blocks {
            match b {
                Block::Heading(l, t) => {
                    let _ = writeln!(s, "{} {t}\n", "#".repeat(usize::from(*l)));
                }
                Block::Para(t) => {
                    let _ = writeln!(s, "{t}\n");
                }
                Block::Table { head, rows } => {
                    let h: Vec<String> = head.iter().map(|c| md_cell(c)).collect();
                    let _ = writeln!(s, "| {} |", h.join(" | "));
                    let _ = writeln!(s, "|{}", "---|".repeat(head.len()));
                    for r in rows {
                        let r: Vec<String> = r.iter().map(|c| md_cell(c)).collect();
                        let _ = writeln!(s, "| {} |", r.join(" | "));
                    }
                    s.push('\n');
                }
                Block::Code(c) => {
                    let _ = writeln!(s, "```sh\n{c}\n```\n");
                }
                Block::Figure { stem, caption } => {
                    let _ = writeln!(
                        s,
                        "![{stem}](plots/{stem}.png)\n\n{caption} ([SVG](plots/{stem}.svg))\n"
                    );
                }
            }
        }
        s
    }

    /// A self-contained HTML page: the same content, tables as HTML tables, the figures'
    /// SVG (read from `dir/plots/`) inline.
    pub fn to_html(&self, dir: &Path) -> Result<String, ReportError> {
        let mut s = String::new();
        let _ = write!(
            s,
            "<!DOCTYPE html>\n<html lang=\"en\">\n<head>\n<meta charset=\"utf-8\">\n<title>{}</title>\n<style>\nbody{{font-family:'DejaVu Sans',sans-serif;max-width:1100px;margin:2em auto;padding:0 1em;line-height:1.45;color:#222}}\ntable{{border-collapse:collapse;margin:0.8em 0;font-size:0.92em}}\nth,td{{border:1px solid #bbb;padding:0.25em 0.6em;text-align:left}}\nth{{background:#eee}}\ncode,pre{{background:#f4f4f4;font-family:'DejaVu Sans Mono',monospace}}\npre{{padding:0.6em;overflow-x:auto}}\nfigure{{margin:1.5em 0}}\nfigure svg{{max-width:100%;height:auto}}\nfigcaption{{font-size:0.92em;color:#444}}\n</style>\n</head>\n<body>\n<h1>{}</h1>\n",
            esc(&self.title),
            esc(&self.title)
        );
        for b in &self.blocks {
            match b {
                Block::Heading(l, t) => {
                    let _ = writeln!(s, "<h{l}>{}</h{l}>", inline(t));
                }
                Block::Para(t) => {
                    let _ = writeln!(s, "<p>{}</p>", inline(t));
                }
                Block::Table { head, rows } => {
                    s += "<table>\n<thead><tr>";
                    for h in head {
                        let _ = write!(s, "<th>{}</th>", inline(h));
                    }
                    s += "</tr></thead>\n<tbody>\n";
                    for r in rows {
                        s += "<tr>";
                        for c in r {
                            let _ = write!(s, "<td>{}</td>", inline(c));
                        }
                        s += "</tr>\n";
                    }
                    s += "</tbody>\n</table>\n";
                }
                Block::Code(c) => {
                    let _ = writeln!(s, "<pre><code>{}</code></pre>", esc(c));
                }
                Block::Figure { stem, caption } => {
                    let p = dir.join("plots").join(format!("{stem}.svg"));
                    let svg = std::fs::read_to_string(&p).map_err(|e| ReportError::file(&p, e))?;
                    let svg = svg
                        .find("<svg")
                        .map_or(svg.as_str(), |i| &svg[i..])
                        .to_string();
                    let _ = writeln!(
                        s,
                        "<figure id=\"{stem}\">\n{svg}\n<figcaption>{} (<a href=\"plots/{stem}.png\">PNG</a>, <a href=\"plots/{stem}.svg\">SVG</a>)</figcaption>\n</figure>",
                        inline(caption)
                    );
                }
            }
        }
        s += "</body>\n</html>\n";
        Ok(s)
    }
}

/// HTML escape.
pub fn esc(s: &str) -> String {
    s.replace('&', "&amp;")
        .replace('<', "&lt;")
        .replace('>', "&gt;")
        .replace('"', "&quot;")
}

/// Escapes and converts `**bold**` and `` `code` `` to HTML.
pub fn inline(s: &str) -> String {
    let mut out = String::new();
    let (mut bold, mut code) = (false, false);
    let mut rest = s;
    while !rest.is_empty() {
        if !code && rest.starts_with("**") {
            out += if bold { "</strong>" } else { "<strong>" };
            bold = !bold;
            rest = &rest[2..];
        } else if rest.starts_with('`') {
            out += if code { "</code>" } else { "<code>" };
            code = !code;
            rest = &rest[1..];
        } else {
            let ch = rest.chars().next().unwrap_or(' ');
            out += &esc(&ch.to_string());
            rest = &rest[ch.len_utf8()..];
        }
    }
    if code {
        out += "</code>";
    }
    if bold {
        out += "</strong>";
    }
    out
}
