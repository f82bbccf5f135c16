//! The paper's system (SPEC.md §20): from a trained scene and candidate extrapolation views
//! to an extrapolated scene, one module per stage —
//!
//! | stage | module | paper |
//! |---|---|---|
//! | independent view detection | [`views`] | §3.2 |
//! | parallel generation on independent views, DIBR propagation, reconstruction | [`stage1`] | §3.3.1 |
//! | residual completion on dependent views | [`stage2`] | §3.3.2 |
//! | interpolation by video reuse and the fixer | [`interpolate`] | §3.3.3 |
//! | the generate–reconstruct–shift cycle (paradigm `cycle`: the baseline, not the method) | [`cycle`] | §1 |
//!
//! with [`recon`] (the QA-Mask-weighted reconstruction every stage ends with), [`evaluate`]
//! (existing / extrapolated PSNR and SSIM on evaluation poses), [`generators`] (slots and
//! the ground-truth generator) and [`rundir`] (the resumable, content-addressed run
//! directory). Nothing below this module imports it. Progress arrives as [`Event`]s, so
//! a command line only draws them.

pub mod artifacts;
pub mod clips;
pub mod compare;
pub mod config;
pub mod cycle;
pub mod depth;
pub mod evaluate;
pub mod generators;
pub mod inputs;
pub mod interpolate;
pub mod poses;
pub mod recon;
pub mod report;
pub mod rundir;
pub mod selection;
pub mod stage1;
pub mod stage2;
pub mod steps;
pub mod views;

pub use config::{
    DensifyScope, FineTuneRates, Hallucination, Inconsistency, Level, MaskSource, Paradigm,
    PipelineConfig, Preset, ReconConfig, Slot, SlotNames, Stage2Depth, TruthDepth,
};

use crate::error::{Error, Result};
pub use artifacts::stem;
use generators::{Generators, GroundTruth};
pub use generators::{candidate_truth, training_truth};
pub use inputs::{Inputs, RESERVED_VIEW_NAMES, load_inputs};
pub use poses::{nearest_training, pose_distance, same_pose};
use rundir::{Mode, RunDir, StepDone};
use std::path::{Path, PathBuf};
pub use steps::{Scene, Scope, Selection, Shape, Stage, Step, Wave};

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

/// One run: what every stage reads, carried by reference — the configuration, the inputs,
/// the run directory (with its step cache), where progress events go, the generators and
/// the steps the run's scope selects. The stages are its methods (`views`, `stage1`,
/// `stage2`, `interpolate`, `eval_masks`, `evaluate`), each taking what the stages before
/// it produced.
#[derive(Clone, Copy)]
pub struct Run<'a> {
    pub config: &'a PipelineConfig,
    pub inputs: &'a Inputs,
    pub dir: &'a RunDir,
    pub on_event: &'a (dyn Fn(Event) + Sync),
    pub gens: &'a Generators,
    pub selection: &'a Selection,
}

impl Run<'_> {
    /// The scope computes `step` or reads it.
    pub fn wants(&self, step: &Step) -> bool {
        self.selection.wants(step)
    }

    /// Step `step` through the run directory ([`RunDir::step`]): computed when the scope
    /// computes it, verified when the scope only reads it.
    pub fn step(
        &self,
        step: &Step,
        inputs: serde_json::Value,
        compute: impl FnOnce(&mut rundir::StepWriter) -> Result<()>,
    ) -> Result<StepDone> {
        let mode = if self.selection.computes(step) {
            Mode::Compute
        } else if self.selection.wants(step) {
            Mode::Verify
        } else {
            return Err(Error::invalid(format!(
                "internal: step {step} is outside the run's selection"
            )));
        };
        self.dir.step(step, mode, inputs, self.on_event, compute)
    }

    /// Announce `stage` when the scope has steps in it.
    fn begin(&self, stage: Stage) {
        if self.selection.wants_stage(stage) {
            (self.on_event)(Event::Stage {
                name: stage.name().into(),
            });
        }
    }
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
    /// Which steps of the run's plan to compute ([`Scope`]): all, one alone or a batch
    /// task's (the steps they read must be done), the steps up to one, or those before one.
    pub scope: Scope,
    /// A step cache shared with other runs (SPEC.md §20.8): steps with equal inputs are
    /// computed once.
    pub cache: Option<PathBuf>,
}

