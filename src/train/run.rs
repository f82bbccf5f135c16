//! The run directory of `unseen train` (SPEC.md §14.6), INRIA's output layout so existing
//! viewers open it:
//!
//! ```text
//! RUN/point_cloud/iteration_N/point_cloud.ply   at each save iteration and the last
//! RUN/cameras.json                              every view of the dataset (INRIA layout)
//! RUN/config.json                               the TrainConfig (INRIA's cfg_args, as JSON)
//! RUN/cfg_args                                  INRIA's Namespace line, for its viewers
//! RUN/manifest.json                             sha256 of every output, seed, config
//! RUN/train_stats.json                          wall time, it/s, peak memory, loss curve
//! RUN/checkpoint.bin                            the training state while the run is going
//! ```
//!
//! Every file is written to a temporary name and renamed, so an interrupted run never leaves
//! a truncated PLY under its final name. `manifest.json` holds no timings, so two runs with
//! the same inputs have the same manifest bytes.

use crate::camera::inria::cameras_json_string;
use crate::dataset::{self, Dataset, LoadOptions};
use crate::error::{Error, Result};
use crate::gaussian::Gaussians;
use crate::gaussian::ply::{ply_bytes, read_ply};
use crate::io::manifest::{FileEntry, Manifest};
use crate::io::{
    Cost, CostMeter, create_dir_all, peak_memory_bytes, remove_stale_temporaries, sha256_hex,
    write_atomic, write_text,
};
use crate::train::checkpoint::{Checkpoint, checkpoint_path};
use crate::train::trainer::{IterationTimes, Progress, TrainConfig, Trainer};
use std::io::Write;
use std::path::{Path, PathBuf};
use std::time::Instant;

/// `RUN/point_cloud/iteration_N/point_cloud.ply`.
pub fn ply_path(run: &Path, iteration: u32) -> PathBuf {
    run.join("point_cloud")
        .join(format!("iteration_{iteration}"))
        .join("point_cloud.ply")
}

/// The highest saved iteration of a run and its PLY.
pub fn latest_ply(run: &Path) -> Result<(u32, PathBuf)> {
    let dir = run.join("point_cloud");
    let entries = std::fs::read_dir(&dir).map_err(|e| Error::io(&dir, e))?;
    let mut best = None;
    for e in entries.flatten() {
        let name = e.file_name().to_string_lossy().into_owned();
        if let Some(n) = name
            .strip_prefix("iteration_")
            .and_then(|n| n.parse::<u32>().ok())
            && ply_path(run, n).is_file()
            && best.is_none_or(|b| n > b)
        {
            best = Some(n);
        }
    }
    let n = best.ok_or_else(|| {
        Error::invalid("no point_cloud/iteration_N/point_cloud.ply in the run").at(&dir)
    })?;
    Ok((n, ply_path(run, n)))
}

/// Read `RUN/config.json`.
pub fn read_config(run: &Path) -> Result<TrainConfig> {
    let p = run.join("config.json");
    let text = std::fs::read(&p).map_err(|e| Error::io(&p, e))?;
    serde_json::from_slice(&text).map_err(|e| Error::parse(&p, format!("invalid config: {e}")))
}

/// `Ok` when the run at `run` was trained under the default convention profile; the
/// QA-Mask, the mask audit and the pipeline render `inria` only (SPEC.md §5.2), and would
/// judge or fine-tune a scene under a clamp it was not trained for.
pub fn require_default_conventions(run: &Path, what: &str) -> Result<()> {
    let cfg = read_config(run)?;
    if cfg.conventions.is_default() {
        return Ok(());
    }
    Err(Error::invalid(format!(
        "the run was trained under conventions '{}'; {what} runs 'inria' only",
        cfg.conventions
    ))
    .at(&run.join("config.json")))
}

/// Load a dataset the way a run's config says.
pub fn load_dataset(dir: &Path, config: &TrainConfig) -> Result<Dataset> {
    dataset::load(dir, &load_options(config))
}

