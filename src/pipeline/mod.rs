//! The paper's system (SPEC.md §20): from a trained scene and candidate extrapolation views
//! to an extrapolated scene, one module per stage —
//!
//! | stage | module | paper |
//! |---|---|---|
//! | independent view detection | [`views`] | §3.2 |
//! | parallel generation on independent views, DIBR propagation, reconstruction | [`stage1`] | §3.3.1 |
//! | residual completion on dependent views | [`stage2`] | §3.3.2 |
//! | interpolation by video reuse and the fixer | [`interpolate`] | §3.3.3 |
//!
//! with [`recon`] (the QA-Mask-weighted reconstruction every stage ends with), [`evaluate`]
//! (existing / extrapolated PSNR and SSIM on evaluation poses), [`generators`] (slots and
//! the ground-truth generator) and [`rundir`] (the resumable, content-addressed run
//! directory). Nothing below this module imports it. Progress arrives as [`Event`]s, so
//! a command line only draws them.

pub mod artifacts;
pub mod audit;
pub mod compare;
pub mod config;
pub mod evaluate;
pub mod generators;
pub mod interpolate;
pub mod recon;
pub mod report;
pub mod rundir;
pub mod stage1;
pub mod stage2;
pub mod views;

pub use config::{
    Hallucination, Inconsistency, Level, MaskSource, PipelineConfig, ReconConfig, SlotNames,
    Stage2Depth, TruthDepth,
};

use crate::camera::Camera;
use crate::camera::inria::read_cameras_json;
use crate::dataset::{Dataset, downscale_camera};
use crate::error::{Error, Result};
use crate::gaussian::Gaussians;
use crate::gaussian::ply::read_ply;
use crate::io::sha256_hex;
use crate::train::run::{latest_ply, load_dataset, read_config, read_train_views};
pub use artifacts::stem;
use generators::{Generators, GroundTruth, Truth};
pub use rundir::Scope;
use rundir::{RunDir, StepDone};
use std::path::{Path, PathBuf};

/// Progress of a run, for a progress display or a log.
#[derive(Clone, Debug, PartialEq)]
pub enum Event {
    /// A stage (views, stage1, stage2, interpolate, eval) begins.
    Stage {
        name: String,
    },
    StepStarted {
        step: String,
    },
    StepFinished {
        step: String,
        seconds: f64,
    },
    /// Verified on disk (`--resume`).
    StepSkipped {
        step: String,
    },
    /// Copied from the step cache (computed by another run with the same inputs).
    StepCached {
        step: String,
    },
    /// Iterations of a reconstruction or QA-Mask fine-tune.
    Iterations {
        step: String,
        done: u32,
        total: u32,
        loss: f64,
    },
    /// A line worth showing.
    Note(String),
}

/// What every stage of a run reads, carried by reference: the configuration, the inputs,
/// the run directory (with its step cache) and where progress events go.
#[derive(Clone, Copy)]
pub struct StageCtx<'a> {
    pub config: &'a PipelineConfig,
    pub inputs: &'a Inputs,
    pub dir: &'a RunDir,
    pub on_event: &'a (dyn Fn(Event) + Sync),
}

/// What the pipeline starts from.
pub struct Inputs {
    /// The `unseen train` run (the original scene).
    pub run: PathBuf,
    pub scene: Gaussians,
    /// sha256 of the scene's PLY bytes.
    pub scene_sha256: String,
    /// The run's dataset at its resolution; `train` lists the run's training views.
    pub data: Dataset,
    /// Candidate extrapolation cameras at the run's resolution.
    pub candidates: Vec<Camera>,
    /// sha256 of the candidates' cameras.json bytes.
    pub candidates_sha256: String,
    /// Evaluation poses (indices into `data.views`, with truth); may be empty.
    pub evaluation: Vec<usize>,
    pub background: [f32; 3],
    /// sha256 of everything above that a step may read (scene, cameras, images, depths,
    /// splits, background) and of the crate and conventions versions: part of every
    /// step's key (SPEC.md §20.8).
    pub digest: String,
}

