//! Evaluation built into the pipeline (SPEC.md §20.7): on the evaluation poses (never given
//! to any stage), PSNR and SSIM of each stage's scene on *existing* pixels (the truth's
//! surface point is seen by some training camera) and on *extrapolated* pixels (the
//! rest), and PSNR / SSIM on the in-distribution test views of the training half (did the
//! original scene degrade?).

use super::artifacts::{load_mask, read_json, save_mask, scene_of, stem};
use super::rundir::StepDone;
use super::steps::Scene;
use super::steps::Step;
use super::{Inputs, Run};
use crate::camera::Camera;
use crate::error::{Error, Result};
use crate::gaussian::Gaussians;
use crate::io::image::write_png;
use crate::io::json_float::show;
use crate::raster::{RenderOptions, render};
use crate::train::ssim::ssim_map;
use glam::DVec3;

/// Relative depth band of the visibility test: a training camera sees a surface point when
/// its own depth at the point's pixel is within this fraction of the point's depth.
pub const VISIBILITY_DEPTH_TOLERANCE: f64 = 0.02;

/// Metrics of one scene (`null` in JSON where a class has no pixel, `"inf"` for the PSNR
/// of identical images: [`crate::io::json_float`]).
#[derive(Clone, Debug, PartialEq, serde::Serialize, serde::Deserialize)]
pub struct Row {
    pub scene: String,
    #[serde(with = "crate::io::json_float")]
    pub psnr_all: f64,
    #[serde(with = "crate::io::json_float")]
    pub psnr_existing: f64,
    #[serde(with = "crate::io::json_float")]
    pub psnr_extrapolated: f64,
    #[serde(with = "crate::io::json_float")]
    pub ssim_all: f64,
    #[serde(with = "crate::io::json_float")]
    pub ssim_existing: f64,
    #[serde(with = "crate::io::json_float")]
    pub ssim_extrapolated: f64,
    /// Mean over the training half's test views.
    #[serde(with = "crate::io::json_float")]
    pub psnr_train_half: f64,
    #[serde(with = "crate::io::json_float")]
    pub ssim_train_half: f64,
    pub gaussians: usize,
    /// Where the scene's Gaussians come from against the original scene, and what the
    /// original scene's lineage alone renders on the training half (§20.7, issue #72);
    /// `None` (not written) for the original scene, the cycle's, and steps made before
    /// reconstructions recorded their lineage.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub lineage: Option<LineageRecord>,
    /// Per evaluation view, the sums the pooled metrics are made of (in evaluation order),
    /// so that pooled PSNR over any subset of views, and a bootstrap over views, can be
    /// computed later (SPEC.md §20.7). Empty in files written before it was recorded.
    #[serde(default, skip_serializing_if = "Vec::is_empty")]
    pub views: Vec<ViewRecord>,
}

/// A scene's Gaussians against the original scene's, through the reconstructions' lineage
/// files (`recon::LINEAGE_FILE`): which descend from an original Gaussian (through
/// fine-tuning, copies and splits) and which the pipeline added (its points and their
/// descendants), and what became of the original Gaussians.
#[derive(Clone, Debug, PartialEq, serde::Serialize, serde::Deserialize)]
pub struct LineageRecord {
    /// Mean training-half PSNR of the scene's Gaussians that descend from the original
    /// scene's, rendered alone (as `psnr_train_half` is): against the original's, the change
    /// within the original lineage (moved, densified, pruned); against the scene's, what the
    /// added Gaussians do to the training views.
    #[serde(with = "crate::io::json_float")]
    pub psnr_train_half_originals: f64,
    /// The scene's Gaussians descending from an original Gaussian, and the others.
    pub from_originals: usize,
    pub added: usize,
    /// The original scene's Gaussians with no descendant left (pruned), with one, with more
    /// (copied or split).
    pub originals_lost: usize,
    pub originals_one: usize,
    pub originals_more: usize,
    /// Over the originals with one descendant, the median distance it moved in units of
    /// the original's largest standard deviation, and the median change of its opacity.
    #[serde(with = "crate::io::json_float")]
    pub moved_median: f64,
    #[serde(with = "crate::io::json_float")]
    pub opacity_change_median: f64,
    /// The reconstruction that made the scene: which views' gradients moved its Gaussians
    /// (§20.5; from its `supervision.json`, when it trained on generated views and
    /// recorded it).
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub attribution: Option<crate::train::attribution::AttributionRecord>,
}

