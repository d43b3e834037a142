//! The expression graph [`Dag`]: hash-consed nodes, so that every distinct subexpression
//! exists once (common-subexpression elimination), with constants folded as nodes are made.
//!
//! Nodes are only created through [`Dag::un`], [`Dag::bin`] and [`Dag::pow`], which
//! - fold an operation whose operands are all constants (in `f64`, with the very functions
//!   the tape uses, so folding never changes a result);
//! - apply rewrites that are exact in IEEE arithmetic: `x*1 = x`, `x/1 = x`, `x*(-1) = -x`,
//!   `x/(-1) = -x`, `-(-x) = x`, `x - c = x + (-c)`, `a + (-b) = a - b`, `a - (-b) = a + b`,
//!   `x^0 = 1`, `x^1 = x`; and the convention `x^0.5 = sqrt(x)`;
//! - put the operands of `+` and `*` in a canonical order (exact: both commute bit for bit),
//!   so that `a*b` and `b*a` are one node.
//!
//! Children always have smaller ids than their parents: the arena is in topological order.
//! [`Un`] and [`Bin`] also own the meaning of every operation for any number type (`apply`),
//! shared by the folding here and by the tape.

use num_dual::DualNum;
use std::collections::HashMap;

/// Index of a node in the [`Dag`].
pub type NodeId = u32;

/// Largest |n| of an integer exponent evaluated by repeated multiplication (`powi`).
pub const MAX_POWI: f64 = 64.0;

/// A one-operand operation.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Hash)]
pub enum Un {
    /// `-x`
    Neg,
    /// `sin x`
    Sin,
    /// `cos x`
    Cos,
    /// `tan x`
    Tan,
    /// `asin x`
    Asin,
    /// `acos x`
    Acos,
    /// `atan x`
    Atan,
    /// `exp x`
    Exp,
    /// `log x` (natural)
    Log,
    /// `sqrt x`
    Sqrt,
    /// `sinh x`
    Sinh,
    /// `cosh x`
    Cosh,
    /// `tanh x`
    Tanh,
    /// `|x|`
    Abs,
    /// `x^n`, n an integer with |n| ≤ [`MAX_POWI`], n ∉ {0, 1}
    Powi(i32),
    /// `x^c`, c a constant that is not such an integer (stored as bits for hashing)
    Powf(u64),
}

/// A two-operand operation.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Hash)]
pub enum Bin {
    /// `a + b`
    Add,
    /// `a - b`
    Sub,
    /// `a * b`
    Mul,
    /// `a / b`
    Div,
    /// `a ^ b` with a non-constant exponent: `exp(b·log a)` (needs `a > 0`)
    Pow,
    /// `atan2(a, b)`
    Atan2,
    /// `min(a, b)`
    Min,
    /// `max(a, b)`
    Max,
}

/// A node: a constant (as bits), a variable (states, then inputs), or an operation.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Hash)]
pub enum Node {
    /// A number, as `f64::to_bits`.
    Const(u64),
    /// Variable `i`: state `i` for `i < nx`, else input `i - nx`.
    Var(u32),
    /// `op(a)`
    Un(Un, NodeId),
    /// `op(a, b)`
    Bin(Bin, NodeId, NodeId),
}

/// `x^n` for an integer n: `x*x` for 2, `1/x` for −1, `powi` otherwise.
#[inline(always)]
pub fn powi<D: DualNum<Primitive = f64> + Copy>(x: D, n: i32) -> D {
    match n {
        2 => x * x,
        -1 => x.recip(),
        _ => x.powi(n),
    }
}

/// `min(a, b)` by the values (at a tie, `a` with its derivatives).
#[inline(always)]
pub fn min<D: DualNum<Primitive = f64> + Copy>(a: D, b: D) -> D {
    if b.re() < a.re() {
        b
    } else {
        a
    }
}

/// `max(a, b)` by the values (at a tie, `a` with its derivatives).
#[inline(always)]
pub fn max<D: DualNum<Primitive = f64> + Copy>(a: D, b: D) -> D {
    if b.re() > a.re() {
        b
    } else {
        a
    }
}

impl Un {
    /// The operation in any number type.
    #[inline(always)]
    pub fn apply<D: DualNum<Primitive = f64> + Copy>(self, x: D) -> D {
        match self {
            Un::Neg => -x,
            Un::Sin => x.sin(),
            Un::Cos => x.cos(),
            Un::Tan => x.tan(),
            Un::Asin => x.asin(),
            Un::Acos => x.acos(),
            Un::Atan => x.atan(),
            Un::Exp => x.exp(),
            Un::Log => x.ln(),
            Un::Sqrt => x.sqrt(),
            Un::Sinh => x.sinh(),
            Un::Cosh => x.cosh(),
            Un::Tanh => x.tanh(),
            Un::Abs => x.abs(),
            Un::Powi(n) => powi(x, n),
            Un::Powf(c) => x.powf(f64::from_bits(c)),
        }
    }
}

