//! An ONNX model's graph, read from its bytes (`onnx.proto`'s field numbers): the nodes in
//! order, the constant tensors (initializers and `Constant` nodes), the graph's inputs with
//! their shapes, and its outputs. Only what [`crate::Policy`] checks and runs is kept;
//! tensors stored outside the file (`external_data`) are refused.

use std::collections::HashMap;

use crate::proto::{self, Fields, Value};
use crate::{Limits, PolicyError};

/// ONNX's element type number of 32-bit floats.
const FLOAT: u64 = 1;

/// A constant tensor: its dimensions and its floats, in row-major order.
#[derive(Debug, Clone, PartialEq)]
pub struct Tensor {
    pub dims: Vec<usize>,
    pub data: Vec<f32>,
}

/// One node: its operator, inputs, outputs and the attributes [`crate::Policy`] reads.
#[derive(Debug, Clone, Default)]
pub struct Node {
    pub op: String,
    pub domain: String,
    pub inputs: Vec<String>,
    pub outputs: Vec<String>,
    pub ints: HashMap<String, i64>,
    pub floats: HashMap<String, f32>,
    /// A `Constant` node's `value`.
    pub tensor: Option<Tensor>,
}

/// A graph input: its name and dimensions (`None`: symbolic, such as a batch size).
#[derive(Debug, Clone)]
pub struct Input {
    pub name: String,
    pub elem_type: u64,
    pub dims: Vec<Option<i64>>,
}

#[derive(Debug, Default)]
pub struct Graph {
    pub nodes: Vec<Node>,
    pub constants: HashMap<String, Tensor>,
    pub inputs: Vec<Input>,
    pub outputs: Vec<String>,
}

/// Reads the graph of the model in `bytes`.
pub fn read(bytes: &[u8], limits: &Limits) -> Result<Graph, PolicyError> {
    let mut graph = None;
    for field in Fields::new(bytes) {
        if let (7, v) = field? {
            graph = Some(read_graph(v.bytes("the graph")?, limits)?);
        }
    }
    graph.ok_or(PolicyError::Malformed("no graph: not an ONNX model"))
}

fn read_graph(bytes: &[u8], limits: &Limits) -> Result<Graph, PolicyError> {
    let mut g = Graph::default();
    let mut floats = 0usize;
    for field in Fields::new(bytes) {
        match field? {
            (1, v) => {
                if g.nodes.len() == limits.max_nodes {
                    return Err(PolicyError::TooLarge("nodes"));
                }
                let node = read_node(v.bytes("a node")?, limits)?;
                floats += node.tensor.as_ref().map_or(0, |t| t.data.len());
                g.nodes.push(node);
            }
            (5, v) => {
                let (name, t) = read_tensor(v.bytes("an initializer")?, limits)?;
                floats += t.data.len();
                g.constants.insert(name, t);
            }
            (11, v) => g.inputs.push(read_input(v.bytes("an input")?)?),
            (12, v) => {
                let name = Fields::new(v.bytes("an output")?)
                    .filter_map(Result::ok)
                    .find(|(n, _)| *n == 1)
                    .map(|(_, v)| v.string("an output's name"))
                    .transpose()?
                    .unwrap_or_default();
                g.outputs.push(name.to_string());
            }
            _ => {}
        }
        if floats > limits.max_parameters {
            return Err(PolicyError::TooLarge("parameters"));
        }
    }
    // `Constant` nodes are constants like initializers.
    for node in &mut g.nodes {
        if node.op == "Constant"
            && let (Some(t), Some(out)) = (node.tensor.take(), node.outputs.first())
        {
            g.constants.insert(out.clone(), t);
        }
    }
    g.nodes.retain(|n| n.op != "Constant");
    Ok(g)
}

fn read_node(bytes: &[u8], limits: &Limits) -> Result<Node, PolicyError> {
    let mut n = Node::default();
    for field in Fields::new(bytes) {
        match field? {
            (1, v) => n.inputs.push(v.string("a node's input")?.to_string()),
            (2, v) => n.outputs.push(v.string("a node's output")?.to_string()),
            (4, v) => n.op = v.string("an operator")?.to_string(),
            (7, v) => n.domain = v.string("a domain")?.to_string(),
            (5, v) => read_attribute(v.bytes("an attribute")?, &mut n, limits)?,
            _ => {}
        }
        if n.inputs.len() + n.outputs.len() > 16 {
            return Err(PolicyError::TooLarge("a node's inputs and outputs"));
        }
    }
    Ok(n)
}