/// No original ancestor: a Gaussian the pipeline added.
const ADDED: u32 = u32::MAX;

/// The scene a reconstruction of `scene` starts from (the head of its starting Gaussians):
/// the chain whose lineage composes back to the original scene.
fn predecessor(scene: Scene) -> Option<Scene> {
    match scene {
        Scene::Stage1 => Some(Scene::Original),
        Scene::Stage2 => Some(Scene::Stage1),
        Scene::Interpolate => Some(Scene::Stage2),
        Scene::Original | Scene::Cycle => None,
    }
}

/// Each Gaussian's original ancestor (or [`ADDED`]) after a reconstruction whose lineage is
/// `lineage` (indices into its start: the previous scene, whose ancestors are `before`,
/// then appended points).
fn compose(before: &[u32], lineage: &[u32]) -> Vec<u32> {
    lineage
        .iter()
        .map(|&i| before.get(i as usize).copied().unwrap_or(ADDED))
        .collect()
}

/// The attribution a reconstruction recorded in its `supervision.json` (`None` where it
/// did not: no generated views, or made before it was recorded).
fn attribution_of(
    recon: &std::path::Path,
) -> Result<Option<crate::train::attribution::AttributionRecord>> {
    let file = recon.join("supervision.json");
    let v: serde_json::Value = read_json(&file)?;
    v.get(super::recon::ATTRIBUTION_KEY)
        .map(|a| {
            serde_json::from_value(a.clone())
                .map_err(|e| Error::invalid(format!("its attribution: {e}")).at(&file))
        })
        .transpose()
}

/// The [`LineageRecord`] of `scene`, whose Gaussians' original ancestors are `ancestors`.
fn lineage_record(
    inputs: &Inputs,
    scene: &Gaussians,
    ancestors: &[u32],
    opts: &RenderOptions,
) -> Result<LineageRecord> {
    let original = &inputs.scene;
    let from: Vec<usize> = (0..scene.len())
        .filter(|&j| ancestors[j] != ADDED)
        .collect();
    let mut descendants = vec![0u32; original.len()];
    let mut last = vec![usize::MAX; original.len()];
    for &j in &from {
        let a = ancestors[j] as usize;
        descendants[a] += 1;
        last[a] = j;
    }
    let (mut moved, mut opacity) = (Vec::new(), Vec::new());
    for (a, &n) in descendants.iter().enumerate() {
        if n != 1 {
            continue;
        }
        let j = last[a];
        let sigma = original.log_scales[a]
            .iter()
            .fold(f32::MIN, |m, &v| m.max(v));
        let d: f64 = (0..3)
            .map(|c| (scene.means[j][c] as f64 - original.means[a][c] as f64).powi(2))
            .sum::<f64>()
            .sqrt();
        moved.push(d / (sigma as f64).exp());
        let sig = |o: f32| 1.0 / (1.0 + (-(o as f64)).exp());
        opacity.push(sig(scene.opacity_logits[j]) - sig(original.opacity_logits[a]));
    }
    let median = |mut v: Vec<f64>| {
        if v.is_empty() {
            return f64::NAN;
        }
        v.sort_by(f64::total_cmp);
        let m = v.len() / 2;
        if v.len() % 2 == 1 {
            v[m]
        } else {
            0.5 * (v[m - 1] + v[m])
        }
    };
    let lineage = scene.select(&from);
    let (psnr, _) = train_half(inputs, &lineage, opts)?;
    Ok(LineageRecord {
        psnr_train_half_originals: psnr,
        from_originals: from.len(),
        added: scene.len() - from.len(),
        originals_lost: descendants.iter().filter(|&&n| n == 0).count(),
        originals_one: descendants.iter().filter(|&&n| n == 1).count(),
        originals_more: descendants.iter().filter(|&&n| n > 1).count(),
        moved_median: median(moved),
        opacity_change_median: median(opacity),
        attribution: None,
    })
}

