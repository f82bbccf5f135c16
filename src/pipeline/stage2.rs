//! Stage 2 (paper §3.3.2, SPEC.md §20.4): residual completion on the dependent views.
//!
//! Step `stage2/dependent`: render the stage-1 scene at every dependent view; inpaint its
//! warp mask (what DIBR propagation did not cover; without propagation, the pixels the
//! stage-1 scene leaves below `coverage_alpha`); its depth by the paper's DIBR-based video
//! depth alignment (a clip from the nearest training view to the inpainted view, aligned
//! as stage 1 aligns its chosen clip: [`super::clips::align_clip`]), with the depth slot's
//! estimate least-squares fitted to the stage-1 render's expected depth (alpha > 0.5) as
//! the clip's end-keyframe hint — and as the depth itself where no clip can be made or
//! aligned, or under the labelled deviation `stage2_depth: render_fit`. Every view's
//! method and fit: `dependent.json`.
//! Step `stage2/videos`: a clip between every two neighbours of the closed trajectory.
//! Step `stage2/recon`: the stage-1 scene fine-tuned on the original views, every
//! trajectory keyframe and the clips' intermediate frames, weighted by the mask of the
//! stage-1 scene.

use super::Run;
use super::artifacts::{
    load_depth, load_image, load_mask, read_json, save_depth, save_image, save_mask, scene_of, stem,
};
use super::clips::{align_clip, save_video, video_supervision};
use super::config::Stage2Depth;
use super::depth::{MIN_ALIGN_PIXELS, apply_alignment, render_rgba, training_depth};
use super::generators::SlotKind;
use super::poses::nearest_training;
use super::recon::{self, Supervision};
use super::rundir::{StepDone, StepWriter};
use super::stage1::Stage1;
use super::steps::{Scene, Step};
use super::views::{Dependent, Views};
use crate::camera::Camera;
use crate::error::{Error, ErrorKind, Result};
use crate::gaussian::Gaussians;
use crate::io::image::ImageF32;
use crate::models::{DepthHint, Keyframe};
use crate::warp::align::{Alignment, Frame, Space, least_squares};
use std::path::PathBuf;

/// Stage 2's results.
pub struct Stage2 {
    pub dependent: Option<StepDone>,
    pub videos: StepDone,
    pub recon: StepDone,
}

/// A trajectory keyframe: camera, image and metric depth.
pub struct Keyview {
    pub camera: Camera,
    pub image: ImageF32,
    pub depth: Vec<f32>,
}

/// The closed trajectory's keyframes, in order: independent views from stage 1, dependent
/// views from `stage2/dependent`.
pub fn keyframes(views: &Views, s1: &Stage1, dependent: Option<&StepDone>) -> Result<Vec<Keyview>> {
    views
        .plan
        .trajectory
        .iter()
        .map(|name| {
            let cam = views.camera(name)?.clone();
            let (wd, ht) = (cam.width as usize, cam.height as usize);
            let dir: PathBuf = match views.plan.independent.iter().position(|n| n == name) {
                Some(k) => s1.views[k].dir.clone(),
                None => dependent
                    .ok_or_else(|| Error::invalid("no dependent step"))?
                    .dir
                    .join(stem(name)),
            };
            Ok(Keyview {
                image: load_image(&dir, "inpaint")?,
                depth: load_depth(&dir, "inpaint", wd, ht)?,
                camera: cam,
            })
        })
        .collect()
}

/// Neighbour pairs of the closed trajectory (one pair for two views, none for one).
pub fn neighbour_pairs(n: usize) -> Vec<(usize, usize)> {
    match n {
        0 | 1 => Vec::new(),
        2 => vec![(0, 1)],
        _ => (0..n).map(|k| (k, (k + 1) % n)).collect(),
    }
}

/// A view's depth fitted to the render of the scene it extends (a dependent view's: the
/// stage-1 scene's), and how (`space`, `alignment`).
pub(super) struct RenderFit {
    pub depth: Vec<f32>,
    pub record: serde_json::Value,
}

