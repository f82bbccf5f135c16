//! Scale-and-offset alignment of a relative depth (or disparity) map to metric depth
//! (SPEC.md §17): closed-form least squares, and RANSAC over one or many frames (the
//! paper's multi-frame video-depth alignment, §3.2).
//!
//! Model: `s·r + t ≈ m`, where `r` is the estimator's value and `m` the metric target in
//! the chosen space — depth `d`, or disparity `1/d` ([`Space`]). A pixel is valid when its
//! target depth is finite and positive and its estimate is finite. Sums are f64 over
//! centred values, in pixel order (frame by frame), so the result does not depend on the
//! thread count.

use crate::error::{Error, Result};
use crate::rng::Uniform;
use rayon::prelude::*;

/// Where the linear model holds.
#[derive(Clone, Copy, Debug, PartialEq, Eq, serde::Serialize, serde::Deserialize)]
#[serde(rename_all = "snake_case")]
pub enum Space {
    /// `s·r + t ≈ d`.
    Depth,
    /// `s·r + t ≈ 1/d` (what Depth Anything's disparity output needs).
    Disparity,
}

crate::error::text_enum!(Space, "space", { Depth => "depth", Disparity => "disparity" });

/// A fitted alignment and how well it fits.
#[derive(Clone, Copy, Debug, PartialEq, serde::Serialize)]
pub struct Alignment {
    pub scale: f64,
    pub offset: f64,
    /// Pixels used by the final fit (all valid ones for least squares).
    pub inliers: usize,
    pub valid: usize,
    /// Absolute residuals `|s·r + t − m|` over the inliers.
    pub residual_mean: f64,
    pub residual_max: f64,
}

impl Alignment {
    /// No fit: the estimate used as it is (`valid` known pixels were too few to fit).
    pub fn identity(valid: usize) -> Alignment {
        Alignment {
            scale: 1.0,
            offset: 0.0,
            inliers: 0,
            valid,
            residual_mean: 0.0,
            residual_max: 0.0,
        }
    }
}

/// One frame: estimator values and metric target depths, same length.
#[derive(Clone, Copy, Debug)]
pub struct Frame<'a> {
    pub estimate: &'a [f32],
    pub depth: &'a [f32],
}

fn pairs(frames: &[Frame], space: Space) -> Result<Vec<(f64, f64)>> {
    let mut out = Vec::new();
    for (k, f) in frames.iter().enumerate() {
        if f.estimate.len() != f.depth.len() {
            return Err(Error::invalid(format!(
                "frame {k}: {} estimates but {} depths",
                f.estimate.len(),
                f.depth.len()
            )));
        }
        for (&r, &d) in f.estimate.iter().zip(f.depth) {
            if r.is_finite() && d.is_finite() && d > 0.0 {
                let m = match space {
                    Space::Depth => d as f64,
                    Space::Disparity => 1.0 / d as f64,
                };
                out.push((r as f64, m));
            }
        }
    }
    Ok(out)
}

fn fit(p: &[(f64, f64)]) -> Result<(f64, f64)> {
    if p.len() < 2 {
        return Err(Error::invalid(format!(
            "alignment needs at least 2 valid pixels, got {}",
            p.len()
        )));
    }
    let n = p.len() as f64;
    let mx = p.iter().map(|q| q.0).sum::<f64>() / n;
    let my = p.iter().map(|q| q.1).sum::<f64>() / n;
    let (mut sxy, mut sxx) = (0.0, 0.0);
    for &(x, y) in p {
        sxy += (x - mx) * (y - my);
        sxx += (x - mx) * (x - mx);
    }
    if sxx <= 0.0 || !sxx.is_finite() {
        return Err(Error::invalid(
            "all estimated values are equal: scale and offset are not determined",
        ));
    }
    let s = sxy / sxx;
    Ok((s, my - s * mx))
}

fn finish(p: &[(f64, f64)], s: f64, t: f64, inliers: usize, valid: usize) -> Alignment {
    let (mut sum, mut max) = (0.0, 0.0f64);
    for &(x, y) in p {
        let e = (s * x + t - y).abs();
        sum += e;
        max = max.max(e);
    }
    Alignment {
        scale: s,
        offset: t,
        inliers,
        valid,
        residual_mean: sum / p.len().max(1) as f64,
        residual_max: max,
    }
}