/// How a run with `config` loads its dataset's views.
pub fn load_options(config: &TrainConfig) -> LoadOptions {
    LoadOptions {
        resolution: config.resolution,
        background: config.background,
        test_every: config.test_every,
    }
}

/// What a finished run reports.
#[derive(Clone, Debug, serde::Serialize)]
pub struct RunSummary {
    pub iterations: u32,
    pub gaussians: usize,
    pub wall_seconds: f64,
    pub iterations_per_second: f64,
    /// Gaussian-pixel pairs blended per second (forward evaluations of the blend kernel).
    pub pairs_per_second: f64,
    pub peak_memory_bytes: Option<u64>,
    /// Wall time and peak resident memory of loading (dataset, initial scene) and of the
    /// iterations (saves included).
    pub stages: Vec<(String, Cost)>,
    /// Where the iterations' time went.
    pub iteration_seconds: IterationTimes,
    pub final_loss_ema: f64,
    pub final_psnr_ema: f64,
    /// `(iteration, seconds since the start)` of every saved PLY.
    pub saves: Vec<(u32, f64)>,
    /// `(iteration, loss EMA, PSNR EMA, Gaussians)` every 100 iterations.
    pub curve: Vec<(u32, f64, f64, usize)>,
    pub ply: PathBuf,
}

/// The names of the views a run trained on (`manifest.json`'s `inputs.train_views`).
pub fn read_train_views(run: &Path) -> Result<Vec<String>> {
    let p = run.join("manifest.json");
    let v = Manifest::read(run)?.inputs;
    let list = v
        .get("train_views")
        .and_then(|x| x.as_array())
        .ok_or_else(|| Error::parse(&p, "no \"train_views\" list"))?;
    list.iter()
        .map(|x| {
            x.as_str()
                .map(str::to_string)
                .ok_or_else(|| Error::parse(&p, "\"train_views\" holds a non-string"))
        })
        .collect()
}

/// INRIA's `cfg_args` (the `ModelParams` namespace its SIBR viewer and render scripts read).
fn cfg_args(dataset_dir: &Path, run: &Path, c: &TrainConfig) -> String {
    let bg = c.background == [1.0; 3];
    format!(
        "Namespace(sh_degree={}, source_path='{}', model_path='{}', images='images', \
         depths='', resolution={}, white_background={}, train_test_exp=False, \
         data_device='cuda', eval={})",
        c.sh_degree,
        dataset_dir.display(),
        run.display(),
        if c.resolution == 1 {
            -1
        } else {
            c.resolution as i64
        },
        if bg { "True" } else { "False" },
        if c.test_every > 0 { "True" } else { "False" },
    )
}

/// Per-view loss weights: camera → per-pixel weight map (`None` = all ones).
pub type ViewWeights<'a> = &'a (dyn Fn(&crate::camera::Camera) -> Result<Option<Vec<f32>>> + Sync);

/// Start from an existing scene instead of the dataset's point cloud, with per-pixel loss
/// weights on the training views (paper Eq. 7; choosing them is the caller's job).
pub struct Init<'a> {
    pub scene: Gaussians,
    pub weights: Option<ViewWeights<'a>>,
}

/// Checkpointing of a run (SPEC.md §14.8).
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq)]
pub struct Checkpointing {
    /// Write `RUN/checkpoint.bin` after every this many iterations (0: never). The file is
    /// removed when the run completes.
    pub every: u32,
    /// Continue from `RUN/checkpoint.bin` if the run has one (else start afresh).
    pub resume: bool,
}

/// A run's bookkeeping between iterations (saved in a checkpoint's header, so a resumed
/// run's summary and manifest continue it).
#[derive(Clone, Debug, Default, serde::Serialize, serde::Deserialize)]
struct Book {
    /// Saved PLYs (relative to the run) and their sha256.
    files: Vec<(PathBuf, String)>,
    /// `(iteration, loss EMA bits, PSNR EMA bits, Gaussians)`: bits, so a diverged run's
    /// NaN survives the JSON header.
    curve: Vec<(u32, u64, u64, usize)>,
    saves: Vec<(u32, f64)>,
    pairs: u64,
    /// Seconds of iterations before this process.
    elapsed: f64,
    times: IterationTimes,
}

