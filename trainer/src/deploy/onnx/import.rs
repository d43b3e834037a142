//! ONNX in: a decoded graph → the dense MLP it computes ([`Mlp`]), or an error naming the
//! first node it cannot take.
//!
//! Accepted: one chain from the single graph input `x` ([N, nx], N symbolic or fixed) to the
//! single output,
//! ```text
//! x → (Sub | Div | Mul | Add by constants)* → Gemm | MatMul [+ Add bias]
//!   → (Tanh | Relu | Softplus → Gemm | MatMul [+ Add bias])* → (Mul | Add | Sub | Div)* → u
//! ```
//! with `Constant` and `Identity` nodes anywhere, weights as initializers or `Constant`s
//! (raw little-endian or typed data, float or double). The leading element-wise ops become
//! the input scaling `a₀ = (x − c) ⊘ h`, the trailing ones the output scaling `u = o + s ∘ y`
//! (as `torch.onnx.export` writes `(x − mean)/std` and `y·std + mean`; those two patterns
//! map exactly, other orders are composed in f64). Gemm: `alpha·A·op(B) + beta·C`,
//! `transA = 0`. All hidden activations must be the same. Files written by
//! `trainer export --onnx` (metadata `ampc.hash`) may also hold the domain projection and
//! the output clamp (`Clip`, with `Split`/`Concat` per component): they are dropped only
//! when their bounds are exactly the metadata's domain and clamp band (`clips`) — then the
//! projection is the identity on X, and the clamp band contains U_d ⊇ κ(X), so the
//! certificate of the unclamped net bounds the clamped one too; any other Clip is refused.
//! The default-domain opset must be in [`super::clips::SUPPORTED_OPSETS`], and tensor names
//! unique.

use super::clips::{clip_bounds, Clip, Side};
use super::graph::{Node, OnnxModel, Tensor, ValueInfo};
use crate::learn::mlp::{Activation, Layer, Mlp};
use std::collections::HashMap;

/// What the importer found besides the network.
#[derive(Debug, Clone, PartialEq, Default)]
pub struct ImportNotes {
    /// Producer of the file.
    pub producer: String,
    /// Highest default-domain opset.
    pub opset: i64,
    /// Whether the file is an `trainer export --onnx` file (metadata `ampc.hash`).
    pub ampc_export: bool,
    /// Number of `Clip` nodes dropped (projection and clamp of an ampc export).
    pub clips_dropped: usize,
}

/// One step of the chain.
#[derive(Debug, Clone)]
enum Step {
    /// `x − v`, `x + v`, `x · v`, `x / v`, `v − x` (element-wise, broadcast).
    Elem(char, Vec<f64>, String),
    /// A dense layer (w row-major out × in, bias); `true` while a MatMul's bias (the next
    /// Add) may still come.
    Linear(Layer, String, bool),
    /// An activation.
    Act(Activation, String),
}

type R<T> = Result<T, String>;

fn scalar_attr(n: &Node, name: &str, default: f64) -> f64 {
    n.attr(name)
        .and_then(|a| a.f.map(f64::from))
        .unwrap_or(default)
}

fn int_attr(n: &Node, name: &str, default: i64) -> i64 {
    n.attr(name).and_then(|a| a.i).unwrap_or(default)
}

/// The constant of a `Constant` node.
fn constant_value(n: &Node, label: &str) -> R<Tensor> {
    for a in &n.attributes {
        match a.name.as_str() {
            "value" => {
                if let Some(t) = &a.t {
                    return Ok(t.clone());
                }
            }
            "value_float" => {
                return Ok(Tensor {
                    values: vec![f64::from(a.f.unwrap_or(0.0))],
                    data_type: super::graph::FLOAT,
                    ..Default::default()
                })
            }
            "value_floats" => {
                return Ok(Tensor {
                    dims: vec![a.floats.len() as i64],
                    values: a.floats.iter().map(|v| f64::from(*v)).collect(),
                    data_type: super::graph::FLOAT,
                    ..Default::default()
                })
            }
            "value_int" | "value_ints" => {
                let ints = if a.name == "value_int" {
                    vec![a.i.unwrap_or(0)]
                } else {
                    a.ints.clone()
                };
                return Ok(Tensor {
                    dims: vec![ints.len() as i64],
                    ints,
                    data_type: super::graph::INT64,
                    ..Default::default()
                });
            }
            _ => {}
        }
    }
    Err(format!(
        "{label}: a Constant without a supported value attribute"
    ))
}

