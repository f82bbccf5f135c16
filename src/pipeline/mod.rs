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
pub mod compare;
pub mod config;
pub mod evaluate;
pub mod generators;
pub mod inputs;
pub mod interpolate;
pub mod poses;
pub mod recon;
pub mod report;
pub mod rundir;
pub mod stage1;
pub mod stage2;
pub mod steps;
pub mod views;

pub use config::{
    Hallucination, Inconsistency, Level, MaskSource, PipelineConfig, Preset, ReconConfig, Slot,
    SlotNames, Stage2Depth, TruthDepth,
};

use crate::error::{Error, Result};
pub use artifacts::stem;
use generators::{Generators, GroundTruth};
pub use generators::{candidate_truth, training_truth};
pub use inputs::{Inputs, RESERVED_VIEW_NAMES, load_inputs};
pub use poses::{nearest_training, pose_distance, same_pose};
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
            target.map(|t| t.to_string()).unwrap_or_default()
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
        name: steps::Stage::Views.name().into(),
    });
    let views = views::run(ctx, &gens)?;
    steps.push(views.step.clone());
    if let Some(gt) = gens.truth.as_mut() {
        for g in &views.plan.gap_cameras {
            gt.add_between(&g.camera, &g.between[0], &g.between[1])?;
        }
    }

    on_event(Event::Stage {
        name: steps::Stage::Stage1.name().into(),
    });
    let s1 = stage1::run(ctx, &gens, &views)?;
    steps.extend(s1.steps.iter().cloned());

    on_event(Event::Stage {
        name: steps::Stage::Stage2.name().into(),
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
            name: steps::Stage::Interpolate.name().into(),
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
                name: steps::Stage::Eval.name().into(),
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
