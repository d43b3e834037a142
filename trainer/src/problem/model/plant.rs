//! [`ExprPlant`]: a plant written as expressions in the problem file (`kind = "ode"` or
//! `kind = "discrete"`), its discrete map F and F's exact derivatives.
//!
//! - `ode`: ẋ = f(x, u) from `rhs`, and `F(x, u) = Φ_h^M(x, u)`, `M = ocp.rk4_substeps`
//!   classical RK4 steps of size `h = Ts / M` — the same operations in the same order as the
//!   built-in plants' RK4, so a plant written as the built-in's formula gives the same bits.
//! - `discrete`: `F(x, u) = next(x, u)` directly (`ocp.ts` is only the sampling period).
//!
//! `∂F/∂x`, `∂F/∂u` and `∇²(λᵀF)` are exact, by forward-mode AD (num-dual) through
//! [`ExprModel::eval`] (and through RK4): `NZ = nx + nu` directions, `NZ` a constant picked by a
//! macro-generated `match` over `1..=MAX_NZ`. The tape's registers and the RK4 stages live in a
//! buffer per thread and number type, grown on the first call: later calls allocate nothing.
//!
//! The wrapper serialises as its [`SystemSpec`] (so a problem file round-trips and hashes by
//! what the user wrote) and compiles it when it is read: a compile error is a problem-file
//! error naming the key and the column. Equality, `Clone` and `Debug` go by the spec.

use super::expr::{compile, ExprError, ExprModel, SystemSpec};
use num_dual::{Dual2SVec64, DualNum, DualSVec64};
use serde::{Deserialize, Serialize};
use std::cell::RefCell;
use std::fmt;

/// Largest `nx + nu` of an expression plant (the dual sizes the derivatives are compiled for).
pub const MAX_NZ: usize = 16;

/// A compiled expression plant; `DISCRETE` is true for `kind = "discrete"`.
#[derive(Clone, Serialize, Deserialize)]
#[serde(try_from = "SystemSpec", into = "SystemSpec")]
pub struct ExprPlant<const DISCRETE: bool> {
    spec: SystemSpec,
    model: ExprModel,
}

/// `kind = "ode"`: ẋ = f(x, u), discretised by RK4.
pub type OdePlant = ExprPlant<false>;
/// `kind = "discrete"`: x⁺ = F(x, u).
pub type DiscretePlant = ExprPlant<true>;

impl<const DISCRETE: bool> TryFrom<SystemSpec> for ExprPlant<DISCRETE> {
    type Error = ExprError;
    fn try_from(spec: SystemSpec) -> Result<Self, ExprError> {
        let model = compile(&spec, DISCRETE)?;
        Ok(ExprPlant { spec, model })
    }
}

impl<const DISCRETE: bool> From<ExprPlant<DISCRETE>> for SystemSpec {
    fn from(p: ExprPlant<DISCRETE>) -> SystemSpec {
        p.spec
    }
}

impl<const DISCRETE: bool> PartialEq for ExprPlant<DISCRETE> {
    fn eq(&self, other: &Self) -> bool {
        self.spec == other.spec
    }
}

impl<const DISCRETE: bool> fmt::Debug for ExprPlant<DISCRETE> {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        f.debug_struct(if DISCRETE {
            "DiscretePlant"
        } else {
            "OdePlant"
        })
        .field("spec", &self.spec)
        .finish()
    }
}

/// Per-thread buffers of one number type: the tape's registers and `8·nx + nu` values
/// (x, u, RK4 stages k1..k4, the stage argument, the discrete output).
pub(super) struct Work<D> {
    pub(super) regs: Vec<D>,
    pub(super) buf: Vec<D>,
}

/// A number type with a per-thread [`Work`] buffer.
pub(super) trait Scratch: Sized + Copy + 'static {
    /// Runs `f` with this thread's buffers of this number type.
    fn with_work<R>(f: impl FnOnce(&mut Work<Self>) -> R) -> R;
}

