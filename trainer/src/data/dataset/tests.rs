//! The dataset: file round trip and CSV, corrupt files, the decoder under mutation, and
//! the determinism of generation (thread count, resume after interruption, shards and
//! their merge, warm vs cold starts).

use super::checkpoint;
use super::*;
use proptest::prelude::*;

fn small_cfg() -> ProblemConfig {
    let path = concat!(
        env!("CARGO_MANIFEST_DIR"),
        "/../configs/double_integrator.toml"
    );
    let mut cfg = ProblemConfig::load(Path::new(path)).unwrap();
    cfg.sampling.counts = vec![9, 7];
    cfg
}

fn tmp(name: &str) -> PathBuf {
    let d = std::env::temp_dir().join(format!("ampc-dataset-{}-{name}", std::process::id()));
    let _ = std::fs::remove_dir_all(&d);
    std::fs::create_dir_all(&d).unwrap();
    d.join("d.bin")
}

#[test]
fn file_round_trip_and_csv() {
    let out = tmp("rt");
    let d = generate(&small_cfg(), &out, &GenerateOptions::default()).unwrap();
    let bytes = std::fs::read(&out).unwrap();
    let back = Dataset::load(&out).unwrap();
    assert_eq!(back, d);
    assert_eq!(back.to_bytes(), bytes);
    assert_eq!(d.records.len(), 63);
    assert_eq!(d.counts().converged, 63);
    let csv = std::fs::read_to_string(csv_path(&out)).unwrap();
    let lines: Vec<&str> = csv.lines().collect();
    assert_eq!(lines.len(), 64);
    assert!(lines[0].starts_with("index,x1,x2,u1,du1_dx1,du1_dx2,cost,status"));
    let f: Vec<&str> = lines[1].split(',').collect();
    assert_eq!(f[1].parse::<f64>().unwrap(), d.records[0].x[0]);
    assert_eq!(f[3].parse::<f64>().unwrap(), d.records[0].u[0]);
    assert!(!partial_path(&out).exists());
}

/// A FIFO as `out` (as `--out /dev/null` names a device): the dataset goes through it, the
/// FIFO stays a FIFO, and no CSV or checkpoint appears beside it.
#[cfg(unix)]
#[test]
fn a_dataset_written_to_a_fifo_leaves_nothing_beside_it() {
    use std::os::unix::fs::FileTypeExt;
    let out = tmp("fifo");
    let made = std::process::Command::new("mkfifo").arg(&out).status();
    if !made.is_ok_and(|s| s.success()) {
        return; // no mkfifo here: nothing to check
    }
    let o2 = out.clone();
    let reader = std::thread::spawn(move || std::fs::read(&o2).unwrap());
    let d = generate(&small_cfg(), &out, &GenerateOptions::default()).unwrap();
    assert!(std::fs::symlink_metadata(&out)
        .unwrap()
        .file_type()
        .is_fifo());
    assert_eq!(reader.join().unwrap(), d.to_bytes());
    let beside: Vec<_> = std::fs::read_dir(out.parent().unwrap()).unwrap().collect();
    assert_eq!(beside.len(), 1, "only the FIFO: {beside:?}");
}

#[test]
fn corrupt_files_are_errors_naming_the_file() {
    let out = tmp("corrupt");
    generate(&small_cfg(), &out, &GenerateOptions::default()).unwrap();
    let bytes = std::fs::read(&out).unwrap();
    let e = Dataset::from_bytes(&bytes[..bytes.len() / 2], "f.bin")
        .unwrap_err()
        .to_string();
    assert!(e.contains("f.bin"), "{e}");
    let mut bad = bytes.clone();
    bad[0] = b'X';
    assert!(Dataset::from_bytes(&bad, "f.bin")
        .unwrap_err()
        .to_string()
        .contains("magic"));
    let mut v = Dataset::from_bytes(&bytes, "f").unwrap();
    v.version = 99;
    assert!(Dataset::from_bytes(&v.to_bytes(), "f")
        .unwrap_err()
        .to_string()
        .contains("version"));
    let e = Dataset::load(Path::new("/nonexistent/x.bin"))
        .unwrap_err()
        .to_string();
    assert!(e.contains("/nonexistent/x.bin"), "{e}");
}

