//! `unseen oracle`: every intermediate and gradient of one render as `.npy` files plus a
//! `manifest.json`, so a GPU port can be diffed against this crate array by array.
//! The file list is in SPEC.md §12.

use crate::camera::Camera;
use crate::error::Result;
use crate::gaussian::Gaussians;
use crate::io::manifest::{FileEntry, Manifest};
use crate::io::npy::{NpyElement, write_npy};
use crate::raster::backward::{GradGroups, ImageGrads, backward, render_for_backward};
use crate::raster::{Outputs, RenderOptions};
use crate::train::loss::{LossInput, LossWeights, image_loss};
use std::path::Path;

/// Image losses the oracle can differentiate.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum Loss {
    /// Mean absolute difference over all pixels and channels.
    L1,
    /// Mean squared difference over all pixels and channels.
    L2,
    /// INRIA's `0.8·L1 + 0.2·(1 − SSIM)` ([`LossWeights::INRIA`]).
    L1DSsim,
}

struct Writer<'a> {
    dir: &'a Path,
    entries: Vec<FileEntry>,
}

impl Writer<'_> {
    fn put<T: NpyElement>(&mut self, name: &str, data: &[T], shape: &[usize]) -> Result<()> {
        let file = format!("{name}.npy");
        let bytes = write_npy(&self.dir.join(&file), data, shape)?;
        self.entries.push(FileEntry {
            name: Some(name.to_string()),
            shape: Some(shape.to_vec()),
            dtype: Some(T::DTYPE.descr().to_string()),
            ..FileEntry::new(file, &bytes)
        });
        Ok(())
    }
}

fn flat<const N: usize>(v: &[[f32; N]]) -> Vec<f32> {
    v.iter().flatten().copied().collect()
}

/// Optional loss targets for the backward dump.
pub struct Targets<'a> {
    /// RGB target in [0, 1], interleaved, the camera's size.
    pub rgb: &'a [f32],
    pub loss: Loss,
    /// Accumulated-depth target (adds the mean |D − D_target| over finite, positive target
    /// pixels).
    pub depth: Option<&'a [f32]>,
}

