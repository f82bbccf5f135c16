//! Any bytes as the candidate and evaluation view lists of `unseen extrapolate` (split at
//! the first NUL: `candidates.json`, `evaluation.json`), loaded by `pipeline::load_inputs`
//! against a fixture (a four-view 4×3 dataset — `a`, `b` trained, `c`, `d` held out, with
//! depth — and a one-iteration run on it, made once per process): Ok with a non-empty list of valid, uniquely named candidates and evaluation
//! views that have truth and are neither candidates nor trained on, or a clear error;
//! never a panic.
#![no_main]
use libfuzzer_sys::fuzz_target;
use std::path::PathBuf;
#[path = "common.rs"]
mod common;

fn fixture() -> &'static (PathBuf, PathBuf) {
    static ROOT: std::sync::OnceLock<(PathBuf, PathBuf)> = std::sync::OnceLock::new();
    ROOT.get_or_init(|| {
        let cams: Vec<unseen::camera::Camera> = ["a", "b", "c", "d"]
            .iter()
            .enumerate()
            .map(|(k, n)| {
                unseen::camera::Camera::look_at(*n, 4, 3, 1.0, [k as f64, 0.0, -3.0].into(),
                    [0.0, 0.0, 0.0].into(), [0.0, -1.0, 0.0].into()).unwrap()
            })
            .collect();
        let cameras = common::file_with("cameras.json",
            unseen::camera::inria::cameras_json_string(&cams).as_bytes());
        let data = cameras.parent().unwrap().join("dataset");
        std::fs::create_dir_all(data.join("images")).unwrap();
        std::fs::create_dir_all(data.join("depth")).unwrap();
        std::fs::rename(&cameras, data.join("cameras.json")).unwrap();
        let img = unseen::io::image::ImageF32::new(4, 3, 3, vec![0.5; 36]).unwrap();
        let depth = unseen::io::image::ImageF32::new(4, 3, 1, vec![3.0; 12]).unwrap();
        for n in ["a", "b", "c", "d"] {
            unseen::io::image::write_png(&data.join("images").join(format!("{n}.png")), &img)
                .unwrap();
            unseen::io::image::write_exr(&data.join("depth").join(format!("{n}.exr")), &depth)
                .unwrap();
        }
        std::fs::write(data.join("split.json"), r#"{"train": ["a", "b"], "heldout": ["c", "d"]}"#)
            .unwrap();
        let run = data.parent().unwrap().join("run");
        let cfg = unseen::train::trainer::TrainConfig {
            iterations: 1,
            save_iterations: vec![],
            ..Default::default()
        };
        unseen::train::run::train_run(&data, &run, &cfg, None, Default::default(), &mut |_| {})
            .unwrap();
        (data, run)
    })
}

fuzz_target!(|bytes: &[u8]| {
    let (data, run) = fixture();
    let cut = bytes.iter().position(|&b| b == 0).unwrap_or(bytes.len());
    let cands = common::file_with("candidates.json", &bytes[..cut]);
    let eval = common::file_with("evaluation.json", bytes.get(cut + 1..).unwrap_or(&[]));
    if let Ok(inp) = unseen::pipeline::load_inputs(run, &cands, Some(&eval), Some(data)) {
        assert!(!inp.candidates.is_empty(), "an empty candidate list was accepted");
        for (i, c) in inp.candidates.iter().enumerate() {
            assert!(c.validate().is_ok(), "an invalid candidate was accepted");
            assert!(inp.candidates[..i].iter().all(|d| d.name != c.name), "a name twice");
        }
        for &e in &inp.evaluation {
            assert!(e < inp.data.views.len());
            assert!(!inp.data.train.contains(&e), "an evaluation view is trained on");
            let name = &inp.data.views[e].camera.name;
            assert!(inp.candidates.iter().all(|c| &c.name != name));
        }
    }
});