/// Closed-form least squares `argmin_{s,t} Σ (s·r + t − m)²` over all valid pixels.
pub fn least_squares(frames: &[Frame], space: Space) -> Result<Alignment> {
    let p = pairs(frames, space)?;
    let (s, t) = fit(&p)?;
    Ok(finish(&p, s, t, p.len(), p.len()))
}

/// RANSAC settings.
#[derive(Clone, Copy, Debug, PartialEq, serde::Serialize, serde::Deserialize)]
pub struct RansacConfig {
    /// Inlier when `|s·r + t − m| ≤ threshold · |m|` (relative to the target).
    pub threshold: f64,
    /// Iterations; with `confidence`, the upper bound of the adaptive count.
    pub iterations: u32,
    /// Stop early once `P(an all-inlier sample was drawn) ≥ confidence`.
    pub confidence: Option<f64>,
    pub seed: u64,
}

impl Default for RansacConfig {
    fn default() -> Self {
        RansacConfig {
            threshold: 0.05,
            iterations: 1000,
            confidence: Some(0.999),
            seed: 0,
        }
    }
}

/// RANSAC over the valid pixels of all frames: minimal samples of 2 pixels with distinct
/// estimates (seeded `rand_pcg`), the model with most inliers wins (ties: the first), then
/// least squares on its inliers.
pub fn ransac(frames: &[Frame], space: Space, cfg: &RansacConfig) -> Result<Alignment> {
    if !(cfg.threshold > 0.0 && cfg.threshold.is_finite()) {
        return Err(Error::invalid("RANSAC threshold must be positive"));
    }
    let p = pairs(frames, space)?;
    fit(&p)?; // the same clear errors as least squares for degenerate input
    let n = p.len();
    let inlier =
        |s: f64, t: f64, q: &(f64, f64)| (s * q.0 + t - q.1).abs() <= cfg.threshold * q.1.abs();
    let mut rng = Uniform::new(crate::rng::stage_seed(cfg.seed, "ransac"));
    let mut best: Option<(usize, f64, f64)> = None;
    let mut needed = cfg.iterations as u64;
    let mut it = 0u64;
    while it < needed {
        it += 1;
        let i = rng.below(n as u32) as usize;
        let j = rng.below(n as u32) as usize;
        let (a, b) = (p[i], p[j]);
        if a.0 == b.0 {
            continue; // no slope from equal estimates; still counts as an iteration
        }
        let s = (b.1 - a.1) / (b.0 - a.0);
        let t = a.1 - s * a.0;
        // An integer count: the same for any thread count.
        let count = p
            .par_iter()
            .with_min_len(1 << 14)
            .filter(|q| inlier(s, t, q))
            .count();
        if best.is_none_or(|bb| count > bb.0) {
            best = Some((count, s, t));
            if let Some(conf) = cfg.confidence {
                // k = log(1 − conf) / log(1 − w²), in f32 with the crate's own `ln` so the
                // count does not depend on the platform's libm.
                use crate::math::fastexp::ln;
                let w = count as f32 / n as f32;
                let miss = 1.0 - w * w;
                let k = if miss <= 0.0 {
                    1.0
                } else {
                    (ln(1.0 - conf as f32) / ln(miss)).ceil()
                };
                if k.is_finite() {
                    needed = needed.min(k.max(1.0) as u64).max(it);
                }
            }
        }
    }
    let Some((_, s, t)) = best else {
        return Err(Error::invalid("RANSAC drew no usable sample"));
    };
    let inl: Vec<(f64, f64)> = p.iter().copied().filter(|q| inlier(s, t, q)).collect();
    // Inliers with equal estimates cannot be refitted: keep the sampled model.
    let (s, t) = fit(&inl).unwrap_or((s, t));
    let inl: Vec<(f64, f64)> = p.iter().copied().filter(|q| inlier(s, t, q)).collect();
    Ok(finish(&inl, s, t, inl.len(), n))
}
