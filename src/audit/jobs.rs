//! The audit's jobs: which (generator, variant, seed) runs exist, the original scene they
//! share, one job's pipeline run and its result record, and which steps jobs share.

use super::{Audit, AuditConfig, GeneratorKind, Variant, config_digest};
use crate::error::{Error, Result};
use crate::pipeline::evaluate::{Row, Summary};
use crate::pipeline::steps::Step;
use crate::pipeline::{Event, PipelineConfig, RunOptions, Scope};
use crate::train::checkpoint::checkpoint_path;
use crate::train::run::{Checkpointing, latest_ply, read_config, train_run};
use std::path::{Path, PathBuf};

/// One job of an audit: the original scene of a seed, a pipeline run, or (for a batch
/// engine, [`super::cluster::waves`]) the steps a seed's variants share under one generator.
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

/// The file a run job writes its evaluation pixels' classes to, beside `audit_job.json`:
/// one byte per pixel (`CLASS_*` of [`crate::pipeline::evaluate`]), the evaluation views in
/// order; absent where the run generated nothing of the unseen surface.
pub const CLASSES_FILE: &str = "classes.bin";

/// Where a [`Job::Shared`] stops: before this step.
pub const SHARED_BEFORE: Step = Step::Stage1Recon;

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
    /// its seed unless it has the same bits (`pairs`, `seed_means`). 0 / empty in job files
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
    /// SHA-256 of the final scene's PLY: two runs with equal digests evaluated the same
    /// scene, so their pair is the *same computation* (SPEC.md §21.5). Empty in samples
    /// written before it was recorded.
    #[serde(default, skip_serializing_if = "String::is_empty")]
    pub scene_sha256: String,
    /// The final scene's PLY, relative to the job's folder (where the audit's pairs
    /// render it again: [`mod@super::pairs`]). Empty in samples written before it was recorded.
    #[serde(default, skip_serializing_if = "String::is_empty")]
    pub final_scene: String,
    /// This run paired with its seed's `full` run on this run's pixel classes
    /// ([`mod@super::pairs`]): made when an audit finishes with both runs' folders at hand
    /// (`Audit::pair_up`); absent for `full` itself and in samples written before.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub pair: Option<super::pairs::Pair>,
    /// What the run did ([`super::diagnostics`]); absent in samples written before.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub diagnostics: Option<super::diagnostics::Diagnostics>,
    /// The candidate family the run was given (SPEC.md §20.7); absent for the bundled
    /// candidates. `--collect` takes a result only of the audit's own family.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub candidates: Option<super::family::Family>,
    /// Every evaluated scene of the run in order (the original, then each stage's) on the
    /// training half, with its Gaussian count: where original areas change (issue #72).
    /// Empty in samples written before it was recorded.
    #[serde(default, skip_serializing_if = "Vec::is_empty")]
    pub stages: Vec<StageRecord>,
}

/// One evaluated scene of a run (`original`, `stage1`, `stage2`, `interpolate`, or the
/// cycle's): its training-half PSNR and SSIM and its Gaussian count.
#[derive(Clone, Debug, PartialEq, serde::Serialize, serde::Deserialize)]
pub struct StageRecord {
    pub scene: String,
    #[serde(with = "crate::io::json_float")]
    pub psnr_train_half: f64,
    #[serde(with = "crate::io::json_float")]
    pub ssim_train_half: f64,
    pub gaussians: usize,
    /// Where the scene's Gaussians come from (`None`, not written: the original scene, the
    /// cycle's, and runs made before reconstructions recorded their lineage).
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub lineage: Option<crate::pipeline::evaluate::LineageRecord>,
}

impl JobResult {
    /// Whether this sample is what this binary computes for its job under the pipeline
    /// configuration digest `config`: the same numerics revision, crate version and
    /// configuration (the determinism contract then makes the run's bits the same), with
    /// every record a run now makes (the final scene's digest, the diagnostics).
    pub fn reproduces(&self, config: &str) -> bool {
        self.numerics_revision == crate::version::NUMERICS_REVISION
            && self.crate_version == env!("CARGO_PKG_VERSION")
            && self.config == config
            && !self.scene_sha256.is_empty()
            && self.diagnostics.is_some()
    }
}

