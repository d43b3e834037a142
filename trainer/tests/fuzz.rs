//! Fuzzing every reader of the trainer: the problem file (TOML, including the
//! `[system]` expression language), the states CSV of `solve`/`eval`, the import CSV, and the
//! artifact decoders — dataset, labelling checkpoint (`.partial`), model, refinement
//! checkpoint, certificate JSON, pipeline manifest, ONNX. (`controller-core`'s `blob::decode`
//! has its own 10⁶-case proptest there.)
//!
//! Inputs: arbitrary bytes, and structured mutations of valid files made by the `trainer`
//! binary — byte flips, insertions, deletions, truncations, duplicated ranges; for the sealed
//! binary formats also mutated bodies re-sealed with a correct checksum (so the decoder
//! behind the checksum is reached); for problem files TOML tables with keys and values
//! replaced, deleted or added, and expressions built from the grammar's tokens.
//!
//! Property of every target: no panic, bounded time per input ([`LIMIT`]); `Ok` only for input
//! that is the original or round-trips (re-encoding the decoded value decodes to the same
//! bytes), and every `Err` names the file (or the setting) at fault.
//!
//! Beside the readers, [`nan_plants`]: expression plants whose arithmetic gives NaN or ±∞ —
//! never a label there, never a certificate from them.
//!
//! `cargo test -p trainer --test fuzz` runs [`SMOKE`] cases per target; the full counts
//! (`fuzz_*`, ignored) run with `cargo test -p trainer --test fuzz -- --ignored`
//! (see BENCHMARKS.md for the counts and times). Fixed RNG seed: the same inputs every run.

use proptest::collection::vec;
use proptest::prelude::*;
use proptest::test_runner::{Config, RngSeed, TestCaseError, TestRunner};
use std::path::{Path, PathBuf};
use std::sync::OnceLock;
use std::time::{Duration, Instant};
use trainer::certify::certificate::Certificate;
use trainer::certify::refine::RefineState;
use trainer::certify::Model;
use trainer::data::dataset::{checkpoint, Dataset};
use trainer::problem::ProblemConfig;

/// Expression plants with NaN/∞-producing terms: no label and no certificate from them.
#[path = "fuzz/nan_plants.rs"]
mod nan_plants;
use nan_plants::nan_plants;

/// Cases per target in the default (debug) test run.
const SMOKE: u32 = 48;
/// Longest time one input may take (a hang is a failure).
const LIMIT: Duration = Duration::from_secs(2);

fn runner(cases: u32) -> TestRunner {
    TestRunner::new(Config {
        rng_seed: RngSeed::Fixed(0x616d_7063),
        failure_persistence: None,
        ..Config::with_cases(cases)
    })
}

/// Runs `f` and fails the case if it takes longer than [`LIMIT`].
fn timed<T>(what: &str, f: impl FnOnce() -> T) -> Result<T, TestCaseError> {
    let t = Instant::now();
    let v = f();
    let dt = t.elapsed();
    if dt > LIMIT {
        return Err(TestCaseError::fail(format!("{what}: {dt:?} for one input")));
    }
    Ok(v)
}

// ---------------------------------------------------------------------------------------
// Valid inputs, made once by the trainer binary on a small problem.

struct Valid {
    dir: PathBuf,
    problems: Vec<(String, String)>,
    dataset: Vec<u8>,
    model: Vec<u8>,
    certificate: String,
    refine_state: Vec<u8>,
    onnx: Vec<u8>,
    manifest: String,
}

fn run(args: &[&str]) {
    let o = std::process::Command::new(env!("CARGO_BIN_EXE_trainer"))
        .args(args)
        .output()
        .expect("run trainer");
    assert!(
        o.status.success(),
        "trainer {args:?}: {}",
        String::from_utf8_lossy(&o.stderr)
    );
}

