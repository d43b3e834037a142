//! `plant_rs_margin`: the **online check's margin** of the generated plant — an *estimate*
//! of how far the device's f32 simulation of a sequence can be from the trainer's f64 model
//! over the horizon, in the units of the check's constraints.
//!
//! ```text
//! d_s = max over trajectories, k = 1…N, finite-bound states i of |x32_k,i − x64_k,i| / s_i
//! d_f = max over trajectories of |V32(x32_N) − V64(x64_N)| / α,  V(x) = (x − x_r)ᵀP_f(x − x_r)
//! (and of |g32_i − g64_i| for the `[ocp]` expression constraints, folded into d_s)
//! m_s = FACTOR · d_s,   m_f = FACTOR · d_f                              (estimated)
//! ```
//! The trajectories: [`MARGIN_STATES`] seeded states uniform in the domain X, each run for N
//! steps under `u_k = Π_U(κ_f(x64_k) + w_k)` (the terminal controller plus uniform noise of
//! a tenth of the input box's width: sequences near the ones the check accepts), both
//! simulations fed the same f32 inputs; a trajectory counts while its f64 states stay in the
//! state box (outside it no sequence is accepted). x32 is an **emulation** of the generated
//! code — the same instruction tape, the same operation order, the same f32
//! functions (`controller_core::safe::fmath`, `libm`) and constants (`tests/safe_plant.rs` compares it with the compiled generated
//! file) — and x64 is `Discrete::step`.
//!
//! What it rests on: a sample (states outside it, other input sequences, are not covered by
//! an argument), multiplied by [`FACTOR`] as a growth allowance. It is written into the
//! generated file as `MARGINS` with the word "estimated", never as a bound.

use crate::problem::model::expr::{ExprModel, Op, Tape};
use crate::problem::model::Discrete;
use crate::problem::ProblemConfig;
use crate::rng::uniform;

/// Initial states of the trajectories.
pub const MARGIN_STATES: usize = 100_000;

/// The allowance multiplying the measured differences.
pub const FACTOR: f64 = 10.0;

/// The measured differences and the margins derived from them.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct MarginEstimate {
    /// d_s: the largest normalised state (or expression-constraint) difference.
    pub stage_diff: f64,
    /// d_f: the largest terminal-cost difference relative to α.
    pub terminal_diff: f64,
    /// Trajectories that stayed in the state box to the end.
    pub trajectories: usize,
    /// m_s = FACTOR · d_s.
    pub stage: f64,
    /// m_f = FACTOR · d_f.
    pub terminal: f64,
}

/// The tape in f32, as the generated `rhs`/`constraints` evaluate it.
pub fn eval_f32(tape: &Tape, x: &[f32], u: &[f32], regs: &mut Vec<f32>, out: &mut [f32]) {
    regs.clear();
    regs.resize(tape.n_registers().max(x.len() + u.len()), 0.0);
    for (r, v) in regs.iter_mut().zip(x.iter().chain(u)) {
        *r = *v;
    }
    for ins in tape.instrs() {
        let g = |a: &u32| regs[*a as usize];
        let c = |c: &f64| *c as f32;
        let v = match &ins.op {
            Op::Const(k) => c(k),
            Op::Add(a, b) => g(a) + g(b),
            Op::Sub(a, b) => g(a) - g(b),
            Op::Mul(a, b) => g(a) * g(b),
            Op::Div(a, b) => g(a) / g(b),
            Op::AddC(a, k) => g(a) + c(k),
            Op::CSub(k, a) => c(k) - g(a),
            Op::MulC(a, k) => g(a) * c(k),
            Op::DivC(a, k) => g(a) / c(k),
            Op::CDiv(k, a) => c(k) / g(a),
            Op::Neg(a) => -g(a),
            Op::Sq(a) => g(a) * g(a),
            Op::Recip(a) => 1.0 / g(a),
            Op::Powi(a, n) => libm::powf(g(a), *n as f32),
            Op::Powf(a, k) => libm::powf(g(a), c(k)),
            Op::Pow(a, b) => libm::expf(g(b) * libm::logf(g(a))),
            Op::Sin(a) => controller_core::safe::fmath::sin(g(a)),
            Op::Cos(a) => controller_core::safe::fmath::cos(g(a)),
            Op::Tan(a) => libm::tanf(g(a)),
            Op::Asin(a) => libm::asinf(g(a)),
            Op::Acos(a) => libm::acosf(g(a)),
            Op::Atan(a) => libm::atanf(g(a)),
            Op::Exp(a) => libm::expf(g(a)),
            Op::Log(a) => libm::logf(g(a)),
            Op::Sqrt(a) => libm::sqrtf(g(a)),
            Op::Sinh(a) => libm::sinhf(g(a)),
            Op::Cosh(a) => libm::coshf(g(a)),
            Op::Tanh(a) => libm::tanhf(g(a)),
            Op::Abs(a) => libm::fabsf(g(a)),
            Op::Atan2(a, b) => libm::atan2f(g(a), g(b)),
            Op::Min(a, b) => {
                if g(b) < g(a) {
                    g(b)
                } else {
                    g(a)
                }
            }
            Op::Max(a, b) => {
                if g(b) > g(a) {
                    g(b)
                } else {
                    g(a)
                }
            }
        };
        regs[ins.dst as usize] = v;
    }
    for (o, r) in out.iter_mut().zip(tape.outs()) {
        *o = regs[*r as usize];
    }
}

