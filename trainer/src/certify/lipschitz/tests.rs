//! The Lipschitz bounds: sampled ≤ vertex ≤ LipSDP ≤ naive on random nets, closed forms
//! (one layer, one neuron, decoupled nets), the vertex enumeration against brute force,
//! LipSDP against an independent solve and its multipliers checked on the LMI assembled
//! independently (Fazlyab et al.'s [A; B] form, not the module's block assembly); the MPC
//! estimates of a linear law.

use super::*;
use crate::learn::mlp::{Activation, Workspace};

fn net(seed: u64, widths: &[usize]) -> Mlp {
    let nx = widths[0];
    let nu = *widths.last().unwrap();
    Mlp::new(
        widths,
        Activation::Tanh,
        seed,
        &vec![-2.0; nx],
        &vec![3.0; nx],
        &vec![-4.0; nu],
        &vec![4.0; nu],
    )
}

#[test]
fn bounds_are_ordered_on_random_nets() {
    for seed in 0..12 {
        for widths in [[2usize, 10, 10, 1].as_slice(), &[2, 6, 1], &[3, 5, 4, 2]] {
            let m = net(seed, widths);
            let naive = naive_bound(&m);
            let sdp = lipsdp_bound(&m);
            let vert = vertex_bound(&m, 20).unwrap();
            let lower = sampled_lower_bound(
                &m,
                &vec![-2.0; widths[0]],
                &vec![3.0; widths[0]],
                2000,
                seed,
            );
            assert!(
                lower <= vert * (1.0 + 1e-9),
                "{seed} {widths:?}: lower {lower} > vertex {vert}"
            );
            assert!(
                vert <= sdp * (1.0 + 1e-6),
                "{seed} {widths:?}: vertex {vert} > lipsdp {sdp}"
            );
            assert!(
                sdp <= naive * (1.0 + 1e-9),
                "{seed} {widths:?}: lipsdp {sdp} > naive {naive}"
            );
        }
    }
}

#[test]
fn single_linear_layer_all_bounds_equal_the_norm() {
    let m = net(3, &[3, 2]);
    let w = DMatrix::from_row_slice(2, 3, &m.physical_layers()[0].w);
    let n = spectral_norm(&w);
    assert!((naive_bound(&m) - n).abs() < 1e-12);
    assert!((lipsdp_bound(&m) - n).abs() < 1e-12);
    assert!((vertex_bound(&m, 20).unwrap() - n).abs() < 1e-12);
    let lower = sampled_lower_bound(&m, &[-2.0; 3], &[3.0; 3], 10, 1);
    assert!((lower - n).abs() < 1e-9);
}

/// One hidden neuron: LipSDP-Neuron is exact, |w₂·w₁|.
#[test]
fn lipsdp_is_exact_for_one_neuron() {
    let mut m = net(1, &[1, 1, 1]);
    m.layers[0].w = vec![0.7];
    m.layers[1].w = vec![-1.9];
    let exact = naive_bound(&m);
    assert!((lipsdp_bound(&m) - exact).abs() <= 1e-6 * exact);
}

/// The original enumeration: the plain product for every slope pattern.
fn vertex_brute_force(mlp: &Mlp) -> f64 {
    let w: Vec<DMatrix<f64>> = mlp.physical_layers().iter().map(mat).collect();
    let hidden: usize = w[..w.len() - 1].iter().map(|m| m.nrows()).sum();
    let mut best = 0.0f64;
    for mask in 0u64..1 << hidden {
        let mut bit = 0;
        let mut p = DMatrix::zeros(0, 0);
        for (j, wj) in w.iter().enumerate() {
            p = if j == 0 { wj.clone() } else { wj * &p };
            if j + 1 < w.len() {
                for r in 0..wj.nrows() {
                    if mask >> bit & 1 == 0 {
                        p.row_mut(r).fill(0.0);
                    }
                    bit += 1;
                }
            }
        }
        best = best.max(spectral_norm(&p));
    }
    best
}

#[test]
fn vertex_enumeration_matches_brute_force() {
    for (seed, widths) in [
        (1u64, [2usize, 6, 5, 1].as_slice()),
        (2, &[2, 4, 7, 2]),
        (3, &[3, 5, 3]),
        (4, &[3, 3, 4, 3, 3]),
        (5, &[1, 6, 2]),
        (6, &[4, 2, 3, 5]),
    ] {
        let m = net(seed, widths);
        let (fast, brute) = (vertex_bound(&m, 22).unwrap(), vertex_brute_force(&m));
        assert!(
            (fast - brute).abs() <= 1e-12 * brute,
            "{widths:?}: {fast} vs {brute}"
        );
    }
}

