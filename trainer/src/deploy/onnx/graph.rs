//! The decoded ONNX model: `ModelProto` → [`OnnxModel`] (graph, nodes, attributes,
//! tensors, metadata), with the field numbers of `onnx.proto`:
//!
//! ```text
//! ModelProto     ir_version 1, producer_name 2, producer_version 3, graph 7, opset_import 8,
//!                metadata_props 14
//! GraphProto     node 1, name 2, initializer 5, input 11, output 12
//! NodeProto      input 1, output 2, name 3, op_type 4, attribute 5, domain 7
//! AttributeProto name 1, f 2, i 3, s 4, t 5, floats 7, ints 8, type 20
//! TensorProto    dims 1, data_type 2, float_data 4, int32_data 5, int64_data 7, name 8,
//!                raw_data 9, double_data 10, data_location 14
//! ValueInfoProto name 1, type 2 → TypeProto.tensor_type 1 → elem_type 1, shape 2 → dim 1
//!                → dim_value 1 | dim_param 2
//! StringStringEntryProto key 1, value 2;  OperatorSetIdProto domain 1, version 2
//! ```
//! Float tensors (FLOAT = 1, DOUBLE = 11) are read as f64 exactly; integer tensors (INT32 = 6,
//! INT64 = 7) as i64. Raw data is little-endian (the ONNX convention).

use super::proto::{doubles, fields, floats, ints, string, Value, WireError};

/// ONNX `TensorProto.DataType` FLOAT.
pub const FLOAT: i64 = 1;
/// ONNX `TensorProto.DataType` INT32.
pub const INT32: i64 = 6;
/// ONNX `TensorProto.DataType` INT64.
pub const INT64: i64 = 7;
/// ONNX `TensorProto.DataType` DOUBLE.
pub const DOUBLE: i64 = 11;

/// A constant tensor.
#[derive(Debug, Clone, PartialEq, Default)]
pub struct Tensor {
    /// Its name.
    pub name: String,
    /// Its shape.
    pub dims: Vec<i64>,
    /// Element type (ONNX code).
    pub data_type: i64,
    /// Values of a float tensor (f32 widened exactly).
    pub values: Vec<f64>,
    /// Values of an integer tensor.
    pub ints: Vec<i64>,
}

/// One attribute of a node (the fields this importer reads).
#[derive(Debug, Clone, PartialEq, Default)]
pub struct Attribute {
    /// Name.
    pub name: String,
    /// `f`.
    pub f: Option<f32>,
    /// `i`.
    pub i: Option<i64>,
    /// `t`.
    pub t: Option<Tensor>,
    /// `floats`.
    pub floats: Vec<f32>,
    /// `ints`.
    pub ints: Vec<i64>,
}

/// One node.
#[derive(Debug, Clone, PartialEq, Default)]
pub struct Node {
    /// Name (may be empty).
    pub name: String,
    /// Operator.
    pub op: String,
    /// Operator domain ("" = the default ONNX domain).
    pub domain: String,
    /// Input tensor names ("" = an omitted optional input).
    pub inputs: Vec<String>,
    /// Output tensor names.
    pub outputs: Vec<String>,
    /// Attributes.
    pub attributes: Vec<Attribute>,
}

impl Node {
    /// The attribute called `name`.
    pub fn attr(&self, name: &str) -> Option<&Attribute> {
        self.attributes.iter().find(|a| a.name == name)
    }
    /// How the node is named in messages: `'name' (Op)` or `#k (Op)`.
    pub fn label(&self, k: usize) -> String {
        if self.name.is_empty() {
            format!("node #{k} ({})", self.op)
        } else {
            format!("node '{}' ({})", self.name, self.op)
        }
    }
}

/// A graph input or output: name, element type and shape (`None` = symbolic dimension).
#[derive(Debug, Clone, PartialEq, Default)]
pub struct ValueInfo {
    /// Name.
    pub name: String,
    /// Element type (0 = unknown).
    pub elem_type: i64,
    /// Dimensions (`None` for a symbolic or unknown one).
    pub dims: Vec<Option<i64>>,
}

/// A decoded model.
#[derive(Debug, Clone, PartialEq, Default)]
pub struct OnnxModel {
    /// IR version.
    pub ir_version: i64,
    /// Producer name.
    pub producer: String,
    /// Opset imports (domain, version).
    pub opsets: Vec<(String, i64)>,
    /// `metadata_props` (key, value).
    pub metadata: Vec<(String, String)>,
    /// Nodes in (topological) order.
    pub nodes: Vec<Node>,
    /// Initializers.
    pub initializers: Vec<Tensor>,
    /// Graph inputs.
    pub inputs: Vec<ValueInfo>,
    /// Graph outputs.
    pub outputs: Vec<ValueInfo>,
}

