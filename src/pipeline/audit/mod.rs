//! `unseen audit` (SPEC.md §21): the paper's claims checked on a dataset with ground truth.
//!
//! Every variant of the paper's ablations (Tables 3 and 4) runs as a whole pipeline from
//! the same original scene, under several generators: the classical slots and the
//! ground-truth generator at controlled inconsistency levels (the x-axis of the paper's
//! mechanism claims: QA-Mask protects existing regions from *inconsistent* generated
//! content; independent views avoid *conflicting* content). Each (generator, variant, seed)
//! is one job with its own run directory; all jobs share one step cache
//! ([`super::RunOptions::cache`]), so a step whose inputs several variants share (the
//! views, the per-view generation, a QA-Mask of a given degree) is computed once.
//!
//! A claim is tested on the paired differences `d = full − variant` of the metric over
//! units (a seed at a numerics revision; [`samples`] pools batches of seeds): *holds* /
//! *contradicted* when significantly above / below its null value (0, or the
//! non-inferiority margin below 0 for "does not hurt") after Holm's correction within the
//! generator family, else *inconclusive* with the minimum detectable effect ([`stats`],
//! SPEC.md §21.2).

use super::evaluate::{ClassSums, Row, Summary, ViewRecord};
use super::{
    Event, Hallucination, Inconsistency, MaskSource, PipelineConfig, RunOptions, Scope, SlotNames,
    Stage2Depth, TruthDepth,
};
use crate::error::{Error, Result};
use crate::train::checkpoint::checkpoint_path;
use crate::train::run::{Checkpointing, latest_ply, read_config, train_run};
use crate::train::trainer::TrainConfig;
use std::path::{Path, PathBuf};

pub mod cluster;
pub mod samples;
pub mod stats;
pub use samples::Samples;

/// One ablation of the paper (or the full method).
#[derive(Clone, Copy, Debug, PartialEq, Eq, serde::Serialize, serde::Deserialize)]
#[serde(rename_all = "snake_case")]
pub enum Variant {
    Full,
    /// Uniform weights on generated views ("w/o QA-Mask").
    NoQaMask,
    /// `1 − alpha` of the scene being updated instead of the QA-Mask (Table 3's baseline).
    OpacityMask,
    /// The same number of views, evenly spaced along the candidate list ("w/o Idpdt Cam
    /// Detection").
    EvenViews,
    NoDepthSupervision,
    NoPropagation,
    QaSh3,
    QaSh4,
    NoInterpolation,
    /// Stage-2 depth by a least-squares fit to the stage-1 render instead of the paper's
    /// video depth alignment (the labelled deviation `stage2_depth: render_fit`).
    Stage2RenderFit,
}

impl Variant {
    pub const ALL: [Variant; 10] = [
        Variant::Full,
        Variant::NoQaMask,
        Variant::OpacityMask,
        Variant::EvenViews,
        Variant::NoDepthSupervision,
        Variant::NoPropagation,
        Variant::QaSh3,
        Variant::QaSh4,
        Variant::NoInterpolation,
        Variant::Stage2RenderFit,
    ];

    pub fn name(self) -> &'static str {
        match self {
            Variant::Full => "full",
            Variant::NoQaMask => "no_qa_mask",
            Variant::OpacityMask => "opacity_mask",
            Variant::EvenViews => "even_views",
            Variant::NoDepthSupervision => "no_depth_supervision",
            Variant::NoPropagation => "no_propagation",
            Variant::QaSh3 => "qa_sh3",
            Variant::QaSh4 => "qa_sh4",
            Variant::NoInterpolation => "no_interpolation",
            Variant::Stage2RenderFit => "stage2_render_fit",
        }
    }

    pub fn by_name(name: &str) -> Result<Variant> {
        Variant::ALL
            .into_iter()
            .find(|v| v.name() == name)
            .ok_or_else(|| {
                Error::invalid(format!(
                    "unknown variant '{name}' ({})",
                    Variant::ALL.map(|v| v.name()).join(", ")
                ))
            })
    }

    /// The variant's switch on top of the preset.
    pub fn apply(self, c: &mut PipelineConfig) {
        match self {
            Variant::Full => {}
            Variant::NoQaMask => c.mask_source = MaskSource::None,
            Variant::OpacityMask => c.mask_source = MaskSource::Opacity,
            Variant::EvenViews => c.independent_detection = false,
            Variant::NoDepthSupervision => c.depth_supervision = false,
            Variant::NoPropagation => c.propagation = false,
            Variant::QaSh3 => c.qa_sh_degree = 3,
            Variant::QaSh4 => c.qa_sh_degree = 4,
            Variant::NoInterpolation => c.interpolation = false,
            Variant::Stage2RenderFit => c.stage2_depth = Stage2Depth::RenderFit,
        }
    }
}

/// Which generators fill the slots of a job.
#[derive(Clone, Copy, Debug, PartialEq)]
pub enum GeneratorKind {
    /// The deterministic classical slots (Telea, depth-fill, morph).
    Classical,
    /// The labelled ground-truth generator at a named inconsistency level.
    Truth(&'static str),
    /// The ground-truth generator at a level (low or high) that also hallucinates unseen
    /// content at that level and answers depth in the relative mode (SPEC.md §20.6): the
    /// generator under which the paper's mechanisms (independent views against conflicting
    /// content, Eq. 5's alignment) have something to do.
    Mechanisms(&'static str),
}

impl GeneratorKind {
    pub fn name(self) -> String {
        match self {
            GeneratorKind::Classical => "classical".into(),
            GeneratorKind::Truth(level) => format!("truth-{level}"),
            GeneratorKind::Mechanisms(level) => format!("truth-{level}+hallucinating+relative"),
        }
    }

    /// `classical`, `truth-none`, `truth-low`, `truth-high`,
    /// `truth-low+hallucinating+relative`, `truth-high+hallucinating+relative`.
    pub fn by_name(name: &str) -> Result<GeneratorKind> {
        match name {
            "classical" => Ok(GeneratorKind::Classical),
            "truth-none" => Ok(GeneratorKind::Truth("none")),
            "truth-low" => Ok(GeneratorKind::Truth("low")),
            "truth-high" => Ok(GeneratorKind::Truth("high")),
            "truth-low+hallucinating+relative" => Ok(GeneratorKind::Mechanisms("low")),
            "truth-high+hallucinating+relative" => Ok(GeneratorKind::Mechanisms("high")),
            _ => Err(Error::invalid(format!(
                "unknown generator '{name}' (classical, truth-none, truth-low, truth-high, truth-low+hallucinating+relative, truth-high+hallucinating+relative)"
            ))),
        }
    }

    fn apply(self, c: &mut PipelineConfig) -> Result<()> {
        match self {
            GeneratorKind::Classical => {
                c.slots = SlotNames::default();
                c.inconsistency = Inconsistency::NONE;
            }
            GeneratorKind::Truth(level) => {
                c.slots = SlotNames::truth();
                c.inconsistency = Inconsistency::by_name(level)?;
            }
            GeneratorKind::Mechanisms(level) => {
                c.slots = SlotNames::truth();
                c.inconsistency = Inconsistency::by_name(level)?;
                c.hallucination = match level {
                    "high" => Hallucination::High,
                    _ => Hallucination::Low,
                };
                c.truth_depth = TruthDepth::Relative;
            }
        }
        Ok(())
    }

    /// The family of Holm's correction: `classical` or `truth` (every level).
    pub fn family(self) -> &'static str {
        match self {
            GeneratorKind::Classical => "classical",
            GeneratorKind::Truth(_) | GeneratorKind::Mechanisms(_) => "truth",
        }
    }

    /// Position on the inconsistency axis (classical: none).
    fn level(self) -> Option<usize> {
        match self {
            GeneratorKind::Classical | GeneratorKind::Mechanisms(_) => None,
            GeneratorKind::Truth(l) => ["none", "low", "high"].iter().position(|&x| x == l),
        }
    }
}

/// What an audit runs.
#[derive(Clone, Debug)]
pub struct AuditConfig {
    /// The pipeline configuration every job starts from (a preset), before its
    /// generator, variant and seed are applied.
    pub base: PipelineConfig,
    pub variants: Vec<Variant>,
    pub generators: Vec<GeneratorKind>,
    /// The seeds of this batch (original scene and pipeline alike); batches of other
    /// seeds pool in the report ([`samples`]).
    pub seeds: std::ops::Range<u32>,
    /// Training of the original scene on the dataset's training half.
    pub train_iterations: u32,
    pub train_resolution: u32,
}

impl AuditConfig {
    /// One seed, every variant, the classical slots and the ground-truth generator at the
    /// low inconsistency level; the original scene as the demo trains it.
    pub fn quick() -> AuditConfig {
        AuditConfig {
            base: PipelineConfig::quick(),
            variants: Variant::ALL.to_vec(),
            generators: vec![GeneratorKind::Classical, GeneratorKind::Truth("low")],
            seeds: 0..1,
            train_iterations: 1500,
            train_resolution: 2,
        }
    }

