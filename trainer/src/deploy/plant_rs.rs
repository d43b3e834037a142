//! `plant_rs`: the plant's discrete map F(x, u) as `no_std` f32 Rust source, for the online
//! check of `controller_core::safe` (issue 41 §3; the dynamics part).
//!
//! ```text
//! ODE plant:      F(x, u) = Φ_h^M(x, u),  M = rk4_substeps, h = Ts/M, u held (zero-order hold)
//!   one sub-step: k1 = f(x), k2 = f(x + k1·(h/2)), k3 = f(x + k2·(h/2)), k4 = f(x + k3·h),
//!                 x ← x + (k1 + 2·k2 + 2·k3 + k4)·(h/6)           (the trainer's order, in f32)
//! discrete plant: F(x, u) = the `next` expressions
//! ```
//! f is the plant's instruction tape ([`ExprModel::tape`]) translated one instruction per
//! line into f32 (constants rounded to nearest, h/2, h, h/6 computed in f64 then rounded;
//! sin and cos from `controller_core::safe::fmath` (f32 only; NaN beyond |x| = 8192), the
//! other transcendental functions from `libm`'s f32 versions, `a^b = exp(b·log a)` as the tape).
//! Covered: the expression plants (`kind = "ode"` and `"discrete"`) and the built-in
//! cart-pole (through its expression form); the built-in pendulum and double integrator
//! and Rust-implemented (`custom`) plants are not (an error names the plant).
//!
//! The generated file defines `NX`, `NU`, `TS`, `SUBSTEPS`, `rhs` (an ODE's f, or a discrete
//! plant's F) and `step` (F); [`ocp_rs`] adds the OCP's costs, input projection and state
//! box (no expression constraints, no stage-dependent bounds); `plant_rs_safe` adds the
//! terminal ingredients and the `Plant` implementation. It needs the `libm` crate. Its difference from the trainer's
//! f64 model is measured by `tests/safe_plant.rs` (that is where the online check's margin
//! comes from; see that test's doc).

use crate::problem::model::expr::{self, ExprModel, Op};
use crate::problem::model::System;
use std::fmt::Write as _;

/// Why a plant cannot be generated as Rust.
#[derive(Debug, thiserror::Error)]
pub enum PlantRsError {
    /// The plant kind has no generator yet.
    #[error("system.kind = \"{0}\": no f32 Rust generator for this plant (expression plants and the cart-pole only)")]
    Unsupported(String),
    /// A part of the OCP has no generator yet.
    #[error("{0}: not generated as f32 Rust yet (the plain boxes, weights and setpoint only)")]
    UnsupportedOcp(String),
    /// The robust design gives no terminal region (or fails): the terminal ingredients of
    /// the generated plant are missing.
    #[error("robust: no terminal region for the generated plant: {0}")]
    NoTerminal(String),
    /// The cart-pole's expression form did not compile (a non-finite parameter).
    #[error("system: the cart-pole's expression form does not compile: {0}")]
    Compile(String),
}

/// The expression model of `system` that the generator translates.
pub fn plant_model(system: &System) -> Result<ExprModel, PlantRsError> {
    match system {
        System::Ode(_) | System::Discrete(_) => system
            .expr_model()
            .cloned()
            .ok_or_else(|| PlantRsError::Unsupported(system.name().to_string())),
        System::CartPole(c) => {
            expr::compile(&c.expressions(), false).map_err(|e| PlantRsError::Compile(e.to_string()))
        }
        _ => Err(PlantRsError::Unsupported(system.name().to_string())),
    }
}

/// An f64 constant as an f32 literal (rounded to nearest; non-finite ones by name).
pub(crate) fn lit(c: f64) -> String {
    let v = c as f32;
    if v.is_nan() {
        "f32::NAN".into()
    } else if v.is_infinite() {
        if v > 0.0 {
            "f32::INFINITY"
        } else {
            "f32::NEG_INFINITY"
        }
        .into()
    } else {
        format!("{v:?}_f32")
    }
}

