//! The labelled dataset D̂ = {(x_i, κ(x_i), ∂κ/∂x(x_i))}: generation, files, shards.
//!
//! **Generation.** The sampler's states are cut into fixed chunks of [`CHUNK`] consecutive
//! indices. A chunk is solved sequentially (each state warm-started from the previous
//! state's solution when `solver.warm_start` is on, after a cold start for the chunk's first
//! state); chunks run in parallel on rayon's pool. A label therefore depends only on its
//! chunk, never on the thread count or the schedule, and shards (`--shard K/N` takes the
//! chunks c with c mod N = K) merge into exactly the single-run dataset.
//!
//! **File format** (version [`FORMAT_VERSION`]): the postcard encoding of [`Dataset`]
//! (magic, version, header, records sorted by index) followed by its SHA-256. A dataset
//! imported from another solver (`trainer import`) is version [`IMPORTED_FORMAT_VERSION`]:
//! the same bytes followed by the postcard encoding of its
//! [`ImportedLabels`], then the SHA-256 of it all; ampc's
//! own datasets stay version 2, byte for byte, unless their starts disagreed somewhere
//! (`solver.starts`, `crate::mpc::law::starts`): then version [`STARTS_FORMAT_VERSION`], the
//! same bytes followed by the postcard encoding of the ascending indices where they did
//! ([`Dataset::disagree`]). A dataset that keeps the optimal input sequences
//! (`[training] outputs = "sequence"`, [`ProblemConfig::keeps_sequences`]) is version
//! [`SEQUENCE_FORMAT_VERSION`]: the version-2 bytes, then the postcard encoding of the
//! disagreeing indices (possibly empty), then that of one sequence per record
//! ([`Record::seq`]: u₀*, …, u_{N−1}*, N·nu f64, empty for an unlabelled state) — N·nu·8
//! bytes more per state (the pendulum's N = 20, nu = 1: 160 bytes beside a version-2
//! record's ≈ 90; the quadrotor's N·nu·8 likewise); all versions are read
//! (`crate::io::seal`; one flipped byte is an error naming the file). Written atomically (temporary file +
//! rename). A run appends each batch of chunks to a checkpoint `<out>.partial` (an
//! append-only log, [`checkpoint`]) and resumes from it when restarted with the same
//! problem, sampler and shard.
//!
//! **CSV export** (for Python users): `index,x1..xn,u1..um,du1_dx1,…,dum_dxn,cost,status,
//! iterations,kkt,degenerate,max_slack`, one row per record; unlabelled states have `NaN`s.

use crate::data::sampling::Sampler;
pub mod checkpoint;
mod csv;
pub(crate) mod gate;
pub(crate) mod labels;
mod sequences;
pub use gate::LabelsError;
pub use labels::ImportedLabels;

use crate::io::{decode_checked, write_atomic};
use crate::mpc::law::{Label, MpcLaw};
use crate::mpc::sensitivity::Degeneracy;
use crate::mpc::sqp::{PrimalDual, SqpStatus};
use crate::problem::{ProblemConfig, SamplingSettings};
use rayon::prelude::*;
use serde::{Deserialize, Serialize};
use std::path::{Path, PathBuf};

/// Dataset file format version (labels from ampc's own solver).
pub const FORMAT_VERSION: u32 = 2;
/// Format version of a dataset whose labels were imported: version 2 plus its
/// [`ImportedLabels`] after the records.
pub const IMPORTED_FORMAT_VERSION: u32 = 3;
/// Format version of a dataset of ampc's solver with states where the starts disagree:
/// version 2 plus the list of those indices ([`Dataset::disagree`]).
pub const STARTS_FORMAT_VERSION: u32 = 4;
/// Format version of a dataset that keeps the optimal input sequences: version 2 plus the
/// disagreeing indices and one sequence per record ([`Record::seq`]).
pub const SEQUENCE_FORMAT_VERSION: u32 = 5;
/// Magic bytes at the start of a dataset file.
pub const MAGIC: [u8; 8] = *b"AMPCDSET";
/// States per chunk (the unit of warm starting, parallelism, sharding and checkpoints).
pub const CHUNK: usize = 16;

