//! Backward-pass throughput: `cargo bench --bench backward [-- --quick]`.
//!
//! Per resolution × threads × gradient groups: median forward and backward wall time per
//! iteration (the backward split into the blend walk and the projection chain), and the
//! backward's Gaussian-pixel pairs per second (pairs walked back to front, counted exactly).
//! `fwd-blend` times the forward composite alone on the same projected splats and tile lists
//! (with the backward state, as training renders); the last three columns compare the two
//! blends in the same run: forward and backward blend pair rates (each its own pair count)
//! and `bwd/fwd`, their ratio (issue #13).
//! `kernel`: both blends timed per form, interleaved within each iteration on the same
//! projected splats and lists — `auto` (AVX-512F where the CPU has it) and `avx2`; the
//! render and the projection chain (`forward`, `bwd-proj`) are the `auto` ones, shared.
//! `frozen` rows: SH-only iterations replayed from a `FrozenBlend` record (forward column =
//! replayed render, backward column = replayed SH backward; the pairs are the full walk's).

mod common;

use common::median;
use std::time::Instant;
use unseen::raster::Kernel;
use unseen::raster::backward::composite::{PixelGrads, composite_backward};
use unseen::raster::backward::frozen::{FrozenBlend, FrozenWork};
use unseen::raster::backward::project::project_backward;
use unseen::raster::backward::{GradGroups, ImageGrads, render_for_backward};
use unseen::raster::composite::{Want, composite};
use unseen::raster::project::CameraF32;
use unseen::raster::{RenderOptions, RenderReport};
use unseen::rng::Uniform;
use unseen::scene::{default_camera, random_scene};

