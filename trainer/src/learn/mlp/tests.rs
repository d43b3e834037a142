//! The passes of [`Mlp`]: the hand-derived gradient and the tangent-pass Jacobian against
//! central differences, the batched kernels against the original per-sample kernels bit
//! for bit, the physical-unit layers against the scaled network.

use super::*;
use proptest::prelude::*;

pub(super) fn net(seed: u64, act: Activation, widths: &[usize]) -> Mlp {
    let nx = widths[0];
    let nu = *widths.last().unwrap();
    let lo: Vec<f64> = (0..nx).map(|i| -1.0 - i as f64).collect();
    let hi: Vec<f64> = (0..nx).map(|i| 2.0 + 0.5 * i as f64).collect();
    let mut m = Mlp::new(widths, act, seed, &lo, &hi, &vec![-3.0; nu], &vec![5.0; nu]);
    for (j, l) in m.layers.iter_mut().enumerate() {
        for (k, b) in l.b.iter_mut().enumerate() {
            *b = 0.3 * (2.0 * crate::rng::uniform(seed + 99, j as u64, k as u64) - 1.0);
        }
    }
    m
}

pub(super) fn data(
    seed: u64,
    nx: usize,
    nu: usize,
    b: usize,
) -> (Vec<f64>, Vec<f64>, Vec<f64>, Vec<bool>) {
    let r = |a: u64, k: usize| 4.0 * crate::rng::uniform(seed, a, k as u64) - 2.0;
    let x = (0..b * nx).map(|k| r(1, k)).collect();
    let u = (0..b * nu).map(|k| r(2, k)).collect();
    let du = (0..b * nu * nx).map(|k| 3.0 * r(3, k)).collect();
    let use_jac = (0..b).map(|i| i % 3 != 1).collect();
    (x, u, du, use_jac)
}

/// Central differences of the loss against the hand-derived gradient, term by term.
fn check_grad(act: Activation, widths: &[usize], seed: u64) {
    check_grad_band(act, widths, seed, false);
    check_grad_band(act, widths, seed, true);
}

/// With `saturated`, the labels are clamped to a band (about half of them land on a
/// bound) and the saturation-aware loss is used.
fn check_grad_band(act: Activation, widths: &[usize], seed: u64, saturated: bool) {
    let m = net(seed, act, widths);
    let (nx, nu) = (m.nx(), m.nu());
    let (x, mut u, du, uj) = data(seed, nx, nu, 16);
    let (blo, bhi) = (vec![-0.3; nu], vec![0.3; nu]);
    if saturated {
        for v in u.iter_mut() {
            *v = v.clamp(-0.3, 0.3);
        }
        // The test must see both cases: clamped-exact samples and ordinary ones.
        let mut ws = Workspace::default();
        let (mut p, mut jac) = (vec![0.0; nu], vec![0.0; nu * nx]);
        let mut exact = 0;
        for i in 0..16 {
            m.eval(&x[i * nx..(i + 1) * nx], &mut p, &mut jac, &mut ws);
            for r in 0..nu {
                exact += clamped_exact(Some((&blo, &bhi)), r, p[r], u[i * nu + r]) as usize;
            }
        }
        assert!(
            exact > 0 && exact < 16 * nu,
            "{exact} of {} clamped-exact",
            16 * nu
        );
    }
    let batch = Batch {
        x: &x,
        u: &u,
        du: &du,
        use_jac: &uj,
        band: saturated.then_some((&blo[..], &bhi[..])),
        seq: None,
    };
    for lam in [
        LossWeights {
            value: 1.0,
            jacobian: 0.0,
            weights: 0.0,
        },
        LossWeights {
            value: 0.0,
            jacobian: 1.0,
            weights: 0.0,
        },
        LossWeights {
            value: 0.0,
            jacobian: 0.0,
            weights: 1.0,
        },
        LossWeights {
            value: 1.0,
            jacobian: 3.0,
            weights: 0.05,
        },
    ] {
        let mut ws = Workspace::default();
        let mut g = m.zero_grad();
        m.loss_grad(&batch, lam, &mut g, &mut ws);
        let h = 1e-6;
        for j in 0..m.layers.len() {
            for k in 0..m.layers[j].w.len() + m.layers[j].b.len() {
                let nw = m.layers[j].w.len();
                let f = |d: f64| {
                    let mut p = m.clone();
                    if k < nw {
                        p.layers[j].w[k] += d;
                    } else {
                        p.layers[j].b[k - nw] += d;
                    }
                    let mut g2 = p.zero_grad();
                    p.loss_grad(&batch, lam, &mut g2, &mut Workspace::default())
                        .total()
                };
                let fd = (f(h) - f(-h)) / (2.0 * h);
                let an = if k < nw { g.w[j][k] } else { g.b[j][k - nw] };
                assert!(
                    (fd - an).abs() <= 1e-6 * (1.0 + an.abs()),
                    "{act:?} {widths:?} {lam:?} layer {j} param {k}: fd {fd} analytic {an}"
                );
            }
        }
    }
}

