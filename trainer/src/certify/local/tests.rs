//! Tests of the local certificate: bounds against sampled errors of synthetic laws.

use super::*;
use crate::certify::netbounds::NetBounder;
use crate::learn::mlp::{Activation, Mlp, Workspace};
use crate::rng::uniform;

/// A smooth "MPC law" with exact derivatives: κ(x) = 3 sin(x₁) + x₁x₂ + 0.5 x₂².
fn smooth(x: &[f64]) -> (f64, [f64; 2]) {
    (
        3.0 * x[0].sin() + x[0] * x[1] + 0.5 * x[1] * x[1],
        [3.0 * x[0].cos() + x[1], x[0] + x[1]],
    )
}
/// A kinked law (an active-set change along x₁ + 0.3 x₂ = 0.2), saturated at ±2.
fn kinked(x: &[f64]) -> (f64, [f64; 2], u64) {
    let s = x[0] + 0.3 * x[1] - 0.2;
    let (v, g, p) = if s > 0.0 {
        (4.0 * s, [4.0, 1.2], 1)
    } else {
        (s, [1.0, 0.3], 0)
    };
    if v > 2.0 {
        (2.0, [0.0, 0.0], 2)
    } else if v < -2.0 {
        (-2.0, [0.0, 0.0], 3)
    } else {
        (v, g, p)
    }
}

fn net() -> Mlp {
    Mlp::new(
        &[2, 8, 8, 1],
        Activation::Tanh,
        3,
        &[-2.0, -2.0],
        &[2.0, 2.0],
        &[-2.0],
        &[2.0],
    )
}

/// A test law: x ↦ (κ, ∂κ/∂x, active-set id).
type Law = dyn Fn(&[f64]) -> (f64, [f64; 2], u64);

/// Bounds a cell of `law`; returns (bound, max sampled |e|).
fn check_cell(law: &Law, m: &Mlp, lo: [f64; 2], hi: [f64; 2], seed: u64) -> (CellBound, f64) {
    let nb = NetBounder::new(m);
    let band = ([-2.0], [2.0]);
    let mut us = Vec::new();
    let mut dus = Vec::new();
    let mut pieces = Vec::new();
    let mut net_u = Vec::new();
    for c in 0..4 {
        let x = [
            if c & 1 == 0 { lo[0] } else { hi[0] },
            if c & 2 == 0 { lo[1] } else { hi[1] },
        ];
        let (u, g, p) = law(&x);
        us.push([u]);
        dus.push(g);
        pieces.push(p);
        net_u.push(m.predict(&x)[0]);
    }
    let corners: Vec<Corner> = (0..4)
        .map(|c| Corner {
            u: &us[c],
            du: &dus[c],
            regular: true,
            piece: pieces[c],
        })
        .collect();
    let b = cell_bound(
        &lo,
        &hi,
        &corners,
        None,
        &Regional::default(),
        &net_u,
        &nb.bounds(&lo, &hi),
        (&band.0, &band.1),
        &LocalSettings::default(),
        &[],
    );
    let mut worst = 0.0f64;
    let mut ws = Workspace::default();
    for s in 0..400u64 {
        let x = [
            lo[0] + (hi[0] - lo[0]) * uniform(seed, s, 0),
            lo[1] + (hi[1] - lo[1]) * uniform(seed, s, 1),
        ];
        let (mut u, mut j) = ([0.0], [0.0; 2]);
        m.eval(&x, &mut u, &mut j, &mut ws);
        worst = worst.max((law(&x).0 - u[0].clamp(-2.0, 2.0)).abs());
    }
    (b, worst)
}

#[test]
fn bounds_hold_on_random_cells_of_smooth_and_kinked_laws() {
    let m = net();
    let sm = |x: &[f64]| {
        let (u, g) = smooth(x);
        (
            u.clamp(-2.0, 2.0),
            if u.abs() < 2.0 { g } else { [0.0; 2] },
            (u.abs() >= 2.0) as u64 * (1 + (u > 0.0) as u64),
        )
    };
    let mut second = 0;
    for (li, law) in [&sm as &Law, &kinked].into_iter().enumerate() {
        for cell in 0..300u64 {
            let c = [
                -1.8 + 3.6 * uniform(40 + li as u64, cell, 0),
                -1.8 + 3.6 * uniform(40 + li as u64, cell, 1),
            ];
            let w = [0.4, 0.1, 0.02][cell as usize % 3];
            let lo = [c[0] - w / 2.0, c[1] - w];
            let hi = [c[0] + w / 2.0, c[1] + w];
            let (b, worst) = check_cell(law, &m, lo, hi, cell);
            assert!(
                worst <= b.eps,
                "law {li} cell {lo:?}..{hi:?}: observed {worst} > bound {b:?}"
            );
            second += (b.form == Form::SecondOrder) as usize;
        }
    }
    assert!(
        second > 50,
        "the second-order form was used on {second} cells only"
    );
}