fn read_attribute(bytes: &[u8], node: &mut Node, limits: &Limits) -> Result<(), PolicyError> {
    let (mut name, mut int, mut float, mut tensor) = ("", None, None, None);
    for field in Fields::new(bytes) {
        match field? {
            (1, v) => name = v.string("an attribute's name")?,
            (2, Value::Fixed32(f)) => float = Some(f32::from_bits(f)),
            (3, v) => int = Some(v.varint("an integer attribute")? as i64),
            (5, v) => tensor = Some(read_tensor(v.bytes("a tensor attribute")?, limits)?.1),
            _ => {}
        }
    }
    if let Some(i) = int {
        node.ints.insert(name.to_string(), i);
    }
    if let Some(f) = float {
        node.floats.insert(name.to_string(), f);
    }
    if name == "value" {
        node.tensor = tensor;
    }
    Ok(())
}

fn read_tensor(bytes: &[u8], limits: &Limits) -> Result<(String, Tensor), PolicyError> {
    let (mut name, mut dims, mut elem, mut data, mut raw) =
        ("", Vec::new(), FLOAT, Vec::new(), None);
    for field in Fields::new(bytes) {
        match field? {
            (1, v) => proto::int64s(v, &mut dims, "a tensor's dimensions")?,
            (2, v) => elem = v.varint("a tensor's type")?,
            (4, v) => proto::floats(v, &mut data, limits.max_parameters, "a tensor's floats")?,
            (8, v) => name = v.string("a tensor's name")?,
            (9, v) => raw = Some(v.bytes("a tensor's raw data")?),
            (13 | 14, _) => return Err(PolicyError::ExternalData),
            _ => {}
        }
        if dims.len() > 8 {
            return Err(PolicyError::TooLarge("a tensor's dimensions"));
        }
    }
    if elem != FLOAT {
        return Err(PolicyError::NotFloat(name.to_string()));
    }
    if let Some(raw) = raw {
        proto::floats(
            Value::Bytes(raw),
            &mut data,
            limits.max_parameters,
            "a tensor's raw data",
        )?;
    }
    let dims = dims
        .into_iter()
        .map(|d| usize::try_from(d).map_err(|_| PolicyError::Malformed("a negative dimension")))
        .collect::<Result<Vec<_>, _>>()?;
    let count = dims
        .iter()
        .try_fold(1usize, |n, &d| n.checked_mul(d))
        .ok_or(PolicyError::TooLarge("a tensor's dimensions"))?;
    if count != data.len() {
        return Err(PolicyError::Malformed(
            "a tensor's data does not fill its dimensions",
        ));
    }
    if data.iter().any(|x| !x.is_finite()) {
        return Err(PolicyError::NotFinite(name.to_string()));
    }
    Ok((name.to_string(), Tensor { dims, data }))
}

fn read_input(bytes: &[u8]) -> Result<Input, PolicyError> {
    let mut input = Input {
        name: String::new(),
        elem_type: 0,
        dims: Vec::new(),
    };
    for field in Fields::new(bytes) {
        match field? {
            (1, v) => input.name = v.string("an input's name")?.to_string(),
            (2, v) => {
                // TypeProto.tensor_type (1): elem_type (1), shape (2) of dims (1), each a
                // dim_value (1) or a dim_param (2).
                for f in Fields::new(v.bytes("an input's type")?) {
                    let (1, tensor) = f? else { continue };
                    for f in Fields::new(tensor.bytes("an input's tensor type")?) {
                        match f? {
                            (1, e) => input.elem_type = e.varint("an input's type")?,
                            (2, shape) => {
                                for d in Fields::new(shape.bytes("an input's shape")?) {
                                    let (1, dim) = d? else { continue };
                                    if input.dims.len() == 8 {
                                        return Err(PolicyError::TooLarge("an input's shape"));
                                    }
                                    let mut value = None;
                                    for x in Fields::new(dim.bytes("a dimension")?) {
                                        if let (1, Value::Varint(n)) = x? {
                                            value = Some(n as i64);
                                        }
                                    }
                                    input.dims.push(value);
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
    Ok(input)
}
