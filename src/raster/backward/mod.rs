//! The backward pass: gradients of a loss on the rendered images with respect to the raw
//! Gaussian parameters and the background. Mirrors the forward file for file:
//! [`composite`] (per-pixel reverse walk, gsplat's formulation) and [`project`] (the
//! projection chain). Deterministic: no atomics, fixed reduction order (SPEC.md §6).

pub mod composite;
pub mod frozen;
pub mod project;
pub mod wide;

pub use composite::{PixelGrads, SplatGrad};
pub use project::{GradGroups, Gradients};

use crate::camera::Camera;
use crate::error::{Error, Result};
use crate::gaussian::Gaussians;
use crate::raster::project::{CameraF32, Projected};
use crate::raster::tile::TileBins;
use crate::raster::{Render, RenderOptions, RenderPlan};

/// Upstream gradients of the loss with respect to the rendered images (planar, row-major,
/// `rgb` interleaved). Absent images contribute nothing.
#[derive(Clone, Debug, Default)]
pub struct ImageGrads {
    pub rgb: Option<Vec<f32>>,
    pub alpha: Option<Vec<f32>>,
    pub depth: Option<Vec<f32>>,
    pub expected_depth: Option<Vec<f32>>,
}

/// What the forward kept for the backward: the render (with `backward_state`), the
/// projected splats and the tile lists.
pub struct ForwardState {
    pub render: Render,
    pub projected: Projected,
    pub bins: TileBins,
    pub plan: RenderPlan,
}

/// Forward render that keeps what the backward needs.
pub fn render_for_backward(
    scene: &Gaussians,
    cam: &Camera,
    opts: &RenderOptions,
) -> Result<ForwardState> {
    if opts.antialiased {
        return Err(Error::invalid(
            "the backward pass of the antialiased mode is not implemented",
        ));
    }
    if opts.cutoffs != crate::raster::Cutoffs::GSPLAT {
        return Err(Error::invalid(format!(
            "the backward pass uses gsplat's cut-offs only (asked for {:?})",
            opts.cutoffs
        )));
    }
    let mut o = opts.clone();
    o.outputs.backward_state = true;
    // ED's gradient needs D itself.
    o.outputs.depth |= o.outputs.expected_depth;
    // Zero SH bands may be skipped in a forward-only render (their terms are exactly 0),
    // but not here: the gradient of a zero coefficient is not zero, and a skipped band
    // would never start to train.
    let plan = RenderPlan::for_backward(scene, &o);
    let (render, projected, bins) = crate::raster::render_staged(scene, cam, &o, &plan)?;
    Ok(ForwardState {
        render,
        projected,
        bins,
        plan,
    })
}

/// Gradients of the raw parameters for the upstream image gradients `v`, and the number of
/// Gaussian-pixel pairs walked.
pub fn backward(
    scene: &Gaussians,
    cam: &Camera,
    opts: &RenderOptions,
    fwd: &ForwardState,
    v: &ImageGrads,
    groups: &GradGroups,
) -> Result<(Gradients, u64)> {
    let mut grads = Gradients::default();
    let pairs = backward_into(scene, cam, opts, fwd, v, groups, &mut grads)?;
    Ok((grads, pairs))
}

/// [`backward`] into `grads`, whose arrays are reused (a training loop allocates them once).
pub fn backward_into(
    scene: &Gaussians,
    cam: &Camera,
    opts: &RenderOptions,
    fwd: &ForwardState,
    v: &ImageGrads,
    groups: &GradGroups,
    grads: &mut Gradients,
) -> Result<u64> {
    let cg = blend_backward(cam, opts, fwd, v, groups)?;
    let camf = CameraF32::new(cam);
    project::project_backward_into(
        scene,
        &camf,
        &fwd.projected,
        &fwd.plan,
        groups,
        &cg.splats,
        opts.kernel,
        grads,
    );
    if groups.background {
        grads.background = cg.background;
    }
    Ok(cg.pairs)
}

/// [`backward_into`] whose parameter gradients go chunk by chunk to `sinks` (the scene's
/// chunks of [`project::CHUNK`] Gaussians, which also hold the parameters the projection
/// backward reads: [`project::project_backward_apply`]) instead of into arrays, each chunk
/// with its splat gradients (the screen-space means: [`project::ChunkGrads::splats`]);
/// `grads` gets only the background's. The same gradients, bit for bit.
#[allow(clippy::too_many_arguments)]
pub fn backward_apply<S: project::GradSink>(
    cam: &Camera,
    opts: &RenderOptions,
    fwd: &ForwardState,
    v: &ImageGrads,
    groups: &GradGroups,
    sinks: &mut [S],
    grads: &mut Gradients,
) -> Result<u64> {
    let cg = blend_backward(cam, opts, fwd, v, groups)?;
    let camf = CameraF32::new(cam);
    grads.background = if groups.background {
        cg.background
    } else {
        [0.0; 3]
    };
    project::project_backward_apply(
        &camf,
        &fwd.projected,
        &fwd.plan,
        groups,
        &cg.splats,
        opts.kernel,
        sinks,
    );
    Ok(cg.pairs)
}

/// The blend's backward (after checking the image gradients against the view and the
/// forward state): per-Gaussian splat gradients, the background's, the pairs walked.
fn blend_backward(
    cam: &Camera,
    opts: &RenderOptions,
    fwd: &ForwardState,
    v: &ImageGrads,
    groups: &GradGroups,
) -> Result<composite::CompositeGrads> {
    let (w, h) = (cam.width as usize, cam.height as usize);
    let npix = w * h;
    for (name, img, ch) in [
        ("rgb", &v.rgb, 3),
        ("alpha", &v.alpha, 1),
        ("depth", &v.depth, 1),
        ("expected_depth", &v.expected_depth, 1),
    ] {
        if let Some(img) = img
            && img.len() != npix * ch
        {
            return Err(Error::invalid(format!(
                "{name} gradient has {} values, the {w}x{h} image needs {}",
                img.len(),
                npix * ch
            )));
        }
    }
    let r = &fwd.render;
    let (Some(final_t), Some(n_contrib), Some(blend_halves)) =
        (&r.final_t, &r.n_contrib, &r.blend_halves)
    else {
        return Err(Error::invalid(
            "the forward render lacks the backward state",
        ));
    };
    if v.expected_depth.is_some() && r.depth.is_none() {
        return Err(Error::invalid(
            "expected-depth gradients need the forward depth output",
        ));
    }
    let depth = r.depth.as_deref();
    let pg = PixelGrads {
        v_rgb: v.rgb.as_deref(),
        v_alpha: v.alpha.as_deref(),
        v_depth: v.depth.as_deref(),
        v_expected_depth: v.expected_depth.as_deref(),
        final_t,
        n_contrib,
        blend_halves,
        depth,
    };
    Ok(composite::composite_backward(
        w,
        h,
        &fwd.projected,
        &fwd.bins,
        fwd.plan.cull_rows,
        fwd.plan.conventions.max_alpha(),
        opts.background,
        &pg,
        groups.geometry(),
        opts.kernel,
    ))
}
