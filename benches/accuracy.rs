//! What accuracy costs in time:
//! `cargo bench --bench accuracy [-- --quick] [--only STAGE,...] [--out DIR]`.
//!
//! Per stage and knob, the error against a shadow computed in the same run and the time,
//! written to `DIR/accuracy.csv`, `DIR/accuracy.md` and `DIR/accuracy.svg` (default
//! `reference_data/accuracy/`). A point is on its stage's Pareto front when no other point
//! of the stage has both less error and less time. Stages (SPEC.md §5.10):
//! - `forward`: an SH-5 scene rendered in f32 at SH degree 0–5 (and every kernel form at 5)
//!   against the f64 twin of the forward at degree 5 (`tests/engine/twin.rs`), and the twin;
//! - `cutoffs`: the blend's cut-offs (`raster::Cutoffs`: alpha threshold 1/255, 1/1000,
//!   none; transmittance stop 1e-4, 1e-6, none) in f32 against exact blending — the f64
//!   twin with neither cut-off (and, unlike the rasterizer, no 3.33σ extent and no σ
//!   clamp) — on the forward stage's scene at SH 3;
//! - `blend`: 16×16 tile lists against one list for the whole image (the same bits), and
//!   f32 against f64 accumulation, against the f64 twin, on the same scene;
//! - `backward`: f32 gradients of every raw parameter against f64 central differences of
//!   the twin, on a smooth scene;
//! - `exp`: our Cephes `exp` (what the blend uses), the platform's `f32::exp`, and `f64::exp`
//!   rounded to f32, in ulp against `f64::exp` (scalar and in AVX2 / AVX-512F lanes);
//! - `ransac`: RANSAC iterations and inlier threshold against the known scale of synthetic
//!   depths with 30 % outliers and ±3 % noise on the inliers (a monocular estimator's
//!   error), relative scale error; and least squares.
//! - `gjk`: the duality-gap tolerance and the iteration cap against box pairs of known
//!   distance (`collide::gjk::proximity_with`);
//! - `gjk-frustums`: the same knobs on random frustum pairs and pairs with nearly
//!   parallel facing faces, against the exact distance by exhaustion
//!   (`tests/engine/polytope.rs`);
//! - `dibr`, `dibr-edges` (both with `--only dibr`): the warp's footprint and crack
//!   closing against a ray-traced plane, and the plane behind a card (depth edges);
//! - `ssim`: the float type (f64 / f32) and window form (separable / direct 11×11) of the
//!   loss's SSIM against the f64 direct window;
//! - `ssim-grad`: the loss's SSIM gradient against f64 central differences of the direct
//!   window (Richardson-extrapolated), every pixel and channel of a small image pair;
//! - `training`: iterations with and without densification on `lounge` against the
//!   test views' mean squared error (ground truth), checkpoints of one run each;
//! - `qa-mask`: fine-tune iterations × SH degree 3–5 against a long SH-5 fine-tune, mean
//!   mask difference on the held-out views;
//! - `pipeline` (full runs only): the `quick` and `paper` presets on the demo's original,
//!   extrapolated-pixel error on the evaluation poses after each stage against the time.
//!
//! Times are the best of several runs on one thread; errors are exact maxima over the
//! inputs used. `--only` prints the chosen stages and writes files only with `--out`.

mod common;

#[path = "../tests/engine/twin.rs"]
#[allow(dead_code)]
mod twin;

#[path = "../tests/engine/polytope.rs"]
mod polytope;

use common::best;
use std::fmt::Write as _;
use std::path::PathBuf;
use std::time::Instant;
use unseen::camera::Camera;
use unseen::gaussian::Gaussians;
use unseen::math::fastexp;
use unseen::pipeline::compare::ulp_distance;
use unseen::raster::{Kernel, Outputs, RenderOptions, render};
use unseen::rng::Uniform;
use unseen::scene::{default_camera, random_scene};
use unseen::warp::align::{Frame, RansacConfig, Space, least_squares, ransac};

struct Point {
    stage: &'static str,
    knob: String,
    /// The shipped default of the stage.
    default: bool,
    metric: &'static str,
    error: f64,
    seconds: f64,
    pareto: bool,
}

/// The scene of SH degree `degree`, camera and background of the `forward` and `cutoffs`
/// stages.
fn forward_setup(quick: bool, degree: u32) -> (Gaussians, Camera, [f32; 3]) {
    let (n, w, h) = if quick {
        (3000, 96, 72)
    } else {
        (20000, 192, 144)
    };
    (
        random_scene(n, degree, 7, 0.01, 0.25),
        default_camera(w, h),
        [0.1, 0.2, 0.3],
    )
}

fn forward(quick: bool, points: &mut Vec<Point>) {
    // One scene of SH degree 5 against its full-degree f64 twin: rendering at a lower
    // degree (`RenderOptions::sh_degree`) trades the truncated bands' colour for time.
    let (scene, cam, bg) = forward_setup(quick, 5);
    let p = twin::flatten(&scene);
    let (t64, reference) = best(1, || twin::forward64(&scene, &p, &cam, bg.map(f64::from)));
    let metric = "max |rgb − f64 twin of SH 5|";
    for degree in [0u32, 1, 2, 3, 4, 5] {
        let kernels: &[(Kernel, &str)] = if degree == 5 {
            &[
                (Kernel::Auto, "auto"),
                (Kernel::Avx2, "avx2"),
                (Kernel::Scalar, "scalar"),
            ]
        } else {
            &[(Kernel::Auto, "auto")]
        };
        for &(kernel, kname) in kernels {
            let opts = RenderOptions {
                background: bg,
                outputs: Outputs::RGB,
                kernel,
                sh_degree: Some(degree),
                ..Default::default()
            };
            let (t, r) = best(5, || render(&scene, &cam, &opts).expect("renders"));
            let rgb = r.rgb.expect("rgb");
            let err = rgb
                .iter()
                .zip(&reference[0])
                .map(|(&a, &b)| (a as f64 - b).abs())
                .fold(0.0, f64::max);
            points.push(Point {
                stage: "forward",
                knob: format!("f32 render at SH {degree}, kernel {kname}"),
                default: degree == 5 && kernel == Kernel::Auto,
                metric,
                error: err,
                seconds: t,
                pareto: false,
            });
        }
    }
    points.push(Point {
        stage: "forward",
        knob: "f64 twin at SH 5 (the shadow itself)".into(),
        default: false,
        metric,
        error: 0.0,
        seconds: t64,
        pareto: false,
    });
}

fn cutoffs(quick: bool, points: &mut Vec<Point>) {
    use unseen::raster::Cutoffs;
    let (scene, cam, bg) = forward_setup(quick, 3);
    let p = twin::flatten(&scene);
    let (t64, exact) = best(1, || {
        twin::forward64_cut(&scene, &p, &cam, bg.map(f64::from), 0.0, 0.0)
    });
    let metric = "max |rgb − f64 exact blending|";
    let knobs: [(f32, &str, f32, &str); 6] = [
        (255.0, "1/255", 1e-4, "1e-4"),
        (1000.0, "1/1000", 1e-4, "1e-4"),
        (255.0, "1/255", 1e-6, "1e-6"),
        (1000.0, "1/1000", 1e-6, "1e-6"),
        (f32::INFINITY, "0", 1e-6, "1e-6"),
        (f32::INFINITY, "0", 0.0, "0"),
    ];
    for (inv, iname, stop, sname) in knobs {
        let opts = RenderOptions {
            background: bg,
            outputs: Outputs::RGB,
            cutoffs: Cutoffs {
                inv_alpha_threshold: inv,
                transmittance_stop: stop,
            },
            ..Default::default()
        };
        let (t, r) = best(5, || render(&scene, &cam, &opts).expect("renders"));
        let err = r
            .rgb
            .expect("rgb")
            .iter()
            .zip(&exact[0])
            .map(|(&a, &b)| (a as f64 - b).abs())
            .fold(0.0, f64::max);
        points.push(Point {
            stage: "cutoffs",
            knob: format!("f32, alpha threshold {iname}, transmittance stop {sname}"),
            default: opts.cutoffs == Cutoffs::GSPLAT,
            metric,
            error: err,
            seconds: t,
            pareto: false,
        });
    }
    points.push(Point {
        stage: "cutoffs",
        knob: "f64 exact blending (the shadow itself)".into(),
        default: false,
        metric,
        error: 0.0,
        seconds: t64,
        pareto: false,
    });
}

