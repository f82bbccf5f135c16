//! The reconstruction every stage ends with (SPEC.md §20.5): fine-tune a scene on the
//! original training views (full weight; their dataset depth only under the non-paper
//! switch `original_view_depth`) plus generated views weighted per pixel by the mask of
//! the scene being updated (paper Eq. 7) and, where a generated view only partly holds
//! content (DIBR propagation), by its coverage; depth supervision (Eq. 7's third term)
//! applies to the generated views' depth priors.
//!
//! The weights apply to the *generated* supervision only: a mask computed on the original
//! scene is ≈ 0 on the original views, so weighting them would silence the data the scene
//! came from (the issue's §6).

use super::artifacts::{save_scene, stem};
use super::config::{DensifyScope, FineTuneRates, MaskSource, PipelineConfig, ReconConfig};
use super::rundir::{StepDone, StepWriter};
use super::steps::{Scene, Step};
use super::{Event, Inputs, Run};
use crate::camera::Camera;
use crate::dataset::{Dataset, View};
use crate::error::{Error, Result};
use crate::gaussian::Gaussians;
use crate::io::image::ImageF32;
use crate::qamask::{
    QaMaskConfig, fine_tune, mask_files, mask_scene, opacity_mask, read_mask_dir, render_qa_mask,
};
use crate::rng::stage_seed;
use crate::train::trainer::{LearningRates, TrainConfig, Trainer, ViewShare};

/// A reconstruction's lineage (`uint32`, one per Gaussian of its `scene.ply`): the index of
/// the starting Gaussian (the scene it fine-tunes, then the points it appended) each
/// descends from through densification.
pub const LINEAGE_FILE: &str = "lineage.npy";

/// The key of a reconstruction's `supervision.json` that holds its
/// [`crate::train::attribution::AttributionRecord`] (when it trained on generated views).
pub const ATTRIBUTION_KEY: &str = "attribution";

/// One generated view for a reconstruction.
#[derive(Clone, Debug)]
pub struct Supervision {
    pub camera: Camera,
    pub image: ImageF32,
    /// Metric camera-z depth (0 = unknown), supervised when depth supervision is on.
    pub depth: Option<Vec<f32>>,
    /// Pixels that hold generated content (`None`: all).
    pub coverage: Option<Vec<bool>>,
}

/// The mask that weights generated views in a reconstruction of `scene`.
pub enum Weights {
    Qa(Box<(Gaussians, QaMaskConfig)>),
    Opacity(Gaussians),
    None,
}

impl Weights {
    /// The per-pixel weight at `cam` (`None` = all ones).
    pub fn at(&self, cam: &Camera) -> Result<Option<Vec<f32>>> {
        Ok(match self {
            Weights::Qa(q) => Some(render_qa_mask(&q.0, cam, &q.1)?),
            Weights::Opacity(g) => Some(opacity_mask(g, cam)?),
            Weights::None => None,
        })
    }
}

/// The QA-Mask settings of a pipeline.
pub fn qa_config(config: &PipelineConfig) -> QaMaskConfig {
    QaMaskConfig {
        sh_degree: config.qa_sh_degree,
        iterations: config.qa_iterations,
        seed: config.seed,
        ..QaMaskConfig::default()
    }
}

