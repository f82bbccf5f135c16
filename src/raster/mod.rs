//! The deterministic CPU rasterizer (forward pass).
//!
//! `render` = [`project::project`] (per Gaussian) → [`tile::bin`] (per-tile depth-sorted
//! lists) → [`composite`] (per-pixel front-to-back blending). Conventions and constants are
//! gsplat's (SPEC.md §4–5); every stage is a pure function of its inputs and gives the same
//! bits for any thread count and any SIMD path.

pub mod backward;
pub mod composite;
pub mod decisions;
pub mod kernel;
pub mod plan;
pub mod project;
pub(crate) mod schedule;
pub mod tile;

pub use kernel::Kernel;
pub use plan::{Outputs, RenderPlan};

use crate::camera::Camera;
use crate::error::{Error, Result};
use crate::gaussian::Gaussians;
use crate::math::sh::MAX_SH_DEGREE;

/// What the caller wants from a render.
#[derive(Clone, Debug, PartialEq)]
pub struct RenderOptions {
    /// Background colour added as `T·bg` (linear, any finite values).
    pub background: [f32; 3],
    /// Evaluate SH up to this degree (default: the scene's degree).
    pub sh_degree: Option<u32>,
    pub outputs: Outputs,
    /// gsplat's antialiased mode (opacity × `sqrt(det₀/det)`); off like INRIA.
    pub antialiased: bool,
    pub kernel: Kernel,
    /// Where blending is cut off: gsplat's values by default. Other values are a
    /// forward-only knob (the accuracy bench's); the backward refuses them.
    pub cutoffs: Cutoffs,
    /// Which published renderer's constants the render follows (SPEC.md §5.2): INRIA's
    /// (the default, which training and the pipeline use) or gsplat ≤ 1.5.3's. Unlike the
    /// cut-offs, both hold in the forward and the backward.
    pub conventions: Conventions,
}

/// A convention profile: the constants in which published 3DGS renderers differ and that a
/// port must match (SPEC.md §5.2). Today only the upper clamp of α differs.
///
/// | profile | α clamp | source |
/// |---|---|---|
/// | `inria` | 0.99 | INRIA `diff-gaussian-rasterization` `forward.cu` (`min(0.99f, …)`), gsplat ≥ 1.5.4 |
/// | `gsplat` | 0.999 | gsplat 1.0–1.5.3 `RasterizeToPixels3DGSFwd.cu` / `Bwd.cu` (`min(0.999f, …)`, the backward's `opac·vis <= 0.999f`) |
///
/// Everything else is the same in both: gsplat's near plane (0.01), ε2d, Jacobian guard,
/// opacity-aware radius, 1/255 threshold and exclusive 1e-4 stop (SPEC.md §5.2).
#[derive(
    Clone, Copy, Debug, Default, PartialEq, Eq, Hash, serde::Serialize, serde::Deserialize,
)]
#[serde(rename_all = "lowercase")]
pub enum Conventions {
    /// α clamp 0.99 (INRIA; gsplat ≥ 1.5.4).
    #[default]
    Inria,
    /// α clamp 0.999 (gsplat 1.0–1.5.3).
    Gsplat,
}

impl Conventions {
    /// Every profile, in a fixed order.
    pub const ALL: [Conventions; 2] = [Conventions::Inria, Conventions::Gsplat];

    /// The upper clamp of a splat's α (`α = min(max_alpha, o·exp(−σ))`); the backward
    /// passes no opacity or geometry gradient where `o·exp(−σ)` exceeds it.
    pub const fn max_alpha(self) -> f32 {
        match self {
            Conventions::Inria => composite::MAX_ALPHA,
            Conventions::Gsplat => composite::MAX_ALPHA_GSPLAT,
        }
    }

    /// Whether this is the default profile (`inria`): configurations leave it out of their
    /// files, so files written before profiles existed keep their bytes.
    pub fn is_default(&self) -> bool {
        *self == Conventions::Inria
    }