/// The blend's structure: tile lists against one list for the whole image, and f32
/// against f64 accumulation (transmittance and sums; α stays f32), on the `cutoffs`
/// stage's scene at SH 3 with gsplat's cut-offs, against the f64 twin of the whole forward
/// (`twin::forward64`). The untiled forms are `twin::blend_untiled` (plain scalar loops
/// over the splats the projection gives), so their times compare with each other and with
/// the scalar kernel, not with the vector kernels.
fn blend(quick: bool, points: &mut Vec<Point>) {
    use unseen::raster::project::project;
    use unseen::raster::{RenderPlan, RenderReport};
    let (scene, cam, bg) = forward_setup(quick, 3);
    let p = twin::flatten(&scene);
    let (t64, reference) = best(1, || twin::forward64(&scene, &p, &cam, bg.map(f64::from)));
    let metric = "max |rgb − f64 twin|";
    let err = |rgb: &mut dyn Iterator<Item = f64>| {
        rgb.zip(&reference[0])
            .map(|(a, &b)| (a - b).abs())
            .fold(0.0, f64::max)
    };
    let mean_err = |rgb: &mut dyn Iterator<Item = f64>| {
        rgb.zip(&reference[0])
            .map(|(a, &b)| (a - b).abs())
            .sum::<f64>()
            / reference[0].len() as f64
    };
    let mut tiled = Vec::new();
    for (kernel, kname) in [(Kernel::Auto, "auto"), (Kernel::Scalar, "scalar")] {
        let opts = RenderOptions {
            background: bg,
            outputs: Outputs::RGB,
            kernel,
            ..Default::default()
        };
        let (t, r) = best(5, || render(&scene, &cam, &opts).expect("renders"));
        tiled = r.rgb.expect("rgb");
        points.push(Point {
            stage: "blend",
            knob: format!("16×16 tiles, f32 accumulation, kernel {kname} (the rasterizer)"),
            default: kernel == Kernel::Auto,
            metric,
            error: err(&mut tiled.iter().map(|&v| f64::from(v))),
            seconds: t,
            pareto: false,
        });
    }
    let opts = RenderOptions {
        background: bg,
        outputs: Outputs::RGB,
        ..Default::default()
    };
    let plan = RenderPlan::new(&scene, &opts);
    let (w, h) = (cam.width as usize, cam.height as usize);
    let project = || project(&scene, &cam, &plan, &opts, &mut RenderReport::default());
    let (t32, out32) = best(3, || twin::blend_untiled::<f32>(&project(), w, h, bg));
    assert_eq!(
        out32[0].iter().map(|v| v.to_bits()).collect::<Vec<_>>(),
        tiled.iter().map(|v| v.to_bits()).collect::<Vec<_>>(),
        "the tiles changed the image (test `tiles_change_no_output_bit`)"
    );
    points.push(Point {
        stage: "blend",
        knob: format!(
            "no tiles (one list for the image), f32 accumulation, scalar: the same bits (mean {:.2e})",
            mean_err(&mut out32[0].iter().map(|&v| f64::from(v)))
        ),
        default: false,
        metric,
        error: err(&mut out32[0].iter().map(|&v| f64::from(v))),
        seconds: t32,
        pareto: false,
    });
    let (tmix, out64) = best(3, || twin::blend_untiled::<f64>(&project(), w, h, bg));
    points.push(Point {
        stage: "blend",
        knob: format!(
            "no tiles, f32 α, f64 accumulation, scalar (mean {:.2e})",
            mean_err(&mut out64[0].iter().copied())
        ),
        default: false,
        metric,
        error: err(&mut out64[0].iter().copied()),
        seconds: tmix,
        pareto: false,
    });
    points.push(Point {
        stage: "blend",
        knob: "f64 twin (the shadow itself)".into(),
        default: false,
        metric,
        error: 0.0,
        seconds: t64,
        pareto: false,
    });
}

/// The backward against central finite differences (in f64) of the f64 twin: the tests'
/// smooth scene of five large Gaussians (`twin::smooth_scene`, SH degree 3, 24×18 image) and the loss `Σ w·rgb`, every raw parameter. The
/// loss is smooth only piecewise (the α = 1/255 cut-off crosses the image border region), so
/// a difference that straddled a crossing would show as a large error; none does here.
fn backward_fd(points: &mut Vec<Point>) {
    use unseen::raster::backward::{GradGroups, ImageGrads, backward, render_for_backward};
    let cam = default_camera(24, 18);
    let npix = 24 * 18;
    let bg = [0.1f32, 0.2, 0.3];
    let g = twin::smooth_scene(3, 21);
    let mut u = Uniform::new(21);
    let w: Vec<f32> = (0..npix * 3)
        .map(|_| u.range(-1.0, 1.0) / npix as f32)
        .collect();
    let loss64 = |p: &[f64]| -> f64 {
        let out = twin::forward64(&g, p, &cam, bg.map(f64::from));
        out[0].iter().zip(&w).map(|(&a, &b)| a * b as f64).sum()
    };
    let p0 = twin::flatten(&g);
    let (t_fd, fd) = best(1, || {
        (0..p0.len())
            .map(|k| {
                let h = 1e-5 * p0[k].abs().max(1.0);
                let mut p = p0.clone();
                p[k] = p0[k] + h;
                let up = loss64(&p);
                p[k] = p0[k] - h;
                (up - loss64(&p)) / (2.0 * h)
            })
            .collect::<Vec<f64>>()
    });
    for (kernel, kname) in [(Kernel::Auto, "auto"), (Kernel::Scalar, "scalar")] {
        let opts = RenderOptions {
            background: bg,
            kernel,
            ..Default::default()
        };
        let v = ImageGrads {
            rgb: Some(w.clone()),
            ..Default::default()
        };
        let (t, gr) = best(20, || {
            let fwd = render_for_backward(&g, &cam, &opts).expect("renders");
            backward(&g, &cam, &opts, &fwd, &v, &GradGroups::ALL)
                .expect("backward")
                .0
        });
        let mut flat = Vec::new();
        for i in 0..g.len() {
            flat.extend(gr.means[i]);
            flat.extend(gr.log_scales[i]);
            flat.extend(gr.quats[i]);
            flat.push(gr.opacity_logits[i]);
            flat.extend(gr.sh_dc[i]);
            flat.extend(&gr.sh_rest[i * 45..(i + 1) * 45]);
        }
        let err = flat
            .iter()
            .zip(&fd)
            .map(|(&a, &b)| (a as f64 - b).abs())
            .fold(0.0, f64::max);
        points.push(Point {
            stage: "backward",
            knob: format!(
                "f32 forward + backward, kernel {kname}, {} parameters (largest |gradient| {:.1e})",
                fd.len(),
                fd.iter().fold(0f64, |m, v| m.max(v.abs()))
            ),
            default: kernel == Kernel::Auto,
            metric: "max |gradient − f64 central differences|",
            error: err,
            seconds: t,
            pareto: false,
        });
    }
    points.push(Point {
        stage: "backward",
        knob: "f64 central differences of the twin (the shadow itself)".into(),
        default: false,
        metric: "max |gradient − f64 central differences|",
        error: 0.0,
        seconds: t_fd,
        pareto: false,
    });
}