impl Run<'_> {
    /// The weights for a reconstruction of `scene` (its digest `scene_digest`): the
    /// QA-Mask is fine-tuned in its own step `qa/<name>` (shared by every variant with the
    /// same scene and QA settings).
    pub fn weights(
        &self,
        scene: &Gaussians,
        scene_digest: &str,
        name: Scene,
    ) -> Result<(Weights, Option<StepDone>)> {
        let config = self.config;
        match config.mask_source {
            MaskSource::None => Ok((Weights::None, None)),
            MaskSource::Opacity => Ok((Weights::Opacity(scene.clone()), None)),
            MaskSource::Qa => {
                let qa = qa_config(config);
                let qa_step = Step::QaMask(name);
                let key = serde_json::json!({"scene": scene_digest, "qa": qa});
                let step = self.step(&qa_step, key, |w| {
                    self.write_qa_mask(scene, &qa_step.to_string(), "", w)
                })?;
                let (g, c) = read_mask_dir(&step.dir)?;
                Ok((Weights::Qa(Box::new((g, c))), Some(step)))
            }
        }
    }

    /// Fine-tune the QA-Mask of `scene` on the training cameras and write its mask
    /// directory's files (`point_cloud.ply`, `qa_mask.json`) under `prefix` of `w` (whose
    /// manifest closes them; progress as `step_name`): what [`read_mask_dir`] reads.
    pub fn write_qa_mask(
        &self,
        scene: &Gaussians,
        step_name: &str,
        prefix: &str,
        w: &mut StepWriter,
    ) -> Result<()> {
        let (on_event, qa) = (self.on_event, qa_config(self.config));
        let views: Vec<Camera> = self.inputs.data.train_cameras();
        let mut g = mask_scene(scene, &qa)?;
        fine_tune(&mut g, &views, &qa, &mut |p| {
            if p.iteration % 50 == 0 || p.iteration == p.iterations {
                on_event(Event::Iterations {
                    step: step_name.to_string(),
                    done: p.iteration,
                    total: p.iterations,
                    loss: p.loss,
                });
            }
        })?;
        let (ply, text) = mask_files(&g, &qa)?;
        w.put(&format!("{prefix}point_cloud.ply"), |p| {
            crate::io::write_atomic(p, |f| std::io::Write::write_all(f, &ply))
        })?;
        w.put(&format!("{prefix}qa_mask.json"), |p| {
            crate::io::write_text(p, &text)
        })?;
        Ok(())
    }
}

/// The key of a reconstruction step: `upstream` (the digests of the steps it reads) with
/// the settings every reconstruction depends on — the weights' step, the mask source, the
/// loss, the reconstruction settings and the seed.
pub fn recon_key(
    config: &PipelineConfig,
    recon: &ReconConfig,
    qa: Option<&StepDone>,
    upstream: serde_json::Value,
) -> serde_json::Value {
    let mut key = upstream;
    let m = key.as_object_mut().expect("upstream digests are an object");
    m.insert("qa".into(), serde_json::json!(qa.map(|s| &s.digest)));
    m.insert("mask_source".into(), serde_json::json!(config.mask_source));
    m.insert("loss".into(), serde_json::json!(config.recon_loss()));
    m.insert(
        "original_view_depth".into(),
        serde_json::json!(config.supervises_original_depth()),
    );
    m.insert("recon".into(), serde_json::json!(recon));
    m.insert("seed".into(), serde_json::json!(config.seed));
    // The fine-tune choices the paper leaves open, only away from their defaults (keys
    // made before them keep their bytes).
    if config.fine_tune_rates != FineTuneRates::Restart {
        m.insert(
            "fine_tune_rates".into(),
            serde_json::json!(config.fine_tune_rates),
        );
    }
    if let Some(share) = config.original_share {
        m.insert("original_share".into(), serde_json::json!(share));
    }
    if !config.generated_supervision {
        m.insert("generated_supervision".into(), serde_json::json!(false));
    }
    if config.attribution {
        m.insert("attribution".into(), serde_json::json!(true));
    }
    if config.densify_scope != DensifyScope::All {
        m.insert(
            "densify_scope".into(),
            serde_json::json!(config.densify_scope),
        );
    }
    key
}

/// Generated views whose targets are remade from the scene being trained (paper §3.3.3:
/// the fixer's outputs of the current renders, added on the fly).
pub struct Refresh<'f> {
    /// Indices into the `generated` list of [`Run::reconstruct`].
    pub views: Vec<usize>,
    /// The targets are remade before iterations `1 + k·every`, `k ≥ 1`.
    pub every: u32,
    /// Current render at a camera → new target.
    pub fix: &'f (dyn Fn(&Camera, &ImageF32) -> Result<ImageF32> + Sync),
}

