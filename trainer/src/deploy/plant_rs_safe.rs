//! `plant_rs_safe`: the complete `controller_core::safe::Plant` implementation of a problem
//! as `no_std` f32 Rust ([`safe_plant_rs`]): the dynamics of [`super::plant_rs::plant_rs`],
//! the OCP of [`super::plant_rs::ocp_rs`], and the terminal ingredients of the trainer's
//! terminal design ([`crate::robust::terminal`]), with the generated type `SafePlant`.
//!
//! ```text
//! g_k(x, u) = path constraints on inputs only (k = 0: the measured state is not constrained),
//!             max(g_X(x), every path constraint) (k ≥ 1)
//! g_N(x)    = max(g_X(x), terminal constraints, ((x − x_r)ᵀP_f(x − x_r) − α) / α)   X_f
//! κ_f(x)    = u_r + K (x − x_r)                                       terminal controller
//! decrease: V_f(F(x, κ_f(x))) − V_f(x) ≤ −ℓ(x, κ_f(x))  on X_f
//! ```
//! P_f, α, K, x_r, u_r are ([`TerminalSource`]):
//! - the terminal region of `robust::design::design(cfg)` (the ancillary LQR's Riccati
//!   matrix and gain) when it has one; V_f is then the OCP's `ocp.p`, the decrease condition
//!   is checked for it on [`DECREASE_SAMPLES`] seeded points of X_f with the f64 model and
//!   stated in the generated `TERMINAL_DECREASE`: `"sampled"` when every sample satisfies it,
//!   `"not established"` otherwise; the invariance tier (`TERMINAL_INVARIANCE`) is the
//!   design's (`proven` for exact or vertex bounds of ρ_f, else `sampled`);
//! - otherwise the nominal terminal ingredients (`robust::terminal_nominal`), whose level was
//!   chosen so that the decrease holds on its samples: both tiers `"sampled"`, and V_f (the
//!   generated `P`, used by `terminal_cost`) is *their* P_f — the matrix the decrease was
//!   checked for, which may differ from `ocp.p`.
//!
//! Neither is ever `"proven"` for the decrease: no bound over the whole set is computed.
//! Without either the generation is refused naming the key `robust`. Stage-dependent bounds
//! (`ocp.stages`) are refused by `ocp_rs`.

use super::plant_rs::{ocp_rs, ocp_rs_with, plant_model, plant_rs, PlantRsError};
use super::plant_rs_margin::{estimate_margins, MarginEstimate, FACTOR, MARGIN_STATES};
use crate::problem::model::Discrete;
use crate::problem::ProblemConfig;
use crate::robust::terminal::TerminalRegion;
use crate::robust::terminal_nominal::{nominal_terminal, NominalTerminal, NOMINAL_SAMPLES};
use std::fmt::Write as _;

/// Points of X_f on which the decrease condition is checked.
pub const DECREASE_SAMPLES: usize = 10_000;

/// The generated source and what it rests on.
#[derive(Debug, Clone)]
pub struct SafePlantRs {
    /// The Rust source (needs the crates `libm` and `controller_core`).
    pub source: String,
    /// The terminal ingredients used.
    pub terminal: TerminalSource,
    /// The decrease condition's tier: `"sampled"` or `"not established"`.
    pub decrease: &'static str,
    /// The largest V_f(F(x, κ_f)) − V_f(x) + ℓ(x, κ_f) over the samples (≤ 0: holds).
    pub decrease_worst: f64,
    /// The online check's margins written as `MARGINS` (estimated, `plant_rs_margin`).
    pub margins: MarginEstimate,
    /// K, written as `K_F` (nu × nx).
    pub k: Vec<Vec<f64>>,
    /// P_f of the terminal set, written as `P_F` (nx × nx).
    pub p_f: Vec<Vec<f64>>,
}

