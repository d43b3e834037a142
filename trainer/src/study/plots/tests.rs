//! The plot helpers: box-plot quartiles, tick labels, the viridis map, and PNG
//! rasterisation with the embedded font, the axis names of an expression plant.

use super::*;

#[test]
fn five_numbers_interpolate_quartiles() {
    assert_eq!(
        five_numbers(&[4.0, 0.0, 2.0, 1.0, 3.0, f64::NAN]),
        Some([0.0, 1.0, 2.0, 3.0, 4.0])
    );
    assert_eq!(five_numbers(&[1.0, 2.0]), Some([1.0, 1.25, 1.5, 1.75, 2.0]));
    assert_eq!(five_numbers(&[f64::NAN]), None);
}

#[test]
fn tick_labels_have_no_negative_zero() {
    let f = tick_fmt(2.0);
    assert_eq!(f(&-0.00001), "0.0");
    assert_eq!(f(&-0.25), "-0.2");
    assert_eq!(tick_fmt(30.0)(&-4.0), "-4");
    assert_eq!(tick_fmt(0.05)(&0.0123), "0.012");
}

#[test]
fn viridis_ends_and_clamps() {
    assert_eq!(viridis(0.0), RGBColor(68, 1, 84));
    assert_eq!(viridis(1.0), RGBColor(253, 231, 37));
    assert_eq!(viridis(2.0), viridis(1.0));
    assert_eq!(viridis(f64::NAN), viridis(0.0));
}

/// Text is rasterised with the embedded font: an SVG holding only text renders dark
/// pixels, and the PNG has the SVG's size × the scale.
#[test]
fn text_renders_with_the_embedded_font() {
    let svg = r#"<svg width="120" height="40" viewBox="0 0 120 40" xmlns="http://www.w3.org/2000/svg"><text x="5" y="28" font-family="sans-serif" font-size="24">κ x₁ 1.5</text></svg>"#;
    let png = to_png("t", svg, 2.0).unwrap();
    let pix = resvg::tiny_skia::Pixmap::decode_png(&png).unwrap();
    assert_eq!((pix.width(), pix.height()), (240, 80));
    let dark = pix.pixels().iter().filter(|p| p.red() < 100).count();
    assert!(dark > 200, "{dark} dark pixels: no text drawn");
    assert!(to_png("t", "<svg", 1.0).is_err());
}

#[test]
fn axis_names_of_expression_plants_are_their_names_with_units() {
    let path = concat!(env!("CARGO_MANIFEST_DIR"), "/../configs/pendulum_ode.toml");
    let cfg = crate::problem::ProblemConfig::load(std::path::Path::new(path)).unwrap();
    let (x, u) = axis_names(&cfg.system);
    assert_eq!(x, ["theta [rad]", "omega [rad/s]"]);
    assert_eq!(u, ["u [N*m]"]);
    assert_eq!(input_unit(&cfg.system), "[N*m]");
}

fn load_config(name: &str) -> crate::problem::ProblemConfig {
    let path =
        std::path::PathBuf::from(concat!(env!("CARGO_MANIFEST_DIR"), "/../configs/")).join(name);
    crate::problem::ProblemConfig::load(&path).unwrap()
}

/// A training set of `nx` states with the same Jacobian `jac` (nu × nx) at every point, one
/// of them marked degenerate with a huge Jacobian that must be ignored.
fn train_with_jacobian(nx: usize, nu: usize, jac: &[f64]) -> crate::learn::train::TrainSet {
    let mut t = crate::learn::train::TrainSet {
        nx,
        nu,
        ..Default::default()
    };
    for k in 0..5 {
        t.x.extend(vec![0.1 * k as f64; nx]);
        t.u.extend(vec![0.0; nu]);
        t.du.extend(jac);
        t.use_jac.push(true);
    }
    t.x.extend(vec![0.0; nx]);
    t.u.extend(vec![0.0; nu]);
    t.du.extend(vec![1e9; nu * nx]);
    t.use_jac.push(false);
    t
}

#[test]
fn slice_axes_are_the_two_states_along_which_kappa_changes_most() {
    // Cart-pole (x, x_dot, theta, theta_dot), X widths (3, 3, 0.3, 2): |∂κ/∂x_i|·width =
    // (3, 1.5, 6, 2) → theta and x, in increasing order.
    let cfg = load_config("cartpole_public.toml");
    let t = train_with_jacobian(4, 1, &[1.0, 0.5, 20.0, 1.0]);
    let s = sensitivity_spread(&cfg, &t);
    for (a, b) in s.iter().zip([3.0, 1.5, 6.0, 2.0]) {
        assert!((a - b).abs() < 1e-12, "{s:?}");
    }
    assert_eq!(slice_axes(&cfg, &t), [0, 2]);
    // Two inputs: the column norms count. Quadrotor widths (2, 2, 1, 2, 2, 2).
    let cfg = load_config("planar_quadrotor.toml");
    let mut jac = vec![0.1; 12];
    jac[4] = 3.0; // ∂u1/∂z_dot
    jac[6 + 4] = 4.0; // ∂u2/∂z_dot: column norm 5, × 2
    jac[6 + 2] = 9.0; // ∂u2/∂theta, × 1
    let t = train_with_jacobian(6, 2, &jac);
    assert_eq!(slice_axes(&cfg, &t), [2, 4]);
    // nx = 2: the whole X, whatever the Jacobians.
    let cfg = load_config("pendulum_ode.toml");
    assert_eq!(
        slice_axes(&cfg, &train_with_jacobian(2, 1, &[0.0, 1.0])),
        [0, 1]
    );
}

