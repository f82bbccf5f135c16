//! The Quality-Aware Mask (paper §3.4, Fig. 5) and the baselines it is compared with
//! (SPEC.md §15).
//!
//! From a trained scene: (1) set every Gaussian's base colour to `base` (SH DC
//! `(base − 0.5)/C0`) and all higher coefficients to 0 at degree `sh_degree`; (2) replace
//! every training image by `target`; (3) fine-tune with only the higher SH coefficients
//! receiving gradients. Directions the training views supervised turn to `target`; the
//! others keep `base`. Rendered with background `base` (holes are "unsupervised"), the mask
//! is the rendered colour's position on the `target → base` axis:
//!
//! `M = clamp(((c − t)·(b − t)) / |b − t|², 0, 1)`
//!
//! For red/black this is the R channel ("after normalizing the R channel"), for any other
//! distinguishable pair the same quantity. 1 = badly supervised, 0 = well supervised.
//!
//! The fine-tune uses the frozen-geometry replay ([`FrozenBlend`]): one recorded blend per
//! training view, no projection backward, no densification.

use crate::camera::Camera;
use crate::error::{Error, Result};
use crate::gaussian::ply::{ply_bytes, read_ply};
use crate::gaussian::{Gaussians, Param};
use crate::io::manifest::{FileEntry, Manifest};
use crate::io::{create_dir_all, write_atomic, write_text};
use crate::math::fastexp::exp;
use crate::math::sh::{SH_C0, num_coeffs};
use crate::raster::backward::frozen::{FrozenBlend, FrozenWork, geometry_of};
use crate::raster::{Outputs, RenderOptions, render};
use crate::rng::Uniform;
use crate::rng::stage_seed;
use crate::train::adam::{Adam, AdamConfig};
use crate::train::loss::{LossInput, LossWeights, image_loss};
use rayon::prelude::*;
use std::io::Write;
use std::path::Path;
use std::sync::Arc;

/// Settings of the QA-Mask fine-tune.
#[derive(Clone, Debug, PartialEq, serde::Serialize, serde::Deserialize)]
#[serde(default)]
pub struct QaMaskConfig {
    /// SH degree of the mask scene (paper: 5; the ablation uses 3 and 4).
    pub sh_degree: u32,
    pub iterations: u32,
    /// The colour every Gaussian starts with (paper: red) and the background of mask renders.
    pub base_color: [f32; 3],
    /// The colour of every training image (paper: black), also the fine-tune background.
    pub target_color: [f32; 3],
    /// Learning rate of the SH rest coefficients (INRIA's `feature_lr / 20`).
    pub lr_sh_rest: f32,
    pub adam: AdamConfig,
    /// The fine-tune loss (INRIA's L1 + D-SSIM).
    pub loss: LossWeights,
    pub seed: u64,
}

impl Default for QaMaskConfig {
    fn default() -> Self {
        QaMaskConfig {
            sh_degree: 5,
            iterations: 20_000,
            base_color: [1.0, 0.0, 0.0],
            target_color: [0.0, 0.0, 0.0],
            lr_sh_rest: 2.5e-3 / 20.0,
            adam: AdamConfig::default(),
            loss: LossWeights::INRIA,
            seed: 0,
        }
    }
}

impl QaMaskConfig {
    pub fn validate(&self) -> Result<()> {
        self.adam.validate()?;
        if !(self.lr_sh_rest >= 0.0 && self.lr_sh_rest.is_finite()) {
            return Err(Error::invalid(format!(
                "the QA-Mask learning rate must be finite and ≥ 0, got {}",
                self.lr_sh_rest
            )));
        }
        if self.sh_degree == 0 || self.sh_degree > crate::math::sh::MAX_SH_DEGREE {
            return Err(Error::invalid(format!(
                "QA-Mask SH degree {} must be 1..=5 (degree 0 has no view dependence)",
                self.sh_degree
            )));
        }
        let (b, t) = (self.base_color, self.target_color);
        if !b
            .iter()
            .chain(&t)
            .all(|v| v.is_finite() && (0.0..=1.0).contains(v))
        {
            return Err(Error::invalid("QA-Mask colours must be in [0, 1]"));
        }
        let d2: f32 = (0..3).map(|c| (b[c] - t[c]) * (b[c] - t[c])).sum();
        if d2 < 0.01 {
            return Err(Error::invalid(format!(
                "QA-Mask colours {b:?} and {t:?} are not distinguishable"
            )));
        }
        Ok(())
    }
}