    /// Three seeds, every variant, the classical slots and the ground-truth generator at
    /// every level, the paper's pipeline settings and INRIA's 30 000 training iterations.
    pub fn paper() -> AuditConfig {
        AuditConfig {
            base: PipelineConfig::paper(),
            variants: Variant::ALL.to_vec(),
            generators: vec![
                GeneratorKind::Classical,
                GeneratorKind::Truth("none"),
                GeneratorKind::Truth("low"),
                GeneratorKind::Truth("high"),
            ],
            seeds: 0..3,
            train_iterations: 30_000,
            train_resolution: 1,
        }
    }

    /// `quick` or `paper` (the pipeline preset of the same name, and the grid above).
    pub fn preset(name: &str) -> Result<AuditConfig> {
        let base = PipelineConfig::preset(name)?;
        let grid = if name == "paper" {
            Self::paper()
        } else {
            Self::quick()
        };
        Ok(AuditConfig { base, ..grid })
    }

    pub fn validate(&self) -> Result<()> {
        if self.variants.is_empty() || self.generators.is_empty() || self.seeds.is_empty() {
            return Err(Error::invalid(
                "an audit needs at least one variant, one generator and one seed",
            ));
        }
        let dup_v =
            (1..self.variants.len()).any(|i| self.variants[..i].contains(&self.variants[i]));
        let dup_g =
            (1..self.generators.len()).any(|i| self.generators[..i].contains(&self.generators[i]));
        if dup_v || dup_g {
            return Err(Error::invalid(
                "a variant or generator is listed twice (each is one set of jobs)",
            ));
        }
        if !self.variants.contains(&Variant::Full) {
            return Err(Error::invalid(
                "every claim compares against the full method: include the variant 'full'",
            ));
        }
        Ok(())
    }

    /// [`config_digest`] of a job's configuration.
    pub fn config_digest(&self, generator: GeneratorKind, variant: Variant) -> Result<String> {
        Ok(config_digest(&self.pipeline_config(generator, variant, 0)?))
    }

    /// The pipeline configuration of one job.
    pub fn pipeline_config(
        &self,
        generator: GeneratorKind,
        variant: Variant,
        seed: u32,
    ) -> Result<PipelineConfig> {
        let mut c = self.base.clone();
        c.seed = seed as u64;
        generator.apply(&mut c)?;
        variant.apply(&mut c);
        Ok(c)
    }

    fn train_config(&self, seed: u32) -> TrainConfig {
        TrainConfig {
            iterations: self.train_iterations,
            resolution: self.train_resolution,
            seed: seed as u64,
            save_iterations: vec![],
            ..TrainConfig::default()
        }
    }
}

/// SHA-256 of a pipeline configuration's JSON with its seed set to 0: what one
/// (generator, variant) cell runs for every seed.
pub fn config_digest(c: &PipelineConfig) -> String {
    let c = PipelineConfig {
        seed: 0,
        ..c.clone()
    };
    crate::io::sha256_hex(&serde_json::to_vec(&c).expect("serializes"))
}

/// One job of an audit: the original scene of a seed, a pipeline run, or (for a batch
/// engine, [`cluster::waves`]) the steps a seed's variants share under one generator.
#[derive(Clone, Debug, PartialEq)]
pub enum Job {
    Original {
        seed: u32,
    },
    Run {
        generator: GeneratorKind,
        variant: Variant,
        seed: u32,
    },
    /// The `full` variant's run up to its first stage-1 reconstruction ([`SHARED_BEFORE`]):
    /// the views, the original scene's QA-Mask and the stage-1 generations, which most
    /// variants share through the step cache. Computed once before the variants start, so
    /// that parallel workers do not all compute them at once; its folder is the `full`
    /// run's, which continues from it.
    Shared {
        generator: GeneratorKind,
        seed: u32,
    },
}

/// Where a [`Job::Shared`] stops: before the first step whose name starts with this.
pub const SHARED_BEFORE: &str = "stage1/recon";

impl Job {
    /// The job's name on the command line: `original/seed-K`,
    /// `runs/<generator>/<variant>/seed-K` (also its folder under the audit directory) or
    /// `shared/<generator>/seed-K`.
    pub fn name(&self) -> String {
        match self {
            Job::Original { seed } => format!("original/seed-{seed}"),
            Job::Run {
                generator,
                variant,
                seed,
            } => format!("runs/{}/{}/seed-{seed}", generator.name(), variant.name()),
            Job::Shared { generator, seed } => format!("shared/{}/seed-{seed}", generator.name()),
        }
    }

