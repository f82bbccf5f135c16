//! Any bytes split at their first two NUL bytes into cameras.txt / images.txt /
//! points3D.txt (text has no NUL) and read as a COLMAP text model: Ok or a clear error, no
//! panic. Without two NULs the rest is empty files.
#![no_main]
use libfuzzer_sys::fuzz_target;
#[path = "common.rs"]
mod common;

fuzz_target!(|data: &[u8]| {
    let mut parts = data.splitn(3, |&b| b == 0);
    let (c, i, p) = (
        parts.next().unwrap_or(&[]),
        parts.next().unwrap_or(&[]),
        parts.next().unwrap_or(&[]),
    );
    common::file_with("cameras.txt", c);
    common::file_with("images.txt", i);
    let dir = common::file_with("points3D.txt", p);
    let _ = unseen::camera::colmap::read_colmap_model(dir.parent().unwrap());
});
