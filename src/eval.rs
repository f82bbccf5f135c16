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

/// Multi-view consistency (SPEC.md §21.7): a render and its alpha and expected depth at one
/// camera, as [`consistency_errors`] warps one into another.
#[derive(Clone, Copy, Debug)]
pub struct DepthRender<'a> {
    pub camera: &'a crate::camera::Camera,
    /// RGB, row-major, clamped to [0, 1].
    pub rgb: &'a [f32],
    pub alpha: &'a [f32],
    /// Expected depth (camera z).
    pub depth: &'a [f32],
}

/// Pixels whose accumulated opacity is below this show mostly background: their depth is
/// not a surface's, so they neither warp nor receive (SPEC.md §21.7).
pub const CONSISTENCY_MIN_ALPHA: f32 = 0.5;

/// A warped point and the receiving render see one surface when their depths agree within
/// this share: twice the warp's own same-surface band (1 %), since each expected depth
/// carries its own blend of splats along its ray (SPEC.md §21.7).
pub const CONSISTENCY_DEPTH_TOL: f32 = 0.02;

/// Per pixel of `to`, the squared colour difference (summed over RGB) between `from`'s
/// render warped there with its expected depth (the DIBR warp, nearest footprint, SPEC.md
/// §18) and `to`'s own render, where both see one surface: the warp landed a point whose
/// depth is within [`CONSISTENCY_DEPTH_TOL`] of `to`'s expected depth and both pixels are
/// opaque ([`CONSISTENCY_MIN_ALPHA`]); NaN elsewhere. A scene that fits disagreeing
/// generations with view-dependent colour shows it here, where its renders from two nearby
/// cameras disagree about one surface.
pub fn consistency_errors(from: DepthRender, to: DepthRender) -> Result<Vec<f64>> {
    use crate::error::Error;
    use crate::warp::dibr::{WarpOptions, warp};
    let check = |r: &DepthRender, which: &str| {
        let n = r.camera.width as usize * r.camera.height as usize;
        if r.rgb.len() != 3 * n || r.alpha.len() != n || r.depth.len() != n {
            return Err(Error::invalid(format!(
                "{which} render of camera '{}' ({}×{}): {} colour, {} alpha and {} depth values",
                r.camera.name,
                r.camera.width,
                r.camera.height,
                r.rgb.len(),
                r.alpha.len(),
                r.depth.len()
            )));
        }
        Ok(n)
    };
    check(&from, "source")?;
    let n = check(&to, "target")?;
    let opaque = |a: f32| a >= CONSISTENCY_MIN_ALPHA;
    let depth: Vec<f32> = from
        .depth
        .iter()
        .zip(from.alpha)
        .map(|(&z, &a)| if opaque(a) { z } else { 0.0 })
        .collect();
    let image = ImageF32 {
        width: from.camera.width as usize,
        height: from.camera.height as usize,
        channels: 3,
        data: from.rgb.to_vec(),
    };
    let w = warp(
        &image,
        &depth,
        from.camera,
        to.camera,
        &WarpOptions::default(),
    )?;
    Ok((0..n)
        .map(|p| {
            let (wz, z) = (w.depth[p], to.depth[p]);
            let seen = !w.holes[p]
                && opaque(to.alpha[p])
                && z > 0.0
                && (wz - z).abs() <= CONSISTENCY_DEPTH_TOL * z;
            if seen {
                (0..3)
                    .map(|c| {
                        let d = f64::from(w.image.data[p * 3 + c] - to.rgb[p * 3 + c]);
                        d * d
                    })
                    .sum()
            } else {
                f64::NAN
            }
        })
        .collect())
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::camera::Camera;
    use glam::DVec3;

    /// Two cameras 0.3 apart along x facing a wall at z = 5 (camera z 5 at every pixel):
    /// the target's render differs from the source's by `δ` in every channel but sees
    /// something nearer in one box and little opacity in another; the source is
    /// transparent in a third.
    #[test]
    fn consistency_compares_the_renders_of_one_surface_only() {
        let (w, h) = (40usize, 30usize);
        let cam = |name: &str, x: f64| {
            let eye = DVec3::new(x, 0.0, 0.0);
            Camera::look_at(
                name,
                w as u32,
                h as u32,
                1.0,
                eye,
                eye + DVec3::Z,
                -DVec3::Y,
            )
            .unwrap()
        };
        let (a, b) = (cam("a", 0.0), cam("b", 0.3));
        let n = w * h;
        let inside = |p: usize, (x0, x1, y0, y1): (usize, usize, usize, usize)| {
            (x0..x1).contains(&(p % w)) && (y0..y1).contains(&(p / w))
        };
        let (near, faint, clear) = ((20, 26, 5, 10), (20, 26, 15, 20), (30, 36, 22, 27));
        let rgb_a = vec![0.25f32; 3 * n];
        let rgb_b = vec![0.375f32; 3 * n];
        let alpha_a: Vec<f32> = (0..n)
            .map(|p| if inside(p, clear) { 0.4 } else { 1.0 })
            .collect();
        let alpha_b: Vec<f32> = (0..n)
            .map(|p| if inside(p, faint) { 0.4 } else { 1.0 })
            .collect();
        let depth_a = vec![5.0f32; n];
        let depth_b: Vec<f32> = (0..n)
            .map(|p| if inside(p, near) { 2.5 } else { 5.0 })
            .collect();
        let from = DepthRender {
            camera: &a,
            rgb: &rgb_a,
            alpha: &alpha_a,
            depth: &depth_a,
        };
        let to = DepthRender {
            camera: &b,
            rgb: &rgb_b,
            alpha: &alpha_b,
            depth: &depth_b,
        };
        let e = consistency_errors(from, to).unwrap();
        let want = 3.0 * f64::from(0.375f32 - 0.25).powi(2);
        // b's view is a's shifted by 0.3 / 5 of the wall's width per unit depth: the
        // focal length 20 / tan(0.5) ≈ 36.6 px, so 0.3 · 36.6 / 5 ≈ 2.2 px; a's clear box
        // lands about 2 px to the left of where it is in a.
        let shift = 0.3 * a.fx / 5.0;
        let mut seen = 0;
        for (p, &e) in e.iter().enumerate() {
            let (x, y) = ((p % w) as f64 + 0.5, (p / w) as f64 + 0.5);
            let from_x = x + shift; // where in a the wall point at b's pixel lies
            let from_clear = (30.0..36.0).contains(&from_x) && (22.0..27.0).contains(&y);
            let edge = (from_x - from_x.round()).abs() < 1e-3;
            if inside(p, near) || inside(p, faint) || from_x >= w as f64 {
                assert!(e.is_nan(), "pixel {p}: {e}");
            } else if from_clear
                && !edge
                && (from_x - 30.0).abs() > 1.0
                && (from_x - 36.0).abs() > 1.0
            {
                assert!(
                    e.is_nan(),
                    "pixel {p} reached from a's transparent box: {e}"
                );
            } else if !from_clear
                && (from_x - 30.0).abs() > 1.0
                && (from_x - 36.0).abs() > 1.0
                && from_x < w as f64 - 1.0
            {
                assert_eq!(e, want, "pixel {p}");
                seen += 1;
            }
        }
        assert!(seen > n / 2, "{seen} of {n}");
        // The same render on both sides agrees exactly wherever it is seen.
        let same = consistency_errors(from, DepthRender { camera: &a, ..from }).unwrap();
        assert!(same.iter().all(|e| e.is_nan() || *e == 0.0));
        assert_eq!(
            same.iter().filter(|e| e.is_nan()).count(),
            alpha_a
                .iter()
                .filter(|&&x| x < CONSISTENCY_MIN_ALPHA)
                .count()
        );
        // Wrong sizes are named.
        let err = consistency_errors(
            from,
            DepthRender {
                depth: &depth_b[1..],
                ..to
            },
        )
        .unwrap_err()
        .to_string();
        assert!(err.contains("target render of camera 'b'"), "{err}");
    }
}