#[test]
fn slice_base_is_the_setpoint_clamped_into_x() {
    let mut cfg = load_config("planar_quadrotor.toml");
    assert_eq!(slice_base(&cfg), vec![0.0; 6]);
    cfg.domain.lo[1] = 0.5;
    cfg.domain.hi[3] = -0.25;
    assert_eq!(slice_base(&cfg), vec![0.0, 0.5, 0.0, -0.25, 0.0, 0.0]);
}

#[test]
fn error_grid_of_a_slice_spans_the_chosen_axes() {
    let cfg = load_config("cartpole_public.toml");
    let t = train_with_jacobian(4, 1, &[1.0, 0.5, 20.0, 1.0]);
    let mlp = crate::learn::mlp::Mlp::new(
        &[4, 3, 1],
        crate::learn::mlp::Activation::Tanh,
        0,
        &cfg.domain.lo,
        &cfg.domain.hi,
        &cfg.ocp.u_lo,
        &cfg.ocp.u_hi,
    );
    let g = ErrorGrid::label(&cfg, &mlp, [3, 2], slice_axes(&cfg, &t));
    assert_eq!(g.axes, [0, 2]);
    assert_eq!((g.lo, g.hi), ([-1.5, -0.15], [1.5, 0.15]));
    assert_eq!(g.err.len(), 6);
    assert!(g.err.iter().all(|e| e.is_finite()), "{:?}", g.err);
}

#[test]
fn eps_map_of_nx_above_two_draws_the_cells_its_slice_cuts() {
    use crate::certify::refine::CellView;
    // dc_motor: 3 states, X = lo..hi; a 2 × 2 × 2 grid of cells split at each axis' middle.
    let cfg = load_config("dc_motor.toml");
    let (lo, hi) = (&cfg.domain.lo, &cfg.domain.hi);
    let mid: Vec<f64> = lo.iter().zip(hi).map(|(a, b)| 0.5 * (a + b)).collect();
    let mut cells = Vec::new();
    for c in 0..8usize {
        let pick = |k: usize| {
            if c >> k & 1 == 0 {
                (lo[k], mid[k])
            } else {
                (mid[k], hi[k])
            }
        };
        cells.push(CellView {
            lo: (0..3).map(|k| pick(k).0).collect(),
            hi: (0..3).map(|k| pick(k).1).collect(),
            eps: 0.1 * (c + 1) as f64,
            binding: 0,
        });
    }
    // κ changes most along axes 0 and 2: the slice holds axis 1 at the setpoint (clamped).
    let base = slice_base(&cfg)[1];
    let fig = eps_map(&cfg, &cells, 0.5, &[3.0, 0.1, 2.0]).unwrap();
    let cut = cells
        .iter()
        .filter(|c| c.lo[1] <= base && (base < c.hi[1] || c.hi[1] >= hi[1]))
        .count();
    assert!(cut > 0 && cut < 8, "{cut}");
    assert!(
        fig.caption
            .contains(&format!("of the {cut} cells the slice cuts"))
            && fig.caption.contains("(8 cells in X)")
            && fig.caption.contains(&format!(" = {base}")),
        "{}",
        fig.caption
    );
    let names = axis_names(&cfg.system).0;
    assert!(fig.svg.contains(names[0].as_str()) && fig.svg.contains(names[2].as_str()));
    // The largest ε_C of all cells is named even when the slice misses its cell.
    assert!(
        fig.caption.contains("max over all 8 cells 0.8000"),
        "{}",
        fig.caption
    );
    // nx = 2: every cell, no slice.
    let cfg2 = load_config("pendulum_ode.toml");
    let two: Vec<CellView> = cells
        .iter()
        .map(|c| CellView {
            lo: c.lo[..2].to_vec(),
            hi: c.hi[..2].to_vec(),
            ..c.clone()
        })
        .collect();
    let fig = eps_map(&cfg2, &two, 0.5, &[]).unwrap();
    assert!(fig.caption.contains("each of the 8 cells") && !fig.caption.contains("slice"));
}

#[test]
fn refine_rounds_curve_keeps_the_smallest_eps_so_far() {
    use crate::certify::refine::RoundLog;
    let eps = [39.6, 20.1, 11.4, 8.6, 5.6, 6.2, 8.5, 5.6, 3.2, 8.3, 0.7497];
    let log: Vec<RoundLog> = eps
        .iter()
        .enumerate()
        .map(|(k, &e)| RoundLog {
            round: k,
            solves: 100 * (k + 1),
            cells: 10 * (k + 1),
            cells_ok: k,
            eps: e,
            eps_d: 0.5 * e.min(5.0),
            second_order: 0,
            seconds: 0.1,
        })
        .collect();
    let best = best_so_far(&log);
    assert_eq!(
        best,
        [39.6, 20.1, 11.4, 8.6, 5.6, 5.6, 5.6, 5.6, 3.2, 3.2, 0.7497]
    );
    assert!(best.windows(2).all(|w| w[1] <= w[0]));
    let fig = refine_rounds(&log, 0.75).unwrap();
    assert!(fig.svg.contains("smallest certified ε so far"), "legend");
    assert!(fig.caption.contains("11 rounds") && fig.caption.contains("0.7497"));
    assert!(to_png(fig.name, &fig.svg, 1.0).is_ok());
    // An infinite ε (a failed corner) is not drawn; no finite round at all is an error.
    let mut inf = log.clone();
    inf[3].eps = f64::INFINITY;
    assert!(refine_rounds(&inf, 0.75).is_ok());
    assert!(refine_rounds(&[], 0.75).is_err());
}