fn exp(quick: bool, points: &mut Vec<Point>) {
    let n = if quick { 1 << 20 } else { 1 << 24 };
    let xs: Vec<f32> = (0..n)
        .map(|i| -87.0 + 175.0 * (i as f32 + 0.5) / n as f32)
        .collect();
    let exact: Vec<f32> = xs.iter().map(|&x| (x as f64).exp() as f32).collect();
    let mut run = |name: &str, default: bool, f: &dyn Fn(f32) -> f32| {
        let (t, out) = best(5, || xs.iter().map(|&x| f(x)).collect::<Vec<f32>>());
        let err = out
            .iter()
            .zip(&exact)
            .map(|(&a, &b)| ulp_distance(a, b) as f64)
            .fold(0.0, f64::max);
        points.push(Point {
            stage: "exp",
            knob: name.to_string(),
            default,
            metric: "max ulp vs f64 exp (per 2^20 calls: s)",
            error: err,
            seconds: t * (1 << 20) as f64 / n as f64,
            pareto: false,
        });
    };
    run("own Cephes exp, scalar", false, &|x| {
        fastexp::exp(std::hint::black_box(x))
    });
    run("platform f32::exp", false, &|x| {
        std::hint::black_box(x).exp()
    });
    run("f64::exp rounded", false, &|x| {
        (std::hint::black_box(x) as f64).exp() as f32
    });
    #[cfg(target_arch = "x86_64")]
    {
        use std::arch::x86_64::*;
        // The widest form this CPU runs is the one the blend uses.
        let widest = if is_x86_feature_detected!("avx512f") {
            16
        } else {
            8
        };
        let mut lanes = |name: &str, width: usize, f: &dyn Fn(&[f32], &mut [f32])| {
            let (t, out) = best(5, || {
                let mut out = vec![0f32; xs.len()];
                for (x, o) in xs.chunks_exact(width).zip(out.chunks_exact_mut(width)) {
                    f(x, o);
                }
                out
            });
            let err = out
                .iter()
                .zip(&exact)
                .map(|(&a, &b)| ulp_distance(a, b) as f64)
                .fold(0.0, f64::max);
            points.push(Point {
                stage: "exp",
                knob: name.to_string(),
                default: width == widest,
                metric: "max ulp vs f64 exp (per 2^20 calls: s)",
                error: err,
                seconds: t * (1 << 20) as f64 / n as f64,
                pareto: false,
            });
        };
        if is_x86_feature_detected!("avx2") {
            // SAFETY: AVX2 was detected; chunks hold exactly 8 f32.
            lanes("own Cephes exp, AVX2 (8 lanes)", 8, &|x, o| unsafe {
                _mm256_storeu_ps(
                    o.as_mut_ptr(),
                    fastexp::exp_avx2(_mm256_loadu_ps(x.as_ptr())),
                )
            });
        }
        if is_x86_feature_detected!("avx512f") {
            // SAFETY: AVX-512F was detected; chunks hold exactly 16 f32.
            lanes(
                "own Cephes exp, AVX-512F (16 lanes, the blend's)",
                16,
                &|x, o| unsafe {
                    _mm512_storeu_ps(
                        o.as_mut_ptr(),
                        fastexp::exp_avx512(_mm512_loadu_ps(x.as_ptr())),
                    )
                },
            );
        }
    }
}

fn alignment(quick: bool, points: &mut Vec<Point>) {
    let (frames, side) = if quick { (4, 128) } else { (16, 256) };
    let (s_true, t_true) = (2.5f64, 0.75f64);
    let mut u = Uniform::new(3);
    let data: Vec<(Vec<f32>, Vec<f32>)> = (0..frames)
        .map(|_| {
            let est: Vec<f32> = (0..side * side).map(|_| u.range(0.2, 4.0)).collect();
            let depth = est
                .iter()
                .map(|&r| {
                    let d = s_true * r as f64 + t_true;
                    if u.range(0.0, 1.0) < 0.3 {
                        u.range(0.1, 12.0) // outlier
                    } else {
                        (d * (1.0 + 0.03 * u.range(-1.0, 1.0) as f64)) as f32
                    }
                })
                .collect();
            (est, depth)
        })
        .collect();
    let fr: Vec<Frame> = data
        .iter()
        .map(|(e, d)| Frame {
            estimate: e,
            depth: d,
        })
        .collect();
    let mut add = |knob: String, default: bool, t: f64, s: f64| {
        points.push(Point {
            stage: "ransac",
            knob,
            default,
            metric: "|s − s_true| / s_true",
            error: (s - s_true).abs() / s_true,
            seconds: t,
            pareto: false,
        })
    };
    let (t, a) = best(3, || least_squares(&fr, Space::Depth).expect("fits"));
    add("least squares (no RANSAC)".into(), false, t, a.scale);
    for threshold in [0.01, 0.05, 0.2] {
        for iterations in [10u32, 30, 100, 300, 1000] {
            let cfg = RansacConfig {
                threshold,
                iterations,
                confidence: None,
                seed: 0,
            };
            let (t, a) = best(3, || ransac(&fr, Space::Depth, &cfg).expect("fits"));
            add(
                format!("threshold {threshold}, {iterations} iterations"),
                false,
                t,
                a.scale,
            );
        }
        let cfg = RansacConfig {
            threshold,
            ..RansacConfig::default()
        };
        let (t, a) = best(3, || ransac(&fr, Space::Depth, &cfg).expect("fits"));
        add(
            format!("threshold {threshold}, adaptive (≤ 1000, 0.999)"),
            threshold == RansacConfig::default().threshold,
            t,
            a.scale,
        );
    }
}

/// The bundled `lounge` scene at `1/resolution`.
fn lounge(resolution: u32) -> unseen::dataset::Dataset {
    use unseen::dataset::{self, LoadOptions};
    let root =
        std::path::Path::new(env!("CARGO_MANIFEST_DIR")).join("reference_data/scenes/lounge");
    dataset::load(
        &root,
        &LoadOptions {
            resolution,
            ..LoadOptions::default()
        },
    )
    .expect("bundled scene")
}

/// Training on `lounge` at resolution 1/2 (80×60; quick to 7000 iterations, full to
/// 30 000): checkpoints of one run per setting
/// (densification on, the INRIA default, and off; and the default trained on images of
/// half that size, INRIA's `-r`), all scored on the test views (INRIA's every 8th training
/// view) at the bench's resolution by their mean squared error against the ground truth
/// images; time is the run's wall time up to the checkpoint.
fn training(quick: bool, points: &mut Vec<Point>) {
    use unseen::dataset::Split;
    use unseen::train::trainer::{TrainConfig, Trainer};
    // The same images in both modes (res. 1 to 30 000 iterations would take hours on one
    // thread); the full run goes on to INRIA's 30 000.
    let resolution = 2;
    let checkpoints: &[u32] = if quick {
        &[250, 500, 1000, 2000, 4000, 7000]
    } else {
        &[250, 500, 1000, 2000, 4000, 7000, 15_000, 30_000]
    };
    let data = lounge(resolution);
    let coarse = lounge(2 * resolution);
    let size = |d: &unseen::dataset::Dataset| {
        let c = &d.views[0].camera;
        format!("{}×{}", c.width, c.height)
    };
    // (training images, densification): the recipe at the bench's resolution, without
    // densification, and on images of half that size — every run scored on the test
    // views at the bench's resolution.
    for (train_data, densify) in [(&data, true), (&data, false), (&coarse, true)] {
        let defaults = TrainConfig::default();
        let halved = std::ptr::eq(train_data, &coarse);
        let cfg = TrainConfig {
            iterations: *checkpoints.last().expect("checkpoints"),
            save_iterations: vec![],
            resolution: if halved { 2 * resolution } else { resolution },
            densify: if densify { defaults.densify } else { None },
            ..defaults
        };
        let mut t = Trainer::new(train_data, cfg.clone()).expect("trainer");
        let mut seconds = 0.0;
        let mut done = 0;
        for &c in checkpoints {
            let t0 = Instant::now();
            while done < c {
                t.step().expect("step");
                done += 1;
            }
            seconds += t0.elapsed().as_secs_f64();
            let r = unseen::eval::evaluate(
                &t.gaussians,
                &data,
                Split::Test,
                cfg.background,
                cfg.conventions,
                None,
            )
            .expect("evaluates");
            let mse = r
                .views
                .iter()
                .map(|v| 10f64.powf(-v.psnr / 10.0))
                .sum::<f64>()
                / r.views.len() as f64;
            let images = if halved {
                format!(", trained on {} images", size(train_data))
            } else {
                String::new()
            };
            points.push(Point {
                stage: "training",
                knob: format!(
                    "{c} iterations, densification {}{images}, {} Gaussians, test PSNR {:.2} dB at {}",
                    if densify { "on" } else { "off" },
                    t.gaussians.len(),
                    r.mean_psnr,
                    size(&data),
                ),
                // The recipe's setting; the iteration count is the user's budget.
                default: densify && !halved,
                metric: "test-view MSE",
                error: mse,
                seconds,
                pareto: false,
            });
        }
    }
}

