//! The sequence net: its u₀ rows are the model's net bit for bit (and not another row), the
//! loss puts the Jacobian on u₀ only and weighs the steps, training on a dataset that keeps
//! sequences gives a model whose file round-trips and refuses a sequence net whose u₀ rows
//! are not the model's net.

use super::*;
use crate::data::dataset::{generate, GenerateOptions};
use crate::learn::mlp::{Batch, Lanes, LossWeights, SeqLoss, Workspace};
use crate::problem::{Activation, Outputs};

fn net(nx: usize, nout: usize, seed: u64) -> Mlp {
    let mut m = Mlp::new(
        &[nx, 7, 5, nout],
        Activation::Tanh,
        seed,
        &vec![-2.0; nx],
        &vec![2.0; nx],
        &vec![-1.0; nout],
        &vec![1.5; nout],
    );
    // Distinct biases and output scales per row, so that a wrong row shows.
    let last = m.layers.last_mut().unwrap();
    for (r, b) in last.b.iter_mut().enumerate() {
        *b = 0.1 * r as f64 - 0.2;
    }
    for (r, h) in m.out_half.iter_mut().enumerate() {
        *h *= 1.0 + 0.05 * r as f64;
    }
    m
}

/// `first_rows` is the sequence net's first nu outputs bit for bit at 200 points, and
/// differs from its outputs nu..2nu (a restriction to another row would fail here).
#[test]
fn first_rows_are_the_u0_outputs_bit_for_bit() {
    let (nx, nu, n) = (3, 2, 4);
    let seq = net(nx, n * nu, 5);
    let first = first_rows(&seq, nu);
    assert_eq!(first.nu(), nu);
    let mut other = seq.clone();
    // The rows of step 1, as a net: what a wrong restriction would give.
    let l = other.layers.last_mut().unwrap();
    l.w.drain(..nu * l.inp);
    l.b.drain(..nu);
    l.out -= nu;
    other.out_center.drain(..nu);
    other.out_half.drain(..nu);
    let other = first_rows(&other, nu);
    let mut differs = 0;
    for i in 0..200u64 {
        let x: Vec<f64> = (0..nx)
            .map(|k| 4.0 * crate::rng::uniform(9, i, k as u64) - 2.0)
            .collect();
        let (a, b) = (seq.predict(&x), first.predict(&x));
        assert_eq!(
            a[..nu].iter().map(|v| v.to_bits()).collect::<Vec<_>>(),
            b.iter().map(|v| v.to_bits()).collect::<Vec<_>>()
        );
        differs += usize::from(other.predict(&x) != b);
    }
    assert_eq!(differs, 200);
}

