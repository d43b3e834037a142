//! The f32 lane engine against the f64 passes (whose gradient is checked against central
//! differences in `mlp::tests`): loss terms, gradient and outputs/Jacobians agree to f32
//! accuracy on every activation, jet size (specialised and not), batch size (partial groups,
//! several flushes) and with the clamp band; results are reproducible bit for bit.

use super::super::tests::{data, net};
use super::*;
use crate::learn::mlp::Workspace;

fn close(a: f64, b: f64, scale: f64, tol: f64) -> bool {
    (a - b).abs() <= tol * (b.abs() + scale)
}

fn max_abs(v: impl Iterator<Item = f64>) -> f64 {
    v.fold(0.0, |m, x| m.max(x.abs()))
}

#[test]
fn lane_loss_and_gradient_match_the_f64_passes() {
    let lams = [
        LossWeights {
            value: 1.0,
            jacobian: 3.0,
            weights: 0.05,
        },
        LossWeights {
            value: 1.0,
            jacobian: 0.0,
            weights: 0.0,
        },
    ];
    let mut lanes = Lanes::default();
    let mut ws = Workspace::default();
    for (case, (act, widths)) in [
        (Activation::Tanh, vec![2, 10, 10, 1]),
        (Activation::Tanh, vec![3, 7, 2]),
        (Activation::Softplus, vec![2, 6, 5, 1]),
        (Activation::Relu, vec![4, 9, 3]),
        (Activation::Tanh, vec![6, 16, 16, 2]),
        (Activation::Tanh, vec![12, 8, 8, 4]),
    ]
    .into_iter()
    .enumerate()
    {
        let m = net(case as u64 + 3, act, &widths);
        let (nx, nu) = (m.nx(), m.nu());
        for bsz in [1usize, 7, 8, 9, 35, 600] {
            let (x, mut u, du, uj) = data(case as u64 * 31 + bsz as u64, nx, nu, bsz);
            for banded in [false, true] {
                let (blo, bhi) = (vec![-0.3; nu], vec![0.3; nu]);
                if banded {
                    u.iter_mut().for_each(|v| *v = v.clamp(-0.3, 0.3));
                }
                let batch = Batch {
                    x: &x,
                    u: &u,
                    du: &du,
                    use_jac: &uj,
                    band: banded.then_some((&blo[..], &bhi[..])),
                    seq: None,
                };
                for lam in lams {
                    let (mut g64, mut g32) = (m.zero_grad(), m.zero_grad());
                    let l64 = m.loss_grad(&batch, lam, &mut g64, &mut ws);
                    let l32 = lanes.loss_grad(&m, &batch, lam, Some(&mut g32));
                    let what = format!("{act:?} {widths:?} B={bsz} band={banded} {lam:?}");
                    let scale = l64.total().abs() + 1e-3;
                    for (a, b) in [
                        (l32.value, l64.value),
                        (l32.jacobian, l64.jacobian),
                        (l32.weights, l64.weights),
                    ] {
                        assert!(close(a, b, scale, 1e-4), "{what}: loss {a} vs {b}");
                    }
                    let flat = |g: &Grad| -> Vec<f64> {
                        g.w.iter().chain(&g.b).flatten().copied().collect()
                    };
                    let (f64s, f32s) = (flat(&g64), flat(&g32));
                    let gmax = max_abs(f64s.iter().copied());
                    let dmax = max_abs(f64s.iter().zip(&f32s).map(|(a, b)| a - b));
                    assert!(gmax > 0.0, "{what}: zero gradient");
                    assert!(
                        dmax <= 2e-4 * gmax,
                        "{what}: gradient off by {dmax} (max {gmax})"
                    );
                    // The loss alone (no gradient) is the same computation.
                    assert_eq!(lanes.loss_grad(&m, &batch, lam, None), l32, "{what}");
                }
            }
        }
    }
}

