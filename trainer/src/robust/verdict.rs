//! [`Verdict`]: whether a trained net's certified ε covers a robust design's ε, and on what
//! the answer rests (the paper's Corollary 1).
//!
//! ```text
//! certified      ⇔  ε_cert + a_f32 ≤ ε_design  ∧  ε_cert's tier is sound
//!                   ∧  recursive feasibility proven  ∧  the per-cell check passed
//!                   ∧  every excluded cell proven infeasible  ∧  no feasible state seen in one
//!                   ∧  no feasible state seen outside X
//! conditional    ⇔  ε_cert + a_f32 ≤ ε_design, the check did not fail, no feasible state was
//!                   seen in an excluded cell or outside X, but something above is not proven: each such
//!                   item is listed in `rests_on` (an estimated L_MPC, a sampled recursive
//!                   feasibility, a check not run, excluded cells estimated infeasible)
//! not_certified  otherwise
//! ```
//! (a_f32: the exported controller's f32 allowance, in the 2-norm ε is stated in). Only
//! `certified` says "Corollary 1 applies"; a `conditional` verdict says the corollary holds
//! if the listed items do.

use super::terminal::Feasibility;
use serde::{Deserialize, Serialize};

/// The three verdicts (module doc).
#[derive(Debug, Clone, Copy, PartialEq, Eq, Serialize, Deserialize)]
#[serde(rename_all = "snake_case")]
pub enum VerdictStatus {
    /// Everything the corollary needs is proven.
    Certified,
    /// The numbers meet the design, but the items in `rests_on` are not proven.
    Conditional,
    /// The numbers miss the design, the check failed, or a feasible state lies in an
    /// excluded cell.
    NotCertified,
}

impl VerdictStatus {
    /// The name written in files: `"certified"`, `"conditional"`, `"not_certified"`.
    pub fn name(self) -> &'static str {
        match self {
            VerdictStatus::Certified => "certified",
            VerdictStatus::Conditional => "conditional",
            VerdictStatus::NotCertified => "not_certified",
        }
    }
}

/// The per-cell check of a certificate (`refine --check`, the robust loop's check).
#[derive(Debug, Clone, Copy, PartialEq, Eq, Serialize, Deserialize)]
#[serde(rename_all = "snake_case")]
pub enum Check {
    /// Run and passed.
    Passed,
    /// Run and failed: the certificate's ε is contradicted.
    Failed,
    /// Not run (the verdict then rests on it).
    NotRun,
}

/// What a verdict is computed from.
#[derive(Debug, Clone, PartialEq)]
pub struct Evidence {
    /// The ε the MPC was made robust against.
    pub design_eps: f64,
    /// The certified ε of the net (Theorem 1, or a local certificate).
    pub certified_eps: f64,
    /// The exported controller's f32 allowance (2-norm over the outputs).
    pub f32_allowance: f64,
    /// How recursive feasibility of the tightened OCP is established.
    pub recursive_feasibility: Feasibility,
    /// Whether ε's tier is sound (every term proven).
    pub eps_sound: bool,
    /// What a non-sound ε rests on (the certificate's assumptions, e.g. `l_mpc: sampled …`).
    pub eps_rests_on: Vec<String>,
    /// The per-cell check.
    pub check: Check,
    /// Excluded boxes (certificate's `local.excluded.boxes`) whose infeasibility for the
    /// tightened OCP is not proven (`robust::exclusion`; 0: none, or all proven).
    pub excluded_unproven: usize,
    /// Monte Carlo states feasible for the tightened MPC inside an excluded cell.
    pub feasible_in_excluded: usize,
    /// Monte Carlo states feasible for the tightened MPC outside X (the feasible set
    /// reaching beyond the certified domain, searched in the OCP's state bounds).
    pub feasible_outside_domain: usize,
}

/// The verdict of a certificate against a design (module doc).
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct Verdict {
    /// The ε the MPC was made robust against.
    pub design_eps: f64,
    /// The certified ε of the net (Theorem 1, or a tighter certificate).
    pub certified_eps: f64,
    /// The exported controller's f32 allowance (sound bound on ‖κ_NN,f32 − κ_NN,f64‖₂).
    #[serde(default)]
    pub f32_allowance: f64,
    /// How recursive feasibility of the tightened OCP is established.
    #[serde(default = "unknown")]
    pub recursive_feasibility: Feasibility,
    /// `certified`, `conditional` or `not_certified` (module doc).
    #[serde(default = "not_certified")]
    pub status: VerdictStatus,
    /// True only for [`VerdictStatus::Certified`].
    pub certified: bool,
    /// What a `conditional` verdict rests on (empty for `certified`); for `not_certified`,
    /// what else was not proven.
    #[serde(default)]
    pub rests_on: Vec<String>,
    /// One line for humans, with the numbers and what is missing.
    pub message: String,
}