/// The vertex loop's lane-wise maximum of squared sums is the sequential one bit for bit:
/// pattern counts around the lane width, 1–3 entries, NaN and ±0 entries included.
#[test]
fn max_sq_sum_is_the_sequential_maximum() {
    let mut st = 0x5EED_u64;
    let mut next = || {
        st = crate::rng::splitmix64(st);
        ((st >> 11) as f64 / (1u64 << 53) as f64 - 0.5) * 8.0
    };
    for n in [1usize, 2, 7, 8, 9, 16, 31, 32, 33] {
        for dim in 1..=3 {
            for special in [None, Some(f64::NAN), Some(-0.0), Some(0.0)] {
                let mut lo: Vec<f64> = (0..n * dim).map(|_| next()).collect();
                let h: Vec<f64> = (0..dim).map(|_| next()).collect();
                if let Some(v) = special {
                    lo[(n * dim) / 2] = v;
                }
                let mut expect = 0.0f64;
                for s in 0..n {
                    let v = (0..dim)
                        .map(|e| (lo[e * n + s] + h[e]) * (lo[e * n + s] + h[e]))
                        .sum::<f64>();
                    expect = expect.max(v);
                }
                assert_eq!(
                    max_sq_sum(&lo, n, &h).to_bits(),
                    expect.to_bits(),
                    "n {n} dim {dim} {special:?}"
                );
            }
        }
    }
}

/// Diagonal (unit-wise decoupled) nets: x_i ↦ w₃ᵢ σ(w₂ᵢ σ(w₁ᵢ xᵢ)), whose Lipschitz
/// constant, LipSDP-Neuron optimum included, is maxᵢ |w₁ᵢ w₂ᵢ w₃ᵢ| (scaling removed).
#[test]
fn lipsdp_reaches_the_known_optimum_of_decoupled_nets() {
    let n = 4;
    let mut m = Mlp::new(
        &[n, n, n, n],
        Activation::Tanh,
        0,
        &vec![-1.0; n],
        &vec![1.0; n],
        &vec![-1.0; n],
        &vec![1.0; n],
    );
    let w: [[f64; 4]; 3] = [
        [0.7, -1.9, 2.5, 0.3],
        [1.4, 0.8, -0.6, 3.0],
        [-2.2, 1.1, 0.9, 0.5],
    ];
    let mut exact = 0.0f64;
    for i in 0..n {
        exact = exact.max((w[0][i] * w[1][i] * w[2][i]).abs());
    }
    for (l, wl) in m.layers.iter_mut().zip(&w) {
        l.w.fill(0.0);
        for i in 0..n {
            l.w[i * n + i] = wl[i];
        }
    }
    let sdp = lipsdp_bound(&m);
    assert!(
        sdp >= exact * (1.0 - 1e-12),
        "{sdp} below the true constant {exact}"
    );
    assert!(sdp <= exact * (1.0 + 1e-5), "{sdp} vs optimum {exact}");
    assert!((vertex_bound(&m, 22).unwrap() - exact).abs() <= 1e-12 * exact);
}

/// The LipSDP-Neuron matrix assembled as in Fazlyab et al. (2019), Theorem 2, with slopes
/// in [α, β] = [0, 1] — independently of `LipSdp::k`/`n1t`:
/// `M = [A; B]ᵀ [[0, T], [T, −2T]] [A; B] + diag(−ρI, 0, …, 0, W̃_lᵀW̃_l)` with
/// `A = [blkdiag(W̃_0, …, W̃_{l−1}), 0]`, `B = [0, I]` over z = (x, hidden units).
fn lmi(mlp: &Mlp, rho: f64, t: &[f64]) -> DMatrix<f64> {
    let w: Vec<DMatrix<f64>> = mlp
        .physical_layers()
        .iter()
        .map(|l| DMatrix::from_row_slice(l.out, l.inp, &l.w))
        .collect();
    let h = w.len() - 1;
    let n0 = w[0].ncols();
    let nh: usize = w[..h].iter().map(|m| m.nrows()).sum();
    let dim = n0 + nh;
    let mut a = DMatrix::zeros(nh, dim);
    let (mut r, mut c) = (0, 0);
    for wj in &w[..h] {
        a.view_mut((r, c), (wj.nrows(), wj.ncols())).copy_from(wj);
        r += wj.nrows();
        c += wj.ncols();
    }
    let mut b = DMatrix::zeros(nh, dim);
    b.view_mut((0, n0), (nh, nh)).fill_with_identity();
    let tm = DMatrix::from_diagonal(&DVector::from_column_slice(t));
    let mut m =
        a.transpose() * &tm * &b + b.transpose() * &tm * &a - b.transpose() * &tm * &b * 2.0;
    for i in 0..n0 {
        m[(i, i)] -= rho;
    }
    let last = &w[h];
    let nl = last.ncols();
    let mut corner = m.view_mut((dim - nl, dim - nl), (nl, nl));
    corner += last.transpose() * last;
    m
}

