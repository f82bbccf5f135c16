//! Stage 1 (paper §3.3.1, SPEC.md §20.3): parallel generation on the independent views.
//!
//! Per independent view `V_I^i` (step `stage1/<view>`, independent of the others, so a
//! batch engine can run them on different machines): its inpainting (detection's first);
//! the `video_sources` closest training views; one clip from each training image to the
//! inpainted image (video slot); the clip chosen by the seed gets video depth, aligned by
//! one RANSAC over all frames against the training depth DIBR-warped to every frame
//! (Eq. 5); `D_I` = the aligned last frame (Eq. 6); new points from the inpainted region
//! at `D_I` (every `init_stride`-th pixel).
//!
//! Step `stage1/propagate`: each dependent view receives the inpainted images of its gap's
//! two independent views, DIBR-warped with their `D_I` (the nearer surface wins); what
//! neither covers is the warp mask stage 2 inpaints.
//!
//! Step `stage1/recon`: the original scene plus the new points, fine-tuned on the original
//! views, the inpainted views, the clips' intermediate frames and the propagated views
//! ([`super::recon`]).

use super::Run;
use super::artifacts::{
    load_depth, load_image, load_mask, load_scene, save_depth, save_image, save_mask, save_scene,
    stem,
};
use super::clips::{align_clip, save_video, video_supervision};
use super::depth::training_depth;
use super::generators::SlotKind;
use super::poses::nearest_training;
use super::recon::{self, Supervision};
use super::rundir::StepDone;
use super::steps::{Scene, Step};
use super::views::Views;
use crate::camera::Camera;
use crate::error::{Error, Result};
use crate::io::image::ImageF32;
use crate::models::Keyframe;
use crate::rng::Uniform;
use crate::rng::stage_seed;
use crate::train::trainer::init_from_points;
use crate::warp::dibr::{WarpOptions, warp};
use rayon::prelude::*;
use std::path::Path;

/// Stage 1's results.
pub struct Stage1 {
    /// Per independent view, in `plan.independent` order.
    pub views: Vec<StepDone>,
    pub propagate: Option<StepDone>,
    pub recon: StepDone,
}

/// Pixels of `mask` every `stride`-th in x and y with a valid depth, unprojected to
/// world points with their colours.
pub fn unproject(
    cam: &Camera,
    image: &ImageF32,
    depth: &[f32],
    mask: &[bool],
    stride: usize,
) -> (Vec<[f32; 3]>, Vec<[f32; 3]>) {
    let (w, h) = (cam.width as usize, cam.height as usize);
    let (mut xyz, mut rgb) = (Vec::new(), Vec::new());
    for y in (0..h).step_by(stride) {
        for x in (0..w).step_by(stride) {
            let p = y * w + x;
            let z = depth[p] as f64;
            if !(mask[p] && z.is_finite() && z > 0.0) {
                continue;
            }
            let pw = cam.pixel_point(x, y, z);
            xyz.push([pw.x as f32, pw.y as f32, pw.z as f32]);
            let c = &image.data[p * 3..p * 3 + 3];
            rgb.push([c[0], c[1], c[2]]);
        }
    }
    (xyz, rgb)
}

