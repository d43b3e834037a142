//! The banded KKT system against the dense one: the banded LU on random banded matrices,
//! random systems on the real layouts of the shipped problems, active-set systems at real
//! solutions; singular matrices are flagged.

use super::*;
use crate::problem::ProblemConfig;
use crate::rng::uniform;

fn load(name: &str) -> ProblemConfig {
    let path =
        std::path::PathBuf::from(concat!(env!("CARGO_MANIFEST_DIR"), "/../configs/")).join(name);
    ProblemConfig::load(&path).unwrap()
}

#[test]
fn band_lu_matches_dense_on_random_banded_matrices() {
    for seed in 0..20u64 {
        let n = 5 + (seed as usize * 7) % 40;
        let (kl, ku) = (1 + seed as usize % 4, 1 + (seed as usize / 3) % 5);
        let mut lu = BandLu::default();
        lu.reset(n, kl, ku);
        let mut dense = DMatrix::<f64>::zeros(n, n);
        let mut c = 0u64;
        for i in 0..n {
            for j in i.saturating_sub(kl)..(i + ku + 1).min(n) {
                c += 1;
                // Zero diagonal in places, to force pivoting.
                let v = if i == j && i % 3 == 0 {
                    0.0
                } else {
                    uniform(seed, c, 0) - 0.5
                };
                assert!(lu.add(i, j, v));
                dense[(i, j)] = v;
            }
        }
        assert!(!lu.add(0, n - 1, 1.0) || n - 1 <= ku);
        let b: Vec<f64> = (0..n).map(|i| uniform(seed, i as u64, 1) - 0.5).collect();
        lu.factor();
        let mut x = b.clone();
        lu.solve_in_place(&mut x);
        let xd = dense.clone().lu().solve(&DVector::from_column_slice(&b));
        let Some(xd) = xd else { continue };
        let scale = xd.amax().max(1.0);
        for i in 0..n {
            assert!((x[i] - xd[i]).abs() <= 1e-9 * scale, "seed {seed} i {i}");
        }
    }
}

#[test]
fn band_lu_skips_only_exact_zeros() {
    // Sparse banded matrices (about half the band zero, zero diagonals to force pivoting):
    // the factorisation from the values' ends, and from the full band's ends (every entry
    // visited, as without the skipping), give the same bits when nonsingular.
    for seed in 0..20u64 {
        let n = 8 + (seed as usize * 5) % 40;
        let (kl, ku) = (2 + seed as usize % 4, 2 + (seed as usize / 3) % 5);
        let mut a = BandLu::default();
        a.reset(n, kl, ku);
        let mut c = 0u64;
        for i in 0..n {
            for j in i.saturating_sub(kl)..(i + ku + 1).min(n) {
                c += 1;
                let keep = uniform(seed, c, 2) < 0.5 || (i == j && i % 3 != 0);
                if keep {
                    assert!(a.add(i, j, uniform(seed, c, 0) - 0.5));
                }
            }
        }
        let mut full = a.clone();
        let ubw = kl + ku;
        let row_end: Vec<usize> = (0..n).map(|i| (i + ubw).min(n - 1)).collect();
        let col_end: Vec<usize> = (0..n).map(|j| (j + kl).min(n - 1)).collect();
        full.factor_with_ends(&row_end, &col_end);
        a.factor();
        assert_eq!(a.pivot_ratio.to_bits(), full.pivot_ratio.to_bits());
        if a.pivot_ratio == 0.0 {
            // Singular (a zero pivot): the solves' infinities and NaNs are not compared.
            continue;
        }
        let b: Vec<f64> = (0..n).map(|i| uniform(seed, i as u64, 1) - 0.5).collect();
        let (mut x, mut y) = (b.clone(), b.clone());
        a.solve_in_place(&mut x);
        full.solve_in_place(&mut y);
        let bits = |v: &[f64]| v.iter().map(|x| x.to_bits()).collect::<Vec<_>>();
        assert_eq!(bits(&x), bits(&y), "seed {seed}");
        let m = 3;
        let bm: Vec<f64> = (0..n * m)
            .map(|i| uniform(seed, i as u64, 3) - 0.5)
            .collect();
        let (mut xm, mut ym) = (bm.clone(), bm.clone());
        a.solve_many_in_place(&mut xm, m);
        full.solve_many_in_place(&mut ym, m);
        assert_eq!(bits(&xm), bits(&ym), "seed {seed}");
    }
}

#[test]
fn band_lu_flags_singular_matrix() {
    let mut lu = BandLu::default();
    lu.reset(4, 1, 1);
    for (i, j, v) in [
        (0, 0, 1.0),
        (0, 1, 2.0),
        (1, 0, 2.0),
        (1, 1, 4.0),
        (2, 2, 1.0),
    ] {
        lu.add(i, j, v);
    }
    lu.add(3, 3, 1.0);
    lu.factor();
    assert!(lu.pivot_ratio <= 1e-14, "{}", lu.pivot_ratio);
}

