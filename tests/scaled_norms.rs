//! Scaled norms (issue 40 §1): a double integrator with mixed units — position in mm,
//! velocity in m/s, force in N. Unscaled, Theorem 1 adds millimetres and metres per second
//! in one covering radius and is vacuous by construction; in the default norm (the
//! half-widths of X and U) the same model and data give a per-input bound in physical units
//! that is far tighter, and still above the error observed at fresh states.

use trainer::certify::norm::Norm;
use trainer::ProblemConfig;

const TOML: &str = r#"
name = "di_mm"

[system]
kind = "discrete"
states = ["p", "v"]
inputs = ["f"]
parameters = { dt = 0.1 }
next = ["p + 1000*(dt*v + 0.5*dt^2*f)", "v + dt*f"]

[ocp]
ts = 0.1
horizon = 15
q = [1e-6, 0.1]
r = [0.1]
p = [1e-6, 0.1]
x_lo = [-5000.0, -1.0]
x_hi = [5000.0, 1.0]
u_lo = [-1.0]
u_hi = [1.0]

[domain]
lo = [-4000.0, -1.0]
hi = [4000.0, 1.0]

[sampling]
sampler = "grid"
counts = [15, 9]

[training]
hidden = [12, 12]
epochs = 300
batch_size = 16
validation_n = 40
log_every = 100
"#;

#[test]
fn mixed_units_scaled_bound_is_far_tighter_and_covers_fresh_states() {
    let dir = tempfile::tempdir().unwrap();
    let cfg = ProblemConfig::from_toml_str(TOML, "di_mm").unwrap();
    assert!(cfg.ocp.x_scale.is_none() && cfg.ocp.u_scale.is_none());
    let data = trainer::sample(&cfg, &dir.path().join("d.bin")).unwrap();
    let mut vcfg = cfg.clone();
    vcfg.sampling.sampler = trainer::problem::SamplerKind::Random;
    vcfg.sampling.n = 40;
    vcfg.sampling.seed = 3;
    let val = trainer::sample(&vcfg, &dir.path().join("v.bin")).unwrap();
    let model = trainer::train(&cfg, &data, &val, false).unwrap();

    // The default norm: the half-widths of X and U.
    let scaled = trainer::certify(&cfg, &model, &data, Some(&val))
        .unwrap()
        .base;
    let norm = scaled
        .scales
        .clone()
        .expect("the certificate states its norm");
    assert_eq!(norm, Norm::of_problem(&cfg));
    assert_eq!(norm.x_scale, vec![4000.0, 1.0]);
    assert_eq!(norm.u_scale, vec![1.0]);
    assert_eq!(scaled.epsilon_per_input, norm.per_input(scaled.eps));
    // The unscaled norm, the same model and data (the scales are not part of the problem
    // hash: the labels do not depend on them).
    let mut ucfg = cfg.clone();
    ucfg.ocp.x_scale = Some(vec![1.0, 1.0]);
    ucfg.ocp.u_scale = Some(vec![1.0]);
    assert_eq!(ucfg.problem_hash(), cfg.problem_hash());
    let unscaled = trainer::certify(&ucfg, &model, &data, Some(&val))
        .unwrap()
        .base;
    assert!(unscaled.scales.as_ref().unwrap().is_unit());
    assert_eq!(unscaled.epsilon_per_input, vec![unscaled.eps]);

    let (e_s, e_u) = (scaled.epsilon_per_input[0], unscaled.epsilon_per_input[0]);
    assert!(
        e_s * 50.0 < e_u,
        "per-input bound in N: scaled {e_s} is not far below unscaled {e_u}"
    );
    // The exported band is the per-input physical bound.
    assert!((scaled.clamp_hi[0] - (1.0 + e_s)).abs() < 1e-12 * (1.0 + e_s));

    // Fresh states (another seed, none of them a grid point): the observed error per input
    // in N stays below the scaled certificate's physical bound.
    let mut fcfg = cfg.clone();
    fcfg.sampling.sampler = trainer::problem::SamplerKind::Random;
    fcfg.sampling.n = 300;
    fcfg.sampling.seed = 11;
    let fresh = trainer::sample(&fcfg, &dir.path().join("f.bin")).unwrap();
    let mut worst = 0.0f64;
    let mut n = 0;
    for r in fresh.records.iter().filter(|r| r.is_labelled()) {
        let u = model.mlp.predict(&r.x);
        worst = worst.max((u[0] - r.u[0]).abs());
        n += 1;
    }
    assert!(n >= 250, "only {n} fresh states labelled");
    assert!(
        worst <= e_s,
        "observed error {worst} N above the scaled per-input bound {e_s} N"
    );
    eprintln!(
        "per-input ε [N]: scaled {e_s:.4}, unscaled {e_u:.4}; observed at {n} fresh states {worst:.4}"
    );
}
