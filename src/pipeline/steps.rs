//! The steps of a run as one type, and the run as one plan of them (SPEC.md §20.8).
//!
//! Every step folder of a run directory is a [`Step`], written and parsed only here
//! (`Display` / `FromStr`), with the [`Stage`] it belongs to and its place in pipeline
//! order. [`plan`] lists a run's steps in dependency [`Wave`]s, each step with the steps it
//! reads; a [`Scope`] (`--only`, `--until`, a batch worker's wave) becomes a [`Selection`]
//! of that plan: the steps to compute and the steps that must already be done. The runner,
//! `compare`, the audit's step sharing and report and the batch fan-out read steps from
//! here, never from string literals (test `step_names_live_in_steps_rs`).

use super::config::{MaskSource, Paradigm, PipelineConfig};
use crate::error::{Error, Result};
use std::collections::BTreeSet;
use std::fmt;
use std::str::FromStr;

/// A scene of a run: the original and the reconstruction each stage ends with (under the
/// cycle paradigm, the last cycle view's). A QA-Mask is fine-tuned on a scene; every scene
/// is evaluated.
#[derive(Clone, Copy, Debug, PartialEq, Eq, Hash, PartialOrd, Ord)]
pub enum Scene {
    Original,
    Stage1,
    Stage2,
    Interpolate,
    Cycle,
}

crate::error::text_enum!(Scene, "scene", {
    Original => "original",
    Stage1 => "stage1",
    Stage2 => "stage2",
    Interpolate => "interpolate",
    Cycle => "cycle",
});

/// One step of a run, named by its folder under the run directory.
#[derive(Clone, Debug, PartialEq, Eq, Hash, PartialOrd, Ord)]
pub enum Step {
    /// `views`: independent-view detection and the plan (SPEC.md §20.2).
    Views,
    /// `stage1/<view>`: one independent view's inpainting and depth (the view's file stem).
    Independent(String),
    /// `stage1/propagate`: DIBR propagation of the independent views.
    Propagate,
    /// `qa/<scene>`: the QA-Mask fine-tuned on a scene (`original`, `stage1`, `stage2`).
    QaMask(Scene),
    /// `stage1/recon`: the stage-1 reconstruction.
    Stage1Recon,
    /// `stage2/dependent`: the dependent views.
    Dependent,
    /// `stage2/videos`: the videos between keyframes.
    Videos,
    /// `stage2/recon`: the stage-2 reconstruction.
    Stage2Recon,
    /// `interpolate/fixer`: the artifact fixer's frames.
    Fixer,
    /// `interpolate/recon`: the interpolation stage's reconstruction.
    Interpolation,
    /// `cycle/<k>`: the cycle paradigm's `k`-th view of the trajectory (from 0): its
    /// generation and the reconstruction after it (SPEC.md §20.11).
    Cycle(usize),
    /// `eval/masks`: the evaluation masks.
    EvalMasks,
    /// `eval/<scene>`: one scene's evaluation.
    Eval(Scene),
}

/// The stages of a run, in order: what the audit reports costs by.
#[derive(Clone, Copy, Debug, PartialEq, Eq, PartialOrd, Ord)]
pub enum Stage {
    Views,
    QaMask,
    Stage1,
    Stage2,
    Interpolate,
    Cycle,
    Eval,
}

impl Stage {
    pub const ALL: [Stage; 7] = [
        Stage::Views,
        Stage::QaMask,
        Stage::Stage1,
        Stage::Stage2,
        Stage::Interpolate,
        Stage::Cycle,
        Stage::Eval,
    ];

    pub fn name(self) -> &'static str {
        match self {
            Stage::Views => "views",
            Stage::QaMask => "qa-mask",
            Stage::Stage1 => "stage1",
            Stage::Stage2 => "stage2",
            Stage::Interpolate => "interpolate",
            Stage::Cycle => "cycle",
            Stage::Eval => "eval",
        }
    }

    /// The folder under a run directory that holds the stage's steps (`qa` for the
    /// QA-Mask's; the views step is its own folder).
    pub fn dir(self, root: &std::path::Path) -> std::path::PathBuf {
        root.join(match self {
            Stage::QaMask => "qa",
            s => s.name(),
        })
    }
}

impl fmt::Display for Stage {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        f.write_str(self.name())
    }
}

