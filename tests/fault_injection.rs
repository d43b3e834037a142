//! Fault injection through the CLI: every command (`trainer run` included) killed
//! (SIGKILL) at random times
//! and rerun, and random bytes flipped in every input file type. Each outcome must be the
//! clean run's result byte for byte, or a nonzero exit whose message names the file — never
//! exit 0 with another result, never a panic. Flips that change a user-written input into
//! another valid input (a digit of a number in the problem file or the states CSV) give a
//! result that follows the changed input: counted as such, and checked to be the result for
//! exactly that input.
//!
//! The default run does a small seeded subset; the full campaign (≥ 50 kills per command,
//! ≥ 100 flips per file type) is `fault_injection_full` (ignored):
//! `cargo test -p ampc-tests --test fault_injection -- --ignored --nocapture`.

use ampc_tests::{config, tempdir, trainer_bin};
use std::collections::BTreeMap;
use std::path::Path;
use std::process::{Command, Output};
use std::time::Instant;
use trainer::data::dataset::{checkpoint, Dataset};

/// splitmix64: the test's seeded random numbers.
struct Rng(u64);
impl Rng {
    fn next(&mut self) -> u64 {
        self.0 = self.0.wrapping_add(0x9e37_79b9_7f4a_7c15);
        let mut z = self.0;
        z = (z ^ (z >> 30)).wrapping_mul(0xbf58_476d_1ce4_e5b9);
        z = (z ^ (z >> 27)).wrapping_mul(0x94d0_49bb_1331_11eb);
        z ^ (z >> 31)
    }
    fn below(&mut self, n: usize) -> usize {
        (self.next() % n as u64) as usize
    }
}

fn run_in(dir: &Path, args: &[&str]) -> Output {
    Command::new(trainer_bin())
        .current_dir(dir)
        .args(args)
        .output()
        .expect("run trainer")
}

/// One command of the campaign: its arguments (paths relative to its directory), the input
/// files it reads and the output files whose bytes are its result (`-` is its stdout).
struct Cmd {
    name: &'static str,
    args: Vec<&'static str>,
    inputs: Vec<&'static str>,
    outputs: Vec<&'static str>,
}

fn commands() -> Vec<Cmd> {
    let c = |name, args: &[&'static str], inputs: &[&'static str], outputs: &[&'static str]| Cmd {
        name,
        args: args.to_vec(),
        inputs: inputs.to_vec(),
        outputs: outputs.to_vec(),
    };
    vec![
        c(
            "sample",
            &["sample", "--config", "p.toml", "--out", "d.bin", "--quiet"],
            &["p.toml"],
            &["d.bin", "d.csv"],
        ),
        c(
            "train",
            &["train", "--data", "d.bin", "--out", "m.bin", "--quiet"],
            &["d.bin"],
            &["m.bin"],
        ),
        c(
            "certify",
            &["certify", "--model", "m.bin", "--data", "d.bin", "--json"],
            &["m.bin", "d.bin"],
            &["-"],
        ),
        c(
            "export",
            &[
                "export",
                "--model",
                "m.bin",
                "--certificate",
                "c.json",
                "--rust",
                "w.rs",
                "--postcard",
                "w.bin",
            ],
            &["m.bin", "c.json"],
            &["w.rs", "w.bin"],
        ),
        c(
            "refine",
            &["refine", "--config", "p.toml", "--out", "ref", "--quiet"],
            &["p.toml"],
            &[
                "ref/model.bin",
                "ref/dataset.bin",
                "ref/dataset.csv",
                "ref/cells.csv",
                "ref/certificate.json",
            ],
        ),
        // The whole pipeline; its result is every output but the manifests and the report
        // (they record stage timings).
        c(
            "run",
            &["run", "--config", "p.toml", "--out", "runs", "--quiet"],
            &["p.toml"],
            &[
                "runs/double_integrator/dataset.bin",
                "runs/double_integrator/dataset.csv",
                "runs/double_integrator/validation.bin",
                "runs/double_integrator/model_nominal.bin",
                "runs/double_integrator/model_regularized.bin",
                "runs/double_integrator/certificate.json",
                "runs/double_integrator/certificate_nominal.json",
                "runs/double_integrator/weights.rs",
                "runs/double_integrator/weights.bin",
                "runs/double_integrator/closed_loop.json",
                "runs/double_integrator/seeds.json",
                "runs/double_integrator/plots/figures.json",
            ],
        ),
        c(
            "solve",
            &[
                "solve", "--config", "p.toml", "--states", "s.csv", "--out", "so.csv",
            ],
            &["p.toml", "s.csv"],
            &["so.csv"],
        ),
        c(
            "eval",
            &[
                "eval", "--model", "m.bin", "--states", "s.csv", "--out", "ev.csv",
            ],
            &["m.bin", "s.csv"],
            &["ev.csv"],
        ),
    ]
}