/// One tape instruction as an f32 expression over the register array `r`.
fn instr(op: &Op) -> String {
    let g = |a: &u32| format!("r[{a}]");
    match op {
        Op::Const(c) => lit(*c),
        Op::Add(a, b) => format!("{} + {}", g(a), g(b)),
        Op::Sub(a, b) => format!("{} - {}", g(a), g(b)),
        Op::Mul(a, b) => format!("{} * {}", g(a), g(b)),
        Op::Div(a, b) => format!("{} / {}", g(a), g(b)),
        Op::AddC(a, c) => format!("{} + {}", g(a), lit(*c)),
        Op::CSub(c, a) => format!("{} - {}", lit(*c), g(a)),
        Op::MulC(a, c) => format!("{} * {}", g(a), lit(*c)),
        Op::DivC(a, c) => format!("{} / {}", g(a), lit(*c)),
        Op::CDiv(c, a) => format!("{} / {}", lit(*c), g(a)),
        Op::Neg(a) => format!("-{}", g(a)),
        Op::Sq(a) => format!("{} * {}", g(a), g(a)),
        Op::Recip(a) => format!("1.0_f32 / {}", g(a)),
        Op::Powi(a, n) => format!("libm::powf({}, {}.0_f32)", g(a), n),
        Op::Powf(a, c) => format!("libm::powf({}, {})", g(a), lit(*c)),
        Op::Pow(a, b) => format!("libm::expf({} * libm::logf({}))", g(b), g(a)),
        Op::Sin(a) => format!("controller_core::safe::fmath::sin({})", g(a)),
        Op::Cos(a) => format!("controller_core::safe::fmath::cos({})", g(a)),
        Op::Tan(a) => format!("libm::tanf({})", g(a)),
        Op::Asin(a) => format!("libm::asinf({})", g(a)),
        Op::Acos(a) => format!("libm::acosf({})", g(a)),
        Op::Atan(a) => format!("libm::atanf({})", g(a)),
        Op::Exp(a) => format!("libm::expf({})", g(a)),
        Op::Log(a) => format!("libm::logf({})", g(a)),
        Op::Sqrt(a) => format!("libm::sqrtf({})", g(a)),
        Op::Sinh(a) => format!("libm::sinhf({})", g(a)),
        Op::Cosh(a) => format!("libm::coshf({})", g(a)),
        Op::Tanh(a) => format!("libm::tanhf({})", g(a)),
        Op::Abs(a) => format!("libm::fabsf({})", g(a)),
        Op::Atan2(a, b) => format!("libm::atan2f({}, {})", g(a), g(b)),
        // The tape's rule: by value, `a` at a tie (and when b is NaN).
        Op::Min(a, b) => format!("if {1} < {0} {{ {1} }} else {{ {0} }}", g(a), g(b)),
        Op::Max(a, b) => format!("if {1} > {0} {{ {1} }} else {{ {0} }}", g(a), g(b)),
    }
}

/// The `rhs` function: the tape, one line per instruction.
fn rhs_fn(model: &ExprModel, out: &mut String) {
    let what = if model.is_discrete() {
        "F(x, u): the discrete plant's `next` expressions"
    } else {
        "f(x, u) = ẋ: the ODE's right-hand side"
    };
    tape_fn(
        model.tape(),
        (model.nx(), model.nu()),
        "rhs",
        "NX",
        what,
        out,
    );
}

/// `pub fn name(x: &[f32; NX], u: &[f32; NU]) -> [f32; outs]`: a tape over (x, u), one line
/// per instruction, in f32.
fn tape_fn(
    tape: &expr::Tape,
    (nx, nu): (usize, usize),
    name: &str,
    outs: &str,
    what: &str,
    out: &mut String,
) {
    let _ = writeln!(out, "/// {what} (the trainer's instruction tape, in f32).");
    let _ = writeln!(out, "#[allow(clippy::all, unused_parens)]");
    // Always inlined, as `step`: the online check calls them 4·N times per sequence, and
    // on a Cortex-M4 the calls cost about a fifth of a safe step (BENCHMARKS.md: 35,476 →
    // 28,332 instructions for the quadrotor with its net; the same arithmetic, so the same
    // bits).
    let _ = writeln!(out, "#[inline(always)]");
    let _ = writeln!(
        out,
        "pub fn {name}(x: &[f32; NX], u: &[f32; NU]) -> [f32; {outs}] {{"
    );
    let _ = writeln!(
        out,
        "    let mut r = [0.0_f32; {}];",
        tape.n_registers().max(nx + nu)
    );
    for i in 0..nx {
        let _ = writeln!(out, "    r[{i}] = x[{i}];");
    }
    for j in 0..nu {
        let _ = writeln!(out, "    r[{}] = u[{j}];", nx + j);
    }
    for ins in tape.instrs() {
        let _ = writeln!(out, "    r[{}] = {};", ins.dst, instr(&ins.op));
    }
    let outs: Vec<String> = tape.outs().iter().map(|o| format!("r[{o}]")).collect();
    let _ = writeln!(out, "    [{}]", outs.join(", "));
    let _ = writeln!(out, "}}");
}

