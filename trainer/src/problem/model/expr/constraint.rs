//! [`ConstraintSet`]: the OCP's path and terminal constraints written as inequalities,
//! compiled into one instruction tape of the functions g_i(x, u) ≤ 0.
//!
//! ```toml
//! [ocp]
//! constraints = ["pos + 0.5*vel <= 1.2", "vel^2 + force^2/4 <= 9"]
//! terminal_constraints = ["pos^2 + 0.5*vel^2 <= 0.25"]
//! ```
//! Each text is `lhs <= rhs` or `lhs >= rhs` over the plant's states, inputs, parameters and
//! definitions (the names of [`SystemSpec`]); it becomes `g = lhs − rhs ≤ 0` (or
//! `g = rhs − lhs ≤ 0`). For every constraint the compiler records the variables it depends
//! on (the sparsity of its row in the OCP) and whether it is **affine** in them: a graph of
//! constants, variables, `+`, `−`, negation, products with a constant factor and quotients by a
//! constant. An affine constraint keeps constant coefficients in the OCP; the others are
//! linearised at every SQP iterate.
//!
//! Where a constraint holds (the OCP's rule, applied by `mpc::ocp`): one in states only on
//! x₁…x_N, one in inputs only on u₀…u_{N−1}, one mixing both on k = 1…N−1; a terminal
//! constraint (states only) on x_N.

use super::compile::{definitions, lower_definitions, names};
use super::dag::{Bin, Dag, Node, NodeId, Un};
use super::error::{ErrorKind, ExprError};
use super::parse;
use super::tape::Tape;
use super::SystemSpec;
use num_dual::DualNum;

/// One compiled inequality.
#[derive(Debug, Clone, PartialEq)]
pub struct ConstraintInfo {
    /// The key it was given under, e.g. `ocp.constraints[1]`.
    pub key: String,
    /// Its text.
    pub text: String,
    /// Whether it is a terminal constraint (on x_N only).
    pub terminal: bool,
    /// The variables it depends on, as indices into the stacked `(x, u)`, ascending.
    pub vars: Vec<usize>,
    /// Whether g is affine in `(x, u)` (then its row has constant coefficients).
    pub affine: bool,
}

impl ConstraintInfo {
    /// Whether it depends on a state (`nx` states come first in `vars`).
    pub fn uses_states(&self, nx: usize) -> bool {
        self.vars.iter().any(|&v| v < nx)
    }
    /// Whether it depends on an input.
    pub fn uses_inputs(&self, nx: usize) -> bool {
        self.vars.iter().any(|&v| v >= nx)
    }
}

/// The compiled constraints: path constraints first, then terminal ones, in the order given.
#[derive(Debug, Clone, PartialEq)]
pub struct ConstraintSet {
    /// One entry per constraint, in output order of the tape.
    pub items: Vec<ConstraintInfo>,
    nx: usize,
    nu: usize,
    tape: Tape,
}

impl ConstraintSet {
    /// Compiles `path` (key `ocp.constraints`) and `terminal` (key `ocp.terminal_constraints`)
    /// over the names of `spec` (its equations are not read). Errors name the key and, inside
    /// an expression, the column.
    pub fn compile(
        spec: &SystemSpec,
        path: &[String],
        terminal: &[String],
    ) -> Result<Self, ExprError> {
        let nx = spec.states.len();
        let nu = spec.inputs.len();
        let mut table = names(spec)?;
        let defs = definitions(spec, &mut table)?;
        let mut low = lower_definitions(spec, &table, &defs)?;
        let mut outputs = Vec::new();
        let mut items = Vec::new();
        let lists = [
            ("constraints", path, false),
            ("terminal_constraints", terminal, true),
        ];
        for (list, texts, is_terminal) in lists {
            for (i, text) in texts.iter().enumerate() {
                let key = format!("ocp.{list}[{i}]");
                let at = |c: usize, k: ErrorKind| ExprError::at(&key, text, c, k);
                let (lhs, op, rhs) = split(text).map_err(|(c, k)| at(c, k))?;
                let a = parse::parse_expr(&lhs).map_err(|(c, k)| at(c, k))?;
                let b = parse::parse_expr(&rhs).map_err(|(c, k)| at(c, k))?;
                let na = low.lower(&a, defs.len()).map_err(|(c, k)| at(c, k))?;
                let nb = low.lower(&b, defs.len()).map_err(|(c, k)| at(c, k))?;
                let g = match op {
                    Cmp::Le => low.dag.bin(Bin::Sub, na, nb),
                    Cmp::Ge => low.dag.bin(Bin::Sub, nb, na),
                };
                let vars = variables(&low.dag, g);
                if vars.is_empty() {
                    let msg = "it depends on no state or input (a constant inequality)".into();
                    return Err(ExprError::at(&key, text, 1, ErrorKind::Constraint(msg)));
                }
                if is_terminal && vars.iter().any(|&v| v >= nx) {
                    let name = &spec.inputs[vars.iter().find(|&&v| v >= nx).unwrap() - nx];
                    let msg = format!(
                        "a terminal constraint holds on x_N only and may not use the input `{name}`"
                    );
                    return Err(ExprError::at(&key, text, 1, ErrorKind::Constraint(msg)));
                }
                items.push(ConstraintInfo {
                    key,
                    text: text.clone(),
                    terminal: is_terminal,
                    affine: affine(&low.dag, g),
                    vars,
                });
                outputs.push(g);
            }
        }
        let tape = Tape::build(&low.dag, nx + nu, &outputs);
        Ok(ConstraintSet {
            items,
            nx,
            nu,
            tape,
        })
    }