/// One evaluation view's sums, per pixel class.
#[derive(Clone, Debug, PartialEq, serde::Serialize, serde::Deserialize)]
pub struct ViewRecord {
    pub view: String,
    pub all: ClassSums,
    pub existing: ClassSums,
    pub extrapolated: ClassSums,
}

/// Sums over the pixels of one class of one view: PSNR over a set of views is
/// `−10·log10(Σ squared_error / (3·Σ pixels))`, SSIM `Σ ssim_sum / Σ pixels`.
#[derive(Clone, Copy, Debug, Default, PartialEq, serde::Serialize, serde::Deserialize)]
pub struct ClassSums {
    pub pixels: u64,
    /// Σ over the class's pixels and the three channels of (render − truth)², both
    /// clamped to [0, 1].
    pub squared_error: f64,
    /// Σ over the class's pixels of the SSIM map (11×11 Gaussian window, σ 1.5).
    pub ssim_sum: f64,
    /// GMSD's blocks over the class ([`crate::eval::GradientBlocks`]): Σ of each pixel's
    /// weight (one over its block's pixels), and Σ weight × the block's deficit `1 −
    /// similarity`, its square, and the render's and the truth's gradient energy (the
    /// deficit, not the similarity near 1, so that the variance does not cancel for
    /// near-identical images). 0 in samples written before they were recorded (the metrics
    /// are then NaN).
    #[serde(default)]
    pub gms_weight: f64,
    #[serde(default)]
    pub gms_deficit: f64,
    #[serde(default)]
    pub gms_deficit_squares: f64,
    #[serde(default)]
    pub render_gradient_energy: f64,
    #[serde(default)]
    pub truth_gradient_energy: f64,
    /// Multi-view consistency over the class ([`crate::eval::consistency_errors`]): recorded
    /// for a pair's classes only, absent before it was (and then not written).
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub consistency: Option<Consistency>,
}

/// A class's multi-view consistency sums (SPEC.md §21.7): its pixels that the nearest other
/// evaluation view's render reached on one surface, and Σ over them and the three channels
/// of the squared colour difference.
#[derive(Clone, Copy, Debug, Default, PartialEq, serde::Serialize, serde::Deserialize)]
pub struct Consistency {
    pub pixels: u64,
    pub squared_error: f64,
}

/// PSNR of `se`, a sum of squared errors over `n` RGB pixels: `−10·log10(se / 3n)` (NaN
/// with no pixel, +∞ with no error).
fn pooled_psnr(se: f64, n: u64) -> f64 {
    if n == 0 {
        f64::NAN
    } else {
        -10.0 * (se / (3 * n) as f64).log10()
    }
}

