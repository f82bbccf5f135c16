//! The 3DGS training loop, INRIA's recipe (SPEC.md §14): initialization from a point
//! cloud, random training view per iteration (a shuffled stack), L1 + D-SSIM (+ depth)
//! loss, Adam with per-group learning rates and the log-linear position schedule,
//! densification and pruning, SH degree +1 every 1000 iterations.
//!
//! Per iteration, in INRIA's order: learning-rate update; SH degree step; pick a view;
//! render; loss; backward; densification statistics; densify/prune and opacity reset;
//! Adam step. As in INRIA's code, an iteration that densifies replaces every parameter
//! tensor, whose new copies carry no gradient, so no Adam step happens there; an opacity
//! reset alone skips the opacity step.

use crate::dataset::{Dataset, View};
use crate::error::{Error, Result};
use crate::gaussian::{Gaussians, Param};
use crate::math::fastexp::ln;
use crate::math::sh::{SH_C0, num_coeffs};
use crate::raster::backward::project::{CHUNK, ChunkGrads, GradSink, ParamView};
use crate::raster::backward::{
    GradGroups, Gradients, ImageGrads, backward_apply, backward_into, render_for_backward,
};
use crate::raster::{Conventions, Outputs, RenderOptions};
use crate::rng::{Uniform, stage_seed};
use crate::train::adam::{Adam, AdamChunk, AdamConfig, ExpSchedule};
use crate::train::attribution::Attribution;
use crate::train::densify::{
    DensifyConfig, DensifyReport, DensifyStats, Normals, StatsChunk, densify_and_prune,
    reset_opacity,
};
use crate::train::knn::mean_sq_dist_3nn;
use crate::train::loss::{LossInput, LossWeights, image_loss, psnr};

/// A chunk of the fused step: Adam's update of the chunk and, on iterations that gather
/// them, its densification statistics (a `size[0] × size[1]` view).
struct TrainChunk<'a> {
    adam: AdamChunk<'a>,
    stats: Option<StatsChunk<'a>>,
    size: [u32; 2],
}

impl GradSink for TrainChunk<'_> {
    fn params(&self) -> ParamView<'_> {
        self.adam.params()
    }
    fn take(&mut self, grads: &ChunkGrads) {
        self.adam.take(grads);
        if let Some(s) = &mut self.stats {
            s.add_view(grads.splats, grads.radii, self.size);
        }
    }
}

/// Learning rates (INRIA `OptimizationParams`; opacity as in the 2024 update).
#[derive(Clone, Copy, Debug, PartialEq, serde::Serialize, serde::Deserialize)]
#[serde(default)]
pub struct LearningRates {
    /// Position rate at iteration 0 and at `position_max_steps`, before the extent scale.
    pub position_init: f32,
    pub position_final: f32,
    pub position_max_steps: u32,
    pub sh_dc: f32,
    pub sh_rest: f32,
    pub opacity: f32,
    pub scaling: f32,
    pub rotation: f32,
    /// Steps the position schedule starts into: 0 for a new training; a fine-tune that
    /// continues a scene's schedule starts where its training stopped (SPEC.md §20.5).
    #[serde(default, skip_serializing_if = "is_zero")]
    pub position_offset: u32,
}

fn is_zero(n: &u32) -> bool {
    *n == 0
}

impl Default for LearningRates {
    fn default() -> Self {
        LearningRates {
            position_init: 1.6e-4,
            position_final: 1.6e-6,
            position_max_steps: 30_000,
            sh_dc: 2.5e-3,
            sh_rest: 2.5e-3 / 20.0,
            opacity: 0.025,
            scaling: 5e-3,
            rotation: 1e-3,
            position_offset: 0,
        }
    }
}

