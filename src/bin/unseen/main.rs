//! The `unseen` command line. Errors are one sentence on stderr and a non-zero exit.

mod geometry;
mod models;
mod pipeline;

use clap::{Parser, Subcommand};
use indicatif::{ProgressBar, ProgressStyle};
use std::path::{Path, PathBuf};
use std::process::ExitCode;
use std::time::Instant;
use unseen::camera::{Camera, inria};
use unseen::dataset::Split;
use unseen::error::{Error, Result};
use unseen::eval::{EvalReport, evaluate};
use unseen::gaussian::ply;
use unseen::io::file_stem;
use unseen::io::image::{ImageF32, write_exr, write_png};
use unseen::qamask::{
    QaMaskConfig, fine_tune, heat_map, mask_scene, opacity_mask, parse_color, read_mask_dir,
    render_qa_mask, scale_mask, write_mask_dir,
};
use unseen::raster::{Outputs, RenderOptions, render};
use unseen::train::loss::LossWeights;
use unseen::train::run::{
    Init, MaskSource, load_dataset, read_config, read_run_scene, read_train_views, train_run,
};
use unseen::train::trainer::{Progress, TrainConfig};

#[derive(Parser)]
#[command(
    name = "unseen",
    version,
    about = "Deterministic CPU scene extrapolation with 3D Gaussian Splatting"
)]
struct Cli {
    #[command(subcommand)]
    command: Command,
}

#[derive(Subcommand)]
enum Command {
    /// The main job on a bundled room: train the original scene on its train half, then
    /// extrapolate it into the held-out half with the quick pipeline; writes
    /// demo-out/report.md.
    Demo(pipeline::DemoArgs),
    /// The paper's pipeline on a trained run: independent views, stage 1, stage 2,
    /// interpolation; a resumable run directory with per-step manifests.
    Extrapolate(pipeline::ExtrapolateArgs),
    /// Compare two extrapolation runs step by step (the GPU port's check); exit 1 on
    /// divergence beyond the tolerance.
    Compare(pipeline::CompareArgs),
    /// Forward-warp an image with its depth from one camera to another (DIBR).
    Warp(geometry::WarpArgs),
    /// Inpaint the non-zero pixels of MASK in IMAGE (Telea by default, as cv2.inpaint).
    Inpaint(models::InpaintArgs),
    /// Estimate depth of an image (depth-fill from a known depth, or an ONNX model).
    Depth(models::DepthArgs),
    /// Do two convex polyhedra intersect? (GJK; exit 0 either way.)
    Collide(geometry::CollideArgs),
    /// Independent views: frustums of the candidates' inpainted regions, their collision
    /// graph, a maximal independent set and its closed trajectory.
    Views(geometry::ViewsArgs),
    /// Render a 3DGS PLY from cameras in INRIA cameras.json layout.
    Render {
        /// Scene in INRIA 3DGS PLY layout.
        scene: Option<PathBuf>,
        /// Cameras (INRIA cameras.json).
        #[arg(long)]
        cameras: PathBuf,
        /// Output folder.
        #[arg(long)]
        out: PathBuf,
        /// Render only the camera with this img_name.
        #[arg(long)]
        camera: Option<String>,
        /// Highest SH degree to evaluate (default: the scene's).
        #[arg(long)]
        sh_degree: Option<u32>,
        /// Background colour, linear, e.g. 0,0,0 or 1,1,1.
        #[arg(long, default_value = "0,0,0", value_parser = parse_rgb)]
        background: [f32; 3],
        /// Float EXR outputs besides the PNG: rgb, alpha, depth (accumulated D),
        /// expected_depth (ED = D / alpha).
        #[arg(long, value_delimiter = ',', default_value = "rgb")]
        outputs: Vec<String>,
        /// Render masks instead of images: a QA-Mask directory (then SCENE may be omitted),
        /// or `opacity` / `scale` (baselines of SCENE). Writes <name>.mask.exr (float) and
        /// <name>.mask.png (heat map).
        #[arg(long)]
        mask: Option<String>,
    },
    /// Train 3D Gaussians on a dataset (unseen scene, COLMAP or transforms.json directory)
    /// with INRIA's recipe; writes INRIA's output layout into --out.
    Train {
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
        /// Fine-tune the latest scene of this run instead of starting from the point cloud.
        #[arg(long)]
        init: Option<PathBuf>,
        /// Per-pixel loss weights for fine-tuning (needs --init): none, opacity (1 − alpha
        /// of the initial scene) or qa (needs --mask-dir). With a mask the loss is the
        /// paper's Eq. 7 (λ = 0.7, 0.2, 0.1).
        #[arg(long, default_value = "none")]
        mask: String,
        /// QA-Mask directory written by `unseen qa-mask`.
        #[arg(long)]
        mask_dir: Option<PathBuf>,
    },
    /// Quality-Aware Mask of a trained run (paper §3.4): base colour, black targets, only
    /// higher SH fine-tuned on the run's training views; writes the mask scene into --out.
    QaMask {
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
    },
    /// Measure the QA-Mask claim on a dataset with a held-out half: fine-tune QA-Masks of a
    /// run at several SH degrees, score them and the baselines (opacity, scale) against the
    /// true per-pixel error on the held-out views (AUROC, Spearman); writes JSON + table.
    MaskAudit {
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
    },
    /// PSNR / SSIM of a run's latest PLY on a split of a dataset; writes RUN/eval.json and
    /// render|ground-truth images into RUN/eval/<split>/.
    Eval {
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
    },
    /// Dump every intermediate (and, for backward, every gradient) of one render as .npy
    /// files with a manifest.json, for comparing a GPU port array by array.
    Oracle {
        #[command(subcommand)]
        pass: OraclePass,
    },
}