/// Whether −M(ρ, T) of [`lmi`] is positive definite (a Cholesky factorisation).
fn lmi_holds(mlp: &Mlp, rho: f64, t: &[f64]) -> bool {
    nalgebra::Cholesky::new(-lmi(mlp, rho, t)).is_some()
}

/// An independent LipSDP-Neuron solve: for fixed T, the least ρ with −M(ρ, T) ⪰ 0 by
/// bisection on Cholesky factorisations of the full matrix of [`lmi`] (no Schur
/// complement, no eigenvalues, no gradients, not the module's assembly), minimised over T
/// by a derivative-free pattern search in log T (coordinate and random directions,
/// shrinking steps).
fn lipsdp_reference(mlp: &Mlp) -> f64 {
    let nh: usize = mlp.layers[..mlp.layers.len() - 1]
        .iter()
        .map(|l| l.out)
        .sum();
    let least_rho = |t: &[f64]| -> f64 {
        let (mut lo, mut hi) = (0.0, 1.0);
        let mut k = 0;
        while !lmi_holds(mlp, hi, t) {
            hi *= 4.0;
            k += 1;
            if k > 200 {
                return f64::INFINITY;
            }
        }
        for _ in 0..200 {
            let mid = 0.5 * (lo + hi);
            if lmi_holds(mlp, mid, t) {
                hi = mid;
            } else {
                lo = mid;
            }
            if hi - lo <= 1e-13 * hi {
                break;
            }
        }
        hi
    };
    let mut th = vec![0.0; nh];
    let eval = |th: &[f64]| least_rho(&th.iter().map(|v| v.exp()).collect::<Vec<_>>());
    // A feasible start: T = 2^k I with K(T) ≻ 0.
    let mut f = eval(&th);
    while !f.is_finite() {
        th.iter_mut().for_each(|v| *v += std::f64::consts::LN_2);
        f = eval(&th);
    }
    let mut step = 1.0;
    let mut it = 0u64;
    while step > 1e-8 {
        let mut improved = false;
        let ndir = 2 * nh + 6 * nh;
        for d in 0..ndir {
            let dir: Vec<f64> = if d < 2 * nh {
                let s = if d % 2 == 0 { 1.0 } else { -1.0 };
                (0..nh).map(|k| if k == d / 2 { s } else { 0.0 }).collect()
            } else {
                it += 1;
                (0..nh)
                    .map(|k| 2.0 * crate::rng::uniform(77, it, k as u64) - 1.0)
                    .collect()
            };
            let cand: Vec<f64> = th.iter().zip(&dir).map(|(a, b)| a + step * b).collect();
            let fc = eval(&cand);
            if fc < f {
                f = fc;
                th = cand;
                improved = true;
            }
        }
        if !improved {
            step *= 0.7;
        }
    }
    f.sqrt()
}

#[test]
fn lipsdp_agrees_with_an_independent_solve() {
    for (seed, widths) in [
        (1u64, [2usize, 4, 3, 1].as_slice()),
        (2, &[2, 5, 5, 1]),
        (3, &[3, 4, 2]),
    ] {
        let m = net(seed, widths);
        let (fast, slow) = (lipsdp_bound(&m), lipsdp_reference(&m));
        eprintln!("{widths:?}: descent {fast}, reference {slow}");
        // Measured gap: both directions up to ~1e-3 (the derivative-free search stalls
        // at kinks of λ_max; the descent in ln T converges slowly where optimal
        // multipliers tend to 0). The target is ~1e-4: not reached yet.
        assert!(
            slow.is_finite() && (fast - slow).abs() <= 2e-3 * slow,
            "{widths:?}: descent {fast} vs reference {slow}"
        );
    }
}