/// Errors of dataset generation and files.
#[derive(Debug, thiserror::Error)]
pub enum DatasetError {
    /// Reading or writing a file failed.
    #[error("{path}: {source}")]
    Io {
        /// The file.
        path: String,
        /// The I/O error.
        source: std::io::Error,
    },
    /// A file is not a dataset of this version, or is corrupt.
    #[error("{path}: {reason}")]
    Format {
        /// The file.
        path: String,
        /// What is wrong.
        reason: String,
    },
    /// A part of a file does not decode.
    #[error("{path}: {part}: {source}")]
    Decode {
        /// The file.
        path: String,
        /// The part that does not decode (`decode error` for the whole body).
        part: &'static str,
        /// The decoder's error.
        source: postcard::Error,
    },
    /// Shards cannot be merged.
    #[error("cannot merge: {0}")]
    Merge(String),
    /// A bad shard specification.
    #[error("invalid shard `{0}`: expected K/N with 0 ≤ K < N")]
    Shard(String),
}

impl From<crate::io::FileError> for DatasetError {
    fn from(e: crate::io::FileError) -> Self {
        match e {
            crate::io::FileError::Io { path, source } => DatasetError::Io { path, source },
            crate::io::FileError::Format { path, reason } => DatasetError::Format { path, reason },
            crate::io::FileError::Decode { path, source } => DatasetError::Decode {
                path,
                part: "decode error",
                source,
            },
        }
    }
}

/// `K/N`: this process computes the chunks c with c mod N = K.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Serialize, Deserialize)]
pub struct Shard {
    /// This shard's index K.
    pub index: u32,
    /// Number of shards N.
    pub count: u32,
}

impl std::str::FromStr for Shard {
    type Err = DatasetError;
    fn from_str(s: &str) -> Result<Self, Self::Err> {
        let err = || DatasetError::Shard(s.to_string());
        let (k, n) = s.split_once('/').ok_or_else(err)?;
        let index: u32 = k.trim().parse().map_err(|_| err())?;
        let count: u32 = n.trim().parse().map_err(|_| err())?;
        if count == 0 || index >= count {
            return Err(err());
        }
        Ok(Shard { index, count })
    }
}

/// What a dataset was made from.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct Header {
    /// Problem name.
    pub problem: String,
    /// [`ProblemConfig::problem_hash`] of the labelling problem.
    pub problem_hash: String,
    /// The full problem file (TOML) used, for reproduction.
    pub config_toml: String,
    /// State dimension.
    pub nx: u32,
    /// Input dimension.
    pub nu: u32,
    /// The sampler.
    pub sampling: SamplingSettings,
    /// Number of states of the whole plan (all shards).
    pub total: u64,
    /// The shard this file holds (`None`: the whole plan).
    pub shard: Option<Shard>,
    /// Chunk size used.
    pub chunk: u32,
}

/// One labelled state.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct Record {
    /// Index in the sampling plan.
    pub index: u64,
    /// State x.
    pub x: Vec<f64>,
    /// κ(x) (NaN if unlabelled).
    pub u: Vec<f64>,
    /// ∂κ/∂x, row-major nu × nx (NaN if unlabelled).
    pub du_dx: Vec<f64>,
    /// Optimal cost.
    pub cost: f64,
    /// Solve status.
    pub status: SqpStatus,
    /// SQP + polish iterations.
    pub iterations: u32,
    /// Final KKT residual.
    pub kkt: f64,
    /// Sensitivity degeneracy (the Jacobian term should be dropped in training).
    pub degeneracy: Option<Degeneracy>,
    /// Largest state-bound slack (soft labels), 0 otherwise.
    pub max_slack: f64,
    /// The optimal input sequence u₀*, …, u_{N−1}*, row-major N × nu (empty when not kept
    /// or unlabelled). Stored after the records in format version
    /// [`SEQUENCE_FORMAT_VERSION`] only.
    #[serde(skip)]
    pub seq: Vec<f64>,
}

