//! The policy runtime against models written as exporters write them: what runs gives what
//! the layers' arithmetic gives, what is outside the allow-list or the limits is refused by
//! name, and no bytes make it panic.

use proptest::prelude::*;

use crate::proto::write::{bytes, int};
use crate::testing::model;
use crate::{Limits, Policy, PolicyError};

fn two_layers() -> Vec<u8> {
    model(
        3,
        &[
            (
                vec![vec![1.0, 0.0, -1.0], vec![0.5, 0.5, 0.5]],
                vec![0.1, -0.2],
                "Relu",
            ),
            (vec![vec![2.0, -1.0]], vec![0.0], "Tanh"),
        ],
    )
}

fn run(p: &Policy, obs: &[f32]) -> Vec<f32> {
    let (mut out, mut scratch) = (Vec::new(), Vec::new());
    p.infer(obs, &mut out, &mut scratch).expect("it runs");
    out
}

#[test]
fn dense_layers_compute_what_their_arithmetic_gives() {
    let p = Policy::from_onnx(&two_layers(), &Limits::default()).expect("a policy");
    assert_eq!(
        (p.input_len(), p.output_len(), p.multiply_adds()),
        (3, 1, 8)
    );
    let obs = [1.0, 2.0, 3.0];
    let h0 = (1.0f32 - 3.0 + 0.1).max(0.0);
    let h1 = (0.5f32 * 1.0 + 0.5 * 2.0 + 0.5 * 3.0 - 0.2).max(0.0);
    assert_eq!(run(&p, &obs), [libm::tanhf(2.0 * h0 - h1)]);
    // The wrong length is an error naming both.
    let (mut out, mut scratch) = (Vec::new(), Vec::new());
    assert_eq!(
        p.infer(&[1.0], &mut out, &mut scratch),
        Err(PolicyError::InputLength {
            expected: 3,
            got: 1
        })
    );
}

#[test]
fn a_long_dot_product_sums_in_one_fixed_order() {
    // 1e8 + 1 - 1e8 in f32 depends on the order: the fixed one is part of the contract.
    let n = 19;
    let w: Vec<f32> = (0..n).map(|i| if i % 3 == 0 { 1e8 } else { 1.0 }).collect();
    let obs: Vec<f32> = (0..n)
        .map(|i| if i % 6 == 0 { -1.0 } else { 1.0 })
        .collect();
    let p = Policy::from_onnx(
        &model(n, &[(vec![w.clone()], vec![0.0], "")]),
        &Limits::default(),
    )
    .expect("a policy");
    let mut acc = [0f32; 8];
    for i in 0..n {
        acc[i % 8] += w[i] * obs[i];
    }
    let expected =
        ((acc[0] + acc[1]) + (acc[2] + acc[3])) + ((acc[4] + acc[5]) + (acc[6] + acc[7]));
    assert_eq!(run(&p, &obs)[0].to_bits(), expected.to_bits());
}

#[test]
fn an_unsupported_operator_is_refused_by_name() {
    // A real graph with one node's operator renamed (same length: the bytes stay valid).
    let good = two_layers();
    let at = good
        .windows(4)
        .position(|w| w == b"Tanh")
        .expect("the node");
    let mut bad = good.clone();
    bad[at..at + 4].copy_from_slice(b"Erfx");
    let e = Policy::from_onnx(&bad, &Limits::default()).unwrap_err();
    assert_eq!(e, PolicyError::Unsupported("Erfx".into()));
    assert!(e.to_string().contains("Gemm, MatMul"), "{e}");
}

#[test]
fn limits_refuse_what_is_too_large() {
    let small = Limits {
        max_parameters: 4,
        ..Limits::default()
    };
    let e = Policy::from_onnx(&two_layers(), &small).unwrap_err();
    assert!(matches!(e, PolicyError::TooLarge(_)), "{e}");
    let narrow = Limits {
        max_width: 2,
        ..Limits::default()
    };
    assert_eq!(
        Policy::from_onnx(&two_layers(), &narrow).unwrap_err(),
        PolicyError::TooLarge("the input's width")
    );
}

#[test]
fn weights_that_do_not_fit_the_layer_before_are_refused() {
    let m = model(4, &[(vec![vec![1.0, 2.0, 3.0]], vec![0.0], "")]);
    let e = Policy::from_onnx(&m, &Limits::default()).unwrap_err();
    assert!(matches!(e, PolicyError::Shape(_)), "{e}");
}

#[test]
fn not_a_model_is_said_so() {
    for bytes in [&b""[..], b"PK\x03\x04 a zip file", &[0xff; 64]] {
        let e = Policy::from_onnx(bytes, &Limits::default()).unwrap_err();
        assert!(matches!(e, PolicyError::Malformed(_)), "{e}");
    }
    // A model whose weights hold a NaN.
    let m = model(1, &[(vec![vec![f32::NAN]], vec![0.0], "")]);
    assert_eq!(
        Policy::from_onnx(&m, &Limits::default()).unwrap_err(),
        PolicyError::NotFinite("w0".into())
    );
    // A model with no input declared.
    let mut graph = Vec::new();
    let mut out = Vec::new();
    bytes(&mut out, 1, b"y");
    bytes(&mut graph, 12, &out);
    let mut m = Vec::new();
    int(&mut m, 1, 8);
    bytes(&mut m, 7, &graph);
    assert!(matches!(
        Policy::from_onnx(&m, &Limits::default()).unwrap_err(),
        PolicyError::NotAChain(_)
    ));
}

proptest! {
    #[test]
    fn no_bytes_make_it_panic(data in proptest::collection::vec(any::<u8>(), 0..2048)) {
        let _ = Policy::from_onnx(&data, &Limits::default());
    }

    #[test]
    fn no_corruption_of_a_real_model_makes_it_panic(
        flips in proptest::collection::vec((any::<prop::sample::Index>(), any::<u8>()), 1..8)
    ) {
        let mut m = two_layers();
        for (at, byte) in flips {
            let i = at.index(m.len());
            m[i] = byte;
        }
        if let Ok(p) = Policy::from_onnx(&m, &Limits::default()) {
            let obs = vec![0.5; p.input_len()];
            let (mut out, mut scratch) = (Vec::new(), Vec::new());
            p.infer(&obs, &mut out, &mut scratch).expect("a checked model runs");
            prop_assert_eq!(out.len(), p.output_len());
        }
    }
}
