//! A training iteration against its roofline: `cargo bench --bench roofline [-- --quick]
//! [--json FILE] [--warmup N] [--reps R] [--views K] [--rounds M] [--resolution D]
//! [--threads N] [--external DIR]`.
//!
//! For lounge at 80×60 and 160×120, after `N` training iterations (default 1 500: a densified
//! state as the pipeline meets it), on 1 and all threads: each stage of one iteration timed
//! on its own (per view the fastest of `R` runs, default 5, then the median over `K` views,
//! default 16) beside its **floor**, measured in the same pool beside every view (the median
//! over the views, as the stage's):
//!
//! | stage | floor |
//! |---|---|
//! | project | the larger of: streaming the parameters it reads (the active SH degree's) and writing its splats and radii; its own kernel on cache-resident visible and culled Gaussians, at the view's counts |
//! | bin | the bare stable radix sort of the visible splats' depth keys and the per-tile count and scatter of their indices |
//! | blend | the evaluated pairs at the bare forward kernel's rate (`composite::bare_blend`) |
//! | loss | the SSIM's blurs (16 planes per channel with the gradient) at the bare blur's rate (`ssim::bare_blur`) |
//! | blend bwd | the pairs the backward walked at the bare backward kernel's rate (`bare_blend_backward`) |
//! | proj bwd | the larger of: streaming the parameters and the splat gradients and writing every parameter's gradient; its own kernel on cache-resident Gaussians, as for project |
//! | adam | stream the gradients, update the parameters and both moments in place |
//! | densify stats | stream the screen-space gradients and radii, update the three statistics |
//!
//! The blend's, the backward blend's and the loss's floors, like the compute side of the
//! projection's, are the stages' own kernels on cache-resident data (as `benches/forward.rs`'
//! bare kernel): what the stage would cost without gathering, list building, memory traffic,
//! mixed blocks or scheduling. So a ratio is the stage's overhead over its kernel, and a
//! floor follows the machine and its instruction set (measured here, not a constant).
//! `stages` is the sum of the rows above (Adam unfused); `iteration` is `Trainer::step`
//! itself (Adam fused into the projection backward, one densification in a hundred steps
//! amortized), fastest of 3 rounds of `4·max(R, 5)` steps from clones of the warmed state;
//! the floor of both is the sum of the stages' floors. `--external DIR` builds the bare
//! kernels written outside the project that `DIR` holds (`common::External`: C files, built
//! without contracted multiply-adds, as the crate's arithmetic) and takes as the blend's and
//! its backward's floor the faster of the crate's bare kernel and the best of those (`ext`
//! beside a row's range, and `floor_external` in the JSON, when theirs was faster). `--rounds M` repeats the measurement
//! M times, the pools alternating, and reports per row the round of the median ratio and
//! the ratios' range (the machine's noise, in the same run). The first line names the CPU
//! and the instruction set the kernels use. `--json FILE` writes one record per (stage,
//! size, threads).

mod common;

use common::{
    External, FloorInput, arg, arg_text, bare_backward_rate, bare_rate, blur_rate, floor_seconds,
    median, stream_seconds, tile_splats,
};
use std::time::Instant;
use unseen::dataset;
use unseen::gaussian::Param;
use unseen::raster::backward::GradGroups;
use unseen::raster::backward::composite::{PixelGrads, composite_backward};
use unseen::raster::backward::project::{Gradients, project_backward_into};
use unseen::raster::plan::RenderPlan;
use unseen::raster::{Kernel, RenderReport, composite, project, tile};
use unseen::train::loss::{LossInput, LossWeights, image_loss};
use unseen::train::trainer::Trainer;

const STAGES: [&str; 8] = [
    "project",
    "bin",
    "blend",
    "loss",
    "blend bwd",
    "proj bwd",
    "adam",
    "densify stats",
];

/// A stage's name, measured seconds and floor seconds in one round, and whether its floor
/// was an external kernel's (in most views).
type Row = (String, f64, f64, bool);

