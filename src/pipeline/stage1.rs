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

use super::artifacts::{
    load_depth, load_image, load_mask, load_scene, save_depth, save_image, save_mask, save_scene,
    stem,
};
use super::generators::{Generators, SlotKind};
use super::poses::nearest_training;
use super::recon::{self, Supervision, reconstruct};
use super::rundir::StepDone;
use super::steps::Step;
use super::views::{Views, apply_alignment, training_depth, warp_depth};
use super::{PipelineConfig, StageCtx};
use crate::camera::Camera;
use crate::camera::inria::{cameras_json_string, read_cameras_json};
use crate::error::{Error, Result};
use crate::io::image::ImageF32;
use crate::io::write_text;
use crate::models::{DepthHint, Keyframe, Video};
use crate::rng::Uniform;
use crate::rng::stage_seed;
use crate::train::trainer::init_from_points;
use crate::warp::align::{Alignment, Frame, RansacConfig, Space, ransac};
use crate::warp::dibr::{WarpOptions, warp};
use rayon::prelude::*;
use std::path::Path;

/// Stage 1's steps and results.
pub struct Stage1 {
    pub steps: Vec<StepDone>,
    /// Per independent view, in `plan.independent` order.
    pub views: Vec<StepDone>,
    pub propagate: Option<StepDone>,
    pub recon: StepDone,
}

/// A clip as stored: `video_<k>/frame_<j>.exr` (+ `.depth.exr`), `video_<k>/cameras.json`.
pub struct StoredVideo {
    pub frames: Vec<ImageF32>,
    pub cameras: Vec<Camera>,
    /// Aligned metric depth per frame, when known.
    pub depths: Option<Vec<Vec<f32>>>,
}

pub(crate) fn save_video(
    w: &mut super::rundir::StepWriter,
    dir: &str,
    frames: &[ImageF32],
    cameras: &[Camera],
    depths: Option<&[Vec<f32>]>,
) -> Result<()> {
    for (j, f) in frames.iter().enumerate() {
        save_image(w, &format!("{dir}/frame_{j:02}"), f)?;
        if let Some(d) = depths {
            save_depth(w, &format!("{dir}/frame_{j:02}"), &d[j], f.width, f.height)?;
        }
    }
    let text = cameras_json_string(cameras);
    w.put(&format!("{dir}/cameras.json"), |p| write_text(p, &text))?;
    Ok(())
}

pub(crate) fn load_video(dir: &Path) -> Result<StoredVideo> {
    let cameras = read_cameras_json(&dir.join("cameras.json"))?;
    let mut frames = Vec::new();
    let mut depths = Vec::new();
    let mut all_depth = true;
    for (j, c) in cameras.iter().enumerate() {
        let s = format!("frame_{j:02}");
        frames.push(load_image(dir, &s)?);
        if dir.join(format!("{s}.depth.exr")).is_file() {
            depths.push(load_depth(dir, &s, c.width as usize, c.height as usize)?);
        } else {
            all_depth = false;
        }
    }
    Ok(StoredVideo {
        frames,
        cameras,
        depths: all_depth.then_some(depths),
    })
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
    let r = cam.world_from_camera_rotation;
    let (mut xyz, mut rgb) = (Vec::new(), Vec::new());
    for y in (0..h).step_by(stride) {
        for x in (0..w).step_by(stride) {
            let p = y * w + x;
            let z = depth[p] as f64;
            if !(mask[p] && z.is_finite() && z > 0.0) {
                continue;
            }
            let xc = ((x as f64 + 0.5) - cam.cx) / cam.fx * z;
            let yc = ((y as f64 + 0.5) - cam.cy) / cam.fy * z;
            let pw = r * glam::DVec3::new(xc, yc, z) + cam.center;
            xyz.push([pw.x as f32, pw.y as f32, pw.z as f32]);
            let c = &image.data[p * 3..p * 3 + 3];
            rgb.push([c[0], c[1], c[2]]);
        }
    }
    (xyz, rgb)
}