#[derive(clap::Args)]
struct OracleScene {
    /// Scene in INRIA 3DGS PLY layout.
    #[arg(long)]
    scene: PathBuf,
    /// Cameras (INRIA cameras.json).
    #[arg(long)]
    cameras: PathBuf,
    /// The camera's img_name (default: the first camera).
    #[arg(long)]
    camera: Option<String>,
    /// Output folder.
    #[arg(long)]
    out: PathBuf,
    /// Background colour, linear.
    #[arg(long, default_value = "0,0,0", value_parser = parse_rgb)]
    background: [f32; 3],
}

#[derive(Subcommand)]
enum OraclePass {
    /// Intermediates and outputs of the forward pass.
    Forward {
        #[command(flatten)]
        common: OracleScene,
    },
    /// Also the loss against a target image and the gradients of every raw parameter.
    Backward {
        #[command(flatten)]
        common: OracleScene,
        /// Target image (PNG, the camera's size), scaled to [0, 1].
        #[arg(long)]
        target: PathBuf,
        /// l1 (mean absolute difference), l2 (mean squared difference) or l1-dssim
        /// (0.8·L1 + 0.2·(1 − SSIM), INRIA's training loss).
        #[arg(long, default_value = "l1")]
        loss: String,
        /// Depth target (EXR, channel Y): adds the mean |D − target| over finite pixels.
        #[arg(long)]
        depth_target: Option<PathBuf>,
    },
}

fn parse_rgb(s: &str) -> std::result::Result<[f32; 3], String> {
    let v: Vec<f32> = s
        .split(',')
        .map(|t| {
            t.trim()
                .parse::<f32>()
                .map_err(|_| format!("'{t}' is not a number"))
        })
        .collect::<std::result::Result<_, _>>()?;
    match v.as_slice() {
        [r, g, b] if v.iter().all(|x| x.is_finite()) => Ok([*r, *g, *b]),
        _ => Err(format!("expected three finite numbers R,G,B, got '{s}'")),
    }
}