/// One row of the table (and of `--json`).
#[derive(serde::Serialize)]
struct Record {
    stage: String,
    width: u32,
    height: u32,
    threads: usize,
    gaussians: usize,
    measured_seconds: f64,
    floor_seconds: f64,
    /// Of the round with the median ratio.
    ratio: f64,
    /// The smallest and largest ratio over the rounds.
    ratio_range: [f64; 2],
    /// The floor was (or held) an external kernel's (`--external`), faster than the
    /// crate's own.
    floor_external: bool,
    rounds: usize,
}

/// The bare kernels' rates in the current pool (measured beside each view).
struct Rates {
    /// Forward and backward bare kernels, pairs per second: the best of the crate's and the
    /// external ones (`--external`).
    forward: f64,
    backward: f64,
    /// Whether an external kernel was the faster.
    forward_external: bool,
    backward_external: bool,
    /// The SSIM blur at the image's width, outputs per second.
    blur: f64,
}

impl Rates {
    fn measure(width: usize, external: Option<&External>) -> Rates {
        let tile = tile_splats();
        let threads = rayon::current_num_threads();
        let best = |ours: f64, theirs: Option<(&str, f64)>| match theirs {
            Some((_, r)) if r > ours => (r, true),
            _ => (ours, false),
        };
        let (forward, forward_external) = best(
            bare_rate(&tile, Kernel::Auto),
            external.and_then(|e| External::best(&e.forward, threads)),
        );
        let (backward, backward_external) = best(
            bare_backward_rate(&tile, Kernel::Auto),
            external.and_then(|e| External::best(&e.backward, threads)),
        );
        Rates {
            forward,
            backward,
            forward_external,
            backward_external,
            blur: blur_rate(width),
        }
    }
}

/// The streaming floors of project, proj bwd, adam and densify stats (seconds), measured
/// beside each view's stages (a floor measured once per round was at the mercy of the
/// neighbours' memory traffic in that one moment: on a shared host Adam came out below it).
fn stream_floors(t: &Trainer) -> [f64; 4] {
    let g = &t.gaussians;
    let n = g.len();
    let rest_active = 3 * ((t.active_sh_degree as usize + 1).pow(2) - 1);
    // The arrays the projection reads (the active SH degree's share of the rest).
    let params_read = [3 * n, 3 * n, 4 * n, n, 3 * n, rest_active * n];
    let groups = [3 * n, 3 * n, 4 * n, n, 3 * n, g.sh_rest.len()];
    let with = |a: &[usize], b: &[usize]| [a, b].concat();
    [
        // Read the parameters; write the splats (10 values) and radii (2).
        stream_seconds(&params_read, &[10 * n, 2 * n]),
        // Read the parameters and the splat gradients (10); write every gradient and the
        // screen-space ones (2 + 2).
        stream_seconds(
            &with(&params_read, &[10 * n]),
            &with(&groups, &[2 * n, 2 * n]),
        ),
        // Per group: read the gradient; update x, m, v.
        groups
            .iter()
            .map(|&len| stream_seconds(&[len], &[len, len, len]))
            .sum(),
        // Read the NDC gradient (2) and radii (2); update the three statistics.
        stream_seconds(&[2 * n, 2 * n], &[n, n, n]),
    ]
}

