//! `unseen train`, `unseen eval`, `unseen qa-mask`, `unseen mask-audit` (SPEC.md §14, §15).

use super::progress::train_with_bar;
use clap::Args;
use indicatif::{ProgressBar, ProgressStyle};
use std::path::PathBuf;
use std::time::Instant;
use unseen::camera::{Camera, inria};
use unseen::dataset::Split;
use unseen::error::{Error, Result};
use unseen::eval::evaluate_run;
use unseen::pipeline::MaskSource;
use unseen::pipeline::recon::Weights;
use unseen::qamask::{
    QaMaskConfig, fine_tune, mask_scene, parse_color, read_mask_dir, write_mask_dir,
};
use unseen::train::loss::LossWeights;
use unseen::train::run::{
    Checkpointing, Init, load_dataset, read_config, read_run_scene, read_train_views,
    require_default_conventions,
};
use unseen::train::trainer::{TrainConfig, TrainOverrides};

#[derive(Args)]
pub struct TrainArgs {
    /// Dataset directory.
    dataset: PathBuf,
    /// Run directory (created).
    #[arg(long)]
    out: PathBuf,
    /// Iterations (default 30000).
    #[arg(long)]
    iterations: Option<u32>,
    /// Seed of every random choice (default 0).
    #[arg(long)]
    seed: Option<u64>,
    /// Integer image downscale factor (INRIA -r; default 1).
    #[arg(long)]
    resolution: Option<u32>,
    /// Largest SH degree (default 3).
    #[arg(long)]
    sh_degree: Option<u32>,
    /// A JSON TrainConfig; any field left out keeps its default (SPEC.md §14).
    /// Flags override it.
    #[arg(long)]
    config: Option<PathBuf>,
    /// Convention profile of every render of the run: `inria` (α clamp 0.99, the default)
    /// or `gsplat` (0.999, gsplat 1.0–1.5.3); recorded in OUT/config.json (SPEC.md §5.2).
    #[arg(long, value_parser = crate::render::parse_conventions)]
    conventions: Option<unseen::raster::Conventions>,
    /// Fine-tune the latest scene of this run instead of starting from the point cloud.
    #[arg(long)]
    init: Option<PathBuf>,
    /// Per-pixel loss weights for fine-tuning (needs --init): none, opacity (1 − alpha
    /// of the initial scene) or qa (needs --mask-dir). With a mask the loss is the
    /// paper's Eq. 7 (λ = 0.7, 0.2, 0.1).
    #[arg(long, default_value = "none", value_parser = crate::one_of(&MaskSource::ALL, MaskSource::name))]
    mask: MaskSource,
    /// QA-Mask directory written by `unseen qa-mask`.
    #[arg(long)]
    mask_dir: Option<PathBuf>,
    /// Save the training state to OUT/checkpoint.bin every this many iterations (0: never;
    /// the file is removed when the run completes).
    #[arg(long, default_value_t = 1000)]
    checkpoint_every: u32,
    /// Continue the interrupted run in OUT from its last checkpoint, with OUT/config.json
    /// (give the same DATASET, --init, --mask and --mask-dir): the result has the same bits
    /// as an uninterrupted run.
    #[arg(long, conflicts_with_all = ["iterations", "seed", "resolution", "sh_degree", "config", "conventions"])]
    resume: bool,
}

#[derive(Args)]
pub struct QaMaskArgs {
    /// Run directory written by `unseen train`.
    run: PathBuf,
    /// Output directory (point_cloud.ply, qa_mask.json, manifest.json).
    #[arg(long)]
    out: PathBuf,
    /// SH degree of the mask scene (paper: 5).
    #[arg(long, default_value_t = 5)]
    sh_degree: u32,
    /// Fine-tune iterations (paper: 20000).
    #[arg(long, default_value_t = 20_000)]
    iterations: u32,
    /// Base and target colours: names (red, green, blue, black, white, ...) or #rrggbb.
    #[arg(long, default_value = "red,black")]
    colors: String,
    /// Learning rate of the higher SH coefficients (INRIA's f_rest rate by default).
    #[arg(long)]
    lr: Option<f32>,
    #[arg(long, default_value_t = 0)]
    seed: u64,
}

