//! Tests of the QP detection and the critical-region proofs against independent MPC solves
//! (the SQP of `mpc::law`, which knows nothing of the affine laws).

use super::*;
use crate::certify::local::exact_cell_bound;
use crate::certify::netbounds::NetBounder;
use crate::learn::mlp::{Activation, Mlp};
use crate::mpc::law::MpcLaw;
use crate::mpc::sqp::SqpStatus;
use crate::rng::uniform;

fn load(name: &str) -> ProblemConfig {
    let path =
        std::path::PathBuf::from(concat!(env!("CARGO_MANIFEST_DIR"), "/../configs/")).join(name);
    let mut cfg = ProblemConfig::load(&path).unwrap();
    // The reference solves converge far below the comparison's 1e-9.
    cfg.solver.tol = 1e-10;
    cfg
}

/// The double integrator of `double_integrator_ode.toml` with its `[system]` table replaced.
fn with_system(system: &str) -> Result<QpCertifier, NotQp> {
    let text = std::fs::read_to_string(concat!(
        env!("CARGO_MANIFEST_DIR"),
        "/../configs/double_integrator_ode.toml"
    ))
    .unwrap();
    let start = text.find("[system]").unwrap();
    let end = text.find("[ocp]").unwrap();
    // The probed systems need not rest at the origin: the setpoint check is waived.
    let ocp = &text[end..].replacen("[ocp]\n", "[ocp]\nsetpoint_tol = 1e300\n", 1);
    let text = format!("{}{system}\n{}", &text[..start], ocp);
    QpCertifier::detect(&ProblemConfig::from_toml_str(&text, "test").unwrap())
}

/// κ(x) and the active set by the SQP (a converged hard solve).
fn solve(law: &mut MpcLaw, x: &[f64]) -> (Vec<f64>, Vec<usize>) {
    let (l, _) = law.solve(x, None);
    assert_eq!(l.status, SqpStatus::Converged, "at {x:?}");
    (l.u, l.active)
}

fn random_in(lo: &[f64], hi: &[f64], seed: u64, i: u64) -> Vec<f64> {
    (0..lo.len())
        .map(|k| lo[k] + (hi[k] - lo[k]) * uniform(seed, i, k as u64))
        .collect()
}

#[test]
fn qps_are_detected_and_everything_else_refused() {
    for name in [
        "double_integrator.toml",
        "double_integrator_ode.toml",
        "dc_motor.toml",
    ] {
        assert!(QpCertifier::detect(&load(name)).is_ok(), "{name}");
    }
    for name in [
        "pendulum.toml",
        "stiff_spring_setpoint.toml",
        "cartpole.toml",
    ] {
        assert!(QpCertifier::detect(&load(name)).is_err(), "{name}");
    }
    let affine = "[system]\nkind = \"discrete\"\nstates = [\"p\", \"v\"]\ninputs = [\"f\"]\n\
                  parameters = { h = 0.1 }\nnext = [\"p + h*v + 0.5*h^2*f\", \"v - (h*f)/-2 + 1\"]\n";
    assert!(with_system(affine).is_ok());
    let products = affine.replace("h*v +", "h*v*v +");
    let e = with_system(&products).unwrap_err();
    assert!(e.0.contains("not affine"), "{e}");
    let sine = affine.replace("v - (h*f)", "sin(v) - (h*f)");
    assert!(with_system(&sine).is_err());
    // A constant inside a nonlinear function stays constant: sin(h)·v is affine.
    let const_fn = affine.replace("v - (h*f)", "sin(h)*v - (h*f)");
    assert!(with_system(&const_fn).is_ok());
    let ode_product = "[system]\nkind = \"ode\"\nstates = [\"p\", \"v\"]\ninputs = [\"f\"]\n\
                       rhs = [\"v\", \"f*v\"]\n";
    assert!(with_system(ode_product).is_err());
}