/// Render, optionally differentiate, and dump everything into `dir`.
pub fn dump(
    scene: &Gaussians,
    cam: &Camera,
    opts: &RenderOptions,
    targets: Option<&Targets>,
    dir: &Path,
) -> Result<()> {
    crate::io::create_dir_all(dir)?;
    let opts = RenderOptions {
        outputs: Outputs::ALL,
        ..opts.clone()
    };
    let fwd = render_for_backward(scene, cam, &opts)?;
    let (w, h) = (cam.width as usize, cam.height as usize);
    let n = scene.len();
    let mut wr = Writer {
        dir,
        entries: Vec::new(),
    };
    let p = &fwd.projected;
    wr.put(
        "means2d",
        &p.splats.iter().flat_map(|s| s.mean).collect::<Vec<f32>>(),
        &[n, 2],
    )?;
    wr.put(
        "conics",
        &p.splats.iter().flat_map(|s| s.conic).collect::<Vec<f32>>(),
        &[n, 3],
    )?;
    wr.put(
        "depths",
        &p.splats.iter().map(|s| s.depth).collect::<Vec<f32>>(),
        &[n],
    )?;
    wr.put(
        "opacities",
        &p.splats.iter().map(|s| s.opacity).collect::<Vec<f32>>(),
        &[n],
    )?;
    wr.put(
        "colors",
        &p.splats.iter().flat_map(|s| s.color).collect::<Vec<f32>>(),
        &[n, 3],
    )?;
    wr.put(
        "radii",
        &p.radii.iter().flatten().copied().collect::<Vec<i32>>(),
        &[n, 2],
    )?;
    let offsets: Vec<u64> = fwd.bins.offsets.iter().map(|&o| o as u64).collect();
    wr.put("tile_offsets", &offsets, &[offsets.len()])?;
    wr.put("tile_ids", &fwd.bins.ids, &[fwd.bins.ids.len()])?;
    let r = &fwd.render;
    let img = |v: &Option<Vec<f32>>| v.clone().unwrap_or_default();
    wr.put("rgb", &img(&r.rgb), &[h, w, 3])?;
    wr.put("alpha", &img(&r.alpha), &[h, w])?;
    wr.put("depth", &img(&r.depth), &[h, w])?;
    wr.put("expected_depth", &img(&r.expected_depth), &[h, w])?;
    wr.put("final_t", &img(&r.final_t), &[h, w])?;
    wr.put(
        "n_contrib",
        r.n_contrib.as_deref().unwrap_or_default(),
        &[h, w],
    )?;
    let command = if let Some(t) = targets {
        let rgb = r.rgb.as_ref().expect("rgb requested");
        let weights = match t.loss {
            Loss::L1 => LossWeights::L1,
            Loss::L2 => LossWeights::L2,
            Loss::L1DSsim => LossWeights::INRIA,
        };
        let out = image_loss(
            &LossInput {
                width: w,
                height: h,
                rgb,
                target_rgb: t.rgb,
                depth: t.depth.and(r.depth.as_deref()),
                target_depth: t.depth,
                mask: None,
            },
            &LossWeights {
                depth: 1.0,
                ..weights
            },
        )?;
        let loss = out.terms.total;
        let v = ImageGrads {
            rgb: Some(out.grad_rgb),
            depth: out.grad_depth,
            ..Default::default()
        };
        let (g, _) = backward(scene, cam, &opts, &fwd, &v, &GradGroups::ALL)?;
        let k1 = scene.rest_per_channel();
        wr.put("loss", &[loss as f32], &[])?;
        wr.put("v_rgb", v.rgb.as_deref().unwrap_or_default(), &[h, w, 3])?;
        if let Some(vd) = &v.depth {
            wr.put("v_depth", vd, &[h, w])?;
        }
        wr.put("grad_means", &flat(&g.means), &[n, 3])?;
        wr.put("grad_log_scales", &flat(&g.log_scales), &[n, 3])?;
        wr.put("grad_quats", &flat(&g.quats), &[n, 4])?;
        wr.put("grad_opacity_logits", &g.opacity_logits, &[n])?;
        wr.put("grad_sh_dc", &flat(&g.sh_dc), &[n, 3])?;
        wr.put("grad_sh_rest", &g.sh_rest, &[n, k1, 3])?;
        wr.put("grad_background", &g.background, &[3])?;
        wr.put("grad_means2d", &flat(&g.means2d), &[n, 2])?;
        wr.put("grad_means2d_ndc", &flat(&g.means2d_ndc), &[n, 2])?;
        "backward"
    } else {
        "forward"
    };
    let inputs = serde_json::json!({
        "camera": cam.name,
        "width": cam.width,
        "height": cam.height,
        "gaussians": n,
        "sh_degree": scene.sh_degree,
        "background": opts.background,
        "conventions": opts.conventions.name(),
    });
    let manifest = Manifest {
        conventions: Some(opts.conventions.name().to_string()),
        ..Manifest::new(&format!("oracle {command}"), "", inputs, wr.entries)
    };
    manifest.write(dir)?;
    Ok(())
}

/// `unseen oracle adam`: Adam from zero moments on `x0` over `grads` (`steps` rows of
/// `x0.len()` values) under `constants` ([`crate::train::adam::adam_trace`]), every step's
/// `params`, `exp_avg` and `exp_avg_sq` as `(S, N)` arrays in `dir` (SPEC.md §12, §14.2).
pub fn dump_adam(
    x0: &[f32],
    grads: &[f32],
    (betas, eps, lr): ([f64; 2], f32, f64),
    constants: crate::train::adam::Constants,
    dir: &Path,
) -> Result<()> {
    let trace = crate::train::adam::adam_trace(betas, eps, lr, constants, x0, grads)?;
    crate::io::create_dir_all(dir)?;
    let (n, steps) = (x0.len(), grads.len() / x0.len());
    let mut wr = Writer {
        dir,
        entries: Vec::new(),
    };
    wr.put("params", &trace.x, &[steps, n])?;
    wr.put("exp_avg", &trace.m, &[steps, n])?;
    wr.put("exp_avg_sq", &trace.v, &[steps, n])?;
    let inputs = serde_json::json!({
        "parameters": n,
        "steps": steps,
        "lr": lr,
        "betas": betas,
        "eps": eps,
        "constants": constants.name(),
    });
    let manifest = Manifest::new("oracle adam", "", inputs, wr.entries);
    manifest.write(dir)?;
    Ok(())
}