impl Record {
    /// Builds a record from a label.
    pub fn from_label(index: u64, l: Label) -> Self {
        Record {
            index,
            x: l.x,
            u: l.u,
            du_dx: l.du_dx,
            cost: l.cost,
            status: l.status,
            iterations: l.info.iterations as u32,
            kkt: l.info.kkt.max(),
            degeneracy: l.degeneracy,
            max_slack: l.max_slack,
            seq: l.seq,
        }
    }
    /// Whether the record may be used for training (hard or soft label).
    pub fn is_labelled(&self) -> bool {
        self.status.is_labelled()
    }
}

/// A dataset file's content.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct Dataset {
    /// Must equal [`MAGIC`].
    pub magic: [u8; 8],
    /// Must equal [`FORMAT_VERSION`].
    pub version: u32,
    /// Provenance.
    pub header: Header,
    /// Records sorted by index.
    pub records: Vec<Record>,
    /// Where the labels come from when they were imported (`None`: ampc's solver). Stored
    /// after the records in format version [`IMPORTED_FORMAT_VERSION`] only.
    #[serde(skip)]
    pub labels: Option<ImportedLabels>,
    /// Ascending indices of the states where the starts reached different hard optima (cost
    /// and u₀ apart, `crate::mpc::law::starts`); the label is the lowest-cost one. Stored
    /// after the records in format version [`STARTS_FORMAT_VERSION`] only (non-empty).
    #[serde(skip)]
    pub disagree: Vec<u64>,
}

/// The format version of ampc's own dataset with these disagreeing indices and records
/// (with sequences: [`SEQUENCE_FORMAT_VERSION`]).
pub fn own_version(disagree: &[u64], records: &[Record]) -> u32 {
    if records.iter().any(|r| !r.seq.is_empty()) {
        SEQUENCE_FORMAT_VERSION
    } else if disagree.is_empty() {
        FORMAT_VERSION
    } else {
        STARTS_FORMAT_VERSION
    }
}

/// Counts by status, for reports.
#[derive(Debug, Clone, Copy, Default, PartialEq, Eq)]
pub struct Counts {
    /// All records.
    pub total: usize,
    /// Hard optimum.
    pub converged: usize,
    /// Soft (exact-penalty) label of a hard-infeasible state.
    pub soft: usize,
    /// Infeasible, unlabelled.
    pub infeasible: usize,
    /// Max-iterations or numerical failures.
    pub failed: usize,
    /// Labelled points whose sensitivity is degenerate.
    pub degenerate: usize,
}

impl Dataset {
    /// Status counts.
    pub fn counts(&self) -> Counts {
        let mut c = Counts {
            total: self.records.len(),
            ..Default::default()
        };
        for r in &self.records {
            match r.status {
                SqpStatus::Converged => c.converged += 1,
                SqpStatus::Soft => c.soft += 1,
                SqpStatus::Infeasible => c.infeasible += 1,
                _ => c.failed += 1,
            }
            if r.is_labelled() && r.degeneracy.is_some() {
                c.degenerate += 1;
            }
        }
        c
    }

    /// Reads and checks a dataset file.
    pub fn load(path: &Path) -> Result<Self, DatasetError> {
        let bytes = std::fs::read(path).map_err(|source| DatasetError::Io {
            path: path.display().to_string(),
            source,
        })?;
        Self::from_bytes(&bytes, &path.display().to_string())
    }

