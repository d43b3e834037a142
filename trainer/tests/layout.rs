//! The tree is the pipeline: `trainer/src/` has one folder per stage, and a stage imports only
//! the stages before it (and the leaf modules `io`, `rng`), so there is no import cycle.
//! This test reads the sources and checks every `crate::<module>` path outside comments.
//! Within a stage, the module files form no circle either: two sibling modules (files or
//! folders under the same parent) never use each other both ways, through `crate::` or
//! `super::` paths (`sibling_modules_form_no_circle`).

use std::collections::{BTreeMap, BTreeSet};
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

/// The module path a library source file defines (`a/b/mod.rs` and `a/b.rs` → `[a, b]`), or
/// `None` for the crate roots and the binary's `cli/`.
fn module_path(p: &Path) -> Option<Vec<String>> {
    module_of(p)?;
    let rel = p.strip_prefix(src()).unwrap();
    let mut parts: Vec<String> = rel
        .components()
        .map(|c| c.as_os_str().to_string_lossy().to_string())
        .collect();
    let last = parts.pop()?;
    if last != "mod.rs" {
        parts.push(last.trim_end_matches(".rs").to_string());
    }
    Some(parts)
}

/// The code of a file: comment lines dropped, and cut before an inline `#[cfg(test)]`
/// module `mod … {` (tests may use any sibling; the circle rule is about the library's
/// code; a `mod tests;` declaration only skips that line's module, a file of its own).
fn code_of(text: &str) -> String {
    let mut out = String::new();
    let mut lines = text.lines().peekable();
    while let Some(line) = lines.next() {
        let t = line.trim_start();
        if t.starts_with("#[cfg(test)]")
            && lines.peek().is_some_and(|n| {
                let n = n.trim();
                n.starts_with("mod ") && n.ends_with('{')
            })
        {
            break;
        }
        if !t.starts_with("//") {
            out.push_str(line);
            out.push('\n');
        }
    }
    out
}

/// The paths a file's code names through `crate::` or `super::`, each as the module path it
/// starts from plus its segments (a `{…}` group gives one path per element).
fn paths_in(code: &str, own: &[String]) -> Vec<Vec<String>> {
    let ident = |s: &str| -> String {
        s.chars()
            .take_while(|c| c.is_ascii_alphanumeric() || *c == '_')
            .collect()
    };
    let mut out = Vec::new();
    let bytes = code.as_bytes();
    let mut i = 0;
    while i < code.len() {
        let rest = &code[i..];
        let starts = rest.starts_with("crate::") || rest.starts_with("super::");
        let boundary = i == 0
            || !(bytes[i - 1].is_ascii_alphanumeric()
                || bytes[i - 1] == b'_'
                || bytes[i - 1] == b'$'
                || bytes[i - 1] == b':');
        if !(starts && boundary) {
            i += rest.chars().next().map_or(1, char::len_utf8);
            continue;
        }
        // The module the path starts from.
        let mut base: Vec<String> = if rest.starts_with("crate::") {
            Vec::new()
        } else {
            own.to_vec()
        };
        // `super` of module `a::b::c` (file `a/b/c.rs` or `a/b/c/mod.rs`) is `a::b`.
        let mut r = rest;
        if let Some(t) = r.strip_prefix("crate::") {
            r = t;
        }
        while let Some(t) = r.strip_prefix("super::") {
            base.pop();
            r = t;
        }
        let mut segs = Vec::new();
        loop {
            let id = ident(r);
            if id.is_empty() {
                break;
            }
            r = &r[id.len()..];
            segs.push(id);
            match r.strip_prefix("::") {
                Some(t) => r = t,
                None => break,
            }
        }
        if let Some(group) = r.strip_prefix('{') {
            let end = group.find('}').unwrap_or(group.len());
            for item in group[..end].split(',') {
                let mut p = segs.clone();
                p.extend(
                    item.trim()
                        .split("::")
                        .map(ident)
                        .take_while(|id| !id.is_empty()),
                );
                out.push(base.iter().cloned().chain(p).collect());
            }
        } else {
            out.push(base.iter().cloned().chain(segs).collect());
        }
        i += (rest.len() - r.len()).max(1);
    }
    out
}

