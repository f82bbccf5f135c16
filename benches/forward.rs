//! Forward-rasterizer throughput: `cargo bench --bench forward [-- --quick]`.
//!
//! Reports, per scene size × resolution × thread count, the median wall time per frame of
//! each stage (project, bin, composite) and the blend throughput in Gaussian-pixel
//! evaluations per second (the pairs the composite kernel evaluates, counted exactly).
//! Scenes are `unseen::scene::random_scene` (seeded) seen by `default_camera`.
//!
//! Beside each line, in the same thread pool and run: the *bare kernel* bound
//! (`composite::bare_blend`: the blend loop alone on an L1-resident list, SPEC.md §5.7), the
//! composite's and the whole frame's pair rates as fractions of it, and the per-Gaussian
//! work (project + bin) in units of bare-kernel pairs per Gaussian (issue #13: ≤ 24), and
//! `read/G`: the time to merely read the parameters the projection reads (236 B per
//! Gaussian at SH degree 3) in the same units, the memory-bandwidth floor of that work.
//!
//! Then the per-Gaussian *floor* of issue #38 (`floor/G`, same units): read + an exact
//! stable depth sort of the visible splats + the per-tile count and scatter of their
//! indices, the sort and scatter written bare here (8-byte keys, one chunk per thread, the
//! rectangles precomputed outside the timing), and `(p+b)/floor`, the projection and
//! binning against it (the criterion: ≤ 1.5 at 100k Gaussians, SH 3, whole frame).

mod common;

use common::{FloorInput, bare_rate, floor_seconds, median, read_seconds, tile_splats};
use std::time::Instant;
use unseen::raster::Kernel;
use unseen::raster::composite::{Want, composite};
use unseen::raster::project::project;
use unseen::raster::tile::bin;
use unseen::raster::{RenderOptions, RenderPlan, RenderReport};
use unseen::scene::{default_camera, random_scene};

