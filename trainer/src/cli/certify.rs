//! `trainer certify`: certifies a trained model (`--model`) on the dataset it was trained
//! on (`--data`) for the problem file (`--config`): ε = ε_D + (L_MPC + L_NN)·r with every
//! term, and optionally the data density a target ε needs. Prints text or JSON to stdout;
//! writes no file.

use super::common::problem_for_data;
use anyhow::{bail, Context, Result};
use std::path::Path;
use trainer::certify::certificate::{certify, requirement, Certificate, CertifyOptions};
use trainer::data::dataset::Dataset;

pub(super) fn execute(
    config: Option<&Path>,
    model: &Path,
    data: &Path,
    target: Option<f64>,
    l_mpc: Option<f64>,
    json: bool,
) -> Result<()> {
    let m = super::common::load_model(model)?;
    let d = Dataset::load(data)?;
    let cfg = problem_for_data(config, data, &d)?;
    if let Some(v) = l_mpc {
        if !(v.is_finite() && v >= 0.0) {
            bail!("--l-mpc must be a finite number ≥ 0, got {v}");
        }
    }
    if let Some(e) = target {
        if !(e.is_finite() && e > 0.0) {
            bail!("--target-eps must be a finite number > 0, got {e}");
        }
    }
    let c = certify(
        &m,
        &d,
        &cfg,
        &CertifyOptions {
            l_mpc,
            ..Default::default()
        },
    )
    .with_context(|| format!("cannot certify {} on {}", model.display(), data.display()))?;
    let req =
        target.map(|e| requirement(e, c.eps_d, c.l_mpc, c.l_nn, &cfg.domain.lo, &cfg.domain.hi));
    if json {
        let mut v = serde_json::to_value(&c)?;
        if let (Some(r), Some(o)) = (req, v.as_object_mut()) {
            o.insert("requirement".into(), serde_json::to_value(r)?);
        }
        println!("{}", serde_json::to_string_pretty(&v)?);
        return Ok(());
    }
    println!(
        "certificate of {} on {} ({} labelled points)",
        model.display(),
        data.display(),
        c.n_points
    );
    print_terms(&c);
    if let Some(r) = req {
        match (r.delta, r.spacing, r.solves) {
            (Some(dl), Some(h), Some(n)) => println!(
                "  target eps {}: covering radius δ ≤ {:.6}, e.g. a grid with spacing {:.6} per axis: {:.0} OCP solves",
                r.target_eps, dl, h, n
            ),
            _ => println!("  target eps {} ≤ eps_D {:.6}: no data density can certify it with this network", r.target_eps, c.eps_d),
        }
    }
    Ok(())
}

/// The certificate's terms as text: ε_D, L_NN (with every bound), L_MPC, r and ε.
fn print_terms(c: &Certificate) {
    println!(
        "  eps_D            {:.6}   (max ‖κ − κ_NN‖ over the data)",
        c.eps_d
    );
    println!(
        "  L_NN             {:.4}   ({:?}, sound)",
        c.l_nn, c.l_nn_method
    );
    println!("    naive          {:.4}", c.l_nn_naive);
    println!("    LipSDP-Neuron  {:.4}", c.l_nn_lipsdp);
    if let Some(v) = c.l_nn_vertex {
        println!("    slope vertices {v:.4}");
    }
    println!("    sampled lower  {:.4}", c.l_nn_lower);
    println!("  L_MPC            {:.4}   ({})", c.l_mpc, c.l_mpc_method);
    println!(
        "  covering radius  {:.6}   ({})",
        c.covering_radius, c.covering_method
    );
    println!(
        "  eps              {:.6}   = eps_D + (L_MPC + L_NN)·r{}",
        c.eps,
        if c.l_mpc_is_estimate {
            "  [L_MPC is an estimate]"
        } else {
            ""
        }
    );
}