/// Everything that decides a training run (serialized into the run directory).
#[derive(Clone, Debug, PartialEq, serde::Serialize, serde::Deserialize)]
#[serde(default)]
pub struct TrainConfig {
    pub iterations: u32,
    pub seed: u64,
    /// Largest SH degree trained (INRIA `sh_degree`).
    pub sh_degree: u32,
    /// The active degree grows by one every this many iterations (INRIA: 1000).
    pub sh_increase_interval: u32,
    pub lr: LearningRates,
    pub adam: AdamConfig,
    /// Parameter groups that never receive a step.
    pub frozen: Vec<Param>,
    /// Densification and pruning; `None` disables both.
    pub densify: Option<DensifyConfig>,
    pub loss: LossWeights,
    /// Render background (INRIA: black unless `--white_background`).
    pub background: [f32; 3],
    /// Random initial points when the dataset has no point cloud (INRIA: 100 000 in
    /// `[-1.3, 1.3]³`).
    pub random_init_points: usize,
    /// Iterations at which the PLY is saved (the last iteration is always saved).
    pub save_iterations: Vec<u32>,
    /// Dataset loading: integer downscale and INRIA's test hold-out.
    pub resolution: u32,
    pub test_every: u32,
    /// The convention profile every render of the run follows (SPEC.md §5.2); left out of
    /// the file when it is the default `inria`, so older run directories keep their bytes.
    #[serde(skip_serializing_if = "Conventions::is_default")]
    pub conventions: Conventions,
    /// A fixed share of the iterations on the first views (a fine-tune's original
    /// training views, the rest generated; SPEC.md §20.5); `None`: INRIA's one stack over
    /// every view.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub view_share: Option<ViewShare>,
}

/// Each iteration draws the group of the dataset's views with index below `views` with
/// probability `share`, then a view of that group from its own INRIA stack.
#[derive(Clone, Copy, Debug, PartialEq, serde::Serialize, serde::Deserialize)]
pub struct ViewShare {
    pub views: usize,
    pub share: f32,
}

impl Default for TrainConfig {
    fn default() -> Self {
        TrainConfig {
            iterations: 30_000,
            seed: 0,
            sh_degree: 3,
            sh_increase_interval: 1000,
            lr: LearningRates::default(),
            adam: AdamConfig::default(),
            frozen: Vec::new(),
            densify: Some(DensifyConfig::default()),
            loss: LossWeights::INRIA,
            background: [0.0; 3],
            random_init_points: 100_000,
            save_iterations: vec![7_000, 30_000],
            resolution: 1,
            test_every: 8,
            conventions: Conventions::Inria,
            view_share: None,
        }
    }
}

/// Command-line overrides of a [`TrainConfig`].
#[derive(Clone, Copy, Debug, Default, PartialEq)]
pub struct TrainOverrides {
    pub iterations: Option<u32>,
    pub seed: Option<u64>,
    pub resolution: Option<u32>,
    pub sh_degree: Option<u32>,
    pub conventions: Option<Conventions>,
}

impl TrainConfig {
    /// The defaults, overlaid by the JSON file `path` (any subset of fields), overlaid by
    /// `flags`.
    pub fn from_file_and_flags(
        path: Option<&std::path::Path>,
        flags: &TrainOverrides,
    ) -> Result<TrainConfig> {
        let mut c = match path {
            Some(p) => {
                let text = std::fs::read(p).map_err(|e| Error::io(p, e))?;
                serde_json::from_slice::<TrainConfig>(&text)
                    .map_err(|e| Error::parse(p, format!("invalid train config: {e}")))?
            }
            None => TrainConfig::default(),
        };
        if let Some(v) = flags.iterations {
            c.iterations = v;
        }
        if let Some(v) = flags.seed {
            c.seed = v;
        }
        if let Some(v) = flags.resolution {
            c.resolution = v;
        }
        if let Some(v) = flags.sh_degree {
            c.sh_degree = v;
        }
        if let Some(v) = flags.conventions {
            c.conventions = v;
        }
        Ok(c)
    }

    pub fn validate(&self) -> Result<()> {
        if self.sh_degree > crate::math::sh::MAX_SH_DEGREE {
            return Err(Error::invalid(format!("SH degree {} > 5", self.sh_degree)));
        }
        self.adam.validate()?;
        if self.resolution == 0 {
            return Err(Error::invalid("resolution factor must be at least 1"));
        }
        let w = &self.loss;
        for (n, v) in [
            ("l1", w.l1),
            ("l2", w.l2),
            ("dssim", w.dssim),
            ("depth", w.depth),
        ] {
            if !v.is_finite() || v < 0.0 {
                return Err(Error::invalid(format!(
                    "loss weight {n} = {v} must be finite and >= 0"
                )));
            }
        }
        if !self.background.iter().all(|v| v.is_finite()) {
            return Err(Error::invalid("background must be finite"));
        }
        if let Some(s) = self.view_share
            && !(s.share > 0.0 && s.share < 1.0)
        {
            return Err(Error::invalid(format!(
                "the share of iterations on the first views must be in (0, 1), got {}",
                s.share
            )));
        }
        Ok(())
    }
}