/// The `step` function: RK4 over `SUBSTEPS` sub-steps (ODE), or `rhs` (discrete).
fn step_fn(model: &ExprModel, ts: f64, substeps: usize, out: &mut String) {
    let _ = writeln!(
        out,
        "/// F(x, u): one sampling period of the nominal model."
    );
    let _ = writeln!(out, "#[inline(always)]");
    let _ = writeln!(
        out,
        "pub fn step(x: &[f32; NX], u: &[f32; NU]) -> [f32; NX] {{"
    );
    if model.is_discrete() {
        let _ = writeln!(out, "    rhs(x, u)");
        let _ = writeln!(out, "}}");
        return;
    }
    let h = ts / substeps.max(1) as f64;
    let _ = writeln!(
        out,
        "    const HALF_H: f32 = {};\n    const H: f32 = {};\n    const H_6: f32 = {};",
        lit(0.5 * h),
        lit(h),
        lit(h / 6.0)
    );
    out.push_str(
        "    let mut x = *x;
    let mut t = [0.0_f32; NX];
    for _ in 0..SUBSTEPS {
        let k1 = rhs(&x, u);
        for ((t, x), k) in t.iter_mut().zip(&x).zip(&k1) {
            *t = *x + *k * HALF_H;
        }
        let k2 = rhs(&t, u);
        for ((t, x), k) in t.iter_mut().zip(&x).zip(&k2) {
            *t = *x + *k * HALF_H;
        }
        let k3 = rhs(&t, u);
        for ((t, x), k) in t.iter_mut().zip(&x).zip(&k3) {
            *t = *x + *k * H;
        }
        let k4 = rhs(&t, u);
        for ((((x, a), b), c), d) in x.iter_mut().zip(&k1).zip(&k2).zip(&k3).zip(&k4) {
            *x += (*a + *b * 2.0 + *c * 2.0 + *d) * H_6;
        }
    }
    x
}
",
    );
}

/// `pub const NAME: [f32; n] = [...];`
fn vec_const(out: &mut String, doc: &str, name: &str, v: &[f64]) {
    let items: Vec<String> = v.iter().map(|c| lit(*c)).collect();
    let _ = writeln!(
        out,
        "/// {doc}\npub const {name}: [f32; {}] = [{}];",
        v.len(),
        items.join(", ")
    );
}

/// `pub const NAME: [[f32; n]; n] = [[...], ...];` (a missing or ragged matrix: zeros, which
/// `validate` has already refused).
fn mat_const(out: &mut String, doc: &str, name: &str, m: &crate::problem::MatrixSpec, n: usize) {
    let d = m.to_dmatrix().filter(|d| d.nrows() == n && d.ncols() == n);
    let rows: Vec<String> = (0..n)
        .map(|i| {
            let r: Vec<String> = (0..n)
                .map(|j| lit(d.as_ref().map_or(0.0, |d| d[(i, j)])))
                .collect();
            format!("[{}]", r.join(", "))
        })
        .collect();
    let _ = writeln!(
        out,
        "/// {doc}\npub const {name}: [[f32; {n}]; {n}] = [{}];",
        rows.join(", ")
    );
}

/// The OCP's part of the online check: setpoint, weights, boxes, the `[ocp]` expression
/// constraints, and the functions `stage_cost`, `terminal_cost`, `project_input`,
/// `state_box_violation`, `constraints`, `path_violation`, `terminal_constraint_violation`.
///
/// ```text
/// ℓ(x, u) = (x − x_ref)ᵀQ(x − x_ref) + (u − u_ref)ᵀR(u − u_ref),  V_f(x) = (x − x_ref)ᵀP(x − x_ref)
/// Π_U(u)_j = clamp(u_j, u_lo,j, u_hi,j)  (NaN → u_ref,j)
/// g_X(x) = max_i max(x_lo,i − x_i, x_i − x_hi,i) / s_i   over finite bounds; s = the state scale
/// g_i(x, u) = lhs − rhs (or rhs − lhs) of `ocp.constraints` / `ocp.terminal_constraints`
///             (raw units, the compiled set's tape in f32), imposed per the OCP's rule:
///             states only on k ≥ 1, inputs only on every k, mixed on k ≥ 1, terminal on x_N
/// ```
/// Stage-dependent (tightened) bounds are not generated: an error names `ocp.stages`.
pub fn ocp_rs(cfg: &crate::problem::ProblemConfig) -> Result<String, PlantRsError> {
    ocp_rs_with(cfg, None)
}

