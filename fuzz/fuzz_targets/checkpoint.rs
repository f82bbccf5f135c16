//! Any bytes as a training checkpoint, with a valid sha256 trailer appended (else the
//! digest check would stop nearly every input before the header): a state or a clear
//! error; never a panic or an allocation the file cannot warrant.
#![no_main]
use libfuzzer_sys::fuzz_target;
#[path = "common.rs"]
mod common;

fuzz_target!(|data: &[u8]| {
    use sha2::Digest;
    let mut bytes = data.to_vec();
    bytes.extend_from_slice(&sha2::Sha256::digest(data));
    let p = common::file_with("checkpoint.bin", &bytes);
    if let Ok(c) = unseen::train::checkpoint::Checkpoint::read(&p) {
        assert_eq!(c.gaussians.len(), c.header.gaussians);
    }
});