fn valid() -> &'static Valid {
    static V: OnceLock<Valid> = OnceLock::new();
    V.get_or_init(|| {
        let dir = std::env::temp_dir().join(format!("ampc-fuzz-{}", std::process::id()));
        let _ = std::fs::remove_dir_all(&dir);
        std::fs::create_dir_all(&dir).unwrap();
        let configs = Path::new(env!("CARGO_MANIFEST_DIR")).join("../configs");
        let mut problems: Vec<(String, String)> = std::fs::read_dir(&configs)
            .unwrap()
            .map(|e| e.unwrap().path())
            .filter(|p| p.extension().is_some_and(|e| e == "toml"))
            .map(|p| {
                (
                    p.file_name().unwrap().to_string_lossy().to_string(),
                    std::fs::read_to_string(&p).unwrap(),
                )
            })
            .collect();
        problems.sort();
        let di = &problems
            .iter()
            .find(|(n, _)| n == "double_integrator.toml")
            .expect("configs/double_integrator.toml")
            .1;
        let small = di.replace("counts = [21, 11]", "counts = [6, 4]");
        assert_ne!(
            &small, di,
            "the double integrator's grid changed: update this test"
        );
        let cfg = dir.join("p.toml");
        std::fs::write(
            &cfg,
            format!(
                "{small}\n[training]\nepochs = 10\nvalidation_n = 10\nlog_every = 50\n\n\
                 [refine]\nbudget = 60\ninitial = [4, 3]\nmax_rounds = 2\ntarget_eps = 100.0\n\n\
                 [refine.training]\nhidden = [4]\nepochs = 10\nvalidation_n = 10\n"
            ),
        )
        .unwrap();
        let s = |p: &str| dir.join(p).to_str().unwrap().to_string();
        let c = s("p.toml");
        run(&["sample", "--config", &c, "--out", &s("d.bin"), "--quiet"]);
        run(&[
            "train",
            "--data",
            &s("d.bin"),
            "--out",
            &s("m.bin"),
            "--quiet",
        ]);
        let o = std::process::Command::new(env!("CARGO_BIN_EXE_trainer"))
            .args([
                "certify",
                "--model",
                &s("m.bin"),
                "--data",
                &s("d.bin"),
                "--json",
            ])
            .output()
            .unwrap();
        assert!(o.status.success(), "{}", String::from_utf8_lossy(&o.stderr));
        let certificate = String::from_utf8(o.stdout).unwrap();
        std::fs::write(dir.join("c.json"), &certificate).unwrap();
        run(&[
            "export",
            "--model",
            &s("m.bin"),
            "--certificate",
            &s("c.json"),
            "--onnx",
            &s("m.onnx"),
        ]);
        run(&["refine", "--config", &c, "--out", &s("ref"), "--quiet"]);
        // A pipeline manifest (the format `trainer run` writes, read before skipping a stage).
        let hashes = |k: &str, c: &str| {
            std::iter::once((k.to_string(), c.repeat(32)))
                .collect::<std::collections::BTreeMap<_, _>>()
        };
        let manifest = serde_json::to_string_pretty(&trainer::pipeline::manifest::Manifest {
            stage: "sample".into(),
            version: "0.1.0".into(),
            inputs: hashes("problem", "cd"),
            outputs: vec!["dataset.bin".into()],
            output_hashes: hashes("dataset.bin", "ab"),
            seconds: 0.25,
        })
        .unwrap();
        Valid {
            problems,
            dataset: std::fs::read(dir.join("d.bin")).unwrap(),
            model: std::fs::read(dir.join("m.bin")).unwrap(),
            certificate,
            refine_state: std::fs::read(dir.join("ref/refine_state.bin")).unwrap(),
            onnx: std::fs::read(dir.join("m.onnx")).unwrap(),
            manifest,
            dir,
        }
    })
}

// ---------------------------------------------------------------------------------------
// Mutations.

#[derive(Debug, Clone)]
enum Op {
    Flip(usize, u8),
    Set(usize, u8),
    Insert(usize, Vec<u8>),
    Delete(usize, usize),
    Truncate(usize),
    Duplicate(usize, usize, usize),
}

