//! `unseen compare RUN_A RUN_B` (SPEC.md §20.9): every step manifest of run A against run
//! B's, file by file — identical (same sha256), else for float artifacts (EXR, PNG, PLY)
//! the largest absolute difference, the largest distance in units in the last place and
//! the PSNR of B against A — in pipeline order, naming the first step that diverges. This
//! is what a GPU port runs against our run directory.

use crate::error::{Error, Result};
use crate::gaussian::Param;
use crate::gaussian::ply::read_ply;
use crate::io::image::{read_exr, read_png};
use crate::io::manifest::Manifest;
use std::path::{Path, PathBuf};

/// One file's comparison.
#[derive(Clone, Debug, PartialEq, serde::Serialize)]
pub struct FileDiff {
    pub path: String,
    pub identical: bool,
    /// `None` when not comparable as floats (or identical).
    pub max_abs: Option<f64>,
    pub max_ulp: Option<u64>,
    pub psnr: Option<f64>,
    /// Why the file could not be compared numerically (missing, shape, kind).
    pub note: Option<String>,
}

/// One step's comparison.
#[derive(Clone, Debug, PartialEq, serde::Serialize)]
pub struct StepDiff {
    pub step: String,
    pub identical: bool,
    pub files: Vec<FileDiff>,
}

/// The whole comparison.
#[derive(Clone, Debug, PartialEq, serde::Serialize)]
pub struct Comparison {
    pub steps: Vec<StepDiff>,
    /// The first step (pipeline order) with a file beyond the tolerance.
    pub first_divergent: Option<String>,
}

impl Comparison {
    /// A Markdown table, one row per step.
    pub fn table(&self) -> String {
        let mut s = String::from(
            "| step | files | identical | max abs | max ULP | min PSNR (dB) |\n|---|---|---|---|---|---|\n",
        );
        for st in &self.steps {
            let same = st.files.iter().filter(|f| f.identical).count();
            let max_abs = st
                .files
                .iter()
                .filter_map(|f| f.max_abs)
                .fold(0.0, f64::max);
            let max_ulp = st.files.iter().filter_map(|f| f.max_ulp).max().unwrap_or(0);
            let psnr = st
                .files
                .iter()
                .filter_map(|f| f.psnr)
                .fold(f64::INFINITY, f64::min);
            s += &format!(
                "| {} | {} | {} | {:.3e} | {} | {} |\n",
                st.step,
                st.files.len(),
                same,
                max_abs,
                max_ulp,
                if psnr.is_finite() {
                    format!("{psnr:.2}")
                } else {
                    "∞".into()
                }
            );
        }
        s
    }
}

/// Rank of a step folder in pipeline order (`Step::order`; a folder that is no step, e.g.
/// an oracle dump's, after every step, by name).
fn rank(step: &str) -> (u32, usize, String) {
    step.parse::<super::steps::Step>()
        .map_or((u32::MAX, 0, step.to_string()), |s| s.order())
}

/// Every `manifest.json` under `root` (relative step names), in pipeline order.
fn manifests(root: &Path) -> Result<Vec<(String, Manifest)>> {
    let mut out = Vec::new();
    let mut stack = vec![root.to_path_buf()];
    while let Some(d) = stack.pop() {
        let entries = std::fs::read_dir(&d).map_err(|e| Error::io(&d, e))?;
        for e in entries.flatten() {
            let p = e.path();
            let hidden = e.file_name().to_string_lossy().starts_with('.');
            if p.is_dir() && !hidden {
                // (Hidden folders are temporaries: a killed copy, a cache entry set aside.)
                stack.push(p);
            } else if p.file_name().is_some_and(|n| n == "manifest.json") && d != root {
                // A manifest that does not parse is damage, not something to skip. The
                // step is named by its folder (a pipeline step's manifest says the same; one
                // written by another command, e.g. `unseen oracle`, says "").
                let m = Manifest::read(&d)?;
                let rel: Vec<String> = d
                    .strip_prefix(root)
                    .unwrap_or(&d)
                    .components()
                    .map(|c| c.as_os_str().to_string_lossy().into_owned())
                    .collect();
                out.push((rel.join("/"), m));
            }
        }
    }
    out.sort_by_key(|(s, _)| rank(s));
    Ok(out)
}

/// Float values of an artifact (all channels / parameters in a fixed order).
fn floats(path: &Path) -> Result<Vec<f32>> {
    let ext = path.extension().and_then(|e| e.to_str()).unwrap_or("");
    match ext {
        "exr" => read_exr(path, &["R", "G", "B"])
            .or_else(|_| read_exr(path, &["Y"]))
            .map(|i| i.data),
        "png" => read_png(path).map(|i| i.data),
        // f32 arrays (`unseen oracle` dumps); other dtypes are compared as bytes only.
        "npy" => crate::io::npy::read_npy_f32(path).map(|(_, v)| v),
        "ply" => {
            let (g, _) = read_ply(path)?;
            let mut v = Vec::new();
            for p in Param::ALL {
                v.extend_from_slice(g.param(p));
            }
            Ok(v)
        }
        _ => Err(Error::unsupported(path, "not a float artifact")),
    }
}

