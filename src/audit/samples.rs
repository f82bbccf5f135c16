//! The audit's samples (SPEC.md §21.3): every job result of every batch of seeds, pooled,
//! so that seeds accumulate instead of each audit being regenerated whole.
//!
//! `DIR/samples.json.gz` holds, gzip-compressed, a header naming what the samples measure
//! (dataset, preset, original-scene training) and one sample per line (a [`JobResult`]
//! without its step list and without the original scene's per-view sums, which its seed's
//! jobs share). A run of the audit adds its batch's results to the samples already in the
//! folder and to those of `--merge` files; samples from another dataset, preset or training
//! are refused with the field that differs. A folder written before the samples were
//! compressed holds `DIR/samples.json` (the same text, uncompressed): it is read as well,
//! and replaced by the compressed file when the audit writes its samples.

use super::JobResult;
use crate::error::{Error, Result};
use crate::pipeline::Preset;
use std::path::Path;

/// The file of an audit folder that holds its samples (gzip; the JSON text compresses
/// 5–7×, which keeps the committed audits within the reference data's budget).
pub const SAMPLES_FILE: &str = "samples.json.gz";

/// The uncompressed samples file of a folder written before [`SAMPLES_FILE`]: read, never
/// written; removed once its samples are in [`SAMPLES_FILE`].
pub const LEGACY_SAMPLES_FILE: &str = "samples.json";

/// The first two bytes of every gzip member (RFC 1952 §2.3.1).
const GZIP_MAGIC: [u8; 2] = [0x1f, 0x8b];

/// The samples files in `dir`, the compressed one first: what an audit of `dir` pools.
pub fn files_in(dir: &Path) -> Vec<std::path::PathBuf> {
    [SAMPLES_FILE, LEGACY_SAMPLES_FILE]
        .iter()
        .map(|f| dir.join(f))
        .filter(|p| p.is_file())
        .collect()
}

/// The format tag of [`SAMPLES_FILE`].
pub const FORMAT: &str = "unseen-audit-samples/1";

/// What every sample of one pool measures.
#[derive(Clone, Debug, PartialEq, serde::Serialize, serde::Deserialize)]
pub struct Provenance {
    /// The dataset folder's name.
    pub dataset: String,
    /// [`dataset_digest`] of the dataset; empty when imported from a report written before
    /// it was recorded (then only the name is compared).
    pub dataset_digest: String,
    pub preset: Preset,
    /// Training of the original scene.
    pub train_iterations: u32,
    pub train_resolution: u32,
    /// The candidate family the pipeline ran with; `None` (not written): the dataset's
    /// bundled `candidates.json`, which [`dataset_digest`] covers.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub candidates: Option<super::family::Family>,
}

/// SHA-256 over the names and bytes of the dataset's top-level JSON files (cameras, split,
/// candidate and evaluation poses, the generator's `meta.json`), in name order: the same
/// dataset on any machine, wherever it lies.
pub fn dataset_digest(dataset: &Path) -> Result<String> {
    let mut names: Vec<String> = std::fs::read_dir(dataset)
        .map_err(|e| Error::io(dataset, e))?
        .filter_map(|e| e.ok())
        .filter(|e| e.path().is_file())
        .filter_map(|e| e.file_name().into_string().ok())
        .filter(|n| n.ends_with(".json"))
        .collect();
    names.sort();
    let mut bytes = Vec::new();
    for n in &names {
        let p = dataset.join(n);
        bytes.extend_from_slice(n.as_bytes());
        bytes.push(0);
        let b = std::fs::read(&p).map_err(|e| Error::io(&p, e))?;
        bytes.extend_from_slice(&(b.len() as u64).to_le_bytes());
        bytes.extend_from_slice(&b);
    }
    Ok(crate::io::sha256_hex(&bytes))
}

/// The dataset's folder name (what a pool compares when a digest is missing).
pub fn dataset_name(dataset: &Path) -> String {
    let p = dataset
        .canonicalize()
        .unwrap_or_else(|_| dataset.to_path_buf());
    p.file_name()
        .map_or_else(|| p.display().to_string(), |n| n.to_string_lossy().into())
}

