//! The in-process research engine (`lasertag_env._native`): bytes → its constructor's
//! arguments and a run of resets and steps, through `lasertag_core::env::engine`, the code
//! the Python module runs for every check and step (a pyo3 extension module cannot be
//! linked here; the engine module says why its checks live in the core).
//!
//! The body is `exercise` beside the engine, so that `cargo test` runs it on fixed inputs
//! too; it panics when a promise breaks (a count past its bound accepted, a refusal without
//! a field, a vector value outside its bounds or NaN, a reward not finite).
#![no_main]

use lasertag_core::env::engine::exercise::exercise;
use libfuzzer_sys::fuzz_target;

fuzz_target!(|data: &[u8]| {
    exercise(data);
});