/// Distance in units in the last place between two finite f32 (sign-aware).
pub fn ulp_distance(a: f32, b: f32) -> u64 {
    let key = |x: f32| {
        let i = x.to_bits() as i32;
        if i < 0 {
            i64::from(i32::MIN) - i64::from(i)
        } else {
            i64::from(i)
        }
    };
    (key(a) - key(b)).unsigned_abs()
}

fn diff_file(a: &Path, b: &Path, rel: &str) -> FileDiff {
    let mut d = FileDiff {
        path: rel.into(),
        identical: false,
        max_abs: None,
        max_ulp: None,
        psnr: None,
        note: None,
    };
    if !b.is_file() {
        d.note = Some("missing in B".into());
        return d;
    }
    match (floats(a), floats(b)) {
        (Ok(x), Ok(y)) if x.len() == y.len() => {
            let (mut ma, mut mu, mut se) = (0f64, 0u64, 0f64);
            for (&p, &q) in x.iter().zip(&y) {
                if p.is_nan() || q.is_nan() {
                    if p.is_nan() != q.is_nan() {
                        ma = f64::INFINITY;
                    }
                    continue;
                }
                let e = (p as f64 - q as f64).abs();
                ma = ma.max(e);
                mu = mu.max(ulp_distance(p, q));
                se += e * e;
            }
            d.max_abs = Some(ma);
            d.max_ulp = Some(mu);
            let mse = se / x.len().max(1) as f64;
            d.psnr = Some(if mse > 0.0 {
                -10.0 * mse.log10()
            } else {
                f64::INFINITY
            });
        }
        (Ok(x), Ok(y)) => d.note = Some(format!("{} values in A, {} in B", x.len(), y.len())),
        _ => d.note = Some("contents differ".into()),
    }
    d
}

/// Compare two run directories; a file counts as divergent when it is not identical and
/// its largest absolute difference exceeds `tolerance` (or it cannot be compared).
pub fn compare(a: &Path, b: &Path, tolerance: f64) -> Result<Comparison> {
    if !(tolerance.is_finite() && tolerance >= 0.0) {
        return Err(Error::invalid(format!(
            "the tolerance {tolerance} must be finite and ≥ 0"
        )));
    }
    for r in [a, b] {
        if !r.is_dir() {
            return Err(Error::invalid("not a run directory").at(r));
        }
    }
    // The steps of A's run (`steps.json`, in run order); a folder without it (an
    // interrupted run) is walked for every manifest.
    let listed: Option<Vec<String>> = std::fs::read(a.join("steps.json"))
        .ok()
        .and_then(|b| serde_json::from_slice(&b).ok());
    if let Some(n) = listed
        .iter()
        .flatten()
        .find(|n| !crate::io::manifest::inside(n))
    {
        return Err(Error::parse(
            &a.join("steps.json"),
            format!("step {n:?} is not a folder inside the run"),
        ));
    }
    let ma = match listed {
        Some(names) => names
            .iter()
            .map(|n| Ok((n.clone(), Manifest::read(&a.join(n))?)))
            .collect::<Result<Vec<_>>>()?,
        None => manifests(a)?,
    };
    if ma.is_empty() {
        let hint = if a.join("manifest.json").is_file() {
            " (a single step's folder: pass the folder that holds it)"
        } else {
            " (is this an `unseen extrapolate` run?)"
        };
        return Err(Error::invalid(format!("no step manifests{hint}")).at(a));
    }
    let mut steps = Vec::new();
    let mut first = None;
    for (step, m) in &ma {
        let dir_a: PathBuf = a.join(step);
        let dir_b: PathBuf = b.join(step);
        let mb: Option<Manifest> = std::fs::read(dir_b.join("manifest.json"))
            .ok()
            .and_then(|x| serde_json::from_slice(&x).ok());
        let mut files = Vec::new();
        for f in &m.files {
            // The files themselves, not the manifests' word for them.
            let same = match (
                std::fs::read(dir_a.join(&f.path)),
                std::fs::read(dir_b.join(&f.path)),
            ) {
                (Ok(x), Ok(y)) => x == y,
                _ => false,
            };
            files.push(if same {
                FileDiff {
                    path: f.path.clone(),
                    identical: true,
                    max_abs: Some(0.0),
                    max_ulp: Some(0),
                    psnr: None,
                    note: None,
                }
            } else if mb.is_none() {
                FileDiff {
                    path: f.path.clone(),
                    identical: false,
                    max_abs: None,
                    max_ulp: None,
                    psnr: None,
                    note: Some("step missing in B".into()),
                }
            } else {
                diff_file(&dir_a.join(&f.path), &dir_b.join(&f.path), &f.path)
            });
        }
        let identical = files.iter().all(|f| f.identical);
        let divergent = files
            .iter()
            .any(|f| !f.identical && f.max_abs.is_none_or(|x| x.is_nan() || x > tolerance));
        if divergent && first.is_none() {
            first = Some(step.clone());
        }
        steps.push(StepDiff {
            step: step.clone(),
            identical,
            files,
        });
    }
    Ok(Comparison {
        steps,
        first_divergent: first,
    })
}