impl Run<'_> {
    /// Stage 1's steps that the scope selects (or verifies), in order, appended to `steps`;
    /// the stage's results when the scope reaches its reconstruction.
    pub fn stage1(&self, views: &Views, steps: &mut Vec<StepDone>) -> Result<Option<Stage1>> {
        let (config, inputs) = (self.config, self.inputs);
        // The QA-Mask of the original scene and the per-view steps read nothing of each
        // other: each is attempted before any error stops the stage.
        let masked = self.wants(&Step::QaMask(Scene::Original)) || self.wants(&Step::Stage1Recon);
        let qa_result =
            masked.then(|| self.weights(&inputs.scene, &inputs.scene_sha256, Scene::Original));
        let per_view: Vec<Result<StepDone>> = views
            .plan
            .independent
            .par_iter()
            .filter(|name| self.wants(&Step::Independent(stem(name))))
            .map(|name| self.independent_view(views, name))
            // No short circuit: every view runs to its end; the first error in view order
            // is reported.
            .collect();
        let qa_result = qa_result.transpose()?;
        let per_view: Vec<StepDone> = per_view.into_iter().collect::<Result<_>>()?;
        if let Some((_, qa)) = &qa_result {
            steps.extend(qa.iter().cloned());
        }
        steps.extend(per_view.iter().cloned());
        let propagate = if self.wants(&Step::Propagate) {
            let s = self.propagate(views, &per_view)?;
            steps.push(s.clone());
            Some(s)
        } else {
            None
        };
        let Some((weights, qa)) = qa_result.filter(|_| self.wants(&Step::Stage1Recon)) else {
            return Ok(None);
        };
        let key = recon::recon_key(
            config,
            &config.stage1,
            qa.as_ref(),
            serde_json::json!({
                "scene": inputs.scene_sha256,
                "views": per_view.iter().map(|s| &s.digest).collect::<Vec<_>>(),
                "propagate": propagate.as_ref().map(|s| &s.digest),
            }),
        );
        let recon_step = self.step(&Step::Stage1Recon, key, |w| {
            let mut init = inputs.scene.clone();
            let mut generated = Vec::new();
            for (name, s) in views.plan.independent.iter().zip(&per_view) {
                let cam = views.camera(name)?;
                if s.dir.join("points.ply").is_file() {
                    let pts = load_scene(&s.dir, "points.ply")?;
                    init.append(&pts);
                }
                generated.extend(independent_supervision(cam, &s.dir)?);
            }
            if let Some(p) = &propagate {
                generated.extend(propagated_supervision(views, &p.dir)?);
            }
            self.reconstruct(
                &config.stage1,
                init,
                &generated,
                &weights,
                None,
                Scene::Stage1.name(),
                0,
                w,
            )?;
            Ok(())
        })?;
        steps.push(recon_step.clone());
        Ok(Some(Stage1 {
            views: per_view,
            propagate,
            recon: recon_step,
        }))
    }

    /// The per-view step of an independent view.
    fn independent_view(&self, views: &Views, name: &str) -> Result<StepDone> {
        let Run {
            config,
            inputs,
            gens,
            ..
        } = *self;
        let key = serde_json::json!({
            "views": views.step.digest,
            "view": name,
            "slots": gens.key(config, &[SlotKind::Video, SlotKind::VideoDepth]),
            "video_sources": config.video_sources,
            "video_frames": config.video_frames,
            "align_space": config.align_space,
            "ransac": [config.ransac_threshold, config.ransac_iterations as f64],
            "init_stride": config.init_stride,
            "sh_degree": inputs.scene.sh_degree,
            "seed": config.seed,
        });
        self.step(&Step::Independent(stem(name)), key, |w| {
        let cam = views.camera(name)?;
        let (wd, ht) = (cam.width as usize, cam.height as usize);
        let (ip, d0) = views.inpainting(name, 0)?;
        let mask = views.mask(name)?;
        let sources = nearest_training(&inputs.data, cam, config.video_sources as usize);
        // Clips the video slot cannot make (e.g. `morph` across a turn that sees neither
        // end) are recorded and left out; the seeded choice is among the clips made.
        let mut clips = Vec::new();
        let mut failed = Vec::new();
        for &src in &sources {
            let sv = &inputs.data.views[src];
            let sd = training_depth(inputs, src)?;
            match gens.video(
                Keyframe {
                    image: &sv.image,
                    camera: &sv.camera,
                    depth: Some(&sd),
                },
                Keyframe {
                    image: &ip,
                    camera: cam,
                    depth: Some(&d0),
                },
                config.video_frames as usize,
            ) {
                Ok(v) => clips.push((src, sd, v)),
                Err(e) if crate::models::morph::cannot_make_clip(&e) => failed.push(serde_json::json!({
                    "source": sv.camera.name,
                    "error": e.message,
                })),
                Err(e) => return Err(e),
            }
        }
        let mut rng = Uniform::new(stage_seed(config.seed, &format!("stage1:{name}")));
        let chosen = (!clips.is_empty()).then(|| rng.below(clips.len() as u32) as usize);
        let mut d_i: Option<Vec<f32>> = None;
        let mut align_record = None;
        for (k, (src, sd, video)) in clips.iter().enumerate() {
            let sv = &inputs.data.views[*src];
            let sd: &[f32] = sd;
            let mut aligned = None;
            if Some(k) == chosen {
                let (depths, a, space) =
                    align_clip(config, gens, video, sd, &sv.camera, &d0, cam, name).map_err(
                        |e| {
                            Error::invalid(format!(
                                "view '{name}': video depth alignment failed: {}",
                                e.message
                            ))
                        },
                    )?;
                d_i = depths.last().cloned();
                align_record = Some(serde_json::json!({
                    "source": sv.camera.name,
                    "space": space,
                    "alignment": a,
                }));
                aligned = Some(depths);
            }
            save_video(
                w,
                &format!("video_{k}"),
                &video.frames,
                &video.cameras,
                aligned.as_deref(),
            )?;
        }
        // No clip: D_I is detection's aligned depth of the inpainting (Eq. 3).
        let d_i = d_i.unwrap_or(d0);
        save_image(w, "inpaint", &ip)?;
        save_depth(w, "inpaint", &d_i, wd, ht)?;
        save_mask(w, "inpaint", &mask, wd, ht)?;
        let (xyz, rgb) = unproject(cam, &ip, &d_i, &mask, config.init_stride as usize);
        if !xyz.is_empty() {
            let g = init_from_points(&xyz, &rgb, inputs.scene.sh_degree)?;
            save_scene(w, "points.ply", &g)?;
        }
        w.json(
            "stage1.json",
            &serde_json::json!({
                "view": name,
                "sources": sources.iter().map(|&s| &inputs.data.views[s].camera.name).collect::<Vec<_>>(),
                "chosen": chosen,
                "failed_clips": failed,
                "alignment": align_record,
                "new_points": xyz.len(),
            }),
        )?;
        Ok(())
    })
    }
}

