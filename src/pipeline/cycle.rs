//! The generate–reconstruct–shift cycle (paper §1; SPEC.md §20.11): **not the paper's
//! method** but the baseline its hierarchical pipeline replaces, as the paradigm `cycle` so
//! that the audit can compare the two on the same inputs.
//!
//! Detection runs as in the paper's pipeline (step `views`); then the closed trajectory's
//! views — independent, dependent and gap cameras alike, in trajectory order — are visited
//! one at a time, one step `cycle/<k>` each: render the current scene at view `k`; the
//! mask `M` of pixels whose alpha is below `coverage_alpha`; when `M` holds a pixel, the
//! render inpainted on `M` (inpaint slot, key `cycle:<view>`), its depth by stage 2's
//! render fit (`Run::render_fit`: the depth slot's estimate least-squares fitted to the
//! render's expected depth where alpha exceeds 0.5) and new points from `M` as stage 1
//! makes them ([`unproject`], every `init_stride`-th pixel); then the current scene plus
//! the new points fine-tuned ([`Run::reconstruct`], random stream `cycle:<k>`) on the
//! original views and every view the cycle generated so far (with its depth prior),
//! weighted by the mask of the current scene (`qa/original` for the first view; later, its
//! QA-Mask fine-tuned inside the step, in `mask/`). The iterations are the full method's
//! total split evenly ([`split_iterations`]), each view's densification stage 1's scaled
//! ([`cycle_recon`]).

use super::Run;
use super::artifacts::{
    load_depth, load_image, save_depth, save_image, save_mask, save_scene, scene_of,
};
use super::config::{MaskSource, PipelineConfig, ReconConfig};
use super::depth::render_rgba;
use super::generators::SlotKind;
use super::recon::{self, Supervision, Weights, qa_config};
use super::rundir::StepDone;
use super::stage1::unproject;
use super::steps::{Scene, Step};
use super::views::Views;
use crate::camera::Camera;
use crate::error::{Error, Result};
use crate::qamask::read_mask_dir;
use crate::train::densify::DensifyConfig;
use crate::train::trainer::init_from_points;
use std::path::Path;

/// The full method's reconstruction iterations: stage 1's, stage 2's and, with the
/// interpolation on, the interpolation's.
pub fn total_iterations(config: &PipelineConfig) -> u64 {
    let interpolate = if config.interpolation {
        config.interpolate.iterations
    } else {
        0
    };
    u64::from(config.stage1.iterations)
        + u64::from(config.stage2.iterations)
        + u64::from(interpolate)
}

/// [`total_iterations`] over `views` cycle views as evenly as possible: the first
/// `total mod views` get one more.
pub fn split_iterations(config: &PipelineConfig, views: usize) -> Vec<u32> {
    let (total, n) = (total_iterations(config), views as u64);
    (0..n)
        .map(|k| u32::try_from(total / n + u64::from(k < total % n)).unwrap_or(u32::MAX))
        .collect()
}

/// One cycle view's reconstruction of `iterations`: stage 1's densification (the stage
/// that, as every cycle view does, adds new points) with its first and last iteration and
/// its opacity-reset interval scaled by `iterations / stage1.iterations` (rounded down):
/// the same part of each fine-tune densifies; the interval between densifications (the
/// gradient statistics each decision rests on) and the thresholds are stage 1's.
pub fn cycle_recon(config: &PipelineConfig, iterations: u32) -> ReconConfig {
    let base = config.stage1.iterations.max(1);
    let scale = |v: u32| (u64::from(v) * u64::from(iterations) / u64::from(base)) as u32;
    ReconConfig {
        iterations,
        densify: config.stage1.densify.map(|d| DensifyConfig {
            from_iter: scale(d.from_iter),
            until_iter: scale(d.until_iter),
            opacity_reset_interval: scale(d.opacity_reset_interval),
            ..d
        }),
    }
}

/// A cycle step's generated view (`inpaint.exr` and its depth in `dir`), `None` when the
/// view generated nothing (the scene covered it).
fn generated_view(camera: &Camera, dir: &Path) -> Result<Option<Supervision>> {
    if !dir.join("inpaint.exr").is_file() {
        return Ok(None);
    }
    let (wd, ht) = (camera.width as usize, camera.height as usize);
    Ok(Some(Supervision {
        camera: camera.clone(),
        image: load_image(dir, "inpaint")?,
        depth: Some(load_depth(dir, "inpaint", wd, ht)?),
        coverage: None,
    }))
}

