//! [`Sweep`]: the discrete map `F(x, u)` of an expression plant as one straight-line program
//! on single-assignment slots, and its exact first and second derivatives by hand-written
//! sweeps — the fast path of `Discrete::linearize` and `Discrete::lagrangian_hessian` for
//! expression plants (the dual-number path, `ExprPlant::linearize`/`lagrangian_hessian`,
//! stays as the reference it is tested against).
//!
//! **Building** ([`Sweep::build`]): for `kind = "ode"` the model's tape is inlined into every
//! stage of `M` classical RK4 steps of size `h = Ts/M`, the RK4 combinations emitted as
//! instructions in the order of the generic RK4 (`x + k₁·(h/2)`, …,
//! `x + (((k₁ + k₂·2) + k₃·2) + k₄)·(h/6)`), so that the values are the f64 step's bits; for
//! `kind = "discrete"` the tape as it is. Slots `0..nz` hold `z = (x, u)`, slot `nz + k` the
//! value of instruction `k` (no reuse: the reverse sweep reads every value).
//!
//! **Sweeps**, for an instruction `c = φ(a, b)` with local partials `φ_a, φ_b, φ_aa, φ_ab,
//! φ_bb` (computed once per instruction, in the forward sweep, from the operands' values):
//! - forward, values and tangents in `NZ = nz` directions seeded by the identity:
//!   `ċ = φ_a ȧ + φ_b ḃ` — the outputs' tangents are the rows of `∂F/∂z`;
//! - reverse with tangents (forward-over-reverse), seeded `c̄ = λᵢ` at output `i`:
//!   `ā += c̄ φ_a`, `(ā)˙ += (c̄)˙ φ_a + c̄ (φ_aa ȧ + φ_ab ḃ)`, and `b̄`, `(b̄)˙` alike with
//!   `φ_b`, `φ_ab ȧ + φ_bb ḃ` — the inputs' adjoint tangents are the rows of `∇²_z (λᵀF)`
//!   (symmetrised: `H = (H + Hᵀ)/2`).
//!
//! Both cost `O(NZ)` per instruction, against `O(NZ²)` for second-order dual numbers, and work
//! in flat per-thread buffers (grown on the first call, then reused: no allocation). Values are
//! those of the f64 tape (the same `f64` functions); derivatives agree with the dual numbers'
//! to rounding (tested to 1e-12 relative).
//!
//! **Shared forward sweep.** The OCP linearises every stage at an iterate and then asks for
//! the Hessians at the same points. [`Sweep::linearize_at`] and
//! [`Sweep::lagrangian_hessian_at`] keep one forward sweep (values, partials, tangents) per
//! stage index in the per-thread buffers, tagged with the sweep's identity and the exact bits
//! of `(x, u)`; a call at the same point reuses it instead of sweeping again (a deterministic
//! sweep of the same program at the same bits: the results are the bits a new sweep gives).

use super::super::nz::by_nz;
use super::super::MAX_NZ;
use super::partials::local;
use super::tape::{args, operands, rename, Op, Tape};
use std::cell::RefCell;
use std::sync::atomic::{AtomicU64, Ordering};

/// Source of [`Sweep`] identities (for the per-thread cache of forward sweeps).
static NEXT_ID: AtomicU64 = AtomicU64::new(0);

/// The discrete map as a program on slots, for one sampling time and sub-step count.
#[derive(Debug, Clone)]
pub struct Sweep {
    /// Identity of this program (clones share it), the key of cached forward sweeps.
    id: u64,
    nx: usize,
    nu: usize,
    /// Instruction `k` writes slot `nz + k`; its operands are slots `< nz + k`.
    code: Vec<Op>,
    /// The slot of each output `F_i`.
    outs: Vec<u32>,
    ts: f64,
    substeps: usize,
}

/// Equal programs (whatever their identities).
impl PartialEq for Sweep {
    fn eq(&self, o: &Self) -> bool {
        (
            self.nx,
            self.nu,
            &self.code,
            &self.outs,
            self.ts,
            self.substeps,
        ) == (o.nx, o.nu, &o.code, &o.outs, o.ts, o.substeps)
    }
}

/// Emits instructions; slot numbers follow the instruction count.
struct Builder {
    nz: usize,
    code: Vec<Op>,
}

