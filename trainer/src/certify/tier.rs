//! [`Tier`]: what a bound rests on — **sound** (the code's arithmetic proves it),
//! **statistical** (holds with a stated probability and confidence) or **estimated** (rests
//! on an assumption) — and the rule that a certificate's `"guarantee"` is the weakest tier
//! of the terms its ε is built from:
//!
//!   guarantee(ε) = max_{t ∈ terms(ε)} tier(t),   sound < statistical < estimated.
//!
//! For Theorem 1, ε = ε_D + (L_MPC + L_NN)·r: ε_D is computed from the labels (sound up to
//! the solver's tolerance, which the labels' KKT residuals record; estimated for labels
//! imported from another solver, of which only a sample is re-solved), L_NN is a sound upper
//! bound (product of norms, LipSDP-Neuron or slope vertices), r is exact for a grid and a
//! sound upper bound for scattered data, and L_MPC is sampled unless given (estimated: a
//! value passed with `--l-mpc` is the user's assumption, not something the code proves).
//! For a local certificate (refinement) the corner errors and the network's enclosures are
//! sound, the MPC's range inside a cell is estimated from its corners — except where the
//! MPC is a QP and the cell's critical-region proof succeeds (`certify::critical`): there
//! the MPC part is exact, and a certificate all of whose cells are exact is sound.

use super::certificate::Certificate;
use serde::{Deserialize, Serialize};
use std::collections::BTreeMap;

/// The tier of a bound, ordered from strongest to weakest.
#[derive(Debug, Clone, Copy, PartialEq, Eq, PartialOrd, Ord, Hash, Serialize, Deserialize)]
#[serde(rename_all = "snake_case")]
pub enum Tier {
    /// Follows from the code's arithmetic.
    Sound,
    /// Holds with a stated probability and confidence.
    Statistical,
    /// Rests on an assumption (e.g. a sampled Lipschitz constant).
    Estimated,
}

impl Tier {
    /// The tier's name as written in files (`"sound"`, `"statistical"`, `"estimated"`).
    pub fn name(self) -> &'static str {
        match self {
            Tier::Sound => "sound",
            Tier::Statistical => "statistical",
            Tier::Estimated => "estimated",
        }
    }
}

/// The tier of every term of an ε and the weakest of them.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct Guarantee {
    /// The weakest tier of the terms: what ε as a whole is.
    pub guarantee: Tier,
    /// Per term, its tier.
    pub tiers: BTreeMap<String, Tier>,
    /// The terms that are not sound, with what they rest on.
    pub assumptions: Vec<String>,
    /// What even a sound ε is about: the definition of the MPC the arithmetic bounds (e.g.
    /// a QP with the f64 plant data, [`crate::certify::critical::QP_DATA_NOTE`]). Not an
    /// unproven term: the tier does not depend on it, but every export repeats it.
    #[serde(default, skip_serializing_if = "Vec::is_empty")]
    pub premises: Vec<String>,
}

impl Guarantee {
    /// From `(term, tier, what a non-sound term rests on)`.
    pub fn from_terms(terms: &[(&str, Tier, &str)]) -> Self {
        Guarantee {
            guarantee: terms.iter().map(|t| t.1).max().unwrap_or(Tier::Estimated),
            tiers: terms.iter().map(|t| (t.0.to_string(), t.1)).collect(),
            assumptions: terms
                .iter()
                .filter(|t| t.1 != Tier::Sound)
                .map(|t| format!("{}: {}", t.0, t.2))
                .collect(),
            premises: Vec::new(),
        }
    }

    /// What ε rests on besides proof, for the exported files: the assumptions, then the
    /// premises.
    pub fn rests_on(&self) -> Vec<String> {
        self.assumptions
            .iter()
            .chain(&self.premises)
            .cloned()
            .collect()
    }
}

/// The tiers of a Theorem 1 certificate.
pub fn theorem1(c: &Certificate) -> Guarantee {
    let l_mpc = if c.l_mpc_is_estimate {
        (
            Tier::Estimated,
            "sampled from the data's sensitivities (an estimate)",
        )
    } else {
        (
            Tier::Estimated,
            "the value given with --l-mpc (the user's assumption)",
        )
    };
    // Labels from another solver are κ only as far as that solver is: the re-solve checks a
    // sample of them, the rest is taken on trust.
    let imported = c.labels.as_ref().map(|l| {
        format!(
            "the imported labels of {} are the MPC's ({} of {} re-solved by ampc{})",
            l.file,
            l.resolved,
            l.rows,
            if l.trusted {
                ", disagreements accepted"
            } else {
                ""
            }
        )
    });
    let eps_d = match &imported {
        Some(why) => (Tier::Estimated, why.as_str()),
        None => (Tier::Sound, ""),
    };
    Guarantee::from_terms(&[
        ("eps_d", eps_d.0, eps_d.1),
        ("l_nn", Tier::Sound, ""),
        ("l_mpc", l_mpc.0, l_mpc.1),
        ("covering_radius", Tier::Sound, ""),
        ("f32_allowance", Tier::Sound, ""),
    ])
}