    /// The job's folder under the audit directory.
    pub fn folder(&self) -> String {
        match *self {
            Job::Shared { generator, seed } => Job::Run {
                generator,
                variant: Variant::Full,
                seed,
            }
            .name(),
            _ => self.name(),
        }
    }
}

/// Every job of `cfg`, originals first (a run needs its seed's original scene).
pub fn jobs(cfg: &AuditConfig) -> Vec<Job> {
    let mut v: Vec<Job> = cfg
        .seeds
        .clone()
        .map(|seed| Job::Original { seed })
        .collect();
    for seed in cfg.seeds.clone() {
        for &generator in &cfg.generators {
            for &variant in &cfg.variants {
                v.push(Job::Run {
                    generator,
                    variant,
                    seed,
                });
            }
        }
    }
    v
}

/// The measured outcome of one pipeline job: one sample of the audit.
#[derive(Clone, Debug, PartialEq, serde::Serialize, serde::Deserialize)]
pub struct JobResult {
    pub generator: String,
    pub variant: String,
    pub seed: u32,
    /// The binary that computed it ([`crate::version::NUMERICS_REVISION`], crate version):
    /// a sample of another revision is another draw of the chaotic training, averaged into
    /// its seed unless it has the same bits ([`pairs`], [`seed_means`]). 0 / empty in job files
    /// written before it was recorded (the audit's own revision applies).
    #[serde(default)]
    pub numerics_revision: u32,
    #[serde(default)]
    pub crate_version: String,
    /// [`config_digest`] of the job's pipeline configuration: samples of another
    /// configuration of the same (generator, variant) are not pooled. Empty in job files
    /// written before it was recorded (taken as this binary's).
    #[serde(default)]
    pub config: String,
    /// The original scene's metrics on the evaluation poses.
    pub original: Row,
    /// The final scene's (the last stage the variant runs).
    pub last: Row,
    /// Per stage (`views`, `stage1`, `stage2`, `interpolate`, `eval`): seconds of the steps
    /// as they were computed (a step copied from the cache counts what it cost there).
    pub stage_seconds: std::collections::BTreeMap<String, f64>,
    /// Every step of the job's run, in run order, with its manifest digest (equal digests
    /// are one computation, shared through the cache) and its compute seconds. Empty in
    /// job files written before it was recorded, and in pooled samples.
    #[serde(default, skip_serializing_if = "Vec::is_empty")]
    pub steps: Vec<StepCost>,
}

/// One step of a job: what [`sharing`] counts.
#[derive(Clone, Debug, PartialEq, serde::Serialize, serde::Deserialize)]
pub struct StepCost {
    pub name: String,
    pub digest: String,
    pub seconds: f64,
}

/// Stage names as the audit reports them (`qa/<scene>` is `qa-mask`).
fn stage_of(step: &str) -> String {
    match step.split('/').next().unwrap_or("") {
        "qa" => "qa-mask".into(),
        s => s.into(),
    }
}

/// What the step cache saves, per stage (in first-seen order): step executions over all
/// jobs, distinct steps (digests), compute seconds if every job computed its own steps, and
/// seconds with each distinct step computed once — what a fresh sequential audit computes;
/// a resumed one, parallel workers or an older cache may have computed a step twice or
/// not at all here (the digests do not say which).
#[derive(Clone, Debug, PartialEq)]
pub struct Sharing {
    pub stage: String,
    pub executions: usize,
    pub distinct: usize,
    pub unshared_seconds: f64,
    pub shared_seconds: f64,
}

/// [`Sharing`] of `results`, per stage and a last row `all`.
pub fn sharing(results: &[JobResult]) -> Vec<Sharing> {
    let mut rows: Vec<Sharing> = Vec::new();
    let mut seen = std::collections::BTreeSet::new();
    let mut add = |stage: String, step: &StepCost, first: bool| {
        let i = match rows.iter().position(|r| r.stage == stage) {
            Some(i) => i,
            None => {
                rows.push(Sharing {
                    stage,
                    executions: 0,
                    distinct: 0,
                    unshared_seconds: 0.0,
                    shared_seconds: 0.0,
                });
                rows.len() - 1
            }
        };
        let r = &mut rows[i];
        r.executions += 1;
        r.unshared_seconds += step.seconds;
        if first {
            r.distinct += 1;
            r.shared_seconds += step.seconds;
        }
    };
    for step in results.iter().flat_map(|r| &r.steps) {
        let first = seen.insert(step.digest.clone());
        add(stage_of(&step.name), step, first);
        add("all".into(), step, first);
    }
    // `all` last.
    if let Some(i) = rows.iter().position(|r| r.stage == "all") {
        let all = rows.remove(i);
        rows.push(all);
    }
    rows
}

/// Run (or verify) one job. Originals are trained once per seed and reused; a pipeline job
/// continues its run directory (verified steps are skipped) and shares `DIR/cache`.
pub fn run_job(
    cfg: &AuditConfig,
    dataset: &Path,
    dir: &Path,
    job: &Job,
    on_event: &(dyn Fn(Event) + Sync),
) -> Result<Option<JobResult>> {
    cfg.validate()?;
    check_inputs(dataset, dir)?;
    match *job {
        Job::Original { seed } => {
            on_event(Event::Stage { name: job.name() });
            original(cfg, dataset, dir, seed, on_event)?;
            Ok(None)
        }
        Job::Shared { generator, seed } => {
            let scope = Scope::Before(SHARED_BEFORE.into());
            pipeline_job(
                cfg,
                dataset,
                dir,
                job,
                generator,
                Variant::Full,
                seed,
                scope,
                on_event,
            )?;
            Ok(None)
        }
        Job::Run {
            generator,
            variant,
            seed,
        } => {
            let (pc, outcome) = pipeline_job(
                cfg,
                dataset,
                dir,
                job,
                generator,
                variant,
                seed,
                Scope::All,
                on_event,
            )?;
            let out = dir.join(job.folder());
            let summary: Summary = outcome.metrics.ok_or_else(|| {
                Error::invalid("the dataset has no evaluation poses (evaluation.json)").at(dataset)
            })?;
            let (first, last) = match (summary.rows.first(), summary.rows.last()) {
                (Some(f), Some(l)) => (f.clone(), l.clone()),
                _ => return Err(Error::invalid("the run evaluated no scene").at(&out)),
            };
            let mut stage_seconds = std::collections::BTreeMap::new();
            let mut steps = Vec::new();
            for step in &outcome.steps {
                let seconds = std::fs::read(step.dir.join(super::rundir::TIMING_FILE))
                    .ok()
                    .and_then(|b| serde_json::from_slice::<crate::io::Cost>(&b).ok())
                    .map_or(0.0, |c| c.seconds);
                *stage_seconds.entry(stage_of(&step.name)).or_insert(0.0) += seconds;
                steps.push(StepCost {
                    name: step.name.clone(),
                    digest: step.digest.clone(),
                    seconds,
                });
            }
            let result = JobResult {
                generator: generator.name(),
                variant: variant.name().into(),
                seed,
                numerics_revision: crate::version::NUMERICS_REVISION,
                crate_version: env!("CARGO_PKG_VERSION").into(),
                config: config_digest(&pc),
                original: first,
                last,
                stage_seconds,
                steps,
            };
            let text = serde_json::to_string_pretty(&result).expect("serializes") + "\n";
            crate::io::write_text(&out.join("audit_job.json"), &text)?;
            Ok(Some(result))
        }
    }
}

/// Run the pipeline of (`generator`, `variant`, `seed`) in `job`'s folder within `scope`,
/// continuing what is there and sharing `DIR/cache`; the seed's original scene must be
/// done. Returns the job's configuration and the run's outcome.
#[allow(clippy::too_many_arguments)]
fn pipeline_job(
    cfg: &AuditConfig,
    dataset: &Path,
    dir: &Path,
    job: &Job,
    generator: GeneratorKind,
    variant: Variant,
    seed: u32,
    scope: Scope,
    on_event: &(dyn Fn(Event) + Sync),
) -> Result<(PipelineConfig, super::Outcome)> {
    let run = require_original(cfg, dataset, dir, job, seed)?;
    on_event(Event::Stage { name: job.name() });
    let inputs = super::load_inputs(
        &run,
        &dataset.join("candidates.json"),
        Some(&dataset.join("evaluation.json")),
        Some(dataset),
    )?;
    let pc = cfg.pipeline_config(generator, variant, seed)?;
    let out = dir.join(job.folder());
    let opts = RunOptions {
        resume: out.is_dir(),
        cache: Some(dir.join("cache")),
        scope,
    };
    let outcome = super::run_with(&pc, &inputs, &out, &opts, on_event)?;
    Ok((pc, outcome))
}

/// The folder of `seed`'s original scene, which `job` needs: an error naming the job to
/// run first unless it is trained ([`original_done`]).
fn require_original(
    cfg: &AuditConfig,
    dataset: &Path,
    dir: &Path,
    job: &Job,
    seed: u32,
) -> Result<PathBuf> {
    let run = dir.join(Job::Original { seed }.name());
    if !original_done(cfg, dataset, &run, seed) {
        return Err(Error::invalid(format!(
            "job {} needs the original scene of seed {seed}: run the job {} first",
            job.name(),
            Job::Original { seed }.name()
        ))
        .at(dir));
    }
    Ok(run)
}

/// The original scene of `seed` is trained in `run`: its manifest names this dataset and
/// every file it lists has its hash, and its configuration is this audit's.
fn original_done(cfg: &AuditConfig, dataset: &Path, run: &Path, seed: u32) -> bool {
    let Ok(m) = crate::io::manifest::Manifest::read(run) else {
        return false;
    };
    let same_path = |a: &Path, b: &Path| match (a.canonicalize(), b.canonicalize()) {
        (Ok(x), Ok(y)) => x == y,
        _ => a == b,
    };
    let same_data = m
        .inputs
        .get("dataset")
        .and_then(|d| d.as_str())
        .is_some_and(|d| same_path(Path::new(d), dataset));
    same_data
        && m.files.iter().all(|f| {
            std::fs::read(run.join(&f.path)).is_ok_and(|b| crate::io::sha256_hex(&b) == f.sha256)
        })
        && latest_ply(run).is_ok()
        && read_config(run).is_ok_and(|c| c == cfg.train_config(seed))
}

/// What every job needs, checked before the first job starts (an audit runs for hours):
/// the dataset's candidate and evaluation poses, readable, and an output path that is
/// not a file.
fn check_inputs(dataset: &Path, dir: &Path) -> Result<()> {
    if dir.is_file() {
        return Err(Error::invalid("the output path is a file").at(dir));
    }
    for f in ["candidates.json", "evaluation.json"] {
        let p = dataset.join(f);
        if !p.is_file() {
            return Err(Error::invalid(format!(
                "an audit needs {f} (candidate and evaluation poses with ground truth)"
            ))
            .at(dataset));
        }
        crate::camera::inria::read_cameras_json(&p)?;
    }
    Ok(())
}

/// Iterations between checkpoints of an original-scene training (a killed audit loses at
/// most this many iterations of it).
const ORIGINAL_CHECKPOINT_EVERY: u32 = 1000;

fn original(
    cfg: &AuditConfig,
    dataset: &Path,
    dir: &Path,
    seed: u32,
    on_event: &(dyn Fn(Event) + Sync),
) -> Result<PathBuf> {
    let run = dir.join(Job::Original { seed }.name());
    if original_done(cfg, dataset, &run, seed) {
        // A kill between the manifest and the checkpoint's removal leaves the latter.
        let _ = std::fs::remove_file(checkpoint_path(&run));
        on_event(Event::StepSkipped {
            step: Job::Original { seed }.name(),
        });
        return Ok(run);
    }
    let tc = cfg.train_config(seed);
    // An interrupted training of this config continues from its checkpoint (same bits,
    // SPEC.md §14.8); anything else there is started again.
    let resumable = checkpoint_path(&run).is_file() && read_config(&run).is_ok_and(|c| c == tc);
    if run.exists() && !resumable {
        std::fs::remove_dir_all(&run).map_err(|e| Error::io(&run, e))?;
    }
    let step = Job::Original { seed }.name();
    on_event(Event::StepStarted { step: step.clone() });
    let t0 = std::time::Instant::now();
    let train = |resume: bool| {
        let checkpoints = Checkpointing {
            every: ORIGINAL_CHECKPOINT_EVERY,
            resume,
        };
        train_run(dataset, &run, &tc, None, checkpoints, &mut |p| {
            if p.iteration % 50 == 0 || p.iteration == tc.iterations {
                on_event(Event::Iterations {
                    step: step.clone(),
                    done: p.iteration,
                    total: tc.iterations,
                    loss: p.loss,
                });
            }
        })
    };
    if let Err(e) = train(resumable) {
        if !resumable {
            return Err(e);
        }
        // A checkpoint that does not continue this training (another build's numerics,
        // another dataset, a damaged file): start again rather than fail every audit.
        on_event(Event::Note(format!(
            "{step}: not resumed ({e}); training again"
        )));
        std::fs::remove_dir_all(&run).map_err(|e| Error::io(&run, e))?;
        train(false)?;
    }
    on_event(Event::StepFinished {
        step,
        seconds: t0.elapsed().as_secs_f64(),
    });
    Ok(run)
}

/// The metric a claim compares (on the evaluation poses, final scene of each variant).
#[derive(Clone, Copy, Debug, PartialEq, Eq, serde::Serialize)]
#[serde(rename_all = "snake_case")]
pub enum Metric {
    PsnrAll,
    PsnrExisting,
    PsnrExtrapolated,
}

impl Metric {
    fn of(self, r: &Row) -> f64 {
        match self {
            Metric::PsnrAll => r.psnr_all,
            Metric::PsnrExisting => r.psnr_existing,
            Metric::PsnrExtrapolated => r.psnr_extrapolated,
        }
    }