/// With the steps after u₀ weighted 0, a sequence net's loss and gradient (f64 and f32
/// engines) are those of its u₀ rows on the u₀ labels: the Jacobian term reads u₀'s
/// labels only (`du` of nu rows), the other rows add nothing. With weight 1 on a later step
/// the value term grows by exactly that step's squared error.
#[test]
fn the_jacobian_term_is_on_u0_and_the_steps_are_weighted() {
    let (nx, nu, n, b) = (2, 1, 3, 24);
    let seq = net(nx, n * nu, 11);
    let first = first_rows(&seq, nu);
    let x: Vec<f64> = (0..b * nx)
        .map(|k| 3.0 * crate::rng::uniform(3, k as u64, 0) - 1.5)
        .collect();
    let u: Vec<f64> = (0..b * n * nu)
        .map(|k| crate::rng::uniform(4, k as u64, 0) - 0.5)
        .collect();
    let u0: Vec<f64> = (0..b)
        .flat_map(|i| u[i * n * nu..i * n * nu + nu].to_vec())
        .collect();
    let du: Vec<f64> = (0..b * nu * nx)
        .map(|k| crate::rng::uniform(5, k as u64, 0) - 0.5)
        .collect();
    let uj = vec![true; b];
    let lam = LossWeights {
        value: 1.0,
        jacobian: 3.0,
        weights: 0.0,
    };
    let w0 = [1.0, 0.0, 0.0];
    let s = Batch {
        x: &x,
        u: &u,
        du: &du,
        use_jac: &uj,
        band: None,
        seq: Some(SeqLoss {
            jac_rows: nu,
            weight: &w0,
        }),
    };
    let f = Batch {
        x: &x,
        u: &u0,
        du: &du,
        use_jac: &uj,
        band: None,
        seq: None,
    };
    let mut ws = Workspace::default();
    let (mut gs, mut gf) = (seq.zero_grad(), first.zero_grad());
    let ls = seq.loss_grad(&s, lam, &mut gs, &mut ws);
    let lf = first.loss_grad(&f, lam, &mut gf, &mut ws);
    assert_eq!(ls, lf);
    assert!(lf.jacobian > 0.0);
    let m = seq.layers.len() - 1;
    assert_eq!(gs.w[..m], gf.w[..m]);
    assert_eq!(gs.w[m][..nu * 5], gf.w[m][..]);
    assert!(gs.w[m][nu * 5..].iter().all(|v| *v == 0.0));
    let mut lanes = Lanes::default();
    let (mut hs, mut hf) = (seq.zero_grad(), first.zero_grad());
    let ks = lanes.loss_grad(&seq, &s, lam, Some(&mut hs));
    let kf = lanes.loss_grad(&first, &f, lam, Some(&mut hf));
    assert_eq!(ks, kf);
    assert_eq!(hs.w[..m], hf.w[..m]);
    // Step 2 weighted 1: the value term gains its squared errors exactly.
    let w2 = [1.0, 0.0, 1.0];
    let s2 = Batch {
        seq: Some(SeqLoss {
            jac_rows: nu,
            weight: &w2,
        }),
        ..s
    };
    let l2 = seq.loss(&s2, lam, &mut ws);
    let extra: f64 = (0..b)
        .map(|i| {
            let p = seq.predict(&x[i * nx..(i + 1) * nx]);
            (p[2] - u[i * n * nu + 2]).powi(2)
        })
        .sum::<f64>()
        / b as f64;
    assert!(
        (l2.value - ls.value - extra).abs() <= 1e-12 * (1.0 + extra),
        "{l2:?} {ls:?}"
    );
    assert_eq!(l2.jacobian, ls.jacobian);
}

/// End to end on the double integrator: the dataset keeps sequences, the sequence net
/// trains, the model's net is its u₀ rows, the model file round-trips with it, and a file
/// whose sequence net's u₀ rows differ from the model's net is refused by name.
#[test]
fn a_sequence_model_trains_round_trips_and_binds_its_u0_rows() {
    let path = concat!(
        env!("CARGO_MANIFEST_DIR"),
        "/../configs/double_integrator.toml"
    );
    let mut cfg = ProblemConfig::load(std::path::Path::new(path)).unwrap();
    cfg.sampling.counts = vec![9, 7];
    cfg.training.outputs = Outputs::Sequence;
    cfg.training.epochs = 60;
    let dir = std::env::temp_dir().join(format!("ampc-seqnet-{}", std::process::id()));
    let _ = std::fs::remove_dir_all(&dir);
    std::fs::create_dir_all(&dir).unwrap();
    let d = generate(&cfg, &dir.join("d.bin"), &GenerateOptions::default()).unwrap();
    // A dataset without sequences is refused, naming it.
    let mut plain_cfg = cfg.clone();
    plain_cfg.training.outputs = Outputs::First;
    let plain = generate(&plain_cfg, &dir.join("p.bin"), &GenerateOptions::default()).unwrap();
    let opts = TrainOptions {
        nominal: false,
        progress: None,
        hold: None,
        keep_best: None,
    };
    let e = train_sequence::<()>(&cfg, &opts, &plain, &plain, ("p.bin", "v"), "h", "d");
    assert!(matches!(e, Err(SequenceError::NoSequences(ref p, 2)) if p == "p.bin"));
    let m: TrainedModel<()> =
        train_sequence(&cfg, &opts, &d, &d, ("d.bin", "v"), "h", "d").unwrap();
    let seq = m.sequence.clone().unwrap();
    let n = cfg.ocp.horizon;
    assert_eq!(seq.nu(), n * cfg.system.nu());
    assert_eq!(m.mlp, first_rows(&seq, cfg.system.nu()));
    assert!(m.train_stats.max.is_finite() && m.train_stats.n == d.records.len());
    // The later steps are learned too: better than predicting zero.
    let set = sequence_set(&d, n, &cfg.training.step_weights(n), None, "d").unwrap();
    let (_, st) = errors(&seq, &set);
    let zero: f64 = (0..set.len())
        .map(|i| {
            set.u[i * set.nu..(i + 1) * set.nu]
                .iter()
                .map(|v| v * v)
                .sum::<f64>()
                .sqrt()
        })
        .fold(0.0, f64::max);
    assert!(st.max < zero, "{} vs {zero}", st.max);
    let back = TrainedModel::<()>::from_bytes(&m.to_bytes(), "m.bin").unwrap();
    assert_eq!(back.sequence, m.sequence);
    assert_eq!(back.mlp, m.mlp);
    let mut bad = m.clone();
    bad.sequence.as_mut().unwrap().layers.last_mut().unwrap().b[0] += 1e-9;
    let err = TrainedModel::<()>::from_bytes(&bad.to_bytes(), "m.bin")
        .unwrap_err()
        .to_string();
    assert!(err.contains("m.bin") && err.contains("first"), "{err}");
    let _ = std::fs::remove_dir_all(&dir);
}