/// Train on `dataset_dir` into `run` (from `init` when given); `on_progress` sees every
/// iteration.
pub fn train_run(
    dataset_dir: &Path,
    run: &Path,
    config: &TrainConfig,
    init: Option<&Init<'_>>,
    checkpoints: Checkpointing,
    on_progress: &mut dyn FnMut(&Progress),
) -> Result<RunSummary> {
    train_run_resuming(
        dataset_dir,
        run,
        config,
        init,
        checkpoints,
        &mut |_| {},
        on_progress,
    )
}

/// [`train_run`], calling `on_resume` with the checkpoint's iteration when it continues one.
pub fn train_run_resuming(
    dataset_dir: &Path,
    run: &Path,
    config: &TrainConfig,
    init: Option<&Init<'_>>,
    checkpoints: Checkpointing,
    on_resume: &mut dyn FnMut(u32),
    on_progress: &mut dyn FnMut(&Progress),
) -> Result<RunSummary> {
    config.validate()?;
    let meter = CostMeter::start();
    let data = load_dataset(dataset_dir, config)?;
    let ck_path = checkpoint_path(run);
    let resumed = open_run(run, &ck_path, checkpoints.resume)?;
    write_run_records(dataset_dir, run, config, &data)?;
    let mut trainer = new_trainer(&data, config, init)?;
    // What the training reads, so that a checkpoint only continues the run it was made by.
    let inputs_sha256 = if checkpoints.every > 0 || checkpoints.resume {
        inputs_digest(&trainer, init.map(|i| &i.scene))?
    } else {
        String::new()
    };
    let mut book = Book::default();
    if let Some(ck) = resumed {
        book = resume(ck, &ck_path, run, &inputs_sha256, &mut trainer)?;
        on_resume(trainer.iteration);
    }
    let mut stages = vec![("load".to_string(), meter.finish())];
    let meter = CostMeter::start();
    let start = Instant::now();
    let elapsed = |b: &Book| b.elapsed + start.elapsed().as_secs_f64();
    while trainer.iteration < config.iterations {
        let mut p = trainer.step()?;
        let it = trainer.iteration;
        book.pairs += p.pairs;
        if it.is_multiple_of(100) || it == config.iterations {
            book.curve
                .push((it, p.loss_ema.to_bits(), p.psnr_ema.to_bits(), p.gaussians));
        }
        if config.save_iterations.contains(&it) || it == config.iterations {
            book.saves.push((it, elapsed(&book)));
            let path = ply_path(run, it);
            create_dir_all(path.parent().expect("has a parent"))?;
            let bytes = ply_bytes(&trainer.gaussians)?;
            write_atomic(&path, |w| w.write_all(&bytes))?;
            let rel = path.strip_prefix(run).unwrap_or(&path).to_path_buf();
            book.files.push((rel, sha256_hex(&bytes)));
        }
        if checkpoints.every > 0 && it.is_multiple_of(checkpoints.every) && it < config.iterations {
            let mut b = book.clone();
            b.elapsed = elapsed(&book);
            b.times = trainer.times;
            let record = serde_json::to_value(&b).expect("book serializes");
            Checkpoint::save(&trainer, inputs_sha256.clone(), record, &ck_path)?;
            p.checkpointed = true;
        }
        on_progress(&p);
    }
    let wall = elapsed(&book);
    stages.push(("train".to_string(), meter.finish()));
    finish_run(
        dataset_dir,
        run,
        config,
        &data,
        &trainer,
        book,
        wall,
        stages,
    )
}

