//! Helpers shared by the engine's suites (`tests/engine/`) and the program's (`tests/suite/`);
//! each test binary uses part of them.
#![allow(dead_code)]
use std::path::{Path, PathBuf};

pub mod tiny_run;

/// The repository's root: the folder holding `reference_data/`, at or above the manifest
/// of the package these tests belong to.
pub fn repo_root() -> PathBuf {
    let manifest = PathBuf::from(env!("CARGO_MANIFEST_DIR"));
    manifest
        .ancestors()
        .find(|d| d.join("reference_data").is_dir())
        .unwrap_or_else(|| panic!("no reference_data/ at or above {}", manifest.display()))
        .to_path_buf()
}

/// `reference_data/<rel>` in the source tree.
pub fn reference(rel: &str) -> PathBuf {
    repo_root().join("reference_data").join(rel)
}

/// Run `f` inside a rayon pool of `threads` threads.
pub fn with_threads<T: Send>(threads: usize, f: impl FnOnce() -> T + Send) -> T {
    rayon::ThreadPoolBuilder::new()
        .num_threads(threads)
        .build()
        .unwrap()
        .install(f)
}

/// Bit patterns of a float slice, for exact comparisons that also see -0.0 and NaN payloads.
pub fn bits(v: &[f32]) -> Vec<u32> {
    v.iter().map(|x| x.to_bits()).collect()
}

/// The case folders under `reference_data/<rel>`, sorted by name.
pub fn case_dirs(rel: &str) -> Vec<PathBuf> {
    let root = reference(rel);
    let mut cases: Vec<PathBuf> = std::fs::read_dir(&root)
        .unwrap_or_else(|e| panic!("{}: {e}", root.display()))
        .map(|e| e.unwrap().path())
        .filter(|p| p.is_dir())
        .collect();
    cases.sort();
    cases
}

/// Every file under `d`, in the order the file system lists them.
pub fn walk(d: &Path) -> Vec<PathBuf> {
    let mut out = Vec::new();
    for e in std::fs::read_dir(d).unwrap().flatten() {
        let p = e.path();
        if p.is_dir() {
            out.extend(walk(&p));
        } else {
            out.push(p);
        }
    }
    out
}

/// The short training preset of the training and QA-Mask tests: INRIA's recipe with
/// densification from iteration 100 every 100, an opacity reset at 250, SH degree +1 every
/// 200 iterations, nothing saved.
pub fn short_train_config(iterations: u32) -> unseen::train::trainer::TrainConfig {
    use unseen::train::densify::DensifyConfig;
    unseen::train::trainer::TrainConfig {
        iterations,
        sh_increase_interval: 200,
        densify: Some(DensifyConfig {
            from_iter: 100,
            interval: 100,
            opacity_reset_interval: 250,
            ..DensifyConfig::default()
        }),
        save_iterations: vec![],
        ..Default::default()
    }
}

/// A path under the system temp dir, unique to this process and `name`, removed (file or
/// folder) when the guard drops — also when the test panics, since the guard drops during
/// unwinding. [`TempDir::new`] creates the folder; [`TempDir::path_only`] leaves the path
/// free for the code under test to create.
pub struct TempDir(pub PathBuf);

impl TempDir {
    pub fn new(name: &str) -> TempDir {
        let t = TempDir::path_only(name);
        std::fs::create_dir_all(&t.0).unwrap();
        t
    }
    pub fn path_only(name: &str) -> TempDir {
        let d = std::env::temp_dir().join(format!("unseen-{name}-{}", std::process::id()));
        remove(&d);
        TempDir(d)
    }
    pub fn path(&self) -> &std::path::Path {
        &self.0
    }
}

fn remove(p: &std::path::Path) {
    if p.is_dir() {
        let _ = std::fs::remove_dir_all(p);
    } else {
        let _ = std::fs::remove_file(p);
    }
}

impl Drop for TempDir {
    fn drop(&mut self) {
        remove(&self.0);
    }
}

impl std::ops::Deref for TempDir {
    type Target = std::path::Path;
    fn deref(&self) -> &std::path::Path {
        &self.0
    }
}

impl AsRef<std::path::Path> for TempDir {
    fn as_ref(&self) -> &std::path::Path {
        &self.0
    }
}

impl AsRef<std::ffi::OsStr> for TempDir {
    fn as_ref(&self) -> &std::ffi::OsStr {
        self.0.as_os_str()
    }
}

/// A pipeline event sink that drops every event.
pub fn quiet(_: unseen::pipeline::Event) {}