macro_rules! scratch {
    ($($t:ty),* $(,)?) => {$(
        impl Scratch for $t {
            fn with_work<R>(f: impl FnOnce(&mut Work<Self>) -> R) -> R {
                thread_local! {
                    static W: RefCell<Work<$t>> =
                        const { RefCell::new(Work { regs: Vec::new(), buf: Vec::new() }) };
                }
                W.with(|w| f(&mut w.borrow_mut()))
            }
        }
    )*};
}

macro_rules! scratch_duals {
    ($($n:literal)*) => { scratch!(f64, $(DualSVec64<$n>, Dual2SVec64<$n>),*); };
}
scratch_duals!(1 2 3 4 5 6 7 8 9 10 11 12 13 14 15 16);

use super::nz::by_nz;

impl<const DISCRETE: bool> ExprPlant<DISCRETE> {
    /// The table as written.
    pub fn spec(&self) -> &SystemSpec {
        &self.spec
    }
    /// The compiled model (names, units, warnings, tape).
    pub fn model(&self) -> &ExprModel {
        &self.model
    }
    /// State dimension.
    pub fn nx(&self) -> usize {
        self.model.nx()
    }
    /// Input dimension.
    pub fn nu(&self) -> usize {
        self.model.nu()
    }
    /// The compiler's warnings (non-smooth functions, unused names), for the caller to show.
    pub fn warnings(&self) -> &[String] {
        self.model.warnings()
    }
    /// The same plant with parameter `name` set to `value` (recompiled).
    pub fn with_parameter(&self, name: &str, value: f64) -> Result<Self, ExprError> {
        let mut spec = self.spec.clone();
        spec.parameters.insert(name.to_string(), value);
        Self::try_from(spec)
    }
    /// The model's outputs in f64: ẋ = f(x, u) (ODE) or x⁺ = F(x, u) (discrete).
    pub fn eval(&self, x: &[f64], u: &[f64], out: &mut [f64]) {
        f64::with_work(|w| self.model.eval(x, u, out, &mut w.regs))
    }

    /// `x ← F(x, u)`; `st` holds `6·nx` values of scratch.
    fn map<D: DualNum<Primitive = f64> + Copy>(
        &self,
        ts: f64,
        substeps: usize,
        x: &mut [D],
        u: &[D],
        st: &mut [D],
        regs: &mut Vec<D>,
    ) {
        let n = x.len();
        let (k1, st) = st.split_at_mut(n);
        let (k2, st) = st.split_at_mut(n);
        let (k3, st) = st.split_at_mut(n);
        let (k4, st) = st.split_at_mut(n);
        let tmp = &mut st[..n];
        if DISCRETE {
            self.model.eval(x, u, k1, regs);
            x.copy_from_slice(k1);
            return;
        }
        let h = ts / substeps as f64;
        for _ in 0..substeps {
            self.model.eval(x, u, k1, regs);
            for i in 0..n {
                tmp[i] = x[i] + k1[i] * (0.5 * h);
            }
            self.model.eval(tmp, u, k2, regs);
            for i in 0..n {
                tmp[i] = x[i] + k2[i] * (0.5 * h);
            }
            self.model.eval(tmp, u, k3, regs);
            for i in 0..n {
                tmp[i] = x[i] + k3[i] * h;
            }
            self.model.eval(tmp, u, k4, regs);
            for i in 0..n {
                x[i] += (k1[i] + k2[i] * 2.0 + k3[i] * 2.0 + k4[i]) * (h / 6.0);
            }
        }
    }

    /// Runs `body` with per-thread buffers `(x, u, stages, registers)` of type `D`, `x` and
    /// `u` seeded by `seed(index, value)` (index over the stacked `(x, u)`).
    fn with_seeded<D: DualNum<Primitive = f64> + Scratch, R>(
        &self,
        x: &[f64],
        u: &[f64],
        seed: impl Fn(usize, f64) -> D,
        body: impl FnOnce(&mut [D], &[D], &mut [D], &mut Vec<D>) -> R,
    ) -> R {
        let (nx, nu) = (self.nx(), self.nu());
        D::with_work(|w| {
            w.buf.resize(8 * nx + nu, D::from(0.0));
            let (xd, rest) = w.buf.split_at_mut(nx);
            let (ud, st) = rest.split_at_mut(nu);
            for i in 0..nx {
                xd[i] = seed(i, x[i]);
            }
            for j in 0..nu {
                ud[j] = seed(nx + j, u[j]);
            }
            body(xd, ud, st, &mut w.regs)
        })
    }