/// `unseen oracle inpaint`: Telea inpainting of `image` (`width × height × channels`) where
/// `mask` is true, traced ([`crate::models::telea::inpaint_traced`], with a port's output
/// as `forced` when given): `image`, `time`, `order`, `mean`, `term`, `bound` and `aside`
/// as .npy in `dir` (SPEC.md §12, §19.1).
pub fn dump_inpaint<T: crate::models::telea::Sample + NpyElement>(
    image: &[T],
    (width, height, channels): (usize, usize, usize),
    mask: &[bool],
    radius: f64,
    forced: Option<&[T]>,
    dir: &Path,
) -> Result<()> {
    let trace =
        crate::models::telea::inpaint_traced(image, width, height, channels, mask, radius, forced)?;
    crate::io::create_dir_all(dir)?;
    let mut wr = Writer {
        dir,
        entries: Vec::new(),
    };
    let (pixels, values) = ([height, width], [height, width, channels]);
    wr.put("image", &trace.image, &values)?;
    wr.put("time", &trace.time, &pixels)?;
    wr.put("order", &trace.order, &pixels)?;
    wr.put("mean", &trace.mean, &values)?;
    wr.put("term", &trace.term, &values)?;
    wr.put("bound", &trace.bound, &values)?;
    wr.put("aside", &trace.aside, &values)?;
    let inputs = serde_json::json!({
        "width": width,
        "height": height,
        "channels": channels,
        "dtype": T::DTYPE.descr(),
        "radius": radius,
        "fill": mask.iter().filter(|&&m| m).count(),
        "forced": forced.is_some(),
    });
    Manifest::new("oracle inpaint", "", inputs, wr.entries).write(dir)?;
    Ok(())
}

/// `unseen oracle warp`: the traced DIBR warp ([`crate::warp::dibr::warp_traced`]):
/// `image` (h, w, C), `depth` (h, w), `holes` and `aside` (u1, (h, w)), and per source
/// pixel `u`, `v` (f8) and `z` (f4), as .npy in `dir` (SPEC.md §12, §18).
pub fn dump_warp(
    image: &crate::io::image::ImageF32,
    depth: &[f32],
    from: &Camera,
    to: &Camera,
    opts: &crate::warp::dibr::WarpOptions,
    dir: &Path,
) -> Result<()> {
    let t = crate::warp::dibr::warp_traced(image, depth, from, to, opts)?;
    crate::io::create_dir_all(dir)?;
    let mut wr = Writer {
        dir,
        entries: Vec::new(),
    };
    let (tw, th) = (to.width as usize, to.height as usize);
    let (sw, sh) = (from.width as usize, from.height as usize);
    wr.put("image", &t.warped.image.data, &[th, tw, image.channels])?;
    wr.put("depth", &t.warped.depth, &[th, tw])?;
    let holes: Vec<u8> = t.warped.holes.iter().map(|&h| h as u8).collect();
    wr.put("holes", &holes, &[th, tw])?;
    wr.put("aside", &t.aside, &[th, tw])?;
    wr.put("u", &t.u, &[sh, sw])?;
    wr.put("v", &t.v, &[sh, sw])?;
    wr.put("z", &t.z, &[sh, sw])?;
    let inputs = serde_json::json!({
        "from": from.name,
        "to": to.name,
        "options": opts,
        "stats": t.warped.stats,
    });
    Manifest::new("oracle warp", "", inputs, wr.entries).write(dir)?;
    Ok(())
}

/// `unseen oracle densify`: one densify-and-prune step of `g` with the given statistics,
/// `extent`, large-Gaussian test and split draws ([`crate::train::densify::Normals::Given`]):
/// the new scene's `means`, `quats` (wxyz), `scales` (log), `opacities` (logits) and `sh`
/// `(N, K, 3)` as .npy in `dir`, the counts in the manifest (SPEC.md §8.2, §14.3).
pub fn dump_densify(
    mut g: Gaussians,
    (grad_accum, count): (Vec<f32>, Vec<u32>),
    extent: f32,
    world_prune: bool,
    normals: &[[f32; 3]],
    dir: &Path,
) -> Result<()> {
    use crate::train::densify::{DensifyConfig, densify_given};
    let n = g.len();
    let cfg = DensifyConfig::default();
    let report = densify_given(
        &mut g,
        (grad_accum, count),
        &cfg,
        extent,
        world_prune,
        normals,
    )?;
    crate::io::create_dir_all(dir)?;
    let mut wr = Writer {
        dir,
        entries: Vec::new(),
    };
    let m = g.len();
    let k = g.rest_per_channel() + 1;
    wr.put("means", &flat(&g.means), &[m, 3])?;
    wr.put("quats", &flat(&g.quats), &[m, 4])?;
    wr.put("scales", &flat(&g.log_scales), &[m, 3])?;
    wr.put("opacities", &g.opacity_logits, &[m])?;
    let sh: Vec<f32> = (0..m)
        .flat_map(|i| {
            g.sh_dc[i]
                .iter()
                .chain(g.rest(i))
                .copied()
                .collect::<Vec<_>>()
        })
        .collect();
    wr.put("sh", &sh, &[m, k, 3])?;
    let inputs = serde_json::json!({
        "gaussians": n,
        "extent": extent,
        "world_prune": world_prune,
        "config": cfg,
        "report": report,
    });
    Manifest::new("oracle densify", "", inputs, wr.entries).write(dir)?;
    Ok(())
}

