//! The flat instruction tape: [`Tape`] (the compiled outputs of a [`Dag`]) and its evaluation
//! in any number type (`f64`, or num-dual's dual numbers for exact derivatives).
//!
//! Building it ([`Tape::build`]):
//! 1. order the nodes that some output needs (dead code, e.g. unused definitions, is dropped)
//!    depth-first from the outputs, the operand that needs more registers first;
//! 2. emit one instruction per operation node in that order, with a constant operand
//!    stored inline in the instruction (`x + c`, `c - x`, `x * c`, `x / c`, `c / x`), `x^2` as
//!    `x*x`, `x^-1` as `1/x`, other integer powers as `powi`; a constant is loaded into a
//!    register only where an operation has no inline form (`atan2`, `min`, `max`, `^`);
//! 3. map the values onto few registers by a linear scan over their lifetimes (a register is
//!    reused once its value has had its last use), so that the scratch stays small.
//!
//! Registers `0..nx` hold the states and `nx..nx+nu` the inputs; [`Tape::eval`] copies them
//! in, runs the instructions, and copies the outputs' registers out (a constant output is
//! loaded by a `Const` instruction, so that reading the outputs has no branch). It allocates
//! nothing once the caller's scratch vector has grown to [`Tape::n_registers`].

use super::dag::{max, min, powi, Bin, Dag, Node, NodeId, Un};
use num_dual::DualNum;
use std::fmt;

/// A register index.
type R = u32;

/// One instruction: the operation and its operands (registers or inline constants).
#[derive(Debug, Clone, Copy, PartialEq)]
pub enum Op {
    /// A constant (only for operands of operations without an inline-constant form).
    Const(f64),
    /// `a + b`
    Add(R, R),
    /// `a - b`
    Sub(R, R),
    /// `a * b`
    Mul(R, R),
    /// `a / b`
    Div(R, R),
    /// `a + c`
    AddC(R, f64),
    /// `c - a`
    CSub(f64, R),
    /// `a * c`
    MulC(R, f64),
    /// `a / c`
    DivC(R, f64),
    /// `c / a`
    CDiv(f64, R),
    /// `-a`
    Neg(R),
    /// `a * a`
    Sq(R),
    /// `1 / a`
    Recip(R),
    /// `a^n`
    Powi(R, i32),
    /// `a^c`
    Powf(R, f64),
    /// `a^b = exp(b·log a)`
    Pow(R, R),
    /// `sin a`
    Sin(R),
    /// `cos a`
    Cos(R),
    /// `tan a`
    Tan(R),
    /// `asin a`
    Asin(R),
    /// `acos a`
    Acos(R),
    /// `atan a`
    Atan(R),
    /// `exp a`
    Exp(R),
    /// `log a`
    Log(R),
    /// `sqrt a`
    Sqrt(R),
    /// `sinh a`
    Sinh(R),
    /// `cosh a`
    Cosh(R),
    /// `tanh a`
    Tanh(R),
    /// `|a|`
    Abs(R),
    /// `atan2(a, b)`
    Atan2(R, R),
    /// `min(a, b)`
    Min(R, R),
    /// `max(a, b)`
    Max(R, R),
}

impl Op {
    /// The lower-case name of the operation (`"addc"`, `"sin"`, `"sq"`, …).
    pub fn name(&self) -> String {
        let name = format!("{self:?}");
        name.split('(').next().unwrap_or("").to_lowercase()
    }
}

/// An instruction: `registers[dst] = op(…)`.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Instr {
    /// The operation.
    pub op: Op,
    /// The register written.
    pub dst: R,
}

/// The compiled outputs: instructions on registers.
#[derive(Debug, Clone, PartialEq)]
pub struct Tape {
    n_in: usize,
    n_regs: usize,
    instrs: Vec<Instr>,
    /// The register of each output.
    outs: Vec<R>,
}

/// An operand before lowering: a value number or an inline constant.
#[derive(Clone, Copy)]
enum Arg {
    V(u32),
    C(f64),
}