impl Run<'_> {
    /// Stage 2's steps that the scope selects (or verifies) — the dependent views, the
    /// trajectory's clips, the stage-1 scene's QA-Mask, the reconstruction — appended to
    /// `steps`; the stage's results when the scope reaches its reconstruction.
    pub fn stage2(
        &self,
        views: &Views,
        s1: &Stage1,
        steps: &mut Vec<StepDone>,
    ) -> Result<Option<Stage2>> {
        let config = self.config;
        let ours = [
            Step::Dependent,
            Step::Videos,
            Step::QaMask(Scene::Stage1),
            Step::Stage2Recon,
        ];
        if !ours.iter().any(|s| self.wants(s)) {
            return Ok(None);
        }
        let s1_scene = scene_of(&s1.recon)?;
        let dependent = if self.wants(&Step::Dependent) {
            self.dependent_step(views, s1, &s1_scene)?
        } else {
            None
        };
        steps.extend(dependent.iter().cloned());
        let clips = if self.wants(&Step::Videos) {
            let keys = keyframes(views, s1, dependent.as_ref())?;
            let pairs = neighbour_pairs(keys.len());
            let videos = self.videos_step(views, s1, dependent.as_ref(), &keys, &pairs)?;
            steps.push(videos.clone());
            Some((keys, pairs, videos))
        } else {
            None
        };
        if !(self.wants(&Step::QaMask(Scene::Stage1)) || self.wants(&Step::Stage2Recon)) {
            return Ok(None);
        }
        let (weights, qa) = self.weights(&s1_scene, &s1.recon.digest, Scene::Stage1)?;
        steps.extend(qa.iter().cloned());
        let Some((keys, pairs, videos)) = clips.filter(|_| self.wants(&Step::Stage2Recon)) else {
            return Ok(None);
        };
        // What the reconstruction reads besides the stage-1 scene and its mask.
        let upstream = serde_json::json!({
            "stage1": s1.recon.digest,
            "videos": videos.digest,
            "dependent": dependent.as_ref().map(|s| &s.digest),
        });
        let rkey = recon::recon_key(config, &config.stage2, qa.as_ref(), upstream);
        let recon_step = self.step(&Step::Stage2Recon, rkey, |w| {
            let mut generated: Vec<Supervision> = keys
                .iter()
                .map(|k| Supervision {
                    camera: k.camera.clone(),
                    image: k.image.clone(),
                    depth: Some(k.depth.clone()),
                    coverage: None,
                })
                .collect();
            for k in made_clips(&videos, pairs.len())? {
                generated.extend(video_supervision(&videos.dir.join(format!("video_{k}")))?);
            }
            self.reconstruct(
                &config.stage2,
                s1_scene.clone(),
                &generated,
                &weights,
                None,
                Scene::Stage2.name(),
                config.stage1.iterations,
                w,
            )?;
            Ok(())
        })?;
        steps.push(recon_step.clone());
        Ok(Some(Stage2 {
            dependent,
            videos,
            recon: recon_step,
        }))
    }

    /// Step `stage2/dependent` (none without dependent views): every dependent view inpainted
    /// and given its depth (`complete_dependent`), the methods in `dependent.json`.
    fn dependent_step(
        &self,
        views: &Views,
        s1: &Stage1,
        s1_scene: &Gaussians,
    ) -> Result<Option<StepDone>> {
        let (config, gens) = (self.config, self.gens);
        if views.plan.dependent.is_empty() {
            return Ok(None);
        }
        let key = serde_json::json!({
            "views": views.step.digest,
            "stage1": s1.recon.digest,
            "propagate": s1.propagate.as_ref().map(|s| &s.digest),
            "slots": gens.key(config, &[SlotKind::Inpaint, SlotKind::Depth, SlotKind::Video, SlotKind::VideoDepth]),
            "coverage_alpha": config.coverage_alpha,
            "align_space": config.align_space,
            "stage2_depth": config.stage2_depth,
            "video_frames": config.video_frames,
            "ransac": [config.ransac_threshold, config.ransac_iterations as f64],
            "seed": config.seed,
        });
        let step = self.step(&Step::Dependent, key, |w| {
            let mut records = Vec::new();
            for dep in &views.plan.dependent {
                records.push(self.complete_dependent(views, s1, s1_scene, dep, w)?);
            }
            w.json("dependent.json", &serde_json::json!({ "views": records }))?;
            Ok(())
        })?;
        Ok(Some(step))
    }

    /// One dependent view `dep`: the stage-1 render, its gap inpainted and the gap's depth;
    /// writes them (and the clip of the depth's video alignment) to `w`; returns the view's
    /// record of how its depth was made.
    fn complete_dependent(
        &self,
        views: &Views,
        s1: &Stage1,
        s1_scene: &Gaussians,
        dep: &Dependent,
        w: &mut StepWriter,
    ) -> Result<serde_json::Value> {
        let (config, inputs, gens) = (self.config, self.inputs, self.gens);
        let camera = views.camera(&dep.name)?;
        let (width, height) = (camera.width as usize, camera.height as usize);
        let (rgb, alpha, ed) = render_rgba(s1_scene, camera, inputs.background)?;
        // The un-extrapolated gap: what the stage-1 scene does not cover and, with
        // propagation, what no warp of an independent view reached either.
        let uncovered = alpha.iter().map(|&a| a < config.coverage_alpha);
        let mask: Vec<bool> = match &s1.propagate {
            Some(p) => load_mask(&p.dir.join(stem(&dep.name)), "covered")?
                .iter()
                .zip(uncovered)
                .map(|(&c, u)| !c && u)
                .collect(),
            None => uncovered.collect(),
        };
        let inpainted = if mask.iter().any(|&m| m) {
            gens.inpaint(camera, &rgb, &mask, &format!("stage2:{}", dep.name))?
        } else {
            rgb.clone()
        };
        let fit = self.render_fit(camera, &inpainted, &alpha, &ed)?;
        let s = stem(&dep.name);
        // The paper's depth (§3.3: DIBR-based video depth alignment throughout): a clip from
        // the nearest training view to the inpainted view; the render fit is its end
        // keyframe's depth hint, and the depth itself where no clip can be made or aligned
        // (recorded).
        let (depth, record) = match config.stage2_depth {
            Stage2Depth::RenderFit => (
                fit.depth,
                serde_json::json!({"view": dep.name, "method": "render_fit", "render_fit": fit.record}),
            ),
            Stage2Depth::Video => self.video_depth(camera, &inpainted, fit, w)?,
        };
        save_image(w, &format!("{s}/render"), &rgb)?;
        save_mask(w, &format!("{s}/inpaint"), &mask, width, height)?;
        save_image(w, &format!("{s}/inpaint"), &inpainted)?;
        save_depth(w, &format!("{s}/inpaint"), &depth, width, height)?;
        Ok(record)
    }

    /// The depth slot's estimate of an inpainted dependent view (at `camera`),
    /// least-squares fitted to the stage-1 render's expected depth `ed` where the render is
    /// opaque (`alpha` > 0.5); the cycle paradigm's depth of every view, fitted to the
    /// render of the current scene.
    pub(super) fn render_fit(
        &self,
        camera: &Camera,
        inpainted: &ImageF32,
        alpha: &[f32],
        ed: &[f32],
    ) -> Result<RenderFit> {
        let (config, gens) = (self.config, self.gens);
        let known: Vec<f32> = ed
            .iter()
            .zip(alpha)
            .map(|(&d, &a)| if a > 0.5 { d } else { 0.0 })
            .collect();
        let estimate = gens.depth(
            camera,
            inpainted,
            DepthHint {
                depth: &known,
                mask: None,
            },
        )?;
        let space = config.align_space.unwrap_or(estimate.kind.space());
        // As in detection (§20.2): too little known depth and a depth-kind estimate → used as
        // it is; a disparity estimate cannot be.
        let known_px = known.iter().filter(|&&d| d > 0.0).count();
        let alignment = if known_px < MIN_ALIGN_PIXELS && space == Space::Depth {
            Alignment::identity(known_px)
        } else {
            least_squares(
                &[Frame {
                    estimate: &estimate.values,
                    depth: &known,
                }],
                space,
            )
            .map_err(|e| {
                Error::invalid(format!(
                    "view '{}': cannot align its depth to the render of the scene it extends ({})",
                    camera.name, e.message
                ))
            })?
        };
        Ok(RenderFit {
            depth: apply_alignment(&estimate, &alignment, space),
            record: serde_json::json!({"space": space, "alignment": alignment}),
        })
    }

    /// The paper's depth of an inpainted dependent view (at `camera`): a clip from the
    /// nearest training view to it, its depth aligned as stage 1 aligns a clip, the last
    /// frame's depth; the clip is written to `w`. Where no clip can be made or aligned, the
    /// render fit, with the reason recorded.
    fn video_depth(
        &self,
        camera: &Camera,
        inpainted: &ImageF32,
        fit: RenderFit,
        w: &mut StepWriter,
    ) -> Result<(Vec<f32>, serde_json::Value)> {
        let (config, inputs, gens) = (self.config, self.inputs, self.gens);
        let name = &camera.name;
        let source = nearest_training(&inputs.data, camera, 1)[0];
        let sv = &inputs.data.views[source];
        let source_depth = training_depth(inputs, source)?;
        let clip = gens.video(
            Keyframe {
                image: &sv.image,
                camera: &sv.camera,
                depth: Some(&source_depth),
            },
            Keyframe {
                image: inpainted,
                camera,
                depth: Some(&fit.depth),
            },
            config.video_frames as usize,
        );
        let aligned = match clip {
            Ok(v) => align_clip(
                config,
                gens,
                &v,
                &source_depth,
                &sv.camera,
                &fit.depth,
                camera,
                &format!("stage2:{name}"),
            )
            .map(|r| (v, r)),
            Err(e) if !crate::models::morph::cannot_make_clip(&e) => return Err(e),
            Err(e) => Err(e),
        };
        match aligned {
            Ok((v, (depths, alignment, space))) => {
                save_video(
                    w,
                    &format!("{}/video", stem(name)),
                    &v.frames,
                    &v.cameras,
                    Some(&depths),
                )?;
                let last = depths.last().cloned().expect("a clip has frames");
                let record = serde_json::json!({
                    "view": name,
                    "method": "video",
                    "source": sv.camera.name,
                    "space": space,
                    "alignment": alignment,
                    "render_fit": fit.record,
                });
                Ok((last, record))
            }
            // No clip, or no alignment of its depth: the render fit.
            Err(e) if e.kind == ErrorKind::Degenerate => {
                let record = serde_json::json!({
                    "view": name,
                    "method": "render_fit",
                    "source": sv.camera.name,
                    "video_failed": e.message,
                    "render_fit": fit.record,
                });
                Ok((fit.depth, record))
            }
            Err(e) => Err(e),
        }
    }

    /// Step `stage2/videos`: a clip between every two neighbours of the closed trajectory
    /// `keys` (`pairs`); a clip the video slot cannot make (`morph` across a turn where an
    /// intermediate camera sees neither end) is recorded and left out, as in stage 1.
    fn videos_step(
        &self,
        views: &Views,
        s1: &Stage1,
        dependent: Option<&StepDone>,
        keys: &[Keyview],
        pairs: &[(usize, usize)],
    ) -> Result<StepDone> {
        let (config, gens) = (self.config, self.gens);
        let key = serde_json::json!({
            "views": views.step.digest,
            "stage1": s1.views.iter().map(|s| &s.digest).collect::<Vec<_>>(),
            "dependent": dependent.map(|s| &s.digest),
            "slots": gens.key(config, &[SlotKind::Video]),
            "video_frames": config.video_frames,
        });
        self.step(&Step::Videos, key, |w| {
        let (mut made, mut failed) = (Vec::new(), Vec::new());
        for (k, &(a, b)) in pairs.iter().enumerate() {
            let (ka, kb) = (&keys[a], &keys[b]);
            let v = match gens.video(
                Keyframe {
                    image: &ka.image,
                    camera: &ka.camera,
                    depth: Some(&ka.depth),
                },
                Keyframe {
                    image: &kb.image,
                    camera: &kb.camera,
                    depth: Some(&kb.depth),
                },
                config.video_frames as usize,
            ) {
                Ok(v) => v,
                Err(e) if crate::models::morph::cannot_make_clip(&e) => {
                    failed.push(serde_json::json!({
                        "pair": [&ka.camera.name, &kb.camera.name],
                        "error": e.message,
                    }));
                    continue;
                }
                Err(e) => return Err(e),
            };
            save_video(
                w,
                &format!("video_{k}"),
                &v.frames,
                &v.cameras,
                v.depths.as_deref(),
            )?;
            made.push(k);
        }
        w.json(
            "videos.json",
            &serde_json::json!({
                "pairs": pairs.iter().map(|&(a, b)| [&keys[a].camera.name, &keys[b].camera.name]).collect::<Vec<_>>(),
                "made": made,
                "failed_clips": failed,
            }),
        )?;
        Ok(())
    })
    }
}

/// The indices (into the neighbour pairs) of the clips `stage2/videos` made, from its
/// `videos.json` (one written before clips could fail has no `made` list: every clip was
/// made).
pub fn made_clips(videos: &StepDone, pairs: usize) -> Result<Vec<usize>> {
    let path = videos.dir.join("videos.json");
    let list: serde_json::Value = read_json(&path)?;
    let Some(made) = list.get("made") else {
        return Ok((0..pairs).collect());
    };
    let made = made
        .as_array()
        .ok_or_else(|| Error::parse(&path, "\"made\" is not a list of clips"))?;
    made.iter()
        .map(|k| match k.as_u64() {
            Some(k) if (k as usize) < pairs => Ok(k as usize),
            _ => Err(Error::parse(
                &path,
                format!("clip index {k} is not one of the {pairs} pairs"),
            )),
        })
        .collect()
}