/// F(x, u) in f32 as the generated `step` computes it (RK4 over the sub-steps, or the
/// discrete map).
pub fn step_f32(model: &ExprModel, ts: f64, substeps: usize, x: &[f32], u: &[f32]) -> Vec<f32> {
    let mut out = vec![0.0; x.len()];
    step_f32_into(
        model,
        ts,
        substeps,
        (x, u),
        &mut out,
        &mut StepScratch::default(),
    );
    out
}

/// The buffers of [`step_f32_into`] (registers, RK4 stages), reused across calls.
#[derive(Debug, Clone, Default)]
pub struct StepScratch {
    regs: Vec<f32>,
    k: [Vec<f32>; 4],
    t: Vec<f32>,
}

/// [`step_f32`] of `(x, u)` into `out` (nx entries) on the buffers `s`: the same operations
/// in the same order, so the same bits, without allocating once `s` has grown.
pub fn step_f32_into(
    model: &ExprModel,
    ts: f64,
    substeps: usize,
    (x, u): (&[f32], &[f32]),
    out: &mut [f32],
    s: &mut StepScratch,
) {
    let nx = x.len();
    let StepScratch {
        regs,
        k: [k1, k2, k3, k4],
        t,
    } = s;
    for v in [&mut *k1, &mut *k2, &mut *k3, &mut *k4, &mut *t] {
        v.clear();
        v.resize(nx, 0.0);
    }
    let mut f = |x: &[f32], o: &mut [f32]| eval_f32(model.tape(), x, u, regs, o);
    if model.is_discrete() {
        out.fill(0.0);
        f(x, out);
        return;
    }
    out.copy_from_slice(x);
    let h = ts / substeps.max(1) as f64;
    let (half_h, hh, h_6) = ((0.5 * h) as f32, h as f32, (h / 6.0) as f32);
    for _ in 0..substeps.max(1) {
        f(out, k1);
        for i in 0..nx {
            t[i] = out[i] + k1[i] * half_h;
        }
        f(t, k2);
        for i in 0..nx {
            t[i] = out[i] + k2[i] * half_h;
        }
        f(t, k3);
        for i in 0..nx {
            t[i] = out[i] + k3[i] * hh;
        }
        f(t, k4);
        for i in 0..nx {
            out[i] += (k1[i] + k2[i] * 2.0 + k3[i] * 2.0 + k4[i]) * h_6;
        }
    }
}

fn quad64(p: &[Vec<f64>], d: &[f64]) -> f64 {
    (0..d.len())
        .map(|i| d[i] * (0..d.len()).map(|j| p[i][j] * d[j]).sum::<f64>())
        .sum()
}

/// (x − x_r)ᵀP_f(x − x_r) in f32 as the generated `quad(&P_F, &diff(x, &X_REF))`.
fn quad32(p: &[Vec<f64>], x: &[f32], xr: &[f64]) -> f32 {
    let d: Vec<f32> = x.iter().zip(xr).map(|(x, r)| *x - *r as f32).collect();
    let mut s = 0.0f32;
    for (row, di) in p.iter().zip(&d) {
        let mut r = 0.0f32;
        for (a, dj) in row.iter().zip(&d) {
            r += *a as f32 * *dj;
        }
        s += *di * r;
    }
    s
}

