//! Any bytes as a training checkpoint: a state or a clear error; never a panic or an
//! allocation the file cannot warrant.
#![no_main]
use libfuzzer_sys::fuzz_target;
#[path = "common.rs"]
mod common;

fuzz_target!(|data: &[u8]| {
    let p = common::file_with("checkpoint.bin", data);
    if let Ok(c) = unseen::train::checkpoint::Checkpoint::read(&p) {
        assert_eq!(c.gaussians.len(), c.header.gaussians);
    }
});