impl Builder {
    fn push(&mut self, op: Op) -> u32 {
        self.code.push(op);
        (self.nz + self.code.len() - 1) as u32
    }
    /// Inlines `tape` with its states in slots `x` and inputs in slots `u`; the outputs' slots.
    fn inline(&mut self, tape: &Tape, x: &[u32], u: &[u32]) -> Vec<u32> {
        let mut reg = vec![u32::MAX; tape.n_registers().max(x.len() + u.len())];
        for (i, &s) in x.iter().chain(u).enumerate() {
            reg[i] = s;
        }
        for ins in tape.instrs() {
            let s = self.push(rename(ins.op, &reg));
            reg[ins.dst as usize] = s;
        }
        tape.outs().iter().map(|&r| reg[r as usize]).collect()
    }
    /// `a + b·c` as the generic RK4 computes it (`b·c` first).
    fn axpy(&mut self, a: u32, b: u32, c: f64) -> u32 {
        let m = self.push(Op::MulC(b, c));
        self.push(Op::Add(a, m))
    }
}

impl Sweep {
    /// The program of `F` for a tape of `nx` outputs on `(x, u)`: the tape itself when
    /// `discrete`, else `substeps` RK4 steps over `ts`.
    pub fn build(
        tape: &Tape,
        nx: usize,
        nu: usize,
        discrete: bool,
        ts: f64,
        substeps: usize,
    ) -> Self {
        let nz = nx + nu;
        let mut b = Builder {
            nz,
            code: Vec::new(),
        };
        let mut x: Vec<u32> = (0..nx as u32).collect();
        let u: Vec<u32> = (nx as u32..nz as u32).collect();
        let substeps = substeps.max(1);
        if discrete {
            x = b.inline(tape, &x, &u);
        } else {
            let h = ts / substeps as f64;
            for _ in 0..substeps {
                let k1 = b.inline(tape, &x, &u);
                let t: Vec<u32> = (0..nx).map(|i| b.axpy(x[i], k1[i], 0.5 * h)).collect();
                let k2 = b.inline(tape, &t, &u);
                let t: Vec<u32> = (0..nx).map(|i| b.axpy(x[i], k2[i], 0.5 * h)).collect();
                let k3 = b.inline(tape, &t, &u);
                let t: Vec<u32> = (0..nx).map(|i| b.axpy(x[i], k3[i], h)).collect();
                let k4 = b.inline(tape, &t, &u);
                x = (0..nx)
                    .map(|i| {
                        let s = b.push(Op::MulC(k2[i], 2.0));
                        let s = b.push(Op::Add(k1[i], s));
                        let c = b.push(Op::MulC(k3[i], 2.0));
                        let s = b.push(Op::Add(s, c));
                        let s = b.push(Op::Add(s, k4[i]));
                        let s = b.push(Op::MulC(s, h / 6.0));
                        b.push(Op::Add(x[i], s))
                    })
                    .collect();
            }
        }
        let sweep = Sweep {
            id: NEXT_ID.fetch_add(1, Ordering::Relaxed),
            nx,
            nu,
            code: b.code,
            outs: x,
            ts,
            substeps,
        };
        debug_assert!(sweep
            .code
            .iter()
            .enumerate()
            .all(|(k, op)| operands(op).iter().all(|&a| (a as usize) < nz + k)));
        sweep
    }

    /// Whether this program was built for sampling time `ts` and `substeps` RK4 sub-steps.
    pub fn is_for(&self, ts: f64, substeps: usize) -> bool {
        self.ts.to_bits() == ts.to_bits() && self.substeps == substeps.max(1)
    }
    /// Number of instructions.
    pub fn len(&self) -> usize {
        self.code.len()
    }
    /// Whether the program has no instruction (`F` copies or permutes its inputs).
    pub fn is_empty(&self) -> bool {
        self.code.is_empty()
    }
    fn nz(&self) -> usize {
        self.nx + self.nu
    }

    /// `f = F(x, u)`, `jx = ∂F/∂x` (row-major nx×nx), `ju = ∂F/∂u` (row-major nx×nu).
    pub fn linearize(&self, x: &[f64], u: &[f64], f: &mut [f64], jx: &mut [f64], ju: &mut [f64]) {
        with_work(|w| {
            by_nz!(self.nz(), self.forward_first(x, u, &mut w.scratch));
            self.outputs(&w.scratch, f, jx, ju);
        })
    }

    /// [`Sweep::linearize`] through the forward sweep cached for `stage` (see the module doc):
    /// reused if it was taken at these `(x, u)`, else swept (partials kept) and cached.
    pub fn linearize_at(
        &self,
        stage: usize,
        x: &[f64],
        u: &[f64],
        f: &mut [f64],
        jx: &mut [f64],
        ju: &mut [f64],
    ) {
        with_work(|w| {
            let fw = self.cached_forward(stage, x, u, w);
            self.outputs(&w.stages[fw], f, jx, ju);
        })
    }