    /// The per-view sums of the metric's pixel class.
    fn class(self, v: &ViewRecord) -> &ClassSums {
        match self {
            Metric::PsnrAll => &v.all,
            Metric::PsnrExisting => &v.existing,
            Metric::PsnrExtrapolated => &v.extrapolated,
        }
    }

    fn label(self) -> &'static str {
        match self {
            Metric::PsnrAll => "PSNR all",
            Metric::PsnrExisting => "PSNR existing",
            Metric::PsnrExtrapolated => "PSNR extrapolated",
        }
    }
}

/// How a claim compares the full method with a variant.
#[derive(Clone, Copy, Debug, PartialEq, Eq, serde::Serialize)]
#[serde(rename_all = "snake_case")]
pub enum Direction {
    /// The full method is better.
    Beats,
    /// The full method is not worse.
    DoesNotHurt,
}

/// A claim of the paper: the full method against one variant on one metric.
#[derive(Clone, Copy, Debug, serde::Serialize)]
pub struct Claim {
    pub id: &'static str,
    pub variant: Variant,
    pub metric: Metric,
    pub direction: Direction,
    /// What the paper reports (and where).
    pub paper: &'static str,
}

/// The claims the audit tests (SPEC.md §21.2).
pub const CLAIMS: [Claim; 12] = [
    Claim {
        id: "independent views",
        variant: Variant::EvenViews,
        metric: Metric::PsnrAll,
        direction: Direction::Beats,
        paper: "Table 4, ScanNet++ PSNR: 23.79 vs 20.27 (−3.52 dB)",
    },
    Claim {
        id: "depth supervision",
        variant: Variant::NoDepthSupervision,
        metric: Metric::PsnrAll,
        direction: Direction::Beats,
        paper: "Table 4, ScanNet++ PSNR: 23.79 vs 23.66 (−0.13 dB)",
    },
    Claim {
        id: "QA-Mask SH 5 over SH 3",
        variant: Variant::QaSh3,
        metric: Metric::PsnrAll,
        direction: Direction::Beats,
        paper: "Table 4, ScanNet++ PSNR: 23.79 vs 22.45 (−1.34 dB)",
    },
    Claim {
        id: "QA-Mask SH 5 over SH 4",
        variant: Variant::QaSh4,
        metric: Metric::PsnrAll,
        direction: Direction::Beats,
        paper: "Table 4, ScanNet++ PSNR: 23.79 vs 23.28 (−0.51 dB)",
    },
    Claim {
        id: "QA-Mask (whole image)",
        variant: Variant::NoQaMask,
        metric: Metric::PsnrAll,
        direction: Direction::Beats,
        paper: "Table 4, Mip-NeRF 360 CLIP-IQA: 0.404 vs 0.343 (no PSNR given)",
    },
    Claim {
        id: "DIBR propagation",
        variant: Variant::NoPropagation,
        metric: Metric::PsnrAll,
        direction: Direction::Beats,
        paper: "Table 4, Mip-NeRF 360 CLIP-IQA: 0.404 vs 0.316 (no PSNR given)",
    },
    Claim {
        id: "QA-Mask protects existing regions",
        variant: Variant::NoQaMask,
        metric: Metric::PsnrExisting,
        direction: Direction::Beats,
        paper: "Table 3, existing PSNR: DiFix3D+ 28.11 → 28.58, GenFusion 26.49 → 28.33",
    },
    Claim {
        id: "QA-Mask does not hurt extrapolation",
        variant: Variant::NoQaMask,
        metric: Metric::PsnrExtrapolated,
        direction: Direction::DoesNotHurt,
        paper: "Table 3, extrapolated PSNR: DiFix3D+ 10.23 → 10.20, GenFusion 15.04 → 15.10",
    },
    Claim {
        id: "QA-Mask over opacity maps, existing",
        variant: Variant::OpacityMask,
        metric: Metric::PsnrExisting,
        direction: Direction::Beats,
        paper: "Table 3, existing PSNR: DiFix3D+ 28.15 → 28.58, GenFusion 28.03 → 28.33",
    },
    Claim {
        id: "QA-Mask over opacity maps, extrapolated",
        variant: Variant::OpacityMask,
        metric: Metric::PsnrExtrapolated,
        direction: Direction::DoesNotHurt,
        paper: "Table 3, extrapolated PSNR: DiFix3D+ 10.17 → 10.20, GenFusion 15.04 → 15.10",
    },
    Claim {
        id: "interpolation stage",
        variant: Variant::NoInterpolation,
        metric: Metric::PsnrAll,
        direction: Direction::Beats,
        paper: "§3.3.3 (design; no ablation number)",
    },
    Claim {
        id: "video depth for dependent views",
        variant: Variant::Stage2RenderFit,
        metric: Metric::PsnrAll,
        direction: Direction::Beats,
        paper: "§3.3 (design: DIBR-based video depth alignment 'throughout the process'; no ablation number)",
    },
];