impl ClassSums {
    /// Pooled PSNR of a set of views' sums (NaN with no pixel, +∞ with no error).
    pub fn psnr<'a>(sums: impl IntoIterator<Item = &'a ClassSums>) -> f64 {
        let (mut se, mut n) = (0f64, 0u64);
        for s in sums {
            se += s.squared_error;
            n += s.pixels;
        }
        pooled_psnr(se, n)
    }

    /// Pooled SSIM of a set of views' sums: the mean of the map over their pixels (NaN
    /// with no pixel).
    pub fn ssim<'a>(sums: impl IntoIterator<Item = &'a ClassSums>) -> f64 {
        let (mut s, mut n) = (0f64, 0u64);
        for c in sums {
            s += c.ssim_sum;
            n += c.pixels;
        }
        if n == 0 { f64::NAN } else { s / n as f64 }
    }

    /// Pooled GMSD of a set of views' sums: the weighted population standard deviation of
    /// the gradient magnitude similarity over the class's blocks (NaN with no block).
    pub fn gmsd<'a>(sums: impl IntoIterator<Item = &'a ClassSums>) -> f64 {
        let (mut w, mut s, mut q) = (0f64, 0f64, 0f64);
        for c in sums {
            w += c.gms_weight;
            s += c.gms_deficit;
            q += c.gms_deficit_squares;
        }
        if w > 0.0 {
            let mean = s / w;
            (q / w - mean * mean).max(0.0).sqrt()
        } else {
            f64::NAN
        }
    }

    /// Pooled detail ratio: the render's gradient energy over the truth's on the class
    /// (below 1 where the render is smoother: averaged generations blur).
    pub fn detail_ratio<'a>(sums: impl IntoIterator<Item = &'a ClassSums>) -> f64 {
        let (mut r, mut t) = (0f64, 0f64);
        for c in sums {
            r += c.render_gradient_energy;
            t += c.truth_gradient_energy;
        }
        if t > 0.0 { r / t } else { f64::NAN }
    }

    /// Pooled consistency PSNR of a set of views' sums: `−10·log10(Σ squared_error / (3·Σ
    /// pixels))` of the neighbours' warped renders against the views' own (NaN with no
    /// pixel, or where a view did not record it).
    pub fn consistency_psnr<'a>(sums: impl IntoIterator<Item = &'a ClassSums>) -> f64 {
        let (mut se, mut n) = (0f64, 0u64);
        for s in sums {
            let Some(c) = s.consistency else {
                return f64::NAN;
            };
            se += c.squared_error;
            n += c.pixels;
        }
        pooled_psnr(se, n)
    }

    /// Add one pixel's consistency error (the sum over RGB; NaN: the pixel is not seen on
    /// one surface from the neighbour, and only starts the record).
    pub fn add_consistency(&mut self, error: f64) {
        let c = self.consistency.get_or_insert_with(Consistency::default);
        if error.is_finite() {
            c.pixels += 1;
            c.squared_error += error;
        }
    }

    /// Add pixel `p` of a scored view: its squared error over the three channels (render
    /// and truth clamped to [0, 1]), its SSIM and its GMSD terms.
    pub fn add(&mut self, v: &ScoredView, p: usize) {
        for c in 0..3 {
            let d = (v.rgb[p * 3 + c] - v.truth[p * 3 + c].clamp(0.0, 1.0)) as f64;
            self.squared_error += d * d;
        }
        self.pixels += 1;
        self.ssim_sum += v.ssim[p];
        self.add_gradients(&v.gradients, p % v.width, p / v.width, v.width, v.height);
    }

    /// Add pixel `(x, y)` of a `w × h` view to the class's GMSD sums.
    pub fn add_gradients(
        &mut self,
        g: &crate::eval::GradientBlocks,
        x: usize,
        y: usize,
        w: usize,
        h: usize,
    ) {
        let (b, weight) = g.block_of(x, y, w, h);
        let d = 1.0 - g.similarity[b];
        self.gms_weight += weight;
        self.gms_deficit += weight * d;
        self.gms_deficit_squares += weight * d * d;
        self.render_gradient_energy += weight * g.render_energy[b];
        self.truth_gradient_energy += weight * g.truth_energy[b];
    }
}

/// A scene rendered at an evaluation view and scored against its truth, per pixel: what
/// [`ClassSums::add`] sums over a class.
pub struct ScoredView<'a> {
    pub width: usize,
    pub height: usize,
    /// The render, clamped to [0, 1].
    pub rgb: Vec<f32>,
    pub truth: &'a [f32],
    /// SSIM's map (11×11 Gaussian window, σ 1.5) and GMSD's blocks.
    pub ssim: Vec<f64>,
    pub gradients: crate::eval::GradientBlocks,
}

impl<'a> ScoredView<'a> {
    /// Render `scene` at `view` under `opts` and score it against the view's image.
    pub fn new(
        scene: &Gaussians,
        view: &'a crate::dataset::View,
        opts: &RenderOptions,
    ) -> Result<ScoredView<'a>> {
        ScoredView::against(scene, &view.camera, &view.image.data, opts)
    }

    /// Render `scene` at `camera` under `opts` and score it against `truth` (RGB of the
    /// camera's size, the image a view holds or one a generator made there).
    pub fn against(
        scene: &Gaussians,
        camera: &Camera,
        truth: &'a [f32],
        opts: &RenderOptions,
    ) -> Result<ScoredView<'a>> {
        let (w, h) = (camera.width as usize, camera.height as usize);
        if truth.len() != w * h * 3 {
            return Err(Error::invalid(format!(
                "an image of {} values to score a {w}×{h} render against (RGB: {})",
                truth.len(),
                w * h * 3
            )));
        }
        let rgb = render(scene, camera, opts)?.rgb.expect("rgb");
        Ok(ScoredView::of_render(rgb, truth, w, h))
    }

    /// Score a `w × h` render's RGB (clamped here) against `truth`, of the same size.
    pub fn of_render(mut rgb: Vec<f32>, truth: &'a [f32], w: usize, h: usize) -> ScoredView<'a> {
        for x in &mut rgb {
            *x = x.clamp(0.0, 1.0);
        }
        ScoredView {
            width: w,
            height: h,
            ssim: ssim_map(&rgb, truth, w, h, 3),
            gradients: crate::eval::GradientBlocks::new(&rgb, truth, w, h),
            rgb,
            truth,
        }
    }
}