fn parse_outputs(names: &[String]) -> Result<Outputs> {
    let mut o = Outputs {
        rgb: true,
        ..Outputs::RGB
    };
    for n in names {
        match n.as_str() {
            "rgb" => o.rgb = true,
            "alpha" => o.alpha = true,
            "depth" => o.depth = true,
            "expected_depth" | "expected-depth" => o.expected_depth = true,
            other => {
                return Err(Error::invalid(format!(
                    "unknown output '{other}' (choose from rgb, alpha, depth, expected_depth)"
                )));
            }
        }
    }
    Ok(o)
}

struct Job<'a> {
    scene_path: &'a Path,
    cameras: Vec<Camera>,
    out: &'a Path,
    opts: RenderOptions,
    exr: Outputs,
}

/// Render every camera; returns the files written.
fn run_render(job: &Job) -> Result<Vec<PathBuf>> {
    let t0 = Instant::now();
    let (scene, info) = ply::read_ply(job.scene_path)?;
    if !info.ignored_properties.is_empty() {
        eprintln!(
            "note: {}: ignored vertex properties: {}",
            job.scene_path.display(),
            info.ignored_properties.join(", ")
        );
    }
    eprintln!(
        "loaded {} Gaussians (SH degree {}) in {:.0} ms",
        scene.len(),
        scene.sh_degree,
        t0.elapsed().as_secs_f64() * 1e3
    );
    unseen::io::create_dir_all(job.out)?;
    let bar = ProgressBar::new(job.cameras.len() as u64);
    bar.set_style(
        ProgressStyle::with_template("{bar:40} {pos}/{len} cameras {msg}").expect("template"),
    );
    let mut written = Vec::new();
    let (mut pairs, mut secs, mut skipped) = (0u64, 0f64, 0u64);
    for cam in &job.cameras {
        let t = Instant::now();
        let r = render(&scene, cam, &job.opts)?;
        secs += t.elapsed().as_secs_f64();
        pairs += r.report.pairs_evaluated;
        skipped += r.report.non_finite + r.report.degenerate;
        let (w, h) = (r.width, r.height);
        let stem = job.out.join(file_stem(&cam.name));
        let rgb = ImageF32::new(w, h, 3, r.rgb.clone().unwrap_or_default())?;
        let mut put = |suffix: &str, img: &ImageF32, exr: bool| -> Result<()> {
            let p = stem.with_extension(suffix);
            if exr {
                write_exr(&p, img)?
            } else {
                write_png(&p, img)?
            }
            written.push(p);
            Ok(())
        };
        put("png", &rgb, false)?;
        if job.exr.rgb {
            put("rgb.exr", &rgb, true)?;
        }
        for (flag, data, suffix) in [
            (job.exr.alpha, &r.alpha, "alpha.exr"),
            (job.exr.depth, &r.depth, "depth.exr"),
            (
                job.exr.expected_depth,
                &r.expected_depth,
                "expected_depth.exr",
            ),
        ] {
            if let (true, Some(d)) = (flag, data) {
                put(suffix, &ImageF32::new(w, h, 1, d.clone())?, true)?;
            }
        }
        bar.inc(1);
    }
    bar.finish_and_clear();
    eprintln!(
        "rendered {} camera(s) in {:.1} ms: {:.1} M Gaussian-pixel evaluations, {:.0} M/s{}",
        job.cameras.len(),
        secs * 1e3,
        pairs as f64 / 1e6,
        pairs as f64 / 1e6 / secs.max(1e-9),
        if skipped > 0 {
            format!(", {skipped} Gaussian(s) skipped as non-finite or degenerate")
        } else {
            String::new()
        }
    );
    Ok(written)
}