#[test]
fn convexity_is_checked_exactly() {
    let m = |r: &[&[f64]]| DMatrix::from_fn(r.len(), r.len(), |i, j| r[i][j]);
    assert!(dominant(&m(&[&[1.0, 0.1], &[0.1, 1.0]]), true));
    assert!(!dominant(&m(&[&[1.0, 0.1], &[0.2, 1.0]]), false)); // not symmetric
    assert!(!dominant(&m(&[&[0.0]]), true));
    assert!(dominant(&m(&[&[0.0]]), false));
    // PSD but not diagonally dominant: refused (not proven), never accepted wrongly.
    assert!(!dominant(&m(&[&[1.0, 2.0], &[2.0, 4.0]]), false));
}

/// Inside boxes proven to lie in one critical region, the affine κ equals fresh SQP solves
/// to 1e-9, and the stated error bound holds.
#[test]
fn the_affine_law_matches_the_qp_solver_inside_proven_boxes() {
    // At least `want` of 40 random boxes (2 % of each side of X, the set active at the
    // centre as W, no disputed rows) lie in one critical region, so the comparison is not
    // vacuous. The double integrator's regions are thin (N = 20, many saturation patterns):
    // 6 of 40 boxes are proven there.
    for (name, want) in [("double_integrator.toml", 5), ("dc_motor.toml", 15)] {
        let cfg = load(name);
        let q = QpCertifier::detect(&cfg).unwrap();
        let mut law = MpcLaw::new(&cfg);
        let (lo, hi) = (&cfg.domain.lo, &cfg.domain.hi);
        let mut proven = 0;
        for b in 0..40u64 {
            let c = random_in(lo, hi, 91, b);
            let (_, set) = solve(&mut law, &c);
            let half: Vec<f64> = (0..lo.len()).map(|k| 0.01 * (hi[k] - lo[k])).collect();
            let blo: Vec<f64> = (0..lo.len()).map(|k| c[k] - half[k]).collect();
            let bhi: Vec<f64> = (0..lo.len()).map(|k| c[k] + half[k]).collect();
            let Some(laws) = q.prove(&blo, &bhi, &set, &[]) else {
                continue;
            };
            proven += 1;
            assert_eq!(laws.len(), 1);
            for i in 0..10u64 {
                let x = random_in(&blo, &bhi, 92 + b, i);
                let (u, _) = solve(&mut law, &x);
                let (ua, err) = q.kappa(&laws[0], &x);
                // The proven bound on the affine law's own rounding (loose: ‖M⁻¹‖∞ times
                // the f64 residual's rounding bound).
                assert!(err < 1e-6, "{name}: error bound {err}");
                for j in 0..u.len() {
                    assert!(
                        (u[j] - ua[j]).abs() < 1e-9,
                        "{name} at {x:?}: SQP {} vs affine {}",
                        u[j],
                        ua[j]
                    );
                }
            }
        }
        assert!(proven >= want, "{name}: only {proven} of 40 boxes proven");
    }
}

/// A point on the boundary between two critical regions of the double integrator (found
/// by bisection along the position axis at velocity 0.3), with the active sets either side.
fn boundary(law: &mut MpcLaw) -> (f64, Vec<usize>, Vec<usize>) {
    let v = 0.3;
    let (mut a, mut b) = (0.0, 4.0);
    let (_, sa) = solve(law, &[a, v]);
    let (_, sb) = solve(law, &[b, v]);
    assert_ne!(sa, sb, "κ changes its active set along the axis");
    for _ in 0..60 {
        let m = 0.5 * (a + b);
        let (_, s) = solve(law, &[m, v]);
        if s == sa {
            a = m;
        } else {
            b = m;
        }
    }
    let (_, s_lo) = solve(law, &[a - 1e-3, v]);
    let (_, s_hi) = solve(law, &[b + 1e-3, v]);
    (0.5 * (a + b), s_lo, s_hi)
}