/// The feedback form's targets: u₀* unchanged, c_k* = u_k* − κ_f(x_k*) along the MPC's
/// predicted trajectory (zero for the terminal controller's own rollout), and the
/// realisation v_k = κ_f(x̂_k) + c_k gives the labels back.
#[test]
fn feedback_targets_are_offsets_from_the_terminal_controller_and_realise_back() {
    let path = concat!(
        env!("CARGO_MANIFEST_DIR"),
        "/../configs/double_integrator.toml"
    );
    let mut cfg = ProblemConfig::load(std::path::Path::new(path)).unwrap();
    cfg.sampling.counts = vec![5, 4];
    cfg.training.outputs = Outputs::Sequence;
    assert!(
        Feedback::of(&cfg).unwrap().is_none(),
        "open by default in code"
    );
    cfg.training.sequence_form = crate::problem::SequenceForm::Feedback;
    let f = Feedback::of(&cfg)
        .unwrap()
        .expect("the double integrator has κ_f");
    let (n, nu) = (cfg.ocp.horizon, cfg.system.nu());
    // The terminal controller's own rollout (unsaturated, near x_ref): all offsets 0.
    let x0 = vec![0.01, -0.01];
    let (mut xk, mut next, mut roll) = (x0.clone(), vec![0.0; 2], Vec::new());
    for _ in 0..n {
        let u = f.terminal_input(&xk);
        f.model.step(&xk, &u, &mut next);
        std::mem::swap(&mut xk, &mut next);
        roll.extend(u);
    }
    let c = f.offsets(&x0, &roll, nu);
    assert_eq!(c[..nu], roll[..nu]);
    assert!(c[nu..].iter().all(|v| v.abs() < 1e-15), "{c:?}");
    // Labels of the MPC: offsets then realisation give them back.
    let dir = std::env::temp_dir().join(format!("ampc-seqfb-{}", std::process::id()));
    let _ = std::fs::remove_dir_all(&dir);
    std::fs::create_dir_all(&dir).unwrap();
    let d = generate(&cfg, &dir.join("d.bin"), &GenerateOptions::default()).unwrap();
    let w = cfg.training.step_weights(n);
    let open = sequence_set(&d, n, &w, None, "d").unwrap();
    let fb = sequence_set(&d, n, &w, Some(&f), "d").unwrap();
    let mut moved = 0;
    for (i, r) in d.records.iter().filter(|r| r.is_labelled()).enumerate() {
        let row = &fb.u[i * n * nu..(i + 1) * n * nu];
        assert_eq!(row, &f.offsets(&r.x, &r.seq, nu)[..]);
        assert_eq!(row[..nu], open.u[i * n * nu..i * n * nu + nu]);
        let back = f.realise(&r.x, row, nu);
        for (a, b) in back.iter().zip(&r.seq) {
            assert!((a - b).abs() < 1e-9, "{a} vs {b}");
        }
        moved += usize::from(row != &open.u[i * n * nu..(i + 1) * n * nu]);
    }
    assert!(moved > 0);
    let _ = std::fs::remove_dir_all(&dir);
}