fn run_oracle(c: &OracleScene, targets: Option<(&Path, &str, Option<&Path>)>) -> Result<()> {
    use unseen::oracle::{Loss, Targets, dump};
    let (scene, _) = ply::read_ply(&c.scene)?;
    let cams = inria::read_cameras_json(&c.cameras)?;
    let cam = match &c.camera {
        Some(name) => cams.iter().find(|k| &k.name == name),
        None => cams.first(),
    }
    .ok_or_else(|| Error::invalid("no such camera (or the file has none)").at(&c.cameras))?;
    let opts = RenderOptions {
        background: c.background,
        ..RenderOptions::default()
    };
    let Some((target, loss, depth)) = targets else {
        dump(&scene, cam, &opts, None, &c.out)?;
        println!(
            "wrote the forward oracle of camera '{}' into {}",
            cam.name,
            c.out.display()
        );
        return Ok(());
    };
    let img = unseen::io::image::read_png(target)?;
    if (img.width, img.height) != (cam.width as usize, cam.height as usize) || img.channels != 3 {
        return Err(Error::invalid(format!(
            "target is {}x{} with {} channel(s), camera '{}' needs {}x{} RGB",
            img.width, img.height, img.channels, cam.name, cam.width, cam.height
        ))
        .at(target));
    }
    let loss = match loss {
        "l1" => Loss::L1,
        "l2" => Loss::L2,
        "l1-dssim" => Loss::L1DSsim,
        other => {
            return Err(Error::invalid(format!(
                "unknown loss '{other}' (l1, l2 or l1-dssim)"
            )));
        }
    };
    let depth_img = match depth {
        Some(p) => Some(unseen::io::image::read_exr(p, &["Y"])?),
        None => None,
    };
    if let (Some(d), Some(p)) = (&depth_img, depth) {
        if (d.width, d.height) != (cam.width as usize, cam.height as usize) {
            return Err(Error::invalid("depth target size differs from the camera's").at(p));
        }
    }
    let t = Targets {
        rgb: &img.data,
        loss,
        depth: depth_img.as_ref().map(|d| d.data.as_slice()),
    };
    dump(&scene, cam, &opts, Some(&t), &c.out)?;
    println!(
        "wrote the backward oracle of camera '{}' into {}",
        cam.name,
        c.out.display()
    );
    Ok(())
}

/// Render masks (QA-Mask directory, or a baseline of `scene`) for `cams` into `out`.
fn render_masks(scene: Option<&Path>, source: &str, cams: &[Camera], out: &Path) -> Result<usize> {
    unseen::io::create_dir_all(out)?;
    let load = || -> Result<unseen::gaussian::Gaussians> {
        let p = scene.ok_or_else(|| Error::invalid(format!("--mask {source} needs SCENE.ply")))?;
        Ok(ply::read_ply(p)?.0)
    };
    enum Src {
        Qa(unseen::gaussian::Gaussians, QaMaskConfig),
        Opacity(unseen::gaussian::Gaussians),
        Scale(unseen::gaussian::Gaussians),
    }
    let src = match source {
        "opacity" => Src::Opacity(load()?),
        "scale" => Src::Scale(load()?),
        dir => {
            let (g, c) = read_mask_dir(Path::new(dir))?;
            Src::Qa(g, c)
        }
    };
    for cam in cams {
        let m = match &src {
            Src::Qa(g, c) => render_qa_mask(g, cam, c)?,
            Src::Opacity(g) => opacity_mask(g, cam)?,
            Src::Scale(g) => scale_mask(g, cam)?,
        };
        let (w, h) = (cam.width as usize, cam.height as usize);
        let stem = file_stem(&cam.name);
        write_exr(
            &out.join(format!("{stem}.mask.exr")),
            &ImageF32::new(w, h, 1, m.clone())?,
        )?;
        write_png(
            &out.join(format!("{stem}.mask.png")),
            &ImageF32::new(w, h, 3, heat_map(&m))?,
        )?;
    }
    Ok(cams.len())
}