    /// Decodes and checks a dataset from bytes; `origin` names it in errors.
    pub fn from_bytes(bytes: &[u8], origin: &str) -> Result<Self, DatasetError> {
        let fmt = |reason: String| DatasetError::Format {
            path: origin.to_string(),
            reason,
        };
        // Both versions pass the version check; version 3 then reads its labels record.
        let mut d: Dataset = decode_checked(
            bytes,
            origin,
            &MAGIC,
            "dataset",
            |d: &Dataset| match d.version {
                IMPORTED_FORMAT_VERSION | STARTS_FORMAT_VERSION | SEQUENCE_FORMAT_VERSION => {
                    FORMAT_VERSION
                }
                v => v,
            },
            FORMAT_VERSION,
        )?;
        if d.version == IMPORTED_FORMAT_VERSION {
            let body = crate::io::unseal(bytes).unwrap_or_default();
            let labels = postcard::take_from_bytes::<Dataset>(body)
                .and_then(|(_, rest)| postcard::from_bytes::<ImportedLabels>(rest))
                .map_err(|source| DatasetError::Decode {
                    path: origin.to_string(),
                    part: "imported dataset without its labels record",
                    source,
                })?;
            d.labels = Some(labels);
        }
        if d.version == STARTS_FORMAT_VERSION {
            let body = crate::io::unseal(bytes).unwrap_or_default();
            d.disagree = postcard::take_from_bytes::<Dataset>(body)
                .and_then(|(_, rest)| postcard::from_bytes::<Vec<u64>>(rest))
                .map_err(|source| DatasetError::Decode {
                    path: origin.to_string(),
                    part: "dataset without its list of disagreeing starts",
                    source,
                })?;
        }
        if d.version == SEQUENCE_FORMAT_VERSION {
            d.read_sequences(bytes, origin)?;
        }
        let (nx, nu) = (d.header.nx as usize, d.header.nu as usize);
        for (i, r) in d.records.iter().enumerate() {
            if r.x.len() != nx || r.u.len() != nu || r.du_dx.len() != nx * nu {
                return Err(fmt(format!("record {i} has wrong dimensions")));
            }
            if i > 0 && d.records[i - 1].index >= r.index {
                return Err(fmt(format!("record {i} is out of order")));
            }
            if r.index >= d.header.total {
                return Err(fmt(format!(
                    "record {i} has index {} ≥ total {}",
                    r.index, d.header.total
                )));
            }
        }
        Ok(d)
    }

    /// Encodes the dataset (postcard, then the imported labels record if any, sealed with
    /// its checksum).
    pub fn to_bytes(&self) -> Vec<u8> {
        let mut body = postcard::to_allocvec(self).unwrap_or_default();
        if let Some(l) = &self.labels {
            body.extend(postcard::to_allocvec(l).unwrap_or_default());
        }
        if self.version == STARTS_FORMAT_VERSION || self.version == SEQUENCE_FORMAT_VERSION {
            body.extend(postcard::to_allocvec(&self.disagree).unwrap_or_default());
        }
        if self.version == SEQUENCE_FORMAT_VERSION {
            let seqs: Vec<&Vec<f64>> = self.records.iter().map(|r| &r.seq).collect();
            body.extend(postcard::to_allocvec(&seqs).unwrap_or_default());
        }
        crate::io::seal(body)
    }

    /// Writes the dataset atomically.
    pub fn save(&self, path: &Path) -> Result<(), DatasetError> {
        Ok(write_atomic(path, &self.to_bytes())?)
    }
}

/// The checkpoint path of an output file.
pub fn partial_path(out: &Path) -> PathBuf {
    let mut s = out.as_os_str().to_owned();
    s.push(".partial");
    PathBuf::from(s)
}

/// The CSV path written beside a dataset file (`.csv` extension).
pub fn csv_path(out: &Path) -> PathBuf {
    out.with_extension("csv")
}

/// Labels one chunk of the plan: indices `[start, end)`, solved in order, warm-started
/// (and from the other `solver.starts`).
pub fn label_chunk(
    law: &mut MpcLaw,
    sampler: &Sampler,
    start: usize,
    end: usize,
    warm_start: bool,
) -> Vec<Record> {
    label_chunk_with(law, sampler, start, end, warm_start).0
}

/// [`label_chunk`] with the indices where the starts disagree.
pub fn label_chunk_with(
    law: &mut MpcLaw,
    sampler: &Sampler,
    start: usize,
    end: usize,
    warm_start: bool,
) -> (Vec<Record>, Vec<u64>) {
    let nx = law.hard_solver().ocp.nx;
    let mut x = vec![0.0; nx];
    let mut prev: Option<PrimalDual> = None;
    let mut out = Vec::with_capacity(end - start);
    // The chunk's labelled states and solutions, for the `neighbour` start.
    let keep = law.starts().contains(&crate::problem::Start::Neighbour);
    let mut done: Vec<(Vec<f64>, PrimalDual)> = Vec::new();
    let scale = sampler.widths();
    let mut disagree = Vec::new();
    for i in start..end {
        sampler.point(i, &mut x);
        let near = crate::mpc::law::starts::nearest(&done, &x, &scale);
        let warm = if warm_start { prev.as_ref() } else { None };
        let (label, sol) = law.solve_starts(&x, warm, near);
        if let (true, Some(p)) = (keep, &sol) {
            done.push((x.clone(), p.clone()));
        }
        prev = sol.or(prev);
        if label.optima > 1 {
            disagree.push(i as u64);
        }
        out.push(Record::from_label(i as u64, label));
    }
    (out, disagree)
}