/// The inputs of every command, made by a clean run in `dir`.
fn setup(dir: &Path) {
    let di = std::fs::read_to_string(config("double_integrator.toml")).unwrap();
    let small = di.replace("counts = [21, 11]", "counts = [6, 4]");
    assert_ne!(
        small, di,
        "the double integrator's grid changed: update this test"
    );
    std::fs::write(
        dir.join("p.toml"),
        format!(
            "{small}\n# fault injection: a small problem\n[training]\nepochs = 20\nvalidation_n = 10\n\
             log_every = 50\n\n[refine]\nbudget = 120\ninitial = [4, 3]\nmax_rounds = 3\n\
             target_eps = 100.0\n\n[refine.training]\nhidden = [6]\nepochs = 30\nvalidation_n = 10\n\n\
             [closed_loop]\nrandom_initial_states = 3\nnoise_runs = 1\nseeds = 2\n\n\
             [certify]\nstatistical = 200\nclosed_loop = 200\n"
        ),
    )
    .unwrap();
    std::fs::write(
        dir.join("s.csv"),
        "x1,x2\n0.1,0.2\n-1.5,0.25\n\n3.0,-0.75\n2.5,0.5\n",
    )
    .unwrap();
    for c in commands() {
        let o = run_in(dir, &c.args);
        assert!(
            o.status.success(),
            "{}: {}",
            c.name,
            String::from_utf8_lossy(&o.stderr)
        );
        if c.name == "certify" {
            std::fs::write(dir.join("c.json"), &o.stdout).unwrap();
        }
    }
}

/// The result of a command in `dir`: its output files' bytes (stdout for `-`).
fn result(dir: &Path, c: &Cmd, o: &Output) -> Vec<Option<Vec<u8>>> {
    c.outputs
        .iter()
        .map(|f| match *f {
            "-" => Some(o.stdout.clone()),
            f => std::fs::read(dir.join(f)).ok(),
        })
        .collect()
}

/// A fresh copy of the clean directory's inputs of `c` (outputs removed).
fn fresh(clean: &Path, work: &Path, c: &Cmd) {
    let _ = std::fs::remove_dir_all(work);
    std::fs::create_dir_all(work).unwrap();
    for f in &c.inputs {
        std::fs::copy(clean.join(f), work.join(f)).unwrap();
    }
}

#[derive(Default, Debug)]
struct Counts {
    identical: usize,
    clear_error: usize,
    follows_input: usize,
    silent: usize,
    panic: usize,
    unclear_error: usize,
}

impl Counts {
    fn bad(&self) -> usize {
        self.silent + self.panic + self.unclear_error
    }
}

fn print(title: &str, t: &BTreeMap<String, Counts>) {
    println!("{title}");
    println!("| {:<22} | identical | clear error | follows input | silent diff | panic | unclear error |", "");
    for (k, c) in t {
        println!(
            "| {:<22} | {:>9} | {:>11} | {:>13} | {:>11} | {:>5} | {:>13} |",
            k, c.identical, c.clear_error, c.follows_input, c.silent, c.panic, c.unclear_error
        );
    }
}