/// The pipeline's presets (`quick`, `paper`; SPEC.md §20) on the demo's original scene
/// (`lounge`'s train half, 1500 iterations at 80×60, as `unseen demo`), extrapolated into
/// the held-out half: after each stage (stage 1, stage 2, interpolation) the evaluation
/// poses' extrapolated pixels scored against the ground truth (error `10^(−PSNR/10)`, the
/// PSNR's mean squared error), time the original's training and the pipeline's step costs
/// up to that stage (the evaluation excluded). Full runs only (`paper` takes over
/// an hour on one thread); the quick preset's rows are the demo's report.
fn pipeline_presets(quick: bool, points: &mut Vec<Point>) {
    use unseen::pipeline::{self, Event, PipelineConfig, Preset, RunOptions, rundir::TIMING_FILE};
    use unseen::train::run::{Checkpointing, train_run};
    use unseen::train::trainer::TrainConfig;
    if quick {
        eprintln!("pipeline: full runs only (the paper preset takes over an hour)");
        return;
    }
    let scene =
        std::path::Path::new(env!("CARGO_MANIFEST_DIR")).join("reference_data/scenes/lounge");
    let dir = Scratch::new("pipeline");
    let original = dir.0.join("original");
    let tc = TrainConfig {
        iterations: 1500,
        resolution: 2,
        save_iterations: vec![],
        ..TrainConfig::default()
    };
    let t0 = Instant::now();
    train_run(
        &scene,
        &original,
        &tc,
        None,
        Checkpointing::default(),
        &mut |_| {},
    )
    .expect("original scene");
    let original_seconds = t0.elapsed().as_secs_f64();
    let inputs = pipeline::load_inputs(
        &original,
        &scene.join("candidates.json"),
        Some(&scene.join("evaluation.json")),
        Some(&scene),
    )
    .expect("inputs");
    let log = |e: Event| {
        if let Event::StepFinished { step, seconds } = e {
            eprintln!("   {step}: {seconds:.1} s");
        }
    };
    for preset in [Preset::Quick, Preset::Paper] {
        let cfg = PipelineConfig::preset(preset);
        let out = dir.0.join(preset.name());
        let outcome = pipeline::run_with(&cfg, &inputs, &out, &RunOptions::default(), &log)
            .expect("pipeline run");
        let metrics = outcome.metrics.expect("evaluation poses");
        let cost = |s: &unseen::pipeline::rundir::StepDone| {
            let b = std::fs::read(s.dir.join(TIMING_FILE)).expect("step cost");
            serde_json::from_slice::<unseen::io::Cost>(&b)
                .expect("cost.json")
                .seconds
        };
        let stage_of = |name: &str| name.split('/').next().unwrap_or("").to_string();
        for row in &metrics.rows {
            // The original is the same for both presets: one row.
            if row.scene == "original" && preset != Preset::Quick {
                continue;
            }
            // The original's training, then the steps up to the last of this stage (the
            // views and QA-Mask fine-tunes before it included, the evaluation's excluded).
            let steps = outcome
                .steps
                .iter()
                .rposition(|s| stage_of(&s.name) == row.scene)
                .map_or(0, |last| last + 1);
            let seconds = original_seconds
                + outcome.steps[..steps]
                    .iter()
                    .filter(|s| stage_of(&s.name) != "eval")
                    .map(cost)
                    .sum::<f64>();
            let knob = if row.scene == "original" {
                "the original (1500 iterations)".to_string()
            } else {
                format!("preset {preset}, after {}", row.scene)
            };
            points.push(Point {
                stage: "pipeline",
                knob: format!(
                    "{knob}: extrapolated PSNR {:.2} dB, existing {:.2} dB, train-half {:.2} dB, {} Gaussians",
                    row.psnr_extrapolated, row.psnr_existing, row.psnr_train_half, row.gaussians
                ),
                default: preset == Preset::Paper && row.scene != "original",
                metric: "extrapolated-pixel MSE",
                error: 10f64.powf(-row.psnr_extrapolated / 10.0),
                seconds,
                pareto: false,
            });
        }
    }
}

/// A temporary folder removed when dropped (also when a stage panics).
struct Scratch(PathBuf);

impl Scratch {
    fn new(name: &str) -> Scratch {
        let p = std::env::temp_dir().join(format!("unseen-accuracy-{name}-{}", std::process::id()));
        std::fs::create_dir_all(&p).expect("scratch folder");
        Scratch(p)
    }
}

impl Drop for Scratch {
    fn drop(&mut self) {
        let _ = std::fs::remove_dir_all(&self.0);
    }
}

/// GJK on pairs of boxes whose exact distance is known: axis-aligned boxes with random
/// extents and gaps (distance `√Σ max(0, gap_i)²`, 0 when they overlap), both moved by one
/// random rigid motion (which keeps the distance, up to the rounding of the vertices,
/// ~1e-16 of the scale). Error: the largest `|d − d_exact| / scale` (`scale` as GJK's, the
/// largest vertex magnitude); a wrong verdict or a non-converged pair counts as 1.
fn gjk(quick: bool, points: &mut Vec<Point>) {
    use glam::{DMat3, DQuat, DVec3};
    use unseen::collide::gjk::ConvexHull;
    let pairs = if quick { 2000 } else { 20000 };
    let mut u = Uniform::new(11);
    let mut r = |lo: f64, hi: f64| f64::from(u.range(lo as f32, hi as f32));
    let cases: Vec<(ConvexHull, ConvexHull, f64)> = (0..pairs)
        .map(|_| {
            let e1 = DVec3::new(r(0.1, 2.0), r(0.1, 2.0), r(0.1, 2.0));
            let e2 = DVec3::new(r(0.1, 2.0), r(0.1, 2.0), r(0.1, 2.0));
            // Gaps per axis in [−1, 1.5], no deeper than the boxes (an overlap of more than
            // both extents would flip the centres' order): about 6 % of the pairs overlap.
            let gap = DVec3::new(r(-1.0, 1.5), r(-1.0, 1.5), r(-1.0, 1.5)).max(-(e1 + e2));
            let sign = DVec3::new(
                if r(0.0, 1.0) < 0.5 { -1.0 } else { 1.0 },
                if r(0.0, 1.0) < 0.5 { -1.0 } else { 1.0 },
                if r(0.0, 1.0) < 0.5 { -1.0 } else { 1.0 },
            );
            let c2 = sign * (e1 + e2 + gap);
            let exact = gap.max(DVec3::ZERO).length();
            let rot = DMat3::from_quat(DQuat::from_axis_angle(
                DVec3::new(r(-1.0, 1.0), r(-1.0, 1.0), r(0.1, 1.0)).normalize(),
                r(0.0, std::f64::consts::TAU),
            ));
            let t = DVec3::new(r(-5.0, 5.0), r(-5.0, 5.0), r(-5.0, 5.0));
            let corners = |c: DVec3, e: DVec3| {
                let v: Vec<DVec3> = (0..8)
                    .map(|k| {
                        let s = DVec3::new(
                            if k & 1 == 0 { -1.0 } else { 1.0 },
                            if k & 2 == 0 { -1.0 } else { 1.0 },
                            if k & 4 == 0 { -1.0 } else { 1.0 },
                        );
                        rot * (c + s * e) + t
                    })
                    .collect();
                ConvexHull::new(v).expect("finite")
            };
            (corners(DVec3::ZERO, e1), corners(c2, e2), exact)
        })
        .collect();
    gjk_knobs("gjk", &cases, points);
}

/// GJK on the frustums the pipeline collides: 2000 random pairs and 500 of each facing
/// family (`polytope::Family`: nearly parallel facing faces, and closer and flatter ones),
/// against the exact distance by exhaustion over feature pairs
/// (`polytope::exact_distance`, 0 where the separating-axis test finds no gap). Pairs
/// within 100 touching tolerances of contact are left out.
fn gjk_frustums(quick: bool, points: &mut Vec<Point>) {
    use polytope::{Family, draw_pair, exact_distance, pair_scale, sat_gap};
    use unseen::collide::gjk::TOUCH_REL;
    let (random, facing) = if quick { (2000, 500) } else { (20000, 3000) };
    let mut u = Uniform::new(5);
    let mut cases = Vec::new();
    for (family, count) in [
        (Family::Random, random),
        (Family::Facing, facing),
        (Family::FacingClose, facing),
    ] {
        for k in 0..count {
            let (a, b) = draw_pair(&mut u, family, k);
            if sat_gap(&a, &b).abs() > 100.0 * TOUCH_REL * pair_scale(&a, &b) {
                cases.push((a.hull(), b.hull(), exact_distance(&a, &b)));
            }
        }
    }
    gjk_knobs("gjk-frustums", &cases, points);
}