impl Step {
    /// The stage the step belongs to.
    pub fn stage(&self) -> Stage {
        match self {
            Step::Views => Stage::Views,
            Step::QaMask(_) => Stage::QaMask,
            Step::Independent(_) | Step::Propagate | Step::Stage1Recon => Stage::Stage1,
            Step::Dependent | Step::Videos | Step::Stage2Recon => Stage::Stage2,
            Step::Fixer | Step::Interpolation => Stage::Interpolate,
            Step::Cycle(_) => Stage::Cycle,
            Step::EvalMasks | Step::Eval(_) => Stage::Eval,
        }
    }

    /// The step's place in pipeline order (ties broken by [`Step::order`]): the order
    /// `compare` lists steps in, every step after the steps it reads (test
    /// `every_plan_orders_its_steps_for_every_reader`). The QA-Mask of a scene comes after
    /// the step that made the scene; the cycle's steps (never in a plan with a stage's)
    /// after the stages'.
    pub fn rank(&self) -> u32 {
        match self {
            Step::Views => 0,
            Step::Independent(_) => 1,
            Step::Propagate => 2,
            Step::QaMask(Scene::Original) => 3,
            Step::Stage1Recon => 4,
            Step::Dependent => 5,
            Step::Videos => 6,
            Step::QaMask(Scene::Stage1) => 7,
            Step::Stage2Recon => 8,
            Step::Fixer => 9,
            Step::QaMask(Scene::Stage2 | Scene::Interpolate | Scene::Cycle) => 10,
            Step::Interpolation => 11,
            Step::Cycle(_) => 12,
            Step::EvalMasks => 13,
            Step::Eval(_) => 14,
        }
    }

    /// The step's place in `compare`'s order: its [`Step::rank`], then a cycle step's index
    /// as a number (`cycle/10` after `cycle/9`), then its name.
    pub fn order(&self) -> (u32, usize, String) {
        let index = match self {
            Step::Cycle(k) => *k,
            _ => 0,
        };
        (self.rank(), index, self.to_string())
    }

    /// The step's folder under the run directory `root`.
    pub fn dir(&self, root: &std::path::Path) -> std::path::PathBuf {
        root.join(self.to_string())
    }
}

impl fmt::Display for Step {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        match self {
            Step::Views => f.write_str("views"),
            Step::Independent(v) => write!(f, "stage1/{v}"),
            Step::Propagate => f.write_str("stage1/propagate"),
            Step::QaMask(s) => write!(f, "qa/{s}"),
            Step::Stage1Recon => f.write_str("stage1/recon"),
            Step::Dependent => f.write_str("stage2/dependent"),
            Step::Videos => f.write_str("stage2/videos"),
            Step::Stage2Recon => f.write_str("stage2/recon"),
            Step::Fixer => f.write_str("interpolate/fixer"),
            Step::Interpolation => f.write_str("interpolate/recon"),
            Step::Cycle(k) => write!(f, "cycle/{k}"),
            Step::EvalMasks => f.write_str("eval/masks"),
            Step::Eval(s) => write!(f, "eval/{s}"),
        }
    }
}

impl FromStr for Step {
    type Err = Error;

    /// A step's folder name back to the step; anything else is an error naming it.
    fn from_str(s: &str) -> Result<Step> {
        let bad = || {
            Error::invalid(format!(
                "'{s}' is not a step of a run (views, stage1/<view>, stage1/propagate, qa/<scene>, stage1/recon, stage2/dependent, stage2/videos, stage2/recon, interpolate/fixer, interpolate/recon, cycle/<k>, eval/masks, eval/<scene>)"
            ))
        };
        let one = |rest: &str| {
            (!rest.is_empty() && !rest.contains('/'))
                .then(|| rest.to_string())
                .ok_or_else(bad)
        };
        let scene = |rest: &str| rest.parse::<Scene>().map_err(|_| bad());
        // A number as `Display` writes it (no sign, no leading zero).
        let index = |rest: &str| {
            rest.parse::<usize>()
                .ok()
                .filter(|k| k.to_string() == rest)
                .ok_or_else(bad)
        };
        Ok(match s {
            "views" => Step::Views,
            "stage1/propagate" => Step::Propagate,
            "stage1/recon" => Step::Stage1Recon,
            "stage2/dependent" => Step::Dependent,
            "stage2/videos" => Step::Videos,
            "stage2/recon" => Step::Stage2Recon,
            "interpolate/fixer" => Step::Fixer,
            "interpolate/recon" => Step::Interpolation,
            "eval/masks" => Step::EvalMasks,
            _ => {
                let (head, rest) = s.split_once('/').ok_or_else(bad)?;
                match head {
                    "stage1" => Step::Independent(one(rest)?),
                    "qa" => Step::QaMask(scene(rest)?),
                    "eval" => Step::Eval(scene(rest)?),
                    "cycle" => Step::Cycle(index(rest)?),
                    _ => return Err(bad()),
                }
            }
        })
    }
}