/// The decrease condition on `samples` seeded points of X_f (uniform in the ball of the
/// P_f-norm through a Cholesky factor): the largest V_f(x⁺) − V_f(x) + ℓ(x, κ_f(x)).
pub fn decrease_check(
    cfg: &ProblemConfig,
    t: &TerminalRegion,
    k: &[Vec<f64>],
    p_f: &[Vec<f64>],
    samples: usize,
) -> f64 {
    let (nx, nu) = (t.x_ref.len(), t.u_ref.len());
    let pf = nalgebra::DMatrix::from_fn(nx, nx, |i, j| p_f[i][j]);
    let Some(ch) = pf.cholesky() else {
        return f64::INFINITY;
    };
    // x − x_r = L⁻ᵀ w with ‖w‖₂ ≤ √α  ⇒  (x − x_r)ᵀP_f(x − x_r) = ‖w‖² ≤ α.
    let lt = ch.l().transpose();
    let (q, r, p) = (cfg.q(), cfg.r(), cfg.p());
    let quad = |m: &nalgebra::DMatrix<f64>, d: &[f64]| {
        let v = nalgebra::DVector::from_column_slice(d);
        (v.transpose() * m * &v)[(0, 0)]
    };
    let model = Discrete::new(cfg.system.clone(), cfg.ocp.ts, cfg.ocp.rk4_substeps);
    let mut seed = 0x5afe_u64;
    let mut next = || {
        seed ^= seed << 13;
        seed ^= seed >> 7;
        seed ^= seed << 17;
        (seed >> 11) as f64 / (1u64 << 53) as f64
    };
    let mut worst = f64::NEG_INFINITY;
    let mut xp = vec![0.0; nx];
    for _ in 0..samples {
        let mut w: Vec<f64> = (0..nx).map(|_| 2.0 * next() - 1.0).collect();
        let norm = w.iter().map(|v| v * v).sum::<f64>().sqrt().max(1e-300);
        let rad = t.alpha.sqrt() * next().powf(1.0 / nx as f64);
        w.iter_mut().for_each(|v| *v *= rad / norm);
        let Some(d) = lt
            .clone()
            .solve_upper_triangular(&nalgebra::DVector::from_vec(w))
        else {
            return f64::INFINITY;
        };
        let x: Vec<f64> = (0..nx).map(|i| t.x_ref[i] + d[i]).collect();
        let u: Vec<f64> = (0..nu)
            .map(|j| t.u_ref[j] + (0..nx).map(|i| k[j][i] * d[i]).sum::<f64>())
            .collect();
        model.step(&x, &u, &mut xp);
        let dx: Vec<f64> = d.iter().copied().collect();
        let du: Vec<f64> = (0..nu).map(|j| u[j] - t.u_ref[j]).collect();
        let dp: Vec<f64> = (0..nx).map(|i| xp[i] - t.x_ref[i]).collect();
        let g = quad(&p, &dp) - quad(&p, &dx) + quad(&q, &dx) + quad(&r, &du);
        // A NaN sample makes the result NaN (the condition then counts as not established).
        worst = if g.is_nan() || worst.is_nan() {
            f64::NAN
        } else {
            worst.max(g)
        };
    }
    worst
}

/// The terminal ingredients written into the generated plant.
#[derive(Debug, Clone)]
pub enum TerminalSource {
    /// The robust design's terminal region (`robust::terminal`), with its tube's K and P.
    Robust(TerminalRegion),
    /// The nominal terminal ingredients (`robust::terminal_nominal`): the robust design has
    /// no region (or fails).
    Nominal(NominalTerminal),
}

impl TerminalSource {
    /// The level α.
    pub fn alpha(&self) -> f64 {
        match self {
            TerminalSource::Robust(t) => t.alpha,
            TerminalSource::Nominal(t) => t.alpha,
        }
    }
}

impl SafePlantRs {
    /// The invariance tier of the terminal set written (`TERMINAL_INVARIANCE`): `"proven"`
    /// for a robust design's region with an exact or vertex bound, else `"sampled"`.
    pub fn invariance(&self) -> &'static str {
        match &self.terminal {
            TerminalSource::Robust(t) if t.proven() => "proven",
            _ => "sampled",
        }
    }
}