/// Every stopping rule (duality gaps 1e-4–1e-15 at the default cap, caps 3–16 at the
/// default gap) on `cases` (pairs and their exact distance). Error: the largest
/// `|d − d_exact| / scale` (`scale` as GJK's, the largest vertex magnitude); a pair called
/// separated while touching, or not converged, counts as 1 (a separated pair called
/// colliding, the stall's safe side, is counted in the knob only).
fn gjk_knobs(
    stage: &'static str,
    cases: &[(
        unseen::collide::gjk::ConvexHull,
        unseen::collide::gjk::ConvexHull,
        f64,
    )],
    points: &mut Vec<Point>,
) {
    use unseen::collide::gjk::{Tolerances, proximity_with};
    let defaults = Tolerances::default();
    let mut knobs: Vec<(String, Tolerances)> = [1e-4, 1e-6, 1e-9, 1e-12, 1e-15]
        .iter()
        .map(|&rel_eps| {
            (
                format!("duality gap {rel_eps:e}, cap {}", defaults.max_iterations),
                Tolerances {
                    rel_eps,
                    ..defaults
                },
            )
        })
        .collect();
    for cap in [3, 5, 8, 16] {
        knobs.push((
            format!("duality gap {:e}, cap {cap}", defaults.rel_eps),
            Tolerances {
                max_iterations: cap,
                ..defaults
            },
        ));
    }
    for (name, tol) in knobs {
        let (t, (err, [unsafe_, conservative, failed])) = best(3, || {
            let mut err = 0f64;
            // Separated called for touching pairs; colliding for separated ones (the
            // stall's safe side); no answer within the cap.
            let mut counts = [0usize; 3];
            for (a, b, exact) in cases {
                let scale = a
                    .vertices
                    .iter()
                    .chain(&b.vertices)
                    .map(|v| v.abs().max_element())
                    .fold(0.0, f64::max);
                match proximity_with(a, b, &tol) {
                    Ok(p) if !p.intersect && *exact <= p.touch_eps => {
                        err = 1.0;
                        counts[0] += 1;
                    }
                    Ok(p) => {
                        counts[1] += usize::from(p.intersect && *exact > p.touch_eps);
                        err = err.max((p.distance - exact).abs() / scale);
                    }
                    Err(_) => {
                        err = 1.0;
                        counts[2] += 1;
                    }
                }
            }
            (err, counts)
        });
        points.push(Point {
            stage,
            knob: format!(
                "{name}: of {} pairs {unsafe_} called separated while touching, {conservative} called colliding while separated, {failed} not converged",
                cases.len()
            ),
            default: tol == defaults,
            metric: "max |d − d_exact| / scale",
            error: err,
            seconds: t,
            pareto: false,
        });
    }
}

/// DIBR against a ray-traced warp, on two scenes seen from a source camera and warped to a
/// target camera moved 0.15 and turned 4°; the shadow is the scene ray-traced from the
/// target (f64):
/// - `dibr`: a slanted textured plane (smooth colours, a known surface);
/// - `dibr-edges`: the same plane behind a textured card at half its depth, whose outline
///   is a depth edge (disocclusions on one side, the card's silhouette on the other).
///
/// Error: mean |warp − ray-traced| over the target pixels the warp fills (holes are counted
/// in the knob, and for the edge scene the pixels whose warped depth is more than 1 % from
/// the ray-traced one, the surface the warp got wrong, and within 2 px of a ray-traced
/// depth edge the holes and the mean error over the filled pixels: each form fills a
/// different set there, so read the two together).
fn dibr(quick: bool, points: &mut Vec<Point>) {
    use glam::{DMat3, DVec3};
    use unseen::io::image::ImageF32;
    use unseen::warp::dibr::{Footprint, WarpOptions, warp};
    let (w, h) = if quick {
        (256usize, 192usize)
    } else {
        (1024, 768)
    };
    let f = 0.5 * w as f64 / 35f64.to_radians().tan();
    let from = Camera::new(
        "from",
        w as u32,
        h as u32,
        f,
        f,
        DMat3::IDENTITY,
        DVec3::ZERO,
    )
    .expect("camera");
    let to = Camera::new(
        "to",
        w as u32,
        h as u32,
        f,
        f,
        DMat3::from_rotation_y(4f64.to_radians()),
        DVec3::new(0.15, -0.05, 0.0),
    )
    .expect("camera");
    // The plane n·P = 4 (slanted), and its texture.
    let n = DVec3::new(0.2, -0.1, 1.0).normalize();
    let plane = |o: DVec3, d: DVec3| {
        let s = (4.0 - n.dot(o)) / n.dot(d);
        let p = o + d * s;
        (
            s,
            [
                0.5 + 0.4 * (3.0 * p.x).sin() * (2.0 * p.y).cos(),
                0.5 + 0.4 * (2.5 * p.y + 1.0).sin(),
                0.5 + 0.3 * (4.0 * (p.x + p.y)).cos(),
            ],
        )
    };
    // The card: z = 2, |x| < 0.35, |y| < 0.3, a texture of other colours.
    let card = |o: DVec3, d: DVec3| {
        let s = (2.0 - o.z) / d.z;
        let p = o + d * s;
        (p.x.abs() < 0.35 && p.y.abs() < 0.3).then(|| {
            (
                s,
                [
                    0.85 - 0.1 * (9.0 * p.x).cos(),
                    0.25 + 0.1 * (7.0 * p.y).sin(),
                    0.15,
                ],
            )
        })
    };
    // Ray-trace a camera: colours and camera z (`d` has camera z 1, so the ray parameter
    // is the camera z).
    let trace = |cam: &Camera, with_card: bool| {
        let mut rgb = Vec::with_capacity(w * h * 3);
        let mut z = Vec::with_capacity(w * h);
        for v in 0..h {
            for u in 0..w {
                let d = DVec3::new(
                    (u as f64 + 0.5 - cam.cx) / cam.fx,
                    (v as f64 + 0.5 - cam.cy) / cam.fy,
                    1.0,
                );
                let dw = cam.world_from_camera_rotation * d;
                let (s, c) = match (with_card, plane(cam.center, dw)) {
                    (true, back) => card(cam.center, dw).unwrap_or(back),
                    (false, back) => back,
                };
                rgb.extend(c.map(|c| c as f32));
                z.push(s as f32);
            }
        }
        (rgb, z)
    };
    let knobs = [
        ("nearest", WarpOptions::default(), false),
        (
            "nearest + crack closing 1 (the pipeline's)",
            WarpOptions {
                close_cracks: 1,
                ..WarpOptions::default()
            },
            true,
        ),
        (
            "bilinear",
            WarpOptions {
                footprint: Footprint::Bilinear,
                ..WarpOptions::default()
            },
            false,
        ),
        (
            "bilinear + crack closing 1",
            WarpOptions {
                footprint: Footprint::Bilinear,
                close_cracks: 1,
                ..WarpOptions::default()
            },
            false,
        ),
    ];
    for (stage, with_card) in [("dibr", false), ("dibr-edges", true)] {
        let (src, src_z) = trace(&from, with_card);
        let (truth, truth_z) = trace(&to, with_card);
        let img = ImageF32::new(w, h, 3, src).expect("image");
        // Target pixels within 2 of a ray-traced depth edge (a 4-neighbour with more than
        // 10 % depth difference).
        let edge_px: Vec<bool> = {
            let jump = |a: usize, b: usize| {
                (truth_z[a] - truth_z[b]).abs() > 0.1 * truth_z[a].min(truth_z[b])
            };
            let on: Vec<bool> = (0..w * h)
                .map(|i| {
                    let (x, y) = (i % w, i / w);
                    (x + 1 < w && jump(i, i + 1)) || (y + 1 < h && jump(i, i + w))
                })
                .collect();
            (0..w * h)
                .map(|i| {
                    let (x, y) = ((i % w) as i64, (i / w) as i64);
                    (-2..=2).any(|dy| {
                        (-2..=2).any(|dx| {
                            let (xx, yy) = (x + dx, y + dy);
                            xx >= 0
                                && yy >= 0
                                && xx < w as i64
                                && yy < h as i64
                                && on[yy as usize * w + xx as usize]
                        })
                    })
                })
                .collect()
        };
        for (name, opts, default) in knobs {
            let (t, r) = best(3, || warp(&img, &src_z, &from, &to, &opts).expect("warps"));
            let (mut sum, mut filled) = (0.0, 0usize);
            let (mut edge_sum, mut edge_filled, mut wrong_surface) = (0.0, 0usize, 0usize);
            let mut edge_holes = 0usize;
            for (i, &hole) in r.holes.iter().enumerate() {
                if hole {
                    edge_holes += usize::from(edge_px[i]);
                    continue;
                }
                let e: f64 = (0..3)
                    .map(|c| (r.image.data[3 * i + c] as f64 - truth[3 * i + c] as f64).abs())
                    .sum();
                filled += 1;
                sum += e;
                if edge_px[i] {
                    edge_filled += 1;
                    edge_sum += e;
                }
                if (r.depth[i] - truth_z[i]).abs() > 0.01 * truth_z[i] {
                    wrong_surface += 1;
                }
            }
            let mut knob = format!("{name}: {} holes of {}", w * h - filled, w * h);
            if with_card {
                knob += &format!(
                    ", {wrong_surface} on the wrong surface; within 2 px of an edge: {edge_holes} holes of {}, {:.2e} mean over the filled",
                    edge_px.iter().filter(|e| **e).count(),
                    edge_sum / (3 * edge_filled.max(1)) as f64
                );
            }
            points.push(Point {
                stage,
                knob,
                default,
                metric: "mean |warp − ray-traced| (filled pixels)",
                error: sum / (3 * filled.max(1)) as f64,
                seconds: t,
                pareto: false,
            });
        }
    }
}