// ------------------------------------------------------------------------------ the plan

/// What detection decided that shapes a run's steps. Before detection, [`Shape::bound`]:
/// every candidate independent and dependent views present — the most steps the run can
/// have.
#[derive(Clone, Debug, PartialEq)]
pub struct Shape {
    /// The independent views' file stems, in plan order.
    pub independent: Vec<String>,
    /// Whether detection left dependent views (stage 2's `dependent` step and stage 1's
    /// propagation exist only then).
    pub dependent: bool,
    /// Whether evaluation poses were given (the `eval/…` steps).
    pub evaluation: bool,
    /// The closed trajectory's length: the cycle paradigm's steps `cycle/<k>`.
    pub trajectory: usize,
    /// The longest trajectory detection can leave for these candidates
    /// ([`most_trajectory`]): the cycle's steps of the bound plan.
    pub most_trajectory: usize,
}

impl Shape {
    /// The largest shape of a run over `candidates` (their file stems).
    pub fn bound(candidates: Vec<String>, evaluation: bool) -> Shape {
        let most = most_trajectory(candidates.len());
        Shape {
            independent: candidates,
            dependent: true,
            evaluation,
            trajectory: most,
            most_trajectory: most,
        }
    }
}

/// The longest closed trajectory over `candidates` views: each active candidate once, plus
/// at most one interpolated camera per gap of the tour of the independent views (none for
/// one view, one for two, one per view from three: `pipeline::views`).
pub fn most_trajectory(candidates: usize) -> usize {
    candidates
        + match candidates {
            0 | 1 => 0,
            2 => 1,
            n => n,
        }
}

/// A step of a plan and the steps whose output it reads.
#[derive(Clone, Debug, PartialEq)]
pub struct Planned {
    pub step: Step,
    pub after: Vec<Step>,
}

/// Steps that read nothing of each other, once every earlier wave is done: a batch engine
/// runs them at once. In pipeline order.
#[derive(Clone, Debug, Default, PartialEq)]
pub struct Wave {
    pub steps: Vec<Planned>,
}

/// A run's steps in dependency waves (SPEC.md §20.8). A step's wave is the longest chain of
/// reads before it in the run's *bound* shape ([`Shape::bound`]: dependent views present),
/// so the waves are numbered alike before and after detection: a wave that detection
/// leaves without steps (no dependent views: no propagation, no `stage2/dependent`) is
/// kept, empty. In a wave, the steps that read nothing of detection come first, then by
/// [`Step::rank`] and name.
pub fn plan(config: &PipelineConfig, shape: &Shape) -> Vec<Wave> {
    let bound = Shape {
        independent: vec![String::new()],
        dependent: true,
        evaluation: shape.evaluation,
        trajectory: shape.most_trajectory,
        most_trajectory: shape.most_trajectory,
    };
    // Waves of the bound graph, by step kind (every independent view alike).
    let kind = |s: &Step| match s {
        Step::Independent(_) => Step::Independent(String::new()),
        s => s.clone(),
    };
    let mut level: std::collections::BTreeMap<Step, usize> = Default::default();
    for p in graph(config, &bound) {
        let l = p
            .after
            .iter()
            .map(|a| level[&kind(a)] + 1)
            .max()
            .unwrap_or(0);
        level.insert(p.step, l);
    }
    let mut waves = vec![Wave::default(); level.values().max().map_or(0, |m| m + 1)];
    let steps = graph(config, shape);
    // Steps that read nothing of detection are the same in every plan of the run: first in
    // their wave, so a batch task's index names the same step before and after detection.
    let mut after_detection = BTreeSet::new();
    for p in &steps {
        if p.after
            .iter()
            .any(|a| *a == Step::Views || after_detection.contains(a))
        {
            after_detection.insert(p.step.clone());
        }
    }
    for p in steps {
        waves[level[&kind(&p.step)]].steps.push(p);
    }
    for w in &mut waves {
        w.steps.sort_by_cached_key(|p| {
            (
                after_detection.contains(&p.step),
                p.step.rank(),
                p.step.clone(),
            )
        });
    }
    waves
}