proptest! {
    #![proptest_config(ProptestConfig {
        rng_seed: proptest::test_runner::RngSeed::Fixed(0x616d_7063),
        ..ProptestConfig::with_cases(256)
    })]
    #[test]
    fn decoder_never_panics_on_mutated_blobs(flips in proptest::collection::vec((0usize..4096, any::<u8>()), 1..8), cut in 0usize..5000) {
        let d = Dataset {
            magic: MAGIC,
            version: FORMAT_VERSION,
            header: Header {
                problem: "p".into(), problem_hash: "h".into(), config_toml: String::new(),
                nx: 2, nu: 1, sampling: SamplingSettings::default(), total: 10, shard: None, chunk: CHUNK as u32,
            },
            records: (0..5).map(|i| Record {
                index: i, x: vec![0.5, 1.0], u: vec![2.0], du_dx: vec![1.0, 2.0], cost: 1.0,
                status: SqpStatus::Converged, iterations: 3, kkt: 1e-9, degeneracy: None, max_slack: 0.0, seq: Vec::new(),
            }).collect(),
            labels: None,
            disagree: Vec::new(),
        };
        let mut b = d.to_bytes();
        for (i, v) in flips { let n = b.len(); b[i % n] = v; }
        b.truncate(cut);
        let _ = Dataset::from_bytes(&b, "fuzz");
    }
}

#[test]
fn results_do_not_depend_on_the_thread_count() {
    let cfg = small_cfg();
    let run = |threads: usize| {
        let out = tmp(&format!("threads{threads}"));
        let pool = rayon::ThreadPoolBuilder::new()
            .num_threads(threads)
            .build()
            .unwrap();
        pool.install(|| generate(&cfg, &out, &GenerateOptions::default()).unwrap());
        std::fs::read(&out).unwrap()
    };
    assert_eq!(run(1), run(3));
}

#[test]
fn an_interrupted_run_resumes_to_the_same_file() {
    let cfg = small_cfg();
    let out = tmp("resume");
    let full = generate(&cfg, &out, &GenerateOptions::default()).unwrap();
    let reference = std::fs::read(&out).unwrap();
    std::fs::remove_file(&out).unwrap();
    // A checkpoint holding chunks 0 and 2 only, as a killed run leaves behind; one of
    // its labels is altered so that we can see it was reused, not recomputed.
    let mut ck = full.clone();
    ck.records
        .retain(|r| matches!(r.index as usize / CHUNK, 0 | 2));
    ck.records[0].iterations = 999;
    checkpoint::create(&partial_path(&out), &ck.header, &ck.records).unwrap();
    let resumed = generate(&cfg, &out, &GenerateOptions::default()).unwrap();
    assert_eq!(resumed.records[0].iterations, 999);
    let mut fixed = resumed.clone();
    fixed.records[0].iterations = full.records[0].iterations;
    assert_eq!(fixed.to_bytes(), reference);
    assert!(!partial_path(&out).exists());
    // A checkpoint of another plan is ignored.
    let mut other = ck.clone();
    other.header.problem_hash = "other".into();
    checkpoint::create(&partial_path(&out), &other.header, &other.records).unwrap();
    generate(&cfg, &out, &GenerateOptions::default()).unwrap();
    assert_eq!(std::fs::read(&out).unwrap(), reference);
}

/// One flipped byte anywhere in a dataset is an error naming the file (never decoded
/// into other labels that move ε_D silently); a flipped checkpoint is not resumed from.
#[test]
fn every_flipped_byte_is_caught() {
    let cfg = small_cfg();
    let out = tmp("flip");
    let full = generate(&cfg, &out, &GenerateOptions::default()).unwrap();
    let bytes = std::fs::read(&out).unwrap();
    for i in 0..bytes.len() {
        let mut b = bytes.clone();
        b[i] ^= 0x10;
        let e = Dataset::from_bytes(&b, "f.bin").unwrap_err().to_string();
        assert!(e.contains("f.bin"), "byte {i}: {e}");
    }
    // A checkpoint with one altered sensitivity, then a flipped byte: the run labels afresh.
    std::fs::remove_file(&out).unwrap();
    let mut ck = full.clone();
    ck.records.retain(|r| r.index as usize / CHUNK == 0);
    ck.records[0].du_dx[0] += 1.0;
    let mut b = checkpoint::encode(&ck.header, &ck.records);
    let n = b.len();
    b[n - 40] ^= 0x01;
    write_atomic(&partial_path(&out), &b).unwrap();
    assert!(
        checkpoint::read(&b).unwrap().1.is_empty(),
        "the damaged batch is dropped"
    );
    generate(&cfg, &out, &GenerateOptions::default()).unwrap();
    assert_eq!(std::fs::read(&out).unwrap(), bytes);
}

