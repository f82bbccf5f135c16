//! Deterministic classical defaults of the model slots (SPEC.md §19.2): `telea`
//! inpainting, `depth-fill` depth, `identity` and `bilateral` artifact fixers. Stand-ins,
//! not substitutes for the paper's generative models: they make the pipeline run end to end
//! with no weights, bit-reproducibly.

use super::VideoDepthEstimator;
use super::telea::inpaint_float;
use super::{ArtifactFixer, DepthEstimator, DepthHint, DepthKind, DepthMap, Inpainter};
use crate::error::{Error, Result};
use crate::io::image::ImageF32;
use crate::math::fastexp::exp;
use rayon::prelude::*;

/// Value span of colours for Telea: `[0, 1]` images are filled as 8-bit ones would be.
pub const COLOR_SPAN: f32 = 255.0;

/// Value span of depth for Telea (its gradient term then moves a filled depth by at most
/// 1.4·10⁻⁴ of the known depth range).
pub const DEPTH_SPAN: f32 = 1.0e4;

/// Telea inpainting on float images (any channel count; SPEC.md §19.1), with the known
/// values mapped to `[0, COLOR_SPAN]` ([`inpaint_float`]).
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Telea {
    pub radius: f64,
}

impl Default for Telea {
    /// OpenCV's usual radius, 3.
    fn default() -> Self {
        Telea { radius: 3.0 }
    }
}

fn check_mask(image: &ImageF32, mask: &[bool]) -> Result<()> {
    if mask.len() != image.width * image.height {
        return Err(Error::invalid(format!(
            "the mask has {} pixels but the image is {}x{}",
            mask.len(),
            image.width,
            image.height
        )));
    }
    Ok(())
}

impl Inpainter for Telea {
    fn name(&self) -> &str {
        "telea"
    }
    fn needs_known_pixels(&self) -> bool {
        true
    }
    fn inpaint(&self, image: &ImageF32, mask: &[bool]) -> Result<ImageF32> {
        check_mask(image, mask)?;
        let data = inpaint_float(
            &image.data,
            image.width,
            image.height,
            image.channels,
            mask,
            self.radius,
            COLOR_SPAN,
        )?;
        ImageF32::new(image.width, image.height, image.channels, data)
    }
}

/// Depth for inpainted regions by extending the known depth into them: Telea on the depth
/// map (float, mapped to `[0, DEPTH_SPAN]`), unknown = not finite, ≤ 0, or under the
/// hint's mask. A stand-in for a
/// monocular estimator: it returns metric depth where the hint is metric, and cannot
/// invent structure the known depth does not imply.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct DepthFill {
    pub radius: f64,
}

impl Default for DepthFill {
    fn default() -> Self {
        DepthFill { radius: 5.0 }
    }
}

impl DepthEstimator for DepthFill {
    fn name(&self) -> &str {
        "depth-fill"
    }
    fn needs_known_depth(&self) -> bool {
        true
    }
    fn estimate(&self, image: &ImageF32, hint: Option<DepthHint>) -> Result<DepthMap> {
        let hint = hint.ok_or_else(|| {
            Error::invalid("depth-fill extends known depth: it needs a depth hint")
        })?;
        let n = image.width * image.height;
        if hint.depth.len() != n || hint.mask.is_some_and(|m| m.len() != n) {
            return Err(Error::invalid(format!(
                "the depth hint does not have the image's {}x{} pixels",
                image.width, image.height
            )));
        }
        let unknown: Vec<bool> = (0..n)
            .map(|i| {
                let d = hint.depth[i];
                !(d.is_finite() && d > 0.0) || hint.mask.is_some_and(|m| m[i])
            })
            .collect();
        if unknown.iter().all(|&u| u) {
            return Err(Error::invalid("depth-fill: the hint has no known depth"));
        }
        let values = inpaint_float(
            hint.depth,
            image.width,
            image.height,
            1,
            &unknown,
            self.radius,
            DEPTH_SPAN,
        )?;
        Ok(DepthMap {
            width: image.width,
            height: image.height,
            kind: DepthKind::Depth,
            values,
        })
    }
}

