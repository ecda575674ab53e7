//! The policies the project ships, built into the binary: listed from the start by the
//! server, and played by name (`policy:<name>`) in the Python environment and the
//! experiments. Each file's making is described beside it (`policy/shipped/<name>.md`).

/// Every shipped policy: its name and its ONNX bytes.
pub const SHIPPED: &[(&str, &[u8])] = &[("learned", include_bytes!("shipped/learned.onnx"))];

/// A shipped policy's ONNX bytes by name.
pub fn shipped(name: &str) -> Option<&'static [u8]> {
    SHIPPED.iter().find(|(n, _)| *n == name).map(|(_, b)| *b)
}