/// INRIA's `create_from_pcd`: means at the points, DC from the colour, zero rest, scale
/// `sqrt(max(mean 3-NN squared distance, 1e-7))` on every axis, identity rotation,
/// opacity 0.1.
pub fn init_from_points(xyz: &[[f32; 3]], rgb: &[[f32; 3]], sh_degree: u32) -> Result<Gaussians> {
    if xyz.is_empty() {
        return Err(Error::invalid(
            "cannot initialize from an empty point cloud",
        ));
    }
    let d2 = mean_sq_dist_3nn(xyz);
    let mut g = Gaussians::new(sh_degree)?;
    let rest = vec![0f32; (num_coeffs(sh_degree) - 1) * 3];
    let op = ln(0.1 / (1.0 - 0.1));
    let c0 = SH_C0 as f32;
    for i in 0..xyz.len() {
        let s = ln(d2[i].max(1e-7).sqrt());
        let dc = rgb[i].map(|c| (c - 0.5) / c0);
        g.push(xyz[i], [s; 3], [1.0, 0.0, 0.0, 0.0], op, dc, &rest);
    }
    Ok(g)
}

/// Progress of one iteration, for a progress bar or a log.
#[derive(Clone, Copy, Debug, Default)]
pub struct Progress {
    pub iteration: u32,
    pub iterations: u32,
    pub loss: f64,
    /// Exponential moving average of the loss (INRIA: 0.4·new + 0.6·old).
    pub loss_ema: f64,
    pub psnr_ema: f64,
    pub gaussians: usize,
    pub pairs: u64,
    pub densify: Option<DensifyReport>,
    /// A checkpoint was written after this iteration (`train::run`).
    pub checkpointed: bool,
}

/// Seconds spent in each part of the iterations so far (wall time, summed over iterations).
#[derive(Clone, Copy, Debug, Default, PartialEq, serde::Serialize, serde::Deserialize)]
pub struct IterationTimes {
    /// Projection, binning and blend with backward state.
    pub forward: f64,
    /// L1 + D-SSIM (+ depth) and their gradient.
    pub loss: f64,
    /// Blend backward and projection backward.
    pub backward: f64,
    /// Densification statistics, densify/prune and opacity reset.
    pub densify: f64,
    pub adam: f64,
}

/// Training state: parameters, optimizer, statistics, generator. A clone continues with
/// the same bits as the original would.
#[derive(Clone)]
pub struct Trainer<'a> {
    pub config: TrainConfig,
    /// The views (borrowed; copied on the first [`Trainer::replace_image`]).
    pub dataset: std::borrow::Cow<'a, Dataset>,
    pub gaussians: Gaussians,
    pub adam: Adam,
    pub stats: DensifyStats,
    pub iteration: u32,
    pub active_sh_degree: u32,
    pub extent: f32,
    /// Per-view loss weights `M` (paper Eq. 7), indexed like `dataset.views`; empty = none.
    pub masks: Vec<Option<Vec<f32>>>,
    /// Where the iterations' time went.
    pub times: IterationTimes,
    pub(crate) rng: Uniform,
    /// INRIA's view stack (views not yet drawn in this pass).
    pub(crate) stack: Vec<usize>,
    pub(crate) loss_ema: f64,
    pub(crate) psnr_ema: f64,
    /// Whether Adam takes the projection backward's gradients chunk by chunk (the
    /// default), or the gradients go into arrays first and Adam steps each group over them
    /// (the reference form: the same bits, `fused_adam_keeps_the_bits_of_separate_steps`).
    pub fused_adam: bool,
    /// The backward's output, reused across iterations.
    grads: Gradients,
    /// Per Gaussian, the index of the starting Gaussian it descends from (densification's
    /// copies and split children take their source's), when tracked
    /// ([`Trainer::track_lineage`]): bookkeeping beside the computation, no bit of which it
    /// moves.
    pub lineage: Option<Vec<u32>>,
    /// Per element, Adam's movement split between the original and the generated views
    /// ([`Trainer::track_attribution`]): bookkeeping beside the computation, like the
    /// lineage.
    pub attribution: Option<Attribution>,
}

