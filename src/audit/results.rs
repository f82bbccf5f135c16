//! The results table of committed audits (SPEC.md §21.7): per room, generator and variant
//! of a primary claim, the primary claim, its within-pair null and the panel's rows that
//! answer the averaging question — PSNR over all pixels (the paper's metric), PSNR, SSIM
//! and GMSD on contested pixels, multi-view consistency there, generation fidelity — each with n, median Δ, its interval
//! and verdict, read from each audit's `audit.json`; at a glance ([`Style::Glance`]) only
//! the primary, its null, the paper's metric and SSIM on contested pixels, one line each.
//! README.md and the audit page show them as generated (`unseen audit-table`), and a test
//! checks the pages and the tool agree.

use crate::error::{Error, Result};
use serde_json::Value;
use std::path::PathBuf;

/// The metrics a row group shows after the primary claim and its null, in this order, by
/// their `audit.json` names: the paper's claim of the same variant, then the panel.
const SHOWN: [&str; 6] = [
    "psnr_all",
    "psnr_contested",
    "ssim_contested",
    "gmsd_contested",
    "consistency_contested",
    "psnr_fidelity",
];

/// What [`Style::Glance`] shows after the primary and its null: the paper's metric and the
/// perceptual one that registers the averaging of conflicting generations.
const GLANCE: [&str; 2] = ["psnr_all", "ssim_contested"];

/// How much of each row group a table shows.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum Style {
    /// The primary, its null and every metric of the panel, the verdict in full.
    Full,
    /// The primary, its null, PSNR over all pixels and SSIM on contested pixels; the claim
    /// named on the primary's row, the room with its training resolution, seeds as judged
    /// of run, the verdict's word alone (README's "Results at a glance").
    Glance,
}

/// One audit of a table: its folder and, when given, the one generator (dose level) shown.
#[derive(Clone, Debug, PartialEq)]
pub struct Source {
    pub folder: PathBuf,
    pub generator: Option<String>,
}

impl Source {
    /// `FOLDER` or `FOLDER:GENERATOR` (e.g. `reference_data/audit/gallery-control:dose-ghosting-100`).
    pub fn parse(arg: &str) -> Source {
        match arg.rsplit_once(':') {
            Some((folder, generator)) if !generator.contains('/') => Source {
                folder: folder.into(),
                generator: Some(generator.to_string()),
            },
            _ => Source {
                folder: arg.into(),
                generator: None,
            },
        }
    }
}