#[derive(Args)]
pub struct MaskAuditArgs {
    /// Run directory written by `unseen train` on DATASET's train half.
    run: PathBuf,
    #[arg(long)]
    dataset: PathBuf,
    /// QA-Mask SH degrees to fine-tune.
    #[arg(long, value_delimiter = ',', default_value = "3,4,5")]
    degrees: Vec<u32>,
    /// Fine-tune iterations per degree (paper: 20000).
    #[arg(long, default_value_t = 20_000)]
    iterations: u32,
    /// SH rest learning rate (INRIA's f_rest rate by default).
    #[arg(long)]
    lr: Option<f32>,
    /// Output JSON (the table is printed).
    #[arg(long)]
    out: PathBuf,
}

#[derive(Args)]
pub struct EvalArgs {
    /// Run directory written by `unseen train`.
    run: PathBuf,
    /// Dataset directory.
    #[arg(long)]
    dataset: PathBuf,
    /// train, test (INRIA's every-8th hold-out) or heldout (the unseen half).
    #[arg(long, default_value = "test")]
    split: Split,
    /// Saved iteration to evaluate (default: the latest).
    #[arg(long)]
    iteration: Option<u32>,
}

pub fn run_train(a: TrainArgs) -> Result<()> {
    let TrainArgs {
        dataset,
        out,
        iterations,
        seed,
        resolution,
        sh_degree,
        config,
        conventions,
        init,
        mask,
        mask_dir,
        checkpoint_every,
        resume,
    } = a;
    let mut cfg = if resume {
        read_config(&out)?
    } else {
        TrainConfig::from_file_and_flags(
            config.as_deref(),
            &TrainOverrides {
                iterations,
                seed,
                resolution,
                sh_degree,
                conventions,
            },
        )?
    };
    let (scene, weights) = match init {
        None if mask != MaskSource::None => {
            return Err(Error::invalid(
                "--mask needs --init RUN (it weights a fine-tune)",
            ));
        }
        None => (None, Weights::None),
        Some(run) => {
            let (_, scene) = read_run_scene(&run, None)?;
            let weights = match mask {
                MaskSource::None => Weights::None,
                MaskSource::Opacity => Weights::Opacity(scene.clone()),
                MaskSource::Qa => {
                    let Some(dir) = &mask_dir else {
                        return Err(Error::invalid("--mask qa needs --mask-dir DIR"));
                    };
                    Weights::Qa(Box::new(read_mask_dir(dir)?))
                }
            };
            if !matches!(weights, Weights::None) {
                cfg.loss = LossWeights::PAPER;
            }
            cfg.sh_degree = scene.sh_degree;
            (Some(scene), weights)
        }
    };
    let at = |cam: &Camera| weights.at(cam);
    let init = scene.map(|scene| Init {
        scene,
        weights: Some(&at),
    });
    let checkpoints = Checkpointing {
        every: checkpoint_every,
        resume,
    };
    let s = train_with_bar(&dataset, &out, &cfg, init.as_ref(), checkpoints)?;
    println!(
        "trained {} iterations in {:.1} s ({:.1} it/s, {:.3} G pairs/s), {} Gaussians: {}",
        s.iterations,
        s.wall_seconds,
        s.iterations_per_second,
        s.pairs_per_second * 1e-9,
        s.gaussians,
        s.ply.display()
    );
    Ok(())
}