    /// `hess = ∇²_{(x,u)} (λᵀF(x, u))`, row-major (nx+nu)×(nx+nu), symmetric.
    pub fn lagrangian_hessian(&self, x: &[f64], u: &[f64], lam: &[f64], hess: &mut [f64]) {
        with_work(|w| {
            by_nz!(self.nz(), self.forward(x, u, &mut w.scratch));
            let Work {
                scratch,
                adj,
                adt,
                live,
                ..
            } = w;
            by_nz!(self.nz(), self.reverse(lam, scratch, adj, adt, live));
            self.symmetrised(adt, hess);
        })
    }

    /// [`Sweep::lagrangian_hessian`] through the forward sweep cached for `stage`.
    pub fn lagrangian_hessian_at(
        &self,
        stage: usize,
        x: &[f64],
        u: &[f64],
        lam: &[f64],
        hess: &mut [f64],
    ) {
        with_work(|w| {
            let fw = self.cached_forward(stage, x, u, w);
            let Work {
                stages,
                adj,
                adt,
                live,
                ..
            } = w;
            by_nz!(self.nz(), self.reverse(lam, &stages[fw], adj, adt, live));
            self.symmetrised(adt, hess);
        })
    }

    /// The index in `w.stages` of a forward sweep (partials kept) at `(x, u)` for `stage`:
    /// the cached one if it is this program's at these bits, else a new one.
    fn cached_forward(&self, stage: usize, x: &[f64], u: &[f64], w: &mut Work) -> usize {
        if w.stages.len() <= stage {
            w.stages.resize_with(stage + 1, Forward::default);
        }
        let fw = &mut w.stages[stage];
        let (nx, nu) = (self.nx, self.nu);
        let same = fw.id == Some(self.id)
            && fw.at.len() == nx + nu
            && x[..nx]
                .iter()
                .chain(&u[..nu])
                .zip(&fw.at)
                .all(|(v, b)| v.to_bits() == *b);
        if !same {
            fw.id = None;
            by_nz!(self.nz(), self.forward(x, u, fw));
            fw.at.clear();
            fw.at
                .extend(x[..nx].iter().chain(&u[..nu]).map(|v| v.to_bits()));
            fw.id = Some(self.id);
        }
        stage
    }

    /// `F` and its Jacobians from a forward sweep.
    fn outputs(&self, fw: &Forward, f: &mut [f64], jx: &mut [f64], ju: &mut [f64]) {
        let (nx, nu) = (self.nx, self.nu);
        let nz = self.nz();
        for (i, &o) in self.outs.iter().enumerate() {
            let o = o as usize;
            f[i] = fw.val[o];
            let t = &fw.tan[o * nz..o * nz + nz];
            jx[i * nx..i * nx + nx].copy_from_slice(&t[..nx]);
            ju[i * nu..i * nu + nu].copy_from_slice(&t[nx..]);
        }
    }

    /// The Hessian `(H + Hᵀ)/2` from the inputs' adjoint tangents `adt`.
    fn symmetrised(&self, adt: &[f64], hess: &mut [f64]) {
        let nz = self.nz();
        for r in 0..nz {
            for c in 0..=r {
                let v = 0.5 * (adt[r * nz + c] + adt[c * nz + r]);
                hess[r * nz + c] = v;
                hess[c * nz + r] = v;
            }
        }
    }

    /// Values and tangents of every slot (for `∂F`).
    fn forward_first<const NZ: usize>(&self, x: &[f64], u: &[f64], w: &mut Forward) {
        self.sweep_forward::<NZ, false>(x, u, w)
    }

    /// Values, local partials and tangents of every slot (for the reverse sweep).
    fn forward<const NZ: usize>(&self, x: &[f64], u: &[f64], w: &mut Forward) {
        self.sweep_forward::<NZ, true>(x, u, w)
    }