fn op() -> impl Strategy<Value = Op> {
    let at = any::<usize>();
    prop_oneof![
        (at, 1u8..=255).prop_map(|(i, m)| Op::Flip(i, m)),
        (at, any::<u8>()).prop_map(|(i, b)| Op::Set(i, b)),
        (at, vec(any::<u8>(), 1..8)).prop_map(|(i, b)| Op::Insert(i, b)),
        (at, 1usize..16).prop_map(|(i, n)| Op::Delete(i, n)),
        at.prop_map(Op::Truncate),
        (at, 1usize..64, at).prop_map(|(i, n, j)| Op::Duplicate(i, n, j)),
    ]
}

fn ops() -> impl Strategy<Value = Vec<Op>> {
    vec(op(), 1..4)
}

fn apply(bytes: &[u8], ops: &[Op]) -> Vec<u8> {
    let mut b = bytes.to_vec();
    for op in ops {
        let n = b.len().max(1);
        match op {
            Op::Flip(i, m) if !b.is_empty() => b[i % n] ^= m,
            Op::Set(i, v) if !b.is_empty() => b[i % n] = *v,
            Op::Insert(i, v) => {
                let i = i % (b.len() + 1);
                b.splice(i..i, v.iter().copied());
            }
            Op::Delete(i, k) if !b.is_empty() => {
                let i = i % n;
                let e = (i + k).min(b.len());
                b.drain(i..e);
            }
            Op::Truncate(i) => b.truncate(i % (b.len() + 1)),
            Op::Duplicate(i, k, j) if !b.is_empty() => {
                let i = i % n;
                let chunk = b[i..(i + k).min(b.len())].to_vec();
                let j = j % (b.len() + 1);
                b.splice(j..j, chunk);
            }
            _ => {}
        }
    }
    b
}

/// A sealed file (`body ‖ SHA-256(body)`) with its body mutated and sealed again.
fn resealed(sealed: &[u8], ops: &[Op]) -> Vec<u8> {
    let body = &sealed[..sealed.len() - trainer::io::CHECKSUM_LEN];
    trainer::io::seal(apply(body, ops))
}

/// Bytes: arbitrary (short), or a mutation of `valid` (raw, or re-sealed when `sealed`).
#[derive(Debug, Clone)]
enum Input {
    Arbitrary(Vec<u8>),
    Mutated(Vec<Op>),
    Resealed(Vec<Op>),
}

fn input(sealed: bool) -> BoxedStrategy<Input> {
    let arb = vec(any::<u8>(), 0..256).prop_map(Input::Arbitrary);
    if sealed {
        prop_oneof![
            1 => arb,
            3 => ops().prop_map(Input::Mutated),
            4 => ops().prop_map(Input::Resealed),
        ]
        .boxed()
    } else {
        prop_oneof![1 => arb, 4 => ops().prop_map(Input::Mutated)].boxed()
    }
}

fn bytes_of(valid: &[u8], i: &Input) -> Vec<u8> {
    match i {
        Input::Arbitrary(b) => b.clone(),
        Input::Mutated(o) => apply(valid, o),
        Input::Resealed(o) => resealed(valid, o),
    }
}

fn names(err: &str, file: &str) -> Result<(), TestCaseError> {
    prop_assert!(err.contains(file), "the error does not name {file}: {err}");
    Ok(())
}

// ---------------------------------------------------------------------------------------
// Targets.

/// A sealed format: `decode` the bytes; `Ok` only for the original bytes when the checksum was
/// not recomputed, else the value must re-encode to bytes that decode to the same bytes.
fn sealed_target<T>(
    cases: u32,
    valid: &'static [u8],
    decode: impl Fn(&[u8], &str) -> Result<T, String>,
    encode: impl Fn(&T) -> Vec<u8>,
) {
    let decode = &decode;
    runner(cases)
        .run(&input(true), |i| {
            let b = bytes_of(valid, &i);
            let r = timed("decode", || decode(&b, "fuzz.bin"))?;
            match r {
                Ok(v) => {
                    if !matches!(i, Input::Resealed(_)) {
                        prop_assert_eq!(&b[..], valid, "accepted a corrupt file ({:?})", i);
                    }
                    let again = encode(&v);
                    let back = decode(&again, "again.bin");
                    prop_assert!(
                        back.is_ok(),
                        "its own encoding is refused: {:?}",
                        back.err()
                    );
                    prop_assert_eq!(encode(&back.unwrap()), again);
                }
                Err(e) => names(&e, "fuzz.bin")?,
            }
            Ok(())
        })
        .unwrap();
}

