//! [`CertificateFile`]: the one reader and writer of `certificate.json` — Theorem 1's terms
//! (or a local certificate's cells), the tier, the statistical blocks, the check result and
//! the requirement — sealed with its checksum ([`super::seal`]) and re-checked on read.
//!
//! ```text
//! Theorem 1:  eps = eps_d + (l_mpc + l_nn)·covering_radius   (the f64 net's bound; the device's
//!             is eps + f32_allowance, the 2-norm bound on |κ_NN,f32 − κ_NN,f64| the export adds)
//! local:      eps = max_C ε_C                      (cells.csv beside the file, when present)
//! band:       u_lo − eps_j ≤ clamp_lo ≤ u_lo,  u_hi ≤ clamp_hi ≤ u_hi + eps_j
//!             eps_j = epsilon_per_input[j] = s_u,j·eps in the certificate's norm
//!             (`norm`: ‖S_u⁻¹Δu‖₂; absent in older files = unscaled, eps_j = eps)
//! tier:       guarantee = max over `tiers`, never stronger than the terms support
//! ```
//!
//! Every writer (`trainer certify --json`, `trainer refine`, the pipeline's certify stage, a
//! Rust caller of the library) goes through [`write_certificate`] / [`CertificateFile::sealed`],
//! so the same inputs give the same bytes. Every reader goes through [`read_certificate`]:
//! a file without a `"checksum"` is refused unless the caller accepts unsealed files
//! (`--accept-unsealed`), which downgrades the tier to `estimated`; a file without
//! `"guarantee"` is refused; [`CertificateFile::recheck`] recomputes what can be recomputed
//! (ε from its terms, the band, the tier from the terms, X and U against the problem, the
//! hashes) and names the first field that disagrees.

use super::certificate::{Certificate, Requirement};
use super::local_summary::LocalSummary;
use super::seal::{Seal, SealError};
use super::statistical::Statistical;
use super::tier::{self, Guarantee, Tier};
use serde::{Deserialize, Serialize};
use std::path::{Path, PathBuf};

/// The file name a run directory keeps its certificate in.
pub const FILE_NAME: &str = crate::io::RunDir::CERTIFICATE;

/// Relative tolerance of the recomputed ε and band (the terms are stored with 17 digits;
/// the sums are recomputed in the same order, so any difference beyond rounding is an edit).
const REL_TOL: f64 = 1e-12;

/// The result of a certificate's check at fresh states (`refine --check`): written into the
/// certificate, so a failed check is part of what it says.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct CheckSummary {
    /// States checked (uniform on X, labelled by the MPC).
    pub states: usize,
    /// States whose error exceeded ε or their cell's ε_C, plus feasible states found in
    /// excluded cells.
    pub exceedances: usize,
    /// Whether the check passed (no exceedance, the per-cell range check within tolerance).
    pub passed: bool,
    /// The check's full report, relative to the certificate (`check.json`).
    pub report: String,
}

/// `certificate.json` as one typed value (keys as in the design's "Certificate" contract;
/// the flattened parts write their keys at the top level, so the file's keys are unchanged).
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct CertificateFile {
    /// The design's keys: ε and its terms, X, U_d, the band, the hashes.
    #[serde(flatten)]
    pub base: Certificate,
    /// `guarantee` (the weakest tier ε rests on), `tiers` (per term), `assumptions`.
    #[serde(flatten)]
    pub guarantee: Guarantee,
    /// A local (per-cell) certificate's figures (`trainer refine`); absent for Theorem 1.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub local: Option<LocalSummary>,
    /// The statistical tier (`--statistical N`).
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub statistical: Option<Statistical>,
    /// The closed-loop statistical tier (`certify --closed-loop`), as written by
    /// `study::statistical_loop::ClosedLoopStatistical` (a later stage's type: kept as
    /// its JSON value here).
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub statistical_closed_loop: Option<serde_json::Value>,
    /// What a target ε requires (`certify --target-eps`).
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub requirement: Option<Requirement>,
    /// The check at fresh states (`refine --check`), when it ran.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub check: Option<CheckSummary>,
}

