//! Trained robot teams' models: an ONNX file read, checked against a small allow-list and run,
//! the same bits on every machine.
//!
//! A policy maps a robot's observation (a vector of floats) to its action (another). What a
//! small trained policy needs of ONNX is a chain of dense layers and activations, which is all
//! this accepts: `Gemm`, `MatMul` followed by an `Add` of a constant, `Relu`, `Tanh`,
//! `Sigmoid`, `Identity` and `Flatten` of a vector, on 32-bit floats, one input `[N]` or
//! `[1, N]` (or a symbolic batch) and one output, each node taking the one before it. Anything
//! else is refused by name before it runs ([`PolicyError`]), and sizes are bounded
//! ([`Limits`]): reading a hostile file allocates at most its own size and never panics.
//!
//! Determinism: each output is a dot product summed in one fixed order (eight running sums,
//! folded pairwise) with no fused multiply-add, and `tanh` and `exp` are `libm`'s software
//! ones, so the same observation gives the same action, bit for bit, whatever the CPU or
//! platform; replays and resumes never need the model again (its actions are recorded), but
//! a researcher's in-process evaluation and the server's agree.
//!
//! Plain Rust (no tokio, serde, clock or I/O), beside `lasertag-core`: the server and the
//! native engine both run policies with it.

mod onnx;
mod proto;
mod shipped;
pub mod team;
pub mod unpark;

pub use shipped::{SHIPPED, shipped};
pub use team::TeamPolicy;