    /// The profile's name in files and on the command line: `inria` or `gsplat`.
    pub const fn name(self) -> &'static str {
        match self {
            Conventions::Inria => "inria",
            Conventions::Gsplat => "gsplat",
        }
    }

    /// The profile called `name` (`inria` or `gsplat`).
    pub fn parse(name: &str) -> Result<Conventions> {
        Conventions::ALL
            .into_iter()
            .find(|c| c.name() == name)
            .ok_or_else(|| {
                Error::invalid(format!(
                    "unknown conventions '{name}' (known: inria, gsplat)"
                ))
            })
    }
}

impl std::fmt::Display for Conventions {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.write_str(self.name())
    }
}

/// The blend's cut-offs (SPEC.md §5.4–5.5): gsplat's `ALPHA_THRESHOLD = 1/255` (with the
/// opacity cull and the radius `√(2·ln(255·o))` σ that follow from it) and the
/// transmittance stop `1e-4`.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Cutoffs {
    /// The reciprocal of the smallest α that is blended (255). `f32::INFINITY` blends every
    /// α > 0 (each splat then reaches its 3.33σ extent; an opacity of 0 is culled).
    pub inv_alpha_threshold: f32,
    /// Blending stops before a splat that would bring transmittance to this or below
    /// (1e-4); 0 stops only where transmittance reaches 0.
    pub transmittance_stop: f32,
}

impl Cutoffs {
    /// gsplat's and INRIA's.
    pub const GSPLAT: Cutoffs = Cutoffs {
        inv_alpha_threshold: 255.0,
        transmittance_stop: composite::TRANSMITTANCE_STOP,
    };
    /// The smallest blended α: `1/inv_alpha_threshold` (exactly `ALPHA_THRESHOLD` by
    /// default), or the smallest positive f32 for +∞ (every α > 0 is blended, an α of 0
    /// is not).
    pub fn alpha_threshold(&self) -> f32 {
        project::alpha_floor(self.inv_alpha_threshold)
    }

    /// Whether row culling is exact (SPEC.md §5.4): the radius `√(2·ln(N·o))`σ reaches
    /// every pixel with α ≥ 1/N only while the 3.33σ cap cannot bind, i.e. `N·o ≤ e^(3.33²/2)
    /// ≈ 255.9` for every `o ≤ 1`: `N ≤ 255`. With a lower threshold the render evaluates
    /// every row of each tile it bins (the tiles themselves still come from the capped
    /// radius, as in gsplat).
    pub fn rows_cull_exactly(&self) -> bool {
        self.inv_alpha_threshold <= 255.0
    }

    /// `Ok` for `N ≥ 1` or +∞ and a stop in [0, 1).
    fn check(&self) -> Result<()> {
        let Cutoffs {
            inv_alpha_threshold: inv,
            transmittance_stop: stop,
        } = *self;
        if inv.is_nan() || inv < 1.0 {
            return Err(Error::invalid(format!(
                "inverse alpha threshold {inv} is not ≥ 1 (or +∞)"
            )));
        }
        if !(0.0..1.0).contains(&stop) {
            return Err(Error::invalid(format!(
                "transmittance stop {stop} is not in [0, 1)"
            )));
        }
        Ok(())
    }
}

impl Default for Cutoffs {
    fn default() -> Self {
        Cutoffs::GSPLAT
    }
}

impl Default for RenderOptions {
    fn default() -> Self {
        RenderOptions {
            background: [0.0; 3],
            sh_degree: None,
            outputs: Outputs::RGB,
            antialiased: false,
            kernel: Kernel::Auto,
            cutoffs: Cutoffs::GSPLAT,
            conventions: Conventions::Inria,
        }
    }
}

/// Counts of what happened to the Gaussians in one render.
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq)]
pub struct RenderReport {
    pub visible: u64,
    pub non_finite: u64,
    pub behind_near_plane: u64,
    pub beyond_far_plane: u64,
    pub degenerate: u64,
    pub low_opacity: u64,
    pub off_screen: u64,
    /// (tile, Gaussian) pairs after binning.
    pub intersections: u64,
    /// Gaussian-pixel evaluations of the blend kernel (the throughput unit).
    pub pairs_evaluated: u64,
}

