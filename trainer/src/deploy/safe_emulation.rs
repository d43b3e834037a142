//! `safe_emulation`: the device's safety-augmented controller at runtime dimensions —
//! [`EmulatedPlant`], the generated `SafePlant` of [`super::plant_rs_safe`] evaluated in f32
//! operation for operation (the same tape through [`super::plant_rs_margin::eval_f32`] and
//! [`super::plant_rs_margin::step_f32`], the same constants rounded to f32, the same order of
//! sums), and [`SafeEmulation`], a mirror of `controller_core::safe::SafeController`'s
//! `check`, `init_with` and `step_with` over `Vec`s:
//!
//! ```text
//! check(x, v):  x_0 = x, x_{k+1} = F32(x_k, v_k);  feasible ⇔ Π_U(v_k) = v_k ∧ g_k + m_s ≤ 0
//!               ∧ g_N(x_N) + m_f ≤ 0 ∧ J finite,  J = Σ ℓ32(x_k, v_k) + V_f32(x_N)
//! step(x, c):   c ← Π_U(c) (finite c);  s = shift(ū) completed by Π_U(κ_f(x_{N−1}));
//!               c if c feasible ∧ (s infeasible
//!               ∨ J(c) ≤ J(s)), else s;  u = Π_U(v_0)
//! ```
//!
//! `SafeController` is const-generic in (NX, NU, N); the trainer's dimensions are runtime
//! values, hence the mirror. `tests/safe_emulation.rs` checks that it gives bit-identical
//! inputs, flags and costs to `SafeController` running the committed generated plants (double
//! integrator, quadrotor) over many states and candidates; `controller_core::safe` stays the
//! definition.

use super::plant_rs::{plant_model, PlantRsError};
use super::plant_rs_margin::{eval_f32, step_f32, step_f32_into, StepScratch};
use super::plant_rs_safe::{safe_plant_rs, SafePlantRs, TerminalSource};
use crate::problem::model::expr::{ConstraintSet, ExprModel};
use crate::problem::ProblemConfig;
use controller_core::safe::{CandidateForm, SafeFlags};

/// The generated `SafePlant` of a problem, evaluated as the generated code evaluates it.
#[derive(Debug, Clone)]
pub struct EmulatedPlant {
    model: ExprModel,
    ts: f64,
    substeps: usize,
    cs: Option<ConstraintSet>,
    /// Where each `[ocp]` constraint is imposed (the generated `C_KIND`).
    c_kind: Vec<u8>,
    x_ref: Vec<f32>,
    u_ref: Vec<f32>,
    /// Q and R: per row with a nonzero entry, (row, [(column, weight)]).
    q: Vec<(usize, Vec<(usize, f32)>)>,
    r: Vec<(usize, Vec<(usize, f32)>)>,
    /// V_f's matrix (the generated `P`).
    p: Vec<Vec<f32>>,
    /// The state box terms the generated `state_box_violation` checks: (i, lower?).
    box_terms: Vec<(usize, bool)>,
    x_lo: Vec<f32>,
    x_hi: Vec<f32>,
    x_scale: Vec<f32>,
    u_lo: Vec<f32>,
    u_hi: Vec<f32>,
    p_f: Vec<Vec<f32>>,
    k_f: Vec<Vec<f32>>,
    alpha: f32,
    /// The generated `MARGINS` (stage, terminal).
    pub margins: (f32, f32),
}

fn f32v(v: &[f64]) -> Vec<f32> {
    v.iter().map(|c| *c as f32).collect()
}

fn f32m(m: &[Vec<f64>]) -> Vec<Vec<f32>> {
    m.iter().map(|r| f32v(r)).collect()
}

/// A `MatrixSpec` as the generator reads it (`n × n`, else zeros).
fn dense(m: &crate::problem::MatrixSpec, n: usize) -> Vec<Vec<f64>> {
    let d = m.to_dmatrix().filter(|d| d.nrows() == n && d.ncols() == n);
    (0..n)
        .map(|i| {
            (0..n)
                .map(|j| d.as_ref().map_or(0.0, |d| d[(i, j)]))
                .collect()
        })
        .collect()
}

