//! The report's first section: the verdict in words — what ε the exported controller has,
//! its tier (sound / statistical / estimated, as `certificate.json` states it) and what it rests
//! on, ε against the input range U, and the band the exported controller clamps to.
//!
//! ε is measured against the largest distance two inputs of U can have, d_U = ‖u_hi − u_lo‖₂:
//! since both κ and the clamped network lie in U, ‖κ − u‖ ≤ d_U holds without any
//! certificate, so ε ≥ d_U says nothing (vacuous); ε ≥ d_U / 5 is called weak.

use super::format::{boxed, num};
use super::{Artifacts, Block};
use crate::problem::ProblemConfig;

/// The band the exported controller clamps to: `export_report.json`'s `clamp_lo`/`clamp_hi`
/// (written by the export stage), else (U ⊕ ε) ∩ U = U from the certificate (the exporter's
/// actuator limits are U).
pub(super) fn exported_band(a: &Artifacts) -> (Vec<f64>, Vec<f64>) {
    let get = |k: &str| -> Option<Vec<f64>> {
        a.export[k]
            .as_array()
            .map(|v| v.iter().filter_map(serde_json::Value::as_f64).collect())
    };
    match (get("clamp_lo"), get("clamp_hi")) {
        (Some(lo), Some(hi)) if lo.len() == a.cert.u_lo.len() && hi.len() == lo.len() => (lo, hi),
        _ => {
            let lo = (a.cert.clamp_lo.iter().zip(&a.cert.u_lo))
                .map(|(c, u)| c.max(*u))
                .collect();
            let hi = (a.cert.clamp_hi.iter().zip(&a.cert.u_hi))
                .map(|(c, u)| c.min(*u))
                .collect();
            (lo, hi)
        }
    }
}

/// How ε compares with d_U (module doc): `(ratio, word)`.
pub fn judge(eps: f64, u_lo: &[f64], u_hi: &[f64]) -> (f64, &'static str) {
    let d = u_lo
        .iter()
        .zip(u_hi)
        .map(|(l, h)| (h - l) * (h - l))
        .sum::<f64>()
        .sqrt();
    let r = eps / d;
    let word = if r.is_nan() || r >= 1.0 {
        "vacuous"
    } else if r >= 0.2 {
        "weak"
    } else {
        "informative"
    };
    (r, word)
}

/// The verdict section (module doc).
pub(super) fn verdict(cfg: &ProblemConfig, a: &Artifacts) -> Vec<Block> {
    let (net, c, g) = a.exported();
    let tier = g.guarantee.name();
    let allowance = a.export["f32_allowance_libm"].as_f64().unwrap_or(f64::NAN);
    let (_, inputs) = crate::study::plots::axis_names(&cfg.system);
    let unit = inputs
        .first()
        .and_then(|s| s.split('[').nth(1))
        .map(|s| format!(" {}", s.trim_end_matches(']')))
        .unwrap_or_default();
    // A scaled norm's ε is a number without unit (its physical bounds are in the note).
    let unit = if c.norm().is_unit() {
        unit
    } else {
        String::new()
    };
    // Against U in physical units (ε itself for the unscaled norm).
    let (ratio, word) = judge(c.eps_physical(), &c.u_lo, &c.u_hi);
    let range = boxed(&c.u_lo, &c.u_hi);
    let source = a.export["source"].as_str().unwrap_or("theorem1");
    let meaning = match word {
        "vacuous" if source != "theorem1" => format!(
            "**Theorem 1's bound is vacuous**: ε is {:.0} % of the largest distance between two inputs of U = {range}; the band exported is the {source} one above",
            100.0 * ratio
        ),
        "vacuous" => format!(
            "**the bound is vacuous**: ε is {:.0} % of the largest distance between two inputs of U = {range}, which the clamp alone guarantees — this certificate says nothing useful; tighten it with `trainer refine` (local certificates) or `--statistical N`",
            100.0 * ratio
        ),
        "weak" => format!(
            "**the bound is weak**: ε is {:.0} % of the largest distance between two inputs of U = {range}; `trainer refine` (local certificates) tightens it",
            100.0 * ratio
        ),
        _ => format!(
            "ε is {:.1} % of the largest distance between two inputs of U = {range}",
            100.0 * ratio
        ),
    };
    let rests_on = if g.assumptions.is_empty() {
        "every term is proven by the code's arithmetic".to_string()
    } else {
        format!("it rests on: {}", g.assumptions.join("; "))
    };
    let (blo, bhi) = exported_band(a);
    let theorem1 = if source == "theorem1" {
        format!("Theorem 1, the exported {net} net")
    } else {
        format!("Theorem 1 of the {net} net; the band exported is the {source} one above")
    };
    let mut blocks = vec![Block::Heading(2, "Verdict".into())];
    blocks.extend(reached(a));
    blocks.extend([
        Block::Para(format!(
            "**ε = {}{unit}, {tier}** ({theorem1}): for every state in X = {}, the MPC's input and the network's differ by at most ε (on the device: ε + f32 allowance {} = {}{unit}). Tier **{tier}**: {rests_on}.",
            num(c.eps),
            boxed(&c.domain_lo, &c.domain_hi),
            num(allowance),
            num(c.eps + allowance),
        )),
        Block::Para(format!("{}Against the input range: {meaning}.", scaled_note(c))),
        Block::Para(format!(
            "Exported: {}.",
            a.export["net_reason"]
                .as_str()
                .unwrap_or("the regularized net (the run predates the choice between the nets)")
        )),
        Block::Para(format!(
            "The exported controller projects the state onto X and clamps its output to u ∈ {}.",
            boxed(&blo, &bhi)
        )),
    ]);
    blocks
}