/// Run stage 1 (or verify it on disk).
pub fn run(ctx: &StageCtx, gens: &Generators, views: &Views) -> Result<Stage1> {
    let StageCtx {
        config,
        inputs,
        dir,
        on_event,
    } = *ctx;
    // The QA-Mask of the original scene and the per-view steps read nothing of each other:
    // each is attempted before any error stops the stage, so `--only` any one of them
    // needs only detection (an out-of-scope sibling's "not done" ends the run once the
    // target is done).
    let qa_result = recon::weights(ctx, &inputs.scene, &inputs.scene_sha256, "original");
    let per_view: Vec<Result<StepDone>> = views
        .plan
        .independent
        .par_iter()
        .map(|name| independent_view(ctx, gens, views, name))
        // No short circuit: every view runs to its end; the first error in view order is
        // reported.
        .collect();
    let (weights, qa) = qa_result?;
    let per_view: Vec<StepDone> = per_view.into_iter().collect::<Result<_>>()?;
    let mut steps: Vec<StepDone> = qa.iter().cloned().collect();
    steps.extend(per_view.iter().cloned());
    let propagate = if config.propagation && !views.plan.dependent.is_empty() {
        let s = propagate(ctx, views, &per_view)?;
        steps.push(s.clone());
        Some(s)
    } else {
        None
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
    let recon_step = dir.step(&Step::Stage1Recon, key, on_event, |w| {
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
        reconstruct(
            ctx,
            &config.stage1,
            init,
            &generated,
            &weights,
            None,
            "stage1",
            w,
        )?;
        Ok(())
    })?;
    steps.push(recon_step.clone());
    Ok(Stage1 {
        steps,
        views: per_view,
        propagate,
        recon: recon_step,
    })
}

/// The per-view step of an independent view.
fn independent_view(
    ctx: &StageCtx,
    gens: &Generators,
    views: &Views,
    name: &str,
) -> Result<StepDone> {
    let StageCtx {
        config,
        inputs,
        dir,
        on_event,
    } = *ctx;
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
    dir.step(&Step::Independent(stem(name)), key, on_event, |w| {
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

/// The start of [`align_clip`]'s error when the clip's depth admits no fit (too few valid
/// pixels, degenerate estimates): a caller with another depth to fall back on matches it.
const NO_ALIGNMENT: &str = "the clip's video depth admits no alignment";

/// DIBR-based video depth alignment (paper §3.3.1, Eq. 5–6) of one clip from a training
/// view (`start_depth`: its dense depth at `start_cam`) to a generated view (`end_cam`,
/// whose current depth `end_depth` is only a hint): video depth of every frame, aligned by
/// one RANSAC over all frames against the start depth DIBR-warped to every frame. Returns
/// the aligned metric depth of every frame (the last is the generated view's `D`), the
/// fit and its space. `view` names the generated view in the RANSAC seed.
#[allow(clippy::too_many_arguments)]
pub(crate) fn align_clip(
    config: &PipelineConfig,
    gens: &Generators,
    video: &Video,
    start_depth: &[f32],
    start_cam: &Camera,
    end_depth: &[f32],
    end_cam: &Camera,
    view: &str,
) -> Result<(Vec<Vec<f32>>, Alignment, Space)> {
    // Eq. 5's target: the start frame's depth warped to every frame.
    let targets: Vec<Vec<f32>> = video
        .cameras
        .iter()
        .map(|c| warp_depth(start_depth, start_cam, c))
        .collect::<Result<_>>()?;
    // What the caller knows of each frame, for estimators that extend known depth: the
    // start frame's warped depth, else the end keyframe's warped there. Only the former
    // is Eq. 5's target.
    let known: Vec<Vec<f32>> = video
        .cameras
        .iter()
        .zip(&targets)
        .map(|(c, t)| {
            let end = warp_depth(end_depth, end_cam, c)?;
            Ok(t.iter()
                .zip(&end)
                .map(|(&a, &b)| if a > 0.0 { a } else { b })
                .collect())
        })
        .collect::<Result<_>>()?;
    let hints: Vec<DepthHint> = known
        .iter()
        .map(|t| DepthHint {
            depth: t,
            mask: None,
        })
        .collect();
    let est = gens.video_depth(video, &hints)?;
    let space = config.align_space.unwrap_or(est[0].kind.space());
    let frames: Vec<Frame> = est
        .iter()
        .zip(&targets)
        .map(|(e, t)| Frame {
            estimate: &e.values,
            depth: t,
        })
        .collect();
    let a = ransac(
        &frames,
        space,
        &RansacConfig {
            threshold: config.ransac_threshold,
            iterations: config.ransac_iterations,
            seed: stage_seed(config.seed, &format!("ransac:{view}")),
            ..RansacConfig::default()
        },
    )
    .map_err(|e| Error::degenerate(format!("{NO_ALIGNMENT}: {}", e.message)))?;
    let depths = est.iter().map(|e| apply_alignment(e, &a, space)).collect();
    Ok((depths, a, space))
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

/// The intermediate frames of a stored clip (the end frames are views already).
pub fn video_supervision(dir: &Path) -> Result<Vec<Supervision>> {
    let v = load_video(dir)?;
    let n = v.frames.len();
    Ok((1..n.saturating_sub(1))
        .map(|j| Supervision {
            camera: v.cameras[j].clone(),
            image: v.frames[j].clone(),
            depth: v.depths.as_ref().map(|d| d[j].clone()),
            coverage: None,
        })
        .collect())
}

/// DIBR propagation of the independent views to the dependent ones.
fn propagate(ctx: &StageCtx, views: &Views, per_view: &[StepDone]) -> Result<StepDone> {
    let StageCtx { dir, on_event, .. } = *ctx;
    let key = serde_json::json!({
        "views": views.step.digest,
        "independent": per_view.iter().map(|s| &s.digest).collect::<Vec<_>>(),
    });
    dir.step(&Step::Propagate, key, on_event, |w| {
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
