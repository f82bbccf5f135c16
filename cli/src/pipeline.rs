//! `unseen extrapolate`, `unseen compare` and `unseen demo`: thin shells over
//! `unseen::pipeline` that draw its events.

use clap::{Args, ValueEnum};
use indicatif::{ProgressBar, ProgressStyle};
use std::path::{Path, PathBuf};
use std::time::Instant;
use unseen::collide::frustum::Outline;
use unseen::error::{Error, Result};
use unseen::pipeline::Level;
use unseen::pipeline::compare::compare;
use unseen::pipeline::selection::SelectionRule;
use unseen::pipeline::steps::Step;
use unseen::pipeline::{
    self, Hallucination, Inconsistency, Inputs, MaskSource, Paradigm, PipelineConfig, Preset,
    RunOptions, Scope, SlotNames, Stage2Depth, TruthDepth, load_inputs,
};
use unseen::train::run::{Checkpointing, train_run};
use unseen::train::trainer::TrainConfig;

#[derive(Clone, Copy, ValueEnum)]
pub enum Generator {
    /// The classical slots (Telea, depth-fill, morph, identity; the default) unless
    /// --config names others.
    Classical,
    /// The labelled ground-truth generator (needs the candidates' truth in the dataset).
    Truth,
}

#[derive(Args)]
pub struct ExtrapolateArgs {
    /// Run directory of `unseen train` (the original scene).
    run: PathBuf,
    /// Candidate extrapolation cameras (INRIA cameras.json layout).
    #[arg(long)]
    views: PathBuf,
    /// Output run directory.
    #[arg(long)]
    out: PathBuf,
    #[arg(long, value_parser = crate::one_of(&Preset::ALL, Preset::name), default_value = "quick")]
    preset: Preset,
    /// A JSON PipelineConfig over the preset (any subset of fields).
    #[arg(long)]
    config: Option<PathBuf>,
    /// Continue a run: verified steps are skipped, the rest recomputed.
    #[arg(long)]
    resume: bool,
    /// Compute only this step (e.g. `stage1/bridge_004`), whose inputs must be done in
    /// OUT: one job of a batch engine. Implies continuing OUT.
    #[arg(long, conflicts_with = "until", value_parser = parse_step)]
    only: Option<Step>,
    /// Compute the steps up to and including this one (e.g. `views`), then stop.
    #[arg(long, conflicts_with = "wave", value_parser = parse_step)]
    until: Option<Step>,
    /// Compute wave K (or waves A-B) of the run's plan (`--plan` lists them), whose earlier
    /// waves must be done in OUT: one job of a batch engine. Implies continuing OUT.
    #[arg(long, conflicts_with = "only", value_parser = parse_waves)]
    wave: Option<(usize, usize)>,
    /// With --wave: only the I-th step of the wave (nothing when it has fewer): one task
    /// of a batch engine's job array.
    #[arg(long, requires = "wave")]
    task: Option<usize>,
    /// Worker threads (default: all cores); results are the same bits for any count.
    #[arg(long)]
    threads: Option<usize>,
    /// Evaluation cameras (cameras.json) with truth in the dataset: metrics per stage.
    #[arg(long)]
    eval: Option<PathBuf>,
    /// Dataset directory (default: the one recorded in RUN/manifest.json).
    #[arg(long)]
    dataset: Option<PathBuf>,
    /// Step cache shared with other runs: a step whose inputs another run already
    /// computed is copied from it instead (same bits).
    #[arg(long)]
    cache: Option<PathBuf>,
    /// Print the run's plan, wave by wave, and exit: what detection found when OUT's views
    /// step is done, else the largest plan (every candidate independent).
    #[arg(long, conflicts_with_all = ["only", "until", "wave", "emit_slurm"])]
    plan: bool,
    /// Write a Slurm submission folder for this run (a job array per wave of the plan that
    /// fans out, the waves between them as one job, the whole run last; submit.sh) and run
    /// nothing.
    #[arg(long, conflicts_with_all = ["only", "until", "wave"])]
    emit_slurm: Option<PathBuf>,
    #[command(flatten)]
    slurm: SlurmArgs,
    #[command(flatten)]
    knobs: Knobs,
}

