//! Adaptive density control as INRIA 3DGS does it (SPEC.md §14.3): gradient statistics,
//! clone, split, prune, opacity reset.
//!
//! Per densification step, in INRIA's order (`densify_and_prune`):
//! 1. `g = accum / count` per Gaussian (0 where it was never visible);
//! 2. **clone** every Gaussian with `g ≥ grad_threshold` and `max scale ≤ percent_dense ·
//!    extent` (copies appended in index order);
//! 3. **split** every original Gaussian with `g ≥ grad_threshold` and `max scale >
//!    percent_dense · extent` into 2: for copy `k` of the selected block (block-major like
//!    `repeat(N, 1)`, copy by copy), `mean = R·(s ⊙ z) + mean` with `z ~ N(0, I)`, `scale = s / 1.6`,
//!    other parameters copied; the originals are removed;
//! 4. **prune** `opacity < min_opacity`, and when the world-space test is on (after the
//!    first opacity reset) `max scale > 0.1 · extent`; a screen-space test (`max radius >
//!    max_screen_size_px`) exists but is off by default because INRIA's code resets the
//!    radii before testing them (graphdeco-inria/gaussian-splatting#123), so its published
//!    results were made without it.
//!
//! New Gaussians get zero Adam moments; survivors keep theirs. The random draws come from
//! the trainer's seeded generator in the children's order — copy, then Gaussian, then
//! axis — or, to compare a port, are given ([`Normals`]).

use crate::error::Result;
use crate::gaussian::Gaussians;
use crate::math::fastexp::{exp, ln, sigmoid};
use crate::raster::backward::composite::SplatGrad;
use crate::raster::backward::project::mean2d_ndc;
use crate::raster::project::quat_to_rotmat;
use crate::rng::Uniform;
use crate::train::adam::Adam;
use rayon::prelude::*;

/// Densification constants (INRIA `OptimizationParams` defaults).
#[derive(Clone, Copy, Debug, PartialEq, serde::Serialize, serde::Deserialize)]
#[serde(default)]
pub struct DensifyConfig {
    /// First iteration after which densification runs (exclusive, as INRIA).
    pub from_iter: u32,
    /// Last iteration (exclusive) at which statistics are gathered and densification runs.
    pub until_iter: u32,
    pub interval: u32,
    pub grad_threshold: f32,
    pub percent_dense: f32,
    pub min_opacity: f32,
    pub opacity_reset_interval: u32,
    /// Opacity after a reset (`min(σ(o), value)`).
    pub opacity_reset_value: f32,
    /// World-space pruning: `max scale > world_prune_fraction · extent`.
    pub world_prune_fraction: f32,
    /// Screen-space pruning in pixels; `None` = INRIA's effective behaviour (off).
    pub max_screen_size_px: Option<f32>,
    /// The first this many Gaussians are neither cloned, split nor pruned (they stay first,
    /// in order): a fine-tune limited to the Gaussians it added (SPEC.md §20.5). 0, and left
    /// out of a written configuration, by default.
    #[serde(skip_serializing_if = "is_zero")]
    pub protected: usize,
}

fn is_zero(n: &usize) -> bool {
    *n == 0
}

impl Default for DensifyConfig {
    fn default() -> Self {
        DensifyConfig {
            from_iter: 500,
            until_iter: 15_000,
            interval: 100,
            grad_threshold: 2e-4,
            percent_dense: 0.01,
            min_opacity: 0.005,
            opacity_reset_interval: 3000,
            opacity_reset_value: 0.01,
            world_prune_fraction: 0.1,
            max_screen_size_px: None,
            protected: 0,
        }
    }
}

/// Per-Gaussian statistics gathered between densification steps.
#[derive(Clone, Debug, Default, PartialEq)]
pub struct DensifyStats {
    /// Sum over views where the Gaussian was visible of `|dL/d mean2d|` in INRIA's NDC units.
    pub grad_accum: Vec<f32>,
    pub count: Vec<u32>,
    /// Largest pixel radius seen.
    pub max_radius: Vec<f32>,
}