/// Open `run` for a training: the checkpoint to continue (with `resume` and one there; a
/// complete run is refused), the folder made and cleared of what a killed process was
/// writing (§10), and on a fresh start the checkpoint and completion records of an earlier
/// run removed (a kill before the first checkpoint must not leave the folder looking
/// complete).
fn open_run(run: &Path, ck_path: &Path, resume: bool) -> Result<Option<Checkpoint>> {
    let resumed = if resume && ck_path.is_file() {
        Some(Checkpoint::read(ck_path)?)
    } else {
        if resume && run.join("manifest.json").is_file() {
            return Err(Error::invalid(
                "the run is complete (manifest.json and no checkpoint.bin): nothing to resume",
            )
            .at(run));
        }
        None
    };
    create_dir_all(run)?;
    remove_stale_temporaries(run)?;
    if let Ok(entries) = std::fs::read_dir(run.join("point_cloud")) {
        for e in entries.flatten() {
            remove_stale_temporaries(&e.path())?;
        }
    }
    if resumed.is_none() {
        for p in [
            ck_path,
            &run.join("manifest.json"),
            &run.join("train_stats.json"),
        ] {
            remove_if_present(p)?;
        }
    }
    Ok(resumed)
}

/// The run's records of what it trains: `config.json`, `cfg_args`, `cameras.json`.
fn write_run_records(
    dataset_dir: &Path,
    run: &Path,
    config: &TrainConfig,
    data: &Dataset,
) -> Result<()> {
    let config_text = serde_json::to_string_pretty(config).expect("config serializes");
    write_text(&run.join("config.json"), &config_text)?;
    write_text(&run.join("cfg_args"), &cfg_args(dataset_dir, run, config))?;
    let cams: Vec<_> = data.views.iter().map(|v| v.camera.clone()).collect();
    write_text(&run.join("cameras.json"), &cameras_json_string(&cams))
}

/// The trainer of a run: INRIA's initialisation, or a fine-tune of `init`'s scene with its
/// per-view loss weights.
fn new_trainer<'a>(
    data: &'a Dataset,
    config: &TrainConfig,
    init: Option<&Init<'_>>,
) -> Result<Trainer<'a>> {
    let Some(i) = init else {
        return Trainer::new(data, config.clone());
    };
    let deg = i.scene.sh_degree;
    let mut t = Trainer::from_gaussians(data, config.clone(), i.scene.clone(), deg)?;
    let mut masks = vec![None; data.views.len()];
    if let Some(w) = i.weights {
        for &vi in &data.train {
            masks[vi] = w(&data.views[vi].camera)?;
        }
    }
    t.masks = masks;
    Ok(t)
}

/// Continue from checkpoint `ck`: refused when it was made from other inputs or a file it
/// records has changed since; the trainer restored; the run's record so far.
fn resume(
    ck: Checkpoint,
    ck_path: &Path,
    run: &Path,
    inputs_sha256: &str,
    trainer: &mut Trainer,
) -> Result<Book> {
    let at = |e: Error| e.at(ck_path);
    if ck.header.inputs_sha256 != inputs_sha256 {
        return Err(at(Error::invalid(
            "the checkpoint was made from other inputs (the dataset's cameras or training \
             images, the --init scene or the --mask weights differ)",
        )));
    }
    let book: Book = serde_json::from_value(ck.header.run.clone())
        .map_err(|e| Error::parse(ck_path, format!("invalid run record: {e}")))?;
    for (rel, sha) in &book.files {
        let p = run.join(rel);
        let bytes = std::fs::read(&p).map_err(|e| Error::io(&p, e))?;
        if sha256_hex(&bytes) != *sha {
            return Err(Error::invalid("changed since the checkpoint was written").at(&p));
        }
    }
    ck.restore(trainer).map_err(at)?;
    trainer.times = book.times;
    Ok(book)
}