/// Kills each command `seeds` times at a random time within its clean run time (×1.2), reruns
/// it, and compares the rerun's result with the clean one.
fn kills(
    clean: &Path,
    seeds: u64,
    only: Option<&str>,
    failures: &mut Vec<String>,
) -> BTreeMap<String, Counts> {
    let mut table = BTreeMap::new();
    let scratch = clean.parent().unwrap().join("kill");
    for c in commands()
        .into_iter()
        .filter(|c| only.is_none_or(|o| o == c.name))
    {
        let t0 = Instant::now();
        fresh(clean, &scratch, &c);
        let o = run_in(&scratch, &c.args);
        let dt = t0.elapsed();
        let want = result(&scratch, &c, &o);
        let counts: &mut Counts = table.entry(c.name.to_string()).or_default();
        for seed in 0..seeds {
            let mut rng = Rng(seed.wrapping_mul(0x616d_7063) ^ c.name.len() as u64);
            fresh(clean, &scratch, &c);
            let delay = dt.mul_f64(1.2 * (rng.next() % 10_000) as f64 / 10_000.0);
            let mut child = Command::new(trainer_bin())
                .current_dir(&scratch)
                .args(&c.args)
                .stdout(std::process::Stdio::null())
                .stderr(std::process::Stdio::null())
                .spawn()
                .unwrap();
            std::thread::sleep(delay);
            child.kill().ok();
            child.wait().unwrap();
            let o = run_in(&scratch, &c.args);
            let err = String::from_utf8_lossy(&o.stderr);
            if err.contains("panicked") {
                counts.panic += 1;
                failures.push(format!("kill {} seed {seed}: {err}", c.name));
            } else if !o.status.success() {
                counts.unclear_error += 1;
                failures.push(format!("kill {} seed {seed}: rerun failed: {err}", c.name));
            } else if result(&scratch, &c, &o) == want {
                counts.identical += 1;
            } else {
                counts.silent += 1;
                failures.push(format!(
                    "kill {} seed {seed} ({delay:?}): another result",
                    c.name
                ));
            }
        }
    }
    table
}

/// What a flip is checked with: the command that reads the file.
struct Target {
    file: &'static str,
    command: &'static str,
    /// A user-written text input: a flip may make another valid input.
    user_text: bool,
}

const TARGETS: [Target; 7] = [
    Target {
        file: "p.toml",
        command: "sample",
        user_text: true,
    },
    Target {
        file: "s.csv",
        command: "solve",
        user_text: true,
    },
    Target {
        file: "d.bin",
        command: "certify",
        user_text: false,
    },
    Target {
        file: "m.bin",
        command: "eval",
        user_text: false,
    },
    Target {
        file: "c.json",
        command: "export",
        user_text: false,
    },
    Target {
        file: "d.bin.partial",
        command: "sample",
        user_text: false,
    },
    Target {
        file: "ref/refine_state.bin",
        command: "refine",
        user_text: false,
    },
];

/// For a flip that makes another valid user input: whether the result is the one for that
/// input (the dataset records the flipped file's problem; the solved states are its states).
fn follows(work: &Path, t: &Target) -> bool {
    match t.file {
        "p.toml" => {
            let text = std::fs::read_to_string(work.join("p.toml")).unwrap_or_default();
            let Ok(cfg) = trainer::problem::ProblemConfig::from_toml_str(&text, "p.toml") else {
                return false;
            };
            Dataset::load(&work.join("d.bin"))
                .is_ok_and(|d| d.header.problem_hash == cfg.problem_hash())
        }
        "s.csv" => {
            let text = std::fs::read_to_string(work.join("s.csv")).unwrap_or_default();
            let Ok(xs) = trainer::data::states::parse_states(&text, "s.csv", 2) else {
                return false;
            };
            let out = std::fs::read_to_string(work.join("so.csv")).unwrap_or_default();
            let rows: Vec<Vec<f64>> = out
                .lines()
                .skip(1)
                .map(|l| {
                    l.split(',')
                        .take(2)
                        .map(|v| v.parse().unwrap_or(f64::NAN))
                        .collect()
                })
                .collect();
            rows == xs
        }
        _ => false,
    }
}

/// The labelling checkpoint of the clean dataset: its first chunk, then the rest in a second
/// frame, as a killed `sample` leaves it.
fn partial(clean: &Path) -> Vec<u8> {
    let d = Dataset::load(&clean.join("d.bin")).unwrap();
    // Whole chunks per frame, as `sample` writes them.
    let (a, b) = d.records.split_at(trainer::data::dataset::CHUNK);
    let mut bytes = checkpoint::encode(&d.header, a);
    let two = checkpoint::encode(&d.header, b);
    let first = 8 + u64::from_le_bytes(two[..8].try_into().unwrap()) as usize;
    bytes.extend_from_slice(&two[first..]);
    bytes
}