/// The plan of a run of `inputs` under `config` into `out` ([`steps::plan`]): what
/// detection found when `out`'s views step is done (its `views/plan.json`), else the
/// largest plan, every candidate independent.
pub fn plan_of(config: &PipelineConfig, inputs: &Inputs, out: &Path) -> Result<Vec<Wave>> {
    let path = Step::Views.dir(out).join("plan.json");
    let shape = if path.is_file() {
        detected_shape(&artifacts::read_json(&path)?, inputs)
    } else {
        bound_shape(inputs)
    };
    Ok(steps::plan(config, &shape))
}

/// The shape of a run of `inputs` whose detection found `plan`.
fn detected_shape(plan: &views::Plan, inputs: &Inputs) -> Shape {
    Shape {
        independent: plan.independent.iter().map(|n| stem(n)).collect(),
        dependent: !plan.dependent.is_empty(),
        evaluation: !inputs.evaluation.is_empty(),
        trajectory: plan.trajectory.len(),
        most_trajectory: steps::most_trajectory(inputs.candidates.len()),
    }
}

/// The largest shape of a run of `inputs` ([`Shape::bound`]): every candidate independent.
pub fn bound_shape(inputs: &Inputs) -> Shape {
    let candidates = inputs.candidates.iter().map(|c| stem(&c.name)).collect();
    Shape::bound(candidates, !inputs.evaluation.is_empty())
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
    // The scope is checked against the largest plan before anything is written. A step
    // that reads nothing of detection is the same in every plan of these candidates (and
    // first in its wave, so a batch task's index names it in both): a selection that does
    // not read detection is final here; one that does is made again once detection is
    // known (`run_in`).
    let bound = steps::plan(config, &bound_shape(inputs));
    let before_views = Selection::new(&opts.scope, &bound).map_err(|e| e.at(out))?;
    if before_views.computed().next().is_none() {
        // A batch task past its wave's steps: nothing to do, nothing written.
        return Ok(Outcome {
            steps: Vec::new(),
            scene: None,
            metrics: None,
        });
    }
    if let Some(c) = &opts.cache
        && c.is_file()
    {
        return Err(Error::invalid("the step cache path is a file").at(c));
    }
    let scoped = opts.scope != Scope::All;
    let mut dir = RunDir::open(out, opts.resume, scoped, &inputs.digest)?;
    if let Some(c) = &opts.cache {
        dir = dir.with_cache(c)?;
    }
    run_in(
        config,
        inputs,
        &dir,
        &opts.scope,
        (&bound, &before_views),
        on_event,
    )
}