/// What an iteration does besides its gradient step ([`Trainer::schedule`]).
#[derive(Clone, Copy, Debug, Default)]
struct Schedule {
    /// Record densification statistics.
    stats: bool,
    densify: bool,
    reset: bool,
}

impl<'a> Trainer<'a> {
    /// Start from the dataset's point cloud (or INRIA's random cube).
    pub fn new(dataset: &'a Dataset, config: TrainConfig) -> Result<Self> {
        config.validate()?;
        let g = match &dataset.points {
            Some(p) if !p.xyz.is_empty() => init_from_points(&p.xyz, &p.rgb, config.sh_degree)?,
            _ => {
                let mut u = Uniform::new(stage_seed(config.seed, "random-init"));
                let n = config.random_init_points.max(1);
                let xyz: Vec<[f32; 3]> =
                    (0..n).map(|_| [0; 3].map(|_| u.range(-1.3, 1.3))).collect();
                // INRIA: SH = random / 255, colour = SH·C0 + 0.5.
                let rgb: Vec<[f32; 3]> = (0..n)
                    .map(|_| [0; 3].map(|_| u.unit() / 255.0 * SH_C0 as f32 + 0.5))
                    .collect();
                init_from_points(&xyz, &rgb, config.sh_degree)?
            }
        };
        Self::from_gaussians(dataset, config, g, 0)
    }

    /// Continue from given Gaussians (fine-tuning); `active_sh_degree` starts at
    /// `initial_sh_degree`.
    pub fn from_gaussians(
        dataset: &'a Dataset,
        config: TrainConfig,
        gaussians: Gaussians,
        initial_sh_degree: u32,
    ) -> Result<Self> {
        config.validate()?;
        gaussians.validate()?;
        if gaussians.sh_degree != config.sh_degree {
            return Err(Error::invalid(format!(
                "the scene has SH degree {} but the config trains degree {}",
                gaussians.sh_degree, config.sh_degree
            )));
        }
        let adam = Adam::new(config.adam, &gaussians)?;
        let stats = DensifyStats::new(gaussians.len());
        let rng = Uniform::new(stage_seed(config.seed, "train"));
        let extent = dataset.scene_extent();
        Ok(Trainer {
            active_sh_degree: initial_sh_degree.min(config.sh_degree),
            config,
            dataset: std::borrow::Cow::Borrowed(dataset),
            gaussians,
            adam,
            stats,
            iteration: 0,
            extent,
            masks: Vec::new(),
            times: IterationTimes::default(),
            rng,
            stack: Vec::new(),
            loss_ema: 0.0,
            psnr_ema: 0.0,
            fused_adam: true,
            grads: Gradients::default(),
            lineage: None,
            attribution: None,
        })
    }

    /// Track every Gaussian's lineage from here on ([`Trainer::lineage`]; each starting
    /// Gaussian its own index). Checkpoints do not keep it.
    pub fn track_lineage(&mut self) {
        self.lineage = Some((0..self.gaussians.len() as u32).collect());
    }

    /// Split every Adam step from here on between the views flagged `generated` (one flag
    /// per view of the dataset) and the others ([`Trainer::attribution`]). The iterations
    /// then take the unfused path (the same bits).
    pub fn track_attribution(&mut self, generated: Vec<bool>) -> Result<()> {
        if self.config.adam.sparse {
            // A sparse step leaves the moments of unseen Gaussians as they were, which the
            // generated group's moment would have to mirror: not supported.
            return Err(Error::invalid(
                "the attribution splits dense Adam steps; sparse Adam is on",
            ));
        }
        if generated.len() != self.dataset.views.len() {
            return Err(Error::invalid(format!(
                "{} view flags for {} views",
                generated.len(),
                self.dataset.views.len()
            )));
        }
        self.attribution = Some(Attribution::new(&self.gaussians, generated)?);
        Ok(())
    }

