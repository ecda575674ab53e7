//! Uploaded policies: bytes → `Policy::from_onnx` (the protobuf reader, the graph's checks,
//! the limits), then an inference on an observation of the right length.
//!
//! Half the inputs are raw bytes; the other half are real models (`testing::model`: dense
//! layers with activations, some outside the allow-list) with a few bytes overwritten where
//! the input says, so the checks past the wire format are reached. Besides "no panic", it
//! checks what the server relies on: a model that passes runs, and gives `output_len` values.
#![no_main]

use lasertag_policy::testing::{DenseLayer, model};
use lasertag_policy::{Limits, Policy};
use libfuzzer_sys::fuzz_target;

const ACTIVATIONS: [&str; 6] = ["", "Relu", "Tanh", "Sigmoid", "Softmax", "Conv"];

fuzz_target!(|data: &[u8]| {
    let Some((&mode, rest)) = data.split_first() else {
        return;
    };
    let bytes = if mode % 2 == 0 {
        rest.to_vec()
    } else {
        let mut it = rest.iter().copied();
        let mut next = || it.next().unwrap_or(0);
        let inputs = 1 + usize::from(next() % 8);
        let mut width = inputs;
        let mut layers: Vec<DenseLayer> = Vec::new();
        for _ in 0..1 + next() % 3 {
            let outputs = 1 + usize::from(next() % 8);
            let weights = (0..outputs)
                .map(|_| (0..width).map(|_| f32::from(next() as i8) / 16.0).collect())
                .collect();
            let bias = (0..outputs)
                .map(|_| f32::from(next() as i8) / 16.0)
                .collect();
            layers.push((
                weights,
                bias,
                ACTIVATIONS[usize::from(next()) % ACTIVATIONS.len()],
            ));
            width = outputs;
        }
        let mut m = model(inputs, &layers);
        // The rest, in pairs: a position and the byte put there.
        let tail: Vec<u8> = rest.iter().skip(64).copied().collect();
        for pair in tail.chunks_exact(2) {
            let at = usize::from(pair[0]) * m.len() / 256;
            m[at] = pair[1];
        }
        m
    };
    let limits = Limits {
        max_parameters: 1 << 16,
        ..Limits::default()
    };
    if let Ok(p) = Policy::from_onnx(&bytes, &limits) {
        let obs: Vec<f32> = (0..p.input_len()).map(|i| i as f32 / 7.0 - 0.5).collect();
        let (mut out, mut scratch) = (Vec::new(), Vec::new());
        p.infer(&obs, &mut out, &mut scratch)
            .expect("a checked model runs on an observation of its length");
        assert_eq!(out.len(), p.output_len());
    }
});
