//! Any bytes as a NeRF transforms.json: cameras or a clear error; never a panic.
#![no_main]
use libfuzzer_sys::fuzz_target;
#[path = "common.rs"]
mod common;

fuzz_target!(|data: &[u8]| {
    let p = common::file_with("transforms.json", data);
    let _ = unseen::camera::transforms::read_transforms_json(&p);
});
