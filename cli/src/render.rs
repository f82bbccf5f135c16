//! `unseen render` and `unseen oracle` (SPEC.md §11, §12).

use clap::{Args, Subcommand};
use indicatif::{ProgressBar, ProgressStyle};
use std::path::{Path, PathBuf};
use std::time::Instant;
use unseen::camera::{Camera, find, inria};
use unseen::error::{Error, Result};
use unseen::gaussian::ply;
use unseen::io::file_stem;
use unseen::io::image::{ImageF32, write_exr, write_png};
use unseen::qamask::{
    QaMaskConfig, heat_map, opacity_mask, read_mask_dir, render_qa_mask, scale_mask,
};
use unseen::raster::{Conventions, Cutoffs, Outputs, RenderOptions, render};

#[derive(Args)]
pub struct RenderArgs {
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
    /// Smallest alpha that is blended, as 1/N or 0 (every α > 0): gsplat's 1/255 by
    /// default. A forward-only knob for images (--mask renders keep gsplat's; SPEC.md §5.4).
    #[arg(long, default_value = "1/255", value_parser = parse_alpha_threshold)]
    alpha_threshold: f32,
    /// Blending stops before a splat that would bring transmittance to this or below:
    /// gsplat's 1e-4 by default, 0 for never early. A forward-only knob for images.
    #[arg(long, default_value_t = Cutoffs::GSPLAT.transmittance_stop)]
    transmittance_stop: f32,
    /// Convention profile: `inria` (α clamp 0.99, INRIA and gsplat ≥ 1.5.4) or `gsplat`
    /// (α clamp 0.999, gsplat 1.0–1.5.3) (SPEC.md §5.2).
    #[arg(long, default_value = "inria", value_parser = parse_conventions)]
    conventions: Conventions,
}

/// `inria` or `gsplat` (SPEC.md §5.2).
pub fn parse_conventions(s: &str) -> std::result::Result<Conventions, String> {
    Conventions::parse(s).map_err(|e| e.to_string())
}

/// `1/N` (N ≥ 1, or `inf`) or `0` as the reciprocal threshold `N` (`0` → +∞), so that
/// `1/255` keeps gsplat's bits (the rasterizer uses `N` itself).
pub fn parse_alpha_threshold(s: &str) -> std::result::Result<f32, String> {
    let t = s.trim();
    if t == "0" {
        return Ok(f32::INFINITY);
    }
    let n = t
        .strip_prefix("1/")
        .and_then(|n| n.trim().parse::<f32>().ok())
        .ok_or_else(|| format!("expected 1/N or 0, got '{s}'"))?;
    if n >= 1.0 {
        Ok(n)
    } else {
        Err(format!("expected 1/N with N ≥ 1, got '{s}'"))
    }
}

#[derive(Args)]
pub struct OracleArgs {
    #[command(subcommand)]
    pass: OraclePass,
}

#[derive(clap::Args)]
pub struct OracleScene {
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
    /// Convention profile: `inria` (α clamp 0.99) or `gsplat` (0.999, gsplat 1.0–1.5.3);
    /// recorded in the dump's manifest (SPEC.md §5.2, §12).
    #[arg(long, default_value = "inria", value_parser = parse_conventions)]
    conventions: Conventions,
}