/// Switches over the preset (each ablation of the paper is one of them).
#[derive(Args)]
pub struct Knobs {
    #[arg(long, value_enum)]
    generator: Option<Generator>,
    /// Inconsistency of the ground-truth generator.
    #[arg(long, value_parser = crate::one_of(&Level::ALL, Level::name))]
    inconsistency: Option<Level>,
    /// Depth of the ground-truth generator's depth slots (labelled modes):
    /// metric camera-z depth (default), or relative — disparity up to a seeded affine map
    /// per image / per clip, with flicker and a mild distortion at the inconsistency level,
    /// what a depth model returns.
    #[arg(long, value_parser = crate::one_of(&TruthDepth::ALL, TruthDepth::name))]
    truth_depth: Option<TruthDepth>,
    /// The ground-truth generator's hallucination of content no training view saw
    /// (labelled mode: differs per call, so independent generations conflict).
    #[arg(long, value_parser = crate::one_of(&Level::ALL, Level::name))]
    hallucination: Option<Level>,
    /// Weights of the generated supervision: the QA-Mask (the paper), 1 − alpha, or none.
    #[arg(long, value_parser = crate::one_of(&MaskSource::ALL, MaskSource::name))]
    mask: Option<MaskSource>,
    #[arg(long)]
    seed: Option<u64>,
    /// Ablations.
    #[arg(long)]
    no_depth_supervision: bool,
    #[arg(long)]
    no_propagation: bool,
    #[arg(long)]
    no_independent_detection: bool,
    #[arg(long)]
    no_interpolation: bool,
    /// Not in the paper: with depth supervision, also supervise the original training
    /// views with the dataset's depth (the paper supervises the generated views' priors).
    #[arg(long)]
    original_view_depth: bool,
    /// Not in the paper: the dependent views' depth by a least-squares fit of the depth
    /// slot to the stage-1 render instead of video depth alignment.
    #[arg(long)]
    stage2_render_fit: bool,
    /// Which independent set detection keeps (the paper leaves it open): greedy in
    /// candidate order (default), maximum cardinality, or maximum coverage.
    #[arg(long, value_parser = crate::one_of(&SelectionRule::ALL, SelectionRule::name))]
    selection: Option<SelectionRule>,
    /// Outline of an inpainted region's frustum: its bounding box (the paper) or hull.
    #[arg(long, value_parser = crate::one_of(&Outline::ALL, Outline::name))]
    frustum_outline: Option<Outline>,
    /// Not the paper's method (an audit comparison): stage 1 generates a colliding set of
    /// the independent set's size whose coverage of the evaluation views' unseen surface
    /// matches the independent set's (needs --eval and a dataset with truth depth).
    #[arg(long)]
    conflicting_views: bool,
    /// Not the paper's method: the generate–reconstruct–shift cycle it replaces (paradigm
    /// `cycle`: the trajectory's views one after another, each inpainted from the current
    /// scene and reconstructed before the next), for comparison.
    #[arg(long)]
    cycle: bool,
}

impl Knobs {
    fn apply(&self, c: &mut PipelineConfig) -> Result<()> {
        if let Some(g) = self.generator {
            c.slots = match g {
                Generator::Classical => SlotNames::default(),
                Generator::Truth => SlotNames::truth(),
            };
        }
        if let Some(l) = self.inconsistency {
            c.inconsistency = Inconsistency::at(l);
        }
        if let Some(d) = self.truth_depth {
            c.truth_depth = d;
        }
        if let Some(l) = self.hallucination {
            c.hallucination = Hallucination::at(l);
        }
        if let Some(m) = self.mask {
            c.mask_source = m;
        }
        if let Some(s) = self.seed {
            c.seed = s;
        }
        c.depth_supervision &= !self.no_depth_supervision;
        c.propagation &= !self.no_propagation;
        c.independent_detection &= !self.no_independent_detection;
        c.interpolation &= !self.no_interpolation;
        c.original_view_depth |= self.original_view_depth;
        if self.stage2_render_fit {
            c.stage2_depth = Stage2Depth::RenderFit;
        }
        if let Some(r) = self.selection {
            c.selection = r;
        }
        if let Some(o) = self.frustum_outline {
            c.frustum_outline = o;
        }
        if self.conflicting_views {
            c.conflicting_views =
                Some(unseen::pipeline::selection::ConflictMatch::EvaluationCoverage);
        }
        if self.cycle {
            c.paradigm = Paradigm::Cycle;
        }
        Ok(())
    }
}