/// The checkpoint is a log: each batch appends a frame; a torn or damaged frame drops itself
/// and every later one, never earlier ones; appending after a resumed, cleaned log works.
#[test]
fn the_checkpoint_log_keeps_its_good_prefix() {
    let cfg = small_cfg();
    let out = tmp("log");
    let full = generate(&cfg, &out, &GenerateOptions::default()).unwrap();
    let p = partial_path(&out);
    let (a, rest) = full.records.split_at(10);
    let (b, c) = rest.split_at(20);
    checkpoint::create(&p, &full.header, a).unwrap();
    let n_a = std::fs::metadata(&p).unwrap().len() as usize;
    checkpoint::append(&p, b).unwrap();
    let n_ab = std::fs::metadata(&p).unwrap().len() as usize;
    checkpoint::append(&p, c).unwrap();
    let bytes = std::fs::read(&p).unwrap();
    assert_eq!(checkpoint::read(&bytes).unwrap().1, full.records);
    // Torn anywhere in the last frame: the first two batches survive.
    for cut in n_ab..bytes.len() {
        let (_, r) = checkpoint::read(&bytes[..cut]).unwrap();
        assert_eq!(r.len(), 30, "cut at {cut}");
    }
    // A damaged middle frame drops itself and the rest.
    let mut bad = bytes.clone();
    bad[(n_a + n_ab) / 2] ^= 0x80;
    assert_eq!(checkpoint::read(&bad).unwrap().1.len(), 10);
    // Not a checkpoint: nothing.
    assert!(checkpoint::read(b"garbage").is_none());
}

#[test]
fn shards_merge_to_the_single_run_and_bad_sets_are_refused() {
    let cfg = small_cfg();
    let out = tmp("shards");
    generate(&cfg, &out, &GenerateOptions::default()).unwrap();
    let single = std::fs::read(&out).unwrap();
    let shards: Vec<Dataset> = (0..3)
        .map(|k| {
            let p = out.with_file_name(format!("s{k}.bin"));
            let opts = GenerateOptions {
                shard: Some(Shard { index: k, count: 3 }),
                progress: false,
            };
            generate(&cfg, &p, &opts).unwrap()
        })
        .collect();
    assert_eq!(merge(&shards).unwrap().to_bytes(), single);
    assert_eq!(
        merge(&[shards[2].clone(), shards[0].clone(), shards[1].clone()])
            .unwrap()
            .to_bytes(),
        single
    );
    let e = merge(&shards[..2]).unwrap_err().to_string();
    assert!(e.contains("missing shards: 2/3"), "{e}");
    let e = merge(&[shards[0].clone(), shards[0].clone(), shards[1].clone()])
        .unwrap_err()
        .to_string();
    assert!(e.contains("given twice"), "{e}");
    let mut alien = shards[1].clone();
    alien.header.problem_hash = "x".into();
    assert!(merge(&[shards[0].clone(), alien, shards[2].clone()]).is_err());
    assert!(
        "3/3".parse::<Shard>().is_err()
            && "a/b".parse::<Shard>().is_err()
            && "1/0".parse::<Shard>().is_err()
    );
    assert_eq!(
        "1/4".parse::<Shard>().unwrap(),
        Shard { index: 1, count: 4 }
    );
}

/// Warm starts change the path, not the answer: on the paper's grid every label equals
/// the cold-start label.
#[test]
fn warm_and_cold_starts_give_the_same_pendulum_labels() {
    let mut cfg = ProblemConfig::default();
    let sampler = Sampler::new(&cfg.sampling, &cfg.domain);
    let mut law = MpcLaw::new(&cfg);
    let warm = label_chunk(&mut law, &sampler, 0, sampler.len(), true);
    cfg.solver.warm_start = false;
    let cold = label_chunk(&mut law, &sampler, 0, sampler.len(), false);
    for (w, c) in warm.iter().zip(&cold) {
        assert_eq!(w.status, c.status, "{:?}", w.x);
        assert!(
            (w.u[0] - c.u[0]).abs() <= 1e-6,
            "{:?}: {} vs {}",
            w.x,
            w.u[0],
            c.u[0]
        );
    }
}