/// The metric table, one row per stage.
#[derive(Clone, Debug, PartialEq, serde::Serialize, serde::Deserialize)]
pub struct Summary {
    pub evaluation_views: usize,
    pub existing_fraction: f64,
    pub rows: Vec<Row>,
}

impl Summary {
    pub fn table(&self) -> String {
        let mut s = String::from(
            "| scene | PSNR existing | PSNR extrapolated | PSNR all | SSIM existing | SSIM extrapolated | train-half PSNR | Gaussians |\n|---|---|---|---|---|---|---|---|\n",
        );
        for r in &self.rows {
            s += &format!(
                "| {} | {} | {} | {} | {:.4} | {:.4} | {} | {} |\n",
                r.scene,
                show(r.psnr_existing, 2),
                show(r.psnr_extrapolated, 2),
                show(r.psnr_all, 2),
                r.ssim_existing,
                r.ssim_extrapolated,
                show(r.psnr_train_half, 2),
                r.gaussians
            );
        }
        s
    }

    pub fn row(&self, scene: &str) -> Option<&Row> {
        self.rows.iter().find(|r| r.scene == scene)
    }
}

/// The pixel (row-major index) of `cam` whose truth depth `depth` sees the world point
/// `p`: `p` projects inside the image, in front of the camera, and the depth there agrees
/// with `p`'s within [`VISIBILITY_DEPTH_TOLERANCE`].
pub fn seen_at(cam: &Camera, depth: &[f32], p: DVec3) -> Option<usize> {
    let q = cam.camera_from_world_point(p);
    if q.z <= 0.0 {
        return None;
    }
    let u = cam.fx * q.x / q.z + cam.cx;
    let v = cam.fy * q.y / q.z + cam.cy;
    if !(u >= 0.0 && v >= 0.0 && u < cam.width as f64 && v < cam.height as f64) {
        return None;
    }
    let i = v as usize * cam.width as usize + u as usize;
    let d = depth[i] as f64;
    (d > 0.0 && (d - q.z).abs() <= VISIBILITY_DEPTH_TOLERANCE * q.z).then_some(i)
}

/// Pixels of `cam` (with truth depth `depth`) whose surface point some training camera
/// sees ([`seen_at`]). Pixels without truth depth are not existing.
pub fn existing_pixels(cam: &Camera, depth: &[f32], train: &[(&Camera, &[f32])]) -> Vec<bool> {
    let (w, h) = (cam.width as usize, cam.height as usize);
    let mut out = vec![false; w * h];
    for y in 0..h {
        for x in 0..w {
            let z = depth[y * w + x] as f64;
            if !(z.is_finite() && z > 0.0) {
                continue;
            }
            let pw = cam.pixel_point(x, y, z);
            out[y * w + x] = train.iter().any(|(t, td)| seen_at(t, td, pw).is_some());
        }
    }
    out
}

/// The existing-pixel masks of the evaluation poses ([`existing_pixels`] against the
/// training views with a truth depth), in `inputs.evaluation` order: what step
/// `eval/masks` writes.
pub fn existing_masks(inputs: &Inputs) -> Vec<Vec<bool>> {
    let data = &inputs.data;
    let train: Vec<(&Camera, &[f32])> = data
        .train
        .iter()
        .filter_map(|&i| {
            let v = &data.views[i];
            v.depth.as_deref().map(|d| (&v.camera, d))
        })
        .collect();
    inputs
        .evaluation
        .iter()
        .map(|&i| {
            let v = &data.views[i];
            let d = v.depth.as_deref().expect("checked by load_inputs");
            existing_pixels(&v.camera, d, &train)
        })
        .collect()
}