    /// Number of constraints.
    pub fn len(&self) -> usize {
        self.items.len()
    }

    /// Whether there are none.
    pub fn is_empty(&self) -> bool {
        self.items.is_empty()
    }

    /// State dimension of the plant it was compiled for.
    pub fn nx(&self) -> usize {
        self.nx
    }

    /// Input dimension of the plant it was compiled for.
    pub fn nu(&self) -> usize {
        self.nu
    }

    /// The instruction tape of all g_i (inputs: the states, then the inputs; outputs in
    /// the order of [`ConstraintSet::items`]), e.g. for code generation.
    pub fn tape(&self) -> &Tape {
        &self.tape
    }

    /// All g_i(x, u), in any number type (f64, or dual numbers for derivatives).
    /// `out.len() == self.len()`; `scratch` is grown on first use.
    pub fn eval<D: DualNum<Primitive = f64> + Copy>(
        &self,
        x: &[D],
        u: &[D],
        out: &mut [D],
        scratch: &mut Vec<D>,
    ) {
        self.tape.eval(x, u, out, scratch)
    }
}

/// A comparison operator.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
enum Cmp {
    Le,
    Ge,
}

/// Splits `lhs <= rhs` / `lhs >= rhs` into the two sides, each padded with spaces to keep
/// the columns of the whole text.
fn split(text: &str) -> Result<(String, Cmp, String), parse::ParseError> {
    let chars: Vec<char> = text.chars().collect();
    let mut found: Vec<(usize, Cmp)> = Vec::new();
    let mut i = 0;
    while i < chars.len() {
        let next = chars.get(i + 1).copied();
        match (chars[i], next) {
            ('<', Some('=')) => {
                found.push((i, Cmp::Le));
                i += 2;
                continue;
            }
            ('>', Some('=')) => {
                found.push((i, Cmp::Ge));
                i += 2;
                continue;
            }
            ('<' | '>', _) => {
                let msg = format!(
                    "`{}` alone is not a comparison: write `<=` or `>=` (constraints are non-strict)",
                    chars[i]
                );
                return Err((i + 1, ErrorKind::Constraint(msg)));
            }
            ('=', Some('=')) => {
                let msg =
                    "`==` is not supported: write an equality as two inequalities `<=` and `>=`";
                return Err((i + 1, ErrorKind::Constraint(msg.into())));
            }
            _ => {}
        }
        i += 1;
    }
    match found.as_slice() {
        [] => Err((
            1,
            ErrorKind::Constraint("expected `lhs <= rhs` or `lhs >= rhs`: no `<=` or `>=`".into()),
        )),
        [(at, cmp)] => {
            let lhs: String = chars[..*at].iter().collect();
            let rhs: String = " ".repeat(at + 2) + &chars[at + 2..].iter().collect::<String>();
            Ok((lhs, *cmp, rhs))
        }
        [_, (at, _), ..] => Err((
            at + 1,
            ErrorKind::Constraint(
                "a second comparison: one constraint is one inequality `lhs <= rhs`".into(),
            ),
        )),
    }
}

/// The variables node `id` depends on, ascending.
fn variables(dag: &Dag, id: NodeId) -> Vec<usize> {
    let mut seen = vec![false; id as usize + 1];
    let mut vars = Vec::new();
    let mut stack = vec![id];
    while let Some(n) = stack.pop() {
        if std::mem::replace(&mut seen[n as usize], true) {
            continue;
        }
        match dag.node(n) {
            Node::Const(_) => {}
            Node::Var(i) => vars.push(i as usize),
            Node::Un(_, a) => stack.push(a),
            Node::Bin(_, a, b) => {
                stack.push(a);
                stack.push(b);
            }
        }
    }
    vars.sort_unstable();
    vars
}

/// Whether node `id` is affine in the variables.
fn affine(dag: &Dag, id: NodeId) -> bool {
    let is_const = |n: NodeId| dag.as_const(n).is_some();
    match dag.node(id) {
        Node::Const(_) | Node::Var(_) => true,
        Node::Un(Un::Neg, a) => affine(dag, a),
        Node::Un(..) => false,
        Node::Bin(Bin::Add | Bin::Sub, a, b) => affine(dag, a) && affine(dag, b),
        Node::Bin(Bin::Mul, a, b) => {
            (is_const(a) && affine(dag, b)) || (is_const(b) && affine(dag, a))
        }
        Node::Bin(Bin::Div, a, b) => is_const(b) && affine(dag, a),
        Node::Bin(..) => false,
    }
}