/// `unseen oracle align`: the alignment `s·r + t ≈ m` of `estimate` to `depth` (RANSAC with
/// `ransac`, else least squares; SPEC.md §17) and per pixel what a port's fit is judged by:
/// `residual` (f4, `|s·r + t − m| / |m|`, NaN where the pixel is not valid) and `inlier`
/// (u1, within the RANSAC threshold); the fit in the manifest.
pub fn dump_align(
    estimate: &[f32],
    depth: &[f32],
    shape: &[usize],
    space: crate::warp::align::Space,
    ransac: Option<&crate::warp::align::RansacConfig>,
    dir: &Path,
) -> Result<()> {
    use crate::warp::align::{Frame, Space, least_squares, ransac as fit_ransac};
    let frames = [Frame { estimate, depth }];
    let fit = match ransac {
        Some(cfg) => fit_ransac(&frames, space, cfg)?,
        None => least_squares(&frames, space)?,
    };
    let threshold = ransac.map_or(f64::INFINITY, |c| c.threshold);
    let (residual, inlier): (Vec<f32>, Vec<u8>) = estimate
        .iter()
        .zip(depth)
        .map(|(&r, &d)| {
            if !(r.is_finite() && d.is_finite() && d > 0.0) {
                return (f32::NAN, 0);
            }
            let m = match space {
                Space::Depth => d as f64,
                Space::Disparity => 1.0 / d as f64,
            };
            let rel = (fit.scale * r as f64 + fit.offset - m).abs() / m.abs();
            (rel as f32, (rel <= threshold) as u8)
        })
        .unzip();
    crate::io::create_dir_all(dir)?;
    let mut wr = Writer {
        dir,
        entries: Vec::new(),
    };
    wr.put("residual", &residual, shape)?;
    wr.put("inlier", &inlier, shape)?;
    let inputs = serde_json::json!({
        "space": space.name(),
        "method": if ransac.is_some() { "ransac" } else { "least_squares" },
        "ransac": ransac,
        "fit": fit,
    });
    Manifest::new("oracle align", "", inputs, wr.entries).write(dir)?;
    Ok(())
}

/// `unseen oracle qa-mask`: the QA-Mask of a (fine-tuned) mask scene for `cam`
/// ([`crate::qamask::render_qa_mask`]) as `mask.npy` `(H, W)`, and the rendered colour it
/// projects as `rgb.npy` `(H, W, 3)` (SPEC.md §15.1).
pub fn dump_qa_mask(
    scene: &Gaussians,
    cam: &Camera,
    cfg: &crate::qamask::QaMaskConfig,
    dir: &Path,
) -> Result<()> {
    cfg.validate()?;
    let mask = crate::qamask::render_qa_mask(scene, cam, cfg)?;
    let opts = RenderOptions {
        background: cfg.base_color,
        ..RenderOptions::default()
    };
    let rgb = crate::raster::render(scene, cam, &opts)?
        .rgb
        .expect("the default outputs hold rgb");
    crate::io::create_dir_all(dir)?;
    let mut wr = Writer {
        dir,
        entries: Vec::new(),
    };
    let (w, h) = (cam.width as usize, cam.height as usize);
    wr.put("mask", &mask, &[h, w])?;
    wr.put("rgb", &rgb, &[h, w, 3])?;
    let inputs = serde_json::json!({
        "camera": cam.name,
        "gaussians": scene.len(),
        "sh_degree": scene.sh_degree,
        "base": cfg.base_color,
        "target": cfg.target_color,
    });
    Manifest::new("oracle qa-mask", "", inputs, wr.entries).write(dir)?;
    Ok(())
}