fn train_with_bar(
    dataset: &Path,
    out: &Path,
    cfg: &TrainConfig,
    init: Option<&Init>,
) -> Result<unseen::train::run::RunSummary> {
    let bar = ProgressBar::new(cfg.iterations as u64);
    bar.set_style(
        ProgressStyle::with_template(
            "{bar:30} {pos}/{len} {msg} [{elapsed_precise}<{eta_precise}, {per_sec}]",
        )
        .expect("valid template"),
    );
    let t0 = Instant::now();
    let mut on_progress = |p: &Progress| {
        // Without a terminal the bar is hidden: a log line every 1000 iterations instead.
        if bar.is_hidden() && (p.iteration % 1000 == 0 || p.iteration == p.iterations) {
            eprintln!(
                "iteration {}/{}: loss {:.4}, PSNR {:.2} dB, {} Gaussians, {:.1} s",
                p.iteration,
                p.iterations,
                p.loss_ema,
                p.psnr_ema,
                p.gaussians,
                t0.elapsed().as_secs_f64()
            );
        }
        if p.iteration % 10 == 0 || p.iteration == p.iterations {
            bar.set_position(p.iteration as u64);
            bar.set_message(format!(
                "loss {:.4} PSNR {:.2} dB, {} Gaussians",
                p.loss_ema, p.psnr_ema, p.gaussians
            ));
        }
    };
    let s = train_run(dataset, out, cfg, init, &mut on_progress);
    bar.finish_and_clear();
    s
}

/// Evaluate a run's latest PLY and merge the report into RUN/eval.json.
fn eval_run(
    run: &Path,
    dataset: &Path,
    split: Split,
    iteration: Option<u32>,
) -> Result<EvalReport> {
    let cfg = read_config(run)?;
    let data = load_dataset(dataset, &cfg)?;
    let (it, g) = read_run_scene(run, iteration)?;
    let split_name = match split {
        Split::Train => "train",
        Split::Test => "test",
        Split::Heldout => "heldout",
    };
    let name = if iteration.is_some() {
        format!("{split_name}_iteration_{it}")
    } else {
        split_name.to_string()
    };
    let report = evaluate(
        &g,
        &data,
        split,
        cfg.background,
        Some(&run.join("eval").join(&name)),
    )?;
    let path = run.join("eval.json");
    let mut all: serde_json::Map<String, serde_json::Value> = std::fs::read(&path)
        .ok()
        .and_then(|b| serde_json::from_slice(&b).ok())
        .unwrap_or_default();
    all.insert(name, serde_json::to_value(&report).expect("serializes"));
    let text = serde_json::to_string_pretty(&all).expect("serializes");
    unseen::io::write_text(&path, &text)?;
    Ok(report)
}