#[derive(Subcommand)]
pub enum OraclePass {
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
    /// Adam from zero moments over a sequence of gradients: every step's parameters and
    /// moments (SPEC.md §14.2), what a port of the optimizer is diffed against.
    Adam {
        /// The parameters, float32 .npy of shape (N,).
        #[arg(long)]
        params: PathBuf,
        /// The gradients, float32 .npy of shape (S, N): one row per step.
        #[arg(long)]
        grads: PathBuf,
        #[arg(long)]
        lr: f64,
        #[arg(long, default_value_t = 0.9)]
        beta1: f64,
        #[arg(long, default_value_t = 0.999)]
        beta2: f64,
        #[arg(long, default_value_t = 1e-15)]
        eps: f32,
        /// Adam's constants: `pytorch` (torch.optim.Adam's, Python-float β) or `unseen` (the
        /// trainer's float32 β). `--conventions` is the older spelling.
        #[arg(long, alias = "conventions", default_value = "pytorch")]
        constants: String,
        /// Output folder.
        #[arg(long)]
        out: PathBuf,
    },
    /// The DIBR forward warp traced for a port's comparison (SPEC.md §18): the warp, each
    /// source pixel's projection and the target pixels near a decision (`unseen warp`'s
    /// arguments; `--out` receives .npy files and a manifest).
    Warp {
        #[command(flatten)]
        args: crate::geometry::WarpArgs,
    },
    /// The QA-Mask of a (fine-tuned) mask scene for one camera (SPEC.md §15.1): the mask
    /// and the colour it projects, rendered over the base colour.
    QaMask {
        /// The mask scene (INRIA 3DGS PLY), e.g. `unseen qa-mask`'s output.
        scene: PathBuf,
        /// Cameras (INRIA cameras.json).
        #[arg(long)]
        cameras: PathBuf,
        /// The camera's img_name (default: the first camera).
        #[arg(long)]
        camera: Option<String>,
        /// The base colour (background of the render): a name or R,G,B in [0, 1].
        #[arg(long, default_value = "red")]
        base: String,
        /// The target colour of the fine-tune.
        #[arg(long, default_value = "black")]
        target: String,
        /// Output folder.
        #[arg(long)]
        out: PathBuf,
    },
    /// The depth alignment `s·r + t ≈ m` (SPEC.md §17): per pixel the relative residual and
    /// whether it is an inlier, the fit in the manifest.
    Align {
        /// The estimate r: float32 .npy of any shape.
        estimate: PathBuf,
        /// The metric depth (valid: finite and > 0): float32 .npy of the estimate's shape.
        depth: PathBuf,
        /// `depth` (m = d) or `disparity` (m = 1/d).
        #[arg(long, default_value = "disparity", value_parser = crate::one_of(&unseen::warp::align::Space::ALL, unseen::warp::align::Space::name))]
        space: unseen::warp::align::Space,
        /// `ransac` or `least_squares`.
        #[arg(long, default_value = "ransac")]
        method: String,
        /// RANSAC: inlier when `|s·r + t − m| ≤ threshold·|m|`.
        #[arg(long, default_value_t = unseen::warp::align::RansacConfig::default().threshold)]
        threshold: f64,
        /// RANSAC: at most this many iterations (adaptive stop at 0.999 confidence).
        #[arg(long, default_value_t = unseen::warp::align::RansacConfig::default().iterations)]
        iterations: u32,
        #[arg(long, default_value_t = 0)]
        seed: u64,
        /// Output folder.
        #[arg(long)]
        out: PathBuf,
    },
    /// One densify-and-prune step with INRIA's thresholds and the split children's draws
    /// given (SPEC.md §14.3): the new scene as .npy (gsplat's conventions) and the counts.
    Densify {
        /// The scene (INRIA 3DGS PLY).
        scene: PathBuf,
        /// Per Gaussian, the sum over visible views of the NDC mean-gradient norm: float32
        /// .npy of shape (N,).
        #[arg(long)]
        grad_accum: PathBuf,
        /// Per Gaussian, the views it was visible in: float32 .npy (N,) of whole numbers.
        #[arg(long)]
        count: PathBuf,
        /// The split children's draws: float32 .npy (2, N, 3), copy c of Gaussian i takes
        /// [c, i].
        #[arg(long)]
        normals: PathBuf,
        /// The scene extent.
        #[arg(long)]
        extent: f32,
        /// Test large Gaussians too (after the first opacity reset).
        #[arg(long)]
        world_prune: bool,
        /// Output folder.
        #[arg(long)]
        out: PathBuf,
    },
    /// GJK's proximity of two convex polyhedra (SPEC.md §16.1): distance, its lower bound,
    /// the contact band, the verdict and the iterations, as .npy scalars.
    Collide {
        /// First polyhedron: {"vertices": [[x, y, z], ...]} (their convex hull).
        a: PathBuf,
        /// Second polyhedron, same format.
        b: PathBuf,
        /// Output folder.
        #[arg(long)]
        out: PathBuf,
    },
    /// Independent-view detection array by array (SPEC.md §16.2–16.3; `unseen views`'s
    /// arguments): the frustums' vertices, every pair's distance and lower bound, the
    /// collisions, the independent views and their trajectory.
    Views {
        #[command(flatten)]
        args: crate::geometry::ViewsArgs,
    },
    /// Telea inpainting traced for a port's comparison (SPEC.md §19.1): the fill, each
    /// pixel's arrival time and order, and per value its mean, gradient term, error bound
    /// and decisions; with `--forced`, each value computed from the port's predecessors.
    Inpaint {
        /// The image: PNG (8-bit gray or RGB: uint8 arithmetic, as cv2.inpaint on uint8)
        /// or float32 .npy of shape (H, W) or (H, W, C).
        image: PathBuf,
        /// The pixels to fill: PNG or .npy of the image's size, non-zero = fill.
        mask: PathBuf,
        #[arg(long, default_value_t = 3.0)]
        radius: f64,
        /// A port's output (the image's format and size): the fill is judged on it.
        #[arg(long)]
        forced: Option<PathBuf>,
        /// Output folder.
        #[arg(long)]
        out: PathBuf,
    },
}