    /// `out = F(x, u)`.
    pub fn step(&self, ts: f64, substeps: usize, x: &[f64], u: &[f64], out: &mut [f64]) {
        self.with_seeded(
            x,
            u,
            |_, v| v,
            |xd, ud, st, regs| {
                self.map(ts, substeps, xd, ud, st, regs);
                out[..xd.len()].copy_from_slice(xd);
            },
        )
    }

    /// `f = F(x, u)`, `jx = ∂F/∂x` (row-major nx×nx), `ju = ∂F/∂u` (row-major nx×nu).
    #[allow(clippy::too_many_arguments)]
    pub fn linearize(
        &self,
        ts: f64,
        substeps: usize,
        x: &[f64],
        u: &[f64],
        f: &mut [f64],
        jx: &mut [f64],
        ju: &mut [f64],
    ) {
        by_nz!(
            self.nx() + self.nu(),
            self.linearize_n(ts, substeps, x, u, f, jx, ju)
        )
    }

    #[allow(clippy::too_many_arguments)]
    fn linearize_n<const NZ: usize>(
        &self,
        ts: f64,
        substeps: usize,
        x: &[f64],
        u: &[f64],
        f: &mut [f64],
        jx: &mut [f64],
        ju: &mut [f64],
    ) where
        DualSVec64<NZ>: Scratch,
    {
        let (nx, nu) = (self.nx(), self.nu());
        self.with_seeded(
            x,
            u,
            |i, v| DualSVec64::<NZ>::from(v).derivative(i),
            |xd, ud, st, regs| {
                self.map(ts, substeps, xd, ud, st, regs);
                super::unpack_jacobian(&xd[..nx], nu, f, jx, ju);
            },
        )
    }

    /// `hess = ∇²_{(x,u)} (λᵀF(x, u))`, row-major (nx+nu)×(nx+nu).
    #[allow(clippy::too_many_arguments)]
    pub fn lagrangian_hessian(
        &self,
        ts: f64,
        substeps: usize,
        x: &[f64],
        u: &[f64],
        lam: &[f64],
        hess: &mut [f64],
    ) {
        by_nz!(
            self.nx() + self.nu(),
            self.hessian_n(ts, substeps, x, u, lam, hess)
        )
    }

    fn hessian_n<const NZ: usize>(
        &self,
        ts: f64,
        substeps: usize,
        x: &[f64],
        u: &[f64],
        lam: &[f64],
        hess: &mut [f64],
    ) where
        Dual2SVec64<NZ>: Scratch,
    {
        self.with_seeded(
            x,
            u,
            |i, v| Dual2SVec64::<NZ>::from(v).derivative(i),
            |xd, ud, st, regs| {
                self.map(ts, substeps, xd, ud, st, regs);
                let mut acc = Dual2SVec64::<NZ>::from(0.0);
                for i in 0..xd.len() {
                    acc += xd[i] * lam[i];
                }
                let h = acc
                    .v2
                    .unwrap_generic(nalgebra::Const::<NZ>, nalgebra::Const::<NZ>);
                for r in 0..NZ {
                    for c in 0..NZ {
                        hess[r * NZ + c] = h[(r, c)];
                    }
                }
            },
        )
    }
}

#[cfg(test)]
mod tests {
    use super::super::{Discrete, Pendulum, System};
    use super::*;

    const PENDULUM: &str = r#"
        states = ["theta", "omega"]
        inputs = ["u"]
        parameters = { m = 1.0, l = 1.0, g = 9.81 }
        rhs = ["omega", "u/(m*l^2) - g/l*sin(theta + pi)"]
    "#;

    fn pair(substeps: usize) -> (Discrete, Discrete) {
        let spec: SystemSpec = toml::from_str(PENDULUM).unwrap();
        let ode = System::Ode(OdePlant::try_from(spec).unwrap());
        (
            Discrete::new(System::Pendulum(Pendulum::default()), 0.05, substeps),
            Discrete::new(ode, 0.05, substeps),
        )
    }