/// The tiers of a local (per-cell) certificate.
pub fn local() -> Guarantee {
    Guarantee::from_terms(&[
        ("corner_errors", Tier::Sound, ""),
        ("network_enclosures", Tier::Sound, ""),
        (
            "mpc_range",
            Tier::Estimated,
            "the MPC's variation inside a cell, estimated from its corners' sensitivities \
             with a safety factor",
        ),
        ("f32_allowance", Tier::Sound, ""),
    ])
}

/// The tiers of a local certificate of which `exact` of `cells` cells have an exact MPC
/// part ([`crate::certify::critical`]: the MPC is a QP and κ is proven affine piecewise on
/// the cell). All exact: every term is sound and nothing is assumed. None: [`local`].
pub fn local_exact(exact: usize, cells: usize) -> Guarantee {
    if exact == 0 || cells == 0 {
        return local();
    }
    let mut g = local_exact_terms(exact, cells);
    g.premises
        .push(crate::certify::critical::QP_DATA_NOTE.to_string());
    g
}

/// [`local_exact`]'s terms (with at least one exact cell).
fn local_exact_terms(exact: usize, cells: usize) -> Guarantee {
    if exact == cells {
        return Guarantee::from_terms(&[
            ("corner_errors", Tier::Sound, ""),
            ("network_enclosures", Tier::Sound, ""),
            ("mpc_range", Tier::Sound, ""),
            ("f32_allowance", Tier::Sound, ""),
        ]);
    }
    let why = format!(
        "the MPC's variation inside {} of {cells} cells, estimated from their corners' \
         sensitivities with a safety factor ({exact} cells are exact: κ proven affine on them)",
        cells - exact
    );
    Guarantee::from_terms(&[
        ("corner_errors", Tier::Sound, ""),
        ("network_enclosures", Tier::Sound, ""),
        ("mpc_range", Tier::Estimated, &why),
        ("f32_allowance", Tier::Sound, ""),
    ])
}

#[cfg(test)]
mod tests {
    use super::*;

    /// A local certificate with exact (QP) cells states what the sound MPC part is about —
    /// the QP with the f64 plant data — and one without exact cells does not.
    #[test]
    fn exact_cells_state_the_qp_data_premise() {
        for (exact, cells) in [(4, 4), (1, 4)] {
            let g = local_exact(exact, cells);
            assert_eq!(
                g.premises,
                vec![crate::certify::critical::QP_DATA_NOTE.to_string()]
            );
            assert_eq!(
                g.rests_on().last().map(String::as_str),
                Some(crate::certify::critical::QP_DATA_NOTE)
            );
        }
        assert_eq!(local_exact(4, 4).guarantee, Tier::Sound);
        assert!(local_exact(0, 4).premises.is_empty());
        assert!(local().premises.is_empty());
    }

    #[test]
    fn the_weakest_term_decides() {
        let g = Guarantee::from_terms(&[("a", Tier::Sound, ""), ("b", Tier::Sound, "")]);
        assert_eq!(g.guarantee, Tier::Sound);
        assert!(g.assumptions.is_empty());
        let g = Guarantee::from_terms(&[("a", Tier::Sound, ""), ("b", Tier::Statistical, "99 %")]);
        assert_eq!(g.guarantee, Tier::Statistical);
        assert_eq!(g.assumptions, vec!["b: 99 %".to_string()]);
        let g =
            Guarantee::from_terms(&[("a", Tier::Estimated, "x"), ("b", Tier::Statistical, "y")]);
        assert_eq!(g.guarantee, Tier::Estimated);
        assert_eq!(
            serde_json::to_value(g).unwrap()["tiers"]["b"],
            serde_json::json!("statistical")
        );
        assert_eq!(local().guarantee, Tier::Estimated);
    }

    #[test]
    fn a_local_certificate_is_sound_only_when_every_cell_is_exact() {
        assert_eq!(local_exact(0, 10), local());
        let g = local_exact(10, 10);
        assert_eq!(g.guarantee, Tier::Sound);
        assert!(g.assumptions.is_empty());
        assert_eq!(g.tiers["mpc_range"], Tier::Sound);
        let g = local_exact(9, 10);
        assert_eq!(g.guarantee, Tier::Estimated);
        assert_eq!(g.assumptions.len(), 1);
        assert!(
            g.assumptions[0].contains("1 of 10 cells"),
            "{:?}",
            g.assumptions
        );
    }
}