/// Corners sharing an active set cannot hide another region inside the box (critical
/// regions are convex), so the check is tested on a box that crosses a boundary directly:
/// with either side's set alone it is refused; with both (the disputed rows) it is proven,
/// and every interior solve is one of the laws.
#[test]
fn a_box_across_a_region_boundary_is_refused_by_one_law_and_covered_by_both() {
    let cfg = load("double_integrator.toml");
    let q = QpCertifier::detect(&cfg).unwrap();
    let mut law = MpcLaw::new(&cfg);
    let (p, s_lo, s_hi) = boundary(&mut law);
    let (lo, hi) = ([p - 0.01, 0.29], [p + 0.01, 0.31]);
    assert!(q.prove(&lo, &hi, &s_lo, &[]).is_none(), "left set accepted");
    assert!(
        q.prove(&lo, &hi, &s_hi, &[]).is_none(),
        "right set accepted"
    );
    // Either side alone on its own side is fine.
    assert!(q
        .prove(&[p - 0.02, 0.29], &[p - 0.01, 0.31], &s_lo, &[])
        .is_some());
    assert!(q
        .prove(&[p + 0.01, 0.29], &[p + 0.02, 0.31], &s_hi, &[])
        .is_some());
    let sets: Vec<Vec<usize>> = (0..4)
        .map(|c| {
            let x = [
                if c & 1 == 0 { lo[0] } else { hi[0] },
                if c & 2 == 0 { lo[1] } else { hi[1] },
            ];
            solve(&mut law, &x).1
        })
        .collect();
    let refs: Vec<Option<&[usize]>> = sets.iter().map(|s| Some(s.as_slice())).collect();
    let laws = q
        .prove_from_corners(&lo, &hi, &refs)
        .expect("the two regions cover the box");
    assert!(laws.len() >= 2);
    let mut used = vec![0; laws.len()];
    for i in 0..200u64 {
        let x = random_in(&lo, &hi, 5, i);
        let (u, _) = solve(&mut law, &x);
        let hit = laws
            .iter()
            .position(|l| (q.kappa(l, &x).0[0] - u[0]).abs() < 1e-9)
            .unwrap_or_else(|| panic!("κ({x:?}) = {} is none of the laws", u[0]));
        used[hit] += 1;
    }
    assert!(used.iter().filter(|&&n| n > 0).count() >= 2, "{used:?}");
    // A corner with an unknown active set (a failed solve) gives no candidate but takes
    // nothing from the proof; with no set known there is nothing to prove.
    let mut refs = refs;
    refs[0] = None;
    assert!(q.prove_from_corners(&lo, &hi, &refs).is_some());
    assert!(q.prove_from_corners(&lo, &hi, &[None; 4]).is_none());
}

/// The double integrator's QP certifier, its MPC law and a seeded 2-8-8-1 tanh net.
fn di_certifier_law_net() -> (QpCertifier, MpcLaw, Mlp) {
    let cfg = load("double_integrator.toml");
    let m = Mlp::new(
        &[2, 8, 8, 1],
        Activation::Tanh,
        11,
        &cfg.domain.lo,
        &cfg.domain.hi,
        &[-1.0],
        &[1.0],
    );
    (QpCertifier::detect(&cfg).unwrap(), MpcLaw::new(&cfg), m)
}

/// The exact cell bound is never exceeded by |κ − sat(κ_NN)| at sampled interior points
/// (κ by fresh SQP solves), on boxes inside one region and across a boundary.
#[test]
fn the_exact_cell_bound_holds_at_sampled_points() {
    let (q, mut law, m) = di_certifier_law_net();
    let nb = NetBounder::new(&m);
    let band = ([-1.0], [1.0]);
    let (p, _, _) = boundary(&mut law);
    let boxes = [
        ([p - 0.01, 0.29], [p + 0.01, 0.31]),
        ([0.1, -0.2], [0.3, -0.1]),
        ([-3.0, 0.5], [-2.8, 0.6]),
    ];
    let mut checked = 0;
    for (lo, hi) in boxes {
        let sets: Vec<Vec<usize>> = (0..4)
            .map(|c| {
                let x = [
                    if c & 1 == 0 { lo[0] } else { hi[0] },
                    if c & 2 == 0 { lo[1] } else { hi[1] },
                ];
                solve(&mut law, &x).1
            })
            .collect();
        let refs: Vec<Option<&[usize]>> = sets.iter().map(|s| Some(s.as_slice())).collect();
        let Some(laws) = q.prove_from_corners(&lo, &hi, &refs) else {
            continue;
        };
        let net_u: Vec<_> = (0..4)
            .map(|c| {
                nb.value_at(&[
                    if c & 1 == 0 { lo[0] } else { hi[0] },
                    if c & 2 == 0 { lo[1] } else { hi[1] },
                ])[0]
            })
            .collect();
        let b = exact_cell_bound(
            &lo,
            &hi,
            &q.pieces(&lo, &hi, &laws),
            &net_u,
            &nb.bounds(&lo, &hi),
            (&band.0, &band.1),
            &[],
        );
        assert!(b.exact && b.eps.is_finite());
        for i in 0..300u64 {
            let x = random_in(&lo, &hi, 17, i);
            let (u, _) = solve(&mut law, &x);
            let e = (u[0] - m.predict(&x)[0].clamp(-1.0, 1.0)).abs();
            assert!(e <= b.eps, "at {x:?}: |e| = {e} > ε_C = {}", b.eps);
        }
        checked += 1;
    }
    assert!(checked >= 2, "only {checked} boxes proven");
}