/// Why a model was refused, or could not run.
#[derive(Debug, Clone, PartialEq, thiserror::Error)]
pub enum PolicyError {
    #[error("not a readable ONNX model: {0}")]
    Malformed(&'static str),
    #[error("the model is too large: {0} over this server's limit")]
    TooLarge(&'static str),
    #[error("operator {0} is not supported (supported: {SUPPORTED})")]
    Unsupported(String),
    #[error("tensor `{0}` is not 32-bit floats")]
    NotFloat(String),
    #[error("tensor `{0}` holds a NaN or an infinity")]
    NotFinite(String),
    #[error("tensors stored outside the file (external data) are not supported")]
    ExternalData,
    #[error("the graph is not one chain of layers: {0}")]
    NotAChain(String),
    #[error("shapes do not agree: {0}")]
    Shape(String),
    #[error("the model takes {expected} inputs, the observation has {got}")]
    InputLength { expected: usize, got: usize },
}

/// The operators a policy may use.
pub const SUPPORTED: &str = "Gemm, MatMul, Add, Relu, Tanh, Sigmoid, Identity, Flatten";

/// What a model may hold.
#[derive(Debug, Clone, Copy)]
pub struct Limits {
    /// Weights and biases, in all.
    pub max_parameters: usize,
    /// Nodes of the graph.
    pub max_nodes: usize,
    /// Widest vector (input, output or any layer's).
    pub max_width: usize,
}

impl Default for Limits {
    /// 4 M parameters (16 MiB of floats), 64 nodes, 4,096 wide.
    fn default() -> Limits {
        Limits {
            max_parameters: 4 << 20,
            max_nodes: 64,
            max_width: 4096,
        }
    }
}

/// One stage of the chain.
#[derive(Debug, Clone, PartialEq)]
enum Layer {
    /// `y = W x + b`, `W` row-major `outputs × inputs`.
    Dense {
        weights: Vec<f32>,
        bias: Vec<f32>,
        inputs: usize,
    },
    Relu,
    Tanh,
    Sigmoid,
}

/// A checked model, ready to run.
#[derive(Debug, Clone, PartialEq)]
pub struct Policy {
    input_len: usize,
    output_len: usize,
    layers: Vec<Layer>,
}

impl Policy {
    /// Reads and checks the ONNX model in `bytes` under `limits`.
    pub fn from_onnx(bytes: &[u8], limits: &Limits) -> Result<Policy, PolicyError> {
        let graph = onnx::read(bytes, limits)?;
        build(graph, limits)
    }

    /// Floats the observation must have.
    pub fn input_len(&self) -> usize {
        self.input_len
    }

    /// Floats of the action.
    pub fn output_len(&self) -> usize {
        self.output_len
    }

    /// Multiply-adds of one inference: what it costs, for pricing.
    pub fn multiply_adds(&self) -> usize {
        self.layers
            .iter()
            .map(|l| match l {
                Layer::Dense { weights, .. } => weights.len(),
                _ => 0,
            })
            .sum()
    }

    /// The action for `observation`, in `action` (resized; `scratch` holds the layer in
    /// between, so a caller that keeps both allocates nothing after the first call).
    pub fn infer(
        &self,
        observation: &[f32],
        action: &mut Vec<f32>,
        scratch: &mut Vec<f32>,
    ) -> Result<(), PolicyError> {
        if observation.len() != self.input_len {
            return Err(PolicyError::InputLength {
                expected: self.input_len,
                got: observation.len(),
            });
        }
        action.clear();
        action.extend_from_slice(observation);
        for layer in &self.layers {
            match layer {
                Layer::Dense {
                    weights,
                    bias,
                    inputs,
                } => {
                    std::mem::swap(action, scratch);
                    action.clear();
                    action.extend(
                        weights
                            .chunks_exact(*inputs)
                            .zip(bias)
                            .map(|(row, b)| dot(row, scratch) + b),
                    );
                }
                Layer::Relu => action.iter_mut().for_each(|x| *x = x.max(0.0)),
                Layer::Tanh => action.iter_mut().for_each(|x| *x = libm::tanhf(*x)),
                Layer::Sigmoid => action
                    .iter_mut()
                    .for_each(|x| *x = 1.0 / (1.0 + libm::expf(-*x))),
            }
        }
        Ok(())
    }
}

/// `Σ w·x` in one fixed order: eight running sums over the elements by position modulo 8,
/// then folded pairwise. The order does not depend on the CPU (no fused multiply-add: Rust
/// never fuses on its own), and the eight independent sums still vectorise.
fn dot(w: &[f32], x: &[f32]) -> f32 {
    let mut acc = [0f32; 8];
    let (wc, xc) = (w.chunks_exact(8), x.chunks_exact(8));
    let (wr, xr) = (wc.remainder(), xc.remainder());
    for (a, b) in wc.zip(xc) {
        for i in 0..8 {
            acc[i] += a[i] * b[i];
        }
    }
    for (i, (a, b)) in wr.iter().zip(xr).enumerate() {
        acc[i] += a * b;
    }
    ((acc[0] + acc[1]) + (acc[2] + acc[3])) + ((acc[4] + acc[5]) + (acc[6] + acc[7]))
}

/// The chain of `graph`, checked.
fn build(graph: onnx::Graph, limits: &Limits) -> Result<Policy, PolicyError> {
    let onnx::Graph {
        nodes,
        mut constants,
        inputs,
        outputs,
    } = graph;
    // Older exporters list the initializers among the inputs too.
    let inputs: Vec<_> = inputs
        .into_iter()
        .filter(|i| !constants.contains_key(&i.name))
        .collect();
    let [input] = inputs.as_slice() else {
        return Err(PolicyError::NotAChain(format!(
            "{} inputs besides the weights; a policy takes one",
            inputs.len()
        )));
    };
    if input.elem_type != 1 {
        return Err(PolicyError::NotFloat(input.name.clone()));
    }
    let width = match input.dims.as_slice() {
        [Some(n)] | [_, Some(n)] => usize::try_from(*n).ok(),
        _ => None,
    }
    .filter(|&n| n > 0)
    .ok_or_else(|| {
        PolicyError::Shape(format!(
            "input `{}` must be [N] or [1, N], with N known",
            input.name
        ))
    })?;
    if width > limits.max_width {
        return Err(PolicyError::TooLarge("the input's width"));
    }
    let [output] = outputs.as_slice() else {
        return Err(PolicyError::NotAChain(format!(
            "{} outputs; a policy has one",
            outputs.len()
        )));
    };
    let mut layers = Vec::new();
    let mut current = input.name.clone();
    let mut width_now = width;
    let mut pending_matmul: Option<(Vec<f32>, usize, usize)> = None;
    for node in &nodes {
        if !node.domain.is_empty() && node.domain != "ai.onnx" {
            return Err(PolicyError::Unsupported(format!(
                "{}.{}",
                node.domain, node.op
            )));
        }
        // The node's data input is the chain's current value; the rest are constants.
        let (data, params): (Vec<&String>, Vec<&String>) = node
            .inputs
            .iter()
            .partition(|i| !constants.contains_key(*i));
        if data.len() != 1 || *data[0] != current {
            return Err(PolicyError::NotAChain(format!(
                "{} `{}` does not take the output of the node before it",
                node.op,
                node.outputs.first().map_or("", String::as_str)
            )));
        }
        let param = |k: usize| -> Result<&onnx::Tensor, PolicyError> {
            params
                .get(k)
                .and_then(|n| constants.get(*n))
                .ok_or_else(|| PolicyError::Shape(format!("{} lacks a constant operand", node.op)))
        };
        if pending_matmul.is_some() && node.op != "Add" {
            let (weights, inputs, outputs) = pending_matmul.take().unwrap_or_default();
            layers.push(Layer::Dense {
                weights,
                bias: vec![0.0; outputs],
                inputs,
            });
        }
        match node.op.as_str() {
            "Gemm" => {
                let alpha = node.floats.get("alpha").copied().unwrap_or(1.0);
                let beta = node.floats.get("beta").copied().unwrap_or(1.0);
                if alpha != 1.0 || beta != 1.0 || node.ints.get("transA").copied().unwrap_or(0) != 0
                {
                    return Err(PolicyError::Unsupported(
                        "Gemm with alpha or beta other than 1, or transA".into(),
                    ));
                }
                let trans_b = node.ints.get("transB").copied().unwrap_or(0) != 0;
                let (weights, outputs) = dense_weights(param(0)?, width_now, trans_b)?;
                let bias = match params.get(1) {
                    Some(_) => bias_of(param(1)?, outputs)?,
                    None => vec![0.0; outputs],
                };
                layers.push(Layer::Dense {
                    weights,
                    bias,
                    inputs: width_now,
                });
                width_now = outputs;
            }
            "MatMul" => {
                // x · W with W [in, out]: as Gemm without transB.
                let (weights, outputs) = dense_weights(param(0)?, width_now, false)?;
                pending_matmul = Some((weights, width_now, outputs));
                width_now = outputs;
            }
            "Add" => {
                let Some((weights, inputs, outputs)) = pending_matmul.take() else {
                    return Err(PolicyError::Unsupported(
                        "Add other than a MatMul's bias".into(),
                    ));
                };
                let bias = bias_of(param(0)?, outputs)?;
                layers.push(Layer::Dense {
                    weights,
                    bias,
                    inputs,
                });
            }
            "Relu" => layers.push(Layer::Relu),
            "Tanh" => layers.push(Layer::Tanh),
            "Sigmoid" => layers.push(Layer::Sigmoid),
            "Identity" | "Flatten" => {}
            other => return Err(PolicyError::Unsupported(other.to_string())),
        }
        if width_now > limits.max_width {
            return Err(PolicyError::TooLarge("a layer's width"));
        }
        current = node
            .outputs
            .first()
            .cloned()
            .ok_or_else(|| PolicyError::NotAChain(format!("{} has no output", node.op)))?;
        constants.remove(&current);
    }
    if let Some((weights, inputs, outputs)) = pending_matmul.take() {
        layers.push(Layer::Dense {
            weights,
            bias: vec![0.0; outputs],
            inputs,
        });
    }
    if *output != current {
        return Err(PolicyError::NotAChain(format!(
            "the output `{output}` is not the last node's"
        )));
    }
    Ok(Policy {
        input_len: width,
        output_len: width_now,
        layers,
    })
}

/// A dense layer's weights as `outputs × inputs` row-major, from `w`: `[inputs, outputs]`
/// (ONNX's `B` of `x·B`), or `[outputs, inputs]` when `transposed` (torch's `Linear`).
fn dense_weights(
    w: &onnx::Tensor,
    inputs: usize,
    transposed: bool,
) -> Result<(Vec<f32>, usize), PolicyError> {
    let [a, b] = w.dims.as_slice() else {
        return Err(PolicyError::Shape(format!(
            "weights of {} dimensions; a dense layer's have 2",
            w.dims.len()
        )));
    };
    let (rows, cols) = (*a, *b);
    if transposed {
        if cols != inputs {
            return Err(PolicyError::Shape(format!(
                "weights [{rows}, {cols}] after a layer of {inputs}"
            )));
        }
        return Ok((w.data.clone(), rows));
    }
    if rows != inputs {
        return Err(PolicyError::Shape(format!(
            "weights [{rows}, {cols}] after a layer of {inputs}"
        )));
    }
    let mut t = vec![0.0; rows * cols];
    for i in 0..rows {
        for o in 0..cols {
            t[o * rows + i] = w.data[i * cols + o];
        }
    }
    Ok((t, cols))
}

fn bias_of(b: &onnx::Tensor, outputs: usize) -> Result<Vec<f32>, PolicyError> {
    let n: usize = b.dims.iter().product();
    if n != outputs || b.dims.iter().filter(|&&d| d != 1).count() > 1 {
        return Err(PolicyError::Shape(format!(
            "a bias of {:?} for a layer of {outputs}",
            b.dims
        )));
    }
    Ok(b.data.clone())
}

/// Models built in memory, as an exporter writes them: for tests (here, in the server and in
/// the engines) and for a policy made without training.
pub mod testing {
    pub use crate::proto_writer::{DenseLayer, model};
}

mod proto_writer {
    use crate::proto::write::{bytes, int};

    /// A dense layer as [`model`] takes it: weights `[outputs][inputs]`, bias, and the
    /// activation's operator after it (`""`: none).
    pub type DenseLayer<'a> = (Vec<Vec<f32>>, Vec<f32>, &'a str);

    /// An ONNX model's bytes: input `obs` `[1, n]`, then for each layer a `Gemm` (transB, as
    /// torch exports a `Linear`) and its activation's node.
    pub fn model(n: usize, layers: &[DenseLayer]) -> Vec<u8> {
        let mut graph = Vec::new();
        let mut current = "obs".to_string();
        for (k, (w, b, activation)) in layers.iter().enumerate() {
            let (wn, bn, out) = (format!("w{k}"), format!("b{k}"), format!("h{k}"));
            let flat: Vec<f32> = w.iter().flatten().copied().collect();
            tensor(
                &mut graph,
                &wn,
                &[w.len(), w.first().map_or(0, Vec::len)],
                &flat,
            );
            tensor(&mut graph, &bn, &[b.len()], b);
            let mut node = Vec::new();
            for i in [&current, &wn, &bn] {
                bytes(&mut node, 1, i.as_bytes());
            }
            bytes(&mut node, 2, out.as_bytes());
            bytes(&mut node, 4, b"Gemm");
            let mut attr = Vec::new();
            bytes(&mut attr, 1, b"transB");
            int(&mut attr, 3, 1);
            int(&mut attr, 20, 2);
            bytes(&mut node, 5, &attr);
            bytes(&mut graph, 1, &node);
            current = out;
            if !activation.is_empty() {
                let out = format!("a{k}");
                let mut node = Vec::new();
                bytes(&mut node, 1, current.as_bytes());
                bytes(&mut node, 2, out.as_bytes());
                bytes(&mut node, 4, activation.as_bytes());
                bytes(&mut graph, 1, &node);
                current = out;
            }
        }
        let value_info = |name: &str, dims: &[usize]| {
            let mut shape = Vec::new();
            for &d in dims {
                let mut dim = Vec::new();
                int(&mut dim, 1, d as i64);
                bytes(&mut shape, 1, &dim);
            }
            let mut tensor_type = Vec::new();
            int(&mut tensor_type, 1, 1);
            bytes(&mut tensor_type, 2, &shape);
            let mut ty = Vec::new();
            bytes(&mut ty, 1, &tensor_type);
            let mut v = Vec::new();
            bytes(&mut v, 1, name.as_bytes());
            bytes(&mut v, 2, &ty);
            v
        };
        let outputs = layers.last().map_or(n, |l| l.1.len());
        bytes(&mut graph, 11, &value_info("obs", &[1, n]));
        bytes(&mut graph, 12, &value_info(&current, &[1, outputs]));
        let mut model = Vec::new();
        int(&mut model, 1, 8);
        bytes(&mut model, 7, &graph);
        model
    }

    fn tensor(graph: &mut Vec<u8>, name: &str, dims: &[usize], data: &[f32]) {
        let mut t = Vec::new();
        for &d in dims {
            int(&mut t, 1, d as i64);
        }
        int(&mut t, 2, 1);
        bytes(&mut t, 8, name.as_bytes());
        let raw: Vec<u8> = data.iter().flat_map(|x| x.to_le_bytes()).collect();
        bytes(&mut t, 9, &raw);
        bytes(graph, 5, &t);
    }
}

#[cfg(test)]
mod tests;