/// The multipliers behind `lipsdp_bound`, checked on the independently assembled LMI by
/// its eigenvalues: M(ρ, T) ⪯ 0 (feasible) and M(0.99ρ, T) not (ρ is tight for this T);
/// and √ρ between the largest sampled Jacobian norm (the network's own forward-mode
/// derivative) and the product of the layers' spectral norms.
#[test]
fn lipsdp_multipliers_are_feasible_for_an_independent_assembly() {
    for (seed, widths) in [
        (1u64, [2usize, 4, 3, 1].as_slice()),
        (2, &[2, 10, 10, 1]),
        (3, &[3, 5, 4, 2]),
        (4, &[4, 16, 16, 16, 2]),
    ] {
        let m = net(seed, widths);
        let (rho, t) = lipsdp_multipliers(&m).expect("a certificate");
        assert_eq!(lipsdp_bound(&m), rho.sqrt());
        assert!(t.iter().all(|v| *v > 0.0), "{widths:?}: T {t:?}");
        let lmax = |r: f64| lmi(&m, r, &t).symmetric_eigenvalues().max();
        let scale = lmi(&m, rho, &t).norm();
        assert!(
            lmax(rho) <= 1e-12 * scale,
            "{widths:?}: λ_max(M(ρ, T)) = {} > 0",
            lmax(rho)
        );
        assert!(
            lmax(0.99 * rho) > 0.0,
            "{widths:?}: ρ not tight for T (λ_max at 0.99ρ = {})",
            lmax(0.99 * rho)
        );
        let product: f64 = m
            .physical_layers()
            .iter()
            .map(|l| {
                DMatrix::from_row_slice(l.out, l.inp, &l.w)
                    .singular_values()
                    .max()
            })
            .product();
        let (nx, nu) = (widths[0], *widths.last().unwrap());
        let mut ws = Workspace::default();
        let (mut u, mut j) = (vec![0.0; nu], vec![0.0; nu * nx]);
        let mut lower = 0.0f64;
        for s in 0..3000u64 {
            let x: Vec<f64> = (0..nx)
                .map(|k| -2.0 + 5.0 * crate::rng::uniform(seed + 100, s, k as u64))
                .collect();
            m.eval(&x, &mut u, &mut j, &mut ws);
            lower = lower.max(DMatrix::from_row_slice(nu, nx, &j).singular_values().max());
        }
        let l = rho.sqrt();
        assert!(
            lower <= l * (1.0 + 1e-12),
            "{widths:?}: sampled {lower} > LipSDP {l}"
        );
        assert!(
            l <= product * (1.0 + 1e-12),
            "{widths:?}: LipSDP {l} > product {product}"
        );
        eprintln!("{widths:?}: sampled {lower:.4} ≤ LipSDP {l:.4} ≤ product {product:.4}");
    }
}

#[test]
fn mpc_estimates_of_a_linear_law() {
    // κ(x) = A x with ‖A‖₂ known: both estimates recover it.
    let a = [3.0, -4.0];
    let mut x = Vec::new();
    let mut u = Vec::new();
    let mut du = Vec::new();
    for i in 0..10 {
        for j in 0..10 {
            let p = [i as f64 * 0.1, j as f64 * 0.2];
            x.extend(p);
            u.push(a[0] * p[0] + a[1] * p[1]);
            du.extend(a);
        }
    }
    let (s, q) = mpc_estimates(&x, &u, &du, &[true; 100], 2, 1);
    assert!((s - 5.0).abs() < 1e-12);
    assert!(q <= 5.0 + 1e-9 && q > 3.0);
}

