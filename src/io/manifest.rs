//! The typed `manifest.json` of a pipeline step (SPEC.md §20.8): crate version, the step,
//! its inputs (settings and upstream digests) and the sha256 of every file it wrote. No
//! timings, so equal inputs give equal manifest bytes.

/// One written file, relative to the manifest's folder.
#[derive(Clone, Debug, PartialEq, Eq, serde::Serialize, serde::Deserialize)]
pub struct FileEntry {
    pub path: String,
    pub sha256: String,
}

/// A step's manifest.
#[derive(Clone, Debug, PartialEq, serde::Serialize, serde::Deserialize)]
pub struct Manifest {
    pub crate_version: String,
    pub command: String,
    pub step: String,
    /// What the step was computed from: its settings and the digests of the steps it read.
    pub inputs: serde_json::Value,
    /// sha256 of `inputs` serialized compactly (the resume key).
    pub inputs_sha256: String,
    /// Sorted by path.
    pub files: Vec<FileEntry>,
}