/// Seconds per stage of one iteration on view `view` of the warmed trainer `t` (the
/// trainer's render options, the INRIA loss, the full backward into arrays, then Adam over
/// the six groups on a copy, then the densification statistics on a copy), fastest of
/// `reps`, and the floors of that view.
fn stages(t: &Trainer, view: &dataset::View, rates: &Rates, reps: usize) -> ([f64; 8], [f64; 8]) {
    let cam = &view.camera;
    let (w, h) = (cam.width as usize, cam.height as usize);
    let mut opts = t.render_options(false);
    opts.outputs.backward_state = true;
    let plan = RenderPlan::for_backward(&t.gaussians, &opts);
    let g = &t.gaussians;
    let mut fastest = [f64::MAX; 8];
    let mut counts = (0u64, 0u64, 0usize);
    let mut grads = Gradients::default();
    let mut last_splat_grads = Vec::new();
    for _ in 0..reps {
        // Adam's and the statistics' state, copied before the iteration (so that, as in
        // training, the forward and backward run between their last touch and Adam).
        let (mut scene, mut adam, mut stats) = (g.clone(), t.adam.clone(), t.stats.clone());
        let mut laps = [0f64; 8];
        let mut clock = Instant::now();
        let mut lap = |k: usize| {
            let now = Instant::now();
            laps[k] = (now - clock).as_secs_f64();
            clock = now;
        };
        let mut report = RenderReport::default();
        let pr = project::project(g, cam, &plan, &opts, &mut report);
        lap(0);
        let bins = tile::bin(&pr, w, h, opts.kernel);
        lap(1);
        let want = composite::Want {
            rgb: true,
            alpha: false,
            depth: false,
            expected_depth: false,
            backward_state: true,
        };
        let out = composite::composite(
            w,
            h,
            &pr,
            &bins,
            &plan,
            opts.background,
            want,
            opts.kernel,
            &mut report,
        );
        lap(2);
        let rgb = out.rgb.as_deref().unwrap();
        let loss = image_loss(
            &LossInput {
                width: w,
                height: h,
                rgb,
                target_rgb: &view.image.data,
                depth: None,
                target_depth: None,
                mask: None,
            },
            &LossWeights::INRIA,
        )
        .unwrap();
        lap(3);
        let pg = PixelGrads {
            v_rgb: Some(&loss.grad_rgb),
            v_alpha: None,
            v_depth: None,
            v_expected_depth: None,
            final_t: out.final_t.as_deref().unwrap(),
            n_contrib: out.n_contrib.as_deref().unwrap(),
            blend_halves: out.blend_halves.as_deref().unwrap(),
            depth: None,
        };
        let cg = composite_backward(
            w,
            h,
            &pr,
            &bins,
            plan.cull_rows,
            plan.conventions.max_alpha(),
            opts.background,
            &pg,
            true,
            opts.kernel,
        );
        lap(4);
        let camf = project::CameraF32::new(cam);
        project_backward_into(
            g,
            &camf,
            &pr,
            &plan,
            &GradGroups::ALL,
            &cg.splats,
            opts.kernel,
            &mut grads,
        );
        lap(5);
        for p in Param::ALL {
            adam.step(&mut scene, p, grads.param(p), 1e-3);
        }
        lap(6);
        stats.add_view(&grads.means2d_ndc, &pr.radii);
        lap(7);
        std::hint::black_box((&scene, &stats));
        for (f, l) in fastest.iter_mut().zip(laps) {
            *f = f.min(l);
        }
        counts = (report.pairs_evaluated, cg.walked, bins.intersections());
        last_splat_grads = cg.splats;
    }
    // The floors of this view.
    let pr = project::project(g, cam, &plan, &opts, &mut RenderReport::default());
    let (sort, scatter, written) = floor_seconds(&FloorInput::new(&pr, w, h));
    assert_eq!(
        written, counts.2,
        "the floor's lists differ from the binning's"
    );
    let (project_compute, backward_compute) = per_gaussian_floors(t, cam, &pr, &last_splat_grads);
    let stream = stream_floors(t);
    let floors = [
        stream[0].max(project_compute),
        sort + scatter,
        counts.0 as f64 / rates.forward,
        (16 * 3 * w * h) as f64 / rates.blur,
        counts.1 as f64 / rates.backward,
        stream[1].max(backward_compute),
        stream[2],
        stream[3],
    ];
    (fastest, floors)
}