    fn lr(&self, p: Param, it: u32) -> f32 {
        let l = &self.config.lr;
        match p {
            Param::Means => ExpSchedule {
                init: l.position_init * self.extent,
                final_: l.position_final * self.extent,
                max_steps: l.position_max_steps,
            }
            .at(it.saturating_add(l.position_offset)),
            Param::ShDc => l.sh_dc,
            Param::ShRest => l.sh_rest,
            Param::OpacityLogits => l.opacity,
            Param::LogScales => l.scaling,
            Param::Quats => l.rotation,
        }
    }

    /// What iteration `it` does besides the gradient step, known before it runs (INRIA's
    /// schedule): whether it records densification statistics, densifies, and resets the
    /// opacities. Nothing after the last iteration could recover from a reset or use a
    /// densification, so the last iteration does neither (INRIA's defaults, 7000 and 30000
    /// iterations, never end on one; a 3000-iteration run would otherwise save Gaussians
    /// whose opacity was just capped at 0.01). INRIA also resets once at `from_iter` when
    /// training on white.
    fn schedule(&self, it: u32, groups: &GradGroups) -> Schedule {
        let Some(d) = self.config.densify else {
            return Schedule::default();
        };
        let last = it == self.config.iterations;
        let stats = it < d.until_iter && groups.geometry() && !last;
        let white_start = self.config.background == [1.0; 3] && it == d.from_iter;
        Schedule {
            stats,
            densify: stats && it > d.from_iter && d.interval > 0 && it.is_multiple_of(d.interval),
            reset: stats
                && ((d.opacity_reset_interval > 0 && it.is_multiple_of(d.opacity_reset_interval))
                    || white_start),
        }
    }

    fn groups(&self) -> GradGroups {
        let on = |p| !self.config.frozen.contains(&p);
        GradGroups {
            means: on(Param::Means),
            log_scales: on(Param::LogScales),
            quats: on(Param::Quats),
            opacities: on(Param::OpacityLogits),
            sh_dc: on(Param::ShDc),
            sh_rest: on(Param::ShRest),
            background: false,
        }
    }

    /// INRIA's view stack: refilled with every training view when empty, one removed at a
    /// uniformly drawn position per iteration.
    fn next_view(&mut self) -> usize {
        if let Some(s) = self.config.view_share {
            // The group first (one draw), then INRIA's stack within it: the stack holds
            // views of both groups, and a group found empty there is refilled alone.
            let first = self.rng.unit() < s.share;
            let train = &self.dataset.train;
            let has = |first: bool| train.iter().any(|&v| (v < s.views) == first);
            let first = if has(first) { first } else { !first };
            let member = |v: usize| (v < s.views) == first;
            if !self.stack.iter().any(|&v| member(v)) {
                self.stack
                    .extend(train.iter().copied().filter(|&v| member(v)));
            }
            let n = self.stack.iter().filter(|&&v| member(v)).count();
            let k = self.rng.below(n as u32) as usize;
            let at = (0..self.stack.len())
                .filter(|&i| member(self.stack[i]))
                .nth(k)
                .expect("k below the group's count");
            return self.stack.remove(at);
        }
        if self.stack.is_empty() {
            self.stack = self.dataset.train.clone();
        }
        let k = self.rng.below(self.stack.len() as u32) as usize;
        self.stack.remove(k)
    }

    /// Render options for a view at the current state.
    pub fn render_options(&self, depth: bool) -> RenderOptions {
        RenderOptions {
            background: self.config.background,
            sh_degree: Some(self.active_sh_degree),
            outputs: Outputs {
                rgb: true,
                expected_depth: depth,
                ..Outputs::default()
            },
            conventions: self.config.conventions,
            ..RenderOptions::default()
        }
    }

