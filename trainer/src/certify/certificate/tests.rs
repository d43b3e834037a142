//! Tests of Theorem 1 and the covering radius (module `certificate`).
use super::*;

#[test]
fn scattered_bound_agrees_with_the_exact_grid_radius() {
    let (lo, hi, counts) = ([-1.0, 0.0], [2.0, 1.0], [7usize, 4usize]);
    let mut pts = Vec::new();
    for i in 0..counts[0] {
        for j in 0..counts[1] {
            pts.push(lo[0] + (hi[0] - lo[0]) * i as f64 / 6.0);
            pts.push(lo[1] + (hi[1] - lo[1]) * j as f64 / 3.0);
        }
    }
    let exact = grid_covering_radius(&lo, &hi, &counts);
    let (ub, lb) = scattered_covering_radius(&pts, &lo, &hi, 1e-6);
    assert!(
        ub >= exact - 1e-12 && lb <= exact + 1e-12,
        "{lb} {exact} {ub}"
    );
    assert!(ub - exact < 2e-6, "{ub} vs {exact}");
    assert!((exact - 0.5 * ((0.5f64).powi(2) + (1.0f64 / 3.0).powi(2)).sqrt()).abs() < 1e-15);
}

#[test]
fn scattered_bound_is_above_sampled_distances() {
    let lo = [0.0, 0.0, 0.0];
    let hi = [1.0, 2.0, 1.0];
    let pts: Vec<f64> = (0..40 * 3)
        .map(|k| crate::rng::uniform(9, k as u64, 0) * if k % 3 == 1 { 2.0 } else { 1.0 })
        .collect();
    let (ub, lb) = scattered_covering_radius(&pts, &lo, &hi, 1e-3);
    assert!(ub >= lb && ub - lb <= 1e-3 + 1e-12);
    for s in 0..20000u64 {
        let x: Vec<f64> = (0..3usize)
            .map(|k| crate::rng::uniform(10, s, k as u64) * (hi[k] - lo[k]))
            .collect();
        let d = (0..40)
            .map(|i| {
                (0..3)
                    .map(|k| (x[k] - pts[i * 3 + k]).powi(2))
                    .sum::<f64>()
                    .sqrt()
            })
            .fold(f64::INFINITY, f64::min);
        assert!(d <= ub + 1e-12, "sampled {d} > bound {ub}");
    }
}

#[test]
fn requirement_inverts_theorem_1() {
    let (lo, hi) = ([-1.0, -1.0], [1.0, 1.0]);
    let r = requirement(1.0, 0.2, 3.0, 5.0, &lo, &hi);
    let delta = r.delta.unwrap();
    assert!((0.2 + 8.0 * delta - 1.0).abs() < 1e-12);
    let c = ((2.0 / r.spacing.unwrap()).ceil() + 1.0) as usize;
    assert!(grid_covering_radius(&lo, &hi, &[c, c]) <= delta + 1e-12);
    assert!(requirement(0.1, 0.2, 3.0, 5.0, &lo, &hi).delta.is_none());
}

/// Two small problems with equal dimensions (the pendulum near upright and the double
/// integrator), their datasets (written by `generate`, headers included) and a briefly
/// trained net of each.
pub(crate) fn two_problems(
    dir: &std::path::Path,
) -> [(
    crate::problem::ProblemConfig,
    crate::data::dataset::Dataset,
    crate::certify::Model,
); 2] {
    use crate::data::dataset::{generate, GenerateOptions};
    use crate::learn::train::{train, TrainOptions, TrainSet};
    use crate::problem::ProblemConfig;
    let mut pend = ProblemConfig::default();
    pend.domain.lo = vec![-0.5, -0.5];
    pend.domain.hi = vec![0.5, 0.5];
    let path = concat!(
        env!("CARGO_MANIFEST_DIR"),
        "/../configs/double_integrator.toml"
    );
    let di = ProblemConfig::load(std::path::Path::new(path)).unwrap();
    [pend, di].map(|mut cfg| {
        cfg.sampling.counts = vec![4, 3];
        cfg.training.epochs = 3;
        cfg.training.hidden = vec![4];
        // The header stores the problem file: the serialised config stands for it.
        let file = dir.join(format!("{}.bin", cfg.name));
        let opts = GenerateOptions {
            shard: None,
            progress: false,
        };
        let data = generate(&cfg, &file, &opts).unwrap();
        let set = TrainSet::from_dataset(&data);
        let model = train(
            &cfg.training,
            &TrainOptions {
                nominal: false,
                progress: None,
                hold: None,
                keep_best: None,
            },
            &set,
            &set,
            (&cfg.domain.lo, &cfg.domain.hi),
            (&cfg.ocp.u_lo, &cfg.ocp.u_hi),
            &data.header.problem_hash,
            "d",
        );
        (cfg, data, model)
    })
}