/// Checkpoint cost per batch stays flat as the log grows (append-only): prints the median
/// time of appending a batch of 256 records over the first 5·10⁴ records and over the last
/// 5·10⁴ of 10⁶ (about 195 appends each).
/// `cargo test -p trainer --release --lib checkpoint_throughput -- --ignored --nocapture`
#[test]
#[ignore = "a measurement: writes 10⁶ records (~150 MB); see BENCHMARKS.md"]
fn checkpoint_throughput_is_flat() {
    let cfg = small_cfg();
    let out = tmp("throughput");
    let d = generate(&cfg, &out, &GenerateOptions::default()).unwrap();
    let proto = d.records[0].clone();
    let batch: Vec<Record> = (0..256u64)
        .map(|i| Record {
            index: i,
            ..proto.clone()
        })
        .collect();
    let p = partial_path(&out);
    checkpoint::create(&p, &d.header, &batch).unwrap();
    let (mut early, mut late) = (Vec::new(), Vec::new());
    let mut written = batch.len();
    while written < 1_000_000 {
        let t = std::time::Instant::now();
        checkpoint::append(&p, &batch).unwrap();
        let dt = t.elapsed().as_secs_f64();
        if written < 50_000 {
            early.push(dt);
        } else if written >= 950_000 {
            late.push(dt);
        }
        written += batch.len();
    }
    let median = |v: &mut Vec<f64>| {
        v.sort_by(f64::total_cmp);
        v[v.len() / 2]
    };
    let (t4, t6) = (median(&mut early), median(&mut late));
    eprintln!(
        "append 256 records: median {:.3} ms over the first 5·10^4, {:.3} ms over the last 5·10^4 of 10^6 records ({:.0} vs {:.0} records/s), ratio {:.2}",
        t4 * 1e3,
        t6 * 1e3,
        256.0 / t4,
        256.0 / t6,
        t6 / t4
    );
    let _ = std::fs::remove_file(&p);
}

/// The indices where starts disagree: a dataset without any stays version 2 byte for byte;
/// with some it is version 4 and reads back with them (also through a checkpoint and a
/// shard merge), and an older version-2 file still reads (with none).
#[test]
fn disagreeing_starts_are_stored_and_read_back() {
    let out = tmp("disagree");
    let d = generate(&small_cfg(), &out, &GenerateOptions::default()).unwrap();
    assert_eq!(d.version, FORMAT_VERSION);
    assert!(d.disagree.is_empty());
    let mut e = d.clone();
    e.disagree = vec![3, 17];
    e.version = own_version(&e.disagree, &e.records);
    assert_eq!(e.version, STARTS_FORMAT_VERSION);
    let bytes = e.to_bytes();
    let back = Dataset::from_bytes(&bytes, "e").unwrap();
    assert_eq!(back, e);
    assert_eq!(back.disagree, vec![3, 17]);
    // The version-2 bytes are the same as before the field existed: read with none.
    assert_eq!(
        Dataset::from_bytes(&d.to_bytes(), "d").unwrap().disagree,
        Vec::<u64>::new()
    );
    // A version-4 file cut after its records (no list) is an error naming it.
    let body = crate::io::unseal(&bytes).unwrap();
    let cut = postcard::take_from_bytes::<Dataset>(body).unwrap().1.len();
    let short = crate::io::seal(body[..body.len() - cut].to_vec());
    let err = Dataset::from_bytes(&short, "short.bin")
        .unwrap_err()
        .to_string();
    assert!(err.contains("short.bin"), "{err}");
    // The checkpoint keeps the list per batch; a batch without one reads as before.
    let (a, b) = e.records.split_at(20);
    let p = tmp("disagree-ck");
    checkpoint::create_with(&p, &e.header, a, &[3, 17]).unwrap();
    checkpoint::append(&p, b).unwrap();
    let (_, r, dis) = checkpoint::read_with(&std::fs::read(&p).unwrap()).unwrap();
    assert_eq!((r, dis), (e.records.clone(), vec![3, 17]));
    // Shards merge their lists.
    let mut shards = Vec::new();
    for k in 0..2 {
        let opts = GenerateOptions {
            shard: Some(Shard { index: k, count: 2 }),
            progress: false,
        };
        let mut s = generate(&small_cfg(), &tmp(&format!("dis-shard{k}")), &opts).unwrap();
        s.disagree = if k == 0 { vec![3] } else { vec![17] };
        s.version = own_version(&s.disagree, &s.records);
        shards.push(s);
    }
    let m = merge(&shards).unwrap();
    assert_eq!(m.disagree, vec![3, 17]);
    assert_eq!(m.version, STARTS_FORMAT_VERSION);
    assert_eq!(m.records, e.records);
}