/// The nonzero entries per row, as `sparse_quad` unrolls them (the f64 test of zero).
fn sparse(m: &[Vec<f64>]) -> Vec<(usize, Vec<(usize, f32)>)> {
    m.iter()
        .enumerate()
        .filter_map(|(i, row)| {
            let nz: Vec<(usize, f32)> = row
                .iter()
                .enumerate()
                .filter(|(_, w)| **w != 0.0)
                .map(|(j, w)| (j, *w as f32))
                .collect();
            (!nz.is_empty()).then_some((i, nz))
        })
        .collect()
}

/// max(a, b), NaN if either is NaN (the generated `max_nan`).
fn max_nan(a: f32, b: f32) -> f32 {
    if a.is_nan() || b.is_nan() {
        f32::NAN
    } else if a > b {
        a
    } else {
        b
    }
}

/// dᵀWd in the generated `quad`'s order.
fn quad(w: &[Vec<f32>], d: &[f32]) -> f32 {
    let mut s = 0.0f32;
    for (row, di) in w.iter().zip(d) {
        let mut r = 0.0f32;
        for (a, dj) in row.iter().zip(d) {
            r += *a * *dj;
        }
        s += *di * r;
    }
    s
}

fn diff(a: &[f32], b: &[f32]) -> Vec<f32> {
    a.iter().zip(b).map(|(a, b)| *a - *b).collect()
}

/// The unrolled `Σ_i d_i (Σ_j w_ij d_j)` of `sparse_quad` (0 without terms).
fn sparse_quad(w: &[(usize, Vec<(usize, f32)>)], d: &[f32]) -> f32 {
    let mut total: Option<f32> = None;
    for (i, row) in w {
        let mut inner: Option<f32> = None;
        for (j, c) in row {
            let t = *c * d[*j];
            inner = Some(inner.map_or(t, |s| s + t));
        }
        let t = d[*i] * inner.unwrap_or(0.0);
        total = Some(total.map_or(t, |s| s + t));
    }
    total.unwrap_or(0.0)
}

impl EmulatedPlant {
    /// The emulation of `cfg`'s generated safe plant, with the generation's result (terminal
    /// ingredients, tiers, margins). Fails where `safe_plant_rs` fails.
    pub fn new(cfg: &ProblemConfig) -> Result<(Self, SafePlantRs), PlantRsError> {
        let g = safe_plant_rs(cfg)?;
        Ok((Self::from_generated(cfg, &g)?, g))
    }

    /// The emulation of the generated plant `g` of `cfg`.
    pub fn from_generated(cfg: &ProblemConfig, g: &SafePlantRs) -> Result<Self, PlantRsError> {
        let model = plant_model(&cfg.system)?;
        let o = &cfg.ocp;
        let (nx, nu) = (cfg.system.nx(), cfg.system.nu());
        let cs = cfg
            .constraint_set()
            .map_err(|e| PlantRsError::UnsupportedOcp(format!("{}: {e}", e.key)))?;
        let c_kind = cs.as_ref().map_or(vec![], |cs| {
            cs.items
                .iter()
                .map(
                    |c| match (c.terminal, c.uses_states(nx), c.uses_inputs(nx)) {
                        (true, _, _) => 3,
                        (false, true, false) => 0,
                        (false, false, true) => 1,
                        _ => 2,
                    },
                )
                .collect()
        });
        let scale = o.x_scale_or_default(&cfg.domain.lo, &cfg.domain.hi);
        let mut box_terms = Vec::new();
        for i in 0..nx {
            for (bound, lower) in [(o.x_lo[i], true), (o.x_hi[i], false)] {
                if bound.is_finite() && scale[i].is_finite() {
                    box_terms.push((i, lower));
                }
            }
        }
        let v_f = match &g.terminal {
            TerminalSource::Nominal(t) => t.p.clone(),
            TerminalSource::Robust(_) => dense(&o.p, nx),
        };
        Ok(EmulatedPlant {
            model,
            ts: o.ts,
            substeps: o.rk4_substeps,
            cs,
            c_kind,
            x_ref: f32v(&o.x_ref_or_origin(nx)),
            u_ref: f32v(&o.u_ref_or_zero(nu)),
            q: sparse(&dense(&o.q, nx)),
            r: sparse(&dense(&o.r, nu)),
            p: f32m(&dense(&crate::problem::MatrixSpec::Full(v_f), nx)),
            box_terms,
            x_lo: f32v(&o.x_lo),
            x_hi: f32v(&o.x_hi),
            x_scale: f32v(&scale),
            u_lo: f32v(&o.u_lo),
            u_hi: f32v(&o.u_hi),
            p_f: f32m(&g.p_f),
            k_f: f32m(&g.k),
            alpha: g.terminal.alpha() as f32,
            margins: (
                (g.margins.stage * (1.0 + 1e-6)) as f32,
                (g.margins.terminal * (1.0 + 1e-6)) as f32,
            ),
        })
    }