/// [`ocp_rs`] with the terminal cost's matrix `vf` in place of the OCP's `ocp.p` (the
/// nominal terminal ingredients' P_f, for which the decrease condition was checked).
pub fn ocp_rs_with(
    cfg: &crate::problem::ProblemConfig,
    vf: Option<&[Vec<f64>]>,
) -> Result<String, PlantRsError> {
    let ocp = &cfg.ocp;
    if ocp.stages.is_some() {
        return Err(PlantRsError::UnsupportedOcp("ocp.stages".into()));
    }
    let (nx, nu) = (cfg.system.nx(), cfg.system.nu());
    let mut out = String::new();
    vec_const(
        &mut out,
        "Setpoint state x_ref.",
        "X_REF",
        &ocp.x_ref_or_origin(nx),
    );
    vec_const(
        &mut out,
        "Setpoint input u_ref.",
        "U_REF",
        &ocp.u_ref_or_zero(nu),
    );
    mat_const(&mut out, "Stage state weight Q.", "Q", &ocp.q, nx);
    mat_const(&mut out, "Stage input weight R.", "R", &ocp.r, nu);
    match vf {
        None => mat_const(&mut out, "Terminal weight P.", "P", &ocp.p, nx),
        Some(m) => {
            let spec = crate::problem::MatrixSpec::Full(m.to_vec());
            mat_const(
                &mut out,
                "Terminal cost V_f's matrix P_f (the nominal terminal ingredients'; not `ocp.p`).",
                "P",
                &spec,
                nx,
            )
        }
    }
    vec_const(
        &mut out,
        "Lower state bounds (x_1 … x_N).",
        "X_LO",
        &ocp.x_lo,
    );
    vec_const(
        &mut out,
        "Upper state bounds (x_1 … x_N).",
        "X_HI",
        &ocp.x_hi,
    );
    let scale = ocp.x_scale_or_default(&cfg.domain.lo, &cfg.domain.hi);
    vec_const(
        &mut out,
        "State scale s of the normalised violation.",
        "X_SCALE",
        &scale,
    );
    vec_const(&mut out, "Lower input bounds.", "U_LO", &ocp.u_lo);
    vec_const(&mut out, "Upper input bounds.", "U_HI", &ocp.u_hi);
    constraints_rs(cfg, &mut out)?;
    sparse_fns(cfg, &mut out);
    out.push_str(OCP_FNS);
    Ok(out)
}

/// `NC`, `C_KIND` and `constraints(x, u)`: the `[ocp]` expression constraints (path, then
/// terminal) as f32 code (an empty set without any).
fn constraints_rs(
    cfg: &crate::problem::ProblemConfig,
    out: &mut String,
) -> Result<(), PlantRsError> {
    let cs = cfg
        .constraint_set()
        .map_err(|e| PlantRsError::UnsupportedOcp(format!("{}: {e}", e.key)))?;
    let (nx, nu) = (cfg.system.nx(), cfg.system.nu());
    let kinds: Vec<&str> = cs.as_ref().map_or(vec![], |cs| {
        cs.items
            .iter()
            .map(
                |c| match (c.terminal, c.uses_states(nx), c.uses_inputs(nx)) {
                    (true, _, _) => "3",
                    (false, true, false) => "0",
                    (false, false, true) => "1",
                    _ => "2",
                },
            )
            .collect()
    });
    let texts: Vec<String> = cs.as_ref().map_or(vec![], |cs| {
        cs.items
            .iter()
            .map(|c| format!("//   {}: `{}`", c.key, c.text))
            .collect()
    });
    let _ = writeln!(
        out,
        "/// Number of `[ocp]` expression constraints g_i(x, u) ≤ 0 (path, then terminal).
         pub const NC: usize = {};
         /// Where each is imposed: 0 = states only (k ≥ 1), 1 = inputs only (every k), 2 = both          (k ≥ 1), 3 = terminal (x_N).
         pub const C_KIND: [u8; NC] = [{}];",
        kinds.len(),
        kinds.join(", ")
    );
    match &cs {
        Some(cs) => {
            let _ = writeln!(out, "// The constraints:\n{}", texts.join("\n"));
            tape_fn(
                cs.tape(),
                (nx, nu),
                "constraints",
                "NC",
                "g(x, u): the `[ocp]` constraints as g_i ≤ 0",
                out,
            );
        }
        None => out.push_str(
            "/// g(x, u): no `[ocp]` expression constraints.\n\
             pub fn constraints(_x: &[f32; NX], _u: &[f32; NU]) -> [f32; NC] {\n    \
             [0.0_f32; NC]\n}\n",
        ),
    }
    Ok(())
}

