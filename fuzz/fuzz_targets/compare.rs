//! Any bytes split at the first NUL into run A's `steps.json` and the manifest of its step
//! `s` (run B holds the same manifest), compared with `unseen compare`'s reader: Ok or a
//! clear error; no panic, and never a step or file outside the runs.
#![no_main]
use libfuzzer_sys::fuzz_target;
#[path = "common.rs"]
mod common;

fuzz_target!(|data: &[u8]| {
    let mut parts = data.splitn(2, |&b| b == 0);
    let (steps, manifest) = (parts.next().unwrap_or(&[]), parts.next().unwrap_or(&[]));
    let root = common::file_with("steps.json", steps).parent().unwrap().to_path_buf();
    let (a, b) = (root.join("a"), root.join("b"));
    for run in [&a, &b] {
        std::fs::create_dir_all(run.join("s")).unwrap();
        std::fs::write(run.join("s").join("manifest.json"), manifest).unwrap();
    }
    std::fs::write(a.join("steps.json"), steps).unwrap();
    if let Ok(c) = unseen::pipeline::compare::compare(&a, &b, 0.0) {
        let _ = c.table();
    }
});