fn unknown() -> Feasibility {
    Feasibility::Unknown
}

fn not_certified() -> VerdictStatus {
    VerdictStatus::NotCertified
}

/// What the corollary rests on beyond the arithmetic, one item per unproven premise.
fn unproven(e: &Evidence) -> Vec<String> {
    let mut r = Vec::new();
    if !e.eps_sound {
        if e.eps_rests_on.is_empty() {
            r.push("eps: its tier is not sound".to_string());
        }
        r.extend(e.eps_rests_on.iter().cloned());
    }
    if e.recursive_feasibility != Feasibility::Proven {
        r.push(format!(
            "recursive feasibility of the tightened OCP: {} (not proven by a terminal region \
             with sound ρ, w̄ and ρ_f)",
            e.recursive_feasibility.name()
        ));
    }
    if e.check == Check::NotRun {
        r.push("the per-cell check of ε: not run".to_string());
    }
    if e.excluded_unproven > 0 {
        r.push(format!(
            "excluded cells: {} excluded boxes of X are assumed infeasible for the tightened \
             MPC (estimated from their cells' corners; no outer bound of their one-step reach \
             proves it)",
            e.excluded_unproven
        ));
    }
    r
}

/// The verdict of `e` (module doc).
pub fn verdict(e: &Evidence) -> Verdict {
    let (eps, a, design) = (e.certified_eps, e.f32_allowance, e.design_eps);
    let total = eps + a;
    let meets = total.is_finite() && a >= 0.0 && total <= design;
    let rests_on = unproven(e);
    let numbers = format!("ε + f32 allowance = {eps:.4} + {a:.2e}");
    let (status, message) = if !meets {
        (
            VerdictStatus::NotCertified,
            format!(
                "NOT certified: {numbers} exceeds the design ε = {design:.4} (factor {:.1}); \
                 recursive feasibility {}; the closed-loop guarantee does not hold, only the \
                 Monte Carlo evidence below",
                total / design,
                e.recursive_feasibility.name()
            ),
        )
    } else if e.check == Check::Failed {
        (
            VerdictStatus::NotCertified,
            format!(
                "NOT certified: {numbers} ≤ design ε = {design:.4}, but the per-cell check \
                 failed (states whose error exceeds the certified bound): ε is contradicted"
            ),
        )
    } else if e.feasible_in_excluded > 0 {
        (
            VerdictStatus::NotCertified,
            format!(
                "NOT certified: {} feasible Monte Carlo states lie in cells the certificate \
                 excludes (the exclusion reaches into the feasible set, which ε must cover); \
                 {numbers} against the design ε = {design:.4}",
                e.feasible_in_excluded
            ),
        )
    } else if e.feasible_outside_domain > 0 {
        (
            VerdictStatus::NotCertified,
            format!(
                "NOT certified: {} Monte Carlo states outside X are feasible for the tightened \
                 MPC (its feasible set reaches beyond the certified domain, where ε does not \
                 hold); {numbers} against the design ε = {design:.4}",
                e.feasible_outside_domain
            ),
        )
    } else if rests_on.is_empty() {
        (
            VerdictStatus::Certified,
            format!(
                "certified: {numbers} ≤ design ε = {design:.4}, ε is sound, the per-cell check \
                 passed and recursive feasibility is proven (terminal region); Corollary 1 \
                 applies (the closed loop stays in the robust MPC's feasible set)"
            ),
        )
    } else {
        (
            VerdictStatus::Conditional,
            format!(
                "conditional: {numbers} ≤ design ε = {design:.4}, resting on: {}. The \
                 corollary's conclusion holds if these do; it is not established by the \
                 arithmetic, only the Monte Carlo evidence below",
                rests_on.join("; ")
            ),
        )
    };
    Verdict {
        design_eps: design,
        certified_eps: eps,
        f32_allowance: a,
        recursive_feasibility: e.recursive_feasibility,
        status,
        certified: status == VerdictStatus::Certified,
        rests_on,
        message,
    }
}