/// A claim tested under one generator (SPEC.md §21.2).
#[derive(Clone, Debug, serde::Serialize)]
pub struct Verdict {
    #[serde(flatten)]
    pub claim: Claim,
    pub generator: String,
    /// The Holm family: the room × generator family (`classical`, `truth`).
    pub family: String,
    /// Paired units (a seed at a numerics revision) with both runs and a finite
    /// difference, and the revisions among them.
    pub seeds: usize,
    pub revisions: Vec<u32>,
    /// Mean and sample standard deviation of `full − variant` over the units (std is NaN,
    /// `null` in JSON, with one).
    pub mean_diff: f64,
    #[serde(with = "crate::io::json_float")]
    pub std_diff: f64,
    /// The value the test compares Δ with: 0, or `−margin` for a "does not hurt" claim.
    pub null: f64,
    /// The t interval (two-sided, level `1 − α`, before the family's correction) and what
    /// the p-value comes from; absent with one unit.
    pub method: Option<stats::Method>,
    pub ci: Option<[f64; 2]>,
    /// The BCa interval (from [`stats::Rule::bootstrap_from`] units).
    pub bca: Option<[f64; 2]>,
    /// Holm-adjusted two-sided p-value of the null value.
    #[serde(with = "crate::io::json_float")]
    pub p_holm: f64,
    /// The smallest true distance from the null value found with the rule's power at the
    /// family's first Holm level, for the measured spread.
    #[serde(with = "crate::io::json_float")]
    pub min_detectable: f64,
    /// Percentile interval of a bootstrap over units, then over the evaluation views of
    /// each unit (pooled PSNR of the resampled views), over the `hierarchical_units`
    /// units with per-view records; absent with fewer than two.
    pub hierarchical: Option<[f64; 2]>,
    pub hierarchical_units: usize,
    /// `holds`, `contradicted`, `inconclusive`, or `inconclusive (1 seed)`.
    pub verdict: String,
}

/// Mean and sample standard deviation (NaN for fewer than 2 values).
fn mean_std(v: &[f64]) -> (f64, f64) {
    let n = v.len() as f64;
    let m = v.iter().sum::<f64>() / n;
    if v.len() < 2 {
        return (m, f64::NAN);
    }
    let var = v.iter().map(|x| (x - m) * (x - m)).sum::<f64>() / (n - 1.0);
    (m, var.sqrt())
}

/// A stable seed for a claim's bootstraps: the first 64 bits of SHA-256 of its names.
fn bootstrap_seed(claim: &Claim, generator: &str, what: &str) -> u64 {
    let h = crate::io::sha256_hex(format!("{what}\0{}\0{generator}", claim.id).as_bytes());
    u64::from_str_radix(&h[..16], 16).expect("hex")
}

/// Replicates of the hierarchical bootstrap.
pub const HIERARCHICAL_REPLICATES: usize = 2000;

/// The hierarchical bootstrap's 95 % percentile interval of the mean paired difference
/// of `metric`: units resampled with replacement, then each unit's evaluation views
/// (the same views for both runs of the pair), the metric recomputed as pooled PSNR of
/// the resampled views. Units without per-view records (or with different view lists)
/// are left out; `None` below two units.
fn hierarchical(
    pairs: &[Pair],
    metric: Metric,
    alpha: f64,
    seed: u64,
) -> (Option<[f64; 2]>, usize) {
    let units: Vec<(&[ViewRecord], &[ViewRecord])> = pairs
        .iter()
        .map(|p| (&p.full.last.views[..], &p.variant.last.views[..]))
        .filter(|(a, b)| {
            !a.is_empty()
                && a.len() == b.len()
                && a.iter().zip(b.iter()).all(|(x, y)| x.view == y.view)
        })
        .collect();
    let n = units.len();
    if n < 2 {
        return (None, n);
    }
    let mut u = crate::rng::Uniform::new(seed);
    let mut reps = Vec::with_capacity(HIERARCHICAL_REPLICATES);
    let mut picks: Vec<usize> = Vec::new();
    for _ in 0..HIERARCHICAL_REPLICATES {
        let (mut sum, mut count) = (0.0, 0usize);
        for _ in 0..n {
            let (a, b) = units[u.below(n as u32) as usize];
            picks.clear();
            picks.extend((0..a.len()).map(|_| u.below(a.len() as u32) as usize));
            let pa = ClassSums::psnr(picks.iter().map(|&i| metric.class(&a[i])));
            let pb = ClassSums::psnr(picks.iter().map(|&i| metric.class(&b[i])));
            let d = pa - pb;
            if d.is_finite() {
                sum += d;
                count += 1;
            }
        }
        if count > 0 {
            reps.push(sum / count as f64);
        }
    }
    if reps.is_empty() {
        return (None, n);
    }
    reps.sort_by(f64::total_cmp);
    let at = |q: f64| stats::quantile_sorted(&reps, q);
    (Some([at(alpha / 2.0), at(1.0 - alpha / 2.0)]), n)
}

/// One draw of a claim's pair: a seed at a numerics revision (SPEC.md §21.2; the unit of
/// the test is the seed, [`seed_means`]).
#[derive(Clone, Debug, PartialEq)]
pub struct Pair<'a> {
    pub seed: u32,
    pub revision: u32,
    pub full: &'a JobResult,
    pub variant: &'a JobResult,
}

/// The pairs (full, `variant`) of `generator` in `pool`: both runs of one seed at one
/// numerics revision, in (seed, revision) order. Pairs of one seed at several revisions
/// count once, at the newest revision, when either run is bit for bit the same (a
/// revision that did not change it; metrics compared, per-view records aside): an
/// independent draw needs both runs to differ.
pub fn pairs<'a>(pool: &'a [JobResult], generator: &str, variant: Variant) -> Vec<Pair<'a>> {
    let cell = |v: Variant| {
        pool.iter()
            .filter(move |r| r.generator == generator && r.variant == v.name())
    };
    let mut out: Vec<Pair<'a>> = Vec::new();
    for full in cell(Variant::Full) {
        let Some(other) = cell(variant)
            .find(|r| r.seed == full.seed && r.numerics_revision == full.numerics_revision)
        else {
            continue;
        };
        out.push(Pair {
            seed: full.seed,
            revision: full.numerics_revision,
            full,
            variant: other,
        });
    }
    // Newest revision first, so that of two bit-identical draws the one kept is the newer
    // (which carries the per-view records of later versions).
    out.sort_by_key(|p| (p.seed, std::cmp::Reverse(p.revision)));
    let bits = |r: &JobResult| serde_json::to_string(&metrics_only(&r.last)).expect("serializes");
    let mut kept: Vec<Pair<'a>> = Vec::new();
    for p in out {
        // Another revision's pair is an independent draw only if neither run reproduces
        // the kept pair's: a pair sharing one run with it would be correlated with it.
        let same = kept.iter().any(|q| {
            q.seed == p.seed && (bits(q.full) == bits(p.full) || bits(q.variant) == bits(p.variant))
        });
        if !same {
            kept.push(p);
        }
    }
    kept.sort_by_key(|p| (p.seed, p.revision));
    kept
}

/// The unit of the test is the seed: per seed, the mean of its pairs' differences
/// `full − variant` over the revisions that drew it (`pairs` in (seed, revision) order).
/// Two draws of one seed at different revisions share the seed's random streams and are
/// correlated (measured between revisions 2 and 4: r = 0.27 [0.07, 0.45] on gallery,
/// −0.08 [−0.28, 0.12] on lounge; SPEC.md §21.2), so a revision adds precision to its seed,
/// not a unit.
pub fn seed_means(pairs: &[Pair], metric: Metric) -> Vec<f64> {
    let mut out = Vec::new();
    let mut k = 0;
    while k < pairs.len() {
        let seed = pairs[k].seed;
        let group: Vec<f64> = pairs[k..]
            .iter()
            .take_while(|p| p.seed == seed)
            .map(|p| metric.of(&p.full.last) - metric.of(&p.variant.last))
            .collect();
        k += group.len();
        out.push(group.iter().sum::<f64>() / group.len() as f64);
    }
    out
}

/// Per seed, its pair at the newest revision (the hierarchical bootstrap's unit).
fn newest_per_seed<'a>(pairs: &[Pair<'a>]) -> Vec<Pair<'a>> {
    let mut out: Vec<Pair<'a>> = Vec::new();
    for p in pairs {
        match out.last_mut() {
            Some(q) if q.seed == p.seed => *q = p.clone(),
            _ => out.push(p.clone()),
        }
    }
    out
}

/// A row's metrics without its per-view records (what two draws are compared on: a sample
/// written before the records existed has the same metrics bits without them).
fn metrics_only(r: &Row) -> Row {
    Row {
        views: Vec::new(),
        ..r.clone()
    }
}