impl OnnxModel {
    /// The metadata value of `key`.
    pub fn meta(&self, key: &str) -> Option<&str> {
        self.metadata
            .iter()
            .find(|(k, _)| k == key)
            .map(|(_, v)| v.as_str())
    }
}

/// Why bytes are not an ONNX model of the form read here: a malformed protobuf field (the
/// part being read and the wire error) or another fault, naming the part.
#[derive(Debug, Clone, PartialEq, thiserror::Error)]
pub enum GraphError {
    /// A malformed protobuf field.
    #[error("{what}: {source}")]
    Wire {
        /// The part being read (`tensor dims`, `node`, …).
        what: &'static str,
        /// The wire error (its byte offset).
        source: WireError,
    },
    /// Any other fault (an unsupported element type, an inconsistent shape, no graph).
    #[error("{0}")]
    Invalid(String),
}

impl From<String> for GraphError {
    fn from(s: String) -> Self {
        GraphError::Invalid(s)
    }
}

impl From<&str> for GraphError {
    fn from(s: &str) -> Self {
        GraphError::Invalid(s.to_string())
    }
}

type R<T> = Result<T, GraphError>;

fn wire(what: &'static str) -> impl Fn(WireError) -> GraphError {
    move |source| GraphError::Wire { what, source }
}

fn bytes<'a>(v: &Value<'a>, what: &str) -> R<&'a [u8]> {
    match v {
        Value::Bytes(b) => Ok(b),
        _ => Err(format!("{what}: expected a length-delimited field").into()),
    }
}

fn int(v: &Value<'_>, what: &str) -> R<i64> {
    match v {
        Value::Varint(x) => Ok(*x as i64),
        _ => Err(format!("{what}: expected a varint field").into()),
    }
}

/// Decodes a `TensorProto`.
pub fn tensor(b: &[u8]) -> R<Tensor> {
    let mut t = Tensor::default();
    let (mut raw, mut f32s, mut f64s, mut i64s) = (None, Vec::new(), Vec::new(), Vec::new());
    let mut external = false;
    for (n, v) in fields(b).map_err(wire("tensor"))? {
        match n {
            1 => t.dims.extend(ints(&v).map_err(wire("tensor dims"))?),
            2 => t.data_type = int(&v, "tensor data_type")?,
            4 => f32s.extend(floats(&v).map_err(wire("tensor float_data"))?),
            5 | 7 => i64s.extend(ints(&v).map_err(wire("tensor int data"))?),
            8 => t.name = string(&v),
            9 => raw = Some(bytes(&v, "tensor raw_data")?),
            10 => f64s.extend(doubles(&v).map_err(wire("tensor double_data"))?),
            14 => external = int(&v, "tensor data_location")? == 1,
            _ => {}
        }
    }
    let label = if t.name.is_empty() {
        "a tensor".to_string()
    } else {
        format!("tensor '{}'", t.name)
    };
    if external {
        return Err(format!(
            "{label} keeps its data in an external file (save the model with its weights inside)"
        )
        .into());
    }
    // Non-negative dimensions whose product fits (a corrupt shape is an error, not an
    // overflow).
    let Some(count) = t
        .dims
        .iter()
        .try_fold(1i64, |a, &d| if d < 0 { None } else { a.checked_mul(d) })
    else {
        return Err(format!("{label}: invalid shape {:?}", t.dims).into());
    };
    match (t.data_type, raw) {
        (FLOAT, Some(r)) if r.len() % 4 == 0 => {
            t.values = r
                .chunks_exact(4)
                .map(|c| f64::from(f32::from_le_bytes(c.try_into().expect("4"))))
                .collect()
        }
        (FLOAT, None) => t.values = f32s.into_iter().map(f64::from).collect(),
        (DOUBLE, Some(r)) if r.len() % 8 == 0 => {
            t.values = r
                .chunks_exact(8)
                .map(|c| f64::from_le_bytes(c.try_into().expect("8")))
                .collect()
        }
        (DOUBLE, None) => t.values = f64s,
        (INT64, Some(r)) if r.len() % 8 == 0 => {
            t.ints = r
                .chunks_exact(8)
                .map(|c| i64::from_le_bytes(c.try_into().expect("8")))
                .collect()
        }
        (INT32, Some(r)) if r.len() % 4 == 0 => {
            t.ints = r
                .chunks_exact(4)
                .map(|c| i64::from(i32::from_le_bytes(c.try_into().expect("4"))))
                .collect()
        }
        (INT64 | INT32, None) => t.ints = i64s,
        (ty, _) => {
            return Err(format!(
                "{label}: element type {ty} not supported (float, double, int32, int64 are)"
            )
            .into())
        }
    }
    let len = t.values.len().max(t.ints.len()) as i64;
    if len != count {
        return Err(format!(
            "{label}: {len} values for shape {:?} ({count} expected)",
            t.dims
        )
        .into());
    }
    Ok(t)
}