pub fn parse_rgb(s: &str) -> std::result::Result<[f32; 3], String> {
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
        let mut r = render(&scene, cam, &job.opts)?;
        secs += t.elapsed().as_secs_f64();
        pairs += r.report.pairs_evaluated;
        skipped += r.report.non_finite + r.report.degenerate;
        let (w, h) = (r.width, r.height);
        let stem = job.out.join(file_stem(&cam.name));
        // Moved, not copied: a 4K frame's colour is 100 MB.
        let rgb = ImageF32::new(w, h, 3, r.rgb.take().unwrap_or_default())?;
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
        Some(name) => find(&cams, name, &c.cameras)?,
        None => cams
            .first()
            .ok_or_else(|| Error::invalid("the file has no camera").at(&c.cameras))?,
    };
    let opts = RenderOptions {
        background: c.background,
        conventions: c.conventions,
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
    if let (Some(d), Some(p)) = (&depth_img, depth)
        && (d.width, d.height) != (cam.width as usize, cam.height as usize)
    {
        return Err(Error::invalid("depth target size differs from the camera's").at(p));
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

pub fn run_render_command(a: RenderArgs) -> Result<()> {
    let RenderArgs {
        scene,
        cameras,
        out,
        camera,
        sh_degree,
        background,
        outputs,
        mask,
        alpha_threshold,
        transmittance_stop,
        conventions,
    } = a;
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
        cutoffs: Cutoffs {
            inv_alpha_threshold: alpha_threshold,
            transmittance_stop,
        },
        conventions,
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

pub fn run_oracle_command(a: OracleArgs) -> Result<()> {
    match a.pass {
        OraclePass::Forward { common } => run_oracle(&common, None),
        OraclePass::Backward {
            common,
            target,
            loss,
            depth_target,
        } => run_oracle(&common, Some((&target, &loss, depth_target.as_deref()))),
        OraclePass::Adam {
            params,
            grads,
            lr,
            beta1,
            beta2,
            eps,
            constants,
            out,
        } => {
            use unseen::train::adam::Constants;
            let constants = Constants::by_name(&constants)?;
            let (xs, x0) = unseen::io::npy::read_npy_f32(&params)?;
            let [n] = xs[..] else {
                return Err(Error::invalid(format!(
                    "the parameters must have shape (N,), got {xs:?}"
                ))
                .at(&params));
            };
            let (gs, g) = unseen::io::npy::read_npy_f32(&grads)?;
            if gs.len() != 2 || gs[1] != n {
                return Err(Error::invalid(format!(
                    "the gradients must have shape (S, {n}) (one row per step), got {gs:?}"
                ))
                .at(&grads));
            }
            unseen::oracle::dump_adam(&x0, &g, ([beta1, beta2], eps, lr), constants, &out)?;
            println!(
                "wrote {} Adam steps of {n} parameters into {}",
                gs[0],
                out.display()
            );
            Ok(())
        }
        OraclePass::Inpaint {
            image,
            mask,
            radius,
            forced,
            out,
        } => run_oracle_inpaint(&image, &mask, radius, forced.as_deref(), &out),
        OraclePass::Densify {
            scene,
            grad_accum,
            count,
            normals,
            extent,
            world_prune,
            out,
        } => {
            let (g, _) = ply::read_ply(&scene)?;
            let n = g.len();
            let vector = |path: &Path| -> Result<Vec<f32>> {
                let (shape, v) = unseen::io::npy::read_npy_f32(path)?;
                if shape != [n] {
                    return Err(Error::invalid(format!(
                        "expected shape ({n},) for the scene's {n} Gaussians, got {shape:?}"
                    ))
                    .at(path));
                }
                Ok(v)
            };
            let acc = vector(&grad_accum)?;
            if let Some(i) = acc.iter().position(|v| !(v.is_finite() && *v >= 0.0)) {
                return Err(
                    Error::invalid(format!("value {i} is not a finite non-negative sum"))
                        .at(&grad_accum),
                );
            }
            let counts = vector(&count)?
                .iter()
                .map(|&c| {
                    (c >= 0.0 && c.fract() == 0.0 && c <= u32::MAX as f32)
                        .then_some(c as u32)
                        .ok_or_else(|| {
                            Error::invalid(format!("{c} is not a whole view count")).at(&count)
                        })
                })
                .collect::<Result<Vec<u32>>>()?;
            let (zs, z) = unseen::io::npy::read_npy_f32(&normals)?;
            if zs != [2, n, 3] || z.iter().any(|v| !v.is_finite()) {
                return Err(Error::invalid(format!(
                    "expected finite draws of shape (2, {n}, 3), got {zs:?}"
                ))
                .at(&normals));
            }
            let z: Vec<[f32; 3]> = z.chunks_exact(3).map(|c| [c[0], c[1], c[2]]).collect();
            unseen::oracle::dump_densify(g, (acc, counts), extent, world_prune, &z, &out)?;
            println!(
                "wrote one densification step of {n} Gaussians into {}",
                out.display()
            );
            Ok(())
        }
        OraclePass::QaMask {
            scene,
            cameras,
            camera,
            base,
            target,
            out,
        } => {
            use unseen::qamask::{QaMaskConfig, parse_color};
            let (g, _) = ply::read_ply(&scene)?;
            let cams = inria::read_cameras_json(&cameras)?;
            let cam = match &camera {
                Some(name) => find(&cams, name, &cameras)?,
                None => cams
                    .first()
                    .ok_or_else(|| Error::invalid("the file lists no camera").at(&cameras))?,
            };
            let cfg = QaMaskConfig {
                sh_degree: g.sh_degree,
                base_color: parse_color(&base)?,
                target_color: parse_color(&target)?,
                ..QaMaskConfig::default()
            };
            unseen::oracle::dump_qa_mask(&g, cam, &cfg, &out).map_err(|e| e.at(&scene))?;
            println!(
                "wrote the QA-Mask of camera '{}' into {}",
                cam.name,
                out.display()
            );
            Ok(())
        }
        OraclePass::Align {
            estimate,
            depth,
            space,
            method,
            threshold,
            iterations,
            seed,
            out,
        } => {
            use unseen::warp::align::RansacConfig;
            let (shape, r) = unseen::io::npy::read_npy_f32(&estimate)?;
            let (dshape, d) = unseen::io::npy::read_npy_f32(&depth)?;
            if dshape != shape {
                return Err(Error::invalid(format!(
                    "the depth has shape {dshape:?}, the estimate {shape:?}"
                ))
                .at(&depth));
            }
            let cfg = RansacConfig {
                threshold,
                iterations,
                seed,
                ..RansacConfig::default()
            };
            let ransac = match method.as_str() {
                "ransac" => Some(&cfg),
                "least_squares" => None,
                other => {
                    return Err(Error::invalid(format!(
                        "--method: expected ransac or least_squares, got {other:?}"
                    )));
                }
            };
            unseen::oracle::dump_align(&r, &d, &shape, space, ransac, &out)
                .map_err(|e| e.at(&estimate))?;
            println!(
                "wrote the {method} alignment of {} into {}",
                estimate.display(),
                out.display()
            );
            Ok(())
        }
        OraclePass::Collide { a, b, out } => {
            let (ha, hb) = (
                crate::geometry::read_hull(&a)?,
                crate::geometry::read_hull(&b)?,
            );
            unseen::oracle::dump_collide(&ha, &hb, &out)?;
            println!(
                "wrote the proximity of {} and {} into {}",
                a.display(),
                b.display(),
                out.display()
            );
            Ok(())
        }
        OraclePass::Views { args } => {
            let i = args.inputs()?;
            let cams: Vec<&unseen::camera::Camera> = i.cameras.iter().collect();
            unseen::oracle::dump_views(&cams, &i.masks, &i.ranges, args.outline(), args.out())?;
            println!(
                "wrote independent-view detection of {} candidates into {}",
                cams.len(),
                args.out().display()
            );
            Ok(())
        }
        OraclePass::Warp { args } => {
            let i = args.inputs()?;
            unseen::oracle::dump_warp(&i.image, &i.depth, &i.from, &i.to, &i.opts, args.out())?;
            println!(
                "wrote the warp oracle {} -> {} into {}",
                i.from.name,
                i.to.name,
                args.out().display()
            );
            Ok(())
        }
    }
}

/// An inpainting input: 8-bit PNG values or float32 .npy values, with its size.
enum Values {
    U8(Vec<u8>),
    F32(Vec<f32>),
}

fn read_values(path: &Path) -> Result<(Values, (usize, usize, usize))> {
    let is_npy = path
        .extension()
        .is_some_and(|e| e.eq_ignore_ascii_case("npy"));
    if is_npy {
        let (shape, v) = unseen::io::npy::read_npy_f32(path)?;
        let size = match shape[..] {
            [h, w] => (w, h, 1),
            [h, w, c] => (w, h, c),
            _ => {
                return Err(Error::invalid(format!(
                    "expected shape (H, W) or (H, W, C), got {shape:?}"
                ))
                .at(path));
            }
        };
        if let Some(i) = v.iter().position(|x| !x.is_finite()) {
            return Err(Error::invalid(format!("value {i} is not finite")).at(path));
        }
        Ok((Values::F32(v), size))
    } else {
        let img = unseen::io::image::read_png(path)?;
        let bytes = img
            .data
            .iter()
            .map(|&v| unseen::io::image::to_u8(v))
            .collect();
        Ok((Values::U8(bytes), (img.width, img.height, img.channels)))
    }
}

fn run_oracle_inpaint(
    image: &Path,
    mask: &Path,
    radius: f64,
    forced: Option<&Path>,
    out: &Path,
) -> Result<()> {
    use unseen::oracle::dump_inpaint;
    let (values, size) = read_values(image)?;
    let (w, h, c) = size;
    let (m, msize) = read_values(mask)?;
    if (msize.0, msize.1) != (w, h) {
        return Err(Error::invalid(format!(
            "the mask is {}x{}, the image {w}x{h}",
            msize.0, msize.1
        ))
        .at(mask));
    }
    let fill: Vec<bool> = match m {
        Values::U8(v) => v
            .chunks(msize.2)
            .map(|p| p.iter().any(|&x| x > 0))
            .collect(),
        Values::F32(v) => v
            .chunks(msize.2)
            .map(|p| p.iter().any(|&x| x != 0.0))
            .collect(),
    };
    let forced = match forced {
        Some(p) => {
            let (v, s) = read_values(p)?;
            if s != size {
                return Err(Error::invalid(format!(
                    "the forced image is {}x{}x{}, the image {w}x{h}x{c}",
                    s.0, s.1, s.2
                ))
                .at(p));
            }
            Some((v, p))
        }
        None => None,
    };
    match (values, forced) {
        (Values::U8(v), None) => dump_inpaint(&v, size, &fill, radius, None, out),
        (Values::U8(v), Some((Values::U8(f), _))) => {
            dump_inpaint(&v, size, &fill, radius, Some(&f), out)
        }
        (Values::F32(v), None) => dump_inpaint(&v, size, &fill, radius, None, out),
        (Values::F32(v), Some((Values::F32(f), _))) => {
            dump_inpaint(&v, size, &fill, radius, Some(&f), out)
        }
        (_, Some((_, p))) => Err(Error::invalid(
            "the forced image must have the image's format (PNG with PNG, .npy with .npy)",
        )
        .at(p)),
    }
    .map_err(|e| e.at(image))?;
    println!(
        "wrote the Telea oracle of {} ({} pixels to fill) into {}",
        image.display(),
        fill.iter().filter(|&&f| f).count(),
        out.display()
    );
    Ok(())
}