/// Every claim whose variant was run, per generator, judged by `rule` within each
/// generator family (SPEC.md §21.2).
pub fn verdicts(cfg: &AuditConfig, pool: &[JobResult], rule: &stats::Rule) -> Vec<Verdict> {
    struct Cell<'a> {
        claim: Claim,
        generator: GeneratorKind,
        pairs: Vec<Pair<'a>>,
        diffs: Vec<f64>,
    }
    let mut cells = Vec::new();
    for claim in CLAIMS {
        if !cfg.variants.contains(&claim.variant) {
            continue;
        }
        for &generator in &cfg.generators {
            // Samples of another pipeline configuration of these cells measure something
            // else ([`JobResult::config`]; empty: recorded before configurations were, by a
            // binary whose method revision 5 changed, so another one).
            let (full_cfg, variant_cfg) = match (
                cfg.config_digest(generator, Variant::Full),
                cfg.config_digest(generator, claim.variant),
            ) {
                (Ok(a), Ok(b)) => (a, b),
                _ => continue,
            };
            let same_config = |r: &JobResult, want: &str| r.config == want;
            let pairs: Vec<Pair> = pairs(pool, &generator.name(), claim.variant)
                .into_iter()
                .filter(|p| same_config(p.full, &full_cfg) && same_config(p.variant, &variant_cfg))
                .filter(|p| {
                    let d = claim.metric.of(&p.full.last) - claim.metric.of(&p.variant.last);
                    d.is_finite()
                })
                .collect();
            if pairs.is_empty() {
                continue;
            }
            let diffs = seed_means(&pairs, claim.metric);
            cells.push(Cell {
                claim,
                generator,
                pairs,
                diffs,
            });
        }
    }
    let null = |c: &Claim| match c.direction {
        Direction::Beats => 0.0,
        Direction::DoesNotHurt => -rule.margin,
    };
    let mut out: Vec<Option<Verdict>> = cells.iter().map(|_| None).collect();
    for family in ["classical", "truth"] {
        let members: Vec<usize> = (0..cells.len())
            .filter(|&i| cells[i].generator.family() == family)
            .collect();
        let data: Vec<stats::ClaimData> = members
            .iter()
            .map(|&i| {
                let c = &cells[i];
                stats::ClaimData {
                    diffs: &c.diffs,
                    null: null(&c.claim),
                    seed: bootstrap_seed(&c.claim, &c.generator.name(), "bca"),
                }
            })
            .collect();
        for (&i, j) in members.iter().zip(rule.judge(&data)) {
            let c = &cells[i];
            let g = c.generator.name();
            let (mean, std) = mean_std(&c.diffs);
            let mut revisions: Vec<u32> = c.pairs.iter().map(|p| p.revision).collect();
            revisions.sort_unstable();
            revisions.dedup();
            let (hier, hier_units) = hierarchical(
                &newest_per_seed(&c.pairs),
                c.claim.metric,
                rule.alpha,
                bootstrap_seed(&c.claim, &g, "hierarchical"),
            );
            let verdict = if j.test.is_none() {
                "inconclusive (1 seed)".to_string()
            } else {
                j.outcome.word().to_string()
            };
            out[i] = Some(Verdict {
                claim: c.claim,
                family: family.into(),
                generator: g,
                seeds: c.diffs.len(),
                revisions,
                mean_diff: mean,
                std_diff: std,
                null: null(&c.claim),
                method: j.test.map(|t| t.method),
                ci: j.test.map(|t| [t.lo, t.hi]),
                bca: j.test.and_then(|t| t.bca),
                p_holm: j.p_holm,
                min_detectable: j.min_detectable(rule),
                hierarchical: hier,
                hierarchical_units: hier_units,
                verdict,
            });
        }
    }
    out.into_iter().flatten().collect()
}

/// What `audit.json` holds.
#[derive(Clone, Debug, serde::Serialize)]
pub struct Report {
    /// The binary that made the report: samples of other revisions are pooled (each
    /// sample names its own, in `samples.json`).
    pub crate_version: String,
    pub numerics_revision: u32,
    #[serde(flatten)]
    pub provenance: samples::Provenance,
    /// Distinct seeds and numerics revisions of the pooled samples.
    pub seeds: Vec<u32>,
    pub revisions: Vec<u32>,
    pub samples: usize,
    /// Samples of another pipeline configuration of their (generator, variant) than this
    /// binary's: kept in `samples.json`, left out of every verdict.
    pub other_config: usize,
    pub generators: Vec<String>,
    pub variants: Vec<String>,
    /// The verdict rule's parameters.
    pub rule: stats::Rule,
    pub verdicts: Vec<Verdict>,
    /// This batch's job results (with their steps): what the step cache saved.
    #[serde(skip)]
    pub results: Vec<JobResult>,
    /// Every pooled sample.
    #[serde(skip)]
    pub pool: Vec<JobResult>,
}

/// The samples an audit of `cfg` in `dir` pools with its own batch: `dir`'s
/// [`samples::SAMPLES_FILE`] and every `merge` file (another audit's samples, or an
/// `audit.json` of an earlier version). Read before any job runs, so that a file that
/// cannot be pooled fails the audit at once.
fn gather(cfg: &AuditConfig, dataset: &Path, dir: &Path, merge: &[PathBuf]) -> Result<Samples> {
    let mut pool = Samples::new(samples::Provenance {
        dataset: samples::dataset_name(dataset),
        dataset_digest: samples::dataset_digest(dataset)?,
        preset: cfg.base.preset.clone(),
        train_iterations: cfg.train_iterations,
        train_resolution: cfg.train_resolution,
    });
    let own = dir.join(samples::SAMPLES_FILE);
    let mut files: Vec<PathBuf> = merge.to_vec();
    if own.is_file() {
        files.insert(0, own);
    }
    for f in files {
        let s = Samples::read(&f)?;
        pool.pool(s, &f)?;
    }
    Ok(pool)
}

/// Run every job of `cfg` that is not done (each resumes its own folder), pool the
/// results with the samples already in `dir` and in `merge` files, then write
/// `DIR/samples.json`, `DIR/audit.json`, `DIR/audit.md` and `DIR/inconsistency.svg`.
pub fn run(
    cfg: &AuditConfig,
    dataset: &Path,
    dir: &Path,
    merge: &[PathBuf],
    on_event: &(dyn Fn(Event) + Sync),
) -> Result<Report> {
    cfg.validate()?;
    check_inputs(dataset, dir)?;
    let pool = gather(cfg, dataset, dir, merge)?;
    crate::io::create_dir_all(dir)?;
    let mut results = Vec::new();
    for job in jobs(cfg) {
        if let Some(r) = run_job(cfg, dataset, dir, &job, on_event)? {
            results.push(r);
        }
    }
    finish(cfg, dir, pool, results)
}

/// The report of the samples in `dir` and `merge` files alone (no job runs).
pub fn report(cfg: &AuditConfig, dataset: &Path, dir: &Path, merge: &[PathBuf]) -> Result<Report> {
    cfg.validate()?;
    check_inputs(dataset, dir)?;
    let pool = gather(cfg, dataset, dir, merge)?;
    if pool.samples.is_empty() {
        return Err(Error::invalid(format!(
            "no samples to report (no {} here and no --merge file)",
            samples::SAMPLES_FILE
        ))
        .at(dir));
    }
    crate::io::create_dir_all(dir)?;
    finish(cfg, dir, pool, Vec::new())
}