fn dataset(cases: u32) {
    sealed_target(
        cases,
        &valid().dataset,
        |b, o| Dataset::from_bytes(b, o).map_err(|e| e.to_string()),
        Dataset::to_bytes,
    );
}

fn model(cases: u32) {
    sealed_target(
        cases,
        &valid().model,
        |b, o| Model::from_bytes(b, o).map_err(|e| e.to_string()),
        Model::to_bytes,
    );
}

fn refine_state(cases: u32) {
    sealed_target(
        cases,
        &valid().refine_state,
        |b, o| RefineState::from_bytes(b, Path::new(o)).map_err(|e| e.to_string()),
        |s| trainer::io::seal(postcard::to_allocvec(s).unwrap()),
    );
}

/// The labelling checkpoint keeps the frames before the first damaged one: whatever it
/// returns must be the original header and a prefix of the original records (a damaged
/// frame costs its batch, never a wrong label).
fn partial(cases: u32) {
    let d = Dataset::from_bytes(&valid().dataset, "d.bin").unwrap();
    let (head, rest) = d.records.split_at(d.records.len() / 2);
    let mut bytes = checkpoint::encode(&d.header, head);
    // A second batch, as `append` writes it: the batch frame of another encoding.
    let two = checkpoint::encode(&d.header, rest);
    bytes.extend_from_slice(&two[frame_len(&two, 0)..]);
    let (h, recs) = checkpoint::read(&bytes).expect("the valid checkpoint");
    assert_eq!(recs, d.records, "two batches read back");
    assert_eq!(h, d.header);
    runner(cases)
        .run(&input(false), |i| {
            let b = bytes_of(&bytes, &i);
            if let Some((h, r)) = timed("checkpoint::read", || checkpoint::read(&b))? {
                prop_assert!(h == d.header, "another header accepted ({:?})", i);
                prop_assert!(
                    r.len() <= d.records.len() && r[..] == d.records[..r.len()],
                    "records that are not a prefix of the written ones ({:?})",
                    i
                );
            }
            Ok(())
        })
        .unwrap();
}

/// Length of the frame starting at `at` (8-byte length prefix + body).
fn frame_len(bytes: &[u8], at: usize) -> usize {
    8 + u64::from_le_bytes(bytes[at..at + 8].try_into().unwrap()) as usize
}

/// Text inputs: mutated bytes read as UTF-8 the way `read_to_string` would (invalid UTF-8
/// never reaches the parser).
fn text_target(
    cases: u32,
    valid: &'static str,
    check: impl Fn(&str, &Input) -> Result<(), TestCaseError>,
) {
    runner(cases)
        .run(&input(false), |i| {
            let b = bytes_of(valid.as_bytes(), &i);
            match std::str::from_utf8(&b) {
                Ok(t) => check(t, &i),
                Err(_) => Ok(()),
            }
        })
        .unwrap();
}

