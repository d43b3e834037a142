//! [`compile`]: a [`SystemSpec`] → an [`ExprModel`], with every check of the table.
//!
//! In order: the names (states, inputs, parameters: identifiers, none twice, none `pi` or a
//! function, parameters finite, at least one state), the equation key (`rhs` for an ODE,
//! `next` for a discrete system) and the number of equations, then each definition and
//! equation is parsed and lowered into one hash-consed [`Dag`]: names are resolved (a
//! parameter becomes its value, a definition the node of its expression, so it is computed
//! once however often it is used), constants are folded and a constant part that is not finite
//! is an error. Last, the `units` keys, the warnings (non-smooth functions, unused
//! definitions or parameters) and the [`Tape`] of the outputs.

use super::dag::{Bin, Dag, Node, NodeId, Un};
use super::error::{ErrorKind, ExprError};
use super::parse::{self, Ast, AstKind, BinOp, Func};
use super::tape::Tape;
use super::{ExprModel, SystemSpec};
use std::collections::{HashMap, HashSet};

/// What a name stands for.
#[derive(Debug, Clone, Copy)]
enum Binding {
    /// State `i` or input `i - nx`.
    Var(u32),
    /// A parameter's value.
    Param(f64),
    /// Definition `i`.
    Def(usize),
}

/// A name with what it stands for and where it was given.
#[derive(Debug, Clone)]
pub(super) struct Entry {
    binding: Binding,
    /// What it is, with an article: `a state`, `an input`, `a parameter`, `a definition`.
    what: String,
    /// The key that gives it.
    key: String,
}

/// Checks a `[system]` table and compiles its equations (`rhs` when `discrete` is false,
/// `next` when it is true) into an [`ExprModel`].
pub fn compile(spec: &SystemSpec, discrete: bool) -> Result<ExprModel, ExprError> {
    let nx = spec.states.len();
    let mut table = names(spec)?;
    let (eq_name, equations) = equations(spec, discrete)?;
    check_count(spec, eq_name, equations)?;
    let defs = definitions(spec, &mut table)?;
    let mut eqs: Vec<(String, &str, Ast)> = Vec::new();
    for (i, text) in equations.iter().enumerate() {
        let key = format!("system.{eq_name}[{i}]");
        let ast = parse::parse_expr(text).map_err(|(c, k)| ExprError::at(&key, text, c, k))?;
        eqs.push((key, text, ast));
    }

    // Lowering into one graph.
    let mut low = lower_definitions(spec, &table, &defs)?;
    let mut outputs = Vec::with_capacity(nx);
    for (key, text, ast) in &eqs {
        let node = low
            .lower(ast, defs.len())
            .map_err(|(c, k)| ExprError::at(key, text, c, k))?;
        outputs.push(node);
    }

    if let Some(t) = &spec.time_unit {
        let ok =
            !t.trim().is_empty() && t.chars().count() <= 16 && !t.chars().any(char::is_control);
        if !ok {
            let kind = ErrorKind::BadTimeUnit { unit: t.clone() };
            return Err(ExprError::key("system.time_unit", kind));
        }
    }
    for name in spec.units.keys() {
        if !table.contains_key(name) {
            let kind = ErrorKind::UnknownUnitName { name: name.clone() };
            return Err(ExprError::key(format!("system.units.{name}"), kind));
        }
    }

    let mut sources: Vec<(&str, &str, &Ast)> = Vec::new();
    for ((key, ast), text) in defs.iter().zip(&spec.definitions) {
        sources.push((key, text, ast));
    }
    for (key, text, ast) in &eqs {
        sources.push((key, text, ast));
    }
    let warnings = warnings(&sources, &table, &low.used);

    let tape = Tape::build(&low.dag, nx + spec.inputs.len(), &outputs);
    Ok(ExprModel {
        discrete,
        states: spec.states.clone(),
        inputs: spec.inputs.clone(),
        units: spec.units.clone(),
        warnings,
        tape,
    })
}