/// Flips `n` random bytes (one per trial) in each input file type and classifies the outcome.
fn flips(
    clean: &Path,
    n: usize,
    only: Option<&str>,
    failures: &mut Vec<String>,
) -> BTreeMap<String, Counts> {
    let mut table = BTreeMap::new();
    let scratch = clean.parent().unwrap().join("flip");
    let cmds = commands();
    std::fs::write(clean.join("d.bin.partial"), partial(clean)).unwrap();
    for t in TARGETS
        .iter()
        .filter(|t| only.is_none_or(|o| o == t.command))
    {
        let c = cmds.iter().find(|c| c.name == t.command).unwrap();
        let want = {
            fresh(clean, &scratch, c);
            let o = run_in(&scratch, &c.args);
            result(&scratch, c, &o)
        };
        let original = std::fs::read(clean.join(t.file)).unwrap();
        let counts: &mut Counts = table.entry(t.file.to_string()).or_default();
        let mut rng = Rng(0x616d_7063 ^ t.file.len() as u64);
        for k in 0..n {
            fresh(clean, &scratch, c);
            let mut bytes = original.clone();
            let at = rng.below(bytes.len());
            bytes[at] ^= 1 + rng.below(255) as u8;
            let path = scratch.join(t.file);
            std::fs::create_dir_all(path.parent().unwrap()).unwrap();
            std::fs::write(&path, &bytes).unwrap();
            if t.file.starts_with("ref/") {
                // Rerun from the flipped checkpoint: the previous outputs are removed so
                // that the result is what this run writes.
                for f in &c.outputs {
                    let _ = std::fs::remove_file(scratch.join(f));
                }
            }
            let o = run_in(&scratch, &c.args);
            let err = String::from_utf8_lossy(&o.stderr);
            let base = Path::new(t.file).file_name().unwrap().to_string_lossy();
            if err.contains("panicked") || o.status.code() == Some(101) {
                counts.panic += 1;
                failures.push(format!("flip {} #{k} byte {at}: {err}", t.file));
            } else if !o.status.success() {
                if err.contains(&*base) {
                    counts.clear_error += 1;
                } else {
                    counts.unclear_error += 1;
                    failures.push(format!("flip {} #{k} byte {at}: unclear: {err}", t.file));
                }
            } else if result(&scratch, c, &o) == want {
                counts.identical += 1;
            } else if t.user_text && follows(&scratch, t) {
                counts.follows_input += 1;
            } else {
                counts.silent += 1;
                failures.push(format!(
                    "flip {} #{k} byte {at} ({:?} -> {:?}): exit 0 with another result",
                    t.file, original[at] as char, bytes[at] as char
                ));
            }
        }
    }
    table
}

/// `seeds` kills per command and `n` flips per file type (only those of command `only`, if
/// given).
fn campaign(seeds: u64, n: usize, only: Option<&str>) {
    let dir = tempdir();
    let clean = dir.path().join("clean");
    std::fs::create_dir_all(&clean).unwrap();
    let t = Instant::now();
    setup(&clean);
    let mut failures = Vec::new();
    let k = kills(&clean, seeds, only, &mut failures);
    print(&format!("kills ({seeds} seeds per command)"), &k);
    let f = flips(&clean, n, only, &mut failures);
    print(&format!("byte flips ({n} per file type)"), &f);
    println!("campaign: {:.1} s", t.elapsed().as_secs_f64());
    let bad: usize = k.values().chain(f.values()).map(Counts::bad).sum();
    assert!(
        bad == 0,
        "{bad} silent differences, panics or unclear errors:\n{}",
        failures.join("\n")
    );
}

#[test]
fn fault_injection_subset() {
    campaign(2, 6, None);
}

#[test]
#[ignore = "the full campaign (minutes): cargo test -p ampc-tests --test fault_injection -- --ignored --nocapture"]
fn fault_injection_full() {
    campaign(50, 100, None);
}

#[test]
#[ignore = "50 kills of `trainer run` alone (minutes): cargo test -p ampc-tests --test fault_injection kill_run -- --ignored --nocapture"]
fn kill_run_full() {
    campaign(50, 0, Some("run"));
}

#[test]
#[ignore = "50 kills of `export` and 100 flips of the certificate it reads: cargo test -p ampc-tests --test fault_injection export_full -- --ignored --nocapture"]
fn export_full() {
    campaign(50, 100, Some("export"));
}