impl Tape {
    /// Compiles the nodes `outputs` of `dag`, whose variables are `0..n_in`.
    pub fn build(dag: &Dag, n_in: usize, outputs: &[NodeId]) -> Tape {
        let nodes = dag.nodes();
        let children = |id: usize| -> ([NodeId; 2], usize) {
            match nodes[id] {
                Node::Un(_, a) => ([a, a], 1),
                Node::Bin(_, a, b) => ([a, b], 2),
                Node::Const(_) | Node::Var(_) => ([0, 0], 0),
            }
        };
        // 1. Registers each subtree needs (Sethi–Ullman numbers; nodes are topological).
        let mut need = vec![0u32; nodes.len()];
        for id in 0..nodes.len() {
            let (c, n) = children(id);
            need[id] = match n {
                0 => 0,
                1 => need[c[0] as usize].max(1),
                _ => {
                    let (p, q) = (need[c[0] as usize], need[c[1] as usize]);
                    if p == q {
                        p + 1
                    } else {
                        p.max(q)
                    }
                }
            };
        }
        // 2. The order of evaluation: depth-first from each output, the child that needs more
        //    registers first, so that few values are alive at once; only needed nodes appear.
        let mut order: Vec<usize> = Vec::new();
        let mut seen = vec![false; nodes.len()];
        let mut stack: Vec<(usize, usize)> = Vec::new();
        for &o in outputs {
            if !seen[o as usize] {
                seen[o as usize] = true;
                stack.push((o as usize, 0));
            }
            while let Some(top) = stack.last_mut() {
                let (id, k) = *top;
                let (c, n) = children(id);
                if k < n {
                    top.1 += 1;
                    let first = usize::from(n == 2 && need[c[1] as usize] > need[c[0] as usize]);
                    let child = c[(first + k) % n] as usize;
                    if !seen[child] {
                        seen[child] = true;
                        stack.push((child, 0));
                    }
                } else {
                    order.push(id);
                    stack.pop();
                }
            }
        }
        // 3. Instructions on value numbers: inputs are 0..n_in, instruction k defines n_in + k.
        let mut ssa: Vec<Op> = Vec::new();
        let mut value: Vec<Option<u32>> = vec![None; nodes.len()];
        let arg = |value: &[Option<u32>], id: NodeId| match (nodes[id as usize], value[id as usize])
        {
            (Node::Const(c), _) => Arg::C(f64::from_bits(c)),
            (_, Some(v)) => Arg::V(v),
            (_, None) => unreachable!("children come before their parents"),
        };
        for id in order {
            let op = match nodes[id] {
                Node::Var(i) => {
                    value[id] = Some(i);
                    continue;
                }
                Node::Const(_) => continue,
                Node::Un(op, a) => {
                    let Arg::V(a) = arg(&value, a) else {
                        unreachable!("constants are folded")
                    };
                    un_op(op, a)
                }
                Node::Bin(op, a, b) => {
                    let (a, b) = (arg(&value, a), arg(&value, b));
                    match bin_op(op, a, b) {
                        Some(op) => op,
                        None => {
                            // No inline form: load the constant operand into a register first.
                            let mut reg = |x: Arg| match x {
                                Arg::V(v) => v,
                                Arg::C(c) => {
                                    ssa.push(Op::Const(c));
                                    (n_in + ssa.len() - 1) as u32
                                }
                            };
                            let (a, b) = (reg(a), reg(b));
                            bin_op(op, Arg::V(a), Arg::V(b)).unwrap_or(Op::Const(f64::NAN))
                        }
                    }
                }
            };
            ssa.push(op);
            value[id] = Some((n_in + ssa.len() - 1) as u32);
        }
        // Outputs are registers; a constant output is loaded by one instruction.
        let outs: Vec<u32> = outputs
            .iter()
            .map(|&o| match arg(&value, o) {
                Arg::V(v) => v,
                Arg::C(c) => {
                    ssa.push(Op::Const(c));
                    (n_in + ssa.len() - 1) as u32
                }
            })
            .collect();
        // 4. Registers by lifetimes.
        let n_val = n_in + ssa.len();
        let mut last_use = vec![0usize; n_val];
        for (k, op) in ssa.iter().enumerate() {
            for v in operands(op) {
                last_use[v as usize] = k;
            }
        }
        for &v in &outs {
            last_use[v as usize] = usize::MAX;
        }
        let mut reg: Vec<R> = (0..n_val as u32).collect();
        let mut free: Vec<R> = Vec::new();
        let mut n_regs = n_in;
        let mut instrs = Vec::with_capacity(ssa.len());
        for (k, op) in ssa.iter().enumerate() {
            let mut ops = operands(op);
            ops.sort_unstable();
            ops.dedup();
            for &v in &ops {
                if v as usize >= n_in && last_use[v as usize] == k {
                    free.push(reg[v as usize]);
                }
            }
            let dst = free.pop().unwrap_or_else(|| {
                n_regs += 1;
                (n_regs - 1) as R
            });
            reg[n_in + k] = dst;
            instrs.push(Instr {
                op: rename(*op, &reg),
                dst,
            });
        }
        let outs = outs.into_iter().map(|v| reg[v as usize]).collect();
        Tape {
            n_in,
            n_regs,
            instrs,
            outs,
        }
    }

