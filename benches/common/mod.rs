//! Timing helpers shared by the benches (each bench includes this module with `mod common;`).
#![allow(dead_code)] // each bench uses some of them

use std::time::Instant;
use unseen::raster::Kernel;
use unseen::raster::composite::bare_blend;
use unseen::raster::project::Splat;
use unseen::raster::tile::tile_rect;

/// The fastest of `runs` runs of `f` in seconds, and the last run's result.
pub fn best<T>(runs: usize, mut f: impl FnMut() -> T) -> (f64, T) {
    let mut t_best = f64::MAX;
    let mut out = None;
    for _ in 0..runs {
        let t = Instant::now();
        let r = f();
        t_best = t_best.min(t.elapsed().as_secs_f64());
        out = Some(r);
    }
    (t_best, out.expect("runs > 0"))
}

/// The median of `v` (the upper one for an even count).
pub fn median(mut v: Vec<f64>) -> f64 {
    v.sort_by(f64::total_cmp);
    v[v.len() / 2]
}

/// Rayon pools of 1 and (when the machine has more) all threads.
pub fn pools() -> Vec<(usize, rayon::ThreadPool)> {
    let all = std::thread::available_parallelism().map_or(1, |n| n.get());
    let mut v = vec![1];
    if all > 1 {
        v.push(all);
    }
    v.into_iter()
        .map(|n| {
            (
                n,
                rayon::ThreadPoolBuilder::new()
                    .num_threads(n)
                    .build()
                    .unwrap(),
            )
        })
        .collect()
}