/// The blocked, parallel sampled lower bound is the serial point-by-point f64 search bit
/// for bit (the algorithm before the blocks and the f32 screen, written out here), for 1
/// and 2 threads, on several shapes (n not a multiple of the block size): the screen ranks
/// these points' 10 largest as f64 does, and every value taken is an f64 evaluation.
#[test]
fn sampled_lower_bound_is_the_serial_search_for_any_thread_count() {
    fn serial(mlp: &Mlp, lo: &[f64], hi: &[f64], n: usize, seed: u64) -> f64 {
        let (nx, nu) = (mlp.nx(), mlp.nu());
        let mut ws = Workspace::default();
        let (mut u, mut j) = (vec![0.0; nu], vec![0.0; nu * nx]);
        let mut norm_at = |x: &[f64], ws: &mut Workspace| {
            mlp.eval(x, &mut u, &mut j, ws);
            spectral_norm(&DMatrix::from_row_slice(nu, nx, &j))
        };
        let mut pts: Vec<(f64, Vec<f64>)> = (0..n)
            .map(|i| {
                let x: Vec<f64> = (0..nx)
                    .map(|k| {
                        lo[k] + (hi[k] - lo[k]) * crate::rng::uniform(seed, i as u64, k as u64)
                    })
                    .collect();
                (norm_at(&x, &mut ws), x)
            })
            .collect();
        pts.sort_by(|a, b| b.0.total_cmp(&a.0));
        let mut best = pts.first().map_or(0.0, |p| p.0);
        for (k, (v0, x0)) in pts.into_iter().take(10).enumerate() {
            let (mut v, mut x) = (v0, x0);
            let mut radius: Vec<f64> = (0..nx).map(|i| 0.05 * (hi[i] - lo[i])).collect();
            for it in 0..400 {
                let cand: Vec<f64> = (0..nx)
                    .map(|i| {
                        let r = 2.0
                            * crate::rng::uniform(seed ^ 0x5151, (k * 1000 + it) as u64, i as u64)
                            - 1.0;
                        (x[i] + r * radius[i]).clamp(lo[i], hi[i])
                    })
                    .collect();
                let c = norm_at(&cand, &mut ws);
                if c > v {
                    v = c;
                    x = cand;
                } else if it % 20 == 19 {
                    radius.iter_mut().for_each(|r| *r *= 0.5);
                }
            }
            best = best.max(v);
        }
        best
    }
    for (seed, widths, n) in [
        (0u64, [2usize, 10, 10, 1].as_slice(), 3000usize),
        (5, &[3, 5, 4, 2], 2500),
        (9, &[4, 6, 3], 7),
    ] {
        let m = net(seed, widths);
        let (lo, hi) = (vec![-2.0; widths[0]], vec![3.0; widths[0]]);
        let want = serial(&m, &lo, &hi, n, seed);
        for threads in [1, 2] {
            let pool = rayon::ThreadPoolBuilder::new()
                .num_threads(threads)
                .build()
                .unwrap();
            let got = pool.install(|| sampled_lower_bound(&m, &lo, &hi, n, seed));
            assert_eq!(
                got.to_bits(),
                want.to_bits(),
                "{widths:?} {threads} threads"
            );
        }
    }
}

/// The search's objective on reusable buffers gives the bits of the `nalgebra` version
/// (value, smoothing and gradient, or `None` for both) at random multipliers around the
/// certified ones, for nets with up to 5 inputs (wider inputs take `matrixmultiply` in
/// `nalgebra`'s product N₁K⁻¹N₁ᵀ, whose order is its own: there ρ and f_μ within 1e-12
/// and the gradient within 1e-6 of its largest entry — the eigenvectors of nearly equal
/// eigenvalues amplify the last bits of A).
#[test]
fn rho_on_buffers_is_the_nalgebra_rho() {
    let mut ws = DenseWork::default();
    for (seed, widths) in [
        (1u64, [2usize, 10, 10, 1].as_slice()),
        (2, &[2, 4, 3, 1]),
        (3, &[3, 5, 4, 2]),
        (4, &[4, 16, 16, 16, 2]),
        (5, &[5, 9, 1]),
        (6, &[6, 32, 32, 2]),
        (7, &[12, 8, 8, 4]),
        // As many hidden units as each other, other blocks: the shared buffers must not
        // keep the first net's factor (nonzero in rows 32‥48 × columns 8‥16) where the
        // second has structural zeros.
        (8, &[4, 8, 8, 32, 2]),
        (9, &[4, 16, 16, 16, 2]),
    ] {
        let m = net(seed, widths);
        let sdp = LipSdp::new(&m);
        let (_, t_opt) = lipsdp_multipliers(&m).expect("a certificate");
        let mut s = seed;
        let mut r = || {
            s = s
                .wrapping_mul(6364136223846793005)
                .wrapping_add(1442695040888963407);
            (s >> 11) as f64 / (1u64 << 53) as f64
        };
        let mut seen_some = false;
        for trial in 0..40 {
            // Around the certified multipliers: some perturbations leave K(T) ≻ 0, some not.
            let spread = 0.05 * trial as f64;
            let t: Vec<f64> = t_opt
                .iter()
                .map(|v| v * (spread * (2.0 * r() - 1.0)).exp())
                .collect();
            let mu = 10f64.powf(-6.0 * r());
            let a = sdp.rho(&t, mu, &mut ws);
            let b = sdp.rho_nalgebra(&t, mu);
            assert_eq!(a.is_some(), b.is_some(), "{widths:?} trial {trial}");
            let (Some((l1, f1, g1)), Some((l2, f2, g2))) = (a, b) else {
                continue;
            };
            seen_some = true;
            if widths[0] <= 5 {
                assert_eq!(l1.to_bits(), l2.to_bits(), "{widths:?} trial {trial}");
                assert_eq!(f1.to_bits(), f2.to_bits(), "{widths:?} trial {trial}");
                let bits = |g: &[f64]| g.iter().map(|v| v.to_bits()).collect::<Vec<_>>();
                assert_eq!(bits(&g1), bits(&g2), "{widths:?} trial {trial}");
            } else {
                let close =
                    |x: f64, y: f64| (x - y).abs() <= 1e-12 * x.abs().max(y.abs()).max(1e-300);
                assert!(close(l1, l2) && close(f1, f2), "{widths:?} trial {trial}");
                let gs = g2.iter().fold(0.0f64, |m, v| m.max(v.abs()));
                assert!(
                    g1.iter().zip(&g2).all(|(x, y)| (x - y).abs() <= 1e-6 * gs),
                    "{widths:?} trial {trial}: {g1:?} vs {g2:?}"
                );
            }
        }
        assert!(seen_some, "{widths:?}: no feasible multipliers tried");
    }
}