impl VideoDepthEstimator for DepthFill {
    fn name(&self) -> &str {
        "depth-fill"
    }
    fn estimate(&self, frames: &[ImageF32], hints: Option<&[DepthHint]>) -> Result<Vec<DepthMap>> {
        let hints = hints.ok_or_else(|| {
            Error::invalid("depth-fill extends known depth: it needs one hint per frame")
        })?;
        if hints.len() != frames.len() {
            return Err(Error::invalid(format!(
                "{} frames but {} depth hints",
                frames.len(),
                hints.len()
            )));
        }
        frames
            .iter()
            .zip(hints)
            .map(|(f, h)| DepthEstimator::estimate(self, f, Some(*h)))
            .collect()
    }
}

/// Returns the render unchanged.
#[derive(Clone, Copy, Debug, Default, PartialEq)]
pub struct Identity;

impl ArtifactFixer for Identity {
    fn name(&self) -> &str {
        "identity"
    }
    fn fix(&self, render: &ImageF32, _reference: Option<&ImageF32>) -> Result<ImageF32> {
        Ok(render.clone())
    }
}

/// A mild edge-preserving bilateral filter: `out(p) = Σ_q w·I(q) / Σ_q w` over the
/// `(2r+1)²` window inside the image, `w = exp(−|p−q|²/(2σ_s²) − |I(p)−I(q)|²/(2σ_r²))`
/// (colour distance summed over channels), with the crate's own `exp` (f32). The reference
/// view is not used.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Bilateral {
    pub radius: usize,
    pub sigma_space: f32,
    pub sigma_range: f32,
}

impl Default for Bilateral {
    fn default() -> Self {
        Bilateral {
            radius: 2,
            sigma_space: 1.5,
            sigma_range: 0.08,
        }
    }
}

impl ArtifactFixer for Bilateral {
    fn name(&self) -> &str {
        "bilateral"
    }
    fn fix(&self, render: &ImageF32, _reference: Option<&ImageF32>) -> Result<ImageF32> {
        if !(self.sigma_space > 0.0 && self.sigma_range > 0.0) {
            return Err(Error::invalid("bilateral sigmas must be positive"));
        }
        let (w, h, ch) = (render.width, render.height, render.channels);
        let r = self.radius as i64;
        let (ks, kr) = (
            0.5 / (self.sigma_space * self.sigma_space),
            0.5 / (self.sigma_range * self.sigma_range),
        );
        let src = &render.data;
        let mut out = vec![0f32; src.len()];
        out.par_chunks_mut(w * ch).enumerate().for_each(|(y, row)| {
            let mut acc = vec![0f32; ch];
            for x in 0..w {
                let p = &src[(y * w + x) * ch..(y * w + x + 1) * ch];
                acc.fill(0.0);
                let mut wsum = 0f32;
                for dy in -r..=r {
                    let yy = y as i64 + dy;
                    if yy < 0 || yy >= h as i64 {
                        continue;
                    }
                    for dx in -r..=r {
                        let xx = x as i64 + dx;
                        if xx < 0 || xx >= w as i64 {
                            continue;
                        }
                        let k = (yy as usize * w + xx as usize) * ch;
                        let q = &src[k..k + ch];
                        let d2: f32 = p.iter().zip(q).map(|(a, b)| (a - b) * (a - b)).sum();
                        let wt = exp(-((dx * dx + dy * dy) as f32) * ks - d2 * kr);
                        for (a, &v) in acc.iter_mut().zip(q) {
                            *a += wt * v;
                        }
                        wsum += wt;
                    }
                }
                for (o, a) in row[x * ch..(x + 1) * ch].iter_mut().zip(&acc) {
                    *o = a / wsum;
                }
            }
        });
        ImageF32::new(w, h, ch, out)
    }
}