/// The inputs of a certificate must belong together: a pendulum net on double-integrator
/// data, data certified for another problem or another domain X are refused (they used
/// to be certified with exit 0).
#[test]
fn mismatched_inputs_are_refused_and_certificates_bind_their_inputs() {
    let dir = std::env::temp_dir().join(format!("ampc_mismatch_{}", std::process::id()));
    std::fs::create_dir_all(&dir).unwrap();
    let [(pcfg, pdata, pmodel), (dcfg, ddata, dmodel)] = two_problems(&dir);
    let o = CertifyOptions::default();
    let c = certify(&dmodel, &ddata, &dcfg, &o).unwrap();
    assert_eq!(c.problem_hash, dcfg.problem_hash());
    let file = std::fs::read(dir.join(format!("{}.bin", dcfg.name))).unwrap();
    assert_eq!(c.dataset_hash, crate::io::sha256_hex(&file));
    assert_eq!(c.hash, dmodel.content_hash());
    assert!(certify(&pmodel, &pdata, &pcfg, &o).is_ok());
    assert!(matches!(
        certify(&pmodel, &ddata, &dcfg, &o),
        Err(MismatchError::ModelProblem { .. })
    ));
    let e = certify(&dmodel, &ddata, &pcfg, &o).unwrap_err();
    assert!(matches!(e, MismatchError::DataProblem { .. }), "{e}");
    assert!(e.to_string().contains(&dcfg.name), "{e}");
    let mut wide = dcfg.clone();
    wide.domain.hi[1] *= 10.0;
    assert!(matches!(
        certify(&dmodel, &ddata, &wide, &o),
        Err(MismatchError::Coverage { .. })
    ));
    let _ = std::fs::remove_dir_all(&dir);
}

/// Theorem 1 with every scale 1 is today's unscaled computation, bit for bit: each term
/// recomputed here from the unscaled net, data and box; the certificate states the unit norm
/// and ε per input = ε. The scales are not part of the problem hash (the dataset labelled
/// without them is accepted). In the default norm (half-widths) the terms are those of the
/// scaled problem: ε_D the largest ‖S_u⁻¹e‖₂, r the grid radius of S_x⁻¹X, the band the
/// per-input physical bound.
#[test]
fn unit_scales_give_the_unscaled_theorem_1_and_default_scales_the_scaled_one() {
    use crate::certify::lipschitz;
    use crate::learn::train::{errors, TrainSet};
    let dir = std::env::temp_dir().join(format!("ampc_unit_norm_{}", std::process::id()));
    std::fs::create_dir_all(&dir).unwrap();
    let [_, (dcfg, ddata, dmodel)] = two_problems(&dir);
    let mut unit = dcfg.clone();
    unit.ocp.x_scale = Some(vec![1.0, 1.0]);
    unit.ocp.u_scale = Some(vec![1.0]);
    let o = CertifyOptions::default();
    let c = certify(&dmodel, &ddata, &unit, &o).unwrap();
    let set = TrainSet::from_dataset(&ddata);
    let (lo, hi) = (&dcfg.domain.lo, &dcfg.domain.hi);
    let eps_d = errors(&dmodel.mlp, &set).1.max;
    let (s, q) = lipschitz::mpc_estimates(&set.x, &set.u, &set.du, &set.use_jac, 2, 1);
    let l_nn = lipschitz::naive_bound(&dmodel.mlp)
        .min(lipschitz::lipsdp_bound(&dmodel.mlp))
        .min(lipschitz::vertex_bound(&dmodel.mlp, 22).unwrap());
    let r = grid_covering_radius(lo, hi, &ddata.header.sampling.counts);
    assert_eq!(c.eps_d.to_bits(), eps_d.to_bits());
    assert_eq!(c.l_mpc.to_bits(), s.max(q).to_bits());
    assert_eq!(c.l_nn.to_bits(), l_nn.to_bits());
    assert_eq!(c.covering_radius.to_bits(), r.to_bits());
    let eps = eps_d + (s.max(q) + l_nn) * r;
    assert_eq!(c.eps.to_bits(), eps.to_bits());
    assert_eq!(c.epsilon_per_input, vec![eps]);
    assert!(c.scales.as_ref().unwrap().is_unit());
    assert_eq!(c.clamp_lo, vec![dcfg.ocp.u_lo[0] - eps]);

    // The double integrator's default norm: X = [−4, 4] × [−1, 1], U = [−1, 1].
    let d = certify(&dmodel, &ddata, &dcfg, &o).unwrap();
    let n = d.scales.clone().unwrap();
    assert_eq!(
        (n.x_scale.clone(), n.u_scale.clone()),
        (vec![4.0, 1.0], vec![1.0])
    );
    let slo: Vec<f64> = lo.iter().zip(&n.x_scale).map(|(a, s)| a / s).collect();
    let shi: Vec<f64> = hi.iter().zip(&n.x_scale).map(|(a, s)| a / s).collect();
    let rs = grid_covering_radius(&slo, &shi, &ddata.header.sampling.counts);
    assert_eq!(d.covering_radius.to_bits(), rs.to_bits());
    assert!(
        rs < r,
        "the scaled radius {rs} is that of the scaled box, not {r}"
    );
    let worst = (0..set.len())
        .map(|i| {
            let u = dmodel.mlp.predict(&set.x[2 * i..2 * i + 2]);
            ((u[0] - set.u[i]) / n.u_scale[0]).abs()
        })
        .fold(0.0, f64::max);
    assert!((d.eps_d - worst).abs() <= 1e-12 * worst.max(1e-300));
    assert_eq!(d.epsilon_per_input, n.per_input(d.eps));
    assert_eq!(d.problem_hash, c.problem_hash);
    let _ = std::fs::remove_dir_all(&dir);
}