/// The name table of a `[system]` table: states, inputs and parameters, each checked.
pub(super) fn names(spec: &SystemSpec) -> Result<HashMap<String, Entry>, ExprError> {
    if spec.states.is_empty() {
        return Err(ExprError::key("system.states", ErrorKind::EmptyStates));
    }
    let mut table: HashMap<String, Entry> = HashMap::new();
    let lists = [
        ("states", "a state", &spec.states),
        ("inputs", "an input", &spec.inputs),
    ];
    let mut var = 0u32;
    for (list, what, names) in lists {
        for (i, name) in names.iter().enumerate() {
            let key = format!("system.{list}[{i}]");
            declare(&mut table, name, Binding::Var(var), what, key)?;
            var += 1;
        }
    }
    for (name, &value) in &spec.parameters {
        let key = format!("system.parameters.{name}");
        if !value.is_finite() {
            let kind = ErrorKind::NonFiniteParameter {
                name: name.clone(),
                value,
            };
            return Err(ExprError::key(key, kind));
        }
        declare(&mut table, name, Binding::Param(value), "a parameter", key)?;
    }
    Ok(table)
}

/// Checks that there is one equation per state.
fn check_count(spec: &SystemSpec, eq_name: &str, equations: &[String]) -> Result<(), ExprError> {
    let nx = spec.states.len();
    let count =
        |msg: String| ExprError::key(format!("system.{eq_name}"), ErrorKind::EquationCount(msg));
    if equations.len() < nx {
        let missing: Vec<&str> = spec.states[equations.len()..]
            .iter()
            .map(String::as_str)
            .collect();
        return Err(count(format!(
            "{nx} states but {} equation{}: no equation for {} (one expression per state, in the order of `states`)",
            equations.len(),
            if equations.len() == 1 { "" } else { "s" },
            missing.iter().map(|s| format!("`{s}`")).collect::<Vec<_>>().join(", ")
        )));
    }
    if equations.len() > nx {
        let key = format!("system.{eq_name}[{nx}]");
        let kind = ErrorKind::EquationCount(format!(
            "{} equations for {nx} states: this one and any after it have no state",
            equations.len()
        ));
        return Err(ExprError::at(key, &equations[nx], 1, kind));
    }
    Ok(())
}

/// Parses the definitions and adds their names to `table`.
pub(super) fn definitions(
    spec: &SystemSpec,
    table: &mut HashMap<String, Entry>,
) -> Result<Vec<(String, Ast)>, ExprError> {
    // Definitions: names first (so that a later one used too early is recognised), then bodies.
    let mut defs: Vec<(String, Ast)> = Vec::new();
    for (i, text) in spec.definitions.iter().enumerate() {
        let key = format!("system.definitions[{i}]");
        let (name, col, ast) =
            parse::parse_definition(text).map_err(|(c, k)| ExprError::at(&key, text, c, k))?;
        if let Some(first) = clash(table, &name) {
            let kind = ErrorKind::Duplicate { name, first };
            return Err(ExprError::at(key, text, col, kind));
        }
        table.insert(
            name.clone(),
            Entry {
                binding: Binding::Def(i),
                what: "a definition".into(),
                key: key.clone(),
            },
        );
        defs.push((key, ast));
    }
    Ok(defs)
}

/// A lowering with the definitions' nodes made (in order).
pub(super) fn lower_definitions<'a>(
    spec: &SystemSpec,
    table: &'a HashMap<String, Entry>,
    defs: &[(String, Ast)],
) -> Result<Lower<'a>, ExprError> {
    let mut low = Lower {
        table,
        dag: Dag::new(),
        def_nodes: Vec::new(),
        used: HashSet::new(),
    };
    for (i, (key, ast)) in defs.iter().enumerate() {
        let text = &spec.definitions[i];
        let node = low
            .lower(ast, i)
            .map_err(|(c, k)| ExprError::at(key, text, c, k))?;
        low.def_nodes.push(node);
    }
    Ok(low)
}

/// Where `abs`, `min`, `max` are used, and the parameters and definitions never used.
fn warnings(
    sources: &[(&str, &str, &Ast)],
    table: &HashMap<String, Entry>,
    used: &HashSet<String>,
) -> Vec<String> {
    let mut out = Vec::new();
    for (key, text, ast) in sources {
        parse::visit(ast, &mut |n| {
            if let AstKind::Call(f, _) = &n.kind {
                if !f.is_smooth() {
                    out.push(format!(
                        "{key}, column {} of `{text}`: `{}` is not smooth: sensitivities are one-sided at their kinks",
                        n.col,
                        f.name()
                    ));
                }
            }
        });
    }
    let mut entries: Vec<(&String, &Entry)> = table.iter().collect();
    entries.sort_by_key(|(name, e)| order(name, e));
    for (name, e) in entries {
        if matches!(e.binding, Binding::Param(_) | Binding::Def(_)) && !used.contains(name) {
            out.push(format!(
                "{}: {} `{name}` is never used",
                e.key,
                e.what.trim_start_matches("a ")
            ));
        }
    }
    out
}