/// The arithmetic floors of the projection and of its backward on view `cam`: each stage's own
/// kernel on cache-resident Gaussians of one kind — visible ones (every lane of a block
/// projected and coloured) and culled ones (the geometry only) — at the seconds per
/// Gaussian of the fastest of 20 calls on at most 4 096 of them per thread (the
/// projection's chunk: one per thread; every k-th, so that their sizes are the scene's),
/// times the view's visible and culled counts. `fwd` is the view's
/// projection, `splat_grads` its blend backward's.
fn per_gaussian_floors(
    t: &Trainer,
    cam: &unseen::camera::Camera,
    fwd: &project::Projected,
    splat_grads: &[unseen::raster::backward::composite::SplatGrad],
) -> (f64, f64) {
    let most = 4096 * rayon::current_num_threads();
    let mut opts = t.render_options(false);
    opts.outputs.backward_state = true;
    let camf = project::CameraF32::new(cam);
    let visible: Vec<usize> = (0..fwd.radii.len())
        .filter(|&i| fwd.radii[i] != [0, 0])
        .collect();
    let culled: Vec<usize> = (0..fwd.radii.len())
        .filter(|&i| fwd.radii[i] == [0, 0])
        .collect();
    let mut floors = (0.0, 0.0);
    for kind in [visible, culled] {
        if kind.is_empty() {
            continue;
        }
        let step = kind.len().div_ceil(most);
        let idx: Vec<usize> = kind.iter().copied().step_by(step).collect();
        let sub = t.gaussians.select(&idx);
        let sg: Vec<_> = idx.iter().map(|&i| splat_grads[i]).collect();
        let plan = RenderPlan::for_backward(&sub, &opts);
        let pr = project::project(&sub, cam, &plan, &opts, &mut RenderReport::default());
        let mut grads = Gradients::default();
        let (mut tp, mut tb) = (f64::MAX, f64::MAX);
        for _ in 0..20 {
            let t0 = Instant::now();
            let p = project::project(&sub, cam, &plan, &opts, &mut RenderReport::default());
            let t1 = Instant::now();
            project_backward_into(
                &sub,
                &camf,
                &pr,
                &plan,
                &GradGroups::ALL,
                &sg,
                opts.kernel,
                &mut grads,
            );
            let t2 = Instant::now();
            std::hint::black_box((p, &grads));
            tp = tp.min((t1 - t0).as_secs_f64());
            tb = tb.min((t2 - t1).as_secs_f64());
        }
        let per = kind.len() as f64 / idx.len() as f64;
        floors.0 += tp * per;
        floors.1 += tb * per;
    }
    floors
}

/// Seconds per `Trainer::step` from clones of `t`: `reps` steps, fastest of 3 rounds.
fn iteration_seconds(t: &Trainer, reps: usize) -> f64 {
    let mut best = f64::MAX;
    for _ in 0..3 {
        let mut c = t.clone();
        let t0 = Instant::now();
        for _ in 0..reps {
            c.step().unwrap();
        }
        best = best.min(t0.elapsed().as_secs_f64() / reps as f64);
    }
    best
}

/// One round on the current pool: per stage the median over `views` views of the fastest of
/// `reps` and its floor, then `stages` (their sum) and `iteration` (`Trainer::step`).
fn measure_rows(
    t: &Trainer,
    data: &dataset::Dataset,
    views: usize,
    reps: usize,
    width: u32,
    external: Option<&External>,
) -> Vec<Row> {
    let mut measured = [const { Vec::new() }; 8];
    let mut floors = [const { Vec::new() }; 8];
    // Per stage, the views whose floor was an external kernel's (the blend's and its
    // backward's only).
    let mut external_views = [0usize; 8];
    for k in 0..views {
        let view = &data.views[data.train[k % data.train.len()]];
        // The bare rates beside every view's stages too, as the streaming floors: each
        // floor is then the median over the same moments as its stage.
        let rates = Rates::measure(width as usize, external);
        external_views[2] += usize::from(rates.forward_external);
        external_views[4] += usize::from(rates.backward_external);
        let (m, f) = stages(t, view, &rates, reps);
        for i in 0..8 {
            measured[i].push(m[i]);
            floors[i].push(f[i]);
        }
    }
    let mut rows: Vec<Row> = STAGES
        .iter()
        .enumerate()
        .map(|(i, s)| {
            (
                s.to_string(),
                median(measured[i].clone()),
                median(floors[i].clone()),
                2 * external_views[i] > views,
            )
        })
        .collect();
    let floor_sum: f64 = rows.iter().map(|r| r.2).sum();
    let stage_sum: f64 = rows.iter().map(|r| r.1).sum();
    let any_external = rows.iter().any(|r| r.3);
    rows.push(("stages".into(), stage_sum, floor_sum, any_external));
    rows.push((
        "iteration".into(),
        iteration_seconds(t, 4 * reps.max(5)),
        floor_sum,
        any_external,
    ));
    rows
}