#[test]
fn gradients_match_finite_differences() {
    check_grad(Activation::Tanh, &[2, 10, 10, 1], 1);
    check_grad(Activation::Tanh, &[3, 4, 2], 2);
    check_grad(Activation::Tanh, &[2, 1], 3);
    check_grad(Activation::Softplus, &[2, 5, 4, 2], 4);
}

proptest! {
    #![proptest_config(ProptestConfig {
        rng_seed: proptest::test_runner::RngSeed::Fixed(0x616d_7063),
        ..ProptestConfig::with_cases(32)
    })]
    #[test]
    fn jacobian_matches_finite_differences(seed in 0u64..1000, x in proptest::collection::vec(-3.0f64..3.0, 3)) {
        for act in [Activation::Tanh, Activation::Softplus] {
            let m = net(seed, act, &[3, 6, 5, 2]);
            let mut ws = Workspace::default();
            let (mut u, mut j) = (vec![0.0; 2], vec![0.0; 6]);
            m.eval(&x, &mut u, &mut j, &mut ws);
            for k in 0..3 {
                let (mut xp, mut xm) = (x.clone(), x.clone());
                xp[k] += 1e-6;
                xm[k] -= 1e-6;
                let (up, um) = (m.predict(&xp), m.predict(&xm));
                for r in 0..2 {
                    let fd = (up[r] - um[r]) / 2e-6;
                    prop_assert!((fd - j[r * 3 + k]).abs() <= 1e-6 * (1.0 + fd.abs()));
                }
            }
        }
    }
}

/// The original per-sample kernels (one state at a time, scalar loops), kept as the
/// reference the batched kernels must reproduce bit for bit.
mod reference {
    use super::super::*;

    #[derive(Default)]
    pub struct Ws {
        a: Vec<Vec<f64>>,
        dz: Vec<Vec<f64>>,
        ddz: Vec<Vec<f64>>,
        t: Vec<Vec<f64>>,
        zt: Vec<Vec<f64>>,
        ga: Vec<f64>,
        gt: Vec<f64>,
        ga2: Vec<f64>,
        gt2: Vec<f64>,
    }

    fn ensure(mlp: &Mlp, ws: &mut Ws) {
        let nx = mlp.nx();
        let w = mlp.widths();
        ws.a = w.iter().map(|&n| vec![0.0; n]).collect();
        ws.dz = w.iter().map(|&n| vec![0.0; n]).collect();
        ws.ddz = w.iter().map(|&n| vec![0.0; n]).collect();
        ws.t = w.iter().map(|&n| vec![0.0; n * nx]).collect();
        ws.zt = w.iter().map(|&n| vec![0.0; n * nx]).collect();
        let maxw = w.into_iter().max().unwrap_or(0);
        ws.ga = vec![0.0; maxw];
        ws.ga2 = vec![0.0; maxw];
        ws.gt = vec![0.0; maxw * nx];
        ws.gt2 = vec![0.0; maxw * nx];
    }

    fn pass(mlp: &Mlp, x: &[f64], ws: &mut Ws) {
        let nx = mlp.nx();
        let m = mlp.layers.len();
        for i in 0..nx {
            ws.a[0][i] = (x[i] - mlp.in_center[i]) / mlp.in_half[i];
            for k in 0..nx {
                ws.t[0][i * nx + k] = if i == k { 1.0 / mlp.in_half[i] } else { 0.0 };
            }
        }
        for (j, l) in mlp.layers.iter().enumerate() {
            let (prev, rest) = ws.a.split_at_mut(j + 1);
            let (tprev, trest) = ws.t.split_at_mut(j + 1);
            let (ap, an) = (&prev[j], &mut rest[0]);
            let (tp, tn) = (&tprev[j], &mut trest[0]);
            let zt = &mut ws.zt[j + 1];
            for r in 0..l.out {
                let row = &l.w[r * l.inp..(r + 1) * l.inp];
                let mut z = l.b[r];
                for c in 0..l.inp {
                    z += row[c] * ap[c];
                }
                for k in 0..nx {
                    let mut s = 0.0;
                    for c in 0..l.inp {
                        s += row[c] * tp[c * nx + k];
                    }
                    zt[r * nx + k] = s;
                }
                if j + 1 < m {
                    let (v, d, dd) = mlp.activation.eval(z);
                    an[r] = v;
                    ws.dz[j + 1][r] = d;
                    ws.ddz[j + 1][r] = dd;
                    for k in 0..nx {
                        tn[r * nx + k] = d * zt[r * nx + k];
                    }
                } else {
                    an[r] = z;
                    for k in 0..nx {
                        tn[r * nx + k] = zt[r * nx + k];
                    }
                }
            }
        }
    }