    /// One iteration on view `view` with an optional per-pixel loss weight.
    pub fn step_on(&mut self, vi: usize, mask: Option<&[f32]>) -> Result<Progress> {
        self.iteration += 1;
        let it = self.iteration;
        if self.config.sh_increase_interval > 0
            && it.is_multiple_of(self.config.sh_increase_interval)
            && self.active_sh_degree < self.config.sh_degree
        {
            self.active_sh_degree += 1;
        }
        let view: &View = &self.dataset.views[vi];
        let use_depth = self.config.loss.depth > 0.0 && view.depth.is_some();
        let opts = self.render_options(use_depth);
        let cam = &view.camera;
        let mut clock = std::time::Instant::now();
        let mut lap = |acc: &mut f64| {
            let now = std::time::Instant::now();
            *acc += (now - clock).as_secs_f64();
            clock = now;
        };
        let fwd = render_for_backward(&self.gaussians, cam, &opts)?;
        lap(&mut self.times.forward);
        let rgb = fwd.render.rgb.as_deref().expect("rgb rendered");
        let input = LossInput {
            width: cam.width as usize,
            height: cam.height as usize,
            rgb,
            target_rgb: &view.image.data,
            depth: if use_depth {
                fwd.render.expected_depth.as_deref()
            } else {
                None
            },
            target_depth: if use_depth {
                view.depth.as_deref()
            } else {
                None
            },
            mask,
        };
        // The progress PSNR beside the loss (both only read the render).
        let (out, p) = rayon::join(
            || image_loss(&input, &self.config.loss),
            || psnr(rgb, &view.image.data),
        );
        let out = out.map_err(|e| Error::invalid(format!("view '{}': {}", cam.name, e.message)))?;
        lap(&mut self.times.loss);
        let v = ImageGrads {
            rgb: Some(out.grad_rgb),
            expected_depth: out.grad_depth,
            ..Default::default()
        };
        let groups = self.groups();
        let plan = self.schedule(it, &groups);
        // Taken for the iteration, put back after Adam (lost only with an error).
        let mut grads = std::mem::take(&mut self.grads);
        // Unless the iteration densifies or resets opacities (both change the scene between
        // the backward and Adam) or Adam is sparse, Adam takes each chunk's gradients as the
        // projection backward makes them: the same bits, and the scene's gradient arrays
        // are neither written nor read back (SPEC.md §14.2).
        let fused = self.fused_adam
            && !self.config.adam.sparse
            && !plan.densify
            && !plan.reset
            && self.attribution.is_none();
        let pairs = if fused {
            let lrs = Param::ALL.map(|p| self.lr(p, it));
            let frozen = Param::ALL.map(|p| self.config.frozen.contains(&p));
            let mut steps = [None; 6];
            for (i, p) in Param::ALL.into_iter().enumerate() {
                if !frozen[i] {
                    steps[i] = Some(self.adam.begin(p, lrs[i]));
                }
            }
            // The densification statistics are added where each chunk's gradients are
            // handed over, too: the same additions as `add_view`, without a pass of their own.
            let stats_on = self.config.densify.is_some() && plan.stats;
            // Each chunk of the scene takes the chunk of statistics beside it.
            assert!(!stats_on || self.stats.count.len() == self.gaussians.len());
            let mut stats = stats_on.then(|| self.stats.chunks_mut(CHUNK).into_iter());
            let size = [cam.width, cam.height];
            let mut chunks: Vec<TrainChunk> = self
                .adam
                .fused_chunks(&mut self.gaussians, steps)
                .into_iter()
                .map(|adam| TrainChunk {
                    adam,
                    stats: stats.as_mut().and_then(Iterator::next),
                    size,
                })
                .collect();
            backward_apply(cam, &opts, &fwd, &v, &groups, &mut chunks, &mut grads)?
        } else {
            backward_into(&self.gaussians, cam, &opts, &fwd, &v, &groups, &mut grads)?
        };
        lap(&mut self.times.backward);

        let mut densified = None;
        let mut reset = false;
        if let Some(d) = self.config.densify
            && plan.stats
        {
            if !fused {
                self.stats
                    .add_view(&grads.means2d_ndc, &fwd.projected.radii);
            }
            if plan.densify {
                let world_prune = it > d.opacity_reset_interval;
                if let Some(l) = self
                    .lineage
                    .as_ref()
                    .filter(|l| l.len() != self.gaussians.len())
                {
                    return Err(Error::invalid(format!(
                        "a lineage of {} entries for {} Gaussians",
                        l.len(),
                        self.gaussians.len()
                    )));
                }
                let follow = self.lineage.is_some() || self.attribution.is_some();
                let mut origins = Vec::new();
                densified = Some(densify_and_prune(
                    &mut self.gaussians,
                    &mut self.adam,
                    &mut self.stats,
                    &d,
                    self.extent,
                    world_prune,
                    Normals::Rng(&mut self.rng),
                    follow.then_some(&mut origins),
                )?);
                if let Some(lineage) = self.lineage.as_mut() {
                    *lineage = origins.iter().map(|o| lineage[o.source()]).collect();
                }
                if let Some(a) = self.attribution.as_mut() {
                    a.follow(&origins);
                }
            }
            if plan.reset {
                reset_opacity(&mut self.gaussians, &mut self.adam, d.opacity_reset_value);
                if let Some(a) = self.attribution.as_mut() {
                    a.reset_moments(Param::OpacityLogits);
                }
                reset = true;
            }
        }
        lap(&mut self.times.densify);
        if densified.is_none() && !fused {
            let visible: Option<Vec<bool>> = self.config.adam.sparse.then(|| {
                let radii = &fwd.projected.radii;
                radii.iter().map(|r| *r != [0, 0]).collect()
            });
            for param in Param::ALL {
                if self.config.frozen.contains(&param) || (reset && param == Param::OpacityLogits) {
                    continue;
                }
                let lr = self.lr(param, it);
                let g = grads.param(param);
                if let Some(a) = self.attribution.as_mut() {
                    a.before_step(&self.gaussians, param);
                }
                self.adam
                    .step_sparse(&mut self.gaussians, param, g, lr, visible.as_deref());
                if let Some(a) = self.attribution.as_mut() {
                    let generated = a.is_generated(vi);
                    a.after_step(&self.gaussians, &self.adam, param, g, generated);
                }
            }
        }
        self.grads = grads;
        lap(&mut self.times.adam);
        let t = out.terms;
        self.loss_ema = if it == 1 {
            t.total
        } else {
            0.4 * t.total + 0.6 * self.loss_ema
        };
        let pf = if p.is_finite() { p } else { 100.0 };
        self.psnr_ema = if it == 1 {
            pf
        } else {
            0.4 * pf + 0.6 * self.psnr_ema
        };
        Ok(Progress {
            iteration: it,
            iterations: self.config.iterations,
            loss: t.total,
            loss_ema: self.loss_ema,
            psnr_ema: self.psnr_ema,
            gaussians: self.gaussians.len(),
            pairs,
            densify: densified,
            checkpointed: false,
        })
    }