/// The full generated plant of `cfg` (module doc): dynamics, OCP, terminal ingredients and
/// `impl controller_core::safe::Plant<NX, NU> for SafePlant`.
pub fn safe_plant_rs(cfg: &ProblemConfig) -> Result<SafePlantRs, PlantRsError> {
    let model = plant_model(&cfg.system)?;
    let design = crate::robust::design::design(cfg);
    let robust = match &design {
        Ok(d) => d.terminal.clone().map(|t| (t, d)),
        Err(_) => None,
    };
    let mut out = plant_rs(&cfg.name, &model, cfg.ocp.ts, cfg.ocp.rk4_substeps);
    out.push('\n');
    let (k, p_f, worst, decrease, invariance, source, head) = match robust {
        Some((t, d)) => {
            let (k, p_f) = (d.tube.k.clone(), d.tube.p.clone());
            let worst = decrease_check(cfg, &t, &k, &p_f, DECREASE_SAMPLES);
            let decrease = if worst <= 0.0 {
                "sampled"
            } else {
                "not established"
            };
            let invariance = if t.proven() { "proven" } else { "sampled" };
            out.push_str(&ocp_rs(cfg)?);
            let head = format!(
                "the terminal region of the trainer's robust design\n\
                 // (robust::terminal; LQR r-scale {:?}, rho_f = {:e}, check {:?}).",
                d.tube.lqr_r_scale, t.rho_local, t.check
            );
            (
                k,
                p_f,
                worst,
                decrease,
                invariance,
                TerminalSource::Robust(t),
                head,
            )
        }
        None => {
            let why = match &design {
                Ok(_) => "the robust design's local feedback admits no radius".to_string(),
                Err(e) => format!("the robust design fails: {e}"),
            };
            let t = nominal_terminal(cfg, NOMINAL_SAMPLES).ok_or_else(|| {
                PlantRsError::NoTerminal(format!(
                    "problem `{}`: {why}, and no nominal terminal level passes the decrease \
                     condition on {NOMINAL_SAMPLES} points (robust::terminal_nominal)",
                    cfg.name
                ))
            })?;
            out.push_str(&ocp_rs_with(cfg, Some(&t.p))?);
            let head = format!(
                "the nominal terminal ingredients (robust::terminal_nominal;\n\
                 // {why}): P_f = {:?}, V_f = P_f (the P above).",
                t.cost
            );
            let (k, p_f, worst) = (t.k.clone(), t.p.clone(), t.decrease_worst);
            (
                k,
                p_f,
                worst,
                "sampled",
                "sampled",
                TerminalSource::Nominal(t),
                head,
            )
        }
    };
    let alpha = source.alpha();
    let _ = writeln!(out, "\n// Terminal ingredients: {head}");
    let _ = writeln!(
        out,
        "/// Level α of the terminal set (x − x_r)ᵀP_f(x − x_r) ≤ α.\npub const ALPHA: f32 = {};",
        super::plant_rs::lit(alpha)
    );
    let rows = |m: &[Vec<f64>]| {
        m.iter()
            .map(|r| {
                let v: Vec<String> = r.iter().map(|c| super::plant_rs::lit(*c)).collect();
                format!("[{}]", v.join(", "))
            })
            .collect::<Vec<_>>()
            .join(", ")
    };
    let (nx, nu) = (cfg.system.nx(), cfg.system.nu());
    let _ = writeln!(
        out,
        "/// P_f: the terminal set's matrix.\n\
         pub const P_F: [[f32; {nx}]; {nx}] = [{}];",
        rows(&p_f)
    );
    let _ = writeln!(
        out,
        "/// K: the terminal controller's gain, κ_f(x) = u_r + K(x − x_r).\n\
         pub const K_F: [[f32; {nx}]; {nu}] = [{}];",
        rows(&k)
    );
    let samples = match &source {
        TerminalSource::Robust(_) => DECREASE_SAMPLES,
        TerminalSource::Nominal(t) => t.samples,
    };
    let _ = writeln!(
        out,
        "/// Invariance of X_f under κ_f: \"proven\" or \"sampled\".\n\
         pub const TERMINAL_INVARIANCE: &str = \"{invariance}\";\n\
         /// V_f(F(x, κ_f)) − V_f(x) ≤ −ℓ(x, κ_f) on X_f for the V_f of `terminal_cost`: \"sampled\" \
         ({samples} seeded points, worst {worst:e}) or \"not established\".\n\
         pub const TERMINAL_DECREASE: &str = \"{decrease}\";"
    );
    let (xr, ur) = match &source {
        TerminalSource::Robust(t) => (t.x_ref.clone(), t.u_ref.clone()),
        TerminalSource::Nominal(t) => (t.x_ref.clone(), t.u_ref.clone()),
    };
    let m = estimate_margins(cfg, &model, (&xr, &ur, &k, &p_f, alpha), MARGIN_STATES);
    let _ = writeln!(
        out,
        "/// The online check's margins — ESTIMATED, not a bound (deploy::plant_rs_margin): \
         {FACTOR} × the largest\n\
         /// f32-vs-f64 difference measured over {MARGIN_STATES} seeded {n}-step trajectories \
         from X ({full} stayed in the box)\n\
         /// under Π_U(κ_f + noise): state/constraint {:e} (normalised), terminal cost {:e} (/α).\n\
         pub const MARGINS: controller_core::safe::Margins = controller_core::safe::Margins {{\n    \
         stage: {},\n    terminal: {},\n}};",
        m.stage_diff,
        m.terminal_diff,
        super::plant_rs::lit(m.stage * (1.0 + 1e-6)),
        super::plant_rs::lit(m.terminal * (1.0 + 1e-6)),
        n = cfg.ocp.horizon,
        full = m.trajectories,
    );
    out.push_str(SAFE_FNS);
    Ok(SafePlantRs {
        source: out,
        terminal: source,
        decrease,
        decrease_worst: worst,
        margins: m,
        k,
        p_f,
    })
}