/// Step 1: the mask scene — same geometry, base colour `base`, zero higher SH at `degree`.
pub fn mask_scene(trained: &Gaussians, cfg: &QaMaskConfig) -> Result<Gaussians> {
    cfg.validate()?;
    let c0 = SH_C0 as f32;
    let dc = cfg.base_color.map(|b| (b - 0.5) / c0);
    let mut g = crate::raster::backward::frozen::geometry_of(trained);
    g.sh_degree = cfg.sh_degree;
    g.sh_dc = vec![dc; trained.len()];
    g.sh_rest = vec![0.0; trained.len() * (num_coeffs(cfg.sh_degree) - 1) * 3];
    g.validate()?;
    Ok(g)
}

/// The mask value of one rendered colour (module docs).
pub fn mask_value(c: [f32; 3], base: [f32; 3], target: [f32; 3]) -> f32 {
    let d = [
        base[0] - target[0],
        base[1] - target[1],
        base[2] - target[2],
    ];
    let num = ((c[0] - target[0]) * d[0] + (c[1] - target[1]) * d[1]) + (c[2] - target[2]) * d[2];
    let den = (d[0] * d[0] + d[1] * d[1]) + d[2] * d[2];
    (num / den).clamp(0.0, 1.0)
}

/// Render the QA-Mask of the (fine-tuned) mask scene for `cam`: background `base`.
pub fn render_qa_mask(scene: &Gaussians, cam: &Camera, cfg: &QaMaskConfig) -> Result<Vec<f32>> {
    let r = render(
        scene,
        cam,
        &RenderOptions {
            background: cfg.base_color,
            ..RenderOptions::default()
        },
    )?;
    let rgb = r.rgb.expect("rgb");
    Ok(rgb
        .chunks_exact(3)
        .map(|c| mask_value([c[0], c[1], c[2]], cfg.base_color, cfg.target_color))
        .collect())
}

/// Progress of the fine-tune.
#[derive(Clone, Copy, Debug)]
pub struct FineTuneProgress<'a> {
    pub iteration: u32,
    pub iterations: u32,
    pub loss: f64,
    /// The scene after this iteration: the same bits as a fine-tune of `iteration`
    /// iterations (no step depends on the budget; test
    /// `qa_mask_fine_tune_checkpoints_are_shorter_fine_tunes`).
    pub scene: &'a Gaussians,
}

/// Steps 2–3: fine-tune `scene` (a [`mask_scene`]) towards `target` on `views`, only SH
/// rest training. View order: INRIA's shuffled stack with the generator of stage
/// "qa-mask". Returns the last loss.
pub fn fine_tune(
    scene: &mut Gaussians,
    views: &[Camera],
    cfg: &QaMaskConfig,
    on_progress: &mut dyn FnMut(&FineTuneProgress),
) -> Result<f64> {
    cfg.validate()?;
    if views.is_empty() {
        return Err(Error::invalid(
            "the QA-Mask fine-tune needs at least one view",
        ));
    }
    let opts = RenderOptions {
        background: cfg.target_color,
        sh_degree: Some(cfg.sh_degree),
        outputs: Outputs::RGB,
        ..RenderOptions::default()
    };
    let geometry = Arc::new(geometry_of(scene));
    // The views in parallel (a record is parallel only over its bands of tile rows: four
    // at 80×60); each record is independent of which thread made it.
    let records: Vec<FrozenBlend> = views
        .par_iter()
        .map(|cam| FrozenBlend::record_shared(scene, cam, &opts, geometry.clone()))
        .collect::<Result<_>>()?;
    let targets: Vec<Vec<f32>> = views
        .iter()
        .map(|c| {
            let n = (c.width * c.height) as usize;
            (0..n).flat_map(|_| cfg.target_color).collect()
        })
        .collect();
    // Gaussians no view has a splat of get a zero gradient at every step, so Adam leaves
    // them (and their zero moments) as they are: skipping them is exact (SPEC.md §15.1).
    let mut seen = vec![false; scene.len()];
    for rec in &records {
        assert_eq!(rec.visible().len(), seen.len(), "a record of another scene");
        for (s, &v) in seen.iter_mut().zip(rec.visible()) {
            *s |= v;
        }
    }
    let skip = seen.contains(&false).then_some(&seen[..]);
    let mut adam = Adam::new(cfg.adam, scene)?;
    let mut rng = Uniform::new(stage_seed(cfg.seed, "qa-mask"));
    let mut stack: Vec<usize> = Vec::new();
    let (mut work, mut rgb) = (FrozenWork::default(), Vec::new());
    let mut loss = 0.0;
    for it in 1..=cfg.iterations {
        if stack.is_empty() {
            stack = (0..views.len()).collect();
        }
        let vi = stack.remove(rng.below(stack.len() as u32) as usize);
        let cam = &views[vi];
        let rec = &records[vi];
        rec.render_rgb_with(scene, &mut work, &mut rgb)?;
        let out = image_loss(
            &LossInput {
                width: cam.width as usize,
                height: cam.height as usize,
                rgb: &rgb,
                target_rgb: &targets[vi],
                depth: None,
                target_depth: None,
                mask: None,
            },
            &cfg.loss,
        )?;
        rec.color_backward(&out.grad_rgb, &mut work)?;
        // The SH-rest gradient is made chunk by chunk inside the Adam step: the full
        // (N, K−1, 3) gradient array is never written.
        adam.step_with(
            scene,
            Param::ShRest,
            cfg.lr_sh_rest,
            &|first, g| rec.sh_rest_grad(&work, first, g),
            skip,
        );
        loss = out.terms.total;
        on_progress(&FineTuneProgress {
            iteration: it,
            iterations: cfg.iterations,
            loss,
            scene,
        });
    }
    Ok(loss)
}