#[test]
fn lane_outputs_and_jacobians_match_the_f64_passes() {
    let mut lanes = Lanes::default();
    for (act, widths) in [
        (Activation::Tanh, vec![2, 10, 10, 1]),
        (Activation::Relu, vec![3, 5, 2]),
        (Activation::Tanh, vec![12, 8, 8, 4]),
    ] {
        let m = net(7, act, &widths);
        let (nx, nu) = (m.nx(), m.nu());
        let n = 37;
        let (x, ..) = data(11, nx, nu, n);
        let mut ws = Workspace::default();
        let (mut u64s, mut j64) = (vec![0.0; n * nu], vec![0.0; n * nu * nx]);
        m.eval_batch(&x, &mut u64s, Some(&mut j64), &mut ws);
        let (mut u32s, mut j32) = (vec![0.0; n * nu], vec![0.0; n * nu * nx]);
        lanes.eval_batch(&m, &x, &mut u32s, Some(&mut j32));
        let umax = max_abs(u64s.iter().copied());
        let jmax = max_abs(j64.iter().copied());
        for (a, b) in u32s.iter().zip(&u64s) {
            assert!(
                (a - b).abs() <= 1e-5 * (umax + 1.0),
                "{widths:?}: u {a} vs {b}"
            );
        }
        for (a, b) in j32.iter().zip(&j64) {
            assert!(
                (a - b).abs() <= 1e-5 * (jmax + 1.0),
                "{widths:?}: J {a} vs {b}"
            );
        }
        // Without Jacobians: the same outputs.
        let mut u_only = vec![0.0; n * nu];
        lanes.eval_batch(&m, &x, &mut u_only, None);
        assert_eq!(u_only, u32s);
    }
}

#[test]
fn lane_results_are_reproducible_bit_for_bit() {
    let m = net(5, Activation::Tanh, &[2, 10, 10, 1]);
    let other = net(6, Activation::Tanh, &[3, 4, 1]);
    let (x, u, du, uj) = data(9, 2, 1, 53);
    let batch = Batch {
        x: &x,
        u: &u,
        du: &du,
        use_jac: &uj,
        band: None,
        seq: None,
    };
    let lam = LossWeights {
        value: 1.0,
        jacobian: 3.0,
        weights: 0.05,
    };
    let run = |lanes: &mut Lanes| {
        let mut g = m.zero_grad();
        let l = lanes.loss_grad(&m, &batch, lam, Some(&mut g));
        (l, g)
    };
    let mut a = Lanes::default();
    let first = run(&mut a);
    // Reused buffers, after a net of another shape: the same bits.
    let (ox, ou, odu, ouj) = data(1, 3, 1, 20);
    let ob = Batch {
        x: &ox,
        u: &ou,
        du: &odu,
        use_jac: &ouj,
        band: None,
        seq: None,
    };
    a.loss_grad(&other, &ob, lam, Some(&mut other.zero_grad()));
    assert_eq!(run(&mut a), first);
    assert_eq!(run(&mut Lanes::default()), first);
}

/// Every x86 build the CPU can run (AVX-512, AVX2, AVX: `loss_grad` dispatches to the
/// first of them the CPU has) and the portable build of the same code give the same bits.
#[test]
fn avx2_avx_and_portable_code_give_the_same_bits() {
    let lam = LossWeights {
        value: 1.0,
        jacobian: 3.0,
        weights: 0.05,
    };
    for widths in [vec![2, 10, 10, 1], vec![5, 9, 3], vec![12, 8, 8, 4]] {
        let m = net(2, Activation::Tanh, &widths);
        let (nx, nu) = (m.nx(), m.nu());
        let (x, u, du, uj) = data(4, nx, nu, 45);
        let batch = Batch {
            x: &x,
            u: &u,
            du: &du,
            use_jac: &uj,
            band: None,
            seq: None,
        };
        let mut lanes = Lanes::default();
        let (mut ga, mut gb) = (m.zero_grad(), m.zero_grad());
        let la = lanes.loss_grad(&m, &batch, lam, Some(&mut ga));
        lanes.load(&m);
        let lb = lanes.loss_grad_impl(
            &m,
            &batch,
            lam,
            Job {
                grad: Some(&mut gb),
                ..Job::default()
            },
        );
        assert_eq!((la, &ga), (lb, &gb), "{widths:?}");
        // Each x86 build the CPU can run, called directly (the dispatch picks one).
        #[cfg(target_arch = "x86_64")]
        {
            use std::arch::is_x86_feature_detected as has;
            type Build = unsafe fn(&mut Lanes, &Mlp, &Batch<'_>, LossWeights, Job<'_>) -> LossParts;
            let builds: [(bool, Build); 3] = [
                (has!("avx"), Lanes::loss_grad_avx),
                (cpu_has_avx2(), Lanes::loss_grad_avx2),
                (cpu_has_avx512(), Lanes::loss_grad_avx512),
            ];
            for (k, &(_, build)) in builds.iter().enumerate().filter(|(_, b)| b.0) {
                let mut gc = m.zero_grad();
                lanes.load(&m);
                let job = Job {
                    grad: Some(&mut gc),
                    ..Job::default()
                };
                // SAFETY: the CPU has every feature the build enables (checked above).
                let lc = unsafe { build(&mut lanes, &m, &batch, lam, job) };
                assert_eq!((la, &ga), (lc, &gc), "{widths:?}, build {k}");
            }
        }
        let (mut ua, mut ja) = (vec![0.0; 45 * nu], vec![0.0; 45 * nu * nx]);
        let (mut ub, mut jb) = (ua.clone(), ja.clone());
        lanes.eval_batch(&m, &x, &mut ua, Some(&mut ja));
        lanes.load(&m);
        lanes.eval_batch_impl(&m, &x, &mut ub, Some(&mut jb));
        assert_eq!((&ua, &ja), (&ub, &jb), "{widths:?}");
        #[cfg(target_arch = "x86_64")]
        if cpu_has_avx2() {
            let (mut uc, mut jc) = (ua.clone(), ja.clone());
            lanes.load(&m);
            // SAFETY: AVX2 implies AVX, checked just above.
            unsafe { lanes.eval_batch_avx(&m, &x, &mut uc, Some(&mut jc)) };
            assert_eq!((ua, ja), (uc, jc), "{widths:?}");
        }
    }
}