/// The vertices of [lo, hi] (bit k of the index: hi_k) and the SQP's active set at each.
fn corner_sets(law: &mut MpcLaw, lo: &[f64], hi: &[f64]) -> Vec<Vec<usize>> {
    QpCertifier::vertices(lo, hi)
        .iter()
        .map(|v| solve(law, v).1)
        .collect()
}

/// The region of a law ([`LawRegion`]): across a region boundary, each side's law is cut
/// to a box that still holds every sampled state where the SQP's solution is that law;
/// on a box wholly on one side, the other side's law is dropped (its region is proven to
/// miss the box) and the own law keeps the whole box.
#[test]
fn a_law_is_bounded_only_where_it_can_hold_and_dropped_where_it_cannot() {
    let cfg = load("double_integrator.toml");
    let q = QpCertifier::detect(&cfg).unwrap();
    let mut law = MpcLaw::new(&cfg);
    let (p, s_lo, s_hi) = boundary(&mut law);
    let (l_lo, l_hi) = (q.law(&s_lo).unwrap(), q.law(&s_hi).unwrap());
    // Wholly right of the boundary: the left law's region misses the box.
    let (blo, bhi) = ([p + 0.01, 0.29], [p + 0.02, 0.31]);
    assert!(q.law_region(&l_lo, &blo, &bhi).shrink(&blo, &bhi).is_none());
    let own = q.law_region(&l_hi, &blo, &bhi);
    assert_eq!(own.shrink(&blo, &bhi), Some((blo.to_vec(), bhi.to_vec())));
    // Across it: both kept, each cut, and each cut box holds its law's states.
    let (lo, hi) = ([p - 0.01, 0.29], [p + 0.01, 0.31]);
    let mut cut = 0;
    let mut boxes = Vec::new();
    for l in [&l_lo, &l_hi] {
        let (a, b) = q.law_region(l, &lo, &hi).shrink(&lo, &hi).expect("kept");
        assert!((0..2).all(|k| lo[k] <= a[k] && a[k] <= b[k] && b[k] <= hi[k]));
        cut += usize::from((0..2).any(|k| a[k] > lo[k] || b[k] < hi[k]));
        boxes.push((l.set.clone(), a, b));
    }
    assert_eq!(cut, 2, "{boxes:?}");
    let mut seen = [0; 2];
    for i in 0..400u64 {
        let x = random_in(&lo, &hi, 23, i);
        let (_, set) = solve(&mut law, &x);
        for (j, (s, a, b)) in boxes.iter().enumerate() {
            if *s == set {
                seen[j] += 1;
                assert!(
                    (0..2).all(|k| a[k] <= x[k] && x[k] <= b[k]),
                    "{x:?} has set {set:?} outside its law's box {a:?}..{b:?}"
                );
            }
        }
    }
    assert!(seen.iter().all(|&n| n > 0), "{seen:?}");
}