    /// The paper's pendulum written as expressions: F, ∂F and ∇²λᵀF bit-identical to the
    /// built-in (same formula, same RK4 operations).
    #[test]
    fn pendulum_ode_is_bit_identical_to_the_built_in() {
        for substeps in [1, 3] {
            let (a, b) = pair(substeps);
            for k in 0..200 {
                let t = k as f64 * 0.37;
                let (x, u, lam) = (
                    [t.sin() * 6.0, t.cos()],
                    [15.0 * (1.3 * t).sin()],
                    [0.3, -t],
                );
                let run = |d: &Discrete| {
                    let (mut f, mut jx, mut ju, mut h, mut s) = (
                        vec![0.0; 2],
                        vec![0.0; 4],
                        vec![0.0; 2],
                        vec![0.0; 9],
                        vec![0.0; 2],
                    );
                    d.linearize(&x, &u, &mut f, &mut jx, &mut ju);
                    d.lagrangian_hessian(&x, &u, &lam, &mut h);
                    d.step(&x, &u, &mut s);
                    [f, jx, ju, h, s]
                        .concat()
                        .into_iter()
                        .map(f64::to_bits)
                        .collect::<Vec<_>>()
                };
                assert_eq!(run(&a), run(&b), "x {x:?} u {u:?}");
            }
        }
    }

    /// The built-in cart-pole is differentiated through its expression form
    /// (`CartPole::expressions`): its F is the f64 step's, bit for bit (the dual numbers'
    /// F is not: they divide as `a·(1/b)`), and ∂F and the Hessian (a sweep's) equal the
    /// dual numbers' of its Rust `rhs` to 1e-12.
    #[test]
    fn cart_pole_expression_form_gives_the_built_in_derivatives() {
        use super::super::{ad_hessian, ad_linearize, CartPole, BUILTIN_MAX_NX};
        let cp = CartPole::default();
        let close = |a: &[f64], b: &[f64], what: &str| {
            let scale = 1.0 + b.iter().fold(0.0f64, |m, v| m.max(v.abs()));
            for (p, q) in a.iter().zip(b) {
                assert!((p - q).abs() <= 1e-12 * scale, "{what}: {p} vs {q}");
            }
        };
        for substeps in [1, 2] {
            let d = Discrete::new(System::CartPole(cp.clone()), 0.05, substeps);
            assert!(d.sweep().is_some());
            for k in 0..300 {
                let t = k as f64 * 0.61;
                let x = [
                    t.sin(),
                    3.0 * (0.7 * t).cos(),
                    (1.1 * t).sin() * 2.0,
                    t.cos() * 5.0,
                ];
                let u = [20.0 * (1.3 * t).sin()];
                let lam = [0.3, -t.sin(), 1.5, t.cos() * 2.0];
                let (mut f, mut jx, mut ju, mut s) = ([0.0; 4], [0.0; 16], [0.0; 4], [0.0; 4]);
                let (mut g, mut gx, mut gu) = ([0.0; 4], [0.0; 16], [0.0; 4]);
                d.linearize(&x, &u, &mut f, &mut jx, &mut ju);
                d.step(&x, &u, &mut s);
                assert_eq!(f.map(f64::to_bits), s.map(f64::to_bits), "x {x:?}");
                ad_linearize::<_, 5, BUILTIN_MAX_NX>(
                    &cp, 0.05, substeps, &x, &u, &mut g, &mut gx, &mut gu,
                );
                close(
                    &[&f[..], &jx, &ju].concat(),
                    &[&g[..], &gx, &gu].concat(),
                    "F, ∂F",
                );
                let (mut h, mut r) = ([0.0; 25], [0.0; 25]);
                d.lagrangian_hessian(&x, &u, &lam, &mut h);
                ad_hessian::<_, 5, BUILTIN_MAX_NX>(&cp, 0.05, substeps, &x, &u, &lam, &mut r);
                close(&h, &r, "Hessian");
            }
        }
    }