fn main() {
    unseen::sys::keep_freed_memory(); // as the CLI does (SPEC.md §6)
    let quick = std::env::args().any(|a| a == "--quick");
    let sizes: &[usize] = if quick {
        &[10_000, 100_000]
    } else {
        &[10_000, 100_000, 1_000_000]
    };
    let resolutions: &[(u32, u32)] = &[(256, 256), (1024, 768)];
    let kernels: &[(&str, Kernel)] = &[
        ("auto", Kernel::Auto),
        ("avx2", Kernel::Avx2),
        ("scalar", Kernel::Scalar),
    ];
    let tile = tile_splats();
    println!(
        "{:>9} {:>9} {:>3} {:>6} {:>9} {:>9} {:>11} {:>9} {:>12} {:>9} {:>9} {:>9} {:>10} {:>9} {:>8} {:>8} {:>11}",
        "gaussians",
        "image",
        "thr",
        "kernel",
        "project",
        "bin",
        "composite",
        "frame",
        "pairs",
        "Gpairs/s",
        "bare",
        "comp/bare",
        "frame/bare",
        "pairs/G",
        "read/G",
        "floor/G",
        "(p+b)/floor"
    );
    for &n in sizes {
        let scene = random_scene(n, 3, 7, 0.003, 0.03);
        for &(w, h) in resolutions {
            let cam = default_camera(w, h);
            let opts = RenderOptions::default();
            let plan = RenderPlan::new(&scene, &opts);
            let want = Want {
                rgb: true,
                alpha: false,
                depth: false,
                expected_depth: false,
                backward_state: false,
            };
            for threads in [1usize, 2] {
                let pool = rayon::ThreadPoolBuilder::new()
                    .num_threads(threads)
                    .build()
                    .unwrap();
                for &(kname, kernel) in kernels {
                    if kernel == Kernel::Scalar && (threads != 1 || n > 100_000) {
                        continue; // the reference kernel once per size, for the speed-up figure
                    }
                    let reps = if n >= 1_000_000 { 3 } else { 7 };
                    let (mut tp, mut tb, mut tc) = (Vec::new(), Vec::new(), Vec::new());
                    let mut pairs = 0;
                    let (mut bare, mut read, mut floor) = (0.0, 0.0, 0.0);
                    pool.install(|| {
                        bare = bare_rate(&tile, kernel);
                        read = read_seconds(&scene);
                        let mut rep = RenderReport::default();
                        let p = project(&scene, &cam, &plan, &opts, &mut rep);
                        let (sort, scatter, written) =
                            floor_seconds(&FloorInput::new(&p, w as usize, h as usize));
                        let b = bin(&p, w as usize, h as usize, kernel);
                        assert_eq!(written, b.intersections(), "the floor's lists differ");
                        floor = read + sort + scatter;
                        for _ in 0..reps {
                            let mut rep = RenderReport::default();
                            let t0 = Instant::now();
                            let p = project(&scene, &cam, &plan, &opts, &mut rep);
                            let t1 = Instant::now();
                            let b = bin(&p, w as usize, h as usize, kernel);
                            let t2 = Instant::now();
                            let out = composite(
                                w as usize,
                                h as usize,
                                &p,
                                &b,
                                &plan,
                                opts.background,
                                want,
                                kernel,
                                &mut rep,
                            );
                            let t3 = Instant::now();
                            std::hint::black_box(out);
                            tp.push((t1 - t0).as_secs_f64());
                            tb.push((t2 - t1).as_secs_f64());
                            tc.push((t3 - t2).as_secs_f64());
                            pairs = rep.pairs_evaluated;
                        }
                    });
                    let (p, b, c) = (median(tp), median(tb), median(tc));
                    let rate = pairs as f64 / c;
                    println!(
                        "{:>9} {:>9} {:>3} {:>6} {:>7.2}ms {:>7.2}ms {:>9.2}ms {:>7.2}ms {:>12} {:>9.3} {:>9.3} {:>9.2} {:>10.2} {:>9.1} {:>8.1} {:>8.1} {:>11.2}",
                        n,
                        format!("{w}x{h}"),
                        threads,
                        kname,
                        p * 1e3,
                        b * 1e3,
                        c * 1e3,
                        (p + b + c) * 1e3,
                        pairs,
                        rate / 1e9,
                        bare / 1e9,
                        rate / bare,
                        pairs as f64 / (p + b + c) / bare,
                        (p + b) * bare / n as f64,
                        read * bare / n as f64,
                        floor * bare / n as f64,
                        (p + b) / floor
                    );
                }
            }
        }
    }
    rounding_peer();
}

/// `math::round::{floor, ceil}` against `f32::{floor, ceil}` (libm calls on the default
/// x86-64 target) in the same run: ns per call over 4M values of the magnitudes splat
/// bounds have.
fn rounding_peer() {
    let v: Vec<f32> = (0..1 << 22)
        .map(|i| ((i as f32) * 0.618_034).fract() * 2048.0 - 1024.0)
        .collect();
    let time = |f: &dyn Fn(f32) -> f32| {
        let mut best = f64::INFINITY;
        for _ in 0..5 {
            let t0 = Instant::now();
            let mut acc = 0f32;
            for &x in &v {
                acc += f(std::hint::black_box(x));
            }
            std::hint::black_box(acc);
            best = best.min(t0.elapsed().as_secs_f64() / v.len() as f64);
        }
        best * 1e9
    };
    let (sf, sc) = (time(&|x| x.floor()), time(&|x| x.ceil()));
    let (of, oc) = (
        time(&|x| unseen::math::round::floor(x)),
        time(&|x| unseen::math::round::ceil(x)),
    );
    println!(
        "rounding: f32::floor {sf:.2} ns, own floor {of:.2} ns ({:.1}x); f32::ceil {sc:.2} ns, own ceil {oc:.2} ns ({:.1}x)",
        sf / of,
        sc / oc
    );
}
