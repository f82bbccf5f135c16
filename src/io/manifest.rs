//! The one `manifest.json` shape (SPEC.md §10): written by `unseen train`, `unseen qa-mask`,
//! `unseen oracle` and every step of `unseen extrapolate` — crate and conventions version,
//! the command (and pipeline step), what it was computed from (`inputs`, with the sha256
//! of their compact JSON), and the sha256 of every file it wrote. No timings, so equal
//! inputs give equal manifest bytes.

use crate::error::{Error, Result};
use crate::io::{sha256_hex, write_text};
use std::path::Path;

/// One written file, relative to the manifest's folder.
#[derive(Clone, Debug, PartialEq, Eq, serde::Serialize, serde::Deserialize)]
pub struct FileEntry {
    pub path: String,
    pub sha256: String,
    /// For arrays (`.npy` dumps): the name, shape and NumPy dtype.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub name: Option<String>,
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub shape: Option<Vec<usize>>,
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub dtype: Option<String>,
}

impl FileEntry {
    /// A file and the sha256 of its bytes.
    pub fn new(path: impl Into<String>, bytes: &[u8]) -> FileEntry {
        FileEntry::hashed(path, sha256_hex(bytes))
    }

    /// A file whose sha256 is already known.
    pub fn hashed(path: impl Into<String>, sha256: String) -> FileEntry {
        FileEntry {
            path: path.into(),
            sha256,
            name: None,
            shape: None,
            dtype: None,
        }
    }
}

/// A command's (or pipeline step's) manifest.
#[derive(Clone, Debug, PartialEq, serde::Serialize, serde::Deserialize)]
pub struct Manifest {
    pub crate_version: String,
    pub conventions_version: u32,
    /// The convention profile of the renders behind the files (SPEC.md §5.2), when it is
    /// not the default `inria` (absent: `inria`; so manifests of default runs keep their
    /// bytes).
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub conventions: Option<String>,
    /// [`crate::version::NUMERICS_REVISION`] of the binary that wrote it (0: written before
    /// the field existed): outputs are bit-reproducible by a binary of the same revision.
    #[serde(default)]
    pub numerics_revision: u32,
    /// `train`, `qa-mask`, `oracle forward`, `oracle backward`, `extrapolate`.
    pub command: String,
    /// The pipeline step (`views`, `stage1/recon`, ...); empty for other commands.
    #[serde(default)]
    pub step: String,
    /// What the output was computed from: settings, seeds, and the digests of the
    /// manifests it read.
    pub inputs: serde_json::Value,
    /// sha256 of `inputs` serialized compactly (the resume key of a pipeline step).
    pub inputs_sha256: String,
    pub files: Vec<FileEntry>,
}

impl Manifest {
    pub fn new(
        command: &str,
        step: &str,
        inputs: serde_json::Value,
        files: Vec<FileEntry>,
    ) -> Manifest {
        Manifest {
            crate_version: env!("CARGO_PKG_VERSION").into(),
            conventions_version: crate::version::CONVENTIONS_VERSION,
            conventions: None,
            numerics_revision: crate::version::NUMERICS_REVISION,
            command: command.into(),
            step: step.into(),
            inputs_sha256: inputs_sha256(&inputs),
            inputs,
            files,
        }
    }

    /// The manifest's bytes (pretty JSON).
    pub fn text(&self) -> String {
        serde_json::to_string_pretty(self).expect("manifest serializes") + "\n"
    }

    /// Write `dir/manifest.json` atomically; returns the sha256 of its bytes.
    pub fn write(&self, dir: &Path) -> Result<String> {
        let text = self.text();
        write_text(&dir.join("manifest.json"), &text)?;
        Ok(sha256_hex(text.as_bytes()))
    }

    /// Read `dir/manifest.json`. Every listed file must lie inside `dir`
    /// ([`inside`]): readers join the paths to `dir`, and a manifest from elsewhere must
    /// not make them read (or verify) files outside it.
    pub fn read(dir: &Path) -> Result<Manifest> {
        let p = dir.join("manifest.json");
        let b = std::fs::read(&p).map_err(|e| Error::io(&p, e))?;
        let m: Manifest = serde_json::from_slice(&b)
            .map_err(|e| Error::parse(&p, format!("invalid manifest: {e}")))?;
        if let Some(f) = m.files.iter().find(|f| !inside(&f.path)) {
            return Err(Error::parse(
                &p,
                format!("file {:?} is not a path inside the folder", f.path),
            ));
        }
        Ok(m)
    }
}

/// `rel` is a non-empty relative path of plain names (no root, no `.` or `..`): joined to a
/// folder, it stays inside it.
pub fn inside(rel: &str) -> bool {
    !rel.is_empty()
        && Path::new(rel)
            .components()
            .all(|c| matches!(c, std::path::Component::Normal(_)))
}

/// sha256 of a value's compact JSON.
pub fn inputs_sha256(inputs: &serde_json::Value) -> String {
    sha256_hex(
        serde_json::to_string(inputs)
            .expect("inputs serialize")
            .as_bytes(),
    )
}