    /// Whether every output is affine in the inputs (states and inputs), decided on the
    /// instructions: a register is constant, affine or other; `+`, `−`, negation, products
    /// and quotients with a constant keep affinity, every other operation of a non-constant
    /// operand is "other". Exact (no evaluation): an affine tape computes an affine function
    /// in real arithmetic.
    pub fn is_affine(&self) -> bool {
        // 0: constant, 1: affine, 2: other. Inputs are affine; unwritten registers "other".
        let mut k = vec![2u8; self.n_regs];
        for v in k.iter_mut().take(self.n_in) {
            *v = 1;
        }
        for ins in &self.instrs {
            let g = |r: R| k.get(r as usize).copied().unwrap_or(2);
            let unary = |a: u8| if a == 0 { 0 } else { 2 };
            let v = match ins.op {
                Op::Const(_) => 0,
                Op::Add(a, b) | Op::Sub(a, b) => g(a).max(g(b)),
                Op::Mul(a, b) => match (g(a), g(b)) {
                    (0, x) | (x, 0) => x,
                    _ => 2,
                },
                Op::Div(a, b) => match (g(a), g(b)) {
                    (x, 0) => x,
                    _ => 2,
                },
                Op::AddC(a, _) | Op::CSub(_, a) | Op::MulC(a, _) | Op::DivC(a, _) | Op::Neg(a) => {
                    g(a)
                }
                Op::CDiv(_, a)
                | Op::Sq(a)
                | Op::Recip(a)
                | Op::Powi(a, _)
                | Op::Powf(a, _)
                | Op::Sin(a)
                | Op::Cos(a)
                | Op::Tan(a)
                | Op::Asin(a)
                | Op::Acos(a)
                | Op::Atan(a)
                | Op::Exp(a)
                | Op::Log(a)
                | Op::Sqrt(a)
                | Op::Sinh(a)
                | Op::Cosh(a)
                | Op::Tanh(a)
                | Op::Abs(a) => unary(g(a)),
                Op::Pow(a, b) | Op::Atan2(a, b) | Op::Min(a, b) | Op::Max(a, b) => {
                    unary(g(a).max(g(b)))
                }
            };
            if let Some(d) = k.get_mut(ins.dst as usize) {
                *d = v;
            }
        }
        self.outs
            .iter()
            .all(|&r| k.get(r as usize).is_some_and(|&v| v <= 1))
    }

    /// The instructions.
    pub fn instrs(&self) -> &[Instr] {
        &self.instrs
    }
    /// The register of each output.
    pub fn outs(&self) -> &[R] {
        &self.outs
    }
    /// Number of registers (the length the scratch vector grows to).
    pub fn n_registers(&self) -> usize {
        self.n_regs
    }
    /// Evaluates all outputs at states `x` and inputs `u` (registers `0..n_in` in that order).
    #[inline]
    pub fn eval<D: DualNum<Primitive = f64> + Copy>(
        &self,
        x: &[D],
        u: &[D],
        out: &mut [D],
        scratch: &mut Vec<D>,
    ) {
        assert!(
            x.len() + u.len() == self.n_in && out.len() == self.outs.len(),
            "eval: {} states + {} inputs given for {}, {} outputs for {}",
            x.len(),
            u.len(),
            self.n_in,
            out.len(),
            self.outs.len()
        );
        if scratch.len() < self.n_regs {
            scratch.resize(self.n_regs, D::from(0.0));
        }
        let r = &mut scratch[..self.n_regs];
        // Element by element: these slices are short, a call of `memmove` costs more.
        let (rx, ru) = r[..self.n_in].split_at_mut(x.len());
        for (d, s) in rx.iter_mut().zip(x) {
            *d = *s;
        }
        for (d, s) in ru.iter_mut().zip(u) {
            *d = *s;
        }
        for ins in &self.instrs {
            let g = |i: R| r[i as usize];
            let v = match ins.op {
                Op::Const(c) => D::from(c),
                Op::Add(a, b) => g(a) + g(b),
                Op::Sub(a, b) => g(a) - g(b),
                Op::Mul(a, b) => g(a) * g(b),
                Op::Div(a, b) => g(a) / g(b),
                Op::AddC(a, c) => g(a) + c,
                Op::CSub(c, a) => D::from(c) - g(a),
                Op::MulC(a, c) => g(a) * c,
                Op::DivC(a, c) => g(a) / c,
                Op::CDiv(c, a) => D::from(c) / g(a),
                Op::Neg(a) => -g(a),
                Op::Sq(a) => g(a) * g(a),
                Op::Recip(a) => g(a).recip(),
                Op::Powi(a, n) => powi(g(a), n),
                Op::Powf(a, c) => g(a).powf(c),
                Op::Pow(a, b) => Bin::Pow.apply(g(a), g(b)),
                Op::Sin(a) => g(a).sin(),
                Op::Cos(a) => g(a).cos(),
                Op::Tan(a) => g(a).tan(),
                Op::Asin(a) => g(a).asin(),
                Op::Acos(a) => g(a).acos(),
                Op::Atan(a) => g(a).atan(),
                Op::Exp(a) => g(a).exp(),
                Op::Log(a) => g(a).ln(),
                Op::Sqrt(a) => g(a).sqrt(),
                Op::Sinh(a) => g(a).sinh(),
                Op::Cosh(a) => g(a).cosh(),
                Op::Tanh(a) => g(a).tanh(),
                Op::Abs(a) => g(a).abs(),
                Op::Atan2(a, b) => g(a).atan2(g(b)),
                Op::Min(a, b) => min(g(a), g(b)),
                Op::Max(a, b) => max(g(a), g(b)),
            };
            r[ins.dst as usize] = v;
        }
        for (o, &i) in out.iter_mut().zip(&self.outs) {
            *o = r[i as usize];
        }
    }
}