    /// (nx, nu).
    pub fn dims(&self) -> (usize, usize) {
        (self.x_ref.len(), self.u_ref.len())
    }

    /// F(x, u): the generated `step`.
    pub fn step(&self, x: &[f32], u: &[f32]) -> Vec<f32> {
        step_f32(&self.model, self.ts, self.substeps, x, u)
    }

    /// F(x, u) into `out` on reused buffers (the same bits as [`Self::step`]).
    pub fn step_into(&self, x: &[f32], u: &[f32], out: &mut [f32], s: &mut StepScratch) {
        step_f32_into(&self.model, self.ts, self.substeps, (x, u), out, s)
    }

    /// The generated `state_box_violation`.
    fn state_box_violation(&self, x: &[f32]) -> f32 {
        if x.iter().any(|v| v.is_nan()) {
            return f32::NAN;
        }
        let mut g = f32::NEG_INFINITY;
        for &(i, lower) in &self.box_terms {
            let v = if lower {
                (self.x_lo[i] - x[i]) / self.x_scale[i]
            } else {
                (x[i] - self.x_hi[i]) / self.x_scale[i]
            };
            if v > g {
                g = v;
            }
        }
        g
    }

    /// The largest `[ocp]` constraint value over the kinds `keep` selects (the generated
    /// `max_kind` over `constraints(x, u)`).
    fn max_kind(&self, x: &[f32], u: &[f32], keep: impl Fn(u8) -> bool) -> f32 {
        let Some(cs) = &self.cs else {
            return f32::NEG_INFINITY;
        };
        let mut g = vec![0.0f32; cs.len()];
        eval_f32(cs.tape(), x, u, &mut Vec::new(), &mut g);
        let mut m = f32::NEG_INFINITY;
        for (g, kind) in g.iter().zip(&self.c_kind) {
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

    /// g_k(x, u): the generated `stage_violation`.
    pub fn stage_violation(&self, k: usize, x: &[f32], u: &[f32]) -> f32 {
        let b = if k == 0 {
            if x.iter().any(|v| v.is_nan()) {
                f32::NAN
            } else {
                f32::NEG_INFINITY
            }
        } else {
            self.state_box_violation(x)
        };
        let path = self.max_kind(x, u, |kind| {
            kind == 1 || (k >= 1 && (kind == 0 || kind == 2))
        });
        max_nan(b, path)
    }

    /// g_N(x): the generated `terminal_violation`.
    pub fn terminal_violation(&self, x: &[f32]) -> f32 {
        let tc = self.max_kind(x, &self.u_ref, |kind| kind == 3);
        let b = max_nan(self.state_box_violation(x), tc);
        max_nan(
            b,
            (quad(&self.p_f, &diff(x, &self.x_ref)) - self.alpha) / self.alpha,
        )
    }

    /// κ_f(x) = u_r + K(x − x_r): the generated `terminal_input`.
    pub fn terminal_input(&self, x: &[f32]) -> Vec<f32> {
        let d = diff(x, &self.x_ref);
        let mut u = self.u_ref.clone();
        for (u, row) in u.iter_mut().zip(&self.k_f) {
            for (k, d) in row.iter().zip(&d) {
                *u += *k * *d;
            }
        }
        u
    }

    /// Π_U(u): the generated `project_input`.
    pub fn project_input(&self, u: &[f32]) -> Vec<f32> {
        (0..self.u_ref.len())
            .map(|j| {
                let v = u.get(j).copied().unwrap_or(f32::NAN);
                if v.is_nan() {
                    self.u_ref[j]
                } else if v < self.u_lo[j] {
                    self.u_lo[j]
                } else if v > self.u_hi[j] {
                    self.u_hi[j]
                } else {
                    v
                }
            })
            .collect()
    }

    /// ℓ(x, u): the generated `stage_cost`.
    pub fn stage_cost(&self, x: &[f32], u: &[f32]) -> f32 {
        let sx = sparse_quad(&self.q, &diff(x, &self.x_ref));
        let su = sparse_quad(&self.r, &diff(u, &self.u_ref));
        sx + su
    }

    /// V_f(x): the generated `terminal_cost`.
    pub fn terminal_cost(&self, x: &[f32]) -> f32 {
        quad(&self.p, &diff(x, &self.x_ref))
    }
}

/// The result of one [`SafeEmulation::step_with`] (`controller_core::safe::SafeOutput`).
#[derive(Debug, Clone, PartialEq)]
pub struct EmulatedOutput {
    /// The input to apply.
    pub u: Vec<f32>,
    /// What happened.
    pub flags: SafeFlags,
    /// J of the candidate (+∞ if it failed the check).
    pub candidate_cost: f32,
    /// J of the safe candidate (+∞ if it failed or none existed).
    pub safe_cost: f32,
    /// Why the candidate passed or failed (not part of the device's output).
    pub diagnosis: CandidateDiagnosis,
}

/// The parts of one online check's verdict, kept apart for the study's diagnosis.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct CheckDetail {
    /// Π_U(v_k) = v_k for every k.
    pub input_box: bool,
    /// g_k(x_k, v_k) + m_s ≤ 0 for every k (state box from k = 1, path constraints).
    pub stage: bool,
    /// g_N(x_N) + m_f ≤ 0 (state box, terminal constraints, terminal set).
    pub terminal: bool,
    /// J(x, v) = Σ ℓ + V_f as simulated (finite or not, feasible or not).
    pub cost: f32,
}

impl CheckDetail {
    /// The check's verdict: every part holds and the cost is finite.
    pub fn feasible(&self) -> bool {
        self.input_box && self.stage && self.terminal && self.cost.is_finite()
    }
}

/// What happened to the network's candidate in one step.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct CandidateDiagnosis {
    /// The candidate as the network gave it (finite) had an input outside U, clamped
    /// before the check (in the feedback form: its first input c_0, the only entry that is
    /// an input before the check).
    pub outside_u: bool,
    /// The check of the clamped candidate.
    pub detail: CheckDetail,
}