/// Centre, radius and height of the pocket of [`pocket`].
const POCKET: ([f64; 2], f64, f64) = ([0.23, 0.21], 0.15, 5.0);

/// A law with an interior pocket: the linear κ₀ = x₁ + 0.3x₂ (active set 0), and on the
/// disk |x − p| < ρ another active set (1) that lifts κ by a cone H·(1 − |x − p|/ρ),
/// touching neither the corners nor the edges of the cell [0, 0.4]². With `lift` false:
/// κ₀ everywhere, but the active set still reported (the corner data a code would see
/// if it used only the corners' values and sensitivities).
fn pocket_law(x: &[f64], lift: bool) -> (f64, [f64; 2], u64) {
    let ([p0, p1], rho, h) = POCKET;
    let d = ((x[0] - p0).powi(2) + (x[1] - p1).powi(2)).sqrt();
    let (mut u, mut g) = (x[0] + 0.3 * x[1], [1.0, 0.3]);
    if lift && d < rho {
        u += h * (1.0 - d / rho);
        if d > 0.0 {
            g[0] -= h / rho * (x[0] - p0) / d;
            g[1] -= h / rho * (x[1] - p1) / d;
        }
    }
    (u, g, (d < rho) as u64)
}

/// The pocket inside a cell: its corners (and edges) see only κ₀, so the cell's bound
/// equals that of κ₀ — the documented blind spot of corner data. One split, as the
/// refinement makes while ε_C is above its target, puts a corner into the pocket, and
/// then every child's bound covers the error sampled in it. In the child holding the
/// pocket's apex, the corner errors plus the network's part of the remainder alone are
/// exceeded by the samples: the bound must use the MPC's slope range on the cell (here
/// the pocket corner's sensitivity, which sees the cone's slope; the edge secants see
/// it too — a pocket corner with κ₀'s sensitivity would need the secants alone, not
/// tested here) and the change of active set (first-order form).
#[test]
fn a_pocket_inside_a_cell_is_covered_once_a_split_puts_a_corner_in_it() {
    let m = net();
    let pocket = |x: &[f64]| pocket_law(x, true);
    let flat = |x: &[f64]| pocket_law(x, false);
    let kappa0 = |x: &[f64]| (x[0] + 0.3 * x[1], [1.0, 0.3], 0u64);
    let (parent, worst_parent) = check_cell(&pocket, &m, [0.0, 0.0], [0.4, 0.4], 5);
    let (parent0, _) = check_cell(&kappa0, &m, [0.0, 0.0], [0.4, 0.4], 5);
    assert_eq!(parent, parent0, "corner data cannot see the pocket");
    eprintln!(
        "parent cell: bound {} vs sampled max {worst_parent}",
        parent.eps
    );
    for (lo, hi) in [
        ([0.0, 0.0], [0.2, 0.2]),
        ([0.2, 0.0], [0.4, 0.2]),
        ([0.0, 0.2], [0.2, 0.4]),
        ([0.2, 0.2], [0.4, 0.4]),
    ] {
        let (b, worst) = check_cell(&pocket, &m, lo, hi, 7);
        assert_eq!(b.form, Form::FirstOrder, "{lo:?}: the active set changes");
        assert!(
            worst <= b.eps,
            "child {lo:?}..{hi:?}: sampled {worst} > bound {b:?}"
        );
        // The network's part of the first-order remainder (κ₀'s secants equal its
        // sensitivities, the active set change forces the first-order form).
        let (b0, _) = check_cell(&flat, &m, lo, hi, 7);
        let corners_only = b.corner + b0.remainder + LABEL_TOL;
        eprintln!(
            "child {lo:?}: bound {} (corner {}, remainder {}), sampled {worst}, \
             corners only {corners_only}",
            b.eps, b.corner, b.remainder
        );
        if lo == [0.2, 0.2] {
            assert!(
                worst > corners_only,
                "the apex's child does not discriminate: sampled {worst} ≤ {corners_only}"
            );
        }
    }
}