fn main() {
    unseen::sys::keep_freed_memory(); // as the CLI does (SPEC.md §6)
    let quick = std::env::args().any(|a| a == "--quick");
    let warmup = arg("--warmup", if quick { 500 } else { 1500 });
    let reps = arg("--reps", if quick { 3 } else { 5 });
    let views = arg("--views", if quick { 4 } else { 16 });
    let rounds = arg("--rounds", 1).max(1);
    let json = arg_text("--json");
    let pools = common::pools();
    println!("{}", common::machine());
    // `--external DIR`: bare kernels written outside the project, built and run once.
    let external = arg_text("--external")
        .map(|d| External::run(std::path::Path::new(&d), pools.last().unwrap().0));
    if let Some(e) = &external {
        for (kind, list) in [("forward", &e.forward), ("backward", &e.backward)] {
            for (file, threads, rate) in list {
                println!(
                    "external {kind} {file}: {threads} threads {:.3} G pairs/s",
                    rate / 1e9
                );
            }
        }
        for s in &e.skipped {
            println!("external skipped: {s}");
        }
        for (threads, pool) in &pools {
            let tile = tile_splats();
            let (f, b) = pool.install(|| {
                (
                    bare_rate(&tile, Kernel::Auto),
                    bare_backward_rate(&tile, Kernel::Auto),
                )
            });
            println!(
                "crate bare forward {:.3}, backward {:.3} G pairs/s on {threads} threads",
                f / 1e9,
                b / 1e9
            );
        }
    }
    let mut records = Vec::new();
    println!(
        "{:>13} {:>8} {:>3} {:>9} {:>12} {:>10} {:>7} {:>13}",
        "stage", "size", "thr", "gaussians", "measured ms", "floor ms", "ratio", "range"
    );
    // `--resolution D`: only 1/D of lounge's size; `--threads N`: only that pool.
    let sizes: Vec<u32> = match arg("--resolution", 0) {
        0 => vec![2, 1],
        d => vec![d as u32],
    };
    let only_threads = arg("--threads", 0);
    for resolution in sizes {
        let (data, cfg) = common::lounge(resolution);
        let mut t = Trainer::new(&data, cfg).unwrap();
        let (_, all) = pools.last().unwrap();
        all.install(|| {
            for _ in 0..warmup {
                t.step().unwrap();
            }
        });
        let cam0 = &data.views[data.train[0]].camera;
        let (width, height) = (cam0.width, cam0.height);
        // Rounds alternate the pools; per (stage, pool) the round of the median ratio is
        // reported, with the ratios' range over the rounds.
        let mut per_pool: Vec<(usize, Vec<Vec<Row>>)> = Vec::new();
        for _ in 0..rounds {
            for (threads, pool) in &pools {
                if only_threads != 0 && *threads != only_threads {
                    continue;
                }
                let rows =
                    pool.install(|| measure_rows(&t, &data, views, reps, width, external.as_ref()));
                match per_pool.iter_mut().find(|(n, _)| n == threads) {
                    Some((_, r)) => r.push(rows),
                    None => per_pool.push((*threads, vec![rows])),
                }
            }
        }
        for (threads, runs) in per_pool {
            for i in 0..runs[0].len() {
                let mut of: Vec<&Row> = runs.iter().map(|r| &r[i]).collect();
                of.sort_by(|a, b| (a.1 / a.2).total_cmp(&(b.1 / b.2)));
                let (lo, hi) = (of[0].1 / of[0].2, of[of.len() - 1].1 / of[of.len() - 1].2);
                let (stage, m, f, ext) = of[of.len() / 2].clone();
                println!(
                    "{:>13} {:>8} {:>3} {:>9} {:>12.3} {:>10.3} {:>7.2} {:>13}",
                    stage,
                    format!("{width}x{height}"),
                    threads,
                    t.gaussians.len(),
                    m * 1e3,
                    f * 1e3,
                    m / f,
                    format!("{lo:.2}-{hi:.2}{}", if ext { " ext" } else { "" })
                );
                records.push(Record {
                    stage,
                    width,
                    height,
                    threads,
                    gaussians: t.gaussians.len(),
                    measured_seconds: m,
                    floor_seconds: f,
                    ratio: m / f,
                    ratio_range: [lo, hi],
                    floor_external: ext,
                    rounds,
                });
            }
        }
    }
    if let Some(path) = json {
        let text = serde_json::to_string_pretty(&records).unwrap();
        std::fs::write(&path, text).unwrap_or_else(|e| panic!("{path}: {e}"));
    }
}