/// The equations to compile and their key (`rhs` or `next`).
fn equations(spec: &SystemSpec, discrete: bool) -> Result<(&'static str, &[String]), ExprError> {
    let err = |key: &str, msg: &str| Err(ExprError::key(key, ErrorKind::EquationKey(msg.into())));
    match (discrete, &spec.rhs, &spec.next) {
        (false, Some(rhs), None) => Ok(("rhs", rhs)),
        (true, None, Some(next)) => Ok(("next", next)),
        (false, _, Some(_)) => err(
            "system.next",
            "`next` (the state at the next sample) is for kind = \"discrete\"; an ODE gives `rhs` (dx/dt)",
        ),
        (true, Some(_), _) => err(
            "system.rhs",
            "`rhs` (dx/dt) is for kind = \"ode\"; a discrete system gives `next` (the state at the next sample)",
        ),
        (false, None, None) => err("system.rhs", "missing: an ODE needs `rhs`, one expression of dx/dt per state"),
        (true, None, None) => err(
            "system.next",
            "missing: a discrete system needs `next`, one expression of the next state per state",
        ),
    }
}

/// The order of names in messages: variables (states, then inputs), parameters by name,
/// definitions in order.
fn order<'a>(name: &'a str, e: &Entry) -> (u8, usize, &'a str) {
    match e.binding {
        Binding::Var(i) => (0, i as usize, name),
        Binding::Param(_) => (1, 0, name),
        Binding::Def(j) => (2, j, name),
    }
}

/// What `name` already is, if anything (including `pi` and the functions).
fn clash(table: &HashMap<String, Entry>, name: &str) -> Option<String> {
    if name == "pi" {
        Some("the constant π".into())
    } else if Func::from_name(name).is_some() {
        Some("a function".into())
    } else {
        table.get(name).map(|e| format!("{} (`{}`)", e.what, e.key))
    }
}

/// Adds a state, input or parameter name to the table after checking it.
fn declare(
    table: &mut HashMap<String, Entry>,
    name: &str,
    binding: Binding,
    what: &str,
    key: String,
) -> Result<(), ExprError> {
    if !parse::is_name(name) {
        let kind = ErrorKind::InvalidName { name: name.into() };
        return Err(ExprError::key(key, kind));
    }
    if let Some(first) = clash(table, name) {
        let kind = ErrorKind::Duplicate {
            name: name.into(),
            first,
        };
        return Err(ExprError::key(key, kind));
    }
    let entry = Entry {
        binding,
        what: what.into(),
        key,
    };
    table.insert(name.into(), entry);
    Ok(())
}

/// The graph's operation of a binary operator of the syntax.
fn bin_op(op: BinOp) -> Bin {
    match op {
        BinOp::Add => Bin::Add,
        BinOp::Sub => Bin::Sub,
        BinOp::Mul => Bin::Mul,
        BinOp::Div => Bin::Div,
        BinOp::Pow => Bin::Pow,
    }
}

/// The lowering of syntax trees into the graph.
pub(super) struct Lower<'a> {
    table: &'a HashMap<String, Entry>,
    /// The graph.
    pub(super) dag: Dag,
    /// The node of each definition lowered so far.
    def_nodes: Vec<NodeId>,
    /// The parameters and definitions used.
    pub(super) used: HashSet<String>,
}