/// The chain read so far: the name of the running value, its components after a `Split`
/// (projection / clamp of an ampc export), the steps and the Clip nodes of an ampc export
/// (checked against its metadata once the chain is known).
struct Chain {
    current: String,
    parts: Option<Vec<String>>,
    steps: Vec<Step>,
    clips: Vec<Clip>,
}

/// Reads the graph as a dense MLP; errors name the node (or tensor) at fault.
pub fn to_mlp(m: &OnnxModel) -> R<(Mlp, ImportNotes)> {
    let ampc = m.meta("ampc.hash").is_some();
    let mut notes = ImportNotes {
        producer: m.producer.clone(),
        opset: super::clips::default_opset(m)?,
        ampc_export: ampc,
        clips_dropped: 0,
    };
    let mut consts: HashMap<String, Tensor> = super::clips::initializers(m)?;
    let (input, output) = input_and_output(m, &consts)?;
    let mut chain = Chain {
        current: input.name.clone(),
        parts: None,
        steps: Vec::new(),
        clips: Vec::new(),
    };
    for (k, n) in m.nodes.iter().enumerate() {
        let label = n.label(k);
        if !(n.domain.is_empty() || n.domain == "ai.onnx") {
            return Err(format!(
                "{label}: operator domain '{}' is not supported",
                n.domain
            ));
        }
        if n.op == "Constant" {
            let t = constant_value(n, &label)?;
            let name = n.outputs.first().cloned().unwrap_or_default();
            if consts.insert(name.clone(), t).is_some() {
                return Err(format!(
                    "{label}: output '{name}' is already defined (tensor names must be unique)"
                ));
            }
            continue;
        }
        let out = n.outputs.first().cloned().unwrap_or_default();
        // Nodes on constants only (e.g. an Identity of a weight).
        if n.op == "Identity" && n.inputs.first().is_some_and(|i| consts.contains_key(i)) {
            let t = consts[&n.inputs[0]].clone();
            consts.insert(out, t);
            continue;
        }
        if ampc && chain.ampc_node(n, &label, &consts, &mut notes)? {
            continue;
        }
        let current = &chain.current;
        let pos = n.inputs.iter().position(|i| i == current);
        let Some(pos) = pos.filter(|_| chain.parts.is_none()) else {
            return Err(format!(
                "{label}: does not take the network's running value ({current}); only a \
                 single chain of dense layers is supported"
            ));
        };
        let other = |i: usize| constant(&consts, n, i, &label);
        let step = match n.op.as_str() {
            "Identity" => {
                chain.current = out;
                continue;
            }
            "Tanh" => Step::Act(Activation::Tanh, label.clone()),
            "Relu" => Step::Act(Activation::Relu, label.clone()),
            "Softplus" => Step::Act(Activation::Softplus, label.clone()),
            "Gemm" | "MatMul" => dense(n, pos, &label, other)?,
            "Add" | "Sub" | "Mul" | "Div" => {
                let t = other(1 - pos.min(1))?;
                let op = elem_op(n, pos, &label)?;
                // A MatMul followed by Add is a layer with its bias.
                if let (Some(Step::Linear(l, _, open @ true)), '+') = (chain.steps.last_mut(), op) {
                    l.b = broadcast(t, l.out, &label)?;
                    *open = false;
                    chain.current = out;
                    continue;
                }
                Step::Elem(op, t.values.clone(), label.clone())
            }
            op => {
                return Err(format!(
                    "{label}: unsupported operator {op} (supported: Gemm, MatMul, Add, Sub, \
                     Mul, Div by constants, Tanh, Relu, Softplus, Constant, Identity)"
                ))
            }
        };
        chain.steps.push(step);
        chain.current = out;
    }
    if chain.current != output.name {
        return Err(format!(
            "the graph output '{}' is not the end of the chain ('{}')",
            output.name, chain.current
        ));
    }
    let n_steps = chain.steps.len();
    let (mlp, notes) = assemble(chain.steps, notes, input.dims.last().copied().flatten())?;
    super::clips::check(m, &chain.clips, n_steps, mlp.nx(), mlp.nu())?;
    Ok((mlp, notes))
}