/// 128 splats inside one 16×16 tile (σ of 1–4 px, opacities 0.02–0.06, so transmittance
/// stays above the stop over the whole list and every splat is evaluated on every row).
pub fn tile_splats() -> Vec<Splat> {
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
pub fn bare_rate(splats: &[Splat], kernel: Kernel) -> f64 {
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
pub fn read_seconds(scene: &unseen::gaussian::Gaussians) -> f64 {
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
pub struct FloorInput {
    keys: Vec<u64>,
    min: u32,
    rects: Vec<[u32; 4]>,
    tiles: (usize, usize),
}

impl FloorInput {
    pub fn new(p: &unseen::raster::project::Projected, w: usize, h: usize) -> FloorInput {
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
pub fn floor_seconds(f: &FloorInput) -> (f64, f64, usize) {
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

/// Backward bare-kernel pairs per second in the current pool (median of 5):
/// `raster::backward::composite::bare_blend_backward` over `splats`.
pub fn bare_backward_rate(splats: &[Splat], kernel: Kernel) -> f64 {
    use unseen::raster::backward::composite::bare_blend_backward;
    let rows = 1 << 12;
    median(
        (0..5)
            .map(|_| {
                let t0 = Instant::now();
                let pairs = bare_blend_backward(splats, rows, kernel);
                pairs as f64 / t0.elapsed().as_secs_f64()
            })
            .collect(),
    )
}

/// The SSIM blur's bare rate at row width `width` in the current pool (outputs per second,
/// median of 5): `train::ssim::bare_blur`.
pub fn blur_rate(width: usize) -> f64 {
    let rows = (1 << 20) / width.max(1);
    median(
        (0..5)
            .map(|_| {
                let t0 = Instant::now();
                let outputs = unseen::train::ssim::bare_blur(width, rows);
                outputs as f64 / t0.elapsed().as_secs_f64()
            })
            .collect(),
    )
}

/// [`stream_seconds`]' kernels: an xor fold, an in-place xor.
#[inline(always)]
fn stream_fold(c: &[u32]) -> u32 {
    c.iter().fold(0u32, |x, &y| x ^ y)
}
#[inline(always)]
fn stream_update(c: &mut [u32], x: u32) {
    c.iter_mut().for_each(|v| *v ^= x);
}
#[cfg(target_arch = "x86_64")]
mod stream_wide {
    #[target_feature(enable = "avx512f")]
    pub fn fold512(c: &[u32]) -> u32 {
        super::stream_fold(c)
    }
    #[target_feature(enable = "avx512f")]
    pub fn update512(c: &mut [u32], x: u32) {
        super::stream_update(c, x)
    }
    #[target_feature(enable = "avx2")]
    pub fn fold256(c: &[u32]) -> u32 {
        super::stream_fold(c)
    }
    #[target_feature(enable = "avx2")]
    pub fn update256(c: &mut [u32], x: u32) {
        super::stream_update(c, x)
    }
}

/// Seconds to stream arrays as a stage does, in one pass: each of `reads` (lengths in 32-bit
/// values) read once and xor-folded, each of `updates` read, xor-ed and written back in
/// place; in the current pool, fastest of 5, arrays allocated and touched before the
/// timing: the memory floor of a stage that reads and updates those arrays (e.g. one Adam
/// group: the gradient read; the parameter and its two moments updated). The pass is split
/// into tasks of 16 384 values of the longest array; task `c` takes the `c`-th share of
/// every array, all its arrays in turn (as the stage's loop has all its streams in flight),
/// each loop compiled for the widest vector unit the CPU has (the library's kernels are;
/// the bench's baseline build is SSE2 only, whose 16-byte operations do not reach the
/// cache's bandwidth).
pub fn stream_seconds(reads: &[usize], updates: &[usize]) -> f64 {
    use rayon::prelude::*;
    const CHUNK: usize = 1 << 14;
    // 2: AVX-512F, 1: AVX2, 0: neither (as the library's kernels choose, cap included).
    let isa = match unseen::raster::kernel::auto_isa_name() {
        "AVX-512F" => 2,
        "AVX2" => 1,
        _ => 0,
    };
    let fold_isa = |c: &[u32]| match isa {
        // SAFETY: the feature was detected above.
        #[cfg(target_arch = "x86_64")]
        2 => unsafe { stream_wide::fold512(c) },
        // SAFETY: as above.
        #[cfg(target_arch = "x86_64")]
        1 => unsafe { stream_wide::fold256(c) },
        _ => stream_fold(c),
    };
    let update_isa = |c: &mut [u32], x: u32| match isa {
        // SAFETY: the feature was detected above.
        #[cfg(target_arch = "x86_64")]
        2 => unsafe { stream_wide::update512(c, x) },
        // SAFETY: as above.
        #[cfg(target_arch = "x86_64")]
        1 => unsafe { stream_wide::update256(c, x) },
        _ => stream_update(c, x),
    };
    let src: Vec<Vec<u32>> = reads.iter().map(|&n| vec![1u32; n]).collect();
    let mut dst: Vec<Vec<u32>> = updates.iter().map(|&n| vec![1u32; n]).collect();
    let longest = reads.iter().chain(updates).copied().max().unwrap_or(0);
    let tasks = longest.div_ceil(CHUNK).max(1);
    let share = |n: usize, c: usize| c * n / tasks..(c + 1) * n / tasks;
    let mut t_best = f64::MAX;
    for _ in 0..5 {
        let t0 = Instant::now();
        // Each task's shares of the updated arrays, split up front (disjoint ranges).
        let mut parts: Vec<Vec<&mut [u32]>> = (0..tasks).map(|_| Vec::new()).collect();
        for d in dst.iter_mut() {
            let n = d.len();
            let mut rest: &mut [u32] = d;
            for (c, p) in parts.iter_mut().enumerate() {
                let len = share(n, c).len();
                let (head, tail) = std::mem::take(&mut rest).split_at_mut(len);
                p.push(head);
                rest = tail;
            }
        }
        parts.into_par_iter().enumerate().for_each(|(c, mut mine)| {
            let mut x = 1u32;
            for s in &src {
                x ^= fold_isa(&s[share(s.len(), c)]);
            }
            for d in mine.iter_mut() {
                update_isa(d, x);
            }
        });
        t_best = t_best.min(t0.elapsed().as_secs_f64());
        std::hint::black_box(&dst);
    }
    t_best
}

/// The bundled lounge at `1/resolution` of its size and a training configuration for it
/// that never ends and never saves (the benches time steps of it).
pub fn lounge(
    resolution: u32,
) -> (
    unseen::dataset::Dataset,
    unseen::train::trainer::TrainConfig,
) {
    use unseen::dataset::{LoadOptions, load};
    let root =
        std::path::Path::new(env!("CARGO_MANIFEST_DIR")).join("reference_data/scenes/lounge");
    let opts = LoadOptions {
        resolution,
        ..LoadOptions::default()
    };
    let cfg = unseen::train::trainer::TrainConfig {
        iterations: u32::MAX,
        resolution,
        save_iterations: vec![],
        ..Default::default()
    };
    (load(&root, &opts).unwrap(), cfg)
}

/// The number after `name` on the command line (`default` without it).
pub fn arg(name: &str, default: usize) -> usize {
    arg_text(name).map_or(default, |v| v.parse().expect("a number"))
}

/// The value after `name` on the command line, if given.
pub fn arg_text(name: &str) -> Option<String> {
    let args: Vec<String> = std::env::args().collect();
    args.iter()
        .position(|a| a == name)
        .and_then(|i| args.get(i + 1))
        .cloned()
}

/// The CPU's model name (from `/proc/cpuinfo` where there is one), its logical CPUs and the
/// widest instruction set the kernels use on it: what a figure's machine is named by.
pub fn machine() -> String {
    let model = std::fs::read_to_string("/proc/cpuinfo")
        .ok()
        .and_then(|s| {
            s.lines()
                .find(|l| l.starts_with("model name"))
                .and_then(|l| l.split(':').nth(1))
                .map(|m| m.trim().to_string())
        })
        .unwrap_or_else(|| "unknown CPU".into());
    let isa = unseen::raster::kernel::auto_isa_name();
    let capped = std::env::var(unseen::raster::kernel::MAX_ISA_VAR)
        .ok()
        .filter(|v| !v.is_empty())
        .map_or(String::new(), |v| {
            format!(" (capped by {}={v})", unseen::raster::kernel::MAX_ISA_VAR)
        });
    let cpus = std::thread::available_parallelism().map_or(1, |n| n.get());
    format!("{model}, {cpus} logical CPUs, {isa}{capped}")
}

/// Bare blend kernels written outside the project (`--external DIR`): every C file of `DIR`
/// that prints lines `threads=N <name>_Gpairs_per_s=X` (one pixel × one splat a pair; a
/// name with `backward` in it is a backward kernel), compiled here and run once per pool
/// size. The floors of a roofline are then the best of the crate's bare kernels and these.
///
/// Compiled with `cc -O3 -march=native -mno-fma -ffp-contract=off -fopenmp`: the crate's
/// arithmetic (SPEC.md §5.4) has no fused multiply-add, and GCC contracts `a·b + c` into one
/// by default for C (`-ffp-contract=fast`) wherever the target has an FMA — which AVX-512F
/// has at 512 bits whatever `-mno-fma` says (that flag removes only the 128/256-bit FMA3
/// extension). A kernel contracted so does other arithmetic than the crate's (fewer
/// roundings, other bits) in fewer instructions: measured on an Intel Xeon with AVX-512F,
/// 1.7 G pairs/s on one thread contracted against 1.1 not, the crate's bare kernel 1.25.
/// With `UNSEEN_MAX_ISA=avx2` the files are built with `-mno-avx512f` (the AVX-512 ones then
/// fail to build and are skipped), so that a capped crate meets floors of its own ISA.
pub struct External {
    /// `(file, threads, pairs per second)` of the forward and backward kernels.
    pub forward: Vec<(String, usize, f64)>,
    pub backward: Vec<(String, usize, f64)>,
    /// Files skipped, with why.
    pub skipped: Vec<String>,
}

impl External {
    /// Build and run every C file of `dir`, each with `OMP_NUM_THREADS` = `threads` (it
    /// reports one thread and that many).
    pub fn run(dir: &std::path::Path, threads: usize) -> External {
        let mut ext = External {
            forward: Vec::new(),
            backward: Vec::new(),
            skipped: Vec::new(),
        };
        let mut files: Vec<_> = std::fs::read_dir(dir)
            .unwrap_or_else(|e| panic!("--external {}: {e}", dir.display()))
            .filter_map(|e| e.ok().map(|e| e.path()))
            .filter(|p| p.extension().is_some_and(|x| x == "c"))
            .collect();
        files.sort();
        let capped = std::env::var("UNSEEN_MAX_ISA").is_ok_and(|v| v == "avx2");
        let build = std::env::temp_dir().join(format!("unseen-external-{}", std::process::id()));
        std::fs::create_dir_all(&build).unwrap();
        for file in files {
            let name = file.file_name().unwrap().to_string_lossy().to_string();
            let exe = build.join(name.trim_end_matches(".c"));
            let cc = std::env::var("CC").unwrap_or_else(|_| "cc".into());
            let mut cmd = std::process::Command::new(&cc);
            cmd.args([
                "-O3",
                "-march=native",
                "-mno-fma",
                "-ffp-contract=off",
                "-fopenmp",
            ]);
            if capped {
                cmd.arg("-mno-avx512f");
            }
            let built = cmd.arg(&file).arg("-o").arg(&exe).arg("-lm").output();
            match built {
                Ok(o) if o.status.success() => {}
                Ok(o) => {
                    let why = String::from_utf8_lossy(&o.stderr);
                    let first = why.lines().find(|l| l.contains("error")).unwrap_or("");
                    ext.skipped
                        .push(format!("{name}: does not build ({first})"));
                    continue;
                }
                Err(e) => {
                    ext.skipped.push(format!("{name}: {cc}: {e}"));
                    continue;
                }
            }
            let out = std::process::Command::new(&exe)
                .env("OMP_NUM_THREADS", threads.to_string())
                .output();
            let text = match out {
                Ok(o) if o.status.success() => String::from_utf8_lossy(&o.stdout).to_string(),
                _ => {
                    ext.skipped.push(format!("{name}: does not run"));
                    continue;
                }
            };
            for line in text.lines() {
                let mut n = None;
                let mut rate = None;
                let mut backward = false;
                for field in line.split_whitespace() {
                    if let Some(v) = field.strip_prefix("threads=") {
                        n = v.parse::<usize>().ok();
                    } else if let Some((key, v)) = field.split_once("_Gpairs_per_s=") {
                        backward = key.contains("backward");
                        rate = v.parse::<f64>().ok().map(|g| g * 1e9);
                    }
                }
                if let (Some(n), Some(r)) = (n, rate) {
                    let to = if backward {
                        &mut ext.backward
                    } else {
                        &mut ext.forward
                    };
                    to.push((name.clone(), n, r));
                }
            }
        }
        let _ = std::fs::remove_dir_all(&build);
        ext
    }

    /// The fastest kernel of `kind` at `threads`: `(file, pairs per second)`.
    pub fn best(kind: &[(String, usize, f64)], threads: usize) -> Option<(&str, f64)> {
        kind.iter()
            .filter(|k| k.1 == threads)
            .max_by(|a, b| a.2.total_cmp(&b.2))
            .map(|k| (k.0.as_str(), k.2))
    }
}
