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

/// GMSD's constant for images in [0, 1]: `T = 170 / 255²` (Xue, Zhang, Mou, Bovik,
/// "Gradient Magnitude Similarity Deviation", IEEE TIP 23(2), 2014; piq's default).
pub const GMSD_CONSTANT: f64 = 170.0 / (255.0 * 255.0);

/// GMSD's maps of a render against its truth, at its half resolution: the luma
/// (`0.299 R + 0.587 G + 0.114 B`, of values clamped to [0, 1]) padded with a zero row and
/// column where a side is odd and averaged over 2 × 2 blocks; Prewitt gradients (`[−1 0 1]`
/// over three rows, ÷ 3, zero padding); per block the gradient magnitude similarity
/// `(2·m_r·m_t + T) / (m_r² + m_t² + T)`; and both squared magnitudes with the edge
/// blocks repeated past the image instead of zeros (the gradient energies a detail ratio
/// divides: zero padding would add the same artificial edge to both). GMSD is the
/// population standard deviation of the similarity over the blocks. All in f64, in block order: the same bits on any thread
/// count.
#[derive(Clone, Debug, PartialEq)]
pub struct GradientBlocks {
    pub width: usize,
    pub height: usize,
    pub similarity: Vec<f64>,
    pub render_energy: Vec<f64>,
    pub truth_energy: Vec<f64>,
}

impl GradientBlocks {
    /// The maps of `render` against `truth` (both `w × h` RGB, row-major).
    pub fn new(render: &[f32], truth: &[f32], w: usize, h: usize) -> GradientBlocks {
        let (bw, bh) = (w.div_ceil(2), h.div_ceil(2));
        let blocks = |img: &[f32]| {
            let luma = |x: usize, y: usize| {
                if x >= w || y >= h {
                    return 0.0;
                }
                let p = &img[(y * w + x) * 3..(y * w + x) * 3 + 3];
                let c = |v: f32| v.clamp(0.0, 1.0) as f64;
                0.299 * c(p[0]) + 0.587 * c(p[1]) + 0.114 * c(p[2])
            };
            let mut out = vec![0f64; bw * bh];
            for by in 0..bh {
                for bx in 0..bw {
                    let (x, y) = (2 * bx, 2 * by);
                    out[by * bw + bx] =
                        (luma(x, y) + luma(x + 1, y) + luma(x, y + 1) + luma(x + 1, y + 1)) / 4.0;
                }
            }
            out
        };
        // `edges`: the stencil reads the nearest block past the image's edge (else zero).
        let energy = |b: &[f64], edges: bool| {
            let at = |x: isize, y: isize| {
                let inside = x >= 0 && y >= 0 && x < bw as isize && y < bh as isize;
                if inside || edges {
                    let (x, y) = (x.clamp(0, bw as isize - 1), y.clamp(0, bh as isize - 1));
                    b[y as usize * bw + x as usize]
                } else {
                    0.0
                }
            };
            let mut out = vec![0f64; bw * bh];
            for y in 0..bh as isize {
                for x in 0..bw as isize {
                    let (mut gx, mut gy) = (0.0, 0.0);
                    for k in -1..=1 {
                        gx += at(x + 1, y + k) - at(x - 1, y + k);
                        gy += at(x + k, y + 1) - at(x + k, y - 1);
                    }
                    let (gx, gy) = (gx / 3.0, gy / 3.0);
                    out[y as usize * bw + x as usize] = gx * gx + gy * gy;
                }
            }
            out
        };
        let (rb, tb) = (blocks(render), blocks(truth));
        let (gr, gt) = (energy(&rb, false), energy(&tb, false));
        let similarity = gr
            .iter()
            .zip(&gt)
            // m_r·m_t as √(m_r²·m_t²): exactly m² for an image against itself.
            .map(|(&er, &et)| (2.0 * (er * et).sqrt() + GMSD_CONSTANT) / (er + et + GMSD_CONSTANT))
            .collect();
        GradientBlocks {
            width: bw,
            height: bh,
            similarity,
            render_energy: energy(&rb, true),
            truth_energy: energy(&tb, true),
        }
    }

    /// The block of pixel `(x, y)` and the weight a pixel of it carries: one over the
    /// block's pixels inside the image, so that a class holding every pixel weighs every
    /// block 1 (GMSD over the whole image).
    pub fn block_of(&self, x: usize, y: usize, w: usize, h: usize) -> (usize, f64) {
        let inside = (2 - (2 * (x / 2) + 1 >= w) as usize) * (2 - (2 * (y / 2) + 1 >= h) as usize);
        ((y / 2) * self.width + x / 2, 1.0 / inside as f64)
    }
}