/// The graph's single input besides its weights (the state) and its single output.
fn input_and_output<'a>(
    m: &'a OnnxModel,
    consts: &HashMap<String, Tensor>,
) -> R<(&'a ValueInfo, &'a ValueInfo)> {
    let inputs: Vec<_> = m
        .inputs
        .iter()
        .filter(|v| !consts.contains_key(&v.name))
        .collect();
    let [input] = inputs.as_slice() else {
        return Err(format!(
            "the graph has {} inputs besides its weights (a controller has one: the state)",
            inputs.len()
        ));
    };
    let [output] = m.outputs.as_slice() else {
        return Err(format!(
            "the graph has {} outputs (a controller has one: the input u)",
            m.outputs.len()
        ));
    };
    Ok((input, output))
}

/// The element-wise op of node `n` with the running value as operand `pos`: `+`, `*`, `-`
/// (x − v), `r` (v − x), `/` (x / v); a constant divided by the running value is refused.
fn elem_op(n: &Node, pos: usize, label: &str) -> R<char> {
    Ok(match (n.op.as_str(), pos) {
        ("Add", _) => '+',
        ("Mul", _) => '*',
        ("Sub", 0) => '-',
        ("Sub", _) => 'r',
        ("Div", 0) => '/',
        _ => {
            return Err(format!(
                "{label}: a constant divided by the running value is not an affine map"
            ))
        }
    })
}

/// The dense layer of a `Gemm` (`alpha·A·op(B) + beta·C`, `transA = 0`) or `MatMul` node
/// whose first operand (`pos`) is the running value; `other(i)` is its constant input `i`.
fn dense<'a>(n: &Node, pos: usize, label: &str, other: impl Fn(usize) -> R<&'a Tensor>) -> R<Step> {
    if pos != 0 {
        return Err(format!(
            "{label}: the running value must be the first operand"
        ));
    }
    let gemm = n.op == "Gemm";
    if gemm && int_attr(n, "transA", 0) != 0 {
        return Err(format!("{label}: transA = 1 is not supported"));
    }
    let b = other(1)?;
    let &[r, c] = &b.dims[..] else {
        return Err(format!(
            "{label}: weight of shape {:?} (2-D expected)",
            b.dims
        ));
    };
    // An integer tensor (no float values) or a shape its values do not fill is
    // refused here, before it is indexed.
    if r < 0 || c < 0 || b.values.len() as u64 != r as u64 * c as u64 {
        return Err(format!(
            "{label}: weight of shape {:?} with {} floating-point values",
            b.dims,
            b.values.len()
        ));
    }
    let (r, c) = (r as usize, c as usize);
    let trans = gemm && int_attr(n, "transB", 0) != 0;
    let (out_w, in_w) = if trans { (r, c) } else { (c, r) };
    let alpha = if gemm {
        scalar_attr(n, "alpha", 1.0)
    } else {
        1.0
    };
    let mut w = vec![0.0; out_w * in_w];
    for o in 0..out_w {
        for i in 0..in_w {
            let v = if trans {
                b.values[o * c + i]
            } else {
                b.values[i * c + o]
            };
            w[o * in_w + i] = if alpha == 1.0 { v } else { alpha * v };
        }
    }
    let mut bias = vec![0.0; out_w];
    if gemm && n.inputs.get(2).is_some_and(|s| !s.is_empty()) {
        let beta = scalar_attr(n, "beta", 1.0);
        let cb = broadcast(other(2)?, out_w, label)?;
        for (b, v) in bias.iter_mut().zip(cb) {
            *b = if beta == 1.0 { v } else { beta * v };
        }
    }
    Ok(Step::Linear(
        Layer {
            inp: in_w,
            out: out_w,
            w,
            b: bias,
        },
        label.to_string(),
        !gemm,
    ))
}