    /// Replace the target image of view `vi` (same size and channels), e.g. with an artifact
    /// fixer's output of the current render (paper §3.3.3, on the fly).
    pub fn replace_image(&mut self, vi: usize, image: crate::io::image::ImageF32) -> Result<()> {
        let v = self
            .dataset
            .views
            .get(vi)
            .ok_or_else(|| Error::invalid(format!("no view {vi}")))?;
        if (image.width, image.height, image.channels)
            != (v.image.width, v.image.height, v.image.channels)
        {
            return Err(Error::invalid(format!(
                "view '{}': the new image is {}x{}x{}, the view's {}x{}x{}",
                v.camera.name,
                image.width,
                image.height,
                image.channels,
                v.image.width,
                v.image.height,
                v.image.channels
            )));
        }
        self.dataset.to_mut().views[vi].image = image;
        Ok(())
    }

    /// One iteration on the next view of the stack (with its mask, if any).
    pub fn step(&mut self) -> Result<Progress> {
        let vi = self.next_view();
        let mask = self.masks.get_mut(vi).and_then(Option::take);
        let r = self.step_on(vi, mask.as_deref());
        if let Some(m) = mask {
            self.masks[vi] = Some(m);
        }
        r
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::camera::Camera;
    use crate::dataset::{Layout, View};
    use crate::io::image::ImageF32;
    use glam::DVec3;

    /// `n` views of 4×4 pixels on a circle, with a scene of one Gaussian.
    fn trainer(n: usize, config: TrainConfig) -> (Dataset, Gaussians, TrainConfig) {
        let views = (0..n)
            .map(|k| {
                let a = k as f64 * 0.3;
                let eye = DVec3::new(a.cos(), 0.0, a.sin()) * 3.0;
                View {
                    camera: Camera::look_at(
                        format!("v{k}"),
                        4,
                        4,
                        1.0,
                        eye,
                        DVec3::ZERO,
                        -DVec3::Y,
                    )
                    .unwrap(),
                    image: ImageF32::new(4, 4, 3, vec![0.5; 48]).unwrap(),
                    depth: None,
                }
            })
            .collect();
        let data = Dataset {
            root: "synthetic".into(),
            layout: Layout::Unseen,
            views,
            points: None,
            train: (0..n).collect(),
            test: Vec::new(),
            heldout: Vec::new(),
        };
        let g = init_from_points(&[[0.0; 3], [0.1, 0.0, 0.0]], &[[0.5; 3]; 2], 0).unwrap();
        (
            data,
            g,
            TrainConfig {
                sh_degree: 0,
                ..config
            },
        )
    }

    /// With a share, each iteration draws the first group with that probability and cycles
    /// each group through its own stack: every group's views come once per pass.
    #[test]
    fn a_view_share_draws_each_group_from_its_own_stack() {
        let share = ViewShare {
            views: 3,
            share: 0.25,
        };
        let (data, g, cfg) = trainer(
            12,
            TrainConfig {
                view_share: Some(share),
                ..TrainConfig::default()
            },
        );
        let mut t = Trainer::from_gaussians(&data, cfg, g, 0).unwrap();
        let draws: Vec<usize> = (0..4000).map(|_| t.next_view()).collect();
        let first: Vec<usize> = draws.iter().copied().filter(|&v| v < 3).collect();
        let rest: Vec<usize> = draws.iter().copied().filter(|&v| v >= 3).collect();
        // Binomial(4000, 1/4): sd ≈ 27.
        assert!(
            (first.len() as f64 - 1000.0).abs() < 110.0,
            "{}",
            first.len()
        );
        for (group, size) in [(&first, 3), (&rest, 9)] {
            for pass in group.chunks_exact(size) {
                let mut p = pass.to_vec();
                p.sort_unstable();
                p.dedup();
                assert_eq!(p.len(), size, "a pass repeats a view: {pass:?}");
            }
        }
        // A share outside (0, 1) is refused; none keeps INRIA's single stack.
        let (data, g, cfg) = trainer(4, TrainConfig::default());
        let bad = TrainConfig {
            view_share: Some(ViewShare {
                views: 2,
                share: 1.0,
            }),
            ..cfg.clone()
        };
        let refused = Trainer::from_gaussians(&data, bad, g.clone(), 0).err();
        assert!(refused.is_some_and(|e| e.to_string().contains("(0, 1)")));
        let mut t = Trainer::from_gaussians(&data, cfg, g, 0).unwrap();
        let mut pass: Vec<usize> = (0..4).map(|_| t.next_view()).collect();
        pass.sort_unstable();
        assert_eq!(pass, [0, 1, 2, 3]);
    }

    /// A continued schedule is the schedule shifted: its first step is the new training's
    /// step `position_offset`.
    #[test]
    fn a_position_offset_shifts_the_schedule() {
        let (data, g, cfg) = trainer(2, TrainConfig::default());
        let fresh = Trainer::from_gaussians(&data, cfg.clone(), g.clone(), 0).unwrap();
        let cfg = TrainConfig {
            lr: LearningRates {
                position_offset: 1500,
                ..cfg.lr
            },
            ..cfg
        };
        let continued = Trainer::from_gaussians(&data, cfg, g, 0).unwrap();
        for it in [1, 600, 29_000] {
            assert_eq!(
                continued.lr(Param::Means, it),
                fresh.lr(Param::Means, it + 1500)
            );
            assert_eq!(continued.lr(Param::ShDc, it), fresh.lr(Param::ShDc, it));
        }
        assert!(continued.lr(Param::Means, 1) < fresh.lr(Param::Means, 1));
    }
}