impl DensifyStats {
    pub fn new(n: usize) -> Self {
        DensifyStats {
            grad_accum: vec![0.0; n],
            count: vec![0; n],
            max_radius: vec![0.0; n],
        }
    }

    /// Add one view: `means2d_ndc` from the backward, `radii` from the projection (a
    /// Gaussian is visible when its radius is positive, INRIA's `visibility_filter`).
    pub fn add_view(&mut self, means2d_ndc: &[[f32; 2]], radii: &[[i32; 2]]) {
        assert_eq!(means2d_ndc.len(), self.count.len());
        assert_eq!(radii.len(), self.count.len());
        // Element-wise: fixed chunks in parallel (every iteration, over every Gaussian).
        const CHUNK: usize = 8192;
        self.grad_accum
            .par_chunks_mut(CHUNK)
            .zip(self.count.par_chunks_mut(CHUNK))
            .zip(self.max_radius.par_chunks_mut(CHUNK))
            .zip(means2d_ndc.par_chunks(CHUNK).zip(radii.par_chunks(CHUNK)))
            .for_each(|(((acc, count), max_r), (m2d, radii))| {
                for i in 0..acc.len() {
                    add_one(&mut acc[i], &mut count[i], &mut max_r[i], m2d[i], radii[i]);
                }
            });
    }

    /// The statistics in chunks of `chunk` Gaussians (the last may be shorter), to be
    /// added to chunk by chunk ([`StatsChunk::add_view`]).
    pub(crate) fn chunks_mut(&mut self, chunk: usize) -> Vec<StatsChunk<'_>> {
        self.grad_accum
            .chunks_mut(chunk)
            .zip(self.count.chunks_mut(chunk))
            .zip(self.max_radius.chunks_mut(chunk))
            .map(|((grad_accum, count), max_radius)| StatsChunk {
                grad_accum,
                count,
                max_radius,
            })
            .collect()
    }
}

/// One Gaussian's statistics after one view: the single definition of what a view adds.
#[inline(always)]
fn add_one(acc: &mut f32, count: &mut u32, max_r: &mut f32, ndc: [f32; 2], radii: [i32; 2]) {
    let r = radii[0].max(radii[1]);
    if r > 0 {
        let [gx, gy] = ndc;
        *acc += (gx * gx + gy * gy).sqrt();
        *count += 1;
        *max_r = max_r.max(r as f32);
    }
}

/// A chunk of [`DensifyStats`] ([`DensifyStats::chunks_mut`]), added to where the projection
/// backward hands over the chunk's gradients: the same additions as
/// [`DensifyStats::add_view`], without a pass of their own.
pub(crate) struct StatsChunk<'a> {
    grad_accum: &'a mut [f32],
    count: &'a mut [u32],
    max_radius: &'a mut [f32],
}

impl StatsChunk<'_> {
    /// Add one view from the chunk's splat gradients (screen-space means in pixels, as
    /// [`crate::raster::backward::project::mean2d_ndc`] converts them for
    /// [`DensifyStats::add_view`]) and radii, on a `width × height` camera.
    pub(crate) fn add_view(&mut self, splats: &[SplatGrad], radii: &[[i32; 2]], size: [u32; 2]) {
        assert!(splats.len() == self.count.len() && radii.len() == self.count.len());
        for i in 0..self.count.len() {
            add_one(
                &mut self.grad_accum[i],
                &mut self.count[i],
                &mut self.max_radius[i],
                mean2d_ndc(splats[i].mean2d, size[0], size[1]),
                radii[i],
            );
        }
    }
}

/// What one densification step did.
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq, serde::Serialize)]
pub struct DensifyReport {
    pub cloned: usize,
    pub split: usize,
    pub pruned: usize,
    pub before: usize,
    pub after: usize,
}