fn certificate(cases: u32) {
    let v = valid();
    let original: Certificate = serde_json::from_str(&v.certificate).unwrap();
    text_target(cases, &v.certificate, |t, _| {
        let r = timed("certificate", || {
            (
                serde_json::from_str::<Certificate>(t),
                trainer::certify::file::CertificateFile::parse(t, "fuzz.json", true)
                    .and_then(|(f, _)| f.recheck("fuzz.json", &Default::default())),
                trainer::certify::seal::verify(t, "fuzz.json"),
            )
        })?;
        // The checksum accepts the certificate as written (up to trailing whitespace) and
        // nothing else.
        match r.2 {
            Ok(trainer::certify::seal::Seal::Verified) => {
                prop_assert_eq!(t.trim_end(), v.certificate.trim_end())
            }
            Ok(trainer::certify::seal::Seal::Absent) => {}
            Err(e) => names(&e.to_string(), "fuzz.json")?,
        }
        if let Ok(c) = r.0 {
            let again = serde_json::to_string(&c).unwrap();
            let back: Certificate = serde_json::from_str(&again).unwrap();
            prop_assert_eq!(serde_json::to_string(&back).unwrap(), again);
            let _ = &original;
        }
        if let Err(e) = r.1 {
            names(&e.to_string(), "fuzz.json")?;
        }
        Ok(())
    });
}

fn manifest(cases: u32) {
    use trainer::pipeline::manifest::Manifest;
    text_target(cases, &valid().manifest, |t, _| {
        if let Ok(m) = timed("manifest", || serde_json::from_str::<Manifest>(t))? {
            let again = serde_json::to_string(&m).unwrap();
            prop_assert!(serde_json::from_str::<Manifest>(&again).is_ok());
        }
        Ok(())
    });
}

fn onnx(cases: u32) {
    let v = valid();
    runner(cases)
        .run(&input(false), |i| {
            let b = bytes_of(&v.onnx, &i);
            match timed("onnx", || {
                trainer::deploy::onnx::import_bytes(&b, "fuzz.onnx")
            })? {
                Ok((m, _)) => {
                    // An ONNX file has no checksum: whatever it accepts must be a consistent
                    // network whose own model file round-trips.
                    let again = m.to_bytes();
                    prop_assert!(Model::from_bytes(&again, "again.bin").is_ok());
                }
                Err(e) => names(&e.to_string(), "fuzz.onnx")?,
            }
            Ok(())
        })
        .unwrap();
}

fn states_csv(cases: u32) {
    use trainer::data::states::parse_states;
    const CSV: &str = "x1,x2\n0.1,0.2\n-1.5, 3e-2\n\n4,-0.25\n";
    text_target(cases, CSV, |t, _| {
        match timed("states", || parse_states(t, "fuzz.csv", 2))? {
            Ok(xs) => {
                prop_assert!(xs
                    .iter()
                    .all(|x| x.len() == 2 && x.iter().all(|v| v.is_finite())));
                let again: String = std::iter::once("x1,x2".to_string())
                    .chain(xs.iter().map(|x| format!("{:?},{:?}", x[0], x[1])))
                    .collect::<Vec<_>>()
                    .join("\n");
                prop_assert_eq!(parse_states(&again, "again.csv", 2).unwrap(), xs);
            }
            Err(e) => prop_assert!(e.0.starts_with("fuzz.csv"), "{}", e.0),
        }
        Ok(())
    });
}

fn import_csv(cases: u32) {
    use trainer::data::import::csv::parse;
    const CSV: &str = "index,x1,x2,u1,du1_dx1,du1_dx2,status\n0,-1.0,0.5,0.25,-1.5,-2.0,optimal\n\
                       1,0.0,0.0,0.0,-1.4,-1.9,optimal\n2,1.0,-0.5,-0.3,-1.5,-2.1,max_iterations\n";
    let sn = vec!["p".to_string(), "v".to_string()];
    let un = vec!["a".to_string()];
    text_target(cases, CSV, |t, _| {
        let r = timed("import csv", || {
            parse(t, "fuzz.csv", (&sn, &un), &[-4.0, -1.0], &[4.0, 1.0], 1)
        })?;
        if let Err(e) = r {
            prop_assert!(e.to_string().starts_with("fuzz.csv:"), "{}", e);
        }
        Ok(())
    });
}

/// A problem-file error names the file (and, for an invalid setting, the key).
fn config_err(e: &str) -> Result<(), TestCaseError> {
    prop_assert!(
        e.contains("fuzz.toml"),
        "the error does not name the file: {e}"
    );
    prop_assert!(
        !e.contains("invalid setting") || e.contains("invalid setting `"),
        "the error does not name the setting: {e}"
    );
    Ok(())
}

