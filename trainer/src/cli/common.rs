//! Helpers shared by the subcommands: the problem file, the states CSV (`solve`, `eval`),
//! the CSV columns of inputs and Jacobians, number formatting for tables, file hashes.

use anyhow::{bail, Context, Result};
use std::path::{Path, PathBuf};
use trainer::certify::Model;
use trainer::data::dataset::Dataset;
use trainer::problem::ProblemConfig;

/// The problem file of `--config`, or — when nothing names a problem — the embedded
/// pendulum, said on stderr ([`embedded_pendulum`]).
pub(super) fn load_config(path: Option<&Path>) -> Result<ProblemConfig> {
    Ok(match path {
        Some(p) => load(p)?,
        None => embedded_pendulum(),
    })
}

/// The problem file at `p` as the pipeline labels it: with `[closed_loop] safety = true`, its
/// MPC imposes the safe controller's online check (`trainer::pipeline::labelling_problem`), so
/// that `trainer sample` / `eval` / `certify` on it use the labels `trainer run` uses.
pub(super) fn load(p: &Path) -> Result<ProblemConfig> {
    let cfg = warn_plant(ProblemConfig::load(p)?);
    Ok(trainer::pipeline::labelling_problem(&cfg)?)
}

/// The embedded pendulum, for a command given no `--config` and no input that names a
/// problem; says so on stderr before anything else.
pub(super) fn embedded_pendulum() -> ProblemConfig {
    eprintln!(
        "problem `pendulum`: the embedded pendulum (configs/pendulum.toml) — no --config \
         given and no input names a problem"
    );
    ProblemConfig::default()
}

/// The problem a model (at `path`) is used with: `--config` if given — then the model's
/// problem hash (and dimensions) must match it — else the problem file stored in the model
/// (`learn::model_file`), else the embedded pendulum only if the model's stored problem
/// hash is the pendulum's (a model of an older build). `None`: no problem is known (an ONNX
/// file, or an older model of another problem). Says on stderr which problem it took.
pub(super) fn problem_for_model(
    config: Option<&Path>,
    path: &Path,
    m: &Model,
) -> Result<Option<ProblemConfig>> {
    if let Some(p) = config {
        let cfg = load(p)?;
        if (m.mlp.nx(), m.mlp.nu()) != (cfg.system.nx(), cfg.system.nu()) {
            bail!(
                "{}: the network maps {} states to {} inputs; problem `{}` of {} has {} and {}",
                path.display(),
                m.mlp.nx(),
                m.mlp.nu(),
                cfg.name,
                p.display(),
                cfg.system.nx(),
                cfg.system.nu()
            );
        }
        if !m.problem_hash.is_empty() && m.problem_hash != cfg.problem_hash() {
            bail!(
                "{} was trained on labels of problem {} (hash {}…), not of problem `{}` of {} \
                 (hash {}…): omit --config to use the model's own problem",
                path.display(),
                stored_name(m.problem_toml.as_deref()),
                short(&m.problem_hash),
                cfg.name,
                p.display(),
                short(&cfg.problem_hash())
            );
        }
        return Ok(Some(cfg));
    }
    if let Some(t) = &m.problem_toml {
        let origin = format!("{} (its stored problem file)", path.display());
        let cfg = warn_plant(ProblemConfig::from_stored_toml(t, &origin)?);
        eprintln!(
            "problem `{}` from {} (no --config given)",
            cfg.name,
            path.display()
        );
        return Ok(Some(cfg));
    }
    let pendulum = ProblemConfig::default();
    if m.problem_hash == pendulum.problem_hash() {
        eprintln!(
            "problem `pendulum`: the embedded pendulum, whose problem hash {} records (no \
             --config given)",
            path.display()
        );
        return Ok(Some(pendulum));
    }
    Ok(None)
}

/// The `name` of a stored problem file, in backquotes (or "of unknown name").
pub(super) fn stored_name(toml: Option<&str>) -> String {
    toml.and_then(|t| t.parse::<toml::Table>().ok())
        .and_then(|t| t.get("name").and_then(|v| v.as_str()).map(str::to_string))
        .map_or_else(|| "of unknown name".into(), |n| format!("`{n}`"))
}

/// The first 12 bytes of a hash (all of it if shorter or not ASCII there).
pub(super) fn short(h: &str) -> &str {
    h.get(..12).unwrap_or(h)
}

/// Shows the plant compiler's warnings (an expression plant's non-smooth functions and
/// unused names) on stderr, and passes the problem on.
pub(super) fn warn_plant(cfg: ProblemConfig) -> ProblemConfig {
    for w in cfg.system.warnings() {
        eprintln!("warning: [system] of problem `{}`: {w}", cfg.name);
    }
    cfg
}

/// The problem a dataset is used with: `--config` if given (the caller checks that the data
/// belongs to it), else the problem file stored in the dataset's header — never the embedded
/// pendulum for data of another problem. Says on stderr which problem it took.
pub(super) fn problem_for_data(
    config: Option<&Path>,
    data_path: &Path,
    data: &Dataset,
) -> Result<ProblemConfig> {
    match config {
        Some(p) => load(p),
        None => {
            let origin = format!("{} (its stored problem file)", data_path.display());
            let cfg = ProblemConfig::from_stored_toml(&data.header.config_toml, &origin)?;
            eprintln!(
                "problem `{}` from {} (no --config given)",
                cfg.name,
                data_path.display()
            );
            Ok(cfg)
        }
    }
}