/// Every step of `shape` with the steps it reads, each after everything it reads: the
/// run's data flow as one table.
fn graph(config: &PipelineConfig, shape: &Shape) -> Vec<Planned> {
    if config.paradigm == Paradigm::Cycle {
        return cycle_graph(config, shape);
    }
    let qa = config.mask_source == MaskSource::Qa;
    let propagate = config.propagation && shape.dependent;
    let independent: Vec<Step> = shape
        .independent
        .iter()
        .map(|v| Step::Independent(v.clone()))
        .collect();
    // The views step and every independent view: what every later step's keyframes read.
    let detected = || std::iter::once(Step::Views).chain(independent.iter().cloned());
    let mut g = Vec::new();
    let mut add = |step: Step, after: Vec<Step>| g.push(Planned { step, after });
    let when = |c: bool, s: Step| c.then_some(s);
    add(Step::Views, vec![]);
    if qa {
        add(Step::QaMask(Scene::Original), vec![]);
    }
    for v in &independent {
        add(v.clone(), vec![Step::Views]);
    }
    if propagate {
        add(Step::Propagate, detected().collect());
    }
    let s1: Vec<Step> = detected()
        .chain(when(propagate, Step::Propagate))
        .chain(when(qa, Step::QaMask(Scene::Original)))
        .collect();
    add(Step::Stage1Recon, s1);
    let dependent = when(shape.dependent, Step::Dependent);
    if shape.dependent {
        let after = detected()
            .chain(when(propagate, Step::Propagate))
            .chain([Step::Stage1Recon])
            .collect();
        add(Step::Dependent, after);
    }
    // The clips' keyframes are the independent and dependent views; stage 2 starts from
    // the stage-1 scene (the runner reaches its steps through stage 1's result), so
    // `stage2/videos` is after `stage1/recon` even where no dependent view is.
    let videos = detected()
        .chain(dependent.clone())
        .chain([Step::Stage1Recon])
        .collect();
    add(Step::Videos, videos);
    if qa {
        add(Step::QaMask(Scene::Stage1), vec![Step::Stage1Recon]);
    }
    let s2 = detected()
        .chain(dependent.clone())
        .chain([Step::Stage1Recon, Step::Videos])
        .chain(when(qa, Step::QaMask(Scene::Stage1)))
        .collect();
    add(Step::Stage2Recon, s2);
    if config.interpolation {
        let fixer = detected()
            .chain(dependent.clone())
            .chain([Step::Videos, Step::Stage2Recon])
            .collect();
        add(Step::Fixer, fixer);
        if qa {
            add(Step::QaMask(Scene::Stage2), vec![Step::Stage2Recon]);
        }
        let ip = detected()
            .chain(dependent.clone())
            .chain([Step::Videos, Step::Stage2Recon, Step::Fixer])
            .chain(when(qa, Step::QaMask(Scene::Stage2)))
            .collect();
        add(Step::Interpolation, ip);
    }
    evaluation(config, shape, &mut g);
    g
}

/// The cycle paradigm's steps (SPEC.md §20.11): detection, the original scene's QA-Mask
/// (the first cycle view's weights), one step per trajectory view, each after the one
/// before it, and the evaluation of the original and the last cycle view's scene.
fn cycle_graph(config: &PipelineConfig, shape: &Shape) -> Vec<Planned> {
    let qa = config.mask_source == MaskSource::Qa;
    let mut g = vec![Planned {
        step: Step::Views,
        after: vec![],
    }];
    if qa {
        g.push(Planned {
            step: Step::QaMask(Scene::Original),
            after: vec![],
        });
    }
    for k in 0..shape.trajectory {
        let after = match k {
            0 => std::iter::once(Step::Views)
                .chain(qa.then_some(Step::QaMask(Scene::Original)))
                .collect(),
            k => vec![Step::Views, Step::Cycle(k - 1)],
        };
        g.push(Planned {
            step: Step::Cycle(k),
            after,
        });
    }
    evaluation(config, shape, &mut g);
    g
}

/// The evaluation steps of `shape` (when it has evaluation poses), appended to `g`.
fn evaluation(config: &PipelineConfig, shape: &Shape, g: &mut Vec<Planned>) {
    if shape.evaluation {
        let mut add = |step: Step, after: Vec<Step>| g.push(Planned { step, after });
        add(Step::EvalMasks, vec![]);
        for (scene, made_by) in scenes(config, shape) {
            add(
                Step::Eval(scene),
                std::iter::once(Step::EvalMasks).chain(made_by).collect(),
            );
        }
    }
}