/// Parses a problem file; an accepted one must be stored and read back as the same problem.
fn check_problem(t: &str) -> Result<(), TestCaseError> {
    match timed("problem", || ProblemConfig::from_toml_str(t, "fuzz.toml"))? {
        Ok(cfg) => {
            let stored = cfg.to_toml_string();
            prop_assert!(stored.is_ok(), "{:?}", stored.err());
            let back = ProblemConfig::from_stored_toml(&stored.unwrap(), "stored.toml");
            prop_assert!(
                back.is_ok(),
                "the stored copy is refused: {}",
                back.err().unwrap()
            );
            prop_assert_eq!(back.unwrap().problem_hash(), cfg.problem_hash());
        }
        Err(e) => config_err(&e.to_string())?,
    }
    Ok(())
}

/// Byte mutations of every shipped problem file.
fn problem_bytes(cases: u32) {
    let v = valid();
    let strat = (0..v.problems.len(), input(false));
    runner(cases)
        .run(&strat, |(k, i)| {
            let b = bytes_of(v.problems[k].1.as_bytes(), &i);
            match std::str::from_utf8(&b) {
                Ok(t) => check_problem(t),
                Err(_) => Ok(()),
            }
        })
        .unwrap();
}

/// A random TOML value.
fn value() -> impl Strategy<Value = toml::Value> {
    use toml::Value as V;
    let leaf = prop_oneof![
        any::<i64>().prop_map(V::Integer),
        prop_oneof![
            Just(0i64),
            Just(-1),
            Just(1),
            Just(2),
            Just(1 << 40),
            Just(i64::MAX)
        ]
        .prop_map(V::Integer),
        any::<f64>().prop_map(V::Float),
        prop_oneof![
            Just(0.0f64),
            Just(-0.0),
            Just(1e-300),
            Just(-1.0),
            Just(1e300),
            Just(f64::NAN),
            Just(f64::INFINITY),
            Just(f64::NEG_INFINITY)
        ]
        .prop_map(V::Float),
        any::<bool>().prop_map(V::Boolean),
        "[a-z_0-9 +*/^().-]{0,12}".prop_map(V::String),
    ];
    leaf.prop_recursive(2, 12, 4, |inner| {
        prop_oneof![
            vec(inner.clone(), 0..5).prop_map(toml::Value::Array),
            vec(("[a-z_]{1,8}", inner), 0..3)
                .prop_map(|kv| toml::Value::Table(kv.into_iter().collect())),
        ]
    })
}

#[derive(Debug, Clone)]
enum Edit {
    Replace(usize, toml::Value),
    Remove(usize),
    Add(usize, String, toml::Value),
    /// Replace a number inside an array value with another.
    Element(usize, usize, toml::Value),
}

fn edit() -> impl Strategy<Value = Edit> {
    let at = any::<usize>();
    prop_oneof![
        (at, value()).prop_map(|(i, v)| Edit::Replace(i, v)),
        at.prop_map(Edit::Remove),
        (at, "[a-z_]{1,12}", value()).prop_map(|(i, k, v)| Edit::Add(i, k, v)),
        (at, any::<usize>(), value()).prop_map(|(i, j, v)| Edit::Element(i, j, v)),
    ]
}

/// Paths of every key of a table (dotted into subtables).
fn key_paths(t: &toml::Table, prefix: &mut Vec<String>, out: &mut Vec<Vec<String>>) {
    for (k, v) in t {
        prefix.push(k.clone());
        out.push(prefix.clone());
        if let toml::Value::Table(s) = v {
            key_paths(s, prefix, out);
        }
        prefix.pop();
    }
}

fn slot<'a>(t: &'a mut toml::Table, path: &[String]) -> Option<&'a mut toml::Value> {
    let (last, init) = path.split_last()?;
    let mut cur = t;
    for k in init {
        cur = cur.get_mut(k)?.as_table_mut()?;
    }
    cur.get_mut(last)
}