/// The module graph between siblings: for every use of module B by a file of module A
/// (neither inside the other), the edge between their ancestors just below the common
/// parent.
fn sibling_edges() -> BTreeMap<Vec<String>, BTreeSet<Vec<String>>> {
    let mut files = Vec::new();
    rust_files(&src(), &mut files);
    let units: Vec<(PathBuf, Vec<String>)> = files
        .iter()
        .filter_map(|f| Some((f.clone(), module_path(f)?)))
        .collect();
    let known: BTreeSet<Vec<String>> = units.iter().map(|(_, m)| m.clone()).collect();
    let mut edges: BTreeMap<Vec<String>, BTreeSet<Vec<String>>> = BTreeMap::new();
    for (f, own) in &units {
        if own.iter().any(|s| s == "tests") {
            continue;
        }
        let text = std::fs::read_to_string(f).unwrap();
        for path in paths_in(&code_of(&text), own) {
            // The longest known module prefix of the path is the module it uses.
            let Some(target) = (0..=path.len())
                .rev()
                .map(|k| path[..k].to_vec())
                .find(|p| known.contains(p))
            else {
                continue;
            };
            let common = own.iter().zip(&target).take_while(|(a, b)| a == b).count();
            if common == own.len() || common == target.len() {
                continue; // the same module, a parent or a child
            }
            edges
                .entry(own[..=common].to_vec())
                .or_default()
                .insert(target[..=common].to_vec());
        }
    }
    edges
}

/// Sibling modules that use each other, directly or around a longer circle.
fn circles(edges: &BTreeMap<Vec<String>, BTreeSet<Vec<String>>>) -> Vec<String> {
    let reach = |from: &Vec<String>| {
        let mut seen = BTreeSet::new();
        let mut todo = vec![from.clone()];
        while let Some(n) = todo.pop() {
            for m in edges.get(&n).into_iter().flatten() {
                if seen.insert(m.clone()) {
                    todo.push(m.clone());
                }
            }
        }
        seen
    };
    let mut out = Vec::new();
    for (a, outs) in edges {
        for b in outs {
            if reach(b).contains(a) {
                out.push(format!(
                    "{} uses {}, which leads back",
                    a.join("::"),
                    b.join("::")
                ));
            }
        }
    }
    out
}

#[test]
fn sibling_modules_form_no_circle() {
    let edges = sibling_edges();
    assert!(
        edges.len() > 20,
        "found only {} modules with sibling uses",
        edges.len()
    );
    let bad = circles(&edges);
    assert!(bad.is_empty(), "module circles:\n{}", bad.join("\n"));
}

#[test]
fn the_checker_sees_a_circle() {
    let own = |s: &str| s.split("::").map(String::from).collect::<Vec<_>>();
    // `super::` goes to the parent; a `{…}` group gives one path each; `$crate` skipped.
    assert_eq!(
        paths_in(
            "use super::parse::Func; $crate::x",
            &own("problem::expr::error")
        ),
        vec![own("problem::expr::parse::Func")]
    );
    assert_eq!(
        paths_in("use super::{a, b::C};", &own("data::dataset")),
        vec![own("data::a"), own("data::b::C")]
    );
    let mut edges = BTreeMap::new();
    edges.insert(own("a::b"), BTreeSet::from([own("a::c")]));
    edges.insert(own("a::c"), BTreeSet::from([own("a::d")]));
    assert!(circles(&edges).is_empty());
    edges.insert(own("a::d"), BTreeSet::from([own("a::b")]));
    assert_eq!(circles(&edges).len(), 3);
}

/// `examples/custom_plant.rs` is written against the crate root's facade only: no
/// `trainer::<module>::` path (the facade is what a program needs).
#[test]
fn the_custom_plant_example_uses_only_the_facade() {
    let p = src().join("../examples/custom_plant.rs");
    let text = std::fs::read_to_string(&p).unwrap();
    let deep: Vec<&str> = text
        .lines()
        .filter(|l| {
            l.split("trainer::").skip(1).any(|rest| {
                let word: String = rest
                    .chars()
                    .take_while(|c| c.is_alphanumeric() || *c == '_')
                    .collect();
                word.starts_with(|c: char| c.is_lowercase()) && rest[word.len()..].starts_with("::")
            })
        })
        .collect();
    assert!(deep.is_empty(), "{}: module paths {deep:?}", p.display());
}

/// Longest function of the library and the binary, in lines from its `fn` line to its
/// closing brace (test code and generated files excepted).
const MAX_FN_LINES: usize = 150;