fn finish(
    cfg: &AuditConfig,
    dir: &Path,
    mut pool: Samples,
    results: Vec<JobResult>,
) -> Result<Report> {
    for r in &results {
        pool.insert(r.clone());
    }
    pool.write(&dir.join(samples::SAMPLES_FILE))?;
    let rule = stats::Rule::default();
    let (seeds, revisions) = pool.seeds_and_revisions();
    let names = |mut v: Vec<String>| {
        v.dedup();
        v
    };
    // Samples of another configuration of their cell than this binary's are kept in the
    // file and left out of everything reported.
    let other = |r: &JobResult| {
        let (Ok(g), Ok(v)) = (
            GeneratorKind::by_name(&r.generator),
            Variant::by_name(&r.variant),
        ) else {
            return false;
        };
        cfg.config_digest(g, v).is_ok_and(|d| d != r.config)
    };
    let total = pool.samples.len();
    let usable: Vec<JobResult> = pool.samples.into_iter().filter(|r| !other(r)).collect();
    let report = Report {
        crate_version: env!("CARGO_PKG_VERSION").into(),
        numerics_revision: crate::version::NUMERICS_REVISION,
        provenance: pool.provenance.clone(),
        seeds,
        revisions,
        samples: usable.len(),
        other_config: total - usable.len(),
        generators: names(cfg.generators.iter().map(|g| g.name()).collect()),
        variants: names(cfg.variants.iter().map(|v| v.name().to_string()).collect()),
        verdicts: verdicts(cfg, &usable, &rule),
        rule,
        results,
        pool: usable,
    };
    let json = serde_json::to_string_pretty(&report).expect("serializes") + "\n";
    crate::io::write_text(&dir.join("audit.json"), &json)?;
    crate::io::write_text(&dir.join("inconsistency.svg"), &plot(cfg, &report.pool))?;
    crate::io::write_text(&dir.join("audit.md"), &markdown(cfg, &report))?;
    Ok(report)
}

/// `mean ± std` over the seeds of one (generator, variant), or `mean` with one seed.
fn stat(results: &[&JobResult], f: impl Fn(&JobResult) -> f64, digits: usize) -> String {
    let v: Vec<f64> = results.iter().map(|r| f(r)).collect();
    let (m, s) = mean_std(&v);
    let m = crate::io::json_float::show(m, digits);
    if s.is_finite() {
        format!("{m} ± {s:.digits$}")
    } else {
        m
    }
}

/// The distinct samples of one (generator, variant) in pool order (a sample another
/// revision reproduced bit for bit counts once).
fn group<'a>(results: &'a [JobResult], generator: &str, variant: Variant) -> Vec<&'a JobResult> {
    let bits = |r: &JobResult| serde_json::to_string(&metrics_only(&r.last)).expect("serializes");
    let mut out: Vec<&JobResult> = Vec::new();
    for r in results
        .iter()
        .filter(|r| r.generator == generator && r.variant == variant.name())
    {
        if !out.iter().any(|o| o.seed == r.seed && bits(o) == bits(r)) {
            out.push(r);
        }
    }
    out
}

/// `0–11, 14` for seeds 0..=11 and 14.
fn seed_ranges(seeds: &[u32]) -> String {
    let mut parts = Vec::new();
    let mut i = 0;
    while i < seeds.len() {
        let mut j = i;
        while j + 1 < seeds.len() && seeds[j].checked_add(1) == Some(seeds[j + 1]) {
            j += 1;
        }
        parts.push(if j > i {
            format!("{}–{}", seeds[i], seeds[j])
        } else {
            seeds[i].to_string()
        });
        i = j + 1;
    }
    parts.join(", ")
}

/// The six metric cells of a table row (PSNR existing, extrapolated, all; SSIM existing,
/// extrapolated; train-half PSNR) of the scene `pick` selects, over the seeds.
fn metric_cells(rows: &[&JobResult], pick: impl Fn(&JobResult) -> &Row) -> String {
    [
        stat(rows, |r| pick(r).psnr_existing, 2),
        stat(rows, |r| pick(r).psnr_extrapolated, 2),
        stat(rows, |r| pick(r).psnr_all, 2),
        stat(rows, |r| pick(r).ssim_existing, 4),
        stat(rows, |r| pick(r).ssim_extrapolated, 4),
        stat(rows, |r| pick(r).psnr_train_half, 2),
    ]
    .join(" | ")
}

/// `audit.md`.
pub fn markdown(cfg: &AuditConfig, report: &Report) -> String {
    let revisions: Vec<String> = report.revisions.iter().map(|r| r.to_string()).collect();
    let mut s = format!(
        "# Audit of the paper's claims\n\nDataset `{}`; preset `{}`; {} seeds ({}) in {} samples at numerics revision{} {}; original scene: {} iterations at resolution 1/{} on the training half. Metrics on the evaluation poses, pixels split into *existing* (seen by the training half) and *extrapolated*. Made by `unseen audit` (SPEC.md §21), crate {} at numerics revision {}; the samples are in `samples.json` (a later batch of seeds adds to them).\n\n",
        report.provenance.dataset,
        report.provenance.preset,
        report.seeds.len(),
        seed_ranges(&report.seeds),
        report.samples,
        if revisions.len() > 1 { "s" } else { "" },
        revisions.join(", "),
        report.provenance.train_iterations,
        report.provenance.train_resolution,
        report.crate_version,
        report.numerics_revision
    );
    if report.other_config > 0 {
        s += &format!(
            "**{} samples ran another pipeline configuration** than this binary's for their generator and variant (another version of the preset): kept in `samples.json`, left out of every verdict and table.\n\n",
            report.other_config
        );
    }
    let r = &report.rule;
    s += &format!(
        "## Claims\n\n**How to read this.** Δ = full − variant (dB), one value per seed: both runs of a seed start from the same original scene with the same random numbers, so Δ is paired; the same seed at another numerics revision is another draw when both of its runs changed (a pair sharing a run's bits with one already counted counts once), and a seed's Δ is the mean of its draws (draws of one seed are correlated: the seed is the unit). *95 % CI*: Student's t with n − 1 degrees of freedom; from {} seeds a verdict also needs the BCa bootstrap over seeds ({} replicates, seeded; its interval in *BCa*) to agree, since the bootstrap alone is too liberal at these sizes (SPEC.md §21.2). A claim that the full method is better **holds** when Δ is significantly above 0 and is **contradicted** when it is significantly below; a claim that the full method *does not hurt* (non-inferiority) holds when Δ is significantly above −{} dB (the margin) and is contradicted when significantly below it. *Significantly*: the two-sided p-value of that null value, after Holm's correction over the claims of the same generator family (classical; truth at every level) on this dataset, is below α = {}. Otherwise **inconclusive**: the *MDE* column is the smallest true distance from the null value that this many seeds find with {:.0} % power at the family's strictest Holm level, for the measured spread — an effect smaller than that could be there. *Hierarchical*: a 95 % percentile interval from resampling seeds, then each seed's evaluation views (pooled PSNR), over the seeds with per-view records: wider than the seed CI where views disagree. The paper's numbers are from ScanNet++ / Mip-NeRF 360 with diffusion generators: compare directions, not values.\n\n| claim | metric | paper | generator | n | Δ (dB) | 95 % CI | BCa | hierarchical | p (Holm) | MDE (dB) | verdict |\n|---|---|---|---|---|---|---|---|---|---|---|---|\n",
        r.bootstrap_from,
        r.replicates,
        r.margin,
        r.alpha,
        100.0 * r.power
    );
    let interval = |ci: Option<[f64; 2]>| {
        ci.map_or_else(
            || "–".to_string(),
            |[lo, hi]| format!("[{lo:+.2}, {hi:+.2}]"),
        )
    };
    let num = |x: f64, digits: usize| {
        if x.is_finite() {
            format!("{x:.digits$}")
        } else {
            "–".into()
        }
    };
    for v in &report.verdicts {
        let null = if v.null != 0.0 {
            format!(" (vs {:+.1})", v.null)
        } else {
            String::new()
        };
        s += &format!(
            "| {} | {} | {} | {} | {} | {:+.2}{null} | {} | {} | {} | {} | {} | **{}** |\n",
            v.claim.id,
            v.claim.metric.label(),
            v.claim.paper,
            v.generator,
            v.seeds,
            v.mean_diff,
            interval(v.ci),
            interval(v.bca),
            interval(v.hierarchical),
            if v.p_holm.is_finite() {
                format!("{:.3}", v.p_holm)
            } else {
                "–".into()
            },
            num(v.min_detectable, 2),
            v.verdict
        );
    }
    s += "\n## Every variant\n\n| generator | variant | PSNR existing | PSNR extrapolated | PSNR all | SSIM existing | SSIM extrapolated | train-half PSNR | compute (s) |\n|---|---|---|---|---|---|---|---|---|\n";
    for g in &cfg.generators {
        let g = g.name();
        let rows = group(&report.pool, &g, Variant::Full);
        if !rows.is_empty() {
            s += &format!(
                "| {g} | *original scene* | {} | |\n",
                metric_cells(&rows, |r| &r.original)
            );
        }
        for v in &cfg.variants {
            let rows = group(&report.pool, &g, *v);
            if rows.is_empty() {
                continue;
            }
            s += &format!(
                "| {g} | {} | {} | {} |\n",
                v.name(),
                metric_cells(&rows, |r| &r.last),
                stat(&rows, |r| r.stage_seconds.values().sum(), 0),
            );
        }
    }
    s += "\n*compute*: the seconds each step took where it was computed; steps shared through the cache are counted in every variant that uses them.\n\n## Compute per stage (s, mean over seeds)\n\n";
    let stages = [
        "views",
        "qa-mask",
        "stage1",
        "stage2",
        "interpolate",
        "eval",
    ];
    s += &format!(
        "| generator | variant | {} |\n|---|---|{}\n",
        stages.join(" | "),
        "---|".repeat(stages.len())
    );
    for g in &cfg.generators {
        let g = g.name();
        for v in &cfg.variants {
            let rows = group(&report.pool, &g, *v);
            if rows.is_empty() {
                continue;
            }
            let cells: Vec<String> = stages
                .iter()
                .map(|st| {
                    let t: f64 = rows
                        .iter()
                        .map(|r| r.stage_seconds.get(*st).copied().unwrap_or(0.0))
                        .sum::<f64>()
                        / rows.len() as f64;
                    format!("{t:.1}")
                })
                .collect();
            s += &format!("| {g} | {} | {} |\n", v.name(), cells.join(" | "));
        }
    }
    let shared = sharing(&report.results);
    if !shared.is_empty() {
        s += "\n## What the step cache saves\n\nSteps whose inputs are equal (same manifest digest) are computed once and reused by every job that needs them (SPEC.md §20.8). *executions*: steps over all jobs; *distinct*: different steps; compute in seconds if every job computed its own steps, and with each distinct step computed once (what a fresh audit computes; a resumed audit, parallel `--only` workers or a cache from an earlier audit may have computed some twice or none here). The original scenes (one training per seed) are not counted.\n\n| stage | executions | distinct | every job its own (s) | each distinct step once (s) | saved |\n|---|---|---|---|---|---|\n";
        for r in &shared {
            let saved = if r.unshared_seconds > 0.0 {
                format!(
                    "{:.0} %",
                    100.0 * (1.0 - r.shared_seconds / r.unshared_seconds)
                )
            } else {
                "–".into()
            };
            s += &format!(
                "| {} | {} | {} | {:.1} | {:.1} | {saved} |\n",
                r.stage, r.executions, r.distinct, r.unshared_seconds, r.shared_seconds
            );
        }
    }
    s += "\n![PSNR against the generator's inconsistency](inconsistency.svg)\n";
    s
}