/// Options of a generation run.
#[derive(Debug, Clone, Default)]
pub struct GenerateOptions {
    /// Compute only this shard.
    pub shard: Option<Shard>,
    /// Show a progress bar (rate, ETA) on stderr.
    pub progress: bool,
}

/// Generates (or resumes) the dataset of `cfg` into `out` (plus the CSV beside it).
pub fn generate(
    cfg: &ProblemConfig,
    out: &Path,
    opts: &GenerateOptions,
) -> Result<Dataset, DatasetError> {
    let sampler = Sampler::new(&cfg.sampling, &cfg.domain);
    let total = sampler.len();
    let header = Header {
        problem: cfg.name.clone(),
        problem_hash: cfg.problem_hash(),
        config_toml: toml::to_string(cfg).unwrap_or_default(),
        nx: cfg.system.nx() as u32,
        nu: cfg.system.nu() as u32,
        sampling: cfg.sampling.clone(),
        total: total as u64,
        shard: opts.shard,
        chunk: CHUNK as u32,
    };
    let n_chunks = total.div_ceil(CHUNK);
    let mine: Vec<usize> = (0..n_chunks)
        .filter(|c| {
            opts.shard
                .is_none_or(|s| c % s.count as usize == s.index as usize)
        })
        .collect();
    // Resume from a checkpoint of the same plan. A device or FIFO (`--out /dev/null`) has
    // no folder of its own to hold a checkpoint or a CSV beside it: neither is written.
    let special = crate::io::is_special(out);
    let partial = partial_path(out);
    let mut records: Vec<Record> = Vec::new();
    let mut disagree: Vec<u64> = Vec::new();
    if let Some(bytes) = (!special).then(|| std::fs::read(&partial).ok()).flatten() {
        // A checkpoint of another plan or of another format: start afresh; a damaged tail
        // costs its batches only.
        if let Some((h, r, d)) = checkpoint::read_with(&bytes) {
            if h == header {
                (records, disagree) = (r, d);
            }
        }
    }
    // The first batch rewrites the checkpoint with the resumed records (dropping a damaged
    // tail, after which appended frames would be unreadable); later batches are appended.
    let keep = cfg.keeps_sequences();
    if keep && records.iter().any(|r| r.is_labelled() && r.seq.is_empty()) {
        // A checkpoint written without sequences cannot complete a dataset that keeps them.
        (records, disagree) = (Vec::new(), Vec::new());
    }
    if !keep {
        records.iter_mut().for_each(|r| r.seq = Vec::new());
    }
    let mut fresh = true;
    let done: std::collections::HashSet<usize> =
        records.iter().map(|r| r.index as usize / CHUNK).collect();
    let todo: Vec<usize> = mine.iter().copied().filter(|c| !done.contains(c)).collect();
    let n_mine: usize = mine
        .iter()
        .map(|&c| (CHUNK * (c + 1)).min(total) - CHUNK * c)
        .sum();
    let bar = if opts.progress {
        let b = indicatif::ProgressBar::new(n_mine as u64);
        b.set_style(
            indicatif::ProgressStyle::with_template(
                "{spinner} labelling [{bar:30}] {pos}/{len} states  {per_sec}  ETA {eta}",
            )
            .unwrap_or_else(|_| indicatif::ProgressStyle::default_bar())
            .progress_chars("=> "),
        );
        b.set_position(records.len() as u64);
        b
    } else {
        indicatif::ProgressBar::hidden()
    };
    let warm = cfg.solver.warm_start;
    let batch = (rayon::current_num_threads() * 8).max(8);
    for group in todo.chunks(batch) {
        let new: Vec<(Vec<Record>, Vec<u64>)> = group
            .par_iter()
            .map_init(
                || MpcLaw::new(cfg),
                |law, &c| {
                    let mut r = label_chunk_with(
                        law,
                        &sampler,
                        c * CHUNK,
                        ((c + 1) * CHUNK).min(total),
                        warm,
                    );
                    if !keep {
                        r.0.iter_mut().for_each(|rec| rec.seq = Vec::new());
                    }
                    bar.inc(r.0.len() as u64);
                    r
                },
            )
            .collect();
        let (new, new_d): (Vec<Vec<Record>>, Vec<Vec<u64>>) = new.into_iter().unzip();
        let (new, new_d): (Vec<Record>, Vec<u64>) = (new.concat(), new_d.concat());
        if special {
            records.extend(new);
            disagree.extend(new_d);
        } else if fresh {
            records.extend(new);
            disagree.extend(new_d);
            checkpoint::create_with(&partial, &header, &records, &disagree)?;
            fresh = false;
        } else {
            checkpoint::append_with(&partial, &new, &new_d)?;
            records.extend(new);
            disagree.extend(new_d);
        }
    }
    bar.finish_and_clear();
    records.sort_by_key(|r| r.index);
    disagree.sort_unstable();
    let d = Dataset {
        magic: MAGIC,
        version: own_version(&disagree, &records),
        header,
        records,
        labels: None,
        disagree,
    };
    // The dataset and its CSV as one set: a failure leaves the previous pair.
    if special {
        crate::io::write_atomic(out, &d.to_bytes())?;
        return Ok(d);
    }
    let csv = csv_path(out);
    crate::io::write_atomic_all(&[(&csv, d.to_csv().as_bytes()), (out, &d.to_bytes())])?;
    let _ = std::fs::remove_file(&partial);
    Ok(d)
}