    /// Timing of `Discrete::linearize`: built-in pendulum vs the same plant as expressions
    /// (`cargo test --release -p trainer --lib linearize_timing -- --ignored --nocapture`).
    #[test]
    #[ignore]
    fn linearize_timing() {
        let (a, b) = pair(1);
        let n = 1_000_000;
        for (name, d) in [("built-in pendulum", &a), ("pendulum_ode", &b)] {
            let (mut f, mut jx, mut ju) = ([0.0; 2], [0.0; 4], [0.0; 2]);
            let t0 = std::time::Instant::now();
            let mut acc = 0.0;
            for k in 0..n {
                let x = [k as f64 * 1e-6, 0.5];
                d.linearize(&x, &[1.0], &mut f, &mut jx, &mut ju);
                acc += jx[2];
            }
            let ns = t0.elapsed().as_nanos() as f64 / n as f64;
            eprintln!("{name}: {ns:.1} ns per linearize ({acc:.3})");
        }
        let chain = Discrete::new(super::super::test_plants::chain12(), 0.1, 1);
        let (x, u, lam) = ([0.1; 12], [0.2; 4], [1.0; 12]);
        let (mut f, mut jx, mut ju, mut h) = ([0.0; 12], [0.0; 144], [0.0; 48], [0.0; 256]);
        let n = 20_000;
        let t0 = std::time::Instant::now();
        for _ in 0..n {
            chain.linearize(&x, &u, &mut f, &mut jx, &mut ju);
        }
        let lin = t0.elapsed().as_nanos() as f64 / n as f64 / 1e3;
        let t0 = std::time::Instant::now();
        for _ in 0..n / 10 {
            chain.lagrangian_hessian(&x, &u, &lam, &mut h);
        }
        let hess = t0.elapsed().as_nanos() as f64 / (n / 10) as f64 / 1e3;
        eprintln!("12-state chain: linearize {lin:.1} µs, lagrangian_hessian {hess:.1} µs");
        // Dual numbers against the sweep, per call, for a small and a large plant.
        let time = |reps: usize, f: &mut dyn FnMut()| {
            let t0 = std::time::Instant::now();
            for _ in 0..reps {
                f();
            }
            t0.elapsed().as_nanos() as f64 / reps as f64
        };
        let quad = {
            let path = concat!(
                env!("CARGO_MANIFEST_DIR"),
                "/../configs/planar_quadrotor.toml"
            );
            let cfg = crate::problem::ProblemConfig::load(std::path::Path::new(path)).unwrap();
            Discrete::new(cfg.system, cfg.ocp.ts, cfg.ocp.rk4_substeps)
        };
        let cart_pole = super::super::CartPole::default();
        let cart = Discrete::new(
            System::Ode(OdePlant::try_from(cart_pole.expressions()).unwrap()),
            0.05,
            1,
        );
        for (name, d, reps) in [
            ("pendulum_ode", &b, 200_000),
            ("cart-pole as expressions", &cart, 100_000),
            ("planar quadrotor", &quad, 20_000),
            ("12-state chain", &chain, 2_000),
        ] {
            let System::Ode(p) = &d.system else {
                panic!("an ODE plant")
            };
            let sw = p.model().sweep(d.ts, d.substeps);
            let (nx, nu) = (p.nx(), p.nu());
            let (x, u, lam) = (vec![0.1; nx], vec![0.2; nu], vec![1.0; nx]);
            let (mut f, mut jx, mut ju) = (vec![0.0; nx], vec![0.0; nx * nx], vec![0.0; nx * nu]);
            let mut h = vec![0.0; (nx + nu) * (nx + nu)];
            let (ts, m) = (d.ts, d.substeps);
            let ld = time(reps, &mut || {
                p.linearize(ts, m, &x, &u, &mut f, &mut jx, &mut ju)
            });
            let ls = time(reps, &mut || sw.linearize(&x, &u, &mut f, &mut jx, &mut ju));
            let hd = time(reps, &mut || {
                p.lagrangian_hessian(ts, m, &x, &u, &lam, &mut h)
            });
            let hs = time(reps, &mut || sw.lagrangian_hessian(&x, &u, &lam, &mut h));
            eprintln!(
                "{name}: linearize dual {ld:.0} ns, sweep {ls:.0} ns; hessian dual {hd:.0} ns, sweep {hs:.0} ns"
            );
        }
    }
}