/// The original training views a reconstruction trains on: image and camera, and their
/// dataset depth only under the non-paper switch (`supervises_original_depth`).
pub fn original_views(config: &PipelineConfig, inputs: &Inputs) -> Vec<View> {
    let keep = config.supervises_original_depth();
    inputs
        .data
        .train
        .iter()
        .map(|&i| {
            let v = &inputs.data.views[i];
            View {
                camera: v.camera.clone(),
                image: v.image.clone(),
                depth: v.depth.clone().filter(|_| keep),
            }
        })
        .collect()
}

impl Run<'_> {
    /// Fine-tune `init` on the original training views and `generated` (with `refresh`, some
    /// of whose targets are remade on the fly), write `scene.ply` and the weight maps' heat
    /// images into `w`; returns the scene. `stage` names its random stream
    /// `stage_seed(seed, stage)` and its progress: a scene's name (`stage1`, `stage2`,
    /// `interpolate`) or the cycle paradigm's `cycle:<k>`; `trained_before`: the iterations
    /// this pipeline's earlier reconstructions trained the scene (where a continued
    /// schedule starts, after the original's).
    #[allow(clippy::too_many_arguments)]
    pub fn reconstruct(
        &self,
        recon: &ReconConfig,
        init: Gaussians,
        generated: &[Supervision],
        weights: &Weights,
        refresh: Option<&Refresh>,
        stage: &str,
        trained_before: u32,
        w: &mut StepWriter,
    ) -> Result<Gaussians> {
        let (config, inputs, on_event) = (self.config, self.inputs, self.on_event);
        // The recipe's control (`generated_supervision` off): the original views alone.
        let (generated, refresh) = if config.generated_supervision {
            (generated, refresh)
        } else {
            (&[][..], None)
        };
        let mut views = original_views(config, inputs);
        let n_orig = views.len();
        let mut masks: Vec<Option<Vec<f32>>> = vec![None; n_orig];
        let mut summary = Vec::new();
        let mut pictures = std::collections::BTreeSet::new();
        for g in generated {
            let n = (g.camera.width * g.camera.height) as usize;
            if g.image.data.len() != n * 3 {
                return Err(Error::invalid(format!(
                    "generated view '{}' is not an RGB image of its camera's size",
                    g.camera.name
                )));
            }
            let mut m = weights.at(&g.camera)?;
            if let Some(cov) = &g.coverage {
                let m = m.get_or_insert_with(|| vec![1.0; n]);
                for (v, &c) in m.iter_mut().zip(cov) {
                    if !c {
                        *v = 0.0;
                    }
                }
            }
            let mean = m
                .as_ref()
                .map_or(1.0, |m| m.iter().map(|&v| v as f64).sum::<f64>() / n as f64);
            // One picture per camera (a camera supervised twice, e.g. a keyframe and its
            // fixed render, has one weight map).
            let pic = format!("weights/{}.png", stem(&g.camera.name));
            if let Some(m) = m.as_ref().filter(|_| !pictures.contains(&pic)) {
                pictures.insert(pic.clone());
                let heat = ImageF32::new(
                    g.camera.width as usize,
                    g.camera.height as usize,
                    3,
                    crate::qamask::heat_map(m),
                )?;
                w.put(&pic, |p| crate::io::image::write_png(p, &heat))?;
            }
            summary.push(serde_json::json!({
                "view": g.camera.name,
                "mean_weight": mean,
                "depth": g.depth.is_some() && config.depth_supervision,
            }));
            masks.push(m);
            views.push(View {
                camera: g.camera.clone(),
                image: g.image.clone(),
                depth: if config.depth_supervision {
                    g.depth.clone()
                } else {
                    None
                },
            });
        }
        let data = Dataset {
            root: inputs.data.root.clone(),
            layout: inputs.data.layout,
            train: (0..views.len()).collect(),
            views,
            points: None,
            test: Vec::new(),
            heldout: Vec::new(),
        };
        let position_offset = config.position_offset(inputs.scene_iterations, trained_before);
        let cfg = TrainConfig {
            iterations: recon.iterations,
            seed: stage_seed(config.seed, stage),
            sh_degree: init.sh_degree,
            // Limited to what the pipeline added: the original scene's Gaussians lead every
            // scene it makes under this scope (appended points follow; densification keeps
            // protected ones first).
            densify: recon.densify.map(|d| crate::train::densify::DensifyConfig {
                protected: match config.densify_scope {
                    DensifyScope::All => 0,
                    DensifyScope::Added => inputs.scene.len(),
                },
                ..d
            }),
            loss: config.recon_loss(),
            background: inputs.background,
            save_iterations: Vec::new(),
            lr: LearningRates {
                position_offset,
                ..LearningRates::default()
            },
            view_share: config.original_share.map(|share| ViewShare {
                views: n_orig,
                share,
            }),
            ..TrainConfig::default()
        };
        let deg = init.sh_degree;
        let mut trainer = Trainer::from_gaussians(&data, cfg, init, deg)?;
        trainer.masks = masks;
        trainer.track_lineage();
        if config.attribution {
            // Which views' gradients move the Gaussians (§20.5): the generated views follow
            // the originals in the dataset.
            trainer.track_attribution((0..data.views.len()).map(|v| v >= n_orig).collect())?;
        }
        let mut refreshed = 0u32;
        while trainer.iteration < recon.iterations {
            if let Some(r) = refresh {
                let it = trainer.iteration;
                if it > 0 && r.every > 0 && it % r.every == 0 {
                    for &k in &r.views {
                        let cam = &generated[k].camera;
                        let rgb =
                            super::depth::render_rgb(&trainer.gaussians, cam, inputs.background)?;
                        trainer.replace_image(n_orig + k, (r.fix)(cam, &rgb)?)?;
                    }
                    refreshed += 1;
                }
            }
            let p = trainer.step()?;
            if p.iteration % 50 == 0 || p.iteration == p.iterations {
                on_event(Event::Iterations {
                    step: stage.to_string(),
                    done: p.iteration,
                    total: p.iterations,
                    loss: p.loss_ema,
                });
            }
        }
        if let Some(r) = refresh {
            // The targets the last part trained on, for people and for a port's diff.
            for &k in &r.views {
                let img = trainer.dataset.views[n_orig + k].image.clone();
                let rel = format!("refreshed/{}.png", stem(&generated[k].camera.name));
                w.put(&rel, |p| crate::io::image::write_png(p, &img))?;
            }
        }
        let lineage = trainer.lineage.take().expect("tracked");
        let attribution = trainer.attribution.take();
        let g = trainer.gaussians;
        save_scene(w, "scene.ply", &g)?;
        // Per Gaussian of the scene, the index in `init` it descends from (§20.5).
        w.put(LINEAGE_FILE, |p| {
            crate::io::npy::write_npy(p, &lineage, &[lineage.len()]).map(|_| ())
        })?;
        let mut supervision = serde_json::json!({
            "original_views": n_orig,
            "original_views_depth": config.supervises_original_depth(),
            "generated": summary,
            "iterations": recon.iterations,
            "refreshed": refreshed,
            "gaussians": g.len(),
        });
        if !config.generated_supervision {
            supervision["generated_supervision"] = serde_json::json!(false);
        }
        if let Some(a) = attribution.filter(|_| n_orig < data.views.len()) {
            a.check(&g)?;
            let all: Vec<usize> = (0..g.len()).collect();
            supervision[ATTRIBUTION_KEY] = serde_json::json!(a.record(&all));
        }
        if let Some(share) = config.original_share {
            supervision["original_share"] = serde_json::json!(share);
        }
        if position_offset > 0 {
            // Only when the schedule continues: earlier runs' files keep their bytes.
            supervision["position_offset"] = serde_json::json!(position_offset);
        }
        w.json("supervision.json", &supervision)?;
        Ok(g)
    }
}