/// The digest of [`Inputs`]: every view's camera, image and depth bits, the splits, the
/// scene and candidates' file hashes, the background, the versions.
fn inputs_digest(
    data: &Dataset,
    scene_sha256: &str,
    candidates: &[Camera],
    evaluation: &[usize],
    background: [f32; 3],
) -> String {
    use sha2::{Digest, Sha256};
    let mut h = Sha256::new();
    let text = |h: &mut Sha256, s: &str| {
        h.update((s.len() as u64).to_le_bytes());
        h.update(s.as_bytes());
    };
    let floats = |h: &mut Sha256, v: &[f32]| {
        h.update((v.len() as u64).to_le_bytes());
        for x in v {
            h.update(x.to_bits().to_le_bytes());
        }
    };
    text(&mut h, env!("CARGO_PKG_VERSION"));
    h.update(crate::version::CONVENTIONS_VERSION.to_le_bytes());
    h.update(crate::version::NUMERICS_REVISION.to_le_bytes());
    text(&mut h, scene_sha256);
    text(
        &mut h,
        &crate::camera::inria::cameras_json_string(candidates),
    );
    floats(&mut h, &background);
    for v in &data.views {
        text(
            &mut h,
            &crate::camera::inria::cameras_json_string(std::slice::from_ref(&v.camera)),
        );
        floats(&mut h, &v.image.data);
        floats(&mut h, v.depth.as_deref().unwrap_or(&[]));
    }
    for list in [&data.train, &data.test, &data.heldout, &evaluation.to_vec()] {
        h.update((list.len() as u64).to_le_bytes());
        for &i in list.iter() {
            h.update((i as u64).to_le_bytes());
        }
    }
    h.finalize().iter().map(|b| format!("{b:02x}")).collect()
}