fn config_from(preset: Preset, file: Option<&Path>, knobs: &Knobs) -> Result<PipelineConfig> {
    let mut c = match file {
        None => PipelineConfig::preset(preset),
        Some(p) => {
            let text = std::fs::read(p).map_err(|e| Error::io(p, e))?;
            let over: serde_json::Value = serde_json::from_slice(&text)
                .map_err(|e| Error::parse(p, format!("invalid JSON: {e}")))?;
            PipelineConfig::with_overrides(preset, over, p)?
        }
    };
    knobs.apply(&mut c)?;
    // An invalid value names the file it came from (knobs are checked as they apply).
    c.validate().map_err(|e| match file {
        Some(p) => e.at(p),
        None => e,
    })?;
    Ok(c)
}

pub fn run_extrapolate(a: &ExtrapolateArgs) -> Result<()> {
    let cfg = config_from(a.preset, a.config.as_deref(), &a.knobs)?;
    let inputs = load_inputs(&a.run, &a.views, a.eval.as_deref(), a.dataset.as_deref())?;
    if a.plan {
        for (k, w) in pipeline::plan_of(&cfg, &inputs, &a.out)?.iter().enumerate() {
            let steps: Vec<String> = w.steps.iter().map(|p| p.step.to_string()).collect();
            println!("wave {k}: {}", steps.join(" "));
        }
        return Ok(());
    }
    if let Some(sub) = &a.emit_slurm {
        return emit_extrapolate(a, &cfg, &inputs, sub);
    }
    let draw = super::progress::drawer();
    let scope = match (&a.only, &a.until, a.wave) {
        (Some(s), _, _) => Scope::Only(s.clone()),
        (None, Some(s), _) => Scope::Until(s.clone()),
        (None, None, Some((first, last))) => Scope::Waves {
            first,
            last,
            task: a.task,
        },
        (None, None, None) => Scope::All,
    };
    let opts = RunOptions {
        resume: a.resume || (scope != Scope::All && a.out.is_dir()),
        scope,
        cache: a.cache.clone(),
    };
    let out = unseen::sys::with_threads(a.threads, || {
        pipeline::run_with(&cfg, &inputs, &a.out, &opts, &draw)
    })??;
    if let Some(m) = &out.metrics {
        print!("{}", m.table());
    }
    match &out.scene {
        Some(s) => println!("extrapolated scene: {}", s.display()),
        None => println!("done: the requested steps are in {}", a.out.display()),
    }
    Ok(())
}

/// `extrapolate --emit-slurm SUB`: the submission folder of `unseen::batch::extrapolate`
/// over this command line (paths absolute).
fn emit_extrapolate(
    a: &ExtrapolateArgs,
    cfg: &PipelineConfig,
    inputs: &Inputs,
    sub: &Path,
) -> Result<()> {
    let abs = |p: &Path| {
        std::path::absolute(p)
            .map(|p| p.display().to_string())
            .map_err(|e| Error::io(p, e))
    };
    let exe = std::env::current_exe().map_err(|e| Error::io(Path::new("unseen"), e))?;
    let mut cmd = vec![
        exe.display().to_string(),
        "extrapolate".into(),
        abs(&a.run)?,
        "--views".into(),
        abs(&a.views)?,
        "--out".into(),
        abs(&a.out)?,
        "--preset".into(),
        cfg.preset.to_string(),
    ];
    for (flag, p) in [
        ("--eval", &a.eval),
        ("--dataset", &a.dataset),
        ("--cache", &a.cache),
    ] {
        if let Some(p) = p {
            cmd.extend([flag.to_string(), abs(p)?]);
        }
    }
    let sub = std::path::absolute(sub).map_err(|e| Error::io(sub, e))?;
    let opts = a.slurm.options();
    for (w, r) in unseen::batch::extrapolate::emit_slurm(cfg, inputs, &cmd, &sub, &opts)? {
        println!(
            "{}: {} tasks, --cpus-per-task={} --mem={}M --time={} min",
            w.name, w.tasks, r.cpus, r.memory_mb, r.time_minutes
        );
    }
    println!("submit with: {}", sub.join("submit.sh").display());
    Ok(())
}

#[derive(Args)]
pub struct AuditTableArgs {
    /// Audit folders (each with an audit.json), in the table's order; `FOLDER:GENERATOR`
    /// shows one generator (dose level) of it.
    #[arg(required = true)]
    folders: Vec<String>,
    /// At a glance: per primary claim its null, the paper's metric and SSIM on contested
    /// pixels, the verdict's word alone (README's "Results at a glance").
    #[arg(long)]
    glance: bool,
}