/// The instruction of a one-operand node.
fn un_op(op: Un, a: R) -> Op {
    match op {
        Un::Neg => Op::Neg(a),
        Un::Sin => Op::Sin(a),
        Un::Cos => Op::Cos(a),
        Un::Tan => Op::Tan(a),
        Un::Asin => Op::Asin(a),
        Un::Acos => Op::Acos(a),
        Un::Atan => Op::Atan(a),
        Un::Exp => Op::Exp(a),
        Un::Log => Op::Log(a),
        Un::Sqrt => Op::Sqrt(a),
        Un::Sinh => Op::Sinh(a),
        Un::Cosh => Op::Cosh(a),
        Un::Tanh => Op::Tanh(a),
        Un::Abs => Op::Abs(a),
        Un::Powi(2) => Op::Sq(a),
        Un::Powi(-1) => Op::Recip(a),
        Un::Powi(n) => Op::Powi(a, n),
        Un::Powf(c) => Op::Powf(a, f64::from_bits(c)),
    }
}

/// The instruction of a two-operand node; `None` when a constant operand has no inline form.
fn bin_op(op: Bin, a: Arg, b: Arg) -> Option<Op> {
    use Arg::{C, V};
    Some(match (op, a, b) {
        (Bin::Add, V(a), V(b)) => Op::Add(a, b),
        (Bin::Add, V(a), C(c)) | (Bin::Add, C(c), V(a)) => Op::AddC(a, c),
        (Bin::Sub, V(a), V(b)) => Op::Sub(a, b),
        (Bin::Sub, V(a), C(c)) => Op::AddC(a, -c),
        (Bin::Sub, C(c), V(a)) => Op::CSub(c, a),
        (Bin::Mul, V(a), V(b)) if a == b => Op::Sq(a),
        (Bin::Mul, V(a), V(b)) => Op::Mul(a, b),
        (Bin::Mul, V(a), C(c)) | (Bin::Mul, C(c), V(a)) => Op::MulC(a, c),
        (Bin::Div, V(a), V(b)) => Op::Div(a, b),
        (Bin::Div, V(a), C(c)) => Op::DivC(a, c),
        (Bin::Div, C(1.0), V(a)) => Op::Recip(a),
        (Bin::Div, C(c), V(a)) => Op::CDiv(c, a),
        (Bin::Pow, V(a), V(b)) => Op::Pow(a, b),
        (Bin::Atan2, V(a), V(b)) => Op::Atan2(a, b),
        (Bin::Min, V(a), V(b)) => Op::Min(a, b),
        (Bin::Max, V(a), V(b)) => Op::Max(a, b),
        _ => return None,
    })
}

