//! Any bytes as an ONNX model card (beside a missing model file): a clear error, never a
//! panic.
#![no_main]
use libfuzzer_sys::fuzz_target;
#[path = "common.rs"]
mod common;

fuzz_target!(|data: &[u8]| {
    let p = common::file_with("card.json", data);
    let _ = unseen::models::onnx::OnnxModel::load(&p);
});