/// `unseen audit-table`: the results table of audits, as README.md shows it.
pub fn run_audit_table(a: &AuditTableArgs) -> Result<()> {
    use unseen::audit::results::{Source, Style, table};
    let sources: Vec<Source> = a.folders.iter().map(|f| Source::parse(f)).collect();
    let style = if a.glance { Style::Glance } else { Style::Full };
    print!("{}", table(&sources, style)?);
    Ok(())
}

#[derive(Args)]
pub struct CompareArgs {
    a: PathBuf,
    b: PathBuf,
    /// Largest absolute difference of a float artifact that still counts as agreeing.
    #[arg(long, default_value_t = 0.0)]
    tolerance: f64,
    /// Also write the full comparison as JSON.
    #[arg(long)]
    json: Option<PathBuf>,
}

/// `unseen compare`: exit 0 when the runs agree within the tolerance, 1 when a step
/// diverges, 2 when they cannot be compared (the error printed).
pub fn run_compare(a: &CompareArgs) -> std::process::ExitCode {
    match compare_runs(a) {
        Ok(true) => std::process::ExitCode::SUCCESS,
        Ok(false) => std::process::ExitCode::from(1),
        Err(e) => {
            eprintln!("error: {e}");
            std::process::ExitCode::from(2)
        }
    }
}

/// Whether the runs agree within the tolerance.
fn compare_runs(a: &CompareArgs) -> Result<bool> {
    let c = compare(&a.a, &a.b, a.tolerance)?;
    print!("{}", c.table());
    if let Some(p) = &a.json {
        unseen::io::write_text(p, &serde_json::to_string_pretty(&c).expect("serializes"))?;
    }
    match &c.first_divergent {
        None => {
            println!(
                "identical{}",
                if c.steps.iter().all(|s| s.identical) {
                    ""
                } else {
                    " within the tolerance"
                }
            );
            Ok(true)
        }
        Some(s) => {
            println!("first divergent step: {s}");
            Ok(false)
        }
    }
}

#[derive(Args)]
pub struct DemoArgs {
    /// Output folder.
    #[arg(long, default_value = "demo-out")]
    out: PathBuf,
    /// Bundled room.
    #[arg(long, default_value = "lounge")]
    scene: String,
    /// Iterations of the original scene's training (at half resolution).
    #[arg(long, default_value_t = 1500)]
    iterations: u32,
    /// A JSON PipelineConfig over the quick preset (any subset of fields).
    #[arg(long)]
    config: Option<PathBuf>,
    #[command(flatten)]
    knobs: Knobs,
    /// Continue an interrupted demo.
    #[arg(long)]
    resume: bool,
}

/// The demo: train the original scene on the train half of a bundled room, extrapolate it
/// with the quick preset into the held-out half, report.
pub fn run_demo(a: &DemoArgs) -> Result<()> {
    // The repository's reference_data/, one level above this package (cli/).
    let manifest = Path::new(env!("CARGO_MANIFEST_DIR"));
    let root = manifest
        .parent()
        .unwrap_or(manifest)
        .join("reference_data/scenes");
    let scene = root.join(&a.scene);
    if !scene.is_dir() {
        return Err(Error::invalid(format!("no bundled scene '{}'", a.scene)).at(&root));
    }
    let cfg = config_from(Preset::Quick, a.config.as_deref(), &a.knobs)?;
    let run = a.out.join("original");
    let ply_done = unseen::train::run::latest_ply(&run).is_ok() && a.resume;
    if !ply_done {
        if a.out.join("extrapolate").is_dir() && !a.resume {
            return Err(Error::invalid(
                "the output folder holds a demo already (pass --resume or remove it)",
            )
            .at(&a.out));
        }
        let tc = TrainConfig {
            iterations: a.iterations,
            resolution: 2,
            save_iterations: vec![],
            ..TrainConfig::default()
        };
        eprintln!(
            "== original scene: {} iterations on the train half of {} at 80x60",
            a.iterations,
            scene.display()
        );
        let bar = ProgressBar::new(a.iterations as u64);
        bar.set_style(ProgressStyle::with_template("   {bar:30} {pos}/{len} {msg}").expect("t"));
        train_run(
            &scene,
            &run,
            &tc,
            None,
            Checkpointing::default(),
            &mut |p| {
                if p.iteration % 10 == 0 {
                    bar.set_position(p.iteration as u64);
                    bar.set_message(format!("PSNR {:.2} dB", p.psnr_ema));
                }
            },
        )?;
        bar.finish_and_clear();
    }
    let inputs: Inputs = load_inputs(
        &run,
        &scene.join("candidates.json"),
        Some(&scene.join("evaluation.json")),
        Some(&scene),
    )?;
    let draw = super::progress::drawer();
    let t0 = Instant::now();
    let ex = a.out.join("extrapolate");
    let outcome = pipeline::run(&cfg, &inputs, &ex, a.resume, &draw)?;
    let report = pipeline::report::markdown(&cfg, &ex, &outcome, t0.elapsed().as_secs_f64())?;
    unseen::io::write_text(&a.out.join("report.md"), &report)?;
    if let Some(m) = &outcome.metrics {
        print!("{}", m.table());
    }
    println!("demo: report in {}", a.out.join("report.md").display());
    Ok(())
}

