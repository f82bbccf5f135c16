//! Evaluation of a trained scene on a dataset split (SPEC.md §14.7): PSNR and SSIM per view
//! and their means, as INRIA's `metrics.py` computes them — the render is clamped to
//! `[0, 1]`, PSNR from the mean squared error over all values, SSIM with the training
//! window (§13).

use crate::dataset::{Dataset, Split};
use crate::error::Result;
use crate::gaussian::Gaussians;
use crate::io::create_dir_all;
use crate::io::image::{ImageF32, write_png};
use crate::io::json_float::show;
use crate::raster::{Conventions, RenderOptions, render};
use crate::train::loss::psnr;
use crate::train::ssim::ssim;
use std::path::Path;

#[derive(Clone, Debug, PartialEq, serde::Serialize, serde::Deserialize)]
pub struct ViewMetrics {
    pub name: String,
    /// +∞ for a render equal to its truth (`"inf"` in JSON: [`crate::io::json_float`]).
    #[serde(with = "crate::io::json_float")]
    pub psnr: f64,
    pub ssim: f64,
}

#[derive(Clone, Debug, PartialEq, serde::Serialize, serde::Deserialize)]
pub struct EvalReport {
    pub split: Split,
    pub views: Vec<ViewMetrics>,
    #[serde(with = "crate::io::json_float")]
    pub mean_psnr: f64,
    pub mean_ssim: f64,
}

impl EvalReport {
    /// A Markdown table of the per-view figures and the mean.
    pub fn table(&self) -> String {
        let mut s = String::from("| view | PSNR (dB) | SSIM |\n|---|---|---|\n");
        for v in &self.views {
            s += &format!("| {} | {} | {:.4} |\n", v.name, show(v.psnr, 2), v.ssim);
        }
        s += &format!(
            "| **mean** | **{}** | **{:.4}** |\n",
            show(self.mean_psnr, 2),
            self.mean_ssim
        );
        s
    }
}

/// An RGB render (left) beside its ground truth (right), both `w × h`.
pub fn side_by_side(rgb: &[f32], gt: &[f32], w: usize, h: usize) -> Result<ImageF32> {
    let mut both = vec![0f32; 2 * w * h * 3];
    for y in 0..h {
        let row = &mut both[y * 2 * w * 3..(y + 1) * 2 * w * 3];
        row[..w * 3].copy_from_slice(&rgb[y * w * 3..(y + 1) * w * 3]);
        row[w * 3..].copy_from_slice(&gt[y * w * 3..(y + 1) * w * 3]);
    }
    ImageF32::new(2 * w, h, 3, both)
}

/// Render every view of `split` (with the `background` and convention profile the scene
/// was trained with), score it, and when `out` is given write
/// `out/<name>.png` with the render (left) beside the ground truth (right).
pub fn evaluate(
    g: &Gaussians,
    data: &Dataset,
    split: Split,
    background: [f32; 3],
    conventions: Conventions,
    out: Option<&Path>,
) -> Result<EvalReport> {
    if data.split(split).is_empty() {
        return Err(crate::error::Error::invalid(format!(
            "dataset {} has no {split:?} views",
            data.root.display()
        )));
    }
    if let Some(o) = out {
        create_dir_all(o)?;
    }
    let opts = RenderOptions {
        background,
        conventions,
        ..RenderOptions::default()
    };
    let mut views = Vec::new();
    for &i in data.split(split) {
        let v = &data.views[i];
        let r = render(g, &v.camera, &opts)?;
        let rgb: Vec<f32> = r
            .rgb
            .expect("rgb")
            .iter()
            .map(|x| x.clamp(0.0, 1.0))
            .collect();
        let gt = &v.image.data;
        let (w, h) = (v.image.width, v.image.height);
        let p = psnr(&rgb, gt);
        let (s, _) = ssim(&rgb, gt, w, h, 3, false);
        if let Some(o) = out {
            let name = crate::io::file_stem(&v.camera.name);
            write_png(
                &o.join(format!("{name}.png")),
                &side_by_side(&rgb, gt, w, h)?,
            )?;
        }
        views.push(ViewMetrics {
            name: v.camera.name.clone(),
            psnr: p,
            ssim: s,
        });
    }
    let n = views.len().max(1) as f64;
    Ok(EvalReport {
        split,
        mean_psnr: views.iter().map(|v| v.psnr).sum::<f64>() / n,
        mean_ssim: views.iter().map(|v| v.ssim).sum::<f64>() / n,
        views,
    })
}

/// The folder of a training run (`unseen train`'s output) that `unseen eval` writes into;
/// not a pipeline step (a pipeline run's evaluation steps are `pipeline::steps::Step::Eval`).
const TRAIN_RUN_EVAL: &str = "eval";

/// Evaluate a run's saved scene (`iteration`, default the latest) on a split of
/// `dataset` (loaded as the run's config says), writing render | truth images into
/// `RUN/eval/<split>[_iteration_N]/` and merging the report into `RUN/eval.json` under
/// that name.
pub fn evaluate_run(
    run: &Path,
    dataset: &Path,
    split: Split,
    iteration: Option<u32>,
) -> Result<EvalReport> {
    use crate::train::run::{load_dataset, read_config, read_run_scene};
    let cfg = read_config(run)?;
    let data = load_dataset(dataset, &cfg)?;
    let (it, g) = read_run_scene(run, iteration)?;
    let split_name = match split {
        Split::Train => "train",
        Split::Test => "test",
        Split::Heldout => "heldout",
    };
    let name = match iteration {
        Some(_) => format!("{split_name}_iteration_{it}"),
        None => split_name.to_string(),
    };
    let report = evaluate(
        &g,
        &data,
        split,
        cfg.background,
        cfg.conventions,
        Some(&run.join(TRAIN_RUN_EVAL).join(&name)),
    )?;
    let path = run.join("eval.json");
    let mut all: serde_json::Map<String, serde_json::Value> = std::fs::read(&path)
        .ok()
        .and_then(|b| serde_json::from_slice(&b).ok())
        .unwrap_or_default();
    all.insert(name, serde_json::to_value(&report).expect("serializes"));
    let text = serde_json::to_string_pretty(&all).expect("serializes");
    crate::io::write_text(&path, &text)?;
    Ok(report)
}
