//! Any bytes as the files a pipeline reads back from a run: a run's `manifest.json`
//! through `train::run::read_train_views` (Ok: a list of names), and a depth map through
//! `io::image::read_depth` at a size from the first two bytes (Ok: exactly width × height
//! values). A clear error otherwise; never a panic.
#![no_main]
use libfuzzer_sys::fuzz_target;
#[path = "common.rs"]
mod common;

fuzz_target!(|data: &[u8]| {
    let p = common::file_with("manifest.json", data);
    let _ = unseen::train::run::read_train_views(p.parent().unwrap());
    if data.len() >= 2 {
        let (w, h) = (1 + data[0] as usize % 64, 1 + data[1] as usize % 64);
        let p = common::file_with("d.depth.exr", &data[2..]);
        if let Ok(d) = unseen::io::image::read_depth(&p, w, h) {
            assert_eq!(d.len(), w * h, "a depth map of another size was accepted");
        }
    }
});