/// Random Hessians/Jacobians on the real layouts of all three configs (hard and soft),
/// with random active sets and row weights: banded and dense solves agree.
#[test]
fn banded_kkt_matches_dense_kkt() {
    for name in ["pendulum.toml", "cartpole.toml", "double_integrator.toml"] {
        let cfg = load(name);
        for soft in [false, true] {
            let ocp = Ocp::new(&cfg, soft);
            let (nx, nu, n) = (ocp.nx, ocp.nu, ocp.horizon);
            let nz = nx + nu;
            for seed in 0..6u64 {
                let mut c = 0u64;
                let mut rnd = || {
                    c += 1;
                    uniform(seed + 100, c, 7) - 0.5
                };
                let mut hess = vec![0.0; (n + 1) * nz * nz];
                for s in 0..=n {
                    for i in 0..nz {
                        for j in 0..=i {
                            let v = rnd() + if i == j { 2.0 } else { 0.0 };
                            hess[s * nz * nz + i * nz + j] = v;
                            hess[s * nz * nz + j * nz + i] = v;
                        }
                    }
                }
                let jac_x: Vec<f64> = (0..n * nx * nx).map(|_| rnd()).collect();
                let jac_u: Vec<f64> = (0..n * nx * nu).map(|_| rnd()).collect();
                // Active set: at most one row per odd stage (LICQ then holds generically: a
                // row at stage 2j+1 can be matched to u_2j (state) or u_2j+1 (input)).
                let stage = var_stages(&ocp);
                let mut active = Vec::new();
                let mut used = std::collections::HashSet::new();
                for (r, row) in ocp.rows.iter().enumerate() {
                    let st = stage[row.idx[0]];
                    if rnd() > 0.0 && st % 2 == 1 && used.insert(st) {
                        active.push(r);
                    }
                }
                let weights: Vec<f64> = (0..ocp.rows.len()).map(|_| rnd() + 0.5).collect();
                for w in [None, Some(&weights[..])] {
                    let act = if w.is_some() { vec![] } else { active.clone() };
                    let dense = dense_kkt_matrix(&ocp, &hess, &jac_x, &jac_u, &act, w);
                    let dim = dense.nrows();
                    let mut kkt = BandedKkt::new(KktLayout::new(&ocp, act.clone()));
                    assert!(kkt.layout.bandwidth() <= 4 * nz + 8, "{name}");
                    let ratio = kkt.factor(&ocp, &hess, &jac_x, &jac_u, w);
                    let b: Vec<f64> = (0..dim).map(|_| rnd()).collect();
                    let xd = dense.clone().lu().solve(&DVector::from_column_slice(&b));
                    let Some(xd) = xd else {
                        assert!(ratio <= 1e-10, "{name}: dense singular, banded not");
                        continue;
                    };
                    assert!(ratio > 1e-14, "{name} soft={soft}: ratio {ratio}");
                    let mut x = b.clone();
                    let mut scratch = Vec::new();
                    assert!(kkt.solve_in_place(&mut x, &mut scratch));
                    let scale = xd.amax().max(1.0);
                    for i in 0..dim {
                        assert!(
                            (x[i] - xd[i]).abs() <= 1e-8 * scale,
                            "{name} soft={soft} seed {seed}: x[{i}] {} vs {}",
                            x[i],
                            xd[i]
                        );
                    }
                }
            }
        }
    }
}

/// Active-set KKT systems at real solutions: the banded factorisation reproduces the
/// dense LU's sensitivities, and a doubly active bound pair is flagged singular.
#[test]
fn active_set_kkt_matches_dense_at_solutions() {
    use crate::mpc::sqp::SqpSolver;
    for name in ["pendulum.toml", "cartpole.toml", "double_integrator.toml"] {
        let cfg = load(name);
        for soft in [false, true] {
            let mut solver = SqpSolver::new(&cfg, soft);
            for i in 0..5u64 {
                let xs: Vec<f64> = (0..cfg.system.nx())
                    .map(|j| {
                        let (lo, hi) = (cfg.domain.lo[j], cfg.domain.hi[j]);
                        lo + (hi - lo) * uniform(3, i, j as u64)
                    })
                    .collect();
                let start = solver.cold_start(&xs);
                let r = solver.solve(&xs, start);
                if r.status != crate::mpc::sqp::SqpStatus::Converged {
                    continue;
                }
                let ocp = &solver.ocp;
                let p = &r.point;
                let active: Vec<usize> = (0..ocp.rows.len())
                    .filter(|&r| p.nu[r] > 1e-7 && ocp.rows[r].slack(&p.z) < 1e-7)
                    .collect();
                let kkt = solver.active_set_kkt(&xs, p, active.clone());
                let (nx, nu, n) = (ocp.nx, ocp.nu, ocp.horizon);
                let mut hess = vec![0.0; (n + 1) * (nx + nu) * (nx + nu)];
                let mut c = vec![0.0; ocp.n_eq];
                let mut jx = vec![0.0; n * nx * nx];
                let mut ju = vec![0.0; n * nx * nu];
                ocp.constraints(&p.z, &xs, &mut c, &mut jx, &mut ju);
                ocp.hessian_blocks(&p.z, &p.lam, &p.nu, &mut hess);
                let dense = dense_kkt_matrix(ocp, &hess, &jx, &ju, &active, None);
                let dim = dense.nrows();
                let mut rhs = DMatrix::zeros(dim, nx);
                for i in 0..nx {
                    rhs[(ocp.n_var + i, i)] = 1.0;
                }
                let sd = dense.lu().solve(&rhs).unwrap();
                let sb = kkt.solve_many(&rhs).unwrap();
                let scale = sd.amax().max(1.0);
                assert!(
                    (sd - sb).amax() <= 1e-8 * scale,
                    "{name} soft={soft} {xs:?}"
                );
                if let Some(&r0) = active.first() {
                    // Add the opposite bound of the same variable (if any) as active too.
                    let v = ocp.rows[r0].idx[0];
                    if let Some(r1) = (0..ocp.rows.len())
                        .find(|&r| r != r0 && ocp.rows[r].len == 1 && ocp.rows[r].idx[0] == v)
                    {
                        let k2 = solver.active_set_kkt(&xs, p, vec![r0, r1]);
                        assert!(k2.is_singular(), "{name}: ratio {}", k2.pivot_ratio);
                        assert!(k2.solve_many(&rhs).is_none());
                    }
                }
            }
        }
    }
}