fn apply_edits(t: &mut toml::Table, edits: &[Edit]) {
    for e in edits {
        let mut paths = Vec::new();
        key_paths(t, &mut Vec::new(), &mut paths);
        if paths.is_empty() {
            return;
        }
        let n = paths.len();
        match e {
            Edit::Replace(i, v) => {
                if let Some(s) = slot(t, &paths[i % n]) {
                    *s = v.clone();
                }
            }
            Edit::Remove(i) => {
                let p = &paths[i % n];
                let (last, init) = p.split_last().unwrap();
                let parent = if init.is_empty() {
                    Some(&mut *t)
                } else {
                    slot(t, init).and_then(|v| v.as_table_mut())
                };
                if let Some(parent) = parent {
                    parent.remove(last);
                }
            }
            Edit::Add(i, k, v) => {
                let p = &paths[i % n];
                let target = match slot(t, p) {
                    Some(toml::Value::Table(s)) => s,
                    _ => &mut *t,
                };
                target.insert(k.clone(), v.clone());
            }
            Edit::Element(i, j, v) => {
                if let Some(toml::Value::Array(a)) = slot(t, &paths[i % n]) {
                    if !a.is_empty() {
                        let m = a.len();
                        a[j % m] = v.clone();
                    }
                }
            }
        }
    }
}

/// Shipped problem files with keys and values replaced, removed and added.
fn problem_tables(cases: u32) {
    let v = valid();
    let tables: Vec<toml::Table> = v
        .problems
        .iter()
        .map(|(_, t)| toml::from_str(t).unwrap())
        .collect();
    let strat = (0..tables.len(), vec(edit(), 1..4));
    runner(cases)
        .run(&strat, |(k, edits)| {
            let mut t = tables[k].clone();
            apply_edits(&mut t, &edits);
            match toml::to_string(&t) {
                Ok(text) => check_problem(&text),
                Err(_) => Ok(()),
            }
        })
        .unwrap();
}

/// Tokens of the expression grammar (and a few that are not).
const TOKENS: &[&str] = &[
    "theta", "omega", "u", "m", "l", "g", "pi", "e", "x", "y", "nope", "1", "0", "2.5", "1e308",
    "1e-320", "0.0", "9e999", "-", "+", "*", "/", "^", "**", "(", ")", ",", " ", "sin", "cos",
    "tan", "exp", "log", "sqrt", "abs", "tanh", "atan2", "min", "max", "pow", "sign", "sat",
    "asin", "acos", "atan", "sinh", "cosh", "sq", "clamp", "if", "<", ">", "=", "!", "&", "#", "é",
    "\u{0}", ".", "1.", ".5", "e5", "theta(", "sin(", "_",
];

fn expression() -> impl Strategy<Value = String> {
    prop_oneof![
        4 => vec(prop::sample::select(TOKENS), 1..24).prop_map(|t| t.concat()),
        1 => vec(prop::sample::select(TOKENS), 1..24).prop_map(|t| t.join(" ")),
        1 => (1usize..20_000, prop::sample::select(&["(", "-", "sin(", "x^", "+", "abs("][..]))
            .prop_map(|(n, t)| {
                let close = if t.ends_with('(') { ")" } else { "" };
                format!("{}omega{}", t.repeat(n), close.repeat(n))
            }),
    ]
}