/// The QA-Mask's fine-tune iterations and SH degree against a long SH-5 fine-tune (the
/// paper's setting, 20 000 iterations, INRIA's fine-tune length: the default) of the
/// same trained lounge scene (1000 iterations at resolution 1/2 in quick mode, 7000 at
/// full resolution). Error: mean |mask − reference mask| over the held-out views' pixels,
/// views no training camera saw, as the pipeline's generated views (the knob also gives it
/// on the in-distribution test views, where the mask goes towards 0). Time: the fine-tune
/// alone, up to the checkpoint.
fn qa_mask(quick: bool, points: &mut Vec<Point>) {
    use unseen::qamask::{QaMaskConfig, fine_tune, mask_scene, render_qa_mask};
    use unseen::train::trainer::{TrainConfig, Trainer};
    // Budgets of every degree, and the SH-5 run's longer ones on the way to the reference.
    type Budgets = (u32, u32, u32, &'static [u32], &'static [u32]);
    let (resolution, train_its, reference_its, budgets, long_budgets): Budgets = if quick {
        (2, 1000, 20_000, &[100, 300, 1000, 3000, 5000], &[10_000])
    } else {
        (1, 7000, 20_000, &[1000, 3000, 5000, 10_000], &[])
    };
    let data = lounge(resolution);
    let mut t = Trainer::new(
        &data,
        TrainConfig {
            iterations: train_its,
            save_iterations: vec![],
            resolution,
            ..TrainConfig::default()
        },
    )
    .expect("trainer");
    for _ in 0..train_its {
        t.step().expect("step");
    }
    let trained = t.gaussians;
    let cams = |split: &[usize]| -> Vec<Camera> {
        split
            .iter()
            .map(|&i| data.views[i].camera.clone())
            .collect()
    };
    let (train, heldout, test) = (cams(&data.train), cams(&data.heldout), cams(&data.test));
    let masks = |scene: &Gaussians, cfg: &QaMaskConfig, views: &[Camera]| -> Vec<f32> {
        views
            .iter()
            .flat_map(|c| render_qa_mask(scene, c, cfg).expect("mask"))
            .collect()
    };
    // One fine-tune per degree, to its longest budget; shorter budgets are its checkpoints
    // (the same bits as fine-tunes of that length, test
    // `qa_mask_fine_tune_checkpoints_are_shorter_fine_tunes`), timed up to the checkpoint
    // without the masks rendered there. Per checkpoint: (iterations, seconds, held-out
    // masks, test-view masks).
    type Checkpoint = (u32, f64, Vec<f32>, Vec<f32>);
    let run = |degree: u32, checkpoints: &[u32]| -> Vec<Checkpoint> {
        let cfg = QaMaskConfig {
            sh_degree: degree,
            iterations: *checkpoints.last().expect("checkpoints"),
            ..QaMaskConfig::default()
        };
        let mut scene = mask_scene(&trained, &cfg).expect("mask scene");
        let mut out = Vec::new();
        let mut aside = 0.0;
        let t0 = Instant::now();
        fine_tune(&mut scene, &train, &cfg, &mut |p| {
            if checkpoints.contains(&p.iteration) {
                let seconds = t0.elapsed().as_secs_f64() - aside;
                let t1 = Instant::now();
                let (h, t) = (masks(p.scene, &cfg, &heldout), masks(p.scene, &cfg, &test));
                out.push((p.iteration, seconds, h, t));
                aside += t1.elapsed().as_secs_f64();
            }
        })
        .expect("fine-tune");
        out
    };
    let mean_diff = |a: &[f32], b: &[f32]| {
        a.iter()
            .zip(b)
            .map(|(x, y)| f64::from((x - y).abs()))
            .sum::<f64>()
            / b.len() as f64
    };
    let default = QaMaskConfig::default();
    let metric = "mean |mask − long SH-5 mask| (held-out pixels)";
    let mut runs = Vec::new();
    for degree in [3, 4, 5] {
        let mut checkpoints = budgets.to_vec();
        if degree == 5 {
            checkpoints.extend(long_budgets);
            checkpoints.push(reference_its);
        }
        runs.push((degree, run(degree, &checkpoints)));
    }
    let (_, ref_seconds, reference, reference_test) = runs[2].1.last().cloned().expect("reference");
    for (degree, checkpoints) in runs {
        for (iterations, seconds, masks, masks_test) in checkpoints {
            if degree == 5 && iterations == reference_its {
                continue;
            }
            points.push(Point {
                stage: "qa-mask",
                knob: format!(
                    "SH {degree}, {iterations} iterations ({:.2e} on the test views)",
                    mean_diff(&masks_test, &reference_test)
                ),
                default: degree == default.sh_degree && iterations == default.iterations,
                metric,
                error: mean_diff(&masks, &reference),
                seconds,
                pareto: false,
            });
        }
    }
    points.push(Point {
        stage: "qa-mask",
        knob: format!(
            "SH 5, {reference_its} iterations (the reference itself; {} Gaussians)",
            trained.len()
        ),
        default: reference_its == default.iterations,
        metric,
        error: 0.0,
        seconds: ref_seconds,
        pareto: false,
    });
}

/// Mean SSIM (`train::ssim`'s definition: 11×11 Gaussian window, σ 1.5, zero padding,
/// per channel) in the float type `$t`, with the 2D window applied directly (`separable:
/// false`, INRIA's `conv2d` with the outer product) or as two 1D passes.
macro_rules! ssim_in {
    ($name:ident, $t:ty) => {
        fn $name(x: &[f32], y: &[f32], w: usize, h: usize, c: usize, separable: bool) -> f64 {
            let k1: Vec<$t> = {
                let g: Vec<f64> = (0..11)
                    .map(|i| (-((i as f64 - 5.0).powi(2)) / (2.0 * 1.5 * 1.5)).exp())
                    .collect();
                let s: f64 = g.iter().sum();
                g.iter().map(|v| (v / s) as $t).collect()
            };
            let blur = |src: &[$t]| -> Vec<$t> {
                let mut out = vec![0 as $t; w * h];
                if separable {
                    // Row-wise passes, taps outer and pixels inner (the loop order of
                    // `train::ssim`'s blur, so both vectorize alike).
                    let mut tmp = vec![0 as $t; w * h];
                    for (row_out, row_in) in tmp.chunks_exact_mut(w).zip(src.chunks_exact(w)) {
                        for (t, &kv) in k1.iter().enumerate() {
                            let off = t as isize - 5;
                            let lo = (-off).max(0) as usize;
                            let hi = (w as isize - off).clamp(0, w as isize) as usize;
                            if lo < hi {
                                let from = (lo as isize + off) as usize;
                                for (o, &v) in row_out[lo..hi].iter_mut().zip(&row_in[from..]) {
                                    *o += kv * v;
                                }
                            }
                        }
                    }
                    for (yy, row_out) in out.chunks_exact_mut(w).enumerate() {
                        for (t, &kv) in k1.iter().enumerate() {
                            let sy = yy as isize + t as isize - 5;
                            if sy >= 0 && (sy as usize) < h {
                                let row = &tmp[sy as usize * w..(sy as usize + 1) * w];
                                for (o, &v) in row_out.iter_mut().zip(row) {
                                    *o += kv * v;
                                }
                            }
                        }
                    }
                } else {
                    for yy in 0..h {
                        for xx in 0..w {
                            let mut acc = 0 as $t;
                            for (ty, &ky) in k1.iter().enumerate() {
                                let sy = yy as isize + ty as isize - 5;
                                if sy < 0 || sy as usize >= h {
                                    continue;
                                }
                                for (tx, &kx) in k1.iter().enumerate() {
                                    let sx = xx as isize + tx as isize - 5;
                                    if sx >= 0 && (sx as usize) < w {
                                        acc += (ky * kx) * src[sy as usize * w + sx as usize];
                                    }
                                }
                            }
                            out[yy * w + xx] = acc;
                        }
                    }
                }
                out
            };
            let (c1, c2) = (0.01 as $t * 0.01 as $t, 0.03 as $t * 0.03 as $t);
            let mut total = 0f64;
            for ch in 0..c {
                let plane = |f: &dyn Fn($t, $t) -> $t| -> Vec<$t> {
                    (0..w * h)
                        .map(|p| f(x[p * c + ch] as $t, y[p * c + ch] as $t))
                        .collect()
                };
                let mx = blur(&plane(&|a, _| a));
                let my = blur(&plane(&|_, b| b));
                let exx = blur(&plane(&|a, _| a * a));
                let eyy = blur(&plane(&|_, b| b * b));
                let exy = blur(&plane(&|a, b| a * b));
                for p in 0..w * h {
                    let (ux, uy) = (mx[p], my[p]);
                    let (sxx, syy, sxy) = (exx[p] - ux * ux, eyy[p] - uy * uy, exy[p] - ux * uy);
                    let v = ((2 as $t) * ux * uy + c1) * ((2 as $t) * sxy + c2)
                        / ((ux * ux + uy * uy + c1) * (sxx + syy + c2));
                    total += f64::from(v);
                }
            }
            total / (w * h * c) as f64
        }
    };
}
ssim_in!(ssim_f32, f32);
ssim_in!(ssim_f64, f64);