/// The terminal ingredients the margins are measured for: x_r, u_r, K, P_f, α.
pub type Ingredients<'a> = (&'a [f64], &'a [f64], &'a [Vec<f64>], &'a [Vec<f64>], f64);

/// The margins of the terminal ingredients (x_r, u_r, K, P_f, α) for `cfg` (module doc),
/// over `states` seeded trajectories.
pub fn estimate_margins(
    cfg: &ProblemConfig,
    model: &ExprModel,
    (xr, ur, k, p_f, alpha): Ingredients<'_>,
    states: usize,
) -> MarginEstimate {
    let (nx, nu) = (xr.len(), ur.len());
    let o = &cfg.ocp;
    let f64_model = Discrete::new(cfg.system.clone(), o.ts, o.rk4_substeps);
    let scale = o.x_scale_or_default(&cfg.domain.lo, &cfg.domain.hi);
    let cs = cfg.constraint_set().ok().flatten();
    let nc = cs.as_ref().map_or(0, |c| c.len());
    let (mut g32, mut g64, mut regs, mut scratch) =
        (vec![0.0f32; nc], vec![0.0f64; nc], Vec::new(), Vec::new());
    let (mut ds, mut df, mut full) = (0.0f64, 0.0f64, 0);
    let (mut y64, mut y32, mut step_scratch) =
        (vec![0.0; nx], vec![0.0f32; nx], StepScratch::default());
    for s in 0..states as u64 {
        let mut x32: Vec<f32> = (0..nx)
            .map(|i| {
                let (lo, hi) = (cfg.domain.lo[i], cfg.domain.hi[i]);
                (lo + (hi - lo) * uniform(0x3a41, s, i as u64)) as f32
            })
            .collect();
        let mut x64: Vec<f64> = x32.iter().map(|v| f64::from(*v)).collect();
        let mut inside = true;
        for step in 0..o.horizon {
            let u: Vec<f32> = (0..nu)
                .map(|j| {
                    let kf = ur[j] + (0..nx).map(|i| k[j][i] * (x64[i] - xr[i])).sum::<f64>();
                    let w = 0.1 * (o.u_hi[j] - o.u_lo[j]).min(1e3);
                    let v = kf + w * (uniform(0x3a42, s, (step * nu + j) as u64) - 0.5);
                    v.clamp(o.u_lo[j], o.u_hi[j]) as f32
                })
                .collect();
            let ud: Vec<f64> = u.iter().map(|v| f64::from(*v)).collect();
            if let Some(cs) = &cs {
                eval_f32(cs.tape(), &x32, &u, &mut regs, &mut g32);
                cs.eval(&x64, &ud, &mut g64, &mut scratch);
                for c in 0..nc {
                    ds = ds.max((f64::from(g32[c]) - g64[c]).abs());
                }
            }
            step_f32_into(
                model,
                o.ts,
                o.rk4_substeps,
                (&x32, &u),
                &mut y32,
                &mut step_scratch,
            );
            x32.copy_from_slice(&y32);
            f64_model.step(&x64, &ud, &mut y64);
            x64.clone_from(&y64);
            inside &= (0..nx).all(|i| o.x_lo[i] <= x64[i] && x64[i] <= o.x_hi[i]);
            if !inside || x64.iter().any(|v| !v.is_finite()) {
                break;
            }
            for i in 0..nx {
                if o.x_lo[i].is_finite() || o.x_hi[i].is_finite() {
                    ds = ds.max((f64::from(x32[i]) - x64[i]).abs() / scale[i]);
                }
            }
        }
        if inside {
            full += 1;
            let d64: Vec<f64> = (0..nx).map(|i| x64[i] - xr[i]).collect();
            let v32 = f64::from(quad32(p_f, &x32, xr));
            df = df.max((v32 - quad64(p_f, &d64)).abs() / alpha);
        }
    }
    MarginEstimate {
        stage_diff: ds,
        terminal_diff: df,
        trajectories: full,
        stage: FACTOR * ds,
        terminal: FACTOR * df,
    }
}