/// Complete a run: its manifest over every file it wrote, `train_stats.json`, and the
/// checkpoint removed.
#[allow(clippy::too_many_arguments)]
fn finish_run(
    dataset_dir: &Path,
    run: &Path,
    config: &TrainConfig,
    data: &Dataset,
    trainer: &Trainer,
    book: Book,
    wall: f64,
    stages: Vec<(String, crate::io::Cost)>,
) -> Result<RunSummary> {
    let ply = book
        .files
        .last()
        .map(|f| run.join(&f.0))
        .unwrap_or_default();
    let mut files = book.files.clone();
    for name in ["config.json", "cfg_args", "cameras.json"] {
        let p = run.join(name);
        let bytes = std::fs::read(&p).map_err(|e| Error::io(&p, e))?;
        files.push((PathBuf::from(name), sha256_hex(&bytes)));
    }
    let inputs = serde_json::json!({
        "dataset": dataset_dir.display().to_string(),
        "seed": config.seed,
        "config": config,
        // The views trained on (the QA-Mask fine-tune and the pipeline use their cameras).
        "train_views": data
            .train
            .iter()
            .map(|&i| data.views[i].camera.name.clone())
            .collect::<Vec<_>>(),
    });
    let files = files
        .iter()
        .map(|(p, h)| FileEntry::hashed(p.display().to_string(), h.clone()))
        .collect();
    Manifest::new("train", "", inputs, files).write(run)?;
    let summary = RunSummary {
        iterations: trainer.iteration,
        gaussians: trainer.gaussians.len(),
        wall_seconds: wall,
        iterations_per_second: trainer.iteration as f64 / wall.max(1e-9),
        pairs_per_second: book.pairs as f64 / wall.max(1e-9),
        peak_memory_bytes: peak_memory_bytes(),
        stages,
        iteration_seconds: trainer.times,
        final_loss_ema: trainer.loss_ema,
        final_psnr_ema: trainer.psnr_ema,
        saves: book.saves,
        curve: book
            .curve
            .iter()
            .map(|&(i, l, p, n)| (i, f64::from_bits(l), f64::from_bits(p), n))
            .collect(),
        ply,
    };
    write_text(
        &run.join("train_stats.json"),
        &serde_json::to_string_pretty(&summary).expect("summary serializes"),
    )?;
    remove_if_present(&checkpoint_path(run))?;
    Ok(summary)
}

/// sha256 of what a trainer's iterations read besides its own state: every camera, the
/// training views' images, depths and loss weights, and the initial scene of a fine-tune.
fn inputs_digest(t: &Trainer<'_>, init: Option<&Gaussians>) -> Result<String> {
    use sha2::{Digest, Sha256};
    let mut h = Sha256::new();
    let cams: Vec<_> = t.dataset.views.iter().map(|v| v.camera.clone()).collect();
    h.update(cameras_json_string(&cams).as_bytes());
    let floats = |h: &mut Sha256, tag: &[u8], v: Option<&[f32]>| {
        h.update(tag);
        h.update((v.map_or(u64::MAX, |v| v.len() as u64)).to_le_bytes());
        for x in v.unwrap_or_default() {
            h.update(x.to_bits().to_le_bytes());
        }
    };
    for &vi in &t.dataset.train {
        let v = &t.dataset.views[vi];
        floats(&mut h, b"image", Some(&v.image.data));
        floats(&mut h, b"depth", v.depth.as_deref());
        floats(&mut h, b"mask", t.masks.get(vi).and_then(|m| m.as_deref()));
    }
    if let Some(g) = init {
        h.update(b"init");
        h.update(ply_bytes(g)?);
    }
    Ok(crate::io::hex(&h.finalize()))
}

/// Remove a file if it exists, naming it in the error otherwise.
fn remove_if_present(p: &Path) -> Result<()> {
    match std::fs::remove_file(p) {
        Err(e) if e.kind() != std::io::ErrorKind::NotFound => Err(Error::io(p, e)),
        _ => Ok(()),
    }
}

/// The Gaussians of a run at `iteration` (default: the latest saved one).
pub fn read_run_scene(run: &Path, iteration: Option<u32>) -> Result<(u32, Gaussians)> {
    let (it, p) = match iteration {
        Some(n) => (n, ply_path(run, n)),
        None => latest_ply(run)?,
    };
    Ok((it, read_ply(&p)?.0))
}