/// Load a run, its dataset (from the run's manifest unless `dataset` is given), the
/// candidate cameras and, optionally, the evaluation cameras (their truth must be in the
/// dataset).
pub fn load_inputs(
    run: &Path,
    candidates: &Path,
    evaluation: Option<&Path>,
    dataset: Option<&Path>,
) -> Result<Inputs> {
    if !run.join("config.json").is_file() {
        return Err(Error::invalid("not an `unseen train` run directory (no config.json)").at(run));
    }
    crate::train::run::require_default_conventions(run, "the pipeline")?;
    let cfg = read_config(run)?;
    let (_, ply) = latest_ply(run)?;
    let bytes = std::fs::read(&ply).map_err(|e| Error::io(&ply, e))?;
    let scene_sha256 = sha256_hex(&bytes);
    // The scene must be the one the run wrote (a reused folder may hold a newer-numbered
    // PLY of another run).
    let manifest = crate::io::manifest::Manifest::read(run)?;
    let rel = ply.strip_prefix(run).unwrap_or(&ply).display().to_string();
    if !manifest
        .files
        .iter()
        .any(|f| f.path == rel && f.sha256 == scene_sha256)
    {
        return Err(Error::invalid(
            "this PLY is not the one the run's manifest.json lists (a stale file of another run?)",
        )
        .at(&ply));
    }
    let (scene, _) = read_ply(&ply)?;
    if scene.is_empty() {
        return Err(Error::invalid("the scene has no Gaussians").at(&ply));
    }
    let data_dir = match dataset {
        Some(d) => d.to_path_buf(),
        None => {
            let m = crate::io::manifest::Manifest::read(run)?;
            PathBuf::from(
                m.inputs
                    .get("dataset")
                    .and_then(|d| d.as_str())
                    .ok_or_else(|| {
                        Error::parse(
                            &run.join("manifest.json"),
                            "no \"dataset\" path (pass --dataset)",
                        )
                    })?,
            )
        }
    };
    let mut data = load_dataset(&data_dir, &cfg)?;
    let names = read_train_views(run)?;
    let train: Vec<usize> = names
        .iter()
        .map(|n| {
            data.views
                .iter()
                .position(|v| &v.camera.name == n)
                .ok_or_else(|| {
                    Error::invalid(format!(
                        "training view '{n}' of the run is not in the dataset"
                    ))
                    .at(&data_dir)
                })
        })
        .collect::<Result<_>>()?;
    data.train = train;
    let cand_bytes = std::fs::read(candidates).map_err(|e| Error::io(candidates, e))?;
    let cands: Vec<Camera> = read_cameras_json(candidates)?
        .iter()
        .map(|c| downscale_camera(c, cfg.resolution))
        .collect();
    if cands.is_empty() {
        return Err(Error::invalid("the view list is empty").at(candidates));
    }
    for (i, c) in cands.iter().enumerate() {
        if c.name.is_empty() || RESERVED_VIEW_NAMES.contains(&c.name.as_str()) {
            return Err(Error::invalid(format!(
                "candidate {i} has the name '{}', which is empty or reserved ({})",
                c.name,
                RESERVED_VIEW_NAMES.join(", ")
            ))
            .at(candidates));
        }
        if cands[..i].iter().any(|d| d.name == c.name) {
            return Err(
                Error::invalid(format!("candidate '{}' is listed twice", c.name)).at(candidates),
            );
        }
        c.validate().map_err(|e| e.at(candidates))?;
    }
    let mut eval_idx = Vec::new();
    if let Some(e) = evaluation {
        for c in read_cameras_json(e)? {
            let i = data
                .views
                .iter()
                .position(|v| v.camera.name == c.name)
                .ok_or_else(|| {
                    Error::invalid(format!(
                        "evaluation view '{}' has no ground truth in the dataset",
                        c.name
                    ))
                    .at(e)
                })?;
            if cands.iter().any(|k| k.name == c.name) || data.train.contains(&i) {
                return Err(Error::invalid(format!(
                    "evaluation view '{}' is also a candidate or training view",
                    c.name
                ))
                .at(e));
            }
            if data.views[i].depth.is_none() {
                return Err(Error::invalid(format!(
                    "evaluation view '{}' has no ground-truth depth (needed to split existing and extrapolated pixels)",
                    c.name
                ))
                .at(e));
            }
            eval_idx.push(i);
        }
    }
    let digest = inputs_digest(&data, &scene_sha256, &cands, &eval_idx, cfg.background);
    Ok(Inputs {
        run: run.to_path_buf(),
        scene,
        scene_sha256,
        data,
        candidates: cands,
        candidates_sha256: sha256_hex(&cand_bytes),
        evaluation: eval_idx,
        background: cfg.background,
        digest,
    })
}

/// The truth of the candidate views, from the dataset (for the ground-truth generator).
/// Whether two cameras have the same pose (centre within 1e-9, rotation entries within
/// 1e-9): what "the same view" means for candidates (SPEC.md §20.2).
pub fn same_pose(a: &Camera, b: &Camera) -> bool {
    (a.center - b.center).length() < 1e-9
        && a.world_from_camera_rotation
            .abs_diff_eq(b.world_from_camera_rotation, 1e-9)
}

pub fn candidate_truth(inputs: &Inputs) -> Result<Vec<Truth>> {
    inputs
        .candidates
        .iter()
        .map(|c| {
            let v = inputs
                .data
                .views
                .iter()
                .find(|v| v.camera.name == c.name)
                .ok_or_else(|| {
                    Error::invalid(format!(
                        "the ground-truth generator needs candidate '{}' in the dataset",
                        c.name
                    ))
                })?;
            if (v.camera.width, v.camera.height) != (c.width, c.height) || !same_pose(&v.camera, c) {
                return Err(Error::invalid(format!(
                    "candidate '{}' differs in size or pose from the dataset's view of that name: the ground-truth generator cannot use its truth",
                    c.name
                ))
                .at(&inputs.data.root));
            }
            let depth = v.depth.clone().ok_or_else(|| {
                Error::invalid(format!(
                    "the ground-truth generator needs the depth of candidate '{}'",
                    c.name
                ))
            })?;
            Ok(Truth {
                camera: c.clone(),
                image: v.image.clone(),
                depth,
            })
        })
        .collect()
}