/// A QA-Mask directory: `DIR/point_cloud.ply` (the fine-tuned mask scene),
/// `DIR/qa_mask.json` (its [`QaMaskConfig`]), `DIR/manifest.json` (sha256 of both).
pub fn write_mask_dir(dir: &Path, scene: &Gaussians, cfg: &QaMaskConfig) -> Result<()> {
    create_dir_all(dir)?;
    let (ply, text) = mask_files(scene, cfg)?;
    let ply_path = dir.join("point_cloud.ply");
    write_atomic(&ply_path, |w| w.write_all(&ply))?;
    write_text(&dir.join("qa_mask.json"), &text)?;
    Manifest::new(
        "qa-mask",
        "",
        serde_json::json!({ "config": cfg }),
        vec![
            FileEntry::new("point_cloud.ply", &ply),
            FileEntry::new("qa_mask.json", text.as_bytes()),
        ],
    )
    .write(dir)?;
    Ok(())
}

/// The two files of a QA-Mask directory: `point_cloud.ply` (bytes) and `qa_mask.json`
/// (text), for a caller that writes them its own way (a pipeline step).
pub fn mask_files(scene: &Gaussians, cfg: &QaMaskConfig) -> Result<(Vec<u8>, String)> {
    let ply = ply_bytes(scene)?;
    let text = serde_json::to_string_pretty(cfg).expect("config serializes");
    Ok((ply, text))
}

/// Read a QA-Mask directory written by [`write_mask_dir`] (or with [`mask_files`]).
pub fn read_mask_dir(dir: &Path) -> Result<(Gaussians, QaMaskConfig)> {
    let p = dir.join("qa_mask.json");
    let text = std::fs::read(&p).map_err(|e| Error::io(&p, e))?;
    let cfg: QaMaskConfig = serde_json::from_slice(&text)
        .map_err(|e| Error::parse(&p, format!("invalid QA-Mask config: {e}")))?;
    cfg.validate().map_err(|e| e.at(&p))?;
    let (g, _) = read_ply(&dir.join("point_cloud.ply"))?;
    if g.sh_degree != cfg.sh_degree {
        return Err(Error::invalid(format!(
            "the mask scene has SH degree {} but qa_mask.json says {}",
            g.sh_degree, cfg.sh_degree
        ))
        .at(&p));
    }
    Ok((g, cfg))
}

