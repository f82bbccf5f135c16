//! Cost of the decision diagnostics against a plain render:
//! `cargo bench --bench decisions [-- --quick] [-- --runs N]`.
//!
//! Per scene size (`random_scene`, seeded, as `forward`) at 256×256 and per thread count, the
//! fastest of N interleaved runs (render, diagnostics, render, …) of a plain forward render
//! (`render`, default options) and of `decisions` (default margins) on the same scene and
//! camera, and their ratio. The diagnostics' stages beside it, each the fastest of N in the
//! same loop: the projection with the relaxed opacity cull plus binning (`proj+bin`) and
//! `conic_rounding` of every visible Gaussian (`rounding`); `walk` is the rest (the per-pixel
//! replay and the per-Gaussian projection flags), by difference of the fastest times.

mod common;

use rayon::prelude::*;
use std::time::Instant;
use unseen::raster::decisions::{Margins, conic_rounding, decisions};
use unseen::raster::project::{CameraF32, project};
use unseen::raster::tile::bin;
use unseen::raster::{Cutoffs, RenderOptions, RenderPlan, RenderReport, render};
use unseen::scene::{default_camera, random_scene};

fn main() {
    unseen::sys::keep_freed_memory(); // as the CLI does (SPEC.md §6)
    let args: Vec<String> = std::env::args().collect();
    let quick = args.iter().any(|a| a == "--quick");
    let runs = args
        .iter()
        .position(|a| a == "--runs")
        .and_then(|i| args.get(i + 1))
        .and_then(|v| v.parse().ok())
        .unwrap_or(if quick { 3 } else { 9 });
    println!(
        "{:>9} {:>9} {:>3} {:>10} {:>10} {:>9} {:>10} {:>10} {:>10}",
        "gaussians", "image", "thr", "render", "decisions", "ratio", "proj+bin", "rounding", "walk"
    );
    let (w, h) = (256u32, 256u32);
    for n in [10_000usize, 100_000] {
        let scene = random_scene(n, 3, 7, 0.003, 0.03);
        let cam = default_camera(w, h);
        let opts = RenderOptions::default();
        let margins = Margins::default();
        // The diagnostics' own projection (their opacity cull lowered by 2·alpha).
        let plan = RenderPlan::new(&scene, &opts);
        let relaxed = RenderPlan {
            cutoffs: Cutoffs {
                inv_alpha_threshold: 255.0 / (1.0 - 2.0 * margins.alpha),
                ..plan.cutoffs
            },
            ..plan
        };
        let camf = CameraF32::new(&cam);
        for (threads, pool) in common::pools() {
            let mut best = [f64::INFINITY; 4];
            pool.install(|| {
                for _ in 0..runs {
                    let t0 = Instant::now();
                    std::hint::black_box(render(&scene, &cam, &opts).unwrap());
                    let t1 = Instant::now();
                    std::hint::black_box(decisions(&scene, &cam, &opts, &margins).unwrap());
                    let t2 = Instant::now();
                    let mut rep = RenderReport::default();
                    let p = project(&scene, &cam, &relaxed, &opts, &mut rep);
                    let b = bin(&p, w as usize, h as usize, opts.kernel);
                    let t3 = Instant::now();
                    let k: f64 = (0..n)
                        .into_par_iter()
                        .filter(|&i| p.radii[i] != [0, 0])
                        .map(|i| conic_rounding(&scene, i, &camf).amplification)
                        .sum();
                    let t4 = Instant::now();
                    std::hint::black_box((b, k));
                    for (s, t) in best.iter_mut().zip([t1 - t0, t2 - t1, t3 - t2, t4 - t3]) {
                        *s = s.min(t.as_secs_f64());
                    }
                }
            });
            let [r, d, pb, cr] = best;
            println!(
                "{:>9} {:>9} {:>3} {:>8.2}ms {:>8.2}ms {:>8.1}x {:>8.2}ms {:>8.2}ms {:>8.2}ms",
                n,
                format!("{w}x{h}"),
                threads,
                r * 1e3,
                d * 1e3,
                d / r,
                pb * 1e3,
                cr * 1e3,
                (d - pb - cr) * 1e3
            );
        }
    }
}