/// `controller_core::safe::SafeController` at runtime dimensions (module doc).
#[derive(Debug, Clone)]
pub struct SafeEmulation<'a> {
    /// The plant.
    pub plant: &'a EmulatedPlant,
    /// Horizon N.
    pub n: usize,
    /// (m_s, m_f).
    pub margins: (f32, f32),
    /// How a candidate's entries become inputs (`SafeController::form`; default open).
    pub form: CandidateForm,
    /// σ of the relaxed decrease (`SafeController::decrease`; default none).
    pub decrease: Option<f32>,
    /// β (`SafeController::bound`).
    bound: f32,
    safe: Option<Vec<Vec<f32>>>,
}

impl<'a> SafeEmulation<'a> {
    /// A controller without a safe sequence, with the plant's generated margins.
    pub fn new(plant: &'a EmulatedPlant, n: usize) -> Self {
        SafeEmulation {
            plant,
            n,
            margins: plant.margins,
            form: CandidateForm::Open,
            decrease: None,
            bound: f32::NEG_INFINITY,
            safe: None,
        }
    }

    /// The same controller with the relaxed decrease σ (`SafeController::with_decrease`).
    pub fn with_decrease(mut self, sigma: Option<f32>) -> Self {
        self.decrease = sigma;
        self
    }

    /// β (`SafeController::bound`).
    pub fn bound(&self) -> f32 {
        self.bound
    }

