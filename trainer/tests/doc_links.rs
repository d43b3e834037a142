//! Every relative link of the documentation resolves: in `README.md`, `BENCHMARKS.md`,
//! `ARCHITECTURE.md` and `docs/*.md`, each Markdown link `[text](target)` outside code whose
//! target is not a URL names an existing file or folder (relative to the linking file), and a
//! `#anchor` on a Markdown file names one of its headings, slugged as a code host does
//! (lower case, punctuation dropped, spaces to hyphens, repeats numbered `-1`, `-2`, …).

use std::collections::HashSet;
use std::path::{Path, PathBuf};

/// The links `[text](target)` of a Markdown text outside fenced code blocks and code spans,
/// with their line numbers.
fn links(text: &str) -> Vec<(usize, String)> {
    let mut out = Vec::new();
    let mut fenced = false;
    for (n, line) in text.lines().enumerate() {
        if line.trim_start().starts_with("```") {
            fenced = !fenced;
            continue;
        }
        if fenced {
            continue;
        }
        // Drop code spans, then find `](`.
        let mut plain = String::new();
        let mut in_code = false;
        for c in line.chars() {
            if c == '`' {
                in_code = !in_code;
            } else if !in_code {
                plain.push(c);
            }
        }
        let mut rest = plain.as_str();
        while let Some(i) = rest.find("](") {
            let after = &rest[i + 2..];
            let Some(end) = after.find(')') else { break };
            let target = after[..end].trim();
            // `[text](target "title")`: the target is the first word.
            let target = target.split_whitespace().next().unwrap_or("");
            out.push((n + 1, target.to_string()));
            rest = &after[end..];
        }
    }
    out
}

/// The anchors a code host gives the headings of a Markdown text.
fn anchors(text: &str) -> HashSet<String> {
    let mut seen = HashSet::new();
    let mut fenced = false;
    for line in text.lines() {
        if line.trim_start().starts_with("```") {
            fenced = !fenced;
            continue;
        }
        if fenced || !line.starts_with('#') {
            continue;
        }
        let title = line.trim_start_matches('#');
        if !title.starts_with(' ') {
            continue;
        }
        let base = slug(title.trim());
        let mut a = base.clone();
        let mut k = 0;
        while seen.contains(&a) {
            k += 1;
            a = format!("{base}-{k}");
        }
        seen.insert(a);
    }
    seen
}

/// A heading's anchor: lower case; letters, digits, `-` and `_` kept, spaces to `-`, every
/// other character dropped.
fn slug(title: &str) -> String {
    title
        .to_lowercase()
        .chars()
        .filter_map(|c| match c {
            ' ' => Some('-'),
            c if c.is_alphanumeric() || c == '-' || c == '_' => Some(c),
            _ => None,
        })
        .collect()
}

/// The broken links of one file: `file:line: target: reason`.
fn broken(file: &Path) -> Vec<String> {
    let text = std::fs::read_to_string(file).unwrap();
    let dir = file.parent().unwrap();
    let mut bad = Vec::new();
    for (line, target) in links(&text) {
        if target.is_empty() || target.contains("://") || target.starts_with("mailto:") {
            continue;
        }
        let (path, anchor) = match target.split_once('#') {
            Some((p, a)) => (p, Some(a)),
            None => (target.as_str(), None),
        };
        let resolved: PathBuf = if path.is_empty() {
            file.to_path_buf()
        } else {
            dir.join(path)
        };
        let at = format!("{}:{line}: {target}", file.display());
        if !resolved.exists() {
            bad.push(format!("{at}: no file {}", resolved.display()));
            continue;
        }
        if let Some(a) = anchor {
            if resolved.extension().is_some_and(|e| e == "md") {
                let headings = anchors(&std::fs::read_to_string(&resolved).unwrap());
                if !headings.contains(a) {
                    bad.push(format!("{at}: no heading with anchor #{a}"));
                }
            }
        }
    }
    bad
}

#[test]
fn every_relative_link_of_the_docs_resolves() {
    let root = Path::new(env!("CARGO_MANIFEST_DIR")).join("..");
    let mut files: Vec<PathBuf> = ["README.md", "BENCHMARKS.md", "ARCHITECTURE.md"]
        .iter()
        .map(|f| root.join(f))
        .collect();
    let docs = root.join("docs");
    let mut pages: Vec<PathBuf> = std::fs::read_dir(&docs)
        .unwrap_or_else(|e| panic!("{}: {e}", docs.display()))
        .map(|e| e.unwrap().path())
        .filter(|p| p.extension().is_some_and(|e| e == "md"))
        .collect();
    pages.sort();
    assert!(!pages.is_empty(), "no Markdown page in {}", docs.display());
    files.extend(pages);
    let bad: Vec<String> = files.iter().flat_map(|f| broken(f)).collect();
    assert!(bad.is_empty(), "broken links:\n{}", bad.join("\n"));
    // The README links into docs/ (the front door leads somewhere).
    let readme = std::fs::read_to_string(root.join("README.md")).unwrap();
    assert!(
        links(&readme).iter().any(|(_, t)| t.starts_with("docs/")),
        "README.md links to no page of docs/"
    );
}

#[test]
fn the_checker_finds_what_it_should() {
    let md =
        "# Title\n## A `[x]` section (with: punctuation)\n## A `[x]` section (with: punctuation)\n\
              see [a](b.md#c) and `[not](a link)`\n```\n[nor](this)\n```\n[t](x \"title\")\n";
    assert_eq!(
        links(md),
        vec![(4, "b.md#c".to_string()), (8, "x".to_string())]
    );
    let a = anchors(md);
    assert!(a.contains("title"));
    assert!(a.contains("a-x-section-with-punctuation"));
    assert!(a.contains("a-x-section-with-punctuation-1"));
    assert_eq!(
        slug("Robust design (the paper's Corollary 1)"),
        "robust-design-the-papers-corollary-1"
    );
    assert_eq!(
        slug("The statistical tier (`--statistical N`)"),
        "the-statistical-tier---statistical-n"
    );
    // A broken file link and a broken anchor are both reported.
    let dir = std::env::temp_dir().join(format!("ampc-doc-links-{}", std::process::id()));
    std::fs::create_dir_all(&dir).unwrap();
    let page = dir.join("p.md");
    std::fs::write(
        &page,
        "# Here\n[ok](p.md#here) [self](#here) [gone](q.md) [bad](p.md#there) [web](https://x.y/z)\n",
    )
    .unwrap();
    let bad = broken(&page);
    std::fs::remove_dir_all(&dir).unwrap();
    assert_eq!(bad.len(), 2, "{bad:?}");
    assert!(bad[0].contains("q.md: no file"), "{bad:?}");
    assert!(bad[1].contains("no heading with anchor #there"), "{bad:?}");
}