/// A view that generated part of the unseen surface: its camera, its truth depth and the
/// pixels it generated (its inpainting mask).
pub struct Generating<'a> {
    pub camera: &'a Camera,
    pub depth: &'a [f32],
    pub mask: &'a [bool],
}

/// The sample of the unseen surface (SPEC.md §21.5): every *extrapolated* pixel of the
/// evaluation views (not in `existing`, [`existing_masks`]) with a truth depth is a surface
/// point no training view sees. `visit` gets, per point in view-then-raster order, the
/// evaluation view's index (in `inputs.evaluation`) and pixel, and the `(view, pixel)` of
/// each of `views` that generated it: the point is visible in the view ([`seen_at`]) at a
/// pixel of its mask. The audit's coverage diagnostic, its pixel classes and the colliding
/// set it matches to the independent set all count on this one sample.
pub fn visit_unseen_surface(
    inputs: &Inputs,
    existing: &[Vec<bool>],
    views: &[Generating],
    mut visit: impl FnMut(usize, usize, &[(usize, usize)]),
) {
    let mut hits: Vec<(usize, usize)> = Vec::with_capacity(views.len());
    for (e, (&i, existing)) in inputs.evaluation.iter().zip(existing).enumerate() {
        let v = &inputs.data.views[i];
        let Some(depth) = v.depth.as_deref() else {
            continue;
        };
        let w = v.camera.width as usize;
        for (p, &seen) in existing.iter().enumerate() {
            let z = depth[p] as f64;
            if seen || !(z.is_finite() && z > 0.0) {
                continue;
            }
            let x = v.camera.pixel_point(p % w, p / w, z);
            hits.clear();
            for (k, g) in views.iter().enumerate() {
                if let Some(q) = seen_at(g.camera, g.depth, x).filter(|&q| g.mask[q]) {
                    hits.push((k, q));
                }
            }
            visit(e, p, &hits);
        }
    }
}

/// An evaluation pixel's class for the audit's pixel classes (SPEC.md §21.5): not on the
/// sample of the unseen surface (existing, or without truth depth).
pub const CLASS_OTHER: u8 = 0;
/// An extrapolated pixel whose surface point at most one stage-1 view generated.
pub const CLASS_UNCONTESTED: u8 = 1;
/// An extrapolated pixel whose surface point two or more stage-1 views generated: where
/// their generations can conflict.
pub const CLASS_CONTESTED: u8 = 2;