#[test]
fn a_non_finite_network_gets_no_bound() {
    let mut m = net();
    let (lo, hi) = ([0.1, 0.1], [0.2, 0.2]);
    let (b, _) = check_cell(&kinked, &m, lo, hi, 3);
    assert!(b.eps.is_finite());
    m.layers[0].b[0] = f64::NAN;
    let (b, _) = check_cell(&kinked, &m, lo, hi, 3);
    assert!(b.eps.is_infinite() && b.corner.is_infinite());
}

#[test]
fn remainder_shrinks_quadratically_where_smooth_and_linearly_across_a_kink() {
    let m = net();
    let sm = |x: &[f64]| {
        let (u, g) = smooth(x);
        (u, g, 0u64)
    };
    let mut prev: Option<f64> = None;
    for e in 0..4 {
        let w = 0.2 / f64::powi(2.0, e);
        let (b, _) = check_cell(&sm, &m, [0.1, 0.1], [0.1 + w, 0.1 + w], 1);
        assert_eq!(b.form, Form::SecondOrder);
        if let Some(p) = prev {
            let ratio = p / b.remainder;
            assert!((3.5..4.5).contains(&ratio), "ratio {ratio}");
        }
        prev = Some(b.remainder);
    }
    // Across the kink (x₁ + 0.3x₂ = 0.2 through the cell centre): first order, ratio ≈ 2.
    let mut prev: Option<f64> = None;
    for e in 0..4 {
        let w = 0.2 / f64::powi(2.0, e);
        let (b, worst) = check_cell(
            &kinked,
            &m,
            [0.2 - w / 2.0, -w / 2.0],
            [0.2 + w / 2.0, w / 2.0],
            2,
        );
        assert_eq!(b.form, Form::FirstOrder);
        assert!(worst <= b.eps);
        if let Some(p) = prev {
            let ratio = p / b.remainder;
            assert!((1.8..2.2).contains(&ratio), "ratio {ratio}");
        }
        prev = Some(b.remainder);
    }
}

/// Bound of the cell [lo, hi] of `law` (corners only) with a given centre sample and
/// neighbourhood.
fn bound_with_extras(
    law: &Law,
    m: &Mlp,
    lo: [f64; 2],
    hi: [f64; 2],
    centre: Option<(f64, [f64; 2], u64)>,
    reg: &Regional,
    s: &LocalSettings,
) -> CellBound {
    let nb = NetBounder::new(m);
    let mut data = Vec::new();
    let mut net_u = Vec::new();
    for c in 0..4 {
        let x = [
            if c & 1 == 0 { lo[0] } else { hi[0] },
            if c & 2 == 0 { lo[1] } else { hi[1] },
        ];
        let (u, g, p) = law(&x);
        data.push(([u], g, p));
        net_u.push(m.predict(&x)[0]);
    }
    let corners: Vec<Corner> = data
        .iter()
        .map(|(u, g, p)| Corner {
            u,
            du: g,
            regular: true,
            piece: *p,
        })
        .collect();
    let cd = centre.map(|(u, g, p)| ([u], g, p));
    let cc = cd.as_ref().map(|(u, g, p)| Corner {
        u,
        du: g,
        regular: true,
        piece: *p,
    });
    cell_bound(
        &lo,
        &hi,
        &corners,
        cc.as_ref(),
        reg,
        &net_u,
        &nb.bounds(&lo, &hi),
        (&[-2.0], &[2.0]),
        s,
        &[],
    )
}

/// The regional floor: a cell whose corners agree (κ constant there, ∂κ = 0) gets no MPC
/// term from its corners, but a nonzero one once its neighbourhood varies — the same
/// bound as the network alone without the floor, a larger one with it, growing with c.
#[test]
fn the_floor_gives_a_cell_with_equal_corners_a_nonzero_mpc_term() {
    let m = net();
    let flat = |_: &[f64]| (1.0, [0.0, 0.0], 0u64);
    let (lo, hi) = ([0.1, 0.1], [0.3, 0.3]);
    let reg = Regional {
        spread: vec![3.0, 0.5],
        quotient: vec![15.0, 2.5],
    };
    let off = LocalSettings {
        floor: 0.0,
        ..Default::default()
    };
    let none = bound_with_extras(&flat, &m, lo, hi, None, &Regional::default(), &off);
    let ignored = bound_with_extras(&flat, &m, lo, hi, None, &reg, &off);
    assert_eq!(none, ignored, "floor 0: the neighbourhood changes nothing");
    let mut prev = none.remainder;
    for c in [0.25, 0.5, 1.0] {
        let s = LocalSettings {
            floor: c,
            ..Default::default()
        };
        let b = bound_with_extras(&flat, &m, lo, hi, None, &reg, &s);
        assert!(
            b.remainder > prev,
            "floor {c}: remainder {} not above {prev}",
            b.remainder
        );
        prev = b.remainder;
    }
}