/// Whether two paths name the same file (the same path, a symbolic or a hard link).
fn same_file(a: &Path, b: &Path) -> bool {
    use std::os::unix::fs::MetadataExt;
    if a.as_os_str().is_empty() || b.as_os_str().is_empty() {
        return false;
    }
    if a == b {
        return true;
    }
    match (std::fs::metadata(a), std::fs::metadata(b)) {
        (Ok(x), Ok(y)) => x.dev() == y.dev() && x.ino() == y.ino(),
        _ => false,
    }
}

/// Refuses a command whose output would replace one of its inputs (or another of its
/// outputs): nothing is read or written then.
pub(super) fn refuse_overwrite(outputs: &[&Path], inputs: &[&Path]) -> Result<()> {
    for (k, o) in outputs.iter().enumerate() {
        if let Some(i) = inputs.iter().find(|i| same_file(o, i)) {
            bail!(
                "refusing to write {}: it is the input {} (choose another output path)",
                o.display(),
                i.display()
            );
        }
        if let Some(p) = outputs[..k].iter().find(|p| same_file(o, p)) {
            bail!(
                "refusing to write {} twice (it is also the output {})",
                o.display(),
                p.display()
            );
        }
    }
    Ok(())
}

/// Reads a states CSV: header `x1,…,xn` or the problem's state names (when a problem is
/// known), one finite state per row (`trainer::data::states::parse_states_named`).
pub(super) fn read_states(
    path: &Path,
    nx: usize,
    problem: Option<&ProblemConfig>,
) -> Result<Vec<Vec<f64>>> {
    let text = std::fs::read_to_string(path)
        .with_context(|| format!("cannot read states file {}", path.display()))?;
    let names = problem.map_or_else(Vec::new, |c| c.system.names().states);
    Ok(trainer::data::states::parse_states_named(
        &text,
        &path.display().to_string(),
        nx,
        &names,
    )?)
}

/// The CSV columns `x1..xn,u1..um,du1_dx1,…,dum_dxn` (state, inputs, row-major Jacobian).
pub(super) fn jacobian_header(nx: usize, nu: usize) -> Vec<String> {
    let mut head: Vec<String> = (1..=nx).map(|i| format!("x{i}")).collect();
    head.extend((1..=nu).map(|j| format!("u{j}")));
    for j in 1..=nu {
        head.extend((1..=nx).map(|i| format!("du{j}_dx{i}")));
    }
    head
}

/// The numbers as CSV fields, in `{:?}` form (round-trips every f64 exactly).
pub(super) fn csv_numbers<'a>(values: impl Iterator<Item = &'a f64>) -> String {
    values
        .map(|v| format!("{v:?}"))
        .collect::<Vec<_>>()
        .join(",")
}

/// `median [min, max]` of the values, each formatted by [`fmt_num`].
pub(super) fn med_range(v: &[f64]) -> String {
    let mut s = v.to_vec();
    s.sort_by(f64::total_cmp);
    let med = if s.is_empty() {
        f64::NAN
    } else if s.len() % 2 == 1 {
        s[s.len() / 2]
    } else {
        0.5 * (s[s.len() / 2 - 1] + s[s.len() / 2])
    };
    format!(
        "{} [{}, {}]",
        fmt_num(med),
        fmt_num(s.first().copied().unwrap_or(f64::NAN)),
        fmt_num(s.last().copied().unwrap_or(f64::NAN))
    )
}

/// A table entry: one decimal from 100 on, four in [0.9, 1) (R² near 1), three otherwise.
fn fmt_num(v: f64) -> String {
    if v.abs() >= 100.0 {
        format!("{v:.1}")
    } else if v.abs() >= 0.9 && v.abs() < 1.0 {
        format!("{v:.4}")
    } else {
        format!("{v:.3}")
    }
}

/// The SHA-256 of a file's bytes, in hex.
pub(super) fn sha256_file(path: &Path) -> Result<String> {
    use sha2::{Digest, Sha256};
    let bytes = std::fs::read(path).with_context(|| format!("cannot read {}", path.display()))?;
    Ok(trainer::io::hex(&Sha256::digest(&bytes)))
}

/// The trained model of `--model`: the trainer's model file or an ONNX file (detected by
/// content, `trainer::deploy::onnx::load_any`); says on stderr what an ONNX import found.
pub(super) fn load_model(path: &Path) -> Result<Model> {
    let (m, notes) = trainer::deploy::onnx::load_any(path)?;
    if let Some(n) = notes {
        let act = format!("{:?}", m.mlp.activation).to_lowercase();
        eprintln!(
            "{}: ONNX (producer `{}`, opset {}) read as a {act} MLP {:?}{}; its hash is the file's SHA-256 {}",
            path.display(),
            n.producer,
            n.opset,
            m.mlp.widths(),
            if n.clips_dropped > 0 {
                format!(
                    " ({} Clip of an ampc export dropped: projection onto X and output clamp)",
                    n.clips_dropped
                )
            } else {
                String::new()
            },
            m.content_hash()
        );
    }
    Ok(m)
}

/// An optional path as a path (the empty path, which names no file, when absent).
pub(super) fn opt(p: &Option<PathBuf>) -> &Path {
    p.as_deref().unwrap_or(Path::new(""))
}
