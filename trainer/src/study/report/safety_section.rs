//! The report's safety section: `closed_loop.json`'s `safety` study (`study::safety`) as a
//! Table-II-style table — safe / plain / MPC: violating steps, violating runs, fallback share
//! of steps, median cost ratio against the MPC, converged runs — for the nominal model (with
//! the guarantee's exact words and what it rests on) and for each mismatch scenario (no
//! guarantee claimed) — and, for the safe controller, why its network candidate was or was
//! not applied (`study::safety_diagnosis::CandidateCounts`).

use super::{Artifacts, Block};
use crate::study::safety::{ControllerRuns, SafetyGroup, SafetyStudy};
use crate::study::safety_diagnosis::CandidateCounts;

/// The diagnosis of the candidate in words (`None` without counts).
pub(super) fn candidate_para(c: Option<&CandidateCounts>) -> Option<Block> {
    let c = c?;
    let pct = |v: u64| 100.0 * v as f64 / c.checked.max(1) as f64;
    let r = c.costlier_rel;
    Some(Block::Para(format!(
        "The network's candidate at the {} steps that had a safe sequence: applied at {} ({:.2} %). \
         Outside U before clamping at {} ({:.2} %; clamped and then applied at {}). \
         The clamped candidate violated a state or path constraint at {} ({:.2} %), missed \
         the terminal set at {} ({:.2} %), was not finite at {}, and was feasible but costlier \
         than the safe fallback at {} ({:.2} %; {} of them with the state already in the \
         terminal set) — relative excess (J(c) − J(s)) / J(s) ≤ 1e-4: {}, ≤ 1e-3: {}, \
         ≤ 1e-2: {}, ≤ 1e-1: {}, larger: {}.",
        c.checked,
        c.taken,
        pct(c.taken),
        c.outside_u,
        pct(c.outside_u),
        c.outside_u_taken,
        c.stage_violation,
        pct(c.stage_violation),
        c.terminal_miss,
        pct(c.terminal_miss),
        c.non_finite,
        c.costlier,
        pct(c.costlier),
        c.costlier_in_xf,
        r[0],
        r[1],
        r[2],
        r[3],
        r[4]
    )))
}

/// The table of one group of runs.
pub(super) fn group_table(g: &SafetyGroup) -> Block {
    let row = |name: &str, c: &ControllerRuns| {
        vec![
            name.to_string(),
            c.total_violations.to_string(),
            format!("{} / {}", c.violating_runs, c.runs.len()),
            format!("{:.2} %", 100.0 * c.fallback_share),
            c.median_cost_ratio
                .map_or("—".into(), |r| format!("{r:.4}")),
            format!("{} / {}", c.converged, c.runs.len()),
        ]
    };
    Block::Table {
        head: [
            "controller",
            "violating steps",
            "violating runs",
            "fallback (share of steps)",
            "median cost / MPC",
            "converged runs",
        ]
        .iter()
        .map(|s| s.to_string())
        .collect(),
        rows: vec![
            row("safe", &g.safe),
            row("plain", &g.plain),
            row("mpc", &g.mpc),
        ],
    }
}

/// The section (nothing when the study did not run).
pub(super) fn safety(a: &Artifacts) -> Vec<Block> {
    a.safety.as_ref().map_or(vec![], section)
}

/// The section of study `s`.
pub(super) fn section(s: &SafetyStudy) -> Vec<Block> {
    let g = &s.nominal;
    let mut out = vec![
        Block::Heading(2, "Safety-augmented controller: closed loops".into()),
        Block::Para(format!(
            "{} closed loops of {} steps per controller from i.i.d. uniform starts in X (seed \
             {}), nominal model. Guarantee of the safe controller: **{}** — resting on {}. \
             Initialisation: {}: {} runs by the MPC's sequence (the MPC's first solve a hard \
             optimum at {} starts), {} by the terminal rollout, {} by a feasible candidate, {} \
             without a safe sequence ({} steps without one in all). Violation: {}.{}",
            s.runs,
            s.steps,
            s.seed,
            s.guarantee,
            s.rests_on,
            s.initialisation,
            g.init_mpc,
            g.mpc_feasible_starts,
            g.init_terminal,
            g.init_candidate,
            g.runs_without_safe_sequence,
            g.safe.no_safe_steps,
            s.violation_rule,
            if s.choice.is_empty() {
                String::new()
            } else {
                format!(" Choice: {}.", s.choice)
            }
        )),
        group_table(g),
    ];
    out.extend(candidate_para(g.safe.candidate.as_ref()));
    for (tag, m) in &s.mismatch {
        out.push(Block::Heading(
            3,
            format!("Model mismatch {tag} (no guarantee claimed)"),
        ));
        out.push(Block::Para(format!(
            "{} loops per controller from the first starts of the same draw; the plant's \
             parameter scaled, the controllers unchanged.",
            m.safe.runs.len()
        )));
        out.push(group_table(m));
        out.extend(candidate_para(m.safe.candidate.as_ref()));
    }
    out
}