/// The training views' cameras and depths, from which the hallucinating ground-truth
/// generator tells seen content from unseen (empty when it does not hallucinate).
pub fn training_truth(inputs: &Inputs, config: &PipelineConfig) -> Result<Vec<(Camera, Vec<f32>)>> {
    if config.hallucination == Hallucination::None {
        return Ok(Vec::new());
    }
    inputs
        .data
        .train
        .iter()
        .map(|&i| {
            let v = &inputs.data.views[i];
            let d = v.depth.clone().ok_or_else(|| {
                Error::invalid(format!(
                    "the hallucinating ground-truth generator needs the depth of training view '{}' (to tell what the training views saw)",
                    v.camera.name
                ))
                .at(&inputs.data.root)
            })?;
            Ok((v.camera.clone(), d))
        })
        .collect()
}

/// What a finished run produced.
#[derive(Clone, Debug)]
pub struct Outcome {
    pub steps: Vec<StepDone>,
    /// The final scene's PLY (`None` when a scoped run stopped before it).
    pub scene: Option<PathBuf>,
    /// `eval/summary.json`'s table, when evaluation poses were given.
    pub metrics: Option<evaluate::Summary>,
}

/// How [`run_with`] treats the run directory.
#[derive(Clone, Debug, Default)]
pub struct RunOptions {
    /// Continue a run: verified steps are skipped, the others recomputed.
    pub resume: bool,
    /// All steps, one step alone (the steps it reads must be done: a batch engine's
    /// worker), or the steps up to one.
    pub scope: Scope,
    /// A step cache shared with other runs (SPEC.md §20.8): steps with equal inputs are
    /// computed once.
    pub cache: Option<PathBuf>,
}

/// Run the whole pipeline into `out` (resuming a previous run with `resume`).
pub fn run(
    config: &PipelineConfig,
    inputs: &Inputs,
    out: &Path,
    resume: bool,
    on_event: &(dyn Fn(Event) + Sync),
) -> Result<Outcome> {
    let opts = RunOptions {
        resume,
        ..RunOptions::default()
    };
    run_with(config, inputs, out, &opts, on_event)
}

/// [`run`] with a scope and a step cache.
pub fn run_with(
    config: &PipelineConfig,
    inputs: &Inputs,
    out: &Path,
    opts: &RunOptions,
    on_event: &(dyn Fn(Event) + Sync),
) -> Result<Outcome> {
    config.validate()?;
    let target = match &opts.scope {
        Scope::All => None,
        Scope::Only(s) | Scope::Until(s) | Scope::Before(s) => Some(s.clone()),
    };
    if let Some(c) = &opts.cache
        && c.is_file()
    {
        return Err(Error::invalid("the step cache path is a file").at(c));
    }
    let mut dir = RunDir::open(out, opts.resume, opts.scope.clone(), &inputs.digest)?;
    if let Some(c) = &opts.cache {
        dir = dir.with_cache(c)?;
    }
    let ctx = StageCtx {
        config,
        inputs,
        dir: &dir,
        on_event,
    };
    match run_in(&ctx) {
        // Anything after a scoped run's last step (a later step, or a sibling of an
        // `--only` step that is not needed) ends the run there.
        Err(_) if dir.scope_finished() => Ok(Outcome {
            steps: Vec::new(),
            scene: None,
            metrics: None,
        }),
        Ok(_) if target.is_some() => Err(Error::invalid(format!(
            "this run has no step called '{}' (the steps are listed in steps.json)",
            target.unwrap_or_default()
        ))
        .at(out)),
        r => r,
    }
}