/// A pool of samples.
#[derive(Clone, Debug, PartialEq)]
pub struct Samples {
    pub provenance: Provenance,
    /// One per (generator, variant, seed, numerics revision), in insertion order.
    pub samples: Vec<JobResult>,
}

#[derive(serde::Deserialize)]
struct File {
    format: String,
    #[serde(flatten)]
    provenance: Provenance,
    samples: Vec<JobResult>,
}

/// An `audit.json` written before samples were kept apart: its results, at its revision.
#[derive(serde::Deserialize)]
struct LegacyReport {
    numerics_revision: u32,
    crate_version: String,
    dataset: String,
    preset: Preset,
    train_iterations: u32,
    train_resolution: u32,
    results: Vec<JobResult>,
}

impl Samples {
    pub fn new(provenance: Provenance) -> Samples {
        Samples {
            provenance,
            samples: Vec::new(),
        }
    }

    /// Read a samples file, gzip-compressed ([`SAMPLES_FILE`]) or not (told by its first
    /// bytes, whatever its name), or an `audit.json` of an earlier version (its results as
    /// samples of its numerics revision).
    pub fn read(path: &Path) -> Result<Samples> {
        let mut bytes = std::fs::read(path).map_err(|e| Error::io(path, e))?;
        if bytes.starts_with(&GZIP_MAGIC) {
            let mut text = Vec::new();
            std::io::Read::read_to_end(&mut flate2::read::GzDecoder::new(&bytes[..]), &mut text)
                .map_err(|e| Error::invalid(format!("damaged gzip: {e}")).at(path))?;
            bytes = text;
        }
        let v: serde_json::Value = serde_json::from_slice(&bytes)
            .map_err(|e| Error::invalid(format!("not JSON: {e}")).at(path))?;
        let bad = |e: serde_json::Error| {
            Error::invalid(format!("not audit samples or an audit report: {e}")).at(path)
        };
        if v.get("format").is_some() {
            let f: File = serde_json::from_value(v).map_err(bad)?;
            if f.format != FORMAT {
                return Err(Error::invalid(format!(
                    "samples of format '{}' (this binary reads '{FORMAT}')",
                    f.format
                ))
                .at(path));
            }
            let s = Samples {
                provenance: f.provenance,
                samples: f.samples,
            };
            s.check(path)?;
            return Ok(s);
        }
        let r: LegacyReport = serde_json::from_value(v).map_err(bad)?;
        let mut s = Samples::new(Provenance {
            dataset: dataset_name(Path::new(&r.dataset)),
            dataset_digest: String::new(),
            preset: r.preset,
            train_iterations: r.train_iterations,
            train_resolution: r.train_resolution,
            candidates: None,
        });
        for mut j in r.results {
            if j.numerics_revision == 0 {
                j.numerics_revision = r.numerics_revision;
                j.crate_version = r.crate_version.clone();
            }
            s.insert(j);
        }
        s.check(path)?;
        Ok(s)
    }

    /// Every sample names its revision; no two share (generator, variant, seed, revision).
    fn check(&self, path: &Path) -> Result<()> {
        if let Some(f) = &self.provenance.candidates {
            f.check().map_err(|e| e.at(path))?;
        }
        for (i, a) in self.samples.iter().enumerate() {
            if a.numerics_revision == 0 {
                return Err(Error::invalid(format!(
                    "sample {} ({}) has no numerics revision",
                    i + 1,
                    key_name(a)
                ))
                .at(path));
            }
            if self.samples[..i].iter().any(|b| same_key(a, b)) {
                return Err(Error::invalid(format!(
                    "sample {} ({}) is listed twice",
                    i + 1,
                    key_name(a)
                ))
                .at(path));
            }
        }
        Ok(())
    }

    /// Add one sample, replacing one of the same generator, variant, seed and revision
    /// (the same computation; the newer copy wins). The step list and the original scene's
    /// per-view sums are dropped.
    pub fn insert(&mut self, mut j: JobResult) {
        j.steps.clear();
        j.original.views.clear();
        match self.samples.iter().position(|s| same_key(s, &j)) {
            Some(i) => self.samples[i] = j,
            None => self.samples.push(j),
        }
    }