    fn next_bound(&self, x: &[f32], v: &[Vec<f32>], cost: f32) -> f32 {
        match (self.decrease, v.first()) {
            (Some(sigma), Some(v0)) => cost - sigma * self.plant.stage_cost(x, v0),
            _ => f32::NEG_INFINITY,
        }
    }

    /// The same controller with candidates of form `form` (`SafeController::with_form`).
    pub fn with_form(mut self, form: CandidateForm) -> Self {
        self.form = form;
        self
    }

    /// Whether a safe sequence exists.
    pub fn has_safe(&self) -> bool {
        self.safe.is_some()
    }

    /// `SafeController::check`: feasibility and cost of `v` from `x` (with `complete`, the
    /// last input is first set to Π_U(κ_f(x_{N−1}))).
    pub fn check(&self, x: &[f32], v: &mut [Vec<f32>], complete: bool) -> (bool, f32) {
        let d = self.check_detail(x, v, complete);
        if d.feasible() {
            (true, d.cost)
        } else {
            (false, f32::INFINITY)
        }
    }

    /// [`Self::check`] with each part of the verdict kept apart ([`CheckDetail`]); the same
    /// operations in the same order, so `feasible()` and the cost are `check`'s.
    pub fn check_detail(&self, x: &[f32], v: &mut [Vec<f32>], complete: bool) -> CheckDetail {
        self.check_detail_as(x, v, complete, false)
    }

    /// [`Self::check_detail`]; with `feedback`, entries 1 … N−1 are first realised as
    /// Π_U(κ_f(x̂_k) + v_k) (`SafeController`'s `check_as`; `v` holds the realised sequence).
    pub fn check_detail_as(
        &self,
        x: &[f32],
        v: &mut [Vec<f32>],
        complete: bool,
        feedback: bool,
    ) -> CheckDetail {
        let p = self.plant;
        let mut xk = x.to_vec();
        let (mut next, mut scratch) = (vec![0.0f32; xk.len()], StepScratch::default());
        let mut d = CheckDetail {
            input_box: true,
            stage: true,
            terminal: true,
            cost: 0.0,
        };
        let last = v.len().wrapping_sub(1);
        for (k, u) in v.iter_mut().enumerate() {
            if complete && k == last {
                *u = p.project_input(&p.terminal_input(&xk));
            } else if feedback && k >= 1 {
                let w: Vec<f32> = u
                    .iter()
                    .zip(p.terminal_input(&xk))
                    .map(|(c, kf)| *c + kf)
                    .collect();
                *u = if w.iter().all(|v| v.is_finite()) {
                    p.project_input(&w)
                } else {
                    w
                };
            }
            d.input_box &= p.project_input(u) == *u;
            d.stage &= p.stage_violation(k, &xk, u) + self.margins.0 <= 0.0;
            d.cost += p.stage_cost(&xk, u);
            p.step_into(&xk, u, &mut next, &mut scratch);
            xk.copy_from_slice(&next);
        }
        d.terminal = p.terminal_violation(&xk) + self.margins.1 <= 0.0;
        d.cost += p.terminal_cost(&xk);
        d
    }

    /// `SafeController::init_with`: adopts `sequence` (N rows of nu) if it passes the check
    /// from `x`; returns its cost.
    pub fn init_with(&mut self, x: &[f32], sequence: &[Vec<f32>]) -> Option<f32> {
        let mut v = sequence.to_vec();
        let (ok, cost) = self.check(x, &mut v, false);
        if ok {
            self.bound = self.next_bound(x, &v, cost);
            self.safe = Some(v);
            Some(cost)
        } else {
            None
        }
    }

