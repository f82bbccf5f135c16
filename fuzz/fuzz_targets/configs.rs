//! Any bytes as a training config, a pipeline config and a run manifest (the JSON files a
//! user or a previous run hands us): parsed and validated, or a clear error; never a panic.
#![no_main]
use libfuzzer_sys::fuzz_target;
#[path = "common.rs"]
mod common;

fuzz_target!(|data: &[u8]| {
    if let Ok(c) = serde_json::from_slice::<unseen::train::trainer::TrainConfig>(data) {
        let _ = c.validate();
    }
    if let Ok(c) = serde_json::from_slice::<unseen::pipeline::PipelineConfig>(data) {
        let _ = c.validate();
    }
    let p = common::file_with("manifest.json", data);
    let _ = unseen::io::manifest::Manifest::read(p.parent().unwrap());
    let p = common::file_with("config.json", data);
    let _ = unseen::train::run::read_config(p.parent().unwrap());
});