/// The resource options of `--emit-slurm`.
#[derive(Args)]
pub struct SlurmArgs {
    /// Slurm partition of every job (--emit-slurm).
    #[arg(long, requires = "emit_slurm")]
    slurm_partition: Option<String>,
    /// Slurm account of every job (--emit-slurm).
    #[arg(long, requires = "emit_slurm")]
    slurm_account: Option<String>,
    /// Another `#SBATCH` option for every job, e.g. `--slurm-extra=--qos=long`; repeatable.
    #[arg(long, requires = "emit_slurm", allow_hyphen_values = true)]
    slurm_extra: Vec<String>,
    /// At most this many tasks of one wave at once (`--array=…%N`).
    #[arg(long, requires = "emit_slurm")]
    slurm_throttle: Option<u32>,
    /// CPUs per task, the workers' thread count (default 2).
    #[arg(long, requires = "emit_slurm")]
    slurm_cpus: Option<u32>,
}

impl SlurmArgs {
    fn options(&self) -> unseen::batch::SlurmOptions {
        unseen::batch::SlurmOptions {
            partition: self.slurm_partition.clone(),
            account: self.slurm_account.clone(),
            extra: self.slurm_extra.clone(),
            throttle: self.slurm_throttle,
            cpus: self.slurm_cpus,
        }
    }
}