/// The restricted bound ([`QpCertifier::restricted_bound`]) holds against dense sampling
/// of the true QP solution over proven boxes (with and without bisection), and across a
/// region boundary it is below the bound of every law over the whole box.
#[test]
fn the_restricted_bound_holds_against_dense_sampling() {
    let (q, mut law, m) = di_certifier_law_net();
    let nb = NetBounder::new(&m);
    let band: (&[f64], &[f64]) = (&[-1.0], &[1.0]);
    let (p, _, _) = boundary(&mut law);
    let boxes = [
        ([p - 0.05, 0.25], [p + 0.05, 0.35]),
        ([p - 0.01, 0.29], [p + 0.01, 0.31]),
        ([-3.0, 0.5], [-2.8, 0.6]),
    ];
    let mut tighter = 0;
    for (lo, hi) in boxes {
        let sets = corner_sets(&mut law, &lo, &hi);
        let refs: Vec<Option<&[usize]>> = sets.iter().map(|s| Some(s.as_slice())).collect();
        let laws = q.prove_from_corners(&lo, &hi, &refs).expect("proven");
        // The largest error at a 60 × 60 grid of true solutions.
        let mut worst = 0.0f64;
        for i in 0..60 {
            for j in 0..60 {
                let x = [
                    lo[0] + (hi[0] - lo[0]) * i as f64 / 59.0,
                    lo[1] + (hi[1] - lo[1]) * j as f64 / 59.0,
                ];
                let (u, _) = solve(&mut law, &x);
                worst = worst.max((u[0] - m.predict(&x)[0].clamp(-1.0, 1.0)).abs());
            }
        }
        let whole = q.restricted_bound(&lo, &hi, &laws, &m, &nb, band, f64::INFINITY);
        let split = q.restricted_bound(&lo, &hi, &laws, &m, &nb, band, worst + 0.01);
        for b in [&whole, &split] {
            assert!(
                b.exact && b.eps >= worst,
                "{lo:?}: ε_C {} < sampled {worst}",
                b.eps
            );
        }
        assert!(split.eps <= whole.eps);
        let nu_c: Vec<_> = QpCertifier::vertices(&lo, &hi)
            .iter()
            .map(|v| nb.value_at(v)[0])
            .collect();
        let unrestricted = exact_cell_bound(
            &lo,
            &hi,
            &q.pieces(&lo, &hi, &laws),
            &nu_c,
            &nb.bounds(&lo, &hi),
            band,
            &[],
        );
        if laws.len() > 1 && split.eps < unrestricted.eps {
            tighter += 1;
        }
    }
    assert!(
        tighter >= 1,
        "the restriction never tightened a disputed box"
    );
}

/// A vertex on a degenerate region boundary of the double integrator (v₀ = −0.5: four
/// saturated inputs and a fifth exactly at its bound bring the velocity to −1, so the input
/// row and the velocity row are dependent): P_D's feasibility has a slack of the data's
/// rounding there, proven exactly; just inside the other region it is refuted.
#[test]
fn exact_witnesses_decide_degenerate_vertices() {
    let cfg = load("double_integrator.toml");
    let q = QpCertifier::detect(&cfg).unwrap();
    let mut law = MpcLaw::new(&cfg);
    let below = [2.375, -0.51];
    let (_, w) = solve(&mut law, &below);
    let l = q.law(&w).expect("W's law");
    let on = [2.375, -0.5];
    // D: the rows outside W that W's law makes (nearly) tight on the boundary.
    let (y, _) = l.eval(&on);
    let d: Vec<usize> = (0..q.n_rows())
        .filter(|r| w.binary_search(r).is_err())
        .filter(|&r| {
            let row = &q.rows[r];
            let dot: f64 = (0..row.len).map(|t| row.coef[t] * y[row.idx[t]]).sum();
            (row.rhs - dot).abs() < 1e-9
        })
        .collect();
    assert!(!d.is_empty(), "no row tight at {on:?}");
    let nz = q.nx + q.nu;
    let hint = |x: &[f64]| -> Vec<f64> {
        let (y, _) = l.eval(x);
        (0..q.horizon).map(|k| y[k * nz + q.nx]).collect()
    };
    assert!(q.exact_witness(&on, &w, &d, &hint(&on)));
    assert!(q.exact_witness(&below, &w, &d, &hint(&below)));
    let above = [2.375, -0.45];
    assert!(!q.exact_witness(&above, &w, &d, &hint(&above)));
    // The cell with its top edge on the boundary is proven.
    let (lo, hi) = ([2.3125, -0.515625], [2.375, -0.5]);
    let sets = corner_sets(&mut law, &lo, &hi);
    let refs: Vec<Option<&[usize]>> = sets.iter().map(|s| Some(s.as_slice())).collect();
    assert!(q.prove_from_corners(&lo, &hi, &refs).is_some());
}