/// The table (markdown, with its header) of the audits of `sources` (each folder holding an
/// `audit.json`), in the order given.
pub fn table(sources: &[Source], style: Style) -> Result<String> {
    let mut s = String::from(match style {
        Style::Full => {
            "| room | generator | variant | metric | n | median Δ [95 % CI] | verdict |\n|---|---|---|---|---|---|---|\n"
        }
        Style::Glance => {
            "| claim | room | generator | metric | seeds | median Δ [95 % CI] | verdict |\n|---|---|---|---|---|---|---|\n"
        }
    });
    for source in sources {
        let path = source.folder.join("audit.json");
        let bytes = std::fs::read(&path).map_err(|e| Error::io(&path, e))?;
        let audit: Value = serde_json::from_slice(&bytes)
            .map_err(|e| Error::parse(&path, format!("invalid JSON: {e}")))?;
        let field = |v: &Value, key: &str| -> Result<String> {
            v.get(key)
                .and_then(Value::as_str)
                .map(str::to_string)
                .ok_or_else(|| Error::parse(&path, format!("no string '{key}'")))
        };
        let room = match audit.get("candidates").and_then(|c| c.get("name")) {
            Some(Value::String(f)) => format!("{} ({f})", field(&audit, "dataset")?),
            _ => field(&audit, "dataset")?,
        };
        // At a glance the room names the resolution its scenes were trained at.
        let room = match (style, audit.get("train_resolution").and_then(Value::as_u64)) {
            (Style::Glance, Some(r)) => format!("{room}, resolution 1/{r}"),
            _ => room,
        };
        let verdicts = audit
            .get("verdicts")
            .and_then(Value::as_array)
            .ok_or_else(|| Error::parse(&path, "no 'verdicts' list"))?;
        for primary in verdicts.iter().filter(|v| {
            v.get("family")
                .and_then(Value::as_str)
                .is_some_and(|f| f.ends_with("-classes"))
                && v.get("metric")
                    .and_then(Value::as_str)
                    .is_some_and(|m| m.ends_with("_contested"))
        }) {
            let (generator, variant) = (field(primary, "generator")?, field(primary, "variant")?);
            if source.generator.as_ref().is_some_and(|g| *g != generator) {
                continue;
            }
            let metric = field(primary, "metric")?;
            let null = metric.replace("_contested", "_uncontested");
            let same = |v: &&Value, m: &str| {
                field(v, "generator").ok().as_deref() == Some(generator.as_str())
                    && field(v, "variant").ok().as_deref() == Some(variant.as_str())
                    && field(v, "metric").ok().as_deref() == Some(m)
            };
            let shown: &[&str] = match style {
                Style::Full => &SHOWN,
                Style::Glance => &GLANCE,
            };
            let names = [metric.as_str(), null.as_str()]
                .into_iter()
                .chain(shown.iter().copied());
            for (k, m) in names.enumerate() {
                let Some(v) = verdicts.iter().find(|v| same(v, m)) else {
                    continue;
                };
                let mark = if k == 0 { "**" } else { "" };
                let judged = v.get("judged").and_then(Value::as_u64).unwrap_or(0);
                let verdict = field(v, "verdict")?;
                s += &match style {
                    Style::Full => format!(
                        "| {room} | {generator} | {variant} | {mark}{}{mark} | {judged} | {} | {verdict} |\n",
                        label(m),
                        delta(v, m),
                    ),
                    Style::Glance => {
                        // The claim on its group's first row only.
                        let id = field(v, "id")?;
                        let claim = match id.split_once(", ") {
                            _ if k > 0 => String::new(),
                            Some((c, _)) => format!("{c} ({variant})"),
                            None => format!("{id} ({variant})"),
                        };
                        let seeds = v.get("seeds").and_then(Value::as_u64).unwrap_or(0);
                        let word = verdict.split(';').next().unwrap_or(&verdict);
                        format!(
                            "| {claim} | {room} | {generator} | {mark}{}{mark} | {judged} of {seeds} | {} | {mark}{word}{mark} |\n",
                            label(m),
                            delta(v, m),
                        )
                    }
                };
            }
        }
    }
    Ok(s)
}

/// A metric's label from its `audit.json` name (`detail_contested` → "detail ratio,
/// contested").
fn label(name: &str) -> String {
    if name == "psnr_all" {
        return "PSNR, all pixels (the paper's)".into();
    }
    if name == "psnr_fidelity" {
        return "PSNR against own generations".into();
    }
    let (measure, region) = name.split_once('_').unwrap_or((name, ""));
    let measure = match measure {
        "detail" => "detail ratio",
        "gmsd" => "GMSD",
        "ssim" => "SSIM",
        "psnr" => "PSNR",
        "consistency" => "multi-view consistency",
        m => m,
    };
    format!(
        "{measure}, {}",
        region.replace("diff_in_diff", "contested − uncontested")
    )
}

/// `+0.1234 [+0.1000, +0.2000]` (dB with two decimals for PSNR and multi-view consistency,
/// a PSNR), `–` where absent.
fn delta(v: &Value, metric: &str) -> String {
    let db = metric.starts_with("psnr") || metric.starts_with("consistency");
    let digits = if db { 2 } else { 4 };
    let unit = if db { " dB" } else { "" };
    let Some(m) = v.get("median_diff").and_then(Value::as_f64) else {
        return "–".into();
    };
    let ci = match v
        .get("ci")
        .and_then(Value::as_array)
        .map(|c| c.iter().filter_map(Value::as_f64).collect::<Vec<_>>())
    {
        Some(c) if c.len() == 2 => format!(" [{:+.digits$}, {:+.digits$}]", c[0], c[1]),
        _ => String::new(),
    };
    format!("{m:+.digits$}{unit}{ci}")
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn a_source_names_a_folder_and_perhaps_one_generator() {
        let s = Source::parse("reference_data/audit/gallery-control:dose-ghosting-100");
        assert_eq!(
            s.folder,
            PathBuf::from("reference_data/audit/gallery-control")
        );
        assert_eq!(s.generator.as_deref(), Some("dose-ghosting-100"));
        let s = Source::parse("reference_data/audit/gallery-control");
        assert_eq!(s.generator, None);
        // A colon before the last path separator is part of the path.
        let s = Source::parse("C:/audits/gallery");
        assert_eq!(
            (s.folder, s.generator),
            (PathBuf::from("C:/audits/gallery"), None)
        );
    }
}