/// `Lanes::grad` (a training step: no loss terms, the minibatch read as rows of the set)
/// gives `loss_grad`'s gradient on those rows gathered into a batch, bit for bit.
#[test]
fn grad_alone_is_the_gradient_of_loss_grad() {
    // One engine throughout: its cached weight-term factors must follow λ₃ and the shape.
    let mut lanes = Lanes::default();
    for widths in [vec![2, 10, 10, 1], vec![6, 16, 16, 2], vec![12, 8, 8, 4]] {
        let m = net(5, Activation::Tanh, &widths);
        let (nx, nu) = (m.nx(), m.nu());
        for (bsz, l3) in [(1, 0.05), (35, 0.05), (35, 0.2), (600, 0.0), (600, 0.05)] {
            let lam = LossWeights {
                value: 1.0,
                jacobian: 3.0,
                weights: l3,
            };
            // A set of 2·bsz + 3 samples; the minibatch: bsz rows in a scrambled order.
            let n = 2 * bsz + 3;
            let (x, u, du, uj) = data(9, nx, nu, n);
            let rows: Vec<usize> = (0..bsz).map(|i| (i * 7 + 5) % n).collect();
            let gather = |v: &[f64], w: usize| -> Vec<f64> {
                rows.iter()
                    .flat_map(|&r| v[r * w..(r + 1) * w].to_vec())
                    .collect()
            };
            let (bx, bu, bdu) = (gather(&x, nx), gather(&u, nu), gather(&du, nu * nx));
            let bj: Vec<bool> = rows.iter().map(|&r| uj[r]).collect();
            let batch = Batch {
                x: &bx,
                u: &bu,
                du: &bdu,
                use_jac: &bj,
                band: None,
                seq: None,
            };
            let set = Batch {
                x: &x,
                u: &u,
                du: &du,
                use_jac: &uj,
                band: None,
                seq: None,
            };
            let (mut ga, mut gb) = (m.zero_grad(), m.zero_grad());
            lanes.loss_grad(&m, &batch, lam, Some(&mut ga));
            lanes.grad(&m, &set, &rows, lam, &mut gb);
            assert_eq!(ga, gb, "{widths:?}, batch {bsz}, λ₃ = {l3}");
        }
    }
}

/// `Lanes::loss_outputs` gives `loss_grad`'s loss and `eval_batch`'s outputs bit for bit,
/// with the tangent pass (λ₂ ≠ 0) and without it.
#[test]
fn loss_outputs_are_the_loss_and_the_outputs_of_eval_batch() {
    let mut lanes = Lanes::default();
    for widths in [vec![2, 10, 10, 1], vec![6, 16, 16, 2]] {
        let m = net(3, Activation::Tanh, &widths);
        let (nx, nu) = (m.nx(), m.nu());
        let (x, u, du, uj) = data(4, nx, nu, 83);
        let batch = Batch {
            x: &x,
            u: &u,
            du: &du,
            use_jac: &uj,
            band: None,
            seq: None,
        };
        for jacobian in [3.0, 0.0] {
            let lam = LossWeights {
                value: 1.0,
                jacobian,
                weights: 0.05,
            };
            let (mut ua, mut ub) = (vec![0.0; 83 * nu], vec![f64::NAN; 83 * nu]);
            lanes.eval_batch(&m, &x, &mut ua, None);
            let la = lanes.loss_grad(&m, &batch, lam, None);
            let lb = lanes.loss_outputs(&m, &batch, lam, &mut ub);
            assert_eq!(la, lb, "{widths:?}, λ₂ = {jacobian}");
            let bits = |v: &[f64]| v.iter().map(|x| x.to_bits()).collect::<Vec<_>>();
            assert_eq!(bits(&ua), bits(&ub), "{widths:?}, λ₂ = {jacobian}");
        }
    }
}