/// One step of a job: what [`sharing`] counts.
#[derive(Clone, Debug, PartialEq, serde::Serialize, serde::Deserialize)]
pub struct StepCost {
    pub name: String,
    pub digest: String,
    pub seconds: f64,
}

/// Stage names as the audit reports them (`qa/<scene>` is `qa-mask`); a name that is no
/// step (a sample written by another version) is its own stage.
fn stage_of(step: &str) -> String {
    step.parse::<Step>()
        .map_or_else(|_| step.to_string(), |s| s.stage().name().to_string())
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

impl Audit<'_> {
    /// Run (or verify) one job. Originals are trained once per seed and reused; a pipeline job
    /// continues its run directory (verified steps are skipped) and shares `DIR/cache`.
    pub fn run_job(&self, job: &Job) -> Result<Option<JobResult>> {
        let Audit {
            cfg,
            dataset,
            dir,
            on_event,
            ..
        } = *self;
        cfg.validate()?;
        self.check_inputs()?;
        match *job {
            Job::Original { seed } => {
                on_event(Event::Stage { name: job.name() });
                self.original(seed)?;
                Ok(None)
            }
            Job::Shared { generator, seed } => {
                let scope = Scope::Before(SHARED_BEFORE);
                self.pipeline_job(job, (generator, Variant::Full, seed), scope)?;
                Ok(None)
            }
            Job::Run {
                generator,
                variant,
                seed,
            } => {
                let (pc, inputs, outcome) =
                    self.pipeline_job(job, (generator, variant, seed), Scope::All)?;
                let out = dir.join(job.folder());
                let summary: Summary = outcome.metrics.ok_or_else(|| {
                    Error::invalid("the dataset has no evaluation poses (evaluation.json)")
                        .at(dataset)
                })?;
                let (first, last) = match (summary.rows.first(), summary.rows.last()) {
                    (Some(f), Some(l)) => (f.clone(), l.clone()),
                    _ => return Err(Error::invalid("the run evaluated no scene").at(&out)),
                };
                let mut stage_seconds = std::collections::BTreeMap::new();
                let mut steps = Vec::new();
                for step in &outcome.steps {
                    let seconds =
                        std::fs::read(step.dir.join(crate::pipeline::rundir::TIMING_FILE))
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
                let scene = outcome
                    .scene
                    .as_ref()
                    .ok_or_else(|| Error::invalid("the run made no final scene").at(&out))?;
                let scene_sha256 =
                    crate::io::sha256_hex(&std::fs::read(scene).map_err(|e| Error::io(scene, e))?);
                let (final_gaussians, _) = crate::gaussian::ply::read_ply(scene)?;
                let (diagnostics, classes) =
                    super::diagnostics::diagnose(&inputs, &outcome.steps, Some(&final_gaussians))?;
                // The classes of the evaluation pixels, for the pairs a claim compares on
                // them (`pairs`); none where the run generated nothing.
                let classes_path = out.join(CLASSES_FILE);
                match classes {
                    Some(c) => crate::io::write_atomic(&classes_path, |f| {
                        std::io::Write::write_all(f, &c.concat())
                    })?,
                    None => match std::fs::remove_file(&classes_path) {
                        Err(e) if e.kind() != std::io::ErrorKind::NotFound => {
                            return Err(Error::io(&classes_path, e));
                        }
                        _ => {}
                    },
                }
                let final_scene = scene
                    .strip_prefix(&out)
                    .map_err(|_| {
                        Error::invalid("the final scene is not in the run's folder").at(scene)
                    })?
                    .to_string_lossy()
                    .into_owned();
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
                    scene_sha256,
                    final_scene,
                    pair: None,
                    diagnostics: Some(diagnostics),
                    candidates: self.candidates.family.clone(),
                    stages: summary
                        .rows
                        .iter()
                        .map(|r| StageRecord {
                            scene: r.scene.clone(),
                            psnr_train_half: r.psnr_train_half,
                            ssim_train_half: r.ssim_train_half,
                            gaussians: r.gaussians,
                            lineage: r.lineage.clone(),
                        })
                        .collect(),
                };
                let text = serde_json::to_string_pretty(&result).expect("serializes") + "\n";
                crate::io::write_text(&out.join("audit_job.json"), &text)?;
                Ok(Some(result))
            }
        }
    }

    /// Run the pipeline of (`generator`, `variant`, `seed`) in `job`'s folder within `scope`,
    /// continuing what is there and sharing `DIR/cache`; the seed's original scene must be
    /// done. Returns the job's configuration, inputs and the run's outcome.
    fn pipeline_job(
        &self,
        job: &Job,
        (generator, variant, seed): (GeneratorKind, Variant, u32),
        scope: Scope,
    ) -> Result<(
        PipelineConfig,
        crate::pipeline::Inputs,
        crate::pipeline::Outcome,
    )> {
        let Audit {
            cfg, dir, on_event, ..
        } = *self;
        let run = self.require_original(job, seed)?;
        on_event(Event::Stage { name: job.name() });
        let inputs = self.seed_inputs(&run)?;
        let pc = cfg.pipeline_config(generator, variant, seed)?;
        let out = dir.join(job.folder());
        let opts = RunOptions {
            resume: out.is_dir(),
            cache: Some(dir.join("cache")),
            scope,
        };
        let outcome = crate::pipeline::run_with(&pc, &inputs, &out, &opts, on_event)?;
        Ok((pc, inputs, outcome))
    }

    /// A pipeline's inputs for the original scene trained in `run`: the audit's candidate
    /// family and the dataset's evaluation poses, with truth.
    pub(super) fn seed_inputs(&self, run: &Path) -> Result<crate::pipeline::Inputs> {
        let dataset = self.dataset;
        crate::pipeline::load_inputs(
            run,
            &self.candidates.file,
            Some(&dataset.join("evaluation.json")),
            Some(dataset),
        )
    }

    /// The folder of `seed`'s original scene, which `job` needs: an error naming the job to
    /// run first unless it is trained (`original_done`).
    pub(super) fn require_original(&self, job: &Job, seed: u32) -> Result<PathBuf> {
        let dir = self.dir;
        let run = dir.join(Job::Original { seed }.name());
        if !self.original_done(&run, seed) {
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
    pub(super) fn original_done(&self, run: &Path, seed: u32) -> bool {
        let (cfg, dataset) = (self.cfg, self.dataset);
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
                std::fs::read(run.join(&f.path))
                    .is_ok_and(|b| crate::io::sha256_hex(&b) == f.sha256)
            })
            && latest_ply(run).is_ok()
            && read_config(run).is_ok_and(|c| c == cfg.train_config(seed))
    }

    /// What every job needs, checked before the first job starts (an audit runs for hours):
    /// the dataset's candidate and evaluation poses, readable, and an output path that is
    /// not a file.
    pub(super) fn check_inputs(&self) -> Result<()> {
        let (dataset, dir) = (self.dataset, self.dir);
        if dir.is_file() {
            return Err(Error::invalid("the output path is a file").at(dir));
        }
        for p in [
            self.candidates.file.clone(),
            dataset.join("evaluation.json"),
        ] {
            let f = p
                .file_name()
                .map_or(String::new(), |f| f.to_string_lossy().into_owned());
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
}

/// Iterations between checkpoints of an original-scene training (a killed audit loses at
/// most this many iterations of it).
const ORIGINAL_CHECKPOINT_EVERY: u32 = 1000;

impl Audit<'_> {
    fn original(&self, seed: u32) -> Result<PathBuf> {
        let Audit {
            cfg,
            dataset,
            dir,
            on_event,
            ..
        } = *self;
        let run = dir.join(Job::Original { seed }.name());
        if self.original_done(&run, seed) {
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
}