/// Where the split children's normal draws `z` come from.
pub enum Normals<'a> {
    /// The trainer's generator, drawn in the children's order (copy, Gaussian, axis).
    Rng(&'a mut Uniform),
    /// Given for every copy and Gaussian of the scene before the step: copy `c` of
    /// Gaussian `i` takes `given[c·n + i]` (`n` Gaussians), whether or not it splits.
    Given(&'a [[f32; 3]]),
}

fn max_scale(ls: [f32; 3]) -> f32 {
    exp(ls[0].max(ls[1]).max(ls[2]))
}

/// Where a Gaussian after a densify step comes from: the Gaussian it was before the step,
/// or the Gaussian a new copy or split child was made from (new Gaussians start with zero
/// optimizer moments). Per-Gaussian bookkeeping beside training (a lineage, an attribution)
/// follows the Gaussians through it.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum Origin {
    Kept(u32),
    New(u32),
}

impl Origin {
    /// The index before the step that the Gaussian is, or was made from.
    pub fn source(self) -> usize {
        match self {
            Origin::Kept(i) | Origin::New(i) => i as usize,
        }
    }
}

/// One densify-and-prune step on `g` (and the optimizer moments), resetting `stats`.
/// `origins`, when given, receives every surviving Gaussian's [`Origin`] in the new order.
#[allow(clippy::too_many_arguments)]
pub fn densify_and_prune(
    g: &mut Gaussians,
    adam: &mut Adam,
    stats: &mut DensifyStats,
    cfg: &DensifyConfig,
    extent: f32,
    world_prune: bool,
    mut normals: Normals<'_>,
    origins: Option<&mut Vec<Origin>>,
) -> Result<DensifyReport> {
    let n0 = g.len();
    if let Normals::Given(z) = &normals
        && z.len() != 2 * n0
    {
        return Err(crate::error::Error::invalid(format!(
            "{} normal draws given for {n0} Gaussians (2 per Gaussian)",
            z.len()
        )));
    }
    let mut report = DensifyReport {
        before: n0,
        ..Default::default()
    };
    // The per-Gaussian passes run in parallel; every collect keeps index order.
    let grads: Vec<f32> = (0..n0)
        .into_par_iter()
        .map(|i| {
            if stats.count[i] == 0 {
                0.0
            } else {
                stats.grad_accum[i] / stats.count[i] as f32
            }
        })
        .collect();
    let dense = cfg.percent_dense * extent;
    let hot = |i: usize| i >= cfg.protected && grads[i] >= cfg.grad_threshold;
    let clone: Vec<usize> = (0..n0)
        .into_par_iter()
        .filter(|&i| hot(i) && max_scale(g.log_scales[i]) <= dense)
        .collect();
    let split: Vec<usize> = (0..n0)
        .into_par_iter()
        .filter(|&i| hot(i) && max_scale(g.log_scales[i]) > dense)
        .collect();
    report.cloned = clone.len();
    report.split = split.len();
    // Radii carried along for the optional screen-space test: copies inherit theirs.
    let mut radius = stats.max_radius.clone();

    // Clone: plain copies. Split: 2 samples per selected Gaussian, block-major. Both go
    // after the scene (`extra`); the result is selected from the two at once.
    let mut extra = g.select(&clone);
    radius.extend(clone.iter().map(|&i| stats.max_radius[i]));
    let mut parts = g.select(&split);
    parts.append(&g.select(&split));
    let k = split.len();
    let shrink = ln(0.8 * 2.0);
    for c in 0..2 * k {
        let src = split[c % k];
        let s = g.log_scales[src].map(exp);
        let q = g.quats[src];
        let qn = (q[0] * q[0] + q[1] * q[1] + q[2] * q[2] + q[3] * q[3]).sqrt();
        let r = quat_to_rotmat(q.map(|v| v / qn));
        let z = match &mut normals {
            Normals::Rng(rng) => [0; 3].map(|_| rng.normal()),
            Normals::Given(z) => z[(c / k) * n0 + src],
        };
        let local = [s[0] * z[0], s[1] * z[1], s[2] * z[2]];
        let m = g.means[src];
        for a in 0..3 {
            parts.means[c][a] =
                ((r[a][0] * local[0] + r[a][1] * local[1]) + r[a][2] * local[2]) + m[a];
        }
        parts.log_scales[c] = g.log_scales[src].map(|v| v - shrink);
    }
    extra.append(&parts);
    radius.extend((0..2 * k).map(|c| stats.max_radius[split[c % k]]));

    // Prune: split originals, transparent, and (optionally) too large ones (over the
    // scene followed by `extra`).
    let total = n0 + extra.len();
    let opacity = |i: usize| {
        if i < n0 {
            g.opacity_logits[i]
        } else {
            extra.opacity_logits[i - n0]
        }
    };
    let log_scales = |i: usize| {
        if i < n0 {
            g.log_scales[i]
        } else {
            extra.log_scales[i - n0]
        }
    };
    let mut remove = vec![false; total];
    for &i in &split {
        remove[i] = true;
    }
    let screen = cfg.max_screen_size_px.filter(|_| world_prune);
    remove.par_iter_mut().enumerate().for_each(|(i, r)| {
        if i < cfg.protected {
            return;
        }
        let transparent = sigmoid(opacity(i)) < cfg.min_opacity;
        let big_world = world_prune && max_scale(log_scales(i)) > cfg.world_prune_fraction * extent;
        let big_screen = screen.is_some_and(|px| radius[i] > px);
        if transparent || big_world || big_screen {
            *r = true;
        }
    });
    let keep: Vec<usize> = (0..total).into_par_iter().filter(|&i| !remove[i]).collect();
    report.pruned = total - keep.len() - split.len();
    if let Some(origins) = origins {
        origins.clear();
        origins.extend(keep.iter().map(|&i| match i {
            i if i < n0 => Origin::Kept(i as u32),
            i if i < n0 + clone.len() => Origin::New(clone[i - n0] as u32),
            i => Origin::New(split[(i - n0 - clone.len()) % k] as u32),
        }));
    }
    *g = g.select_joined(&extra, &keep);
    adam.select_joined(extra.len(), &keep)?;
    *stats = DensifyStats::new(g.len());
    report.after = g.len();
    Ok(report)
}