fn run_in(ctx: &StageCtx) -> Result<Outcome> {
    let StageCtx {
        config,
        inputs,
        dir,
        on_event,
    } = *ctx;
    let out = dir.root.as_path();
    let config_text = serde_json::to_string_pretty(config).expect("config serializes") + "\n";
    crate::io::write_text(&out.join("config.json"), &config_text)?;
    let truth = if config.slots.uses_truth() {
        Some(
            GroundTruth::new(candidate_truth(inputs)?, config.inconsistency, config.seed)
                .with_depth(config.truth_depth)
                .hallucinating(config.hallucination, training_truth(inputs, config)?),
        )
    } else {
        None
    };
    let mut gens = Generators::new(&config.slots, truth, config.seed)?;
    let mut steps = Vec::new();
    // Read only the dataset: attempted first, its error (if any) kept until it is needed,
    // so `--only` of a later step does not need it.
    let eval_masks = (!inputs.evaluation.is_empty()).then(|| evaluate::masks(ctx));

    on_event(Event::Stage {
        name: "views".into(),
    });
    let views = views::run(ctx, &gens)?;
    steps.push(views.step.clone());
    if let Some(gt) = gens.truth.as_mut() {
        for g in &views.plan.gap_cameras {
            gt.add_between(&g.camera, &g.between[0], &g.between[1])?;
        }
    }

    on_event(Event::Stage {
        name: "stage1".into(),
    });
    let s1 = stage1::run(ctx, &gens, &views)?;
    steps.extend(s1.steps.iter().cloned());

    on_event(Event::Stage {
        name: "stage2".into(),
    });
    let s2 = stage2::run(ctx, &gens, &views, &s1)?;
    steps.extend(s2.steps.iter().cloned());

    let mut last = s2.recon.clone();
    let mut scenes = vec![
        ("original".to_string(), None),
        ("stage1".to_string(), Some(s1.recon.clone())),
        ("stage2".to_string(), Some(s2.recon.clone())),
    ];
    if config.interpolation {
        on_event(Event::Stage {
            name: "interpolate".into(),
        });
        let ip = interpolate::run(ctx, &gens, &views, &s1, &s2)?;
        steps.extend(ip.steps.iter().cloned());
        last = ip.recon.clone();
        scenes.push(("interpolate".to_string(), Some(ip.recon)));
    }

    let metrics = match eval_masks {
        None => None,
        Some(masks) => {
            on_event(Event::Stage {
                name: "eval".into(),
            });
            let (summary, st) = evaluate::run(ctx, &scenes, masks?)?;
            steps.extend(st);
            Some(summary)
        }
    };
    // The run's steps in order (what `compare` walks: steps of an earlier configuration
    // left in the folder are not part of this run) and their times.
    let names: Vec<&str> = steps.iter().map(|s| s.name.as_str()).collect();
    let text = serde_json::to_string_pretty(&names).expect("serializes") + "\n";
    crate::io::write_text(&out.join("steps.json"), &text)?;
    let t = serde_json::to_string_pretty(&dir.timings(&steps)).expect("serializes") + "\n";
    crate::io::write_text(&out.join("timings.json"), &t)?;
    Ok(Outcome {
        steps,
        scene: Some(last.dir.join("scene.ply")),
        metrics,
    })
}

/// Names a candidate may not have: its stage-1 folder would be another step's.
pub const RESERVED_VIEW_NAMES: [&str; 2] = ["recon", "propagate"];

/// The pose distance used to pick "the closest training cameras" (SPEC.md §20.2):
/// centre distance in units of the scene extent plus `1 − cos` of the angle between the
/// viewing directions, so a camera at the same place looking the other way is far.
pub fn pose_distance(a: &Camera, b: &Camera, extent: f64) -> f64 {
    let za = a.world_from_camera_rotation.z_axis;
    let zb = b.world_from_camera_rotation.z_axis;
    (a.center - b.center).length() / extent.max(1e-12) + (1.0 - za.dot(zb))
}

/// The `k` training views of `data` closest to `cam` by [`pose_distance`] (ties: the
/// lower view index), nearest first.
pub fn nearest_training(data: &Dataset, cam: &Camera, k: usize) -> Vec<usize> {
    let extent = data.scene_extent() as f64;
    let mut d: Vec<(f64, usize)> = data
        .train
        .iter()
        .map(|&i| (pose_distance(&data.views[i].camera, cam, extent), i))
        .collect();
    d.sort_by(|x, y| x.0.total_cmp(&y.0).then(x.1.cmp(&y.1)));
    d.into_iter().take(k).map(|(_, i)| i).collect()
}