/// Why a certificate file is refused.
#[derive(Debug, thiserror::Error)]
pub enum CertFileError {
    /// The file cannot be read.
    #[error("{path}: {source}")]
    Io {
        /// The file.
        path: PathBuf,
        /// The cause.
        source: std::io::Error,
    },
    /// Writing the file failed.
    #[error(transparent)]
    Write(#[from] crate::io::FileError),
    /// The checksum does not verify (or is malformed, or the text is not JSON).
    #[error(transparent)]
    Seal(#[from] SealError),
    /// No `"checksum"` and unsealed files were not accepted.
    #[error(
        "{origin}: no `checksum`: an unsealed certificate's numbers cannot be trusted (any \
         edit goes through) — regenerate it with `trainer certify` or `trainer refine`, or \
         pass --accept-unsealed to read it with the tier `estimated`"
    )]
    Unsealed {
        /// The file.
        origin: String,
    },
    /// No `"guarantee"` key: the tier is decided when the certificate is made, not on read.
    #[error(
        "{origin}: no `guarantee` key: the certificate does not say what its ε rests on — \
         regenerate it with `trainer certify` or `trainer refine`"
    )]
    NoGuarantee {
        /// The file.
        origin: String,
    },
    /// A key is missing or has the wrong type (the JSON parser's error names the key).
    #[error("{origin}: not a certificate: {source}")]
    Json {
        /// The file.
        origin: String,
        /// The parser's error.
        #[source]
        source: serde_json::Error,
    },
    /// The text is not a certificate's JSON object.
    #[error("{origin}: not a certificate: {why}")]
    Format {
        /// The file.
        origin: String,
        /// The parser's message (names the key).
        why: String,
    },
    /// A stored value disagrees with what it is recomputed from.
    #[error("{origin}: `{key}` = {found} but {expected}")]
    Inconsistent {
        /// The file.
        origin: String,
        /// The key at fault.
        key: String,
        /// Its stored value.
        found: String,
        /// What it is recomputed as, in words.
        expected: String,
    },
    /// The certificate's check at fresh states failed.
    #[error(
        "{origin}: the certificate's check failed ({exceedances} of {states} states over ε or \
         their cell's ε_C, see {report}): it is not exported"
    )]
    CheckFailed {
        /// The file.
        origin: String,
        /// States checked.
        states: usize,
        /// Exceedances found.
        exceedances: usize,
        /// The check's report.
        report: String,
    },
}

/// What a read certificate is re-checked against (each `None` is skipped).
#[derive(Debug, Clone, Copy, Default)]
pub struct Against<'a> {
    /// SHA-256 of the model the certificate must be about (`hash`).
    pub model_hash: Option<&'a str>,
    /// The problem: its hash (`problem_hash`), its domain X (`domain_lo`, `domain_hi`) and
    /// its stage-0 input bounds U_d (`u_lo`, `u_hi`).
    pub problem: Option<&'a crate::problem::ProblemConfig>,
    /// SHA-256 of the dataset the bound was computed on (`dataset_hash`).
    pub dataset_hash: Option<&'a str>,
    /// A local certificate's `cells.csv` (its `eps_c` column): ε must be its maximum.
    pub cells_csv: Option<&'a Path>,
}

impl CertificateFile {
    /// A Theorem 1 certificate with its tiers ([`tier::theorem1`]).
    pub fn theorem1(base: Certificate) -> Self {
        CertificateFile {
            guarantee: tier::theorem1(&base),
            base,
            local: None,
            statistical: None,
            statistical_closed_loop: None,
            requirement: None,
            check: None,
        }
    }

    /// The tier the terms support: [`tier::local_exact`] for a local certificate,
    /// [`tier::theorem1`] otherwise. A stored `guarantee` may be weaker, never stronger.
    pub fn supported(&self) -> Guarantee {
        match &self.local {
            Some(l) => tier::local_exact(l.cells_exact.unwrap_or(0), l.cells),
            None => tier::theorem1(&self.base),
        }
    }

    /// The tier of the certificate (what export copies).
    pub fn tier(&self) -> Tier {
        self.guarantee.guarantee
    }

    /// The sealed text (pretty JSON with its `checksum`): what [`write_certificate`] writes.
    pub fn sealed(&self) -> Result<String, SealError> {
        super::seal::sealed_json(self)
    }