/// The guarantee reached, why not a stronger one and the next command (`export_report.json`'s
/// `"verdict"`), and the closed loop's statistical statement; nothing for runs before them.
fn reached(a: &Artifacts) -> Vec<Block> {
    let v = &a.export["verdict"];
    let Some(reached) = v["reached"].as_str() else {
        return Vec::new();
    };
    let mut out = vec![Block::Para(format!("**Guarantee reached — {reached}.**"))];
    let why: Vec<&str> = v["why_not_stronger"]
        .as_array()
        .map(|w| w.iter().filter_map(|s| s.as_str()).collect())
        .unwrap_or_default();
    if !why.is_empty() {
        out.push(Block::Para(format!("Not stronger: {}.", why.join("; "))));
    }
    if let Some(cl) = &a.cl_stat {
        out.push(Block::Para(closed_loop_statement(cl)));
    }
    if let Some(next) = v["next"].as_str() {
        out.push(Block::Para(format!("Next: {next}.")));
    }
    out
}

/// `closed_loop_statistical.json` in words.
fn closed_loop_statement(cl: &serde_json::Value) -> String {
    if cl["ran"] == serde_json::Value::Bool(false) {
        return format!(
            "Closed loop, statistically: not run ({}).",
            cl["reason"].as_str().unwrap_or("")
        );
    }
    let b = |k: &str| {
        let x = &cl[k];
        (
            x["p_violation_upper"].as_f64().unwrap_or(f64::NAN),
            x["violating"].as_u64().unwrap_or(0),
            x["trajectories"].as_u64().unwrap_or(0),
        )
    };
    let (pf, kf, nf) = b("failing_feasible");
    let (pa, ka, na) = b("failing");
    format!(
        "Closed loop, statistically (Clopper–Pearson, confidence {}): P(a run of the exported \
         controller violates a constraint or does not converge) ≤ {pf:.3e} from i.i.d. \
         uniform MPC-feasible starts ({kf} of {nf} runs of {} steps failed), ≤ {pa:.3e} from \
         all starts ({ka} of {na}; {} did not converge).",
        cl["confidence"].as_f64().unwrap_or(f64::NAN),
        cl["steps"].as_u64().unwrap_or(0),
        cl["not_converged"].as_u64().unwrap_or(0),
    ) + &mpc_beside(cl)
        + &left_domain(cl)
        + &convergence_rule(cl)
}

