//! Depth and renders every stage reads: a training view's metric depth, a depth map warped
//! to another camera, an estimate under a fitted alignment (SPEC.md §20.2–20.4), and a
//! scene's colour, coverage and expected depth at a camera.

use super::Inputs;
use crate::camera::Camera;
use crate::error::Result;
use crate::io::image::ImageF32;
use crate::models::DepthMap;
use crate::raster::{Outputs, RenderOptions, render};
use crate::warp::align::{Alignment, Space};
use crate::warp::dibr::{WarpOptions, warp};

/// Fewest known-depth pixels a candidate must share with its reference training view.
pub const MIN_ALIGN_PIXELS: usize = 16;

/// Aligned metric depth from an estimate: `s·R + t`, or its inverse in disparity space;
/// non-positive or non-finite results are 0 (unknown).
pub fn apply_alignment(est: &DepthMap, a: &Alignment, space: Space) -> Vec<f32> {
    est.values
        .iter()
        .map(|&r| {
            let m = a.scale * r as f64 + a.offset;
            let d = match space {
                Space::Depth => m,
                Space::Disparity => 1.0 / m,
            };
            if d.is_finite() && d > 0.0 {
                d as f32
            } else {
                0.0
            }
        })
        .collect()
}

/// The metric depth of a training view: the dataset's, else the scene's expected depth.
pub fn training_depth(inputs: &Inputs, vi: usize) -> Result<Vec<f32>> {
    let v = &inputs.data.views[vi];
    if let Some(d) = &v.depth {
        return Ok(d.clone());
    }
    let r = render(
        &inputs.scene,
        &v.camera,
        &RenderOptions {
            background: inputs.background,
            outputs: Outputs {
                rgb: false,
                alpha: true,
                expected_depth: true,
                ..Outputs::default()
            },
            ..RenderOptions::default()
        },
    )?;
    let a = r.alpha.expect("alpha");
    Ok(r.expected_depth
        .expect("expected depth")
        .iter()
        .zip(&a)
        .map(|(&d, &al)| if al > 0.5 { d } else { 0.0 })
        .collect())
}

/// Warp a metric depth map from one camera to another (nearest, crack closing 1).
pub fn warp_depth(depth: &[f32], from: &Camera, to: &Camera) -> Result<Vec<f32>> {
    let img = ImageF32::new(from.width as usize, from.height as usize, 1, depth.to_vec())?;
    let w = warp(
        &img,
        depth,
        from,
        to,
        &WarpOptions {
            close_cracks: 1,
            ..WarpOptions::default()
        },
    )?;
    Ok(w.depth)
}

/// Render RGB alone (what the fixer reads): the same RGB bits as [`render_rgba`] without
/// the depth accumulation (`raster::plan`'s skips are exact).
pub fn render_rgb(
    scene: &crate::gaussian::Gaussians,
    cam: &Camera,
    background: [f32; 3],
) -> Result<ImageF32> {
    let r = render(
        scene,
        cam,
        &RenderOptions {
            background,
            outputs: Outputs::RGB,
            ..RenderOptions::default()
        },
    )?;
    ImageF32::new(r.width, r.height, 3, r.rgb.expect("rgb"))
}

/// Render RGB, alpha and expected depth.
pub fn render_rgba(
    scene: &crate::gaussian::Gaussians,
    cam: &Camera,
    background: [f32; 3],
) -> Result<(ImageF32, Vec<f32>, Vec<f32>)> {
    let r = render(
        scene,
        cam,
        &RenderOptions {
            background,
            outputs: Outputs {
                rgb: true,
                alpha: true,
                expected_depth: true,
                ..Outputs::default()
            },
            ..RenderOptions::default()
        },
    )?;
    let (w, h) = (r.width, r.height);
    Ok((
        ImageF32::new(w, h, 3, r.rgb.expect("rgb"))?,
        r.alpha.expect("alpha"),
        r.expected_depth.expect("expected depth"),
    ))
}
