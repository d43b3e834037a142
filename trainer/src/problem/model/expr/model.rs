//! [`ExprModel`]: a compiled expression model — names, units, warnings and the instruction
//! tape that evaluates all `nx` outputs (ẋ for an ODE, x⁺ for a discrete system) at once.

use super::tape::Tape;
use super::Sweep;
use num_dual::DualNum;
use std::collections::BTreeMap;
use std::fmt;

/// A model compiled by [`compile`](super::compile).
#[derive(Debug, Clone, PartialEq)]
pub struct ExprModel {
    pub(super) discrete: bool,
    pub(super) states: Vec<String>,
    pub(super) inputs: Vec<String>,
    pub(super) units: BTreeMap<String, String>,
    pub(super) warnings: Vec<String>,
    pub(super) tape: Tape,
}

impl ExprModel {
    /// State dimension n_x (= number of outputs).
    pub fn nx(&self) -> usize {
        self.states.len()
    }
    /// Input dimension n_u.
    pub fn nu(&self) -> usize {
        self.inputs.len()
    }
    /// True for `kind = "discrete"` (outputs are x⁺), false for an ODE (outputs are ẋ).
    pub fn is_discrete(&self) -> bool {
        self.discrete
    }
    /// State names, in order.
    pub fn state_names(&self) -> &[String] {
        &self.states
    }
    /// Input names, in order.
    pub fn input_names(&self) -> &[String] {
        &self.inputs
    }
    /// The `units` table (name → unit).
    pub fn units(&self) -> &BTreeMap<String, String> {
        &self.units
    }
    /// The unit of a state, input, parameter or definition, if given.
    pub fn unit(&self, name: &str) -> Option<&str> {
        self.units.get(name).map(String::as_str)
    }
    /// Warnings of the compilation: where a non-smooth function (`abs`, `min`, `max`) is used
    /// ("sensitivities are one-sided at their kinks"), and unused parameters or definitions.
    pub fn warnings(&self) -> &[String] {
        &self.warnings
    }
    /// Number of instructions of the tape (after common-subexpression elimination).
    pub fn n_instructions(&self) -> usize {
        self.tape.instrs().len()
    }
    /// Number of instructions that compute `f` (e.g. `"sin"`, `"mul"`, `"powi"`), for tests
    /// and reports; names are those of the listing ([`fmt::Display`]).
    pub fn count_op(&self, f: &str) -> usize {
        self.tape
            .instrs()
            .iter()
            .filter(|i| i.op.name() == f)
            .count()
    }
    /// Whether every output (ẋ or x⁺) is affine in (x, u), decided exactly on the tape
    /// (see `Tape::is_affine`): then RK4 of an ODE, a composition of affine maps with u held
    /// over the step, is affine too.
    pub fn is_affine(&self) -> bool {
        self.tape.is_affine()
    }
    /// The discrete map `F` of this model as a [`Sweep`] (RK4 over `ts` with `substeps`
    /// sub-steps for an ODE; the tape itself for a discrete model), for fast exact derivatives.
    pub fn sweep(&self, ts: f64, substeps: usize) -> Sweep {
        Sweep::build(
            &self.tape,
            self.nx(),
            self.nu(),
            self.discrete,
            ts,
            substeps,
        )
    }
    /// The instruction tape (read-only; the code generators of `deploy` translate it).
    pub fn tape(&self) -> &Tape {
        &self.tape
    }
    /// Number of registers: the length `scratch` grows to in [`ExprModel::eval`].
    pub fn n_registers(&self) -> usize {
        self.tape.n_registers()
    }
    /// Evaluates all outputs: `out = f(x, u)` (ODE) or `out = F(x, u)` (discrete), in `f64` or
    /// in dual numbers (exact derivatives). `x.len() == nx`, `u.len() == nu`,
    /// `out.len() == nx`; `scratch` is grown on the first call and reused, so later calls
    /// allocate nothing.
    #[inline]
    pub fn eval<D: DualNum<Primitive = f64> + Copy>(
        &self,
        x: &[D],
        u: &[D],
        out: &mut [D],
        scratch: &mut Vec<D>,
    ) {
        assert_eq!(
            x.len(),
            self.nx(),
            "ExprModel::eval: x has the wrong length"
        );
        self.tape.eval(x, u, out, scratch)
    }
}

impl fmt::Display for ExprModel {
    /// The tape: registers `r0..` hold the states, then the inputs; one line per instruction.
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        let names: Vec<String> = self
            .states
            .iter()
            .chain(&self.inputs)
            .enumerate()
            .map(|(i, n)| format!("r{i} = {n}"))
            .collect();
        writeln!(f, "# {}", names.join(", "))?;
        write!(f, "{}", self.tape)
    }
}
