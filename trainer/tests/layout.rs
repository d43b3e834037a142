//! The tree is the pipeline: `trainer/src/` has one folder per stage, and a stage imports only
//! the stages before it (and the leaf modules `io`, `rng`), so there is no import cycle.
//! This test reads the sources and checks every `crate::<module>` path outside comments.

use std::path::{Path, PathBuf};

/// The library's top-level modules in data-flow order: each may import only those before it.
/// `io` and `rng` are leaves (they import nothing of the crate).
const ORDER: [&str; 11] = [
    "io", "rng", "problem", "robust", "mpc", "data", "learn", "certify", "deploy", "study",
    "pipeline",
];

/// Largest number of lines of a source file (generated files excepted).
const MAX_LINES: usize = 700;

fn src() -> PathBuf {
    Path::new(env!("CARGO_MANIFEST_DIR")).join("src")
}

fn rust_files(dir: &Path, out: &mut Vec<PathBuf>) {
    let mut entries: Vec<_> = std::fs::read_dir(dir)
        .unwrap_or_else(|e| panic!("{}: {e}", dir.display()))
        .map(|e| e.unwrap().path())
        .collect();
    entries.sort();
    for p in entries {
        if p.is_dir() {
            rust_files(&p, out);
        } else if p.extension().is_some_and(|e| e == "rs") {
            out.push(p);
        }
    }
}

/// The top-level module a source file belongs to (`None` for lib.rs, main.rs and cli/).
fn module_of(p: &Path) -> Option<String> {
    let rel = p.strip_prefix(src()).unwrap();
    let first = rel
        .components()
        .next()?
        .as_os_str()
        .to_string_lossy()
        .to_string();
    let name = first.trim_end_matches(".rs").to_string();
    ORDER.contains(&name.as_str()).then_some(name)
}

/// The top-level modules named by `crate::<name>` in the code (comments skipped).
fn imports(text: &str) -> Vec<(usize, String)> {
    let mut out = Vec::new();
    for (i, line) in text.lines().enumerate() {
        let code = line.trim_start();
        if code.starts_with("//") {
            continue;
        }
        let mut rest = code;
        while let Some(k) = rest.find("crate::") {
            let tail = &rest[k + 7..];
            let name: String = tail
                .chars()
                .take_while(|c| c.is_ascii_alphanumeric() || *c == '_')
                .collect();
            if ORDER.contains(&name.as_str()) {
                out.push((i + 1, name));
            }
            rest = tail;
        }
    }
    out
}

#[test]
fn stages_import_only_earlier_stages() {
    let mut files = Vec::new();
    rust_files(&src(), &mut files);
    assert!(files.len() > 20, "found only {} files", files.len());
    let rank = |m: &str| ORDER.iter().position(|o| *o == m).unwrap();
    let mut bad = Vec::new();
    for f in &files {
        let Some(m) = module_of(f) else { continue };
        let text = std::fs::read_to_string(f).unwrap();
        for (line, dep) in imports(&text) {
            let leaf = m == "io" || m == "rng";
            if dep != m && (leaf || rank(&dep) > rank(&m)) {
                bad.push(format!("{}:{line}: `{m}` imports `{dep}`", f.display()));
            }
        }
    }
    assert!(
        bad.is_empty(),
        "imports against the data flow:\n{}",
        bad.join("\n")
    );
}

#[test]
fn the_checker_sees_a_backward_import() {
    let v = imports("use crate::study::plots::Figure;\n// crate::pipeline in a comment\nlet x = crate::io::hex(b);");
    assert_eq!(v, vec![(1, "study".to_string()), (3, "io".to_string())]);
}

#[test]
fn source_files_are_small_enough_to_read() {
    let mut files = Vec::new();
    rust_files(&src(), &mut files);
    let long: Vec<String> = files
        .iter()
        .filter_map(|f| {
            let text = std::fs::read_to_string(f).unwrap();
            let n = text.lines().count();
            (n > MAX_LINES && !text.contains("@generated"))
                .then(|| format!("{}: {n} lines", f.display()))
        })
        .collect();
    assert!(
        long.is_empty(),
        "files over {MAX_LINES} lines:\n{}",
        long.join("\n")
    );
}