/// `unseen oracle collide`: GJK's proximity of two convex hulls (SPEC.md §16.1) as .npy
/// scalars: `distance`, `lower_bound` and `touch_eps` (f8), `intersect` (u1) and
/// `iterations` (u4). A port's verdict is judged against `intersect` unless
/// `lower_bound` lies within the contact band of `touch_eps`
/// (`unseen.testing.compare_collide`).
pub fn dump_collide(
    a: &crate::collide::gjk::ConvexHull,
    b: &crate::collide::gjk::ConvexHull,
    dir: &Path,
) -> Result<()> {
    let p = crate::collide::gjk::proximity(a, b)?;
    crate::io::create_dir_all(dir)?;
    let mut wr = Writer {
        dir,
        entries: Vec::new(),
    };
    wr.put("distance", &[p.distance], &[])?;
    wr.put("lower_bound", &[p.lower_bound], &[])?;
    wr.put("touch_eps", &[p.touch_eps], &[])?;
    wr.put("intersect", &[u8::from(p.intersect)], &[])?;
    wr.put("iterations", &[p.iterations as u32], &[])?;
    let inputs = serde_json::json!({
        "vertices": [a.vertices.len(), b.vertices.len()],
    });
    Manifest::new("oracle collide", "", inputs, wr.entries).write(dir)?;
    Ok(())
}

/// `unseen oracle views`: independent-view detection on regions given as masks and depth
/// ranges (SPEC.md §16.2–16.3), array by array: the frustums' vertices in world
/// coordinates, all views' together (`vertices` (ΣV, 3) f8; view `k`'s are rows
/// `offsets[k]..offsets[k + 1]`, `offsets` (n + 1,) u4), `ranges` (n, 2) f8, every pair's
/// GJK `distance` and `lower_bound` (n, n) f8 (0 on the diagonal), `collisions` (n, n) u1,
/// and the `independent` views in greedy order and their `trajectory` (k,) u4.
pub fn dump_views(
    cams: &[&Camera],
    masks: &[Vec<bool>],
    ranges: &[[f64; 2]],
    outline: crate::collide::frustum::Outline,
    dir: &Path,
) -> Result<()> {
    use crate::collide::gjk::proximity;
    use crate::collide::independent::select_regions;
    let (polys, sel) = select_regions(cams, masks, ranges, outline, None)?;
    let n = polys.len();
    let hulls = polys.iter().map(|p| p.hull()).collect::<Result<Vec<_>>>()?;
    let (mut distance, mut lower) = (vec![0f64; n * n], vec![0f64; n * n]);
    let mut collisions = vec![0u8; n * n];
    for i in 0..n {
        for j in i + 1..n {
            let p = proximity(&hulls[i], &hulls[j])?;
            for (a, b) in [(i, j), (j, i)] {
                distance[a * n + b] = p.distance;
                lower[a * n + b] = p.lower_bound;
            }
        }
    }
    for &(i, j) in &sel.edges {
        collisions[i * n + j] = 1;
        collisions[j * n + i] = 1;
    }
    let mut offsets = vec![0u32];
    let mut vertices = Vec::new();
    for p in &polys {
        vertices.extend(p.vertices.iter().flat_map(|v| [v.x, v.y, v.z]));
        offsets.push((vertices.len() / 3) as u32);
    }
    let index = |v: &[usize]| v.iter().map(|&i| i as u32).collect::<Vec<u32>>();
    crate::io::create_dir_all(dir)?;
    let mut wr = Writer {
        dir,
        entries: Vec::new(),
    };
    wr.put("vertices", &vertices, &[vertices.len() / 3, 3])?;
    wr.put("offsets", &offsets, &[n + 1])?;
    let flat_ranges: Vec<f64> = ranges.iter().flatten().copied().collect();
    wr.put("ranges", &flat_ranges, &[n, 2])?;
    wr.put("distance", &distance, &[n, n])?;
    wr.put("lower_bound", &lower, &[n, n])?;
    wr.put("collisions", &collisions, &[n, n])?;
    wr.put(
        "independent",
        &index(&sel.independent),
        &[sel.independent.len()],
    )?;
    wr.put(
        "trajectory",
        &index(&sel.trajectory),
        &[sel.trajectory.len()],
    )?;
    let inputs = serde_json::json!({
        "cameras": cams.iter().map(|c| c.name.as_str()).collect::<Vec<_>>(),
        "outline": outline.name(),
    });
    Manifest::new("oracle views", "", inputs, wr.entries).write(dir)?;
    Ok(())
}