impl Chain {
    /// Takes node `n` when it is part of an ampc export's projection or clamp (`Split` →
    /// `Clip` per component → `Concat`, or one `Clip`): records the Clip for the check
    /// against the metadata and returns `true`; `false` for any other node.
    fn ampc_node(
        &mut self,
        n: &Node,
        label: &str,
        consts: &HashMap<String, Tensor>,
        notes: &mut ImportNotes,
    ) -> R<bool> {
        let out = n.outputs.first().cloned().unwrap_or_default();
        // The ampc export's per-component Clip: Split → Clip each → Concat.
        match n.op.as_str() {
            "Split" if n.inputs.first() == Some(&self.current) && self.parts.is_none() => {
                unit_split(n, label, consts)?;
                self.parts = Some(n.outputs.clone());
                return Ok(true);
            }
            "Clip" if !n.inputs.is_empty() => {
                let (component, slot) = match self.parts.as_mut() {
                    Some(p) => match p.iter_mut().position(|s| *s == n.inputs[0]) {
                        Some(k) => (Some(k), Some(&mut p[k])),
                        None => (None, None),
                    },
                    None if n.inputs[0] == self.current => (None, Some(&mut self.current)),
                    None => (None, None),
                };
                if let Some(slot) = slot {
                    *slot = out;
                    let (lo, hi) = clip_bounds(n, label, |name| consts.get(name).cloned())?;
                    let linear = self.steps.iter().any(|s| matches!(s, Step::Linear(..)));
                    if !linear && !self.steps.is_empty() {
                        return Err(format!(
                            "{label}: a Clip after the input scaling (only the projection \
                             onto X before the first layer and the output clamp after the \
                             last are supported)"
                        ));
                    }
                    self.clips.push(Clip {
                        label: label.to_string(),
                        side: if linear {
                            Side::Clamp
                        } else {
                            Side::Projection
                        },
                        component,
                        lo,
                        hi,
                        at_step: self.steps.len(),
                    });
                    notes.clips_dropped += 1;
                    return Ok(true);
                }
            }
            "Concat"
                if self.parts.as_deref() == Some(&n.inputs[..]) && int_attr(n, "axis", 1) == 1 =>
            {
                self.parts = None;
                self.current = out;
                return Ok(true);
            }
            _ => {}
        }
        Ok(false)
    }
}

/// An ampc export's `Split` along axis 1 into parts of width 1 (input 2 or attribute `split`
/// all ones, or absent: equal parts); anything else is refused naming the node.
fn unit_split(n: &Node, label: &str, consts: &HashMap<String, Tensor>) -> R<()> {
    let sizes = match n.inputs.get(1).filter(|s| !s.is_empty()) {
        Some(name) => consts
            .get(name)
            .map(|t| t.ints.clone())
            .ok_or_else(|| format!("{label}: split sizes '{name}' are not a constant"))?,
        None => n.attr("split").map(|a| a.ints.clone()).unwrap_or_default(),
    };
    let axis = int_attr(n, "axis", 0);
    if axis != 1 || !(sizes.is_empty() || sizes.iter().all(|s| *s == 1)) {
        return Err(format!(
            "{label}: Split on axis {axis} into sizes {sizes:?} (an ampc export splits axis 1 \
             into components of width 1)"
        ));
    }
    Ok(())
}

/// Input `i` of node `n`, which must be a constant.
fn constant<'a>(
    consts: &'a HashMap<String, Tensor>,
    n: &Node,
    i: usize,
    label: &str,
) -> R<&'a Tensor> {
    let name = n
        .inputs
        .get(i)
        .ok_or_else(|| format!("{label}: missing input {i}"))?;
    consts.get(name).ok_or_else(|| {
        format!(
            "{label}: input '{name}' is not a constant (weights must be initializers or \
             Constants)"
        )
    })
}

/// The values of `t` broadcast to length `n` (a scalar or a vector of `n`).
fn broadcast(t: &Tensor, n: usize, label: &str) -> R<Vec<f64>> {
    match t.values.len() {
        1 => Ok(vec![t.values[0]; n]),
        l if l == n => Ok(t.values.clone()),
        l => Err(format!("{label}: a constant of {l} values for width {n}")),
    }
}