impl Bin {
    /// The operation in any number type.
    #[inline(always)]
    pub fn apply<D: DualNum<Primitive = f64> + Copy>(self, a: D, b: D) -> D {
        match self {
            Bin::Add => a + b,
            Bin::Sub => a - b,
            Bin::Mul => a * b,
            Bin::Div => a / b,
            Bin::Pow => a.powd(b),
            Bin::Atan2 => a.atan2(b),
            Bin::Min => min(a, b),
            Bin::Max => max(a, b),
        }
    }
}

/// The hash-consed expression graph.
#[derive(Debug, Default)]
pub struct Dag {
    nodes: Vec<Node>,
    index: HashMap<Node, NodeId>,
}

impl Dag {
    /// An empty graph.
    pub fn new() -> Self {
        Dag::default()
    }
    /// The nodes in topological order (children first).
    pub fn nodes(&self) -> &[Node] {
        &self.nodes
    }
    /// The node of that id.
    pub fn node(&self, id: NodeId) -> Node {
        self.nodes[id as usize]
    }
    /// The value of a constant node.
    pub fn as_const(&self, id: NodeId) -> Option<f64> {
        match self.node(id) {
            Node::Const(b) => Some(f64::from_bits(b)),
            _ => None,
        }
    }
    fn intern(&mut self, n: Node) -> NodeId {
        if let Some(&id) = self.index.get(&n) {
            return id;
        }
        let id = NodeId::try_from(self.nodes.len()).unwrap_or(NodeId::MAX);
        self.nodes.push(n);
        self.index.insert(n, id);
        id
    }
    /// The constant `c`.
    pub fn constant(&mut self, c: f64) -> NodeId {
        self.intern(Node::Const(c.to_bits()))
    }
    /// Variable `i` (state `i` for `i < nx`, else an input).
    pub fn var(&mut self, i: u32) -> NodeId {
        self.intern(Node::Var(i))
    }
    /// `op(a)`, folded and simplified.
    pub fn un(&mut self, op: Un, a: NodeId) -> NodeId {
        if let Some(c) = self.as_const(a) {
            return self.constant(op.apply(c));
        }
        match (op, self.node(a)) {
            (Un::Neg, Node::Un(Un::Neg, x)) => x,
            _ => self.intern(Node::Un(op, a)),
        }
    }
    /// `op(a, b)`, folded, simplified and with commuting operands in canonical order.
    pub fn bin(&mut self, op: Bin, a: NodeId, b: NodeId) -> NodeId {
        if op == Bin::Pow {
            return self.pow(a, b);
        }
        let (ca, cb) = (self.as_const(a), self.as_const(b));
        if let (Some(x), Some(y)) = (ca, cb) {
            return self.constant(op.apply(x, y));
        }
        let neg_of = |dag: &Dag, id: NodeId| match dag.node(id) {
            Node::Un(Un::Neg, x) => Some(x),
            _ => None,
        };
        match op {
            Bin::Add => {
                if let Some(y) = neg_of(self, b) {
                    return self.bin(Bin::Sub, a, y);
                }
                if let Some(x) = neg_of(self, a) {
                    return self.bin(Bin::Sub, b, x);
                }
            }
            Bin::Sub => {
                if let Some(c) = cb {
                    let nc = self.constant(-c);
                    return self.bin(Bin::Add, a, nc);
                }
                if let Some(y) = neg_of(self, b) {
                    return self.bin(Bin::Add, a, y);
                }
            }
            Bin::Mul => match (ca, cb) {
                (Some(1.0), _) => return b,
                (_, Some(1.0)) => return a,
                (Some(-1.0), _) => return self.un(Un::Neg, b),
                (_, Some(-1.0)) => return self.un(Un::Neg, a),
                _ => {}
            },
            Bin::Div => match cb {
                Some(1.0) => return a,
                Some(-1.0) => return self.un(Un::Neg, a),
                _ => {}
            },
            Bin::Pow | Bin::Atan2 | Bin::Min | Bin::Max => {}
        }
        let (a, b) = if matches!(op, Bin::Add | Bin::Mul) && b < a {
            (b, a)
        } else {
            (a, b)
        };
        self.intern(Node::Bin(op, a, b))
    }
    /// `a ^ b`: `powi` for a constant integer exponent, `sqrt` for 0.5, `powf` for another
    /// constant, `exp(b·log a)` for a variable exponent.
    pub fn pow(&mut self, a: NodeId, b: NodeId) -> NodeId {
        let Some(e) = self.as_const(b) else {
            return self.intern(Node::Bin(Bin::Pow, a, b));
        };
        match pow_op(e) {
            None if e == 0.0 => self.constant(1.0),
            None => a,
            Some(op) => self.un(op, a),
        }
    }
}

/// The operation `x ↦ x^e` for a constant `e`; `None` for `e = 0` (1) and `e = 1` (x).
pub fn pow_op(e: f64) -> Option<Un> {
    if e.fract() == 0.0 && e.abs() <= MAX_POWI {
        match e as i32 {
            0 | 1 => None,
            n => Some(Un::Powi(n)),
        }
    } else if e == 0.5 {
        Some(Un::Sqrt)
    } else {
        Some(Un::Powf(e.to_bits()))
    }
}