impl Run<'_> {
    /// The cycle's steps that the scope selects (or verifies), in trajectory order, after
    /// the original scene's QA-Mask (the first view's weights), appended to `steps`; the
    /// last view's step when the scope reaches it.
    pub fn cycle(&self, views: &Views, steps: &mut Vec<StepDone>) -> Result<Option<StepDone>> {
        let inputs = self.inputs;
        let trajectory = &views.plan.trajectory;
        let first = if self.wants(&Step::QaMask(Scene::Original)) || self.wants(&Step::Cycle(0)) {
            let (weights, qa) =
                self.weights(&inputs.scene, &inputs.scene_sha256, Scene::Original)?;
            steps.extend(qa.iter().cloned());
            Some((weights, qa))
        } else {
            None
        };
        let iterations = split_iterations(self.config, trajectory.len());
        let mut done: Vec<StepDone> = Vec::new();
        for (k, name) in trajectory.iter().enumerate() {
            // The scope's cycle steps are a prefix of the chain (each reads the one before).
            if !self.wants(&Step::Cycle(k)) {
                break;
            }
            let trained_before = iterations[..k]
                .iter()
                .fold(0u32, |a, &b| a.saturating_add(b));
            let s = self.cycle_view(
                views,
                name,
                iterations[k],
                trained_before,
                &done,
                first.as_ref(),
            )?;
            steps.push(s.clone());
            done.push(s);
        }
        Ok(done
            .last()
            .filter(|_| done.len() == trajectory.len())
            .cloned())
    }

    /// Step `cycle/<k>` of view `name` (`k` = the steps `before` it): generation at the
    /// view from the current scene (the last of `before`'s, else the original), then the
    /// reconstruction on every view generated so far; `first`: the original scene's
    /// weights and their step.
    fn cycle_view(
        &self,
        views: &Views,
        name: &str,
        iterations: u32,
        trained_before: u32,
        before: &[StepDone],
        first: Option<&(Weights, Option<StepDone>)>,
    ) -> Result<StepDone> {
        let (config, inputs, gens) = (self.config, self.inputs, self.gens);
        let k = before.len();
        let step = Step::Cycle(k);
        let prev = before.last();
        let recon_config = cycle_recon(config, iterations);
        let qa_inside = k > 0 && config.mask_source == MaskSource::Qa;
        let upstream = serde_json::json!({
            "views": views.step.digest,
            "view": name,
            "index": k,
            "scene": prev.map_or(&inputs.scene_sha256, |p| &p.digest),
            "generated": before.iter().map(|s| &s.digest).collect::<Vec<_>>(),
            "slots": gens.key(config, &[SlotKind::Inpaint, SlotKind::Depth]),
            "coverage_alpha": config.coverage_alpha,
            "align_space": config.align_space,
            "init_stride": config.init_stride,
            "sh_degree": inputs.scene.sh_degree,
            "qa_mask": qa_inside.then(|| qa_config(config)),
        });
        let qa_step = first.and_then(|f| f.1.as_ref()).filter(|_| k == 0);
        let key = recon::recon_key(config, &recon_config, qa_step, upstream);
        self.step(&step, key, |w| {
            let camera = views.camera(name)?;
            let (wd, ht) = (camera.width as usize, camera.height as usize);
            let scene = match prev {
                None => inputs.scene.clone(),
                Some(p) => scene_of(p)?,
            };
            // The mask of the scene being updated.
            let own;
            let weights = if k == 0 {
                &first
                    .ok_or_else(|| Error::invalid("internal: the first cycle view has no weights"))?
                    .0
            } else {
                own = match config.mask_source {
                    MaskSource::Qa => {
                        self.write_qa_mask(&scene, &step.to_string(), "mask/", w)?;
                        Weights::Qa(Box::new(read_mask_dir(&w.dir().join("mask"))?))
                    }
                    MaskSource::Opacity => Weights::Opacity(scene.clone()),
                    MaskSource::None => Weights::None,
                };
                &own
            };
            let (rgb, alpha, ed) = render_rgba(&scene, camera, inputs.background)?;
            let mask: Vec<bool> = alpha.iter().map(|&a| a < config.coverage_alpha).collect();
            let masked = mask.iter().filter(|&&m| m).count();
            save_image(w, "render", &rgb)?;
            let mut init = scene;
            let mut record = serde_json::json!({
                "view": name,
                "index": k,
                "masked": masked,
                "generated": masked > 0,
                "iterations": iterations,
                "densify": recon_config.densify,
            });
            if masked > 0 {
                let inpainted = gens.inpaint(camera, &rgb, &mask, &format!("cycle:{name}"))?;
                let fit = self.render_fit(camera, &inpainted, &alpha, &ed)?;
                save_mask(w, "inpaint", &mask, wd, ht)?;
                save_image(w, "inpaint", &inpainted)?;
                save_depth(w, "inpaint", &fit.depth, wd, ht)?;
                let stride = config.init_stride as usize;
                let (xyz, rgb) = unproject(camera, &inpainted, &fit.depth, &mask, stride);
                if !xyz.is_empty() {
                    let g = init_from_points(&xyz, &rgb, inputs.scene.sh_degree)?;
                    save_scene(w, "points.ply", &g)?;
                    init.append(&g);
                }
                record["render_fit"] = fit.record;
                record["new_points"] = xyz.len().into();
            }
            // Every view generated so far in the cycle, this one last.
            let mut generated = Vec::new();
            for (j, s) in before.iter().enumerate() {
                let cam = views.camera(&views.plan.trajectory[j])?;
                generated.extend(generated_view(cam, &s.dir)?);
            }
            generated.extend(generated_view(camera, w.dir())?);
            record["supervised"] = generated
                .iter()
                .map(|g| g.camera.name.clone())
                .collect::<Vec<_>>()
                .into();
            let seed_key = format!("cycle:{k}");
            self.reconstruct(
                &recon_config,
                init,
                &generated,
                weights,
                None,
                &seed_key,
                trained_before,
                w,
            )?;
            w.json("cycle.json", &record)?;
            Ok(())
        })
    }
}