    /// `SafeController::step_with` with the candidate `candidate` (N rows of nu).
    pub fn step_with(&mut self, x: &[f32], mut candidate: Vec<Vec<f32>>) -> EmulatedOutput {
        let mut flags = SafeFlags::EMPTY;
        if !x.iter().all(|v| v.is_finite()) {
            flags = flags.union(SafeFlags::NON_FINITE_STATE);
        }
        let mut outside_u = false;
        let feedback = self.form == CandidateForm::Feedback;
        if candidate.iter().flatten().all(|v| v.is_finite()) {
            // The feedback form's offsets are projected after κ_f is added (in the check).
            let inputs = if feedback { 1 } else { candidate.len() };
            for u in candidate.iter_mut().take(inputs) {
                let q = self.plant.project_input(u);
                outside_u |= q != *u;
                *u = q;
            }
        } else {
            flags = flags.union(SafeFlags::NON_FINITE_CANDIDATE);
        }
        let detail = self.check_detail_as(x, &mut candidate, false, feedback);
        let (c_ok, c_cost) = if detail.feasible() {
            (true, detail.cost)
        } else {
            (false, f32::INFINITY)
        };
        let diagnosis = CandidateDiagnosis { outside_u, detail };
        let Some(previous) = self.safe.take() else {
            if c_ok {
                self.bound = self.next_bound(x, &candidate, c_cost);
                let out = self.output(
                    &candidate,
                    flags
                        .union(SafeFlags::CANDIDATE)
                        .union(SafeFlags::INITIALISED),
                    (c_cost, f32::INFINITY),
                    diagnosis,
                );
                self.safe = Some(candidate);
                return out;
            }
            return self.output(
                &candidate,
                flags.union(SafeFlags::NO_SAFE),
                (c_cost, f32::INFINITY),
                diagnosis,
            );
        };
        let nu = self.plant.dims().1;
        let mut shifted: Vec<Vec<f32>> = (0..self.n)
            .map(|k| previous.get(k + 1).cloned().unwrap_or(vec![0.0; nu]))
            .collect();
        let (s_ok, s_cost) = self.check(x, &mut shifted, true);
        if !s_ok {
            flags = flags.union(SafeFlags::SAFE_INFEASIBLE);
        }
        let (chosen, flag, cost) = if c_ok && (!s_ok || c_cost <= s_cost || c_cost <= self.bound) {
            (candidate, SafeFlags::CANDIDATE, c_cost)
        } else {
            (shifted, SafeFlags::FALLBACK, s_cost)
        };
        self.bound = if cost.is_finite() {
            self.next_bound(x, &chosen, cost)
        } else {
            f32::NEG_INFINITY
        };
        let out = self.output(&chosen, flags.union(flag), (c_cost, s_cost), diagnosis);
        self.safe = Some(chosen);
        out
    }

    fn output(
        &self,
        v: &[Vec<f32>],
        flags: SafeFlags,
        (cand, safe): (f32, f32),
        diagnosis: CandidateDiagnosis,
    ) -> EmulatedOutput {
        let nu = self.plant.dims().1;
        let first = v.first().cloned().unwrap_or(vec![f32::NAN; nu]);
        EmulatedOutput {
            u: self.plant.project_input(&first),
            flags,
            candidate_cost: cand,
            safe_cost: safe,
            diagnosis,
        }
    }
}

/// The sequence net as the device evaluates it (`controller_core::safe::SequenceNet` over the
/// folded f32 layers of `deploy::sequence_rs`, the accurate tanh), reshaped into N rows of
/// nu (missing outputs NaN, surplus ignored, as `SequenceNet`).
#[derive(Debug, Clone)]
pub struct EmulatedSequenceNet {
    folded: super::export::Folded,
    n: usize,
    nu: usize,
}

impl EmulatedSequenceNet {
    /// The folded net of `seq` for horizon `n` and `nu` inputs.
    pub fn new(seq: &crate::learn::mlp::Mlp, n: usize, nu: usize) -> Self {
        EmulatedSequenceNet {
            folded: super::sequence_rs::fold(seq),
            n,
            nu,
        }
    }

    /// The candidate (c_0 … c_{N−1}) at `x`.
    pub fn sequence(&self, x: &[f32]) -> Vec<Vec<f32>> {
        let inf = vec![f32::INFINITY; x.len()];
        let ninf = vec![f32::NEG_INFINITY; x.len()];
        let y = super::export::eval_f32(&self.folded, &ninf, &inf, x, super::export::Tanh::Libm);
        (0..self.n)
            .map(|k| {
                (0..self.nu)
                    .map(|j| y.get(k * self.nu + j).copied().unwrap_or(f32::NAN))
                    .collect()
            })
            .collect()
    }
}