/// Existing and extrapolated PSNR of full / w/o QA-Mask / opacity mask against the
/// ground-truth generator's inconsistency level (mean over seeds), as an SVG.
pub fn plot(cfg: &AuditConfig, results: &[JobResult]) -> String {
    let levels = ["none", "low", "high"];
    let series = [
        (Variant::Full, "#1f77b4"),
        (Variant::NoQaMask, "#d62728"),
        (Variant::OpacityMask, "#2ca02c"),
    ];
    let truth: Vec<GeneratorKind> = cfg
        .generators
        .iter()
        .copied()
        .filter(|g| g.level().is_some())
        .collect();
    // Mean and std over seeds of one (generator, variant, metric).
    let point = |g: GeneratorKind, v: Variant, m: Metric| {
        let vals: Vec<f64> = group(results, &g.name(), v)
            .iter()
            .map(|r| m.of(&r.last))
            .filter(|x| x.is_finite())
            .collect();
        (!vals.is_empty()).then(|| mean_std(&vals))
    };
    let panels = [Metric::PsnrExisting, Metric::PsnrExtrapolated];
    let mut all = Vec::new();
    for m in panels {
        for (v, _) in series {
            for &g in &truth {
                if let Some((y, sd)) = point(g, v, m) {
                    let sd = if sd.is_nan() { 0.0 } else { sd };
                    all.extend([y - sd, y + sd]);
                }
            }
        }
    }
    let (lo, hi) = if all.is_empty() {
        (0.0, 1.0)
    } else {
        let lo = all.iter().cloned().fold(f64::INFINITY, f64::min);
        let hi = all.iter().cloned().fold(f64::NEG_INFINITY, f64::max);
        ((lo - 1.0).floor(), (hi + 1.0).ceil())
    };
    let (pw, ph, left, top) = (300.0, 220.0, 60.0, 40.0);
    let x_of = |i: usize| left + 30.0 + i as f64 * (pw - 60.0) / 2.0;
    let y_of = |v: f64| top + ph - (v - lo) / (hi - lo) * ph;
    let mut svg = format!(
        "<svg xmlns=\"http://www.w3.org/2000/svg\" width=\"{}\" height=\"{}\" font-family=\"sans-serif\" font-size=\"12\">\n",
        2.0 * (pw + left) + 40.0,
        ph + top + 90.0
    );
    for (k, m) in panels.iter().enumerate() {
        let dx = k as f64 * (pw + left + 20.0);
        svg += &format!("<g transform=\"translate({dx},0)\">\n");
        svg += &format!(
            "<text x=\"{}\" y=\"20\" text-anchor=\"middle\">{} (dB)</text>\n",
            left + pw / 2.0,
            m.label()
        );
        svg += &format!(
            "<rect x=\"{left}\" y=\"{top}\" width=\"{pw}\" height=\"{ph}\" fill=\"none\" stroke=\"#888\"/>\n"
        );
        let step = if hi - lo > 10.0 { 2.0 } else { 1.0 };
        let mut t = lo;
        while t <= hi + 1e-9 {
            svg += &format!(
                "<text x=\"{}\" y=\"{}\" text-anchor=\"end\">{t:.0}</text>\n",
                left - 5.0,
                y_of(t) + 4.0
            );
            t += step;
        }
        for (i, l) in levels.iter().enumerate() {
            svg += &format!(
                "<text x=\"{}\" y=\"{}\" text-anchor=\"middle\">{l}</text>\n",
                x_of(i),
                top + ph + 18.0
            );
        }
        // Series side by side around each level (offset 8 px), ±1 std as a bar.
        for (j, (v, color)) in series.iter().enumerate() {
            let dx = (j as f64 - 1.0) * 8.0;
            let pts: Vec<(f64, f64, f64)> = truth
                .iter()
                .filter_map(|&g| {
                    let (y, sd) = point(g, *v, *m)?;
                    Some((x_of(g.level()?) + dx, y, if sd.is_nan() { 0.0 } else { sd }))
                })
                .collect();
            if pts.len() > 1 {
                let path: Vec<String> = pts
                    .iter()
                    .map(|(x, y, _)| format!("{x:.1},{:.1}", y_of(*y)))
                    .collect();
                svg += &format!(
                    "<polyline points=\"{}\" fill=\"none\" stroke=\"{color}\" stroke-width=\"2\"/>\n",
                    path.join(" ")
                );
            }
            for (x, y, sd) in pts {
                if sd > 0.0 {
                    svg += &format!(
                        "<line x1=\"{x:.1}\" x2=\"{x:.1}\" y1=\"{:.1}\" y2=\"{:.1}\" stroke=\"{color}\"/>\n",
                        y_of(y - sd),
                        y_of(y + sd)
                    );
                }
                svg += &format!(
                    "<circle cx=\"{x:.1}\" cy=\"{:.1}\" r=\"4\" fill=\"{color}\"/>\n",
                    y_of(y)
                );
            }
        }
        svg += "</g>\n";
    }
    for (i, (v, color)) in series.iter().enumerate() {
        let x = left + i as f64 * 170.0;
        let y = top + ph + 50.0;
        svg += &format!(
            "<rect x=\"{x}\" y=\"{}\" width=\"12\" height=\"12\" fill=\"{color}\"/><text x=\"{}\" y=\"{y}\">{}</text>\n",
            y - 10.0,
            x + 18.0,
            v.name()
        );
    }
    svg += &format!(
        "<text x=\"{left}\" y=\"{}\">x: the ground-truth generator's inconsistency level (SPEC.md §20.6); mean ± 1 std over seeds</text>\n</svg>\n",
        top + ph + 75.0
    );
    svg
}
