//! Interpolation by video reuse (paper §3.3.3, SPEC.md §20.5).
//!
//! Step `interpolate/fixer`: render the stage-2 scene at every trajectory keyframe and at
//! every intermediate pose of the stage-2 clips and pass each render through the fixer
//! slot. Step `interpolate/recon`: the stage-2 scene fine-tuned on the original views,
//! the trajectory keyframes, the intermediate frames of every clip of both stages (the
//! reused videos) and the fixer outputs, weighted by the mask of the stage-2 scene.
//!
//! Deviation: the paper adds the fixer outputs "on the fly" during the final training; we
//! fix the renders of the stage-2 scene once, before it (SPEC.md §20.5 says why).

use super::Run;
use super::artifacts::{load_image, save_image, scene_of, stem};
use super::clips::{load_video, video_supervision};
use super::depth::render_rgb;
use super::generators::SlotKind;
use super::recon::{self, Refresh, Supervision};
use super::rundir::StepDone;
use super::stage1::{Stage1, independent_supervision};
use super::stage2::made_clips;
use super::stage2::{Stage2, keyframes, neighbour_pairs};
use super::steps::{Scene, Step};
use super::views::Views;
use crate::error::Result;
use std::collections::BTreeMap;

pub struct Interpolation {
    pub fixer: StepDone,
    pub recon: StepDone,
}