/// A colour by name (`red`, `green`, `blue`, `black`, `white`, `yellow`, `cyan`,
/// `magenta`) or as `#rrggbb`.
pub fn parse_color(s: &str) -> Result<[f32; 3]> {
    let named = match s {
        "red" => Some([1.0, 0.0, 0.0]),
        "green" => Some([0.0, 1.0, 0.0]),
        "blue" => Some([0.0, 0.0, 1.0]),
        "black" => Some([0.0; 3]),
        "white" => Some([1.0; 3]),
        "yellow" => Some([1.0, 1.0, 0.0]),
        "cyan" => Some([0.0, 1.0, 1.0]),
        "magenta" => Some([1.0, 0.0, 1.0]),
        _ => None,
    };
    if let Some(c) = named {
        return Ok(c);
    }
    let hex = s.strip_prefix('#').filter(|h| h.len() == 6 && h.is_ascii());
    if let Some(h) = hex {
        let byte = |k: usize| u8::from_str_radix(&h[2 * k..2 * k + 2], 16).ok();
        if let (Some(r), Some(g), Some(b)) = (byte(0), byte(1), byte(2)) {
            return Ok([r, g, b].map(|v| v as f32 / 255.0));
        }
    }
    Err(Error::invalid(format!(
        "unknown colour '{s}' (a name such as red or black, or #rrggbb)"
    )))
}

/// A heat map of a mask in `[0, 1]` for viewing (piecewise linear through black, dark
/// blue, magenta, orange, pale yellow — an inferno-like ramp).
pub fn heat_map(mask: &[f32]) -> Vec<f32> {
    const STOPS: [[f32; 3]; 5] = [
        [0.0, 0.0, 0.02],
        [0.2, 0.05, 0.45],
        [0.7, 0.15, 0.45],
        [0.98, 0.55, 0.05],
        [0.99, 1.0, 0.65],
    ];
    mask.iter()
        .flat_map(|&m| {
            let x = if m.is_finite() {
                m.clamp(0.0, 1.0)
            } else {
                0.0
            } * 4.0;
            let k = (x as usize).min(3);
            let f = x - k as f32;
            let (a, b) = (STOPS[k], STOPS[k + 1]);
            [0, 1, 2].map(|c| a[c] + (b[c] - a[c]) * f)
        })
        .collect()
}

/// Baseline: the opacity map, `1 − alpha` (holes and thin coverage are "bad").
pub fn opacity_mask(scene: &Gaussians, cam: &Camera) -> Result<Vec<f32>> {
    let r = render(
        scene,
        cam,
        &RenderOptions {
            outputs: Outputs {
                rgb: false,
                alpha: true,
                ..Outputs::RGB
            },
            ..RenderOptions::default()
        },
    )?;
    Ok(r.alpha
        .expect("alpha")
        .iter()
        .map(|a| (1.0 - a).clamp(0.0, 1.0))
        .collect())
}

/// Baseline: 3DGS-Enhancer's "large Gaussians are badly reconstructed". Each Gaussian
/// carries the quantile of its largest scale among all Gaussians (0 = smallest, 1 =
/// largest; ties share the lower rank by index order), blended like a colour; uncovered
/// pixels count as bad (background 1).
pub fn scale_mask(scene: &Gaussians, cam: &Camera) -> Result<Vec<f32>> {
    let n = scene.len();
    let maxs: Vec<f32> = scene
        .log_scales
        .iter()
        .map(|l| exp(l[0].max(l[1]).max(l[2])))
        .collect();
    let mut order: Vec<usize> = (0..n).collect();
    order.sort_by(|&a, &b| maxs[a].total_cmp(&maxs[b]).then(a.cmp(&b)));
    let mut q = vec![0f32; n];
    for (rank, &i) in order.iter().enumerate() {
        q[i] = if n > 1 {
            rank as f32 / (n - 1) as f32
        } else {
            0.0
        };
    }
    let c0 = SH_C0 as f32;
    let mut g = geometry_of(scene);
    g.sh_degree = 0;
    g.sh_dc = q.iter().map(|&v| [(v - 0.5) / c0; 3]).collect();
    g.sh_rest = Vec::new();
    let r = render(
        &g,
        cam,
        &RenderOptions {
            background: [1.0; 3],
            ..RenderOptions::default()
        },
    )?;
    Ok(r.rgb
        .expect("rgb")
        .chunks_exact(3)
        .map(|c| c[0].clamp(0.0, 1.0))
        .collect())
}

