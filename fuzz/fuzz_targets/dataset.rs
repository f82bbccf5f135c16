//! Any bytes as the `split.json` of a small unseen-layout dataset (three 4×3 views `a`, `b`,
//! `c`, written once per process), loaded with `dataset::load`: Ok with train / held-out /
//! test lists that name loaded views and never share one, or a clear error; no panic.
#![no_main]
use libfuzzer_sys::fuzz_target;
use std::path::PathBuf;
#[path = "common.rs"]
mod common;

fn fixture() -> &'static PathBuf {
    static ROOT: std::sync::OnceLock<PathBuf> = std::sync::OnceLock::new();
    ROOT.get_or_init(|| {
        let cams: Vec<unseen::camera::Camera> = ["a", "b", "c"]
            .iter()
            .enumerate()
            .map(|(k, n)| {
                unseen::camera::Camera::look_at(*n, 4, 3, 1.0, [k as f64, 0.0, -3.0].into(),
                    [0.0, 0.0, 0.0].into(), [0.0, -1.0, 0.0].into()).unwrap()
            })
            .collect();
        let cameras = common::file_with("cameras.json",
            unseen::camera::inria::cameras_json_string(&cams).as_bytes());
        let root = cameras.parent().unwrap().to_path_buf();
        std::fs::create_dir_all(root.join("images")).unwrap();
        let img = unseen::io::image::ImageF32::new(4, 3, 3, vec![0.5; 36]).unwrap();
        for n in ["a", "b", "c"] {
            unseen::io::image::write_png(&root.join("images").join(format!("{n}.png")), &img)
                .unwrap();
        }
        root
    })
}

fuzz_target!(|data: &[u8]| {
    let root = fixture();
    std::fs::write(root.join("split.json"), data).unwrap();
    if let Ok(d) = unseen::dataset::load(root, &unseen::dataset::LoadOptions::default()) {
        let n = d.views.len();
        for list in [&d.train, &d.heldout, &d.test] {
            assert!(list.iter().all(|&i| i < n), "index out of range");
        }
        assert!(d.heldout.iter().all(|i| !d.train.contains(i) && !d.test.contains(i)),
            "a held-out view is trained on or tested");
    }
});
