//! The run report (`report.md`): problem, dataset, Table I and Table II side by side with
//! the paper's figures, every term of the certificate, closed-loop distributions, stage
//! timings and the command that reproduces the run.

use crate::certificate::Certificate;
use crate::closed_loop::Run;
use crate::config::ProblemConfig;
use crate::dataset::Dataset;
use crate::pipeline::ClosedLoop;
use crate::train::TrainedModel;
use std::fmt::Write as _;
use std::path::Path;

/// Median, minimum and maximum.
pub fn med_min_max(v: &[f64]) -> (f64, f64, f64) {
    let mut s: Vec<f64> = v.iter().copied().filter(|x| !x.is_nan()).collect();
    if s.is_empty() {
        return (f64::NAN, f64::NAN, f64::NAN);
    }
    s.sort_by(f64::total_cmp);
    let n = s.len();
    let med = if n % 2 == 1 {
        s[n / 2]
    } else {
        0.5 * (s[n / 2 - 1] + s[n / 2])
    };
    (med, s[0], s[n - 1])
}

fn mmm(v: &[f64]) -> String {
    let (a, b, c) = med_min_max(v);
    format!("{a:.3} [{b:.3}, {c:.3}]")
}

fn load<T: serde::de::DeserializeOwned>(p: &Path) -> Result<T, String> {
    let t = std::fs::read_to_string(p).map_err(|e| format!("{}: {e}", p.display()))?;
    serde_json::from_str(&t).map_err(|e| format!("{}: {e}", p.display()))
}

