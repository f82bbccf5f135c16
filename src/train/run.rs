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
    Cost, CostMeter, create_dir_all, peak_memory_bytes, sha256_hex, write_atomic, write_text,
};
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

/// Load a dataset the way a run's config says.
pub fn load_dataset(dir: &Path, config: &TrainConfig) -> Result<Dataset> {
    dataset::load(
        dir,
        &LoadOptions {
            resolution: config.resolution,
            background: config.background,
            test_every: config.test_every,
        },
    )
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

/// Train on `dataset_dir` into `run` (from `init` when given); `on_progress` sees every
/// iteration.
pub fn train_run(
    dataset_dir: &Path,
    run: &Path,
    config: &TrainConfig,
    init: Option<&Init<'_>>,
    on_progress: &mut dyn FnMut(&Progress),
) -> Result<RunSummary> {
    config.validate()?;
    let meter = CostMeter::start();
    let data = load_dataset(dataset_dir, config)?;
    create_dir_all(run)?;
    let config_text = serde_json::to_string_pretty(config).expect("config serializes");
    write_text(&run.join("config.json"), &config_text)?;
    write_text(&run.join("cfg_args"), &cfg_args(dataset_dir, run, config))?;
    let cams: Vec<_> = data.views.iter().map(|v| v.camera.clone()).collect();
    write_text(&run.join("cameras.json"), &cameras_json_string(&cams))?;

    let start = Instant::now();
    let mut trainer = match init {
        None => Trainer::new(&data, config.clone())?,
        Some(i) => {
            let deg = i.scene.sh_degree;
            let mut t = Trainer::from_gaussians(&data, config.clone(), i.scene.clone(), deg)?;
            let mut masks = vec![None; data.views.len()];
            if let Some(w) = i.weights {
                for &vi in &data.train {
                    masks[vi] = w(&data.views[vi].camera)?;
                }
            }
            t.masks = masks;
            t
        }
    };
    let mut stages = vec![("load".to_string(), meter.finish())];
    let meter = CostMeter::start();
    let mut files: Vec<(PathBuf, String)> = Vec::new();
    let mut curve = Vec::new();
    let mut pairs = 0u64;
    let mut last = Progress::default();
    let mut saves = Vec::new();
    let mut save = |it: u32, g: &Gaussians| -> Result<()> {
        saves.push((it, start.elapsed().as_secs_f64()));
        let p = ply_path(run, it);
        create_dir_all(p.parent().expect("has a parent"))?;
        let bytes = ply_bytes(g)?;
        write_atomic(&p, |w| w.write_all(&bytes))?;
        files.push((p, sha256_hex(&bytes)));
        Ok(())
    };
    trainer.run(
        &mut |p| {
            pairs += p.pairs;
            if p.iteration % 100 == 0 || p.iteration == p.iterations {
                curve.push((p.iteration, p.loss_ema, p.psnr_ema, p.gaussians));
            }
            last = *p;
            on_progress(p);
        },
        &mut save,
    )?;
    let wall = start.elapsed().as_secs_f64();
    stages.push(("train".to_string(), meter.finish()));
    let ply = files.last().map(|f| f.0.clone()).unwrap_or_default();
    for name in ["config.json", "cfg_args", "cameras.json"] {
        let p = run.join(name);
        let bytes = std::fs::read(&p).map_err(|e| Error::io(&p, e))?;
        files.push((p, sha256_hex(&bytes)));
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
        .map(|(p, h)| {
            FileEntry::hashed(
                p.strip_prefix(run).unwrap_or(p).display().to_string(),
                h.clone(),
            )
        })
        .collect();
    Manifest::new("train", "", inputs, files).write(run)?;
    let summary = RunSummary {
        iterations: trainer.iteration,
        gaussians: trainer.gaussians.len(),
        wall_seconds: wall,
        iterations_per_second: trainer.iteration as f64 / wall.max(1e-9),
        pairs_per_second: pairs as f64 / wall.max(1e-9),
        peak_memory_bytes: peak_memory_bytes(),
        stages,
        iteration_seconds: trainer.times,
        final_loss_ema: last.loss_ema,
        final_psnr_ema: last.psnr_ema,
        saves,
        curve,
        ply,
    };
    write_text(
        &run.join("train_stats.json"),
        &serde_json::to_string_pretty(&summary).expect("summary serializes"),
    )?;
    Ok(summary)
}

/// The Gaussians of a run at `iteration` (default: the latest saved one).
pub fn read_run_scene(run: &Path, iteration: Option<u32>) -> Result<(u32, Gaussians)> {
    let (it, p) = match iteration {
        Some(n) => (n, ply_path(run, n)),
        None => latest_ply(run)?,
    };
    Ok((it, read_ply(&p)?.0))
}