/// The run: detection (when the scope reads it), then the plan of what detection found,
/// the scope's selection of it, and the stages in order, each stopping where the
/// selection does.
fn run_in(
    config: &PipelineConfig,
    inputs: &Inputs,
    dir: &RunDir,
    scope: &Scope,
    (bound, before_views): (&[Wave], &Selection),
    on_event: &(dyn Fn(Event) + Sync),
) -> Result<Outcome> {
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
    let mut scenes = vec![(Scene::Original, None)];
    let first = Run {
        config,
        inputs,
        dir,
        on_event,
        gens: &gens,
        selection: before_views,
    };
    if !first.wants(&Step::Views) {
        // Nothing the scope selects reads detection: at most the original scene's QA-Mask
        // and evaluation.
        if first.wants(&Step::QaMask(Scene::Original)) {
            first.begin(Stage::QaMask);
            let (_, qa) = first.weights(&inputs.scene, &inputs.scene_sha256, Scene::Original)?;
            steps.extend(qa);
        }
        return first.finish(steps, &scenes, bound);
    }
    first.begin(Stage::Views);
    let views = first.views()?;
    steps.push(views.step.clone());
    if let Some(gt) = gens.truth.as_mut() {
        for g in &views.plan.gap_cameras {
            gt.add_between(&g.camera, &g.between[0], &g.between[1])?;
        }
    }
    let shape = detected_shape(&views.plan, inputs);
    if shape.trajectory > shape.most_trajectory {
        return Err(Error::invalid(format!(
            "internal: a trajectory of {} views over {} candidates (at most {})",
            shape.trajectory,
            inputs.candidates.len(),
            shape.most_trajectory
        ))
        .at(out));
    }
    let waves = steps::plan(config, &shape);
    let selection = Selection::new(scope, &waves).map_err(|e| e.at(out))?;
    let run = Run {
        config,
        inputs,
        dir,
        on_event,
        gens: &gens,
        selection: &selection,
    };

    if config.paradigm == Paradigm::Cycle {
        run.begin(Stage::Cycle);
        if let Some(last) = run.cycle(&views, &mut steps)? {
            scenes.push((Scene::Cycle, Some(last)));
        }
        return run.finish(steps, &scenes, &waves);
    }

    run.begin(Stage::Stage1);
    let Some(s1) = run.stage1(&views, &mut steps)? else {
        return run.finish(steps, &scenes, &waves);
    };
    scenes.push((Scene::Stage1, Some(s1.recon.clone())));

    run.begin(Stage::Stage2);
    let Some(s2) = run.stage2(&views, &s1, &mut steps)? else {
        return run.finish(steps, &scenes, &waves);
    };
    scenes.push((Scene::Stage2, Some(s2.recon.clone())));

    if config.interpolation {
        run.begin(Stage::Interpolate);
        let Some(ip) = run.interpolate(&views, &s1, &s2, &mut steps)? else {
            return run.finish(steps, &scenes, &waves);
        };
        scenes.push((Scene::Interpolate, Some(ip.recon)));
    }
    run.finish(steps, &scenes, &waves)
}

impl Run<'_> {
    /// Evaluate the scenes made (those the scope selects) and close the run: every step
    /// the selection computes must have run (else an internal error names it); a run of
    /// its whole plan writes `eval/summary.json`, `steps.json` (its steps in order: what
    /// `compare` walks; steps of an earlier configuration left in the folder are not part
    /// of this run) and `timings.json`.
    fn finish(
        &self,
        mut steps: Vec<StepDone>,
        scenes: &[(Scene, Option<StepDone>)],
        waves: &[Wave],
    ) -> Result<Outcome> {
        let metrics = if self.wants(&Step::EvalMasks) {
            self.begin(Stage::Eval);
            let masks = self.eval_masks()?;
            let (summary, st) = self.evaluate(scenes, masks)?;
            steps.extend(st);
            Some(summary)
        } else {
            None
        };
        if let Some(missed) = self
            .selection
            .computed()
            .find(|s| !steps.iter().any(|d| d.name == s.to_string()))
        {
            return Err(Error::invalid(format!(
                "internal: the run selected step {missed} and never reached it"
            ))
            .at(&self.dir.root));
        }
        let whole = self.selection.is_whole(waves);
        if whole {
            let out = self.dir.root.as_path();
            if let Some(summary) = &metrics {
                let text = serde_json::to_string_pretty(summary).expect("serializes") + "\n";
                crate::io::write_text(&Stage::Eval.dir(out).join("summary.json"), &text)?;
            }
            let names: Vec<&str> = steps.iter().map(|s| s.name.as_str()).collect();
            let text = serde_json::to_string_pretty(&names).expect("serializes") + "\n";
            crate::io::write_text(&out.join("steps.json"), &text)?;
            let t =
                serde_json::to_string_pretty(&self.dir.timings(&steps)).expect("serializes") + "\n";
            crate::io::write_text(&out.join("timings.json"), &t)?;
        }
        let last = scenes.last().and_then(|(_, s)| s.as_ref());
        Ok(Outcome {
            scene: last.filter(|_| whole).map(|s| s.dir.join("scene.ply")),
            steps,
            metrics,
        })
    }
}