    /// Parses and verifies a certificate text read from `origin`. Without a checksum it is
    /// refused unless `accept_unsealed`; then its tier is lowered to `estimated` (an
    /// assumption says why) and a missing `guarantee` is taken as `estimated`. Returns the
    /// certificate and whether it was sealed. Call [`CertificateFile::recheck`] next.
    pub fn parse(
        text: &str,
        origin: &str,
        accept_unsealed: bool,
    ) -> Result<(Self, Seal), CertFileError> {
        let seal = super::seal::verify(text, origin)?;
        if seal == Seal::Absent && !accept_unsealed {
            return Err(CertFileError::Unsealed {
                origin: origin.into(),
            });
        }
        let mut v: serde_json::Value =
            serde_json::from_str(text).map_err(|e| CertFileError::Json {
                origin: origin.into(),
                source: e,
            })?;
        let o = v.as_object_mut().ok_or_else(|| CertFileError::Format {
            origin: origin.into(),
            why: "not a JSON object".into(),
        })?;
        if !o.contains_key("guarantee") {
            if seal == Seal::Verified {
                return Err(CertFileError::NoGuarantee {
                    origin: origin.into(),
                });
            }
            o.insert("guarantee".into(), serde_json::json!("estimated"));
        }
        for (k, empty) in [
            ("tiers", serde_json::json!({})),
            ("assumptions", serde_json::json!([])),
        ] {
            if seal == Seal::Absent && !o.contains_key(k) {
                o.insert(k.into(), empty);
            }
        }
        let mut f: CertificateFile =
            serde_json::from_value(v).map_err(|e| CertFileError::Json {
                origin: origin.into(),
                source: e,
            })?;
        if seal == Seal::Absent {
            f.guarantee.guarantee = Tier::Estimated;
            f.guarantee.assumptions.push(format!(
                "unsealed: {origin} carries no checksum, its numbers are not verified \
                 (read with --accept-unsealed)"
            ));
        }
        Ok((f, seal))
    }

    /// Re-checks what can be recomputed (module doc): ε from its terms, the clamp band
    /// against U_d and ε, the tier against its terms, the check result, and whatever
    /// `against` gives (model, problem, dataset, cells). The error names the first key at
    /// fault and the file.
    pub fn recheck(&self, origin: &str, against: &Against<'_>) -> Result<(), CertFileError> {
        let bad = |key: &str, found: String, expected: String| {
            Err(CertFileError::Inconsistent {
                origin: origin.into(),
                key: key.into(),
                found,
                expected,
            })
        };
        let c = &self.base;
        for (key, v) in [
            ("eps", c.eps),
            ("eps_d", c.eps_d),
            ("l_nn", c.l_nn),
            ("l_mpc", c.l_mpc),
            ("covering_radius", c.covering_radius),
            ("f32_allowance", c.f32_allowance),
        ] {
            if !(v.is_finite() && v >= 0.0) {
                return bad(key, v.to_string(), "a finite number ≥ 0".into());
            }
        }
        let close = |a: f64, b: f64| (a - b).abs() <= REL_TOL * a.abs().max(b.abs()).max(1e-300);
        match &self.local {
            None => {
                let terms = c.eps_d + (c.l_mpc + c.l_nn) * c.covering_radius;
                if !close(c.eps, terms) {
                    return bad(
                        "eps",
                        c.eps.to_string(),
                        format!(
                            "ε_D + (L_MPC + L_NN)·r = {} + ({} + {})·{} = {terms}",
                            c.eps_d, c.l_mpc, c.l_nn, c.covering_radius
                        ),
                    );
                }
            }
            Some(l) => {
                if c.eps < c.eps_d {
                    return bad(
                        "eps",
                        c.eps.to_string(),
                        format!(
                            "ε = max_C ε_C ≥ the largest corner error eps_d = {}",
                            c.eps_d
                        ),
                    );
                }
                if l.met && c.eps > l.target_eps {
                    return bad(
                        "local.met",
                        "true".into(),
                        format!("ε = {} > local.target_eps = {}", c.eps, l.target_eps),
                    );
                }
                if let Some(p) = against.cells_csv.filter(|p| p.exists()) {
                    let max = cells_eps_max(p).map_err(|why| CertFileError::Format {
                        origin: p.display().to_string(),
                        why,
                    })?;
                    if !close(c.eps, max) {
                        return bad(
                            "eps",
                            c.eps.to_string(),
                            format!("max_C ε_C = {max} (the eps_c column of {})", p.display()),
                        );
                    }
                }
            }
        }
        self.recheck_band(origin)?;
        self.recheck_tier(origin)?;
        if let Some(k) = &self.check {
            if !k.passed || k.exceedances > 0 {
                return Err(CertFileError::CheckFailed {
                    origin: origin.into(),
                    states: k.states,
                    exceedances: k.exceedances,
                    report: k.report.clone(),
                });
            }
        }
        self.recheck_against(origin, against)
    }