/// One [`densify_and_prune`] step of `g` outside training, for a port's comparison: the
/// statistics given (`grad_accum`, `count` per Gaussian), fresh Adam moments, the split
/// draws given ([`Normals::Given`]).
pub fn densify_given(
    g: &mut Gaussians,
    (grad_accum, count): (Vec<f32>, Vec<u32>),
    cfg: &DensifyConfig,
    extent: f32,
    world_prune: bool,
    normals: &[[f32; 3]],
) -> Result<DensifyReport> {
    let n = g.len();
    if grad_accum.len() != n || count.len() != n {
        return Err(crate::error::Error::invalid(format!(
            "{} gradient sums and {} counts for {n} Gaussians",
            grad_accum.len(),
            count.len()
        )));
    }
    if !(extent.is_finite() && extent > 0.0) {
        return Err(crate::error::Error::invalid(format!(
            "the extent must be finite and positive, got {extent}"
        )));
    }
    let mut stats = DensifyStats {
        grad_accum,
        count,
        max_radius: vec![0.0; n],
    };
    let mut adam = Adam::new(crate::train::adam::AdamConfig::default(), g)?;
    densify_and_prune(
        g,
        &mut adam,
        &mut stats,
        cfg,
        extent,
        world_prune,
        Normals::Given(normals),
        None,
    )
}

/// INRIA's opacity reset: `opacity = min(σ(o), value)` as a logit, Adam moments zeroed.
pub fn reset_opacity(g: &mut Gaussians, adam: &mut Adam, value: f32) {
    let cap = ln(value / (1.0 - value));
    for o in g.opacity_logits.iter_mut() {
        // σ is monotonic: min(σ(o), v) = σ(min(o, logit v)).
        *o = o.min(cap);
    }
    adam.reset_moments(crate::gaussian::Param::OpacityLogits);
}