/// `[training] outputs = "sequence"`: every labelled record keeps u₀*, …, u_{N−1}* (its first
/// nu values are the label u), the file is version 5 and round-trips byte for byte (with
/// the CSV's sequence columns); a resumed checkpoint, shards and their merge keep the
/// sequences byte-identically; the default keeps none and stays version 2; and a version-2
/// file still reads (without sequences).
#[test]
fn sequences_are_kept_round_trip_and_survive_shards_and_resume() {
    let plain = generate(&small_cfg(), &tmp("seq-plain"), &GenerateOptions::default()).unwrap();
    assert_eq!(plain.version, FORMAT_VERSION);
    assert!(plain.records.iter().all(|r| r.seq.is_empty()));
    assert_eq!(plain.sequence_horizon(), None);
    let mut cfg = small_cfg();
    cfg.training.outputs = crate::problem::Outputs::Sequence;
    let n = cfg.ocp.horizon;
    let out = tmp("seq");
    let d = generate(&cfg, &out, &GenerateOptions::default()).unwrap();
    assert_eq!(d.version, SEQUENCE_FORMAT_VERSION);
    assert_eq!(d.sequence_horizon(), Some(n));
    for (r, p) in d.records.iter().zip(&plain.records) {
        assert_eq!(r.seq.len(), n * r.u.len());
        assert_eq!(&r.seq[..r.u.len()], &r.u[..]);
        // The sequence is the plan of the OCP: not the first input repeated.
        assert!(r.seq.iter().any(|v| *v != r.u[0]) || r.u[0] == 0.0);
        // Everything else is the label of the default run.
        let mut q = r.clone();
        q.seq = Vec::new();
        assert_eq!(&q, p);
    }
    let bytes = std::fs::read(&out).unwrap();
    let back = Dataset::load(&out).unwrap();
    assert_eq!(back, d);
    assert_eq!(back.to_bytes(), bytes);
    // The version-2 prefix holds the default run's records (the header differs only in the
    // stored problem file): an older reader's view.
    let body = crate::io::unseal(&bytes).unwrap();
    let (mut head, _) = postcard::take_from_bytes::<Dataset>(body).unwrap();
    head.header
        .config_toml
        .clone_from(&plain.header.config_toml);
    head.version = FORMAT_VERSION;
    assert_eq!(head.to_bytes(), plain.to_bytes());
    let csv = std::fs::read_to_string(csv_path(&out)).unwrap();
    let first = csv.lines().next().unwrap();
    assert!(first.ends_with(&format!(",u1_{}", n - 1)), "{first}");
    // A record's sequence of the wrong length is refused, naming the file and record.
    let mut bad = d.clone();
    bad.records[5].seq.pop();
    let err = Dataset::from_bytes(&bad.to_bytes(), "bad.bin")
        .unwrap_err()
        .to_string();
    assert!(err.contains("bad.bin") && err.contains("record 5"), "{err}");
    // Resume: a checkpoint holding the first chunks (with their sequences) completes to the
    // same bytes; one written without sequences is not resumed into a sequence run.
    let out2 = tmp("seq-resume");
    checkpoint::create(&partial_path(&out2), &d.header, &d.records[..CHUNK]).unwrap();
    let r = generate(&cfg, &out2, &GenerateOptions::default()).unwrap();
    assert_eq!(r.to_bytes(), bytes);
    let (_, ck, _) = checkpoint::read_with(&{
        let p = tmp("seq-ck");
        checkpoint::create(&p, &d.header, &d.records[..CHUNK]).unwrap();
        std::fs::read(&p).unwrap()
    })
    .unwrap();
    assert_eq!(ck, d.records[..CHUNK].to_vec());
    let out3 = tmp("seq-resume-plain");
    checkpoint::create(&partial_path(&out3), &d.header, &plain.records[..CHUNK]).unwrap();
    assert_eq!(
        generate(&cfg, &out3, &GenerateOptions::default())
            .unwrap()
            .to_bytes(),
        bytes
    );
    // Shards and their merge.
    let shards: Vec<Dataset> = (0..3)
        .map(|k| {
            let opts = GenerateOptions {
                shard: Some(Shard { index: k, count: 3 }),
                progress: false,
            };
            let s = generate(&cfg, &tmp(&format!("seq-shard{k}")), &opts).unwrap();
            Dataset::from_bytes(&s.to_bytes(), "shard").unwrap()
        })
        .collect();
    assert!(shards.iter().all(|s| s.version == SEQUENCE_FORMAT_VERSION));
    assert_eq!(merge(&shards).unwrap().to_bytes(), bytes);
}