fn run(cli: Cli) -> Result<()> {
    match cli.command {
        Command::Oracle {
            pass: OraclePass::Forward { common },
        } => run_oracle(&common, None),
        Command::Oracle {
            pass:
                OraclePass::Backward {
                    common,
                    target,
                    loss,
                    depth_target,
                },
        } => run_oracle(&common, Some((&target, &loss, depth_target.as_deref()))),
        Command::Demo(a) => pipeline::run_demo(&a),
        Command::Extrapolate(a) => pipeline::run_extrapolate(&a),
        Command::Compare(a) => {
            if pipeline::run_compare(&a)? {
                Ok(())
            } else {
                Err(Error::invalid("the runs diverge"))
            }
        }
        Command::Warp(a) => geometry::run_warp(&a),
        Command::Inpaint(a) => models::run_inpaint(&a),
        Command::Depth(a) => models::run_depth(&a),
        Command::Collide(a) => geometry::run_collide(&a),
        Command::Views(a) => geometry::run_views(&a),
        Command::Train {
            dataset,
            out,
            iterations,
            seed,
            resolution,
            sh_degree,
            config,
            init,
            mask,
            mask_dir,
        } => {
            let mut cfg = match config {
                Some(p) => {
                    let text = std::fs::read(&p).map_err(|e| Error::io(&p, e))?;
                    serde_json::from_slice::<TrainConfig>(&text)
                        .map_err(|e| Error::parse(&p, format!("invalid train config: {e}")))?
                }
                None => TrainConfig::default(),
            };
            if let Some(v) = iterations {
                cfg.iterations = v;
            }
            if let Some(v) = seed {
                cfg.seed = v;
            }
            if let Some(v) = resolution {
                cfg.resolution = v;
            }
            if let Some(v) = sh_degree {
                cfg.sh_degree = v;
            }
            let init = match init {
                None if mask != "none" => {
                    return Err(Error::invalid(
                        "--mask needs --init RUN (it weights a fine-tune)",
                    ));
                }
                None => None,
                Some(run) => {
                    let (_, scene) = read_run_scene(&run, None)?;
                    let source = match mask.as_str() {
                        "none" => MaskSource::None,
                        "opacity" => MaskSource::Opacity,
                        "qa" => {
                            let Some(dir) = &mask_dir else {
                                return Err(Error::invalid("--mask qa needs --mask-dir DIR"));
                            };
                            let (g, c) = read_mask_dir(dir)?;
                            MaskSource::Qa(Box::new((g, c)))
                        }
                        m => {
                            return Err(Error::invalid(format!(
                                "unknown --mask '{m}' (none, opacity or qa)"
                            )));
                        }
                    };
                    if !matches!(source, MaskSource::None) {
                        cfg.loss = LossWeights::PAPER;
                    }
                    cfg.sh_degree = scene.sh_degree;
                    Some(Init {
                        scene,
                        mask: source,
                    })
                }
            };
            let s = train_with_bar(&dataset, &out, &cfg, init.as_ref())?;
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
        Command::QaMask {
            run,
            out,
            sh_degree,
            iterations,
            colors,
            lr,
            seed,
        } => {
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
        Command::MaskAudit {
            run,
            dataset,
            degrees,
            iterations,
            lr,
            out,
        } => {
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
        Command::Eval {
            run,
            dataset,
            split,
            iteration,
        } => {
            let r = eval_run(&run, &dataset, split, iteration)?;
            print!("{}", r.table());
            println!("wrote {}", run.join("eval.json").display());
            Ok(())
        }
        Command::Render {
            scene,
            cameras,
            out,
            camera,
            sh_degree,
            background,
            outputs,
            mask,
        } => {
            let mut cams = inria::read_cameras_json(&cameras)?;
            if let Some(name) = camera {
                cams.retain(|c| c.name == name);
                if cams.is_empty() {
                    return Err(Error::invalid(format!("no camera named '{name}'")).at(&cameras));
                }
            }
            if let Some(m) = mask {
                let n = render_masks(scene.as_deref(), &m, &cams, &out)?;
                println!("wrote {n} mask(s) into {}", out.display());
                return Ok(());
            }
            let Some(scene) = scene else {
                return Err(Error::invalid("render needs a SCENE.ply (or --mask DIR)"));
            };
            let exr = parse_outputs(&outputs)?;
            let exr = Outputs {
                rgb: outputs.iter().any(|o| o == "rgb"),
                ..exr
            };
            let opts = RenderOptions {
                background,
                sh_degree,
                outputs: Outputs { rgb: true, ..exr },
                ..RenderOptions::default()
            };
            let files = run_render(&Job {
                scene_path: &scene,
                cameras: cams,
                out: &out,
                opts,
                exr,
            })?;
            println!("wrote {} file(s) into {}", files.len(), out.display());
            Ok(())
        }
    }
}

fn main() -> ExitCode {
    match run(Cli::parse()) {
        Ok(()) => ExitCode::SUCCESS,
        Err(e) => {
            eprintln!("error: {e}");
            ExitCode::FAILURE
        }
    }
}