    /// The forward sweep; the local partials are kept (for [`Sweep::reverse`]) when `KEEP`
    /// (else their second-order entries are unused, and left to the optimiser to drop).
    #[inline(always)]
    fn sweep_forward<const NZ: usize, const KEEP: bool>(
        &self,
        x: &[f64],
        u: &[f64],
        w: &mut Forward,
    ) {
        let n = NZ + self.code.len();
        w.val.resize(n, 0.0);
        w.tan.resize(n * NZ, 0.0);
        if KEEP {
            w.part.resize(self.code.len(), [0.0; 5]);
        }
        w.val[..self.nx].copy_from_slice(&x[..self.nx]);
        w.val[self.nx..NZ].copy_from_slice(&u[..self.nu]);
        w.tan[..NZ * NZ].fill(0.0);
        for i in 0..NZ {
            w.tan[i * NZ + i] = 1.0;
        }
        for (k, op) in self.code.iter().enumerate() {
            let s = NZ + k;
            let (v, p) = local(*op, &w.val);
            w.val[s] = v;
            if KEEP {
                w.part[k] = p;
            }
            let (lo, hi) = w.tan.split_at_mut(s * NZ);
            let t: &mut [f64; NZ] = (&mut hi[..NZ]).try_into().expect("NZ");
            match arity(op) {
                (0, _, _) => *t = [0.0; NZ],
                (1, a, _) => {
                    let ta: &[f64; NZ] = lo[a * NZ..a * NZ + NZ].try_into().expect("NZ");
                    match *op {
                        // The dual numbers' rounding (`ε / c`, `0 − ε`), so that these
                        // common operations give their tangents' bits.
                        Op::DivC(_, c) => {
                            for j in 0..NZ {
                                t[j] = ta[j] / c;
                            }
                        }
                        Op::CSub(..) => {
                            for j in 0..NZ {
                                t[j] = 0.0 - ta[j];
                            }
                        }
                        _ => {
                            for j in 0..NZ {
                                t[j] = ta[j] * p[0];
                            }
                        }
                    }
                }
                (_, a, b) => {
                    let ta: &[f64; NZ] = lo[a * NZ..a * NZ + NZ].try_into().expect("NZ");
                    let tb: &[f64; NZ] = lo[b * NZ..b * NZ + NZ].try_into().expect("NZ");
                    if let Op::Div(..) = *op {
                        // `(ε_a b − ε_b a) / b / b` as the dual numbers round it.
                        let (va, vb) = (w.val[a], w.val[b]);
                        let inv = 1.0 / vb;
                        for j in 0..NZ {
                            t[j] = (ta[j] * vb - tb[j] * va) * inv * inv;
                        }
                    } else {
                        for j in 0..NZ {
                            t[j] = ta[j] * p[0] + tb[j] * p[1];
                        }
                    }
                }
            }
        }
    }