fn main() {
    unseen::sys::keep_freed_memory(); // as the CLI does (SPEC.md §6)
    let quick = std::env::args().any(|a| a == "--quick");
    let n = 100_000;
    let scene = random_scene(n, 3, 7, 0.003, 0.03);
    println!(
        "{:>9} {:>9} {:>3} {:>8} {:>6} {:>10} {:>10} {:>10} {:>10} {:>10} {:>12} {:>10} {:>9} {:>9} {:>7}",
        "gaussians",
        "image",
        "thr",
        "groups",
        "kernel",
        "forward",
        "fwd-blend",
        "bwd-blend",
        "bwd-proj",
        "backward",
        "pairs",
        "Mpairs/s",
        "fwd Mp/s",
        "bwd Mp/s",
        "bwd/fwd"
    );
    let want = Want {
        rgb: true,
        alpha: false,
        depth: false,
        expected_depth: false,
        backward_state: true,
    };
    let resolutions: &[(u32, u32)] = if quick {
        &[(256, 256)]
    } else {
        &[(256, 256), (1024, 768)]
    };
    for &(w, h) in resolutions {
        let cam = default_camera(w, h);
        let opts = RenderOptions::default();
        let mut u = Uniform::new(3);
        let v = ImageGrads {
            rgb: Some(
                (0..(w * h * 3) as usize)
                    .map(|_| u.range(-1.0, 1.0))
                    .collect(),
            ),
            ..Default::default()
        };
        for threads in [1usize, 2] {
            let pool = rayon::ThreadPoolBuilder::new()
                .num_threads(threads)
                .build()
                .unwrap();
            for (gname, groups) in [("full", GradGroups::ALL), ("sh_rest", GradGroups::SH_REST)] {
                const KERNELS: [(&str, Kernel); 2] =
                    [("auto", Kernel::Auto), ("avx2", Kernel::Avx2)];
                let (mut tf, mut tp) = (Vec::new(), Vec::new());
                let (mut tfc, mut tc) = ([Vec::new(), Vec::new()], [Vec::new(), Vec::new()]);
                let (mut pairs, mut fwd_pairs) = (0, 0);
                pool.install(|| {
                    for _ in 0..5 {
                        let t0 = Instant::now();
                        let fwd = render_for_backward(&scene, &cam, &opts).unwrap();
                        tf.push(t0.elapsed().as_secs_f64());
                        let r = &fwd.render;
                        let pg = PixelGrads {
                            v_rgb: v.rgb.as_deref(),
                            v_alpha: None,
                            v_depth: None,
                            v_expected_depth: None,
                            final_t: r.final_t.as_deref().unwrap(),
                            n_contrib: r.n_contrib.as_deref().unwrap(),
                            blend_halves: r.blend_halves.as_deref().unwrap(),
                            depth: None,
                        };
                        let mut splat_grads = Vec::new();
                        for (k, &(_, kernel)) in KERNELS.iter().enumerate() {
                            let t1 = Instant::now();
                            let mut rep = RenderReport::default();
                            let out = composite(
                                w as usize,
                                h as usize,
                                &fwd.projected,
                                &fwd.bins,
                                &fwd.plan,
                                opts.background,
                                want,
                                kernel,
                                &mut rep,
                            );
                            tfc[k].push(t1.elapsed().as_secs_f64());
                            std::hint::black_box(out);
                            fwd_pairs = rep.pairs_evaluated;
                            let t1 = Instant::now();
                            let cg = composite_backward(
                                w as usize,
                                h as usize,
                                &fwd.projected,
                                &fwd.bins,
                                fwd.plan.cull_rows,
                                fwd.plan.conventions.max_alpha(),
                                opts.background,
                                &pg,
                                groups.geometry(),
                                kernel,
                            );
                            tc[k].push(t1.elapsed().as_secs_f64());
                            pairs = cg.pairs;
                            if kernel == opts.kernel {
                                splat_grads = cg.splats;
                            }
                        }
                        let t2 = Instant::now();
                        let g = project_backward(
                            &scene,
                            &CameraF32::new(&cam),
                            &fwd.projected,
                            &fwd.plan,
                            &groups,
                            &splat_grads,
                            opts.kernel,
                        );
                        tp.push(t2.elapsed().as_secs_f64());
                        std::hint::black_box(g);
                    }
                });
                let (f, p) = (median(tf), median(tp));
                for (k, (kname, _)) in KERNELS.iter().enumerate() {
                    let (fc, c) = (median(tfc[k].clone()), median(tc[k].clone()));
                    let b = c + p;
                    let (fr, br) = (fwd_pairs as f64 / fc / 1e6, pairs as f64 / c / 1e6);
                    println!(
                        "{:>9} {:>9} {:>3} {:>8} {:>6} {:>8.1}ms {:>8.1}ms {:>8.1}ms {:>8.1}ms {:>8.1}ms {:>12} {:>10.1} {:>9.1} {:>9.1} {:>7.2}",
                        n,
                        format!("{w}x{h}"),
                        threads,
                        gname,
                        kname,
                        f * 1e3,
                        fc * 1e3,
                        c * 1e3,
                        p * 1e3,
                        b * 1e3,
                        pairs,
                        pairs as f64 / b / 1e6,
                        fr,
                        br,
                        br / fr
                    );
                }
                if groups == GradGroups::SH_REST {
                    // Frozen geometry: record once, then replay forward and backward.
                    let (mut rf, mut rb) = (Vec::new(), Vec::new());
                    pool.install(|| {
                        let frozen = FrozenBlend::record(&scene, &cam, &opts).unwrap();
                        // The QA fine-tune's fused path: blend backward, then the SH-rest
                        // gradient of every Gaussian.
                        let (mut ws, mut rgb) = (FrozenWork::default(), Vec::new());
                        let mut g = vec![0f32; scene.sh_rest.len()];
                        for _ in 0..5 {
                            let t0 = Instant::now();
                            frozen.render_rgb_with(&scene, &mut ws, &mut rgb).unwrap();
                            let t1 = Instant::now();
                            frozen
                                .color_backward(v.rgb.as_deref().unwrap(), &mut ws)
                                .unwrap();
                            frozen.sh_rest_grad(&ws, 0, &mut g);
                            let t2 = Instant::now();
                            std::hint::black_box((&rgb, &g));
                            rf.push((t1 - t0).as_secs_f64());
                            rb.push((t2 - t1).as_secs_f64());
                        }
                    });
                    let (a, b) = (median(rf), median(rb));
                    println!(
                        "{:>9} {:>9} {:>3} {:>8} {:>6} {:>8.1}ms {:>10} {:>10} {:>10} {:>8.1}ms {:>12} {:>10.1}",
                        n,
                        format!("{w}x{h}"),
                        threads,
                        "frozen",
                        "",
                        a * 1e3,
                        "",
                        "",
                        "",
                        b * 1e3,
                        pairs,
                        pairs as f64 / b / 1e6
                    );
                }
            }
        }
    }
}