impl Run<'_> {
    /// The existing-pixel masks of the evaluation poses (step `eval/masks`).
    pub fn eval_masks(&self) -> Result<StepDone> {
        let inputs = self.inputs;
        let data = &inputs.data;
        let names: Vec<&str> = inputs
            .evaluation
            .iter()
            .map(|&i| data.views[i].camera.name.as_str())
            .collect();
        let key = serde_json::json!({
            "evaluation": names,
            "train": data.train.iter().map(|&i| &data.views[i].camera.name).collect::<Vec<_>>(),
            "tolerance": VISIBILITY_DEPTH_TOLERANCE,
        });
        self.step(&Step::EvalMasks, key, |w| {
            for (&i, m) in inputs.evaluation.iter().zip(existing_masks(inputs)) {
                let v = &data.views[i];
                save_mask(
                    w,
                    &stem(&v.camera.name),
                    &m,
                    v.camera.width as usize,
                    v.camera.height as usize,
                )?;
            }
            Ok(())
        })
    }

    /// Evaluate those of `scenes` the scope selects (`None` = the original scene; else a
    /// reconstruction step) with the masks of [`Run::eval_masks`].
    pub fn evaluate(
        &self,
        scenes: &[(Scene, Option<StepDone>)],
        masks: StepDone,
    ) -> Result<(Summary, Vec<StepDone>)> {
        let inputs = self.inputs;
        let data = &inputs.data;
        let existing: Vec<Vec<bool>> = inputs
            .evaluation
            .iter()
            .map(|&i| {
                let v = &data.views[i];
                let m = load_mask(&masks.dir, &stem(&v.camera.name))?;
                if m.len() != v.image.width * v.image.height {
                    return Err(Error::invalid(format!(
                        "the existing-pixel mask of '{}' does not have the view's size",
                        v.camera.name
                    ))
                    .at(&masks.dir));
                }
                Ok(m)
            })
            .collect::<Result<_>>()?;
        let mut steps = vec![masks.clone()];
        let mut rows = Vec::new();
        // Each scene's original ancestors along the chain original → stage 1 → stage 2 →
        // interpolation (`None` where a lineage is missing or the chain breaks).
        let mut ancestors: Option<Vec<u32>> = None;
        let mut previous: Option<Scene> = None;
        for (name, step) in scenes {
            ancestors = match (step, predecessor(*name)) {
                (None, _) if *name == Scene::Original => {
                    Some((0..inputs.scene.len() as u32).collect())
                }
                (Some(s), Some(p)) if previous == Some(p) => {
                    let file = s.dir.join(super::recon::LINEAGE_FILE);
                    match (&ancestors, file.is_file()) {
                        (Some(before), true) => {
                            let (_, lineage) = crate::io::npy::read_npy::<u32>(&file)?;
                            Some(compose(before, &lineage))
                        }
                        _ => None,
                    }
                }
                _ => None,
            };
            previous = Some(*name);
            if !self.wants(&Step::Eval(*name)) {
                continue;
            }
            let with_lineage = ancestors.as_deref().filter(|_| *name != Scene::Original);
            let name = name.name();
            let (scene, digest): (Gaussians, String) = match step {
                None => (inputs.scene.clone(), inputs.scene_sha256.clone()),
                Some(s) => (scene_of(s)?, s.digest.clone()),
            };
            // `records`: the metrics carry per-view sums, with GMSD's (a step cached before
            // they were recorded is not reused).
            let key = serde_json::json!({
                "scene": digest, "masks": masks.digest, "records": "per-view+gradients+lineage"
            });
            let st = self.step(&Step::Eval(name.parse()?), key, |w| {
                let mut row = score(inputs, &scene, name, &existing, w)?;
                if let Some(a) = with_lineage {
                    if a.len() != scene.len() {
                        return Err(Error::invalid(format!(
                            "the lineage of scene '{name}' lists {} Gaussians, its PLY {}",
                            a.len(),
                            scene.len()
                        )));
                    }
                    let opts = RenderOptions {
                        background: inputs.background,
                        ..RenderOptions::default()
                    };
                    let mut record = lineage_record(inputs, &scene, a, &opts)?;
                    if let Some(s) = step {
                        record.attribution = attribution_of(&s.dir)?;
                    }
                    row.lineage = Some(record);
                }
                w.json("metrics.json", &row)?;
                Ok(())
            })?;
            rows.push(read_json::<Row>(&st.dir.join("metrics.json"))?);
            steps.push(st);
        }
        let total: usize = existing.iter().map(|m| m.len()).sum();
        let ex: usize = existing
            .iter()
            .map(|m| m.iter().filter(|&&b| b).count())
            .sum();
        let summary = Summary {
            evaluation_views: inputs.evaluation.len(),
            existing_fraction: ex as f64 / total.max(1) as f64,
            rows,
        };
        Ok((summary, steps))
    }
}