/// Area under the ROC curve of `score` for detecting `positive` pixels (Mann–Whitney U with
/// average ranks for ties); `None` when one class is empty.
pub fn auroc(score: &[f32], positive: &[bool]) -> Option<f64> {
    let ranks = average_ranks(score);
    let np = positive.iter().filter(|&&p| p).count();
    let nn = positive.len() - np;
    if np == 0 || nn == 0 {
        return None;
    }
    let sum: f64 = ranks
        .iter()
        .zip(positive)
        .filter(|(_, p)| **p)
        .map(|(r, _)| r)
        .sum();
    Some((sum - (np as f64) * (np as f64 + 1.0) / 2.0) / (np as f64 * nn as f64))
}

/// Spearman's rank correlation (Pearson correlation of average ranks); `None` if either
/// side is constant.
pub fn spearman(a: &[f32], b: &[f32]) -> Option<f64> {
    let (ra, rb) = (average_ranks(a), average_ranks(b));
    let n = ra.len() as f64;
    let (ma, mb) = (ra.iter().sum::<f64>() / n, rb.iter().sum::<f64>() / n);
    let (mut sab, mut saa, mut sbb) = (0.0, 0.0, 0.0);
    for (x, y) in ra.iter().zip(&rb) {
        sab += (x - ma) * (y - mb);
        saa += (x - ma) * (x - ma);
        sbb += (y - mb) * (y - mb);
    }
    (saa > 0.0 && sbb > 0.0).then(|| sab / (saa * sbb).sqrt())
}

/// 1-based ranks, ties given their average rank.
fn average_ranks(v: &[f32]) -> Vec<f64> {
    let mut idx: Vec<usize> = (0..v.len()).collect();
    idx.sort_by(|&a, &b| v[a].total_cmp(&v[b]).then(a.cmp(&b)));
    let mut ranks = vec![0f64; v.len()];
    let mut i = 0;
    while i < idx.len() {
        let mut j = i;
        while j + 1 < idx.len() && v[idx[j + 1]].total_cmp(&v[idx[i]]).is_eq() {
            j += 1;
        }
        let r = (i + j) as f64 / 2.0 + 1.0;
        for &k in &idx[i..=j] {
            ranks[k] = r;
        }
        i = j + 1;
    }
    ranks
}

/// Per-pixel error of a render against ground truth: mean absolute RGB difference of the
/// clamped render.
pub fn pixel_error(rgb: &[f32], gt: &[f32]) -> Vec<f32> {
    rgb.par_chunks_exact(3)
        .zip(gt.par_chunks_exact(3))
        .map(|(a, b)| {
            let d = |c: usize| (a[c].clamp(0.0, 1.0) - b[c]).abs();
            (d(0) + d(1) + d(2)) / 3.0
        })
        .collect()
}

/// Pixels whose mean absolute RGB error exceeds this are "badly reconstructed" in the
/// audit (SPEC.md §15.2).
pub const BAD_PIXEL_ERROR: f32 = 0.1;

/// One mask's figures in [`audit`].
#[derive(Clone, Debug, PartialEq, serde::Serialize, serde::Deserialize)]
pub struct AuditRow {
    /// `qa-<degree>`, `opacity` or `scale`.
    pub mask: String,
    pub auroc: f64,
    pub spearman: f64,
    /// Mean mask value over the held-out and over the in-distribution test views.
    pub mean_heldout: f64,
    pub mean_test: f64,
    /// Fine-tune wall time (0 for the baselines).
    pub seconds: f64,
}

/// The measured check of the paper's claim on one scene.
#[derive(Clone, Debug, PartialEq, serde::Serialize, serde::Deserialize)]
pub struct AuditReport {
    pub bad_pixel_error: f32,
    /// Fraction of held-out pixels that are bad.
    pub bad_fraction: f64,
    pub heldout_pixels: usize,
    pub rows: Vec<AuditRow>,
}

impl AuditReport {
    pub fn table(&self) -> String {
        let mut s = format!(
            "bad pixel: error > {} ({:.1} % of {} held-out pixels)\n\n\
             | mask | AUROC | Spearman | mean (heldout) | mean (test) | fine-tune s |\n\
             |---|---|---|---|---|---|\n",
            self.bad_pixel_error,
            100.0 * self.bad_fraction,
            self.heldout_pixels
        );
        for r in &self.rows {
            s += &format!(
                "| {} | {:.3} | {:.3} | {:.3} | {:.3} | {:.1} |\n",
                r.mask, r.auroc, r.spearman, r.mean_heldout, r.mean_test, r.seconds
            );
        }
        s
    }
}

fn mean(v: &[f32]) -> f64 {
    v.iter().map(|&x| x as f64).sum::<f64>() / v.len().max(1) as f64
}

