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

use common::median;
use std::time::Instant;
use unseen::raster::Kernel;
use unseen::raster::composite::{Want, bare_blend, composite};
use unseen::raster::project::{Splat, project};
use unseen::raster::tile::{bin, tile_rect};
use unseen::raster::{RenderOptions, RenderPlan, RenderReport};
use unseen::scene::{default_camera, random_scene};

/// 128 splats inside one 16×16 tile (σ of 1–4 px, opacities 0.02–0.06, so transmittance
/// stays above the stop over the whole list and every splat is evaluated on every row).
fn tile_splats() -> Vec<Splat> {
    let mut u = unseen::rng::Uniform::new(3);
    (0..128)
        .map(|_| {
            let sd = u.range(1.0, 4.0);
            let inv = 1.0 / (sd * sd);
            Splat {
                mean: [u.range(0.0, 16.0), u.range(0.0, 16.0)],
                conic: [inv, u.range(-0.2, 0.2) * inv, inv],
                opacity: u.range(0.02, 0.06),
                color: [u.unit(), u.unit(), u.unit()],
                depth: u.range(1.0, 5.0),
            }
        })
        .collect()
}

/// Bare-kernel pairs per second in the current pool (median of 5).
fn bare_rate(splats: &[Splat], kernel: Kernel) -> f64 {
    let rows = 1 << 14;
    median(
        (0..5)
            .map(|_| {
                let t0 = Instant::now();
                let pairs = bare_blend(splats, rows, kernel);
                pairs as f64 / t0.elapsed().as_secs_f64()
            })
            .collect(),
    )
}

/// Seconds to read every parameter the projection reads (means, scales, rotations,
/// opacities, SH) once, xor-folded in parallel chunks (median of 5): the memory-bandwidth
/// floor of the per-Gaussian stages in the current pool. (An f32 sum here was bound by the
/// add's latency, one value per 3–4 cycles, not by memory: it overstated the floor ~3×.)
fn read_seconds(scene: &unseen::gaussian::Gaussians) -> f64 {
    use rayon::prelude::*;
    let arrays: [&[f32]; 6] = [
        scene.means.as_flattened(),
        scene.log_scales.as_flattened(),
        scene.quats.as_flattened(),
        &scene.opacity_logits,
        scene.sh_dc.as_flattened(),
        &scene.sh_rest,
    ];
    median(
        (0..5)
            .map(|_| {
                let t0 = Instant::now();
                let s: u32 = arrays
                    .iter()
                    .map(|a| {
                        a.par_chunks(1 << 14)
                            .map(|c| c.iter().fold(0u32, |x, &y| x ^ y.to_bits()))
                            .reduce(|| 0, |x, y| x ^ y)
                    })
                    .fold(0, |x, y| x ^ y);
                std::hint::black_box(s);
                t0.elapsed().as_secs_f64()
            })
            .collect(),
    )
}

/// The binning floor's input, made outside the timing from a projection: the visible
/// splats' keys `depth_bits << 32 | index` in index order, the smallest depth bits, and every
/// splat's tile rectangle.
struct FloorInput {
    keys: Vec<u64>,
    min: u32,
    rects: Vec<[u32; 4]>,
    tiles: (usize, usize),
}

impl FloorInput {
    fn new(p: &unseen::raster::project::Projected, w: usize, h: usize) -> FloorInput {
        let tiles = (w.div_ceil(16), h.div_ceil(16));
        let rects = p
            .splats
            .iter()
            .zip(&p.radii)
            .map(|(s, &r)| tile_rect(s.mean, r, tiles.0, tiles.1).map(|v| v as u32))
            .collect();
        let keys: Vec<u64> = (0..p.radii.len())
            .filter(|&i| p.radii[i][0] > 0 || p.radii[i][1] > 0)
            .map(|i| u64::from(p.splats[i].depth.to_bits()) << 32 | i as u64)
            .collect();
        let min = keys.iter().map(|k| (k >> 32) as u32).min().unwrap_or(0);
        FloorInput {
            keys,
            min,
            rects,
            tiles,
        }
    }
}