fn score(
    inputs: &Inputs,
    scene: &Gaussians,
    name: &str,
    existing: &[Vec<bool>],
    w: &mut super::rundir::StepWriter,
) -> Result<Row> {
    let data = &inputs.data;
    let opts = RenderOptions {
        background: inputs.background,
        ..RenderOptions::default()
    };
    // Pool squared errors and SSIM values over all evaluation pixels of each class.
    let (mut se, mut n) = ([0f64; 3], [0usize; 3]);
    let (mut ss, mut sn) = ([0f64; 3], [0usize; 3]);
    let mut views = Vec::with_capacity(inputs.evaluation.len());
    for (k, &i) in inputs.evaluation.iter().enumerate() {
        let v = &data.views[i];
        let (wd, ht) = (v.image.width, v.image.height);
        let scored = ScoredView::new(scene, v, &opts)?;
        let (rgb, map) = (&scored.rgb, &scored.ssim);
        // The pooled sums run over all views in pixel order (their bits are the metrics'
        // since revision 1); the view's own sums beside them.
        let mut own = [ClassSums::default(); 3];
        for p in 0..wd * ht {
            let class = if existing[k][p] { 1 } else { 2 };
            for cls in [0, class] {
                for c in 0..3 {
                    let d = (rgb[p * 3 + c] - v.image.data[p * 3 + c].clamp(0.0, 1.0)) as f64;
                    se[cls] += d * d;
                }
                n[cls] += 3;
                ss[cls] += map[p];
                sn[cls] += 1;
                own[cls].add(&scored, p);
            }
        }
        let [all, existing_sums, extrapolated] = own;
        views.push(ViewRecord {
            view: v.camera.name.clone(),
            all,
            existing: existing_sums,
            extrapolated,
        });
        if k < 4 {
            let img = crate::eval::side_by_side(rgb, &v.image.data, wd, ht)?;
            w.put(&format!("{}.png", stem(&v.camera.name)), |p| {
                write_png(p, &img)
            })?;
        }
    }
    let psnr = |k: usize| {
        if n[k] == 0 {
            f64::NAN
        } else {
            -10.0 * (se[k] / n[k] as f64).log10()
        }
    };
    let ssim = |k: usize| {
        if sn[k] == 0 {
            f64::NAN
        } else {
            ss[k] / sn[k] as f64
        }
    };
    let (psnr_train_half, ssim_train_half) = train_half(inputs, scene, &opts)?;
    Ok(Row {
        scene: name.into(),
        psnr_all: psnr(0),
        psnr_existing: psnr(1),
        psnr_extrapolated: psnr(2),
        ssim_all: ssim(0),
        ssim_existing: ssim(1),
        ssim_extrapolated: ssim(2),
        psnr_train_half,
        ssim_train_half,
        gaussians: scene.len(),
        lineage: None,
        views,
    })
}

/// Mean PSNR and SSIM of `scene` over the training half's test views, as `unseen eval`
/// scores them (§14.7); NaN without test views.
fn train_half(inputs: &Inputs, scene: &Gaussians, opts: &RenderOptions) -> Result<(f64, f64)> {
    let data = &inputs.data;
    if data.test.is_empty() {
        return Ok((f64::NAN, f64::NAN));
    }
    let (mut tp, mut ts) = (0f64, 0f64);
    for &i in &data.test {
        let v = &data.views[i];
        let rgb: Vec<f32> = render(scene, &v.camera, opts)?
            .rgb
            .expect("rgb")
            .iter()
            .map(|x| x.clamp(0.0, 1.0))
            .collect();
        tp += crate::train::loss::psnr(&rgb, &v.image.data);
        ts +=
            crate::train::ssim::ssim(&rgb, &v.image.data, v.image.width, v.image.height, 3, false)
                .0;
    }
    let nt = data.test.len() as f64;
    Ok((tp / nt, ts / nt))
}

#[cfg(test)]
mod tests {
    use super::ClassSums;
    use crate::eval::GradientBlocks;

    /// An image against itself: every block's similarity is 1, GMSD 0 and the detail ratio
    /// 1; on odd sides every pixel of the image weighs its block once in all.
    #[test]
    fn gradient_blocks_of_an_image_against_itself() {
        for (w, h) in [(8, 6), (7, 5), (1, 1), (3, 2)] {
            let img: Vec<f32> = (0..w * h * 3)
                .map(|i| ((i * 37) % 101) as f32 / 100.0)
                .collect();
            let g = GradientBlocks::new(&img, &img, w, h);
            assert_eq!((g.width, g.height), (w.div_ceil(2), h.div_ceil(2)));
            assert!(g.similarity.iter().all(|&s| s == 1.0));
            let mut all = ClassSums::default();
            for p in 0..w * h {
                all.add_gradients(&g, p % w, p / w, w, h);
            }
            assert_eq!(all.gms_weight, (g.width * g.height) as f64, "{w}×{h}");
            assert_eq!(ClassSums::gmsd([&all]), 0.0);
            let flat = all.truth_gradient_energy == 0.0;
            assert!(flat || ClassSums::detail_ratio([&all]) == 1.0);
        }
    }
}