    pub fn eval(mlp: &Mlp, x: &[f64], u: &mut [f64], jac: &mut [f64]) {
        let mut ws = Ws::default();
        ensure(mlp, &mut ws);
        pass(mlp, x, &mut ws);
        let (nx, m) = (mlp.nx(), mlp.layers.len());
        for r in 0..mlp.nu() {
            u[r] = mlp.out_center[r] + mlp.out_half[r] * ws.a[m][r];
            for k in 0..nx {
                jac[r * nx + k] = mlp.out_half[r] * ws.t[m][r * nx + k];
            }
        }
    }

    pub fn loss_grad(mlp: &Mlp, batch: &Batch, lam: LossWeights, grad: &mut Grad) -> LossParts {
        let mut ws = Ws::default();
        ensure(mlp, &mut ws);
        let (nx, nu, m) = (mlp.nx(), mlp.nu(), mlp.layers.len());
        let bsz = batch.use_jac.len();
        for (gw, gb) in grad.w.iter_mut().zip(grad.b.iter_mut()) {
            gw.fill(0.0);
            gb.fill(0.0);
        }
        let inv_b = 1.0 / bsz.max(1) as f64;
        let mut parts = LossParts::default();
        for i in 0..bsz {
            let x = &batch.x[i * nx..(i + 1) * nx];
            pass(mlp, x, &mut ws);
            let use_jac = batch.use_jac[i] && lam.jacobian != 0.0;
            for r in 0..nu {
                let s = mlp.out_half[r];
                let pred = mlp.out_center[r] + s * ws.a[m][r];
                let exact = super::clamped_exact(batch.band, r, pred, batch.u[i * nu + r]);
                let e = if exact {
                    0.0
                } else {
                    pred - batch.u[i * nu + r]
                };
                parts.value += lam.value * inv_b * e * e;
                ws.ga[r] = 2.0 * lam.value * inv_b * e * s;
                for k in 0..nx {
                    let g = if use_jac && !exact {
                        let e = s * ws.t[m][r * nx + k] - batch.du[i * nu * nx + r * nx + k];
                        parts.jacobian += lam.jacobian * inv_b * e * e;
                        2.0 * lam.jacobian * inv_b * e * s
                    } else {
                        0.0
                    };
                    ws.gt[r * nx + k] = g;
                }
            }
            for j in (0..m).rev() {
                let l = &mlp.layers[j];
                if j + 1 < m {
                    let (d, dd, zt) = (&ws.dz[j + 1], &ws.ddz[j + 1], &ws.zt[j + 1]);
                    for r in 0..l.out {
                        let mut acc = 0.0;
                        for k in 0..nx {
                            acc += ws.gt[r * nx + k] * zt[r * nx + k];
                            ws.gt[r * nx + k] *= d[r];
                        }
                        ws.ga[r] = d[r] * ws.ga[r] + dd[r] * acc;
                    }
                }
                let (ap, tp) = (&ws.a[j], &ws.t[j]);
                let gw = &mut grad.w[j];
                for r in 0..l.out {
                    grad.b[j][r] += ws.ga[r];
                    for c in 0..l.inp {
                        let mut g = ws.ga[r] * ap[c];
                        for k in 0..nx {
                            g += ws.gt[r * nx + k] * tp[c * nx + k];
                        }
                        gw[r * l.inp + c] += g;
                    }
                }
                if j > 0 {
                    for c in 0..l.inp {
                        let mut g = 0.0;
                        for r in 0..l.out {
                            g += l.w[r * l.inp + c] * ws.ga[r];
                        }
                        ws.ga2[c] = g;
                        for k in 0..nx {
                            let mut g = 0.0;
                            for r in 0..l.out {
                                g += l.w[r * l.inp + c] * ws.gt[r * nx + k];
                            }
                            ws.gt2[c * nx + k] = g;
                        }
                    }
                    std::mem::swap(&mut ws.ga, &mut ws.ga2);
                    std::mem::swap(&mut ws.gt, &mut ws.gt2);
                }
            }
        }
        if lam.weights != 0.0 {
            for (j, l) in mlp.layers.iter().enumerate() {
                for r in 0..l.out {
                    let rs = if j + 1 == m { mlp.out_half[r] } else { 1.0 };
                    for c in 0..l.inp {
                        let cs = if j == 0 { 1.0 / mlp.in_half[c] } else { 1.0 };
                        let f = rs * rs * cs * cs;
                        let w = l.w[r * l.inp + c];
                        parts.weights += lam.weights * f * w * w;
                        grad.w[j][r * l.inp + c] += 2.0 * lam.weights * f * w;
                    }
                }
            }
        }
        parts
    }
}