/// The terminal functions and the trait implementation (fixed text over the constants).
const SAFE_FNS: &str = "
/// κ_f(x) = u_r + K(x − x_r) (u_r = U_REF, x_r = X_REF).
pub fn terminal_input(x: &[f32; NX]) -> [f32; NU] {
    let d = diff(x, &X_REF);
    let mut u = U_REF;
    for (u, row) in u.iter_mut().zip(&K_F) {
        for (k, d) in row.iter().zip(&d) {
            *u += *k * *d;
        }
    }
    u
}

/// max(a, b), NaN if either is NaN.
fn max_nan(a: f32, b: f32) -> f32 {
    if a.is_nan() || b.is_nan() {
        f32::NAN
    } else if a > b {
        a
    } else {
        b
    }
}

/// g_k: at k = 0 (the measured state) only the inputs-only path constraints, from k = 1 on
/// the state box and every path constraint (NaN for a NaN state).
pub fn stage_violation(k: usize, x: &[f32; NX], u: &[f32; NU]) -> f32 {
    let b = if k == 0 {
        if x.iter().any(|v| v.is_nan()) {
            f32::NAN
        } else {
            f32::NEG_INFINITY
        }
    } else {
        state_box_violation(x)
    };
    max_nan(b, path_violation(k, x, u))
}

/// g_N = max(state box, terminal constraints, ((x − x_r)ᵀP_f(x − x_r) − α)/α) (NaN for a
/// NaN state).
pub fn terminal_violation(x: &[f32; NX]) -> f32 {
    let b = max_nan(state_box_violation(x), terminal_constraint_violation(x));
    max_nan(b, (quad(&P_F, &diff(x, &X_REF)) - ALPHA) / ALPHA)
}

/// The generated plant as a `controller_core::safe::Plant`.
#[derive(Clone, Copy, Debug, Default, PartialEq)]
pub struct SafePlant;

impl controller_core::safe::Plant<NX, NU> for SafePlant {
    fn step(&self, x: &[f32; NX], u: &[f32; NU]) -> [f32; NX] {
        step(x, u)
    }
    fn stage_violation(&self, k: usize, x: &[f32; NX], u: &[f32; NU]) -> f32 {
        stage_violation(k, x, u)
    }
    fn terminal_violation(&self, x: &[f32; NX]) -> f32 {
        terminal_violation(x)
    }
    fn terminal_input(&self, x: &[f32; NX]) -> [f32; NU] {
        terminal_input(x)
    }
    fn project_input(&self, u: &[f32; NU]) -> [f32; NU] {
        project_input(u)
    }
    fn stage_cost(&self, x: &[f32; NX], u: &[f32; NU]) -> f32 {
        stage_cost(x, u)
    }
    fn terminal_cost(&self, x: &[f32; NX]) -> f32 {
        terminal_cost(x)
    }
}
";