/// The MLP of the chain: its dense layers alternating with one hidden activation, the
/// element-wise ops before the first layer as the input scaling, those after the last as
/// the output scaling; `nx_decl` is the input width the graph declares, if any.
fn assemble(steps: Vec<Step>, notes: ImportNotes, nx_decl: Option<i64>) -> R<(Mlp, ImportNotes)> {
    let first = steps
        .iter()
        .position(|s| matches!(s, Step::Linear(..)))
        .ok_or("the graph has no dense layer (Gemm or MatMul)")?;
    let last = steps
        .iter()
        .rposition(|s| matches!(s, Step::Linear(..)))
        .expect("one exists");
    let mut layers: Vec<Layer> = Vec::new();
    let mut act: Option<Activation> = None;
    let mut expect_act = false;
    for s in &steps[first..=last] {
        match s {
            Step::Linear(l, label, _) => {
                if expect_act {
                    return Err(format!(
                        "{label}: two dense layers without an activation between them"
                    ));
                }
                if let Some(p) = layers.last() {
                    if p.out != l.inp {
                        return Err(format!(
                            "{label}: takes {} inputs, the layer before gives {}",
                            l.inp, p.out
                        ));
                    }
                }
                layers.push(l.clone());
                expect_act = true;
            }
            Step::Act(a, label) => {
                if !expect_act {
                    return Err(format!("{label}: two activations in a row"));
                }
                if act.is_some_and(|b| b != *a) {
                    return Err(format!(
                        "{label}: hidden layers with different activations ({:?} and {a:?})",
                        act.unwrap_or(*a)
                    ));
                }
                act = Some(*a);
                expect_act = false;
            }
            Step::Elem(_, _, label) => {
                return Err(format!(
                    "{label}: element-wise op between the layers (only input and output \
                     scaling are supported)"
                ))
            }
        }
    }
    let nx = layers[0].inp;
    let nu = layers.last().map_or(0, |l| l.out);
    if let Some(d) = nx_decl.filter(|d| *d as usize != nx) {
        return Err(format!(
            "the graph input has {d} components, the first layer takes {nx}"
        ));
    }
    let (c, h) = input_scaling(&steps[..first], nx)?;
    let (o, sc) = output_scaling(&steps[last + 1..], nu)?;
    if let Some(i) = h
        .iter()
        .chain(&sc)
        .position(|v| *v == 0.0 || !v.is_finite())
    {
        return Err(format!("scaling {i}: zero or non-finite scale"));
    }
    let finite = layers
        .iter()
        .all(|l| l.w.iter().chain(&l.b).all(|v| v.is_finite()))
        && c.iter().chain(&o).all(|v| v.is_finite());
    if !finite {
        return Err("non-finite weights".into());
    }
    // A net without hidden layers has no activation: any will do.
    let activation = act.unwrap_or(Activation::Tanh);
    Ok((
        Mlp {
            layers,
            activation,
            in_center: c,
            in_half: h,
            out_center: o,
            out_half: sc,
        },
        notes,
    ))
}

/// The input scaling a₀ = (x − c) ⊘ h composed from the element-wise ops before the first
/// layer, in f64; an activation there is refused.
fn input_scaling(steps: &[Step], nx: usize) -> R<(Vec<f64>, Vec<f64>)> {
    let (mut c, mut h) = (vec![0.0; nx], vec![1.0; nx]);
    for s in steps {
        let Step::Elem(op, v, label) = s else {
            let Step::Act(_, label) = s else {
                unreachable!()
            };
            return Err(format!("{label}: an activation before the first layer"));
        };
        let v = broadcast(
            &Tensor {
                values: v.clone(),
                ..Default::default()
            },
            nx,
            label,
        )?;
        for i in 0..nx {
            match op {
                '-' => c[i] += v[i] * h[i],
                '+' => c[i] -= v[i] * h[i],
                '/' => h[i] *= v[i],
                '*' => h[i] /= v[i],
                _ => {
                    c[i] += v[i] * h[i];
                    h[i] = -h[i];
                }
            }
        }
    }
    Ok((c, h))
}

/// The output scaling u = o + s ∘ y composed from the element-wise ops after the last layer,
/// in f64; an activation there is refused (the output must be linear).
fn output_scaling(steps: &[Step], nu: usize) -> R<(Vec<f64>, Vec<f64>)> {
    let (mut o, mut sc) = (vec![0.0; nu], vec![1.0; nu]);
    for s in steps {
        let Step::Elem(op, v, label) = s else {
            let Step::Act(_, label) = s else {
                unreachable!()
            };
            return Err(format!(
                "{label}: an activation after the last layer (the output must be linear)"
            ));
        };
        let v = broadcast(
            &Tensor {
                values: v.clone(),
                ..Default::default()
            },
            nu,
            label,
        )?;
        for j in 0..nu {
            match op {
                '-' => o[j] -= v[j],
                '+' => o[j] += v[j],
                '*' => {
                    o[j] *= v[j];
                    sc[j] *= v[j];
                }
                '/' => {
                    o[j] /= v[j];
                    sc[j] /= v[j];
                }
                _ => {
                    o[j] = v[j] - o[j];
                    sc[j] = -sc[j];
                }
            }
        }
    }
    Ok((o, sc))
}