    /// Adjoints `adj` and their tangents `adt`, seeded by `λ` at the outputs, after the
    /// forward sweep `w` (partials kept: [`Sweep::forward`]).
    ///
    /// `adt` is not cleared: `live[s]` says whether slot `s`'s adjoint tangent has been
    /// written in this sweep (its first write stores `0 + v`, what `+=` on a zeroed entry
    /// gives; an unwritten one reads as zeros), so the `O(n·NZ)` clear is an `O(n)` one.
    /// Operations whose local second derivatives vanish identically (sums, differences,
    /// constant scalings, `abs`, `min`, `max`; `a·b` has only `φ_ab`) skip the terms those
    /// zeros multiply, and an unwritten adjoint tangent passes nothing on through them.
    fn reverse<const NZ: usize>(
        &self,
        lam: &[f64],
        w: &Forward,
        adj: &mut Vec<f64>,
        adt: &mut Vec<f64>,
        live: &mut Vec<bool>,
    ) {
        let n = NZ + self.code.len();
        adj.clear();
        adj.resize(n, 0.0);
        live.clear();
        live.resize(n, false);
        if adt.len() < n * NZ {
            adt.resize(n * NZ, 0.0);
        }
        for (i, &o) in self.outs.iter().enumerate() {
            adj[o as usize] += lam[i];
        }
        for (k, op) in self.code.iter().enumerate().rev() {
            let s = NZ + k;
            let c = adj[s];
            let (lo, hi) = adt.split_at_mut(s * NZ);
            let ct: [f64; NZ] = if live[s] {
                (&hi[..NZ]).try_into().expect("NZ")
            } else {
                [0.0; NZ]
            };
            if c == 0.0 && ct.iter().all(|&v| v == 0.0) {
                continue;
            }
            let p = w.part[k];
            let tan = &w.tan;
            let tangent =
                |a: usize| -> &[f64; NZ] { tan[a * NZ..a * NZ + NZ].try_into().expect("NZ") };
            match *op {
                Op::Const(_) => {}
                Op::AddC(..)
                | Op::CSub(..)
                | Op::MulC(..)
                | Op::DivC(..)
                | Op::Neg(_)
                | Op::Abs(_) => {
                    let a = arity(op).1;
                    adj[a] += c * p[0];
                    if live[s] {
                        accumulate::<NZ>(lo, live, a, |j| ct[j] * p[0]);
                    }
                }
                Op::Add(..) | Op::Sub(..) | Op::Min(..) | Op::Max(..) => {
                    let (_, a, b) = arity(op);
                    adj[a] += c * p[0];
                    adj[b] += c * p[1];
                    if live[s] {
                        accumulate::<NZ>(lo, live, a, |j| ct[j] * p[0]);
                        accumulate::<NZ>(lo, live, b, |j| ct[j] * p[1]);
                    }
                }
                Op::Mul(..) => {
                    let (_, a, b) = arity(op);
                    adj[a] += c * p[0];
                    adj[b] += c * p[1];
                    let (ta, tb) = (tangent(a), tangent(b));
                    let cab = c * p[3];
                    accumulate::<NZ>(lo, live, a, |j| ct[j] * p[0] + cab * tb[j]);
                    accumulate::<NZ>(lo, live, b, |j| ct[j] * p[1] + cab * ta[j]);
                }
                _ => match arity(op) {
                    (0, _, _) => {}
                    (1, a, _) => {
                        adj[a] += c * p[0];
                        let ta = tangent(a);
                        let caa = c * p[2];
                        accumulate::<NZ>(lo, live, a, |j| ct[j] * p[0] + caa * ta[j]);
                    }
                    (_, a, b) => {
                        adj[a] += c * p[0];
                        adj[b] += c * p[1];
                        let (ta, tb) = (tangent(a), tangent(b));
                        let (caa, cab, cbb) = (c * p[2], c * p[3], c * p[4]);
                        accumulate::<NZ>(lo, live, a, |j| ct[j] * p[0] + caa * ta[j] + cab * tb[j]);
                        accumulate::<NZ>(lo, live, b, |j| ct[j] * p[1] + cab * ta[j] + cbb * tb[j]);
                    }
                },
            }
        }
        // The inputs' adjoint tangents (the Hessian's rows): zeros where never written.
        for (i, &l) in live[..NZ].iter().enumerate() {
            if !l {
                adt[i * NZ..i * NZ + NZ].fill(0.0);
            }
        }
    }
}

/// `adt[a] += v` over the NZ tangent directions, or `adt[a] = 0 + v` (the same bits as `+=`
/// on a zeroed entry) if slot `a` was not written yet in this sweep.
#[inline(always)]
fn accumulate<const NZ: usize>(
    lo: &mut [f64],
    live: &mut [bool],
    a: usize,
    v: impl Fn(usize) -> f64,
) {
    let at: &mut [f64; NZ] = (&mut lo[a * NZ..a * NZ + NZ]).try_into().expect("NZ");
    if live[a] {
        for (j, x) in at.iter_mut().enumerate() {
            *x += v(j);
        }
    } else {
        for (j, x) in at.iter_mut().enumerate() {
            *x = 0.0 + v(j);
        }
        live[a] = true;
    }
}

/// `(number of operands, a, b)` of an instruction, slots as indices.
#[inline(always)]
fn arity(op: &Op) -> (usize, usize, usize) {
    let (n, a, b) = args(op);
    (n, a as usize, b as usize)
}

/// One forward sweep: values, local partials (if kept) and tangents of every slot.
#[derive(Default)]
struct Forward {
    /// The [`Sweep`] it belongs to, if it is a cached one (see `at`).
    id: Option<u64>,
    /// The bits of `(x, u)` it was taken at (cached ones).
    at: Vec<u64>,
    val: Vec<f64>,
    part: Vec<[f64; 5]>,
    tan: Vec<f64>,
}

/// Per-thread buffers of the sweeps.
#[derive(Default)]
struct Work {
    /// The forward sweep of the uncached calls.
    scratch: Forward,
    /// The cached forward sweep of each stage index.
    stages: Vec<Forward>,
    adj: Vec<f64>,
    adt: Vec<f64>,
    /// Which slots' entries of `adt` the current reverse sweep has written.
    live: Vec<bool>,
}

fn with_work<R>(f: impl FnOnce(&mut Work) -> R) -> R {
    thread_local! {
        static W: RefCell<Work> = RefCell::new(Work::default());
    }
    W.with(|w| f(&mut w.borrow_mut()))
}