/// The pendulum written as an expression plant, with a random expression in place of one of
/// its right-hand sides, definitions or parameters.
fn expressions(cases: u32) {
    let v = valid();
    let base: toml::Table = toml::from_str(
        &v.problems
            .iter()
            .find(|(n, _)| n == "pendulum_ode.toml")
            .expect("configs/pendulum_ode.toml")
            .1,
    )
    .unwrap();
    let strat = (0usize..4, expression(), expression());
    runner(cases)
        .run(&strat, |(slot, a, b)| {
            let mut t = base.clone();
            let sys = t.get_mut("system").unwrap().as_table_mut().unwrap();
            let s = |x: &str| toml::Value::String(x.to_string());
            match slot {
                0 => {
                    sys.insert("rhs".into(), toml::Value::Array(vec![s("omega"), s(&a)]));
                }
                1 => {
                    sys.insert("rhs".into(), toml::Value::Array(vec![s(&a), s(&b)]));
                }
                2 => {
                    sys.insert(
                        "definitions".into(),
                        toml::Value::Array(vec![s(&format!("w = {a}")), s(&b)]),
                    );
                    sys.insert("rhs".into(), toml::Value::Array(vec![s("w"), s("u")]));
                }
                _ => {
                    sys.insert("kind".into(), s("discrete"));
                    sys.remove("rhs");
                    sys.insert(
                        "next".into(),
                        toml::Value::Array(vec![s(&a), s(&format!("omega + 0.05*({b})"))]),
                    );
                }
            }
            check_problem(&toml::to_string(&t).unwrap())
        })
        .unwrap();
}

/// Arbitrary bytes as a problem file.
fn problem_arbitrary(cases: u32) {
    runner(cases)
        .run(&vec(any::<u8>(), 0..256), |b| {
            match std::str::from_utf8(&b) {
                Ok(t) => check_problem(t),
                Err(_) => Ok(()),
            }
        })
        .unwrap();
}

macro_rules! targets {
    ($($full:ident, $smoke:ident, $f:ident, $n:expr;)*) => {$(
        #[test]
        #[ignore = "fuzz campaign: cargo test -p trainer --test fuzz -- --ignored"]
        fn $full() {
            $f($n);
        }
        #[test]
        fn $smoke() {
            $f(SMOKE);
        }
    )*};
}

targets! {
    fuzz_dataset, smoke_dataset, dataset, 1_000_000;
    fuzz_model, smoke_model, model, 1_000_000;
    fuzz_refine_state, smoke_refine_state, refine_state, 200_000;
    fuzz_partial, smoke_partial, partial, 1_000_000;
    fuzz_certificate, smoke_certificate, certificate, 1_000_000;
    fuzz_manifest, smoke_manifest, manifest, 1_000_000;
    fuzz_onnx, smoke_onnx, onnx, 500_000;
    fuzz_states_csv, smoke_states_csv, states_csv, 1_000_000;
    fuzz_import_csv, smoke_import_csv, import_csv, 1_000_000;
    fuzz_problem_bytes, smoke_problem_bytes, problem_bytes, 20_000;
    fuzz_problem_tables, smoke_problem_tables, problem_tables, 20_000;
    fuzz_expressions, smoke_expressions, expressions, 20_000;
    fuzz_problem_arbitrary, smoke_problem_arbitrary, problem_arbitrary, 100_000;
}

// A plant costs a dataset's solves, not a decode: fewer cases (60: ~18 s in the campaign).
#[test]
#[ignore = "fuzz campaign: cargo test -p trainer --test fuzz -- --ignored"]
fn fuzz_nan_plants() {
    nan_plants(60);
}
#[test]
fn smoke_nan_plants() {
    nan_plants(3);
}

#[test]
fn valid_inputs_are_accepted() {
    let v = valid();
    assert!(Dataset::from_bytes(&v.dataset, "d.bin").is_ok());
    assert!(Model::from_bytes(&v.model, "m.bin").is_ok());
    assert!(RefineState::from_bytes(&v.refine_state, Path::new("r.bin")).is_ok());
    assert!(trainer::deploy::onnx::import_bytes(&v.onnx, "m.onnx").is_ok());
    assert!(serde_json::from_str::<Certificate>(&v.certificate).is_ok());
    assert_eq!(
        trainer::certify::seal::verify(&v.certificate, "c.json"),
        Ok(trainer::certify::seal::Seal::Verified)
    );
    assert!(serde_json::from_str::<trainer::pipeline::manifest::Manifest>(&v.manifest).is_ok());
    for (n, t) in &v.problems {
        assert!(ProblemConfig::from_toml_str(t, n).is_ok(), "{n}");
    }
    assert!(v.dir.exists());
}