impl Run<'_> {
    /// The interpolation stage's steps that the scope selects (or verifies) — the fixer, the
    /// stage-2 scene's QA-Mask, the reconstruction — appended to `steps`; its results when
    /// the scope reaches its reconstruction.
    pub fn interpolate(
        &self,
        views: &Views,
        s1: &Stage1,
        s2: &Stage2,
        steps: &mut Vec<StepDone>,
    ) -> Result<Option<Interpolation>> {
        let (config, inputs, gens) = (self.config, self.inputs, self.gens);
        let ours = [
            Step::Fixer,
            Step::QaMask(Scene::Stage2),
            Step::Interpolation,
        ];
        if !ours.iter().any(|s| self.wants(s)) {
            return Ok(None);
        }
        let s2_scene = scene_of(&s2.recon)?;
        let keys = keyframes(views, s1, s2.dependent.as_ref())?;
        let pairs = neighbour_pairs(keys.len());
        let fkey = serde_json::json!({
            "stage2": s2.recon.digest,
            "videos": s2.videos.digest,
            "slots": gens.key(config, &[SlotKind::Fixer]),
        });
        let fixer = self
            .wants(&Step::Fixer)
            .then(|| {
                self.step(&Step::Fixer, fkey, |w| {
                    // The fixer poses, in order: the keyframes, then each clip's intermediate frames.
                    let mut cams: Vec<crate::camera::Camera> = Vec::new();
                    for k in &keys {
                        let rgb = render_rgb(&s2_scene, &k.camera, inputs.background)?;
                        let fixed = gens.fix(&k.camera, &rgb, None)?;
                        save_image(w, &format!("{}/render", stem(&k.camera.name)), &rgb)?;
                        save_image(w, &format!("{}/fixed", stem(&k.camera.name)), &fixed)?;
                        cams.push(k.camera.clone());
                    }
                    for p in made_clips(&s2.videos, pairs.len())? {
                        let (a, b) = pairs[p];
                        let v = load_video(&s2.videos.dir.join(format!("video_{p}")))?;
                        let n = v.cameras.len();
                        for j in 1..n.saturating_sub(1) {
                            let cam = &v.cameras[j];
                            let rgb = render_rgb(&s2_scene, cam, inputs.background)?;
                            let fixed = gens.fix(
                                cam,
                                &rgb,
                                Some((&keys[a].camera, &keys[b].camera, j, n)),
                            )?;
                            save_image(w, &format!("{}/render", stem(&cam.name)), &rgb)?;
                            save_image(w, &format!("{}/fixed", stem(&cam.name)), &fixed)?;
                            cams.push(cam.clone());
                        }
                    }
                    let text = crate::camera::inria::cameras_json_string(&cams);
                    w.put("cameras.json", |p| crate::io::write_text(p, &text))?;
                    Ok(())
                })
            })
            .transpose()?;
        steps.extend(fixer.iter().cloned());
        if !(self.wants(&Step::QaMask(Scene::Stage2)) || self.wants(&Step::Interpolation)) {
            return Ok(None);
        }
        let (weights, qa) = self.weights(&s2_scene, &s2.recon.digest, Scene::Stage2)?;
        steps.extend(qa.iter().cloned());
        let Some(fixer) = fixer.filter(|_| self.wants(&Step::Interpolation)) else {
            return Ok(None);
        };
        // What the reconstruction reads besides the stage-2 scene and its mask.
        let upstream = serde_json::json!({
            "stage2": s2.recon.digest,
            "fixer": fixer.digest,
            "stage1_views": s1.views.iter().map(|s| &s.digest).collect::<Vec<_>>(),
            "videos": s2.videos.digest,
            "fixer_every": config.fixer_every,
            "slots": gens.key(config, &[SlotKind::Fixer]),
        });
        let rkey = recon::recon_key(config, &config.interpolate, qa.as_ref(), upstream);
        let recon_step = self.step(&Step::Interpolation, rkey, |w| {
            let mut generated: Vec<Supervision> = Vec::new();
            for (name, s) in views.plan.independent.iter().zip(&s1.views) {
                // The inpainted view itself is a keyframe below; keep its clips' frames.
                let sup = independent_supervision(views.camera(name)?, &s.dir)?;
                generated.extend(sup.into_iter().skip(1));
            }
            for k in made_clips(&s2.videos, pairs.len())? {
                generated.extend(video_supervision(
                    &s2.videos.dir.join(format!("video_{k}")),
                )?);
            }
            for k in &keys {
                generated.push(Supervision {
                    camera: k.camera.clone(),
                    image: k.image.clone(),
                    depth: Some(k.depth.clone()),
                    coverage: None,
                });
            }
            // Where each fixer pose lies (for the truth slot): a keyframe, or frame j of n
            // of the clip between keyframes a and b.
            let mut between: BTreeMap<String, (usize, usize, usize, usize)> = BTreeMap::new();
            for p in made_clips(&s2.videos, pairs.len())? {
                let (a, b) = pairs[p];
                let v = load_video(&s2.videos.dir.join(format!("video_{p}")))?;
                let n = v.cameras.len();
                for (j, c) in v.cameras.iter().enumerate() {
                    between.insert(c.name.clone(), (a, b, j, n));
                }
            }
            let cams = crate::camera::inria::read_cameras_json(&fixer.dir.join("cameras.json"))?;
            let first_fixed = generated.len();
            for c in cams {
                generated.push(Supervision {
                    image: load_image(&fixer.dir.join(stem(&c.name)), "fixed")?,
                    camera: c,
                    depth: None,
                    coverage: None,
                });
            }
            let fix = |cam: &crate::camera::Camera, render: &crate::io::image::ImageF32| {
                let b = between
                    .get(&cam.name)
                    .map(|&(a, b, j, n)| (&keys[a].camera, &keys[b].camera, j, n));
                gens.fix(cam, render, b)
            };
            let refresh = Refresh {
                views: (first_fixed..generated.len()).collect(),
                every: config.fixer_every,
                fix: &fix,
            };
            self.reconstruct(
                &config.interpolate,
                s2_scene.clone(),
                &generated,
                &weights,
                Some(&refresh),
                Scene::Interpolate.name(),
                config
                    .stage1
                    .iterations
                    .saturating_add(config.stage2.iterations),
                w,
            )?;
            Ok(())
        })?;
        steps.push(recon_step.clone());
        Ok(Some(Interpolation {
            fixer,
            recon: recon_step,
        }))
    }
}