/// SSIM's float type and window form against the f64 direct 2D window (the shadow) on a
/// pair of 3-channel images: a smooth texture with noise, and it blurred, shifted in
/// colour and noised again (a render against its ground truth). Error: |mean SSIM −
/// shadow|.
fn ssim_stage(quick: bool, points: &mut Vec<Point>) {
    let (w, h) = if quick { (128, 96) } else { (512, 384) };
    let mut u = Uniform::new(21);
    let x: Vec<f32> = (0..w * h * 3)
        .map(|i| {
            let (p, c) = (i / 3, i % 3);
            let (px, py) = ((p % w) as f32, (p / w) as f32);
            (0.5 + 0.3 * (0.11 * px + c as f32).sin() * (0.07 * py).cos() + 0.05 * u.normal())
                .clamp(0.0, 1.0)
        })
        .collect();
    let y: Vec<f32> = (0..w * h * 3)
        .map(|i| {
            let l = if i >= 3 { x[i - 3] } else { x[i] };
            (0.5 * (x[i] + l) + 0.02 + 0.03 * u.normal()).clamp(0.0, 1.0)
        })
        .collect();
    let (_, shadow) = best(1, || ssim_f64(&x, &y, w, h, 3, false));
    let runs = if quick { 3 } else { 1 };
    type Form<'a> = (&'a str, bool, Box<dyn Fn() -> f64 + 'a>);
    let forms: [Form; 4] = [
        (
            "f64 separable (train::ssim, the loss's)",
            true,
            Box::new(|| unseen::train::ssim::ssim(&x, &y, w, h, 3, false).0),
        ),
        (
            "f64 direct 11×11 window (the shadow itself)",
            false,
            Box::new(|| ssim_f64(&x, &y, w, h, 3, false)),
        ),
        (
            "f32 direct 11×11 window (INRIA's conv2d arithmetic)",
            false,
            Box::new(|| ssim_f32(&x, &y, w, h, 3, false)),
        ),
        (
            "f32 separable",
            false,
            Box::new(|| ssim_f32(&x, &y, w, h, 3, true)),
        ),
    ];
    for (name, default, f) in forms {
        let (t, v) = best(runs, &f);
        points.push(Point {
            stage: "ssim",
            knob: format!("{name}, {w}×{h}×3 (SSIM {v:.6})"),
            default,
            metric: "|SSIM − f64 direct window|",
            error: (v - shadow).abs(),
            seconds: t,
            pareto: false,
        });
    }
}

/// `Σ_q S_q` over the pixels `q` whose 11×11 window holds pixel `(px, py)` (channel `ch`),
/// each windowed SSIM computed directly in f64 (zero padding): the only terms of the mean
/// SSIM that pixel changes.
#[allow(clippy::too_many_arguments)]
fn ssim_local_sum(
    x: &[f64],
    y: &[f32],
    w: usize,
    h: usize,
    c: usize,
    ch: usize,
    px: usize,
    py: usize,
) -> f64 {
    let g: Vec<f64> = (0..11)
        .map(|i| (-((i as f64 - 5.0).powi(2)) / (2.0 * 1.5 * 1.5)).exp())
        .collect();
    let norm: f64 = g.iter().sum();
    let (c1, c2) = (0.01f64 * 0.01, 0.03f64 * 0.03);
    let mut total = 0.0;
    for qy in py.saturating_sub(5)..(py + 6).min(h) {
        for qx in px.saturating_sub(5)..(px + 6).min(w) {
            let (mut mx, mut my, mut exx, mut eyy, mut exy) = (0.0, 0.0, 0.0, 0.0, 0.0);
            for (ty, ky) in g.iter().enumerate() {
                let sy = qy as isize + ty as isize - 5;
                if sy < 0 || sy as usize >= h {
                    continue;
                }
                for (tx, kx) in g.iter().enumerate() {
                    let sx = qx as isize + tx as isize - 5;
                    if sx < 0 || sx as usize >= w {
                        continue;
                    }
                    let k = ky * kx / (norm * norm);
                    let i = (sy as usize * w + sx as usize) * c + ch;
                    let (a, b) = (x[i], f64::from(y[i]));
                    mx += k * a;
                    my += k * b;
                    exx += k * a * a;
                    eyy += k * b * b;
                    exy += k * a * b;
                }
            }
            let (sxx, syy, sxy) = (exx - mx * mx, eyy - my * my, exy - mx * my);
            total += (2.0 * mx * my + c1) * (2.0 * sxy + c2)
                / ((mx * mx + my * my + c1) * (sxx + syy + c2));
        }
    }
    total
}

/// SSIM's gradient (what the loss backpropagates) against central differences of the mean
/// SSIM in f64 with the direct 2D window, Richardson-extrapolated (steps 1e-3 and 5e-4:
/// truncation O(h⁴)), on every pixel and channel of a small pair of images like
/// [`ssim_stage`]'s. Only the windows that hold the pixel change, so each difference sums
/// those (`ssim_local_sum`). Error: max |g − g_fd| / max |g_fd|.
fn ssim_grad_stage(quick: bool, points: &mut Vec<Point>) {
    let (w, h) = if quick { (24, 18) } else { (48, 36) };
    let c = 3;
    let mut u = Uniform::new(22);
    let x: Vec<f32> = (0..w * h * c)
        .map(|i| {
            let (p, ch) = (i / c, i % c);
            let (px, py) = ((p % w) as f32, (p / w) as f32);
            (0.5 + 0.3 * (0.31 * px + ch as f32).sin() * (0.23 * py).cos() + 0.05 * u.normal())
                .clamp(0.0, 1.0)
        })
        .collect();
    let y: Vec<f32> = (0..w * h * c)
        .map(|i| {
            let l = if i >= c { x[i - c] } else { x[i] };
            (0.5 * (x[i] + l) + 0.02 + 0.03 * u.normal()).clamp(0.0, 1.0)
        })
        .collect();
    let n = (w * h * c) as f64;
    let (t_fd, fd) = best(1, || {
        let mut xd: Vec<f64> = x.iter().map(|&v| f64::from(v)).collect();
        let mut g = vec![0.0f64; x.len()];
        for (i, gi) in g.iter_mut().enumerate() {
            let (p, ch) = (i / c, i % c);
            let (px, py) = (p % w, p / w);
            let mut diff = |step: f64| {
                let v = xd[i];
                xd[i] = v + step;
                let up = ssim_local_sum(&xd, &y, w, h, c, ch, px, py);
                xd[i] = v - step;
                let down = ssim_local_sum(&xd, &y, w, h, c, ch, px, py);
                xd[i] = v;
                (up - down) / (2.0 * step) / n
            };
            let (d1, d2) = (diff(1e-3), diff(5e-4));
            *gi = (4.0 * d2 - d1) / 3.0;
        }
        g
    });
    let scale = fd.iter().fold(0.0f64, |m, v| m.max(v.abs()));
    let runs = if quick { 5 } else { 3 };
    let (t, g) = best(runs, || {
        unseen::train::ssim::ssim(&x, &y, w, h, c, true)
            .1
            .expect("gradient requested")
    });
    let err = g
        .iter()
        .zip(&fd)
        .fold(0.0f64, |m, (a, b)| m.max((f64::from(*a) - b).abs()))
        / scale;
    points.push(Point {
        stage: "ssim-grad",
        knob: format!(
            "f64 separable, gradient rounded to f32 (train::ssim, the loss's), {w}×{h}×3 (largest |g| {scale:.1e})"
        ),
        default: true,
        metric: "max |dSSIM/dx − f64 differences| / max |differences|",
        error: err,
        seconds: t,
        pareto: false,
    });
    points.push(Point {
        stage: "ssim-grad",
        knob: "f64 central differences of the direct window, Richardson (the shadow itself)"
            .to_string(),
        default: false,
        metric: "max |dSSIM/dx − f64 differences| / max |differences|",
        error: 0.0,
        seconds: t_fd,
        pareto: false,
    });
}