/// The scenes a run makes, in order, with the step that makes each (none for the
/// original): what the evaluation compares.
fn scenes(config: &PipelineConfig, shape: &Shape) -> Vec<(Scene, Option<Step>)> {
    if config.paradigm == Paradigm::Cycle {
        let last = shape.trajectory.checked_sub(1).map(Step::Cycle);
        let cycle = last.map(|l| (Scene::Cycle, Some(l)));
        return std::iter::once((Scene::Original, None))
            .chain(cycle)
            .collect();
    }
    let mut s = vec![
        (Scene::Original, None),
        (Scene::Stage1, Some(Step::Stage1Recon)),
        (Scene::Stage2, Some(Step::Stage2Recon)),
    ];
    if config.interpolation {
        s.push((Scene::Interpolate, Some(Step::Interpolation)));
    }
    s
}

/// Which steps a run computes (SPEC.md §20.8).
#[derive(Clone, Debug, Default, PartialEq, Eq)]
pub enum Scope {
    /// Every step of the plan.
    #[default]
    All,
    /// One step alone; the steps it reads must be done (a batch engine's worker).
    Only(Step),
    /// One step and every step it reads, directly or not.
    Until(Step),
    /// Every step that does not read this one, directly or not (the audit's shared steps).
    Before(Step),
    /// Waves `first..=last` of the plan ([`plan`]); with `task`, only the `task`-th step
    /// of each (none where a wave has fewer): a batch engine's array task. The steps they
    /// read must be done.
    Waves {
        first: usize,
        last: usize,
        task: Option<usize>,
    },
}

/// A [`Scope`] applied to a plan: the steps to compute and the steps that must already be
/// done (verified on disk or in the step cache, never computed).
#[derive(Clone, Debug, Default, PartialEq)]
pub struct Selection {
    compute: BTreeSet<Step>,
    verify: BTreeSet<Step>,
}

impl Selection {
    /// `scope` over `waves`; a scope naming a step or wave the plan does not have is an
    /// error naming it.
    pub fn new(scope: &Scope, waves: &[Wave]) -> Result<Selection> {
        let planned: Vec<&Planned> = waves.iter().flat_map(|w| &w.steps).collect();
        let all: BTreeSet<Step> = planned.iter().map(|p| p.step.clone()).collect();
        let find = |s: &Step| {
            if all.contains(s) {
                Ok(s.clone())
            } else {
                let names: Vec<String> = planned.iter().map(|p| p.step.to_string()).collect();
                Err(Error::invalid(format!(
                    "this run has no step called '{s}' (its steps: {})",
                    names.join(", ")
                )))
            }
        };
        // Everything `from` reads, directly or not.
        let ancestors = |from: &BTreeSet<Step>| {
            let mut out = BTreeSet::new();
            for p in planned.iter().rev() {
                if from.contains(&p.step) || out.contains(&p.step) {
                    out.extend(p.after.iter().cloned());
                }
            }
            out
        };
        let (compute, verify) = match scope {
            Scope::All => (all.clone(), BTreeSet::new()),
            Scope::Only(s) => {
                let one = BTreeSet::from([find(s)?]);
                let before = ancestors(&one);
                (one, before)
            }
            Scope::Until(s) => {
                let mut up = BTreeSet::from([find(s)?]);
                up.extend(ancestors(&up));
                (up, BTreeSet::new())
            }
            Scope::Before(s) => {
                let mut after = BTreeSet::from([find(s)?]);
                for p in &planned {
                    if p.after.iter().any(|a| after.contains(a)) {
                        after.insert(p.step.clone());
                    }
                }
                (all.difference(&after).cloned().collect(), BTreeSet::new())
            }
            &Scope::Waves { first, last, task } => {
                if first > last {
                    return Err(Error::invalid(format!(
                        "waves {first}-{last} are no range (the first must not exceed the last)"
                    )));
                }
                if last >= waves.len() {
                    return Err(Error::invalid(format!(
                        "this run has waves 0 to {}; there is no wave {last}",
                        waves.len().saturating_sub(1)
                    )));
                }
                let chosen: BTreeSet<Step> = waves[first..=last]
                    .iter()
                    .flat_map(|w| match task {
                        None => w.steps.iter().collect::<Vec<_>>(),
                        Some(t) => w.steps.get(t).into_iter().collect(),
                    })
                    .map(|p| p.step.clone())
                    .collect();
                let before = ancestors(&chosen).difference(&chosen).cloned().collect();
                (chosen, before)
            }
        };
        Ok(Selection { compute, verify })
    }