/// `Σ_ij w_ij d_i d_j` unrolled over the nonzero entries of `m` (`0.0` without any), over
/// the difference `d` named `d`.
fn sparse_quad(m: &crate::problem::MatrixSpec, n: usize) -> String {
    let Some(w) = m.to_dmatrix().filter(|d| d.nrows() == n && d.ncols() == n) else {
        return "0.0_f32".into();
    };
    let mut terms = Vec::new();
    for i in 0..n {
        let row: Vec<String> = (0..n)
            .filter(|&j| w[(i, j)] != 0.0)
            .map(|j| format!("{} * d[{j}]", lit(w[(i, j)])))
            .collect();
        if !row.is_empty() {
            terms.push(format!("d[{i}] * ({})", row.join(" + ")));
        }
    }
    if terms.is_empty() {
        "0.0_f32".into()
    } else {
        terms.join("\n        + ")
    }
}

/// `stage_cost` (Q, R unrolled over their nonzero entries) and `state_box_violation` (over
/// the finite bounds only): the functions the online check calls N times per sequence.
fn sparse_fns(cfg: &crate::problem::ProblemConfig, out: &mut String) {
    let ocp = &cfg.ocp;
    let (nx, nu) = (cfg.system.nx(), cfg.system.nu());
    let _ = writeln!(
        out,
        "\n/// ℓ(x, u) = (x − x_ref)ᵀQ(x − x_ref) + (u − u_ref)ᵀR(u − u_ref) (unrolled over the \
         nonzero weights).\n\
         #[allow(clippy::all)]\n\
         pub fn stage_cost(x: &[f32; NX], u: &[f32; NU]) -> f32 {{\n    \
         let sx = {{\n        let d = diff(x, &X_REF);\n        {}\n    }};\n    \
         let su = {{\n        let d = diff(u, &U_REF);\n        {}\n    }};\n    sx + su\n}}",
        sparse_quad(&ocp.q, nx),
        sparse_quad(&ocp.r, nu)
    );
    let scale = ocp.x_scale_or_default(&cfg.domain.lo, &cfg.domain.hi);
    let mut body = String::new();
    for i in 0..nx {
        for (bound, expr) in [
            (ocp.x_lo[i], format!("(X_LO[{i}] - x[{i}]) / X_SCALE[{i}]")),
            (ocp.x_hi[i], format!("(x[{i}] - X_HI[{i}]) / X_SCALE[{i}]")),
        ] {
            if bound.is_finite() && scale[i].is_finite() {
                let _ = write!(
                    body,
                    "    let v = {expr};\n    if v > g {{\n        g = v;\n    }}\n"
                );
            }
        }
    }
    let _ = writeln!(
        out,
        "\n/// max_i max(x_lo,i − x_i, x_i − x_hi,i) / s_i over the finite bounds (−∞ if none; \
         NaN for\n/// a NaN state): `≤ 0` inside the state box.\n\
         #[allow(clippy::all)]\n\
         pub fn state_box_violation(x: &[f32; NX]) -> f32 {{\n    \
         if x.iter().any(|v| v.is_nan()) {{\n        return f32::NAN;\n    }}\n    \
         let mut g = f32::NEG_INFINITY;\n{body}    g\n}}"
    );
}

/// The OCP's functions (fixed text over the constants above).
const OCP_FNS: &str = "
/// dᵀWd.
fn quad<const M: usize>(w: &[[f32; M]; M], d: &[f32; M]) -> f32 {
    let mut s = 0.0_f32;
    for (row, di) in w.iter().zip(d) {
        let mut r = 0.0_f32;
        for (a, dj) in row.iter().zip(d) {
            r += *a * *dj;
        }
        s += *di * r;
    }
    s
}

/// a − b, element by element.
fn diff<const M: usize>(a: &[f32; M], b: &[f32; M]) -> [f32; M] {
    let mut d = [0.0_f32; M];
    for ((d, a), b) in d.iter_mut().zip(a).zip(b) {
        *d = *a - *b;
    }
    d
}