/// Mark each stage's Pareto front (less error and less time than every other point of the
/// stage in at least one, no more in the other).
fn mark_pareto(points: &mut [Point]) {
    for i in 0..points.len() {
        let dominated = points.iter().enumerate().any(|(j, q)| {
            j != i
                && q.stage == points[i].stage
                && q.error <= points[i].error
                && q.seconds <= points[i].seconds
                && (q.error < points[i].error || q.seconds < points[i].seconds)
        });
        points[i].pareto = !dominated;
    }
}

fn csv(points: &[Point]) -> String {
    let mut s = String::from("stage,knob,default,metric,error,seconds,pareto\n");
    for p in points {
        let _ = writeln!(
            s,
            "{},\"{}\",{},\"{}\",{:e},{:e},{}",
            p.stage, p.knob, p.default, p.metric, p.error, p.seconds, p.pareto
        );
    }
    s
}

fn markdown(points: &[Point], made_by: &str) -> String {
    let mut s = format!(
        "# Accuracy against time\n\nMade by `{made_by}` (one thread, best of several runs; errors are exact maxima over the inputs). *Pareto*: no other point of the stage has less error and less time. *Default*: what the crate ships. SPEC.md §5.10 says why each default sits where it does.\n",
    );
    let mut stage = "";
    for p in points {
        if p.stage != stage {
            stage = p.stage;
            let _ = write!(
                s,
                "\n## {stage}\n\n| knob | {} | time (s) | Pareto | default |\n|---|---|---|---|---|\n",
                p.metric.replace('|', "\\|")
            );
        }
        let _ = writeln!(
            s,
            "| {} | {:.3e} | {:.3e} | {} | {} |",
            p.knob.replace('|', "\\|"),
            p.error,
            p.seconds,
            if p.pareto { "yes" } else { "" },
            if p.default { "**default**" } else { "" }
        );
    }
    s
}

/// One panel per stage: log10 error (zero errors drawn at the panel's floor) against log10
/// time; Pareto points filled, the default ringed.
fn svg(points: &[Point]) -> String {
    let stages: Vec<&str> = {
        let mut v: Vec<&str> = points.iter().map(|p| p.stage).collect();
        v.dedup();
        v
    };
    let (pw, ph, m) = (320.0, 240.0, 50.0);
    let width = stages.len() as f64 * (pw + m) + m;
    let mut s = format!(
        "<svg xmlns=\"http://www.w3.org/2000/svg\" width=\"{width}\" height=\"{}\" font-family=\"sans-serif\" font-size=\"11\">\n",
        ph + 2.0 * m
    );
    for (k, stage) in stages.iter().enumerate() {
        let ps: Vec<&Point> = points.iter().filter(|p| p.stage == *stage).collect();
        let le = |p: &Point| {
            if p.error > 0.0 {
                p.error.log10()
            } else {
                f64::NAN
            }
        };
        let lt = |p: &Point| p.seconds.log10();
        let finite: Vec<f64> = ps.iter().map(|p| le(p)).filter(|v| v.is_finite()).collect();
        let (emin, emax) = finite
            .iter()
            .fold((f64::MAX, f64::MIN), |(a, b), &v| (a.min(v), b.max(v)));
        let (emin, emax) = if finite.is_empty() {
            (-1.0, 0.0)
        } else {
            (emin - 1.0, emax + 0.5)
        };
        let (tmin, tmax) = ps.iter().fold((f64::MAX, f64::MIN), |(a, b), p| {
            (a.min(lt(p)), b.max(lt(p)))
        });
        let (tmin, tmax) = (tmin - 0.2, tmax + 0.2);
        let x0 = m + k as f64 * (pw + m);
        let px = |t: f64| x0 + (t - tmin) / (tmax - tmin) * pw;
        let py = |e: f64| m + ph - (e - emin) / (emax - emin) * ph;
        let _ = writeln!(
            s,
            "<rect x=\"{x0}\" y=\"{m}\" width=\"{pw}\" height=\"{ph}\" fill=\"none\" stroke=\"#888\"/>\n<text x=\"{}\" y=\"{}\" text-anchor=\"middle\">{stage}</text>\n<text x=\"{}\" y=\"{}\" text-anchor=\"middle\">log10 seconds ({tmin:.1} … {tmax:.1})</text>\n<text x=\"{}\" y=\"{}\" transform=\"rotate(-90 {} {})\" text-anchor=\"middle\">log10 error ({emin:.1} … {emax:.1}; 0 at the floor)</text>",
            x0 + pw / 2.0,
            m - 10.0,
            x0 + pw / 2.0,
            m + ph + 30.0,
            x0 - 12.0,
            m + ph / 2.0,
            x0 - 12.0,
            m + ph / 2.0
        );
        for p in &ps {
            let e = le(p);
            let (x, y) = (px(lt(p)), if e.is_finite() { py(e) } else { m + ph - 4.0 });
            let fill = if p.pareto { "#1f77b4" } else { "white" };
            let _ = writeln!(
                s,
                "<circle cx=\"{x:.1}\" cy=\"{y:.1}\" r=\"4\" fill=\"{fill}\" stroke=\"#1f77b4\"><title>{}: {:.3e}, {:.3e} s</title></circle>",
                p.knob, p.error, p.seconds
            );
            if p.default {
                let _ = writeln!(
                    s,
                    "<circle cx=\"{x:.1}\" cy=\"{y:.1}\" r=\"8\" fill=\"none\" stroke=\"#d62728\"/>"
                );
            }
        }
    }
    s + "</svg>\n"
}

fn main() {
    let args: Vec<String> = std::env::args().collect();
    let value = |flag: &str| {
        args.iter()
            .position(|a| a == flag)
            .and_then(|i| args.get(i + 1))
    };
    let quick = args.iter().any(|a| a == "--quick");
    // `--only gjk,dibr` runs those stages and writes only where `--out` says (a partial
    // table must not replace the committed one by default).
    let only: Option<Vec<&str>> = value("--only").map(|v| v.split(',').collect());
    let out = match (value("--out"), &only) {
        (Some(dir), _) => Some(PathBuf::from(dir)),
        (None, None) => Some(PathBuf::from("reference_data/accuracy")),
        (None, Some(_)) => None,
    };
    type Stage = fn(bool, &mut Vec<Point>);
    let stages: [(&str, Stage); 14] = [
        ("forward", forward),
        ("cutoffs", cutoffs),
        ("blend", blend),
        ("backward", |_, p| backward_fd(p)),
        ("exp", exp),
        ("ransac", alignment),
        ("gjk", gjk),
        ("gjk-frustums", gjk_frustums),
        ("dibr", dibr),
        ("ssim", ssim_stage),
        ("ssim-grad", ssim_grad_stage),
        ("training", training),
        ("qa-mask", qa_mask),
        ("pipeline", pipeline_presets),
    ];
    if let Some(names) = &only {
        for name in names {
            assert!(
                stages.iter().any(|(s, _)| s == name),
                "--only: no stage {name:?} (stages: forward, cutoffs, blend, backward, exp, ransac, gjk, gjk-frustums, dibr, ssim, ssim-grad, training, qa-mask, pipeline)"
            );
        }
    }
    let pool = rayon::ThreadPoolBuilder::new()
        .num_threads(1)
        .build()
        .expect("pool");
    let mut points = Vec::new();
    pool.install(|| {
        for (name, stage) in stages {
            if only.as_ref().is_none_or(|o| o.contains(&name)) {
                stage(quick, &mut points);
            }
        }
    });
    mark_pareto(&mut points);
    let mut made_by = String::from("cargo bench --bench accuracy --");
    if quick {
        made_by += " --quick";
    }
    if let Some(names) = &only {
        made_by += &format!(" --only {}", names.join(","));
    }
    if let (Some(dir), Some(_)) = (value("--out"), &only) {
        made_by += &format!(" --out {dir}");
    }
    let made_by = made_by.trim_end_matches(" --");
    let md = markdown(&points, made_by);
    print!("{md}");
    let Some(out) = out else { return };
    std::fs::create_dir_all(&out).expect("output folder");
    for (name, text) in [
        ("accuracy.csv", csv(&points)),
        ("accuracy.md", md),
        ("accuracy.svg", svg(&points)),
    ] {
        let path = out.join(name);
        let tmp = out.join(format!(".{name}.tmp"));
        std::fs::write(&tmp, text)
            .and_then(|()| std::fs::rename(&tmp, &path))
            .unwrap_or_else(|e| panic!("{}: {e}", path.display()));
    }
    eprintln!("wrote {}", out.display());
}