    /// The clamp band inside U_d ⊕ [−ε, ε] and around U_d.
    fn recheck_band(&self, origin: &str) -> Result<(), CertFileError> {
        let c = &self.base;
        let nu = c.u_lo.len();
        for (key, v) in [
            ("u_hi", &c.u_hi),
            ("clamp_lo", &c.clamp_lo),
            ("clamp_hi", &c.clamp_hi),
        ] {
            if v.len() != nu {
                return Err(CertFileError::Inconsistent {
                    origin: origin.into(),
                    key: key.into(),
                    found: format!("{v:?}"),
                    expected: format!("{nu} entries, as u_lo has"),
                });
            }
        }
        self.recheck_norm(origin)?;
        // Per input in physical units (the norm's s_u,j·ε; ε itself for the unscaled norm).
        let per = c.eps_per_input();
        for j in 0..nu {
            let e = per[j];
            let slack = |u: f64| REL_TOL * (u.abs() + e).max(1e-300);
            let (ul, uh, cl, ch) = (c.u_lo[j], c.u_hi[j], c.clamp_lo[j], c.clamp_hi[j]);
            let lo_ok = cl >= ul - e - slack(ul) && cl <= ul;
            let hi_ok = ch <= uh + e + slack(uh) && ch >= uh;
            if !(lo_ok && hi_ok) {
                let key = if lo_ok { "clamp_hi" } else { "clamp_lo" };
                let found = if lo_ok { ch } else { cl };
                return Err(CertFileError::Inconsistent {
                    origin: origin.into(),
                    key: format!("{key}[{j}]"),
                    found: found.to_string(),
                    expected: format!(
                        "the band lies in U_d ⊕ [−ε_{j}, ε_{j}] = [{}, {}] (ε_{j} = {e}, ε per \
                         input in physical units) and contains U_d = [{ul}, {uh}]",
                        ul - e,
                        uh + e
                    ),
                });
            }
        }
        Ok(())
    }

    /// `norm` (when present): one scale per state and input, each finite and > 0; and
    /// `epsilon_per_input` (when present): s_u,j·ε per input, as [`Norm::per_input`]
    /// computes it.
    ///
    /// [`Norm::per_input`]: crate::certify::norm::Norm::per_input
    fn recheck_norm(&self, origin: &str) -> Result<(), CertFileError> {
        let c = &self.base;
        let bad = |key: String, found: String, expected: String| {
            Err(CertFileError::Inconsistent {
                origin: origin.into(),
                key,
                found,
                expected,
            })
        };
        if let Some(n) = &c.scales {
            for (key, v, len) in [
                ("norm.x_scale", &n.x_scale, c.domain_lo.len()),
                ("norm.u_scale", &n.u_scale, c.u_lo.len()),
            ] {
                if v.len() != len {
                    return bad(key.into(), format!("{v:?}"), format!("{len} entries"));
                }
                if let Some(i) = v.iter().position(|s| !(s.is_finite() && *s > 0.0)) {
                    return bad(
                        format!("{key}[{i}]"),
                        v[i].to_string(),
                        "a finite scale > 0".into(),
                    );
                }
            }
        }
        if !c.epsilon_per_input.is_empty() {
            let want = c.norm().per_input(c.eps);
            if c.epsilon_per_input.len() != want.len() {
                return bad(
                    "epsilon_per_input".into(),
                    format!("{:?}", c.epsilon_per_input),
                    format!("{} entries, one per input", want.len()),
                );
            }
            for (j, (f, w)) in c.epsilon_per_input.iter().zip(&want).enumerate() {
                if (f - w).abs() > REL_TOL * f.abs().max(w.abs()).max(1e-300) {
                    return bad(
                        format!("epsilon_per_input[{j}]"),
                        f.to_string(),
                        format!("s_u,{j}·ε = {w} (norm.u_scale[{j}] times eps, rounded up)"),
                    );
                }
            }
        }
        Ok(())
    }

    /// `guarantee` is the weakest of `tiers`, and no term is stronger than its terms support.
    fn recheck_tier(&self, origin: &str) -> Result<(), CertFileError> {
        let g = &self.guarantee;
        let bad = |key: String, found: &str, expected: String| {
            Err(CertFileError::Inconsistent {
                origin: origin.into(),
                key,
                found: format!("\"{found}\""),
                expected,
            })
        };
        if let Some(weakest) = g.tiers.values().max() {
            if g.guarantee < *weakest {
                return bad(
                    "guarantee".into(),
                    g.guarantee.name(),
                    format!("the weakest of `tiers` is \"{}\"", weakest.name()),
                );
            }
        }
        let s = self.supported();
        if g.guarantee < s.guarantee {
            return bad(
                "guarantee".into(),
                g.guarantee.name(),
                format!(
                    "the terms support \"{}\" at most ({})",
                    s.guarantee.name(),
                    s.assumptions.join("; ")
                ),
            );
        }
        for (term, t) in &s.tiers {
            match g.tiers.get(term) {
                Some(stored) if stored < t => {
                    return bad(
                        format!("tiers.{term}"),
                        stored.name(),
                        format!("the term is \"{}\" at most", t.name()),
                    )
                }
                _ => {}
            }
        }
        Ok(())
    }