/// The register operands of an instruction: `(number of operands, a, b)` of an instruction (`b` = `a` for one operand, 0 for none);
/// allocation-free, for the evaluation loops.
#[inline(always)]
pub(super) fn args(op: &Op) -> (usize, R, R) {
    match *op {
        Op::Const(_) => (0, 0, 0),
        Op::Add(a, b)
        | Op::Sub(a, b)
        | Op::Mul(a, b)
        | Op::Div(a, b)
        | Op::Pow(a, b)
        | Op::Atan2(a, b)
        | Op::Min(a, b)
        | Op::Max(a, b) => (2, a, b),
        Op::AddC(a, _)
        | Op::CSub(_, a)
        | Op::MulC(a, _)
        | Op::DivC(a, _)
        | Op::CDiv(_, a)
        | Op::Neg(a)
        | Op::Sq(a)
        | Op::Recip(a)
        | Op::Powi(a, _)
        | Op::Powf(a, _)
        | Op::Sin(a)
        | Op::Cos(a)
        | Op::Tan(a)
        | Op::Asin(a)
        | Op::Acos(a)
        | Op::Atan(a)
        | Op::Exp(a)
        | Op::Log(a)
        | Op::Sqrt(a)
        | Op::Sinh(a)
        | Op::Cosh(a)
        | Op::Tanh(a)
        | Op::Abs(a) => (1, a, a),
    }
}

/// The register operands of an instruction, as a list.
pub(super) fn operands(op: &Op) -> Vec<R> {
    let (n, a, b) = args(op);
    [a, b][..n].to_vec()
}

/// `op` with its value numbers replaced by registers.
pub(super) fn rename(op: Op, reg: &[R]) -> Op {
    let m = |v: R| reg[v as usize];
    match op {
        Op::Const(c) => Op::Const(c),
        Op::Add(a, b) => Op::Add(m(a), m(b)),
        Op::Sub(a, b) => Op::Sub(m(a), m(b)),
        Op::Mul(a, b) => Op::Mul(m(a), m(b)),
        Op::Div(a, b) => Op::Div(m(a), m(b)),
        Op::Pow(a, b) => Op::Pow(m(a), m(b)),
        Op::Atan2(a, b) => Op::Atan2(m(a), m(b)),
        Op::Min(a, b) => Op::Min(m(a), m(b)),
        Op::Max(a, b) => Op::Max(m(a), m(b)),
        Op::AddC(a, c) => Op::AddC(m(a), c),
        Op::CSub(c, a) => Op::CSub(c, m(a)),
        Op::MulC(a, c) => Op::MulC(m(a), c),
        Op::DivC(a, c) => Op::DivC(m(a), c),
        Op::CDiv(c, a) => Op::CDiv(c, m(a)),
        Op::Powi(a, n) => Op::Powi(m(a), n),
        Op::Powf(a, c) => Op::Powf(m(a), c),
        Op::Neg(a) => Op::Neg(m(a)),
        Op::Sq(a) => Op::Sq(m(a)),
        Op::Recip(a) => Op::Recip(m(a)),
        Op::Sin(a) => Op::Sin(m(a)),
        Op::Cos(a) => Op::Cos(m(a)),
        Op::Tan(a) => Op::Tan(m(a)),
        Op::Asin(a) => Op::Asin(m(a)),
        Op::Acos(a) => Op::Acos(m(a)),
        Op::Atan(a) => Op::Atan(m(a)),
        Op::Exp(a) => Op::Exp(m(a)),
        Op::Log(a) => Op::Log(m(a)),
        Op::Sqrt(a) => Op::Sqrt(m(a)),
        Op::Sinh(a) => Op::Sinh(m(a)),
        Op::Cosh(a) => Op::Cosh(m(a)),
        Op::Tanh(a) => Op::Tanh(m(a)),
        Op::Abs(a) => Op::Abs(m(a)),
    }
}

impl fmt::Display for Tape {
    /// One line per instruction, e.g. `r3 = sin r0`, then the outputs.
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        for ins in &self.instrs {
            write!(f, "r{} = ", ins.dst)?;
            match ins.op {
                Op::Const(c) => writeln!(f, "{c}")?,
                Op::AddC(a, c) => writeln!(f, "r{a} + {c}")?,
                Op::CSub(c, a) => writeln!(f, "{c} - r{a}")?,
                Op::MulC(a, c) => writeln!(f, "r{a} * {c}")?,
                Op::DivC(a, c) => writeln!(f, "r{a} / {c}")?,
                Op::CDiv(c, a) => writeln!(f, "{c} / r{a}")?,
                Op::Powi(a, n) => writeln!(f, "r{a} ^ {n}")?,
                Op::Powf(a, c) => writeln!(f, "r{a} ^ {c}")?,
                op => {
                    let name = op.name();
                    let regs: Vec<String> = operands(&op).iter().map(|r| format!("r{r}")).collect();
                    writeln!(f, "{name} {}", regs.join(", "))?
                }
            }
        }
        for (i, r) in self.outs.iter().enumerate() {
            writeln!(f, "out[{i}] = r{r}")?;
        }
        Ok(())
    }
}
