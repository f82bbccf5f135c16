//! Shared by the targets that exercise path-based readers: the input bytes are written to
//! a file in this process's scratch folder (libFuzzer runs one input at a time).
#![allow(dead_code)]
use std::path::PathBuf;

/// `<temp>/unseen-fuzz-<pid>/<name>` holding `data`.
pub fn file_with(name: &str, data: &[u8]) -> PathBuf {
    let dir = std::env::temp_dir().join(format!("unseen-fuzz-{}", std::process::id()));
    std::fs::create_dir_all(&dir).unwrap();
    let p = dir.join(name);
    std::fs::write(&p, data).unwrap();
    p
}