    /// Pool `other` (read from `from`) into this one: refused, naming the field, when it
    /// measures another dataset, preset or original-scene training.
    pub fn pool(&mut self, other: Samples, from: &Path) -> Result<()> {
        let (a, b) = (&self.provenance, &other.provenance);
        let differs = if a.dataset != b.dataset {
            Some(format!("dataset '{}', not '{}'", b.dataset, a.dataset))
        } else if !a.dataset_digest.is_empty()
            && !b.dataset_digest.is_empty()
            && a.dataset_digest != b.dataset_digest
        {
            let short = |d: &str| d.chars().take(12).collect::<String>();
            Some(format!(
                "dataset '{}' with other content (digest {}…, not {}…)",
                b.dataset,
                short(&b.dataset_digest),
                short(&a.dataset_digest)
            ))
        } else if a.candidates != b.candidates {
            let name = |f: &Option<super::family::Family>| {
                f.as_ref()
                    .map_or("the bundled candidates".to_string(), |f| {
                        format!("candidate family '{}' ({}…)", f.name, f.short())
                    })
            };
            Some(format!(
                "{}, not {}",
                name(&b.candidates),
                name(&a.candidates)
            ))
        } else if a.preset != b.preset {
            Some(format!("preset '{}', not '{}'", b.preset, a.preset))
        } else if (a.train_iterations, a.train_resolution)
            != (b.train_iterations, b.train_resolution)
        {
            Some(format!(
                "original scenes trained {} iterations at 1/{}, not {} at 1/{}",
                b.train_iterations, b.train_resolution, a.train_iterations, a.train_resolution
            ))
        } else {
            None
        };
        if let Some(d) = differs {
            return Err(Error::invalid(format!("cannot pool samples of {d}")).at(from));
        }
        if self.provenance.dataset_digest.is_empty() {
            self.provenance.dataset_digest = other.provenance.dataset_digest.clone();
        }
        for j in other.samples {
            self.insert(j);
        }
        Ok(())
    }

    /// Write `path` atomically, gzip-compressed (level 9, no name, time 0: the same
    /// samples give the same bytes): the header, then one sample per line.
    pub fn write(&self, path: &Path) -> Result<()> {
        let head = serde_json::to_value(&self.provenance).expect("serializes");
        let mut s = format!("{{\"format\": \"{FORMAT}\",\n");
        for (k, v) in head.as_object().expect("a struct") {
            s += &format!(" {}: {v},\n", serde_json::Value::from(k.as_str()));
        }
        s += " \"samples\": [\n";
        for (i, j) in self.samples.iter().enumerate() {
            s += "  ";
            s += &serde_json::to_string(j).expect("serializes");
            s += if i + 1 < self.samples.len() {
                ",\n"
            } else {
                "\n"
            };
        }
        s += " ]\n}\n";
        crate::io::write_atomic(path, |w| {
            let mut gz = flate2::GzBuilder::new()
                .mtime(0)
                .write(w, flate2::Compression::best());
            std::io::Write::write_all(&mut gz, s.as_bytes())?;
            gz.finish().map(|_| ())
        })
    }

    /// The distinct seeds and numerics revisions of the pool, ascending.
    pub fn seeds_and_revisions(&self) -> (Vec<u32>, Vec<u32>) {
        let mut seeds: Vec<u32> = self.samples.iter().map(|s| s.seed).collect();
        let mut revs: Vec<u32> = self.samples.iter().map(|s| s.numerics_revision).collect();
        for v in [&mut seeds, &mut revs] {
            v.sort_unstable();
            v.dedup();
        }
        (seeds, revs)
    }
}

fn same_key(a: &JobResult, b: &JobResult) -> bool {
    (&a.generator, &a.variant, a.seed, a.numerics_revision)
        == (&b.generator, &b.variant, b.seed, b.numerics_revision)
}

fn key_name(j: &JobResult) -> String {
    format!(
        "{}/{}/seed-{} at revision {}",
        j.generator, j.variant, j.seed, j.numerics_revision
    )
}