/// The centre check: a smooth cell uses the second-order form when its solved centre has
/// the corners' active set and agrees with the curvature estimate, and falls back to the
/// first-order form when the centre is in another active set (a pocket at the centre) or
/// departs from the corners' interpolant by more than the estimate allows.
#[test]
fn the_second_order_form_needs_a_consistent_centre() {
    let m = net();
    let sm = |x: &[f64]| {
        let (u, g) = smooth(x);
        (u, g, 0u64)
    };
    let s = LocalSettings::default();
    let (lo, hi) = ([0.1, 0.1], [0.15, 0.15]);
    let c = [0.125, 0.125];
    let (uc, gc) = smooth(&c);
    let reg = Regional::default();
    let unchecked = bound_with_extras(&sm, &m, lo, hi, None, &reg, &s);
    assert_eq!(unchecked.form, Form::SecondOrder);
    let good = bound_with_extras(&sm, &m, lo, hi, Some((uc, gc, 0)), &reg, &s);
    assert_eq!(good.form, Form::SecondOrder, "the true centre agrees");
    let other_set = bound_with_extras(&sm, &m, lo, hi, Some((uc, gc, 9)), &reg, &s);
    assert_eq!(
        other_set.form,
        Form::FirstOrder,
        "another active set at the centre"
    );
    // A centre value off by 10× the interpolation error the estimate allows there.
    let mean: f64 = (0..4)
        .map(|k| {
            smooth(&[
                if k & 1 == 0 { lo[0] } else { hi[0] },
                if k & 2 == 0 { lo[1] } else { hi[1] },
            ])
            .0
        })
        .sum::<f64>()
        / 4.0;
    let allowed = (uc - mean).abs().max(1e-6) * 20.0;
    let off = bound_with_extras(&sm, &m, lo, hi, Some((mean + allowed, gc, 0)), &reg, &s);
    assert_eq!(
        off.form,
        Form::FirstOrder,
        "curvature inconsistent with the estimate"
    );
    assert!(off.eps >= good.eps);
}

/// The exact cell bound's label tolerance is the piece's verified error plus the radius of
/// the network's corner enclosures — no constant: a network equal to the piece up to
/// rounding gets ε_C of the order of those bounds (far below the solved labels'
/// [`LABEL_TOL`]), and a wide corner enclosure is counted in full.
#[test]
fn exact_cell_bound_uses_the_verified_errors_not_a_constant() {
    let (lo, hi) = ([0.0, 0.0], [0.1, 0.2]);
    let piece = ExactPiece {
        u: vec![0.5; 4],
        u_err: 1e-15,
        gain: vec![0.0, 0.0],
        gain_err: vec![0.0, 0.0],
    };
    let net = |r: f64| BoxBounds {
        value: vec![Iv {
            lo: 0.5 - r,
            hi: 0.5 + r,
        }],
        jac: vec![Iv { lo: 0.0, hi: 0.0 }; 2],
        hess_diag: None,
    };
    let band = ([-1.0], [1.0]);
    let corners = |r: f64| {
        vec![
            Iv {
                lo: 0.5 - r,
                hi: 0.5 + r
            };
            4
        ]
    };
    let tight = exact_cell_bound(
        &lo,
        &hi,
        std::slice::from_ref(&piece),
        &corners(1e-14),
        &net(1e-14),
        (&band.0, &band.1),
        &[],
    );
    assert!(tight.exact);
    assert!(
        // (0.5 ± 1e-14 is stored to within an ulp of 0.5: the radius is ≈ 1e-14)
        tight.eps >= 0.99 * (1e-14 + 1e-15) && tight.eps < 1e-12,
        "ε_C {} (LABEL_TOL is {LABEL_TOL})",
        tight.eps
    );
    let wide = exact_cell_bound(
        &lo,
        &hi,
        std::slice::from_ref(&piece),
        &corners(1e-3),
        &net(1e-3),
        (&band.0, &band.1),
        &[],
    );
    assert!(wide.eps >= 1e-3 && wide.eps < 1.1e-3, "ε_C {}", wide.eps);
    // A NaN enclosure gives no bound.
    let nan = exact_cell_bound(
        &lo,
        &hi,
        std::slice::from_ref(&piece),
        &[Iv {
            lo: f64::NAN,
            hi: 0.5,
        }; 4],
        &net(1e-14),
        (&band.0, &band.1),
        &[],
    );
    assert!(!nan.exact && nan.eps.is_infinite(), "{nan:?}");
}