#[derive(Args)]
pub struct AuditArgs {
    /// Dataset with ground truth, candidates.json and evaluation.json (a bundled room).
    dataset: PathBuf,
    /// Audit directory (continued when it exists: finished jobs are verified and kept).
    #[arg(long)]
    out: PathBuf,
    #[arg(long, value_parser = crate::one_of(&Preset::ALL, Preset::name), default_value = "quick")]
    preset: Preset,
    /// Variants, comma-separated (default: every variant but the opt-in ones): full, no_qa_mask, opacity_mask,
    /// even_views, conflicting_views, no_depth_supervision, no_propagation, qa_sh3, qa_sh4,
    /// no_interpolation, stage2_render_fit, cycle; opt-in sensitivity pairs: full_max_cardinality,
    /// even_views_max_cardinality, full_max_coverage, even_views_max_coverage, full_hull,
    /// even_views_hull; opt-in control: originals_only (the fine-tunes on the original views
    /// alone).
    #[arg(long, value_delimiter = ',')]
    variants: Vec<String>,
    /// Generators, comma-separated: classical, truth-none, truth-low, truth-high,
    /// truth-low+hallucinating+relative, truth-high+hallucinating+relative (default: quick
    /// classical,truth-low; paper classical and the three truth levels).
    #[arg(long, value_delimiter = ',')]
    generators: Vec<String>,
    /// A dose–response sweep, `PARAM=v1,v2,…` with PARAM hallucination, photometric,
    /// depth_distortion or ghosting (the planted-harm control: true images shifted by
    /// level × 8 px per call) and levels in [0, 1], ghosting's in [0, 2] (e.g.
    /// `hallucination=0,0.25,0.5,0.75,1`): one
    /// generator per level (`dose-<param>-<percent>`), added to `--generators` (alone when
    /// none is given). Repeatable.
    #[arg(long)]
    sweep: Vec<String>,
    /// The candidate poses the pipeline is given: a family of the dataset
    /// (`families/<FAMILY>.json`, e.g. ring-7, ring-13, walk-0, walk-1 in the bundled
    /// rooms) instead of its bundled bridge views (`candidates.json`). Samples of one
    /// family pool only with samples of the same family.
    #[arg(long, value_name = "FAMILY")]
    candidates: Option<String>,
    /// The seeds of this batch: `K` (seeds 0 to K−1) or `A..B` (seeds A to B−1; default:
    /// quick 1, paper 3). The report pools them with the samples already in the folder
    /// (`samples.json`) and in `--merge` files: seeds accumulate.
    #[arg(long)]
    seeds: Option<String>,
    /// The planned sample per claim (default 16): verdicts are taken on the first N seeds
    /// of the pool; a claim with fewer is an interim look, not a verdict.
    #[arg(long, value_name = "N")]
    planned_seeds: Option<usize>,
    /// Pool the samples of another audit (its `samples.json`, or an `audit.json` of an
    /// earlier version) into the report; repeatable. Refused when it measures another
    /// dataset, preset or original-scene training.
    #[arg(long)]
    merge: Vec<PathBuf>,
    /// Run no job: write the report of the samples in the folder and in `--merge` files.
    #[arg(long, conflicts_with_all = ["only", "list"])]
    report_only: bool,
    /// Training iterations of the original scene (default: quick 1500, paper 30000).
    #[arg(long)]
    train_iterations: Option<u32>,
    /// A JSON PipelineConfig over the preset (any subset of fields): every job's
    /// pipeline before its generator, variant and seed.
    #[arg(long)]
    config: Option<PathBuf>,
    /// Downscale of the dataset's images for the original scene and the pipeline
    /// (default: quick 2, paper 1).
    #[arg(long)]
    train_resolution: Option<u32>,
    /// Run one job alone (`original/seed-K`, `shared/<generator>/seed-K` or
    /// `runs/<generator>/<variant>/seed-K`, as `--list` prints them): a batch engine's
    /// worker. It writes DIR/receipts/<job>.json, also when it fails. Finish with
    /// `--collect`, or with a run without `--only`.
    #[arg(long)]
    only: Option<String>,
    /// With --only: the worker's log, named in its receipt.
    #[arg(long, requires = "only")]
    log: Option<PathBuf>,
    /// Print the audit's jobs and exit; with --estimate, wave by wave those still to run
    /// beside the samples pooled in --out and --merge files, with their expected costs.
    #[arg(long)]
    list: bool,
    /// With --list: each job's expected seconds and peak memory on 2 threads (from this
    /// audit's finished jobs where there are some, else the built-in calibration), and
    /// per wave the CPU-hours and the largest peak.
    #[arg(long, requires = "list")]
    estimate: bool,
    /// Run no job: merge the jobs' receipts and results into the report; every job still
    /// to run beside the pooled samples without a receipt of a success is named (with its
    /// log) and the merge fails.
    #[arg(long, conflicts_with_all = ["only", "list", "report_only"])]
    collect: bool,
    /// With --collect: the Slurm submission folder the jobs ran from (names their logs).
    #[arg(long, requires = "collect")]
    submission: Option<PathBuf>,
    /// Write a Slurm submission folder for the jobs of this audit not pooled yet as this
    /// binary computes them (job arrays in waves, a merge job, submit.sh) and run no job.
    #[arg(long, conflicts_with_all = ["only", "list", "report_only", "collect"])]
    emit_slurm: Option<PathBuf>,
    #[command(flatten)]
    slurm: SlurmArgs,
    /// Worker threads (default: all cores); results are the same bits for any count.
    #[arg(long)]
    threads: Option<usize>,
}

/// `--wave`: `K` or `A-B` (plan waves).
fn parse_waves(s: &str) -> std::result::Result<(usize, usize), String> {
    let n = |t: &str| {
        t.parse::<usize>()
            .map_err(|_| format!("'{s}' is not a wave (K or A-B)"))
    };
    match s.split_once('-') {
        None => n(s).map(|k| (k, k)),
        Some((a, b)) => Ok((n(a)?, n(b)?)),
    }
}

/// `--only` / `--until`: a step's folder name (`unseen::pipeline::steps::Step`).
fn parse_step(s: &str) -> std::result::Result<Step, String> {
    s.parse().map_err(|e: Error| e.to_string())
}