/// A rendered image. Planar per output, row-major, `width × height` pixels; `rgb` has 3
/// interleaved channels.
#[derive(Clone, Debug, Default, PartialEq)]
pub struct Render {
    pub width: usize,
    pub height: usize,
    pub rgb: Option<Vec<f32>>,
    pub alpha: Option<Vec<f32>>,
    /// Accumulated depth `D` (camera z, background 0).
    pub depth: Option<Vec<f32>>,
    /// Expected depth `ED = D / max(alpha, 1e-10)`.
    pub expected_depth: Option<Vec<f32>>,
    /// Final transmittance per pixel (backward state).
    pub final_t: Option<Vec<f32>>,
    /// Per pixel: one past the position, in its tile's list, of the last blended splat
    /// (INRIA's `n_contrib`; 0 when nothing was blended). Backward state.
    pub n_contrib: Option<Vec<u32>>,
    /// Per (tile, Gaussian) intersection (in the tile lists' order): which halves of which
    /// tile rows blended the splat (`composite::CompositeOut::blend_halves`). Backward state.
    pub blend_halves: Option<Vec<u32>>,
    pub plan: Option<RenderPlan>,
    pub report: RenderReport,
}

fn check_options(scene: &Gaussians, opts: &RenderOptions) -> Result<()> {
    scene.validate()?;
    if !opts.background.iter().all(|v| v.is_finite()) {
        return Err(Error::invalid(format!(
            "background {:?} is not finite",
            opts.background
        )));
    }
    if let Some(d) = opts.sh_degree
        && d > MAX_SH_DEGREE
    {
        return Err(Error::invalid(format!("SH degree {d} > {MAX_SH_DEGREE}")));
    }
    opts.cutoffs.check()
}

/// Render `scene` from `cam` with the minimal plan for `opts`.
pub fn render(scene: &Gaussians, cam: &Camera, opts: &RenderOptions) -> Result<Render> {
    check_options(scene, opts)?;
    render_with_plan(scene, cam, opts, &RenderPlan::new(scene, opts))
}

/// Render with an explicit plan (tests compare the minimal plan against [`RenderPlan::full`]).
pub fn render_with_plan(
    scene: &Gaussians,
    cam: &Camera,
    opts: &RenderOptions,
    plan: &RenderPlan,
) -> Result<Render> {
    Ok(render_staged(scene, cam, opts, plan)?.0)
}

/// Render and also return the projected splats and tile lists (the backward needs them).
pub fn render_staged(
    scene: &Gaussians,
    cam: &Camera,
    opts: &RenderOptions,
    plan: &RenderPlan,
) -> Result<(Render, project::Projected, tile::TileBins)> {
    check_options(scene, opts)?;
    plan.cutoffs.check()?;
    cam.validate()?;
    let (w, h) = (cam.width as usize, cam.height as usize);
    let mut report = RenderReport::default();
    let projected = project::project(scene, cam, plan, opts, &mut report);
    let bins = tile::bin(&projected, w, h, opts.kernel);
    report.intersections = bins.intersections() as u64;
    let o = opts.outputs;
    let want = composite::Want {
        rgb: o.rgb,
        alpha: o.alpha,
        depth: o.depth && plan.accumulate_depth,
        expected_depth: o.expected_depth && plan.accumulate_depth,
        backward_state: o.backward_state && plan.track_backward_state,
    };
    let out = composite::composite(
        w,
        h,
        &projected,
        &bins,
        plan,
        opts.background,
        want,
        opts.kernel,
        &mut report,
    );
    let render = Render {
        width: w,
        height: h,
        rgb: out.rgb,
        alpha: out.alpha,
        depth: out.depth,
        expected_depth: out.expected_depth,
        final_t: out.final_t,
        n_contrib: out.n_contrib,
        blend_halves: out.blend_halves,
        plan: Some(*plan),
        report,
    };
    Ok((render, projected, bins))
}