/// How many failing runs left X, where the device projects the state onto X, and where the
/// runs went (empty when none did, or in files written before it was counted).
fn left_domain(cl: &serde_json::Value) -> String {
    let k = cl["failing_left_domain"].as_u64().unwrap_or(0);
    let corner = |i: usize| -> Option<String> {
        let v: Option<Vec<f64>> = cl["reach"][i]
            .as_array()?
            .iter()
            .map(|x| x.as_f64())
            .collect();
        Some(crate::study::statistical_loop::short(&v?))
    };
    let (Some(lo), Some(hi)) = (corner(0), corner(1)) else {
        return String::new();
    };
    if k == 0 {
        return String::new();
    }
    format!(
        " {k} of the failing runs evaluated the controller at states outside X, where the \
         device projects the state onto X before the network (the band holds on X only): \
         the runs reached [{lo}] … [{hi}]. A `[domain]` that covers where the closed loop goes \
         (then `trainer run` again: new data, training and bounds) tests the network there \
         instead of its projection."
    )
}

/// The convergence rule, the run length's origin and a steady offset at the setpoint
/// (empty in files written before they were stated).
fn convergence_rule(cl: &serde_json::Value) -> String {
    let mut out = String::new();
    if let Some(c) = cl["convergence"].as_str().filter(|c| !c.is_empty()) {
        out += &format!(" Convergence: {c}.");
    }
    let tol = crate::study::statistical_loop::CONVERGE_TOL;
    if let Some(o) = cl["setpoint_offset"].as_f64().filter(|o| *o > tol) {
        out += &format!(
            " The exported controller has a steady offset at the setpoint: started at x_ref it \
             ends {o:.3} away (scaled), above the tolerance {tol}, so its runs cannot converge \
             in this sense (a bias correction would be a new net, to be certified anew)."
        );
    }
    out
}

/// The MPC's own failures from the same starts, beside the controller's (empty in files
/// written before they were counted).
fn mpc_beside(cl: &serde_json::Value) -> String {
    let m = &cl["mpc_failing"];
    let (Some(k), Some(n), Some(c)) = (
        m["violating"].as_u64(),
        m["trajectories"].as_u64(),
        cl["controller_failing_same"].as_u64(),
    ) else {
        return String::new();
    };
    format!(
        " The MPC itself, run in closed loop from {n} further i.i.d. starts for the same {} \
         steps, fails on {k} of them ({:.1} %; P ≤ {:.3e}); the exported controller fails on \
         {c} of those {n}.",
        cl["steps"].as_u64().unwrap_or(0),
        100.0 * k as f64 / n.max(1) as f64,
        m["p_violation_upper"].as_f64().unwrap_or(f64::NAN),
    )
}

/// For a scaled norm: what ε measures and its bound per input in physical units (empty for
/// the unscaled norm, whose ε is the physical 2-norm).
fn scaled_note(c: &crate::certify::certificate::Certificate) -> String {
    let n = c.norm();
    if n.is_unit() {
        return String::new();
    }
    let per: Vec<String> = c.eps_per_input().iter().map(|e| num(*e)).collect();
    format!(
        "ε is stated in the scaled norm ‖S_u⁻¹Δu‖₂ (u_scale = {:?}, states as ‖S_x⁻¹Δx‖₂ with \
         x_scale = {:?}): per input in physical units |Δu_j| ≤ [{}], ‖Δu‖₂ ≤ {}. ",
        n.u_scale,
        n.x_scale,
        per.join(", "),
        num(c.eps_physical())
    )
}

#[cfg(test)]
mod tests {
    use super::judge;

    #[test]
    fn judge_compares_eps_with_the_diagonal_of_u() {
        // |u| ≤ 15: d_U = 30.
        assert_eq!(judge(31.0, &[-15.0], &[15.0]).1, "vacuous");
        assert_eq!(judge(30.0, &[-15.0], &[15.0]).1, "vacuous");
        assert_eq!(judge(6.0, &[-15.0], &[15.0]).1, "weak");
        assert_eq!(judge(0.748, &[-15.0], &[15.0]).1, "informative");
        assert!((judge(0.75, &[-15.0], &[15.0]).0 - 0.025).abs() < 1e-15);
        // Two inputs: the diagonal, not one side (5 = ‖(3, 4)‖).
        assert_eq!(judge(4.5, &[0.0, 0.0], &[3.0, 4.0]).1, "weak");
        assert_eq!(judge(5.0, &[0.0, 0.0], &[3.0, 4.0]).1, "vacuous");
        assert_eq!(judge(f64::NAN, &[-1.0], &[1.0]).1, "vacuous");
    }
}