/// Renders the report of the run in `dir`.
pub fn markdown(
    cfg: &ProblemConfig,
    dir: &Path,
    timings: &[(String, f64)],
) -> Result<String, String> {
    let data = Dataset::load(&dir.join("dataset.bin")).map_err(|e| e.to_string())?;
    let nom = TrainedModel::load(&dir.join("model_nominal.bin")).map_err(|e| e.to_string())?;
    let reg = TrainedModel::load(&dir.join("model_regularized.bin")).map_err(|e| e.to_string())?;
    let cert: Certificate = load(&dir.join("certificate.json"))?;
    let cert_n: Certificate = load(&dir.join("certificate_nominal.json"))?;
    let cl: ClosedLoop = load(&dir.join("closed_loop.json"))?;
    let c = data.counts();
    let mut s = String::new();
    let _ = writeln!(s, "# ampc run: {}\n", cfg.name);
    let _ = writeln!(
        s,
        "System `{}`, Ts = {} s, N = {}, RK4 sub-steps {}; X = {:?} × {:?}; U = [{:?}, {:?}].\n",
        cfg.system.name(),
        cfg.ocp.ts,
        cfg.ocp.horizon,
        cfg.ocp.rk4_substeps,
        cfg.domain.lo,
        cfg.domain.hi,
        cfg.ocp.u_lo,
        cfg.ocp.u_hi
    );
    let _ = writeln!(s, "## Dataset\n");
    let _ = writeln!(
        s,
        "{} states ({:?} sampler): {} converged, {} soft (hard OCP infeasible, exact-penalty label), {} infeasible, {} failed; {} labelled points have a degenerate sensitivity (Jacobian term dropped).\n",
        c.total, data.header.sampling.sampler, c.converged, c.soft, c.infeasible, c.failed, c.degenerate
    );
    let _ = writeln!(s, "## Table I: networks after training\n");
    let _ = writeln!(s, "| net | validation R² | ε_D | L_NN (sound, method) | LipSDP-Neuron | naive | sampled lower | median error | paper R² / ε_D / L |");
    let _ = writeln!(s, "|---|---|---|---|---|---|---|---|---|");
    for (name, m, ce, paper) in [
        ("nominal", &nom, &cert_n, "0.985 / 3.231 / 384.01"),
        ("regularized", &reg, &cert, "0.992 / 1.823 / 207.66"),
    ] {
        let _ = writeln!(
            s,
            "| {name} | {:.4} | {:.3} | {:.2} ({:?}) | {:.2} | {:.2} | {:.2} | {:.3} | {paper} |",
            m.validation_stats.r2,
            ce.eps_d,
            ce.l_nn,
            ce.l_nn_method,
            ce.l_nn_lipsdp,
            ce.l_nn_naive,
            ce.l_nn_lower,
            m.train_stats.median
        );
    }
    let _ = writeln!(s, "\nOne training seed ({}); `trainer compare --data dataset.bin --seeds 10` gives median [min, max] over seeds.\n", cfg.training.seed);
    let _ = writeln!(s, "## Certificate (regularized net, Theorem 1)\n");
    let _ = writeln!(s, "| term | value | how |\n|---|---|---|");
    let _ = writeln!(
        s,
        "| ε_D | {:.6} | max ‖κ − κ_NN‖ over {} labelled points |",
        cert.eps_d, cert.n_points
    );
    let _ = writeln!(
        s,
        "| L_NN | {:.4} | {:?} (sound upper bound) |",
        cert.l_nn, cert.l_nn_method
    );
    let _ = writeln!(s, "| L_MPC | {:.4} | {} |", cert.l_mpc, cert.l_mpc_method);
    let _ = writeln!(
        s,
        "| r | {:.6} | {} |",
        cert.covering_radius, cert.covering_method
    );
    let _ = writeln!(
        s,
        "| **ε** | **{:.4}** | ε_D + (L_MPC + L_NN)·r{} |\n",
        cert.eps,
        if cert.l_mpc_is_estimate {
            "; L_MPC is an estimate, so ε is too"
        } else {
            ""
        }
    );
    let _ = writeln!(s, "## Table II: closed loop\n");
    let first = |k: &str| cl.get(k).and_then(|v| v.first());
    let _ = writeln!(
        s,
        "From x₀ = {:?} ({} steps):\n",
        first("mpc").map(|r| r.x0.clone()).unwrap_or_default(),
        first("mpc").map_or(0, |r| r.steps)
    );
    let _ = writeln!(s, "| controller | violating steps % | max violation | max input divergence | cost | settling step | left certified band | paper % / max / divergence |\n|---|---|---|---|---|---|---|---|");
    for (k, paper) in [
        ("mpc", "—"),
        ("nominal", "46.534 / 1.113 / 2.975"),
        ("regularized", "39.604 / 1.032 / 0.649"),
    ] {
        if let Some(r) = first(k) {
            let _ = writeln!(
                s,
                "| {k} | {:.3} | {:.4} | {:.4} | {:.1} | {} | {} | {paper} |",
                r.violation_percent,
                r.max_violation,
                r.max_input_divergence,
                r.cost,
                r.settling_step.map_or("never".into(), |v| v.to_string()),
                r.left_band
            );
        }
    }
    let _ = writeln!(
        s,
        "\nOver all initial states and robustness runs, median [min, max]:\n"
    );
    let _ = writeln!(s, "| runs | n | violating steps % | max violation | max input divergence | cost |\n|---|---|---|---|---|---|");
    for (k, runs) in &cl {
        let col = |f: fn(&Run) -> f64| mmm(&runs.iter().map(f).collect::<Vec<_>>());
        let _ = writeln!(
            s,
            "| {k} | {} | {} | {} | {} | {} |",
            runs.len(),
            col(|r| r.violation_percent),
            col(|r| r.max_violation),
            col(|r| r.max_input_divergence),
            col(|r| r.cost)
        );
    }
    let _ = writeln!(s, "\n## Stage timings\n\n| stage | seconds |\n|---|---|");
    for (st, t) in timings {
        let _ = writeln!(s, "| {st} | {t:.3} |");
    }
    let _ = writeln!(
        s,
        "\n## Reproduce\n\n```sh\ncargo run --release -p trainer -- run {} --out {}\n```",
        dir.join("problem.toml").display(),
        dir.parent().map_or(".".into(), |p| p.display().to_string())
    );
    Ok(s)
}
