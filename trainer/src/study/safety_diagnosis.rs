//! `safety_diagnosis`: [`CandidateCounts`], why the safe controller's network candidate was
//! or was not applied, counted per step of the safety study (`study::safety`), for the steps
//! at which a safe sequence existed (the ones where the candidate competes with the safe
//! fallback s):
//!
//! ```text
//! checked            steps with a safe sequence before the step
//! outside_u          the network's (finite) candidate c had an input outside U; the controller
//!                    clamps it, c ← Π_U(c), before the check
//! outside_u_taken    … and the clamped candidate was applied
//! non_finite         c had a NaN/±inf entry (or J(c) was not finite)
//! stage_violation    clamped c violates a state-box or path constraint g_k + m_s ≤ 0 (k < N)
//! terminal_miss      clamped c misses g_N(x_N) + m_f ≤ 0 (state box at x_N, terminal
//!                    constraints, terminal set (x_N − x_ref)ᵀP(x_N − x_ref) ≤ α)
//! costlier           c feasible, s feasible, J(c) > J(s): the fallback is applied
//! costlier_rel[b]    of those, (J(c) − J(s)) / J(s) in (0, 1e-4], (1e-4, 1e-3], (1e-3, 1e-2],
//!                    (1e-2, 1e-1], (1e-1, ∞) (b = 0 … 4; J(s) = 0 counts in b = 4)
//! costlier_in_xf     costlier steps whose state x_k was already in the terminal set
//! taken              c applied (feasible ∧ (s infeasible ∨ J(c) ≤ J(s)))
//! ```
//!
//! A candidate can violate a stage constraint and miss the terminal set in the same step
//! (both counted), so the fallback steps are at most
//! `non_finite + stage_violation + terminal_miss + costlier` and at least `costlier`.

use crate::deploy::safe_emulation::{EmulatedOutput, EmulatedPlant};
use controller_core::safe::SafeFlags;
use serde::{Deserialize, Serialize};

/// Upper ends of the `costlier_rel` buckets (the last bucket is unbounded).
pub const COSTLIER_BUCKETS: [f64; 4] = [1e-4, 1e-3, 1e-2, 1e-1];

/// Per-step counts of what happened to the candidate (module doc).
#[derive(Debug, Clone, Copy, Default, PartialEq, Eq, Serialize, Deserialize)]
pub struct CandidateCounts {
    /// Steps with a safe sequence before the step.
    pub checked: u64,
    /// The finite candidate had an input outside U (clamped before the check).
    pub outside_u: u64,
    /// … and the clamped candidate was applied.
    pub outside_u_taken: u64,
    /// A NaN/±inf candidate entry, or a non-finite cost.
    pub non_finite: u64,
    /// The clamped candidate violates a stage (state box / path) constraint with its margin.
    pub stage_violation: u64,
    /// The clamped candidate's x_N fails the terminal check (box, terminal constraints,
    /// terminal set) with its margin.
    pub terminal_miss: u64,
    /// Feasible but costlier than the feasible safe candidate (fallback applied).
    pub costlier: u64,
    /// Costlier steps by relative excess (J(c) − J(s)) / J(s) (module doc's buckets).
    pub costlier_rel: [u64; 5],
    /// Costlier steps whose state was in the terminal set.
    pub costlier_in_xf: u64,
    /// Steps that applied the candidate.
    pub taken: u64,
}

impl CandidateCounts {
    /// Counts one step of the emulated controller at the (f32) state `x`.
    pub fn record(&mut self, plant: &EmulatedPlant, x: &[f32], out: &EmulatedOutput) {
        let f = out.flags;
        let had_safe = f.contains(SafeFlags::FALLBACK)
            || (f.contains(SafeFlags::CANDIDATE) && !f.contains(SafeFlags::INITIALISED));
        if !had_safe {
            return;
        }
        let d = &out.diagnosis;
        let taken = f.contains(SafeFlags::CANDIDATE);
        self.checked += 1;
        self.taken += u64::from(taken);
        self.outside_u += u64::from(d.outside_u);
        self.outside_u_taken += u64::from(d.outside_u && taken);
        let nf = f.contains(SafeFlags::NON_FINITE_CANDIDATE) || !d.detail.cost.is_finite();
        self.non_finite += u64::from(nf);
        self.stage_violation += u64::from(!nf && !d.detail.stage);
        self.terminal_miss += u64::from(!nf && !d.detail.terminal);
        let (c, s) = (out.candidate_cost, out.safe_cost);
        if d.detail.feasible() && s.is_finite() && c > s {
            self.costlier += 1;
            let rel = if s > 0.0 {
                f64::from(c - s) / f64::from(s)
            } else {
                f64::INFINITY
            };
            let b = COSTLIER_BUCKETS
                .iter()
                .position(|e| rel <= *e)
                .unwrap_or(COSTLIER_BUCKETS.len());
            self.costlier_rel[b] += 1;
            self.costlier_in_xf += u64::from(plant.terminal_violation(x) <= 0.0);
        }
    }

    /// The sum of two sets of counts.
    pub fn add(&mut self, o: &CandidateCounts) {
        self.checked += o.checked;
        self.outside_u += o.outside_u;
        self.outside_u_taken += o.outside_u_taken;
        self.non_finite += o.non_finite;
        self.stage_violation += o.stage_violation;
        self.terminal_miss += o.terminal_miss;
        self.costlier += o.costlier;
        for (a, b) in self.costlier_rel.iter_mut().zip(o.costlier_rel) {
            *a += b;
        }
        self.costlier_in_xf += o.costlier_in_xf;
        self.taken += o.taken;
    }

    /// The sum over runs (None when no run has counts).
    pub fn total<'a>(runs: impl Iterator<Item = Option<&'a CandidateCounts>>) -> Option<Self> {
        runs.flatten().fold(None, |acc, c| {
            let mut t = acc.unwrap_or_default();
            t.add(c);
            Some(t)
        })
    }
}