impl Lower<'_> {
    /// The node of `ast`, where definitions `0..visible` may be used.
    pub(super) fn lower(&mut self, ast: &Ast, visible: usize) -> Result<NodeId, parse::ParseError> {
        let id = match &ast.kind {
            AstKind::Num(v) => return Ok(self.dag.constant(*v)),
            AstKind::Name(name) => return self.name(name, ast.col, visible),
            AstKind::Neg(a) => {
                let a = self.lower(a, visible)?;
                self.dag.un(Un::Neg, a)
            }
            AstKind::Bin(op, a, b) => {
                let (a, b) = (self.lower(a, visible)?, self.lower(b, visible)?);
                self.dag.bin(bin_op(*op), a, b)
            }
            AstKind::Chain(first, rest) => {
                // Left to right, as the binary tree `((a ± b) ± c) …` was: the same graph;
                // each partial result checked like a `Bin` node.
                let mut acc = self.lower(first, visible)?;
                for (op, b) in rest {
                    let b = self.lower(b, visible)?;
                    acc = self.dag.bin(bin_op(*op), acc, b);
                    self.finite_constant(acc, ast.col)?;
                }
                acc
            }
            AstKind::Call(f, args) => {
                let mut ids = Vec::with_capacity(args.len());
                for a in args {
                    ids.push(self.lower(a, visible)?);
                }
                match (binary(*f), unary(*f), ids.as_slice()) {
                    (Some(op), _, &[a, b]) => self.dag.bin(op, a, b),
                    (_, Some(op), &[a]) => self.dag.un(op, a),
                    _ => {
                        let kind = ErrorKind::Arity {
                            func: f.name().into(),
                            expected: f.arity(),
                            got: ids.len(),
                        };
                        return Err((ast.col, kind));
                    }
                }
            }
        };
        self.finite_constant(id, ast.col)
    }

    /// `id`, unless it is a constant that is not finite (an error at column `col`).
    fn finite_constant(&self, id: NodeId, col: usize) -> Result<NodeId, parse::ParseError> {
        match self.dag.node(id) {
            Node::Const(b) if !f64::from_bits(b).is_finite() => Err((
                col,
                ErrorKind::NonFiniteConstant {
                    value: f64::from_bits(b),
                },
            )),
            _ => Ok(id),
        }
    }

    fn name(
        &mut self,
        name: &str,
        col: usize,
        visible: usize,
    ) -> Result<NodeId, parse::ParseError> {
        let Some(entry) = self.table.get(name) else {
            return Err((
                col,
                ErrorKind::UnknownName {
                    name: name.into(),
                    known: self.known(visible),
                },
            ));
        };
        match entry.binding {
            Binding::Var(i) => Ok(self.dag.var(i)),
            Binding::Param(v) => {
                self.used.insert(name.into());
                Ok(self.dag.constant(v))
            }
            Binding::Def(j) if j < visible => {
                self.used.insert(name.into());
                Ok(self.def_nodes[j])
            }
            Binding::Def(_) => Err((
                col,
                ErrorKind::UsedBeforeDefined {
                    name: name.into(),
                    defined_at: entry.key.clone(),
                },
            )),
        }
    }

    /// The names usable where definitions `0..visible` are defined (for messages).
    fn known(&self, visible: usize) -> String {
        let mut groups: [(&str, Vec<(&String, &Entry)>); 4] = [
            ("states", vec![]),
            ("inputs", vec![]),
            ("parameters", vec![]),
            ("definitions", vec![]),
        ];
        for (name, e) in self.table {
            let g = match e.binding {
                Binding::Var(_) if e.what == "a state" => 0,
                Binding::Var(_) => 1,
                Binding::Param(_) => 2,
                Binding::Def(j) if j < visible => 3,
                Binding::Def(_) => continue,
            };
            groups[g].1.push((name, e));
        }
        let mut parts = Vec::new();
        for (label, mut names) in groups {
            if names.is_empty() {
                continue;
            }
            names.sort_by_key(|(name, e)| order(name, e));
            let list: Vec<&str> = names.iter().map(|(n, _)| n.as_str()).collect();
            parts.push(format!("{label} {}", list.join(", ")));
        }
        parts.push("the constant pi".into());
        parts.join("; ")
    }
}

/// The graph operation of a two-argument function.
fn binary(f: Func) -> Option<Bin> {
    match f {
        Func::Atan2 => Some(Bin::Atan2),
        Func::Min => Some(Bin::Min),
        Func::Max => Some(Bin::Max),
        _ => None,
    }
}

/// The graph operation of a one-argument function.
fn unary(f: Func) -> Option<Un> {
    Some(match f {
        Func::Sin => Un::Sin,
        Func::Cos => Un::Cos,
        Func::Tan => Un::Tan,
        Func::Asin => Un::Asin,
        Func::Acos => Un::Acos,
        Func::Atan => Un::Atan,
        Func::Exp => Un::Exp,
        Func::Log => Un::Log,
        Func::Sqrt => Un::Sqrt,
        Func::Sinh => Un::Sinh,
        Func::Cosh => Un::Cosh,
        Func::Tanh => Un::Tanh,
        Func::Abs => Un::Abs,
        Func::Atan2 | Func::Min | Func::Max => return None,
    })
}