/// V_f(x) = (x − x_ref)ᵀP(x − x_ref).
pub fn terminal_cost(x: &[f32; NX]) -> f32 {
    quad(&P, &diff(x, &X_REF))
}

/// Π_U(u): clamp to [U_LO, U_HI]; a NaN component becomes u_ref's.
pub fn project_input(u: &[f32; NU]) -> [f32; NU] {
    let mut p = U_REF;
    for ((((p, u), lo), hi), r) in p.iter_mut().zip(u).zip(&U_LO).zip(&U_HI).zip(&U_REF) {
        *p = if u.is_nan() {
            *r
        } else if *u < *lo {
            *lo
        } else if *u > *hi {
            *hi
        } else {
            *u
        };
    }
    p
}

/// The largest of `g` over the constraints of `C_KIND` selected by `keep` (−∞ if none; NaN
/// if one is NaN).
fn max_kind(g: &[f32; NC], keep: impl Fn(u8) -> bool) -> f32 {
    let mut m = f32::NEG_INFINITY;
    for (g, kind) in g.iter().zip(&C_KIND) {
        if keep(*kind) {
            if g.is_nan() {
                return f32::NAN;
            }
            if *g > m {
                m = *g;
            }
        }
    }
    m
}

/// The path constraints the OCP imposes at stage k on (x_k, u_k): inputs-only ones at every
/// k, the others from k = 1 on (raw units; −∞ if none).
pub fn path_violation(k: usize, x: &[f32; NX], u: &[f32; NU]) -> f32 {
    if NC == 0 {
        return f32::NEG_INFINITY;
    }
    let g = constraints(x, u);
    max_kind(&g, |kind| kind == 1 || (k >= 1 && (kind == 0 || kind == 2)))
}

/// The terminal constraints at x_N (raw units; −∞ if none).
pub fn terminal_constraint_violation(x: &[f32; NX]) -> f32 {
    if NC == 0 {
        return f32::NEG_INFINITY;
    }
    let g = constraints(x, &U_REF);
    max_kind(&g, |kind| kind == 3)
}

";

/// The Rust source of the plant's F for `name` (a comment), with sampling time `ts` and
/// `substeps` RK4 sub-steps.
pub fn plant_rs(name: &str, model: &ExprModel, ts: f64, substeps: usize) -> String {
    let mut out = String::new();
    let kind = if model.is_discrete() {
        "discrete"
    } else {
        "ode"
    };
    let _ = writeln!(
        out,
        "// The plant of problem `{name}` ({kind}, states {:?}, inputs {:?}) in f32:\n\
         // generated by `trainer` (deploy::plant_rs) from the problem's model. Do not edit.\n",
        model.state_names(),
        model.input_names()
    );
    let _ = writeln!(
        out,
        "/// State dimension.\npub const NX: usize = {};",
        model.nx()
    );
    let _ = writeln!(
        out,
        "/// Input dimension.\npub const NU: usize = {};",
        model.nu()
    );
    let _ = writeln!(
        out,
        "/// Sampling time Ts.\npub const TS: f32 = {};",
        lit(ts)
    );
    let _ = writeln!(
        out,
        "/// RK4 sub-steps per sampling period (unused by a discrete plant).\n\
         pub const SUBSTEPS: usize = {};\n",
        substeps.max(1)
    );
    rhs_fn(model, &mut out);
    out.push('\n');
    step_fn(model, ts, substeps, &mut out);
    out
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::problem::model::{CartPole, Pendulum};

    #[test]
    fn literals_round_to_nearest_f32_and_name_non_finite_values() {
        assert_eq!(lit(0.1), "0.1_f32");
        assert_eq!(lit(1e300), "f32::INFINITY");
        assert_eq!(lit(-1e300), "f32::NEG_INFINITY");
        assert_eq!(lit(f64::NAN), "f32::NAN");
        assert_eq!(lit(2.0), "2.0_f32");
    }

    #[test]
    fn unsupported_plants_are_named() {
        let e = plant_model(&System::Pendulum(Pendulum::default())).unwrap_err();
        assert!(e.to_string().contains("\"pendulum\""), "{e}");
        let m = plant_model(&System::CartPole(CartPole::default())).unwrap();
        assert_eq!((m.nx(), m.nu()), (4, 1));
        let src = plant_rs("cp", &m, 0.05, 2);
        assert!(src.contains("pub const SUBSTEPS: usize = 2;"), "{src}");
        assert!(
            src.contains("fmath::sin(") && src.contains("fmath::cos("),
            "{src}"
        );
    }
}