/// Functions over [`MAX_FN_LINES`] whose rewrite is another change's (the refinement rounds,
/// their check and certificate under `certify/refine/`, and the closed-loop simulation):
/// `(file under src/, function)`. An entry that has become short is reported, not failed.
const LONG_FN_ALLOWED: &[(&str, &str)] = &[];

/// The functions of `text` over `max` lines: (name, 1-based `fn` line, lines). A function
/// runs from its `fn` line to the first later line at its indentation starting with `}`;
/// the text is cut before an inline `#[cfg(test)]` module.
fn long_functions(text: &str, max: usize) -> Vec<(String, usize, usize)> {
    let mut lines: Vec<&str> = Vec::new();
    let mut it = text.lines().peekable();
    while let Some(line) = it.next() {
        if line.trim_start().starts_with("#[cfg(test)]")
            && it.peek().is_some_and(|n| {
                let n = n.trim();
                n.starts_with("mod ") && n.ends_with('{')
            })
        {
            break;
        }
        lines.push(line);
    }
    let mut out = Vec::new();
    for (i, line) in lines.iter().enumerate() {
        let mut t = line.trim_start();
        let indent = &line[..line.len() - t.len()];
        while let Some(rest) = ["pub(crate) ", "pub(super) ", "pub ", "const ", "unsafe "]
            .iter()
            .find_map(|p| t.strip_prefix(p))
        {
            t = rest;
        }
        let Some(rest) = t.strip_prefix("fn ") else {
            continue;
        };
        let tail = line.trim_end();
        if tail.ends_with(';') || tail.ends_with('}') {
            continue; // a declaration, or a function on one line
        }
        let name: String = rest
            .chars()
            .take_while(|c| c.is_alphanumeric() || *c == '_')
            .collect();
        // The closing brace: the first later line at this indentation that is not the
        // signature's continuation (`) -> T {`, `where`); anything else ends the search.
        for (j, l) in lines.iter().enumerate().skip(i + 1) {
            let lt = l.trim_start();
            if lt.is_empty() || l.len() - lt.len() > indent.len() {
                continue;
            }
            if l.len() - lt.len() < indent.len() {
                break;
            }
            if lt.starts_with('}') {
                if j - i + 1 > max {
                    out.push((name.clone(), i + 1, j - i + 1));
                }
                break;
            }
            if !(lt.starts_with(')') || lt.starts_with("where") || lt.starts_with('{')) {
                break;
            }
        }
    }
    out
}

#[test]
fn functions_are_short_enough_to_read() {
    let mut files = Vec::new();
    rust_files(&src(), &mut files);
    let mut long = Vec::new();
    let mut allowed_seen = BTreeSet::new();
    for f in &files {
        let rel = f
            .strip_prefix(src())
            .unwrap()
            .to_string_lossy()
            .replace('\\', "/");
        let name = f.file_name().unwrap().to_string_lossy();
        let test_file = name == "tests.rs"
            || name.ends_with("_tests.rs")
            || rel.split('/').any(|c| c == "tests");
        let text = std::fs::read_to_string(f).unwrap();
        if test_file || text.contains("@generated") {
            continue;
        }
        for (func, line, n) in long_functions(&text, MAX_FN_LINES) {
            if LONG_FN_ALLOWED.contains(&(rel.as_str(), func.as_str())) {
                allowed_seen.insert((rel.clone(), func));
            } else {
                long.push(format!("src/{rel}:{line}: fn {func}: {n} lines"));
            }
        }
    }
    for (file, func) in LONG_FN_ALLOWED {
        if !allowed_seen.contains(&(file.to_string(), func.to_string())) {
            eprintln!("note: src/{file} fn {func} is not over {MAX_FN_LINES} lines: drop it from LONG_FN_ALLOWED");
        }
    }
    assert!(
        long.is_empty(),
        "functions over {MAX_FN_LINES} lines:\n{}",
        long.join("\n")
    );
}

#[test]
fn the_checker_sees_a_long_function() {
    let body = "        x += 1;\n".repeat(4);
    let text = format!(
        "pub(crate) fn short() {{}}\nimpl A {{\n    pub fn long(&self) {{\n{body}    }}\n}}\nfn decl();\n#[cfg(test)]\nmod tests {{\n    fn long_test() {{\n{body}    }}\n}}\n"
    );
    assert_eq!(long_functions(&text, 5), vec![("long".to_string(), 3, 6)]);
    assert!(long_functions(&text, 6).is_empty());
}