/// The row path of `spectral_norm` gives the bits of `nalgebra`'s SVD, on rows of every
/// length up to 13 with entries of mixed sign and magnitudes from 1e-300 to 1e300, zeros
/// among them.
#[test]
fn row_norm_is_the_svd_norm_bit_for_bit() {
    let mut s = 17u64;
    let mut r = || {
        s = s
            .wrapping_mul(6364136223846793005)
            .wrapping_add(1442695040888963407);
        (s >> 11) as f64 / (1u64 << 53) as f64
    };
    for trial in 0..40_000 {
        let n = 1 + trial % 13;
        let scale = 10f64.powf(600.0 * r() - 300.0);
        let row: Vec<f64> = (0..n)
            .map(|_| {
                let v = (2.0 * r() - 1.0) * scale * 10f64.powf(4.0 * r() - 2.0);
                if r() < 0.1 {
                    0.0
                } else {
                    v
                }
            })
            .collect();
        let a = DMatrix::from_row_slice(1, n, &row);
        let svd = a.singular_values().max();
        assert_eq!(spectral_norm(&a).to_bits(), svd.to_bits(), "{row:?}");
    }
}

/// The split evaluation of the line search: value then gradient gives `rho`'s bits, and a
/// gradient after a T where K(T) is not positive definite is zero, never the previous T's.
#[test]
fn rho_value_then_grad_is_rho_and_never_stale() {
    let m = net(1, &[2, 10, 10, 1]);
    let sdp = LipSdp::new(&m);
    let (_, t) = lipsdp_multipliers(&m).expect("a certificate");
    let mut ws = DenseWork::default();
    let (l, f, g) = sdp
        .rho(&t, 1e-3, &mut ws)
        .expect("K ≻ 0 at the certified T");
    let mut ws2 = DenseWork::default();
    let (l2, f2) = sdp.rho_value(&t, 1e-3, &mut ws2).expect("the same T");
    let g2 = sdp.rho_grad(&mut ws2);
    assert_eq!((l.to_bits(), f.to_bits()), (l2.to_bits(), f2.to_bits()));
    let bits = |g: &[f64]| g.iter().map(|v| v.to_bits()).collect::<Vec<_>>();
    assert_eq!(bits(&g), bits(&g2));
    assert!(g.iter().any(|v| *v != 0.0));
    // Tiny multipliers: the last block 2T − W̃ᵀW̃ is indefinite.
    let tiny = vec![1e-12; t.len()];
    assert!(sdp.rho_value(&tiny, 1e-3, &mut ws2).is_none());
    assert!(sdp.rho_grad(&mut ws2).iter().all(|v| *v == 0.0));
}
