//! Candidate families of a dataset (SPEC.md §20.7): other candidate poses than its bundled
//! `candidates.json`, each `families/<name>.json`, which `unseen audit --candidates` gives
//! the pipeline and a pool's provenance records.

use crate::error::{Error, Result};
use std::path::{Path, PathBuf};

/// A candidate family of a dataset (SPEC.md §20.7): `families/<name>.json`, an INRIA
/// cameras.json of candidate poses whose images and depths lie in the dataset's folders.
#[derive(Clone, Debug, PartialEq, Eq, serde::Serialize, serde::Deserialize)]
pub struct Family {
    pub name: String,
    /// SHA-256 of the family's file (the dataset digest covers only top-level files).
    pub sha256: String,
}

impl Family {
    /// The first 12 characters of the digest, for messages and reports.
    pub fn short(&self) -> String {
        self.sha256.chars().take(12).collect()
    }

    /// A record read from a file: a family name and a SHA-256 of 64 hex digits.
    pub fn check(&self) -> Result<()> {
        check_family_name(&self.name)?;
        if self.sha256.len() != 64 || !self.sha256.chars().all(|c| c.is_ascii_hexdigit()) {
            return Err(Error::invalid(format!(
                "candidate family '{}': its SHA-256 is not 64 hex digits",
                self.name
            )));
        }
        Ok(())
    }
}

/// The folder of a dataset that holds its candidate families.
pub const FAMILIES_DIR: &str = "families";

/// A family name is a file stem of lower-case letters, digits and '-' (`meta` is the
/// generator's record, not a family).
pub fn check_family_name(name: &str) -> Result<()> {
    let ok = !name.is_empty()
        && name != "meta"
        && name
            .chars()
            .all(|c| c.is_ascii_lowercase() || c.is_ascii_digit() || c == '-');
    if ok {
        Ok(())
    } else {
        Err(Error::invalid(format!(
            "'{name}' is not a candidate family name (lower-case letters, digits and '-'; not 'meta')"
        )))
    }
}

/// The candidate poses an audit gives the pipeline (SPEC.md §20.7), resolved once from the
/// configuration's choice against the dataset ([`Candidates::resolve`]): the family's record
/// (`None` for the bundled `candidates.json`), which jobs and pools record, and the file of
/// poses.
#[derive(Clone, Debug, PartialEq)]
pub struct Candidates {
    pub family: Option<Family>,
    pub file: PathBuf,
}

impl Candidates {
    /// The candidates named `family` (`None`: the bundled ones) in `dataset`: an error naming
    /// the families there when it has none of that name.
    pub fn resolve(dataset: &Path, family: Option<&str>) -> Result<Candidates> {
        Ok(Candidates {
            family: record(dataset, family)?,
            file: candidates_file(dataset, family),
        })
    }
}

/// The candidate poses of `family` in `dataset`: `candidates.json` for `None`, else
/// `families/<name>.json`.
fn candidates_file(dataset: &Path, family: Option<&str>) -> PathBuf {
    match family {
        None => dataset.join("candidates.json"),
        Some(f) => dataset.join(FAMILIES_DIR).join(format!("{f}.json")),
    }
}

/// The families a dataset offers (`families/*.json` but `meta.json`), by name.
pub fn families(dataset: &Path) -> Vec<String> {
    let mut names: Vec<String> = std::fs::read_dir(dataset.join(FAMILIES_DIR))
        .into_iter()
        .flatten()
        .filter_map(|e| e.ok())
        .filter_map(|e| e.file_name().into_string().ok())
        .filter_map(|n| n.strip_suffix(".json").map(str::to_string))
        .filter(|n| check_family_name(n).is_ok())
        .collect();
    names.sort();
    names
}

/// The [`Family`] record of `family` in `dataset` (`None` for the bundled candidates): an
/// error naming the families there when it has none of that name.
fn record(dataset: &Path, family: Option<&str>) -> Result<Option<Family>> {
    let Some(name) = family else {
        return Ok(None);
    };
    check_family_name(name)?;
    let p = candidates_file(dataset, Some(name));
    if !p.is_file() {
        let have = families(dataset);
        return Err(Error::invalid(format!(
            "no candidate family '{name}' ({}/{name}.json); this dataset has {}",
            FAMILIES_DIR,
            if have.is_empty() {
                "none".to_string()
            } else {
                have.join(", ")
            }
        ))
        .at(dataset));
    }
    let b = std::fs::read(&p).map_err(|e| Error::io(&p, e))?;
    Ok(Some(Family {
        name: name.to_string(),
        sha256: crate::io::sha256_hex(&b),
    }))
}