/// The supervision a stage-1 view step provides: the inpainted view (with `D_I`) and the
/// intermediate frames of its clips (with aligned depth for the chosen clip).
pub fn independent_supervision(cam: &Camera, dir: &Path) -> Result<Vec<Supervision>> {
    let (wd, ht) = (cam.width as usize, cam.height as usize);
    let mut out = vec![Supervision {
        camera: cam.clone(),
        image: load_image(dir, "inpaint")?,
        depth: Some(load_depth(dir, "inpaint", wd, ht)?),
        coverage: None,
    }];
    let mut k = 0;
    while dir.join(format!("video_{k}")).is_dir() {
        out.extend(video_supervision(&dir.join(format!("video_{k}")))?);
        k += 1;
    }
    Ok(out)
}

impl Run<'_> {
    /// DIBR propagation of the independent views to the dependent ones.
    fn propagate(&self, views: &Views, per_view: &[StepDone]) -> Result<StepDone> {
        let key = serde_json::json!({
            "views": views.step.digest,
            "independent": per_view.iter().map(|s| &s.digest).collect::<Vec<_>>(),
        });
        self.step(&Step::Propagate, key, |w| {
            let source = |name: &str| -> Result<(&Camera, ImageF32, Vec<f32>)> {
                let k = views
                    .plan
                    .independent
                    .iter()
                    .position(|n| n == name)
                    .ok_or_else(|| Error::invalid(format!("'{name}' is not independent")))?;
                let cam = views.camera(name)?;
                let d = &per_view[k].dir;
                Ok((
                    cam,
                    load_image(d, "inpaint")?,
                    load_depth(d, "inpaint", cam.width as usize, cam.height as usize)?,
                ))
            };
            for dep in &views.plan.dependent {
                let to = views.camera(&dep.name)?;
                let (wd, ht) = (to.width as usize, to.height as usize);
                let mut image = ImageF32::new(wd, ht, 3, vec![0.0; wd * ht * 3])?;
                let mut depth = vec![0f32; wd * ht];
                let mut ends = vec![dep.between[0].as_str()];
                if dep.between[1] != dep.between[0] {
                    ends.push(dep.between[1].as_str());
                }
                for e in ends {
                    let (from, img, d) = source(e)?;
                    let wp = warp(
                        &img,
                        &d,
                        from,
                        to,
                        &WarpOptions {
                            close_cracks: 1,
                            ..WarpOptions::default()
                        },
                    )?;
                    #[allow(clippy::needless_range_loop)]
                    for p in 0..wd * ht {
                        let z = wp.depth[p];
                        if !wp.holes[p] && z > 0.0 && (depth[p] == 0.0 || z < depth[p]) {
                            depth[p] = z;
                            image.data[p * 3..p * 3 + 3]
                                .copy_from_slice(&wp.image.data[p * 3..p * 3 + 3]);
                        }
                    }
                }
                let covered: Vec<bool> = depth.iter().map(|&z| z > 0.0).collect();
                let s = stem(&dep.name);
                save_image(w, &format!("{s}/warped"), &image)?;
                save_depth(w, &format!("{s}/warped"), &depth, wd, ht)?;
                save_mask(w, &format!("{s}/covered"), &covered, wd, ht)?;
            }
            Ok(())
        })
    }
}

/// The propagated views as supervision (weighted by coverage).
pub fn propagated_supervision(views: &Views, dir: &Path) -> Result<Vec<Supervision>> {
    views
        .plan
        .dependent
        .iter()
        .map(|dep| {
            let cam = views.camera(&dep.name)?;
            let d = dir.join(stem(&dep.name));
            let covered = load_mask(&d, "covered")?;
            Ok(Supervision {
                camera: cam.clone(),
                image: load_image(&d, "warped")?,
                depth: Some(load_depth(
                    &d,
                    "warped",
                    cam.width as usize,
                    cam.height as usize,
                )?),
                coverage: Some(covered),
            })
        })
        .collect::<Result<Vec<_>>>()
        .map(|v| {
            v.into_iter()
                .filter(|s| s.coverage.as_ref().is_some_and(|c| c.iter().any(|&x| x)))
                .collect()
        })
}