    /// The step is computed (or reused when its inputs match).
    pub fn computes(&self, s: &Step) -> bool {
        self.compute.contains(s)
    }

    /// The step is computed, or must already be done.
    pub fn wants(&self, s: &Step) -> bool {
        self.compute.contains(s) || self.verify.contains(s)
    }

    /// Some step of `stage` is computed or read.
    pub fn wants_stage(&self, stage: Stage) -> bool {
        self.compute
            .iter()
            .chain(&self.verify)
            .any(|s| s.stage() == stage)
    }

    /// The steps to compute.
    pub fn computed(&self) -> impl Iterator<Item = &Step> {
        self.compute.iter()
    }

    /// Every step of `waves` is computed.
    pub fn is_whole(&self, waves: &[Wave]) -> bool {
        waves
            .iter()
            .flat_map(|w| &w.steps)
            .all(|p| self.compute.contains(&p.step))
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    /// Every step's name parses back to the step; names that are not steps are errors.
    #[test]
    fn step_names_round_trip() {
        let all = [
            Step::Views,
            Step::Independent("view_07".into()),
            Step::Propagate,
            Step::QaMask(Scene::Original),
            Step::Stage1Recon,
            Step::Dependent,
            Step::Videos,
            Step::QaMask(Scene::Stage1),
            Step::Stage2Recon,
            Step::Fixer,
            Step::QaMask(Scene::Stage2),
            Step::Interpolation,
            Step::Cycle(0),
            Step::Cycle(7),
            Step::Cycle(10),
            Step::EvalMasks,
            Step::Eval(Scene::Cycle),
            Step::Eval(Scene::Stage2),
        ];
        for s in &all {
            assert_eq!(s.to_string().parse::<Step>().unwrap(), *s);
        }
        // Pipeline order is the order above.
        assert!(
            all.windows(2).all(|w| w[0].order() < w[1].order()),
            "{all:?}"
        );
        for bad in [
            "",
            "stage1",
            "stage1/",
            "stage3/x",
            "qa/a/b",
            "qa/x",
            "eval/stage9",
            "eval",
            "view",
            "cycle/",
            "cycle/x",
            "cycle/01",
            "cycle/-1",
            "cycle/1/2",
        ] {
            assert!(bad.parse::<Step>().is_err(), "{bad}");
        }
        assert_eq!(Step::Stage1Recon.stage().name(), "stage1");
        assert_eq!(Step::QaMask(Scene::Stage1).stage().name(), "qa-mask");
        assert_eq!(Step::Cycle(3).stage().name(), "cycle");
    }

    /// The candidates of a shape of [`every_plan`]: its independent views and two more.
    fn candidates_of(shape: &Shape) -> Vec<String> {
        let mut c = shape.independent.clone();
        c.extend(["view_x".to_string(), "view_y".to_string()]);
        c
    }

    /// Every configuration switch that adds or removes steps (the paradigm among them),
    /// and the shapes detection can leave (of `n` independent views among `n + 2`
    /// candidates, with dependent views or without; the trajectory of the independent views
    /// and, with dependent views, two more).
    fn every_plan() -> Vec<(PipelineConfig, Shape, Vec<Wave>)> {
        let mut out = Vec::new();
        for paradigm in Paradigm::ALL {
            for mask_source in MaskSource::ALL {
                for (propagation, interpolation, evaluation, dependent) in
                    (0..16).map(|b| (b & 1 != 0, b & 2 != 0, b & 4 != 0, b & 8 != 0))
                {
                    for n in [1, 3] {
                        let config = PipelineConfig {
                            paradigm,
                            mask_source,
                            propagation,
                            interpolation,
                            ..PipelineConfig::preset(super::super::Preset::Quick)
                        };
                        let shape = Shape {
                            independent: (0..n).map(|k| format!("view_{k}")).collect(),
                            dependent,
                            evaluation,
                            trajectory: n + if dependent { 2 } else { 0 },
                            most_trajectory: most_trajectory(n + 2),
                        };
                        let waves = plan(&config, &shape);
                        out.push((config, shape, waves));
                    }
                }
            }
        }
        out
    }

    /// What a new step must get right to flow through the runner, `compare`, the audit's
    /// step sharing and the batch fan-out, over every shape of plan: each step once; each
    /// after the steps it reads — in a later wave (a batch engine runs the waves in order)
    /// and later in `compare`'s order (the first divergent step is upstream of the rest);
    /// the waves numbered alike before and after detection; the audit's shared job
    /// (`Before(stage1/recon)`; `Before(cycle/0)` under the cycle paradigm) selects the
    /// steps that do not read the first reconstruction; `--until` every step that no other
    /// reads is the whole run. Under the cycle paradigm: no stage's step, a chain of one
    /// step per trajectory view, and the original and the cycle evaluated.
    #[test]
    fn every_plan_orders_its_steps_for_every_reader() {
        for (config, shape, waves) in every_plan() {
            let at: std::collections::BTreeMap<&Step, usize> = waves
                .iter()
                .enumerate()
                .flat_map(|(k, w)| w.steps.iter().map(move |p| (&p.step, k)))
                .collect();
            let n: usize = waves.iter().map(|w| w.steps.len()).sum();
            assert_eq!(at.len(), n, "a step twice: {waves:?}");
            for p in waves.iter().flat_map(|w| &w.steps) {
                for a in &p.after {
                    assert!(at[a] < at[&p.step], "{a} not before {}", p.step);
                    assert!(a.order() < p.step.order(), "compare lists {} first", p.step);
                }
            }
            let bound = Shape::bound(candidates_of(&shape), shape.evaluation);
            assert_eq!(plan(&config, &bound).len(), waves.len(), "{shape:?}");
            let cycle = config.paradigm == Paradigm::Cycle;
            let first_recon = if cycle {
                Step::Cycle(0)
            } else {
                Step::Stage1Recon
            };
            let shared = Selection::new(&Scope::Before(first_recon.clone()), &waves).unwrap();
            let whole = Selection::new(&Scope::All, &waves).unwrap();
            for p in waves.iter().flat_map(|w| &w.steps) {
                let reads_recon = {
                    let mut up = BTreeSet::from([p.step.clone()]);
                    for q in waves.iter().flat_map(|w| &w.steps).rev() {
                        if up.contains(&q.step) {
                            up.extend(q.after.iter().cloned());
                        }
                    }
                    up.contains(&first_recon)
                };
                assert_eq!(shared.computes(&p.step), !reads_recon, "{}", p.step);
                assert!(whole.computes(&p.step));
            }
            // `--until` each step no other reads: together, the whole run.
            let steps: Vec<&Planned> = waves.iter().flat_map(|w| &w.steps).collect();
            let mut until = Selection::default();
            for p in &steps {
                if !steps.iter().any(|q| q.after.contains(&p.step)) {
                    let s = Selection::new(&Scope::Until(p.step.clone()), &waves).unwrap();
                    until.compute.extend(s.compute);
                }
            }
            assert!(until.is_whole(&waves), "{shape:?}");
            let has = |f: &dyn Fn(&Step) -> bool| steps.iter().any(|p| f(&p.step));
            let cycles: Vec<&Planned> = steps
                .iter()
                .filter(|p| matches!(p.step, Step::Cycle(_)))
                .copied()
                .collect();
            if cycle {
                assert!(!has(&|s| matches!(
                    s.stage(),
                    Stage::Stage1 | Stage::Stage2 | Stage::Interpolate
                )));
                assert_eq!(cycles.len(), shape.trajectory);
                for (k, p) in cycles.iter().enumerate() {
                    assert_eq!(p.step, Step::Cycle(k));
                    assert!(p.after.contains(&Step::Views));
                    assert_eq!(k == 0, !p.after.contains(&Step::Cycle(k.wrapping_sub(1))));
                }
                let evaluated: Vec<&Step> = steps
                    .iter()
                    .filter(|p| matches!(p.step, Step::Eval(_)))
                    .map(|p| &p.step)
                    .collect();
                let want = [Step::Eval(Scene::Original), Step::Eval(Scene::Cycle)];
                assert_eq!(
                    evaluated,
                    want.iter()
                        .take(2 * usize::from(shape.evaluation))
                        .collect::<Vec<_>>()
                );
            } else {
                assert!(cycles.is_empty() && !has(&|s| *s == Step::Eval(Scene::Cycle)));
            }
        }
    }

    /// A batch task (`Waves` with a task index) is resolved as the runner resolves it: on
    /// the bound plan when that step reads nothing of detection, else on the plan detection
    /// gave. Over every plan, the tasks of a wave compute each of its steps exactly once
    /// (the index names the same step before and after detection).
    #[test]
    fn batch_tasks_compute_every_step_of_their_wave_once() {
        for (config, shape, waves) in every_plan() {
            let bound = plan(
                &config,
                &Shape::bound(candidates_of(&shape), shape.evaluation),
            );
            for (k, wave) in waves.iter().enumerate() {
                let mut done: Vec<Step> = Vec::new();
                for task in 0..bound[k].steps.len() {
                    let scope = Scope::Waves {
                        first: k,
                        last: k,
                        task: Some(task),
                    };
                    let first = Selection::new(&scope, &bound).unwrap();
                    let s = if first.wants(&Step::Views) {
                        Selection::new(&scope, &waves).unwrap()
                    } else {
                        first
                    };
                    done.extend(s.computed().cloned());
                }
                let mut want: Vec<Step> = wave.steps.iter().map(|p| p.step.clone()).collect();
                done.sort();
                want.sort();
                assert_eq!(done, want, "wave {k} of {shape:?}");
            }
        }
    }

    /// A scope names a step or wave of the plan, or is an error naming it; `--only` and a
    /// wave's task compute their steps alone and verify what those read.
    #[test]
    fn scopes_select_from_the_plan() {
        let config = PipelineConfig::preset(super::super::Preset::Quick);
        let shape = Shape::bound(vec!["a".into(), "b".into()], true);
        let waves = plan(&config, &shape);
        let only = Selection::new(&Scope::Only(Step::Independent("b".into())), &waves).unwrap();
        assert!(only.computes(&Step::Independent("b".into())));
        assert!(!only.computes(&Step::Views) && only.wants(&Step::Views));
        assert!(!only.wants(&Step::Independent("a".into())));
        // Wave 1: the original's evaluation (it reads nothing of detection) first, then
        // the independent views.
        let task = Scope::Waves {
            first: 1,
            last: 1,
            task: Some(2),
        };
        assert_eq!(Selection::new(&task, &waves).unwrap(), only);
        let past = Scope::Waves {
            first: 1,
            last: 1,
            task: Some(9),
        };
        assert!(Selection::new(&past, &waves).unwrap().compute.is_empty());
        for bad in [
            Scope::Only(Step::Independent("c".into())),
            Scope::Until(Step::QaMask(Scene::Interpolate)),
            Scope::Waves {
                first: 0,
                last: waves.len(),
                task: None,
            },
        ] {
            let e = Selection::new(&bad, &waves).unwrap_err().to_string();
            assert!(e.contains("no step called") || e.contains("no wave"), "{e}");
        }
        // The cycle paradigm: `--only cycle/1` verifies the chain before it and detection;
        // before detection every candidate's longest trajectory is planned, and the
        // evaluation of the cycle stays in its wave after detection.
        let cycle = PipelineConfig {
            paradigm: Paradigm::Cycle,
            ..config
        };
        let bound = plan(&cycle, &shape);
        let steps = |w: &[Wave]| -> Vec<Step> {
            w.iter()
                .flat_map(|w| &w.steps)
                .map(|p| p.step.clone())
                .collect()
        };
        assert_eq!(most_trajectory(2), 3);
        assert!(steps(&bound).contains(&Step::Cycle(2)));
        assert!(!steps(&bound).contains(&Step::Cycle(3)));
        let detected = Shape {
            trajectory: 2,
            ..shape.clone()
        };
        let waves = plan(&cycle, &detected);
        assert_eq!(waves.len(), bound.len());
        assert!(!steps(&waves).contains(&Step::Cycle(2)));
        let at = |w: &[Wave], s: &Step| w.iter().position(|w| w.steps.iter().any(|p| p.step == *s));
        let eval = Step::Eval(Scene::Cycle);
        assert_eq!(at(&waves, &eval), at(&bound, &eval));
        let only = Selection::new(&Scope::Only(Step::Cycle(1)), &waves).unwrap();
        assert_eq!(only.computed().collect::<Vec<_>>(), [&Step::Cycle(1)]);
        for s in [Step::Cycle(0), Step::Views, Step::QaMask(Scene::Original)] {
            assert!(only.wants(&s), "{s}");
        }
        assert!(!only.wants(&Step::EvalMasks));
    }
}