    /// The part of [`CertificateFile::recheck`] that compares with `a`: the model's hash, the
    /// dataset's, the problem's hash, X and U_d.
    pub fn recheck_against(&self, origin: &str, a: &Against<'_>) -> Result<(), CertFileError> {
        let c = &self.base;
        let bad = |key: &str, found: String, expected: String| {
            Err(CertFileError::Inconsistent {
                origin: origin.into(),
                key: key.into(),
                found,
                expected,
            })
        };
        if let Some(h) = a.model_hash {
            if c.hash != h {
                return bad(
                    "hash",
                    c.hash.clone(),
                    format!(
                        "the model's content hash is {h}: the certificate is about another network"
                    ),
                );
            }
        }
        if let Some(h) = a.dataset_hash {
            if c.dataset_hash != h {
                return bad(
                    "dataset_hash",
                    c.dataset_hash.clone(),
                    format!("the dataset hashes to {h}"),
                );
            }
        }
        if let Some(cfg) = a.problem {
            let ph = cfg.problem_hash();
            if c.problem_hash != ph {
                return bad(
                    "problem_hash",
                    c.problem_hash.clone(),
                    format!("problem `{}` hashes to {ph}", cfg.name),
                );
            }
            for (key, stored, want) in [
                ("domain_lo", &c.domain_lo, &cfg.domain.lo),
                ("domain_hi", &c.domain_hi, &cfg.domain.hi),
            ] {
                if !same(stored, want) {
                    return bad(
                        key,
                        format!("{stored:?}"),
                        format!("the problem's domain X has {key} = {want:?}"),
                    );
                }
            }
            let (ul, uh) = cfg.ocp.u_bounds(0);
            for (key, stored, want) in [("u_lo", &c.u_lo, ul), ("u_hi", &c.u_hi, uh)] {
                if !same(stored, want) {
                    return bad(
                        key,
                        format!("{stored:?}"),
                        format!("the problem's input bounds U_d have {key} = {want:?}"),
                    );
                }
            }
        }
        Ok(())
    }
}

/// Equal vectors up to the JSON parser's last-bit rounding ([`REL_TOL`]).
fn same(a: &[f64], b: &[f64]) -> bool {
    a.len() == b.len()
        && a.iter()
            .zip(b)
            .all(|(x, y)| x == y || (x - y).abs() <= REL_TOL * x.abs().max(y.abs()))
}

/// The largest `eps_c` of a `cells.csv` (as `trainer refine` writes it).
fn cells_eps_max(p: &Path) -> Result<f64, String> {
    let text = std::fs::read_to_string(p).map_err(|e| e.to_string())?;
    let mut lines = text.lines();
    let head = lines.next().ok_or("empty file")?;
    let col = head
        .split(',')
        .position(|h| h == "eps_c")
        .ok_or("no `eps_c` column")?;
    let mut max = f64::NEG_INFINITY;
    for (i, l) in lines.enumerate() {
        let v: f64 = l
            .split(',')
            .nth(col)
            .and_then(|s| s.parse().ok())
            .ok_or_else(|| format!("line {}: no number in column eps_c", i + 2))?;
        max = max.max(v);
    }
    Ok(max)
}

/// Writes `c` sealed to `path` (atomically): the one way a certificate file is written.
pub fn write_certificate(path: &Path, c: &CertificateFile) -> Result<(), CertFileError> {
    let text = c.sealed()?;
    Ok(crate::io::write_atomic(path, text.as_bytes())?)
}

/// Reads and verifies the certificate at `path` ([`CertificateFile::parse`]) and re-checks
/// it against `against` plus its own terms ([`CertificateFile::recheck`]; a local
/// certificate's `cells.csv` beside it is used when `against` names none).
pub fn read_certificate(
    path: &Path,
    accept_unsealed: bool,
    against: &Against<'_>,
) -> Result<(CertificateFile, Seal), CertFileError> {
    let text = std::fs::read_to_string(path).map_err(|e| CertFileError::Io {
        path: path.into(),
        source: e,
    })?;
    let origin = path.display().to_string();
    let (f, seal) = CertificateFile::parse(&text, &origin, accept_unsealed)?;
    let sibling = path.with_file_name(crate::io::RunDir::CELLS);
    let mut a = *against;
    if a.cells_csv.is_none() && f.local.is_some() {
        a.cells_csv = Some(&sibling);
    }
    f.recheck(&origin, &a)?;
    Ok((f, seal))
}

#[cfg(test)]
#[path = "file_tests.rs"]
mod tests;
