//! Local cells in the scaled norm (issue 40 §1): two decoupled integrators in mixed units —
//! a in mm driven by f in mm/s (|f| ≤ 1000), b in m driven by g in m/s (|g| ≤ 1), the same
//! problem in two units. The same net is certified cell by cell (`refine`, certify-only)
//! in the unscaled norm and in the default one (the half-widths of X and U):
//! - unscaled, ε = ‖(e_f, e_g)‖₂ adds mm/s and m/s, so the bound it gives on g is the error
//!   on f in mm/s — beyond g's whole range (meaningless);
//! - scaled, ε = ‖(e_f/1000, e_g/1)‖₂ and the per-input bounds s_u,j·ε stay within each
//!   input's range, the bound on g within 2× of g's sampled error (one norm for both
//!   inputs: f's scaled bound, s_u,f·ε, is then looser than its unscaled one, since ε is
//!   set by g's error);
//! - a second method: at fresh states the sampled error of each input never exceeds its
//!   per-input bound (in either norm), nor the scaled error the scaled ε.

use trainer::certify::norm::Norm;
use trainer::certify::refine::{certificate, refine, RefineOptions};
use trainer::ProblemConfig;

const TOML: &str = r#"
name = "two_units"

[system]
kind = "discrete"
states = ["a", "b"]
inputs = ["f", "g"]
parameters = { dt = 0.1 }
next = ["a + dt*f", "b + dt*g"]

[ocp]
ts = 0.1
horizon = 10
q = [1e-6, 1.0]
r = [1e-7, 0.1]
p = [1e-6, 1.0]
x_lo = [-2000.0, -2.0]
x_hi = [2000.0, 2.0]
u_lo = [-1000.0, -1.0]
u_hi = [1000.0, 1.0]

[domain]
lo = [-1000.0, -1.0]
hi = [1000.0, 1.0]

[sampling]
sampler = "grid"
counts = [9, 9]

[training]
hidden = [12, 12]
epochs = 200
batch_size = 16
validation_n = 30
log_every = 100
"#;

/// The local certificate of `model` under `cfg` (certify-only: the net is fixed).
fn local(
    cfg: &ProblemConfig,
    model: &trainer::certify::Model,
) -> trainer::certify::certificate::Certificate {
    let mut rs = cfg.refine.clone();
    rs.initial = vec![5, 5];
    rs.budget = 400;
    rs.max_rounds = 3;
    rs.target_eps = 1e-9;
    let r = refine(
        cfg,
        &rs,
        None,
        &RefineOptions {
            fixed: Some(model.clone()),
            ..Default::default()
        },
    )
    .unwrap();
    assert!(r.state.bounds.iter().all(|(_, b)| b.eps.is_finite()));
    certificate(cfg, &rs, &r).base
}

#[test]
fn local_cells_in_the_scaled_norm_are_tight_per_input_and_cover_fresh_states() {
    let dir = tempfile::tempdir().unwrap();
    let cfg = ProblemConfig::from_toml_str(TOML, "two_units").unwrap();
    let data = trainer::sample(&cfg, &dir.path().join("d.bin")).unwrap();
    let mut vcfg = cfg.clone();
    vcfg.sampling.sampler = trainer::problem::SamplerKind::Random;
    vcfg.sampling.n = 30;
    vcfg.sampling.seed = 3;
    let val = trainer::sample(&vcfg, &dir.path().join("v.bin")).unwrap();
    let model = trainer::train(&cfg, &data, &val, false).unwrap();

    let scaled = local(&cfg, &model);
    let norm = scaled
        .scales
        .clone()
        .expect("the certificate states its norm");
    assert_eq!(norm, Norm::of_problem(&cfg));
    assert_eq!(norm.u_scale, vec![1000.0, 1.0]);
    assert_eq!(scaled.epsilon_per_input, norm.per_input(scaled.eps));
    let mut ucfg = cfg.clone();
    ucfg.ocp.x_scale = Some(vec![1.0, 1.0]);
    ucfg.ocp.u_scale = Some(vec![1.0, 1.0]);
    let unscaled = local(&ucfg, &model);
    assert!(unscaled.scales.as_ref().unwrap().is_unit());
    assert_eq!(unscaled.epsilon_per_input, vec![unscaled.eps; 2]);

    // g's range is 2 m/s: the unscaled bound on it is meaningless, the scaled one tight.
    let (gs, gu) = (scaled.epsilon_per_input[1], unscaled.epsilon_per_input[1]);
    let (fs, fu) = (scaled.epsilon_per_input[0], unscaled.epsilon_per_input[0]);
    eprintln!(
        "local ε: scaled {:.5} → f {fs:.3} mm/s, g {gs:.5} m/s; unscaled {:.3} → f {fu:.3}, g {gu:.3}",
        scaled.eps, unscaled.eps
    );
    assert!(
        gu >= 2.0,
        "unscaled bound on g {gu} m/s is not beyond g's range"
    );
    assert!(
        gs * 50.0 < gu,
        "scaled bound on g {gs} not far below unscaled {gu}"
    );
    assert!(
        gs < 2.0,
        "scaled bound on g {gs} m/s is not below g's range (2)"
    );
    assert!(
        fs < 2000.0,
        "scaled bound on f {fs} mm/s is not below f's range (2000)"
    );

    // Second method: fresh states (another seed), the MPC's label against the clamped net.
    let mut fcfg = cfg.clone();
    fcfg.sampling.sampler = trainer::problem::SamplerKind::Random;
    fcfg.sampling.n = 400;
    fcfg.sampling.seed = 17;
    let fresh = trainer::sample(&fcfg, &dir.path().join("f.bin")).unwrap();
    let (mut worst, mut worst_scaled, mut n) = ([0.0f64; 2], 0.0f64, 0);
    for r in fresh.records.iter().filter(|r| r.is_labelled()) {
        let u = model.mlp.predict(&r.x);
        let e: Vec<f64> = (0..2)
            .map(|j| (r.u[j] - u[j].clamp(scaled.clamp_lo[j], scaled.clamp_hi[j])).abs())
            .collect();
        for j in 0..2 {
            worst[j] = worst[j].max(e[j]);
        }
        worst_scaled = worst_scaled.max(norm.input_norm(&e));
        n += 1;
    }
    assert!(n >= 380, "only {n} fresh states labelled");
    eprintln!(
        "sampled at {n} fresh states: f {:.3}, g {:.5}, scaled {worst_scaled:.5}",
        worst[0], worst[1]
    );
    // Tight per input where it matters: the scaled bound on g is within 2× of g's sampled
    // error (the net fits g poorly: its training loss is in physical units, where g's
    // errors weigh 10⁻⁶ of f's), the unscaled one over 100× above it.
    assert!(
        gs <= 2.0 * worst[1],
        "g: bound {gs} vs sampled {}",
        worst[1]
    );
    assert!(
        gu >= 100.0 * worst[1],
        "g: unscaled {gu} vs sampled {}",
        worst[1]
    );
    for (j, w) in worst.iter().enumerate() {
        assert!(
            *w <= scaled.epsilon_per_input[j],
            "input {j}: sampled {w} above {}",
            scaled.epsilon_per_input[j]
        );
        assert!(*w <= unscaled.epsilon_per_input[j]);
    }
    assert!(
        worst_scaled <= scaled.eps,
        "sampled scaled error {worst_scaled} above ε {}",
        scaled.eps
    );
    // The bound is no free pass: the sampled error is a sizeable part of it.
    assert!(
        worst_scaled * 20.0 >= scaled.eps,
        "ε {} far above the sampled {worst_scaled}",
        scaled.eps
    );
}