fn attribute(b: &[u8]) -> R<Attribute> {
    let mut a = Attribute::default();
    for (n, v) in fields(b).map_err(wire("attribute"))? {
        match n {
            1 => a.name = string(&v),
            2 => a.f = floats(&v).map_err(wire("attribute f"))?.first().copied(),
            3 => a.i = Some(int(&v, "attribute i")?),
            5 => a.t = Some(tensor(bytes(&v, "attribute t")?)?),
            7 => a
                .floats
                .extend(floats(&v).map_err(wire("attribute floats"))?),
            8 => a.ints.extend(ints(&v).map_err(wire("attribute ints"))?),
            _ => {}
        }
    }
    Ok(a)
}

fn node(b: &[u8]) -> R<Node> {
    let mut nd = Node::default();
    for (n, v) in fields(b).map_err(wire("node"))? {
        match n {
            1 => nd.inputs.push(string(&v)),
            2 => nd.outputs.push(string(&v)),
            3 => nd.name = string(&v),
            4 => nd.op = string(&v),
            5 => nd.attributes.push(attribute(bytes(&v, "node attribute")?)?),
            7 => nd.domain = string(&v),
            _ => {}
        }
    }
    Ok(nd)
}

fn value_info(b: &[u8]) -> R<ValueInfo> {
    let mut vi = ValueInfo::default();
    for (n, v) in fields(b).map_err(wire("value info"))? {
        match n {
            1 => vi.name = string(&v),
            2 => {
                for (n2, v2) in fields(bytes(&v, "type")?).map_err(wire("type"))? {
                    if n2 != 1 {
                        continue;
                    }
                    for (n3, v3) in
                        fields(bytes(&v2, "tensor type")?).map_err(wire("tensor type"))?
                    {
                        match n3 {
                            1 => vi.elem_type = int(&v3, "elem_type")?,
                            2 => {
                                for (_, d) in fields(bytes(&v3, "shape")?).map_err(wire("shape"))? {
                                    let mut dim = None;
                                    for (n4, v4) in
                                        fields(bytes(&d, "dim")?).map_err(wire("dim"))?
                                    {
                                        if n4 == 1 {
                                            dim = Some(int(&v4, "dim_value")?);
                                        }
                                    }
                                    vi.dims.push(dim);
                                }
                            }
                            _ => {}
                        }
                    }
                }
            }
            _ => {}
        }
    }
    Ok(vi)
}

/// Decodes a serialized `ModelProto`; the error says what is malformed.
pub fn decode(b: &[u8]) -> R<OnnxModel> {
    let mut m = OnnxModel::default();
    let mut graph = None;
    for (n, v) in fields(b).map_err(wire("model"))? {
        match n {
            1 => m.ir_version = int(&v, "ir_version")?,
            2 => m.producer = string(&v),
            7 => graph = Some(bytes(&v, "graph")?),
            8 => {
                let (mut d, mut ver) = (String::new(), 0);
                for (n2, v2) in fields(bytes(&v, "opset_import")?).map_err(wire("opset"))? {
                    match n2 {
                        1 => d = string(&v2),
                        2 => ver = int(&v2, "opset version")?,
                        _ => {}
                    }
                }
                m.opsets.push((d, ver));
            }
            14 => {
                let (mut k, mut val) = (String::new(), String::new());
                for (n2, v2) in fields(bytes(&v, "metadata_props")?).map_err(wire("metadata"))? {
                    match n2 {
                        1 => k = string(&v2),
                        2 => val = string(&v2),
                        _ => {}
                    }
                }
                m.metadata.push((k, val));
            }
            _ => {}
        }
    }
    let g = graph.ok_or("no graph (not an ONNX ModelProto)")?;
    for (n, v) in fields(g).map_err(wire("graph"))? {
        match n {
            1 => m.nodes.push(node(bytes(&v, "node")?)?),
            5 => m.initializers.push(tensor(bytes(&v, "initializer")?)?),
            11 => m.inputs.push(value_info(bytes(&v, "graph input")?)?),
            12 => m.outputs.push(value_info(bytes(&v, "graph output")?)?),
            _ => {}
        }
    }
    if m.ir_version <= 0 || m.opsets.is_empty() {
        return Err("no ir_version or opset_import (not an ONNX ModelProto)".into());
    }
    Ok(m)
}