/// `--seeds`: `K` (0..K) or `A..B`, not empty.
fn parse_seeds(s: &str) -> std::result::Result<std::ops::Range<u32>, String> {
    let num = |t: &str| {
        t.trim()
            .parse::<u32>()
            .map_err(|_| format!("'{t}' is not a seed number (seeds are K or A..B)"))
    };
    let r = match s.split_once("..") {
        Some((a, b)) => num(a)?..num(b)?,
        None => 0..num(s)?,
    };
    if r.is_empty() {
        return Err(format!("the seed range '{s}' is empty"));
    }
    Ok(r)
}

/// `unseen audit`: every job (or one), then the report.
pub fn run_audit(a: &AuditArgs) -> Result<()> {
    use unseen::audit::{self, AuditConfig, GeneratorKind, Variant, cluster};
    let preset = a.preset;
    let mut cfg = AuditConfig::preset(preset);
    if let Some(p) = &a.config {
        let text = std::fs::read(p).map_err(|e| Error::io(p, e))?;
        let over: serde_json::Value = serde_json::from_slice(&text)
            .map_err(|e| Error::parse(p, format!("invalid JSON: {e}")))?;
        cfg.base = PipelineConfig::with_overrides(preset, over, p)?;
        cfg.base.validate()?;
    }
    if !a.variants.is_empty() {
        cfg.variants = a
            .variants
            .iter()
            .map(|v| v.parse::<Variant>())
            .collect::<Result<_>>()?;
    }
    if !a.generators.is_empty() {
        cfg.generators = a
            .generators
            .iter()
            .map(|g| GeneratorKind::by_name(g))
            .collect::<Result<_>>()?;
    }
    if !a.sweep.is_empty() {
        if a.generators.is_empty() {
            cfg.generators.clear();
        }
        for s in &a.sweep {
            for g in unseen::audit::dose::parse_sweep(s)? {
                if !cfg.generators.contains(&g) {
                    cfg.generators.push(g);
                }
            }
        }
    }
    if let Some(k) = &a.seeds {
        cfg.seeds = parse_seeds(k).map_err(Error::invalid)?;
    }
    cfg.candidates = a.candidates.clone();
    if let Some(n) = a.train_iterations {
        cfg.train_iterations = n;
    }
    if let Some(n) = a.planned_seeds {
        cfg.planned_seeds = n;
    }
    if let Some(r) = a.train_resolution {
        if r == 0 {
            return Err(Error::invalid("--train-resolution must be at least 1"));
        }
        cfg.train_resolution = r;
    }
    cfg.validate()?;
    if a.list {
        return list_audit(&cfg, a);
    }
    if let Some(sub) = &a.emit_slurm {
        return emit_audit(&cfg, a, preset, sub);
    }
    let draw = super::progress::drawer();
    let run = audit::Audit::new(&cfg, &a.dataset, &a.out)?.with_events(&draw);
    if let Some(only) = &a.only {
        let waves = cluster::waves(&cfg);
        let job = waves
            .iter()
            .flat_map(|w| &w.jobs)
            .find(|j| &j.name() == only)
            .ok_or_else(|| Error::invalid(format!("no job '{only}' in this audit (see --list)")))?;
        unseen::sys::with_threads(a.threads, || {
            run.run_job_with_receipt(job, a.log.as_deref())
        })??;
        println!("done: {only}");
        return Ok(());
    }
    let report = if a.collect {
        let waves = run.waves_to_run(&a.merge)?;
        let log_of = |j: &audit::Job| {
            a.submission
                .as_ref()
                .and_then(|s| cluster::log_in_submission(&waves, s, j))
        };
        match run.collect(&a.merge, &log_of)? {
            Ok(r) => r,
            Err(missing) => {
                for m in &missing {
                    let log = m
                        .log
                        .as_deref()
                        .map_or(String::new(), |l| format!(" (log: {l})"));
                    eprintln!("not done: {}: {}{log}", m.job, m.why);
                }
                let total: usize = waves.iter().map(|w| w.jobs.len()).sum();
                return Err(Error::invalid(format!(
                    "{} of {total} jobs have no receipt of a success (listed above; the first: {}): nothing merged",
                    missing.len(),
                    missing[0].job
                ))
                .at(&a.out));
            }
        }
    } else if a.report_only {
        run.report(&a.merge)?
    } else {
        unseen::sys::with_threads(a.threads, || run.run(&a.merge))??
    };
    // Verdicts are about the median Δ; the mean is printed beside it, labelled.
    for v in &report.verdicts {
        println!(
            "{:<58} {:<11} median {:>10} (mean {:>10})  {}",
            v.claim.id,
            v.generator,
            v.median_shown(),
            unseen::audit::shown_delta(v.mean_diff, v.claim.metric),
            v.verdict
        );
    }
    println!("audit: report in {}", a.out.join("audit.md").display());
    Ok(())
}