pub fn run_qa_mask(a: QaMaskArgs) -> Result<()> {
    let QaMaskArgs {
        run,
        out,
        sh_degree,
        iterations,
        colors,
        lr,
        seed,
    } = a;
    let (base, target) = colors
        .split_once(',')
        .ok_or_else(|| Error::invalid(format!("--colors '{colors}' is not BASE,TARGET")))?;
    let mut cfg = QaMaskConfig {
        sh_degree,
        iterations,
        base_color: parse_color(base)?,
        target_color: parse_color(target)?,
        seed,
        ..QaMaskConfig::default()
    };
    if let Some(lr) = lr {
        cfg.lr_sh_rest = lr;
    }
    require_default_conventions(&run, "the QA-Mask")?;
    let (it, trained) = read_run_scene(&run, None)?;
    let names = read_train_views(&run)?;
    let all = inria::read_cameras_json(&run.join("cameras.json"))?;
    let views: Vec<Camera> = all
        .into_iter()
        .filter(|c| names.contains(&c.name))
        .collect();
    let mut scene = mask_scene(&trained, &cfg)?;
    let bar = ProgressBar::new(iterations as u64);
    bar.set_style(
        ProgressStyle::with_template(
            "{bar:30} {pos}/{len} {msg} [{elapsed_precise}<{eta_precise}]",
        )
        .expect("valid template"),
    );
    let t0 = Instant::now();
    let loss = fine_tune(&mut scene, &views, &cfg, &mut |p| {
        if bar.is_hidden() && p.iteration % 2000 == 0 {
            eprintln!(
                "iteration {}/{}: loss {:.5}, {:.1} s",
                p.iteration,
                p.iterations,
                p.loss,
                t0.elapsed().as_secs_f64()
            );
        }
        if p.iteration % 50 == 0 || p.iteration == p.iterations {
            bar.set_position(p.iteration as u64);
            bar.set_message(format!("loss {:.5}", p.loss));
        }
    })?;
    bar.finish_and_clear();
    write_mask_dir(&out, &scene, &cfg)?;
    println!(
        "QA-Mask of {} (iteration {it}): {} views, {} iterations in {:.1} s, last loss {loss:.5}; wrote {}",
        run.display(),
        views.len(),
        iterations,
        t0.elapsed().as_secs_f64(),
        out.display()
    );
    Ok(())
}

pub fn run_mask_audit(a: MaskAuditArgs) -> Result<()> {
    let MaskAuditArgs {
        run,
        dataset,
        degrees,
        iterations,
        lr,
        out,
    } = a;
    require_default_conventions(&run, "the mask audit")?;
    let cfg = read_config(&run)?;
    let data = load_dataset(&dataset, &cfg)?;
    let (it, trained) = read_run_scene(&run, None)?;
    let configs: Vec<QaMaskConfig> = degrees
        .iter()
        .map(|&d| QaMaskConfig {
            sh_degree: d,
            iterations,
            lr_sh_rest: lr.unwrap_or(QaMaskConfig::default().lr_sh_rest),
            ..QaMaskConfig::default()
        })
        .collect();
    let bar = ProgressBar::new((iterations as u64) * configs.len() as u64);
    let mut done = 0u64;
    let t0 = Instant::now();
    let report = unseen::qamask::audit(&trained, &data, &configs, &mut |name, p| {
        if bar.is_hidden() && p.iteration % 2000 == 0 {
            eprintln!(
                "{name}: iteration {}/{}, loss {:.5}, {:.1} s",
                p.iteration,
                p.iterations,
                p.loss,
                t0.elapsed().as_secs_f64()
            );
        }
        if p.iteration % 50 == 0 {
            bar.set_position(done + p.iteration as u64);
            bar.set_message(format!("{name} loss {:.5}", p.loss));
        }
        if p.iteration == p.iterations {
            done += p.iterations as u64;
        }
    })?;
    bar.finish_and_clear();
    let json = serde_json::json!({
        "run": run.display().to_string(),
        "iteration": it,
        "dataset": dataset.display().to_string(),
        "qa_iterations": iterations,
        "report": report,
    });
    unseen::io::write_text(
        &out,
        &serde_json::to_string_pretty(&json).expect("serializes"),
    )?;
    print!("{}", report.table());
    println!("wrote {}", out.display());
    Ok(())
}

pub fn run_eval(a: EvalArgs) -> Result<()> {
    let EvalArgs {
        run,
        dataset,
        split,
        iteration,
    } = a;
    let r = evaluate_run(&run, &dataset, split, iteration)?;
    print!("{}", r.table());
    println!("wrote {}", run.join("eval.json").display());
    Ok(())
}