/// Merges shard files into the single-run dataset (byte-identical to an unsharded run).
pub fn merge(inputs: &[Dataset]) -> Result<Dataset, DatasetError> {
    let first = inputs
        .first()
        .ok_or_else(|| DatasetError::Merge("no input files".into()))?;
    let mut base = first.header.clone();
    base.shard = None;
    let n = first.header.shard.map(|s| s.count).ok_or_else(|| {
        DatasetError::Merge("input 1 is not a shard (it holds the whole plan)".into())
    })?;
    let mut seen = vec![false; n as usize];
    for (i, d) in inputs.iter().enumerate() {
        let mut h = d.header.clone();
        let s = h
            .shard
            .take()
            .ok_or_else(|| DatasetError::Merge(format!("input {} is not a shard", i + 1)))?;
        if h != base {
            return Err(DatasetError::Merge(format!(
                "input {} was made from another problem, sampler or format than input 1",
                i + 1
            )));
        }
        if s.count != n {
            return Err(DatasetError::Merge(format!(
                "input {} is shard {}/{}, not of {n}",
                i + 1,
                s.index,
                s.count
            )));
        }
        if std::mem::replace(&mut seen[s.index as usize], true) {
            return Err(DatasetError::Merge(format!(
                "shard {}/{n} given twice",
                s.index
            )));
        }
    }
    let missing: Vec<String> = seen
        .iter()
        .enumerate()
        .filter(|(_, &s)| !s)
        .map(|(k, _)| format!("{k}/{n}"))
        .collect();
    if !missing.is_empty() {
        return Err(DatasetError::Merge(format!(
            "missing shards: {}",
            missing.join(", ")
        )));
    }
    let mut records: Vec<Record> = inputs
        .iter()
        .flat_map(|d| d.records.iter().cloned())
        .collect();
    records.sort_by_key(|r| r.index);
    if records.len() as u64 != base.total || records.windows(2).any(|w| w[0].index == w[1].index) {
        return Err(DatasetError::Merge(format!(
            "shards hold {} records for a plan of {} states (incomplete shard files?)",
            records.len(),
            base.total
        )));
    }
    let mut disagree: Vec<u64> = inputs.iter().flat_map(|d| d.disagree.clone()).collect();
    disagree.sort_unstable();
    Ok(Dataset {
        magic: MAGIC,
        version: own_version(&disagree, &records),
        header: base,
        records,
        labels: None,
        disagree,
    })
}

#[cfg(test)]
mod tests;