/// `--list [--estimate]`: the jobs wave by wave.
fn list_audit(cfg: &unseen::audit::AuditConfig, a: &AuditArgs) -> Result<()> {
    if !a.estimate {
        for j in unseen::audit::jobs(cfg) {
            println!("{}", j.name());
        }
        return Ok(());
    }
    let gb = |b: f64| b / 1e9;
    let (mut cpu_hours, mut jobs) = (0.0, 0);
    for (wave, costs) in unseen::audit::Audit::new(cfg, &a.dataset, &a.out)?.estimate(&a.merge)? {
        let hours: f64 = costs.iter().map(|c| c.seconds).sum::<f64>() * 2.0 / 3600.0;
        let peak = costs.iter().map(|c| c.peak_rss_bytes).fold(0.0, f64::max);
        let longest = costs.iter().map(|c| c.seconds).fold(0.0, f64::max);
        let measured = costs.iter().filter(|c| c.measured).count();
        println!(
            "wave {}: {} jobs, {hours:.1} CPU-hours (2 threads each), longest {:.1} h, peak {:.2} GB ({measured} of {} from this audit's finished jobs)",
            wave.name,
            wave.jobs.len(),
            longest / 3600.0,
            gb(peak),
            costs.len()
        );
        for (j, c) in wave.jobs.iter().zip(&costs) {
            println!(
                "  {:<56} {:>9.0} s {:>7.2} GB",
                j.name(),
                c.seconds,
                gb(c.peak_rss_bytes)
            );
        }
        cpu_hours += hours;
        jobs += wave.jobs.len();
    }
    println!("total: {jobs} jobs, {cpu_hours:.1} CPU-hours");
    Ok(())
}

/// `--emit-slurm SUB`: the submission folder; the workers' command line names the grid
/// in absolute paths and the resolved pipeline configuration (a copy in SUB).
fn emit_audit(
    cfg: &unseen::audit::AuditConfig,
    a: &AuditArgs,
    preset: Preset,
    sub: &Path,
) -> Result<()> {
    let abs = |p: &Path| std::path::absolute(p).map_err(|e| Error::io(p, e));
    let sub = abs(sub)?;
    unseen::io::create_dir_all(&sub)?;
    let config = sub.join("pipeline-config.json");
    let text = serde_json::to_string_pretty(&cfg.base).expect("serializes") + "\n";
    unseen::io::write_text(&config, &text)?;
    let exe = std::env::current_exe().map_err(|e| Error::io(Path::new("unseen"), e))?;
    let show = |p: PathBuf| p.display().to_string();
    let mut command = vec![
        show(exe),
        "audit".into(),
        show(abs(&a.dataset)?),
        "--out".into(),
        show(abs(&a.out)?),
        "--preset".into(),
        preset.to_string(),
        "--config".into(),
        show(config),
        "--variants".into(),
        cfg.variants
            .iter()
            .map(|v| v.name())
            .collect::<Vec<_>>()
            .join(","),
        "--generators".into(),
        cfg.generators
            .iter()
            .map(|g| g.name())
            .collect::<Vec<_>>()
            .join(","),
        "--seeds".into(),
        format!("{}..{}", cfg.seeds.start, cfg.seeds.end),
        "--train-iterations".into(),
        cfg.train_iterations.to_string(),
        "--train-resolution".into(),
        cfg.train_resolution.to_string(),
    ];
    if let Some(f) = &cfg.candidates {
        command.extend(["--candidates".into(), f.clone()]);
    }
    for m in &a.merge {
        command.extend(["--merge".into(), show(abs(m)?)]);
    }
    let opts = a.slurm.options();
    let waves = unseen::audit::Audit::new(cfg, &a.dataset, &a.out)?
        .emit_slurm(&command, &a.merge, &sub, &opts)?;
    for (w, r) in &waves {
        println!(
            "{}: {} jobs, --cpus-per-task={} --mem={}M --time={} min",
            w.name,
            w.jobs.len(),
            r.cpus,
            r.memory_mb,
            r.time_minutes
        );
    }
    println!("submit with: {}", sub.join("submit.sh").display());
    Ok(())
}
