//! Any bytes as a training config, a pipeline config, a run manifest and an audit's samples
//! (the JSON files a user or a previous run hands us): parsed and validated, or a clear
//! error; never a panic. Samples that parse are judged (the audit's statistics on
//! arbitrary values).
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
    let p = common::file_with("samples.json", data);
    if let Ok(s) = unseen::audit::Samples::read(&p) {
        use unseen::audit::{AuditConfig, stats::Rule, verdicts};
        let rule = Rule {
            replicates: 100,
            ..Rule::default()
        };
        let _ = verdicts(&AuditConfig::quick(), &s.samples, &rule);
    }
});