fn bits(v: &[f64]) -> Vec<u64> {
    v.iter().map(|x| x.to_bits()).collect()
}

/// The batched kernels reproduce the per-sample reference bit for bit: loss terms,
/// gradients, values and Jacobians, for batch sizes across the block boundary, all
/// activations, with and without the Jacobian term.
#[test]
fn batched_kernels_match_the_per_sample_reference_bitwise() {
    let cases: [(Activation, &[usize]); 5] = [
        (Activation::Tanh, &[2, 10, 10, 1]),
        (Activation::Tanh, &[3, 4, 2]),
        (Activation::Tanh, &[2, 1]),
        (Activation::Softplus, &[2, 5, 4, 2]),
        (Activation::Relu, &[4, 7, 3, 5, 2]),
    ];
    for (ci, (act, widths)) in cases.into_iter().enumerate() {
        let m = net(10 + ci as u64, act, widths);
        let (nx, nu) = (m.nx(), m.nu());
        let mut ws = Workspace::default();
        for b in [1usize, 7, 35, 64, 65, 200] {
            let (x, mut u, du, uj) = data(ci as u64 + 3 * b as u64, nx, nu, b);
            let (blo, bhi) = (vec![-0.5; nu], vec![0.5; nu]);
            let banded = b % 2 == 1;
            if banded {
                u.iter_mut().for_each(|v| *v = v.clamp(-0.5, 0.5));
            }
            let batch = Batch {
                x: &x,
                u: &u,
                du: &du,
                use_jac: &uj,
                band: banded.then_some((&blo[..], &bhi[..])),
                seq: None,
            };
            for lam in [
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
            ] {
                let (mut g1, mut g2) = (m.zero_grad(), m.zero_grad());
                let p1 = m.loss_grad(&batch, lam, &mut g1, &mut ws);
                let p2 = reference::loss_grad(&m, &batch, lam, &mut g2);
                let p3 = m.loss(&batch, lam, &mut ws);
                for (q, r) in [(p1, p2), (p3, p2)] {
                    assert_eq!(
                        bits(&[q.value, q.jacobian, q.weights]),
                        bits(&[r.value, r.jacobian, r.weights]),
                        "{widths:?} b={b} {lam:?}"
                    );
                }
                for j in 0..m.layers.len() {
                    assert_eq!(bits(&g1.w[j]), bits(&g2.w[j]), "{widths:?} b={b} W{j}");
                    assert_eq!(bits(&g1.b[j]), bits(&g2.b[j]), "{widths:?} b={b} b{j}");
                }
            }
            let (mut u1, mut j1) = (vec![0.0; b * nu], vec![0.0; b * nu * nx]);
            m.eval_batch(&x, &mut u1, Some(&mut j1), &mut ws);
            let mut u3 = vec![0.0; b * nu];
            m.eval_batch(&x, &mut u3, None, &mut ws);
            assert_eq!(bits(&u1), bits(&u3));
            for i in 0..b {
                let (mut u2, mut j2) = (vec![0.0; nu], vec![0.0; nu * nx]);
                reference::eval(&m, &x[i * nx..(i + 1) * nx], &mut u2, &mut j2);
                assert_eq!(bits(&u1[i * nu..(i + 1) * nu]), bits(&u2));
                assert_eq!(bits(&j1[i * nu * nx..(i + 1) * nu * nx]), bits(&j2));
                let (mut u4, mut j4) = (vec![0.0; nu], vec![0.0; nu * nx]);
                m.eval(&x[i * nx..(i + 1) * nx], &mut u4, &mut j4, &mut ws);
                assert_eq!(bits(&u4), bits(&u2));
                assert_eq!(bits(&j4), bits(&j2));
            }
        }
    }
}

#[test]
fn physical_layers_compute_the_same_function() {
    let m = net(5, Activation::Tanh, &[2, 7, 3]);
    let phys = m.physical_layers();
    let x = [0.7, -1.3];
    let mut a = x.to_vec();
    for (j, l) in phys.iter().enumerate() {
        let mut z = l.b.clone();
        for r in 0..l.out {
            for c in 0..l.inp {
                z[r] += l.w[r * l.inp + c] * a[c];
            }
        }
        a = if j + 1 < phys.len() {
            z.iter().map(|v| v.tanh()).collect()
        } else {
            z
        };
    }
    let u = m.predict(&x);
    for r in 0..3 {
        assert!((u[r] - a[r]).abs() < 1e-12);
    }
}