/// Seconds of the bare sort and the bare count-and-scatter of `f` in the current pool
/// (median of 5 each), and the intersections written (checked against the binning's).
fn floor_seconds(f: &FloorInput) -> (f64, f64, usize) {
    use rayon::prelude::*;
    let n = f.keys.len();
    let threads = rayon::current_num_threads();
    let len = n.div_ceil(threads).max(1);
    let (mut a, mut b) = (f.keys.clone(), f.keys.clone());
    let max = a.iter().map(|k| (k >> 32) as u32).max().unwrap_or(0);
    let bits = 32 - (max - f.min).leading_zeros();
    let passes = bits.div_ceil(11);
    // LSD radix sort, equal digits of ≤ 11 bits: per-chunk histograms, a prefix sum in
    // (digit, chunk) order, per-chunk scatters.
    let mut sort = || {
        a.copy_from_slice(&f.keys);
        if passes == 0 {
            return;
        }
        let width = bits.div_ceil(passes);
        let buckets = 1usize << width;
        for pass in 0..passes {
            let shift = 32 + pass * width;
            let min = u64::from(f.min) << 32;
            let digit = move |k: u64| ((k - min) >> shift) as usize & (buckets - 1);
            let mut hist: Vec<Vec<usize>> = a
                .par_chunks(len)
                .map(|c| {
                    let mut h = vec![0usize; buckets];
                    c.iter().for_each(|&k| h[digit(k)] += 1);
                    h
                })
                .collect();
            let mut acc = 0;
            for d in 0..buckets {
                for h in hist.iter_mut() {
                    (h[d], acc) = (acc, acc + h[d]);
                }
            }
            let out = b.as_mut_ptr() as usize;
            a.par_chunks(len).zip(hist).for_each(|(c, mut cur)| {
                for &k in c {
                    let d = digit(k);
                    // SAFETY: the prefix sum gives each (chunk, digit) its own range < n.
                    unsafe { (out as *mut u64).add(cur[d]).write(k) };
                    cur[d] += 1;
                }
            });
            std::mem::swap(&mut a, &mut b);
        }
    };
    let mut t_sort = Vec::new();
    for _ in 0..5 {
        let t0 = Instant::now();
        sort();
        t_sort.push(t0.elapsed().as_secs_f64());
    }
    let sorted = a;
    // Per-tile counts per chunk of the sorted keys, a prefix sum in (tile, chunk) order,
    // per-chunk scatters of the indices.
    let (tx, ty) = f.tiles;
    let mut ids = vec![0u32; 0];
    let mut scatter = || {
        let mut cur: Vec<Vec<usize>> = sorted
            .par_chunks(len)
            .map(|c| {
                let mut count = vec![0usize; tx * ty];
                for &k in c {
                    let [x0, x1, y0, y1] = f.rects[k as u32 as usize].map(|v| v as usize);
                    for y in y0..y1 {
                        count[y * tx + x0..y * tx + x1]
                            .iter_mut()
                            .for_each(|v| *v += 1);
                    }
                }
                count
            })
            .collect();
        let mut acc = 0;
        for t in 0..tx * ty {
            for c in cur.iter_mut() {
                (c[t], acc) = (acc, acc + c[t]);
            }
        }
        ids.resize(acc, 0);
        let out = ids.as_mut_ptr() as usize;
        sorted.par_chunks(len).zip(cur).for_each(|(c, mut cur)| {
            for &k in c {
                let [x0, x1, y0, y1] = f.rects[k as u32 as usize].map(|v| v as usize);
                for y in y0..y1 {
                    for c in &mut cur[y * tx + x0..y * tx + x1] {
                        // SAFETY: the prefix sum gives each (chunk, tile) its own range.
                        unsafe { (out as *mut u32).add(*c).write(k as u32) };
                        *c += 1;
                    }
                }
            }
        });
    };
    let mut t_scatter = Vec::new();
    for _ in 0..5 {
        let t0 = Instant::now();
        scatter();
        t_scatter.push(t0.elapsed().as_secs_f64());
    }
    (median(t_sort), median(t_scatter), ids.len())
}

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