/// Score QA-Mask (one fine-tune per config) and the baselines against the true error of
/// `trained` on the held-out views of `data` (fine-tuning on its train views).
pub fn audit(
    trained: &Gaussians,
    data: &crate::dataset::Dataset,
    configs: &[QaMaskConfig],
    on_progress: &mut dyn FnMut(&str, &FineTuneProgress),
) -> Result<AuditReport> {
    use crate::dataset::Split;
    if data.heldout.is_empty() {
        return Err(Error::invalid(
            "the audit needs a dataset with held-out views",
        ));
    }
    let mut err = Vec::new();
    for &i in &data.heldout {
        let v = &data.views[i];
        let r = render(trained, &v.camera, &RenderOptions::default())?;
        err.extend(pixel_error(&r.rgb.expect("rgb"), &v.image.data));
    }
    let bad: Vec<bool> = err.iter().map(|&e| e > BAD_PIXEL_ERROR).collect();
    let score = |f: &dyn Fn(&Camera) -> Result<Vec<f32>>, s: Split| -> Result<Vec<f32>> {
        let mut out = Vec::new();
        for &i in data.split(s) {
            out.extend(f(&data.views[i].camera)?);
        }
        Ok(out)
    };
    let row =
        |name: String, f: &dyn Fn(&Camera) -> Result<Vec<f32>>, secs: f64| -> Result<AuditRow> {
            let held = score(f, Split::Heldout)?;
            let test = score(f, Split::Test)?;
            Ok(AuditRow {
                mask: name,
                auroc: auroc(&held, &bad).unwrap_or(f64::NAN),
                spearman: spearman(&held, &err).unwrap_or(f64::NAN),
                mean_heldout: mean(&held),
                mean_test: mean(&test),
                seconds: secs,
            })
        };
    let train: Vec<Camera> = data
        .train
        .iter()
        .map(|&i| data.views[i].camera.clone())
        .collect();
    let mut rows = Vec::new();
    for cfg in configs {
        let name = format!("qa-{}", cfg.sh_degree);
        let mut s = mask_scene(trained, cfg)?;
        let t0 = std::time::Instant::now();
        fine_tune(&mut s, &train, cfg, &mut |p| on_progress(&name, p))?;
        let secs = t0.elapsed().as_secs_f64();
        rows.push(row(name, &|c: &Camera| render_qa_mask(&s, c, cfg), secs)?);
    }
    rows.push(row(
        "opacity".into(),
        &|c: &Camera| opacity_mask(trained, c),
        0.0,
    )?);
    rows.push(row(
        "scale".into(),
        &|c: &Camera| scale_mask(trained, c),
        0.0,
    )?);
    Ok(AuditReport {
        bad_pixel_error: BAD_PIXEL_ERROR,
        bad_fraction: bad.iter().filter(|&&b| b).count() as f64 / bad.len().max(1) as f64,
        heldout_pixels: bad.len(),
        rows,
    })
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn auroc_and_spearman_on_known_cases() {
        let s = [0.1, 0.4, 0.5, 0.8];
        let p = [false, true, false, true];
        assert_eq!(auroc(&s, &p), Some(0.75));
        assert_eq!(auroc(&[0.5; 4], &p), Some(0.5), "ties are half");
        assert_eq!(auroc(&s, &[true; 4]), None);
        let r = spearman(&[1.0, 2.0, 3.0, 4.0], &[10.0, 20.0, 15.0, 40.0]).unwrap();
        assert!((r - 0.8).abs() < 1e-12, "{r}");
        assert_eq!(spearman(&[1.0; 3], &[1.0, 2.0, 3.0]), None);
    }

    #[test]
    fn mask_value_projects_on_the_colour_axis() {
        let (r, k, g) = ([1.0, 0.0, 0.0], [0.0; 3], [0.0, 1.0, 0.0]);
        assert_eq!(
            mask_value([0.3, 0.9, 0.2], r, k),
            0.3,
            "red/black: the R channel"
        );
        assert_eq!(
            mask_value([0.9, 0.3, 0.2], g, k),
            0.3,
            "green/black: the G channel"
        );
        assert_eq!(mask_value([2.0, 0.0, 0.0], r, k), 1.0);
        assert_eq!(mask_value([0.5, 0.0, 0.0], k, r), 0.5, "reversed pair");
    }
}
