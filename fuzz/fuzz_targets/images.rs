//! Any bytes as PNG, EXR and npy through our readers (which check declared sizes before
//! decoding): an image or a clear error; never a panic or an allocation the file cannot
//! warrant.
#![no_main]
use libfuzzer_sys::fuzz_target;
#[path = "common.rs"]
mod common;

fuzz_target!(|data: &[u8]| {
    let p = common::file_with("image.png", data);
    let _ = unseen::io::image::read_png(&p);
    let _ = unseen::io::image::read_rgb(&p, [0.0; 3]);
    let p = common::file_with("image.exr", data);
    let _ = unseen::io::image::read_exr(&p, &["Y"]);
    let p = common::file_with("array.npy", data);
    let _ = unseen::io::npy::read_npy_f32(&p);
});
